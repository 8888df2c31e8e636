//! The harness itself: a failed wait must say what the children of the test were doing.

use std::path::Path;
use std::time::Duration;

use evgate_e2e::{wait_until, Process};

#[test]
fn a_timeout_reports_the_exit_status_and_last_stderr_lines_of_the_children() {
    let mut failed = Process::start(
        Path::new("/bin/sh"),
        &[
            "-c",
            "echo first line >&2; echo cannot open the service >&2; exit 3",
        ],
    )
    .unwrap();
    let _running = Process::start(
        Path::new("/bin/sh"),
        &["-c", "echo still here >&2; sleep 30"],
    )
    .unwrap();
    failed.wait(Duration::from_secs(30)).unwrap();

    let error = wait_until(
        "something that never happens",
        Duration::from_millis(50),
        || false,
    )
    .unwrap_err()
    .to_string();
    assert!(
        error.starts_with("something that never happens did not happen within 50ms"),
        "{error}"
    );
    assert!(error.contains("exit status: 3"), "{error}");
    assert!(error.contains("    cannot open the service"), "{error}");
    assert!(error.contains("still running"), "{error}");
}

#[test]
fn a_failed_summary_reports_the_stderr_of_its_process() {
    let mut failed = Process::start(
        Path::new("/bin/sh"),
        &["-c", "echo no such stream >&2; exit 2"],
    )
    .unwrap();
    let error = failed
        .summary(Duration::from_secs(30))
        .unwrap_err()
        .to_string();
    assert!(error.contains("exit status: 2"), "{error}");
    assert!(error.contains("    no such stream"), "{error}");
}
