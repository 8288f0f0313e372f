//! Library side of the `realitygap` command: the engines compiled in, the
//! sequences of the long commands (`run`, `compare`, `replay`, `tune`,
//! `reproduce`) that the command and the Python package (`crates/python`)
//! share, and helpers for the tests and benchmarks. The work is done by the
//! library crates (`realitygap-study` for studies and their evaluation,
//! `realitygap-runner` for batches of runs); the binary (`main.rs`) is a
//! thin layer of argument parsing and printing over them.

#![forbid(unsafe_code)]

pub mod batch;
pub mod compare;
pub mod replay;
pub mod reproduce;
pub mod tune;
pub mod tune_tosses;
pub mod ui;

use realitygap_core::engine::Engine;
use realitygap_core::params::ParamKey;

/// Every engine compiled in (cargo features of this crate), in
/// `realitygap engines` order: the command's registry, and the tests' and
/// benchmarks' list of engines.
// The pushes depend on the features compiled in: no `vec![...]` can say that.
#[allow(clippy::vec_init_then_push)]
pub fn compiled_engines() -> Vec<Box<dyn Engine>> {
    #[allow(unused_mut)]
    let mut engines: Vec<Box<dyn Engine>> = Vec::new();
    #[cfg(feature = "mujoco")]
    engines.push(Box::new(realitygap_engine_mujoco::MujocoEngine));
    #[cfg(feature = "ode")]
    engines.push(Box::new(realitygap_engine_ode::OdeEngine));
    #[cfg(feature = "rapier")]
    engines.push(Box::new(realitygap_engine_rapier::RapierEngine));
    #[cfg(feature = "bullet")]
    engines.push(Box::new(realitygap_engine_bullet::BulletEngine));
    #[cfg(feature = "physx")]
    engines.push(Box::new(realitygap_engine_physx::PhysxEngine));
    #[cfg(feature = "dart")]
    engines.push(Box::new(realitygap_engine_dart::DartEngine));
    #[cfg(feature = "ideal")]
    engines.push(Box::new(realitygap_engine_ideal::IdealEngine));
    engines
}

/// Every engine this binary can run: the engines linked in
/// ([`compiled_engines`]), then the engines out of process that can start
/// (the installed built-in adapters and the user's own engines,
/// [`realitygap_engine_remote::registry::available`]). The command's
/// registry: `--engine`, `realitygap engines` and the defaults of
/// `reproduce` and `replay` take their engines from here.
pub fn engines() -> Vec<Box<dyn Engine>> {
    let mut all = compiled_engines();
    all.extend(
        realitygap_engine_remote::registry::available()
            .into_iter()
            .map(|e| Box::new(e) as Box<dyn Engine>),
    );
    all
}

/// The compiled-in engines that simulate physics: every one but the
/// physics-free model (`ideal`), which has no dynamics to hand over, no
/// contact and no forces (for the checks of physical effects).
pub fn physics_engines() -> Vec<Box<dyn Engine>> {
    compiled_engines()
        .into_iter()
        .filter(|e| e.name() != realitygap_core::engine::PHYSICS_FREE_ENGINE)
        .collect()
}

/// Prepares the engines' native libraries for this process (MuJoCo, ODE
/// and Bullet: route their fatal-error messages to standard error). Call
/// once, early (the child process of a run does, before its job).
pub fn install_native_handlers() {
    #[cfg(feature = "mujoco")]
    realitygap_engine_mujoco::install_message_handler();
    #[cfg(feature = "ode")]
    realitygap_engine_ode::install_message_handler();
    #[cfg(feature = "bullet")]
    realitygap_engine_bullet::install_message_handler();
}

/// The child's side of a run, `realitygap __run-one`: one job (JSON on
/// standard input) run with the engines compiled in, its result on
/// standard output.
pub fn run_one() -> anyhow::Result<()> {
    realitygap_runner::run_one(engines, install_native_handlers)
}

/// Every parameter key with what it becomes in `engine`: the engine's own
/// mapping, the controller's for the keys core applies, or "not supported
/// (an error)".
pub fn param_table(engine: &dyn Engine) -> Vec<(ParamKey, String)> {
    let support = engine.param_support();
    ParamKey::ALL
        .iter()
        .map(|&key| {
            let mapping = match (key.core_mapping(), support.iter().find(|s| s.key == key)) {
                (Some(core), _) => format!("core controller: {core}"),
                (None, Some(s)) => s.mapping.to_string(),
                (None, None) => "not supported (a file setting it is an error)".to_string(),
            };
            (key, mapping)
        })
        .collect()
}

/// The study's recordings (with `kinova_description`), for tests and
/// benchmarks: `realitygap_core::testing::paper_data`, which finds
/// `../shared/paper-data` or the built-in study data unpacked in the cache
/// and otherwise panics (in CI always), so that no test passes without them.
pub fn paper_data_for_tests() -> Option<std::path::PathBuf> {
    realitygap_core::testing::paper_data()
}

#[cfg(test)]
mod paper_tests {
    use super::*;
    use realitygap_analysis::compare::{AnalysisMode, CompareOptions};
    use realitygap_core::robot::{PackageResolver, RobotModel};
    use realitygap_core::{Pose, Quat, Vec3};
    use realitygap_study::{evaluate, Roots, Study};
    use std::path::PathBuf;

    fn study() -> Study {
        Study::from_file(
            &PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../assets/studies/collins2019.toml"),
        )
        .unwrap()
    }

    /// The goals in the study file are forward kinematics of the official
    /// URDF at each scene's final targets, base raised 0.055 m.
    #[test]
    fn study_goals_match_forward_kinematics() {
        let Some(data) = paper_data_for_tests() else {
            return;
        };
        let mut res = PackageResolver::new();
        res.insert("kinova_description", data.join("kinova_description"));
        let robot =
            RobotModel::from_urdf_file(&data.join("kinova_description/urdf/m1n6s300.urdf"), &res)
                .unwrap();
        let wrist = robot.link_by_name("m1n6s300_link_6").unwrap();
        let finals: [[f64; 6]; 3] = [
            [0.0, -100.0, 0.0, 0.0, 0.0, 0.0],
            [0.0; 6],
            [0.0, -67.0, 30.0, 90.0, 0.0, 0.0],
        ];
        for (scene, targets) in study().scenes.iter().zip(finals) {
            let mut q = vec![0.0; robot.joints.len()];
            for (j, deg) in targets.iter().enumerate() {
                q[robot
                    .joint_by_name(&format!("m1n6s300_joint_{}", j + 1))
                    .unwrap()] = deg.to_radians();
            }
            let base = Pose::new(Vec3::new(0.0, 0.0, 0.055), Quat::IDENTITY);
            let p = robot.link_pose(&base, &q, wrist).unwrap().position_m;
            let goal = Vec3::from_array(scene.goal_m.unwrap());
            assert!(
                p.distance(goal) < 1e-5,
                "{}: FK {p:?} vs study file {goal:?}",
                scene.name
            );
        }
    }

    #[test]
    fn study_mode_reproduces_the_table_shape_and_the_cube_fact() {
        let Some(data) = paper_data_for_tests() else {
            return;
        };
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        let opts = CompareOptions {
            mode: AnalysisMode::Study,
            ..Default::default()
        };
        let roots = Roots {
            data,
            results: root,
        };
        let reports = evaluate(&study(), &roots, &opts).unwrap();
        for r in &reports {
            assert_eq!(r.sources.len(), 7);
            for s in &r.sources {
                let e = s.accumulated_error_m.unwrap();
                if s.source == "V-Rep ODE" {
                    assert!(e > 1e15, "{}: ODE {e}", r.scene);
                } else {
                    assert!(
                        e.is_finite() && e > 0.0 && e < 1000.0,
                        "{} {}: {e}",
                        r.scene,
                        s.source
                    );
                }
                assert_eq!(s.runs_used, 20);
            }
        }
        if std::env::var_os("RG_PRINT").is_some() {
            println!(
                "{}",
                realitygap_analysis::table::render(
                    &reports,
                    realitygap_analysis::table::Format::Markdown
                )
            );
        }
        let cube = reports[2].reference.cube.as_ref().unwrap();
        let dx = cube.final_offset_from_nominal_m.unwrap()[0];
        assert!(
            (dx - 0.0975).abs() < 0.0005,
            "real cube final x - 0.5 = {dx}"
        );
    }

    #[test]
    fn default_mode_flags_the_broken_runs() {
        let Some(data) = paper_data_for_tests() else {
            return;
        };
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        let roots = Roots {
            data,
            results: root,
        };
        for r in evaluate(&study(), &roots, &CompareOptions::default()).unwrap() {
            if std::env::var_os("RG_PRINT").is_some() {
                println!(
                    "{}",
                    realitygap_analysis::table::render(
                        std::slice::from_ref(&r),
                        realitygap_analysis::table::Format::Markdown
                    )
                );
            }
            for src in &r.sources {
                let excluded: Vec<&str> = src
                    .runs_flagged
                    .iter()
                    .filter(|f| f.excluded)
                    .map(|f| f.run.as_str())
                    .collect();
                match (src.source.as_str(), r.scene.as_str()) {
                    ("V-Rep ODE", _) => assert_eq!(
                        (excluded.len(), src.runs_used, src.accumulated_error_m),
                        (20, 0, None)
                    ),
                    ("V-Rep Bullet 2.83", "scene2_two_joints") => {
                        assert_eq!(excluded, ["Double_VRepBullet283_5"])
                    }
                    _ => {
                        assert!(
                            excluded.is_empty(),
                            "{} {}: {excluded:?}",
                            r.scene,
                            src.source
                        );
                        assert!(src.accumulated_error_m.unwrap().is_finite());
                    }
                }
            }
            let a = r.alignment.as_ref().unwrap();
            assert_eq!(a.runs.len(), 20, "{}: every real run aligned", r.scene);
        }
    }
}
