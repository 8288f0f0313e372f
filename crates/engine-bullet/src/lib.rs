//! The Bullet engine of realitygap: Bullet 3 (the physics of PyBullet),
//! driven through PyBullet's own C API (`PhysicsClientC_API.h`) in DIRECT
//! mode, as bundled and built from source by the `rubullet-sys` crate.
//!
//! [`BulletEngine`] implements [`realitygap_core::Engine`]. It builds the
//! world of a [`Scene`] the way a PyBullet script would, in this order:
//!
//! 1. gravity (0, 0, -9.81) m/s^2, a fixed timestep (default 0.01 s, the
//!    study's PyBullet), no substeps, and the solver settings of
//!    [`SETTINGS`];
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
//! # The URDF file Bullet reads
//!
//! Bullet opens the URDF file and its meshes itself and does not know ROS
//! packages. When the robot has meshes, the engine writes a temporary copy
//! of the URDF in which every mesh file name is the absolute path the
//! [`RobotModel`] resolved (`package://` URIs included), loads it and
//! deletes it. After loading, every link that has collision shapes in the
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

mod ffi;
mod messages;
mod urdf_file;

pub use messages::{install_message_handler, take_messages, BulletMessage, Level};

use realitygap_core::engine::{
    Engine, EngineError, EngineSettings, ModelVariation, SettingInfo, Simulation,
};
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

/// Gravity along -z, m/s^2.
pub const GRAVITY_M_S2: f64 = 9.81;

/// The motor force used for an unlimited (infinite) force limit, N m.
pub const UNLIMITED_FORCE_N_M: f64 = 1e12;

/// Force of the motor holding a non-controlled joint whose URDF gives no
/// effort limit, N m (PyBullet's default motor force).
pub const HELD_JOINT_DEFAULT_FORCE_N_M: f64 = 1e6;

/// The settings accepted in `[engine.bullet]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo { key: "timestep_s", help: "fixed timestep, s (> 0); default 0.01 (the study's PyBullet)" },
    SettingInfo {
        key: "solver_iterations",
        help: "numSolverIterations: constraint solver iterations per step (>= 1); default 50",
    },
    SettingInfo {
        key: "solver_residual_threshold",
        help: "solverResidualThreshold: the solver stops when the residual falls below it (>= 0); default 1e-7",
    },
    SettingInfo { key: "contact_erp", help: "defaultContactERP: contact error reduction per step, 0..1; default 0.08" },
    SettingInfo {
        key: "non_contact_erp",
        help: "defaultNonContactERP: error reduction of joint limits and motors, 0..1; default 0.2",
    },
    SettingInfo { key: "friction_erp", help: "frictionERP: error reduction of friction anchors, 0..1; default 0.2" },
    SettingInfo { key: "global_cfm", help: "defaultGlobalCFM: constraint force mixing (>= 0); default 0" },
    SettingInfo { key: "split_impulse", help: "useSplitImpulse: true | false; default true" },
    SettingInfo {
        key: "split_impulse_penetration_threshold_m",
        help: "splitImpulsePenetrationThreshold: penetration beyond which split impulse is used, m; default -0.04",
    },
    SettingInfo {
        key: "contact_breaking_threshold_m",
        help: "contactBreakingThreshold: contact points farther apart are dropped, m (> 0); default 0.01",
    },
    SettingInfo { key: "cone_friction", help: "enableConeFriction: true | false; default true" },
    SettingInfo {
        key: "max_force_n_m",
        help: "maximum motor force of every controlled joint, N m (> 0); default: the scene's force limits (the study's PyBullet used 10)",
    },
    SettingInfo {
        key: "velocity_gain",
        help: "velocityGain of the velocity motors: share of the velocity error removed per step, (0, 1]; default 1",
    },
    SettingInfo {
        key: "inertia_from_file",
        help: "use the URDF's inertia tensors (true), or let Bullet compute them from the collision shapes (false, PyBullet's default without URDF_USE_INERTIA_FROM_FILE); default true",
    },
    SettingInfo {
        key: "self_collision",
        help: "collisions between the robot's links, neighbouring links excepted: true | false; default false",
    },
    SettingInfo {
        key: "implicit_cylinders",
        help: "URDF cylinders as exact cylinders (true) or as convex hulls (false, Bullet's default); default false",
    },
];

/// Engine settings, checked.
#[derive(Debug, Clone, PartialEq)]
struct Options {
    timestep_s: f64,
    solver_iterations: Option<i32>,
    solver_residual_threshold: Option<f64>,
    contact_erp: Option<f64>,
    non_contact_erp: Option<f64>,
    friction_erp: Option<f64>,
    global_cfm: Option<f64>,
    split_impulse: Option<bool>,
    split_impulse_penetration_threshold_m: Option<f64>,
    contact_breaking_threshold_m: Option<f64>,
    cone_friction: Option<bool>,
    max_force_n_m: Option<f64>,
    velocity_gain: f64,
    inertia_from_file: bool,
    self_collision: bool,
    implicit_cylinders: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            timestep_s: DEFAULT_TIMESTEP_S,
            solver_iterations: None,
            solver_residual_threshold: None,
            contact_erp: None,
            non_contact_erp: None,
            friction_erp: None,
            global_cfm: None,
            split_impulse: None,
            split_impulse_penetration_threshold_m: None,
            contact_breaking_threshold_m: None,
            cone_friction: None,
            max_force_n_m: None,
            velocity_gain: 1.0,
            inertia_from_file: true,
            self_collision: false,
            implicit_cylinders: false,
        }
    }
}

fn setting_error(key: &str, message: impl Into<String>) -> EngineError {
    EngineError::Setting {
        engine: ENGINE_NAME.to_string(),
        key: key.to_string(),
        message: message.into(),
    }
}

fn load_error(message: impl Into<String>) -> EngineError {
    EngineError::Load {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

fn parse_options(settings: &EngineSettings) -> Result<Options, EngineError> {
    let mut o = Options::default();
    for (key, value) in settings {
        let number = |min: f64, max: f64, min_inclusive: bool| -> Result<f64, EngineError> {
            let v = value.as_f64().ok_or_else(|| {
                setting_error(key, format!("expected a number, found \"{value}\""))
            })?;
            let above = if min_inclusive { v >= min } else { v > min };
            if v.is_finite() && above && v <= max {
                Ok(v)
            } else {
                let low = if min_inclusive {
                    format!(">= {min}")
                } else {
                    format!("> {min}")
                };
                let high = if max.is_finite() {
                    format!(" and <= {max}")
                } else {
                    String::new()
                };
                Err(setting_error(
                    key,
                    format!("must be a number {low}{high}, found {v}"),
                ))
            }
        };
        let any_number = || -> Result<f64, EngineError> {
            value.as_f64().filter(|v| v.is_finite()).ok_or_else(|| {
                setting_error(key, format!("expected a finite number, found \"{value}\""))
            })
        };
        let whole = |min: i64| -> Result<i32, EngineError> {
            let v = value.as_i64().ok_or_else(|| {
                setting_error(key, format!("expected a whole number, found \"{value}\""))
            })?;
            if v >= min && v <= i32::MAX as i64 {
                Ok(v as i32)
            } else {
                Err(setting_error(
                    key,
                    format!("must be a whole number >= {min}, found {v}"),
                ))
            }
        };
        let boolean = || -> Result<bool, EngineError> {
            value.as_bool().ok_or_else(|| {
                setting_error(key, format!("expected true or false, found \"{value}\""))
            })
        };
        match key.as_str() {
            "timestep_s" => o.timestep_s = number(0.0, f64::INFINITY, false)?,
            "solver_iterations" => o.solver_iterations = Some(whole(1)?),
            "solver_residual_threshold" => {
                o.solver_residual_threshold = Some(number(0.0, f64::INFINITY, true)?)
            }
            "contact_erp" => o.contact_erp = Some(number(0.0, 1.0, true)?),
            "non_contact_erp" => o.non_contact_erp = Some(number(0.0, 1.0, true)?),
            "friction_erp" => o.friction_erp = Some(number(0.0, 1.0, true)?),
            "global_cfm" => o.global_cfm = Some(number(0.0, f64::INFINITY, true)?),
            "split_impulse" => o.split_impulse = Some(boolean()?),
            "split_impulse_penetration_threshold_m" => {
                o.split_impulse_penetration_threshold_m = Some(any_number()?)
            }
            "contact_breaking_threshold_m" => {
                o.contact_breaking_threshold_m = Some(number(0.0, f64::INFINITY, false)?)
            }
            "cone_friction" => o.cone_friction = Some(boolean()?),
            "max_force_n_m" => o.max_force_n_m = Some(number(0.0, f64::INFINITY, false)?),
            "velocity_gain" => o.velocity_gain = number(0.0, 1.0, false)?,
            "inertia_from_file" => o.inertia_from_file = boolean()?,
            "self_collision" => o.self_collision = boolean()?,
            "implicit_cylinders" => o.implicit_cylinders = boolean()?,
            other => {
                return Err(setting_error(
                    other,
                    format!(
                        "unknown setting (Bullet accepts: {})",
                        SETTINGS
                            .iter()
                            .map(|s| s.key)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ))
            }
        }
    }
    Ok(o)
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
        Ok(parse_options(settings)?.timestep_s)
    }

    fn load(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<Box<dyn Simulation>, EngineError> {
        Ok(Box::new(BulletSimulation::load(
            scene, robot, settings, variation,
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

/// A controlled joint: its Bullet indices and motor force.
#[derive(Debug, Clone)]
struct MotorJoint {
    /// Bullet joint index.
    index: c_int,
    /// Index into the actual-state position array.
    q_index: usize,
    /// Index into the velocity array, also the motor's dof index.
    u_index: c_int,
    /// Maximum motor force, N m (or N).
    max_force: f64,
}

/// What a tracked body is in Bullet.
#[derive(Debug, Clone, Copy)]
enum Tracked {
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
    steps: u64,
    velocity_gain: f64,
    joints: Vec<MotorJoint>,
    tracked: Vec<Tracked>,
    targets_rad_s: Vec<f64>,
    targets_pending: bool,
    // The state after the last step (or reset).
    angles_rad: Vec<f64>,
    poses: Vec<Pose>,
    /// Largest |generalized velocity| seen at the last refresh, rad/s or m/s.
    max_speed: f64,
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
    /// Builds the Bullet world of `scene` with `robot` (see the crate
    /// documentation), applies `settings` and `variation`, and puts it in
    /// its initial state.
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<BulletSimulation, EngineError> {
        let options = parse_options(settings)?;
        let usable = variation.mass_scale.is_finite()
            && variation.mass_scale > 0.0
            && variation.friction_scale.is_finite()
            && variation.friction_scale >= 0.0;
        if !usable {
            return Err(load_error(format!(
                "unusable model variation {variation:?}"
            )));
        }
        install_message_handler();
        check_meshes(robot)?;
        let urdf = urdf_file::prepare(robot).map_err(load_error)?;
        let urdf_c_path = urdf.c_path().map_err(load_error)?;
        let _guard = ffi::lock();
        take_messages();
        let client = ffi::Client::connect().ok_or_else(|| {
            load_error(format!(
                "cannot start a Bullet physics server{}",
                bullet_said()
            ))
        })?;
        let h = client.handle();

        // 1. Physics parameters.
        // SAFETY (this and every block below): the commands are created on
        // this client and submitted once, with the Bullet lock held; the
        // pointers passed point to live arrays of the sizes the C API reads.
        unsafe {
            let cmd = ffi::b3InitPhysicsParamCommand(h);
            ffi::b3PhysicsParamSetGravity(cmd, 0.0, 0.0, -GRAVITY_M_S2);
            ffi::b3PhysicsParamSetTimeStep(cmd, options.timestep_s);
            ffi::b3PhysicsParamSetNumSubSteps(cmd, 0);
            if let Some(v) = options.solver_iterations {
                ffi::b3PhysicsParamSetNumSolverIterations(cmd, v);
            }
            if let Some(v) = options.solver_residual_threshold {
                ffi::b3PhysicsParamSetSolverResidualThreshold(cmd, v);
            }
            if let Some(v) = options.contact_erp {
                ffi::b3PhysicsParamSetDefaultContactERP(cmd, v);
            }
            if let Some(v) = options.non_contact_erp {
                ffi::b3PhysicsParamSetDefaultNonContactERP(cmd, v);
            }
            if let Some(v) = options.friction_erp {
                ffi::b3PhysicsParamSetDefaultFrictionERP(cmd, v);
            }
            if let Some(v) = options.global_cfm {
                ffi::b3PhysicsParamSetDefaultGlobalCFM(cmd, v);
            }
            if let Some(v) = options.split_impulse {
                ffi::b3PhysicsParamSetUseSplitImpulse(cmd, v as c_int);
            }
            if let Some(v) = options.split_impulse_penetration_threshold_m {
                ffi::b3PhysicsParamSetSplitImpulsePenetrationThreshold(cmd, v);
            }
            if let Some(v) = options.contact_breaking_threshold_m {
                ffi::b3PhysicsParamSetContactBreakingThreshold(cmd, v);
            }
            if let Some(v) = options.cone_friction {
                ffi::b3PhysicsParamSetEnableConeFriction(cmd, v as c_int);
            }
            expect(
                client.submit(cmd).kind,
                ffi::CMD_CLIENT_COMMAND_COMPLETED,
                "setting the physics parameters",
            )?;
        }

        // 2. The ground.
        let ground = match &scene.ground {
            None => None,
            Some(g) => {
                let shape = unsafe {
                    let cmd = ffi::b3CreateCollisionShapeCommandInit(h);
                    ffi::b3CreateCollisionShapeAddPlane(cmd, [0.0, 0.0, 1.0].as_ptr(), 0.0);
                    let r = client.submit(cmd);
                    expect(
                        r.kind,
                        ffi::CMD_CREATE_COLLISION_SHAPE_COMPLETED,
                        "creating the ground plane",
                    )?;
                    ffi::b3GetStatusCollisionShapeUniqueId(r.handle)
                };
                let body = create_body(
                    &client,
                    0.0,
                    shape,
                    Pose::new(Vec3::new(0.0, 0.0, g.height_m), Quat::IDENTITY),
                    "the ground",
                )?;
                if let Some(f) = g.friction {
                    set_friction(&client, body, -1, f)?;
                }
                Some(body)
            }
        };

        // 3. The robot.
        let mut flags = 0;
        if options.inertia_from_file {
            flags |= ffi::URDF_USE_INERTIA_FROM_FILE;
        }
        if options.self_collision {
            flags |= ffi::URDF_USE_SELF_COLLISION | ffi::URDF_USE_SELF_COLLISION_EXCLUDE_PARENT;
        }
        if options.implicit_cylinders {
            flags |= ffi::URDF_USE_IMPLICIT_CYLINDER;
        }
        let base = scene.robot.base;
        let robot_id = unsafe {
            let cmd = ffi::b3LoadUrdfCommandInit(h, urdf_c_path.as_ptr());
            let p = base.position_m;
            let q = base.orientation;
            ffi::b3LoadUrdfCommandSetStartPosition(cmd, p.x, p.y, p.z);
            ffi::b3LoadUrdfCommandSetStartOrientation(cmd, q.x, q.y, q.z, q.w);
            ffi::b3LoadUrdfCommandSetUseFixedBase(cmd, 1);
            ffi::b3LoadUrdfCommandSetFlags(cmd, flags);
            let r = client.submit(cmd);
            if r.kind != ffi::CMD_URDF_LOADING_COMPLETED {
                return Err(load_error(format!(
                    "Bullet could not load URDF file {} ({}){}",
                    robot.source.display(),
                    ffi::status_name(r.kind),
                    bullet_said()
                )));
            }
            ffi::b3GetStatusBodyIndex(r.handle)
        };
        drop(urdf);

        // Joint and link indices by name.
        let joint_count = unsafe { ffi::b3GetNumJoints(h, robot_id) };
        let mut infos = Vec::with_capacity(joint_count.max(0) as usize);
        for j in 0..joint_count {
            let mut info = ffi::b3JointInfo::default();
            // SAFETY: `info` is a b3JointInfo of the C layout (checked by a test).
            unsafe { ffi::b3GetJointInfo(h, robot_id, j, &mut info) };
            infos.push(info);
        }
        let joint_names: Vec<String> = infos.iter().map(|i| ffi::c_text(&i.m_joint_name)).collect();
        let link_names: Vec<String> = infos.iter().map(|i| ffi::c_text(&i.m_link_name)).collect();
        let root_link_name = robot.links[robot.root_link].name.clone();

        // Every link with collision shapes in the URDF has one in Bullet,
        // and Bullet read every mesh.
        let messages = take_messages();
        if let Some(m) = messages.iter().find(|m| {
            m.level != Level::Info
                && (m.text.contains("cannot extract")
                    || m.text.contains("Cannot find")
                    || m.text.contains("filesize mismatch")
                    || m.text.contains("unknown collision geometry"))
        }) {
            return Err(load_error(format!(
                "URDF file {}: Bullet could not read a mesh: {}",
                robot.source.display(),
                m.text
            )));
        }
        check_colliders(&client, robot_id, robot, &link_names)?;

        // 4. The objects.
        let mut objects = Vec::new();
        let mut object_names = Vec::new();
        for object in &scene.objects {
            let ObjectShape::Box { size_m } = object.shape;
            let shape = unsafe {
                let cmd = ffi::b3CreateCollisionShapeCommandInit(h);
                let half = [size_m.x / 2.0, size_m.y / 2.0, size_m.z / 2.0];
                ffi::b3CreateCollisionShapeAddBox(cmd, half.as_ptr());
                let r = client.submit(cmd);
                expect(
                    r.kind,
                    ffi::CMD_CREATE_COLLISION_SHAPE_COMPLETED,
                    &format!("creating the shape of object \"{}\"", object.name),
                )?;
                ffi::b3GetStatusCollisionShapeUniqueId(r.handle)
            };
            let body = create_body(
                &client,
                object.mass_kg,
                shape,
                object.pose,
                &format!("object \"{}\"", object.name),
            )?;
            if let Some(f) = object.friction {
                set_friction(&client, body, -1, f)?;
            }
            objects.push(body);
            object_names.push(object.name.clone());
        }

        // 5. Joints: controlled joints get velocity motors, the other
        // movable joints are held.
        let mut joints = Vec::new();
        for a in &scene.actuators {
            let j = joint_names
                .iter()
                .position(|n| *n == a.joint)
                .ok_or_else(|| {
                    load_error(format!(
                        "Bullet's model of {} has no joint \"{}\"",
                        robot.source.display(),
                        a.joint
                    ))
                })?;
            let info = &infos[j];
            if info.m_joint_type != ffi::JOINT_REVOLUTE && info.m_joint_type != ffi::JOINT_PRISMATIC
            {
                return Err(load_error(format!(
                    "joint \"{}\" is not a revolute or prismatic joint in Bullet",
                    a.joint
                )));
            }
            let limit = options.max_force_n_m.unwrap_or(a.force_limit);
            let max_force = if limit.is_finite() {
                limit
            } else {
                UNLIMITED_FORCE_N_M
            };
            joints.push(MotorJoint {
                index: j as c_int,
                q_index: info.m_q_index as usize,
                u_index: info.m_u_index,
                max_force,
            });
        }
        let held: Vec<(usize, f64, f64)> = infos
            .iter()
            .enumerate()
            .filter(|(j, i)| {
                (i.m_joint_type == ffi::JOINT_REVOLUTE || i.m_joint_type == ffi::JOINT_PRISMATIC)
                    && !scene.actuators.iter().any(|a| a.joint == joint_names[*j])
            })
            .map(|(j, i)| {
                let angle = scene
                    .robot
                    .held_joints_rad
                    .get(&joint_names[j])
                    .copied()
                    .unwrap_or(0.0);
                let force = if i.m_joint_max_force > 0.0 {
                    i.m_joint_max_force
                } else {
                    HELD_JOINT_DEFAULT_FORCE_N_M
                };
                (j, angle, force)
            })
            .collect();
        unsafe {
            if held.iter().any(|&(_, angle, _)| angle != 0.0) {
                let cmd = ffi::b3CreatePoseCommandInit(h, robot_id);
                for &(j, angle, _) in &held {
                    ffi::b3CreatePoseCommandSetJointPosition(h, cmd, j as c_int, angle);
                    ffi::b3CreatePoseCommandSetJointVelocity(h, cmd, j as c_int, 0.0);
                }
                expect(
                    client.submit(cmd).kind,
                    ffi::CMD_CLIENT_COMMAND_COMPLETED,
                    "setting the held joints",
                )?;
            }
            if !held.is_empty() {
                let cmd = ffi::b3JointControlCommandInit2(
                    h,
                    robot_id,
                    ffi::CONTROL_MODE_POSITION_VELOCITY_PD,
                );
                for &(j, angle, force) in &held {
                    let info = &infos[j];
                    ffi::b3JointControlSetDesiredPosition(cmd, info.m_q_index, angle);
                    ffi::b3JointControlSetKp(cmd, info.m_u_index, 1.0);
                    ffi::b3JointControlSetDesiredVelocity(cmd, info.m_u_index, 0.0);
                    ffi::b3JointControlSetKd(cmd, info.m_u_index, 1.0);
                    ffi::b3JointControlSetMaximumForce(cmd, info.m_u_index, force);
                }
                expect(
                    client.submit(cmd).kind,
                    ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
                    "locking the held joints",
                )?;
            }
        }

        // Model variation.
        if !variation.is_identity() {
            let mut bodies: Vec<(c_int, c_int)> =
                (-1..joint_count).map(|l| (robot_id, l)).collect();
            bodies.extend(objects.iter().map(|&b| (b, -1)));
            if variation.mass_scale != 1.0 {
                for &(body, link) in &bodies {
                    let info = dynamics_info(&client, body, link)?;
                    if info.m_mass > 0.0 {
                        let inertia = info
                            .m_localInertialDiagonal
                            .map(|i| i * variation.mass_scale);
                        unsafe {
                            let cmd = ffi::b3InitChangeDynamicsInfo(h);
                            ffi::b3ChangeDynamicsInfoSetMass(
                                cmd,
                                body,
                                link,
                                info.m_mass * variation.mass_scale,
                            );
                            ffi::b3ChangeDynamicsInfoSetLocalInertiaDiagonal(
                                cmd,
                                body,
                                link,
                                inertia.as_ptr(),
                            );
                            expect(
                                client.submit(cmd).kind,
                                ffi::CMD_CLIENT_COMMAND_COMPLETED,
                                "scaling masses",
                            )?;
                        }
                    }
                }
            }
            if variation.friction_scale != 1.0 {
                // Bullet multiplies the two friction coefficients of a
                // contact, so each is scaled by the square root.
                bodies.extend(ground.map(|g| (g, -1)));
                let factor = variation.friction_scale.sqrt();
                for &(body, link) in &bodies {
                    let info = dynamics_info(&client, body, link)?;
                    set_friction(&client, body, link, info.m_lateralFrictionCoeff * factor)?;
                }
            }
        }

        // Tracked bodies.
        let mut tracked = Vec::new();
        for t in &scene.tracked {
            tracked.push(match &t.target {
                TrackTarget::Link(name) if *name == root_link_name => Tracked::Root(base),
                TrackTarget::Link(name) => {
                    let l = link_names.iter().position(|n| n == name).ok_or_else(|| {
                        load_error(format!(
                            "tracked link \"{name}\" is not a link of Bullet's model of {}",
                            robot.source.display()
                        ))
                    })?;
                    Tracked::Link(l as c_int)
                }
                TrackTarget::Object(name) => {
                    let i = object_names.iter().position(|n| n == name).ok_or_else(|| {
                        load_error(format!("tracked object \"{name}\" is not in the scene"))
                    })?;
                    Tracked::Object(i)
                }
            });
        }

        let n = joints.len();
        let mut sim = BulletSimulation {
            client,
            robot: robot_id,
            ground,
            objects,
            object_names,
            link_names,
            root_link_name,
            timestep_s: options.timestep_s,
            steps: 0,
            velocity_gain: options.velocity_gain,
            joints,
            tracked,
            targets_rad_s: vec![0.0; n],
            targets_pending: true,
            angles_rad: vec![0.0; n],
            poses: vec![Pose::IDENTITY; scene.tracked.len()],
            max_speed: 0.0,
        };
        sim.send_targets()?;
        sim.refresh()?;
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

    /// Sends the velocity targets to the motors. Call with the lock held.
    fn send_targets(&mut self) -> Result<(), EngineError> {
        let h = self.client.handle();
        // SAFETY: see `load`.
        unsafe {
            let cmd = ffi::b3JointControlCommandInit2(h, self.robot, ffi::CONTROL_MODE_VELOCITY);
            for (joint, &v) in self.joints.iter().zip(&self.targets_rad_s) {
                ffi::b3JointControlSetDesiredVelocity(cmd, joint.u_index, v);
                ffi::b3JointControlSetKd(cmd, joint.u_index, self.velocity_gain);
                ffi::b3JointControlSetMaximumForce(cmd, joint.u_index, joint.max_force);
            }
            expect(
                self.client.submit(cmd).kind,
                ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
                "sending the motor targets",
            )?;
        }
        self.targets_pending = false;
        Ok(())
    }

    /// Reads the joint angles and tracked poses. Call with the lock held.
    /// Bullet recomputes the link frames from the joint positions first:
    /// the frames it keeps are those of the collision detection, one
    /// position update behind after a step (3 mm at the wrist in scene 1).
    fn refresh(&mut self) -> Result<(), EngineError> {
        let h = self.client.handle();
        let mut max_speed: f64 = 0.0;
        // SAFETY: see `load`; the state arrays are read within the sizes
        // Bullet reported, before the next command is submitted.
        unsafe {
            let cmd = ffi::b3RequestActualStateCommandInit(h, self.robot);
            ffi::b3RequestActualStateCommandComputeForwardKinematics(cmd, 1);
            let r = self.client.submit(cmd);
            expect(
                r.kind,
                ffi::CMD_ACTUAL_STATE_UPDATE_COMPLETED,
                "reading the robot's state",
            )?;
            let (q, qdot) = actual_state(r)?;
            for (out, joint) in self.angles_rad.iter_mut().zip(&self.joints) {
                *out = q.get(joint.q_index).copied().unwrap_or(f64::NAN);
            }
            for v in qdot {
                max_speed = max_speed.max(if v.is_finite() {
                    v.abs()
                } else {
                    f64::INFINITY
                });
            }
            for (out, t) in self.poses.iter_mut().zip(&self.tracked) {
                match *t {
                    Tracked::Link(l) => {
                        let mut state = ffi::b3LinkState::default();
                        if ffi::b3GetLinkState(h, r.handle, l, &mut state) == 0 {
                            return Err(self.unstable(format!("Bullet gave no state for link {l}")));
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
                    .submit(ffi::b3RequestActualStateCommandInit(h, body));
                expect(
                    r.kind,
                    ffi::CMD_ACTUAL_STATE_UPDATE_COMPLETED,
                    "reading an object's state",
                )?;
                let (q, qdot) = actual_state(r)?;
                if q.len() < 7 {
                    return Err(self.unstable(format!(
                        "Bullet gave {} state values for object \"{}\"",
                        q.len(),
                        self.object_names[i]
                    )));
                }
                let pose = Pose::new(
                    Vec3::new(q[0], q[1], q[2]),
                    Quat::new(q[6], q[3], q[4], q[5]),
                );
                for v in qdot {
                    max_speed = max_speed.max(if v.is_finite() {
                        v.abs()
                    } else {
                        f64::INFINITY
                    });
                }
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
        EngineError::Unstable {
            engine: ENGINE_NAME.to_string(),
            t_s: self.time_s(),
            message,
        }
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
        let _guard = ffi::lock();
        if self.targets_pending {
            self.send_targets()?;
        }
        for _ in 0..n {
            self.step_once()?;
        }
        Ok(())
    }

    fn step_once(&mut self) -> Result<(), EngineError> {
        // SAFETY: see `load`.
        let kind = unsafe {
            self.client
                .submit(ffi::b3InitStepSimulationCommand(self.client.handle()))
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
        let _guard = ffi::lock();
        let h = self.client.handle();
        let mut pairs = Vec::new();
        // SAFETY: see `load`; the contact array is read within the count
        // Bullet reported.
        unsafe {
            let r = self
                .client
                .submit(ffi::b3InitRequestContactPointInformation(h));
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
        let _guard = ffi::lock();
        let Some(l) = self.link_names.iter().position(|n| n == name) else {
            return Ok(None);
        };
        let h = self.client.handle();
        // SAFETY: see `load`.
        unsafe {
            let cmd = ffi::b3RequestActualStateCommandInit(h, self.robot);
            ffi::b3RequestActualStateCommandComputeForwardKinematics(cmd, 1);
            let r = self.client.submit(cmd);
            expect(
                r.kind,
                ffi::CMD_ACTUAL_STATE_UPDATE_COMPLETED,
                "reading the robot's state",
            )?;
            let mut state = ffi::b3LinkState::default();
            if ffi::b3GetLinkState(h, r.handle, l as c_int, &mut state) == 0 {
                return Ok(None);
            }
            Ok(Some(link_frame(&state)))
        }
    }

    /// Mass (kg) and lateral friction coefficient of a robot link (by URDF
    /// name) or of a scene object (`object:NAME`) as Bullet holds them.
    pub fn mass_and_friction(&mut self, name: &str) -> Result<Option<(f64, f64)>, EngineError> {
        let _guard = ffi::lock();
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
                let info = dynamics_info(&self.client, body, link)?;
                Ok(Some((info.m_mass, info.m_lateralFrictionCoeff)))
            }
        }
    }

    /// The physics parameters Bullet is using.
    pub fn physics_parameters(&mut self) -> Result<PhysicsParameters, EngineError> {
        let _guard = ffi::lock();
        let h = self.client.handle();
        let mut p = ffi::b3PhysicsSimulationParameters::default();
        // SAFETY: see `load`; `p` has the C layout (checked by a test).
        unsafe {
            let r = self.client.submit(ffi::b3InitRequestPhysicsParamCommand(h));
            expect(
                r.kind,
                ffi::CMD_REQUEST_PHYSICS_SIMULATION_PARAMETERS_COMPLETED,
                "reading the physics parameters",
            )?;
            ffi::b3GetStatusPhysicsSimulationParameters(r.handle, &mut p);
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
fn expect(kind: c_int, expected: c_int, what: &str) -> Result<(), EngineError> {
    if kind == expected {
        Ok(())
    } else {
        Err(load_error(format!(
            "Bullet failed {what} ({}){}",
            ffi::status_name(kind),
            bullet_said()
        )))
    }
}

/// The position and velocity arrays of an actual-state reply.
///
/// # Safety
/// `reply` must be the latest reply of its client and of type
/// CMD_ACTUAL_STATE_UPDATE_COMPLETED; the slices are valid until the next
/// command.
unsafe fn actual_state<'a>(reply: ffi::Reply) -> Result<(&'a [f64], &'a [f64]), EngineError> {
    let (mut nq, mut nu) = (0, 0);
    let (mut q, mut qdot): (*const f64, *const f64) = (ptr::null(), ptr::null());
    let ok = ffi::b3GetStatusActualState(
        reply.handle,
        ptr::null_mut(),
        &mut nq,
        &mut nu,
        ptr::null_mut(),
        &mut q,
        &mut qdot,
        ptr::null_mut(),
    );
    if ok == 0 || q.is_null() || qdot.is_null() {
        return Err(load_error("Bullet returned no state"));
    }
    Ok((
        std::slice::from_raw_parts(q, nq.max(0) as usize),
        std::slice::from_raw_parts(qdot, nu.max(0) as usize),
    ))
}

/// Creates a single-body multibody with a collision shape. Lock held.
fn create_body(
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
    // SAFETY: see `BulletSimulation::load`.
    unsafe {
        let cmd = ffi::b3CreateMultiBodyCommandInit(client.handle());
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
        let r = client.submit(cmd);
        expect(
            r.kind,
            ffi::CMD_CREATE_MULTI_BODY_COMPLETED,
            &format!("creating {what}"),
        )?;
        Ok(ffi::b3GetStatusBodyIndex(r.handle))
    }
}

/// Sets the lateral friction coefficient of a body's link. Lock held.
fn set_friction(
    client: &ffi::Client,
    body: c_int,
    link: c_int,
    friction: f64,
) -> Result<(), EngineError> {
    // SAFETY: see `BulletSimulation::load`.
    unsafe {
        let cmd = ffi::b3InitChangeDynamicsInfo(client.handle());
        ffi::b3ChangeDynamicsInfoSetLateralFriction(cmd, body, link, friction);
        expect(
            client.submit(cmd).kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "setting a friction coefficient",
        )
    }
}

/// The dynamics of a body's link. Lock held.
fn dynamics_info(
    client: &ffi::Client,
    body: c_int,
    link: c_int,
) -> Result<ffi::b3DynamicsInfo, EngineError> {
    // SAFETY: see `BulletSimulation::load`; b3DynamicsInfo has the C layout
    // (checked by a test) and is plain data, so zeroed is a valid value.
    unsafe {
        let r = client.submit(ffi::b3GetDynamicsInfoCommandInit(
            client.handle(),
            body,
            link,
        ));
        expect(
            r.kind,
            ffi::CMD_GET_DYNAMICS_INFO_COMPLETED,
            "reading masses and frictions",
        )?;
        let mut info: ffi::b3DynamicsInfo = std::mem::zeroed();
        ffi::b3GetDynamicsInfo(r.handle, &mut info);
        Ok(info)
    }
}

/// Checks the robot's collision meshes before Bullet reads them: Bullet
/// replaces a mesh it cannot read by an empty shape, with at most a
/// warning (none at all for a Wavefront OBJ file without geometry), so a
/// damaged file is caught here with a precise message. STL files are read
/// in full; OBJ files must have at least three vertices and one face;
/// COLLADA files are refused (Bullet's reader crashes on malformed ones);
/// other formats are left to Bullet (whose warnings are checked after
/// loading).
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
            match extension.as_str() {
                "stl" => {
                    let mesh = TriangleMesh::read(path).map_err(|e| fail(e.to_string()))?;
                    if mesh.triangles.is_empty() {
                        return Err(fail(format!("{} has no triangles", path.display())));
                    }
                }
                "obj" => {
                    let bytes = std::fs::read(path).map_err(|e| fail(format!("{}: {e}", path.display())))?;
                    let text = String::from_utf8_lossy(&bytes);
                    let starts = |prefix: &str| {
                        text.lines().filter(|l| l.trim_start().strip_prefix(prefix).is_some_and(|r| r.starts_with([' ', '\t']))).count()
                    };
                    if starts("v") < 3 || starts("f") < 1 {
                        return Err(fail(format!("{} has no vertices and faces (not a Wavefront OBJ mesh?)", path.display())));
                    }
                }
                "dae" => {
                    return Err(fail(format!(
                        "{}: COLLADA meshes are not accepted by the Bullet engine (Bullet 3.08's COLLADA reader \
                         crashes on files it does not expect, so it cannot be trusted with them); convert the mesh to STL or OBJ",
                        path.display()
                    )))
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// Fails when a link with collision shapes in the URDF has none in Bullet.
fn check_colliders(
    client: &ffi::Client,
    body: c_int,
    robot: &RobotModel,
    link_names: &[String],
) -> Result<(), EngineError> {
    // SAFETY: see `BulletSimulation::load`.
    unsafe {
        let r = client.submit(ffi::b3RequestCollisionInfoCommandInit(
            client.handle(),
            body,
        ));
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
            let ok = ffi::b3GetStatusAABB(r.handle, index, lo.as_mut_ptr(), hi.as_mut_ptr());
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
        self.steps as f64 * self.timestep_s
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
        let _guard = ffi::lock();
        let h = self.client.handle();
        // SAFETY: see `load`.
        unsafe {
            let cmd = ffi::b3CreatePoseCommandInit(h, self.robot);
            for (joint, &angle) in self.joints.iter().zip(rad) {
                ffi::b3CreatePoseCommandSetJointPosition(h, cmd, joint.index, angle);
                ffi::b3CreatePoseCommandSetJointVelocity(h, cmd, joint.index, 0.0);
            }
            expect(
                self.client.submit(cmd).kind,
                ffi::CMD_CLIENT_COMMAND_COMPLETED,
                "setting the joint angles",
            )?;
        }
        self.refresh()
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        for (t, &v) in self.targets_rad_s.iter_mut().zip(rad_s) {
            *t = v;
        }
        self.targets_pending = true;
    }

    fn step(&mut self) -> Result<(), EngineError> {
        self.step_n(1)
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        let _guard = ffi::lock();
        if self.targets_pending {
            self.send_targets()?;
        }
        for _ in 0..n {
            self.step_once()?;
        }
        self.refresh()?;
        self.check_stability()
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        out.copy_from_slice(&self.angles_rad[..out.len()]);
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        out.copy_from_slice(&self.poses[..out.len()]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::SettingValue;

    fn settings(pairs: &[(&str, SettingValue)]) -> EngineSettings {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn parses_settings() {
        let o = parse_options(&settings(&[
            ("timestep_s", SettingValue::Float(0.005)),
            ("solver_iterations", SettingValue::Integer(100)),
            ("max_force_n_m", SettingValue::Integer(10)),
            ("velocity_gain", SettingValue::Float(0.5)),
            ("split_impulse", SettingValue::Bool(false)),
            (
                "split_impulse_penetration_threshold_m",
                SettingValue::Float(-0.02),
            ),
        ]))
        .unwrap();
        assert_eq!(o.timestep_s, 0.005);
        assert_eq!(o.solver_iterations, Some(100));
        assert_eq!(o.max_force_n_m, Some(10.0));
        assert_eq!(o.velocity_gain, 0.5);
        assert_eq!(o.split_impulse, Some(false));
        assert_eq!(o.split_impulse_penetration_threshold_m, Some(-0.02));
        assert!(o.inertia_from_file);
        assert_eq!(
            BulletEngine.check_settings(&EngineSettings::new()).unwrap(),
            0.01
        );
    }

    #[test]
    fn rejects_bad_settings() {
        let cases: &[(&str, SettingValue, &str)] = &[
            (
                "timestep_s",
                SettingValue::Float(0.0),
                "must be a number > 0",
            ),
            (
                "timestep_s",
                SettingValue::Text("fast".into()),
                "expected a number",
            ),
            (
                "solver_iterations",
                SettingValue::Integer(0),
                "whole number >= 1",
            ),
            (
                "solver_iterations",
                SettingValue::Float(2.5),
                "expected a whole number",
            ),
            ("contact_erp", SettingValue::Float(1.5), "<= 1"),
            ("velocity_gain", SettingValue::Float(0.0), "> 0"),
            ("max_force_n_m", SettingValue::Float(-1.0), "> 0"),
            (
                "split_impulse",
                SettingValue::Integer(1),
                "expected true or false",
            ),
            (
                "split_impulse_penetration_threshold_m",
                SettingValue::Float(f64::NAN),
                "finite",
            ),
            (
                "integrator",
                SettingValue::Text("rk4".into()),
                "unknown setting (Bullet accepts: timestep_s",
            ),
        ];
        for (key, value, expected) in cases {
            let e = parse_options(&settings(&[(key, value.clone())])).unwrap_err();
            let text = e.to_string();
            assert!(
                text.starts_with(&format!("engine bullet: setting `{key}`:")),
                "{text}"
            );
            assert!(text.contains(expected), "{key}={value}: {text}");
        }
    }

    #[test]
    fn every_setting_is_documented_and_accepted() {
        for s in SETTINGS {
            let value = match s.key {
                "split_impulse" | "cone_friction" | "inertia_from_file" | "self_collision"
                | "implicit_cylinders" => SettingValue::Bool(true),
                "solver_iterations" => SettingValue::Integer(10),
                _ => SettingValue::Float(0.5),
            };
            parse_options(&settings(&[(s.key, value)]))
                .unwrap_or_else(|e| panic!("{}: {e}", s.key));
            assert!(!s.help.is_empty());
        }
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
