//! EVIMO `.npz` recordings: the `events` array, float64 of shape (N, 4) with rows
//! `[t seconds, x, y, p]`, streamed from inside the zip (the archive member is inflated on a
//! helper thread in bounded blocks, so memory stays bounded). The sensor size comes from the
//! shape (F, H, W) of the `mask` member when present. EVIMO's `events.txt` layout is read by
//! the text decoder. The ground truth (masks, depth, frame times) of every EVIMO layout is read
//! by [`crate::evimo_recording::EvimoRecording`].

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver};
use std::thread::JoinHandle;

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::format::Format;
use crate::npy::{read_header, DType};
use crate::records::{BadRecord, RecordFormat};
use crate::report::Admission;
use crate::source::{ByteSource, BLOCK_BYTES};
use crate::stream_decoder::StreamDecoder;

const RECORD_BYTES: usize = 32;
/// Inflated blocks in flight between the helper thread and the decoder.
const BLOCKS_IN_FLIGHT: usize = 4;

/// Reads one zip member as a stream, inflated on a helper thread that ends with the stream.
pub(crate) struct MemberStream {
    blocks: Receiver<std::io::Result<Vec<u8>>>,
    block: Vec<u8>,
    position: usize,
    helper: Option<JoinHandle<()>>,
}

impl Drop for MemberStream {
    /// Hangs up, so the helper's next send fails, and waits for it: a detached helper went on
    /// inflating after its reader was gone (the `evimo_npz` fuzz target's leak report).
    fn drop(&mut self) {
        drop(std::mem::replace(&mut self.blocks, sync_channel(0).1));
        if let Some(helper) = self.helper.take() {
            let _ = helper.join();
        }
    }
}

impl Read for MemberStream {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        while self.position == self.block.len() {
            match self.blocks.recv() {
                Ok(block) => {
                    self.block = block?;
                    self.position = 0;
                }
                Err(_) => return Ok(0),
            }
        }
        let n = out.len().min(self.block.len() - self.position);
        out[..n].copy_from_slice(&self.block[self.position..self.position + n]);
        self.position += n;
        Ok(n)
    }
}

pub(crate) fn open_member(path: &Path, member: &str) -> Result<Option<MemberStream>, DecodeError> {
    let file = File::open(path).map_err(|source| DecodeError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let mut archive =
        zip::ZipArchive::new(BufReader::new(file)).map_err(|e| DecodeError::Unrecognised {
            path: path.to_path_buf(),
            problem: format!("not a readable .npz (zip) archive: {e}"),
        })?;
    let Some(index) = archive.index_for_name(member) else {
        return Ok(None);
    };
    let (sender, blocks) = sync_channel(BLOCKS_IN_FLIGHT);
    let helper = std::thread::spawn(move || {
        let mut entry = match archive.by_index(index) {
            Ok(entry) => entry,
            Err(e) => {
                let _ = sender.send(Err(std::io::Error::other(e)));
                return;
            }
        };
        loop {
            let mut block = vec![0; BLOCK_BYTES];
            match entry.read(&mut block) {
                Ok(0) => return,
                Ok(n) => block.truncate(n),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    let _ = sender.send(Err(e));
                    return;
                }
            }
            // The decoder hung up: stop inflating.
            if sender.send(Ok(block)).is_err() {
                return;
            }
        }
    });
    Ok(Some(MemberStream {
        blocks,
        block: Vec::new(),
        position: 0,
        helper: Some(helper),
    }))
}

/// EVIMO's float64 rows `[t seconds, x, y, p]`: each row stands alone.
pub struct EvimoRows;

pub type EvimoDecoder = StreamDecoder<EvimoRows>;

impl EvimoDecoder {
    /// Opens the `events` member; `sensor_size` overrides the size taken from `mask`.
    pub fn open(path: &Path, sensor_size: Option<SensorSize>) -> Result<Self, DecodeError> {
        let member_path = PathBuf::from(format!("{}:events.npy", path.display()));
        let bad = |problem: String| DecodeError::BadHeader {
            path: member_path.clone(),
            offset: 0,
            problem,
        };
        let mut events = open_member(path, "events.npy")?.ok_or_else(|| DecodeError::Unrecognised {
            path: path.to_path_buf(),
            problem: "no `events` array: not an EVIMO .npz (labelled sequences are read with LabelledSequence::read)".into(),
        })?;
        let header = read_header(&mut events).map_err(|e| bad(e.to_string()))?;
        if header.dtype != DType::Scalar("<f8".into())
            || header.shape.len() != 2
            || header.shape[1] != 4
        {
            return Err(bad(format!(
                "`events` is {} of shape {:?}, expected <f8 of shape (N, 4)",
                header.dtype, header.shape
            )));
        }
        let sensor_size = match sensor_size {
            Some(size) => size,
            None => mask_size(path)?.unwrap_or(crate::reader::UNBOUNDED_SENSOR),
        };
        Ok(Self::from_parts(
            ByteSource::new(member_path, Box::new(events)),
            sensor_size,
            EvimoRows,
        ))
    }
}

impl RecordFormat for EvimoRows {
    const FORMAT: Format = Format::EvimoNpz;
    const RECORD_BYTES: usize = RECORD_BYTES;
    const RECORD_NAME: &'static str = "an EVIMO event row";

    #[inline]
    fn decode_record(
        &mut self,
        offset: u64,
        row: &[u8],
        admission: &mut Admission,
        out: &mut Vec<Event>,
    ) -> Result<(), BadRecord> {
        let value =
            |k: usize| f64::from_le_bytes(row[8 * k..8 * k + 8].try_into().expect("8 bytes"));
        let (t, x, y, p) = (value(0), value(1), value(2), value(3));
        let coordinate =
            |v: f64| (v.fract() == 0.0 && (0.0..=65535.0).contains(&v)).then_some(v as u16);
        let micros = t * 1e6;
        let on = match p {
            1.0 => Some(true),
            0.0 | -1.0 => Some(false),
            _ => None,
        };
        match (
            micros.is_finite() && micros.abs() < 9e18,
            coordinate(x),
            coordinate(y),
            on,
        ) {
            (true, Some(x), Some(y), Some(on)) => {
                admission.admit(out, Event::new(micros.round() as i64, x, y, on), offset)
            }
            _ => {
                let row = [t, x, y, p];
                return Err(BadRecord {
                    offset,
                    problem: format!(
                        "row {row:?} is not [t seconds, x, y, p] with integral coordinates in 0..=65535 and p in 1, 0, -1"
                    ),
                });
            }
        }
        Ok(())
    }
}

/// (H, W) of the `mask` array (F, H, W), read from its header only.
fn mask_size(path: &Path) -> Result<Option<SensorSize>, DecodeError> {
    let Some(mut mask) = open_member(path, "mask.npy")? else {
        return Ok(None);
    };
    let header = read_header(&mut mask).map_err(|e| DecodeError::BadHeader {
        path: PathBuf::from(format!("{}:mask.npy", path.display())),
        offset: 0,
        problem: e.to_string(),
    })?;
    Ok(match header.shape.as_slice() {
        [_, h, w] => u16::try_from(*w)
            .ok()
            .zip(u16::try_from(*h).ok())
            .filter(|&(w, h)| w > 0 && h > 0)
            .map(|(w, h)| SensorSize::new(w, h)),
        _ => None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::npz::{NpzCompression, NpzWriter};

    #[test]
    fn events_stream_out_of_a_compressed_npz_with_the_mask_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("evimo.npz");
        let rows: Vec<f64> = (0..20_000)
            .flat_map(|i| {
                [
                    i as f64 * 1e-5,
                    (i % 346) as f64,
                    (i % 260) as f64,
                    (i % 2) as f64,
                ]
            })
            .collect();
        let mut npz = NpzWriter::create(&path, NpzCompression::Deflated).unwrap();
        npz.add("events", &[20_000, 4], &rows).unwrap();
        npz.add("mask", &[1, 260, 346], &vec![0u8; 260 * 346])
            .unwrap();
        npz.finish().unwrap();
        let mut decoder = EvimoDecoder::open(&path, None).unwrap();
        assert_eq!(decoder.sensor_size(), SensorSize::new(346, 260));
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk).unwrap() > 0 {
            all.extend_from_slice(&chunk);
        }
        assert_eq!(all.len(), 20_000);
        assert_eq!(
            all[12_345],
            Event::new(123_450, (12_345 % 346) as u16, (12_345 % 260) as u16, true)
        );
        assert!(decoder.report().is_clean());
    }

    #[test]
    fn wrong_shapes_and_bad_rows_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.npz");
        let mut npz = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        npz.add("events", &[2, 3], &[0.0f64; 6]).unwrap();
        npz.finish().unwrap();
        let err = EvimoDecoder::open(&path, None).err().unwrap().to_string();
        assert!(
            err.contains("bad.npz:events.npy") && err.contains("(N, 4)"),
            "{err}"
        );

        let mut npz = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        npz.add("events", &[2, 4], &[0.0, 1.0, 2.0, 1.0, 0.1, 1.5, 2.0, 1.0])
            .unwrap();
        npz.finish().unwrap();
        let err = EvimoDecoder::open(&path, None)
            .unwrap()
            .read_chunk(&mut Vec::new())
            .unwrap_err()
            .to_string();
        assert!(err.contains("offset 32") && err.contains("1.5"), "{err}");

        let mut npz = NpzWriter::create(&path, NpzCompression::Stored).unwrap();
        npz.add("other", &[1], &[0u8]).unwrap();
        npz.finish().unwrap();
        let err = EvimoDecoder::open(&path, None).err().unwrap().to_string();
        assert!(err.contains("no `events` array"), "{err}");
    }
}
