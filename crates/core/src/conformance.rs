//! The conformance suite every engine crate runs in its tests: what the
//! [`Engine`] / [`Simulation`] contract promises, measured the same way for
//! every engine. Each check returns the number it measured, so an engine's
//! test states its own tolerance (and the README its reason) instead of
//! the suite hiding it. Like [`crate::testing`], these panic on error, as
//! tests want; they are not for production code.
//!
//! | check | function |
//! |---|---|
//! | state round trip (save at tick k, continue to 2k; restore into a fresh simulation and continue) | [`state_round_trip`] |
//! | a state loaded into another simulation gives the same tracked positions | [`handover_gap`] |
//! | more joint damping slows a joint falling with its servo off | [`falling_angle_rad`] |
//! | a lower force limit makes joint 2 lag its target | [`force_limit_effect_m`] |
//! | cube friction changes how far the push moves the cube | [`cube_push_m`] |
//! | an unsupported parameter is an error naming engine and key | [`unsupported_key_error`] |
//! | gravity comes from the scene | [`gravity_effect_rad`] |
//! | a diverging setting ends the run as diverged | [`diverges`] |
//! | each kind of joint command (velocity, position, effort) against the analytic response of one joint | [`step_response`] |
//! | commands of every kind survive a state round trip, and switching back to velocity targets | [`command_round_trip`] |

use crate::controller::{
    load_prepared, prepare, ControlParams, ControllerLoop, RunOptions, RunOutcome, RunStatus,
};
use crate::engine::{Engine, EngineError, EngineSettings, Simulation};
use crate::params::{JointParams, ObjectParams, ParamKey, PhysicalParams};
use crate::pose::{Pose, Vec3};
use crate::robot::RobotModel;
use crate::scene::Scene;
use crate::testing;

/// An engine under test with the settings to run it at.
#[derive(Clone, Copy)]
pub struct Subject<'a> {
    /// The engine.
    pub engine: &'a dyn Engine,
    /// Its settings (e.g. a coarser timestep to keep tests fast).
    pub settings: &'a EngineSettings,
}

fn load(
    subject: Subject<'_>,
    scene: &Scene,
    robot: &RobotModel,
    params: &PhysicalParams,
) -> (Scene, Box<dyn Simulation>) {
    let (scene, robot) = prepare(subject.engine, scene, robot, params).unwrap();
    let settings = params.settings_over(subject.engine.name(), subject.settings);
    let sim = load_prepared(
        subject.engine,
        &scene,
        &robot,
        &settings,
        params,
        &RunOptions::default(),
    )
    .unwrap();
    (scene, sim)
}

fn positions(outcome: &RunOutcome, from_tick: usize) -> Vec<Vec<Vec3>> {
    let t = &outcome.trajectory;
    (from_tick..t.len())
        .map(|i| {
            t.bodies
                .iter()
                .map(|b| b.poses[i].expect("recorded pose").position_m)
                .collect()
        })
        .collect()
}

fn max_gap(a: &[Vec<Vec3>], b: &[Vec<Vec3>]) -> f64 {
    assert_eq!(a.len(), b.len(), "row counts differ");
    a.iter()
        .zip(b)
        .flat_map(|(ra, rb)| ra.iter().zip(rb).map(|(p, q)| p.distance(*q)))
        .fold(0.0, f64::max)
}

/// Runs `scene` to tick `k`, takes the state, and continues to tick `2k`;
/// loads the state into a fresh simulation (the whole state, or only its
/// portable part when `portable`) and continues that one to `2k` with the
/// same controller. Returns the largest distance between the two runs'
/// tracked positions over ticks `k..2k`, m.
pub fn state_round_trip(
    subject: Subject<'_>,
    scene: &Scene,
    robot: &RobotModel,
    k: usize,
    portable: bool,
) -> f64 {
    let params = PhysicalParams::none();
    let (scene, mut first) = load(subject, scene, robot, &params);
    let control = ControlParams::default();
    let mut run = ControllerLoop::new(&scene, &RunOptions::default(), &control);
    run.start(first.as_mut()).unwrap();
    run.advance(first.as_mut(), k).unwrap();
    let mut state = first.state().unwrap();
    if portable {
        state = state.portable();
    }
    let mut resumed_run = run.clone();
    run.advance(first.as_mut(), 2 * k).unwrap();
    let (_, mut second) = load(subject, &scene, robot, &params);
    second.set_state(&state).unwrap();
    assert!(
        (second.time_s() - state.time_s).abs() < 1e-9,
        "set_state must set the time: {} vs {}",
        second.time_s(),
        state.time_s
    );
    resumed_run.advance(second.as_mut(), 2 * k).unwrap();
    let a = run.finish();
    let b = resumed_run.finish();
    assert_eq!(a.status, RunStatus::Completed, "{:?}", a.status);
    assert_eq!(b.status, RunStatus::Completed, "{:?}", b.status);
    max_gap(&positions(&a, k), &positions(&b, k))
}

/// [`state_round_trip`] with the whole state and with its portable part
/// from one run: `scene` runs to tick `k` once, both states are taken
/// there, and each is loaded into a fresh simulation continued to `2k`.
/// Returns (native, portable) gaps, m: what two calls of
/// [`state_round_trip`] return, at two thirds of their simulation.
pub fn state_round_trips(
    subject: Subject<'_>,
    scene: &Scene,
    robot: &RobotModel,
    k: usize,
) -> (f64, f64) {
    let params = PhysicalParams::none();
    let (scene, mut first) = load(subject, scene, robot, &params);
    let control = ControlParams::default();
    let mut run = ControllerLoop::new(&scene, &RunOptions::default(), &control);
    run.start(first.as_mut()).unwrap();
    run.advance(first.as_mut(), k).unwrap();
    let native = first.state().unwrap();
    let portable = native.portable();
    let resumed = run.clone();
    run.advance(first.as_mut(), 2 * k).unwrap();
    let a = run.finish();
    assert_eq!(a.status, RunStatus::Completed, "{:?}", a.status);
    let reference = positions(&a, k);
    let gap = |state: &crate::engine::SimState| {
        let (_, mut second) = load(subject, &scene, robot, &params);
        second.set_state(state).unwrap();
        assert!(
            (second.time_s() - state.time_s).abs() < 1e-9,
            "set_state must set the time: {} vs {}",
            second.time_s(),
            state.time_s
        );
        let mut again = resumed.clone();
        again.advance(second.as_mut(), 2 * k).unwrap();
        let b = again.finish();
        assert_eq!(b.status, RunStatus::Completed, "{:?}", b.status);
        max_gap(&reference, &positions(&b, k))
    };
    (gap(&native), gap(&portable))
}

/// Runs `scene` in `from` to tick `k`, loads the portable state into a
/// fresh simulation of `to`, and returns the largest distance between the
/// tracked positions the two report right after, m. Also checks that the
/// joint angles arrive (1e-9 rad, or f32 precision for f32 engines:
/// returned in the second value, rad).
pub fn handover_gap(
    from: Subject<'_>,
    to: Subject<'_>,
    scene: &Scene,
    robot: &RobotModel,
    k: usize,
) -> (f64, f64) {
    let params = PhysicalParams::none();
    let (scene, mut a) = load(from, scene, robot, &params);
    let mut run = ControllerLoop::new(&scene, &RunOptions::default(), &ControlParams::default());
    run.start(a.as_mut()).unwrap();
    run.advance(a.as_mut(), k).unwrap();
    let state = a.state().unwrap().portable();
    let (_, mut b) = load(to, &scene, robot, &params);
    b.set_state(&state).unwrap();
    let mut pa = vec![Pose::IDENTITY; scene.tracked.len()];
    let mut pb = pa.clone();
    a.tracked_poses(&mut pa);
    b.tracked_poses(&mut pb);
    let gap = pa
        .iter()
        .zip(&pb)
        .map(|(p, q)| p.position_m.distance(q.position_m))
        .fold(0.0, f64::max);
    let mut qa = vec![0.0; scene.actuators.len()];
    let mut qb = qa.clone();
    a.joint_angles_rad(&mut qa);
    b.joint_angles_rad(&mut qb);
    let angle_gap = qa
        .iter()
        .zip(&qb)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    (gap, angle_gap)
}

/// Every servo off (force limit 0), joint 2 started at -0.5 rad and left
/// to fall under gravity for 0.3 s with `damping` N m s/rad on it: how far
/// joint 2 moved, rad.
pub fn falling_angle_rad(subject: Subject<'_>, damping: f64) -> f64 {
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let mut params = motors_off(&scene);
    params
        .joints
        .entry("m1n6s300_joint_2".into())
        .or_default()
        .damping = Some(damping);
    free_fall(subject, &scene, &robot, &params)
}

fn motors_off(scene: &Scene) -> PhysicalParams {
    let mut params = PhysicalParams::none();
    for a in &scene.actuators {
        params.joints.insert(
            a.joint.clone(),
            JointParams {
                force_limit: Some(0.0),
                ..JointParams::default()
            },
        );
    }
    params
}

fn free_fall(
    subject: Subject<'_>,
    scene: &Scene,
    robot: &RobotModel,
    params: &PhysicalParams,
) -> f64 {
    let (_, mut sim) = load(subject, scene, robot, params);
    let mut start = vec![0.0; scene.actuators.len()];
    start[1] = -0.5;
    sim.set_joint_angles_rad(&start).unwrap();
    sim.set_joint_velocity_targets(&vec![0.0; start.len()]);
    let steps = (0.3 / sim.timestep_s()).round() as u64;
    sim.step_n(steps).unwrap();
    let mut q = vec![0.0; start.len()];
    sim.joint_angles_rad(&mut q);
    (q[1] - start[1]).abs()
}

/// Scene 1 to 1.5 s with joint 2's force limit at `limit` N m and without
/// it: the distance between the two wrists at 1.5 s, m.
pub fn force_limit_effect_m(subject: Subject<'_>, limit: f64) -> f64 {
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let mut limited = PhysicalParams::none();
    limited.joints.insert(
        "m1n6s300_joint_2".into(),
        JointParams {
            force_limit: Some(limit),
            ..JointParams::default()
        },
    );
    let wrist = |params: &PhysicalParams| {
        let (scene, mut sim) = load(subject, &scene, &robot, params);
        let mut run =
            ControllerLoop::new(&scene, &RunOptions::default(), &ControlParams::default());
        run.start(sim.as_mut()).unwrap();
        run.advance(sim.as_mut(), 31).unwrap();
        let out = run.finish();
        out.trajectory.positions("wrist")[30].expect("wrist at 1.5 s")
    };
    wrist(&limited).distance(wrist(&PhysicalParams::none()))
}

/// Scene 3 with the cube's friction coefficient at `friction`: the cube's
/// final displacement along x, m.
pub fn cube_push_m(subject: Subject<'_>, friction: f64) -> f64 {
    let scene = testing::scene("scene3_cube_push");
    let robot = testing::mico2();
    let mut params = PhysicalParams::none();
    params.objects.insert(
        "cube".into(),
        ObjectParams {
            friction: Some(friction),
            ..ObjectParams::default()
        },
    );
    let (scene, mut sim) = load(subject, &scene, &robot, &params);
    let mut run = ControllerLoop::new(&scene, &RunOptions::default(), &ControlParams::default());
    run.start(sim.as_mut()).unwrap();
    run.advance(sim.as_mut(), usize::MAX).unwrap();
    let out = run.finish();
    assert_eq!(out.status, RunStatus::Completed, "{:?}", out.status);
    let cube = out.trajectory.positions("cube");
    let first = cube[0].expect("cube at start");
    let last = cube[cube.len() - 1].expect("cube at end");
    last.x - first.x
}

/// A parameter key that neither core nor the engine honours, set in a
/// file, and the error loading it gives; `None` when the engine honours
/// every key.
pub fn unsupported_key_error(engine: &dyn Engine) -> Option<(ParamKey, EngineError)> {
    let support = engine.param_support();
    let key = ParamKey::ALL
        .into_iter()
        .find(|k| !k.is_core() && !support.iter().any(|s| s.key == *k))?;
    let text = match key {
        ParamKey::JointDamping => "[joints.m1n6s300_joint_2]\ndamping = 1.0\n",
        ParamKey::JointArmature => "[joints.m1n6s300_joint_2]\narmature = 0.01\n",
        ParamKey::JointFrictionloss => "[joints.m1n6s300_joint_2]\nfrictionloss = 0.1\n",
        ParamKey::JointKv => "[joints.m1n6s300_joint_2]\nkv = 40.0\n",
        ParamKey::JointForceLimit => "[joints.m1n6s300_joint_2]\nforce_limit = 30.0\n",
        ParamKey::LinkMassScale => "[links.m1n6s300_link_3]\nmass_scale = 1.1\n",
        ParamKey::ObjectMass => "[objects.cube]\nmass_kg = 0.1\n",
        ParamKey::ObjectFriction => "[objects.cube]\nfriction = 0.5\n",
        ParamKey::ObjectRestitution => "[objects.cube]\nrestitution = 0.1\n",
        ParamKey::ContactTimeConstant => "[contact]\ntime_constant_s = 0.02\n",
        ParamKey::ContactDampingRatio => "[contact]\ndamping_ratio = 1.0\n",
        _ => unreachable!("core keys are honoured by every engine"),
    };
    let params =
        PhysicalParams::from_toml_str(text, std::path::Path::new("/conformance/params.toml"))
            .unwrap();
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    match prepare(engine, &scene, &robot, &params) {
        Err(crate::controller::RunError::Engine(e)) => Some((key, e)),
        Err(e) => panic!("unexpected error for {key}: {e}"),
        Ok(_) => panic!(
            "engine {} loaded {key}, which its param_support does not list",
            engine.name()
        ),
    }
}

/// Every servo off, joint 2 started at -0.5 rad: how far it moves in 0.3 s
/// with the scene's gravity set to zero (first value) and at the default
/// (second), rad.
pub fn gravity_effect_rad(subject: Subject<'_>) -> (f64, f64) {
    let mut scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let params = motors_off(&scene);
    let with = free_fall(subject, &scene, &robot, &params);
    scene.gravity_m_s2 = Vec3::new(0.0, 0.0, 0.0);
    let without = free_fall(subject, &scene, &robot, &params);
    (without, with)
}

/// Runs scene 1 at `settings` (meant to be unstable) and returns the run:
/// the caller asserts it ended as [`RunStatus::Diverged`].
pub fn diverges(engine: &dyn Engine, settings: &EngineSettings) -> RunOutcome {
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    // Meant to be unstable: run it even when the engine knows it is.
    let options = RunOptions {
        allow_unstable: true,
        ..RunOptions::default()
    };
    crate::controller::simulate(engine, &scene, &robot, settings, &options).unwrap()
}

/// The rotor of the step-response checks: one revolute joint about the
/// vertical (so gravity exerts no torque on it), a disc of known inertia.
const ROTOR_URDF: &str = r#"<?xml version="1.0"?>
<robot name="rotor">
  <link name="base">
    <inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="spin" type="revolute">
    <parent link="base"/><child link="disc"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.0" upper="3.0" effort="50" velocity="100"/>
  </joint>
  <link name="disc">
    <inertial><origin xyz="0 0 0"/><mass value="2.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0"/><geometry><box size="0.1 0.1 0.02"/></geometry></collision>
  </link>
</robot>
"#;

/// The rotor's inertia about its axis, kg m^2.
pub const ROTOR_INERTIA_KG_M2: f64 = 0.01;
/// The rotor servo's velocity gain, N m s/rad (time constant I/kv = 0.1 s).
pub const ROTOR_KV: f64 = 0.1;
/// The rotor servo's position gain, N m/rad (with kv: natural frequency
/// 10 rad/s, damping ratio 0.5).
pub const ROTOR_KP: f64 = 1.0;

/// The rotor scene and robot (files in a temporary folder of this process).
pub fn rotor() -> (Scene, RobotModel) {
    let dir = std::env::temp_dir().join(format!("realitygap-rotor-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = dir.join("rotor.urdf");
    if !urdf.is_file() {
        let tmp = dir.join(format!("rotor.urdf.{:?}", std::thread::current().id()));
        std::fs::write(&tmp, ROTOR_URDF).unwrap();
        std::fs::rename(&tmp, &urdf).unwrap();
    }
    let text = format!(
        r#"
name = "rotor"
description = "one joint about the vertical, for the servo step responses"
duration_s = 1.0
[robot]
urdf = "rotor.urdf"
base_position_m = [0.0, 0.0, 0.0]
[controller]
gain_per_s = 1.0
max_speed_deg_s = 1.0
period_s = 0.01
[[actuator]]
joint = "spin"
kv = {ROTOR_KV:?}
kp = {ROTOR_KP:?}
force_limit = 50.0
[[schedule]]
t_s = 0.0
targets_deg = {{}}
[[track]]
role = "disc"
link = "disc"
"#
    );
    let scene = Scene::from_toml_str(&text, &dir.join("rotor.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&urdf, &crate::robot::PackageResolver::new()).unwrap();
    (scene, robot)
}

/// The law an engine's position servo follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PositionLaw {
    /// The PD law `I q'' = kp (q* - q) - kv q'`.
    Pd,
    /// A velocity constraint `q' = (kp / kv)(q* - q)` (Bullet's
    /// `POSITION_CONTROL` motor with positionGain `kp dt / kv`): first
    /// order, time constant `kv / kp`.
    FirstOrder,
    /// Perfect tracking: the joint is at the target at once (the
    /// physics-free model).
    Instant,
}

/// The rotor's angle at `t_s` under the position step through a servo of
/// `law`, rad.
pub fn rotor_position_rad(law: PositionLaw, t_s: f64) -> f64 {
    match law {
        PositionLaw::Pd => rotor_analytic_rad(crate::trajectory::CommandKind::Position, t_s),
        PositionLaw::FirstOrder => STEP_POSITION_RAD * (1.0 - (-t_s * ROTOR_KP / ROTOR_KV).exp()),
        PositionLaw::Instant => STEP_POSITION_RAD,
    }
}

/// The rotor's analytic angle at `t_s` under a step command of `kind`
/// from rest at 0 (see [`step_response`]), rad.
pub fn rotor_analytic_rad(kind: crate::trajectory::CommandKind, t_s: f64) -> f64 {
    use crate::trajectory::CommandKind;
    let i = ROTOR_INERTIA_KG_M2;
    match kind {
        CommandKind::Velocity => {
            // I v' = kv (v* - v): v = v* (1 - e^(-t/T)), T = I / kv.
            let tau = i / ROTOR_KV;
            STEP_VELOCITY_RAD_S * (t_s - tau * (1.0 - (-t_s / tau).exp()))
        }
        CommandKind::Position => {
            // I q'' = kp (q* - q) - kv q', under-damped.
            let w = (ROTOR_KP / i).sqrt();
            let z = ROTOR_KV / (2.0 * (ROTOR_KP * i).sqrt());
            let wd = w * (1.0 - z * z).sqrt();
            STEP_POSITION_RAD
                * (1.0
                    - (-z * w * t_s).exp()
                        * ((wd * t_s).cos() + z / (1.0 - z * z).sqrt() * (wd * t_s).sin()))
        }
        CommandKind::Effort => STEP_EFFORT_NM * t_s * t_s / (2.0 * i),
    }
}

/// The velocity step of [`step_response`], rad/s.
pub const STEP_VELOCITY_RAD_S: f64 = 1.0;
/// The position step, rad.
pub const STEP_POSITION_RAD: f64 = 0.5;
/// The effort step, N m (the rotor turns 1 rad in 1 s).
pub const STEP_EFFORT_NM: f64 = 0.02;

/// What [`step_response`] measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepResponse {
    /// The largest gap between the engine's angle and the analytic one
    /// over the second, rad.
    pub max_error_rad: f64,
    /// The gap at the end of the second, rad.
    pub final_error_rad: f64,
    /// The analytic angle at the end of the second, rad (the scale).
    pub final_rad: f64,
}

/// The rotor ([`rotor`]) from rest at 0 under one step command of `kind`
/// for 1 s ([`STEP_VELOCITY_RAD_S`], [`STEP_POSITION_RAD`] or
/// [`STEP_EFFORT_NM`]) through [`Simulation::set_joint_commands`], against
/// the analytic response of the law ([`rotor_analytic_rad`]).
pub fn step_response(subject: Subject<'_>, kind: crate::trajectory::CommandKind) -> StepResponse {
    step_response_with(subject, kind, PositionLaw::Pd)
}

/// [`step_response`] with the position step compared with `law`'s
/// response.
pub fn step_response_with(
    subject: Subject<'_>,
    kind: crate::trajectory::CommandKind,
    law: PositionLaw,
) -> StepResponse {
    use crate::engine::ServoCommand;
    use crate::trajectory::CommandKind;
    let (scene, robot) = rotor();
    let (_, mut sim) = load(subject, &scene, &robot, &PhysicalParams::none());
    let command = match kind {
        CommandKind::Velocity => ServoCommand::velocity(STEP_VELOCITY_RAD_S),
        CommandKind::Position => ServoCommand::position(STEP_POSITION_RAD),
        CommandKind::Effort => ServoCommand::effort(STEP_EFFORT_NM),
    };
    sim.set_joint_commands(&[command]).unwrap();
    let reference = |t: f64| match kind {
        CommandKind::Position => rotor_position_rad(law, t),
        _ => rotor_analytic_rad(kind, t),
    };
    let dt = sim.timestep_s();
    let steps = (1.0 / dt).round() as u64;
    let mut q = [0.0];
    let mut max_error: f64 = 0.0;
    let mut last = 0.0;
    for k in 1..=steps {
        sim.step().unwrap();
        sim.joint_angles_rad(&mut q);
        last = (q[0] - reference(k as f64 * dt)).abs();
        max_error = max_error.max(last);
    }
    StepResponse {
        max_error_rad: max_error,
        final_error_rad: last,
        final_rad: reference(steps as f64 * dt),
    }
}

/// The rotor under a position command for 0.3 s, then its state (with the
/// commands in force) taken and loaded into a fresh simulation (the whole
/// state, or only its portable part when `portable`), both continued 0.3
/// s; then both switched to an effort command for 0.2 s, and both back to
/// a velocity target of 0 for 0.2 s. Returns the largest gap between the
/// two angles over the continuation, rad, and asserts the state reports
/// the position command.
pub fn command_round_trip(subject: Subject<'_>, portable: bool) -> f64 {
    command_round_trip_with(subject, portable, true)
}

/// [`command_round_trip`]; without `efforts` the middle phase is a
/// velocity command (for an engine that takes no efforts).
pub fn command_round_trip_with(subject: Subject<'_>, portable: bool, efforts: bool) -> f64 {
    use crate::engine::ServoCommand;
    use crate::trajectory::CommandKind;
    let (scene, robot) = rotor();
    let (_, mut a) = load(subject, &scene, &robot, &PhysicalParams::none());
    a.set_joint_commands(&[ServoCommand::position(STEP_POSITION_RAD)])
        .unwrap();
    let dt = a.timestep_s();
    let steps = |s: f64| (s / dt).round() as u64;
    a.step_n(steps(0.3)).unwrap();
    let mut state = a.state().unwrap();
    assert_eq!(
        state.servo_commands,
        vec![ServoCommand::position(STEP_POSITION_RAD)],
        "the state carries the command in force"
    );
    if portable {
        state = state.portable();
    }
    let (_, mut b) = load(subject, &scene, &robot, &PhysicalParams::none());
    b.set_state(&state).unwrap();
    let mut gap: f64 = 0.0;
    let (mut qa, mut qb) = ([0.0], [0.0]);
    let mut phase = |a: &mut Box<dyn Simulation>, b: &mut Box<dyn Simulation>, n: u64| {
        for _ in 0..n {
            a.step().unwrap();
            b.step().unwrap();
            a.joint_angles_rad(&mut qa);
            b.joint_angles_rad(&mut qb);
            gap = gap.max((qa[0] - qb[0]).abs());
        }
    };
    phase(&mut a, &mut b, steps(0.3));
    for sim in [&mut a, &mut b] {
        if efforts {
            sim.set_joint_commands(&[ServoCommand::effort(-STEP_EFFORT_NM)])
                .unwrap();
            assert_eq!(
                sim.state().unwrap().servo_commands[0].kind,
                CommandKind::Effort
            );
        } else {
            sim.set_joint_commands(&[ServoCommand::velocity(-STEP_VELOCITY_RAD_S)])
                .unwrap();
        }
    }
    phase(&mut a, &mut b, steps(0.2));
    for sim in [&mut a, &mut b] {
        sim.set_joint_velocity_targets(&[0.0]);
        assert!(
            sim.state().unwrap().servo_commands.is_empty(),
            "velocity targets again: no other commands in the state"
        );
    }
    phase(&mut a, &mut b, steps(0.2));
    gap
}

/// A position command to a joint without a position gain, and a command
/// of the wrong count: the errors the engine gives (both must be errors).
pub fn bad_commands(subject: Subject<'_>) -> (EngineError, EngineError) {
    use crate::engine::ServoCommand;
    let (mut scene, robot) = rotor();
    scene.actuators[0].kp = None;
    let (_, mut sim) = load(subject, &scene, &robot, &PhysicalParams::none());
    let no_gain = sim
        .set_joint_commands(&[ServoCommand::position(0.1)])
        .expect_err("a position command without kp is an error");
    let count = sim
        .set_joint_commands(&[ServoCommand::effort(0.1), ServoCommand::effort(0.1)])
        .expect_err("two commands for one joint is an error");
    (no_gain, count)
}
