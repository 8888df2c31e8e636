//! Gating throughput next to a plain copy of the same bytes: 1 M events of a 50 ms window
//! against a mask covering about a fifth of a 346×260 sensor.

mod cpu_time;
mod uniform_events;

use criterion::measurement::Measurement;
use criterion::{black_box, Criterion, Throughput};
use evgate_core::{keep_bitmap, partition, BitMask, Event, ForecastView, GateMode, SensorSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use uniform_events::{uniform_events, EVENTS};

const SENSOR: SensorSize = SensorSize::new(346, 260);

/// Random pixels set with probability 0.2: keep decisions are unpredictable, which is what the
/// branch-free kernel is built for.
fn random_mask(rng: &mut ChaCha8Rng) -> BitMask {
    let mut mask = BitMask::new(SENSOR).expect("sensor is non-empty");
    for y in 0..SENSOR.height {
        for x in 0..SENSOR.width {
            mask.set(x, y, rng.gen_bool(0.2))
                .expect("pixel is on the sensor");
        }
    }
    mask
}

/// Runs under wall time (`gate`) and under the thread's CPU time (`gate-cpu`), the latter for
/// a figure that other jobs on the machine move less.
fn gating<M: Measurement>(criterion: &mut Criterion<M>, group_name: &str) {
    let events = uniform_events(SENSOR, 11);
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mask = random_mask(&mut rng);
    let horizons_us = [0, 20_000, 40_000, 60_000];
    let forecast_words: Vec<u64> = (0..horizons_us.len())
        .flat_map(|_| random_mask(&mut rng).as_words().to_vec())
        .collect();
    let forecast = ForecastView::new(0, &horizons_us, SENSOR, &forecast_words)
        .expect("forecast is well formed");
    let mode = GateMode::KeepMovingObjects;

    let mut group = criterion.benchmark_group(group_name);
    group.throughput(Throughput::Elements(EVENTS as u64));
    let mut copy = vec![Event::default(); EVENTS];
    group.bench_function("memcpy", |bencher| {
        bencher.iter(|| copy.copy_from_slice(black_box(&events)))
    });
    let (mut kept, mut suppressed, mut unjudged) = (Vec::new(), Vec::new(), Vec::new());
    group.bench_function("partition", |bencher| {
        bencher.iter(|| {
            kept.clear();
            suppressed.clear();
            partition(
                black_box(&events),
                mask.view(),
                mode,
                &mut kept,
                &mut suppressed,
            )
        })
    });
    let mut keep = vec![0u64; EVENTS.div_ceil(64)];
    group.bench_function("bitmap", |bencher| {
        bencher.iter(|| keep_bitmap(black_box(&events), mask.view(), mode, &mut keep))
    });
    group.bench_function("forecast-partition-4-horizons", |bencher| {
        bencher.iter(|| {
            kept.clear();
            suppressed.clear();
            unjudged.clear();
            forecast.partition(
                black_box(&events),
                mode,
                &mut kept,
                &mut suppressed,
                &mut unjudged,
            )
        })
    });
    let mut judged = vec![0u64; EVENTS.div_ceil(64)];
    group.bench_function("forecast-bitmap-4-horizons", |bencher| {
        bencher.iter(|| forecast.keep_bitmap(black_box(&events), mode, &mut keep, &mut judged))
    });
    group.finish();
}

wall_and_cpu_time_main!(gating, "gate", "gate-cpu");
