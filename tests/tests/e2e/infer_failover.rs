//! The real inference service killed mid-stream: the gate keeps gating under its no-forecast
//! policy and judges by forecasts again once a new inference process publishes.
//! Needs the bundled model (models/evgate-S.onnx, or EVGATE_TEST_MODEL) and `.ort/`.

use std::time::Duration;

use evgate_e2e::{start_service, test_model_path, unique_names, wait_until};
use evgate_ipc::{create_node, LatestSubscriber, PipelineStats, Stream};

const TIMEOUT: Duration = Duration::from_secs(120);

#[test]
fn killing_infer_leaves_the_gate_on_its_policy_and_a_new_infer_takes_over() {
    let model = test_model_path();
    let model = model.to_str().unwrap();
    let names = unique_names("failover");
    let node = create_node("failover-test").unwrap();
    let stats = LatestSubscriber::<PipelineStats>::open(&node, &names, Stream::Stats).unwrap();
    let start_infer = || start_service("evgate-infer", &names, &["--model", model]).unwrap();

    let mut gate = start_service(
        "evgate-gate",
        &names,
        &[
            "--no-forecast",
            "pass",
            "--stats-interval-ms",
            "20",
            "--json",
        ],
    )
    .unwrap();
    let mut infer = start_infer();
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &["--sim-duration-s", "30", "--wait-for-subscribers", "2"],
    )
    .unwrap();

    let mut latest = PipelineStats::default();
    let mut wait_for = |what: &str, accept: &dyn Fn(&PipelineStats) -> bool| {
        wait_until(what, TIMEOUT, || {
            if let Some(fresh) = stats.latest().unwrap() {
                latest = fresh;
            }
            accept(&latest)
        })
        .unwrap();
        latest
    };
    let judged = |s: &PipelineStats| s.kept_events + s.suppressed_events;

    let before_kill = wait_for("forecasts judging events", &|s| {
        s.forecasts_used > 0 && judged(s) > 0
    });
    infer.signal(libc::SIGKILL);
    infer.wait(TIMEOUT).unwrap();

    // Without forecasts the latest one expires and the policy passes the events.
    let without = wait_for("events passed by the policy", &|s| {
        s.unjudged_passed_events > before_kill.unjudged_passed_events + 10_000
    });
    assert!(gate.is_running(), "the gate must outlive the inference");

    let mut infer = start_infer();
    let after = wait_for("a new inference's forecasts judging events again", &|s| {
        s.forecasts_received > without.forecasts_received && judged(s) > judged(&without)
    });
    assert!(after.is_balanced());
    assert_eq!(after.dropped_events, 0);

    ingest.signal(libc::SIGTERM);
    ingest.wait(TIMEOUT).unwrap();
    infer.signal(libc::SIGTERM);
    gate.signal(libc::SIGTERM);
    let summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(summary["ended-by"], "signal");
    assert_eq!(summary["balanced"], true);
}
