//! The guide's your-robot walkthrough (docs/your-robot.md, its first code
//! block), run as a user types it, start to end, on recordings of two
//! robots written by an independent writer (`scripts/make-fixtures`):
//!
//! - a Franka Emika Panda with a gripper (pybullet's `panda.urdf`: two
//!   prismatic finger joints, the second a `<mimic>` of the first, meshes as
//!   `package://meshes/...` beside the URDF), whose bags record the seven
//!   arm joints only, as franka_ros2's do, with commands that name no joint;
//! - the KUKA iiwa of the other tests.
//!
//! `import rosbag`, then `replay --params my_gains.toml` (a gains file with
//! `kv`: every engine's row is there, or marked with the reason), then
//! `tune --recordings ... --params my_gains.toml`.

mod common;
use common::{path, realitygap, scratch, text};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The three commands of the guide, for one robot.
struct Walkthrough {
    bags: Vec<PathBuf>,
    urdf: PathBuf,
    truth: Value,
}

/// The Franka's fixtures.
fn franka() -> Walkthrough {
    let root = realitygap_core::testing::workspace();
    let f = root.join("third_party/fixtures/franka");
    assert!(
        f.join("truth.json").is_file(),
        "the Franka fixtures are missing at {}: run scripts/make-fixtures (scripts/setup --tests does)",
        f.display()
    );
    Walkthrough {
        bags: vec![f.join("mcap/episode_000"), f.join("sqlite3/episode_001")],
        urdf: root.join("third_party/pybullet_data/franka_panda/panda.urdf"),
        truth: serde_json::from_str(&std::fs::read_to_string(f.join("truth.json")).unwrap())
            .unwrap(),
    }
}

/// The iiwa's fixtures.
fn iiwa() -> Walkthrough {
    let f = realitygap_core::testing::joint_recording_fixtures();
    Walkthrough {
        bags: (0..2)
            .map(|e| f.join(format!("mcap/episode_{e:03}")))
            .collect(),
        urdf: realitygap_core::testing::iiwa_urdf(),
        truth: serde_json::from_str(&std::fs::read_to_string(f.join("truth.json")).unwrap())
            .unwrap(),
    }
}

/// A user's gains file: the servo's kp and kv (the writer's kd) per joint,
/// and nothing else.
fn my_gains(dir: &Path, truth: &Value) -> PathBuf {
    let mut toml = String::from("# The servo gains of my arm's controller.\n");
    for (name, j) in truth["joints"].as_object().unwrap() {
        toml.push_str(&format!(
            "[joints.{name}]\nkp = {}\nkv = {}\n",
            j["kp"].as_f64().unwrap(),
            j["kd"].as_f64().unwrap()
        ));
    }
    let file = dir.join("my_gains.toml");
    std::fs::write(&file, toml).unwrap();
    file
}

/// Runs the walkthrough in `dir`; returns the import's standard output,
/// the replay's rows and the tune's summary.
fn walk(dir: &Path, w: &Walkthrough) -> (String, Vec<Value>, Value) {
    let real = dir.join("results/real/my_arm");
    // import rosbag my_bag/ --robot my_arm.urdf --out results/real/my_arm
    let mut args = vec!["import".to_string(), "rosbag".into()];
    args.extend(w.bags.iter().map(|b| path(b)));
    args.extend(["--robot".into(), path(&w.urdf), "--out".into(), path(&real)]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let import = realitygap(&args);
    let said = text(&import.stdout);
    assert!(
        import.status.success(),
        "import: {said}{}",
        text(&import.stderr)
    );
    // replay results/real/my_arm --params my_gains.toml --out results/replay
    let gains = my_gains(dir, &w.truth);
    let replayed = dir.join("results/replay");
    let replay = realitygap(&[
        "replay",
        &path(&real),
        "--params",
        &path(&gains),
        "--out",
        &path(&replayed),
    ]);
    assert!(
        replay.status.success(),
        "replay: {}{}",
        text(&replay.stdout),
        text(&replay.stderr)
    );
    let rows: Vec<Value> =
        serde_json::from_str(&std::fs::read_to_string(replayed.join("joint_space.json")).unwrap())
            .unwrap();
    // tune --recordings results/real/my_arm --engine mujoco --params my_gains.toml --out results/tune-my-arm
    let tuned = dir.join("results/tune-my-arm");
    let tune = realitygap(&[
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        "mujoco",
        "--params",
        &path(&gains),
        "--out",
        &path(&tuned),
    ]);
    assert!(
        tune.status.success(),
        "tune: {}{}",
        text(&tune.stdout),
        text(&tune.stderr)
    );
    assert!(tuned.join("tuned.toml").is_file());
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(tuned.join("summary.json")).unwrap())
            .unwrap();
    (said, rows, summary)
}

/// Every compiled engine has its row, with numbers or with the reason it
/// was not replayed; the physics-free model's row is `ideal`.
fn every_engine_has_a_row(rows: &[Value]) {
    assert_eq!(rows[0]["source"], "ideal", "{rows:?}");
    for e in realitygap::compiled_engines() {
        let row = rows
            .iter()
            .find(|r| r["source"] == e.name())
            .unwrap_or_else(|| panic!("no row for {}: {rows:?}", e.name()));
        assert!(
            row["rms_all_deg"].as_f64().is_some_and(f64::is_finite)
                || row["refused"].as_str().is_some_and(|w| w.contains("kv")),
            "{row}"
        );
    }
}

#[test]
fn a_franka_with_a_gripper_goes_through_the_guide_as_written() {
    let dir = scratch("your-robot", "franka");
    let w = franka();
    let (said, rows, summary) = walk(&dir, &w);
    // The fingers the bag does not record are held, said in one line; the
    // package:// meshes are found beside the URDF, said in one line.
    let held: Vec<&str> = said.lines().filter(|l| l.contains("held still")).collect();
    assert_eq!(held.len(), 1, "{said}");
    assert!(
        held[0].contains("panda_finger_joint1 at 0")
            && held[0].contains("mimic joints panda_finger_joint2")
            && held[0].contains("--hold JOINT=VALUE"),
        "{said}"
    );
    assert!(
        said.contains("note: package 'meshes' of the URDF's package:// meshes is not known: found beside the URDF"),
        "{said}"
    );
    // The commands name no joint: they are the recorded joints'.
    assert!(said.contains("panda_joint1, panda_joint2"), "{said}");
    let manifest: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("results/real/my_arm/manifest.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(manifest["settings"]["joints"].as_array().unwrap().len(), 7);
    assert_eq!(
        manifest["settings"]["held_joints"]["panda_finger_joint1"],
        0.0
    );
    // The end effector is the hand the last recorded joint carries, not a
    // held finger.
    assert_eq!(manifest["settings"]["end_effector_link"], "panda_hand");
    every_engine_has_a_row(&rows);
    // MuJoCo with the writer's gains (the rest at its defaults) follows
    // the arm far closer than perfect tracking does; tuned, closer still.
    let rms = |s: &str| {
        rows.iter().find(|r| r["source"] == s).unwrap()["rms_all_deg"]
            .as_f64()
            .unwrap()
    };
    println!(
        "franka: ideal {:.3} deg, mujoco {:.3} deg",
        rms("ideal"),
        rms("mujoco")
    );
    assert!(rms("mujoco") < rms("ideal"), "{rows:?}");
    println!("franka tune: {summary}");
    // One held-out episode: the summary says why its interval is missing.
    let md = std::fs::read_to_string(dir.join("results/tune-my-arm/summary.md")).unwrap();
    assert!(
        md.contains("n/a: an interval over episodes needs at least two episodes; the training set has 1, the held-out set has 1"),
        "{md}"
    );
}

#[test]
fn the_iiwa_goes_through_the_guide_as_written() {
    let dir = scratch("your-robot", "iiwa");
    let w = iiwa();
    let (said, rows, _) = walk(&dir, &w);
    assert!(!said.contains("held still"), "{said}");
    every_engine_has_a_row(&rows);
}

#[test]
fn a_held_finger_can_be_placed_and_a_wrong_hold_is_named() {
    let dir = scratch("your-robot", "hold");
    let w = franka();
    let real = dir.join("real");
    let import = |extra: &[&str]| {
        let mut args = vec![
            "import".to_string(),
            "rosbag".into(),
            path(&w.bags[0]),
            "--robot".into(),
            path(&w.urdf),
            "--out".into(),
            path(&real),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        realitygap(&args)
    };
    let out = import(&["--hold", "panda_finger_joint1=0.02"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("panda_finger_joint1 at 0.02"),
        "{}",
        text(&out.stdout)
    );
    let out = import(&["--hold", "panda_joint3=0.1"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains(
            "--hold panda_joint3=0.1: the recording names joint 'panda_joint3', so it is not held"
        ),
        "{}",
        text(&out.stderr)
    );
    let out = import(&["--hold", "gripper=0.1"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("has no moving joint 'gripper'"),
        "{}",
        text(&out.stderr)
    );
    // A recorded name the URDF spells otherwise, renamed on import: the
    // URDF's first joint is `j1` here (its meshes beside it, as before).
    let urdf = dir.join("renamed.urdf");
    let text_of = std::fs::read_to_string(&w.urdf).unwrap();
    std::fs::write(&urdf, text_of.replace("\"panda_joint1\"", "\"j1\"")).unwrap();
    std::os::unix::fs::symlink(w.urdf.parent().unwrap().join("meshes"), dir.join("meshes"))
        .unwrap();
    let renamed = |extra: &[&str]| {
        let mut args = vec![
            "import".to_string(),
            "rosbag".into(),
            path(&w.bags[0]),
            "--robot".into(),
            path(&urdf),
            "--out".into(),
            path(&dir.join("renamed")),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        realitygap(&args)
    };
    let out = renamed(&[]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("names joint 'panda_joint1'"),
        "{}",
        text(&out.stderr)
    );
    let out = renamed(&["--rename", "panda_joint1=j1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("renamed/manifest.json")).unwrap())
            .unwrap();
    assert_eq!(manifest["settings"]["joints"][0], "j1");
}

#[test]
fn gains_given_in_part_are_named_and_an_unstable_tune_says_what_works() {
    let dir = scratch("your-robot", "partial");
    let w = iiwa();
    let real = dir.join("real");
    let import = realitygap(&[
        "import",
        "rosbag",
        &path(&w.bags[0]),
        "--robot",
        &path(&w.urdf),
        "--out",
        &path(&real),
    ]);
    assert!(import.status.success(), "{}", text(&import.stderr));
    // kp without kv: one warning naming the default kv that fills it in.
    let gains = dir.join("kp_only.toml");
    std::fs::write(&gains, "[joints.lbr_iiwa_joint_2]\nkp = 800.0\n").unwrap();
    let replay = realitygap(&[
        "replay",
        &path(&real),
        "--engine",
        "mujoco",
        "--params",
        &path(&gains),
        "--out",
        &path(&dir.join("replay")),
    ]);
    let stderr = text(&replay.stderr);
    assert!(replay.status.success(), "{stderr}");
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("without kv"))
        .collect();
    assert_eq!(warnings.len(), 1, "{stderr}");
    assert!(
        warnings[0].contains(
            "joints.lbr_iiwa_joint_2: kp = 800 is given without kv: the scene's kv = 600 N m s/rad fills it in"
        ),
        "{stderr}"
    );
    // Settings the engine cannot integrate: the tune's refusal suggests
    // what works for a tune, not a flag it does not take.
    let euler = dir.join("euler.toml");
    std::fs::write(&euler, "[engine.mujoco]\nintegrator = \"Euler\"\n").unwrap();
    let tune = realitygap(&[
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        "mujoco",
        "--params",
        &path(&euler),
        "--out",
        &path(&dir.join("tune")),
    ]);
    let stderr = text(&tune.stderr);
    assert!(!tune.status.success());
    assert!(
        stderr.contains("refused before running")
            && stderr.contains("a tune stays within the stable range when its --space file bounds the parameter there"),
        "{stderr}"
    );
}
