//! What the service counts and measures, printed as a stats line and written as JSON.

use std::path::PathBuf;

use evgate_model::ActiveProvider;
use serde::Serialize;

use crate::latency::{TimingRecorder, TimingSummary};
use crate::worker::ForecastReady;

/// Counters and timings since start.
#[derive(Debug, Default)]
pub struct InferCounters {
    pub batches_received: u64,
    /// Batches whose header did not describe their payload, skipped.
    pub batches_rejected: u64,
    pub events_received: u64,
    pub gaps_detected: u64,
    pub streams_started: u64,
    pub windows_closed: u64,
    /// Windows replaced by a newer one before the model got to them.
    pub windows_skipped_busy: u64,
    pub forecasts_published: u64,
    /// Forecasts published while no subscriber (gate) was connected.
    pub forecasts_without_subscriber: u64,
    events_in_windows: u64,
    mask_pixels: u64,
    sensor_pixels: u64,
    pub voxelisation: TimingRecorder,
    pub inference: TimingRecorder,
    pub thresholding: TimingRecorder,
    pub processing: TimingRecorder,
    /// Window closed (seen by the receiving thread) → forecast published.
    pub latency: TimingRecorder,
}

impl InferCounters {
    pub fn record_forecast(&mut self, ready: &ForecastReady, recipients: usize) {
        self.forecasts_published += 1;
        if recipients == 0 {
            self.forecasts_without_subscriber += 1;
        }
        self.events_in_windows += ready.events_in_window as u64;
        self.mask_pixels += ready.current_mask_pixels as u64;
        self.sensor_pixels += ready.sensor.pixels() as u64;
        self.voxelisation.record(ready.voxelisation);
        self.inference.record(ready.inference);
        self.thresholding.record(ready.thresholding);
        self.processing.record(ready.processing());
        self.latency.record(ready.closed_at.elapsed());
    }
}

/// Fixed facts of the run, for the report.
#[derive(Debug, Clone)]
pub struct RunDescription {
    pub model: PathBuf,
    pub model_id: u64,
    pub model_size: &'static str,
    pub provider: ActiveProvider,
    /// Whether the recurrent state stays bound to the session's device between windows.
    pub state_bound: bool,
    /// The run on a zero window before subscribing, which pays ONNX Runtime's lazy set-up.
    pub warm_up_ms: f64,
    pub threads: usize,
    /// The mask threshold in use: --threshold-logit, else the model's.
    pub threshold_logit: f32,
    /// The keep regions' threshold and dilation in use: the flags, else the model's.
    pub keep_threshold_logit: f32,
    pub keep_dilation_px: u16,
    /// Side of the square of sensor pixels one network input cell bins.
    pub downsample: u16,
    pub horizons_ms: Vec<f32>,
    pub windowing: String,
}

/// How far ahead a horizon's mask still reaches once the forecast is out.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct PredictionAge {
    pub horizon_ms: f32,
    /// Horizon − median model runtime (voxelisation + inference + thresholding).
    pub after_runtime_ms: f64,
    /// Horizon − median latency from window close to publication (adds any queueing).
    pub after_latency_ms: f64,
}

/// The stats as printed and written.
#[derive(Debug, Clone, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct InferReport {
    pub model: PathBuf,
    pub model_id: String,
    pub model_size: &'static str,
    pub provider: ActiveProvider,
    pub state_bound: bool,
    pub warm_up_ms: f64,
    pub threads: usize,
    pub threshold_logit: f32,
    pub keep_threshold_logit: f32,
    pub keep_dilation_px: u16,
    pub downsample: u16,
    pub horizons_ms: Vec<f32>,
    pub windowing: String,
    pub elapsed_s: f64,
    pub batches_received: u64,
    pub batches_rejected: u64,
    pub events_received: u64,
    pub gaps_detected: u64,
    pub streams_started: u64,
    pub windows_closed: u64,
    pub windows_skipped_busy: u64,
    /// Empty windows passed over after a silence in event time.
    pub windows_skipped_silent: u64,
    pub forecasts_published: u64,
    pub forecasts_without_subscriber: u64,
    pub mean_events_per_window: f64,
    /// Share of sensor pixels set in the current masks.
    pub mean_current_mask_share: f64,
    pub voxelisation: TimingSummary,
    pub inference: TimingSummary,
    pub thresholding: TimingSummary,
    pub processing: TimingSummary,
    pub latency: TimingSummary,
    pub prediction_age: Vec<PredictionAge>,
}

impl InferReport {
    pub fn new(
        description: &RunDescription,
        counters: &InferCounters,
        windows_skipped_silent: u64,
        elapsed_s: f64,
    ) -> Self {
        let processing = counters.processing.summary();
        let latency = counters.latency.summary();
        let published = counters.forecasts_published.max(1) as f64;
        Self {
            model: description.model.clone(),
            model_id: format!("{:016x}", description.model_id),
            model_size: description.model_size,
            provider: description.provider,
            state_bound: description.state_bound,
            warm_up_ms: description.warm_up_ms,
            threads: description.threads,
            threshold_logit: description.threshold_logit,
            keep_threshold_logit: description.keep_threshold_logit,
            keep_dilation_px: description.keep_dilation_px,
            downsample: description.downsample,
            horizons_ms: description.horizons_ms.clone(),
            windowing: description.windowing.clone(),
            elapsed_s,
            batches_received: counters.batches_received,
            batches_rejected: counters.batches_rejected,
            events_received: counters.events_received,
            gaps_detected: counters.gaps_detected,
            streams_started: counters.streams_started,
            windows_closed: counters.windows_closed,
            windows_skipped_busy: counters.windows_skipped_busy,
            windows_skipped_silent,
            forecasts_published: counters.forecasts_published,
            forecasts_without_subscriber: counters.forecasts_without_subscriber,
            mean_events_per_window: counters.events_in_windows as f64 / published,
            mean_current_mask_share: counters.mask_pixels as f64
                / counters.sensor_pixels.max(1) as f64,
            voxelisation: counters.voxelisation.summary(),
            inference: counters.inference.summary(),
            thresholding: counters.thresholding.summary(),
            prediction_age: description
                .horizons_ms
                .iter()
                .map(|&horizon_ms| PredictionAge {
                    horizon_ms,
                    after_runtime_ms: f64::from(horizon_ms) - processing.median_ms,
                    after_latency_ms: f64::from(horizon_ms) - latency.median_ms,
                })
                .collect(),
            processing,
            latency,
        }
    }

    /// One human-readable line.
    pub fn line(&self) -> String {
        format!(
            "windows {} (skipped busy {}, silent {}), forecasts {} ({} without subscriber), \
             events {}, inference median {:.2} ms p99 {:.2} ms, voxelisation median {:.2} ms, \
             latency median {:.2} ms, prediction age at {} ms: {:.1} ms",
            self.windows_closed,
            self.windows_skipped_busy,
            self.windows_skipped_silent,
            self.forecasts_published,
            self.forecasts_without_subscriber,
            self.events_received,
            self.inference.median_ms,
            self.inference.p99_ms,
            self.voxelisation.median_ms,
            self.latency.median_ms,
            self.prediction_age.last().map_or(0.0, |age| age.horizon_ms),
            self.prediction_age
                .last()
                .map_or(0.0, |age| age.after_latency_ms),
        )
    }
}
