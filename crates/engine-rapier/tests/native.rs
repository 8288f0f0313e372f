//! What only Rapier's own API shows (the rest is the kit, tests/kit.rs,
//! and the command's cross-engine tests): the contacts at rest, and a
//! non-finite body state reported as unstable.

use realitygap_core::controller::{run_scene, RunOptions, RunStatus};
use realitygap_core::engine::{EngineError, EngineSettings, ModelVariation, Simulation};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_core::testing::{kit, mico2, scene};
use realitygap_engine_rapier::RapierSimulation;

fn load(scene: &Scene, robot: &RobotModel) -> RapierSimulation {
    scene.validate(robot).unwrap();
    RapierSimulation::load(
        scene,
        robot,
        &EngineSettings::new(),
        &ModelVariation::default(),
    )
    .unwrap()
}

/// At rest, upright, no two robot bodies touch, and nothing touches the
/// cube but the ground: with the project's Mico2 and the official model.
#[test]
fn no_contacts_at_rest_but_the_cube_on_the_ground() {
    for (label, s, robot) in kit::robots(&scene("scene1_single_joint")) {
        let mut sim = load(&s, &robot);
        sim.step_raw(20);
        let contacts = sim.contacts();
        assert!(
            contacts.contains(&("ground".to_string(), "object:cube".to_string())),
            "{label}: {contacts:?}"
        );
        for (a, b) in contacts {
            let pair = [a.as_str(), b.as_str()];
            assert!(
                pair.contains(&"object:cube") && pair.contains(&"ground"),
                "{label}: unexpected contact {a} - {b}"
            );
        }
    }
}

/// A non-finite state (here a cube flung at NaN speed) is reported as
/// unstable, and the controller ends the run as diverged.
#[test]
fn non_finite_state_is_reported_unstable() {
    let s = scene("scene1_single_joint");
    let mut sim = load(&s, &mico2());
    sim.step_n(3).unwrap();
    let cube = sim.object_body("cube").unwrap();
    sim.world_mut().bodies[cube].set_linvel(rapier3d::math::Vector::new(f32::NAN, 0.0, 0.0), true);
    match sim.step() {
        Err(EngineError::Unstable {
            engine,
            t_s,
            message,
        }) => {
            assert_eq!(engine, "rapier");
            assert!((t_s - 0.04).abs() < 1e-12, "{t_s}");
            assert!(message.contains("non-finite"), "{message}");
        }
        other => panic!("expected Unstable, got {other:?}"),
    }

    let mut sim = load(&s, &mico2());
    let cube = sim.object_body("cube").unwrap();
    sim.world_mut().bodies[cube]
        .set_linvel(rapier3d::math::Vector::new(0.0, f32::INFINITY, 0.0), true);
    let out = run_scene(&mut sim, &s, &RunOptions::default()).unwrap();
    match out.status {
        RunStatus::Diverged { t_s, reason } => assert!(
            t_s < 0.05 && reason.contains("non-finite"),
            "{t_s} {reason}"
        ),
        RunStatus::Completed => panic!("the run completed"),
    }
}
