//! Sustained throughput into the gate with zero loss, and the resident memory of each service.
//!
//! Phase 1: this process publishes pre-generated batches (random events on a 346x260 sensor,
//! all judged by a forecast that keeps half the sensor) as fast as the gate takes them: the
//! events stream blocks instead of dropping, so nothing may be lost. The rate is the events
//! counted by the gate divided by the time from the first publication to the gate's
//! end-of-stream stats; the run fails unless the gate reports zero lost events and balanced
//! accounting.
//! Phase 2: the real services (evgate-ingest on the simulated camera, evgate-gate, and
//! evgate-infer with models/evgate-S.onnx when that file exists) run a short stream while
//! /proc/<pid>/status is polled; the largest VmHWM of each is reported.
//!
//! `cargo bench -p evgate-benches --bench throughput -- --out target/bench/throughput.json`

mod gate_fixture;

use std::time::{Duration, Instant};

use evgate_core::Event;
use evgate_e2e::{binary, unique_names, wait_until, workspace_root, Process};
use evgate_ipc::{
    clock, create_node, BatchFlags, BatchHeader, ForecastHeader, LatestSubscriber, PipelineStats,
    Qos, SlicePublisher, Stream,
};
use gate_fixture::{
    flag_value, forecast, left_columns_mask, random_batch, write_report, BenchResult, SENSOR,
};
use serde_json::json;

/// The stream id of the bench's batches, which its forecast names.
const STREAM_ID: u64 = 3;

const TIMEOUT: Duration = Duration::from_secs(120);

fn main() -> BenchResult<()> {
    // cargo runs benches in the package directory; relative paths mean the workspace root.
    let out = workspace_root()
        .join(flag_value("--out").unwrap_or_else(|| "target/bench/throughput.json".to_owned()));
    let total_events: u64 = flag_value("--events").map_or(Ok(200_000_000), |v| v.parse())?;
    let batch_events: usize = flag_value("--batch-events").map_or(Ok(100_000), |v| v.parse())?;

    let throughput = sustained_throughput(total_events, batch_events)?;
    eprintln!("{throughput}");
    let memory = service_memory()?;
    eprintln!("{memory}");
    let report = json!({
        "bench": "throughput",
        "throughput": throughput,
        "resident-memory": memory,
    });
    write_report(&out, &report)
}

fn half_sensor_forecast() -> (ForecastHeader, Vec<u64>) {
    forecast(&left_columns_mask(SENSOR.width / 2), STREAM_ID)
}

fn sustained_throughput(total_events: u64, batch_events: usize) -> BenchResult<serde_json::Value> {
    let events = random_batch(batch_events, 7);

    let names = unique_names("throughput");
    let node = create_node("throughput-bench")?;
    let qos = Qos {
        initial_max_slice_len: batch_events,
        block_timeout_ms: 10_000,
        ..Qos::default()
    };
    let input = SlicePublisher::<Event, BatchHeader>::open(&node, &names, Stream::Events, &qos)?;
    let forecasts = SlicePublisher::<u64, ForecastHeader>::open(
        &node,
        &names,
        Stream::Forecast,
        &Qos::default(),
    )?;
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats)?;
    let mut gate = Process::start(
        &binary("evgate-gate")?,
        &[
            "--domain",
            &names.domain,
            "--camera",
            &names.camera,
            "--outputs",
            "kept,suppressed",
            "--exit-at-end-of-stream",
            "--json",
            "--stats-interval-ms",
            "100",
        ],
    )?;
    wait_until("the gate subscribing", TIMEOUT, || {
        input.subscriber_count() == 1 && forecasts.subscriber_count() == 1
    })?;
    let (forecast_header, masks) = half_sensor_forecast();
    forecasts.publish(forecast_header, &masks)?;

    let batches = total_events.div_ceil(batch_events as u64);
    let mut undelivered = 0;
    let started = Instant::now();
    for sequence in 0..=batches {
        let last = sequence == batches;
        let payload: &[Event] = if last { &[] } else { &events };
        let header = BatchHeader {
            stream_id: STREAM_ID,
            sequence,
            first_event_index: sequence * batch_events as u64,
            event_count: payload.len() as u64,
            t_begin_us: events[0].t,
            t_end_us: events[batch_events - 1].t + 1,
            published_at_monotonic_ns: clock::monotonic_ns(),
            width: SENSOR.width,
            height: SENSOR.height,
            flags: if last { BatchFlags::END_OF_STREAM } else { 0 },
        };
        undelivered += input.publish(header, payload)?.undelivered;
    }
    let published_s = started.elapsed().as_secs_f64();
    let gate_hwm_kib = vm_hwm_kib(gate.pid());
    let mut last_stats = None;
    wait_until("the gate's end-of-stream stats", TIMEOUT, || {
        if let Ok(Some(fresh)) = stats.latest() {
            last_stats = Some(fresh);
        }
        last_stats.is_some_and(|s| s.end_of_stream == 1)
    })?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let summary = gate.summary(TIMEOUT)?;
    let stats = last_stats.expect("waited for it");
    let expected = batches * batch_events as u64;
    if stats.input_events != expected
        || stats.dropped_events != 0
        || !stats.is_balanced()
        || undelivered != 0
    {
        return Err(format!("events were lost: published {expected}, gate stats {stats:?}, undelivered batches {undelivered}").into());
    }
    Ok(json!({
        "batch-events": batch_events,
        "events": expected,
        "seconds": elapsed_s,
        "publish-seconds": published_s,
        "events-per-s": expected as f64 / elapsed_s,
        "lost-events": stats.dropped_events,
        "balanced": stats.is_balanced(),
        "kept-events": stats.kept_events,
        "suppressed-events": stats.suppressed_events,
        "gate-vm-hwm-mib": gate_hwm_kib.map(|kib| kib as f64 / 1024.0),
        "gate-summary": summary,
    }))
}

/// Peak resident set size of a live process, KiB (VmHWM in /proc/<pid>/status).
fn vm_hwm_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|line| line.strip_prefix("VmHWM:"))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
}

fn service_memory() -> BenchResult<serde_json::Value> {
    let names = unique_names("memory");
    let common = [
        "--domain",
        names.domain.as_str(),
        "--camera",
        names.camera.as_str(),
    ];
    let mut services = vec![Process::start(
        &binary("evgate-gate")?,
        &[
            &common[..],
            &[
                "--exit-at-end-of-stream",
                "--outputs",
                "kept,suppressed,keep-bitmap",
            ],
        ]
        .concat(),
    )?];
    let model = workspace_root().join("models/evgate-S.onnx");
    let with_infer = model.is_file();
    if with_infer {
        let model = model.display().to_string();
        services.push(Process::start(
            &binary("evgate-infer")?,
            &[&common[..], &["--exit-at-end", "--model", &model]].concat(),
        )?);
    }
    let subscribers = services.len().to_string();
    services.push(Process::start(
        &binary("evgate-ingest")?,
        &[
            &common[..],
            &[
                "--fast",
                "--sim-duration-s",
                "2",
                "--wait-for-subscribers",
                &subscribers,
                "--sim-threads",
                "2",
            ],
        ]
        .concat(),
    )?);
    let mut peaks = vec![0u64; services.len()];
    let deadline = Instant::now() + TIMEOUT * 3;
    while services.iter_mut().any(Process::is_running) {
        for (service, peak) in services.iter_mut().zip(peaks.iter_mut()) {
            if let Some(kib) = vm_hwm_kib(service.pid()) {
                *peak = (*peak).max(kib);
            }
        }
        if Instant::now() >= deadline {
            return Err("the services did not finish their stream within 6 minutes".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut report = serde_json::Map::new();
    for (service, peak) in services.iter().zip(peaks) {
        report.insert(
            format!("{}-vm-hwm-mib", service.name),
            json!(peak as f64 / 1024.0),
        );
    }
    report.insert("infer-measured".to_owned(), json!(with_infer));
    Ok(serde_json::Value::Object(report))
}
