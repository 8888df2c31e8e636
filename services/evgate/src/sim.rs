//! `evgate sim`: simulate one labelled sequence (events plus ground truth), or a whole
//! benchmark suite with `evgate sim suite`.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use evgate_sim::sequence::SequenceReport;
use evgate_sim::{simulate_sequence, Preset, SequenceOptions, SimConfig};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

/// Simulate an event camera with ground truth and write `sequence.npz`.
#[derive(Args)]
pub struct SimArgs {
    /// Scene preset: boxes, floor, wall, table, fast, tabletop (346×260) or driving (640×480).
    #[arg(long, default_value = "boxes")]
    pub preset: Preset,
    /// JSON configuration file replacing the preset's (see docs/simulator.md; keys kebab-case).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Random seed: the same preset, seed and duration give the same sequence.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated duration in seconds (at least 0.15).
    #[arg(long, default_value_t = 2.0)]
    pub duration_s: f64,
    /// Forecast horizons sampled per 50 ms reference time.
    #[arg(long, default_value_t = 2)]
    pub horizons: usize,
    /// Output directory (created if missing).
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Print the summary as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// What one simulated sequence holds, printed and written as `summary.json`.
#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct SequenceSummary {
    pub preset: String,
    pub seed: u64,
    pub duration_s: f64,
    pub events: u64,
    pub object_event_share: f64,
    pub on_event_share: f64,
    pub events_per_second: f64,
    pub object_count: usize,
    pub renders: u64,
    pub wall_s: f64,
    pub realtime_factor: f64,
    pub files: Vec<PathBuf>,
}

pub fn run(args: SimArgs) -> anyhow::Result<()> {
    let out = args.out.context("--out is required")?;
    let config = match &args.config {
        Some(path) => load_config(path)?,
        None => args.preset.config(),
    };
    let options = SequenceOptions {
        duration_us: (args.duration_s * 1e6).round() as i64,
        horizons_per_reference: args.horizons,
    };
    fs::create_dir_all(&out)
        .with_context(|| format!("cannot create output directory {}", out.display()))?;
    let bar = progress_bar(
        options.duration_us,
        &format!("{} seed {}", config.preset, args.seed),
    );
    let summary = write_sequence(&config, args.seed, &options, &out, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let json = serde_json::to_string_pretty(&summary)?;
    fs::write(out.join("summary.json"), &json)
        .with_context(|| format!("cannot write {}", out.join("summary.json").display()))?;
    if args.json {
        println!("{json}");
    } else {
        println!(
            "{} seed {}: {:.2} s simulated in {:.2} s ({:.2}× real time), {} events ({:.0}/s), {:.1} % from {} moving objects, {:.1} % ON, {} renders",
            summary.preset,
            summary.seed,
            summary.duration_s,
            summary.wall_s,
            summary.realtime_factor,
            summary.events,
            summary.events_per_second,
            summary.object_event_share * 100.0,
            summary.object_count,
            summary.on_event_share * 100.0,
            summary.renders,
        );
        for file in &summary.files {
            println!("wrote {}", file.display());
        }
    }
    Ok(())
}

/// Reads a simulator configuration (the JSON form of [`SimConfig`]).
pub fn load_config(path: &Path) -> anyhow::Result<SimConfig> {
    let text = fs::read_to_string(path)
        .with_context(|| format!("cannot read simulator config {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| {
        format!(
            "simulator config {}: invalid JSON or unknown field",
            path.display()
        )
    })
}

/// Simulates one sequence into `dir` (`sequence.npz`, `events.evg`) and summarises it.
pub fn write_sequence(
    config: &SimConfig,
    seed: u64,
    options: &SequenceOptions,
    dir: &Path,
    progress: &mut dyn FnMut(i64, i64),
) -> anyhow::Result<SequenceSummary> {
    let started = std::time::Instant::now();
    let (sequence, report) = simulate_sequence(config, seed, options, progress)?;
    let wall_s = started.elapsed().as_secs_f64();
    let npz = dir.join("sequence.npz");
    sequence
        .write(&npz)
        .with_context(|| format!("cannot write {}", npz.display()))?;
    Ok(summarise(config, seed, options, &report, wall_s, vec![npz]))
}

fn summarise(
    config: &SimConfig,
    seed: u64,
    options: &SequenceOptions,
    report: &SequenceReport,
    wall_s: f64,
    files: Vec<PathBuf>,
) -> SequenceSummary {
    let stats = report.stats;
    let events = stats.events.max(1) as f64;
    let duration_s = options.duration_us as f64 * 1e-6;
    SequenceSummary {
        preset: config.preset.clone(),
        seed,
        duration_s,
        events: stats.events,
        object_event_share: stats.object_events as f64 / events,
        on_event_share: stats.on_events as f64 / events,
        events_per_second: stats.events as f64 / duration_s,
        object_count: report.object_count,
        renders: stats.renders,
        wall_s,
        realtime_factor: duration_s / wall_s.max(1e-9),
        files,
    }
}

pub fn progress_bar(length: i64, message: &str) -> ProgressBar {
    let bar = ProgressBar::new(length.max(1) as u64);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{elapsed_precise}] {wide_bar} {percent}% eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(message.to_string());
    bar
}
