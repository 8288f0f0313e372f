//! Study files: which scenes, which reference, which sources.
//!
//! A study file is TOML:
//!
//! ```toml
//! name = "collins2019"
//! control_period_s = 0.05
//!
//! # Sources listed once, used in every scene; `{name}` placeholders are
//! # filled from each scene's `vars`.
//! [[sources]]
//! name = "MuJoCo"
//! format = "recorded"            # recorded | qualisys | store
//! files = "Simulation/{experiment}/{prefix}_Mujoco_*.csv"
//! quat_order = "wxyz"
//!
//! # Optional: the real runs fitted on and scored on (numbers from 1 in
//! # file order); the command line's --runs / --holdout take precedence.
//! runs = "1-15"
//! holdout = "16-20"
//!
//! [[scenes]]
//! name = "scene1_single_joint"
//! # The scene file (relative to this study file): its schedule, controller
//! # and robot give the kinematic reference the real runs are aligned to.
//! scene = "../scenes/scene1_single_joint.toml"
//! steps = 120
//! goal_m = [0.49, 0.07, 0.29]
//! vars = { experiment = "Experiment1", prefix = "Single" }
//! [scenes.reference]
//! name = "real"
//! format = "qualisys"
//! files = "MotionCapture/{experiment}/{prefix}*_6D.tsv"
//! alignment = { method = "onset", lead_frames = 93 }
//! ```
//!
//! `files` is a path relative to the data directory (`--data`, else the
//! study file's folder) whose last component may hold `*` wildcards; the
//! matches are taken in natural order (`_2` before `_10`). A `store` source
//! names a results directory (`dir`), relative to the results directory
//! given on the command line, else to the study file's folder.

use anyhow::{anyhow, bail, Context, Result};
use realitygap_analysis::align::Alignment;
use realitygap_analysis::compare::CubeSpec;
use realitygap_data::QuatOrder;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A whole study file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Study {
    /// Short name.
    pub name: String,
    /// Long title, for reports.
    #[serde(default)]
    pub title: Option<String>,
    /// Control period of the compared data, seconds.
    #[serde(default = "default_period")]
    pub control_period_s: f64,
    /// Sources used in every scene.
    #[serde(default)]
    pub sources: Vec<SourceSpec>,
    /// The scenes.
    pub scenes: Vec<StudyScene>,
    /// Real runs to fit on (and to score on without `holdout`), e.g.
    /// `"1-15"`; default all.
    #[serde(default)]
    pub runs: Option<String>,
    /// Real runs to score on and never fit on, e.g. `"16-20"`.
    #[serde(default)]
    pub holdout: Option<String>,
    /// The study file's folder (scene files are relative to it); set when
    /// the file is read.
    #[serde(skip)]
    pub folder: PathBuf,
}

fn default_period() -> f64 {
    0.05
}

/// One scene of a study.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyScene {
    /// Scene name.
    pub name: String,
    /// The scene file, relative to the study file's folder: its schedule,
    /// controller and robot give the kinematic reference.
    #[serde(default)]
    pub scene: Option<String>,
    /// Control steps compared (120 for the study's scene 1, 400 otherwise).
    pub steps: usize,
    /// Wrist position at the final target configuration, metres.
    #[serde(default)]
    pub goal_m: Option<[f64; 3]>,
    /// Convergence tolerance, metres (default 0.01).
    #[serde(default = "default_tol")]
    pub goal_tolerance_m: f64,
    /// Start times of the schedule's phases, seconds.
    #[serde(default)]
    pub phases_s: Vec<f64>,
    /// Cube measures, for scenes with a cube.
    #[serde(default)]
    pub cube: Option<CubeSpec>,
    /// Values for `{placeholders}` in file patterns.
    #[serde(default)]
    pub vars: BTreeMap<String, String>,
    /// The reference (usually the real arm).
    pub reference: SourceSpec,
    /// Sources of this scene only, after the study-wide ones.
    #[serde(default)]
    pub sources: Vec<SourceSpec>,
}

fn default_tol() -> f64 {
    0.01
}

/// Where a source's runs come from.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    /// Display name.
    pub name: String,
    /// What the source is, in words (simulator version, settings), for the
    /// report's provenance.
    #[serde(default)]
    pub about: Option<String>,
    /// `qualisys`, `recorded` or `store`.
    pub format: SourceFormat,
    /// File pattern (qualisys, recorded).
    #[serde(default)]
    pub files: Option<String>,
    /// Results directory (store).
    #[serde(default)]
    pub dir: Option<String>,
    /// Quaternion order of recorded files.
    #[serde(default)]
    pub quat_order: Option<QuatOrder>,
    /// Alignment of a recording on its own clock (qualisys).
    #[serde(default)]
    pub alignment: Option<Alignment>,
    /// Capture frequency of headerless qualisys files, Hz (default 100).
    #[serde(default)]
    pub frequency_hz: Option<f64>,
    /// Body names of headerless qualisys files, in file order.
    #[serde(default)]
    pub bodies: Option<Vec<String>>,
    /// Body name -> role (`wrist`, `cube`, `base`) for qualisys files.
    #[serde(default)]
    pub roles: Option<BTreeMap<String, String>>,
}

/// Source file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceFormat {
    /// Qualisys 6DOF TSV (the real arm).
    Qualisys,
    /// Recorded simulator CSV (14 numbers per control step).
    Recorded,
    /// A realitygap results directory.
    Store,
}

impl Study {
    /// Reads and checks a study file; errors name the file and the TOML
    /// line and column.
    pub fn from_file(path: &Path) -> Result<Study> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read study file {}", path.display()))?;
        Study::from_toml_str(&text, path)
    }

    /// Parses and checks a study from its text; `path` names it in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Study> {
        let mut study: Study = toml::from_str(text)
            .map_err(|e| anyhow!("{}: {}", path.display(), toml_error(text, &e)))?;
        study.folder = path.parent().map(Path::to_path_buf).unwrap_or_default();
        study
            .check()
            .with_context(|| format!("in study file {}", path.display()))?;
        Ok(study)
    }

    fn check(&self) -> Result<()> {
        if self.control_period_s.is_nan() || self.control_period_s <= 0.0 {
            bail!(
                "control_period_s must be positive, found {}",
                self.control_period_s
            );
        }
        if self.scenes.is_empty() {
            bail!("no [[scenes]]");
        }
        for (field, value) in [("runs", &self.runs), ("holdout", &self.holdout)] {
            if let Some(v) = value {
                realitygap_analysis::selection::RunRange::parse(v, &format!("`{field}`"))?;
            }
        }
        for s in &self.scenes {
            if s.steps == 0 {
                bail!("scene '{}': steps must be at least 1", s.name);
            }
            for src in self.sources.iter().chain(&s.sources).chain([&s.reference]) {
                src.check()
                    .with_context(|| format!("scene '{}', source '{}'", s.name, src.name))?;
            }
        }
        Ok(())
    }
}

/// Formats a TOML error with its line and column.
pub fn toml_error(text: &str, e: &toml::de::Error) -> String {
    match e.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            let col = span.start
                - text[..span.start.min(text.len())]
                    .rfind('\n')
                    .map_or(0, |i| i + 1)
                + 1;
            format!("line {line}, column {col}: {}", e.message())
        }
        None => e.message().to_string(),
    }
}

impl SourceSpec {
    fn check(&self) -> Result<()> {
        match self.format {
            SourceFormat::Qualisys | SourceFormat::Recorded if self.files.is_none() => {
                bail!("format '{:?}' needs `files`", self.format)
            }
            SourceFormat::Recorded if self.quat_order.is_none() => {
                bail!("format 'recorded' needs `quat_order` (\"wxyz\" or \"xyzw\")")
            }
            SourceFormat::Store if self.dir.is_none() => bail!("format 'store' needs `dir`"),
            _ => Ok(()),
        }
    }
}

/// Fills `{name}` placeholders from `vars`.
pub fn expand(pattern: &str, vars: &BTreeMap<String, String>) -> Result<String> {
    let mut out = pattern.to_string();
    for (k, v) in vars {
        out = out.replace(&format!("{{{k}}}"), v);
    }
    if let Some(i) = out.find('{') {
        let end = out[i..].find('}').map_or(out.len(), |j| i + j + 1);
        bail!(
            "pattern '{pattern}' has an unknown placeholder {} (scene vars: {:?})",
            &out[i..end],
            vars.keys().collect::<Vec<_>>()
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders() {
        let vars: BTreeMap<String, String> = [("e".to_string(), "Experiment1".to_string())].into();
        assert_eq!(expand("S/{e}/a.csv", &vars).unwrap(), "S/Experiment1/a.csv");
        assert!(expand("S/{x}/a.csv", &vars)
            .unwrap_err()
            .to_string()
            .contains("{x}"));
    }

    #[test]
    fn bad_study_files_name_the_line() {
        let dir = std::env::temp_dir().join(format!("rg-study-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.toml");
        std::fs::write(
            &p,
            "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = \"many\"\n",
        )
        .unwrap();
        let e = format!("{:#}", Study::from_file(&p).unwrap_err());
        assert!(e.contains("bad.toml") && e.contains("line 4"), "{e}");
        std::fs::write(&p, "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = 3\n[scenes.reference]\nname = \"r\"\nformat = \"recorded\"\nfiles = \"a\"\n").unwrap();
        let e = format!("{:#}", Study::from_file(&p).unwrap_err());
        assert!(e.contains("quat_order"), "{e}");
        std::fs::write(&p, "name = \"x\"\nholdout = \"16-\"\n[[scenes]]\nname = \"s\"\nsteps = 3\n[scenes.reference]\nname = \"r\"\nformat = \"store\"\ndir = \"d\"\n").unwrap();
        let e = format!("{:#}", Study::from_file(&p).unwrap_err());
        assert!(
            e.contains("bad.toml") && e.contains("`holdout` \"16-\""),
            "{e}"
        );
    }
}
