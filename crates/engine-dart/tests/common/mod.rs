//! Shared helpers of the DART engine's integration tests.
#![allow(dead_code, unused_imports)]

pub use realitygap_core::testing::{
    cube, final_angles_deg, mico2, official_robot, official_scene, paper_data, scene,
    with_official_robot, workspace, wrist,
};

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::engine::{Engine, EngineSettings, SettingValue};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;

/// Settings from `key=value` pairs.
pub fn settings(pairs: &[&str]) -> EngineSettings {
    realitygap_core::testing::kit::settings(pairs)
}

/// Runs a scene through `engine` with the given settings; the run must
/// complete.
pub fn run_with_settings(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
) -> RunOutcome {
    scene.validate(robot).unwrap();
    let out = simulate(engine, scene, robot, settings, &RunOptions::default()).unwrap();
    assert_eq!(
        out.status,
        RunStatus::Completed,
        "{} in {}",
        scene.name,
        engine.name()
    );
    out
}

/// The MuJoCo run of a scene with the scene's MuJoCo settings, the
/// integrator `implicitfast` when `implicit`.
pub fn mujoco(scene: &Scene, robot: &RobotModel, implicit: bool) -> RunOutcome {
    let mut s = scene.settings_for("mujoco");
    if implicit {
        s.insert(
            "integrator".into(),
            SettingValue::Text("implicitfast".into()),
        );
    }
    run_with_settings(&realitygap_engine_mujoco::MujocoEngine, scene, robot, &s)
}

/// The largest and the final distance between two runs' wrists, m.
pub fn wrist_gaps(a: &RunOutcome, b: &RunOutcome) -> (f64, f64) {
    let (wa, wb) = (wrist(a), wrist(b));
    let max = wa
        .iter()
        .zip(&wb)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f64::max);
    (max, wa.last().unwrap().distance(*wb.last().unwrap()))
}

/// The KUKA iiwa of `scripts/setup` (from the pybullet wheel) for a scene
/// that names it; fails with the fix when it is missing.
pub fn iiwa(scene: &Scene) -> RobotModel {
    assert!(
        scene.robot.urdf.as_ref().is_some_and(|u| u.is_file()),
        "{} is missing: run scripts/setup (it extracts the KUKA iiwa from the pybullet wheel)",
        scene.robot.urdf_label()
    );
    scene.robot.model(&PackageResolver::new()).unwrap()
}
