//! What a tune minimises, and how a candidate is simulated.
//!
//! **Objective** (metres): the accumulated wrist error of every scene of
//! the study against the real arm's mean over the training runs (the
//! measure `compare` reports), summed over the scenes, plus, in every
//! scene with a cube, the cube's final pose error times the scene's
//! compared steps ([`CUBE_WEIGHT_PER_STEP`] = 0.1 per step by default, so
//! a 0.05 m miss of the cube counts like a 0.05 m wrist error held through
//! a tenth of the scene; `tune --cube-weight` changes it). The pose error is
//! the distance between the simulated and the real cube's final positions
//! plus how far the difference of their turns moves the cube's face
//! centres (the angle between the two rotations from the start, in
//! radians, times half the cube's longest edge): a cube pushed to the
//! right place but tipped over is not a right push. The
//! real runs are aligned and registered exactly as `compare` does; the
//! registration of a candidate is its own (the measurement's estimate,
//! moved by the candidate's registration offset when the space fits it).
//!
//! **Simulation**: each scene of a candidate runs in a child process
//! (`realitygap __run-one`), as `run` isolates its runs: a candidate that
//! diverges, crashes or times out scores [`FAILED_OBJECTIVE`] and the
//! search goes on.

use anyhow::{anyhow, bail, Context, Result};
use realitygap_analysis::bootstrap::BootstrapOptions;
use realitygap_analysis::compare::{
    CompareOptions, RegistrationChoice, RunInput, SceneReport, SourceRuns,
};
use realitygap_analysis::registration::Registration;
use realitygap_analysis::selection::{RunRange, RunSelection};
use realitygap_analysis::{
    align_references, evaluate_study_aligned, AlignedReferences, SceneInput,
};
use realitygap_core::params::PhysicalParams;
use realitygap_core::{Quat, Trajectory, Vec3};
use realitygap_runner::{run_child, ChildEnd, Job, Launcher};
use realitygap_study::{LoadedScene, Roots, Study};
use serde::Serialize;
use std::path::PathBuf;

/// The default weight of a cube's final pose error, per compared step
/// of its scene: in the study's scene 3 (400 steps) a 1 cm miss counts
/// 0.4 m, about the real runs' own noise on the wrist total (0.26-0.31
/// m). At 1 per step a centimetre counted 4 m, and the searches gave up
/// 2-6 m of wrist for the push's last centimetres (docs/tune.md).
pub const CUBE_WEIGHT_PER_STEP: f64 = 0.1;

/// The objective of a candidate that diverged, crashed or could not be
/// measured, metres: far above any finished candidate's.
pub const FAILED_OBJECTIVE: f64 = 1.0e6;

/// A child process running one scene is killed after this many seconds.
pub const SCENE_TIMEOUT_S: f64 = 300.0;

/// One scene of the study as a tune sees it.
#[derive(Debug, Clone, Serialize)]
pub struct TargetScene {
    /// The scene's name.
    pub name: String,
    /// The scene file simulated.
    pub scene_file: PathBuf,
    /// Control steps compared.
    pub steps: usize,
    /// True when the scene has a cube (its final position is measured).
    pub cube: bool,
    /// The weight of the cube's final pose error in the objective (m per
    /// m; 0 without a cube).
    pub cube_weight: f64,
    /// The lever of the cube's turn error: half the longest edge of the
    /// tracked cube (0 when the scene's cube is not a box it knows).
    pub cube_lever_m: f64,
}

/// The real arm a tune fits: the study's scenes with their real runs.
pub struct Target {
    /// The scenes, in study order.
    pub scenes: Vec<TargetScene>,
    loaded: Vec<LoadedScene>,
    /// The training runs (fit and scored on).
    pub train: RunSelection,
    /// The held-out runs (never fitted on), if any.
    pub holdout: Option<RunRange>,
    /// The measurement's own registration, estimated from the training
    /// runs against the kinematic reference (no simulator is read).
    pub base_registration: Registration,
    /// The control period, s.
    pub period_s: f64,
    /// The weight of a cube's final pose error per compared step.
    pub cube_weight_per_step: f64,
    /// The training runs selected and aligned once: every candidate is
    /// scored against the same real runs.
    aligned_train: Option<AlignedReferences>,
}

/// One scene's share of an objective.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneScore {
    /// Scene name.
    pub scene: String,
    /// Accumulated wrist error, metres.
    pub accumulated_m: f64,
    /// Distance between the simulated and the real cube's final
    /// positions, metres (scenes with a cube).
    pub cube_final_m: Option<f64>,
    /// Angle between the simulated and the real cube's rotations from
    /// their starts, degrees (scenes with a cube).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cube_turn_deg: Option<f64>,
}

/// A candidate's objective.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// The objective, metres ([`FAILED_OBJECTIVE`] when failed).
    pub objective: f64,
    /// Per scene (empty when failed).
    pub scenes: Vec<SceneScore>,
    /// Why the candidate failed, if it did.
    pub failed: Option<String>,
}

impl Score {
    /// The score of a failed candidate.
    pub fn failed(message: String) -> Score {
        Score {
            objective: FAILED_OBJECTIVE,
            scenes: Vec::new(),
            failed: Some(message),
        }
    }
}

/// `base` moved by a rotation vector (degrees) and a translation (metres)
/// applied after it.
pub fn offset_registration(
    base: &Registration,
    rot_deg: [f64; 3],
    trans_m: [f64; 3],
) -> Registration {
    let v = Vec3::from_array(rot_deg.map(f64::to_radians));
    let angle = v.norm();
    let d = if angle > 0.0 {
        Quat::from_axis_angle(v.scale(1.0 / angle), angle)
    } else {
        Quat::IDENTITY
    };
    Registration {
        rotation: (d * base.rotation).normalized().unwrap_or(Quat::IDENTITY),
        translation_m: d.rotate(base.translation_m) + Vec3::from_array(trans_m),
    }
}

impl Target {
    /// The study's scenes with their real runs (study sources are
    /// dropped), the training and held-out runs, and the measurement's
    /// registration estimated from the training runs.
    pub fn new(
        study: &Study,
        roots: &Roots,
        runs: Option<RunRange>,
        holdout: Option<RunRange>,
        cube_weight_per_step: f64,
    ) -> Result<Target> {
        if !cube_weight_per_step.is_finite() || cube_weight_per_step < 0.0 {
            bail!("--cube-weight {cube_weight_per_step}: expected a finite number >= 0");
        }
        let mut study = study.clone();
        study.sources.clear();
        let mut scenes = Vec::new();
        for s in &mut study.scenes {
            s.sources.clear();
            let Some(file) = &s.scene else {
                bail!(
                    "study scene '{}' has no `scene` file: a tune needs the scene to simulate",
                    s.name
                );
            };
            let scene_file = study.folder.join(file);
            if !scene_file.is_file() {
                bail!(
                    "study scene '{}': scene file {} not found",
                    s.name,
                    scene_file.display()
                );
            }
            let cube_lever_m = if s.cube.is_some() {
                cube_lever(&scene_file)?
            } else {
                0.0
            };
            scenes.push(TargetScene {
                name: s.name.clone(),
                scene_file,
                steps: s.steps,
                cube: s.cube.is_some(),
                cube_weight: if s.cube.is_some() {
                    cube_weight_per_step * s.steps as f64
                } else {
                    0.0
                },
                cube_lever_m,
            });
        }
        let loaded = study.load(roots)?;
        // Without --runs, every run not held out is fitted on (never the
        // held-out ones).
        let most = loaded
            .iter()
            .map(|l| l.reference.runs.len())
            .max()
            .unwrap_or(0);
        RunSelection {
            runs: runs.clone(),
            holdout: holdout.clone(),
        }
        .check_count(most, "runs")?;
        let runs = match (&runs, &holdout) {
            (None, Some(h)) => Some(h.complement(most).ok_or_else(|| {
                anyhow::anyhow!(
                    "{} \"{}\" holds out every run: none is left to fit on",
                    h.origin,
                    h.text
                )
            })?),
            _ => runs,
        };
        let train = RunSelection {
            runs: runs.clone(),
            holdout: None,
        };
        // Every selection must pick runs in every scene, before anything
        // runs.
        for l in &loaded {
            let n = l.reference.runs.len();
            train.select(&l.spec.name, n)?;
            if holdout.is_some() {
                RunSelection {
                    runs: runs.clone(),
                    holdout: holdout.clone(),
                }
                .select(&l.spec.name, n)?;
            }
        }
        let mut target = Target {
            scenes,
            loaded,
            train,
            holdout,
            base_registration: Registration::IDENTITY,
            period_s: study.control_period_s,
            cube_weight_per_step,
            aligned_train: None,
        };
        // Align the training runs once; the registration estimate and every
        // candidate's score reuse that alignment.
        let no_sources = vec![Vec::new(); target.scenes.len()];
        let opts = target.options(RegistrationChoice::Estimate, &target.train, None);
        let inputs = target.inputs(&no_sources);
        let aligned = align_references(&inputs, &opts)?;
        let reports = evaluate_study_aligned(&inputs, &aligned, &opts);
        target.base_registration = reports
            .iter()
            .find_map(|r| r.registration.as_ref().map(|x| x.registration()))
            .unwrap_or(Registration::IDENTITY);
        target.aligned_train = Some(aligned);
        Ok(target)
    }

    /// The fewest real runs of any scene (what folds of runs can split).
    pub fn run_count(&self) -> usize {
        self.loaded
            .iter()
            .map(|l| l.reference.runs.len())
            .min()
            .unwrap_or(0)
    }

    /// The held-out selection (`--runs` fitted, `--holdout` scored).
    pub fn holdout_selection(&self) -> Option<RunSelection> {
        self.holdout.as_ref().map(|h| RunSelection {
            runs: self.train.runs.clone(),
            holdout: Some(h.clone()),
        })
    }

    /// The analysis options for `registration`, `selection` and
    /// `bootstrap` resamples (`None`: no intervals).
    fn options(
        &self,
        registration: RegistrationChoice,
        selection: &RunSelection,
        bootstrap: Option<usize>,
    ) -> CompareOptions {
        CompareOptions {
            registration,
            runs: selection.clone(),
            bootstrap: Some(BootstrapOptions {
                resamples: bootstrap.unwrap_or(0),
                ..BootstrapOptions::default()
            }),
            ..CompareOptions::default()
        }
    }

    /// The scenes with `sources` (per scene) as analysis input.
    fn inputs<'a>(&'a self, sources: &'a [Vec<SourceRuns>]) -> Vec<SceneInput<'a>> {
        self.loaded
            .iter()
            .zip(sources)
            .map(|(l, s)| SceneInput {
                spec: &l.spec,
                reference: &l.reference,
                sources: s,
            })
            .collect()
    }

    /// Runs the analysis on `sources` (per scene) with `registration`,
    /// `selection`, and `bootstrap` resamples (`None`: no intervals).
    pub fn evaluate(
        &self,
        sources: &[Vec<SourceRuns>],
        registration: RegistrationChoice,
        selection: &RunSelection,
        bootstrap: Option<usize>,
    ) -> Result<Vec<SceneReport>> {
        let opts = self.options(registration, selection, bootstrap);
        Ok(realitygap_analysis::evaluate_study(
            &self.inputs(sources),
            &opts,
        )?)
    }

    /// One source per scene named `name` from one trajectory per scene.
    pub fn sources(&self, name: &str, trajectories: Vec<Trajectory>) -> Vec<Vec<SourceRuns>> {
        trajectories
            .into_iter()
            .map(|trajectory| {
                vec![SourceRuns {
                    name: name.to_string(),
                    kind: "simulated".into(),
                    rate_hz: 1.0 / self.period_s,
                    alignment: None,
                    runs: vec![RunInput {
                        id: "run000".into(),
                        trajectory,
                        failed: None,
                    }],
                }]
            })
            .collect()
    }

    /// The objective of one simulated trajectory per scene, registered by
    /// `registration`, on the training runs.
    pub fn score(&self, trajectories: Vec<Trajectory>, registration: &Registration) -> Score {
        match self.candidate_reports(trajectories, registration) {
            Ok(reports) => score_of(&reports, &self.scenes),
            Err(m) => Score::failed(m),
        }
    }

    /// The training runs' reports of one simulated trajectory per scene,
    /// registered by `registration` (the runs aligned once, in [`Target::new`]).
    fn candidate_reports(
        &self,
        trajectories: Vec<Trajectory>,
        registration: &Registration,
    ) -> std::result::Result<Vec<SceneReport>, String> {
        let sources = self.sources("candidate", trajectories);
        let choice = RegistrationChoice::Given {
            registration: *registration,
            origin: "tune candidate".into(),
        };
        let opts = self.options(choice, &self.train, None);
        match &self.aligned_train {
            Some(aligned) => Ok(evaluate_study_aligned(
                &self.inputs(&sources),
                aligned,
                &opts,
            )),
            None => realitygap_analysis::evaluate_study(&self.inputs(&sources), &opts)
                .map_err(|e| e.to_string()),
        }
    }
}

impl Target {
    /// The errors of one simulated trajectory per scene, registered by
    /// `registration`, on the training runs: each compared step's wrist
    /// error (the simulated mean minus the reference's), then, per scene
    /// with a cube, its weighted final pose error.
    pub fn errors(
        &self,
        trajectories: Vec<Trajectory>,
        registration: &Registration,
    ) -> std::result::Result<Errors, String> {
        let reports = self.candidate_reports(trajectories, registration)?;
        let score = score_of(&reports, &self.scenes);
        if let Some(m) = score.failed {
            return Err(m);
        }
        let mut out = Errors::default();
        for (report, s) in reports.iter().zip(&self.scenes) {
            let series = report.sources.first().map(|x| &x.series);
            let reference = &report.reference.series.wrist_mean_m;
            out.wrist.extend((0..s.steps).map(|k| {
                let compared = series
                    .and_then(|x| x.wrist_distance_to_reference_m.get(k).copied().flatten())
                    .is_some();
                let a = series.and_then(|x| x.wrist_mean_m.get(k).copied().flatten());
                let b = reference.get(k).copied().flatten();
                match (compared, a, b) {
                    (true, Some(a), Some(b)) => Some([a[0] - b[0], a[1] - b[1], a[2] - b[2]]),
                    _ => None,
                }
            }));
            if let Some(sc) = score.scenes.iter().find(|x| x.scene == s.name) {
                if let Some(c) = sc.cube_final_m {
                    let e = cube_pose_error_m(c, sc.cube_turn_deg.unwrap_or(0.0), s.cube_lever_m);
                    out.cube.push((s.cube_weight * e).max(0.0));
                }
            }
        }
        Ok(out)
    }
}

/// A candidate's errors ([`Target::errors`]): the objective is the sum of
/// the wrist errors' lengths and the cubes' weighted errors.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Errors {
    /// Per compared step of every scene, the wrist error (metres); `None`
    /// where a step is not compared.
    pub wrist: Vec<Option<[f64; 3]>>,
    /// Per scene with a cube, its weighted final pose error.
    pub cube: Vec<f64>,
    /// The pull toward the physics-free model's values
    /// ([`crate::Tuner::prior_residuals`]): residuals whose squares are
    /// added to the objective. Empty without a pull.
    pub prior: Vec<f64>,
}

/// Weights of the reweighted least squares ([`Errors::weights`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    wrist: Vec<f64>,
    cube: Vec<f64>,
}

impl Errors {
    /// The objective: the wrist errors' lengths and the cubes' errors,
    /// summed.
    pub fn objective(&self) -> f64 {
        self.wrist.iter().flatten().map(norm).sum::<f64>()
            + self.cube.iter().sum::<f64>()
            + self.prior.iter().map(|r| r * r).sum::<f64>()
    }

    /// Reweighting at this point: each error's length, floored at
    /// `floor_m`, to the power -1/2 ([`Errors::residuals`]).
    pub fn weights(&self, floor_m: f64) -> Weights {
        let w = |d: f64| 1.0 / d.max(floor_m).sqrt();
        Weights {
            wrist: self
                .wrist
                .iter()
                .map(|e| e.map(|e| w(norm(&e))).unwrap_or(0.0))
                .collect(),
            cube: self.cube.iter().map(|&c| w(c)).collect(),
        }
    }

    /// Least-squares residuals. Without weights: the square root of each
    /// error's length (0 where a step is not compared), whose squares sum
    /// to the objective, but whose Jacobian is poor where an error is
    /// small. With weights from a point `x0`: each error's components times
    /// its weight, whose squares sum to the objective at `x0` and near it
    /// are smooth (iteratively reweighted least squares for a sum of
    /// lengths).
    pub fn residuals(&self, weights: Option<&Weights>) -> Vec<f64> {
        match weights {
            None => self
                .wrist
                .iter()
                .map(|e| e.map(|e| norm(&e).sqrt()).unwrap_or(0.0))
                .chain(self.cube.iter().map(|c| c.sqrt()))
                .chain(self.prior.iter().copied())
                .collect(),
            Some(w) => {
                let mut r = Vec::with_capacity(3 * self.wrist.len() + self.cube.len());
                for (e, w) in self.wrist.iter().zip(&w.wrist) {
                    let e = e.unwrap_or([0.0; 3]);
                    r.extend(e.iter().map(|x| x * w));
                }
                r.extend(self.cube.iter().zip(&w.cube).map(|(c, w)| c * w));
                r.extend(self.prior.iter().copied());
                r
            }
        }
    }
}

fn norm(e: &[f64; 3]) -> f64 {
    (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
}

/// The angle, degrees, between two rotations of a cube from its start,
/// each given as its change of roll, pitch and yaw (degrees; the study's
/// cube starts level, so these are its end orientation's angles).
pub fn turn_between_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let q =
        |r: [f64; 3]| Quat::from_euler_rpy(r[0].to_radians(), r[1].to_radians(), r[2].to_radians());
    q(a).angle_to(q(b)).to_degrees()
}

/// The cube's final pose error, metres: the distance between the final
/// positions plus the turn between the final rotations (degrees) at the
/// lever `lever_m`.
fn cube_pose_error_m(distance_m: f64, turn_deg: f64, lever_m: f64) -> f64 {
    distance_m + lever_m * turn_deg.to_radians()
}

/// Half the longest edge of the box a scene tracks as its cube (the
/// `[[track]]` with role `cube`): the lever of the cube's turn error. 0
/// when the scene tracks no such box.
fn cube_lever(scene_file: &std::path::Path) -> Result<f64> {
    use realitygap_core::scene::{ObjectShape, Scene, TrackTarget};
    let scene = Scene::from_file(scene_file)
        .with_context(|| format!("reading scene {}", scene_file.display()))?;
    let name = scene.tracked.iter().find_map(|t| match &t.target {
        TrackTarget::Object(o) if t.role == "cube" => Some(o.clone()),
        _ => None,
    });
    Ok(name
        .and_then(|n| scene.objects.iter().find(|o| o.name == n))
        .map(|o| match o.shape {
            ObjectShape::Box { size_m } => size_m.x.max(size_m.y).max(size_m.z) / 2.0,
        })
        .unwrap_or(0.0))
}

/// The objective from the reports of one source per scene.
pub fn score_of(reports: &[SceneReport], scenes: &[TargetScene]) -> Score {
    let mut out = Vec::new();
    let mut total = 0.0;
    for (r, s) in reports.iter().zip(scenes) {
        let Some(src) = r.sources.first() else {
            return Score::failed(format!("scene {}: nothing was measured", s.name));
        };
        let Some(acc) = src.accumulated_error_m.filter(|a| a.is_finite()) else {
            let why = src
                .runs_flagged
                .iter()
                .flat_map(|f| f.flags.iter().map(|x| format!("{x:?}")))
                .collect::<Vec<_>>()
                .join("; ");
            return Score::failed(format!(
                "scene {}: no accumulated error ({})",
                s.name,
                if why.is_empty() {
                    "no run compared"
                } else {
                    &why
                }
            ));
        };
        total += acc;
        let mut cube_turn_deg = None;
        let cube_final_m = if s.cube {
            match (&src.cube, &r.reference.cube) {
                (Some(c), Some(rc)) => {
                    let d = Vec3::from_array(c.final_position_m)
                        .distance(Vec3::from_array(rc.final_position_m));
                    let turn = turn_between_deg(c.rpy_change_deg, rc.rpy_change_deg);
                    total += s.cube_weight * cube_pose_error_m(d, turn, s.cube_lever_m);
                    cube_turn_deg = Some(turn);
                    Some(d)
                }
                _ => return Score::failed(format!("scene {}: the cube was not measured", s.name)),
            }
        } else {
            None
        };
        out.push(SceneScore {
            scene: s.name.clone(),
            accumulated_m: acc,
            cube_final_m,
            cube_turn_deg,
        });
    }
    Score {
        objective: total,
        scenes: out,
        failed: None,
    }
}

/// A scene's trajectory from its child's end, or why it failed.
fn trajectory_of(scene: &TargetScene, end: ChildEnd) -> std::result::Result<Trajectory, String> {
    match end {
        ChildEnd::Failed(m) => Err(format!("scene {}: failed: {m}", scene.name)),
        ChildEnd::Done(r) => {
            if let Some((t, why)) = &r.diverged {
                return Err(format!("scene {}: diverged at {t:.2} s: {why}", scene.name));
            }
            r.trajectory()
                .map_err(|e| format!("scene {}: {e:#}", scene.name))
        }
    }
}

/// Runs candidates' scenes in child processes, on this machine or as
/// Slurm job arrays.
#[derive(Clone)]
pub struct Simulator {
    /// How to start a child.
    pub launcher: Launcher,
    /// The engine.
    pub engine: String,
    /// The `--robot` value, if any.
    pub robot: Option<String>,
    /// `NAME=DIR` package locations.
    pub packages: Vec<String>,
    /// `None`: child processes here; `Some`: Slurm job arrays.
    pub slurm: Option<std::sync::Arc<crate::slurm_batch::Gatherer>>,
}

impl Simulator {
    /// Simulates every scene with `params`; the trajectories, or why the
    /// candidate failed (the first scene that diverged or failed).
    pub fn simulate(
        &self,
        scenes: &[TargetScene],
        params: &PhysicalParams,
    ) -> std::result::Result<Vec<Trajectory>, String> {
        let text = params.to_toml_string();
        if let Some(g) = &self.slurm {
            let jobs = scenes.iter().map(|s| self.job_for(s, &text)).collect();
            return scenes
                .iter()
                .zip(g.run(jobs))
                .map(|(s, end)| trajectory_of(s, end))
                .collect();
        }
        scenes
            .iter()
            .map(|s| {
                let job = self.job_for(s, &text);
                trajectory_of(s, run_child(&self.launcher, &job, Some(SCENE_TIMEOUT_S)))
            })
            .collect()
    }

    /// Checks, before anything runs, that every scene loads with `params`
    /// (names exist, the engine honours every key and setting).
    pub fn check(&self, scenes: &[TargetScene], params: &PhysicalParams) -> Result<()> {
        let text = params.to_toml_string();
        for s in scenes {
            let job = Job {
                check_only: true,
                ..self.job_for(s, &text)
            };
            if let ChildEnd::Failed(m) = run_child(&self.launcher, &job, Some(SCENE_TIMEOUT_S)) {
                return Err(anyhow!("{m}"))
                    .with_context(|| format!("scene {} in {}", s.name, self.engine));
            }
        }
        Ok(())
    }

    fn job_for(&self, scene: &TargetScene, params_text: &str) -> Job {
        Job {
            scene_file: scene.scene_file.clone(),
            engine: self.engine.clone(),
            robot: self.robot.clone(),
            packages: self.packages.clone(),
            set: Vec::new(),
            perturb: Vec::new(),
            seed: 0,
            params: None,
            params_text: Some(params_text.to_string()),
            check_only: false,
            stitch: None,
            allow_unstable: false,
            replay: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The pull's residuals are added to the objective as their squares,
    /// and both kinds of residuals keep summing to the objective.
    #[test]
    fn the_pull_adds_its_squares_to_the_objective_and_the_residuals() {
        let plain = Errors {
            wrist: vec![Some([0.03, 0.04, 0.0]), None, Some([0.0, 0.0, 0.01])],
            cube: vec![0.02],
            prior: Vec::new(),
        };
        let pulled = Errors {
            prior: vec![0.1, -0.2],
            ..plain.clone()
        };
        assert!((plain.objective() - 0.08).abs() < 1e-12);
        assert!((pulled.objective() - (0.08 + 0.01 + 0.04)).abs() < 1e-12);
        let squares = |r: Vec<f64>| r.iter().map(|x| x * x).sum::<f64>();
        assert!((squares(pulled.residuals(None)) - pulled.objective()).abs() < 1e-12);
        let w = pulled.weights(1e-6);
        assert!((squares(pulled.residuals(Some(&w))) - pulled.objective()).abs() < 1e-12);
        assert_eq!(pulled.residuals(Some(&w)).len(), 3 * 3 + 1 + 2);
    }

    #[test]
    fn the_turn_between_two_cube_rotations_is_their_geodesic_angle() {
        assert_eq!(turn_between_deg([0.0; 3], [0.0; 3]), 0.0);
        // A yaw of 24.6 degrees against a level, unturned cube.
        assert!((turn_between_deg([0.0, 0.0, 24.6], [0.0; 3]) - 24.6).abs() < 1e-9);
        // The same turn either way, and across the wrap at 180 degrees.
        assert!((turn_between_deg([0.0, 0.0, 179.0], [0.0, 0.0, -179.0]) - 2.0).abs() < 1e-9);
        // A cube tipped on its side (90 degrees of roll) against one that
        // turned 90 degrees about the vertical: 120 degrees apart.
        assert!((turn_between_deg([90.0, 0.0, 0.0], [0.0, 0.0, 90.0]) - 120.0).abs() < 1e-9);
    }

    #[test]
    fn the_cube_lever_is_half_the_tracked_box_longest_edge() {
        let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/scenes");
        let lever = cube_lever(&scenes.join("scene3_cube_push.toml")).unwrap();
        assert!((lever - 0.0375).abs() < 1e-12, "{lever}");
        // A scene without a tracked cube: no lever.
        assert_eq!(cube_lever(&scenes.join("iiwa_reach.toml")).unwrap(), 0.0);
        let e = cube_lever(&scenes.join("no_such_scene.toml")).unwrap_err();
        assert!(format!("{e:#}").contains("no_such_scene.toml"), "{e:#}");
    }
}
