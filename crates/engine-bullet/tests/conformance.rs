//! Core's conformance suite with Bullet, each check with the tolerance
//! measured for this engine (see the README's "Conformance" section), and
//! the effects of the parameters Bullet maps itself.

mod common;

use common::*;
use realitygap_core::conformance::{self, Subject};
use realitygap_core::controller::{prepare, simulate_with, RunOptions, RunStatus};
use realitygap_core::engine::{
    Engine, EngineError, EngineSettings, ModelVariation, SettingValue, SimState, Simulation,
};
use realitygap_core::params::{ParamKey, PhysicalParams};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_bullet::BulletEngine;
use std::path::Path;

fn report(check: &str, value: f64, tolerance: &str) {
    eprintln!("CONFORMANCE engine=bullet check={check} value={value} tolerance={tolerance}");
}

fn subject(settings: &EngineSettings) -> Subject<'_> {
    Subject {
        engine: &BulletEngine,
        settings,
    }
}

fn params(text: &str) -> PhysicalParams {
    PhysicalParams::from_toml_str(text, Path::new("/test/params.toml")).unwrap()
}

/// Native round trip on scene 3 (the cube rests on the ground throughout,
/// so there are contact manifolds to carry), saved at 10 s, compared over
/// 10..20 s (the push included).
#[test]
fn native_round_trip_is_exact() {
    let s = EngineSettings::new();
    let gap = conformance::state_round_trip(
        subject(&s),
        &scene("scene3_cube_push"),
        &mico2(),
        200,
        false,
    );
    report("state_round_trip_native", gap, "0 (exact)");
    assert_eq!(gap, 0.0, "native round trip gap {gap} m");
}

/// The portable round trip: no contact manifolds (warm starts) carry over,
/// so the solver starts the cube's contacts from zero impulses.
#[test]
fn portable_round_trip() {
    let s = EngineSettings::new();
    let gap =
        conformance::state_round_trip(subject(&s), &scene("scene3_cube_push"), &mico2(), 200, true);
    report("state_round_trip_portable", gap, "1e-3 m");
    assert!(gap <= 1e-3, "portable round trip gap {gap} m");
}

/// Scene 1 has the cube resting on the table: its contact impulses (the
/// solver's warm start) are not in the portable state, and Bullet solves
/// every constraint of the world in one loop, so the arm's motors see it.
/// Without the cube the portable state carries almost everything.
#[test]
fn portable_round_trip_scene1_with_and_without_the_cube() {
    let s = EngineSettings::new();
    let mut scene1 = scene("scene1_single_joint");
    let with = conformance::state_round_trip(subject(&s), &scene1, &mico2(), 40, true);
    report("state_round_trip_portable_scene1", with, "1e-3 m");
    assert!(with <= 1e-3, "{with}");
    scene1.objects.clear();
    scene1.tracked.retain(|t| t.role != "cube");
    let without = conformance::state_round_trip(subject(&s), &scene1, &mico2(), 40, true);
    report(
        "state_round_trip_portable_scene1_no_cube",
        without,
        "1e-6 m",
    );
    assert!(without <= 1e-6, "{without}");
}

#[test]
fn handover_into_a_fresh_bullet() {
    let s = EngineSettings::new();
    for (name, k) in [("scene1_single_joint", 40), ("scene3_cube_push", 300)] {
        let (gap, angles) =
            conformance::handover_gap(subject(&s), subject(&s), &scene(name), &mico2(), k);
        report(&format!("handover_{name}"), gap, "1e-6 m");
        report(&format!("handover_angles_{name}"), angles, "1e-9 rad");
        assert!(gap <= 1e-6, "{name}: {gap} m");
        assert!(angles <= 1e-9, "{name}: {angles} rad");
    }
}

#[test]
fn unsupported_key_is_an_error_naming_engine_and_key() {
    let (key, e) = conformance::unsupported_key_error(&BulletEngine).expect("Bullet lacks keys");
    let text = e.to_string();
    eprintln!("{key}: {text}");
    report("unsupported_key_error", 1.0, "error names engine and key");
    assert!(matches!(e, EngineError::Param { .. }), "{e:?}");
    assert!(text.contains("bullet"), "{text}");
    assert!(text.contains(&key_name(key)), "{text}");
}

fn key_name(key: ParamKey) -> String {
    key.pattern().replace("<joint>", "m1n6s300_joint_2")
}

#[test]
fn a_diverging_setting_ends_as_diverged() {
    // A constraint force mixing so large that no constraint holds: the
    // cube sinks through the table (Bullet's multibody solver is otherwise
    // hard to blow up: 0.05 s steps, ERP 1, one solver iteration all
    // complete scene 1).
    let settings: EngineSettings = [("global_cfm".to_string(), SettingValue::Float(1e6))]
        .into_iter()
        .collect();
    let out = conformance::diverges(&BulletEngine, &settings);
    eprintln!("{:?}", out.status);
    let diverged = matches!(out.status, RunStatus::Diverged { .. });
    report("diverges", diverged as u8 as f64, "1 (diverged)");
    assert!(diverged, "{:?}", out.status);
}

/// `--params` with `force_limit = 2.0` on joint 2, read from a file.
#[test]
fn force_limit_from_a_parameters_file() {
    let dir = std::env::temp_dir().join(format!("realitygap-bullet-params-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("p.toml");
    std::fs::write(&file, "[joints.m1n6s300_joint_2]\nforce_limit = 2.0\n").unwrap();
    let p = PhysicalParams::from_file(&file).unwrap();
    let (s, r) = (scene("scene1_single_joint"), mico2());
    let none = EngineSettings::new();
    let opts = RunOptions::default();
    let a = simulate_with(&BulletEngine, &s, &r, &none, &p, &opts).unwrap();
    let b = simulate_with(&BulletEngine, &s, &r, &none, &PhysicalParams::none(), &opts).unwrap();
    let gap = wrist(&a)[30].distance(wrist(&b)[30]);
    eprintln!("wrist at 1.5 s moved {gap} m by force_limit = 2");
    assert!(gap > 0.005, "{gap}");
    // The parameter wins over the max_force_n_m setting.
    let set: EngineSettings = [("max_force_n_m".to_string(), SettingValue::Float(1000.0))]
        .into_iter()
        .collect();
    let c = simulate_with(&BulletEngine, &s, &r, &set, &p, &opts).unwrap();
    assert!(wrist(&c)[30].distance(wrist(&a)[30]) < 1e-9);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Loads `scene` with `params` through core's prepare, as `run` does.
fn load(scene: &Scene, params: &PhysicalParams) -> Box<dyn Simulation> {
    let (s, r) = prepare(&BulletEngine, scene, &mico2(), params).unwrap();
    BulletEngine
        .load_with(
            &s,
            &r,
            &EngineSettings::new(),
            &ModelVariation::default(),
            params,
        )
        .unwrap()
}

/// The cube dropped from `height_m` (bottom face above the ground) with
/// the arm at rest: the highest its centre gets after the first impact,
/// above its resting height, m.
fn rebound_m(params: &PhysicalParams, height_m: f64) -> f64 {
    let scene = scene("scene3_cube_push");
    let mut sim = load(&scene, params);
    let mut state: SimState = sim.state().unwrap().portable();
    state.objects[0].pose.position_m.z += height_m;
    sim.set_state(&state).unwrap();
    let mut poses = vec![realitygap_core::Pose::IDENTITY; 2];
    let (mut fallen, mut best) = (false, f64::NEG_INFINITY);
    let mut last_z = f64::INFINITY;
    for _ in 0..150 {
        sim.step().unwrap();
        sim.tracked_poses(&mut poses);
        let z = poses[1].position_m.z - 0.0375;
        if !fallen && z > last_z {
            fallen = true; // moving up again: the first impact is over
        }
        if fallen {
            best = best.max(z);
        }
        last_z = z;
    }
    best.max(0.0)
}

#[test]
fn restitution_makes_the_cube_bounce() {
    let at = |r: f64| {
        rebound_m(
            &params(&format!("[objects.cube]\nrestitution = {r:?}\n")),
            0.2,
        )
    };
    let (plastic, half, elastic) = (at(0.0), at(0.5), at(0.9));
    let default = rebound_m(&PhysicalParams::none(), 0.2);
    eprintln!("rebound from 0.2 m: restitution 0 {plastic} m, 0.5 {half} m, 0.9 {elastic} m, none {default} m");
    assert!(plastic < 0.005, "{plastic}");
    assert!(default < 0.005, "{default}");
    assert!(half > 0.01 && elastic > half, "{half} {elastic}");
}

/// Height of the cube's centre after 1 s at rest on the ground, m.
fn resting_height_m(params: &PhysicalParams) -> f64 {
    let mut sim = load(&scene("scene3_cube_push"), params);
    sim.step_n(100).unwrap();
    let mut poses = vec![realitygap_core::Pose::IDENTITY; 2];
    sim.tracked_poses(&mut poses);
    poses[1].position_m.z
}

/// A soft contact (long time constant) lets the cube sink into the ground.
/// At rest Bullet's box-plane manifold holds two points (two opposite
/// corners, measured), each a spring k = m / tc^2 (Bullet's rows give
/// exactly F = k * penetration at rest), so the cube sinks by m g / (2 k)
/// = g tc^2 / 2 (12.3 mm at tc = 0.05 s).
#[test]
fn contact_softness_changes_the_penetration() {
    let rigid = resting_height_m(&PhysicalParams::none());
    let soft = resting_height_m(&params(
        "[contact]\ntime_constant_s = 0.05\ndamping_ratio = 1.0\n",
    ));
    let expected = 9.81 * 0.05 * 0.05 / 2.0;
    eprintln!("cube centre at rest: rigid {rigid} m, tc 0.05 s {soft} m; sink {} m, expected {expected} m", rigid - soft);
    assert!((rigid - 0.0375).abs() < 2e-3, "{rigid}");
    assert!(
        ((rigid - soft) - expected).abs() < 0.02 * expected,
        "{rigid} {soft}"
    );
}

/// Joint 2 falling with its servo off: dry friction slows it, and with the
/// servo on frictionloss is a parameter error.
#[test]
fn frictionloss_acts_with_the_servo_off_and_is_refused_with_it_on() {
    let s = scene("scene1_single_joint");
    let off: String = s
        .actuators
        .iter()
        .map(|a| format!("[joints.{}]\nforce_limit = 0.0\n", a.joint))
        .collect();
    let fall = |extra: &str| {
        let text = off.replace(
            "[joints.m1n6s300_joint_2]\nforce_limit = 0.0\n",
            &format!("[joints.m1n6s300_joint_2]\nforce_limit = 0.0\n{extra}"),
        );
        let mut sim = load(&s, &params(&text));
        let mut q = vec![0.0; 6];
        q[1] = -0.5;
        sim.set_joint_angles_rad(&q).unwrap();
        sim.step_n(30).unwrap();
        sim.joint_angles_rad(&mut q);
        (q[1] + 0.5).abs()
    };
    let free = fall("");
    let rubbing = fall("frictionloss = 1.0\n");
    let stuck = fall("frictionloss = 50.0\n");
    eprintln!("joint 2 fell {free} rad free, {rubbing} rad with 1 N m, {stuck} rad with 50 N m");
    assert!(rubbing < free * 0.95, "{free} {rubbing}");
    assert!(stuck < 1e-6, "{stuck}");
    let on = params("[joints.m1n6s300_joint_2]\nfrictionloss = 1.0\n");
    let (sc, r) = prepare(&BulletEngine, &s, &mico2(), &on).unwrap();
    let e = BulletEngine
        .load_with(
            &sc,
            &r,
            &EngineSettings::new(),
            &ModelVariation::default(),
            &on,
        )
        .err()
        .unwrap();
    assert!(matches!(e, EngineError::Param { .. }), "{e:?}");
    assert!(
        e.to_string()
            .contains("joints.m1n6s300_joint_2.frictionloss"),
        "{e}"
    );
}

/// `links.L.mass_scale` reaches Bullet's link mass.
#[test]
fn mass_scale_reaches_bullet() {
    use realitygap_engine_bullet::BulletSimulation;
    let p = params("[links.m1n6s300_link_3]\nmass_scale = 2.0\n");
    let s = scene("scene1_single_joint");
    let (sc, r) = prepare(&BulletEngine, &s, &mico2(), &p).unwrap();
    let none = EngineSettings::new();
    let v = ModelVariation::default();
    let mut scaled = BulletSimulation::load_with(&sc, &r, &none, &v, &p).unwrap();
    let mut plain = BulletSimulation::load(&s, &mico2(), &none, &v).unwrap();
    let (m2, _) = scaled
        .mass_and_friction("m1n6s300_link_3")
        .unwrap()
        .unwrap();
    let (m1, _) = plain.mass_and_friction("m1n6s300_link_3").unwrap().unwrap();
    assert!((m2 - 2.0 * m1).abs() < 1e-12, "{m1} {m2}");
}

/// Issue 10 item 6: a robot read from a string (the CLI's built-in Mico2,
/// whose `source` is not a file) loads, and runs as the file does.
#[test]
fn a_built_in_robot_loads_and_matches_the_file() {
    let path = workspace().join("assets/robots/mico2/mico2.urdf");
    let text = std::fs::read_to_string(&path).unwrap();
    let built_in = RobotModel::from_urdf_str(
        &text,
        Path::new("mico2.urdf (built in)"),
        &PackageResolver::new(),
    )
    .unwrap();
    let s = scene("scene1_single_joint");
    let none = EngineSettings::new();
    let opts = RunOptions::default();
    let p = PhysicalParams::none();
    let a = simulate_with(&BulletEngine, &s, &built_in, &none, &p, &opts).unwrap();
    let b = simulate_with(&BulletEngine, &s, &mico2(), &none, &p, &opts).unwrap();
    assert_eq!(a.status, RunStatus::Completed);
    let gap = gaps(&wrist(&a), &wrist(&b)).into_iter().fold(0.0, f64::max);
    eprintln!("built-in vs file: largest wrist gap {gap} m");
    assert!(gap < 1e-5, "{gap}");
    let first = wrist(&a)[0].distance(wrist(&b)[0]);
    eprintln!("built-in vs file at t = 0: {first} m");
    assert!(first < 1e-12, "{first}");
}

/// `position_servo = "pd_control"`: PyBullet's PD_CONTROL, the explicit PD
/// law, on the kit's rotor against the law's analytic response (the
/// default POSITION_CONTROL is the kit's first-order law).
#[test]
fn pd_control_follows_the_pd_law() {
    let settings =
        realitygap_core::testing::kit::settings(&["timestep_s=0.001", "position_servo=pd_control"]);
    let r = conformance::step_response(
        Subject {
            engine: &BulletEngine,
            settings: &settings,
        },
        realitygap_core::trajectory::CommandKind::Position,
    );
    report("step_response_position_pd_control", r.max_error_rad, "6e-3");
    assert!(r.max_error_rad < 6e-3, "{r:?}");
}
