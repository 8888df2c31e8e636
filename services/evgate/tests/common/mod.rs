//! Running the `evgate` binary from the command-line tests.

use std::process::Command;

/// Runs `evgate args`; returns whether it succeeded, its stdout and its stderr.
pub fn evgate(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_evgate"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("evgate runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
