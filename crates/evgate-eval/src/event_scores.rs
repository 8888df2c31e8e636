//! Per-event scores of the suppression operator: every event of the forecast interval is either
//! flagged as coming from an independently moving object (it falls inside the forecast mask) or
//! not, and the simulator's label says where it truly came from. The IMO class is the positive
//! one, so precision and recall describe the events a "keep IMO events" gate keeps (equivalently
//! the events a "keep ego-motion events" gate suppresses).

use serde::{Deserialize, Serialize};

/// Event counts of flagged-as-IMO against truly-from-an-IMO.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EventConfusion {
    pub true_positive: u64,
    pub false_positive: u64,
    pub false_negative: u64,
    pub true_negative: u64,
}

impl EventConfusion {
    pub fn add(&mut self, flagged_imo: bool, truly_imo: bool) {
        match (flagged_imo, truly_imo) {
            (true, true) => self.true_positive += 1,
            (true, false) => self.false_positive += 1,
            (false, true) => self.false_negative += 1,
            (false, false) => self.true_negative += 1,
        }
    }

    pub fn merge(&mut self, other: EventConfusion) {
        self.true_positive += other.true_positive;
        self.false_positive += other.false_positive;
        self.false_negative += other.false_negative;
        self.true_negative += other.true_negative;
    }

    pub fn events(&self) -> u64 {
        self.true_positive + self.false_positive + self.false_negative + self.true_negative
    }

    /// Share of flagged events that truly came from an IMO; `None` when nothing was flagged.
    pub fn precision(&self) -> Option<f64> {
        let flagged = self.true_positive + self.false_positive;
        (flagged > 0).then(|| self.true_positive as f64 / flagged as f64)
    }

    /// Share of IMO events that were flagged; `None` when there was no IMO event.
    pub fn recall(&self) -> Option<f64> {
        let imo = self.true_positive + self.false_negative;
        (imo > 0).then(|| self.true_positive as f64 / imo as f64)
    }

    /// Harmonic mean of precision and recall; 0 when both are 0, `None` when either is undefined.
    pub fn f1(&self) -> Option<f64> {
        let (precision, recall) = (self.precision()?, self.recall()?);
        Some(if precision + recall > 0.0 {
            2.0 * precision * recall / (precision + recall)
        } else {
            0.0
        })
    }
}

/// Precision, recall and F1 in one record for reports.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EventScores {
    pub precision: Option<f64>,
    pub recall: Option<f64>,
    pub f1: Option<f64>,
    pub events: u64,
}

impl From<EventConfusion> for EventScores {
    fn from(counts: EventConfusion) -> Self {
        Self {
            precision: counts.precision(),
            recall: counts.recall(),
            f1: counts.f1(),
            events: counts.events(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_precision_recall_f1() {
        let mut counts = EventConfusion::default();
        for (flagged, truth) in [(true, true), (true, true), (true, false), (false, true)] {
            counts.add(flagged, truth);
        }
        counts.add(false, false);
        assert_eq!(counts.precision(), Some(2.0 / 3.0));
        assert_eq!(counts.recall(), Some(2.0 / 3.0));
        assert!((counts.f1().unwrap() - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(counts.events(), 5);
    }

    #[test]
    fn undefined_when_nothing_flagged_or_nothing_true() {
        let mut counts = EventConfusion::default();
        counts.add(false, false);
        assert_eq!(counts.precision(), None);
        assert_eq!(counts.recall(), None);
        assert_eq!(counts.f1(), None);
    }

    #[test]
    fn zero_f1_when_all_flags_are_wrong() {
        let mut counts = EventConfusion::default();
        counts.add(true, false);
        counts.add(false, true);
        assert_eq!(counts.f1(), Some(0.0));
    }
}
