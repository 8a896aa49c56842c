//! A streaming reader for the EuRoC/ASL `data.csv` files: a `#`-prefixed header naming the columns
//! (units in brackets are ignored when matching), then one comma-separated row per line. Columns
//! are found by name, so extra or reordered columns are fine; spaces around cells are trimmed.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use crate::error::{DatasetError, Result};

/// An open `data.csv` positioned after its header.
#[derive(Debug)]
pub struct CsvReader {
    path: PathBuf,
    reader: BufReader<File>,
    line: usize,
    buf: String,
    /// For each requested column, its index in the file.
    index: Vec<usize>,
    names: Vec<&'static str>,
}

/// One data row: the cells of the requested columns, in request order.
#[derive(Debug)]
pub struct Row<'a> {
    reader: &'a CsvReader,
    cells: Vec<&'a str>,
}

/// The column name without `#`, units in brackets, or surrounding space.
fn column_key(header_cell: &str) -> &str {
    let s = header_cell.trim().trim_start_matches('#').trim();
    s.split('[').next().unwrap_or(s).trim()
}

impl CsvReader {
    /// Opens a file and locates the `columns` (names without units) in its header.
    pub fn open(path: &Path, columns: &[&'static str]) -> Result<Self> {
        let file = File::open(path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                DatasetError::MissingFile {
                    path: path.to_owned(),
                    what: "sensor data".into(),
                }
            } else {
                DatasetError::io(path, e)
            }
        })?;
        let mut r = CsvReader {
            path: path.to_owned(),
            reader: BufReader::new(file),
            line: 0,
            buf: String::new(),
            index: Vec::new(),
            names: columns.to_vec(),
        };
        if !r.read_line()? {
            return Err(DatasetError::parse(
                path,
                1,
                "empty file: expected a `#timestamp,...` header",
            ));
        }
        let header: Vec<&str> = r.buf.split(',').map(column_key).collect();
        let mut index = Vec::with_capacity(columns.len());
        for name in columns {
            let at = header.iter().position(|h| h == name).ok_or_else(|| {
                DatasetError::parse(
                    path,
                    r.line,
                    format!(
                        "missing column `{name}` (header has: {})",
                        header.join(", ")
                    ),
                )
            })?;
            index.push(at);
        }
        r.index = index;
        Ok(r)
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The 1-based number of the line last read.
    pub fn line(&self) -> usize {
        self.line
    }

    /// Reads the next non-blank line into `buf`; false at end of file.
    fn read_line(&mut self) -> Result<bool> {
        loop {
            self.buf.clear();
            let n = self
                .reader
                .read_line(&mut self.buf)
                .map_err(|e| DatasetError::io(&self.path, e))?;
            if n == 0 {
                return Ok(false);
            }
            self.line += 1;
            let trimmed_len = self.buf.trim_end().len();
            self.buf.truncate(trimmed_len);
            if !self.buf.trim().is_empty() {
                return Ok(true);
            }
        }
    }

    /// The next data row, `None` at end of file.
    pub fn next_row(&mut self) -> Option<Result<Row<'_>>> {
        match self.read_line() {
            Ok(true) => {}
            Ok(false) => return None,
            Err(e) => return Some(Err(e)),
        }
        let all: Vec<&str> = self.buf.split(',').map(str::trim).collect();
        let mut cells = Vec::with_capacity(self.index.len());
        for (&at, name) in self.index.iter().zip(&self.names) {
            match all.get(at) {
                Some(c) => cells.push(*c),
                None => {
                    return Some(Err(DatasetError::parse(
                        &self.path,
                        self.line,
                        format!("missing column `{name}`: row has {} cells", all.len()),
                    )));
                }
            }
        }
        Some(Ok(Row {
            reader: self,
            cells,
        }))
    }
}

impl Row<'_> {
    /// The 1-based line number.
    pub fn line(&self) -> usize {
        self.reader.line
    }

    fn error(&self, col: usize, what: &str) -> DatasetError {
        DatasetError::parse(
            &self.reader.path,
            self.reader.line,
            format!(
                "column `{}`: '{}' is not {what}",
                self.reader.names[col], self.cells[col]
            ),
        )
    }

    /// A parse error about this row as a whole.
    pub fn invalid(&self, message: impl Into<String>) -> DatasetError {
        DatasetError::parse(&self.reader.path, self.reader.line, message.into())
    }

    /// Cell `col` (request order) as text.
    pub fn str(&self, col: usize) -> &str {
        self.cells[col]
    }

    /// Cell `col` as an integer.
    pub fn i64(&self, col: usize) -> Result<i64> {
        self.cells[col]
            .parse()
            .map_err(|_| self.error(col, "an integer"))
    }

    /// Cell `col` as a finite number.
    pub fn f64(&self, col: usize) -> Result<f64> {
        self.cells[col]
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| self.error(col, "a finite number"))
    }

    /// Cell `col` as a finite number, or `None` when the cell is empty (an optional value).
    pub fn opt_f64(&self, col: usize) -> Result<Option<f64>> {
        if self.cells[col].trim().is_empty() {
            Ok(None)
        } else {
            self.f64(col).map(Some)
        }
    }

    /// Cells `first..first + N` as numbers.
    pub fn f64s<const N: usize>(&self, first: usize) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for (i, v) in out.iter_mut().enumerate() {
            *v = self.f64(first + i)?;
        }
        Ok(out)
    }
}

/// Checks that timestamps strictly increase, naming the file and line otherwise.
#[derive(Debug, Default)]
pub struct Monotonic {
    prev: Option<i64>,
}

impl Monotonic {
    /// Accepts `t_ns` if it is after the previous one.
    pub fn check(&mut self, path: &Path, line: usize, t_ns: i64) -> Result<()> {
        if let Some(prev) = self.prev.filter(|&p| t_ns <= p) {
            return Err(DatasetError::TimeBackwards {
                path: path.to_owned(),
                line,
                t_ns,
                prev_t_ns: prev,
            });
        }
        self.prev = Some(t_ns);
        Ok(())
    }
}
