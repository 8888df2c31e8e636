//! What the harness reads from one labelled sequence: its preset, the reference times to score,
//! ground-truth frames by time and the image-plane speed of its objects.

use std::collections::BTreeMap;
use std::path::Path;

use evgate_io::sequence::LabelledSequence;

use crate::config::EvalConfig;

/// Ground-truth frames are looked up by time; a frame within this tolerance counts as "at" it.
const FRAME_TIME_TOLERANCE_US: i64 = 500;

/// A labelled sequence with its name and preset.
pub struct SequenceView<'a> {
    pub sequence: &'a LabelledSequence,
    pub name: String,
    pub preset: String,
}

impl<'a> SequenceView<'a> {
    /// The preset comes from the `preset` field of the sequence's `meta` JSON; sequences without
    /// one (converted recordings) are grouped under their parent folder's name.
    pub fn new(sequence: &'a LabelledSequence, path: &Path) -> Self {
        let from_meta = serde_json::from_str::<serde_json::Value>(&sequence.meta)
            .ok()
            .and_then(|meta| meta.get("preset")?.as_str().map(str::to_owned));
        let preset = from_meta.unwrap_or_else(|| {
            path.parent().and_then(Path::file_name).map_or_else(
                || "unknown".to_owned(),
                |n| n.to_string_lossy().into_owned(),
            )
        });
        // A suite stores each sequence as `<preset>-<seed>/sequence.npz`: the folder names it.
        let named_by_folder = path.file_stem().is_some_and(|s| s == "sequence");
        let name_source = if named_by_folder {
            path.parent().and_then(Path::file_name)
        } else {
            path.file_stem()
        };
        let name = name_source.map_or_else(
            || path.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        Self {
            sequence,
            name,
            preset,
        }
    }

    /// Reference times whose full window lies after the first event, within the configured
    /// leading span of the sequence.
    pub fn reference_times(&self, config: &EvalConfig) -> Vec<i64> {
        let Some(first_event) = self.sequence.events.first().map(|e| e.t) else {
            return Vec::new();
        };
        let window_us = i64::from(config.window_ms) * 1000;
        let limit_us = config
            .max_seconds_per_sequence
            .map(|seconds| first_event + (seconds * 1e6) as i64);
        self.sequence
            .ref_ts
            .iter()
            .copied()
            .filter(|&t| t - window_us >= first_event)
            .filter(|&t| limit_us.is_none_or(|limit| t <= limit))
            .collect()
    }

    /// Index of the ground-truth frame at time `t_us`, if there is one.
    pub fn frame_at(&self, t_us: i64) -> Option<usize> {
        let times = &self.sequence.gt_ts;
        let after = times.partition_point(|&t| t < t_us);
        [after.checked_sub(1), Some(after)]
            .into_iter()
            .flatten()
            .filter(|&i| i < times.len())
            .min_by_key(|&i| (times[i] - t_us).abs())
            .filter(|&i| (times[i] - t_us).abs() <= FRAME_TIME_TOLERANCE_US)
    }

    /// The object-id mask at time `t_us`, if a frame lies there.
    pub fn truth_at(&self, t_us: i64) -> Option<&'a [u8]> {
        self.frame_at(t_us).map(|f| self.sequence.mask_frame(f))
    }

    /// Mean image-plane speed (px/s) of the objects visible at `t_us`: centroid displacement to
    /// the next ground-truth frame over the time between them. `None` without objects or a
    /// next frame.
    pub fn object_speed_px_per_s(&self, t_us: i64) -> Option<f64> {
        let frame = self.frame_at(t_us)?;
        if frame + 1 >= self.sequence.gt_ts.len() {
            return None;
        }
        let elapsed_s = (self.sequence.gt_ts[frame + 1] - self.sequence.gt_ts[frame]) as f64 / 1e6;
        if elapsed_s <= 0.0 {
            return None;
        }
        let width = usize::from(self.sequence.sensor_size.width);
        let now = centroids(self.sequence.mask_frame(frame), width);
        let next = centroids(self.sequence.mask_frame(frame + 1), width);
        let speeds: Vec<f64> = now
            .iter()
            .filter_map(|(id, a)| {
                let b = next.get(id)?;
                Some(((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt() / elapsed_s)
            })
            .collect();
        (!speeds.is_empty()).then(|| speeds.iter().sum::<f64>() / speeds.len() as f64)
    }
}

/// Centroid (x, y) of every object id in a mask.
fn centroids(mask: &[u8], width: usize) -> BTreeMap<u8, (f64, f64)> {
    let mut sums: BTreeMap<u8, (f64, f64, f64)> = BTreeMap::new();
    for (pixel, &id) in mask.iter().enumerate() {
        if id != 0 {
            let entry = sums.entry(id).or_default();
            entry.0 += (pixel % width) as f64;
            entry.1 += (pixel / width) as f64;
            entry.2 += 1.0;
        }
    }
    sums.into_iter()
        .map(|(id, (x, y, n))| (id, (x / n, y / n)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixture;

    #[test]
    fn suite_sequences_are_named_by_their_folder() {
        let sequence = fixture::sequence();
        let view = SequenceView::new(&sequence, Path::new("data/test/boxes-300001/sequence.npz"));
        assert_eq!(view.name, "boxes-300001");
        assert_eq!(view.preset, "slide");
    }

    #[test]
    fn preset_falls_back_to_the_parent_folder() {
        let mut sequence = fixture::sequence();
        sequence.meta = "{}".to_owned();
        let view = SequenceView::new(&sequence, Path::new("recordings/evimo-table/seq_01.npz"));
        assert_eq!(
            (view.name.as_str(), view.preset.as_str()),
            ("seq_01", "evimo-table")
        );
    }

    #[test]
    fn frames_are_found_within_tolerance_only() {
        let sequence = fixture::sequence();
        let view = SequenceView::new(&sequence, Path::new("s.npz"));
        assert_eq!(view.frame_at(20_000), Some(2));
        assert_eq!(view.frame_at(20_400), Some(2));
        assert_eq!(view.frame_at(25_000), None);
        assert_eq!(view.frame_at(1_000_000), None);
    }

    #[test]
    fn object_speed_matches_the_fixture() {
        let sequence = fixture::sequence();
        let view = SequenceView::new(&sequence, Path::new("s.npz"));
        // 0.2 px/ms = 200 px/s.
        let speed = view.object_speed_px_per_s(100_000).unwrap();
        assert!((speed - 200.0).abs() < 1e-9, "{speed}");
        assert_eq!(view.object_speed_px_per_s(400_000), None);
    }
}
