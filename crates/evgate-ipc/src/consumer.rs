//! Reading a running pipeline from another process: the events the gate keeps or suppresses,
//! its keep bitmaps and its stats, each through a typed subscriber that borrows the sample's
//! shared memory instead of copying it.
//!
//! ```no_run
//! use std::time::Duration;
//! use evgate_ipc::consumer::{EventBatches, EventStream};
//! use evgate_ipc::{create_node, PipelineNames};
//!
//! let node = create_node("my-consumer")?;
//! let names = PipelineNames::new("evgate", "cam0")?;
//! let kept = EventBatches::open(&node, &names, EventStream::Kept)?;
//! while let Some(batch) = kept.next(Duration::from_secs(1))? {
//!     println!("{} events up to t = {} µs", batch.events().len(), batch.header().t_end_us);
//!     if batch.header().is_end_of_stream() {
//!         break;
//!     }
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Open the subscribers before the pipeline starts publishing (a consumer that joins late
//! starts at the next batch), and run the consumer as the same user as the pipeline: the
//! services live under that user's evgate root (see [`crate::iceoryx_config`]).

use std::time::{Duration, Instant};

use evgate_core::Event;
use iceoryx2::port::listener::Listener;
use iceoryx2::sample::Sample;

use crate::names::{PipelineNames, Stream};
use crate::ports::{LatestSubscriber, OpenError, ReceiveError, SliceSubscriber};
use crate::qos::Qos;
use crate::stats::PipelineStats;
use crate::{BatchHeader, Node, Service};

/// The gate's event outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventStream {
    /// Events the gate passes (`<domain>/<camera>/kept`).
    Kept,
    /// Events the gate holds back (`<domain>/<camera>/suppressed`); published only when the
    /// gate runs with `--outputs` including `suppressed` (the default).
    Suppressed,
}

impl EventStream {
    fn stream(self) -> Stream {
        match self {
            Self::Kept => Stream::Kept,
            Self::Suppressed => Stream::Suppressed,
        }
    }
}

/// One batch of events, as the gate published it; holds the shared-memory sample until dropped.
pub struct EventBatch(Sample<Service, [Event], BatchHeader>);

impl EventBatch {
    /// The batch's header: stream id, sequence, time span, sensor size and flags.
    pub fn header(&self) -> &BatchHeader {
        self.0.user_header()
    }

    /// The events, in time order, read in place from shared memory.
    pub fn events(&self) -> &[Event] {
        self.0.payload()
    }
}

/// One batch's keep bitmap: bit i (word i / 64, bit i % 64) tells whether the gate passed the
/// input batch's event i.
pub struct KeepBitmap(Sample<Service, [u64], BatchHeader>);

impl KeepBitmap {
    /// The header of the input batch the bitmap describes.
    pub fn header(&self) -> &BatchHeader {
        self.0.user_header()
    }

    /// The packed bits, least significant first.
    pub fn words(&self) -> &[u64] {
        self.0.payload()
    }

    /// Whether event `index` of the input batch passed; false past the batch's end.
    pub fn passed(&self, index: usize) -> bool {
        self.words()
            .get(index / 64)
            .is_some_and(|word| word >> (index % 64) & 1 == 1)
    }
}

/// Waits on `listener` for up to `timeout` until `receive` yields.
fn wait_for<T>(
    listener: &Listener<Service>,
    timeout: Duration,
    mut receive: impl FnMut() -> Result<Option<T>, ReceiveError>,
) -> Result<Option<T>, ReceiveError> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(item) = receive()? {
            return Ok(Some(item));
        }
        let remaining = deadline.saturating_duration_since(Instant::now());
        if remaining.is_zero() {
            return Ok(None);
        }
        // A failed wait only costs a spurious wake-up: the loop polls again.
        let _ = listener.timed_wait(|_| {}, remaining);
    }
}

/// The kept or suppressed events of one pipeline.
pub struct EventBatches(SliceSubscriber<Event, BatchHeader>);

impl EventBatches {
    /// Subscribes to `stream` of the pipeline `names`, with room for [`Qos::default`]'s
    /// buffer of batches (a consumer that falls further behind loses batches unless the gate
    /// runs with `--overflow block`).
    pub fn open(
        node: &Node,
        names: &PipelineNames,
        stream: EventStream,
    ) -> Result<Self, OpenError> {
        SliceSubscriber::open(node, names, stream.stream(), &Qos::default()).map(Self)
    }

    /// The next batch if one is waiting.
    pub fn try_next(&self) -> Result<Option<EventBatch>, ReceiveError> {
        Ok(self.0.receive()?.map(EventBatch))
    }

    /// The next batch, waiting up to `timeout` for one (None when none came).
    pub fn next(&self, timeout: Duration) -> Result<Option<EventBatch>, ReceiveError> {
        wait_for(self.0.listener(), timeout, || self.try_next())
    }

    /// The wake-up listener, to wait on several subscribers at once in an iceoryx2 `WaitSet`.
    pub fn listener(&self) -> &Listener<Service> {
        self.0.listener()
    }
}

/// The keep bitmaps of one pipeline (published when the gate runs with `--outputs` including
/// `keep-bitmap`): one per input batch, for consumers that already hold the input events.
pub struct KeepBitmaps(SliceSubscriber<u64, BatchHeader>);

impl KeepBitmaps {
    /// Subscribes to `<domain>/<camera>/keep-bitmap` of the pipeline `names`.
    pub fn open(node: &Node, names: &PipelineNames) -> Result<Self, OpenError> {
        SliceSubscriber::open(node, names, Stream::KeepBitmap, &Qos::default()).map(Self)
    }

    /// The next bitmap if one is waiting.
    pub fn try_next(&self) -> Result<Option<KeepBitmap>, ReceiveError> {
        Ok(self.0.receive()?.map(KeepBitmap))
    }

    /// The next bitmap, waiting up to `timeout` for one (None when none came).
    pub fn next(&self, timeout: Duration) -> Result<Option<KeepBitmap>, ReceiveError> {
        wait_for(self.0.listener(), timeout, || self.try_next())
    }

    /// The wake-up listener, to wait on several subscribers at once in an iceoryx2 `WaitSet`.
    pub fn listener(&self) -> &Listener<Service> {
        self.0.listener()
    }
}

/// The gate's counters, published every `--stats-interval-ms`.
pub struct StatsReader(LatestSubscriber<PipelineStats>);

impl StatsReader {
    /// Subscribes to `<domain>/<camera>/stats` of the pipeline `names`; a new reader gets the
    /// latest publication at once.
    pub fn open(node: &Node, names: &PipelineNames) -> Result<Self, OpenError> {
        LatestSubscriber::open(node, names, Stream::Stats).map(Self)
    }

    /// The newest stats published since the last call (the first call: since the gate
    /// started), if any.
    pub fn latest(&self) -> Result<Option<PipelineStats>, ReceiveError> {
        self.0.latest()
    }
}
