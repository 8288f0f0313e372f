//! Helpers shared by the tests and benchmarks of the workspace's crates
//! (every engine's integration tests load the same scenes and robots and
//! look at the same recordings). Not for production code: these panic on
//! error, as tests want.

pub mod bench;
pub mod fuzz;
pub mod kit;

use crate::controller::RunOutcome;
use crate::robot::{PackageResolver, RobotModel};
use crate::scene::Scene;
use crate::trajectory::{CUBE, WRIST};
use crate::Vec3;
use std::path::{Path, PathBuf};

/// Runs the calling test again in a child process (this test binary, the
/// test `test` alone, single-threaded, `--nocapture`) with the environment
/// variable `env` set, and returns what it printed and how it ended; in
/// the child (where `env` is set) returns `None`, and the test does the
/// child's work. For checks of what an engine prints and of aborts, which
/// only a separate process can observe.
pub fn rerun_in_child(test: &str, env: &str) -> Option<std::process::Output> {
    if std::env::var_os(env).is_some() {
        return None;
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", test, "--nocapture", "--test-threads=1", "-q"])
        .env(env, "1")
        .output()
        .unwrap();
    Some(out)
}

/// The workspace root (the folder with `assets/` and `crates/`).
pub fn workspace() -> PathBuf {
    // Under cargo, CARGO_MANIFEST_DIR at run time is the tested crate's own
    // directory (every crate is `crates/NAME`); the compile-time value can
    // name another checkout when a shared target directory was built there.
    let dir = std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .filter(|d| d.join("../../Cargo.toml").is_file())
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    dir.join("../..")
}

/// Environment variable that lets the tests needing the study's recordings
/// skip (after a message) when no copy is found, outside CI.
pub const ALLOW_MISSING_PAPER_DATA: &str = "REALITYGAP_ALLOW_MISSING_PAPER_DATA";

/// The study's recordings (with the `kinova_description` package): found by
/// [`find_paper_data`]. When there is none, a panic that says how to get
/// them, so that no test passes without checking; outside CI (neither `CI`
/// nor `REALITYGAP_REQUIRE_PAPER_DATA` set) with
/// `REALITYGAP_ALLOW_MISSING_PAPER_DATA` set, `None` after a message instead.
pub fn paper_data() -> Option<PathBuf> {
    if let Some(dir) = find_paper_data() {
        return Some(dir);
    }
    let ci = ["CI", "REALITYGAP_REQUIRE_PAPER_DATA"]
        .iter()
        .any(|v| std::env::var_os(v).is_some());
    if !ci && std::env::var_os(ALLOW_MISSING_PAPER_DATA).is_some() {
        eprintln!(
            "SKIPPED ({ALLOW_MISSING_PAPER_DATA} is set): this test needs the study's recordings"
        );
        return None;
    }
    panic!(
        "the study's recordings were found neither at {} nor unpacked from the built-in archive in the cache; \
         unpack them with `cargo test -p realitygap-data` (or `realitygap compare --data builtin`), \
         or set {ALLOW_MISSING_PAPER_DATA}=1 outside CI to skip the tests that need them",
        workspace().join("../shared/paper-data").display()
    );
}

/// Where the study's recordings are: `../shared/paper-data` beside the
/// project, else the built-in archive's copy already unpacked in the cache
/// (`<cache root>/study-data/<first 16 hex digits of its SHA-256>/`, the
/// cache root as `realitygap-data` chooses it). `None` when neither is there.
pub fn find_paper_data() -> Option<PathBuf> {
    let complete = |dir: &Path| {
        dir.join("MotionCapture").is_dir()
            && dir.join("Simulation").is_dir()
            && dir.join("kinova_description/urdf/m1n6s300.urdf").is_file()
    };
    let shared = workspace().join("../shared/paper-data");
    if complete(&shared) {
        return Some(shared);
    }
    builtin_copy().filter(|d| complete(d))
}

/// The built-in archive's unpacked copy in the cache, if finished (its
/// manifest is written last).
fn builtin_copy() -> Option<PathBuf> {
    let checksum =
        std::fs::read_to_string(workspace().join("assets/study-data/paper-data.tar.zst.sha256"))
            .ok()?;
    let key = checksum
        .split_whitespace()
        .next()?
        .get(..16)?
        .to_ascii_lowercase();
    let var = |name: &str| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    let root = var("REALITYGAP_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("realitygap")))
        .or_else(|| var("HOME").map(|d| d.join(".cache/realitygap")))
        .unwrap_or_else(|| std::env::temp_dir().join("realitygap-test-cache"));
    let dir = root.join("study-data").join(key);
    dir.join(".realitygap-unpacked.json")
        .is_file()
        .then_some(dir)
}

/// The joint-recording fixtures: a simulated KUKA iiwa written as ROS 2
/// bags, CSV and a LeRobot dataset by an independent writer
/// (`tools/fixtures/`, made by `scripts/make-fixtures`, which
/// `scripts/setup --tests` runs). Panics with that advice when absent.
pub fn joint_recording_fixtures() -> PathBuf {
    let dir = workspace().join("third_party/fixtures/joint-recordings");
    assert!(
        dir.join("truth.json").is_file(),
        "the joint-recording fixtures are missing at {}: run scripts/make-fixtures (scripts/setup --tests does)",
        dir.display()
    );
    dir
}

/// The KUKA LBR iiwa's URDF that `scripts/setup` takes from the pybullet
/// wheel.
pub fn iiwa_urdf() -> PathBuf {
    workspace().join("third_party/pybullet_data/kuka_iiwa/model.urdf")
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Once the built-in archive is unpacked, the helper the engines' tests
    /// use finds that copy (so they run without `../shared/paper-data`).
    #[test]
    fn the_unpacked_builtin_copy_is_found() {
        let unpacked = crate::robot::mico2_tests::paper_data();
        assert_eq!(builtin_copy(), Some(unpacked.clone()));
        let found = find_paper_data().expect("a copy is found");
        assert!(found == unpacked || found == workspace().join("../shared/paper-data"));
        assert_eq!(paper_data(), Some(found));
    }
}
