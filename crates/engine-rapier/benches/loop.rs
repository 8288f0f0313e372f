//! Benchmark: the shared controller loop against a bare Rapier stepping loop
//! on the same model and the same motion, and the real-time factor of each
//! scene.
//!
//! For each model (the project's Mico2, and the official Kinova URDF with
//! its STL meshes when the paper data is present) and scene: the scene is
//! run once through `controller::run_scene` (reading the state, computing
//! the commands, recording the trajectory, checking for divergence and
//! Rapier's quarantine after every step), and once as a bare loop that only
//! sets the recorded commands on the joint motors and calls Rapier's
//! `PhysicsWorld::step` the same number of times. Times are the thread's
//! CPU time (so that other processes on a shared machine disturb them
//! little), the best of `REPEATS` (default 5) alternating rounds. Prints
//! steps per second, the loop's overhead, the real-time factor (simulated
//! time over CPU time of the controller loop) and the time to build the
//! model.
//!
//!     cargo bench -p realitygap-engine-rapier --bench loop
//!     REPEATS=5 SCENES=scene1_single_joint cargo bench -p realitygap-engine-rapier --bench loop

use realitygap_core::controller::{run_scene, RunOptions};
use realitygap_core::engine::{EngineSettings, ModelVariation, Simulation};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_rapier::RapierSimulation;
use std::path::{Path, PathBuf};

/// CPU time used by this thread so far, s.
fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec it is given.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

struct Measure {
    loop_s: f64,
    raw_s: f64,
    load_s: f64,
    steps: u64,
}

fn measure(scene: &Scene, robot: &RobotModel, repeats: usize) -> Measure {
    let settings = EngineSettings::new();
    let mut load_s = f64::INFINITY;
    let mut load = || {
        let start = thread_cpu_s();
        let sim = RapierSimulation::load(scene, robot, &settings, &ModelVariation::default())
            .expect("the model loads");
        load_s = load_s.min(thread_cpu_s() - start);
        sim
    };
    let mut m = Measure {
        loop_s: f64::INFINITY,
        raw_s: f64::INFINITY,
        load_s: 0.0,
        steps: 0,
    };
    for _ in 0..repeats {
        let mut sim = load();
        let start = thread_cpu_s();
        let out = run_scene(&mut sim, scene, &RunOptions::default()).expect("the scene runs");
        m.loop_s = m.loop_s.min(thread_cpu_s() - start);
        m.steps = out.engine_steps;
        let commands = out
            .trajectory
            .joint_velocity_commands_rad_s
            .expect("recorded");
        let per_period = m.steps / commands.len() as u64;

        let mut sim = load();
        let start = thread_cpu_s();
        for c in &commands {
            sim.set_joint_velocity_targets(c);
            sim.step_raw(per_period);
        }
        m.raw_s = m.raw_s.min(thread_cpu_s() - start);
    }
    m.load_s = load_s;
    m
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is understood.
    let repeats: usize = std::env::var("REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5)
        .max(1);
    let scene_names: Vec<String> = std::env::var("SCENES")
        .map(|s| s.split(',').map(str::to_string).collect())
        .unwrap_or_else(|_| {
            vec![
                "scene1_single_joint".into(),
                "scene2_two_joints".into(),
                "scene3_cube_push".into(),
            ]
        });
    let paper = workspace().join("../shared/paper-data");
    let mico2 = RobotModel::from_urdf_file(
        &workspace().join("assets/robots/mico2/mico2.urdf"),
        &PackageResolver::new(),
    )
    .expect("the Mico2 URDF loads");
    let official = paper.join("kinova_description").is_dir().then(|| {
        let mut r = PackageResolver::new();
        r.insert("kinova_description", paper.join("kinova_description"));
        RobotModel::from_urdf_file(&paper.join("kinova_description/urdf/m1n6s300.urdf"), &r)
            .expect("the official URDF loads")
    });
    if official.is_none() {
        println!(
            "(paper data not found at {}: the official URDF is left out)",
            paper.display()
        );
    }
    println!(
        "{:<20} {:<16} {:>12} {:>12} {:>9} {:>11} {:>8}",
        "scene", "model", "loop steps/s", "raw steps/s", "overhead", "real-time x", "load ms"
    );
    let mut worst: f64 = f64::NEG_INFINITY;
    for name in &scene_names {
        let scene = Scene::from_file(
            &workspace()
                .join("assets/scenes")
                .join(format!("{name}.toml")),
        )
        .expect("the scene loads");
        let mut cases: Vec<(&str, Scene, &RobotModel)> = vec![("mico2", scene.clone(), &mico2)];
        if let Some(official) = &official {
            let mut s = scene.clone();
            s.set_robot_urdf(paper.join("kinova_description/urdf/m1n6s300.urdf"));
            cases.push(("official (STL)", s, official));
        }
        for (label, scene, robot) in cases {
            scene.validate(robot).expect("the scene fits the robot");
            let m = measure(&scene, robot, repeats);
            let overhead = (m.loop_s - m.raw_s) / m.raw_s;
            worst = worst.max(overhead);
            println!(
                "{:<20} {:<16} {:>12.0} {:>12.0} {:>8.2}% {:>11.1} {:>8.1}",
                name,
                label,
                m.steps as f64 / m.loop_s,
                m.steps as f64 / m.raw_s,
                overhead * 100.0,
                scene.duration_s / m.loop_s,
                m.load_s * 1e3
            );
        }
    }
    println!(
        "largest overhead of the controller loop: {:.2}% (target: at most 5%)",
        worst * 100.0
    );
}
