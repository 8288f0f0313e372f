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
    assert_eq!(rows.len(), 21);
    for scene in SCENES {
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
    assert_eq!(lines.len(), 1 + 21 + 7);
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
