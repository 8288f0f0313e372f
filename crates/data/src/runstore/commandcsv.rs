//! The commands file of a run driven by recorded commands:
//! `runs/<id>.commands.csv`, beside the run CSV.
//!
//! One header line, then one row per command: `t_s` (seconds from the start
//! of the run, non-decreasing), then one column per commanded joint named
//! after the command kind and the joint's 1-based column in the run CSV:
//! `pos_cmd<j>_rad` (position), `vel_cmd<j>_rad_s` (velocity) or
//! `eff_cmd<j>_nm` (effort); every column of one file is of one kind.
//! Numbers as in the run CSV (shortest text that reads back exactly).

use super::runcsv::push_f64;
use crate::error::{show_bytes, ImportError};
use crate::text::{parse_f64_str, Lines};
use realitygap_core::{CommandKind, JointCommands};
use std::fmt::Write as _;
use std::path::Path;

/// The column-name prefix and suffix of a kind.
fn affixes(kind: CommandKind) -> (&'static str, &'static str) {
    match kind {
        CommandKind::Position => ("pos_cmd", "_rad"),
        CommandKind::Velocity => ("vel_cmd", "_rad_s"),
        CommandKind::Effort => ("eff_cmd", "_nm"),
    }
}

/// Formats commands as a commands file's text.
pub fn format_commands_csv(commands: &JointCommands) -> String {
    let (prefix, suffix) = affixes(commands.kind);
    let mut out = String::with_capacity(32 + commands.len() * (20 + 20 * commands.joints.len()));
    out.push_str("t_s");
    for &j in &commands.joints {
        let _ = write!(out, ",{prefix}{}{suffix}", j + 1);
    }
    out.push('\n');
    for (t, row) in commands.time_s.iter().zip(&commands.values) {
        push_f64(&mut out, *t);
        for &x in row {
            out.push(',');
            push_f64(&mut out, x);
        }
        out.push('\n');
    }
    out
}

/// Reads a commands file's header: the kind and the joint indices.
fn parse_header(
    names: &[&str],
    line: usize,
    file: &Path,
) -> Result<(CommandKind, Vec<usize>), ImportError> {
    let at = |col: usize, message: String| {
        ImportError::at_line(file, line, message).with_column(col + 1)
    };
    if names.first().map(|n| n.trim()) != Some("t_s") {
        let found = names.first().copied().unwrap_or_default();
        return Err(at(
            0,
            format!(
                "expected the column name \"t_s\", found {}",
                show_bytes(found.as_bytes(), 40)
            ),
        ));
    }
    let mut kind = None;
    let mut joints = Vec::with_capacity(names.len() - 1);
    for (col, name) in names.iter().enumerate().skip(1) {
        let name = name.trim();
        let parsed = CommandKind::ALL.into_iter().find_map(|k| {
            let (prefix, suffix) = affixes(k);
            let number = name.strip_prefix(prefix)?.strip_suffix(suffix)?;
            let j: usize = number.parse().ok().filter(|&j| j >= 1)?;
            Some((k, j - 1))
        });
        let Some((k, j)) = parsed else {
            return Err(at(
                col,
                format!(
                    "unexpected column name {}: expected pos_cmd<j>_rad, vel_cmd<j>_rad_s or eff_cmd<j>_nm",
                    show_bytes(name.as_bytes(), 40)
                ),
            ));
        };
        if kind.is_some_and(|first| first != k) {
            return Err(at(
                col,
                format!(
                    "a {k} command column among {} command columns",
                    kind.unwrap_or(k)
                ),
            ));
        }
        if joints.contains(&j) {
            return Err(at(col, format!("joint {} is commanded twice", j + 1)));
        }
        kind = Some(k);
        joints.push(j);
    }
    let kind = kind.ok_or_else(|| at(0, "the header names no command column".into()))?;
    Ok((kind, joints))
}

/// Parses a commands file's text; `file` is used in messages only. Never
/// panics, whatever the bytes.
pub fn parse_commands_csv(bytes: &[u8], file: &Path) -> Result<JointCommands, ImportError> {
    let mut lines = Lines::new(bytes).filter(|l| !l.bytes.is_empty());
    let first = lines
        .next()
        .ok_or_else(|| ImportError::new(file, "the file is empty"))?;
    let header_text = String::from_utf8_lossy(first.bytes);
    let names: Vec<&str> = header_text.split(',').collect();
    let (kind, joints) = parse_header(&names, first.number, file)?;
    let mut commands = JointCommands {
        kind,
        joints,
        time_s: Vec::new(),
        values: Vec::new(),
    };
    for line in lines {
        let text = String::from_utf8_lossy(line.bytes);
        let cells: Vec<&str> = text.split(',').collect();
        if cells.len() != names.len() {
            return Err(ImportError::at_line(
                file,
                line.number,
                format!(
                    "expected {} columns as in the header, found {}",
                    names.len(),
                    cells.len()
                ),
            ));
        }
        let mut numbers = Vec::with_capacity(cells.len());
        for (col, cell) in cells.iter().enumerate() {
            let x = parse_f64_str(cell).ok_or_else(|| {
                ImportError::at_line(
                    file,
                    line.number,
                    format!(
                        "expected a number, found {}",
                        show_bytes(cell.as_bytes(), 40)
                    ),
                )
                .with_column(col + 1)
                .with_field(names[col].trim().to_string())
            })?;
            numbers.push(x);
        }
        let t = numbers[0];
        if !t.is_finite() || commands.time_s.last().is_some_and(|&p| t < p) {
            return Err(ImportError::at_line(
                file,
                line.number,
                format!("time {t} s is not finite or goes backwards"),
            )
            .with_column(1)
            .with_field("t_s"));
        }
        commands.time_s.push(t);
        commands.values.push(numbers.split_off(1));
    }
    Ok(commands)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_round_trip_exactly() {
        for kind in CommandKind::ALL {
            let c = JointCommands {
                kind,
                joints: vec![0, 2, 6],
                time_s: vec![0.0, 0.01, 0.1 + 0.2],
                values: vec![
                    vec![0.1, -2.5e-7, 3.0],
                    vec![1e300, f64::MIN_POSITIVE, -0.0],
                    vec![1.0 / 3.0, 2.0, 4.0],
                ],
            };
            let text = format_commands_csv(&c);
            let back = parse_commands_csv(text.as_bytes(), Path::new("c.csv")).unwrap();
            assert_eq!(back, c);
        }
    }

    #[test]
    fn bad_commands_files_are_located_errors() {
        let cases = [
            ("", "c.csv: the file is empty"),
            (
                "time,pos_cmd1_rad\n",
                "c.csv:1: column 1: expected the column name \"t_s\"",
            ),
            (
                "t_s,pos_cmd1_rad,vel_cmd2_rad_s\n",
                "c.csv:1: column 3: a velocity command column among position",
            ),
            (
                "t_s,pos_cmd1_rad,pos_cmd1_rad\n",
                "c.csv:1: column 3: joint 1 is commanded twice",
            ),
            (
                "t_s,pos_cmd0_rad\n",
                "c.csv:1: column 2: unexpected column name",
            ),
            (
                "t_s\n",
                "c.csv:1: column 1: the header names no command column",
            ),
            (
                "t_s,pos_cmd1_rad\n0,1\n0.1\n",
                "c.csv:3: expected 2 columns",
            ),
            (
                "t_s,pos_cmd1_rad\n0,x\n",
                "c.csv:2: column 2 (pos_cmd1_rad): expected a number, found \"x\"",
            ),
            (
                "t_s,pos_cmd1_rad\n1,0\n0.5,0\n",
                "c.csv:3: column 1 (t_s): time 0.5 s is not finite or goes backwards",
            ),
        ];
        for (text, want) in cases {
            let e = parse_commands_csv(text.as_bytes(), Path::new("c.csv")).unwrap_err();
            assert!(e.to_string().starts_with(want), "{text:?}: {e}");
        }
    }
}
