//! The verdict on one batch: a pass bit per event, from the forecast where one applies and from
//! the no-forecast policy elsewhere.

use evgate_core::{Event, GateMode, MaskView};
use evgate_ipc::batch::bitmap_words;
use evgate_ipc::SliceWriter;

use crate::forecast_store::StoredForecast;
use crate::policy::{NoForecast, Policy};

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
    pub fn passed(&self) -> u64 {
        self.kept + self.unjudged_passed
    }
}

/// Reusable bit buffers of the verdicts.
#[derive(Default)]
pub struct Judge {
    /// Bit i = event i passes (kept, or unjudged and passed by the policy).
    pub pass: Vec<u64>,
    judged: Vec<u64>,
}

fn bit(words: &[u64], index: usize) -> bool {
    words[index / 64] >> (index % 64) & 1 == 1
}

fn set_bit(words: &mut [u64], index: usize) {
    words[index / 64] |= 1 << (index % 64);
}

fn mask_keeps(mask: MaskView<'_>, mode: GateMode, event: &Event) -> bool {
    let in_mask = mask.size().contains(event) && mask.get(event.x, event.y);
    match mode {
        GateMode::KeepMovingObjects => in_mask,
        GateMode::KeepEgoMotion => !in_mask,
    }
}

impl Judge {
    /// Judges `events`; `forecast` is the newest valid forecast for this stream and sensor.
    pub fn judge(
        &mut self,
        events: &[Event],
        forecast: Option<&StoredForecast>,
        mode: GateMode,
        policy: Policy,
    ) -> Verdict {
        let words = bitmap_words(events.len());
        self.pass.clear();
        self.pass.resize(words, 0);
        self.judged.clear();
        self.judged.resize(words, 0);
        let mut verdict = Verdict::default();
        let mut unjudged = events.len() as u64;
        if let Some(forecast) = forecast {
            let view = forecast.view().expect("validated when stored");
            let counts = view
                .keep_bitmap(events, mode, &mut self.pass, &mut self.judged)
                .expect("bitmaps are sized for the batch");
            verdict.kept = counts.kept as u64;
            verdict.suppressed = counts.suppressed as u64;
            verdict.forecast_used = counts.kept + counts.suppressed > 0;
            unjudged = counts.unjudged as u64;
        }
        if unjudged == 0 {
            return verdict;
        }
        for (index, event) in events.iter().enumerate() {
            if bit(&self.judged, index) {
                continue;
            }
            let passes = match policy.no_forecast {
                NoForecast::Pass => true,
                NoForecast::Drop => false,
                NoForecast::LastMask => match forecast {
                    Some(forecast) => {
                        let reference = forecast.header.reference_time_us;
                        let max_age = policy.last_mask_max_age.as_micros() as i64;
                        if (event.t - reference).abs() > max_age {
                            true
                        } else if event.t < reference {
                            mask_keeps(forecast.current_mask(), mode, event)
                        } else {
                            mask_keeps(forecast.last_mask(), mode, event)
                        }
                    }
                    None => true,
                },
            };
            if passes {
                set_bit(&mut self.pass, index);
                verdict.unjudged_passed += 1;
            } else {
                verdict.unjudged_dropped += 1;
            }
        }
        verdict
    }

    /// Writes the events whose pass bit equals `passed` to `writer`, in order. Whole words of
    /// selected events go in one copy; elsewhere each set bit is found with a trailing-zero
    /// count, so the work follows the selected events, not a branch per event.
    pub fn write_selected(
        &self,
        events: &[Event],
        passed: bool,
        writer: &mut SliceWriter<'_, Event>,
    ) {
        let flip = if passed { 0 } else { u64::MAX };
        for (chunk, &word) in events.chunks(64).zip(&self.pass) {
            // Bits past the last event of a partial chunk are clear in `pass` and must stay
            // clear after the flip.
            let valid = u64::MAX >> (64 - chunk.len());
            let mut selected = (word ^ flip) & valid;
            if selected == valid {
                writer.extend_from_slice(chunk);
                continue;
            }
            while selected != 0 {
                writer.push(chunk[selected.trailing_zeros() as usize]);
                selected &= selected - 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use evgate_core::{BitMask, SensorSize};
    use evgate_ipc::ForecastHeader;
    use proptest::prelude::*;
    use std::time::Duration;

    const SENSOR: SensorSize = SensorSize::new(8, 4);

    /// Current mask: column 0; horizon 10 ms: column 1; horizon 20 ms: column 2.
    fn forecast(reference_time_us: i64) -> StoredForecast {
        let mut words = Vec::new();
        for column in 0..3 {
            let mut mask = BitMask::new(SENSOR).unwrap();
            for y in 0..SENSOR.height {
                mask.set(column, y, true).unwrap();
            }
            words.extend_from_slice(mask.as_words());
        }
        let mut header = ForecastHeader {
            source_stream_id: 1,
            reference_time_us,
            horizon_count: 2,
            words_per_mask: 1,
            width: SENSOR.width,
            height: SENSOR.height,
            ..Default::default()
        };
        header.horizons_us[..2].copy_from_slice(&[10_000, 20_000]);
        StoredForecast::copy_from(header, &words).unwrap()
    }

    fn selected(judge: &Judge, events: &[Event], passed: bool) -> Vec<Event> {
        let mut slots = vec![std::mem::MaybeUninit::uninit(); events.len()];
        let mut writer = SliceWriter::new(&mut slots);
        judge.write_selected(events, passed, &mut writer);
        assert_eq!(writer.overflowed(), 0);
        writer.as_written().to_vec()
    }

    fn policy(no_forecast: NoForecast) -> Policy {
        Policy {
            no_forecast,
            last_mask_max_age: Duration::from_millis(100),
        }
    }

    #[test]
    fn forecast_judges_by_horizon_and_policy_takes_the_rest() {
        let forecast = forecast(1_000_000);
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
            Some(&forecast),
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
            Some(&forecast),
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
            let forecast = forecast(1_000_000);
            let no_forecast = [NoForecast::Pass, NoForecast::Drop, NoForecast::LastMask][policy_index];
            let mode = if ego { GateMode::KeepEgoMotion } else { GateMode::KeepMovingObjects };
            let mut judge = Judge::default();
            let verdict = judge.judge(&events, with_forecast.then_some(&forecast), mode, policy(no_forecast));
            let total = verdict.kept + verdict.suppressed + verdict.unjudged_passed + verdict.unjudged_dropped;
            prop_assert_eq!(total, events.len() as u64);
            let kept = selected(&judge, &events, true);
            let suppressed = selected(&judge, &events, false);
            prop_assert_eq!(kept.len() as u64, verdict.passed());
            prop_assert_eq!(kept.len() + suppressed.len(), events.len());
            // Both outputs keep the input order and follow the pass bits.
            let bit_of = |index: usize| judge.pass[index / 64] >> (index % 64) & 1 == 1;
            let expected_kept: Vec<Event> = (0..events.len()).filter(|&i| bit_of(i)).map(|i| events[i]).collect();
            let expected_suppressed: Vec<Event> = (0..events.len()).filter(|&i| !bit_of(i)).map(|i| events[i]).collect();
            prop_assert_eq!(kept, expected_kept);
            prop_assert_eq!(suppressed, expected_suppressed);
        }
    }
}
