//! The methods a run compares and how the report names and describes them.

use evgate_core::SensorSize;
use evgate_model::{MaskRule, ModelMetadata};
use serde::{Deserialize, Serialize};

use crate::config::EvalConfig;
use crate::oms::OmsParameters;

/// The paper counts operations for every method at one input size, 640×480.
pub const GFLOPS_REFERENCE_SENSOR: SensorSize = SensorSize::new(640, 480);
/// EVIMO's camera, the other size the model tables count at.
pub const DAVIS346_SENSOR: SensorSize = SensorSize::new(346, 260);

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
    /// The ground-truth mask of each instant, gated with the keep regions
    /// `oracle-keep-dilation-px` draws around it.
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
    /// Whether the weights were trained (`evgate.train-manifest-sha256` is not `untrained`).
    #[serde(default = "trained_by_default")]
    pub trained: bool,
    pub path: Option<std::path::PathBuf>,
    /// Counted in the ONNX file (the elements of its initializers).
    #[serde(default)]
    pub parameters: Option<u64>,
    /// The FLOP table the GFLOPs come from (only when its row has this parameter count).
    #[serde(default)]
    pub size_figures_from: Option<std::path::PathBuf>,
    /// The mask rule the run applied (reports written before these fields had 0, 0 and 0).
    #[serde(default)]
    pub threshold_logit: f32,
    #[serde(default)]
    pub keep_threshold_logit: f32,
    #[serde(default)]
    pub keep_dilation_px: u16,
}

/// Reports written before the field existed only held trained models.
fn trained_by_default() -> bool {
    true
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
    /// The same at 346×260 (EVIMO's DAVIS346), where known.
    #[serde(default)]
    pub gflops_346x260: Option<f64>,
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
            gflops_346x260: None,
            model: None,
        }
    }

    pub fn oms(parameters: OmsParameters) -> Self {
        let description = format!(
            "OMS, centre radius {}, surround radius {}, threshold {} (published EVIMO setting), \
             same mask for every horizon",
            parameters.centre_radius, parameters.surround_radius, parameters.threshold
        );
        let gflops_at = |sensor| parameters.flops_per_frame(sensor) as f64 / 1e9;
        Self {
            gflops: Some(gflops_at(GFLOPS_REFERENCE_SENSOR)),
            gflops_346x260: Some(gflops_at(DAVIS346_SENSOR)),
            ..Self::baseline("oms", description, MethodKind::Oms(parameters), 0.0)
        }
    }

    /// `current_source`: the model whose current mask is held and its mask rule, which the
    /// baseline's keep regions follow (`None`: the ground truth).
    pub fn no_forecast(current_source: Option<(&str, MaskRule)>) -> Self {
        let description = format!("{}, used for every horizon", source(current_source));
        Self::baseline("no-forecast", description, MethodKind::NoForecast, 0.0)
    }

    /// `current_source`: the model whose current mask is extrapolated and its mask rule.
    pub fn linear(config: &EvalConfig, current_source: Option<(&str, MaskRule)>) -> Self {
        let description = format!(
            "{}, components shifted by their centroid velocity over the last window",
            source(current_source)
        );
        let horizon = f64::from(config.headline_horizon_ms);
        Self::baseline("linear", description, MethodKind::Linear, horizon)
    }

    pub fn oracle(config: &EvalConfig) -> Self {
        let description = match config.oracle_keep_dilation_px {
            0 => "ground-truth masks of every instant, gated undilated".to_owned(),
            radius => format!("ground-truth masks of every instant, gated dilated by {radius} px"),
        };
        let horizon = f64::from(config.headline_horizon_ms);
        Self::baseline("oracle", description, MethodKind::Oracle, horizon)
    }

    pub fn model(
        index: usize,
        label: &str,
        path: &std::path::Path,
        metadata: &ModelMetadata,
        rule: MaskRule,
        config: &EvalConfig,
    ) -> Self {
        let atc = serde_json::to_value(metadata.atc)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default();
        Self {
            name: format!("model:{label}"),
            description: format!(
                "network {label} (size {}, ATC {atc}, {} training steps{}), future masks by flow \
                 warping, threshold logit {}{}",
                metadata.model_size.label(),
                metadata.train_steps,
                if metadata.train_manifest_sha256.is_none() {
                    ", untrained weights"
                } else {
                    ""
                },
                rule.threshold_logit,
                keep_rule(rule),
            ),
            kind: MethodKind::Model(index),
            forecast_horizon_ms: f64::from(config.headline_horizon_ms),
            gflops: None,
            gflops_346x260: None,
            model: Some(ModelInfo {
                size: metadata.model_size.label().to_owned(),
                atc,
                base_channels: metadata.base_channels,
                train_steps: metadata.train_steps,
                trained: metadata.train_manifest_sha256.is_some(),
                path: Some(path.to_path_buf()),
                parameters: None,
                size_figures_from: None,
                threshold_logit: rule.threshold_logit,
                keep_threshold_logit: rule.keep_threshold_logit,
                keep_dilation_px: rule.keep_dilation_px,
            }),
        }
    }
}

fn source(current_source: Option<(&str, MaskRule)>) -> String {
    current_source.map_or_else(
        || "the ground-truth mask at t".to_owned(),
        |(model, rule)| match (rule.keeps_at_the_mask_threshold(), rule.keep_dilation_px) {
            (true, 0) => format!("the current mask of {model}"),
            (true, px) => format!("the current mask of {model} (kept regions dilated by {px} px)"),
            (false, px) => format!(
                "the current mask of {model} (kept regions: the mask above logit {}, moved alike \
                 and dilated by {px} px)",
                rule.keep_threshold_logit
            ),
        },
    )
}

fn keep_rule(rule: MaskRule) -> String {
    if rule.keeps_the_forecast() {
        String::new()
    } else {
        format!(
            "; keeps events in the forecasts dilated by {} px above logit {}",
            rule.keep_dilation_px, rule.keep_threshold_logit
        )
    }
}
