//! Settings of an evaluation run (kebab-case keys, every one with a default).

use serde::{Deserialize, Serialize};
use thiserror::Error;

use evgate_model::metadata::MAX_KEEP_DILATION_PX;

use crate::oms::OmsParameters;

#[derive(Debug, Error, PartialEq)]
pub enum ConfigError {
    #[error("horizons-ms must be non-empty and strictly increasing, got {0:?}")]
    Horizons(Vec<u32>),
    #[error("headline-horizon-ms {headline} is not one of horizons-ms {horizons:?}")]
    Headline { headline: u32, horizons: Vec<u32> },
    #[error("gate-span-ms {0} must be > 0 and not beyond the last horizon")]
    GateSpan(u32),
    #[error("{field} must lie in (0, 1], got {value}")]
    Threshold { field: &'static str, value: f64 },
    #[error("speed-bucket-edges-px-per-s must be positive and strictly increasing, got {0:?}")]
    SpeedEdges(Vec<f64>),
    #[error("oms-sweep.{field} must not be empty")]
    EmptySweep { field: &'static str },
    #[error("window-ms must be > 0, got 0")]
    Window,
    #[error("camera-frame-tolerance-ms must be finite and ≥ 0, got {0}")]
    FrameTolerance(f64),
    #[error("oracle-keep-dilation-px must be a whole number of pixels from 0 to {MAX_KEEP_DILATION_PX}, got {0}")]
    OracleDilation(u16),
}

/// The OMS parameter grid searched for the best setting.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default, deny_unknown_fields)]
pub struct OmsSweep {
    pub centre_radii: Vec<u32>,
    pub surround_radii: Vec<u32>,
    pub thresholds: Vec<f32>,
}

impl Default for OmsSweep {
    fn default() -> Self {
        Self {
            centre_radii: vec![1, 2, 3],
            surround_radii: vec![4, 6, 8],
            thresholds: vec![0.5, 0.6, 0.7, 0.8, 0.9, 0.96],
        }
    }
}

impl OmsSweep {
    /// Every combination with the surround wider than the centre.
    pub fn settings(&self) -> Vec<OmsParameters> {
        let mut settings = Vec::new();
        for &centre_radius in &self.centre_radii {
            for &surround_radius in self.surround_radii.iter().filter(|&&s| s > centre_radius) {
                for &threshold in &self.thresholds {
                    settings.push(OmsParameters {
                        centre_radius,
                        surround_radius,
                        threshold,
                    });
                }
            }
        }
        settings
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default, deny_unknown_fields)]
pub struct EvalConfig {
    /// Forecast horizons scored, on the ground truth's 10 ms grid.
    pub horizons_ms: Vec<u32>,
    /// The horizon of the headline tables (Table I, ablation, model sizes) and the binned plots.
    pub headline_horizon_ms: u32,
    /// Length of the event window that ends at each reference time.
    pub window_ms: u32,
    /// Events in [t, t + gate-span) are gated by the forecast made at t and scored per event
    /// (the next forecast takes over after one reference period).
    pub gate_span_ms: u32,
    /// IoU above which a matched instance counts as found (R@0.5) and at or above which a frame
    /// counts as a success (SR@0.5).
    pub iou_threshold: f64,
    /// The OMS setting reported as "published".
    pub oms: OmsParameters,
    pub oms_sweep: OmsSweep,
    /// Linear extrapolation pairs components whose centroids moved at most this far per window.
    pub linear_max_match_distance_px: f64,
    /// Object-speed bucket boundaries in pixels per second.
    pub speed_bucket_edges_px_per_s: Vec<f64>,
    /// Bins per decade of the events-per-window plot (10² to 10⁶ events).
    pub event_bins_per_decade: u32,
    /// Only the first this-many seconds of each sequence are scored (all when absent).
    pub max_seconds_per_sequence: Option<f64>,
    /// Recordings with masks at camera frame times (EVIMO): the frame nearest to t + Δt is the
    /// truth at t + Δt when it lies at most this far away (half the 10 ms horizon step, so no
    /// frame stands in for a horizon nearer another one). The simulator's exact grid uses 0.5.
    pub camera_frame_tolerance_ms: f64,
    /// The oracle gates with the true masks dilated by this many pixels (the keep rule's square):
    /// an object's events fire on its edges, partly outside its mask, so undilated masks bound
    /// the per-event scores from below, not above. 0 gates with the masks themselves. Without a
    /// model, no-forecast and linear, which then move the true mask at t, dilate alike.
    pub oracle_keep_dilation_px: u16,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            horizons_ms: (0..=100).step_by(10).collect(),
            headline_horizon_ms: 100,
            window_ms: 50,
            gate_span_ms: 50,
            iou_threshold: 0.5,
            oms: OmsParameters::PUBLISHED_EVIMO,
            oms_sweep: OmsSweep::default(),
            linear_max_match_distance_px: 40.0,
            speed_bucket_edges_px_per_s: vec![90.0, 120.0, 240.0, 480.0],
            event_bins_per_decade: 2,
            max_seconds_per_sequence: None,
            camera_frame_tolerance_ms: 5.0,
            oracle_keep_dilation_px: 0,
        }
    }
}

impl EvalConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.horizons_ms.is_empty() || self.horizons_ms.windows(2).any(|p| p[1] <= p[0]) {
            return Err(ConfigError::Horizons(self.horizons_ms.clone()));
        }
        if !self.horizons_ms.contains(&self.headline_horizon_ms) {
            return Err(ConfigError::Headline {
                headline: self.headline_horizon_ms,
                horizons: self.horizons_ms.clone(),
            });
        }
        if self.window_ms == 0 {
            return Err(ConfigError::Window);
        }
        let tolerance = self.camera_frame_tolerance_ms;
        if !tolerance.is_finite() || tolerance < 0.0 {
            return Err(ConfigError::FrameTolerance(tolerance));
        }
        if self.oracle_keep_dilation_px > MAX_KEEP_DILATION_PX {
            return Err(ConfigError::OracleDilation(self.oracle_keep_dilation_px));
        }
        let last = *self.horizons_ms.last().expect("checked non-empty");
        if self.gate_span_ms == 0 || self.gate_span_ms > last {
            return Err(ConfigError::GateSpan(self.gate_span_ms));
        }
        if !(self.iou_threshold > 0.0 && self.iou_threshold <= 1.0) {
            return Err(ConfigError::Threshold {
                field: "iou-threshold",
                value: self.iou_threshold,
            });
        }
        if !(self.oms.threshold > 0.0 && self.oms.threshold <= 1.0) {
            return Err(ConfigError::Threshold {
                field: "oms.threshold",
                value: self.oms.threshold.into(),
            });
        }
        let edges = &self.speed_bucket_edges_px_per_s;
        if edges.iter().any(|&e| e.is_nan() || e <= 0.0) || edges.windows(2).any(|p| p[1] <= p[0]) {
            return Err(ConfigError::SpeedEdges(edges.clone()));
        }
        let sweep = &self.oms_sweep;
        for (field, empty) in [
            ("centre-radii", sweep.centre_radii.is_empty()),
            ("surround-radii", sweep.surround_radii.is_empty()),
            ("thresholds", sweep.thresholds.is_empty()),
        ] {
            if empty {
                return Err(ConfigError::EmptySweep { field });
            }
        }
        Ok(())
    }

    pub fn camera_frame_tolerance_us(&self) -> i64 {
        (self.camera_frame_tolerance_ms * 1000.0).round() as i64
    }

    pub fn horizons_us(&self) -> Vec<i64> {
        self.horizons_ms
            .iter()
            .map(|&h| i64::from(h) * 1000)
            .collect()
    }

    /// Index of the headline horizon in `horizons_ms`.
    pub fn headline_index(&self) -> usize {
        self.horizons_ms
            .iter()
            .position(|&h| h == self.headline_horizon_ms)
            .unwrap_or(self.horizons_ms.len() - 1)
    }

    /// Speed bucket names, e.g. `≤90`, `90–120`, `>480` px/s.
    pub fn speed_bucket_labels(&self) -> Vec<String> {
        let edges = &self.speed_bucket_edges_px_per_s;
        let mut labels = Vec::with_capacity(edges.len() + 1);
        if let Some(first) = edges.first() {
            labels.push(format!("<={first}"));
        }
        for pair in edges.windows(2) {
            labels.push(format!("{}-{}", pair[0], pair[1]));
        }
        labels.push(match edges.last() {
            Some(last) => format!(">{last}"),
            None => "all".to_string(),
        });
        labels
    }

    /// Bucket index of a speed in px/s.
    pub fn speed_bucket(&self, speed: f64) -> usize {
        self.speed_bucket_edges_px_per_s
            .iter()
            .take_while(|&&edge| speed > edge)
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_match_the_paper() {
        let config = EvalConfig::default();
        config.validate().unwrap();
        assert_eq!(config.horizons_ms.len(), 11);
        assert_eq!(config.headline_index(), 10);
        assert_eq!(config.oms, OmsParameters::PUBLISHED_EVIMO);
    }

    #[test]
    fn kebab_case_keys_with_defaults() {
        let config: EvalConfig =
            serde_json::from_str(r#"{"headline-horizon-ms": 50, "gate-span-ms": 20}"#).unwrap();
        assert_eq!(config.headline_horizon_ms, 50);
        assert_eq!(config.window_ms, 50);
        config.validate().unwrap();
    }

    #[test]
    fn headline_must_be_a_scored_horizon() {
        let config = EvalConfig {
            headline_horizon_ms: 55,
            ..EvalConfig::default()
        };
        assert!(config
            .validate()
            .unwrap_err()
            .to_string()
            .contains("headline-horizon-ms 55"));
    }

    #[test]
    fn camera_frame_tolerance_must_be_a_distance() {
        let config: EvalConfig =
            serde_json::from_str(r#"{"camera-frame-tolerance-ms": 12.5}"#).unwrap();
        assert_eq!(config.camera_frame_tolerance_us(), 12_500);
        let negative = EvalConfig {
            camera_frame_tolerance_ms: -1.0,
            ..EvalConfig::default()
        };
        assert_eq!(
            negative.validate().unwrap_err().to_string(),
            "camera-frame-tolerance-ms must be finite and ≥ 0, got -1"
        );
    }

    #[test]
    fn the_oracles_keep_dilation_is_a_keep_rule_radius() {
        let config: EvalConfig =
            serde_json::from_str(r#"{"oracle-keep-dilation-px": 16}"#).unwrap();
        config.validate().unwrap();
        let wide: EvalConfig = serde_json::from_str(r#"{"oracle-keep-dilation-px": 17}"#).unwrap();
        assert_eq!(
            wide.validate().unwrap_err().to_string(),
            "oracle-keep-dilation-px must be a whole number of pixels from 0 to 16, got 17"
        );
    }

    #[test]
    fn speed_buckets() {
        let config = EvalConfig::default();
        assert_eq!(config.speed_bucket(90.0), 0);
        assert_eq!(config.speed_bucket(100.0), 1);
        assert_eq!(config.speed_bucket(1000.0), 4);
        assert_eq!(
            config.speed_bucket_labels(),
            vec!["<=90", "90-120", "120-240", "240-480", ">480"]
        );
    }

    #[test]
    fn sweep_skips_surround_not_wider_than_centre() {
        let sweep = OmsSweep {
            centre_radii: vec![2, 4],
            surround_radii: vec![4],
            thresholds: vec![0.9],
        };
        assert_eq!(sweep.settings().len(), 1);
    }
}
