//! Benchmark: the shared controller loop against a bare `mj_step` loop on
//! the same model and the same motion.
//!
//! For each model (the project's Mico2 built from URDF, and the study's own
//! MJCF when the paper data is present) and scene: the scene is run once
//! through `controller::run_scene` (reading the state, computing the
//! commands, recording the trajectory, checking for divergence), and once
//! as a bare loop that only sets the recorded commands and calls `mj_step`
//! the same number of times. The best of `REPEATS` (default 3) alternating
//! rounds is kept. Prints steps per second and the loop's overhead.
//!
//!     cargo bench -p realitygap-engine-mujoco --bench loop
//!     REPEATS=5 SCENES=scene1_single_joint cargo bench -p realitygap-engine-mujoco --bench loop

use realitygap_core::controller::{run_scene, RunOptions};
use realitygap_core::engine::ModelVariation;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_mujoco::MujocoSimulation;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Seconds for the controller loop and for the bare loop (best of `repeats`).
fn measure(scene: &Scene, robot: &RobotModel, repeats: usize) -> (f64, f64, u64) {
    let settings = scene.settings_for("mujoco");
    let load = || {
        MujocoSimulation::load(scene, robot, &settings, &ModelVariation::default())
            .expect("the model loads")
    };
    let mut best_loop = f64::INFINITY;
    let mut best_raw = f64::INFINITY;
    let mut steps = 0;
    for _ in 0..repeats {
        let mut sim = load();
        let start = Instant::now();
        let out = run_scene(&mut sim, scene, &RunOptions::default()).expect("the scene runs");
        best_loop = best_loop.min(start.elapsed().as_secs_f64());
        steps = out.engine_steps;
        let commands = out
            .trajectory
            .joint_velocity_commands_rad_s
            .expect("recorded");
        let per_period = steps / commands.len() as u64;

        let mut sim = load();
        let start = Instant::now();
        for c in &commands {
            sim.set_controls(c);
            sim.step_raw(per_period);
        }
        best_raw = best_raw.min(start.elapsed().as_secs_f64());
    }
    (best_loop, best_raw, steps)
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is understood.
    realitygap_engine_mujoco::install_message_handler();
    let repeats: usize = std::env::var("REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3);
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
            "(paper data not found at {}: the study's MJCF is left out)",
            paper.display()
        );
    }
    println!(
        "{:<22} {:<20} {:>12} {:>12} {:>9}",
        "scene", "model", "loop steps/s", "raw steps/s", "overhead"
    );
    let mut worst: f64 = 0.0;
    for name in &scene_names {
        let scene = Scene::from_file(
            &workspace()
                .join("assets/scenes")
                .join(format!("{name}.toml")),
        )
        .expect("the scene loads");
        let mut cases: Vec<(&str, Scene, &RobotModel)> =
            vec![("mico2 (URDF)", scene.clone(), &mico2)];
        if let Some(official) = &official {
            let mut study = scene.clone();
            study.robot.mjcf = Some(paper.join("kinova_description/urdf/m1n6s300.xml"));
            cases.push(("study MJCF", study, official));
        }
        for (label, scene, robot) in cases {
            scene.validate(robot).expect("the scene fits the robot");
            let (t_loop, t_raw, steps) = measure(&scene, robot, repeats);
            let overhead = (t_loop - t_raw) / t_raw;
            worst = worst.max(overhead);
            println!(
                "{:<22} {:<20} {:>12.0} {:>12.0} {:>8.2}%",
                name,
                label,
                steps as f64 / t_loop,
                steps as f64 / t_raw,
                overhead * 100.0
            );
        }
    }
    println!(
        "largest overhead of the controller loop: {:.2}% (target: at most 5%)",
        worst * 100.0
    );
}
