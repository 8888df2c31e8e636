//! `evgate run`: starts ingest (the built-in simulated camera or a recording), inference and
//! gate as child processes on a private domain, shows a live status line from the gate's stats
//! and ends with a summary, including per-event precision, recall and F1 against the labels
//! when the source has them.

mod children;
mod default_model;
mod metrics;
mod scoring;
mod service_configs;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use evgate_core::{GateMode, NoForecast};
use evgate_ipc::{
    create_node, BatchHeader, LatestSubscriber, PipelineNames, PipelineStats, Qos, SliceSubscriber,
    Stream, WaitStrategy,
};
use iceoryx2::prelude::{CallbackProgression, WaitSetAttachmentId, WaitSetBuilder};
use iceoryx2::waitset::WaitSetRunResult;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use tracing::{info, warn};

use children::{binary_directory, Service};
use clap::Parser;
use default_model::ModelChoice;
use evgate_gate::Output;
use evgate_ipc::Overflow;
use scoring::{Scorer, Scores};
use service_configs::ServiceConfigs;

/// Arguments of `evgate run`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// TOML file of defaults (example: examples/config/run.toml): its keys are this command's
    /// flags without the dashes, a string or number for a flag that takes a value, true or
    /// false for a switch; a flag given on the command line overrides its key.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Recording to replay: any format evgate-io decodes, or a labelled-sequence .npz (then
    /// scored against its labels); or a live AEDAT 4 network stream, tcp://HOST:PORT or
    /// unix:///PATH (a DV camera through the DV runtime, dv-processing's NetworkWriter);
    /// without it, the built-in simulated camera.
    #[arg(long)]
    input: Option<PathBuf>,
    /// Sensor size of --input as WIDTHxHEIGHT: required for files that give none (text), and
    /// overrides the file's otherwise.
    #[arg(long, value_parser = evgate_io::header::parse_sensor_flag)]
    sensor: Option<evgate_core::SensorSize>,
    /// Scene of the simulated camera: boxes, floor, wall, table, fast, tabletop or driving.
    #[arg(long, default_value = "boxes")]
    preset: String,
    /// Seed of the simulated scene.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seconds of events: simulated time for the simulated camera; for a recording, the run
    /// stops after this much wall-clock time (the whole file when not given).
    #[arg(long)]
    duration: Option<f64>,
    /// Exported network the inference runs; default: the shipped export for the source's
    /// sensor size, models/evgate-S.onnx (sensors padding to 352×272, such as 346×260) or
    /// models/evgate-S-640x480.onnx (640×480; larger sensors binned to fit, see
    /// --downsample), looked for in the executable's directory and its ancestors, and used
    /// only where no other user could have put it.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Bin the sensor's pixels N×N for the network (events are still gated at full
    /// resolution); default: 1, or without --model, for a sensor larger than every shipped
    /// export, the smallest N up to 8 that fits the 352×272 one (1280×720: 4).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=16))]
    downsample: Option<u16>,
    /// Execution provider of the inference service: cpu, cuda (falls back to cpu with a
    /// warning when CUDA cannot be used) or auto.
    #[arg(long, default_value = "cpu")]
    provider: evgate_model::Provider,
    /// Run without the inference service: every event then follows --no-forecast.
    #[arg(long)]
    no_infer: bool,
    /// Which events pass.
    #[arg(long, value_enum, default_value = "keep-moving-objects")]
    mode: GateMode,
    /// Fate of events no valid forecast judges.
    #[arg(long, value_enum, default_value = "pass")]
    no_forecast: NoForecast,
    /// How the gate and the inference service wait for their input: event (sleep until
    /// notified) or busy-poll (lowest latency, one core each at 100 %; see --gate-cpu and
    /// --infer-cpu).
    #[arg(long, value_enum, default_value = "event")]
    wait: WaitStrategy,
    /// Pin the gate's thread to this CPU.
    #[arg(long)]
    gate_cpu: Option<usize>,
    /// Pin the inference service's loop thread to this CPU.
    #[arg(long)]
    infer_cpu: Option<usize>,
    /// Publish events as fast as possible instead of at the pace of their timestamps.
    #[arg(long)]
    fast: bool,
    /// Replay --input from its start again whenever it ends (stream time keeps increasing),
    /// until --duration or a signal.
    #[arg(long = "loop", requires = "input")]
    loop_input: bool,
    /// Judge every event by the forecast of the newest window that ended at or before it, with
    /// every window forecast (evgate-gate --lock-step, evgate-infer --every-window): the
    /// decisions of `evgate eval` on the same recording, model and horizons, at the price of
    /// latency (each batch waits for its forecast).
    #[arg(long, conflicts_with = "no_infer")]
    lock_step: bool,
    /// Forecast horizons of the inference service in milliseconds, comma-separated and
    /// ascending (at most 8); default: the service's.
    #[arg(long, value_delimiter = ',')]
    horizons_ms: Vec<f32>,
    /// Write the gate's verdict on every input event to FILE (.npy, one uint8 per event in
    /// input order: 1 passed, 0 suppressed), as `evgate eval --keep-bits` does.
    #[arg(long, value_name = "FILE")]
    keep_bits: Option<PathBuf>,
    /// Batch span in milliseconds.
    #[arg(long, default_value_t = 1.0)]
    batch_ms: f64,
    /// Pipeline domain; default: a fresh one per run, so runs never share services.
    #[arg(long)]
    domain: Option<String>,
    /// Camera name within the domain.
    #[arg(long, default_value = "cam0")]
    camera: String,
    /// Refresh period of the status line, milliseconds.
    #[arg(long, default_value_t = 250)]
    status_interval_ms: u64,
    /// Also serve the kept events as an AEDAT 4 network stream on tcp://HOST:PORT or
    /// unix:///PATH (evgate-gate --serve-kept), for DV tools and dv-processing's NetworkReader.
    #[arg(long)]
    serve_kept: Option<String>,
    /// After the last batch, how long --serve-kept holds its client connections open before it
    /// closes them, milliseconds (evgate-gate --serve-kept-linger-ms).
    #[arg(long, default_value_t = 1000)]
    serve_kept_linger_ms: u64,
    /// Serve Prometheus metrics at http://HOST:PORT/metrics: the gate's event and forecast
    /// counters, and the model runtime and prediction age sampled at each stats publication.
    #[arg(long)]
    metrics_addr: Option<String>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    json: bool,
}

/// The gate's verdict on each input event, by its index in the input (`--keep-bits`).
#[derive(Default)]
struct Verdicts {
    passed: Vec<u8>,
}

impl Verdicts {
    fn add(&mut self, header: &BatchHeader, bitmap: &[u64]) {
        let first = header.first_event_index as usize;
        let end = first + header.event_count as usize;
        if self.passed.len() < end {
            self.passed.resize(end, 0);
        }
        for (offset, verdict) in self.passed[first..end].iter_mut().enumerate() {
            *verdict = u8::from(
                bitmap
                    .get(offset / 64)
                    .is_some_and(|word| word >> (offset % 64) & 1 == 1),
            );
        }
    }
}

/// Rates between two status updates.
#[derive(Clone, Copy, Debug, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
struct Rates {
    events_in_per_s: f64,
    events_out_per_s: f64,
}

/// What `evgate run` prints at the end.
#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct RunSummary {
    domain: String,
    source: String,
    /// `end-of-stream`, `duration`, `signal` or `service-failed`.
    ended_by: &'static str,
    wall_s: f64,
    mean_rates: Rates,
    kept_ratio: Option<f64>,
    /// The gate's final counters (null when it never published).
    stats: Option<PipelineStats>,
    balanced: Option<bool>,
    /// Per-event scores of the kept events against the labels (null without labels).
    /// Positive class: the events the mode keeps (label > 0 for keep-moving-objects).
    scores: Option<Scores>,
    /// The JSON summaries the services printed at exit.
    services: serde_json::Map<String, serde_json::Value>,
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    if let Some(duration) = args.duration {
        if !(duration > 0.0 && duration.is_finite()) {
            bail!("--duration = {duration} must be a positive number of seconds");
        }
    }
    let model = match (&args.model, args.no_infer) {
        (_, true) => None,
        (Some(model), false) if model.is_file() => Some(ModelChoice {
            path: model.clone(),
            downsample: args.downsample.unwrap_or(1),
        }),
        (Some(model), false) => bail!(
            "model {} not found: export one (models/training) or pass another --model, or run \
             with --no-infer",
            model.display()
        ),
        (None, false) => {
            let sensor =
                default_model::source_sensor(args.input.as_deref(), args.sensor, &args.preset)?;
            let search_from: Vec<PathBuf> = binary_directory().into_iter().collect();
            Some(default_model::shipped_model_for(
                sensor,
                args.downsample,
                &search_from,
            )?)
        }
    };
    let domain = args
        .domain
        .clone()
        .unwrap_or_else(|| format!("evgate-run-{}", std::process::id()));
    let names = PipelineNames::new(&domain, &args.camera)?;
    let node = create_node("evgate-run")?;
    // Subscribe before any service starts so no batch is missed.
    let reader_qos = Qos::default();
    let labels =
        SliceSubscriber::<u16, BatchHeader>::open(&node, &names, Stream::Labels, &reader_qos)?;
    let bitmaps =
        SliceSubscriber::<u64, BatchHeader>::open(&node, &names, Stream::KeepBitmap, &reader_qos)?;
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats)?;

    let directory = binary_directory()?;
    // Each service gets its typed configuration as its own --config file.
    let configs = ServiceConfigs::new()?;
    let mut gate = evgate_gate::Config::parse_from(["evgate-gate"]);
    gate.domain = domain.clone();
    gate.camera = args.camera.clone();
    gate.mode = args.mode;
    gate.no_forecast = args.no_forecast;
    gate.wait = args.wait;
    gate.outputs = vec![Output::Kept, Output::Suppressed, Output::KeepBitmap];
    // The scores need every bitmap; this reader keeps up, so blocking costs nothing.
    gate.overflow = Overflow::Block;
    gate.exit_at_end_of_stream = true;
    gate.json = true;
    gate.cpu = args.gate_cpu;
    gate.serve_kept = args.serve_kept.clone();
    gate.serve_kept_linger_ms = args.serve_kept_linger_ms;
    gate.lock_step = args.lock_step;
    let gate_args = configs.arguments("evgate-gate", &gate)?;
    let mut services = vec![Service::start(&directory, "evgate-gate", &gate_args)?];
    if let Some(model) = &model {
        let mut infer = evgate_infer::Config::parse_from(["evgate-infer"]);
        infer.domain = domain.clone();
        infer.camera = args.camera.clone();
        infer.model = model.path.clone();
        infer.downsample = model.downsample;
        infer.provider = args.provider;
        infer.exit_at_end = true;
        infer.wait = args.wait;
        infer.cpu = args.infer_cpu;
        infer.every_window = args.lock_step;
        infer.horizons_ms = args.horizons_ms.clone();
        let infer_args = configs.arguments("evgate-infer", &infer)?;
        services.push(Service::start(&directory, "evgate-infer", &infer_args)?);
    }
    let mut ingest = evgate_ingest::Config::parse_from(["evgate-ingest"]);
    ingest.domain = domain.clone();
    ingest.camera = args.camera.clone();
    ingest.wait_for_subscribers = services.len();
    ingest.batch_ms = args.batch_ms;
    ingest.json = true;
    ingest.fast = args.fast;
    ingest.repeat = args.loop_input;
    let source = match &args.input {
        Some(path) => {
            ingest.input = Some(path.clone());
            ingest.sensor = args.sensor;
            path.display().to_string()
        }
        None => {
            ingest.preset = args.preset.parse()?;
            ingest.seed = args.seed;
            ingest.sim_duration_s = args.duration.unwrap_or(10.0);
            format!(
                "simulated camera, preset {} seed {}",
                args.preset, args.seed
            )
        }
    };
    let ingest_args = configs.arguments("evgate-ingest", &ingest)?;
    services.push(Service::start(&directory, "evgate-ingest", &ingest_args)?);
    info!(%domain, %source, "pipeline started");

    let waitset = WaitSetBuilder::new()
        .create::<evgate_ipc::Service>()
        .context("cannot create the iceoryx2 waitset")?;
    let labels_guard = waitset
        .attach_notification(labels.listener())
        .context("cannot attach the labels listener")?;
    let bitmaps_guard = waitset
        .attach_notification(bitmaps.listener())
        .context("cannot attach the keep-bitmap listener")?;
    let status_tick = waitset
        .attach_interval(Duration::from_millis(args.status_interval_ms.max(1)))
        .context("cannot attach the status interval")?;
    let missed_wakeup_poll = waitset
        .attach_interval(evgate_ipc::MISSED_WAKEUP_POLL)
        .context("cannot attach the missed wake-up poll")?;

    let mut scorer = Scorer::new(args.mode);
    let mut verdicts = Verdicts::default();
    let mut saw_labels = false;
    let mut end_of_stream = false;
    let mut latest_stats: Option<PipelineStats> = None;
    let mut metrics = args
        .metrics_addr
        .as_deref()
        .map(metrics::RunMetrics::serve)
        .transpose()?;
    let mut previous: Option<(Instant, PipelineStats)> = None;
    let mut ended_by = "end-of-stream";
    let mut failure: Option<anyhow::Error> = None;
    let started = Instant::now();
    let wall_limit = args
        .input
        .as_ref()
        .and(args.duration)
        .map(Duration::from_secs_f64);
    let status = ProgressBar::new_spinner();
    status.set_style(
        ProgressStyle::with_template("{spinner} {elapsed} {msg}")
            .context("status line template")?,
    );

    let outcome = evgate_ipc::run_until_stopped(
        &waitset,
        |attachment: WaitSetAttachmentId<evgate_ipc::Service>| {
            let step = (|| -> anyhow::Result<bool> {
                // The poll reads both streams as if both had notified.
                let polled = attachment.has_event_from(&missed_wakeup_poll);
                if polled || attachment.has_event_from(&labels_guard) {
                    labels.clear_wakeups();
                    while let Some(sample) = labels.receive()? {
                        let header = sample.user_header();
                        saw_labels = true;
                        scorer.add_labels(header.stream_id, header.sequence, sample.payload());
                    }
                }
                if polled || attachment.has_event_from(&bitmaps_guard) {
                    bitmaps.clear_wakeups();
                    while let Some(sample) = bitmaps.receive()? {
                        let header = sample.user_header();
                        scorer.add_bitmap(header.stream_id, header.sequence, sample.payload());
                        verdicts.add(header, sample.payload());
                        end_of_stream |= header.is_end_of_stream();
                    }
                }
                if attachment.has_event_from(&status_tick) {
                    if let Some(fresh) = stats.latest()? {
                        latest_stats = Some(fresh);
                        if let Some(metrics) = &mut metrics {
                            metrics.update(&fresh);
                        }
                    }
                    if let Some(current) = latest_stats {
                        status.set_message(status_line(previous.as_ref(), &current));
                        previous = Some((Instant::now(), current));
                    }
                    status.tick();
                    for service in services.iter_mut() {
                        if let Some(status) = service.status()? {
                            if !status.success() {
                                bail!(
                                    "{} (pid {}) failed: {status}",
                                    service.binary,
                                    service.pid()
                                );
                            }
                        }
                    }
                    if wall_limit.is_some_and(|limit| started.elapsed() >= limit) {
                        ended_by = "duration";
                        return Ok(true);
                    }
                }
                Ok(end_of_stream)
            })();
            match step {
                Ok(true) => CallbackProgression::Stop,
                Ok(false) => CallbackProgression::Continue,
                Err(error) => {
                    failure = Some(error);
                    CallbackProgression::Stop
                }
            }
        },
    )
    .context("waiting on the iceoryx2 waitset failed")?;
    status.finish_and_clear();
    if outcome == WaitSetRunResult::TerminationRequest {
        ended_by = "signal";
    }
    if failure.is_some() {
        ended_by = "service-failed";
    }
    let wall_s = started.elapsed().as_secs_f64();

    // At the end of the stream the services exit by themselves; otherwise they are asked to.
    let grace = Duration::from_secs(10);
    if ended_by != "end-of-stream" {
        for service in services.iter_mut() {
            service.request_stop()?;
        }
    }
    let mut summaries = serde_json::Map::new();
    for service in services.iter_mut() {
        let output = service.finish(grace)?;
        match serde_json::from_str::<serde_json::Value>(&output) {
            Ok(value) => {
                summaries.insert(service.binary.to_owned(), value);
            }
            Err(_) if output.trim().is_empty() => {}
            Err(error) => warn!(service = service.binary, %error, "summary is not JSON"),
        }
    }
    if let Some(fresh) = stats.latest()? {
        latest_stats = Some(fresh);
    }
    // Bitmaps published after the end-of-stream stop (none, normally) still count.
    while let Some(sample) = labels.receive()? {
        let header = sample.user_header();
        scorer.add_labels(header.stream_id, header.sequence, sample.payload());
    }
    while let Some(sample) = bitmaps.receive()? {
        let header = sample.user_header();
        scorer.add_bitmap(header.stream_id, header.sequence, sample.payload());
        verdicts.add(header, sample.payload());
    }
    if let Some(path) = &args.keep_bits {
        crate::eval::write_verdicts(path, &verdicts.passed)
            .with_context(|| format!("--keep-bits: cannot write {}", path.display()))?;
    }

    let summary = RunSummary {
        domain,
        source,
        ended_by,
        wall_s,
        mean_rates: latest_stats
            .map(|s| Rates {
                events_in_per_s: s.input_events as f64 / wall_s,
                events_out_per_s: s.passed_events() as f64 / wall_s,
            })
            .unwrap_or_default(),
        kept_ratio: latest_stats
            .filter(|s| s.input_events > 0)
            .map(|s| s.passed_events() as f64 / s.input_events as f64),
        balanced: latest_stats.map(|s| s.is_balanced()),
        stats: latest_stats,
        scores: saw_labels.then(|| scorer.scores()),
        services: summaries,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary);
    }
    if let Some(error) = failure {
        return Err(error);
    }
    Ok(())
}

fn status_line(previous: Option<&(Instant, PipelineStats)>, current: &PipelineStats) -> String {
    let rates = previous
        .map(|(at, before)| {
            let seconds = at.elapsed().as_secs_f64().max(1e-6);
            Rates {
                events_in_per_s: (current.input_events
                    - before.input_events.min(current.input_events))
                    as f64
                    / seconds,
                events_out_per_s: (current.passed_events()
                    - before.passed_events().min(current.passed_events()))
                    as f64
                    / seconds,
            }
        })
        .unwrap_or_default();
    let kept = if current.input_events > 0 {
        100.0 * current.passed_events() as f64 / current.input_events as f64
    } else {
        0.0
    };
    let measured = |value: i64, scale: f64, unit: &str| {
        if value == evgate_ipc::stats::NOT_MEASURED {
            "n/a".to_owned()
        } else {
            format!("{:.1} {unit}", value as f64 / scale)
        }
    };
    format!(
        "in {:.2} Mev/s  out {:.2} Mev/s  kept {kept:.1}%  inference {}  prediction age {}  dropped {}",
        rates.events_in_per_s / 1e6,
        rates.events_out_per_s / 1e6,
        measured(current.latest_model_runtime_us, 1e3, "ms"),
        measured(current.latest_prediction_age_us, 1e3, "ms"),
        current.dropped_events,
    )
}

fn print_summary(summary: &RunSummary) {
    println!(
        "evgate run on {} ({}), ended by {} after {:.1} s",
        summary.source, summary.domain, summary.ended_by, summary.wall_s
    );
    if let Some(stats) = &summary.stats {
        println!(
            "events: {} in, {} kept, {} suppressed, {} unjudged passed, {} unjudged dropped, {} lost; balanced: {}",
            stats.input_events,
            stats.kept_events,
            stats.suppressed_events,
            stats.unjudged_passed_events,
            stats.unjudged_dropped_events,
            stats.dropped_events,
            stats.is_balanced()
        );
        println!(
            "forecasts: {} received, {} used, {} rejected",
            stats.forecasts_received, stats.forecasts_used, stats.forecasts_rejected
        );
    }
    println!(
        "mean rates: {:.3} Mev/s in, {:.3} Mev/s out",
        summary.mean_rates.events_in_per_s / 1e6,
        summary.mean_rates.events_out_per_s / 1e6
    );
    if let Some(scores) = &summary.scores {
        let show = |value: Option<f64>| value.map_or("n/a".to_owned(), |v| format!("{v:.3}"));
        println!(
            "per-event scores over {} events: precision {}, recall {}, F1 {}, suppressed {}",
            scores.events_scored,
            show(scores.precision),
            show(scores.recall),
            show(scores.f1),
            show(scores.suppressed_ratio)
        );
    }
}
