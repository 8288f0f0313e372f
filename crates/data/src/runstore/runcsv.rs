//! The run CSV (see the [parent module](super) for the layout): written and
//! read here, in named steps.
//!
//! Not with the `csv` crate: measured on the study's 480 runs (`cargo bench
//! -p realitygap-data --bench import`), csv 1.4 formatted 13 % and parsed
//! 23 % slower (CPU time) than this code, and the format needs none of
//! its quoting (roles are kept free of `,`, `"` and line breaks).

use super::StoreError;
use crate::error::{show_bytes, ImportError};
use crate::text::{parse_f64_str, Lines};
use realitygap_core::{Pose, Quat, Trajectory, TrajectoryError, Vec3};
use std::fmt::Write as _;
use std::fs;
use std::path::Path;

/// Suffixes of a body's seven columns.
const BODY_SUFFIXES: [&str; 7] = ["_x_m", "_y_m", "_z_m", "_qw", "_qx", "_qy", "_qz"];

/// Appends a number in the shortest form that reads back to the same
/// `f64`; exponent form for magnitudes below 1e-5 or from 1e16 on.
pub(crate) fn push_f64(out: &mut String, x: f64) {
    let a = x.abs();
    let _ = if x.is_nan() {
        out.write_str("NaN")
    } else if a == 0.0 || a.is_infinite() || (1e-5..1e16).contains(&a) {
        write!(out, "{x}")
    } else {
        write!(out, "{x:e}")
    };
}

/// An [`StoreError::InvalidTrajectory`] without run id (the caller adds it).
fn invalid(message: String) -> StoreError {
    StoreError::InvalidTrajectory {
        id: String::new(),
        message,
    }
}

/// Checks that a trajectory can be written as run CSV: valid, roles usable
/// as column prefixes, finite times.
fn check_writable(trajectory: &Trajectory) -> Result<(), StoreError> {
    trajectory
        .validate()
        .map_err(|e: TrajectoryError| invalid(e.to_string()))?;
    for b in &trajectory.bodies {
        if b.role.is_empty() || b.role.contains([',', '"', '\n', '\r']) {
            return Err(invalid(format!(
                "body role {:?} cannot be a CSV column prefix",
                b.role
            )));
        }
    }
    if let Some(i) = trajectory.time_s.iter().position(|t| !t.is_finite()) {
        return Err(invalid(format!("sample {i} has a non-finite time")));
    }
    Ok(())
}

/// Number of values per row in optional per-sample rows (0 when absent).
fn row_width(rows: &Option<Vec<Vec<f64>>>) -> usize {
    rows.as_ref().and_then(|r| r.first()).map_or(0, Vec::len)
}

/// Appends the header line.
fn push_header(out: &mut String, trajectory: &Trajectory) {
    out.push_str("t_s");
    for b in &trajectory.bodies {
        for s in BODY_SUFFIXES {
            let _ = write!(out, ",{}{s}", b.role);
        }
    }
    for j in 1..=row_width(&trajectory.joint_angles_rad) {
        let _ = write!(out, ",q{j}_rad");
    }
    for j in 1..=row_width(&trajectory.joint_velocity_commands_rad_s) {
        let _ = write!(out, ",qd_cmd{j}_rad_s");
    }
    for j in 1..=row_width(&trajectory.joint_velocities_rad_s) {
        let _ = write!(out, ",qd{j}_rad_s");
    }
    for j in 1..=row_width(&trajectory.joint_efforts_nm) {
        let _ = write!(out, ",tau{j}_nm");
    }
    out.push('\n');
}

/// Appends sample `i` as one line: time, seven cells per body (empty at a
/// gap), joint angles, joint velocity commands, measured joint velocities,
/// joint efforts.
fn push_sample(out: &mut String, trajectory: &Trajectory, i: usize) {
    push_f64(out, trajectory.time_s[i]);
    for b in &trajectory.bodies {
        match &b.poses[i] {
            Some(p) => {
                let (v, o) = (p.position_m, p.orientation);
                for x in [v.x, v.y, v.z, o.w, o.x, o.y, o.z] {
                    out.push(',');
                    push_f64(out, x);
                }
            }
            None => out.push_str(",,,,,,,"),
        }
    }
    for rows in [
        &trajectory.joint_angles_rad,
        &trajectory.joint_velocity_commands_rad_s,
        &trajectory.joint_velocities_rad_s,
        &trajectory.joint_efforts_nm,
    ]
    .into_iter()
    .flatten()
    {
        for &x in &rows[i] {
            out.push(',');
            push_f64(out, x);
        }
    }
    out.push('\n');
}

/// The columns of a trajectory as its run CSV has them: each named by its
/// header (`t_s`, `wrist_x_m`, ..., `q1_rad`, ...), one value per sample
/// (`NaN` in a body's seven columns at a gap). For array libraries (the
/// Python package's `load_run`).
pub fn run_columns(trajectory: &Trajectory) -> Vec<(String, Vec<f64>)> {
    let mut header = String::new();
    push_header(&mut header, trajectory);
    let names = header.trim_end().split(',').map(str::to_string);
    let mut columns: Vec<Vec<f64>> = vec![trajectory.time_s.clone()];
    for b in &trajectory.bodies {
        let mut seven: Vec<Vec<f64>> = (0..7).map(|_| Vec::with_capacity(b.poses.len())).collect();
        for p in &b.poses {
            let values = match p {
                Some(p) => {
                    let (v, o) = (p.position_m, p.orientation);
                    [v.x, v.y, v.z, o.w, o.x, o.y, o.z]
                }
                None => [f64::NAN; 7],
            };
            for (c, x) in seven.iter_mut().zip(values) {
                c.push(x);
            }
        }
        columns.extend(seven);
    }
    for rows in [
        &trajectory.joint_angles_rad,
        &trajectory.joint_velocity_commands_rad_s,
        &trajectory.joint_velocities_rad_s,
        &trajectory.joint_efforts_nm,
    ]
    .into_iter()
    .flatten()
    {
        for j in 0..rows.first().map_or(0, Vec::len) {
            columns.push(rows.iter().map(|r| r[j]).collect());
        }
    }
    names.zip(columns).collect()
}

/// Formats a trajectory as run CSV text (see the module docs). Roles must
/// be non-empty and free of `,`, `"` and line breaks.
pub fn format_run_csv(trajectory: &Trajectory) -> Result<String, StoreError> {
    check_writable(trajectory)?;
    let mut out =
        String::with_capacity(64 + trajectory.len() * (24 + 7 * 20 * trajectory.bodies.len()));
    push_header(&mut out, trajectory);
    for i in 0..trajectory.len() {
        push_sample(&mut out, trajectory, i);
    }
    Ok(out)
}

/// One data line split into cells (byte ranges of its text).
struct Row<'a> {
    /// The line, read lossily if it is not UTF-8 so that a bad cell shows
    /// up as a non-number at its own column.
    text: &'a str,
    /// Start and end of each cell in `text`.
    ranges: &'a [(usize, usize)],
}

impl Row<'_> {
    /// Number of cells.
    fn len(&self) -> usize {
        self.ranges.len()
    }

    /// Cell `col` (empty past the end).
    fn cell(&self, col: usize) -> &str {
        self.ranges
            .get(col)
            .and_then(|&(a, b)| self.text.get(a..b))
            .unwrap_or("")
    }
}

/// Splits `text` at commas into `ranges` (cleared first).
fn split_cells(text: &str, ranges: &mut Vec<(usize, usize)>) {
    ranges.clear();
    let mut from = 0;
    for (i, b) in text.bytes().enumerate() {
        if b == b',' {
            ranges.push((from, i));
            from = i + 1;
        }
    }
    ranges.push((from, text.len()));
}

/// What a run-CSV column holds.
#[derive(Debug, Clone, Copy)]
enum Column {
    /// Cell `k` (0..7) of body `b`'s pose.
    Body(usize, usize),
    /// The next value of per-joint series `k` ([`SERIES`]).
    Series(usize),
}

/// The per-joint series of a run CSV, in column order: the column name's
/// prefix and suffix around the 1-based joint number: joint angles, joint
/// velocity commands, measured joint velocities, joint efforts.
const SERIES: [(&str, &str); 4] = [
    ("q", "_rad"),
    ("qd_cmd", "_rad_s"),
    ("qd", "_rad_s"),
    ("tau", "_nm"),
];

/// The columns of a run CSV, read from its header.
struct Header {
    /// Line of the header (1-based).
    line: usize,
    /// Column names, as written (without quotes and surrounding spaces).
    names: Vec<Vec<u8>>,
    /// What each column after `t_s` holds.
    columns: Vec<Column>,
    /// Body roles, in column order.
    roles: Vec<String>,
    /// Number of columns of each per-joint series ([`SERIES`]).
    series: [usize; 4],
}

impl Header {
    /// An error at the header's column `col` (0-based).
    fn error(&self, file: &Path, col: usize, message: String) -> ImportError {
        ImportError::at_line(file, self.line, message).with_column(col + 1)
    }

    /// Reads the header line.
    fn parse(bytes: &[u8], line: usize, file: &Path) -> Result<Header, ImportError> {
        let names: Vec<Vec<u8>> = bytes
            .split(|&b| b == b',')
            .map(|n| unquote(n).to_vec())
            .collect();
        let mut h = Header {
            line,
            columns: Vec::with_capacity(names.len()),
            names,
            roles: Vec::new(),
            series: [0; 4],
        };
        if h.names.first().map(Vec::as_slice) != Some(b"t_s") {
            let found = h.names.first().map(Vec::as_slice).unwrap_or_default();
            return Err(h.error(
                file,
                0,
                format!(
                    "expected the column name \"t_s\", found {}",
                    show_bytes(found, 40)
                ),
            ));
        }
        let mut i = 1;
        while i < h.names.len() {
            i += h.parse_column(i, file)?;
        }
        Ok(h)
    }

    /// Reads the column(s) starting at `i`; returns how many were read.
    fn parse_column(&mut self, i: usize, file: &Path) -> Result<usize, ImportError> {
        let name = self.names[i].clone();
        if let Some(role) = name.strip_suffix(b"_x_m") {
            self.parse_body(i, role, file)?;
            Ok(7)
        } else if let Some(k) = (0..SERIES.len()).find(|&k| {
            let (prefix, suffix) = SERIES[k];
            name == format!("{prefix}{}{suffix}", self.series[k] + 1).as_bytes()
        }) {
            self.columns.push(Column::Series(k));
            self.series[k] += 1;
            Ok(1)
        } else {
            let expected: Vec<String> = (0..SERIES.len())
                .map(|k| format!("{}{}{}", SERIES[k].0, self.series[k] + 1, SERIES[k].1))
                .collect();
            Err(self.error(
                file,
                i,
                format!(
                    "unexpected column name {}: expected <role>_x_m, {}",
                    show_bytes(&name, 40),
                    expected.join(", ")
                ),
            ))
        }
    }

    /// Reads the seven columns of body `role`, starting at `i`.
    fn parse_body(&mut self, i: usize, role: &[u8], file: &Path) -> Result<(), ImportError> {
        let role_text = String::from_utf8_lossy(role).into_owned();
        if role.is_empty() {
            return Err(self.error(file, i, "a body column needs a role before \"_x_m\"".into()));
        }
        if self.roles.contains(&role_text) {
            return Err(self.error(file, i, format!("body role '{role_text}' appears twice")));
        }
        for (k, suffix) in BODY_SUFFIXES.iter().enumerate() {
            let want = format!("{role_text}{suffix}");
            match self.names.get(i + k) {
                Some(n) if n.as_slice() == want.as_bytes() => {
                    self.columns.push(Column::Body(self.roles.len(), k));
                }
                Some(n) => {
                    let message = format!(
                        "expected the column name {want:?}, found {}",
                        show_bytes(n, 40)
                    );
                    return Err(self.error(file, i + k, message));
                }
                None => {
                    let message = format!("the header ends before the column {want:?}");
                    return Err(self.error(file, i + k, message));
                }
            }
        }
        self.roles.push(role_text);
        Ok(())
    }
}

/// The trajectory being read, one sample at a time.
struct Samples<'h> {
    header: &'h Header,
    file: &'h Path,
    trajectory: Trajectory,
    /// Rows of each per-joint series ([`SERIES`]).
    series: [Vec<Vec<f64>>; 4],
    /// Scratch: the current row's seven cells per body.
    body_cells: Vec<[Option<f64>; 7]>,
}

impl<'h> Samples<'h> {
    fn new(header: &'h Header, file: &'h Path) -> Self {
        Samples {
            header,
            file,
            trajectory: Trajectory::with_bodies(&header.roles),
            series: Default::default(),
            body_cells: vec![[None; 7]; header.roles.len()],
        }
    }

    /// An error at column `col` (0-based) of line `line`, naming the column.
    fn error(&self, line: usize, col: usize, message: String) -> ImportError {
        let e = ImportError::at_line(self.file, line, message).with_column(col + 1);
        match self.header.names.get(col) {
            Some(n) => e.with_field(String::from_utf8_lossy(n).into_owned()),
            None => e,
        }
    }

    /// The number in cell `col`.
    fn number(&self, row: &Row, line: usize, col: usize) -> Result<f64, ImportError> {
        let cell = row.cell(col);
        parse_f64_str(cell).ok_or_else(|| {
            let found = show_bytes(cell.as_bytes(), 40);
            self.error(line, col, format!("expected a number, found {found}"))
        })
    }

    /// Reads one data line.
    fn push(&mut self, record: &Row, line: usize) -> Result<(), ImportError> {
        let width = self.header.names.len();
        if record.len() != width {
            return Err(ImportError::at_line(
                self.file,
                line,
                format!(
                    "expected {width} columns as in the header, found {}",
                    record.len()
                ),
            ));
        }
        let t = self.number(record, line, 0)?;
        if !t.is_finite() || self.trajectory.time_s.last().is_some_and(|&p| t < p) {
            return Err(self.error(
                line,
                0,
                format!("time {t} s is not finite or goes backwards"),
            ));
        }
        self.trajectory.time_s.push(t);
        let mut rows: [Vec<f64>; 4] =
            std::array::from_fn(|k| Vec::with_capacity(self.header.series[k]));
        for (col, column) in self.header.columns.iter().enumerate() {
            let col = col + 1;
            match *column {
                Column::Body(b, k) => {
                    let empty = record.cell(col).is_empty();
                    self.body_cells[b][k] = if empty {
                        None
                    } else {
                        Some(self.number(record, line, col)?)
                    };
                }
                Column::Series(k) => rows[k].push(self.number(record, line, col)?),
            }
        }
        self.push_poses(line)?;
        for (k, row) in rows.into_iter().enumerate() {
            if self.header.series[k] > 0 {
                self.series[k].push(row);
            }
        }
        Ok(())
    }

    /// Turns the current row's body cells into poses (or gaps).
    fn push_poses(&mut self, line: usize) -> Result<(), ImportError> {
        for b in 0..self.body_cells.len() {
            let cells = self.body_cells[b];
            let pose = if cells.iter().all(Option::is_none) {
                None
            } else if let Some(k) = cells.iter().position(Option::is_none) {
                let col = 1 + self
                    .header
                    .columns
                    .iter()
                    .position(|c| matches!(c, Column::Body(bb, kk) if *bb == b && *kk == k))
                    .unwrap_or(0);
                return Err(self.error(
                    line,
                    col,
                    "a pose needs all seven cells, or none for a gap; this one is empty".into(),
                ));
            } else {
                let v: [f64; 7] = std::array::from_fn(|k| cells[k].unwrap_or(f64::NAN));
                Some(Pose::new(
                    Vec3::new(v[0], v[1], v[2]),
                    Quat::new(v[3], v[4], v[5], v[6]),
                ))
            };
            self.trajectory.bodies[b].poses.push(pose);
        }
        Ok(())
    }

    /// The trajectory read.
    fn finish(mut self) -> Trajectory {
        let [angles, velocity_commands, velocities, efforts] = self.series;
        let present = |k: usize, rows| (self.header.series[k] > 0).then_some(rows);
        let t = &mut self.trajectory;
        t.joint_angles_rad = present(0, angles);
        t.joint_velocity_commands_rad_s = present(1, velocity_commands);
        t.joint_velocities_rad_s = present(2, velocities);
        t.joint_efforts_nm = present(3, efforts);
        debug_assert!(self.trajectory.validate().is_ok());
        self.trajectory
    }
}

/// Reads a run CSV file.
pub fn read_run_csv(path: &Path) -> Result<Trajectory, ImportError> {
    let bytes =
        fs::read(path).map_err(|e| ImportError::new(path, format!("cannot read the file: {e}")))?;
    parse_run_csv(&bytes, path)
}

/// Parses run CSV text (see the module docs); `file` is used in messages
/// only. Never panics, whatever the bytes.
pub fn parse_run_csv(bytes: &[u8], file: &Path) -> Result<Trajectory, ImportError> {
    let mut lines = Lines::new(bytes).filter(|l| !l.bytes.is_empty());
    let first = lines
        .next()
        .ok_or_else(|| ImportError::new(file, "the file is empty"))?;
    let header = Header::parse(first.bytes, first.number, file)?;
    let mut samples = Samples::new(&header, file);
    let mut ranges = Vec::with_capacity(header.names.len());
    for line in lines {
        // Validate the line's UTF-8 once; a damaged line is read lossily.
        let lossy;
        let text: &str = match std::str::from_utf8(line.bytes) {
            Ok(s) => s,
            Err(_) => {
                lossy = String::from_utf8_lossy(line.bytes);
                &lossy
            }
        };
        split_cells(text, &mut ranges);
        let row = Row {
            text,
            ranges: &ranges,
        };
        samples.push(&row, line.number)?;
    }
    Ok(samples.finish())
}

/// A header cell without surrounding spaces and double quotes.
fn unquote(cell: &[u8]) -> &[u8] {
    let mut c = cell;
    while let [b' ', rest @ ..] = c {
        c = rest;
    }
    while let [rest @ .., b' '] = c {
        c = rest;
    }
    match c {
        [b'"', inner @ .., b'"'] => inner,
        _ => c,
    }
}
