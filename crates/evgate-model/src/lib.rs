//! evgate-model: the ONNX Runtime side of evgate. Finds and loads the runtime library, loads an
//! exported network, checks it against docs/model-contract.md, and runs one 50 ms window at a
//! time with the ConvGRU state carried inside.

pub mod bound_state;
pub mod contract;
pub mod environment;
pub mod forecaster;
pub mod identity;
pub mod library;
pub mod metadata;
pub mod options;
pub mod output;
pub mod runtime;
pub mod state;
pub mod trusted_path;

pub use forecaster::{Forecast, ForecastError, Forecaster, MaskRule};
pub use library::{locate_onnxruntime, LibraryError};
pub use metadata::{AtcVariant, MetadataError, ModelMetadata, ModelSize};
pub use options::{ActiveProvider, Provider, RuntimeOptions, StateBinding};
pub use output::ForecastOutput;
pub use runtime::{ModelError, ModelRuntime};
