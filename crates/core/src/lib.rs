//! Core types of realitygap, shared by every other crate.
//!
//! - [`pose`]: 3-vectors, unit quaternions and rigid poses, with the
//!   conversions the importers need (rotation matrix, Euler angles) and the
//!   measures the analysis needs (roll/pitch/yaw, geodesic angle).
//! - [`trajectory`]: [`Trajectory`], the one shape every source of motion
//!   (a simulated engine, a motion-capture recording, a recorded simulator
//!   file) is turned into before it is analysed.
//! - [`robot`]: [`RobotModel`], a robot's kinematic tree, inertias and
//!   geometry read from URDF, with forward kinematics.
//! - [`scene`]: [`Scene`], one scripted experiment read from TOML.
//! - [`engine`]: the [`Engine`] / [`Simulation`] interface every physics
//!   engine implements.
//! - [`params`]: [`PhysicalParams`], the typed physical parameters of a run
//!   (`--params FILE`), and which engine honours which.
//! - [`conformance`]: the checks every engine's tests run (state round
//!   trip, handover, parameter effects, gravity, divergence).
//! - [`controller`]: the controller loop shared by every engine
//!   ([`controller::run_scene`]) and the seeded per-run perturbations.
//! - [`fingerprint`]: a stable hash (FNV-1a) for names, keys and seeds.
//! - [`stitch`]: stitched runs, one engine per schedule phase, the state
//!   handed over at each phase boundary.
//!
//! Units everywhere: metres, radians, seconds, kilograms, unless a name says
//! otherwise (`_deg`, `_mm`).

#![forbid(unsafe_code)]

pub mod actuator;
pub mod conformance;
pub mod controller;
pub mod engine;
pub mod fingerprint;
pub mod instability;
pub mod params;
pub mod pose;
pub mod randomize;
pub mod replay;
pub mod robot;
pub mod scene;
pub mod stitch;
pub mod testing;
pub mod trajectory;

pub use engine::{Engine, EngineError, EngineSettings, ObjectState, SimState, Simulation};
pub use params::{ParamKey, ParamSupport, PhysicalParams};
pub use pose::{Pose, Quat, Vec3};
pub use robot::{RobotError, RobotModel};
pub use scene::{Scene, SceneError};
pub use trajectory::{BodyTrack, CommandKind, JointCommands, Trajectory, TrajectoryError};

/// The version of realitygap, as written into every manifest.
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");
