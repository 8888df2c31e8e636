//! One recording as the harness scores it: events, what ground truth it carries (masks on a
//! regular grid with per-event labels from the simulator, masks at camera frame times from
//! EVIMO, or none for events-only recordings such as DSEC), the reference times to score and
//! the ground-truth frames by time.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};
use evgate_io::sequence::LabelledSequence;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::config::EvalConfig;

/// The simulator's frames lie on an exact 10 ms grid: a frame within this tolerance is "at" a
/// time.
pub const SIMULATOR_FRAME_TOLERANCE_US: i64 = 500;

#[derive(Debug, Error, PartialEq)]
pub enum RecordingError {
    #[error(
        "{path}: {field} has {actual} entries but the recording has {expected} {unit} \
         ({why})"
    )]
    Length {
        path: PathBuf,
        field: &'static str,
        actual: usize,
        expected: usize,
        unit: &'static str,
        why: &'static str,
    },
    #[error("{path}: {field} must be in increasing time order, but entry {index} ({value} µs) is before the previous one")]
    Unordered {
        path: PathBuf,
        field: &'static str,
        index: usize,
        value: i64,
    },
    #[error("{path}: the recording has no events")]
    NoEvents { path: PathBuf },
    #[error("{path}: sensor size {sensor} has no pixels")]
    EmptySensor { path: PathBuf, sensor: SensorSize },
}

/// What a recording can be scored against.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GroundTruth {
    /// Object-id masks on a regular grid and an object id per event (the simulator's
    /// labelled sequences): every metric.
    MasksAndEventLabels,
    /// Object-id masks at camera frame times, no per-event labels (EVIMO): every mask metric;
    /// per-event precision / recall / F1 are not available.
    Masks,
    /// Events only (DSEC): kept ratio, event rates, runtime and prediction age; every metric
    /// that needs ground truth is not available.
    EventsOnly,
}

impl GroundTruth {
    /// What reports written before recordings other than the simulator's held.
    pub fn simulator() -> Self {
        GroundTruth::MasksAndEventLabels
    }

    pub fn has_masks(self) -> bool {
        !matches!(self, GroundTruth::EventsOnly)
    }
}

/// Object-id masks (0 = static world, k = object k) at increasing times.
#[derive(Clone, Debug, PartialEq)]
pub struct MaskFrames {
    pub times_us: Vec<i64>,
    /// F × H × W, row-major.
    pub masks: Vec<u8>,
    /// A frame within this distance of a time is the ground truth at that time.
    pub tolerance_us: i64,
}

/// A recording ready to be scored.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub path: PathBuf,
    pub name: String,
    /// Sequences are averaged per group (the simulator's preset, the dataset scene).
    pub group: String,
    pub sensor_size: SensorSize,
    /// In time order.
    pub events: Vec<Event>,
    /// Object id per event, when known (the simulator's `events_label`).
    pub event_labels: Option<Vec<u16>>,
    pub frames: Option<MaskFrames>,
    /// Candidate reference times (each needs a full window after the first event to be scored).
    pub reference_times_us: Vec<i64>,
}

impl Recording {
    /// A simulator sequence (docs/sequence-format.md): reference times `ref_ts`, masks on the
    /// 10 ms grid `gt_ts`, per-event labels. The group is the `preset` of its `meta` JSON, or
    /// the parent folder's name for sequences without one (converted recordings).
    pub fn from_labelled(sequence: LabelledSequence, path: &Path) -> Result<Self, RecordingError> {
        let from_meta = serde_json::from_str::<serde_json::Value>(&sequence.meta)
            .ok()
            .and_then(|meta| meta.get("preset")?.as_str().map(str::to_owned));
        let group = from_meta.unwrap_or_else(|| parent_name(path));
        if sequence.labels.len() != sequence.events.len() {
            return Err(RecordingError::Length {
                path: path.to_path_buf(),
                field: "events_label",
                actual: sequence.labels.len(),
                expected: sequence.events.len(),
                unit: "events",
                why: "labels are needed for per-event scores",
            });
        }
        let frames = MaskFrames {
            times_us: sequence.gt_ts,
            masks: sequence.masks,
            tolerance_us: SIMULATOR_FRAME_TOLERANCE_US,
        };
        Self {
            path: path.to_path_buf(),
            name: recording_name(path),
            group,
            sensor_size: sequence.sensor_size,
            events: sequence.events,
            event_labels: Some(sequence.labels),
            frames: Some(frames),
            reference_times_us: sequence.ref_ts,
        }
        .validated()
    }

    /// A recording with object masks at camera frame times (EVIMO): the frame times are the
    /// reference times, and a frame within `tolerance_us` of t + Δt is the truth at t + Δt.
    pub fn with_mask_frames(
        path: &Path,
        group: String,
        sensor_size: SensorSize,
        events: Vec<Event>,
        frames: MaskFrames,
    ) -> Result<Self, RecordingError> {
        Self {
            path: path.to_path_buf(),
            name: recording_name(path),
            group,
            sensor_size,
            events,
            event_labels: None,
            reference_times_us: frames.times_us.clone(),
            frames: Some(frames),
        }
        .validated()
    }

    /// A recording without ground truth (DSEC, any event file): reference times every
    /// `period_us` from the first event.
    pub fn events_only(
        path: &Path,
        group: String,
        sensor_size: SensorSize,
        events: Vec<Event>,
        period_us: i64,
    ) -> Result<Self, RecordingError> {
        let (Some(first), Some(last)) = (events.first(), events.last()) else {
            return Err(RecordingError::NoEvents {
                path: path.to_path_buf(),
            });
        };
        let reference_times_us = (1..)
            .map(|k| first.t + k * period_us.max(1))
            .take_while(|&t| t <= last.t)
            .collect();
        Self {
            path: path.to_path_buf(),
            name: recording_name(path),
            group,
            sensor_size,
            events,
            event_labels: None,
            frames: None,
            reference_times_us,
        }
        .validated()
    }

    /// Every constructor ends here: the sensor, the time order and the mask sizes checked.
    fn validated(self) -> Result<Self, RecordingError> {
        if self.sensor_size.pixels() == 0 {
            return Err(RecordingError::EmptySensor {
                path: self.path.clone(),
                sensor: self.sensor_size,
            });
        }
        let ordered = |field: &'static str, times: &mut dyn Iterator<Item = i64>| {
            let mut previous = i64::MIN;
            for (index, value) in times.enumerate() {
                if value < previous {
                    return Err(RecordingError::Unordered {
                        path: self.path.clone(),
                        field,
                        index,
                        value,
                    });
                }
                previous = value;
            }
            Ok(())
        };
        ordered("events", &mut self.events.iter().map(|e| e.t))?;
        if let Some(frames) = &self.frames {
            ordered("mask frame times", &mut frames.times_us.iter().copied())?;
            let expected = frames.times_us.len() * self.sensor_size.pixels();
            if frames.masks.len() != expected {
                return Err(RecordingError::Length {
                    path: self.path.clone(),
                    field: "mask",
                    actual: frames.masks.len(),
                    expected,
                    unit: "mask pixels (frames × height × width)",
                    why: "one object-id mask per frame time",
                });
            }
        }
        Ok(self)
    }

    pub fn ground_truth(&self) -> GroundTruth {
        match (&self.frames, &self.event_labels) {
            (Some(_), Some(_)) => GroundTruth::MasksAndEventLabels,
            (Some(_), None) => GroundTruth::Masks,
            (None, _) => GroundTruth::EventsOnly,
        }
    }

    /// Reference times whose full window lies after the first event, within the configured
    /// leading span of the recording.
    pub fn reference_times(&self, config: &EvalConfig) -> Vec<i64> {
        let Some(first_event) = self.events.first().map(|e| e.t) else {
            return Vec::new();
        };
        let window_us = i64::from(config.window_ms) * 1000;
        let limit_us = config
            .max_seconds_per_sequence
            .map(|seconds| first_event + (seconds * 1e6) as i64);
        self.reference_times_us
            .iter()
            .copied()
            .filter(|&t| t - window_us >= first_event)
            .filter(|&t| limit_us.is_none_or(|limit| t <= limit))
            .collect()
    }

    /// Index of the ground-truth frame nearest to `t_us`, if one lies within the tolerance.
    pub fn frame_at(&self, t_us: i64) -> Option<usize> {
        let frames = self.frames.as_ref()?;
        let times = &frames.times_us;
        let after = times.partition_point(|&t| t < t_us);
        [after.checked_sub(1), Some(after)]
            .into_iter()
            .flatten()
            .filter(|&i| i < times.len())
            .min_by_key(|&i| (times[i] - t_us).abs())
            .filter(|&i| (times[i] - t_us).abs() <= frames.tolerance_us)
    }

    fn mask_frame(&self, frame: usize) -> &[u8] {
        let pixels = self.sensor_size.pixels();
        let frames = self
            .frames
            .as_ref()
            .expect("frame indices come from frame_at");
        &frames.masks[frame * pixels..(frame + 1) * pixels]
    }

    /// The object-id mask at time `t_us`, if a frame lies there.
    pub fn truth_at(&self, t_us: i64) -> Option<&[u8]> {
        self.frame_at(t_us).map(|f| self.mask_frame(f))
    }

    /// Mean image-plane speed (px/s) of the objects visible at `t_us`: centroid displacement to
    /// the next ground-truth frame over the time between them. `None` without objects or a
    /// next frame.
    pub fn object_speed_px_per_s(&self, t_us: i64) -> Option<f64> {
        let frame = self.frame_at(t_us)?;
        let times = &self.frames.as_ref()?.times_us;
        if frame + 1 >= times.len() {
            return None;
        }
        let elapsed_s = (times[frame + 1] - times[frame]) as f64 / 1e6;
        if elapsed_s <= 0.0 {
            return None;
        }
        let width = usize::from(self.sensor_size.width);
        let now = centroids(self.mask_frame(frame), width);
        let next = centroids(self.mask_frame(frame + 1), width);
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

/// A suite stores each sequence as `<preset>-<seed>/sequence.npz`: the folder names it; any
/// other file is named by its stem.
fn recording_name(path: &Path) -> String {
    let named_by_folder = path.file_stem().is_some_and(|s| s == "sequence");
    let source = if named_by_folder {
        path.parent().and_then(Path::file_name)
    } else {
        path.file_stem()
    };
    source.map_or_else(
        || path.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    )
}

/// The name of the folder holding `path` ("unknown" at the root).
pub fn parent_name(path: &Path) -> String {
    path.parent().and_then(Path::file_name).map_or_else(
        || "unknown".to_owned(),
        |n| n.to_string_lossy().into_owned(),
    )
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

    fn fixture_recording(path: &str) -> Recording {
        Recording::from_labelled(fixture::sequence(), Path::new(path)).unwrap()
    }

    #[test]
    fn suite_sequences_are_named_by_their_folder() {
        let recording = fixture_recording("data/test/boxes-300001/sequence.npz");
        assert_eq!(recording.name, "boxes-300001");
        assert_eq!(recording.group, "slide");
        assert_eq!(recording.ground_truth(), GroundTruth::MasksAndEventLabels);
    }

    #[test]
    fn group_falls_back_to_the_parent_folder() {
        let mut sequence = fixture::sequence();
        sequence.meta = "{}".to_owned();
        let recording =
            Recording::from_labelled(sequence, Path::new("recordings/evimo-table/seq_01.npz"))
                .unwrap();
        assert_eq!(
            (recording.name.as_str(), recording.group.as_str()),
            ("seq_01", "evimo-table")
        );
    }

    #[test]
    fn labels_must_match_events() {
        let mut sequence = fixture::sequence();
        sequence.labels.pop();
        let error = Recording::from_labelled(sequence, Path::new("x.npz")).unwrap_err();
        assert!(error.to_string().contains("events_label"), "{error}");
        assert!(error.to_string().starts_with("x.npz"), "{error}");
    }

    #[test]
    fn frames_are_found_within_tolerance_only() {
        let recording = fixture_recording("s.npz");
        assert_eq!(recording.frame_at(20_000), Some(2));
        assert_eq!(recording.frame_at(20_400), Some(2));
        assert_eq!(recording.frame_at(25_000), None);
        assert_eq!(recording.frame_at(1_000_000), None);
    }

    #[test]
    fn camera_frames_use_their_own_tolerance_and_are_the_reference_times() {
        let size = SensorSize::new(4, 2);
        let frames = MaskFrames {
            times_us: vec![100_000, 125_000, 150_000],
            masks: vec![0; 3 * size.pixels()],
            tolerance_us: 5_000,
        };
        let events = vec![Event::new(0, 0, 0, true), Event::new(200_000, 1, 1, false)];
        let recording = Recording::with_mask_frames(
            Path::new("evimo/box/seq_00.npz"),
            "box".to_owned(),
            size,
            events,
            frames,
        )
        .unwrap();
        assert_eq!(recording.ground_truth(), GroundTruth::Masks);
        assert_eq!(recording.frame_at(130_000), Some(1));
        assert_eq!(recording.frame_at(120_000), Some(1));
        assert_eq!(recording.frame_at(112_000), None);
        assert_eq!(
            recording.reference_times(&EvalConfig::default()),
            [100_000, 125_000, 150_000]
        );
    }

    #[test]
    fn mask_frames_must_fit_the_sensor() {
        let frames = MaskFrames {
            times_us: vec![0, 10],
            masks: vec![0; 7],
            tolerance_us: 1,
        };
        let error = Recording::with_mask_frames(
            Path::new("e.npz"),
            "g".to_owned(),
            SensorSize::new(2, 2),
            vec![Event::new(0, 0, 0, true)],
            frames,
        )
        .unwrap_err();
        assert!(
            error.to_string().contains("mask has 7 entries") && error.to_string().contains("8"),
            "{error}"
        );
    }

    #[test]
    fn events_only_recordings_are_referenced_every_period() {
        let events = (0..=10)
            .map(|k| Event::new(1_000 + k * 20_000, 0, 0, true))
            .collect();
        let recording = Recording::events_only(
            Path::new("dsec/zurich_city_00_a/events.h5"),
            "dsec".to_owned(),
            SensorSize::new(640, 480),
            events,
            50_000,
        )
        .unwrap();
        assert_eq!(recording.ground_truth(), GroundTruth::EventsOnly);
        assert_eq!(
            recording.reference_times_us,
            [51_000, 101_000, 151_000, 201_000]
        );
        assert_eq!(recording.truth_at(51_000), None);
        let error = Recording::events_only(
            Path::new("empty.h5"),
            "dsec".to_owned(),
            SensorSize::new(640, 480),
            Vec::new(),
            50_000,
        )
        .unwrap_err();
        assert_eq!(error.to_string(), "empty.h5: the recording has no events");
    }

    #[test]
    fn unordered_events_are_refused() {
        let events = vec![Event::new(10, 0, 0, true), Event::new(5, 0, 0, true)];
        let error = Recording::events_only(
            Path::new("u.raw"),
            "g".to_owned(),
            SensorSize::new(2, 2),
            events,
            50_000,
        )
        .unwrap_err();
        assert!(error.to_string().contains("entry 1 (5 µs)"), "{error}");
    }

    #[test]
    fn object_speed_matches_the_fixture() {
        let recording = fixture_recording("s.npz");
        // 0.2 px/ms = 200 px/s.
        let speed = recording.object_speed_px_per_s(100_000).unwrap();
        assert!((speed - 200.0).abs() < 1e-9, "{speed}");
        assert_eq!(recording.object_speed_px_per_s(400_000), None);
    }
}
