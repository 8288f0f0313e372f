//! The Bullet engine of realitygap: Bullet 3 (the physics of PyBullet),
//! driven through PyBullet's own C API (`PhysicsClientC_API.h`) in DIRECT
//! mode, as bundled and built from source by the `rubullet-sys` crate.
//!
//! [`BulletEngine`] implements [`realitygap_core::Engine`]. It builds the
//! world of a [`Scene`] the way a PyBullet script would, in this order:
//!
//! 1. the scene's gravity ([`Scene::gravity_m_s2`], default (0, 0, -9.81)
//!    m/s^2), a fixed timestep (default 0.01 s, the study's PyBullet), no
//!    substeps, and the solver settings of [`SETTINGS`];
//! 2. the ground: a static `GEOM_PLANE` collision shape at the scene's
//!    ground height (built here, no `pybullet_data` files needed);
//! 3. the robot: `loadURDF` with a fixed base at the scene's base pose, the
//!    URDF's inertias (`URDF_USE_INERTIA_FROM_FILE`), no self-collision
//!    (Bullet's default; the `self_collision` setting turns it on for
//!    non-neighbouring links). Mesh paths come from the [`RobotModel`]'s
//!    package resolver (see [`urdf_file`](crate#the-urdf-file-bullet-reads));
//! 4. the scene's objects: a `GEOM_BOX` collision shape in a
//!    `createMultiBody` of the object's mass (Bullet computes the box
//!    inertia) and pose;
//! 5. the joints: every controlled joint gets a `VELOCITY_CONTROL` motor
//!    with maximum force = the scene's force limit (or `max_force_n_m`) and
//!    velocity gain `velocity_gain`; every other movable joint is set to its
//!    held angle and locked there by a `POSITION_CONTROL` motor (position
//!    and velocity gains 1, force = its URDF effort limit).
//!
//! # The velocity servo in Bullet
//!
//! A scene's actuator is "a velocity servo with gain `kv` and a force
//! limit": torque `kv (v_target - v)`, clipped to the limit. Bullet has no
//! such actuator. Its velocity motor (`btMultiBodyJointMotor`) is a
//! constraint row solved together with the contacts: each step it asks for
//! the joint velocity `v + velocity_gain (v_target - v)` at the end of the
//! step and applies whatever torque that takes, up to the maximum force.
//! With the default `velocity_gain` 1 that is an infinitely stiff velocity
//! servo limited only by the force; its equivalent continuous gain,
//! `velocity_gain * I_eff / dt`, depends on the inertia the joint moves and
//! on the timestep, so `kv` (N m s/rad) has no analogue and is not used.
//! The force limit maps exactly (an infinite limit becomes 1e12 N m).
//!
//! # Physical parameters
//!
//! [`Engine::param_support`] lists the keys Bullet honours and how each
//! maps (joint damping, frictionloss with the servo off, force limit, link
//! mass scale, object mass, friction and restitution, contact softness);
//! `armature` (Bullet's multibodies have no rotor inertia) and `kv` (see
//! below) are not honoured, so core refuses them with an error. Every
//! parameter is applied while loading, never per step.
//!
//! # Simulation state
//!
//! [`Simulation::state`] carries Bullet's own serialization of the world
//! (contact manifolds included) for an exact same-engine restore, and the
//! portable fields for any engine; see the `state` module's documentation
//! in the source and the README.
//!
//! # The URDF file Bullet reads
//!
//! Bullet opens the URDF file and its meshes itself and does not know ROS
//! packages. When the robot has meshes, the engine writes a temporary copy
//! of the URDF in which every mesh file name is the absolute path the
//! [`RobotModel`] resolved (`package://` URIs included), loads it and
//! deletes it. A robot model whose `source` is not a file (read from a
//! string, such as the CLI's built-in Mico2) is written out from the model
//! itself (links, inertials, collision shapes, joints; no visuals). After
//! loading, every link that has collision shapes in the
//! URDF must have a collision shape in Bullet, and Bullet must not have
//! reported a mesh it could not read; otherwise loading fails with an error
//! naming the link and quoting Bullet.
//!
//! # Bullet's own output
//!
//! Bullet prints messages with `printf` unless hooks are installed; the
//! engine installs them ([`install_message_handler`]) before it creates a
//! world, so Bullet's messages go to the `log` crate (target `bullet`) and
//! into error messages, never to standard output. One Bullet feature that
//! prints unconditionally (switching the constraint solver type) is not
//! offered as a setting for that reason.
//!
//! # Threads
//!
//! Bullet keeps process-wide state, so every call into Bullet holds one
//! process-wide lock: simulations in several threads of one process take
//! turns. Run simulations in parallel in separate processes, as
//! `realitygap run` does.

#![warn(missing_docs)]

mod build;
mod ffi;
mod messages;
mod params;
mod settings;
mod state;
mod urdf_file;

pub use messages::{install_message_handler, take_messages, BulletMessage, Level};
pub use settings::{BulletSettings, PositionServo, SETTINGS};

use build::{
    apply_variation, check_mesh_messages, create_ground, create_objects, hold_joints, load_robot,
    motor_joints, set_physics, tracked_bodies, BulletModel,
};

use realitygap_core::engine::{
    check_servo_commands, CommandKind, CommandSupport, Engine, EngineError, EngineSettings,
    ModelVariation, ServoCommand, SettingInfo, SimState, Simulation,
};
use realitygap_core::params::{ParamSupport, PhysicalParams};
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::{Geometry, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene, TrackTarget};
use std::ffi::c_int;
use std::ptr;

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = "bullet";

/// The version of the Bullet sources `rubullet-sys` bundles and builds
/// (their `VERSION` file; PyBullet 3.0.8 was built from the same release).
pub const BULLET_VERSION: &str = "3.08";

/// PyBullet's C-API version of those sources
/// (`SHARED_MEMORY_MAGIC_NUMBER` in `SharedMemoryPublic.h`).
pub const BULLET_API_VERSION: i64 = 202010061;

/// The timestep used when the settings give none, s: the study's PyBullet
/// setting (PyBullet's own default is 1/240 s).
pub const DEFAULT_TIMESTEP_S: f64 = 0.01;

/// The motor force used for an unlimited (infinite) force limit, N m.
pub const UNLIMITED_FORCE_N_M: f64 = 1e12;

/// Force of the motor holding a non-controlled joint whose URDF gives no
/// effort limit, N m (PyBullet's default motor force).
pub const HELD_JOINT_DEFAULT_FORCE_N_M: f64 = 1e6;

fn load_error(message: impl Into<String>) -> EngineError {
    EngineError::Load {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

/// The Bullet engine.
#[derive(Debug, Default, Clone, Copy)]
pub struct BulletEngine;

impl Engine for BulletEngine {
    fn name(&self) -> &'static str {
        ENGINE_NAME
    }

    fn version(&self) -> String {
        format!("Bullet {BULLET_VERSION} (PyBullet C API {BULLET_API_VERSION}, rubullet-sys 0.1.0-alpha-2)")
    }

    fn default_timestep_s(&self) -> f64 {
        DEFAULT_TIMESTEP_S
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        SETTINGS.to_vec()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        Ok(BulletSettings::parse(settings)?.timestep_s)
    }

    fn param_support(&self) -> Vec<ParamSupport> {
        params::SUPPORT.to_vec()
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
        Ok(Box::new(BulletSimulation::load_with(
            scene, robot, settings, variation, params,
        )?))
    }
}

/// Bullet's physics parameters as the server reports them (for checks and
/// documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicsParameters {
    /// Fixed timestep, s.
    pub timestep_s: f64,
    /// Gravity, m/s^2.
    pub gravity_m_s2: [f64; 3],
    /// Constraint solver iterations per step.
    pub solver_iterations: i32,
    /// Residual below which the solver stops early.
    pub solver_residual_threshold: f64,
    /// Contact error reduction parameter.
    pub contact_erp: f64,
    /// Error reduction parameter of joint limits and motors.
    pub non_contact_erp: f64,
    /// Error reduction parameter of friction.
    pub friction_erp: f64,
    /// Global constraint force mixing.
    pub global_cfm: f64,
    /// Split impulse on or off.
    pub split_impulse: bool,
    /// Split impulse penetration threshold, m.
    pub split_impulse_penetration_threshold_m: f64,
    /// Contact breaking threshold, m.
    pub contact_breaking_threshold_m: f64,
    /// Cone friction on or off.
    pub cone_friction: bool,
}

/// How Bullet takes each kind of joint command, through PyBullet's own
/// control modes.
pub const COMMAND_SUPPORT: [CommandSupport; 3] = [
    CommandSupport {
        kind: CommandKind::Velocity,
        mechanism: "VELOCITY_CONTROL motor (a velocity constraint, gain velocity_gain; kv unused), max force = the limit",
    },
    CommandSupport {
        kind: CommandKind::Position,
        mechanism: "POSITION_CONTROL motor with positionGain = kp dt / kv, velocityGain 1: the constraint asks for (kp/kv)(q - angle), at most the limit (setting position_servo = \"pd_control\": PD_CONTROL, the explicit law kp (q - angle) - kv qd before every step)",
    },
    CommandSupport {
        kind: CommandKind::Effort,
        mechanism: "TORQUE_CONTROL (clamped effort) sent before every step; the velocity motor off",
    },
];

/// A controlled joint: its Bullet indices and motor force.
#[derive(Debug, Clone)]
pub(crate) struct MotorJoint {
    /// Bullet joint index.
    index: c_int,
    /// Index into the actual-state position array.
    q_index: usize,
    /// Index into the velocity array, also the motor's dof index.
    u_index: c_int,
    /// Maximum motor force, N m (or N).
    max_force: f64,
    /// Dry friction, N m (or N), when the servo is off and a `frictionloss`
    /// parameter is set: the motor then holds velocity 0 with this force.
    friction: Option<f64>,
    /// The PD law's position gain for position commands, N m/rad.
    kp: f64,
    /// The PD law's damping gain (the scene's `kv`), N m s/rad.
    kv: f64,
}

/// What a tracked body is in Bullet.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Tracked {
    /// A link of the robot other than its root: its Bullet link index.
    Link(c_int),
    /// The robot's root link: fixed at the base pose.
    Root(Pose),
    /// A scene object: index into `objects`.
    Object(usize),
}

/// A Bullet world built from a scene, driven through [`Simulation`].
pub struct BulletSimulation {
    client: ffi::Client,
    robot: c_int,
    ground: Option<c_int>,
    /// Body id of each scene object, in scene order.
    objects: Vec<c_int>,
    object_names: Vec<String>,
    /// URDF link name of each Bullet link index (the root link is -1).
    link_names: Vec<String>,
    root_link_name: String,
    timestep_s: f64,
    /// Steps since `time_origin_s`.
    steps: u64,
    /// Simulated time at step 0, s (0 after loading; set by `set_state`).
    time_origin_s: f64,
    velocity_gain: f64,
    position_servo: PositionServo,
    joints: Vec<MotorJoint>,
    /// Every movable joint that is not controlled: Bullet joint index and
    /// q/u index, its held position, rad (or m).
    held: Vec<HeldJoint>,
    tracked: Vec<Tracked>,
    targets_rad_s: Vec<f64>,
    targets_pending: bool,
    /// The commands in force when some joint's are not velocity targets;
    /// empty otherwise.
    commands: Vec<ServoCommand>,
    /// True while a joint may have a PD law of the pdControl plugin.
    pd_active: bool,
    /// The kinds of command the motors were last set for.
    kinds_sent: Vec<CommandKind>,
    /// The scene, for checking commands.
    scene: Scene,
    // The state after the last step (or reset).
    angles_rad: Vec<f64>,
    velocities_rad_s: Vec<f64>,
    /// Each object's pose, linear and angular velocity (world frame).
    object_states: Vec<(Pose, Vec3, Vec3)>,
    poses: Vec<Pose>,
    /// Largest |generalized velocity| seen at the last refresh, rad/s or m/s.
    max_speed: f64,
}

/// A movable joint without a servo, locked at its scene position.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeldJoint {
    /// Bullet joint index.
    index: c_int,
    /// Held position, rad (or m).
    position: f64,
}

/// The messages Bullet reported, for an error message.
fn bullet_said() -> String {
    let m = take_messages();
    let interesting: Vec<String> = m
        .iter()
        .filter(|m| m.level != Level::Info)
        .map(|m| m.text.clone())
        .collect();
    if interesting.is_empty() {
        String::new()
    } else {
        format!("; Bullet said: {}", interesting.join(" | "))
    }
}

/// The world pose of a link's URDF frame from its state: the centre-of-mass
/// frame composed with the inverse of the link's inertial frame, in double
/// precision. (`b3LinkState`'s own `m_worldLinkFrame*` fields are computed
/// by the C API with Bullet3Common's single-precision `b3Transform` in this
/// build, which would round positions to about 1e-7 m.)
fn link_frame(state: &ffi::b3LinkState) -> Pose {
    let pose = |p: [f64; 3], q: [f64; 4]| {
        Pose::new(
            Vec3::new(p[0], p[1], p[2]),
            Quat::new(q[3], q[0], q[1], q[2]),
        )
    };
    let com = pose(state.m_world_position, state.m_world_orientation);
    let inertial = pose(
        state.m_local_inertial_position,
        state.m_local_inertial_orientation,
    );
    let inverse_rotation = inertial.orientation.conjugate();
    let inverse = Pose::new(
        inverse_rotation.rotate(inertial.position_m).scale(-1.0),
        inverse_rotation,
    );
    com.compose(&inverse)
}

fn xyzw(q: Quat) -> [f64; 4] {
    [q.x, q.y, q.z, q.w]
}

impl BulletSimulation {
    /// Builds the Bullet world of `scene` with `robot` without physical
    /// parameters (see [`BulletSimulation::load_with`]).
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<BulletSimulation, EngineError> {
        Self::load_with(scene, robot, settings, variation, &PhysicalParams::none())
    }

    /// Builds the Bullet world of `scene` with `robot` (see the crate
    /// documentation), applies `settings`, `variation` and the keys of
    /// `params` this engine maps itself (frictionloss, restitution, contact
    /// softness; the others arrive through `scene` and `robot`, which carry
    /// what [`PhysicalParams::apply`] wrote), and puts it in its initial
    /// state. Everything is applied here, once; stepping costs the same.
    pub fn load_with(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        params: &PhysicalParams,
    ) -> Result<BulletSimulation, EngineError> {
        let options = BulletSettings::parse(settings)?;
        params.check_support(ENGINE_NAME, params::SUPPORT)?;
        params.check_fixed_base_masses(ENGINE_NAME, scene, robot)?;
        let contact = params::ContactPlan::new(scene, params)?;
        variation.check().map_err(load_error)?;
        for o in &scene.objects {
            o.check_shape().map_err(load_error)?;
        }
        install_message_handler();
        check_meshes(robot)?;
        let urdf = urdf_file::prepare(robot).map_err(load_error)?;
        let urdf_c_path = urdf.c_path().map_err(load_error)?;
        let lock = &ffi::lock();
        take_messages();
        let client = ffi::Client::connect(lock).ok_or_else(|| {
            load_error(format!(
                "cannot start a Bullet physics server{}",
                bullet_said()
            ))
        })?;
        set_physics(lock, &client, &options, scene.gravity_m_s2)?;
        let ground = create_ground(lock, &client, scene)?;
        let robot_id = load_robot(lock, &client, &options, scene, robot, &urdf_c_path)?;
        drop(urdf);
        let model = BulletModel::read(lock, &client, robot_id);
        check_mesh_messages(robot)?;
        check_colliders(lock, &client, robot_id, robot, &model.link_names)?;
        params::apply_robot_dynamics(lock, &client, robot_id, robot, &model)?;
        let (objects, object_names) = create_objects(lock, &client, scene)?;
        contact.apply(lock, &client, ground, robot_id, &model, &objects)?;
        let joints = motor_joints(scene, params, &options, &model, robot)?;
        let held = hold_joints(lock, &client, scene, robot_id, &model)?;
        if !variation.is_identity() {
            apply_variation(lock, &client, variation, robot_id, &model, &objects, ground)?;
        }
        let root_link_name = robot.links[robot.root_link].name.clone();
        let tracked = tracked_bodies(scene, robot, &root_link_name, &model, &object_names)?;
        let n = joints.len();
        let mut sim = BulletSimulation {
            client,
            robot: robot_id,
            ground,
            objects,
            object_names,
            link_names: model.link_names,
            root_link_name,
            timestep_s: options.timestep_s,
            steps: 0,
            time_origin_s: 0.0,
            velocity_gain: options.velocity_gain,
            position_servo: options.position_servo,
            joints,
            held,
            tracked,
            targets_rad_s: vec![0.0; n],
            targets_pending: true,
            commands: Vec::new(),
            pd_active: false,
            kinds_sent: Vec::new(),
            scene: scene.clone(),
            angles_rad: vec![0.0; n],
            velocities_rad_s: vec![0.0; n],
            object_states: vec![(Pose::IDENTITY, Vec3::ZERO, Vec3::ZERO); scene.objects.len()],
            poses: vec![Pose::IDENTITY; scene.tracked.len()],
            max_speed: 0.0,
        };
        sim.send_targets(lock)
            .and_then(|()| sim.refresh(lock))
            .map_err(|e| load_error(e.to_string()))?;
        for m in take_messages() {
            if m.level == Level::Error {
                return Err(load_error(format!(
                    "Bullet reported an error while loading {}: {}",
                    robot.source.display(),
                    m.text
                )));
            }
        }
        Ok(sim)
    }

    /// Sends the commands to the joints (see [`COMMAND_SUPPORT`]): the
    /// velocity targets to the motors (a joint with a dry friction instead
    /// of a servo holds velocity 0 with the friction force; a joint with a
    /// position or effort command has its motor off), and the PD laws of
    /// position commands to the pdControl plugin (removed from the other
    /// joints). Needs the Bullet lock (`lock`). A failure means the
    /// simulation can no longer be driven: [`EngineError::Unstable`].
    fn send_targets(&mut self, lock: &ffi::BulletLock) -> Result<(), EngineError> {
        let h = self.client.handle(lock);
        let kind_of = |i: usize| {
            self.commands
                .get(i)
                .map_or(CommandKind::Velocity, |c: &ServoCommand| c.kind)
        };
        let pd = self.position_servo == PositionServo::PdControl;
        if self.pd_active || (pd && !self.commands.is_empty()) {
            // SAFETY: the command is created on this client and submitted
            // once, with the lock held.
            let kind = unsafe {
                let cmd = ffi::b3JointControlCommandInit2(h, self.robot, ffi::CONTROL_MODE_PD);
                for (i, joint) in self.joints.iter().enumerate() {
                    if pd && kind_of(i) == CommandKind::Position {
                        ffi::b3JointControlSetDesiredPosition(
                            cmd,
                            joint.q_index as c_int,
                            self.commands[i].value,
                        );
                        ffi::b3JointControlSetKp(cmd, joint.u_index, joint.kp);
                        ffi::b3JointControlSetKd(cmd, joint.u_index, joint.kv);
                        ffi::b3JointControlSetMaximumForce(cmd, joint.u_index, joint.max_force);
                    } else {
                        // A zero maximum force removes the joint's PD law.
                        ffi::b3JointControlSetDesiredVelocity(cmd, joint.u_index, 0.0);
                        ffi::b3JointControlSetMaximumForce(cmd, joint.u_index, 0.0);
                    }
                }
                self.client.submit(lock, cmd).kind
            };
            check_status(
                kind,
                ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
                "sending the PD laws",
            )
            .map_err(|m| self.unstable(m))?;
            self.pd_active = pd
                && self
                    .commands
                    .iter()
                    .any(|c| c.kind == CommandKind::Position);
        }
        // The velocity command, unless every joint's motor is a position
        // motor already (a replay of position commands changes only the
        // targets, ten times in a hundred steps).
        let kinds: Vec<CommandKind> = (0..self.joints.len()).map(kind_of).collect();
        let only_positions = !pd && kinds.iter().all(|&k| k == CommandKind::Position);
        if !(only_positions && kinds == self.kinds_sent) {
            self.send_velocities(lock, &kind_of, pd)?;
        }
        self.kinds_sent = kinds;
        if !pd
            && self
                .commands
                .iter()
                .any(|c| c.kind == CommandKind::Position)
        {
            // POSITION_CONTROL: the motor's constraint asks for the joint
            // velocity positionGain (q - angle) / dt at the end of the step;
            // positionGain = kp dt / kv makes it (kp / kv)(q - angle), the
            // PD law's velocity with the damping term made exact.
            // SAFETY: the command is created on this client and submitted
            // once, with the lock held.
            let kind = unsafe {
                let cmd = ffi::b3JointControlCommandInit2(
                    h,
                    self.robot,
                    ffi::CONTROL_MODE_POSITION_VELOCITY_PD,
                );
                for (i, joint) in self.joints.iter().enumerate() {
                    if kind_of(i) != CommandKind::Position {
                        continue;
                    }
                    let gain = if joint.kv > 0.0 {
                        (joint.kp * self.timestep_s / joint.kv).min(1.0)
                    } else {
                        1.0
                    };
                    ffi::b3JointControlSetDesiredPosition(
                        cmd,
                        joint.q_index as c_int,
                        self.commands[i].value,
                    );
                    ffi::b3JointControlSetKp(cmd, joint.u_index, gain);
                    ffi::b3JointControlSetDesiredVelocity(cmd, joint.u_index, 0.0);
                    ffi::b3JointControlSetKd(cmd, joint.u_index, 1.0);
                    ffi::b3JointControlSetMaximumForce(cmd, joint.u_index, joint.max_force);
                }
                self.client.submit(lock, cmd).kind
            };
            check_status(
                kind,
                ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
                "sending the position targets",
            )
            .map_err(|m| self.unstable(m))?;
        }
        self.targets_pending = false;
        Ok(())
    }

    /// Reads the joint angles and velocities, the objects' states and the
    /// tracked poses. Needs the Bullet lock (`lock`). Bullet recomputes the link
    /// frames from the joint positions first: the frames it keeps are those
    /// of the collision detection, one position update behind after a step
    /// (3 mm at the wrist in scene 1). A failure means the state is
    /// unusable: [`EngineError::Unstable`].
    fn refresh(&mut self, lock: &ffi::BulletLock) -> Result<(), EngineError> {
        let h = self.client.handle(lock);
        let mut max_speed: f64 = 0.0;
        let mut track = |v: &[f64]| {
            for x in v {
                max_speed = max_speed.max(if x.is_finite() {
                    x.abs()
                } else {
                    f64::INFINITY
                });
            }
        };
        // SAFETY: the commands are created on this client and submitted once,
        // with the Bullet lock held (`lock`); the state arrays are read within the sizes
        // Bullet reported, before the next command is submitted.
        unsafe {
            let cmd = ffi::b3RequestActualStateCommandInit(h, self.robot);
            ffi::b3RequestActualStateCommandComputeForwardKinematics(cmd, 1);
            let r = self.client.submit(lock, cmd);
            check_status(
                r.kind,
                ffi::CMD_ACTUAL_STATE_UPDATE_COMPLETED,
                "reading the robot's state",
            )
            .map_err(|m| self.unstable(m))?;
            let (q, qdot) = actual_state(&r).map_err(|m| self.unstable(m))?;
            for (i, joint) in self.joints.iter().enumerate() {
                self.angles_rad[i] = q.get(joint.q_index).copied().unwrap_or(f64::NAN);
                self.velocities_rad_s[i] = qdot
                    .get(joint.u_index as usize)
                    .copied()
                    .unwrap_or(f64::NAN);
            }
            track(qdot);
            for (out, t) in self.poses.iter_mut().zip(&self.tracked) {
                match *t {
                    Tracked::Link(l) => {
                        let mut state = ffi::b3LinkState::default();
                        if ffi::b3GetLinkState(h, r.handle(), l, &mut state) == 0 {
                            return Err(unstable_at(
                                self.steps,
                                self.timestep_s,
                                self.time_origin_s,
                                format!("Bullet gave no state for link {l}"),
                            ));
                        }
                        *out = link_frame(&state);
                    }
                    Tracked::Root(pose) => *out = pose,
                    Tracked::Object(_) => {}
                }
            }
            for (i, &body) in self.objects.iter().enumerate() {
                let r = self
                    .client
                    .submit(lock, ffi::b3RequestActualStateCommandInit(h, body));
                let read = check_status(
                    r.kind,
                    ffi::CMD_ACTUAL_STATE_UPDATE_COMPLETED,
                    "reading an object's state",
                )
                .and_then(|()| actual_state(&r));
                let (q, qdot) = match read {
                    Ok((q, qdot)) if q.len() >= 7 && qdot.len() >= 6 => (q, qdot),
                    Ok((q, _)) => {
                        return Err(self.unstable(format!(
                            "Bullet gave {} state values for object \"{}\"",
                            q.len(),
                            self.object_names[i]
                        )))
                    }
                    Err(m) => return Err(self.unstable(m)),
                };
                let pose = Pose::new(
                    Vec3::new(q[0], q[1], q[2]),
                    Quat::new(q[6], q[3], q[4], q[5]),
                );
                self.object_states[i] = (
                    pose,
                    Vec3::new(qdot[0], qdot[1], qdot[2]),
                    Vec3::new(qdot[3], qdot[4], qdot[5]),
                );
                track(qdot);
                for (out, t) in self.poses.iter_mut().zip(&self.tracked) {
                    if matches!(*t, Tracked::Object(k) if k == i) {
                        *out = pose;
                    }
                }
            }
        }
        self.max_speed = max_speed;
        Ok(())
    }

    fn unstable(&self, message: String) -> EngineError {
        unstable_at(self.steps, self.timestep_s, self.time_origin_s, message)
    }

    /// An instability Bullet papers over: a generalized velocity at Bullet's
    /// clamp, or not finite.
    fn check_stability(&self) -> Result<(), EngineError> {
        if !self.max_speed.is_finite() {
            return Err(self.unstable("a velocity is not finite".into()));
        }
        if self.max_speed >= ffi::MAX_COORDINATE_VELOCITY * (1.0 - 1e-9) {
            return Err(self.unstable(format!(
                "a velocity reached Bullet's clamp of {} rad/s (m/s): the simulation blew up",
                ffi::MAX_COORDINATE_VELOCITY
            )));
        }
        Ok(())
    }

    /// Steps Bullet `n` times, sending the velocity targets set since the
    /// last step first, without reading the state back: the raw stepping
    /// loop of the benchmark. The reported joint angles and poses are not
    /// updated (they are again after the next [`Simulation::step_n`]).
    pub fn step_raw(&mut self, n: u64) -> Result<(), EngineError> {
        let lock = &ffi::lock();
        if self.targets_pending {
            self.send_targets(lock)?;
        }
        for _ in 0..n {
            self.step_once(lock)?;
        }
        Ok(())
    }

    /// Sends the velocity motors' command: the velocity targets, the dry
    /// friction of a joint without a servo, every other motor off (a
    /// position motor is set apart). Needs the Bullet lock (`lock`).
    fn send_velocities(
        &self,
        lock: &ffi::BulletLock,
        kind_of: &dyn Fn(usize) -> CommandKind,
        pd: bool,
    ) -> Result<(), EngineError> {
        let h = self.client.handle(lock);
        // SAFETY: the command is created on this client and
        // submitted once, with the lock held.
        let kind = unsafe {
            let cmd = ffi::b3JointControlCommandInit2(h, self.robot, ffi::CONTROL_MODE_VELOCITY);
            for (i, (joint, &v)) in self.joints.iter().zip(&self.targets_rad_s).enumerate() {
                let (target, gain, force) = match (kind_of(i), joint.friction) {
                    // The position motor is set below.
                    (CommandKind::Position, _) if !pd => continue,
                    (CommandKind::Position | CommandKind::Effort, _) => (0.0, 1.0, 0.0),
                    (CommandKind::Velocity, Some(f)) => (0.0, 1.0, f),
                    (CommandKind::Velocity, None) => (v, self.velocity_gain, joint.max_force),
                };
                ffi::b3JointControlSetDesiredVelocity(cmd, joint.u_index, target);
                ffi::b3JointControlSetKd(cmd, joint.u_index, gain);
                ffi::b3JointControlSetMaximumForce(cmd, joint.u_index, force);
            }
            self.client.submit(lock, cmd).kind
        };
        check_status(
            kind,
            ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
            "sending the motor targets",
        )
        .map_err(|m| self.unstable(m))
    }

    /// Sends the effort commands as joint torques for the next step
    /// (Bullet clears them after each). Needs the Bullet lock (`lock`).
    fn send_efforts(&mut self, lock: &ffi::BulletLock) -> Result<(), EngineError> {
        if !self.commands.iter().any(|c| c.kind == CommandKind::Effort) {
            return Ok(());
        }
        let h = self.client.handle(lock);
        // SAFETY: the command is created on this client and submitted once,
        // with the Bullet lock held (`lock`).
        let kind = unsafe {
            let cmd = ffi::b3JointControlCommandInit2(h, self.robot, ffi::CONTROL_MODE_TORQUE);
            for (joint, c) in self.joints.iter().zip(&self.commands) {
                if c.kind == CommandKind::Effort {
                    let limit = joint.max_force;
                    ffi::b3JointControlSetDesiredForceTorque(
                        cmd,
                        joint.u_index,
                        c.value.clamp(-limit, limit),
                    );
                }
            }
            self.client.submit(lock, cmd).kind
        };
        check_status(
            kind,
            ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
            "sending the joint torques",
        )
        .map_err(|m| self.unstable(m))
    }

    fn step_once(&mut self, lock: &ffi::BulletLock) -> Result<(), EngineError> {
        self.send_efforts(lock)?;
        // SAFETY: the command is created on this client and submitted once,
        // with the Bullet lock held (`lock`).
        let kind = unsafe {
            self.client
                .submit(
                    lock,
                    ffi::b3InitStepSimulationCommand(self.client.handle(lock)),
                )
                .kind
        };
        if kind != ffi::CMD_STEP_FORWARD_SIMULATION_COMPLETED {
            return Err(self.unstable(format!(
                "Bullet did not step ({}){}",
                ffi::status_name(kind),
                bullet_said()
            )));
        }
        self.steps += 1;
        Ok(())
    }

    /// The pairs of bodies in contact now, by name: robot links by their
    /// URDF name, objects as `object:NAME`, the ground as `ground`.
    pub fn contacts(&mut self) -> Result<Vec<(String, String)>, EngineError> {
        let lock = &ffi::lock();
        let h = self.client.handle(lock);
        let mut pairs = Vec::new();
        // SAFETY: the command is created on this client and submitted once,
        // with the Bullet lock held; the contact array is read within the count
        // Bullet reported.
        unsafe {
            let r = self
                .client
                .submit(lock, ffi::b3InitRequestContactPointInformation(h));
            expect(
                r.kind,
                ffi::CMD_CONTACT_POINT_INFORMATION_COMPLETED,
                "reading the contacts",
            )?;
            let mut info = ffi::b3ContactInformation {
                m_numContactPoints: 0,
                m_contactPointData: ptr::null_mut(),
            };
            ffi::b3GetContactPointInformation(h, &mut info);
            if !info.m_contactPointData.is_null() {
                let points = std::slice::from_raw_parts(
                    info.m_contactPointData,
                    info.m_numContactPoints.max(0) as usize,
                );
                for c in points {
                    pairs.push((
                        self.body_name(c.m_bodyUniqueIdA, c.m_linkIndexA),
                        self.body_name(c.m_bodyUniqueIdB, c.m_linkIndexB),
                    ));
                }
            }
        }
        pairs.sort();
        pairs.dedup();
        Ok(pairs)
    }

    fn body_name(&self, body: c_int, link: c_int) -> String {
        if body == self.robot {
            if link < 0 {
                self.root_link_name.clone()
            } else {
                self.link_names
                    .get(link as usize)
                    .cloned()
                    .unwrap_or_else(|| format!("link {link}"))
            }
        } else if Some(body) == self.ground {
            "ground".into()
        } else if let Some(i) = self.objects.iter().position(|&b| b == body) {
            format!("object:{}", self.object_names[i])
        } else {
            format!("body {body}")
        }
    }

    /// World pose of the frame of the robot link called `name` (URDF
    /// convention), or `None` when the robot has no such link.
    pub fn link_pose(&mut self, name: &str) -> Result<Option<Pose>, EngineError> {
        let lock = &ffi::lock();
        let Some(l) = self.link_names.iter().position(|n| n == name) else {
            return Ok(None);
        };
        let h = self.client.handle(lock);
        // SAFETY: the command is created on this client and submitted once,
        // with the Bullet lock held (`lock`).
        unsafe {
            let cmd = ffi::b3RequestActualStateCommandInit(h, self.robot);
            ffi::b3RequestActualStateCommandComputeForwardKinematics(cmd, 1);
            let r = self.client.submit(lock, cmd);
            expect(
                r.kind,
                ffi::CMD_ACTUAL_STATE_UPDATE_COMPLETED,
                "reading the robot's state",
            )?;
            let mut state = ffi::b3LinkState::default();
            if ffi::b3GetLinkState(h, r.handle(), l as c_int, &mut state) == 0 {
                return Ok(None);
            }
            Ok(Some(link_frame(&state)))
        }
    }

    /// Mass (kg) and lateral friction coefficient of a robot link (by URDF
    /// name) or of a scene object (`object:NAME`) as Bullet holds them.
    pub fn mass_and_friction(&mut self, name: &str) -> Result<Option<(f64, f64)>, EngineError> {
        let lock = &ffi::lock();
        let target = if let Some(object) = name.strip_prefix("object:") {
            self.object_names
                .iter()
                .position(|n| n == object)
                .map(|i| (self.objects[i], -1))
        } else if name == self.root_link_name {
            Some((self.robot, -1))
        } else {
            self.link_names
                .iter()
                .position(|n| n == name)
                .map(|l| (self.robot, l as c_int))
        };
        match target {
            None => Ok(None),
            Some((body, link)) => {
                let info = dynamics_info(lock, &self.client, body, link)?;
                Ok(Some((info.m_mass, info.m_lateralFrictionCoeff)))
            }
        }
    }

    /// The physics parameters Bullet is using.
    pub fn physics_parameters(&mut self) -> Result<PhysicsParameters, EngineError> {
        let lock = &ffi::lock();
        let h = self.client.handle(lock);
        let mut p = ffi::b3PhysicsSimulationParameters::default();
        // SAFETY: the command is created on this client and submitted once,
        // with the Bullet lock held; `p` has the C layout (checked by a test).
        unsafe {
            let r = self
                .client
                .submit(lock, ffi::b3InitRequestPhysicsParamCommand(h));
            expect(
                r.kind,
                ffi::CMD_REQUEST_PHYSICS_SIMULATION_PARAMETERS_COMPLETED,
                "reading the physics parameters",
            )?;
            ffi::b3GetStatusPhysicsSimulationParameters(r.handle(), &mut p);
        }
        Ok(PhysicsParameters {
            timestep_s: p.m_deltaTime,
            gravity_m_s2: p.m_gravityAcceleration,
            solver_iterations: p.m_numSolverIterations,
            solver_residual_threshold: p.m_solverResidualThreshold,
            contact_erp: p.m_defaultContactERP,
            non_contact_erp: p.m_defaultNonContactERP,
            friction_erp: p.m_frictionERP,
            global_cfm: p.m_defaultGlobalCFM,
            split_impulse: p.m_useSplitImpulse != 0,
            split_impulse_penetration_threshold_m: p.m_splitImpulsePenetrationThreshold,
            contact_breaking_threshold_m: p.m_contactBreakingThreshold,
            cone_friction: p.m_enableConeFriction != 0,
        })
    }
}

/// Fails with a message naming `what` when Bullet answered `kind` instead
/// of `expected`.
/// (While loading: an [`EngineError::Load`].)
fn expect(kind: c_int, expected: c_int, what: &str) -> Result<(), EngineError> {
    check_status(kind, expected, what).map_err(load_error)
}

/// The message for Bullet answering `kind` instead of `expected` to the
/// command doing `what`, with what Bullet said.
fn check_status(kind: c_int, expected: c_int, what: &str) -> Result<(), String> {
    if kind == expected {
        Ok(())
    } else {
        Err(format!(
            "Bullet failed {what} ({}){}",
            ffi::status_name(kind),
            bullet_said()
        ))
    }
}

/// An [`EngineError::Unstable`] at the time of step `steps` after
/// `origin_s`.
fn unstable_at(steps: u64, timestep_s: f64, origin_s: f64, message: String) -> EngineError {
    EngineError::Unstable {
        engine: ENGINE_NAME.to_string(),
        t_s: origin_s + steps as f64 * timestep_s,
        message,
    }
}

/// The position and velocity arrays of an actual-state reply.
///
/// # Safety
/// `reply` must be the latest reply of its client and of type
/// CMD_ACTUAL_STATE_UPDATE_COMPLETED. The slices borrow the reply, which
/// borrows its client and the lock; they are valid until the next command.
unsafe fn actual_state<'r>(reply: &'r ffi::Reply<'_>) -> Result<(&'r [f64], &'r [f64]), String> {
    let (mut nq, mut nu) = (0, 0);
    let (mut q, mut qdot): (*const f64, *const f64) = (ptr::null(), ptr::null());
    // SAFETY: `reply` is the latest actual-state reply of its client (this
    // fn's contract); the out-pointers are locals or null where unused.
    let ok = unsafe {
        ffi::b3GetStatusActualState(
            reply.handle(),
            ptr::null_mut(),
            &mut nq,
            &mut nu,
            ptr::null_mut(),
            &mut q,
            &mut qdot,
            ptr::null_mut(),
        )
    };
    if ok == 0 || q.is_null() || qdot.is_null() {
        return Err("Bullet returned no state".to_string());
    }
    // SAFETY: Bullet reports `nq` positions at `q` and `nu` velocities at
    // `qdot`, valid until the client's next command (this fn's contract).
    Ok(unsafe {
        (
            std::slice::from_raw_parts(q, nq.max(0) as usize),
            std::slice::from_raw_parts(qdot, nu.max(0) as usize),
        )
    })
}

/// Creates a single-body multibody with a collision shape. Needs the Bullet lock (`lock`).
fn create_body(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    mass_kg: f64,
    shape: c_int,
    pose: Pose,
    what: &str,
) -> Result<c_int, EngineError> {
    let p = pose.position_m.to_array();
    let q = xyzw(pose.orientation);
    let inertial_p = [0.0; 3];
    let inertial_q = [0.0, 0.0, 0.0, 1.0];
    // SAFETY: the command is created on `client` and submitted once,
    // with the Bullet lock held (`lock`).
    unsafe {
        let cmd = ffi::b3CreateMultiBodyCommandInit(client.handle(lock));
        ffi::b3CreateMultiBodyBase(
            cmd,
            mass_kg,
            shape,
            -1,
            p.as_ptr(),
            q.as_ptr(),
            inertial_p.as_ptr(),
            inertial_q.as_ptr(),
        );
        let r = client.submit(lock, cmd);
        expect(
            r.kind,
            ffi::CMD_CREATE_MULTI_BODY_COMPLETED,
            &format!("creating {what}"),
        )?;
        Ok(ffi::b3GetStatusBodyIndex(r.handle()))
    }
}

/// Sets the lateral friction coefficient of a body's link. Needs the Bullet lock (`lock`).
fn set_friction(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    body: c_int,
    link: c_int,
    friction: f64,
) -> Result<(), EngineError> {
    // SAFETY: the command is created on `client` and submitted once,
    // with the Bullet lock held (`lock`).
    unsafe {
        let cmd = ffi::b3InitChangeDynamicsInfo(client.handle(lock));
        ffi::b3ChangeDynamicsInfoSetLateralFriction(cmd, body, link, friction);
        expect(
            client.submit(lock, cmd).kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "setting a friction coefficient",
        )
    }
}

/// The dynamics of a body's link. Needs the Bullet lock (`lock`).
fn dynamics_info(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    body: c_int,
    link: c_int,
) -> Result<ffi::b3DynamicsInfo, EngineError> {
    // SAFETY: the command is created on `client` and submitted once,
    // with the Bullet lock held; b3DynamicsInfo has the C layout
    // (checked by a test) and is plain data, so zeroed is a valid value.
    unsafe {
        let r = client.submit(
            lock,
            ffi::b3GetDynamicsInfoCommandInit(client.handle(lock), body, link),
        );
        expect(
            r.kind,
            ffi::CMD_GET_DYNAMICS_INFO_COMPLETED,
            "reading masses and frictions",
        )?;
        let mut info: ffi::b3DynamicsInfo = std::mem::zeroed();
        ffi::b3GetDynamicsInfo(r.handle(), &mut info);
        Ok(info)
    }
}

/// Checks the robot's collision meshes before Bullet reads them: Bullet
/// replaces a mesh it cannot read by an empty shape, with at most a
/// warning (none at all for a Wavefront OBJ file without geometry), so a
/// damaged file is caught here with a precise message: STL, OBJ and
/// COLLADA files are read in full by realitygap's reader (COLLADA files
/// then reach Bullet as STL: see `urdf_file`); other formats are left to
/// Bullet (whose warnings are checked after loading).
fn check_meshes(robot: &RobotModel) -> Result<(), EngineError> {
    for link in &robot.links {
        for c in &link.collisions {
            let Geometry::Mesh { path, .. } = &c.geometry else {
                continue;
            };
            let fail = |what: String| {
                load_error(format!(
                    "URDF file {}: link \"{}\": collision mesh {what}",
                    robot.source.display(),
                    link.name
                ))
            };
            let extension = path
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            if matches!(extension.as_str(), "stl" | "obj" | "dae") {
                let mesh = TriangleMesh::read(path).map_err(|e| fail(e.to_string()))?;
                if mesh.triangles.is_empty() {
                    return Err(fail(format!("{} has no triangles", path.display())));
                }
            }
        }
    }
    Ok(())
}

/// Fails when a link with collision shapes in the URDF has none in Bullet.
fn check_colliders(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    body: c_int,
    robot: &RobotModel,
    link_names: &[String],
) -> Result<(), EngineError> {
    // SAFETY: the command is created on `client` and submitted once,
    // with the Bullet lock held (`lock`).
    unsafe {
        let r = client.submit(
            lock,
            ffi::b3RequestCollisionInfoCommandInit(client.handle(lock), body),
        );
        expect(
            r.kind,
            ffi::CMD_REQUEST_COLLISION_INFO_COMPLETED,
            "reading the collision shapes",
        )?;
        for link in robot.links.iter().filter(|l| !l.collisions.is_empty()) {
            let index = if link.name == robot.links[robot.root_link].name {
                -1
            } else {
                match link_names.iter().position(|n| *n == link.name) {
                    Some(i) => i as c_int,
                    None => {
                        return Err(load_error(format!(
                            "link \"{}\" of {} is missing from Bullet's model",
                            link.name,
                            robot.source.display()
                        )))
                    }
                }
            };
            let (mut lo, mut hi) = ([0.0f64; 3], [0.0f64; 3]);
            let ok = ffi::b3GetStatusAABB(r.handle(), index, lo.as_mut_ptr(), hi.as_mut_ptr());
            if ok == 0 || (0..3).any(|k| lo[k] > hi[k]) {
                return Err(load_error(format!(
                    "link \"{}\" of {} has collision shapes but Bullet built none (a mesh it could not read?){}",
                    link.name,
                    robot.source.display(),
                    bullet_said()
                )));
            }
        }
    }
    Ok(())
}

impl Simulation for BulletSimulation {
    fn timestep_s(&self) -> f64 {
        self.timestep_s
    }

    fn time_s(&self) -> f64 {
        self.time_origin_s + self.steps as f64 * self.timestep_s
    }

    fn joint_count(&self) -> usize {
        self.joints.len()
    }

    fn tracked_count(&self) -> usize {
        self.tracked.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        if rad.len() != self.joints.len() {
            return Err(EngineError::Usage {
                engine: ENGINE_NAME.to_string(),
                message: format!(
                    "{} joint angles given for {} joints",
                    rad.len(),
                    self.joints.len()
                ),
            });
        }
        if let Some(i) = rad.iter().position(|a| !a.is_finite()) {
            return Err(EngineError::Usage {
                engine: ENGINE_NAME.to_string(),
                message: format!(
                    "joint \"{}\": angle {} is not finite",
                    self.scene.actuators[i].joint, rad[i]
                ),
            });
        }
        let lock = &ffi::lock();
        let h = self.client.handle(lock);
        // SAFETY: the command is created on this client and
        // submitted once, with the lock held.
        let kind = unsafe {
            let cmd = ffi::b3CreatePoseCommandInit(h, self.robot);
            for (joint, &angle) in self.joints.iter().zip(rad) {
                ffi::b3CreatePoseCommandSetJointPosition(h, cmd, joint.index, angle);
                ffi::b3CreatePoseCommandSetJointVelocity(h, cmd, joint.index, 0.0);
            }
            self.client.submit(lock, cmd).kind
        };
        check_status(
            kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "setting the joint angles",
        )
        .map_err(|m| self.unstable(m))?;
        self.refresh(lock)
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        for (t, &v) in self.targets_rad_s.iter_mut().zip(rad_s) {
            *t = v;
        }
        self.commands.clear();
        self.targets_pending = true;
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(ENGINE_NAME, &self.scene, commands)?;
        if commands.iter().all(|c| c.kind == CommandKind::Velocity) {
            let v: Vec<f64> = commands.iter().map(|c| c.value).collect();
            self.set_joint_velocity_targets(&v);
            return Ok(());
        }
        self.targets_rad_s = commands
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
        self.targets_pending = true;
        Ok(())
    }

    fn step(&mut self) -> Result<(), EngineError> {
        self.step_n(1)
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        let lock = &ffi::lock();
        if self.targets_pending {
            self.send_targets(lock)?;
        }
        for _ in 0..n {
            self.step_once(lock)?;
        }
        self.refresh(lock)?;
        self.check_stability()
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        out.copy_from_slice(&self.angles_rad[..out.len()]);
    }

    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        // The rates read after each step: `state` also reads the native
        // state.
        out.copy_from_slice(&self.velocities_rad_s[..out.len()]);
        Ok(())
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        out.copy_from_slice(&self.poses[..out.len()]);
    }

    fn state(&self) -> Result<SimState, EngineError> {
        let lock = &ffi::lock();
        self.take_state(lock)
    }

    fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let lock = &ffi::lock();
        self.put_state(lock, state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene1() -> BulletSimulation {
        BulletSimulation::load(
            &realitygap_core::testing::scene("scene1_single_joint"),
            &realitygap_core::testing::mico2(),
            &EngineSettings::new(),
            &ModelVariation::default(),
        )
        .unwrap()
    }

    /// Issue 10 item 6: Bullet failing while stepping (here: asked about
    /// a body that does not exist) is an instability with the time, never
    /// "cannot load the scene".
    #[test]
    fn a_bullet_failure_while_stepping_is_unstable() {
        let mut sim = scene1();
        sim.step_n(10).unwrap();
        sim.robot = 1234; // no such body: state reads and motor commands fail
        let e = sim.step_n(1).unwrap_err();
        assert!(
            matches!(&e, EngineError::Unstable { t_s, .. } if (*t_s - 0.11).abs() < 1e-9),
            "{e:?}"
        );
        assert!(!e.to_string().contains("cannot load"), "{e}");
        sim.set_joint_velocity_targets(&[0.1; 6]);
        let e = sim.step_n(1).unwrap_err();
        assert!(matches!(e, EngineError::Unstable { .. }), "{e:?}");
    }

    /// A native state of another world is refused before Bullet sees it.
    #[test]
    fn native_state_of_another_world_is_refused() {
        let mut sim = scene1();
        let mut state = sim.state().unwrap();
        let native = state.native.as_mut().unwrap();
        eprintln!("native state of scene 1: {} numbers", native.data.len());
        native.data[2] += 1.0;
        let e = sim.set_state(&state).unwrap_err();
        assert!(matches!(e, EngineError::State { .. }), "{e:?}");
        assert!(e.to_string().contains("another world"), "{e}");
        state.joint_angles_rad.pop();
        let e = sim.set_state(&state).unwrap_err();
        assert!(matches!(e, EngineError::State { .. }), "{e:?}");
    }

    #[test]
    fn c_structs_have_the_c_layout() {
        // Sizes from the bundled SharedMemoryPublic.h (x86_64).
        assert_eq!(std::mem::size_of::<ffi::b3JointInfo>(), 2272);
        assert_eq!(std::mem::size_of::<ffi::b3LinkState>(), 264);
        assert_eq!(std::mem::size_of::<ffi::b3DynamicsInfo>(), 200);
        assert_eq!(
            std::mem::size_of::<ffi::b3PhysicsSimulationParameters>(),
            224
        );
        assert_eq!(std::mem::size_of::<rubullet_sys::b3ContactPointData>(), 176);
    }
}
