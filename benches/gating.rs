//! The gate's production judge (`evgate_core::Judge`, what `evgate-gate` runs on every batch)
//! next to a plain copy of the same bytes: 1 M events of a 50 ms window, a forecast of 4 or 8
//! horizons over that window, each mask covering about a fifth of a 346×260 sensor.
//!
//! Rows: `memcpy` (16 bytes per event); `keep-bitmap-K` (the judgement alone: its pass bits are
//! the keep-bitmap output); `kept-K` (judgement, then the kept events selected: the work of
//! dv-processing's EventMaskFilter, `scripts/bench-gating.sh`); `kept-and-suppressed-K`
//! (judgement, then both event streams selected, the gate's default outputs);
//! `keep-bitmap-8-last-mask` (a fifth of the events before the forecast's reference time, left
//! to the `last-mask` policy's per-event path).

mod cpu_time;
mod uniform_events;

use std::time::Duration;

use criterion::measurement::Measurement;
use criterion::{black_box, Criterion, Throughput};
use evgate_core::{
    BitMask, Event, Forecast, ForecastView, GateMode, Judge, MaskView, NoForecast, Policy,
    SensorSize,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use uniform_events::{uniform_events, EVENTS, WINDOW_US};

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

/// The current mask then one per horizon, as the forecast stream carries them.
fn forecast_masks(horizons: usize, rng: &mut ChaCha8Rng) -> Vec<u64> {
    (0..=horizons)
        .flat_map(|_| random_mask(rng).as_words().to_vec())
        .collect()
}

/// `count` horizons evenly over the window, from 0.
fn horizons_us(count: usize) -> Vec<i64> {
    (0..count as i64)
        .map(|k| k * WINDOW_US / (count as i64 - 1))
        .collect()
}

fn forecast<'a>(reference_us: i64, horizons: &'a [i64], words: &'a [u64]) -> Forecast<'a> {
    let per_mask = words.len() / (horizons.len() + 1);
    Forecast {
        current: MaskView::new(SENSOR, &words[..per_mask]).expect("mask is well formed"),
        horizons: ForecastView::new(reference_us, horizons, SENSOR, &words[per_mask..])
            .expect("forecast is well formed"),
    }
}

const PASS: Policy = Policy {
    no_forecast: NoForecast::Pass,
    last_mask_max_age: Duration::from_millis(200),
};

/// Runs under wall time (`gate`) and under the thread's CPU time (`gate-cpu`), the latter for
/// a figure that other jobs on the machine move less.
fn gating<M: Measurement>(criterion: &mut Criterion<M>, group_name: &str) {
    let events = uniform_events(SENSOR, 11);
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mode = GateMode::KeepMovingObjects;
    let mut group = criterion.benchmark_group(group_name);
    group.throughput(Throughput::Elements(EVENTS as u64));
    let mut copy = vec![Event::default(); EVENTS];
    group.bench_function("memcpy", |bencher| {
        bencher.iter(|| copy.copy_from_slice(black_box(&events)))
    });
    let mut judge = Judge::default();
    let (mut kept, mut suppressed) = (Vec::with_capacity(EVENTS), Vec::with_capacity(EVENTS));
    for count in [4, 8] {
        let horizons = horizons_us(count);
        let words = forecast_masks(count, &mut rng);
        let forecast = forecast(0, &horizons, &words);
        group.bench_function(format!("keep-bitmap-{count}"), |bencher| {
            bencher.iter(|| judge.judge(black_box(&events), Some(forecast), mode, PASS))
        });
        group.bench_function(format!("kept-{count}"), |bencher| {
            bencher.iter(|| {
                judge.judge(black_box(&events), Some(forecast), mode, PASS);
                kept.clear();
                judge.select(&events, true, &mut kept);
            })
        });
        group.bench_function(format!("kept-and-suppressed-{count}"), |bencher| {
            bencher.iter(|| {
                judge.judge(black_box(&events), Some(forecast), mode, PASS);
                kept.clear();
                suppressed.clear();
                judge.select(&events, true, &mut kept);
                judge.select(&events, false, &mut suppressed);
            })
        });
    }
    let horizons = horizons_us(8);
    let words = forecast_masks(8, &mut rng);
    let late = forecast(WINDOW_US / 5, &horizons, &words);
    let last_mask = Policy {
        no_forecast: NoForecast::LastMask,
        ..PASS
    };
    group.bench_function("keep-bitmap-8-last-mask", |bencher| {
        bencher.iter(|| judge.judge(black_box(&events), Some(late), mode, last_mask))
    });
    group.finish();
}

wall_and_cpu_time_main!(gating, "gate", "gate-cpu");
