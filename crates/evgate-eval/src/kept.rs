//! What a gate keeps, measurable without ground truth: the share of judged events it keeps and
//! the event rates before and after it.

use serde::{Deserialize, Serialize};

/// Events judged and kept by a "keep moving objects" gate over a total gated time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KeptCounts {
    pub judged: u64,
    pub kept: u64,
    /// Sum of the gated spans.
    pub span_us: i64,
}

impl KeptCounts {
    pub fn merge(&mut self, other: KeptCounts) {
        self.judged += other.judged;
        self.kept += other.kept;
        self.span_us += other.span_us;
    }

    pub fn rates(&self) -> KeptRates {
        let seconds = self.span_us as f64 / 1e6;
        let per_second = |count: u64| (self.span_us > 0).then(|| count as f64 / seconds);
        KeptRates {
            kept_ratio: (self.judged > 0).then(|| self.kept as f64 / self.judged as f64),
            event_rate_hz: per_second(self.judged),
            kept_event_rate_hz: per_second(self.kept),
            judged_events: self.judged,
        }
    }
}

/// Kept ratio and event rates of one method over one sequence, or averaged over sequences.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", default)]
pub struct KeptRates {
    /// Share of the judged events the gate keeps (flags as moving-object events).
    pub kept_ratio: Option<f64>,
    /// Judged events per second entering the gate.
    pub event_rate_hz: Option<f64>,
    /// Kept events per second leaving it.
    pub kept_event_rate_hz: Option<f64>,
    pub judged_events: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_of_known_counts() {
        let mut counts = KeptCounts {
            judged: 300,
            kept: 30,
            span_us: 50_000,
        };
        counts.merge(KeptCounts {
            judged: 100,
            kept: 10,
            span_us: 50_000,
        });
        let rates = counts.rates();
        assert_eq!(rates.kept_ratio, Some(0.1));
        assert_eq!(rates.event_rate_hz, Some(4_000.0));
        assert_eq!(rates.kept_event_rate_hz, Some(400.0));
        assert_eq!(rates.judged_events, 400);
    }

    #[test]
    fn nothing_gated_is_not_available() {
        let rates = KeptCounts::default().rates();
        assert_eq!(rates.kept_ratio, None);
        assert_eq!(rates.event_rate_hz, None);
    }
}
