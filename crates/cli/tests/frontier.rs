//! `realitygap frontier` end to end: a two-setting sweep on a short scene,
//! a diverging setting, and bad sweeps.
#![cfg(feature = "mujoco")]

use realitygap_core::params::PhysicalParams;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = realitygap(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Scene 1 cut to 1 s (20 samples), under another name (no study scene).
fn short_scene(dir: &Path) -> PathBuf {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let text = std::fs::read_to_string(assets.join("scenes/scene1_single_joint.toml")).unwrap();
    let urdf = assets.join("robots/mico2/mico2.urdf");
    let text = text
        .replace("name = \"scene1_single_joint\"", "name = \"short_scene\"")
        .replace("duration_s = 6.0", "duration_s = 1.0")
        .replace(
            "urdf = \"../robots/mico2/mico2.urdf\"",
            &format!("urdf = \"{}\"", urdf.display()),
        );
    assert!(text.contains("short_scene") && text.contains("duration_s = 1.0"));
    let path = dir.join("short.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn frontier_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("frontier.json")).unwrap()).unwrap()
}

#[test]
fn a_two_setting_sweep_writes_frontier_json_figures_and_a_usable_params_file() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = short_scene(tmp.path());
    let out = tmp.path().join("f");
    let stdout = ok(&[
        "frontier",
        scene.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--sweep",
        "integrator=implicitfast",
        "--sweep",
        "timestep_s=0.005,0.001",
        "--repeats",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(stdout.contains("recommended:"), "{stdout}");
    let j = frontier_json(&out);
    assert_eq!(j["repeats"], 2);
    assert_eq!(j["tolerance_m"], 0.001);
    // The finest setting is 0.001 s; the reference halves it at least once.
    assert_eq!(j["reference"]["finest_set"][1], "mujoco.timestep_s=0.001");
    let halvings = j["reference"]["halvings"].as_array().unwrap();
    assert!(!halvings.is_empty());
    assert_eq!(halvings[0]["timestep_s"], 0.0005);
    assert_eq!(
        halvings[0]["change_by_scene_m"].as_array().unwrap().len(),
        1
    );
    assert!(j["reference"]["cpu_s"].as_f64().unwrap() > 0.0);
    let points = j["points"].as_array().unwrap();
    assert_eq!(points.len(), 3, "two settings and the scene's own");
    assert_eq!(points[2]["scene_setting"], true);
    for p in points {
        assert_eq!(p["status"], "ok", "{p}");
        assert!(p["cpu_s"].as_f64().unwrap() > 0.0);
        assert!(p["real_time_factor"].as_f64().unwrap() > 0.0);
        let max = p["max_deviation_m"].as_f64().unwrap();
        let mean = p["mean_deviation_m"].as_f64().unwrap();
        assert!(max.is_finite() && mean <= max, "{p}");
        assert!(p["gap_m"].is_null(), "no --data, no gap");
    }
    // The coarser setting is the cheaper one.
    assert!(points[0]["cpu_s"].as_f64() < points[1]["cpu_s"].as_f64());
    let rec = &j["recommended"];
    assert!(rec["max_deviation_m"].as_f64().unwrap() <= 0.001);
    assert!(rec["speedup_over_reference"].as_f64().unwrap() > 1.0);
    let svg = std::fs::read_to_string(out.join("frontier_deviation.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("recommended:"));
    let png = std::fs::read(out.join("frontier_deviation.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    // The params file is read by `run --params`, and the rerun stays within
    // the tolerance of the reference on every row.
    let params = PhysicalParams::from_file(&out.join("recommended.toml")).unwrap();
    assert!(params.engine_settings.contains_key("mujoco"));
    let runs = tmp.path().join("runs");
    ok(&[
        "run",
        scene.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--params",
        out.join("recommended.toml").to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
    ]);
    let rerun =
        realitygap_data::runstore::read_run_csv(&runs.join("short_scene/mujoco/runs/run000.csv"))
            .unwrap();
    let reference = realitygap_data::runstore::read_run_csv(
        &out.join("reference/short_scene/mujoco/runs/run000.csv"),
    )
    .unwrap();
    assert_eq!(rerun.len(), reference.len());
    let (a, b) = (rerun.positions("wrist"), reference.positions("wrist"));
    for (i, (a, b)) in a.iter().zip(&b).enumerate() {
        let d = a.unwrap().distance(b.unwrap());
        assert!(d <= 0.001, "row {i}: {d} m from the reference");
    }
}

#[test]
fn a_diverging_setting_is_recorded_and_the_sweep_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = short_scene(tmp.path());
    let out = tmp.path().join("f");
    // Euler at 5 ms is unstable with the study's servos; implicitfast is not.
    ok(&[
        "frontier",
        scene.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--sweep",
        "integrator=euler,implicitfast",
        "--sweep",
        "timestep_s=0.005",
        "--repeats",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    let j = frontier_json(&out);
    let points = j["points"].as_array().unwrap();
    assert_eq!(points.len(), 3);
    assert_eq!(points[0]["status"], "diverged", "{}", points[0]);
    assert_eq!(points[0]["within_tolerance"], false);
    assert!(points[0]["max_deviation_m"].is_null(), "{}", points[0]);
    let message = points[0]["scenes"][0]["message"].as_str().unwrap();
    assert!(message.contains("diverged at t ="), "{message}");
    assert_eq!(points[1]["status"], "ok");
    assert_eq!(j["recommended"]["label"], "implicitfast 0.005 s");
    assert!(out.join("frontier_deviation.png").is_file());
}

#[test]
fn bad_sweeps_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = short_scene(tmp.path());
    let out = tmp.path().join("f");
    let cases: [(&[&str], &[&str]); 7] = [
        (
            &["--sweep", "no_such_key=1,2"],
            &["--sweep", "no_such_key", "timestep_s"],
        ),
        (
            &["--sweep", "integrator=euler,bogus"],
            &["--sweep", "integrator", "bogus"],
        ),
        (
            &["--sweep", "timestep_s=0.003"],
            &["--sweep", "0.003", "control period"],
        ),
        (&["--sweep", "timestep_s=-1"], &["--sweep", "timestep_s"]),
        (&["--sweep", "timestep_s="], &["--sweep", "no values"]),
        (&["--sweep", "timestep_s"], &["--sweep", "KEY=V1,V2"]),
        (&["--tolerance-mm", "0"], &["--tolerance-mm", "positive"]),
    ];
    for (extra, expected) in cases {
        let mut args = vec![
            "frontier",
            scene.to_str().unwrap(),
            "--engine",
            "mujoco",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = realitygap(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{extra:?} was accepted");
        assert!(!err.contains("panicked"), "{extra:?}: {err}");
        for e in expected {
            assert!(err.contains(e), "{extra:?}: expected \"{e}\" in: {err}");
        }
    }
    let o = realitygap(&[
        "frontier",
        scene.to_str().unwrap(),
        "--engine",
        "nosuch",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--engine") && err.contains("nosuch"),
        "{err}"
    );
    assert!(!out.join("frontier.json").exists(), "nothing ran");
}

#[test]
fn with_data_the_gap_is_the_one_reproduce_reports() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let scene =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/scenes/scene1_single_joint.toml");
    let out = tmp.path().join("f");
    ok(&[
        "frontier",
        scene.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--sweep",
        "integrator=implicitfast",
        "--sweep",
        "timestep_s=0.005",
        "--repeats",
        "1",
        "--max-halvings",
        "1",
        "--data",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let j = frontier_json(&out);
    let points = j["points"].as_array().unwrap();
    // The scene's own setting (Euler, 1e-4 s): MuJoCo's scene-1 entry of
    // the reproduce table, 8.347 m.
    let own = points[1]["gap_m"].as_f64().unwrap();
    assert!((own - 8.347).abs() < 0.001, "{own}");
    assert!(points[0]["gap_m"].as_f64().unwrap().is_finite());
    assert!(j["reference"]["gap_m"].as_f64().unwrap().is_finite());
    assert!(out.join("frontier_gap.svg").is_file() && out.join("frontier_gap.png").is_file());
}

/// A scene outside the study (the iiwa reach) swept with study scenes:
/// each point's gap is the study scenes' alone, the same as without it, and
/// a note says the other scene has no real arm to compare with.
#[test]
fn a_scene_outside_the_study_leaves_the_gap_to_the_study_scenes() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/scenes");
    let run = |name: &str, extra: &[&str]| {
        let out = tmp.path().join(name);
        let mut args = vec![
            "frontier".to_string(),
            scenes
                .join("scene1_single_joint.toml")
                .display()
                .to_string(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        for a in [
            "--engine",
            "ode",
            "--sweep",
            "timestep_s=0.01",
            "--repeats",
            "1",
            "--max-halvings",
            "1",
            "--data",
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ] {
            args.push(a.to_string());
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        ok(&args);
        frontier_json(&out)
    };
    let alone = run("alone", &[]);
    let iiwa = scenes.join("iiwa_reach.toml").display().to_string();
    let mixed = run("mixed", &[&iiwa]);
    for (a, b) in alone["points"]
        .as_array()
        .unwrap()
        .iter()
        .zip(mixed["points"].as_array().unwrap())
    {
        let (ga, gb) = (a["gap_m"].as_f64().unwrap(), b["gap_m"].as_f64().unwrap());
        assert!((ga - gb).abs() < 1e-9, "{ga} vs {gb}");
    }
    let notes = mixed["notes"].to_string();
    assert!(notes.contains("iiwa_reach"), "{notes}");
    assert!(tmp.path().join("mixed/frontier_gap.svg").is_file());
}
