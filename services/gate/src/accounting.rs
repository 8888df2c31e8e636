//! Counts every input event into exactly one fate and detects lost batches.

use evgate_ipc::{BatchHeader, PipelineStats};
use tracing::{info, warn};

use evgate_core::Verdict;

/// The stats of the current input stream.
pub struct Accounting {
    pub stats: PipelineStats,
    /// `first_event_index` the next batch should have.
    expected_index: Option<u64>,
}

/// What the accounting learned from a batch header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Admission {
    /// Next batch of the stream; `lost_events` were published before it and never received.
    Accept { lost_events: u64 },
    /// Already counted (a replayed or duplicated batch): ignore it.
    Duplicate,
}

impl Default for Accounting {
    fn default() -> Self {
        Self {
            stats: PipelineStats::new(0),
            expected_index: None,
        }
    }
}

impl Accounting {
    /// Admits a batch: switches to a new stream when the id changes and counts lost events.
    pub fn admit(&mut self, header: &BatchHeader) -> Admission {
        if self.expected_index.is_none() || header.stream_id != self.stats.stream_id {
            if self.expected_index.is_some() {
                info!(
                    old = self.stats.stream_id,
                    new = header.stream_id,
                    "input stream changed: counters restart"
                );
            }
            let sequence = self.stats.sequence;
            self.stats = PipelineStats::new(header.stream_id);
            self.stats.sequence = sequence;
            // A gate that was listening when the stream began sees batch 0 and counts from 0;
            // one started mid-stream counts from the first batch it receives.
            let joined = if header.sequence == 0 {
                0
            } else {
                header.first_event_index
            };
            self.stats.joined_at_event_index = joined;
            self.expected_index = Some(joined);
        }
        let expected = self.expected_index.unwrap_or(0);
        // The ingest repeats the end-of-stream marker until every reader has it.
        let repeated_end = header.is_end_of_stream() && self.stats.end_of_stream == 1;
        if (header.end_event_index() <= expected && header.event_count > 0) || repeated_end {
            warn!(sequence = header.sequence, "batch already counted: ignored");
            return Admission::Duplicate;
        }
        let lost_events = header.first_event_index.saturating_sub(expected);
        if lost_events > 0 {
            self.stats.dropped_events += lost_events;
            self.stats.gaps_detected += 1;
            warn!(
                sequence = header.sequence,
                lost_events, "events lost before this batch"
            );
        }
        self.expected_index = Some(header.end_event_index());
        self.stats.input_events = header
            .end_event_index()
            .saturating_sub(self.stats.joined_at_event_index);
        self.stats.input_batches += 1;
        if header.is_end_of_stream() {
            self.stats.end_of_stream = 1;
        }
        Admission::Accept { lost_events }
    }

    /// Adds the fates of an admitted batch.
    pub fn record(&mut self, verdict: &Verdict) {
        self.stats.kept_events += verdict.kept;
        self.stats.suppressed_events += verdict.suppressed;
        self.stats.unjudged_passed_events += verdict.unjudged_passed;
        self.stats.unjudged_dropped_events += verdict.unjudged_dropped;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(sequence: u64, first_event_index: u64, event_count: u64) -> BatchHeader {
        BatchHeader {
            stream_id: 5,
            sequence,
            first_event_index,
            event_count,
            t_end_us: 10,
            ..Default::default()
        }
    }

    #[test]
    fn holes_count_as_dropped_and_the_identity_holds() {
        let mut accounting = Accounting::default();
        assert_eq!(
            accounting.admit(&header(0, 0, 10)),
            Admission::Accept { lost_events: 0 }
        );
        accounting.record(&Verdict {
            kept: 4,
            suppressed: 6,
            ..Default::default()
        });
        assert_eq!(
            accounting.admit(&header(2, 25, 5)),
            Admission::Accept { lost_events: 15 }
        );
        accounting.record(&Verdict {
            unjudged_passed: 5,
            ..Default::default()
        });
        assert_eq!(accounting.stats.input_events, 30);
        assert!(accounting.stats.is_balanced());
        assert_eq!(accounting.admit(&header(1, 10, 15)), Admission::Duplicate);
    }

    #[test]
    fn a_repeated_end_of_stream_marker_is_counted_once() {
        let mut accounting = Accounting::default();
        accounting.admit(&header(0, 0, 10));
        let end = BatchHeader {
            flags: evgate_ipc::BatchFlags::END_OF_STREAM,
            ..header(1, 10, 0)
        };
        assert_eq!(accounting.admit(&end), Admission::Accept { lost_events: 0 });
        assert_eq!(accounting.admit(&end), Admission::Duplicate);
        assert_eq!(accounting.stats.input_batches, 2);
    }

    #[test]
    fn a_gate_started_mid_stream_counts_from_its_first_batch() {
        let mut accounting = Accounting::default();
        accounting.admit(&header(7, 700, 100));
        accounting.record(&Verdict {
            kept: 100,
            ..Default::default()
        });
        assert_eq!(accounting.stats.joined_at_event_index, 700);
        assert_eq!(accounting.stats.input_events, 100);
        assert!(accounting.stats.is_balanced());
    }
}
