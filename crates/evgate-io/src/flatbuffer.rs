//! Just enough of the FlatBuffers wire format to read AEDAT 4 headers and event packets, with
//! every offset bounds-checked (the input is untrusted).

#[derive(Debug, thiserror::Error)]
#[error("flatbuffer byte {offset}: {problem}")]
pub struct FlatbufferError {
    pub offset: usize,
    pub problem: String,
}

fn fail(offset: usize, problem: impl Into<String>) -> FlatbufferError {
    FlatbufferError {
        offset,
        problem: problem.into(),
    }
}

fn bytes<const N: usize>(buf: &[u8], at: usize) -> Result<[u8; N], FlatbufferError> {
    buf.get(
        at..at
            .checked_add(N)
            .ok_or_else(|| fail(at, "offset overflows"))?,
    )
    .and_then(|b| b.try_into().ok())
    .ok_or_else(|| {
        fail(
            at,
            format!("reading {N} bytes runs past the end ({} bytes)", buf.len()),
        )
    })
}

fn u32_at(buf: &[u8], at: usize) -> Result<u32, FlatbufferError> {
    bytes::<4>(buf, at).map(u32::from_le_bytes)
}

/// Follows a forward `uoffset` stored at `at`.
fn follow(buf: &[u8], at: usize) -> Result<usize, FlatbufferError> {
    at.checked_add(u32_at(buf, at)? as usize)
        .filter(|&target| target < buf.len())
        .ok_or_else(|| fail(at, "offset points past the end"))
}

/// A table inside a buffer.
#[derive(Clone, Copy)]
pub struct Table<'a> {
    buf: &'a [u8],
    pos: usize,
    vtable: usize,
    vtable_len: usize,
}

impl<'a> Table<'a> {
    /// The root table; `identifier` (4 bytes after the root offset) is checked when given.
    pub fn root(buf: &'a [u8], identifier: Option<&[u8; 4]>) -> Result<Self, FlatbufferError> {
        if let Some(identifier) = identifier {
            let found = bytes::<4>(buf, 4)?;
            if &found != identifier {
                return Err(fail(
                    4,
                    format!(
                        "identifier {:?} is not {:?}",
                        String::from_utf8_lossy(&found),
                        String::from_utf8_lossy(identifier)
                    ),
                ));
            }
        }
        Self::at(buf, follow(buf, 0)?)
    }

    fn at(buf: &'a [u8], pos: usize) -> Result<Self, FlatbufferError> {
        let soffset = i32::from_le_bytes(bytes::<4>(buf, pos)?) as i64;
        let vtable = usize::try_from(pos as i64 - soffset)
            .ok()
            .filter(|&v| v + 4 <= buf.len())
            .ok_or_else(|| fail(pos, "vtable offset points outside the buffer"))?;
        let vtable_len = u16::from_le_bytes(bytes::<2>(buf, vtable)?) as usize;
        if vtable_len < 4 || vtable + vtable_len > buf.len() {
            return Err(fail(
                vtable,
                format!("vtable length {vtable_len} is invalid"),
            ));
        }
        Ok(Self {
            buf,
            pos,
            vtable,
            vtable_len,
        })
    }

    /// Absolute position of field `index`, `None` when absent (default value).
    fn field(&self, index: usize) -> Result<Option<usize>, FlatbufferError> {
        let entry = 4 + 2 * index;
        if entry + 2 > self.vtable_len {
            return Ok(None);
        }
        let offset = u16::from_le_bytes(bytes::<2>(self.buf, self.vtable + entry)?) as usize;
        Ok((offset != 0).then_some(self.pos + offset))
    }

    pub fn i32_field(&self, index: usize, default: i32) -> Result<i32, FlatbufferError> {
        match self.field(index)? {
            Some(at) => bytes::<4>(self.buf, at).map(i32::from_le_bytes),
            None => Ok(default),
        }
    }

    pub fn i64_field(&self, index: usize, default: i64) -> Result<i64, FlatbufferError> {
        match self.field(index)? {
            Some(at) => bytes::<8>(self.buf, at).map(i64::from_le_bytes),
            None => Ok(default),
        }
    }

    /// A vector of fixed-size structs: the bytes of all elements, `None` when absent.
    pub fn struct_vector(
        &self,
        index: usize,
        element: usize,
    ) -> Result<Option<&'a [u8]>, FlatbufferError> {
        let Some(at) = self.field(index)? else {
            return Ok(None);
        };
        let start = follow(self.buf, at)?;
        let len = u32_at(self.buf, start)? as usize;
        let data = start + 4;
        let end = len
            .checked_mul(element)
            .and_then(|n| n.checked_add(data))
            .filter(|&end| end <= self.buf.len())
            .ok_or_else(|| fail(start, format!("vector of {len} elements runs past the end")))?;
        Ok(Some(&self.buf[data..end]))
    }

    pub fn string_field(&self, index: usize) -> Result<Option<&'a str>, FlatbufferError> {
        let Some(at) = self.field(index)? else {
            return Ok(None);
        };
        let start = follow(self.buf, at)?;
        let len = u32_at(self.buf, start)? as usize;
        let text = self
            .buf
            .get(start + 4..start + 4 + len)
            .ok_or_else(|| fail(start, format!("string of {len} bytes runs past the end")))?;
        std::str::from_utf8(text)
            .map(Some)
            .map_err(|_| fail(start, "string is not UTF-8"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-assembled buffer: root offset, identifier, vtable, table with an i32 and a vector.
    fn buffer() -> Vec<u8> {
        let mut buf = Vec::new();
        buf.extend_from_slice(&16u32.to_le_bytes()); // root table at 16
        buf.extend_from_slice(b"TEST");
        buf.extend_from_slice(&[8, 0, 12, 0, 4, 0, 8, 0]); // vtable at 8: 2 fields
        buf.extend_from_slice(&8i32.to_le_bytes()); // table at 16: soffset to vtable
        buf.extend_from_slice(&(-7i32).to_le_bytes()); // field 0 at 20
        buf.extend_from_slice(&4u32.to_le_bytes()); // field 1 at 24 -> vector at 28
        buf.extend_from_slice(&2u32.to_le_bytes());
        buf.extend_from_slice(&[1, 2, 3, 4]);
        buf
    }

    #[test]
    fn fields_and_vectors_read() {
        let buf = buffer();
        let table = Table::root(&buf, Some(b"TEST")).unwrap();
        assert_eq!(table.i32_field(0, 0).unwrap(), -7);
        assert_eq!(
            table.struct_vector(1, 2).unwrap(),
            Some(&[1u8, 2, 3, 4][..])
        );
        assert_eq!(table.i64_field(5, 99).unwrap(), 99);
    }

    #[test]
    fn corrupt_offsets_are_errors_not_panics() {
        let buf = buffer();
        assert!(Table::root(&buf, Some(b"EVTS")).is_err());
        let mut bad = buf.clone();
        bad[28] = 0xff; // vector length
        let table = Table::root(&bad, None).unwrap();
        assert!(table.struct_vector(1, 2).is_err());
        for cut in 0..buf.len() {
            let _ = Table::root(&buf[..cut], None).and_then(|t| t.struct_vector(1, 2));
        }
    }
}
