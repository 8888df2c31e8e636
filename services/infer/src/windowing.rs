//! Cutting the incoming event stream into the network's input windows: every `stride` of event
//! time a window `[t − window, t]` closes at reference time t, or, by count, every N events.

use evgate_core::window::TimeSpan;
use evgate_core::Event;

/// When windows close.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WindowMode {
    /// A window of `window_us` ending at each multiple of `stride_us` after the stream start.
    Duration { window_us: i64, stride_us: i64 },
    /// A window of exactly `events` events, back to back.
    EventCount { events: usize },
}

#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum WindowingError {
    #[error("window length must be at least 1 µs, got {value} µs")]
    Window { value: i64 },
    #[error("window stride must be at least 1 µs, got {value} µs")]
    Stride { value: i64 },
    #[error("--window-events must be at least 1, got 0")]
    EventCount,
}

/// One closed window: its events are a copy, so the assembler can keep receiving.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedWindow {
    /// The window's time span; the voxel grid counts events with start ≤ t ≤ end.
    pub span: TimeSpan,
    pub events: Vec<Event>,
}

impl ClosedWindow {
    /// The time t the forecast refers to: the window's end.
    pub fn reference_time_us(&self) -> i64 {
        self.span.end
    }
}

/// Most windows one batch may close; after a longer silence in event time (a paused camera) the
/// windows in between would all be empty and are skipped and counted instead.
const MAX_WINDOWS_PER_BATCH: i64 = 4;

pub struct WindowAssembler {
    mode: WindowMode,
    buffer: Vec<Event>,
    next_reference_us: Option<i64>,
    /// End of the window [`WindowAssembler::close_at_stream_end`] closed last.
    stream_end_us: Option<i64>,
    skipped_silent_windows: u64,
}

impl WindowAssembler {
    pub fn new(mode: WindowMode) -> Result<Self, WindowingError> {
        match mode {
            WindowMode::Duration { window_us, .. } if window_us < 1 => {
                return Err(WindowingError::Window { value: window_us })
            }
            WindowMode::Duration { stride_us, .. } if stride_us < 1 => {
                return Err(WindowingError::Stride { value: stride_us })
            }
            WindowMode::EventCount { events: 0 } => return Err(WindowingError::EventCount),
            _ => {}
        }
        Ok(Self {
            mode,
            buffer: Vec::new(),
            next_reference_us: None,
            stream_end_us: None,
            skipped_silent_windows: 0,
        })
    }

    /// Forgets the stream (a new stream id, a restart): the next batch starts afresh.
    pub fn reset(&mut self) {
        self.buffer.clear();
        self.next_reference_us = None;
        self.stream_end_us = None;
    }

    /// Windows passed over because a batch jumped far ahead in event time.
    pub fn skipped_silent_windows(&self) -> u64 {
        self.skipped_silent_windows
    }

    /// Adds one time-sorted batch covering `[batch_begin_us, batch_end_us)` and appends the
    /// windows it closes to `closed`, oldest first.
    pub fn push(
        &mut self,
        events: &[Event],
        batch_begin_us: i64,
        batch_end_us: i64,
        closed: &mut Vec<ClosedWindow>,
    ) {
        self.buffer.extend_from_slice(events);
        match self.mode {
            WindowMode::Duration {
                window_us,
                stride_us,
            } => self.close_by_duration(window_us, stride_us, batch_begin_us, batch_end_us, closed),
            WindowMode::EventCount { events } => self.close_by_count(events, closed),
        }
    }

    /// Closes a last window ending at `end_us`, the stream's end (after its last event), unless
    /// one already ends there or later. Under `--every-window` the last forecast then lies past
    /// every event, which tells a lock-step gate that its forecasts are all in.
    pub fn close_at_stream_end(&mut self, end_us: i64, closed: &mut Vec<ClosedWindow>) {
        let last_closed_us = closed
            .last()
            .map(ClosedWindow::reference_time_us)
            .max(self.stream_end_us);
        let start = match self.mode {
            WindowMode::Duration {
                window_us,
                stride_us,
            } => {
                let previous = self.next_reference_us.map(|next| next - stride_us);
                if previous.max(last_closed_us).is_some_and(|t| t >= end_us) {
                    return;
                }
                end_us - window_us
            }
            WindowMode::EventCount { .. } => {
                if last_closed_us.is_some_and(|t| t >= end_us) {
                    return;
                }
                self.buffer.first().map_or(end_us - 1, |e| e.t)
            }
        };
        closed.push(self.window(TimeSpan {
            start: start.min(end_us - 1),
            end: end_us,
        }));
        self.stream_end_us = Some(end_us);
    }

    /// The buffered events of `span` (both ends included), as a closed window.
    fn window(&self, span: TimeSpan) -> ClosedWindow {
        let first = self.buffer.partition_point(|e| e.t < span.start);
        let last = self.buffer.partition_point(|e| e.t <= span.end);
        ClosedWindow {
            span,
            events: self.buffer[first..last.max(first)].to_vec(),
        }
    }

    fn close_by_duration(
        &mut self,
        window_us: i64,
        stride_us: i64,
        batch_begin_us: i64,
        batch_end_us: i64,
        closed: &mut Vec<ClosedWindow>,
    ) {
        let stream_start = self
            .buffer
            .first()
            .map_or(batch_begin_us, |e| e.t.min(batch_begin_us));
        let mut reference = *self
            .next_reference_us
            .get_or_insert(stream_start.saturating_add(window_us));
        // Every event with t ≤ reference has arrived once a batch ends after the reference.
        let last_complete = batch_end_us.saturating_sub(1).max(
            self.buffer
                .last()
                .map_or(i64::MIN, |e| e.t.saturating_sub(1)),
        );
        if last_complete >= reference {
            let closable = (last_complete - reference) / stride_us + 1;
            if closable > MAX_WINDOWS_PER_BATCH {
                let skipped = closable - MAX_WINDOWS_PER_BATCH;
                self.skipped_silent_windows += skipped as u64;
                reference += skipped * stride_us;
            }
        }
        while reference <= last_complete {
            closed.push(self.window(TimeSpan {
                start: reference - window_us,
                end: reference,
            }));
            reference += stride_us;
        }
        self.next_reference_us = Some(reference);
        let keep_from = self.buffer.partition_point(|e| e.t < reference - window_us);
        self.buffer.drain(..keep_from);
    }

    fn close_by_count(&mut self, count: usize, closed: &mut Vec<ClosedWindow>) {
        let mut start = 0;
        while self.buffer.len() - start >= count {
            let events = &self.buffer[start..start + count];
            let (first, last) = (events[0].t, events[count - 1].t);
            // A window needs a positive duration; a burst of equal times gets 1 µs.
            let span = TimeSpan {
                start: first,
                end: last.max(first + 1),
            };
            closed.push(ClosedWindow {
                span,
                events: events.to_vec(),
            });
            start += count;
        }
        self.buffer.drain(..start);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn event(t: i64) -> Event {
        Event::new(t, 1, 1, true)
    }

    fn duration(window_us: i64, stride_us: i64) -> WindowAssembler {
        WindowAssembler::new(WindowMode::Duration {
            window_us,
            stride_us,
        })
        .unwrap()
    }

    #[test]
    fn the_stream_end_closes_a_last_window_past_every_event() {
        let mut assembler = duration(50, 50);
        let mut closed = Vec::new();
        assembler.push(&[event(0), event(60), event(120)], 0, 121, &mut closed);
        assert_eq!(
            closed.iter().map(|w| w.span.end).collect::<Vec<_>>(),
            vec![50, 100]
        );
        assembler.close_at_stream_end(121, &mut closed);
        let last = closed.last().unwrap();
        assert_eq!(
            last.span,
            TimeSpan {
                start: 71,
                end: 121
            }
        );
        assert_eq!(
            last.events.iter().map(|e| e.t).collect::<Vec<_>>(),
            vec![120]
        );
        let windows = closed.len();
        assembler.close_at_stream_end(121, &mut closed);
        assert_eq!(closed.len(), windows, "the end closes one window only");
    }

    #[test]
    fn a_window_closes_once_a_batch_ends_after_its_reference_time() {
        let mut assembler = duration(50, 50);
        let mut closed = Vec::new();
        assembler.push(&[event(0), event(20)], 0, 40, &mut closed);
        assert!(closed.is_empty());
        assembler.push(&[event(50)], 40, 50, &mut closed);
        assert!(closed.is_empty(), "an event at t = 50 may still come");
        assembler.push(&[event(55)], 50, 60, &mut closed);
        assert_eq!(closed.len(), 1);
        assert_eq!(closed[0].span, TimeSpan { start: 0, end: 50 });
        assert_eq!(
            closed[0].events.iter().map(|e| e.t).collect::<Vec<_>>(),
            vec![0, 20, 50]
        );
    }

    #[test]
    fn overlapping_windows_share_events() {
        let mut assembler = duration(50, 25);
        let mut closed = Vec::new();
        let events: Vec<Event> = (0..100).step_by(10).map(event).collect();
        assembler.push(&events, 0, 101, &mut closed);
        let spans: Vec<(i64, i64)> = closed.iter().map(|w| (w.span.start, w.span.end)).collect();
        assert_eq!(spans, vec![(0, 50), (25, 75), (50, 100)]);
        assert_eq!(
            closed[1].events.iter().map(|e| e.t).collect::<Vec<_>>(),
            vec![30, 40, 50, 60, 70]
        );
    }

    #[test]
    fn a_long_silence_skips_and_counts_the_empty_windows() {
        let mut assembler = duration(50, 50);
        let mut closed = Vec::new();
        assembler.push(&[event(0)], 0, 10, &mut closed);
        assembler.push(&[event(100_000)], 10, 100_001, &mut closed);
        assert_eq!(closed.len() as i64, MAX_WINDOWS_PER_BATCH);
        assert_eq!(closed.last().unwrap().span.end, 100_000);
        assert_eq!(closed.last().unwrap().events.len(), 1);
        assert_eq!(assembler.skipped_silent_windows(), 2000 - 4);
    }

    #[test]
    fn count_windows_take_exactly_n_events() {
        let mut assembler = WindowAssembler::new(WindowMode::EventCount { events: 3 }).unwrap();
        let mut closed = Vec::new();
        assembler.push(&[event(1), event(2)], 0, 3, &mut closed);
        assert!(closed.is_empty());
        assembler.push(
            &[event(3), event(3), event(3), event(3), event(9)],
            3,
            10,
            &mut closed,
        );
        assert_eq!(closed.len(), 2);
        assert_eq!(closed[0].span, TimeSpan { start: 1, end: 3 });
        assert_eq!(closed[1].span, TimeSpan { start: 3, end: 4 });
    }

    #[test]
    fn invalid_modes_are_rejected() {
        assert!(WindowAssembler::new(WindowMode::EventCount { events: 0 }).is_err());
        assert!(WindowAssembler::new(WindowMode::Duration {
            window_us: 0,
            stride_us: 1
        })
        .is_err());
        assert!(WindowAssembler::new(WindowMode::Duration {
            window_us: 1,
            stride_us: 0
        })
        .is_err());
    }

    proptest! {
        /// However the stream is cut into batches (each covering [begin, end) as the ingest
        /// publishes them), the windows hold exactly the events of their span.
        #[test]
        fn windows_hold_exactly_the_events_of_their_span(
            gaps in proptest::collection::vec(0i64..30, 1..300),
            cuts in proptest::collection::vec(1usize..40, 1..50),
        ) {
            let times: Vec<i64> = gaps.iter().scan(0i64, |t, gap| { *t += gap; Some(*t) }).collect();
            let events: Vec<Event> = times.iter().map(|&t| event(t)).collect();
            let mut assembler = duration(50, 20);
            let mut closed = Vec::new();
            let mut start = 0;
            let mut batch_begin = 0;
            for cut in cuts.iter().cycle() {
                if start >= events.len() { break; }
                // A batch covers [begin, end): it ends where the next batch's first event is,
                // so equal times never straddle two batches.
                let mut end = (start + cut).min(events.len());
                while end < events.len() && events[end].t == events[end - 1].t {
                    end += 1;
                }
                let batch_end = events.get(end).map_or(events[end - 1].t + 1, |e| e.t);
                assembler.push(&events[start..end], batch_begin, batch_end, &mut closed);
                batch_begin = batch_end;
                start = end;
            }
            for window in &closed {
                let expected: Vec<i64> = times
                    .iter()
                    .copied()
                    .filter(|&t| window.span.start <= t && t <= window.span.end)
                    .collect();
                let got: Vec<i64> = window.events.iter().map(|e| e.t).collect();
                prop_assert_eq!(got, expected);
            }
            for pair in closed.windows(2) {
                prop_assert!(pair[1].span.end > pair[0].span.end);
            }
        }
    }
}
