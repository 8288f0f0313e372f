//! The PhysX engine of realitygap: NVIDIA PhysX 5.1 (the physics of Isaac
//! Sim and Isaac Lab) through the `physx-sys` bindings, which build it from
//! source, with the robot as a reduced-coordinate articulation
//! (`PxArticulationReducedCoordinate`).
//!
//! [`PhysxEngine`] implements [`realitygap_core::Engine`]. Loading a scene
//! runs the stages of the `world` module: rigid groups of links from core's shared
//! planning, articulation links with the URDF mass properties, shapes
//! (primitives and STL meshes cooked as convex hulls, the `shapes` module),
//! revolute joints with limits and velocity drives, the ground plane and
//! the objects. The model is built from the [`RobotModel`] every engine
//! shares, not by a URDF loader of PhysX's own.
//!
//! The scene's velocity servo (torque `kv * (v_target - v)`, at most the
//! force limit) is the joint's articulation drive with stiffness 0, damping
//! `kv`, the force limit as its maximum force and `v_target` as its target
//! velocity, the mapping of MuJoCo's `kv` servo. PhysX solves it implicitly
//! with the joints, limits and contacts, by PGS or TGS ([`settings`]).
//!
//! Every simulation steps on its caller's thread (a CPU dispatcher without
//! worker threads), so runs are deterministic and parallel runs are
//! separate threads. PhysX's messages go to the `log` crate, never to
//! standard output (the `sdk` module). A non-finite joint or object state after a
//! step ends the run as [`EngineError::Unstable`], with what PhysX said.
//!
//! Physical parameters: [`params`] lists the keys PhysX honours and how
//! each maps. Simulation state: [`state`] reads and sets it.

pub mod params;
pub(crate) mod sdk;
pub mod settings;
pub(crate) mod shapes;
pub mod state;
pub(crate) mod world;

use physx_sys::*;
use realitygap_core::engine::{
    check_servo_commands, CommandKind, CommandSupport, Engine, EngineError, EngineSettings,
    ModelVariation, ServoCommand, SettingInfo, SimState, Simulation,
};
use realitygap_core::params::{ParamSupport, PhysicalParams};
use realitygap_core::pose::Pose;
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use settings::PhysxSettings;
use world::{from_px, ActorFrame, Recipe, World};

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = "physx";

/// The version of the `physx-sys` crate this engine is built with (pinned
/// exactly in Cargo.toml).
pub const PHYSX_SYS_VERSION: &str = "0.11.5";

/// The PhysX engine.
#[derive(Debug, Default, Clone, Copy)]
pub struct PhysxEngine;

impl Engine for PhysxEngine {
    fn name(&self) -> &'static str {
        ENGINE_NAME
    }

    fn version(&self) -> String {
        let (a, b, c) = sdk::PHYSX_VERSION;
        format!("PhysX {a}.{b}.{c} (physx-sys {PHYSX_SYS_VERSION}, CPU, articulation)")
    }

    fn default_timestep_s(&self) -> f64 {
        settings::DEFAULT_TIMESTEP_S
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        settings::SETTINGS.to_vec()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        Ok(PhysxSettings::parse(settings)?.timestep_s)
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
        Ok(Box::new(PhysxSimulation::load_with(
            scene, robot, settings, variation, params,
        )?))
    }
}

/// How PhysX takes each kind of joint command: the joint's articulation
/// drive (force type, solved implicitly) for velocity and position, and for
/// efforts the articulation cache's joint force (`applyCache` with
/// `eFORCE`, before every step), the drive then keeping only the joint's
/// viscous damping.
pub const COMMAND_SUPPORT: [CommandSupport; 3] = [
    CommandSupport {
        kind: CommandKind::Velocity,
        mechanism: "articulation drive: stiffness 0, damping kv, target velocity v, max force = the limit",
    },
    CommandSupport {
        kind: CommandKind::Position,
        mechanism: "articulation drive: stiffness kp, damping kv, target q, target velocity 0, max force = the limit",
    },
    CommandSupport {
        kind: CommandKind::Effort,
        mechanism: "articulation cache jointForce (applyCache eFORCE before every step), clamped to the limit; drive stiffness and gain 0",
    },
];

/// What a simulation was built from, kept to rebuild it
/// ([`Simulation::set_state`] starts from a fresh world).
struct Inputs {
    scene: Scene,
    robot: RobotModel,
    variation: ModelVariation,
    params: PhysicalParams,
}

/// A PhysX scene of a realitygap scene, driven through [`Simulation`].
pub struct PhysxSimulation {
    world: World,
    inputs: Inputs,
    settings: PhysxSettings,
    /// Simulated time at the last [`Simulation::set_state`] (0 at load), s.
    time_origin_s: f64,
    /// Steps taken since then.
    steps: u64,
    /// The servo velocity targets in force, rad/s.
    targets: Vec<f64>,
    /// The commands in force when some joint's are not velocity targets;
    /// empty otherwise.
    commands: Vec<ServoCommand>,
    /// Each controlled joint's first degree of freedom in the
    /// articulation cache (its child link's low-level order).
    dof_start: Vec<usize>,
}

// SAFETY: the PhysX objects of a simulation belong to it alone (its own
// scene, articulation, actors and dispatcher without threads); they are
// used only through `&mut self` or `&self` of this value, never from two
// threads at once. Shared SDK objects are used under the SDK lock.
unsafe impl Send for PhysxSimulation {}

pub(crate) fn load_error(message: impl Into<String>) -> EngineError {
    EngineError::Load {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

pub(crate) fn usage_error(message: impl Into<String>) -> EngineError {
    EngineError::Usage {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

impl PhysxSimulation {
    /// Builds the world of `scene` with `robot` (see the `world` module), configured
    /// by `settings` and changed by `variation`, with the engine-mapped keys
    /// of `params` (`armature`, `restitution`; `scene` and `robot` already
    /// carry the keys [`PhysicalParams::apply`] writes), at rest with every
    /// controlled joint at 0.
    pub fn load_with(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        physical: &PhysicalParams,
    ) -> Result<PhysxSimulation, EngineError> {
        let settings = PhysxSettings::parse(settings)?;
        params::check(scene, robot, physical)?;
        let inputs = Inputs {
            scene: scene.clone(),
            robot: robot.clone(),
            variation: *variation,
            params: physical.clone(),
        };
        let world = Self::build(&inputs, &settings)?;
        let mut sim = PhysxSimulation {
            targets: vec![0.0; world.drives.len()],
            commands: Vec::new(),
            dof_start: Vec::new(),
            world,
            inputs,
            settings,
            time_origin_s: 0.0,
            steps: 0,
        };
        // The links' poses from the joint state, as after a `set_state`.
        sim.update_kinematics();
        Ok(sim)
    }

    fn build(inputs: &Inputs, settings: &PhysxSettings) -> Result<World, EngineError> {
        world::build(&Recipe {
            scene: &inputs.scene,
            robot: &inputs.robot,
            settings,
            variation: &inputs.variation,
            params: &inputs.params,
        })
        .map_err(|m| {
            load_error(format!(
                "{m} (robot {}, scene {})",
                inputs.robot.source.display(),
                inputs.scene.source.display()
            ))
        })
    }

    /// [`PhysxSimulation::load_with`] without physical parameters.
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<PhysxSimulation, EngineError> {
        Self::load_with(scene, robot, settings, variation, &PhysicalParams::none())
    }

    /// The checked settings in force.
    pub fn settings(&self) -> &PhysxSettings {
        &self.settings
    }

    /// Steps `n` times with PhysX's `simulate`/`fetchResults` and nothing
    /// else: no checks, no control. The baseline of the controller-loop
    /// benchmark.
    pub fn step_raw(&mut self, n: u64) {
        for _ in 0..n {
            self.simulate();
        }
        self.steps += n;
    }

    fn simulate(&mut self) {
        // Shared with other scenes stepping, exclusive of any thread
        // building or releasing a world (see the sdk module).
        let _stepping = sdk::sdk().ok().map(|s| s.stepping());
        // SAFETY: the scene is valid and not simulating (every simulate is
        // followed by a blocking fetchResults).
        unsafe {
            PxScene_simulate_mut(
                self.world.scene,
                self.settings.timestep_s as f32,
                std::ptr::null_mut(),
                std::ptr::null_mut(),
                0,
                true,
            );
            let mut error = 0u32;
            PxScene_fetchResults_mut(self.world.scene, true, &mut error);
        }
    }

    /// World pose of a URDF link's frame by name (for tests and tools).
    pub fn link_pose(&self, link: &str) -> Option<Pose> {
        self.world.links.get(link).map(frame_pose)
    }

    /// The drive parameters PhysX holds for controlled joint `i`:
    /// (stiffness, damping, max force) (for tests and tools).
    pub fn drive_params(&self, i: usize) -> Option<(f32, f32, f32)> {
        let d = self.world.drives.get(i)?;
        // SAFETY: the joint belongs to this simulation's articulation.
        let p = unsafe { PxArticulationJointReducedCoordinate_getDriveParams(d.joint, d.axis) };
        Some((p.stiffness, p.damping, p.maxForce))
    }

    fn joint_position(&self, i: usize) -> f64 {
        let d = &self.world.drives[i];
        // SAFETY: the joint belongs to this simulation's articulation,
        // which is in its scene and not simulating.
        unsafe { PxArticulationJointReducedCoordinate_getJointPosition(d.joint, d.axis) as f64 }
    }

    fn joint_velocity(&self, i: usize) -> f64 {
        let d = &self.world.drives[i];
        // SAFETY: as in `joint_position`.
        unsafe { PxArticulationJointReducedCoordinate_getJointVelocity(d.joint, d.axis) as f64 }
    }

    /// Unstable when a joint or object state is not finite after a step.
    fn check_finite(&self) -> Result<(), EngineError> {
        let joint = (0..self.world.drives.len())
            .find(|&i| !(self.joint_position(i).is_finite() && self.joint_velocity(i).is_finite()));
        let object = self.world.objects.iter().position(|&o| {
            // SAFETY: the object belongs to this simulation's scene.
            let p = unsafe { PxRigidActor_getGlobalPose(o as *const PxRigidActor) };
            !from_px(&p).is_finite()
        });
        let what = match (joint, object) {
            (Some(i), _) => format!("joint \"{}\" is not finite", self.world.drives[i].name),
            (None, Some(i)) => format!(
                "object \"{}\" has a non-finite pose",
                self.inputs.scene.objects[i].name
            ),
            (None, None) => return Ok(()),
        };
        Err(EngineError::Unstable {
            engine: ENGINE_NAME.to_string(),
            t_s: self.time_s(),
            message: format!("{what}{}", sdk::said()),
        })
    }

    /// Recomputes the links' poses and velocities from the joint state.
    /// The commands in force, for a state (empty: the velocity targets).
    pub(crate) fn servo_commands(&self) -> Vec<ServoCommand> {
        self.commands.clone()
    }

    /// Sets drive `i` for `command` (see [`COMMAND_SUPPORT`]): its
    /// stiffness, damping and largest force, target and target velocity.
    fn set_drive(&self, i: usize, command: ServoCommand) {
        let d = &self.world.drives[i];
        let (stiffness, damping, max_force) = match command.kind {
            CommandKind::Velocity => (0.0, d.kv + d.damping, d.max_force),
            CommandKind::Position => (d.kp, d.kv + d.damping, d.max_force),
            CommandKind::Effort => (0.0, d.damping, f32::MAX as f64),
        };
        // With the servo off (limit 0) only the damping remains.
        let (stiffness, damping, max_force) = if d.max_force > 0.0 {
            (stiffness, damping, max_force)
        } else {
            (0.0, d.damping, f32::MAX as f64)
        };
        // SAFETY: the joint belongs to this simulation's articulation, in
        // its scene, not simulating.
        unsafe {
            let drive = PxArticulationDrive_new_1(
                stiffness as f32,
                damping as f32,
                max_force as f32,
                PxArticulationDriveType::Force,
            );
            PxArticulationJointReducedCoordinate_setDriveParams_mut(d.joint, d.axis, &drive);
            let (target, velocity) = match command.kind {
                CommandKind::Velocity => (0.0, d.target(command.value)),
                CommandKind::Position if d.max_force > 0.0 => (command.value as f32, 0.0),
                _ => (0.0, 0.0),
            };
            PxArticulationJointReducedCoordinate_setDriveTarget_mut(d.joint, d.axis, target, true);
            PxArticulationJointReducedCoordinate_setDriveVelocity_mut(
                d.joint, d.axis, velocity, true,
            );
        }
    }

    /// Each controlled joint's first degree of freedom in the articulation
    /// cache: the sum of the inbound joint DOFs of the links with lower
    /// low-level indices (PhysX's cache indexing).
    fn cache_dofs(&self) -> Vec<usize> {
        // SAFETY: the articulation and its joints belong to this
        // simulation's live world.
        unsafe {
            let a = self.world.articulation;
            let n = PxArticulationReducedCoordinate_getNbLinks(a) as usize;
            let mut links = vec![std::ptr::null_mut::<PxArticulationLink>(); n];
            PxArticulationReducedCoordinate_getLinks(a, links.as_mut_ptr(), n as u32, 0);
            let mut dofs = vec![0usize; n];
            for &l in &links {
                dofs[PxArticulationLink_getLinkIndex(l) as usize] =
                    PxArticulationLink_getInboundJointDof(l) as usize;
            }
            self.world
                .drives
                .iter()
                .map(|d| {
                    let child =
                        PxArticulationJointReducedCoordinate_getChildArticulationLink(d.joint);
                    let index = PxArticulationLink_getLinkIndex(child) as usize;
                    dofs[..index].iter().sum()
                })
                .collect()
        }
    }

    /// Writes the effort commands into the articulation cache's joint
    /// forces and applies them (every other DOF's force 0).
    fn apply_efforts(&mut self) {
        if !self.commands.iter().any(|c| c.kind == CommandKind::Effort) {
            return;
        }
        // SAFETY: the articulation is in its scene and not simulating; the
        // cache is this articulation's, its jointForce array holds
        // getDofs() numbers, and every index written is below that.
        unsafe {
            let a = self.world.articulation;
            if self.world.cache.is_null() {
                self.world.cache = PxArticulationReducedCoordinate_createCache(a);
                self.dof_start = self.cache_dofs();
            }
            let cache = self.world.cache;
            let dofs = PxArticulationReducedCoordinate_getDofs(a) as usize;
            let forces = std::slice::from_raw_parts_mut((*cache).jointForce, dofs);
            forces.fill(0.0);
            for ((c, d), &at) in self
                .commands
                .iter()
                .zip(&self.world.drives)
                .zip(&self.dof_start)
            {
                if c.kind == CommandKind::Effort && at < dofs {
                    let limit = if d.max_force > 0.0 { d.max_force } else { 0.0 };
                    forces[at] = c.value.clamp(-limit, limit) as f32;
                }
            }
            PxArticulationReducedCoordinate_applyCache_mut(
                a,
                cache,
                PxArticulationCacheFlags::Force,
                true,
            );
        }
    }

    fn update_kinematics(&mut self) {
        // SAFETY: the articulation is in its scene and not simulating.
        unsafe {
            PxArticulationReducedCoordinate_updateKinematic_mut(
                self.world.articulation,
                PxArticulationKinematicFlags::Position | PxArticulationKinematicFlags::Velocity,
            )
        };
    }
}

/// The world pose of a frame on an actor.
fn frame_pose(frame: &ActorFrame) -> Pose {
    // SAFETY: the actor belongs to a live world.
    let t = unsafe { PxRigidActor_getGlobalPose(frame.actor) };
    let pose = from_px(&t).compose(&frame.offset);
    // Single-precision rotations compose to a norm a few 1e-7 off 1:
    // renormalize (a non-finite one stays as it is).
    Pose::new(
        pose.position_m,
        pose.orientation.normalized().unwrap_or(pose.orientation),
    )
}

impl Simulation for PhysxSimulation {
    fn timestep_s(&self) -> f64 {
        self.settings.timestep_s
    }

    fn time_s(&self) -> f64 {
        self.time_origin_s + self.steps as f64 * self.settings.timestep_s
    }

    fn joint_count(&self) -> usize {
        self.world.drives.len()
    }

    fn tracked_count(&self) -> usize {
        self.world.tracked.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        if rad.len() != self.world.drives.len() {
            return Err(usage_error(format!(
                "{} joint angles given for {} joints",
                rad.len(),
                self.world.drives.len()
            )));
        }
        if let Some(i) = rad.iter().position(|a| !a.is_finite()) {
            return Err(usage_error(format!(
                "the angle of joint \"{}\" is not finite",
                self.world.drives[i].name
            )));
        }
        for (d, &a) in self.world.drives.iter().zip(rad) {
            // SAFETY: the joint belongs to this simulation's articulation.
            unsafe {
                PxArticulationJointReducedCoordinate_setJointPosition_mut(
                    d.joint, d.axis, a as f32,
                );
                PxArticulationJointReducedCoordinate_setJointVelocity_mut(d.joint, d.axis, 0.0);
            }
        }
        self.update_kinematics();
        Ok(())
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(ENGINE_NAME, &self.inputs.scene, commands)?;
        if commands.iter().all(|c| c.kind == CommandKind::Velocity) {
            let v: Vec<f64> = commands.iter().map(|c| c.value).collect();
            self.set_joint_velocity_targets(&v);
            return Ok(());
        }
        for (i, &c) in commands.iter().enumerate() {
            self.set_drive(i, c);
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
        Ok(())
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        if !self.commands.is_empty() {
            self.commands.clear();
            for (i, &v) in rad_s.iter().enumerate().take(self.world.drives.len()) {
                self.set_drive(i, ServoCommand::velocity(v));
            }
        }
        for ((t, d), &v) in self.targets.iter_mut().zip(&self.world.drives).zip(rad_s) {
            *t = v;
            // SAFETY: the joint belongs to this simulation's articulation.
            unsafe {
                PxArticulationJointReducedCoordinate_setDriveVelocity_mut(
                    d.joint,
                    d.axis,
                    d.target(v),
                    true,
                )
            };
        }
    }

    fn step(&mut self) -> Result<(), EngineError> {
        self.apply_efforts();
        self.simulate();
        self.steps += 1;
        self.check_finite()
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        for _ in 0..n {
            self.apply_efforts();
            self.simulate();
            self.steps += 1;
        }
        self.check_finite()
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        for (i, o) in out.iter_mut().enumerate().take(self.world.drives.len()) {
            *o = self.joint_position(i);
        }
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        for (o, frame) in out.iter_mut().zip(&self.world.tracked) {
            *o = frame_pose(frame);
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
            manifest.contains(&format!("physx-sys = \"={PHYSX_SYS_VERSION}\"")),
            "PHYSX_SYS_VERSION {PHYSX_SYS_VERSION} differs from Cargo.toml"
        );
        assert!(PhysxEngine.version().starts_with("PhysX 5.1.3"));
    }
}
