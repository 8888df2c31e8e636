//! DSEC `events.h5` (HDF5): `events/x`, `events/y` (uint16), `events/t` (µs since
//! `t_offset`: uint32, or int64 / uint64), `events/p` (uint8, 1 = ON), `ms_to_idx` (uint64:
//! the index of the first event at or after each millisecond of relative time) and the int64
//! scalar `t_offset` (absolute µs of relative time 0; 0 when absent, as DSEC's own slicer
//! assumes). Event times delivered are absolute: `t + t_offset`.
//!
//! Memory stays bounded: events are read as hyperslabs of [`BLOCK_EVENTS`] rows, which HDF5
//! decompresses chunk by chunk (DSEC compresses with the Blosc filter, id 32001, loaded from
//! the system's HDF5 plugin directory; see scripts/setup-hdf5.sh). `ms_to_idx` (8 bytes per
//! millisecond of recording) is held in memory to seek time windows
//! ([`DsecReader::seek_window`], [`DsecReader::events_between`]); a sequential read checks
//! it against the decoded times.

use std::path::{Path, PathBuf};

use evgate_core::{Event, SensorSize};
use hdf5_metno::types::{IntSize, TypeDescriptor};
use hdf5_metno::{Dataset, File};

use crate::error::DecodeError;
use crate::report::{Admission, DecodeReport};

/// DSEC's Prophesee Gen3.1 event cameras.
pub const DSEC_SENSOR: SensorSize = SensorSize::new(640, 480);
/// Rows per hyperslab: 128 Ki events, 1.2 MiB of raw columns.
pub const BLOCK_EVENTS: usize = 128 * 1024;

pub struct DsecReader {
    path: PathBuf,
    x: Dataset,
    y: Dataset,
    t: Dataset,
    p: Dataset,
    ms_to_idx: Vec<u64>,
    t_offset_us: i64,
    events: u64,
    file_bytes: u64,
    next: u64,
    /// Relative end of the window being read (exclusive); `None` reads to the end.
    window_end_rel: Option<i64>,
    /// Relative start of the window: earlier events of the first millisecond are skipped.
    window_start_rel: i64,
    /// Next millisecond whose `ms_to_idx` entry a sequential read verifies; `None` once a
    /// window was sought (the check needs every event from index 0).
    next_ms_to_check: Option<usize>,
    admission: Admission,
}

fn dataset_error(path: &Path, dataset: &str, problem: impl Into<String>) -> DecodeError {
    DecodeError::Dataset {
        path: path.to_path_buf(),
        dataset: dataset.to_owned(),
        problem: problem.into(),
    }
}

fn describe(descriptor: &TypeDescriptor) -> String {
    let bits = |size: &IntSize| (*size as usize) * 8;
    match descriptor {
        TypeDescriptor::Unsigned(size) => format!("uint{}", bits(size)),
        TypeDescriptor::Integer(size) => format!("int{}", bits(size)),
        other => format!("{other}"),
    }
}

/// Opens `name`, checks it is 1-D and of one of the `accepted` types; returns its length and
/// type.
fn column(
    file: &File,
    path: &Path,
    name: &str,
    accepted: &[TypeDescriptor],
) -> Result<(Dataset, u64, TypeDescriptor), DecodeError> {
    let dataset = file.dataset(name).map_err(|e| {
        let present = file
            .member_names()
            .map(|names| names.join(", "))
            .unwrap_or_default();
        dataset_error(
            path,
            name,
            format!("missing or unreadable ({e}); top-level members present: {present}"),
        )
    })?;
    let descriptor = dataset
        .dtype()
        .and_then(|dtype| dtype.to_descriptor())
        .map_err(|e| dataset_error(path, name, format!("unreadable type: {e}")))?;
    if !accepted.contains(&descriptor) {
        let names: Vec<String> = accepted.iter().map(describe).collect();
        return Err(dataset_error(
            path,
            name,
            format!(
                "type {} (accepted: {})",
                describe(&descriptor),
                names.join(", ")
            ),
        ));
    }
    let shape = dataset.shape();
    let [length] = shape.as_slice() else {
        return Err(dataset_error(
            path,
            name,
            format!("shape {shape:?}, expected one dimension"),
        ));
    };
    Ok((dataset, *length as u64, descriptor))
}

fn read_u16(dataset: &Dataset, range: std::ops::Range<usize>) -> hdf5_metno::Result<Vec<u16>> {
    Ok(dataset.read_slice_1d::<u16, _>(range)?.to_vec())
}

impl DsecReader {
    /// Opens a DSEC `events.h5`; `sensor_size` defaults to DSEC's 640x480.
    pub fn open(path: &Path, sensor_size: Option<SensorSize>) -> Result<Self, DecodeError> {
        let file = File::open(path).map_err(|e| DecodeError::Unrecognised {
            path: path.to_path_buf(),
            problem: format!("not a readable HDF5 file: {e}"),
        })?;
        use TypeDescriptor::{Integer, Unsigned};
        let (x, x_len, _) = column(&file, path, "events/x", &[Unsigned(IntSize::U2)])?;
        let (y, y_len, _) = column(&file, path, "events/y", &[Unsigned(IntSize::U2)])?;
        let (t, t_len, _) = column(
            &file,
            path,
            "events/t",
            &[
                Unsigned(IntSize::U4),
                Integer(IntSize::U8),
                Unsigned(IntSize::U8),
            ],
        )?;
        let (p, p_len, _) = column(&file, path, "events/p", &[Unsigned(IntSize::U1)])?;
        if [y_len, t_len, p_len].iter().any(|&len| len != x_len) {
            return Err(dataset_error(
                path,
                "events",
                format!(
                    "the columns disagree in length: x {x_len}, y {y_len}, t {t_len}, p {p_len}"
                ),
            ));
        }
        let (ms_dataset, _, _) = column(
            &file,
            path,
            "ms_to_idx",
            &[Unsigned(IntSize::U8), Integer(IntSize::U8)],
        )?;
        let ms_to_idx: Vec<u64> = ms_dataset
            .read_1d::<u64>()
            .map_err(|e| dataset_error(path, "ms_to_idx", format!("unreadable: {e}")))?
            .to_vec();
        if let Some(ms) = (1..ms_to_idx.len()).find(|&ms| ms_to_idx[ms] < ms_to_idx[ms - 1]) {
            return Err(dataset_error(
                path,
                "ms_to_idx",
                format!(
                    "decreases at millisecond {ms}: {} after {}",
                    ms_to_idx[ms],
                    ms_to_idx[ms - 1]
                ),
            ));
        }
        if let Some(ms) = ms_to_idx.iter().position(|&index| index > x_len) {
            return Err(dataset_error(
                path,
                "ms_to_idx",
                format!("entry {ms} is {}, beyond the {x_len} events", ms_to_idx[ms]),
            ));
        }
        let t_offset_us = if file.link_exists("t_offset") {
            let dataset = file
                .dataset("t_offset")
                .map_err(|e| dataset_error(path, "t_offset", format!("unreadable: {e}")))?;
            let descriptor = dataset.dtype().and_then(|d| d.to_descriptor()).ok();
            let integral = matches!(
                descriptor,
                Some(Integer(IntSize::U8) | Unsigned(IntSize::U8))
            );
            if !integral || dataset.size() != 1 {
                return Err(dataset_error(
                    path,
                    "t_offset",
                    format!(
                        "{} of shape {:?}, expected one int64 (µs)",
                        descriptor
                            .as_ref()
                            .map_or("an unreadable type".into(), describe),
                        dataset.shape()
                    ),
                ));
            }
            let values = dataset
                .read_raw::<i64>()
                .map_err(|e| dataset_error(path, "t_offset", format!("unreadable: {e}")))?;
            values[0]
        } else {
            0
        };
        let file_bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        Ok(Self {
            path: path.to_path_buf(),
            x,
            y,
            t,
            p,
            ms_to_idx,
            t_offset_us,
            events: x_len,
            file_bytes,
            next: 0,
            window_end_rel: None,
            window_start_rel: i64::MIN,
            next_ms_to_check: Some(0),
            admission: Admission::new(sensor_size.unwrap_or(DSEC_SENSOR)),
        })
    }

    pub fn sensor_size(&self) -> SensorSize {
        self.admission.sensor_size()
    }

    pub fn report(&self) -> &DecodeReport {
        &self.admission.report
    }

    /// The absolute time (µs) of relative time 0.
    pub fn t_offset_us(&self) -> i64 {
        self.t_offset_us
    }

    /// Events in the file (before any repair).
    pub fn event_count(&self) -> u64 {
        self.events
    }

    /// The `ms_to_idx` table.
    pub fn ms_to_idx(&self) -> &[u64] {
        &self.ms_to_idx
    }

    /// The compressed file bytes the events read so far correspond to (for progress).
    pub fn bytes_read(&self) -> u64 {
        if self.events == 0 {
            return self.file_bytes;
        }
        (self.file_bytes as f64 * self.next as f64 / self.events as f64) as u64
    }

    /// Restricts the following [`Self::read_chunk`] calls to events with absolute time in
    /// `[t0_us, t1_us)`, starting at the `ms_to_idx` entry of `t0_us`'s millisecond. Times
    /// must be sorted, as in DSEC.
    pub fn seek_window(&mut self, t0_us: i64, t1_us: i64) -> Result<(), DecodeError> {
        if t1_us < t0_us {
            return Err(DecodeError::Unrecognised {
                path: self.path.clone(),
                problem: format!("window [{t0_us}, {t1_us}) µs ends before it starts"),
            });
        }
        let start_rel = t0_us.saturating_sub(self.t_offset_us);
        let ms = usize::try_from(start_rel.max(0) / 1000).unwrap_or(usize::MAX);
        // Beyond the table the events (if any) lie after its last entry.
        self.next = match self.ms_to_idx.get(ms) {
            Some(&index) => index,
            None => self.ms_to_idx.last().copied().unwrap_or(0),
        };
        self.window_start_rel = start_rel;
        self.window_end_rel = Some(t1_us.saturating_sub(self.t_offset_us));
        self.next_ms_to_check = None;
        Ok(())
    }

    /// All events with absolute time in `[t0_us, t1_us)` (DSEC's `EventSlicer.get_events`).
    pub fn events_between(&mut self, t0_us: i64, t1_us: i64) -> Result<Vec<Event>, DecodeError> {
        self.seek_window(t0_us, t1_us)?;
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while self.read_chunk(&mut chunk)? > 0 {
            all.extend_from_slice(&chunk);
        }
        Ok(all)
    }

    fn read_times(&self, range: std::ops::Range<usize>) -> Result<Vec<i64>, DecodeError> {
        let descriptor = self.t.dtype().and_then(|d| d.to_descriptor());
        let result = match descriptor {
            Ok(TypeDescriptor::Unsigned(IntSize::U4)) => self
                .t
                .read_slice_1d::<u32, _>(range.clone())
                .map(|a| a.iter().map(|&t| t as i64).collect()),
            Ok(TypeDescriptor::Unsigned(IntSize::U8)) => {
                let values = self.t.read_slice_1d::<u64, _>(range.clone());
                match values {
                    Ok(values) => {
                        if let Some((i, &t)) = values
                            .iter()
                            .enumerate()
                            .find(|(_, &t)| t > i64::MAX as u64)
                        {
                            return Err(dataset_error(
                                &self.path,
                                "events/t",
                                format!(
                                    "event {}: t = {t} does not fit in int64 µs",
                                    range.start + i
                                ),
                            ));
                        }
                        Ok(values.iter().map(|&t| t as i64).collect())
                    }
                    Err(e) => Err(e),
                }
            }
            _ => self
                .t
                .read_slice_1d::<i64, _>(range.clone())
                .map(|a| a.to_vec()),
        };
        result.map_err(|e| {
            dataset_error(
                &self.path,
                "events/t",
                format!(
                    "rows {}..{} unreadable: {e}{}",
                    range.start,
                    range.end,
                    filter_hint(&e)
                ),
            )
        })
    }

    /// Clears `out` and fills it with the next block of events; 0 means the end (of the file or
    /// of the window).
    pub fn read_chunk(&mut self, out: &mut Vec<Event>) -> Result<usize, DecodeError> {
        out.clear();
        while out.is_empty() && self.next < self.events {
            let start = self.next as usize;
            let end = (self.events as usize).min(start + BLOCK_EVENTS);
            let unreadable = |name: &str, e: hdf5_metno::Error| {
                dataset_error(
                    &self.path,
                    name,
                    format!("rows {start}..{end} unreadable: {e}{}", filter_hint(&e)),
                )
            };
            let xs = read_u16(&self.x, start..end).map_err(|e| unreadable("events/x", e))?;
            let ys = read_u16(&self.y, start..end).map_err(|e| unreadable("events/y", e))?;
            let ps = self
                .p
                .read_slice_1d::<u8, _>(start..end)
                .map_err(|e| unreadable("events/p", e))?
                .to_vec();
            let ts = self.read_times(start..end)?;
            for (k, &t_rel) in ts.iter().enumerate() {
                let index = start + k;
                if let Some(ms) = self.next_ms_to_check.as_mut() {
                    check_ms_to_idx(&self.path, &self.ms_to_idx, ms, index as u64, t_rel)?;
                }
                if t_rel < self.window_start_rel {
                    if t_rel < (self.window_start_rel.max(0) / 1000) * 1000 {
                        return Err(dataset_error(
                            &self.path,
                            "ms_to_idx",
                            format!(
                                "points at event {index} (t = {t_rel} µs) for millisecond {}, which starts at {} µs",
                                self.window_start_rel.max(0) / 1000,
                                (self.window_start_rel.max(0) / 1000) * 1000
                            ),
                        ));
                    }
                    continue;
                }
                if self.window_end_rel.is_some_and(|end_rel| t_rel >= end_rel) {
                    self.next = self.events;
                    return Ok(out.len());
                }
                let p = ps[k];
                if p > 1 {
                    return Err(dataset_error(
                        &self.path,
                        "events/p",
                        format!("event {index}: p = {p} (accepted: 0, 1)"),
                    ));
                }
                let t = t_rel.checked_add(self.t_offset_us).ok_or_else(|| {
                    dataset_error(
                        &self.path,
                        "events/t",
                        format!(
                            "event {index}: t = {t_rel} + t_offset {} overflows int64 µs",
                            self.t_offset_us
                        ),
                    )
                })?;
                self.admission
                    .admit(out, Event::new(t, xs[k], ys[k], p == 1), index as u64);
            }
            self.next = end as u64;
            // The table may list milliseconds after the last event: they point past the end.
            if self.next == self.events {
                if let Some(ms) = self.next_ms_to_check {
                    if let Some(bad) =
                        (ms..self.ms_to_idx.len()).find(|&m| self.ms_to_idx[m] != self.events)
                    {
                        return Err(dataset_error(
                            &self.path,
                            "ms_to_idx",
                            format!(
                                "entry {bad} is {}, but no event is at or after {} µs: expected {} (the event count)",
                                self.ms_to_idx[bad],
                                bad as i64 * 1000,
                                self.events
                            ),
                        ));
                    }
                }
            }
        }
        Ok(out.len())
    }
}

/// A missing compression filter is the usual cause of unreadable DSEC data: say how to get it.
fn filter_hint(error: &hdf5_metno::Error) -> &'static str {
    let text = error.to_string().to_lowercase();
    if ["filter", "plugin", "directory"]
        .iter()
        .any(|word| text.contains(word))
    {
        " (DSEC compresses with the Blosc filter, id 32001: install it with scripts/setup-hdf5.sh or point HDF5_PLUGIN_PATH at a directory holding it)"
    } else {
        ""
    }
}

/// `ms_to_idx[ms]` must be the first event index whose relative time is at or after
/// `ms * 1000`: when event `index` (time `t_rel`) is the first to reach a millisecond, that
/// millisecond's entry must be `index`.
fn check_ms_to_idx(
    path: &Path,
    ms_to_idx: &[u64],
    next_ms: &mut usize,
    index: u64,
    t_rel: i64,
) -> Result<(), DecodeError> {
    while *next_ms < ms_to_idx.len() && (*next_ms as i64) * 1000 <= t_rel {
        let entry = ms_to_idx[*next_ms];
        if entry != index {
            return Err(dataset_error(
                path,
                "ms_to_idx",
                format!(
                    "entry {} is {entry}, but the first event at or after {} µs is event {index} (t = {t_rel} µs)",
                    *next_ms,
                    *next_ms as i64 * 1000
                ),
            ));
        }
        *next_ms += 1;
    }
    Ok(())
}
