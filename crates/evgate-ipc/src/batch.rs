//! The user header of every per-event stream (events, labels, kept, suppressed, keep-bitmap).

use evgate_core::SensorSize;
use iceoryx2::prelude::ZeroCopySend;

/// Bits of [`BatchHeader::flags`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchFlags;

impl BatchFlags {
    /// The source has no more events: this is the last batch of the stream.
    pub const END_OF_STREAM: u32 = 1 << 0;
    /// Events were lost before this batch (a publisher discarded batches for a slow reader, or
    /// the source itself reported a gap). Readers also detect it from `first_event_index`.
    pub const GAP_DETECTED: u32 = 1 << 1;
    /// The source restarted from its beginning (looping replay): event times jump back.
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
    pub width: u16,
    pub height: u16,
    /// [`BatchFlags`] bits.
    pub flags: u32,
}

const _: () = assert!(core::mem::size_of::<BatchHeader>() == 64);

impl BatchHeader {
    pub const fn sensor(&self) -> SensorSize {
        SensorSize::new(self.width, self.height)
    }

    pub const fn is_end_of_stream(&self) -> bool {
        self.flags & BatchFlags::END_OF_STREAM != 0
    }

    pub const fn has_gap(&self) -> bool {
        self.flags & BatchFlags::GAP_DETECTED != 0
    }

    pub const fn is_restart(&self) -> bool {
        self.flags & BatchFlags::STREAM_RESTARTED != 0
    }

    /// Index one past the last event of this batch in the stream.
    pub const fn end_event_index(&self) -> u64 {
        self.first_event_index + self.event_count
    }
}

/// Number of `u64` words of a keep bitmap for `event_count` events (bit `i % 64` of word `i / 64`).
pub const fn bitmap_words(event_count: usize) -> usize {
    event_count.div_ceil(64)
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

    #[test]
    fn bitmap_words_round_up() {
        assert_eq!(bitmap_words(0), 0);
        assert_eq!(bitmap_words(64), 1);
        assert_eq!(bitmap_words(65), 2);
    }
}
