//! Prophesee RAW EVT 3.0: 16-bit little-endian words, the type in the top 4 bits.
//!
//! `ADDR_Y` (0x0): row; `ADDR_X` (0x2): one event at x with polarity bit 11; `VECT_BASE_X`
//! (0x3): base column and polarity for the vectors that follow; `VECT_12` (0x4) / `VECT_8`
//! (0x5): a bit mask of events at base, base+1, … after which the base advances by 12 / 8;
//! `TIME_LOW` (0x6) / `TIME_HIGH` (0x8): bits 0..12 / 12..24 of the time; `TIME_HIGH` steps,
//! wraps of the 24-bit time and corrupt values follow [`crate::time_high`]. `CONTINUED_4`
//! (0x7), `EXT_TRIGGER` (0xA), `OTHERS` (0xE) and `CONTINUED_12` (0xF) carry no CD events and
//! are passed over; any other type is skipped and counted.
//!
//! `% evgate_time_offset_us N` in the header (written by our encoder) is added to every time.
//!
//! A `TIME_LOW` smaller than the previous one under the same `TIME_HIGH` is taken at face value
//! (the event time steps back and the regression is counted): it is not a wrap, since the
//! sensor sends a new `TIME_HIGH` whenever bit 12 changes. [`Evt3TimeLow::CarryOnStepBack`]
//! reproduces the reader that treats every `TIME_LOW` step back as a carry (expelliarmus,
//! which made `shared/data/real/evt3_sample.npy`).

use evgate_core::{Event, SensorSize};

use crate::format::Format;
use crate::records::{BadRecord, RecordFormat};
use crate::report::Admission;
use crate::source::ByteSource;
use crate::stream_decoder::StreamDecoder;
use crate::time_high::TimeHigh;

/// What one carry of the 12-bit `TIME_LOW` adds under [`Evt3TimeLow::CarryOnStepBack`].
const TIME_LOW_CARRY: i64 = 1 << 12;

/// How a `TIME_LOW` smaller than the previous one is read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Evt3TimeLow {
    /// The EVT 3.0 rule: time = `TIME_HIGH` << 12 | `TIME_LOW`; a step back under the same
    /// `TIME_HIGH` stays a step back (counted as a time regression).
    #[default]
    Evt3,
    /// Compatibility with expelliarmus: every `TIME_LOW` smaller than the previous `TIME_LOW`
    /// is a carry that adds 4096 µs to this and every later time — also the ordinary restart
    /// of `TIME_LOW` after a new `TIME_HIGH`, which then counts twice.
    CarryOnStepBack,
}

impl Evt3TimeLow {
    pub const NAMES: [&'static str; 2] = ["evt3", "carry-on-step-back"];

    pub fn name(self) -> &'static str {
        match self {
            Evt3TimeLow::Evt3 => Self::NAMES[0],
            Evt3TimeLow::CarryOnStepBack => Self::NAMES[1],
        }
    }
}

impl std::fmt::Display for Evt3TimeLow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[derive(Debug, thiserror::Error)]
#[error("`{0}` is not an EVT 3.0 TIME_LOW rule (accepted: evt3, carry-on-step-back)")]
pub struct UnknownTimeLowRule(pub String);

impl std::str::FromStr for Evt3TimeLow {
    type Err = UnknownTimeLowRule;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "evt3" => Ok(Evt3TimeLow::Evt3),
            "carry-on-step-back" => Ok(Evt3TimeLow::CarryOnStepBack),
            other => Err(UnknownTimeLowRule(other.to_owned())),
        }
    }
}

/// The state EVT 3.0 words carry from one to the next: time base, row, vector base.
pub struct Evt3Words {
    time_low: i64,
    /// Bits 12..24 of the time.
    time_high: TimeHigh,
    /// The header's time offset plus the carries of [`Evt3TimeLow::CarryOnStepBack`].
    wraps: i64,
    y: u16,
    base_x: u16,
    vector_on: bool,
    time_low_rule: Evt3TimeLow,
}

pub type Evt3Decoder = StreamDecoder<Evt3Words>;

impl Evt3Decoder {
    /// `source` must be positioned after the `%` header; `time_offset` is added to every time.
    pub fn new(source: ByteSource, sensor_size: SensorSize, time_offset: i64) -> Self {
        Self::from_parts(
            source,
            sensor_size,
            Evt3Words {
                time_low: 0,
                time_high: TimeHigh::new(12, 1 << 12),
                wraps: time_offset,
                y: 0,
                base_x: 0,
                vector_on: false,
                time_low_rule: Evt3TimeLow::default(),
            },
        )
    }

    /// Reads `TIME_LOW` steps back by `rule` instead of the EVT 3.0 rule.
    pub fn with_time_low_rule(mut self, rule: Evt3TimeLow) -> Self {
        self.format.time_low_rule = rule;
        self
    }
}

impl RecordFormat for Evt3Words {
    const FORMAT: Format = Format::Evt3;
    const RECORD_BYTES: usize = 2;
    const RECORD_NAME: &'static str = "an EVT 3.0 word";

    #[inline]
    fn decode_record(
        &mut self,
        offset: u64,
        word: &[u8],
        admission: &mut Admission,
        out: &mut Vec<Event>,
    ) -> Result<(), BadRecord> {
        let word = u16::from_le_bytes([word[0], word[1]]);
        // Saturating: adversarial input can repeat wraps past the i64 range.
        let t = self
            .wraps
            .saturating_add(self.time_high.base_us() + self.time_low);
        match word >> 12 {
            0x0 => self.y = word & 0x7ff,
            0x2 => {
                let on = word & 0x800 != 0;
                admission.admit(out, Event::new(t, word & 0x7ff, self.y, on), offset);
            }
            0x3 => {
                self.base_x = word & 0x7ff;
                self.vector_on = word & 0x800 != 0;
            }
            kind @ (0x4 | 0x5) => {
                let (width, mask) = if kind == 0x4 {
                    (12, word & 0xfff)
                } else {
                    (8, word & 0xff)
                };
                let mut bits = mask;
                while bits != 0 {
                    let bit = bits.trailing_zeros() as u16;
                    bits &= bits - 1;
                    // Columns past the 11-bit range wrap in the sensor's arithmetic;
                    // saturating keeps them off the sensor so they are dropped and counted.
                    let x = self.base_x.saturating_add(bit);
                    admission.admit(out, Event::new(t, x, self.y, self.vector_on), offset);
                }
                self.base_x = self.base_x.saturating_add(width);
            }
            0x6 => {
                let time_low = (word & 0xfff) as i64;
                if self.time_low_rule == Evt3TimeLow::CarryOnStepBack && time_low < self.time_low {
                    self.wraps = self.wraps.saturating_add(TIME_LOW_CARRY);
                }
                self.time_low = time_low;
            }
            0x8 => self
                .time_high
                .update((word & 0xfff) as i64, offset, &mut admission.report),
            0x7 | 0xA | 0xE | 0xF => {}
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

    fn decode(words: &[u16], sensor_size: SensorSize) -> (Vec<Event>, DecodeReport) {
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let source = ByteSource::new("mem.raw".into(), Box::new(Cursor::new(bytes)));
        let mut decoder = Evt3Decoder::new(source, sensor_size, 0);
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk).unwrap() > 0 {
            all.extend_from_slice(&chunk);
        }
        (all, decoder.report().clone())
    }

    #[test]
    fn single_and_vector_events_decode() {
        let (events, report) = decode(
            &[
                0x8003, // time high 3
                0x6005, // time low 5
                0x0007, // y 7
                0x2804, // x 4 ON
                0x3010, // base x 16 OFF
                0x4005, // vect12: bits 0, 2
                0x5001, // vect8 at base 28: bit 0
                0xA001, // trigger: passed over
            ],
            SensorSize::new(64, 8),
        );
        let t = (3 << 12) + 5;
        assert_eq!(
            events,
            vec![
                Event::new(t, 4, 7, true),
                Event::new(t, 16, 7, false),
                Event::new(t, 18, 7, false),
                Event::new(t, 28, 7, false),
            ]
        );
        assert!(report.is_clean());
    }

    #[test]
    fn time_high_wrap_adds_24_bits_and_time_low_steps_back_are_counted() {
        let (events, report) = decode(
            &[
                0x8fff, 0x6010, 0x2001, 0x8000, 0x6002, 0x2001, 0x6001, 0x2001,
            ],
            SensorSize::new(8, 8),
        );
        let times: Vec<i64> = events.iter().map(|e| e.t).collect();
        assert_eq!(
            times,
            vec![(0xfff << 12) + 0x10, (1 << 24) + 2, (1 << 24) + 1]
        );
        assert_eq!(report.time_regressions, 1);
        assert_eq!(report.first_time_regression_index, Some(2));
    }

    #[test]
    fn carry_rule_adds_4096_on_every_time_low_step_back() {
        let words = [
            0x8001, 0x6100, 0x2001, 0x6050, 0x2001, 0x8002, 0x6000, 0x2001,
        ];
        let bytes: Vec<u8> = words.iter().flat_map(|w: &u16| w.to_le_bytes()).collect();
        let source = ByteSource::new("mem.raw".into(), Box::new(Cursor::new(bytes)));
        let mut decoder = Evt3Decoder::new(source, SensorSize::new(8, 8), 0)
            .with_time_low_rule(Evt3TimeLow::CarryOnStepBack);
        let mut events = Vec::new();
        decoder.read_chunk(&mut events).unwrap();
        let times: Vec<i64> = events.iter().map(|e| e.t).collect();
        assert_eq!(
            times,
            vec![
                (1 << 12) + 0x100,
                (1 << 12) + 0x50 + 4096,
                (2 << 12) + 2 * 4096
            ]
        );
        assert_eq!(
            "carry-on-step-back".parse::<Evt3TimeLow>().unwrap(),
            Evt3TimeLow::CarryOnStepBack
        );
        let err = "wrap".parse::<Evt3TimeLow>().unwrap_err().to_string();
        assert!(
            err.contains("`wrap`") && err.contains("evt3, carry-on-step-back"),
            "{err}"
        );
    }

    #[test]
    fn unknown_types_are_skipped_and_vectors_past_the_sensor_dropped() {
        let (events, report) = decode(&[0x1234, 0x9000, 0x3006, 0x4fff], SensorSize::new(8, 8));
        assert_eq!(events.len(), 2);
        assert_eq!(report.skipped_words, 2);
        assert_eq!(report.first_skipped_word_offset, Some(0));
        assert_eq!(report.dropped_out_of_sensor, 10);
        assert_eq!(report.first_out_of_sensor_offset, Some(6));
    }
}
