//! Ray casting of a scene at one instant: log intensity, surface id and depth per pixel, by
//! ray–plane and ray–box intersection with a pinhole camera (so camera translation produces
//! parallax and objects occlude by depth).

use std::ops::Range;

use crate::camera::project_world;
#[cfg(target_arch = "x86_64")]
use crate::index_lanes::checked_first_and_uniform;
use crate::linalg::{Mat3, RigidTransform, Vec3};
use crate::scene::{Panel, Scene, Shape};

/// Log intensity of a ray that hits nothing (darker than any lit texel).
const LOG_DARK: f32 = -6.0;

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

    /// [`Snapshot::render_rows_portable`] in its AVX2 build where the CPU has AVX2.
    fn render_rows_where_supported<const SHADE: bool, const LOCATE: bool>(
        &self,
        first_row: usize,
        log_intensity: &mut [f32],
        surface: &mut [u16],
        depth: &mut [f32],
        scratch: &mut RowScratch,
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe {
                self.render_rows_avx2::<SHADE, LOCATE>(
                    first_row,
                    log_intensity,
                    surface,
                    depth,
                    scratch,
                )
            };
            return;
        }
        self.render_rows_portable::<false, SHADE, LOCATE>(
            first_row,
            log_intensity,
            surface,
            depth,
            scratch,
        );
    }

    /// [`Snapshot::render_rows_portable`] compiled for AVX2, whose 8-lane vectors double the
    /// width of the vectorised passes, with textures sampled eight pixels at a time from the
    /// atlas. Without FMA (Rust never fuses on its own) every operation rounds as in the
    /// portable build: the output is the same bit for bit.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn render_rows_avx2<const SHADE: bool, const LOCATE: bool>(
        &self,
        first_row: usize,
        log_intensity: &mut [f32],
        surface: &mut [u16],
        depth: &mut [f32],
        scratch: &mut RowScratch,
    ) {
        self.render_rows_portable::<true, SHADE, LOCATE>(
            first_row,
            log_intensity,
            surface,
            depth,
            scratch,
        );
    }

    /// With `GATHER`, only for callers compiled for AVX2 on a CPU that has it. Without
    /// `SHADE`, `log_intensity` is not touched (and may be empty); without `LOCATE`, neither
    /// are `surface` and `depth`.
    #[inline(always)]
    fn render_rows_portable<const GATHER: bool, const SHADE: bool, const LOCATE: bool>(
        &self,
        first_row: usize,
        log_intensity: &mut [f32],
        surface: &mut [u16],
        depth: &mut [f32],
        scratch: &mut RowScratch,
    ) {
        let width = self.scene.sensor.width as usize;
        let rows = if LOCATE {
            surface.len()
        } else {
            log_intensity.len()
        } / width;
        for row in 0..rows {
            let y = (first_row + row) as f32;
            let pixels = row * width..(row + 1) * width;
            self.nearest_panels(y, 0..width, scratch);
            if SHADE {
                self.shade_panels::<GATHER>(scratch, &mut log_intensity[pixels.clone()]);
            }
            if LOCATE {
                surface[pixels.clone()].fill(0);
                depth[pixels.clone()].copy_from_slice(&scratch.nearest_depth[..width]);
            }
            scratch.active_objects.clear();
            scratch.active_objects.extend(
                (0..self.objects.len()).filter(|&i| self.objects[i].bounds.contains_row(y)),
            );
            let Some(columns) = scratch
                .active_objects
                .iter()
                .map(|&i| self.objects[i].bounds.columns(width))
                .filter(|columns| !columns.is_empty())
                .reduce(|a, b| a.start.min(b.start)..a.end.max(b.end))
            else {
                continue;
            };
            let mut batch = TexelBatch::default();
            for column in columns {
                let direction = scratch.directions.at(column);
                if let Some(hit) = self.nearest_object(
                    column as f32,
                    direction,
                    scratch.nearest_depth[column],
                    &scratch.active_objects,
                ) {
                    let i = pixels.start + column;
                    if LOCATE {
                        surface[i] = hit.id;
                        depth[i] = hit.depth;
                    }
                    if SHADE
                        && batch.push(i, self.material_texel(&hit.material, direction, hit.depth))
                    {
                        batch.shade_into(self.scene, log_intensity);
                    }
                }
            }
            if SHADE {
                batch.shade_into(self.scene, log_intensity);
            }
        }
    }

    /// Log intensity of the nearest panel along each ray of the row searched by
    /// [`Snapshot::nearest_panels`] (dark where there is none): what `nearest_surface` and
    /// `shade` compute, pixel by pixel without the objects.
    #[inline(always)]
    fn shade_panels<const GATHER: bool>(&self, scratch: &RowScratch, log_intensity: &mut [f32]) {
        if GATHER {
            for (start, block) in (0..).step_by(8).zip(log_intensity.chunks_mut(8)) {
                // The row's last block may be partial: its lanes past the row end are dark
                // (the search arrays are padded to whole blocks) and are not kept.
                let mut partial = [0.0f32; 8];
                let lanes = if block.len() == 8 {
                    &mut block[..]
                } else {
                    &mut partial[..]
                };
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `GATHER` is set only by `render_rows_avx2`, which runs where the CPU
                // has AVX2.
                unsafe {
                    self.shade_panels8(scratch, start, lanes)
                };
                #[cfg(not(target_arch = "x86_64"))]
                unreachable!("GATHER is set only by the x86-64 AVX2 build");
                if block.len() < 8 {
                    let kept = block.len();
                    block.copy_from_slice(&partial[..kept]);
                }
            }
            return;
        }
        for (c, log) in log_intensity.iter_mut().enumerate() {
            *log = match self.panel_texel(scratch, c) {
                None => LOG_DARK,
                Some(texel) => {
                    self.scene.textures[texel.texture].sample(texel.u, texel.v, texel.footprint)
                        + texel.log_illumination
                }
            };
        }
    }

    /// [`Snapshot::shade_panels`] for columns `start..start + 8` (`log_intensity`), in vector
    /// registers from the panels to the store.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn shade_panels8(&self, scratch: &RowScratch, start: usize, log_intensity: &mut [f32]) {
        use std::arch::x86_64::*;
        assert_eq!(log_intensity.len(), 8);
        let texels = self.panel_texels8(scratch, start);
        // SAFETY: the lanes' textures are the scene's panels' textures.
        let sampled =
            self.scene
                .atlas
                .sample8_lanes(texels.texture, texels.u, texels.v, texels.footprint);
        let lit = _mm256_add_ps(sampled, texels.log_illumination);
        // SAFETY: `log_intensity` has eight values (asserted).
        _mm256_storeu_ps(
            log_intensity.as_mut_ptr(),
            _mm256_blendv_ps(lit, _mm256_set1_ps(LOG_DARK), texels.dark),
        );
    }

    /// [`Snapshot::panel_texel`] for columns `start..start + 8` at once.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn panel_texels8(&self, scratch: &RowScratch, start: usize) -> PanelTexels8 {
        use std::arch::x86_64::*;
        let block = start..start + 8;
        let id = _mm256_loadu_si256(scratch.nearest_panel[block.clone()].as_ptr().cast());
        let dark = _mm256_cmpeq_epi32(id, _mm256_set1_epi32(NO_PANEL as i32));
        let panel = _mm256_andnot_si256(dark, id);
        // Most blocks lie on one panel: their constants are loaded once and broadcast rather
        // than gathered lane by lane (the same values, hence the same bits).
        let (first, uniform) =
            checked_first_and_uniform(panel, self.panel_constants.len(), "panel");
        let record = &self.panel_constants[first].0;
        let base = self.panel_constants.as_ptr().cast::<f32>();
        let stride_index = _mm256_mullo_epi32(panel, _mm256_set1_epi32(PANEL_FIELDS as i32));
        // SAFETY (gathers): every lane's panel index is below the panel count (asserted), and
        // each field lies within its record.
        let gather = |field: usize| {
            if uniform {
                _mm256_set1_ps(record[field])
            } else {
                _mm256_i32gather_ps::<4>(
                    base,
                    _mm256_add_epi32(stride_index, _mm256_set1_epi32(field as i32)),
                )
            }
        };
        let [dx, dy, dz] = scratch.directions.block8(block.start);
        let t = _mm256_loadu_ps(scratch.nearest_depth[block].as_ptr());
        let camera = self.camera.translation;
        // relative = camera + direction · t − panel origin, per component.
        let relative = |camera: f32, direction: __m256, origin: usize| {
            _mm256_sub_ps(
                _mm256_add_ps(_mm256_set1_ps(camera), _mm256_mul_ps(direction, t)),
                gather(origin),
            )
        };
        let (rx, ry, rz) = (
            relative(camera.x, dx, field::ORIGIN),
            relative(camera.y, dy, field::ORIGIN + 1),
            relative(camera.z, dz, field::ORIGIN + 2),
        );
        let axis = |first: usize| [gather(first), gather(first + 1), gather(first + 2)];
        let relative = [rx, ry, rz];
        let texels_per_m = gather(field::TEXELS_PER_M);
        let metres_per_pixel = self.metres_per_pixel8(axis(field::NORMAL), [dx, dy, dz], t);
        let dark_ps = _mm256_castsi256_ps(dark);
        // Dark lanes read texel (0, 0) of the panel-0 texture at level 0; their value is
        // replaced by the dark level.
        let or_zero = |value: __m256| _mm256_andnot_ps(dark_ps, value);
        PanelTexels8 {
            texture: _mm256_castps_si256(gather(field::TEXTURE)),
            u: or_zero(_mm256_mul_ps(
                dot8(relative, axis(field::AXIS_U)),
                texels_per_m,
            )),
            v: or_zero(_mm256_mul_ps(
                dot8(relative, axis(field::AXIS_V)),
                texels_per_m,
            )),
            footprint: _mm256_blendv_ps(
                _mm256_mul_ps(metres_per_pixel, texels_per_m),
                _mm256_set1_ps(1.0),
                dark_ps,
            ),
            log_illumination: gather(field::LOG_ILLUMINATION),
            dark: dark_ps,
        }
    }

    /// Where the ray of column `c` (searched by [`Snapshot::nearest_panels`]) meets its
    /// nearest panel, in texture terms: what `nearest_surface` and `shade` compute.
    #[inline(always)]
    fn panel_texel(&self, scratch: &RowScratch, c: usize) -> Option<PanelTexel> {
        let i = scratch.nearest_panel[c];
        if i == NO_PANEL {
            return None;
        }
        let (panel, plane) = (
            &self.scene.panels[i as usize],
            &self.panel_planes[i as usize],
        );
        let direction = scratch.directions.at(c);
        let distance = scratch.nearest_depth[c];
        let relative = self.camera.translation + direction * distance - panel.origin;
        let metres_per_pixel = self.metres_per_pixel(plane.normal, direction, distance);
        let tpm = plane.texels_per_m;
        Some(PanelTexel {
            texture: panel.texture,
            u: relative.dot(panel.axis_u) * tpm,
            v: relative.dot(panel.axis_v) * tpm,
            footprint: metres_per_pixel * tpm,
            log_illumination: plane.log_illumination,
        })
    }

    /// Buffers for rendering rows of this snapshot's sensor, allocated once per worker.
    pub fn row_scratch(&self) -> RowScratch {
        let width = self.scene.sensor.width as usize;
        let intrinsics = &self.scene.intrinsics;
        RowScratch {
            ray_x: (0..width)
                .map(|column| intrinsics.ray(column as f32, 0.0).x)
                .collect(),
            // Whole blocks of `LANES` columns: the panel search's last block reads past the
            // sensor's last column (its lanes there are never eligible).
            directions: RowDirections::new(width.div_ceil(LANES) * LANES),
            nearest_depth: vec![f32::INFINITY; width.div_ceil(LANES) * LANES],
            nearest_panel: vec![NO_PANEL; width.div_ceil(LANES) * LANES],
            row_panels: Vec::with_capacity(self.scene.panels.len()),
            active_objects: Vec::with_capacity(self.objects.len()),
        }
    }

    /// Fills `scratch` with the ray directions of `columns` of row `y` (from index 0) and the
    /// nearest panel along each.
    #[inline(always)]
    fn nearest_panels(&self, y: f32, columns: Range<usize>, scratch: &mut RowScratch) {
        let width = self.scene.sensor.width as usize;
        let n = columns.len();
        let ray_y = self.scene.intrinsics.ray(0.0, y).y;
        scratch.directions.fill(
            &self.camera.rotation,
            &scratch.ray_x[columns.clone()],
            ray_y,
        );
        scratch.row_panels.clear();
        for (i, bounds) in self.panel_bounds.iter().enumerate() {
            if bounds.contains_row(y) {
                let on_panel = bounds.columns(width);
                let start = on_panel.start.max(columns.start);
                let end = on_panel.end.min(columns.end);
                if start >= end {
                    continue;
                }
                let local = start - columns.start..end - columns.start;
                let in_front = self.columns_in_front(i, &scratch.directions, local);
                if !in_front.is_empty() {
                    scratch.row_panels.push(RowPanel {
                        index: i,
                        start: in_front.start,
                        end: in_front.end,
                    });
                }
            }
        }
        self.narrow_unbounded_panels(&scratch.directions, n, &mut scratch.row_panels);
        self.nearest_on_panels(
            &scratch.directions,
            &scratch.row_panels,
            &mut scratch.nearest_depth[..n.div_ceil(LANES) * LANES],
            &mut scratch.nearest_panel[..n.div_ceil(LANES) * LANES],
        );
    }

    /// The part of `columns` (non-empty, of one row) whose rays may meet panel `i`'s plane in
    /// front of the camera: the others cannot hit the panel. `n·d` is linear along a row, so
    /// its sign changes at most once, and the distance `offset / n·d` is negative where the
    /// signs of offset and `n·d` differ. Columns next to the change are kept, as are all where
    /// `n·d` is near zero at an end or changes too slowly to place the change: there rounding
    /// could flip a sign. A room's walls each face only part of a row; their other part was
    /// tested pixel by pixel for nothing.
    #[inline(always)]
    fn columns_in_front(
        &self,
        i: usize,
        directions: &RowDirections,
        columns: Range<usize>,
    ) -> Range<usize> {
        /// Columns kept beyond the computed sign change, far more than its error (below
        /// 0.1 column with the slopes accepted).
        const MARGIN: usize = 2;
        let plane = &self.panel_planes[i];
        let (start, last_column) = (columns.start, columns.end - 1);
        let first = plane.normal.dot(directions.at(start));
        let last = plane.normal.dot(directions.at(last_column));
        if !(first.abs() > 1e-4 && last.abs() > 1e-4) {
            return columns;
        }
        let behind = |dot: f32| plane.offset * dot < 0.0;
        match (behind(first), behind(last)) {
            (false, false) => columns,
            (true, true) => start..start,
            (first_behind, _) => {
                let span = (last_column - start) as f32;
                if (last - first).abs() / span < 1e-5 {
                    return columns;
                }
                let change = start as f32 + span * first / (first - last);
                if first_behind {
                    (change.floor() as usize).saturating_sub(MARGIN).max(start)..columns.end
                } else {
                    start..(change.ceil() as usize + MARGIN).min(columns.end)
                }
            }
        }
    }

    /// Narrows each unbounded panel of a row (columns `0..n` of `directions`) to the columns
    /// where it may be the nearest of the row's unbounded panels. A plane's inverse distance
    /// `n·d / offset` is linear along a row, so of two planes one is the nearer on one side of
    /// a column and the other beyond it: a room's walls each win one stretch of a row, and
    /// elsewhere their search was wasted. A panel is dropped only from columns where another
    /// one in front of the camera is nearer by a relative [`NEAREST_TOLERANCE`], far beyond
    /// rounding, and [`NEAREST_MARGIN`] columns more are kept: the nearest panel is found as
    /// before, with the same distance bits, and no dropped panel could have tied with it.
    #[inline(always)]
    fn narrow_unbounded_panels(
        &self,
        directions: &RowDirections,
        n: usize,
        row_panels: &mut Vec<RowPanel>,
    ) {
        /// Planes nearer than this (metres) leave the row as it is: a ray accepts only hits
        /// beyond 1 mm, and a plane too near might be skipped there.
        const NEAREST_PLANE_M: f32 = 0.01;
        const MOST_PLANES: usize = 16;
        if n < 2 {
            return;
        }
        let (first, last) = (directions.at(0), directions.at(n - 1));
        let inverse_distance = |normal: Vec3, offset: f32, d: Vec3| {
            (normal.x as f64 * d.x as f64
                + normal.y as f64 * d.y as f64
                + normal.z as f64 * d.z as f64)
                / offset as f64
        };
        // Per unbounded plane of the row: its place in `row_panels` and its inverse distance at
        // the row's first and last column.
        let mut planes = [(0usize, 0.0f64, 0.0f64); MOST_PLANES];
        let mut count = 0;
        for (k, row_panel) in row_panels.iter().enumerate() {
            if self.scene.panels[row_panel.index].half_extent.is_some() {
                continue;
            }
            let plane = &self.panel_planes[row_panel.index];
            // NaN offsets fail the comparison too.
            let far_enough = plane.offset.abs() > NEAREST_PLANE_M;
            if count == MOST_PLANES || !far_enough {
                return;
            }
            planes[count] = (
                k,
                inverse_distance(plane.normal, plane.offset, first),
                inverse_distance(plane.normal, plane.offset, last),
            );
            count += 1;
        }
        if count < 2 {
            return;
        }
        let planes = &planes[..count];
        let span = (n - 1) as f64;
        for &(k, start_j, end_j) in planes {
            // Where the others leave plane j a chance: `low..=high`, in columns.
            let (mut low, mut high) = (0.0f64, span);
            for &(other, start_i, end_i) in planes {
                if other == k {
                    continue;
                }
                let tolerance = NEAREST_TOLERANCE
                    * start_i
                        .abs()
                        .max(end_i.abs())
                        .max(start_j.abs())
                        .max(end_j.abs());
                // Plane i is surely the nearer where this is positive (linear along the row).
                let (at_start, at_end) = (start_i - start_j - tolerance, end_i - end_j - tolerance);
                match (at_start > 0.0, at_end > 0.0) {
                    (true, true) => {
                        low = f64::INFINITY;
                        break;
                    }
                    (false, false) => {}
                    (true, false) => low = low.max(span * at_start / (at_start - at_end)),
                    (false, true) => high = high.min(span * at_start / (at_start - at_end)),
                }
            }
            let row_panel = &mut row_panels[k];
            let keep_from = (low - NEAREST_MARGIN).floor().max(0.0);
            let keep_to = (high + NEAREST_MARGIN).ceil() + 1.0;
            if keep_from >= keep_to {
                row_panel.end = row_panel.start;
            } else {
                row_panel.start = row_panel.start.max(keep_from as usize);
                row_panel.end = row_panel
                    .end
                    .min(keep_to.min(n as f64) as usize)
                    .max(row_panel.start);
            }
        }
        row_panels.retain(|row_panel| row_panel.start < row_panel.end);
    }

    /// Draws the moving objects over `columns` of row `row`, whose static-world log intensity
    /// `log_intensity` holds (and `surface` zeros): wherever an object is nearer than every
    /// panel, its shaded log intensity and id replace them. Pixel for pixel the same objects,
    /// depths and shading as [`Snapshot::trace`].
    pub fn overlay_objects(
        &self,
        row: usize,
        columns: Range<usize>,
        log_intensity: &mut [f32],
        surface: &mut [u16],
        scratch: &mut RowScratch,
    ) {
        let y = row as f32;
        scratch.active_objects.clear();
        scratch
            .active_objects
            .extend((0..self.objects.len()).filter(|&i| self.objects[i].bounds.contains_row(y)));
        if scratch.active_objects.is_empty() {
            return;
        }
        let first_column = columns.start;
        self.nearest_panels(y, columns, scratch);
        // Whole blocks of eight pixels in vector registers where the CPU has AVX2, the rest
        // pixel by pixel (the same operations either way).
        let mut blocks_end = 0;
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            blocks_end = surface.len() / LANES * LANES;
            for k in (0..blocks_end).step_by(LANES) {
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe {
                    self.overlay_objects8(
                        first_column + k,
                        scratch,
                        k,
                        &mut log_intensity[k..k + LANES],
                        &mut surface[k..k + LANES],
                    )
                };
            }
        }
        let mut batch = TexelBatch::default();
        for (k, id) in surface.iter_mut().enumerate().skip(blocks_end) {
            let direction = scratch.directions.at(k);
            if let Some(hit) = self.nearest_object(
                (first_column + k) as f32,
                direction,
                scratch.nearest_depth[k],
                &scratch.active_objects,
            ) {
                *id = hit.id;
                if batch.push(k, self.material_texel(&hit.material, direction, hit.depth)) {
                    batch.shade_into(self.scene, log_intensity);
                }
            }
        }
        batch.shade_into(self.scene, log_intensity);
    }

    /// Widens `region` (one column range per sensor row; empty where nothing is marked) to
    /// the hull of itself and every pixel any moving object may cover at this instant.
    pub fn extend_object_region(&self, region: &mut [Range<usize>]) {
        let width = self.scene.sensor.width as usize;
        for object in &self.objects {
            let bounds = object.bounds;
            let columns = bounds.columns(width);
            if columns.is_empty() || bounds.y0.is_nan() || bounds.y1.is_nan() {
                continue;
            }
            let first_row = if bounds.y0 <= 0.0 {
                0
            } else {
                (bounds.y0.ceil() as usize).min(region.len())
            };
            let end_row = if bounds.y1 >= region.len() as f32 {
                region.len()
            } else {
                (bounds.y1.floor() as usize + 1).max(first_row)
            };
            for range in &mut region[first_row..end_row] {
                *range = if range.start >= range.end {
                    columns.clone()
                } else {
                    range.start.min(columns.start)..range.end.max(columns.end)
                };
            }
        }
    }

    /// The nearest of `panels` along each ray in `directions` (and its depth), or
    /// [`NO_PANEL`] (at infinity), for whole blocks of [`LANES`] columns
    /// (`nearest_depth.len()` a multiple of it; columns beyond the panels' ranges are never
    /// eligible): the per-pixel test of [`Snapshot::trace`], panel after panel in index order,
    /// in AVX2 where the CPU has it.
    #[inline(always)]
    fn nearest_on_panels(
        &self,
        directions: &RowDirections,
        panels: &[RowPanel],
        nearest_depth: &mut [f32],
        nearest_panel: &mut [u32],
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe {
                self.nearest_in_blocks_avx2(directions, panels, nearest_depth, nearest_panel)
            };
            return;
        }
        self.nearest_in_blocks(directions, panels, nearest_depth, nearest_panel);
    }

    /// [`Snapshot::nearest_on_panels`] without AVX2, written without branches so that it
    /// vectorises. Eight pixels at a time keep their nearest depth and panel in registers over
    /// all panels and store them once: a pass per panel over the row stored them back after
    /// every panel, which LLVM compiled to masked stores, slow on AMD Zen.
    #[inline(always)]
    fn nearest_in_blocks(
        &self,
        directions: &RowDirections,
        panels: &[RowPanel],
        nearest_depth: &mut [f32],
        nearest_panel: &mut [u32],
    ) {
        let blocks = nearest_depth.len();
        let (xs, ys, zs) = (&directions.x, &directions.y, &directions.z);
        let origin = self.camera.translation;
        for start in (0..blocks).step_by(LANES) {
            let block = start..start + LANES;
            let (bx, by, bz) = (&xs[block.clone()], &ys[block.clone()], &zs[block.clone()]);
            let mut depth = [f32::INFINITY; LANES];
            let mut id = [NO_PANEL; LANES];
            for row_panel in panels {
                if row_panel.end <= start || row_panel.start >= block.end {
                    continue;
                }
                let i = row_panel.index;
                let plane = &self.panel_planes[i];
                let mut distance = [0.0f32; LANES];
                for k in 0..LANES {
                    distance[k] = plane.offset / plane.normal.dot(Vec3::new(bx[k], by[k], bz[k]));
                }
                // Lanes of columns outside the panel's bounds, or off a bounded panel, keep
                // what they have.
                let mut eligible = [true; LANES];
                for (k, eligible) in eligible.iter_mut().enumerate() {
                    let column = start + k;
                    *eligible = (column >= row_panel.start) & (column < row_panel.end);
                }
                let panel = &self.scene.panels[i];
                if let Some((hu, hv)) = panel.half_extent {
                    for k in 0..LANES {
                        let direction = Vec3::new(bx[k], by[k], bz[k]);
                        let relative = origin + direction * distance[k] - panel.origin;
                        // Non-short-circuit `&` and `|` keep the loop free of branches.
                        eligible[k] &= !((relative.dot(panel.axis_u).abs() > hu)
                            | (relative.dot(panel.axis_v).abs() > hv));
                    }
                }
                for k in 0..LANES {
                    let closer = (distance[k] > 1e-3) & (distance[k] < depth[k]) & eligible[k];
                    let mask = (closer as u32).wrapping_neg();
                    depth[k] = f32::from_bits(
                        (distance[k].to_bits() & mask) | (depth[k].to_bits() & !mask),
                    );
                    id[k] = (i as u32 & mask) | (id[k] & !mask);
                }
            }
            nearest_depth[block.clone()].copy_from_slice(&depth);
            nearest_panel[block].copy_from_slice(&id);
        }
    }

    /// [`Snapshot::nearest_in_blocks`] in AVX2 intrinsics: the same operations in the same
    /// order (hence the same bits), with the lanes' column tests and selections as vector
    /// compares and blends, which the compiler did not find (it built the masks byte by byte).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn nearest_in_blocks_avx2(
        &self,
        directions: &RowDirections,
        panels: &[RowPanel],
        nearest_depth: &mut [f32],
        nearest_panel: &mut [u32],
    ) {
        use std::arch::x86_64::*;
        let blocks = nearest_depth.len();
        assert!(
            blocks.is_multiple_of(LANES)
                && directions.x.len() >= blocks
                && directions.y.len() >= blocks
                && directions.z.len() >= blocks
                && nearest_panel.len() == blocks
        );
        let origin = self.camera.translation;
        let lane_offsets = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let sign = _mm256_set1_ps(-0.0);
        let near_limit = _mm256_set1_ps(1e-3);
        for start in (0..blocks).step_by(LANES) {
            let end = start + LANES;
            // SAFETY (loads and stores): `start..end` lies within every slice (asserted).
            let dx = _mm256_loadu_ps(directions.x.as_ptr().add(start));
            let dy = _mm256_loadu_ps(directions.y.as_ptr().add(start));
            let dz = _mm256_loadu_ps(directions.z.as_ptr().add(start));
            let columns = _mm256_add_epi32(_mm256_set1_epi32(start as i32), lane_offsets);
            let mut depth = _mm256_set1_ps(f32::INFINITY);
            let mut id = _mm256_set1_epi32(NO_PANEL as i32);
            for row_panel in panels {
                if row_panel.end <= start || row_panel.start >= end {
                    continue;
                }
                let i = row_panel.index;
                let plane = &self.panel_planes[i];
                let normal = plane.normal;
                let along_normal = dot8(broadcast(normal), [dx, dy, dz]);
                let distance = _mm256_div_ps(_mm256_set1_ps(plane.offset), along_normal);
                // Columns are below 2^31: the panel's range as signed compares.
                let mut eligible = _mm256_andnot_si256(
                    _mm256_cmpgt_epi32(_mm256_set1_epi32(row_panel.start as i32), columns),
                    _mm256_cmpgt_epi32(_mm256_set1_epi32(row_panel.end as i32), columns),
                );
                let panel = &self.scene.panels[i];
                if let Some((hu, hv)) = panel.half_extent {
                    let relative = |origin: f32, direction: __m256, panel_origin: f32| {
                        _mm256_sub_ps(
                            _mm256_add_ps(
                                _mm256_set1_ps(origin),
                                _mm256_mul_ps(direction, distance),
                            ),
                            _mm256_set1_ps(panel_origin),
                        )
                    };
                    let (rx, ry, rz) = (
                        relative(origin.x, dx, panel.origin.x),
                        relative(origin.y, dy, panel.origin.y),
                        relative(origin.z, dz, panel.origin.z),
                    );
                    let outside = |axis: Vec3, half: f32| {
                        let along = dot8([rx, ry, rz], broadcast(axis));
                        _mm256_cmp_ps::<_CMP_GT_OQ>(
                            _mm256_andnot_ps(sign, along),
                            _mm256_set1_ps(half),
                        )
                    };
                    let outside =
                        _mm256_or_ps(outside(panel.axis_u, hu), outside(panel.axis_v, hv));
                    eligible = _mm256_andnot_si256(_mm256_castps_si256(outside), eligible);
                }
                let closer = _mm256_and_ps(
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GT_OQ>(distance, near_limit),
                        _mm256_cmp_ps::<_CMP_LT_OQ>(distance, depth),
                    ),
                    _mm256_castsi256_ps(eligible),
                );
                depth = _mm256_blendv_ps(depth, distance, closer);
                id = _mm256_castps_si256(_mm256_blendv_ps(
                    _mm256_castsi256_ps(id),
                    _mm256_castsi256_ps(_mm256_set1_epi32(i as i32)),
                    closer,
                ));
            }
            _mm256_storeu_ps(nearest_depth.as_mut_ptr().add(start), depth);
            _mm256_storeu_si256(nearest_panel.as_mut_ptr().add(start).cast(), id);
        }
    }

    /// What the ray through pixel centre (x, y) hits.
    pub fn trace(&self, x: f32, y: f32) -> Hit {
        let (direction, nearest_depth, nearest_panel) = self.nearest_panel_along(x, y);
        let (located, material) = self.nearest_surface(
            x,
            direction,
            nearest_depth,
            nearest_panel,
            &self.all_objects,
        );
        Hit {
            surface: located.surface,
            point: located.point,
            depth: located.depth,
            log_intensity: material.map_or(LOG_DARK, |material| {
                self.shade(&material, direction, located.depth)
            }),
        }
    }

    /// [`Snapshot::trace`] without the shading.
    pub fn locate(&self, x: f32, y: f32) -> Located {
        let (direction, nearest_depth, nearest_panel) = self.nearest_panel_along(x, y);
        self.nearest_surface(
            x,
            direction,
            nearest_depth,
            nearest_panel,
            &self.all_objects,
        )
        .0
    }

    /// Where the ray through pixel (`x`, `y`) meets the static world (the point
    /// [`Snapshot::trace`] reports where no object is nearer), without shading it: what the
    /// motion probe needs, at a fraction of the cost.
    pub fn static_point(&self, x: f32, y: f32) -> Option<Vec3> {
        let (direction, depth, panel) = self.nearest_panel_along(x, y);
        panel.map(|_| self.camera.translation + direction * depth)
    }

    /// The ray direction through pixel (`x`, `y`), and the depth and index of the nearest
    /// panel along it (infinity and `None` where there is none).
    fn nearest_panel_along(&self, x: f32, y: f32) -> (Vec3, f32, Option<usize>) {
        let scene = self.scene;
        let direction = self.camera.rotation.apply(scene.intrinsics.ray(x, y));
        let origin = self.camera.translation;
        let mut nearest_depth = f32::INFINITY;
        let mut nearest_panel = None;
        for i in 0..scene.panels.len() {
            if !self.panel_bounds[i].contains_column(x) {
                continue;
            }
            let plane = &self.panel_planes[i];
            // Parallel rays give an infinite or NaN distance, which fails the comparison.
            let distance = plane.offset / plane.normal.dot(direction);
            if !(distance > 1e-3 && distance < nearest_depth) {
                continue;
            }
            let panel = &scene.panels[i];
            if let Some((hu, hv)) = panel.half_extent {
                let relative = origin + direction * distance - panel.origin;
                if relative.dot(panel.axis_u).abs() > hu || relative.dot(panel.axis_v).abs() > hv {
                    continue;
                }
            }
            nearest_depth = distance;
            nearest_panel = Some(i);
        }
        (direction, nearest_depth, nearest_panel)
    }

    /// Finishes a ray in `direction` through column `x` whose nearest static surface is
    /// `panel` at `panel_depth`: tests the moving objects (those listed in `objects`) and
    /// returns the nearest surface with its material (none where nothing is hit).
    fn nearest_surface(
        &self,
        x: f32,
        direction: Vec3,
        panel_depth: f32,
        panel: Option<usize>,
        objects: &[usize],
    ) -> (Located, Option<Material>) {
        let scene = self.scene;
        let origin = self.camera.translation;
        let mut best = Located {
            surface: 0,
            point: Vec3::default(),
            depth: panel_depth,
        };
        let mut best_material = panel.map(|i| {
            let panel = &scene.panels[i];
            best.point = origin + direction * best.depth;
            let relative = best.point - panel.origin;
            Material {
                texture: panel.texture,
                texels_per_m: self.panel_planes[i].texels_per_m,
                u: relative.dot(panel.axis_u),
                v: relative.dot(panel.axis_v),
                normal: self.panel_planes[i].normal,
                log_illumination: self.panel_planes[i].log_illumination,
            }
        });
        if let Some(hit) = self.nearest_object(x, direction, best.depth, objects) {
            best.surface = hit.id;
            best.point = hit.point;
            best.depth = hit.depth;
            best_material = Some(hit.material);
        }
        (best, best_material)
    }

    /// [`Snapshot::overlay_objects`] for the eight columns from `first_column` (scratch
    /// index `k`): where an object is nearer than the panels, its shaded log intensity and id
    /// replace `log_intensity` and `surface`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn overlay_objects8(
        &self,
        first_column: usize,
        scratch: &RowScratch,
        k: usize,
        log_intensity: &mut [f32],
        surface: &mut [u16],
    ) {
        use std::arch::x86_64::*;
        assert!(log_intensity.len() == LANES && surface.len() == LANES);
        let block = k..k + LANES;
        let [dx, dy, dz] = scratch.directions.block8(block.start);
        let depth_limit = _mm256_loadu_ps(scratch.nearest_depth[block].as_ptr());
        let hits = self.nearest_objects8(first_column, [dx, dy, dz], depth_limit, scratch);
        let hit = _mm256_cmpgt_epi32(hits.id, _mm256_setzero_si256());
        let hit_lanes = _mm256_movemask_ps(_mm256_castsi256_ps(hit));
        if hit_lanes == 0 {
            return;
        }
        let hit_ps = _mm256_castsi256_ps(hit);
        // `material_texel`, lane by lane.
        let metres_per_pixel = self.metres_per_pixel8(hits.normal, [dx, dy, dz], hits.depth);
        // Lanes without a hit sample a valid texel of a hit lane's texture; their value is
        // discarded.
        let first_hit = hit_lanes.trailing_zeros() as i32;
        let hit_texture = _mm256_permutevar8x32_epi32(hits.texture, _mm256_set1_epi32(first_hit));
        let texture = _mm256_castps_si256(_mm256_blendv_ps(
            _mm256_castsi256_ps(hit_texture),
            _mm256_castsi256_ps(hits.texture),
            hit_ps,
        ));
        let or_zero = |value: __m256| _mm256_and_ps(hit_ps, value);
        let sampled = self.scene.atlas.sample8_lanes(
            texture,
            or_zero(_mm256_mul_ps(hits.u, hits.texels_per_m)),
            or_zero(_mm256_mul_ps(hits.v, hits.texels_per_m)),
            _mm256_blendv_ps(
                _mm256_set1_ps(1.0),
                _mm256_mul_ps(metres_per_pixel, hits.texels_per_m),
                hit_ps,
            ),
        );
        let lit = _mm256_add_ps(sampled, hits.log_illumination);
        let before = _mm256_loadu_ps(log_intensity.as_ptr());
        _mm256_storeu_ps(
            log_intensity.as_mut_ptr(),
            _mm256_blendv_ps(before, lit, hit_ps),
        );
        let mut ids = [0i32; LANES];
        _mm256_storeu_si256(ids.as_mut_ptr().cast(), hits.id);
        for (lane, id) in surface.iter_mut().enumerate() {
            if hit_lanes & (1 << lane) != 0 {
                *id = ids[lane] as u16;
            }
        }
    }

    /// [`Snapshot::nearest_object`] for eight rays (`direction`, from columns
    /// `first_column..first_column + 8`) among `scratch.active_objects`: the same operations
    /// in the same order per lane, hence the same hits bit for bit.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn nearest_objects8(
        &self,
        first_column: usize,
        direction: [std::arch::x86_64::__m256; 3],
        depth_limit: std::arch::x86_64::__m256,
        scratch: &RowScratch,
    ) -> ObjectHits8 {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_ps();
        let mut best = ObjectHits8 {
            id: _mm256_setzero_si256(),
            depth: depth_limit,
            texture: _mm256_setzero_si256(),
            texels_per_m: zero,
            u: zero,
            v: zero,
            normal: [zero; 3],
            log_illumination: zero,
        };
        // Columns are far below 2^24: exact as `f32`.
        let x = _mm256_add_ps(
            _mm256_set1_ps(first_column as f32),
            _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
        );
        let sign_bit = _mm256_set1_ps(-0.0);
        let abs = |value: __m256| _mm256_andnot_ps(sign_bit, value);
        // `Mat3::apply`, lane by lane.
        let apply = |m: &Mat3, v: [__m256; 3]| m.rows.map(|row| dot8(broadcast(row), v));
        for &i in &scratch.active_objects {
            let placed = &self.objects[i];
            let bounds = placed.bounds;
            let in_bounds = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(x, _mm256_set1_ps(bounds.x0)),
                _mm256_cmp_ps::<_CMP_LE_OQ>(x, _mm256_set1_ps(bounds.x1)),
            );
            if _mm256_movemask_ps(in_bounds) == 0 {
                continue;
            }
            let object = &self.scene.objects[i];
            let origin = placed.local_camera;
            let local = apply(&placed.inverse_rotation, direction);
            let (hit, distance, u, v, normal, log_illumination) = match object.shape {
                Shape::Cuboid { half } => {
                    let mut near = _mm256_set1_ps(f32::MIN);
                    let mut far = _mm256_set1_ps(f32::MAX);
                    let mut near_axis = _mm256_setzero_si256();
                    let mut missed = _mm256_setzero_ps();
                    for (axis, &d) in local.iter().enumerate() {
                        let (o, h) = (origin.axis(axis), half.axis(axis));
                        let parallel = _mm256_cmp_ps::<_CMP_LT_OQ>(abs(d), _mm256_set1_ps(1e-12));
                        if o.abs() > h {
                            missed = _mm256_or_ps(missed, parallel);
                        }
                        let inv = _mm256_div_ps(_mm256_set1_ps(1.0), d);
                        let a = _mm256_mul_ps(_mm256_set1_ps(-h - o), inv);
                        let b = _mm256_mul_ps(_mm256_set1_ps(h - o), inv);
                        let a_first = _mm256_cmp_ps::<_CMP_LT_OQ>(a, b);
                        let t0 = _mm256_blendv_ps(b, a, a_first);
                        let t1 = _mm256_blendv_ps(a, b, a_first);
                        let nearer =
                            _mm256_andnot_ps(parallel, _mm256_cmp_ps::<_CMP_GT_OQ>(t0, near));
                        near = _mm256_blendv_ps(near, t0, nearer);
                        near_axis = _mm256_castps_si256(_mm256_blendv_ps(
                            _mm256_castsi256_ps(near_axis),
                            _mm256_castsi256_ps(_mm256_set1_epi32(axis as i32)),
                            nearer,
                        ));
                        far = _mm256_blendv_ps(_mm256_min_ps(t1, far), far, parallel);
                    }
                    let hit = _mm256_andnot_ps(
                        _mm256_or_ps(
                            missed,
                            _mm256_or_ps(
                                _mm256_cmp_ps::<_CMP_GT_OQ>(near, far),
                                _mm256_cmp_ps::<_CMP_LE_OQ>(near, _mm256_set1_ps(1e-3)),
                            ),
                        ),
                        _mm256_castsi256_ps(_mm256_cmpeq_epi32(
                            _mm256_setzero_si256(),
                            _mm256_setzero_si256(),
                        )),
                    );
                    let on_axis = |k: i32| {
                        _mm256_castsi256_ps(_mm256_cmpeq_epi32(near_axis, _mm256_set1_epi32(k)))
                    };
                    let (on_x, on_y) = (on_axis(0), on_axis(1));
                    let pick = |values: [__m256; 3]| {
                        _mm256_blendv_ps(
                            _mm256_blendv_ps(values[2], values[1], on_y),
                            values[0],
                            on_x,
                        )
                    };
                    let p = [0, 1, 2].map(|c| {
                        _mm256_add_ps(
                            _mm256_set1_ps(origin.axis(c)),
                            _mm256_mul_ps(local[c], near),
                        )
                    });
                    let towards = _mm256_cmp_ps::<_CMP_GT_OQ>(pick(local), zero);
                    let sign = _mm256_blendv_ps(_mm256_set1_ps(1.0), _mm256_set1_ps(-1.0), towards);
                    let face_offset = _mm256_mul_ps(
                        _mm256_add_ps(
                            _mm256_mul_ps(_mm256_cvtepi32_ps(near_axis), _mm256_set1_ps(2.0)),
                            _mm256_andnot_ps(towards, _mm256_set1_ps(1.0)),
                        ),
                        _mm256_set1_ps(0.73),
                    );
                    let u = _mm256_add_ps(pick([p[2], p[0], p[0]]), face_offset);
                    let v = _mm256_add_ps(pick([p[1], p[2], p[1]]), face_offset);
                    let local_normal =
                        [on_x, on_y, _mm256_andnot_ps(_mm256_or_ps(on_x, on_y), hit)]
                            .map(|on| _mm256_and_ps(on, sign));
                    let light = placed.log_illumination.map(|l| _mm256_set1_ps(l));
                    (
                        hit,
                        near,
                        u,
                        v,
                        apply(&placed.pose.rotation, local_normal),
                        pick(light),
                    )
                }
                Shape::Ellipse { half_x, half_y } => {
                    let edge_on = _mm256_cmp_ps::<_CMP_LT_OQ>(abs(local[2]), _mm256_set1_ps(1e-9));
                    let distance = _mm256_div_ps(_mm256_set1_ps(-origin.z), local[2]);
                    let p = [0, 1].map(|c| {
                        _mm256_add_ps(
                            _mm256_set1_ps(origin.axis(c)),
                            _mm256_mul_ps(local[c], distance),
                        )
                    });
                    let nx = _mm256_div_ps(p[0], _mm256_set1_ps(half_x));
                    let ny = _mm256_div_ps(p[1], _mm256_set1_ps(half_y));
                    let inside = _mm256_cmp_ps::<_CMP_LE_OQ>(
                        _mm256_add_ps(_mm256_mul_ps(nx, nx), _mm256_mul_ps(ny, ny)),
                        _mm256_set1_ps(1.0),
                    );
                    let hit = _mm256_andnot_ps(
                        edge_on,
                        _mm256_and_ps(
                            _mm256_cmp_ps::<_CMP_GT_OQ>(distance, _mm256_set1_ps(1e-3)),
                            inside,
                        ),
                    );
                    let normal = placed.pose.rotation.apply(Vec3::new(0.0, 0.0, 1.0));
                    (
                        hit,
                        distance,
                        p[0],
                        p[1],
                        [normal.x, normal.y, normal.z].map(|c| _mm256_set1_ps(c)),
                        _mm256_set1_ps(placed.log_illumination[2]),
                    )
                }
            };
            // `nearest_object` keeps a hit unless it is at or beyond the best depth so far.
            let closer = _mm256_and_ps(
                _mm256_and_ps(hit, in_bounds),
                _mm256_cmp_ps::<_CMP_NGE_UQ>(distance, best.depth),
            );
            if _mm256_movemask_ps(closer) == 0 {
                continue;
            }
            let take = |old: __m256, new: __m256| _mm256_blendv_ps(old, new, closer);
            let take_i = |old: __m256i, new: i32| {
                _mm256_castps_si256(take(
                    _mm256_castsi256_ps(old),
                    _mm256_castsi256_ps(_mm256_set1_epi32(new)),
                ))
            };
            best.id = take_i(best.id, i as i32 + 1);
            best.depth = take(best.depth, distance);
            best.texture = take_i(
                best.texture,
                i32::try_from(object.texture).expect("texture index under 2^31"),
            );
            best.texels_per_m = take(best.texels_per_m, _mm256_set1_ps(placed.texels_per_m));
            best.u = take(best.u, u);
            best.v = take(best.v, v);
            best.normal = [0, 1, 2].map(|c| take(best.normal[c], normal[c]));
            best.log_illumination = take(best.log_illumination, log_illumination);
        }
        best
    }

    /// The nearest of the moving objects listed in `objects` that the ray in `direction`
    /// through column `x` meets closer than `depth_limit`.
    fn nearest_object(
        &self,
        x: f32,
        direction: Vec3,
        depth_limit: f32,
        objects: &[usize],
    ) -> Option<ObjectHit> {
        let scene = self.scene;
        let mut best: Option<ObjectHit> = None;
        let mut best_depth = depth_limit;
        for &i in objects {
            let placed = &self.objects[i];
            if !placed.bounds.contains_column(x) {
                continue;
            }
            let object = &scene.objects[i];
            let local_origin = placed.local_camera;
            let local_direction = placed.inverse_rotation.apply(direction);
            let Some(local_hit) = intersect_shape(&object.shape, local_origin, local_direction)
            else {
                continue;
            };
            if local_hit.distance >= best_depth {
                continue;
            }
            best_depth = local_hit.distance;
            let normal = placed.pose.rotation.apply(local_hit.normal);
            best = Some(ObjectHit {
                id: i as u16 + 1,
                point: local_origin + local_direction * local_hit.distance,
                depth: local_hit.distance,
                material: Material {
                    texture: object.texture,
                    texels_per_m: placed.texels_per_m,
                    u: local_hit.u,
                    v: local_hit.v,
                    normal,
                    log_illumination: placed.log_illumination[local_hit.axis],
                },
            });
        }
        best
    }

    fn shade(&self, material: &Material, direction: Vec3, depth: f32) -> f32 {
        let texel = self.material_texel(material, direction, depth);
        self.scene.textures[texel.texture].sample(texel.u, texel.v, texel.footprint)
            + texel.log_illumination
    }

    /// The width of a pixel's footprint, in metres, on a surface of normal `normal` met at
    /// `depth` along `direction` (grazing angles capped at a cosine of 0.05).
    fn metres_per_pixel(&self, normal: Vec3, direction: Vec3, depth: f32) -> f32 {
        let cos_incidence = (normal.dot(direction).abs() / direction.length()).max(0.05);
        depth / (self.scene.intrinsics.fx * cos_incidence)
    }

    /// [`Snapshot::metres_per_pixel`] for eight lanes, the same operations per lane.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn metres_per_pixel8(
        &self,
        normal: [std::arch::x86_64::__m256; 3],
        direction: [std::arch::x86_64::__m256; 3],
        depth: std::arch::x86_64::__m256,
    ) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let cosine = _mm256_div_ps(
            _mm256_andnot_ps(_mm256_set1_ps(-0.0), dot8(normal, direction)),
            _mm256_sqrt_ps(dot8(direction, direction)),
        );
        let cos_incidence = _mm256_max_ps(cosine, _mm256_set1_ps(0.05));
        _mm256_div_ps(
            depth,
            _mm256_mul_ps(_mm256_set1_ps(self.scene.intrinsics.fx), cos_incidence),
        )
    }

    /// What [`Snapshot::shade`] samples, and the light it adds.
    #[inline(always)]
    fn material_texel(&self, material: &Material, direction: Vec3, depth: f32) -> PanelTexel {
        let metres_per_pixel = self.metres_per_pixel(material.normal, direction, depth);
        PanelTexel {
            texture: material.texture,
            u: material.u * material.texels_per_m,
            v: material.v * material.texels_per_m,
            footprint: metres_per_pixel * material.texels_per_m,
            log_illumination: material.log_illumination,
        }
    }
}

/// [`Vec3::dot`] for eight lanes: `(a.x·b.x + a.y·b.y) + a.z·b.z`, rounded as the scalar one.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn dot8(
    a: [std::arch::x86_64::__m256; 3],
    b: [std::arch::x86_64::__m256; 3],
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_add_ps(
        _mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])),
        _mm256_mul_ps(a[2], b[2]),
    )
}

/// `v` in every lane, one vector per component.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn broadcast(v: Vec3) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    [
        _mm256_set1_ps(v.x),
        _mm256_set1_ps(v.y),
        _mm256_set1_ps(v.z),
    ]
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
        Shape::Ellipse { half_x, half_y } => {
            if direction.z.abs() < 1e-9 {
                return None;
            }
            let distance = -origin.z / direction.z;
            let p = origin + direction * distance;
            let (nx, ny) = (p.x / half_x, p.y / half_y);
            (distance > 1e-3 && nx * nx + ny * ny <= 1.0).then_some(LocalHit {
                distance,
                u: p.x,
                v: p.y,
                normal: Vec3::new(0.0, 0.0, 1.0),
                axis: 2,
            })
        }
    }
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
    if near > far || near <= 1e-3 {
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
        let (mut cuboid_pixels, mut ellipse_pixels) = (0, 0);
        for preset in [Preset::Boxes, Preset::Fast, Preset::Tabletop] {
            let config = preset.config().at_reduced_resolution(2);
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
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(
            cuboid_pixels > 1000 && ellipse_pixels > 500,
            "{cuboid_pixels}, {ellipse_pixels}"
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
