//! `evgate info --evt3-time-low carry-on-step-back` reproduces the reference decode's times of
//! `evt3_sample.raw` (expelliarmus adds 4096 µs at each of its eleven TIME_LOW steps back).

use std::process::Command;

const EVT3: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/real/evt3_sample.raw"
);

fn info(extra: &[&str]) -> Result<serde_json::Value, String> {
    let out = Command::new(env!("CARGO_BIN_EXE_evgate"))
        .args(["info", EVT3, "--json"])
        .args(extra)
        .env("RUST_LOG", "warn")
        .output()
        .expect("evgate runs");
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    Ok(serde_json::from_slice(&out.stdout).expect("JSON"))
}

#[test]
fn the_carry_rule_moves_the_last_time_by_eleven_carries() {
    let spec = info(&[]).unwrap();
    let carry = info(&["--evt3-time-low", "carry-on-step-back"]).unwrap();
    assert_eq!(spec["evt3-time-low"], "evt3");
    assert_eq!(carry["evt3-time-low"], "carry-on-step-back");
    assert_eq!(carry["events"], spec["events"]);
    assert_eq!(carry["first-t-us"], spec["first-t-us"]);
    assert_eq!(
        carry["last-t-us"].as_i64().unwrap(),
        spec["last-t-us"].as_i64().unwrap() + 11 * 4096
    );
    let err = info(&["--evt3-time-low", "wrap"]).unwrap_err();
    assert!(
        err.contains("wrap") && err.contains("carry-on-step-back"),
        "{err}"
    );
}
