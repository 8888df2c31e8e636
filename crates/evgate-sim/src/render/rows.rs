//! The row renderer: rows of pixels at once, the static world panel by panel, then the
//! objects overlaid where they may be.

use super::*;

impl<'a> Snapshot<'a> {
    /// [`Snapshot::render_rows_portable`] in its AVX2 build where the CPU has AVX2.
    pub(super) fn render_rows_where_supported<const SHADE: bool, const LOCATE: bool>(
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

    /// With `GATHER`, only for callers compiled for AVX2 on a CPU that has it. Without
    /// `SHADE`, `log_intensity` is not touched (and may be empty); without `LOCATE`, neither
    /// are `surface` and `depth`.
    #[inline(always)]
    pub(super) fn render_rows_portable<
        const GATHER: bool,
        const SHADE: bool,
        const LOCATE: bool,
    >(
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
    pub(super) fn shade_panels<const GATHER: bool>(
        &self,
        scratch: &RowScratch,
        log_intensity: &mut [f32],
    ) {
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

    /// Where the ray of column `c` (searched by [`Snapshot::nearest_panels`]) meets its
    /// nearest panel, in texture terms: what `nearest_surface` and `shade` compute.
    #[inline(always)]
    pub(super) fn panel_texel(&self, scratch: &RowScratch, c: usize) -> Option<PanelTexel> {
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
}
