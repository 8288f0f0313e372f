//! The world Bullet builds from a scene: links where the URDF's forward
//! kinematics puts them, contacts only where they belong, the three study
//! scenes with both robot models, model variations and settings applied.

mod common;

use common::*;
use realitygap_core::controller::{simulate, RunOptions, RunStatus};
use realitygap_core::engine::{EngineSettings, ModelVariation, SettingValue, Simulation};
use realitygap_core::pose::Pose;
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_engine_bullet::{BulletEngine, BulletSimulation};

fn load(
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
    variation: &ModelVariation,
) -> BulletSimulation {
    scene.validate(robot).unwrap();
    BulletSimulation::load(scene, robot, settings, variation).unwrap()
}

/// At rest the only contact is the cube on the ground; the initial state
/// is the scene's.
#[test]
fn at_rest_only_the_cube_touches_the_ground() {
    for (s, robot) in [(scene("scene1_single_joint"), mico2())]
        .into_iter()
        .chain(paper_data().map(|p| {
            (
                official_scene("scene1_single_joint", &p),
                official_robot(&p),
            )
        }))
    {
        let mut sim = load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        );
        let mut poses = [Pose::IDENTITY; 2];
        sim.tracked_poses(&mut poses);
        assert!(poses[1].position_m.distance(s.objects[0].pose.position_m) < 1e-12);
        sim.step_n(10).unwrap();
        let contacts = sim.contacts().unwrap();
        assert!(
            !contacts.is_empty(),
            "{}: the cube should rest on the ground",
            robot.name
        );
        for (a, b) in &contacts {
            let pair = [a.as_str(), b.as_str()];
            assert!(
                pair.contains(&"object:cube") && pair.contains(&"ground"),
                "{}: unexpected contact {a} - {b}",
                robot.name
            );
        }
        sim.tracked_poses(&mut poses);
        assert!(
            poses[1].position_m.distance(s.objects[0].pose.position_m) < 1e-3,
            "cube moved: {:?}",
            poses[1]
        );
    }
}

/// Contact between the hand and the cube: the hand, lowered until its
/// fingertips are 7 cm above the table (joint 2 at -85, joint 3 at 30,
/// joint 4 at 90 degrees), sweeps sideways (joint 1 at 0.3 rad/s) into a
/// cube placed in the fingertips' path, and pushes it along. (In scene 3
/// itself Bullet's stiff motors hold the hand about 2 cm higher than
/// MuJoCo's servos do and it only grazes the cube, as in the study's
/// PyBullet recording.)
#[test]
fn sweeping_hand_pushes_the_cube() {
    let runs = [("mico2", scene("scene3_cube_push"), mico2())]
        .into_iter()
        .chain(paper_data().map(|p| {
            (
                "official",
                official_scene("scene3_cube_push", &p),
                official_robot(&p),
            )
        }))
        .map(|(label, mut s, robot)| {
            s.objects[0].pose.position_m = realitygap_core::Vec3::new(0.575, -0.12, 0.0375);
            (label, s, robot)
        });
    for (label, s, robot) in runs {
        let mut sim = load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation::default(),
        );
        sim.set_joint_angles_rad(&[
            0.0,
            (-85f64).to_radians(),
            30f64.to_radians(),
            90f64.to_radians(),
            0.0,
            0.0,
        ])
        .unwrap();
        sim.set_joint_velocity_targets(&[0.3, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let mut touched = None;
        for tick in 0..40 {
            sim.step_n(5).unwrap();
            let hand_on_cube = sim.contacts().unwrap().into_iter().find(|(a, b)| {
                (a == "object:cube" && b.starts_with("m1n6s300"))
                    || (b == "object:cube" && a.starts_with("m1n6s300"))
            });
            if let (None, Some(pair)) = (&touched, hand_on_cube) {
                touched = Some((tick, pair));
            }
        }
        let mut poses = [Pose::IDENTITY; 2];
        sim.tracked_poses(&mut poses);
        let moved = poses[1].position_m.distance(s.objects[0].pose.position_m);
        eprintln!(
            "{label}: first hand-cube contact {touched:?}; the cube moved {:.1} mm",
            moved * 1e3
        );
        assert!(
            touched.is_some(),
            "{label}: the hand never touched the cube"
        );
        assert!(moved > 0.01, "{label}: the cube moved only {moved} m");
    }
}

#[test]
fn every_scene_runs_with_both_robots() {
    let paper = paper_data();
    for name in [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ] {
        let mut runs = vec![("mico2", scene(name), mico2())];
        if let Some(p) = &paper {
            runs.push(("official", official_scene(name, p), official_robot(p)));
        }
        for (label, s, robot) in runs {
            let out = run(&s, &robot);
            assert_eq!(out.trajectory.len(), s.sample_count());
            out.trajectory.validate().unwrap();
            let w = wrist(&out);
            let goal_reached = out
                .trajectory
                .joint_angles_rad
                .as_ref()
                .unwrap()
                .last()
                .unwrap()
                .clone();
            eprintln!(
                "{name} / {label}: final wrist ({:.4}, {:.4}, {:.4}) m, joints {:?} rad, {:.0} steps/s",
                w.last().unwrap().x,
                w.last().unwrap().y,
                w.last().unwrap().z,
                goal_reached.iter().map(|a| (a * 1e3).round() / 1e3).collect::<Vec<_>>(),
                out.steps_per_second()
            );
        }
    }
}

#[test]
fn settings_reach_bullet() {
    let s = scene("scene1_single_joint");
    let settings: EngineSettings = [
        ("timestep_s", SettingValue::Float(0.005)),
        ("solver_iterations", SettingValue::Integer(123)),
        ("contact_erp", SettingValue::Float(0.3)),
        ("split_impulse", SettingValue::Bool(false)),
        ("cone_friction", SettingValue::Bool(false)),
        ("contact_breaking_threshold_m", SettingValue::Float(0.01)),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    let mut sim = load(&s, &mico2(), &settings, &ModelVariation::default());
    let p = sim.physics_parameters().unwrap();
    assert_eq!(p.timestep_s, 0.005);
    assert_eq!(p.gravity_m_s2, [0.0, 0.0, -9.81]);
    assert_eq!(p.solver_iterations, 123);
    assert_eq!(p.contact_erp, 0.3);
    assert!(!p.split_impulse);
    assert!(!p.cone_friction);
    assert_eq!(p.contact_breaking_threshold_m, 0.01);
    assert_eq!(sim.timestep_s(), 0.005);
    // The defaults the settings' help texts state are Bullet's.
    let mut defaults = load(
        &s,
        &mico2(),
        &EngineSettings::new(),
        &ModelVariation::default(),
    );
    let d = defaults.physics_parameters().unwrap();
    eprintln!("Bullet defaults: {d:?}");
    assert_eq!(d.timestep_s, 0.01);
    assert_eq!(d.solver_iterations, 50);
    assert_eq!(d.solver_residual_threshold, 1e-7);
    assert_eq!(d.contact_erp, 0.08);
    assert_eq!(
        (d.non_contact_erp, d.friction_erp, d.global_cfm),
        (0.2, 0.2, 0.0)
    );
    assert!(d.split_impulse && d.cone_friction);
    assert!((d.split_impulse_penetration_threshold_m + 0.04).abs() < 1e-8);
    assert_eq!(d.contact_breaking_threshold_m, 0.01);
    let help = |key: &str| {
        realitygap_engine_bullet::SETTINGS
            .iter()
            .find(|s| s.key == key)
            .unwrap()
            .help
    };
    assert!(help("contact_erp").ends_with("default 0.08"));
    assert!(help("contact_breaking_threshold_m").ends_with("default 0.01"));
    assert!(help("solver_iterations").ends_with("default 50"));
}

#[test]
fn variations_scale_masses_and_frictions() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let mut plain = load(
        &s,
        &robot,
        &EngineSettings::new(),
        &ModelVariation::default(),
    );
    let variation = ModelVariation {
        mass_scale: 1.5,
        friction_scale: 0.25,
    };
    let mut varied = load(&s, &robot, &EngineSettings::new(), &variation);
    for name in ["m1n6s300_link_3", "object:cube"] {
        let (m0, f0) = plain.mass_and_friction(name).unwrap().unwrap();
        let (m1, f1) = varied.mass_and_friction(name).unwrap().unwrap();
        assert!((m1 - 1.5 * m0).abs() < 1e-12, "{name}: mass {m0} -> {m1}");
        assert!(
            (f1 - 0.5 * f0).abs() < 1e-12,
            "{name}: friction {f0} -> {f1} (sqrt of 0.25 per body)"
        );
    }
    let (cube_mass, cube_friction) = plain.mass_and_friction("object:cube").unwrap().unwrap();
    assert_eq!(cube_mass, 0.0884);
    assert_eq!(cube_friction, 0.5, "Bullet's default lateral friction");
}

/// A run whose motors cannot hold the arm (force 1e-3 N m) still completes
/// and reports where gravity took it; and the reported state is Bullet's,
/// not clamped.
#[test]
fn weak_motors_let_the_arm_fall() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let weak: EngineSettings = [("max_force_n_m".to_string(), SettingValue::Float(1e-3))]
        .into_iter()
        .collect();
    let out = simulate(&BulletEngine, &s, &robot, &weak, &RunOptions::default()).unwrap();
    assert_eq!(out.status, RunStatus::Completed);
    let strong = run(&s, &robot);
    let (a, b) = (wrist(&out), wrist(&strong));
    assert!(
        a.last().unwrap().distance(*b.last().unwrap()) > 0.05,
        "a weak arm should end elsewhere"
    );
}
