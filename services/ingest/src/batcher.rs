//! Cuts the event stream into batches by duration or by count.

use evgate_core::Event;

use crate::source::{Chunk, EventSource, SourceError};

/// How batches are cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BatchSize {
    /// Consecutive time spans `[t0 + k·d, t0 + (k+1)·d)` of `d` microseconds (empty spans are
    /// skipped).
    Duration { micros: i64 },
    /// `n` events per batch (the last may be shorter).
    Count { events: usize },
    /// Whatever each chunk of the source brings, at once: a live stream's packets as they
    /// arrive.
    Arrival,
}

/// One batch ready to publish.
pub struct Batch<'a> {
    pub events: &'a [Event],
    /// Empty when the source has no labels.
    pub labels: &'a [u16],
    pub t_begin_us: i64,
    pub t_end_us: i64,
    /// The source has no further events (after this batch).
    pub last: bool,
}

/// Pulls chunks from a source and hands out batches.
pub struct Batcher {
    size: BatchSize,
    pending_events: Vec<Event>,
    pending_labels: Vec<u16>,
    /// Events of `pending_*` already handed out.
    consumed: usize,
    watermark_us: i64,
    exhausted: bool,
    /// Start of the next duration batch; unset before the first event.
    next_begin_us: Option<i64>,
}

impl Batcher {
    pub fn new(size: BatchSize) -> Self {
        Self {
            size,
            pending_events: Vec::new(),
            pending_labels: Vec::new(),
            consumed: 0,
            watermark_us: i64::MIN,
            exhausted: false,
            next_begin_us: None,
        }
    }

    /// Starts a new pass over a restarted source; the time grid continues.
    pub fn resume(&mut self) {
        self.exhausted = false;
    }

    /// The next batch, pulling from `source` as needed; `None` once the source is exhausted
    /// and everything was handed out.
    pub fn next_batch<'a>(
        &'a mut self,
        source: &mut dyn EventSource,
    ) -> Result<Option<Batch<'a>>, SourceError> {
        self.compact();
        while !self.exhausted && !self.batch_ready() {
            match source.next_chunk(&mut self.pending_events, &mut self.pending_labels)? {
                Chunk::Events { watermark_us } => self.watermark_us = watermark_us,
                Chunk::End => self.exhausted = true,
            }
        }
        let available = self.pending_events.len() - self.consumed;
        if available == 0 && self.exhausted {
            return Ok(None);
        }
        let first_t = self.pending_events[self.consumed].t;
        let (count, t_begin_us, t_end_us) = match self.size {
            BatchSize::Count { events } => {
                let count = events.min(available);
                let last_t = self.pending_events[self.consumed + count - 1].t;
                (count, first_t, last_t.saturating_add(1))
            }
            BatchSize::Arrival => {
                let last_t = self.pending_events[self.pending_events.len() - 1].t;
                (available, first_t, last_t.saturating_add(1))
            }
            BatchSize::Duration { micros } => {
                let grid_begin = *self.next_begin_us.get_or_insert(first_t);
                // Skip empty spans so the batch starts at the span holding the next event.
                let skipped = (first_t - grid_begin).div_euclid(micros);
                let t_begin = grid_begin + skipped * micros;
                // Saturating: a span reaching past i64::MAX still takes its events, so the loop
                // always makes progress.
                let t_end = t_begin.saturating_add(micros);
                self.next_begin_us = Some(t_end);
                let count = self.pending_events[self.consumed..]
                    .partition_point(|e| e.t < t_end || t_end == i64::MAX);
                (count, t_begin, t_end)
            }
        };
        let range = self.consumed..self.consumed + count;
        self.consumed += count;
        let labels = if self.pending_labels.len() == self.pending_events.len() {
            &self.pending_labels[range.clone()]
        } else {
            &[]
        };
        Ok(Some(Batch {
            events: &self.pending_events[range],
            labels,
            t_begin_us,
            t_end_us,
            last: self.exhausted && self.consumed == self.pending_events.len(),
        }))
    }

    fn batch_ready(&self) -> bool {
        let available = self.pending_events.len() - self.consumed;
        if available == 0 {
            return false;
        }
        match self.size {
            BatchSize::Count { events } => available >= events,
            BatchSize::Arrival => true,
            BatchSize::Duration { micros } => {
                let first_t = self.pending_events[self.consumed].t;
                let grid_begin = self.next_begin_us.unwrap_or(first_t);
                let skipped = (first_t - grid_begin).div_euclid(micros);
                let t_end = (grid_begin + skipped * micros).saturating_add(micros);
                self.watermark_us >= t_end
            }
        }
    }

    fn compact(&mut self) {
        if self.consumed > 0 {
            self.pending_events.drain(..self.consumed);
            if !self.pending_labels.is_empty() {
                self.pending_labels.drain(..self.consumed);
            }
            self.consumed = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use evgate_core::SensorSize;

    struct Scripted {
        chunks: Vec<Vec<i64>>,
    }

    impl EventSource for Scripted {
        fn sensor(&self) -> SensorSize {
            SensorSize::new(4, 4)
        }
        fn has_labels(&self) -> bool {
            true
        }
        fn next_chunk(
            &mut self,
            events: &mut Vec<Event>,
            labels: &mut Vec<u16>,
        ) -> Result<Chunk, SourceError> {
            if self.chunks.is_empty() {
                return Ok(Chunk::End);
            }
            let times = self.chunks.remove(0);
            for &t in &times {
                events.push(Event::new(t, 0, 0, true));
                labels.push(t as u16);
            }
            Ok(Chunk::Events {
                watermark_us: *times.last().unwrap(),
            })
        }
        fn restart(&mut self, _pass: i64) -> Result<(), SourceError> {
            Ok(())
        }
    }

    fn collect(size: BatchSize, chunks: Vec<Vec<i64>>) -> Vec<(Vec<i64>, i64, i64, bool)> {
        let mut source = Scripted { chunks };
        let mut batcher = Batcher::new(size);
        let mut out = Vec::new();
        while let Some(batch) = batcher.next_batch(&mut source).unwrap() {
            assert_eq!(batch.events.len(), batch.labels.len());
            out.push((
                batch.events.iter().map(|e| e.t).collect(),
                batch.t_begin_us,
                batch.t_end_us,
                batch.last,
            ));
        }
        out
    }

    #[test]
    fn duration_batches_follow_a_time_grid_and_skip_empty_spans() {
        let batches = collect(
            BatchSize::Duration { micros: 10 },
            vec![vec![0, 3, 9], vec![10, 12], vec![35, 36, 50]],
        );
        assert_eq!(
            batches,
            vec![
                (vec![0, 3, 9], 0, 10, false),
                (vec![10, 12], 10, 20, false),
                (vec![35, 36], 30, 40, false),
                (vec![50], 50, 60, true),
            ]
        );
    }

    #[test]
    fn count_batches_hold_n_events_and_every_event_once() {
        let batches = collect(
            BatchSize::Count { events: 2 },
            vec![vec![1, 2, 3], vec![4, 5]],
        );
        let times: Vec<i64> = batches.iter().flat_map(|b| b.0.clone()).collect();
        assert_eq!(times, vec![1, 2, 3, 4, 5]);
        assert_eq!(batches.len(), 3);
        assert!(batches[2].3);
        assert_eq!((batches[0].1, batches[0].2), (1, 3));
    }

    #[test]
    fn arrival_batches_are_the_chunks_as_they_come() {
        let batches = collect(
            BatchSize::Arrival,
            vec![vec![5, 7], vec![7, 20, 21], vec![40]],
        );
        let spans: Vec<(Vec<i64>, i64, i64)> = batches
            .iter()
            .map(|(times, begin, end, _)| (times.clone(), *begin, *end))
            .collect();
        assert_eq!(
            spans,
            vec![
                (vec![5, 7], 5, 8),
                (vec![7, 20, 21], 7, 22),
                (vec![40], 40, 41)
            ]
        );
    }

    /// Issue 15: spans ending past i64::MAX wrapped, so no event fitted and `evgate-ingest`
    /// looped forever on empty batches.
    #[test]
    fn spans_at_the_end_of_the_time_range_still_take_their_events() {
        let near_max = i64::MAX - 5;
        let batches = collect(
            BatchSize::Duration { micros: 1_000 },
            vec![vec![near_max - 2_000, near_max, i64::MAX]],
        );
        let times: Vec<i64> = batches.iter().flat_map(|b| b.0.clone()).collect();
        assert_eq!(times, vec![near_max - 2_000, near_max, i64::MAX]);
        let batches = collect(BatchSize::Count { events: 1 }, vec![vec![i64::MAX]]);
        assert_eq!(batches[0].2, i64::MAX);
    }
}
