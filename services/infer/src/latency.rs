//! Summaries of repeated timings: totals over the whole run, percentiles over a recent window
//! (a long-running service must not grow without bound).

use std::collections::VecDeque;
use std::time::Duration;

use serde::Serialize;

/// Samples kept for the percentiles (at 20 windows per second, the last 3.4 minutes).
const RECENT_SAMPLES: usize = 4096;

#[derive(Debug, Default)]
pub struct TimingRecorder {
    count: u64,
    total_ms: f64,
    max_ms: f64,
    recent_ms: VecDeque<f64>,
}

/// What a [`TimingRecorder`] reports, in milliseconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct TimingSummary {
    pub count: u64,
    pub mean_ms: f64,
    /// Median of the most recent samples (up to 4096).
    pub median_ms: f64,
    /// 99th percentile (nearest rank) of the most recent samples.
    pub p99_ms: f64,
    pub max_ms: f64,
}

impl TimingRecorder {
    pub fn record(&mut self, duration: Duration) {
        let ms = duration.as_secs_f64() * 1e3;
        self.count += 1;
        self.total_ms += ms;
        self.max_ms = self.max_ms.max(ms);
        if self.recent_ms.len() == RECENT_SAMPLES {
            self.recent_ms.pop_front();
        }
        self.recent_ms.push_back(ms);
    }

    pub fn summary(&self) -> TimingSummary {
        if self.count == 0 {
            return TimingSummary::default();
        }
        let mut sorted: Vec<f64> = self.recent_ms.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        TimingSummary {
            count: self.count,
            mean_ms: self.total_ms / self.count as f64,
            median_ms: nearest_rank(&sorted, 0.5),
            p99_ms: nearest_rank(&sorted, 0.99),
            max_ms: self.max_ms,
        }
    }
}

/// Nearest-rank percentile of sorted, non-empty samples.
pub fn nearest_rank(sorted: &[f64], quantile: f64) -> f64 {
    let rank = (quantile * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_of_one_to_a_hundred() {
        let mut recorder = TimingRecorder::default();
        for ms in (1..=100).rev() {
            recorder.record(Duration::from_millis(ms));
        }
        let summary = recorder.summary();
        assert_eq!(summary.count, 100);
        assert!((summary.mean_ms - 50.5).abs() < 1e-9);
        assert!((summary.median_ms - 50.0).abs() < 1e-9);
        assert!((summary.p99_ms - 99.0).abs() < 1e-9);
        assert!((summary.max_ms - 100.0).abs() < 1e-9);
    }

    #[test]
    fn an_empty_recorder_reports_zeros() {
        assert_eq!(
            TimingRecorder::default().summary(),
            TimingSummary::default()
        );
    }
}
