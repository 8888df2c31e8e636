//! The per-event gating kernel: every event is kept or suppressed by the mask bit of its pixel,
//! and with a forecast, by the mask of the horizon its time falls into.

use serde::{Deserialize, Serialize};

use crate::event::Event;
use crate::geometry::SensorSize;
use crate::mask::{words_for, MaskError, MaskView};

/// Why a gating call could not run.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum GateError {
    #[error("keep bitmap has {actual} words, {events} events need {required}")]
    BitmapTooShort {
        actual: usize,
        required: usize,
        events: usize,
    },
    #[error("forecast needs at least one horizon, got none")]
    NoHorizons,
    #[error("forecast horizon {index} is {horizon_us} µs; horizons must be ≥ 0 µs")]
    NegativeHorizon { index: usize, horizon_us: i64 },
    #[error(
        "forecast horizons must increase strictly: horizon {index} is {horizon_us} µs after \
         {previous_us} µs"
    )]
    HorizonsNotIncreasing {
        index: usize,
        horizon_us: i64,
        previous_us: i64,
    },
    #[error(
        "forecast with {horizons} horizons over a {size} sensor needs {expected} mask words, \
         got {actual}"
    )]
    MaskWordCount {
        horizons: usize,
        size: SensorSize,
        expected: usize,
        actual: usize,
    },
    #[error("forecast mask {index}: {source}")]
    Mask { index: usize, source: MaskError },
}

/// Which events pass the gate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GateMode {
    /// Keep the events of independently moving objects (pixels in the mask), suppress the rest.
    KeepMovingObjects,
    /// Keep the ego-motion events (pixels outside the mask), e.g. for visual odometry.
    KeepEgoMotion,
}

impl GateMode {
    /// The value XOR-ed with a mask bit to get the keep bit.
    const fn inversion(self) -> u64 {
        match self {
            GateMode::KeepMovingObjects => 0,
            GateMode::KeepEgoMotion => 1,
        }
    }
}

/// Where the events of one gating call went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct GateCounts {
    pub kept: usize,
    pub suppressed: usize,
    /// Events no mask could judge (outside the sensor, or outside the forecast's time range).
    pub unjudged: usize,
}

/// What the kernel needs of a mask, in registers.
#[derive(Clone, Copy)]
struct MaskLookup<'a> {
    words: &'a [u64],
    width: u32,
    height: u32,
}

impl<'a> MaskLookup<'a> {
    fn new(mask: MaskView<'a>) -> Self {
        let size = mask.size();
        Self {
            words: mask.as_words(),
            width: u32::from(size.width),
            height: u32::from(size.height),
        }
    }

    /// (1 if the pixel lies on the sensor, its mask bit or 0 off the sensor), without branches.
    #[inline(always)]
    fn probe(&self, event: &Event) -> (u64, u64) {
        let (x, y) = (u32::from(event.x), u32::from(event.y));
        let inside = (x < self.width) & (y < self.height);
        // Off-sensor events read pixel 0 (the mask is never empty) and are masked out below.
        let index = (u32::from(inside) * (y * self.width + x)) as usize;
        let bit = self.words[index / 64] >> (index % 64) & 1;
        (u64::from(inside), bit & u64::from(inside))
    }
}

/// Appends each event to `kept` or `suppressed` by the mask bit of its pixel (order preserved
/// in both); events off the sensor count as outside the mask. Returns the number kept.
pub fn partition(
    events: &[Event],
    mask: MaskView<'_>,
    mode: GateMode,
    kept: &mut Vec<Event>,
    suppressed: &mut Vec<Event>,
) -> usize {
    let lookup = MaskLookup::new(mask);
    let inversion = mode.inversion();
    let mut outputs = Outputs::new([kept, suppressed], events.len());
    outputs.route(events, |event| {
        let (_, bit) = lookup.probe(event);
        bit ^ inversion
    });
    let [kept_count, _] = outputs.finish();
    kept_count
}

/// Writes one keep bit per event into `keep` (bit i of word i / 64 for event i; the rest of the
/// last word cleared); events off the sensor count as outside the mask. Returns the number
/// kept.
pub fn keep_bitmap(
    events: &[Event],
    mask: MaskView<'_>,
    mode: GateMode,
    keep: &mut [u64],
) -> Result<usize, GateError> {
    check_bitmap(keep, events.len())?;
    let lookup = MaskLookup::new(mask);
    let inversion = mode.inversion();
    let mut kept = 0;
    let mut sinks = BitSinks::new([keep]);
    sinks.extend(events, |event| {
        let (_, bit) = lookup.probe(event);
        let keep_bit = bit ^ inversion;
        kept += keep_bit as usize;
        [keep_bit]
    });
    sinks.finish();
    Ok(kept)
}

fn check_bitmap(words: &[u64], events: usize) -> Result<(), GateError> {
    let required = events.div_ceil(64);
    if words.len() < required {
        return Err(GateError::BitmapTooShort {
            actual: words.len(),
            required,
            events,
        });
    }
    Ok(())
}

/// Positions of the output vectors of a partition.
const KEPT: usize = 0;
const SUPPRESSED: usize = 1;
const UNJUDGED: usize = 2;

/// The output vectors of a partition (kept, suppressed and, for a forecast, unjudged), filled
/// without a branch per event.
struct Outputs<'a, const N: usize> {
    vectors: [&'a mut Vec<Event>; N],
    written: [usize; N],
}

impl<'a, const N: usize> Outputs<'a, N> {
    fn new(mut vectors: [&'a mut Vec<Event>; N], events: usize) -> Self {
        for vector in &mut vectors {
            vector.reserve(events);
        }
        let written = vectors.each_ref().map(|vector| vector.len());
        Self { vectors, written }
    }

    /// Appends each event of `events` to the kept vector when `keep_of` gives 1, to the
    /// suppressed one when it gives 0. At most as many events as were announced to `new` may be
    /// routed in all.
    #[inline(always)]
    fn route(&mut self, events: &[Event], keep_of: impl Fn(&Event) -> u64) {
        // Bases and cursors live in locals for the loop: kept behind `&mut Vec`, every write
        // of an event would make the compiler reload them.
        let kept_base = self.vectors[KEPT].as_mut_ptr();
        let suppressed_base = self.vectors[SUPPRESSED].as_mut_ptr();
        let [mut kept, mut suppressed] = [self.written[KEPT], self.written[SUPPRESSED]];
        for event in events {
            let keep = keep_of(event) as usize;
            debug_assert!(kept < self.vectors[KEPT].capacity());
            debug_assert!(suppressed < self.vectors[SUPPRESSED].capacity());
            // Branch-free: write at both cursors and advance only the chosen one.
            // SAFETY: `new` reserved one slot per announced event beyond each initial length,
            // and each event advances one cursor, so both cursors stay below capacity.
            unsafe {
                kept_base.add(kept).write(*event);
                suppressed_base.add(suppressed).write(*event);
            }
            kept += keep;
            suppressed += 1 - keep;
        }
        [self.written[KEPT], self.written[SUPPRESSED]] = [kept, suppressed];
    }

    /// Appends the events of `chunk` (at most 64) whose bit is set in `bits` to vector `index`,
    /// in order; set bits are found by trailing-zero counts, a full word is one copy.
    #[inline(always)]
    fn push_selected(&mut self, index: usize, chunk: &[Event], bits: u64) {
        let all = u64::MAX >> (64 - chunk.len());
        if bits == all {
            self.push_all_into(index, chunk);
            return;
        }
        let base = self.vectors[index].as_mut_ptr();
        let mut written = self.written[index];
        let mut rest = bits & all;
        while rest != 0 {
            let event = chunk[rest.trailing_zeros() as usize];
            debug_assert!(written < self.vectors[index].capacity());
            // SAFETY: `new` reserved one slot per announced event and each event is pushed
            // once, into one vector.
            unsafe { base.add(written).write(event) };
            written += 1;
            rest &= rest - 1;
        }
        self.written[index] = written;
    }

    /// Appends `events` to vector `index`.
    fn push_all_into(&mut self, index: usize, events: &[Event]) {
        let (vector, written) = (&mut self.vectors[index], &mut self.written[index]);
        debug_assert!(*written + events.len() <= vector.capacity());
        // SAFETY: as in `route`: the slots were reserved by `new`, and the source is a
        // caller's slice, which cannot overlap the vector's spare capacity.
        unsafe {
            std::ptr::copy_nonoverlapping(
                events.as_ptr(),
                vector.as_mut_ptr().add(*written),
                events.len(),
            )
        };
        *written += events.len();
    }

    /// Commits the written events; returns how many each vector gained.
    fn finish(self) -> [usize; N] {
        let mut gained = [0; N];
        for ((vector, written), gain) in self.vectors.into_iter().zip(self.written).zip(&mut gained)
        {
            *gain = written - vector.len();
            // SAFETY: every slot below `written` was initialised by `route`, `push_selected`
            // or `push_all_into`.
            unsafe { vector.set_len(written) };
        }
        gained
    }
}

/// Packs `N` bits per event into `N` bitmaps (bit i of word i / 64 for event i), filling whole
/// words 64 events at a time where a run of events allows.
struct BitSinks<'a, const N: usize> {
    bitmaps: [&'a mut [u64]; N],
    index: usize,
    partial: [u64; N],
}

impl<'a, const N: usize> BitSinks<'a, N> {
    /// The bitmaps must hold a bit for every event that will be pushed (see `check_bitmap`).
    fn new(bitmaps: [&'a mut [u64]; N]) -> Self {
        Self {
            bitmaps,
            index: 0,
            partial: [0; N],
        }
    }

    #[inline(always)]
    fn push(&mut self, bits: [u64; N]) {
        for (partial, bit) in self.partial.iter_mut().zip(bits) {
            *partial |= bit << (self.index % 64);
        }
        self.index += 1;
        if self.index.is_multiple_of(64) {
            self.flush();
        }
    }

    fn flush(&mut self) {
        let word = (self.index - 1) / 64;
        for (bitmap, partial) in self.bitmaps.iter_mut().zip(&mut self.partial) {
            bitmap[word] = std::mem::take(partial);
        }
    }

    /// Pushes the bits of every event of `run`, in order.
    #[inline(always)]
    fn extend(&mut self, run: &[Event], mut bits_of: impl FnMut(&Event) -> [u64; N]) {
        let head = ((64 - self.index % 64) % 64).min(run.len());
        for event in &run[..head] {
            self.push(bits_of(event));
        }
        let mut chunks = run[head..].chunks_exact(64);
        for chunk in &mut chunks {
            let mut words = [0u64; N];
            for (position, event) in chunk.iter().enumerate() {
                for (word, bit) in words.iter_mut().zip(bits_of(event)) {
                    *word |= bit << position;
                }
            }
            for (bitmap, word) in self.bitmaps.iter_mut().zip(words) {
                bitmap[self.index / 64] = word;
            }
            self.index += 64;
        }
        for event in chunks.remainder() {
            self.push(bits_of(event));
        }
    }

    /// Writes the last, partly filled words (their unused bits clear).
    fn finish(mut self) {
        if !self.index.is_multiple_of(64) {
            self.index += 64 - self.index % 64;
            self.flush();
        }
    }
}

/// A forecast as the gate reads it: the reference time t, horizons h_1 < … < h_K and one mask
/// per horizon, stored back to back as packed words (the shared-memory layout).
///
/// An event at τ is judged by the mask whose interval contains d = τ − t. Mask 1 covers d from
/// 0; mask k (k > 1) starts at the midpoint between h_{k−1} and h_k (rounded up to a whole µs,
/// so an event exactly at a midpoint goes to the later mask); each mask ends where the next
/// starts. The last mask covers up to and including the valid limit h_K + (h_K − h_{K−1})/2
/// (rounded down), or h_1 when K = 1. Events with d < 0 or beyond the limit are unjudged, as are
/// events off the sensor.
#[derive(Clone, Copy, Debug)]
pub struct ForecastView<'a> {
    reference_time_us: i64,
    horizons_us: &'a [i64],
    size: SensorSize,
    mask_words: &'a [u64],
}

impl<'a> ForecastView<'a> {
    /// Checks the horizons (non-empty, ≥ 0, strictly increasing) and that `mask_words` holds
    /// exactly one valid mask of `size` per horizon.
    pub fn new(
        reference_time_us: i64,
        horizons_us: &'a [i64],
        size: SensorSize,
        mask_words: &'a [u64],
    ) -> Result<Self, GateError> {
        let Some(&first) = horizons_us.first() else {
            return Err(GateError::NoHorizons);
        };
        if first < 0 {
            return Err(GateError::NegativeHorizon {
                index: 0,
                horizon_us: first,
            });
        }
        if let Some(index) = (1..horizons_us.len()).find(|&k| horizons_us[k] <= horizons_us[k - 1])
        {
            return Err(GateError::HorizonsNotIncreasing {
                index,
                horizon_us: horizons_us[index],
                previous_us: horizons_us[index - 1],
            });
        }
        let per_mask = words_for(size);
        let expected = per_mask * horizons_us.len();
        if mask_words.len() != expected {
            return Err(GateError::MaskWordCount {
                horizons: horizons_us.len(),
                size,
                expected,
                actual: mask_words.len(),
            });
        }
        for (index, words) in mask_words.chunks(per_mask.max(1)).enumerate() {
            MaskView::new(size, words).map_err(|source| GateError::Mask { index, source })?;
        }
        Ok(Self {
            reference_time_us,
            horizons_us,
            size,
            mask_words,
        })
    }

    pub fn reference_time_us(&self) -> i64 {
        self.reference_time_us
    }

    pub fn horizons_us(&self) -> &'a [i64] {
        self.horizons_us
    }

    /// The mask of horizon `index` (0-based), or `None` past the last.
    pub fn mask(&self, index: usize) -> Option<MaskView<'a>> {
        let per_mask = words_for(self.size);
        let words = self
            .mask_words
            .get(index * per_mask..(index + 1) * per_mask)?;
        Some(MaskView::new(self.size, words).expect("masks were validated in ForecastView::new"))
    }

    /// The largest d = τ − t that is judged.
    pub fn valid_limit_us(&self) -> i64 {
        match *self.horizons_us {
            [only] => only,
            [.., previous, last] => last.saturating_add((last - previous) / 2),
            [] => unreachable!("ForecastView::new rejects an empty horizon list"),
        }
    }

    /// Absolute time interval `[first, last]` (both included) judged by mask `index`.
    fn interval(&self, index: usize) -> (i64, i64) {
        let start_of = |k: usize| -> i64 {
            if k == 0 {
                return 0;
            }
            let (previous, current) = (self.horizons_us[k - 1], self.horizons_us[k]);
            let gap = current - previous;
            previous + gap / 2 + gap % 2
        };
        let relative_last = if index + 1 == self.horizons_us.len() {
            self.valid_limit_us()
        } else {
            start_of(index + 1) - 1
        };
        (
            self.reference_time_us.saturating_add(start_of(index)),
            self.reference_time_us.saturating_add(relative_last),
        )
    }

    /// Calls `judge` on consecutive runs of `events`: (first index, run, Some(mask index) or
    /// None for a run no mask can judge). Runs are found by binary search, which needs events
    /// sorted by time (the stream contract); the kernels recheck each event's time, so an
    /// unsorted event ends unjudged rather than judged by the wrong mask.
    fn for_each_run(&self, events: &[Event], mut judge: impl FnMut(&[Event], Option<usize>)) {
        let mut rest = events;
        let before = rest.partition_point(|event| event.t < self.interval(0).0);
        judge(&rest[..before], None);
        rest = &rest[before..];
        for index in 0..self.horizons_us.len() {
            let (_, last) = self.interval(index);
            let count = rest.partition_point(|event| event.t <= last);
            judge(&rest[..count], Some(index));
            rest = &rest[count..];
        }
        judge(rest, None);
    }

    /// Appends every event to exactly one of `kept`, `suppressed`, `unjudged`, preserving order
    /// within each.
    pub fn partition(
        &self,
        events: &[Event],
        mode: GateMode,
        kept: &mut Vec<Event>,
        suppressed: &mut Vec<Event>,
        unjudged: &mut Vec<Event>,
    ) -> GateCounts {
        let inversion = mode.inversion();
        let mut outputs = Outputs::new([kept, suppressed, unjudged], events.len());
        self.for_each_run(events, |run, mask_index| {
            let Some(index) = mask_index else {
                outputs.push_all_into(UNJUDGED, run);
                return;
            };
            let lookup = MaskLookup::new(self.mask(index).expect("run index is a horizon"));
            let (first, last) = self.interval(index);
            // Bits first, then copies: each event is written once, and judged words of one
            // fate are copied whole.
            for chunk in run.chunks(64) {
                let (mut keep, mut judged) = (0u64, 0u64);
                for (position, event) in chunk.iter().enumerate() {
                    let (inside, bit) = lookup.probe(event);
                    let judged_bit = inside & u64::from((event.t >= first) & (event.t <= last));
                    judged |= judged_bit << position;
                    keep |= (judged_bit & (bit ^ inversion)) << position;
                }
                let all = u64::MAX >> (64 - chunk.len());
                outputs.push_selected(KEPT, chunk, keep);
                outputs.push_selected(SUPPRESSED, chunk, judged & !keep);
                if judged != all {
                    outputs.push_selected(UNJUDGED, chunk, all & !judged);
                }
            }
        });
        let [kept, suppressed, unjudged] = outputs.finish();
        GateCounts {
            kept,
            suppressed,
            unjudged,
        }
    }

    /// Writes two bits per event i, at bit i of word i / 64: `judged` (a mask judged it) and
    /// `keep` (judged and kept); unjudged events have both bits clear.
    pub fn keep_bitmap(
        &self,
        events: &[Event],
        mode: GateMode,
        keep: &mut [u64],
        judged: &mut [u64],
    ) -> Result<GateCounts, GateError> {
        check_bitmap(keep, events.len())?;
        check_bitmap(judged, events.len())?;
        let inversion = mode.inversion();
        let mut sinks = BitSinks::new([keep, judged]);
        let mut counts = GateCounts::default();
        self.for_each_run(events, |run, mask_index| {
            let Some(index) = mask_index else {
                sinks.extend(run, |_| [0, 0]);
                counts.unjudged += run.len();
                return;
            };
            let lookup = MaskLookup::new(self.mask(index).expect("run index is a horizon"));
            let (first, last) = self.interval(index);
            sinks.extend(run, |event| {
                let (inside, bit) = lookup.probe(event);
                let judged_bit = inside & u64::from((event.t >= first) & (event.t <= last));
                let keep_bit = judged_bit & (bit ^ inversion);
                counts.kept += keep_bit as usize;
                counts.unjudged += (1 - judged_bit) as usize;
                [keep_bit, judged_bit]
            });
        });
        sinks.finish();
        counts.suppressed = events.len() - counts.kept - counts.unjudged;
        Ok(counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mask::BitMask;
    use proptest::prelude::*;

    const SIZE: SensorSize = SensorSize::new(9, 7);

    fn mask_of(pixels: &[(u16, u16)]) -> BitMask {
        let mut mask = BitMask::new(SIZE).unwrap();
        for &(x, y) in pixels {
            mask.set(x, y, true).unwrap();
        }
        mask
    }

    fn bit(words: &[u64], index: usize) -> bool {
        words[index / 64] >> (index % 64) & 1 == 1
    }

    #[test]
    fn single_mask_partition_follows_pixels() {
        let mask = mask_of(&[(1, 1)]);
        let events = [
            Event::new(0, 1, 1, true),
            Event::new(1, 2, 1, true),
            Event::new(2, 9, 0, true),
        ];
        let (mut kept, mut suppressed) = (Vec::new(), Vec::new());
        let count = partition(
            &events,
            mask.view(),
            GateMode::KeepMovingObjects,
            &mut kept,
            &mut suppressed,
        );
        assert_eq!(count, 1);
        assert_eq!(kept, &events[..1]);
        assert_eq!(suppressed, &events[1..]);
    }

    #[test]
    fn horizon_intervals_follow_the_documented_rule() {
        let words = mask_of(&[]).as_words().repeat(3);
        let horizons = [10, 20, 40];
        let forecast = ForecastView::new(1_000, &horizons, SIZE, &words).unwrap();
        assert_eq!(forecast.interval(0), (1_000, 1_014));
        assert_eq!(forecast.interval(1), (1_015, 1_029));
        assert_eq!(forecast.interval(2), (1_030, 1_050));
        assert_eq!(forecast.valid_limit_us(), 50);
        let single = ForecastView::new(0, &horizons[..1], SIZE, &words[..words.len() / 3]);
        assert_eq!(single.unwrap().interval(0), (0, 10));
        let odd = [0, 3];
        let forecast = ForecastView::new(0, &odd, SIZE, &words[..words.len() / 3 * 2]).unwrap();
        assert_eq!(
            (forecast.interval(0), forecast.interval(1)),
            ((0, 1), (2, 4))
        );
    }

    #[test]
    fn forecast_picks_the_mask_of_the_event_time() {
        let first = mask_of(&[(0, 0)]);
        let second = mask_of(&[(1, 0)]);
        let words = [first.as_words(), second.as_words()].concat();
        let horizons = [0, 20];
        let forecast = ForecastView::new(100, &horizons, SIZE, &words).unwrap();
        let events = [
            Event::new(99, 0, 0, true),  // before t: unjudged
            Event::new(105, 0, 0, true), // mask 1, set: kept
            Event::new(109, 1, 0, true), // mask 1, clear: suppressed
            Event::new(110, 1, 0, true), // mask 2, set: kept
            Event::new(115, 9, 0, true), // off the sensor: unjudged
            Event::new(130, 0, 0, true), // mask 2 up to 30: suppressed
            Event::new(131, 1, 0, true), // past the limit: unjudged
        ];
        let (mut kept, mut suppressed, mut unjudged) = (Vec::new(), Vec::new(), Vec::new());
        let counts = forecast.partition(
            &events,
            GateMode::KeepMovingObjects,
            &mut kept,
            &mut suppressed,
            &mut unjudged,
        );
        assert_eq!(kept, [events[1], events[3]]);
        assert_eq!(suppressed, [events[2], events[5]]);
        assert_eq!(unjudged, [events[0], events[4], events[6]]);
        assert_eq!(
            counts,
            GateCounts {
                kept: 2,
                suppressed: 2,
                unjudged: 3
            }
        );
    }

    #[test]
    fn unsorted_events_are_never_judged_by_the_wrong_mask() {
        let words = [mask_of(&[]).as_words(), mask_of(&[(0, 0)]).as_words()].concat();
        let horizons = [0, 100];
        let forecast = ForecastView::new(0, &horizons, SIZE, &words).unwrap();
        // The event at t = 90 belongs to mask 2 but sits among mask-1 events.
        let events = [
            Event::new(1, 0, 0, true),
            Event::new(90, 0, 0, true),
            Event::new(2, 0, 0, true),
        ];
        let (mut kept, mut suppressed, mut unjudged) = (Vec::new(), Vec::new(), Vec::new());
        forecast.partition(
            &events,
            GateMode::KeepMovingObjects,
            &mut kept,
            &mut suppressed,
            &mut unjudged,
        );
        // Judged or not, each event's outcome must match its own time's mask: mask 1 is empty
        // (events at 1 and 2 may only be suppressed), mask 2 holds the pixel (90 may only be
        // kept).
        assert!(!kept.contains(&events[0]) && !kept.contains(&events[2]));
        assert!(!suppressed.contains(&events[1]));
        assert_eq!(kept.len() + suppressed.len() + unjudged.len(), 3);
    }

    #[test]
    fn bad_forecasts_are_rejected() {
        let words = mask_of(&[]).as_words().repeat(2);
        let size = SIZE;
        assert_eq!(
            ForecastView::new(0, &[], size, &[]).unwrap_err(),
            GateError::NoHorizons
        );
        assert!(matches!(
            ForecastView::new(0, &[-1, 5], size, &words),
            Err(GateError::NegativeHorizon { index: 0, .. })
        ));
        assert!(matches!(
            ForecastView::new(0, &[5, 5], size, &words),
            Err(GateError::HorizonsNotIncreasing { index: 1, .. })
        ));
        assert!(matches!(
            ForecastView::new(0, &[5], size, &words),
            Err(GateError::MaskWordCount {
                expected: 1,
                actual: 2,
                ..
            })
        ));
        assert!(matches!(
            ForecastView::new(0, &[5], size, &[u64::MAX]),
            Err(GateError::Mask { index: 0, .. })
        ));
        let mask = mask_of(&[]);
        assert!(matches!(
            keep_bitmap(
                &[Event::default(); 65],
                mask.view(),
                GateMode::KeepEgoMotion,
                &mut [0]
            ),
            Err(GateError::BitmapTooShort { required: 2, .. })
        ));
    }

    fn arbitrary_mask() -> impl Strategy<Value = BitMask> {
        prop::collection::vec(any::<bool>(), SIZE.pixels()).prop_map(|bits| {
            let mut mask = BitMask::new(SIZE).unwrap();
            for (index, on) in bits.into_iter().enumerate() {
                let (x, y) = ((index % 9) as u16, (index / 9) as u16);
                mask.set(x, y, on).unwrap();
            }
            mask
        })
    }

    fn arbitrary_events() -> impl Strategy<Value = Vec<Event>> {
        prop::collection::vec(
            (-20i64..150, 0u16..11, 0u16..8, any::<bool>())
                .prop_map(|(t, x, y, on)| Event::new(t, x, y, on)),
            0..300,
        )
        .prop_map(|mut events| {
            events.sort_by_key(|event| event.t);
            events
        })
    }

    fn mode() -> impl Strategy<Value = GateMode> {
        prop_oneof![
            Just(GateMode::KeepMovingObjects),
            Just(GateMode::KeepEgoMotion)
        ]
    }

    /// True when `part` is a subsequence of `whole` (order preserved).
    fn is_subsequence(part: &[Event], whole: &[Event]) -> bool {
        let mut rest = whole.iter();
        part.iter()
            .all(|event| rest.any(|candidate| candidate == event))
    }

    proptest! {
        #[test]
        fn single_mask_outputs_cover_input_and_agree(
            events in arbitrary_events(), mask in arbitrary_mask(), mode in mode(),
        ) {
            let (mut kept, mut suppressed) = (vec![Event::new(-1, 0, 0, true)], Vec::new());
            let count = partition(&events, mask.view(), mode, &mut kept, &mut suppressed);
            let kept = &kept[1..];
            prop_assert_eq!(count, kept.len());
            prop_assert_eq!(kept.len() + suppressed.len(), events.len());
            prop_assert!(is_subsequence(kept, &events) && is_subsequence(&suppressed, &events));
            let mut bitmap = vec![u64::MAX; events.len().div_ceil(64) + 1];
            let bitmap_count = keep_bitmap(&events, mask.view(), mode, &mut bitmap).unwrap();
            prop_assert_eq!(bitmap_count, count);
            let from_bitmap: Vec<Event> = (0..events.len())
                .filter(|&i| bit(&bitmap, i))
                .map(|i| events[i])
                .collect();
            prop_assert_eq!(&from_bitmap[..], kept);
            if events.len() % 64 != 0 {
                prop_assert_eq!(bitmap[events.len() / 64] >> (events.len() % 64), 0);
            }
            for (index, event) in events.iter().enumerate() {
                let in_mask = mask.get(event.x, event.y);
                prop_assert_eq!(bit(&bitmap, index), in_mask == (mode == GateMode::KeepMovingObjects));
            }
        }

        #[test]
        fn inverting_the_mode_swaps_outputs(events in arbitrary_events(), mask in arbitrary_mask()) {
            let (mut kept, mut suppressed) = (Vec::new(), Vec::new());
            partition(&events, mask.view(), GateMode::KeepMovingObjects, &mut kept, &mut suppressed);
            let (mut kept_inverse, mut suppressed_inverse) = (Vec::new(), Vec::new());
            partition(&events, mask.view(), GateMode::KeepEgoMotion, &mut kept_inverse, &mut suppressed_inverse);
            prop_assert_eq!(kept, suppressed_inverse);
            prop_assert_eq!(suppressed, kept_inverse);
        }

        #[test]
        fn forecast_outputs_cover_input_and_agree(
            events in arbitrary_events(),
            masks in prop::collection::vec(arbitrary_mask(), 1..4),
            mode in mode(),
        ) {
            let horizons: Vec<i64> = (0..masks.len() as i64).map(|k| 10 + 30 * k).collect();
            let words: Vec<u64> = masks.iter().flat_map(|m| m.as_words()).copied().collect();
            let forecast = ForecastView::new(0, &horizons, SIZE, &words).unwrap();
            let (mut kept, mut suppressed, mut unjudged) = (Vec::new(), Vec::new(), Vec::new());
            let counts = forecast.partition(&events, mode, &mut kept, &mut suppressed, &mut unjudged);
            prop_assert_eq!(
                (counts.kept, counts.suppressed, counts.unjudged),
                (kept.len(), suppressed.len(), unjudged.len())
            );
            prop_assert_eq!(kept.len() + suppressed.len() + unjudged.len(), events.len());
            for part in [&kept, &suppressed, &unjudged] {
                prop_assert!(is_subsequence(part, &events));
            }
            let words_needed = events.len().div_ceil(64);
            let (mut keep, mut judged) = (vec![u64::MAX; words_needed], vec![u64::MAX; words_needed]);
            let bitmap_counts = forecast.keep_bitmap(&events, mode, &mut keep, &mut judged).unwrap();
            prop_assert_eq!(bitmap_counts, counts);
            let pick = |want_judged: bool, want_keep: bool| -> Vec<Event> {
                (0..events.len())
                    .filter(|&i| bit(&judged, i) == want_judged && bit(&keep, i) == want_keep)
                    .map(|i| events[i])
                    .collect()
            };
            prop_assert_eq!(pick(true, true), kept.clone());
            prop_assert_eq!(pick(true, false), suppressed.clone());
            prop_assert_eq!(pick(false, false), unjudged.clone());
            // Reference judgement, event by event, from the documented rule.
            for (index, event) in events.iter().enumerate() {
                let d = event.t;
                let expected = if d < 0 || d > forecast.valid_limit_us() || !SIZE.contains(event) {
                    None
                } else {
                    let mask_index = (1..horizons.len())
                        .rev()
                        .find(|&k| 2 * d >= horizons[k - 1] + horizons[k])
                        .unwrap_or(0);
                    Some(masks[mask_index].get(event.x, event.y) == (mode == GateMode::KeepMovingObjects))
                };
                let actual = bit(&judged, index).then(|| bit(&keep, index));
                prop_assert_eq!(actual, expected, "event {} {:?}", index, event);
            }
        }
    }
}
