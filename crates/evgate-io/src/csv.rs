//! Text events, one per line: `t x y p`, separated by commas and/or whitespace (CSV, the ECD /
//! EVIMO `events.txt` layout).
//!
//! - An optional header line (its first field not a number, e.g. `t,x,y,p`) and lines starting
//!   with `#` are passed over; so are blank lines.
//! - The time unit is chosen by the first event line: a time written with a decimal point or an
//!   exponent (`0.003811`, `1e-3`) means seconds for the whole file, an integer means
//!   microseconds. Seconds are rounded to the nearest microsecond.
//! - Polarity: `1` = ON; `0` or `-1` = OFF.
//! - Anything else is an error naming the line, its byte offset and the field.

use std::path::Path;

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::format::Format;
use crate::source::ByteSource;
use crate::stream_decoder::{ChunkFormat, DecoderInput, StreamDecoder};

/// Events per chunk.
const CHUNK_EVENTS: usize = 64 * 1024;
const MAX_LINE: usize = 4096;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TimeUnit {
    Microseconds,
    Seconds,
}

/// What a text stream carries from line to line: the time unit, the line number, whether a
/// header line may still come.
pub struct CsvLines {
    unit: Option<TimeUnit>,
    line_number: u64,
    header_allowed: bool,
    /// Reused for every line so reading allocates nothing per event.
    line: Vec<u8>,
}

pub type CsvDecoder = StreamDecoder<CsvLines>;

impl CsvDecoder {
    /// Text files carry no sensor size: the caller gives it (events outside are dropped and
    /// counted).
    pub fn new(source: ByteSource, sensor_size: SensorSize) -> Self {
        Self::from_parts(
            source,
            sensor_size,
            CsvLines {
                unit: None,
                line_number: 0,
                header_allowed: true,
                line: Vec::new(),
            },
        )
    }
}

impl ChunkFormat for CsvLines {
    const FORMAT: Format = Format::Csv;

    /// Fills `out` with up to 65 536 events.
    fn decode_chunk(
        &mut self,
        input: &mut DecoderInput,
        out: &mut Vec<Event>,
    ) -> Result<(), DecodeError> {
        let mut line = std::mem::take(&mut self.line);
        let result = self.fill(input, out, &mut line);
        self.line = line;
        result
    }
}

impl CsvLines {
    fn fill(
        &mut self,
        input: &mut DecoderInput,
        out: &mut Vec<Event>,
        line: &mut Vec<u8>,
    ) -> Result<(), DecodeError> {
        while out.len() < CHUNK_EVENTS {
            let Some(offset) = input.source.read_line(MAX_LINE, line)? else {
                break;
            };
            self.line_number += 1;
            let text = std::str::from_utf8(line)
                .map_err(|_| self.error(input.source.path(), offset, "is not UTF-8 text".into()))?;
            let text = text.trim();
            if text.is_empty() || text.starts_with('#') {
                continue;
            }
            let mut fields = [""; 4];
            let mut count = 0;
            for field in text
                .split(|c: char| c == ',' || c.is_ascii_whitespace())
                .filter(|f| !f.is_empty())
            {
                if let Some(slot) = fields.get_mut(count) {
                    *slot = field;
                }
                count += 1;
            }
            if self.header_allowed {
                self.header_allowed = false;
                if fields[0].parse::<f64>().is_err() {
                    continue;
                }
            }
            let event = self.parse(input.source.path(), offset, &fields, count)?;
            input.admission.admit(out, event, offset);
        }
        Ok(())
    }

    fn error(&self, path: &Path, offset: u64, problem: String) -> DecodeError {
        DecodeError::Malformed {
            path: path.to_path_buf(),
            offset,
            problem: format!("line {} {problem}", self.line_number),
        }
    }

    fn parse(
        &mut self,
        path: &Path,
        offset: u64,
        fields: &[&str; 4],
        count: usize,
    ) -> Result<Event, DecodeError> {
        if count != 4 {
            return Err(self.error(
                path,
                offset,
                format!("has {count} fields, expected 4 (t x y p)"),
            ));
        }
        let looks_fractional = fields[0].contains(['.', 'e', 'E']);
        let unit = *self.unit.get_or_insert(if looks_fractional {
            TimeUnit::Seconds
        } else {
            TimeUnit::Microseconds
        });
        let t = match (unit, looks_fractional) {
            (TimeUnit::Microseconds, false) => fields[0].parse::<i64>().ok(),
            (TimeUnit::Microseconds, true) => fields[0]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && v.abs() < 9e18)
                .map(|v| v.round() as i64),
            (TimeUnit::Seconds, _) => fields[0]
                .parse::<f64>()
                .ok()
                .map(|v| v * 1e6)
                .filter(|v| v.is_finite() && v.abs() < 9e18)
                .map(|v| v.round() as i64),
        }
        .ok_or_else(|| {
            self.error(
                path,
                offset,
                format!("field t: `{}` is not a time", fields[0]),
            )
        })?;
        let coordinate = |index: usize, name: &str| {
            fields[index].parse::<u16>().map_err(|_| {
                self.error(
                    path,
                    offset,
                    format!(
                        "field {name}: `{}` is not a coordinate in 0..=65535",
                        fields[index]
                    ),
                )
            })
        };
        let x = coordinate(1, "x")?;
        let y = coordinate(2, "y")?;
        let on = match fields[3] {
            "1" | "+1" => true,
            "0" | "-1" => false,
            other => {
                return Err(self.error(
                    path,
                    offset,
                    format!("field p: `{other}` is not a polarity (accepted: 1, 0, -1)"),
                ))
            }
        };
        Ok(Event::new(t, x, y, on))
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;
    use crate::report::DecodeReport;

    fn decode(text: &str) -> Result<(Vec<Event>, DecodeReport), DecodeError> {
        let source = ByteSource::new(
            "mem.csv".into(),
            Box::new(Cursor::new(text.as_bytes().to_vec())),
        );
        let mut decoder = CsvDecoder::new(source, SensorSize::new(10, 10));
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while decoder.read_chunk(&mut chunk)? > 0 {
            all.extend_from_slice(&chunk);
        }
        Ok((all, decoder.report().clone()))
    }

    #[test]
    fn header_separators_and_units() {
        let (events, _) = decode("t,x,y,p\n10,1,2,1\n# note\n\n11 , 3, 4 ,0\n").unwrap();
        assert_eq!(
            events,
            vec![Event::new(10, 1, 2, true), Event::new(11, 3, 4, false)]
        );
        let (events, _) = decode("0.000010 1 2 1\r\n0.0000115\t3 4 -1\n").unwrap();
        assert_eq!(
            events,
            vec![Event::new(10, 1, 2, true), Event::new(12, 3, 4, false)]
        );
    }

    #[test]
    fn bad_lines_name_line_offset_and_field() {
        let err = decode("t,x,y,p\n1,2,3,1\n2,x,3,1\n")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("line 3") && err.contains("offset 16") && err.contains("field x"),
            "{err}"
        );
        let err = decode("1,2,3,7\n").unwrap_err().to_string();
        assert!(err.contains("field p") && err.contains("`7`"), "{err}");
        let err = decode("1,2,3\n").unwrap_err().to_string();
        assert!(err.contains("3 fields"), "{err}");
        let err = decode("t,x,y,p\nt,x,y,p\n").unwrap_err().to_string();
        assert!(err.contains("line 2") && err.contains("field t"), "{err}");
    }

    #[test]
    fn empty_text_has_no_events_and_outside_events_are_counted() {
        assert!(decode("").unwrap().0.is_empty());
        let (events, report) = decode("1,10,0,1\n2,0,0,1\n1,0,0,1\n").unwrap();
        assert_eq!(events.len(), 2);
        assert_eq!(report.dropped_out_of_sensor, 1);
        assert_eq!(report.time_regressions, 1);
        assert_eq!(report.first_time_regression_index, Some(1));
    }
}
