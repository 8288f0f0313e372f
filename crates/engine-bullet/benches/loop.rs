//! Benchmark: the shared controller loop driving Bullet against a raw
//! Bullet stepping loop on the same model, per scene and robot model.
//!
//! The raw loop replays the velocity commands the controller sent (so
//! Bullet computes the same motion and contacts) and only steps: no state
//! is read back. The difference is the cost of the engine interface (state
//! reads, the controller) on top of Bullet. Timing and table:
//! `realitygap_core::testing::bench` (thread CPU time, best of `REPEATS`,
//! default 5; `--quick` for one round).
//!
//!     cargo bench -p realitygap-engine-bullet --bench loop

use realitygap_core::engine::{ModelVariation, Simulation};
use realitygap_core::testing::bench;
use realitygap_engine_bullet::BulletSimulation;

fn main() {
    bench::run(
        "Bullet (timestep 0.01 s)",
        5,
        bench::cases(),
        |scene, robot| {
            let settings = scene.settings_for("bullet");
            BulletSimulation::load(scene, robot, &settings, &ModelVariation::default())
                .expect("the model loads")
        },
        |sim, commands, per_period| {
            for c in commands {
                sim.set_joint_velocity_targets(c);
                sim.step_raw(per_period).expect("Bullet steps");
            }
        },
    );
}
