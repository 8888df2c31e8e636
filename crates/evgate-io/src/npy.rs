//! The NumPy `.npy` array format (versions 1.0, 2.0 and 3.0), little-endian, C order.
//!
//! Only what the project exchanges with NumPy is supported: plain numeric dtypes, read into typed
//! vectors, and structured (record) dtypes, whose fields are listed so a caller can read them by
//! byte offset.

use std::io::{Read, Write};

const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// NumPy aligns the data start to 64 bytes so arrays can be memory-mapped.
const HEADER_ALIGNMENT: usize = 64;

#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    #[error("not a .npy array: the first 6 bytes are {found:02x?}, expected \\x93NUMPY")]
    BadMagic { found: Vec<u8> },
    #[error("unsupported .npy version {major}.{minor} (accepted: 1.0, 2.0, 3.0)")]
    UnsupportedVersion { major: u8, minor: u8 },
    #[error("malformed .npy header at byte {offset}: {problem} (header: {header:?})")]
    MalformedHeader {
        offset: usize,
        problem: String,
        header: String,
    },
    #[error(".npy header of {length} bytes is longer than the {limit} accepted")]
    HeaderTooLarge { length: usize, limit: usize },
    #[error("fortran-order arrays are not supported (save with np.ascontiguousarray)")]
    FortranOrder,
    #[error("dtype `{found}` is not the expected `{expected}`")]
    DType { expected: String, found: String },
    #[error("dtype `{0}` is not supported (accepted: |b1, |u1, |i1, <u2, <i2, <u4, <i4, <u8, <i8, <f2, <f4, <f8, |V<n> and records of them)")]
    UnsupportedDType(String),
    #[error("the data ends after {found} bytes, the header announces {expected}")]
    Truncated { expected: usize, found: usize },
    #[error("the pickled object is larger than {limit} bytes")]
    ObjectTooLarge { limit: u64 },
    #[error("shape {shape:?} overflows the address space")]
    ShapeOverflow { shape: Vec<usize> },
}

/// A scalar type that has a little-endian `.npy` dtype.
pub trait NpyElement: Copy {
    /// The dtype string NumPy writes for this type (`<i8`, `|u1`, ...).
    const DESCR: &'static str;
    const SIZE: usize;
    fn from_le_slice(bytes: &[u8]) -> Self;
    fn extend_le(self, out: &mut Vec<u8>);
}

macro_rules! npy_element {
    ($ty:ty, $descr:literal) => {
        impl NpyElement for $ty {
            const DESCR: &'static str = $descr;
            const SIZE: usize = std::mem::size_of::<$ty>();
            fn from_le_slice(bytes: &[u8]) -> Self {
                <$ty>::from_le_bytes(bytes.try_into().expect("chunk of SIZE bytes"))
            }
            fn extend_le(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    };
}

npy_element!(u8, "|u1");
npy_element!(i8, "|i1");
npy_element!(u16, "<u2");
npy_element!(i16, "<i2");
npy_element!(u32, "<u4");
npy_element!(i32, "<i4");
npy_element!(u64, "<u8");
npy_element!(i64, "<i8");
npy_element!(half::f16, "<f2");
npy_element!(f32, "<f4");
npy_element!(f64, "<f8");

/// One field of a structured dtype.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordField {
    pub name: String,
    pub descr: String,
    /// Byte offset inside one record.
    pub offset: usize,
    pub size: usize,
}

/// The element type of an array: one scalar dtype string or a record of fields.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DType {
    Scalar(String),
    Record(Vec<RecordField>),
    /// `|O`: Python objects; the data is a pickle (see [`read_pickled_object`]).
    Object,
}

impl DType {
    /// Bytes per element.
    pub fn item_size(&self) -> Result<usize, NpyError> {
        match self {
            DType::Scalar(descr) => scalar_size(descr),
            DType::Record(fields) => Ok(fields.iter().map(|f| f.size).sum()),
            DType::Object => Err(NpyError::UnsupportedDType(
                "|O (an object array is a pickle: read it with read_pickled_object)".into(),
            )),
        }
    }
}

impl std::fmt::Display for DType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DType::Scalar(descr) => f.write_str(descr),
            DType::Object => f.write_str("|O"),
            DType::Record(fields) => {
                f.write_str("[")?;
                for (i, field) in fields.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "('{}', '{}')", field.name, field.descr)?;
                }
                f.write_str("]")
            }
        }
    }
}

fn scalar_size(descr: &str) -> Result<usize, NpyError> {
    let unsupported = || NpyError::UnsupportedDType(descr.to_owned());
    let mut chars = descr.chars();
    let order = chars.next().ok_or_else(unsupported)?;
    let kind = chars.next().ok_or_else(unsupported)?;
    let size: usize = chars.as_str().parse().map_err(|_| unsupported())?;
    let order_ok = match (kind, size) {
        ('V', _) => order == '|',
        (_, 1) => matches!(order, '|' | '<' | '='),
        _ => order == '<',
    };
    let kind_ok = match kind {
        'b' | 'u' | 'i' => matches!(size, 1 | 2 | 4 | 8) && (kind != 'b' || size == 1),
        'f' => matches!(size, 2 | 4 | 8),
        'V' => size > 0,
        _ => false,
    };
    if order_ok && kind_ok {
        Ok(size)
    } else {
        Err(unsupported())
    }
}

/// Single-byte dtypes may be written with any byte-order mark; compare them without it.
fn same_scalar(found: &str, expected: &str) -> bool {
    let strip = |d: &str| -> String {
        if d.len() == 3 && d.ends_with('1') {
            d[1..].to_owned()
        } else {
            d.to_owned()
        }
    };
    strip(found) == strip(expected)
}

/// A whole array held in memory as raw little-endian bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    pub dtype: DType,
    pub shape: Vec<usize>,
    pub data: Vec<u8>,
}

impl NpyArray {
    /// Number of elements (the product of the shape; 1 for a 0-d array).
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reads the data as scalars of type `T`, checking the dtype.
    pub fn to_vec<T: NpyElement>(&self) -> Result<Vec<T>, NpyError> {
        match &self.dtype {
            DType::Scalar(descr) if same_scalar(descr, T::DESCR) => Ok(self
                .data
                .chunks_exact(T::SIZE)
                .map(T::from_le_slice)
                .collect()),
            other => Err(NpyError::DType {
                expected: T::DESCR.to_owned(),
                found: other.to_string(),
            }),
        }
    }

    /// Builds an array of scalars from a typed slice.
    pub fn from_slice<T: NpyElement>(shape: &[usize], values: &[T]) -> Self {
        debug_assert_eq!(shape.iter().product::<usize>(), values.len());
        let mut data = Vec::with_capacity(values.len() * T::SIZE);
        for &value in values {
            value.extend_le(&mut data);
        }
        Self {
            dtype: DType::Scalar(T::DESCR.to_owned()),
            shape: shape.to_vec(),
            data,
        }
    }

    /// Reads an array from a `.npy` stream.
    pub fn read(reader: &mut impl Read) -> Result<Self, NpyError> {
        let header = read_header(reader)?;
        let item_size = header.dtype.item_size()?;
        let byte_len = header
            .shape
            .iter()
            .try_fold(item_size, |acc, &dim| acc.checked_mul(dim))
            .ok_or_else(|| NpyError::ShapeOverflow {
                shape: header.shape.clone(),
            })?;
        // Grow while reading instead of trusting the header's size for the allocation: a
        // corrupt header must not make us reserve terabytes.
        let mut data = Vec::new();
        reader.take(byte_len as u64).read_to_end(&mut data)?;
        if data.len() != byte_len {
            return Err(NpyError::Truncated {
                expected: byte_len,
                found: data.len(),
            });
        }
        Ok(Self {
            dtype: header.dtype,
            shape: header.shape,
            data,
        })
    }

    /// Writes the array as a version 1.0 `.npy` stream (2.0 when the header needs it).
    pub fn write(&self, writer: &mut impl Write) -> Result<(), NpyError> {
        let shape = match self.shape.as_slice() {
            [single] => format!("({single},)"),
            dims => format!(
                "({})",
                dims.iter()
                    .map(|d| d.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let descr = match &self.dtype {
            DType::Scalar(descr) => format!("'{descr}'"),
            DType::Object => "'|O'".to_owned(),
            record => record.to_string(),
        };
        let mut dict = format!("{{'descr': {descr}, 'fortran_order': False, 'shape': {shape}, }}");
        let (version, length_bytes) = if dict.len() + 1 + 10 < u16::MAX as usize {
            (1u8, 2usize)
        } else {
            (2u8, 4usize)
        };
        let preamble = MAGIC.len() + 2 + length_bytes;
        let padded = (preamble + dict.len() + 1).div_ceil(HEADER_ALIGNMENT) * HEADER_ALIGNMENT;
        dict.extend(std::iter::repeat_n(' ', padded - preamble - dict.len() - 1));
        dict.push('\n');
        writer.write_all(MAGIC)?;
        writer.write_all(&[version, 0])?;
        if version == 1 {
            writer.write_all(&(dict.len() as u16).to_le_bytes())?;
        } else {
            writer.write_all(&(dict.len() as u32).to_le_bytes())?;
        }
        writer.write_all(dict.as_bytes())?;
        writer.write_all(&self.data)?;
        Ok(())
    }
}

/// What a `.npy` header announces.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NpyHeader {
    pub dtype: DType,
    pub shape: Vec<usize>,
}

/// Reads the magic, version and header dictionary, leaving the reader at the first data byte.
pub fn read_header(reader: &mut impl Read) -> Result<NpyHeader, NpyError> {
    let mut magic = [0u8; 8];
    read_prefix(reader, &mut magic)?;
    if &magic[..6] != MAGIC {
        return Err(NpyError::BadMagic {
            found: magic[..6].to_vec(),
        });
    }
    let (major, minor) = (magic[6], magic[7]);
    let header_len = match (major, minor) {
        (1, 0) => {
            let mut len = [0u8; 2];
            read_prefix(reader, &mut len)?;
            u16::from_le_bytes(len) as usize
        }
        (2, 0) | (3, 0) => {
            let mut len = [0u8; 4];
            read_prefix(reader, &mut len)?;
            u32::from_le_bytes(len) as usize
        }
        _ => return Err(NpyError::UnsupportedVersion { major, minor }),
    };
    if header_len > MAX_HEADER_BYTES {
        return Err(NpyError::HeaderTooLarge {
            length: header_len,
            limit: MAX_HEADER_BYTES,
        });
    }
    let mut text = Vec::new();
    reader.take(header_len as u64).read_to_end(&mut text)?;
    if text.len() != header_len {
        return Err(NpyError::Truncated {
            expected: header_len,
            found: text.len(),
        });
    }
    let text = String::from_utf8_lossy(&text).into_owned();
    HeaderParser::new(&text).parse()
}

/// The pickle bytes of an object array (`np.save(..., allow_pickle=True)`), at most
/// `max_bytes` long. Unpickle them with [`crate::pickle::read_pickle`].
pub fn read_pickled_object(reader: &mut impl Read, max_bytes: u64) -> Result<Vec<u8>, NpyError> {
    let header = read_header(reader)?;
    if header.dtype != DType::Object {
        return Err(NpyError::DType {
            expected: "|O".into(),
            found: header.dtype.to_string(),
        });
    }
    let mut data = Vec::new();
    reader.take(max_bytes + 1).read_to_end(&mut data)?;
    if data.len() as u64 > max_bytes {
        return Err(NpyError::ObjectTooLarge { limit: max_bytes });
    }
    Ok(data)
}

fn read_prefix(reader: &mut impl Read, buf: &mut [u8]) -> Result<(), NpyError> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..])? {
            0 => {
                return Err(NpyError::Truncated {
                    expected: buf.len(),
                    found: filled,
                })
            }
            n => filled += n,
        }
    }
    Ok(())
}

/// The longest header read. NumPy refuses headers over 10 000 bytes by default (its
/// `max_header_size`); a record dtype of many fields is the only large one in practice.
const MAX_HEADER_BYTES: usize = 1 << 20;

/// The deepest nesting of tuples and lists in a header: a record dtype's fields are two levels
/// down, its sub-array shapes three; deeper is hostile (it once overflowed the stack).
const MAX_HEADER_DEPTH: usize = 8;

/// How much of a malformed header an error quotes.
const QUOTED_HEADER_CHARS: usize = 200;

/// A parser for the Python literal NumPy writes as the header: a dict with `descr`,
/// `fortran_order` and `shape`.
struct HeaderParser<'a> {
    text: &'a str,
    pos: usize,
}

enum Literal {
    Str(String),
    Bool(bool),
    Int(usize),
    Seq(Vec<Literal>),
}

impl<'a> HeaderParser<'a> {
    fn new(text: &'a str) -> Self {
        Self { text, pos: 0 }
    }

    fn fail(&self, problem: impl Into<String>) -> NpyError {
        NpyError::MalformedHeader {
            offset: self.pos,
            problem: problem.into(),
            header: quoted(self.text.trim_end()),
        }
    }

    fn skip_space(&mut self) {
        while let Some(c) = self.peek() {
            if c.is_whitespace() {
                self.pos += c.len_utf8();
            } else {
                break;
            }
        }
    }

    fn peek(&self) -> Option<char> {
        self.text[self.pos..].chars().next()
    }

    fn expect(&mut self, c: char) -> Result<(), NpyError> {
        self.skip_space();
        if self.peek() == Some(c) {
            self.pos += c.len_utf8();
            Ok(())
        } else {
            Err(self.fail(format!("expected `{c}`")))
        }
    }

    /// Consumes `c` if it is next.
    fn eat(&mut self, c: char) -> bool {
        self.skip_space();
        if self.peek() == Some(c) {
            self.pos += c.len_utf8();
            true
        } else {
            false
        }
    }

    fn parse(mut self) -> Result<NpyHeader, NpyError> {
        self.expect('{')?;
        let (mut descr, mut fortran, mut shape) = (None, None, None);
        while !self.eat('}') {
            let key = match self.literal(0)? {
                Literal::Str(key) => key,
                _ => return Err(self.fail("expected a string key")),
            };
            self.expect(':')?;
            let value = self.literal(0)?;
            match key.as_str() {
                "descr" => descr = Some(value),
                "fortran_order" => fortran = Some(value),
                "shape" => shape = Some(value),
                other => return Err(self.fail(format!("unknown key `{other}`"))),
            }
            if !self.eat(',') {
                self.expect('}')?;
                break;
            }
        }
        match fortran {
            Some(Literal::Bool(false)) => {}
            Some(Literal::Bool(true)) => return Err(NpyError::FortranOrder),
            _ => return Err(self.fail("`fortran_order` missing or not a boolean")),
        }
        let shape = match shape {
            Some(Literal::Seq(dims)) => dims
                .into_iter()
                .map(|d| match d {
                    Literal::Int(n) => Ok(n),
                    _ => Err(self.fail("`shape` holds a non-integer")),
                })
                .collect::<Result<Vec<_>, _>>()?,
            _ => return Err(self.fail("`shape` missing or not a tuple")),
        };
        let dtype = match descr {
            Some(Literal::Str(descr)) if descr == "|O" => DType::Object,
            Some(Literal::Str(descr)) => {
                scalar_size(&descr)?;
                DType::Scalar(descr)
            }
            Some(Literal::Seq(fields)) => self.record(fields)?,
            _ => return Err(self.fail("`descr` missing or neither a string nor a list")),
        };
        Ok(NpyHeader { dtype, shape })
    }

    fn record(&self, fields: Vec<Literal>) -> Result<DType, NpyError> {
        let mut offset = 0;
        let mut out = Vec::with_capacity(fields.len());
        for field in fields {
            let Literal::Seq(parts) = field else {
                return Err(self.fail("a record field is not a (name, dtype) tuple"));
            };
            match parts.as_slice() {
                [Literal::Str(name), Literal::Str(descr)] => {
                    let size = scalar_size(descr)?;
                    out.push(RecordField {
                        name: name.clone(),
                        descr: descr.clone(),
                        offset,
                        size,
                    });
                    offset += size;
                }
                _ => {
                    return Err(self.fail(
                        "a record field is not a (name, dtype) tuple of strings (sub-arrays are not supported)",
                    ))
                }
            }
        }
        Ok(DType::Record(out))
    }

    fn literal(&mut self, depth: usize) -> Result<Literal, NpyError> {
        self.skip_space();
        match self.peek() {
            Some(quote @ ('\'' | '"')) => {
                self.pos += 1;
                let end = self.text[self.pos..]
                    .find(quote)
                    .ok_or_else(|| self.fail("unterminated string"))?;
                let value = self.text[self.pos..self.pos + end].to_owned();
                self.pos += end + 1;
                Ok(Literal::Str(value))
            }
            Some(open @ ('(' | '[')) => {
                if depth >= MAX_HEADER_DEPTH {
                    return Err(self.fail(format!(
                        "tuples and lists nested deeper than {MAX_HEADER_DEPTH} levels"
                    )));
                }
                let close = if open == '(' { ')' } else { ']' };
                self.pos += 1;
                let mut items = Vec::new();
                while !self.eat(close) {
                    items.push(self.literal(depth + 1)?);
                    if !self.eat(',') {
                        self.expect(close)?;
                        break;
                    }
                }
                Ok(Literal::Seq(items))
            }
            Some(c) if c.is_ascii_digit() => {
                let len = self.text[self.pos..]
                    .find(|c: char| !c.is_ascii_digit())
                    .unwrap_or(self.text.len() - self.pos);
                let digits = &self.text[self.pos..self.pos + len];
                let value = digits
                    .parse()
                    .map_err(|_| self.fail(format!("integer `{digits}` is too large")))?;
                self.pos += len;
                // Python 2 era files may write `3L`.
                if self.peek() == Some('L') {
                    self.pos += 1;
                }
                Ok(Literal::Int(value))
            }
            _ => {
                for (word, value) in [("True", true), ("False", false)] {
                    if self.text[self.pos..].starts_with(word) {
                        self.pos += word.len();
                        return Ok(Literal::Bool(value));
                    }
                }
                Err(self.fail("expected a string, tuple, list, integer or boolean"))
            }
        }
    }
}

/// `text`, cut to its first [`QUOTED_HEADER_CHARS`] characters.
fn quoted(text: &str) -> String {
    match text.char_indices().nth(QUOTED_HEADER_CHARS) {
        Some((cut, _)) => format!("{}… ({} bytes in all)", &text[..cut], text.len()),
        None => text.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_array_round_trips() {
        let values: Vec<i64> = vec![-3, 0, 7, i64::MAX, 12, 5];
        let array = NpyArray::from_slice(&[3, 2], &values);
        let mut bytes = Vec::new();
        array.write(&mut bytes).unwrap();
        assert_eq!(bytes.len() % HEADER_ALIGNMENT, (6 * 8) % HEADER_ALIGNMENT);
        let back = NpyArray::read(&mut bytes.as_slice()).unwrap();
        assert_eq!(back.shape, vec![3, 2]);
        assert_eq!(back.to_vec::<i64>().unwrap(), values);
    }

    #[test]
    fn header_written_by_numpy_parses() {
        let text = "{'descr': [('t', '<i8'), ('x', '<i2'), ('y', '<i2'), ('p', '|u1'), ('', '|V3')], 'fortran_order': False, 'shape': (219596,), }        \n";
        let header = HeaderParser::new(text).parse().unwrap();
        assert_eq!(header.shape, vec![219596]);
        let DType::Record(fields) = header.dtype else {
            panic!("expected a record dtype");
        };
        let offsets: Vec<_> = fields.iter().map(|f| (f.name.as_str(), f.offset)).collect();
        assert_eq!(
            offsets,
            vec![("t", 0), ("x", 8), ("y", 10), ("p", 12), ("", 13)]
        );
    }

    #[test]
    fn zero_dimensional_and_empty_shapes_parse() {
        let header = HeaderParser::new("{'descr': '<f8', 'fortran_order': False, 'shape': (), }")
            .parse()
            .unwrap();
        assert!(header.shape.is_empty());
        let header =
            HeaderParser::new("{'descr': '|u1', 'fortran_order': False, 'shape': (0, 4), }")
                .parse()
                .unwrap();
        assert_eq!(header.shape, vec![0, 4]);
    }

    #[test]
    fn wrong_dtype_is_named() {
        let array = NpyArray::from_slice(&[2], &[1u16, 2]);
        let err = array.to_vec::<i64>().unwrap_err().to_string();
        assert!(err.contains("<u2") && err.contains("<i8"), "{err}");
    }

    fn version_two(header: &str) -> Vec<u8> {
        let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
        bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes
    }

    /// Issue 15: a header of 10^6 nested `[` overflowed the stack (`evgate info` aborted).
    #[test]
    fn deeply_nested_headers_are_errors_not_aborts() {
        let deep = format!("{{{}", "[".repeat(1_000_000));
        let error = NpyArray::read(&mut version_two(&deep).as_slice()).unwrap_err();
        let message = error.to_string();
        assert!(message.contains("nested deeper than 8"), "{message}");
        assert!(message.len() < 1_000, "the error quotes the whole header");
        // Eight levels still parse: a record dtype needs three.
        let nested = "{'descr': [('a', '<i8')], 'fortran_order': False, 'shape': (0,), }";
        assert!(HeaderParser::new(nested).parse().is_ok());
    }

    #[test]
    fn headers_past_the_limit_are_refused_before_reading() {
        let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
        bytes.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            NpyArray::read(&mut bytes.as_slice()),
            Err(NpyError::HeaderTooLarge { .. })
        ));
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(matches!(
            NpyArray::read(&mut &b"NOTNUMPY"[..]),
            Err(NpyError::BadMagic { .. })
        ));
        assert!(matches!(
            NpyArray::read(&mut &b"\x93NUM"[..]),
            Err(NpyError::Truncated { .. })
        ));
        let mut bytes = Vec::new();
        NpyArray::from_slice(&[4], &[1u32, 2, 3, 4])
            .write(&mut bytes)
            .unwrap();
        bytes.truncate(bytes.len() - 3);
        assert!(matches!(
            NpyArray::read(&mut bytes.as_slice()),
            Err(NpyError::Truncated { .. })
        ));
        let fortran = b"{'descr': '<f8', 'fortran_order': True, 'shape': (2,), }";
        assert!(matches!(
            HeaderParser::new(std::str::from_utf8(fortran).unwrap()).parse(),
            Err(NpyError::FortranOrder)
        ));
        let big_endian = "{'descr': '>i8', 'fortran_order': False, 'shape': (2,), }";
        assert!(matches!(
            HeaderParser::new(big_endian).parse(),
            Err(NpyError::UnsupportedDType(_))
        ));
        let garbage = "{'descr': '<i8', 'fortran_order': False, 'shape': (2,, }";
        assert!(matches!(
            HeaderParser::new(garbage).parse(),
            Err(NpyError::MalformedHeader { .. })
        ));
    }
}
