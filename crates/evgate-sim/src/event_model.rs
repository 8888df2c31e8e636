//! Parameters of the event-camera pixel model, with their sources.

use serde::{Deserialize, Serialize};

/// How pixels turn log-intensity changes into events, and how often the scene is rendered.
///
/// Defaults: contrast thresholds 0.2 ± 0.03 (log units) and the 0.5 ms refractory period are
/// v2e's defaults (Hu, Liu, Delbruck, CVPRW 2021, `v2e_args.py`); leak noise 0.1 Hz per pixel is
/// v2e's `noisy` setting; shot noise 0.5 Hz per pixel lies between v2e's good-light default
/// (0.001 Hz) and its `noisy` setting (5 Hz), in the range of DAVIS346 background activity
/// indoors. Sampling follows ESIM (Rebecq, Gehrig, Scaramuzza, CoRL 2018): renders are spaced
/// so that no image point moves more than `max-step-px` between two renders (1 px, the bound
/// v2e's automatic timestamp resolution uses), and event times are interpolated linearly in log
/// intensity between renders.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default, deny_unknown_fields)]
pub struct EventModel {
    /// Mean ON threshold in log intensity.
    pub threshold_on: f32,
    /// Mean OFF threshold in log intensity.
    pub threshold_off: f32,
    /// Standard deviation of the per-pixel thresholds (fixed-pattern mismatch).
    pub threshold_sigma: f32,
    /// Floor for a pixel's threshold after drawing the mismatch.
    pub threshold_min: f32,
    /// A pixel that fired ignores crossings for this long (µs).
    pub refractory_us: i64,
    /// Temporal noise: ON and OFF events at random times, per pixel (Hz).
    pub shot_noise_hz: f32,
    /// Leak events: ON events from reference drift, per pixel (Hz).
    pub leak_noise_hz: f32,
    /// Share of pixels that are hot (fire ON events at `hot-pixel-hz`); 0 disables them.
    pub hot_pixel_fraction: f32,
    /// Rate of each hot pixel (Hz).
    pub hot_pixel_hz: f32,
    /// Largest image motion between two renders (pixels).
    pub max_step_px: f32,
    /// Longest time between two renders (µs), also when nothing moves.
    pub max_step_us: i64,
    /// Shortest time between two renders (µs), bounding the cost of extreme motion.
    pub min_step_us: i64,
    /// Mean readout delay of an event after its threshold crossing (µs, exponentially
    /// distributed): the timestamp jitter of an arbitrated readout; 0 stamps the crossing.
    #[serde(skip_serializing_if = "is_zero")]
    pub timestamp_jitter_us: f32,
}

fn is_zero(value: &f32) -> bool {
    *value == 0.0
}

impl Default for EventModel {
    fn default() -> Self {
        Self {
            threshold_on: 0.2,
            threshold_off: 0.2,
            threshold_sigma: 0.03,
            threshold_min: 0.05,
            refractory_us: 500,
            shot_noise_hz: 0.5,
            leak_noise_hz: 0.1,
            hot_pixel_fraction: 0.0,
            hot_pixel_hz: 100.0,
            max_step_px: 1.0,
            max_step_us: 5_000,
            min_step_us: 20,
            timestamp_jitter_us: 0.0,
        }
    }
}

impl EventModel {
    /// The first parameter outside its valid range, as (field, value, accepted range).
    pub fn invalid_field(&self) -> Option<(&'static str, f64, &'static str)> {
        let checks: [(&'static str, f64, bool, &'static str); 11] = [
            (
                "threshold-on",
                self.threshold_on as f64,
                self.threshold_on > 0.0,
                "> 0",
            ),
            (
                "threshold-off",
                self.threshold_off as f64,
                self.threshold_off > 0.0,
                "> 0",
            ),
            (
                "threshold-sigma",
                self.threshold_sigma as f64,
                self.threshold_sigma >= 0.0,
                ">= 0",
            ),
            (
                "threshold-min",
                self.threshold_min as f64,
                self.threshold_min > 0.0,
                "> 0",
            ),
            (
                "refractory-us",
                self.refractory_us as f64,
                self.refractory_us >= 0,
                ">= 0",
            ),
            (
                "shot-noise-hz",
                self.shot_noise_hz as f64,
                self.shot_noise_hz >= 0.0,
                ">= 0",
            ),
            (
                "leak-noise-hz",
                self.leak_noise_hz as f64,
                self.leak_noise_hz >= 0.0,
                ">= 0",
            ),
            (
                "hot-pixel-fraction",
                self.hot_pixel_fraction as f64,
                (0.0..=1.0).contains(&self.hot_pixel_fraction),
                "0..=1",
            ),
            (
                "max-step-px",
                self.max_step_px as f64,
                self.max_step_px > 0.0,
                "> 0",
            ),
            (
                "min-step-us",
                self.min_step_us as f64,
                self.min_step_us >= 1 && self.min_step_us <= self.max_step_us,
                "1..=max-step-us",
            ),
            (
                "timestamp-jitter-us",
                self.timestamp_jitter_us as f64,
                (0.0..=10_000.0).contains(&self.timestamp_jitter_us),
                "0..=10000",
            ),
        ];
        checks
            .into_iter()
            .find(|(_, _, ok, _)| !ok)
            .map(|(field, value, _, accepted)| (field, value, accepted))
    }
}
