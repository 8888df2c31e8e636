//! Evaluation of motion-aware event suppression: metrics (IoU, mIoU, pIoU, SR@0.5, R@0.5,
//! per-event precision / recall / F1), the baselines (OMS, no forecast, linear extrapolation,
//! oracle), the harness that runs them and the models over recordings (the simulator's labelled
//! sequences, EVIMO with masks at its frame times, events-only recordings such as DSEC), and
//! the reports (JSON, Markdown tables including the ablation and model sizes, PNG plots).

pub mod binned;
pub mod bootstrap;
pub mod comparison;
pub mod components;
pub mod config;
pub mod event_scores;
#[cfg(test)]
mod fixture;
pub mod flops;
pub mod harness;
pub mod hungarian;
pub mod inputs;
pub mod instances;
pub mod kept;
pub mod linear;
pub mod markdown;
pub mod method;
mod method_output;
pub mod model_tables;
pub mod oms;
pub mod onnx_parameters;
pub mod output;
pub mod plot;
pub mod recording;
pub mod report;
pub mod segmentation;
pub mod summary;

pub use config::{EvalConfig, OmsSweep};
pub use flops::{FlopTable, FlopTableError};
pub use harness::{Evaluation, HarnessError, KeepRecord, LoadedModel, KEPT, NOT_GATED, SUPPRESSED};
pub use inputs::{read_recording, InputError, InputOptions};
pub use method::{MethodInfo, MethodKind};
pub use oms::OmsParameters;
pub use output::{write_report, OutputError, WrittenReport};
pub use recording::{GroundTruth, MaskFrames, Recording, RecordingError};
pub use report::Report;
