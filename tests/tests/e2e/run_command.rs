//! `evgate run`: the three services as children, a summary with counters and per-event scores.

use std::time::Duration;

use evgate_e2e::{binary, test_model_path, u64_at, Process};

const TIMEOUT: Duration = Duration::from_secs(120);

/// `evgate`, built with the services it starts (it finds them next to its own executable).
fn evgate() -> std::path::PathBuf {
    binary("evgate").unwrap()
}

/// `evgate run ARGS --json` to the end of its stream, every event accounted for; its summary.
fn run_to_the_end(args: &[&str]) -> serde_json::Value {
    let mut all = vec!["run"];
    all.extend_from_slice(args);
    all.extend(["--json", "--status-interval-ms", "50"]);
    let summary = Process::start(&evgate(), &all)
        .unwrap()
        .summary(TIMEOUT)
        .unwrap();
    assert_eq!(summary["ended-by"], "end-of-stream");
    assert_eq!(summary["balanced"], true);
    summary
}

#[test]
fn run_without_inference_passes_everything_and_scores_it_against_the_labels() {
    let summary = run_to_the_end(&["--no-infer", "--duration", "0.1", "--fast"]);
    let input = u64_at(&summary, "/stats/input-events");
    assert!(input > 0);
    assert_eq!(u64_at(&summary, "/stats/unjudged-passed-events"), input);
    // Every event was scored; with nothing suppressed, recall is 1 and nothing is negative.
    assert_eq!(u64_at(&summary, "/scores/events-scored"), input);
    assert_eq!(u64_at(&summary, "/scores/false-negative"), 0);
    assert_eq!(u64_at(&summary, "/scores/true-negative"), 0);
    assert_eq!(summary["scores"]["recall"], 1.0);
    assert_eq!(
        u64_at(&summary, "/services/evgate-ingest/events-published"),
        input
    );
}

#[test]
fn run_with_the_bundled_model_reports_inference_and_scores() {
    let model = test_model_path();
    let summary = run_to_the_end(&["--duration", "0.3", "--model", model.to_str().unwrap()]);
    assert!(u64_at(&summary, "/stats/forecasts-received") > 0);
    // Which events a forecast judges depends on how far inference lags the stream on this
    // machine; that it ran and reported is not.
    assert!(summary["stats"]["latest-model-runtime-us"].is_number());
    assert!(u64_at(&summary, "/services/evgate-infer/forecasts-published") > 0);
    assert_eq!(
        u64_at(&summary, "/scores/events-scored"),
        u64_at(&summary, "/stats/input-events")
    );
    assert!(summary["scores"]["precision"].is_number());
}

#[test]
fn a_640x480_recording_runs_with_the_shipped_640x480_export_by_default() {
    let recording = evgate_e2e::workspace_root().join("../shared/data/real/evt2_640x480.raw");
    let summary = run_to_the_end(&["--input", recording.to_str().unwrap()]);
    assert_eq!(u64_at(&summary, "/stats/input-events"), 521_252);
    let infer = &summary["services"]["evgate-infer"];
    let model = infer["model"].as_str().unwrap();
    assert!(model.ends_with("models/evgate-S-640x480.onnx"), "{model}");
    assert!(u64_at(&summary, "/services/evgate-infer/forecasts-published") > 0);
}

#[test]
fn a_320x240_recording_runs_padded_into_the_shipped_346x260_export() {
    let recording = evgate_e2e::workspace_root().join("../shared/data/real/sample.aedat4");
    let summary = run_to_the_end(&["--input", recording.to_str().unwrap()]);
    let input = u64_at(&summary, "/stats/input-events");
    assert!(input > 0);
    let model = summary["services"]["evgate-infer"]["model"]
        .as_str()
        .unwrap();
    assert!(model.ends_with("models/evgate-S.onnx"), "{model}");
    assert!(u64_at(&summary, "/services/evgate-infer/forecasts-published") > 0);
    assert_eq!(
        u64_at(&summary, "/services/evgate-ingest/events-published"),
        input
    );
}

#[test]
fn a_1280x720_recording_runs_binned_4x4_into_the_shipped_346x260_export() {
    // 8.8 ms of a Prophesee Gen4 recording, shorter than one window: looped, with event time
    // going on across passes, it closes windows all the same.
    let recording = evgate_e2e::workspace_root().join("../shared/data/real/evt3_sample.raw");
    let summary = Process::start(
        &evgate(),
        &[
            "run",
            "--input",
            recording.to_str().unwrap(),
            "--loop",
            "--duration",
            "4",
            "--json",
            "--status-interval-ms",
            "50",
        ],
    )
    .unwrap()
    .summary(TIMEOUT)
    .unwrap();
    assert_eq!(summary["ended-by"], "duration");
    let infer = &summary["services"]["evgate-infer"];
    let model = infer["model"].as_str().unwrap();
    assert!(model.ends_with("models/evgate-S.onnx"), "{model}");
    assert_eq!(infer["downsample"], 4);
    assert!(u64_at(&summary, "/services/evgate-infer/forecasts-published") > 0);
    assert!(u64_at(&summary, "/stats/forecasts-received") > 0);
    assert!(u64_at(&summary, "/services/evgate-ingest/passes") > 1);
}

#[test]
fn the_example_config_file_runs_and_a_flag_overrides_its_keys() {
    let config = evgate_e2e::workspace_root().join("examples/config/run.toml");
    let config = config.to_str().unwrap();
    let from_file = run_to_the_end(&["--config", config, "--duration", "0.2", "--fast"]);
    assert_eq!(
        from_file["source"],
        "simulated camera, preset tabletop seed 7"
    );
    let overridden = run_to_the_end(&[
        "--config",
        config,
        "--preset",
        "boxes",
        "--duration",
        "0.2",
        "--fast",
        "--no-infer",
    ]);
    assert_eq!(
        overridden["source"],
        "simulated camera, preset boxes seed 7"
    );
}

#[test]
fn a_config_file_with_an_unknown_key_is_refused_naming_it() {
    let config = tempfile::NamedTempFile::with_suffix(".toml").unwrap();
    std::fs::write(config.path(), "preset = \"boxes\"\ndration = 1.0\n").unwrap();
    let output = std::process::Command::new(evgate())
        .args(["run", "--config", config.path().to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(
        message.contains("unknown key `dration`") && message.contains("accepted keys: input,"),
        "{message}"
    );
}

/// The verdicts of a `--keep-bits` file (`evgate eval --help`).
const KEPT: u8 = 1;
const NOT_GATED: u8 = 2;

/// One `--keep-bits` file: a uint8 per event.
fn read_verdicts(path: &std::path::Path) -> Vec<u8> {
    let mut file = std::fs::File::open(path).unwrap();
    evgate_io::npy::NpyArray::read(&mut file)
        .unwrap()
        .to_vec::<u8>()
        .unwrap()
}

#[test]
fn eval_and_a_lock_step_run_keep_exactly_the_same_events_of_a_recording() {
    let recording = evgate_e2e::workspace_root().join("../shared/data/real/sample.aedat4");
    let model = test_model_path();
    let out = tempfile::tempdir().unwrap();
    let settings = out.path().join("eval.json");
    std::fs::write(
        &settings,
        r#"{"horizons-ms": [0, 10, 20, 30, 40, 50], "headline-horizon-ms": 50, "gate-span-ms": 50}"#,
    )
    .unwrap();
    let path = |name: &str| out.path().join(name).to_str().unwrap().to_owned();
    Process::start(
        &evgate(),
        &[
            "eval",
            "--input",
            recording.to_str().unwrap(),
            "--model",
            model.to_str().unwrap(),
            "--config",
            &path("eval.json"),
            "--report",
            &path("report"),
            "--keep-bits",
            &path("eval-verdicts"),
            "--json",
        ],
    )
    .unwrap()
    .summary(TIMEOUT)
    .unwrap();
    let summary = run_to_the_end(&[
        "--input",
        recording.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
        "--lock-step",
        "--horizons-ms",
        "0,10,20,30,40,50",
        "--keep-bits",
        &path("run-verdicts.npy"),
        "--fast",
    ]);
    assert_eq!(
        u64_at(&summary, "/services/evgate-infer/windows-skipped-busy"),
        0
    );

    let evaluated: Vec<_> = std::fs::read_dir(out.path().join("eval-verdicts"))
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .collect();
    assert_eq!(evaluated.len(), 1, "{evaluated:?}");
    let by_eval = read_verdicts(&evaluated[0]);
    let by_run = read_verdicts(out.path().join("run-verdicts.npy").as_path());
    assert_eq!(by_eval.len(), by_run.len());
    let gated: Vec<usize> = (0..by_eval.len())
        .filter(|&i| by_eval[i] != NOT_GATED)
        .collect();
    let kept = gated.iter().filter(|&&i| by_eval[i] == KEPT).count();
    // Both fates occur, so agreement is not that of an empty or a full mask.
    assert!(
        kept > 0 && kept < gated.len() && gated.len() > by_eval.len() / 2,
        "{kept} kept of {} gated of {} events",
        gated.len(),
        by_eval.len()
    );
    let differing: Vec<usize> = gated
        .iter()
        .copied()
        .filter(|&i| by_eval[i] != by_run[i])
        .collect();
    assert!(
        differing.is_empty(),
        "{} of {} gated events differ, first at {:?}",
        differing.len(),
        gated.len(),
        &differing[..differing.len().min(5)]
    );
}
