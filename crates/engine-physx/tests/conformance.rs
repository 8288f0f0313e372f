//! The core conformance suite (`realitygap_core::conformance`) run with
//! PhysX, each check with the tolerance measured for this engine (the
//! crate README gives the numbers and the reasons), and the effect of each
//! engine-mapped parameter key.

use realitygap_core::conformance::{self, Subject};
use realitygap_core::controller::{
    load_prepared, prepare, simulate_with, RunOptions, RunOutcome, RunStatus,
};
use realitygap_core::engine::{EngineError, EngineSettings, SettingValue, Simulation};
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::Pose;
use realitygap_core::testing::{mico2, scene};
use realitygap_engine_physx::PhysxEngine;
use std::path::Path;

fn report(check: &str, value: impl std::fmt::Display, tolerance: &str) {
    eprintln!("CONFORMANCE engine=physx check={check} value={value} tolerance={tolerance}");
}

fn subject(settings: &EngineSettings) -> Subject<'_> {
    Subject {
        engine: &PhysxEngine,
        settings,
    }
}

/// Round trip of scene 1 taken at 2 s (the arm in the air, the cube
/// resting on the table): PhysX's state is portable only, and setting it
/// rebuilds the world. The continued runs agree to 1.8e-7 m (measured):
/// single-precision state read back and set again.
#[test]
fn round_trip_scene1() {
    let settings = EngineSettings::new();
    for portable in [false, true] {
        let gap = conformance::state_round_trip(
            subject(&settings),
            &scene("scene1_single_joint"),
            &mico2(),
            40,
            portable,
        );
        report(
            &format!("round_trip_scene1_portable_{portable}"),
            gap,
            "1e-6",
        );
        assert!(gap <= 1e-6, "round trip of scene 1 moved {gap} m");
    }
}

/// Scene 3 taken at 12 s, while the hand pushes the cube: PhysX's contact
/// manifolds are not numbers of the state, so the restored run starts its
/// contacts afresh: the runs end 0.39 mm apart (measured; the push is
/// sensitive, see the README, hence the tolerance).
#[test]
fn round_trip_scene3_while_pushing() {
    let settings = EngineSettings::new();
    let gap = conformance::state_round_trip(
        subject(&settings),
        &scene("scene3_cube_push"),
        &mico2(),
        240,
        false,
    );
    report("round_trip_scene3", gap, "0.005");
    assert!(gap <= 0.005, "round trip of scene 3 moved {gap} m");
}

#[test]
fn handover_into_a_fresh_physx() {
    let settings = EngineSettings::new();
    let s = subject(&settings);
    for (name, k) in [("scene1_single_joint", 40), ("scene3_cube_push", 240)] {
        let (gap, angles) = conformance::handover_gap(s, s, &scene(name), &mico2(), k);
        report(&format!("handover_{name}_m"), gap, "1e-6");
        report(&format!("handover_{name}_rad"), angles, "1e-6");
        assert!(
            gap <= 1e-6,
            "{name}: positions {gap} m apart after the handover"
        );
        assert!(
            angles <= 1e-6,
            "{name}: angles {angles} rad apart after the handover"
        );
    }
}

/// PhysX to MuJoCo and MuJoCo to PhysX: the tracked positions and joint
/// angles carry over (to single precision).
#[test]
fn handover_with_mujoco_both_ways() {
    let physx_settings = EngineSettings::new();
    let s1 = scene("scene1_single_joint");
    let mujoco_settings = s1.settings_for("mujoco");
    let physx = subject(&physx_settings);
    let mujoco = Subject {
        engine: &realitygap_engine_mujoco::MujocoEngine,
        settings: &mujoco_settings,
    };
    for (label, from, to) in [
        ("physx_to_mujoco", physx, mujoco),
        ("mujoco_to_physx", mujoco, physx),
    ] {
        let (gap, angles) = conformance::handover_gap(from, to, &s1, &mico2(), 40);
        report(&format!("handover_{label}_m"), gap, "1e-5");
        report(&format!("handover_{label}_rad"), angles, "1e-5");
        assert!(gap <= 1e-5, "{label}: positions {gap} m apart");
        assert!(angles <= 1e-5, "{label}: angles {angles} rad apart");
    }
}

#[test]
fn more_damping_slows_the_fall() {
    let settings = EngineSettings::new();
    let free = conformance::falling_angle_rad(subject(&settings), 0.0);
    let damped = conformance::falling_angle_rad(subject(&settings), 5.0);
    report("falling_angle_damping0_rad", free, "> damped");
    report("falling_angle_damping5_rad", damped, "< free");
    assert!(free > 0.05, "joint 2 fell only {free} rad without damping");
    assert!(
        damped < free * 0.9,
        "damping 5: {damped} rad, none: {free} rad"
    );
}

#[test]
fn force_limit_makes_joint_2_lag() {
    let settings = EngineSettings::new();
    let d = conformance::force_limit_effect_m(subject(&settings), 2.0);
    report("force_limit_effect_m", d, "> 0.005");
    assert!(d > 0.005, "force limit 2 N m moved the wrist {d} m");
}

#[test]
fn cube_friction_changes_the_push() {
    let settings = EngineSettings::new();
    let slippery = conformance::cube_push_m(subject(&settings), 0.0);
    let rough = conformance::cube_push_m(subject(&settings), 1.0);
    report("cube_push_friction0_m", slippery, "differs");
    report("cube_push_friction1_m", rough, "differs");
    report("cube_push_difference_m", (slippery - rough).abs(), "> 0.01");
    assert!(
        (slippery - rough).abs() > 0.01,
        "friction 0: {slippery} m, friction 1: {rough} m"
    );
}

/// PhysX has no constant joint friction torque and no `[contact]`
/// softness: those keys are errors naming the engine and the key; a key
/// set where it would have no effect (damping on a held finger joint) too.
#[test]
fn unsupported_and_meaningless_keys_are_errors() {
    let (key, e) = conformance::unsupported_key_error(&PhysxEngine).expect("an unsupported key");
    report(
        "unsupported_key",
        format!("{key}: {e}"),
        "names engine and key",
    );
    let text = e.to_string();
    assert!(
        text.contains("physx") && text.contains("frictionloss"),
        "{text}"
    );
    for toml in [
        "[contact]\ntime_constant_s = 0.02\n",
        "[contact]\ndamping_ratio = 1.0\n",
    ] {
        let params =
            PhysicalParams::from_toml_str(toml, Path::new("/conformance/params.toml")).unwrap();
        let e = prepare(
            &PhysxEngine,
            &scene("scene1_single_joint"),
            &mico2(),
            &params,
        )
        .map(|_| ())
        .expect_err("refused")
        .to_string();
        assert!(e.contains("physx") && e.contains("contact."), "{e}");
    }
    let params = PhysicalParams::from_toml_str(
        "[joints.m1n6s300_joint_finger_1]\ndamping = 1.0\n",
        Path::new("/conformance/params.toml"),
    )
    .unwrap();
    let e = load_error(&params);
    report(
        "meaningless_key_error",
        format!("{e:?}"),
        "names engine and key",
    );
    match &e {
        EngineError::Param { engine, key, .. } => {
            assert_eq!(engine, "physx");
            assert_eq!(key, "joints.m1n6s300_joint_finger_1.damping");
        }
        other => panic!("{other:?}"),
    }
    let params = PhysicalParams::from_toml_str(
        "[links.m1n6s300_link_base]\nmass_scale = 2.0\n",
        Path::new("/conformance/params.toml"),
    )
    .unwrap();
    let e = load_error(&params).to_string();
    assert!(
        e.contains("physx") && e.contains("links.m1n6s300_link_base.mass_scale"),
        "{e}"
    );
}

fn load_error(params: &PhysicalParams) -> EngineError {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let (s, robot) = prepare(&PhysxEngine, &s, &robot, params).unwrap();
    match load_prepared(
        &PhysxEngine,
        &s,
        &robot,
        &EngineSettings::new(),
        params,
        &RunOptions::default(),
    ) {
        Err(realitygap_core::controller::RunError::Engine(e)) => e,
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("loaded"),
    }
}

#[test]
fn gravity_comes_from_the_scene() {
    let settings = EngineSettings::new();
    let (without, with) = conformance::gravity_effect_rad(subject(&settings));
    report("gravity_zero_moved_rad", without, "1e-6");
    report("gravity_default_moved_rad", with, "> 0.05");
    assert!(without < 1e-6, "moved {without} rad without gravity");
    assert!(with > 0.05, "moved only {with} rad with gravity");
}

/// The harshest accepted settings (the longest timestep the control
/// period allows, one position iteration, no velocity iteration) and a
/// cube launched at 1e30 m/s: the run ends as diverged, not averaged in.
#[test]
fn divergence_is_reported() {
    let mut settings = EngineSettings::new();
    for (k, v) in [
        ("timestep_s", SettingValue::Float(0.05)),
        ("position_iterations", SettingValue::Integer(1)),
        ("velocity_iterations", SettingValue::Integer(0)),
    ] {
        settings.insert(k.to_string(), v);
    }
    let out = conformance::diverges(&PhysxEngine, &settings);
    report(
        "diverges_harshest_settings",
        format!("{:?}", out.status),
        "Completed or Diverged, never a silent number",
    );
    assert!(matches!(
        out.status,
        RunStatus::Completed | RunStatus::Diverged { .. }
    ));

    let s = scene("scene1_single_joint");
    let mut sim = realitygap_engine_physx::PhysxSimulation::load(
        &s,
        &mico2(),
        &EngineSettings::new(),
        &Default::default(),
    )
    .unwrap();
    let mut state = sim.state().unwrap();
    state.objects[0].linear_velocity_m_s = realitygap_core::Vec3::new(1e15, 0.0, 0.0);
    sim.set_state(&state).unwrap();
    let out = realitygap_core::controller::run_scene(&mut sim, &s, &RunOptions::default()).unwrap();
    report(
        "diverges_cube_at_1e15_m_s",
        format!("{:?}", out.status),
        "Diverged",
    );
    assert!(
        matches!(out.status, RunStatus::Diverged { .. }),
        "{:?}",
        out.status
    );
}

fn wrist_at(out: &RunOutcome, tick: usize) -> realitygap_core::Vec3 {
    out.trajectory.positions("wrist")[tick].expect("wrist recorded")
}

fn run(scene_name: &str, toml: &str) -> RunOutcome {
    let params =
        PhysicalParams::from_toml_str(toml, Path::new("/conformance/params.toml")).unwrap();
    let out = simulate_with(
        &PhysxEngine,
        &scene(scene_name),
        &mico2(),
        &EngineSettings::new(),
        &params,
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(out.status, RunStatus::Completed, "{:?}", out.status);
    out
}

/// A parameters file with joint 2's force limit at 2 N m moves the wrist
/// at 1.5 s by more than 5 mm.
#[test]
fn params_file_force_limit_moves_the_wrist() {
    let base = run("scene1_single_joint", "");
    let limited = run(
        "scene1_single_joint",
        "[joints.m1n6s300_joint_2]\nforce_limit = 2.0\n",
    );
    let d = wrist_at(&base, 30).distance(wrist_at(&limited, 30));
    report("params_file_force_limit_m", d, "> 0.005");
    assert!(d > 0.005, "{d} m");
}

/// Joint 2 falling with its servo off for 0.3 s, with `armature`.
fn fall_with(extra: &str) -> f64 {
    let mut toml = String::new();
    for j in 1..=6 {
        toml.push_str(&format!("[joints.m1n6s300_joint_{j}]\nforce_limit = 0.0\n"));
        if j == 2 {
            toml.push_str(extra);
        }
    }
    let params =
        PhysicalParams::from_toml_str(&toml, Path::new("/conformance/params.toml")).unwrap();
    let s = scene("scene1_single_joint");
    let (s, robot) = prepare(&PhysxEngine, &s, &mico2(), &params).unwrap();
    let mut sim = load_prepared(
        &PhysxEngine,
        &s,
        &robot,
        &EngineSettings::new(),
        &params,
        &RunOptions::default(),
    )
    .unwrap();
    let start = [0.0, -0.5, 0.0, 0.0, 0.0, 0.0];
    sim.set_joint_angles_rad(&start).unwrap();
    sim.step_n(60).unwrap();
    let mut q = [0.0; 6];
    sim.joint_angles_rad(&mut q);
    (q[1] - start[1]).abs()
}

#[test]
fn armature_slows_the_fall() {
    let plain = fall_with("");
    let heavy = fall_with("armature = 0.5\n");
    report("armature_fall_0_rad", plain, "> with armature");
    report("armature_fall_0.5_rad", heavy, "< without");
    assert!(
        heavy < plain * 0.8,
        "armature 0.5: {heavy} rad, none: {plain} rad"
    );
}

/// The cube dropped from 0.2 m: the highest it climbs after its first
/// impact, m above its resting height.
fn bounce_m(toml: &str) -> f64 {
    let params =
        PhysicalParams::from_toml_str(toml, Path::new("/conformance/params.toml")).unwrap();
    let s = scene("scene3_cube_push");
    let (s, robot) = prepare(&PhysxEngine, &s, &mico2(), &params).unwrap();
    let mut sim = load_prepared(
        &PhysxEngine,
        &s,
        &robot,
        &EngineSettings::new(),
        &params,
        &RunOptions::default(),
    )
    .unwrap();
    let mut state = sim.state().unwrap().portable();
    let rest = state.objects[0].pose.position_m.z;
    let p = state.objects[0].pose.position_m;
    state.objects[0].pose = Pose::new(
        realitygap_core::Vec3::new(p.x, p.y, rest + 0.2),
        state.objects[0].pose.orientation,
    );
    sim.set_state(&state).unwrap();
    let (mut fell, mut top) = (false, f64::NEG_INFINITY);
    for _ in 0..200 {
        sim.step().unwrap();
        let z = sim.state().unwrap().objects[0].pose.position_m.z - rest;
        if z < 0.01 {
            fell = true;
        } else if fell {
            top = top.max(z);
        }
    }
    top.max(0.0)
}

#[test]
fn restitution_makes_the_cube_bounce() {
    let dead = bounce_m("");
    let lively = bounce_m("[objects.cube]\nrestitution = 0.8\n");
    // Elastic to 0.8: back up to 0.8^2 x 0.2 m = 0.128 m.
    report("bounce_restitution0_m", dead, "< 0.01");
    report("bounce_restitution0.8_m", lively, "> 0.05");
    assert!(dead < 0.01, "{dead} m");
    assert!(lively > 0.05, "{lively} m");
}
