//! Time spans of stream time and the events of a time-sorted slice that fall in one, without
//! copying.

use crate::event::Event;

/// Why a time span could not be built.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum WindowError {
    #[error("time range is empty or reversed: begin = {begin_us} µs, end = {end_us} µs")]
    EmptyRange { begin_us: i64, end_us: i64 },
}

/// A half-open interval of stream time `[start, end)` in microseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TimeSpan {
    pub start: i64,
    pub end: i64,
}

impl TimeSpan {
    /// Builds a span; `end` must be after `start`.
    pub fn new(start: i64, end: i64) -> Result<Self, WindowError> {
        if end <= start {
            return Err(WindowError::EmptyRange {
                begin_us: start,
                end_us: end,
            });
        }
        Ok(Self { start, end })
    }

    /// Length in microseconds.
    pub const fn duration(&self) -> i64 {
        self.end - self.start
    }
}

/// The events with `begin ≤ t < end` of a time-sorted slice (binary search, no copy).
pub fn events_in(events: &[Event], span: TimeSpan) -> &[Event] {
    let first = events.partition_point(|event| event.t < span.start);
    let rest = &events[first..];
    &rest[..rest.partition_point(|event| event.t < span.end)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn at(times: &[i64]) -> Vec<Event> {
        times.iter().map(|&t| Event::new(t, 0, 0, true)).collect()
    }

    #[test]
    fn empty_and_reversed_spans_are_rejected() {
        assert_eq!(
            TimeSpan::new(5, 5).unwrap_err(),
            WindowError::EmptyRange {
                begin_us: 5,
                end_us: 5
            }
        );
        assert!(TimeSpan::new(5, 4).is_err());
        assert_eq!(TimeSpan::new(-3, 7).unwrap().duration(), 10);
    }

    #[test]
    fn events_in_selects_half_open_range() {
        let events = at(&[1, 2, 3, 4, 5]);
        assert_eq!(
            events_in(&events, TimeSpan::new(2, 4).unwrap()),
            &events[1..3]
        );
    }

    proptest! {
        #[test]
        fn events_in_keeps_exactly_the_events_of_the_span(
            mut times in prop::collection::vec(-1_000i64..1_000, 0..200),
            start in -1_200i64..1_200,
            duration in 1i64..300,
        ) {
            times.sort_unstable();
            let events = at(&times);
            let span = TimeSpan::new(start, start + duration).unwrap();
            let inside: Vec<Event> = events.iter().copied().filter(|e| e.t >= span.start && e.t < span.end).collect();
            prop_assert_eq!(events_in(&events, span), &inside[..]);
        }
    }
}
