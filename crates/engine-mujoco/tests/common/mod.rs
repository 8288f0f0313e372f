//! Shared helpers of the engine's integration tests.
#![allow(dead_code, unused_imports)]

pub use realitygap_core::testing::{
    cube, mico2, official_robot, paper_data, scene, workspace, wrist,
};

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_mujoco::MujocoEngine;
use std::path::{Path, PathBuf};

/// Runs a scene through MuJoCo with the scene's own settings.
pub fn run(scene: &Scene, robot: &RobotModel) -> RunOutcome {
    scene.validate(robot).unwrap();
    let out = simulate(
        &MujocoEngine,
        scene,
        robot,
        &scene.settings_for("mujoco"),
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(out.status, RunStatus::Completed, "{}", scene.name);
    out
}

/// Rows of a study simulation CSV (14 numbers each).
pub fn read_study_csv(path: &Path) -> Vec<[f64; 14]> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            v.try_into().unwrap()
        })
        .collect()
}
