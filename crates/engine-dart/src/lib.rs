//! The DART engine of realitygap: DART 6.12 (the Dynamic Animation and
//! Robotics Toolkit, the physics of Gazebo's `dartsim` plugin) from
//! Debian's `libdart-dev`, through a thin C++ shim (`shim/dart_shim.cc`)
//! built as a library of its own and loaded when a DART world is first made
//! (`ffi`).
//!
//! [`DartEngine`] implements [`realitygap_core::Engine`]. The robot is one
//! DART skeleton in generalized coordinates (Featherstone's articulated
//! body algorithm), built by the [`world`] module from core's rigid-group
//! planning, not by DART's URDF loader: the same masses, inertias, merged
//! fixed joints, held joints and meshes as the ODE, Rapier and PhysX
//! engines, and no package resolution of DART's own (see the README).
//!
//! Every controlled joint has DART's FORCE actuator, and the scene's servo
//! laws are set before every step through DART's own implicit joint terms
//! ([`world::JointModel::drive`]): the velocity servo `kv (v_target - v)`
//! is the joint damping `kv` with the torque `kv v_target`, the PD servo is
//! the joint spring `kp` at the target with the damping `kv`, an effort is
//! the torque; each clamped to the force limit. With `servo = "servo"`
//! velocity commands use DART's SERVO actuator (a velocity constraint)
//! instead. Contacts, joint limits and joint Coulomb friction are DART's
//! constraints, solved by its boxed LCP solver ([`settings`]).
//!
//! DART's printing goes to the `log` crate, never to standard output (the
//! shim captures it per thread). A non-finite state, a joint faster than
//! [`MAX_JOINT_SPEED`] or an object faster than [`MAX_SPEED_M_S`] (or
//! spinning faster than [`MAX_SPIN_RAD_S`]) ends the run as
//! [`EngineError::Unstable`], with what DART said.
//!
//! Physical parameters: [`params`]. Simulation state: [`state`].

mod ffi;
pub mod params;
pub mod settings;
pub mod state;
pub mod world;

use realitygap_core::engine::{
    check_servo_commands, CommandKind, CommandSupport, Engine, EngineError, EngineSettings,
    ModelVariation, ServoCommand, SettingInfo, SimState, Simulation,
};
use realitygap_core::params::{ParamSupport, PhysicalParams};
use realitygap_core::pose::Pose;
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use settings::{DartSettings, Servo, ENGINE_NAME};
use world::{forward_messages, ode_guard, Recipe, Tracked, World};

pub use settings::{Detector, Lcp};

/// A controlled joint turning faster than this, rad/s (or m/s), means the
/// simulation blew up (the arms' joints stay below 2 rad/s).
pub const MAX_JOINT_SPEED: f64 = 1000.0;

/// An object moving faster than this, m/s, means the simulation blew up.
pub const MAX_SPEED_M_S: f64 = 100.0;

/// An object spinning faster than this, rad/s, means the simulation blew
/// up.
pub const MAX_SPIN_RAD_S: f64 = 1000.0;

/// The DART version of the headers the shim was built with, e.g. `6.12.1`
/// (`DART_VERSION`, read by build.rs: naming it loads nothing).
pub fn dart_version() -> String {
    env!("REALITYGAP_DART_HEADER_VERSION").to_string()
}

/// Prints `text` the ways DART prints (its `dtmsg`, `dtwarn`, `dterr`
/// macros and std::cout and std::clog) inside the shim, which captures it
/// like any DART message: it goes to the `log` crate and is returned, and
/// reaches no stream. For the tests of that capture.
#[doc(hidden)]
pub fn say_through_dart(text: &str) -> String {
    if let Err(e) = ffi::say(text) {
        return e.to_string();
    }
    forward_messages()
}

/// The DART engine.
#[derive(Debug, Default, Clone, Copy)]
pub struct DartEngine;

impl Engine for DartEngine {
    fn name(&self) -> &'static str {
        ENGINE_NAME
    }

    fn version(&self) -> String {
        format!(
            "DART {} (Debian libdart {})",
            dart_version(),
            env!("REALITYGAP_DART_PKG_VERSION")
        )
    }

    fn default_timestep_s(&self) -> f64 {
        settings::DEFAULT_TIMESTEP_S
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        settings::SETTINGS.to_vec()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        Ok(DartSettings::parse(settings)?.timestep_s)
    }

    fn param_support(&self) -> Vec<ParamSupport> {
        params::PARAM_SUPPORT.to_vec()
    }

    fn command_support(&self) -> Vec<CommandSupport> {
        COMMAND_SUPPORT.to_vec()
    }

    fn load_with(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        params: &PhysicalParams,
    ) -> Result<Box<dyn Simulation>, EngineError> {
        Ok(Box::new(DartSimulation::load_with(
            scene, robot, settings, variation, params,
        )?))
    }
}

/// How DART takes each kind of joint command: DART's FORCE actuator and
/// its implicit joint damping and spring, set before every step.
pub const COMMAND_SUPPORT: [CommandSupport; 3] = [
    CommandSupport {
        kind: CommandKind::Velocity,
        mechanism: "FORCE actuator: joint damping kv (implicit) and command kv v, the limit when kv (v - qd) exceeds it (servo = \"servo\": DART's SERVO actuator, a velocity constraint bounded by the limit)",
    },
    CommandSupport {
        kind: CommandKind::Position,
        mechanism: "FORCE actuator: joint spring kp at rest position q and damping kv (both implicit), the limit when kp (q - angle) - kv qd exceeds it",
    },
    CommandSupport {
        kind: CommandKind::Effort,
        mechanism: "FORCE actuator: setCommand(clamped effort) before every step",
    },
];

fn load_error(message: impl Into<String>) -> EngineError {
    EngineError::Load {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

fn usage_error(message: impl Into<String>) -> EngineError {
    EngineError::Usage {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

/// A DART world of a scene, driven through [`Simulation`].
pub struct DartSimulation {
    world: World,
    scene: Scene,
    settings: DartSettings,
    /// Simulated time at the last [`Simulation::set_state`] (0 at load), s.
    time_origin_s: f64,
    /// Steps taken since then.
    steps: u64,
    /// The command of every controlled joint (velocity targets included).
    commands: Vec<ServoCommand>,
    /// Whether a joint has DART's SERVO actuator now.
    servo_actuator: Vec<bool>,
    /// Joint positions and velocities after the last step or state change.
    q: Vec<f64>,
    v: Vec<f64>,
    /// Drive buffers: command, damping, stiffness, rest.
    drives: [Vec<f64>; 4],
}

impl DartSimulation {
    /// Builds the DART world of `scene` with `robot` (validated against the
    /// scene), configured by `settings` and changed by `variation`, with the
    /// engine-mapped keys of `params` (`armature`, `restitution`; `scene`
    /// and `robot` already carry the keys [`PhysicalParams::apply`]
    /// writes), at rest with every controlled joint at 0.
    pub fn load_with(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        physical: &PhysicalParams,
    ) -> Result<DartSimulation, EngineError> {
        let settings = DartSettings::parse(settings)?;
        params::check(scene, robot, &settings, physical)?;
        let world = world::build(&Recipe {
            scene,
            robot,
            settings: &settings,
            variation,
            params: physical,
        })
        .map_err(|m| {
            load_error(format!(
                "{m} (robot {}, scene {})",
                robot.source.display(),
                scene.source.display()
            ))
        })?;
        let n = world.joints.len();
        let mut sim = DartSimulation {
            world,
            scene: scene.clone(),
            time_origin_s: 0.0,
            steps: 0,
            commands: vec![ServoCommand::velocity(0.0); n],
            servo_actuator: vec![settings.servo == Servo::Servo; n],
            settings,
            q: vec![0.0; n],
            v: vec![0.0; n],
            drives: [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]],
        };
        sim.read_joints();
        Ok(sim)
    }

    /// [`DartSimulation::load_with`] without physical parameters.
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<DartSimulation, EngineError> {
        Self::load_with(scene, robot, settings, variation, &PhysicalParams::none())
    }

    /// The checked settings in force.
    pub fn settings(&self) -> &DartSettings {
        &self.settings
    }

    /// The controlled joints' servo and passive terms.
    pub fn joints(&self) -> &[world::JointModel] {
        &self.world.joints
    }

    fn read_joints(&mut self) {
        self.world.raw().joint_state(&mut self.q, &mut self.v);
    }

    /// Computes every joint's drive from its command and the current state.
    fn compute_drives(&mut self) {
        let h = self.settings.timestep_s;
        for (i, j) in self.world.joints.iter().enumerate() {
            let d = j.drive(
                self.commands[i],
                self.q[i],
                self.v[i],
                h,
                self.servo_actuator[i],
            );
            self.drives[0][i] = d.command;
            self.drives[1][i] = d.damping;
            self.drives[2][i] = d.stiffness;
            self.drives[3][i] = d.rest;
        }
    }

    fn unstable(&self, message: String) -> EngineError {
        EngineError::Unstable {
            engine: ENGINE_NAME.to_string(),
            t_s: self.time_s(),
            message,
        }
    }

    /// One step (the lock, when needed, is held by the caller): the drives,
    /// DART's step and the joint state in one call to the shim.
    fn step_once(&mut self) -> Result<(), EngineError> {
        self.compute_drives();
        let [c, d, k, r] = &self.drives;
        let stepped = self
            .world
            .raw_mut()
            .advance(c, d, k, r, &mut self.q, &mut self.v);
        self.steps += 1;
        match stepped {
            Err(e) => {
                self.read_joints();
                let message = format!("DART failed: {}", e.what());
                forward_messages();
                Err(self.unstable(message))
            }
            Ok(report) => self.check_state(&report),
        }
    }

    /// Unstable when the state is not finite or moves impossibly fast.
    fn check_state(&self, report: &ffi::StepReport) -> Result<(), EngineError> {
        let said = if report.said {
            forward_messages()
        } else {
            String::new()
        };
        let joints_fine = self
            .v
            .iter()
            .zip(&self.q)
            .all(|(v, q)| q.is_finite() && v.abs() <= MAX_JOINT_SPEED);
        let objects_fine = report.objects_finite
            && report.max_speed <= MAX_SPEED_M_S
            && report.max_spin <= MAX_SPIN_RAD_S;
        if joints_fine && objects_fine {
            return Ok(());
        }
        let mut message = self.describe_trouble();
        if !said.is_empty() {
            message.push_str(&format!(" (DART said: {said})"));
        }
        Err(self.unstable(message))
    }

    /// What is wrong with the state (after a step found it so).
    fn describe_trouble(&self) -> String {
        for (i, (q, v)) in self.q.iter().zip(&self.v).enumerate() {
            let name = &self.world.joints[i].name;
            if !(q.is_finite() && v.is_finite()) {
                return format!("joint \"{name}\" is not finite (angle {q}, rate {v})");
            }
            if v.abs() > MAX_JOINT_SPEED {
                return format!(
                    "joint \"{name}\" turns at {v:.4e} rad/s, past {MAX_JOINT_SPEED} rad/s"
                );
            }
        }
        for (i, name) in self.world.objects.iter().enumerate() {
            let (pose, lin, ang) = self.world.object_state(i);
            if !(pose.is_finite() && lin.is_finite() && ang.is_finite()) {
                return format!("object \"{name}\" has a non-finite pose or twist");
            }
            if lin.norm() > MAX_SPEED_M_S {
                return format!(
                    "object \"{name}\" moves at {:.4e} m/s, past {MAX_SPEED_M_S} m/s",
                    lin.norm()
                );
            }
            if ang.norm() > MAX_SPIN_RAD_S {
                return format!(
                    "object \"{name}\" spins at {:.4e} rad/s, past {MAX_SPIN_RAD_S} rad/s",
                    ang.norm()
                );
            }
        }
        "the state is not finite".to_string()
    }

    /// Steps `n` times with the drives as last set and nothing else: no
    /// servo laws, no checks. The baseline of the controller-loop
    /// benchmark.
    pub fn step_raw(&mut self, n: u64) {
        let _guard = ode_guard(self.world.uses_ode);
        self.compute_drives();
        let [c, d, k, r] = &self.drives;
        if self.world.raw_mut().set_drives(c, d, k, r).is_ok()
            && self.world.raw_mut().step_raw(n).is_ok()
        {
            self.steps += n;
        }
        self.read_joints();
    }

    /// Contact points DART found in the last step.
    pub fn last_contact_count(&self) -> usize {
        self.world.raw().contact_count()
    }

    /// World pose of a URDF link's frame, by name (for tests and tools).
    pub fn link_pose(&self, name: &str) -> Option<Pose> {
        let &(body, offset) = self.world.links.get(name)?;
        Some(self.world.body_pose(body).compose(&offset))
    }

    /// Switches joint `i`'s actuator between DART's SERVO and FORCE.
    fn set_servo_actuator(&mut self, i: usize, servo: bool) -> Result<(), EngineError> {
        if self.servo_actuator[i] != servo {
            let limit = self.world.joints[i].force_limit;
            self.world
                .raw_mut()
                .set_actuator(i, servo, limit)
                .map_err(|e| usage_error(e.what().to_string()))?;
            self.servo_actuator[i] = servo;
        }
        Ok(())
    }

    /// The commands in force, for a state (empty: velocity targets only).
    pub(crate) fn servo_commands(&self) -> Vec<ServoCommand> {
        if self
            .commands
            .iter()
            .all(|c| c.kind == CommandKind::Velocity)
        {
            Vec::new()
        } else {
            self.commands.clone()
        }
    }

    /// The velocity targets in force (0 for a joint with another kind of
    /// command).
    pub(crate) fn velocity_targets(&self) -> Vec<f64> {
        self.commands
            .iter()
            .map(|c| {
                if c.kind == CommandKind::Velocity {
                    c.value
                } else {
                    0.0
                }
            })
            .collect()
    }
}

impl Simulation for DartSimulation {
    fn timestep_s(&self) -> f64 {
        self.settings.timestep_s
    }

    fn time_s(&self) -> f64 {
        self.time_origin_s + self.steps as f64 * self.settings.timestep_s
    }

    fn joint_count(&self) -> usize {
        self.world.joints.len()
    }

    fn tracked_count(&self) -> usize {
        self.world.tracked.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        let n = self.world.joints.len();
        if rad.len() != n {
            return Err(usage_error(format!(
                "{} joint angles given for {n} joints",
                rad.len()
            )));
        }
        if let Some(i) = rad.iter().position(|a| !a.is_finite()) {
            return Err(usage_error(format!(
                "the angle of joint \"{}\" is not finite",
                self.world.joints[i].name
            )));
        }
        let zeros = vec![0.0; n];
        self.world
            .raw_mut()
            .set_joint_state(rad, &zeros)
            .map_err(|e| usage_error(e.what().to_string()))?;
        self.read_joints();
        Ok(())
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        let servo = self.settings.servo == Servo::Servo;
        for (i, &v) in rad_s.iter().enumerate().take(self.commands.len()) {
            // Switching back to DART's SERVO actuator cannot fail for a
            // joint that had it at load.
            let _ = self.set_servo_actuator(i, servo);
            self.commands[i] = ServoCommand::velocity(v);
        }
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(ENGINE_NAME, &self.scene, commands)?;
        let servo = self.settings.servo == Servo::Servo;
        for (i, &c) in commands.iter().enumerate() {
            self.set_servo_actuator(i, servo && c.kind == CommandKind::Velocity)?;
            self.commands[i] = c;
        }
        Ok(())
    }

    fn step(&mut self) -> Result<(), EngineError> {
        let _guard = ode_guard(self.world.uses_ode);
        self.step_once()
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        let _guard = ode_guard(self.world.uses_ode);
        for _ in 0..n {
            self.step_once()?;
        }
        Ok(())
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        for (o, &q) in out.iter_mut().zip(&self.q) {
            *o = q;
        }
    }

    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        for (o, &v) in out.iter_mut().zip(&self.v) {
            *o = v;
        }
        Ok(())
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        for (o, t) in out.iter_mut().zip(&self.world.tracked) {
            *o = match *t {
                Tracked::Link { body, offset } => self.world.body_pose(body).compose(&offset),
                Tracked::Object(i) => self.world.object_state(i).0,
            };
        }
    }

    fn state(&self) -> Result<SimState, EngineError> {
        Ok(self.read_state())
    }

    fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        self.write_state(state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_names_dart_6_12() {
        assert!(
            DartEngine.version().starts_with("DART 6.12"),
            "{}",
            DartEngine.version()
        );
    }
}
