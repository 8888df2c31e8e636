//! Damaged and odd inputs give errors that name the file, the offset and the problem, or a
//! counted repair; never a panic.

use std::path::{Path, PathBuf};

use evgate_core::SensorSize;
use evgate_io::{open, read_all};

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn decode_error(path: &Path) -> String {
    match open(path) {
        Err(e) => e.to_string(),
        Ok(mut reader) => read_all(reader.as_mut())
            .map(|events| format!("no error, {} events", events.len()))
            .unwrap_or_else(|e| e.to_string()),
    }
}

#[test]
fn empty_files_are_empty_streams_or_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write(dir.path(), "empty.csv", b"");
    assert!(read_all(open(&csv).unwrap().as_mut()).unwrap().is_empty());
    let header_only = write(dir.path(), "empty.raw", b"% evt 3.0\n% geometry 4x4\n");
    assert!(read_all(open(&header_only).unwrap().as_mut())
        .unwrap()
        .is_empty());
    for name in [
        "empty.raw",
        "empty.aedat4",
        "empty.evg",
        "empty.bin",
        "empty.dat",
    ] {
        let path = write(dir.path(), name, b"");
        let err = decode_error(&path);
        assert!(
            err.contains(name) && !err.starts_with("no error"),
            "{name}: {err}"
        );
    }
    let err = decode_error(&write(dir.path(), "short.dat", b"% Width 4\n% Height 4\n"));
    assert!(
        err.contains("short.dat") && err.contains("truncated"),
        "{err}"
    );
}

#[test]
fn truncated_files_name_the_offset() {
    let dir = tempfile::tempdir().unwrap();
    let mut evt3 = b"% evt 3.0\n% geometry 8x8\n".to_vec();
    let header_len = evt3.len();
    evt3.extend_from_slice(&[0x01, 0x00, 0x01, 0x28, 0x05]);
    let err = decode_error(&write(dir.path(), "cut.raw", &evt3));
    assert!(
        err.contains("cut.raw") && err.contains(&format!("offset {}", header_len + 4)),
        "{err}"
    );

    let real = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/real/sample.aedat4"
    );
    let bytes = std::fs::read(real).unwrap();
    let err = decode_error(&write(dir.path(), "cut.aedat4", &bytes[..5000]));
    assert!(
        err.contains("cut.aedat4") && err.contains("AEDAT 4 packet"),
        "{err}"
    );
    let err = decode_error(&write(dir.path(), "head.aedat4", &bytes[..100]));
    assert!(
        err.contains("head.aedat4") && err.contains("header"),
        "{err}"
    );
}

#[test]
fn wrong_magic_and_headers_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let err = decode_error(&write(dir.path(), "x.aedat4", b"#!AER-DAT3.1\r\n"));
    assert!(err.contains("x.aedat4"), "{err}");
    let err = decode_error(&write(dir.path(), "x.raw", b"\x00\x00\x00\x00"));
    assert!(err.contains("`%` header"), "{err}");
    let err = decode_error(&write(dir.path(), "nosize.raw", b"% evt 3.0\n\x00\x00"));
    assert!(err.contains("no sensor size"), "{err}");
    let err = decode_error(&write(dir.path(), "v4.raw", b"% evt 4.0\n"));
    assert!(err.contains("`4.0`"), "{err}");
}

#[test]
fn outside_events_unknown_words_and_backwards_time_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    let mut evt3 = b"% evt 3.0\n% geometry 8x8\n".to_vec();
    let header_len = evt3.len() as u64;
    for word in [
        0x8000u16, 0x6010, 0x0009, 0x2001, 0x0001, 0x2001, 0x9abc, 0x6002, 0x2002,
    ] {
        evt3.extend_from_slice(&word.to_le_bytes());
    }
    let mut reader = open(write(dir.path(), "odd.raw", &evt3)).unwrap();
    assert_eq!(reader.sensor_size(), SensorSize::new(8, 8));
    let events = read_all(reader.as_mut()).unwrap();
    assert_eq!(events.len(), 2);
    let report = reader.report();
    assert_eq!(report.dropped_out_of_sensor, 1);
    assert_eq!(report.first_out_of_sensor_offset, Some(header_len + 6));
    assert_eq!(report.skipped_words, 1);
    assert_eq!(report.first_skipped_word_offset, Some(header_len + 12));
    assert_eq!(report.time_regressions, 1);
    assert_eq!(report.first_time_regression_index, Some(1));
    assert_eq!(report.largest_time_regression_us, 14);
}
