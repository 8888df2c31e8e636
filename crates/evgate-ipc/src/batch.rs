//! The user header of every per-event stream (events, labels, kept, suppressed, keep-bitmap).

use evgate_core::{is_event_time, SensorSize, MAX_EVENT_TIME_US};
use iceoryx2::prelude::ZeroCopySend;

/// A batch whose header does not describe its payload; readers skip it (its events then show
/// as lost at the next good batch).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum BatchError {
    #[error("batch {sequence}: header field event-count = {announced} but the payload holds {actual} items")]
    EventCount {
        sequence: u64,
        announced: u64,
        actual: usize,
    },
    #[error("batch {sequence}: header fields first-event-index = {first} + event-count = {count} overflow u64")]
    IndexOverflow {
        sequence: u64,
        first: u64,
        count: u64,
    },
    #[error("batch {sequence}: header span t-begin-us = {begin} .. t-end-us = {end} is reversed or outside ±{MAX_EVENT_TIME_US}")]
    Span { sequence: u64, begin: i64, end: i64 },
}

/// Bits of [`BatchHeader::flags`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchFlags;

impl BatchFlags {
    /// The source has no more events: this is the last batch of the stream.
    pub const END_OF_STREAM: u32 = 1 << 0;
    /// Events were lost before this batch (a publisher discarded batches for a slow reader, or
    /// the source itself reported a gap). Readers also detect it from `first_event_index`.
    pub const GAP_DETECTED: u32 = 1 << 1;
    /// The source restarted from its beginning (looping replay): the scene jumps, while event
    /// times go on increasing (each pass is shifted by the source's span).
    pub const STREAM_RESTARTED: u32 = 1 << 2;
}

/// Describes one batch of events and everything derived from it.
///
/// The gate republishes the header of an input batch unchanged (except for `flags` it adds) on
/// its kept, suppressed and keep-bitmap streams, so a reader can join them with the input and
/// label streams by `(stream_id, sequence)`.
#[repr(C)]
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable, ZeroCopySend,
)]
#[type_name("evgate::BatchHeader/v1")]
pub struct BatchHeader {
    /// Random id chosen by the ingest at start; changes when the ingest restarts.
    pub stream_id: u64,
    /// Batch number within the stream, from 0, without holes on the publisher side.
    pub sequence: u64,
    /// Number of events published on the stream before this batch; a reader that sees it jump
    /// knows exactly how many events it never received.
    pub first_event_index: u64,
    /// Events in the input batch (the slice length of the events and labels streams).
    pub event_count: u64,
    /// Start of the time span the batch covers, microseconds (inclusive).
    pub t_begin_us: i64,
    /// End of the time span the batch covers, microseconds (exclusive).
    pub t_end_us: i64,
    /// CLOCK_MONOTONIC of the moment the input batch was published, nanoseconds
    /// (see [`crate::clock::monotonic_ns`]); end-to-end latency is measured from it.
    pub published_at_monotonic_ns: u64,
    /// Sensor width in pixels: every event's x is below it.
    pub width: u16,
    /// Sensor height in pixels: every event's y is below it.
    pub height: u16,
    /// [`BatchFlags`] bits.
    pub flags: u32,
}

const _: () = assert!(core::mem::size_of::<BatchHeader>() == 64);

impl BatchHeader {
    /// The sensor size, `width` × `height`.
    pub const fn sensor(&self) -> SensorSize {
        SensorSize::new(self.width, self.height)
    }

    /// The last batch of its stream: nothing follows (it may hold no events).
    pub const fn is_end_of_stream(&self) -> bool {
        self.flags & BatchFlags::END_OF_STREAM != 0
    }

    /// Events were lost before this batch.
    pub const fn has_gap(&self) -> bool {
        self.flags & BatchFlags::GAP_DETECTED != 0
    }

    /// The source started over (looping replay): the scene jumps, event time goes on.
    pub const fn is_restart(&self) -> bool {
        self.flags & BatchFlags::STREAM_RESTARTED != 0
    }

    /// Index one past the last event of this batch in the stream (saturating; a validated
    /// header never saturates).
    pub const fn end_event_index(&self) -> u64 {
        self.first_event_index.saturating_add(self.event_count)
    }

    /// Checks that the header describes a payload of `payload_len` events (or labels: one per
    /// event; a keep bitmap is shorter). Validate a copy, never the header in shared memory:
    /// its publisher can still write it.
    pub fn validate(&self, payload_len: usize) -> Result<(), BatchError> {
        let sequence = self.sequence;
        if self.event_count != payload_len as u64 {
            return Err(BatchError::EventCount {
                sequence,
                announced: self.event_count,
                actual: payload_len,
            });
        }
        if self
            .first_event_index
            .checked_add(self.event_count)
            .is_none()
        {
            return Err(BatchError::IndexOverflow {
                sequence,
                first: self.first_event_index,
                count: self.event_count,
            });
        }
        if !(is_event_time(self.t_begin_us) && is_event_time(self.t_end_us))
            || self.t_begin_us > self.t_end_us
        {
            return Err(BatchError::Span {
                sequence,
                begin: self.t_begin_us,
                end: self.t_end_us,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_plain_bytes() {
        let header = BatchHeader {
            stream_id: 7,
            sequence: 3,
            first_event_index: 100,
            event_count: 20,
            flags: BatchFlags::END_OF_STREAM,
            ..Default::default()
        };
        let bytes = bytemuck::bytes_of(&header);
        let back: BatchHeader = bytemuck::pod_read_unaligned(bytes);
        assert_eq!(back, header);
        assert_eq!(back.end_event_index(), 120);
        assert!(back.is_end_of_stream());
        assert!(!back.has_gap());
    }

    /// Issue 15: the count, the index sum and the span were trusted unchecked.
    #[test]
    fn headers_that_lie_about_their_payload_are_refused() {
        let good = BatchHeader {
            sequence: 4,
            first_event_index: 10,
            event_count: 3,
            t_begin_us: 0,
            t_end_us: 1_000,
            ..Default::default()
        };
        good.validate(3).unwrap();
        assert!(matches!(
            good.validate(2),
            Err(BatchError::EventCount {
                announced: 3,
                actual: 2,
                ..
            })
        ));
        let overflowing = BatchHeader {
            first_event_index: u64::MAX - 1,
            ..good
        };
        assert!(matches!(
            overflowing.validate(3),
            Err(BatchError::IndexOverflow { .. })
        ));
        assert_eq!(overflowing.end_event_index(), u64::MAX);
        for (begin, end) in [(5, 4), (i64::MIN, 0), (0, i64::MAX)] {
            let span = BatchHeader {
                t_begin_us: begin,
                t_end_us: end,
                ..good
            };
            assert!(matches!(span.validate(3), Err(BatchError::Span { .. })));
        }
    }
}
