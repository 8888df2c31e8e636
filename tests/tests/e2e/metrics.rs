//! `--metrics-addr`: Prometheus text scraped from the gate, the inference service and
//! `evgate run` while they run.

use std::time::Duration;

use evgate_e2e::{
    binary, free_local_address, metric_sample, scrape_metrics, start_service, test_model_path,
    unique_names, wait_until, Process,
};

const TIMEOUT: Duration = Duration::from_secs(120);

/// Scrapes `address` until every one of `names` has a positive sample.
fn wait_for_positive(address: &str, names: &[&str]) -> String {
    let mut latest = String::new();
    wait_until(&format!("{names:?} above 0 at {address}"), TIMEOUT, || {
        latest = scrape_metrics(address).unwrap_or_default();
        names
            .iter()
            .all(|name| metric_sample(&latest, name).is_some_and(|value| value > 0.0))
    })
    .unwrap_or_else(|error| panic!("{error}; last scrape:\n{latest}"));
    latest
}

#[test]
fn gate_and_inference_serve_counters_and_histograms_while_running() {
    let names = unique_names("metrics");
    let (gate_address, infer_address) = (free_local_address(), free_local_address());
    let mut gate = start_service(
        "evgate-gate",
        &names,
        &[
            "--metrics-addr",
            &gate_address,
            "--exit-at-end-of-stream",
            "--json",
        ],
    )
    .unwrap();
    let model = test_model_path();
    let mut infer = start_service(
        "evgate-infer",
        &names,
        &[
            "--metrics-addr",
            &infer_address,
            "--model",
            model.to_str().unwrap(),
            "--exit-at-end",
        ],
    )
    .unwrap();
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &[
            "--sim-duration-s",
            "3",
            "--wait-for-subscribers",
            "2",
            "--json",
        ],
    )
    .unwrap();

    let gate_text = wait_for_positive(
        &gate_address,
        &[
            "evgate_events_in_total",
            "evgate_forecasts_received_total",
            "evgate_prediction_age_seconds_count",
        ],
    );
    assert!(
        gate_text.contains("# TYPE evgate_events_kept counter"),
        "{gate_text}"
    );
    assert!(
        gate_text.contains("evgate_prediction_age_seconds_bucket{le="),
        "{gate_text}"
    );
    let infer_text = wait_for_positive(
        &infer_address,
        &[
            "evgate_inference_seconds_count",
            "evgate_forecast_latency_seconds_count",
            "evgate_forecasts_published_total",
            "evgate_windows_closed_total",
        ],
    );
    assert!(
        infer_text.contains("# TYPE evgate_inference_seconds histogram"),
        "{infer_text}"
    );

    ingest.summary(TIMEOUT).unwrap();
    gate.summary(TIMEOUT).unwrap();
    infer.summary(TIMEOUT).unwrap();
}

#[test]
fn evgate_run_serves_the_pipeline_counters() {
    let address = free_local_address();
    let mut run = Process::start(
        &binary("evgate").unwrap(),
        &[
            "run",
            "--duration",
            "3",
            "--metrics-addr",
            &address,
            "--json",
            "--status-interval-ms",
            "50",
        ],
    )
    .unwrap();
    let text = wait_for_positive(
        &address,
        &["evgate_events_in_total", "evgate_inference_seconds_count"],
    );
    assert!(text.contains("evgate_events_suppressed_total"), "{text}");
    let summary = run.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "end-of-stream");
}
