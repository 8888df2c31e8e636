//! Voxelisation throughput into a 2-bin grid: 1 M synthetic events of a 50 ms window with
//! pixels uniform over the sensor, and the real 640×480 EVT 2.0 recordings cut into 50 ms
//! windows.

mod cpu_time;
mod uniform_events;

use criterion::measurement::Measurement;
use criterion::{black_box, BenchmarkId, Criterion, Throughput};
use evgate_core::{events_in, Event, SensorSize, TimeSpan, VoxelGrid};
use uniform_events::{uniform_events, EVENTS, WINDOW_US};

/// Real recordings, relative to this package's manifest (shared/ sits beside the repository).
const RECORDINGS: [&str; 2] = [
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/real/evt2_640x480.raw"
    ),
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/real/evt2_sample.raw"
    ),
];

/// A decoded recording and its 50 ms windows (one window over the whole span when the
/// recording is no longer than that, so that no window holds a lone trailing event).
struct Recording {
    name: String,
    sensor: SensorSize,
    events: Vec<Event>,
    /// `(span, first event index, event count)` per window.
    windows: Vec<(TimeSpan, usize, usize)>,
}

impl Recording {
    fn load(path: &str) -> Self {
        let mut reader = evgate_io::open(path).unwrap_or_else(|error| panic!("{path}: {error}"));
        let sensor = reader.sensor_size();
        let events =
            evgate_io::read_all(reader.as_mut()).unwrap_or_else(|error| panic!("{path}: {error}"));
        let (first, last) = match (events.first(), events.last()) {
            (Some(first), Some(last)) => (first.t, last.t),
            _ => panic!("{path}: no events"),
        };
        let windows = if last - first <= WINDOW_US {
            let span = TimeSpan::new(first, last.max(first + 1)).expect("span is non-empty");
            vec![(span, 0, events.len())]
        } else {
            // Consecutive 50 ms windows from the first event, as the inference service cuts them.
            let mut next_first = 0;
            (0..=(last - first) / WINDOW_US)
                .map(|k| {
                    let span = TimeSpan::new(first + k * WINDOW_US, first + (k + 1) * WINDOW_US)
                        .expect("span is non-empty");
                    let count = events_in(&events, span).len();
                    let window = (span, next_first, count);
                    next_first += count;
                    window
                })
                .collect()
        };
        let name = std::path::Path::new(path)
            .file_stem()
            .map(|stem| stem.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.to_owned());
        let per_window: Vec<String> = windows
            .iter()
            .map(|(span, _, count)| format!("{count} events / {} µs", span.duration()))
            .collect();
        eprintln!(
            "{name}: {sensor}, {} events, windows: {}",
            events.len(),
            per_window.join(", ")
        );
        Self {
            name,
            sensor,
            events,
            windows,
        }
    }

    fn window_events(&self, first: usize, count: usize) -> &[Event] {
        &self.events[first..first + count]
    }
}

/// Runs under wall time (`voxelise`) and under the thread's CPU time (`voxelise-cpu`), the
/// latter for a figure that other jobs on the machine move less.
fn voxelisation<M: Measurement>(criterion: &mut Criterion<M>, group_name: &str) {
    let window = TimeSpan::new(0, WINDOW_US).expect("window is non-empty");
    let mut group = criterion.benchmark_group(group_name);
    group.throughput(Throughput::Elements(EVENTS as u64));
    for sensor in [SensorSize::new(346, 260), SensorSize::new(640, 480)] {
        let events = uniform_events(sensor, 7);
        let mut grid = VoxelGrid::new(sensor, 2).expect("sensor and bins are valid");
        group.bench_with_input(
            BenchmarkId::new("accumulate", sensor),
            &events,
            |bencher, events| bencher.iter(|| grid.accumulate(black_box(events), window)),
        );
        grid.clear();
        grid.accumulate(&events, window);
        group.bench_function(
            BenchmarkId::new("clear-accumulate-normalise", sensor),
            |bencher| {
                bencher.iter(|| {
                    grid.clear();
                    grid.accumulate(black_box(&events), window);
                    grid.normalise()
                })
            },
        );
    }
    for path in RECORDINGS {
        let recording = Recording::load(path);
        group.throughput(Throughput::Elements(recording.events.len() as u64));
        let mut grid = VoxelGrid::new(recording.sensor, 2).expect("sensor and bins are valid");
        group.bench_function(
            BenchmarkId::new("accumulate-windows", &recording.name),
            |bencher| {
                bencher.iter(|| {
                    for &(span, first, count) in &recording.windows {
                        grid.accumulate(black_box(recording.window_events(first, count)), span);
                    }
                })
            },
        );
        group.bench_function(
            BenchmarkId::new("clear-accumulate-normalise-windows", &recording.name),
            |bencher| {
                bencher.iter(|| {
                    for &(span, first, count) in &recording.windows {
                        grid.clear();
                        grid.accumulate(black_box(recording.window_events(first, count)), span);
                        black_box(grid.normalise());
                    }
                })
            },
        );
    }
    group.finish();
}

wall_and_cpu_time_main!(voxelisation, "voxelise", "voxelise-cpu");
