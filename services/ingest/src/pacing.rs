//! Publishes batches at the pace of their timestamps (optionally sped up or slowed down).

use std::time::{Duration, Instant};

/// Maps stream time to wall-clock time from the first batch on.
pub struct Pacer {
    speed: f64,
    origin: Option<(Instant, i64)>,
}

impl Pacer {
    /// `speed` = stream seconds per wall-clock second (2.0 replays twice as fast).
    pub fn new(speed: f64) -> Self {
        Self {
            speed,
            origin: None,
        }
    }

    /// How long to wait before publishing a batch that ends at `t_end_us` (a batch is complete,
    /// in real time, once its span has elapsed).
    pub fn wait_before(&mut self, t_end_us: i64, now: Instant) -> Duration {
        let (start, first_t) = *self.origin.get_or_insert((now, t_end_us));
        let stream_elapsed = (t_end_us - first_t).max(0) as f64 * 1e-6 / self.speed;
        let due = start + Duration::from_secs_f64(stream_elapsed);
        due.saturating_duration_since(now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_for_the_stream_time_divided_by_speed() {
        let mut pacer = Pacer::new(2.0);
        let start = Instant::now();
        assert_eq!(pacer.wait_before(1_000_000, start), Duration::ZERO);
        let wait = pacer.wait_before(3_000_000, start);
        assert_eq!(wait, Duration::from_secs(1));
        assert_eq!(
            pacer.wait_before(3_000_000, start + Duration::from_secs(5)),
            Duration::ZERO
        );
    }
}
