//! The ODE engine through `realitygap`: listed with its version, runs the
//! three scenes with both robots, reports a deliberately unstable setting as
//! a diverged run (status, time, the samples before) while the rest of the
//! batch goes on, and rejects bad ODE settings with a clear error.
#![cfg(feature = "ode")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_realitygap")
}

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets")
}

fn realitygap(args: &[&str]) -> Output {
    Command::new(exe()).args(args).output().unwrap()
}

fn manifest(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap()
}

#[test]
fn ode_is_listed_with_its_version_and_settings() {
    let out = realitygap(&["engines", "--settings"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with("ode "))
        .unwrap_or_else(|| panic!("no ode line in:\n{text}"));
    assert!(
        line.contains("ODE 0.16") && line.contains("double precision") && line.contains("0.01 s"),
        "{line}"
    );
    for key in [
        "stepper",
        "quick_step_iterations",
        "erp",
        "cfm",
        "contact_mu",
        "servo",
    ] {
        assert!(text.contains(key), "setting {key} not listed");
    }
}

/// Scene 1 twice in one batch: once with an unstable ODE setting in its
/// `[engine.ode]` table (the iterative solver with a single iteration at
/// the largest timestep the 0.05 s control period allows), once as it is.
#[test]
fn unstable_setting_is_recorded_as_diverged_and_the_batch_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(assets().join("scenes/scene1_single_joint.toml"))
        .unwrap()
        .replace(
            "urdf = \"../robots/mico2/mico2.urdf\"",
            &format!(
                "urdf = {:?}",
                assets()
                    .join("robots/mico2/mico2.urdf")
                    .display()
                    .to_string()
            ),
        );
    let unstable = text.replace("name = \"scene1_single_joint\"", "name = \"unstable\"")
        + "\n[engine.ode]\ntimestep_s = 0.05\nstepper = \"quick_step\"\nquick_step_iterations = 1\n";
    let stable = text.replace("name = \"scene1_single_joint\"", "name = \"stable\"");
    std::fs::write(tmp.path().join("unstable.toml"), unstable).unwrap();
    std::fs::write(tmp.path().join("stable.toml"), stable).unwrap();
    let results = tmp.path().join("out");
    let out = realitygap(&[
        "run",
        tmp.path().join("unstable.toml").to_str().unwrap(),
        tmp.path().join("stable.toml").to_str().unwrap(),
        "--engine",
        "ode",
        "--out",
        results.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stdout.contains("unstable/ode: 0 ok, 1 diverged, 0 failed"),
        "{stdout}"
    );
    assert!(
        stdout.contains("stable/ode: 1 ok, 0 diverged, 0 failed"),
        "{stdout}"
    );

    let m = manifest(&results.join("unstable/ode"));
    let run = &m["runs"][0];
    assert_eq!(run["status"], "diverged", "{run}");
    let t = run["extra"]["diverged_at_s"].as_f64().unwrap();
    assert!(t > 0.0 && t < 6.0, "{t}");
    let message = run["message"].as_str().unwrap();
    assert!(
        message.starts_with("diverged at t = ") && message.contains("m/s"),
        "{message}"
    );
    assert_eq!(
        m["settings"]["config"]["engine_settings"]["stepper"],
        "quick_step"
    );
    // The samples before the divergence are kept, all finite.
    let csv = std::fs::read_to_string(results.join("unstable/ode/runs/run000.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert!(!rows.is_empty() && rows.len() < 120, "{} rows", rows.len());
    assert!(
        (rows.len() as f64 * 0.05 - t).abs() < 0.05 + 1e-9,
        "{} rows, diverged at {t} s",
        rows.len()
    );
    for row in &rows {
        for cell in row.split(',') {
            let v: f64 = cell
                .parse()
                .unwrap_or_else(|_| panic!("not a number: {cell}"));
            assert!(v.is_finite() && v.abs() < 1e3, "{row}");
        }
    }

    let m = manifest(&results.join("stable/ode"));
    assert_eq!(m["runs"][0]["status"], "ok");
    assert!(m["engine"]["version"]
        .as_str()
        .unwrap()
        .starts_with("ODE 0.16"));
}

#[test]
fn all_scenes_run_with_both_robots() {
    let tmp = tempfile::tempdir().unwrap();
    let results = tmp.path().join("out");
    let scenes: Vec<String> = [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ]
    .iter()
    .map(|s| {
        assets()
            .join(format!("scenes/{s}.toml"))
            .display()
            .to_string()
    })
    .collect();
    let mut args: Vec<String> = vec!["run".into()];
    args.extend(scenes.iter().cloned());
    args.extend(["--engine", "ode", "--out", results.to_str().unwrap()].map(String::from));
    let out = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut robots = vec!["ode"];
    if let Some(paper) = realitygap::paper_data_for_tests() {
        args.extend([
            "--robot".to_string(),
            "official".to_string(),
            "--package".to_string(),
        ]);
        args.push(format!(
            "kinova_description={}",
            paper.join("kinova_description").display()
        ));
        let out = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        robots.push("ode-official");
    }
    for scene in [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ] {
        for source in &robots {
            let m = manifest(&results.join(scene).join(source));
            assert_eq!(
                m["runs"][0]["status"], "ok",
                "{scene} {source}: {}",
                m["runs"][0]
            );
        }
    }
}

#[test]
fn bad_ode_settings_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = assets().join("scenes/scene1_single_joint.toml");
    for (set, expected) in [
        (
            "ode.stepper=euler",
            "setting `stepper`: \"euler\" is not one of world_step, quick_step",
        ),
        (
            "ode.iterations=5",
            "setting `iterations`: unknown setting (accepted:",
        ),
        (
            "ode.timestep_s=0.03",
            "not a whole number of engine timesteps",
        ),
    ] {
        let out = realitygap(&[
            "run",
            scene.to_str().unwrap(),
            "--engine",
            "ode",
            "--set",
            set,
            "--out",
            tmp.path().join("out").to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{set} was accepted");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.contains(expected),
            "{set}: expected \"{expected}\" in: {err}"
        );
    }
}
