//! Benchmark: the shared controller loop against a bare ODE stepping loop on
//! the same model and the same motion, and the real-time factor per scene.
//!
//! For each scene and model (the project's Mico2, and the official Kinova
//! URDF with its STL meshes when the paper data is present), with the
//! default settings (dWorldStep, dt = 0.01 s): the scene is run once through
//! `controller::run_scene` (reading the state, computing the commands,
//! recording the trajectory, the engine's per-step divergence check and
//! angle tracking), and once as a bare loop that only sets the recorded
//! commands and does what a hand-written ODE program does each step
//! (`dSpaceCollide`, `dWorldStep`, `dJointGroupEmpty`) the same number of
//! times. Times are the thread's CPU time (Linux; wall time elsewhere), so
//! other processes on a shared machine disturb them less; the best of
//! `REPEATS` (default 15) alternating rounds is kept. Prints steps per
//! second, the loop's overhead and the real-time factor (simulated seconds
//! per second of the controller loop).
//!
//!     cargo bench -p realitygap-engine-ode --bench loop
//!     REPEATS=9 SCENES=scene3_cube_push cargo bench -p realitygap-engine-ode --bench loop

use realitygap_core::controller::{run_scene, RunOptions, RunStatus};
use realitygap_core::engine::{EngineSettings, ModelVariation, Simulation};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_ode::OdeSimulation;
use std::path::{Path, PathBuf};

/// A stopwatch of this thread's CPU time (Linux), else of wall time.
struct Stopwatch {
    start: f64,
}

#[cfg(target_os = "linux")]
fn now_s() -> f64 {
    #[repr(C)]
    struct Timespec {
        tv_sec: i64,
        tv_nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut ts = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a plain system call writing into `ts`.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime");
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

#[cfg(not(target_os = "linux"))]
fn now_s() -> f64 {
    use std::sync::OnceLock;
    static ORIGIN: OnceLock<std::time::Instant> = OnceLock::new();
    ORIGIN
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
}

impl Stopwatch {
    fn start() -> Self {
        Stopwatch { start: now_s() }
    }
    fn elapsed_s(&self) -> f64 {
        now_s() - self.start
    }
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Seconds of the controller loop and of the bare loop (best of
/// `repeats`), and the engine steps taken.
fn measure(scene: &Scene, robot: &RobotModel, repeats: usize) -> (f64, f64, u64) {
    let settings = EngineSettings::new();
    let load = || {
        OdeSimulation::load(scene, robot, &settings, &ModelVariation::default())
            .expect("the model loads")
    };
    let mut best_loop = f64::INFINITY;
    let mut best_raw = f64::INFINITY;
    let mut steps = 0;
    for _ in 0..repeats {
        let mut sim = load();
        let watch = Stopwatch::start();
        let out = run_scene(&mut sim, scene, &RunOptions::default()).expect("the scene runs");
        best_loop = best_loop.min(watch.elapsed_s());
        assert_eq!(out.status, RunStatus::Completed, "{}", scene.name);
        steps = out.engine_steps;
        let commands = out
            .trajectory
            .joint_velocity_commands_rad_s
            .expect("recorded");
        let per_period = steps / commands.len() as u64;

        let mut sim = load();
        let watch = Stopwatch::start();
        for c in &commands {
            sim.set_joint_velocity_targets(c);
            sim.step_raw(per_period);
        }
        best_raw = best_raw.min(watch.elapsed_s());
    }
    (best_loop, best_raw, steps)
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is understood.
    realitygap_engine_ode::install_message_handler();
    let repeats: usize = std::env::var("REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(15);
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
        "ODE {} with the default settings (world_step, dt = 0.01 s); thread CPU time, best of {repeats}",
        realitygap_engine_ode::ode_version()
    );
    println!(
        "{:<22} {:<16} {:>12} {:>12} {:>9} {:>11}",
        "scene", "model", "loop steps/s", "raw steps/s", "overhead", "real time x"
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
            let (t_loop, t_raw, steps) = measure(&scene, robot, repeats);
            let overhead = (t_loop - t_raw) / t_raw;
            worst = worst.max(overhead);
            println!(
                "{:<22} {:<16} {:>12.0} {:>12.0} {:>8.2}% {:>11.0}",
                name,
                label,
                steps as f64 / t_loop,
                steps as f64 / t_raw,
                overhead * 100.0,
                scene.duration_s / t_loop
            );
        }
    }
    println!(
        "largest overhead of the controller loop: {:.2}% (target: at most 5%)",
        worst * 100.0
    );
}
