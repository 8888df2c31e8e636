//! `evgate info` / `evgate convert` on a DSEC `events.h5` (the evgate-io fixture): decoded when
//! built with `--features dsec`, a clear error naming the feature otherwise.

mod common;

use common::evgate;

const DSEC: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../crates/evgate-io/tests/fixtures/dsec_events.h5"
);

#[cfg(feature = "dsec")]
#[test]
fn info_and_convert_read_the_dsec_file() {
    let (ok, stdout, stderr) = evgate(&["info", DSEC, "--json"]);
    assert!(ok, "{stderr}");
    let info: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(info["format"], "dsec-h5");
    assert_eq!(info["events"], 3000);
    assert_eq!(info["sensor-width"], 640);
    assert_eq!(info["sensor-height"], 480);
    assert_eq!(info["first-t-us"], 49_599_300_523_i64 + 1000);
    assert_eq!(info["report"]["dropped-out-of-sensor"], 0);

    let dir = tempfile::tempdir().unwrap();
    let evg = dir.path().join("dsec.evg");
    let (ok, _, stderr) = evgate(&["convert", DSEC, evg.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    let (ok, stdout, stderr) = evgate(&["info", evg.to_str().unwrap(), "--json"]);
    assert!(ok, "{stderr}");
    let converted: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(converted["events"], 3000);
    assert_eq!(converted["last-t-us"], info["last-t-us"]);
}

#[cfg(not(feature = "dsec"))]
#[test]
fn without_the_feature_an_h5_input_says_how_to_build() {
    let (ok, _, stderr) = evgate(&["info", DSEC]);
    assert!(!ok);
    assert!(
        stderr.contains("dsec_events.h5") && stderr.contains("--features dsec"),
        "{stderr}"
    );
}
