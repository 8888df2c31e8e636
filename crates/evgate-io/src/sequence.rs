//! The labelled sequence (`.npz`) of docs/sequence-format.md: events with per-event object ids,
//! ground-truth masks and depth on a 10 ms grid, and forecasting targets (future masks and flow)
//! at sampled horizons.

use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};
use half::f16;

use crate::npy::NpyArray;
use crate::npz::{NpzCompression, NpzError, NpzReader, NpzWriter};

#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    #[error(transparent)]
    Npz(#[from] NpzError),
    #[error("{path}: key `{key}`: value {value} at index {index} is invalid: {problem}")]
    BadValue {
        path: PathBuf,
        key: &'static str,
        index: usize,
        value: String,
        problem: &'static str,
    },
    #[error("{path}: key `meta` is not UTF-8 text: {source}")]
    MetaNotUtf8 {
        path: PathBuf,
        source: std::string::FromUtf8Error,
    },
    #[error("labelled sequence for {path}: field `{field}` has {found} elements, expected {expected} ({why})")]
    Inconsistent {
        path: PathBuf,
        field: &'static str,
        found: usize,
        expected: usize,
        why: String,
    },
}

/// One labelled sequence held in memory. Frame arrays are flat, row-major, in the documented
/// axis order; use the `*_frame` accessors to slice them.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelledSequence {
    /// Events in time order (`events_t`, `events_xy`, `events_p`).
    pub events: Vec<Event>,
    /// Object id per event (`events_label`): 0 = static world or noise, k = object k.
    pub labels: Vec<u16>,
    /// Sensor width and height (`resolution`); frames are `height × width`.
    pub sensor_size: SensorSize,
    /// Pinhole intrinsics, row-major (`K`).
    pub intrinsics: [[f64; 3]; 3],
    /// Ground-truth frame times in µs (`gt_ts`), F of them.
    pub gt_ts: Vec<i64>,
    /// Object id per pixel, F × H × W (`mask`).
    pub masks: Vec<u8>,
    /// Depth in metres, F × H × W (`depth`, float16 on disk).
    pub depth: Vec<f32>,
    /// Reference times in µs (`ref_ts`), R of them.
    pub ref_ts: Vec<i64>,
    /// Horizons per reference time (the second axis of `horizon_us`).
    pub horizons_per_reference: usize,
    /// Horizons in µs, R × horizons_per_reference (`horizon_us`).
    pub horizon_us: Vec<i64>,
    /// Object id per pixel at `ref_ts + horizon_us`, R × horizons × H × W (`future_mask`).
    pub future_mask: Vec<u8>,
    /// Forward flow (dx, dy) in pixels, R × horizons × H × W × 2 (`future_flow`, float16 on disk).
    pub future_flow: Vec<f32>,
    /// UTF-8 JSON: preset, seed, simulator parameters, version (`meta`).
    pub meta: String,
}

impl LabelledSequence {
    pub fn frame_count(&self) -> usize {
        self.gt_ts.len()
    }

    pub fn reference_count(&self) -> usize {
        self.ref_ts.len()
    }

    /// The object-id mask at `gt_ts[frame]`.
    pub fn mask_frame(&self, frame: usize) -> &[u8] {
        let pixels = self.sensor_size.pixels();
        &self.masks[frame * pixels..(frame + 1) * pixels]
    }

    /// The depth map at `gt_ts[frame]`.
    pub fn depth_frame(&self, frame: usize) -> &[f32] {
        let pixels = self.sensor_size.pixels();
        &self.depth[frame * pixels..(frame + 1) * pixels]
    }

    /// The horizon in µs of sample `horizon` of reference time `reference`.
    pub fn horizon(&self, reference: usize, horizon: usize) -> i64 {
        self.horizon_us[reference * self.horizons_per_reference + horizon]
    }

    /// The object-id mask at `ref_ts[reference] + horizon(reference, horizon)`.
    pub fn future_mask_frame(&self, reference: usize, horizon: usize) -> &[u8] {
        let pixels = self.sensor_size.pixels();
        let start = (reference * self.horizons_per_reference + horizon) * pixels;
        &self.future_mask[start..start + pixels]
    }

    /// The flow field (interleaved dx, dy per pixel) for one reference time and horizon.
    pub fn future_flow_frame(&self, reference: usize, horizon: usize) -> &[f32] {
        let pixels = self.sensor_size.pixels();
        let start = (reference * self.horizons_per_reference + horizon) * pixels * 2;
        &self.future_flow[start..start + pixels * 2]
    }

    /// Checks that every array has the length its axes imply.
    pub fn validate(&self, path: &Path) -> Result<(), SequenceError> {
        let pixels = self.sensor_size.pixels();
        let frames = self.gt_ts.len();
        let references = self.ref_ts.len();
        let horizons = self.horizons_per_reference;
        let checks: [(&'static str, usize, usize, String); 6] = [
            (
                "labels",
                self.labels.len(),
                self.events.len(),
                "one per event".into(),
            ),
            (
                "masks",
                self.masks.len(),
                frames * pixels,
                format!("{frames} frames x {}", self.sensor_size),
            ),
            (
                "depth",
                self.depth.len(),
                frames * pixels,
                format!("{frames} frames x {}", self.sensor_size),
            ),
            (
                "horizon_us",
                self.horizon_us.len(),
                references * horizons,
                format!("{references} reference times x {horizons} horizons"),
            ),
            (
                "future_mask",
                self.future_mask.len(),
                references * horizons * pixels,
                format!("{references} x {horizons} x {}", self.sensor_size),
            ),
            (
                "future_flow",
                self.future_flow.len(),
                references * horizons * pixels * 2,
                format!("{references} x {horizons} x {} x 2", self.sensor_size),
            ),
        ];
        for (field, found, expected, why) in checks {
            if found != expected {
                return Err(SequenceError::Inconsistent {
                    path: path.to_path_buf(),
                    field,
                    found,
                    expected,
                    why,
                });
            }
        }
        Ok(())
    }

    /// Writes the sequence as a deflate-compressed `.npz`.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), SequenceError> {
        self.write_with(path, NpzCompression::Deflated)
    }

    pub fn write_with(
        &self,
        path: impl AsRef<Path>,
        compression: NpzCompression,
    ) -> Result<(), SequenceError> {
        let path = path.as_ref();
        self.validate(path)?;
        let n = self.events.len();
        let (h, w) = (
            self.sensor_size.height as usize,
            self.sensor_size.width as usize,
        );
        let (f, r, k) = (
            self.gt_ts.len(),
            self.ref_ts.len(),
            self.horizons_per_reference,
        );
        let times: Vec<i64> = self.events.iter().map(|e| e.t).collect();
        let xy: Vec<u16> = self.events.iter().flat_map(|e| [e.x, e.y]).collect();
        let polarity: Vec<u8> = self.events.iter().map(|e| e.is_on() as u8).collect();
        let arrays = [
            ("events_t", NpyArray::from_slice(&[n], &times)),
            ("events_xy", NpyArray::from_slice(&[n, 2], &xy)),
            ("events_p", NpyArray::from_slice(&[n], &polarity)),
            ("events_label", NpyArray::from_slice(&[n], &self.labels)),
            (
                "resolution",
                NpyArray::from_slice(&[2], &[w as i64, h as i64]),
            ),
            (
                "K",
                NpyArray::from_slice(&[3, 3], self.intrinsics.as_flattened()),
            ),
            ("gt_ts", NpyArray::from_slice(&[f], &self.gt_ts)),
            ("mask", NpyArray::from_slice(&[f, h, w], &self.masks)),
            (
                "depth",
                NpyArray::from_slice(&[f, h, w], &to_f16(&self.depth)),
            ),
            ("ref_ts", NpyArray::from_slice(&[r], &self.ref_ts)),
            (
                "horizon_us",
                NpyArray::from_slice(&[r, k], &self.horizon_us),
            ),
            (
                "future_mask",
                NpyArray::from_slice(&[r, k, h, w], &self.future_mask),
            ),
            (
                "future_flow",
                NpyArray::from_slice(&[r, k, h, w, 2], &to_f16(&self.future_flow)),
            ),
            (
                "meta",
                NpyArray::from_slice(&[self.meta.len()], self.meta.as_bytes()),
            ),
        ];
        let mut out = NpzWriter::create(path, compression)?;
        out.add_arrays(&arrays)?;
        out.finish()?;
        Ok(())
    }

    /// Whether `path` is a labelled sequence: an `.npz` holding per-event labels
    /// (`events_label`). Other `.npz` files (EVIMO recordings) are for the decoders.
    pub fn is_labelled_sequence(path: impl AsRef<Path>) -> bool {
        let path = path.as_ref();
        path.extension().is_some_and(|ext| ext == "npz")
            && NpzReader::open(path)
                .map(|archive| archive.contains("events_label"))
                .unwrap_or(false)
    }

    /// The sensor size of the sequence at `path`, read without its events and frames.
    pub fn read_sensor_size(path: impl AsRef<Path>) -> Result<SensorSize, SequenceError> {
        let path = path.as_ref();
        let (_, resolution) = NpzReader::open(path)?.read_typed::<i64>("resolution", &[Some(2)])?;
        sensor_size_from(path, &resolution)
    }

    /// Reads and checks a sequence: every key present with the documented dtype and a shape
    /// consistent with the others.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, SequenceError> {
        let path = path.as_ref();
        let mut npz = NpzReader::open(path)?;

        let (_, resolution) = npz.read_typed::<i64>("resolution", &[Some(2)])?;
        let sensor_size = sensor_size_from(path, &resolution)?;
        let (w, h) = (sensor_size.width as usize, sensor_size.height as usize);

        let (shape, times) = npz.read_typed::<i64>("events_t", &[None])?;
        let n = shape[0];
        let (_, xy) = npz.read_typed::<u16>("events_xy", &[Some(n), Some(2)])?;
        let (_, polarity) = npz.read_typed::<u8>("events_p", &[Some(n)])?;
        let (_, labels) = npz.read_typed::<u16>("events_label", &[Some(n)])?;
        if let Some(index) = polarity.iter().position(|&p| p > 1) {
            return Err(SequenceError::BadValue {
                path: path.to_path_buf(),
                key: "events_p",
                index,
                value: polarity[index].to_string(),
                problem: "polarity must be 0 (OFF) or 1 (ON)",
            });
        }
        if let Some(index) = times.windows(2).position(|pair| pair[1] < pair[0]) {
            return Err(SequenceError::BadValue {
                path: path.to_path_buf(),
                key: "events_t",
                index: index + 1,
                value: times[index + 1].to_string(),
                problem: "event times must be non-decreasing",
            });
        }
        let events = times
            .iter()
            .zip(xy.chunks_exact(2))
            .zip(&polarity)
            .map(|((&t, xy), &p)| Event::new(t, xy[0], xy[1], p == 1))
            .collect();

        let (_, k_flat) = npz.read_typed::<f64>("K", &[Some(3), Some(3)])?;
        let mut intrinsics = [[0.0; 3]; 3];
        for (row, chunk) in intrinsics.iter_mut().zip(k_flat.chunks_exact(3)) {
            row.copy_from_slice(chunk);
        }

        let (shape, gt_ts) = npz.read_typed::<i64>("gt_ts", &[None])?;
        let f = shape[0];
        let (_, masks) = npz.read_typed::<u8>("mask", &[Some(f), Some(h), Some(w)])?;
        let (_, depth) = npz.read_typed::<f16>("depth", &[Some(f), Some(h), Some(w)])?;

        let (shape, ref_ts) = npz.read_typed::<i64>("ref_ts", &[None])?;
        let r = shape[0];
        let (shape, horizon_us) = npz.read_typed::<i64>("horizon_us", &[Some(r), None])?;
        let k = shape[1];
        let (_, future_mask) =
            npz.read_typed::<u8>("future_mask", &[Some(r), Some(k), Some(h), Some(w)])?;
        let (_, future_flow) = npz.read_typed::<f16>(
            "future_flow",
            &[Some(r), Some(k), Some(h), Some(w), Some(2)],
        )?;
        let (_, meta) = npz.read_typed::<u8>("meta", &[None])?;
        let meta = String::from_utf8(meta).map_err(|source| SequenceError::MetaNotUtf8 {
            path: path.to_path_buf(),
            source,
        })?;

        Ok(Self {
            events,
            labels,
            sensor_size,
            intrinsics,
            gt_ts,
            masks,
            depth: depth.iter().map(|v| v.to_f32()).collect(),
            ref_ts,
            horizons_per_reference: k,
            horizon_us,
            future_mask,
            future_flow: future_flow.iter().map(|v| v.to_f32()).collect(),
            meta,
        })
    }
}

fn sensor_size_from(path: &Path, resolution: &[i64]) -> Result<SensorSize, SequenceError> {
    let mut sides = [0u16; 2];
    for (index, (side, &value)) in sides.iter_mut().zip(resolution).enumerate() {
        *side = u16::try_from(value)
            .ok()
            .filter(|&v| v > 0)
            .ok_or_else(|| SequenceError::BadValue {
                path: path.to_path_buf(),
                key: "resolution",
                index,
                value: value.to_string(),
                problem: "sensor sides must be in 1..=65535",
            })?;
    }
    Ok(SensorSize::new(sides[0], sides[1]))
}

fn to_f16(values: &[f32]) -> Vec<f16> {
    values.iter().map(|&v| f16::from_f32(v)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small but complete sequence whose values are exactly representable in float16.
    pub(crate) fn sample() -> LabelledSequence {
        let sensor_size = SensorSize::new(5, 3);
        let pixels = sensor_size.pixels();
        let (frames, references, horizons) = (3, 2, 2);
        LabelledSequence {
            events: vec![
                Event::new(0, 0, 0, true),
                Event::new(10, 4, 2, false),
                Event::new(10, 2, 1, true),
                Event::new(25_000, 3, 0, false),
            ],
            labels: vec![0, 1, 2, 1],
            sensor_size,
            intrinsics: [[200.0, 0.0, 2.5], [0.0, 200.0, 1.5], [0.0, 0.0, 1.0]],
            gt_ts: vec![0, 10_000, 20_000],
            masks: (0..frames * pixels).map(|i| (i % 3) as u8).collect(),
            depth: (0..frames * pixels)
                .map(|i| 0.5 + i as f32 * 0.25)
                .collect(),
            ref_ts: vec![50_000, 100_000],
            horizons_per_reference: horizons,
            horizon_us: vec![0, 37_000, 12_000, 100_000],
            future_mask: (0..references * horizons * pixels)
                .map(|i| (i % 2) as u8)
                .collect(),
            future_flow: (0..references * horizons * pixels * 2)
                .map(|i| i as f32 * 0.5 - 10.0)
                .collect(),
            meta: r#"{"preset":"unit","seed":7,"version":"0.1.0"}"#.into(),
        }
    }

    #[test]
    fn sequence_round_trips_through_npz() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("seq.npz");
        let sequence = sample();
        sequence.write(&path).unwrap();
        let back = LabelledSequence::read(&path).unwrap();
        assert_eq!(back, sequence);
        assert!(LabelledSequence::is_labelled_sequence(&path));
        assert_eq!(
            LabelledSequence::read_sensor_size(&path).unwrap(),
            sequence.sensor_size
        );
        assert_eq!(
            back.future_mask_frame(1, 1),
            sequence.future_mask_frame(1, 1)
        );
        assert_eq!(back.horizon(1, 0), 12_000);
    }

    #[test]
    fn inconsistent_lengths_are_refused_on_write() {
        let dir = tempfile::tempdir().unwrap();
        let mut sequence = sample();
        sequence.depth.pop();
        let err = sequence
            .write(dir.path().join("bad.npz"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`depth`") && err.contains("44") && err.contains("45"),
            "{err}"
        );
    }

    #[test]
    fn wrong_shape_wrong_dtype_and_missing_key_name_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.npz");
        let mut out = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        out.add("resolution", &[2], &[5i64, 3]).unwrap();
        out.add("events_t", &[2], &[0i64, 1]).unwrap();
        out.add("events_xy", &[2, 3], &[0u16; 6]).unwrap();
        out.finish().unwrap();
        let err = LabelledSequence::read(&path).unwrap_err().to_string();
        assert!(
            err.contains("broken.npz") && err.contains("`events_xy`") && err.contains("(2, 2)"),
            "{err}"
        );
        assert!(!LabelledSequence::is_labelled_sequence(&path), "no labels");

        let mut out = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        out.add("resolution", &[2], &[5i32, 3]).unwrap();
        out.finish().unwrap();
        let err = LabelledSequence::read(&path).unwrap_err().to_string();
        assert!(err.contains("`resolution`") && err.contains("<i4"), "{err}");

        let mut out = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        out.add("resolution", &[2], &[5i64, 3]).unwrap();
        out.finish().unwrap();
        let err = LabelledSequence::read(&path).unwrap_err().to_string();
        assert!(err.contains("`events_t` is missing"), "{err}");
    }

    #[test]
    fn backwards_time_is_reported_with_its_index() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("seq.npz");
        let mut sequence = sample();
        sequence.events[1].t = 5;
        sequence.events[2].t = 5;
        sequence.write(&path).unwrap();
        assert!(LabelledSequence::read(&path).is_ok());
        sequence.events[2].t = 4;
        sequence.write(&path).unwrap();
        let err = LabelledSequence::read(&path).unwrap_err().to_string();
        assert!(
            err.contains("`events_t`") && err.contains("index 2"),
            "{err}"
        );
    }

    #[test]
    fn polarity_outside_zero_one_is_reported_with_its_index() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("seq.npz");
        let mut out = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        out.add("resolution", &[2], &[5i64, 3]).unwrap();
        out.add("events_t", &[2], &[0i64, 1]).unwrap();
        out.add("events_xy", &[2, 2], &[0u16; 4]).unwrap();
        out.add("events_p", &[2], &[1u8, 255]).unwrap();
        out.add("events_label", &[2], &[0u16; 2]).unwrap();
        out.finish().unwrap();
        let err = LabelledSequence::read(&path).unwrap_err().to_string();
        assert!(
            err.contains("`events_p`") && err.contains("255") && err.contains("index 1"),
            "{err}"
        );
    }
}
