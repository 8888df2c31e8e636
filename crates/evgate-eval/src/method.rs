//! The methods a run compares and how the report names and describes them.

use evgate_core::SensorSize;
use evgate_model::ModelMetadata;
use serde::{Deserialize, Serialize};

use crate::config::EvalConfig;
use crate::oms::OmsParameters;

/// The paper counts operations for every method at one input size, 640×480.
pub const GFLOPS_REFERENCE_SENSOR: SensorSize = SensorSize::new(640, 480);

/// What produces a method's masks.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodKind {
    /// OMS on the window's event-presence frame; the same mask for every horizon.
    Oms(OmsParameters),
    /// The current mask, used for every future instant.
    NoForecast,
    /// The current mask's components moved on at their last velocity.
    Linear,
    /// The network (index into the run's models).
    Model(usize),
    /// The ground-truth mask of each instant: the upper bound for gating.
    Oracle,
}

/// A model's identity in the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct ModelInfo {
    pub size: String,
    pub atc: String,
    pub base_channels: u32,
    pub train_steps: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct MethodInfo {
    /// Key of the method in every summary map.
    pub name: String,
    pub description: String,
    pub kind: MethodKind,
    /// How far ahead the output looks (prediction age = this − runtime).
    pub forecast_horizon_ms: f64,
    /// Analytical floating-point operations per frame at 640×480, where known.
    pub gflops: Option<f64>,
    pub model: Option<ModelInfo>,
}

impl MethodInfo {
    fn baseline(name: &str, description: String, kind: MethodKind, horizon_ms: f64) -> Self {
        Self {
            name: name.to_owned(),
            description,
            kind,
            forecast_horizon_ms: horizon_ms,
            gflops: None,
            model: None,
        }
    }

    pub fn oms(parameters: OmsParameters) -> Self {
        let description = format!(
            "OMS, centre radius {}, surround radius {}, threshold {} (published EVIMO setting), \
             same mask for every horizon",
            parameters.centre_radius, parameters.surround_radius, parameters.threshold
        );
        Self {
            gflops: Some(parameters.flops_per_frame(GFLOPS_REFERENCE_SENSOR) as f64 / 1e9),
            ..Self::baseline("oms", description, MethodKind::Oms(parameters), 0.0)
        }
    }

    /// `current_source` names the model whose current mask is held (`None`: the ground truth).
    pub fn no_forecast(current_source: Option<&str>) -> Self {
        let description = format!("{}, used for every horizon", source(current_source));
        Self::baseline("no-forecast", description, MethodKind::NoForecast, 0.0)
    }

    /// `current_source` names the model whose current mask is extrapolated.
    pub fn linear(config: &EvalConfig, current_source: Option<&str>) -> Self {
        let description = format!(
            "{}, components shifted by their centroid velocity over the last window",
            source(current_source)
        );
        let horizon = f64::from(config.headline_horizon_ms);
        Self::baseline("linear", description, MethodKind::Linear, horizon)
    }

    pub fn oracle(config: &EvalConfig) -> Self {
        let description = "ground-truth masks of every instant (upper bound for gating)".to_owned();
        let horizon = f64::from(config.headline_horizon_ms);
        Self::baseline("oracle", description, MethodKind::Oracle, horizon)
    }

    pub fn model(index: usize, label: &str, metadata: &ModelMetadata, config: &EvalConfig) -> Self {
        let atc = serde_json::to_value(metadata.atc)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        Self {
            name: format!("model:{label}"),
            description: format!(
                "network {label} (size {}, ATC {atc}), future masks by flow warping",
                metadata.model_size.label()
            ),
            kind: MethodKind::Model(index),
            forecast_horizon_ms: f64::from(config.headline_horizon_ms),
            gflops: None,
            model: Some(ModelInfo {
                size: metadata.model_size.label().to_owned(),
                atc,
                base_channels: metadata.base_channels,
                train_steps: metadata.train_steps,
            }),
        }
    }
}

fn source(current_source: Option<&str>) -> String {
    current_source.map_or_else(
        || "the ground-truth mask at t".to_owned(),
        |model| format!("the current mask of {model}"),
    )
}
