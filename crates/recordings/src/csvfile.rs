//! CSV joint recordings: one file per episode, one row per sample, read
//! with the `csv` crate (quoted headers and cells as spreadsheets write
//! them).
//!
//! Columns are found by name:
//! - **time**: `time_s`, `time`, `t`, `timestamp`, `stamp` or `__time`
//!   (PlotJuggler's export), in seconds; a name ending in `_ns` is read in
//!   nanoseconds.
//! - **joint values**: `<joint>/<field>` or `<joint>.<field>`, with any
//!   prefix before the joint (`/joint_states/<joint>/position`, as
//!   PlotJuggler exports a bag), where `<field>` is `position`, `velocity`
//!   or `effort` (measured) or `position_command`, `velocity_command` or
//!   `effort_command` (what was commanded at that row's time; one kind per
//!   file).
//! - **a column map** (`--column ROLE=NAME`, ROLE being `time` or
//!   `<joint>/<field>`) names columns that follow no such convention; it
//!   replaces what the names would say.
//!
//! Other columns are ignored, and the import says which. Every joint with
//! a value column needs a position column; velocities and efforts are kept
//! when every joint has them.

use crate::recording::{check_time, seconds_to_ns, Commands, JointStates, Recording};
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
}

/// Names a time column may have (case-insensitive).
const TIME_NAMES: [&str; 6] = ["time_s", "time", "t", "timestamp", "stamp", "__time"];

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
}

/// `(joint, field)` of a column named by the convention.
fn by_convention(name: &str) -> Option<(String, Field)> {
    let cut = name.rfind(['/', '.'])?;
    let field = Field::parse(&name[cut + 1..])?;
    let rest = &name[..cut];
    let joint = rest.rsplit('/').next().unwrap_or(rest);
    (!joint.is_empty()).then(|| (joint.to_string(), field))
}

/// Reads one CSV file as one episode.
pub fn import_csv(path: &Path, opts: &CsvOptions) -> Result<Recording, ImportError> {
    let bytes =
        std::fs::read(path).map_err(|e| ImportError::new(path, format!("cannot read: {e}")))?;
    parse_csv(&bytes, path, opts)
}

/// Parses CSV text as one episode; `path` names it in messages and gives the
/// run id. Never panics, whatever the bytes.
pub fn parse_csv(bytes: &[u8], path: &Path, opts: &CsvOptions) -> Result<Recording, ImportError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .from_reader(bytes);
    let headers: Vec<String> = reader
        .byte_headers()
        .map_err(|e| csv_error(path, &e))?
        .iter()
        .map(|h| String::from_utf8_lossy(h).trim().to_string())
        .collect();
    if headers.iter().all(|h| h.is_empty()) {
        return Err(ImportError::new(path, "the file is empty (no header line)"));
    }
    let layout = Layout::from_headers(path, &headers, opts)?;
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
        let cell = |col: usize| -> Result<f64, ImportError> {
            let text = String::from_utf8_lossy(record.get(col).unwrap_or_default());
            let text = text.trim();
            let located = |message: String| {
                ImportError::at_line(path, line, message)
                    .with_column(col + 1)
                    .with_field(headers[col].clone())
            };
            if text.is_empty() {
                return Err(located(
                    "the cell is empty; every row needs every value".into(),
                ));
            }
            let x: f64 = text
                .parse()
                .map_err(|_| located(format!("expected a number, found {text:?}")))?;
            if !x.is_finite() {
                return Err(located(format!("the value is {x}")));
            }
            Ok(x)
        };
        let raw_t = cell(layout.time)?;
        let t = if layout.time_in_ns {
            Some(raw_t.round() as i64).filter(|_| raw_t.abs() < 9.2e18)
        } else {
            seconds_to_ns(raw_t)
        }
        .ok_or_else(|| {
            ImportError::at_line(path, line, format!("time {raw_t} is out of range"))
                .with_column(layout.time + 1)
                .with_field(headers[layout.time].clone())
        })?;
        check_time(
            path,
            &format!("line {line}"),
            states.time_ns.last().copied(),
            t,
        )
        .map_err(|e| {
            ImportError::at_line(path, line, e.message)
                .with_column(layout.time + 1)
                .with_field(headers[layout.time].clone())
        })?;
        let row = |cols: &[usize]| {
            cols.iter()
                .map(|&c| cell(c))
                .collect::<Result<Vec<f64>, _>>()
        };
        states.time_ns.push(t);
        states.position.push(row(&layout.position)?);
        if let Some(cols) = &layout.velocity {
            velocity.push(row(cols)?);
        }
        if let Some(cols) = &layout.effort {
            effort.push(row(cols)?);
        }
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
    states.velocity = layout.velocity.is_some().then_some(velocity);
    states.effort = layout.effort.is_some().then_some(effort);
    let mut info = Map::new();
    info.insert("format".into(), Value::from("csv"));
    info.insert(
        "time_column".into(),
        Value::from(headers[layout.time].clone()),
    );
    let mut warnings = Vec::new();
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
    time: usize,
    time_in_ns: bool,
    joints: Vec<String>,
    position: Vec<usize>,
    velocity: Option<Vec<usize>>,
    effort: Option<Vec<usize>>,
    command_kind: Option<CommandKind>,
    command_joints: Vec<String>,
    command: Vec<usize>,
    ignored: Vec<String>,
}

impl Layout {
    fn from_headers(
        path: &Path,
        headers: &[String],
        opts: &CsvOptions,
    ) -> Result<Layout, ImportError> {
        let header_error = |col: usize, message: String| {
            ImportError::at_line(path, 1, message)
                .with_column(col + 1)
                .with_field(headers[col].clone())
        };
        let column_of = |name: &str| -> Result<usize, ImportError> {
            headers.iter().position(|h| h == name).ok_or_else(|| {
                ImportError::at_line(
                    path,
                    1,
                    format!(
                        "no column named {name:?}; the columns are {}",
                        headers.join(", ")
                    ),
                )
            })
        };
        let mut time = None;
        let mut values: BTreeMap<(String, Field), usize> = BTreeMap::new();
        let mut mapped = vec![false; headers.len()];
        for (role, name) in &opts.columns {
            let col = column_of(name)?;
            mapped[col] = true;
            if role == "time" {
                time = Some(col);
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
        let mut ignored = Vec::new();
        for (col, name) in headers.iter().enumerate() {
            if mapped[col] {
                continue;
            }
            if time.is_none()
                && TIME_NAMES.iter().any(|t| {
                    name.eq_ignore_ascii_case(t) || name.eq_ignore_ascii_case(&format!("{t}_ns"))
                })
            {
                time = Some(col);
            } else if let Some(key) = by_convention(name) {
                if let Some(&other) = values.get(&key) {
                    return Err(header_error(
                        col,
                        format!(
                            "joint '{}' has its {:?} twice (also column {})",
                            key.0,
                            key.1,
                            other + 1
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
                    "no time column (named {}; or give --column time=NAME); the columns are {}",
                    TIME_NAMES.join(", "),
                    headers.join(", ")
                ),
            )
        })?;
        let time_in_ns = headers[time].to_ascii_lowercase().ends_with("_ns");
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
                    "no joint column (named <joint>/position, <joint>/velocity, ...; or give --column); the columns are {}",
                    headers.join(", ")
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
            return Err(ImportError::at_line(
                path,
                1,
                format!(
                    "joint '{}' has value columns but no position column",
                    joints[k]
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
            time_in_ns,
            position: position.into_iter().flatten().collect(),
            joints,
            velocity,
            effort,
            command_kind,
            command_joints,
            command,
            ignored,
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
    fn a_column_map_names_unconventional_columns() {
        let opts = CsvOptions {
            columns: vec![
                ("time".into(), "sec".into()),
                ("j1/position".into(), "q0".into()),
            ],
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
                "ep.csv:1: joint 'a' has value columns but no position column",
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
        ];
        for (text, want) in cases {
            let e = parse(text).unwrap_err();
            assert!(e.to_string().starts_with(want), "{text:?}: {e}");
        }
    }
}
