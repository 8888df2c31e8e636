//! The shared-memory contracts of the evgate pipeline.
//!
//! Every process of a pipeline (ingest → infer → gate, plus any consumer) agrees on three things
//! defined here and nowhere else:
//!
//! * the service names, built from a [`PipelineNames`] (`<domain>/<camera>/<stream>`), so several
//!   pipelines can share one machine and tests can use unique names;
//! * the payload types ([`BatchHeader`], [`ForecastHeader`], [`PipelineStats`]), `#[repr(C)]`,
//!   `Pod` and registered with versioned iceoryx2 type names;
//! * the service limits and port settings ([`Qos`]), so whichever process creates a service
//!   creates it the way the others open it.
//!
//! A process that reads a running pipeline (a robot's planner, a tracker, a logger) needs only
//! [`consumer`]: typed subscribers for the kept and suppressed events, the keep bitmaps and the
//! stats; `examples/rust/kept_consumer.rs` is one to copy.
//!
//! Publishers pair each sample with an iceoryx2 event notification of the same service name so
//! readers sleep in a `WaitSet` instead of polling.

pub mod batch;
pub mod clock;
#[cfg(feature = "service")]
pub mod config_file;
pub mod consumer;
pub mod forecast;
pub mod iceoryx_config;
#[cfg(feature = "service")]
pub mod logging;
#[cfg(feature = "service")]
pub mod metrics;
pub mod names;
pub mod node;
pub mod ports;
pub mod qos;
pub mod slice_writer;
pub mod stale_service;
pub mod stats;
pub mod stop_request;
pub mod wait;

pub use batch::{BatchError, BatchFlags, BatchHeader};
#[cfg(feature = "service")]
pub use config_file::{parse_with_config_file, try_parse_with_config_file, ConfigFileError};
pub use forecast::{ForecastError, ForecastHeader, MAX_HORIZONS};
pub use iceoryx_config::{evgate_config, SharedMemoryRootError};
#[cfg(feature = "service")]
pub use logging::init_service_logging;
pub use names::{NameError, PipelineNames, Stream};
pub use node::{create_node, NodeError};
pub use ports::{
    Delivery, LatestPublisher, LatestSubscriber, OpenError, PublishError, ReceiveError,
    SlicePublisher, SliceSubscriber, WrittenDelivery,
};
pub use qos::{Overflow, Qos};
pub use slice_writer::SliceWriter;
pub use stats::PipelineStats;
pub use stop_request::{run_until_stopped, stop_requested, StopChecks};
pub use wait::{pin_current_thread, Backoff, PinError, WaitStrategy, MISSED_WAKEUP_POLL};

/// The iceoryx2 service flavour every evgate process uses: inter-process shared memory.
pub type Service = iceoryx2::service::ipc::Service;

/// The iceoryx2 node of an evgate process (see [`create_node`]).
pub type Node = iceoryx2::prelude::Node<Service>;
