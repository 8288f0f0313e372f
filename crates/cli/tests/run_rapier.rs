//! `realitygap` end to end with the Rapier engine: listed by `engines`, runs
//! the study's scenes with the project's Mico2 and the official Kinova URDF,
//! and rejects bad settings with a message naming them.
#![cfg(feature = "rapier")]

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
fn engines_lists_rapier_with_its_version_and_settings() {
    let out = Command::new(exe())
        .args(["engines", "--settings"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("rapier ") && l.contains("Rapier 0.36") && l.contains("0.01 s")),
        "{text}"
    );
    for key in [
        "timestep_s",
        "solver_iterations",
        "internal_pgs_iterations",
        "mesh_shape",
    ] {
        assert!(text.contains(key), "{key} missing from:\n{text}");
    }
}

/// Runs the three scenes with `robot_args` and checks every run finished:
/// scene 1 ends with joint 2 near -100 degrees, scene 3 moves the cube.
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
        .args(["--engine", "rapier", "--out"])
        .arg(&out)
        .args(robot_args)
        .status()
        .unwrap();
    assert!(status.success());
    let s1 = last_row(
        &out.join("scene1_single_joint")
            .join(engine_dir)
            .join("runs/run000.csv"),
    );
    assert!(
        (s1["q2_rad"].to_degrees() + 100.0).abs() < 1.5,
        "joint 2 ends at {} deg",
        s1["q2_rad"].to_degrees()
    );
    let s2 = last_row(
        &out.join("scene2_two_joints")
            .join(engine_dir)
            .join("runs/run000.csv"),
    );
    assert!(s2["q2_rad"].abs() < 0.01 && s2["q5_rad"].abs() < 0.01);
    let s3 = last_row(
        &out.join("scene3_cube_push")
            .join(engine_dir)
            .join("runs/run000.csv"),
    );
    assert!(
        s3["cube_x_m"] > 0.55,
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
            .starts_with("Rapier 0.36"),
        "{manifest}"
    );
}

#[test]
fn runs_the_three_scenes_with_the_project_mico2() {
    run_all(&[], "rapier");
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
        "rapier-official",
    );
}

#[test]
fn bad_rapier_settings_fail_naming_the_setting() {
    let tmp = tempfile::tempdir().unwrap();
    for (set, expected) in [
        ("rapier.substeps=4", "setting `substeps`: unknown setting"),
        (
            "rapier.internal_pgs_iterations=0",
            "setting `internal_pgs_iterations`: must be a whole number from 1",
        ),
        (
            "rapier.mesh_shape=voxels",
            "\"voxels\" is not one of convex_hull, trimesh",
        ),
    ] {
        let out = Command::new(exe())
            .arg("run")
            .arg(scene("scene1_single_joint"))
            .args(["--engine", "rapier", "--set", set, "--out"])
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
