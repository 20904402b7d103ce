//! A reader for the one kind of Python pickle the LPIPS weights come in: nested dicts of
//! str keys whose leaves are little-endian float32 numpy arrays (as `pickle.dump` writes
//! them with protocols 2–4: `numpy.core.multiarray._reconstruct` + `ndarray.__setstate__`).
//!
//! Only the opcodes such a file needs are understood; anything else (another global,
//! another dtype, an opcode outside the subset) is an error, never code run. Every length
//! is checked against the bytes left, so a truncated or hostile file fails cleanly.

use std::collections::BTreeMap;

/// A float32 array: row-major values of `shape`.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// The values the subset of the pickle machine handles.
#[derive(Clone, Debug)]
enum Value {
    None,
    Bool(bool),
    Int(i64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<Value>),
    Dict(Vec<(Value, Value)>),
    /// `numpy.core.multiarray._reconstruct`, `numpy.ndarray`, `numpy.dtype`.
    Global(&'static str),
    /// A `numpy.dtype` built from its code (`'f4'`), updated by BUILD.
    Dtype {
        code: String,
        little: bool,
    },
    /// An empty `ndarray` from `_reconstruct`, filled by BUILD.
    Ndarray(Option<Array>),
    Mark,
}

/// A nested dict of arrays flattened to `"a/b/c"` keys.
pub type Arrays = BTreeMap<String, Array>;

const ALLOWED_GLOBALS: [(&str, &str, &str); 4] = [
    ("numpy.core.multiarray", "_reconstruct", "reconstruct"),
    ("numpy._core.multiarray", "_reconstruct", "reconstruct"),
    ("numpy", "ndarray", "ndarray"),
    ("numpy", "dtype", "dtype"),
];

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let end = end.ok_or_else(|| format!("truncated: {n} bytes wanted at byte {}", self.at))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<usize, String> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
    }
    fn line(&mut self) -> Result<&'a str, String> {
        let rest = &self.b[self.at..];
        let n = rest
            .iter()
            .position(|&c| c == b'\n')
            .ok_or("truncated: no end of line")?;
        let s = std::str::from_utf8(&rest[..n]).map_err(|_| "a name is not UTF-8")?;
        self.at += n + 1;
        Ok(s)
    }
}

fn utf8(b: &[u8]) -> Result<String, String> {
    String::from_utf8(b.to_vec()).map_err(|_| "a string is not UTF-8".to_string())
}

fn global(module: &str, name: &str) -> Result<Value, String> {
    ALLOWED_GLOBALS
        .iter()
        .find(|(m, n, _)| *m == module && *n == name)
        .map(|(_, _, tag)| Value::Global(tag))
        .ok_or_else(|| format!("unexpected global {module}.{name} (only numpy arrays are read)"))
}

/// Parse the pickle in `bytes` into its arrays, keys joined with '/'.
pub(crate) fn read_arrays(bytes: &[u8]) -> Result<Arrays, String> {
    let root = run(bytes)?;
    let mut out = Arrays::new();
    flatten(root, "", &mut out)?;
    if out.is_empty() {
        return Err("no arrays in the pickle".into());
    }
    Ok(out)
}

fn flatten(v: Value, prefix: &str, out: &mut Arrays) -> Result<(), String> {
    match v {
        Value::Dict(items) => {
            for (k, v) in items {
                let Value::Str(k) = k else {
                    return Err("a dict key is not a string".into());
                };
                let key = if prefix.is_empty() {
                    k
                } else {
                    format!("{prefix}/{k}")
                };
                flatten(v, &key, out)?;
            }
            Ok(())
        }
        Value::Ndarray(Some(a)) => {
            out.insert(prefix.to_string(), a);
            Ok(())
        }
        _ => Err(format!("'{prefix}' is neither a dict nor a float32 array")),
    }
}

fn pop(stack: &mut Vec<Value>) -> Result<Value, String> {
    stack
        .pop()
        .ok_or_else(|| "corrupt: stack underflow".to_string())
}

/// The items above the topmost mark, and the mark removed.
fn pop_mark(stack: &mut Vec<Value>) -> Result<Vec<Value>, String> {
    let k = stack
        .iter()
        .rposition(|v| matches!(v, Value::Mark))
        .ok_or("corrupt: no mark")?;
    let items = stack.split_off(k + 1);
    stack.pop();
    Ok(items)
}

fn run(bytes: &[u8]) -> Result<Value, String> {
    let mut r = Reader { b: bytes, at: 0 };
    let mut stack: Vec<Value> = Vec::new();
    let mut memo: BTreeMap<usize, Value> = BTreeMap::new();
    loop {
        let op = r.u8()?;
        match op {
            0x80 => {
                let proto = r.u8()?;
                if !(2..=5).contains(&proto) {
                    return Err(format!("pickle protocol {proto} is not supported"));
                }
            }
            0x95 => {
                r.take(8)?; // FRAME: a length hint only
            }
            b'.' => return pop(&mut stack),
            b'}' => stack.push(Value::Dict(Vec::new())),
            b')' => stack.push(Value::Tuple(Vec::new())),
            b'(' => stack.push(Value::Mark),
            b'N' => stack.push(Value::None),
            0x88 => stack.push(Value::Bool(true)),
            0x89 => stack.push(Value::Bool(false)),
            b'K' => stack.push(Value::Int(r.u8()? as i64)),
            b'M' => {
                let s = r.take(2)?;
                stack.push(Value::Int(u16::from_le_bytes([s[0], s[1]]) as i64));
            }
            b'J' => {
                let s = r.take(4)?;
                stack.push(Value::Int(
                    i32::from_le_bytes([s[0], s[1], s[2], s[3]]) as i64
                ));
            }
            b'X' => {
                let n = r.u32()?;
                stack.push(Value::Str(utf8(r.take(n)?)?));
            }
            0x8c => {
                let n = r.u8()? as usize;
                stack.push(Value::Str(utf8(r.take(n)?)?));
            }
            b'C' => {
                let n = r.u8()? as usize;
                stack.push(Value::Bytes(r.take(n)?.to_vec()));
            }
            b'B' => {
                let n = r.u32()?;
                stack.push(Value::Bytes(r.take(n)?.to_vec()));
            }
            b'c' => {
                let module = r.line()?;
                let name = r.line()?;
                stack.push(global(module, name)?);
            }
            0x93 => {
                let (name, module) = (pop(&mut stack)?, pop(&mut stack)?);
                let (Value::Str(m), Value::Str(n)) = (module, name) else {
                    return Err("corrupt: STACK_GLOBAL without two names".into());
                };
                stack.push(global(&m, &n)?);
            }
            b'q' | b'r' | 0x94 => {
                let k = match op {
                    b'q' => r.u8()? as usize,
                    b'r' => r.u32()?,
                    _ => memo.len(),
                };
                memo.insert(k, memo_copy(stack.last())?);
            }
            b'h' | b'j' => {
                let k = if op == b'h' {
                    r.u8()? as usize
                } else {
                    r.u32()?
                };
                let v = memo
                    .get(&k)
                    .ok_or_else(|| format!("corrupt: memo {k} unset"))?;
                stack.push(v.clone());
            }
            b't' => {
                let items = pop_mark(&mut stack)?;
                stack.push(Value::Tuple(items));
            }
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                if stack.len() < n {
                    return Err("corrupt: stack underflow".into());
                }
                let items = stack.split_off(stack.len() - n);
                stack.push(Value::Tuple(items));
            }
            b's' | b'u' => {
                let items = if op == b's' {
                    let v = pop(&mut stack)?;
                    vec![pop(&mut stack)?, v]
                } else {
                    pop_mark(&mut stack)?
                };
                if items.len() % 2 != 0 {
                    return Err("corrupt: odd number of dict items".into());
                }
                let Some(Value::Dict(d)) = stack.last_mut() else {
                    return Err("corrupt: SETITEMS on a non-dict".into());
                };
                let mut it = items.into_iter();
                while let (Some(k), Some(v)) = (it.next(), it.next()) {
                    d.push((k, v));
                }
            }
            b'R' => {
                let args = pop(&mut stack)?;
                let f = pop(&mut stack)?;
                stack.push(reduce(f, args)?);
            }
            b'b' => {
                let state = pop(&mut stack)?;
                let obj = pop(&mut stack)?;
                stack.push(build(obj, state)?);
            }
            _ => {
                return Err(format!(
                    "unsupported pickle opcode 0x{op:02x} at byte {}",
                    r.at - 1
                ));
            }
        }
    }
}

/// What the memo keeps of the top of the stack: a copy (the files read here only fetch
/// names, globals and dtypes back from it), except array bytes, never fetched again and
/// too big to copy.
fn memo_copy(top: Option<&Value>) -> Result<Value, String> {
    match top.ok_or("corrupt: memo of nothing")? {
        Value::Bytes(_) => Ok(Value::None),
        v => Ok(v.clone()),
    }
}

fn reduce(f: Value, args: Value) -> Result<Value, String> {
    let Value::Tuple(args) = args else {
        return Err("corrupt: REDUCE arguments are not a tuple".into());
    };
    match (f, args.as_slice()) {
        (Value::Global("reconstruct"), [Value::Global("ndarray"), ..]) => Ok(Value::Ndarray(None)),
        (Value::Global("dtype"), [Value::Str(code), ..]) => Ok(Value::Dtype {
            code: code.clone(),
            little: true,
        }),
        _ => Err("unexpected call in the pickle (only numpy arrays are read)".into()),
    }
}

fn build(obj: Value, state: Value) -> Result<Value, String> {
    let Value::Tuple(state) = state else {
        return Err("corrupt: BUILD state is not a tuple".into());
    };
    match obj {
        // dtype state: (version, byte order, subarray, names, fields, elsize, alignment, flags)
        Value::Dtype { code, .. } => match state.get(1) {
            Some(Value::Str(order)) => Ok(Value::Dtype {
                code,
                little: order != ">",
            }),
            _ => Err("corrupt: dtype state without byte order".into()),
        },
        // ndarray state: (version, shape, dtype, is_fortran, raw bytes)
        Value::Ndarray(None) => {
            let [
                _,
                Value::Tuple(shape),
                Value::Dtype { code, little },
                Value::Bool(fortran),
                Value::Bytes(raw),
            ] = state.as_slice()
            else {
                return Err(
                    "corrupt: ndarray state is not (version, shape, dtype, order, bytes)".into(),
                );
            };
            if code != "f4" || !little || *fortran {
                return Err(format!(
                    "array of dtype '{code}'{}{}: only little-endian C-order float32 is read",
                    if *little { "" } else { " big-endian" },
                    if *fortran { " Fortran order" } else { "" }
                ));
            }
            let shape = shape
                .iter()
                .map(|d| match d {
                    Value::Int(n) if *n >= 0 => Ok(*n as usize),
                    _ => Err("corrupt: array dimension is not a size".to_string()),
                })
                .collect::<Result<Vec<_>, _>>()?;
            let count = shape
                .iter()
                .try_fold(1usize, |a, &d| a.checked_mul(d))
                .ok_or("corrupt: array size overflows")?;
            if count.checked_mul(4) != Some(raw.len()) {
                return Err(format!(
                    "array of shape {shape:?} holds {} bytes, not {}",
                    raw.len(),
                    count.saturating_mul(4)
                ));
            }
            let data = raw
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            Ok(Value::Ndarray(Some(Array { shape, data })))
        }
        _ => Err("corrupt: BUILD on an object that is not a dtype or ndarray".into()),
    }
}

#[cfg(test)]
#[path = "pickle_tests.rs"]
mod tests;
