//! `evgate-gate` as a library (a typed [`Config`] and [`run`]): keeps or suppresses every event of `<domain>/<camera>/events` by the forecast
//! mask of its time (from `.../forecast`), publishes the kept and suppressed events (and a keep
//! bitmap on request) and its counters on `.../stats`. It sleeps in an iceoryx2 WaitSet until a
//! batch or a forecast arrives.

mod accounting;
mod error;
mod forecast_store;
mod lock_step;
mod serve_kept;
mod waiting;

pub use error::RunError;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use evgate_core::{Event, Forecast, GateMode, Judge, NoForecast, Policy};
use evgate_ipc::metrics::{self, MetricsError, MetricsServer, PipelineCounters};
use evgate_ipc::stats::NOT_MEASURED;
use evgate_ipc::{
    clock, create_node, pin_current_thread, BatchFlags, BatchHeader, ForecastHeader,
    LatestPublisher, Overflow, PipelineNames, PipelineStats, Qos, SlicePublisher, SliceSubscriber,
    StopChecks, Stream, WaitStrategy,
};
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::Registry;
use serde::Serialize;
use serve_kept::KeptServer;
use tracing::{info, warn};

use accounting::{Accounting, Admission};
use forecast_store::StoredForecast;
use lock_step::LockStep;

/// Output streams the gate can publish.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Output {
    /// `<domain>/<camera>/kept`: the events that pass.
    Kept,
    /// `<domain>/<camera>/suppressed`: the events that do not.
    Suppressed,
    /// `<domain>/<camera>/keep-bitmap`: one bit per input event, 1 = passes.
    KeepBitmap,
}

/// Keep or suppress each event of an evgate pipeline by its forecast mask.
#[derive(Parser, Debug, Clone, Serialize)]
#[command(name = "evgate-gate", version, about)]
#[serde(rename_all = "kebab-case")]
pub struct Config {
    /// TOML file of defaults: its keys are this command's flags without the dashes, a string
    /// or number for a flag that takes a value (an array for a list), true or false for a
    /// switch; a flag given on the command line overrides its key.
    #[arg(long)]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Pipeline domain: the first part of every service name.
    #[arg(long, default_value = "evgate")]
    pub domain: String,
    /// Camera name within the domain: the second part of every service name.
    #[arg(long, default_value = "cam0")]
    pub camera: String,
    /// Which events pass.
    #[arg(long, value_enum, default_value = "keep-moving-objects")]
    pub mode: GateMode,
    /// Fate of events no valid forecast judges: pass, drop or last-mask.
    #[arg(long, value_enum, default_value = "pass")]
    pub no_forecast: NoForecast,
    /// Under --no-forecast last-mask, the largest distance between an event and the latest
    /// forecast's time for which its masks are still used, milliseconds.
    #[arg(long, default_value_t = 200)]
    pub last_mask_max_age_ms: u64,
    /// Streams to publish, comma-separated: kept, suppressed, keep-bitmap.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Output::Kept, Output::Suppressed])]
    pub outputs: Vec<Output>,
    /// What the outputs (the --serve-kept network stream too) do when a consumer's buffer is
    /// full: drop-and-count (a slow consumer never stalls the gate) or block (up to
    /// --block-timeout-ms).
    #[arg(long, value_enum, default_value = "drop-and-count")]
    pub overflow: Overflow,
    /// Longest wait for a full consumer under --overflow block, milliseconds.
    #[arg(long, default_value_t = 500)]
    pub block_timeout_ms: u64,
    /// Input batches that may wait for the gate (1 to 16).
    #[arg(long, default_value_t = 16)]
    pub input_buffer: usize,
    /// Period of the stats publication, milliseconds.
    #[arg(long, default_value_t = 100)]
    pub stats_interval_ms: u64,
    /// Judge every event by the forecast of the newest window that ended at or before it,
    /// holding each batch (copied) until that forecast is in, as `evgate eval` does: with
    /// `evgate-infer --every-window` on a replay, the gate then keeps exactly the events the
    /// evaluation keeps. Without it, a batch is judged at once by the newest forecast.
    #[arg(long)]
    pub lock_step: bool,
    /// Exit once the end-of-stream batch has been gated.
    #[arg(long)]
    pub exit_at_end_of_stream: bool,
    /// How to wait for batches and forecasts: event (sleep until notified) or busy-poll (never
    /// sleep: lowest latency, one core at 100 %; give it its own core with --cpu).
    #[arg(long, value_enum, default_value = "event")]
    pub wait: WaitStrategy,
    /// Pin the gating thread to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Serve Prometheus metrics at http://HOST:PORT/metrics: the event and forecast
    /// counters (as of the latest stats publication) and the prediction age per batch.
    #[arg(long)]
    pub metrics_addr: Option<String>,
    /// Also serve the kept events as an AEDAT 4 network stream on tcp://HOST:PORT or
    /// unix:///PATH, for DV tools and dv-processing's NetworkReader (the header goes out once
    /// the first batch gives the sensor size).
    #[arg(long)]
    pub serve_kept: Option<String>,
    /// After the last batch, how long --serve-kept holds its client connections open before it
    /// closes them, milliseconds: dv-processing's NetworkReader discards what it received but
    /// has not yet handed out once the server closes, so a reader that lags gets this long to
    /// catch up.
    #[arg(long, default_value_t = 1000)]
    pub serve_kept_linger_ms: u64,
    /// Print the final counters as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// What `--metrics-addr` serves.
struct GateMetrics {
    counters: PipelineCounters,
    prediction_age: Histogram,
    /// Clients of `--serve-kept`, when it is on.
    kept_stream_clients: Option<Gauge>,
    _server: MetricsServer,
}

impl GateMetrics {
    fn serve(addr: &str, serving_kept: bool) -> Result<Self, MetricsError> {
        let counters = PipelineCounters::default();
        let prediction_age = metrics::duration_histogram();
        let mut registry = Registry::default();
        counters.register(&mut registry);
        registry.register(
            "evgate_prediction_age_seconds",
            "per batch a forecast judged: the batch's end time less the forecast's reference time",
            prediction_age.clone(),
        );
        let kept_stream_clients = serving_kept.then(|| {
            let gauge = Gauge::default();
            registry.register(
                "evgate_kept_stream_clients",
                "clients of the --serve-kept AEDAT 4 network stream",
                gauge.clone(),
            );
            gauge
        });
        Ok(Self {
            counters,
            prediction_age,
            kept_stream_clients,
            _server: MetricsServer::serve(addr, registry)?,
        })
    }
}

/// What the gate did, printed at exit.
#[derive(Debug, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct GateSummary {
    pub stats: PipelineStats,
    pub balanced: bool,
    pub wall_s: f64,
    /// `end-of-stream`, `signal` or `error`.
    pub ended_by: &'static str,
    /// Under --serve-kept: batches not sent because the network fell behind (null without it).
    pub kept_stream_batches_not_sent: Option<u64>,
    /// Under --serve-kept: clients disconnected for not taking a packet within a second.
    pub kept_stream_clients_dropped: Option<u64>,
}

/// The gate's ports and state.
struct Gate {
    mode: GateMode,
    policy: Policy,
    kept: Option<SlicePublisher<Event, BatchHeader>>,
    suppressed: Option<SlicePublisher<Event, BatchHeader>>,
    keep_bitmap: Option<SlicePublisher<u64, BatchHeader>>,
    stats: LatestPublisher<PipelineStats>,
    accounting: Accounting,
    forecast: Option<StoredForecast>,
    /// Under --lock-step: the held batches and the forecasts that will judge them.
    lock_step: Option<LockStep>,
    judge: Judge,
    /// Forecast counters survive a change of input stream.
    forecasts_received: u64,
    forecasts_rejected: u64,
    latest_model_runtime_us: i64,
    stats_interval: Duration,
    stats_published_at: Instant,
    stop_checks: StopChecks,
    metrics: Option<GateMetrics>,
    kept_server: Option<KeptServer>,
}

/// Gates until the end of the stream (under --exit-at-end-of-stream) or SIGINT/SIGTERM.
pub fn run(args: &Config) -> Result<GateSummary, RunError> {
    if args.stats_interval_ms == 0 {
        return Err(RunError::StatsInterval);
    }
    let names = PipelineNames::new(&args.domain, &args.camera)?;
    if let Some(cpu) = args.cpu {
        pin_current_thread(cpu)?;
    }
    let node = create_node("evgate-gate")?;
    let input_qos = Qos {
        buffer_size: args.input_buffer,
        ..Qos::default()
    };
    let output_qos = Qos {
        overflow: args.overflow,
        block_timeout_ms: args.block_timeout_ms,
        ..Qos::default()
    };
    // The subscribers live outside `Gate`: the waitset borrows their listeners while the
    // callback mutates the gate.
    let events =
        SliceSubscriber::<Event, BatchHeader>::open(&node, &names, Stream::Events, &input_qos)?;
    let forecasts = SliceSubscriber::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )?;
    let wants = |output| args.outputs.contains(&output);
    let mut gate = Gate {
        mode: args.mode,
        policy: Policy {
            no_forecast: args.no_forecast,
            last_mask_max_age: Duration::from_millis(args.last_mask_max_age_ms),
        },
        kept: wants(Output::Kept)
            .then(|| SlicePublisher::open(&node, &names, Stream::Kept, &output_qos))
            .transpose()?,
        suppressed: wants(Output::Suppressed)
            .then(|| SlicePublisher::open(&node, &names, Stream::Suppressed, &output_qos))
            .transpose()?,
        keep_bitmap: wants(Output::KeepBitmap)
            .then(|| SlicePublisher::open(&node, &names, Stream::KeepBitmap, &output_qos))
            .transpose()?,
        stats: LatestPublisher::open(&node, &names, Stream::Stats)?,
        accounting: Accounting::default(),
        forecast: None,
        lock_step: args.lock_step.then(LockStep::default),
        judge: Judge::default(),
        forecasts_received: 0,
        forecasts_rejected: 0,
        latest_model_runtime_us: NOT_MEASURED,
        stats_interval: Duration::from_millis(args.stats_interval_ms),
        stats_published_at: Instant::now(),
        stop_checks: StopChecks::default(),
        metrics: None,
        kept_server: None,
    };
    gate.metrics = args
        .metrics_addr
        .as_deref()
        .map(|addr| GateMetrics::serve(addr, args.serve_kept.is_some()))
        .transpose()?;
    gate.kept_server = args
        .serve_kept
        .as_deref()
        .map(|endpoint| {
            let gauge = gate
                .metrics
                .as_ref()
                .and_then(|m| m.kept_stream_clients.clone());
            KeptServer::start(
                endpoint,
                gauge,
                args.overflow,
                Duration::from_millis(args.block_timeout_ms),
                Duration::from_millis(args.serve_kept_linger_ms),
            )
        })
        .transpose()?;
    info!(
        events = events.service_name(),
        mode = ?gate.mode,
        policy = ?gate.policy,
        "gating"
    );

    let started = Instant::now();
    let ended_by = match args.wait {
        WaitStrategy::Event => gate.run_on_events(&node, &events, &forecasts, args)?,
        WaitStrategy::BusyPoll => gate.run_busy_polling(&node, &events, &forecasts, args)?,
    };
    if gate
        .lock_step
        .as_ref()
        .is_some_and(|held| held.held_batches() > 0)
    {
        // Stopped before their forecasts came: judged by those that did.
        gate.release_held(&node, true)?;
        gate.publish_stats()?;
    }
    let stats = gate.accounting.stats;
    let kept_stream_batches_not_sent = gate.kept_server.as_ref().map(KeptServer::batches_not_sent);
    let kept_stream_clients_dropped = gate.kept_server.as_ref().map(KeptServer::clients_dropped);
    // Sends what is queued to the network clients before the summary reports the run done.
    drop(gate);
    Ok(GateSummary {
        balanced: stats.is_balanced(),
        stats,
        wall_s: started.elapsed().as_secs_f64(),
        ended_by,
        kept_stream_batches_not_sent,
        kept_stream_clients_dropped: kept_stream_clients_dropped
            .map(|dropped| dropped.load(std::sync::atomic::Ordering::Relaxed)),
    })
}

/// How a drain of the events queue ended.
enum Drained {
    /// The queue is empty.
    Empty,
    /// The end-of-stream batch was among the batches.
    EndOfStream,
    /// A termination signal arrived.
    Signal,
}

impl Gate {
    /// Keeps the newest valid forecast; returns how many forecasts arrived.
    fn take_forecasts(
        &mut self,
        forecasts: &SliceSubscriber<u64, ForecastHeader>,
    ) -> Result<u32, RunError> {
        let mut received = 0;
        while let Some(sample) = forecasts.receive()? {
            received += 1;
            self.forecasts_received += 1;
            // The header is copied out before it is checked: its publisher may still write the
            // shared memory.
            match StoredForecast::copy_from(*sample.user_header(), sample.payload()) {
                Ok(forecast) => {
                    self.latest_model_runtime_us = forecast.header.model_runtime_us as i64;
                    match &mut self.lock_step {
                        Some(lock_step) => lock_step.add_forecast(forecast),
                        None => self.forecast = Some(forecast),
                    }
                }
                Err(error) => {
                    self.forecasts_rejected += 1;
                    warn!(%error, "forecast ignored");
                }
            }
        }
        Ok(received)
    }

    /// Gates every waiting batch, stopping early for a signal: under a sustained flood the
    /// queue never empties, so this loop never returns to the waitset that watches for them.
    /// Returns how the drain ended and how many batches it took.
    fn drain_events(
        &mut self,
        node: &evgate_ipc::Node,
        events: &SliceSubscriber<Event, BatchHeader>,
        forecasts: &SliceSubscriber<u64, ForecastHeader>,
    ) -> Result<(Drained, u32), RunError> {
        let mut reached_end = false;
        let mut batches = 0u32;
        while let Some(sample) = events.receive()? {
            batches = batches.wrapping_add(1);
            if self.stop_checks.requested(node) {
                return Ok((Drained::Signal, batches));
            }
            // A forecast that arrived meanwhile judges this batch already.
            self.take_forecasts(forecasts)?;
            // Copied before it is checked: the publisher may still write the shared memory.
            let header = *sample.user_header();
            if let Err(error) = header.validate(sample.payload().len()) {
                // Its events show as lost at the next good batch.
                warn!(%error, "batch ignored");
                continue;
            }
            match &mut self.lock_step {
                Some(lock_step) => {
                    lock_step.hold(header, sample.payload());
                    drop(sample);
                    reached_end |= self.release_held(node, false)?;
                }
                None => {
                    let stored = self.forecast.take();
                    let forecast = stored
                        .as_ref()
                        .filter(|forecast| forecast.describes(&header))
                        .map(StoredForecast::forecast);
                    let gated =
                        self.gate_batch(node, &header, sample.payload(), forecast.as_slice());
                    self.forecast = stored;
                    reached_end |= gated?;
                }
            }
            // Under a sustained flood this loop does not return to the waitset, whose interval
            // would then never fire.
            if self.stats_published_at.elapsed() >= self.stats_interval {
                self.publish_stats()?;
            }
        }
        // Forecasts that arrived after the last batch may release held ones.
        reached_end |= self.release_held(node, false)?;
        let drained = if reached_end {
            Drained::EndOfStream
        } else {
            Drained::Empty
        };
        Ok((drained, batches))
    }

    /// Gates the held batches whose forecasts are all in (every held batch when `flush`);
    /// returns whether the end-of-stream batch was among them. Nothing to do without
    /// --lock-step.
    fn release_held(&mut self, node: &evgate_ipc::Node, flush: bool) -> Result<bool, RunError> {
        let Some(mut lock_step) = self.lock_step.take() else {
            return Ok(false);
        };
        let mut reached_end = Ok(false);
        while let Some(batch) = lock_step.next_ready(flush) {
            let forecasts = lock_step.forecasts_for(&batch);
            let gated = self.gate_batch(node, &batch.header, &batch.events, &forecasts);
            drop(forecasts);
            lock_step.judged(&batch);
            match gated {
                Ok(end) => reached_end = reached_end.map(|before| before | end),
                Err(error) => {
                    reached_end = Err(error);
                    break;
                }
            }
        }
        self.lock_step = Some(lock_step);
        reached_end
    }

    /// Judges one batch, each event by the newest of `forecasts` (those of its stream and
    /// sensor, oldest first) at or before it, and publishes the outcome.
    fn gate_batch(
        &mut self,
        node: &evgate_ipc::Node,
        header: &BatchHeader,
        events: &[Event],
        forecasts: &[Forecast<'_>],
    ) -> Result<bool, RunError> {
        let lost_events = match self.accounting.admit(header) {
            Admission::Accept { lost_events } => lost_events,
            Admission::Duplicate => return Ok(false),
        };
        let kernel_start = Instant::now();
        let verdict = self
            .judge
            .judge_by_time(events, forecasts, self.mode, self.policy);
        let kernel_ns = kernel_start.elapsed().as_nanos() as i64;
        // Measured from the newest forecast at or before the batch's last event.
        let references = forecasts.iter().map(|f| f.horizons.reference_time_us());
        let newest_reference = references
            .clone()
            .rfind(|&reference| events.last().is_none_or(|last| reference <= last.t))
            .or_else(|| references.clone().next());
        let prediction_age_us =
            newest_reference.map_or(NOT_MEASURED, |reference| header.t_end_us - reference);
        if let (Some(metrics), Some(_)) = (&self.metrics, newest_reference) {
            metrics
                .prediction_age
                .observe(prediction_age_us as f64 * 1e-6);
        }
        if let Some(server) = &self.kept_server {
            let mut kept = Vec::with_capacity(verdict.passed() as usize);
            self.judge.select(events, true, &mut kept);
            server.send(header.sensor(), kept);
        }
        self.accounting.record(&verdict);

        let mut out_header = *header;
        if lost_events > 0 {
            out_header.flags |= BatchFlags::GAP_DETECTED;
        }
        let mut undelivered = 0;
        let passed = verdict.passed() as usize;
        for (output, passes, count) in [
            (&self.kept, true, passed),
            (&self.suppressed, false, events.len() - passed),
        ] {
            let Some(output) = output else { continue };
            let outcome = output.publish_written(out_header, count, |writer| {
                self.judge.select(events, passes, writer)
            })?;
            // The count comes from the same pass bits the selection reads, so a mismatch is a
            // bug; it must not pass as silently zeroed or lost events.
            if outcome.written != count || outcome.overflowed != 0 {
                return Err(RunError::SelectionMismatch {
                    written: outcome.written,
                    overflowed: outcome.overflowed,
                    service: output.service_name().to_owned(),
                    counted: count,
                });
            }
            undelivered += outcome.delivery.undelivered;
        }
        if let Some(keep_bitmap) = &self.keep_bitmap {
            undelivered += keep_bitmap
                .publish(out_header, self.judge.pass_bits())?
                .undelivered;
        }
        if undelivered > 0 {
            // A consumer that stopped taking samples may have died: free its port so later
            // batches do not wait for it (under --overflow block, one timeout per batch).
            node.try_cleanup_dead_nodes();
        }
        let stats = &mut self.accounting.stats;
        stats.output_samples_undelivered += undelivered as u64;
        stats.forecasts_used += u64::from(verdict.forecast_used);
        // The latest-figures describe real batches, not the empty end-of-stream marker.
        if let Some(last) = events.last() {
            stats.latest_event_time_us = last.t;
            stats.latest_prediction_age_us = prediction_age_us;
            stats.latest_kernel_ns = kernel_ns;
            stats.latest_gate_latency_ns =
                clock::monotonic_ns().saturating_sub(header.published_at_monotonic_ns) as i64;
        }
        if header.is_end_of_stream() {
            self.publish_stats()?;
            info!(stats = ?self.accounting.stats, "end of stream gated");
            return Ok(true);
        }
        Ok(false)
    }

    fn publish_stats(&mut self) -> Result<(), RunError> {
        let stats = &mut self.accounting.stats;
        stats.forecasts_received = self.forecasts_received;
        stats.forecasts_rejected = self.forecasts_rejected;
        stats.latest_model_runtime_us = self.latest_model_runtime_us;
        stats.published_at_monotonic_us = clock::monotonic_us();
        self.stats.publish(*stats)?;
        if let Some(metrics) = &self.metrics {
            metrics.counters.update(stats);
        }
        stats.sequence += 1;
        self.stats_published_at = Instant::now();
        Ok(())
    }
}
