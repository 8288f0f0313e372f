//! Helpers shared by the CLI's end-to-end tests: running the binary and
//! scratch folders.

// Each test file uses the helpers it needs.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `realitygap` binary with `args`.
pub fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// Output bytes as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A fresh, empty scratch folder `<group>/<name>` in cargo's temporary
/// folder for tests.
pub fn scratch(group: &str, name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(group)
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A path as a command-line argument.
pub fn path(p: &Path) -> String {
    p.display().to_string()
}

/// Imports the first `episodes` episodes of the independent writer's MCAP
/// bags (`scripts/make-fixtures`) into `dir/real`.
pub fn import_bags(dir: &Path, episodes: usize) -> PathBuf {
    let real = dir.join("real");
    let f = realitygap_core::testing::joint_recording_fixtures();
    let mut args = vec!["import".to_string(), "rosbag".into()];
    for e in 0..episodes {
        args.push(path(&f.join(format!("mcap/episode_{e:03}"))));
    }
    args.extend([
        "--robot".into(),
        path(&realitygap_core::testing::iiwa_urdf()),
        "--out".into(),
        path(&real),
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = realitygap(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    real
}

/// The writer's known parameters (`truth.json`: kp, kd as kv, damping,
/// armature, frictionloss, the delay) as a params file in `dir`, without
/// the keys in `leave_out` (`delay_s` leaves the delay out).
pub fn truth_params(dir: &Path, leave_out: &[&str]) -> PathBuf {
    let truth = truth();
    let mut toml = String::new();
    for (name, j) in truth["joints"].as_object().unwrap() {
        toml.push_str(&format!("[joints.{name}]\n"));
        for (ours, theirs) in [
            ("kp", "kp"),
            ("kv", "kd"),
            ("damping", "damping"),
            ("armature", "armature"),
            ("frictionloss", "frictionloss"),
        ] {
            if !leave_out.contains(&ours) {
                toml.push_str(&format!("{ours} = {}\n", j[theirs].as_f64().unwrap()));
            }
        }
    }
    if !leave_out.contains(&"delay_s") {
        toml.push_str(&format!(
            "[controller]\ndelay_s = {}\n",
            truth["delay_s"].as_f64().unwrap()
        ));
    }
    let file = dir.join(format!("truth-{}.toml", leave_out.join("-")));
    std::fs::write(&file, toml).unwrap();
    file
}

/// The writer's `truth.json`.
pub fn truth() -> serde_json::Value {
    let f = realitygap_core::testing::joint_recording_fixtures().join("truth.json");
    serde_json::from_str(&std::fs::read_to_string(&f).unwrap()).unwrap()
}
