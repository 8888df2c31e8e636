//! The service loop: the main thread owns the shared-memory ports (iceoryx2 ports stay on the
//! thread that made them), drains the event stream every cycle and publishes finished
//! forecasts; the inference thread works on the newest closed window (on every window in turn
//! under `--every-window`).

use std::path::Path;
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use evgate_core::{words_for, Event, SensorSize};
use evgate_ipc::{
    clock, create_node, pin_current_thread, BatchHeader, ForecastHeader, PipelineNames, Qos,
    SlicePublisher, SliceSubscriber, Stream, MAX_HORIZONS,
};
use evgate_model::{Forecaster, MaskRule, ModelRuntime, RuntimeOptions};
use tracing::{error, info, warn};

use crate::config::Config;
use crate::error::InferError;
use crate::horizons::{horizon_us, resolve_horizons};
use crate::loop_wait::LoopWait;
use crate::metrics::InferMetrics;
use crate::stats::{InferCounters, InferReport, RunDescription};
use crate::window_handover::WindowHandover;
use crate::windowing::{ClosedWindow, WindowAssembler, WindowMode};
use crate::worker::{ForecastReady, WindowJob, Worker, WorkerError};

/// Runs until SIGINT/SIGTERM (or the end of the stream with `--exit-at-end`) and returns the
/// final stats.
pub fn run(args: &Config) -> Result<InferReport, InferError> {
    if let Some(cpu) = args.cpu {
        pin_current_thread(cpu)?;
    }
    let node = create_node("evgate-infer")?;
    // iceoryx2 installs its SIGINT/SIGTERM handlers on the first wait; doing it now, before the
    // model loads, turns an early Ctrl-C into a clean stop instead of the default kill.
    if evgate_ipc::stop_requested(&node, Duration::ZERO) {
        return Err(InferError::StoppedBeforeStart);
    }
    let options = RuntimeOptions {
        provider: args.provider,
        intra_threads: args.threads,
        spin_threads: args.spin_threads,
        cuda_device: args.cuda_device,
        library: None,
        state_binding: args.state_binding,
    };
    let mut runtime = ModelRuntime::load(&args.model, options)?;
    let metadata = runtime.metadata().clone();
    let horizons_ms = resolve_horizons(&args.horizons_ms, metadata.max_horizon_ms)?;
    // Before subscribing, so that the stream (which waits for its subscribers) does not flow
    // past a first window that on CUDA took 2 s (H200: cuDNN's algorithm search).
    let warm_up = runtime.warm_up(&horizons_ms)?;
    info!(warm_up_ms = warm_up.as_secs_f64() * 1e3, "model warmed up");
    let rule = MaskRule {
        threshold_logit: args.threshold_logit.unwrap_or(metadata.threshold_logit),
        keep_threshold_logit: args
            .keep_threshold_logit
            .unwrap_or(metadata.keep_threshold_logit),
        keep_dilation_px: args.keep_dilation_px.unwrap_or(metadata.keep_dilation_px),
    };
    for (flag, value) in [
        ("--threshold-logit", rule.threshold_logit),
        ("--keep-threshold-logit", rule.keep_threshold_logit),
    ] {
        if !value.is_finite() {
            return Err(InferError::ThresholdLogit { flag, value });
        }
    }
    let window_us = i64::from(metadata.window_ms) * 1000;
    let mode = match args.window_events {
        Some(events) => WindowMode::EventCount { events },
        None => WindowMode::Duration {
            window_us,
            stride_us: args
                .stride_ms
                .map_or(window_us, |ms| (ms * 1000.0).round() as i64),
        },
    };
    let mut assembler = WindowAssembler::new(mode)?;
    let description = RunDescription {
        model: args.model.clone(),
        model_id: runtime.model_id(),
        model_size: metadata.model_size.label(),
        provider: runtime.active_provider(),
        state_bound: runtime.state_bound(),
        warm_up_ms: warm_up.as_secs_f64() * 1e3,
        threads: args.threads,
        threshold_logit: rule.threshold_logit,
        keep_threshold_logit: rule.keep_threshold_logit,
        keep_dilation_px: rule.keep_dilation_px,
        downsample: args.downsample,
        horizons_ms: horizons_ms.clone(),
        windowing: describe(mode),
    };

    let names = PipelineNames::new(&args.domain, &args.camera)?;
    let events = SliceSubscriber::<Event, BatchHeader>::open(
        &node,
        &names,
        Stream::Events,
        &Qos::default(),
    )?;
    let forecasts = SlicePublisher::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )?;
    info!(
        events = events.service_name(),
        forecasts = forecasts.service_name(),
        horizons_ms = ?horizons_ms,
        windowing = %description.windowing,
        "inference service ready"
    );

    let slot = Arc::new(WindowHandover::<WindowJob>::new(args.every_window));
    let (result_sender, results) = mpsc::channel();
    let worker = {
        let slot = Arc::clone(&slot);
        let worker = Worker::new(
            Forecaster::new(runtime, rule, args.downsample).keep_regions_only(),
            horizons_ms.clone(),
        );
        std::thread::Builder::new()
            .name("evgate-infer-model".to_owned())
            .spawn(move || worker.run(slot, result_sender))
            .map_err(InferError::Thread)?
    };

    let mut state = LoopState {
        description,
        horizons_us: horizons_ms.iter().map(|&ms| horizon_us(ms)).collect(),
        counters: InferCounters::default(),
        current_stream: None,
        next_event_index: 0,
        stream_epoch: 0,
        end_seen: false,
        jobs_in_flight: 0,
        forecast_sequence: 0,
        closed: Vec::new(),
        metrics: args
            .metrics_addr
            .as_deref()
            .map(InferMetrics::serve)
            .transpose()?,
    };
    let started = Instant::now();
    let stats_interval =
        (args.stats_interval_s > 0.0).then(|| Duration::from_secs_f64(args.stats_interval_s));
    let mut last_stats = Instant::now();
    let mut wait = LoopWait::new(args.wait, Duration::from_micros(args.cycle_us.max(1)));

    let outcome = loop {
        if wait.stop_requested(&node) {
            info!("stopping on SIGINT or SIGTERM");
            break Ok(());
        }
        let worked = match state.receive_batches(&events, &mut assembler, &slot, args.every_window)
        {
            Ok(batches) => batches > 0,
            Err(failure) => break Err(failure),
        };
        match state.publish_results(&results, &forecasts) {
            Ok(Published::Forecasts) => wait.worked(),
            Ok(Published::Nothing) if worked => wait.worked(),
            Ok(Published::Nothing) => wait.idle(),
            Ok(Published::WorkerStopped) => break Err(InferError::WorkerStopped),
            Err(failure) => break Err(failure),
        }
        if stats_interval.is_some_and(|interval| last_stats.elapsed() >= interval) {
            last_stats = Instant::now();
            let report = state.report(&assembler, started);
            info!("{}", report.line());
            write_json(args.stats_json.as_deref(), &report)?;
        }
        if args.exit_at_end && state.end_seen && state.jobs_in_flight == 0 {
            info!("event stream ended; last forecast published");
            break Ok(());
        }
    };

    slot.close();
    if worker.join().is_err() {
        error!("the inference thread panicked");
    }
    // Forecasts finished while shutting down still go out.
    if outcome.is_ok() {
        state.publish_results(&results, &forecasts)?;
    }
    let report = state.report(&assembler, started);
    write_json(args.stats_json.as_deref(), &report)?;
    outcome.map(|()| report)
}

/// What a look at the inference thread's results found.
enum Published {
    Nothing,
    Forecasts,
    /// The inference thread went away with windows still in flight.
    WorkerStopped,
}

struct LoopState {
    description: RunDescription,
    horizons_us: Vec<i64>,
    counters: InferCounters,
    current_stream: Option<(u64, SensorSize)>,
    next_event_index: u64,
    /// Changes with every new stream or restart; the worker resets the recurrent state when
    /// it sees a new epoch, even if the first window of the epoch was skipped.
    stream_epoch: u64,
    end_seen: bool,
    /// Jobs handed to the worker whose result has not come back (displaced ones excluded).
    jobs_in_flight: u64,
    forecast_sequence: u64,
    closed: Vec<ClosedWindow>,
    metrics: Option<InferMetrics>,
}

impl LoopState {
    fn receive_batches(
        &mut self,
        events: &SliceSubscriber<Event, BatchHeader>,
        assembler: &mut WindowAssembler,
        slot: &WindowHandover<WindowJob>,
        every_window: bool,
    ) -> Result<u32, InferError> {
        events.clear_wakeups();
        let mut batches = 0;
        while let Some(sample) = events.receive()? {
            batches += 1;
            // Copied before it is checked: the publisher may still write the shared memory.
            let header = *sample.user_header();
            if let Err(error) = header.validate(sample.payload().len()) {
                self.counters.batches_rejected += 1;
                warn!(%error, "batch ignored");
                continue;
            }
            self.note_batch(&header, assembler);
            assembler.push(
                sample.payload(),
                header.t_begin_us,
                header.t_end_us,
                &mut self.closed,
            );
            drop(sample);
            if every_window && header.is_end_of_stream() {
                assembler.close_at_stream_end(header.t_end_us, &mut self.closed);
            }
            let closed_at = Instant::now();
            for window in self.closed.drain(..) {
                let job = WindowJob {
                    window,
                    stream_id: header.stream_id,
                    sensor: header.sensor(),
                    stream_epoch: self.stream_epoch,
                    closed_at,
                };
                self.counters.windows_closed += 1;
                self.jobs_in_flight += 1;
                let skipped = slot.put(job).is_some();
                if skipped {
                    self.counters.windows_skipped_busy += 1;
                    self.jobs_in_flight -= 1;
                }
                if let Some(metrics) = &self.metrics {
                    metrics.record_window(skipped);
                }
            }
            if header.is_end_of_stream() {
                self.end_seen = true;
            }
        }
        Ok(batches)
    }

    fn note_batch(&mut self, header: &BatchHeader, assembler: &mut WindowAssembler) {
        self.counters.batches_received += 1;
        self.counters.events_received += header.event_count;
        if let Some(metrics) = &self.metrics {
            metrics.record_events(header.event_count);
        }
        let sensor = header.sensor();
        let new_stream = self.current_stream != Some((header.stream_id, sensor));
        if new_stream {
            self.counters.streams_started += 1;
            info!(stream_id = header.stream_id, %sensor, "new event stream");
            assembler.reset();
            self.stream_epoch += 1;
            self.end_seen = false;
            self.current_stream = Some((header.stream_id, sensor));
        } else if header.is_restart() {
            // Event time goes on across a loop, so the windows do too (a recording shorter
            // than a window still closes them); the scene does not, so the state starts over.
            self.stream_epoch += 1;
        } else if header.has_gap() || header.first_event_index > self.next_event_index {
            self.counters.gaps_detected += 1;
            warn!(
                missing_events = header
                    .first_event_index
                    .saturating_sub(self.next_event_index),
                sequence = header.sequence,
                "gap in the event stream"
            );
        }
        self.next_event_index = header.end_event_index();
    }

    /// Publishes every finished forecast.
    fn publish_results(
        &mut self,
        results: &Receiver<Result<ForecastReady, WorkerError>>,
        forecasts: &SlicePublisher<u64, ForecastHeader>,
    ) -> Result<Published, InferError> {
        let mut published = Published::Nothing;
        loop {
            let ready = match results.try_recv() {
                Ok(result) => result?,
                Err(TryRecvError::Empty) => return Ok(published),
                Err(TryRecvError::Disconnected) if self.jobs_in_flight == 0 => {
                    return Ok(published)
                }
                Err(TryRecvError::Disconnected) => return Ok(Published::WorkerStopped),
            };
            published = Published::Forecasts;
            self.jobs_in_flight = self.jobs_in_flight.saturating_sub(1);
            let header = self.header_for(&ready);
            let delivery = forecasts.publish_with(header, ready.mask_words.len(), |words| {
                words.copy_from_slice(&ready.mask_words)
            })?;
            self.counters.record_forecast(&ready, delivery.recipients);
            if let Some(metrics) = &self.metrics {
                metrics.record_forecast(&ready);
            }
            self.forecast_sequence += 1;
        }
    }

    fn header_for(&self, ready: &ForecastReady) -> ForecastHeader {
        let mut horizons_us = [0i64; MAX_HORIZONS];
        horizons_us[..self.horizons_us.len()].copy_from_slice(&self.horizons_us);
        ForecastHeader {
            sequence: self.forecast_sequence,
            model_id: self.description.model_id,
            source_stream_id: ready.stream_id,
            reference_time_us: ready.reference_time_us,
            window_start_us: ready.window_start_us,
            horizons_us,
            model_runtime_us: ready.processing().as_micros() as u64,
            published_at_wall_us: clock::wall_us(),
            published_at_monotonic_us: clock::monotonic_us(),
            width: ready.sensor.width,
            height: ready.sensor.height,
            horizon_count: self.horizons_us.len() as u32,
            words_per_mask: words_for(ready.sensor.pixels()) as u32,
            reserved: 0,
        }
    }

    fn report(&self, assembler: &WindowAssembler, started: Instant) -> InferReport {
        InferReport::new(
            &self.description,
            &self.counters,
            assembler.skipped_silent_windows(),
            started.elapsed().as_secs_f64(),
        )
    }
}

fn describe(mode: WindowMode) -> String {
    match mode {
        WindowMode::Duration {
            window_us,
            stride_us,
        } => format!(
            "{} ms windows every {} ms of event time",
            window_us as f64 / 1000.0,
            stride_us as f64 / 1000.0
        ),
        WindowMode::EventCount { events } => format!("windows of {events} events"),
    }
}

fn write_json(path: Option<&Path>, report: &InferReport) -> Result<(), InferError> {
    let Some(path) = path else {
        return Ok(());
    };
    let json = serde_json::to_string_pretty(report).expect("the report serialises");
    std::fs::write(path, json + "\n").map_err(|source| InferError::StatsJson {
        path: path.to_owned(),
        source,
    })
}
