//! Core's conformance suite ([`realitygap_core::conformance`]) run with
//! MuJoCo. Every test prints what it measured as
//! `CONFORMANCE engine=mujoco check=... value=... tolerance=...`; the
//! tolerances are the measured values with their reasons (README).
//!
//! The scenes run at their own MuJoCo setting (timestep 1e-4 s, Euler):
//! the project's Mico2 steps at about 100k steps/s, so even the 20 s of
//! scene 3 take about 2 s.

use realitygap_core::conformance::{self as c, Subject};
use realitygap_core::controller::{prepare, RunStatus};
use realitygap_core::engine::{Engine, EngineError, EngineSettings, SettingValue};
use realitygap_core::params::PhysicalParams;
use realitygap_core::testing::{mico2, scene};
use realitygap_engine_mujoco::MujocoEngine;

fn report(check: &str, value: f64, tolerance: &str) {
    eprintln!("CONFORMANCE engine=mujoco check={check} value={value:e} tolerance={tolerance}");
}

/// The scenes' own MuJoCo settings (timestep 1e-4 s).
fn scene_settings() -> EngineSettings {
    scene("scene1_single_joint").settings_for("mujoco")
}

fn with<T>(f: impl FnOnce(Subject<'_>) -> T) -> T {
    let settings = scene_settings();
    f(Subject {
        engine: &MujocoEngine,
        settings: &settings,
    })
}

#[test]
fn native_round_trip_is_exact() {
    // Scene 1 while joint 2 swings (0.5 s in), and scene 3 during the push
    // (14.5 s in, the hand against the cube).
    for (name, k) in [("scene1_single_joint", 10), ("scene3_cube_push", 290)] {
        let gap = with(|s| c::state_round_trip(s, &scene(name), &mico2(), k, false));
        report(&format!("native_round_trip_{name}"), gap, "0");
        assert_eq!(gap, 0.0, "{name}: native round trip must be bit-identical");
    }
}

#[test]
fn portable_round_trip_is_close() {
    // Differs only by the solver's warm start (reset on a portable load):
    // the solver starts from another guess and stops within its tolerance
    // (1e-8) elsewhere. Measured 1.0e-13 m (scene 1) and 3.6e-13 m
    // (scene 3, during the push).
    for (name, k, tol) in [
        ("scene1_single_joint", 10, 1e-9),
        ("scene3_cube_push", 290, 1e-9),
    ] {
        let gap = with(|s| c::state_round_trip(s, &scene(name), &mico2(), k, true));
        report(
            &format!("portable_round_trip_{name}"),
            gap,
            &format!("{tol:e}"),
        );
        assert!(gap <= tol, "{name}: portable round trip {gap} m");
    }
}

#[test]
fn handover_into_a_fresh_simulation() {
    for (name, k) in [("scene1_single_joint", 10), ("scene3_cube_push", 290)] {
        let (gap, angles) = with(|s| c::handover_gap(s, s, &scene(name), &mico2(), k));
        report(&format!("handover_position_{name}"), gap, "1e-6");
        report(&format!("handover_angle_{name}"), angles, "0");
        assert!(gap <= 1e-6, "{name}: positions {gap} m apart");
        assert_eq!(angles, 0.0, "{name}: joint angles must arrive exactly");
    }
}

#[test]
fn damping_slows_the_fall() {
    let (free, damped) = with(|s| (c::falling_angle_rad(s, 0.0), c::falling_angle_rad(s, 5.0)));
    report("falling_angle_damping_0", free, "> damped");
    report("falling_angle_damping_5", damped, "< free / 2");
    assert!(damped < 0.5 * free, "damped {damped} rad, free {free} rad");
}

#[test]
fn force_limit_makes_joint_2_lag() {
    let gap = with(|s| c::force_limit_effect_m(s, 2.0));
    report("force_limit_effect", gap, "> 0.005");
    assert!(gap > 0.005, "{gap} m");
}

#[test]
fn cube_friction_changes_the_push() {
    let (slippery, rough) = with(|s| (c::cube_push_m(s, 0.0), c::cube_push_m(s, 1.0)));
    report(
        "cube_push_friction_0",
        slippery,
        "differs from friction 1 by > 5 mm",
    );
    report(
        "cube_push_friction_1",
        rough,
        "differs from friction 0 by > 5 mm",
    );
    assert!(
        (slippery - rough).abs() > 5e-3,
        "friction 0: {slippery} m, friction 1: {rough} m"
    );
}

#[test]
fn unsupported_key_names_engine_and_key() {
    // MuJoCo honours every key, so the suite finds none to try ...
    let found = c::unsupported_key_error(&MujocoEngine);
    report(
        "unsupported_key",
        found.iter().count() as f64,
        "0 (every key honoured)",
    );
    assert!(found.is_none(), "{found:?}");
    // ... and a key it cannot honour with its value names engine and key.
    let p = PhysicalParams::from_toml_str(
        "[objects.cube]\nrestitution = 1.0\n",
        std::path::Path::new("/conformance/params.toml"),
    )
    .unwrap();
    let scene = scene("scene1_single_joint");
    let err = match prepare(&MujocoEngine, &scene, &mico2(), &p) {
        Ok((s, r)) => MujocoEngine
            .load_with(&s, &r, &scene_settings(), &Default::default(), &p)
            .err()
            .expect("restitution 1 is refused"),
        Err(e) => panic!("{e}"),
    };
    let text = err.to_string();
    assert!(matches!(err, EngineError::Param { .. }), "{text}");
    assert!(
        text.contains("mujoco") && text.contains("objects.cube.restitution"),
        "{text}"
    );
}

#[test]
fn gravity_comes_from_the_scene() {
    let (without, with_gravity) = with(c::gravity_effect_rad);
    report("gravity_zero_moved", without, "< 1e-6");
    report("gravity_default_moved", with_gravity, "> 0.1");
    assert!(without < 1e-6, "{without} rad without gravity");
    assert!(with_gravity > 0.1, "{with_gravity} rad with gravity");
}

#[test]
fn a_coarse_timestep_diverges() {
    // One Euler step per control period (0.05 s): the kv servos are
    // explicit and far beyond their stable step.
    let mut settings = EngineSettings::new();
    settings.insert("timestep_s".into(), SettingValue::Float(0.05));
    let out = c::diverges(&MujocoEngine, &settings);
    let t = match &out.status {
        RunStatus::Diverged { t_s, .. } => *t_s,
        other => panic!("expected a divergence, got {other:?}"),
    };
    report("diverges_timestep_0.05", t, "Diverged");
}
