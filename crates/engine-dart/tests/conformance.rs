//! The core conformance suite (`realitygap_core::conformance`) run with
//! DART, each check with the tolerance measured for this engine (the crate
//! README gives the numbers and the reasons).

mod common;

use common::*;
use realitygap_core::conformance::{self, Subject};
use realitygap_core::controller::{load_prepared, prepare, RunOptions, RunStatus};
use realitygap_core::engine::{EngineError, EngineSettings, Simulation};
use realitygap_core::params::PhysicalParams;
use realitygap_core::trajectory::CommandKind;
use realitygap_engine_dart::{DartEngine, DartSimulation};
use std::path::Path;

fn report(check: &str, value: impl std::fmt::Display, tolerance: &str) {
    eprintln!("CONFORMANCE engine=dart check={check} value={value} tolerance={tolerance}");
}

fn subject(settings: &EngineSettings) -> Subject<'_> {
    Subject {
        engine: &DartEngine,
        settings,
    }
}

/// Scene 1 taken at 2 s (the arm moving, the cube at rest on the table)
/// and scene 3 at 12 s (the hand pushing the cube), restored into a fresh
/// simulation: the native state is DART's own coordinates, and nothing
/// else carries over a step (contacts are found afresh, the LCP starts
/// cold), so the continuation is exact. The portable state holds the same
/// joint coordinates; only the cube's free-joint coordinates go through a
/// pose (rounding).
#[test]
fn state_round_trips() {
    let settings = EngineSettings::new();
    for (name, k) in [("scene1_single_joint", 40), ("scene3_cube_push", 240)] {
        for portable in [false, true] {
            let gap = conformance::state_round_trip(
                subject(&settings),
                &scene(name),
                &mico2(),
                k,
                portable,
            );
            let what = if portable { "portable" } else { "native" };
            report(&format!("round_trip_{name}_{what}"), gap, "see assert");
            if portable {
                assert!(gap <= 1e-9, "{name}: portable round trip moved {gap} m");
            } else {
                assert_eq!(gap, 0.0, "{name}: native round trip moved {gap} m");
            }
        }
    }
}

#[test]
fn handover_into_a_fresh_dart() {
    let settings = EngineSettings::new();
    let s = subject(&settings);
    for (name, k) in [("scene1_single_joint", 40), ("scene3_cube_push", 240)] {
        let (gap, angles) = conformance::handover_gap(s, s, &scene(name), &mico2(), k);
        report(&format!("handover_{name}_m"), gap, "1e-12");
        report(&format!("handover_{name}_rad"), angles, "0");
        assert!(gap <= 1e-12, "{name}: positions {gap} m apart");
        assert_eq!(angles, 0.0, "{name}: angles {angles} rad apart");
    }
}

/// DART to MuJoCo and MuJoCo to DART: both take the joint angles as their
/// coordinates, so the tracked positions carry over to rounding.
#[test]
fn handover_with_mujoco_both_ways() {
    let dart_settings = EngineSettings::new();
    for name in ["scene1_single_joint", "scene3_cube_push"] {
        let s = scene(name);
        let mujoco_settings = s.settings_for("mujoco");
        let dart = subject(&dart_settings);
        let mujoco = Subject {
            engine: &realitygap_engine_mujoco::MujocoEngine,
            settings: &mujoco_settings,
        };
        let k = if name == "scene1_single_joint" {
            40
        } else {
            240
        };
        for (label, from, to) in [
            ("dart_to_mujoco", dart, mujoco),
            ("mujoco_to_dart", mujoco, dart),
        ] {
            let (gap, angles) = conformance::handover_gap(from, to, &s, &mico2(), k);
            report(&format!("handover_{name}_{label}_m"), gap, "1e-6");
            report(&format!("handover_{name}_{label}_rad"), angles, "1e-9");
            assert!(gap <= 1e-6, "{name} {label}: positions {gap} m apart");
            assert!(angles <= 1e-9, "{name} {label}: angles {angles} rad apart");
        }
    }
}

fn load_error(params: &PhysicalParams, settings: &EngineSettings) -> EngineError {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let (s, robot) = match prepare(&DartEngine, &s, &robot, params) {
        Ok(v) => v,
        Err(realitygap_core::controller::RunError::Engine(e)) => return e,
        Err(e) => panic!("{e}"),
    };
    match load_prepared(
        &DartEngine,
        &s,
        &robot,
        settings,
        params,
        &RunOptions::default(),
    ) {
        Err(realitygap_core::controller::RunError::Engine(e)) => e,
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("loaded"),
    }
}

fn params(toml: &str) -> PhysicalParams {
    PhysicalParams::from_toml_str(toml, Path::new("/conformance/params.toml")).unwrap()
}

/// The `[contact]` keys are the ones DART does not honour: an error naming
/// engine and key; keys that would have no effect (damping on a held
/// finger, the base's mass) and gains the SERVO actuator has no use for
/// are errors too.
#[test]
fn unsupported_and_meaningless_keys_are_errors() {
    let (key, e) = conformance::unsupported_key_error(&DartEngine).expect("an unsupported key");
    report(
        "unsupported_key",
        format!("{key}: {e}"),
        "names engine and key",
    );
    let text = e.to_string();
    assert!(text.contains("dart") && text.contains("contact."), "{text}");
    for (toml, key, settings) in [
        (
            "[joints.m1n6s300_joint_finger_1]\ndamping = 1.0\n",
            "joints.m1n6s300_joint_finger_1.damping",
            EngineSettings::new(),
        ),
        (
            "[links.m1n6s300_link_base]\nmass_scale = 2.0\n",
            "links.m1n6s300_link_base.mass_scale",
            EngineSettings::new(),
        ),
        (
            "[joints.m1n6s300_joint_2]\narmature = 0.1\n",
            "joints.m1n6s300_joint_2.armature",
            settings(&["servo=servo"]),
        ),
        (
            "[joints.m1n6s300_joint_2]\nkv = 10.0\n",
            "joints.m1n6s300_joint_2.kv",
            settings(&["servo=servo"]),
        ),
    ] {
        let e = load_error(&params(toml), &settings);
        report(
            "meaningless_key_error",
            format!("{e}"),
            "names engine and key",
        );
        match &e {
            EngineError::Param { engine, key: k, .. } => {
                assert_eq!(engine, "dart");
                assert_eq!(k, key);
            }
            other => panic!("{other:?}"),
        }
    }
}

/// Bad settings: one error style, naming engine, key and what is accepted.
#[test]
fn bad_settings_are_errors() {
    for (pair, want) in [
        ("timestep_s=0", "must be greater than 0 s"),
        (
            "collision_detector=physx",
            "is not one of ode, fcl, bullet, dart",
        ),
        ("lcp_solver=lemke", "is not one of dantzig, pgs"),
        ("servo=pd", "is not one of kv, servo"),
        ("iterations=10", "unknown setting"),
    ] {
        let e = DartSimulation::load(
            &scene("scene1_single_joint"),
            &mico2(),
            &settings(&[pair]),
            &Default::default(),
        )
        .err()
        .expect("refused");
        let text = e.to_string();
        assert!(text.starts_with("engine dart: setting `"), "{text}");
        assert!(text.contains(want), "{pair}: {text}");
    }
}

/// Extreme parameter values give an error naming the key before running,
/// or a run that ends as diverged (or completes): never a crash.
#[test]
fn extreme_values_are_errors_or_runs_never_crashes() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let values = ["0", "1e-300", "1e300", "3.4028234663852886e38"];
    let fields = [
        ("joints.m1n6s300_joint_2", "damping"),
        ("joints.m1n6s300_joint_2", "armature"),
        ("joints.m1n6s300_joint_2", "frictionloss"),
        ("joints.m1n6s300_joint_2", "kv"),
        ("joints.m1n6s300_joint_2", "force_limit"),
        ("links.m1n6s300_link_3", "mass_scale"),
        ("objects.cube", "mass_kg"),
        ("objects.cube", "friction"),
        ("objects.cube", "restitution"),
    ];
    let mut outcomes = Vec::new();
    for (table, field) in fields {
        for v in values {
            let text = format!("[{table}]\n{field} = {v}\n");
            let p = match PhysicalParams::from_toml_str(&text, Path::new("/x/params.toml")) {
                Ok(p) => p,
                Err(e) => {
                    outcomes.push(format!("{table}.{field}={v}: refused by core: {e}"));
                    continue;
                }
            };
            eprintln!("extreme: running {table}.{field}={v}");
            let options = RunOptions {
                allow_unstable: true,
                ..RunOptions::default()
            };
            let out = realitygap_core::controller::simulate_with(
                &DartEngine,
                &s,
                &robot,
                &EngineSettings::new(),
                &p,
                &options,
            );
            let what = match &out {
                Ok(o) => format!("{:?}", o.status),
                Err(e) => {
                    let t = e.to_string();
                    assert!(
                        t.contains(field) || t.contains("dart"),
                        "{table}.{field}={v}: {t}"
                    );
                    format!("error: {t}")
                }
            };
            if let Ok(o) = &out {
                assert!(
                    matches!(o.status, RunStatus::Completed | RunStatus::Diverged { .. }),
                    "{table}.{field}={v}: {:?}",
                    o.status
                );
            }
            outcomes.push(format!("{table}.{field}={v}: {what}"));
        }
    }
    for o in &outcomes {
        eprintln!("extreme: {o}");
    }
}

/// A cube launched at 1e15 m/s ends the run as diverged, with the speed in
/// the message; the harshest timestep the control period allows runs or
/// diverges, never returns silent numbers.
#[test]
fn divergence_is_reported() {
    let s = scene("scene1_single_joint");
    let mut sim =
        DartSimulation::load(&s, &mico2(), &EngineSettings::new(), &Default::default()).unwrap();
    let mut state = sim.state().unwrap().portable();
    state.objects[0].linear_velocity_m_s = realitygap_core::Vec3::new(1e15, 0.0, 0.0);
    sim.set_state(&state).unwrap();
    let e = sim.step().unwrap_err();
    report("diverges_cube_at_1e15_m_s", &e, "Unstable");
    assert!(
        matches!(&e, EngineError::Unstable { message, .. } if message.contains("cube")),
        "{e}"
    );
    let out = realitygap_core::controller::run_scene(&mut sim, &s, &RunOptions::default()).unwrap();
    assert!(
        matches!(out.status, RunStatus::Diverged { .. }),
        "{:?}",
        out.status
    );

    let out = conformance::diverges(&DartEngine, &settings(&["timestep_s=0.05"]));
    report(
        "diverges_timestep_0.05",
        format!("{:?}", out.status),
        "Completed or Diverged",
    );
    assert!(matches!(
        out.status,
        RunStatus::Completed | RunStatus::Diverged { .. }
    ));
    // A state with a NaN is refused before it reaches DART.
    let mut bad = sim.state().unwrap().portable();
    bad.joint_angles_rad[1] = f64::NAN;
    let e = sim.set_state(&bad).unwrap_err();
    assert!(matches!(e, EngineError::State { .. }), "{e}");
}

/// The other velocity servo, DART's SERVO actuator (`servo = "servo"`): a
/// velocity constraint with no gain, so the rotor reaches the target
/// velocity in one step instead of with the time constant I/kv = 0.1 s:
/// the gap to the analytic kv law is the law's own lag, 0.1 rad.
#[test]
fn servo_actuator_is_stiff() {
    let set = settings(&["timestep_s=0.001", "servo=servo"]);
    let r = conformance::step_response(subject(&set), CommandKind::Velocity);
    report(
        "servo_actuator_step_velocity_rad",
        r.max_error_rad,
        "0.09..0.11",
    );
    assert!((0.09..0.11).contains(&r.max_error_rad), "{r:?}");
    for kind in [CommandKind::Position, CommandKind::Effort] {
        let r = conformance::step_response(subject(&set), kind);
        report(
            &format!("servo_actuator_step_{}_rad", kind.name()),
            r.max_error_rad,
            "3e-3",
        );
        assert!(r.max_error_rad < 3e-3, "{kind:?}: {r:?}");
    }
}
