//! [`Scene`]: one scripted experiment, read from a TOML file.
//!
//! A scene says everything an engine needs to reproduce a run and nothing
//! about any particular engine, except in its per-engine settings tables:
//!
//! - the robot (a URDF file, its base pose, the positions its non-actuated
//!   joints are held at, optionally an MJCF file that a MuJoCo engine loads
//!   as it is instead of building a model from the URDF);
//! - the ground and the free objects (boxes with size, mass, pose and
//!   optional friction);
//! - the controller (proportional on joint velocity: gain, speed clamp,
//!   control period) and the actuator of each controlled joint (a velocity
//!   servo: gain `kv`, force limit);
//! - the schedule (times at which the joint targets change), the duration;
//! - the tracked bodies (a robot link's frame, or an object) recorded into
//!   the [`Trajectory`](crate::Trajectory);
//! - per-engine settings (`[engine.mujoco] timestep_s = 1e-4`), checked by
//!   the engine that uses them.
//!
//! # File format
//!
//! ```toml
//! name = "scene1_single_joint"
//! description = "Joint 2 to -100 degrees"
//! duration_s = 6.0
//! gravity_m_s2 = [0.0, 0.0, -9.81]          # optional, world frame (the default)
//!
//! [robot]
//! urdf = "../robots/mico2/mico2.urdf"     # relative to this file, or absolute
//! base_position_m = [0.0, 0.0, 0.055]
//! base_rpy_deg = [0.0, 0.0, 0.0]           # optional
//! # mjcf = "model.xml"                     # optional, MuJoCo loads it as is
//! [robot.held_joints_deg]                  # optional; other idle joints are held at 0
//! m1n6s300_joint_finger_1 = 0.0
//!
//! [ground]                                 # optional; a plane z = height_m
//! height_m = 0.0
//!
//! [[object]]
//! name = "cube"
//! shape = "box"
//! size_m = [0.075, 0.075, 0.075]
//! mass_kg = 0.0884
//! position_m = [0.5, 0.0, 0.0375]
//! # rpy_deg = [0, 0, 0]   friction = 0.8   (optional)
//! # linear_velocity_m_s = [0, 0, 0]        (optional: initial velocity, world frame)
//! # angular_velocity_rad_s = [0, 0, 0]     (optional: initial angular velocity, world frame)
//!
//! [controller]
//! gain_per_s = 10.0        # v_deg_s = gain * error_deg
//! max_speed_deg_s = 30.0   # clamp
//! period_s = 0.05
//!
//! [[actuator]]             # one per controlled joint, in command order
//! joint = "m1n6s300_joint_1"
//! kv = 10.0                # N m s/rad
//! force_limit = 2000.0     # N m
//! # kp = 700.0             # optional: N m/rad, the PD servo of position commands
//!
//! [[schedule]]             # joints not named target 0
//! t_s = 0.0
//! targets_deg = { m1n6s300_joint_2 = -100.0 }
//!
//! [[track]]
//! role = "wrist"
//! link = "m1n6s300_link_6"
//! [[track]]
//! role = "cube"
//! object = "cube"
//!
//! [engine.mujoco]
//! timestep_s = 1e-4
//! ```
//!
//! # Free objects alone
//!
//! A scene may leave out `[robot]`: free objects over a ground (a tossed
//! cube). It then has no `[[actuator]]` or `[[schedule]]`; its
//! `[controller]` is optional and only sets `period_s`, the sample period
//! (default [`FREE_SAMPLE_PERIOD_S`]). Its robot is
//! [`RobotModel::world`](crate::robot::RobotModel::world), which every engine
//! builds as nothing. Objects start with their initial velocities
//! ([`crate::controller::ControllerLoop::start`]).
//!
//! Reading a file ([`Scene::from_file`]) checks what the file alone can
//! show; [`Scene::validate`] checks it against the loaded robot (joint and
//! link names, joint limits), and [`Scene::steps_per_period`] against an
//! engine's timestep. Every error names the file and, where it can, the
//! line and column and the field.

use crate::engine::{EngineSettings, SettingValue};
use crate::pose::{Pose, Quat, Vec3};
use crate::robot::{JointKind, RobotModel};
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Standard gravity, m/s^2: a scene's default is `(0, 0, -9.81)`.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.81;

/// A scripted experiment: robot, objects, controller, schedule, tracked
/// bodies and per-engine settings. See the [module documentation](self) for
/// the file format.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Short name, used for result directories (letters, digits, `_`, `-`, `.`).
    pub name: String,
    /// Free text for people.
    pub description: String,
    /// The scene file (absolute when read with [`Scene::from_file`]).
    pub source: PathBuf,
    /// Length of a run, s; the run records `duration_s / period_s` samples.
    pub duration_s: f64,
    /// Gravity in the world frame, m/s^2 (`gravity_m_s2`, default
    /// `[0, 0, -9.81]`). Every engine uses it.
    pub gravity_m_s2: Vec3,
    /// The robot and where it stands.
    pub robot: RobotSpec,
    /// The ground plane, when there is one.
    pub ground: Option<Ground>,
    /// Free objects, in file order.
    pub objects: Vec<SceneObject>,
    /// The joint-velocity controller.
    pub controller: ControllerSpec,
    /// One velocity servo per controlled joint; their order is the order of
    /// every per-joint vector (commands, joint angles in the trajectory).
    pub actuators: Vec<ActuatorSpec>,
    /// When the targets change, sorted by time.
    pub schedule: Vec<ScheduleEntry>,
    /// The bodies recorded at every control step, in trajectory order.
    pub tracked: Vec<TrackedBody>,
    /// Settings per engine name (`[engine.NAME]` tables), as written.
    pub engine_settings: BTreeMap<String, EngineSettings>,
    /// Line/column of fields, for errors found after parsing.
    locations: HashMap<String, (usize, usize)>,
}

/// The sample period of a scene of free objects alone that gives no
/// `[controller]` table, s.
pub const FREE_SAMPLE_PERIOD_S: f64 = 0.01;

/// The robot of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSpec {
    /// The URDF file (absolute, resolved against the scene file's
    /// directory); `None` for a scene of free objects alone (no `[robot]`
    /// table), whose robot is [`RobotModel::world`]: one fixed link with no
    /// mass, shape or joint, which every engine builds as nothing.
    pub urdf: Option<PathBuf>,
    /// Pose of the robot's root link frame in the world (m, unit quaternion).
    pub base: Pose,
    /// An MJCF file that a MuJoCo engine loads as it is instead of building a
    /// model from the URDF (absolute path). Its joints, bodies and actuators
    /// are found by the scene's names; its own objects, ground and actuator
    /// gains are used.
    pub mjcf: Option<PathBuf>,
    /// Positions (rad) at which non-actuated movable joints are held; joints
    /// not listed are held at 0.
    pub held_joints_rad: BTreeMap<String, f64>,
}

impl RobotSpec {
    /// No robot: a scene of free objects alone.
    pub fn none() -> RobotSpec {
        RobotSpec {
            urdf: None,
            base: Pose::IDENTITY,
            mjcf: None,
            held_joints_rad: BTreeMap::new(),
        }
    }

    /// Whether the scene has a robot.
    pub fn is_some(&self) -> bool {
        self.urdf.is_some()
    }

    /// The robot model: the URDF read with `resolver`, or
    /// [`RobotModel::world`] for a scene without a robot.
    pub fn model(
        &self,
        resolver: &crate::robot::PackageResolver,
    ) -> Result<RobotModel, crate::robot::RobotError> {
        match &self.urdf {
            Some(path) => RobotModel::from_urdf_file(path, resolver),
            None => Ok(RobotModel::world()),
        }
    }

    /// The URDF's path for people: `(none: free objects alone)` without a
    /// robot.
    pub fn urdf_label(&self) -> String {
        match &self.urdf {
            Some(p) => p.display().to_string(),
            None => "(none: free objects alone)".to_string(),
        }
    }
}

/// A ground plane `z = height_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ground {
    /// Height of the plane, m.
    pub height_m: f64,
    /// Sliding friction coefficient; `None` = the engine's default.
    pub friction: Option<f64>,
}

/// A free rigid object.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// Unique name, used by `[[track]] object = ...`.
    pub name: String,
    /// Its shape.
    pub shape: ObjectShape,
    /// Mass, kg (uniform density).
    pub mass_kg: f64,
    /// Initial pose of the shape's centre in the world.
    pub pose: Pose,
    /// Initial velocity of its centre, world frame, m/s (default 0).
    pub linear_velocity_m_s: Vec3,
    /// Initial angular velocity, world frame, rad/s (default 0).
    pub angular_velocity_rad_s: Vec3,
    /// Sliding friction coefficient; `None` = the engine's default.
    pub friction: Option<f64>,
}

/// The shape of a [`SceneObject`], centred on its frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ObjectShape {
    /// A box with full edge lengths along x, y, z, m.
    Box {
        /// Full edge lengths, m.
        size_m: Vec3,
    },
}

impl SceneObject {
    /// Checks the shape: every edge of a box positive and finite; the
    /// message names the object.
    pub fn check_shape(&self) -> Result<(), String> {
        match self.shape {
            ObjectShape::Box { size_m: s } => {
                if [s.x, s.y, s.z].iter().all(|v| v.is_finite() && *v > 0.0) {
                    Ok(())
                } else {
                    Err(format!(
                        "object \"{}\": box size [{}, {}, {}] m must be positive and finite",
                        self.name, s.x, s.y, s.z
                    ))
                }
            }
        }
    }

    /// Half of each edge, m: the reach of the shape from its centre along
    /// its own axes.
    pub fn half_extents_m(&self) -> Vec3 {
        match self.shape {
            ObjectShape::Box { size_m: s } => Vec3::new(0.5 * s.x, 0.5 * s.y, 0.5 * s.z),
        }
    }

    /// Principal moments of inertia about the centre, kg m^2 (uniform density).
    pub fn principal_inertia(&self) -> Vec3 {
        match self.shape {
            ObjectShape::Box { size_m: s } => {
                let k = self.mass_kg / 12.0;
                Vec3::new(
                    k * (s.y * s.y + s.z * s.z),
                    k * (s.x * s.x + s.z * s.z),
                    k * (s.x * s.x + s.y * s.y),
                )
            }
        }
    }
}

/// The proportional joint-velocity controller of METHOD.md, per joint:
/// `v_deg_s = clamp(gain_per_s * (target_deg - angle_deg), -max, +max)`,
/// sent in rad/s, every `period_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerSpec {
    /// Proportional gain, 1/s (velocity per unit of angle error).
    pub gain_per_s: f64,
    /// Largest commanded speed, deg/s (the clamp).
    pub max_speed_deg_s: f64,
    /// Control period, s.
    pub period_s: f64,
}

/// A velocity servo on one joint: torque `kv * (v_target - v)`, limited to
/// `+-force_limit`.
#[derive(Debug, Clone, PartialEq)]
pub struct ActuatorSpec {
    /// The joint's name in the URDF.
    pub joint: String,
    /// Velocity gain, N m s/rad (the PD servo's `kd` for position
    /// commands).
    pub kv: f64,
    /// Position gain of the servo's PD law for position commands
    /// (`tau = kp (q_target - q) - kv qd`), N m/rad; `None`: the joint
    /// takes no position commands.
    pub kp: Option<f64>,
    /// Largest torque, N m (infinite = unlimited).
    pub force_limit: f64,
}

/// From `t_s` on, the controlled joints target these angles; joints not
/// named target 0.
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduleEntry {
    /// Time the targets take effect, s.
    pub t_s: f64,
    /// Target angles by joint name, degrees.
    pub targets_deg: BTreeMap<String, f64>,
}

/// A body whose pose is recorded at every control step.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackedBody {
    /// Role name in the trajectory (`wrist`, `cube`, ...).
    pub role: String,
    /// What is tracked.
    pub target: TrackTarget,
}

/// What a [`TrackedBody`] follows.
#[derive(Debug, Clone, PartialEq)]
pub enum TrackTarget {
    /// The frame of a robot link, by name.
    Link(String),
    /// A scene object (its centre and orientation), by name.
    Object(String),
}

/// A scene file that cannot be read or used.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {}: {reason}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The TOML is malformed, or a field is missing, unknown or of the
    /// wrong type.
    #[error("{}{}: {message}", path.display(), Loc(*line, *column))]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line, when known.
        line: Option<usize>,
        /// 1-based column, when known.
        column: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A value is well-formed but not usable (unknown joint, target out of
    /// limits, non-positive duration, ...).
    #[error("{}{}: {field}: {message}", path.display(), Loc(*line, *column))]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the field, when known.
        line: Option<usize>,
        /// 1-based column of the field, when known.
        column: Option<usize>,
        /// The field, e.g. `schedule[0].targets_deg.m1n6s300_joint_9`.
        field: String,
        /// What is wrong and what was expected.
        message: String,
    },
}

struct Loc(Option<usize>, Option<usize>);

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.0, self.1) {
            (Some(l), Some(c)) => write!(f, ":{l}:{c}"),
            (Some(l), None) => write!(f, ":{l}"),
            _ => Ok(()),
        }
    }
}

// ---------------------------------------------------------------------------
// The file's shape.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileScene {
    name: Spanned<String>,
    #[serde(default)]
    description: String,
    duration_s: Spanned<f64>,
    gravity_m_s2: Option<Spanned<[f64; 3]>>,
    robot: Option<FileRobot>,
    ground: Option<FileGround>,
    #[serde(default, rename = "object")]
    objects: Vec<FileObject>,
    controller: Option<FileController>,
    #[serde(default, rename = "actuator")]
    actuators: Vec<FileActuator>,
    #[serde(default)]
    schedule: Vec<FileScheduleEntry>,
    #[serde(default, rename = "track")]
    tracks: Vec<FileTrack>,
    #[serde(default)]
    engine: BTreeMap<String, BTreeMap<Spanned<String>, Spanned<toml::Value>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileRobot {
    urdf: Spanned<String>,
    base_position_m: Spanned<[f64; 3]>,
    base_rpy_deg: Option<Spanned<[f64; 3]>>,
    mjcf: Option<Spanned<String>>,
    #[serde(default)]
    held_joints_deg: BTreeMap<Spanned<String>, Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileGround {
    #[serde(default)]
    height_m: f64,
    friction: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileObject {
    name: Spanned<String>,
    shape: Spanned<String>,
    size_m: Spanned<[f64; 3]>,
    mass_kg: Spanned<f64>,
    position_m: Spanned<[f64; 3]>,
    rpy_deg: Option<Spanned<[f64; 3]>>,
    linear_velocity_m_s: Option<Spanned<[f64; 3]>>,
    angular_velocity_rad_s: Option<Spanned<[f64; 3]>>,
    friction: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileController {
    gain_per_s: Option<Spanned<f64>>,
    max_speed_deg_s: Option<Spanned<f64>>,
    period_s: Spanned<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileActuator {
    joint: Spanned<String>,
    kv: Spanned<f64>,
    kp: Option<Spanned<f64>>,
    force_limit: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileScheduleEntry {
    t_s: Spanned<f64>,
    #[serde(default)]
    targets_deg: BTreeMap<Spanned<String>, Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileTrack {
    role: Spanned<String>,
    link: Option<Spanned<String>>,
    object: Option<Spanned<String>>,
}

/// Byte offset -> 1-based (line, column), column in characters.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[line_start..].chars().count() + 1;
    (line, column)
}

struct Builder<'a> {
    path: &'a Path,
    text: &'a str,
    locations: HashMap<String, (usize, usize)>,
}

impl Builder<'_> {
    fn at<T>(&mut self, field: &str, s: &Spanned<T>) {
        let lc = line_col(self.text, s.span().start);
        self.locations.insert(field.to_string(), lc);
    }

    fn invalid<T>(
        &self,
        field: &str,
        s: Option<&Spanned<T>>,
        message: impl Into<String>,
    ) -> SceneError {
        let (line, column) = match s {
            Some(s) => {
                let (l, c) = line_col(self.text, s.span().start);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        SceneError::Invalid {
            path: self.path.to_path_buf(),
            line,
            column,
            field: field.to_string(),
            message: message.into(),
        }
    }

    fn finite(&self, field: &str, s: &Spanned<f64>) -> Result<f64, SceneError> {
        let v = *s.get_ref();
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.invalid(
                field,
                Some(s),
                format!("must be a finite number, found {v}"),
            ))
        }
    }

    fn positive(&self, field: &str, s: &Spanned<f64>) -> Result<f64, SceneError> {
        let v = self.finite(field, s)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, Some(s), format!("must be greater than 0, found {v}")))
        }
    }

    fn non_negative(&self, field: &str, s: &Spanned<f64>) -> Result<f64, SceneError> {
        let v = self.finite(field, s)?;
        if v >= 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(field, Some(s), format!("must not be negative, found {v}")))
        }
    }

    fn vec3(&self, field: &str, s: &Spanned<[f64; 3]>) -> Result<Vec3, SceneError> {
        let a = *s.get_ref();
        if a.iter().all(|v| v.is_finite()) {
            Ok(Vec3::from_array(a))
        } else {
            Err(self.invalid(field, Some(s), "every component must be a finite number"))
        }
    }

    fn rpy(&self, field: &str, s: Option<&Spanned<[f64; 3]>>) -> Result<Quat, SceneError> {
        match s {
            None => Ok(Quat::IDENTITY),
            Some(s) => {
                let v = self.vec3(field, s)?;
                Ok(Quat::from_euler_rpy(
                    v.x.to_radians(),
                    v.y.to_radians(),
                    v.z.to_radians(),
                ))
            }
        }
    }

    /// `rel` against the scene file's directory, with `.` and `..`
    /// removed lexically (`/a/scenes/../robots/x` -> `/a/robots/x`).
    fn resolve(&self, rel: &str) -> PathBuf {
        let p = Path::new(rel);
        let joined = if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.path.parent().unwrap_or(Path::new(".")).join(p)
        };
        let mut out = PathBuf::new();
        for c in joined.components() {
            match c {
                std::path::Component::CurDir => {}
                std::path::Component::ParentDir => match out.components().next_back() {
                    Some(std::path::Component::Normal(_)) => {
                        out.pop();
                    }
                    // `/..` is `/`.
                    Some(std::path::Component::RootDir | std::path::Component::Prefix(_)) => {}
                    _ => out.push(".."),
                },
                other => out.push(other),
            }
        }
        out
    }
}

/// A TOML value as an engine setting; `None` for arrays and tables.
pub fn setting_value(v: &toml::Value) -> Option<SettingValue> {
    match v {
        toml::Value::Boolean(b) => Some(SettingValue::Bool(*b)),
        toml::Value::Integer(i) => Some(SettingValue::Integer(*i)),
        toml::Value::Float(f) => Some(SettingValue::Float(*f)),
        toml::Value::String(s) => Some(SettingValue::Text(s.clone())),
        _ => None,
    }
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        && !name.starts_with('.')
}

/// Reads the TOML into the file's shape; a syntax or type error names its
/// line and column.
fn parse_file(text: &str, path: &Path) -> Result<FileScene, SceneError> {
    toml::from_str(text).map_err(|e| {
        let (line, column) = match e.span() {
            Some(span) => {
                let (l, c) = line_col(text, span.start);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        SceneError::Parse {
            path: path.to_path_buf(),
            line,
            column,
            message: e.message().trim().to_string(),
        }
    })
}

/// The steps of [`Scene::from_toml_str`], one per part of the file.
impl Builder<'_> {
    /// The `[robot]` table.
    fn robot(&mut self, r: &FileRobot) -> Result<RobotSpec, SceneError> {
        if r.urdf.get_ref().trim().is_empty() {
            return Err(self.invalid("robot.urdf", Some(&r.urdf), "must name a URDF file"));
        }
        self.at("robot.urdf", &r.urdf);
        let urdf = self.resolve(r.urdf.get_ref());
        let base = Pose::new(
            self.vec3("robot.base_position_m", &r.base_position_m)?,
            self.rpy("robot.base_rpy_deg", r.base_rpy_deg.as_ref())?,
        );
        let mjcf = match &r.mjcf {
            Some(m) => {
                self.at("robot.mjcf", m);
                Some(self.resolve(m.get_ref()))
            }
            None => None,
        };
        let mut held_joints_rad = BTreeMap::new();
        for (joint, value) in &r.held_joints_deg {
            let field = format!("robot.held_joints_deg.{}", joint.get_ref());
            let v = self.finite(&field, value)?;
            self.at(&field, joint);
            held_joints_rad.insert(joint.get_ref().clone(), v.to_radians());
        }
        Ok(RobotSpec {
            urdf: Some(urdf),
            base,
            mjcf,
            held_joints_rad,
        })
    }

    /// The optional `[ground]` table.
    fn ground(&self, g: Option<&FileGround>) -> Result<Option<Ground>, SceneError> {
        let ground = match g {
            Some(g) => {
                if !g.height_m.is_finite() {
                    return Err(self.invalid::<f64>(
                        "ground.height_m",
                        None,
                        "must be a finite number",
                    ));
                }
                let friction = match &g.friction {
                    Some(f) => Some(self.non_negative("ground.friction", f)?),
                    None => None,
                };
                Some(Ground {
                    height_m: g.height_m,
                    friction,
                })
            }
            None => None,
        };
        Ok(ground)
    }

    /// The `[[object]]` entries.
    fn objects(&mut self, file_objects: &[FileObject]) -> Result<Vec<SceneObject>, SceneError> {
        let mut objects: Vec<SceneObject> = Vec::new();
        for (i, o) in file_objects.iter().enumerate() {
            let f = |k: &str| format!("object[{i}].{k}");
            let name = o.name.get_ref().clone();
            if !valid_name(&name) {
                return Err(self.invalid(
                    &f("name"),
                    Some(&o.name),
                    format!("\"{name}\" is not a usable name (letters, digits, '_', '-', '.')"),
                ));
            }
            if objects.iter().any(|p| p.name == name) {
                return Err(self.invalid(
                    &f("name"),
                    Some(&o.name),
                    format!("another object is already named \"{name}\""),
                ));
            }
            self.at(&f("name"), &o.name);
            let shape = match o.shape.get_ref().as_str() {
                "box" => {
                    let s = self.vec3(&f("size_m"), &o.size_m)?;
                    if s.x <= 0.0 || s.y <= 0.0 || s.z <= 0.0 {
                        return Err(self.invalid(
                            &f("size_m"),
                            Some(&o.size_m),
                            "every edge length must be greater than 0",
                        ));
                    }
                    ObjectShape::Box { size_m: s }
                }
                other => {
                    return Err(self.invalid(
                        &f("shape"),
                        Some(&o.shape),
                        format!("unknown shape \"{other}\" (expected \"box\")"),
                    ))
                }
            };
            let mass_kg = self.positive(&f("mass_kg"), &o.mass_kg)?;
            let pose = Pose::new(
                self.vec3(&f("position_m"), &o.position_m)?,
                self.rpy(&f("rpy_deg"), o.rpy_deg.as_ref())?,
            );
            let friction = match &o.friction {
                Some(fr) => Some(self.non_negative(&f("friction"), fr)?),
                None => None,
            };
            let linear_velocity_m_s = match &o.linear_velocity_m_s {
                Some(v) => self.vec3(&f("linear_velocity_m_s"), v)?,
                None => Vec3::ZERO,
            };
            let angular_velocity_rad_s = match &o.angular_velocity_rad_s {
                Some(v) => self.vec3(&f("angular_velocity_rad_s"), v)?,
                None => Vec3::ZERO,
            };
            objects.push(SceneObject {
                name,
                shape,
                mass_kg,
                pose,
                linear_velocity_m_s,
                angular_velocity_rad_s,
                friction,
            });
        }
        Ok(objects)
    }

    /// The `[controller]` table, and the check that the run lasts a whole
    /// number of control periods.
    fn controller(
        &mut self,
        c: Option<&FileController>,
        has_robot: bool,
        duration: &Spanned<f64>,
        duration_s: f64,
    ) -> Result<ControllerSpec, SceneError> {
        let Some(c) = c else {
            if has_robot {
                return Err(self.invalid::<f64>(
                    "controller",
                    None,
                    "a scene with a [robot] needs a [controller] table (gain_per_s, max_speed_deg_s, period_s)",
                ));
            }
            return self.sampling_only(duration, duration_s);
        };
        let gain = |field: &str, v: &Option<Spanned<f64>>| match v {
            Some(v) => self.positive(field, v),
            None if has_robot => {
                Err(self.invalid::<f64>(field, None, "missing: a scene with a [robot] needs it"))
            }
            // A scene of free objects alone drives no joint: its
            // controller only sets the sample period.
            None => Ok(f64::INFINITY),
        };
        let gain_per_s = gain("controller.gain_per_s", &c.gain_per_s)?;
        let max_speed_deg_s = gain("controller.max_speed_deg_s", &c.max_speed_deg_s)?;
        let controller = ControllerSpec {
            gain_per_s,
            max_speed_deg_s,
            period_s: self.positive("controller.period_s", &c.period_s)?,
        };
        self.at("controller.period_s", &c.period_s);
        let ticks = duration_s / controller.period_s;
        if (ticks - ticks.round()).abs() > 1e-6 * ticks.max(1.0) {
            return Err(self.invalid(
            "duration_s",
            Some(duration),
            format!(
                "{duration_s} s is not a whole number of control periods ({} s): a run records one sample per period",
                controller.period_s
            ),
        ));
        }
        Ok(controller)
    }

    /// A scene of free objects alone without a `[controller]` table:
    /// samples every [`FREE_SAMPLE_PERIOD_S`], or once at the end of a
    /// shorter run.
    fn sampling_only(
        &mut self,
        duration: &Spanned<f64>,
        duration_s: f64,
    ) -> Result<ControllerSpec, SceneError> {
        let period_s = FREE_SAMPLE_PERIOD_S.min(duration_s);
        let ticks = duration_s / period_s;
        if (ticks - ticks.round()).abs() > 1e-6 * ticks.max(1.0) {
            return Err(self.invalid(
                "duration_s",
                Some(duration),
                format!("{duration_s} s is not a whole number of the default sample period ({period_s} s): give [controller] period_s"),
            ));
        }
        Ok(ControllerSpec {
            gain_per_s: f64::INFINITY,
            max_speed_deg_s: f64::INFINITY,
            period_s,
        })
    }

    /// The `[[actuator]]` entries: at least one with a robot, none
    /// without.
    fn actuators(
        &mut self,
        file_actuators: &[FileActuator],
        has_robot: bool,
    ) -> Result<Vec<ActuatorSpec>, SceneError> {
        if file_actuators.is_empty() && has_robot {
            return Err(self.invalid::<f64>(
                "actuator",
                None,
                "the scene needs at least one [[actuator]] (a controlled joint)",
            ));
        }
        if let (Some(a), false) = (file_actuators.first(), has_robot) {
            return Err(self.invalid(
                "actuator[0].joint",
                Some(&a.joint),
                "a scene without a [robot] has no joint to drive: remove its [[actuator]]s or add a [robot]",
            ));
        }
        let mut actuators: Vec<ActuatorSpec> = Vec::new();
        for (i, a) in file_actuators.iter().enumerate() {
            let f = |k: &str| format!("actuator[{i}].{k}");
            let joint = a.joint.get_ref().clone();
            if actuators.iter().any(|p| p.joint == joint) {
                return Err(self.invalid(
                    &f("joint"),
                    Some(&a.joint),
                    format!("joint \"{joint}\" already has an actuator"),
                ));
            }
            self.at(&f("joint"), &a.joint);
            let kv = self.positive(&f("kv"), &a.kv)?;
            let force_limit = match &a.force_limit {
                Some(fl) => {
                    let v = *fl.get_ref();
                    if v.is_nan() || v <= 0.0 {
                        return Err(self.invalid(
                            &f("force_limit"),
                            Some(fl),
                            format!("must be greater than 0, found {v}"),
                        ));
                    }
                    v
                }
                None => f64::INFINITY,
            };
            let kp = match &a.kp {
                Some(k) => Some(self.non_negative(&f("kp"), k)?),
                None => None,
            };
            actuators.push(ActuatorSpec {
                joint,
                kv,
                kp,
                force_limit,
            });
        }
        Ok(actuators)
    }

    /// The `[[schedule]]` entries (at least one; times increasing, before
    /// the end; targets only for actuated joints).
    fn schedule(
        &mut self,
        entries: &[FileScheduleEntry],
        duration_s: f64,
        actuators: &[ActuatorSpec],
    ) -> Result<Vec<ScheduleEntry>, SceneError> {
        if entries.is_empty() && actuators.is_empty() {
            return Ok(Vec::new());
        }
        if entries.is_empty() {
            return Err(self.invalid::<f64>(
                "schedule",
                None,
                "the scene needs at least one [[schedule]] entry",
            ));
        }
        let mut schedule: Vec<ScheduleEntry> = Vec::new();
        for (i, e) in entries.iter().enumerate() {
            let field = format!("schedule[{i}].t_s");
            let t_s = self.non_negative(&field, &e.t_s)?;
            if t_s >= duration_s {
                return Err(self.invalid(
                    &field,
                    Some(&e.t_s),
                    format!("{t_s} s is not before the end of the run ({duration_s} s)"),
                ));
            }
            if let Some(prev) = schedule.last() {
                if t_s <= prev.t_s {
                    return Err(self.invalid(
                        &field,
                        Some(&e.t_s),
                        format!("times must increase: {t_s} s follows {} s", prev.t_s),
                    ));
                }
            }
            let mut targets_deg = BTreeMap::new();
            for (joint, value) in &e.targets_deg {
                let field = format!("schedule[{i}].targets_deg.{}", joint.get_ref());
                let v = self.finite(&field, value)?;
                if !actuators.iter().any(|a| &a.joint == joint.get_ref()) {
                    return Err(self.invalid(
                        &field,
                        Some(joint),
                        format!(
                            "joint \"{}\" has no [[actuator]] (controlled joints: {})",
                            joint.get_ref(),
                            actuators
                                .iter()
                                .map(|a| a.joint.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                }
                self.at(&field, joint);
                targets_deg.insert(joint.get_ref().clone(), v);
            }
            schedule.push(ScheduleEntry { t_s, targets_deg });
        }
        Ok(schedule)
    }

    /// The `[[track]]` entries: each a link or one of the objects.
    fn tracks(
        &mut self,
        tracks: &[FileTrack],
        objects: &[SceneObject],
    ) -> Result<Vec<TrackedBody>, SceneError> {
        let mut tracked: Vec<TrackedBody> = Vec::new();
        for (i, t) in tracks.iter().enumerate() {
            let f = |k: &str| format!("track[{i}].{k}");
            let role = t.role.get_ref().clone();
            if role.trim().is_empty() {
                return Err(self.invalid(&f("role"), Some(&t.role), "must not be empty"));
            }
            if tracked.iter().any(|p| p.role == role) {
                return Err(self.invalid(
                    &f("role"),
                    Some(&t.role),
                    format!("role \"{role}\" is tracked twice"),
                ));
            }
            let target = match (&t.link, &t.object) {
                (Some(l), None) => {
                    self.at(&f("link"), l);
                    TrackTarget::Link(l.get_ref().clone())
                }
                (None, Some(o)) => {
                    if !objects.iter().any(|x| &x.name == o.get_ref()) {
                        return Err(self.invalid(
                            &f("object"),
                            Some(o),
                            format!(
                                "no object is named \"{}\" (objects: {})",
                                o.get_ref(),
                                if objects.is_empty() {
                                    "none".to_string()
                                } else {
                                    objects
                                        .iter()
                                        .map(|x| x.name.as_str())
                                        .collect::<Vec<_>>()
                                        .join(", ")
                                }
                            ),
                        ));
                    }
                    TrackTarget::Object(o.get_ref().clone())
                }
                _ => {
                    return Err(self.invalid(
                        &f("role"),
                        Some(&t.role),
                        "give exactly one of `link` or `object`",
                    ))
                }
            };
            tracked.push(TrackedBody { role, target });
        }
        Ok(tracked)
    }

    /// The `[engine.<name>]` tables.
    fn engine_settings(
        &mut self,
        engine: &BTreeMap<String, BTreeMap<Spanned<String>, Spanned<toml::Value>>>,
    ) -> Result<BTreeMap<String, EngineSettings>, SceneError> {
        let mut engine_settings = BTreeMap::new();
        for (engine, table) in engine {
            let mut settings = EngineSettings::new();
            for (key, value) in table {
                let field = format!("engine.{engine}.{}", key.get_ref());
                let v = setting_value(value.get_ref()).ok_or_else(|| {
                    self.invalid(
                        &field,
                        Some(value),
                        "must be a boolean, integer, float or string",
                    )
                })?;
                self.at(&field, key);
                settings.insert(key.get_ref().clone(), v);
            }
            engine_settings.insert(engine.clone(), settings);
        }
        Ok(engine_settings)
    }
}

/// The steps of [`Scene::validate`]: a scene checked against its robot.
struct Checker<'a> {
    scene: &'a Scene,
    robot: &'a RobotModel,
}

impl Checker<'_> {
    /// The robot's movable joints, for messages.
    fn joint_list(&self) -> String {
        self.robot
            .joints
            .iter()
            .filter(|j| j.kind.is_movable())
            .map(|j| j.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The index of joint `name`, which must exist and not be fixed.
    fn movable(&self, field: &str, name: &str) -> Result<usize, SceneError> {
        let robot = self.robot;
        let j = robot.joint_by_name(name).ok_or_else(|| {
            self.scene.error(
                field,
                format!(
                    "robot \"{}\" has no joint \"{name}\" (movable joints: {})",
                    robot.name,
                    self.joint_list()
                ),
            )
        })?;
        if robot.joints[j].kind == JointKind::Fixed {
            return Err(self.scene.error(
                field,
                format!(
                    "joint \"{name}\" of robot \"{}\" is fixed and cannot move",
                    robot.name
                ),
            ));
        }
        Ok(j)
    }

    /// Checks that `value_rad` is within joint `j`'s limits (if any).
    fn within(
        &self,
        field: &str,
        j: usize,
        value_rad: f64,
        shown: String,
    ) -> Result<(), SceneError> {
        if let Some(lim) = self.robot.joints[j].limits {
            let eps = 1e-9;
            if value_rad < lim.lower - eps || value_rad > lim.upper + eps {
                return Err(self.scene.error(
                    field,
                    format!(
                        "{shown} is outside the limits of joint \"{}\" ({:.4} to {:.4} deg)",
                        self.robot.joints[j].name,
                        lim.lower.to_degrees(),
                        lim.upper.to_degrees()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Actuated joints are movable, revolute and not mimic joints.
    fn actuators(&self) -> Result<(), SceneError> {
        for (i, a) in self.scene.actuators.iter().enumerate() {
            let field = format!("actuator[{i}].joint");
            let j = self.movable(&field, &a.joint)?;
            if self.robot.joints[j].mimic.is_some() {
                return Err(self.scene.error(
                    &field,
                    format!(
                        "joint \"{}\" mimics another joint and cannot be actuated",
                        a.joint
                    ),
                ));
            }
            if self.robot.joints[j].kind == JointKind::Prismatic {
                return Err(self.scene.error(
                    &field,
                    format!(
                        "joint \"{}\" is prismatic; the controller drives revolute joints",
                        a.joint
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Every scheduled target names a movable joint and is within its limits.
    fn schedule_targets(&self) -> Result<(), SceneError> {
        for (i, e) in self.scene.schedule.iter().enumerate() {
            for (joint, &deg) in &e.targets_deg {
                let field = format!("schedule[{i}].targets_deg.{joint}");
                let j = self.movable(&field, joint)?;
                self.within(&field, j, deg.to_radians(), format!("target {deg} deg"))?;
            }
        }
        Ok(())
    }

    /// Joints not named in an entry target 0: check 0 is reachable.
    fn default_targets(&self) -> Result<(), SceneError> {
        for a in &self.scene.actuators {
            if let Some(j) = self.robot.joint_by_name(&a.joint) {
                let named_everywhere = self
                    .scene
                    .schedule
                    .iter()
                    .all(|e| e.targets_deg.contains_key(&a.joint));
                if !named_everywhere {
                    self.within(
                        &format!("actuator.{}", a.joint),
                        j,
                        0.0,
                        "the default target 0 deg".to_string(),
                    )?;
                }
            }
        }
        Ok(())
    }

    /// Held joints are movable, not actuated, and held within their limits.
    fn held_joints(&self) -> Result<(), SceneError> {
        for (joint, &rad) in &self.scene.robot.held_joints_rad {
            let field = format!("robot.held_joints_deg.{joint}");
            let j = self.movable(&field, joint)?;
            if self.scene.actuators.iter().any(|a| &a.joint == joint) {
                return Err(self.scene.error(
                    &field,
                    format!("joint \"{joint}\" has an actuator and cannot also be held"),
                ));
            }
            self.within(&field, j, rad, format!("{} deg", rad.to_degrees()))?;
        }
        Ok(())
    }

    /// Tracked links exist.
    fn tracked_links(&self) -> Result<(), SceneError> {
        let robot = self.robot;
        for (i, t) in self.scene.tracked.iter().enumerate() {
            if let TrackTarget::Link(link) = &t.target {
                if robot.link_by_name(link).is_none() {
                    return Err(self.scene.error(
                        &format!("track[{i}].link"),
                        format!(
                            "robot \"{}\" has no link \"{link}\" (links: {})",
                            robot.name,
                            robot
                                .links
                                .iter()
                                .map(|l| l.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

impl Scene {
    /// Reads and checks a scene file. The paths inside it are resolved
    /// against the file's directory. The robot is not loaded: call
    /// [`Scene::validate`] with it.
    pub fn from_file(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|reason| SceneError::Io {
            path: path.to_path_buf(),
            reason,
        })?;
        let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        Scene::from_toml_str(&text, &abs)
    }

    /// Parses scene TOML text; `path` names the file in errors and is the
    /// base for relative paths.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let file = parse_file(text, path)?;
        let mut b = Builder {
            path,
            text,
            locations: HashMap::new(),
        };
        let name = file.name.get_ref().clone();
        if !valid_name(&name) {
            return Err(b.invalid(
                "name",
                Some(&file.name),
                format!("\"{name}\" is not a usable name: use letters, digits, '_', '-' and '.' (it names result directories)"),
            ));
        }
        let duration_s = b.positive("duration_s", &file.duration_s)?;
        b.at("duration_s", &file.duration_s);

        let has_robot = file.robot.is_some();
        let robot = match &file.robot {
            Some(r) => b.robot(r)?,
            None => RobotSpec::none(),
        };
        let ground = b.ground(file.ground.as_ref())?;
        let objects = b.objects(&file.objects)?;
        if !has_robot && objects.is_empty() {
            return Err(b.invalid::<f64>(
                "robot",
                None,
                "the scene has neither a [robot] nor an [[object]]: nothing would move",
            ));
        }
        let controller = b.controller(
            file.controller.as_ref(),
            has_robot,
            &file.duration_s,
            duration_s,
        )?;
        let actuators = b.actuators(&file.actuators, has_robot)?;
        let schedule = b.schedule(&file.schedule, duration_s, &actuators)?;
        let tracked = b.tracks(&file.tracks, &objects)?;
        let engine_settings = b.engine_settings(&file.engine)?;
        let gravity_m_s2 = match &file.gravity_m_s2 {
            Some(g) => b.vec3("gravity_m_s2", g)?,
            None => Vec3::new(0.0, 0.0, -STANDARD_GRAVITY_M_S2),
        };
        Ok(Scene {
            name,
            description: file.description.clone(),
            source: path.to_path_buf(),
            duration_s,
            gravity_m_s2,
            robot,
            ground,
            objects,
            controller,
            actuators,
            schedule,
            tracked,
            engine_settings,
            locations: b.locations,
        })
    }

    /// An error about a field of this scene, with the field's line and
    /// column when the file gave it.
    pub fn error(&self, field: &str, message: impl Into<String>) -> SceneError {
        let (line, column) = match self.locations.get(field) {
            Some(&(l, c)) => (Some(l), Some(c)),
            None => (None, None),
        };
        SceneError::Invalid {
            path: self.source.clone(),
            line,
            column,
            field: field.to_string(),
            message: message.into(),
        }
    }

    /// Checks the scene against its robot: every actuated, targeted, held and
    /// tracked name exists, actuated joints are movable, targets and held
    /// positions are within the joints' limits.
    pub fn validate(&self, robot: &RobotModel) -> Result<(), SceneError> {
        let c = Checker { scene: self, robot };
        c.actuators()?;
        c.schedule_targets()?;
        c.default_targets()?;
        c.held_joints()?;
        c.tracked_links()
    }

    /// Number of samples a complete run records: one per control period.
    pub fn sample_count(&self) -> usize {
        (self.duration_s / self.controller.period_s).round() as usize
    }

    /// Number of engine steps per control period for `timestep_s`; an error
    /// naming the scene's `controller.period_s` when the period is not a
    /// whole number of timesteps (within 1e-6 relative) or `timestep_s` is
    /// not positive.
    pub fn steps_per_period(&self, timestep_s: f64) -> Result<u64, SceneError> {
        if !(timestep_s.is_finite() && timestep_s > 0.0) {
            return Err(self.error(
                "controller.period_s",
                format!("the engine timestep must be positive, found {timestep_s} s"),
            ));
        }
        let ratio = self.controller.period_s / timestep_s;
        let n = ratio.round();
        if n < 1.0 || (ratio - n).abs() > 1e-6 * n {
            return Err(self.error(
                "controller.period_s",
                format!(
                    "the control period {} s is not a whole number of engine timesteps ({timestep_s} s gives {ratio:.6} steps)",
                    self.controller.period_s
                ),
            ));
        }
        Ok(n as u64)
    }

    /// Names of the controlled joints, in command order.
    pub fn controlled_joints(&self) -> Vec<&str> {
        self.actuators.iter().map(|a| a.joint.as_str()).collect()
    }

    /// Target angles (degrees, command order) of the schedule entry in force
    /// at control tick `tick` (time `tick * period_s`); all zero before the
    /// first entry. An entry at `t_s` takes effect at the first tick whose
    /// time is not before `t_s` (1e-9 s tolerance).
    pub fn targets_deg_at_tick(&self, tick: usize) -> Vec<f64> {
        let t = tick as f64 * self.controller.period_s;
        let entry = self.schedule.iter().rev().find(|e| e.t_s <= t + 1e-9);
        self.actuators
            .iter()
            .map(|a| {
                entry
                    .and_then(|e| e.targets_deg.get(&a.joint))
                    .copied()
                    .unwrap_or(0.0)
            })
            .collect()
    }

    /// The settings of `engine` from the scene file (empty when none).
    pub fn settings_for(&self, engine: &str) -> EngineSettings {
        self.engine_settings
            .get(engine)
            .cloned()
            .unwrap_or_default()
    }

    /// The object with this name.
    pub fn object(&self, name: &str) -> Option<&SceneObject> {
        self.objects.iter().find(|o| o.name == name)
    }

    /// Replaces the robot description (e.g. `--robot PATH`): a new URDF,
    /// and no MJCF override. The scene must be validated again.
    pub fn set_robot_urdf(&mut self, urdf: PathBuf) {
        self.robot.urdf = Some(urdf);
        self.robot.mjcf = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
name = "t"
duration_s = 1.0
[robot]
urdf = "arm.urdf"
base_position_m = [0, 0, 0.055]
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "j1"
kv = 10.0
force_limit = 100.0
[[actuator]]
joint = "j2"
kv = 4.0
[[schedule]]
t_s = 0.0
targets_deg = { j1 = -90.0 }
[[schedule]]
t_s = 0.5
targets_deg = { j2 = 45.0 }
[[object]]
name = "cube"
shape = "box"
size_m = [0.1, 0.1, 0.1]
mass_kg = 0.5
position_m = [0.5, 0, 0.05]
[[track]]
role = "wrist"
link = "l2"
[[track]]
role = "cube"
object = "cube"
[engine.mujoco]
timestep_s = 1e-4
integrator = "euler"
"#;

    fn parse(text: &str) -> Result<Scene, SceneError> {
        Scene::from_toml_str(text, Path::new("/scenes/t.toml"))
    }

    #[test]
    fn parses_minimal_scene() {
        let s = parse(MINIMAL).unwrap();
        assert_eq!(s.robot.urdf, Some(PathBuf::from("/scenes/arm.urdf")));
        let up = parse(&MINIMAL.replace("urdf = \"arm.urdf\"", "urdf = \"../robots/./arm.urdf\""))
            .unwrap();
        assert_eq!(up.robot.urdf, Some(PathBuf::from("/robots/arm.urdf")));
        assert_eq!(s.sample_count(), 20);
        assert_eq!(s.controlled_joints(), vec!["j1", "j2"]);
        assert_eq!(s.actuators[1].force_limit, f64::INFINITY);
        assert_eq!(s.targets_deg_at_tick(0), vec![-90.0, 0.0]);
        assert_eq!(s.targets_deg_at_tick(9), vec![-90.0, 0.0]);
        assert_eq!(s.targets_deg_at_tick(10), vec![0.0, 45.0]);
        assert_eq!(s.steps_per_period(1e-4).unwrap(), 500);
        assert_eq!(s.steps_per_period(0.01).unwrap(), 5);
        assert!(s.steps_per_period(0.03).is_err());
        assert_eq!(
            s.settings_for("mujoco").get("timestep_s"),
            Some(&SettingValue::Float(1e-4))
        );
        let inertia = s.objects[0].principal_inertia();
        assert!((inertia.x - 0.5 * 0.02 / 12.0).abs() < 1e-15);
    }

    /// A toss: a cube with an initial twist over a ground, no robot.
    const FREE: &str = r#"
name = "toss"
duration_s = 0.5
[ground]
height_m = 0.0
[[object]]
name = "cube"
shape = "box"
size_m = [0.1, 0.1, 0.1]
mass_kg = 0.37
position_m = [0.0, 0.0, 0.3]
linear_velocity_m_s = [1.0, 0.0, 2.0]
angular_velocity_rad_s = [0.0, 3.0, 0.0]
[[track]]
role = "cube"
object = "cube"
"#;

    #[test]
    fn free_objects_alone_need_no_robot_controller_or_schedule() {
        let s = parse(FREE).unwrap();
        assert!(!s.robot.is_some());
        assert_eq!(s.robot.urdf, None);
        assert!(s.actuators.is_empty() && s.schedule.is_empty());
        assert_eq!(s.controller.period_s, FREE_SAMPLE_PERIOD_S);
        assert_eq!(s.sample_count(), 50);
        assert_eq!(s.objects[0].linear_velocity_m_s, Vec3::new(1.0, 0.0, 2.0));
        assert_eq!(
            s.objects[0].angular_velocity_rad_s,
            Vec3::new(0.0, 3.0, 0.0)
        );
        assert_eq!(s.objects[0].half_extents_m(), Vec3::new(0.05, 0.05, 0.05));
        let robot = s
            .robot
            .model(&crate::robot::PackageResolver::new())
            .unwrap();
        assert_eq!((robot.links.len(), robot.joints.len()), (1, 0));
        s.validate(&robot).unwrap();
        // A sample period of its own.
        let s = parse(&format!("{FREE}[controller]\nperiod_s = 0.025\n")).unwrap();
        assert_eq!(s.sample_count(), 20);
    }

    #[test]
    fn free_objects_alone_refuse_what_drives_a_robot() {
        let msg = parse(&format!("{FREE}[[actuator]]\njoint = \"j1\"\nkv = 1.0\n"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("actuator[0].joint: a scene without a [robot] has no joint to drive"),
            "{msg}"
        );
        let msg = parse("name = \"empty\"\nduration_s = 1.0\n")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("neither a [robot] nor an [[object]]"), "{msg}");
        let msg = parse(&MINIMAL.replace("gain_per_s = 10.0", ""))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("controller.gain_per_s: missing"), "{msg}");
        let msg = parse(&FREE.replace("[0.0, 3.0, 0.0]", "[0.0, nan, 0.0]"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("object[0].angular_velocity_rad_s"), "{msg}");
    }

    #[test]
    fn syntax_error_names_line_and_column() {
        let bad = MINIMAL.replace("duration_s = 1.0", "duration_s = = 1.0");
        let e = parse(&bad).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("/scenes/t.toml:3:"), "{msg}");
    }

    #[test]
    fn unknown_field_is_reported() {
        let bad = MINIMAL.replace("kv = 4.0", "kv = 4.0\ngain = 3");
        let msg = parse(&bad).unwrap_err().to_string();
        assert!(msg.contains("unknown field `gain`"), "{msg}");
        assert!(msg.contains("/scenes/t.toml:"), "{msg}");
    }

    #[test]
    fn non_positive_duration_is_rejected() {
        let msg = parse(&MINIMAL.replace("duration_s = 1.0", "duration_s = 0.0"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains(":3:14: duration_s: must be greater than 0"),
            "{msg}"
        );
        let msg = parse(&MINIMAL.replace("duration_s = 1.0", "duration_s = 1.02"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("not a whole number of control periods"),
            "{msg}"
        );
    }

    #[test]
    fn target_of_uncontrolled_joint_is_rejected() {
        let msg = parse(&MINIMAL.replace("{ j2 = 45.0 }", "{ j9 = 45.0 }"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("schedule[1].targets_deg.j9: joint \"j9\" has no [[actuator]]"),
            "{msg}"
        );
    }

    #[test]
    fn schedule_must_increase_and_fit() {
        let msg = parse(&MINIMAL.replace("t_s = 0.5", "t_s = 0.0"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("times must increase"), "{msg}");
        let msg = parse(&MINIMAL.replace("t_s = 0.5", "t_s = 1.5"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("not before the end of the run"), "{msg}");
    }

    #[test]
    fn unknown_tracked_object_and_bad_shape() {
        let msg = parse(&MINIMAL.replace("object = \"cube\"", "object = \"ball\""))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("no object is named \"ball\""), "{msg}");
        let msg = parse(&MINIMAL.replace("shape = \"box\"", "shape = \"cone\""))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("unknown shape \"cone\""), "{msg}");
    }

    #[test]
    fn bad_engine_setting_type() {
        let msg = parse(&MINIMAL.replace("integrator = \"euler\"", "integrator = [1, 2]"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("engine.mujoco.integrator"), "{msg}");
    }

    #[test]
    fn bad_name_is_rejected() {
        let msg = parse(&MINIMAL.replace("name = \"t\"", "name = \"a/b\""))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("name: \"a/b\" is not a usable name"), "{msg}");
    }
}
