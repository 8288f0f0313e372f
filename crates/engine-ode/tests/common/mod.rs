//! Shared helpers of the ODE engine's integration tests.
#![allow(dead_code, unused_imports)]

pub use realitygap_core::testing::{
    cube, final_angles_deg, mico2, official_robot, paper_data, scene, with_official_robot,
    workspace, wrist,
};

use realitygap_core::controller::{simulate, RunOptions, RunOutcome};
use realitygap_core::engine::{EngineSettings, SettingValue};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_ode::OdeEngine;
use std::path::{Path, PathBuf};

/// Settings from `key=value` pairs.
pub fn settings(pairs: &[&str]) -> EngineSettings {
    pairs
        .iter()
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap();
            (k.to_string(), SettingValue::parse(v))
        })
        .collect()
}

/// Runs a scene through ODE with `pairs` as settings.
pub fn run_ode(scene: &Scene, robot: &RobotModel, pairs: &[&str]) -> RunOutcome {
    scene.validate(robot).unwrap();
    simulate(
        &OdeEngine,
        scene,
        robot,
        &settings(pairs),
        &RunOptions::default(),
    )
    .unwrap()
}
