//! Why the ingest stopped with an error.

use evgate_io::network::NetworkError;
use evgate_ipc::{NameError, NodeError, OpenError, PublishError};

use crate::source::SourceError;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("--{flag} = {value}: {problem}")]
    Setting {
        flag: &'static str,
        value: String,
        problem: &'static str,
    },
    #[error(transparent)]
    Name(#[from] NameError),
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error(transparent)]
    Publish(#[from] PublishError),
    #[error(transparent)]
    Source(#[from] SourceError),
    #[error(transparent)]
    Network(#[from] NetworkError),
    #[error("cannot start the thread that watches for SIGINT and SIGTERM: {0}")]
    StopWatcher(std::io::Error),
    #[error("progress bar template: {0}")]
    ProgressTemplate(#[from] indicatif::style::TemplateError),
}
