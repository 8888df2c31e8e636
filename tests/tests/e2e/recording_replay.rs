//! A real recording replayed by evgate-ingest reaches the gate event for event, in real time.

use std::path::PathBuf;
use std::time::Duration;

use evgate_e2e::{start_service, u64_at, unique_names, workspace_root};

const TIMEOUT: Duration = Duration::from_secs(90);

/// The shared 9 ms EVT 3.0 recording and its decoded events.
fn evt3_sample() -> (PathBuf, Vec<evgate_core::Event>) {
    let recording = workspace_root().join("../shared/data/real/evt3_sample.raw");
    let mut reader = evgate_io::open(&recording).expect("the shared EVT 3.0 sample decodes");
    let events = evgate_io::read_all(reader.as_mut()).expect("the shared EVT 3.0 sample decodes");
    (recording, events)
}

#[test]
fn a_real_evt3_recording_reaches_the_gate_event_for_event_at_its_own_pace() {
    let (recording, decoded) = evt3_sample();
    let span_s = (decoded.last().unwrap().t - decoded[0].t) as f64 * 1e-6;

    let names = unique_names("replay");
    let mut gate = start_service(
        "evgate-gate",
        &names,
        &["--json", "--exit-at-end-of-stream"],
    )
    .unwrap();
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &[
            "--json",
            "--input",
            recording.to_str().unwrap(),
            "--wait-for-subscribers",
            "1",
        ],
    )
    .unwrap();
    let ingest_summary = ingest.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(
        u64_at(&ingest_summary, "/events-published"),
        decoded.len() as u64
    );
    assert_eq!(u64_at(&ingest_summary, "/sensor-width"), 1280);
    assert_eq!(
        u64_at(&gate_summary, "/stats/input-events"),
        decoded.len() as u64
    );
    assert_eq!(gate_summary["balanced"], true);
    // Paced by the timestamps: publishing took at least the recording's span.
    let wall_s = ingest_summary["wall-s"].as_f64().unwrap();
    assert!(
        wall_s >= span_s * 0.9,
        "published {span_s:.3} s of events in {wall_s:.3} s"
    );
}

#[test]
fn a_looping_replay_runs_until_sigint_and_then_ends_the_stream_cleanly() {
    let (recording, decoded) = evt3_sample();
    let per_pass = decoded.len() as u64;

    let names = unique_names("loop");
    let node = evgate_ipc::create_node("loop-test").unwrap();
    let stats = evgate_ipc::LatestSubscriber::<evgate_ipc::PipelineStats>::open(
        &node,
        &names,
        evgate_ipc::Stream::Stats,
    )
    .unwrap();
    let mut gate = start_service(
        "evgate-gate",
        &names,
        &[
            "--json",
            "--exit-at-end-of-stream",
            "--stats-interval-ms",
            "10",
        ],
    )
    .unwrap();
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &[
            "--json",
            "--fast",
            "--loop",
            "--input",
            recording.to_str().unwrap(),
            "--wait-for-subscribers",
            "1",
        ],
    )
    .unwrap();
    evgate_e2e::wait_until("three passes through the gate", TIMEOUT, || {
        stats
            .latest()
            .unwrap()
            .is_some_and(|s| s.input_events > 3 * per_pass)
    })
    .unwrap();
    ingest.signal(libc::SIGINT);
    let ingest_summary = ingest.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    assert_eq!(ingest_summary["ended-by"], "signal");
    assert!(u64_at(&ingest_summary, "/passes") >= 3);
    // The stream ended with an end-of-stream batch: the gate saw it and exited by itself.
    assert_eq!(gate_summary["ended-by"], "end-of-stream");
    assert_eq!(
        u64_at(&gate_summary, "/stats/input-events"),
        u64_at(&ingest_summary, "/events-published")
    );
    assert_eq!(gate_summary["balanced"], true);
}

#[test]
fn a_reader_that_connects_after_the_whole_recording_was_published_still_gets_all_of_it() {
    let (recording, decoded) = evt3_sample();
    let events = decoded.len() as u64;

    let names = unique_names("late-reader");
    let node = evgate_ipc::create_node("late-reader-test").unwrap();
    let subscriber =
        evgate_ipc::SliceSubscriber::<evgate_core::Event, evgate_ipc::BatchHeader>::open(
            &node,
            &names,
            evgate_ipc::Stream::Events,
            &evgate_ipc::Qos::default(),
        )
        .unwrap();
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &[
            "--json",
            "--fast",
            "--input",
            recording.to_str().unwrap(),
            "--wait-for-subscribers",
            "1",
        ],
    )
    .unwrap();
    // The 9 ms recording is published within this pause, before the reader's first receive
    // connects it to the publisher; the publisher must still be there when it does.
    std::thread::sleep(Duration::from_secs(1));
    let mut received = 0;
    let mut ended = false;
    evgate_e2e::wait_until("the end-of-stream batch", TIMEOUT, || {
        while let Some(sample) = subscriber.receive().unwrap() {
            received += sample.payload().len() as u64;
            ended |= sample.user_header().is_end_of_stream();
        }
        ended
    })
    .unwrap();
    drop(subscriber);
    let summary = ingest.summary(TIMEOUT).unwrap();
    assert_eq!(received, events);
    assert_eq!(u64_at(&summary, "/events-published"), events);
}

/// Issue 15: a CSV time near i64::MAX made evgate-ingest publish nothing and never end, and a
/// CSV without geometry read as a 65535×65535 sensor that the inference could not pad.
#[test]
fn hostile_text_input_ends_with_its_repairs_counted() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("t.csv");
    std::fs::write(&text, "1,1,1,1\n9223372036854775000,1,1,1\n2,2,2,0\n").unwrap();
    let names = unique_names("hostile-csv");
    let without_sensor = start_service(
        "evgate-ingest",
        &names,
        &["--json", "--fast", "--input", text.to_str().unwrap()],
    )
    .unwrap()
    .wait(TIMEOUT)
    .unwrap();
    assert!(!without_sensor.0.success());
    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &[
            "--json",
            "--fast",
            "--linger-ms",
            "0",
            "--sensor",
            "8x8",
            "--input",
            text.to_str().unwrap(),
        ],
    )
    .unwrap();
    let summary = ingest.summary(TIMEOUT).unwrap();
    assert_eq!(u64_at(&summary, "/events-published"), 2);
    assert_eq!(
        u64_at(&summary, "/input-report/dropped-out-of-time-range"),
        1
    );
}
