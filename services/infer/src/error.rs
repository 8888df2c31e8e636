//! Why the inference service stopped with an error.

use std::path::PathBuf;

use evgate_ipc::metrics::MetricsError;
use evgate_ipc::{NameError, NodeError, OpenError, PinError, PublishError, ReceiveError};
use evgate_model::ModelError;

use crate::horizons::HorizonError;
use crate::windowing::WindowingError;
use crate::worker::WorkerError;

#[derive(Debug, thiserror::Error)]
pub enum InferError {
    #[error(transparent)]
    Pin(#[from] PinError),
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error("stopped by SIGINT or SIGTERM before starting")]
    StoppedBeforeStart,
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Horizons(#[from] HorizonError),
    #[error("{flag} {value}: must be a finite number")]
    ThresholdLogit { flag: &'static str, value: f32 },
    #[error(transparent)]
    Windowing(#[from] WindowingError),
    #[error(transparent)]
    Name(#[from] NameError),
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error(transparent)]
    Publish(#[from] PublishError),
    #[error(transparent)]
    Receive(#[from] ReceiveError),
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    #[error("cannot start the inference thread: {0}")]
    Thread(std::io::Error),
    #[error("the inference thread stopped unexpectedly")]
    WorkerStopped,
    #[error("inference failed: {0}")]
    Inference(#[from] WorkerError),
    #[error("cannot write the stats to {path}: {source}")]
    StatsJson {
        path: PathBuf,
        source: std::io::Error,
    },
}
