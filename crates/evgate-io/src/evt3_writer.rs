//! EVT 3.0 output: a `%` header (`% evt 3.0`, `% format EVT3;height=H;width=W`, `% geometry
//! WxH`, `% end`), then per event the `TIME_HIGH` / `TIME_LOW` / `ADDR_Y` words that changed and
//! one `ADDR_X` word.
//!
//! The format's time base is 24 bits with wraps detected on `TIME_HIGH`, so events must be in
//! non-decreasing time and non-negative; a gap of more than 4095 `TIME_HIGH` units is bridged
//! with intermediate `TIME_HIGH` words so a decoder counts every wrap.

use std::io::Write;
use std::path::PathBuf;

use evgate_core::{Event, SensorSize};

use crate::format::Format;
use crate::writer::{io_error, EncodeError, EventWriter};

/// Coordinates are 11-bit fields.
const MAX_SIDE: u16 = 2048;
/// The largest `TIME_HIGH` step a decoder reads unambiguously (a smaller 12-bit value = a wrap).
const MAX_TIME_HIGH_STEP: u64 = 4095;

pub struct Evt3Writer<W: Write> {
    path: PathBuf,
    out: W,
    words: Vec<u8>,
    time_high: Option<u64>,
    time_low: Option<u16>,
    y: Option<u16>,
    last_t: i64,
    index: u64,
}

impl<W: Write> Evt3Writer<W> {
    pub fn new(path: PathBuf, mut out: W, sensor_size: SensorSize) -> Result<Self, EncodeError> {
        let SensorSize { width, height } = sensor_size;
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(EncodeError::UnsupportedSensor {
                path,
                sensor_size,
                problem: format!("EVT 3.0 needs sides in 1..={MAX_SIDE}"),
            });
        }
        let header = format!(
            "% evt 3.0\n% format EVT3;height={height};width={width}\n% geometry {width}x{height}\n% end\n"
        );
        out.write_all(header.as_bytes())
            .map_err(io_error(&path, "write"))?;
        Ok(Self {
            path,
            out,
            words: Vec::new(),
            time_high: None,
            time_low: None,
            y: None,
            last_t: 0,
            index: 0,
        })
    }

    fn push(&mut self, kind: u16, payload: u16) {
        self.words
            .extend_from_slice(&((kind << 12) | payload).to_le_bytes());
    }

    fn encode(&mut self, event: &Event) -> Result<(), EncodeError> {
        let problem = if event.t < self.last_t {
            Some(format!(
                "time goes back from {} µs (EVT 3.0 needs non-decreasing, non-negative times)",
                self.last_t
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
        self.last_t = event.t;
        let time_high = event.t as u64 >> 12;
        let time_low = (event.t & 0xfff) as u16;
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
        self.out.flush().map_err(io_error(&self.path, "flush"))
    }
}
