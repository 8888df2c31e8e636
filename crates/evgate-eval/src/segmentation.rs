//! Pixel-level segmentation scores: IoU of the IMO class and of the background, their mean
//! (mIoU) and the point-based IoU (pIoU) restricted to pixels that hold events.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A prediction, a ground truth or an event-presence map that does not cover the frame.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum SegmentationError {
    #[error("{what} has {actual} pixels but the frame has {expected} (width × height)")]
    SizeMismatch {
        what: &'static str,
        actual: usize,
        expected: usize,
    },
}

/// Pixel counts of a binary IMO prediction against a ground truth (IMO = positive class).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PixelConfusion {
    pub true_positive: u64,
    pub false_positive: u64,
    pub false_negative: u64,
    pub true_negative: u64,
}

impl PixelConfusion {
    /// Counts every pixel; `truth_ids` holds instance ids (0 = background).
    pub fn count(predicted_imo: &[bool], truth_ids: &[u8]) -> Result<Self, SegmentationError> {
        check_len("ground-truth mask", truth_ids.len(), predicted_imo.len())?;
        let mut counts = Self::default();
        for (&predicted, &id) in predicted_imo.iter().zip(truth_ids) {
            counts.add(predicted, id != 0);
        }
        Ok(counts)
    }

    /// Counts only the pixels where `considered` is true (pIoU: pixels that hold an event).
    pub fn count_where(
        predicted_imo: &[bool],
        truth_ids: &[u8],
        considered: &[bool],
    ) -> Result<Self, SegmentationError> {
        check_len("ground-truth mask", truth_ids.len(), predicted_imo.len())?;
        check_len("event-presence map", considered.len(), predicted_imo.len())?;
        let mut counts = Self::default();
        for ((&predicted, &id), &keep) in predicted_imo.iter().zip(truth_ids).zip(considered) {
            if keep {
                counts.add(predicted, id != 0);
            }
        }
        Ok(counts)
    }

    fn add(&mut self, predicted: bool, truth: bool) {
        match (predicted, truth) {
            (true, true) => self.true_positive += 1,
            (true, false) => self.false_positive += 1,
            (false, true) => self.false_negative += 1,
            (false, false) => self.true_negative += 1,
        }
    }

    /// IoU of the IMO class; `None` when neither prediction nor truth has an IMO pixel.
    pub fn imo_iou(&self) -> Option<f64> {
        ratio(
            self.true_positive,
            self.true_positive + self.false_positive + self.false_negative,
        )
    }

    /// IoU of the background class; `None` when neither has a background pixel.
    pub fn background_iou(&self) -> Option<f64> {
        ratio(
            self.true_negative,
            self.true_negative + self.false_positive + self.false_negative,
        )
    }

    /// Mean of the defined class IoUs (NaN-aware, like `np.nanmean`); `None` for an empty frame.
    pub fn mean_iou(&self) -> Option<f64> {
        let defined: Vec<f64> = [self.imo_iou(), self.background_iou()]
            .into_iter()
            .flatten()
            .collect();
        (!defined.is_empty()).then(|| defined.iter().sum::<f64>() / defined.len() as f64)
    }
}

fn ratio(numerator: u64, denominator: u64) -> Option<f64> {
    (denominator > 0).then(|| numerator as f64 / denominator as f64)
}

fn check_len(what: &'static str, actual: usize, expected: usize) -> Result<(), SegmentationError> {
    if actual == expected {
        Ok(())
    } else {
        Err(SegmentationError::SizeMismatch {
            what,
            actual,
            expected,
        })
    }
}

/// The scores of one predicted frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameScores {
    pub imo_iou: Option<f64>,
    pub background_iou: Option<f64>,
    pub mean_iou: Option<f64>,
}

impl From<PixelConfusion> for FrameScores {
    fn from(counts: PixelConfusion) -> Self {
        Self {
            imo_iou: counts.imo_iou(),
            background_iou: counts.background_iou(),
            mean_iou: counts.mean_iou(),
        }
    }
}

/// SR@0.5 contribution of one frame: IMO IoU ≥ 0.5. A frame without IMO pixels in prediction
/// and truth has no IMO IoU and is left out (`None`), as in the paper's reference code
/// (uzh-rpg/event_suppression, `metrics.success_at` and its `nanmean`).
pub fn frame_success(counts: &PixelConfusion, threshold: f64) -> Option<bool> {
    counts.imo_iou().map(|iou| iou >= threshold)
}

#[cfg(test)]
mod tests {
    use super::*;

    // 4×2 frame: truth has object 3 on the left two columns of row 0 and object 1 at (3, 1).
    const TRUTH: [u8; 8] = [3, 3, 0, 0, 0, 0, 0, 1];
    const PREDICTION: [bool; 8] = [true, false, true, false, false, false, false, true];

    #[test]
    fn counts_known_confusion() {
        let counts = PixelConfusion::count(&PREDICTION, &TRUTH).unwrap();
        assert_eq!(
            counts,
            PixelConfusion {
                true_positive: 2,
                false_positive: 1,
                false_negative: 1,
                true_negative: 4
            }
        );
        assert_eq!(counts.imo_iou(), Some(0.5));
        assert_eq!(counts.background_iou(), Some(4.0 / 6.0));
        assert_eq!(counts.mean_iou(), Some((0.5 + 4.0 / 6.0) / 2.0));
    }

    #[test]
    fn point_iou_ignores_pixels_without_events() {
        let events = [true, true, false, false, true, false, false, false];
        let counts = PixelConfusion::count_where(&PREDICTION, &TRUTH, &events).unwrap();
        assert_eq!(counts.true_positive, 1);
        assert_eq!(counts.false_negative, 1);
        assert_eq!(counts.false_positive, 0);
        assert_eq!(counts.true_negative, 1);
        assert_eq!(counts.imo_iou(), Some(0.5));
    }

    #[test]
    fn empty_imo_class_is_left_out_of_the_mean() {
        let counts = PixelConfusion::count(&[false; 4], &[0; 4]).unwrap();
        assert_eq!(counts.imo_iou(), None);
        assert_eq!(counts.background_iou(), Some(1.0));
        assert_eq!(counts.mean_iou(), Some(1.0));
        assert_eq!(frame_success(&counts, 0.5), None);
    }

    #[test]
    fn success_needs_half_overlap() {
        let counts = PixelConfusion::count(&PREDICTION, &TRUTH).unwrap();
        assert_eq!(frame_success(&counts, 0.5), Some(true));
        assert_eq!(frame_success(&counts, 0.51), Some(false));
    }

    #[test]
    fn size_mismatch_is_reported() {
        let error = PixelConfusion::count(&[true; 3], &[0; 4]).unwrap_err();
        assert_eq!(
            error.to_string(),
            "ground-truth mask has 4 pixels but the frame has 3 (width × height)"
        );
    }
}
