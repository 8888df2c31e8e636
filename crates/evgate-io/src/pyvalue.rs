//! Python values as EVIMO stores its metadata: `meta.txt` is a Python literal (read by `eval`
//! in EVIMO's own tools) and the `meta` array of the `.npz` layouts is a pickle of the same
//! dict. Both are turned into a [`PyValue`] tree; [`parse_literal`] reads the literal form.

/// A Python value. Objects this reader does not model (NumPy arrays, class instances) keep
/// their class name, constructor arguments and state so callers can still look inside.
#[derive(Clone, Debug, PartialEq)]
pub enum PyValue {
    None,
    Bool(bool),
    /// EVIMO writes frame ids up to 2^64 − 1, beyond `i64`.
    Int(i128),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    List(Vec<PyValue>),
    Tuple(Vec<PyValue>),
    /// Keys in insertion order.
    Dict(Vec<(PyValue, PyValue)>),
    Object {
        class: String,
        args: Vec<PyValue>,
        state: Option<Box<PyValue>>,
    },
}

#[derive(Debug, thiserror::Error)]
#[error("python literal at byte {offset}: {problem} (near {context:?})")]
pub struct LiteralError {
    pub offset: usize,
    pub problem: String,
    pub context: String,
}

impl PyValue {
    /// The value of a string key of a dict.
    pub fn get(&self, key: &str) -> Option<&PyValue> {
        match self {
            PyValue::Dict(items) => items
                .iter()
                .find(|(k, _)| matches!(k, PyValue::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            PyValue::Str(s) => Some(s),
            _ => None,
        }
    }

    pub fn as_list(&self) -> Option<&[PyValue]> {
        match self {
            PyValue::List(items) | PyValue::Tuple(items) => Some(items),
            _ => None,
        }
    }

    /// A number as f64: Python ints and floats, and NumPy scalars (`numpy.float64` and
    /// friends pickle as `scalar(dtype, raw bytes)`).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            PyValue::Int(i) => Some(*i as f64),
            PyValue::Float(f) => Some(*f),
            PyValue::Object { class, args, .. } if class.ends_with(".scalar") => {
                let descr = args.first()?.numpy_dtype_name()?;
                let PyValue::Bytes(raw) = args.get(1)? else {
                    return None;
                };
                match (descr.as_str(), raw.len()) {
                    ("f8", 8) => Some(f64::from_le_bytes(raw[..8].try_into().ok()?)),
                    ("f4", 4) => Some(f32::from_le_bytes(raw[..4].try_into().ok()?) as f64),
                    ("i8", 8) => Some(i64::from_le_bytes(raw[..8].try_into().ok()?) as f64),
                    ("u8", 8) => Some(u64::from_le_bytes(raw[..8].try_into().ok()?) as f64),
                    ("i4", 4) => Some(i32::from_le_bytes(raw[..4].try_into().ok()?) as f64),
                    _ => None,
                }
            }
            _ => None,
        }
    }

    /// `f8` for a pickled `numpy.dtype('f8', ...)`.
    fn numpy_dtype_name(&self) -> Option<String> {
        match self {
            PyValue::Object { class, args, .. } if class.ends_with(".dtype") => {
                args.first()?.as_str().map(str::to_owned)
            }
            _ => None,
        }
    }

    /// The first dict (depth first) that has the string key `key`: finds EVIMO's metadata dict
    /// inside the pickled 0-d object array that wraps it, whatever NumPy version wrote it.
    pub fn find_dict_with_key(&self, key: &str) -> Option<&PyValue> {
        self.find_dict_with_key_at_depth(key, 0)
    }

    fn find_dict_with_key_at_depth(&self, key: &str, depth: usize) -> Option<&PyValue> {
        // The metadata sits a few levels down; a bound keeps hostile nesting from recursing
        // without end.
        if depth > 16 {
            return None;
        }
        if self.get(key).is_some() {
            return Some(self);
        }
        let children: Box<dyn Iterator<Item = &PyValue>> = match self {
            PyValue::List(items) | PyValue::Tuple(items) => Box::new(items.iter()),
            PyValue::Dict(items) => Box::new(items.iter().map(|(_, v)| v)),
            PyValue::Object { args, state, .. } => {
                Box::new(args.iter().chain(state.iter().map(|s| s.as_ref())))
            }
            _ => return None,
        };
        children
            .into_iter()
            .find_map(|child| child.find_dict_with_key_at_depth(key, depth + 1))
    }
}

/// Parses one Python literal: dicts, lists, tuples, strings, numbers, `True`, `False`,
/// `None`, `nan`/`inf` (as C++ prints them).
pub fn parse_literal(text: &str) -> Result<PyValue, LiteralError> {
    let mut parser = LiteralParser { text, pos: 0 };
    let value = parser.value(0)?;
    parser.skip_space();
    if parser.pos != text.len() {
        return Err(parser.fail("unexpected text after the value"));
    }
    Ok(value)
}

struct LiteralParser<'a> {
    text: &'a str,
    pos: usize,
}

/// Nesting deeper than this is not EVIMO metadata.
const MAX_DEPTH: usize = 64;

impl LiteralParser<'_> {
    fn fail(&self, problem: impl Into<String>) -> LiteralError {
        let end = (self.pos + 40).min(self.text.len());
        let start = self.pos.min(end);
        LiteralError {
            offset: self.pos,
            problem: problem.into(),
            context: self
                .text
                .get(start..end)
                .unwrap_or_default()
                .chars()
                .collect(),
        }
    }

    fn peek(&self) -> Option<u8> {
        self.text.as_bytes().get(self.pos).copied()
    }

    fn skip_space(&mut self) {
        while matches!(self.peek(), Some(b' ' | b'\t' | b'\n' | b'\r')) {
            self.pos += 1;
        }
    }

    fn eat(&mut self, c: u8) -> bool {
        self.skip_space();
        if self.peek() == Some(c) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn value(&mut self, depth: usize) -> Result<PyValue, LiteralError> {
        if depth > MAX_DEPTH {
            return Err(self.fail(format!("nested deeper than {MAX_DEPTH} levels")));
        }
        self.skip_space();
        match self.peek() {
            Some(b'{') => {
                self.pos += 1;
                let mut items = Vec::new();
                while !self.eat(b'}') {
                    let key = self.value(depth + 1)?;
                    if !self.eat(b':') {
                        return Err(self.fail("expected `:` after a dict key"));
                    }
                    let value = self.value(depth + 1)?;
                    items.push((key, value));
                    if !self.eat(b',') {
                        if self.eat(b'}') {
                            break;
                        }
                        return Err(self.fail("expected `,` or `}` in a dict"));
                    }
                }
                Ok(PyValue::Dict(items))
            }
            Some(open @ (b'[' | b'(')) => {
                let close = if open == b'[' { b']' } else { b')' };
                self.pos += 1;
                let mut items = Vec::new();
                while !self.eat(close) {
                    items.push(self.value(depth + 1)?);
                    if !self.eat(b',') {
                        if self.eat(close) {
                            break;
                        }
                        return Err(self.fail(format!("expected `,` or `{}`", close as char)));
                    }
                }
                Ok(if open == b'[' {
                    PyValue::List(items)
                } else {
                    PyValue::Tuple(items)
                })
            }
            Some(quote @ (b'\'' | b'"')) => self.string(quote),
            Some(c) if c == b'-' || c == b'+' || c == b'.' || c.is_ascii_digit() => self.number(),
            Some(_) => {
                for (word, value) in [
                    ("True", PyValue::Bool(true)),
                    ("False", PyValue::Bool(false)),
                    ("None", PyValue::None),
                    ("nan", PyValue::Float(f64::NAN)),
                    ("inf", PyValue::Float(f64::INFINITY)),
                ] {
                    if self.text[self.pos..].starts_with(word) {
                        self.pos += word.len();
                        return Ok(value);
                    }
                }
                Err(self.fail("expected a dict, list, tuple, string, number, True, False or None"))
            }
            None => Err(self.fail("the text ends where a value was expected")),
        }
    }

    fn string(&mut self, quote: u8) -> Result<PyValue, LiteralError> {
        let start = self.pos;
        self.pos += 1;
        let mut out = String::new();
        loop {
            let Some(c) = self.text[self.pos..].chars().next() else {
                self.pos = start;
                return Err(self.fail("unterminated string"));
            };
            self.pos += c.len_utf8();
            match c {
                c if c as u32 == quote as u32 => return Ok(PyValue::Str(out)),
                '\\' => {
                    let Some(escaped) = self.text[self.pos..].chars().next() else {
                        return Err(self.fail("unterminated escape"));
                    };
                    self.pos += escaped.len_utf8();
                    out.push(match escaped {
                        'n' => '\n',
                        't' => '\t',
                        'r' => '\r',
                        '0' => '\0',
                        other => other,
                    });
                }
                other => out.push(other),
            }
        }
    }

    fn number(&mut self) -> Result<PyValue, LiteralError> {
        let start = self.pos;
        let len = self.text[start..]
            .find(|c: char| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '+' | '.')))
            .unwrap_or(self.text.len() - start);
        let word = &self.text[start..start + len];
        let value = if let Ok(int) = word.parse::<i128>() {
            PyValue::Int(int)
        } else if let Ok(float) = word.parse::<f64>() {
            PyValue::Float(float)
        } else {
            return Err(self.fail(format!("`{word}` is not a number")));
        };
        self.pos += len;
        Ok(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evimo_meta_text_parses() {
        let text = "{\n'meta': {'fx': 519.299927, 'res_x': 640, 'res_y': 480, 'dist_model': 'radtan'}\n, 'frames': [\n{\n'id': 18446744073709551615,\t\t'ts': 5.446962,\n'cam': {'pos': {'t': {'x': -0.5}}, 'ts': 5.446962},\n'gt_frame': 'depth_mask_3.png'\n},\n], 'flag': (True, None, -1e-3, nan)}";
        let value = parse_literal(text).unwrap();
        assert_eq!(
            value
                .get("meta")
                .and_then(|m| m.get("res_x"))
                .and_then(PyValue::as_f64),
            Some(640.0)
        );
        let frames = value.get("frames").and_then(PyValue::as_list).unwrap();
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].get("id"), Some(&PyValue::Int(u64::MAX as i128)));
        assert_eq!(
            frames[0].get("ts").and_then(PyValue::as_f64),
            Some(5.446962)
        );
        assert_eq!(
            frames[0].get("gt_frame").and_then(PyValue::as_str),
            Some("depth_mask_3.png")
        );
        assert_eq!(
            value.find_dict_with_key("res_y"),
            value.get("meta"),
            "the nested dict is found"
        );
    }

    #[test]
    fn malformed_literals_name_the_offset() {
        let err = parse_literal("{'a': 1, 'b' 2}").unwrap_err();
        assert_eq!(err.offset, 13, "{err}");
        assert!(err.to_string().contains("expected `:`"), "{err}");
        let err = parse_literal("{'a': 'open").unwrap_err().to_string();
        assert!(err.contains("unterminated string"), "{err}");
        let err = parse_literal("[1, 2] tail").unwrap_err().to_string();
        assert!(err.contains("after the value"), "{err}");
        let err = parse_literal(&"[".repeat(100)).unwrap_err().to_string();
        assert!(err.contains("nested deeper"), "{err}");
    }
}
