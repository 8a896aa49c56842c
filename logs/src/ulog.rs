//! PX4 ULog (`.ulg`) reader: the byte layer (PX4 "ULog File Format" specification).
//!
//! A 16-byte header (magic `ULog\x01\x12\x35`, version, boot timestamp µs), then messages of
//! `u16 size, u8 type, payload[size]`: the definitions (`B` flag bits, `F` formats, `I`/`M` info,
//! `P`/`Q` parameters) and the data section (`A` add-logged subscription, `R` remove, `D` data,
//! `L`/`C` logging, `S` sync, `O` dropout). Formats are `name:type field;type field;...` with
//! nested message types and fixed arrays; fields named `_padding*` occupy bytes but carry nothing,
//! and a trailing padding field may be missing from the data. When flag bit `incompat[0] & 1` is
//! set, data was appended at the offsets the `B` message gives: the main section ends at the first
//! of them and reading continues there.
//!
//! Errors name the byte offset of the offending message; nothing indexes the input unchecked.

use std::collections::{BTreeMap, HashMap};

use crate::error::{Bytes, LogError, text};

const MAGIC: &[u8; 7] = b"ULog\x01\x12\x35";
const HEADER_LEN: usize = 16;

pub(crate) fn sniff(data: &[u8]) -> bool {
    data.starts_with(MAGIC)
}

/// A primitive field type.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Prim {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Bool,
    Char,
}

impl Prim {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "int8_t" => Prim::I8,
            "uint8_t" => Prim::U8,
            "int16_t" => Prim::I16,
            "uint16_t" => Prim::U16,
            "int32_t" => Prim::I32,
            "uint32_t" => Prim::U32,
            "int64_t" => Prim::I64,
            "uint64_t" => Prim::U64,
            "float" => Prim::F32,
            "double" => Prim::F64,
            "bool" => Prim::Bool,
            "char" => Prim::Char,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Prim::I8 | Prim::U8 | Prim::Bool | Prim::Char => 1,
            Prim::I16 | Prim::U16 => 2,
            Prim::I32 | Prim::U32 | Prim::F32 => 4,
            Prim::I64 | Prim::U64 | Prim::F64 => 8,
        }
    }

    fn decode(self, b: &[u8]) -> Option<f64> {
        let a = |n: usize| b.get(..n);
        Some(match self {
            Prim::I8 => f64::from(*b.first()? as i8),
            Prim::U8 | Prim::Bool | Prim::Char => f64::from(*b.first()?),
            Prim::I16 => f64::from(i16::from_le_bytes(a(2)?.try_into().ok()?)),
            Prim::U16 => f64::from(u16::from_le_bytes(a(2)?.try_into().ok()?)),
            Prim::I32 => f64::from(i32::from_le_bytes(a(4)?.try_into().ok()?)),
            Prim::U32 => f64::from(u32::from_le_bytes(a(4)?.try_into().ok()?)),
            Prim::I64 => i64::from_le_bytes(a(8)?.try_into().ok()?) as f64,
            Prim::U64 => u64::from_le_bytes(a(8)?.try_into().ok()?) as f64,
            Prim::F32 => f64::from(f32::from_le_bytes(a(4)?.try_into().ok()?)),
            Prim::F64 => f64::from_le_bytes(a(8)?.try_into().ok()?),
        })
    }
}

/// A topic's flattened layout: `field` or `field[i]` or `nested.field` → (offset, type).
#[derive(Debug, Clone, Default)]
pub(crate) struct Layout {
    fields: HashMap<String, (usize, Prim)>,
}

impl Layout {
    pub(crate) fn has(&self, name: &str) -> bool {
        self.fields.contains_key(name) || self.fields.contains_key(&format!("{name}[0]"))
    }
}

/// One subscribed topic instance and its data messages (payload after the msg id).
#[derive(Debug, Clone)]
pub(crate) struct Topic {
    pub(crate) name: String,
    pub(crate) multi_id: u8,
    pub(crate) layout: Layout,
    pub(crate) rows: Vec<Vec<u8>>,
}

impl Topic {
    /// A scalar field (or array element `name[i]`) of row `r`.
    pub(crate) fn get(&self, r: &[u8], name: &str) -> Option<f64> {
        let (off, p) = self.layout.fields.get(name)?;
        p.decode(r.get(*off..)?)
    }
}

/// A parsed ULog file.
#[derive(Debug, Clone, Default)]
pub(crate) struct ULog {
    pub(crate) topics: Vec<Topic>,
    pub(crate) params: BTreeMap<String, f64>,
    pub(crate) info: BTreeMap<String, String>,
    pub(crate) log_messages: Vec<String>,
    pub(crate) damage: Option<LogError>,
}

impl ULog {
    /// Instance 0 of a topic with rows.
    pub(crate) fn topic(&self, name: &str) -> Option<&Topic> {
        self.topics
            .iter()
            .find(|t| t.name == name && t.multi_id == 0 && !t.rows.is_empty())
    }
}

/// Flattens format `name` into `out` at `base` with `prefix`; returns its size.
fn flatten(
    formats: &HashMap<String, String>,
    name: &str,
    base: usize,
    prefix: &str,
    out: &mut HashMap<String, (usize, Prim)>,
    depth: usize,
) -> Result<usize, String> {
    if depth > 16 {
        return Err(format!("format {name} nests too deeply"));
    }
    let body = formats
        .get(name)
        .ok_or_else(|| format!("no format definition for type {name}"))?;
    let mut off = 0usize;
    for field in body.split(';').map(str::trim).filter(|f| !f.is_empty()) {
        let (ty, fname) = field
            .split_once(' ')
            .ok_or_else(|| format!("bad field {field:?} in {name}"))?;
        let (ty, n) = match ty.split_once('[') {
            Some((t, rest)) => {
                let n: usize = rest
                    .trim_end_matches(']')
                    .parse()
                    .map_err(|_| format!("bad array size in {field:?}"))?;
                (t, Some(n))
            }
            None => (ty, None),
        };
        let count = n.unwrap_or(1);
        let padding = fname.starts_with("_padding");
        for i in 0..count {
            let key = match n {
                Some(_) => format!("{prefix}{fname}[{i}]"),
                None => format!("{prefix}{fname}"),
            };
            let size = match Prim::parse(ty) {
                Some(p) => {
                    if !padding {
                        out.insert(key, (base + off, p));
                    }
                    p.size()
                }
                None => flatten(formats, ty, base + off, &format!("{key}."), out, depth + 1)?,
            };
            off = off
                .checked_add(size)
                .ok_or_else(|| format!("format {name} too large"))?;
        }
    }
    Ok(off)
}

/// Parses a ULog file; a file that ends inside a message, and with `stop_at_damage` any error,
/// ends the parse with the error kept in [`ULog::damage`].
pub(crate) fn parse(data: &[u8], stop_at_damage: bool) -> Result<ULog, LogError> {
    let file = Bytes::new(data, 0);
    let head = file.slice(0, HEADER_LEN, "ULog header")?;
    if &head[..7] != MAGIC {
        return Err(LogError::corrupt(0, "not a ULog file (bad magic)"));
    }
    let mut st = State::default();
    let mut pos = HEADER_LEN;
    while pos < data.len() {
        match st.step(file, pos) {
            Ok(next) => pos = next,
            // A cut tail keeps what came before it (see `dataflash::parse`).
            Err(e) if stop_at_damage || e.is_cut_tail() => {
                st.log.damage = Some(e);
                break;
            }
            Err(e) => return Err(e),
        }
    }
    Ok(st.log)
}

#[derive(Debug, Default)]
struct State {
    log: ULog,
    formats: HashMap<String, String>,
    /// msg id → index into `log.topics`.
    subs: HashMap<u16, usize>,
    /// Start offsets of appended data, ascending.
    appended: Vec<usize>,
}

impl State {
    fn step(&mut self, file: Bytes<'_>, pos: usize) -> Result<usize, LogError> {
        let size = usize::from(file.u16(pos, "message header")?);
        let kind = file.u8(pos + 2, "message header")?;
        // a message must not run into appended data: the main section ends there
        let end = pos + 3 + size;
        if let Some(&boundary) = self.appended.iter().find(|&&a| a > pos)
            && end > boundary
        {
            return Ok(boundary);
        }
        let msg = file.view(pos + 3, size, "message")?;
        let bad = |r: String| LogError::corrupt(pos, r);
        match kind {
            b'B' => {
                let incompat = msg.u8(8, "flag bits")?;
                if incompat & 1 != 0 {
                    for i in 0..3 {
                        let off = msg.u64(16 + 8 * i, "appended offset")?;
                        if off > 0 {
                            self.appended
                                .push(usize::try_from(off).unwrap_or(usize::MAX));
                        }
                    }
                    self.appended.sort_unstable();
                }
            }
            b'F' => {
                let s = text(msg.slice(0, size, "format")?);
                let (name, body) = s
                    .split_once(':')
                    .ok_or_else(|| bad(format!("format without ':': {s:?}")))?;
                self.formats.insert(name.to_string(), body.to_string());
            }
            b'I' | b'M' | b'P' | b'Q' => {
                // `M` and `Q` carry one more byte (is_continued / default type) before the key
                let skip = usize::from(kind == b'M' || kind == b'Q');
                let klen = usize::from(msg.u8(skip, "key length")?);
                let key = text(msg.slice(skip + 1, klen, "key")?);
                let value = msg.slice(
                    skip + 1 + klen,
                    size.saturating_sub(skip + 1 + klen),
                    "value",
                )?;
                let (ty, name) = key
                    .split_once(' ')
                    .ok_or_else(|| bad(format!("bad key {key:?}")))?;
                match kind {
                    b'P' => {
                        let v = match ty {
                            "float" => Prim::F32.decode(value),
                            "int32_t" => Prim::I32.decode(value),
                            _ => None,
                        };
                        if let Some(v) = v {
                            self.log.params.insert(name.to_string(), v);
                        }
                    }
                    b'I' => {
                        let v = if ty.starts_with("char") {
                            text(value)
                        } else {
                            Prim::parse(ty)
                                .and_then(|p| p.decode(value))
                                .map_or_else(String::new, |v| v.to_string())
                        };
                        self.log.info.insert(name.to_string(), v);
                    }
                    _ => {}
                }
            }
            b'A' => {
                let multi_id = msg.u8(0, "multi id")?;
                let id = msg.u16(1, "msg id")?;
                let name = text(msg.slice(3, size.saturating_sub(3), "message name")?);
                let mut fields = HashMap::new();
                flatten(&self.formats, &name, 0, "", &mut fields, 0).map_err(bad)?;
                self.log.topics.push(Topic {
                    name,
                    multi_id,
                    layout: Layout { fields },
                    rows: Vec::new(),
                });
                self.subs.insert(id, self.log.topics.len() - 1);
            }
            b'R' => {
                let id = msg.u16(0, "msg id")?;
                self.subs.remove(&id);
            }
            b'D' => {
                let id = msg.u16(0, "msg id")?;
                let idx = *self.subs.get(&id).ok_or_else(|| {
                    bad(format!("data for msg id {id}, which was not subscribed"))
                })?;
                let payload = msg.slice(2, size.saturating_sub(2), "data")?;
                if let Some(t) = self.log.topics.get_mut(idx) {
                    t.rows.push(payload.to_vec());
                }
            }
            b'L' => {
                let m = text(msg.slice(9, size.saturating_sub(9), "log text")?);
                self.log.log_messages.push(m);
            }
            b'C' => {
                let m = text(msg.slice(11, size.saturating_sub(11), "log text")?);
                self.log.log_messages.push(m);
            }
            // sync, dropout, and types newer than this reader: the specification says skip
            _ => {}
        }
        Ok(end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flatten_nested_arrays_and_padding() {
        let mut f = HashMap::new();
        f.insert(
            "inner".to_string(),
            "float a;uint8_t[2] _padding0;".to_string(),
        );
        f.insert(
            "outer".to_string(),
            "uint64_t timestamp;inner[2] x;int16_t[3] v;".to_string(),
        );
        let mut out = HashMap::new();
        let size = flatten(&f, "outer", 0, "", &mut out, 0).expect("flatten");
        assert_eq!(size, 8 + 2 * 6 + 6);
        assert_eq!(out["x[1].a"], (14, Prim::F32));
        assert_eq!(out["v[2]"], (24, Prim::I16));
        assert!(!out.keys().any(|k| k.contains("_padding")));
    }
}
