//! Simulator output recorded elsewhere: one row of 14 numbers per control
//! step (the study's MuJoCo, PyBullet and V-Rep files).
//!
//! # Format
//!
//! Each row: wrist position `x y z` (m), wrist orientation quaternion (4
//! numbers, order given by [`QuatOrder`]), cube position `x y z` (m), cube
//! quaternion. Numbers are separated by spaces, tabs or commas; line ends
//! are CRLF or LF. `nan`, `inf`, `-inf` and exponents (`1e17`, `2.07E-19`)
//! are numbers. Leading lines that start with a word (a column-name header)
//! are skipped with a warning. Row `i` is at time `i * control_period_s`.
//!
//! # What is kept as read, and flagged
//!
//! - Rows whose 14 numbers are all exactly zero (a simulator that wrote
//!   nothing for that step) are kept, at the origin with identity
//!   orientation, and listed in [`ImportedRun::zero_rows`].
//! - A quaternion whose norm is off 1 by more than the tolerance, or not
//!   finite, puts the row in [`ImportedRun::bad_norm_rows`]; finite non-zero
//!   quaternions are then normalised, others kept as read.
//! - Huge or non-finite positions (a diverged simulation) are kept as read,
//!   with a warning (beyond 1 km, or NaN/inf); the analysis decides what
//!   diverged means.
//!
//! A row with another count of numbers, or a cell that is not a number, is an
//! [`ImportError`] with line, column and field; a last line without a line
//! end that is incomplete (as an interrupted copy leaves it) is dropped with
//! a warning.

use crate::error::{show_bytes, ImportError};
use crate::text::{parse_f64_str, Lines};
use crate::ImportedRun;
use realitygap_core::trajectory::{CUBE, WRIST};
use realitygap_core::{BodyTrack, Pose, Quat, Trajectory, Vec3};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;
use std::str::FromStr;

/// Numbers per row.
const NUMBERS: usize = 14;
/// Positions farther than this from the origin (m) get a warning: no lab
/// robot reaches a kilometre.
const FAR_M: f64 = 1000.0;

/// Order of a quaternion's four numbers in a recorded file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QuatOrder {
    /// Scalar first: `w x y z` (MuJoCo).
    Wxyz,
    /// Scalar last: `x y z w` (PyBullet, V-Rep).
    Xyzw,
}

impl QuatOrder {
    /// The quaternion from its four numbers in this order (no normalisation).
    pub fn quat(self, v: &[f64; 4]) -> Quat {
        match self {
            QuatOrder::Wxyz => Quat::new(v[0], v[1], v[2], v[3]),
            QuatOrder::Xyzw => Quat::new(v[3], v[0], v[1], v[2]),
        }
    }

    /// Names of the four components in file order.
    fn component_names(self) -> [&'static str; 4] {
        match self {
            QuatOrder::Wxyz => ["qw", "qx", "qy", "qz"],
            QuatOrder::Xyzw => ["qx", "qy", "qz", "qw"],
        }
    }
}

impl fmt::Display for QuatOrder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            QuatOrder::Wxyz => "wxyz",
            QuatOrder::Xyzw => "xyzw",
        })
    }
}

impl FromStr for QuatOrder {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "wxyz" => Ok(QuatOrder::Wxyz),
            "xyzw" => Ok(QuatOrder::Xyzw),
            _ => Err(format!(
                "unknown quaternion order '{s}': expected wxyz or xyzw"
            )),
        }
    }
}

/// How to read a recorded simulator file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordedOptions {
    /// Order of the quaternion numbers.
    pub quat_order: QuatOrder,
    /// Time between rows in seconds (the control period; 0.05 s in the study).
    pub control_period_s: f64,
    /// Largest accepted deviation of a quaternion's norm from 1 (default 1e-3).
    pub norm_tolerance: f64,
}

impl RecordedOptions {
    /// Options with the study's control period (0.05 s) and a norm
    /// tolerance of 1e-3.
    pub fn new(quat_order: QuatOrder) -> Self {
        RecordedOptions {
            quat_order,
            control_period_s: 0.05,
            norm_tolerance: 1e-3,
        }
    }
}

/// Reads a recorded simulator file (see the module docs).
pub fn read(path: &Path, opts: &RecordedOptions) -> Result<ImportedRun, ImportError> {
    let bytes = std::fs::read(path)
        .map_err(|e| ImportError::new(path, format!("cannot read the file: {e}")))?;
    parse(&bytes, path, opts)
}

/// Name of the `i`th number of a row (0-based), e.g. `cube qw`.
fn field_name(order: QuatOrder, i: usize) -> String {
    let body = if i < 7 { "wrist" } else { "cube" };
    let k = i % 7;
    let comp = if k < 3 {
        ["x", "y", "z"][k]
    } else {
        order.component_names()[k - 3]
    };
    format!("{body} {comp}")
}

/// Splits a line into cells: on commas when it has any (cells trimmed of
/// spaces and tabs; one trailing comma allowed), else on runs of spaces and
/// tabs. Returns the cell count and fills `out` with the byte ranges of the
/// first `out.len()` cells. An empty cell between commas is reported as
/// `Err(0-based column)`.
fn split_cells(line: &[u8], out: &mut [(usize, usize)]) -> Result<usize, usize> {
    let mut count = 0;
    let mut push = |start: usize, end: usize| {
        if let Some(slot) = out.get_mut(count) {
            *slot = (start, end);
        }
        count += 1;
    };
    let is_space = |b: u8| b == b' ' || b == b'\t';
    if line.contains(&b',') {
        let n = line.iter().filter(|&&b| b == b',').count() + 1;
        let mut from = 0;
        for i in 0..n {
            let to = line[from..]
                .iter()
                .position(|&b| b == b',')
                .map_or(line.len(), |p| from + p);
            let mut start = from;
            let mut end = to;
            while start < end && is_space(line[start]) {
                start += 1;
            }
            while end > start && is_space(line[end - 1]) {
                end -= 1;
            }
            if start == end {
                if i + 1 == n && i > 0 {
                    break; // trailing comma
                }
                return Err(i);
            }
            push(start, end);
            from = to + 1;
        }
    } else {
        let mut i = 0;
        while i < line.len() {
            if is_space(line[i]) {
                i += 1;
                continue;
            }
            let start = i;
            while i < line.len() && !is_space(line[i]) {
                i += 1;
            }
            push(start, i);
        }
    }
    Ok(count)
}

/// Parses the bytes of a recorded simulator file; `file` is used in
/// messages only. Never panics, whatever the bytes.
/// Checks the options: a positive control period, a norm tolerance >= 0.
fn check_options(opts: &RecordedOptions, file: &Path) -> Result<(), ImportError> {
    if !(opts.control_period_s.is_finite() && opts.control_period_s > 0.0) {
        return Err(ImportError::new(
            file,
            format!(
                "the control period {} s is not positive",
                opts.control_period_s
            ),
        ));
    }
    if opts.norm_tolerance.is_nan() || opts.norm_tolerance < 0.0 {
        return Err(ImportError::new(
            file,
            format!("the norm tolerance {} is not >= 0", opts.norm_tolerance),
        ));
    }
    Ok(())
}

/// The samples read so far, and the rows worth a warning.
#[derive(Default)]
struct Samples {
    wrist: Vec<Option<Pose>>,
    cube: Vec<Option<Pose>>,
    zero_rows: Vec<usize>,
    bad_norm_rows: Vec<usize>,
    non_finite_rows: Vec<usize>,
    far_rows: Vec<(usize, f64)>,
}

impl Samples {
    /// Adds one row: an all-zero row becomes identity poses (and is noted);
    /// quaternions are normalised, a norm off 1 by more than
    /// `norm_tolerance` noted.
    fn push(&mut self, v: [f64; NUMBERS], order: QuatOrder, norm_tolerance: f64) {
        let index = self.wrist.len();
        if v.iter().all(|&x| x == 0.0) {
            self.zero_rows.push(index);
            self.wrist.push(Some(Pose::IDENTITY));
            self.cube.push(Some(Pose::IDENTITY));
            return;
        }
        if v.iter().any(|x| !x.is_finite()) {
            self.non_finite_rows.push(index);
        }
        let farthest = [v[0], v[1], v[2], v[7], v[8], v[9]]
            .iter()
            .map(|x| x.abs())
            .fold(0.0, f64::max);
        if farthest > FAR_M {
            self.far_rows.push((index, farthest));
        }
        let mut norm_off = false;
        for (offset, track) in [(0, &mut self.wrist), (7, &mut self.cube)] {
            let position = Vec3::new(v[offset], v[offset + 1], v[offset + 2]);
            let q = order.quat(&[v[offset + 3], v[offset + 4], v[offset + 5], v[offset + 6]]);
            let norm = q.norm();
            if norm.is_nan() || (norm - 1.0).abs() > norm_tolerance {
                norm_off = true;
            }
            let orientation = if norm == 0.0 {
                Quat::IDENTITY
            } else {
                q.normalized().unwrap_or(q)
            };
            track.push(Some(Pose::new(position, orientation)));
        }
        if norm_off {
            self.bad_norm_rows.push(index);
        }
    }

    /// The warnings on the rows noted.
    fn warnings(&self, norm_tolerance: f64, warnings: &mut Vec<String>) {
        let (zero_rows, bad_norm_rows, far_rows, non_finite_rows) = (
            &self.zero_rows,
            &self.bad_norm_rows,
            &self.far_rows,
            &self.non_finite_rows,
        );
        if !zero_rows.is_empty() {
            warnings.push(format!(
                "{} rows are all zero (samples {}): the simulator wrote nothing there",
                zero_rows.len(),
                ranges(zero_rows)
            ));
        }
        if !bad_norm_rows.is_empty() {
            warnings.push(format!(
                "{} rows have a quaternion whose norm is off 1 by more than {} (samples {})",
                bad_norm_rows.len(),
                norm_tolerance,
                ranges(bad_norm_rows)
            ));
        }
        if let Some(&(first, _)) = far_rows.first() {
            let largest = far_rows.iter().map(|r| r.1).fold(0.0, f64::max);
            warnings.push(format!(
                "{} rows have positions beyond {FAR_M} m (first at sample {first}, largest {largest:e} m): \
                 the simulation probably diverged",
                far_rows.len()
            ));
        }
        if !non_finite_rows.is_empty() {
            warnings.push(format!(
                "{} rows hold non-finite values (samples {}): the simulation diverged",
                non_finite_rows.len(),
                ranges(non_finite_rows)
            ));
        }
    }
}

/// The run read: the errors and warnings on what the rows held, then the
/// trajectory on the control grid.
fn into_run(
    samples: Samples,
    header_lines: usize,
    opts: &RecordedOptions,
    file: &Path,
    mut warnings: Vec<String>,
) -> Result<ImportedRun, ImportError> {
    if samples.wrist.is_empty() {
        let what = if header_lines > 0 {
            format!("the file has no data rows, only {header_lines} line(s) of words (taken for column names)")
        } else {
            "the file has no complete data rows".to_string()
        };
        return Err(ImportError::new(file, what));
    }
    if header_lines > 0 {
        warnings.push(format!(
            "skipped {header_lines} header line(s) before the data"
        ));
    }
    samples.warnings(opts.norm_tolerance, &mut warnings);
    let Samples {
        wrist,
        cube,
        zero_rows,
        bad_norm_rows,
        ..
    } = samples;
    let samples = wrist.len();
    let trajectory = Trajectory {
        time_s: (0..samples)
            .map(|i| i as f64 * opts.control_period_s)
            .collect(),
        bodies: vec![
            BodyTrack {
                role: WRIST.into(),
                poses: wrist,
            },
            BodyTrack {
                role: CUBE.into(),
                poses: cube,
            },
        ],
        ..Trajectory::default()
    };
    Ok(ImportedRun {
        trajectory,
        frequency_hz: 1.0 / opts.control_period_s,
        source_file: file.to_path_buf(),
        body_names: vec![WRIST.into(), CUBE.into()],
        warnings,
        zero_rows,
        bad_norm_rows,
    })
}

/// The fourteen numbers of a row, or where and why it is not one.
fn row_numbers(
    split: Result<usize, usize>,
    cells: &[&str; NUMBERS],
    order: QuatOrder,
    file: &Path,
    line: usize,
) -> Result<[f64; NUMBERS], ImportError> {
    match split {
        Err(col) => Err(ImportError::at_line(file, line, "expected a number, found an empty cell")
            .with_column(col + 1)
            .with_field(field_name(order, col.min(NUMBERS - 1)))),
        Ok(n) => parse_numbers(&cells[..n.min(NUMBERS)]).map_err(|i| {
            ImportError::at_line(file, line, format!("expected a number, found {}", show_bytes(cells[i].as_bytes(), 40)))
                .with_column(i + 1)
                .with_field(field_name(order, i))
        }).and_then(|v| {
            if n == NUMBERS {
                return Ok(v);
            }
            let what = if n < NUMBERS {
                format!("the row ends after {n}, before {}", field_name(order, n))
            } else {
                format!("the row has {n}")
            };
            Err(ImportError::at_line(
                file,
                line,
                format!(
                    "expected {NUMBERS} numbers (wrist x y z, wrist quaternion {order}, cube x y z, \
                     cube quaternion {order}), but {what}"
                ),
            )
            .with_column(n.min(NUMBERS) + 1))
        }),
    }
}

/// Parses the bytes of a recorded simulator file; `file` is used in
/// messages only. Never panics, whatever the bytes.
pub fn parse(
    bytes: &[u8],
    file: &Path,
    opts: &RecordedOptions,
) -> Result<ImportedRun, ImportError> {
    check_options(opts, file)?;
    let order = opts.quat_order;
    let mut warnings = Vec::new();
    let mut samples = Samples::default();
    let mut header_lines = 0usize;
    let mut any_content = false;
    let mut ranges_buf = [(0usize, 0usize); NUMBERS];

    for line in Lines::new(bytes) {
        if line.bytes.iter().all(|&b| b == b' ' || b == b'\t') {
            continue;
        }
        any_content = true;
        // Validate the line's UTF-8 once; a damaged line is read lossily so
        // the bad cell shows up as a non-number at its own column.
        let lossy;
        let text: &str = match std::str::from_utf8(line.bytes) {
            Ok(s) => s,
            Err(_) => {
                lossy = String::from_utf8_lossy(line.bytes);
                &lossy
            }
        };
        let split = split_cells(text.as_bytes(), &mut ranges_buf);
        let cells: [&str; NUMBERS] =
            std::array::from_fn(|i| text.get(ranges_buf[i].0..ranges_buf[i].1).unwrap_or(""));
        // A column-name header before the data.
        if samples.wrist.is_empty() && split.is_ok() {
            let first = cells[0];
            if first
                .as_bytes()
                .first()
                .is_some_and(u8::is_ascii_alphabetic)
                && parse_f64_str(first).is_none()
            {
                header_lines += 1;
                continue;
            }
        }
        let row = row_numbers(split, &cells, order, file, line.number);
        let v = match row {
            Ok(v) => v,
            Err(e) => {
                // Cut short: too few cells, or the last cell present is not a
                // number, on a last line without a line end.
                let short =
                    matches!(split, Ok(n) if n <= NUMBERS && e.column.is_some_and(|c| c >= n));
                if !line.terminated && short {
                    warnings.push(format!(
                        "line {}: the last line is cut short and was dropped",
                        line.number
                    ));
                    break;
                }
                return Err(e);
            }
        };

        samples.push(v, order, opts.norm_tolerance);
    }
    if !any_content {
        return Err(ImportError::new(file, "the file is empty"));
    }
    into_run(samples, header_lines, opts, file, warnings)
}

/// Parses cells as numbers; on failure the index of the first bad cell.
fn parse_numbers(cells: &[&str]) -> Result<[f64; NUMBERS], usize> {
    let mut v = [0.0; NUMBERS];
    for (i, (slot, cell)) in v.iter_mut().zip(cells).enumerate() {
        *slot = parse_f64_str(cell).ok_or(i)?;
    }
    Ok(v)
}

/// Sorted indices as compact ranges, e.g. `3, 7-9, 12`; at most 6 ranges
/// then `...`.
pub(crate) fn ranges(indices: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < indices.len() {
        let start = indices[i];
        let mut end = start;
        while i + 1 < indices.len() && indices[i + 1] == end + 1 {
            end += 1;
            i += 1;
        }
        i += 1;
        if parts.len() == 6 {
            parts.push("...".into());
            break;
        }
        parts.push(if start == end {
            start.to_string()
        } else {
            format!("{start}-{end}")
        });
    }
    parts.join(", ")
}

#[cfg(test)]
mod tests;
