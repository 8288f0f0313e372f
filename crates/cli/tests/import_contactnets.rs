//! `realitygap import contactnets` end to end: the three real tosses
//! committed with `realitygap-contactnets` (BSD 3-Clause, the independent
//! writer's output) into a results directory, and a damaged toss refused
//! with its file and byte named and nothing written.

use realitygap_data::RunStore;
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

/// The committed tosses (`tosses/`, with `experiment.json` beside it).
fn tosses() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../contactnets/tests/data/tosses")
}

#[test]
fn imports_the_tosses_as_real_runs_of_the_cube() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("real");
    let o = realitygap(&[
        "import",
        "contactnets",
        tosses().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = text(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", text(&o.stderr));
    assert!(
        stdout.contains("experiment.json: dt 0.006757 s (148 Hz), g 187.21 half-widths/s², so one half-width is 0.0524 m and the cube's edge 0.1048 m"),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "imported 3 tosses (80-367 samples, 0.53-2.47 s) as real runs of the cube into"
        ),
        "{stdout}"
    );
    let store = RunStore::open(&out).unwrap();
    let ids: Vec<&str> = store.runs().iter().map(|r| r.id.as_str()).collect();
    assert_eq!(ids, ["185", "229", "563"]);
    let run = store.read_run("563").unwrap();
    assert_eq!((run.len(), run.bodies[0].role.as_str()), (367, "cube"));
    assert_eq!(
        store.read_run_velocities("563").unwrap()[0].twists.len(),
        367
    );
}

#[test]
fn a_damaged_toss_is_named_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tosses");
    std::fs::create_dir(&dir).unwrap();
    std::fs::copy(tosses().join("185.pt"), dir.join("185.pt")).unwrap();
    let good = std::fs::read(tosses().join("229.pt")).unwrap();
    std::fs::write(dir.join("229.pt"), &good[..good.len() - 100]).unwrap();
    let out = tmp.path().join("real");
    let o = realitygap(&[
        "import",
        "contactnets",
        dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let stderr = text(&o.stderr);
    assert!(
        stderr.contains("229.pt: byte 336 (storage): the file is truncated: the storage's 1520 float64 values need 12160 bytes"),
        "{stderr}"
    );
    assert!(!out.exists());
}
