//! Service limits shared by every process and the per-port settings each process may choose.

use serde::{Deserialize, Serialize};

/// What a publisher does when a subscriber's buffer is full.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "service", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Overflow {
    /// Wait for the subscriber to make room, up to `block-timeout-ms`; after that the sample is
    /// discarded for that subscriber and counted (a dead or stuck reader must not stall the
    /// pipeline forever).
    Block,
    /// Discard the sample for that subscriber at once and count it.
    DropAndCount,
}

/// Port settings. The service-wide limits are fixed in this crate ([`ServiceLimits`]) because
/// iceoryx2 rejects opening a service with settings that differ from its creator's.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default)]
pub struct Qos {
    /// Samples a subscriber can hold before the publisher overflows it (1..=`ServiceLimits::SUBSCRIBER_MAX_BUFFER`).
    pub buffer_size: usize,
    /// Slice length a publisher preallocates; larger batches grow the shared memory by powers of two.
    pub initial_max_slice_len: usize,
    pub overflow: Overflow,
    /// Longest wait of the `block` policy for one subscriber, milliseconds.
    pub block_timeout_ms: u64,
}

impl Default for Qos {
    fn default() -> Self {
        Self {
            buffer_size: ServiceLimits::SUBSCRIBER_MAX_BUFFER,
            initial_max_slice_len: 4096,
            overflow: Overflow::Block,
            block_timeout_ms: 500,
        }
    }
}

impl Qos {
    /// Default settings with another overflow policy.
    pub fn with_overflow(overflow: Overflow) -> Self {
        Self {
            overflow,
            ..Self::default()
        }
    }
}

/// Service-wide limits every evgate process creates and opens services with.
pub struct ServiceLimits;

impl ServiceLimits {
    /// Largest buffer a subscriber may ask for.
    pub const SUBSCRIBER_MAX_BUFFER: usize = 16;
    /// Samples a subscriber may hold at once (one being processed plus one kept as "latest").
    pub const SUBSCRIBER_MAX_BORROWED: usize = 2;
    /// Publishers per service: one live writer plus room for ports of crashed processes that
    /// have not been cleaned up yet.
    pub const MAX_PUBLISHERS: usize = 4;
    pub const MAX_SUBSCRIBERS: usize = 8;
    pub const MAX_NODES: usize = 16;
    /// Samples replayed to a late subscriber of the forecast and stats streams (the latest one).
    pub const LATEST_HISTORY: usize = 1;
}
