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
use rayon::prelude::*;
use realitygap_analysis::align::Alignment;
use realitygap_analysis::compare::{CubeSpec, RunInput, SceneSpec, SourceRuns};
use realitygap_analysis::kinematic::{kinematic_track, KinematicTrack};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::WRIST;
use realitygap_data::{
    qualisys, recorded, QualisysOptions, QuatOrder, RecordedOptions, RunStatus, RunStore,
    SourceKind,
};
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
        if !(self.control_period_s > 0.0) {
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

/// Where relative paths point.
#[derive(Debug, Clone)]
pub struct Roots {
    /// For `files` patterns.
    pub data: PathBuf,
    /// For `store` directories.
    pub results: PathBuf,
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

/// Files matching a pattern whose last component may hold `*`, in natural
/// order. An error when the folder is missing or nothing matches.
pub fn glob(root: &Path, pattern: &str) -> Result<Vec<PathBuf>> {
    let full = root.join(pattern);
    let name = full
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| anyhow!("bad file pattern '{pattern}'"))?
        .to_string();
    let dir = full.parent().map(Path::to_path_buf).unwrap_or_default();
    if !name.contains('*') {
        if full.is_file() {
            return Ok(vec![full]);
        }
        bail!("file not found: {}", full.display());
    }
    let entries = std::fs::read_dir(&dir).with_context(|| {
        format!(
            "cannot list folder {} (for pattern '{pattern}')",
            dir.display()
        )
    })?;
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().map(|t| t.is_file()).unwrap_or(false))
        .filter(|e| {
            e.file_name()
                .to_str()
                .is_some_and(|n| wildcard_match(&name, n))
        })
        .map(|e| e.path())
        .collect();
    if out.is_empty() {
        bail!("no file matches {}", full.display());
    }
    out.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    Ok(out)
}

/// `*` matches any run of characters; everything else literally.
pub fn wildcard_match(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !name.starts_with(first)
        || !name[first.len()..].ends_with(last)
        || name.len() < first.len() + last.len()
    {
        return false;
    }
    let mut rest = &name[first.len()..name.len() - last.len()];
    for mid in &parts[1..parts.len() - 1] {
        match rest.find(mid) {
            Some(i) => rest = &rest[i + mid.len()..],
            None => return false,
        }
    }
    true
}

/// Compares strings with digit runs as numbers (`a2` < `a10`).
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return std::cmp::Ordering::Equal,
            (None, _) => return std::cmp::Ordering::Less,
            (_, None) => return std::cmp::Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let na = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let nb = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (da, db) = (&a[..na], &b[..nb]);
                let strip = |d: &[u8]| -> Vec<u8> {
                    d.iter().skip_while(|c| **c == b'0').copied().collect()
                };
                let (sa, sb) = (strip(da), strip(db));
                let ord = sa.len().cmp(&sb.len()).then(sa.cmp(&sb)).then(na.cmp(&nb));
                if ord != std::cmp::Ordering::Equal {
                    return ord;
                }
                a = &a[na..];
                b = &b[nb..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Reads every run of a source. Files are read in parallel, each once.
pub fn load_source(
    spec: &SourceSpec,
    vars: &BTreeMap<String, String>,
    roots: &Roots,
    period_s: f64,
) -> Result<SourceRuns> {
    let ctx = || format!("source '{}'", spec.name);
    match spec.format {
        SourceFormat::Qualisys => {
            let pattern =
                expand(spec.files.as_deref().unwrap_or_default(), vars).with_context(ctx)?;
            let files = glob(&roots.data, &pattern).with_context(ctx)?;
            let mut opts = QualisysOptions::collins2019();
            if let Some(f) = spec.frequency_hz {
                opts.frequency_hz = Some(f);
            }
            if let Some(b) = &spec.bodies {
                opts.body_names = Some(b.clone());
            }
            if let Some(r) = &spec.roles {
                opts.roles = r.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
            }
            let runs: Vec<(RunInput, f64)> = files
                .par_iter()
                .map(|f| {
                    let r = qualisys::read(f, &opts)?;
                    Ok((
                        RunInput {
                            id: stem(f),
                            trajectory: r.trajectory,
                            failed: None,
                        },
                        r.frequency_hz,
                    ))
                })
                .collect::<Result<_, realitygap_data::ImportError>>()
                .with_context(ctx)?;
            let rate = runs.first().map_or(100.0, |r| r.1);
            if let Some((r, f)) = runs.iter().find(|r| (r.1 - rate).abs() > 1e-9) {
                bail!(
                    "source '{}': run {} is at {f} Hz but the first run is at {rate} Hz",
                    spec.name,
                    r.id
                );
            }
            Ok(SourceRuns {
                name: spec.name.clone(),
                kind: "real".into(),
                rate_hz: rate,
                alignment: Some(spec.alignment.clone().unwrap_or_else(Alignment::estimate)),
                runs: runs.into_iter().map(|r| r.0).collect(),
            })
        }
        SourceFormat::Recorded => {
            let pattern =
                expand(spec.files.as_deref().unwrap_or_default(), vars).with_context(ctx)?;
            let files = glob(&roots.data, &pattern).with_context(ctx)?;
            let opts = RecordedOptions {
                control_period_s: period_s,
                ..RecordedOptions::new(spec.quat_order.unwrap_or(QuatOrder::Wxyz))
            };
            let runs: Vec<RunInput> = files
                .par_iter()
                .map(|f| {
                    let r = recorded::read(f, &opts)?;
                    Ok(RunInput {
                        id: stem(f),
                        trajectory: r.trajectory,
                        failed: None,
                    })
                })
                .collect::<Result<_, realitygap_data::ImportError>>()
                .with_context(ctx)?;
            Ok(SourceRuns {
                name: spec.name.clone(),
                kind: "recorded".into(),
                rate_hz: 1.0 / period_s,
                alignment: None,
                runs,
            })
        }
        SourceFormat::Store => {
            let dir = roots
                .results
                .join(expand(spec.dir.as_deref().unwrap_or_default(), vars).with_context(ctx)?);
            load_store(&dir, Some(&spec.name), spec.alignment.clone())
        }
    }
}

/// Reads every run of a results directory as a source. Runs recorded as
/// failed or diverged are kept (with their message) so the analysis can
/// list them.
pub fn load_store(
    dir: &Path,
    name: Option<&str>,
    alignment: Option<Alignment>,
) -> Result<SourceRuns> {
    let store =
        RunStore::open(dir).with_context(|| format!("results directory {}", dir.display()))?;
    let m = store.manifest();
    let entries: Vec<_> = store.runs().to_vec();
    let runs: Vec<RunInput> = entries
        .par_iter()
        .map(|e| {
            let failed = match e.status {
                RunStatus::Ok => None,
                _ => Some(
                    e.message
                        .clone()
                        .unwrap_or_else(|| format!("{:?}", e.status).to_lowercase()),
                ),
            };
            let trajectory = match store.read_run(&e.id) {
                Ok(t) => t,
                // A failed run may have no trajectory file: keep it, empty.
                Err(_) if failed.is_some() => realitygap_core::Trajectory::default(),
                Err(err) => return Err(anyhow!("run '{}' of {}: {err}", e.id, dir.display())),
            };
            Ok(RunInput {
                id: e.id.clone(),
                trajectory,
                failed,
            })
        })
        .collect::<Result<_>>()?;
    let rate_hz = runs
        .iter()
        .find(|r| r.trajectory.len() > 1)
        .map(|r| {
            let t = &r.trajectory.time_s;
            (t.len() - 1) as f64 / (t[t.len() - 1] - t[0])
        })
        .filter(|f| f.is_finite() && *f > 0.0)
        .unwrap_or(20.0);
    let (kind, alignment) = match m.kind {
        SourceKind::Real => ("real", Some(alignment.unwrap_or_else(Alignment::estimate))),
        SourceKind::Simulated => ("simulated", None),
        SourceKind::Recorded => ("recorded", None),
    };
    Ok(SourceRuns {
        name: name.map_or_else(|| m.source.clone(), str::to_string),
        kind: kind.into(),
        rate_hz,
        alignment,
        runs,
    })
}

impl Study {
    /// The kinematic reference of a scene file (relative to the study's
    /// folder) over `steps` control steps.
    pub fn kinematic(&self, file: &str, steps: usize) -> Result<KinematicTrack> {
        let path = self.folder.join(file);
        let scene = Scene::from_file(&path)?;
        let robot = RobotModel::from_urdf_file(&scene.robot.urdf, &PackageResolver::from_env())
            .with_context(|| format!("robot of scene file {}", path.display()))?;
        kinematic_track(&scene, &robot, WRIST, steps)
            .map_err(|e| anyhow!("{}: {e}", path.display()))
    }
}

/// A scene ready for analysis: its spec, reference and sources.
pub struct LoadedScene {
    /// What the analysis needs of the scene.
    pub spec: SceneSpec,
    /// The reference's runs.
    pub reference: SourceRuns,
    /// The sources' runs.
    pub sources: Vec<SourceRuns>,
}

impl LoadedScene {
    /// The scene as input to `realitygap_analysis::evaluate_study`.
    pub fn input(&self) -> realitygap_analysis::SceneInput<'_> {
        realitygap_analysis::SceneInput {
            spec: &self.spec,
            reference: &self.reference,
            sources: &self.sources,
        }
    }
}

impl Study {
    /// Loads every scene's reference and sources.
    pub fn load(&self, roots: &Roots) -> Result<Vec<LoadedScene>> {
        self.scenes
            .iter()
            .map(|s| {
                let ctx = || format!("scene '{}'", s.name);
                let reference = load_source(&s.reference, &s.vars, roots, self.control_period_s)
                    .with_context(ctx)?;
                let specs: Vec<&SourceSpec> = self.sources.iter().chain(&s.sources).collect();
                let sources = specs
                    .par_iter()
                    .map(|src| load_source(src, &s.vars, roots, self.control_period_s))
                    .collect::<Result<Vec<_>>>()
                    .with_context(ctx)?;
                let kinematic = match &s.scene {
                    Some(file) => Some(self.kinematic(file, s.steps).with_context(|| {
                        format!("scene '{}': `scene = \"{file}\"` in the study file", s.name)
                    })?),
                    None => None,
                };
                Ok(LoadedScene {
                    spec: SceneSpec {
                        name: s.name.clone(),
                        steps: s.steps,
                        control_period_s: self.control_period_s,
                        goal_m: s.goal_m,
                        goal_tolerance_m: s.goal_tolerance_m,
                        phases_s: if s.phases_s.is_empty() {
                            vec![0.0]
                        } else {
                            s.phases_s.clone()
                        },
                        cube: s.cube.clone(),
                        kinematic,
                    },
                    reference,
                    sources,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcards_and_natural_order() {
        assert!(wildcard_match(
            "Single_Mujoco_*.csv",
            "Single_Mujoco_12.csv"
        ));
        assert!(!wildcard_match(
            "Single_Mujoco_*.csv",
            "Single_PyBullet_1.csv"
        ));
        assert!(wildcard_match("Single*_6D.tsv", "Single0001_6D.tsv"));
        assert!(!wildcard_match("a*b*c", "acb"));
        assert!(wildcard_match("a*b*c", "axxbyyc"));
        let mut v = vec!["x_10", "x_2", "x_1"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["x_1", "x_2", "x_10"]);
    }

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
