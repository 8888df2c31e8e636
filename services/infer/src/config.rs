//! The settings of `evgate-infer`: its command line, and `--config` file keys.

use std::path::PathBuf;

use clap::Parser;
use evgate_ipc::WaitStrategy;
use evgate_model::{Provider, StateBinding};
use serde::Serialize;

/// Runs the suppression network on the event stream of one pipeline and publishes forecast
/// masks (the current mask and one per horizon) on `<domain>/<camera>/forecast`.
#[derive(Debug, Clone, Parser, Serialize)]
#[command(name = "evgate-infer", version, about)]
#[serde(rename_all = "kebab-case")]
pub struct Config {
    /// TOML file of defaults: its keys are this command's flags without the dashes, a string
    /// or number for a flag that takes a value (an array for a list), true or false for a
    /// switch; a flag given on the command line overrides its key.
    #[arg(long)]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Exported network (docs/model-contract.md).
    #[arg(long, default_value = "models/evgate-S.onnx")]
    pub model: PathBuf,
    /// Execution provider: cpu, cuda (falls back to cpu with a warning when CUDA cannot be
    /// used) or auto (cuda when usable, else cpu).
    #[arg(long, default_value = "cpu")]
    pub provider: Provider,
    /// Threads ONNX Runtime uses inside one operator (0: one per core).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Keep ONNX Runtime's idle threads spinning between windows: lower latency, but they burn
    /// the cores that ingest and gate share.
    #[arg(long)]
    pub spin_threads: bool,
    /// CUDA device ordinal for the cuda and auto providers.
    #[arg(long, default_value_t = 0)]
    pub cuda_device: i32,
    /// Where the network's recurrent state lives between windows: auto (in GPU memory when the
    /// session runs on CUDA, saving a copy of every state tensor to the host and back per
    /// window), always (bound on the CPU too) or never (passed through host memory).
    #[arg(long, default_value = "auto")]
    pub state_binding: StateBinding,
    /// Pipeline domain: the first part of the service names `<domain>/<camera>/<stream>`.
    #[arg(long, default_value = "evgate")]
    pub domain: String,
    /// Camera name: the second part of the service names.
    #[arg(long, default_value = "cam0")]
    pub camera: String,
    /// Forecast horizons in milliseconds, comma-separated and ascending, at most
    /// evgate_ipc::MAX_HORIZONS; default: that many evenly spaced up to the model's largest
    /// horizon.
    #[arg(long, value_delimiter = ',')]
    pub horizons_ms: Vec<f32>,
    /// Event time between two forecasts in milliseconds; default: the model's window length.
    #[arg(long)]
    pub stride_ms: Option<f64>,
    /// Close a window every this many events instead of by event time.
    #[arg(long, conflicts_with = "stride_ms")]
    pub window_events: Option<usize>,
    /// Logit above which a pixel is marked as independently moving (0 ⇔ probability 0.5);
    /// default: the model's `evgate.threshold-logit` (chosen on validation data), else 0.
    #[arg(long, allow_negative_numbers = true)]
    pub threshold_logit: Option<f32>,
    /// Logit above which a pixel of a dilated forecast is in the keep region the gate judges a
    /// horizon's events by; default: the model's `evgate.keep-threshold-logit` (chosen on
    /// validation data), else the mask threshold.
    #[arg(long, allow_negative_numbers = true)]
    pub keep_threshold_logit: Option<f32>,
    /// Publish for each horizon the keep region instead of the forecast mask: the forecast
    /// logits dilated by this many model pixels (each pixel takes the largest logit of the
    /// (2N + 1)-pixel square around it), above --keep-threshold-logit; default: the model's
    /// `evgate.keep-dilation-px` (chosen on validation data), else 0.
    #[arg(long, value_parser = clap::value_parser!(u16).range(0..=i64::from(evgate_model::metadata::MAX_KEEP_DILATION_PX)))]
    pub keep_dilation_px: Option<u16>,
    /// Bin the sensor's pixels N×N for the network, so that a sensor larger than the model's
    /// input runs (1280×720 with N = 2 on a 640×480 export); every pixel takes its cell's
    /// verdict, so events are still gated at full resolution.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=16))]
    pub downsample: u16,
    /// Sleep between two polls of the event stream, microseconds (under --wait event).
    #[arg(long, default_value_t = 1000)]
    pub cycle_us: u64,
    /// How the service loop waits: event (sleeps --cycle-us between polls) or busy-poll (never
    /// sleeps: a window closes and its forecast goes out within microseconds, at the price of
    /// one core at 100 %; give it its own core with --cpu).
    #[arg(long, value_enum, default_value = "event")]
    pub wait: WaitStrategy,
    /// Pin the service loop's thread (the one that polls the events and publishes forecasts)
    /// to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Seconds between two stats lines; 0 prints them only at exit.
    #[arg(long, default_value_t = 5.0)]
    pub stats_interval_s: f64,
    /// Also write the stats as JSON to this file, at every stats line and at exit.
    #[arg(long)]
    pub stats_json: Option<PathBuf>,
    /// Serve Prometheus metrics at http://HOST:PORT/metrics: inference time and forecast
    /// latency as histograms, windows and forecasts as counters.
    #[arg(long)]
    pub metrics_addr: Option<String>,
    /// Forecast every window in turn instead of only the newest when the model falls behind:
    /// the forecasts of a replay are then those of `evgate eval`, at the price of a growing
    /// delay (and queue) while the model is slower than the events.
    #[arg(long)]
    pub every_window: bool,
    /// Exit once the event stream has ended and the forecast of its last window is published.
    #[arg(long)]
    pub exit_at_end: bool,
}
