//! The gate's verdict on one batch: a pass bit per event, from the forecast where one applies
//! and from the no-forecast policy elsewhere, and the selection of the events of either fate
//! into any [`EventSink`].

use std::ops::Range;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::bitset::{self, bit, set_bit};
use crate::event::Event;
use crate::gate::{ForecastView, GateMode};
use crate::mask::MaskView;

/// Fate of an event without a valid forecast (before the first forecast, after the latest one
/// expired, or off the forecast's time range).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum NoForecast {
    /// Let it through (nothing is lost when the inference lags or stops).
    Pass,
    /// Suppress it.
    Drop,
    /// Judge it by the nearest mask of the latest forecast (the current mask before the
    /// forecast's time, the farthest horizon after it) while that forecast is at most the
    /// policy's last-mask age away from the event; older forecasts let it through.
    LastMask,
}

/// The no-forecast policy with its parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Policy {
    pub no_forecast: NoForecast,
    pub last_mask_max_age: Duration,
}

/// A forecast as the judge reads it: the mask at its reference time and one per horizon.
#[derive(Clone, Copy, Debug)]
pub struct Forecast<'a> {
    pub current: MaskView<'a>,
    pub horizons: ForecastView<'a>,
}

impl Forecast<'_> {
    /// Whether the policy's nearest mask keeps `event` (`LastMask`), or `None` when the
    /// forecast is too far from the event to judge it.
    fn nearest_mask_keeps(&self, event: &Event, mode: GateMode, max_age_us: i64) -> Option<bool> {
        let reference = self.horizons.reference_time_us();
        if (event.t - reference).abs() > max_age_us {
            return None;
        }
        let mask = if event.t < reference {
            self.current
        } else {
            let last = self.horizons.horizons_us().len() - 1;
            self.horizons
                .mask(last)
                .expect("the last horizon has a mask")
        };
        let in_mask = mask.size().contains(event) && mask.get(event.x, event.y);
        Some(in_mask ^ (mode == GateMode::KeepEgoMotion))
    }
}

/// Where the events of one batch went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Verdict {
    pub kept: u64,
    pub suppressed: u64,
    pub unjudged_passed: u64,
    pub unjudged_dropped: u64,
    /// A forecast judged at least one event.
    pub forecast_used: bool,
}

impl Verdict {
    /// Events that pass the gate: kept, or unjudged and passed by the policy.
    pub fn passed(&self) -> u64 {
        self.kept + self.unjudged_passed
    }
}

/// Where selected events go: a vector, or a loaned shared-memory slice.
pub trait EventSink {
    fn push(&mut self, event: Event);
    fn extend_from_slice(&mut self, events: &[Event]);
}

impl EventSink for Vec<Event> {
    #[inline(always)]
    fn push(&mut self, event: Event) {
        Vec::push(self, event);
    }

    fn extend_from_slice(&mut self, events: &[Event]) {
        Vec::extend_from_slice(self, events);
    }
}

/// The gate's judgement with reusable bit buffers.
#[derive(Default)]
pub struct Judge {
    /// Bit i = event i passes (the keep bitmap the gate publishes).
    pass: Vec<u64>,
    judged: Vec<u64>,
    /// Bits of one time span of a batch judged by several forecasts, before they are copied
    /// into place.
    span_pass: Vec<u64>,
    span_judged: Vec<u64>,
}

impl Judge {
    /// Judges `events` (sorted by time, the stream contract); `forecast` is the newest valid
    /// forecast for their stream and sensor.
    pub fn judge(
        &mut self,
        events: &[Event],
        forecast: Option<Forecast<'_>>,
        mode: GateMode,
        policy: Policy,
    ) -> Verdict {
        self.judge_by_time(events, forecast.as_slice(), mode, policy)
    }

    /// Judges `events` (sorted by time) each with the newest of `forecasts` (sorted by
    /// reference time) whose reference time is at or before it, the events before the second
    /// forecast with the first: as `evgate eval` judges the events of [t, next t) with the
    /// forecast of t. With one forecast this is [`Judge::judge`].
    pub fn judge_by_time(
        &mut self,
        events: &[Event],
        forecasts: &[Forecast<'_>],
        mode: GateMode,
        policy: Policy,
    ) -> Verdict {
        bitset::reset(&mut self.pass, events.len());
        bitset::reset(&mut self.judged, events.len());
        let mut verdict = Verdict::default();
        if forecasts.is_empty() {
            self.apply_policy(events, 0..events.len(), None, mode, policy, &mut verdict);
            return verdict;
        }
        let mut start = 0;
        for (index, forecast) in forecasts.iter().enumerate() {
            let end = match forecasts.get(index + 1) {
                Some(next) => {
                    let next_reference = next.horizons.reference_time_us();
                    start + events[start..].partition_point(|event| event.t < next_reference)
                }
                None => events.len(),
            };
            if end > start {
                self.judge_span(events, start..end, forecast, mode, policy, &mut verdict);
            }
            start = end;
        }
        verdict
    }

    /// Judges `events[span]` with one forecast, then the events it leaves by the policy.
    fn judge_span(
        &mut self,
        events: &[Event],
        span: Range<usize>,
        forecast: &Forecast<'_>,
        mode: GateMode,
        policy: Policy,
        verdict: &mut Verdict,
    ) {
        let whole_batch = span.start == 0 && span.end == events.len();
        let (pass, judged) = if whole_batch {
            (&mut self.pass, &mut self.judged)
        } else {
            bitset::reset(&mut self.span_pass, span.len());
            bitset::reset(&mut self.span_judged, span.len());
            (&mut self.span_pass, &mut self.span_judged)
        };
        let counts = forecast
            .horizons
            .keep_bitmap(&events[span.clone()], mode, pass, judged)
            .expect("bitmaps are sized for the span");
        if !whole_batch {
            for offset in 0..span.len() {
                if bit(&self.span_pass, offset) {
                    set_bit(&mut self.pass, span.start + offset);
                }
                if bit(&self.span_judged, offset) {
                    set_bit(&mut self.judged, span.start + offset);
                }
            }
        }
        verdict.kept += counts.kept as u64;
        verdict.suppressed += counts.suppressed as u64;
        verdict.forecast_used |= counts.kept + counts.suppressed > 0;
        if counts.unjudged > 0 {
            self.apply_policy(events, span, Some(forecast), mode, policy, verdict);
        }
    }

    /// Gives the events of `span` that no forecast judged the policy's fate.
    fn apply_policy(
        &mut self,
        events: &[Event],
        span: Range<usize>,
        forecast: Option<&Forecast<'_>>,
        mode: GateMode,
        policy: Policy,
        verdict: &mut Verdict,
    ) {
        let max_age_us = policy.last_mask_max_age.as_micros() as i64;
        for index in span {
            if bit(&self.judged, index) {
                continue;
            }
            let event = &events[index];
            let passes = match policy.no_forecast {
                NoForecast::Pass => true,
                NoForecast::Drop => false,
                NoForecast::LastMask => forecast
                    .and_then(|forecast| forecast.nearest_mask_keeps(event, mode, max_age_us))
                    .unwrap_or(true),
            };
            if passes {
                set_bit(&mut self.pass, index);
                verdict.unjudged_passed += 1;
            } else {
                verdict.unjudged_dropped += 1;
            }
        }
    }

    /// The pass bits of the last judged batch: bit i of word i / 64 for event i.
    pub fn pass_bits(&self) -> &[u64] {
        &self.pass
    }

    /// Sends the events of the last judged batch whose pass bit equals `passed` to `sink`, in
    /// order. Whole words of selected events go in one copy; elsewhere each set bit is found
    /// with a trailing-zero count, so the work follows the selected events, not a branch per
    /// event.
    pub fn select(&self, events: &[Event], passed: bool, sink: &mut impl EventSink) {
        let flip = if passed { 0 } else { u64::MAX };
        for (chunk, &word) in events.chunks(64).zip(&self.pass) {
            // Bits past the last event of a partial chunk are clear in `pass` and must stay
            // clear after the flip.
            let valid = u64::MAX >> (64 - chunk.len());
            let mut selected = (word ^ flip) & valid;
            if selected == valid {
                sink.extend_from_slice(chunk);
                continue;
            }
            while selected != 0 {
                sink.push(chunk[selected.trailing_zeros() as usize]);
                selected &= selected - 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::SensorSize;
    use crate::mask::BitMask;
    use proptest::prelude::*;

    const SENSOR: SensorSize = SensorSize::new(8, 4);
    const HORIZONS_US: [i64; 2] = [10_000, 20_000];

    /// Current mask: column 0; horizon 10 ms: column 1; horizon 20 ms: column 2.
    fn column_masks() -> Vec<u64> {
        let mut words = Vec::new();
        for column in 0..3 {
            let mut mask = BitMask::new(SENSOR).unwrap();
            for y in 0..SENSOR.height {
                mask.set(column, y, true).unwrap();
            }
            words.extend_from_slice(mask.as_words());
        }
        words
    }

    fn forecast(words: &[u64], reference_time_us: i64) -> Forecast<'_> {
        Forecast {
            current: MaskView::new(SENSOR, &words[..1]).unwrap(),
            horizons: ForecastView::new(reference_time_us, &HORIZONS_US, SENSOR, &words[1..])
                .unwrap(),
        }
    }

    fn selected(judge: &Judge, events: &[Event], passed: bool) -> Vec<Event> {
        let mut sink = Vec::new();
        judge.select(events, passed, &mut sink);
        sink
    }

    fn policy(no_forecast: NoForecast) -> Policy {
        Policy {
            no_forecast,
            last_mask_max_age: Duration::from_millis(100),
        }
    }

    #[test]
    fn forecast_judges_by_horizon_and_policy_takes_the_rest() {
        let words = column_masks();
        let forecast = forecast(&words, 1_000_000);
        let events = [
            Event::new(1_005_000, 1, 0, true), // horizon 10 ms mask: column 1 → kept
            Event::new(1_005_000, 2, 0, true), // suppressed
            Event::new(1_020_000, 2, 1, true), // horizon 20 ms mask: kept
            Event::new(999_000, 0, 0, true),   // before the forecast: unjudged
            Event::new(1_500_000, 2, 0, true), // far after: unjudged
        ];
        let mut judge = Judge::default();
        let verdict = judge.judge(
            &events,
            Some(forecast),
            GateMode::KeepMovingObjects,
            policy(NoForecast::Drop),
        );
        assert_eq!(
            (verdict.kept, verdict.suppressed, verdict.unjudged_dropped),
            (2, 1, 2)
        );
        assert_eq!(selected(&judge, &events, true), vec![events[0], events[2]]);
        assert_eq!(
            selected(&judge, &events, false),
            vec![events[1], events[3], events[4]]
        );

        let verdict = judge.judge(
            &events,
            Some(forecast),
            GateMode::KeepMovingObjects,
            policy(NoForecast::LastMask),
        );
        // Before the forecast: current mask (column 0) keeps event 3; 500 ms later is past the
        // age limit, so event 4 passes.
        assert_eq!((verdict.unjudged_passed, verdict.unjudged_dropped), (2, 0));

        let verdict = judge.judge(
            &events,
            None,
            GateMode::KeepEgoMotion,
            policy(NoForecast::Pass),
        );
        assert_eq!(verdict.unjudged_passed, 5);
        assert!(!verdict.forecast_used);
    }

    proptest! {
        #[test]
        fn every_event_gets_exactly_one_fate(
            raw in proptest::collection::vec((990_000i64..1_200_000, 0u16..10, 0u16..5), 0..600),
            policy_index in 0usize..3,
            ego in any::<bool>(),
            with_forecast in any::<bool>(),
        ) {
            let mut events: Vec<Event> = raw.iter().map(|&(t, x, y)| Event::new(t, x, y, true)).collect();
            events.sort_by_key(|e| e.t);
            let words = column_masks();
            let forecast = forecast(&words, 1_000_000);
            let no_forecast = [NoForecast::Pass, NoForecast::Drop, NoForecast::LastMask][policy_index];
            let mode = if ego { GateMode::KeepEgoMotion } else { GateMode::KeepMovingObjects };
            let mut judge = Judge::default();
            let verdict = judge.judge(&events, with_forecast.then_some(forecast), mode, policy(no_forecast));
            let total = verdict.kept + verdict.suppressed + verdict.unjudged_passed + verdict.unjudged_dropped;
            prop_assert_eq!(total, events.len() as u64);
            let kept = selected(&judge, &events, true);
            let suppressed = selected(&judge, &events, false);
            prop_assert_eq!(kept.len() as u64, verdict.passed());
            prop_assert_eq!(kept.len() + suppressed.len(), events.len());
            // Both outputs keep the input order and follow the pass bits.
            let passes = |index: usize| bit(judge.pass_bits(), index);
            let expected_kept: Vec<Event> = (0..events.len()).filter(|&i| passes(i)).map(|i| events[i]).collect();
            let expected_suppressed: Vec<Event> = (0..events.len()).filter(|&i| !passes(i)).map(|i| events[i]).collect();
            prop_assert_eq!(kept, expected_kept);
            prop_assert_eq!(suppressed, expected_suppressed);
        }

        #[test]
        fn judging_by_time_is_judging_each_forecasts_span_alone(
            raw in proptest::collection::vec((990_000i64..1_120_000, 0u16..10, 0u16..5), 0..600),
            policy_index in 0usize..3,
            ego in any::<bool>(),
        ) {
            let mut events: Vec<Event> = raw.iter().map(|&(t, x, y)| Event::new(t, x, y, true)).collect();
            events.sort_by_key(|e| e.t);
            let (earlier_words, later_words) = (column_masks(), column_masks().iter().map(|w| !w & 0xffff_ffff).collect::<Vec<_>>());
            let forecasts = [forecast(&earlier_words, 1_000_000), forecast(&later_words, 1_015_000)];
            let no_forecast = [NoForecast::Pass, NoForecast::Drop, NoForecast::LastMask][policy_index];
            let mode = if ego { GateMode::KeepEgoMotion } else { GateMode::KeepMovingObjects };
            let mut judge = Judge::default();
            let verdict = judge.judge_by_time(&events, &forecasts, mode, policy(no_forecast));
            let split = events.partition_point(|e| e.t < 1_015_000);
            let mut alone = Judge::default();
            let mut expected_passes = Vec::new();
            let mut expected = Verdict::default();
            for (span, forecast) in [(&events[..split], forecasts[0]), (&events[split..], forecasts[1])] {
                let part = alone.judge(span, Some(forecast), mode, policy(no_forecast));
                expected.kept += part.kept;
                expected.suppressed += part.suppressed;
                expected.unjudged_passed += part.unjudged_passed;
                expected.unjudged_dropped += part.unjudged_dropped;
                expected.forecast_used |= part.forecast_used;
                expected_passes.extend((0..span.len()).map(|i| bit(alone.pass_bits(), i)));
            }
            prop_assert_eq!(verdict, expected);
            let passes: Vec<bool> = (0..events.len()).map(|i| bit(judge.pass_bits(), i)).collect();
            prop_assert_eq!(passes, expected_passes);
        }
    }
}
