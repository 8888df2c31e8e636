//! DSEC `events.h5`: the committed Blosc-compressed fixture (made by
//! fixtures/make_dsec_fixture.py) decodes to the generator's events; `ms_to_idx` windows; bad
//! files made here with the HDF5 library.
#![cfg(feature = "dsec")]

use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};
use evgate_io::dsec::DsecReader;
use evgate_io::{open, read_all, Format};
use hdf5_metno::File;

const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/dsec_events.h5");
const COUNT: usize = 3000;
const T_OFFSET_US: i64 = 49_599_300_523;

/// The generator's `event_at`: (t relative µs, x, y, p).
fn event_at(i: usize) -> (i64, u16, u16, u8) {
    let t = 1000 + 7 * i + i % 3 + if i >= 2000 { 5000 } else { 0 };
    (
        t as i64,
        ((i * 7919) % 640) as u16,
        ((i * 104_729) % 480) as u16,
        ((i * 31 / 7) % 2) as u8,
    )
}

fn expected_events() -> Vec<Event> {
    (0..COUNT)
        .map(|i| {
            let (t, x, y, p) = event_at(i);
            Event::new(t + T_OFFSET_US, x, y, p == 1)
        })
        .collect()
}

#[test]
fn the_blosc_fixture_decodes_to_the_generator_events() {
    let mut reader = open(FIXTURE).unwrap();
    assert_eq!(reader.format(), Format::Dsec);
    assert_eq!(reader.sensor_size(), SensorSize::new(640, 480));
    let events = read_all(reader.as_mut()).unwrap();
    assert_eq!(events, expected_events());
    assert!(reader.report().is_clean(), "{:?}", reader.report());
}

#[test]
fn ms_to_idx_windows_equal_a_filter_of_all_events() {
    let all = expected_events();
    let mut reader = DsecReader::open(Path::new(FIXTURE), None).unwrap();
    assert_eq!(reader.t_offset_us(), T_OFFSET_US);
    assert_eq!(reader.event_count(), COUNT as u64);
    assert_eq!(reader.ms_to_idx().len(), 27);
    let windows = [
        (5_500, 9_000),
        (0, 1_001),
        (14_990, 20_010), // across the 5 ms gap
        (16_000, 19_000), // inside the gap: empty
        (26_000, 40_000), // past the end of the table
        (-5_000, 500),    // before the first event
        (7_777, 7_777),   // empty window
    ];
    for (from, to) in windows {
        let (t0, t1) = (T_OFFSET_US + from, T_OFFSET_US + to);
        let window = reader.events_between(t0, t1).unwrap();
        let expected: Vec<Event> = all
            .iter()
            .copied()
            .filter(|e| (t0..t1).contains(&e.t))
            .collect();
        assert_eq!(window, expected, "window [{from}, {to}) µs after t_offset");
    }
    let err = reader
        .events_between(T_OFFSET_US + 10, T_OFFSET_US)
        .unwrap_err()
        .to_string();
    assert!(err.contains("ends before it starts"), "{err}");
}

/// Columns of a DSEC-layout file written uncompressed by the test.
struct Columns {
    x: Vec<u16>,
    y: Vec<u16>,
    t: Vec<u32>,
    p: Vec<u8>,
    ms_to_idx: Vec<u64>,
    t_offset: Option<i64>,
}

fn valid_columns() -> Columns {
    let events: Vec<_> = (0..400).map(event_at).collect();
    let t: Vec<u32> = events.iter().map(|e| e.0 as u32).collect();
    let last_ms = *t.last().unwrap() as u64 / 1000;
    let ms_to_idx = (0..=last_ms)
        .map(|ms| t.iter().position(|&t| t as u64 >= ms * 1000).unwrap() as u64)
        .collect();
    Columns {
        x: events.iter().map(|e| e.1).collect(),
        y: events.iter().map(|e| e.2).collect(),
        t,
        p: events.iter().map(|e| e.3).collect(),
        ms_to_idx,
        t_offset: Some(1_000_000),
    }
}

fn write(dir: &Path, name: &str, columns: &Columns, skip: Option<&str>) -> PathBuf {
    let path = dir.join(name);
    let file = File::create(&path).unwrap();
    file.create_group("events").unwrap();
    let put = |dataset: &str| skip != Some(dataset);
    if put("events/x") {
        file.new_dataset_builder()
            .with_data(&columns.x[..])
            .create("events/x")
            .unwrap();
    }
    if put("events/y") {
        file.new_dataset_builder()
            .with_data(&columns.y[..])
            .create("events/y")
            .unwrap();
    }
    if put("events/t") {
        file.new_dataset_builder()
            .with_data(&columns.t[..])
            .create("events/t")
            .unwrap();
    }
    if put("events/p") {
        file.new_dataset_builder()
            .with_data(&columns.p[..])
            .create("events/p")
            .unwrap();
    }
    if put("ms_to_idx") {
        file.new_dataset_builder()
            .with_data(&columns.ms_to_idx[..])
            .create("ms_to_idx")
            .unwrap();
    }
    if let Some(offset) = columns.t_offset {
        file.new_dataset::<i64>()
            .create("t_offset")
            .unwrap()
            .write_scalar(&offset)
            .unwrap();
    }
    path
}

fn decode(path: &Path) -> Result<(Vec<Event>, evgate_io::DecodeReport), String> {
    let mut reader = DsecReader::open(path, None).map_err(|e| e.to_string())?;
    let mut all = Vec::new();
    let mut chunk = Vec::new();
    while reader.read_chunk(&mut chunk).map_err(|e| e.to_string())? > 0 {
        all.extend_from_slice(&chunk);
    }
    Ok((all, reader.report().clone()))
}

#[test]
fn an_uncompressed_file_and_a_missing_t_offset_decode() {
    let dir = tempfile::tempdir().unwrap();
    let columns = valid_columns();
    let (events, report) = decode(&write(dir.path(), "ok.h5", &columns, None)).unwrap();
    assert_eq!(events.len(), 400);
    assert_eq!(events[7].t, 1_000_000 + event_at(7).0);
    assert!(report.is_clean());
    let no_offset = Columns {
        t_offset: None,
        ..valid_columns()
    };
    let (events, _) = decode(&write(dir.path(), "no_offset.h5", &no_offset, None)).unwrap();
    assert_eq!(events[7].t, event_at(7).0);
}

#[test]
fn coordinates_outside_640x480_are_dropped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let mut columns = valid_columns();
    columns.x[10] = 640;
    columns.y[20] = 480;
    let (events, report) = decode(&write(dir.path(), "outside.h5", &columns, None)).unwrap();
    assert_eq!(events.len(), 398);
    assert_eq!(report.dropped_out_of_sensor, 2);
    assert_eq!(
        report.first_out_of_sensor_offset,
        Some(10),
        "the offset is the event index"
    );
}

/// (file name, damage, dataset left out, what the error must say).
type BadCase = (
    &'static str,
    Box<dyn Fn(&mut Columns)>,
    Option<&'static str>,
    Vec<&'static str>,
);

#[test]
fn bad_files_name_the_dataset_and_the_value() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<BadCase> = vec![
        (
            "missing_p.h5",
            Box::new(|_| {}),
            Some("events/p"),
            vec!["`events/p`", "missing"],
        ),
        (
            "missing_table.h5",
            Box::new(|_| {}),
            Some("ms_to_idx"),
            vec!["`ms_to_idx`", "missing", "events"],
        ),
        (
            "short_y.h5",
            Box::new(|c| {
                c.y.pop();
            }),
            None,
            vec!["`events`", "disagree", "y 399", "x 400"],
        ),
        (
            "bad_p.h5",
            Box::new(|c| c.p[5] = 2),
            None,
            vec!["`events/p`", "event 5", "p = 2", "accepted: 0, 1"],
        ),
        (
            "shifted_table.h5",
            Box::new(|c| c.ms_to_idx[3] += 1),
            None,
            vec!["`ms_to_idx`", "entry 3", "3000 µs"],
        ),
        (
            "decreasing_table.h5",
            Box::new(|c| {
                c.ms_to_idx[3] = 0;
            }),
            None,
            vec!["`ms_to_idx`", "decreases at millisecond 3", "0 after 143"],
        ),
        (
            "long_table.h5",
            Box::new(|c| {
                c.ms_to_idx.push(400);
                c.ms_to_idx.push(7);
            }),
            None,
            vec!["`ms_to_idx`", "decreases"],
        ),
        (
            "beyond_table.h5",
            Box::new(|c| {
                let n = c.ms_to_idx.len();
                c.ms_to_idx[n - 1] = 401;
            }),
            None,
            vec!["`ms_to_idx`", "401", "beyond the 400 events"],
        ),
    ];
    for (name, damage, skip, needles) in cases {
        let mut columns = valid_columns();
        damage(&mut columns);
        let path = write(dir.path(), name, &columns, skip);
        let err = decode(&path)
            .err()
            .unwrap_or_else(|| panic!("{name} decoded"));
        assert!(err.contains(name), "{err}");
        for needle in needles {
            assert!(err.contains(needle), "{name}: `{needle}` not in: {err}");
        }
    }

    // A column of the wrong type.
    let path = dir.path().join("wide_x.h5");
    let file = File::create(&path).unwrap();
    file.create_group("events").unwrap();
    file.new_dataset_builder()
        .with_data(&[1u32, 2][..])
        .create("events/x")
        .unwrap();
    drop(file);
    let err = decode(&path).err().unwrap();
    assert!(
        err.contains("`events/x`") && err.contains("uint32") && err.contains("accepted: uint16"),
        "{err}"
    );

    // Not HDF5 at all.
    let path = dir.path().join("text.h5");
    std::fs::write(&path, b"t,x,y,p\n").unwrap();
    let err = decode(&path).err().unwrap();
    assert!(
        err.contains("text.h5") && err.contains("not a readable HDF5 file"),
        "{err}"
    );
}
