//! End-to-end tests of `realitygap compare` on the study's recordings.

use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn compare(extra: &[&str]) -> Option<(String, String)> {
    let data = realitygap::paper_data_for_tests()?;
    let out = bin()
        .arg("compare")
        .arg(root().join("assets/studies/collins2019.toml"))
        .arg("--data")
        .arg(data)
        .args(extra)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "compare failed: {stderr}");
    Some((String::from_utf8(out.stdout).unwrap(), stderr))
}

const SOURCES: [&str; 7] = [
    "MuJoCo",
    "PyBullet",
    "V-Rep Bullet 2.78",
    "V-Rep Bullet 2.83",
    "V-Rep Newton",
    "V-Rep Vortex",
    "V-Rep ODE",
];
const SCENES: [&str; 3] = [
    "scene1_single_joint",
    "scene2_two_joints",
    "scene3_cube_push",
];

#[test]
fn study_mode_json_has_every_cell_and_the_cube_figure() {
    let Some((out, _)) = compare(&["--mode", "study", "--format", "json"]) else {
        return;
    };
    let v: Value = serde_json::from_str(&out).unwrap();
    let rows = v["rows"].as_array().unwrap();
    // The study's 7 sources and the physics-free model, in 3 scenes.
    assert_eq!(rows.len(), 24);
    for scene in SCENES {
        let free = rows
            .iter()
            .find(|r| r["scene"] == scene && r["source"] == "physics-free (this tool)")
            .unwrap();
        let e = free["accumulated_error_m"].as_f64().unwrap();
        assert!(e.is_finite() && e > 1.0 && e < 200.0, "{scene}: {e}");
        for source in SOURCES {
            let row = rows
                .iter()
                .find(|r| r["scene"] == scene && r["source"] == source)
                .unwrap();
            let e = row["accumulated_error_m"].as_f64().unwrap();
            assert_eq!(row["runs_used"], 20);
            if source == "V-Rep ODE" {
                // The study averaged its diverged runs in: ~1e17 and beyond.
                assert!(e > 1e15, "{scene} ODE: {e}");
            } else {
                assert!(
                    e.is_finite() && e > 1.0 && e < 200.0,
                    "{scene} {source}: {e}"
                );
            }
        }
    }
    for source in SOURCES {
        assert!(v["totals"][source].as_f64().is_some(), "total of {source}");
    }
    let cube = &v["scenes"]["scene3_cube_push"]["reference"]["cube"];
    let dx = cube["final_offset_from_nominal_m"][0].as_f64().unwrap();
    assert!(
        (dx - 0.0975).abs() < 0.0005,
        "real cube final x - 0.5 m = {dx}"
    );
    // The per-scene measures are there too.
    let s1 = &v["scenes"]["scene1_single_joint"];
    assert!(s1["sources"][0]["goal"]["final_distance_m"]
        .as_f64()
        .is_some());
    assert!(s1["alignment"]["method"]
        .as_str()
        .unwrap()
        .contains("onset"));
}

#[test]
fn default_mode_flags_and_leaves_out_broken_runs() {
    let Some((out, _)) = compare(&["--format", "json"]) else {
        return;
    };
    let v: Value = serde_json::from_str(&out).unwrap();
    for row in v["rows"].as_array().unwrap() {
        let flagged: Vec<&str> = row["runs_flagged"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["excluded"] == true)
            .map(|f| f["run"].as_str().unwrap())
            .collect();
        match (
            row["source"].as_str().unwrap(),
            row["scene"].as_str().unwrap(),
        ) {
            ("V-Rep ODE", _) => {
                assert_eq!(flagged.len(), 20);
                assert!(row["accumulated_error_m"].is_null());
                assert_eq!(row["runs_used"], 0);
            }
            ("V-Rep Bullet 2.83", "scene2_two_joints") => {
                assert_eq!(flagged, ["Double_VRepBullet283_5"]);
                assert_eq!(row["runs_used"], 19);
            }
            (source, scene) => {
                assert!(flagged.is_empty(), "{scene} {source}: {flagged:?}");
                let e = row["accumulated_error_m"].as_f64().unwrap();
                assert!(
                    e.is_finite() && e > 0.0 && e < 200.0,
                    "{scene} {source}: {e}"
                );
            }
        }
    }
    // The default mode says which alignment it estimated, per run.
    let a = &v["scenes"]["scene1_single_joint"]["alignment"];
    assert!(a["method"].as_str().unwrap().contains("estimated"));
    assert_eq!(a["runs"].as_array().unwrap().len(), 20);
    assert!(a["runs"][0]["start_frame"].as_u64().is_some());
}

#[test]
fn every_format_renders() {
    let Some((md, _)) = compare(&["--format", "md"]) else {
        return;
    };
    for s in SOURCES {
        assert!(md.contains(&format!("| {s} |")), "markdown row for {s}");
    }
    let (csv, _) = compare(&["--format", "csv"]).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("source,scene,accumulated_error_m"));
    assert_eq!(lines.len(), 1 + 24 + 8);
    let (tex, _) = compare(&["--format", "latex", "--mode", "study"]).unwrap();
    assert!(
        tex.contains("\\begin{tabular}") && tex.contains("V-Rep ODE & $"),
        "{tex}"
    );
    let (fixed, _) = compare(&["--format", "json", "--alignment", "fixed:39"]).unwrap();
    let v: Value = serde_json::from_str(&fixed).unwrap();
    assert_eq!(
        v["scenes"]["scene1_single_joint"]["alignment"]["runs"][3]["start_frame"],
        39
    );
}

#[test]
fn bad_input_gives_a_located_error() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("broken.toml");
    std::fs::write(
        &study,
        "name = \"x\"\ncontrol_period_s = 0.05\n[[scenes]]\nname = \"s\"\nsteps = -3\n",
    )
    .unwrap();
    let out = bin().arg("compare").arg(&study).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("broken.toml") && err.contains("line 5"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    // A garbled recording: the error names the file and line.
    let data = dir.path().join("data");
    std::fs::create_dir_all(data.join("sim")).unwrap();
    std::fs::write(
        data.join("sim/run_0.csv"),
        "0 0 0.8 1 0 0 0 0.5 0 0.0375 1 0 0 0\n0 0 0.8 1 0 0 0 0.5 0 oops 1 0 0 0\n",
    )
    .unwrap();
    std::fs::write(
        &study,
        "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = 2\n[scenes.reference]\nname = \"r\"\nformat = \"recorded\"\nfiles = \"sim/run_*.csv\"\nquat_order = \"wxyz\"\n",
    )
    .unwrap();
    let out = bin()
        .arg("compare")
        .arg(&study)
        .arg("--data")
        .arg(&data)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("run_0.csv") && err.contains(":2"), "{err}");

    // A pattern that matches nothing.
    std::fs::write(
        &study,
        "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = 2\n[scenes.reference]\nname = \"r\"\nformat = \"recorded\"\nfiles = \"sim/none_*.csv\"\nquat_order = \"wxyz\"\n",
    )
    .unwrap();
    let out = bin()
        .arg("compare")
        .arg(&study)
        .arg("--data")
        .arg(&data)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("no file matches"),
        "{err}"
    );
}

/// The study file with absolute scene paths (so that a copy in another
/// folder still finds them), keeping only the study-wide sources named.
fn study_copy(dir: &std::path::Path, keep: &[&str]) -> PathBuf {
    let text = std::fs::read_to_string(root().join("assets/studies/collins2019.toml")).unwrap();
    let scenes = root().join("assets/scenes");
    let text = text.replace("\"../scenes/", &format!("\"{}/", scenes.display()));
    // Blocks start at a blank line; drop the [[sources]] blocks not kept.
    let kept: Vec<&str> = text
        .split("\n\n")
        .filter(|block| {
            let Some(rest) = block.trim_start().strip_prefix("[[sources]]") else {
                return true;
            };
            keep.iter()
                .any(|k| rest.contains(&format!("name = \"{k}\"\n")))
        })
        .collect();
    let path = dir.join("study.toml");
    std::fs::write(&path, kept.join("\n\n")).unwrap();
    path
}

fn compare_study(study: &std::path::Path, extra: &[&str]) -> std::process::Output {
    let data = realitygap::paper_data_for_tests().unwrap();
    bin()
        .arg("compare")
        .arg(study)
        .arg("--data")
        .arg(data)
        .args(extra)
        .output()
        .unwrap()
}

fn starts(v: &Value) -> Vec<(String, Vec<(String, u64)>)> {
    SCENES
        .iter()
        .map(|scene| {
            let runs = v["scenes"][scene]["alignment"]["runs"].as_array().unwrap();
            (
                scene.to_string(),
                runs.iter()
                    .map(|r| {
                        (
                            r["run"].as_str().unwrap().to_string(),
                            r["start_frame"].as_u64().unwrap(),
                        )
                    })
                    .collect(),
            )
        })
        .collect()
}

#[test]
fn real_start_frames_do_not_depend_on_the_simulated_sources() {
    if realitygap::paper_data_for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let full = compare_study(
        &study_copy(dir.path(), &SOURCES),
        &["--format", "json", "--no-physics-free"],
    );
    assert!(
        full.status.success(),
        "{}",
        String::from_utf8_lossy(&full.stderr)
    );
    let one_dir = tempfile::tempdir().unwrap();
    let one = compare_study(
        &study_copy(one_dir.path(), &["PyBullet"]),
        &["--format", "json", "--no-physics-free"],
    );
    assert!(
        one.status.success(),
        "{}",
        String::from_utf8_lossy(&one.stderr)
    );
    let full: Value = serde_json::from_slice(&full.stdout).unwrap();
    let one: Value = serde_json::from_slice(&one.stdout).unwrap();
    assert_eq!(
        one["rows"].as_array().unwrap().len(),
        3,
        "one source per scene"
    );
    let (a, b) = (starts(&full), starts(&one));
    assert_eq!(a, b);
    for (scene, runs) in &a {
        assert_eq!(runs.len(), 20, "{scene}");
    }
    // The registration, fitted on the real runs only, is the same too.
    assert_eq!(full["registration"], one["registration"]);
    assert!(full["registration"]["rotation_wxyz"].is_array());
}

#[test]
fn fit_on_runs_1_to_15_and_score_on_16_to_20() {
    let Some((out, _)) = compare(&["--runs", "1-15", "--holdout", "16-20", "--format", "json"])
    else {
        return;
    };
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(
        v["runs"].as_str().unwrap().contains("16-20"),
        "{}",
        v["runs"]
    );
    for scene in SCENES {
        let s = &v["scenes"][scene];
        let fit: Vec<&str> = s["runs"]["fit"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_str().unwrap())
            .collect();
        let scored: Vec<&str> = s["runs"]["scored"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_str().unwrap())
            .collect();
        assert_eq!((fit.len(), scored.len()), (15, 5), "{scene}");
        assert!(
            scored[0].contains("0016") && scored[4].contains("0020"),
            "{scored:?}"
        );
        assert_eq!(s["reference"]["runs_total"], 5);
        // The registration's residual on the held-out runs is reported.
        assert!(s["registration"]["residual_scored_rms_m"].as_f64().unwrap() < 0.05);
    }
    for row in v["rows"].as_array().unwrap() {
        if row["accumulated_error_m"].is_null() {
            continue;
        }
        let e = row["accumulated_error_m"].as_f64().unwrap();
        let i = &row["accumulated_error_interval_m"];
        let (lo, hi) = (i["low_m"].as_f64().unwrap(), i["high_m"].as_f64().unwrap());
        assert!(lo < hi && lo < e * 1.2 && hi > e * 0.8, "{row}");
    }
    // Every scene names its closest source, or says two cannot be told apart.
    for scene in SCENES {
        let verdict = v["scenes"][scene]["verdict"].as_str().unwrap();
        let c = &v["scenes"][scene]["closest_comparison"];
        let p = c["probability_closer"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&p));
        if c["distinguishable"] == true {
            assert!(verdict.starts_with("closest source:"), "{verdict}");
            assert_eq!(v["scenes"][scene]["closest_source"], c["closest"]);
        } else {
            assert!(verdict.contains("cannot be told apart"), "{verdict}");
            assert!(v["scenes"][scene]["closest_source"].is_null());
        }
    }
}

#[test]
fn intervals_in_every_format_and_a_saved_registration_reapplies() {
    let Some((md, _)) = compare(&["--verbose"]) else {
        return;
    };
    let row = md.lines().find(|l| l.starts_with("| PyBullet |")).unwrap();
    assert_eq!(row.matches(" [").count(), 4, "{row}");
    assert!(
        md.contains("Registration: capture frame registered into the world"),
        "{md}"
    );
    let (csv, _) = compare(&["--format", "csv"]).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let lo = header.iter().position(|h| *h == "interval_low_m").unwrap();
    let py = csv
        .lines()
        .find(|l| l.starts_with("PyBullet,scene1"))
        .unwrap();
    assert!(
        py.split(',').nth(lo).unwrap().parse::<f64>().is_ok(),
        "{py}"
    );
    let (tex, _) = compare(&["--format", "latex"]).unwrap();
    assert!(tex.contains("{\\scriptsize ["), "{tex}");
    let dir = tempfile::tempdir().unwrap();
    let saved = dir.path().join("registration.json");
    let (json, _) = compare(&[
        "--format",
        "json",
        "--save-registration",
        saved.to_str().unwrap(),
    ])
    .unwrap();
    let given = compare(&[
        "--format",
        "json",
        "--registration",
        saved.to_str().unwrap(),
    ])
    .unwrap()
    .0;
    let (a, b): (Value, Value) = (
        serde_json::from_str(&json).unwrap(),
        serde_json::from_str(&given).unwrap(),
    );
    for (x, y) in a["rows"]
        .as_array()
        .unwrap()
        .iter()
        .zip(b["rows"].as_array().unwrap())
    {
        match (
            x["accumulated_error_m"].as_f64(),
            y["accumulated_error_m"].as_f64(),
        ) {
            (Some(p), Some(q)) => assert!((p - q).abs() < 1e-9, "{p} {q}"),
            (p, q) => assert_eq!(p, q),
        }
    }
    assert!(b["registration"]["method"]
        .as_str()
        .unwrap()
        .contains("registration.json"));
    // Without registration the table is different (the offset is paid).
    let (raw, _) = compare(&["--format", "json", "--registration", "none"]).unwrap();
    let raw: Value = serde_json::from_str(&raw).unwrap();
    assert!(raw["registration"].is_null());
    assert_ne!(raw["totals"]["PyBullet"], a["totals"]["PyBullet"]);
}

#[test]
fn bad_registration_files_and_run_ranges_name_the_culprit() {
    if realitygap::paper_data_for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let study = root().join("assets/studies/collins2019.toml");
    let cases = [
        (
            "nonunit.json",
            r#"{"rotation_wxyz": [1, 0.2, 0, 0], "translation_m": [0, 0, 0]}"#,
            "unit quaternion",
        ),
        (
            "nan.json",
            r#"{"rotation_wxyz": [1, 0, 0, 0], "translation_m": [0, NaN, 0]}"#,
            "nan.json",
        ),
        (
            "missing.json",
            r#"{"rotation_wxyz": [1, 0, 0, 0]}"#,
            "translation_m",
        ),
    ];
    for (name, text, expect) in cases {
        let file = dir.path().join(name);
        std::fs::write(&file, text).unwrap();
        let out = compare_study(&study, &["--registration", file.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name} accepted");
        assert!(err.contains(name) && err.contains(expect), "{name}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    for (args, expect) in [
        (
            vec!["--runs", "25-30"],
            "--runs \"25-30\" names run 30, but there are 20 runs (numbered 1-20)",
        ),
        (
            vec!["--holdout", "1-20"],
            "--holdout \"1-20\" holds out every run",
        ),
        (vec!["--runs", "1-x"], "--runs \"1-x\""),
        (
            vec!["--mode", "study", "--registration", "none"],
            "--registration does not apply to --mode study",
        ),
    ] {
        let out = compare_study(&study, &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(expect),
            "{args:?}: {err}"
        );
    }
}

/// The study mode's table is the study's procedure and must not change:
/// it is the one in the README.
#[test]
fn study_mode_table_matches_the_readme() {
    let Some((md, _)) = compare(&["--mode", "study"]) else {
        return;
    };
    let readme = std::fs::read_to_string(root().join("docs/study.md")).unwrap();
    let block = readme.split("<!-- study-table -->\n").nth(1).unwrap();
    let expected: Vec<&str> = block.lines().take_while(|l| l.starts_with('|')).collect();
    let got: Vec<&str> = md
        .lines()
        .skip_while(|l| !l.starts_with("| Source"))
        .take_while(|l| l.starts_with('|'))
        .collect();
    assert_eq!(got, expected);
}

/// `compare --joint-space`: per scene, the real arm in joint space (IK of
/// the wrist, registration fitted on runs 1-15, scored on 16-20) against
/// the physics-free model (the study's recorded simulators carry no joint
/// angles, so they have no row), in Markdown and JSON; csv is refused.
#[test]
fn joint_space_tables_of_the_study() {
    let Some((json, _)) = compare(&[
        "--joint-space",
        "--runs",
        "1-15",
        "--holdout",
        "16-20",
        "--format",
        "json",
        "--bootstrap",
        "0",
    ]) else {
        return;
    };
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let tables = v["joint_space"].as_array().unwrap();
    assert_eq!(tables.len(), 3);
    for (t, scene) in tables.iter().zip(SCENES) {
        assert_eq!(t["scene"], scene);
        assert_eq!(t["scored_runs"].as_array().unwrap().len(), 5);
        assert_eq!(t["fit_runs"].as_array().unwrap().len(), 15);
        let (mm, deg) = (
            t["ik_residual"][0].as_f64().unwrap(),
            t["ik_residual"][1].as_f64().unwrap(),
        );
        assert!(
            mm < 1.5 && deg < 2.0,
            "{scene}: IK residual {mm} mm, {deg} deg"
        );
        let rows = t["rows"].as_array().unwrap();
        assert_eq!(rows.len(), 1, "only the physics-free model: {rows:?}");
        let all = rows[0]["rms_all_deg"].as_f64().unwrap();
        assert!(all > 0.5 && all < 10.0, "{scene}: kinematic {all} deg");
    }
    let (md, _) = compare(&["--joint-space", "--bootstrap", "0"]).unwrap();
    assert!(
        md.contains("## Joint space") && md.contains("| physics-free (perfect tracking) | 1 |"),
        "{md}"
    );
    let out = bin()
        .args(["compare", "--joint-space", "--format", "csv"])
        .arg(root().join("assets/studies/collins2019.toml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--joint-space is written as md or json"));
}

/// Without --format the terminal gets the summary: the table, the verdict
/// per scene and each kind of flag once; --verbose gives the full tables.
/// Colour only where asked for, and never with NO_COLOR.
#[test]
fn the_terminal_gets_a_summary_and_colour_only_when_wanted() {
    let Some((short, _)) = compare(&[]) else {
        return;
    };
    let (full, _) = compare(&["--verbose"]).unwrap();
    assert!(short.lines().count() < 40, "{short}");
    assert!(full.lines().count() > 100, "{full}");
    assert!(!short.contains("Mean err") && full.contains("Mean err"));
    assert_eq!(short.matches("- diverged: ").count(), 1, "{short}");
    assert!(
        short.contains("60 runs (all left out) of V-Rep ODE"),
        "{short}"
    );
    assert!(full.matches("(left out): diverged").count() >= 60);
    assert!(short.contains("--verbose"), "{short}");
    assert!(!short.contains('\u{1b}'), "no colour in a pipe: {short}");
    let data = realitygap::paper_data_for_tests().unwrap();
    let coloured = |no_color: bool| {
        let mut c = bin();
        c.arg("compare")
            .arg(root().join("assets/studies/collins2019.toml"))
            .arg("--data")
            .arg(&data)
            .env("CLICOLOR_FORCE", "1")
            .env_remove("NO_COLOR");
        if no_color {
            c.env("NO_COLOR", "1");
        }
        String::from_utf8(c.output().unwrap().stdout).unwrap()
    };
    assert!(
        coloured(false).contains("\u{1b}["),
        "CLICOLOR_FORCE gives colour"
    );
    assert!(!coloured(true).contains('\u{1b}'), "NO_COLOR wins");
}

/// `--physics-free` adds the physics-free model (perfect tracking, run
/// from each scene file) and, from a tune's folder, the physics-free model
/// fitted beside it; a parameters file gives the same row as its tune
/// folder; a folder without a fitted model, or no such path, is a clear
/// error.
#[test]
fn physics_free_rows_from_the_scene_files_and_a_tune_folder() {
    if realitygap::paper_data_for_tests().is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // A tune's output folder (its engine and tuned.toml) with the
    // physics-free model fitted beside it, as `realitygap tune` writes it.
    let tune = tmp.path().join("tune-mujoco");
    let fitted = tune.join("physics-free-actuator");
    std::fs::create_dir_all(&fitted).unwrap();
    std::fs::write(tune.join("summary.json"), r#"{"engine": "mujoco"}"#).unwrap();
    std::fs::write(tune.join("tuned.toml"), "[controller]\ndelay_s = 0.01\n").unwrap();
    std::fs::write(fitted.join("summary.json"), r#"{"engine": "ideal"}"#).unwrap();
    let fitted_toml = fitted.join("tuned.toml");
    std::fs::write(
        &fitted_toml,
        "[controller]\ndelay_s = 0.05\n\n[actuator]\nfrequency_rad_s = 20.0\ndamping_ratio = 0.5\n",
    )
    .unwrap();
    let run = |physics_free: &[&str]| -> Value {
        let mut args = vec!["--runs", "1-15", "--holdout", "16-20", "--format", "json"];
        args.extend(physics_free);
        serde_json::from_str(&compare(&args).unwrap().0).unwrap()
    };
    let row = |v: &Value, scene: &str, source: &str| -> Option<Value> {
        v["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["scene"] == scene && r["source"] == source)
            .cloned()
    };
    let error = |v: &Value, scene: &str, source: &str| -> Option<f64> {
        row(v, scene, source).map(|r| r["accumulated_error_m"].as_f64().unwrap())
    };
    let plain = run(&["--physics-free"]);
    let by_default = run(&[]);
    let without = run(&["--no-physics-free"]);
    let from_dir = run(&["--physics-free", tune.to_str().unwrap()]);
    let from_file = run(&["--physics-free", fitted_toml.to_str().unwrap()]);
    for scene in SCENES {
        let perfect = error(&plain, scene, "physics-free (this tool)").unwrap();
        assert!(perfect.is_finite() && perfect > 0.1, "{scene}: {perfect}");
        assert_eq!(error(&plain, scene, "physics-free (tuned)"), None);
        // Perfect tracking is a row by default; --no-physics-free leaves
        // it out, and the study's own rows are the same either way.
        assert_eq!(
            row(&by_default, scene, "physics-free (this tool)"),
            row(&plain, scene, "physics-free (this tool)")
        );
        assert_eq!(error(&without, scene, "physics-free (this tool)"), None);
        for source in SOURCES {
            assert_eq!(
                row(&without, scene, source),
                row(&by_default, scene, source),
                "{scene} {source}"
            );
        }
        // The untuned row does not depend on the tune.
        assert_eq!(
            error(&from_dir, scene, "physics-free (this tool)"),
            Some(perfect)
        );
        let tuned = error(&from_dir, scene, "physics-free (tuned)").unwrap();
        assert!(
            tuned.is_finite() && (tuned - perfect).abs() > 1e-3,
            "{scene}"
        );
        assert_eq!(
            error(&from_file, scene, "physics-free (tuned)"),
            Some(tuned)
        );
        // The study's own sources are all still there.
        for source in SOURCES {
            assert!(row(&from_dir, scene, source).is_some(), "{scene} {source}");
        }
    }
    // A tune folder without a fitted physics-free model, and no such path.
    std::fs::remove_dir_all(&fitted).unwrap();
    for (given, says) in [
        (tune.clone(), "holds no fitted physics-free model"),
        (
            tmp.path().join("nosuch"),
            "no such parameters file or tune folder",
        ),
    ] {
        let out = compare_study(
            &root().join("assets/studies/collins2019.toml"),
            &["--physics-free", given.to_str().unwrap()],
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(stderr.contains(says), "{stderr}");
        assert!(stderr.contains(&given.display().to_string()), "{stderr}");
    }
}

/// A study that has a physics-free source already (as a `reproduce`
/// folder's study has) gets no second one by default.
#[test]
fn no_second_physics_free_row_by_default() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = root().join("assets/scenes/scene1_single_joint.toml");
    let runs = tmp.path().join("runs");
    let out = bin()
        .args(["run", scene.to_str().unwrap(), "--engine", "ideal", "--out"])
        .arg(&runs)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let study = tmp.path().join("study.toml");
    std::fs::write(
        &study,
        format!(
            r#"name = "has its physics-free row"
[[scenes]]
name = "scene1_single_joint"
scene = "{}"
steps = 120
[scenes.reference]
name = "reference"
format = "store"
dir = "runs/scene1_single_joint/ideal"
[[scenes.sources]]
name = "physics-free (this tool)"
format = "store"
dir = "runs/scene1_single_joint/ideal"
"#,
            scene.display()
        ),
    )
    .unwrap();
    let out = bin()
        .arg("compare")
        .arg(&study)
        .args(["--data", "none", "--format", "csv"])
        .output()
        .unwrap();
    let csv = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = csv
        .lines()
        .filter(|l| l.starts_with("physics-free (this tool),scene1_single_joint,"))
        .count();
    assert_eq!(rows, 1, "{csv}");
}
