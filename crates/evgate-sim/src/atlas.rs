//! Every texel of every texture of a scene in one array, so that eight texture samples (of any
//! textures and mip levels) are taken at once with AVX2: the arithmetic in 8-lane vectors, the
//! texels read by scalar loads (AMD Zen runs gather instructions as microcode, slower than the
//! loads they are made of). The same operations in the same order as [`Texture::sample`],
//! hence the same bits. Each texel is stored with its right-hand neighbour, so that one 8-byte
//! load reads both texels of a bilinear footprint's row: half the loads, and half the lane
//! index extractions that feed them, of single texels, for twice the memory (textures are
//! small: a 256² texture's levels take 0.7 MB). Each level is stored in tiles of 4×4 such
//! pairs, two 64-byte cache lines: a bilinear footprint then mostly lies in one tile, and a
//! row of pixels crossing the texture in any direction touches fewer lines than with
//! row-major texels.

#[cfg(target_arch = "x86_64")]
use crate::index_lanes::checked_first_and_uniform;
use crate::texture::Texture;

/// Most mip levels per texture (a 32768-texel texture has 16).
const MAX_LEVELS: usize = 16;
/// log2 of a tile's side in texels (levels narrower than a tile are one tile of their size).
const TILE_LOG2: i32 = 2;
/// Texel pairs per tile: two cache lines.
const TILE_TEXELS: usize = 1 << (2 * TILE_LOG2);

/// A texel and its right-hand neighbour (wrapping around the level).
type TexelPair = [f32; 2];

/// One tile, aligned to cache lines.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
struct Tile([TexelPair; TILE_TEXELS]);

/// The texels of all textures' mip levels, and where each level starts.
#[derive(Clone, Debug, Default)]
pub struct TextureAtlas {
    /// Every level starts at a tile, and its texel pairs are tiled (see [`tiled_index`]).
    tiles: Vec<Tile>,
    /// Index (in texel pairs) of level l of texture t at `t * MAX_LEVELS + l`.
    level_starts: Vec<i32>,
    /// Per texture: log2 of the side of its level 0.
    size_log2: Vec<i32>,
    /// Per texture: its number of mip levels.
    level_counts: Vec<i32>,
}

/// Where texel (x, y) of a level of side `1 << side_log2` lies in its tiled storage: tiles in
/// row-major order, texels row-major within a tile. The sum of a part that depends on x only
/// and one that depends on y only, as the gathers compute it.
fn tiled_index(x: usize, y: usize, side_log2: u32) -> usize {
    let tile_log2 = side_log2.min(TILE_LOG2 as u32);
    let tile_mask = (1 << tile_log2) - 1;
    let column = ((x >> tile_log2) << (2 * tile_log2)) + (x & tile_mask);
    let row = ((y >> tile_log2) << (side_log2 + tile_log2)) + ((y & tile_mask) << tile_log2);
    row + column
}

impl TextureAtlas {
    pub fn new(textures: &[Texture]) -> TextureAtlas {
        let mut atlas = TextureAtlas::default();
        for texture in textures {
            let levels = texture.level_texels();
            assert!(
                levels.len() <= MAX_LEVELS,
                "a texture of side {} has more than {MAX_LEVELS} mip levels",
                texture.size()
            );
            let mut starts = [0i32; MAX_LEVELS];
            for (level, (start, texels)) in starts.iter_mut().zip(&levels).enumerate() {
                let first_tile = atlas.tiles.len();
                *start = i32::try_from(first_tile * TILE_TEXELS)
                    .expect("texture atlas under 2^31 texels");
                let side = texture.size() >> level;
                let side_log2 = side.trailing_zeros();
                atlas.tiles.resize(
                    first_tile + texels.len().div_ceil(TILE_TEXELS),
                    Tile::default(),
                );
                let storage = &mut atlas.tiles[first_tile..];
                for (y, row) in texels.chunks_exact(side).enumerate() {
                    for (x, &texel) in row.iter().enumerate() {
                        let index = tiled_index(x, y, side_log2);
                        storage[index / TILE_TEXELS].0[index % TILE_TEXELS] =
                            [texel, row[(x + 1) % side]];
                    }
                }
            }
            atlas.level_starts.extend_from_slice(&starts);
            atlas.size_log2.push(texture.size().trailing_zeros() as i32);
            atlas.level_counts.push(levels.len() as i32);
        }
        atlas
    }

    /// [`Texture::sample`] for eight lanes at once: texture `texture[k]` at (`u[k]`, `v[k]`)
    /// with footprint `footprint[k]` (texture indices must be valid).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub unsafe fn sample8(
        &self,
        texture: &[i32; 8],
        u: &[f32; 8],
        v: &[f32; 8],
        footprint: &[f32; 8],
    ) -> [f32; 8] {
        use std::arch::x86_64::*;
        let sampled = self.sample8_lanes(
            _mm256_loadu_si256(texture.as_ptr().cast()),
            _mm256_loadu_ps(u.as_ptr()),
            _mm256_loadu_ps(v.as_ptr()),
            _mm256_loadu_ps(footprint.as_ptr()),
        );
        let mut out = [0.0f32; 8];
        _mm256_storeu_ps(out.as_mut_ptr(), sampled);
        out
    }

    /// [`TextureAtlas::sample8`] on vectors, for callers that have them in registers
    /// (a round trip through memory per block cost a render as much as its blending).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub unsafe fn sample8_lanes(
        &self,
        texture: std::arch::x86_64::__m256i,
        u: std::arch::x86_64::__m256,
        v: std::arch::x86_64::__m256,
        footprint: std::arch::x86_64::__m256,
    ) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        // Where all lanes sample one texture, its sizes are broadcast instead of gathered.
        let (first, uniform) =
            checked_first_and_uniform(texture, self.level_counts.len(), "texture");
        // SAFETY (all gathers and loads): every index is a valid texture (asserted above), a level
        // below its count, or a texel inside that level (masked by its size).
        let (level_counts, size_log2) = if uniform {
            (
                _mm256_set1_epi32(self.level_counts[first]),
                _mm256_set1_epi32(self.size_log2[first]),
            )
        } else {
            (
                _mm256_i32gather_epi32::<4>(self.level_counts.as_ptr(), texture),
                _mm256_i32gather_epi32::<4>(self.size_log2.as_ptr(), texture),
            )
        };
        // Where each lane's level starts: for one texture, looked up among its levels'
        // starts held in two registers (a permutation each) instead of gathered from memory.
        let uniform_starts = uniform.then(|| {
            let starts = &self.level_starts[first * MAX_LEVELS..(first + 1) * MAX_LEVELS];
            (
                _mm256_loadu_si256(starts.as_ptr().cast()),
                _mm256_loadu_si256(starts.as_ptr().add(8).cast()),
            )
        });
        let level_start = |level: __m256i| match uniform_starts {
            Some((low, high)) => _mm256_blendv_epi8(
                _mm256_permutevar8x32_epi32(low, level),
                _mm256_permutevar8x32_epi32(high, level),
                _mm256_cmpgt_epi32(level, _mm256_set1_epi32(7)),
            ),
            None => _mm256_i32gather_epi32::<4>(
                self.level_starts.as_ptr(),
                _mm256_add_epi32(_mm256_slli_epi32::<4>(texture), level),
            ),
        };
        let one_i = _mm256_set1_epi32(1);
        // approximate_log2(footprint), clamped to the coarsest level.
        let bits = _mm256_castps_si256(footprint);
        let exponent = _mm256_sub_ps(
            _mm256_cvtepi32_ps(_mm256_and_si256(
                _mm256_srli_epi32::<23>(bits),
                _mm256_set1_epi32(0xff),
            )),
            _mm256_set1_ps(127.0),
        );
        let mantissa = _mm256_castsi256_ps(_mm256_or_si256(
            _mm256_and_si256(bits, _mm256_set1_epi32(0x007f_ffff)),
            _mm256_set1_epi32(0x3f80_0000),
        ));
        let log2 = _mm256_sub_ps(_mm256_add_ps(exponent, mantissa), _mm256_set1_ps(1.0));
        let coarsest = _mm256_cvtepi32_ps(_mm256_sub_epi32(level_counts, one_i));
        let level = _mm256_min_ps(log2, coarsest);
        // Footprints up to one texel read level 0 with coordinates scaled by 1.0 (exact).
        let fine_only = _mm256_cmp_ps::<_CMP_LE_OQ>(footprint, _mm256_set1_ps(1.0));
        let fine_only_i = _mm256_castps_si256(fine_only);
        let fine = _mm256_andnot_si256(fine_only_i, _mm256_cvttps_epi32(level));
        let blend = _mm256_sub_ps(level, _mm256_cvtepi32_ps(fine));
        let scale = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_sub_epi32(
            _mm256_set1_epi32(127),
            fine,
        )));
        let (us, vs) = (_mm256_mul_ps(u, scale), _mm256_mul_ps(v, scale));
        let a = self.bilinear8(level_start(fine), size_log2, fine, us, vs);
        let next = _mm256_add_epi32(fine, one_i);
        let has_next = _mm256_cmpgt_epi32(level_counts, next);
        let blends = _mm256_cmp_ps::<_CMP_NEQ_UQ>(blend, _mm256_setzero_ps());
        let use_coarser = _mm256_and_ps(
            _mm256_andnot_ps(fine_only, _mm256_castsi256_ps(has_next)),
            blends,
        );
        // Where no lane blends with a coarser level (all footprints within a texel, say), its
        // gathers are skipped, as the scalar path skips the second bilinear sample.
        if _mm256_movemask_ps(use_coarser) == 0 {
            return a;
        }
        let coarser_level = _mm256_min_epi32(next, _mm256_sub_epi32(level_counts, one_i));
        let half = _mm256_set1_ps(0.5);
        let b = self.bilinear8(
            level_start(coarser_level),
            size_log2,
            coarser_level,
            _mm256_mul_ps(us, half),
            _mm256_mul_ps(vs, half),
        );
        let mixed = _mm256_add_ps(a, _mm256_mul_ps(_mm256_sub_ps(b, a), blend));
        _mm256_blendv_ps(a, mixed, use_coarser)
    }

    /// `Level::bilinear` of level `level` (of a texture whose level 0 has side
    /// `1 << size_log2`), stored from index `start`, for eight lanes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn bilinear8(
        &self,
        start: std::arch::x86_64::__m256i,
        size_log2: std::arch::x86_64::__m256i,
        level: std::arch::x86_64::__m256i,
        u: std::arch::x86_64::__m256,
        v: std::arch::x86_64::__m256,
    ) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let half = _mm256_set1_ps(0.5);
        let (x, y) = (_mm256_sub_ps(u, half), _mm256_sub_ps(v, half));
        // fast_floor: truncate, minus one where the truncation rounded up.
        let floor = |value: __m256| {
            let truncated = _mm256_cvttps_epi32(value);
            let rounded_up = _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_cvtepi32_ps(truncated), value);
            _mm256_add_epi32(truncated, _mm256_castps_si256(rounded_up))
        };
        let (ix, iy) = (floor(x), floor(y));
        let fx = _mm256_sub_ps(x, _mm256_cvtepi32_ps(ix));
        let fy = _mm256_sub_ps(y, _mm256_cvtepi32_ps(iy));
        let side_log2 = _mm256_sub_epi32(size_log2, level);
        let one_i = _mm256_set1_epi32(1);
        let mask = _mm256_sub_epi32(_mm256_sllv_epi32(one_i, side_log2), one_i);
        let tile_log2 = _mm256_min_epi32(side_log2, _mm256_set1_epi32(TILE_LOG2));
        let tile_mask = _mm256_sub_epi32(_mm256_sllv_epi32(one_i, tile_log2), one_i);
        // `tiled_index`, split into its column and row parts.
        let tile_area_log2 = _mm256_add_epi32(tile_log2, tile_log2);
        let column = |x: __m256i| {
            let x = _mm256_and_si256(x, mask);
            _mm256_add_epi32(
                _mm256_sllv_epi32(_mm256_srlv_epi32(x, tile_log2), tile_area_log2),
                _mm256_and_si256(x, tile_mask),
            )
        };
        let tile_row_log2 = _mm256_add_epi32(side_log2, tile_log2);
        let row = |y: __m256i| {
            let y = _mm256_and_si256(y, mask);
            _mm256_add_epi32(
                start,
                _mm256_add_epi32(
                    _mm256_sllv_epi32(_mm256_srlv_epi32(y, tile_log2), tile_row_log2),
                    _mm256_sllv_epi32(_mm256_and_si256(y, tile_mask), tile_log2),
                ),
            )
        };
        let x0 = column(ix);
        let (row0, row1) = (row(iy), row(_mm256_add_epi32(iy, one_i)));
        let base = self.tiles.as_ptr().cast::<TexelPair>();
        // Both texels of a footprint row per lane, by scalar 8-byte loads (AMD Zen executes
        // gathers as microcode, slower than the loads they are made of), two lanes to a
        // 128-bit half, then split into the left and the right texels of the eight lanes.
        let pairs = |row: __m256i| {
            let mut index = [0i32; 8];
            _mm256_storeu_si256(index.as_mut_ptr().cast(), _mm256_add_epi32(row, x0));
            let two_lanes = |a: i32, b: i32| {
                let low = _mm_load_sd(base.add(a as usize).cast::<f64>());
                _mm_castpd_ps(_mm_loadh_pd(low, base.add(b as usize).cast::<f64>()))
            };
            let (lanes01, lanes23) = (two_lanes(index[0], index[1]), two_lanes(index[2], index[3]));
            let (lanes45, lanes67) = (two_lanes(index[4], index[5]), two_lanes(index[6], index[7]));
            let lanes0145 = _mm256_set_m128(lanes45, lanes01);
            let lanes2367 = _mm256_set_m128(lanes67, lanes23);
            (
                _mm256_shuffle_ps::<0b10_00_10_00>(lanes0145, lanes2367),
                _mm256_shuffle_ps::<0b11_01_11_01>(lanes0145, lanes2367),
            )
        };
        let ((left0, right0), (left1, right1)) = (pairs(row0), pairs(row1));
        let corners = [left0, right0, left1, right1];
        let corner = |k: usize| corners[k];
        let one = _mm256_set1_ps(1.0);
        let (gx, gy) = (_mm256_sub_ps(one, fx), _mm256_sub_ps(one, fy));
        let top = _mm256_add_ps(_mm256_mul_ps(corner(0), gx), _mm256_mul_ps(corner(1), fx));
        let bottom = _mm256_add_ps(_mm256_mul_ps(corner(2), gx), _mm256_mul_ps(corner(3), fx));
        _mm256_add_ps(_mm256_mul_ps(top, gy), _mm256_mul_ps(bottom, fy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::TextureStyle;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn tiled_index_is_a_permutation_of_each_level() {
        for side_log2 in 0..6 {
            let side = 1usize << side_log2;
            let mut seen = vec![false; side * side];
            for y in 0..side {
                for x in 0..side {
                    let index = tiled_index(x, y, side_log2);
                    assert!(!seen[index], "side {side}: ({x}, {y}) shares index {index}");
                    seen[index] = true;
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn gathered_samples_match_the_texture_bit_for_bit() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let textures: Vec<Texture> = [64, 8, 4, 1]
            .into_iter()
            .map(|size| Texture::generate(size, &TextureStyle::default(), &mut rng))
            .collect();
        let atlas = TextureAtlas::new(&textures);
        for _ in 0..2000 {
            // Half the blocks sample one texture in every lane (the broadcast path).
            let texture: [i32; 8] = if rng.gen_bool(0.5) {
                [rng.gen_range(0..4); 8]
            } else {
                std::array::from_fn(|_| rng.gen_range(0..4))
            };
            let u: [f32; 8] = std::array::from_fn(|_| rng.gen_range(-300.0..300.0));
            let v: [f32; 8] = std::array::from_fn(|_| rng.gen_range(-300.0..300.0));
            let footprint: [f32; 8] = std::array::from_fn(|_| 2f32.powf(rng.gen_range(-2.0..8.0)));
            // SAFETY: the CPU has AVX2 (checked above).
            let sampled = unsafe { atlas.sample8(&texture, &u, &v, &footprint) };
            for k in 0..8 {
                let expected = textures[texture[k] as usize].sample(u[k], v[k], footprint[k]);
                assert_eq!(
                    sampled[k].to_bits(),
                    expected.to_bits(),
                    "texture {} at ({}, {}), footprint {}",
                    texture[k],
                    u[k],
                    v[k],
                    footprint[k]
                );
            }
        }
    }
}
