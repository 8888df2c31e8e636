//! encode → decode gives back the same events, for every format with an encoder.

use evgate_core::{Event, SensorSize};
use evgate_io::{create, open, open_with, read_all, Format, OpenOptions};
use proptest::prelude::*;

const SENSOR: SensorSize = SensorSize::new(1280, 720);

/// Sorted events on the sensor: small steps (same time, same row) mixed with gaps long enough
/// to wrap EVT 3.0's 24-bit time base several times.
fn sorted_events() -> impl Strategy<Value = Vec<Event>> {
    let step = prop_oneof![
        4 => Just(0i64),
        4 => 0i64..100,
        1 => 0i64..(1 << 26),
    ];
    (
        -(1i64 << 40)..(1 << 40),
        prop::collection::vec((step, 0u16..1280, 0u16..720, any::<bool>()), 0..300),
    )
        .prop_map(|(start, steps)| {
            let mut t = start;
            steps
                .into_iter()
                .map(|(dt, x, y, on)| {
                    t += dt;
                    Event::new(t, x, y, on)
                })
                .collect()
        })
}

fn round_trip(extension: &str, events: &[Event]) -> (Format, Vec<Event>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(format!("events.{extension}"));
    let mut writer = create(&path, SENSOR).unwrap();
    // Two writes check that encoder state carries across calls.
    let (head, tail) = events.split_at(events.len() / 2);
    writer.write(head).unwrap();
    writer.write(tail).unwrap();
    writer.finish().unwrap();
    let options = OpenOptions {
        sensor_size: (extension == "csv").then_some(SENSOR),
        ..OpenOptions::default()
    };
    let mut reader = open_with(&path, &options).unwrap();
    assert_eq!(reader.sensor_size(), SENSOR);
    let decoded = read_all(reader.as_mut()).unwrap();
    assert!(reader.report().is_clean(), "{:?}", reader.report());
    (reader.format(), decoded)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn csv_round_trips(events in sorted_events()) {
        let (format, decoded) = round_trip("csv", &events);
        prop_assert_eq!(format, Format::Csv);
        prop_assert_eq!(decoded, events);
    }

    #[test]
    fn evt3_round_trips(events in sorted_events()) {
        let (format, decoded) = round_trip("raw", &events);
        prop_assert_eq!(format, Format::Evt3);
        prop_assert_eq!(decoded, events);
    }

    #[test]
    fn native_round_trips(events in sorted_events()) {
        let (format, decoded) = round_trip("evg", &events);
        prop_assert_eq!(format, Format::Native);
        prop_assert_eq!(decoded, events);
    }
}

#[test]
fn native_keeps_unsorted_and_negative_times() {
    let events = [Event::new(5, 1, 1, true), Event::new(-3, 2, 2, false)];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("e.evg");
    let mut writer = create(&path, SENSOR).unwrap();
    writer.write(&events).unwrap();
    writer.finish().unwrap();
    let mut reader = open(&path).unwrap();
    assert_eq!(read_all(reader.as_mut()).unwrap(), events);
    assert_eq!(reader.report().time_regressions, 1);
}

#[test]
fn evt3_refuses_what_it_cannot_represent() {
    let dir = tempfile::tempdir().unwrap();
    let mut writer = create(dir.path().join("e.raw"), SENSOR).unwrap();
    let err = writer
        .write(&[Event::new(10, 0, 0, true), Event::new(9, 0, 0, true)])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("event 1") && err.contains("time goes back"),
        "{err}"
    );
    let err = create(dir.path().join("big.raw"), SensorSize::new(4096, 10))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("4096x10"), "{err}");
    let err = create(dir.path().join("e.aedat4"), SENSOR)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("aedat4") && err.contains(".evg"), "{err}");
}

#[test]
fn absolute_unix_times_convert_to_a_compact_evt3_file_and_back() {
    let real = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/real/sample.aedat4"
    );
    let events = read_all(open(real).unwrap().as_mut()).unwrap();
    assert!(events[0].t > 1_600_000_000_000_000);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("from_aedat4.raw");
    let mut writer = create(&path, SensorSize::new(320, 240)).unwrap();
    writer.write(&events).unwrap();
    writer.finish().unwrap();
    // A few words per event, not millions of bridging TIME_HIGH words.
    let bytes = std::fs::metadata(&path).unwrap().len();
    assert!(bytes < events.len() as u64 * 10, "{bytes} bytes");
    assert_eq!(read_all(open(&path).unwrap().as_mut()).unwrap(), events);
}

#[test]
fn an_empty_evt3_file_still_has_a_readable_header() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.raw");
    create(&path, SENSOR).unwrap().finish().unwrap();
    let mut reader = open(&path).unwrap();
    assert_eq!(reader.sensor_size(), SENSOR);
    assert!(read_all(reader.as_mut()).unwrap().is_empty());
}
