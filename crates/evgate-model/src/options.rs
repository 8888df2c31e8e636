//! How a session is set up: execution provider, CPU threads and where the state lives.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Which execution provider runs the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Provider {
    /// ONNX Runtime's CPU kernels.
    #[default]
    Cpu,
    /// The CUDA execution provider; falls back to CPU with a warning when it cannot be used.
    Cuda,
    /// CUDA when the loaded library has it and it registers, else CPU (logged at info level).
    Auto,
}

/// Accepted spellings of [`Provider`], for messages.
pub const PROVIDER_NAMES: &str = "cpu, cuda, auto";

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown execution provider {value:?}; accepted values: {PROVIDER_NAMES}")]
pub struct ProviderParseError {
    pub value: String,
}

impl FromStr for Provider {
    type Err = ProviderParseError;

    fn from_str(value: &str) -> Result<Self, Self::Err> {
        match value.trim().to_ascii_lowercase().as_str() {
            "cpu" => Ok(Self::Cpu),
            "cuda" => Ok(Self::Cuda),
            "auto" => Ok(Self::Auto),
            _ => Err(ProviderParseError {
                value: value.to_owned(),
            }),
        }
    }
}

impl fmt::Display for Provider {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Cpu => "cpu",
            Self::Cuda => "cuda",
            Self::Auto => "auto",
        })
    }
}

/// Where the recurrent state lives between windows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StateBinding {
    /// Bound to the session's device when the session runs on CUDA, passed through host
    /// memory on the CPU (where binding gains nothing).
    #[default]
    Auto,
    /// Bound on any provider; on the CPU the state stays in host memory either way, so this
    /// serves to compare the two paths.
    Always,
    /// Passed as run inputs and returned as run outputs every window: on CUDA each window copies
    /// every state tensor to the device and back.
    Never,
}

/// Accepted spellings of [`StateBinding`], for messages.
pub const STATE_BINDING_NAMES: &str = "auto, always, never";

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown state binding {value:?}; accepted values: {STATE_BINDING_NAMES}")]
pub struct StateBindingParseError {
    pub value: String,
}

impl FromStr for StateBinding {
    type Err = StateBindingParseError;

    fn from_str(value: &str) -> Result<Self, Self::Err> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(Self::Auto),
            "always" => Ok(Self::Always),
            "never" => Ok(Self::Never),
            _ => Err(StateBindingParseError {
                value: value.to_owned(),
            }),
        }
    }
}

impl fmt::Display for StateBinding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Auto => "auto",
            Self::Always => "always",
            Self::Never => "never",
        })
    }
}

impl StateBinding {
    /// Whether a session on `provider` binds its state.
    pub fn binds_on(self, provider: ActiveProvider) -> bool {
        match self {
            Self::Auto => provider == ActiveProvider::Cuda,
            Self::Always => true,
            Self::Never => false,
        }
    }
}

/// The provider a session actually runs on after any fall-back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ActiveProvider {
    Cpu,
    Cuda,
}

impl fmt::Display for ActiveProvider {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Cpu => "cpu",
            Self::Cuda => "cuda",
        })
    }
}

/// Session settings.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default)]
pub struct RuntimeOptions {
    pub provider: Provider,
    /// Threads inside one operator (convolutions); 0 lets ONNX Runtime pick (one per core).
    pub intra_threads: usize,
    /// Keep idle worker threads spinning between runs: lower latency, but they burn the cores
    /// that ingest and gate share with inference, so it is off unless asked for.
    pub spin_threads: bool,
    /// CUDA device ordinal when the CUDA provider is used.
    pub cuda_device: i32,
    /// Library to load instead of the discovered one (see `library`).
    pub library: Option<PathBuf>,
    /// Where the recurrent state lives between windows.
    pub state_binding: StateBinding,
}

impl Default for RuntimeOptions {
    fn default() -> Self {
        Self {
            provider: Provider::Cpu,
            intra_threads: 2,
            spin_threads: false,
            cuda_device: 0,
            library: None,
            state_binding: StateBinding::Auto,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn provider_round_trips_through_its_name() {
        for provider in [Provider::Cpu, Provider::Cuda, Provider::Auto] {
            assert_eq!(provider.to_string().parse::<Provider>().unwrap(), provider);
        }
    }

    #[test]
    fn unknown_provider_lists_accepted_values() {
        let message = "tensorrt".parse::<Provider>().unwrap_err().to_string();
        assert!(message.contains("tensorrt") && message.contains(PROVIDER_NAMES));
    }

    #[test]
    fn state_binding_round_trips_and_lists_accepted_values() {
        for binding in [
            StateBinding::Auto,
            StateBinding::Always,
            StateBinding::Never,
        ] {
            assert_eq!(
                binding.to_string().parse::<StateBinding>().unwrap(),
                binding
            );
        }
        let message = "device".parse::<StateBinding>().unwrap_err().to_string();
        assert!(message.contains("device") && message.contains(STATE_BINDING_NAMES));
    }

    #[test]
    fn auto_binds_the_state_on_cuda_only() {
        assert!(StateBinding::Auto.binds_on(ActiveProvider::Cuda));
        assert!(!StateBinding::Auto.binds_on(ActiveProvider::Cpu));
        assert!(StateBinding::Always.binds_on(ActiveProvider::Cpu));
        assert!(!StateBinding::Never.binds_on(ActiveProvider::Cuda));
    }

    #[test]
    fn options_deserialise_from_kebab_case_with_defaults() {
        let options: RuntimeOptions =
            serde_json::from_str(r#"{"provider":"auto","intra-threads":4}"#).unwrap();
        assert_eq!(options.provider, Provider::Auto);
        assert_eq!(options.intra_threads, 4);
        assert!(!options.spin_threads);
    }
}
