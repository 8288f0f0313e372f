//! CSV joint recordings: one file per episode, one row per sample, read
//! with the `csv` crate (quoted headers and cells as spreadsheets write
//! them).
//!
//! Columns are found by name:
//! - **time**: the header stamp where there is one (`header.stamp` in
//!   nanoseconds, as `rostopic echo -p` writes it, or `header.stamp.sec` and
//!   `.nanosec`, with any prefix), else `time_s`, `t_s`, `time`, `t`,
//!   `timestamp`, `stamp`, `__time` (PlotJuggler's export) in seconds, or
//!   `%time` in nanoseconds; a name ending in `_ns` is read in nanoseconds.
//! - **joint values**: `<joint>/<field>` or `<joint>.<field>`, with any
//!   prefix before the joint (`/joint_states/<joint>/position`, as
//!   PlotJuggler exports a bag), where `<field>` is `position`, `velocity`
//!   or `effort` (measured) or `position_command`, `velocity_command` or
//!   `effort_command` (what was commanded at that row's time; one kind per
//!   file).
//! - **a JointState flattened** as `rostopic echo -p` writes it (columns
//!   `field.name0`, `field.name1`, ..., `field.position0`, ...; the joint
//!   names are the cells), or with list cells (`name` = `['a', 'b']`,
//!   `position` = `[0.1, 0.2]`, as a data frame of the messages is
//!   written), or without a header as `ros2 topic echo --csv` prints it
//!   (`sec, nanosec, frame_id`, the names, the positions, then the
//!   velocities and efforts when recorded).
//! - **patterns** (`--columns 'q_{joint}_rad=position,...'`): `{joint}`
//!   stands for each joint's name; `time=NAME` names the time column.
//! - **a column map** (`--column ROLE=NAME`, ROLE being `time` or
//!   `<joint>/<field>`) names single columns; it replaces what the names
//!   or patterns would say.
//!
//! Other columns are ignored, and the import says which. Every joint with
//! a value column needs a position column; velocities and efforts are kept
//! when every joint has them. Rows must be in time order, and two rows at
//! one time are an error naming the line.

use crate::recording::{check_state_time, Commands, JointStates, Recording};
use realitygap_core::CommandKind;
use realitygap_data::ImportError;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::path::Path;

/// How to read CSV recordings.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CsvOptions {
    /// Explicit columns: (role, column name), role `time` or
    /// `<joint>/<field>`.
    pub columns: Vec<(String, String)>,
    /// Column patterns (`--columns`), tried before the naming conventions.
    pub patterns: Vec<ColumnPattern>,
}

/// One entry of `--columns`: columns named like `pattern` hold `field`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ColumnPattern {
    /// The column name with `{joint}` where each joint's name stands, or
    /// (field `time`) the time column's name.
    pub pattern: String,
    /// `time`, `position`, `velocity`, `effort` or `<kind>_command`.
    pub field: String,
}

/// The placeholder of a joint's name in a [`ColumnPattern`].
pub const JOINT_PLACEHOLDER: &str = "{joint}";

/// Parses a `--columns` list: comma-separated `PATTERN=FIELD` entries
/// (`q_{joint}_rad=position,qd_{joint}_rad_s=velocity`), where `{joint}`
/// stands for each joint's name and FIELD is `position`, `velocity`,
/// `effort` or `<kind>_command`; `time=NAME` (or `NAME=time`) names the
/// time column.
pub fn parse_column_patterns(list: &str) -> Result<Vec<ColumnPattern>, String> {
    let fields =
        "time, position, velocity, effort, position_command, velocity_command or effort_command";
    let mut out = Vec::new();
    for item in list.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let (left, right) = item
            .rsplit_once('=')
            .map(|(l, r)| (l.trim(), r.trim()))
            .filter(|(l, r)| !l.is_empty() && !r.is_empty())
            .ok_or_else(|| {
                format!("expected PATTERN=FIELD (e.g. q_{{joint}}_rad=position), FIELD being {fields}; found {item:?}")
            })?;
        let (pattern, field) = if Field::parse(right).is_some() || right == "time" {
            (left, right)
        } else if left == "time" {
            (right, "time")
        } else {
            return Err(format!(
                "{item:?}: {right:?} is not a field; FIELD is {fields}"
            ));
        };
        let holes = pattern.matches(JOINT_PLACEHOLDER).count();
        if field == "time" && holes != 0 {
            return Err(format!(
                "{item:?}: the time column is one column: its name has no {JOINT_PLACEHOLDER}"
            ));
        }
        if field != "time" && holes != 1 {
            return Err(format!(
                "{item:?}: the pattern needs {JOINT_PLACEHOLDER} once, where each joint's name stands"
            ));
        }
        out.push(ColumnPattern {
            pattern: pattern.to_string(),
            field: field.to_string(),
        });
    }
    if out.is_empty() {
        return Err("expected PATTERN=FIELD entries, found none".into());
    }
    Ok(out)
}

/// Names a time column in seconds may have (case-insensitive), in order
/// of preference.
const TIME_NAMES: [&str; 7] = ["time_s", "t_s", "time", "t", "timestamp", "stamp", "__time"];

/// What a value column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Field {
    Position,
    Velocity,
    Effort,
    Command(CommandKind),
}

impl Field {
    fn parse(name: &str) -> Option<Field> {
        Some(match name {
            "position" => Field::Position,
            "velocity" => Field::Velocity,
            "effort" => Field::Effort,
            "position_command" => Field::Command(CommandKind::Position),
            "velocity_command" => Field::Command(CommandKind::Velocity),
            "effort_command" => Field::Command(CommandKind::Effort),
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            Field::Position => "position",
            Field::Velocity => "velocity",
            Field::Effort => "effort",
            Field::Command(CommandKind::Position) => "position_command",
            Field::Command(CommandKind::Velocity) => "velocity_command",
            Field::Command(CommandKind::Effort) => "effort_command",
        }
    }
}

/// `(joint, field)` of a column named by the convention.
fn by_convention(name: &str) -> Option<(String, Field)> {
    let cut = name.rfind(['/', '.'])?;
    let field = Field::parse(&name[cut + 1..])?;
    let rest = &name[..cut];
    let joint = rest.rsplit('/').next().unwrap_or(rest);
    (!joint.is_empty()).then(|| (joint.to_string(), field))
}

/// The last segment of a column name (after `/` or `.`).
fn last_segment(name: &str) -> &str {
    name.rsplit(['/', '.']).next().unwrap_or(name)
}

/// The arrays of a JointState, as columns name them.
const ARRAYS: [&str; 4] = ["name", "position", "velocity", "effort"];

/// `(prefix, array, index)` of a column of a flattened JointState:
/// `field.position3`, `position_3`, `position[3]`, `msg.position.3` (one
/// element) or `position`, `/joint_states/position` (a list cell, no
/// index), with array `name`, `position`, `velocity` or `effort` as its last
/// segment after the prefix.
fn split_array(name: &str) -> Option<(&str, &'static str, Option<usize>)> {
    let (base, digits) = if let Some(inner) = name.strip_suffix(']') {
        let open = inner.rfind('[')?;
        (&inner[..open], &inner[open + 1..])
    } else {
        let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let (base, digits) = name.split_at(name.len() - digits);
        let base = if digits.is_empty() {
            base
        } else {
            base.strip_suffix(['_', '.']).unwrap_or(base)
        };
        (base, digits)
    };
    let index = match digits {
        "" => None,
        d if d.len() <= 6 => Some(d.parse().ok()?),
        _ => return None,
    };
    let segment = last_segment(base);
    let array = ARRAYS
        .into_iter()
        .find(|a| segment.eq_ignore_ascii_case(a))?;
    Some((&base[..base.len() - segment.len()], array, index))
}

/// Decimal text as an integer count of `10^-scale` units, exactly (no
/// floating point: nanoseconds since the epoch need 19 digits).
fn parse_decimal(text: &str, scale: u32) -> Option<i64> {
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.strip_prefix('+').unwrap_or(text)),
    };
    let (whole, frac) = digits.split_once('.').unwrap_or((digits, ""));
    if whole.is_empty() && frac.is_empty()
        || !whole.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let mut value: i64 = 0;
    for b in whole.bytes() {
        value = value.checked_mul(10)?.checked_add(i64::from(b - b'0'))?;
    }
    for k in 0..scale as usize {
        let d = frac.as_bytes().get(k).map_or(0, |b| i64::from(b - b'0'));
        value = value.checked_mul(10)?.checked_add(d)?;
    }
    // Round half up on the first dropped digit.
    if frac
        .as_bytes()
        .get(scale as usize)
        .is_some_and(|&b| b >= b'5')
    {
        value = value.checked_add(1)?;
    }
    Some(if negative { -value } else { value })
}

/// Seconds as written (`12.005`, `1.7e9`) to nanoseconds: exactly for
/// plain decimals, else through f64; `None` when not a finite number in
/// range.
fn seconds_text_to_ns(text: &str) -> Option<i64> {
    parse_decimal(text, 9).or_else(|| {
        let x: f64 = text.parse().ok()?;
        crate::recording::seconds_to_ns(x).filter(|_| x.is_finite())
    })
}

/// Nanoseconds as written (an integer, or a float in scientific notation).
fn nanoseconds_text_to_ns(text: &str) -> Option<i64> {
    parse_decimal(text, 0).or_else(|| {
        let x: f64 = text.parse().ok()?;
        (x.is_finite() && x.abs() < 9.2e18).then(|| x.round() as i64)
    })
}

/// Where a row's time comes from.
#[derive(Debug, Clone, Copy)]
enum TimeSource {
    /// One column in seconds.
    Seconds(usize),
    /// One column in nanoseconds.
    Nanoseconds(usize),
    /// Whole seconds and nanoseconds (a ROS header stamp).
    SecNanosec(usize, usize),
}

impl TimeSource {
    fn columns(self) -> Vec<usize> {
        match self {
            TimeSource::Seconds(c) | TimeSource::Nanoseconds(c) => vec![c],
            TimeSource::SecNanosec(a, b) => vec![a, b],
        }
    }
}

/// Where an array of a JointState is: one column per element, or one
/// column holding a list.
#[derive(Debug, Clone)]
enum ArraySource {
    Columns(Vec<usize>),
    List(usize),
}

/// A JointState flattened into a row: the names are cells.
#[derive(Debug, Clone)]
struct Arrays {
    names: ArraySource,
    position: ArraySource,
    velocity: Option<ArraySource>,
    effort: Option<ArraySource>,
}

/// The elements of a list cell: `[a, b]`, `[a b]`, `['a', 'b']`, `(a, b)`.
fn list_elements(text: &str) -> Vec<String> {
    let t = text.trim();
    let t = t
        .strip_prefix(['[', '('])
        .and_then(|t| t.strip_suffix([']', ')']))
        .unwrap_or(t);
    t.split(|c: char| c == ',' || c.is_whitespace())
        .map(|e| e.trim().trim_matches(['\'', '"']))
        .filter(|e| !e.is_empty())
        .map(str::to_string)
        .collect()
}

/// Reads one CSV file as one episode.
pub fn import_csv(path: &Path, opts: &CsvOptions) -> Result<Recording, ImportError> {
    let bytes =
        std::fs::read(path).map_err(|e| ImportError::new(path, format!("cannot read: {e}")))?;
    parse_csv(&bytes, path, opts)
}

/// Whether the first line is data, as `ros2 topic echo --csv` prints it: a
/// stamp's seconds and nanoseconds first.
fn is_headerless(first: &[String]) -> bool {
    first.len() >= 4
        && first[..2]
            .iter()
            .all(|c| !c.is_empty() && c.bytes().all(|b| b.is_ascii_digit()))
}

/// Parses CSV text as one episode; `path` names it in messages and gives the
/// run id. Never panics, whatever the bytes.
pub fn parse_csv(bytes: &[u8], path: &Path, opts: &CsvOptions) -> Result<Recording, ImportError> {
    let first: Vec<String> = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(bytes)
        .byte_records()
        .next()
        .transpose()
        .map_err(|e| csv_error(path, &e))?
        .map(|r| {
            r.iter()
                .map(|h| String::from_utf8_lossy(h).trim().to_string())
                .collect()
        })
        .unwrap_or_default();
    if first.iter().all(|h| h.is_empty()) {
        return Err(ImportError::new(path, "the file is empty (no header line)"));
    }
    let headerless = opts.columns.is_empty() && opts.patterns.is_empty() && is_headerless(&first);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(!headerless)
        .flexible(false)
        .from_reader(bytes);
    let (headers, mut layout) = if headerless {
        let layout = Layout::headerless(path, &first)?;
        let names = (1..=first.len()).map(|c| format!("cell {c}")).collect();
        (names, layout)
    } else {
        let headers: Vec<String> = reader
            .byte_headers()
            .map_err(|e| csv_error(path, &e))?
            .iter()
            .map(|h| String::from_utf8_lossy(h).trim().to_string())
            .collect();
        let layout = Layout::from_headers(path, &headers, opts)?;
        (headers, layout)
    };
    let mut states = JointStates {
        names: layout.joints.clone(),
        ..JointStates::default()
    };
    let mut velocity = Vec::new();
    let mut effort = Vec::new();
    let mut commands = layout.command_kind.map(|kind| Commands {
        kind,
        names: layout.command_joints.clone(),
        time_ns: Vec::new(),
        values: Vec::new(),
    });
    let mut record = csv::ByteRecord::new();
    loop {
        match reader.read_byte_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(csv_error(path, &e)),
        }
        let line = record.position().map_or(0, |p| p.line() as usize);
        let located = |col: usize, message: String| {
            ImportError::at_line(path, line, message)
                .with_column(col + 1)
                .with_field(headers[col].clone())
        };
        let text = |col: usize| -> Result<String, ImportError> {
            let text = String::from_utf8_lossy(record.get(col).unwrap_or_default())
                .trim()
                .to_string();
            if text.is_empty() {
                return Err(located(
                    col,
                    "the cell is empty; every row needs every value".into(),
                ));
            }
            Ok(text)
        };
        let number = |col: usize, text: &str| -> Result<f64, ImportError> {
            let x: f64 = text
                .parse()
                .map_err(|_| located(col, format!("expected a number, found {text:?}")))?;
            if !x.is_finite() {
                return Err(located(col, format!("the value is {x}")));
            }
            Ok(x)
        };
        let cell = |col: usize| -> Result<f64, ImportError> { number(col, &text(col)?) };
        let time_col = layout.time.columns()[0];
        let t = match layout.time {
            TimeSource::Seconds(c) => {
                let s = text(c)?;
                number(c, &s)?;
                seconds_text_to_ns(&s)
            }
            TimeSource::Nanoseconds(c) => {
                let s = text(c)?;
                number(c, &s)?;
                nanoseconds_text_to_ns(&s)
            }
            TimeSource::SecNanosec(a, b) => {
                let (sa, sb) = (text(a)?, text(b)?);
                let sec = parse_decimal(&sa, 0)
                    .ok_or_else(|| located(a, format!("expected whole seconds, found {sa:?}")))?;
                let nsec = parse_decimal(&sb, 0)
                    .filter(|n| (0..1_000_000_000).contains(n))
                    .ok_or_else(|| {
                        located(b, format!("expected nanoseconds 0-999999999, found {sb:?}"))
                    })?;
                sec.checked_mul(1_000_000_000)
                    .and_then(|s| s.checked_add(nsec))
            }
        }
        .ok_or_else(|| located(time_col, "the time is out of range".into()))?;
        check_state_time(
            path,
            &format!("line {line}"),
            states.time_ns.last().copied(),
            t,
        )
        .map_err(|e| located(time_col, e.message))?;
        let row = |cols: &[usize]| {
            cols.iter()
                .map(|&c| cell(c))
                .collect::<Result<Vec<f64>, _>>()
        };
        if let Some(arrays) = &layout.arrays {
            let strings = |source: &ArraySource| -> Result<(usize, Vec<String>), ImportError> {
                Ok(match source {
                    ArraySource::Columns(cols) => (
                        cols[0],
                        cols.iter().map(|&c| text(c)).collect::<Result<_, _>>()?,
                    ),
                    ArraySource::List(c) => (*c, list_elements(&text(*c)?)),
                })
            };
            let (name_col, names) = strings(&arrays.names)?;
            if states.names.is_empty() {
                if names.is_empty() {
                    return Err(located(name_col, "the joint state names no joint".into()));
                }
                states.names = names;
            } else if names != states.names {
                return Err(located(
                    name_col,
                    format!(
                        "the joint names change from {} (first row) to {}: one joint order per file",
                        states.names.join(", "),
                        names.join(", ")
                    ),
                ));
            }
            let values = |source: &ArraySource, what: &str| -> Result<Vec<f64>, ImportError> {
                let (col, cells) = strings(source)?;
                if cells.len() != states.names.len() {
                    return Err(located(
                        col,
                        format!(
                            "{} {what} values for {} joint names",
                            cells.len(),
                            states.names.len()
                        ),
                    ));
                }
                let col_of = |k: usize| match source {
                    ArraySource::Columns(cols) => cols[k],
                    ArraySource::List(c) => *c,
                };
                cells
                    .iter()
                    .enumerate()
                    .map(|(k, s)| number(col_of(k), s))
                    .collect()
            };
            states.position.push(values(&arrays.position, "position")?);
            if let Some(v) = &arrays.velocity {
                velocity.push(values(v, "velocity")?);
            }
            if let Some(e) = &arrays.effort {
                effort.push(values(e, "effort")?);
            }
        } else {
            states.position.push(row(&layout.position)?);
            if let Some(cols) = &layout.velocity {
                velocity.push(row(cols)?);
            }
            if let Some(cols) = &layout.effort {
                effort.push(row(cols)?);
            }
        }
        states.time_ns.push(t);
        if let Some(c) = &mut commands {
            c.time_ns.push(t);
            c.values.push(row(&layout.command)?);
        }
    }
    if states.time_ns.is_empty() {
        return Err(ImportError::new(
            path,
            "the file has a header but no row: the episode is empty",
        ));
    }
    let has_velocity =
        layout.velocity.is_some() || layout.arrays.as_ref().is_some_and(|a| a.velocity.is_some());
    let has_effort =
        layout.effort.is_some() || layout.arrays.as_ref().is_some_and(|a| a.effort.is_some());
    states.velocity = has_velocity.then_some(velocity);
    states.effort = has_effort.then_some(effort);
    let mut info = Map::new();
    info.insert("format".into(), Value::from("csv"));
    let time_names: Vec<&str> = layout
        .time
        .columns()
        .iter()
        .map(|&c| headers[c].as_str())
        .collect();
    info.insert("time_column".into(), Value::from(time_names.join(" + ")));
    if let Some(style) = layout.style {
        info.insert("style".into(), Value::from(style));
    }
    let mut warnings = std::mem::take(&mut layout.warnings);
    if !layout.ignored.is_empty() {
        warnings.push(format!("columns ignored: {}", layout.ignored.join(", ")));
    }
    if commands.is_none() {
        warnings.push("no command column: the run cannot be replayed".into());
    }
    Ok(Recording {
        file: path.to_path_buf(),
        id: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "episode".into()),
        states,
        commands,
        info,
        warnings,
    })
}

/// A csv crate error as an import error at its line.
fn csv_error(path: &Path, e: &csv::Error) -> ImportError {
    let message = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => {
            format!("expected {expected_len} cells as in the header, found {len}")
        }
        _ => e.to_string(),
    };
    match e.position() {
        Some(p) => ImportError::at_line(path, p.line() as usize, message),
        None => ImportError::new(path, message),
    }
}

/// Which column holds what.
struct Layout {
    time: TimeSource,
    joints: Vec<String>,
    position: Vec<usize>,
    velocity: Option<Vec<usize>>,
    effort: Option<Vec<usize>>,
    /// A flattened JointState (the joints are then named by the first row).
    arrays: Option<Arrays>,
    command_kind: Option<CommandKind>,
    command_joints: Vec<String>,
    command: Vec<usize>,
    ignored: Vec<String>,
    /// Which exporter's layout was recognised, for the manifest.
    style: Option<&'static str>,
    warnings: Vec<String>,
}

/// The time column among `headers` by name, skipping `taken` columns: a
/// header stamp first (as the bags use), then the names of [`TIME_NAMES`]
/// in order, then `%time`.
fn find_time(headers: &[String], taken: &[bool]) -> Option<TimeSource> {
    let free = |c: usize| !taken[c];
    let find = |want: &dyn Fn(&str) -> bool| {
        headers
            .iter()
            .enumerate()
            .position(|(c, h)| free(c) && want(&h.to_ascii_lowercase()))
    };
    // `suffix` is the whole name, or its end after a separator.
    let stamp = |suffix: &'static str| move |h: &str| h == &suffix[1..] || h.ends_with(suffix);
    for (sec, nsec) in [
        (".header.stamp.sec", ".header.stamp.nanosec"),
        (".header.stamp.secs", ".header.stamp.nsecs"),
        ("/header/stamp/sec", "/header/stamp/nanosec"),
    ] {
        if let (Some(a), Some(b)) = (find(&stamp(sec)), find(&stamp(nsec))) {
            return Some(TimeSource::SecNanosec(a, b));
        }
    }
    if let Some(c) = find(&|h: &str| h == "header.stamp" || h.ends_with(".header.stamp")) {
        return Some(TimeSource::Nanoseconds(c));
    }
    for name in TIME_NAMES {
        if let Some(c) = find(&|h: &str| h == name) {
            return Some(TimeSource::Seconds(c));
        }
        let ns = format!("{name}_ns");
        if let Some(c) = find(&|h: &str| h == ns) {
            return Some(TimeSource::Nanoseconds(c));
        }
    }
    find(&|h: &str| h == "%time").map(TimeSource::Nanoseconds)
}

/// Which joint pattern a column name matches, with the joint's name: the
/// most specific one (the longest fixed text); an error when two match
/// equally.
fn match_patterns<'a>(
    name: &str,
    patterns: &'a [(usize, &'a str, &'a str, Field)],
) -> Result<Option<(usize, String, Field)>, String> {
    let mut best: Option<(usize, usize, String, Field)> = None;
    for &(k, prefix, suffix, field) in patterns {
        if name.len() > prefix.len() + suffix.len()
            && name.starts_with(prefix)
            && name.ends_with(suffix)
        {
            let joint = name[prefix.len()..name.len() - suffix.len()].to_string();
            let fixed = prefix.len() + suffix.len();
            match &best {
                Some((_, f, j, bf)) if *f == fixed && (j != &joint || *bf != field) => {
                    return Err(format!(
                        "column {name:?} matches two patterns equally ({}{JOINT_PLACEHOLDER}{} and {prefix}{JOINT_PLACEHOLDER}{suffix})",
                        patterns[best.as_ref().map_or(0, |b| b.0)].1,
                        patterns[best.as_ref().map_or(0, |b| b.0)].2,
                    ));
                }
                Some((_, f, _, _)) if *f >= fixed => {}
                _ => best = Some((k, fixed, joint, field)),
            }
        }
    }
    Ok(best.map(|(k, _, j, f)| (k, j, f)))
}

impl Layout {
    /// The layout of a file without a header, as `ros2 topic echo --csv`
    /// prints a JointState: `sec, nanosec, frame_id`, the joint names, then
    /// the positions and, when recorded, the velocities and efforts.
    fn headerless(path: &Path, first: &[String]) -> Result<Layout, ImportError> {
        let names = first[3..]
            .iter()
            .take_while(|c| c.parse::<f64>().is_err())
            .count();
        let values = first.len() - 3 - names;
        if names == 0 || !values.is_multiple_of(names) || !(1..=3).contains(&(values / names)) {
            return Err(ImportError::at_line(
                path,
                1,
                format!(
                    "no header line, and not a JointState as `ros2 topic echo --csv` prints it (sec, nanosec, frame_id, then the names, positions, velocities, efforts): {} cells, {names} of them names",
                    first.len()
                ),
            ));
        }
        let block = |k: usize| {
            let start = 3 + names * k;
            (k < values / names + 1).then(|| ArraySource::Columns((start..start + names).collect()))
        };
        let arrays = Arrays {
            names: block(0).unwrap_or(ArraySource::Columns(Vec::new())),
            position: block(1).unwrap_or(ArraySource::Columns(Vec::new())),
            velocity: block(2),
            effort: block(3),
        };
        let mut warnings = Vec::new();
        if values / names == 2 {
            warnings.push(
                "no header: the second array of values taken as velocities (sec, nanosec, frame_id, names, positions, velocities)".into(),
            );
        }
        Ok(Layout {
            time: TimeSource::SecNanosec(0, 1),
            joints: Vec::new(),
            position: Vec::new(),
            velocity: None,
            effort: None,
            arrays: Some(arrays),
            command_kind: None,
            command_joints: Vec::new(),
            command: Vec::new(),
            ignored: Vec::new(),
            style: Some("ros2 topic echo --csv"),
            warnings,
        })
    }

    fn from_headers(
        path: &Path,
        headers: &[String],
        opts: &CsvOptions,
    ) -> Result<Layout, ImportError> {
        let columns_found = || format!("the columns are {}", headers.join(", "));
        let header_error = |col: usize, message: String| {
            ImportError::at_line(path, 1, message)
                .with_column(col + 1)
                .with_field(headers[col].clone())
        };
        let column_of = |name: &str, how: &str| -> Result<usize, ImportError> {
            headers.iter().position(|h| h == name).ok_or_else(|| {
                ImportError::at_line(
                    path,
                    1,
                    format!("no column named {name:?} ({how}); {}", columns_found()),
                )
            })
        };
        let mut time = None;
        let mut values: BTreeMap<(String, Field), usize> = BTreeMap::new();
        let mut mapped = vec![false; headers.len()];
        for (role, name) in &opts.columns {
            let col = column_of(name, &format!("--column {role}={name}"))?;
            mapped[col] = true;
            if role == "time" {
                time = Some(if name.to_ascii_lowercase().ends_with("_ns") {
                    TimeSource::Nanoseconds(col)
                } else {
                    TimeSource::Seconds(col)
                });
            } else {
                let (joint, field) = role
                    .rsplit_once(['/', '.'])
                    .and_then(|(j, f)| Some((j.to_string(), Field::parse(f)?)))
                    .ok_or_else(|| {
                        ImportError::new(
                            path,
                            format!(
                                "column role {role:?} is neither time nor <joint>/<field> with field position, velocity, effort or <kind>_command"
                            ),
                        )
                    })?;
                values.insert((joint, field), col);
            }
        }
        // Patterns: the time column by name, then every column a joint
        // pattern matches.
        let mut joint_patterns: Vec<(usize, &str, &str, Field)> = Vec::new();
        for (k, p) in opts.patterns.iter().enumerate() {
            if p.field == "time" {
                if time.is_none() {
                    let col = column_of(&p.pattern, &format!("--columns time={}", p.pattern))?;
                    mapped[col] = true;
                    time = Some(if p.pattern.to_ascii_lowercase().ends_with("_ns") {
                        TimeSource::Nanoseconds(col)
                    } else {
                        TimeSource::Seconds(col)
                    });
                }
                continue;
            }
            let field = Field::parse(&p.field).ok_or_else(|| {
                ImportError::new(path, format!("--columns: {:?} is not a field", p.field))
            })?;
            let (prefix, suffix) = p.pattern.split_once(JOINT_PLACEHOLDER).ok_or_else(|| {
                ImportError::new(
                    path,
                    format!(
                        "--columns: pattern {:?} has no {JOINT_PLACEHOLDER}",
                        p.pattern
                    ),
                )
            })?;
            joint_patterns.push((k, prefix, suffix, field));
        }
        let mut matches = vec![0usize; opts.patterns.len()];
        for (col, name) in headers.iter().enumerate() {
            if mapped[col] || joint_patterns.is_empty() {
                continue;
            }
            let found = match_patterns(name, &joint_patterns).map_err(|m| header_error(col, m))?;
            if let Some((k, joint, field)) = found {
                matches[k] += 1;
                mapped[col] = true;
                let key = (joint, field);
                if let Some(&other) = values.get(&key) {
                    return Err(header_error(
                        col,
                        format!(
                            "joint '{}' has its {} twice (also column {}, {})",
                            key.0,
                            field.name(),
                            other + 1,
                            headers[other]
                        ),
                    ));
                }
                values.insert(key, col);
            }
        }
        for &(k, _, _, field) in &joint_patterns {
            if matches[k] == 0 {
                return Err(ImportError::at_line(
                    path,
                    1,
                    format!(
                        "--columns pattern {:?} ({}) matches no column; {}",
                        opts.patterns[k].pattern,
                        field.name(),
                        columns_found()
                    ),
                ));
            }
        }
        if time.is_none() {
            time = find_time(headers, &mapped);
            if let Some(t) = time {
                for c in t.columns() {
                    mapped[c] = true;
                }
            }
        }
        // A flattened JointState: `field.name0`, ... or list cells, every
        // array with the names' prefix.
        let split: Vec<Option<(&str, &'static str, Option<usize>)>> = headers
            .iter()
            .enumerate()
            .map(|(c, h)| if mapped[c] { None } else { split_array(h) })
            .collect();
        let name_prefix = split
            .iter()
            .flatten()
            .find(|(_, array, _)| *array == "name")
            .map(|(prefix, _, _)| *prefix);
        let of_array = |array: &str| -> Vec<(Option<usize>, usize)> {
            split
                .iter()
                .enumerate()
                .filter_map(|(c, s)| match s {
                    Some((p, a, i)) if Some(*p) == name_prefix && *a == array => Some((*i, c)),
                    _ => None,
                })
                .collect()
        };
        let arrays = if name_prefix.is_some() {
            let names = of_array("name");
            let listed = names.iter().all(|(i, _)| i.is_none());
            let source = |array: &'static str| -> Result<Option<ArraySource>, ImportError> {
                let found = of_array(array);
                if found.is_empty() {
                    return Ok(None);
                }
                if listed {
                    return Ok(Some(ArraySource::List(found[0].1)));
                }
                let mut cols = Vec::with_capacity(names.len());
                for (i, _) in &names {
                    let c = found
                        .iter()
                        .find(|(j, _)| j == i)
                        .map(|&(_, c)| c)
                        .ok_or_else(|| {
                            ImportError::at_line(
                                path,
                                1,
                                format!(
                                    "the joint state has name{} but no {array}{0} column; {}",
                                    i.unwrap_or(0),
                                    columns_found()
                                ),
                            )
                        })?;
                    cols.push(c);
                }
                Ok(Some(ArraySource::Columns(cols)))
            };
            let position = source("position")?.ok_or_else(|| {
                ImportError::at_line(
                    path,
                    1,
                    format!(
                        "column {} holds the joint names but no position column goes with it; {}",
                        headers[names[0].1],
                        columns_found()
                    ),
                )
            })?;
            Some(Arrays {
                names: if listed {
                    ArraySource::List(names[0].1)
                } else {
                    ArraySource::Columns(names.iter().map(|&(_, c)| c).collect())
                },
                position,
                velocity: source("velocity")?,
                effort: source("effort")?,
            })
        } else {
            None
        };
        let array_cols: Vec<usize> = arrays
            .iter()
            .flat_map(|a| {
                [
                    Some(&a.names),
                    Some(&a.position),
                    a.velocity.as_ref(),
                    a.effort.as_ref(),
                ]
            })
            .flatten()
            .flat_map(|s| match s {
                ArraySource::Columns(c) => c.clone(),
                ArraySource::List(c) => vec![*c],
            })
            .collect();
        for &c in &array_cols {
            mapped[c] = true;
        }
        let mut ignored = Vec::new();
        for (col, name) in headers.iter().enumerate() {
            if mapped[col] {
                continue;
            }
            if let Some(key) = by_convention(name) {
                if let Some(&other) = values.get(&key) {
                    return Err(header_error(
                        col,
                        format!(
                            "joint '{}' has its {} twice (also column {}, {})",
                            key.0,
                            key.1.name(),
                            other + 1,
                            headers[other]
                        ),
                    ));
                }
                values.insert(key, col);
            } else {
                ignored.push(name.clone());
            }
        }
        let time = time.ok_or_else(|| {
            ImportError::at_line(
                path,
                1,
                format!(
                    "no time column (a header stamp, or named {}, %time; or give --column time=NAME); {}",
                    TIME_NAMES.join(", "),
                    columns_found()
                ),
            )
        })?;
        if let Some(arrays) = arrays {
            if !values.is_empty() {
                return Err(ImportError::at_line(
                    path,
                    1,
                    format!(
                        "the file holds a flattened joint state and <joint>/<field> columns too ({}): one layout per file",
                        values.values().map(|&c| headers[c].as_str()).collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
            let style = match arrays.names {
                ArraySource::Columns(_) => "flattened JointState (rostopic echo -p)",
                ArraySource::List(_) => "JointState with list cells",
            };
            return Ok(Layout {
                time,
                joints: Vec::new(),
                position: Vec::new(),
                velocity: None,
                effort: None,
                arrays: Some(arrays),
                command_kind: None,
                command_joints: Vec::new(),
                command: Vec::new(),
                ignored,
                style: Some(style),
                warnings: Vec::new(),
            });
        }
        let mut joints: Vec<String> = Vec::new();
        for (joint, _) in values.keys() {
            if !joints.contains(joint) {
                joints.push(joint.clone());
            }
        }
        // Joints in column order of their first column.
        joints.sort_by_key(|j| {
            values
                .iter()
                .filter(|((jj, _), _)| jj == j)
                .map(|(_, &c)| c)
                .min()
        });
        if joints.is_empty() {
            return Err(ImportError::at_line(
                path,
                1,
                format!(
                    "no joint column (named <joint>/position, <joint>/velocity, ...; or give --columns 'PATTERN_{{joint}}=position,...' or --column); {}",
                    columns_found()
                ),
            ));
        }
        let series = |field: Field| -> Vec<Option<usize>> {
            joints
                .iter()
                .map(|j| values.get(&(j.clone(), field)).copied())
                .collect()
        };
        let position = series(Field::Position);
        if let Some(k) = position.iter().position(Option::is_none) {
            let joint = &joints[k];
            let own: Vec<&str> = values
                .iter()
                .filter(|((j, _), _)| j == joint)
                .map(|(_, &c)| headers[c].as_str())
                .collect();
            return Err(ImportError::at_line(
                path,
                1,
                format!(
                    "joint '{joint}' has value columns ({}) but no position column; {}",
                    own.join(", "),
                    columns_found()
                ),
            ));
        }
        let all_or_none = |field: Field, what: &str| -> Result<Option<Vec<usize>>, ImportError> {
            let cols = series(field);
            match (
                cols.iter().all(Option::is_some),
                cols.iter().all(Option::is_none),
            ) {
                (true, _) => Ok(Some(cols.into_iter().flatten().collect())),
                (_, true) => Ok(None),
                _ => {
                    let missing: Vec<&str> = joints
                        .iter()
                        .zip(&cols)
                        .filter(|(_, c)| c.is_none())
                        .map(|(j, _)| j.as_str())
                        .collect();
                    Err(ImportError::at_line(
                        path,
                        1,
                        format!(
                            "some joints have a {what} column and {} do not",
                            missing.join(", ")
                        ),
                    ))
                }
            }
        };
        let velocity = all_or_none(Field::Velocity, "velocity")?;
        let effort = all_or_none(Field::Effort, "effort")?;
        let kinds: Vec<CommandKind> = CommandKind::ALL
            .into_iter()
            .filter(|&k| values.keys().any(|(_, f)| *f == Field::Command(k)))
            .collect();
        if kinds.len() > 1 {
            let names: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
            return Err(ImportError::at_line(
                path,
                1,
                format!(
                    "commands of several kinds ({}): one kind per file",
                    names.join(", ")
                ),
            ));
        }
        let command_kind = kinds.first().copied();
        let (mut command_joints, mut command) = (Vec::new(), Vec::new());
        if let Some(kind) = command_kind {
            for j in &joints {
                if let Some(&c) = values.get(&(j.clone(), Field::Command(kind))) {
                    command_joints.push(j.clone());
                    command.push(c);
                }
            }
        }
        Ok(Layout {
            time,
            position: position.into_iter().flatten().collect(),
            joints,
            velocity,
            effort,
            arrays: None,
            command_kind,
            command_joints,
            command,
            ignored,
            style: (!opts.patterns.is_empty()).then_some("--columns patterns"),
            warnings: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Recording, ImportError> {
        parse_csv(text.as_bytes(), Path::new("ep.csv"), &CsvOptions::default())
    }

    #[test]
    fn reads_plotjuggler_style_names() {
        let r = parse(
            "__time,/joint_states/a/position,/joint_states/b/position,/joint_states/a/velocity,/joint_states/b/velocity,a/position_command,extra\n\
             10.0,0.1,0.2,1,2,0.15,x\n10.01,0.11,0.21,1.1,2.1,0.16,y\n",
        )
        .unwrap();
        assert_eq!(r.states.names, ["a", "b"]);
        assert_eq!(r.states.time_ns, [10_000_000_000, 10_010_000_000]);
        assert_eq!(r.states.position[1], [0.11, 0.21]);
        assert_eq!(r.states.velocity.as_ref().unwrap()[0], [1.0, 2.0]);
        assert!(r.states.effort.is_none());
        let c = r.commands.unwrap();
        assert_eq!(
            (c.kind, c.names.as_slice()),
            (CommandKind::Position, ["a".to_string()].as_slice())
        );
        assert_eq!(c.values, [[0.15], [0.16]]);
        assert_eq!(r.warnings, ["columns ignored: extra"]);
        assert_eq!(r.id, "ep");
    }

    #[test]
    fn patterns_parse_and_name_joints() {
        let p =
            parse_column_patterns("q_{joint}_rad=position, time=t_s ,qd_{joint}=velocity").unwrap();
        assert_eq!(
            p.iter()
                .map(|p| (p.pattern.as_str(), p.field.as_str()))
                .collect::<Vec<_>>(),
            [
                ("q_{joint}_rad", "position"),
                ("t_s", "time"),
                ("qd_{joint}", "velocity")
            ]
        );
        for bad in [
            "q_rad=position",
            "q_{joint}=angle",
            "{joint}{joint}=effort",
            "t_{joint}=time",
            "",
            "=position",
        ] {
            assert!(parse_column_patterns(bad).is_err(), "{bad:?}");
        }
        let opts = CsvOptions {
            patterns: p,
            ..CsvOptions::default()
        };
        // The longest fixed text wins: qd_a is a velocity, not a q_ position.
        let r = parse_csv(
            b"t_s,q_a_rad,qd_a,q_b_rad,qd_b\n0,1,2,3,4\n",
            Path::new("x.csv"),
            &opts,
        )
        .unwrap();
        assert_eq!(r.states.names, ["a", "b"]);
        assert_eq!(r.states.position, [[1.0, 3.0]]);
        assert_eq!(r.states.velocity, Some(vec![vec![2.0, 4.0]]));
        let e = parse_csv(b"t_s,q_a_rad\n0,1\n", Path::new("x.csv"), &opts).unwrap_err();
        assert!(e.to_string().starts_with("x.csv:1: --columns pattern \"qd_{joint}\" (velocity) matches no column; the columns are t_s, q_a_rad"), "{e}");
    }

    #[test]
    fn times_are_read_exactly() {
        assert_eq!(
            seconds_text_to_ns("1700000000.005"),
            Some(1_700_000_000_005_000_000)
        );
        assert_eq!(seconds_text_to_ns("-0.5"), Some(-500_000_000));
        assert_eq!(seconds_text_to_ns("1.5e-3"), Some(1_500_000));
        assert_eq!(seconds_text_to_ns("0.0000000015"), Some(2));
        assert_eq!(
            nanoseconds_text_to_ns("1700000000005000001"),
            Some(1_700_000_000_005_000_001)
        );
        assert_eq!(seconds_text_to_ns("9e30"), None);
        assert_eq!(seconds_text_to_ns("."), None);
        assert_eq!(
            ns_time("a/position,t_ns\n1,1700000000005000001\n"),
            1_700_000_000_005_000_001
        );
        assert_eq!(ns_time("%time,x/position\n17,1\n"), 17);
        assert_eq!(
            ns_time("m.header.stamp.sec,m.header.stamp.nanosec,x/position\n3,5,1\n"),
            3_000_000_005
        );
    }

    fn ns_time(text: &str) -> i64 {
        let r = parse(text).unwrap_or_else(|e| panic!("{e}"));
        r.states.time_ns[0]
    }

    #[test]
    fn flattened_joint_states_read_their_names_from_the_cells() {
        let r = parse("%time,field.header.stamp,field.name0,field.name1,field.position0,field.position1\n9,5,a,b,1,2\n10,6,a,b,3,4\n").unwrap();
        assert_eq!(r.states.names, ["a", "b"]);
        assert_eq!(r.states.time_ns, [5, 6]);
        assert_eq!(r.states.position, [[1.0, 2.0], [3.0, 4.0]]);
        assert!(r.states.velocity.is_none());
        let r = parse("1,5,f,a,b,1,2,3,4\n1,6,f,a,b,5,6,7,8\n").unwrap();
        assert_eq!(r.states.time_ns, [1_000_000_005, 1_000_000_006]);
        assert_eq!(
            r.states.velocity,
            Some(vec![vec![3.0, 4.0], vec![7.0, 8.0]])
        );
        let r = parse("t,name,position,effort\n0,\"['a', 'b']\",\"[1.0, 2.0]\",[3 4]\n").unwrap();
        assert_eq!(r.states.names, ["a", "b"]);
        assert_eq!(r.states.effort, Some(vec![vec![3.0, 4.0]]));
    }

    #[test]
    fn a_column_map_names_unconventional_columns() {
        let opts = CsvOptions {
            columns: vec![
                ("time".into(), "sec".into()),
                ("j1/position".into(), "q0".into()),
            ],
            ..CsvOptions::default()
        };
        let r = parse_csv(b"sec,q0\n0,1\n0.5,2\n", Path::new("x.csv"), &opts).unwrap();
        assert_eq!(r.states.names, ["j1"]);
        assert_eq!(r.states.position, [[1.0], [2.0]]);
    }

    #[test]
    fn bad_files_are_located_errors() {
        let cases = [
            ("", "ep.csv: the file is empty"),
            (
                "time_s,a/position\n",
                "ep.csv: the file has a header but no row",
            ),
            ("x,a/position\n0,1\n", "ep.csv:1: no time column"),
            ("t,foo\n0,1\n", "ep.csv:1: no joint column"),
            (
                "t,a/velocity\n0,1\n",
                "ep.csv:1: joint 'a' has value columns (a/velocity) but no position column; the columns are t, a/velocity",
            ),
            (
                "t,a/position\n0,1\n0.1\n",
                "ep.csv:3: expected 2 cells as in the header, found 1",
            ),
            (
                "t,a/position\n0,1\n0.1,\n",
                "ep.csv:3: column 2 (a/position): the cell is empty",
            ),
            (
                "t,a/position\n0,1\n0.1,NaN\n",
                "ep.csv:3: column 2 (a/position): the value is NaN",
            ),
            (
                "t,a/position\n0,1\n0.1,abc\n",
                "ep.csv:3: column 2 (a/position): expected a number, found \"abc\"",
            ),
            (
                "t,a/position\n1,1\n0.5,1\n",
                "ep.csv:3: column 1 (t): the timestamp goes backwards by 0.5 s",
            ),
            (
                "t,a/position,b/position,a/effort\n0,1,2,3\n",
                "ep.csv:1: some joints have a effort column and b do not",
            ),
            (
                "t,a/position,a/position_command,a/velocity_command\n0,1,2,3\n",
                "ep.csv:1: commands of several kinds",
            ),
            (
                "t,a/position\n0,1\n0.5,1\n0.5,1\n",
                "ep.csv:4: column 1 (t): the timestamp 0.5 s repeats the previous sample's",
            ),
            (
                "t,field.name0,field.name1,field.position0\n0,a,b,1\n",
                "ep.csv:1: the joint state has name1 but no position1 column",
            ),
            (
                "t,name,position\n0,\"['a', 'b']\",[1.0]\n",
                "ep.csv:2: column 3 (position): 1 position values for 2 joint names",
            ),
            (
                "t,field.name0,field.position0\n0,a,1\n0.1,b,2\n",
                "ep.csv:3: column 2 (field.name0): the joint names change from a (first row) to b",
            ),
            (
                "1,2,,a,b,0.5\n",
                "ep.csv:1: no header line, and not a JointState as `ros2 topic echo --csv` prints it",
            ),
        ];
        for (text, want) in cases {
            let e = parse(text).unwrap_err();
            assert!(e.to_string().starts_with(want), "{text:?}: {e}");
        }
    }
}
