//! Counts a network's parameters from its ONNX file: the elements of the graph's initializers
//! (for the exported networks exactly PyTorch's parameter count). Read with a minimal protobuf
//! walk (ModelProto.graph = 7, GraphProto.initializer = 5, TensorProto.dims = 1), so the
//! count describes the file evaluated rather than a table of another export.

use std::path::{Path, PathBuf};

use thiserror::Error;

#[derive(Debug, Error)]
pub enum OnnxParametersError {
    #[error("cannot read model {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("model {path}: byte {offset}: {problem} (not a valid ONNX protobuf)")]
    Malformed {
        path: PathBuf,
        offset: usize,
        problem: &'static str,
    },
    #[error("model {path}: no graph (ModelProto field 7)")]
    NoGraph { path: PathBuf },
}

const MODEL_GRAPH: u64 = 7;
const GRAPH_INITIALIZER: u64 = 5;
const TENSOR_DIMS: u64 = 1;

/// A protobuf field: its number and either a varint / fixed value or a length-delimited body.
enum Value<'a> {
    Scalar(u64),
    Bytes(&'a [u8], usize),
}

/// Walks the fields of one message body starting at file offset `base`.
struct Fields<'a> {
    bytes: &'a [u8],
    position: usize,
    base: usize,
}

type Malformed = (usize, &'static str);

impl<'a> Fields<'a> {
    fn new(bytes: &'a [u8], base: usize) -> Self {
        Self {
            bytes,
            position: 0,
            base,
        }
    }

    fn varint(&mut self) -> Result<u64, Malformed> {
        let mut value = 0u64;
        for shift in (0..64).step_by(7) {
            let byte = *self
                .bytes
                .get(self.position)
                .ok_or((self.base + self.position, "truncated varint"))?;
            self.position += 1;
            value |= u64::from(byte & 0x7f) << shift;
            if byte & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err((self.base + self.position, "varint longer than 10 bytes"))
    }

    fn take(&mut self, length: usize) -> Result<(&'a [u8], usize), Malformed> {
        let start = self.position;
        let end = start
            .checked_add(length)
            .filter(|&end| end <= self.bytes.len())
            .ok_or((self.base + start, "field runs past the end of its message"))?;
        self.position = end;
        Ok((&self.bytes[start..end], self.base + start))
    }

    fn next_field(&mut self) -> Option<Result<(u64, Value<'a>), Malformed>> {
        (self.position < self.bytes.len()).then(|| {
            let key = self.varint()?;
            let value = match key & 7 {
                0 => Value::Scalar(self.varint()?),
                1 => Value::Scalar(u64::from_le_bytes(
                    self.take(8)?.0.try_into().expect("8 bytes"),
                )),
                2 => {
                    let length = usize::try_from(self.varint()?)
                        .map_err(|_| (self.base + self.position, "length beyond memory"))?;
                    let (body, offset) = self.take(length)?;
                    Value::Bytes(body, offset)
                }
                5 => Value::Scalar(u64::from(u32::from_le_bytes(
                    self.take(4)?.0.try_into().expect("4 bytes"),
                ))),
                _ => return Err((self.base + self.position, "unsupported wire type")),
            };
            Ok((key >> 3, value))
        })
    }
}

/// Elements of one TensorProto: the product of its dims (packed or not).
fn tensor_elements(body: &[u8], base: usize) -> Result<u64, Malformed> {
    let mut dims = Vec::new();
    let mut fields = Fields::new(body, base);
    while let Some(field) = fields.next_field() {
        match field? {
            (TENSOR_DIMS, Value::Scalar(dim)) => dims.push(dim),
            (TENSOR_DIMS, Value::Bytes(packed, offset)) => {
                let mut packed = Fields::new(packed, offset);
                while packed.position < packed.bytes.len() {
                    dims.push(packed.varint()?);
                }
            }
            _ => {}
        }
    }
    Ok(dims.iter().product())
}

/// Sum of the initializer elements of an ONNX model held in memory.
pub fn count_parameters(bytes: &[u8]) -> Result<Option<u64>, Malformed> {
    let mut model = Fields::new(bytes, 0);
    let mut total = None;
    while let Some(field) = model.next_field() {
        if let (MODEL_GRAPH, Value::Bytes(graph, offset)) = field? {
            let mut sum = 0u64;
            let mut graph = Fields::new(graph, offset);
            while let Some(field) = graph.next_field() {
                if let (GRAPH_INITIALIZER, Value::Bytes(tensor, offset)) = field? {
                    sum += tensor_elements(tensor, offset)?;
                }
            }
            total = Some(sum);
        }
    }
    Ok(total)
}

/// The parameter count of the ONNX file at `path`.
pub fn onnx_parameters(path: &Path) -> Result<u64, OnnxParametersError> {
    let bytes = std::fs::read(path).map_err(|source| OnnxParametersError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    count_parameters(&bytes)
        .map_err(|(offset, problem)| OnnxParametersError::Malformed {
            path: path.to_path_buf(),
            offset,
            problem,
        })?
        .ok_or_else(|| OnnxParametersError::NoGraph {
            path: path.to_path_buf(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn varint(mut value: u64, out: &mut Vec<u8>) {
        loop {
            let byte = (value & 0x7f) as u8;
            value >>= 7;
            if value == 0 {
                out.push(byte);
                return;
            }
            out.push(byte | 0x80);
        }
    }

    fn message(field: u64, body: &[u8], out: &mut Vec<u8>) {
        varint(field << 3 | 2, out);
        varint(body.len() as u64, out);
        out.extend_from_slice(body);
    }

    /// A TensorProto with `dims` (packed or one varint field each), a data type and raw data.
    fn tensor(dims: &[u64], packed: bool) -> Vec<u8> {
        let mut out = Vec::new();
        if packed {
            let mut body = Vec::new();
            dims.iter().for_each(|&d| varint(d, &mut body));
            message(TENSOR_DIMS, &body, &mut out);
        } else {
            for &d in dims {
                varint(TENSOR_DIMS << 3, &mut out);
                varint(d, &mut out);
            }
        }
        varint(2 << 3, &mut out); // data_type = FLOAT
        varint(1, &mut out);
        message(
            9,
            &vec![0u8; 4 * dims.iter().product::<u64>() as usize],
            &mut out,
        );
        out
    }

    fn model(tensors: &[Vec<u8>]) -> Vec<u8> {
        let mut graph = Vec::new();
        message(1, b"node", &mut graph); // a node before the initializers
        for t in tensors {
            message(GRAPH_INITIALIZER, t, &mut graph);
        }
        let mut out = Vec::new();
        varint(1 << 3, &mut out); // ir_version
        varint(8, &mut out);
        message(MODEL_GRAPH, &graph, &mut out);
        // metadata_props after the graph, with a fixed64 inside another message.
        message(14, &[0x09, 1, 2, 3, 4, 5, 6, 7, 8], &mut out);
        out
    }

    #[test]
    fn counts_the_elements_of_every_initializer() {
        let bytes = model(&[
            tensor(&[16, 2, 3, 3], true),
            tensor(&[16], false),
            tensor(&[], true),
        ]);
        // 288 weights, 16 biases and a scalar (no dims: one element).
        assert_eq!(count_parameters(&bytes), Ok(Some(288 + 16 + 1)));
    }

    #[test]
    fn truncated_files_name_the_offset() {
        let bytes = model(&[tensor(&[4, 4], true)]);
        let cut = &bytes[..bytes.len() - 12];
        let (offset, problem) = count_parameters(cut).unwrap_err();
        assert_eq!(problem, "field runs past the end of its message");
        assert!(offset < cut.len());
        assert_eq!(count_parameters(&[]), Ok(None));
    }
}
