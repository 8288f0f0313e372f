//! The interface every physics engine implements: [`Engine`] loads a
//! [`Scene`] into a [`Simulation`], which takes joint commands (velocity
//! targets for the study's controller; position targets or efforts for a
//! recording's replay), steps, and reports joint angles and the poses of
//! the tracked bodies.
//!
//! That is all an engine does. The controller, the recording and the
//! divergence checks live in [`crate::controller`], identical for every
//! engine, which is what makes the comparison fair and what lets a new
//! engine arrive as one small crate.
//!
//! Contract of a [`Simulation`] returned by [`Engine::load`]:
//! - it starts at time 0 with every controlled joint at 0 rad (the URDF
//!   zero), held joints at their scene positions, objects at their scene
//!   poses, all at rest, and its reported state (angles, poses) is already
//!   valid before the first step;
//! - `joint_*` vectors are in the scene's actuator order
//!   ([`Scene::controlled_joints`]); poses in [`Scene::tracked`] order;
//! - a tracked link's pose is the pose of the URDF link frame in the world
//!   (metres, unit quaternion body to world); an object's pose is its centre;
//! - [`Simulation::step`] advances exactly one timestep; an engine that finds
//!   its own state unusable (NaN, an instability it detects and would
//!   otherwise paper over, such as MuJoCo's automatic reset) returns
//!   [`EngineError::Unstable`].

use crate::params::{ParamSupport, PhysicalParams};
use crate::pose::{Pose, Vec3};
use crate::robot::RobotModel;
use crate::scene::Scene;
pub use crate::trajectory::CommandKind;
use std::collections::BTreeMap;
use std::fmt;

/// The name of the physics-free model's engine (perfect tracking, the
/// `realitygap-engine-ideal` crate): a baseline source, left out where
/// engines are compared as physics (stitching plans, handovers).
pub const PHYSICS_FREE_ENGINE: &str = "ideal";

/// The engines linked into realitygap that simulate physics, each behind
/// a cargo feature of the command (a build may leave some out), in the
/// order a generated scene lists their settings.
pub const LINKED_ENGINES: &[&str] = &["mujoco", "bullet", "ode", "rapier", "physx", "dart"];

/// The engine setting every engine has: its fixed step, seconds
/// (`[engine.NAME] timestep_s`, `--set NAME.timestep_s=...`). `frontier`
/// sweeps it and `tune` halves it to check a fit.
pub const TIMESTEP_KEY: &str = "timestep_s";

/// Engine settings by key, as written in a scene's `[engine.NAME]` table or
/// given on the command line (`--set key=value`). The engine checks them.
pub type EngineSettings = BTreeMap<String, SettingValue>;

/// One engine setting value.
#[derive(Debug, Clone, PartialEq)]
pub enum SettingValue {
    /// `true` / `false`.
    Bool(bool),
    /// A whole number.
    Integer(i64),
    /// A real number.
    Float(f64),
    /// Text, e.g. an integrator name.
    Text(String),
}

impl SettingValue {
    /// Parses a command-line value: `true`/`false`, an integer, a float, or
    /// else text.
    pub fn parse(text: &str) -> SettingValue {
        let t = text.trim();
        if t == "true" {
            SettingValue::Bool(true)
        } else if t == "false" {
            SettingValue::Bool(false)
        } else if let Ok(i) = t.parse::<i64>() {
            SettingValue::Integer(i)
        } else if let Ok(f) = t.parse::<f64>() {
            SettingValue::Float(f)
        } else {
            SettingValue::Text(t.to_string())
        }
    }

    /// The value as a number (integers convert), else `None`.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            SettingValue::Integer(i) => Some(*i as f64),
            SettingValue::Float(f) => Some(*f),
            _ => None,
        }
    }

    /// The value as a whole number, else `None`.
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            SettingValue::Integer(i) => Some(*i),
            _ => None,
        }
    }

    /// The value as text, else `None`.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            SettingValue::Text(s) => Some(s),
            _ => None,
        }
    }

    /// The value as a boolean, else `None`.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            SettingValue::Bool(b) => Some(*b),
            _ => None,
        }
    }
}

impl fmt::Display for SettingValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SettingValue::Bool(b) => write!(f, "{b}"),
            SettingValue::Integer(i) => write!(f, "{i}"),
            SettingValue::Float(x) => write!(f, "{x:?}"),
            SettingValue::Text(s) => write!(f, "{s}"),
        }
    }
}

/// Changes to the physical model for one run (a perturbation), applied by
/// the engine when it loads the scene. The identity leaves the model as the
/// scene and robot describe it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelVariation {
    /// Factor on every body's mass and inertia (robot links and objects).
    pub mass_scale: f64,
    /// Factor on every friction coefficient (ground, objects, robot).
    pub friction_scale: f64,
}

impl Default for ModelVariation {
    fn default() -> Self {
        ModelVariation {
            mass_scale: 1.0,
            friction_scale: 1.0,
        }
    }
}

impl ModelVariation {
    /// True when the variation changes nothing.
    pub fn is_identity(&self) -> bool {
        self.mass_scale == 1.0 && self.friction_scale == 1.0
    }

    /// Checks the factors: masses by a positive, friction by a
    /// non-negative finite factor; the message says which is not.
    pub fn check(&self) -> Result<(), String> {
        if !(self.mass_scale.is_finite() && self.mass_scale > 0.0) {
            return Err(format!(
                "the mass factor must be positive and finite, found {}",
                self.mass_scale
            ));
        }
        if !(self.friction_scale.is_finite() && self.friction_scale >= 0.0) {
            return Err(format!(
                "the friction factor must be >= 0 and finite, found {}",
                self.friction_scale
            ));
        }
        Ok(())
    }
}

/// A setting an engine accepts, for `realitygap engines` and error messages.
#[derive(Debug, Clone, PartialEq)]
pub struct SettingInfo {
    /// The key, e.g. `timestep_s`.
    pub key: &'static str,
    /// What it does, its unit, its allowed values and its default.
    pub help: &'static str,
}

/// The one parse path for engine settings: every engine reads its
/// `[engine.NAME]` table and `--set` values through this, so unknown keys,
/// wrong types and out-of-range values give the same error everywhere:
/// `engine NAME: setting `KEY`: must be ..., found ...`.
pub struct SettingsReader<'a> {
    engine: &'a str,
    settings: &'a EngineSettings,
}

impl<'a> SettingsReader<'a> {
    /// A reader of `settings` for `engine`, whose accepted keys are
    /// `known`; a key not among them is an error listing the known ones.
    pub fn new(
        engine: &'a str,
        settings: &'a EngineSettings,
        known: &[SettingInfo],
    ) -> Result<SettingsReader<'a>, EngineError> {
        let reader = SettingsReader { engine, settings };
        if let Some(key) = settings
            .keys()
            .find(|k| !known.iter().any(|i| i.key == k.as_str()))
        {
            let names: Vec<&str> = known.iter().map(|i| i.key).collect();
            return Err(reader.error(
                key,
                format!("unknown setting (accepted: {})", names.join(", ")),
            ));
        }
        Ok(reader)
    }

    /// An error about `key` in this engine's style.
    pub fn error(&self, key: &str, message: impl Into<String>) -> EngineError {
        EngineError::Setting {
            engine: self.engine.to_string(),
            key: key.to_string(),
            message: message.into(),
        }
    }

    /// A number (integers convert; the text `inf` is infinity), when set;
    /// `ok` says which values are accepted and `what` describes them
    /// (`"greater than 0 s"`). NaN is never accepted, infinity only when
    /// `ok` accepts it.
    pub fn number(
        &self,
        key: &str,
        ok: impl Fn(f64) -> bool,
        what: &str,
    ) -> Result<Option<f64>, EngineError> {
        let Some(value) = self.settings.get(key) else {
            return Ok(None);
        };
        let v = match value {
            SettingValue::Text(t)
                if matches!(t.trim().to_ascii_lowercase().as_str(), "inf" | "infinity") =>
            {
                f64::INFINITY
            }
            other => other
                .as_f64()
                .ok_or_else(|| self.error(key, format!("expected a number, found \"{other}\"")))?,
        };
        if v.is_nan() || !ok(v) {
            return Err(self.error(key, format!("must be {what}, found {v}")));
        }
        Ok(Some(v))
    }

    /// A whole number in `min..=max`, when set.
    pub fn integer(&self, key: &str, min: i64, max: i64) -> Result<Option<i64>, EngineError> {
        let Some(value) = self.settings.get(key) else {
            return Ok(None);
        };
        let v = value.as_i64().ok_or_else(|| {
            self.error(key, format!("expected a whole number, found \"{value}\""))
        })?;
        if !(min..=max).contains(&v) {
            return Err(self.error(
                key,
                format!("must be a whole number from {min} to {max}, found {v}"),
            ));
        }
        Ok(Some(v))
    }

    /// `true` or `false`, when set.
    pub fn boolean(&self, key: &str) -> Result<Option<bool>, EngineError> {
        match self.settings.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_bool()
                .map(Some)
                .ok_or_else(|| self.error(key, format!("expected true or false, found \"{v}\""))),
        }
    }

    /// One of `choices` by name (case-insensitive), when set.
    pub fn choice<T: Copy>(
        &self,
        key: &str,
        choices: &[(&str, T)],
    ) -> Result<Option<T>, EngineError> {
        let Some(value) = self.settings.get(key) else {
            return Ok(None);
        };
        let text = value.as_str().map(|t| t.trim().to_ascii_lowercase());
        choices
            .iter()
            .find(|(name, _)| Some(*name) == text.as_deref())
            .map(|(_, v)| Some(*v))
            .ok_or_else(|| {
                let names: Vec<&str> = choices.iter().map(|(n, _)| *n).collect();
                self.error(
                    key,
                    format!("\"{value}\" is not one of {}", names.join(", ")),
                )
            })
    }
}

/// What went wrong in an engine.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EngineError {
    /// A setting is unknown or has a bad value.
    #[error("engine {engine}: setting `{key}`: {message}")]
    Setting {
        /// The engine's name.
        engine: String,
        /// The setting's key.
        key: String,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// The scene or robot cannot be turned into a model (a missing file, a
    /// feature the engine lacks, a model the engine rejects).
    #[error("engine {engine}: cannot load the scene: {message}")]
    Load {
        /// The engine's name.
        engine: String,
        /// The reason, with the file and element when known.
        message: String,
    },
    /// The simulation became unusable (non-finite state, a detected
    /// instability) at time `t_s`.
    #[error("engine {engine}: unstable at t = {t_s} s: {message}")]
    Unstable {
        /// The engine's name.
        engine: String,
        /// Simulated time, s.
        t_s: f64,
        /// What the engine reported.
        message: String,
    },
    /// A physical parameter the engine cannot honour, or cannot honour
    /// with this value.
    #[error("engine {engine}: parameter `{key}`: {message}")]
    Param {
        /// The engine's name.
        engine: String,
        /// The parameter, e.g. `joints.m1n6s300_joint_2.armature`.
        key: String,
        /// Why, and what the engine honours instead.
        message: String,
    },
    /// A state that cannot be loaded (wrong joint or object count,
    /// non-finite values).
    #[error("engine {engine}: cannot set the state: {message}")]
    State {
        /// The engine's name.
        engine: String,
        /// What does not fit.
        message: String,
    },
    /// Settings that the engine knows to be numerically unstable for the
    /// loaded model ([`Simulation::stability_issues`]); refused before the
    /// run unless the run allows unstable settings.
    #[error("engine {engine}: unstable settings for this model, refused before running: {message} (`realitygap run --allow-unstable` runs such settings anyway; a tune stays within the stable range when its --space file bounds the parameter there)")]
    UnstableSettings {
        /// The engine's name.
        engine: String,
        /// Every issue found: joint, quantity, bound and the fixes.
        message: String,
    },
    /// A call that does not fit the simulation (e.g. a vector of the wrong
    /// length).
    #[error("engine {engine}: {message}")]
    Usage {
        /// The engine's name.
        engine: String,
        /// What was wrong.
        message: String,
    },
}

/// A physics engine: a factory of [`Simulation`]s.
pub trait Engine: Send + Sync {
    /// Short lowercase name, used on the command line and in result
    /// directories (`mujoco`).
    fn name(&self) -> &'static str;
    /// The engine library's version (e.g. `MuJoCo 3.17.0`), recorded in
    /// every manifest.
    fn version(&self) -> String;
    /// The timestep used when the settings give none, s.
    fn default_timestep_s(&self) -> f64;
    /// The settings this engine accepts.
    fn settings_help(&self) -> Vec<SettingInfo>;
    /// Checks settings without loading anything and returns the timestep
    /// they select, s.
    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError>;
    /// The physical parameters this engine maps itself, and how (the keys
    /// [`crate::params::ParamKey::is_core`] need not be listed: the controller loop
    /// applies them). A key set in a parameters file and absent here is an
    /// error ([`PhysicalParams::check_support`]).
    fn param_support(&self) -> Vec<ParamSupport>;
    /// How this engine's servos take each kind of joint command
    /// ([`Simulation::set_joint_commands`]): one entry per kind, saying the
    /// engine's own mechanism (e.g. MuJoCo's `<position>` actuator law),
    /// for `realitygap engines` and the documentation. Every engine takes
    /// every kind.
    fn command_support(&self) -> Vec<CommandSupport>;
    /// Builds a simulation of `scene` with `robot` (already validated against
    /// the scene), configured by `settings`, changed by `variation`, with the
    /// engine-mapped physical parameters of `params` applied (armature,
    /// restitution, contact softness, and anything a model loaded as is,
    /// such as an MJCF file, must take from `params` itself).
    ///
    /// `scene` and `robot` already carry the parameters that
    /// [`PhysicalParams::apply`] writes into them; [`crate::controller::simulate_with`]
    /// calls `apply` and [`PhysicalParams::check_support`] before this.
    fn load_with(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        params: &PhysicalParams,
    ) -> Result<Box<dyn Simulation>, EngineError>;
    /// [`Engine::load_with`] without physical parameters.
    fn load(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<Box<dyn Simulation>, EngineError> {
        self.load_with(scene, robot, settings, variation, &PhysicalParams::none())
    }
}

/// One joint's servo command: what it asks ([`CommandKind`]) and the value,
/// in the kind's unit for a revolute joint (rad, rad/s, N m).
///
/// - `Velocity`: the velocity servo, `tau = kv (value - qd)`;
/// - `Position`: the PD servo, `tau = kp (value - q) - kv qd` (the scene
///   actuator's `kp` and `kv`);
/// - `Effort`: `tau = value`.
///
/// Every law is limited to the actuator's force limit.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ServoCommand {
    /// What the servo is asked to do.
    pub kind: CommandKind,
    /// The target or effort.
    pub value: f64,
}

impl ServoCommand {
    /// A velocity target, rad/s.
    pub fn velocity(rad_s: f64) -> ServoCommand {
        ServoCommand {
            kind: CommandKind::Velocity,
            value: rad_s,
        }
    }
    /// A position target, rad.
    pub fn position(rad: f64) -> ServoCommand {
        ServoCommand {
            kind: CommandKind::Position,
            value: rad,
        }
    }
    /// An effort, N m.
    pub fn effort(nm: f64) -> ServoCommand {
        ServoCommand {
            kind: CommandKind::Effort,
            value: nm,
        }
    }
}

/// How an engine honours one kind of joint command
/// ([`Engine::command_support`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CommandSupport {
    /// The kind.
    pub kind: CommandKind,
    /// The engine's mechanism, e.g. `<velocity kv> actuator (gain kv, bias -kv qd)`.
    pub mechanism: &'static str,
}

/// Checks servo commands against the scene's actuators before an engine
/// applies them: one per controlled joint, finite values, and a position
/// gain `kp` on every joint given a position command. The error names the
/// engine, the joint and the reason.
pub fn check_servo_commands(
    engine: &str,
    scene: &Scene,
    commands: &[ServoCommand],
) -> Result<(), EngineError> {
    let usage = |message: String| EngineError::Usage {
        engine: engine.to_string(),
        message,
    };
    if commands.len() != scene.actuators.len() {
        return Err(usage(format!(
            "{} servo commands for {} controlled joints",
            commands.len(),
            scene.actuators.len()
        )));
    }
    for (c, a) in commands.iter().zip(&scene.actuators) {
        if !c.value.is_finite() {
            return Err(usage(format!(
                "the {} command of joint \"{}\" is {}",
                c.kind.name(),
                a.joint,
                c.value
            )));
        }
        if c.kind == CommandKind::Position && a.kp.is_none() {
            return Err(usage(format!(
                "joint \"{}\" takes a position command but its actuator has no position gain: set kp in the scene's [[actuator]] or joints.{}.kp in the parameters",
                a.joint, a.joint
            )));
        }
    }
    Ok(())
}

/// The dynamic state of one scene object: pose and twist, world frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectState {
    /// The object's name in the scene.
    pub name: String,
    /// Its centre and orientation (body to world).
    pub pose: Pose,
    /// Velocity of its centre, world frame, m/s.
    pub linear_velocity_m_s: Vec3,
    /// Angular velocity, world frame, rad/s.
    pub angular_velocity_rad_s: Vec3,
}

/// An engine's own complete state, for restoring into the same engine
/// exactly (solver warm starts, held joints, actuator activations). Other
/// engines ignore it and load the portable fields of [`SimState`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NativeState {
    /// The engine's name ([`Engine::name`]).
    pub engine: String,
    /// The engine's numbers, in its own layout.
    pub data: Vec<f64>,
}

/// The state of a running simulation: everything needed to continue it in
/// this engine or hand it over to another one running the same scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimState {
    /// Simulated time, s.
    pub time_s: f64,
    /// Controlled joints' angles, rad, in the scene's actuator order.
    pub joint_angles_rad: Vec<f64>,
    /// Controlled joints' velocities, rad/s, same order.
    pub joint_velocities_rad_s: Vec<f64>,
    /// The servo velocity targets in force, rad/s, same order.
    pub joint_velocity_targets_rad_s: Vec<f64>,
    /// The servo commands in force when some joint's servo is not a
    /// velocity servo (a position or effort command), same order; empty
    /// when every servo runs on the velocity targets above.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub servo_commands: Vec<ServoCommand>,
    /// Every scene object, in the scene's order.
    pub objects: Vec<ObjectState>,
    /// The engine's own complete state, when it has one.
    pub native: Option<NativeState>,
}

impl SimState {
    /// The portable part only (no [`NativeState`]): what another engine
    /// loads, and what a same-engine restore without warm starts uses.
    pub fn portable(&self) -> SimState {
        SimState {
            native: None,
            ..self.clone()
        }
    }

    /// Checks the state against a simulation's joint and object counts and
    /// for non-finite numbers; the message says what does not fit.
    pub fn check(&self, joints: usize, objects: &[&str]) -> Result<(), String> {
        let vectors = [
            ("joint_angles_rad", &self.joint_angles_rad),
            ("joint_velocities_rad_s", &self.joint_velocities_rad_s),
            (
                "joint_velocity_targets_rad_s",
                &self.joint_velocity_targets_rad_s,
            ),
        ];
        for (name, v) in vectors {
            if v.len() != joints {
                return Err(format!(
                    "{name} has {} values, the simulation {joints} joints",
                    v.len()
                ));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!("{name}[{i}] is not finite"));
            }
        }
        if !self.servo_commands.is_empty() {
            if self.servo_commands.len() != joints {
                return Err(format!(
                    "servo_commands has {} values, the simulation {joints} joints",
                    self.servo_commands.len()
                ));
            }
            if let Some(i) = self
                .servo_commands
                .iter()
                .position(|c| !c.value.is_finite())
            {
                return Err(format!("servo_commands[{i}] is not finite"));
            }
        }
        if !self.time_s.is_finite() || self.time_s < 0.0 {
            return Err(format!("time {} s is not a finite time >= 0", self.time_s));
        }
        let names: Vec<&str> = self.objects.iter().map(|o| o.name.as_str()).collect();
        if names != objects {
            return Err(format!(
                "the state has objects {names:?}, the scene {objects:?}"
            ));
        }
        for o in &self.objects {
            let finite = o.pose.is_finite()
                && [o.linear_velocity_m_s, o.angular_velocity_rad_s]
                    .iter()
                    .all(|v| v.x.is_finite() && v.y.is_finite() && v.z.is_finite());
            if !finite {
                return Err(format!(
                    "object '{}' has a non-finite pose or twist",
                    o.name
                ));
            }
        }
        Ok(())
    }
}

/// A setting that an engine knows to be numerically unstable for the
/// loaded model, found at load time (after the model is built, so that
/// masses and inertias are known).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StabilityIssue {
    /// The joint concerned (the model's name), when the issue is a joint's.
    pub joint: Option<String>,
    /// The quantity checked, e.g. `kv*dt/I_eff`.
    pub quantity: String,
    /// Its value for this model and these settings.
    pub value: f64,
    /// The bound it must stay below.
    pub bound: f64,
    /// The whole explanation: the numbers that make up the quantity and
    /// the fixes (another setting, a smaller timestep).
    pub message: String,
}

/// One stretch of an open-loop schedule ([`Simulation::run_segments`]):
/// read the state first (when `read`), then set the commands (when
/// given), then take `steps` steps.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Read the state before anything else.
    pub read: bool,
    /// The commands from here on (see [`Simulation::set_joint_commands`]).
    pub commands: Option<Vec<ServoCommand>>,
    /// Steps to take.
    pub steps: u64,
}

/// The state read at a [`Segment`] with `read`.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentReading {
    /// Controlled joints' angles, rad.
    pub angles_rad: Vec<f64>,
    /// Controlled joints' velocities, rad/s.
    pub velocities_rad_s: Vec<f64>,
    /// Tracked bodies' poses.
    pub poses: Vec<Pose>,
}

/// One running simulation of a scene (see the module documentation for the
/// contract).
pub trait Simulation: Send {
    /// The settings of this simulation that the engine knows to be
    /// numerically unstable for its model, worst first; empty when none is
    /// known (the default). [`crate::controller::refuse_unstable`] refuses
    /// to run a simulation with issues unless its
    /// [`crate::controller::RunOptions`] allow it.
    fn stability_issues(&self) -> Vec<StabilityIssue> {
        Vec::new()
    }
    /// The fixed timestep, s.
    fn timestep_s(&self) -> f64;
    /// Simulated time since the start, s.
    fn time_s(&self) -> f64;
    /// Number of controlled joints (the scene's actuators).
    fn joint_count(&self) -> usize;
    /// Number of tracked bodies (the scene's `[[track]]` entries).
    fn tracked_count(&self) -> usize;
    /// Places the controlled joints at these angles (rad, at rest) before
    /// the first step, e.g. for perturbed initial conditions; the reported
    /// state is updated.
    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError>;
    /// Sets the velocity targets of the controlled joints' servos, rad/s;
    /// they hold until set again. Every servo becomes a velocity servo.
    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]);
    /// Sets one command per controlled joint, each of its own kind (see
    /// [`ServoCommand`]), through the engine's own mechanism for that kind
    /// ([`Engine::command_support`]); they hold until set again, and a
    /// joint's servo switches kind with its command. Checked with
    /// [`check_servo_commands`]: a wrong count, a non-finite value or a
    /// position command to a joint without `kp` is an error.
    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError>;
    /// Advances one timestep.
    fn step(&mut self) -> Result<(), EngineError>;
    /// Advances `n` timesteps (engines may check for trouble once per call).
    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }
    /// Runs an open-loop schedule: each segment in order (see
    /// [`Segment`]), the readings appended to `readings`. A failure
    /// part-way ends the schedule there with the readings taken before it
    /// kept. The default does it call by call; an engine that can take a
    /// whole schedule at once (one message for an engine out of process)
    /// does so, with the same result.
    fn run_segments(
        &mut self,
        segments: &[Segment],
        readings: &mut Vec<SegmentReading>,
    ) -> Result<(), EngineError> {
        for segment in segments {
            if segment.read {
                let mut angles_rad = vec![0.0; self.joint_count()];
                let mut velocities_rad_s = vec![0.0; self.joint_count()];
                let mut poses = vec![Pose::IDENTITY; self.tracked_count()];
                self.joint_angles_rad(&mut angles_rad);
                self.joint_velocities_rad_s(&mut velocities_rad_s)?;
                self.tracked_poses(&mut poses);
                readings.push(SegmentReading {
                    angles_rad,
                    velocities_rad_s,
                    poses,
                });
            }
            if let Some(commands) = &segment.commands {
                self.set_joint_commands(commands)?;
            }
            for _ in 0..segment.steps {
                self.step()?;
            }
        }
        Ok(())
    }
    /// Writes the controlled joints' angles, rad, into `out`
    /// (`out.len() == joint_count()`).
    fn joint_angles_rad(&self, out: &mut [f64]);
    /// Writes the controlled joints' velocities, rad/s, into `out`
    /// (`out.len() == joint_count()`). The default reads them from
    /// [`Simulation::state`]; an engine whose state is costly to read (a
    /// native copy) reads them directly.
    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        let state = self.state()?;
        for (o, v) in out.iter_mut().zip(&state.joint_velocities_rad_s) {
            *o = *v;
        }
        Ok(())
    }
    /// Writes the tracked bodies' world poses into `out`
    /// (`out.len() == tracked_count()`).
    fn tracked_poses(&self, out: &mut [Pose]);
    /// The current state (see [`SimState`]); valid at any time, also
    /// before the first step.
    fn state(&self) -> Result<SimState, EngineError>;
    /// Sets the state, at any time of the run. A state with a
    /// [`NativeState`] of this engine is restored exactly; otherwise the
    /// portable fields are loaded: joint angles and velocities, servo
    /// targets, object poses and twists and the time, with held joints at
    /// their scene positions and at rest, and whatever else the engine
    /// keeps (warm starts, contact caches) reset. The reported angles and
    /// poses are valid at once.
    fn set_state(&mut self, state: &SimState) -> Result<(), EngineError>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_reader_gives_one_error_style() {
        let known = [
            SettingInfo {
                key: "timestep_s",
                help: "",
            },
            SettingInfo {
                key: "iterations",
                help: "",
            },
            SettingInfo {
                key: "solver",
                help: "",
            },
            SettingInfo {
                key: "warm",
                help: "",
            },
        ];
        let mut s = EngineSettings::new();
        s.insert("timestep_s".into(), SettingValue::Integer(1));
        s.insert("iterations".into(), SettingValue::Integer(20));
        s.insert("solver".into(), SettingValue::Text("PGS".into()));
        s.insert("warm".into(), SettingValue::Bool(true));
        let r = SettingsReader::new("toy", &s, &known).unwrap();
        assert_eq!(
            r.number("timestep_s", |v| v > 0.0, "> 0").unwrap(),
            Some(1.0)
        );
        assert_eq!(r.number("absent", |v| v > 0.0, "> 0").unwrap(), None);
        assert_eq!(r.integer("iterations", 1, 100).unwrap(), Some(20));
        assert_eq!(
            r.choice("solver", &[("pgs", 1), ("tgs", 2)]).unwrap(),
            Some(1)
        );
        assert_eq!(r.boolean("warm").unwrap(), Some(true));
        let e = r
            .number("timestep_s", |v| v < 0.5, "below 0.5 s")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "engine toy: setting `timestep_s`: must be below 0.5 s, found 1"
        );
        let e = r.integer("iterations", 1, 10).unwrap_err().to_string();
        assert!(e.contains("from 1 to 10, found 20"), "{e}");
        let e = r.choice("solver", &[("tgs", 2)]).unwrap_err().to_string();
        assert!(e.contains("is not one of tgs"), "{e}");
        let e = r.boolean("solver").unwrap_err().to_string();
        assert!(e.contains("expected true or false"), "{e}");
        s.insert("bogus".into(), SettingValue::Integer(1));
        let e = SettingsReader::new("toy", &s, &known)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("setting `bogus`: unknown setting (accepted: timestep_s"),
            "{e}"
        );
    }

    #[test]
    fn parses_setting_values() {
        assert_eq!(SettingValue::parse("true"), SettingValue::Bool(true));
        assert_eq!(SettingValue::parse("12"), SettingValue::Integer(12));
        assert_eq!(SettingValue::parse("1e-4"), SettingValue::Float(1e-4));
        assert_eq!(SettingValue::parse("rk4"), SettingValue::Text("rk4".into()));
        assert_eq!(SettingValue::Integer(3).as_f64(), Some(3.0));
        assert_eq!(SettingValue::Text("x".into()).as_f64(), None);
        assert_eq!(SettingValue::Float(1e-4).to_string(), "0.0001");
    }
}
