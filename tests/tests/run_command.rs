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
