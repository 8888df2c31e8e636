//! Voxelisation throughput: 1 M events of a 50 ms window splatted into a 2-bin grid.

mod cpu_time;

use criterion::measurement::Measurement;
use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use evgate_core::{Event, SensorSize, TimeSpan, VoxelGrid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const EVENTS: usize = 1_000_000;
const WINDOW_US: i64 = 50_000;

/// Time-sorted events spread uniformly over the sensor: the cache-unfriendliest layout, so the
/// figure is a floor for real, spatially clustered streams.
fn uniform_events(sensor: SensorSize) -> Vec<Event> {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    (0..EVENTS)
        .map(|index| {
            Event::new(
                index as i64 * WINDOW_US / EVENTS as i64,
                rng.gen_range(0..sensor.width),
                rng.gen_range(0..sensor.height),
                rng.gen(),
            )
        })
        .collect()
}

/// Runs under wall time (`voxelise`) and under the thread's CPU time (`voxelise-cpu`), the
/// latter for a figure that other jobs on the machine move less.
fn voxelisation<M: Measurement>(criterion: &mut Criterion<M>, group_name: &str) {
    let window = TimeSpan::new(0, WINDOW_US).expect("window is non-empty");
    let mut group = criterion.benchmark_group(group_name);
    group.throughput(Throughput::Elements(EVENTS as u64));
    for sensor in [SensorSize::new(346, 260), SensorSize::new(640, 480)] {
        let events = uniform_events(sensor);
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
    group.finish();
}

fn wall_time(criterion: &mut Criterion) {
    voxelisation(criterion, "voxelise");
}

fn cpu_time(criterion: &mut Criterion<cpu_time::ThreadCpuTime>) {
    voxelisation(criterion, "voxelise-cpu");
}

criterion_group!(wall, wall_time);
criterion_group!(
    name = cpu;
    config = Criterion::default().with_measurement(cpu_time::ThreadCpuTime);
    targets = cpu_time
);
criterion_main!(wall, cpu);
