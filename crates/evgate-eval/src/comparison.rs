//! The model-shipping rule: a candidate beats a baseline on a metric when the 95 % bootstrap
//! interval of their paired per-sequence difference lies above zero (docs/evaluation.md).
//!
//! The two may be two reports of one split (a new model against the shipped one) or two methods
//! of one report (the model against linear extrapolation). Sequences are paired by name; a
//! sequence scored on one side only is left out and counted.

use serde::Serialize;

use crate::bootstrap::{paired_difference, Interval, Metric};
use crate::report::Report;

/// One side of a comparison: a report and the method in it.
pub struct Side<'a> {
    pub report: &'a Report,
    pub method: &'a str,
}

/// Why two sides cannot be compared.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ComparisonError {
    #[error("method {method:?} is not in the {side} report; it has: {available}")]
    UnknownMethod {
        side: &'static str,
        method: String,
        available: String,
    },
    #[error(
        "the reports score different headline horizons (baseline {baseline} ms, candidate \
         {candidate} ms); evaluate both with the same --config"
    )]
    DifferentHeadline { baseline: u32, candidate: u32 },
    #[error("the reports share no sequence name: compare reports of the same split")]
    NoCommonSequence,
}

/// The paired difference of one metric.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct MetricDifference {
    pub metric: Metric,
    /// Sequences where both sides have the metric.
    pub sequences: usize,
    pub baseline_mean: Option<f64>,
    pub candidate_mean: Option<f64>,
    /// Mean of candidate − baseline over those sequences.
    pub mean_difference: Option<f64>,
    pub interval: Option<Interval>,
    /// The interval lies above zero: a gain beyond the sequences' noise.
    pub clear_gain: bool,
    /// The interval lies below zero: a loss beyond the sequences' noise.
    pub clear_loss: bool,
}

/// Every metric's paired difference, and the verdict on the deciding one.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct Comparison {
    pub baseline: String,
    pub candidate: String,
    pub headline_horizon_ms: u32,
    pub paired_sequences: usize,
    /// Sequence names scored on one side only, left out.
    pub unpaired_sequences: Vec<String>,
    pub deciding_metric: Metric,
    /// The rule's verdict: the deciding metric shows a clear gain.
    pub ships: bool,
    pub metrics: Vec<MetricDifference>,
}

fn check_method(side: &Side<'_>, name: &'static str) -> Result<(), ComparisonError> {
    if side.report.method(side.method).is_some() {
        return Ok(());
    }
    Err(ComparisonError::UnknownMethod {
        side: name,
        method: side.method.to_owned(),
        available: side
            .report
            .methods
            .iter()
            .map(|m| m.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// Compares `candidate` with `baseline` on every metric; `deciding` decides whether it ships.
pub fn compare(
    baseline: &Side<'_>,
    candidate: &Side<'_>,
    deciding: Metric,
) -> Result<Comparison, ComparisonError> {
    check_method(baseline, "baseline")?;
    check_method(candidate, "candidate")?;
    let headline = baseline.report.config.headline_horizon_ms;
    if candidate.report.config.headline_horizon_ms != headline {
        return Err(ComparisonError::DifferentHeadline {
            baseline: headline,
            candidate: candidate.report.config.headline_horizon_ms,
        });
    }
    let mut pairs = Vec::new();
    let mut unpaired = Vec::new();
    for sequence in &baseline.report.sequences {
        let other = candidate
            .report
            .sequences
            .iter()
            .find(|s| s.name == sequence.name);
        match (
            sequence.methods.get(baseline.method),
            other.and_then(|s| s.methods.get(candidate.method)),
        ) {
            (Some(b), Some(c)) => pairs.push((b, c)),
            _ => unpaired.push(sequence.name.clone()),
        }
    }
    unpaired.extend(
        candidate
            .report
            .sequences
            .iter()
            .filter(|s| !baseline.report.sequences.iter().any(|b| b.name == s.name))
            .map(|s| s.name.clone()),
    );
    if pairs.is_empty() {
        return Err(ComparisonError::NoCommonSequence);
    }
    let metrics: Vec<MetricDifference> = Metric::ALL
        .into_iter()
        .map(|metric| {
            let values: Vec<(f64, f64)> = pairs
                .iter()
                .filter_map(|(b, c)| Some((metric.of(c, headline)?, metric.of(b, headline)?)))
                .collect();
            let n = values.len() as f64;
            let mean = |pick: fn(&(f64, f64)) -> f64| {
                (!values.is_empty()).then(|| values.iter().map(pick).sum::<f64>() / n)
            };
            let interval = paired_difference(&values);
            MetricDifference {
                metric,
                sequences: values.len(),
                baseline_mean: mean(|v| v.1),
                candidate_mean: mean(|v| v.0),
                mean_difference: mean(|v| v.0 - v.1),
                interval,
                clear_gain: interval.is_some_and(|i| i.low > 0.0),
                clear_loss: interval.is_some_and(|i| i.high < 0.0),
            }
        })
        .collect();
    let ships = metrics
        .iter()
        .any(|difference| difference.metric == deciding && difference.clear_gain);
    Ok(Comparison {
        baseline: baseline.method.to_owned(),
        candidate: candidate.method.to_owned(),
        headline_horizon_ms: headline,
        paired_sequences: pairs.len(),
        unpaired_sequences: unpaired,
        deciding_metric: deciding,
        ships,
        metrics,
    })
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::{fixture, EvalConfig, Evaluation, Recording};

    fn two_sequence_report() -> Report {
        let mut evaluation = Evaluation::new(EvalConfig::default(), Vec::new()).unwrap();
        for name in ["suite/val/slide-0001.npz", "suite/val/slide-0002.npz"] {
            let recording = Recording::from_labelled(fixture::sequence(), Path::new(name)).unwrap();
            evaluation.evaluate(&recording, || {}).unwrap();
        }
        evaluation.finish(Some("val".to_owned())).unwrap()
    }

    #[test]
    fn a_method_against_itself_does_not_ship() {
        let report = two_sequence_report();
        let side = Side {
            report: &report,
            method: "linear",
        };
        let comparison = compare(&side, &side, Metric::MeanIou).unwrap();
        assert_eq!(comparison.paired_sequences, 2);
        assert!(comparison.unpaired_sequences.is_empty());
        assert!(!comparison.ships);
        let miou = &comparison.metrics[0];
        assert_eq!(miou.metric, Metric::MeanIou);
        assert_eq!(miou.mean_difference, Some(0.0));
        assert!(!miou.clear_gain && !miou.clear_loss);
    }

    #[test]
    fn the_oracle_clearly_beats_linear_extrapolation_where_it_is_better_everywhere() {
        let report = two_sequence_report();
        let headline = report.config.headline_horizon_ms;
        let oracle = report.overall["oracle"]
            .at(headline)
            .unwrap()
            .mean_iou
            .unwrap();
        let linear = report.overall["linear"]
            .at(headline)
            .unwrap()
            .mean_iou
            .unwrap();
        let comparison = compare(
            &Side {
                report: &report,
                method: "linear",
            },
            &Side {
                report: &report,
                method: "oracle",
            },
            Metric::MeanIou,
        )
        .unwrap();
        // Both sequences are the same recording, so the difference is the same in each: the
        // interval is that point, above zero exactly when the oracle is better.
        assert_eq!(comparison.ships, oracle > linear);
        let miou = &comparison.metrics[0];
        assert!((miou.mean_difference.unwrap() - (oracle - linear)).abs() < 1e-12);
    }

    #[test]
    fn an_unknown_method_names_the_available_ones() {
        let report = two_sequence_report();
        let error = compare(
            &Side {
                report: &report,
                method: "model:nope",
            },
            &Side {
                report: &report,
                method: "linear",
            },
            Metric::MeanIou,
        )
        .unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains("model:nope") && message.contains("linear"),
            "{message}"
        );
    }
}
