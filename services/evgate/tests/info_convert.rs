//! `evgate info` and `evgate convert` on a real recording, end to end through the binary.

mod common;

use common::evgate;

const EVT3: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/real/evt3_sample.raw"
);

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

#[test]
fn info_reports_the_recording_as_json() {
    let (ok, stdout, stderr) = evgate(&["info", EVT3, "--json"]);
    assert!(ok, "{stderr}");
    let info = json(&stdout);
    assert_eq!(info["format"], "evt3");
    assert_eq!(info["events"], 219_596);
    assert_eq!(
        (
            info["sensor-width"].as_u64(),
            info["sensor-height"].as_u64()
        ),
        (Some(1280), Some(720))
    );
    assert_eq!(info["first-t-us"], 11_718_656);
    assert_eq!(info["last-t-us"], 11_727_457);
    assert_eq!(
        info["on-events"].as_u64().unwrap() + info["off-events"].as_u64().unwrap(),
        219_596
    );
    assert_eq!(info["report"]["time-regressions"], 0);
}

#[test]
fn convert_to_csv_and_evg_keeps_every_event() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sample.csv");
    let evg = dir.path().join("sample.evg");
    let (ok, _, stderr) = evgate(&["convert", EVT3, csv.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().next(), Some("t,x,y,p"));
    assert_eq!(text.lines().count(), 219_597);
    let (ok, stdout, stderr) = evgate(&[
        "convert",
        csv.to_str().unwrap(),
        evg.to_str().unwrap(),
        "--sensor",
        "1280x720",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    assert_eq!(json(&stdout)["events"], 219_596);
    let (ok, stdout, _) = evgate(&["info", evg.to_str().unwrap(), "--json"]);
    assert!(ok);
    let (ok, original, _) = evgate(&["info", EVT3, "--json"]);
    assert!(ok);
    for key in [
        "events",
        "first-t-us",
        "last-t-us",
        "on-events",
        "max-x",
        "max-y",
        "sensor-width",
    ] {
        assert_eq!(json(&stdout)[key], json(&original)[key], "{key}");
    }
}

#[test]
fn bad_arguments_and_files_fail_with_a_named_cause() {
    let (ok, _, stderr) = evgate(&["info", "/nonexistent/file.raw"]);
    assert!(!ok && stderr.contains("/nonexistent/file.raw"), "{stderr}");
    let (ok, _, stderr) = evgate(&["convert", EVT3, "/tmp/out.aedat4"]);
    assert!(!ok && stderr.contains("no encoder"), "{stderr}");
    let (ok, _, stderr) = evgate(&["info", EVT3, "--sensor", "12"]);
    assert!(!ok && stderr.contains("WxH"), "{stderr}");
}
