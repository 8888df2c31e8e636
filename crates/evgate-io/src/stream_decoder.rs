//! What every byte-stream decoder shares: its input (the byte source and the admission of
//! events: sensor bounds, time order, the report), the accessors and the [`EventReader`]
//! implementation. A format supplies only how the next chunk of events is decoded
//! ([`ChunkFormat`]; formats of fixed-size records implement [`crate::records::RecordFormat`]
//! instead).

use evgate_core::{Event, SensorSize};

use crate::error::DecodeError;
use crate::format::Format;
use crate::reader::EventReader;
use crate::report::{Admission, DecodeReport};
use crate::source::ByteSource;

pub struct DecoderInput {
    pub source: ByteSource,
    pub admission: Admission,
}

impl DecoderInput {
    /// A [`DecodeError::Malformed`] at `offset` of this input.
    pub fn malformed(&self, offset: u64, problem: String) -> DecodeError {
        DecodeError::Malformed {
            path: self.source.path().to_path_buf(),
            offset,
            problem,
        }
    }
}

/// How one format turns its input into events.
pub trait ChunkFormat: Send {
    const FORMAT: Format;

    /// Fills `out` (empty on entry) with the next chunk of events; leaving it empty means the
    /// end of the stream.
    fn decode_chunk(
        &mut self,
        input: &mut DecoderInput,
        out: &mut Vec<Event>,
    ) -> Result<(), DecodeError>;
}

pub struct StreamDecoder<F> {
    input: DecoderInput,
    /// The format's own state (time bases, header fields, buffers).
    pub(crate) format: F,
}

impl<F: ChunkFormat> StreamDecoder<F> {
    /// `source` must be positioned at the format's first event data.
    pub(crate) fn from_parts(source: ByteSource, sensor_size: SensorSize, format: F) -> Self {
        Self {
            input: DecoderInput {
                source,
                admission: Admission::new(sensor_size),
            },
            format,
        }
    }

    pub fn sensor_size(&self) -> SensorSize {
        self.input.admission.sensor_size()
    }

    pub fn report(&self) -> &DecodeReport {
        &self.input.admission.report
    }

    /// Bytes of the input consumed so far.
    pub fn bytes_read(&self) -> u64 {
        self.input.source.offset()
    }

    /// Clears `out` and fills it with the next chunk of events; 0 means end of stream.
    pub fn read_chunk(&mut self, out: &mut Vec<Event>) -> Result<usize, DecodeError> {
        out.clear();
        self.format.decode_chunk(&mut self.input, out)?;
        Ok(out.len())
    }
}

impl<F: ChunkFormat> EventReader for StreamDecoder<F> {
    fn format(&self) -> Format {
        F::FORMAT
    }
    fn sensor_size(&self) -> SensorSize {
        StreamDecoder::sensor_size(self)
    }
    fn read_chunk(&mut self, out: &mut Vec<Event>) -> Result<usize, DecodeError> {
        StreamDecoder::read_chunk(self, out)
    }
    fn report(&self) -> &DecodeReport {
        StreamDecoder::report(self)
    }
    fn bytes_read(&self) -> u64 {
        StreamDecoder::bytes_read(self)
    }
}
