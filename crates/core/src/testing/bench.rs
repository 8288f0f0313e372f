//! The one skeleton of the engines' loop benchmarks
//! (`cargo bench -p realitygap-engine-<name> --bench loop`): per scene and
//! robot model, the shared controller loop (`controller::run_scene`:
//! reading the state, computing the commands, recording the trajectory,
//! checking for divergence) against a bare engine loop that replays the
//! recorded commands and only steps, the same number of steps. Times are
//! the CPU time of the benchmark's thread (wall time where the platform has
//! no thread clock), so that other processes on a shared machine disturb
//! them little; each figure is the best of several alternating rounds.
//!
//! Environment: `REPEATS` (rounds; `--quick` means 1), `SCENES`
//! (comma-separated scene names; all three by default).

use crate::controller::{run_scene, RunOptions, RunStatus};
use crate::engine::Simulation;
use crate::robot::RobotModel;
use crate::scene::Scene;

/// CPU time used by the calling thread so far, s (on a platform without a
/// thread CPU clock: wall time since the first call).
pub fn thread_cpu_s() -> f64 {
    #[cfg(unix)]
    {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    }
    #[cfg(not(unix))]
    {
        use std::sync::OnceLock;
        static ORIGIN: OnceLock<std::time::Instant> = OnceLock::new();
        ORIGIN
            .get_or_init(std::time::Instant::now)
            .elapsed()
            .as_secs_f64()
    }
}

/// The number of rounds: 1 with `--quick` on the command line, else
/// `REPEATS` from the environment, else `default` (at least 1).
pub fn repeats(default: usize) -> usize {
    if std::env::args().any(|a| a == "--quick") {
        return 1;
    }
    match std::env::var("REPEATS") {
        Err(_) => default.max(1),
        Ok(v) => match v.trim().parse::<usize>() {
            Ok(n) if n > 0 => n,
            _ => usage(&format!(
                "REPEATS={v:?} is not a positive whole number of rounds"
            )),
        },
    }
}

/// Stops the benchmark with a message naming the bad setting (a mistyped
/// environment variable is the user's input, not a defect to panic on).
fn usage(message: &str) -> ! {
    eprintln!("benchmark: {message}");
    std::process::exit(2)
}

/// One benchmark case: a scene with a robot model.
pub struct Case {
    /// The scene's name (`scene1_single_joint`, ...).
    pub scene_name: String,
    /// The model's label in the table (`mico2`, `official (STL)`, ...).
    pub model: String,
    /// The scene, with its robot set to the model.
    pub scene: Scene,
    /// The robot model.
    pub robot: RobotModel,
}

/// The cases of the benchmark: each scene of `SCENES` (default: all three)
/// with the project's Mico2 and with the official Kinova URDF and its STL
/// meshes, from the study's recordings ([`super::paper_data`]).
pub fn cases() -> Vec<Case> {
    let names: Vec<String> = std::env::var("SCENES")
        .map(|s| s.split(',').map(str::to_string).collect())
        .unwrap_or_else(|_| {
            [
                "scene1_single_joint",
                "scene2_two_joints",
                "scene3_cube_push",
            ]
            .map(String::from)
            .to_vec()
        });
    let folder = super::workspace().join("assets/scenes");
    let known = || {
        let mut names: Vec<String> = std::fs::read_dir(&folder)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| {
                let n = e.file_name().to_string_lossy().into_owned();
                n.strip_suffix(".toml").map(str::to_string)
            })
            .collect();
        names.sort();
        names.join(", ")
    };
    for name in &names {
        if !folder.join(format!("{name}.toml")).is_file() {
            usage(&format!(
                "SCENES names '{name}', which is not a scene of {} (known: {})",
                folder.display(),
                known()
            ));
        }
    }
    let paper = super::paper_data();
    let official = paper.as_deref().map(super::official_robot);
    let mut cases = Vec::new();
    for name in names {
        cases.push(Case {
            scene_name: name.clone(),
            model: "mico2".into(),
            scene: super::scene(&name),
            robot: super::mico2(),
        });
        if let (Some(paper), Some(robot)) = (&paper, &official) {
            cases.push(Case {
                scene_name: name.clone(),
                model: "official (STL)".into(),
                scene: super::official_scene(&name, paper),
                robot: robot.clone(),
            });
        }
    }
    cases
}

/// The figures of one case, best of the rounds.
pub struct Figures {
    /// Engine steps of one run of the scene.
    pub steps: u64,
    /// CPU time of the controller loop, s.
    pub loop_s: f64,
    /// CPU time of the bare loop, s.
    pub raw_s: f64,
    /// CPU time to build the engine's model, s.
    pub load_s: f64,
    /// Simulated time of one run, s.
    pub duration_s: f64,
}

impl Figures {
    /// The controller loop's overhead over the bare loop (0.05 = 5 %).
    pub fn overhead(&self) -> f64 {
        (self.loop_s - self.raw_s) / self.raw_s
    }
}

/// Measures `case`: `load` builds a fresh simulation, `raw` replays the
/// recorded velocity commands (rad/s, one per control period) on it, each
/// for `steps_per_period` engine steps, without reading the state back.
pub fn measure<S: Simulation>(
    case: &Case,
    repeats: usize,
    mut load: impl FnMut(&Scene, &RobotModel) -> S,
    mut raw: impl FnMut(&mut S, &[Vec<f64>], u64),
) -> Figures {
    case.scene
        .validate(&case.robot)
        .expect("the scene fits the robot");
    let mut f = Figures {
        steps: 0,
        loop_s: f64::INFINITY,
        raw_s: f64::INFINITY,
        load_s: f64::INFINITY,
        duration_s: case.scene.duration_s,
    };
    let mut timed_load = || {
        let start = thread_cpu_s();
        let sim = load(&case.scene, &case.robot);
        (sim, thread_cpu_s() - start)
    };
    for _ in 0..repeats {
        let (mut sim, load_s) = timed_load();
        f.load_s = f.load_s.min(load_s);
        let start = thread_cpu_s();
        let out = run_scene(&mut sim, &case.scene, &RunOptions::default()).expect("the scene runs");
        f.loop_s = f.loop_s.min(thread_cpu_s() - start);
        assert_eq!(out.status, RunStatus::Completed, "{}", case.scene_name);
        f.steps = out.engine_steps;
        let commands = out
            .trajectory
            .joint_velocity_commands_rad_s
            .expect("recorded");
        let per_period = f.steps / commands.len() as u64;
        let (mut sim, _) = timed_load();
        let start = thread_cpu_s();
        raw(&mut sim, &commands, per_period);
        f.raw_s = f.raw_s.min(thread_cpu_s() - start);
    }
    f
}

/// Measures every case (usually [`cases`]) and prints the table (the same
/// in every engine's benchmark): `engine` names the engine and its settings.
pub fn run<S: Simulation>(
    engine: &str,
    default_repeats: usize,
    cases: Vec<Case>,
    mut load: impl FnMut(&Scene, &RobotModel) -> S,
    mut raw: impl FnMut(&mut S, &[Vec<f64>], u64),
) {
    let repeats = repeats(default_repeats);
    println!("{engine}: controller loop vs bare loop; thread CPU time, best of {repeats}");
    println!(
        "{:<20} {:<16} {:>12} {:>12} {:>9} {:>11} {:>8}",
        "scene", "model", "loop steps/s", "raw steps/s", "overhead", "real-time x", "load ms"
    );
    let mut worst = f64::NEG_INFINITY;
    for case in cases {
        let f = measure(&case, repeats, &mut load, &mut raw);
        worst = worst.max(f.overhead());
        println!(
            "{:<20} {:<16} {:>12.0} {:>12.0} {:>8.2}% {:>11.1} {:>8.1}",
            case.scene_name,
            case.model,
            f.steps as f64 / f.loop_s,
            f.steps as f64 / f.raw_s,
            f.overhead() * 100.0,
            f.duration_s / f.loop_s,
            f.load_s * 1e3
        );
    }
    println!(
        "largest overhead of the controller loop: {:.2}% (target: at most 5%)",
        worst * 100.0
    );
}
