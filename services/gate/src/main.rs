//! `evgate-gate`: keeps or suppresses every event of `<domain>/<camera>/events` by the forecast
//! mask of its time (from `.../forecast`), publishes the kept and suppressed events (and a keep
//! bitmap on request) and its counters on `.../stats`. It sleeps in an iceoryx2 WaitSet until a
//! batch or a forecast arrives.

mod accounting;
mod forecast_store;
mod judge;
mod policy;

use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use evgate_core::{Event, GateMode};
use evgate_ipc::stats::NOT_MEASURED;
use evgate_ipc::{
    clock, create_node, BatchFlags, BatchHeader, ForecastHeader, LatestPublisher, Overflow,
    PipelineNames, PipelineStats, Qos, SlicePublisher, SliceSubscriber, Stream,
};
use iceoryx2::prelude::{CallbackProgression, WaitSetAttachmentId, WaitSetBuilder};
use iceoryx2::waitset::WaitSetRunResult;
use serde::Serialize;
use tracing::{info, warn};

use accounting::{Accounting, Admission};
use forecast_store::StoredForecast;
use judge::Judge;
use policy::{NoForecast, Policy};

/// Which events pass the gate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum ModeArg {
    /// Keep the events of independently moving objects, suppress the ego-motion events.
    KeepMovingObjects,
    /// Keep the ego-motion events (e.g. for visual odometry), suppress the moving objects.
    KeepEgoMotion,
}

/// Output streams the gate can publish.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Output {
    /// `<domain>/<camera>/kept`: the events that pass.
    Kept,
    /// `<domain>/<camera>/suppressed`: the events that do not.
    Suppressed,
    /// `<domain>/<camera>/keep-bitmap`: one bit per input event, 1 = passes.
    KeepBitmap,
}

/// Keep or suppress each event of an evgate pipeline by its forecast mask.
#[derive(Parser, Debug)]
#[command(name = "evgate-gate", version, about)]
struct Args {
    /// Pipeline domain: the first part of every service name.
    #[arg(long, default_value = "evgate")]
    domain: String,
    /// Camera name within the domain: the second part of every service name.
    #[arg(long, default_value = "cam0")]
    camera: String,
    /// Which events pass.
    #[arg(long, value_enum, default_value = "keep-moving-objects")]
    mode: ModeArg,
    /// Fate of events no valid forecast judges: pass, drop or last-mask.
    #[arg(long, value_enum, default_value = "pass")]
    no_forecast: NoForecast,
    /// Under --no-forecast last-mask, the largest distance between an event and the latest
    /// forecast's time for which its masks are still used, milliseconds.
    #[arg(long, default_value_t = 200)]
    last_mask_max_age_ms: u64,
    /// Streams to publish, comma-separated: kept, suppressed, keep-bitmap.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Output::Kept, Output::Suppressed])]
    outputs: Vec<Output>,
    /// What the outputs do when a consumer's buffer is full: drop-and-count (a slow consumer
    /// never stalls the gate) or block (up to --block-timeout-ms).
    #[arg(long, value_enum, default_value = "drop-and-count")]
    overflow: Overflow,
    /// Longest wait for a full consumer under --overflow block, milliseconds.
    #[arg(long, default_value_t = 500)]
    block_timeout_ms: u64,
    /// Input batches that may wait for the gate (1 to 16).
    #[arg(long, default_value_t = 16)]
    input_buffer: usize,
    /// Period of the stats publication, milliseconds.
    #[arg(long, default_value_t = 100)]
    stats_interval_ms: u64,
    /// Exit once the end-of-stream batch has been gated.
    #[arg(long)]
    exit_at_end_of_stream: bool,
    /// Print the final counters as JSON on stdout.
    #[arg(long)]
    json: bool,
}

/// Printed at exit.
#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct GateSummary {
    stats: PipelineStats,
    balanced: bool,
    wall_s: f64,
    /// `end-of-stream`, `signal` or `error`.
    ended_by: &'static str,
}

fn main() -> anyhow::Result<()> {
    evgate_ipc::init_service_logging("info,iceoryx2_bb_loggers=error");
    let args = Args::parse();
    if args.stats_interval_ms == 0 {
        anyhow::bail!("--stats-interval-ms = 0 must be at least 1");
    }
    let summary = run(&args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        info!(stats = ?summary.stats, balanced = summary.balanced, "gate finished");
    }
    Ok(())
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
    judge: Judge,
    /// Forecast counters survive a change of input stream.
    forecasts_received: u64,
    forecasts_rejected: u64,
    latest_model_runtime_us: i64,
    stats_interval: Duration,
    stats_published_at: Instant,
}

fn run(args: &Args) -> anyhow::Result<GateSummary> {
    let names = PipelineNames::new(&args.domain, &args.camera)?;
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
        mode: match args.mode {
            ModeArg::KeepMovingObjects => GateMode::KeepMovingObjects,
            ModeArg::KeepEgoMotion => GateMode::KeepEgoMotion,
        },
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
        judge: Judge::default(),
        forecasts_received: 0,
        forecasts_rejected: 0,
        latest_model_runtime_us: NOT_MEASURED,
        stats_interval: Duration::from_millis(args.stats_interval_ms),
        stats_published_at: Instant::now(),
    };
    info!(
        events = events.service_name(),
        mode = ?gate.mode,
        policy = ?gate.policy,
        "gating"
    );

    let waitset = WaitSetBuilder::new()
        .create::<evgate_ipc::Service>()
        .context("cannot create the iceoryx2 waitset")?;
    let events_guard = waitset
        .attach_notification(events.listener())
        .context("cannot attach the events listener to the waitset")?;
    let forecast_guard = waitset
        .attach_notification(forecasts.listener())
        .context("cannot attach the forecast listener to the waitset")?;
    let stats_tick = waitset
        .attach_interval(Duration::from_millis(args.stats_interval_ms))
        .context("cannot attach the stats interval to the waitset")?;

    let started = Instant::now();
    let mut failure = None;
    let mut reached_end = false;
    let mut stopped_by_signal = false;
    let on_wakeup = |attachment: WaitSetAttachmentId<evgate_ipc::Service>| {
        let step = if attachment.has_event_from(&forecast_guard) {
            forecasts.clear_wakeups();
            gate.take_forecasts(&forecasts).map(|()| false)
        } else if attachment.has_event_from(&events_guard) {
            events.clear_wakeups();
            gate.drain_events(&node, &events, &forecasts)
                .map(|drained| match drained {
                    Drained::EndOfStream => true,
                    Drained::Signal => {
                        stopped_by_signal = true;
                        true
                    }
                    Drained::Empty => false,
                })
        } else if attachment.has_event_from(&stats_tick) {
            gate.publish_stats().map(|()| false)
        } else {
            Ok(false)
        };
        match step {
            Ok(true) if stopped_by_signal => CallbackProgression::Stop,
            Ok(true) if args.exit_at_end_of_stream => {
                reached_end = true;
                CallbackProgression::Stop
            }
            Ok(_) => CallbackProgression::Continue,
            Err(error) => {
                failure = Some(error);
                CallbackProgression::Stop
            }
        }
    };
    let outcome = evgate_ipc::run_until_stopped(&waitset, on_wakeup)
        .context("waiting on the iceoryx2 waitset failed")?;
    drop(events_guard);
    drop(forecast_guard);
    drop(stats_tick);
    gate.publish_stats()?;
    if let Some(error) = failure {
        return Err(error);
    }
    let ended_by = match outcome {
        WaitSetRunResult::TerminationRequest => "signal",
        _ if reached_end => "end-of-stream",
        _ => "signal",
    };
    let stats = gate.accounting.stats;
    Ok(GateSummary {
        balanced: stats.is_balanced(),
        stats,
        wall_s: started.elapsed().as_secs_f64(),
        ended_by,
    })
}

/// Batches gated between two looks for a termination signal.
const SIGNAL_CHECK_BATCHES: u32 = 16;

/// How a drain of the events queue ended.
enum Drained {
    /// The queue is empty.
    Empty,
    /// The end-of-stream batch was among the batches.
    EndOfStream,
    /// A termination signal arrived.
    Signal,
}

/// The stored forecast when it describes this stream and sensor.
fn forecast_for<'a>(
    forecast: Option<&'a StoredForecast>,
    header: &BatchHeader,
) -> Option<&'a StoredForecast> {
    forecast.filter(|forecast| {
        forecast.header.source_stream_id == header.stream_id && forecast.sensor() == header.sensor()
    })
}

impl Gate {
    /// Keeps the newest valid forecast.
    fn take_forecasts(
        &mut self,
        forecasts: &SliceSubscriber<u64, ForecastHeader>,
    ) -> anyhow::Result<()> {
        while let Some(sample) = forecasts.receive()? {
            self.forecasts_received += 1;
            // The header is copied out before it is checked: its publisher may still write the
            // shared memory.
            match StoredForecast::copy_from(*sample.user_header(), sample.payload()) {
                Ok(forecast) => {
                    self.latest_model_runtime_us = forecast.header.model_runtime_us as i64;
                    self.forecast = Some(forecast);
                }
                Err(error) => {
                    self.forecasts_rejected += 1;
                    warn!(%error, "forecast ignored");
                }
            }
        }
        Ok(())
    }

    /// Gates every waiting batch, stopping early for a signal: under a sustained flood the
    /// queue never empties, so this loop never returns to the waitset that watches for them.
    fn drain_events(
        &mut self,
        node: &evgate_ipc::Node,
        events: &SliceSubscriber<Event, BatchHeader>,
        forecasts: &SliceSubscriber<u64, ForecastHeader>,
    ) -> anyhow::Result<Drained> {
        let mut reached_end = false;
        let mut batches = 0u32;
        while let Some(sample) = events.receive()? {
            batches = batches.wrapping_add(1);
            if batches.is_multiple_of(SIGNAL_CHECK_BATCHES)
                && evgate_ipc::stop_requested(node, Duration::ZERO)
            {
                return Ok(Drained::Signal);
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
            reached_end |= self.gate_batch(node, &header, sample.payload())?;
            // Under a sustained flood this loop does not return to the waitset, whose interval
            // would then never fire.
            if self.stats_published_at.elapsed() >= self.stats_interval {
                self.publish_stats()?;
            }
        }
        Ok(if reached_end {
            Drained::EndOfStream
        } else {
            Drained::Empty
        })
    }

    fn gate_batch(
        &mut self,
        node: &evgate_ipc::Node,
        header: &BatchHeader,
        events: &[Event],
    ) -> anyhow::Result<bool> {
        let lost_events = match self.accounting.admit(header) {
            Admission::Accept { lost_events } => lost_events,
            Admission::Duplicate => return Ok(false),
        };
        let kernel_start = Instant::now();
        let forecast = forecast_for(self.forecast.as_ref(), header);
        let verdict = self.judge.judge(events, forecast, self.mode, self.policy);
        let kernel_ns = kernel_start.elapsed().as_nanos() as i64;
        let prediction_age_us = forecast.map_or(NOT_MEASURED, |forecast| {
            header.t_end_us - forecast.header.reference_time_us
        });
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
                self.judge.write_selected(events, passes, writer)
            })?;
            // The count comes from the same pass bits the selection reads, so a mismatch is a
            // bug; it must not pass as silently zeroed or lost events.
            anyhow::ensure!(
                outcome.written == count && outcome.overflowed == 0,
                "gating selected {} events (and {} more that did not fit) for {} where the \
                 verdict counted {count}",
                outcome.written,
                outcome.overflowed,
                output.service_name(),
            );
            undelivered += outcome.delivery.undelivered;
        }
        if let Some(keep_bitmap) = &self.keep_bitmap {
            undelivered += keep_bitmap
                .publish(out_header, &self.judge.pass)?
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

    fn publish_stats(&mut self) -> anyhow::Result<()> {
        let stats = &mut self.accounting.stats;
        stats.forecasts_received = self.forecasts_received;
        stats.forecasts_rejected = self.forecasts_rejected;
        stats.latest_model_runtime_us = self.latest_model_runtime_us;
        stats.published_at_monotonic_us = clock::monotonic_us();
        self.stats.publish(*stats)?;
        stats.sequence += 1;
        self.stats_published_at = Instant::now();
        Ok(())
    }
}
