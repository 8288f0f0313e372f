//! The effect of each engine-mapped parameter key in DART: armature slows
//! a falling joint as the reflected inertia it is, frictionloss holds a
//! joint against a small torque, restitution makes the cube bounce, and
//! mass and friction of the cube change the push.

mod common;

use common::*;
use realitygap_core::controller::{load_prepared, prepare, RunOptions};
use realitygap_core::engine::{EngineSettings, ServoCommand, Simulation};
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::Pose;
use realitygap_core::scene::Scene;
use realitygap_engine_dart::DartEngine;
use std::path::Path;

fn report(check: &str, value: f64, tolerance: &str) {
    eprintln!("CONFORMANCE engine=dart check={check} value={value} tolerance={tolerance}");
}

fn load(s: &Scene, toml: &str) -> Box<dyn Simulation> {
    let params = PhysicalParams::from_toml_str(toml, Path::new("/params/params.toml")).unwrap();
    let (s, robot) = prepare(&DartEngine, s, &mico2(), &params).unwrap();
    load_prepared(
        &DartEngine,
        &s,
        &robot,
        &EngineSettings::new(),
        &params,
        &RunOptions::default(),
    )
    .unwrap()
}

/// Joint 2 falling for 0.3 s from -0.5 rad, every servo off, with `extra`
/// on joint 2: how far it moved, rad.
fn fall_with(extra: &str) -> f64 {
    let mut toml = String::new();
    for j in 1..=6 {
        toml.push_str(&format!("[joints.m1n6s300_joint_{j}]\nforce_limit = 0.0\n"));
        if j == 2 {
            toml.push_str(extra);
        }
    }
    let mut sim = load(&scene("scene1_single_joint"), &toml);
    let start = [0.0, -0.5, 0.0, 0.0, 0.0, 0.0];
    sim.set_joint_angles_rad(&start).unwrap();
    sim.step_n(300).unwrap();
    let mut q = [0.0; 6];
    sim.joint_angles_rad(&mut q);
    (q[1] - start[1]).abs()
}

/// Armature is reflected inertia: on the rotor (inertia 0.01 kg m^2) an
/// armature of 0.01 halves the acceleration of a constant torque, exactly
/// (the emulation through DART's implicit damping adds the armature to
/// the joint's projected inertia); on the arm it slows the fall.
#[test]
fn armature_is_reflected_inertia() {
    let plain = fall_with("");
    let heavy = fall_with("armature = 0.5\n");
    report("armature_fall_0_rad", plain, "> with armature");
    report("armature_fall_0.5_rad", heavy, "< 0.8 without");
    assert!(
        heavy < plain * 0.8,
        "armature 0.5: {heavy} rad, none: {plain} rad"
    );

    let (rotor, robot) = realitygap_core::conformance::rotor();
    let angle = |armature: f64| {
        let params = PhysicalParams::from_toml_str(
            &format!("[joints.spin]\narmature = {armature:?}\n"),
            Path::new("/params/params.toml"),
        )
        .unwrap();
        let (s, r) = prepare(&DartEngine, &rotor, &robot, &params).unwrap();
        let mut sim = load_prepared(
            &DartEngine,
            &s,
            &r,
            &EngineSettings::new(),
            &params,
            &RunOptions::default(),
        )
        .unwrap();
        sim.set_joint_commands(&[ServoCommand::effort(0.02)])
            .unwrap();
        sim.step_n(1000).unwrap();
        let mut q = [0.0];
        sim.joint_angles_rad(&mut q);
        q[0]
    };
    let (free, loaded) = (angle(0.0), angle(0.01));
    report("armature_rotor_ratio", loaded / free, "0.5");
    assert!((loaded / free - 0.5).abs() < 1e-9, "{loaded} / {free}");
}

/// Dry friction (frictionloss, DART's joint Coulomb friction constraint)
/// holds joint 2 against gravity when it exceeds the gravity torque, and
/// slows it when it does not.
#[test]
fn frictionloss_holds_the_joint() {
    let free = fall_with("");
    let some = fall_with("frictionloss = 1.0\n");
    let stuck = fall_with("frictionloss = 50.0\n");
    report("frictionloss_fall_0_rad", free, "> 1 N m");
    report("frictionloss_fall_1_rad", some, "< free");
    report("frictionloss_fall_50_rad", stuck, "< 1e-9");
    assert!(some < free * 0.95, "{some} vs {free}");
    assert!(stuck < 1e-9, "{stuck}");
}

/// The rotor (inertia 0.01 kg m^2, no gravity torque) sliding under a
/// stiff velocity servo (kv 10, 1 rad/s asked) against dry friction of 2
/// N m: its steady rate is 1 - 2 / 10 = 0.8 rad/s at any timestep. DART's
/// friction constraint does not see the servo's implicit damping, so
/// without the shim's correction it took 1 + dt kv / I times the friction
/// (0.6 rad/s at 1 ms, 0.75 at 0.25 ms).
#[test]
fn friction_beside_the_servo_does_not_depend_on_the_timestep() {
    let (rotor, robot) = realitygap_core::conformance::rotor();
    let rate = |timestep_s: f64| {
        let params = PhysicalParams::from_toml_str(
            "[joints.spin]\nkv = 10.0\nfrictionloss = 2.0\n",
            Path::new("/params/params.toml"),
        )
        .unwrap();
        let (s, r) = prepare(&DartEngine, &rotor, &robot, &params).unwrap();
        let mut settings = EngineSettings::new();
        settings.insert(
            "timestep_s".into(),
            realitygap_core::engine::SettingValue::Float(timestep_s),
        );
        let mut sim = load_prepared(
            &DartEngine,
            &s,
            &r,
            &settings,
            &params,
            &RunOptions::default(),
        )
        .unwrap();
        sim.set_joint_commands(&[ServoCommand::velocity(1.0)])
            .unwrap();
        let steps = (0.2 / timestep_s).round() as u64;
        sim.step_n(steps).unwrap();
        let mut a = [0.0];
        sim.joint_angles_rad(&mut a);
        sim.step_n(steps).unwrap();
        let mut b = [0.0];
        sim.joint_angles_rad(&mut b);
        (b[0] - a[0]) / 0.2
    };
    for dt in [0.005, 0.001, 0.00025] {
        let v = rate(dt);
        report(&format!("friction_servo_rate_dt_{dt}"), v, "0.8 rad/s");
        assert!((v - 0.8).abs() < 0.002, "at {dt} s: {v} rad/s");
    }
}

/// The cube dropped from 0.2 m above its rest: the highest it climbs after
/// its first impact, m.
fn bounce_m(toml: &str) -> f64 {
    let mut sim = load(&scene("scene3_cube_push"), toml);
    let mut state = sim.state().unwrap().portable();
    let rest = state.objects[0].pose.position_m.z;
    let p = state.objects[0].pose.position_m;
    state.objects[0].pose = Pose::new(
        realitygap_core::Vec3::new(p.x, p.y, rest + 0.2),
        state.objects[0].pose.orientation,
    );
    sim.set_state(&state).unwrap();
    let (mut fell, mut top) = (false, f64::NEG_INFINITY);
    for _ in 0..1000 {
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
    report("bounce_restitution0.8_m", lively, "0.1..0.14");
    assert!(dead < 0.01, "{dead} m");
    assert!((0.1..0.14).contains(&lively), "{lively} m");
}

/// A heavier cube moves less under the same push.
#[test]
fn cube_mass_changes_the_push() {
    let push = |toml: &str| {
        let params = PhysicalParams::from_toml_str(toml, Path::new("/params/params.toml")).unwrap();
        let out = realitygap_core::controller::simulate_with(
            &DartEngine,
            &scene("scene3_cube_push"),
            &mico2(),
            &EngineSettings::new(),
            &params,
            &RunOptions::default(),
        )
        .unwrap();
        let c = cube(&out);
        c.last().unwrap().x - c[0].x
    };
    let light = push("");
    let heavy = push("[objects.cube]\nmass_kg = 5.0\n");
    report("cube_push_0.0884kg_m", light, "differs");
    report("cube_push_5kg_m", heavy, "differs");
    assert!((light - heavy).abs() > 0.005, "{light} vs {heavy}");
}
