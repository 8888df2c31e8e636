//! The OMS baseline (retina-inspired object motion sensitivity, Clerico et al.), as the
//! authors' code computes it (soykilian/oms_generation: `gaussian_filter`, `apply_convolution`
//! and `neuro_activation_function`, with the EVIMO setting of its `main.ipynb`):
//!
//! * the frame is the window's event presence (1 where a pixel fired, either polarity);
//! * centre and surround are 2-D Gaussian kernels of `2r + 1` taps per side sampled on [-1, 1]
//!   with σ = 1 there (so σ is `r` pixels and the kernel is cut at one σ), scaled by
//!   1 / (2π) and *not* normalised: the surround weighs about 3.5 times the centre;
//! * each is convolved with zero padding ("same"), the response is |centre − surround|, then
//!   `(response − min) / max` over the frame (the reference divides by the maximum, not the
//!   range), and pixels at or above the threshold are flagged.
//!
//! Where events are dense the surround outweighs the centre, so OMS flags the densest patches of
//! the window; an isolated event gives almost no response. A worked example computed by the
//! reference code is a test (`tests/oms_reference.rs`).

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

/// |centre − surround| divided by its frame maximum after subtracting its minimum, as the
/// reference normalises it (all zeros for a flat frame, where the reference divides by zero).
pub fn normalised_response(
    presence: &[bool],
    size: SensorSize,
    centre_radius: u32,
    surround_radius: u32,
) -> Vec<f32> {
    let frame: Vec<f64> = presence.iter().map(|&p| p as u8 as f64).collect();
    let centre = gaussian_blur(&frame, size, centre_radius);
    let surround = gaussian_blur(&frame, size, surround_radius);
    let response: Vec<f64> = centre
        .iter()
        .zip(&surround)
        .map(|(c, s)| (c - s).abs())
        .collect();
    let (low, high) = response
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    response
        .iter()
        .map(|&value| {
            if high > 0.0 {
                ((value - low) / high) as f32
            } else {
                0.0
            }
        })
        .collect()
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

/// One axis of the reference's 2-D kernel: `exp(-u² / 2)` at `2r + 1` points evenly spaced on
/// [-1, 1], times 1 / sqrt(2π), so the outer product of two is the reference's kernel.
fn gaussian_axis(radius: u32) -> Vec<f64> {
    let radius = radius.max(1) as i64;
    (-radius..=radius)
        .map(|d| {
            let u = d as f64 / radius as f64;
            (-u * u / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt()
        })
        .collect()
}

/// The 2-D Gaussian of the reference applied as two separable passes, zeros outside the frame.
fn gaussian_blur(frame: &[f64], size: SensorSize, radius: u32) -> Vec<f64> {
    let kernel = gaussian_axis(radius);
    let rows_done = blur_along(frame, size, &kernel, (1, 0));
    blur_along(&rows_done, size, &kernel, (0, 1))
}

/// One pass of the separable blur: each pixel becomes the `kernel`-weighted sum of the pixels
/// centred on it along `step` (x, y); pixels outside the frame count as zero.
fn blur_along(frame: &[f64], size: SensorSize, kernel: &[f64], step: (i64, i64)) -> Vec<f64> {
    let (width, height) = (size.width as i64, size.height as i64);
    let r = (kernel.len() / 2) as i64;
    let mut blurred = vec![0.0f64; frame.len()];
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
    fn the_kernel_is_the_reference_gaussian_on_minus_one_to_one() {
        for radius in [1, 2, 4] {
            let axis = gaussian_axis(radius);
            assert_eq!(axis.len(), 2 * radius as usize + 1);
            // The 2-D centre tap is 1 / (2π); the corner tap exp(-1) / (2π).
            let tau = 2.0 * std::f64::consts::PI;
            let centre = axis[radius as usize] * axis[radius as usize];
            assert!((centre - 1.0 / tau).abs() < 1e-12);
            assert!((axis[0] * axis[0] - (-1.0f64).exp() / tau).abs() < 1e-12);
        }
    }

    #[test]
    fn a_solid_patch_responds_at_its_corners_and_a_lone_event_hardly_at_all() {
        // A solid 5×5 patch and one lone event in an empty 31×21 frame. Inside the patch the
        // centre is full and the surround partly so; the difference peaks at the patch's corners
        // (what the reference gives for this frame), while the lone event stays near zero.
        let size = SensorSize::new(31, 21);
        let mut events: Vec<Event> = (8..13)
            .flat_map(|y| (6..11).map(move |x| Event::new(0, x, y, true)))
            .collect();
        events.push(Event::new(0, 25, 10, true));
        let presence = event_presence(&events, size);
        let response = normalised_response(&presence, size, 2, 4);
        for (x, y) in [(6, 8), (10, 8), (6, 12), (10, 12)] {
            assert_eq!(response[size.index(x, y)], 1.0, "corner ({x}, {y})");
        }
        assert!(response[size.index(25, 10)] < 0.05);
        let mask = threshold_response(&response, 0.9);
        let flagged: Vec<(u16, u16)> = (0..size.height)
            .flat_map(|y| (0..size.width).map(move |x| (x, y)))
            .filter(|&(x, y)| mask[size.index(x, y)])
            .collect();
        assert_eq!(flagged.len(), 12);
        assert!(flagged
            .iter()
            .all(|&(x, y)| (6..=10).contains(&x) && (8..=12).contains(&y)));
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
