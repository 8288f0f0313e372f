//! Benchmark: the shared controller loop against a bare DART stepping loop
//! (`World::step` in the shim, the recorded velocity targets set as the
//! servo's drive once per control period: with the law below the force
//! limit the implicit damper's drive does not change within the period)
//! on the same model and motion, for the project's Mico2 and the official
//! Kinova URDF with its STL meshes. Timing and table:
//! `realitygap_core::testing::bench` (thread CPU time, best of `REPEATS`,
//! default 5; `SCENES` selects scenes).
//!
//!     cargo bench -p realitygap-engine-dart --bench loop
//!     REPEATS=5 SCENES=scene1_single_joint cargo bench -p realitygap-engine-dart --bench loop

use realitygap_core::engine::{EngineSettings, ModelVariation, Simulation};
use realitygap_core::testing::bench;
use realitygap_engine_dart::DartSimulation;

fn main() {
    bench::run(
        "DART (default settings: ODE collision detector, Dantzig, 1 ms)",
        5,
        bench::cases(),
        |scene, robot| {
            DartSimulation::load(
                scene,
                robot,
                &EngineSettings::new(),
                &ModelVariation::default(),
            )
            .expect("the model loads")
        },
        |sim, commands, per_period| {
            for c in commands {
                sim.set_joint_velocity_targets(c);
                sim.step_raw(per_period);
            }
        },
    );
}
