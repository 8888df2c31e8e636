//! What a decoder repaired or skipped, and the policy that decides it.
//!
//! Policy (the same for every format):
//! - an event outside the sensor is dropped and counted (`dropped_out_of_sensor`, with the byte
//!   offset of the first one);
//! - an event whose time lies outside ±[`MAX_EVENT_TIME_US`] (about 36 600 years) is dropped and
//!   counted (`dropped_out_of_time_range`, with the byte offset of the first one): no camera
//!   writes such a time, and downstream arithmetic on stream time (batch spans, horizons) must
//!   not overflow;
//! - an event earlier than the one before it is kept unchanged and counted (`time_regressions`,
//!   with the index of the first such event among the delivered ones and the largest step back);
//! - a word of an unknown or unsupported type is skipped and counted (`skipped_words`, with the
//!   byte offset of the first one);
//! - an EVT `TIME_HIGH` that jumps implausibly far is ignored and counted
//!   (`implausible_time_jumps`; see [`crate::time_high`] for when a jump is followed);
//! - everything else that is wrong (bad magic or header, truncation, unparsable text) is an error.

pub use evgate_core::MAX_EVENT_TIME_US;
use evgate_core::{is_event_time, Event, SensorSize};
use serde::Serialize;

#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct DecodeReport {
    /// Events delivered to the caller.
    pub events: u64,
    pub dropped_out_of_sensor: u64,
    pub first_out_of_sensor_offset: Option<u64>,
    pub dropped_out_of_time_range: u64,
    pub first_out_of_time_range_offset: Option<u64>,
    pub time_regressions: u64,
    pub first_time_regression_index: Option<u64>,
    pub largest_time_regression_us: i64,
    pub skipped_words: u64,
    pub first_skipped_word_offset: Option<u64>,
    /// EVT `TIME_HIGH` words ignored as corrupt ([`crate::time_high`]).
    pub implausible_time_jumps: u64,
    pub first_implausible_time_jump_offset: Option<u64>,
}

impl DecodeReport {
    /// True when nothing was dropped, skipped or found out of order.
    pub fn is_clean(&self) -> bool {
        self.dropped_out_of_sensor == 0
            && self.dropped_out_of_time_range == 0
            && self.time_regressions == 0
            && self.skipped_words == 0
            && self.implausible_time_jumps == 0
    }

    pub fn skip_word(&mut self, offset: u64) {
        self.skipped_words += 1;
        self.first_skipped_word_offset.get_or_insert(offset);
    }
}

/// Applies the policy to each decoded event before it reaches the caller.
pub struct Admission {
    sensor_size: SensorSize,
    last_t: Option<i64>,
    pub report: DecodeReport,
}

impl Admission {
    pub fn new(sensor_size: SensorSize) -> Self {
        Self {
            sensor_size,
            last_t: None,
            report: DecodeReport::default(),
        }
    }

    pub fn sensor_size(&self) -> SensorSize {
        self.sensor_size
    }

    /// Delivers `event` into `out` or drops it; `offset` is where its bytes start.
    #[inline]
    pub fn admit(&mut self, out: &mut Vec<Event>, event: Event, offset: u64) {
        if !self.sensor_size.contains(&event) {
            self.report.dropped_out_of_sensor += 1;
            self.report.first_out_of_sensor_offset.get_or_insert(offset);
            return;
        }
        if !is_event_time(event.t) {
            self.report.dropped_out_of_time_range += 1;
            self.report
                .first_out_of_time_range_offset
                .get_or_insert(offset);
            return;
        }
        if let Some(last_t) = self.last_t {
            if event.t < last_t {
                self.report.time_regressions += 1;
                self.report
                    .first_time_regression_index
                    .get_or_insert(self.report.events);
                self.report.largest_time_regression_us = self
                    .report
                    .largest_time_regression_us
                    .max(last_t.saturating_sub(event.t));
            }
        }
        self.last_t = Some(event.t);
        self.report.events += 1;
        out.push(event);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_sensor_is_dropped_and_regressions_are_kept_and_counted() {
        let mut admission = Admission::new(SensorSize::new(4, 4));
        let mut out = Vec::new();
        admission.admit(&mut out, Event::new(10, 1, 1, true), 0);
        admission.admit(&mut out, Event::new(11, 4, 1, true), 4);
        admission.admit(&mut out, Event::new(7, 1, 3, false), 8);
        admission.admit(&mut out, Event::new(9, 1, 1, false), 12);
        admission.admit(&mut out, Event::new(2, 0, 0, false), 16);
        assert_eq!(out.len(), 4);
        let report = &admission.report;
        assert_eq!(report.dropped_out_of_sensor, 1);
        assert_eq!(report.first_out_of_sensor_offset, Some(4));
        assert_eq!(report.time_regressions, 2);
        assert_eq!(report.first_time_regression_index, Some(1));
        assert_eq!(report.largest_time_regression_us, 7);
        assert!(!report.is_clean());
    }

    #[test]
    fn a_regression_across_the_whole_time_range_is_counted() {
        let mut admission = Admission::new(SensorSize::new(4, 4));
        let mut out = Vec::new();
        admission.admit(&mut out, Event::new(MAX_EVENT_TIME_US, 0, 0, true), 0);
        admission.admit(&mut out, Event::new(-MAX_EVENT_TIME_US, 0, 0, true), 16);
        assert_eq!(
            admission.report.largest_time_regression_us,
            2 * MAX_EVENT_TIME_US
        );
        assert_eq!(admission.report.time_regressions, 1);
    }

    /// Issue 15: a CSV time near i64::MAX made evgate-ingest loop forever on batch spans that
    /// overflowed.
    #[test]
    fn times_past_the_range_are_dropped_and_counted() {
        let mut admission = Admission::new(SensorSize::new(4, 4));
        let mut out = Vec::new();
        admission.admit(&mut out, Event::new(5, 0, 0, true), 0);
        admission.admit(
            &mut out,
            Event::new(9_223_372_036_854_775_000, 1, 1, true),
            20,
        );
        admission.admit(&mut out, Event::new(i64::MIN, 1, 1, true), 40);
        admission.admit(&mut out, Event::new(6, 0, 0, true), 60);
        assert_eq!(
            out,
            vec![Event::new(5, 0, 0, true), Event::new(6, 0, 0, true)]
        );
        assert_eq!(admission.report.dropped_out_of_time_range, 2);
        assert_eq!(admission.report.first_out_of_time_range_offset, Some(20));
        assert_eq!(admission.report.time_regressions, 0);
        assert!(!admission.report.is_clean());
    }
}
