//! Typed physical parameters of one simulation: what `--params FILE` gives
//! and what tuning writes.
//!
//! ```toml
//! [joints.m1n6s300_joint_2]   # any joint of the robot, by URDF name
//! damping = 0.5               # viscous, N m s/rad
//! armature = 0.01             # reflected rotor inertia, kg m^2
//! frictionloss = 0.2          # dry (Coulomb) joint friction, N m
//! kv = 40.0                   # velocity-servo gain, N m s/rad
//! kp = 700.0                  # position gain of a replay's PD servo, N m/rad
//! force_limit = 30.0          # actuator torque limit, N m
//! offset_deg = 0.3            # encoder zero offset: true = measured + offset
//!
//! [links.m1n6s300_link_3]
//! mass_scale = 1.1            # scales mass and inertia
//!
//! [objects.cube]
//! mass_kg = 0.09
//! friction = 0.6              # sliding friction coefficient
//! restitution = 0.0
//!
//! [contact]                   # engine-independent contact softness
//! time_constant_s = 0.02
//! damping_ratio = 1.0
//!
//! [controller]
//! delay_s = 0.05              # actuation latency of the arm
//! gain_per_s = 10.0
//! max_speed_deg_s = 30.0
//! max_accel_deg_s2 = 120.0    # acceleration limit of the velocity loop
//!
//! [actuator]                  # the actuator stage between command and servo
//! frequency_rad_s = 19.0      # second-order response of the velocity loop
//! damping_ratio = 0.5
//! max_velocity_deg_s = 40.0   # the servo target's largest speed
//! deadband_deg_s = 0.5        # commands smaller than this do not move the joint
//!
//! [engine.mujoco]             # engine settings, as in a scene's [engine.NAME]
//! timestep_s = 0.002
//! ```
//!
//! Every key is optional: absent means the scene's or the engine's own
//! value. Who honours what:
//!
//! - the controller loop in core applies `offset_deg` and `[controller]`
//!   identically for every engine ([`ParamKey::is_core`]);
//! - [`PhysicalParams::apply`] writes `kv`, `force_limit`, `damping`,
//!   `frictionloss`, `mass_scale`, `mass_kg` and `friction` into the
//!   [`Scene`] and [`RobotModel`] an engine is loaded from;
//! - each engine maps the rest (`armature`, `restitution`, `[contact]`) onto
//!   its own mechanism, and lists every key it honours with
//!   [`crate::Engine::param_support`]. A key that is set but not listed is
//!   an error naming the engine and the key ([`PhysicalParams::check_support`]),
//!   never silently ignored.

use crate::engine::{EngineError, EngineSettings, SettingValue};
use crate::robot::RobotModel;
use crate::scene::{line_col, setting_value, Scene};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Parameters of one joint; `None` keeps the scene's or robot's value.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointParams {
    /// Viscous damping, N m s/rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping: Option<f64>,
    /// Reflected rotor inertia added on the joint axis, kg m^2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub armature: Option<f64>,
    /// Dry (Coulomb) joint friction, N m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frictionloss: Option<f64>,
    /// Velocity-servo gain, N m s/rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kv: Option<f64>,
    /// Position gain of the PD servo that replays recorded position
    /// commands (`tau = kp (q_cmd - q) - kv qd`), N m/rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kp: Option<f64>,
    /// Actuator torque limit, N m (0 switches the servo off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub force_limit: Option<f64>,
    /// Encoder zero offset, degrees: true angle = measured angle + offset.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset_deg: Option<f64>,
}

/// Parameters of one robot link.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkParams {
    /// Factor on the link's mass and inertia.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass_scale: Option<f64>,
}

/// Parameters of one scene object.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectParams {
    /// Mass, kg (the inertia follows from the shape).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
    /// Sliding friction coefficient.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub friction: Option<f64>,
    /// Coefficient of restitution, 0 (plastic) to 1 (elastic).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restitution: Option<f64>,
}

/// Engine-independent contact softness: a contact behaves like a
/// mass-spring-damper with this time constant and damping ratio.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactParams {
    /// Time constant, s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_constant_s: Option<f64>,
    /// Damping ratio (1 = critically damped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping_ratio: Option<f64>,
}

/// Parameters of the controller and of the arm's velocity loop.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerParams {
    /// Actuation latency: a command reaches the servos this long after it
    /// is computed, s. Any value; applied at the first engine step at or
    /// after the due time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delay_s: Option<f64>,
    /// Proportional gain, 1/s (replaces the scene's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain_per_s: Option<f64>,
    /// Command clamp, degrees/s (replaces the scene's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_speed_deg_s: Option<f64>,
    /// Acceleration limit of the arm's velocity loop, degrees/s^2: the
    /// velocity target reaching a servo changes by at most this much per
    /// second (unlimited when absent).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_accel_deg_s2: Option<f64>,
}

/// The actuator stage: how the command in force (after the controller's
/// delay and acceleration limit) becomes the target the engine's servo
/// tracks, the same for every engine (see [`crate::controller`]). For
/// velocity commands (the study's controller, a replay of velocity
/// commands) the stage acts on the velocity target; for a replay's
/// position commands on the position target (the deadband does not
/// apply).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorParams {
    /// Natural frequency of a second-order response of the target to the
    /// command, rad/s (`target'' = w^2 (command - target) - 2 zeta w
    /// target'`); absent: the target is the command.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frequency_rad_s: Option<f64>,
    /// Damping ratio of that response (default 1, critically damped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping_ratio: Option<f64>,
    /// Largest speed of the target, degrees/s (of the velocity target's
    /// value for velocity commands, of the position target's rate for
    /// position commands).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_velocity_deg_s: Option<f64>,
    /// Velocity commands smaller than this are 0, degrees/s (a motor's
    /// stiction).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deadband_deg_s: Option<f64>,
}

/// The typed physical parameters of a run (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PhysicalParams {
    /// The file they were read from, if any.
    #[serde(skip)]
    pub source: Option<PathBuf>,
    /// Per joint, by URDF name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub joints: BTreeMap<String, JointParams>,
    /// Per link, by URDF name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub links: BTreeMap<String, LinkParams>,
    /// Per scene object, by name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub objects: BTreeMap<String, ObjectParams>,
    /// Contact softness.
    #[serde(skip_serializing_if = "is_default")]
    pub contact: ContactParams,
    /// Controller and velocity loop.
    #[serde(skip_serializing_if = "is_default")]
    pub controller: ControllerParams,
    /// The actuator stage.
    #[serde(skip_serializing_if = "is_default")]
    pub actuator: ActuatorParams,
    /// Engine settings by engine name (`[engine.mujoco]`), applied over the
    /// scene's; `--set` on the command line still wins.
    #[serde(skip)]
    pub engine_settings: BTreeMap<String, EngineSettings>,
    #[serde(skip)]
    locations: BTreeMap<String, (usize, usize)>,
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

/// One kind of parameter, independent of which joint, link or object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ParamKey {
    /// `joints.J.damping`
    JointDamping,
    /// `joints.J.armature`
    JointArmature,
    /// `joints.J.frictionloss`
    JointFrictionloss,
    /// `joints.J.kv`
    JointKv,
    /// `joints.J.kp`
    JointKp,
    /// `joints.J.force_limit`
    JointForceLimit,
    /// `joints.J.offset_deg`
    JointOffset,
    /// `links.L.mass_scale`
    LinkMassScale,
    /// `objects.O.mass_kg`
    ObjectMass,
    /// `objects.O.friction`
    ObjectFriction,
    /// `objects.O.restitution`
    ObjectRestitution,
    /// `contact.time_constant_s`
    ContactTimeConstant,
    /// `contact.damping_ratio`
    ContactDampingRatio,
    /// `controller.delay_s`
    ControllerDelay,
    /// `controller.gain_per_s`
    ControllerGain,
    /// `controller.max_speed_deg_s`
    ControllerMaxSpeed,
    /// `controller.max_accel_deg_s2`
    ControllerMaxAccel,
    /// `actuator.frequency_rad_s`
    ActuatorFrequency,
    /// `actuator.damping_ratio`
    ActuatorDamping,
    /// `actuator.max_velocity_deg_s`
    ActuatorMaxVelocity,
    /// `actuator.deadband_deg_s`
    ActuatorDeadband,
}

impl ParamKey {
    /// Every key, in the file's order.
    pub const ALL: [ParamKey; 21] = [
        ParamKey::JointDamping,
        ParamKey::JointArmature,
        ParamKey::JointFrictionloss,
        ParamKey::JointKv,
        ParamKey::JointKp,
        ParamKey::JointForceLimit,
        ParamKey::JointOffset,
        ParamKey::LinkMassScale,
        ParamKey::ObjectMass,
        ParamKey::ObjectFriction,
        ParamKey::ObjectRestitution,
        ParamKey::ContactTimeConstant,
        ParamKey::ContactDampingRatio,
        ParamKey::ControllerDelay,
        ParamKey::ControllerGain,
        ParamKey::ControllerMaxSpeed,
        ParamKey::ControllerMaxAccel,
        ParamKey::ActuatorFrequency,
        ParamKey::ActuatorDamping,
        ParamKey::ActuatorMaxVelocity,
        ParamKey::ActuatorDeadband,
    ];

    /// The key as written in a file, with `<joint>`, `<link>`, `<object>`
    /// standing for the name.
    pub fn pattern(self) -> &'static str {
        match self {
            ParamKey::JointDamping => "joints.<joint>.damping",
            ParamKey::JointArmature => "joints.<joint>.armature",
            ParamKey::JointFrictionloss => "joints.<joint>.frictionloss",
            ParamKey::JointKv => "joints.<joint>.kv",
            ParamKey::JointKp => "joints.<joint>.kp",
            ParamKey::JointForceLimit => "joints.<joint>.force_limit",
            ParamKey::JointOffset => "joints.<joint>.offset_deg",
            ParamKey::LinkMassScale => "links.<link>.mass_scale",
            ParamKey::ObjectMass => "objects.<object>.mass_kg",
            ParamKey::ObjectFriction => "objects.<object>.friction",
            ParamKey::ObjectRestitution => "objects.<object>.restitution",
            ParamKey::ContactTimeConstant => "contact.time_constant_s",
            ParamKey::ContactDampingRatio => "contact.damping_ratio",
            ParamKey::ControllerDelay => "controller.delay_s",
            ParamKey::ControllerGain => "controller.gain_per_s",
            ParamKey::ControllerMaxSpeed => "controller.max_speed_deg_s",
            ParamKey::ControllerMaxAccel => "controller.max_accel_deg_s2",
            ParamKey::ActuatorFrequency => "actuator.frequency_rad_s",
            ParamKey::ActuatorDamping => "actuator.damping_ratio",
            ParamKey::ActuatorMaxVelocity => "actuator.max_velocity_deg_s",
            ParamKey::ActuatorDeadband => "actuator.deadband_deg_s",
        }
    }

    /// Keys the controller loop in core applies the same way for every
    /// engine; engines need not list them.
    pub fn is_core(self) -> bool {
        matches!(
            self,
            ParamKey::JointOffset
                | ParamKey::JointKp
                | ParamKey::ControllerDelay
                | ParamKey::ControllerGain
                | ParamKey::ControllerMaxSpeed
                | ParamKey::ControllerMaxAccel
                | ParamKey::ActuatorFrequency
                | ParamKey::ActuatorDamping
                | ParamKey::ActuatorMaxVelocity
                | ParamKey::ActuatorDeadband
        )
    }

    /// How the controller loop applies a core key.
    pub fn core_mapping(self) -> Option<&'static str> {
        match self {
            ParamKey::JointOffset => {
                Some("the controller reads angle - offset, so the joint settles at target + offset")
            }
            ParamKey::ControllerDelay => {
                Some("commands reach the servos delay_s after they are computed; the engine step a command falls inside runs on the average of the old and the new command, so the delay acts continuously")
            }
            ParamKey::JointKp => Some(
                "written into the scene's actuator: the gain of the PD servo that position commands drive (tau = kp (q_cmd - q) - kv qd), each engine's own mechanism (`realitygap engines` lists them)",
            ),
            ParamKey::ControllerGain => Some("replaces the scene's controller gain"),
            ParamKey::ControllerMaxSpeed => Some("replaces the scene's command clamp"),
            ParamKey::ControllerMaxAccel => Some(
                "the velocity target in force moves toward each new command by at most max_accel x the control period",
            ),
            ParamKey::ActuatorFrequency => Some(
                "the actuator stage: the servo's target follows the command in force through a second-order response of this natural frequency, integrated every millisecond",
            ),
            ParamKey::ActuatorDamping => Some("the actuator stage: that response's damping ratio"),
            ParamKey::ActuatorMaxVelocity => {
                Some("the actuator stage: the servo's target at most this fast")
            }
            ParamKey::ActuatorDeadband => {
                Some("the actuator stage: velocity commands smaller than this are 0")
            }
            _ => None,
        }
    }
}

impl fmt::Display for ParamKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.pattern())
    }
}

/// One parameter an engine honours, and how (for `realitygap engines
/// --params` and the README's table).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSupport {
    /// The parameter.
    pub key: ParamKey,
    /// What it becomes in the engine, e.g. `dof_damping`.
    pub mapping: &'static str,
}

/// A parameters file that cannot be read or used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{}: {message}", path_text(path), loc(*line, *column))]
pub struct ParamsError {
    /// The file, when the parameters came from one.
    pub path: Option<PathBuf>,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// 1-based column, when known.
    pub column: Option<usize>,
    /// What is wrong and what is expected.
    pub message: String,
}

fn path_text(path: &Option<PathBuf>) -> String {
    match path {
        Some(p) => p.display().to_string(),
        None => "parameters".to_string(),
    }
}

fn loc(line: Option<usize>, column: Option<usize>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!(":{l}:{c}"),
        (Some(l), None) => format!(":{l}"),
        _ => String::new(),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileParams {
    #[serde(default)]
    joints: BTreeMap<Spanned<String>, FileJoint>,
    #[serde(default)]
    links: BTreeMap<Spanned<String>, FileLink>,
    #[serde(default)]
    objects: BTreeMap<Spanned<String>, FileObject>,
    #[serde(default)]
    contact: Option<FileContact>,
    #[serde(default)]
    controller: Option<FileController>,
    #[serde(default)]
    actuator: Option<FileActuator>,
    #[serde(default)]
    engine: BTreeMap<String, BTreeMap<String, Spanned<toml::Value>>>,
}

type Num = Option<Spanned<f64>>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileJoint {
    damping: Num,
    armature: Num,
    frictionloss: Num,
    kv: Num,
    kp: Num,
    force_limit: Num,
    offset_deg: Num,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileLink {
    mass_scale: Num,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileObject {
    mass_kg: Num,
    friction: Num,
    restitution: Num,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileContact {
    time_constant_s: Num,
    damping_ratio: Num,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileController {
    delay_s: Num,
    gain_per_s: Num,
    max_speed_deg_s: Num,
    max_accel_deg_s2: Num,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileActuator {
    frequency_rad_s: Num,
    damping_ratio: Num,
    max_velocity_deg_s: Num,
    deadband_deg_s: Num,
}

/// The allowed range of a value.
#[derive(Clone, Copy)]
enum Range {
    /// `>= 0`.
    NonNegative,
    /// `[0, 1]`.
    Unit,
    /// From the first to the second, both included: the physical range of
    /// a quantity the engines compute with ([`PHYSICAL_MAX`],
    /// [`PHYSICAL_MIN`]).
    Span(f64, f64),
}

/// The largest magnitude of a physical parameter (N m s/rad, kg m^2, N m,
/// kg, 1/s, ...). Beyond it the engines' numbers overflow or their solvers
/// break: single-precision engines (Rapier, PhysX) hold at most 3.4e38, so
/// 1e300 becomes infinite; a joint damping of 1e300 panicked Rapier's
/// solver and aborted PhysX (`PxIsFinite`); a link mass scale of 1e300
/// aborted ODE. No robot comes near it (the iiwa's 300 N m, servo gains
/// in the hundreds, tuning spaces up to a few thousand).
pub const PHYSICAL_MAX: f64 = 1e6;

/// The least value of a parameter that must be positive and that the
/// engines divide by or invert (masses, a servo's kv, the contact's time
/// constant and damping ratio, the actuator's damping ratio): below it the
/// engines' inverses overflow (a 1e-300 kg cube aborted ODE and DART;
/// Rapier and PhysX refuse it as no single-precision number).
pub const PHYSICAL_MIN: f64 = 1e-6;

/// `[0, PHYSICAL_MAX]`.
const BOUNDED: Range = Range::Span(0.0, PHYSICAL_MAX);
/// `[PHYSICAL_MIN, PHYSICAL_MAX]`.
const BOUNDED_POSITIVE: Range = Range::Span(PHYSICAL_MIN, PHYSICAL_MAX);

struct Reader<'a> {
    path: &'a Path,
    text: &'a str,
    locations: BTreeMap<String, (usize, usize)>,
}

impl Reader<'_> {
    fn error_at(&self, offset: Option<usize>, message: String) -> ParamsError {
        let (line, column) = match offset {
            Some(o) => {
                let (l, c) = line_col(self.text, o);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        ParamsError {
            path: Some(self.path.to_path_buf()),
            line,
            column,
            message,
        }
    }

    fn value(&mut self, field: &str, v: &Num, range: Range) -> Result<Option<f64>, ParamsError> {
        let Some(s) = v else { return Ok(None) };
        let x = *s.get_ref();
        let (ok, want) = match range {
            Range::NonNegative => (x.is_finite() && x >= 0.0, "a finite number >= 0"),
            Range::Unit => (
                x.is_finite() && (0.0..=1.0).contains(&x),
                "a number from 0 to 1",
            ),
            Range::Span(lo, hi) => {
                if !(x.is_finite() && (lo..=hi).contains(&x)) {
                    return Err(self.error_at(
                        Some(s.span().start),
                        format!(
                            "{field}: must be a number from {lo:e} to {hi:e} (outside, the engines' numbers \
                             overflow or their solvers break), found {x:e}"
                        ),
                    ));
                }
                (true, "")
            }
        };
        if !ok {
            return Err(self.error_at(
                Some(s.span().start),
                format!("{field}: must be {want}, found {x}"),
            ));
        }
        self.locations
            .insert(field.to_string(), line_col(self.text, s.span().start));
        Ok(Some(x))
    }

    fn name(&mut self, field: String, name: &Spanned<String>) -> String {
        self.locations
            .insert(field, line_col(self.text, name.span().start));
        name.get_ref().clone()
    }
}

impl PhysicalParams {
    /// No parameters: every value is the scene's or the engine's own.
    pub fn none() -> PhysicalParams {
        PhysicalParams::default()
    }

    /// True when nothing is set (engine settings included).
    pub fn is_empty(&self) -> bool {
        self.set_keys().is_empty() && self.engine_settings.is_empty()
    }

    /// Reads a parameters file.
    pub fn from_file(path: &Path) -> Result<PhysicalParams, ParamsError> {
        let text = std::fs::read_to_string(path).map_err(|e| ParamsError {
            path: Some(path.to_path_buf()),
            line: None,
            column: None,
            message: format!("cannot read the parameters file: {e}"),
        })?;
        PhysicalParams::from_toml_str(&text, path)
    }

    /// Parses parameters TOML; `path` names the file in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<PhysicalParams, ParamsError> {
        let mut r = Reader {
            path,
            text,
            locations: BTreeMap::new(),
        };
        let file: FileParams = toml::from_str(text)
            .map_err(|e| r.error_at(e.span().map(|s| s.start), e.message().trim().to_string()))?;
        let mut p = PhysicalParams {
            source: Some(path.to_path_buf()),
            ..PhysicalParams::default()
        };
        for (name, j) in &file.joints {
            let n = r.name(format!("joints.{}", name.get_ref()), name);
            let f = |k: &str| format!("joints.{n}.{k}");
            let jp = JointParams {
                damping: r.value(&f("damping"), &j.damping, BOUNDED)?,
                armature: r.value(&f("armature"), &j.armature, BOUNDED)?,
                frictionloss: r.value(&f("frictionloss"), &j.frictionloss, BOUNDED)?,
                kv: r.value(&f("kv"), &j.kv, BOUNDED_POSITIVE)?,
                kp: r.value(&f("kp"), &j.kp, BOUNDED)?,
                force_limit: r.value(&f("force_limit"), &j.force_limit, BOUNDED)?,
                offset_deg: r.value(&f("offset_deg"), &j.offset_deg, Range::Span(-360.0, 360.0))?,
            };
            p.joints.insert(n, jp);
        }
        for (name, l) in &file.links {
            let n = r.name(format!("links.{}", name.get_ref()), name);
            let mass_scale = r.value(
                &format!("links.{n}.mass_scale"),
                &l.mass_scale,
                BOUNDED_POSITIVE,
            )?;
            p.links.insert(n, LinkParams { mass_scale });
        }
        for (name, o) in &file.objects {
            let n = r.name(format!("objects.{}", name.get_ref()), name);
            let f = |k: &str| format!("objects.{n}.{k}");
            let op = ObjectParams {
                mass_kg: r.value(&f("mass_kg"), &o.mass_kg, BOUNDED_POSITIVE)?,
                friction: r.value(&f("friction"), &o.friction, BOUNDED)?,
                restitution: r.value(&f("restitution"), &o.restitution, Range::Unit)?,
            };
            p.objects.insert(n, op);
        }
        if let Some(c) = &file.contact {
            p.contact = ContactParams {
                time_constant_s: r.value(
                    "contact.time_constant_s",
                    &c.time_constant_s,
                    BOUNDED_POSITIVE,
                )?,
                damping_ratio: r.value(
                    "contact.damping_ratio",
                    &c.damping_ratio,
                    BOUNDED_POSITIVE,
                )?,
            };
        }
        if let Some(c) = &file.controller {
            p.controller = ControllerParams {
                delay_s: r.value("controller.delay_s", &c.delay_s, Range::NonNegative)?,
                gain_per_s: r.value("controller.gain_per_s", &c.gain_per_s, BOUNDED_POSITIVE)?,
                max_speed_deg_s: r.value(
                    "controller.max_speed_deg_s",
                    &c.max_speed_deg_s,
                    BOUNDED_POSITIVE,
                )?,
                max_accel_deg_s2: r.value(
                    "controller.max_accel_deg_s2",
                    &c.max_accel_deg_s2,
                    BOUNDED_POSITIVE,
                )?,
            };
        }
        if let Some(a) = &file.actuator {
            p.actuator = ActuatorParams {
                frequency_rad_s: r.value(
                    "actuator.frequency_rad_s",
                    &a.frequency_rad_s,
                    BOUNDED_POSITIVE,
                )?,
                damping_ratio: r.value(
                    "actuator.damping_ratio",
                    &a.damping_ratio,
                    BOUNDED_POSITIVE,
                )?,
                max_velocity_deg_s: r.value(
                    "actuator.max_velocity_deg_s",
                    &a.max_velocity_deg_s,
                    BOUNDED_POSITIVE,
                )?,
                deadband_deg_s: r.value("actuator.deadband_deg_s", &a.deadband_deg_s, BOUNDED)?,
            };
        }
        for (engine, table) in &file.engine {
            let mut settings = EngineSettings::new();
            for (key, value) in table {
                let v = setting_value(value.get_ref()).ok_or_else(|| {
                    r.error_at(
                        Some(value.span().start),
                        format!("engine.{engine}.{key}: expected a number, true/false or text"),
                    )
                })?;
                settings.insert(key.clone(), v);
            }
            p.engine_settings.insert(engine.clone(), settings);
        }
        if let Some(delay) = p.controller.delay_s {
            if delay > 10.0 {
                return Err(r.error_at(
                    None,
                    format!("controller.delay_s: {delay} s is longer than 10 s; is it in seconds?"),
                ));
            }
        }
        p.locations = r.locations;
        Ok(p)
    }

    /// Writes the parameters as TOML in the file format (engine settings
    /// included), for `tuned.toml` and manifests.
    pub fn to_toml_string(&self) -> String {
        let mut out = String::new();
        let num = |x: f64| format!("{x:?}");
        for (name, j) in &self.joints {
            out.push_str(&format!("[joints.{}]\n", quote_key(name)));
            let fields = [
                ("damping", j.damping),
                ("armature", j.armature),
                ("frictionloss", j.frictionloss),
                ("kv", j.kv),
                ("kp", j.kp),
                ("force_limit", j.force_limit),
                ("offset_deg", j.offset_deg),
            ];
            for (k, v) in fields {
                if let Some(v) = v {
                    out.push_str(&format!("{k} = {}\n", num(v)));
                }
            }
            out.push('\n');
        }
        for (name, l) in &self.links {
            out.push_str(&format!("[links.{}]\n", quote_key(name)));
            if let Some(v) = l.mass_scale {
                out.push_str(&format!("mass_scale = {}\n", num(v)));
            }
            out.push('\n');
        }
        for (name, o) in &self.objects {
            out.push_str(&format!("[objects.{}]\n", quote_key(name)));
            for (k, v) in [
                ("mass_kg", o.mass_kg),
                ("friction", o.friction),
                ("restitution", o.restitution),
            ] {
                if let Some(v) = v {
                    out.push_str(&format!("{k} = {}\n", num(v)));
                }
            }
            out.push('\n');
        }
        let sections = [
            (
                "contact",
                vec![
                    ("time_constant_s", self.contact.time_constant_s),
                    ("damping_ratio", self.contact.damping_ratio),
                ],
            ),
            (
                "controller",
                vec![
                    ("delay_s", self.controller.delay_s),
                    ("gain_per_s", self.controller.gain_per_s),
                    ("max_speed_deg_s", self.controller.max_speed_deg_s),
                    ("max_accel_deg_s2", self.controller.max_accel_deg_s2),
                ],
            ),
            (
                "actuator",
                vec![
                    ("frequency_rad_s", self.actuator.frequency_rad_s),
                    ("damping_ratio", self.actuator.damping_ratio),
                    ("max_velocity_deg_s", self.actuator.max_velocity_deg_s),
                    ("deadband_deg_s", self.actuator.deadband_deg_s),
                ],
            ),
        ];
        for (section, fields) in sections {
            if fields.iter().any(|(_, v)| v.is_some()) {
                out.push_str(&format!("[{section}]\n"));
                for (k, v) in fields {
                    if let Some(v) = v {
                        out.push_str(&format!("{k} = {}\n", num(v)));
                    }
                }
                out.push('\n');
            }
        }
        for (engine, settings) in &self.engine_settings {
            out.push_str(&format!("[engine.{}]\n", quote_key(engine)));
            for (k, v) in settings {
                let value = match v {
                    SettingValue::Text(s) => format!("{s:?}"),
                    SettingValue::Float(x) => num(*x),
                    other => other.to_string(),
                };
                out.push_str(&format!("{} = {value}\n", quote_key(k)));
            }
            out.push('\n');
        }
        out
    }

    /// Every key set, with the name it is set for (`None` for the
    /// `[contact]` and `[controller]` keys).
    pub fn set_keys(&self) -> Vec<(ParamKey, Option<String>)> {
        let mut keys = Vec::new();
        for (n, j) in &self.joints {
            let named = [
                (ParamKey::JointDamping, j.damping),
                (ParamKey::JointArmature, j.armature),
                (ParamKey::JointFrictionloss, j.frictionloss),
                (ParamKey::JointKv, j.kv),
                (ParamKey::JointKp, j.kp),
                (ParamKey::JointForceLimit, j.force_limit),
                (ParamKey::JointOffset, j.offset_deg),
            ];
            keys.extend(
                named
                    .iter()
                    .filter(|(_, v)| v.is_some())
                    .map(|(k, _)| (*k, Some(n.clone()))),
            );
        }
        for (n, l) in &self.links {
            if l.mass_scale.is_some() {
                keys.push((ParamKey::LinkMassScale, Some(n.clone())));
            }
        }
        for (n, o) in &self.objects {
            for (k, v) in [
                (ParamKey::ObjectMass, o.mass_kg),
                (ParamKey::ObjectFriction, o.friction),
                (ParamKey::ObjectRestitution, o.restitution),
            ] {
                if v.is_some() {
                    keys.push((k, Some(n.clone())));
                }
            }
        }
        for (k, v) in [
            (ParamKey::ContactTimeConstant, self.contact.time_constant_s),
            (ParamKey::ContactDampingRatio, self.contact.damping_ratio),
            (ParamKey::ControllerDelay, self.controller.delay_s),
            (ParamKey::ControllerGain, self.controller.gain_per_s),
            (
                ParamKey::ControllerMaxSpeed,
                self.controller.max_speed_deg_s,
            ),
            (
                ParamKey::ControllerMaxAccel,
                self.controller.max_accel_deg_s2,
            ),
            (ParamKey::ActuatorFrequency, self.actuator.frequency_rad_s),
            (ParamKey::ActuatorDamping, self.actuator.damping_ratio),
            (
                ParamKey::ActuatorMaxVelocity,
                self.actuator.max_velocity_deg_s,
            ),
            (ParamKey::ActuatorDeadband, self.actuator.deadband_deg_s),
        ] {
            if v.is_some() {
                keys.push((k, None));
            }
        }
        keys
    }

    /// The error for `links.L.mass_scale` set on a link of the robot's
    /// fixed base (no controlled joint between it and the root): the
    /// engine welds it to the world, so its mass has no effect.
    pub fn check_fixed_base_masses(
        &self,
        engine: &str,
        scene: &Scene,
        robot: &RobotModel,
    ) -> Result<(), EngineError> {
        for (name, l) in &self.links {
            let Some(link) = robot.link_by_name(name) else {
                continue; // `apply` reports unknown names.
            };
            if l.mass_scale.is_some() && crate::robot::plan::in_fixed_base(scene, robot, link) {
                return Err(EngineError::Param {
                    engine: engine.to_string(),
                    key: format!("links.{name}.mass_scale"),
                    message: format!(
                        "link {name} is part of the robot's fixed base (no controlled joint between it \
                         and the root), so its mass has no effect"
                    ),
                });
            }
        }
        Ok(())
    }

    /// The error for every key set that neither core nor `engine` (whose
    /// [`crate::Engine::param_support`] is `support`) honours; `Ok` when all
    /// are honoured.
    pub fn check_support(&self, engine: &str, support: &[ParamSupport]) -> Result<(), EngineError> {
        for (key, name) in self.set_keys() {
            if key.is_core() || support.iter().any(|s| s.key == key) {
                continue;
            }
            let full = key_field(key, name.as_deref());
            let honoured: Vec<&str> = support.iter().map(|s| s.key.pattern()).collect();
            let at = self.located(&full);
            return Err(EngineError::Param {
                engine: engine.to_string(),
                key: full,
                message: format!(
                    "{at}this engine has no equivalent; it honours: {}",
                    if honoured.is_empty() {
                        "only the controller keys".to_string()
                    } else {
                        honoured.join(", ")
                    }
                ),
            });
        }
        Ok(())
    }

    /// `file:line:col: ` of a field, or the file, or nothing.
    fn located(&self, field: &str) -> String {
        match (&self.source, self.locations.get(field)) {
            (Some(p), Some((l, c))) => format!("{}:{l}:{c}: ", p.display()),
            (Some(p), None) => format!("{}: ", p.display()),
            _ => String::new(),
        }
    }

    fn name_error(&self, field: &str, message: String) -> ParamsError {
        let (line, column) = match self.locations.get(field) {
            Some(&(l, c)) => (Some(l), Some(c)),
            None => (None, None),
        };
        ParamsError {
            path: self.source.clone(),
            line,
            column,
            message,
        }
    }

    /// Writes the parameters that live in the scene and the robot model
    /// into copies of them: servo `kv` and `force_limit` into the scene's
    /// actuators (and `kp`), joint `damping` and `frictionloss` and link `mass_scale`
    /// into the robot, object `mass_kg` and `friction` into the scene's
    /// objects, and the controller's gain and clamp into the scene's
    /// controller. Names that the robot or scene lacks are errors.
    pub fn apply(
        &self,
        scene: &Scene,
        robot: &RobotModel,
    ) -> Result<(Scene, RobotModel), ParamsError> {
        let mut scene = scene.clone();
        let mut robot = robot.clone();
        for (name, j) in &self.joints {
            let Some(ji) = robot.joint_by_name(name) else {
                return Err(self.name_error(
                    &format!("joints.{name}"),
                    format!(
                        "joints.{name}: the robot {} has no joint of that name",
                        robot.name
                    ),
                ));
            };
            let joint = &mut robot.joints[ji];
            if let Some(d) = j.damping {
                joint.damping = d;
            }
            if let Some(f) = j.frictionloss {
                joint.friction = f;
            }
            let actuator = scene.actuators.iter_mut().find(|a| &a.joint == name);
            let servo_keys = j.kv.is_some()
                || j.kp.is_some()
                || j.force_limit.is_some()
                || j.offset_deg.is_some();
            match actuator {
                Some(a) => {
                    if let Some(kv) = j.kv {
                        a.kv = kv;
                    }
                    if let Some(kp) = j.kp {
                        a.kp = Some(kp);
                    }
                    if let Some(f) = j.force_limit {
                        a.force_limit = f;
                    }
                }
                None if servo_keys => {
                    return Err(self.name_error(
                        &format!("joints.{name}"),
                        format!(
                            "joints.{name}: kv, kp, force_limit and offset_deg need a controlled joint, and the scene {} has no [[actuator]] for it",
                            scene.name
                        ),
                    ));
                }
                None => {}
            }
        }
        for (name, l) in &self.links {
            let Some(li) = robot.link_by_name(name) else {
                return Err(self.name_error(
                    &format!("links.{name}"),
                    format!(
                        "links.{name}: the robot {} has no link of that name",
                        robot.name
                    ),
                ));
            };
            if let (Some(s), Some(inertial)) = (l.mass_scale, robot.links[li].inertial.as_mut()) {
                inertial.mass_kg *= s;
                for v in inertial.inertia.iter_mut() {
                    *v *= s;
                }
            }
        }
        for (name, o) in &self.objects {
            let Some(object) = scene.objects.iter_mut().find(|x| &x.name == name) else {
                return Err(self.name_error(
                    &format!("objects.{name}"),
                    format!(
                        "objects.{name}: the scene {} has no object of that name",
                        scene.name
                    ),
                ));
            };
            if let Some(m) = o.mass_kg {
                object.mass_kg = m;
            }
            if let Some(f) = o.friction {
                object.friction = Some(f);
            }
        }
        if let Some(g) = self.controller.gain_per_s {
            scene.controller.gain_per_s = g;
        }
        if let Some(v) = self.controller.max_speed_deg_s {
            scene.controller.max_speed_deg_s = v;
        }
        Ok((scene, robot))
    }

    /// The encoder offsets of the scene's controlled joints, rad, in
    /// actuator order (0 where none is set).
    pub fn offsets_rad(&self, scene: &Scene) -> Vec<f64> {
        scene
            .actuators
            .iter()
            .map(|a| {
                self.joints
                    .get(&a.joint)
                    .and_then(|j| j.offset_deg)
                    .unwrap_or(0.0)
                    .to_radians()
            })
            .collect()
    }

    /// The acceleration limit of the velocity loop, rad/s^2 (infinite when
    /// none is set).
    pub fn max_accel_rad_s2(&self) -> f64 {
        self.controller
            .max_accel_deg_s2
            .map_or(f64::INFINITY, f64::to_radians)
    }

    /// The actuation latency, s (0 when none is set).
    pub fn delay_s(&self) -> f64 {
        self.controller.delay_s.unwrap_or(0.0)
    }

    /// Armature of a joint, kg m^2, when set.
    pub fn armature(&self, joint: &str) -> Option<f64> {
        self.joints.get(joint).and_then(|j| j.armature)
    }

    /// Restitution of an object, when set.
    pub fn restitution(&self, object: &str) -> Option<f64> {
        self.objects.get(object).and_then(|o| o.restitution)
    }

    /// The engine settings of `engine` in the file, laid over `base`.
    pub fn settings_over(&self, engine: &str, base: &EngineSettings) -> EngineSettings {
        let mut s = base.clone();
        if let Some(own) = self.engine_settings.get(engine) {
            for (k, v) in own {
                s.insert(k.clone(), v.clone());
            }
        }
        s
    }
}

fn key_field(key: ParamKey, name: Option<&str>) -> String {
    match name {
        Some(n) => {
            let mut parts = key.pattern().split('.');
            let section = parts.next().unwrap_or_default();
            let field = parts.nth(1).unwrap_or_default();
            format!("{section}.{n}.{field}")
        }
        None => key.pattern().to_string(),
    }
}

fn quote_key(k: &str) -> String {
    if !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        k.to_string()
    } else {
        format!("{k:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing;

    const FULL: &str = r#"
[joints.m1n6s300_joint_2]
damping = 0.5
armature = 0.01
frictionloss = 0.2
kv = 40.0
force_limit = 30.0
offset_deg = 0.3

[links.m1n6s300_link_3]
mass_scale = 1.1

[objects.cube]
mass_kg = 0.09
friction = 0.6
restitution = 0.0

[contact]
time_constant_s = 0.02
damping_ratio = 1.0

[controller]
delay_s = 0.05
gain_per_s = 10.0
max_speed_deg_s = 30.0

[engine.mujoco]
timestep_s = 0.002
integrator = "implicitfast"
"#;

    fn parse(text: &str) -> Result<PhysicalParams, ParamsError> {
        PhysicalParams::from_toml_str(text, Path::new("/p/params.toml"))
    }

    #[test]
    fn reads_every_key_and_writes_it_back() {
        let p = parse(FULL).unwrap();
        assert_eq!(p.joints["m1n6s300_joint_2"].armature, Some(0.01));
        assert_eq!(p.links["m1n6s300_link_3"].mass_scale, Some(1.1));
        assert_eq!(p.objects["cube"].friction, Some(0.6));
        assert_eq!(p.contact.time_constant_s, Some(0.02));
        assert_eq!(p.controller.delay_s, Some(0.05));
        assert_eq!(
            p.engine_settings["mujoco"]["integrator"],
            SettingValue::Text("implicitfast".into())
        );
        assert_eq!(p.set_keys().len(), 15);
        let again = parse(&p.to_toml_string()).unwrap();
        assert_eq!(again.joints, p.joints);
        assert_eq!(again.links, p.links);
        assert_eq!(again.objects, p.objects);
        assert_eq!(again.contact, p.contact);
        assert_eq!(again.controller, p.controller);
        assert_eq!(again.engine_settings, p.engine_settings);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let e = parse("[joints.a]\ndamping = 1.0\nbogus = 2\n").unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("/p/params.toml:3:1:"), "{s}");
        assert!(s.contains("bogus"), "{s}");
        let e = parse("[joints.a]\ndamping = -1.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/p/params.toml:2:11:"), "{e}");
        assert!(
            e.contains("joints.a.damping") && e.contains("from 0e0 to 1e6"),
            "{e}"
        );
        let e = parse("[objects.cube]\nrestitution = 1.5\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("from 0 to 1"), "{e}");
        let e = parse("[joints.a\n").unwrap_err().to_string();
        assert!(e.starts_with("/p/params.toml:1:"), "{e}");
        let e = parse("[controller]\ndelay_s = 50\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("longer than 10 s"), "{e}");
        let e = parse("[joints.a]\nkv = nan\n").unwrap_err().to_string();
        assert!(e.contains("from 1e-6 to 1e6"), "{e}");
        // Beyond the physical range: the engines' numbers would overflow.
        let e = parse("[joints.a]\ndamping = 1e300\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("/p/params.toml:2:11:")
                && e.contains("joints.a.damping")
                && e.contains("overflow"),
            "{e}"
        );
        let e = parse("[objects.cube]\nmass_kg = 1e-300\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("objects.cube.mass_kg") && e.contains("from 1e-6"),
            "{e}"
        );
    }

    #[test]
    fn unsupported_keys_name_engine_and_key() {
        let p = parse(FULL).unwrap();
        let support = [ParamSupport {
            key: ParamKey::JointDamping,
            mapping: "x",
        }];
        let e = p.check_support("toy", &support).unwrap_err().to_string();
        assert!(e.contains("toy"), "{e}");
        assert!(e.contains("joints.m1n6s300_joint_2.armature"), "{e}");
        assert!(e.contains("/p/params.toml:4:12"), "{e}");
        let all: Vec<ParamSupport> = ParamKey::ALL
            .iter()
            .map(|&key| ParamSupport { key, mapping: "x" })
            .collect();
        p.check_support("toy", &all).unwrap();
        // Core keys need no engine support.
        let core = parse("[controller]\ndelay_s = 0.1\n[joints.a]\noffset_deg = 1.0\n").unwrap();
        core.check_support("toy", &[]).unwrap();
    }

    #[test]
    fn applies_scene_and_robot_keys() {
        let scene = testing::scene("scene1_single_joint");
        let robot = testing::mico2();
        let p = parse(FULL).unwrap();
        let (s, r) = p.apply(&scene, &robot).unwrap();
        let a = s
            .actuators
            .iter()
            .find(|a| a.joint == "m1n6s300_joint_2")
            .unwrap();
        assert_eq!((a.kv, a.force_limit), (40.0, 30.0));
        let j = &r.joints[r.joint_by_name("m1n6s300_joint_2").unwrap()];
        assert_eq!((j.damping, j.friction), (0.5, 0.2));
        let l = r.link_by_name("m1n6s300_link_3").unwrap();
        let before = robot.links[l].inertial.as_ref().unwrap();
        let after = r.links[l].inertial.as_ref().unwrap();
        assert!((after.mass_kg - 1.1 * before.mass_kg).abs() < 1e-12);
        assert!((after.inertia[0] - 1.1 * before.inertia[0]).abs() < 1e-15);
        assert_eq!(s.objects[0].mass_kg, 0.09);
        assert_eq!(s.objects[0].friction, Some(0.6));
        let offsets = p.offsets_rad(&s);
        assert!((offsets[1] - 0.3f64.to_radians()).abs() < 1e-15);
        assert_eq!(offsets[0], 0.0);

        let e = parse("[joints.nope]\ndamping = 1.0\n")
            .unwrap()
            .apply(&scene, &robot)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/p/params.toml:1:9:"), "{e}");
        assert!(e.contains("no joint of that name"), "{e}");
        let e = parse("[objects.ball]\nmass_kg = 1.0\n")
            .unwrap()
            .apply(&scene, &robot)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no object"), "{e}");
        let e = parse("[joints.m1n6s300_joint_finger_1]\nkv = 1.0\n")
            .unwrap()
            .apply(&scene, &robot)
            .unwrap_err()
            .to_string();
        assert!(e.contains("controlled joint"), "{e}");
    }
}
