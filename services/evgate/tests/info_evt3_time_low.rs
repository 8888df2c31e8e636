//! `evgate info --evt3-time-low carry-on-step-back` reproduces the reference decode's times of
//! `evt3_sample.raw` (expelliarmus adds 4096 µs at each of its eleven TIME_LOW steps back).

mod common;

use common::evgate;

const EVT3: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/real/evt3_sample.raw"
);

fn info(extra: &[&str]) -> Result<serde_json::Value, String> {
    let (ok, stdout, stderr) = evgate(&[&["info", EVT3, "--json"], extra].concat());
    if !ok {
        return Err(stderr);
    }
    Ok(serde_json::from_str(&stdout).expect("JSON"))
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
