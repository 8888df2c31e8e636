//! The high time bits of Prophesee EVT 2.0 and 3.0 streams, with one policy for corrupt words.
//!
//! A sensor sends `TIME_HIGH` at every step of its high bits (every 64 µs in EVT 2.0, every
//! 4096 µs in EVT 3.0), so consecutive values step forward by a unit or two and wrap at the top
//! of their range. A value that steps forward (modulo the range) by more than
//! [`MAX_TIME_HIGH_STEP_US`] is taken for a corrupt word: it is ignored, counted as
//! `implausible-time-jumps` with the offset of the first, and the time base stays where it was,
//! unless the next `TIME_HIGH` follows on from it within the same bound, in which case the
//! stream really jumped (lost data, a paused camera) and the decoder follows it. Reading every
//! such word as a wrap instead added 2^34 µs (EVT 2.0) or 2^24 µs (EVT 3.0) to the time, and a
//! paced replay then slept for hours.

use crate::report::DecodeReport;

/// The largest forward step of one `TIME_HIGH` taken as the stream's own (about one second).
pub const MAX_TIME_HIGH_STEP_US: i64 = 1 << 20;

/// Where the sum of wraps stops growing: far past any time a decoder delivers (±2^60 µs), yet
/// far enough below `i64::MAX` that adding the high and low bits of a word cannot overflow.
const WRAPPED_US_CAP: i64 = i64::MAX / 2;

/// The time base that `TIME_HIGH` words carry.
pub struct TimeHigh {
    unit_us: i64,
    range: i64,
    /// The accepted high value, in units; `None` before the first.
    current: Option<i64>,
    /// An implausible value waiting for a second word to confirm it.
    candidate: Option<i64>,
    /// Microseconds of the completed wraps.
    wrapped_us: i64,
    /// `wrapped_us` plus the accepted value in microseconds.
    base_us: i64,
}

impl TimeHigh {
    /// High values of `bits` bits in units of `unit_us` microseconds.
    pub const fn new(bits: u32, unit_us: i64) -> Self {
        Self {
            unit_us,
            range: 1 << bits,
            current: None,
            candidate: None,
            wrapped_us: 0,
            base_us: 0,
        }
    }

    /// Microseconds of the accepted high bits, wraps included; adding a word's low bits to it
    /// cannot overflow.
    #[inline]
    pub fn base_us(&self) -> i64 {
        self.base_us
    }

    /// Takes the value of a `TIME_HIGH` word found at byte `offset`.
    pub fn update(&mut self, value: i64, offset: u64, report: &mut DecodeReport) {
        let Some(current) = self.current else {
            self.accept(value);
            return;
        };
        let step_us = |from: i64| (value - from).rem_euclid(self.range) * self.unit_us;
        let plausible = |from: i64| step_us(from) <= MAX_TIME_HIGH_STEP_US;
        if plausible(current) || self.candidate.is_some_and(plausible) {
            if value < current {
                // Capped: adversarial input can repeat wraps past the i64 range.
                self.wrapped_us = (self.wrapped_us + self.range * self.unit_us).min(WRAPPED_US_CAP);
            }
            self.accept(value);
        } else {
            self.candidate = Some(value);
            report.implausible_time_jumps += 1;
            report
                .first_implausible_time_jump_offset
                .get_or_insert(offset);
        }
    }

    fn accept(&mut self, value: i64) {
        self.current = Some(value);
        self.candidate = None;
        self.base_us = self.wrapped_us + value * self.unit_us;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(values: &[i64]) -> (Vec<i64>, DecodeReport) {
        let mut report = DecodeReport::default();
        let mut high = TimeHigh::new(12, 4096);
        let bases = values
            .iter()
            .enumerate()
            .map(|(index, &value)| {
                high.update(value, index as u64 * 2, &mut report);
                high.base_us()
            })
            .collect();
        (bases, report)
    }

    #[test]
    fn steps_and_wraps_are_followed() {
        let (bases, report) = feed(&[4094, 4095, 0, 1]);
        assert_eq!(
            bases,
            vec![4094 * 4096, 4095 * 4096, 4096 << 12, 4097 * 4096]
        );
        assert_eq!(report.implausible_time_jumps, 0);
    }

    /// Issue 15: one bad word was read as a wrap (+2^24 µs here).
    #[test]
    fn one_corrupt_word_is_ignored_and_counted() {
        let (bases, report) = feed(&[100, 101, 7, 102, 103]);
        assert_eq!(
            bases,
            vec![100 * 4096, 101 * 4096, 101 * 4096, 102 * 4096, 103 * 4096]
        );
        assert_eq!(report.implausible_time_jumps, 1);
        assert_eq!(report.first_implausible_time_jump_offset, Some(4));
    }

    #[test]
    fn a_real_jump_is_followed_at_its_second_word() {
        let (bases, report) = feed(&[100, 2000, 2001, 2002]);
        assert_eq!(
            bases,
            vec![100 * 4096, 100 * 4096, 2001 * 4096, 2002 * 4096]
        );
        assert_eq!(report.implausible_time_jumps, 1);
        // A jump across the top of the range counts the wrap.
        let (bases, _) = feed(&[3000, 10, 11]);
        assert_eq!(bases[2], (4096 + 11) * 4096);
    }
}
