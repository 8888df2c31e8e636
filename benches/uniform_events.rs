//! The synthetic input of the core-kernel benches (gating, voxel).

use evgate_core::{Event, SensorSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub const EVENTS: usize = 1_000_000;
pub const WINDOW_US: i64 = 50_000;

/// [`EVENTS`] events evenly spaced in time over [`WINDOW_US`], pixels uniform over the sensor
/// and polarities random (both drawn from `seed`): the cache-unfriendliest layout, so the
/// figures are a floor for real, spatially clustered streams.
pub fn uniform_events(sensor: SensorSize, seed: u64) -> Vec<Event> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
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
