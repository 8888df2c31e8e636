//! End-to-end latency of the gate over shared memory, next to a raw echo of the same payload,
//! under both wait strategies.
//!
//! For batches of 1 k, 10 k and 100 k events: publish a batch on `<domain>/cam/events`, wait
//! until the batch comes back on `.../kept`, and record published → received from the batch
//! header's CLOCK_MONOTONIC stamp (a round trip: two shared-memory hops and the peer's work).
//! Two peers do the middle hop in separate processes: the real `evgate-gate` (a forecast whose
//! masks keep every event, so the output is as large as the input) and a raw echo (this
//! executable with `--echo`: the same ports, the batch copied through without gating). Each
//! runs under `--wait event` (both sides sleep until notified) and `--wait busy-poll` (both
//! sides poll without sleeping), with this process pinned to CPU 0 and the peer to CPU 1. The
//! gate's production judge (`evgate_core::Judge` and the selection of the kept events) is timed
//! on the same batch in this process.
//!
//! `cargo bench -p evgate-benches --bench ipc_latency -- --out target/bench/ipc_latency.json`

mod gate_fixture;

use std::time::{Duration, Instant};

use evgate_core::{
    words_for, Event, Forecast, ForecastView, GateMode, Judge, MaskView, NoForecast, Policy,
};
use evgate_e2e::{binary, unique_names, wait_until, workspace_root, Process};
use evgate_ipc::{
    clock, create_node, pin_current_thread, Backoff, BatchHeader, ForecastHeader, PipelineNames,
    Qos, SlicePublisher, SliceSubscriber, Stream, WaitStrategy,
};
use gate_fixture::{
    flag_value, forecast, left_columns_mask, random_batch, write_report, BenchResult, HORIZONS_US,
    REFERENCE_US, SENSOR,
};
use serde_json::json;

const TIMEOUT: Duration = Duration::from_secs(60);

/// The CPUs of this process and of the peer.
const BENCH_CPU: usize = 0;
const PEER_CPU: usize = 1;

/// The stream id of the bench's batches, which its forecast names.
const STREAM_ID: u64 = 1;

const STRATEGIES: [WaitStrategy; 2] = [WaitStrategy::Event, WaitStrategy::BusyPoll];

fn main() -> BenchResult<()> {
    if let Some(domain) = flag_value("--echo") {
        let strategy = match flag_value("--wait").as_deref() {
            Some("busy-poll") => WaitStrategy::BusyPoll,
            _ => WaitStrategy::Event,
        };
        pin_current_thread(PEER_CPU)?;
        return echo(&PipelineNames::new(&domain, "cam")?, strategy);
    }
    // cargo runs benches in the package directory; relative paths mean the workspace root.
    let out = workspace_root()
        .join(flag_value("--out").unwrap_or_else(|| "target/bench/ipc_latency.json".to_owned()));
    pin_current_thread(BENCH_CPU)?;
    let mut results = Vec::new();
    for (size, iterations) in [(1_000, 3_000), (10_000, 2_000), (100_000, 500)] {
        let events = random_batch(size, size as u64);
        let kernel = kernel_times(&events, iterations.min(1_000));
        let kernel_p50 = percentile(&kernel, 0.5);
        let mut by_strategy = serde_json::Map::new();
        for strategy in STRATEGIES {
            let gate = measure_peer(Peer::Gate, strategy, &events, iterations)?;
            let raw = measure_peer(Peer::RawEcho, strategy, &events, iterations)?;
            let budget_p99 = 2.0 * (percentile(&raw, 0.99) + kernel_p50);
            by_strategy.insert(
                flag(strategy),
                json!({
                    "gate-us": summary(&gate),
                    "raw-echo-us": summary(&raw),
                    "target-p99-us (2 x (raw p99 + kernel p50))": budget_p99,
                    "gate-p99-within-target": percentile(&gate, 0.99) <= budget_p99,
                }),
            );
        }
        let result = json!({
            "batch-events": size,
            "iterations": iterations,
            "gating-kernel-us": summary(&kernel),
            "wait": by_strategy,
        });
        eprintln!("{result}");
        results.push(result);
    }
    let report = json!({
        "bench": "ipc_latency",
        "machine": machine(),
        "cpus": {"bench": BENCH_CPU, "peer": PEER_CPU},
        "results": results,
    });
    write_report(&out, &report)
}

fn flag(strategy: WaitStrategy) -> String {
    match strategy {
        WaitStrategy::Event => "event",
        WaitStrategy::BusyPoll => "busy-poll",
    }
    .to_owned()
}

#[derive(Clone, Copy, Debug)]
enum Peer {
    Gate,
    RawEcho,
}

/// A forecast whose masks cover the whole sensor: every event is judged and kept.
fn full_sensor_forecast() -> (ForecastHeader, Vec<u64>) {
    forecast(&left_columns_mask(SENSOR.width), STREAM_ID)
}

/// Round trips through `peer`, in microseconds.
fn measure_peer(
    peer: Peer,
    strategy: WaitStrategy,
    events: &[Event],
    iterations: usize,
) -> BenchResult<Vec<f64>> {
    let names = unique_names("latency");
    let node = create_node("ipc-latency-bench")?;
    let qos = Qos {
        initial_max_slice_len: events.len(),
        ..Qos::default()
    };
    let input = SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &qos)?;
    let output = SliceSubscriber::<Event, BatchHeader>::open(&node, &names, Stream::Kept, &qos)?;
    let forecasts = SlicePublisher::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )?;
    let _peer = start_peer(peer, strategy, &names)?;
    wait_until("the peer subscribing", TIMEOUT, || {
        input.subscriber_count() == 1
    })?;
    if let Peer::Gate = peer {
        wait_until("the gate subscribing to forecasts", TIMEOUT, || {
            forecasts.subscriber_count() == 1
        })?;
        let (header, masks) = full_sensor_forecast();
        forecasts.publish(header, &masks)?;
    }
    let warmup = iterations / 10 + 10;
    let mut latencies = Vec::with_capacity(iterations);
    for sequence in 0..(warmup + iterations) as u64 {
        let header = BatchHeader {
            stream_id: STREAM_ID,
            sequence,
            first_event_index: sequence * events.len() as u64,
            event_count: events.len() as u64,
            t_begin_us: events[0].t,
            t_end_us: events[events.len() - 1].t + 1,
            published_at_monotonic_ns: clock::monotonic_ns(),
            width: SENSOR.width,
            height: SENSOR.height,
            flags: 0,
        };
        input.publish(header, events)?;
        let received_ns = receive_one(&output, strategy, events.len())?;
        if sequence as usize >= warmup {
            latencies.push((received_ns - header.published_at_monotonic_ns) as f64 / 1e3);
        }
    }
    Ok(latencies)
}

/// Waits for the echoed batch (asleep on the wake-up listener, or polling); returns the arrival
/// time.
fn receive_one(
    output: &SliceSubscriber<Event, BatchHeader>,
    strategy: WaitStrategy,
    expected: usize,
) -> BenchResult<u64> {
    let deadline = Instant::now() + TIMEOUT;
    let mut backoff = Backoff::default();
    loop {
        if let Some(sample) = output.receive()? {
            let now = clock::monotonic_ns();
            if sample.payload().len() != expected {
                return Err(format!(
                    "peer returned {} events, {expected} expected",
                    sample.payload().len()
                )
                .into());
            }
            return Ok(now);
        }
        if Instant::now() >= deadline {
            return Err("the peer did not return the batch within 60 s".into());
        }
        match strategy {
            WaitStrategy::Event => {
                output
                    .listener()
                    .timed_wait(|_| {}, Duration::from_millis(100))?;
            }
            WaitStrategy::BusyPoll => backoff.idle(),
        }
    }
}

fn start_peer(peer: Peer, strategy: WaitStrategy, names: &PipelineNames) -> BenchResult<Process> {
    let wait = flag(strategy);
    let cpu = PEER_CPU.to_string();
    Ok(match peer {
        Peer::Gate => Process::start(
            &binary("evgate-gate")?,
            &[
                "--domain",
                &names.domain,
                "--camera",
                &names.camera,
                "--outputs",
                "kept",
                "--no-forecast",
                "drop",
                "--stats-interval-ms",
                "1000",
                "--wait",
                &wait,
                "--cpu",
                &cpu,
            ],
        )?,
        Peer::RawEcho => Process::start(
            &std::env::current_exe()?,
            &["--echo", &names.domain, "--wait", &wait],
        )?,
    })
}

/// The raw peer: copies every batch from the events stream to the kept stream.
fn echo(names: &PipelineNames, strategy: WaitStrategy) -> BenchResult<()> {
    let node = create_node("ipc-latency-echo")?;
    let input =
        SliceSubscriber::<Event, BatchHeader>::open(&node, names, Stream::Events, &Qos::default())?;
    let output =
        SlicePublisher::<Event, BatchHeader>::open(&node, names, Stream::Kept, &Qos::default())?;
    let mut backoff = Backoff::default();
    loop {
        let mut echoed = false;
        while let Some(sample) = input.receive()? {
            output.publish(*sample.user_header(), sample.payload())?;
            echoed = true;
        }
        // The bench kills this process when done; SIGTERM/SIGINT end the wait too.
        match strategy {
            WaitStrategy::Event => {
                input.clear_wakeups();
                if input
                    .listener()
                    .timed_wait(|_| {}, Duration::from_millis(100))
                    .is_err()
                {
                    return Ok(());
                }
            }
            WaitStrategy::BusyPoll if echoed => backoff.reset(),
            WaitStrategy::BusyPoll => backoff.idle(),
        }
    }
}

/// The gate's judge and the selection of the kept events on the same batch, microseconds per
/// call.
fn kernel_times(events: &[Event], iterations: usize) -> Vec<f64> {
    let (_, words) = full_sensor_forecast();
    let per_mask = words_for(SENSOR.pixels());
    let forecast = Forecast {
        current: MaskView::new(SENSOR, &words[..per_mask]).expect("valid mask"),
        horizons: ForecastView::new(REFERENCE_US, &HORIZONS_US, SENSOR, &words[per_mask..])
            .expect("valid forecast"),
    };
    let policy = Policy {
        no_forecast: NoForecast::Drop,
        last_mask_max_age: Duration::from_millis(200),
    };
    let mut judge = Judge::default();
    let mut kept = Vec::with_capacity(events.len());
    (0..iterations)
        .map(|_| {
            let start = Instant::now();
            let verdict = judge.judge(
                std::hint::black_box(events),
                Some(forecast),
                GateMode::KeepMovingObjects,
                policy,
            );
            kept.clear();
            judge.select(events, true, &mut kept);
            std::hint::black_box((verdict, &kept));
            start.elapsed().as_secs_f64() * 1e6
        })
        .collect()
}

fn percentile(values: &[f64], quantile: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let index = ((sorted.len() as f64 * quantile).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[index]
}

fn summary(values: &[f64]) -> serde_json::Value {
    json!({
        "p50": percentile(values, 0.5),
        "p99": percentile(values, 0.99),
        "p99.9": percentile(values, 0.999),
        "max": percentile(values, 1.0),
        "samples": values.len(),
    })
}

/// What the figures were measured on.
fn machine() -> serde_json::Value {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_owned())
        });
    json!({
        "cpu": cpu,
        "logical-cpus": std::thread::available_parallelism().map(|n| n.get()).ok(),
    })
}
