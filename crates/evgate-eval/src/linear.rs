//! Linear extrapolation: every connected component of the current mask moves on at the velocity
//! of its centroid between the previous window's mask and the current one.
//!
//! Components are paired one-to-one by the Hungarian algorithm on centroid distance; pairs
//! farther apart than `max_match_distance_px`, and components without a partner, keep still.

use evgate_core::SensorSize;

use crate::components::Components;
use crate::hungarian::maximum_weight_assignment;

/// Velocities in pixels per microsecond of the current components.
pub fn component_velocities(
    previous: &Components,
    current: &Components,
    elapsed_us: i64,
    max_match_distance_px: f64,
) -> Vec<(f64, f64)> {
    let distance =
        |a: (f64, f64), b: (f64, f64)| ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt();
    let closeness: Vec<Vec<f64>> = current
        .components
        .iter()
        .map(|now| {
            previous
                .components
                .iter()
                .map(|before| -distance(now.centroid, before.centroid))
                .collect()
        })
        .collect();
    let pairs = maximum_weight_assignment(&closeness);
    current
        .components
        .iter()
        .zip(pairs)
        .map(|(now, partner)| match partner {
            Some(index) if elapsed_us > 0 => {
                let before = previous.components[index].centroid;
                if distance(now.centroid, before) > max_match_distance_px {
                    (0.0, 0.0)
                } else {
                    (
                        (now.centroid.0 - before.0) / elapsed_us as f64,
                        (now.centroid.1 - before.1) / elapsed_us as f64,
                    )
                }
            }
            _ => (0.0, 0.0),
        })
        .collect()
}

/// The current mask moved forward by `horizon_us` with per-component velocities (pixels that
/// leave the frame are dropped).
pub fn shift_components(
    current: &Components,
    velocities: &[(f64, f64)],
    size: SensorSize,
    horizon_us: i64,
) -> Vec<bool> {
    let mut future = vec![false; size.pixels()];
    let offsets: Vec<(i64, i64)> = velocities
        .iter()
        .map(|(vx, vy)| {
            (
                (vx * horizon_us as f64).round() as i64,
                (vy * horizon_us as f64).round() as i64,
            )
        })
        .collect();
    let width = size.width as i64;
    for (pixel, &label) in current.labels.iter().enumerate() {
        if label == 0 {
            continue;
        }
        let (dx, dy) = offsets[label as usize - 1];
        let (x, y) = (pixel as i64 % width + dx, pixel as i64 / width + dy);
        if x >= 0 && y >= 0 && x < width && y < size.height as i64 {
            future[(y * width + x) as usize] = true;
        }
    }
    future
}

/// Forecasts of `current` at every horizon, given the mask one window earlier.
pub fn extrapolate(
    previous: &[bool],
    current: &[bool],
    size: SensorSize,
    elapsed_us: i64,
    horizons_us: &[i64],
    max_match_distance_px: f64,
) -> Vec<Vec<bool>> {
    let before = Components::label(previous, size);
    let now = Components::label(current, size);
    let velocities = component_velocities(&before, &now, elapsed_us, max_match_distance_px);
    horizons_us
        .iter()
        .map(|&horizon| shift_components(&now, &velocities, size, horizon))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(size: SensorSize, left: u16, top: u16, side: u16) -> Vec<bool> {
        let mut mask = vec![false; size.pixels()];
        for y in top..top + side {
            for x in left..left + side {
                mask[size.index(x, y)] = true;
            }
        }
        mask
    }

    #[test]
    fn moving_square_keeps_moving() {
        let size = SensorSize::new(30, 20);
        let previous = square(size, 2, 5, 3);
        let current = square(size, 6, 5, 3);
        // 4 px per 50 ms → 8 px after 100 ms, 0 px at horizon 0.
        let futures = extrapolate(&previous, &current, size, 50_000, &[0, 100_000], 20.0);
        assert_eq!(futures[0], current);
        assert_eq!(futures[1], square(size, 14, 5, 3));
    }

    #[test]
    fn two_objects_get_their_own_velocities() {
        let size = SensorSize::new(40, 20);
        let mut previous = square(size, 2, 2, 2);
        let mut current = square(size, 4, 2, 2);
        for (p, c) in previous.iter_mut().zip(square(size, 30, 12, 2)) {
            *p |= c;
        }
        for (p, c) in current.iter_mut().zip(square(size, 30, 10, 2)) {
            *p |= c;
        }
        let future = extrapolate(&previous, &current, size, 10, &[10], 20.0).remove(0);
        let mut expected = square(size, 6, 2, 2);
        for (e, c) in expected.iter_mut().zip(square(size, 30, 8, 2)) {
            *e |= c;
        }
        assert_eq!(future, expected);
    }

    #[test]
    fn unmatched_or_far_components_stay_still() {
        let size = SensorSize::new(40, 10);
        let current = square(size, 30, 2, 2);
        let nothing_before = vec![false; size.pixels()];
        let future = extrapolate(&nothing_before, &current, size, 50, &[100], 5.0).remove(0);
        assert_eq!(future, current);
        let far_before = square(size, 1, 2, 2);
        let future = extrapolate(&far_before, &current, size, 50, &[100], 5.0).remove(0);
        assert_eq!(future, current);
    }

    #[test]
    fn pixels_leaving_the_frame_are_dropped() {
        let size = SensorSize::new(10, 4);
        let previous = square(size, 5, 1, 2);
        let current = square(size, 7, 1, 2);
        let future = extrapolate(&previous, &current, size, 1, &[1], 10.0).remove(0);
        assert_eq!(future.iter().filter(|&&m| m).count(), 2);
    }
}
