//! Prophesee RAW EVT 2.0: 32-bit little-endian words, the type in the top 4 bits.
//!
//! `CD_OFF` (0x0) / `CD_ON` (0x1): 6 low time bits at 22..28, x at 11..22, y at 0..11;
//! `TIME_HIGH` (0x8): bits 6..34 of the time; `EXT_TRIGGER` (0xA), `OTHERS` (0xE) and
//! `CONTINUED` (0xF) carry no CD events and are passed over; any other type is skipped and
//! counted. `TIME_HIGH` steps, wraps of the 34-bit time and corrupt values follow
//! [`crate::time_high`].

use evgate_core::{Event, SensorSize};

use crate::format::Format;
use crate::records::{BadRecord, RecordFormat};
use crate::report::Admission;
use crate::source::ByteSource;
use crate::stream_decoder::StreamDecoder;
use crate::time_high::TimeHigh;

/// The time base EVT 2.0 words carry from one to the next.
pub struct Evt2Words {
    /// Bits 6..34 of the time.
    time_high: TimeHigh,
}

pub type Evt2Decoder = StreamDecoder<Evt2Words>;

impl Evt2Decoder {
    /// `source` must be positioned after the `%` header.
    pub fn new(source: ByteSource, sensor_size: SensorSize) -> Self {
        Self::from_parts(
            source,
            sensor_size,
            Evt2Words {
                time_high: TimeHigh::new(28, 64),
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
                let t = self.time_high.base_us() + ((word >> 22) & 0x3f) as i64;
                let x = ((word >> 11) & 0x7ff) as u16;
                let y = (word & 0x7ff) as u16;
                admission.admit(out, Event::new(t, x, y, kind == 1), offset);
            }
            0x8 => {
                self.time_high
                    .update((word & 0x0fff_ffff) as i64, offset, &mut admission.report)
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
            0x8fff_ffff,
            cd(true, 5, 10, 20),
            0xA000_0000,
            cd(false, 63, 639, 479),
            0x8000_0000,
            cd(true, 0, 1, 2),
        ]);
        assert_eq!(
            events,
            vec![
                Event::new((1 << 34) - 59, 10, 20, true),
                Event::new((1 << 34) - 1, 639, 479, false),
                Event::new(1 << 34, 1, 2, true),
            ]
        );
        assert!(report.is_clean());
    }

    /// Issue 15: a `TIME_HIGH` one step back was read as a wrap, +2^34 µs.
    #[test]
    fn a_corrupt_time_high_is_ignored_and_counted() {
        let (events, report) = decode(&[
            0x8000_0002,
            cd(true, 5, 10, 20),
            0x8000_0001,
            cd(true, 6, 1, 2),
            0x8000_0003,
            cd(true, 0, 1, 2),
        ]);
        let times: Vec<i64> = events.iter().map(|e| e.t).collect();
        assert_eq!(times, vec![133, 134, 192]);
        assert_eq!(report.implausible_time_jumps, 1);
        assert_eq!(report.first_implausible_time_jump_offset, Some(8));
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
