//! Ray casting of a scene at one instant: log intensity, surface id and depth per pixel, by
//! ray–plane and ray–box intersection with a pinhole camera (so camera translation produces
//! parallax and objects occlude by depth).

use std::ops::Range;

use crate::camera::project_world;
#[cfg(target_arch = "x86_64")]
use crate::index_lanes::checked_first_and_uniform;
use crate::linalg::{Mat3, RigidTransform, Vec3};
use crate::scene::{Panel, Scene, Shape};

#[cfg(target_arch = "x86_64")]
mod avx2;
mod panels;
mod reference;
mod rows;

/// Log intensity of a ray that hits nothing (darker than any lit texel).
const LOG_DARK: f32 = -6.0;

/// Surfaces closer to a ray's origin than this, in metres, are not hit: the camera's near
/// plane, the same in the per-pixel path, the row renderer and every kernel.
const NEAR_PLANE_M: f32 = 1e-3;

/// Pixel-aligned buffers of one rendered instant (row-major).
#[derive(Clone, Debug, Default)]
pub struct Frame {
    pub log_intensity: Vec<f32>,
    /// 0 = static world, k = moving object k.
    pub surface: Vec<u16>,
    /// Distance along the optical axis in metres (`f32::INFINITY` where nothing is hit).
    pub depth: Vec<f32>,
}

impl Frame {
    pub fn new(pixels: usize) -> Frame {
        Frame {
            log_intensity: vec![0.0; pixels],
            surface: vec![0; pixels],
            depth: vec![0.0; pixels],
        }
    }
}

/// What a pixel's ray hit: enough to follow the surface point through time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// 0 = static world, k = moving object k.
    pub surface: u16,
    /// The hit point: world coordinates for the static world, object-local coordinates for an
    /// object (so it can be moved with the object's pose at another time).
    pub point: Vec3,
    pub depth: f32,
    pub log_intensity: f32,
}

/// A [`Hit`] without its shading: what the ground truth (masks, depth, flow) needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    /// 0 = static world, k = moving object k.
    pub surface: u16,
    /// As [`Hit::point`].
    pub point: Vec3,
    pub depth: f32,
}

/// Where every surface is at one instant, plus screen-space bounds used to skip rays that
/// cannot hit a finite surface.
pub struct Snapshot<'a> {
    scene: &'a Scene,
    camera: RigidTransform,
    objects: Vec<PlacedObject>,
    panel_bounds: Vec<ScreenBounds>,
    panel_planes: Vec<PlanePlacement>,
    panel_constants: Vec<PanelConstants>,
    all_objects: Vec<usize>,
}

/// A panel's shading constants in one cache line, for eight pixels' panels: broadcast from one
/// record where a block lies on one panel, gathered field by field (a stride of
/// [`PANEL_FIELDS`]) where it does not.
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
struct PanelConstants([f32; PANEL_FIELDS]);

/// Values per [`PanelConstants`] record.
const PANEL_FIELDS: usize = 16;

/// Where each constant lies in a [`PanelConstants`] record (the texture index as `f32` bits).
mod field {
    pub const ORIGIN: usize = 0;
    pub const AXIS_U: usize = 3;
    pub const AXIS_V: usize = 6;
    pub const NORMAL: usize = 9;
    pub const TEXELS_PER_M: usize = 12;
    pub const LOG_ILLUMINATION: usize = 13;
    pub const TEXTURE: usize = 14;
}

impl PanelConstants {
    fn new(panel: &Panel, plane: &PlanePlacement) -> PanelConstants {
        let mut record = [0.0; PANEL_FIELDS];
        for (first, vector) in [
            (field::ORIGIN, panel.origin),
            (field::AXIS_U, panel.axis_u),
            (field::AXIS_V, panel.axis_v),
            (field::NORMAL, plane.normal),
        ] {
            record[first..first + 3].copy_from_slice(&[vector.x, vector.y, vector.z]);
        }
        record[field::TEXELS_PER_M] = plane.texels_per_m;
        record[field::LOG_ILLUMINATION] = plane.log_illumination;
        record[field::TEXTURE] =
            f32::from_bits(i32::try_from(panel.texture).expect("texture index under 2^31") as u32);
        PanelConstants(record)
    }
}

/// A panel's plane relative to the camera centre: a ray `t·d` meets it at `t = offset / (n·d)`.
struct PlanePlacement {
    normal: Vec3,
    offset: f32,
    log_illumination: f32,
    /// `1 / texel-m`, once per panel rather than per pixel.
    texels_per_m: f32,
}

struct PlacedObject {
    pose: RigidTransform,
    inverse_rotation: Mat3,
    /// The camera centre in the object's frame: the origin of every ray there.
    local_camera: Vec3,
    /// The light on faces normal to each local axis (either side: the same bits, as
    /// [`log_illumination`] depends on the normal's sign only through an absolute value).
    log_illumination: [f32; 3],
    bounds: ScreenBounds,
    /// `1 / texel-m`, once per object rather than per pixel.
    texels_per_m: f32,
}

#[derive(Clone, Copy)]
struct ScreenBounds {
    x0: f32,
    x1: f32,
    y0: f32,
    y1: f32,
}

impl ScreenBounds {
    const EVERYWHERE: ScreenBounds = ScreenBounds {
        x0: f32::MIN,
        x1: f32::MAX,
        y0: f32::MIN,
        y1: f32::MAX,
    };

    /// Bounds of the projected points, one pixel wider; everywhere when a point is behind the
    /// camera (its projection is unbounded).
    fn of_points(
        scene: &Scene,
        camera: &RigidTransform,
        points: impl Iterator<Item = Vec3>,
    ) -> ScreenBounds {
        let mut bounds = ScreenBounds {
            x0: f32::MAX,
            x1: f32::MIN,
            y0: f32::MAX,
            y1: f32::MIN,
        };
        for point in points {
            let Some((x, y)) = project_world(&scene.intrinsics, camera, point) else {
                return ScreenBounds::EVERYWHERE;
            };
            bounds.x0 = bounds.x0.min(x - 1.0);
            bounds.x1 = bounds.x1.max(x + 1.0);
            bounds.y0 = bounds.y0.min(y - 1.0);
            bounds.y1 = bounds.y1.max(y + 1.0);
        }
        bounds
    }

    fn contains_row(&self, y: f32) -> bool {
        y >= self.y0 && y <= self.y1
    }

    fn contains_column(&self, x: f32) -> bool {
        x >= self.x0 && x <= self.x1
    }

    /// The columns `c` of a row `width` wide with `contains_column(c as f32)`: a contiguous
    /// range because the test is monotonic in `c` (empty for NaN bounds).
    fn columns(&self, width: usize) -> Range<usize> {
        if self.x0.is_nan() || self.x1.is_nan() || self.x0 > self.x1 {
            return 0..0;
        }
        let first = if self.x0 <= 0.0 {
            0
        } else {
            (self.x0.ceil() as usize).min(width)
        };
        let end = if self.x1 >= width as f32 {
            width
        } else {
            (self.x1.floor() as usize + 1).max(first)
        };
        first..end
    }
}

/// Relative gap in inverse distance beyond which one plane is surely nearer than another
/// (rounding errs by around 1e-7).
const NEAREST_TOLERANCE: f64 = 1e-4;
/// Columns searched beyond where a plane is computed to stop being the nearest.
const NEAREST_MARGIN: f64 = 2.0;

/// Pixels per block of the loops written for vectorisation.
const LANES: usize = 8;

/// Marks a pixel whose ray meets no panel.
const NO_PANEL: u32 = u32::MAX;

/// Per-worker buffers for rendering rows: the columns' ray slopes, a row of ray directions
/// and the nearest panel along each.
pub struct RowScratch {
    ray_x: Vec<f32>,
    directions: RowDirections,
    nearest_depth: Vec<f32>,
    nearest_panel: Vec<u32>,
    row_panels: Vec<RowPanel>,
    active_objects: Vec<usize>,
}

/// A panel that may be the nearest along some rays of a row: its index and the columns (from
/// the first searched one) where its screen bounds put it.
struct RowPanel {
    index: usize,
    start: usize,
    end: usize,
}

/// World-frame ray directions of one row, one array per component so that loops over columns
/// vectorise.
struct RowDirections {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
}

impl RowDirections {
    fn new(width: usize) -> RowDirections {
        RowDirections {
            x: vec![0.0; width],
            y: vec![0.0; width],
            z: vec![0.0; width],
        }
    }

    /// The directions `rotation · ray(column, row)` of a row, from the columns' `ray_x` and
    /// the row's `ray_y` (as [`Snapshot::trace`] computes them).
    #[inline(always)]
    fn fill(&mut self, rotation: &Mat3, ray_x: &[f32], ray_y: f32) {
        // Zipped rather than indexed: without bounds checks the loop vectorises.
        let components = self.x.iter_mut().zip(&mut self.y).zip(&mut self.z);
        for (&x, ((dx, dy), dz)) in ray_x.iter().zip(components) {
            let direction = rotation.apply(Vec3::new(x, ray_y, 1.0));
            (*dx, *dy, *dz) = (direction.x, direction.y, direction.z);
        }
    }

    fn at(&self, column: usize) -> Vec3 {
        Vec3::new(self.x[column], self.y[column], self.z[column])
    }

    /// The directions of columns `start..start + 8`, one vector per component.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn block8(&self, start: usize) -> [std::arch::x86_64::__m256; 3] {
        [&self.x, &self.y, &self.z].map(|component| {
            std::arch::x86_64::_mm256_loadu_ps(component[start..start + 8].as_ptr())
        })
    }
}

impl<'a> Snapshot<'a> {
    pub fn new(scene: &'a Scene, t_s: f32) -> Snapshot<'a> {
        Snapshot::build(scene, t_s, true)
    }

    /// The static world alone at `t_s`, as if no object moved through it: what the moving
    /// objects occlude is still rendered (the simulator interpolates it between renders).
    pub fn static_world(scene: &'a Scene, t_s: f32) -> Snapshot<'a> {
        Snapshot::build(scene, t_s, false)
    }

    fn build(scene: &'a Scene, t_s: f32, with_objects: bool) -> Snapshot<'a> {
        let camera = scene.ego.pose(t_s);
        let drive = scene.ego.drive_offset(t_s);
        let object_count = if with_objects { scene.objects.len() } else { 0 };
        let objects = scene.objects[..object_count]
            .iter()
            .map(|object| {
                let pose = object.path.pose(t_s, drive);
                let corners = object.shape.corners().map(|c| pose.to_world(c));
                PlacedObject {
                    pose,
                    inverse_rotation: pose.rotation.transpose(),
                    local_camera: pose
                        .rotation
                        .transpose()
                        .apply(camera.translation - pose.translation),
                    log_illumination: [
                        Vec3::new(1.0, 0.0, 0.0),
                        Vec3::new(0.0, 1.0, 0.0),
                        Vec3::new(0.0, 0.0, 1.0),
                    ]
                    .map(|axis| log_illumination(scene, pose.rotation.apply(axis))),
                    bounds: ScreenBounds::of_points(scene, &camera, corners.into_iter()),
                    texels_per_m: 1.0 / object.texel_m,
                }
            })
            .collect();
        let panel_bounds = scene
            .panels
            .iter()
            .map(|panel| match panel.half_extent {
                None => ScreenBounds::EVERYWHERE,
                Some((hu, hv)) => {
                    let corners = [(-hu, -hv), (hu, -hv), (-hu, hv), (hu, hv)]
                        .map(|(u, v)| panel.origin + panel.axis_u * u + panel.axis_v * v);
                    ScreenBounds::of_points(scene, &camera, corners.into_iter())
                }
            })
            .collect();
        let panel_planes: Vec<PlanePlacement> = scene
            .panels
            .iter()
            .map(|panel| {
                let normal = panel.normal();
                PlanePlacement {
                    normal,
                    offset: normal.dot(panel.origin - camera.translation),
                    log_illumination: log_illumination(scene, normal),
                    texels_per_m: 1.0 / panel.texel_m,
                }
            })
            .collect();
        Snapshot {
            scene,
            camera,
            panel_constants: scene
                .panels
                .iter()
                .zip(&panel_planes)
                .map(|(panel, plane)| PanelConstants::new(panel, plane))
                .collect(),
            panel_planes,
            all_objects: (0..object_count).collect(),
            objects,
            panel_bounds,
        }
    }

    pub fn camera(&self) -> &RigidTransform {
        &self.camera
    }

    /// Pose of object `k` (1-based) at this instant.
    pub fn object_pose(&self, k: u16) -> &RigidTransform {
        &self.objects[k as usize - 1].pose
    }

    /// Renders rows `first_row..first_row + rows` into the given row-major slices.
    ///
    /// A row is rendered in passes over its columns: the panels are searched panel after
    /// panel, then the texture coordinates and footprint of every panel hit are computed, in
    /// plain loops that the compiler vectorises; the texture lookups follow, and the moving
    /// objects (within their bounds only) are intersected pixel by pixel and shaded in
    /// batches of eight. Every pixel still sees the same
    /// operations in the same order as [`Snapshot::trace`], so the output is bit-identical to
    /// tracing pixel by pixel.
    pub fn render_rows(
        &self,
        first_row: usize,
        log_intensity: &mut [f32],
        surface: &mut [u16],
        depth: &mut [f32],
    ) {
        self.render_rows_where_supported::<true, true>(
            first_row,
            log_intensity,
            surface,
            depth,
            &mut self.row_scratch(),
        );
    }

    /// The log intensity of [`Snapshot::render_rows`], bit for bit, without writing surface
    /// ids and depths: the static world's renders need only the intensity, and each frame's
    /// needless writes cost memory bandwidth, which limits the simulator.
    pub fn shade_rows(
        &self,
        first_row: usize,
        log_intensity: &mut [f32],
        scratch: &mut RowScratch,
    ) {
        self.render_rows_where_supported::<true, false>(
            first_row,
            log_intensity,
            &mut [],
            &mut [],
            scratch,
        );
    }

    /// The surface ids and depths of [`Snapshot::render_rows`], bit for bit, without shading
    /// (the texture lookups are most of a render's cost).
    pub fn locate_rows(
        &self,
        first_row: usize,
        surface: &mut [u16],
        depth: &mut [f32],
        scratch: &mut RowScratch,
    ) {
        self.render_rows_where_supported::<false, true>(
            first_row,
            &mut [],
            surface,
            depth,
            scratch,
        );
    }
}

/// Ambient plus Lambertian light on a surface with this normal (both sides lit), as a log.
fn log_illumination(scene: &Scene, normal: Vec3) -> f32 {
    let lambert = normal.dot(scene.light).abs();
    (scene.ambient + (1.0 - scene.ambient) * lambert).ln()
}

struct Material {
    texture: usize,
    texels_per_m: f32,
    u: f32,
    v: f32,
    normal: Vec3,
    log_illumination: f32,
}

/// Up to eight pixels' texture samples, taken together: by the atlas's 8-lane AVX2 sampler
/// where the CPU has AVX2 (the same bits as [`Texture::sample`](crate::texture::Texture)),
/// rather than one pixel's whole sample after another.
#[derive(Default)]
struct TexelBatch {
    pixels: [usize; 8],
    texture: [i32; 8],
    u: [f32; 8],
    v: [f32; 8],
    footprint: [f32; 8],
    log_illumination: [f32; 8],
    len: usize,
}

impl TexelBatch {
    /// Adds pixel `pixel`'s sample; true when the batch is full.
    fn push(&mut self, pixel: usize, texel: PanelTexel) -> bool {
        let k = self.len;
        self.pixels[k] = pixel;
        self.texture[k] = texel.texture as i32;
        self.u[k] = texel.u;
        self.v[k] = texel.v;
        self.footprint[k] = texel.footprint;
        self.log_illumination[k] = texel.log_illumination;
        self.len += 1;
        self.len == 8
    }

    /// Writes each pixel's log intensity (sample plus light) into `log_intensity` and empties
    /// the batch.
    fn shade_into(&mut self, scene: &Scene, log_intensity: &mut [f32]) {
        let len = std::mem::take(&mut self.len);
        if len == 0 {
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // Unused lanes repeat the first pixel's sample, which is valid.
            for k in len..8 {
                self.texture[k] = self.texture[0];
                self.u[k] = self.u[0];
                self.v[k] = self.v[0];
                self.footprint[k] = self.footprint[0];
            }
            // SAFETY: the CPU has AVX2 (checked above); the textures are the scene's.
            let sampled = unsafe {
                scene
                    .atlas
                    .sample8(&self.texture, &self.u, &self.v, &self.footprint)
            };
            for k in 0..len {
                log_intensity[self.pixels[k]] = sampled[k] + self.log_illumination[k];
            }
            return;
        }
        for k in 0..len {
            log_intensity[self.pixels[k]] = scene.textures[self.texture[k] as usize].sample(
                self.u[k],
                self.v[k],
                self.footprint[k],
            ) + self.log_illumination[k];
        }
    }
}

/// A surface's texture, the texel coordinates and footprint where a ray meets it, and its light.
struct PanelTexel {
    texture: usize,
    u: f32,
    v: f32,
    footprint: f32,
    log_illumination: f32,
}

/// [`PanelTexel`] for eight columns, and which of them meet no panel.
#[cfg(target_arch = "x86_64")]
struct PanelTexels8 {
    texture: std::arch::x86_64::__m256i,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
    footprint: std::arch::x86_64::__m256,
    log_illumination: std::arch::x86_64::__m256,
    /// All bits set in the lanes that meet no panel.
    dark: std::arch::x86_64::__m256,
}

/// [`ObjectHit`]s of eight rays: id 0 where no object is met.
#[cfg(target_arch = "x86_64")]
struct ObjectHits8 {
    id: std::arch::x86_64::__m256i,
    depth: std::arch::x86_64::__m256,
    texture: std::arch::x86_64::__m256i,
    texels_per_m: std::arch::x86_64::__m256,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
    normal: [std::arch::x86_64::__m256; 3],
    log_illumination: std::arch::x86_64::__m256,
}

/// A moving object met by a ray: its id, the object-local point, depth and surface.
struct ObjectHit {
    id: u16,
    point: Vec3,
    depth: f32,
    material: Material,
}

struct LocalHit {
    distance: f32,
    u: f32,
    v: f32,
    /// ± the unit vector of local axis `axis`.
    normal: Vec3,
    axis: usize,
}

fn intersect_shape(shape: &Shape, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    match *shape {
        Shape::Cuboid { half } => intersect_cuboid(half, origin, direction),
        Shape::Ellipse { half_x, half_y } => intersect_plate(origin, direction, |x, y| {
            let (nx, ny) = (x / half_x, y / half_y);
            nx * nx + ny * ny <= 1.0
        }),
        Shape::Cutout(silhouette) => {
            intersect_plate(origin, direction, |x, y| silhouette.contains(x, y))
        }
    }
}

/// A flat object in the local x–y plane, whose outline holds the points where `inside` is true.
fn intersect_plate(
    origin: Vec3,
    direction: Vec3,
    inside: impl Fn(f32, f32) -> bool,
) -> Option<LocalHit> {
    if direction.z.abs() < 1e-9 {
        return None;
    }
    let distance = -origin.z / direction.z;
    let p = origin + direction * distance;
    (distance > NEAR_PLANE_M && inside(p.x, p.y)).then_some(LocalHit {
        distance,
        u: p.x,
        v: p.y,
        normal: Vec3::new(0.0, 0.0, 1.0),
        axis: 2,
    })
}

/// Slab test; the texture coordinates of a face are its two in-plane coordinates, shifted per
/// face so the six faces do not show the same patch.
fn intersect_cuboid(half: Vec3, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    let mut near = f32::MIN;
    let mut far = f32::MAX;
    let mut near_axis = 0;
    for axis in 0..3 {
        let (o, d, h) = (origin.axis(axis), direction.axis(axis), half.axis(axis));
        if d.abs() < 1e-12 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d;
        let (a, b) = ((-h - o) * inv, (h - o) * inv);
        let (t0, t1) = if a < b { (a, b) } else { (b, a) };
        if t0 > near {
            near = t0;
            near_axis = axis;
        }
        far = far.min(t1);
    }
    if near > far || near <= NEAR_PLANE_M {
        return None;
    }
    let p = origin + direction * near;
    let sign = if direction.axis(near_axis) > 0.0 {
        -1.0
    } else {
        1.0
    };
    let mut normal = Vec3::default();
    let face_offset = (near_axis as f32 * 2.0 + if sign > 0.0 { 1.0 } else { 0.0 }) * 0.73;
    let (u, v) = match near_axis {
        0 => {
            normal.x = sign;
            (p.z, p.y)
        }
        1 => {
            normal.y = sign;
            (p.x, p.z)
        }
        _ => {
            normal.z = sign;
            (p.x, p.y)
        }
    };
    Some(LocalHit {
        distance: near,
        u: u + face_offset,
        v: v + face_offset,
        normal,
        axis: near_axis,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ObjectVariation;
    use crate::preset::Preset;
    use crate::world::build_scene;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn rendering_whole_rows_and_locating_match_tracing_each_pixel_bit_for_bit() {
        for preset in [
            Preset::Boxes,
            Preset::Fast,
            Preset::Wall,
            Preset::Table,
            Preset::Driving,
        ] {
            let config = preset.config().at_reduced_resolution(4);
            let scene = build_scene(&config, &[], &mut ChaCha8Rng::seed_from_u64(4));
            let (width, height) = (config.sensor.width as usize, config.sensor.height as usize);
            for t_s in [0.0, 0.37, 1.3, 2.2] {
                let snapshot = Snapshot::new(&scene, t_s);
                let mut frame = Frame::new(width * height);
                snapshot.render_rows(
                    0,
                    &mut frame.log_intensity,
                    &mut frame.surface,
                    &mut frame.depth,
                );
                let (mut surface, mut depth) = (vec![0; width * height], vec![0.0; width * height]);
                snapshot.locate_rows(0, &mut surface, &mut depth, &mut snapshot.row_scratch());
                let mut shaded = vec![0.0f32; width * height];
                snapshot.shade_rows(0, &mut shaded, &mut snapshot.row_scratch());
                assert!(shaded
                    .iter()
                    .zip(&frame.log_intensity)
                    .all(|(a, b)| a.to_bits() == b.to_bits()));
                let static_world = Snapshot::static_world(&scene, t_s);
                for y in 0..height {
                    for x in 0..width {
                        let hit = snapshot.trace(x as f32, y as f32);
                        let i = y * width + x;
                        // Ground truth located without shading: the same surfaces and points.
                        let located = snapshot.locate(x as f32, y as f32);
                        assert_eq!(
                            (located.surface, located.point, located.depth.to_bits()),
                            (hit.surface, hit.point, hit.depth.to_bits())
                        );
                        assert_eq!(
                            (surface[i], depth[i].to_bits()),
                            (hit.surface, hit.depth.to_bits())
                        );
                        let behind_objects = static_world.trace(x as f32, y as f32);
                        assert_eq!(
                            static_world.static_point(x as f32, y as f32),
                            behind_objects
                                .depth
                                .is_finite()
                                .then_some(behind_objects.point)
                        );
                        assert_eq!(
                            (
                                frame.log_intensity[i].to_bits(),
                                frame.surface[i],
                                frame.depth[i].to_bits()
                            ),
                            (
                                hit.log_intensity.to_bits(),
                                hit.surface,
                                hit.depth.to_bits()
                            ),
                            "{preset} at {t_s} s, pixel ({x}, {y})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_rooms_walls_are_searched_about_once_per_pixel() {
        let config = Preset::Fast.config();
        let scene = build_scene(&config, &[], &mut ChaCha8Rng::seed_from_u64(4));
        let (width, height) = (config.sensor.width as usize, config.sensor.height as usize);
        for t_s in [0.0, 0.37, 1.3] {
            let snapshot = Snapshot::static_world(&scene, t_s);
            let mut scratch = snapshot.row_scratch();
            let (mut searched, mut walls) = (0, 0);
            for y in 0..height {
                snapshot.nearest_panels(y as f32, 0..width, &mut scratch);
                for row_panel in &scratch.row_panels {
                    if scene.panels[row_panel.index].half_extent.is_none() {
                        searched += row_panel.end - row_panel.start;
                        walls += 1;
                    }
                }
            }
            // Each wall is searched a few columns beyond where it stops being the nearest.
            let margins = walls * 2 * (NEAREST_MARGIN as usize + 2);
            assert!(
                searched <= width * height + margins,
                "at {t_s} s: {searched} wall columns searched for {} pixels",
                width * height
            );
        }
    }

    #[test]
    fn overlaying_objects_matches_tracing_bit_for_bit() {
        let (mut cuboid_pixels, mut ellipse_pixels, mut cutout_pixels) = (0, 0, 0);
        let cutouts = ObjectVariation {
            cutout_share: 0.7,
            ..ObjectVariation::default()
        };
        for (preset, variation) in [
            (Preset::Boxes, ObjectVariation::default()),
            (Preset::Fast, ObjectVariation::default()),
            (Preset::Tabletop, ObjectVariation::default()),
            (Preset::Wall, cutouts),
            (Preset::Tabletop, cutouts),
        ] {
            let mut config = preset.config().at_reduced_resolution(2);
            config.scene.variation = variation;
            let (width, height) = (config.sensor.width as usize, config.sensor.height as usize);
            for seed in [4, 9, 13] {
                let scene = build_scene(&config, &[], &mut ChaCha8Rng::seed_from_u64(seed));
                for t_s in [0.0, 0.37, 1.3, 2.2] {
                    let snapshot = Snapshot::new(&scene, t_s);
                    let static_world = Snapshot::static_world(&scene, t_s);
                    let mut scratch = snapshot.row_scratch();
                    // Whole rows, and a range that starts and ends off the 8-pixel blocks.
                    for columns in [0..width, 3..width - 5] {
                        for y in 0..height {
                            let mut row = vec![0.0f32; width];
                            static_world.shade_rows(y, &mut row, &mut scratch);
                            let mut log = row[columns.clone()].to_vec();
                            let mut surface = vec![0u16; columns.len()];
                            snapshot.overlay_objects(
                                y,
                                columns.clone(),
                                &mut log,
                                &mut surface,
                                &mut scratch,
                            );
                            for (k, x) in columns.clone().enumerate() {
                                let hit = snapshot.trace(x as f32, y as f32);
                                assert_eq!(
                                    (log[k].to_bits(), surface[k]),
                                    (hit.log_intensity.to_bits(), hit.surface),
                                    "{preset} seed {seed} at {t_s} s, pixel ({x}, {y})"
                                );
                                if hit.surface != 0 {
                                    match scene.objects[hit.surface as usize - 1].shape {
                                        Shape::Cuboid { .. } => cuboid_pixels += 1,
                                        Shape::Ellipse { .. } => ellipse_pixels += 1,
                                        Shape::Cutout(_) => cutout_pixels += 1,
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(
            cuboid_pixels > 1000 && ellipse_pixels > 500 && cutout_pixels > 500,
            "{cuboid_pixels}, {ellipse_pixels}, {cutout_pixels}"
        );
    }

    #[test]
    fn cuboid_hit_from_the_front_reports_front_face() {
        let hit = intersect_cuboid(
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(0.0, 0.0, -5.0),
            Vec3::new(0.0, 0.0, 1.0),
        )
        .unwrap();
        assert!((hit.distance - 4.0).abs() < 1e-5);
        assert_eq!(hit.normal, Vec3::new(0.0, 0.0, -1.0));
    }

    #[test]
    fn cuboid_missed_to_the_side() {
        assert!(intersect_cuboid(
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(2.0, 0.0, -5.0),
            Vec3::new(0.0, 0.0, 1.0)
        )
        .is_none());
    }

    #[test]
    fn ellipse_hit_inside_only() {
        let shape = Shape::Ellipse {
            half_x: 1.0,
            half_y: 0.5,
        };
        let down = Vec3::new(0.0, 0.0, 1.0);
        assert!(intersect_shape(&shape, Vec3::new(0.9, 0.0, -1.0), down).is_some());
        assert!(intersect_shape(&shape, Vec3::new(0.0, 0.6, -1.0), down).is_none());
    }
}
