//! ArduPilot DataFlash (`.BIN`) reader: the byte layer.
//!
//! A DataFlash log is a sequence of messages, each `A3 95 <type>` then a payload whose layout a
//! `FMT` message (type 128, itself 89 bytes) declared earlier: type, total length, 4-char name,
//! up to 16 format characters and up to 64 characters of comma-separated labels. Format characters
//! and the scale the value carries (ArduPilot's `LogStructure.h` documentation):
//!
//! | char | stored | value |
//! |---|---|---|
//! | `b` `B` `M` | i8 / u8 / u8 (flight mode) | as is |
//! | `h` `H` | i16 / u16 | as is |
//! | `i` `I` | i32 / u32 | as is |
//! | `q` `Q` | i64 / u64 | as is |
//! | `f` `d` | f32 / f64 | as is |
//! | `g` | f16 | as is |
//! | `c` `C` `e` `E` | i16 / u16 / i32 / u32 | × 0.01 |
//! | `L` | i32 | × 1e-7 (latitude/longitude, degrees) |
//! | `n` `N` `Z` | char\[4\] / \[16\] / \[64\] | text |
//! | `a` | i16\[32\] | (not decoded) |
//!
//! The reader is strict: bytes that are not a message header where one must start, a type no
//! `FMT` declared, an `FMT` whose length disagrees with its format string, or a file that ends
//! inside a message, are errors naming the byte offset. Only the messages the importer asks for
//! are kept (decoded to `f64`/text); every type is counted.

use std::collections::{BTreeMap, HashMap, HashSet};

use crate::error::{Bytes, LogError, text};

/// The two sync bytes that start every message.
pub(crate) const HEADER: [u8; 2] = [0xA3, 0x95];
/// The message type of `FMT`.
const FMT_TYPE: u8 = 128;
/// Total length of an `FMT` message, header included.
const FMT_LEN: usize = 89;

/// One decoded field value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Value {
    Num(f64),
    Text(String),
}

/// A message type's layout, from its `FMT`.
#[derive(Debug, Clone)]
struct Format {
    name: String,
    /// Total message length, header included.
    len: usize,
    chars: Vec<u8>,
    /// Whether `chars` describe `len` bytes; a message of a format that does not is stepped over
    /// by its stated length and not decoded.
    decodable: bool,
}

/// All kept rows of one message name.
#[derive(Debug, Clone, Default)]
pub(crate) struct Table {
    labels: Vec<String>,
    column: HashMap<String, usize>,
    /// Rows, each one value per label.
    pub(crate) rows: Vec<Vec<Value>>,
}

impl Table {
    fn new(labels: Vec<String>) -> Self {
        let column = labels
            .iter()
            .enumerate()
            .map(|(i, l)| (l.clone(), i))
            .collect();
        Self {
            labels,
            column,
            rows: Vec::new(),
        }
    }

    /// Whether the layout has this field.
    pub(crate) fn has(&self, label: &str) -> bool {
        self.column.contains_key(label)
    }

    /// The first of `labels` the layout has (firmware versions rename fields).
    pub(crate) fn pick(&self, labels: &[&str]) -> Option<usize> {
        labels.iter().find_map(|l| self.column.get(*l).copied())
    }

    /// A numeric field of a row.
    pub(crate) fn num(&self, row: &[Value], label: &str) -> Option<f64> {
        self.num_at(row, *self.column.get(label)?)
    }

    /// A numeric field of a row by column index.
    pub(crate) fn num_at(&self, row: &[Value], col: usize) -> Option<f64> {
        match row.get(col)? {
            Value::Num(v) => Some(*v),
            Value::Text(_) => None,
        }
    }

    /// A text field of a row.
    pub(crate) fn text<'r>(&self, row: &'r [Value], label: &str) -> Option<&'r str> {
        match row.get(*self.column.get(label)?)? {
            Value::Text(s) => Some(s),
            Value::Num(_) => None,
        }
    }
}

/// A parsed DataFlash log: the kept messages by name, and a count of every message by name.
#[derive(Debug, Clone, Default)]
pub(crate) struct DfLog {
    pub(crate) tables: BTreeMap<String, Table>,
    pub(crate) counts: BTreeMap<String, usize>,
    /// Where parsing stopped early (a cut tail, or any damage with `stop_at_damage`).
    pub(crate) damage: Option<LogError>,
    /// Message types whose `FMT` length disagrees with its format string: framed by the stated
    /// length, their rows skipped (one line each, for the import's notes).
    pub(crate) skipped_formats: Vec<String>,
}

impl DfLog {
    pub(crate) fn table(&self, name: &str) -> Option<&Table> {
        self.tables.get(name).filter(|t| !t.rows.is_empty())
    }
}

/// Size in bytes of a format character, `None` when unknown.
fn field_size(c: u8) -> Option<usize> {
    Some(match c {
        b'b' | b'B' | b'M' => 1,
        b'h' | b'H' | b'c' | b'C' | b'g' => 2,
        b'i' | b'I' | b'e' | b'E' | b'L' | b'f' | b'n' => 4,
        b'd' | b'q' | b'Q' => 8,
        b'N' => 16,
        b'Z' | b'a' => 64,
        _ => return None,
    })
}

/// IEEE 754 half precision to f64 (format `g`).
fn half_to_f64(bits: u16) -> f64 {
    let sign = if bits & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((bits >> 10) & 0x1f);
    let frac = f64::from(bits & 0x3ff);
    match exp {
        0 => sign * frac * 2f64.powi(-24),
        31 if frac == 0.0 => sign * f64::INFINITY,
        31 => f64::NAN,
        e => sign * (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

/// Decodes one field whose bytes are `b` (exactly `field_size(c)` long).
fn decode(c: u8, b: &[u8]) -> Value {
    let i16_ = || f64::from(i16::from_le_bytes([b[0], b[1]]));
    let u16_ = || f64::from(u16::from_le_bytes([b[0], b[1]]));
    let i32_ = || f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let u32_ = || f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let b8 = || {
        let mut a = [0u8; 8];
        a.copy_from_slice(&b[..8]);
        a
    };
    Value::Num(match c {
        b'b' => f64::from(b[0] as i8),
        b'B' | b'M' => f64::from(b[0]),
        b'h' => i16_(),
        b'H' => u16_(),
        b'i' => i32_(),
        b'I' => u32_(),
        b'q' => i64::from_le_bytes(b8()) as f64,
        b'Q' => u64::from_le_bytes(b8()) as f64,
        b'f' => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        b'd' => f64::from_le_bytes(b8()),
        b'g' => half_to_f64(u16::from_le_bytes([b[0], b[1]])),
        b'c' => i16_() * 0.01,
        b'C' => u16_() * 0.01,
        b'e' => i32_() * 0.01,
        b'E' => u32_() * 0.01,
        b'L' => i32_() * 1e-7,
        b'n' | b'N' | b'Z' => return Value::Text(text(b)),
        _ => f64::NAN, // 'a' arrays: not needed by the importer
    })
}

/// Whether the bytes look like a DataFlash log (a message header at the start).
pub(crate) fn sniff(data: &[u8]) -> bool {
    data.len() >= 3 && data[..2] == HEADER
}

/// Parses a DataFlash log, keeping the rows of the message names in `keep`. A log that ends
/// inside a message, and with `stop_at_damage` any error, ends the parse: the error is returned
/// in [`DfLog::damage`] with everything read before it; otherwise an error is the result.
pub(crate) fn parse(
    data: &[u8],
    keep: &HashSet<&str>,
    stop_at_damage: bool,
) -> Result<DfLog, LogError> {
    let mut log = DfLog::default();
    let mut formats: HashMap<u8, Format> = HashMap::new();
    formats.insert(
        FMT_TYPE,
        Format {
            name: "FMT".into(),
            len: FMT_LEN,
            chars: b"BBnNZ".to_vec(),
            decodable: true,
        },
    );
    let file = Bytes::new(data, 0);
    let mut pos = 0usize;
    while pos < data.len() {
        match step(file, pos, &mut formats, &mut log, keep) {
            Ok(next) => pos = next,
            // A log that ends inside a message was cut (the logger lost power or stopped
            // mid-write, as on 5 of 20 public ArduPilot flights with GNSS checked here): what
            // came before is whole, so it is kept, with a note naming the byte offset.
            Err(e) if stop_at_damage || e.is_cut_tail() => {
                log.damage = Some(e);
                break;
            }
            Err(e) => return Err(e),
        }
    }
    Ok(log)
}

/// Reads the message at `pos`, returns the position of the next one.
fn step(
    file: Bytes<'_>,
    pos: usize,
    formats: &mut HashMap<u8, Format>,
    log: &mut DfLog,
    keep: &HashSet<&str>,
) -> Result<usize, LogError> {
    let head = file.slice(pos, 3, "message header")?;
    if head[..2] != HEADER {
        return Err(LogError::corrupt(
            pos,
            format!(
                "expected a message header A3 95, found {:02X} {:02X}",
                head[0], head[1]
            ),
        ));
    }
    let id = head[2];
    let Some(fmt) = formats.get(&id) else {
        return Err(LogError::corrupt(
            pos,
            format!("message type {id} was not declared by an FMT message"),
        ));
    };
    let what = if id == FMT_TYPE {
        "FMT message"
    } else {
        "message"
    };
    let len = fmt.len;
    let msg = file.view(pos, len, what)?;
    *log.counts.entry(fmt.name.clone()).or_default() += 1;
    if id == FMT_TYPE {
        let (new_id, new) = parse_fmt(msg, pos)?;
        if !new.decodable {
            log.skipped_formats.push(format!(
                "{} (type {new_id}, FMT at byte {pos}): stated length {} does not match its \
                 format {:?}; its messages were skipped",
                new.name,
                new.len,
                String::from_utf8_lossy(&new.chars)
            ));
        }
        if keep.contains(new.name.as_str()) && new.decodable {
            let labels = fmt_labels(msg)?;
            let table = log.tables.entry(new.name.clone()).or_default();
            // A redefinition with other labels after rows were kept would mix layouts: keep the
            // first (real logs declare each type once).
            if table.rows.is_empty() {
                *table = Table::new(labels);
            }
        }
        formats.insert(new_id, new);
        return Ok(pos + len);
    } else if fmt.decodable
        && keep.contains(fmt.name.as_str())
        && let Some(table) = log.tables.get_mut(&fmt.name)
        && table.labels.len() == fmt.chars.len()
    {
        let mut row = Vec::with_capacity(fmt.chars.len());
        let mut at = 3;
        for &c in &fmt.chars {
            // sizes were validated against the length when the FMT was read
            let n = field_size(c).unwrap_or(0);
            row.push(decode(c, msg.slice(at, n, "field")?));
            at += n;
        }
        table.rows.push(row);
    }
    Ok(pos + len)
}

/// Decodes an `FMT` message (header included) at file offset `pos`.
fn parse_fmt(msg: Bytes<'_>, pos: usize) -> Result<(u8, Format), LogError> {
    let id = msg.u8(3, "FMT type")?;
    let len = usize::from(msg.u8(4, "FMT length")?);
    let name = text(msg.slice(5, 4, "FMT name")?);
    let chars: Vec<u8> = msg
        .slice(9, 16, "FMT format")?
        .iter()
        .copied()
        .take_while(|&b| b != 0)
        .collect();
    let mut size = 3;
    for &c in &chars {
        size += field_size(c).ok_or_else(|| {
            LogError::corrupt(
                pos,
                format!("FMT of {name}: unknown format character {:?}", c as char),
            )
        })?;
    }
    if id == FMT_TYPE && len != FMT_LEN {
        return Err(LogError::corrupt(
            pos,
            "FMT redefines FMT with another length",
        ));
    }
    if len < 3 {
        return Err(LogError::corrupt(
            pos,
            format!("FMT of {name} (type {id}): length {len} is shorter than a message header"),
        ));
    }
    // Some autopilot builds wrote an FMT whose length disagrees with its own format string
    // (ArduPilot logs on Erle-Brain declare EKF5 as 28 bytes for a 40-byte format). The writer
    // framed the messages by the stated length, so the log stays readable by it; the fields
    // cannot be trusted, so those messages are not decoded.
    let decodable = size == len;
    Ok((
        id,
        Format {
            name,
            len,
            chars,
            decodable,
        },
    ))
}

fn fmt_labels(msg: Bytes<'_>) -> Result<Vec<String>, LogError> {
    Ok(text(msg.slice(25, 64, "FMT labels")?)
        .split(',')
        .map(|s| s.trim().to_string())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_precision() {
        assert_eq!(half_to_f64(0x3c00), 1.0);
        assert_eq!(half_to_f64(0xc000), -2.0);
        assert_eq!(half_to_f64(0x0001), 2f64.powi(-24));
        assert!(half_to_f64(0x7e00).is_nan());
    }

    #[test]
    fn scaled_fields() {
        assert_eq!(decode(b'c', &(-1234i16).to_le_bytes()), Value::Num(-12.34));
        assert_eq!(
            decode(b'L', &428_537_709i32.to_le_bytes()),
            Value::Num(428_537_709.0 * 1e-7)
        );
        assert_eq!(decode(b'n', b"IMU\0"), Value::Text("IMU".into()));
    }
}
