//! Inference latency of an exported network, window after window with the recurrent state
//! carried, as the infer service runs it: voxelisation, the ONNX Runtime call, thresholding of
//! the current and horizon masks and of the keep regions (the horizons' logits dilated by the
//! model's keep rule), and the prediction age (horizon − runtime) they leave.
//!
//! A bench binary rather than criterion because the figures wanted are a median and a p99 per
//! stage, written as JSON. Settings come from the environment:
//!
//! | variable | default |
//! |---|---|
//! | `EVGATE_BENCH_MODEL` | `models/evgate-S.onnx` |
//! | `EVGATE_BENCH_THREADS` | 2 (intra-op threads) |
//! | `EVGATE_BENCH_SPIN` | false (idle ONNX Runtime threads spin when true) |
//! | `EVGATE_BENCH_PROVIDER` | cpu (cpu, cuda, auto) |
//! | `EVGATE_BENCH_STATE_BINDING` | auto (auto, always, never: where the recurrent state lives) |
//! | `EVGATE_BENCH_HORIZONS` | `MAX_HORIZONS` (8, the infer service's default): K, spread evenly up to the model's largest horizon |
//! | `EVGATE_BENCH_WINDOWS` | 200 measured windows (after 20 warm-up windows) |
//! | `EVGATE_BENCH_EVENTS` | 100000 events per 50 ms window |
//! | `EVGATE_BENCH_JSON` | `target/bench-results/inference.json` |
//!
//! Run: `cargo bench -p evgate-benches --bench inference`.

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::{Duration, Instant};

use evgate_core::{
    dilate_logits, BitMask, DilationScratch, Event, SensorSize, TimeSpan, VoxelGrid,
};
use evgate_ipc::MAX_HORIZONS;
use evgate_model::{MaskRule, ModelRuntime, Provider, RuntimeOptions, StateBinding};
use indicatif::{ProgressBar, ProgressStyle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

const WORKSPACE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
const WINDOW_US: i64 = 50_000;
const WARM_UP_WINDOWS: usize = 20;

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct Stage {
    median_ms: f64,
    p99_ms: f64,
    mean_ms: f64,
    min_ms: f64,
    max_ms: f64,
}

impl Stage {
    fn of(samples: &[Duration]) -> Self {
        let mut ms: Vec<f64> = samples.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        ms.sort_by(f64::total_cmp);
        let rank = |quantile: f64| {
            let rank = (quantile * ms.len() as f64).ceil() as usize;
            ms[rank.clamp(1, ms.len()) - 1]
        };
        Self {
            median_ms: rank(0.5),
            p99_ms: rank(0.99),
            mean_ms: ms.iter().sum::<f64>() / ms.len() as f64,
            min_ms: ms[0],
            max_ms: ms[ms.len() - 1],
        }
    }
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct PredictionAge {
    horizon_ms: f32,
    /// Horizon − median of voxelisation + inference + thresholding.
    age_ms: f64,
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct InferenceReport {
    model: PathBuf,
    model_size: &'static str,
    sensor: String,
    input: String,
    provider: String,
    /// Whether the recurrent state stayed bound to the session's device between windows.
    state_bound: bool,
    intra_threads: usize,
    spin_threads: bool,
    cpu_cores_visible: usize,
    /// 1, 5 and 15 minute load averages (/proc/loadavg) before and after the measured windows:
    /// on a shared machine the wall times only mean something next to them.
    load_average_before: Option<[f64; 3]>,
    load_average_after: Option<[f64; 3]>,
    windows: usize,
    events_per_window: usize,
    horizons_ms: Vec<f32>,
    voxelisation: Stage,
    /// ONNX Runtime call with the `horizons_ms` (`EVGATE_BENCH_HORIZONS` of them).
    inference: Stage,
    /// Process CPU time (all threads) spent in that call: unlike wall time it barely moves when
    /// other processes compete for the cores, so it shows the work itself.
    inference_cpu: Stage,
    /// ONNX Runtime call with the single horizon 100 ms (the cost of the extra horizons).
    inference_one_horizon: Stage,
    thresholding: Stage,
    /// Voxelisation + inference + thresholding per window.
    total: Stage,
    prediction_age: Vec<PredictionAge>,
}

/// The 1, 5 and 15 minute load averages, where /proc/loadavg exists.
fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut fields = text.split_whitespace().map(str::parse::<f64>);
    Some([
        fields.next()?.ok()?,
        fields.next()?.ok()?,
        fields.next()?.ok()?,
    ])
}

/// User + system CPU time of the whole process so far.
fn process_cpu_time() -> Duration {
    // SAFETY: getrusage only writes the zero-initialised struct it is handed.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_SELF, &mut usage);
        usage
    };
    let to_duration = |time: libc::timeval| {
        Duration::from_secs(time.tv_sec as u64) + Duration::from_micros(time.tv_usec as u64)
    };
    to_duration(usage.ru_utime) + to_duration(usage.ru_stime)
}

fn setting<T: FromStr>(name: &str, default: T) -> T {
    match std::env::var(name) {
        Ok(value) => value.parse().unwrap_or_else(|_| {
            eprintln!("{name}={value:?} is not valid; using the default");
            default
        }),
        Err(_) => default,
    }
}

/// Window `index` of the synthetic stream: its events and its span.
fn window(
    rng: &mut ChaCha8Rng,
    sensor: SensorSize,
    index: usize,
    events_per_window: usize,
) -> Result<(Vec<Event>, TimeSpan), Box<dyn std::error::Error>> {
    let start_us = index as i64 * WINDOW_US;
    let events = window_events(rng, sensor, start_us, events_per_window);
    Ok((events, TimeSpan::new(start_us, start_us + WINDOW_US)?))
}

fn voxelise(grid: &mut VoxelGrid, events: &[Event], span: TimeSpan) {
    grid.clear();
    grid.accumulate(events, span);
    grid.normalise();
}

/// A 40 × 40 block moving right at 1 px/ms over uniform background noise: a quarter of the
/// events on the object, time-sorted.
fn window_events(
    rng: &mut ChaCha8Rng,
    sensor: SensorSize,
    start_us: i64,
    count: usize,
) -> Vec<Event> {
    (0..count)
        .map(|index| {
            let t = start_us + index as i64 * WINDOW_US / count as i64;
            let (x, y) = if index % 4 == 0 {
                let left = ((t / 1000) % i64::from(sensor.width - 40)) as u16;
                (left + rng.gen_range(0..40), 100 + rng.gen_range(0..40))
            } else {
                (
                    rng.gen_range(0..sensor.width),
                    rng.gen_range(0..sensor.height),
                )
            };
            Event::new(t, x, y, rng.gen())
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let model: PathBuf = setting(
        "EVGATE_BENCH_MODEL",
        Path::new(WORKSPACE).join("models/evgate-S.onnx"),
    );
    let threads: usize = setting("EVGATE_BENCH_THREADS", 2);
    let spin_threads: bool = setting("EVGATE_BENCH_SPIN", false);
    let provider: Provider = setting("EVGATE_BENCH_PROVIDER", Provider::Cpu);
    let state_binding: StateBinding = setting("EVGATE_BENCH_STATE_BINDING", StateBinding::Auto);
    let horizon_count: usize =
        setting("EVGATE_BENCH_HORIZONS", MAX_HORIZONS).clamp(1, MAX_HORIZONS);
    let windows: usize = setting("EVGATE_BENCH_WINDOWS", 200).max(1);
    let events_per_window: usize = setting("EVGATE_BENCH_EVENTS", 100_000).max(1);
    let json_path: PathBuf = setting(
        "EVGATE_BENCH_JSON",
        Path::new(WORKSPACE).join("target/bench-results/inference.json"),
    );

    let options = RuntimeOptions {
        provider,
        intra_threads: threads,
        spin_threads,
        state_binding,
        ..RuntimeOptions::default()
    };
    let mut runtime = ModelRuntime::load(&model, options)?;
    let metadata = runtime.metadata().clone();
    let input = runtime.input_size();
    // The largest sensor that pads to the model's input is the one it was exported for in
    // practice (346 × 260 → 352 × 272); use the DAVIS346 size when it fits.
    let sensor = if SensorSize::new(346, 260).padded_to(16) == Some(input) {
        SensorSize::new(346, 260)
    } else {
        input
    };
    let horizons_ms: Vec<f32> = (1..=horizon_count)
        .map(|k| metadata.max_horizon_ms * k as f32 / horizon_count as f32)
        .collect();
    let one_horizon = [metadata.max_horizon_ms];

    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut grid = VoxelGrid::new(sensor, metadata.bins as usize)?;
    let mut mask = BitMask::new(sensor)?;
    let row_stride = usize::from(input.width);
    // The model's own mask rule, as the service applies it (evgate_model::Forecaster, keep
    // regions only): the current mask, then each horizon's forecast mask, or its keep region
    // where the rule dilates.
    let rule = MaskRule::of(&metadata);
    let (mut dilation_scratch, mut dilated) = (DilationScratch::default(), Vec::new());
    let mut voxelisation = Vec::with_capacity(windows);
    let mut inference = Vec::with_capacity(windows);
    let mut inference_cpu = Vec::with_capacity(windows);
    let mut inference_one_horizon = Vec::with_capacity(windows);
    let mut thresholding = Vec::with_capacity(windows);
    let mut total = Vec::with_capacity(windows);

    let load_average_before = load_average();
    let progress = ProgressBar::new(2 * (WARM_UP_WINDOWS + windows) as u64);
    progress.set_style(ProgressStyle::with_template(
        "{msg} [{bar:40}] {pos}/{len} windows ({eta} left)",
    )?);
    progress.set_message(format!(
        "{} {} on {provider}, {threads} threads",
        metadata.model_size.label(),
        input
    ));
    for index in 0..WARM_UP_WINDOWS + windows {
        let (events, span) = window(&mut rng, sensor, index, events_per_window)?;
        let started = Instant::now();
        voxelise(&mut grid, &events, span);
        let voxel_time = started.elapsed();

        let cpu_before = process_cpu_time();
        let output = runtime.forecast(grid.as_slice(), &horizons_ms)?;
        let inference_cpu_time = process_cpu_time().saturating_sub(cpu_before);
        let inference_time = output.inference_time();

        let started = Instant::now();
        mask.fill_from_logits(output.mask_logits(), row_stride, rule.threshold_logit)?;
        for logits in output.future_mask_logits() {
            if rule.keeps_the_forecast() {
                mask.fill_from_logits(logits, row_stride, rule.threshold_logit)?;
            } else {
                dilate_logits(
                    logits,
                    row_stride,
                    output.height(),
                    usize::from(rule.keep_dilation_px),
                    &mut dilation_scratch,
                    &mut dilated,
                );
                mask.fill_from_logits(&dilated, row_stride, rule.keep_threshold_logit)?;
            }
        }
        let threshold_time = started.elapsed();
        drop(output);

        if index >= WARM_UP_WINDOWS {
            voxelisation.push(voxel_time);
            inference.push(inference_time);
            inference_cpu.push(inference_cpu_time);
            thresholding.push(threshold_time);
            total.push(voxel_time + inference_time + threshold_time);
        }
        progress.inc(1);
    }
    // The single largest horizon, to show what the extra horizons cost, in a pass of its own
    // rather than interleaved window by window: the infer service never changes K within a
    // session, and on the CUDA provider alternating the horizon count made every run about 5×
    // slower (H200, 2026-11-26: S at 346×260 with K=8, 41–44 ms per run interleaved, 2.6 ms not).
    for index in 0..WARM_UP_WINDOWS + windows {
        let (events, span) = window(&mut rng, sensor, index, events_per_window)?;
        voxelise(&mut grid, &events, span);
        let one = runtime.forecast(grid.as_slice(), &one_horizon)?;
        if index >= WARM_UP_WINDOWS {
            inference_one_horizon.push(one.inference_time());
        }
        progress.inc(1);
    }
    progress.finish_and_clear();
    let load_average_after = load_average();

    let total_stage = Stage::of(&total);
    let report = InferenceReport {
        model: model.clone(),
        model_size: metadata.model_size.label(),
        sensor: sensor.to_string(),
        input: input.to_string(),
        provider: runtime.active_provider().to_string(),
        state_bound: runtime.state_bound(),
        intra_threads: threads,
        spin_threads,
        cpu_cores_visible: std::thread::available_parallelism().map_or(0, |n| n.get()),
        load_average_before,
        load_average_after,
        windows,
        events_per_window,
        prediction_age: horizons_ms
            .iter()
            .map(|&horizon_ms| PredictionAge {
                horizon_ms,
                age_ms: f64::from(horizon_ms) - total_stage.median_ms,
            })
            .collect(),
        horizons_ms,
        voxelisation: Stage::of(&voxelisation),
        inference: Stage::of(&inference),
        inference_cpu: Stage::of(&inference_cpu),
        inference_one_horizon: Stage::of(&inference_one_horizon),
        thresholding: Stage::of(&thresholding),
        total: total_stage,
    };

    println!(
        "model {} ({}), sensor {} → input {}, {} on {} threads, state {}, {} windows of {} events",
        report.model.display(),
        report.model_size,
        report.sensor,
        report.input,
        report.provider,
        report.intra_threads,
        if report.state_bound {
            "bound to the device"
        } else {
            "through host memory"
        },
        report.windows,
        report.events_per_window
    );
    let describe_load = |load: Option<[f64; 3]>| {
        load.map_or("unknown".to_owned(), |[one, five, fifteen]| {
            format!("{one:.2} {five:.2} {fifteen:.2}")
        })
    };
    println!(
        "load average (1, 5, 15 min): {} before, {} after",
        describe_load(report.load_average_before),
        describe_load(report.load_average_after)
    );
    for (name, stage) in [
        ("voxelisation", &report.voxelisation),
        ("inference", &report.inference),
        ("inference cpu time", &report.inference_cpu),
        ("inference, 1 horizon", &report.inference_one_horizon),
        ("thresholding", &report.thresholding),
        ("total", &report.total),
    ] {
        println!(
            "{name:>22}: median {:8.3} ms  p99 {:8.3} ms  mean {:8.3} ms  min {:8.3} ms  max {:8.3} ms",
            stage.median_ms, stage.p99_ms, stage.mean_ms, stage.min_ms, stage.max_ms
        );
    }
    for age in &report.prediction_age {
        println!(
            "prediction age at {:5.1} ms: {:6.2} ms",
            age.horizon_ms, age.age_ms
        );
    }
    if let Some(directory) = json_path.parent() {
        std::fs::create_dir_all(directory)?;
    }
    std::fs::write(&json_path, serde_json::to_string_pretty(&report)? + "\n")?;
    println!("wrote {}", json_path.display());
    Ok(())
}
