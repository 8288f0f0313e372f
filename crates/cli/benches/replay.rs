//! Replay overhead: `realitygap replay`'s loop (the recorded position
//! commands through each engine's own PD mechanism, set when they change;
//! the state read at the recording's 200 Hz sample times) against the raw
//! engine loop on the same simulation (the same number of `step` calls
//! under one constant position command, the same mechanism), per compiled
//! engine, on the first episode of the independent writer's iiwa
//! recordings (10 s at 1 ms: 10 000 steps). Thread CPU time, best of
//! `REPEATS` (default 3). Also the time to load the model (what every
//! replay of `tune --recordings` pays before its first step) and its ratio
//! to the replay.
//!
//!     cargo bench -p realitygap --bench replay

use realitygap_core::controller::{load_prepared, prepare, RunOptions};
use realitygap_core::replay::replay;
use realitygap_core::testing::{bench::thread_cpu_s, iiwa_urdf, joint_recording_fixtures};
use realitygap_core::PhysicalParams;
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use realitygap_recordings::{end_effector, store, StoreTarget};
use realitygap_study::replay::{plan_for, prepare_replay, ReplayRequest};

fn main() {
    let repeats: usize = std::env::var("REPEATS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(3);
    let tmp = tempfile::tempdir().unwrap();
    let urdf = iiwa_urdf();
    let robot = realitygap_core::RobotModel::from_urdf_file(
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
    let link = end_effector(&robot, None).unwrap();
    store(
        &recs,
        &StoreTarget {
            out: &real,
            source: "real",
            urdf: &urdf,
            robot: &robot,
            link,
            joints: &Default::default(),
        },
    )
    .unwrap();
    let params = PhysicalParams::none();
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
    println!(
        "{:<8} {:>8} {:>14} {:>14} {:>9} {:>9} {:>16}",
        "engine", "steps", "replay steps/s", "raw steps/s", "overhead", "load, s", "load / replay"
    );
    for engine in realitygap::compiled_engines() {
        let (scene, robot) =
            prepare(engine.as_ref(), &prepared.scene, &prepared.robot, &params).unwrap();
        let settings = scene
            .engine_settings
            .get(engine.name())
            .cloned()
            .unwrap_or_default();
        let plan = plan_for(episode, &scene, &params).unwrap();
        let load = || {
            load_prepared(
                engine.as_ref(),
                &scene,
                &robot,
                &settings,
                &params,
                &RunOptions::default(),
            )
            .unwrap()
        };
        let (mut best_replay, mut best_raw, mut steps) = (f64::INFINITY, f64::INFINITY, 0);
        let mut best_load = f64::INFINITY;
        for _ in 0..repeats {
            let t0 = thread_cpu_s();
            let mut sim = load();
            best_load = best_load.min(thread_cpu_s() - t0);
            let t0 = thread_cpu_s();
            let outcome = replay(sim.as_mut(), &plan).unwrap();
            best_replay = best_replay.min(thread_cpu_s() - t0);
            steps = outcome.engine_steps;
            let mut sim = load();
            let hold: Vec<_> = plan
                .initial_angles_rad
                .iter()
                .map(|&q| realitygap_core::engine::ServoCommand::position(q))
                .collect();
            // From the recording's first angles, as the replay starts.
            sim.set_joint_angles_rad(&plan.initial_angles_rad).unwrap();
            let t0 = thread_cpu_s();
            sim.set_joint_commands(&hold).unwrap();
            for _ in 0..steps {
                sim.step().unwrap();
            }
            best_raw = best_raw.min(thread_cpu_s() - t0);
        }
        let (r, w) = (steps as f64 / best_replay, steps as f64 / best_raw);
        println!(
            "{:<8} {steps:>8} {r:>14.0} {w:>14.0} {:>8.1}% {best_load:>9.4} {:>16.2}",
            engine.name(),
            100.0 * (w / r - 1.0),
            best_load / best_replay
        );
    }
}
