//! Shared helpers of the engine's integration tests.
#![allow(dead_code)]

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::engine::{Engine, EngineSettings};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use std::path::{Path, PathBuf};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The study's recordings and robot description, or `None` (with a
/// message) when they are absent.
pub fn paper_data() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/paper-data");
    if dir.join("kinova_description").is_dir() {
        Some(dir)
    } else if std::env::var_os("REALITYGAP_REQUIRE_PAPER_DATA").is_some() {
        panic!(
            "paper data not found at {} and REALITYGAP_REQUIRE_PAPER_DATA is set",
            dir.display()
        );
    } else {
        eprintln!(
            "paper data not found at {}: skipping this test",
            dir.display()
        );
        None
    }
}

/// One of the project's scenes.
pub fn scene(name: &str) -> Scene {
    Scene::from_file(
        &workspace()
            .join("assets/scenes")
            .join(format!("{name}.toml")),
    )
    .unwrap()
}

/// The official Kinova URDF, with its meshes resolved in the paper data.
pub fn official_robot(paper: &Path) -> RobotModel {
    let mut resolver = PackageResolver::new();
    resolver.insert("kinova_description", paper.join("kinova_description"));
    RobotModel::from_urdf_file(
        &paper.join("kinova_description/urdf/m1n6s300.urdf"),
        &resolver,
    )
    .unwrap()
}

/// A scene switched to the official URDF.
pub fn official_scene(name: &str, paper: &Path) -> Scene {
    let mut s = scene(name);
    s.set_robot_urdf(paper.join("kinova_description/urdf/m1n6s300.urdf"));
    s
}

/// The project's Mico2.
pub fn mico2() -> RobotModel {
    RobotModel::from_urdf_file(
        &workspace().join("assets/robots/mico2/mico2.urdf"),
        &PackageResolver::new(),
    )
    .unwrap()
}

/// Runs a scene through `engine` with the scene's own settings for it;
/// the run must complete.
pub fn run_with(engine: &dyn Engine, scene: &Scene, robot: &RobotModel) -> RunOutcome {
    run_with_settings(engine, scene, robot, &scene.settings_for(engine.name()))
}

/// Runs a scene through `engine` with the given settings; the run must
/// complete.
pub fn run_with_settings(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
) -> RunOutcome {
    scene.validate(robot).unwrap();
    let out = simulate(engine, scene, robot, settings, &RunOptions::default()).unwrap();
    assert_eq!(
        out.status,
        RunStatus::Completed,
        "{} in {}",
        scene.name,
        engine.name()
    );
    out
}

/// Wrist positions of a run.
pub fn wrist(out: &RunOutcome) -> Vec<Vec3> {
    out.trajectory
        .positions("wrist")
        .into_iter()
        .map(|p| p.unwrap())
        .collect()
}

/// Cube positions of a run.
pub fn cube(out: &RunOutcome) -> Vec<Vec3> {
    out.trajectory
        .positions("cube")
        .into_iter()
        .map(|p| p.unwrap())
        .collect()
}

/// Final joint angles of a run, degrees.
pub fn final_angles_deg(out: &RunOutcome) -> Vec<f64> {
    out.trajectory
        .joint_angles_rad
        .as_ref()
        .unwrap()
        .last()
        .unwrap()
        .iter()
        .map(|a| a.to_degrees())
        .collect()
}

/// The angles (degrees, actuator order) at which the scene's servos hold
/// the arm still against gravity with the given targets: each servo pushes
/// `kv * gain * (target - angle)` (rad/s from degrees), which must cancel
/// the gravity torque of [`RobotModel::gravity_torques`]. Solved by fixed
/// point from the targets (the droop is a degree or two).
pub fn static_equilibrium_deg(scene: &Scene, robot: &RobotModel, targets_deg: &[f64]) -> Vec<f64> {
    let joints: Vec<usize> = scene
        .actuators
        .iter()
        .map(|a| robot.joint_by_name(&a.joint).unwrap())
        .collect();
    let mut angles = targets_deg.to_vec();
    for _ in 0..50 {
        let mut positions = vec![0.0; robot.joints.len()];
        for (&j, a) in joints.iter().zip(&angles) {
            positions[j] = a.to_radians();
        }
        for (name, &v) in &scene.robot.held_joints_rad {
            positions[robot.joint_by_name(name).unwrap()] = v;
        }
        let torques =
            robot.gravity_torques(&scene.robot.base, &positions, Vec3::new(0.0, 0.0, -9.81));
        angles = scene
            .actuators
            .iter()
            .zip(&joints)
            .zip(targets_deg)
            .map(|((a, &j), &t)| t + torques[j] / (a.kv * scene.controller.gain_per_s.to_radians()))
            .collect();
    }
    angles
}
