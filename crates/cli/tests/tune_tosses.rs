//! `realitygap tune` of a study of tosses end to end: the contact fitted on
//! real tosses (the three committed with `realitygap-contactnets`, BSD
//! 3-Clause, written by the data's authors, and the 456 built in), scored
//! on the held-out ones, resumed, and its `tuned.toml` replayed.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../contactnets/tests/data")
}

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets")
}

/// A study of the three committed tosses: 185 and 563 fitted, 229 held out.
fn small_study(dir: &Path) -> PathBuf {
    let file = dir.join("three.toml");
    std::fs::write(
        &file,
        "kind = \"tosses\"\nname = \"three\"\ntitle = \"three tosses\"\ntosses = \"tosses\"\nexperiment = \"experiment.json\"\nheld_out_every = 2\nbudget = 8\n",
    )
    .unwrap();
    file
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn the_contact_is_fitted_scored_on_held_out_tosses_resumed_and_replayed() {
    let tmp = tempfile::tempdir().unwrap();
    let study = small_study(tmp.path());
    let out = tmp.path().join("tuned");
    let data_dir = data();
    let args = [
        "tune",
        study.to_str().unwrap(),
        "--data",
        data_dir.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--out",
        out.to_str().unwrap(),
    ];
    let o = realitygap(&args);
    let stdout = text(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("2 tosses to fit on, 1 held out"),
        "{}",
        text(&o.stderr)
    );
    let s = summary(&out);
    assert_eq!(s["fitted_tosses"], serde_json::json!(["185", "563"]));
    assert_eq!(s["held_out_tosses"], serde_json::json!(["229"]));
    assert_eq!(s["evaluations"], 8);
    let rows = s["held_out"].as_array().unwrap();
    let sources: Vec<&str> = rows.iter().map(|r| r["source"].as_str().unwrap()).collect();
    assert_eq!(sources, ["mujoco at its defaults", "mujoco tuned", "ideal"]);
    for r in rows {
        assert_eq!(r["tosses"], 1, "{r}");
        assert!(r["position_error_edges"].as_f64().unwrap() > 0.0, "{r}");
    }
    let keys: Vec<&str> = s["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["key"].as_str().unwrap())
        .collect();
    assert_eq!(
        keys,
        [
            "objects.cube.friction",
            "objects.cube.restitution",
            "contact.time_constant_s",
            "contact.damping_ratio"
        ]
    );
    let tuned = std::fs::read_to_string(out.join("tuned.toml")).unwrap();
    assert!(
        tuned.contains("[objects.cube]") && tuned.contains("[contact]"),
        "{tuned}"
    );
    assert!(stdout.contains("## Held-out tosses"), "{stdout}");

    // The same command again resumes: every evaluation is replayed from
    // history.csv and the result is the same.
    let o = realitygap(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(
        std::fs::read_to_string(out.join("tuned.toml")).unwrap(),
        tuned
    );
    assert_eq!(summary(&out)["parameters"], s["parameters"]);

    // The contract: tuned.toml is what `replay` takes for the tosses.
    let real = tmp.path().join("real");
    let o = realitygap(&[
        "import",
        "contactnets",
        data().join("tosses").to_str().unwrap(),
        "--out",
        real.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let replay = tmp.path().join("replay");
    let o = realitygap(&[
        "replay",
        real.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--engine",
        "ideal",
        "--params",
        out.join("tuned.toml").to_str().unwrap(),
        "--out",
        replay.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(replay.join("mujoco/runs/229.csv").is_file());
    assert!(replay.join("ideal/runs/229.csv").is_file());
}

#[test]
fn the_built_in_study_tunes_on_365_tosses_and_holds_out_91() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("tuned");
    let o = realitygap(&[
        "tune",
        assets()
            .join("studies/contactnets2020.toml")
            .to_str()
            .unwrap(),
        "--engine",
        "mujoco",
        "--budget",
        "4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let s = summary(&out);
    assert_eq!(s["fitted_tosses"].as_array().unwrap().len(), 365);
    assert_eq!(s["held_out_tosses"].as_array().unwrap().len(), 91);
    let rows = s["held_out"].as_array().unwrap();
    let error = |i: usize| rows[i]["position_error_edges"].as_f64().unwrap();
    // The search starts at the data's published friction and restitution:
    // already far closer than MuJoCo's defaults (friction 1), and than
    // the physics-free toss.
    assert!(error(1) < 0.5 * error(0), "{s}");
    assert!(error(1) < 0.5 * error(2), "{s}");
}

#[test]
fn options_of_the_arm_s_tune_and_the_physics_free_engine_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let study = small_study(tmp.path());
    let out = tmp.path().join("t");
    let data_dir = data();
    let base = [
        "tune",
        study.to_str().unwrap(),
        "--data",
        data_dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    for (extra, says) in [
        (
            vec!["--engine", "mujoco", "--runs", "1-2"],
            "--runs does not apply to a study of tosses",
        ),
        (vec!["--engine", "ideal"], "has nothing to tune"),
    ] {
        let mut args: Vec<&str> = base.to_vec();
        args.extend(extra);
        let o = realitygap(&args);
        assert!(!o.status.success());
        assert!(text(&o.stderr).contains(says), "{}", text(&o.stderr));
    }
    let space = tmp.path().join("space.toml");
    std::fs::write(
        &space,
        "[params]\n\"joints.j.damping\" = { low = 0.0, high = 1.0 }\n",
    )
    .unwrap();
    let mut args: Vec<&str> = base.to_vec();
    args.extend(["--engine", "mujoco", "--space", space.to_str().unwrap()]);
    let o = realitygap(&args);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("`joints.j.damping` is not a parameter of a toss"),
        "{}",
        text(&o.stderr)
    );
    assert!(!out.join("tuned.toml").exists());
}
