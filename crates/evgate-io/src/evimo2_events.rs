//! EVIMO2 (v2 layout) events: three parallel arrays in one sequence folder,
//! `dataset_events_t.npy` (float64 seconds, (N,)), `dataset_events_xy.npy` (uint16, (N, 2))
//! and `dataset_events_p.npy` (uint8, (N,)), read in lockstep in bounded blocks.

use std::fs::File;
use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::npy::{read_header, DType, NpyHeader};
use crate::report::{Admission, DecodeReport};
use crate::source::ByteSource;

pub const TIMES_FILE: &str = "dataset_events_t.npy";
pub const COORDINATES_FILE: &str = "dataset_events_xy.npy";
pub const POLARITIES_FILE: &str = "dataset_events_p.npy";

/// Events per block: 64 Ki rows is 1.5 MiB over the three arrays.
const BLOCK_EVENTS: usize = 64 * 1024;

pub struct Evimo2EventsDecoder {
    times: ByteSource,
    coordinates: ByteSource,
    polarities: ByteSource,
    rows: u64,
    next_row: u64,
    admission: Admission,
}

/// Opens one array, checks its dtype and shape, and leaves it at its first data byte.
fn open_array(
    folder: &Path,
    name: &str,
    descr: &str,
    columns: Option<usize>,
) -> Result<(ByteSource, u64), DecodeError> {
    let path = folder.join(name);
    let mut file = File::open(&path).map_err(|source| DecodeError::Open {
        path: path.clone(),
        source,
    })?;
    let header = read_header(&mut file).map_err(|e| DecodeError::BadHeader {
        path: path.clone(),
        offset: 0,
        problem: e.to_string(),
    })?;
    let NpyHeader { dtype, shape } = &header;
    let shape_ok = match (columns, shape.as_slice()) {
        (None, [_]) => true,
        (Some(c), [_, found]) => *found == c,
        _ => false,
    };
    let dtype_ok = matches!(dtype, DType::Scalar(d) if d.trim_start_matches(['<', '|', '=']) == descr.trim_start_matches(['<', '|']));
    if !shape_ok || !dtype_ok {
        let expected_shape = columns.map_or("(N,)".to_owned(), |c| format!("(N, {c})"));
        return Err(DecodeError::BadHeader {
            path,
            offset: 0,
            problem: format!(
                "array is {dtype} of shape {shape:?}, expected {descr} of shape {expected_shape}"
            ),
        });
    }
    Ok((ByteSource::new(path, Box::new(file)), shape[0] as u64))
}

impl Evimo2EventsDecoder {
    /// Opens the three arrays of the sequence folder `folder`; their lengths must agree.
    pub fn open(folder: &Path, sensor_size: SensorSize) -> Result<Self, DecodeError> {
        let (times, n_t) = open_array(folder, TIMES_FILE, "<f8", None)?;
        let (coordinates, n_xy) = open_array(folder, COORDINATES_FILE, "<u2", Some(2))?;
        let (polarities, n_p) = open_array(folder, POLARITIES_FILE, "|u1", None)?;
        if n_t != n_xy || n_t != n_p {
            return Err(DecodeError::Unrecognised {
                path: folder.to_path_buf(),
                problem: format!(
                    "the event arrays disagree in length: {TIMES_FILE} has {n_t} rows, {COORDINATES_FILE} {n_xy}, {POLARITIES_FILE} {n_p}"
                ),
            });
        }
        Ok(Self {
            times,
            coordinates,
            polarities,
            rows: n_t,
            next_row: 0,
            admission: Admission::new(sensor_size),
        })
    }

    pub fn sensor_size(&self) -> SensorSize {
        self.admission.sensor_size()
    }

    pub fn report(&self) -> &DecodeReport {
        &self.admission.report
    }

    /// Bytes of the three arrays consumed so far.
    pub fn bytes_read(&self) -> u64 {
        self.next_row * (8 + 4 + 1)
    }

    /// The folder the arrays are read from (for messages).
    fn folder(&self) -> PathBuf {
        self.times
            .path()
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
    }

    /// Clears `out` and fills it with the next block of events; 0 means end of stream.
    pub fn read_chunk(&mut self, out: &mut Vec<Event>) -> Result<usize, DecodeError> {
        out.clear();
        while out.is_empty() && self.next_row < self.rows {
            let n = (self.rows - self.next_row).min(BLOCK_EVENTS as u64) as usize;
            let times = self.times.read_exact(8 * n, "event times")?.to_vec();
            let coordinates = self
                .coordinates
                .read_exact(4 * n, "event coordinates")?
                .to_vec();
            let polarities = self.polarities.read_exact(n, "event polarities")?;
            for i in 0..n {
                let row = self.next_row + i as u64;
                let seconds = f64::from_le_bytes(times[8 * i..8 * i + 8].try_into().expect("8"));
                let micros = seconds * 1e6;
                let x = u16::from_le_bytes([coordinates[4 * i], coordinates[4 * i + 1]]);
                let y = u16::from_le_bytes([coordinates[4 * i + 2], coordinates[4 * i + 3]]);
                let p = polarities[i];
                if !(micros.is_finite() && micros.abs() < 9e18) || p > 1 {
                    return Err(DecodeError::Unrecognised {
                        path: self.folder(),
                        problem: format!(
                            "event row {row}: t = {seconds} s, p = {p}; expected a finite time and p in 0, 1"
                        ),
                    });
                }
                self.admission
                    .admit(out, Event::new(micros.round() as i64, x, y, p == 1), row);
            }
            self.next_row += n as u64;
        }
        Ok(out.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::npy::NpyArray;

    fn write(folder: &Path, name: &str, array: NpyArray) {
        let mut file = File::create(folder.join(name)).unwrap();
        array.write(&mut file).unwrap();
    }

    #[test]
    fn three_arrays_decode_in_lockstep_and_out_of_sensor_rows_are_counted() {
        let dir = tempfile::tempdir().unwrap();
        let n = 70_000;
        let t: Vec<f64> = (0..n).map(|i| 1.5 + i as f64 * 1e-6).collect();
        let xy: Vec<u16> = (0..n)
            .flat_map(|i| [(i % 700) as u16, (i % 480) as u16])
            .collect();
        let p: Vec<u8> = (0..n).map(|i| (i % 3 == 0) as u8).collect();
        write(dir.path(), TIMES_FILE, NpyArray::from_slice(&[n], &t));
        write(
            dir.path(),
            COORDINATES_FILE,
            NpyArray::from_slice(&[n, 2], &xy),
        );
        write(dir.path(), POLARITIES_FILE, NpyArray::from_slice(&[n], &p));
        let mut decoder = Evimo2EventsDecoder::open(dir.path(), SensorSize::new(640, 480)).unwrap();
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk).unwrap() > 0 {
            all.extend_from_slice(&chunk);
        }
        let outside = (0..n).filter(|i| i % 700 >= 640).count();
        assert_eq!(all.len(), n - outside);
        assert_eq!(decoder.report().dropped_out_of_sensor, outside as u64);
        assert_eq!(all[3], Event::new(1_500_003, 3, 3, true));
        assert_eq!(all[4], Event::new(1_500_004, 4, 4, false));
    }

    #[test]
    fn disagreeing_lengths_wrong_dtypes_and_bad_polarities_are_named() {
        let dir = tempfile::tempdir().unwrap();
        write(
            dir.path(),
            TIMES_FILE,
            NpyArray::from_slice(&[2], &[0.0f64, 1.0]),
        );
        write(
            dir.path(),
            COORDINATES_FILE,
            NpyArray::from_slice(&[2, 2], &[1u16, 2, 3, 4]),
        );
        write(
            dir.path(),
            POLARITIES_FILE,
            NpyArray::from_slice(&[3], &[0u8, 1, 1]),
        );
        let err = Evimo2EventsDecoder::open(dir.path(), SensorSize::new(8, 8))
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("disagree") && err.contains("3"), "{err}");

        write(
            dir.path(),
            POLARITIES_FILE,
            NpyArray::from_slice(&[2], &[0i64, 1]),
        );
        let err = Evimo2EventsDecoder::open(dir.path(), SensorSize::new(8, 8))
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains(POLARITIES_FILE) && err.contains("<i8") && err.contains("|u1"),
            "{err}"
        );

        write(
            dir.path(),
            POLARITIES_FILE,
            NpyArray::from_slice(&[2], &[0u8, 7]),
        );
        let err = Evimo2EventsDecoder::open(dir.path(), SensorSize::new(8, 8))
            .unwrap()
            .read_chunk(&mut Vec::new())
            .unwrap_err()
            .to_string();
        assert!(err.contains("row 1") && err.contains("p = 7"), "{err}");
    }
}
