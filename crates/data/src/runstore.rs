//! The results directory: `manifest.json` plus one CSV per run.
//!
//! ```text
//! results/mujoco-scene1/
//!   manifest.json        tool version, source, kind, scene, engine, settings, one entry per run
//!   runs/<run id>.csv    the run's trajectory
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
//! `qd_cmd1_rad_s..qd_cmdN_rad_s` (commanded joint velocities). A gap (lost
//! pose) is seven empty cells. Numbers are printed with the shortest text
//! that reads back to the same `f64` (exponent form below 1e-5 and from
//! 1e16 on; `NaN`, `inf`, `-inf`), so a written run reads back exactly.
//! `pandas.read_csv` reads it as is.

use crate::error::{show_bytes, ImportError};
use crate::text::{parse_f64_str, Lines};
use realitygap_core::{Pose, Quat, Trajectory, TrajectoryError, Vec3};
use serde::{Deserialize, Serialize};
use std::fmt::{self, Write as _};
use std::fs;
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

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
}

impl fmt::Display for RunStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            RunStatus::Ok => "ok",
            RunStatus::Failed => "failed",
            RunStatus::Diverged => "diverged",
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
    #[error("cannot {action} {}: {source}", path.display())]
    Io {
        /// What was being done (`read`, `write`, `create`, ...).
        action: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: io::Error,
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
    move |source| StoreError::Io {
        action,
        path: path.to_path_buf(),
        source,
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
            matches!(r.status, RunStatus::Ok | RunStatus::Diverged)
                && !r.file.is_empty()
                && self.dir.join(&r.file).is_file()
        })
    }

    /// Stores a run: writes `runs/<id>.csv` atomically, then adds (or
    /// replaces) its manifest entry and rewrites the manifest atomically.
    /// `entry.file` is set by the store.
    pub fn write_run(
        &mut self,
        mut entry: RunEntry,
        trajectory: &Trajectory,
    ) -> Result<(), StoreError> {
        validate_run_id(&entry.id)?;
        let text = format_run_csv(trajectory).map_err(|e| match e {
            StoreError::InvalidTrajectory { message, .. } => StoreError::InvalidTrajectory {
                id: entry.id.clone(),
                message,
            },
            other => other,
        })?;
        entry.file = format!("{RUNS_DIR}/{}.csv", entry.id);
        let runs = self.dir.join(RUNS_DIR);
        fs::create_dir_all(&runs).map_err(io_err("create", &runs))?;
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
        let old = self.dir.join(RUNS_DIR).join(format!("{}.csv", entry.id));
        match fs::remove_file(&old) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(StoreError::Io {
                    action: "remove",
                    path: old,
                    source: e,
                })
            }
        }
        self.upsert(entry);
        self.save_manifest()
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
        let rel = Path::new(&entry.file);
        if rel.is_absolute()
            || rel
                .components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(no(format!(
                "its file '{}' is not a path inside the directory",
                entry.file
            )));
        }
        let path = self.dir.join(rel);
        let bytes = fs::read(&path).map_err(io_err("read", &path))?;
        Ok(parse_run_csv(&bytes, &path)?)
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

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes a file atomically: a temporary file in the same directory,
/// fsync, rename over the target, fsync of the directory.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), StoreError> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned());
    let tmp = dir.join(format!(
        ".{name}.tmp-{}-{}",
        std::process::id(),
        TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut f = fs::File::create(&tmp).map_err(io_err("create", &tmp))?;
        f.write_all(bytes).map_err(io_err("write", &tmp))?;
        f.sync_all().map_err(io_err("sync", &tmp))?;
        drop(f);
        fs::rename(&tmp, path).map_err(io_err("replace", path))
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result?;
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

// ---- Run CSV ---------------------------------------------------------------

/// Suffixes of a body's seven columns.
const BODY_SUFFIXES: [&str; 7] = ["_x_m", "_y_m", "_z_m", "_qw", "_qx", "_qy", "_qz"];

/// Appends a number in the shortest form that reads back to the same
/// `f64`; exponent form for magnitudes below 1e-5 or from 1e16 on.
fn push_f64(out: &mut String, x: f64) {
    let a = x.abs();
    let _ = if x.is_nan() {
        out.write_str("NaN")
    } else if a == 0.0 || a.is_infinite() || (1e-5..1e16).contains(&a) {
        write!(out, "{x}")
    } else {
        write!(out, "{x:e}")
    };
}

/// Formats a trajectory as run CSV text (see the module docs). Roles must
/// be non-empty and free of `,`, `"` and line breaks.
pub fn format_run_csv(trajectory: &Trajectory) -> Result<String, StoreError> {
    let invalid = |message: String| StoreError::InvalidTrajectory {
        id: String::new(),
        message,
    };
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
    let joints = trajectory
        .joint_angles_rad
        .as_ref()
        .and_then(|r| r.first())
        .map_or(0, Vec::len);
    let commands = trajectory
        .joint_velocity_commands_rad_s
        .as_ref()
        .and_then(|r| r.first())
        .map_or(0, Vec::len);

    let mut out =
        String::with_capacity(64 + trajectory.len() * (24 + 7 * 20 * trajectory.bodies.len()));
    out.push_str("t_s");
    for b in &trajectory.bodies {
        for s in BODY_SUFFIXES {
            let _ = write!(out, ",{}{s}", b.role);
        }
    }
    for j in 1..=joints {
        let _ = write!(out, ",q{j}_rad");
    }
    for j in 1..=commands {
        let _ = write!(out, ",qd_cmd{j}_rad_s");
    }
    out.push('\n');
    for (i, &t) in trajectory.time_s.iter().enumerate() {
        push_f64(&mut out, t);
        for b in &trajectory.bodies {
            match &b.poses[i] {
                Some(p) => {
                    let o = p.orientation;
                    for v in [
                        p.position_m.x,
                        p.position_m.y,
                        p.position_m.z,
                        o.w,
                        o.x,
                        o.y,
                        o.z,
                    ] {
                        out.push(',');
                        push_f64(&mut out, v);
                    }
                }
                None => out.push_str(",,,,,,,"),
            }
        }
        for rows in [
            &trajectory.joint_angles_rad,
            &trajectory.joint_velocity_commands_rad_s,
        ]
        .into_iter()
        .flatten()
        {
            for &v in &rows[i] {
                out.push(',');
                push_f64(&mut out, v);
            }
        }
        out.push('\n');
    }
    Ok(out)
}

/// What a run-CSV column holds.
#[derive(Debug, Clone, Copy)]
enum Column {
    Body(usize, usize),
    Joint,
    Command,
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
    let header = lines
        .next()
        .ok_or_else(|| ImportError::new(file, "the file is empty"))?;
    let names: Vec<&[u8]> = header.bytes.split(|&b| b == b',').map(unquote).collect();
    let at = |col: usize, message: String| {
        ImportError::at_line(file, header.number, message).with_column(col + 1)
    };
    if names[0] != b"t_s" {
        return Err(at(
            0,
            format!(
                "expected the column name \"t_s\", found {}",
                show_bytes(names[0], 40)
            ),
        ));
    }
    let mut columns: Vec<Column> = Vec::with_capacity(names.len());
    let mut roles: Vec<String> = Vec::new();
    let (mut joints, mut commands) = (0usize, 0usize);
    let mut i = 1;
    while i < names.len() {
        let name = names[i];
        if let Some(role) = name.strip_suffix(b"_x_m") {
            let role_text = String::from_utf8_lossy(role).into_owned();
            if role.is_empty() {
                return Err(at(i, "a body column needs a role before \"_x_m\"".into()));
            }
            if roles.contains(&role_text) {
                return Err(at(i, format!("body role '{role_text}' appears twice")));
            }
            for (k, suffix) in BODY_SUFFIXES.iter().enumerate() {
                let want = format!("{role_text}{suffix}");
                match names.get(i + k) {
                    Some(n) if *n == want.as_bytes() => columns.push(Column::Body(roles.len(), k)),
                    Some(n) => {
                        return Err(at(
                            i + k,
                            format!(
                                "expected the column name {want:?}, found {}",
                                show_bytes(n, 40)
                            ),
                        ))
                    }
                    None => {
                        return Err(at(
                            i + k,
                            format!("the header ends before the column {want:?}"),
                        ))
                    }
                }
            }
            roles.push(role_text);
            i += 7;
        } else if name == format!("q{}_rad", joints + 1).as_bytes() {
            columns.push(Column::Joint);
            joints += 1;
            i += 1;
        } else if name == format!("qd_cmd{}_rad_s", commands + 1).as_bytes() {
            columns.push(Column::Command);
            commands += 1;
            i += 1;
        } else {
            return Err(at(
                i,
                format!(
                    "unexpected column name {}: expected <role>_x_m, q{}_rad or qd_cmd{}_rad_s",
                    show_bytes(name, 40),
                    joints + 1,
                    commands + 1
                ),
            ));
        }
    }

    let mut trajectory = Trajectory::with_bodies(&roles);
    let mut angles: Vec<Vec<f64>> = Vec::new();
    let mut velocity_commands: Vec<Vec<f64>> = Vec::new();
    let mut ranges: Vec<(usize, usize)> = Vec::with_capacity(names.len());
    let mut body_cells: Vec<[Option<f64>; 7]> = vec![[None; 7]; roles.len()];
    for line in lines {
        // Validate the line's UTF-8 once; a damaged line is read lossily so
        // the bad cell shows up as a non-number at its own column.
        let lossy;
        let text: &str = match std::str::from_utf8(line.bytes) {
            Ok(s) => s,
            Err(_) => {
                lossy = String::from_utf8_lossy(line.bytes);
                &lossy
            }
        };
        ranges.clear();
        let mut from = 0;
        for (i, b) in text.bytes().enumerate() {
            if b == b',' {
                ranges.push((from, i));
                from = i + 1;
            }
        }
        ranges.push((from, text.len()));
        let cell = |col: usize| text.get(ranges[col].0..ranges[col].1).unwrap_or("");
        let fields = &ranges;
        let err = |col: usize, message: String| {
            let e = ImportError::at_line(file, line.number, message).with_column(col + 1);
            match names.get(col) {
                Some(n) => e.with_field(String::from_utf8_lossy(n).into_owned()),
                None => e,
            }
        };
        if fields.len() != names.len() {
            return Err(ImportError::at_line(
                file,
                line.number,
                format!(
                    "expected {} columns as in the header, found {}",
                    names.len(),
                    fields.len()
                ),
            ));
        }
        let number = |col: usize| {
            parse_f64_str(cell(col)).ok_or_else(|| {
                err(
                    col,
                    format!(
                        "expected a number, found {}",
                        show_bytes(cell(col).as_bytes(), 40)
                    ),
                )
            })
        };
        let t = number(0)?;
        if !t.is_finite() || trajectory.time_s.last().is_some_and(|&p| t < p) {
            return Err(err(
                0,
                format!("time {t} s is not finite or goes backwards"),
            ));
        }
        trajectory.time_s.push(t);
        let mut angle_row = Vec::with_capacity(joints);
        let mut command_row = Vec::with_capacity(commands);
        for (col, column) in columns.iter().enumerate() {
            let col = col + 1;
            match *column {
                Column::Body(b, k) => {
                    body_cells[b][k] = if cell(col).is_empty() {
                        None
                    } else {
                        Some(number(col)?)
                    };
                }
                Column::Joint => angle_row.push(number(col)?),
                Column::Command => command_row.push(number(col)?),
            }
        }
        for (b, cells) in body_cells.iter().enumerate() {
            let pose = if cells.iter().all(Option::is_none) {
                None
            } else if let Some(k) = cells.iter().position(Option::is_none) {
                let col = 1 + columns
                    .iter()
                    .position(|c| matches!(c, Column::Body(bb, kk) if *bb == b && *kk == k))
                    .unwrap_or(0);
                return Err(err(
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
            trajectory.bodies[b].poses.push(pose);
        }
        if joints > 0 {
            angles.push(angle_row);
        }
        if commands > 0 {
            velocity_commands.push(command_row);
        }
    }
    if joints > 0 {
        trajectory.joint_angles_rad = Some(angles);
    }
    if commands > 0 {
        trajectory.joint_velocity_commands_rad_s = Some(velocity_commands);
    }
    debug_assert!(trajectory.validate().is_ok());
    Ok(trajectory)
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

#[cfg(test)]
mod tests;
