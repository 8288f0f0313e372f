//! Benchmark: the shared controller loop against a bare PhysX stepping loop
//! (`PxScene::simulate` and `fetchResults` after setting the recorded
//! commands on the joint drives) on the same model and the same motion,
//! for the project's Mico2 and the official Kinova URDF with its STL
//! meshes. Timing and table: `realitygap_core::testing::bench` (thread CPU
//! time, best of `REPEATS`, default 5; `SCENES` selects scenes).
//!
//!     cargo bench -p realitygap-engine-physx --bench loop
//!     REPEATS=5 SCENES=scene1_single_joint cargo bench -p realitygap-engine-physx --bench loop

use realitygap_core::engine::{EngineSettings, ModelVariation, Simulation};
use realitygap_core::testing::bench;
use realitygap_engine_physx::PhysxSimulation;

fn main() {
    bench::run(
        "PhysX (default settings)",
        5,
        bench::cases(),
        |scene, robot| {
            PhysxSimulation::load(
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
