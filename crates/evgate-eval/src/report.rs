//! The result of a run: every summary, serialisable as JSON (the source of the Markdown tables
//! and plots).

use std::collections::BTreeMap;
use std::path::PathBuf;

use evgate_core::SensorSize;
use serde::{Deserialize, Serialize};

use crate::binned::BinValue;
use crate::bootstrap::MethodIntervals;
use crate::config::EvalConfig;
use crate::method::MethodInfo;
use crate::oms::OmsParameters;
use crate::recording::GroundTruth;
use crate::summary::{HorizonSummary, Mean, MethodSummary};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct SequenceResult {
    pub name: String,
    pub path: PathBuf,
    pub preset: String,
    pub sensor: SensorSize,
    pub references: usize,
    /// What the recording could be scored against; metrics needing more are `null`.
    #[serde(default = "GroundTruth::simulator")]
    pub ground_truth: GroundTruth,
    /// Models that could not see this recording (its padded sensor exceeds their input); their
    /// scores, and those of the baselines built on the first model's mask, leave it out.
    #[serde(default)]
    pub models_not_run: Vec<ModelNotRun>,
    pub methods: BTreeMap<String, MethodSummary>,
}

/// A model left out of one recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct ModelNotRun {
    pub method: String,
    pub model_input: SensorSize,
    pub padded_sensor: SensorSize,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct PresetResult {
    pub preset: String,
    pub sequences: usize,
    pub methods: BTreeMap<String, MethodSummary>,
    /// 95 % bootstrap intervals over this preset's sequences (`crate::bootstrap`).
    #[serde(default)]
    pub intervals: BTreeMap<String, MethodIntervals>,
}

/// Headline scores of one OMS setting.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct SweepScores {
    pub parameters: OmsParameters,
    /// At the headline horizon.
    pub mean_iou: Option<f64>,
    pub instance_recall: Option<f64>,
    pub success_rate: Option<f64>,
    /// At the reference time.
    pub point_iou: Option<f64>,
}

impl SweepScores {
    pub fn new(parameters: OmsParameters, headline: &HorizonSummary, point_iou: &Mean) -> Self {
        Self {
            parameters,
            mean_iou: headline.mean_iou,
            instance_recall: headline.instance_recall,
            success_rate: headline.success_rate,
            point_iou: point_iou.value(),
        }
    }

    /// Mean over sequences of each score.
    pub fn average(parameters: OmsParameters, per_sequence: &[&SweepScores]) -> Self {
        let mean = |f: fn(&SweepScores) -> Option<f64>| {
            let mut mean = Mean::default();
            per_sequence.iter().for_each(|s| mean.add(f(s)));
            mean.value()
        };
        Self {
            parameters,
            mean_iou: mean(|s| s.mean_iou),
            instance_recall: mean(|s| s.instance_recall),
            success_rate: mean(|s| s.success_rate),
            point_iou: mean(|s| s.point_iou),
        }
    }
}

/// The published OMS setting and the best one of the sweep (by mIoU at the headline horizon,
/// chosen on the evaluated sequences themselves, so it is an optimistic bound for OMS).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct OmsSweepResult {
    pub published: Option<SweepScores>,
    pub best: Option<SweepScores>,
    pub settings: Vec<SweepScores>,
}

impl OmsSweepResult {
    pub fn from_settings(published: OmsParameters, settings: Vec<SweepScores>) -> Self {
        let best = settings
            .iter()
            .filter(|s| s.mean_iou.is_some())
            .max_by(|a, b| a.mean_iou.partial_cmp(&b.mean_iou).expect("finite means"))
            .cloned();
        Self {
            published: settings.iter().find(|s| s.parameters == published).cloned(),
            best,
            settings,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct Report {
    /// The suite split evaluated, when the sequences came from a suite.
    pub split: Option<String>,
    pub config: EvalConfig,
    pub methods: Vec<MethodInfo>,
    pub sequences: Vec<SequenceResult>,
    /// Averages over the sequences of each preset.
    pub presets: Vec<PresetResult>,
    /// Averages over all sequences.
    pub overall: BTreeMap<String, MethodSummary>,
    /// 95 % bootstrap intervals over all sequences of the headline metrics (`crate::bootstrap`).
    #[serde(default)]
    pub intervals: BTreeMap<String, MethodIntervals>,
    pub oms_sweep: OmsSweepResult,
    /// mIoU at the headline horizon pooled over frames, binned by events in the window.
    pub events_per_window: BTreeMap<String, Vec<BinValue>>,
    /// mIoU at the headline horizon pooled over frames, binned by object speed.
    pub object_speed: BTreeMap<String, Vec<BinValue>>,
    pub elapsed_s: f64,
}

impl Report {
    /// The method of `kind`'s name, if the run had it.
    pub fn method(&self, name: &str) -> Option<&MethodInfo> {
        self.methods.iter().find(|m| m.name == name)
    }

    /// The model methods, in the order given.
    pub fn models(&self) -> impl Iterator<Item = &MethodInfo> {
        self.methods.iter().filter(|m| m.model.is_some())
    }
}
