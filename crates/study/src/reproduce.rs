//! The study `realitygap reproduce` compares: the reference study
//! (built in) with this tool's engines added to every scene, or, without
//! recordings, the engines compared with each other.

use crate::data_source::{assets_dir, DataSource};
use crate::load::Roots;
use crate::study::{SourceFormat, SourceSpec, Study, StudyScene};
use anyhow::{bail, Context, Result};
use realitygap_analysis::compare::CubeSpec;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::{Scene, TrackTarget};
use realitygap_core::trajectory::WRIST;
use realitygap_data::RunStore;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The study definition, built in.
const COLLINS2019: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../assets/studies/collins2019.toml"
));

/// The names of the study's scenes, in order (files
/// `assets/scenes/<name>.toml`).
pub const STUDY_SCENES: [&str; 3] = [
    "scene1_single_joint",
    "scene2_two_joints",
    "scene3_cube_push",
];

/// The study's scene files in the assets folder.
pub fn study_scene_files() -> Vec<PathBuf> {
    let dir = assets_dir().join("scenes");
    STUDY_SCENES
        .iter()
        .map(|s| dir.join(format!("{s}.toml")))
        .collect()
}

/// The folder of the study's recordings `data` names (`None` for `none`),
/// checked to hold them.
pub fn study_recordings(data: &DataSource) -> Result<Option<PathBuf>> {
    let data = data.resolve()?;
    if let Some(d) = &data {
        if !d.join("MotionCapture").is_dir() || !d.join("Simulation").is_dir() {
            bail!("--data {}: expected the study's recordings there (folders MotionCapture/ and Simulation/)", d.display());
        }
    }
    Ok(data)
}

/// A reproduction's study, its path (for the report) and roots: with
/// recordings (`data`), the reference study restricted to the scenes of
/// `scene_files`, this tool's engines (results in `runs_dir`) added to
/// each; without, the engines compared with the first one (the study
/// "file" in `out`).
pub fn reproduction_study(
    scene_files: &[PathBuf],
    data: Option<&Path>,
    out: &Path,
    runs_dir: &Path,
    engines: &[String],
) -> Result<(Study, PathBuf, Roots)> {
    let loaded: Vec<Scene> = scene_files
        .iter()
        .map(|p| Scene::from_file(p).map_err(anyhow::Error::from))
        .collect::<Result<_>>()?;
    let roots = |data: &Path| Roots {
        data: data.to_path_buf(),
        results: runs_dir.to_path_buf(),
    };
    let (study, study_path, roots) = match data {
        Some(data) => {
            let path = assets_dir().join("studies/collins2019.toml");
            let mut study = Study::from_toml_str(COLLINS2019, &path)?;
            study
                .scenes
                .retain(|s| loaded.iter().any(|l| l.name == s.name));
            for s in &mut study.scenes {
                s.sources
                    .extend(engine_sources(runs_dir, &s.name, engines)?);
            }
            (study, path, roots(data))
        }
        None => {
            let study = cross_engine_study(&loaded, runs_dir, engines)?;
            (study, out.join("study.toml"), roots(out))
        }
    };
    if study.scenes.is_empty() {
        bail!(
            "none of the scenes is part of the study (expected scene names {:?})",
            STUDY_SCENES
        );
    }
    Ok((study, study_path, roots))
}

/// A tune's outputs for `reproduce --tuned`: the engine (from
/// `summary.json`) and the parameters file `tuned.toml`.
#[derive(Debug, Clone, PartialEq)]
pub struct TunedEngine {
    /// The engine tuned.
    pub engine: String,
    /// Its `tuned.toml`.
    pub params: PathBuf,
    /// The folder the tuned runs go to, relative to the runs folder.
    pub runs_subdir: String,
}

impl TunedEngine {
    /// Reads a tune's output folder.
    pub fn from_dir(dir: &Path) -> Result<TunedEngine> {
        let summary = dir.join("summary.json");
        let text = std::fs::read_to_string(&summary).with_context(|| {
            format!(
                "--tuned {}: no {} (is it the --out folder of a finished `realitygap tune`?)",
                dir.display(),
                summary.display()
            )
        })?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}: not valid JSON", summary.display()))?;
        let Some(engine) = v.get("engine").and_then(|e| e.as_str()) else {
            bail!("{}: field `engine` missing", summary.display());
        };
        let params = dir.join("tuned.toml");
        if !params.is_file() {
            bail!("--tuned {}: no tuned.toml", dir.display());
        }
        Ok(TunedEngine {
            engine: engine.to_string(),
            params,
            runs_subdir: format!("tuned-{engine}"),
        })
    }

    /// The tunes of `dirs`, each followed by the fitted physics-free row
    /// it holds (`DIR/physics-free-actuator`, a tune folder of the
    /// physics-free model behind its fitted actuator stage), once: the
    /// first tune's, unless a physics-free folder is given itself.
    pub fn with_physics_free(dirs: &[PathBuf], physics_free_dir: &str) -> Result<Vec<TunedEngine>> {
        let mut out: Vec<TunedEngine> = dirs
            .iter()
            .map(|d| TunedEngine::from_dir(d))
            .collect::<Result<_>>()?;
        let given = out
            .iter()
            .any(|t| t.engine == realitygap_core::engine::PHYSICS_FREE_ENGINE);
        if !given {
            let fitted = dirs
                .iter()
                .map(|d| d.join(physics_free_dir))
                .find(|d| d.join("summary.json").is_file() && d.join("tuned.toml").is_file());
            if let Some(d) = fitted {
                out.push(TunedEngine::from_dir(&d)?);
            }
        }
        Ok(out)
    }

    /// The scene's source of the tuned runs under `runs_dir`, named like
    /// the engine's own with "(tuned)", e.g. `MuJoCo 3.17.0 (tuned)`.
    pub fn source(&self, runs_dir: &Path, scene: &str) -> Result<Option<SourceSpec>> {
        let dir = runs_dir.join(&self.runs_subdir);
        Ok(
            engine_sources(&dir, scene, std::slice::from_ref(&self.engine))?
                .into_iter()
                .next()
                .map(|mut s| {
                    s.name = s.name.replace("(this tool)", "(tuned)");
                    s.about = Some(format!(
                        "{}, with the parameters and settings of {}",
                        s.about.unwrap_or_default(),
                        self.params.display()
                    ));
                    s.dir = s.dir.map(|d| format!("{}/{d}", self.runs_subdir));
                    s
                }),
        )
    }
}

/// One `store` source per engine results directory of a scene, named after
/// the engine and version in its manifest, e.g. `MuJoCo 3.17.0 (this tool)`.
pub fn engine_sources(runs_dir: &Path, scene: &str, engines: &[String]) -> Result<Vec<SourceSpec>> {
    let mut out = Vec::new();
    for engine in engines {
        let dir = runs_dir.join(scene).join(engine);
        if !dir.join("manifest.json").is_file() {
            continue;
        }
        let store = RunStore::open(&dir)?;
        let m = store.manifest();
        // "MuJoCo 3.17.0 (mujoco-rs 7.0.0)" -> "MuJoCo 3.17.0 (this tool)".
        let version = m
            .engine
            .as_ref()
            .map(|e| e.version.clone())
            .unwrap_or_default();
        let label = version.split(" (").next().unwrap_or_default().trim();
        out.push(SourceSpec {
            name: format!(
                "{} (this tool)",
                if label.is_empty() {
                    engine.as_str()
                } else {
                    label
                }
            ),
            about: Some(format!("simulated by this tool: {version}")),
            format: SourceFormat::Store,
            files: None,
            dir: Some(format!("{scene}/{engine}")),
            quat_order: None,
            alignment: None,
            frequency_hz: None,
            bodies: None,
            roles: None,
        });
    }
    Ok(out)
}

/// Without recordings: a study comparing the engines with the first one.
/// Each scene's goal is the wrist at the final targets, by forward
/// kinematics of the scene's robot.
fn cross_engine_study(scenes: &[Scene], runs_dir: &Path, engines: &[String]) -> Result<Study> {
    let mut out = Vec::new();
    for scene in scenes {
        let mut sources = engine_sources(runs_dir, &scene.name, engines)?;
        if sources.is_empty() {
            continue;
        }
        let reference = sources.remove(0);
        let robot = scene
            .robot
            .model(&PackageResolver::from_env())
            .with_context(|| format!("scene {}", scene.name))?;
        let goal = final_wrist(scene, &robot);
        let cube = scene.objects.first().map(|o| CubeSpec {
            nominal_start_m: Some(o.pose.position_m.to_array()),
            contact_threshold_m: 0.005,
        });
        let mut phases: Vec<f64> = scene.schedule.iter().map(|e| e.t_s).collect();
        if phases.first() != Some(&0.0) {
            phases.insert(0, 0.0);
        }
        out.push(StudyScene {
            name: scene.name.clone(),
            steps: scene.sample_count(),
            goal_m: goal,
            goal_tolerance_m: 0.01,
            phases_s: phases,
            cube: if scene
                .tracked
                .iter()
                .any(|t| matches!(t.target, TrackTarget::Object(_)))
            {
                cube
            } else {
                None
            },
            scene: None,
            vars: BTreeMap::new(),
            reference,
            sources,
        });
    }
    Ok(Study {
        name: "cross-engine".into(),
        title: Some("The engines compared with each other (no real recordings given)".into()),
        control_period_s: scenes.first().map_or(0.05, |s| s.controller.period_s),
        sources: vec![],
        scenes: out,
        runs: None,
        holdout: None,
        folder: PathBuf::new(),
    })
}

/// The wrist's world position at the scene's final targets.
fn final_wrist(scene: &Scene, robot: &RobotModel) -> Option<[f64; 3]> {
    let link = scene
        .tracked
        .iter()
        .find(|t| t.role == WRIST)
        .and_then(|t| match &t.target {
            TrackTarget::Link(l) => robot.link_by_name(l),
            TrackTarget::Object(_) => None,
        })?;
    let last_tick = scene.sample_count().saturating_sub(1);
    let targets = scene.targets_deg_at_tick(last_tick);
    let mut q = vec![0.0; robot.joints.len()];
    for (name, deg) in scene.controlled_joints().iter().zip(targets) {
        q[robot.joint_by_name(name)?] = deg.to_radians();
    }
    for (name, rad) in &scene.robot.held_joints_rad {
        if let Some(j) = robot.joint_by_name(name) {
            q[j] = *rad;
        }
    }
    robot
        .link_pose(&scene.robot.base, &q, link)
        .map(|p| p.position_m.to_array())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tune_dir(dir: &Path, engine: &str) {
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(
            dir.join("summary.json"),
            format!("{{\"engine\": \"{engine}\"}}"),
        )
        .unwrap();
        std::fs::write(dir.join("tuned.toml"), "").unwrap();
    }

    #[test]
    fn a_tune_brings_its_fitted_physics_free_row_once() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b) = (tmp.path().join("tune-mujoco"), tmp.path().join("tune-ode"));
        tune_dir(&a, "mujoco");
        tune_dir(&a.join("physics-free-actuator"), "ideal");
        tune_dir(&b, "ode");
        tune_dir(&b.join("physics-free-actuator"), "ideal");
        let engines = |dirs: &[PathBuf]| -> Vec<(String, PathBuf)> {
            TunedEngine::with_physics_free(dirs, "physics-free-actuator")
                .unwrap()
                .into_iter()
                .map(|t| (t.engine, t.params))
                .collect()
        };
        let both = engines(&[a.clone(), b.clone()]);
        assert_eq!(
            both,
            [
                ("mujoco".to_string(), a.join("tuned.toml")),
                ("ode".to_string(), b.join("tuned.toml")),
                (
                    "ideal".to_string(),
                    a.join("physics-free-actuator/tuned.toml")
                ),
            ]
        );
        // Given itself, it is not added again.
        let given = engines(&[b.join("physics-free-actuator"), a.clone()]);
        assert_eq!(given.iter().filter(|(e, _)| e == "ideal").count(), 1);
        assert_eq!(given[0].1, b.join("physics-free-actuator/tuned.toml"));
        // A tune without one brings none.
        let c = tmp.path().join("tune-bullet");
        tune_dir(&c, "bullet");
        assert_eq!(engines(&[c]).len(), 1);
    }
}
