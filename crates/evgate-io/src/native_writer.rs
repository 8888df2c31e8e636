//! `.evg` output (docs/native-format.md): the header is written with an unknown count first and
//! patched with the real count by [`EventWriter::finish`].

use std::io::{Seek, SeekFrom, Write};
use std::path::PathBuf;

use evgate_core::{Event, SensorSize};

use crate::format::Format;
use crate::native::{encode_record, header, UNKNOWN_COUNT};
use crate::writer::{io_error, EncodeError, EventWriter};

pub struct NativeWriter<W: Write + Seek> {
    path: PathBuf,
    out: W,
    sensor_size: SensorSize,
    count: u64,
    buffer: Vec<u8>,
}

impl<W: Write + Seek> NativeWriter<W> {
    pub fn new(path: PathBuf, mut out: W, sensor_size: SensorSize) -> Result<Self, EncodeError> {
        if sensor_size.width == 0 || sensor_size.height == 0 {
            return Err(EncodeError::UnsupportedSensor {
                path,
                sensor_size,
                problem: "a side is zero".into(),
            });
        }
        out.write_all(&header(sensor_size, UNKNOWN_COUNT))
            .map_err(io_error(&path, "write"))?;
        Ok(Self {
            path,
            out,
            sensor_size,
            count: 0,
            buffer: Vec::new(),
        })
    }
}

impl<W: Write + Seek> EventWriter for NativeWriter<W> {
    fn format(&self) -> Format {
        Format::Native
    }

    fn write(&mut self, events: &[Event]) -> Result<(), EncodeError> {
        self.buffer.clear();
        for event in events {
            self.buffer.extend_from_slice(&encode_record(event));
        }
        self.out
            .write_all(&self.buffer)
            .map_err(io_error(&self.path, "write"))?;
        self.count += events.len() as u64;
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> Result<(), EncodeError> {
        let path = self.path.clone();
        self.out
            .seek(SeekFrom::Start(0))
            .and_then(|_| self.out.write_all(&header(self.sensor_size, self.count)))
            .and_then(|_| self.out.flush())
            .map_err(io_error(&path, "finish"))
    }
}
