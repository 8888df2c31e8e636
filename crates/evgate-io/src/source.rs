//! A byte stream read in bounded blocks that knows the file offset of every byte it hands out,
//! so decoders can name the exact offset of a problem.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::DecodeError;

/// Bytes read from the underlying stream per refill: large enough to amortise system calls,
/// small enough that a chunk of decoded events stays a few MiB.
pub const BLOCK_BYTES: usize = 256 * 1024;

pub struct ByteSource {
    path: PathBuf,
    reader: Box<dyn Read + Send>,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    /// File offset of `buf[0]`.
    buf_offset: u64,
    eof: bool,
}

impl ByteSource {
    pub fn new(path: PathBuf, reader: Box<dyn Read + Send>) -> Self {
        Self {
            path,
            reader,
            buf: vec![0; BLOCK_BYTES],
            start: 0,
            end: 0,
            buf_offset: 0,
            eof: false,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// File offset of the next unconsumed byte.
    pub fn offset(&self) -> u64 {
        self.buf_offset + self.start as u64
    }

    /// Bytes not consumed yet in the buffer.
    fn available(&self) -> &[u8] {
        &self.buf[self.start..self.end]
    }

    /// Moves leftover bytes to the front and reads more; returns false at end of stream.
    fn refill(&mut self) -> Result<bool, DecodeError> {
        if self.eof {
            return Ok(false);
        }
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.buf_offset += self.start as u64;
            self.end -= self.start;
            self.start = 0;
        }
        if self.end == self.buf.len() {
            self.buf.resize(self.buf.len() * 2, 0);
        }
        loop {
            match self.reader.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    return Ok(false);
                }
                Ok(n) => {
                    self.end += n;
                    return Ok(true);
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(source) => {
                    return Err(DecodeError::Io {
                        path: self.path.clone(),
                        offset: self.offset(),
                        source,
                    })
                }
            }
        }
    }

    /// The next byte without consuming it; `None` at end of stream.
    pub fn peek(&mut self) -> Result<Option<u8>, DecodeError> {
        if self.start == self.end && !self.refill()? {
            return Ok(None);
        }
        Ok(self.available().first().copied())
    }

    /// Consumes exactly `n` bytes; `what` names them in the error if the stream ends first.
    pub fn read_exact(&mut self, n: usize, what: &'static str) -> Result<&[u8], DecodeError> {
        while self.end - self.start < n {
            if !self.refill()? {
                return Err(DecodeError::Truncated {
                    path: self.path.clone(),
                    offset: self.offset(),
                    what,
                    needed: n,
                    found: self.end - self.start,
                });
            }
        }
        let bytes = &self.buf[self.start..self.start + n];
        self.start += n;
        Ok(bytes)
    }

    /// Consumes one line into `line` (without its `\n` or `\r\n`) and returns its offset;
    /// `None` at end of stream. Lines are capped at `max_len` bytes so a binary file mistaken for
    /// text cannot exhaust memory.
    pub fn read_line(
        &mut self,
        max_len: usize,
        line: &mut Vec<u8>,
    ) -> Result<Option<u64>, DecodeError> {
        line.clear();
        let line_offset = self.offset();
        let mut scanned = 0;
        loop {
            if let Some(pos) = self.available()[scanned..].iter().position(|&b| b == b'\n') {
                let end = self.start + scanned + pos;
                line.extend_from_slice(&self.buf[self.start..end]);
                self.start = end + 1;
                if line.last() == Some(&b'\r') {
                    line.pop();
                }
                return Ok(Some(line_offset));
            }
            scanned = self.end - self.start;
            if scanned > max_len {
                return Err(DecodeError::Malformed {
                    path: self.path.clone(),
                    offset: line_offset,
                    problem: format!("line longer than {max_len} bytes (is this a text file?)"),
                });
            }
            if !self.refill()? {
                if self.start == self.end {
                    return Ok(None);
                }
                line.extend_from_slice(self.available());
                self.start = self.end;
                return Ok(Some(line_offset));
            }
        }
    }

    /// Hands out the buffered bytes that form whole records of `record` bytes, refilling first
    /// if fewer than one record is buffered. Returns the file offset of the first byte and the
    /// records; an empty slice means end of stream. A partial record at the end is an error.
    pub fn next_records(
        &mut self,
        record: usize,
        what: &'static str,
    ) -> Result<(u64, &[u8]), DecodeError> {
        if self.end - self.start < record.max(BLOCK_BYTES / 2) {
            while self.refill()? && self.end - self.start < BLOCK_BYTES / 2 {}
        }
        let whole = (self.end - self.start) / record * record;
        if whole == 0 && self.eof && self.end > self.start {
            return Err(DecodeError::Truncated {
                path: self.path.clone(),
                offset: self.offset(),
                what,
                needed: record,
                found: self.end - self.start,
            });
        }
        let offset = self.offset();
        let bytes = &self.buf[self.start..self.start + whole];
        self.start += whole;
        Ok((offset, bytes))
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn source(bytes: &[u8]) -> ByteSource {
        ByteSource::new("mem".into(), Box::new(Cursor::new(bytes.to_vec())))
    }

    #[test]
    fn lines_then_records_keep_offsets() {
        let mut src = source(b"% a\r\n% bb\n\x01\x02\x03\x04\x05");
        let mut line = Vec::new();
        assert_eq!(src.read_line(100, &mut line).unwrap(), Some(0));
        assert_eq!(line, b"% a");
        assert_eq!(src.read_line(100, &mut line).unwrap(), Some(5));
        assert_eq!(line, b"% bb");
        assert_eq!(src.peek().unwrap(), Some(1));
        let (offset, records) = src.next_records(2, "word").unwrap();
        assert_eq!((offset, records), (10, &[1u8, 2, 3, 4][..]));
        let err = src.next_records(2, "word").unwrap_err().to_string();
        assert!(err.contains("offset 14") && err.contains("word"), "{err}");
    }

    #[test]
    fn read_exact_reports_truncation() {
        let mut src = source(b"abc");
        assert_eq!(src.read_exact(2, "magic").unwrap(), b"ab");
        let err = src.read_exact(2, "magic").unwrap_err().to_string();
        assert!(err.contains("offset 2") && err.contains("magic"), "{err}");
    }
}
