//! Formats of fixed-size records (EVT 2.0 and 3.0 words, DAT records, `.evg` events, EVIMO
//! rows) share the chunk loop: take the whole records buffered, decode them, repeat until an
//! event comes out or the stream ends (a partial record at the end is an error).

use evgate_core::Event;

use crate::error::DecodeError;
use crate::format::Format;
use crate::report::Admission;
use crate::stream_decoder::{ChunkFormat, DecoderInput};

/// A record that cannot be decoded: where it is and what is wrong.
pub struct BadRecord {
    pub offset: u64,
    pub problem: String,
}

pub trait RecordFormat: Send {
    const FORMAT: Format;
    const RECORD_BYTES: usize;
    /// Names a record in truncation errors ("an EVT 2.0 word").
    const RECORD_NAME: &'static str;

    /// Decodes one record (`RECORD_BYTES` long, at file offset `offset`) into `out` through
    /// `admission`. Implementations are `#[inline]`: the loop below calls this once per record,
    /// and without the hint the call stayed out of line (`.evg` and DAT decoded about 40 %
    /// slower in the decode bench).
    fn decode_record(
        &mut self,
        offset: u64,
        record: &[u8],
        admission: &mut Admission,
        out: &mut Vec<Event>,
    ) -> Result<(), BadRecord>;

    /// Called when the stream ends at `offset` (after the last whole record).
    fn at_end(&mut self, _offset: u64) -> Result<(), BadRecord> {
        Ok(())
    }
}

impl<R: RecordFormat> ChunkFormat for R {
    const FORMAT: Format = R::FORMAT;

    fn decode_chunk(
        &mut self,
        input: &mut DecoderInput,
        out: &mut Vec<Event>,
    ) -> Result<(), DecodeError> {
        while out.is_empty() {
            let (start, records) = input.source.next_records(R::RECORD_BYTES, R::RECORD_NAME)?;
            let end = records.is_empty();
            let decoded = if end {
                self.at_end(start)
            } else {
                records
                    .chunks_exact(R::RECORD_BYTES)
                    .enumerate()
                    .try_for_each(|(i, record)| {
                        let offset = start + (i * R::RECORD_BYTES) as u64;
                        self.decode_record(offset, record, &mut input.admission, out)
                    })
            };
            decoded.map_err(|bad| input.malformed(bad.offset, bad.problem))?;
            if end {
                break;
            }
        }
        Ok(())
    }
}
