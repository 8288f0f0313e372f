//! Qualisys Track Manager 6DOF TSV exports: the real arm's motion capture.
//!
//! # Format
//!
//! Tab-separated, one row per captured frame. An export may start with a
//! header block of `KEY<TAB>value` lines (`NO_OF_FRAMES`, `FREQUENCY`,
//! `BODY_NAMES`, ...) followed by a column-name line (`RB2(Black) X<TAB>Y...`,
//! or `Frame<TAB>Time<TAB>...`); the study's experiment files have neither,
//! so the frequency and the body names then come from [`QualisysOptions`].
//!
//! A row holds optionally the frame number and the time (s), then for every
//! rigid body 16 cells and one empty separator cell:
//! `X Y Z` (mm), `Roll Pitch Yaw` (degrees), `Residual` (mm), `Rot[0..8]`.
//! The final separator (a trailing tab) may be absent. Line ends may be
//! CRLF or LF.
//!
//! # Rotation matrix layout (checked on the study's recordings)
//!
//! `Rot[0..8]` is the body-to-capture-frame rotation matrix stored
//! **column-major**: `Rot[0] Rot[1] Rot[2]` is the first column
//! (`R00 R10 R20`). With that reading, the matrix equals
//! `Rx(roll) Ry(pitch) Rz(yaw)` built from the Roll/Pitch/Yaw cells (Qualisys'
//! default Euler convention, rotations about the rotating X, then Y, then Z
//! axes) to the 5 printed decimals on every row of the study's files, while
//! the row-major reading is off by up to 2 (see the test
//! `rotation_matrix_is_column_major_on_real_data`). Orientation is taken from
//! the matrix, not from the Euler angles (which are singular at pitch +-90
//! degrees).
//!
//! # Lost markers
//!
//! A body whose `X Y Z` cells are empty, `NaN` (or not finite) or all exactly
//! 0, or whose `Rot` cells are empty, `NaN` or all 0, was not seen: its pose
//! at that sample is a gap (`None`), never a pose at the origin. A `Rot`
//! that is not a rotation (orthonormality off by more than 0.01) is also a
//! gap. Gaps are counted in the warnings.
//!
//! # Time
//!
//! Sample times are taken from the time column when it is present, finite
//! and strictly increasing; otherwise from frame number / frequency; without
//! a frame column, from row index / frequency. The first sample is at 0 s.
//!
//! # Errors and damaged files
//!
//! A wrong number of cells on a row, a cell that is not a number, an empty
//! file, a header with no data, frame numbers that do not increase, or a
//! malformed header value are [`ImportError`]s naming line, column and field.
//! A **last line cut short** (no line end, and too few cells or a last cell
//! that is not a number, as an interrupted copy leaves it) is dropped with a
//! warning rather than failing the whole recording; any other short or
//! damaged line is an error.

use crate::error::{show_bytes, ImportError};
use crate::text::{is_blank, parse_f64, split_tab_line, Line, Lines};
use crate::ImportedRun;
use realitygap_core::trajectory::{BASE, CUBE, WRIST};
use realitygap_core::{BodyTrack, Pose, Quat, Trajectory, Vec3};
use std::path::Path;

/// Cells per rigid body, not counting the empty separator after it.
const CELLS_PER_BODY: usize = 16;
/// Columns per rigid body including the separator.
const STRIDE: usize = CELLS_PER_BODY + 1;
/// Names of a body's cells in a column-name line (the first is prefixed
/// with the body's name).
const CELL_NAMES: [&str; CELLS_PER_BODY] = [
    "X", "Y", "Z", "Roll", "Pitch", "Yaw", "Residual", "Rot[0]", "Rot[1]", "Rot[2]", "Rot[3]",
    "Rot[4]", "Rot[5]", "Rot[6]", "Rot[7]", "Rot[8]",
];
/// Largest tolerated deviation of `R Rᵀ` from the identity.
const ORTHONORMAL_TOLERANCE: f64 = 0.01;

/// How to read a Qualisys export whose header is missing, and which role
/// (`wrist`, `cube`, `base`, ...) each body plays.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct QualisysOptions {
    /// Capture frequency in Hz, for files without a `FREQUENCY` header line.
    /// A header value takes precedence (with a warning if they differ).
    pub frequency_hz: Option<f64>,
    /// Body names in file order, for files without a `BODY_NAMES` header
    /// line. Header names take precedence (with a warning if they differ).
    pub body_names: Option<Vec<String>>,
    /// Body name -> role. Bodies without a mapping keep their name as role.
    pub roles: Vec<(String, String)>,
}

impl QualisysOptions {
    /// The layout of the reference study's recordings (Collins et al. 2019):
    /// headerless, 100 Hz, bodies `RB2(Black)`, `RB1(Orange)`, `PCube`;
    /// `RB1(Orange)` is the wrist, `RB2(Black)` the base, `PCube` the cube.
    pub fn collins2019() -> Self {
        QualisysOptions {
            frequency_hz: Some(100.0),
            body_names: Some(vec![
                "RB2(Black)".into(),
                "RB1(Orange)".into(),
                "PCube".into(),
            ]),
            roles: vec![
                ("RB1(Orange)".into(), WRIST.into()),
                ("RB2(Black)".into(), BASE.into()),
                ("PCube".into(), CUBE.into()),
            ],
        }
    }

    /// The role of a body: its mapping, or its own name.
    pub fn role_of(&self, body_name: &str) -> String {
        self.roles
            .iter()
            .rev()
            .find(|(name, _)| name == body_name)
            .map_or_else(|| body_name.to_string(), |(_, role)| role.clone())
    }
}

/// Reads a Qualisys 6DOF TSV file (see the module docs).
pub fn read(path: &Path, opts: &QualisysOptions) -> Result<ImportedRun, ImportError> {
    let bytes = std::fs::read(path)
        .map_err(|e| ImportError::new(path, format!("cannot read the file: {e}")))?;
    parse(&bytes, path, opts)
}

/// What the header block said.
#[derive(Default)]
struct Header {
    /// `NO_OF_FRAMES` and its line.
    frames: Option<(usize, usize)>,
    /// `FREQUENCY` in Hz.
    frequency_hz: Option<f64>,
    /// `BODY_NAMES`.
    body_names: Option<Vec<String>>,
    /// `NO_OF_BODIES` and its line.
    bodies: Option<(usize, usize)>,
}

/// Column layout of the data rows.
#[derive(Debug, Clone, Copy)]
struct Layout {
    /// Rows start with frame number and time.
    frame_time: bool,
    /// Rows end with the last body's (empty) separator cell.
    trailing_separator: bool,
    /// Number of bodies.
    bodies: usize,
}

impl Layout {
    fn offset(self) -> usize {
        if self.frame_time {
            2
        } else {
            0
        }
    }
    fn columns(self) -> usize {
        self.offset() + STRIDE * self.bodies - usize::from(!self.trailing_separator)
    }
    fn describe(self) -> String {
        format!(
            "{}{} bodies of {} columns{}",
            if self.frame_time { "frame, time, " } else { "" },
            self.bodies,
            STRIDE,
            if self.trailing_separator {
                ""
            } else {
                " without the final empty column"
            }
        )
    }
}

/// The lines before the data: header block, column-name line, first data row.
struct Preamble<'a> {
    header: Header,
    /// The column-name line, if any.
    column_line: Option<Line<'a>>,
    /// The first data row.
    first_data: Line<'a>,
    /// The input from the first data row on.
    data: &'a [u8],
}

/// Reads the header block and the column-name line up to the first data row.
fn read_preamble<'a>(bytes: &'a [u8], file: &Path) -> Result<Preamble<'a>, ImportError> {
    let mut lines = Lines::new(bytes);
    let mut header = Header::default();
    let mut column_line: Option<Line> = None;
    let mut first_data: Option<Line> = None;
    let mut any_content = false;
    let mut data: &[u8] = &[];
    loop {
        let rest = lines.rest();
        let Some(line) = lines.next() else { break };
        if is_blank(line.bytes) {
            continue;
        }
        any_content = true;
        let first = line.bytes.split(|&b| b == b'\t').next().unwrap_or_default();
        let first = trim_spaces(first);
        let wordy =
            first.first().is_some_and(u8::is_ascii_alphabetic) && parse_f64(first).is_none();
        if !wordy || column_line.is_some() {
            first_data = Some(line);
            data = rest;
            break;
        }
        if first == b"Frame" || first.ends_with(b" X") {
            column_line = Some(line);
        } else if is_header_key(first) {
            read_header_line(&line, file, &mut header)?;
        } else {
            return Err(ImportError::at_line(
                file,
                line.number,
                format!(
                    "expected a header line (KEY<TAB>value), a column-name line or a data row, found {}",
                    show_bytes(line.bytes, 60)
                ),
            ));
        }
    }
    if !any_content {
        return Err(ImportError::new(file, "the file is empty"));
    }
    let Some(first_data) = first_data else {
        return Err(ImportError::new(
            file,
            "the file has a header but no data rows",
        ));
    };
    Ok(Preamble {
        header,
        column_line,
        first_data,
        data,
    })
}

/// The capture frequency, Hz: the header's, else the options'.
fn frequency(
    header: &Header,
    opts: &QualisysOptions,
    file: &Path,
    warnings: &mut Vec<String>,
) -> Result<f64, ImportError> {
    Ok(match (header.frequency_hz, opts.frequency_hz) {
        (Some(h), Some(o)) => {
            if h != o {
                warnings.push(format!("the header's FREQUENCY {h} Hz is used instead of the given {o} Hz"));
            }
            h
        }
        (Some(h), None) => h,
        (None, Some(o)) if o.is_finite() && o > 0.0 => o,
        (None, Some(o)) => return Err(ImportError::new(file, format!("the given frequency {o} Hz is not positive"))),
        (None, None) => {
            return Err(ImportError::new(
                file,
                "the file has no FREQUENCY header line: the capture frequency must be given (e.g. --frequency 100)",
            ))
        }
    })
}

/// The rigid bodies' names in file order: the header's, else the options'.
fn body_names(
    header: &mut Header,
    opts: &QualisysOptions,
    file: &Path,
    warnings: &mut Vec<String>,
) -> Result<Vec<String>, ImportError> {
    let body_names = match (header.body_names.take(), &opts.body_names) {
        (Some(h), Some(o)) => {
            if &h != o {
                warnings.push(format!(
                    "the header's BODY_NAMES ({}) are used instead of the given names ({})",
                    h.join(", "),
                    o.join(", ")
                ));
            }
            h
        }
        (Some(h), None) => h,
        (None, Some(o)) if !o.is_empty() => o.clone(),
        (None, _) => {
            return Err(ImportError::new(
                file,
                "the file has no BODY_NAMES header line: the rigid-body names must be given in file order \
                 (e.g. --bodies \"RB2(Black),RB1(Orange),PCube\")",
            ))
        }
    };
    if let Some((n, line)) = header.bodies {
        if n != body_names.len() {
            warnings.push(format!(
                "line {line}: NO_OF_BODIES says {n} but BODY_NAMES lists {}; using BODY_NAMES",
                body_names.len()
            ));
        }
    }

    Ok(body_names)
}

/// The bodies' roles (distinct); warns of roles given for absent bodies.
fn roles(
    body_names: &[String],
    opts: &QualisysOptions,
    file: &Path,
    warnings: &mut Vec<String>,
) -> Result<Vec<String>, ImportError> {
    let roles: Vec<String> = body_names.iter().map(|n| opts.role_of(n)).collect();
    for (i, role) in roles.iter().enumerate() {
        if let Some(j) = roles[..i].iter().position(|r| r == role) {
            return Err(ImportError::new(
                file,
                format!(
                    "bodies '{}' and '{}' both have the role '{role}'",
                    body_names[j], body_names[i]
                ),
            ));
        }
    }
    let mut unknown: Vec<&str> = opts
        .roles
        .iter()
        .map(|(n, _)| n.as_str())
        .filter(|n| !body_names.iter().any(|b| b == n))
        .collect();
    unknown.dedup();
    if !unknown.is_empty() {
        warnings.push(format!(
            "role given for bodies not in the file: {}",
            unknown.join(", ")
        ));
    }

    Ok(roles)
}

/// The data rows read so far.
struct Rows {
    /// Per body, its pose (or gap) per sample.
    poses: Vec<Vec<Option<Pose>>>,
    /// Per body, samples lost.
    lost: Vec<usize>,
    /// Per body, samples whose Rot[] is not a rotation.
    not_rotation: Vec<usize>,
    /// Frame numbers (frame-time layout).
    frames: Vec<u64>,
    /// Time cells, `NaN` when empty (frame-time layout).
    times: Vec<f64>,
    /// The first problem with the time column, if any.
    time_problem: Option<String>,
}

impl Rows {
    fn new(bodies: usize) -> Self {
        Rows {
            poses: vec![Vec::new(); bodies],
            lost: vec![0; bodies],
            not_rotation: vec![0; bodies],
            frames: Vec::new(),
            times: Vec::new(),
            time_problem: None,
        }
    }

    /// Records a row's frame number and time; frames must increase, a bad
    /// time is remembered (times then come from the frames).
    fn push_frame_time(
        &mut self,
        frame: u64,
        time: Option<f64>,
        file: &Path,
        number: usize,
    ) -> Result<(), ImportError> {
        if let Some(&prev) = self.frames.last() {
            if frame <= prev {
                return Err(ImportError::at_line(
                    file,
                    number,
                    format!("frame numbers must increase, but frame {frame} follows frame {prev}"),
                )
                .with_column(1)
                .with_field("Frame"));
            }
        }
        self.frames.push(frame);
        match time {
            Some(t) if t.is_finite() && self.times.last().is_none_or(|&p| t > p) => {}
            Some(t) if self.time_problem.is_none() => {
                self.time_problem = Some(format!(
                    "line {}: time {t} does not follow the previous one",
                    number
                ));
            }
            None if self.time_problem.is_none() => {
                self.time_problem = Some(format!("line {}: the time cell is empty", number));
            }
            _ => {}
        }
        self.times.push(time.unwrap_or(f64::NAN));
        Ok(())
    }

    /// Records a row's bodies.
    fn push_cells(&mut self, row_cells: &mut Vec<Cells>) {
        for (b, cells) in row_cells.drain(..).enumerate() {
            let pose = match cells {
                Cells::Pose(p) => Some(p),
                Cells::Lost => {
                    self.lost[b] += 1;
                    None
                }
                Cells::NotRotation => {
                    self.not_rotation[b] += 1;
                    None
                }
            };
            self.poses[b].push(pose);
        }
    }
}

/// Reads the data rows, split in one pass over the bytes; a cut last line
/// (an interrupted copy) is dropped with a warning.
fn read_rows(
    pre: &Preamble,
    layout: Layout,
    body_names: &[String],
    file: &Path,
    warnings: &mut Vec<String>,
) -> Result<Rows, ImportError> {
    let columns = layout.columns();
    let mut rows = Rows::new(body_names.len());
    let mut fields: Vec<&[u8]> = Vec::with_capacity(columns + 1);
    let mut row_cells: Vec<Cells> = Vec::with_capacity(body_names.len());
    let mut rest = pre.data;
    let mut number = pre.first_data.number - 1;
    while !rest.is_empty() {
        number += 1;
        fields.clear();
        let (used, terminated) = split_tab_line(rest, &mut fields);
        rest = &rest[used..];
        if fields.len() == 1 && is_blank(fields[0]) {
            continue;
        }
        let parsed = if fields.len() != columns {
            Err(ImportError::at_line(
                file,
                number,
                format!(
                    "expected {columns} columns ({}), found {}",
                    layout.describe(),
                    fields.len()
                ),
            ))
        } else {
            parse_row(&fields, layout, &mut row_cells).map_err(|(col, what)| {
                ImportError::at_line(
                    file,
                    number,
                    format!("expected {what}, found {}", show_bytes(fields[col], 40)),
                )
                .with_column(col + 1)
                .with_field(column_name(layout, body_names, col))
            })
        };
        let (frame, time) = match parsed {
            Ok(v) => v,
            Err(e) => {
                // A last line without a line end that stops early, or whose
                // last cell is cut, is what an interrupted copy leaves.
                let cut = !terminated
                    && (fields.len() < columns
                        || (fields.len() == columns && e.column == Some(columns)));
                if cut {
                    warnings.push(format!(
                        "line {}: the last line is cut short and was dropped",
                        number
                    ));
                    break;
                }
                return Err(e);
            }
        };
        if layout.frame_time {
            rows.push_frame_time(frame, time, file, number)?;
        }
        rows.push_cells(&mut row_cells);
    }
    Ok(rows)
}

/// The sample times, seconds from the first: the time column when it is
/// usable (warning when it disagrees with the frames), else frame numbers
/// at the frequency; without frame-time columns, the row index.
fn sample_times(
    rows: &Rows,
    layout: Layout,
    frequency_hz: f64,
    samples: usize,
    warnings: &mut Vec<String>,
) -> Vec<f64> {
    let (frames, times) = (&rows.frames, &rows.times);
    if layout.frame_time {
        let by_frame = |f: u64| (f - frames[0]) as f64 / frequency_hz;
        match &rows.time_problem {
            None => {
                let span = times[samples - 1] - times[0];
                let expected = by_frame(frames[samples - 1]);
                if (span - expected).abs() > 0.5 / frequency_hz {
                    warnings.push(format!(
                        "the time column spans {span} s but the frame numbers at {frequency_hz} Hz span {expected} s; \
                         using the time column"
                    ));
                }
                times.iter().map(|t| t - times[0]).collect()
            }
            Some(problem) => {
                warnings.push(format!(
                    "{problem}: times computed from frame numbers at {frequency_hz} Hz instead"
                ));
                frames.iter().map(|&f| by_frame(f)).collect()
            }
        }
    } else {
        (0..samples).map(|i| i as f64 / frequency_hz).collect()
    }
}

/// Warnings on counts: NO_OF_FRAMES against the rows, gaps and non-rotations.
fn count_warnings(
    header: &Header,
    rows: &Rows,
    body_names: &[String],
    roles: &[String],
    samples: usize,
    warnings: &mut Vec<String>,
) {
    let (lost, not_rotation) = (&rows.lost, &rows.not_rotation);
    if let Some((n, line)) = header.frames {
        if n != samples {
            warnings.push(format!(
                "line {line}: NO_OF_FRAMES says {n} but the file has {samples} data rows"
            ));
        }
    }
    for b in 0..body_names.len() {
        if lost[b] > 0 {
            warnings.push(format!(
                "body '{}' ({}): lost in {} of {samples} samples (gaps)",
                body_names[b], roles[b], lost[b]
            ));
        }
        if not_rotation[b] > 0 {
            warnings.push(format!(
                "body '{}' ({}): Rot[] is not a rotation matrix in {} of {samples} samples (treated as gaps)",
                body_names[b], roles[b], not_rotation[b]
            ));
        }
    }
}

/// Parses the bytes of a Qualisys 6DOF TSV export; `file` is used in
/// messages only. Never panics, whatever the bytes.
pub fn parse(
    bytes: &[u8],
    file: &Path,
    opts: &QualisysOptions,
) -> Result<ImportedRun, ImportError> {
    let mut warnings = Vec::new();
    let mut pre = read_preamble(bytes, file)?;
    // Frequency and body names: header first, then options.
    let frequency_hz = frequency(&pre.header, opts, file, &mut warnings)?;
    let body_names = body_names(&mut pre.header, opts, file, &mut warnings)?;
    let roles = roles(&body_names, opts, file, &mut warnings)?;
    // Layout: from the column-name line if any, and the first row's width.
    let names_frame_time = match &pre.column_line {
        Some(line) => Some(check_column_names(line, file, &body_names)?),
        None => None,
    };
    let layout = choose_layout(&pre.first_data, file, body_names.len(), names_frame_time)?;
    let rows = read_rows(&pre, layout, &body_names, file, &mut warnings)?;
    let samples = rows.poses.first().map_or(0, Vec::len);
    if samples == 0 {
        return Err(ImportError::new(file, "the file has no complete data rows"));
    }
    let time_s = sample_times(&rows, layout, frequency_hz, samples, &mut warnings);
    count_warnings(
        &pre.header,
        &rows,
        &body_names,
        &roles,
        samples,
        &mut warnings,
    );
    let trajectory = Trajectory {
        time_s,
        bodies: roles
            .into_iter()
            .zip(rows.poses)
            .map(|(role, poses)| BodyTrack { role, poses })
            .collect(),
        ..Trajectory::default()
    };
    Ok(ImportedRun {
        trajectory,
        frequency_hz,
        source_file: file.to_path_buf(),
        body_names,
        warnings,
        zero_rows: Vec::new(),
        bad_norm_rows: Vec::new(),
    })
}

/// Parses one row of the right width: frame number and time (when the
/// layout has them; `None` time for an empty cell) and every body's cells
/// into `out`. On failure: the 0-based column and what was expected there.
fn parse_row(
    fields: &[&[u8]],
    layout: Layout,
    out: &mut Vec<Cells>,
) -> Result<(u64, Option<f64>), (usize, &'static str)> {
    out.clear();
    let mut frame_time = (0, None);
    if layout.frame_time {
        let frame = parse_u64(trim_spaces(fields[0])).ok_or((0, "a frame number"))?;
        let cell = trim_spaces(fields[1]);
        let time = if cell.is_empty() {
            None
        } else {
            Some(parse_f64(cell).ok_or((1, "a time in seconds"))?)
        };
        frame_time = (frame, time);
    }
    for b in 0..layout.bodies {
        let base = layout.offset() + STRIDE * b;
        let mut cells = [None; CELLS_PER_BODY];
        for (k, slot) in cells.iter_mut().enumerate() {
            let cell = trim_spaces(fields[base + k]);
            if !cell.is_empty() {
                *slot = Some(parse_f64(cell).ok_or((base + k, "a number"))?);
            }
        }
        let separator = base + CELLS_PER_BODY;
        if separator < fields.len() && !trim_spaces(fields[separator]).is_empty() {
            return Err((separator, "an empty column between bodies"));
        }
        out.push(pose_from_cells(&cells));
    }
    Ok(frame_time)
}

/// What a body's 16 cells amount to.
enum Cells {
    Pose(Pose),
    Lost,
    NotRotation,
}

/// Builds a pose from a body's cells (`None` = empty cell).
fn pose_from_cells(cells: &[Option<f64>; CELLS_PER_BODY]) -> Cells {
    let finite = |c: &[Option<f64>]| c.iter().all(|v| v.is_some_and(f64::is_finite));
    let all_zero = |c: &[Option<f64>]| c.iter().all(|v| *v == Some(0.0));
    let (position, rot) = (&cells[0..3], &cells[7..16]);
    if !finite(position) || all_zero(position) || !finite(rot) || all_zero(rot) {
        return Cells::Lost;
    }
    let r: [f64; 9] = std::array::from_fn(|i| rot[i].unwrap_or(0.0));
    // Rot[] is column-major (see the module docs); core wants row-major.
    let m = [r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8]];
    if !is_rotation(&m) {
        return Cells::NotRotation;
    }
    let mm = |v: Option<f64>| v.unwrap_or(0.0) / 1000.0;
    Cells::Pose(Pose::new(
        Vec3::new(mm(position[0]), mm(position[1]), mm(position[2])),
        Quat::from_rotation_matrix(&m),
    ))
}

/// True when the row-major matrix is orthonormal (within
/// [`ORTHONORMAL_TOLERANCE`]) with determinant +1.
fn is_rotation(m: &[f64; 9]) -> bool {
    for i in 0..3 {
        for j in i..3 {
            let dot =
                m[3 * i] * m[3 * j] + m[3 * i + 1] * m[3 * j + 1] + m[3 * i + 2] * m[3 * j + 2];
            let target = if i == j { 1.0 } else { 0.0 };
            if (dot - target).abs() > ORTHONORMAL_TOLERANCE {
                return false;
            }
        }
    }
    let det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
        + m[2] * (m[3] * m[7] - m[4] * m[6]);
    det > 0.0
}

/// `[A-Z][A-Z0-9_]*`: the shape of a header key.
fn is_header_key(s: &[u8]) -> bool {
    s.first().is_some_and(u8::is_ascii_uppercase)
        && s.iter()
            .all(|&b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'_')
}

/// Reads one `KEY<TAB>value...` line into the header.
fn read_header_line(line: &Line, file: &Path, header: &mut Header) -> Result<(), ImportError> {
    let mut fields = line.bytes.split(|&b| b == b'\t').map(trim_spaces);
    let key = fields.next().unwrap_or_default();
    let mut values: Vec<&[u8]> = fields.collect();
    while values.last().is_some_and(|v| v.is_empty()) {
        values.pop();
    }
    let key_name = String::from_utf8_lossy(key).into_owned();
    let bad = |what: &str| {
        ImportError::at_line(
            file,
            line.number,
            format!(
                "expected {what}, found {}",
                values
                    .first()
                    .map_or("nothing".to_string(), |v| show_bytes(v, 40))
            ),
        )
        .with_column(2)
        .with_field(key_name.clone())
    };
    match key {
        b"NO_OF_FRAMES" => {
            let n = values
                .first()
                .and_then(|v| parse_u64(v))
                .ok_or_else(|| bad("a frame count"))?;
            header.frames = Some((n as usize, line.number));
        }
        b"NO_OF_BODIES" => {
            let n = values
                .first()
                .and_then(|v| parse_u64(v))
                .ok_or_else(|| bad("a body count"))?;
            header.bodies = Some((n as usize, line.number));
        }
        b"FREQUENCY" => {
            let f = values
                .first()
                .and_then(|v| parse_f64(v))
                .filter(|f| f.is_finite() && *f > 0.0)
                .ok_or_else(|| bad("a positive frequency in Hz"))?;
            header.frequency_hz = Some(f);
        }
        b"BODY_NAMES" => {
            if values.is_empty() || values.iter().any(|v| v.is_empty()) {
                return Err(bad("a non-empty body name in every column"));
            }
            let names: Vec<String> = values
                .iter()
                .map(|v| String::from_utf8_lossy(v).into_owned())
                .collect();
            for (i, n) in names.iter().enumerate() {
                if names[..i].contains(n) {
                    return Err(ImportError::at_line(
                        file,
                        line.number,
                        format!("body name '{n}' appears twice"),
                    )
                    .with_field("BODY_NAMES"));
                }
            }
            header.body_names = Some(names);
        }
        b"DATA_INCLUDED" if values.first().is_some_and(|v| *v != b"6D") => {
            return Err(bad("6D (only 6DOF exports can be imported)"));
        }
        _ => {}
    }
    Ok(())
}

/// Checks a column-name line against the body names; returns whether the
/// rows start with frame number and time.
fn check_column_names(
    line: &Line,
    file: &Path,
    body_names: &[String],
) -> Result<bool, ImportError> {
    let fields: Vec<&[u8]> = line.bytes.split(|&b| b == b'\t').map(trim_spaces).collect();
    let frame_time = fields.first().is_some_and(|f| *f == b"Frame");
    let mut expected: Vec<String> = Vec::new();
    if frame_time {
        expected.extend(["Frame".to_string(), "Time".to_string()]);
    }
    for name in body_names {
        expected.push(format!("{name} X"));
        expected.extend(CELL_NAMES[1..].iter().map(|s| s.to_string()));
        expected.push(String::new());
    }
    let acceptable = fields.len() == expected.len() || fields.len() + 1 == expected.len();
    for (col, (found, want)) in fields.iter().zip(&expected).enumerate() {
        if *found != want.as_bytes() {
            return Err(ImportError::at_line(
                file,
                line.number,
                format!(
                    "expected the column name {want:?}, found {}",
                    show_bytes(found, 40)
                ),
            )
            .with_column(col + 1));
        }
    }
    if !acceptable {
        return Err(ImportError::at_line(
            file,
            line.number,
            format!(
                "expected {} column names (for the bodies {}), found {}",
                expected.len(),
                body_names.join(", "),
                fields.len()
            ),
        ));
    }
    Ok(frame_time)
}

/// Chooses the column layout from the first data row's width.
fn choose_layout(
    first: &Line,
    file: &Path,
    bodies: usize,
    frame_time: Option<bool>,
) -> Result<Layout, ImportError> {
    let width = first.bytes.split(|&b| b == b'\t').count();
    let candidates = [(true, true), (true, false), (false, true), (false, false)];
    for (ft, trailing) in candidates {
        let layout = Layout {
            frame_time: ft,
            trailing_separator: trailing,
            bodies,
        };
        if frame_time.is_none_or(|f| f == ft) && layout.columns() == width {
            return Ok(layout);
        }
    }
    let wanted: Vec<String> = candidates
        .iter()
        .filter(|(ft, _)| frame_time.is_none_or(|f| f == *ft))
        .map(|&(ft, tr)| {
            Layout {
                frame_time: ft,
                trailing_separator: tr,
                bodies,
            }
            .columns()
            .to_string()
        })
        .collect();
    let mut message = format!(
        "expected {} columns for {bodies} bodies of {STRIDE} columns (plus frame and time), found {width}",
        wanted.join(" or ")
    );
    // Hint: how many bodies would this width fit?
    for (ft, tr) in candidates {
        let off = if ft { 2 } else { 0 };
        let w = width + usize::from(!tr);
        if w > off && (w - off) % STRIDE == 0 && frame_time.is_none_or(|f| f == ft) {
            let k = (w - off) / STRIDE;
            message.push_str(&format!(
                "; the row has the width of {k} bodies: are the body names ({bodies} given) right?"
            ));
            break;
        }
    }
    Err(ImportError::at_line(file, first.number, message))
}

/// Name of a data column, for messages.
fn column_name(layout: Layout, body_names: &[String], col: usize) -> String {
    let off = layout.offset();
    if layout.frame_time && col == 0 {
        return "Frame".into();
    }
    if layout.frame_time && col == 1 {
        return "Time".into();
    }
    let rel = col - off;
    let (b, k) = (rel / STRIDE, rel % STRIDE);
    let name = body_names.get(b).map_or("?", String::as_str);
    match CELL_NAMES.get(k) {
        Some(cell) => format!("{name} {cell}"),
        None => format!("separator after {name}"),
    }
}

/// Parses an unsigned integer (a frame number or count).
fn parse_u64(s: &[u8]) -> Option<u64> {
    if s.is_empty() || s.len() > 19 || !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(
        s.iter()
            .fold(0u64, |acc, &b| acc * 10 + u64::from(b - b'0')),
    )
}

/// The cell without leading and trailing spaces.
#[inline]
fn trim_spaces(mut s: &[u8]) -> &[u8] {
    while let [b' ', rest @ ..] = s {
        s = rest;
    }
    while let [rest @ .., b' '] = s {
        s = rest;
    }
    s
}

#[cfg(test)]
mod tests;
