//! ESIM-style pixel model: each pixel memorises the log intensity at its last event and fires
//! one event per threshold crossing, timed by linear interpolation between two renders.

use std::ops::Range;

use evgate_core::Event;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::event_model::EventModel;

/// An event with the id of the surface that caused it (0 = static world or noise).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LabelledEvent {
    pub event: Event,
    pub label: u16,
}

/// Per-pixel state, row-major.
#[derive(Clone, Debug)]
pub struct PixelState {
    reference: Vec<f32>,
    previous: Vec<f32>,
    previous_surface: Vec<u16>,
    threshold_on: Vec<f32>,
    threshold_off: Vec<f32>,
    last_event_us: Vec<i64>,
}

/// The part of [`PixelState`] belonging to a band of rows, for one worker thread.
pub struct PixelBand<'a> {
    first_pixel: usize,
    width: usize,
    reference: &'a mut [f32],
    previous: &'a mut [f32],
    previous_surface: &'a mut [u16],
    threshold_on: &'a [f32],
    threshold_off: &'a [f32],
    last_event_us: &'a mut [i64],
}

impl PixelState {
    /// Starts every pixel at the first rendered frame, with thresholds drawn around the model's
    /// means (normal mismatch, clamped at `threshold-min`).
    pub fn new(
        model: &EventModel,
        log_intensity: &[f32],
        surface: &[u16],
        rng: &mut ChaCha8Rng,
    ) -> PixelState {
        let pixels = log_intensity.len();
        let mut draw = |mean: f32| -> Vec<f32> {
            (0..pixels)
                .map(|_| {
                    (mean + model.threshold_sigma * standard_normal(rng)).max(model.threshold_min)
                })
                .collect()
        };
        let threshold_on = draw(model.threshold_on);
        let threshold_off = draw(model.threshold_off);
        PixelState {
            reference: log_intensity.to_vec(),
            previous: log_intensity.to_vec(),
            previous_surface: surface.to_vec(),
            threshold_on,
            threshold_off,
            last_event_us: vec![i64::MIN / 2; pixels],
        }
    }

    /// Splits the state into consecutive bands of `band_rows[k]` rows each (together at most
    /// the state's rows).
    pub fn bands(&mut self, width: usize, band_rows: &[usize]) -> Vec<PixelBand<'_>> {
        let (mut reference, mut previous, mut previous_surface) = (
            &mut self.reference[..],
            &mut self.previous[..],
            &mut self.previous_surface[..],
        );
        let (mut threshold_on, mut threshold_off, mut last_event_us) = (
            &self.threshold_on[..],
            &self.threshold_off[..],
            &mut self.last_event_us[..],
        );
        let mut first_pixel = 0;
        band_rows
            .iter()
            .map(|&rows| {
                let pixels = rows * width;
                let band = PixelBand {
                    first_pixel,
                    width,
                    reference: split_off_front(&mut reference, pixels),
                    previous: split_off_front(&mut previous, pixels),
                    previous_surface: split_off_front(&mut previous_surface, pixels),
                    threshold_on: split_off_front_shared(&mut threshold_on, pixels),
                    threshold_off: split_off_front_shared(&mut threshold_off, pixels),
                    last_event_us: split_off_front(&mut last_event_us, pixels),
                };
                first_pixel += pixels;
                band
            })
            .collect()
    }

    /// Whether pixel `index` may fire at `t_us` (outside its refractory period); if so, records
    /// the event.
    pub fn try_fire(&mut self, index: usize, t_us: i64, refractory_us: i64) -> bool {
        if t_us - self.last_event_us[index] < refractory_us {
            return false;
        }
        self.last_event_us[index] = t_us;
        true
    }
}

impl PixelBand<'_> {
    /// Compares the band's new render (at `t1_us`) with the previous one (at `t0_us`) and
    /// appends the events of every threshold crossing. A change between a moving object and
    /// anything else is attributed to the object (leading and trailing edges alike); between
    /// two objects, to the one now in front.
    pub fn emit(
        &mut self,
        log_intensity: &[f32],
        surface: &[u16],
        t0_us: i64,
        t1_us: i64,
        refractory_us: i64,
        out: &mut Vec<LabelledEvent>,
    ) {
        for (i, (&log, &id)) in log_intensity.iter().zip(surface).enumerate() {
            self.emit_pixel(i, log, id, t0_us, t1_us, refractory_us, out);
        }
    }

    /// [`PixelBand::emit`] for the band's pixel `i` alone, whose value at `t1_us` is `l1` on
    /// surface `surface` (its previous value is the one at `t0_us`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn emit_pixel(
        &mut self,
        i: usize,
        l1: f32,
        surface: u16,
        t0_us: i64,
        t1_us: i64,
        refractory_us: i64,
        out: &mut Vec<LabelledEvent>,
    ) {
        let reference = self.reference[i];
        // Most pixels cross no threshold in a step: that test stays inline, the crossings
        // are handled out of line.
        if l1 - reference >= self.threshold_on[i] || reference - l1 >= self.threshold_off[i] {
            self.fire(i, l1, surface, t0_us, t1_us, refractory_us, out);
        }
        self.previous[i] = l1;
        self.previous_surface[i] = surface;
    }

    /// [`PixelBand::emit_pixel`] on the static world (surface 0) for the band's pixels
    /// `pixels`, whose values at `t1_us` are `log_intensity`. The threshold tests run over
    /// blocks of pixels, eight per vector compare ([`list_crossing_blocks`]), which lists the
    /// pixels that cross: only those are visited.
    pub fn emit_static_run(
        &mut self,
        pixels: Range<usize>,
        log_intensity: &[f32],
        t0_us: i64,
        t1_us: i64,
        refractory_us: i64,
        out: &mut Vec<LabelledEvent>,
    ) {
        // Blocks with a crossing are listed first and their state that only a crossing reads
        // is prefetched: it is rarely in cache, and its loads would otherwise stall each
        // crossing in turn. A run is handled in chunks so that the list has a fixed size.
        const CHUNK_BLOCKS: usize = 64;
        let first = pixels.start;
        for chunk_start in (0..pixels.len()).step_by(BLOCK * CHUNK_BLOCKS) {
            let chunk_end = (chunk_start + BLOCK * CHUNK_BLOCKS).min(pixels.len());
            let mut crossing_blocks = [CrossingBlock::default(); CHUNK_BLOCKS];
            let chunk = first + chunk_start..first + chunk_end;
            let crossings = list_crossing_blocks(
                &log_intensity[chunk_start..chunk_end],
                &self.reference[chunk.clone()],
                &self.threshold_on[chunk.clone()],
                &self.threshold_off[chunk],
                &mut crossing_blocks,
            );
            let crossing_blocks = &crossing_blocks[..crossings];
            for block in crossing_blocks {
                let start = first + chunk_start + block.start;
                let end = (start + BLOCK).min(first + chunk_end);
                prefetch(&self.last_event_us[start]);
                prefetch(&self.last_event_us[end - 1]);
                prefetch(&self.previous[start]);
            }
            for block in crossing_blocks {
                let mut lanes = block.lanes;
                while lanes != 0 {
                    let offset = chunk_start + block.start + lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    let l1 = log_intensity[offset];
                    self.fire(first + offset, l1, 0, t0_us, t1_us, refractory_us, out);
                }
            }
        }
        self.previous[pixels.clone()].copy_from_slice(log_intensity);
        self.previous_surface[pixels].fill(0);
    }

    /// The events of pixel `i` crossing one or more thresholds on its way to `l1`.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn fire(
        &mut self,
        i: usize,
        l1: f32,
        surface: u16,
        t0_us: i64,
        t1_us: i64,
        refractory_us: i64,
        out: &mut Vec<LabelledEvent>,
    ) {
        let l0 = self.previous[i];
        let mut reference = self.reference[i];
        let (on, off) = (self.threshold_on[i], self.threshold_off[i]);
        let label = if surface != 0 {
            surface
        } else {
            self.previous_surface[i]
        };
        let span = (t1_us - t0_us) as f32;
        let pixel = self.first_pixel + i;
        let (x, y) = ((pixel % self.width) as u16, (pixel / self.width) as u16);
        let change = l1 - l0;
        let positive = l1 > reference;
        let step = if positive { on } else { -off };
        while (positive && l1 - reference >= on) || (!positive && reference - l1 >= off) {
            reference += step;
            let fraction = if change.abs() > 1e-9 {
                ((reference - l0) / change).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let t = (t0_us + ceil_non_negative(fraction * span)).clamp(t0_us + 1, t1_us);
            if t - self.last_event_us[i] >= refractory_us {
                self.last_event_us[i] = t;
                out.push(LabelledEvent {
                    event: Event::new(t, x, y, positive),
                    label,
                });
            }
        }
        self.reference[i] = reference;
    }
}

/// The first `len` elements of `slice`, which keeps the rest.
pub(crate) fn split_off_front<'a, T>(slice: &mut &'a mut [T], len: usize) -> &'a mut [T] {
    let (front, rest) = std::mem::take(slice).split_at_mut(len);
    *slice = rest;
    front
}

/// [`split_off_front`] for a shared slice.
pub(crate) fn split_off_front_shared<'a, T>(slice: &mut &'a [T], len: usize) -> &'a [T] {
    let (front, rest) = slice.split_at(len);
    *slice = rest;
    front
}

/// Pixels whose threshold tests [`list_crossing_blocks`] takes together.
const BLOCK: usize = 8;

/// A block of [`BLOCK`] pixels in which some pixel crosses a threshold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct CrossingBlock {
    /// Offset of the block's first pixel.
    start: usize,
    /// Bit k set where pixel `start + k` crosses.
    lanes: u8,
}

/// Writes to `blocks` each block of [`BLOCK`] pixels (the last may be shorter) in which some
/// pixel crosses a threshold on its way from `reference` to `log_intensity`, with the pixels
/// that do, and returns how many there are (`blocks` must have room for every block).
fn list_crossing_blocks(
    log_intensity: &[f32],
    reference: &[f32],
    on: &[f32],
    off: &[f32],
    blocks: &mut [CrossingBlock],
) -> usize {
    let n = log_intensity.len();
    assert!(reference.len() == n && on.len() == n && off.len() == n);
    assert!(blocks.len() >= n.div_ceil(BLOCK));
    #[cfg(target_arch = "x86_64")]
    let (mut count, scalar_from) = if std::is_x86_feature_detected!("avx2") {
        let whole = n / BLOCK * BLOCK;
        // SAFETY: the CPU supports AVX2, checked just above.
        let count = unsafe {
            list_whole_crossing_blocks_avx2(
                &log_intensity[..whole],
                &reference[..whole],
                &on[..whole],
                &off[..whole],
                blocks,
            )
        };
        (count, whole)
    } else {
        (0, 0)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let (mut count, scalar_from) = (0, 0);
    for start in (scalar_from..n).step_by(BLOCK) {
        let end = (start + BLOCK).min(n);
        let lanes = (start..end).fold(0u8, |lanes, i| {
            let (l1, reference) = (log_intensity[i], reference[i]);
            let crosses = (l1 - reference >= on[i]) | (reference - l1 >= off[i]);
            lanes | (u8::from(crosses) << (i - start))
        });
        if lanes != 0 {
            blocks[count] = CrossingBlock { start, lanes };
            count += 1;
        }
    }
    count
}

/// [`list_crossing_blocks`] for whole blocks (`log_intensity.len()` a multiple of [`BLOCK`]),
/// eight pixels per vector compare: the same tests, so the same blocks and pixels.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn list_whole_crossing_blocks_avx2(
    log_intensity: &[f32],
    reference: &[f32],
    on: &[f32],
    off: &[f32],
    blocks: &mut [CrossingBlock],
) -> usize {
    use std::arch::x86_64::*;
    let n = log_intensity.len();
    assert!(n.is_multiple_of(BLOCK) && reference.len() == n && on.len() == n && off.len() == n);
    assert!(blocks.len() >= n / BLOCK);
    let mut count = 0;
    for start in (0..n).step_by(BLOCK) {
        // SAFETY (loads): `start + 8 <= n` for every slice (asserted).
        let l1 = _mm256_loadu_ps(log_intensity.as_ptr().add(start));
        let reference = _mm256_loadu_ps(reference.as_ptr().add(start));
        let brighter = _mm256_cmp_ps::<_CMP_GE_OQ>(
            _mm256_sub_ps(l1, reference),
            _mm256_loadu_ps(on.as_ptr().add(start)),
        );
        let darker = _mm256_cmp_ps::<_CMP_GE_OQ>(
            _mm256_sub_ps(reference, l1),
            _mm256_loadu_ps(off.as_ptr().add(start)),
        );
        let lanes = _mm256_movemask_ps(_mm256_or_ps(brighter, darker)) as u8;
        // Written whether or not the block crosses, so that the loop does not branch.
        blocks[count] = CrossingBlock { start, lanes };
        count += (lanes != 0) as usize;
    }
    count
}

/// `x.ceil() as i64` for `x >= 0` (and NaN, which gives 0), inline: `f32::ceil` is a
/// library call on x86-64 without SSE4.1, and it was a tenth of the cost of each event.
#[inline(always)]
fn ceil_non_negative(x: f32) -> i64 {
    let truncated = x as i64;
    truncated + i64::from((truncated as f32) < x)
}

/// Asks the CPU to bring `value`'s cache line closer, without waiting for it.
#[inline(always)]
fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults and changes no memory; SSE is part of x86-64.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((value as *const T).cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

/// A standard normal draw (Box–Muller), avoiding a dependency for one distribution.
pub fn standard_normal(rng: &mut impl Rng) -> f32 {
    let u1: f32 = rng.gen_range(f32::EPSILON..1.0);
    let u2: f32 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn model() -> EventModel {
        EventModel {
            threshold_sigma: 0.0,
            refractory_us: 0,
            ..EventModel::default()
        }
    }

    #[test]
    fn one_event_per_threshold_crossing_with_interpolated_times() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut state = PixelState::new(&model(), &[0.0, 0.0], &[0, 0], &mut rng);
        let mut out = Vec::new();
        let mut bands = state.bands(2, &[1]);
        // Pixel 0 brightens by 0.5 log units (two ON events), pixel 1 darkens by 0.25 (one OFF).
        bands[0].emit(&[0.5, -0.25], &[0, 3], 1000, 2000, 0, &mut out);
        let times: Vec<(i64, bool, u16)> = out
            .iter()
            .map(|e| (e.event.t, e.event.is_on(), e.label))
            .collect();
        assert_eq!(
            times,
            vec![(1400, true, 0), (1800, true, 0), (1800, false, 3)]
        );
    }

    #[test]
    fn crossing_blocks_list_the_pixels_past_a_threshold() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for n in [0, 1, 7, 8, 9, 64, 100, 346] {
            let draw = |rng: &mut ChaCha8Rng, range: std::ops::Range<f32>| -> Vec<f32> {
                (0..n).map(|_| rng.gen_range(range.clone())).collect()
            };
            let reference = draw(&mut rng, -2.0..2.0);
            let on = draw(&mut rng, 0.1..0.3);
            let off = draw(&mut rng, 0.1..0.3);
            // Mostly small changes, as between two renders: some blocks cross, most not.
            let log: Vec<f32> = reference
                .iter()
                .map(|&r| {
                    let change = if rng.gen_bool(0.04) { 0.5 } else { 0.09 };
                    r + rng.gen_range(-change..change)
                })
                .collect();
            let expected: Vec<CrossingBlock> = (0..n)
                .step_by(BLOCK)
                .map(|start| CrossingBlock {
                    start,
                    lanes: (start..(start + BLOCK).min(n))
                        .filter(|&i| {
                            log[i] - reference[i] >= on[i] || reference[i] - log[i] >= off[i]
                        })
                        .map(|i| 1u8 << (i - start))
                        .sum(),
                })
                .filter(|block| block.lanes != 0)
                .collect();
            let mut blocks = vec![CrossingBlock::default(); n.div_ceil(BLOCK)];
            let count = list_crossing_blocks(&log, &reference, &on, &off, &mut blocks);
            assert_eq!(&blocks[..count], &expected[..], "{n} pixels");
            assert!(
                n < 64 || (0 < count && count < n / BLOCK),
                "{n} pixels: {count} crossing"
            );
            assert!(
                expected.iter().any(|block| block.lanes.count_ones() == 1) || n < 64,
                "{n} pixels: no block with a single crossing pixel"
            );
        }
    }

    #[test]
    fn inline_ceiling_matches_the_library_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let special = [
            0.0,
            -0.0,
            0.5,
            1.0,
            1.0 + f32::EPSILON,
            4999.999,
            5000.0,
            f32::NAN,
        ];
        let drawn = (0..100_000).map(|_| rng.gen_range(0.0f32..6000.0));
        for x in special.into_iter().chain(drawn) {
            assert_eq!(ceil_non_negative(x), x.ceil() as i64, "{x}");
        }
    }

    #[test]
    fn refractory_period_drops_close_events() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let refractory = EventModel {
            refractory_us: 500,
            ..model()
        };
        let mut state = PixelState::new(&refractory, &[0.0], &[0], &mut rng);
        let mut out = Vec::new();
        state.bands(1, &[1])[0].emit(&[1.0], &[0], 0, 1000, 500, &mut out);
        // Crossings at 200, 400, …, 1000 µs; each kept event silences the next 500 µs.
        let times: Vec<i64> = out.iter().map(|e| e.event.t).collect();
        assert_eq!(times, vec![200, 800]);
    }

    #[test]
    fn trailing_edge_of_an_object_is_labelled_with_the_object() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut state = PixelState::new(&model(), &[0.0], &[2], &mut rng);
        let mut out = Vec::new();
        state.bands(1, &[1])[0].emit(&[-1.0], &[0], 0, 100, 0, &mut out);
        assert!(!out.is_empty() && out.iter().all(|e| e.label == 2 && !e.event.is_on()));
    }
}
