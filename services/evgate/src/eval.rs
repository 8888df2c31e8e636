//! `evgate eval`: scores the model and the baselines (OMS, no forecast, linear extrapolation,
//! oracle) on a split of the simulator's suite or on labelled sequences, and writes the report
//! (JSON, Markdown tables, PNG plots).

#[path = "eval_models.rs"]
mod models;

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use evgate_core::SensorSize;
use evgate_eval::{
    read_recording, write_report, EvalConfig, Evaluation, FlopTable, InputOptions, LoadedModel,
    Report,
};
use evgate_model::{Forecaster, MaskRule, ModelRuntime, Provider, RuntimeOptions};
use indicatif::{ProgressBar, ProgressStyle};

use models::{select_models, ModelSpec, DEFAULT_MODEL};

/// Where the network's parameters and GFLOPs are looked up when `--model-flops` is not given:
/// the committed table first, then the training code's output folder.
const DEFAULT_FLOPS_TABLES: [&str; 2] = [
    "evidence/models/flops.json",
    "models/training/runs/flops.json",
];

/// Evaluate forecasts and baselines on labelled sequences and write a report.
#[derive(Args)]
pub struct EvalArgs {
    /// Suite split to evaluate: train, val, test or test-ood (sequences under
    /// SUITE/SPLIT/*/sequence.npz). Choices are made on val; test-ood only reports.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Root folder of the simulator's suite (as written by `evgate sim suite`).
    #[arg(long, default_value = "data/suite")]
    pub suite: PathBuf,
    /// Recordings to evaluate instead of a split (repeatable): a simulator sequence (.npz,
    /// docs/sequence-format.md; every metric); an EVIMO recording (another .npz, an EVIMO2
    /// sequence folder or an EVIMO text folder; masks at the ground-truth frames, no per-event
    /// scores); or any event file evgate-io reads (DSEC events.h5 when built with the `dsec`
    /// feature, RAW, AEDAT 4, …; no ground truth: kept ratio, event rates, runtime and
    /// prediction age only).
    #[arg(long = "input", visible_alias = "sequence", value_name = "PATH")]
    pub inputs: Vec<PathBuf>,
    /// Averaging group of every --input recording (default: a simulator sequence's preset,
    /// else the name of the folder holding the file or sequence folder).
    #[arg(long)]
    pub group: Option<String>,
    /// Sensor size WxH for event files whose header gives none (e.g. 640x480).
    #[arg(long, value_parser = evgate_io::header::parse_sensor_flag)]
    pub sensor: Option<SensorSize>,
    /// ONNX model as NAME=PATH or PATH (named by its file stem), repeatable. The first is the
    /// model under test: its current mask feeds the no-forecast and linear baselines. Size,
    /// ATC variant and training steps come from each file's `evgate.*` metadata and label its
    /// rows in the ablation (Table VI) and model-size (Table VII) tables. Default:
    /// models/evgate-S.onnx when it exists.
    #[arg(long = "model", value_name = "[NAME=]PATH")]
    pub models: Vec<ModelSpec>,
    /// Also evaluate every .onnx file of this folder (named by file stem, after the --model
    /// ones; files already given and copies of a loaded model are skipped), e.g.
    /// models/ablation.
    #[arg(long, value_name = "DIR")]
    pub ablation_models: Option<PathBuf>,
    /// Evaluate the baselines only (no-forecast and linear then start from the ground truth).
    #[arg(long, conflicts_with_all = ["models", "ablation_models"])]
    pub no_model: bool,
    /// Folder for report.json, report.md and the plots (created if missing).
    #[arg(long, default_value = "reports/eval")]
    pub report: PathBuf,
    /// JSON evaluation settings (kebab-case keys of EvalConfig; missing keys keep defaults,
    /// see docs/evaluation.md).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Evaluate at most this many sequences (taken round-robin over presets, so every preset
    /// is represented).
    #[arg(long)]
    pub max_sequences: Option<usize>,
    /// Score only the first this-many seconds of each sequence.
    #[arg(long)]
    pub max_seconds: Option<f64>,
    /// Only sequences of these presets (repeatable), e.g. --preset boxes --preset fast.
    #[arg(long = "preset", value_name = "NAME")]
    pub presets: Vec<String>,
    /// Execution provider of the model: cpu, cuda or auto.
    #[arg(long, default_value = "cpu")]
    pub provider: Provider,
    /// ONNX Runtime threads per operator.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// GFLOPs per model size (the JSON of `python -m evgate_train.flops`) for tables III and
    /// VII, used where a row's parameter count is the model file's (within the 1 % that folded
    /// batch norm explains); default:
    /// evidence/models/flops.json, else models/training/runs/flops.json, when present.
    #[arg(long)]
    pub model_flops: Option<PathBuf>,
    /// Also write the first model's verdict on every event of each recording to
    /// DIR/<sequence>.npy: one uint8 per event in file order, 1 kept, 0 suppressed, 2 not
    /// gated (outside every [t, t + gate-span) or off the sensor). `evgate run --lock-step
    /// --keep-bits` writes the live pipeline's for comparison.
    #[arg(long, value_name = "DIR")]
    pub keep_bits: Option<PathBuf>,
    /// Print the overall summary as JSON on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let mut config = match &args.config {
        Some(path) => {
            let text = fs::read_to_string(path)
                .with_context(|| format!("cannot read evaluation config {}", path.display()))?;
            serde_json::from_str::<EvalConfig>(&text).with_context(|| {
                format!(
                    "evaluation config {}: invalid JSON or unknown key",
                    path.display()
                )
            })?
        }
        None => EvalConfig::default(),
    };
    if let Some(seconds) = args.max_seconds {
        if seconds.is_nan() || seconds <= 0.0 {
            bail!("--max-seconds must be > 0, got {seconds}");
        }
        config.max_seconds_per_sequence = Some(seconds);
    }

    let (split, mut paths) = if args.inputs.is_empty() {
        (
            Some(args.split.clone()),
            split_sequences(&args.suite, &args.split)?,
        )
    } else {
        (None, args.inputs.clone())
    };
    paths = select(paths, &args.presets, args.max_sequences);
    if paths.is_empty() {
        bail!(
            "no sequence left to evaluate (presets {:?}, --max-sequences {:?})",
            args.presets,
            args.max_sequences
        );
    }

    let model_specs = if args.no_model {
        Vec::new()
    } else {
        select_models(
            &args.models,
            args.ablation_models.as_deref(),
            Path::new(DEFAULT_MODEL),
        )?
    };
    let options = RuntimeOptions {
        provider: args.provider,
        intra_threads: args.threads,
        ..RuntimeOptions::default()
    };
    let mut models: Vec<LoadedModel> = Vec::new();
    for spec in &model_specs {
        let runtime = ModelRuntime::load(&spec.path, options.clone())
            .with_context(|| format!("cannot load model {}", spec.path.display()))?;
        // A folder of variants may hold a copy of the model under test: evaluate it once.
        let same = models
            .iter()
            .find(|m| m.forecaster.runtime().model_id() == runtime.model_id());
        if let (true, Some(same)) = (spec.from_folder, same) {
            tracing::info!(
                path = %spec.path.display(),
                same_as = %same.label,
                "skipped: the same file content as a model already loaded"
            );
            continue;
        }
        let metadata = runtime.metadata();
        tracing::info!(
            model = %spec.label,
            path = %spec.path.display(),
            size = metadata.model_size.label(),
            atc = ?metadata.atc,
            steps = metadata.train_steps,
            "loaded"
        );
        let rule = MaskRule::of(metadata);
        models.push(LoadedModel {
            label: spec.label.clone(),
            forecaster: Forecaster::new(runtime, rule, 1),
        });
    }

    let input_options = InputOptions {
        group: args.group.clone(),
        sensor_size: args.sensor,
    };
    let mut evaluation = Evaluation::new(config, models)?;
    if let Some(directory) = &args.keep_bits {
        fs::create_dir_all(directory)
            .with_context(|| format!("--keep-bits {}: cannot create it", directory.display()))?;
        evaluation.record_verdicts();
    }
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} windows ({eta} left) {msg}",
        )
        .expect("valid progress template"),
    );
    for (index, path) in paths.iter().enumerate() {
        bar.set_message(format!(
            "sequence {}/{}: loading {}",
            index + 1,
            paths.len(),
            path.display()
        ));
        let recording = read_recording(path, evaluation.config(), &input_options)?;
        bar.inc_length(evaluation.reference_count(&recording) as u64);
        bar.set_message(format!(
            "sequence {}/{}: {}",
            index + 1,
            paths.len(),
            path.display()
        ));
        let result = evaluation.evaluate(&recording, || bar.inc(1))?;
        for left_out in &result.models_not_run {
            tracing::warn!(
                sequence = %result.name,
                model = %left_out.method,
                sensor = %left_out.padded_sensor,
                model_input = %left_out.model_input,
                "the recording is larger than the model's input: the model (and the baselines on \
                 its mask, if it is the first) sit this recording out"
            );
        }
        let name = result.name.clone();
        tracing::info!(
            sequence = %result.name,
            preset = %result.preset,
            references = result.references,
            ground_truth = ?result.ground_truth,
            "evaluated"
        );
        if let (Some(directory), Some(record)) = (&args.keep_bits, evaluation.keep_record()) {
            let path = directory.join(format!("{}.npy", name.replace('/', "_")));
            write_verdicts(&path, &record.verdicts)
                .with_context(|| format!("--keep-bits: cannot write {}", path.display()))?;
        }
    }
    bar.finish_and_clear();

    let mut report = evaluation.finish(split)?;
    let flops_path = args.model_flops.clone().or_else(|| {
        DEFAULT_FLOPS_TABLES
            .iter()
            .map(PathBuf::from)
            .find(|p| p.is_file())
    });
    if let Some(path) = flops_path {
        let mismatched = FlopTable::read(&path)?.apply(&mut report, &path);
        if !mismatched.is_empty() {
            tracing::warn!(
                table = %path.display(),
                models = ?mismatched,
                "the FLOP table's row for these models' size has another parameter count (another \
                 architecture): their GFLOPs are left out"
            );
        }
    }
    let written = write_report(&report, &args.report)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report.overall)?);
    } else {
        print_summary(&report);
        println!("wrote {}", written.markdown.display());
        println!("wrote {}", written.json.display());
        for plot in &written.plots {
            println!("wrote {}", plot.display());
        }
    }
    Ok(())
}

/// The sequences of one split: SUITE/SPLIT/<name>/sequence.npz and SUITE/SPLIT/*.npz, sorted.
fn split_sequences(suite: &Path, split: &str) -> anyhow::Result<Vec<PathBuf>> {
    split.parse::<evgate_sim::Split>()?;
    let folder = suite.join(split);
    let entries = fs::read_dir(&folder).with_context(|| {
        format!(
            "cannot list split folder {} (generate the suite with `evgate sim suite`, or pass \
             --suite or --sequence)",
            folder.display()
        )
    })?;
    let mut paths = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("cannot list {}", folder.display()))?
            .path();
        // The suite generator writes into `<name>.partial` and renames when the sequence is done.
        if path.extension().is_some_and(|e| e == "partial") {
            continue;
        }
        let nested = path.join("sequence.npz");
        if nested.is_file() {
            paths.push(nested);
        } else if path.extension().is_some_and(|e| e == "npz") {
            paths.push(path);
        }
    }
    if paths.is_empty() {
        bail!(
            "no labelled sequence (*/sequence.npz or *.npz) in {}",
            folder.display()
        );
    }
    paths.sort();
    Ok(paths)
}

/// The preset a suite path belongs to, from its folder name `<preset>-<seed>`.
fn preset_of(path: &Path) -> Option<String> {
    let folder = if path.file_name().is_some_and(|n| n == "sequence.npz") {
        path.parent()?.file_name()?
    } else {
        path.file_stem()?
    };
    let name = folder.to_string_lossy();
    Some(
        name.rsplit_once('-')
            .map_or(name.as_ref(), |(preset, _)| preset)
            .to_owned(),
    )
}

/// Keeps the wanted presets and at most `max` sequences, taken round-robin over presets.
fn select(paths: Vec<PathBuf>, presets: &[String], max: Option<usize>) -> Vec<PathBuf> {
    let mut groups: Vec<(String, Vec<PathBuf>)> = Vec::new();
    for path in paths {
        let preset = preset_of(&path).unwrap_or_default();
        if !presets.is_empty() && !presets.contains(&preset) {
            continue;
        }
        match groups.iter_mut().find(|(p, _)| *p == preset) {
            Some((_, members)) => members.push(path),
            None => groups.push((preset, vec![path])),
        }
    }
    let limit = max.unwrap_or(usize::MAX);
    let mut chosen = Vec::new();
    let mut round = 0;
    while chosen.len() < limit {
        let before = chosen.len();
        for (_, members) in &groups {
            if let Some(path) = members.get(round) {
                if chosen.len() < limit {
                    chosen.push(path.clone());
                }
            }
        }
        if chosen.len() == before {
            break;
        }
        round += 1;
    }
    chosen
}

fn percent(value: Option<f64>) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{:.1}", v * 100.0))
}

/// One uint8 per event as a `.npy` file.
pub fn write_verdicts(path: &std::path::Path, verdicts: &[u8]) -> anyhow::Result<()> {
    let mut file = std::io::BufWriter::new(fs::File::create(path)?);
    evgate_io::npy::NpyArray::from_slice(&[verdicts.len()], verdicts).write(&mut file)?;
    std::io::Write::flush(&mut file)?;
    Ok(())
}

fn print_summary(report: &Report) {
    let headline = report.config.headline_horizon_ms;
    println!(
        "{} sequences, headline horizon {headline} ms (scores in %):",
        report.sequences.len()
    );
    println!(
        "{:<36} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>9} {:>9} {:>9}",
        "method", "mIoU", "R@0.5", "SR@0.5", "pIoU", "evt F1", "kept", "run ms", "median", "age ms"
    );
    for method in &report.methods {
        let Some(summary) = report.overall.get(&method.name) else {
            continue;
        };
        let at = summary.at(headline);
        let milliseconds =
            |value: Option<f64>| value.map_or_else(|| "–".to_owned(), |v| format!("{v:.2}"));
        println!(
            "{:<36} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>9} {:>9} {:>9}",
            method.name,
            percent(at.and_then(|h| h.mean_iou)),
            percent(at.and_then(|h| h.instance_recall)),
            percent(at.and_then(|h| h.success_rate)),
            percent(summary.point_iou),
            percent(summary.events.f1),
            percent(summary.kept.kept_ratio),
            milliseconds(summary.runtime_ms_mean),
            milliseconds(summary.runtime_ms_median),
            summary
                .prediction_age_ms
                .map_or_else(|| "–".to_owned(), |v| format!("{v:.1}")),
        );
    }
    if let Some(best) = &report.oms_sweep.best {
        println!(
            "OMS best of sweep: centre {} surround {} threshold {}: mIoU {} R@0.5 {}",
            best.parameters.centre_radius,
            best.parameters.surround_radius,
            best.parameters.threshold,
            percent(best.mean_iou),
            percent(best.instance_recall)
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_come_from_suite_folder_names() {
        assert_eq!(
            preset_of(Path::new("data/test/boxes-300001/sequence.npz")).as_deref(),
            Some("boxes")
        );
        assert_eq!(
            preset_of(Path::new("x/fast-3.npz")).as_deref(),
            Some("fast")
        );
    }

    #[derive(clap::Parser)]
    struct Command {
        #[command(flatten)]
        eval: EvalArgs,
    }

    #[test]
    fn an_event_file_without_ground_truth_gives_a_report_with_null_truth_metrics() {
        use clap::Parser;
        let folder = tempfile::tempdir().unwrap();
        let input = folder.path().join("events.csv");
        let text: String = (0..3000)
            .map(|k| format!("{} {} {} {}\n", k * 100, k * 7 % 40, k * 3 % 30, k % 2))
            .collect();
        fs::write(&input, text).unwrap();
        let report_folder = folder.path().join("report");
        let command = Command::parse_from([
            "eval".as_ref(),
            "--input".as_ref(),
            input.as_os_str(),
            "--sensor".as_ref(),
            "40x30".as_ref(),
            "--group".as_ref(),
            "drive".as_ref(),
            "--no-model".as_ref(),
            "--report".as_ref(),
            report_folder.as_os_str(),
        ]);
        run(command.eval).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(report_folder.join("report.json")).unwrap())
                .unwrap();
        let sequence = &json["sequences"][0];
        assert_eq!(sequence["ground-truth"], "events-only");
        assert_eq!(sequence["preset"], "drive");
        let oms = &json["overall"]["oms"];
        assert!(oms["horizons"][10]["mean-iou"].is_null());
        assert!(oms["point-iou"].is_null());
        assert!(oms["kept"]["event-rate-hz"].as_f64().unwrap() > 0.0);
        let markdown = fs::read_to_string(report_folder.join("report.md")).unwrap();
        assert!(markdown.contains("| drive | n/a — no masks in this recording |"));
    }

    #[test]
    fn selection_is_round_robin_over_presets() {
        let paths: Vec<PathBuf> = ["a-1", "a-2", "a-3", "b-1", "c-1", "c-2"]
            .iter()
            .map(|n| PathBuf::from(format!("test/{n}/sequence.npz")))
            .collect();
        let chosen = select(paths.clone(), &[], Some(4));
        let names: Vec<String> = chosen.iter().map(|p| preset_of(p).unwrap()).collect();
        assert_eq!(names, ["a", "b", "c", "a"]);
        let only_c = select(paths, &["c".to_owned()], None);
        assert_eq!(only_c.len(), 2);
    }
}
