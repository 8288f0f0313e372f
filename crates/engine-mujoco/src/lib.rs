//! The MuJoCo engine of realitygap, through the `mujoco-rs` bindings
//! (MuJoCo 3.17).
//!
//! [`MujocoEngine`] implements [`realitygap_core::Engine`]. It builds a
//! MuJoCo model in one of two ways:
//! - from the scene and its URDF robot ([`mjcf::scene_to_mjcf`]: ground,
//!   link bodies with URDF inertias and collision shapes, hinge joints for
//!   the controlled joints, held joints welded, velocity servos with the
//!   scene's `kv` and force limits, free-floating objects);
//! - from an MJCF file given as the scene's `robot.mjcf`, loaded as it is
//!   (the study's own `m1n6s300.xml`): the controlled joints, the tracked
//!   links and objects are then found by name, each controlled joint must
//!   have an actuator, and the file's own actuator gains, objects and ground
//!   are used.
//!
//! In both cases the engine settings ([`SETTINGS`], parsed into
//! [`MujocoSettings`]: timestep, integrator, solver, ...) and the scene's
//! gravity are applied to the compiled model, then the physical parameters
//! ([`model_params`]: armature, restitution and contact softness on both
//! models, and every key on an MJCF file loaded as is), then the mass and
//! friction factors of a [`ModelVariation`]. All of it happens once, at
//! load; stepping is a bare `mj_step`.
//!
//! [`Simulation::state`] holds MuJoCo's complete state (`mj_getState`) for
//! an exact restore, and the portable fields for other engines (see the
//! `state` module).
//!
//! State is read at one time: after stepping, the kinematics are computed
//! again (`mj_kinematics`) so that the body poses (`xpos`, `xquat`) belong
//! to the same `qpos` as the joint angles. A bare `mj_step` leaves them
//! from its own kinematics pass, one timestep earlier, as the study's
//! Python loop read them (at dt = 1e-4 s and 0.5 m/s, 0.05 mm); reporting
//! both at time t is what lets a state move between engines exactly.
//!
//! MuJoCo ends the process on a fatal error (`mju_error`). Call
//! [`install_message_handler`] once at the start of a program so that the
//! message goes to standard error with a clear prefix before that happens;
//! the `realitygap run` command runs each simulation in a child process so
//! that such an exit fails only that run. MuJoCo's instability warnings
//! (it resets the state when accelerations blow up) are turned into
//! [`EngineError::Unstable`], never silently stepped over.

pub mod mjcf;
pub mod model_params;
pub mod settings;
pub mod stability;
mod state;

pub use settings::{MujocoSettings, MUJOCO_DEFAULT_TIMESTEP_S, SETTINGS};

use model_params::ModelSource;
use mujoco_rs::mujoco_c;
use mujoco_rs::prelude::*;
use realitygap_core::engine::{
    check_servo_commands, CommandKind, CommandSupport, Engine, EngineError, EngineSettings,
    ModelVariation, ServoCommand, SettingInfo, SimState, Simulation, StabilityIssue,
};
use realitygap_core::params::{ParamSupport, PhysicalParams};
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::{Scene, TrackTarget};
use std::ffi::CStr;
use std::sync::Mutex;

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = "mujoco";

/// The messages MuJoCo reported through its log since the last
/// [`take_messages`] (warnings and errors; at most 64 kept).
static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

fn message_handler(message: &MjLogMessage) {
    let level = match message.level() {
        MjtLogLevel::mjLOG_ERROR => "error",
        MjtLogLevel::mjLOG_WARNING => "warning",
        MjtLogLevel::mjLOG_INFO => "info",
        MjtLogLevel::mjLOG_DEBUG => return,
    };
    let mut text = message.subject().to_string();
    if let Some(body) = message.body().filter(|b| !b.is_empty()) {
        text.push_str(": ");
        text.push_str(body);
    }
    if level == "error" {
        // MuJoCo exits right after this returns: the parent process reads
        // this line as the run's failure message.
        eprintln!("MuJoCo error: {text}");
    }
    if let Ok(mut m) = MESSAGES.lock() {
        if m.len() < 64 {
            m.push(format!("MuJoCo {level}: {text}"));
        }
    }
}

/// Routes MuJoCo's log messages (warnings, errors) to this crate: errors
/// are printed to standard error as `MuJoCo error: ...` before MuJoCo ends
/// the process, warnings are kept for [`EngineError`] messages. Call it
/// once, early, before other threads use MuJoCo; later calls do nothing.
pub fn install_message_handler() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: `Once` runs this at most once; callers are told to call it
        // before other threads use MuJoCo.
        unsafe { set_log_handler(message_handler) };
    });
}

/// The MuJoCo messages collected since the last call.
pub fn take_messages() -> Vec<String> {
    MESSAGES
        .lock()
        .map(|mut m| std::mem::take(&mut *m))
        .unwrap_or_default()
}

/// The linked MuJoCo library's version, e.g. `3.17.0`.
pub fn mujoco_version() -> String {
    // SAFETY: mj_versionString returns a pointer to a static NUL-terminated string.
    unsafe { CStr::from_ptr(mujoco_c::mj_versionString()) }
        .to_string_lossy()
        .into_owned()
}

/// The MuJoCo engine.
#[derive(Debug, Default, Clone, Copy)]
pub struct MujocoEngine;

fn load_error(message: impl Into<String>) -> EngineError {
    EngineError::Load {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

impl Engine for MujocoEngine {
    fn name(&self) -> &'static str {
        ENGINE_NAME
    }

    fn version(&self) -> String {
        format!("MuJoCo {} (mujoco-rs 7.0.0)", mujoco_version())
    }

    fn default_timestep_s(&self) -> f64 {
        MUJOCO_DEFAULT_TIMESTEP_S
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        SETTINGS.to_vec()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        Ok(MujocoSettings::parse(settings)?
            .timestep_s
            .unwrap_or(MUJOCO_DEFAULT_TIMESTEP_S))
    }

    fn param_support(&self) -> Vec<ParamSupport> {
        model_params::param_support()
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
        Ok(Box::new(MujocoSimulation::load_with(
            scene, robot, settings, variation, params,
        )?))
    }
}

/// How MuJoCo takes each kind of joint command: the joint's actuator is
/// switched between the laws of MuJoCo's own `<velocity>`, `<position>`
/// and `<motor>` actuators by its gain and bias parameters (so that the
/// implicit integrators treat the damping term `-kv qd` implicitly, as
/// they do for those actuators), its force range kept.
pub const COMMAND_SUPPORT: [CommandSupport; 3] = [
    CommandSupport {
        kind: CommandKind::Velocity,
        mechanism: "<velocity> actuator law: ctrl = v, gainprm[0] = kv, biasprm = [0, 0, -kv]",
    },
    CommandSupport {
        kind: CommandKind::Position,
        mechanism: "<position> actuator law with damping: ctrl = q, gainprm[0] = kp, biasprm = [0, -kp, -kv]",
    },
    CommandSupport {
        kind: CommandKind::Effort,
        mechanism: "<motor> actuator law: ctrl = tau, gainprm[0] = 1, biasprm = 0",
    },
];

/// The servo law of one controlled joint's actuator, for switching it
/// between command kinds.
#[derive(Debug, Clone, Copy)]
struct ServoLaw {
    /// The actuator's velocity gain (its `kv` when it is a velocity servo,
    /// else the scene's), N m s/rad.
    kv: f64,
    /// The scene's position gain, N m/rad.
    kp: f64,
    /// The actuator's own gain, bias and control limit, restored for
    /// velocity commands.
    gain: [f64; 3],
    bias: [f64; 3],
    ctrllimited: bool,
}

/// A scene object's body in the model and its free joint's addresses.
#[derive(Debug, Clone)]
struct ObjectSlot {
    name: String,
    /// `qpos` and `qvel` addresses of the object body's free joint; `None`
    /// when the model (an MJCF file) lacks the body or it is not free.
    free: Option<(usize, usize)>,
}

/// A held joint that is a joint of the model (MJCF files; the model built
/// from URDF welds held joints): its addresses and scene angle.
#[derive(Debug, Clone, Copy)]
struct HeldJoint {
    qpos_adr: usize,
    dof_adr: usize,
    angle_rad: f64,
}

/// A MuJoCo model and its state, driven through [`Simulation`].
pub struct MujocoSimulation {
    data: MjData<Box<MjModel>>,
    /// `qpos` address of each controlled joint.
    qpos_adr: Vec<usize>,
    /// `qvel` address of each controlled joint.
    dof_adr: Vec<usize>,
    /// Actuator (control) index of each controlled joint.
    ctrl_index: Vec<usize>,
    /// Body index of each tracked body.
    tracked_body: Vec<usize>,
    /// The scene's objects, in scene order.
    objects: Vec<ObjectSlot>,
    /// Held joints that are joints of the model.
    held: Vec<HeldJoint>,
    /// Warning counters already seen (BADQPOS, BADQVEL, BADQACC).
    warnings_seen: [i32; 3],
    /// The pre-run stability check's findings ([`stability::check`]).
    stability: Vec<StabilityIssue>,
    /// Each controlled joint's servo laws.
    laws: Vec<ServoLaw>,
    /// The kind of command each controlled joint's actuator now takes.
    kinds: Vec<CommandKind>,
    /// The scene, for checking commands (its actuators' gains).
    scene: Scene,
}

const INSTABILITY_WARNINGS: [(mujoco_c::mjtWarning, &str); 3] = [
    (
        mujoco_c::mjtWarning::mjWARN_BADQPOS,
        "bad joint position (NaN or huge), state reset by MuJoCo",
    ),
    (
        mujoco_c::mjtWarning::mjWARN_BADQVEL,
        "bad joint velocity (NaN or huge), state reset by MuJoCo",
    ),
    (
        mujoco_c::mjtWarning::mjWARN_BADQACC,
        "bad joint acceleration (NaN or huge), state reset by MuJoCo",
    ),
];

/// Compiles the model: the scene's MJCF file as is, or MJCF written from
/// the scene and `robot`.
fn compile(scene: &Scene, robot: &RobotModel) -> Result<MjModel, EngineError> {
    match &scene.robot.mjcf {
        Some(path) => {
            if !path.is_file() {
                return Err(load_error(format!(
                    "MJCF file {} not found",
                    path.display()
                )));
            }
            MjModel::from_xml(path)
                .map_err(|e| load_error(format!("MJCF file {}: {e}", path.display())))
        }
        None => {
            for o in &scene.objects {
                o.check_shape().map_err(load_error)?;
            }
            let xml = mjcf::scene_to_mjcf(scene, robot)
                .map_err(|e| load_error(format!("{} (robot {})", e.0, robot.source.display())))?;
            MjModel::from_xml_string(&xml).map_err(|e| {
                load_error(format!(
                    "MuJoCo rejected the model built from {}: {e}",
                    robot.source.display()
                ))
            })
        }
    }
}

/// Stops the robot's links colliding with each other (`self_collision =
/// false`) with MuJoCo's contact bits: a pair of geoms may touch when one's
/// `contype` shares a bit with the other's `conaffinity`. Robot geoms get
/// type 2 and affinity 1, the environment's (the world body's, the ground,
/// and the scene objects') type 1 and affinity 3: the robot touches the
/// environment, the environment itself, but never the robot. A geom that
/// collides with nothing stays so, and the bodies' bits (what the broad
/// phase prunes by) are recomputed.
fn without_self_collision(model: &mut MjModel) {
    let environment: Vec<bool> = (0..model.ffi().nbody as usize)
        .map(|b| {
            b == 0
                || model
                    .id_to_name(MjtObjBase::mjOBJ_BODY, b)
                    .is_some_and(|n| n.starts_with(mjcf::OBJECT_BODY_PREFIX))
        })
        .collect();
    let bodies: Vec<usize> = model.geom_bodyid().iter().map(|&b| b as usize).collect();
    for (g, &b) in bodies.iter().enumerate() {
        if model.geom_contype()[g] == 0 && model.geom_conaffinity()[g] == 0 {
            continue;
        }
        let (t, a) = if environment[b] { (1, 3) } else { (2, 1) };
        model.geom_contype_mut()[g] = t;
        model.geom_conaffinity_mut()[g] = a;
    }
    let nbody = environment.len();
    let (mut t, mut a) = (vec![0; nbody], vec![0; nbody]);
    for (g, &b) in bodies.iter().enumerate() {
        t[b] |= model.geom_contype()[g];
        a[b] |= model.geom_conaffinity()[g];
    }
    model.body_contype_mut().copy_from_slice(&t);
    model.body_conaffinity_mut().copy_from_slice(&a);
}

/// Multiplies every body's mass and inertia and every geom's sliding
/// friction by the variation's factors.
fn apply_variation(model: &mut MjModel, variation: &ModelVariation) {
    for m in model.body_mass_mut() {
        *m *= variation.mass_scale;
    }
    for i in model.body_inertia_mut() {
        for c in i.iter_mut() {
            *c *= variation.mass_scale;
        }
    }
    for f in model.geom_friction_mut() {
        f[0] *= variation.friction_scale;
    }
}

/// Per controlled joint: `qpos` addresses, `qvel` addresses, actuators.
type JointAddresses = (Vec<usize>, Vec<usize>, Vec<usize>);

/// Addresses of the controlled joints: (qpos, qvel, actuator) per joint.
fn resolve_actuators(model: &MjModel, scene: &Scene) -> Result<JointAddresses, EngineError> {
    let mut qpos_adr = Vec::new();
    let mut dof_adr = Vec::new();
    let mut ctrl_index = Vec::new();
    for a in &scene.actuators {
        let j = model
            .name_to_id(MjtObjBase::mjOBJ_JOINT, &a.joint)
            .ok_or_else(|| {
                load_error(format!(
                    "the model has no joint named \"{}\"{}",
                    a.joint,
                    mjcf_note(scene)
                ))
            })?;
        let jtype = model.jnt_type()[j];
        if jtype != mujoco_c::mjtJoint::mjJNT_HINGE && jtype != mujoco_c::mjtJoint::mjJNT_SLIDE {
            return Err(load_error(format!(
                "joint \"{}\" is not a hinge or slide joint in the model",
                a.joint
            )));
        }
        qpos_adr.push(model.jnt_qposadr()[j] as usize);
        dof_adr.push(model.jnt_dofadr()[j] as usize);
        let actuator = model_params::actuator_of(model, &a.joint).ok_or_else(|| {
            load_error(format!(
                "no actuator drives joint \"{}\"{}",
                a.joint,
                mjcf_note(scene)
            ))
        })?;
        ctrl_index.push(actuator);
    }
    Ok((qpos_adr, dof_adr, ctrl_index))
}

fn resolve_tracked(model: &MjModel, scene: &Scene) -> Result<Vec<usize>, EngineError> {
    let mut tracked_body = Vec::new();
    for t in &scene.tracked {
        let body = match &t.target {
            TrackTarget::Link(link) => model
                .name_to_id(MjtObjBase::mjOBJ_BODY, &mjcf::body_name(link))
                .ok_or_else(|| {
                    load_error(format!(
                        "tracked link \"{link}\" is not a body of the model{}",
                        mjcf_note(scene)
                    ))
                })?,
            TrackTarget::Object(object) => {
                model_params::object_body(model, object).ok_or_else(|| {
                    load_error(format!(
                        "tracked object \"{object}\" is not a body of the model{}",
                        mjcf_note(scene)
                    ))
                })?
            }
        };
        tracked_body.push(body);
    }
    Ok(tracked_body)
}

/// The scene's objects in the model, and the held joints that are joints
/// of it.
fn resolve_state_slots(model: &MjModel, scene: &Scene) -> (Vec<ObjectSlot>, Vec<HeldJoint>) {
    let objects = scene
        .objects
        .iter()
        .map(|o| {
            let body = model_params::object_body(model, &o.name);
            let free = body.and_then(|b| {
                let j = model.body_jntadr()[b];
                (model.body_jntnum()[b] == 1
                    && j >= 0
                    && model.jnt_type()[j as usize] == mujoco_c::mjtJoint::mjJNT_FREE)
                    .then(|| {
                        (
                            model.jnt_qposadr()[j as usize] as usize,
                            model.jnt_dofadr()[j as usize] as usize,
                        )
                    })
            });
            ObjectSlot {
                name: o.name.clone(),
                free,
            }
        })
        .collect();
    let held = scene
        .robot
        .held_joints_rad
        .iter()
        .filter_map(|(name, &angle_rad)| {
            let j = model.name_to_id(MjtObjBase::mjOBJ_JOINT, name)?;
            let t = model.jnt_type()[j];
            (t == mujoco_c::mjtJoint::mjJNT_HINGE || t == mujoco_c::mjtJoint::mjJNT_SLIDE).then(
                || HeldJoint {
                    qpos_adr: model.jnt_qposadr()[j] as usize,
                    dof_adr: model.jnt_dofadr()[j] as usize,
                    angle_rad,
                },
            )
        })
        .collect();
    (objects, held)
}

impl MujocoSimulation {
    /// [`MujocoSimulation::load_with`] without physical parameters.
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
    ) -> Result<MujocoSimulation, EngineError> {
        Self::load_with(scene, robot, settings, variation, &PhysicalParams::none())
    }

    /// Builds the model of `scene` (from its MJCF file when it names one,
    /// else from `robot`), applies `settings`, the scene's gravity,
    /// `params` ([`model_params::apply`]) and `variation`, and puts it in
    /// its initial state: held joints at their scene angles, all at rest.
    pub fn load_with(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        params: &PhysicalParams,
    ) -> Result<MujocoSimulation, EngineError> {
        let options = MujocoSettings::parse(settings)?;
        variation.check().map_err(load_error)?;
        if scene.robot.mjcf.is_none() {
            params.check_fixed_base_masses(ENGINE_NAME, scene, robot)?;
        }
        let mut model = Box::new(compile(scene, robot)?);
        {
            let opt = model.opt_mut();
            if scene.robot.mjcf.is_none() {
                opt.timestep = MUJOCO_DEFAULT_TIMESTEP_S;
            }
            options.apply(opt);
            opt.gravity = scene.gravity_m_s2.to_array();
        }
        let source = match &scene.robot.mjcf {
            Some(p) => ModelSource::AsIs(p),
            None => ModelSource::Generated,
        };
        if options.self_collision == Some(false) {
            without_self_collision(&mut model);
        }
        let mut set_const = model_params::apply(&mut model, scene, params, source)?;
        if !variation.is_identity() {
            apply_variation(&mut model, variation);
            set_const = true;
        }
        let (qpos_adr, dof_adr, ctrl_index) = resolve_actuators(&model, scene)?;
        if source == ModelSource::Generated {
            for a in scene.actuators.iter().filter(|a| a.force_limit == 0.0) {
                model_params::set_servo(&mut model, &a.joint, None, Some(0.0), source)?;
            }
        }
        let tracked_body = resolve_tracked(&model, scene)?;
        let (objects, held) = resolve_state_slots(&model, scene);

        let mut data = MjData::try_new(model)
            .map_err(|e| load_error(format!("cannot allocate the simulation data: {e}")))?;
        if set_const {
            // SAFETY: model and data belong together and are not in use elsewhere.
            unsafe {
                let d = data.ffi_mut() as *mut mujoco_c::mjData;
                let m = data.model_mut().ffi_mut() as *mut mujoco_c::mjModel;
                mujoco_c::mj_setConst(m, d);
            }
        }
        let laws = ctrl_index
            .iter()
            .zip(&scene.actuators)
            .map(|(&u, a)| {
                let model = data.model();
                let g = model.actuator_gainprm()[u];
                let b = model.actuator_biasprm()[u];
                let velocity_servo = b[0] == 0.0 && b[1] == 0.0 && b[2] == -g[0] && g[0] > 0.0;
                ServoLaw {
                    kv: if velocity_servo { g[0] } else { a.kv },
                    kp: a.kp.unwrap_or(0.0),
                    gain: [g[0], g[1], g[2]],
                    bias: [b[0], b[1], b[2]],
                    ctrllimited: model.actuator_ctrllimited()[u],
                }
            })
            .collect();
        let kinds = vec![CommandKind::Velocity; ctrl_index.len()];
        let mut sim = MujocoSimulation {
            data,
            qpos_adr,
            dof_adr,
            ctrl_index,
            tracked_body,
            objects,
            held,
            warnings_seen: [0; 3],
            stability: Vec::new(),
            laws,
            kinds,
            scene: scene.clone(),
        };
        sim.place_held_joints();
        sim.data.forward();
        sim.warnings_seen = sim.warning_counts();
        let servos: Vec<stability::ServoJoint<'_>> = scene
            .actuators
            .iter()
            .enumerate()
            .map(|(i, a)| stability::ServoJoint {
                name: &a.joint,
                dof: sim.dof_adr[i],
                actuator: sim.ctrl_index[i],
            })
            .collect();
        sim.stability = stability::check(&mut sim.data, &servos);
        Ok(sim)
    }

    /// Puts the held joints that are joints of the model at their scene
    /// angles, at rest.
    fn place_held_joints(&mut self) {
        for h in &self.held {
            self.data.qpos_mut()[h.qpos_adr] = h.angle_rad;
            self.data.qvel_mut()[h.dof_adr] = 0.0;
        }
    }

    fn warning_counts(&self) -> [i32; 3] {
        let w = &self.data.ffi().warning;
        INSTABILITY_WARNINGS.map(|(kind, _)| w[kind as usize].number)
    }

    /// After a step: an error when MuJoCo flagged (and reset) an unusable
    /// state during it; `t_s` is the simulated time the step started from.
    fn check_stability(&mut self, t_s: f64) -> Result<(), EngineError> {
        let counts = self.warning_counts();
        if counts == self.warnings_seen {
            return Ok(());
        }
        let i = (0..3)
            .find(|&i| counts[i] > self.warnings_seen[i])
            .unwrap_or(2);
        self.warnings_seen = counts;
        let mut message = INSTABILITY_WARNINGS[i].1.to_string();
        if let Some(m) = take_messages().into_iter().last() {
            message.push_str(&format!(" ({m})"));
        }
        Err(EngineError::Unstable {
            engine: ENGINE_NAME.to_string(),
            t_s,
            message,
        })
    }

    /// Steps `n` times with `mj_step` and nothing else: no checks, no
    /// control. The baseline of the controller-loop benchmark.
    pub fn step_raw(&mut self, n: u64) {
        for _ in 0..n {
            self.data.step();
        }
    }

    /// Switches the actuator of controlled joint `i` to the law of `kind`.
    fn switch_law(&mut self, i: usize, kind: CommandKind) {
        if self.kinds[i] == kind {
            return;
        }
        let u = self.ctrl_index[i];
        let law = self.laws[i];
        let (gain, bias, ctrllimited) = match kind {
            CommandKind::Velocity => (law.gain, law.bias, law.ctrllimited),
            CommandKind::Position => ([law.kp, 0.0, 0.0], [0.0, -law.kp, -law.kv], false),
            CommandKind::Effort => ([1.0, 0.0, 0.0], [0.0; 3], false),
        };
        // SAFETY: only parameter values of this simulation's own model
        // change (not the gain or bias type, nor any index MuJoCo reads
        // unchecked), between steps.
        let model = unsafe { self.data.model_mut() };
        {
            // SAFETY: as above.
            let g = unsafe { model.actuator_gainprm_mut() };
            g[u] = [0.0; 10];
            g[u][..3].copy_from_slice(&gain);
        }
        let b = model.actuator_biasprm_mut();
        b[u] = [0.0; 10];
        b[u][..3].copy_from_slice(&bias);
        model.actuator_ctrllimited_mut()[u] = ctrllimited;
        self.kinds[i] = kind;
    }

    /// The commands in force, for a state: empty while every actuator
    /// takes velocity commands.
    pub(crate) fn servo_commands(&self) -> Vec<ServoCommand> {
        if self.kinds.iter().all(|&k| k == CommandKind::Velocity) {
            return Vec::new();
        }
        let ctrl = self.data.ctrl();
        self.kinds
            .iter()
            .zip(&self.ctrl_index)
            .map(|(&kind, &u)| ServoCommand {
                kind,
                value: ctrl[u],
            })
            .collect()
    }

    /// Sets the controls of the controlled joints' servos directly, rad/s.
    pub fn set_controls(&mut self, rad_s: &[f64]) {
        let ctrl = self.data.ctrl_mut();
        for (&u, &v) in self.ctrl_index.iter().zip(rad_s) {
            ctrl[u] = v;
        }
    }

    /// The pairs of bodies in contact now, by MuJoCo body name (one entry
    /// per contact point), for diagnosing a model.
    pub fn contacts(&self) -> Vec<(String, String)> {
        let model = self.data.model();
        let body_of = |g: i32| {
            let b = model.geom_bodyid()[g as usize] as usize;
            model
                .id_to_name(MjtObjBase::mjOBJ_BODY, b)
                .unwrap_or("world")
                .to_string()
        };
        self.data
            .contact()
            .iter()
            .map(|c| (body_of(c.geom[0]), body_of(c.geom[1])))
            .collect()
    }

    /// The MuJoCo model.
    pub fn model(&self) -> &MjModel {
        self.data.model()
    }

    /// World pose of the body of a URDF link, or of any MuJoCo body by its
    /// MuJoCo name (for tests and tools).
    pub fn body_pose(&self, name: &str) -> Option<Pose> {
        let b = self
            .data
            .model()
            .name_to_id(MjtObjBase::mjOBJ_BODY, &mjcf::body_name(name))?;
        Some(self.body_pose_by_index(b))
    }

    fn body_pose_by_index(&self, b: usize) -> Pose {
        let p = self.data.xpos()[b];
        let q = self.data.xquat()[b];
        Pose::new(
            Vec3::new(p[0], p[1], p[2]),
            Quat::new(q[0], q[1], q[2], q[3]),
        )
    }
}

fn mjcf_note(scene: &Scene) -> String {
    match &scene.robot.mjcf {
        Some(p) => format!(" (MJCF file {})", p.display()),
        None => String::new(),
    }
}

impl Simulation for MujocoSimulation {
    fn stability_issues(&self) -> Vec<StabilityIssue> {
        self.stability.clone()
    }

    fn timestep_s(&self) -> f64 {
        self.data.model().opt().timestep
    }

    fn time_s(&self) -> f64 {
        self.data.ffi().time
    }

    fn joint_count(&self) -> usize {
        self.qpos_adr.len()
    }

    fn tracked_count(&self) -> usize {
        self.tracked_body.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        if rad.len() != self.qpos_adr.len() {
            return Err(EngineError::Usage {
                engine: ENGINE_NAME.to_string(),
                message: format!(
                    "{} joint angles given for {} joints",
                    rad.len(),
                    self.qpos_adr.len()
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
        let qpos = self.data.qpos_mut();
        for (&a, &v) in self.qpos_adr.iter().zip(rad) {
            qpos[a] = v;
        }
        let qvel = self.data.qvel_mut();
        for &a in &self.dof_adr {
            qvel[a] = 0.0;
        }
        self.data.forward();
        Ok(())
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        for i in 0..self.kinds.len() {
            self.switch_law(i, CommandKind::Velocity);
        }
        self.set_controls(rad_s);
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(ENGINE_NAME, &self.scene, commands)?;
        for (i, c) in commands.iter().enumerate() {
            self.switch_law(i, c.kind);
            let u = self.ctrl_index[i];
            self.data.ctrl_mut()[u] = c.value;
        }
        Ok(())
    }

    fn step(&mut self) -> Result<(), EngineError> {
        let t_s = self.time_s();
        self.data.step();
        self.check_stability(t_s)?;
        self.data.kinematics();
        Ok(())
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        for _ in 0..n {
            let t_s = self.data.ffi().time;
            self.data.step();
            if self.data.ffi().warning[mujoco_c::mjtWarning::mjWARN_BADQACC as usize].number
                != self.warnings_seen[2]
                || self.data.ffi().warning[mujoco_c::mjtWarning::mjWARN_BADQPOS as usize].number
                    != self.warnings_seen[0]
                || self.data.ffi().warning[mujoco_c::mjtWarning::mjWARN_BADQVEL as usize].number
                    != self.warnings_seen[1]
            {
                return self.check_stability(t_s);
            }
        }
        // Body poses at the current qpos (mj_step computed them before
        // integrating); once per call, not per step.
        self.data.kinematics();
        Ok(())
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        let qpos = self.data.qpos();
        for (o, &a) in out.iter_mut().zip(&self.qpos_adr) {
            *o = qpos[a];
        }
    }

    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        // Directly from qvel: `state` would copy MuJoCo's whole native
        // state.
        let qvel = self.data.qvel();
        for (o, &a) in out.iter_mut().zip(&self.dof_adr) {
            *o = qvel[a];
        }
        Ok(())
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        for (o, &b) in out.iter_mut().zip(&self.tracked_body) {
            *o = self.body_pose_by_index(b);
        }
    }

    fn state(&self) -> Result<SimState, EngineError> {
        self.read_state()
    }

    fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        self.write_state(state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::SettingValue;
    use realitygap_core::robot::PackageResolver;
    use std::path::{Path, PathBuf};

    fn workspace() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
    }

    fn scene1() -> Scene {
        Scene::from_file(&workspace().join("assets/scenes/scene1_single_joint.toml")).unwrap()
    }

    fn mico2() -> RobotModel {
        RobotModel::from_urdf_file(
            &workspace().join("assets/robots/mico2/mico2.urdf"),
            &PackageResolver::new(),
        )
        .unwrap()
    }

    fn settings(pairs: &[(&str, SettingValue)]) -> EngineSettings {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn settings_are_checked() {
        let e = MujocoEngine;
        assert_eq!(
            e.check_settings(&EngineSettings::new()).unwrap(),
            MUJOCO_DEFAULT_TIMESTEP_S
        );
        let ok = settings(&[
            ("timestep_s", SettingValue::Float(1e-4)),
            ("integrator", SettingValue::Text("RK4".into())),
            ("solver", SettingValue::Text("pgs".into())),
            ("iterations", SettingValue::Integer(50)),
            ("cone", SettingValue::Text("elliptic".into())),
            ("impratio", SettingValue::Integer(10)),
            ("noslip_iterations", SettingValue::Integer(0)),
            ("tolerance", SettingValue::Float(0.0)),
        ]);
        assert_eq!(e.check_settings(&ok).unwrap(), 1e-4);
        for (key, value, expected) in [
            ("timestep_s", SettingValue::Float(0.0), "must be > 0"),
            (
                "timestep_s",
                SettingValue::Text("fast".into()),
                "expected a number",
            ),
            (
                "integrator",
                SettingValue::Text("verlet".into()),
                "not one of euler, rk4",
            ),
            (
                "iterations",
                SettingValue::Float(2.5),
                "expected a whole number",
            ),
            (
                "iterations",
                SettingValue::Integer(0),
                "whole number from 1 to",
            ),
            (
                "gravity",
                SettingValue::Float(1.0),
                "unknown setting (accepted: timestep_s",
            ),
        ] {
            let err = e
                .check_settings(&settings(&[(key, value)]))
                .unwrap_err()
                .to_string();
            assert!(err.contains(key) && err.contains(expected), "{err}");
        }
    }

    #[test]
    fn settings_reach_the_model() {
        let s = scene1();
        let robot = mico2();
        let set = settings(&[
            ("timestep_s", SettingValue::Float(5e-4)),
            ("integrator", SettingValue::Text("implicitfast".into())),
            ("iterations", SettingValue::Integer(7)),
        ]);
        let sim = MujocoSimulation::load(&s, &robot, &set, &ModelVariation::default()).unwrap();
        let opt = sim.model().opt();
        assert_eq!(opt.timestep, 5e-4);
        assert_eq!(
            opt.integrator,
            mujoco_c::mjtIntegrator::mjINT_IMPLICITFAST as i32
        );
        assert_eq!(opt.iterations, 7);
        assert_eq!(sim.joint_count(), 6);
        assert_eq!(sim.tracked_count(), 2);
    }

    #[test]
    fn generated_model_has_urdf_masses_and_the_cube() {
        let s = scene1();
        let robot = mico2();
        let sim = MujocoSimulation::load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        )
        .unwrap();
        let total: f64 = sim.model().body_mass().iter().sum();
        let expected = robot.total_mass_kg() + 0.0884;
        assert!((total - expected).abs() < 1e-9, "{total} vs {expected}");
        // The cube rests on the ground at its scene pose.
        let mut poses = [Pose::IDENTITY; 2];
        sim.tracked_poses(&mut poses);
        assert!(poses[1].position_m.distance(Vec3::new(0.5, 0.0, 0.0375)) < 1e-12);
    }

    #[test]
    fn mass_and_friction_variation_scale_the_model() {
        let s = scene1();
        let robot = mico2();
        let base = MujocoSimulation::load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        )
        .unwrap();
        let v = ModelVariation {
            mass_scale: 1.1,
            friction_scale: 0.5,
        };
        let varied = MujocoSimulation::load(&s, &robot, &EngineSettings::new(), &v).unwrap();
        let sum = |m: &MujocoSimulation| m.model().body_mass().iter().sum::<f64>();
        assert!((sum(&varied) - 1.1 * sum(&base)).abs() < 1e-9);
        let f0 = base.model().geom_friction()[0][0];
        assert!((varied.model().geom_friction()[0][0] - 0.5 * f0).abs() < 1e-12);
    }

    #[test]
    fn mjcf_mode_errors_name_what_is_missing() {
        let mut s = scene1();
        let robot = mico2();
        s.robot.mjcf = Some(PathBuf::from("/nonexistent/model.xml"));
        let err = MujocoSimulation::load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        )
        .err()
        .unwrap();
        assert!(
            err.to_string()
                .contains("MJCF file /nonexistent/model.xml not found"),
            "{err}"
        );

        // A model without the scene's joints.
        let dir = std::env::temp_dir().join(format!("rg-mjcf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("pendulum.xml");
        std::fs::write(
            &file,
            "<mujoco><worldbody><body name=\"m1n6s300_link_6\"><joint name=\"m1n6s300_joint_1\"/><geom size=\"0.1\"/></body></worldbody></mujoco>",
        )
        .unwrap();
        s.robot.mjcf = Some(file.clone());
        let err = MujocoSimulation::load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        )
        .err()
        .unwrap();
        assert!(
            err.to_string()
                .contains("no actuator drives joint \"m1n6s300_joint_1\""),
            "{err}"
        );

        // Malformed XML: MuJoCo's parser message, with the file.
        std::fs::write(&file, "<mujoco><worldbody>").unwrap();
        let err = MujocoSimulation::load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        )
        .err()
        .unwrap();
        assert!(err.to_string().contains("pendulum.xml"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn formats_the_version() {
        assert!(mujoco_version().starts_with("3."));
        assert!(MujocoEngine.version().contains(&mujoco_version()));
    }
}
