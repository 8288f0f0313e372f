//! `realitygap run` end to end: a batch killed midway keeps its finished
//! runs byte for byte, and a rerun completes only the missing ones.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_realitygap")
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/scenes")
        .join(format!("{name}.toml"))
}

fn manifest(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap()
}

fn finished(dir: &Path) -> Vec<String> {
    if !dir.join("manifest.json").exists() {
        return Vec::new();
    }
    manifest(dir)["runs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["status"] == "ok")
        .map(|r| r["id"].as_str().unwrap().to_string())
        .collect()
}

/// The bytes and modification time of every run file.
fn snapshot(dir: &Path) -> BTreeMap<String, (Vec<u8>, SystemTime)> {
    let mut out = BTreeMap::new();
    for e in std::fs::read_dir(dir.join("runs")).unwrap() {
        let e = e.unwrap();
        let name = e.file_name().to_string_lossy().into_owned();
        if name.ends_with(".csv") {
            out.insert(
                name,
                (
                    std::fs::read(e.path()).unwrap(),
                    e.metadata().unwrap().modified().unwrap(),
                ),
            );
        }
    }
    out
}

#[test]
fn killed_batch_resumes_without_recomputing_finished_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("results");
    let dir = out.join("scene1_single_joint/mujoco");
    let args = |c: &mut Command| {
        c.arg("run")
            .arg(scene("scene1_single_joint"))
            .args([
                "--engine",
                "mujoco",
                "--repeats",
                "5",
                "--jobs",
                "1",
                "--out",
            ])
            .arg(&out);
    };

    // Start the batch and kill it once a run has finished.
    let mut cmd = Command::new(exe());
    args(&mut cmd);
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while finished(&dir).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no run finished within 120 s"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the batch ended before it could be interrupted"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let done_before = finished(&dir);
    assert!(
        !done_before.is_empty() && done_before.len() < 5,
        "finished before the kill: {done_before:?}"
    );
    let before = snapshot(&dir);
    let entries_before: Vec<serde_json::Value> = manifest(&dir)["runs"].as_array().unwrap().clone();
    std::thread::sleep(Duration::from_millis(50));

    // Rerun: completes the rest, keeps the finished ones untouched.
    let mut cmd = Command::new(exe());
    args(&mut cmd);
    let result = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(
        result.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert!(
        stdout.contains(&format!(
            "{} ok, 0 diverged, 0 failed, {} kept",
            5 - done_before.len(),
            done_before.len()
        )),
        "{stdout}"
    );
    let after = snapshot(&dir);
    assert_eq!(after.len(), 5);
    for (name, (bytes, mtime)) in &before {
        // A run file that existed but was not yet in the manifest (killed
        // between the two writes) may be rewritten; finished ones may not.
        if done_before.iter().any(|id| format!("{id}.csv") == *name) {
            assert_eq!(&after[name].0, bytes, "{name} changed");
            assert_eq!(after[name].1, *mtime, "{name} was rewritten");
        }
    }
    let entries_after = manifest(&dir)["runs"].as_array().unwrap().clone();
    for e in &entries_before {
        if e["status"] == "ok" {
            assert!(entries_after.contains(e), "manifest entry changed: {e}");
        }
    }
    // Deterministic engine, no perturbation: every run is the same.
    let first = &after.values().next().unwrap().0;
    assert!(after.values().all(|(b, _)| b == first));
    assert_eq!(manifest(&dir)["settings"]["config"]["deterministic"], true);

    // A third run has nothing left to do.
    let mut cmd = Command::new(exe());
    args(&mut cmd);
    let result = cmd.output().unwrap();
    assert!(result.status.success());
    assert!(String::from_utf8_lossy(&result.stdout).contains("0 ok, 0 diverged, 0 failed, 5 kept"));
    assert_eq!(snapshot(&dir), after);
}

#[test]
fn rerun_with_other_settings_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        Command::new(exe())
            .arg("run")
            .arg(scene("scene1_single_joint"))
            .args([
                "--engine",
                "mujoco",
                "--repeats",
                "1",
                "--set",
                "timestep_s=0.0005",
                // Euler at 5e-4 s is refused on the Mico2 (kv*dt/I_eff
                // past 2); implicitfast runs it.
                "--set",
                "integrator=implicitfast",
                "--out",
            ])
            .arg(tmp.path())
            .args(extra)
            .output()
            .unwrap()
    };
    assert!(run(&[]).status.success());
    let other = run(&["--perturb", "initial_offset_deg=1"]);
    assert!(!other.status.success());
    let err = String::from_utf8_lossy(&other.stderr);
    assert!(err.contains("holds runs made with other settings"), "{err}");
}

#[test]
fn perturbed_repeats_differ_and_are_seeded() {
    let tmp = tempfile::tempdir().unwrap();
    let run = |out: &Path| {
        Command::new(exe())
            .arg("run")
            .arg(scene("scene1_single_joint"))
            .args([
                "--engine",
                "mujoco",
                "--repeats",
                "3",
                "--set",
                "mujoco.timestep_s=0.00025",
                "--set",
                "mujoco.integrator=implicitfast",
                "--seed",
                "7",
            ])
            .args([
                "--perturb",
                "initial_offset_deg=2,sensor_noise_deg=0.2",
                "--perturb",
                "mass_scale=0.1",
            ])
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for d in [&a, &b] {
        let r = run(d);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    let da = a.join("scene1_single_joint/mujoco");
    let m = manifest(&da);
    assert_eq!(m["settings"]["config"]["deterministic"], false);
    assert_eq!(
        m["settings"]["config"]["engine_settings"]["timestep_s"],
        0.00025
    );
    let runs = m["runs"].as_array().unwrap();
    assert!(
        runs.iter()
            .all(|r| r["seed"].is_u64() && r["status"] == "ok"),
        "{runs:?}"
    );
    let sa = snapshot(&da);
    let files: Vec<&Vec<u8>> = sa.values().map(|(b, _)| b).collect();
    assert_ne!(files[0], files[1]);
    assert_ne!(files[1], files[2]);
    // The same seed gives the same runs.
    let sb = snapshot(&b.join("scene1_single_joint/mujoco"));
    for (name, (bytes, _)) in &sa {
        assert_eq!(
            &sb[name].0, bytes,
            "{name} differs between two batches with the same seed"
        );
    }
}

#[test]
fn engines_lists_mujoco_with_its_version() {
    let out = Command::new(exe()).arg("engines").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("mujoco ") && l.contains("MuJoCo 3.")),
        "{text}"
    );
}

/// At dt = 1e-3 the velocity servos of the light wrist links are unstable
/// with explicit Euler (kv dt / I > 2): refused before running unless
/// `--allow-unstable`; then MuJoCo flags it and resets, and the run is
/// stored as diverged, with when and why, rather than averaged in.
#[test]
fn unstable_timestep_is_recorded_as_diverged() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(exe())
        .arg("run")
        .arg(scene("scene1_single_joint"))
        .args([
            "--engine",
            "mujoco",
            "--set",
            "timestep_s=0.001",
            "--allow-unstable",
            "--out",
        ])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m = manifest(&tmp.path().join("scene1_single_joint/mujoco"));
    let run = &m["runs"][0];
    assert_eq!(run["status"], "diverged");
    let message = run["message"].as_str().unwrap();
    assert!(
        message.contains("diverged at t = 0.0") && message.contains("QACC"),
        "{message}"
    );
    assert!(run["extra"]["diverged_at_s"].as_f64().unwrap() < 0.05);
}
