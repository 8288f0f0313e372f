//! Scene 1 (joint 2 to -100 degrees, free motion against gravity): the arm
//! tracks its targets with the default settings, ends where the servos
//! balance gravity, and within 5 mm of the MuJoCo engine on the same model;
//! with PhysX's stock solver settings it sags more.

mod common;

use common::*;
use realitygap_core::engine::{EngineSettings, ModelVariation, SettingValue};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_engine_mujoco::MujocoEngine;
use realitygap_engine_physx::PhysxEngine;

/// Runs scene 1 in PhysX (default settings) and MuJoCo (the scene's
/// settings) and checks the final angles and the wrist.
fn check_scene1(label: &str, scene: &Scene, robot: &RobotModel) {
    let physx = run_with_settings(&PhysxEngine, scene, robot, &EngineSettings::new());
    let mujoco = run_with(&MujocoEngine, scene, robot);
    let targets = scene.targets_deg_at_tick(scene.sample_count() - 1);
    assert_eq!(targets, vec![0.0, -100.0, 0.0, 0.0, 0.0, 0.0]);
    let equilibrium = static_equilibrium_deg(scene, robot, &targets);
    let (r, m) = (final_angles_deg(&physx), final_angles_deg(&mujoco));
    let (wr, wm) = (wrist(&physx), wrist(&mujoco));
    let last = wr.last().unwrap().distance(*wm.last().unwrap());
    let max = wr
        .iter()
        .zip(&wm)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    eprintln!("{label}: final angles (deg) physx  {r:.2?}");
    eprintln!("{label}:                    mujoco {m:.2?}");
    eprintln!("{label}:  servo/gravity balance {equilibrium:.2?}");
    eprintln!(
        "{label}: off target by {:.2?} deg; final wrist {:.3} mm from MuJoCo (largest gap {:.2} mm); {:.0} steps/s",
        r.iter().zip(&targets).map(|(a, t)| a - t).collect::<Vec<_>>(),
        last * 1e3,
        max * 1e3,
        physx.steps_per_second()
    );
    for j in 0..6 {
        // The arm ends where the servos hold it against gravity: that is
        // the target, less the droop kv * gain cannot take out (1.4 deg on
        // joint 2, 1.9 deg on joint 3, 1.1 deg on joints 4 and 5), in both
        // engines alike.
        assert!(
            (r[j] - equilibrium[j]).abs() < 0.1,
            "{label}: joint {} ends at {:.3} deg, the servos balance gravity at {:.3} deg",
            j + 1,
            r[j],
            equilibrium[j]
        );
        assert!(
            (r[j] - targets[j]).abs() < 2.5,
            "{label}: joint {} is {:.2} deg off its target",
            j + 1,
            r[j] - targets[j]
        );
        assert!(
            (r[j] - m[j]).abs() < 0.1,
            "{label}: joint {} ends {:.3} deg from MuJoCo",
            j + 1,
            r[j] - m[j]
        );
    }
    // Joints 1 and 6 carry no gravity load: they hold their target.
    assert!(
        r[0].abs() < 0.05 && r[5].abs() < 0.1,
        "{label}: joints 1 and 6 at {:.3} and {:.3} deg",
        r[0],
        r[5]
    );
    // Joint 2 reaches -100 within its gravity droop.
    assert!(
        (r[1] + 100.0).abs() < 1.5,
        "{label}: joint 2 ends at {:.2} deg",
        r[1]
    );
    assert!(
        last < 0.005,
        "{label}: the final wrist is {:.2} mm from MuJoCo's",
        last * 1e3
    );
    assert!(
        max < 0.01,
        "{label}: the wrist strays {:.2} mm from MuJoCo's",
        max * 1e3
    );
}

#[test]
fn mico2_tracks_scene1_like_mujoco() {
    check_scene1("mico2", &scene("scene1_single_joint"), &mico2());
}

#[test]
fn official_model_tracks_scene1_like_mujoco() {
    let Some(paper) = paper_data() else { return };
    check_scene1(
        "official",
        &official_scene("scene1_single_joint", &paper),
        &official_robot(&paper),
    );
}

fn settings(pairs: &[(&str, i64)]) -> EngineSettings {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), SettingValue::Integer(*v)))
        .collect()
}

/// Why the default raises the position iterations: with PhysX's stock 4
/// the six coupled drives are far from converged and the arm sags (joint 3
/// ends some 24 degrees past where the servos balance gravity); with the
/// default 32 it ends there (see the README's table).
#[test]
fn stock_position_iterations_let_the_arm_sag() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let stock = run_with_settings(
        &PhysxEngine,
        &s,
        &robot,
        &settings(&[("position_iterations", 4)]),
    );
    let equilibrium = static_equilibrium_deg(&s, &robot, &s.targets_deg_at_tick(119));
    let sag: Vec<f64> = final_angles_deg(&stock)
        .iter()
        .zip(&equilibrium)
        .map(|(a, e)| a - e)
        .collect();
    eprintln!(
        "stock position iterations: final angles off the servo/gravity balance by {sag:.2?} deg"
    );
    assert!(
        sag[2] > 10.0,
        "joint 3 sags only {:.2} deg with the stock settings",
        sag[2]
    );
}

/// Heavier links droop more: with every mass 1.5 times larger the arm ends
/// where the servos balance the larger gravity torques. (With masses
/// doubled the hand droops onto the cube and the table.)
#[test]
fn mass_variation_changes_the_droop() {
    use realitygap_core::controller::{run_scene, RunOptions};
    use realitygap_engine_physx::PhysxSimulation;
    let s = scene("scene1_single_joint");
    let robot = mico2();
    s.validate(&robot).unwrap();
    let mut heavy = robot.clone();
    for link in &mut heavy.links {
        if let Some(i) = &mut link.inertial {
            i.mass_kg *= 1.5;
        }
    }
    let targets = s.targets_deg_at_tick(119);
    for (mass_scale, model) in [(1.0, &robot), (1.5, &heavy)] {
        let variation = ModelVariation {
            mass_scale,
            friction_scale: 1.0,
        };
        let mut sim =
            PhysxSimulation::load(&s, &robot, &EngineSettings::new(), &variation).unwrap();
        let out = run_scene(&mut sim, &s, &RunOptions::default()).unwrap();
        let got = final_angles_deg(&out);
        let want = static_equilibrium_deg(&s, model, &targets);
        eprintln!("masses x{mass_scale}: final {got:.2?} deg, balance {want:.2?} deg");
        for j in 0..6 {
            assert!(
                (got[j] - want[j]).abs() < 0.1,
                "masses x{mass_scale}: joint {} at {:.3}, balance {:.3}",
                j + 1,
                got[j],
                want[j]
            );
        }
    }
}
