//! `realitygap` end to end with the Bullet engine: listed by `engines`, runs
//! the study's scenes with the project's Mico2 and the official Kinova URDF,
//! rejects bad settings and a broken mesh with messages naming them, and
//! Bullet writes nothing on standard output.
#![cfg(feature = "bullet")]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

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
fn last_row(csv: &Path) -> HashMap<String, f64> {
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

/// Fails when standard output shows Bullet's own printing: its warnings
/// and errors start with `b3Warning[file,line]:` / `b3Error[file,line]:`
/// unless the engine's hooks catch them. (The engine's error messages quote
/// Bullet as `Bullet said: File.cpp:line: ...`, which is allowed.)
fn assert_no_bullet_output(out: &Output) {
    let stdout = String::from_utf8_lossy(&out.stdout);
    for marker in [
        "b3Warning[",
        "b3Error[",
        "b3Printf",
        "switched solver",
        "PyBullet: Constraint Solver",
    ] {
        assert!(
            !stdout.contains(marker),
            "Bullet output ({marker}) on standard output:\n{stdout}"
        );
    }
}

#[test]
fn engines_lists_bullet_with_its_version_and_settings() {
    let out = Command::new(exe())
        .args(["engines", "--settings"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("bullet ") && l.contains("Bullet 3.08") && l.contains("0.01 s")),
        "{text}"
    );
    for key in [
        "solver_iterations",
        "contact_erp",
        "max_force_n_m",
        "velocity_gain",
        "inertia_from_file",
    ] {
        assert!(text.contains(key), "{key} missing from:\n{text}");
    }
}

/// Runs the three scenes with `robot_args`: scene 1 ends with joint 2 at
/// -100 degrees, scene 2 back at 0, scene 3 with the wrist where PyBullet
/// puts it (0.507, -0.007, 0.340 m).
fn run_all(robot_args: &[&str], engine_dir: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("results");
    let out = Command::new(exe())
        .arg("run")
        .args(
            [
                "scene1_single_joint",
                "scene2_two_joints",
                "scene3_cube_push",
            ]
            .map(scene),
        )
        .args(["--engine", "bullet", "--out"])
        .arg(&out_dir)
        .args(robot_args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_no_bullet_output(&out);
    let s1 = last_row(
        &out_dir
            .join("scene1_single_joint")
            .join(engine_dir)
            .join("runs/run000.csv"),
    );
    assert!(
        (s1["q2_rad"].to_degrees() + 100.0).abs() < 0.1,
        "joint 2 ends at {} deg",
        s1["q2_rad"].to_degrees()
    );
    let s2 = last_row(
        &out_dir
            .join("scene2_two_joints")
            .join(engine_dir)
            .join("runs/run000.csv"),
    );
    assert!(s2["q2_rad"].abs() < 0.01 && s2["q5_rad"].abs() < 0.01);
    let s3 = last_row(
        &out_dir
            .join("scene3_cube_push")
            .join(engine_dir)
            .join("runs/run000.csv"),
    );
    let wrist = [s3["wrist_x_m"], s3["wrist_y_m"], s3["wrist_z_m"]];
    let expected = [0.5074, -0.0070, 0.3397];
    assert!(
        wrist
            .iter()
            .zip(expected)
            .all(|(a, b)| (a - b).abs() < 1e-3),
        "scene 3 wrist ends at {wrist:?}"
    );
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(
            out_dir
                .join("scene1_single_joint")
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
            .starts_with("Bullet 3.08"),
        "{manifest}"
    );
}

#[test]
fn runs_the_three_scenes_with_the_project_mico2() {
    run_all(&[], "bullet");
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
        "bullet-official",
    );
}

#[test]
fn bad_bullet_settings_fail_naming_the_setting() {
    let tmp = tempfile::tempdir().unwrap();
    for (set, expected) in [
        (
            "bullet.solver=dantzig",
            "setting `solver`: unknown setting (accepted: timestep_s",
        ),
        (
            "bullet.velocity_gain=2",
            "setting `velocity_gain`: must be a number > 0 and <= 1",
        ),
        (
            "bullet.timestep_s=0.03",
            "not a whole number of engine timesteps",
        ),
    ] {
        let out = Command::new(exe())
            .arg("run")
            .arg(scene("scene1_single_joint"))
            .args(["--engine", "bullet", "--set", set, "--out"])
            .arg(tmp.path().join("r"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{set} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(expected) && !err.contains("panicked"),
            "{set}: {err}"
        );
        assert_no_bullet_output(&out);
    }
}

/// A robot whose mesh is not an STL file: the run fails, the message names
/// the URDF file, the link and the mesh, nothing panics, and Bullet's
/// complaints stay off standard output.
#[test]
fn broken_mesh_fails_the_run_with_a_clear_message() {
    let tmp = tempfile::tempdir().unwrap();
    let mico2 = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/robots/mico2/mico2.urdf");
    let text = std::fs::read_to_string(mico2).unwrap();
    // Replace the hand's first collision shape by a mesh that is no STL.
    let start = text.find("<link name=\"m1n6s300_link_6\">").unwrap();
    let collision = start + text[start..].find("<collision").unwrap();
    let geometry_start = collision + text[collision..].find("<geometry>").unwrap();
    let geometry_end =
        geometry_start + text[geometry_start..].find("</geometry>").unwrap() + "</geometry>".len();
    let broken = format!(
        "{}<geometry><mesh filename=\"hand.stl\"/></geometry>{}",
        &text[..geometry_start],
        &text[geometry_end..]
    );
    std::fs::write(tmp.path().join("arm.urdf"), broken).unwrap();
    std::fs::write(tmp.path().join("hand.stl"), "not an STL file").unwrap();
    let out = Command::new(exe())
        .arg("run")
        .arg(scene("scene1_single_joint"))
        .args(["--engine", "bullet", "--robot"])
        .arg(tmp.path().join("arm.urdf"))
        .arg("--out")
        .arg(tmp.path().join("r"))
        .output()
        .unwrap();
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!out.status.success(), "a broken mesh was accepted: {all}");
    assert!(
        all.contains("arm.urdf") && all.contains("m1n6s300_link_6") && all.contains("hand.stl"),
        "{all}"
    );
    assert!(!all.contains("panicked"), "{all}");
    assert_no_bullet_output(&out);
}

/// `--robot mico2` (the built-in description, which is no file on disk)
/// runs in Bullet, which needs a URDF file: the engine writes one from the
/// robot model.
#[test]
fn the_built_in_mico2_runs_in_bullet() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(exe())
        .arg("run")
        .arg(scene("scene1_single_joint"))
        .args(["--engine", "bullet", "--robot", "mico2", "--out"])
        .arg(tmp.path().join("r"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = tmp
        .path()
        .join("r/scene1_single_joint/bullet-mico2/runs/run000.csv");
    let last = last_row(&csv);
    assert!(
        (last["q2_rad"].to_degrees() + 100.0).abs() < 1.0,
        "joint 2 ends at {} degrees",
        last["q2_rad"].to_degrees()
    );
}
