//! `realitygap` end to end with the PhysX engine: listed by `engines`, runs
//! the study's scenes with the project's Mico2 and the official Kinova URDF,
//! ends scene 1 where MuJoCo's servo leaves the arm, and rejects bad
//! settings with a message naming them.
#![cfg(feature = "physx")]

use std::path::{Path, PathBuf};
use std::process::Command;

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_realitygap")
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/scenes")
        .join(format!("{name}.toml"))
}

use realitygap_core::testing::paper_data;

/// The last row of a run CSV, by column name.
fn last_row(csv: &Path) -> std::collections::HashMap<String, f64> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let last = lines.last().unwrap();
    header
        .iter()
        .map(|h| h.to_string())
        .zip(last.split(',').map(|v| v.parse::<f64>().unwrap()))
        .collect()
}

#[test]
fn engines_lists_physx_with_its_version_and_settings() {
    let out = Command::new(exe())
        .args(["engines", "--settings"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("physx ") && l.contains("PhysX 5.1.3") && l.contains("0.005 s")),
        "{text}"
    );
    for key in [
        "timestep_s",
        "solver",
        "position_iterations",
        "velocity_iterations",
        "contact_offset_m",
    ] {
        assert!(text.contains(key), "{key} missing from:\n{text}");
    }
}

/// Runs the three scenes with `robot_args` and checks every run finished:
/// scene 1 ends with joint 2 near -100 degrees, scene 2 upright, scene 3
/// moves the cube along x.
fn run_all(robot_args: &[&str], engine_dir: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("results");
    let status = Command::new(exe())
        .arg("run")
        .args(
            [
                "scene1_single_joint",
                "scene2_two_joints",
                "scene3_cube_push",
            ]
            .map(scene),
        )
        .args(["--engine", "physx", "--out"])
        .arg(&out)
        .args(robot_args)
        .status()
        .unwrap();
    assert!(status.success());
    let csv = |s: &str| out.join(s).join(engine_dir).join("runs/run000.csv");
    let s1 = last_row(&csv("scene1_single_joint"));
    assert!(
        (s1["q2_rad"].to_degrees() + 100.0).abs() < 1.5,
        "joint 2 ends at {} deg",
        s1["q2_rad"].to_degrees()
    );
    let s2 = last_row(&csv("scene2_two_joints"));
    assert!(s2["q2_rad"].abs() < 0.01 && s2["q5_rad"].abs() < 0.01);
    let s3 = last_row(&csv("scene3_cube_push"));
    eprintln!(
        "{engine_dir}: scene 3 cube ends at x = {:.4} m (from 0.5)",
        s3["cube_x_m"]
    );
    assert!(
        s3["cube_x_m"] > 0.52,
        "the cube ends at x = {} m",
        s3["cube_x_m"]
    );
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(
            out.join("scene1_single_joint")
                .join(engine_dir)
                .join("manifest.json"),
        )
        .unwrap(),
    )
    .unwrap();
    assert!(
        manifest["engine"]["version"]
            .as_str()
            .unwrap()
            .starts_with("PhysX 5.1.3"),
        "{manifest}"
    );
}

#[test]
fn runs_the_three_scenes_with_the_project_mico2() {
    run_all(&[], "physx");
}

#[test]
fn runs_the_three_scenes_with_the_official_urdf() {
    let Some(paper) = paper_data() else { return };
    let package = format!(
        "kinova_description={}",
        paper.join("kinova_description").display()
    );
    run_all(
        &["--robot", "official", "--package", &package],
        "physx-official",
    );
}

/// The issue's "must show": `run scene1 --engine physx --repeats 2` ends
/// with the wrist where MuJoCo's `kv` servo leaves it (within a
/// millimetre), not on the targets' forward kinematics: a velocity servo
/// under a proportional controller holds the arm where `kv * gain *
/// error` balances gravity, 1.4 degrees past the target on joint 2 and 1.9
/// degrees on joint 3 (and 1.1 on joints 4 and 5), which puts the wrist
/// 23.8 mm from the targets' pose: the 20 mm are met against MuJoCo's
/// servo (0.31 mm), not against the targets, in PhysX as in MuJoCo.
#[test]
fn scene1_ends_where_mujocos_servo_leaves_the_wrist() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("results");
    for (engine, repeats) in [("physx", "2"), ("mujoco", "1")] {
        let status = Command::new(exe())
            .arg("run")
            .arg(scene("scene1_single_joint"))
            .args(["--engine", engine, "--repeats", repeats, "--out"])
            .arg(&out)
            .status()
            .unwrap();
        assert!(status.success(), "{engine}");
    }
    let wrist = |engine: &str, run: &str| {
        let r = last_row(
            &out.join("scene1_single_joint")
                .join(engine)
                .join(format!("runs/{run}.csv")),
        );
        realitygap_core::Vec3::new(r["wrist_x_m"], r["wrist_y_m"], r["wrist_z_m"])
    };
    let s = realitygap_core::testing::scene("scene1_single_joint");
    let robot = realitygap_core::testing::mico2();
    let mut named: std::collections::HashMap<String, f64> = s
        .controlled_joints()
        .iter()
        .map(|n| (n.to_string(), 0.0))
        .collect();
    named.insert("m1n6s300_joint_2".into(), (-100.0f64).to_radians());
    for (n, &a) in &s.robot.held_joints_rad {
        named.insert(n.clone(), a);
    }
    let fk = robot.forward_kinematics(&s.robot.base, &robot.positions_from_names(&named).unwrap());
    let target = fk[robot.link_by_name("m1n6s300_link_6").unwrap()].position_m;
    let mujoco = wrist("mujoco", "run000");
    for run in ["run000", "run001"] {
        let w = wrist("physx", run);
        let to_mujoco = w.distance(mujoco);
        let to_target = w.distance(target);
        eprintln!(
            "physx {run}: final wrist {:.2} mm from MuJoCo's, {:.2} mm from the targets' forward kinematics",
            to_mujoco * 1e3,
            to_target * 1e3
        );
        assert!(to_mujoco < 0.001, "{} mm from MuJoCo", to_mujoco * 1e3);
        // The gravity droop of a velocity servo: MuJoCo's wrist is as far.
        assert!(
            (to_target - mujoco.distance(target)).abs() < 0.001,
            "{} mm from the targets, MuJoCo {} mm",
            to_target * 1e3,
            mujoco.distance(target) * 1e3
        );
    }
}

#[test]
fn bad_physx_settings_fail_naming_the_setting() {
    let tmp = tempfile::tempdir().unwrap();
    for (set, expected) in [
        ("physx.substeps=4", "setting `substeps`: unknown setting"),
        (
            "physx.position_iterations=0",
            "setting `position_iterations`: must be a whole number from 1",
        ),
        ("physx.solver=jacobi", "\"jacobi\" is not one of pgs, tgs"),
    ] {
        let out = Command::new(exe())
            .arg("run")
            .arg(scene("scene1_single_joint"))
            .args(["--engine", "physx", "--set", set, "--out"])
            .arg(tmp.path().join("r"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{set} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(expected) && !err.contains("panicked"),
            "{set}: {err}"
        );
    }
}
