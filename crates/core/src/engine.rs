//! The interface every physics engine implements: [`Engine`] loads a
//! [`Scene`] into a [`Simulation`], which takes joint velocity targets,
//! steps, and reports joint angles and the poses of the tracked bodies.
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

use crate::pose::Pose;
use crate::robot::RobotModel;
use crate::scene::Scene;
use std::collections::BTreeMap;
use std::fmt;

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
}

/// A setting an engine accepts, for `realitygap engines` and error messages.
#[derive(Debug, Clone, PartialEq)]
pub struct SettingInfo {
    /// The key, e.g. `timestep_s`.
    pub key: &'static str,
    /// What it does, its unit, its allowed values and its default.
    pub help: &'static str,
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
    /// Builds a simulation of `scene` with `robot` (already validated against
    /// the scene), configured by `settings` and changed by `variation`.
    fn load(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<Box<dyn Simulation>, EngineError>;
}

/// One running simulation of a scene (see the module documentation for the
/// contract).
pub trait Simulation: Send {
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
    /// they hold until set again.
    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]);
    /// Advances one timestep.
    fn step(&mut self) -> Result<(), EngineError>;
    /// Advances `n` timesteps (engines may check for trouble once per call).
    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }
    /// Writes the controlled joints' angles, rad, into `out`
    /// (`out.len() == joint_count()`).
    fn joint_angles_rad(&self, out: &mut [f64]);
    /// Writes the tracked bodies' world poses into `out`
    /// (`out.len() == tracked_count()`).
    fn tracked_poses(&self, out: &mut [Pose]);
}

#[cfg(test)]
mod tests {
    use super::*;

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
