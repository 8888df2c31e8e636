//! examples/python/kept_consumer.py, on the iceoryx2 PyPI bindings, reads the gate's kept
//! stream. examples/python/setup.sh creates its environment (it installs iceoryx2 from PyPI).

use std::process::Command;
use std::time::Duration;

use evgate_e2e::{start_service, u64_at, unique_names, wait_until, workspace_root, Process};
use evgate_ipc::{create_node, BatchHeader, Qos, SlicePublisher, Stream};

const TIMEOUT: Duration = Duration::from_secs(90);

#[test]
fn python_consumer_receives_every_kept_event() {
    let root = workspace_root();
    let setup = Command::new(root.join("examples/python/setup.sh"))
        .output()
        .expect("examples/python/setup.sh runs");
    assert!(
        setup.status.success(),
        "examples/python/setup.sh failed: {}",
        String::from_utf8_lossy(&setup.stderr)
    );
    let python = String::from_utf8(setup.stdout).unwrap().trim().to_owned();

    let names = unique_names("python");
    let mut gate = start_service(
        "evgate-gate",
        &names,
        &["--json", "--exit-at-end-of-stream"],
    )
    .unwrap();
    let mut consumer = Process::start(
        std::path::Path::new(&python),
        &[
            root.join("examples/python/kept_consumer.py")
                .to_str()
                .unwrap(),
            "--domain",
            &names.domain,
            "--camera",
            &names.camera,
            "--timeout-s",
            "60",
        ],
    )
    .unwrap();
    // The consumer must be subscribed before the first batch is gated.
    let node = create_node("python-test").unwrap();
    let kept_probe = SlicePublisher::<evgate_core::Event, BatchHeader>::open(
        &node,
        &names,
        Stream::Kept,
        &Qos::default(),
    )
    .unwrap();
    wait_until("the python consumer subscribing", TIMEOUT, || {
        kept_probe.subscriber_count() == 1
    })
    .unwrap();

    let mut ingest = start_service(
        "evgate-ingest",
        &names,
        &[
            "--json",
            "--fast",
            "--sim-duration-s",
            "0.05",
            "--wait-for-subscribers",
            "1",
        ],
    )
    .unwrap();
    let ingest_summary = ingest.summary(TIMEOUT).unwrap();
    let consumer_summary = consumer.summary(TIMEOUT).unwrap();
    let gate_summary = gate.summary(TIMEOUT).unwrap();
    let passed = u64_at(&gate_summary, "/stats/kept-events")
        + u64_at(&gate_summary, "/stats/unjudged-passed-events");
    assert_eq!(consumer_summary["ended-by"], "end-of-stream");
    assert_eq!(u64_at(&consumer_summary, "/events"), passed);
    assert_eq!(
        u64_at(&consumer_summary, "/batches"),
        u64_at(&ingest_summary, "/batches-published")
    );
    assert!(passed > 0);
}
