//! Deterministic repeats are simulated twice, proven byte-identical, and
//! the other repeats recorded as copies of the first; perturbed repeats
//! are each simulated.
#![cfg(feature = "ode")]

use realitygap_data::runstore::RunStore;
use std::path::Path;
use std::process::Command;

fn run(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn scene1() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/scenes/scene1_single_joint.toml")
        .display()
        .to_string()
}

#[test]
fn deterministic_repeats_beyond_two_are_copies_of_the_first() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("r");
    let out_s = out.to_str().unwrap();
    run(&[
        "run",
        &scene1(),
        "--engine",
        "ode",
        "--repeats",
        "5",
        "--out",
        out_s,
    ]);
    let store = RunStore::open(&out.join("scene1_single_joint/ode")).unwrap();
    assert_eq!(store.runs().len(), 5);
    for id in ["run000", "run001"] {
        let e = store.run(id).unwrap();
        assert!(e.extra.get("copy_of").is_none(), "{id} was simulated");
        assert!(e.extra.get("engine_steps").is_some());
    }
    let first = std::fs::read(out.join("scene1_single_joint/ode/runs/run000.csv")).unwrap();
    for id in ["run002", "run003", "run004"] {
        let e = store.run(id).unwrap();
        assert_eq!(e.extra["copy_of"], serde_json::json!("run000"), "{id}");
        let copy =
            std::fs::read(out.join(format!("scene1_single_joint/ode/runs/{id}.csv"))).unwrap();
        assert_eq!(copy, first, "{id} is not a byte copy");
    }
    // A rerun with more repeats copies again, and keeps what is there.
    run(&[
        "run",
        &scene1(),
        "--engine",
        "ode",
        "--repeats",
        "7",
        "--out",
        out_s,
    ]);
    let store = RunStore::open(&out.join("scene1_single_joint/ode")).unwrap();
    assert_eq!(store.runs().len(), 7);
    // Two new repeats are simulated and compared again: none is a copy.
    assert!(store.run("run005").unwrap().extra.get("copy_of").is_none());
    assert!(store.run("run006").unwrap().extra.get("copy_of").is_none());
}

#[test]
fn perturbed_repeats_are_each_simulated() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("p");
    run(&[
        "run",
        &scene1(),
        "--engine",
        "ode",
        "--repeats",
        "3",
        "--perturb",
        "sensor_noise_deg=0.1",
        "--out",
        out.to_str().unwrap(),
    ]);
    let store = RunStore::open(&out.join("scene1_single_joint/ode")).unwrap();
    for e in store.runs() {
        assert!(e.extra.get("copy_of").is_none(), "{} is a copy", e.id);
        assert!(e.seed.is_some());
    }
    let a = std::fs::read(out.join("scene1_single_joint/ode/runs/run000.csv")).unwrap();
    let b = std::fs::read(out.join("scene1_single_joint/ode/runs/run001.csv")).unwrap();
    assert_ne!(a, b);
}
