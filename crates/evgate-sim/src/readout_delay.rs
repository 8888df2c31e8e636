//! Timestamp jitter: a real sensor stamps an event when its arbiter reads the pixel out, a
//! little after the threshold crossing, and the delay varies from event to event. Each event is
//! delayed by an exponentially distributed time (mean [`EventModel::timestamp_jitter_us`]), and
//! the stream is put back in delivery order.
//!
//! Delays are never negative, so once the simulator has produced every crossing up to `t`, no
//! later crossing can be stamped at or before `t`: the delayed events up to `t` are final and
//! can be delivered, and the others wait for the next call.
//!
//! [`EventModel::timestamp_jitter_us`]: crate::EventModel::timestamp_jitter_us

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::esim::LabelledEvent;
use crate::event_sort::event_order;

/// Decorrelates the delays' generator from the scene's and the noise's, which use the seed.
const DELAY_SALT: u64 = 0x5851_f42d_4c95_7f2d;

/// Delays events by a random readout time and keeps the stream in delivery order.
#[derive(Debug)]
pub struct ReadoutDelay {
    mean_us: f32,
    rng: ChaCha8Rng,
    /// Delayed events not yet due, in no particular order.
    held: Vec<LabelledEvent>,
}

impl ReadoutDelay {
    pub fn new(mean_us: f32, seed: u64) -> ReadoutDelay {
        ReadoutDelay {
            mean_us,
            rng: ChaCha8Rng::seed_from_u64(seed ^ DELAY_SALT),
            held: Vec::new(),
        }
    }

    /// Delays `crossings` (every crossing up to `t_end_us`, in delivery order) and appends to
    /// `out`, in delivery order, the delayed events due by `t_end_us`.
    pub fn delay(
        &mut self,
        crossings: &[LabelledEvent],
        t_end_us: i64,
        out: &mut Vec<LabelledEvent>,
    ) {
        for crossing in crossings {
            let mut delayed = *crossing;
            // Inverse transform of the exponential distribution; `1 - u` lies in (0, 1].
            let u: f64 = self.rng.gen();
            let delay = -(1.0 - u).ln() * f64::from(self.mean_us);
            delayed.event.t = delayed.event.t.saturating_add(delay.round() as i64);
            self.held.push(delayed);
        }
        // Events stay in the order they arrived where the delivery order ties (one pixel at one
        // microsecond), as the simulator's own sort keeps them.
        self.held.sort_by_key(event_order);
        let due = self.held.partition_point(|e| e.event.t <= t_end_us);
        out.extend(self.held.drain(..due));
    }
}

#[cfg(test)]
mod tests {
    use evgate_core::Event;

    use super::*;

    fn crossing(t: i64, x: u16) -> LabelledEvent {
        LabelledEvent {
            event: Event::new(t, x, 0, true),
            label: x,
        }
    }

    #[test]
    fn delays_are_positive_with_the_requested_mean_and_the_stream_stays_ordered() {
        let mut delay = ReadoutDelay::new(40.0, 3);
        let crossings: Vec<_> = (0..20_000)
            .map(|i| crossing(i * 10, (i % 300) as u16))
            .collect();
        let mut out = Vec::new();
        for chunk in crossings.chunks(1_000) {
            let t_end = chunk.last().unwrap().event.t;
            delay.delay(chunk, t_end, &mut out);
            assert!(out.iter().all(|e| e.event.t <= t_end));
        }
        delay.delay(&[], i64::MAX, &mut out);
        assert_eq!(out.len(), crossings.len());
        assert!(out
            .windows(2)
            .all(|w| event_order(&w[0]) <= event_order(&w[1])));
        let mut shifts: Vec<i64> = Vec::new();
        let mut by_label = crossings.clone();
        by_label.sort_by_key(|e| (e.label, e.event.t));
        let mut delayed = out.clone();
        delayed.sort_by_key(|e| (e.label, e.event.t));
        for (before, after) in by_label.iter().zip(&delayed) {
            shifts.push(after.event.t - before.event.t);
        }
        let mean = shifts.iter().sum::<i64>() as f64 / shifts.len() as f64;
        assert!(shifts.iter().all(|&s| s >= 0));
        assert!((mean - 40.0).abs() < 3.0, "mean delay {mean}");
    }

    #[test]
    fn zero_mean_changes_nothing() {
        let crossings: Vec<_> = (0..100).map(|i| crossing(i, i as u16)).collect();
        let mut out = Vec::new();
        ReadoutDelay::new(0.0, 1).delay(&crossings, 99, &mut out);
        assert_eq!(out, crossings);
    }
}
