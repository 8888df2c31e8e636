//! The AVX2 kernels of the row renderer and panel search: eight columns per vector, equal to
//! the portable code they stand in for.

use super::*;

impl<'a> Snapshot<'a> {
    /// [`Snapshot::render_rows_portable`] compiled for AVX2, whose 8-lane vectors double the
    /// width of the vectorised passes, with textures sampled eight pixels at a time from the
    /// atlas. Without FMA (Rust never fuses on its own) every operation rounds as in the
    /// portable build: the output is the same bit for bit.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn render_rows_avx2<const SHADE: bool, const LOCATE: bool>(
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

    /// [`Snapshot::shade_panels`] for columns `start..start + 8` (`log_intensity`), in vector
    /// registers from the panels to the store.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn shade_panels8(
        &self,
        scratch: &RowScratch,
        start: usize,
        log_intensity: &mut [f32],
    ) {
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
    pub(super) unsafe fn panel_texels8(&self, scratch: &RowScratch, start: usize) -> PanelTexels8 {
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

    /// [`Snapshot::nearest_in_blocks`] in AVX2 intrinsics: the same operations in the same
    /// order (hence the same bits), with the lanes' column tests and selections as vector
    /// compares and blends, which the compiler did not find (it built the masks byte by byte).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn nearest_in_blocks_avx2(
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
        let near_limit = _mm256_set1_ps(NEAR_PLANE_M);
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

    /// [`Snapshot::overlay_objects`] for the eight columns from `first_column` (scratch
    /// index `k`): where an object is nearer than the panels, its shaded log intensity and id
    /// replace `log_intensity` and `surface`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn overlay_objects8(
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
    pub(super) unsafe fn nearest_objects8(
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
                                _mm256_cmp_ps::<_CMP_LE_OQ>(near, _mm256_set1_ps(NEAR_PLANE_M)),
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
                Shape::Ellipse { .. } | Shape::Cutout(_) => {
                    let edge_on = _mm256_cmp_ps::<_CMP_LT_OQ>(abs(local[2]), _mm256_set1_ps(1e-9));
                    let distance = _mm256_div_ps(_mm256_set1_ps(-origin.z), local[2]);
                    let p = [0, 1].map(|c| {
                        _mm256_add_ps(
                            _mm256_set1_ps(origin.axis(c)),
                            _mm256_mul_ps(local[c], distance),
                        )
                    });
                    let inside = match object.shape {
                        Shape::Cutout(silhouette) => silhouette.contains8(p[0], p[1]),
                        Shape::Ellipse { half_x, half_y } => {
                            let nx = _mm256_div_ps(p[0], _mm256_set1_ps(half_x));
                            let ny = _mm256_div_ps(p[1], _mm256_set1_ps(half_y));
                            _mm256_cmp_ps::<_CMP_LE_OQ>(
                                _mm256_add_ps(_mm256_mul_ps(nx, nx), _mm256_mul_ps(ny, ny)),
                                _mm256_set1_ps(1.0),
                            )
                        }
                        Shape::Cuboid { .. } => unreachable!("cuboids are matched above"),
                    };
                    let hit = _mm256_andnot_ps(
                        edge_on,
                        _mm256_and_ps(
                            _mm256_cmp_ps::<_CMP_GT_OQ>(distance, _mm256_set1_ps(NEAR_PLANE_M)),
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

    /// [`Snapshot::metres_per_pixel`] for eight lanes, the same operations per lane.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn metres_per_pixel8(
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
}

/// [`Vec3::dot`] for eight lanes: `(a.x·b.x + a.y·b.y) + a.z·b.z`, rounded as the scalar one.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn dot8(
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
pub(super) unsafe fn broadcast(v: Vec3) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    [
        _mm256_set1_ps(v.x),
        _mm256_set1_ps(v.y),
        _mm256_set1_ps(v.z),
    ]
}
