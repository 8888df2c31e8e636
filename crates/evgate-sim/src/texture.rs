//! Procedural textures with edges at many scales, stored as mip pyramids so that distant or
//! slanted surfaces are filtered instead of aliasing (aliasing would make a static scene flicker
//! and emit spurious events). Texels hold log reflectance: the renderer adds log illumination
//! instead of taking a logarithm per pixel.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// How a texture looks: mean reflectance, contrast and the mix of pattern families.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default)]
pub struct TextureStyle {
    /// Mean reflectance in (0, 1].
    pub mean: f32,
    /// Half the peak-to-peak reflectance range, relative to the mean.
    pub contrast: f32,
    /// Weight of smooth multi-octave value noise (stains, shading, carpet).
    pub noise: f32,
    /// Shapes (rectangles and discs with hard edges) per 32×32-texel cell, summed over scales.
    pub shape_density: f32,
    /// Weight of periodic stripes (wood grain, tiles, lane markings).
    pub stripes: f32,
    /// Weight of 1/f noise: random-phase waves whose amplitude falls as one over their
    /// frequency, the amplitude spectrum of natural images.
    pub spectral: f32,
    /// Brush strokes and glyph-like marks (clusters of short curved strokes) per
    /// 32×32-texel cell.
    pub strokes: f32,
    /// Weight of one smooth shading gradient across the texture.
    pub gradient: f32,
    /// Share of the texture in large regions of low contrast (blank walls, paper, sky).
    pub flat_share: f32,
}

impl Default for TextureStyle {
    fn default() -> Self {
        Self {
            mean: 0.45,
            contrast: 0.8,
            noise: 0.5,
            shape_density: 1.0,
            stripes: 0.0,
            spectral: 0.0,
            strokes: 0.0,
            gradient: 0.0,
            flat_share: 0.0,
        }
    }
}

/// A square, tileable log-reflectance texture with its mip levels (level 0 is the finest).
#[derive(Clone, Debug)]
pub struct Texture {
    levels: Vec<Level>,
}

#[derive(Clone, Debug)]
struct Level {
    size: usize,
    texels: Vec<f32>,
    /// For each texel, itself and its right, lower and lower-right neighbours (wrapping):
    /// a bilinear sample reads one 16-byte entry instead of four scattered texels.
    quads: Vec<[f32; 4]>,
}

impl Level {
    fn new(size: usize, texels: Vec<f32>) -> Level {
        let mask = size - 1;
        let quads = (0..size * size)
            .map(|index| {
                let (x, y) = (index & mask, index / size);
                let (right, below) = ((x + 1) & mask, ((y + 1) & mask) * size);
                [
                    texels[y * size + x],
                    texels[y * size + right],
                    texels[below + x],
                    texels[below + right],
                ]
            })
            .collect();
        Level {
            size,
            texels,
            quads,
        }
    }

    /// Bilinear sample at continuous texel coordinates, wrapping around the edges.
    #[inline(always)]
    fn bilinear(&self, u: f32, v: f32) -> f32 {
        let x = u - 0.5;
        let y = v - 0.5;
        let (ix, iy) = (fast_floor(x), fast_floor(y));
        let fx = x - ix as f32;
        let fy = y - iy as f32;
        let mask = self.size as i32 - 1;
        let index = (iy & mask) as usize * self.size + (ix & mask) as usize;
        // `quads` holds size² (a power of two) entries, so the index is already below that;
        // masking it again lets the compiler drop the bounds check of this hot lookup.
        let [a, b, c, d] = self.quads[index & (self.quads.len() - 1)];
        let top = a * (1.0 - fx) + b * fx;
        let bottom = c * (1.0 - fx) + d * fx;
        top * (1.0 - fy) + bottom * fy
    }

    fn downsampled(&self) -> Level {
        let size = self.size / 2;
        let mut texels = vec![0.0; size * size];
        for y in 0..size {
            for x in 0..size {
                let (sx, sy) = (2 * x, 2 * y);
                let n = self.size;
                texels[y * size + x] = 0.25
                    * (self.texels[sy * n + sx]
                        + self.texels[sy * n + sx + 1]
                        + self.texels[(sy + 1) * n + sx]
                        + self.texels[(sy + 1) * n + sx + 1]);
            }
        }
        Level::new(size, texels)
    }
}

impl TextureStyle {
    /// No pattern at all: a base to switch single families on.
    pub fn blank() -> Self {
        Self {
            noise: 0.0,
            shape_density: 0.0,
            ..Self::default()
        }
    }
}

impl Texture {
    /// Builds a texture from level-0 log-reflectance texels (`size` must be a power of two).
    pub fn from_texels(size: usize, texels: Vec<f32>) -> Texture {
        assert!(size.is_power_of_two() && texels.len() == size * size);
        let mut levels = vec![Level::new(size, texels)];
        while levels.last().map(|l| l.size).unwrap_or(1) > 1 {
            let next = levels
                .last()
                .map(Level::downsampled)
                .unwrap_or_else(|| unreachable!());
            levels.push(next);
        }
        Texture { levels }
    }

    /// Generates a texture of `size`×`size` texels in the given style.
    pub fn generate(size: usize, style: &TextureStyle, rng: &mut impl Rng) -> Texture {
        let mut texels = vec![0.0f32; size * size];
        add_value_noise(&mut texels, size, style.noise, rng);
        add_shapes(&mut texels, size, style.shape_density, rng);
        add_stripes(&mut texels, size, style.stripes, rng);
        // The families below draw from `rng` only when used, so textures without them (every
        // suite before version 5) are unchanged.
        add_spectral_noise(&mut texels, size, style.spectral, rng);
        add_strokes(&mut texels, size, style.strokes, rng);
        add_gradient(&mut texels, size, style.gradient, rng);
        flatten_regions(&mut texels, size, style.flat_share, rng);
        normalise(&mut texels, style.mean, style.contrast);
        for texel in texels.iter_mut() {
            *texel = texel.ln();
        }
        Texture::from_texels(size, texels)
    }

    /// The texels of each mip level (row-major), finest first.
    pub fn level_texels(&self) -> Vec<&[f32]> {
        self.levels.iter().map(|level| &level.texels[..]).collect()
    }

    /// Side of level 0 in texels.
    pub fn size(&self) -> usize {
        self.levels[0].size
    }

    /// Log reflectance at level-0 texel coordinates (u, v), filtered for a pixel footprint of
    /// `footprint` texels (trilinear between the two nearest mip levels).
    #[inline(always)]
    pub fn sample(&self, u: f32, v: f32, footprint: f32) -> f32 {
        if footprint <= 1.0 {
            return self.levels[0].bilinear(u, v);
        }
        let level = approximate_log2(footprint).min((self.levels.len() - 1) as f32);
        // `level` is positive here (footprint > 1): truncation is its floor, without a call.
        let fine = level as usize;
        let blend = level - fine as f32;
        // 2^-fine, built from its exponent bits: exact, as the division it replaces.
        let scale = f32::from_bits((127 - fine as u32) << 23);
        let a = self.levels[fine].bilinear(u * scale, v * scale);
        if fine + 1 >= self.levels.len() || blend == 0.0 {
            return a;
        }
        let b = self.levels[fine + 1].bilinear(u * scale * 0.5, v * scale * 0.5);
        a + (b - a) * blend
    }
}

/// Floor of `x` as an integer; without SSE4.1 `f32::floor` is a library call, and this runs
/// eight times per pixel. Values beyond ±2³¹ saturate (texture coordinates never get there).
fn fast_floor(x: f32) -> i32 {
    let truncated = x as i32;
    truncated - ((truncated as f32) > x) as i32
}

/// Piecewise-linear log2 (exact at powers of two, continuous and monotonic in between): the
/// mip level only needs to be smooth, not exact.
fn approximate_log2(x: f32) -> f32 {
    let bits = x.to_bits();
    let exponent = ((bits >> 23) & 0xff) as f32 - 127.0;
    let mantissa = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    exponent + mantissa - 1.0
}

/// Smooth noise: random values on coarse grids, interpolated with a smoothstep, octaves halving
/// in cell size and amplitude.
fn add_value_noise(texels: &mut [f32], size: usize, weight: f32, rng: &mut impl Rng) {
    if weight <= 0.0 {
        return;
    }
    add_value_noise_octaves(texels, size, weight, 4, size / 2, rng);
}

/// Value-noise octaves from `first_cells` to `last_cells` grid cells per side.
fn add_value_noise_octaves(
    texels: &mut [f32],
    size: usize,
    weight: f32,
    first_cells: usize,
    last_cells: usize,
    rng: &mut impl Rng,
) {
    let mut cells = first_cells;
    let mut amplitude = weight;
    while cells <= last_cells {
        let grid: Vec<f32> = (0..cells * cells)
            .map(|_| rng.gen_range(-1.0..1.0))
            .collect();
        let cell = size as f32 / cells as f32;
        // The grid cells and blend weight of each column (rows use the same), computed once
        // per octave rather than once per texel.
        let lattice: Vec<(usize, usize, f32)> = (0..size)
            .map(|i| {
                let g = i as f32 / cell;
                let (low, blend) = (g.floor() as usize % cells, smoothstep(g.fract()));
                (low, (low + 1) % cells, blend)
            })
            .collect();
        for (y, &(y0, y1, fy)) in lattice.iter().enumerate() {
            for (x, &(x0, x1, fx)) in lattice.iter().enumerate() {
                let top = grid[y0 * cells + x0] * (1.0 - fx) + grid[y0 * cells + x1] * fx;
                let bottom = grid[y1 * cells + x0] * (1.0 - fx) + grid[y1 * cells + x1] * fx;
                texels[y * size + x] += amplitude * (top * (1.0 - fy) + bottom * fy);
            }
        }
        cells *= 2;
        amplitude *= 0.55;
    }
}

fn smoothstep(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// Hard-edged rectangles and discs from a quarter of the texture down to a few texels, each
/// with its own grey level and opacity, so edges of every scale and contrast appear.
fn add_shapes(texels: &mut [f32], size: usize, density: f32, rng: &mut impl Rng) {
    if density <= 0.0 {
        return;
    }
    let mut extent = size / 4;
    while extent >= 3 {
        let cells = (size as f32 / 32.0).powi(2);
        let count = (density * cells * (32.0 / extent as f32).min(4.0) / 3.0).ceil() as usize;
        for _ in 0..count {
            let w = rng.gen_range(extent / 2..=extent) as i64;
            let h = rng.gen_range(extent / 2..=extent) as i64;
            let cx = rng.gen_range(0..size) as i64;
            let cy = rng.gen_range(0..size) as i64;
            let value: f32 = rng.gen_range(-1.2..1.2);
            let opacity: f32 = rng.gen_range(0.3..1.0);
            let disc = rng.gen_bool(0.4);
            for dy in -h / 2..=h / 2 {
                for dx in -w / 2..=w / 2 {
                    if disc {
                        let (nx, ny) = (dx as f32 / (w as f32 / 2.0), dy as f32 / (h as f32 / 2.0));
                        if nx * nx + ny * ny > 1.0 {
                            continue;
                        }
                    }
                    let x = (cx + dx).rem_euclid(size as i64) as usize;
                    let y = (cy + dy).rem_euclid(size as i64) as usize;
                    let texel = &mut texels[y * size + x];
                    *texel += (value - *texel) * opacity;
                }
            }
        }
        extent /= 2;
    }
}

/// Periodic square-wave stripes with a random period and orientation that tile seamlessly.
fn add_stripes(texels: &mut [f32], size: usize, weight: f32, rng: &mut impl Rng) {
    if weight <= 0.0 {
        return;
    }
    // Integer wave numbers along both axes keep the pattern tileable.
    let kx = rng.gen_range(0..6) as f32;
    let ky = rng.gen_range(1..10) as f32;
    let duty: f32 = rng.gen_range(0.2..0.6);
    for y in 0..size {
        for x in 0..size {
            let phase = (kx * x as f32 + ky * y as f32) / size as f32;
            let stripe = if phase.fract() < duty { 1.0 } else { -1.0 };
            texels[y * size + x] += weight * stripe;
        }
    }
}

/// 1/f noise: 48 tileable waves (integer wave numbers) with log-uniform frequencies from one
/// period per texture to one per 4 texels, random orientations and phases, amplitude ∝ 1/f.
fn add_spectral_noise(texels: &mut [f32], size: usize, weight: f32, rng: &mut impl Rng) {
    if weight <= 0.0 {
        return;
    }
    const WAVES: usize = 48;
    let highest = (size as f32 / 4.0).max(1.0);
    let mut waves = Vec::with_capacity(WAVES);
    while waves.len() < WAVES {
        let frequency = highest.powf(rng.gen_range(0.0..1.0f32));
        let angle = rng.gen_range(0.0..std::f32::consts::TAU);
        let (kx, ky) = (
            (frequency * angle.cos()).round(),
            (frequency * angle.sin()).round(),
        );
        let phase = rng.gen_range(0.0..std::f32::consts::TAU);
        if kx == 0.0 && ky == 0.0 {
            continue;
        }
        let amplitude = weight / (kx * kx + ky * ky).sqrt();
        waves.push((kx, ky, phase, amplitude));
    }
    let step = std::f32::consts::TAU / size as f32;
    for y in 0..size {
        for x in 0..size {
            let texel = &mut texels[y * size + x];
            for &(kx, ky, phase, amplitude) in &waves {
                *texel += amplitude * ((kx * x as f32 + ky * y as f32) * step + phase).sin();
            }
        }
    }
}

/// Curved brush strokes (quadratic Bézier curves stamped with a round brush) and glyph-like
/// marks (two to four short strokes inside a small box), each with its own grey and opacity.
fn add_strokes(texels: &mut [f32], size: usize, density: f32, rng: &mut impl Rng) {
    if density <= 0.0 {
        return;
    }
    let cells = (size as f32 / 32.0).powi(2);
    let marks = (density * cells).ceil() as usize;
    for _ in 0..marks {
        let value: f32 = rng.gen_range(-1.2..1.2);
        let opacity: f32 = rng.gen_range(0.4..1.0);
        let origin = (
            rng.gen_range(0.0..size as f32),
            rng.gen_range(0.0..size as f32),
        );
        let glyph = rng.gen_bool(0.4);
        let (strokes, reach, width) = if glyph {
            (
                rng.gen_range(2..=4),
                rng.gen_range(3.0..8.0f32),
                rng.gen_range(0.8..1.8f32),
            )
        } else {
            (
                1,
                rng.gen_range(4.0..(size as f32 / 6.0).max(5.0)),
                rng.gen_range(1.0..4.0f32),
            )
        };
        for _ in 0..strokes {
            let mut point = || {
                (
                    origin.0 + rng.gen_range(-reach..reach),
                    origin.1 + rng.gen_range(-reach..reach),
                )
            };
            let (a, control, b) = (point(), point(), point());
            stamp_curve(texels, size, [a, control, b], width, value, opacity);
        }
    }
}

/// Stamps a round brush of `width` texels along a quadratic Bézier curve, wrapping around.
fn stamp_curve(
    texels: &mut [f32],
    size: usize,
    [a, c, b]: [(f32, f32); 3],
    width: f32,
    value: f32,
    opacity: f32,
) {
    let length = ((a.0 - c.0).hypot(a.1 - c.1) + (c.0 - b.0).hypot(c.1 - b.1)).max(1.0);
    let steps = (length * 2.0).ceil() as usize;
    let radius = width / 2.0;
    let reach = radius.ceil() as i64;
    let mut painted = std::collections::HashSet::new();
    for step in 0..=steps {
        let t = step as f32 / steps as f32;
        let (u, v) = (1.0 - t, t);
        let x = u * u * a.0 + 2.0 * u * v * c.0 + v * v * b.0;
        let y = u * u * a.1 + 2.0 * u * v * c.1 + v * v * b.1;
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let (px, py) = (x.floor() as i64 + dx, y.floor() as i64 + dy);
                let (cx, cy) = (px as f32 + 0.5 - x, py as f32 + 0.5 - y);
                if cx * cx + cy * cy > radius * radius + 0.25 {
                    continue;
                }
                let index = py.rem_euclid(size as i64) as usize * size
                    + px.rem_euclid(size as i64) as usize;
                // Each texel once per stroke, so overlapping brush stamps do not stack.
                if painted.insert(index) {
                    let texel = &mut texels[index];
                    *texel += (value - *texel) * opacity;
                }
            }
        }
    }
}

/// One smooth period of shading across the texture in a random direction (tileable).
fn add_gradient(texels: &mut [f32], size: usize, weight: f32, rng: &mut impl Rng) {
    if weight <= 0.0 {
        return;
    }
    let (kx, ky) = [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, -1.0)][rng.gen_range(0..4)];
    let phase = rng.gen_range(0.0..std::f32::consts::TAU);
    let step = std::f32::consts::TAU / size as f32;
    for y in 0..size {
        for x in 0..size {
            texels[y * size + x] += weight * ((kx * x as f32 + ky * y as f32) * step + phase).cos();
        }
    }
}

/// Pulls `share` of the texture, in a few large blobs (a coarse noise field above its
/// quantile), to nearly one level: a tenth of its contrast is left there, with a soft border.
fn flatten_regions(texels: &mut [f32], size: usize, share: f32, rng: &mut impl Rng) {
    if share <= 0.0 {
        return;
    }
    let mut field = vec![0.0f32; size * size];
    add_value_noise_octaves(&mut field, size, 1.0, 4, 8, rng);
    let mut ranked = field.clone();
    let rank = ((1.0 - share.min(1.0)) * (ranked.len() - 1) as f32) as usize;
    let (_, &mut cut, _) = ranked.select_nth_unstable_by(rank, f32::total_cmp);
    let soft = 0.05;
    let level = texels.iter().sum::<f32>() / texels.len() as f32;
    for (texel, &f) in texels.iter_mut().zip(&field) {
        let flat = smoothstep(((f - cut) / soft + 0.5).clamp(0.0, 1.0));
        *texel += (level + (*texel - level) * 0.1 - *texel) * flat;
    }
}

/// Maps texel values linearly to `mean ± mean·contrast`, clamped to a positive reflectance.
fn normalise(texels: &mut [f32], mean: f32, contrast: f32) {
    let (lo, hi) = texels
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let centre = texels.iter().sum::<f32>() / texels.len() as f32;
    let half_range = (hi - centre).max(centre - lo).max(1e-6);
    for texel in texels.iter_mut() {
        let unit = (*texel - centre) / half_range;
        *texel = (mean * (1.0 + contrast * unit)).clamp(0.01, 1.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn generated_texture_has_contrast_and_stays_in_range() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let texture = Texture::generate(64, &TextureStyle::default(), &mut rng);
        let samples: Vec<f32> = (0..64)
            .map(|i| texture.sample(i as f32 + 0.5, 10.5, 1.0).exp())
            .collect();
        let lo = samples.iter().cloned().fold(f32::MAX, f32::min);
        let hi = samples.iter().cloned().fold(f32::MIN, f32::max);
        assert!(lo >= 0.0099 && hi <= 1.0001);
        assert!(
            hi - lo > 0.1,
            "a row of the texture is almost flat: {lo}..{hi}"
        );
    }

    #[test]
    fn coarse_levels_average_the_texture() {
        let texels: Vec<f32> = (0..16)
            .map(|i| if i % 2 == 0 { 0.2 } else { 0.6 })
            .collect();
        let texture = Texture::from_texels(4, texels);
        assert!((texture.sample(1.3, 2.7, 4.0) - 0.4).abs() < 1e-5);
        assert!((texture.sample(1.3, 2.7, 1e6) - 0.4).abs() < 1e-5);
    }

    #[test]
    fn fast_helpers_match_the_library() {
        for x in [-3.5f32, -1.0, -0.25, 0.0, 0.75, 2.0, 1e6] {
            assert_eq!(fast_floor(x), x.floor() as i32, "{x}");
        }
        for x in [1.0f32, 2.0, 8.0, 1024.0] {
            assert_eq!(approximate_log2(x), x.log2());
        }
        assert!((approximate_log2(3.0) - 3f32.log2()).abs() < 0.1);
    }

    fn row_spread(texture: &Texture, row: f32) -> f32 {
        let samples: Vec<f32> = (0..texture.size())
            .map(|i| texture.sample(i as f32 + 0.5, row, 1.0))
            .collect();
        let lo = samples.iter().cloned().fold(f32::MAX, f32::min);
        let hi = samples.iter().cloned().fold(f32::MIN, f32::max);
        hi - lo
    }

    #[test]
    fn every_family_alone_makes_a_textured_image_in_range() {
        let families = [
            TextureStyle {
                spectral: 1.0,
                ..TextureStyle::blank()
            },
            TextureStyle {
                strokes: 2.0,
                ..TextureStyle::blank()
            },
            TextureStyle {
                gradient: 1.0,
                ..TextureStyle::blank()
            },
        ];
        for style in families {
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let texture = Texture::generate(128, &style, &mut rng);
            let texels = texture.level_texels()[0];
            assert!(texels
                .iter()
                .all(|t| t.exp() >= 0.0099 && t.exp() <= 1.0001));
            let spread = (0..128)
                .map(|row| row_spread(&texture, row as f32 + 0.5))
                .fold(0.0, f32::max);
            assert!(spread > 0.1, "{style:?} left the texture flat");
        }
    }

    #[test]
    fn flat_regions_cover_their_share_with_little_contrast() {
        let busy = TextureStyle {
            noise: 0.0,
            shape_density: 0.0,
            spectral: 1.0,
            ..TextureStyle::default()
        };
        let flat = TextureStyle {
            flat_share: 0.5,
            ..busy
        };
        let gradients = |style: &TextureStyle| -> Vec<f32> {
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            let texture = Texture::generate(128, style, &mut rng);
            let texels = texture.level_texels()[0];
            let mut steps: Vec<f32> = (0..128 * 127)
                .map(|i| (i / 127) * 128 + i % 127)
                .map(|i| (texels[i + 1] - texels[i]).abs())
                .collect();
            steps.sort_by(f32::total_cmp);
            steps
        };
        let (busy_steps, flat_steps) = (gradients(&busy), gradients(&flat));
        // The quietest third of the texture is much quieter with half of it flattened.
        let third = busy_steps.len() / 3;
        assert!(flat_steps[third] < busy_steps[third] * 0.5);
    }

    #[test]
    fn sampling_wraps_around() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let texture = Texture::generate(32, &TextureStyle::default(), &mut rng);
        assert!((texture.sample(3.5, 7.25, 1.0) - texture.sample(35.5, -24.75, 1.0)).abs() < 1e-5);
    }
}
