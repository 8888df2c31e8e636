//! The Python examples, on the iceoryx2 PyPI bindings and the evgate_reader package, read the
//! gate's kept stream: kept_consumer.py, and bench_reader.py, which reads each batch both by a
//! per-event loop and by the NumPy view and checks that they agree. examples/python/setup.sh
//! creates their environment (iceoryx2 and NumPy from PyPI, evgate_reader from the folder).

use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;

use evgate_e2e::{consume_kept_stream, u64_at, workspace_root, ConsumerRun};

/// The examples' Python, set up once per test binary (two pip runs at once in one environment
/// break each other).
fn python_environment() -> &'static str {
    static PYTHON: OnceLock<String> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let setup = Command::new(workspace_root().join("examples/python/setup.sh"))
            .output()
            .expect("examples/python/setup.sh runs");
        assert!(
            setup.status.success(),
            "examples/python/setup.sh failed: {}",
            String::from_utf8_lossy(&setup.stderr)
        );
        String::from_utf8(setup.stdout).unwrap().trim().to_owned()
    })
}

/// Runs `script` (under examples/python) on a gate's kept stream.
fn run_python_consumer(script: &str) -> ConsumerRun {
    let script = workspace_root().join("examples/python").join(script);
    consume_kept_stream(Path::new(python_environment()), |names| {
        vec![
            script.display().to_string(),
            "--domain".to_owned(),
            names.domain.clone(),
            "--camera".to_owned(),
            names.camera.clone(),
            "--timeout-s".to_owned(),
            "60".to_owned(),
        ]
    })
}

#[test]
fn python_consumer_receives_every_kept_event() {
    let run = run_python_consumer("kept_consumer.py");
    let passed = run.passed();
    assert_eq!(run.consumer["ended-by"], "end-of-stream");
    assert_eq!(u64_at(&run.consumer, "/events"), passed);
    assert_eq!(
        u64_at(&run.consumer, "/batches"),
        u64_at(&run.ingest, "/batches-published")
    );
    assert!(passed > 0);
}

#[test]
fn the_numpy_view_reads_what_the_per_event_loop_reads() {
    let run = run_python_consumer("bench_reader.py");
    // The script exits with an error on the first batch where the two readings differ.
    assert_eq!(u64_at(&run.consumer, "/events"), run.passed());
    assert!(run.consumer["numpy-view-events-per-s"].is_number());
    assert!(run.consumer["per-event-loop-events-per-s"].is_number());
}
