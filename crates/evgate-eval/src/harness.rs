//! The evaluation harness: runs every method over every reference time of each sequence, in
//! time order (the model's recurrent state carries across windows), scores the forecasts and
//! collects the per-sequence, per-preset and overall summaries.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use evgate_core::bitset::{bit, words_for};
use evgate_core::{
    events_in, BitMask, ForecastView, GateError, GateMode, MaskError, SensorSize, TimeSpan,
    VoxelError, WindowError, PADDING_MULTIPLE,
};
use evgate_model::{ForecastError, Forecaster, ModelError};
use thiserror::Error;

use crate::binned::{BinnedMeans, LogBins, EVENT_BINS_FIRST_DECADE, EVENT_BINS_LAST_DECADE};
use crate::bootstrap::intervals_over;
use crate::config::{ConfigError, EvalConfig};
use crate::event_scores::EventConfusion;
use crate::instances::match_instances;
use crate::kept::KeptCounts;
use crate::method::{MethodInfo, MethodKind};
use crate::method_output::{to_mask, BaselineSource, MethodOutput, ReferenceInputs};
use crate::oms::{event_presence, normalised_response, threshold_response, OmsParameters};
use crate::onnx_parameters::{onnx_parameters, OnnxParametersError};
use crate::recording::{GroundTruth, Recording};
use crate::report::{
    ModelNotRun, OmsSweepResult, PresetResult, Report, SequenceResult, SweepScores,
};
use crate::segmentation::{PixelConfusion, SegmentationError};
use crate::summary::{HorizonAccumulator, Mean, MethodAccumulator, MethodSummary};

#[derive(Debug, Error)]
pub enum HarnessError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("{path}: {source}")]
    Model {
        path: PathBuf,
        source: Box<ModelError>,
    },
    #[error("model {path}: {source}")]
    Forecast {
        path: PathBuf,
        source: Box<ForecastError>,
    },
    #[error("{sequence}: voxel grid: {source}")]
    Voxel {
        sequence: String,
        source: VoxelError,
    },
    #[error("{sequence}: window ending at {reference_us} µs: {source}")]
    Window {
        sequence: String,
        reference_us: i64,
        source: WindowError,
    },
    #[error("{sequence}: at {reference_us} µs: {source}")]
    Scoring {
        sequence: String,
        reference_us: i64,
        source: SegmentationError,
    },
    #[error("{sequence}: mask at {reference_us} µs: {source}")]
    Mask {
        sequence: String,
        reference_us: i64,
        source: MaskError,
    },
    #[error("{sequence}: gating at {reference_us} µs: {source}")]
    Gate {
        sequence: String,
        reference_us: i64,
        source: GateError,
    },
    #[error("no sequence was evaluated")]
    NothingEvaluated,
    #[error(transparent)]
    Parameters(#[from] OnnxParametersError),
}

/// A loaded network and the name it is reported under.
pub struct LoadedModel {
    pub label: String,
    /// The network with the model's own mask rule, unbinned: what `evgate-infer` runs.
    pub forecaster: Forecaster,
}

/// Everything the scorer needs about one reference time.
struct ReferenceTruth<'a> {
    /// `None` for a recording without masks.
    now: Option<&'a [u8]>,
    at_horizon: Vec<Option<&'a [u8]>>,
    presence: Vec<bool>,
    events_in_window: usize,
    speed_px_per_s: Option<f64>,
}

/// Pooled per-frame scores of one method at the headline horizon.
struct BinnedAccumulators {
    events_per_window: BinnedMeans,
    speed: BinnedMeans,
}

/// Runs the methods over sequences and collects their scores.
pub struct Evaluation {
    config: EvalConfig,
    models: Vec<LoadedModel>,
    methods: Vec<MethodInfo>,
    sweep_settings: Vec<OmsParameters>,
    sequences: Vec<SequenceResult>,
    sweep_per_sequence: Vec<Vec<SweepScores>>,
    binned: Vec<BinnedAccumulators>,
    event_bins: LogBins,
    started: Instant,
    /// The first model's verdict on each event of the last sequence, when asked for.
    keep_record: Option<KeepRecord>,
}

/// The first model's verdict on each event of one recording, in file order: [`KEPT`],
/// [`SUPPRESSED`], or [`NOT_GATED`] for an event outside every gated span [t, t + gate-span)
/// or off the sensor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KeepRecord {
    pub verdicts: Vec<u8>,
}

pub const SUPPRESSED: u8 = 0;
pub const KEPT: u8 = 1;
pub const NOT_GATED: u8 = 2;

impl Evaluation {
    /// `models[0]`, when present, is the model under test: its current mask also feeds the
    /// no-forecast and linear baselines (as in the paper's ablation). Without a model those
    /// baselines start from the ground-truth mask at the reference time.
    pub fn new(config: EvalConfig, models: Vec<LoadedModel>) -> Result<Self, HarnessError> {
        config.validate()?;
        let source = models
            .first()
            .map(|m| (m.label.as_str(), m.forecaster.rule()));
        let mut methods = vec![
            MethodInfo::oms(config.oms),
            MethodInfo::no_forecast(source),
            MethodInfo::linear(&config, source),
        ];
        for (index, model) in models.iter().enumerate() {
            let runtime = model.forecaster.runtime();
            let mut method = MethodInfo::model(
                index,
                &model.label,
                runtime.model_path(),
                runtime.metadata(),
                model.forecaster.rule(),
                &config,
            );
            if let Some(info) = method.model.as_mut() {
                info.parameters = Some(onnx_parameters(runtime.model_path())?);
            }
            methods.push(method);
        }
        methods.push(MethodInfo::oracle(&config));
        let event_bins = LogBins {
            first_decade: EVENT_BINS_FIRST_DECADE,
            last_decade: EVENT_BINS_LAST_DECADE,
            per_decade: config.event_bins_per_decade.max(1),
        };
        let binned = methods
            .iter()
            .map(|_| BinnedAccumulators {
                events_per_window: BinnedMeans::new(event_bins.count()),
                speed: BinnedMeans::new(config.speed_bucket_edges_px_per_s.len() + 1),
            })
            .collect();
        Ok(Self {
            sweep_settings: config.oms_sweep.settings(),
            config,
            models,
            methods,
            sequences: Vec::new(),
            sweep_per_sequence: Vec::new(),
            binned,
            event_bins,
            started: Instant::now(),
            keep_record: None,
        })
    }

    /// Records the first model's verdict on every event of each sequence from now on; read it
    /// after each [`Evaluation::evaluate`] with [`Evaluation::keep_record`].
    pub fn record_verdicts(&mut self) {
        self.keep_record.get_or_insert_with(KeepRecord::default);
    }

    /// The first model's verdicts on the events of the last evaluated sequence.
    pub fn keep_record(&self) -> Option<&KeepRecord> {
        self.keep_record.as_ref()
    }

    pub fn config(&self) -> &EvalConfig {
        &self.config
    }

    pub fn methods(&self) -> &[MethodInfo] {
        &self.methods
    }

    /// Reference times that [`Self::evaluate`] will score for this recording.
    pub fn reference_count(&self, recording: &Recording) -> usize {
        recording.reference_times(&self.config).len()
    }

    /// Scores one recording; `on_reference` is called after each reference time (progress).
    /// Metrics that need ground truth the recording lacks are left undefined (`None`).
    pub fn evaluate(
        &mut self,
        recording: &Recording,
        mut on_reference: impl FnMut(),
    ) -> Result<&SequenceResult, HarnessError> {
        let name = recording.name.as_str();
        let size = recording.sensor_size;
        let padded = size
            .padded_to(PADDING_MULTIPLE)
            .ok_or(HarnessError::Voxel {
                sequence: name.to_owned(),
                source: VoxelError::SensorTooLarge { sensor: size },
            })?;
        let (runs_here, models_not_run) = self.prepare_models(padded)?;

        let config = self.config.clone();
        let horizons_us = config.horizons_us();
        let horizons_ms_f32: Vec<f32> = config.horizons_ms.iter().map(|&h| h as f32).collect();
        let window_us = i64::from(config.window_ms) * 1000;
        let gate_span_us = i64::from(config.gate_span_ms) * 1000;
        let headline = config.headline_index();
        let ground_truth = recording.ground_truth();
        let mut accumulators: Vec<MethodAccumulator> = self
            .methods
            .iter()
            .map(|_| MethodAccumulator::new(horizons_us.len()))
            .collect();
        let mut sweep: Vec<(HorizonAccumulator, Mean)> =
            vec![Default::default(); self.sweep_settings.len()];
        let mut previous_current: Option<(i64, BaselineSource)> = None;
        if let Some(record) = &mut self.keep_record {
            record.verdicts.clear();
            record.verdicts.resize(recording.events.len(), NOT_GATED);
        }
        let first_model_method = self
            .methods
            .iter()
            .position(|method| method.kind == MethodKind::Model(0));
        let references = recording.reference_times(&config);
        let gating_horizons: Vec<usize> = (0..horizons_us.len())
            .filter(|&k| horizons_us[k] <= gate_span_us)
            .collect();

        for &reference_us in &references {
            let scoring_error = |source| HarnessError::Scoring {
                sequence: name.to_owned(),
                reference_us,
                source,
            };
            let span = TimeSpan::new(reference_us - window_us, reference_us).map_err(|source| {
                HarnessError::Window {
                    sequence: name.to_owned(),
                    reference_us,
                    source,
                }
            })?;
            // The window [t − 50 ms, t] includes its end, as the voxel grid does.
            let window = events_in(
                &recording.events,
                TimeSpan {
                    start: span.start,
                    end: span.end + 1,
                },
            );

            // The recurrent state must see every window, even one we cannot score.
            let ModelRuns {
                outputs: model_outputs,
                first_current_keep,
            } = self.run_models(&runs_here, size, window, span, &horizons_ms_f32)?;

            let now = recording.truth_at(reference_us);
            // A recording with masks is scored only where a mask lies at t.
            if ground_truth.has_masks() && now.is_none() {
                on_reference();
                continue;
            }
            let truth = ReferenceTruth {
                now,
                at_horizon: horizons_us
                    .iter()
                    .map(|&h| recording.truth_at(reference_us + h))
                    .collect(),
                presence: event_presence(window, size),
                events_in_window: window.len(),
                speed_px_per_s: recording.object_speed_px_per_s(reference_us),
            };

            let current_source = match (model_outputs.first(), now) {
                (Some(Some(output)), _) => Some(BaselineSource {
                    current: output.current.clone(),
                    current_keep: first_current_keep,
                    runtime: output.runtime,
                }),
                (Some(None), _) => None,
                (None, Some(now)) => Some(BaselineSource {
                    current: to_mask(now),
                    current_keep: None,
                    runtime: Duration::ZERO,
                }),
                (None, None) => None,
            };
            let inputs = ReferenceInputs {
                config: &config,
                size,
                reference_us,
                horizons_us: &horizons_us,
                window,
                current: current_source.as_ref(),
                baseline_dilation_px: if model_outputs.is_empty() {
                    self.config.oracle_keep_dilation_px
                } else {
                    self.models[0].forecaster.rule().keep_dilation_px
                },
                previous: previous_current.as_ref(),
                models: &model_outputs,
                truth_now: now,
                truth_at_horizon: &truth.at_horizon,
            };
            let outputs: Vec<Option<MethodOutput>> = self
                .methods
                .iter()
                .map(|method| method.kind.output(&inputs))
                .collect();
            previous_current = current_source.map(|source| (reference_us, source));

            let gated = gated_events(recording, reference_us, gate_span_us);
            let truth_at_every_gating_horizon = gating_horizons
                .iter()
                .all(|&k| truth.at_horizon[k].is_some());
            // With per-event labels every method is gated over the same spans (those the oracle
            // can gate), so their event scores compare; camera-rate masks rarely cover every
            // gating horizon, so there only the oracle waits for them.
            let can_gate = |kind: MethodKind| match kind {
                MethodKind::Oracle => truth_at_every_gating_horizon,
                _ => {
                    ground_truth != GroundTruth::MasksAndEventLabels
                        || truth_at_every_gating_horizon
                }
            };
            let kinds: Vec<MethodKind> = self.methods.iter().map(|method| method.kind).collect();
            for (index, (output, &kind)) in outputs.iter().zip(&kinds).enumerate() {
                let Some(output) = output else {
                    continue;
                };
                let accumulator = &mut accumulators[index];
                accumulator
                    .runtime_ms
                    .add(output.runtime.as_secs_f64() * 1e3);
                if can_gate(kind) {
                    let gate = score_events(
                        &gated,
                        reference_us,
                        &gating_horizons,
                        &horizons_us,
                        output.keep_regions(),
                        size,
                    )
                    .map_err(|error| error.at(name, reference_us))?;
                    if let (Some(record), true) =
                        (&mut self.keep_record, Some(index) == first_model_method)
                    {
                        gate.record(&mut record.verdicts[gated.first_index..]);
                    }
                    accumulator.kept.merge(KeptCounts {
                        span_us: gate_span_us,
                        ..gate.kept
                    });
                    accumulator.events.merge(gate.confusion);
                }
                self.score_masks(index, output, &truth, size, accumulator)
                    .map_err(scoring_error)?;
            }
            if truth.now.is_some() {
                self.sweep_oms(&truth, size, headline, &mut sweep)
                    .map_err(scoring_error)?;
            }
            on_reference();
        }

        let methods = self
            .methods
            .iter()
            .zip(&accumulators)
            .map(|(method, accumulator)| {
                (
                    method.name.clone(),
                    accumulator.summary(&config.horizons_ms, method.forecast_horizon_ms),
                )
            })
            .collect();
        self.sweep_per_sequence.push(
            sweep
                .iter()
                .zip(&self.sweep_settings)
                .map(|((horizon, point), &parameters)| {
                    SweepScores::new(
                        parameters,
                        &horizon.summary(config.headline_horizon_ms),
                        point,
                    )
                })
                .collect(),
        );
        self.sequences.push(SequenceResult {
            name: name.to_owned(),
            path: recording.path.clone(),
            preset: recording.group.clone(),
            sensor: size,
            references: references.len(),
            ground_truth,
            models_not_run,
            methods,
        });
        Ok(self.sequences.last().expect("just pushed"))
    }
    /// Scores one method's current and future masks against the truth of one reference time,
    /// where the recording has masks.
    fn score_masks(
        &mut self,
        method_index: usize,
        output: &MethodOutput,
        truth: &ReferenceTruth<'_>,
        size: SensorSize,
        accumulator: &mut MethodAccumulator,
    ) -> Result<(), SegmentationError> {
        let Some(now) = truth.now else {
            return Ok(());
        };
        let iou_threshold = self.config.iou_threshold;
        let point = PixelConfusion::count_where(&output.current, now, &truth.presence)?;
        accumulator.point_iou.add(point.imo_iou());
        for (k, future) in output.futures.iter().enumerate() {
            let Some(target) = truth.at_horizon[k] else {
                continue;
            };
            let pixels = PixelConfusion::count(future, target)?;
            let instances = match_instances(future, target, size, iou_threshold)?;
            accumulator.horizons[k].add(&pixels, instances, iou_threshold);
            if k == self.config.headline_index() {
                let binned = &mut self.binned[method_index];
                if let Some(bin) = self.event_bins.bin(truth.events_in_window as f64) {
                    binned.events_per_window.add(bin, pixels.mean_iou());
                }
                if let Some(speed) = truth.speed_px_per_s {
                    binned
                        .speed
                        .add(self.config.speed_bucket(speed), pixels.mean_iou());
                }
            }
        }
        Ok(())
    }

    /// Resets the state of every model that can see a sensor padded to `padded`; the others
    /// sit the recording out (and so do the baselines built on the first model's mask).
    fn prepare_models(
        &mut self,
        padded: SensorSize,
    ) -> Result<(Vec<bool>, Vec<ModelNotRun>), HarnessError> {
        let mut models_not_run = Vec::new();
        let mut runs_here = Vec::with_capacity(self.models.len());
        for model in &mut self.models {
            let input = model.forecaster.runtime().input_size();
            let fits = input.width >= padded.width && input.height >= padded.height;
            runs_here.push(fits);
            if !fits {
                models_not_run.push(ModelNotRun {
                    method: format!("model:{}", model.label),
                    model_input: input,
                    padded_sensor: padded,
                });
                continue;
            }
            let path = model.forecaster.runtime().model_path().to_path_buf();
            model
                .forecaster
                .reset_state()
                .map_err(|source| HarnessError::Model {
                    path,
                    source: Box::new(source),
                })?;
        }
        Ok((runs_here, models_not_run))
    }

    /// Each model's masks for one window.
    fn run_models(
        &mut self,
        runs_here: &[bool],
        size: SensorSize,
        window: &[evgate_core::Event],
        span: TimeSpan,
        horizons_ms: &[f32],
    ) -> Result<ModelRuns, HarnessError> {
        let mut model_outputs = Vec::with_capacity(self.models.len());
        let mut first_current_keep = None;
        for (model, &runs) in self.models.iter_mut().zip(runs_here) {
            if !runs {
                model_outputs.push(None);
                continue;
            }
            let path = model.forecaster.runtime().model_path().to_path_buf();
            let rule = model.forecaster.rule();
            let forecast = model
                .forecaster
                .forecast(size, window, span, horizons_ms)
                .map_err(|source| HarnessError::Forecast {
                    path,
                    source: Box::new(source),
                })?;
            let to_bools = |masks: &[evgate_core::BitMask]| -> Vec<Vec<bool>> {
                masks.iter().map(|mask| mask.view().to_bools()).collect()
            };
            if model_outputs.is_empty() && !rule.keeps_at_the_mask_threshold() {
                first_current_keep = Some(forecast.current_keep.view().to_bools());
            }
            model_outputs.push(Some(MethodOutput {
                current: forecast.current.view().to_bools(),
                futures: to_bools(forecast.futures),
                keep: (!rule.keeps_the_forecast()).then(|| to_bools(forecast.keep)),
                runtime: forecast.inference,
            }));
        }
        Ok(ModelRuns {
            outputs: model_outputs,
            first_current_keep,
        })
    }

    /// Scores every OMS setting of the sweep at the headline horizon and the current instant.
    fn sweep_oms(
        &self,
        truth: &ReferenceTruth<'_>,
        size: SensorSize,
        headline: usize,
        sweep: &mut [(HorizonAccumulator, Mean)],
    ) -> Result<(), SegmentationError> {
        let threshold = self.config.iou_threshold;
        let Some(now) = truth.now else {
            return Ok(());
        };
        let mut responses: BTreeMap<(u32, u32), Vec<f32>> = BTreeMap::new();
        for (setting, (horizon, point)) in self.sweep_settings.iter().zip(sweep.iter_mut()) {
            let response = responses
                .entry((setting.centre_radius, setting.surround_radius))
                .or_insert_with(|| {
                    normalised_response(
                        &truth.presence,
                        size,
                        setting.centre_radius,
                        setting.surround_radius,
                    )
                });
            let mask = threshold_response(response, setting.threshold);
            let current = PixelConfusion::count_where(&mask, now, &truth.presence)?;
            point.add(current.imo_iou());
            if let Some(target) = truth.at_horizon[headline] {
                let pixels = PixelConfusion::count(&mask, target)?;
                let instances = match_instances(&mask, target, size, threshold)?;
                horizon.add(&pixels, instances, threshold);
            }
        }
        Ok(())
    }

    /// Averages per preset and overall, picks the best OMS setting and assembles the report.
    pub fn finish(self, split: Option<String>) -> Result<Report, HarnessError> {
        if self.sequences.is_empty() {
            return Err(HarnessError::NothingEvaluated);
        }
        let average_over = |sequences: &[&SequenceResult]| -> BTreeMap<String, MethodSummary> {
            self.methods
                .iter()
                .filter_map(|method| {
                    let summaries: Vec<&MethodSummary> = sequences
                        .iter()
                        .filter_map(|s| s.methods.get(&method.name))
                        .collect();
                    Some((method.name.clone(), MethodSummary::average(&summaries)?))
                })
                .collect()
        };
        let headline_ms = self.config.headline_horizon_ms;
        let method_names = || self.methods.iter().map(|m| m.name.clone());
        let mut preset_names: Vec<&str> =
            self.sequences.iter().map(|s| s.preset.as_str()).collect();
        preset_names.sort_unstable();
        preset_names.dedup();
        let presets = preset_names
            .iter()
            .map(|&preset| {
                let members: Vec<&SequenceResult> = self
                    .sequences
                    .iter()
                    .filter(|s| s.preset == preset)
                    .collect();
                PresetResult {
                    preset: preset.to_owned(),
                    sequences: members.len(),
                    methods: average_over(&members),
                    intervals: intervals_over(&members, method_names(), headline_ms),
                }
            })
            .collect();
        let all: Vec<&SequenceResult> = self.sequences.iter().collect();
        let overall = average_over(&all);
        let intervals = intervals_over(&all, method_names(), headline_ms);

        let sweep_settings: Vec<SweepScores> = self
            .sweep_settings
            .iter()
            .enumerate()
            .map(|(k, &parameters)| {
                let per_sequence: Vec<&SweepScores> =
                    self.sweep_per_sequence.iter().map(|s| &s[k]).collect();
                SweepScores::average(parameters, &per_sequence)
            })
            .collect();
        let oms_sweep = OmsSweepResult::from_settings(self.config.oms, sweep_settings);

        let bins = &self.event_bins;
        let labels = self.config.speed_bucket_labels();
        let edges = &self.config.speed_bucket_edges_px_per_s;
        let mut events_per_window = BTreeMap::new();
        let mut object_speed = BTreeMap::new();
        for (method, binned) in self.methods.iter().zip(&self.binned) {
            events_per_window.insert(
                method.name.clone(),
                binned
                    .events_per_window
                    .bins
                    .iter()
                    .enumerate()
                    .map(|(k, mean)| {
                        let (lower, upper) = bins.bounds(k);
                        crate::binned::BinValue {
                            label: format!("{lower:.0}-{upper:.0}"),
                            lower: Some(lower),
                            upper: Some(upper),
                            frames: mean.count(),
                            mean_iou: mean.value(),
                        }
                    })
                    .collect(),
            );
            object_speed.insert(
                method.name.clone(),
                binned
                    .speed
                    .bins
                    .iter()
                    .enumerate()
                    .map(|(k, mean)| crate::binned::BinValue {
                        label: labels[k].clone(),
                        lower: k.checked_sub(1).map(|i| edges[i]),
                        upper: edges.get(k).copied(),
                        frames: mean.count(),
                        mean_iou: mean.value(),
                    })
                    .collect(),
            );
        }

        Ok(Report {
            split,
            config: self.config,
            methods: self.methods,
            sequences: self.sequences,
            presets,
            overall,
            intervals,
            oms_sweep,
            events_per_window,
            object_speed,
            elapsed_s: self.started.elapsed().as_secs_f64(),
        })
    }
}

/// The events of [t, t + span), where they start in the recording, and their labels when the
/// recording has them.
struct GatedSpan<'a> {
    first_index: usize,
    events: &'a [evgate_core::Event],
    labels: Option<&'a [u16]>,
}

/// The models' masks for one window.
struct ModelRuns {
    /// One per model, `None` for a model that sits the recording out.
    outputs: Vec<Option<MethodOutput>>,
    /// The first model's current mask at its keep threshold, where that differs from its mask
    /// threshold: what the baselines' keep regions start from.
    first_current_keep: Option<Vec<bool>>,
}

fn gated_events(recording: &Recording, reference_us: i64, span_us: i64) -> GatedSpan<'_> {
    let events = &recording.events;
    let first = events.partition_point(|e| e.t < reference_us);
    let last = events.partition_point(|e| e.t < reference_us + span_us);
    GatedSpan {
        first_index: first,
        events: &events[first..last],
        labels: recording
            .event_labels
            .as_deref()
            .map(|labels| &labels[first..last]),
    }
}

/// A gating failure before the sequence and time are known.
enum GatingError {
    Mask(MaskError),
    Gate(GateError),
}

impl GatingError {
    fn at(self, sequence: &str, reference_us: i64) -> HarnessError {
        match self {
            GatingError::Mask(source) => HarnessError::Mask {
                sequence: sequence.to_owned(),
                reference_us,
                source,
            },
            GatingError::Gate(source) => HarnessError::Gate {
                sequence: sequence.to_owned(),
                reference_us,
                source,
            },
        }
    }
}

/// What gating one span gave: kept counts always, the confusion against labels when known,
/// and the keep and judged bits of its events.
struct GateScores {
    kept: KeptCounts,
    confusion: EventConfusion,
    keep: Vec<u64>,
    judged: Vec<u64>,
}

impl GateScores {
    /// Writes the span's verdicts into `verdicts` (from the span's first event on).
    fn record(&self, verdicts: &mut [u8]) {
        for (index, verdict) in verdicts.iter_mut().enumerate().take(self.judged.len() * 64) {
            if bit(&self.judged, index) {
                *verdict = if bit(&self.keep, index) {
                    KEPT
                } else {
                    SUPPRESSED
                };
            }
        }
    }
}

/// Gates the events with the forecast masks of the gating horizons (the gate kernel's
/// horizon intervals), counts what is kept and, with labels, flagged-as-IMO against the truth.
fn score_events(
    GatedSpan { events, labels, .. }: &GatedSpan<'_>,
    reference_us: i64,
    gating_horizons: &[usize],
    horizons_us: &[i64],
    futures: &[Vec<bool>],
    size: SensorSize,
) -> Result<GateScores, GatingError> {
    if events.is_empty() {
        return Ok(GateScores {
            kept: KeptCounts::default(),
            confusion: EventConfusion::default(),
            keep: Vec::new(),
            judged: Vec::new(),
        });
    }
    let mut words = Vec::new();
    for &k in gating_horizons {
        let mut mask = BitMask::new(size).map_err(GatingError::Mask)?;
        for (pixel, _) in futures[k].iter().enumerate().filter(|(_, &on)| on) {
            let (x, y) = (
                pixel % usize::from(size.width),
                pixel / usize::from(size.width),
            );
            mask.set(x as u16, y as u16, true)
                .map_err(GatingError::Mask)?;
        }
        words.extend_from_slice(mask.as_words());
    }
    let horizons: Vec<i64> = gating_horizons.iter().map(|&k| horizons_us[k]).collect();
    let view =
        ForecastView::new(reference_us, &horizons, size, &words).map_err(GatingError::Gate)?;
    let word_count = words_for(events.len());
    let (mut keep, mut judged) = (vec![0u64; word_count], vec![0u64; word_count]);
    view.keep_bitmap(events, GateMode::KeepMovingObjects, &mut keep, &mut judged)
        .map_err(GatingError::Gate)?;
    let mut scores = GateScores {
        kept: KeptCounts::default(),
        confusion: EventConfusion::default(),
        keep,
        judged,
    };
    let (keep, judged) = (&scores.keep, &scores.judged);
    for i in (0..events.len()).filter(|&i| bit(judged, i)) {
        let kept = bit(keep, i);
        scores.kept.judged += 1;
        scores.kept.kept += u64::from(kept);
        if let Some(labels) = labels {
            scores.confusion.add(kept, labels[i] != 0);
        }
    }
    Ok(scores)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::fixture;
    use crate::recording::MaskFrames;

    fn run(config: EvalConfig) -> Report {
        let recording =
            Recording::from_labelled(fixture::sequence(), Path::new("suite/test/slide-0001.npz"))
                .unwrap();
        let mut evaluation = Evaluation::new(config, Vec::new()).unwrap();
        let expected = evaluation.reference_count(&recording);
        let mut seen = 0;
        evaluation.evaluate(&recording, || seen += 1).unwrap();
        assert_eq!(seen, expected);
        evaluation.finish(Some("test".to_owned())).unwrap()
    }

    fn small_config() -> EvalConfig {
        EvalConfig {
            oms_sweep: crate::config::OmsSweep {
                centre_radii: vec![1, 2],
                surround_radii: vec![4],
                thresholds: vec![0.9, 0.96],
            },
            ..EvalConfig::default()
        }
    }

    #[test]
    fn events_are_judged_by_the_mask_of_their_horizon_interval() {
        let size = SensorSize::new(4, 2);
        let mut at_0 = vec![false; 8];
        at_0[size.index(0, 0)] = true;
        let mut at_10 = vec![false; 8];
        at_10[size.index(1, 0)] = true;
        let t = 1_000_000;
        let events = [
            evgate_core::Event::new(t + 1_000, 0, 0, true), // mask 0 flags it, an IMO event
            evgate_core::Event::new(t + 1_000, 1, 0, true), // mask 0 leaves it, background
            evgate_core::Event::new(t + 2_000, 2, 1, false), // missed IMO event
            evgate_core::Event::new(t + 9_000, 0, 0, true), // mask 10 ms leaves it, background
            evgate_core::Event::new(t + 9_000, 1, 0, true), // mask 10 ms flags it, an IMO event
            evgate_core::Event::new(t + 9_500, 9, 9, true), // off the sensor: unjudged
        ];
        let labels = [3, 0, 3, 0, 3, 3];
        let scores = score_events(
            &GatedSpan {
                first_index: 0,
                events: &events[..],
                labels: Some(&labels[..]),
            },
            t,
            &[0, 1],
            &[0, 10_000],
            &[at_0, at_10],
            size,
        )
        .ok()
        .unwrap();
        assert_eq!(
            scores.kept,
            KeptCounts {
                judged: 5,
                kept: 2,
                span_us: 0
            }
        );
        assert_eq!(
            scores.confusion,
            EventConfusion {
                true_positive: 2,
                false_positive: 0,
                false_negative: 1,
                true_negative: 2
            }
        );
        let mut verdicts = [NOT_GATED; 6];
        scores.record(&mut verdicts);
        assert_eq!(
            verdicts,
            [KEPT, SUPPRESSED, SUPPRESSED, SUPPRESSED, KEPT, NOT_GATED]
        );
    }

    #[test]
    fn intervals_come_from_the_per_sequence_scores() {
        // The same recording twice under two names: two sequences with equal scores, so every
        // interval is the point of that score; one sequence alone gives no interval.
        let mut evaluation = Evaluation::new(small_config(), Vec::new()).unwrap();
        for name in ["suite/test/slide-0001.npz", "suite/test/slide-0002.npz"] {
            let recording = Recording::from_labelled(fixture::sequence(), Path::new(name)).unwrap();
            evaluation.evaluate(&recording, || {}).unwrap();
        }
        let report = evaluation.finish(Some("test".to_owned())).unwrap();
        let headline = report.config.headline_horizon_ms;
        let linear = &report.intervals["linear"];
        let miou = linear[&crate::bootstrap::Metric::MeanIou];
        let expected = report.overall["linear"]
            .at(headline)
            .unwrap()
            .mean_iou
            .unwrap();
        assert!((miou.low - expected).abs() < 1e-12 && (miou.high - expected).abs() < 1e-12);
        assert!(
            linear.contains_key(&crate::bootstrap::Metric::PointIou)
                || report.overall["linear"].point_iou.is_none()
        );
        assert!(run(small_config()).intervals["linear"].is_empty());
        let markdown = crate::markdown::render(&report, &[]);
        assert!(markdown.contains(&format!(
            "[{:.1}, {:.1}]",
            miou.low * 100.0,
            miou.high * 100.0
        )));
    }

    #[test]
    fn oracle_is_perfect_where_truth_exists() {
        let report = run(small_config());
        let oracle = &report.overall["oracle"];
        for horizon in &oracle.horizons {
            assert_eq!(horizon.mean_iou, Some(1.0), "at {} ms", horizon.horizon_ms);
            assert_eq!(horizon.instance_recall, Some(1.0));
            assert_eq!(horizon.success_rate, Some(1.0));
        }
        assert_eq!(oracle.point_iou, Some(1.0));
        // Edge events lie inside the object's mask at the 10 ms grid instant nearest to them,
        // except the leading edge as the object moves between grid instants.
        assert!(oracle.events.precision.unwrap() > 0.9);
        assert!(oracle.events.recall.unwrap() > 0.5);
    }

    #[test]
    fn the_truth_gated_wider_keeps_more_of_the_object() {
        let undilated = run(small_config());
        let dilated = run(EvalConfig {
            oracle_keep_dilation_px: 2,
            ..small_config()
        });
        // The leading edge fires ahead of the mask of the nearest 10 ms instant, and ahead of
        // the held or extrapolated mask at t; 2 px reach part of it and take in only a few of the
        // scattered background events.
        for method in ["oracle", "no-forecast", "linear"] {
            let events = |report: &Report| report.overall[method].events;
            assert!(
                events(&dilated).recall.unwrap() > events(&undilated).recall.unwrap(),
                "{method}"
            );
            assert!(events(&dilated).precision.unwrap() > 0.9, "{method}");
            assert_eq!(
                dilated.overall[method].horizons, undilated.overall[method].horizons,
                "{method}: the scored masks changed"
            );
        }
        let description = |report: &Report| {
            let oracle = report.methods.iter().find(|m| m.name == "oracle").unwrap();
            oracle.description.clone()
        };
        assert!(
            description(&dilated).contains("dilated by 2 px"),
            "{}",
            description(&dilated)
        );
        assert!(description(&undilated).contains("undilated"));
    }

    #[test]
    fn linear_extrapolation_of_a_constant_velocity_beats_no_forecast() {
        let report = run(small_config());
        let at = |method: &str| report.overall[method].at(100).unwrap().clone();
        let (still, moving) = (at("no-forecast"), at("linear"));
        // The object moves 20 px in 100 ms, more than its 6 px width: the held mask misses it.
        assert!(still.imo_iou.unwrap() == 0.0);
        assert_eq!(still.instance_recall, Some(0.0));
        // Constant velocity on an integer grid: linear extrapolation is exact after the first
        // reference time (which has no previous window and so keeps still).
        assert!(moving.imo_iou.unwrap() > 0.8, "{moving:?}");
        assert!(moving.instance_recall.unwrap() > 0.8);
        // At horizon 0 both equal the truth.
        assert_eq!(
            report.overall["no-forecast"].at(0).unwrap().mean_iou,
            Some(1.0)
        );
    }

    #[test]
    fn references_and_presets_come_from_the_sequence() {
        let report = run(small_config());
        assert_eq!(report.presets.len(), 1);
        assert_eq!(report.presets[0].preset, "slide");
        assert_eq!(report.sequences[0].name, "slide-0001");
        // ref_ts 50..400 ms; the first full window ends at 50 ms.
        assert_eq!(report.sequences[0].references, 8);
        // Horizons past the last truth frame (400 ms) are not scored.
        let frames_at_100 = report.overall["oracle"].at(100).unwrap().frames;
        assert_eq!(frames_at_100, 6);
        assert_eq!(report.oms_sweep.settings.len(), 4);
        assert!(report.oms_sweep.best.is_some());
    }

    #[test]
    fn models_left_out_of_a_recording_are_listed_in_the_report() {
        let mut report = run(small_config());
        assert!(report.sequences[0].models_not_run.is_empty());
        report.sequences[0].models_not_run.push(ModelNotRun {
            method: "model:S".to_owned(),
            model_input: SensorSize::new(352, 272),
            padded_sensor: SensorSize::new(640, 480),
        });
        let markdown = crate::markdown::render(&report, &[]);
        assert!(
            markdown.contains("`model:S` on slide-0001 (640x480 > 352x272)"),
            "{markdown}"
        );
    }

    #[test]
    fn max_seconds_limits_the_references() {
        let report = run(EvalConfig {
            max_seconds_per_sequence: Some(0.2),
            ..small_config()
        });
        assert_eq!(report.sequences[0].references, 4);
    }

    fn run_recording(recording: &Recording) -> Report {
        let mut evaluation = Evaluation::new(small_config(), Vec::new()).unwrap();
        evaluation.evaluate(recording, || {}).unwrap();
        evaluation.finish(None).unwrap()
    }

    #[test]
    fn events_only_recordings_report_kept_ratio_and_rates_without_truth_metrics() {
        let sequence = fixture::sequence();
        let recording = Recording::events_only(
            Path::new("dsec/zurich_city_00_a/events.h5"),
            "dsec".to_owned(),
            sequence.sensor_size,
            sequence.events,
            50_000,
        )
        .unwrap();
        let report = run_recording(&recording);
        assert_eq!(report.sequences[0].ground_truth, GroundTruth::EventsOnly);
        let oms = &report.overall["oms"];
        // The fixture emits 15 events every 500 µs: 30 000 events/s, all on the sensor.
        let rate = oms.kept.event_rate_hz.unwrap();
        assert!((rate - 30_000.0).abs() < 1.0, "{rate}");
        let kept = oms.kept.kept_ratio.unwrap();
        assert!(kept > 0.0 && kept < 1.0, "{kept}");
        assert!(oms.runtime_ms_median.is_some());
        assert!(oms
            .horizons
            .iter()
            .all(|h| h.mean_iou.is_none() && h.frames == 0));
        assert_eq!(oms.point_iou, None);
        assert_eq!(oms.events.f1, None);
        // Without a model or masks there is no current mask to hold, extrapolate or copy.
        for method in ["no-forecast", "linear", "oracle"] {
            assert_eq!(report.overall[method].runtime_ms_mean, None, "{method}");
            assert_eq!(report.overall[method].kept.kept_ratio, None, "{method}");
        }
        assert!(report.oms_sweep.best.is_none());
    }

    #[test]
    fn mask_recordings_score_masks_at_the_nearest_frame_but_not_events() {
        let sequence = fixture::sequence();
        let pixels = sequence.sensor_size.pixels();
        // Camera frames every 25 ms (40 Hz), as EVIMO's; the fixture's grid is 10 ms.
        let frame_indices: Vec<usize> = (0..sequence.gt_ts.len())
            .filter(|&f| sequence.gt_ts[f] % 50_000 == 0 || sequence.gt_ts[f] % 50_000 == 30_000)
            .collect();
        let frames = MaskFrames {
            times_us: frame_indices.iter().map(|&f| sequence.gt_ts[f]).collect(),
            masks: frame_indices
                .iter()
                .flat_map(|&f| sequence.masks[f * pixels..(f + 1) * pixels].to_vec())
                .collect(),
            tolerance_us: 5_000,
        };
        let recording = Recording::with_mask_frames(
            Path::new("evimo/box/seq_00.npz"),
            "box".to_owned(),
            sequence.sensor_size,
            sequence.events,
            frames,
        )
        .unwrap();
        let report = run_recording(&recording);
        assert_eq!(report.sequences[0].ground_truth, GroundTruth::Masks);
        let markdown = crate::markdown::render(&report, &[]);
        assert!(
            markdown.contains("the frame nearest to it within 5 ms"),
            "{markdown}"
        );
        assert_eq!(report.presets[0].preset, "box");
        let oracle = &report.overall["oracle"];
        // Frames (and reference times) at 0 and 30 ms past each 50 ms: t + 10 ms is 10 or 20 ms
        // from every frame, beyond the 5 ms tolerance; t + 30 ms always finds one.
        assert!(oracle.at(30).unwrap().frames > 0);
        assert_eq!(oracle.at(10).unwrap().frames, 0);
        assert_eq!(oracle.at(30).unwrap().mean_iou, Some(1.0));
        assert_eq!(oracle.events.f1, None);
        // Gating needs masks at 0, 10, … 50 ms: camera frames never cover all of them, so only
        // the methods that forecast every horizon are gated.
        assert_eq!(oracle.kept.kept_ratio, None);
        assert!(report.overall["oms"].kept.kept_ratio.is_some());
        assert!(report.overall["linear"].kept.kept_ratio.is_some());
        // No model: no-forecast holds the ground truth at t and is exact at horizon 0.
        assert_eq!(
            report.overall["no-forecast"].at(0).unwrap().mean_iou,
            Some(1.0)
        );
    }

    #[test]
    fn finishing_without_sequences_is_an_error() {
        let evaluation = Evaluation::new(small_config(), Vec::new()).unwrap();
        assert!(matches!(
            evaluation.finish(None),
            Err(HarnessError::NothingEvaluated)
        ));
    }

    #[test]
    fn report_files_are_written() {
        let report = run(small_config());
        let folder = tempfile::tempdir().unwrap();
        let written = crate::write_report(&report, folder.path()).unwrap();
        let markdown = std::fs::read_to_string(&written.markdown).unwrap();
        assert!(markdown.contains("(Table I)"));
        assert!(markdown.contains("| slide |"));
        let json: Report =
            serde_json::from_str(&std::fs::read_to_string(&written.json).unwrap()).unwrap();
        assert_eq!(json.sequences.len(), 1);
        assert!(written
            .plots
            .iter()
            .any(|p| p.ends_with("horizon-slide.png")));
        assert!(written.plots.iter().all(|p| p.is_file()));
    }
}
