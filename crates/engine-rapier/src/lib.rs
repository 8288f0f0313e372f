//! The Rapier engine of realitygap: the pure-Rust physics engine
//! [Rapier](https://rapier.rs) (`rapier3d` 0.36, single precision), with the
//! robot as a multibody in reduced (joint) coordinates.
//!
//! [`RapierEngine`] implements [`realitygap_core::Engine`]. Loading a scene
//! runs the stages of [`assemble`]: rigid groups of links, bodies with the
//! URDF mass properties, colliders (primitives and STL meshes, see
//! [`shapes`]), multibody joints with force-based velocity motors, ground and
//! objects. The model is built from the [`RobotModel`] that every engine
//! shares rather than by `rapier3d-urdf`, so frames, inertias, held joints
//! and `package://` meshes are exactly those of the other engines (the crate
//! README says why `rapier3d-urdf` does not fit).
//!
//! The scene's velocity servo (torque `kv * (v_target - v)`, at most the
//! force limit) is Rapier's force-based joint motor with `damping = kv`,
//! target velocity `v_target`, stiffness 0 and maximum force = the limit. It
//! is solved implicitly, together with the contacts and limits, by Rapier's
//! projected Gauss-Seidel solver; the settings ([`settings::SETTINGS`]) pick
//! the timestep and how many solver and Gauss-Seidel iterations it runs.
//!
//! Rapier quarantines a body whose state turns non-finite (it freezes it at
//! its last valid pose and disables it); [`RapierSimulation`] reports that as
//! [`EngineError::Unstable`] rather than stepping on.
//!
//! Physical parameters: [`params`] lists the keys Rapier honours and how
//! each maps; they are applied at load. Simulation state: [`state`] reads
//! and sets it (portable, and native with the exact single-precision
//! values).

#![forbid(unsafe_code)]

pub mod assemble;
pub mod params;
pub mod settings;
pub mod shapes;
pub mod state;

use assemble::{from_rapier_pose, Assembly, BodyFrame, ControlledJoint};
use rapier3d::prelude::{PhysicsWorld, RigidBodyHandle};
use realitygap_core::engine::{
    check_servo_commands, CommandKind, CommandSupport, Engine, EngineError, EngineSettings,
    ModelVariation, ServoCommand, SettingInfo, SimState, Simulation,
};
use realitygap_core::params::{ParamSupport, PhysicalParams};
use realitygap_core::pose::Pose;
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use settings::RapierSettings;
use std::collections::HashMap;

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = "rapier";

/// The version of the `rapier3d` crate this engine is built with (pinned
/// exactly in Cargo.toml).
pub const RAPIER_VERSION: &str = "0.36.1";

/// The Rapier engine.
#[derive(Debug, Default, Clone, Copy)]
pub struct RapierEngine;

impl Engine for RapierEngine {
    fn name(&self) -> &'static str {
        ENGINE_NAME
    }

    fn version(&self) -> String {
        format!("Rapier {RAPIER_VERSION} (rapier3d, f32, multibody)")
    }

    fn default_timestep_s(&self) -> f64 {
        settings::DEFAULT_TIMESTEP_S
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        settings::SETTINGS.to_vec()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        Ok(RapierSettings::parse(settings)?.timestep_s)
    }

    fn param_support(&self) -> Vec<ParamSupport> {
        params::support()
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
        Ok(Box::new(RapierSimulation::load_with(
            scene, robot, settings, variation, params,
        )?))
    }
}

/// How Rapier takes each kind of joint command: the force-based joint
/// motor (solved implicitly with the contacts) for velocity and position,
/// and for efforts an equal and opposite torque (a force, for a prismatic
/// joint) on the two bodies the joint connects, set again before every
/// step as the joint's axis turns.
pub const COMMAND_SUPPORT: [CommandSupport; 3] = [
    CommandSupport {
        kind: CommandKind::Velocity,
        mechanism: "force-based joint motor: set_motor_velocity(v, damping = kv), stiffness 0, max force = the limit",
    },
    CommandSupport {
        kind: CommandKind::Position,
        mechanism: "force-based joint motor: set_motor(q, 0, stiffness = kp, damping = kv), max force = the limit",
    },
    CommandSupport {
        kind: CommandKind::Effort,
        mechanism: "motor off; the effort (clamped to the limit) as a torque pair on the joint's two bodies about its world axis (add_torque), before every step",
    },
];

/// A Rapier world of a scene, driven through [`Simulation`].
pub struct RapierSimulation {
    world: PhysicsWorld,
    /// The world as loaded, before the first step: [`Simulation::set_state`]
    /// starts from it, so a state set mid-run continues exactly as in a
    /// freshly loaded simulation.
    pristine: state::Pristine,
    joints: Vec<ControlledJoint>,
    tracked: Vec<BodyFrame>,
    links: HashMap<String, BodyFrame>,
    body_names: HashMap<RigidBodyHandle, String>,
    /// The scene objects: name and body, in the scene's order.
    objects: Vec<(String, RigidBodyHandle)>,
    settings: RapierSettings,
    /// Simulated time at the last [`Simulation::set_state`] (0 at load), s.
    time_origin_s: f64,
    /// Steps taken since then.
    steps: u64,
    /// The servo velocity targets in force, rad/s.
    targets: Vec<f64>,
    /// The commands in force when some joint's are not velocity targets;
    /// empty otherwise.
    commands: Vec<ServoCommand>,
    /// The scene, for checking commands.
    scene: Scene,
}

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

impl RapierSimulation {
    /// Builds the world of `scene` with `robot` (see [`assemble`]), configured
    /// by `settings` and changed by `variation`, at rest with every controlled
    /// joint at 0, without physical parameters.
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<RapierSimulation, EngineError> {
        Self::load_with(scene, robot, settings, variation, &PhysicalParams::none())
    }

    /// [`RapierSimulation::load`] with the engine-mapped keys of `params`
    /// (`armature`, `restitution`, `[contact]`) applied; `scene` and `robot`
    /// already carry the keys [`PhysicalParams::apply`] writes. A key that
    /// would have no effect on this model is an [`EngineError::Param`]
    /// ([`params::check`]).
    pub fn load_with(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        physical: &PhysicalParams,
    ) -> Result<RapierSimulation, EngineError> {
        let settings = RapierSettings::parse(settings)?;
        params::check(scene, robot, physical)?;
        let Assembly {
            world,
            joints,
            tracked,
            links,
            body_names,
            objects,
        } = assemble::assemble(scene, robot, &settings, variation, physical).map_err(|m| {
            load_error(format!(
                "{m} (robot {}, scene {})",
                robot.source.display(),
                scene.source.display()
            ))
        })?;
        let objects = scene
            .objects
            .iter()
            .map(|o| o.name.clone())
            .zip(objects)
            .collect();
        Ok(RapierSimulation {
            pristine: state::Pristine::of(&world),
            targets: vec![0.0; joints.len()],
            commands: Vec::new(),
            scene: scene.clone(),
            world,
            joints,
            tracked,
            links,
            body_names,
            objects,
            settings,
            time_origin_s: 0.0,
            steps: 0,
        })
    }

    /// The checked settings in force.
    pub fn settings(&self) -> &RapierSettings {
        &self.settings
    }

    /// The Rapier world (for tests and tools).
    pub fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    /// Steps `n` times with Rapier's pipeline and nothing else: no checks, no
    /// control. The baseline of the controller-loop benchmark.
    pub fn step_raw(&mut self, n: u64) {
        for _ in 0..n {
            self.world.step();
        }
        self.steps += n;
    }

    /// World pose of a URDF link's frame by name (for tests and tools).
    pub fn link_pose(&self, link: &str) -> Option<Pose> {
        self.links.get(link).map(|f| self.frame_pose(f))
    }

    /// The pairs of bodies touching now (one entry per collider pair with
    /// an active contact), by name: a robot body by the top link of its
    /// rigid group, `object:NAME` for a scene object, `ground`.
    pub fn contacts(&self) -> Vec<(String, String)> {
        let name = |c| {
            let body = self
                .world
                .colliders
                .get(c)
                .and_then(|c: &rapier3d::prelude::Collider| c.parent());
            body.and_then(|b| self.body_names.get(&b))
                .cloned()
                .unwrap_or_else(|| "?".to_string())
        };
        self.world
            .narrow_phase
            .contact_pairs()
            .filter(|pair| pair.has_any_active_contact())
            .map(|pair| (name(pair.collider1), name(pair.collider2)))
            .collect()
    }

    /// The Rapier world, to change it directly (for tests and tools: such
    /// changes are not part of the scene and are not recorded anywhere).
    pub fn world_mut(&mut self) -> &mut PhysicsWorld {
        &mut self.world
    }

    /// The Rapier body of a scene object, by the object's name.
    pub fn object_body(&self, object: &str) -> Option<rapier3d::prelude::RigidBodyHandle> {
        let key = format!("object:{object}");
        self.body_names
            .iter()
            .find(|(_, n)| **n == key)
            .map(|(&b, _)| b)
    }

    fn frame_pose(&self, frame: &BodyFrame) -> Pose {
        match self.world.bodies.get(frame.body) {
            Some(body) => {
                // Single-precision rotations compose to a norm a few 1e-7
                // off 1: renormalize (a non-finite one stays as it is).
                let pose = from_rapier_pose(body.position()).compose(&frame.offset);
                Pose::new(
                    pose.position_m,
                    pose.orientation.normalized().unwrap_or(pose.orientation),
                )
            }
            None => Pose::new(
                realitygap_core::pose::Vec3::new(f64::NAN, f64::NAN, f64::NAN),
                realitygap_core::pose::Quat::new(f64::NAN, f64::NAN, f64::NAN, f64::NAN),
            ),
        }
    }

    fn joint_coordinate(&self, joint: &ControlledJoint) -> f64 {
        match self.world.multibody_joints.get(joint.handle) {
            Some((mb, link)) => mb
                .link(link)
                .map_or(f64::NAN, |l| l.joint().coords()[joint.coordinate] as f64),
            None => f64::NAN,
        }
    }

    /// The commands in force, for a state (empty: the velocity targets).
    pub(crate) fn servo_commands(&self) -> Vec<ServoCommand> {
        self.commands.clone()
    }

    /// Sets the effort commands as torque (or force) pairs on the joints'
    /// bodies about their current world axes; clears the others' (every
    /// user force on the arm's bodies is the efforts').
    fn apply_efforts(&mut self) {
        if self.commands.is_empty() {
            return;
        }
        let bodies = &mut self.world.bodies;
        for joint in &self.joints {
            for h in [joint.parent_body, joint.child_body] {
                if let Some(b) = bodies.get_mut(h) {
                    b.reset_forces(false);
                    b.reset_torques(false);
                }
            }
        }
        for (joint, c) in self.joints.iter().zip(&self.commands) {
            if c.kind != CommandKind::Effort {
                continue;
            }
            let effort = c.value.clamp(-joint.force_limit, joint.force_limit) as f32;
            let Some((mb, link_id)) = self.world.multibody_joints.get(joint.handle) else {
                continue;
            };
            let Some(link) = mb.link(link_id) else {
                continue;
            };
            let frame2 = link.joint.data.local_frame2;
            let Some(child) = bodies.get(joint.child_body) else {
                continue;
            };
            let frame = *child.position() * frame2;
            let axis = frame.rotation * rapier3d::math::Vector::X;
            let anchor = frame.translation;
            let revolute = joint.axis == rapier3d::dynamics::JointAxis::AngX;
            for (h, sign) in [(joint.child_body, 1.0f32), (joint.parent_body, -1.0)] {
                if let Some(b) = bodies.get_mut(h) {
                    if revolute {
                        b.add_torque(axis * (sign * effort), true);
                    } else {
                        b.add_force_at_point(axis * (sign * effort), anchor, true);
                    }
                }
            }
        }
    }

    /// Unstable when Rapier quarantined anything during the last step.
    fn check_stability(&self) -> Result<(), EngineError> {
        let q = self.world.quarantine();
        if q.is_empty() {
            return Ok(());
        }
        Err(EngineError::Unstable {
            engine: ENGINE_NAME.to_string(),
            t_s: self.time_s(),
            message: format!(
                "Rapier found a non-finite state and disabled {} bodies and {} colliders",
                q.bodies().len(),
                q.colliders().len()
            ),
        })
    }
}

impl Simulation for RapierSimulation {
    fn timestep_s(&self) -> f64 {
        self.settings.timestep_s
    }

    fn time_s(&self) -> f64 {
        self.time_origin_s + self.steps as f64 * self.settings.timestep_s
    }

    fn joint_count(&self) -> usize {
        self.joints.len()
    }

    fn tracked_count(&self) -> usize {
        self.tracked.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        if rad.len() != self.joints.len() {
            return Err(usage_error(format!(
                "{} joint angles given for {} joints",
                rad.len(),
                self.joints.len()
            )));
        }
        if let Some(i) = rad.iter().position(|a| !a.is_finite()) {
            return Err(usage_error(format!(
                "the angle of joint \"{}\" is not finite",
                self.joints[i].name
            )));
        }
        let world = &mut self.world;
        for (joint, &target) in self.joints.iter().zip(rad) {
            let (mb, link_id) = world
                .multibody_joints
                .get_mut(joint.handle)
                .expect("controlled joints exist");
            let link = mb.link_mut(link_id).expect("controlled joints have a link");
            let current = link.joint.coords()[joint.coordinate];
            link.joint.apply_displacement(&[target as f32 - current]);
        }
        if let Some(joint) = self.joints.first() {
            let (mb, _) = world
                .multibody_joints
                .get_mut(joint.handle)
                .expect("controlled joints exist");
            mb.generalized_velocity_mut().fill(0.0);
            mb.forward_kinematics(&world.bodies, false);
            mb.update_rigid_bodies(&mut world.bodies, true);
        }
        Ok(())
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        for (t, &v) in self.targets.iter_mut().zip(rad_s) {
            *t = v;
        }
        let switching = !self.commands.is_empty();
        if switching {
            // Back from other kinds: no effort torques remain.
            self.commands = vec![ServoCommand::velocity(0.0); self.joints.len()];
            self.apply_efforts();
            self.commands.clear();
        }
        let world = &mut self.world;
        for (joint, &v) in self.joints.iter().zip(rad_s) {
            if let Some((mb, link_id)) = world.multibody_joints.get_mut(joint.handle) {
                if let Some(link) = mb.link_mut(link_id) {
                    let data = &mut link.joint.data;
                    if switching {
                        data.set_motor(joint.axis, 0.0, v as f32, 0.0, joint.kv);
                        data.set_motor_max_force(joint.axis, joint.max_motor_force());
                    } else {
                        data.set_motor_velocity(joint.axis, v as f32, joint.kv);
                    }
                }
            }
        }
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(ENGINE_NAME, &self.scene, commands)?;
        if commands.iter().all(|c| c.kind == CommandKind::Velocity) {
            let v: Vec<f64> = commands.iter().map(|c| c.value).collect();
            self.set_joint_velocity_targets(&v);
            return Ok(());
        }
        let world = &mut self.world;
        for (joint, c) in self.joints.iter().zip(commands) {
            let Some((mb, link_id)) = world.multibody_joints.get_mut(joint.handle) else {
                continue;
            };
            let Some(link) = mb.link_mut(link_id) else {
                continue;
            };
            let data = &mut link.joint.data;
            let value = c.value as f32;
            // An effort's motor is off (no force at all); the others' at
            // most the force limit.
            let max_force = match c.kind {
                CommandKind::Effort => 0.0,
                _ => joint.max_motor_force(),
            };
            match c.kind {
                CommandKind::Velocity => data.set_motor(joint.axis, 0.0, value, 0.0, joint.kv),
                CommandKind::Position => data.set_motor(joint.axis, value, 0.0, joint.kp, joint.kv),
                CommandKind::Effort => data.set_motor(joint.axis, 0.0, 0.0, 0.0, 0.0),
            };
            data.set_motor_max_force(joint.axis, max_force);
        }
        self.targets = commands
            .iter()
            .map(|c| {
                if c.kind == CommandKind::Velocity {
                    c.value
                } else {
                    0.0
                }
            })
            .collect();
        self.commands = commands.to_vec();
        self.apply_efforts();
        Ok(())
    }

    fn step(&mut self) -> Result<(), EngineError> {
        self.apply_efforts();
        self.world.step();
        self.steps += 1;
        self.check_stability()
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        for (o, joint) in out.iter_mut().zip(&self.joints) {
            *o = self.joint_coordinate(joint);
        }
    }

    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        // The multibody's generalized velocity directly: `state` also
        // serializes the native state.
        let qd = self.generalized_velocity();
        for (o, j) in out.iter_mut().zip(&self.joints) {
            *o = qd.get(j.dof).map_or(f64::NAN, |&v| v as f64);
        }
        Ok(())
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        for (o, frame) in out.iter_mut().zip(&self.tracked) {
            *o = self.frame_pose(frame);
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
    fn version_matches_the_pinned_dependency() {
        let manifest = include_str!("../Cargo.toml");
        assert!(
            manifest.contains(&format!("rapier3d = {{ version = \"={RAPIER_VERSION}\"")),
            "RAPIER_VERSION {RAPIER_VERSION} differs from the rapier3d version pinned in Cargo.toml"
        );
        assert!(RapierEngine.version().starts_with("Rapier 0.36.1"));
    }
}
