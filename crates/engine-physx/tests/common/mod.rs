//! Shared helpers of the engine's integration tests.
#![allow(dead_code, unused_imports)]

pub use realitygap_core::testing::{
    cube, final_angles_deg, mico2, official_robot, official_scene, paper_data, scene, workspace,
    wrist,
};

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::engine::{Engine, EngineSettings};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use std::path::{Path, PathBuf};

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
