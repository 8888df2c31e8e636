//! Simulator speed: how many simulated seconds `evgate-sim` produces per wall-clock second for
//! each preset (issue 3 asks for at least real time at 346×260 on 2 cores).
//!
//! `cargo bench -p evgate-benches --bench sim` runs criterion over 20 ms slices of simulated
//! time (one simulator per preset keeps advancing, so every slice is a steady-state slice), then
//! times one continuous second per preset, streamed in 1 ms chunks as `evgate-ingest` streams
//! the simulated camera, from a fresh simulator `EVGATE_BENCH_REPEATS` times (default 3: the
//! same work each time, so their spread is the machine's; the run of median wall time is
//! reported, with every run's factor), and writes the real-time factors as JSON to
//! `target/bench-results/sim.json` (override with `EVGATE_BENCH_JSON`). Restrict the cores with
//! `taskset -c 0,1` to measure on 2 cores; the simulator uses every core it is allowed. The
//! JSON also gives the CPU time, which a shared machine's load distorts much less than the wall
//! time. `EVGATE_BENCH_PRESETS=boxes,table` limits the presets; `EVGATE_BENCH_SIMULATED_MS=100`
//! shortens the timed run (for instruction counts under `valgrind --tool=callgrind`).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use criterion::{criterion_group, Criterion, Throughput};
use evgate_core::SensorSize;
use evgate_sim::{Preset, SimStats, Simulator};
use serde::Serialize;

const SLICE_US: i64 = 20_000;
/// The timed second is streamed in chunks of this much simulated time, as the ingest service
/// streams the simulated camera.
const STREAM_CHUNK_US: i64 = 1_000;
/// Skipped before measuring, so the scene is in motion and not at its initial pose.
const WARM_UP_US: i64 = 100_000;
const SEED: u64 = 7;
const WORKSPACE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/..");

fn presets() -> Vec<Preset> {
    match std::env::var("EVGATE_BENCH_PRESETS") {
        Ok(list) => list
            .split(',')
            .filter_map(|name| name.trim().parse().ok())
            .collect(),
        Err(_) => Preset::ALL.to_vec(),
    }
}

fn slices(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim_20ms_slice");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    for preset in presets() {
        let mut simulator = Simulator::from_preset(preset, SEED);
        let mut events = Vec::new();
        simulator.advance(WARM_UP_US, &mut events);
        group.throughput(Throughput::Elements((SLICE_US / 1000) as u64));
        group.bench_function(preset.name(), |b| {
            b.iter_custom(|iterations| {
                let started = Instant::now();
                for _ in 0..iterations {
                    events.clear();
                    let end = simulator.time_us() + SLICE_US;
                    simulator.advance(end, &mut events);
                }
                started.elapsed()
            })
        });
    }
    group.finish();
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct PresetSpeed {
    preset: &'static str,
    width: u16,
    height: u16,
    simulated_s: f64,
    /// Of the run with the median wall time (the figures below are that run's too).
    wall_s: f64,
    realtime_factor: f64,
    /// Every run's real-time factor, in the order run.
    realtime_factor_runs: Vec<f64>,
    /// User + system CPU time of the whole process while simulating.
    cpu_s: f64,
    /// Simulated seconds per CPU second: on a machine shared with other jobs the wall time
    /// depends on the load; the CPU time much less.
    simulated_s_per_cpu_s: f64,
    /// Instants sampled for events (the objects' rate where they move).
    renders_per_simulated_s: f64,
    /// Full renders of the static world (interpolated in between).
    background_renders_per_simulated_s: f64,
    events_per_simulated_s: f64,
    object_event_share: f64,
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct Report {
    /// Worker threads of each simulator (the cores this process may use).
    threads: usize,
    seed: u64,
    /// The machine's 1-minute load average before and after the timed runs: on a shared
    /// machine the wall times depend on it.
    load_average_before: Option<f64>,
    load_average_after: Option<f64>,
    presets: Vec<PresetSpeed>,
}

/// One continuous simulated second per preset, streamed in [`STREAM_CHUNK_US`] chunks and timed
/// end to end (scene setup excluded), repeated from a fresh simulator.
fn realtime_report() -> Report {
    let load_average_before = load_average();
    // A shorter run suits instruction counting under callgrind, which is ~50× slower.
    let simulated_us = std::env::var("EVGATE_BENCH_SIMULATED_MS")
        .ok()
        .and_then(|ms| ms.parse::<i64>().ok())
        .map_or(1_000_000, |ms| ms * 1000);
    let repeats = std::env::var("EVGATE_BENCH_REPEATS")
        .ok()
        .and_then(|n| n.parse::<usize>().ok())
        .unwrap_or(3)
        .max(1);
    let presets = presets()
        .into_iter()
        .map(|preset| {
            let mut runs: Vec<TimedRun> = (0..repeats)
                .map(|_| time_one_run(preset, simulated_us))
                .collect();
            let simulated_s = simulated_us as f64 * 1e-6;
            let realtime_factor_runs = runs.iter().map(|run| simulated_s / run.wall_s).collect();
            runs.sort_by(|a, b| a.wall_s.total_cmp(&b.wall_s));
            let TimedRun {
                stats,
                sensor,
                wall_s,
                cpu_s,
            } = runs.swap_remove(runs.len() / 2);
            PresetSpeed {
                preset: preset.name(),
                width: sensor.width,
                height: sensor.height,
                simulated_s,
                wall_s,
                realtime_factor: simulated_s / wall_s,
                realtime_factor_runs,
                cpu_s,
                simulated_s_per_cpu_s: simulated_s / cpu_s,
                renders_per_simulated_s: stats.renders as f64 / simulated_s,
                background_renders_per_simulated_s: stats.background_renders as f64 / simulated_s,
                events_per_simulated_s: stats.events as f64 / simulated_s,
                object_event_share: stats.object_events as f64 / stats.events.max(1) as f64,
            }
        })
        .collect();
    Report {
        threads: std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1),
        seed: SEED,
        load_average_before,
        load_average_after: load_average(),
        presets,
    }
}

/// One timed run of a preset: its times and the simulator's counters (the simulator, with its
/// helper threads, is gone before the next run).
struct TimedRun {
    stats: SimStats,
    sensor: SensorSize,
    wall_s: f64,
    cpu_s: f64,
}

fn time_one_run(preset: Preset, simulated_us: i64) -> TimedRun {
    let mut simulator = Simulator::from_preset(preset, SEED);
    let mut events = Vec::new();
    let cpu_before = process_cpu_s();
    let started = Instant::now();
    let mut t = 0;
    while t < simulated_us {
        t = (t + STREAM_CHUNK_US).min(simulated_us);
        // Consumed as they come, as by the ingest service: kept, a second of events (60 MB
        // for `fast`) cost the run its allocation and page faults.
        events.clear();
        simulator.advance(t, &mut events);
    }
    TimedRun {
        wall_s: started.elapsed().as_secs_f64(),
        cpu_s: process_cpu_s() - cpu_before,
        stats: simulator.stats(),
        sensor: simulator.sensor(),
    }
}

/// The 1-minute load average from `/proc/loadavg` (`None` where there is none).
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// User plus system CPU seconds used by this process so far.
fn process_cpu_s() -> f64 {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes a complete `rusage` into the pointer it is given.
    let usage = unsafe {
        libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr());
        usage.assume_init()
    };
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}

criterion_group!(benches, slices);

fn main() -> Result<(), Box<dyn std::error::Error>> {
    benches();
    Criterion::default().configure_from_args().final_summary();
    let report = realtime_report();
    println!(
        "{} threads; load average {:?} before, {:?} after",
        report.threads, report.load_average_before, report.load_average_after
    );
    for p in &report.presets {
        let runs: Vec<String> = p
            .realtime_factor_runs
            .iter()
            .map(|factor| format!("{factor:.2}"))
            .collect();
        println!(
            "{:>9} {}x{}: {:.2}x real time (runs: {}; {:.2} s wall, {:.2} CPU s per simulated s), {:.0} renders/s ({:.0} of the static world), {:.2} M events/s, {:.1} % object events",
            p.preset,
            p.width,
            p.height,
            p.realtime_factor,
            runs.join(", "),
            p.wall_s / p.simulated_s,
            p.cpu_s / p.simulated_s,
            p.renders_per_simulated_s,
            p.background_renders_per_simulated_s,
            p.events_per_simulated_s * 1e-6,
            p.object_event_share * 100.0
        );
    }
    let json_path: PathBuf = std::env::var_os("EVGATE_BENCH_JSON")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(WORKSPACE).join("target/bench-results/sim.json"));
    if let Some(directory) = json_path.parent() {
        std::fs::create_dir_all(directory)?;
    }
    std::fs::write(&json_path, serde_json::to_string_pretty(&report)? + "\n")?;
    println!("wrote {}", json_path.display());
    Ok(())
}
