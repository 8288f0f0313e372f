//! Getting trajectories in and out of realitygap's files.
//!
//! - [`qualisys`]: the real arm's motion capture, Qualisys Track Manager
//!   6DOF TSV exports (with or without their header block).
//! - [`recorded`]: simulator output recorded elsewhere (the study's MuJoCo,
//!   PyBullet and V-Rep CSV files: 14 numbers per control step).
//! - [`runstore`]: the results directory, `manifest.json` plus one CSV per
//!   run, written atomically so an interrupted batch loses no finished run.
//! - [`builtin`]: the study's recordings shipped as one checksummed archive,
//!   unpacked once into a verified cache folder.
//!
//! Every importer returns an [`ImportedRun`]: a
//! [`Trajectory`] in metres, radians and
//! seconds, plus what the reader noticed on the way (warnings, lost-marker
//! gaps, all-zero rows, quaternions off unit norm). Input that cannot be
//! read gives an [`ImportError`] naming the file, line, column and field;
//! no input makes a reader panic.

#![forbid(unsafe_code)]

pub mod builtin;
pub mod error;
pub mod qualisys;
pub mod recorded;
pub mod runstore;
mod text;

pub use error::ImportError;
pub use qualisys::QualisysOptions;
pub use recorded::{QuatOrder, RecordedOptions};
pub use runstore::{
    discover, format_commands_csv, format_run_csv, format_velocities_csv, parse_commands_csv,
    parse_run_csv, parse_velocities_csv, read_run_csv, sanitize_run_id, validate_run_id, BodyTwist,
    EngineInfo, Manifest, RunEntry, RunStatus, RunStore, RunVelocities, SourceKind, StoreError,
    VelocityTrack,
};

use realitygap_core::Trajectory;
use std::path::PathBuf;

/// One imported file: its trajectory and what the importer noticed.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedRun {
    /// The motion: time from the first sample (s), poses in metres and unit
    /// quaternions in the source's own world frame, gaps as `None`.
    pub trajectory: Trajectory,
    /// Sampling frequency in Hz (the capture rate, or 1 / control period).
    pub frequency_hz: f64,
    /// The file read.
    pub source_file: PathBuf,
    /// Names of the bodies as the file calls them, in the order of
    /// `trajectory.bodies` (for recorded files: the roles themselves).
    pub body_names: Vec<String>,
    /// Things a person should know that did not stop the import (gaps,
    /// header disagreements, a dropped truncated last line, ...).
    pub warnings: Vec<String>,
    /// Sample indices (0-based) whose numbers were all exactly zero (a
    /// simulator that wrote nothing for that step). Their poses are kept as
    /// read: position at the origin, identity orientation.
    pub zero_rows: Vec<usize>,
    /// Sample indices (0-based, not in `zero_rows`) where a quaternion's
    /// norm differed from 1 by more than the tolerance, or was not finite.
    /// Finite non-zero quaternions are normalised; others are kept as read.
    pub bad_norm_rows: Vec<usize>,
}

impl ImportedRun {
    /// Number of gaps (samples without a pose) summed over all bodies.
    pub fn gap_count(&self) -> usize {
        self.trajectory
            .bodies
            .iter()
            .map(|b| b.poses.iter().filter(|p| p.is_none()).count())
            .sum()
    }
}

/// The study's recordings for tests: the built-in archive
/// (`assets/study-data/`), unpacked once per process into the cache
/// ([`builtin::default_cache_root`], else a folder in the system's temporary
/// folder) and reused. Always there: the tests that need the recordings
/// never skip. Panics if the archive cannot be unpacked.
#[cfg(test)]
pub(crate) fn paper_data() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets");
        let archive = builtin::StudyArchive::in_assets(&assets).unwrap_or_else(|e| panic!("{e}"));
        let cache = builtin::default_cache_root()
            .unwrap_or_else(|_| std::env::temp_dir().join("realitygap-test-cache"));
        builtin::open_or_unpack(&archive, &cache)
            .unwrap_or_else(|e| panic!("{e}"))
            .dir
    })
    .clone()
}

/// The study's recordings as published, beside the project
/// (`../shared/paper-data`), when that folder is there: the one test that
/// compares the built-in archive with them does the full comparison then,
/// and checks the archive against its committed file list otherwise. A
/// clone without `../shared` (how anyone who clones the project gets it)
/// passes every test.
#[cfg(test)]
pub(crate) fn published_paper_data() -> Option<PathBuf> {
    // The crate's folder at run time (cargo sets it; so does
    // scripts/test-without-shared for a copy of the project), else at build
    // time: the copy's ../shared is what counts, not the build's.
    let crate_dir = std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .filter(|d| d.join("../../Cargo.toml").is_file())
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    let dir = crate_dir.join("../../../shared/paper-data");
    (dir.join("MotionCapture").is_dir() && dir.join("Simulation").is_dir()).then_some(dir)
}
