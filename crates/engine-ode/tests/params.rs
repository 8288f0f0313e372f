//! The physical parameters in ODE: each key the engine lists changes what
//! it says it changes, by the amount the mapping predicts (on the
//! pendulum of `common`, whose dynamics are known in closed form, and on
//! the cube of scene 1), and a force limit read from a file makes the
//! wrist lag in scene 1.

mod common;

use common::*;
use realitygap_core::controller::{simulate_with, RunOptions, RunStatus};
use realitygap_core::engine::{EngineError, Simulation};
use realitygap_core::params::PhysicalParams;
use realitygap_engine_ode::OdeSimulation;

/// Angular acceleration of the pendulum from rest over its first steps,
/// rad/s^2 (semi-implicit Euler: the mean velocity over steps 2-5 minus
/// that of step 1, over 2.5 steps).
fn acceleration(sim: &mut OdeSimulation) -> f64 {
    sim.set_joint_velocity_targets(&[0.0]);
    let v1 = velocity_over(sim, 1);
    let v5 = velocity_over(sim, 4);
    (v5 - v1) / (2.5 * sim.timestep_s())
}

fn pendulum_with(tag: &str, pairs: &[&str], text: &str) -> OdeSimulation {
    let p = pendulum(tag, 100.0, 1.0);
    load_with_params(&p.scene, &p.robot, pairs, &params(text)).unwrap()
}

/// The pendulum with its servo off (force limit 0) and `hinge_lines`
/// more parameters of its joint.
fn free_pendulum(tag: &str, hinge_lines: &str) -> OdeSimulation {
    pendulum_with(
        tag,
        &[],
        &format!("[joints.hinge]\nforce_limit = 0.0\n{hinge_lines}"),
    )
}

/// Issue 10's must-show: `[joints.m1n6s300_joint_2] force_limit = 2.0`
/// read from a file moves the wrist at 1.5 s by more than 5 mm.
#[test]
fn force_limit_from_a_file_makes_the_wrist_lag() {
    let dir = std::env::temp_dir().join(format!("realitygap-ode-params-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("p.toml");
    std::fs::write(&file, "[joints.m1n6s300_joint_2]\nforce_limit = 2.0\n").unwrap();
    let limited = PhysicalParams::from_file(&file).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let settings = s.settings_for("ode");
    let wrist_at_1_5_s = |p: &PhysicalParams| {
        let out = simulate_with(
            &realitygap_engine_ode::OdeEngine,
            &s,
            &robot,
            &settings,
            p,
            &RunOptions::default(),
        )
        .unwrap();
        assert_eq!(out.status, RunStatus::Completed);
        wrist(&out)[30]
    };
    let gap = wrist_at_1_5_s(&limited).distance(wrist_at_1_5_s(&PhysicalParams::none()));
    eprintln!(
        "wrist at 1.5 s with joint 2 limited to 2 N m: {:.1} mm away",
        gap * 1e3
    );
    assert!(gap > 0.005, "{gap} m");
}

/// Armature adds to the joint's inertia: with the servo off and an
/// armature equal to the pendulum's own inertia it accelerates half as
/// fast.
#[test]
fn armature_adds_to_the_joint_inertia() {
    let free = acceleration(&mut free_pendulum("arm0", ""));
    let heavy = acceleration(&mut free_pendulum(
        "arm1",
        &format!("armature = {PENDULUM_INERTIA}\n"),
    ));
    let expected = PENDULUM_TORQUE_NM / (2.0 * PENDULUM_INERTIA);
    eprintln!("acceleration {free} rad/s^2 free, {heavy} with armature (expected {expected})");
    assert!(
        (free - 2.0 * expected).abs() < 0.02 * 2.0 * expected,
        "{free}"
    );
    assert!((heavy - expected).abs() < 0.02 * expected, "{heavy}");
}

/// Damping is an implicit damper: with the servo off the pendulum
/// settles at torque / damping at once, even with a damping (10 N m s/rad)
/// whose time constant (1 ms) is far below the timestep, which an explicit
/// damping torque would blow up on.
#[test]
fn damping_gives_the_terminal_velocity() {
    let mut sim = free_pendulum("damp", "damping = 10.0\n");
    sim.set_joint_velocity_targets(&[0.0]);
    sim.step_n(3).unwrap();
    let v = velocity_over(&mut sim, 10);
    let expected = PENDULUM_TORQUE_NM / 10.0;
    eprintln!("terminal velocity {v} rad/s, expected {expected}");
    assert!((v - expected).abs() < 0.02 * expected, "{v}");
}

/// Frictionloss is a torque the joint must overcome: 2 N m holds the
/// pendulum (0.981 N m of gravity), 0.5 N m leaves it the difference.
#[test]
fn frictionloss_resists_up_to_its_torque() {
    let mut held = free_pendulum("fric2", "frictionloss = 2.0\n");
    held.set_joint_velocity_targets(&[0.0]);
    let v = velocity_over(&mut held, 20);
    assert!(v.abs() < 1e-4, "held pendulum moves at {v} rad/s");
    let slipping = acceleration(&mut free_pendulum("fric05", "frictionloss = 0.5\n"));
    let expected = (PENDULUM_TORQUE_NM - 0.5) / PENDULUM_INERTIA;
    eprintln!("acceleration with 0.5 N m friction {slipping}, expected {expected}");
    assert!((slipping - expected).abs() < 0.02 * expected, "{slipping}");
}

/// `kv` is the motor's gain with `servo = "kv"`: the loaded pendulum
/// creeps at torque / kv; with the stiff default motor it is an error.
#[test]
fn kv_sets_the_servo_gain_or_is_refused() {
    let mut sim = pendulum_with("kv", &["servo=kv"], "[joints.hinge]\nkv = 20.0\n");
    sim.set_joint_velocity_targets(&[0.0]);
    sim.step_n(10).unwrap();
    let v = velocity_over(&mut sim, 10);
    let expected = PENDULUM_TORQUE_NM / 20.0;
    assert!(
        (v - expected).abs() < 0.01 * expected,
        "creeps at {v}, expected {expected}"
    );

    let p = pendulum("kv-motor", 100.0, 1.0);
    let e = load_with_params(
        &p.scene,
        &p.robot,
        &[],
        &params("[joints.hinge]\nkv = 20.0\n"),
    )
    .err()
    .expect("kv with servo = motor is refused");
    let text = e.to_string();
    assert!(matches!(e, EngineError::Param { .. }), "{text}");
    assert!(
        text.contains("engine ode")
            && text.contains("joints.hinge.kv")
            && text.contains("servo = \"kv\""),
        "{text}"
    );
}

/// `mass_scale` scales the link's body: twice the mass sags the kv servo
/// twice as fast.
#[test]
fn mass_scale_scales_the_link() {
    let mut sim = pendulum_with("mass", &["servo=kv"], "[links.arm]\nmass_scale = 2.0\n");
    sim.set_joint_velocity_targets(&[0.0]);
    sim.step_n(10).unwrap();
    let v = velocity_over(&mut sim, 10);
    let expected = 2.0 * PENDULUM_TORQUE_NM / 10.0;
    assert!(
        (v - expected).abs() < 0.01 * expected,
        "creeps at {v}, expected {expected}"
    );
}

/// Passive keys on a joint ODE holds rigid are refused, naming the key.
#[test]
fn passive_keys_need_a_controlled_joint() {
    for field in ["damping", "armature", "frictionloss"] {
        let text = format!("[joints.m1n6s300_joint_finger_1]\n{field} = 0.1\n");
        let e = load_with_params(&scene("scene1_single_joint"), &mico2(), &[], &params(&text))
            .err()
            .expect("refused");
        let msg = e.to_string();
        assert!(
            msg.contains(&format!("joints.m1n6s300_joint_finger_1.{field}"))
                && msg.contains("rigid"),
            "{msg}"
        );
    }
}

/// The cube of scene 1 (the arm holding still): its centre height after
/// each step for `seconds`, m, starting `lift_m` above its scene pose.
fn cube_heights(pairs: &[&str], text: &str, lift_m: f64, seconds: f64) -> Vec<f64> {
    let mut s = scene("scene1_single_joint");
    s.objects[0].pose.position_m.z += lift_m;
    let mut sim = load_with_params(&s, &mico2(), pairs, &params(text)).unwrap();
    sim.set_joint_velocity_targets(&[0.0; 6]);
    let steps = (seconds / sim.timestep_s()).round() as usize;
    (0..steps)
        .map(|_| {
            sim.step().unwrap();
            sim.state().unwrap().objects[0].pose.position_m.z
        })
        .collect()
}

/// The cube's resting centre height in scene 1, m.
const CUBE_REST_Z: f64 = 0.0375;

/// Restitution: the cube dropped from 10 cm bounces back to about e^2 of
/// the height; without it, it stays down.
#[test]
fn restitution_makes_the_cube_bounce() {
    let rebound = |text: &str| {
        let z = cube_heights(&[], text, 0.1, 1.0);
        let first_low = z.windows(2).position(|w| w[1] > w[0]).expect("it lands");
        z[first_low..].iter().fold(f64::MIN, |m, &h| m.max(h)) - CUBE_REST_Z
    };
    let plastic = rebound("");
    let half = rebound("[objects.cube]\nrestitution = 0.5\n");
    eprintln!(
        "rebound from 0.1 m: {plastic} m without restitution, {half} m with 0.5 (e^2 h = 0.025 m)"
    );
    assert!(plastic < 1e-3, "{plastic}");
    assert!((half - 0.025).abs() < 0.2 * 0.025, "{half}");
}

/// Contact softness: the resting cube sinks by g (zeta tc)^2, the static
/// deflection of the spring-damper the parameters describe; ODE's default
/// contact (ERP 0.2, CFM 1e-5) sinks by less than a micrometre.
#[test]
fn contact_softness_sets_the_rest_sink() {
    let sink = |text: &str| CUBE_REST_Z - cube_heights(&[], text, 0.0, 1.0).last().unwrap();
    let stiff = sink("");
    let soft = sink("[contact]\ntime_constant_s = 0.02\n");
    let underdamped = sink("[contact]\ntime_constant_s = 0.02\ndamping_ratio = 0.5\n");
    let expected = |tc: f64, zeta: f64| 9.81 * (zeta * tc).powi(2);
    eprintln!(
        "rest sink: default {stiff:e} m, tc 0.02 s {soft:e} m (expected {:e}), zeta 0.5 {underdamped:e} m (expected {:e})",
        expected(0.02, 1.0),
        expected(0.02, 0.5)
    );
    assert!(stiff.abs() < 1e-6, "{stiff}");
    assert!(
        (soft - expected(0.02, 1.0)).abs() < 0.03 * expected(0.02, 1.0),
        "{soft}"
    );
    assert!(
        (underdamped - expected(0.02, 0.5)).abs() < 0.03 * expected(0.02, 0.5),
        "{underdamped}"
    );
}

/// Object mass reaches ODE: on the default contacts (a stiff spring of
/// ERP / (dt CFM) per point) the resting cube sinks in proportion to its
/// weight.
#[test]
fn object_mass_sets_the_weight() {
    let sink = |text: &str| CUBE_REST_Z - cube_heights(&[], text, 0.0, 1.0).last().unwrap();
    let light = sink("[objects.cube]\nmass_kg = 0.1\n");
    let heavy = sink("[objects.cube]\nmass_kg = 10.0\n");
    eprintln!("rest sink {light:e} m at 0.1 kg, {heavy:e} m at 10 kg");
    assert!(light > 0.0, "{light}");
    assert!((heavy / light - 100.0).abs() < 5.0, "{}", heavy / light);
}
