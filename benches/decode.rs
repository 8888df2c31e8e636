//! Decoder throughput per format, in bytes/s and events/s: the real recordings in
//! `../shared/data/real/` (EVT 2.0, EVT 3.0, AEDAT 4) and CSV / native / DAT files generated from
//! the EVT 2.0 recording's events. Inputs are held in memory so the figures are decoding, not
//! disk speed.

use std::io::Cursor;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use evgate_core::{Event, SensorSize};
use evgate_io::csv_writer::CsvWriter;
use evgate_io::native_writer::NativeWriter;
use evgate_io::reader::from_bytes;
use evgate_io::{read_all, EventWriter, Format};

fn real(name: &str) -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/real/"
    ))
    .join(name)
}

fn decode_count(bytes: &[u8], format: Format, sensor: Option<SensorSize>) -> usize {
    let mut reader = from_bytes("bench", bytes.to_vec(), format, sensor).expect("input opens");
    let mut chunk = Vec::new();
    let mut count = 0;
    while reader.read_chunk(&mut chunk).expect("input decodes") > 0 {
        count += black_box(&chunk).len();
    }
    count
}

struct Input {
    name: &'static str,
    format: Format,
    sensor: Option<SensorSize>,
    bytes: Vec<u8>,
}

fn inputs() -> Vec<Input> {
    let read = |name: &str| std::fs::read(real(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    let evt2 = read("evt2_sample.raw");
    let sensor = SensorSize::new(640, 480);
    let events: Vec<Event> = {
        let mut reader = from_bytes("evt2_sample.raw", evt2.clone(), Format::Evt2, None)
            .expect("evt2 sample opens");
        read_all(reader.as_mut()).expect("evt2 sample decodes")
    };

    let mut csv = Vec::new();
    let mut writer = CsvWriter::new("bench.csv".into(), &mut csv).expect("csv header");
    writer.write(&events).expect("csv encodes");
    drop(writer);

    let mut native = Cursor::new(Vec::new());
    let mut writer = NativeWriter::new("bench.evg".into(), &mut native, sensor).expect("header");
    writer.write(&events).expect("native encodes");
    Box::new(writer).finish().expect("native finishes");

    let mut dat = b"% Width 640\n% Height 480\n\x0c\x08".to_vec();
    for event in &events {
        dat.extend_from_slice(&evgate_io::dat::encode_record(event));
    }

    vec![
        Input {
            name: "evt2 (evt2_sample.raw)",
            format: Format::Evt2,
            sensor: None,
            bytes: evt2,
        },
        Input {
            name: "evt3 (evt3_sample.raw)",
            format: Format::Evt3,
            sensor: None,
            bytes: read("evt3_sample.raw"),
        },
        Input {
            name: "aedat4 (sample.aedat4)",
            format: Format::Aedat4,
            sensor: None,
            bytes: read("sample.aedat4"),
        },
        Input {
            name: "csv (generated)",
            format: Format::Csv,
            sensor: Some(sensor),
            bytes: csv,
        },
        Input {
            name: "evg (generated)",
            format: Format::Native,
            sensor: None,
            bytes: native.into_inner(),
        },
        Input {
            name: "dat (generated)",
            format: Format::Dat,
            sensor: None,
            bytes: dat,
        },
    ]
}

fn decode(criterion: &mut Criterion) {
    for input in inputs() {
        let events = decode_count(&input.bytes, input.format, input.sensor) as u64;
        for (unit, throughput) in [
            ("bytes", Throughput::Bytes(input.bytes.len() as u64)),
            ("events", Throughput::Elements(events)),
        ] {
            let mut group = criterion.benchmark_group(format!("decode/{unit}"));
            group
                .sample_size(10)
                .warm_up_time(Duration::from_millis(500))
                .measurement_time(Duration::from_secs(2))
                .throughput(throughput);
            group.bench_function(input.name, |b| {
                b.iter(|| decode_count(&input.bytes, input.format, input.sensor))
            });
            group.finish();
        }
    }
}

criterion_group!(benches, decode);
criterion_main!(benches);
