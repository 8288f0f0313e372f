//! [`ImportError`]: what went wrong reading a file, and where.

use std::fmt;
use std::path::{Path, PathBuf};

/// An input file that cannot be read as the expected format.
///
/// It names the file and, where they are known, the 1-based line and column
/// and the name of the field (for example `RB1(Orange) Y` or `cube qw`).
/// Displayed as
/// `path/to/file.tsv:1234: column 5 (RB1(Orange) Y): expected a number, found "abc"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImportError {
    /// The file being read.
    pub file: PathBuf,
    /// Line number, 1-based, when the problem is on one line.
    pub line: Option<usize>,
    /// Column (field) number within the line, 1-based.
    pub column: Option<usize>,
    /// Name of the field, e.g. `RB1(Orange) X` or `cube qw`.
    pub field: Option<String>,
    /// What is wrong, phrased for a person (what was expected, what was found).
    pub message: String,
}

impl ImportError {
    /// An error about the whole file.
    pub fn new(file: &Path, message: impl Into<String>) -> Self {
        ImportError {
            file: file.to_path_buf(),
            line: None,
            column: None,
            field: None,
            message: message.into(),
        }
    }

    /// An error on one line (1-based).
    pub fn at_line(file: &Path, line: usize, message: impl Into<String>) -> Self {
        ImportError {
            line: Some(line),
            ..ImportError::new(file, message)
        }
    }

    /// Sets the 1-based column.
    pub fn with_column(mut self, column: usize) -> Self {
        self.column = Some(column);
        self
    }

    /// Sets the field name.
    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        self.field = Some(field.into());
        self
    }
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        match (self.column, &self.field) {
            (Some(c), Some(name)) => write!(f, ": column {c} ({name})")?,
            (Some(c), None) => write!(f, ": column {c}")?,
            (None, Some(name)) => write!(f, ": {name}")?,
            (None, None) => {}
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for ImportError {}

/// Shows at most `max` bytes of a cell for an error message, quoted, with
/// invalid UTF-8 replaced and control characters escaped.
pub(crate) fn show_bytes(cell: &[u8], max: usize) -> String {
    let cut = cell.len() > max;
    let text = String::from_utf8_lossy(&cell[..cell.len().min(max)]);
    let mut s = format!("{:?}", text);
    if cut {
        s.push_str("...");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_names_file_line_column_field() {
        let e = ImportError::at_line(
            Path::new("path/to/file.tsv"),
            1234,
            "expected a number, found \"abc\"",
        )
        .with_column(5)
        .with_field("RB1(Orange) Y");
        assert_eq!(
            e.to_string(),
            "path/to/file.tsv:1234: column 5 (RB1(Orange) Y): expected a number, found \"abc\""
        );
        let e = ImportError::new(Path::new("a.csv"), "the file is empty");
        assert_eq!(e.to_string(), "a.csv: the file is empty");
        let e = ImportError::new(Path::new("a.csv"), "bad").with_field("cube qw");
        assert_eq!(e.to_string(), "a.csv: cube qw: bad");
    }

    #[test]
    fn show_bytes_is_safe() {
        assert_eq!(show_bytes(b"abc", 10), "\"abc\"");
        assert_eq!(show_bytes(b"abcdef", 3), "\"abc\"...");
        assert_eq!(show_bytes(&[0xff, b'\t'], 10), "\"\u{fffd}\\t\"");
        // Cutting inside a multi-byte character must not panic.
        let _ = show_bytes("é".as_bytes(), 1);
    }
}
