//! Benchmark: the shared controller loop driving Bullet against a raw
//! Bullet stepping loop on the same model, per scene and robot model.
//!
//! The raw loop replays the velocity commands the controller sent (so
//! Bullet computes the same motion and contacts) and only steps: no state
//! is read back. The difference is the cost of the engine interface (state
//! reads, the controller) on top of Bullet. Each figure is the best of
//! several repetitions, to resist the noise of a shared machine.
//!
//! Run: `cargo bench -p realitygap-engine-bullet --bench loop`
//! (`-- --quick` for one repetition; paper data in ../shared/paper-data
//! adds the official mesh model).

use realitygap_core::controller::{run_scene, RunOptions, RunStatus};
use realitygap_core::engine::{ModelVariation, Simulation};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_bullet::BulletSimulation;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

struct Figures {
    loop_steps_per_s: f64,
    raw_steps_per_s: f64,
    real_time_factor: f64,
}

fn measure(scene: &Scene, robot: &RobotModel, repeats: usize) -> Figures {
    scene.validate(robot).unwrap();
    let settings = scene.settings_for("bullet");
    let load =
        || BulletSimulation::load(scene, robot, &settings, &ModelVariation::default()).unwrap();
    let mut best_loop = f64::INFINITY;
    let mut best_raw = f64::INFINITY;
    let mut steps = 0;
    let mut commands = Vec::new();
    for _ in 0..repeats {
        let mut sim = load();
        let out = run_scene(&mut sim, scene, &RunOptions::default()).unwrap();
        assert_eq!(out.status, RunStatus::Completed);
        best_loop = best_loop.min(out.wall_time_s);
        steps = out.engine_steps;
        commands = out
            .trajectory
            .joint_velocity_commands_rad_s
            .clone()
            .unwrap();
    }
    let per_period = steps / commands.len() as u64;
    for _ in 0..repeats {
        let mut sim = load();
        let start = Instant::now();
        for c in &commands {
            sim.set_joint_velocity_targets(c);
            sim.step_raw(per_period).unwrap();
        }
        best_raw = best_raw.min(start.elapsed().as_secs_f64());
    }
    Figures {
        loop_steps_per_s: steps as f64 / best_loop,
        raw_steps_per_s: steps as f64 / best_raw,
        real_time_factor: scene.duration_s / best_loop,
    }
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let repeats = if quick { 1 } else { 5 };
    let paper = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/paper-data");
    let mut robots = vec![(
        "mico2",
        None,
        RobotModel::from_urdf_file(
            &workspace().join("assets/robots/mico2/mico2.urdf"),
            &PackageResolver::new(),
        )
        .unwrap(),
    )];
    if paper.join("kinova_description").is_dir() {
        let mut resolver = PackageResolver::new();
        resolver.insert("kinova_description", paper.join("kinova_description"));
        let urdf = paper.join("kinova_description/urdf/m1n6s300.urdf");
        robots.push((
            "official",
            Some(urdf.clone()),
            RobotModel::from_urdf_file(&urdf, &resolver).unwrap(),
        ));
    } else {
        eprintln!(
            "paper data not found at {}: the official mesh model is left out",
            paper.display()
        );
    }
    println!("Bullet: controller loop vs raw stepping loop (best of {repeats}, timestep 0.01 s)");
    println!(
        "{:<22} {:<9} {:>12} {:>12} {:>9} {:>11}",
        "scene", "robot", "loop step/s", "raw step/s", "overhead", "real-time x"
    );
    let mut worst: f64 = 0.0;
    for name in [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ] {
        for (label, urdf, robot) in &robots {
            let mut scene = Scene::from_file(
                &workspace()
                    .join("assets/scenes")
                    .join(format!("{name}.toml")),
            )
            .unwrap();
            if let Some(u) = urdf {
                scene.set_robot_urdf(u.clone());
            }
            let f = measure(&scene, robot, repeats);
            let overhead = f.raw_steps_per_s / f.loop_steps_per_s - 1.0;
            worst = worst.max(overhead);
            println!(
                "{:<22} {:<9} {:>12.0} {:>12.0} {:>8.1}% {:>11.0}",
                name,
                label,
                f.loop_steps_per_s,
                f.raw_steps_per_s,
                overhead * 100.0,
                f.real_time_factor
            );
        }
    }
    println!(
        "largest overhead of the controller loop over raw stepping: {:.1}% (target <= 5%)",
        worst * 100.0
    );
}
