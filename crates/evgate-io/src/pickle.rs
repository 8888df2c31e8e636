//! A reader for the pickles NumPy stores in object arrays (`np.savez(..., meta=dict)`), enough
//! to get EVIMO's metadata dict out of `dataset_info.npz` / `dataset.npz`.
//!
//! Nothing is executed: `GLOBAL`, `REDUCE`, `NEWOBJ` and `BUILD` only record the class name,
//! the arguments and the state as a [`PyValue::Object`]. Values live in an arena addressed by
//! index so that the memo and later `SETITEMS` / `APPENDS` act on the same container, as in
//! Python.

use std::collections::HashMap;

use crate::pyvalue::PyValue;

#[derive(Debug, thiserror::Error)]
#[error("pickle at byte {offset}: {problem}")]
pub struct PickleError {
    pub offset: usize,
    pub problem: String,
}

enum Node {
    Leaf(PyValue),
    List(Vec<usize>),
    Tuple(Vec<usize>),
    Dict(Vec<(usize, usize)>),
    Global(String),
    Object {
        class: usize,
        args: usize,
        state: Option<usize>,
    },
}

#[derive(Clone, Copy)]
enum Slot {
    Mark,
    Value(usize),
}

/// Decodes one pickle (protocols 2 to 5, the binary opcodes Python 3 writes).
pub fn read_pickle(bytes: &[u8]) -> Result<PyValue, PickleError> {
    let mut machine = Machine {
        bytes,
        pos: 0,
        nodes: Vec::new(),
        stack: Vec::new(),
        memo: HashMap::new(),
    };
    let root = machine.run()?;
    // Shared references (memo) make a graph that is expanded into a tree: a budget stops a
    // small hostile pickle from expanding exponentially.
    let budget = std::cell::Cell::new(machine.nodes.len().saturating_mul(16).max(1 << 20));
    machine.to_value(root, 0, &budget)
}

struct Machine<'a> {
    bytes: &'a [u8],
    pos: usize,
    nodes: Vec<Node>,
    stack: Vec<Slot>,
    memo: HashMap<u64, usize>,
}

/// Deeper nesting than this is not metadata (and would exhaust the stack when converted).
const MAX_DEPTH: usize = 128;

impl Machine<'_> {
    fn fail(&self, offset: usize, problem: impl Into<String>) -> PickleError {
        PickleError {
            offset,
            problem: problem.into(),
        }
    }

    fn take(&mut self, n: usize) -> Result<&[u8], PickleError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&end| end <= self.bytes.len())
            .ok_or_else(|| {
                self.fail(
                    self.pos,
                    format!(
                        "truncated: {n} bytes needed, {} left",
                        self.bytes.len() - self.pos
                    ),
                )
            })?;
        let out = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(out)
    }

    fn uint(&mut self, n: usize) -> Result<u64, PickleError> {
        let raw = self.take(n)?;
        let mut le = [0u8; 8];
        le[..n].copy_from_slice(raw);
        Ok(u64::from_le_bytes(le))
    }

    fn line(&mut self) -> Result<String, PickleError> {
        let start = self.pos;
        let end = self.bytes[start..]
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| self.fail(start, "unterminated text line"))?;
        self.pos = start + end + 1;
        Ok(String::from_utf8_lossy(&self.bytes[start..start + end]).into_owned())
    }

    fn push(&mut self, node: Node) {
        self.nodes.push(node);
        self.stack.push(Slot::Value(self.nodes.len() - 1));
    }

    fn pop(&mut self, at: usize) -> Result<usize, PickleError> {
        match self.stack.pop() {
            Some(Slot::Value(index)) => Ok(index),
            Some(Slot::Mark) => Err(self.fail(at, "a value was expected, found a mark")),
            None => Err(self.fail(at, "the stack is empty")),
        }
    }

    fn top(&self, at: usize) -> Result<usize, PickleError> {
        match self.stack.last() {
            Some(Slot::Value(index)) => Ok(*index),
            _ => Err(self.fail(at, "a value was expected on the stack")),
        }
    }

    /// Pops everything down to the last mark.
    fn pop_to_mark(&mut self, at: usize) -> Result<Vec<usize>, PickleError> {
        let mark = self
            .stack
            .iter()
            .rposition(|slot| matches!(slot, Slot::Mark))
            .ok_or_else(|| self.fail(at, "no mark on the stack"))?;
        let items = self.stack.split_off(mark + 1);
        self.stack.pop();
        Ok(items
            .into_iter()
            .map(|slot| match slot {
                Slot::Value(index) => index,
                Slot::Mark => unreachable!("marks above the last mark were excluded"),
            })
            .collect())
    }

    fn string(&mut self, len: u64, at: usize) -> Result<Node, PickleError> {
        let len = usize::try_from(len).map_err(|_| self.fail(at, "string length overflows"))?;
        let raw = self.take(len)?;
        let text = std::str::from_utf8(raw)
            .map(str::to_owned)
            .map_err(|_| PickleError {
                offset: at,
                problem: "a unicode string is not valid UTF-8".into(),
            })?;
        Ok(Node::Leaf(PyValue::Str(text)))
    }

    fn bytes(&mut self, len: u64, at: usize) -> Result<Node, PickleError> {
        let len = usize::try_from(len).map_err(|_| self.fail(at, "bytes length overflows"))?;
        Ok(Node::Leaf(PyValue::Bytes(self.take(len)?.to_vec())))
    }

    fn extend(&mut self, target: usize, items: Vec<usize>, at: usize) -> Result<(), PickleError> {
        match &mut self.nodes[target] {
            Node::List(list) => {
                list.extend(items);
                Ok(())
            }
            _ => Err(self.fail(at, "APPEND(S)/ADDITEMS on something that is not a list")),
        }
    }

    fn set_items(
        &mut self,
        target: usize,
        items: Vec<usize>,
        at: usize,
    ) -> Result<(), PickleError> {
        if !items.len().is_multiple_of(2) {
            return Err(self.fail(at, "SETITEMS with an odd number of keys and values"));
        }
        match &mut self.nodes[target] {
            Node::Dict(dict) => {
                dict.extend(items.chunks_exact(2).map(|kv| (kv[0], kv[1])));
                Ok(())
            }
            _ => Err(self.fail(at, "SETITEM(S) on something that is not a dict")),
        }
    }

    fn run(&mut self) -> Result<usize, PickleError> {
        loop {
            let at = self.pos;
            let opcode = self.take(1)?[0];
            match opcode {
                0x80 => {
                    let protocol = self.take(1)?[0];
                    if protocol > 5 {
                        return Err(self.fail(at, format!("protocol {protocol} (accepted: 2 to 5)")));
                    }
                }
                0x95 => {
                    self.take(8)?;
                }
                b'.' => return self.pop(at),
                b'(' => self.stack.push(Slot::Mark),
                b'N' => self.push(Node::Leaf(PyValue::None)),
                0x88 => self.push(Node::Leaf(PyValue::Bool(true))),
                0x89 => self.push(Node::Leaf(PyValue::Bool(false))),
                b'J' => {
                    let v = self.uint(4)? as u32 as i32;
                    self.push(Node::Leaf(PyValue::Int(v as i128)));
                }
                b'K' => {
                    let v = self.uint(1)?;
                    self.push(Node::Leaf(PyValue::Int(v as i128)));
                }
                b'M' => {
                    let v = self.uint(2)?;
                    self.push(Node::Leaf(PyValue::Int(v as i128)));
                }
                0x8a | 0x8b => {
                    let len = if opcode == 0x8a {
                        self.uint(1)?
                    } else {
                        self.uint(4)?
                    } as usize;
                    if len > 16 {
                        return Err(self.fail(at, format!("a {len}-byte integer (at most 16 supported)")));
                    }
                    let raw = self.take(len)?;
                    let negative = raw.last().is_some_and(|&b| b & 0x80 != 0);
                    let mut le = [if negative { 0xff } else { 0 }; 16];
                    le[..len].copy_from_slice(raw);
                    self.push(Node::Leaf(PyValue::Int(i128::from_le_bytes(le))));
                }
                b'G' => {
                    let raw: [u8; 8] = self.take(8)?.try_into().expect("8 bytes");
                    self.push(Node::Leaf(PyValue::Float(f64::from_be_bytes(raw))));
                }
                0x8c => {
                    let len = self.uint(1)?;
                    let node = self.string(len, at)?;
                    self.push(node);
                }
                b'X' => {
                    let len = self.uint(4)?;
                    let node = self.string(len, at)?;
                    self.push(node);
                }
                0x8d => {
                    let len = self.uint(8)?;
                    let node = self.string(len, at)?;
                    self.push(node);
                }
                b'C' | b'U' => {
                    let len = self.uint(1)?;
                    let node = self.bytes(len, at)?;
                    self.push(node);
                }
                b'B' | b'T' => {
                    let len = self.uint(4)?;
                    let node = self.bytes(len, at)?;
                    self.push(node);
                }
                0x8e => {
                    let len = self.uint(8)?;
                    let node = self.bytes(len, at)?;
                    self.push(node);
                }
                b')' => self.push(Node::Tuple(Vec::new())),
                0x85..=0x87 => {
                    let n = (opcode - 0x84) as usize;
                    let mut items = Vec::with_capacity(n);
                    for _ in 0..n {
                        items.push(self.pop(at)?);
                    }
                    items.reverse();
                    self.push(Node::Tuple(items));
                }
                b't' => {
                    let items = self.pop_to_mark(at)?;
                    self.push(Node::Tuple(items));
                }
                b']' | 0x8f => self.push(Node::List(Vec::new())),
                b'l' | 0x91 => {
                    let items = self.pop_to_mark(at)?;
                    self.push(Node::List(items));
                }
                b'a' => {
                    let item = self.pop(at)?;
                    let list = self.top(at)?;
                    self.extend(list, vec![item], at)?;
                }
                b'e' | 0x90 => {
                    let items = self.pop_to_mark(at)?;
                    let list = self.top(at)?;
                    self.extend(list, items, at)?;
                }
                b'}' => self.push(Node::Dict(Vec::new())),
                b'd' => {
                    let items = self.pop_to_mark(at)?;
                    self.push(Node::Dict(Vec::new()));
                    let dict = self.top(at)?;
                    self.set_items(dict, items, at)?;
                }
                b's' => {
                    let value = self.pop(at)?;
                    let key = self.pop(at)?;
                    let dict = self.top(at)?;
                    self.set_items(dict, vec![key, value], at)?;
                }
                b'u' => {
                    let items = self.pop_to_mark(at)?;
                    let dict = self.top(at)?;
                    self.set_items(dict, items, at)?;
                }
                b'c' => {
                    let module = self.line()?;
                    let name = self.line()?;
                    self.push(Node::Global(format!("{module}.{name}")));
                }
                0x93 => {
                    let name = self.pop(at)?;
                    let module = self.pop(at)?;
                    let text = |machine: &Self, index: usize| match &machine.nodes[index] {
                        Node::Leaf(PyValue::Str(s)) => Ok(s.clone()),
                        _ => Err(machine.fail(at, "STACK_GLOBAL needs two strings")),
                    };
                    let global = format!("{}.{}", text(self, module)?, text(self, name)?);
                    self.push(Node::Global(global));
                }
                b'R' | 0x81 => {
                    let args = self.pop(at)?;
                    let class = self.pop(at)?;
                    self.push(Node::Object {
                        class,
                        args,
                        state: None,
                    });
                }
                b'b' => {
                    let new_state = self.pop(at)?;
                    let target = self.top(at)?;
                    match &mut self.nodes[target] {
                        Node::Object { state, .. } => *state = Some(new_state),
                        _ => return Err(self.fail(at, "BUILD on something that is not an object")),
                    }
                }
                b'q' | b'r' | 0x94 => {
                    let key = match opcode {
                        b'q' => self.uint(1)?,
                        b'r' => self.uint(4)?,
                        _ => self.memo.len() as u64,
                    };
                    let value = self.top(at)?;
                    self.memo.insert(key, value);
                }
                b'h' | b'j' => {
                    let key = if opcode == b'h' {
                        self.uint(1)?
                    } else {
                        self.uint(4)?
                    };
                    let value = *self
                        .memo
                        .get(&key)
                        .ok_or_else(|| self.fail(at, format!("memo entry {key} was never stored")))?;
                    self.stack.push(Slot::Value(value));
                }
                other => {
                    return Err(self.fail(
                        at,
                        format!("opcode 0x{other:02x} is not supported (only the binary opcodes of protocols 2 to 5 that build plain data)"),
                    ))
                }
            }
        }
    }

    fn to_value(
        &self,
        index: usize,
        depth: usize,
        budget: &std::cell::Cell<usize>,
    ) -> Result<PyValue, PickleError> {
        if depth > MAX_DEPTH {
            return Err(self.fail(
                self.pos,
                format!("values nested deeper than {MAX_DEPTH} levels (or a cycle)"),
            ));
        }
        if budget.get() == 0 {
            return Err(self.fail(
                self.pos,
                "shared references expand to too many values (more than 16 per pickled value)",
            ));
        }
        budget.set(budget.get() - 1);
        let convert = |i: usize| self.to_value(i, depth + 1, budget);
        Ok(match &self.nodes[index] {
            Node::Leaf(value) => value.clone(),
            Node::List(items) => PyValue::List(
                items
                    .iter()
                    .map(|&i| convert(i))
                    .collect::<Result<_, _>>()?,
            ),
            Node::Tuple(items) => PyValue::Tuple(
                items
                    .iter()
                    .map(|&i| convert(i))
                    .collect::<Result<_, _>>()?,
            ),
            Node::Dict(items) => PyValue::Dict(
                items
                    .iter()
                    .map(|&(k, v)| Ok((convert(k)?, convert(v)?)))
                    .collect::<Result<_, PickleError>>()?,
            ),
            Node::Global(name) => PyValue::Object {
                class: name.clone(),
                args: Vec::new(),
                state: None,
            },
            Node::Object { class, args, state } => {
                let class = match &self.nodes[*class] {
                    Node::Global(name) => name.clone(),
                    _ => "<callable>".to_owned(),
                };
                let args = match convert(*args)? {
                    PyValue::Tuple(items) => items,
                    other => vec![other],
                };
                PyValue::Object {
                    class,
                    args,
                    state: match state {
                        Some(s) => Some(Box::new(convert(*s)?)),
                        None => None,
                    },
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pickle.dumps({'frames': [{'ts': 0.5, 'gt_frame': 'depth_mask_0.png', 'id': 0}], 'meta': {'res_x': 346}}, protocol=3)`
    /// written out opcode by opcode.
    fn sample() -> Vec<u8> {
        let mut p = vec![0x80, 3, b'}', b'q', 0, b'('];
        let text = |p: &mut Vec<u8>, s: &str| {
            p.push(b'X');
            p.extend_from_slice(&(s.len() as u32).to_le_bytes());
            p.extend_from_slice(s.as_bytes());
        };
        text(&mut p, "frames");
        p.extend_from_slice(&[b']', b'q', 1, b'}', b'q', 2, b'(']);
        text(&mut p, "ts");
        p.push(b'G');
        p.extend_from_slice(&0.5f64.to_be_bytes());
        text(&mut p, "gt_frame");
        text(&mut p, "depth_mask_0.png");
        text(&mut p, "id");
        p.extend_from_slice(&[b'K', 0, b'u', b'a']);
        text(&mut p, "meta");
        p.extend_from_slice(b"}(");
        text(&mut p, "res_x");
        p.extend_from_slice(&[b'M', 0x5a, 0x01, b'u', b'u', b'.']);
        p
    }

    #[test]
    fn a_metadata_dict_is_read() {
        let value = read_pickle(&sample()).unwrap();
        let frames = value.get("frames").and_then(PyValue::as_list).unwrap();
        assert_eq!(frames[0].get("ts").and_then(PyValue::as_f64), Some(0.5));
        assert_eq!(
            frames[0].get("gt_frame").and_then(PyValue::as_str),
            Some("depth_mask_0.png")
        );
        assert_eq!(
            value
                .get("meta")
                .and_then(|m| m.get("res_x"))
                .and_then(PyValue::as_f64),
            Some(346.0)
        );
    }

    #[test]
    fn numpy_object_array_wrapping_is_looked_through() {
        // np.array(dict) pickles as _reconstruct(ndarray, (0,), b'b') + BUILD((1, (), dtype, False, [dict])).
        let mut p = vec![0x80, 2, b'c'];
        p.extend_from_slice(b"numpy.core.multiarray\n_reconstruct\n");
        p.push(b'c');
        p.extend_from_slice(b"numpy\nndarray\n");
        p.extend_from_slice(&[b'K', 0, 0x85, b'C', 1, b'b', 0x87, b'R']);
        p.extend_from_slice(&[b'(', b'K', 1, b')', b'N', 0x89, b']']);
        p.extend_from_slice(&sample()[2..sample().len() - 1]);
        p.extend_from_slice(b"atb.");
        let value = read_pickle(&p).unwrap();
        let meta = value.find_dict_with_key("frames").unwrap();
        assert!(meta.get("meta").is_some());
    }

    #[test]
    fn shared_references_cannot_expand_exponentially() {
        // l0 = []; l1 = [l0, l0]; l2 = [l1, l1]; ... 100 levels: 2^100 leaves as a tree.
        let mut p = vec![0x80, 3, b']', b'r', 0, 0, 0, 0];
        for level in 1u32..=100 {
            p.extend_from_slice(b"](j");
            p.extend_from_slice(&(level - 1).to_le_bytes());
            p.push(b'j');
            p.extend_from_slice(&(level - 1).to_le_bytes());
            p.extend_from_slice(b"er");
            p.extend_from_slice(&level.to_le_bytes());
        }
        p.push(b'.');
        let err = read_pickle(&p).unwrap_err().to_string();
        assert!(err.contains("too many values"), "{err}");
    }

    #[test]
    fn damaged_pickles_name_the_offset() {
        let bytes = sample();
        let err = read_pickle(&bytes[..bytes.len() - 10]).unwrap_err();
        assert!(err.problem.contains("truncated"), "{err}");
        let err = read_pickle(&[0x80, 3, b'i']).unwrap_err();
        assert_eq!(err.offset, 2);
        assert!(err.to_string().contains("0x69"), "{err}");
        let err = read_pickle(&[0x80, 3, b'h', 7, b'.']).unwrap_err();
        assert!(err.to_string().contains("memo entry 7"), "{err}");
    }
}
