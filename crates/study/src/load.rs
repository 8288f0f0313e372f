//! Reading every source a study names: recordings (Qualisys, recorded
//! simulator CSV) by file pattern, results directories by folder. Files
//! are read in parallel, each once.

use crate::files::glob;
use crate::study::{expand, SourceFormat, SourceSpec, Study, StudyScene};
use anyhow::{anyhow, bail, Context, Result};
use rayon::prelude::*;
use realitygap_analysis::align::Alignment;
use realitygap_analysis::compare::{RunInput, SceneSpec, SourceRuns};
use realitygap_analysis::kinematic::{kinematic_track, KinematicTrack};
use realitygap_core::robot::PackageResolver;
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::WRIST;
use realitygap_data::{
    qualisys, recorded, QualisysOptions, QuatOrder, RecordedOptions, RunStatus, RunStore,
    SourceKind,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where relative paths point.
#[derive(Debug, Clone)]
pub struct Roots {
    /// For `files` patterns.
    pub data: PathBuf,
    /// For `store` directories.
    pub results: PathBuf,
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Reads every run of a source.
pub fn load_source(
    spec: &SourceSpec,
    vars: &BTreeMap<String, String>,
    roots: &Roots,
    period_s: f64,
) -> Result<SourceRuns> {
    let ctx = || format!("source '{}'", spec.name);
    let files = || -> Result<Vec<PathBuf>> {
        let pattern = expand(spec.files.as_deref().unwrap_or_default(), vars).with_context(ctx)?;
        glob(&roots.data, &pattern).with_context(ctx)
    };
    match spec.format {
        SourceFormat::Qualisys => load_qualisys(spec, &files()?),
        SourceFormat::Recorded => load_recorded(spec, &files()?, period_s),
        SourceFormat::Store => {
            let dir = roots
                .results
                .join(expand(spec.dir.as_deref().unwrap_or_default(), vars).with_context(ctx)?);
            load_store(&dir, Some(&spec.name), spec.alignment.clone())
        }
    }
}

/// Reads a Qualisys source's files: the real arm, on its own clock.
fn load_qualisys(spec: &SourceSpec, files: &[PathBuf]) -> Result<SourceRuns> {
    let mut opts = QualisysOptions::collins2019();
    if let Some(f) = spec.frequency_hz {
        opts.frequency_hz = Some(f);
    }
    if let Some(b) = &spec.bodies {
        opts.body_names = Some(b.clone());
    }
    if let Some(r) = &spec.roles {
        opts.roles = r.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    }
    let runs: Vec<(RunInput, f64)> = files
        .par_iter()
        .map(|f| {
            let r = qualisys::read(f, &opts)?;
            Ok((
                RunInput {
                    id: stem(f),
                    trajectory: r.trajectory,
                    failed: None,
                },
                r.frequency_hz,
            ))
        })
        .collect::<Result<_, realitygap_data::ImportError>>()
        .with_context(|| format!("source '{}'", spec.name))?;
    let rate = runs.first().map_or(100.0, |r| r.1);
    if let Some((r, f)) = runs.iter().find(|r| (r.1 - rate).abs() > 1e-9) {
        bail!(
            "source '{}': run {} is at {f} Hz but the first run is at {rate} Hz",
            spec.name,
            r.id
        );
    }
    Ok(SourceRuns {
        name: spec.name.clone(),
        kind: "real".into(),
        rate_hz: rate,
        alignment: Some(spec.alignment.clone().unwrap_or_else(Alignment::estimate)),
        runs: runs.into_iter().map(|r| r.0).collect(),
    })
}

/// Reads a recorded simulator's files (one sample per control period).
fn load_recorded(spec: &SourceSpec, files: &[PathBuf], period_s: f64) -> Result<SourceRuns> {
    let opts = RecordedOptions {
        control_period_s: period_s,
        ..RecordedOptions::new(spec.quat_order.unwrap_or(QuatOrder::Wxyz))
    };
    let runs: Vec<RunInput> = files
        .par_iter()
        .map(|f| {
            let r = recorded::read(f, &opts)?;
            Ok(RunInput {
                id: stem(f),
                trajectory: r.trajectory,
                failed: None,
            })
        })
        .collect::<Result<_, realitygap_data::ImportError>>()
        .with_context(|| format!("source '{}'", spec.name))?;
    Ok(SourceRuns {
        name: spec.name.clone(),
        kind: "recorded".into(),
        rate_hz: 1.0 / period_s,
        alignment: None,
        runs,
    })
}

/// One run of a results directory; a failed run may have no trajectory
/// file, and is then kept empty, with its message.
fn store_run(store: &RunStore, dir: &Path, e: &realitygap_data::RunEntry) -> Result<RunInput> {
    let failed = match e.status {
        RunStatus::Ok => None,
        _ => Some(
            e.message
                .clone()
                .unwrap_or_else(|| format!("{:?}", e.status).to_lowercase()),
        ),
    };
    let trajectory = match store.read_run(&e.id) {
        Ok(t) => t,
        Err(_) if failed.is_some() => realitygap_core::Trajectory::default(),
        Err(err) => return Err(anyhow!("run '{}' of {}: {err}", e.id, dir.display())),
    };
    Ok(RunInput {
        id: e.id.clone(),
        trajectory,
        failed,
    })
}

/// Reads every run of a results directory as a source. Runs recorded as
/// failed or diverged are kept (with their message) so the analysis can
/// list them.
pub fn load_store(
    dir: &Path,
    name: Option<&str>,
    alignment: Option<Alignment>,
) -> Result<SourceRuns> {
    let store =
        RunStore::open(dir).with_context(|| format!("results directory {}", dir.display()))?;
    let m = store.manifest();
    let entries: Vec<_> = store.runs().to_vec();
    let runs: Vec<RunInput> = entries
        .par_iter()
        .map(|e| store_run(&store, dir, e))
        .collect::<Result<_>>()?;
    let rate_hz = runs
        .iter()
        .find(|r| r.trajectory.len() > 1)
        .map(|r| {
            let t = &r.trajectory.time_s;
            (t.len() - 1) as f64 / (t[t.len() - 1] - t[0])
        })
        .filter(|f| f.is_finite() && *f > 0.0)
        .unwrap_or(20.0);
    let (kind, alignment) = match m.kind {
        SourceKind::Real => ("real", Some(alignment.unwrap_or_else(Alignment::estimate))),
        SourceKind::Simulated => ("simulated", None),
        SourceKind::Recorded => ("recorded", None),
    };
    Ok(SourceRuns {
        name: name.map_or_else(|| m.source.clone(), str::to_string),
        kind: kind.into(),
        rate_hz,
        alignment,
        runs,
    })
}

/// A scene ready for analysis: its spec, reference and sources.
pub struct LoadedScene {
    /// What the analysis needs of the scene.
    pub spec: SceneSpec,
    /// The reference's runs.
    pub reference: SourceRuns,
    /// The sources' runs.
    pub sources: Vec<SourceRuns>,
}

impl LoadedScene {
    /// The scene as input to `realitygap_analysis::evaluate_study`.
    pub fn input(&self) -> realitygap_analysis::SceneInput<'_> {
        realitygap_analysis::SceneInput {
            spec: &self.spec,
            reference: &self.reference,
            sources: &self.sources,
        }
    }
}

impl Study {
    /// The kinematic reference of a scene file (relative to the study's
    /// folder) over `steps` control steps.
    pub fn kinematic(&self, file: &str, steps: usize) -> Result<KinematicTrack> {
        let path = self.folder.join(file);
        let scene = Scene::from_file(&path)?;
        let robot = scene
            .robot
            .model(&PackageResolver::from_env())
            .with_context(|| format!("robot of scene file {}", path.display()))?;
        kinematic_track(&scene, &robot, WRIST, steps)
            .map_err(|e| anyhow!("{}: {e}", path.display()))
    }

    /// Loads every scene's reference and sources.
    pub fn load(&self, roots: &Roots) -> Result<Vec<LoadedScene>> {
        self.scenes
            .iter()
            .map(|s| self.load_scene(s, roots))
            .collect()
    }

    /// Loads one scene's reference and sources (the study-wide ones, then
    /// the scene's own) and its kinematic reference.
    fn load_scene(&self, s: &StudyScene, roots: &Roots) -> Result<LoadedScene> {
        let ctx = || format!("scene '{}'", s.name);
        let reference =
            load_source(&s.reference, &s.vars, roots, self.control_period_s).with_context(ctx)?;
        let specs: Vec<&SourceSpec> = self.sources.iter().chain(&s.sources).collect();
        let sources = specs
            .par_iter()
            .map(|src| load_source(src, &s.vars, roots, self.control_period_s))
            .collect::<Result<Vec<_>>>()
            .with_context(ctx)?;
        let kinematic = match &s.scene {
            Some(file) => Some(self.kinematic(file, s.steps).with_context(|| {
                format!("scene '{}': `scene = \"{file}\"` in the study file", s.name)
            })?),
            None => None,
        };
        Ok(LoadedScene {
            spec: SceneSpec {
                name: s.name.clone(),
                steps: s.steps,
                control_period_s: self.control_period_s,
                goal_m: s.goal_m,
                goal_tolerance_m: s.goal_tolerance_m,
                phases_s: if s.phases_s.is_empty() {
                    vec![0.0]
                } else {
                    s.phases_s.clone()
                },
                cube: s.cube.clone(),
                kinematic,
            },
            reference,
            sources,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::pose::{Pose, Quat, Vec3};
    use realitygap_core::Trajectory;
    use realitygap_data::RunEntry;

    fn trajectory(samples: usize, period_s: f64) -> Trajectory {
        let mut t = Trajectory::with_bodies(&["wrist"]);
        t.time_s = (0..samples).map(|i| i as f64 * period_s).collect();
        t.bodies[0].poses = (0..samples)
            .map(|i| Some(Pose::new(Vec3::new(i as f64, 0.0, 0.0), Quat::IDENTITY)))
            .collect();
        t
    }

    #[test]
    fn a_results_directory_is_a_source_with_its_failed_runs_listed() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("scene/engine");
        let mut store =
            RunStore::create_or_open(&dir, "engine", SourceKind::Simulated, Some("scene")).unwrap();
        store
            .write_run(RunEntry::new("run000"), &trajectory(5, 0.05))
            .unwrap();
        let mut failed = RunEntry::new("run001");
        failed.message = Some("killed by signal 11".into());
        store.record_failed_run(failed).unwrap();

        let src = load_store(&dir, None, None).unwrap();
        assert_eq!(
            (src.name.as_str(), src.kind.as_str()),
            ("engine", "simulated")
        );
        assert!((src.rate_hz - 20.0).abs() < 1e-9, "{}", src.rate_hz);
        assert!(src.alignment.is_none());
        let ids: Vec<&str> = src.runs.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["run000", "run001"]);
        assert_eq!(src.runs[0].trajectory.len(), 5);
        assert_eq!(src.runs[1].failed.as_deref(), Some("killed by signal 11"));
        assert_eq!(src.runs[1].trajectory.len(), 0);

        let named = load_store(&dir, Some("Engine 1.0"), None).unwrap();
        assert_eq!(named.name, "Engine 1.0");
        let e = load_store(&tmp.path().join("none"), None, None).unwrap_err();
        assert!(format!("{e:#}").contains("results directory"), "{e:#}");
    }

    #[test]
    fn store_sources_resolve_against_the_results_root_with_placeholders() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("scene1/mujoco");
        let mut store =
            RunStore::create_or_open(&dir, "mujoco", SourceKind::Simulated, Some("scene1"))
                .unwrap();
        store
            .write_run(RunEntry::new("run000"), &trajectory(3, 0.1))
            .unwrap();
        let spec: SourceSpec =
            toml::from_str("name = \"MuJoCo\"\nformat = \"store\"\ndir = \"{scene}/mujoco\"\n")
                .unwrap();
        let vars: BTreeMap<String, String> = [("scene".into(), "scene1".into())].into();
        let roots = Roots {
            data: tmp.path().join("unused"),
            results: tmp.path().to_path_buf(),
        };
        let src = load_source(&spec, &vars, &roots, 0.05).unwrap();
        assert_eq!((src.name.as_str(), src.runs.len()), ("MuJoCo", 1));
        assert!((src.rate_hz - 10.0).abs() < 1e-9);
        let e = load_source(&spec, &BTreeMap::new(), &roots, 0.05).unwrap_err();
        assert!(format!("{e:#}").contains("source 'MuJoCo'"), "{e:#}");
    }
}
