//! Splitting a time-sorted event slice into windows, by duration or by event count, without
//! copying: every window is a sub-slice of the input.

use crate::event::Event;

/// Why a window split could not be set up.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum WindowError {
    #[error("window duration must be at least 1 µs, got {duration_us} µs")]
    NonPositiveDuration { duration_us: i64 },
    #[error("window event count must be at least 1, got 0")]
    ZeroCount,
    #[error(
        "events are not sorted by time: event {index} has t = {t} µs, before the previous \
         event's t = {previous_t} µs"
    )]
    Unsorted {
        index: usize,
        t: i64,
        previous_t: i64,
    },
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

/// One window of a duration split: its time span and the events that fall in it (maybe none).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeWindow<'a> {
    pub span: TimeSpan,
    pub events: &'a [Event],
}

/// Index of the first event that breaks time order, if any.
fn first_unsorted(events: &[Event]) -> Option<usize> {
    events
        .windows(2)
        .position(|pair| pair[1].t < pair[0].t)
        .map(|position| position + 1)
}

fn require_sorted(events: &[Event]) -> Result<(), WindowError> {
    match first_unsorted(events) {
        Some(index) => Err(WindowError::Unsorted {
            index,
            t: events[index].t,
            previous_t: events[index - 1].t,
        }),
        None => Ok(()),
    }
}

/// The events with `begin ≤ t < end` of a time-sorted slice (binary search, no copy).
pub fn events_in(events: &[Event], span: TimeSpan) -> &[Event] {
    let first = events.partition_point(|event| event.t < span.start);
    let rest = &events[first..];
    &rest[..rest.partition_point(|event| event.t < span.end)]
}

/// Iterator over consecutive windows `[start + k·d, start + (k+1)·d)`, k = 0, 1, …, up to the
/// window holding the last event. Windows without events are yielded too (a gap in the stream
/// is information for the consumer). Events before `start` belong to no window; their number is
/// [`WindowsByDuration::skipped_before_start`].
#[derive(Clone, Debug)]
pub struct WindowsByDuration<'a> {
    remaining: &'a [Event],
    next_start: Option<i64>,
    duration_us: i64,
    skipped_before_start: usize,
}

impl<'a> WindowsByDuration<'a> {
    /// Splits `events` (sorted by time, checked) into windows of `duration_us` aligned to
    /// `start_us`.
    pub fn new(events: &'a [Event], start_us: i64, duration_us: i64) -> Result<Self, WindowError> {
        if duration_us <= 0 {
            return Err(WindowError::NonPositiveDuration { duration_us });
        }
        require_sorted(events)?;
        let skipped_before_start = events.partition_point(|event| event.t < start_us);
        Ok(Self {
            remaining: &events[skipped_before_start..],
            next_start: Some(start_us),
            duration_us,
            skipped_before_start,
        })
    }

    /// Number of events earlier than the first window's start.
    pub fn skipped_before_start(&self) -> usize {
        self.skipped_before_start
    }
}

impl<'a> Iterator for WindowsByDuration<'a> {
    type Item = TimeWindow<'a>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.remaining.is_empty() {
            return None;
        }
        let start = self.next_start?;
        // Near i64::MAX the window is cut short rather than wrapping around.
        let end = start.saturating_add(self.duration_us);
        let count = if end == i64::MAX {
            self.remaining.len()
        } else {
            self.remaining.partition_point(|event| event.t < end)
        };
        let (inside, rest) = self.remaining.split_at(count);
        self.remaining = rest;
        self.next_start = (end != i64::MAX).then_some(end);
        Some(TimeWindow {
            span: TimeSpan { start, end },
            events: inside,
        })
    }
}

/// Splits `events` into consecutive windows of `count` events; the last one may be shorter.
pub fn windows_by_count(
    events: &[Event],
    count: usize,
) -> Result<std::slice::Chunks<'_, Event>, WindowError> {
    if count == 0 {
        return Err(WindowError::ZeroCount);
    }
    Ok(events.chunks(count))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn at(times: &[i64]) -> Vec<Event> {
        times.iter().map(|&t| Event::new(t, 0, 0, true)).collect()
    }

    #[test]
    fn duration_windows_report_empty_gaps() {
        let events = at(&[0, 5, 9, 31]);
        let windows: Vec<_> = WindowsByDuration::new(&events, 0, 10).unwrap().collect();
        let lengths: Vec<_> = windows.iter().map(|w| w.events.len()).collect();
        assert_eq!(lengths, [3, 0, 0, 1]);
        assert_eq!(windows[3].span, TimeSpan { start: 30, end: 40 });
    }

    #[test]
    fn duration_windows_skip_events_before_start() {
        let events = at(&[-3, -1, 0, 10]);
        let mut windows = WindowsByDuration::new(&events, 0, 10).unwrap();
        assert_eq!(windows.skipped_before_start(), 2);
        assert_eq!(windows.next().unwrap().events, &events[2..3]);
        assert_eq!(windows.next().unwrap().events, &events[3..4]);
        assert!(windows.next().is_none());
    }

    #[test]
    fn window_boundaries_are_half_open() {
        let events = at(&[9, 10]);
        let windows: Vec<_> = WindowsByDuration::new(&events, 0, 10).unwrap().collect();
        assert_eq!(windows[0].events, &events[..1]);
        assert_eq!(windows[1].events, &events[1..]);
    }

    #[test]
    fn windows_near_the_end_of_time_do_not_overflow() {
        let events = at(&[i64::MAX - 1, i64::MAX]);
        let windows: Vec<_> = WindowsByDuration::new(&events, i64::MAX - 5, 100)
            .unwrap()
            .collect();
        assert_eq!(windows.len(), 1);
        assert_eq!(windows[0].events.len(), 2);
    }

    #[test]
    fn bad_parameters_are_rejected() {
        assert_eq!(
            WindowsByDuration::new(&[], 0, 0).unwrap_err(),
            WindowError::NonPositiveDuration { duration_us: 0 }
        );
        assert_eq!(
            windows_by_count(&[], 0).unwrap_err(),
            WindowError::ZeroCount
        );
        assert_eq!(
            WindowsByDuration::new(&at(&[1, 3, 2]), 0, 5).unwrap_err(),
            WindowError::Unsorted {
                index: 2,
                t: 2,
                previous_t: 3
            }
        );
        assert!(TimeSpan::new(5, 5).is_err());
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
        fn duration_windows_cover_every_event_once(
            mut times in prop::collection::vec(-1_000i64..1_000, 0..200),
            start in -1_200i64..1_200,
            duration in 1i64..300,
        ) {
            times.sort_unstable();
            let events = at(&times);
            let windows = WindowsByDuration::new(&events, start, duration).unwrap();
            let skipped = windows.skipped_before_start();
            let mut expected_start = start;
            let mut seen = skipped;
            for window in windows {
                prop_assert_eq!(window.span.start, expected_start);
                prop_assert_eq!(window.span.duration(), duration);
                for event in window.events {
                    prop_assert!(event.t >= window.span.start && event.t < window.span.end);
                }
                prop_assert_eq!(window.events, &events[seen..seen + window.events.len()]);
                seen += window.events.len();
                expected_start += duration;
            }
            prop_assert_eq!(seen, events.len());
            prop_assert_eq!(skipped, times.iter().filter(|&&t| t < start).count());
        }

        #[test]
        fn count_windows_concatenate_to_input(
            times in prop::collection::vec(0i64..1_000, 0..200),
            count in 1usize..50,
        ) {
            let events = at(&times);
            let windows: Vec<&[Event]> = windows_by_count(&events, count).unwrap().collect();
            prop_assert!(windows.iter().all(|w| w.len() <= count && !w.is_empty()));
            prop_assert_eq!(windows.concat(), events);
        }
    }
}
