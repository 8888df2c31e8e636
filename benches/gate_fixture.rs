//! What the shared-memory benches (ipc_latency, throughput) feed the gate: random event
//! batches on one sensor and forecasts over it.

use evgate_core::{words_for, BitMask, Event, SensorSize};
use evgate_ipc::ForecastHeader;
use rand::{Rng, SeedableRng};

pub use evgate_benches::{flag_value, write_report, BenchResult};

pub const SENSOR: SensorSize = SensorSize::new(346, 260);
pub const REFERENCE_US: i64 = 1_000_000;
pub const HORIZONS_US: [i64; 2] = [25_000, 50_000];

/// `size` random events on the sensor, all inside the forecast's horizons, in time order.
pub fn random_batch(size: usize, seed: u64) -> Vec<Event> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut events: Vec<Event> = (0..size)
        .map(|_| {
            Event::new(
                REFERENCE_US + rng.gen_range(0..HORIZONS_US[1]),
                rng.gen_range(0..SENSOR.width),
                rng.gen_range(0..SENSOR.height),
                rng.gen_bool(0.5),
            )
        })
        .collect();
    events.sort_by_key(|e| e.t);
    events
}

/// A mask of the pixels in the sensor's leftmost `columns` columns.
pub fn left_columns_mask(columns: u16) -> BitMask {
    let mut mask = BitMask::new(SENSOR).expect("non-empty sensor");
    for y in 0..SENSOR.height {
        for x in 0..columns {
            mask.set(x, y, true).expect("pixel on the sensor");
        }
    }
    mask
}

/// A forecast for stream `stream_id` at the reference time whose masks (now and at every
/// horizon) are all `mask`.
pub fn forecast(mask: &BitMask, stream_id: u64) -> (ForecastHeader, Vec<u64>) {
    let mut header = ForecastHeader {
        source_stream_id: stream_id,
        reference_time_us: REFERENCE_US,
        window_start_us: REFERENCE_US - 50_000,
        horizon_count: HORIZONS_US.len() as u32,
        words_per_mask: words_for(SENSOR.pixels()) as u32,
        width: SENSOR.width,
        height: SENSOR.height,
        ..Default::default()
    };
    header.horizons_us[..HORIZONS_US.len()].copy_from_slice(&HORIZONS_US);
    (header, mask.as_words().repeat(1 + HORIZONS_US.len()))
}
