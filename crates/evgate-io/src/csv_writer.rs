//! CSV output: a `t,x,y,p` header line, then one `t,x,y,p` line per event (t in µs, p 1 = ON,
//! 0 = OFF).

use std::io::Write;
use std::path::PathBuf;

use evgate_core::Event;

use crate::format::Format;
use crate::writer::{io_error, EncodeError, EventWriter};

pub struct CsvWriter<W: Write> {
    path: PathBuf,
    out: W,
    line: Vec<u8>,
}

impl<W: Write> CsvWriter<W> {
    pub fn new(path: PathBuf, mut out: W) -> Result<Self, EncodeError> {
        out.write_all(b"t,x,y,p\n")
            .map_err(io_error(&path, "write"))?;
        Ok(Self {
            path,
            out,
            line: Vec::with_capacity(64),
        })
    }
}

impl<W: Write> EventWriter for CsvWriter<W> {
    fn format(&self) -> Format {
        Format::Csv
    }

    fn write(&mut self, events: &[Event]) -> Result<(), EncodeError> {
        for event in events {
            self.line.clear();
            // Writing into a Vec cannot fail.
            let _ = writeln!(
                self.line,
                "{},{},{},{}",
                event.t,
                event.x,
                event.y,
                event.is_on() as u8
            );
            self.out
                .write_all(&self.line)
                .map_err(io_error(&self.path, "write"))?;
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> Result<(), EncodeError> {
        self.out.flush().map_err(io_error(&self.path, "flush"))
    }
}
