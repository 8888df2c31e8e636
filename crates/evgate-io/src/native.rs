//! The native `.evg` format (docs/native-format.md): a 24-byte header, then the 16-byte
//! [`Event`] records exactly as they lie in memory on a little-endian machine.

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::format::Format;
use crate::records::{BadRecord, RecordFormat};
use crate::report::Admission;
use crate::source::ByteSource;
use crate::stream_decoder::StreamDecoder;

/// Like PNG's: a non-ASCII first byte and CR-LF / Ctrl-Z / LF catch text-mode transfers.
pub const MAGIC: [u8; 8] = *b"\x89EVG\r\n\x1a\n";
pub const VERSION: u16 = 1;
pub const HEADER_BYTES: usize = 24;
pub const RECORD_BYTES: usize = 16;
/// The event count of a file whose writer did not finish (or could not seek back).
pub const UNKNOWN_COUNT: u64 = u64::MAX;

/// Builds the header of a file holding `count` events.
pub fn header(sensor_size: SensorSize, count: u64) -> [u8; HEADER_BYTES] {
    let mut header = [0u8; HEADER_BYTES];
    header[..8].copy_from_slice(&MAGIC);
    header[8..10].copy_from_slice(&VERSION.to_le_bytes());
    header[10..12].copy_from_slice(&sensor_size.width.to_le_bytes());
    header[12..14].copy_from_slice(&sensor_size.height.to_le_bytes());
    header[16..24].copy_from_slice(&count.to_le_bytes());
    header
}

/// Encodes one record (little-endian whatever the host).
pub fn encode_record(event: &Event) -> [u8; RECORD_BYTES] {
    let mut record = [0u8; RECORD_BYTES];
    record[..8].copy_from_slice(&event.t.to_le_bytes());
    record[8..10].copy_from_slice(&event.x.to_le_bytes());
    record[10..12].copy_from_slice(&event.y.to_le_bytes());
    record[12] = event.is_on() as u8;
    record
}

/// The event count the header declares, checked against the records at the end.
pub struct NativeRecords {
    declared_count: Option<u64>,
    records_seen: u64,
}

pub type NativeDecoder = StreamDecoder<NativeRecords>;

impl NativeDecoder {
    /// Reads and checks the header; `source` must be at the start of the file.
    pub fn new(mut source: ByteSource) -> Result<Self, DecodeError> {
        let path = source.path().to_path_buf();
        let bad = |offset: u64, problem: String| DecodeError::BadHeader {
            path: path.clone(),
            offset,
            problem,
        };
        let header = source.read_exact(HEADER_BYTES, "the .evg header")?;
        if header[..8] != MAGIC {
            return Err(bad(
                0,
                format!(
                    "magic {:02x?} is not the .evg magic {MAGIC:02x?}",
                    &header[..8]
                ),
            ));
        }
        let version = u16::from_le_bytes([header[8], header[9]]);
        if version != VERSION {
            return Err(bad(
                8,
                format!("version {version} is not supported (accepted: {VERSION})"),
            ));
        }
        let width = u16::from_le_bytes([header[10], header[11]]);
        let height = u16::from_le_bytes([header[12], header[13]]);
        if width == 0 || height == 0 {
            return Err(bad(
                10,
                format!("sensor size {width}x{height} has a zero side"),
            ));
        }
        let flags = u16::from_le_bytes([header[14], header[15]]);
        if flags != 0 {
            return Err(bad(
                14,
                format!("flags 0x{flags:04x} are not defined in version 1 (must be 0)"),
            ));
        }
        let count = u64::from_le_bytes(header[16..24].try_into().expect("8 header bytes"));
        Ok(Self::from_parts(
            source,
            SensorSize::new(width, height),
            NativeRecords {
                declared_count: (count != UNKNOWN_COUNT).then_some(count),
                records_seen: 0,
            },
        ))
    }
}

impl RecordFormat for NativeRecords {
    const FORMAT: Format = Format::Native;
    const RECORD_BYTES: usize = RECORD_BYTES;
    const RECORD_NAME: &'static str = "an .evg record";

    #[inline]
    fn decode_record(
        &mut self,
        offset: u64,
        record: &[u8],
        admission: &mut Admission,
        out: &mut Vec<Event>,
    ) -> Result<(), BadRecord> {
        let polarity = record[12];
        let reserved = [record[13], record[14], record[15]];
        if polarity > 1 || reserved != [0, 0, 0] {
            return Err(BadRecord {
                offset: offset + 12,
                problem: format!(
                    "polarity byte {polarity} and reserved bytes {reserved:?} must be 0/1 and zero"
                ),
            });
        }
        let event = Event::new(
            i64::from_le_bytes(record[..8].try_into().expect("8 time bytes")),
            u16::from_le_bytes([record[8], record[9]]),
            u16::from_le_bytes([record[10], record[11]]),
            polarity == 1,
        );
        admission.admit(out, event, offset);
        self.records_seen += 1;
        Ok(())
    }

    fn at_end(&mut self, offset: u64) -> Result<(), BadRecord> {
        match self.declared_count {
            Some(declared) if declared != self.records_seen => Err(BadRecord {
                offset,
                problem: format!(
                    "the header declares {declared} events, the file holds {}",
                    self.records_seen
                ),
            }),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn open(bytes: Vec<u8>) -> Result<NativeDecoder, DecodeError> {
        NativeDecoder::new(ByteSource::new(
            "mem.evg".into(),
            Box::new(Cursor::new(bytes)),
        ))
    }

    fn file(count: u64, events: &[Event]) -> Vec<u8> {
        let mut bytes = header(SensorSize::new(10, 5), count).to_vec();
        for event in events {
            bytes.extend_from_slice(&encode_record(event));
        }
        bytes
    }

    #[test]
    fn header_and_records_decode() {
        let events = [Event::new(-4, 9, 4, true), Event::new(3, 0, 0, false)];
        let mut decoder = open(file(2, &events)).unwrap();
        assert_eq!(decoder.sensor_size(), SensorSize::new(10, 5));
        let mut chunk = Vec::new();
        decoder.read_chunk(&mut chunk).unwrap();
        assert_eq!(chunk, events);
        assert_eq!(decoder.read_chunk(&mut chunk).unwrap(), 0);
    }

    #[test]
    fn bad_magic_version_polarity_and_count_are_errors_with_offsets() {
        let mut bytes = file(0, &[]);
        bytes[0] = b'X';
        assert!(open(bytes).err().unwrap().to_string().contains("magic"));
        let mut bytes = file(0, &[]);
        bytes[8] = 9;
        let err = open(bytes).err().unwrap().to_string();
        assert!(
            err.contains("offset 8") && err.contains("version 9"),
            "{err}"
        );
        let mut bytes = file(1, &[Event::new(0, 0, 0, true)]);
        bytes[HEADER_BYTES + 12] = 7;
        let err = open(bytes)
            .unwrap()
            .read_chunk(&mut Vec::new())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("offset 36") && err.contains("polarity byte 7"),
            "{err}"
        );
        let err = open(file(3, &[Event::new(0, 0, 0, true)]))
            .unwrap()
            .read_chunk(&mut Vec::new())
            .and_then(|_| open(file(3, &[])).unwrap().read_chunk(&mut Vec::new()))
            .unwrap_err()
            .to_string();
        assert!(err.contains("declares 3 events"), "{err}");
        let err = open(b"\x89EVG".to_vec()).err().unwrap().to_string();
        assert!(
            err.contains("truncated") && err.contains(".evg header"),
            "{err}"
        );
    }
}
