//! Benchmark of `realitygap tune`: per engine, a tune of the study's three
//! scenes on real runs 1-15 (held out 16-20) with the engine's default
//! space, and the figures the issue asks for: evaluations per second, the
//! evaluations and the wall time until the best objective was within 5 %
//! of the final one, and the cost of an evaluation against the raw
//! simulation of its three scenes (`realitygap run`, one job, the same
//! settings).
//!
//!     cargo bench -p realitygap --bench tune
//!     BUDGET=120 ENGINES=mujoco,ode cargo bench -p realitygap --bench tune

use realitygap_core::params::PhysicalParams;
use realitygap_tune::space::Space;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn realitygap(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .expect("realitygap starts");
    assert!(
        out.status.success(),
        "realitygap {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Seconds of one `realitygap run` of the three scenes at the space's
/// settings, one job: the simulation an evaluation cannot avoid.
fn raw_seconds(engine: &str, dir: &Path) -> f64 {
    let space = Space::from_file(&root().join(format!("assets/tuning/{engine}.toml"))).unwrap();
    let mut p = PhysicalParams::none();
    if let Some(s) = space.settings.get(engine) {
        p.engine_settings.insert(engine.to_string(), s.clone());
    }
    let params = dir.join("settings.toml");
    std::fs::write(&params, p.to_toml_string()).unwrap();
    let scenes: Vec<String> = [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ]
    .iter()
    .map(|s| {
        root()
            .join(format!("assets/scenes/{s}.toml"))
            .display()
            .to_string()
    })
    .collect();
    let out = dir.join("raw");
    let mut args: Vec<&str> = vec!["run"];
    args.extend(scenes.iter().map(String::as_str));
    args.extend(["--engine", engine, "--jobs", "1", "--params"]);
    args.push(params.to_str().unwrap());
    args.push("--out");
    args.push(out.to_str().unwrap());
    let t = Instant::now();
    realitygap(&args);
    t.elapsed().as_secs_f64()
}

fn main() {
    let data = realitygap_core::testing::paper_data().expect("the study's recordings");
    let budget = std::env::var("BUDGET").unwrap_or_else(|_| "600".into());
    let engines =
        std::env::var("ENGINES").unwrap_or_else(|_| "mujoco,rapier,ode,bullet,physx".into());
    let study = root().join("assets/studies/collins2019.toml");
    println!(
        "tune benchmark: budget {budget} evaluations, runs 1-15 fitted, 16-20 held out, 2 jobs"
    );
    println!(
        "| engine | evaluations/s | core-seconds per evaluation | raw 3-scene run, s | evaluation / raw | evaluations to 5 % | wall to 5 %, s | wall, s | held-out total untuned -> tuned (m) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---|");
    for engine in engines.split(',') {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("tune");
        let t = Instant::now();
        realitygap(&[
            "tune",
            study.to_str().unwrap(),
            "--data",
            data.to_str().unwrap(),
            "--engine",
            engine,
            "--runs",
            "1-15",
            "--holdout",
            "16-20",
            "--budget",
            &budget,
            "--jobs",
            "2",
            "--out",
            out.to_str().unwrap(),
        ]);
        let wall = t.elapsed().as_secs_f64();
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        let rate = s["evaluations_per_s"].as_f64().expect("a fresh tune");
        let to5 = s["evaluations_to_5pct"].as_u64();
        let raw = raw_seconds(engine, tmp.path());
        let per_eval = 2.0 / rate;
        let total = |k: &str| s["holdout"][k]["value_m"].as_f64().unwrap_or(f64::NAN);
        println!(
            "| {engine} | {rate:.2} | {per_eval:.3} | {raw:.3} | {:.2} | {} | {} | {wall:.1} | {:.3} -> {:.3} |",
            per_eval / raw,
            to5.map_or("n/a".into(), |n| n.to_string()),
            to5.map_or("n/a".into(), |n| format!("{:.1}", n as f64 / rate)),
            total("total_untuned"),
            total("total_tuned"),
        );
    }
}
