//! The OMS baseline (retina-inspired object motion sensitivity, Clerico et al.): an
//! event-presence frame is filtered by a small Gaussian centre and a wider Gaussian surround;
//! where the centre's activity exceeds its surround's the pixel is "object motion". The
//! difference is min–max normalised over the frame and thresholded, so the threshold is a share
//! of the frame's range (0.96 keeps only the strongest 4 %).
//!
//! Kernels are square, separable, truncated at the radius with σ = radius / 2 and normalised to
//! sum 1, so centre and surround are weighted local averages of event presence.

use evgate_core::{Event, SensorSize};
use serde::{Deserialize, Serialize};

/// One OMS setting.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct OmsParameters {
    /// Radius of the centre kernel in pixels.
    pub centre_radius: u32,
    /// Radius of the surround kernel in pixels.
    pub surround_radius: u32,
    /// Share of the normalised centre − surround range above which a pixel is flagged.
    pub threshold: f32,
}

impl OmsParameters {
    /// The published EVIMO setting: radius 2 centre, radius 4 surround, threshold 0.96.
    pub const PUBLISHED_EVIMO: Self = Self {
        centre_radius: 2,
        surround_radius: 4,
        threshold: 0.96,
    };

    /// Floating-point operations for one frame of `size`: two separable passes per kernel
    /// (a multiply and an add per tap), the difference and the normalisation.
    pub fn flops_per_frame(&self, size: SensorSize) -> u64 {
        let taps = |radius: u32| 2 * (2 * radius as u64 + 1);
        size.pixels() as u64 * (2 * taps(self.centre_radius) + 2 * taps(self.surround_radius) + 4)
    }
}

impl Default for OmsParameters {
    fn default() -> Self {
        Self::PUBLISHED_EVIMO
    }
}

/// Marks every pixel that holds at least one event of `events` (events off the frame are
/// ignored).
pub fn event_presence(events: &[Event], size: SensorSize) -> Vec<bool> {
    let mut presence = vec![false; size.pixels()];
    for event in events.iter().filter(|e| size.contains(e)) {
        presence[size.index(event.x, event.y)] = true;
    }
    presence
}

/// Centre − surround response normalised to [0, 1] over the frame (all zeros for a flat frame).
pub fn normalised_response(
    presence: &[bool],
    size: SensorSize,
    centre_radius: u32,
    surround_radius: u32,
) -> Vec<f32> {
    let frame: Vec<f32> = presence.iter().map(|&p| p as u8 as f32).collect();
    let centre = gaussian_blur(&frame, size, centre_radius);
    let surround = gaussian_blur(&frame, size, surround_radius);
    let mut response: Vec<f32> = centre.iter().zip(&surround).map(|(c, s)| c - s).collect();
    let (low, high) = response
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let range = high - low;
    for value in &mut response {
        *value = if range > 0.0 {
            (*value - low) / range
        } else {
            0.0
        };
    }
    response
}

/// The OMS mask of a normalised response.
pub fn threshold_response(response: &[f32], threshold: f32) -> Vec<bool> {
    response
        .iter()
        .map(|&v| v >= threshold && v > 0.0)
        .collect()
}

/// The OMS mask of the events of one window.
pub fn oms_mask(events: &[Event], size: SensorSize, parameters: &OmsParameters) -> Vec<bool> {
    let presence = event_presence(events, size);
    let response = normalised_response(
        &presence,
        size,
        parameters.centre_radius,
        parameters.surround_radius,
    );
    threshold_response(&response, parameters.threshold)
}

fn gaussian_kernel(radius: u32) -> Vec<f32> {
    let sigma = (radius as f32 / 2.0).max(0.5);
    let weights: Vec<f32> = (-(radius as i32)..=radius as i32)
        .map(|d| (-(d * d) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let total: f32 = weights.iter().sum();
    weights.into_iter().map(|w| w / total).collect()
}

/// Separable blur with zeros outside the frame.
fn gaussian_blur(frame: &[f32], size: SensorSize, radius: u32) -> Vec<f32> {
    let kernel = gaussian_kernel(radius);
    let rows_done = blur_along(frame, size, &kernel, (1, 0));
    blur_along(&rows_done, size, &kernel, (0, 1))
}

/// One pass of the separable blur: each pixel becomes the `kernel`-weighted sum of the pixels
/// centred on it along `step` (x, y); pixels outside the frame count as zero.
fn blur_along(frame: &[f32], size: SensorSize, kernel: &[f32], step: (i64, i64)) -> Vec<f32> {
    let (width, height) = (size.width as i64, size.height as i64);
    let r = (kernel.len() / 2) as i64;
    let mut blurred = vec![0.0f32; frame.len()];
    for y in 0..height {
        for x in 0..width {
            let mut sum = 0.0;
            for (k, weight) in kernel.iter().enumerate() {
                let offset = k as i64 - r;
                let (sx, sy) = (x + offset * step.0, y + offset * step.1);
                if (0..width).contains(&sx) && (0..height).contains(&sy) {
                    sum += weight * frame[(sy * width + sx) as usize];
                }
            }
            blurred[(y * width + x) as usize] = sum;
        }
    }
    blurred
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_sum_to_one_and_peak_in_the_middle() {
        for radius in [1, 2, 4] {
            let kernel = gaussian_kernel(radius);
            assert_eq!(kernel.len(), 2 * radius as usize + 1);
            assert!((kernel.iter().sum::<f32>() - 1.0).abs() < 1e-6);
            assert!(kernel[radius as usize] > kernel[0]);
        }
    }

    #[test]
    fn isolated_blob_stands_out_of_a_uniform_field_edge() {
        // A 3×3 blob of events in an otherwise empty 21×21 frame: the blob centre has the
        // strongest centre-over-surround excess, an empty corner has none.
        let size = SensorSize::new(21, 21);
        let events: Vec<Event> = (9..12)
            .flat_map(|y| (9..12).map(move |x| Event::new(0, x, y, true)))
            .collect();
        let presence = event_presence(&events, size);
        let response = normalised_response(&presence, size, 1, 4);
        assert_eq!(response[size.index(10, 10)], 1.0);
        let mask = threshold_response(&response, 0.9);
        assert!(mask[size.index(10, 10)]);
        assert!(!mask[size.index(0, 0)]);
        assert!(mask.iter().filter(|&&m| m).count() <= 9);
    }

    #[test]
    fn empty_window_flags_nothing() {
        let size = SensorSize::new(8, 6);
        let mask = oms_mask(&[], size, &OmsParameters::PUBLISHED_EVIMO);
        assert!(mask.iter().all(|&m| !m));
    }

    #[test]
    fn events_off_the_frame_are_ignored() {
        let size = SensorSize::new(4, 4);
        let presence = event_presence(&[Event::new(0, 9, 1, true)], size);
        assert!(presence.iter().all(|&p| !p));
    }

    #[test]
    fn flops_grow_with_radii() {
        let size = SensorSize::new(640, 480);
        let published = OmsParameters::PUBLISHED_EVIMO.flops_per_frame(size);
        assert_eq!(published, 640 * 480 * (2 * 10 + 2 * 18 + 4));
    }
}
