//! Why the gate stopped with an error.

use evgate_ipc::metrics::MetricsError;
use evgate_ipc::{NameError, NodeError, OpenError, PinError, PublishError, ReceiveError};
use iceoryx2::waitset::{WaitSetAttachmentError, WaitSetCreateError, WaitSetRunError};

use crate::serve_kept::ServeError;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("--stats-interval-ms = 0 must be at least 1")]
    StatsInterval,
    #[error(transparent)]
    Name(#[from] NameError),
    #[error(transparent)]
    Pin(#[from] PinError),
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error(transparent)]
    Publish(#[from] PublishError),
    #[error(transparent)]
    Receive(#[from] ReceiveError),
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    #[error(transparent)]
    Serve(#[from] ServeError),
    #[error("cannot create the iceoryx2 waitset: {0}")]
    WaitSetCreate(WaitSetCreateError),
    #[error("cannot attach the {what} to the waitset: {source}")]
    WaitSetAttach {
        what: &'static str,
        source: WaitSetAttachmentError,
    },
    #[error("waiting on the iceoryx2 waitset failed: {0}")]
    WaitSetRun(WaitSetRunError),
    #[error(
        "gating selected {written} events (and {overflowed} more that did not fit) for \
         {service} where the verdict counted {counted}"
    )]
    SelectionMismatch {
        written: usize,
        overflowed: usize,
        service: String,
        counted: usize,
    },
}
