//! `evgate sim`: simulate one labelled sequence (events plus ground truth), or a whole
//! benchmark suite with `evgate sim suite`.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use evgate_sim::sequence::SequenceReport;
use evgate_sim::{
    simulate_sequence, suite_plan, Preset, SequenceOptions, SimConfig, Split, SuiteEntry,
    SuiteScale, SUITE_VERSION,
};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

/// Simulate an event camera with ground truth and write `events.evg`, `sequence.npz` and
/// `summary.json`; `evgate sim suite` generates the whole benchmark suite.
#[derive(Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SimArgs {
    #[command(subcommand)]
    pub command: Option<SimCommand>,
    #[command(flatten)]
    pub sequence: SequenceArgs,
}

#[derive(clap::Subcommand)]
pub enum SimCommand {
    /// Generate the versioned train/val/test/test-ood benchmark suite with a manifest (seeds,
    /// parameters, event counts, SHA-256 of every file and photograph).
    Suite(SuiteArgs),
}

#[derive(Args)]
pub struct SuiteArgs {
    /// Output directory; sequences go to <OUT>/<split>/<preset>-<seed>/, the manifest to
    /// <OUT>/manifest.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Suite size: small (105 simulated seconds: 2 train, 1 val, 1 test and 1 test-ood sequence
    /// of 3 s per preset, for quick checks) or full (1302 s: 40, 4, 16 and 2 per preset).
    #[arg(long, default_value = "small")]
    pub scale: SuiteScale,
    /// Splits to generate, comma-separated: train, val, test, test-ood (default: all).
    #[arg(long, value_delimiter = ',')]
    pub splits: Vec<Split>,
    /// Folder of PNG photographs for the test-ood split (scripts/fetch-photos.sh fills the
    /// default); every PNG in it is used, in name order.
    #[arg(long, default_value = "data/photos")]
    pub photos: PathBuf,
    /// Generate only the first N sequences of each preset in each split (their seeds and files
    /// are those of the whole suite): a smaller training set, quickly (default: all).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub per_preset: Option<u64>,
    /// Sequences simulated at once (each renders on every core; more jobs keep the cores busy
    /// while others compress and write). The files are the same for any number of jobs.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub jobs: u64,
    /// After generating, compare every file's SHA-256 (and every photograph's) with this
    /// manifest of an earlier run; fails listing each difference.
    #[arg(long, value_name = "MANIFEST")]
    pub verify: Option<PathBuf>,
    /// Print the manifest totals as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Args)]
pub struct SequenceArgs {
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
    /// Forecast horizons sampled per 50 ms reference time (1–16).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=16))]
    pub horizons: u64,
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
    /// Events per 50 ms window (the network's input span): fewest, median and most.
    pub events_per_window: WindowCounts,
    pub object_count: usize,
    pub renders: u64,
    pub wall_s: f64,
    pub realtime_factor: f64,
    pub files: Vec<PathBuf>,
}

pub fn run(args: SimArgs) -> anyhow::Result<()> {
    match args.command {
        Some(SimCommand::Suite(suite)) => run_suite(suite),
        None => run_sequence(args.sequence),
    }
}

fn run_sequence(args: SequenceArgs) -> anyhow::Result<()> {
    let out = args.out.context("--out is required")?;
    let config = match &args.config {
        Some(path) => load_config(path)?,
        None => args.preset.config(),
    };
    let options = SequenceOptions {
        duration_us: (args.duration_s * 1e6).round() as i64,
        horizons_per_reference: args.horizons as usize,
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

/// Events per window of one sequence.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub struct WindowCounts {
    pub window_ms: u32,
    pub min: u64,
    pub median: u64,
    pub max: u64,
}

impl WindowCounts {
    /// Counts of the consecutive `window_us` windows from 0 that `events` (in time order) span.
    fn of(events: &[evgate_core::Event], duration_us: i64, window_us: i64) -> WindowCounts {
        let windows = (duration_us / window_us).max(1) as usize;
        let mut counts = vec![0u64; windows];
        for event in events {
            let index = (event.t.max(0) / window_us) as usize;
            if let Some(count) = counts.get_mut(index) {
                *count += 1;
            }
        }
        counts.sort_unstable();
        WindowCounts {
            window_ms: (window_us / 1000) as u32,
            min: counts[0],
            median: counts[counts.len() / 2],
            max: counts[counts.len() - 1],
        }
    }
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
    let evg = dir.join("events.evg");
    let mut writer = evgate_io::create(&evg, config.sensor)
        .with_context(|| format!("cannot create {}", evg.display()))?;
    writer
        .write(&sequence.events)
        .with_context(|| format!("cannot write {}", evg.display()))?;
    writer
        .finish()
        .with_context(|| format!("cannot finish {}", evg.display()))?;
    let window_counts = WindowCounts::of(&sequence.events, options.duration_us, 50_000);
    Ok(summarise(
        config,
        seed,
        options,
        &report,
        window_counts,
        wall_s,
        vec![evg, npz],
    ))
}

fn summarise(
    config: &SimConfig,
    seed: u64,
    options: &SequenceOptions,
    report: &SequenceReport,
    events_per_window: WindowCounts,
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
        events_per_window,
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

/// One file of the suite with its size and SHA-256.
#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct ManifestFile {
    path: PathBuf,
    bytes: u64,
    sha256: String,
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct ManifestEntry {
    #[serde(flatten)]
    plan: SuiteEntry,
    events: u64,
    object_event_share: f64,
    on_event_share: f64,
    events_per_window: WindowCounts,
    object_count: usize,
    renders: u64,
    wall_s: f64,
    files: Vec<ManifestFile>,
    /// The complete simulator configuration of the sequence.
    config: SimConfig,
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct SuiteTotals {
    sequences: usize,
    simulated_s: f64,
    events: u64,
    bytes: u64,
    wall_s: f64,
}

#[derive(Serialize)]
#[serde(rename_all = "kebab-case")]
struct Manifest {
    version: &'static str,
    generator: String,
    scale: SuiteScale,
    /// `--per-preset`: the first N sequences of each preset and split; absent for all.
    #[serde(skip_serializing_if = "Option::is_none")]
    per_preset: Option<u64>,
    totals: SuiteTotals,
    /// The photographs of the test-ood split, relative to `--photos`, with their SHA-256.
    photographs: Vec<ManifestFile>,
    sequences: Vec<ManifestEntry>,
}

/// The PNG files of `dir`, in name order; the test-ood split needs at least one.
fn photographs_in(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let entries = fs::read_dir(dir).with_context(|| {
        format!(
            "--photos {}: cannot list the photographs of the test-ood split; \
             run scripts/fetch-photos.sh or name a folder of PNG files",
            dir.display()
        )
    })?;
    let mut photographs = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("cannot list {}", dir.display()))?
            .path();
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
        {
            photographs.push(path);
        }
    }
    photographs.sort();
    if photographs.is_empty() {
        anyhow::bail!(
            "--photos {}: no PNG file there; the test-ood split needs photographs \
             (scripts/fetch-photos.sh)",
            dir.display()
        );
    }
    Ok(photographs)
}

/// The sequences of the suite at `scale` in `splits` (all when empty), the first `per_preset`
/// of each preset in each split where given.
fn selected_plan(scale: SuiteScale, splits: &[Split], per_preset: Option<u64>) -> Vec<SuiteEntry> {
    suite_plan(scale)
        .into_iter()
        .filter(|entry| splits.is_empty() || splits.contains(&entry.split))
        .filter(|entry| per_preset.is_none_or(|count| entry.index < count))
        .collect()
}

fn run_suite(args: SuiteArgs) -> anyhow::Result<()> {
    let plan = selected_plan(args.scale, &args.splits, args.per_preset);
    let photographs = if plan.iter().any(|entry| entry.split == Split::TestOod) {
        photographs_in(&args.photos)?
    } else {
        Vec::new()
    };
    let photograph_files = photographs
        .iter()
        .map(|path| describe_file(path, &args.photos))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let total_us: i64 = plan.iter().map(progress_weight).sum();
    let bar = progress_bar(
        total_us,
        &format!("suite {} ({} sequences)", args.scale, plan.len()),
    );
    let started = std::time::Instant::now();
    let entries = simulate_plan(&plan, &photographs, &args.out, args.jobs as usize, &bar)?;
    bar.finish_and_clear();
    let totals = SuiteTotals {
        sequences: entries.len(),
        simulated_s: entries
            .iter()
            .map(|e| e.plan.duration_us as f64 * 1e-6)
            .sum(),
        events: entries.iter().map(|e| e.events).sum(),
        bytes: entries
            .iter()
            .flat_map(|e| e.files.iter().map(|f| f.bytes))
            .sum(),
        wall_s: started.elapsed().as_secs_f64(),
    };
    let manifest = Manifest {
        version: SUITE_VERSION,
        generator: format!("evgate {}", env!("CARGO_PKG_VERSION")),
        scale: args.scale,
        per_preset: args.per_preset,
        totals,
        photographs: photograph_files,
        sequences: entries,
    };
    let path = args.out.join("manifest.json");
    fs::write(&path, serde_json::to_string_pretty(&manifest)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if let Some(reference) = &args.verify {
        verify_against(&manifest, reference)?;
    }
    let totals = &manifest.totals;
    if args.json {
        println!("{}", serde_json::to_string_pretty(totals)?);
    } else {
        println!(
            "suite {} ({}): {} sequences, {:.1} simulated s, {} events, {:.1} MB, generated in {:.1} s; manifest {}",
            SUITE_VERSION,
            args.scale,
            totals.sequences,
            totals.simulated_s,
            totals.events,
            totals.bytes as f64 / 1e6,
            totals.wall_s,
            path.display()
        );
    }
    Ok(())
}

/// A sequence's share of the progress bar: its simulated time and a quarter for writing it.
fn progress_weight(entry: &SuiteEntry) -> i64 {
    entry.duration_us + entry.duration_us / 4
}

/// Simulates every sequence of `plan` into `out`, `jobs` at a time, and returns their manifest
/// entries in plan order. After a failure no further sequence starts; once the running ones
/// end, the error of the earliest failed sequence in plan order returns.
fn simulate_plan(
    plan: &[SuiteEntry],
    photographs: &[PathBuf],
    out: &Path,
    jobs: usize,
    bar: &ProgressBar,
) -> anyhow::Result<Vec<ManifestEntry>> {
    use std::sync::atomic::{AtomicBool, AtomicI64, AtomicUsize, Ordering};
    use std::sync::Mutex;

    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let finished_us = AtomicI64::new(0);
    let running_us: Vec<AtomicI64> = (0..jobs).map(|_| AtomicI64::new(0)).collect();
    let results: Mutex<Vec<(usize, anyhow::Result<ManifestEntry>)>> = Mutex::new(Vec::new());
    let show_progress = || {
        let running: i64 = running_us.iter().map(|r| r.load(Ordering::Relaxed)).sum();
        bar.set_position((finished_us.load(Ordering::Relaxed) + running) as u64);
    };
    std::thread::scope(|scope| {
        for running in &running_us {
            let (next, failed, finished_us, results) = (&next, &failed, &finished_us, &results);
            let show_progress = &show_progress;
            scope.spawn(move || loop {
                let position = next.fetch_add(1, Ordering::Relaxed);
                if position >= plan.len() || failed.load(Ordering::Relaxed) {
                    break;
                }
                let entry = &plan[position];
                bar.set_message(entry.name.clone());
                let result = simulate_entry(entry, photographs, out, &mut |done| {
                    running.store(done, Ordering::Relaxed);
                    show_progress();
                });
                running.store(0, Ordering::Relaxed);
                finished_us.fetch_add(progress_weight(entry), Ordering::Relaxed);
                show_progress();
                let mut results = results
                    .lock()
                    .unwrap_or_else(|poisoned| poisoned.into_inner());
                match &result {
                    Ok(simulated) => bar.suspend(|| {
                        // A line per sequence, so the progress shows where the bar is not
                        // drawn (a log file).
                        tracing::info!(
                            sequence = %entry.name,
                            done = results.len() + 1,
                            of = plan.len(),
                            events = simulated.events,
                            wall_s = format!("{:.1}", simulated.wall_s),
                            "simulated"
                        )
                    }),
                    Err(_) => failed.store(true, Ordering::Relaxed),
                }
                results.push((position, result));
            });
        }
    });
    let mut results = results
        .into_inner()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    results.sort_by_key(|(position, _)| *position);
    results.into_iter().map(|(_, result)| result).collect()
}

/// Simulates one suite sequence into its folder under `out` and describes it for the manifest.
fn simulate_entry(
    entry: &SuiteEntry,
    photographs: &[PathBuf],
    out: &Path,
    progress: &mut dyn FnMut(i64),
) -> anyhow::Result<ManifestEntry> {
    let dir = out.join(&entry.name);
    fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let config = entry.config(photographs);
    let options = SequenceOptions {
        duration_us: entry.duration_us,
        ..SequenceOptions::default()
    };
    let summary = write_sequence(&config, entry.seed, &options, &dir, &mut |done, _| {
        progress(done)
    })?;
    let files = summary
        .files
        .iter()
        .map(|path| describe_file(path, out))
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(ManifestEntry {
        plan: entry.clone(),
        events: summary.events,
        object_event_share: summary.object_event_share,
        on_event_share: summary.on_event_share,
        events_per_window: summary.events_per_window,
        object_count: summary.object_count,
        renders: summary.renders,
        wall_s: summary.wall_s,
        files,
        config,
    })
}

/// The SHA-256 of each file named in the manifest at `path` (sequence files and photographs).
fn reference_hashes(path: &Path) -> anyhow::Result<std::collections::BTreeMap<String, String>> {
    let text = fs::read_to_string(path)
        .with_context(|| format!("--verify {}: cannot read the manifest", path.display()))?;
    let manifest: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("--verify {}: not a suite manifest", path.display()))?;
    let mut hashes = std::collections::BTreeMap::new();
    let sequences = manifest["sequences"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let files = sequences
        .iter()
        .flat_map(|entry| entry["files"].as_array().cloned().unwrap_or_default())
        .map(|file| (file, ""))
        .chain(
            manifest["photographs"]
                .as_array()
                .cloned()
                .unwrap_or_default()
                .into_iter()
                .map(|file| (file, "photograph ")),
        );
    for (file, kind) in files {
        if let (Some(name), Some(sha)) = (file["path"].as_str(), file["sha256"].as_str()) {
            hashes.insert(format!("{kind}{name}"), sha.to_owned());
        }
    }
    Ok(hashes)
}

/// Fails unless every file this run wrote has the SHA-256 the reference manifest gives it.
fn verify_against(manifest: &Manifest, reference: &Path) -> anyhow::Result<()> {
    let expected = reference_hashes(reference)?;
    let generated = manifest
        .sequences
        .iter()
        .flat_map(|entry| entry.files.iter().map(|file| (String::new(), file)))
        .chain(
            manifest
                .photographs
                .iter()
                .map(|file| ("photograph ".to_owned(), file)),
        );
    let mut differences = Vec::new();
    let mut checked = 0;
    for (kind, file) in generated {
        let name = format!("{kind}{}", file.path.display());
        checked += 1;
        match expected.get(&name) {
            Some(sha) if *sha == file.sha256 => {}
            Some(sha) => differences.push(format!("{name}: {} here, {sha} there", file.sha256)),
            None => differences.push(format!("{name}: not in {}", reference.display())),
        }
    }
    if !differences.is_empty() {
        anyhow::bail!(
            "--verify {}: {} of {checked} files differ:\n{}",
            reference.display(),
            differences.len(),
            differences.join("\n")
        );
    }
    println!(
        "verified: all {checked} files match the SHA-256 of {}",
        reference.display()
    );
    Ok(())
}

/// Size and SHA-256 of a generated file, its path relative to the suite root.
fn describe_file(path: &Path, root: &Path) -> anyhow::Result<ManifestFile> {
    use sha2::{Digest, Sha256};
    let mut file = fs::File::open(path)
        .with_context(|| format!("cannot open {} to hash it", path.display()))?;
    let mut hasher = Sha256::new();
    let bytes = std::io::copy(&mut file, &mut hasher)
        .with_context(|| format!("cannot read {} to hash it", path.display()))?;
    let digest = hasher.finalize();
    Ok(ManifestFile {
        path: path.strip_prefix(root).unwrap_or(path).to_path_buf(),
        bytes,
        sha256: digest.iter().map(|b| format!("{b:02x}")).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use evgate_core::Event;

    #[test]
    fn window_counts_cover_every_window_including_empty_ones() {
        let events: Vec<Event> = [1_000, 2_000, 60_000, 149_999]
            .iter()
            .map(|&t| Event::new(t, 0, 0, true))
            .collect();
        let counts = WindowCounts::of(&events, 200_000, 50_000);
        assert_eq!(
            counts,
            WindowCounts {
                window_ms: 50,
                min: 0,
                median: 1,
                max: 2
            }
        );
    }

    #[test]
    fn verification_names_every_file_whose_hash_differs() {
        let dir = tempfile::tempdir().unwrap();
        let manifest = Manifest {
            version: SUITE_VERSION,
            generator: "test".to_owned(),
            scale: SuiteScale::Small,
            per_preset: None,
            totals: SuiteTotals {
                sequences: 0,
                simulated_s: 0.0,
                events: 0,
                bytes: 0,
                wall_s: 0.0,
            },
            photographs: vec![ManifestFile {
                path: PathBuf::from("moon.png"),
                bytes: 3,
                sha256: "aa".to_owned(),
            }],
            sequences: Vec::new(),
        };
        let reference = dir.path().join("manifest.json");
        let write = |sha: &str| {
            let text = format!(
                "{{\"photographs\": [{{\"path\": \"moon.png\", \"sha256\": \"{sha}\"}}], \"sequences\": []}}"
            );
            fs::write(&reference, text).unwrap();
        };
        write("aa");
        verify_against(&manifest, &reference).unwrap();
        write("bb");
        let error = verify_against(&manifest, &reference)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("photograph moon.png: aa here, bb there"),
            "{error}"
        );
    }

    #[test]
    fn per_preset_takes_the_first_sequences_of_each_preset() {
        let names = |plan: Vec<SuiteEntry>| plan.into_iter().map(|e| e.name).collect::<Vec<_>>();
        assert_eq!(
            names(selected_plan(SuiteScale::Full, &[Split::Train], Some(2))),
            names(selected_plan(SuiteScale::Small, &[Split::Train], None)),
        );
        assert_eq!(
            selected_plan(SuiteScale::Full, &[Split::Val], Some(100)).len(),
            selected_plan(SuiteScale::Full, &[Split::Val], None).len(),
        );
    }

    #[test]
    fn concurrent_jobs_write_the_same_files_in_plan_order() {
        let plan: Vec<SuiteEntry> = selected_plan(SuiteScale::Full, &[Split::Val], Some(1))
            .into_iter()
            .filter(|entry| entry.preset != Preset::Driving)
            .take(4)
            .map(|entry| SuiteEntry {
                duration_us: 200_000,
                ..entry
            })
            .collect();
        let root = tempfile::tempdir().unwrap();
        let hashes = |jobs: usize| {
            let out = root.path().join(jobs.to_string());
            let entries = simulate_plan(&plan, &[], &out, jobs, &ProgressBar::hidden()).unwrap();
            entries
                .iter()
                .flat_map(|entry| {
                    entry
                        .files
                        .iter()
                        .map(|file| (file.path.clone(), file.sha256.clone()))
                })
                .collect::<Vec<_>>()
        };
        let sequential = hashes(1);
        assert_eq!(sequential.len(), 2 * plan.len());
        assert!(sequential[0].0.starts_with(&plan[0].name));
        assert_eq!(hashes(3), sequential);
    }

    #[test]
    fn the_scale_help_states_each_scales_plan() {
        use clap::Args as _;
        let command = SuiteArgs::augment_args(clap::Command::new("suite"));
        let help = command
            .get_arguments()
            .find(|argument| argument.get_id() == "scale")
            .and_then(|argument| argument.get_help())
            .unwrap()
            .to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        for (scale, phrase) in [
            (
                SuiteScale::Small,
                "small ({s} simulated seconds: {n} train, {n} val, {n} test and {n} test-ood",
            ),
            (
                SuiteScale::Full,
                "full ({s} s: {n}, {n}, {n} and {n} per preset)",
            ),
        ] {
            let plan = suite_plan(scale);
            let seconds: i64 = plan.iter().map(|entry| entry.duration_us).sum::<i64>() / 1_000_000;
            let mut expected = phrase.replacen("{s}", &seconds.to_string(), 1);
            for split in Split::ALL {
                let count = plan
                    .iter()
                    .filter(|entry| entry.split == split && entry.preset == Preset::Boxes)
                    .count();
                expected = expected.replacen("{n}", &count.to_string(), 1);
            }
            assert!(help.contains(&expected), "{expected:?} not in {help:?}");
        }
    }

    #[test]
    fn a_folder_without_photographs_is_refused_with_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let error = format!("{:#}", photographs_in(dir.path()).unwrap_err());
        assert!(error.contains("scripts/fetch-photos.sh"), "{error}");
        let missing = dir.path().join("none");
        let error = format!("{:#}", photographs_in(&missing).unwrap_err());
        assert!(error.contains("--photos"), "{error}");
    }
}
