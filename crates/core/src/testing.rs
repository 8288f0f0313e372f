//! Helpers shared by the tests and benchmarks of the workspace's crates
//! (every engine's integration tests load the same scenes and robots and
//! look at the same recordings). Not for production code: these panic on
//! error, as tests want.

use crate::controller::RunOutcome;
use crate::robot::{PackageResolver, RobotModel};
use crate::scene::Scene;
use crate::trajectory::{CUBE, WRIST};
use crate::Vec3;
use std::path::{Path, PathBuf};

/// The workspace root (the folder with `assets/` and `crates/`).
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The study's recordings beside the project (`../shared/paper-data`), or
/// `None` after a message when they are absent. When the environment
/// variable `REALITYGAP_REQUIRE_PAPER_DATA` is set (CI sets it) their
/// absence is a panic, so that tests cannot pass by skipping.
pub fn paper_data() -> Option<PathBuf> {
    let dir = workspace().join("../shared/paper-data");
    if dir.join("MotionCapture").is_dir()
        && dir.join("kinova_description/urdf/m1n6s300.urdf").is_file()
    {
        Some(dir)
    } else if std::env::var_os("REALITYGAP_REQUIRE_PAPER_DATA").is_some() {
        panic!(
            "paper-data not found at {} but REALITYGAP_REQUIRE_PAPER_DATA is set",
            dir.display()
        );
    } else {
        eprintln!(
            "SKIPPED: paper-data not found at {}; this test needs the study's recordings",
            dir.display()
        );
        None
    }
}

/// One of the project's scenes, by name (`scene1_single_joint`, ...).
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

/// One of the project's scenes with the official Kinova URDF as its robot.
pub fn official_scene(name: &str, paper: &Path) -> Scene {
    let mut s = scene(name);
    s.set_robot_urdf(paper.join("kinova_description/urdf/m1n6s300.urdf"));
    s
}

/// A copy of `scene` with the official robot, validated against it.
pub fn with_official_robot(scene: &Scene, paper: &Path) -> (Scene, RobotModel) {
    let mut s = scene.clone();
    s.set_robot_urdf(paper.join("kinova_description/urdf/m1n6s300.urdf"));
    let robot = official_robot(paper);
    s.validate(&robot).unwrap();
    (s, robot)
}

/// The project's Mico2 (primitive collision shapes).
pub fn mico2() -> RobotModel {
    RobotModel::from_urdf_file(
        &workspace().join("assets/robots/mico2/mico2.urdf"),
        &PackageResolver::new(),
    )
    .unwrap()
}

/// Wrist positions of a run, metres (panics at a gap).
pub fn wrist(out: &RunOutcome) -> Vec<Vec3> {
    out.trajectory
        .positions(WRIST)
        .into_iter()
        .map(|p| p.unwrap())
        .collect()
}

/// Cube positions of a run, metres (panics at a gap).
pub fn cube(out: &RunOutcome) -> Vec<Vec3> {
    out.trajectory
        .positions(CUBE)
        .into_iter()
        .map(|p| p.unwrap())
        .collect()
}

/// Joint angles at the end of a run, degrees.
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
