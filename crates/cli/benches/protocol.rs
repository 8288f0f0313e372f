//! The engine protocol's overhead: MuJoCo 3.17 linked into this process
//! against the same MuJoCo 3.17 out of process, through the Python SDK's
//! adapter (`realitygap_engine.adapters.mujoco` run by a Python that has
//! `mujoco==3.17.0`: `$REALITYGAP_BENCH_PYTHON`, else the test suite's
//! `~/.cache/realitygap/py-deps-venv`, else the fixtures' venv), on
//!
//! - scene 2 (the Mico2 raising two joints against gravity, 20 s at
//!   0.1 ms: 200 000 steps, one message per 0.05 s control period), and
//! - the replay of the first iiwa recording of the independent writer
//!   (10 s at 1 ms; the recorded commands set when they change, the state
//!   read at the recording's sample times).
//!
//! Wall time (the work is in another process), best of `REPEATS` (default
//! 3), with the load (model building, and for the adapter the Python
//! start) apart from the run; the ratio out of process / linked.
//!
//!     cargo bench -p realitygap --bench protocol [-- scene|iiwa]
//!
//! An argument keeps the cases whose name holds it (`iiwa`: the replay
//! alone, for a profiler).

use realitygap_core::controller::{load_prepared, prepare, run_scene, RunOptions};
use realitygap_core::engine::Engine;
use realitygap_core::replay::replay;
use realitygap_core::testing::{self, iiwa_urdf, joint_recording_fixtures};
use realitygap_core::PhysicalParams;
use realitygap_engine_remote::child::Launch;
use realitygap_engine_remote::registry;
use realitygap_engine_remote::RemoteEngine;
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use realitygap_recordings::{end_effector, store, StoreTarget};
use realitygap_study::replay::{plan_for, prepare_replay, ReplayRequest};
use std::path::PathBuf;
use std::time::Instant;

fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("REALITYGAP_BENCH_PYTHON") {
        return p.into();
    }
    let home = PathBuf::from(std::env::var_os("HOME").expect("HOME"));
    for venv in ["py-deps-venv", "fixtures-venv"] {
        let p = home.join(".cache/realitygap").join(venv).join("bin/python");
        if p.is_file() {
            return p;
        }
    }
    panic!("no Python with mujoco==3.17.0: run scripts/test-python once, or set REALITYGAP_BENCH_PYTHON");
}

/// Best wall times (load, run) of `f` over `repeats`.
fn best(repeats: usize, mut f: impl FnMut() -> (f64, f64)) -> (f64, f64) {
    (0..repeats).fold((f64::INFINITY, f64::INFINITY), |(l, r), _| {
        let (a, b) = f();
        (l.min(a), r.min(b))
    })
}

fn main() {
    let repeats = realitygap_core::testing::bench::repeats(3);
    let filters: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let wanted =
        |case: &str| filters.is_empty() || filters.iter().any(|f| case.contains(f.as_str()));
    let linked = realitygap_engine_mujoco::MujocoEngine;
    let remote = RemoteEngine::new(
        "mujoco",
        Launch {
            command: vec![
                python().display().to_string(),
                "-m".into(),
                "realitygap_engine.adapters.mujoco".into(),
            ],
            env: vec![
                (
                    "PYTHONPATH".into(),
                    registry::sdk_dir().unwrap().display().to_string(),
                ),
                ("REALITYGAP_ENGINE_NAME".into(), "mujoco".into()),
            ],
        },
    );
    println!(
        "linked: {}; out of process: {}",
        linked.version(),
        remote.version()
    );
    println!(
        "{:<26} {:>12} {:>12} {:>12} {:>12} {:>8}",
        "case", "linked load", "linked run", "remote load", "remote run", "ratio"
    );

    let cases = ["scene 2", "iiwa replay"];
    if !cases.iter().any(|c| wanted(c)) {
        eprintln!("no case matches {filters:?}: the cases are {cases:?}");
        std::process::exit(2);
    }
    if wanted(cases[0]) {
        scene_2(repeats, &linked, &remote);
    }
    if wanted(cases[1]) {
        iiwa_replay(repeats, &linked, &remote);
    }
}

/// Scene 2 at the scene's MuJoCo settings.
fn scene_2(repeats: usize, linked: &dyn Engine, remote: &dyn Engine) {
    let scene = testing::scene("scene2_two_joints");
    let robot = testing::mico2();
    let settings = scene.settings_for("mujoco");
    let params = PhysicalParams::none();
    let time_scene = |engine: &dyn Engine| {
        best(repeats, || {
            let t0 = Instant::now();
            let mut sim = load_prepared(
                engine,
                &scene,
                &robot,
                &settings,
                &params,
                &RunOptions::default(),
            )
            .unwrap();
            let load = t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            let out = run_scene(sim.as_mut(), &scene, &RunOptions::default()).unwrap();
            assert!(matches!(
                out.status,
                realitygap_core::controller::RunStatus::Completed
            ));
            (load, t0.elapsed().as_secs_f64())
        })
    };
    let (ll, lr) = time_scene(linked);
    let (rl, rr) = time_scene(remote);
    println!(
        "{:<26} {ll:>12.4} {lr:>12.4} {rl:>12.4} {rr:>12.4} {:>8.2}",
        "scene 2 (200 000 steps)",
        rr / lr
    );
}

/// The replay of the first iiwa recording of the independent writer.
fn iiwa_replay(repeats: usize, linked: &dyn Engine, remote: &dyn Engine) {
    let params = PhysicalParams::none();
    let tmp = tempfile::tempdir().unwrap();
    let urdf = iiwa_urdf();
    let iiwa = realitygap_core::RobotModel::from_urdf_file(
        &urdf,
        &realitygap_core::robot::PackageResolver::new(),
    )
    .unwrap();
    let opts = RosbagOptions {
        robot_joints: (1..=7).map(|j| format!("lbr_iiwa_joint_{j}")).collect(),
        ..RosbagOptions::default()
    };
    let recs = import_rosbag(&joint_recording_fixtures().join("mcap/episode_000"), &opts).unwrap();
    let real = tmp.path().join("real");
    let link = end_effector(&iiwa, None).unwrap();
    store(
        &recs,
        &StoreTarget {
            out: &real,
            source: "real",
            urdf: &urdf,
            robot: &iiwa,
            link,
            joints: &Default::default(),
        },
    )
    .unwrap();
    let prepared = prepare_replay(&ReplayRequest {
        real_dir: &real,
        urdf: None,
        packages: &[],
        params: &params,
        scene: None,
        out: &tmp.path().join("out"),
    })
    .unwrap();
    let episode = &prepared.episodes[0];
    let mut steps = 0;
    let mut time_replay = |engine: &dyn Engine| {
        let (scene, robot) = prepare(engine, &prepared.scene, &prepared.robot, &params).unwrap();
        let settings = scene.settings_for("mujoco");
        let plan = plan_for(episode, &scene, &params).unwrap();
        best(repeats, || {
            let t0 = Instant::now();
            let mut sim = load_prepared(
                engine,
                &scene,
                &robot,
                &settings,
                &params,
                &RunOptions::default(),
            )
            .unwrap();
            let load = t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            steps = replay(sim.as_mut(), &plan).unwrap().engine_steps;
            (load, t0.elapsed().as_secs_f64())
        })
    };
    let (ll, lr) = time_replay(linked);
    let (rl, rr) = time_replay(remote);
    println!(
        "{:<26} {ll:>12.4} {lr:>12.4} {rl:>12.4} {rr:>12.4} {:>8.2}",
        format!("iiwa replay ({steps} steps)"),
        rr / lr
    );
}
