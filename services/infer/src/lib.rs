//! `evgate-infer`, the inference service of the pipeline (see docs/runtime.md), as a library:
//! a typed [`Config`] (the command line and its `--config` file) and [`run`].

mod config;
mod error;
mod horizons;
mod latency;
mod loop_wait;
mod metrics;
mod service;
mod stats;
mod window_handover;
mod windowing;
mod worker;

pub use config::Config;
pub use error::InferError;
pub use service::run;
pub use stats::InferReport;
