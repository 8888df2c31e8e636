//! Which panel each column of a row meets first: screen-space bounds narrow the candidates,
//! then the nearest of them is found in blocks of eight columns.

use super::*;

impl<'a> Snapshot<'a> {
    /// Fills `scratch` with the ray directions of `columns` of row `y` (from index 0) and the
    /// nearest panel along each.
    #[inline(always)]
    pub(super) fn nearest_panels(&self, y: f32, columns: Range<usize>, scratch: &mut RowScratch) {
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
    pub(super) fn columns_in_front(
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
    pub(super) fn narrow_unbounded_panels(
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

    /// The nearest of `panels` along each ray in `directions` (and its depth), or
    /// [`NO_PANEL`] (at infinity), for whole blocks of [`LANES`] columns
    /// (`nearest_depth.len()` a multiple of it; columns beyond the panels' ranges are never
    /// eligible): the per-pixel test of [`Snapshot::trace`], panel after panel in index order,
    /// in AVX2 where the CPU has it.
    #[inline(always)]
    pub(super) fn nearest_on_panels(
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
    pub(super) fn nearest_in_blocks(
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
                    let closer =
                        (distance[k] > NEAR_PLANE_M) & (distance[k] < depth[k]) & eligible[k];
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
}
