//! A small, forgiving parser for the YAML subset of EuRoC/Kalibr `sensor.yaml` files.
//!
//! Handles: `%YAML` directives and `---`, `#` comments (also trailing ones), `key: value` scalars,
//! inline lists `[a, b, ...]` that may span several lines, one or more levels of indented maps
//! (`T_BS:` → `cols/rows/data`), and `- item` block lists. Keys we do not know are kept and
//! ignored. Anything else is an error naming the file and line.

use std::path::{Path, PathBuf};

use crate::error::{DatasetError, Result};

/// A parsed value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A scalar, unquoted.
    Scalar(String),
    /// An inline or block list of scalars (nested inline lists are flattened).
    List(Vec<String>),
    /// A nested map, in file order.
    Map(Vec<(String, Node)>),
    /// `key:` with nothing under it.
    Empty,
}

/// A value and the 1-based line of its key.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// The value.
    pub value: Value,
    /// The line of the key.
    pub line: usize,
}

/// One parsed YAML file.
#[derive(Debug, Clone)]
pub struct Yaml {
    path: PathBuf,
    root: Vec<(String, Node)>,
}

/// A logical line: comment stripped, continuation lines of an inline list joined.
struct Line {
    number: usize,
    indent: usize,
    text: String,
}

impl Yaml {
    /// Reads and parses a file; a missing file is [`DatasetError::MissingFile`].
    pub fn read(path: &Path) -> Result<Self> {
        if !path.exists() {
            return Err(DatasetError::MissingFile {
                path: path.to_owned(),
                what: "sensor description".into(),
            });
        }
        let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
        Self::parse(path, &text)
    }

    /// Parses text; `path` is only used in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let lines = logical_lines(path, text)?;
        let mut idx = 0;
        let indent = lines.first().map_or(0, |l| l.indent);
        let root = parse_map(path, &lines, &mut idx, indent)?;
        if let Some(line) = lines.get(idx) {
            return Err(DatasetError::parse(
                path,
                line.number,
                "unexpected indentation",
            ));
        }
        Ok(Yaml {
            path: path.to_owned(),
            root,
        })
    }

    /// The file this was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A top-level key.
    pub fn get(&self, key: &str) -> Option<&Node> {
        lookup(&self.root, key)
    }

    /// A required top-level key.
    pub fn require(&self, key: &str) -> Result<&Node> {
        self.get(key).ok_or_else(|| DatasetError::MissingKey {
            path: self.path.clone(),
            key: key.to_owned(),
        })
    }

    /// A required number.
    pub fn f64(&self, key: &str) -> Result<f64> {
        let node = self.require(key)?;
        match &node.value {
            Value::Scalar(s) => self.number(key, s, node.line),
            _ => Err(DatasetError::parse(
                &self.path,
                node.line,
                format!("`{key}` must be a number"),
            )),
        }
    }

    /// A required string.
    pub fn str(&self, key: &str) -> Result<&str> {
        let node = self.require(key)?;
        match &node.value {
            Value::Scalar(s) => Ok(s),
            _ => Err(DatasetError::parse(
                &self.path,
                node.line,
                format!("`{key}` must be a single value"),
            )),
        }
    }

    /// A required list of exactly `n` numbers.
    pub fn f64_list(&self, key: &str, n: usize) -> Result<Vec<f64>> {
        let node = self.require(key)?;
        self.numbers(key, node, n)
    }

    /// A 4×4 row-major matrix given either as an OpenCV-style map (`rows`, `cols`, `data`) or as a
    /// flat or block list of 16 numbers.
    pub fn matrix4(&self, key: &str) -> Result<[f64; 16]> {
        let node = self.require(key)?;
        let values = match &node.value {
            Value::Map(entries) => {
                for (dim, expected) in [("rows", 4.0), ("cols", 4.0)] {
                    if let Some(n) = lookup(entries, dim) {
                        let v = match &n.value {
                            Value::Scalar(s) => self.number(dim, s, n.line)?,
                            _ => f64::NAN,
                        };
                        if v != expected {
                            return Err(DatasetError::parse(
                                &self.path,
                                n.line,
                                format!("`{key}.{dim}` must be 4"),
                            ));
                        }
                    }
                }
                let data = lookup(entries, "data").ok_or_else(|| DatasetError::MissingKey {
                    path: self.path.clone(),
                    key: format!("{key}.data"),
                })?;
                self.numbers(&format!("{key}.data"), data, 16)?
            }
            _ => self.numbers(key, node, 16)?,
        };
        let mut m = [0.0; 16];
        m.copy_from_slice(&values);
        Ok(m)
    }

    fn numbers(&self, key: &str, node: &Node, n: usize) -> Result<Vec<f64>> {
        let Value::List(items) = &node.value else {
            return Err(DatasetError::parse(
                &self.path,
                node.line,
                format!("`{key}` must be a list of {n} numbers"),
            ));
        };
        if items.len() != n {
            return Err(DatasetError::parse(
                &self.path,
                node.line,
                format!("`{key}` has {} values, expected {n}", items.len()),
            ));
        }
        items
            .iter()
            .map(|s| self.number(key, s, node.line))
            .collect()
    }

    fn number(&self, key: &str, s: &str, line: usize) -> Result<f64> {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                DatasetError::parse(&self.path, line, format!("`{key}`: '{s}' is not a number"))
            })
    }
}

fn lookup<'a>(entries: &'a [(String, Node)], key: &str) -> Option<&'a Node> {
    entries.iter().find(|(k, _)| k == key).map(|(_, n)| n)
}

/// Removes a `#` comment that is not inside quotes.
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    let mut prev_space = true;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (None, '"' | '\'') => quote = Some(c),
            (None, '#') if prev_space => return &line[..i],
            _ => {}
        }
        prev_space = c.is_whitespace();
    }
    line
}

fn logical_lines(path: &Path, text: &str) -> Result<Vec<Line>> {
    let mut out: Vec<Line> = Vec::new();
    let mut open_list: Option<usize> = None; // index in `out` of a line whose `[` is not closed yet
    for (i, raw) in text.lines().enumerate() {
        let number = i + 1;
        let body = strip_comment(raw).trim_end();
        if let Some(at) = open_list {
            out[at].text.push(' ');
            out[at].text.push_str(body.trim());
            if bracket_depth(&out[at].text) <= 0 {
                open_list = None;
            }
            continue;
        }
        let trimmed = body.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('%') || trimmed == "---" || trimmed == "..." {
            continue;
        }
        if body.contains('\t') && body.starts_with('\t') {
            return Err(DatasetError::parse(
                path,
                number,
                "tab indentation is not YAML",
            ));
        }
        let indent = body.len() - trimmed.len();
        out.push(Line {
            number,
            indent,
            text: trimmed.to_owned(),
        });
        if bracket_depth(trimmed) > 0 {
            open_list = Some(out.len() - 1);
        }
    }
    if let Some(at) = open_list {
        return Err(DatasetError::parse(
            path,
            out[at].number,
            "unterminated `[` list",
        ));
    }
    Ok(out)
}

fn bracket_depth(s: &str) -> i32 {
    s.chars()
        .map(|c| i32::from(c == '[') - i32::from(c == ']'))
        .sum()
}

fn parse_map(
    path: &Path,
    lines: &[Line],
    idx: &mut usize,
    indent: usize,
) -> Result<Vec<(String, Node)>> {
    let mut entries = Vec::new();
    while let Some(line) = lines.get(*idx) {
        if line.indent < indent {
            break;
        }
        if line.indent > indent {
            return Err(DatasetError::parse(
                path,
                line.number,
                "unexpected indentation",
            ));
        }
        let (key, rest) = split_key(&line.text).ok_or_else(|| {
            DatasetError::parse(
                path,
                line.number,
                format!("expected `key: value`, found '{}'", line.text),
            )
        })?;
        *idx += 1;
        let value = if rest.is_empty() {
            parse_nested(path, lines, idx, indent)?
        } else if rest.starts_with('[') {
            Value::List(inline_list(rest))
        } else {
            Value::Scalar(unquote(rest).to_owned())
        };
        entries.push((
            key.to_owned(),
            Node {
                value,
                line: line.number,
            },
        ));
    }
    Ok(entries)
}

/// The value of a `key:` line with nothing after the colon: a block list, a nested map, or empty.
fn parse_nested(path: &Path, lines: &[Line], idx: &mut usize, indent: usize) -> Result<Value> {
    let Some(next) = lines.get(*idx) else {
        return Ok(Value::Empty);
    };
    // YAML allows a block list at the same indentation as its key.
    if next.text.starts_with('-') && next.indent >= indent {
        let list_indent = next.indent;
        let mut items = Vec::new();
        while let Some(l) = lines
            .get(*idx)
            .filter(|l| l.indent == list_indent && l.text.starts_with('-'))
        {
            let item = l.text[1..].trim();
            if item.starts_with('[') {
                items.extend(inline_list(item));
            } else {
                items.push(unquote(item).to_owned());
            }
            *idx += 1;
        }
        return Ok(Value::List(items));
    }
    if next.indent > indent {
        return Ok(Value::Map(parse_map(path, lines, idx, next.indent)?));
    }
    Ok(Value::Empty)
}

fn split_key(text: &str) -> Option<(&str, &str)> {
    let (key, rest) = if let Some(k) = text.strip_suffix(':') {
        (k, "")
    } else {
        let at = text.find(": ")?;
        (&text[..at], text[at + 2..].trim())
    };
    let key = unquote(key.trim());
    (!key.is_empty()).then_some((key, rest))
}

/// The items of `[a, b, [c, d]]`, flattened, unquoted and trimmed.
fn inline_list(text: &str) -> Vec<String> {
    text.split([',', '[', ']'])
        .map(|s| unquote(s.trim()))
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
        .collect()
}

fn unquote(s: &str) -> &str {
    let s = s.trim();
    for q in ['"', '\''] {
        if let Some(inner) = s.strip_prefix(q).and_then(|r| r.strip_suffix(q)) {
            return inner;
        }
    }
    s
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const EUROC_CAM: &str = "%YAML:1.0\n# General sensor definitions.\nsensor_type: camera\ncomment: VI-Sensor cam0 (MT9M034)\n\nT_BS:\n  cols: 4\n  rows: 4\n  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,\n         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,\n        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,\n         0.0, 0.0, 0.0, 1.0]\n\nrate_hz: 20\nresolution: [752, 480]\ncamera_model: pinhole\nintrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv\ndistortion_model: radial-tangential\ndistortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\n";

    #[test]
    fn parses_euroc_camera() {
        let y = Yaml::parse(Path::new("cam0/sensor.yaml"), EUROC_CAM).unwrap();
        assert_eq!(y.f64("rate_hz").unwrap(), 20.0);
        assert_eq!(y.f64_list("intrinsics", 4).unwrap()[3], 248.375);
        assert_eq!(y.str("distortion_model").unwrap(), "radial-tangential");
        let m = y.matrix4("T_BS").unwrap();
        assert_eq!(m[1], -0.999880929698);
        assert_eq!(m[15], 1.0);
        assert_eq!(y.get("T_BS").unwrap().line, 6);
    }

    #[test]
    fn block_lists_and_flat_matrix() {
        let text = "T_BS: [1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\norigin:\n- 47.0\n- 8.0\n- 400.0\n";
        let y = Yaml::parse(Path::new("x.yaml"), text).unwrap();
        assert_eq!(y.matrix4("T_BS").unwrap()[3], 0.5);
        assert_eq!(y.f64_list("origin", 3).unwrap(), vec![47.0, 8.0, 400.0]);
    }

    #[test]
    fn errors_name_file_and_line() {
        let y = Yaml::parse(
            Path::new("imu0/sensor.yaml"),
            "rate_hz: 200\n\ngyroscope_noise_density: abc\n",
        )
        .unwrap();
        let e = y.f64("gyroscope_noise_density").unwrap_err().to_string();
        assert!(e.starts_with("imu0/sensor.yaml:3:"), "{e}");
        let e = y
            .f64("accelerometer_noise_density")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("missing key `accelerometer_noise_density`"),
            "{e}"
        );
        let e = Yaml::parse(Path::new("a.yaml"), "a: 1\nnot a mapping\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("a.yaml:2:"), "{e}");
        let e = Yaml::parse(Path::new("a.yaml"), "a: [1, 2,\n 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unterminated"), "{e}");
    }
}
