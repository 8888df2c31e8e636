//! Accumulation of per-frame scores into per-sequence summaries, and the averages over
//! sequences (per sequence first, then over sequences, as the paper does).

use serde::{Deserialize, Serialize};

use crate::event_scores::{EventConfusion, EventScores};
use crate::instances::InstanceCounts;
use crate::kept::{KeptCounts, KeptRates};
use crate::segmentation::{frame_success, PixelConfusion};

/// Running mean of the defined values.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mean {
    sum: f64,
    count: u64,
}

impl Mean {
    pub fn add(&mut self, value: Option<f64>) {
        if let Some(value) = value.filter(|v| v.is_finite()) {
            self.sum += value;
            self.count += 1;
        }
    }

    pub fn value(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }

    pub fn count(&self) -> u64 {
        self.count
    }
}

/// Running mean and standard deviation, and the median of the values seen.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Spread {
    sum: f64,
    sum_of_squares: f64,
    count: u64,
    values: Vec<f64>,
}

impl Spread {
    pub fn add(&mut self, value: f64) {
        self.sum += value;
        self.sum_of_squares += value * value;
        self.count += 1;
        self.values.push(value);
    }

    /// The middle value (the mean of the two middle ones for an even count).
    pub fn median(&self) -> Option<f64> {
        let mut sorted = self.values.clone();
        sorted.sort_by(f64::total_cmp);
        let middle = sorted.len() / 2;
        match sorted.len() {
            0 => None,
            n if n % 2 == 1 => Some(sorted[middle]),
            _ => Some((sorted[middle - 1] + sorted[middle]) / 2.0),
        }
    }

    pub fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }

    /// Population standard deviation.
    pub fn std(&self) -> Option<f64> {
        let mean = self.mean()?;
        Some(
            (self.sum_of_squares / self.count as f64 - mean * mean)
                .max(0.0)
                .sqrt(),
        )
    }
}

/// Scores of one method at one horizon, accumulated over frames.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HorizonAccumulator {
    pub mean_iou: Mean,
    pub imo_iou: Mean,
    /// Frames with IMO IoU ≥ the threshold, over those with an IMO in prediction or truth.
    pub success: Mean,
    pub frames: u64,
    pub instances: InstanceCounts,
}

impl HorizonAccumulator {
    pub fn add(&mut self, pixels: &PixelConfusion, instances: InstanceCounts, threshold: f64) {
        self.mean_iou.add(pixels.mean_iou());
        self.imo_iou.add(pixels.imo_iou());
        self.success
            .add(frame_success(pixels, threshold).map(|success| f64::from(u8::from(success))));
        self.frames += 1;
        self.instances.merge(instances);
    }

    pub fn summary(&self, horizon_ms: u32) -> HorizonSummary {
        HorizonSummary {
            horizon_ms,
            mean_iou: self.mean_iou.value(),
            imo_iou: self.imo_iou.value(),
            success_rate: self.success.value(),
            instance_recall: self.instances.recall(),
            frames: self.frames,
        }
    }
}

/// The scores of one method over one sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodAccumulator {
    pub horizons: Vec<HorizonAccumulator>,
    pub point_iou: Mean,
    pub events: EventConfusion,
    pub kept: KeptCounts,
    pub runtime_ms: Spread,
}

impl MethodAccumulator {
    pub fn new(horizon_count: usize) -> Self {
        Self {
            horizons: vec![HorizonAccumulator::default(); horizon_count],
            point_iou: Mean::default(),
            events: EventConfusion::default(),
            kept: KeptCounts::default(),
            runtime_ms: Spread::default(),
        }
    }

    /// `forecast_horizon_ms` is how far ahead the method's output looks (0 for methods that
    /// only describe the present): prediction age = that − runtime.
    pub fn summary(&self, horizons_ms: &[u32], forecast_horizon_ms: f64) -> MethodSummary {
        let runtime_ms_mean = self.runtime_ms.mean();
        MethodSummary {
            horizons: self
                .horizons
                .iter()
                .zip(horizons_ms)
                .map(|(accumulator, &h)| accumulator.summary(h))
                .collect(),
            point_iou: self.point_iou.value(),
            events: self.events.into(),
            kept: self.kept.rates(),
            runtime_ms_mean,
            runtime_ms_std: self.runtime_ms.std(),
            runtime_ms_median: self.runtime_ms.median(),
            prediction_age_ms: runtime_ms_mean.map(|r| forecast_horizon_ms - r),
        }
    }
}

/// One method at one horizon.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct HorizonSummary {
    pub horizon_ms: u32,
    /// Mean over frames of the mean of IMO and background IoU.
    pub mean_iou: Option<f64>,
    pub imo_iou: Option<f64>,
    /// SR@0.5: share of frames with IMO IoU ≥ the threshold, over the frames with an IMO in
    /// prediction or truth (frames with neither are left out, as in the paper's code).
    pub success_rate: Option<f64>,
    /// R@0.5: found over all ground-truth instances.
    pub instance_recall: Option<f64>,
    pub frames: u64,
}

/// One method over one sequence, or averaged over sequences.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct MethodSummary {
    pub horizons: Vec<HorizonSummary>,
    /// IMO IoU at the reference time over pixels that hold an event of the window.
    pub point_iou: Option<f64>,
    /// The suppression operator scored per event (needs per-event labels).
    pub events: EventScores,
    /// What the gate keeps (needs no ground truth).
    #[serde(default)]
    pub kept: KeptRates,
    pub runtime_ms_mean: Option<f64>,
    pub runtime_ms_std: Option<f64>,
    /// Per sequence the median; averaged over sequences like every other score.
    #[serde(default)]
    pub runtime_ms_median: Option<f64>,
    pub prediction_age_ms: Option<f64>,
}

fn mean_of(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let mut mean = Mean::default();
    values.for_each(|v| mean.add(v));
    mean.value()
}

impl MethodSummary {
    /// The macro average over sequences: each field is the mean of the sequences where it is
    /// defined; frame and event counts are summed. `None` for no summaries.
    pub fn average(summaries: &[&MethodSummary]) -> Option<MethodSummary> {
        let first = summaries.first()?;
        let horizons = (0..first.horizons.len())
            .map(|k| {
                let at = |f: fn(&HorizonSummary) -> Option<f64>| {
                    mean_of(summaries.iter().map(|s| s.horizons.get(k).and_then(f)))
                };
                HorizonSummary {
                    horizon_ms: first.horizons[k].horizon_ms,
                    mean_iou: at(|h| h.mean_iou),
                    imo_iou: at(|h| h.imo_iou),
                    success_rate: at(|h| h.success_rate),
                    instance_recall: at(|h| h.instance_recall),
                    frames: summaries
                        .iter()
                        .filter_map(|s| s.horizons.get(k))
                        .map(|h| h.frames)
                        .sum(),
                }
            })
            .collect();
        let field = |f: fn(&MethodSummary) -> Option<f64>| mean_of(summaries.iter().map(|s| f(s)));
        Some(MethodSummary {
            horizons,
            point_iou: field(|s| s.point_iou),
            events: EventScores {
                precision: field(|s| s.events.precision),
                recall: field(|s| s.events.recall),
                f1: field(|s| s.events.f1),
                events: summaries.iter().map(|s| s.events.events).sum(),
            },
            kept: KeptRates {
                kept_ratio: field(|s| s.kept.kept_ratio),
                event_rate_hz: field(|s| s.kept.event_rate_hz),
                kept_event_rate_hz: field(|s| s.kept.kept_event_rate_hz),
                judged_events: summaries.iter().map(|s| s.kept.judged_events).sum(),
            },
            runtime_ms_mean: field(|s| s.runtime_ms_mean),
            runtime_ms_std: field(|s| s.runtime_ms_std),
            runtime_ms_median: field(|s| s.runtime_ms_median),
            prediction_age_ms: field(|s| s.prediction_age_ms),
        })
    }

    /// The summary at horizon `horizon_ms`, if scored.
    pub fn at(&self, horizon_ms: u32) -> Option<&HorizonSummary> {
        self.horizons.iter().find(|h| h.horizon_ms == horizon_ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn success_rate_leaves_out_frames_without_any_imo() {
        let mut horizon = HorizonAccumulator::default();
        // Nothing in truth nor prediction: left out, as in the paper's code.
        let empty = PixelConfusion::count(&[false; 4], &[0; 4]).unwrap();
        horizon.add(&empty, InstanceCounts::default(), 0.5);
        // A claimed object where there is none: IMO IoU 0, a failure.
        let false_alarm = PixelConfusion::count(&[true, false, false, false], &[0; 4]).unwrap();
        horizon.add(&false_alarm, InstanceCounts::default(), 0.5);
        let summary = horizon.summary(100);
        assert_eq!(summary.success_rate, Some(0.0));
        assert_eq!(summary.frames, 2);
    }

    #[test]
    fn mean_skips_undefined_values() {
        let mut mean = Mean::default();
        mean.add(Some(1.0));
        mean.add(None);
        mean.add(Some(f64::NAN));
        mean.add(Some(0.0));
        assert_eq!(mean.value(), Some(0.5));
        assert_eq!(mean.count(), 2);
    }

    #[test]
    fn spread_of_known_values() {
        let mut spread = Spread::default();
        for v in [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0] {
            spread.add(v);
        }
        assert_eq!(spread.mean(), Some(5.0));
        assert_eq!(spread.std(), Some(2.0));
        assert_eq!(spread.median(), Some(4.5));
        spread.add(1.0);
        assert_eq!(spread.median(), Some(4.0));
        assert_eq!(Spread::default().median(), None);
    }

    #[test]
    fn sequences_are_averaged_not_pooled() {
        // Sequence A: 1 frame with mIoU 1.0; sequence B: 3 frames with mIoU 0.0.
        // Per-sequence-then-over-sequences gives 0.5 (pooling frames would give 0.25).
        let perfect = PixelConfusion {
            true_positive: 1,
            true_negative: 1,
            ..Default::default()
        };
        let wrong = PixelConfusion {
            false_positive: 1,
            false_negative: 1,
            ..Default::default()
        };
        let mut a = MethodAccumulator::new(1);
        a.horizons[0].add(
            &perfect,
            InstanceCounts {
                found: 1,
                instances: 1,
            },
            0.5,
        );
        let mut b = MethodAccumulator::new(1);
        for _ in 0..3 {
            b.horizons[0].add(
                &wrong,
                InstanceCounts {
                    found: 0,
                    instances: 1,
                },
                0.5,
            );
        }
        let (a, b) = (a.summary(&[0], 0.0), b.summary(&[0], 0.0));
        let average = MethodSummary::average(&[&a, &b]).unwrap();
        let horizon = average.at(0).unwrap();
        assert_eq!(horizon.mean_iou, Some(0.5));
        assert_eq!(horizon.success_rate, Some(0.5));
        assert_eq!(horizon.instance_recall, Some(0.5));
        assert_eq!(horizon.frames, 4);
    }

    #[test]
    fn prediction_age_is_horizon_minus_runtime() {
        let mut accumulator = MethodAccumulator::new(0);
        accumulator.runtime_ms.add(6.0);
        accumulator.runtime_ms.add(4.0);
        let summary = accumulator.summary(&[], 100.0);
        assert_eq!(summary.prediction_age_ms, Some(95.0));
    }
}
