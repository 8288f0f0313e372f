//! Shared helpers of the engine's integration tests.
#![allow(dead_code)]

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_mujoco::MujocoEngine;
use std::path::{Path, PathBuf};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The study's recordings, or `None` (with a message) when they are absent.
pub fn paper_data() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/paper-data");
    if dir.join("Simulation").is_dir() {
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

/// The project's Mico2.
pub fn mico2() -> RobotModel {
    RobotModel::from_urdf_file(
        &workspace().join("assets/robots/mico2/mico2.urdf"),
        &PackageResolver::new(),
    )
    .unwrap()
}

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
