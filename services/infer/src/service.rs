//! The service loop: the main thread owns the shared-memory ports (iceoryx2 ports stay on the
//! thread that made them), drains the event stream every cycle and publishes finished
//! forecasts; the inference thread works on the newest closed window.

use std::path::Path;
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use evgate_core::{words_for, Event, SensorSize};
use evgate_ipc::{
    clock, create_node, BatchHeader, ForecastHeader, PipelineNames, Qos, SlicePublisher,
    SliceSubscriber, Stream, MAX_HORIZONS,
};
use evgate_model::{ModelRuntime, RuntimeOptions};
use tracing::{error, info, warn};

use crate::args::InferArgs;
use crate::horizons::{horizon_us, resolve_horizons};
use crate::latest_slot::LatestSlot;
use crate::stats::{InferCounters, InferReport, RunDescription};
use crate::windowing::{ClosedWindow, WindowAssembler, WindowMode};
use crate::worker::{ForecastReady, WindowJob, Worker, WorkerError};

/// Runs until SIGINT/SIGTERM (or the end of the stream with `--exit-at-end`) and returns the
/// final stats.
pub fn run(args: &InferArgs) -> anyhow::Result<InferReport> {
    let node = create_node("evgate-infer")?;
    // iceoryx2 installs its SIGINT/SIGTERM handlers on the first wait; doing it now, before the
    // model loads, turns an early Ctrl-C into a clean stop instead of the default kill.
    if evgate_ipc::stop_requested(&node, Duration::ZERO) {
        bail!("stopped by SIGINT or SIGTERM before starting");
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

    let slot = Arc::new(LatestSlot::<WindowJob>::default());
    let (result_sender, results) = mpsc::channel();
    let worker = {
        let slot = Arc::clone(&slot);
        let worker = Worker::new(runtime, horizons_ms.clone(), args.threshold_logit);
        std::thread::Builder::new()
            .name("evgate-infer-model".to_owned())
            .spawn(move || worker.run(slot, result_sender))
            .context("cannot start the inference thread")?
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
    };
    let started = Instant::now();
    let stats_interval =
        (args.stats_interval_s > 0.0).then(|| Duration::from_secs_f64(args.stats_interval_s));
    let mut last_stats = Instant::now();
    let cycle = Duration::from_micros(args.cycle_us.max(1));

    let outcome = loop {
        if evgate_ipc::stop_requested(&node, cycle) {
            info!("stopping on SIGINT or SIGTERM");
            break Ok(());
        }
        if let Err(failure) = state.receive_batches(&events, &mut assembler, &slot) {
            break Err(failure);
        }
        match state.publish_results(&results, &forecasts) {
            Ok(true) => {}
            Ok(false) => break Err(anyhow::anyhow!("the inference thread stopped unexpectedly")),
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
}

impl LoopState {
    fn receive_batches(
        &mut self,
        events: &SliceSubscriber<Event, BatchHeader>,
        assembler: &mut WindowAssembler,
        slot: &LatestSlot<WindowJob>,
    ) -> anyhow::Result<()> {
        events.clear_wakeups();
        while let Some(sample) = events.receive()? {
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
                if slot.put(job).is_some() {
                    self.counters.windows_skipped_busy += 1;
                    self.jobs_in_flight -= 1;
                }
            }
            if header.is_end_of_stream() {
                self.end_seen = true;
            }
        }
        Ok(())
    }

    fn note_batch(&mut self, header: &BatchHeader, assembler: &mut WindowAssembler) {
        self.counters.batches_received += 1;
        self.counters.events_received += header.event_count;
        let sensor = header.sensor();
        let new_stream = self.current_stream != Some((header.stream_id, sensor));
        if new_stream || header.is_restart() {
            if new_stream {
                self.counters.streams_started += 1;
                info!(stream_id = header.stream_id, %sensor, "new event stream");
            }
            assembler.reset();
            self.stream_epoch += 1;
            self.end_seen = false;
            self.current_stream = Some((header.stream_id, sensor));
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

    /// Publishes every finished forecast; `Ok(false)` when the worker has gone away.
    fn publish_results(
        &mut self,
        results: &Receiver<Result<ForecastReady, WorkerError>>,
        forecasts: &SlicePublisher<u64, ForecastHeader>,
    ) -> anyhow::Result<bool> {
        loop {
            let ready = match results.try_recv() {
                Ok(result) => result.context("inference failed")?,
                Err(TryRecvError::Empty) => return Ok(true),
                Err(TryRecvError::Disconnected) => return Ok(self.jobs_in_flight == 0),
            };
            self.jobs_in_flight = self.jobs_in_flight.saturating_sub(1);
            let header = self.header_for(&ready);
            let delivery = forecasts.publish_with(header, ready.mask_words.len(), |words| {
                words.copy_from_slice(&ready.mask_words)
            })?;
            self.counters.record_forecast(&ready, delivery.recipients);
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
            words_per_mask: words_for(ready.sensor) as u32,
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

fn write_json(path: Option<&Path>, report: &InferReport) -> anyhow::Result<()> {
    let Some(path) = path else {
        return Ok(());
    };
    let json = serde_json::to_string_pretty(report)?;
    std::fs::write(path, json + "\n")
        .with_context(|| format!("cannot write the stats to {}", path.display()))
}
