//! Benchmark: the shared controller loop against a bare `mj_step` loop on
//! the same model and the same motion, for the project's Mico2 built from
//! URDF and the study's own MJCF (with the official robot). The bare loop
//! only sets the recorded commands and calls `mj_step` the same number of
//! times. Timing and table: `realitygap_core::testing::bench` (thread CPU
//! time, best of `REPEATS`, default 3; `SCENES` selects scenes).
//!
//!     cargo bench -p realitygap-engine-mujoco --bench loop
//!     REPEATS=5 SCENES=scene1_single_joint cargo bench -p realitygap-engine-mujoco --bench loop

use realitygap_core::engine::ModelVariation;
use realitygap_core::testing::{bench, paper_data};
use realitygap_engine_mujoco::MujocoSimulation;

fn main() {
    realitygap_engine_mujoco::install_message_handler();
    let paper = paper_data();
    let cases = bench::cases()
        .into_iter()
        .map(|mut case| {
            if let (Some(paper), false) = (&paper, case.model == "mico2") {
                case.model = "study MJCF".into();
                case.scene.robot.mjcf = Some(paper.join("kinova_description/urdf/m1n6s300.xml"));
            }
            case
        })
        .collect();
    bench::run(
        &format!("MuJoCo {}", realitygap_engine_mujoco::mujoco_version()),
        3,
        cases,
        |scene, robot| {
            let settings = scene.settings_for("mujoco");
            MujocoSimulation::load(scene, robot, &settings, &ModelVariation::default())
                .expect("the model loads")
        },
        |sim, commands, per_period| {
            for c in commands {
                sim.set_controls(c);
                sim.step_raw(per_period);
            }
        },
    );
}
