//! Cut-out silhouettes: flat objects whose outline is a union of rectangles and ellipses minus
//! holes, so that a scene holds non-convex outlines (crosses, L and T shapes, crescents), thin
//! parts (handles, spokes) and holes (rings, frames), not only boxes and discs.
//!
//! The inside test is written twice, for one point and for eight lanes, with the same
//! operations in the same order: the two renderers must agree bit for bit.

use rand::Rng;

/// Most parts a silhouette joins.
pub const MAX_PARTS: usize = 3;
/// Most holes a silhouette cuts.
pub const MAX_HOLES: usize = 2;

/// A rectangle or an ellipse in the silhouette's plane, rotated about its centre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Part {
    pub centre: [f32; 2],
    pub half: [f32; 2],
    /// Cosine and sine of the rotation of the part's axes.
    pub cos: f32,
    pub sin: f32,
    /// An ellipse when true, a rectangle otherwise.
    pub rounded: bool,
}

impl Part {
    fn new(centre: [f32; 2], half: [f32; 2], angle: f32, rounded: bool) -> Part {
        Part {
            centre,
            half,
            cos: angle.cos(),
            sin: angle.sin(),
            rounded,
        }
    }

    pub fn contains(&self, x: f32, y: f32) -> bool {
        let dx = x - self.centre[0];
        let dy = y - self.centre[1];
        let u = (dx * self.cos + dy * self.sin) / self.half[0];
        let v = (dy * self.cos - dx * self.sin) / self.half[1];
        if self.rounded {
            u * u + v * v <= 1.0
        } else {
            u.abs() <= 1.0 && v.abs() <= 1.0
        }
    }

    /// Half extents of the part's axis-aligned bounding box, about the silhouette's origin.
    fn reach(&self) -> [f32; 2] {
        let (c, s) = (self.cos.abs(), self.sin.abs());
        let [hu, hv] = self.half;
        [
            self.centre[0].abs() + hu * c + hv * s,
            self.centre[1].abs() + hu * s + hv * c,
        ]
    }
}

/// The outline of a flat object in its local x–y plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Silhouette {
    parts: [Part; MAX_PARTS],
    part_count: usize,
    holes: [Part; MAX_HOLES],
    hole_count: usize,
}

/// The families a random silhouette comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SilhouetteKind {
    /// Two or three bars: crosses, L, T and asterisk shapes.
    Bars,
    /// An ellipse with a hole: a ring, or a crescent where the hole bites the edge.
    Ring,
    /// A head on a long thin handle.
    Tool,
    /// A rectangle with one or two windows.
    Frame,
}

impl SilhouetteKind {
    pub const ALL: [SilhouetteKind; 4] = [
        SilhouetteKind::Bars,
        SilhouetteKind::Ring,
        SilhouetteKind::Tool,
        SilhouetteKind::Frame,
    ];
}

impl Silhouette {
    pub fn new(parts: &[Part], holes: &[Part]) -> Silhouette {
        assert!(
            (1..=MAX_PARTS).contains(&parts.len()) && holes.len() <= MAX_HOLES,
            "a silhouette joins 1..={MAX_PARTS} parts and cuts at most {MAX_HOLES} holes"
        );
        let mut silhouette = Silhouette {
            parts: [Part::default(); MAX_PARTS],
            part_count: parts.len(),
            holes: [Part::default(); MAX_HOLES],
            hole_count: holes.len(),
        };
        silhouette.parts[..parts.len()].copy_from_slice(parts);
        silhouette.holes[..holes.len()].copy_from_slice(holes);
        silhouette
    }

    /// A silhouette of `kind` whose longest side is about `size` (metres).
    pub fn random(kind: SilhouetteKind, size: f32, rng: &mut impl Rng) -> Silhouette {
        let h = size / 2.0;
        let quarter = std::f32::consts::FRAC_PI_2;
        match kind {
            SilhouetteKind::Bars => {
                let thickness = h * rng.gen_range(0.15..0.35);
                let main = Part::new([0.0, 0.0], [h, thickness], 0.0, false);
                let along = h * rng.gen_range(-0.75..0.75);
                let cross_half = h * rng.gen_range(0.4..0.7);
                // The crossbar starts at the main bar (T, L) or straddles it (cross).
                let across = if rng.gen_bool(0.5) {
                    0.0
                } else {
                    cross_half - thickness
                };
                let cross = Part::new([along, across], [cross_half, thickness], quarter, false);
                if rng.gen_bool(0.3) {
                    let third =
                        Part::new([0.0, 0.0], [h * 0.9, thickness * 0.7], quarter / 1.5, false);
                    Silhouette::new(&[main, cross, third], &[])
                } else {
                    Silhouette::new(&[main, cross], &[])
                }
            }
            SilhouetteKind::Ring => {
                let aspect = rng.gen_range(0.6..1.0);
                let outer = Part::new([0.0, 0.0], [h, h * aspect], 0.0, true);
                let inner_scale = rng.gen_range(0.35..0.6);
                let offset = if rng.gen_bool(0.5) {
                    [0.0, 0.0]
                } else {
                    // A crescent: the hole bites through one side.
                    let angle = rng.gen_range(0.0..std::f32::consts::TAU);
                    let reach = h * (1.0 - inner_scale * 0.5);
                    [reach * angle.cos(), reach * aspect * angle.sin()]
                };
                let hole = Part::new(
                    offset,
                    [h * inner_scale, h * aspect * inner_scale],
                    0.0,
                    true,
                );
                Silhouette::new(&[outer], &[hole])
            }
            SilhouetteKind::Tool => {
                let head = [h * rng.gen_range(0.3..0.45), h * rng.gen_range(0.25..0.45)];
                let handle_thickness = h * rng.gen_range(0.04..0.09);
                let head_part = Part::new([h - head[0], 0.0], head, 0.0, rng.gen_bool(0.6));
                let handle_half = h - head[0];
                let handle = Part::new(
                    [-h + handle_half, 0.0],
                    [handle_half, handle_thickness],
                    0.0,
                    false,
                );
                Silhouette::new(&[head_part, handle], &[])
            }
            SilhouetteKind::Frame => {
                let aspect = rng.gen_range(0.6..1.0);
                let outer = Part::new([0.0, 0.0], [h, h * aspect], 0.0, false);
                let border = h * rng.gen_range(0.1..0.2);
                let inner_height = h * aspect - border;
                if rng.gen_bool(0.5) {
                    let window = Part::new([0.0, 0.0], [h - border, inner_height], 0.0, false);
                    Silhouette::new(&[outer], &[window])
                } else {
                    // Two windows side by side, split by a bar as wide as the border.
                    let half_width = (h - 1.5 * border) / 2.0;
                    let offset = border / 2.0 + half_width;
                    let left = Part::new([-offset, 0.0], [half_width, inner_height], 0.0, false);
                    let right = Part::new([offset, 0.0], [half_width, inner_height], 0.0, false);
                    Silhouette::new(&[outer], &[left, right])
                }
            }
        }
    }

    pub fn parts(&self) -> &[Part] {
        &self.parts[..self.part_count]
    }

    pub fn holes(&self) -> &[Part] {
        &self.holes[..self.hole_count]
    }

    pub fn contains(&self, x: f32, y: f32) -> bool {
        self.parts().iter().any(|part| part.contains(x, y))
            && !self.holes().iter().any(|hole| hole.contains(x, y))
    }

    /// Half extents of the bounding box about the origin.
    pub fn reach(&self) -> [f32; 2] {
        self.parts().iter().fold([0.0, 0.0], |reach, part| {
            let [x, y] = part.reach();
            [reach[0].max(x), reach[1].max(y)]
        })
    }

    /// The inside test of eight points, lane by lane as [`Silhouette::contains`]: all ones
    /// where inside, zero elsewhere.
    ///
    /// # Safety
    /// The CPU must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    pub unsafe fn contains8(
        &self,
        x: std::arch::x86_64::__m256,
        y: std::arch::x86_64::__m256,
    ) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let part_contains = |part: &Part| {
            let dx = _mm256_sub_ps(x, _mm256_set1_ps(part.centre[0]));
            let dy = _mm256_sub_ps(y, _mm256_set1_ps(part.centre[1]));
            let (cos, sin) = (_mm256_set1_ps(part.cos), _mm256_set1_ps(part.sin));
            let u = _mm256_div_ps(
                _mm256_add_ps(_mm256_mul_ps(dx, cos), _mm256_mul_ps(dy, sin)),
                _mm256_set1_ps(part.half[0]),
            );
            let v = _mm256_div_ps(
                _mm256_sub_ps(_mm256_mul_ps(dy, cos), _mm256_mul_ps(dx, sin)),
                _mm256_set1_ps(part.half[1]),
            );
            let one = _mm256_set1_ps(1.0);
            if part.rounded {
                _mm256_cmp_ps::<_CMP_LE_OQ>(
                    _mm256_add_ps(_mm256_mul_ps(u, u), _mm256_mul_ps(v, v)),
                    one,
                )
            } else {
                let sign_bit = _mm256_set1_ps(-0.0);
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_andnot_ps(sign_bit, u), one),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_andnot_ps(sign_bit, v), one),
                )
            }
        };
        let union = |parts: &[Part]| {
            parts.iter().fold(_mm256_setzero_ps(), |inside, part| {
                _mm256_or_ps(inside, part_contains(part))
            })
        };
        _mm256_andnot_ps(union(self.holes()), union(self.parts()))
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// Share of a grid over the bounding box that lies inside.
    fn fill(silhouette: &Silhouette) -> f32 {
        let [rx, ry] = silhouette.reach();
        let n = 200;
        let inside = (0..n * n)
            .filter(|i| {
                let x = -rx + 2.0 * rx * ((i % n) as f32 + 0.5) / n as f32;
                let y = -ry + 2.0 * ry * ((i / n) as f32 + 0.5) / n as f32;
                silhouette.contains(x, y)
            })
            .count();
        inside as f32 / (n * n) as f32
    }

    #[test]
    fn a_ring_has_a_hole_and_a_frame_has_windows() {
        let ring = Silhouette::new(
            &[Part::new([0.0, 0.0], [1.0, 1.0], 0.0, true)],
            &[Part::new([0.0, 0.0], [0.5, 0.5], 0.0, true)],
        );
        assert!(!ring.contains(0.0, 0.0));
        assert!(ring.contains(0.75, 0.0));
        assert!(!ring.contains(0.95, 0.95));
        let frame = Silhouette::new(
            &[Part::new([0.0, 0.0], [1.0, 0.5], 0.0, false)],
            &[
                Part::new([-0.5, 0.0], [0.4, 0.4], 0.0, false),
                Part::new([0.5, 0.0], [0.4, 0.4], 0.0, false),
            ],
        );
        assert!(frame.contains(0.0, 0.0));
        assert!(!frame.contains(-0.5, 0.0) && !frame.contains(0.5, 0.1));
        assert!(frame.contains(0.95, 0.45));
    }

    #[test]
    fn an_l_shape_is_not_convex() {
        let quarter = std::f32::consts::FRAC_PI_2;
        let l = Silhouette::new(
            &[
                Part::new([0.0, 0.0], [1.0, 0.2], 0.0, false),
                Part::new([-0.8, 0.6], [0.6, 0.2], quarter, false),
            ],
            &[],
        );
        let (a, b) = ((0.9, 0.0), (-0.8, 1.1));
        assert!(l.contains(a.0, a.1) && l.contains(b.0, b.1));
        // The midpoint of two inside points lies outside.
        assert!(!l.contains((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0));
    }

    #[test]
    fn every_family_is_neither_empty_nor_its_bounding_box() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for kind in SilhouetteKind::ALL {
            for _ in 0..50 {
                let silhouette = Silhouette::random(kind, 0.4, &mut rng);
                let [rx, ry] = silhouette.reach();
                assert!(
                    rx <= 0.2 * 1.5 && ry <= 0.2 * 1.5,
                    "{kind:?} reaches {rx}, {ry}"
                );
                let share = fill(&silhouette);
                assert!(
                    share > 0.1 && share < 0.85,
                    "{kind:?} fills {share}: {silhouette:?}"
                );
            }
        }
    }

    #[test]
    fn a_tool_has_a_thin_handle() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for _ in 0..20 {
            let tool = Silhouette::random(SilhouetteKind::Tool, 1.0, &mut rng);
            let handle = tool.parts()[1];
            assert!(handle.half[0] / handle.half[1] > 3.0, "{handle:?}");
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_lanes_agree_with_one_point_bit_for_bit() {
        if !is_x86_feature_detected!("avx") {
            return;
        }
        use std::arch::x86_64::*;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for kind in SilhouetteKind::ALL {
            for _ in 0..20 {
                let silhouette = Silhouette::random(kind, 0.5, &mut rng);
                for _ in 0..200 {
                    let xs: [f32; 8] = std::array::from_fn(|_| rng.gen_range(-0.3..0.3));
                    let ys: [f32; 8] = std::array::from_fn(|_| rng.gen_range(-0.3..0.3));
                    let mut lanes = [0.0f32; 8];
                    // SAFETY: AVX was detected above.
                    unsafe {
                        let inside = silhouette
                            .contains8(_mm256_loadu_ps(xs.as_ptr()), _mm256_loadu_ps(ys.as_ptr()));
                        _mm256_storeu_ps(lanes.as_mut_ptr(), inside);
                    }
                    for k in 0..8 {
                        assert_eq!(
                            lanes[k].to_bits() != 0,
                            silhouette.contains(xs[k], ys[k]),
                            "{kind:?} at ({}, {})",
                            xs[k],
                            ys[k]
                        );
                    }
                }
            }
        }
    }
}
