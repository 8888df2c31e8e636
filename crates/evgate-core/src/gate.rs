//! The per-event gating kernel: every event is kept or suppressed by the mask bit of its pixel,
//! and with a forecast, by the mask of the horizon its time falls into.

use serde::{Deserialize, Serialize};

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;

use crate::bitset::words_for;
use crate::event::Event;
use crate::geometry::SensorSize;
use crate::mask::{MaskError, MaskView};

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
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum GateMode {
    /// Keep the events of independently moving objects (pixels in the mask), suppress the rest.
    KeepMovingObjects,
    /// Keep the ego-motion events (pixels outside the mask), e.g. for visual odometry.
    KeepEgoMotion,
}

impl GateMode {
    /// The value XOR-ed with a mask bit to get the keep bit.
    pub(crate) const fn inversion(self) -> u64 {
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

    /// `[keep, judged]` bits of one event against this mask and the time interval
    /// `[first, last]`, without branches: judged when on the sensor and inside the interval,
    /// kept when judged and its mask bit (XOR `inversion`) is set.
    #[inline(always)]
    fn bits(&self, event: &Event, first: i64, last: i64, inversion: u64) -> [u64; 2] {
        let (x, y) = (u32::from(event.x), u32::from(event.y));
        let inside = (x < self.width) & (y < self.height);
        // Off-sensor events read pixel 0 (the mask is never empty) and are masked out below.
        let index = (u32::from(inside) * (y * self.width + x)) as usize;
        let bit = self.words[index / 64] >> (index % 64) & 1;
        let judged = u64::from(inside & (event.t >= first) & (event.t <= last));
        [judged & (bit ^ inversion), judged]
    }

    /// The bits of 64 events, eight at a time with AVX-512 or four with AVX2 where the CPU has
    /// them.
    #[inline(always)]
    fn chunk_bits(&self, chunk: &[Event; 64], first: i64, last: i64, inversion: u64) -> [u64; 2] {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU was just found to support AVX-512F.
            return unsafe { avx512::chunk_bits(chunk, self, first, last, inversion) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU was just found to support AVX2.
            return unsafe { avx2::chunk_bits(chunk, self, first, last, inversion) };
        }
        let mut words = [0u64; 2];
        for (position, event) in chunk.iter().enumerate() {
            for (word, bit) in words
                .iter_mut()
                .zip(self.bits(event, first, last, inversion))
            {
                *word |= bit << position;
            }
        }
        words
    }
}

fn check_bitmap(words: &[u64], events: usize) -> Result<(), GateError> {
    let required = words_for(events);
    if words.len() < required {
        return Err(GateError::BitmapTooShort {
            actual: words.len(),
            required,
            events,
        });
    }
    Ok(())
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

    /// Pushes the bits of every event of `run`, in order: `bits_of` for the events before
    /// and after the whole words, `chunk_bits_of` for each word-aligned run of 64.
    #[inline(always)]
    fn extend(
        &mut self,
        run: &[Event],
        mut bits_of: impl FnMut(&Event) -> [u64; N],
        mut chunk_bits_of: impl FnMut(&[Event; 64]) -> [u64; N],
    ) {
        let head = ((64 - self.index % 64) % 64).min(run.len());
        for event in &run[..head] {
            self.push(bits_of(event));
        }
        let (chunks, tail) = run[head..].as_chunks::<64>();
        for chunk in chunks {
            let words = chunk_bits_of(chunk);
            for (bitmap, word) in self.bitmaps.iter_mut().zip(words) {
                bitmap[self.index / 64] = word;
            }
            self.index += 64;
        }
        for event in tail {
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
        let per_mask = words_for(size.pixels());
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
        let per_mask = words_for(self.size.pixels());
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
        let mut sinks = BitSinks::new([&mut *keep, &mut *judged]);
        self.for_each_run(events, |run, mask_index| {
            let Some(index) = mask_index else {
                sinks.extend(run, |_| [0, 0], |_| [0, 0]);
                return;
            };
            let lookup = MaskLookup::new(self.mask(index).expect("run index is a horizon"));
            let (first, last) = self.interval(index);
            sinks.extend(
                run,
                |event| lookup.bits(event, first, last, inversion),
                |chunk| lookup.chunk_bits(chunk, first, last, inversion),
            );
        });
        sinks.finish();
        let words = words_for(events.len());
        let ones = |bitmap: &[u64]| {
            bitmap[..words]
                .iter()
                .map(|w| w.count_ones() as usize)
                .sum()
        };
        let (kept, judged): (usize, usize) = (ones(keep), ones(judged));
        Ok(GateCounts {
            kept,
            suppressed: judged - kept,
            unjudged: events.len() - judged,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bitset::bit;
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

    /// (judged, kept) bits of every event, as `Option<bool>`: None when unjudged.
    fn fates(forecast: &ForecastView<'_>, events: &[Event], mode: GateMode) -> Vec<Option<bool>> {
        let words = words_for(events.len());
        let (mut keep, mut judged) = (vec![u64::MAX; words], vec![u64::MAX; words]);
        let counts = forecast
            .keep_bitmap(events, mode, &mut keep, &mut judged)
            .unwrap();
        let fates: Vec<Option<bool>> = (0..events.len())
            .map(|i| bit(&judged, i).then(|| bit(&keep, i)))
            .collect();
        assert_eq!(
            counts.kept,
            fates.iter().filter(|f| **f == Some(true)).count()
        );
        assert_eq!(
            counts.unjudged,
            fates.iter().filter(|f| f.is_none()).count()
        );
        assert_eq!(
            counts.kept + counts.suppressed + counts.unjudged,
            events.len()
        );
        if !events.len().is_multiple_of(64) {
            assert_eq!(keep[events.len() / 64] >> (events.len() % 64), 0);
            assert_eq!(judged[events.len() / 64] >> (events.len() % 64), 0);
        }
        fates
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
        assert_eq!(
            fates(&forecast, &events, GateMode::KeepMovingObjects),
            [
                None,
                Some(true),
                Some(false),
                Some(true),
                None,
                Some(false),
                None
            ]
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
        let fates = fates(&forecast, &events, GateMode::KeepMovingObjects);
        // Judged or not, each event's outcome must match its own time's mask: mask 1 is empty
        // (events at 1 and 2 may only be suppressed), mask 2 holds the pixel (90 may only be
        // kept).
        assert!(fates[0] != Some(true) && fates[2] != Some(true));
        assert!(fates[1] != Some(false));
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
        let forecast = ForecastView::new(0, &[5], size, &words[..1]).unwrap();
        assert!(matches!(
            forecast.keep_bitmap(
                &[Event::default(); 65],
                GateMode::KeepEgoMotion,
                &mut [0],
                &mut [0, 0]
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

    fn any_event() -> impl Strategy<Value = Event> {
        (
            prop_oneof![-30i64..60, any::<i64>()],
            prop_oneof![0u16..12, any::<u16>()],
            prop_oneof![0u16..9, any::<u16>()],
            any::<bool>(),
        )
            .prop_map(|(t, x, y, on)| Event::new(t, x, y, on))
    }

    proptest! {
        #[test]
        fn the_avx2_and_avx512_chunk_kernels_equal_the_scalar_one(
            events in prop::collection::vec(any_event(), 64),
            mask in arbitrary_mask(),
            bounds in (prop_oneof![-10i64..50, any::<i64>()], prop_oneof![-10i64..50, any::<i64>()]),
            inversion in 0u64..2,
        ) {
            if !std::is_x86_feature_detected!("avx2") {
                return Ok(());
            }
            let chunk: &[Event; 64] = events.as_slice().try_into().unwrap();
            let lookup = MaskLookup::new(mask.view());
            let (first, last) = bounds;
            let mut scalar = [0u64; 2];
            for (position, event) in chunk.iter().enumerate() {
                for (word, bit) in scalar.iter_mut().zip(lookup.bits(event, first, last, inversion)) {
                    *word |= bit << position;
                }
            }
            // SAFETY: AVX2 was detected above.
            let vector = unsafe { avx2::chunk_bits(chunk, &lookup, first, last, inversion) };
            prop_assert_eq!(vector, scalar);
            if std::is_x86_feature_detected!("avx512f") {
                // SAFETY: AVX-512F was just detected.
                let wide = unsafe { avx512::chunk_bits(chunk, &lookup, first, last, inversion) };
                prop_assert_eq!(wide, scalar);
            }
        }

        #[test]
        fn inverting_the_mode_swaps_kept_and_suppressed(
            events in arbitrary_events(),
            masks in prop::collection::vec(arbitrary_mask(), 1..4),
        ) {
            let horizons: Vec<i64> = (0..masks.len() as i64).map(|k| 10 + 30 * k).collect();
            let words: Vec<u64> = masks.iter().flat_map(|m| m.as_words()).copied().collect();
            let forecast = ForecastView::new(0, &horizons, SIZE, &words).unwrap();
            let moving = fates(&forecast, &events, GateMode::KeepMovingObjects);
            let ego = fates(&forecast, &events, GateMode::KeepEgoMotion);
            let inverted: Vec<Option<bool>> = moving.iter().map(|fate| fate.map(|kept| !kept)).collect();
            prop_assert_eq!(ego, inverted);
        }

        #[test]
        fn every_event_is_judged_by_the_documented_rule(
            events in arbitrary_events(),
            masks in prop::collection::vec(arbitrary_mask(), 1..4),
            mode in mode(),
        ) {
            let horizons: Vec<i64> = (0..masks.len() as i64).map(|k| 10 + 30 * k).collect();
            let words: Vec<u64> = masks.iter().flat_map(|m| m.as_words()).copied().collect();
            let forecast = ForecastView::new(0, &horizons, SIZE, &words).unwrap();
            let fates = fates(&forecast, &events, mode);
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
                prop_assert_eq!(fates[index], expected, "event {} {:?}", index, event);
            }
        }
    }
}
