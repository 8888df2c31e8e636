//! EVT 3.0 output: a `%` header (`% evt 3.0`, `% format EVT3;height=H;width=W`, `% geometry
//! WxH`, `% end`), then per event the `TIME_HIGH` / `TIME_LOW` / `ADDR_Y` words that changed and
//! one `ADDR_X` word.
//!
//! The format's time base is 24 bits with wraps detected on `TIME_HIGH`, so events must be in
//! non-decreasing time; a gap of more than [`MAX_TIME_HIGH_STEP_US`] is bridged with
//! intermediate `TIME_HIGH` words, as a sensor sends them, so a decoder counts every wrap and
//! never takes a step for a corrupt word ([`crate::time_high`]). Times are written relative to
//! the first event's time rounded down to a multiple of 2^24 µs, declared in the header as
//! `% evgate_time_offset_us N` (our decoder adds it back; other readers see the times modulo
//! it): absolute times (AEDAT 4 records Unix time) would otherwise need millions of bridging
//! words. The header is therefore written with the first event (or by `finish`).

use std::io::Write;
use std::path::PathBuf;

use evgate_core::{Event, SensorSize};

use crate::format::Format;
use crate::time_high::MAX_TIME_HIGH_STEP_US;
use crate::writer::{io_error, EncodeError, EventWriter};

/// Coordinates are 11-bit fields.
const MAX_SIDE: u16 = 2048;
/// The time offset is a whole number of 24-bit wraps, so the low bits are written unchanged.
const TIME_BASE_WRAP: i64 = 1 << 24;
/// The largest `TIME_HIGH` step, in units of 4096 µs, that a decoder takes as the stream's own.
const MAX_TIME_HIGH_STEP: u64 = (MAX_TIME_HIGH_STEP_US >> 12) as u64;

pub struct Evt3Writer<W: Write> {
    path: PathBuf,
    out: W,
    sensor_size: SensorSize,
    /// Set with the first event, when the header is written.
    time_offset: Option<i64>,
    words: Vec<u8>,
    time_high: Option<u64>,
    time_low: Option<u16>,
    y: Option<u16>,
    last_t: Option<i64>,
    index: u64,
}

impl<W: Write> Evt3Writer<W> {
    pub fn new(path: PathBuf, out: W, sensor_size: SensorSize) -> Result<Self, EncodeError> {
        let SensorSize { width, height } = sensor_size;
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(EncodeError::UnsupportedSensor {
                path,
                sensor_size,
                problem: format!("EVT 3.0 needs sides in 1..={MAX_SIDE}"),
            });
        }
        Ok(Self {
            path,
            out,
            sensor_size,
            time_offset: None,
            words: Vec::new(),
            time_high: None,
            time_low: None,
            y: None,
            last_t: None,
            index: 0,
        })
    }

    fn header(&self, time_offset: i64) -> String {
        let SensorSize { width, height } = self.sensor_size;
        format!(
            "% evt 3.0\n% format EVT3;height={height};width={width}\n% geometry {width}x{height}\n% evgate_time_offset_us {time_offset}\n% end\n"
        )
    }

    fn push(&mut self, kind: u16, payload: u16) {
        self.words
            .extend_from_slice(&((kind << 12) | payload).to_le_bytes());
    }

    fn encode(&mut self, event: &Event) -> Result<(), EncodeError> {
        let problem = if self.last_t.is_some_and(|last| event.t < last) {
            Some(format!(
                "time goes back from {} µs (EVT 3.0 needs non-decreasing times)",
                self.last_t.unwrap_or_default()
            ))
        } else if event.x >= MAX_SIDE || event.y >= MAX_SIDE {
            Some(format!("coordinates must be below {MAX_SIDE}"))
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(EncodeError::Unencodable {
                path: self.path.clone(),
                index: self.index,
                event: *event,
                problem,
            });
        }
        self.last_t = Some(event.t);
        let time_offset = match self.time_offset {
            Some(offset) => offset,
            None => {
                let offset = event.t.div_euclid(TIME_BASE_WRAP) * TIME_BASE_WRAP;
                let header = self.header(offset);
                self.words.extend_from_slice(header.as_bytes());
                self.time_offset = Some(offset);
                offset
            }
        };
        // Non-negative: times never go below the first one, which is at or above the offset.
        let relative = event
            .t
            .checked_sub(time_offset)
            .ok_or_else(|| EncodeError::Unencodable {
                path: self.path.clone(),
                index: self.index,
                event: *event,
                problem: format!(
                    "more than 2^63 µs after the first event (offset {time_offset} µs)"
                ),
            })? as u64;
        let time_high = relative >> 12;
        let time_low = (relative & 0xfff) as u16;
        if self.time_high != Some(time_high) {
            let mut current = self.time_high.unwrap_or(0);
            while time_high - current > MAX_TIME_HIGH_STEP {
                current += MAX_TIME_HIGH_STEP;
                self.push(0x8, (current & 0xfff) as u16);
            }
            self.push(0x8, (time_high & 0xfff) as u16);
            self.time_high = Some(time_high);
            self.time_low = None;
        }
        if self.time_low != Some(time_low) {
            self.push(0x6, time_low);
            self.time_low = Some(time_low);
        }
        if self.y != Some(event.y) {
            self.push(0x0, event.y);
            self.y = Some(event.y);
        }
        self.push(0x2, ((event.is_on() as u16) << 11) | event.x);
        self.index += 1;
        Ok(())
    }
}

impl<W: Write> EventWriter for Evt3Writer<W> {
    fn format(&self) -> Format {
        Format::Evt3
    }

    fn write(&mut self, events: &[Event]) -> Result<(), EncodeError> {
        self.words.clear();
        for event in events {
            self.encode(event)?;
        }
        self.out
            .write_all(&self.words)
            .map_err(io_error(&self.path, "write"))
    }

    fn finish(mut self: Box<Self>) -> Result<(), EncodeError> {
        if self.time_offset.is_none() {
            let header = self.header(0);
            self.out
                .write_all(header.as_bytes())
                .map_err(io_error(&self.path, "write"))?;
        }
        self.out.flush().map_err(io_error(&self.path, "flush"))
    }
}
