//! Builds a random scene (world geometry, textures, object paths, camera motion) from a preset's
//! recipe and a seed.

use rand::Rng;

use crate::atlas::TextureAtlas;
use crate::camera::project_world;
use crate::config::{Layout, SceneParams, SimConfig};
use crate::linalg::{Mat3, RigidTransform, Vec3};
use crate::motion::{EgoMotion, ObjectPath, Vec3Def, Wobble};
use crate::scene::{MovingObject, Panel, Scene, Shape};
use crate::texture::{Texture, TextureStyle};
use crate::variation::vary_objects;

/// Side of every texture in texels.
pub const TEXTURE_SIZE: usize = 256;

/// Share of the image width and height, centred, within which the filmed object's path stays
/// at the camera's base pose; the ego wobble (up to about a third of the field of view) then
/// carries it towards the edges or briefly out of view, but not away for good.
const FILMED_VIEW_SHARE: f32 = 0.6;

/// Largest amplitude of one term of the camera's yaw or pitch wobble (rad); the three terms
/// together swing the view by at most about a third of its width.
const MAX_SWING_RAD: f32 = 0.2;

/// Where moving objects may be, and whether they rest on a surface.
pub(crate) struct ObjectRegion {
    pub lower: Vec3,
    pub upper: Vec3,
    /// y of the supporting surface (objects rest on it) or `None` when they fly.
    pub ground_y: Option<f32>,
}

/// Builds the scene of `config`; with `photographs`, every surface takes one of them at random
/// instead of a procedural texture of its style.
pub fn build_scene(config: &SimConfig, photographs: &[Texture], rng: &mut impl Rng) -> Scene {
    let params = &config.scene;
    let mut textures = Vec::new();
    let mut new_texture = |style: &TextureStyle, rng: &mut dyn rand::RngCore| {
        let mut rng = RngAdapter(rng);
        textures.push(if photographs.is_empty() {
            Texture::generate(TEXTURE_SIZE, style, &mut rng)
        } else {
            photographs[rng.gen_range(0..photographs.len())].clone()
        });
        textures.len() - 1
    };
    let world_style = params.world_texture;
    let mut panels = Vec::new();
    let (ego, region) = match params.layout {
        Layout::Room | Layout::Floor | Layout::Wall => {
            let (back_z, camera_height, pitch) = match params.layout {
                Layout::Room => (rng.gen_range(3.5..5.0), 1.2, rng.gen_range(-0.15..0.05)),
                Layout::Floor => (rng.gen_range(3.5..5.0), 1.0, rng.gen_range(-0.8..-0.55)),
                _ => (rng.gen_range(1.4..2.0), 1.2, rng.gen_range(-0.05..0.05)),
            };
            add_room(
                &mut panels,
                &mut new_texture,
                &world_style,
                back_z,
                camera_height,
                rng,
            );
            if params.layout != Layout::Wall {
                add_furniture(
                    &mut panels,
                    &mut new_texture,
                    &world_style,
                    back_z,
                    camera_height,
                    rng,
                );
            }
            let region = match params.layout {
                Layout::Room => ObjectRegion {
                    lower: Vec3::new(-1.8, -0.6, 1.0),
                    upper: Vec3::new(1.8, camera_height - 0.2, back_z - 0.8),
                    ground_y: None,
                },
                Layout::Floor => ObjectRegion {
                    lower: Vec3::new(-1.5, camera_height, 0.9),
                    upper: Vec3::new(1.5, camera_height, 2.8),
                    ground_y: Some(camera_height),
                },
                // No nearer than 1 m: closer, an object fills much of the view and its events
                // outnumber the wall's (up to 45 % of the stream before suite version 3).
                _ => ObjectRegion {
                    lower: Vec3::new(-1.6, -0.8, 1.0),
                    upper: Vec3::new(1.6, 0.8, back_z - 0.3),
                    ground_y: None,
                },
            };
            (hand_held(params, pitch, rng), region)
        }
        Layout::Table => {
            let table_y = 0.55;
            let table_z = 0.85;
            add_room(
                &mut panels,
                &mut new_texture,
                &world_style,
                3.0,
                table_y + 0.75,
                rng,
            );
            panels.push(Panel {
                origin: Vec3::new(0.0, table_y, table_z),
                axis_u: Vec3::new(1.0, 0.0, 0.0),
                axis_v: Vec3::new(0.0, 0.0, 1.0),
                half_extent: Some((0.9, 0.6)),
                texture: new_texture(&world_style, rng),
                texel_m: 0.004,
            });
            let region = ObjectRegion {
                lower: Vec3::new(-0.6, table_y, table_z - 0.45),
                upper: Vec3::new(0.6, table_y, table_z + 0.45),
                ground_y: Some(table_y),
            };
            (hand_held(params, rng.gen_range(-0.8..-0.6), rng), region)
        }
        Layout::Road => {
            let camera_height = 1.4;
            add_street(
                &mut panels,
                &mut new_texture,
                &world_style,
                camera_height,
                rng,
            );
            let region = ObjectRegion {
                lower: Vec3::new(-5.5, camera_height, 5.0),
                upper: Vec3::new(5.5, camera_height, 30.0),
                ground_y: Some(camera_height),
            };
            let mut ego = hand_held(params, rng.gen_range(-0.06..0.0), rng);
            ego.drive_velocity = Vec3Def([0.0, 0.0, params.drive_mps]);
            (ego, region)
        }
    };
    let object_count =
        rng.gen_range(params.min_objects..=params.max_objects.max(params.min_objects));
    // As in EVIMO, where the objects are filmed, the first object moves within the camera's
    // view; the others roam the whole region and enter and leave it. Traffic needs no such
    // rule: several cars share the road ahead.
    let filmed = match params.layout {
        Layout::Road => None,
        _ => filmed_region(&region, &ego, config),
    };
    let mut objects: Vec<MovingObject> = (0..object_count)
        .map(|k| {
            let texture = new_texture(&params.object_texture, rng);
            let object_region = match &filmed {
                Some(filmed) if k == 0 => filmed,
                _ => &region,
            };
            random_object(params, object_region, texture, rng)
        })
        .collect();
    let light = Vec3::new(rng.gen_range(-0.5..0.5), -1.0, rng.gen_range(-0.8..-0.2)).normalized();
    vary_objects(params, &region, &ego, &mut objects, &mut new_texture, rng);
    Scene {
        sensor: config.sensor,
        intrinsics: config.intrinsics,
        ego,
        panels,
        objects,
        atlas: TextureAtlas::new(&textures),
        textures,
        light,
        ambient: 0.45,
    }
}

/// The part of `region` that the camera sees, at its base pose, within the central
/// [`FILMED_VIEW_SHARE`] of the image: `region` scaled about the point the camera looks at (on
/// the supporting surface, or on the optical axis at the region's middle depth) as far as all
/// its corners stay in that part of the image. `None` when that point itself is out of view.
fn filmed_region(
    region: &ObjectRegion,
    ego: &EgoMotion,
    config: &SimConfig,
) -> Option<ObjectRegion> {
    let [yaw, pitch, roll] = ego.base_attitude;
    let camera = RigidTransform {
        rotation: Mat3::from_yaw_pitch_roll(yaw, pitch, roll),
        translation: ego.base_position.into(),
    };
    let axis = camera.rotation.apply(Vec3::new(0.0, 0.0, 1.0));
    let origin = camera.translation;
    let along_axis = match region.ground_y {
        Some(ground) => (ground - origin.y) / axis.y,
        None => ((region.lower.z + region.upper.z) / 2.0 - origin.z) / axis.z,
    };
    // NaN or infinite when the axis runs parallel to the supporting surface.
    if !along_axis.is_finite() || along_axis <= 0.0 {
        return None;
    }
    let clamp = |p: Vec3| {
        Vec3::new(
            p.x.clamp(region.lower.x, region.upper.x),
            p.y.clamp(region.lower.y, region.upper.y),
            p.z.clamp(region.lower.z, region.upper.z),
        )
    };
    let centre = clamp(origin + axis * along_axis);
    let (width, height) = (config.sensor.width as f32, config.sensor.height as f32);
    let margin = (1.0 - FILMED_VIEW_SHARE) / 2.0;
    let in_view = |p: Vec3| {
        project_world(&config.intrinsics, &camera, p).is_some_and(|(x, y)| {
            (margin * width..=(1.0 - margin) * width).contains(&x)
                && (margin * height..=(1.0 - margin) * height).contains(&y)
        })
    };
    if !in_view(centre) {
        return None;
    }
    let scaled = |scale: f32| {
        (
            clamp(centre + (region.lower - centre) * scale),
            clamp(centre + (region.upper - centre) * scale),
        )
    };
    let corners_in_view = |(lower, upper): (Vec3, Vec3)| {
        (0..8).all(|i| {
            in_view(Vec3::new(
                if i & 1 == 0 { lower.x } else { upper.x },
                if i & 2 == 0 { lower.y } else { upper.y },
                if i & 4 == 0 { lower.z } else { upper.z },
            ))
        })
    };
    // The view is convex and contains the centre, so the scales that fit form an interval
    // from 0: bisect for its end.
    let (mut fits, mut too_large) = (0.0f32, 1.0f32);
    if corners_in_view(scaled(1.0)) {
        fits = 1.0;
    }
    while fits < 1.0 && too_large - fits > 1e-3 {
        let middle = (fits + too_large) / 2.0;
        if corners_in_view(scaled(middle)) {
            fits = middle;
        } else {
            too_large = middle;
        }
    }
    let (lower, upper) = scaled(fits);
    Some(ObjectRegion {
        lower,
        upper,
        ground_y: region.ground_y,
    })
}

/// `rand::Rng` over a `dyn RngCore`, so one closure can draw textures from the caller's generator.
struct RngAdapter<'a>(&'a mut dyn rand::RngCore);

impl rand::RngCore for RngAdapter<'_> {
    fn next_u32(&mut self) -> u32 {
        self.0.next_u32()
    }
    fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn fill_bytes(&mut self, dest: &mut [u8]) {
        self.0.fill_bytes(dest)
    }
    fn try_fill_bytes(&mut self, dest: &mut [u8]) -> Result<(), rand::Error> {
        self.0.try_fill_bytes(dest)
    }
}

/// Camera wobble around a base attitude; negative `pitch` tilts the view down (y points down).
fn hand_held(params: &SceneParams, pitch: f32, rng: &mut impl Rng) -> EgoMotion {
    let rotation = params.ego_rotation_rad_s;
    let translation = params.ego_translation_mps;
    EgoMotion {
        base_position: Vec3Def([0.0, 0.0, 0.0]),
        base_attitude: [rng.gen_range(-0.15..0.15), pitch, 0.0],
        drive_velocity: Vec3Def::default(),
        // Yaw and pitch dominate hand-held motion; roll is weaker. Their swings are bounded
        // because the camera films the objects: it looks around them, not away.
        attitude_wobble: [
            Wobble::random_bounded(3, rotation, MAX_SWING_RAD, 0.15, 1.5, rng),
            Wobble::random_bounded(3, rotation * 0.7, MAX_SWING_RAD, 0.15, 1.5, rng),
            Wobble::random(2, rotation * 0.3, 0.1, 1.0, rng),
        ],
        position_wobble: [
            Wobble::random(2, translation, 0.1, 1.0, rng),
            Wobble::random(2, translation * 0.6, 0.1, 1.0, rng),
            Wobble::random(2, translation * 0.8, 0.1, 1.0, rng),
        ],
    }
}

pub(crate) type NewTexture<'a> = dyn FnMut(&TextureStyle, &mut dyn rand::RngCore) -> usize + 'a;

/// Floor, ceiling, back wall and side walls of a room around the camera at the origin.
fn add_room(
    panels: &mut Vec<Panel>,
    new_texture: &mut NewTexture<'_>,
    style: &TextureStyle,
    back_z: f32,
    camera_height: f32,
    rng: &mut impl Rng,
) {
    let floor_style = TextureStyle {
        mean: style.mean * 0.8,
        stripes: style.stripes.max(0.2),
        ..*style
    };
    let x = Vec3::new(1.0, 0.0, 0.0);
    let y = Vec3::new(0.0, 1.0, 0.0);
    let z = Vec3::new(0.0, 0.0, 1.0);
    let half_width = rng.gen_range(2.2..3.2);
    let mut planes = vec![
        (Vec3::new(0.0, camera_height, 0.0), x, z, floor_style, 0.015),
        (
            Vec3::new(0.0, camera_height - 2.8, 0.0),
            x,
            z,
            TextureStyle {
                mean: 0.7,
                contrast: 0.3,
                ..*style
            },
            0.02,
        ),
        (Vec3::new(0.0, 0.0, back_z), x, y, *style, 0.02),
        (Vec3::new(-half_width, 0.0, 0.0), z, y, *style, 0.015),
        (Vec3::new(half_width, 0.0, 0.0), z, y, *style, 0.015),
    ];
    // A wall behind the camera closes the room for strong rotations.
    planes.push((Vec3::new(0.0, 0.0, -1.5), x, y, *style, 0.015));
    for (origin, axis_u, axis_v, texture_style, texel_m) in planes {
        let texture = new_texture(&texture_style, rng);
        panels.push(Panel {
            origin,
            axis_u,
            axis_v,
            half_extent: None,
            texture,
            texel_m,
        });
    }
}

/// Finite panels at intermediate depths (shelves, cabinets, posters on stands): extra depth
/// layers that occlude the walls and create parallax.
fn add_furniture(
    panels: &mut Vec<Panel>,
    new_texture: &mut NewTexture<'_>,
    style: &TextureStyle,
    back_z: f32,
    camera_height: f32,
    rng: &mut impl Rng,
) {
    for _ in 0..rng.gen_range(2..=4) {
        let half_w = rng.gen_range(0.25..0.7);
        let half_h = rng.gen_range(0.3..0.9);
        let yaw: f32 = rng.gen_range(-0.8..0.8);
        let axis_u = Vec3::new(yaw.cos(), 0.0, -yaw.sin());
        let style = TextureStyle {
            mean: rng.gen_range(0.25..0.7),
            ..*style
        };
        let texture = new_texture(&style, rng);
        panels.push(Panel {
            origin: Vec3::new(
                rng.gen_range(-2.0..2.0),
                camera_height - half_h,
                rng.gen_range(2.0..back_z - 0.3),
            ),
            axis_u,
            axis_v: Vec3::new(0.0, 1.0, 0.0),
            half_extent: Some((half_w, half_h)),
            texture,
            texel_m: 0.01,
        });
    }
}

/// Road, facades on both sides, a distant backdrop and sky, and roadside posts and signs.
fn add_street(
    panels: &mut Vec<Panel>,
    new_texture: &mut NewTexture<'_>,
    style: &TextureStyle,
    camera_height: f32,
    rng: &mut impl Rng,
) {
    let x = Vec3::new(1.0, 0.0, 0.0);
    let y = Vec3::new(0.0, 1.0, 0.0);
    let z = Vec3::new(0.0, 0.0, 1.0);
    let asphalt = TextureStyle {
        mean: 0.3,
        contrast: 0.5,
        noise: 1.0,
        shape_density: 0.2,
        stripes: 0.6,
        ..TextureStyle::default()
    };
    let facade = TextureStyle {
        shape_density: 2.0,
        ..*style
    };
    let sky = TextureStyle {
        mean: 0.9,
        contrast: 0.1,
        noise: 1.0,
        shape_density: 0.0,
        stripes: 0.0,
        ..TextureStyle::default()
    };
    let street_half_width = rng.gen_range(7.0..10.0);
    let planes = [
        (Vec3::new(0.0, camera_height, 0.0), x, z, asphalt, 0.03),
        (Vec3::new(-street_half_width, 0.0, 0.0), z, y, facade, 0.05),
        (Vec3::new(street_half_width, 0.0, 0.0), z, y, facade, 0.05),
        (Vec3::new(0.0, -30.0, 0.0), x, z, sky, 1.0),
        (Vec3::new(0.0, 0.0, 2000.0), x, y, sky, 5.0),
    ];
    for (origin, axis_u, axis_v, texture_style, texel_m) in planes {
        let texture = new_texture(&texture_style, rng);
        panels.push(Panel {
            origin,
            axis_u,
            axis_v,
            half_extent: None,
            texture,
            texel_m,
        });
    }
    let post_style = TextureStyle {
        mean: 0.55,
        contrast: 0.9,
        ..*style
    };
    let mut z_along = rng.gen_range(5.0..15.0);
    while z_along < 400.0 {
        let side = if rng.gen_bool(0.5) { -1.0 } else { 1.0 };
        let half_w = rng.gen_range(0.15..1.2);
        let half_h = rng.gen_range(1.0..2.5);
        let texture = new_texture(&post_style, rng);
        panels.push(Panel {
            origin: Vec3::new(
                side * rng.gen_range(4.5..street_half_width - 0.5),
                camera_height - half_h,
                z_along,
            ),
            axis_u: x,
            axis_v: y,
            half_extent: Some((half_w, half_h)),
            texture,
            texel_m: 0.02,
        });
        z_along += rng.gen_range(6.0..20.0);
    }
}

/// A box whose longest side is `size`.
pub(crate) fn random_box(size: f32, rng: &mut impl Rng) -> Shape {
    let half = size / 2.0;
    Shape::Cuboid {
        half: Vec3::new(
            half,
            half * rng.gen_range(0.5..1.0),
            half * rng.gen_range(0.5..1.0),
        ),
    }
}

/// A random axis for a flying object to tumble about; objects on a surface turn about the
/// vertical.
pub(crate) fn random_spin_axis(flying: bool, rng: &mut impl Rng) -> Vec3 {
    if flying {
        Vec3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        )
        .normalized()
    } else {
        Vec3::new(0.0, 1.0, 0.0)
    }
}

fn random_object(
    params: &SceneParams,
    region: &ObjectRegion,
    texture: usize,
    rng: &mut impl Rng,
) -> MovingObject {
    let size = rng
        .gen_range(params.object_size_m[0]..=params.object_size_m[1].max(params.object_size_m[0]));
    let driving = params.layout == Layout::Road;
    let shape = if driving {
        if rng.gen_bool(0.35) {
            // A pedestrian.
            Shape::Cuboid {
                half: Vec3::new(0.25, 0.85, 0.2),
            }
        } else {
            Shape::Cuboid {
                half: Vec3::new(0.9, 0.75, size / 2.0),
            }
        }
    } else if rng.gen_bool(params.flat_object_share.clamp(0.0, 1.0) as f64) {
        Shape::Ellipse {
            half_x: size / 2.0,
            half_y: size / 2.0 * rng.gen_range(0.5..1.0),
        }
    } else {
        random_box(size, rng)
    };
    let half_height = shape.half_height();
    let (mut lower, mut upper) = (region.lower, region.upper);
    if let Some(ground) = region.ground_y {
        lower.y = ground - half_height;
        upper.y = ground - half_height;
    }
    let speed = params.object_speed_mps * rng.gen_range(0.6..1.4);
    let heading: f32 = rng.gen_range(0.0..std::f32::consts::TAU);
    let climb = if region.ground_y.is_some() {
        0.0
    } else {
        rng.gen_range(-0.4..0.4)
    };
    let velocity = Vec3::new(heading.cos(), climb, heading.sin()).normalized() * speed;
    let start = Vec3::new(
        rng.gen_range(lower.x..=upper.x),
        rng.gen_range(lower.y..=upper.y),
        rng.gen_range(lower.z..=upper.z),
    );
    let flying = region.ground_y.is_none();
    let wobble_speed = speed * 0.6;
    let wobble = [
        Wobble::random(2, wobble_speed, 0.2, 1.2, rng),
        if flying {
            Wobble::random(2, wobble_speed * 0.5, 0.2, 1.2, rng)
        } else {
            Wobble::default()
        },
        Wobble::random(
            2,
            wobble_speed * if driving { 4.0 } else { 1.0 },
            0.05,
            0.8,
            rng,
        ),
    ];
    let spin_axis = random_spin_axis(flying, rng);
    let spin_rate = if driving {
        0.0
    } else {
        rng.gen_range(-2.0..2.0)
    };
    // Traffic moves mostly along the street, relative to the driving camera.
    let velocity = if driving {
        Vec3::new(velocity.x * 0.3, 0.0, velocity.z)
    } else {
        velocity
    };
    MovingObject {
        shape,
        path: ObjectPath {
            start: start.into(),
            velocity: velocity.into(),
            speed_modulation: (
                rng.gen_range(0.0..0.7),
                rng.gen_range(0.5..3.0),
                rng.gen_range(0.0..std::f32::consts::TAU),
            ),
            wobble,
            lower: lower.into(),
            upper: upper.into(),
            follows_drive: driving,
            base_rotation: [
                rng.gen_range(-std::f32::consts::PI..std::f32::consts::PI),
                0.0,
                0.0,
            ],
            spin_axis: spin_axis.into(),
            spin_rate,
            spin_wobble: Wobble::random(1, 0.5, 0.2, 1.0, rng),
            turn_rate: 0.0,
        },
        texture,
        texel_m: size / 128.0,
    }
}
