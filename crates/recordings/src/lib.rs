//! A robot's own joint recordings, brought into realitygap: ROS 2 bags
//! ([`rosbag`], MCAP or sqlite3 storage, CDR messages), CSV files
//! ([`csvfile`]) and LeRobot datasets ([`lerobot`], behind the default
//! `lerobot` feature), each read into [`Recording`]s (joint names as
//! recorded, absolute times, measured positions, velocities and efforts,
//! and the commands that drove the robot at their own timestamps).
//!
//! The pipeline, stage by stage:
//!
//! ```text
//! bag / CSV / dataset ──> importer ──> Recording (one per episode)
//!   ──> Recording::to_trajectory (joints matched to the URDF, FK poses)
//!   ──> store (one run per episode in a results directory)
//! ```
//!
//! Every error names the file and the place in it (topic and message index,
//! line and column, row and column), and nothing is written until every
//! episode has been read: a bad input leaves no partial results directory.

pub mod csvfile;
#[cfg(feature = "lerobot")]
pub mod lerobot;
pub mod recording;
pub mod rosbag;

pub use recording::{
    end_effector, end_effector_of, Commands, JointMatch, JointPlan, JointStates, Recording,
};

use realitygap_core::robot::RobotModel;
use realitygap_core::Trajectory;
use realitygap_data::{ImportError, RunEntry, RunStore, SourceKind, StoreError};
use serde_json::{json, Value};
use std::path::Path;

/// What went wrong storing recordings.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// An input could not be read or does not fit the robot.
    #[error(transparent)]
    Import(#[from] ImportError),
    /// The results directory could not be written.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Two episodes would be one run.
    #[error(
        "{first} and {second} would both be run '{id}': import them into different directories"
    )]
    DuplicateRun {
        /// The run id.
        id: String,
        /// One episode's file.
        first: String,
        /// The other's.
        second: String,
    },
}

/// One episode as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredRun {
    /// The run id.
    pub id: String,
    /// Its trajectory.
    pub trajectory: Trajectory,
    /// What the importer noticed.
    pub warnings: Vec<String>,
    /// Whether it replaced a run of the same id.
    pub replaced: bool,
}

/// Where and as what the recordings are stored.
pub struct StoreTarget<'a> {
    /// The results directory (created if needed).
    pub out: &'a Path,
    /// The source name in the manifest (`real` by default).
    pub source: &'a str,
    /// The robot's URDF, for the manifest.
    pub urdf: &'a Path,
    /// The robot.
    pub robot: &'a RobotModel,
    /// The end-effector link whose pose is stored as the `wrist` body.
    pub link: usize,
    /// Joint renames and held positions (`--rename`, `--hold`).
    pub joints: &'a JointMatch,
}

/// What [`store`] stored.
#[derive(Debug, Clone, PartialEq)]
pub struct Stored {
    /// One run per episode.
    pub runs: Vec<StoredRun>,
    /// The joints driven and held.
    pub plan: JointPlan,
}

/// The recordings with their joints renamed (`joints.rename`), and how
/// they meet `robot` ([`JointPlan`], from the first episode's joints; the
/// others must name the same).
pub fn plan_joints(
    recordings: &[Recording],
    robot: &RobotModel,
    urdf: &Path,
    joints: &JointMatch,
) -> Result<(Vec<Recording>, JointPlan), ImportError> {
    let mut renamed = recordings.to_vec();
    for r in &mut renamed {
        r.rename_joints(&joints.rename)?;
    }
    let first = renamed
        .first()
        .map(|r| r.states.names.clone())
        .unwrap_or_default();
    let plan = JointPlan::new(robot, &first, &joints.hold)
        .map_err(|e| ImportError::new(renamed.first().map_or(urdf, |r| r.file.as_path()), e))?;
    Ok((renamed, plan))
}

/// Turns every recording into a run of the robot, then stores them all:
/// one run per episode, source kind `real`, the joint names, held joints,
/// end-effector link and URDF in the manifest's settings. The recordings'
/// joints are renamed first (`target.joints.rename`); the robot's moving
/// joints they do not name are held ([`JointPlan`]). Nothing is written
/// when any recording fails.
pub fn store(recordings: &[Recording], target: &StoreTarget) -> Result<Stored, RecordingError> {
    let (renamed, plan) = plan_joints(recordings, target.robot, target.urdf, target.joints)?;
    let recordings = &renamed[..];
    let robot = target.robot;
    let mut runs = Vec::with_capacity(recordings.len());
    for (i, r) in recordings.iter().enumerate() {
        if let Some(other) = recordings[..i].iter().find(|o| o.id == r.id) {
            return Err(RecordingError::DuplicateRun {
                id: r.id.clone(),
                first: other.file.display().to_string(),
                second: r.file.display().to_string(),
            });
        }
        realitygap_data::validate_run_id(&r.id)?;
        runs.push(r.to_trajectory_planned(robot, target.link, &plan)?);
    }
    let joints: Vec<&str> = plan
        .driven
        .iter()
        .map(|&j| robot.joints[j].name.as_str())
        .collect();
    let mut store = RunStore::create_or_open(target.out, target.source, SourceKind::Real, None)?;
    store.set_settings(json!({
        "robot": robot.name,
        "urdf": std::fs::canonicalize(target.urdf).unwrap_or_else(|_| target.urdf.to_path_buf()).display().to_string(),
        "joints": joints,
        "held_joints": plan.held,
        "end_effector_link": robot.links[target.link].name,
    }))?;
    let mut stored = Vec::with_capacity(runs.len());
    for (r, trajectory) in recordings.iter().zip(runs) {
        let mut entry = RunEntry::new(&r.id);
        let origin = std::fs::canonicalize(&r.file).unwrap_or_else(|_| r.file.clone());
        entry.origin = vec![origin.display().to_string()];
        if !r.warnings.is_empty() {
            entry.message = Some(r.warnings.join("; "));
        }
        entry.extra = r.info.clone();
        entry
            .extra
            .insert("samples".into(), Value::from(trajectory.len()));
        if let Some(c) = &trajectory.commands {
            entry.extra.insert("commands".into(), Value::from(c.len()));
            entry
                .extra
                .insert("command_kind".into(), Value::from(c.kind.name()));
        }
        let replaced = store.run(&r.id).is_some();
        store.write_run(entry, &trajectory)?;
        stored.push(StoredRun {
            id: r.id.clone(),
            trajectory,
            warnings: r.warnings.clone(),
            replaced,
        });
    }
    Ok(Stored { runs: stored, plan })
}
