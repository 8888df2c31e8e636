//! Reads any input of `evgate eval` into a [`Recording`]: a simulator sequence (labelled
//! `.npz`: every metric), an EVIMO recording (any other `.npz`, an EVIMO2 sequence folder or an
//! EVIMO text folder: masks at the ground-truth frame times, no per-event labels), or any event
//! file evgate-io decodes (DSEC `events.h5` with the `dsec` feature, RAW, AEDAT 4, …: no
//! ground truth).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};
use evgate_io::npz::NpzReader;
use evgate_io::{
    open_with, DecodeError, EventReader, EvimoError, EvimoRecording, LabelledSequence, OpenOptions,
    SequenceError,
};
use thiserror::Error;

use crate::config::EvalConfig;
use crate::recording::{parent_name, MaskFrames, Recording, RecordingError};

#[derive(Debug, Error)]
pub enum InputError {
    #[error(transparent)]
    Sequence(#[from] SequenceError),
    #[error(transparent)]
    Evimo(#[from] EvimoError),
    #[error(transparent)]
    Decode(#[from] DecodeError),
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error(
        "{path}: frame at {t_us} µs: object id {id} is the {count}th distinct object of the \
         recording; masks are scored with at most 255 objects"
    )]
    TooManyObjects {
        path: PathBuf,
        t_us: i64,
        id: u16,
        count: usize,
    },
}

/// How an input is read, beyond the file itself.
#[derive(Clone, Debug, Default)]
pub struct InputOptions {
    /// Averaging group of the recording (default: a simulator sequence's preset, else the name
    /// of the folder holding the file or sequence folder).
    pub group: Option<String>,
    /// Sensor size for event files whose header gives none.
    pub sensor_size: Option<SensorSize>,
}

/// True for the simulator's labelled sequences (docs/sequence-format.md), which hold `ref_ts`.
fn is_labelled_sequence(path: &Path) -> bool {
    is_npz(path) && NpzReader::open(path).is_ok_and(|npz| npz.contains("ref_ts"))
}

fn is_npz(path: &Path) -> bool {
    path.is_file() && path.extension().is_some_and(|e| e == "npz")
}

/// EVIMO layouts: a folder with `dataset_info.npz` (EVIMO2) or `meta.txt` (text), or a `.npz`
/// that is not a simulator sequence.
fn is_evimo(path: &Path) -> bool {
    if path.is_dir() {
        return path.join("dataset_info.npz").is_file() || path.join("meta.txt").is_file();
    }
    is_npz(path)
}

/// The time span after the first event that the scored references need, when limited.
fn span_limit_us(config: &EvalConfig) -> Option<i64> {
    let last_horizon_ms = config.horizons_ms.last().copied().unwrap_or(0);
    config.max_seconds_per_sequence.map(|seconds| {
        (seconds * 1e6) as i64 + i64::from(last_horizon_ms.max(config.gate_span_ms)) * 1000
    })
}

/// Reads one input (see the module documentation for what decides its kind). With
/// `max-seconds-per-sequence` set, events and frames past the scored span are not read.
pub fn read_recording(
    path: &Path,
    config: &EvalConfig,
    options: &InputOptions,
) -> Result<Recording, InputError> {
    let mut recording = if is_labelled_sequence(path) {
        Recording::from_labelled(LabelledSequence::read(path)?, path)?
    } else if is_evimo(path) {
        read_evimo(path, config)?
    } else {
        read_events_only(path, config, options.sensor_size)?
    };
    if let Some(group) = &options.group {
        recording.group = group.clone();
    }
    Ok(recording)
}

/// An EVIMO recording: events, and the object-id masks at the ground-truth frame times, which
/// are also the reference times; the truth at t + Δt is the frame nearest to it within
/// `camera-frame-tolerance-ms`.
pub fn read_evimo(path: &Path, config: &EvalConfig) -> Result<Recording, InputError> {
    let evimo = EvimoRecording::open(path)?;
    let limit = span_limit_us(config);
    let events = read_events(evimo.events()?.as_mut(), limit)?;
    let end_us = match (limit, events.first()) {
        (Some(limit), Some(first)) => Some(first.t + limit),
        _ => None,
    };
    // EVIMO's ids (object id × 1000 on disk) become 1, 2, … in order of appearance.
    let mut compact_ids: BTreeMap<u16, u8> = BTreeMap::new();
    let (mut times_us, mut masks) = (Vec::new(), Vec::new());
    for frame in evimo.frames()? {
        let frame = frame?;
        if end_us.is_some_and(|end| frame.t_us > end) {
            break;
        }
        for &id in &frame.mask {
            let next = compact_ids.len() + 1;
            let compact = match id {
                0 => 0,
                id => *compact_ids.entry(id).or_insert(next.min(255) as u8),
            };
            if compact_ids.len() > 255 {
                return Err(InputError::TooManyObjects {
                    path: path.to_path_buf(),
                    t_us: frame.t_us,
                    id,
                    count: compact_ids.len(),
                });
            }
            masks.push(compact);
        }
        times_us.push(frame.t_us);
    }
    let frames = MaskFrames {
        times_us,
        masks,
        tolerance_us: config.camera_frame_tolerance_us(),
    };
    Ok(Recording::with_mask_frames(
        path,
        parent_name(path),
        evimo.sensor_size(),
        events,
        frames,
    )?)
}

/// Any event file, without ground truth: references every window length from the first event.
pub fn read_events_only(
    path: &Path,
    config: &EvalConfig,
    sensor_size: Option<SensorSize>,
) -> Result<Recording, InputError> {
    let options = OpenOptions {
        format: None,
        sensor_size,
    };
    let mut reader = open_with(path, &options)?;
    let events = read_events(reader.as_mut(), span_limit_us(config))?;
    Ok(Recording::events_only(
        path,
        parent_name(path),
        reader.sensor_size(),
        events,
        i64::from(config.window_ms) * 1000,
    )?)
}

/// Every event (or those within `span_limit_us` of the first), in time order: decoders pass
/// small timestamp regressions through (and count them), windows need order.
pub fn read_events(
    reader: &mut dyn EventReader,
    span_limit_us: Option<i64>,
) -> Result<Vec<Event>, DecodeError> {
    let mut events: Vec<Event> = Vec::new();
    let mut chunk = Vec::new();
    while reader.read_chunk(&mut chunk)? > 0 {
        let first = events.first().or(chunk.first()).map_or(0, |e| e.t);
        match span_limit_us {
            Some(limit) if chunk.last().is_some_and(|e| e.t > first + limit) => {
                events.extend(chunk.iter().filter(|e| e.t <= first + limit));
                break;
            }
            _ => events.extend_from_slice(&chunk),
        }
    }
    if events.windows(2).any(|pair| pair[1].t < pair[0].t) {
        events.sort_by_key(|e| e.t);
    }
    Ok(events)
}

#[cfg(test)]
mod tests {
    use std::fs::File;

    use super::*;
    use crate::recording::GroundTruth;
    use crate::Evaluation;

    const WIDTH: usize = 32;
    const HEIGHT: usize = 16;
    /// EVIMO's ground truth comes at the camera's frame rate: 40 Hz here.
    const FRAME_PERIOD_S: f64 = 0.025;
    const FRAMES: usize = 16;

    /// Left edge of the 4×4 object at `t_s`: 2 px + 60 px/s.
    fn object_left(t_s: f64) -> usize {
        2 + (t_s * 60.0) as usize
    }

    fn write_png(path: &Path, raw_mask: &[u16]) {
        let file = File::create(path).unwrap();
        let mut encoder = png::Encoder::new(file, WIDTH as u32, HEIGHT as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Sixteen);
        let mut writer = encoder.write_header().unwrap();
        // EVIMO writes BGR with OpenCV: read back, red holds the mask and blue the depth (mm).
        let data: Vec<u8> = raw_mask
            .iter()
            .flat_map(|&m| [m.to_be_bytes(), [0, 0], 1500u16.to_be_bytes()].concat())
            .collect();
        writer.write_image_data(&data).unwrap();
    }

    /// An EVIMO text folder as EVIMO's ground-truth tool writes it: `meta.txt` (a Python
    /// literal), `events.txt` (t in seconds) and one `depth_mask_<i>.png` per frame, the object
    /// (id 3, stored as 3000) sliding right.
    fn write_evimo_text_folder(folder: &Path) {
        let mut meta = format!(
            "{{'meta': {{'fx': 200.0, 'res_x': {WIDTH}, 'res_y': {HEIGHT}}}, 'frames': [\n"
        );
        for i in 0..FRAMES {
            let ts = 0.1 + i as f64 * FRAME_PERIOD_S;
            meta.push_str(&format!(
                "{{'id': {i}, 'ts': {ts:.6}, 'gt_frame': 'depth_mask_{i}.png'}},\n"
            ));
            let left = object_left(ts);
            let raw: Vec<u16> = (0..WIDTH * HEIGHT)
                .map(|p| {
                    let (x, y) = (p % WIDTH, p / WIDTH);
                    if (left..left + 4).contains(&x) && (6..10).contains(&y) {
                        3000
                    } else {
                        0
                    }
                })
                .collect();
            write_png(&folder.join(format!("depth_mask_{i}.png")), &raw);
        }
        meta.push_str("], 'full_trajectory': []}\n");
        std::fs::write(folder.join("meta.txt"), meta).unwrap();
        let mut text = String::new();
        for step in 0..500 {
            let t = 0.04 + step as f64 * 0.001;
            let left = object_left(t);
            for y in 6..10 {
                text.push_str(&format!("{t:.6} {} {y} 1\n", left + 3));
                text.push_str(&format!("{t:.6} {left} {y} 0\n"));
            }
            text.push_str(&format!(
                "{t:.6} {} {} 1\n",
                step * 7 % WIDTH,
                step % HEIGHT
            ));
        }
        std::fs::write(folder.join("events.txt"), text).unwrap();
    }

    #[test]
    fn evimo_text_folders_become_recordings_with_masks_at_frame_times() {
        let root = tempfile::tempdir().unwrap();
        let folder = root.path().join("box").join("seq_00");
        std::fs::create_dir_all(&folder).unwrap();
        write_evimo_text_folder(&folder);
        let config = EvalConfig::default();
        let recording = read_recording(&folder, &config, &InputOptions::default()).unwrap();
        assert_eq!(recording.ground_truth(), GroundTruth::Masks);
        assert_eq!(
            (recording.name.as_str(), recording.group.as_str()),
            ("seq_00", "box")
        );
        assert_eq!(
            recording.sensor_size,
            SensorSize::new(WIDTH as u16, HEIGHT as u16)
        );
        assert_eq!(recording.reference_times_us.len(), FRAMES);
        assert_eq!(recording.reference_times_us[1], 125_000);
        // Object id 3 (3000 on disk) is the recording's first object.
        let mask = recording.truth_at(100_000).unwrap();
        assert_eq!(mask.iter().filter(|&&id| id == 1).count(), 16);
        assert_eq!(mask.iter().filter(|&&id| id > 1).count(), 0);
        // t + 10 ms lies 10 ms and 15 ms from the frames around it: beyond the 5 ms tolerance.
        assert_eq!(recording.truth_at(110_000), None);

        let mut evaluation = Evaluation::new(config, Vec::new()).unwrap();
        evaluation.evaluate(&recording, || {}).unwrap();
        let report = evaluation.finish(None).unwrap();
        let oracle = &report.overall["oracle"];
        assert_eq!(oracle.at(50).unwrap().mean_iou, Some(1.0));
        assert_eq!(oracle.at(10).unwrap().frames, 0);
        assert_eq!(report.overall["oms"].events.f1, None);
        assert!(report.overall["oms"].kept.kept_ratio.is_some());
    }

    #[test]
    fn a_npz_that_is_neither_a_sequence_nor_evimo_is_named() {
        let root = tempfile::tempdir().unwrap();
        let path = root.path().join("other.npz");
        let mut writer =
            evgate_io::npz::NpzWriter::create(&path, evgate_io::npz::NpzCompression::Stored)
                .unwrap();
        writer.add::<f32>("x", &[1], &[0.0]).unwrap();
        writer.finish().unwrap();
        let error = read_recording(&path, &EvalConfig::default(), &InputOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("other.npz") && error.contains("not an EVIMO recording"),
            "{error}"
        );
    }

    #[test]
    fn event_files_become_events_only_recordings_limited_to_the_scored_span() {
        let folder = tempfile::tempdir().unwrap();
        let path = folder.path().join("drive").join("events.csv");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let text: String = (0..400)
            .map(|k| format!("{} {} {} {}\n", 1_000 + k * 1_000, k % 20, k % 10, k % 2))
            .collect();
        std::fs::write(&path, text).unwrap();
        let options = InputOptions {
            group: None,
            sensor_size: Some(SensorSize::new(20, 10)),
        };
        let recording = read_recording(&path, &EvalConfig::default(), &options).unwrap();
        assert_eq!(recording.group, "drive");
        assert_eq!(recording.events.len(), 400);
        assert_eq!(recording.sensor_size, SensorSize::new(20, 10));
        assert_eq!(recording.ground_truth(), GroundTruth::EventsOnly);
        // Every 50 ms from the first event; the first full window ends at 51 ms.
        assert_eq!(recording.reference_times_us.first(), Some(&51_000));

        let limited = EvalConfig {
            max_seconds_per_sequence: Some(0.1),
            ..EvalConfig::default()
        };
        let recording = read_recording(&path, &limited, &options).unwrap();
        // 100 ms scored plus the 100 ms horizon after it.
        assert_eq!(recording.events.last().unwrap().t, 201_000);
        let grouped = InputOptions {
            group: Some("dsec".to_owned()),
            ..options
        };
        assert_eq!(
            read_recording(&path, &limited, &grouped).unwrap().group,
            "dsec"
        );
    }

    /// evgate-io's DSEC fixture: 3000 events on a 640×480 sensor over 27 ms, times stored
    /// relative to `t_offset` 49 599 300 523 µs (see its make_dsec_fixture.py).
    #[cfg(feature = "dsec")]
    #[test]
    fn dsec_recordings_are_scored_without_ground_truth() {
        let path = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../evgate-io/tests/fixtures/dsec_events.h5"
        ));
        // The fixture is shorter than one 50 ms window: score 10 ms windows.
        let config = EvalConfig {
            window_ms: 10,
            gate_span_ms: 10,
            horizons_ms: vec![0, 10, 20],
            headline_horizon_ms: 20,
            ..EvalConfig::default()
        };
        let options = InputOptions {
            group: Some("dsec".to_owned()),
            sensor_size: None,
        };
        let recording = read_recording(path, &config, &options).unwrap();
        assert_eq!(recording.ground_truth(), GroundTruth::EventsOnly);
        assert_eq!(recording.sensor_size, SensorSize::new(640, 480));
        assert_eq!(recording.events.len(), 3000);
        let first = 49_599_300_523 + 1000;
        assert_eq!(recording.events[0].t, first);
        assert_eq!(
            recording.reference_times(&config),
            [first + 10_000, first + 20_000]
        );

        let mut evaluation = Evaluation::new(config, Vec::new()).unwrap();
        evaluation.evaluate(&recording, || {}).unwrap();
        let report = evaluation.finish(None).unwrap();
        let oms = &report.overall["oms"];
        // [t, t + 10 ms) of the two references (relative 11 and 21 ms): 714 events (the 5 ms
        // gap lies in the first span), then 857; 1571 events over 20 ms.
        assert_eq!(oms.kept.judged_events, 714 + 857);
        let rate = oms.kept.event_rate_hz.unwrap();
        assert!((rate - 78_550.0).abs() < 1e-6, "{rate}");
        assert!(oms.kept.kept_ratio.is_some());
        assert!(oms.horizons.iter().all(|h| h.mean_iou.is_none()));
    }

    #[test]
    fn unreadable_inputs_name_the_file() {
        let error = read_recording(
            Path::new("/nonexistent/run.raw"),
            &EvalConfig::default(),
            &InputOptions::default(),
        )
        .unwrap_err();
        assert!(
            error.to_string().contains("/nonexistent/run.raw"),
            "{error}"
        );
    }
}
