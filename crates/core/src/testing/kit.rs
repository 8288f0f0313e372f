//! The engine test kit: one suite of checks that every engine crate runs on
//! its own engine with one macro call, [`engine_test_kit!`](crate::engine_test_kit),
//! in a test file of its own (`tests/kit.rs`):
//!
//! ```ignore
//! realitygap_core::engine_test_kit!(realitygap_engine_ode::OdeEngine, SPEC);
//! ```
//!
//! After the `object_store` crate's `integration` module: each check is a
//! public function here taking the engine and its [`KitSpec`] (the
//! engine's settings for the check and its tolerances, each with its reason
//! in the engine's `tests/kit.rs`); the macro makes one `#[test]` of each.
//! The checks measure with [`crate::conformance`] and print what they
//! measured as `CONFORMANCE engine=<name> check=<check> value=<v>
//! tolerance=<t>`, so that a README's table can be regenerated from a test
//! run. Like the rest of [`crate::testing`], they panic on failure.
//!
//! | group | checks |
//! |---|---|
//! | [`rotor`] | each kind of joint command against its analytic response; commands across a state round trip; bad commands |
//! | [`model`] | every link's tracked pose against the URDF's forward kinematics (both robot models); the initial state |
//! | [`errors`] | bad settings, scene and robot mismatches, bad meshes and inertias, bad angles and states, divergence |
//! | [`physics`] | state round trips, handover into a fresh simulation, each physical parameter's effect (or its refusal), self-collision on and off |
//! | [`free`] | objects alone: free flight against the parabola, torque-free rotation (momentum and energy held), a cube dropped flat comes to rest on its face |
//! | [`scenes`] | the study's three scenes with both robot models, the KUKA iiwa's scenes |
//!
//! What the kit cannot see from core — other engines — is checked in the
//! command's crate, which compiles them all: handovers between every pair
//! of engines and the scenes against MuJoCo (`crates/cli/tests/engines.rs`),
//! and extreme parameter values through the `realitygap` binary, whose
//! child processes survive an engine's abort.
//!
//! A [`KitSpec`] says what an engine lacks ([`KitSpec::dynamics`],
//! [`KitSpec::takes_efforts`], and the parameter keys its
//! [`Engine::param_support`] leaves out): the kit then checks the refusal
//! instead of skipping the check.

pub mod errors;
pub mod free;
pub mod model;
pub mod physics;
pub mod rotor;
pub mod scenes;

pub use rotor::{bad_commands, command_round_trip, step_response};

use crate::conformance::{PositionLaw, Subject};
use crate::controller::{
    load_prepared, prepare, simulate_with, RunError, RunOptions, RunOutcome, RunStatus,
};
use crate::engine::{Engine, EngineError, EngineSettings, SettingValue, Simulation};
use crate::params::{ParamKey, PhysicalParams};
use crate::robot::{PackageResolver, RobotModel};
use crate::scene::Scene;
use crate::testing;
use std::path::{Path, PathBuf};

/// One engine's settings and tolerances for the kit's checks. Start from
/// [`KitSpec::CONTRACT`] (the tolerances the engine contract asks of an
/// engine in double precision) and change what differs, each change with
/// its reason:
///
/// ```ignore
/// const SPEC: KitSpec = KitSpec {
///     /// Single precision: ...
///     handover_rad: 1e-6,
///     ..KitSpec::CONTRACT
/// };
/// ```
#[derive(Debug, Clone, Copy)]
pub struct KitSpec {
    /// Whether the engine simulates dynamics (the physics-free model does
    /// not: no gravity, forces or contact; the kit then checks that it
    /// refuses the parameters of physical effects and leaves objects where
    /// they are).
    pub dynamics: bool,
    /// Whether the engine takes effort commands (the physics-free model
    /// does not: the kit then checks that an effort is refused, not
    /// ignored).
    pub takes_efforts: bool,
    /// Settings of every check but the rotor's (`key=value` pairs), laid
    /// over the scene's own `[engine.NAME]` table; empty: the engine's
    /// defaults, as a run uses them.
    pub settings: &'static [&'static str],

    /// Settings of the rotor's step responses and command round trips
    /// (typically a 1 ms timestep).
    pub rotor_settings: &'static [&'static str],
    /// The largest gap from the analytic response over the second of each
    /// step command, rad: velocity, position, effort (the responses reach
    /// 0.9, 0.5 and 1 rad).
    pub step_tolerance_rad: [f64; 3],
    /// The largest gap between a run and its continuation from its own
    /// state, rad: native state (the engine's own), portable state.
    pub command_round_trip_rad: [f64; 2],
    /// The law the engine's position servo follows at its default
    /// settings.
    pub position_law: PositionLaw,

    /// The model against the URDF's forward kinematics.
    pub kinematics: Kinematics,
    /// More settings to check the kinematics with (each a list of
    /// `key=value` pairs over [`KitSpec::settings`]), e.g. another way of
    /// building the model.
    pub kinematics_settings: &'static [&'static [&'static str]],

    /// The largest distance between a run and its continuation from its
    /// own state over the continued ticks, m: `[scene 1 taken at 2 s,
    /// scene 3 taken at 12 s]` x `[native state, portable state]`.
    pub round_trip_m: [[f64; 2]; 2],
    /// The largest distance between the tracked positions of a simulation
    /// and of a fresh one given its portable state, m: scene 1 at 2 s,
    /// scene 3 at 12 s.
    pub handover_m: [f64; 2],
    /// The largest joint angle gap after that handover, rad.
    pub handover_rad: f64,

    /// The physical parameters' effects.
    pub effects: Effects,
    /// How the kit makes scene 1 diverge.
    pub divergence: Divergence,
    /// Whether the engine's divergence report names the body that ran
    /// away (the cube launched at 1e15 m/s); otherwise any reason will do.
    pub divergence_names_body: bool,
    /// Engine-specific bad settings (`key=value`) and a part of the error
    /// each must give (every engine also gets an unknown key and a
    /// negative timestep).
    pub bad_settings: &'static [(&'static str, &'static str)],
    /// Whether the engine reads the robot's geometry and inertias (the
    /// physics-free model reads neither: the kit then checks that a robot
    /// with broken meshes or no masses loads).
    pub reads_geometry: bool,
    /// Whether a moving link whose inertia is not positive definite (link
    /// 3 with a zero moment) is a load error naming the link; otherwise
    /// the engine makes do with it, and scene 1 must still complete with
    /// finite numbers.
    pub refuses_singular_inertia: bool,
    /// Whether moving links without mass (link 6 and the fingers with no
    /// `<inertial>`) are a load error naming the link; otherwise the
    /// engine gives them a mass of its own, and scene 1 must still
    /// complete with finite numbers.
    pub refuses_massless_links: bool,
    /// Whether the held joints (the fingers) are rigid in the engine's
    /// model, so that joint keys set on them have no effect and are the
    /// engine's error naming the key; otherwise they are joints held by
    /// servos, and the keys are honoured.
    pub held_joints_rigid: bool,

    /// Where scene 1 ends.
    pub scene1_end: End,
    /// The engine library's own solver settings where the engine's
    /// defaults raise them (`key=value`): with them the six coupled servos
    /// are far from converged and scene 1's joint 3 sags more than 10
    /// degrees past where the servos balance gravity. Empty: the engine
    /// keeps its library's defaults.
    pub stock_settings: &'static [&'static str],
    /// The largest distance of scene 2's final wrist from the upright
    /// arm's, m.
    pub scene2_upright_m: f64,
    /// The largest final joint angle of scene 2 (all targets back at 0),
    /// rad.
    pub scene2_angle_rad: f64,
    /// The farthest scene 2's cube (untouched) may move, m.
    pub scene2_cube_m: f64,
    /// The largest gap of an iiwa scene's final joint angles from where
    /// [`KitSpec::scene1_end`]'s law puts them, deg.
    pub iiwa_end_deg: f64,
    /// Scene 3's push; `None`: the engine has no contact, and the cube
    /// stays where it is.
    pub push: Option<Push>,
    /// The free-body checks ([`free`]).
    pub free: free::FreeBody,
}

/// Tolerances of the model against the URDF's forward kinematics.
#[derive(Debug, Clone, Copy)]
pub struct Kinematics {
    /// Largest distance of a link frame from forward kinematics, m.
    pub position_m: f64,
    /// Largest angle of a link frame from forward kinematics, rad.
    pub angle_rad: f64,
    /// Largest gap between the joint angles set and read back, rad.
    pub readback_rad: f64,
    /// Largest distance of a scene object from its scene pose before the
    /// first step, m.
    pub object_m: f64,
    /// The angle range of continuous joints in the random
    /// configurations, rad (beyond pi: angles must not wrap).
    pub turn_rad: f64,
    /// For an engine that measures the joint angles from its bodies: the
    /// largest change of any angle over one step at rest with the servos
    /// holding (no jump, no sign flip), rad; `None`: not checked (the
    /// contract asks nothing of a step here: a velocity servo yields to
    /// gravity).
    pub after_step_rad: Option<f64>,
}

/// The effects of the physical parameters an engine honours. A key the
/// engine does not list in its [`Engine::param_support`] is not measured:
/// the kit checks that setting it is an error naming the engine and the
/// key.
#[derive(Debug, Clone, Copy)]
pub struct Effects {
    /// Joint 2 falling with its servo off for 0.3 s: the largest ratio of
    /// the fall with `damping = 5` to the fall without.
    pub damping_ratio: f64,
    /// The same fall: the largest ratio with `armature = 0.5`.
    pub armature_ratio: f64,
    /// The rotor under a constant torque with an armature equal to its
    /// inertia: the largest gap of its angle ratio from 1/2.
    pub armature_rotor_ratio: f64,
    /// The same fall: the largest ratio with `frictionloss = 1` N m, and
    /// the largest fall with 50 N m (more than gravity's torque), rad.
    pub frictionloss: [f64; 2],
    /// Joint 2 falling without gravity, rad (the largest); with it, rad
    /// (the least).
    pub gravity_rad: [f64; 2],
    /// The least difference of scene 3's push with the cube's friction at
    /// 0 and 1, m.
    pub friction_push_m: f64,
    /// The least difference of scene 3's push with the cube at 5 kg and at
    /// its own 0.0884 kg, m.
    pub cube_mass_push_m: f64,
    /// The cube dropped from 0.2 m: the largest rebound without
    /// restitution, m.
    pub dead_bounce_m: f64,
    /// The rebound with restitution 0.5 and 0.8 over the elastic model's
    /// `e^2 h`: the least and the largest ratio.
    pub bounce_ratio: [f64; 2],
    /// The cube at rest with the softer `[contact]` parameters (time
    /// constant 0.02 s, damping ratio 1 then 2): the least sinking, m, of
    /// each against the previous (the engine's own contact first).
    pub contact_sink_m: f64,
    /// Whether the engine's own contact is the first softer one (time
    /// constant 0.02 s, damping ratio 1: MuJoCo's default `solref`): the
    /// cube then rests at the same height with and without it (1e-12 m),
    /// and the second step changes the rest height by
    /// [`Effects::contact_sink_m`] in either direction.
    pub own_contact_is_tau_0_02: bool,
}

/// How scene 1 fares at the engine's harshest or diverging settings.
#[derive(Debug, Clone, Copy)]
pub enum Divergence {
    /// These settings (`key=value`) make scene 1 diverge: the run must end
    /// as diverged.
    Diverges(&'static [&'static str]),
    /// No accepted setting makes scene 1 diverge: at the harshest (these)
    /// it completes with finite numbers.
    Completes(&'static [&'static str]),
    /// At the harshest settings (these) scene 1 completes with finite
    /// numbers or ends as diverged, never with silent numbers.
    CompletesOrDiverges(&'static [&'static str]),
}

/// Where scene 1 (joint 2 to -100 degrees, the others held at 0) ends.
#[derive(Debug, Clone, Copy)]
pub enum End {
    /// Where the velocity servos balance gravity
    /// ([`static_equilibrium_deg`]): the largest gap of any joint, deg
    /// (the law `kv (v_target - v)` yields under load).
    Equilibrium(f64),
    /// At the targets: the largest gap of any joint, deg (a stiff servo).
    Targets(f64),
}

/// Scene 3's push of the cube.
#[derive(Debug, Clone, Copy)]
pub struct Push {
    /// The least distance the cube moves along +x, m.
    pub min_x_m: f64,
    /// The window in which the cube starts moving, s (the hand reaches it
    /// at about 11.3 s in MuJoCo); `None`: not checked (an engine whose
    /// hand only grazes the cube).
    pub contact_s: Option<(f64, f64)>,
    /// Whether the cube ends at rest on one of its faces (it may tip over).
    pub ends_on_a_face: bool,
    /// The deepest the cube may sink below its rest height under the
    /// hand's push, m.
    pub max_sink_m: f64,
}

impl KitSpec {
    /// What the engine contract asks of an engine in double precision,
    /// with the study's scenes at the engine's defaults: the base of every
    /// engine's spec. Each value's reason:
    ///
    /// - kinematics: the model places the links where the URDF does, to
    ///   rounding (1e-9 m, 1e-9 rad; angles read back as set, 1e-12 rad;
    ///   continuous joints beyond a turn, 5 rad);
    /// - round trips: the native state restores the run exactly (0); the
    ///   portable state lacks warm starts and contact caches: 1e-6 m in
    ///   scene 1 (the arm in the air), 1e-3 m in scene 3 (the hand on the
    ///   cube, a push that amplifies the contact's first step);
    /// - handover: a portable state places the arm by its joint angles:
    ///   1e-6 m, the angles exactly (1e-9 rad);
    /// - effects: [`Effects::CONTRACT`]; divergence: none given (every
    ///   engine states its own);
    /// - scene 1 ends where the servos balance gravity (0.1 deg); scene 2
    ///   upright (1 mm); the iiwa's scenes end within 1 deg of the same law
    ///   (DART's check against MuJoCo); scene 3 pushes the cube over 2 cm from a contact
    ///   between 10 and 20 s.
    pub const CONTRACT: KitSpec = KitSpec {
        dynamics: true,
        takes_efforts: true,
        settings: &[],
        rotor_settings: &["timestep_s=0.001"],
        step_tolerance_rad: [2e-3, 4e-3, 2e-3],
        command_round_trip_rad: [0.0, 0.0],
        position_law: PositionLaw::Pd,
        kinematics: Kinematics {
            position_m: 1e-9,
            angle_rad: 1e-9,
            readback_rad: 1e-12,
            object_m: 1e-12,
            turn_rad: 5.0,
            after_step_rad: None,
        },
        kinematics_settings: &[],
        round_trip_m: [[0.0, 1e-6], [0.0, 1e-3]],
        handover_m: [1e-6, 1e-6],
        handover_rad: 1e-9,
        effects: Effects::CONTRACT,
        divergence: Divergence::CompletesOrDiverges(&[]),
        divergence_names_body: true,
        bad_settings: &[],
        reads_geometry: true,
        refuses_singular_inertia: false,
        refuses_massless_links: true,
        held_joints_rigid: true,
        scene1_end: End::Equilibrium(0.1),
        stock_settings: &[],
        scene2_upright_m: 1e-3,
        scene2_angle_rad: 0.01,
        scene2_cube_m: 1e-4,
        iiwa_end_deg: 1.0,
        push: Some(Push {
            min_x_m: 0.02,
            contact_s: Some((10.0, 20.0)),
            ends_on_a_face: true,
            max_sink_m: 0.002,
        }),
        free: free::FreeBody::CONTRACT,
    };
}

impl Effects {
    /// The effects the study's scenes need to show a parameter matters:
    /// damping 5 slows joint 2's fall by a tenth (0.9), armature 0.5 by a
    /// fifth (0.8); armature doubles the rotor's inertia (ratio 1/2 to
    /// 1e-3); dry friction of 1 N m slows the fall by 5 % and 50 N m holds
    /// the joint (1e-6 rad); without gravity nothing moves (1e-6 rad), with
    /// it joint 2 falls (0.05 rad); the cube's friction and mass change the
    /// push (1 cm, 5 mm); a plastic cube stays down (1 cm); restitution
    /// 0.5 and 0.8 give the elastic model's rebound `e^2 h` to a factor 2;
    /// softer contacts sink the cube by 1 mm more each.
    pub const CONTRACT: Effects = Effects {
        damping_ratio: 0.9,
        armature_ratio: 0.8,
        armature_rotor_ratio: 1e-3,
        frictionloss: [0.95, 1e-6],
        gravity_rad: [1e-6, 0.05],
        friction_push_m: 0.01,
        cube_mass_push_m: 0.005,
        dead_bounce_m: 0.01,
        bounce_ratio: [0.5, 2.0],
        contact_sink_m: 1e-3,
        own_contact_is_tau_0_02: false,
    };
}

/// Settings from `key=value` pairs (values as on the command line).
pub fn settings(pairs: &[&str]) -> EngineSettings {
    pairs
        .iter()
        .map(|p| {
            let (k, v) = p
                .split_once('=')
                .unwrap_or_else(|| panic!("setting \"{p}\" is not key=value"));
            (k.to_string(), SettingValue::parse(v))
        })
        .collect()
}

/// The settings of a check on `scene`: the scene's own `[engine.NAME]`
/// table with the spec's settings and `extra` over it.
pub fn settings_for(
    engine: &dyn Engine,
    spec: &KitSpec,
    scene: &Scene,
    extra: &[&str],
) -> EngineSettings {
    let mut s = scene.settings_for(engine.name());
    s.extend(settings(spec.settings));
    s.extend(settings(extra));
    s
}

/// The settings of the checks on the study's scenes (scene 1's table with
/// the spec's settings: every study scene has the same engine tables).
pub fn study_settings(engine: &dyn Engine, spec: &KitSpec) -> EngineSettings {
    settings_for(engine, spec, &testing::scene("scene1_single_joint"), &[])
}

/// Prints one measurement in the kit's format.
pub fn report(engine: &dyn Engine, check: &str, value: f64, tolerance: f64) {
    eprintln!(
        "CONFORMANCE engine={} check={check} value={value:e} tolerance={tolerance:e}",
        engine.name()
    );
}

/// A [`Subject`] with the study's settings, for the conformance functions.
pub fn with_subject<T>(engine: &dyn Engine, spec: &KitSpec, f: impl FnOnce(Subject<'_>) -> T) -> T {
    let settings = study_settings(engine, spec);
    f(Subject {
        engine,
        settings: &settings,
    })
}

/// Parameters from TOML text (named `/kit/params.toml` in errors).
pub fn params(text: &str) -> PhysicalParams {
    PhysicalParams::from_toml_str(text, Path::new("/kit/params.toml"))
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Loads `scene` with `robot` and `params` as a run does (core's checks
/// and [`PhysicalParams::apply`], then the engine), with the check's
/// settings.
pub fn load(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
    params: &PhysicalParams,
) -> Result<Box<dyn Simulation>, EngineError> {
    let (scene, robot) = match prepare(engine, scene, robot, params) {
        Ok(p) => p,
        Err(RunError::Engine(e)) => return Err(e),
        Err(e) => panic!("{e}"),
    };
    let settings = params.settings_over(engine.name(), settings);
    match load_prepared(
        engine,
        &scene,
        &robot,
        &settings,
        params,
        &RunOptions::default(),
    ) {
        Ok(sim) => Ok(sim),
        Err(RunError::Engine(e)) => Err(e),
        Err(e) => panic!("{e}"),
    }
}

/// Runs `scene` with `robot`, `params` and the check's settings (plus
/// `extra`); the run must complete.
pub fn run(
    engine: &dyn Engine,
    spec: &KitSpec,
    scene: &Scene,
    robot: &RobotModel,
    params: &PhysicalParams,
    extra: &[&str],
) -> RunOutcome {
    scene.validate(robot).unwrap();
    let settings = settings_for(engine, spec, scene, extra);
    let out = simulate_with(
        engine,
        scene,
        robot,
        &settings,
        params,
        &RunOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{} in {}: {e}", scene.name, engine.name()));
    assert_eq!(
        out.status,
        RunStatus::Completed,
        "{} in {}",
        scene.name,
        engine.name()
    );
    out
}

/// Whether `engine` honours `key` (its own mapping, or core's).
pub fn honours(engine: &dyn Engine, key: ParamKey) -> bool {
    key.is_core() || engine.param_support().iter().any(|s| s.key == key)
}

/// Checks that setting `text` (which sets `key`, written `field` in the
/// file) is an error naming the engine and the field, for an engine that
/// does not honour the key.
pub fn assert_refused(engine: &dyn Engine, text: &str, field: &str) {
    let p = params(text);
    let scene = testing::scene("scene1_single_joint");
    let e = match prepare(engine, &scene, &testing::mico2(), &p) {
        Err(RunError::Engine(e)) => e,
        Err(e) => panic!("{}: {field}: unexpected error {e}", engine.name()),
        Ok(_) => panic!(
            "{}: {field} was accepted, but the engine does not list it",
            engine.name()
        ),
    };
    let text = e.to_string();
    assert!(
        matches!(e, EngineError::Param { .. })
            && text.contains(&format!("engine {}", engine.name()))
            && text.contains(field),
        "{}: expected a parameter error naming the engine and {field}, got {text}",
        engine.name()
    );
    report(engine, &format!("refused {field}"), 0.0, 0.0);
}

/// The robots of a scene's checks: the project's Mico2 and, when the
/// study's recordings are there, the official Kinova model.
pub fn robots(scene: &Scene) -> Vec<(&'static str, Scene, RobotModel)> {
    let mut v = vec![("mico2", scene.clone(), testing::mico2())];
    if let Some(paper) = testing::paper_data() {
        let (s, r) = testing::with_official_robot(scene, &paper);
        v.push(("official", s, r));
    }
    v
}

/// One of the two robot models by label (`mico2`, `official`), with
/// `scene` set to it; `None` for the official one when the study's
/// recordings are missing (and allowed to be).
pub fn robot(label: &str, scene: &Scene) -> Option<(Scene, RobotModel)> {
    match label {
        "mico2" => Some((scene.clone(), testing::mico2())),
        "official" => {
            let paper = testing::paper_data()?;
            Some(testing::with_official_robot(scene, &paper))
        }
        other => panic!("no robot {other}"),
    }
}

/// The angles (degrees, actuator order) at which the scene's servos hold
/// the arm still against gravity with the given targets: each servo pushes
/// `kv * gain * (target - angle)` (rad/s from degrees), which must cancel
/// the gravity torque of [`RobotModel::gravity_torques`]. Solved by fixed
/// point from the targets (the droop is a degree or two).
pub fn static_equilibrium_deg(scene: &Scene, robot: &RobotModel, targets_deg: &[f64]) -> Vec<f64> {
    let joints: Vec<usize> = scene
        .actuators
        .iter()
        .map(|a| robot.joint_by_name(&a.joint).unwrap())
        .collect();
    let mut angles = targets_deg.to_vec();
    for _ in 0..50 {
        let mut positions = vec![0.0; robot.joints.len()];
        for (&j, a) in joints.iter().zip(&angles) {
            positions[j] = a.to_radians();
        }
        for (name, &v) in &scene.robot.held_joints_rad {
            positions[robot.joint_by_name(name).unwrap()] = v;
        }
        let torques = robot.gravity_torques(&scene.robot.base, &positions, scene.gravity_m_s2);
        angles = scene
            .actuators
            .iter()
            .zip(&joints)
            .zip(targets_deg)
            .map(|((a, &j), &t)| t + torques[j] / (a.kv * scene.controller.gain_per_s.to_radians()))
            .collect();
    }
    angles
}

/// The largest and the final distance between two runs' wrists, m.
pub fn wrist_gaps(a: &RunOutcome, b: &RunOutcome) -> (f64, f64) {
    let (wa, wb) = (testing::wrist(a), testing::wrist(b));
    let max = wa
        .iter()
        .zip(&wb)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f64::max);
    (max, wa.last().unwrap().distance(*wb.last().unwrap()))
}

/// A scratch folder of this process (removed on drop).
pub struct TempDir {
    dir: PathBuf,
}

impl TempDir {
    /// A fresh folder named after `engine` and `tag`.
    pub fn new(engine: &str, tag: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!(
            "realitygap-kit-{engine}-{tag}-{}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir { dir }
    }

    /// A path in the folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// The project's Mico2 URDF with `edit` applied, written here and read
    /// as a model.
    pub fn mico2_with(&self, edit: impl Fn(String) -> String) -> RobotModel {
        let text =
            std::fs::read_to_string(testing::workspace().join("assets/robots/mico2/mico2.urdf"))
                .unwrap();
        let path = self.dir.join("mico2.urdf");
        std::fs::write(&path, edit(text)).unwrap();
        RobotModel::from_urdf_file(&path, &PackageResolver::new()).unwrap()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

/// Where a run recorded a number that is not finite, as a message;
/// `None` when every number is finite.
pub fn non_finite(out: &RunOutcome) -> Option<String> {
    let t = &out.trajectory;
    for (i, row) in t.joint_angles_rad.iter().flatten().enumerate() {
        if row.iter().any(|a| !a.is_finite()) {
            return Some(format!("joint angles at sample {i}: {row:?}"));
        }
    }
    for (i, row) in t.joint_velocity_commands_rad_s.iter().flatten().enumerate() {
        if row.iter().any(|a| !a.is_finite()) {
            return Some(format!("velocity commands at sample {i}: {row:?}"));
        }
    }
    for b in &t.bodies {
        if let Some(i) = b
            .poses
            .iter()
            .position(|p| p.is_some_and(|p| !p.is_finite()))
        {
            return Some(format!("pose of {} at sample {i}", b.role));
        }
    }
    None
}

/// The kit: one `#[test]` per check, on `$engine` (an expression of a type
/// implementing [`Engine`]) with `$spec` (a [`KitSpec`]). Call it once in
/// an engine crate's `tests/kit.rs`.
///
/// `engine_test_kit!(grouped: $engine, $spec)` makes one `#[test]` per
/// group instead (`rotor`, `model`, `errors`, `physics`, `scenes`, `free`),
/// each running its checks in turn on one value of `$engine` (see
/// [`run_group`]): for an engine whose start costs seconds, such as one
/// out of process whose child is reused from load to load, the checks of a
/// group then share one start instead of paying one each.
#[macro_export]
macro_rules! engine_test_kit {
    ($engine:expr, $spec:expr) => {
        $crate::engine_test_kit!(@checks @tests $engine, $spec);
    };
    (grouped: $engine:expr, $spec:expr) => {
        $crate::engine_test_kit!(@checks @grouped $engine, $spec);
    };
    (@checks @$how:ident $engine:expr, $spec:expr) => {
        $crate::engine_test_kit!(@$how $engine, $spec,
            rotor {
                step_response_velocity,
                step_response_position,
                step_response_effort,
                command_round_trip,
                bad_commands
            },
            model { kinematics_mico2, kinematics_official, initial_state },
            errors {
                bad_settings,
                scene_mismatches,
                bad_robots,
                bad_angles_and_states,
                divergence
            },
            physics {
                state_round_trips,
                handover,
                damping,
                force_limit,
                cube_friction,
                unsupported_keys,
                gravity,
                armature,
                frictionloss,
                restitution,
                contact_softness,
                cube_mass,
                masses,
                self_collision
            },
            scenes {
                scene1_mico2,
                scene1_official,
                stock_settings,
                scene2_mico2,
                scene2_official,
                scene3_mico2,
                scene3_official,
                iiwa_reach,
                iiwa_push
            },
            free { free_flight, torque_free_rotation, drop_flat, slide }
        );
    };
    (@tests $engine:expr, $spec:expr, $($group:ident { $($check:ident),* }),*) => {
        $($(
            #[test]
            fn $check() {
                $crate::testing::kit::$group::$check(&$engine, &$spec);
            }
        )*)*
    };
    (@grouped $engine:expr, $spec:expr, $($group:ident { $($check:ident),* }),*) => {
        $(
            #[test]
            fn $group() {
                let engine = $engine;
                $crate::testing::kit::run_group(
                    stringify!($group),
                    &[$((stringify!($check), &|| {
                        $crate::testing::kit::$group::$check(&engine, &$spec)
                    })),*],
                );
            }
        )*
    };
}

/// Runs a group's checks in turn (the `grouped:` form of
/// [`engine_test_kit!`](crate::engine_test_kit)): each check's name, time
/// and result on stderr, every check run even after one fails, and a panic
/// at the end naming each failed check with its message.
pub fn run_group(group: &str, checks: &[(&str, &dyn Fn())]) {
    let mut failed = Vec::new();
    for (name, check) in checks {
        eprintln!("kit: {group}::{name} ...");
        let started = std::time::Instant::now();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(check));
        let took = started.elapsed().as_secs_f64();
        match result {
            Ok(()) => eprintln!("kit: {group}::{name} passed in {took:.1} s"),
            Err(panic) => {
                let message = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "(a panic without a message)".into());
                eprintln!("kit: {group}::{name} FAILED in {took:.1} s");
                failed.push(format!("{group}::{name}: {message}"));
            }
        }
    }
    assert!(
        failed.is_empty(),
        "{} of {} checks failed:\n{}",
        failed.len(),
        checks.len(),
        failed.join("\n")
    );
}

#[cfg(test)]
mod tests {
    use super::run_group;
    use std::cell::RefCell;

    #[test]
    fn a_group_runs_every_check_and_names_each_that_failed() {
        let ran = RefCell::new(Vec::new());
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_group(
                "g",
                &[
                    ("first", &|| ran.borrow_mut().push("first")),
                    ("second", &|| {
                        ran.borrow_mut().push("second");
                        panic!("gap 3 mm, 1 mm allowed")
                    }),
                    ("third", &|| ran.borrow_mut().push("third")),
                    ("fourth", &|| panic!("{} NaN", "a")),
                ],
            )
        }));
        assert_eq!(*ran.borrow(), ["first", "second", "third"]);
        let panic = result.unwrap_err();
        let message = panic.downcast_ref::<String>().unwrap();
        assert_eq!(
            message,
            "2 of 4 checks failed:\ng::second: gap 3 mm, 1 mm allowed\ng::fourth: a NaN"
        );
    }

    #[test]
    fn a_group_whose_checks_pass_returns() {
        run_group("g", &[("only", &|| ())]);
    }
}
