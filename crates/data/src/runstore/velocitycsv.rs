//! The velocities file of a run whose source knows its bodies' velocities
//! (a free object's recorded twist): `runs/<id>.velocities.csv`, beside the
//! run CSV, which it leaves as it is (every reader of run CSVs reads the
//! run unchanged).
//!
//! One header line, then one row per sample of the run CSV, at the same
//! times: `t_s`, then for each body with velocities
//! `<role>_vx_m_s,<role>_vy_m_s,<role>_vz_m_s` (the linear velocity of its
//! origin, world frame, m/s) and
//! `<role>_wx_body_rad_s,<role>_wy_body_rad_s,<role>_wz_body_rad_s` (its
//! angular velocity in its own body frame, rad/s: as MuJoCo's free joint
//! and the ContactNets data hold it; world frame = `orientation.rotate`).
//! Six empty cells where a body's velocity is not known. Numbers as in the
//! run CSV (shortest text that reads back exactly).

use super::runcsv::push_f64;
use super::StoreError;
use crate::error::{show_bytes, ImportError};
use crate::text::{parse_f64_str, Lines};
use realitygap_core::{Quat, Vec3};
use std::fmt::Write as _;
use std::path::Path;

/// Suffixes of a body's six columns.
const SUFFIXES: [&str; 6] = [
    "_vx_m_s",
    "_vy_m_s",
    "_vz_m_s",
    "_wx_body_rad_s",
    "_wy_body_rad_s",
    "_wz_body_rad_s",
];

/// The velocity of one body at one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyTwist {
    /// Velocity of the body's origin, world frame, m/s.
    pub linear_m_s: Vec3,
    /// Angular velocity in the body's own frame, rad/s.
    pub angular_body_rad_s: Vec3,
}

impl BodyTwist {
    /// The angular velocity in the world frame (rad/s), for a body whose
    /// orientation (body to world) is `orientation`.
    pub fn angular_world_rad_s(&self, orientation: Quat) -> Vec3 {
        orientation.rotate(self.angular_body_rad_s)
    }

    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        self.linear_m_s.is_finite() && self.angular_body_rad_s.is_finite()
    }
}

/// The velocities of one tracked body of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct VelocityTrack {
    /// Role of the body: one of the run's tracked bodies.
    pub role: String,
    /// One entry per sample of the run; `None` where not known.
    pub twists: Vec<Option<BodyTwist>>,
}

/// A velocities file as read: its times and its bodies' velocities.
#[derive(Debug, Clone, PartialEq)]
pub struct RunVelocities {
    /// Sample times, s (the run CSV's).
    pub time_s: Vec<f64>,
    /// The bodies with velocities, in column order.
    pub bodies: Vec<VelocityTrack>,
}

/// Formats velocities as a velocities file's text; every track must have
/// one entry per time, distinct roles free of `,`, `"` and line breaks.
pub fn format_velocities_csv(
    time_s: &[f64],
    tracks: &[VelocityTrack],
) -> Result<String, StoreError> {
    let invalid = |message: String| StoreError::InvalidTrajectory {
        id: String::new(),
        message,
    };
    for (i, t) in tracks.iter().enumerate() {
        if t.role.is_empty() || t.role.contains([',', '"', '\n', '\r']) {
            return Err(invalid(format!(
                "velocities: body role {:?} cannot be a CSV column prefix",
                t.role
            )));
        }
        if tracks[..i].iter().any(|o| o.role == t.role) {
            return Err(invalid(format!(
                "velocities: body role '{}' appears twice",
                t.role
            )));
        }
        if t.twists.len() != time_s.len() {
            return Err(invalid(format!(
                "velocities of body '{}' have {} samples but the trajectory has {}",
                t.role,
                t.twists.len(),
                time_s.len()
            )));
        }
    }
    let mut out = String::with_capacity(64 + time_s.len() * (24 + 6 * 20 * tracks.len()));
    out.push_str("t_s");
    for t in tracks {
        for s in SUFFIXES {
            let _ = write!(out, ",{}{s}", t.role);
        }
    }
    out.push('\n');
    for (i, &t) in time_s.iter().enumerate() {
        push_f64(&mut out, t);
        for track in tracks {
            match &track.twists[i] {
                Some(w) => {
                    let (v, a) = (w.linear_m_s, w.angular_body_rad_s);
                    for x in [v.x, v.y, v.z, a.x, a.y, a.z] {
                        out.push(',');
                        push_f64(&mut out, x);
                    }
                }
                None => out.push_str(",,,,,,"),
            }
        }
        out.push('\n');
    }
    Ok(out)
}

/// Reads a velocities file's header: the roles, six columns each.
fn parse_header(names: &[&str], line: usize, file: &Path) -> Result<Vec<String>, ImportError> {
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
    let mut roles: Vec<String> = Vec::new();
    let mut col = 1;
    while col < names.len() {
        let first = names[col].trim();
        let Some(role) = first.strip_suffix(SUFFIXES[0]).filter(|r| !r.is_empty()) else {
            return Err(at(
                col,
                format!(
                    "unexpected column name {}: expected <role>{}",
                    show_bytes(first.as_bytes(), 40),
                    SUFFIXES[0]
                ),
            ));
        };
        if roles.iter().any(|r| r == role) {
            return Err(at(col, format!("body role '{role}' appears twice")));
        }
        for (k, suffix) in SUFFIXES.iter().enumerate() {
            let want = format!("{role}{suffix}");
            match names.get(col + k).map(|n| n.trim()) {
                Some(n) if n == want => {}
                Some(n) => {
                    return Err(at(
                        col + k,
                        format!(
                            "expected the column name {want:?}, found {}",
                            show_bytes(n.as_bytes(), 40)
                        ),
                    ))
                }
                None => {
                    return Err(at(
                        col + k,
                        format!("the header ends before the column {want:?}"),
                    ))
                }
            }
        }
        roles.push(role.to_string());
        col += SUFFIXES.len();
    }
    Ok(roles)
}

/// Parses a velocities file's text; `file` is used in messages only. Never
/// panics, whatever the bytes.
pub fn parse_velocities_csv(bytes: &[u8], file: &Path) -> Result<RunVelocities, ImportError> {
    let mut lines = Lines::new(bytes).filter(|l| !l.bytes.is_empty());
    let first = lines
        .next()
        .ok_or_else(|| ImportError::new(file, "the file is empty"))?;
    let header_text = String::from_utf8_lossy(first.bytes);
    let names: Vec<&str> = header_text.split(',').collect();
    let roles = parse_header(&names, first.number, file)?;
    let mut out = RunVelocities {
        time_s: Vec::new(),
        bodies: roles
            .into_iter()
            .map(|role| VelocityTrack {
                role,
                twists: Vec::new(),
            })
            .collect(),
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
        let number = |col: usize| {
            parse_f64_str(cells[col]).ok_or_else(|| {
                ImportError::at_line(
                    file,
                    line.number,
                    format!(
                        "expected a number, found {}",
                        show_bytes(cells[col].as_bytes(), 40)
                    ),
                )
                .with_column(col + 1)
                .with_field(names[col].trim().to_string())
            })
        };
        let t = number(0)?;
        if !t.is_finite() || out.time_s.last().is_some_and(|&p| t < p) {
            return Err(ImportError::at_line(
                file,
                line.number,
                format!("time {t} s is not finite or goes backwards"),
            )
            .with_column(1)
            .with_field("t_s"));
        }
        out.time_s.push(t);
        for (b, track) in out.bodies.iter_mut().enumerate() {
            let from = 1 + 6 * b;
            let empty = (from..from + 6)
                .filter(|&c| cells[c].trim().is_empty())
                .count();
            let twist = match empty {
                6 => None,
                0 => {
                    let mut x = [0.0; 6];
                    for (k, slot) in x.iter_mut().enumerate() {
                        *slot = number(from + k)?;
                    }
                    Some(BodyTwist {
                        linear_m_s: Vec3::new(x[0], x[1], x[2]),
                        angular_body_rad_s: Vec3::new(x[3], x[4], x[5]),
                    })
                }
                _ => {
                    let col = (from..from + 6)
                        .find(|&c| cells[c].trim().is_empty())
                        .unwrap_or(from);
                    return Err(ImportError::at_line(
                        file,
                        line.number,
                        "a velocity needs all six cells, or none where it is not known; this one is empty",
                    )
                    .with_column(col + 1)
                    .with_field(names[col].trim().to_string()));
                }
            };
            track.twists.push(twist);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn twist(a: f64) -> BodyTwist {
        BodyTwist {
            linear_m_s: Vec3::new(a, -2.5e-7, 1e300),
            angular_body_rad_s: Vec3::new(1.0 / 3.0, -0.0, f64::MIN_POSITIVE),
        }
    }

    #[test]
    fn velocities_round_trip_exactly() {
        let time_s = vec![0.0, 1.0 / 148.0, 0.1 + 0.2];
        let tracks = vec![
            VelocityTrack {
                role: "cube".into(),
                twists: vec![Some(twist(1.0)), None, Some(twist(-3.5))],
            },
            VelocityTrack {
                role: "ball".into(),
                twists: vec![None, Some(twist(0.25)), None],
            },
        ];
        let text = format_velocities_csv(&time_s, &tracks).unwrap();
        assert!(text.starts_with("t_s,cube_vx_m_s,cube_vy_m_s,cube_vz_m_s,cube_wx_body_rad_s,cube_wy_body_rad_s,cube_wz_body_rad_s,ball_vx_m_s,"));
        let back = parse_velocities_csv(text.as_bytes(), Path::new("v.csv")).unwrap();
        assert_eq!(back.time_s, time_s);
        assert_eq!(back.bodies, tracks);
    }

    #[test]
    fn unwritable_velocities() {
        let track = |role: &str, n: usize| VelocityTrack {
            role: role.into(),
            twists: vec![None; n],
        };
        for (tracks, want) in [
            (
                vec![track("cube", 1)],
                "have 1 samples but the trajectory has 2",
            ),
            (vec![track("a,b", 2)], "cannot be a CSV column prefix"),
            (vec![track("cube", 2), track("cube", 2)], "appears twice"),
        ] {
            let e = format_velocities_csv(&[0.0, 0.1], &tracks).unwrap_err();
            assert!(e.to_string().contains(want), "{e}");
        }
    }

    #[test]
    fn bad_velocities_files_are_located_errors() {
        let head = "t_s,cube_vx_m_s,cube_vy_m_s,cube_vz_m_s,cube_wx_body_rad_s,cube_wy_body_rad_s,cube_wz_body_rad_s\n";
        let with = |rows: &str| format!("{head}{rows}");
        let cases = [
            (String::new(), "v.csv: the file is empty"),
            (
                "time,cube_vx_m_s\n".to_string(),
                "v.csv:1: column 1: expected the column name \"t_s\"",
            ),
            (
                "t_s,cube_x_m\n".to_string(),
                "v.csv:1: column 2: unexpected column name \"cube_x_m\"",
            ),
            (
                "t_s,cube_vx_m_s,cube_vy_m_s,cube_vz_m_s,cube_wx_rad_s\n".to_string(),
                "v.csv:1: column 5: expected the column name \"cube_wx_body_rad_s\"",
            ),
            (
                "t_s,cube_vx_m_s,cube_vy_m_s\n".to_string(),
                "v.csv:1: column 4: the header ends before the column \"cube_vz_m_s\"",
            ),
            (with("0,1,2,3,4,5\n"), "v.csv:2: expected 7 columns"),
            (
                with("0,1,2,x,4,5,6\n"),
                "v.csv:2: column 4 (cube_vz_m_s): expected a number, found \"x\"",
            ),
            (
                with("0,1,2,3,,5,6\n"),
                "v.csv:2: column 5 (cube_wx_body_rad_s): a velocity needs all six cells",
            ),
            (
                with("1,,,,,,\n0.5,,,,,,\n"),
                "v.csv:3: column 1 (t_s): time 0.5 s is not finite or goes backwards",
            ),
        ];
        for (text, want) in cases {
            let e = parse_velocities_csv(text.as_bytes(), Path::new("v.csv")).unwrap_err();
            assert!(e.to_string().starts_with(want), "{text:?}: {e}");
        }
    }
}
