//! Prophesee DAT: a `%` header, one byte of event type and one of event size, then 8-byte
//! little-endian records: a 32-bit time in µs and a 32-bit word with x in bits 0..14, y in
//! 14..28 and the polarity in 28..32. A time more than 2^31 µs below the previous one is a wrap
//! of the 32-bit counter; a smaller step back is a time regression (counted, kept).

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::format::Format;
use crate::records::{BadRecord, RecordFormat};
use crate::report::Admission;
use crate::source::ByteSource;
use crate::stream_decoder::StreamDecoder;

/// Event types whose 8-byte records hold change-detection events: 0x0C (`CD`) in current files,
/// 0x00 (`TD`) in ATIS-era ones.
const CD_EVENT_TYPES: [u8; 2] = [0x0c, 0x00];
const RECORD_BYTES: usize = 8;
const TIME_WRAP: i64 = 1 << 32;

/// The 32-bit time counter DAT records carry from one to the next.
pub struct DatRecords {
    last_raw_t: Option<u32>,
    wraps: i64,
}

pub type DatDecoder = StreamDecoder<DatRecords>;

impl DatDecoder {
    /// `source` must be positioned after the `%` header; reads the type and size bytes.
    pub fn new(mut source: ByteSource, sensor_size: SensorSize) -> Result<Self, DecodeError> {
        let offset = source.offset();
        let kind = source.read_exact(2, "the DAT event type and size bytes")?;
        let (event_type, event_size) = (kind[0], kind[1]);
        if !CD_EVENT_TYPES.contains(&event_type) || event_size as usize != RECORD_BYTES {
            return Err(DecodeError::BadHeader {
                path: source.path().to_path_buf(),
                offset,
                problem: format!(
                    "DAT event type 0x{event_type:02x} of size {event_size} is not supported (accepted: type 0x0c or 0x00 with size 8)"
                ),
            });
        }
        Ok(Self::from_parts(
            source,
            sensor_size,
            DatRecords {
                last_raw_t: None,
                wraps: 0,
            },
        ))
    }
}

impl RecordFormat for DatRecords {
    const FORMAT: Format = Format::Dat;
    const RECORD_BYTES: usize = RECORD_BYTES;
    const RECORD_NAME: &'static str = "a DAT record";

    #[inline]
    fn decode_record(
        &mut self,
        offset: u64,
        record: &[u8],
        admission: &mut Admission,
        out: &mut Vec<Event>,
    ) -> Result<(), BadRecord> {
        let raw_t = u32::from_le_bytes([record[0], record[1], record[2], record[3]]);
        let data = u32::from_le_bytes([record[4], record[5], record[6], record[7]]);
        if let Some(last) = self.last_raw_t {
            if raw_t < last && last - raw_t > 1 << 31 {
                self.wraps = self.wraps.saturating_add(TIME_WRAP);
            }
        }
        self.last_raw_t = Some(raw_t);
        let event = Event::new(
            self.wraps.saturating_add(raw_t as i64),
            (data & 0x3fff) as u16,
            ((data >> 14) & 0x3fff) as u16,
            (data >> 28) != 0,
        );
        admission.admit(out, event, offset);
        Ok(())
    }
}

/// Encodes one CD record (used by tests and benchmarks to make DAT files).
pub fn encode_record(event: &Event) -> [u8; RECORD_BYTES] {
    let data = (event.x as u32 & 0x3fff)
        | ((event.y as u32 & 0x3fff) << 14)
        | ((event.is_on() as u32) << 28);
    let mut record = [0u8; RECORD_BYTES];
    record[..4].copy_from_slice(&(event.t as u32).to_le_bytes());
    record[4..].copy_from_slice(&data.to_le_bytes());
    record
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn decoder(bytes: Vec<u8>) -> Result<DatDecoder, DecodeError> {
        let source = ByteSource::new("mem.dat".into(), Box::new(Cursor::new(bytes)));
        DatDecoder::new(source, SensorSize::new(304, 240))
    }

    #[test]
    fn records_decode_with_time_wrap() {
        let mut bytes = vec![0x0c, 8];
        for event in [
            Event::new(4_294_967_000, 303, 239, true),
            Event::new(4_294_967_296 + 5, 1, 2, false),
        ] {
            bytes.extend_from_slice(&encode_record(&event));
        }
        let mut decoder = decoder(bytes).unwrap();
        let mut chunk = Vec::new();
        decoder.read_chunk(&mut chunk).unwrap();
        assert_eq!(
            chunk,
            vec![
                Event::new(4_294_967_000, 303, 239, true),
                Event::new(4_294_967_301, 1, 2, false),
            ]
        );
        assert_eq!(decoder.read_chunk(&mut chunk).unwrap(), 0);
    }

    #[test]
    fn unsupported_type_and_truncated_record_are_errors() {
        let err = decoder(vec![0x0e, 8]).err().unwrap().to_string();
        assert!(err.contains("0x0e") && err.contains("offset 0"), "{err}");
        let err = decoder(vec![0x0c]).err().unwrap().to_string();
        assert!(err.contains("truncated"), "{err}");
        let mut bytes = vec![0x0c, 8];
        bytes.extend_from_slice(&[1, 2, 3]);
        let err = decoder(bytes)
            .unwrap()
            .read_chunk(&mut Vec::new())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("offset 2") && err.contains("DAT record"),
            "{err}"
        );
    }
}
