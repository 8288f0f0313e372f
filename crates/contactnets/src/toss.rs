//! One toss in SI units: the 1 x T x 19 tensor of an `N.pt` file, checked
//! and converted with the experiment's constants (`experiment.json`).
//!
//! Columns of the published tensor: position (3), orientation quaternion
//! (4, scalar first, body to world), linear velocity (3, world frame),
//! angular velocity (3, body frame), then 6 control inputs (zero: the cube
//! is free; not read). Lengths are in cube half-widths: one half-width is
//! `9.81 / g` metres, `g` being the gravity in half-widths/s² that
//! `experiment.json` gives (187.21, so 0.0524 m). Sample `k` is at
//! `k dt` seconds (`dt` = 1/148 s).

use crate::pt::{read_pt, PtTensor};
use realitygap_core::trajectory::CUBE;
use realitygap_core::{BodyTrack, Pose, Quat, Trajectory, Vec3};
use realitygap_data::{BodyTwist, ImportError, VelocityTrack};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Numbers per sample in the published tensor.
pub const COLUMNS: usize = 19;
/// The columns' names, for messages.
pub const COLUMN_NAMES: [&str; COLUMNS] = [
    "x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz", "u1", "u2", "u3",
    "u4", "u5", "u6",
];
/// The standard gravity the authors scaled with, m/s²: `g` in
/// half-widths/s² is `9.81 / half-width`.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.81;
/// Largest accepted deviation of a quaternion's norm from 1 (the published
/// ones are unit to 4e-16; they are normalised).
pub const QUAT_NORM_TOLERANCE: f64 = 1e-3;

/// The experiment's constants, from `experiment.json` or as published.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    /// Time between samples, s.
    pub dt_s: f64,
    /// Gravity in cube half-widths per s² (the data's length unit).
    pub g_half_widths_s2: f64,
    /// The cube's mass, kg, when given.
    pub mass_kg: Option<f64>,
    /// The friction coefficient the authors used (not a measurement).
    pub mu: Option<f64>,
    /// The coefficient of restitution the authors used (not a measurement).
    pub restitution: Option<f64>,
    /// The cube's edge in half-widths: the extent of its vertices (2).
    pub edge_half_widths: f64,
    /// The file read; `None` for the published constants.
    pub file: Option<PathBuf>,
}

/// `experiment.json` as written by the authors (other keys ignored).
#[derive(Deserialize)]
struct RawExperiment {
    dt: Option<f64>,
    g: Option<f64>,
    mass: Option<f64>,
    mu: Option<f64>,
    restitution: Option<f64>,
    vertices: Option<Vec<[f64; 3]>>,
}

impl Experiment {
    /// The published constants (`experiment.json` of DAIRLab/contact-nets):
    /// dt = 1/148 s, g = 187.21 half-widths/s², 0.37 kg, mu 0.18,
    /// restitution 0.125, a cube of edge 2 half-widths.
    pub fn published() -> Experiment {
        Experiment {
            dt_s: 0.006756756756756757,
            g_half_widths_s2: 187.21374045801525,
            mass_kg: Some(0.37),
            mu: Some(0.18),
            restitution: Some(0.125),
            edge_half_widths: 2.0,
            file: None,
        }
    }

    /// Reads an `experiment.json`: `dt` and `g` are required (positive),
    /// `mass`, `mu`, `restitution` and `vertices` (a cube's eight corners)
    /// are read when present.
    pub fn read(path: &Path) -> Result<Experiment, ImportError> {
        let bytes = std::fs::read(path)
            .map_err(|e| ImportError::new(path, format!("cannot read the file: {e}")))?;
        let raw: RawExperiment = serde_json::from_slice(&bytes).map_err(|e| {
            // serde's message without its own " at line L column C".
            let text = e.to_string();
            let text = text
                .rsplit_once(" at line ")
                .map_or(text.as_str(), |(m, _)| m);
            ImportError::at_line(path, e.line(), format!("not an experiment.json: {text}"))
                .with_column(e.column())
        })?;
        let positive =
            |v: Option<f64>, key: &str, what: &str| -> Result<Option<f64>, ImportError> {
                match v {
                    Some(x) if !(x.is_finite() && x > 0.0) => Err(ImportError::new(
                        path,
                        format!("{what} must be a positive number, found {x}"),
                    )
                    .with_field(key.to_string())),
                    other => Ok(other),
                }
            };
        let required = |v: Option<f64>, key: &str, what: &str| -> Result<f64, ImportError> {
            positive(v, key, what)?.ok_or_else(|| {
                ImportError::new(path, format!("missing: {what}")).with_field(key.to_string())
            })
        };
        let dt_s = required(raw.dt, "dt", "the time between samples (s)")?;
        let g = required(raw.g, "g", "the gravity in half-widths/s²")?;
        let mass_kg = positive(raw.mass, "mass", "the mass (kg)")?;
        let mu = non_negative(raw.mu, "mu", path)?;
        let restitution = non_negative(raw.restitution, "restitution", path)?;
        let edge_half_widths = match raw.vertices {
            None => 2.0,
            Some(v) => cube_edge(&v)
                .map_err(|m| ImportError::new(path, m).with_field("vertices".to_string()))?,
        };
        Ok(Experiment {
            dt_s,
            g_half_widths_s2: g,
            mass_kg,
            mu,
            restitution,
            edge_half_widths,
            file: Some(path.to_path_buf()),
        })
    }

    /// One half-width (the data's length unit) in metres: `9.81 / g`.
    pub fn half_width_m(&self) -> f64 {
        STANDARD_GRAVITY_M_S2 / self.g_half_widths_s2
    }

    /// The cube's edge, m.
    pub fn edge_m(&self) -> f64 {
        self.edge_half_widths * self.half_width_m()
    }

    /// The sampling frequency, Hz.
    pub fn frequency_hz(&self) -> f64 {
        1.0 / self.dt_s
    }
}

/// A number >= 0 when given.
fn non_negative(v: Option<f64>, key: &str, path: &Path) -> Result<Option<f64>, ImportError> {
    match v {
        Some(x) if !(x.is_finite() && x >= 0.0) => Err(ImportError::new(
            path,
            format!("must be a number >= 0, found {x}"),
        )
        .with_field(key.to_string())),
        other => Ok(other),
    }
}

/// The edge of the cube whose corners are `vertices`, in their unit.
fn cube_edge(vertices: &[[f64; 3]]) -> Result<f64, String> {
    if vertices.len() != 8 || vertices.iter().flatten().any(|x| !x.is_finite()) {
        return Err(format!(
            "expected a cube's 8 corners (finite numbers), found {} points",
            vertices.len()
        ));
    }
    let extent = |a: usize| {
        let (lo, hi) = vertices
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v[a]), hi.max(v[a]))
            });
        hi - lo
    };
    let e = [extent(0), extent(1), extent(2)];
    if e[0] <= 0.0 || (e[1] - e[0]).abs() > 1e-9 * e[0] || (e[2] - e[0]).abs() > 1e-9 * e[0] {
        return Err(format!(
            "the corners span {} x {} x {}: not a cube",
            e[0], e[1], e[2]
        ));
    }
    Ok(e[0])
}

/// One toss, in SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct Toss {
    /// The toss's number (the file's stem).
    pub number: u64,
    /// The file read.
    pub file: PathBuf,
    /// Sample times, s: `k dt`.
    pub time_s: Vec<f64>,
    /// The cube's pose at each sample: centre in metres (ground at z = 0),
    /// orientation body to world.
    pub poses: Vec<Pose>,
    /// The cube's velocity at each sample: linear (world frame, m/s) and
    /// angular (body frame, rad/s).
    pub twists: Vec<BodyTwist>,
    /// The largest deviation of a recorded quaternion's norm from 1
    /// (before normalising).
    pub max_quat_norm_error: f64,
    /// What a person should know that did not stop the import.
    pub warnings: Vec<String>,
}

impl Toss {
    /// Reads toss `number` from its `.pt` file.
    pub fn read(path: &Path, number: u64, experiment: &Experiment) -> Result<Toss, ImportError> {
        let bytes = std::fs::read(path)
            .map_err(|e| ImportError::new(path, format!("cannot read the file: {e}")))?;
        let tensor = read_pt(&bytes, path)?;
        Toss::from_tensor(&tensor, number, path, experiment)
    }

    /// Checks a tensor (1 x T x 19, finite poses and velocities, unit
    /// quaternions) and converts it to SI units; errors name `file`, the
    /// byte offset, the sample and the column.
    pub fn from_tensor(
        tensor: &PtTensor,
        number: u64,
        file: &Path,
        experiment: &Experiment,
    ) -> Result<Toss, ImportError> {
        let at = |byte: usize, field: String, message: String| {
            ImportError::new(file, message).with_field(format!("byte {byte} ({field})"))
        };
        let samples = match tensor.shape[..] {
            [1, t, COLUMNS] if t > 0 => t,
            _ => {
                let shown: Vec<String> = tensor.shape.iter().map(|d| d.to_string()).collect();
                return Err(at(
                    tensor.shape_at,
                    "tensor size".into(),
                    format!(
                        "expected a 1 x T x 19 tensor (one toss: T > 0 samples of 19 columns), found {}",
                        if shown.is_empty() { "a scalar".to_string() } else { shown.join(" x ") }
                    ),
                ));
            }
        };
        let scale = experiment.half_width_m();
        let mut toss = Toss {
            number,
            file: file.to_path_buf(),
            time_s: Vec::with_capacity(samples),
            poses: Vec::with_capacity(samples),
            twists: Vec::with_capacity(samples),
            max_quat_norm_error: 0.0,
            warnings: Vec::new(),
        };
        let mut nonzero_controls = 0usize;
        for (k, row) in tensor.values.chunks_exact(COLUMNS).enumerate() {
            let byte = |c: usize| tensor.values_at + 8 * (k * COLUMNS + c);
            let field =
                |c: usize| format!("sample {} of {samples}, column {}", k + 1, COLUMN_NAMES[c]);
            if let Some(c) = row[..13].iter().position(|x| !x.is_finite()) {
                let what = if c < 7 { "pose" } else { "velocity" };
                return Err(at(
                    byte(c),
                    field(c),
                    format!("{} in the cube's {what}", row[c]),
                ));
            }
            nonzero_controls += row[13..].iter().filter(|&&u| u != 0.0).count();
            let q = Quat::new(row[3], row[4], row[5], row[6]);
            let norm = q.norm();
            let error = (norm - 1.0).abs();
            if error > QUAT_NORM_TOLERANCE {
                return Err(at(
                    byte(3),
                    field(3),
                    format!("the orientation quaternion's norm is {norm:.6}, not 1 (within {QUAT_NORM_TOLERANCE})"),
                ));
            }
            toss.max_quat_norm_error = toss.max_quat_norm_error.max(error);
            let orientation = q.normalized().unwrap_or(q);
            toss.time_s.push(k as f64 * experiment.dt_s);
            toss.poses.push(Pose::new(
                Vec3::new(row[0], row[1], row[2]).scale(scale),
                orientation,
            ));
            toss.twists.push(BodyTwist {
                linear_m_s: Vec3::new(row[7], row[8], row[9]).scale(scale),
                angular_body_rad_s: Vec3::new(row[10], row[11], row[12]),
            });
        }
        if nonzero_controls > 0 {
            toss.warnings.push(format!(
                "{nonzero_controls} control inputs (columns u1-u6) are not zero; they are not read (the cube is taken as free)"
            ));
        }
        Ok(toss)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when there is no sample (never, for a toss read).
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// The toss as a run's trajectory: one body, `cube`.
    pub fn trajectory(&self) -> Trajectory {
        let mut t = Trajectory::with_bodies(&[CUBE]);
        t.time_s = self.time_s.clone();
        t.bodies[0] = BodyTrack {
            role: CUBE.to_string(),
            poses: self.poses.iter().copied().map(Some).collect(),
        };
        t
    }

    /// The cube's velocities, for the run's velocities file.
    pub fn velocities(&self) -> VelocityTrack {
        VelocityTrack {
            role: CUBE.to_string(),
            twists: self.twists.iter().copied().map(Some).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn published_constants_give_the_readme_units() {
        let e = Experiment::published();
        assert!((e.half_width_m() - 0.0524).abs() < 1e-12);
        assert!((e.edge_m() - 0.1048).abs() < 1e-12);
        assert!((e.frequency_hz() - 148.0).abs() < 1e-9);
    }

    #[test]
    fn experiment_files_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("experiment.json");
        let cases = [
            ("{\"dt\": 0.01", "experiment.json:1: column 11: not an experiment.json"),
            ("{\"g\": 187}", "experiment.json: dt: missing: the time between samples (s)"),
            ("{\"dt\": 0.01, \"g\": -1}", "experiment.json: g: the gravity in half-widths/s² must be a positive number, found -1"),
            ("{\"dt\": 0.01, \"g\": 187, \"mu\": -0.1}", "experiment.json: mu: must be a number >= 0, found -0.1"),
            ("{\"dt\": 0.01, \"g\": 187, \"vertices\": [[0,0,0]]}", "experiment.json: vertices: expected a cube's 8 corners"),
            ("{\"dt\": \"x\", \"g\": 187}", "experiment.json:1: column 10: not an experiment.json: invalid type: string \"x\", expected f64"),
        ];
        for (text, want) in cases {
            std::fs::write(&path, text).unwrap();
            let e = Experiment::read(&path).unwrap_err().to_string();
            let e = e
                .replace(&format!("{}", dir.path().display()), "")
                .replacen('/', "", 1);
            assert!(e.starts_with(want), "{text}: {e}");
        }
        let mut corners = Vec::new();
        for x in [-1.5, 1.5] {
            for y in [-1.5, 1.5] {
                for z in [-1.5, 1.5] {
                    corners.push(format!("[{x},{y},{z}]"));
                }
            }
        }
        std::fs::write(
            &path,
            format!(
                "{{\"dt\": 0.01, \"g\": 98.1, \"vertices\": [{}], \"other\": 1}}",
                corners.join(",")
            ),
        )
        .unwrap();
        let e = Experiment::read(&path).unwrap();
        assert_eq!(e.edge_half_widths, 3.0);
        assert!((e.edge_m() - 0.3).abs() < 1e-12);
        assert_eq!((e.mass_kg, e.mu, e.restitution), (None, None, None));
    }
}
