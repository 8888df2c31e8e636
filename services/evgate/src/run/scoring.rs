//! Per-event scores of the gate against the simulator's labels: the keep bitmap of each batch
//! joined with the label slice of the same batch.

use evgate_core::GateMode;
use std::collections::HashMap;

use serde::Serialize;

/// Confusion counts of "kept" against "wanted", and their scores.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct Scores {
    pub events_scored: u64,
    /// Kept and wanted.
    pub true_positive: u64,
    /// Kept but not wanted.
    pub false_positive: u64,
    /// Suppressed but wanted.
    pub false_negative: u64,
    /// Suppressed and not wanted.
    pub true_negative: u64,
    pub precision: Option<f64>,
    pub recall: Option<f64>,
    pub f1: Option<f64>,
    /// Fraction of the scored events suppressed.
    pub suppressed_ratio: Option<f64>,
}

impl Scores {
    fn finish(mut self) -> Self {
        let ratio = |num: u64, den: u64| (den > 0).then(|| num as f64 / den as f64);
        self.precision = ratio(self.true_positive, self.true_positive + self.false_positive);
        self.recall = ratio(self.true_positive, self.true_positive + self.false_negative);
        self.f1 = ratio(
            2 * self.true_positive,
            2 * self.true_positive + self.false_positive + self.false_negative,
        );
        self.suppressed_ratio = ratio(self.false_negative + self.true_negative, self.events_scored);
        self
    }
}

/// Joins labels and keep bitmaps by batch sequence number.
pub struct Scorer {
    /// The events the gate should keep: the positive class of the scores (label > 0 for
    /// moving objects, label = 0 for ego-motion).
    wanted: GateMode,
    stream_id: Option<u64>,
    labels: HashMap<u64, Vec<u16>>,
    bitmaps: HashMap<u64, Vec<u64>>,
    counts: Scores,
}

impl Scorer {
    pub fn new(wanted: GateMode) -> Self {
        Self {
            wanted,
            stream_id: None,
            labels: HashMap::new(),
            bitmaps: HashMap::new(),
            counts: Scores::default(),
        }
    }

    /// Forgets pending halves of another stream (an ingest restart).
    fn follow(&mut self, stream_id: u64) {
        if self.stream_id != Some(stream_id) {
            self.stream_id = Some(stream_id);
            self.labels.clear();
            self.bitmaps.clear();
        }
    }

    pub fn add_labels(&mut self, stream_id: u64, sequence: u64, labels: &[u16]) {
        self.follow(stream_id);
        match self.bitmaps.remove(&sequence) {
            Some(bitmap) => self.score(labels, &bitmap),
            None => {
                self.labels.insert(sequence, labels.to_vec());
            }
        }
    }

    pub fn add_bitmap(&mut self, stream_id: u64, sequence: u64, bitmap: &[u64]) {
        self.follow(stream_id);
        match self.labels.remove(&sequence) {
            Some(labels) => self.score(&labels, bitmap),
            None => {
                self.bitmaps.insert(sequence, bitmap.to_vec());
            }
        }
    }

    fn score(&mut self, labels: &[u16], bitmap: &[u64]) {
        for (index, &label) in labels.iter().enumerate() {
            let Some(word) = bitmap.get(index / 64) else {
                break;
            };
            let kept = word >> (index % 64) & 1 == 1;
            let wanted = match self.wanted {
                GateMode::KeepMovingObjects => label > 0,
                GateMode::KeepEgoMotion => label == 0,
            };
            let counts = &mut self.counts;
            counts.events_scored += 1;
            match (kept, wanted) {
                (true, true) => counts.true_positive += 1,
                (true, false) => counts.false_positive += 1,
                (false, true) => counts.false_negative += 1,
                (false, false) => counts.true_negative += 1,
            }
        }
    }

    pub fn scores(&self) -> Scores {
        self.counts.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joins_halves_in_either_order_and_scores_them() {
        let mut scorer = Scorer::new(GateMode::KeepMovingObjects);
        // Batch 0: labels first. Events: object, object, background, background; kept 1 and 3.
        scorer.add_labels(9, 0, &[1, 2, 0, 0]);
        scorer.add_bitmap(9, 0, &[0b1010]);
        // Batch 1: bitmap first. One background event, kept.
        scorer.add_bitmap(9, 1, &[0b1]);
        scorer.add_labels(9, 1, &[0]);
        let scores = scorer.scores();
        assert_eq!(scores.events_scored, 5);
        assert_eq!(
            (
                scores.true_positive,
                scores.false_positive,
                scores.false_negative,
                scores.true_negative
            ),
            (1, 2, 1, 1)
        );
        assert_eq!(scores.precision, Some(1.0 / 3.0));
        assert_eq!(scores.recall, Some(0.5));
        assert_eq!(scores.f1, Some(0.4));
    }
}
