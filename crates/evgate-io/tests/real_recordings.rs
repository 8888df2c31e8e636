//! Decoding the real recordings in `../shared/data/real/` (see its README).

use std::path::PathBuf;

use evgate_core::{Event, SensorSize};
use evgate_io::npy::{DType, NpyArray};
use evgate_io::{open, read_all, Format};

fn real(name: &str) -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/real/"
    ))
    .join(name)
}

/// Reads the reference decode: a structured array with fields t (<i8), x, y (<i2), p (|u1).
fn reference_events() -> Vec<Event> {
    let path = real("evt3_sample.npy");
    let array = NpyArray::read(&mut std::fs::File::open(&path).unwrap()).unwrap();
    let DType::Record(fields) = &array.dtype else {
        panic!(
            "{}: expected a structured dtype, found {}",
            path.display(),
            array.dtype
        );
    };
    let field = |name: &str, descr: &str| {
        let field = fields.iter().find(|f| f.name == name).unwrap();
        assert_eq!(field.descr, descr, "field {name}");
        field.offset
    };
    let (t, x, y, p) = (
        field("t", "<i8"),
        field("x", "<i2"),
        field("y", "<i2"),
        field("p", "|u1"),
    );
    let record = array.dtype.item_size().unwrap();
    array
        .data
        .chunks_exact(record)
        .map(|r| {
            let t = i64::from_le_bytes(r[t..t + 8].try_into().unwrap());
            let x = i16::from_le_bytes([r[x], r[x + 1]]);
            let y = i16::from_le_bytes([r[y], r[y + 1]]);
            assert!(r[p] <= 1 && x >= 0 && y >= 0);
            Event::new(t, x as u16, y as u16, r[p] == 1)
        })
        .collect()
}

/// The reference (expelliarmus) treats every `TIME_LOW` smaller than the previous one as a
/// wrap of the 12 low bits and adds 4096 µs. This recording has nine `TIME_LOW` words a few µs
/// ahead of their neighbours (right after each repeated `TIME_HIGH`), so the reference opens
/// eleven gaps of about 4.1 ms in a stream whose events are otherwise at most 1 µs apart. We
/// follow the EVT 3.0 definition (time = TIME_HIGH << 12 | TIME_LOW, wraps only on `TIME_HIGH`);
/// the test checks that every row matches the reference in x, y and p exactly, and in t exactly
/// up to those 4096 µs steps, which must sit exactly at the reference's gaps.
#[test]
fn evt3_sample_matches_the_reference_decode_row_by_row() {
    let reference = reference_events();
    let mut reader = open(real("evt3_sample.raw")).unwrap();
    assert_eq!(reader.format(), Format::Evt3);
    assert_eq!(reader.sensor_size(), SensorSize::new(1280, 720));
    let events = read_all(reader.as_mut()).unwrap();
    assert_eq!(events.len(), reference.len());
    assert_eq!(events.len(), 219_596);
    let mut steps = 0i64;
    for (i, (ours, theirs)) in events.iter().zip(&reference).enumerate() {
        assert_eq!(
            (ours.x, ours.y, ours.polarity),
            (theirs.x, theirs.y, theirs.polarity),
            "row {i}"
        );
        if i > 0 && theirs.t - reference[i - 1].t >= 2048 {
            steps += 1;
        }
        assert_eq!(
            theirs.t - ours.t,
            4096 * steps,
            "row {i}: t {} vs {}",
            ours.t,
            theirs.t
        );
    }
    assert_eq!(steps, 11);
    assert_eq!(events[0].t, reference[0].t);
    assert!(events
        .windows(2)
        .all(|w| w[1].t >= w[0].t && w[1].t - w[0].t <= 1));
    assert!(reader.report().is_clean(), "{:?}", reader.report());
}

#[test]
fn every_real_recording_decodes_inside_its_sensor() {
    let expected = [
        ("evt2_sample.raw", Format::Evt2, SensorSize::new(640, 480)),
        ("evt2_640x480.raw", Format::Evt2, SensorSize::new(640, 480)),
        ("evt3_sample.raw", Format::Evt3, SensorSize::new(1280, 720)),
        ("sample.aedat4", Format::Aedat4, SensorSize::new(320, 240)),
    ];
    for (name, format, sensor_size) in expected {
        let mut reader = open(real(name)).unwrap();
        assert_eq!(
            (reader.format(), reader.sensor_size()),
            (format, sensor_size),
            "{name}"
        );
        let events = read_all(reader.as_mut()).unwrap();
        let report = reader.report();
        eprintln!(
            "{name}: {} events, t {}..{}, report {report:?}",
            events.len(),
            events.first().map_or(0, |e| e.t),
            events.last().map_or(0, |e| e.t)
        );
        assert!(!events.is_empty(), "{name}");
        assert!(events.iter().all(|e| sensor_size.contains(e)), "{name}");
        assert_eq!(report.events as usize, events.len(), "{name}");
        let regressions = events.windows(2).filter(|w| w[1].t < w[0].t).count();
        assert_eq!(regressions as u64, report.time_regressions, "{name}");
    }
}

/// With the `carry-on-step-back` rule (expelliarmus' reading of `TIME_LOW` steps back) the
/// decode equals the reference in every field of every row.
#[test]
fn evt3_sample_with_the_carry_rule_equals_the_reference_exactly() {
    let reference = reference_events();
    let mut reader = evgate_io::open_with_time_low_rule(
        real("evt3_sample.raw"),
        &evgate_io::OpenOptions::default(),
        evgate_io::Evt3TimeLow::CarryOnStepBack,
    )
    .unwrap();
    let events = read_all(reader.as_mut()).unwrap();
    assert_eq!(events.len(), reference.len());
    for (i, (ours, theirs)) in events.iter().zip(&reference).enumerate() {
        assert_eq!(ours, theirs, "row {i}");
    }
    assert!(reader.report().is_clean(), "{:?}", reader.report());
}
