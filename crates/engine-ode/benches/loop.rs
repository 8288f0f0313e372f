//! Benchmark: the shared controller loop against a bare ODE stepping loop
//! on the same model and the same motion, with the default settings
//! (dWorldStep, dt = 0.01 s), for the project's Mico2 and the official
//! Kinova URDF with its STL meshes. The bare loop sets the recorded
//! commands and does what a hand-written ODE program does each step
//! (`dSpaceCollide`, `dWorldStep`, `dJointGroupEmpty`). Timing and table:
//! `realitygap_core::testing::bench` (thread CPU time, best of `REPEATS`,
//! default 15; `SCENES` selects scenes).
//!
//!     cargo bench -p realitygap-engine-ode --bench loop
//!     REPEATS=9 SCENES=scene3_cube_push cargo bench -p realitygap-engine-ode --bench loop

use realitygap_core::engine::{EngineSettings, ModelVariation, Simulation};
use realitygap_core::testing::bench;
use realitygap_engine_ode::OdeSimulation;

fn main() {
    realitygap_engine_ode::install_message_handler();
    bench::run(
        &format!(
            "ODE {} (world_step, dt = 0.01 s)",
            realitygap_engine_ode::ode_version()
        ),
        15,
        bench::cases(),
        |scene, robot| {
            OdeSimulation::load(
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
