//! 95 % percentile-bootstrap intervals over sequences.
//!
//! Sequences are the unit of resampling: frames of one sequence share its scene, motion and
//! texture, so they are not independent draws. Each interval resamples the per-sequence scores
//! with replacement [`RESAMPLES`] times and takes the 2.5th and 97.5th percentiles of the
//! resampled means. The generator is seeded with a constant, so a report regenerates bit for bit.
//!
//! The shipping rule (docs/evaluation.md) uses [`paired_difference`]: candidate minus baseline
//! per sequence, the same sequences on both sides, resampled together.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::report::SequenceResult;
use crate::summary::MethodSummary;

/// Resampled means per interval.
pub const RESAMPLES: usize = 4000;
/// Seed of every interval's resampling.
const SEED: u64 = 0x05ee_d0fe_6a7e;

/// A two-sided 95 % interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct Interval {
    pub low: f64,
    pub high: f64,
}

impl Interval {
    /// Half the width: what a "± x" states.
    pub fn half_width(&self) -> f64 {
        (self.high - self.low) / 2.0
    }
}

/// The 95 % bootstrap interval of the mean of `values` (one per sequence); `None` for fewer
/// than two values, where resampling says nothing.
pub fn mean_interval(values: &[f64]) -> Option<Interval> {
    if values.len() < 2 {
        return None;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(SEED);
    let n = values.len();
    let mut means: Vec<f64> = (0..RESAMPLES)
        .map(|_| (0..n).map(|_| values[rng.gen_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    Some(Interval {
        low: percentile(&means, 0.025),
        high: percentile(&means, 0.975),
    })
}

/// The 95 % bootstrap interval of the mean paired difference `candidate - baseline` over the
/// sequences both score; `None` with fewer than two such sequences.
pub fn paired_difference(pairs: &[(f64, f64)]) -> Option<Interval> {
    let differences: Vec<f64> = pairs
        .iter()
        .map(|(candidate, baseline)| candidate - baseline)
        .collect();
    mean_interval(&differences)
}

/// Linear interpolation between the two nearest order statistics of `sorted`.
fn percentile(sorted: &[f64], quantile: f64) -> f64 {
    let position = quantile * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = (below + 1).min(sorted.len() - 1);
    let weight = position - below as f64;
    sorted[below] * (1.0 - weight) + sorted[above] * weight
}

/// One headline score of a method in one sequence: the metrics that get intervals.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Metric {
    /// mIoU at the headline horizon.
    MeanIou,
    /// IMO IoU at the headline horizon.
    ImoIou,
    /// SR@0.5 at the headline horizon.
    SuccessRate,
    /// R@0.5 at the headline horizon.
    InstanceRecall,
    /// pIoU at the reference time.
    PointIou,
    /// Per-event precision of the gate.
    EventPrecision,
    /// Per-event recall of the gate.
    EventRecall,
    /// Per-event F1 of the gate.
    EventF1,
}

impl Metric {
    pub const ALL: [Metric; 8] = [
        Metric::MeanIou,
        Metric::ImoIou,
        Metric::SuccessRate,
        Metric::InstanceRecall,
        Metric::PointIou,
        Metric::EventPrecision,
        Metric::EventRecall,
        Metric::EventF1,
    ];

    /// The name used on the command line and in tables.
    pub const fn name(self) -> &'static str {
        match self {
            Metric::MeanIou => "miou",
            Metric::ImoIou => "imo-iou",
            Metric::SuccessRate => "sr",
            Metric::InstanceRecall => "r",
            Metric::PointIou => "piou",
            Metric::EventPrecision => "event-precision",
            Metric::EventRecall => "event-recall",
            Metric::EventF1 => "event-f1",
        }
    }

    /// Parses [`Metric::name`].
    pub fn from_name(name: &str) -> Option<Metric> {
        Metric::ALL.into_iter().find(|metric| metric.name() == name)
    }

    /// This metric of `summary`, with horizon metrics read at `headline_ms`.
    pub fn of(self, summary: &MethodSummary, headline_ms: u32) -> Option<f64> {
        let at = summary.at(headline_ms);
        match self {
            Metric::MeanIou => at.and_then(|h| h.mean_iou),
            Metric::ImoIou => at.and_then(|h| h.imo_iou),
            Metric::SuccessRate => at.and_then(|h| h.success_rate),
            Metric::InstanceRecall => at.and_then(|h| h.instance_recall),
            Metric::PointIou => summary.point_iou,
            Metric::EventPrecision => summary.events.precision,
            Metric::EventRecall => summary.events.recall,
            Metric::EventF1 => summary.events.f1,
        }
        .filter(|value| value.is_finite())
    }
}

/// The intervals of one method's headline metrics over a set of sequences.
pub type MethodIntervals = BTreeMap<Metric, Interval>;

/// Per method, the interval of each metric over `sequences` (metrics defined in fewer than two
/// of them are left out).
pub fn intervals_over(
    sequences: &[&SequenceResult],
    methods: impl IntoIterator<Item = String>,
    headline_ms: u32,
) -> BTreeMap<String, MethodIntervals> {
    methods
        .into_iter()
        .map(|method| {
            let intervals = Metric::ALL
                .into_iter()
                .filter_map(|metric| {
                    let values: Vec<f64> = sequences
                        .iter()
                        .filter_map(|s| s.methods.get(&method))
                        .filter_map(|summary| metric.of(summary, headline_ms))
                        .collect();
                    Some((metric, mean_interval(&values)?))
                })
                .collect();
            (method, intervals)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_interval_holds_the_mean_and_narrows_with_more_sequences() {
        let few: Vec<f64> = [0.60, 0.70, 0.65, 0.75].to_vec();
        let many: Vec<f64> = few.iter().cycle().take(64).copied().collect();
        let (few_interval, many_interval) =
            (mean_interval(&few).unwrap(), mean_interval(&many).unwrap());
        for interval in [few_interval, many_interval] {
            assert!(
                interval.low < 0.675 && 0.675 < interval.high,
                "{interval:?}"
            );
        }
        assert!(many_interval.half_width() < few_interval.half_width() / 2.0);
    }

    #[test]
    fn identical_values_give_a_point_and_one_value_gives_none() {
        assert_eq!(
            mean_interval(&[0.5, 0.5, 0.5]),
            Some(Interval {
                low: 0.5,
                high: 0.5
            })
        );
        assert_eq!(mean_interval(&[0.5]), None);
    }

    #[test]
    fn intervals_are_reproducible() {
        let values = [0.1, 0.4, 0.35, 0.8, 0.2];
        assert_eq!(mean_interval(&values), mean_interval(&values));
    }

    #[test]
    fn a_consistent_gain_is_clear_of_zero_and_noise_is_not() {
        // Every sequence gains about 2 points: the paired interval excludes 0, although each
        // side's own interval is far wider than the gain.
        let baseline = [0.50, 0.70, 0.60, 0.80, 0.55, 0.65];
        let gains = [0.021, 0.019, 0.020, 0.022, 0.018, 0.020];
        let pairs: Vec<(f64, f64)> = baseline
            .iter()
            .zip(gains)
            .map(|(&b, g)| (b + g, b))
            .collect();
        let difference = paired_difference(&pairs).unwrap();
        assert!(difference.low > 0.0, "{difference:?}");
        assert!(mean_interval(&baseline).unwrap().half_width() > 0.02);
        // Gains of either sign around zero do not clear it.
        let noisy: Vec<(f64, f64)> = baseline
            .iter()
            .zip([0.03, -0.03, 0.02, -0.02, 0.01, -0.01])
            .map(|(&b, g)| (b + g, b))
            .collect();
        let difference = paired_difference(&noisy).unwrap();
        assert!(difference.low < 0.0 && difference.high > 0.0);
    }

    #[test]
    fn metric_names_round_trip() {
        for metric in Metric::ALL {
            assert_eq!(Metric::from_name(metric.name()), Some(metric));
        }
        assert_eq!(Metric::from_name("accuracy"), None);
    }
}
