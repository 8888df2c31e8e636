//! Instance recall R@0.5: predicted connected components are matched one-to-one to ground-truth
//! instances by the Hungarian algorithm on IoU; an instance counts as found when its matched
//! component overlaps it with IoU above the threshold.

use std::collections::{BTreeMap, HashMap};

use evgate_core::SensorSize;
use serde::{Deserialize, Serialize};

use crate::components::Components;
use crate::hungarian::maximum_weight_assignment;
use crate::segmentation::SegmentationError;

/// Found and total ground-truth instances of one or more frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct InstanceCounts {
    pub found: u64,
    pub instances: u64,
}

impl InstanceCounts {
    /// Found over total; `None` when there was no instance.
    pub fn recall(&self) -> Option<f64> {
        (self.instances > 0).then(|| self.found as f64 / self.instances as f64)
    }

    pub fn merge(&mut self, other: InstanceCounts) {
        self.found += other.found;
        self.instances += other.instances;
    }
}

/// Matches the components of `predicted_imo` to the instances of `truth_ids` (0 = background).
pub fn match_instances(
    predicted_imo: &[bool],
    truth_ids: &[u8],
    size: SensorSize,
    iou_threshold: f64,
) -> Result<InstanceCounts, SegmentationError> {
    for (what, actual) in [
        ("prediction", predicted_imo.len()),
        ("ground-truth mask", truth_ids.len()),
    ] {
        if actual != size.pixels() {
            return Err(SegmentationError::SizeMismatch {
                what,
                actual,
                expected: size.pixels(),
            });
        }
    }
    let mut truth_areas: BTreeMap<u8, u64> = BTreeMap::new();
    for &id in truth_ids.iter().filter(|&&id| id != 0) {
        *truth_areas.entry(id).or_default() += 1;
    }
    if truth_areas.is_empty() {
        return Ok(InstanceCounts::default());
    }
    let components = Components::label(predicted_imo, size);
    let mut intersections: HashMap<(u8, u32), u64> = HashMap::new();
    for (&id, &label) in truth_ids.iter().zip(&components.labels) {
        if id != 0 && label != 0 {
            *intersections.entry((id, label - 1)).or_default() += 1;
        }
    }
    let ious: Vec<Vec<f64>> = truth_areas
        .iter()
        .map(|(&id, &truth_area)| {
            components
                .components
                .iter()
                .enumerate()
                .map(|(index, component)| {
                    let shared = intersections.get(&(id, index as u32)).copied().unwrap_or(0);
                    shared as f64 / (truth_area + component.area - shared) as f64
                })
                .collect()
        })
        .collect();
    let assignment = maximum_weight_assignment(&ious);
    let found = assignment
        .iter()
        .enumerate()
        .filter(|(row, column)| column.is_some_and(|c| ious[*row][c] > iou_threshold))
        .count();
    Ok(InstanceCounts {
        found: found as u64,
        instances: truth_areas.len() as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(rows: &[&str]) -> (Vec<bool>, Vec<u8>, SensorSize) {
        // '#' predicted only, digit = truth id not predicted, letter a.. = truth id 1.. predicted.
        let size = SensorSize::new(rows[0].len() as u16, rows.len() as u16);
        let mut predicted = Vec::new();
        let mut truth = Vec::new();
        for c in rows.iter().flat_map(|r| r.chars()) {
            let (p, t) = match c {
                '#' => (true, 0),
                '.' => (false, 0),
                d @ '1'..='9' => (false, d as u8 - b'0'),
                l => (true, l as u8 - b'a' + 1),
            };
            predicted.push(p);
            truth.push(t);
        }
        (predicted, truth, size)
    }

    #[test]
    fn one_good_match_one_missed_instance() {
        // Instance 1: 4 pixels, predicted component covers 3 of them + 1 extra → IoU 3/5.
        // Instance 2: 2 pixels, predicted nothing.
        let (predicted, truth, size) = frame(&["aa#...", "a1..22", "......"]);
        let counts = match_instances(&predicted, &truth, size, 0.5).unwrap();
        assert_eq!(
            counts,
            InstanceCounts {
                found: 1,
                instances: 2
            }
        );
        assert_eq!(counts.recall(), Some(0.5));
    }

    #[test]
    fn one_blob_over_two_instances_finds_at_most_one() {
        // A single component covering both instances can be matched to one of them only.
        let (predicted, truth, size) = frame(&["aaabbb", "......"]);
        let counts = match_instances(&predicted, &truth, size, 0.4).unwrap();
        assert_eq!(
            counts,
            InstanceCounts {
                found: 1,
                instances: 2
            }
        );
    }

    #[test]
    fn threshold_is_strict() {
        // IoU exactly 0.5: 2 shared pixels, 2 extra predicted.
        let (predicted, truth, size) = frame(&["aa##", "...."]);
        let counts = match_instances(&predicted, &truth, size, 0.5).unwrap();
        assert_eq!(counts.found, 0);
    }

    #[test]
    fn no_instances_gives_no_recall() {
        let (predicted, truth, size) = frame(&["##..", "...."]);
        let counts = match_instances(&predicted, &truth, size, 0.5).unwrap();
        assert_eq!(counts.recall(), None);
    }
}
