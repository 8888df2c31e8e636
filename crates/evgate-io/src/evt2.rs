//! Prophesee RAW EVT 2.0: 32-bit little-endian words, the type in the top 4 bits.
//!
//! `CD_OFF` (0x0) / `CD_ON` (0x1): 6 low time bits at 22..28, x at 11..22, y at 0..11;
//! `TIME_HIGH` (0x8): bits 6..34 of the time; `EXT_TRIGGER` (0xA), `OTHERS` (0xE) and
//! `CONTINUED` (0xF) carry no CD events and are passed over; any other type is skipped and
//! counted. A `TIME_HIGH` smaller than the previous one is a wrap of the 34-bit time.

use evgate_core::{Event, SensorSize};

use crate::format::Format;
use crate::records::{BadRecord, RecordFormat};
use crate::report::Admission;
use crate::source::ByteSource;
use crate::stream_decoder::StreamDecoder;

const TIME_HIGH_WRAP: i64 = 1 << 34;

/// The time base EVT 2.0 words carry from one to the next.
pub struct Evt2Words {
    time_high: i64,
    wraps: i64,
}

pub type Evt2Decoder = StreamDecoder<Evt2Words>;

impl Evt2Decoder {
    /// `source` must be positioned after the `%` header.
    pub fn new(source: ByteSource, sensor_size: SensorSize) -> Self {
        Self::from_parts(
            source,
            sensor_size,
            Evt2Words {
                time_high: 0,
                wraps: 0,
            },
        )
    }
}

impl RecordFormat for Evt2Words {
    const FORMAT: Format = Format::Evt2;
    const RECORD_BYTES: usize = 4;
    const RECORD_NAME: &'static str = "an EVT 2.0 word";

    #[inline]
    fn decode_record(
        &mut self,
        offset: u64,
        word: &[u8],
        admission: &mut Admission,
        out: &mut Vec<Event>,
    ) -> Result<(), BadRecord> {
        let word = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
        match word >> 28 {
            kind @ (0x0 | 0x1) => {
                // Saturating: adversarial input can repeat wraps past the i64 range.
                let t = self
                    .wraps
                    .saturating_add(self.time_high + ((word >> 22) & 0x3f) as i64);
                let x = ((word >> 11) & 0x7ff) as u16;
                let y = (word & 0x7ff) as u16;
                admission.admit(out, Event::new(t, x, y, kind == 1), offset);
            }
            0x8 => {
                let time_high = ((word & 0x0fff_ffff) as i64) << 6;
                if time_high < self.time_high {
                    self.wraps = self.wraps.saturating_add(TIME_HIGH_WRAP);
                }
                self.time_high = time_high;
            }
            0xA | 0xE | 0xF => {}
            _ => admission.report.skip_word(offset),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;
    use crate::report::DecodeReport;

    fn decode(words: &[u32]) -> (Vec<Event>, DecodeReport) {
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let source = ByteSource::new("mem.raw".into(), Box::new(Cursor::new(bytes)));
        let mut decoder = Evt2Decoder::new(source, SensorSize::new(640, 480));
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk).unwrap() > 0 {
            all.extend_from_slice(&chunk);
        }
        (all, decoder.report().clone())
    }

    fn cd(on: bool, t_low: u32, x: u32, y: u32) -> u32 {
        ((on as u32) << 28) | (t_low << 22) | (x << 11) | y
    }

    #[test]
    fn words_decode_to_events_with_time_high_and_wrap() {
        let (events, report) = decode(&[
            0x8000_0002,
            cd(true, 5, 10, 20),
            0xA000_0000,
            cd(false, 63, 639, 479),
            0x8000_0001,
            cd(true, 0, 1, 2),
        ]);
        assert_eq!(
            events,
            vec![
                Event::new(133, 10, 20, true),
                Event::new(191, 639, 479, false),
                Event::new((1 << 34) + 64, 1, 2, true),
            ]
        );
        assert!(report.is_clean());
    }

    #[test]
    fn unknown_types_and_out_of_sensor_events_are_counted() {
        let (events, report) = decode(&[0x3000_0000, cd(true, 0, 640, 0), cd(true, 1, 0, 0)]);
        assert_eq!(events.len(), 1);
        assert_eq!(report.skipped_words, 1);
        assert_eq!(report.first_skipped_word_offset, Some(0));
        assert_eq!(report.dropped_out_of_sensor, 1);
        assert_eq!(report.first_out_of_sensor_offset, Some(4));
    }

    #[test]
    fn a_partial_word_at_the_end_is_an_error_with_its_offset() {
        let source = ByteSource::new(
            "cut.raw".into(),
            Box::new(Cursor::new(vec![1, 0, 0, 0x10, 7, 7])),
        );
        let mut decoder = Evt2Decoder::new(source, SensorSize::new(640, 480));
        let mut chunk = Vec::new();
        assert_eq!(decoder.read_chunk(&mut chunk).unwrap(), 1);
        let err = decoder.read_chunk(&mut chunk).unwrap_err().to_string();
        assert!(err.contains("cut.raw") && err.contains("offset 4"), "{err}");
    }
}
