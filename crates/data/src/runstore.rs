//! The results directory: `manifest.json` plus one CSV per run.
//!
//! ```text
//! results/mujoco-scene1/
//!   manifest.json        tool version, source, kind, scene, engine, settings, one entry per run
//!   runs/<run id>.csv    the run's trajectory
//!   runs/<run id>.commands.csv   the joint commands it was driven by, at their
//!                        own timestamps (runs of a joint recording only)
//!   runs/<run id>.velocities.csv the bodies' recorded velocities (runs of a
//!                        free object whose source records them, such as
//!                        the ContactNets tosses)
//! ```
//!
//! One directory holds one source (an engine, the real arm, a recorded
//! simulator) on one scene; a parent directory may hold many of them
//! ([`discover`] finds them).
//!
//! Every file is written atomically (temporary file in the same directory,
//! fsync, rename), and the manifest is rewritten after every run, so an
//! interrupted batch loses no finished run and a rerun can ask
//! [`RunStore::has_finished_run`]. One process at a time should write a
//! given directory (the store takes `&mut self`; share it behind a mutex).
//!
//! # Run CSV
//!
//! Comma-separated, LF line ends, one header line then one row per sample:
//! `t_s`, then for each body `<role>_x_m,<role>_y_m,<role>_z_m,<role>_qw,
//! <role>_qx,<role>_qy,<role>_qz` (position in metres, unit quaternion body
//! to world), then when known `q1_rad..qN_rad` (joint angles) and
//! `qd_cmd1_rad_s..qd_cmdN_rad_s` (commanded joint velocities), then for
//! joint recordings `qd1_rad_s..qdN_rad_s` (measured joint velocities) and
//! `tau1_nm..tauN_nm` (measured joint efforts). A gap (lost
//! pose) is seven empty cells. Numbers are printed with the shortest text
//! that reads back to the same `f64` (exponent form below 1e-5 and from
//! 1e16 on; `NaN`, `inf`, `-inf`), so a written run reads back exactly.
//! `pandas.read_csv` reads it as is.

use crate::error::ImportError;
use realitygap_core::Trajectory;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::fs;
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};

mod commandcsv;
mod runcsv;
mod velocitycsv;
pub use commandcsv::{format_commands_csv, parse_commands_csv};
pub use runcsv::{format_run_csv, parse_run_csv, read_run_csv, run_columns};
pub use velocitycsv::{
    format_velocities_csv, parse_velocities_csv, BodyTwist, RunVelocities, VelocityTrack,
};

/// File name of the manifest in a results directory.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Sub-directory of a results directory holding the run CSVs.
pub const RUNS_DIR: &str = "runs";

/// Where a results directory's trajectories come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceKind {
    /// The real robot (motion capture).
    Real,
    /// Simulated by realitygap with one of its engines.
    Simulated,
    /// Simulated elsewhere, imported from recorded files.
    Recorded,
}

impl fmt::Display for SourceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SourceKind::Real => "real",
            SourceKind::Simulated => "simulated",
            SourceKind::Recorded => "recorded",
        })
    }
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunStatus {
    /// Finished; its trajectory is stored.
    Ok,
    /// Did not produce a trajectory (the message says why).
    Failed,
    /// Finished but the simulation blew up; its trajectory is stored.
    Diverged,
    /// Finished, but its motion has the signature of a numerical
    /// instability (`realitygap_core::instability`; the message says which
    /// joint and when); its trajectory is stored.
    Unstable,
}

impl fmt::Display for RunStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            RunStatus::Ok => "ok",
            RunStatus::Failed => "failed",
            RunStatus::Diverged => "diverged",
            RunStatus::Unstable => "unstable",
        })
    }
}

/// Name and version of the physics engine that produced a directory's runs.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EngineInfo {
    /// Engine name, e.g. `mujoco`.
    pub name: String,
    /// Engine version, e.g. `3.1.6`.
    pub version: String,
}

/// One run in the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunEntry {
    /// Run id, unique in the directory; also the CSV's file stem.
    pub id: String,
    /// Path of the run's CSV relative to the directory (`runs/<id>.csv`);
    /// empty for a failed run without trajectory.
    #[serde(default)]
    pub file: String,
    /// Path of the run's commands file relative to the directory
    /// (`runs/<id>.commands.csv`), for a run driven by recorded commands.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commands_file: Option<String>,
    /// Path of the run's velocities file relative to the directory
    /// (`runs/<id>.velocities.csv`), for a run whose bodies' velocities
    /// were recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocities_file: Option<String>,
    /// Files the run was imported from (empty for simulated runs).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub origin: Vec<String>,
    /// How the run ended.
    pub status: RunStatus,
    /// Why it failed or diverged, or what the importer noticed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    /// Random seed, for engines that use one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Wall-clock time the run took, in seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_time_s: Option<f64>,
    /// Anything else worth keeping (counts of gaps, zero rows, ...).
    #[serde(default, skip_serializing_if = "serde_json::Map::is_empty")]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl RunEntry {
    /// An `ok` entry with this id and nothing else set.
    pub fn new(id: impl Into<String>) -> Self {
        RunEntry {
            id: id.into(),
            file: String::new(),
            commands_file: None,
            velocities_file: None,
            origin: Vec::new(),
            status: RunStatus::Ok,
            message: None,
            seed: None,
            wall_time_s: None,
            extra: serde_json::Map::new(),
        }
    }
}

/// The contents of `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Version of realitygap that last wrote the directory.
    pub tool_version: String,
    /// Name of the source: an engine (`mujoco`), `real`, or a recorded
    /// simulator (`VRepODE`).
    pub source: String,
    /// What kind of source it is.
    pub kind: SourceKind,
    /// The scene the runs are of.
    #[serde(default)]
    pub scene: Option<String>,
    /// The engine, for simulated runs.
    #[serde(default)]
    pub engine: Option<EngineInfo>,
    /// Parameters used (timestep, controller, importer options, ...).
    #[serde(default)]
    pub settings: serde_json::Value,
    /// The runs, in the order they were first written.
    #[serde(default)]
    pub runs: Vec<RunEntry>,
}

/// Errors of the results directory.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file operation failed.
    #[error("cannot {action} {}: {reason}", path.display())]
    Io {
        /// What was being done (`read`, `write`, `create`, ...).
        action: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        reason: io::Error,
    },
    /// `manifest.json` is not a valid manifest.
    #[error("{}:{line}:{column}: not a valid realitygap manifest: {message}", path.display())]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// Line of the problem (1-based).
        line: usize,
        /// Column of the problem (1-based).
        column: usize,
        /// serde's description.
        message: String,
    },
    /// The directory holds another source, kind or scene than asked for.
    #[error("{}: {message}", path.display())]
    Mismatch {
        /// The results directory.
        path: PathBuf,
        /// What differs.
        message: String,
    },
    /// A run id that cannot be a file name.
    #[error("invalid run id {id:?}: {reason}")]
    InvalidRunId {
        /// The id.
        id: String,
        /// Why.
        reason: String,
    },
    /// No run with this id.
    #[error("{}: no run '{id}' in the manifest", dir.display())]
    UnknownRun {
        /// The results directory.
        dir: PathBuf,
        /// The id asked for.
        id: String,
    },
    /// The run has no stored trajectory, or its entry points outside the
    /// directory.
    #[error("{}: run '{id}': {message}", dir.display())]
    NoTrajectory {
        /// The results directory.
        dir: PathBuf,
        /// The run.
        id: String,
        /// Why.
        message: String,
    },
    /// A trajectory that cannot be stored.
    #[error("run '{id}': {message}")]
    InvalidTrajectory {
        /// The run (empty when not known).
        id: String,
        /// What is wrong.
        message: String,
    },
    /// A run CSV that cannot be read.
    #[error(transparent)]
    RunCsv(#[from] ImportError),
}

fn io_err<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(io::Error) -> StoreError + 'a {
    move |reason| StoreError::Io {
        action,
        path: path.to_path_buf(),
        reason,
    }
}

/// A results directory open for reading and writing.
#[derive(Debug)]
pub struct RunStore {
    dir: PathBuf,
    manifest: Manifest,
}

impl RunStore {
    /// Opens the results directory `dir`, or creates it (with an empty
    /// manifest) when it has no manifest yet. An existing directory must
    /// hold the same source, kind and scene.
    pub fn create_or_open(
        dir: &Path,
        source: &str,
        kind: SourceKind,
        scene: Option<&str>,
    ) -> Result<Self, StoreError> {
        if dir.join(MANIFEST_FILE).exists() {
            let store = RunStore::open(dir)?;
            let m = &store.manifest;
            if m.source != source || m.kind != kind || m.scene.as_deref() != scene {
                let describe = |s: &str, k: SourceKind, sc: Option<&str>| {
                    format!(
                        "source '{s}' ({k}), scene {}",
                        sc.map_or("(none)".to_string(), |s| format!("'{s}'"))
                    )
                };
                return Err(StoreError::Mismatch {
                    path: dir.to_path_buf(),
                    message: format!(
                        "this results directory holds {}, not {}; use another output directory",
                        describe(&m.source, m.kind, m.scene.as_deref()),
                        describe(source, kind, scene)
                    ),
                });
            }
            return Ok(store);
        }
        let runs = dir.join(RUNS_DIR);
        fs::create_dir_all(&runs).map_err(io_err("create", &runs))?;
        let store = RunStore {
            dir: dir.to_path_buf(),
            manifest: Manifest {
                tool_version: realitygap_core::TOOL_VERSION.to_string(),
                source: source.to_string(),
                kind,
                scene: scene.map(str::to_string),
                engine: None,
                settings: serde_json::Value::Object(serde_json::Map::new()),
                runs: Vec::new(),
            },
        };
        store.save_manifest()?;
        Ok(store)
    }

    /// Opens an existing results directory.
    pub fn open(dir: &Path) -> Result<Self, StoreError> {
        let path = dir.join(MANIFEST_FILE);
        let bytes = fs::read(&path).map_err(io_err("read", &path))?;
        let manifest: Manifest =
            serde_json::from_slice(&bytes).map_err(|e| StoreError::Manifest {
                path: path.clone(),
                line: e.line(),
                column: e.column(),
                message: e.to_string(),
            })?;
        for (i, run) in manifest.runs.iter().enumerate() {
            if manifest.runs[..i].iter().any(|r| r.id == run.id) {
                return Err(StoreError::Mismatch {
                    path,
                    message: format!("run id '{}' appears twice in the manifest", run.id),
                });
            }
        }
        Ok(RunStore {
            dir: dir.to_path_buf(),
            manifest,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The manifest as last written.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The runs, in the order they were first written.
    pub fn runs(&self) -> &[RunEntry] {
        &self.manifest.runs
    }

    /// The entry of run `id`.
    pub fn run(&self, id: &str) -> Option<&RunEntry> {
        self.manifest.runs.iter().find(|r| r.id == id)
    }

    /// Replaces the settings and rewrites the manifest.
    pub fn set_settings(&mut self, settings: serde_json::Value) -> Result<(), StoreError> {
        self.manifest.settings = settings;
        self.save_manifest()
    }

    /// Records the engine and rewrites the manifest.
    pub fn set_engine(&mut self, engine: EngineInfo) -> Result<(), StoreError> {
        self.manifest.engine = Some(engine);
        self.save_manifest()
    }

    /// True when run `id` finished (status `ok` or `diverged`) and its CSV
    /// exists: a rerun can skip it.
    pub fn has_finished_run(&self, id: &str) -> bool {
        self.run(id).is_some_and(|r| {
            matches!(
                r.status,
                RunStatus::Ok | RunStatus::Diverged | RunStatus::Unstable
            ) && !r.file.is_empty()
                && self.dir.join(&r.file).is_file()
        })
    }

    /// Stores a run: writes `runs/<id>.csv` atomically, then adds (or
    /// replaces) its manifest entry and rewrites the manifest atomically.
    /// `entry.file` is set by the store.
    pub fn write_run(
        &mut self,
        entry: RunEntry,
        trajectory: &Trajectory,
    ) -> Result<(), StoreError> {
        self.write_run_with_velocities(entry, trajectory, &[])
    }

    /// Stores a run as [`RunStore::write_run`] does, with its bodies'
    /// recorded velocities in `runs/<id>.velocities.csv` (each track's role
    /// one of the trajectory's bodies, one entry per sample); no tracks
    /// writes no velocities file (and removes one an earlier run left).
    pub fn write_run_with_velocities(
        &mut self,
        mut entry: RunEntry,
        trajectory: &Trajectory,
        velocities: &[VelocityTrack],
    ) -> Result<(), StoreError> {
        validate_run_id(&entry.id)?;
        let with_id = |e: StoreError| match e {
            StoreError::InvalidTrajectory { message, .. } => StoreError::InvalidTrajectory {
                id: entry.id.clone(),
                message,
            },
            other => other,
        };
        let text = format_run_csv(trajectory).map_err(with_id)?;
        if let Some(t) = velocities
            .iter()
            .find(|t| trajectory.body(&t.role).is_none())
        {
            return Err(with_id(StoreError::InvalidTrajectory {
                id: String::new(),
                message: format!(
                    "velocities of body '{}', which the trajectory does not track",
                    t.role
                ),
            }));
        }
        let velocity_text = if velocities.is_empty() {
            None
        } else {
            Some(format_velocities_csv(&trajectory.time_s, velocities).map_err(with_id)?)
        };
        entry.file = format!("{RUNS_DIR}/{}.csv", entry.id);
        let runs = self.dir.join(RUNS_DIR);
        fs::create_dir_all(&runs).map_err(io_err("create", &runs))?;
        let commands_file = format!("{RUNS_DIR}/{}.commands.csv", entry.id);
        match &trajectory.commands {
            Some(c) => {
                write_atomic(
                    &self.dir.join(&commands_file),
                    format_commands_csv(c).as_bytes(),
                )?;
                entry.commands_file = Some(commands_file);
            }
            None => {
                remove_if_there(&self.dir.join(&commands_file))?;
                entry.commands_file = None;
            }
        }
        let velocities_file = format!("{RUNS_DIR}/{}.velocities.csv", entry.id);
        match velocity_text {
            Some(v) => {
                write_atomic(&self.dir.join(&velocities_file), v.as_bytes())?;
                entry.velocities_file = Some(velocities_file);
            }
            None => {
                remove_if_there(&self.dir.join(&velocities_file))?;
                entry.velocities_file = None;
            }
        }
        write_atomic(&self.dir.join(&entry.file), text.as_bytes())?;
        self.upsert(entry);
        self.save_manifest()
    }

    /// Records a run that produced no trajectory (status `failed`; its
    /// message should say why), removing any CSV an earlier attempt left.
    pub fn record_failed_run(&mut self, mut entry: RunEntry) -> Result<(), StoreError> {
        validate_run_id(&entry.id)?;
        entry.status = RunStatus::Failed;
        entry.file = String::new();
        entry.commands_file = None;
        entry.velocities_file = None;
        for suffix in ["csv", "commands.csv", "velocities.csv"] {
            remove_if_there(
                &self
                    .dir
                    .join(RUNS_DIR)
                    .join(format!("{}.{suffix}", entry.id)),
            )?;
        }
        self.upsert(entry);
        self.save_manifest()
    }

    /// The recorded velocities of run `id`'s bodies (empty when it has
    /// none), checked against its trajectory: the same sample times, and
    /// bodies it tracks.
    pub fn read_run_velocities(&self, id: &str) -> Result<Vec<VelocityTrack>, StoreError> {
        let entry = self.run(id).ok_or_else(|| StoreError::UnknownRun {
            dir: self.dir.clone(),
            id: id.to_string(),
        })?;
        let Some(file) = &entry.velocities_file else {
            return Ok(Vec::new());
        };
        let path = self.inside(id, file)?;
        let bytes = fs::read(&path).map_err(io_err("read", &path))?;
        let velocities = parse_velocities_csv(&bytes, &path)?;
        let trajectory = self.read_run(id)?;
        if velocities.time_s.len() != trajectory.len() {
            return Err(ImportError::new(
                &path,
                format!(
                    "{} samples, but the run's trajectory has {}",
                    velocities.time_s.len(),
                    trajectory.len()
                ),
            )
            .into());
        }
        if let Some(i) =
            (0..trajectory.len()).find(|&i| velocities.time_s[i] != trajectory.time_s[i])
        {
            // Line i + 2: after the header, 1-based.
            return Err(ImportError::at_line(
                &path,
                i + 2,
                format!(
                    "time {} s, but the run's sample {i} is at {} s",
                    velocities.time_s[i], trajectory.time_s[i]
                ),
            )
            .with_column(1)
            .with_field("t_s")
            .into());
        }
        if let Some(t) = velocities
            .bodies
            .iter()
            .find(|t| trajectory.body(&t.role).is_none())
        {
            return Err(ImportError::new(
                &path,
                format!("body '{}' is not one of the run's tracked bodies", t.role),
            )
            .into());
        }
        Ok(velocities.bodies)
    }

    /// The path of a file named in run `id`'s entry, which must be inside
    /// the directory.
    fn inside(&self, id: &str, file: &str) -> Result<PathBuf, StoreError> {
        let rel = Path::new(file);
        if rel.is_absolute()
            || rel
                .components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(StoreError::NoTrajectory {
                dir: self.dir.clone(),
                id: id.to_string(),
                message: format!("its file '{file}' is not a path inside the directory"),
            });
        }
        Ok(self.dir.join(rel))
    }

    /// Reads the trajectory of run `id`.
    pub fn read_run(&self, id: &str) -> Result<Trajectory, StoreError> {
        let entry = self.run(id).ok_or_else(|| StoreError::UnknownRun {
            dir: self.dir.clone(),
            id: id.to_string(),
        })?;
        let no = |message: String| StoreError::NoTrajectory {
            dir: self.dir.clone(),
            id: id.to_string(),
            message,
        };
        if entry.file.is_empty() {
            return Err(no(format!(
                "the run has no trajectory (status {})",
                entry.status
            )));
        }
        let inside = |file: &str| self.inside(id, file);
        let path = inside(&entry.file)?;
        let bytes = fs::read(&path).map_err(io_err("read", &path))?;
        let mut trajectory = parse_run_csv(&bytes, &path)?;
        if let Some(file) = &entry.commands_file {
            let path = inside(file)?;
            let bytes = fs::read(&path).map_err(io_err("read", &path))?;
            let commands = parse_commands_csv(&bytes, &path)?;
            commands
                .validate(trajectory.joint_count())
                .map_err(|e| ImportError::new(&path, e.to_string()))?;
            trajectory.commands = Some(commands);
        }
        Ok(trajectory)
    }

    fn upsert(&mut self, entry: RunEntry) {
        match self.manifest.runs.iter_mut().find(|r| r.id == entry.id) {
            Some(slot) => *slot = entry,
            None => self.manifest.runs.push(entry),
        }
    }

    fn save_manifest(&self) -> Result<(), StoreError> {
        let mut manifest = self.manifest.clone();
        manifest.tool_version = realitygap_core::TOOL_VERSION.to_string();
        let mut text =
            serde_json::to_string_pretty(&manifest).map_err(|e| StoreError::InvalidTrajectory {
                id: String::new(),
                message: format!("cannot serialise the manifest: {e}"),
            })?;
        text.push('\n');
        write_atomic(&self.dir.join(MANIFEST_FILE), text.as_bytes())
    }
}

/// Removes a file, if it is there.
fn remove_if_there(path: &Path) -> Result<(), StoreError> {
    match fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(StoreError::Io {
            action: "remove",
            path: path.to_path_buf(),
            reason: e,
        }),
    }
}

/// Checks that a run id can be a file stem on every platform: 1-200
/// characters from `A-Z a-z 0-9 . _ - + = @`, not starting with `.`.
pub fn validate_run_id(id: &str) -> Result<(), StoreError> {
    let bad = |reason: &str| {
        Err(StoreError::InvalidRunId {
            id: id.to_string(),
            reason: reason.to_string(),
        })
    };
    if id.is_empty() || id.len() > 200 {
        return bad("it must have 1 to 200 characters");
    }
    if id.starts_with('.') {
        return bad("it must not start with '.'");
    }
    if let Some(c) = id
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || "._-+=@".contains(*c)))
    {
        return bad(&format!(
            "'{c}' is not allowed (use letters, digits and . _ - + = @)"
        ));
    }
    Ok(())
}

/// Turns any text (e.g. a file stem) into a valid run id: disallowed
/// characters become `_`, a leading `.` is dropped, at most 200 bytes.
pub fn sanitize_run_id(text: &str) -> String {
    let mut id: String = text
        .trim_start_matches('.')
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-+=@".contains(c) {
                c
            } else {
                '_'
            }
        })
        .take(200)
        .collect();
    if id.is_empty() {
        id.push_str("run");
    }
    id
}

/// Writes a file atomically: a temporary file in the same directory
/// (removed again if anything fails), fsync, rename over the target, fsync
/// of the directory.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), StoreError> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::Builder::new()
        .prefix(".tmp-")
        .tempfile_in(dir)
        .map_err(io_err("create a temporary file in", dir))?;
    tmp.write_all(bytes).map_err(io_err("write", tmp.path()))?;
    tmp.as_file()
        .sync_all()
        .map_err(io_err("sync", tmp.path()))?;
    tmp.persist(path)
        .map_err(|e| io_err("replace", path)(e.error))?;
    // Make the rename itself durable (best effort: not every platform
    // can open a directory).
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Results directories under `root` (itself included): every directory
/// down to depth 3 that holds a `manifest.json`, sorted. Hidden directories
/// are skipped; unreadable ones are ignored.
pub fn discover(root: &Path) -> Vec<PathBuf> {
    fn visit(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) {
        if dir.join(MANIFEST_FILE).is_file() {
            out.push(dir.to_path_buf());
            return;
        }
        if depth == 3 {
            return;
        }
        let Ok(entries) = fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if !hidden && path.is_dir() {
                visit(&path, depth + 1, out);
            }
        }
    }
    let mut out = Vec::new();
    visit(root, 0, &mut out);
    out.sort();
    out
}

#[cfg(test)]
mod tests;
