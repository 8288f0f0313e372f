//! Shared helpers of the ODE engine's integration tests.
#![allow(dead_code)]

use realitygap_core::controller::{simulate, RunOptions, RunOutcome};
use realitygap_core::engine::{EngineSettings, SettingValue};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_ode::OdeEngine;
use std::path::{Path, PathBuf};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The study's recordings (with the official URDF and meshes), or `None`
/// (with a message) when they are absent.
pub fn paper_data() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/paper-data");
    if dir.join("kinova_description/urdf/m1n6s300.urdf").is_file() {
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

/// A scene with the official robot instead of its own.
pub fn with_official_robot(scene: &Scene, paper: &Path) -> (Scene, RobotModel) {
    let mut s = scene.clone();
    s.set_robot_urdf(paper.join("kinova_description/urdf/m1n6s300.urdf"));
    let robot = official_robot(paper);
    s.validate(&robot).unwrap();
    (s, robot)
}

/// The project's Mico2.
pub fn mico2() -> RobotModel {
    RobotModel::from_urdf_file(
        &workspace().join("assets/robots/mico2/mico2.urdf"),
        &PackageResolver::new(),
    )
    .unwrap()
}

/// Settings from `key=value` pairs.
pub fn settings(pairs: &[&str]) -> EngineSettings {
    pairs
        .iter()
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap();
            (k.to_string(), SettingValue::parse(v))
        })
        .collect()
}

/// Runs a scene through ODE with `pairs` as settings.
pub fn run_ode(scene: &Scene, robot: &RobotModel, pairs: &[&str]) -> RunOutcome {
    scene.validate(robot).unwrap();
    simulate(
        &OdeEngine,
        scene,
        robot,
        &settings(pairs),
        &RunOptions::default(),
    )
    .unwrap()
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
