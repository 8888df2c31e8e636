//! Decoder throughput per format, in bytes/s and events/s: the real recordings in
//! `../shared/data/real/` (EVT 2.0, EVT 3.0, AEDAT 4) and CSV / native / DAT / EVIMO (and, with
//! the `dsec` feature, DSEC) inputs generated from the EVT 2.0 recording's events. Byte-stream
//! formats are decoded from memory, so the figures are decoding, not disk speed; the
//! path-based layouts (EVIMO `.npz`, EVIMO2 folder, DSEC `.h5`) are written once to
//! `target/bench-inputs/` and read back through the page cache.

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use evgate_core::{Event, SensorSize};
use evgate_io::csv_writer::CsvWriter;
use evgate_io::evimo2_events::{COORDINATES_FILE, POLARITIES_FILE, TIMES_FILE};
use evgate_io::native_writer::NativeWriter;
use evgate_io::npy::NpyArray;
use evgate_io::npz::{NpzCompression, NpzWriter};
use evgate_io::reader::from_bytes;
use evgate_io::{open_with, read_all, EventReader, EventWriter, Format, OpenOptions};

fn real(name: &str) -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/real/"
    ))
    .join(name)
}

/// Where the path-based inputs are written (regenerated on every run).
fn generated(name: &str) -> PathBuf {
    let folder = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../target/bench-inputs"
    ));
    std::fs::create_dir_all(&folder).expect("target/bench-inputs is writable");
    folder.join(name)
}

enum Data {
    Memory(Vec<u8>),
    /// A file or folder, opened by path on every iteration.
    Path(PathBuf),
}

struct Input {
    name: &'static str,
    format: Format,
    sensor: Option<SensorSize>,
    data: Data,
    /// Bytes the throughput in bytes/s counts: the file or the whole folder.
    bytes: u64,
}

impl Input {
    fn in_memory(
        name: &'static str,
        format: Format,
        sensor: Option<SensorSize>,
        bytes: Vec<u8>,
    ) -> Self {
        Self {
            name,
            format,
            sensor,
            bytes: bytes.len() as u64,
            data: Data::Memory(bytes),
        }
    }

    fn at_path(name: &'static str, format: Format, sensor: SensorSize, path: PathBuf) -> Self {
        Self {
            name,
            format,
            sensor: Some(sensor),
            bytes: size_on_disk(&path),
            data: Data::Path(path),
        }
    }

    fn open(&self) -> Box<dyn EventReader> {
        match &self.data {
            Data::Memory(bytes) => from_bytes("bench", bytes.clone(), self.format, self.sensor),
            Data::Path(path) => open_with(
                path,
                &OpenOptions {
                    format: Some(self.format),
                    sensor_size: self.sensor,
                },
            ),
        }
        .unwrap_or_else(|e| panic!("{}: {e}", self.name))
    }

    fn decode_count(&self) -> usize {
        let mut reader = self.open();
        let mut chunk = Vec::new();
        let mut count = 0;
        while reader.read_chunk(&mut chunk).expect("input decodes") > 0 {
            count += black_box(&chunk).len();
        }
        count
    }
}

fn size_on_disk(path: &Path) -> u64 {
    if path.is_dir() {
        std::fs::read_dir(path)
            .expect("generated folder lists")
            .map(|entry| size_on_disk(&entry.expect("folder entry").path()))
            .sum()
    } else {
        std::fs::metadata(path)
            .expect("generated file exists")
            .len()
    }
}

/// EVIMO's single `.npz`: `events` as float64 rows `[t seconds, x, y, p]`.
fn write_evimo_npz(path: &Path, events: &[Event], compression: NpzCompression) {
    let rows: Vec<f64> = events
        .iter()
        .flat_map(|e| [e.t as f64 * 1e-6, e.x as f64, e.y as f64, e.polarity as f64])
        .collect();
    let mut npz = NpzWriter::create(path, compression).expect("npz creates");
    npz.add("events", &[events.len(), 4], &rows)
        .expect("events array writes");
    npz.finish().expect("npz finishes");
}

/// EVIMO2's sequence folder: three parallel `.npy` arrays.
fn write_evimo2_folder(folder: &Path, events: &[Event]) {
    std::fs::create_dir_all(folder).expect("folder creates");
    let n = events.len();
    let times: Vec<f64> = events.iter().map(|e| e.t as f64 * 1e-6).collect();
    let coordinates: Vec<u16> = events.iter().flat_map(|e| [e.x, e.y]).collect();
    let polarities: Vec<u8> = events.iter().map(|e| e.polarity).collect();
    for (name, array) in [
        (TIMES_FILE, NpyArray::from_slice(&[n], &times)),
        (
            COORDINATES_FILE,
            NpyArray::from_slice(&[n, 2], &coordinates),
        ),
        (POLARITIES_FILE, NpyArray::from_slice(&[n], &polarities)),
    ] {
        let mut file = std::fs::File::create(folder.join(name)).expect("array file creates");
        array.write(&mut file).expect("array writes");
    }
}

/// EVIMO's `events.txt`: `t x y p` with t in seconds.
fn evimo_text(events: &[Event]) -> Vec<u8> {
    events
        .iter()
        .map(|e| format!("{:.6} {} {} {}\n", e.t as f64 * 1e-6, e.x, e.y, e.polarity))
        .collect::<String>()
        .into_bytes()
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

    let evimo_stored = generated("evimo_stored.npz");
    write_evimo_npz(&evimo_stored, &events, NpzCompression::Stored);
    let evimo_deflated = generated("evimo_deflated.npz");
    write_evimo_npz(&evimo_deflated, &events, NpzCompression::Deflated);
    let evimo2 = generated("evimo2_folder");
    write_evimo2_folder(&evimo2, &events);

    let inputs = vec![
        Input::in_memory("evt2 (evt2_sample.raw)", Format::Evt2, None, evt2),
        Input::in_memory(
            "evt3 (evt3_sample.raw)",
            Format::Evt3,
            None,
            read("evt3_sample.raw"),
        ),
        Input::in_memory(
            "aedat4 (sample.aedat4)",
            Format::Aedat4,
            None,
            read("sample.aedat4"),
        ),
        Input::in_memory("csv (generated)", Format::Csv, Some(sensor), csv),
        Input::in_memory("evg (generated)", Format::Native, None, native.into_inner()),
        Input::in_memory("dat (generated)", Format::Dat, None, dat),
        Input::in_memory(
            "evimo events.txt (generated)",
            Format::Csv,
            Some(sensor),
            evimo_text(&events),
        ),
        Input::at_path(
            "evimo npz stored (generated)",
            Format::EvimoNpz,
            sensor,
            evimo_stored,
        ),
        Input::at_path(
            "evimo npz deflated (generated)",
            Format::EvimoNpz,
            sensor,
            evimo_deflated,
        ),
        Input::at_path(
            "evimo2 folder (generated)",
            Format::Evimo2Folder,
            sensor,
            evimo2,
        ),
    ];
    #[cfg(feature = "dsec")]
    let inputs = {
        let mut inputs = inputs;
        inputs.extend(dsec::inputs(&events, sensor));
        inputs
    };
    inputs
}

/// DSEC `events.h5` written with the hdf5 crate in DSEC's layout (see evgate-io's dsec.rs).
#[cfg(feature = "dsec")]
mod dsec {
    use evgate_core::{Event, SensorSize};
    use evgate_io::Format;
    use hdf5_metno::H5Type;

    use super::{generated, Input};

    /// Rows per HDF5 chunk (DSEC's files are chunked; the chunk is the unit of decompression).
    const CHUNK_ROWS: usize = 16 * 1024;
    /// The Blosc HDF5 filter as DSEC uses it: zstd, level 1, byte shuffle (the filter fills
    /// in the first four values).
    const BLOSC_FILTER: i32 = 32001;
    const BLOSC_ZSTD_LEVEL_1_SHUFFLE: [u32; 7] = [0, 0, 0, 0, 1, 1, 5];

    fn column<T: H5Type>(
        group: &hdf5_metno::Group,
        name: &str,
        values: &[T],
        blosc: bool,
    ) -> hdf5_metno::Result<()> {
        let mut builder = group.new_dataset_builder().chunk(CHUNK_ROWS);
        if blosc {
            builder = builder.add_filter(BLOSC_FILTER, &BLOSC_ZSTD_LEVEL_1_SHUFFLE);
        }
        builder.with_data(values).create(name)?;
        Ok(())
    }

    fn write(path: &std::path::Path, events: &[Event], blosc: bool) -> hdf5_metno::Result<()> {
        let t_offset = events[0].t;
        let t: Vec<u32> = events.iter().map(|e| (e.t - t_offset) as u32).collect();
        let file = hdf5_metno::File::create(path)?;
        let group = file.create_group("events")?;
        let x: Vec<u16> = events.iter().map(|e| e.x).collect();
        let y: Vec<u16> = events.iter().map(|e| e.y).collect();
        let p: Vec<u8> = events.iter().map(|e| e.polarity).collect();
        column(&group, "x", &x, blosc)?;
        column(&group, "y", &y, blosc)?;
        column(&group, "t", &t, blosc)?;
        column(&group, "p", &p, blosc)?;
        let last_ms = *t.last().expect("events") as u64 / 1000;
        let ms_to_idx: Vec<u64> = (0..=last_ms)
            .map(|ms| t.partition_point(|&t| (t as u64) < ms * 1000) as u64)
            .collect();
        file.new_dataset_builder()
            .with_data(ms_to_idx.as_slice())
            .create("ms_to_idx")?;
        file.new_dataset::<i64>()
            .create("t_offset")?
            .write_scalar(&t_offset)?;
        Ok(())
    }

    pub(super) fn inputs(events: &[Event], sensor: SensorSize) -> Vec<Input> {
        [
            ("dsec h5 blosc (generated)", "dsec_blosc.h5", true),
            ("dsec h5 uncompressed (generated)", "dsec_plain.h5", false),
        ]
        .into_iter()
        .map(|(name, file, blosc)| {
            let path = generated(file);
            write(&path, events, blosc).unwrap_or_else(|e| {
                panic!(
                    "{}: cannot write the DSEC input (is the Blosc filter installed? scripts/setup-hdf5.sh): {e}",
                    path.display()
                )
            });
            Input::at_path(name, Format::Dsec, sensor, path)
        })
        .collect()
    }
}

fn decode(criterion: &mut Criterion) {
    for input in inputs() {
        let events = input.decode_count() as u64;
        println!(
            "input {}: {} bytes, {events} events",
            input.name, input.bytes
        );
        for (unit, throughput) in [
            ("bytes", Throughput::Bytes(input.bytes)),
            ("events", Throughput::Elements(events)),
        ] {
            let mut group = criterion.benchmark_group(format!("decode/{unit}"));
            group
                .sample_size(10)
                .warm_up_time(Duration::from_millis(500))
                .measurement_time(Duration::from_secs(2))
                .throughput(throughput);
            group.bench_function(input.name, |b| b.iter(|| input.decode_count()));
            group.finish();
        }
    }
}

criterion_group!(benches, decode);
criterion_main!(benches);
