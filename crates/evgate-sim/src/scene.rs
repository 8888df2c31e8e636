//! What the camera looks at: a static world of textured planes at several depths and
//! independently moving textured objects, with the camera's own motion.

use evgate_core::SensorSize;

use crate::atlas::TextureAtlas;
use crate::camera::Intrinsics;
use crate::linalg::Vec3;
use crate::motion::{EgoMotion, ObjectPath};
use crate::silhouette::Silhouette;
use crate::texture::Texture;

/// A textured plane of the static world: infinite (floor, back wall) or a finite rectangle
/// (panels, furniture, buildings) when `half_extent` is set.
#[derive(Clone, Debug)]
pub struct Panel {
    pub origin: Vec3,
    /// Unit in-plane axes; the texture's u and v run along them.
    pub axis_u: Vec3,
    pub axis_v: Vec3,
    /// Half width and half height along the axes, in metres.
    pub half_extent: Option<(f32, f32)>,
    pub texture: usize,
    /// Metres per texel of level 0.
    pub texel_m: f32,
}

impl Panel {
    pub fn normal(&self) -> Vec3 {
        self.axis_u.cross(self.axis_v).normalized()
    }
}

/// Geometry of a moving object in its own frame (centred at the origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// A box with these half sizes along its local axes.
    Cuboid { half: Vec3 },
    /// A flat ellipse in the local x–y plane (a thrown disc, a sheet, a sign).
    Ellipse { half_x: f32, half_y: f32 },
    /// A flat plate in the local x–y plane cut to a silhouette (non-convex outlines, thin
    /// parts, holes).
    Cutout(Silhouette),
}

impl Shape {
    /// Corners of the local bounding box, for screen-space culling and speed estimates.
    pub fn corners(&self) -> [Vec3; 8] {
        let half = match *self {
            Shape::Cuboid { half } => half,
            Shape::Ellipse { half_x, half_y } => Vec3::new(half_x, half_y, 0.0),
            Shape::Cutout(silhouette) => {
                let [x, y] = silhouette.reach();
                Vec3::new(x, y, 0.0)
            }
        };
        let mut corners = [Vec3::default(); 8];
        for (i, corner) in corners.iter_mut().enumerate() {
            let sx = if i & 1 == 0 { -1.0 } else { 1.0 };
            let sy = if i & 2 == 0 { -1.0 } else { 1.0 };
            let sz = if i & 4 == 0 { -1.0 } else { 1.0 };
            *corner = Vec3::new(half.x * sx, half.y * sy, half.z * sz);
        }
        corners
    }

    /// How far the object reaches below its centre along its local y axis (an object resting
    /// on a surface stands that high above it).
    pub fn half_height(&self) -> f32 {
        match *self {
            Shape::Cuboid { half } => half.y,
            Shape::Ellipse { half_y, .. } => half_y,
            Shape::Cutout(silhouette) => silhouette.reach()[1],
        }
    }
}

/// An independently moving object; its id (1-based) is the label of its pixels and events.
#[derive(Clone, Debug)]
pub struct MovingObject {
    pub shape: Shape,
    pub path: ObjectPath,
    pub texture: usize,
    pub texel_m: f32,
}

/// A complete scene, enough to render any instant.
#[derive(Clone, Debug)]
pub struct Scene {
    pub sensor: SensorSize,
    pub intrinsics: Intrinsics,
    pub ego: EgoMotion,
    pub panels: Vec<Panel>,
    pub objects: Vec<MovingObject>,
    pub textures: Vec<Texture>,
    /// The same textures in one array, for sampling eight pixels at once.
    pub atlas: TextureAtlas,
    /// Unit direction towards a distant light, in world coordinates.
    pub light: Vec3,
    /// Share of light that reaches every surface regardless of orientation.
    pub ambient: f32,
}
