//! `realitygap stitch`: does simulating each phase of a task in the engine
//! that models that phase best come closer to the real arm than any single
//! engine? (The closing proposal of the reference study, built and
//! measured.)
//!
//! 1. Every scene of the study is simulated in every engine (one
//!    deterministic run each, `OUT/runs/<scene>/<engine>/`).
//! 2. On the training runs of the real arm (`--runs`), each engine's
//!    accumulated error per schedule phase (`phase_errors_m`) picks the
//!    **automatic plan**: per phase the engine with the lowest error.
//! 3. The study's **proposed plan**: an engine with stiff constraint
//!    motors (Bullet by default) for free motion, MuJoCo for contact; the
//!    contact phases are the phase in which the real cube starts to move
//!    on the training runs (`contact_onset_s` of the reference) and every
//!    phase after it. A scene without a cube is free motion throughout.
//! 4. Both plans are run as stitched sources
//!    (`OUT/runs/<scene>/stitched-.../`, see `realitygap_core::stitch`)
//!    and every engine and plan is scored on the training runs and on the
//!    held-out runs (`--holdout`), with bootstrap intervals and, for each
//!    plan, a paired comparison with the best single engine.
//!
//! Plans given with `--plan` are run and scored the same way. Engines
//! given with a parameters file of their own (`--tuned ENGINE=FILE`, e.g.
//! a tune's `tuned.toml`) take part as candidates beside the engines at
//! their defaults: their single runs go to `OUT/runs/tuned-<label>/`, and
//! a plan names them `ENGINE@FILE`.
//!
//! The physics-free model (perfect tracking of the commands, the `ideal`
//! engine) is scored in every scene as a baseline row, never a phase's
//! engine; so is the physics-free model fitted by a tune (its
//! `physics-free-actuator/` folder, when a `--tuned` tune folder holds
//! one). Each scene then says whether its closest engine or plan beats
//! them ([`AgainstPhysicsFree`]).
//!
//! Outputs: `OUT/stitch.md` and `OUT/stitch.json` ([`StitchStudy`]), and
//! `OUT/report/` (the report of every source on the held-out runs, else
//! the training runs; the stitched sources' handovers drawn as vertical
//! lines in their colour).

use crate::data_source::DataSource;
use crate::evaluate::evaluate_scenes;
use crate::load::Roots;
use crate::measure::Measure;
use crate::provenance::{measure_details, provenance_for_study};
use crate::reproduce::engine_sources;
use crate::study::{SourceFormat, SourceSpec, Study};
use anyhow::{bail, Context, Result};
use realitygap_analysis::bootstrap::{paired, Interval, PairedComparison};
use realitygap_analysis::compare::{fmt_interval, SceneReport, SourceSummary};
use realitygap_core::scene::Scene;
use realitygap_core::stitch::{entry_label, phase_ticks, split_entry, StitchPlan};
use realitygap_report::html::ExtraSection;
use realitygap_runner::prepare::engine_names;
use realitygap_runner::{BatchSpec, Launcher, Plan, Registry};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What `realitygap stitch` is asked to do.
#[derive(Debug, Clone)]
pub struct StitchOptions {
    /// The study file.
    pub study: PathBuf,
    /// The real arm's recordings.
    pub data: DataSource,
    /// Output folder.
    pub out: PathBuf,
    /// How the gap is measured; its `runs` choose the plan, its `holdout`
    /// scores it.
    pub measure: Measure,
    /// Engines taking part; empty: every engine compiled in.
    pub engines: Vec<String>,
    /// The stiff-motor engine of the study's proposed plan.
    pub stiff_engine: String,
    /// The contact engine of the study's proposed plan.
    pub contact_engine: String,
    /// Runs at a time (default: the number of cores).
    pub jobs: Option<usize>,
    /// More plans to score, `E1,E2,...` (in each scene with at least as
    /// many phases as engines named).
    pub plans: Vec<String>,
    /// Engines with a parameters file of their own (e.g. a tune's
    /// `tuned.toml`), `ENGINE=FILE`: candidates for the automatic plan
    /// beside the engines at their defaults. A tune's output folder may be
    /// given instead of `ENGINE=FILE`.
    pub tuned: Vec<String>,
    /// The sub-folder of a tune's output folder that holds the physics-free
    /// model fitted beside it (`realitygap tune` writes
    /// `physics-free-actuator/`): the first `--tuned` folder's takes part
    /// as a physics-free row, unless a physics-free model is given in
    /// `tuned` itself. `None`: only the given ones.
    pub physics_free_subdir: Option<String>,
}

/// How the runs are made: the engines and the child process.
#[derive(Debug, Clone)]
pub struct Runner {
    /// The engines compiled in.
    pub registry: Registry,
    /// How to start a child process for one run.
    pub launcher: Launcher,
}

/// One source's score on one set of real runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// Accumulated error, metres.
    pub error_m: Option<f64>,
    /// Its 95 % bootstrap interval, metres.
    pub interval_m: Option<Interval>,
    /// Accumulated error per phase, metres.
    pub phase_errors_m: Vec<f64>,
    /// How far the mean cube moved from its start by the end, metres
    /// (scenes with a cube).
    pub cube_displacement_m: Option<f64>,
}

/// One row of a scene's table: a single engine or a stitched plan.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// The source's name in the comparison.
    pub source: String,
    /// `engine`, `automatic`, `proposed` or `given` (`--plan`), or
    /// `physics-free` (a baseline: the model with no physics at its
    /// defaults, and behind a tune's fitted actuator stage); a plan that
    /// is also an earlier role's is listed once, under that role.
    pub role: String,
    /// The engine of every phase (a single engine: the same throughout).
    pub plan: Vec<String>,
    /// On the training runs.
    pub training: Score,
    /// On the held-out runs (`None` without `--holdout`).
    pub held_out: Option<Score>,
}

/// A plan against the best single engine, on one set of runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Versus {
    /// The plan's source name.
    pub plan: String,
    /// The best single engine on these runs.
    pub best_single: String,
    /// Best single engine's error minus the plan's, metres (positive: the
    /// plan is closer to the real arm).
    pub gain_m: f64,
    /// Interval of the gain over the bootstrap replicates, metres.
    pub gain_interval_m: Option<Interval>,
    /// Probability that the plan is closer than the best single engine.
    pub probability_better: f64,
}

/// The closest engine or plan against one physics-free row, on one set
/// of runs: does simulating physics beat perfect tracking at all?
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AgainstPhysicsFree {
    /// The physics-free row's source name.
    pub physics_free: String,
    /// The engine or plan with the smallest error on these runs.
    pub closest: String,
    /// The physics-free row's error minus the closest source's, metres
    /// (positive: the simulation is closer to the real arm).
    pub gain_m: f64,
    /// Interval of the gain over the bootstrap replicates, metres.
    pub gain_interval_m: Option<Interval>,
    /// Probability that the closest source is closer than the physics-free
    /// row.
    pub probability_better: f64,
}

/// The outcome in one scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneStitch {
    /// The scene.
    pub scene: String,
    /// Start times of the phases, seconds.
    pub phases_s: Vec<f64>,
    /// When the real cube starts to move on the training runs, seconds.
    pub contact_onset_s: Option<f64>,
    /// How far the real cube moved on the training runs, metres.
    pub real_cube_displacement_m: Option<f64>,
    /// The automatic plan.
    pub automatic: Vec<String>,
    /// The study's proposed plan.
    pub proposed: Vec<String>,
    /// Every engine and plan, scored.
    pub rows: Vec<Row>,
    /// The plans against the best single engine, on the training runs.
    pub training_versus: Vec<Versus>,
    /// The same on the held-out runs.
    pub held_out_versus: Vec<Versus>,
    /// The closest engine or plan against each physics-free row, on the
    /// training runs.
    pub training_versus_physics_free: Vec<AgainstPhysicsFree>,
    /// The same on the held-out runs.
    pub held_out_versus_physics_free: Vec<AgainstPhysicsFree>,
}

/// The whole outcome.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StitchStudy {
    /// The study file.
    pub study: String,
    /// The training runs, in words.
    pub training_runs: String,
    /// The held-out runs, in words.
    pub held_out_runs: Option<String>,
    /// Per scene.
    pub scenes: Vec<SceneStitch>,
}

/// A study scene with its scene file.
struct StudySceneFile {
    name: String,
    file: PathBuf,
    scene: Scene,
}

/// Runs everything (see the module documentation) and writes
/// `stitch.md` and `stitch.json` into `opts.out`.
pub fn stitch_study(opts: &StitchOptions, runner: &Runner) -> Result<StitchStudy> {
    let study = Study::from_file(&opts.study)?;
    let scenes = scene_files(&study, &opts.study)?;
    let taking = engines_taking_part(runner.registry, opts)?;
    let engines = &taking.candidates;
    let all = taking.all();
    let data = opts
        .data
        .resolve()?
        .with_context(|| "--data: `stitch` needs the real arm's recordings, not none")?;
    let runs_dir = opts.out.join("runs");
    let roots = Roots {
        data,
        results: runs_dir.clone(),
    };
    let files: Vec<PathBuf> = scenes.iter().map(|s| s.file.clone()).collect();
    simulate(runner, opts, &files, &all, None)?;
    let training = Measure {
        holdout: None,
        ..opts.measure.clone()
    };
    let with_engines = without_holdout(&with_sources(&study, &runs_dir, engines, &[])?);
    let fit = evaluate(&with_engines, &roots, &training)?;
    let mut plans = Vec::new();
    for s in &scenes {
        plans.push(plan_scene(opts, runner, s, (&fit, &with_engines), engines)?);
    }
    let stitched: Vec<(String, Vec<String>)> = plans
        .iter()
        .flat_map(|(scene, roles, _)| roles.iter().map(|(_, p)| (scene.clone(), p.clone())))
        .collect();
    let full = with_sources(&study, &runs_dir, &all, &stitched)?;
    let train_reports = evaluate(&without_holdout(&full), &roots, &training)?;
    let held_reports = match &opts.measure.holdout.clone().or(study.holdout.clone()) {
        Some(_) => Some(evaluate(&full, &roots, &opts.measure)?),
        None => None,
    };
    let mut out = Vec::new();
    for (scene, roles, onset) in plans {
        let find = |reports: &[SceneReport]| reports.iter().find(|r| r.scene == scene).cloned();
        let train = find(&train_reports).context("training report")?;
        let held = held_reports.as_deref().and_then(find);
        out.push(scene_outcome(
            &full,
            &taking,
            (&train, held.as_ref()),
            &roles,
            onset,
        )?);
    }
    let result = StitchStudy {
        study: opts.study.display().to_string(),
        training_runs: train_reports
            .first()
            .and_then(|r| r.runs.as_ref())
            .map_or("all".into(), |r| r.selection.clone()),
        held_out_runs: held_reports
            .as_ref()
            .and_then(|r| r.first())
            .and_then(|r| r.runs.as_ref())
            .map(|r| r.selection.clone()),
        scenes: out,
    };
    write_outputs(&opts.out, &result)?;
    let mut provenance = provenance_for_study(&full, &opts.study, &roots, opts.measure.mode);
    provenance.details.extend(opts.data.provenance());
    provenance.details.extend(measure_details(&opts.measure));
    let scored = held_reports.as_ref().unwrap_or(&train_reports);
    let report_dir = opts.out.join("report");
    realitygap_report::write_report_with(
        scored,
        &provenance,
        &report_dir,
        &[report_section(&result)],
    )
    .with_context(|| format!("writing the report into {}", report_dir.display()))?;
    Ok(result)
}

/// A scene's plans (role, engine per phase), all run, and when the real
/// cube starts to move.
type ScenePlans = (String, Vec<(String, Vec<String>)>, Option<f64>);

/// Chooses and runs the plans of one scene from its training report
/// (`fit`, evaluated on `study`).
fn plan_scene(
    opts: &StitchOptions,
    runner: &Runner,
    s: &StudySceneFile,
    (fit, study): (&[SceneReport], &Study),
    engines: &[String],
) -> Result<ScenePlans> {
    let report = fit
        .iter()
        .find(|r| r.scene == s.name)
        .with_context(|| format!("scene {} was not evaluated", s.name))?;
    let phases = phase_ticks(&s.scene).len();
    let mut roles = vec![
        (
            "automatic".to_string(),
            automatic_plan(report, study, &s.name, engines)?,
        ),
        (
            "proposed".to_string(),
            proposed_plan(&s.scene, report, opts),
        ),
    ];
    for given in &opts.plans {
        // A plan longer than the scene's phases does not apply to it.
        if let Ok(p) = StitchPlan::parse(given, &engine_names(runner.registry))
            .with_context(|| "--plan")?
            .per_phase(phases)
        {
            roles.push(("given".to_string(), p));
        }
    }
    for (_, plan) in &roles {
        simulate(runner, opts, std::slice::from_ref(&s.file), &[], Some(plan))?;
    }
    let onset = report
        .reference
        .cube
        .as_ref()
        .and_then(|c| c.contact_onset_s);
    Ok((s.name.clone(), roles, onset))
}

/// The study's scenes with their scene files (relative to the study file).
fn scene_files(study: &Study, path: &Path) -> Result<Vec<StudySceneFile>> {
    study
        .scenes
        .iter()
        .map(|s| {
            let Some(rel) = &s.scene else {
                bail!(
                    "{}: scene '{}' names no scene file (`scene = ...`), so it cannot be simulated",
                    path.display(),
                    s.name
                );
            };
            let file = study.folder.join(rel);
            let scene = Scene::from_file(&file)
                .with_context(|| format!("{}: scene '{}'", path.display(), s.name))?;
            Ok(StudySceneFile {
                name: s.name.clone(),
                file,
                scene,
            })
        })
        .collect()
}

/// The engines asked for (checked), else every one compiled in; the
/// proposed plan's engines must be among them.
fn engines_taking_part(registry: Registry, opts: &StitchOptions) -> Result<Taking> {
    use realitygap_core::engine::PHYSICS_FREE_ENGINE;
    let known = engine_names(registry);
    let engines = if opts.engines.is_empty() {
        // The physics-free model is a baseline, not a phase's engine.
        known
            .iter()
            .filter(|e| *e != PHYSICS_FREE_ENGINE)
            .cloned()
            .collect()
    } else {
        opts.engines.clone()
    };
    for e in engines
        .iter()
        .chain([&opts.stiff_engine, &opts.contact_engine])
    {
        if !known.contains(e) {
            bail!("unknown engine \"{e}\" (compiled in: {})", known.join(", "));
        }
        if e == PHYSICS_FREE_ENGINE {
            bail!("the physics-free model ({PHYSICS_FREE_ENGINE}) is a baseline row of every table, not an engine to stitch: leave it out of --engine, --stiff and --contact");
        }
    }
    if engines.is_empty() {
        bail!("no physics engine is compiled into this binary");
    }
    let mut taking = Taking {
        candidates: engines,
        physics_free: Vec::new(),
    };
    if known.iter().any(|k| k == PHYSICS_FREE_ENGINE) {
        taking.physics_free.push(PHYSICS_FREE_ENGINE.to_string());
    }
    let mut fitted_physics_free: Option<String> = None;
    for t in &opts.tuned {
        // A tune's output folder names its engine and holds tuned.toml.
        let dir = std::path::Path::new(t.as_str());
        let from_dir = dir
            .is_dir()
            .then(|| crate::reproduce::TunedEngine::from_dir(dir))
            .transpose()?
            .map(|te| format!("{}={}", te.engine, te.params.display()));
        let fitted = opts
            .physics_free_subdir
            .as_ref()
            .map(|sub| dir.join(sub))
            .filter(|d| d.join("summary.json").is_file() && d.join("tuned.toml").is_file());
        if let (None, Some(_), Some(d)) = (&fitted_physics_free, &from_dir, fitted) {
            let te = crate::reproduce::TunedEngine::from_dir(&d)?;
            let params = absolute(&te.params, t)?;
            fitted_physics_free = Some(format!("{}@{}", te.engine, params.display()));
        }
        let spec = from_dir.as_deref().unwrap_or(t.as_str());
        let Some((engine, file)) = spec.split_once('=') else {
            bail!("--tuned \"{t}\": expected ENGINE=FILE (a parameters file, e.g. a tune's tuned.toml) or the --out folder of a `realitygap tune`");
        };
        let engine = engine.trim();
        if !known.iter().any(|k| k == engine) {
            bail!(
                "--tuned \"{t}\": unknown engine \"{engine}\" (compiled in: {})",
                known.join(", ")
            );
        }
        let path = absolute(Path::new(file.trim()), t)?;
        if !path.is_file() {
            bail!("--tuned \"{t}\": no parameters file {}", path.display());
        }
        let entry = format!("{engine}@{}", path.display());
        if engine == PHYSICS_FREE_ENGINE {
            // Given itself: it replaces the one a tune's folder holds.
            taking.physics_free.push(entry);
            fitted_physics_free = Some(String::new());
        } else {
            taking.candidates.push(entry);
        }
    }
    taking
        .physics_free
        .extend(fitted_physics_free.filter(|e| !e.is_empty()));
    Ok(taking)
}

/// `path` made absolute (for `--tuned "given"`'s errors).
fn absolute(path: &Path, given: &str) -> Result<PathBuf> {
    std::path::absolute(path).with_context(|| format!("--tuned \"{given}\""))
}

/// The engines of a stitch: candidates for the plans' phases (the engines
/// at their defaults, then those with a parameters file of their own),
/// and the physics-free rows (the model at its defaults, and the one
/// fitted by a tune), scored beside them and never a phase's engine.
struct Taking {
    candidates: Vec<String>,
    physics_free: Vec<String>,
}

impl Taking {
    fn all(&self) -> Vec<String> {
        self.candidates
            .iter()
            .chain(&self.physics_free)
            .cloned()
            .collect()
    }
}

/// Where the single-engine runs of a candidate are, relative to
/// `OUT/runs`: `<scene>/<engine>`, or for an engine with a parameters
/// file `tuned-<label>/<scene>/<engine>`.
fn candidate_dir(scene: &str, entry: &str) -> String {
    match split_entry(entry) {
        (engine, Some(_)) => format!("tuned-{}/{scene}/{engine}", entry_label(entry)),
        (engine, None) => format!("{scene}/{engine}"),
    }
}

/// Runs `scenes` in the candidates `engines` (see [`candidate_dir`]), or
/// as the stitched `plan`.
fn simulate(
    runner: &Runner,
    opts: &StitchOptions,
    scenes: &[PathBuf],
    engines: &[String],
    plan: Option<&Vec<String>>,
) -> Result<()> {
    let plain: Vec<String> = engines
        .iter()
        .filter(|e| split_entry(e).1.is_none())
        .cloned()
        .collect();
    if !plain.is_empty() || plan.is_some() {
        simulate_batch(runner, opts, scenes, &plain, plan, None)?;
    }
    for entry in engines.iter().filter(|e| split_entry(e).1.is_some()) {
        let (engine, params) = split_entry(entry);
        let tuned = (
            params.map(PathBuf::from),
            format!("tuned-{}", entry_label(entry)),
        );
        simulate_batch(
            runner,
            opts,
            scenes,
            &[engine.to_string()],
            None,
            Some(tuned),
        )?;
    }
    Ok(())
}

/// One batch into `OUT/runs` (or `OUT/runs/<subfolder>` with a
/// parameters file: `tuned`), one deterministic run each; finished runs
/// are kept.
fn simulate_batch(
    runner: &Runner,
    opts: &StitchOptions,
    scenes: &[PathBuf],
    engines: &[String],
    plan: Option<&Vec<String>>,
    tuned: Option<(Option<PathBuf>, String)>,
) -> Result<()> {
    let (params, out) = match tuned {
        Some((params, folder)) => (params, opts.out.join("runs").join(folder)),
        None => (None, opts.out.join("runs")),
    };
    let spec = BatchSpec {
        scenes: scenes.to_vec(),
        engines: engines.to_vec(),
        repeats: 1,
        out,
        robot: None,
        packages: vec![],
        jobs: opts.jobs,
        seed: 0,
        perturb: vec![],
        set: vec![],
        timeout_s: None,
        params,
        stitch: plan.map(|p| p.join(",")),
        allow_unstable: false,
    };
    let mut batch = Plan::new(runner.registry, spec)?;
    batch.check_loads(&runner.launcher);
    let stats = batch.execute(&runner.launcher, &())?;
    for g in &batch.groups {
        if let Some(e) = &g.load_error {
            bail!(
                "{}/{}: the engine could not load the scene: {e}",
                g.scene_name,
                g.source
            );
        }
    }
    if stats.failures > 0 {
        bail!(
            "{} runs failed (see the manifests in {})",
            stats.failures,
            opts.out.join("runs").display()
        );
    }
    Ok(())
}

/// The study with this tool's engines and the stitched plans (scene,
/// engines per phase) added to its scenes.
fn with_sources(
    study: &Study,
    runs_dir: &Path,
    engines: &[String],
    stitched: &[(String, Vec<String>)],
) -> Result<Study> {
    let mut study = study.clone();
    for s in &mut study.scenes {
        for entry in engines {
            let (engine, params) = split_entry(entry);
            let dir = candidate_dir(&s.name, entry);
            let folder = runs_dir.join(&dir);
            let Some(root) = folder.parent().and_then(Path::parent) else {
                continue;
            };
            for mut source in engine_sources(root, &s.name, &[engine.to_string()])? {
                if let Some(p) = params {
                    let stem = Path::new(p)
                        .file_stem()
                        .unwrap_or_default()
                        .to_string_lossy();
                    source.name = source
                        .name
                        .replace("(this tool)", &format!("(this tool, {stem})"));
                    source.about = Some(format!(
                        "{}, with the parameters file {p}",
                        source.about.unwrap_or_default()
                    ));
                }
                source.dir = Some(dir.clone());
                s.sources.push(source);
            }
        }
        for (_, plan) in stitched.iter().filter(|(scene, _)| *scene == s.name) {
            let p = StitchPlan {
                engines: plan.clone(),
            };
            let (name, dir) = (p.display_name(plan.len())?, p.dir_name(plan.len())?);
            if s.sources.iter().any(|x| x.name == name) {
                continue;
            }
            s.sources.push(SourceSpec {
                name,
                about: Some("stitched by this tool: one engine per phase".into()),
                format: SourceFormat::Store,
                files: None,
                dir: Some(format!("{}/{dir}", s.name)),
                quat_order: None,
                alignment: None,
                frequency_hz: None,
                bodies: None,
                roles: None,
            });
        }
    }
    Ok(study)
}

/// The study scored on its training runs (its `holdout` dropped).
fn without_holdout(study: &Study) -> Study {
    Study {
        holdout: None,
        ..study.clone()
    }
}

fn evaluate(study: &Study, roots: &Roots, measure: &Measure) -> Result<Vec<SceneReport>> {
    let opts = measure.options(study)?;
    evaluate_scenes(&study.load(roots)?, &opts)
}

/// The name the comparison gives candidate `engine`'s source in `scene`.
fn engine_source_name(study: &Study, scene: &str, engine: &str) -> Option<String> {
    let dir = candidate_dir(scene, engine);
    study
        .scenes
        .iter()
        .find(|s| s.name == scene)?
        .sources
        .iter()
        .find(|s| s.dir.as_deref() == Some(dir.as_str()))
        .map(|s| s.name.clone())
}

/// Per phase, the engine with the lowest accumulated error in it.
fn automatic_plan(
    report: &SceneReport,
    study: &Study,
    scene: &str,
    engines: &[String],
) -> Result<Vec<String>> {
    let summaries: Vec<(&String, &SourceSummary)> = engines
        .iter()
        .filter_map(|e| {
            let name = engine_source_name(study, scene, e)?;
            Some((e, report.sources.iter().find(|s| s.source == name)?))
        })
        .collect();
    (0..report.phases_s.len().max(1))
        .map(|i| {
            summaries
                .iter()
                .filter(|(_, s)| s.phase_errors_m.get(i).is_some_and(|v| v.is_finite()))
                .min_by(|a, b| a.1.phase_errors_m[i].total_cmp(&b.1.phase_errors_m[i]))
                .map(|(e, _)| (*e).clone())
                .with_context(|| {
                    format!("scene {scene}: no engine has an error in phase {}", i + 1)
                })
        })
        .collect()
}

/// The study's proposal: the stiff-motor engine until the phase in which
/// the real cube starts to move, the contact engine from it on.
fn proposed_plan(scene: &Scene, report: &SceneReport, opts: &StitchOptions) -> Vec<String> {
    let onset = report
        .reference
        .cube
        .as_ref()
        .and_then(|c| c.contact_onset_s);
    let phases = phase_ticks(scene);
    let period = scene.controller.period_s;
    phases
        .iter()
        .map(|&(_, end)| match onset {
            Some(t) if t < end as f64 * period => opts.contact_engine.clone(),
            _ => opts.stiff_engine.clone(),
        })
        .collect()
}

fn score(s: &SourceSummary) -> Score {
    Score {
        error_m: s.accumulated_error_m,
        interval_m: s.accumulated_error_interval_m,
        phase_errors_m: s.phase_errors_m.clone(),
        cube_displacement_m: s.cube.as_ref().map(|c| c.final_displacement_m),
    }
}

/// One scene's rows and comparisons from its training and held-out
/// reports.
fn scene_outcome(
    study: &Study,
    taking: &Taking,
    (train, held): (&SceneReport, Option<&SceneReport>),
    roles: &[(String, Vec<String>)],
    contact_onset_s: Option<f64>,
) -> Result<SceneStitch> {
    let plan_of = |role: &str| {
        roles
            .iter()
            .find(|(r, _)| r == role)
            .map(|(_, p)| p.clone())
            .unwrap_or_default()
    };
    let (automatic, proposed) = (plan_of("automatic"), plan_of("proposed"));
    let scene = train.scene.clone();
    let summary =
        |r: &SceneReport, name: &str| r.sources.iter().find(|s| s.source == name).cloned();
    let mut rows = Vec::new();
    let mut entries: Vec<(String, String, Vec<String>)> = Vec::new();
    for (list, role) in [
        (&taking.candidates, "engine"),
        (&taking.physics_free, "physics-free"),
    ] {
        for e in list {
            if let Some(name) = engine_source_name(study, &scene, e) {
                entries.push((name, role.into(), vec![e.clone(); automatic.len()]));
            }
        }
    }
    for (role, plan) in roles {
        let p = StitchPlan {
            engines: plan.clone(),
        };
        let name = p.display_name(plan.len())?;
        if !entries.iter().any(|(n, _, _)| *n == name) {
            entries.push((name, role.clone(), plan.clone()));
        }
    }
    for (source, role, plan) in entries {
        let Some(t) = summary(train, &source) else {
            continue;
        };
        rows.push(Row {
            training: score(&t),
            held_out: held.and_then(|h| summary(h, &source)).map(|s| score(&s)),
            source,
            role,
            plan,
        });
    }
    let versus = |r: &SceneReport| -> Vec<Versus> {
        let singles: Vec<&SourceSummary> = rows
            .iter()
            .filter(|row| row.role == "engine")
            .filter_map(|row| r.sources.iter().find(|s| s.source == row.source))
            .collect();
        let plans: Vec<&SourceSummary> = rows
            .iter()
            .filter(|row| row.role != "engine" && row.role != "physics-free")
            .filter_map(|row| r.sources.iter().find(|s| s.source == row.source))
            .collect();
        plans
            .iter()
            .filter_map(|p| against_best(p, &singles))
            .collect()
    };
    let versus_physics_free = |r: &SceneReport| -> Vec<AgainstPhysicsFree> {
        let of = |physics_free: bool| -> Vec<&SourceSummary> {
            rows.iter()
                .filter(|row| (row.role == "physics-free") == physics_free)
                .filter_map(|row| r.sources.iter().find(|s| s.source == row.source))
                .collect()
        };
        let Some(closest) = closest(&of(false)) else {
            return Vec::new();
        };
        of(true)
            .into_iter()
            .filter_map(|free| {
                let (gain_m, gain_interval_m, probability_better) = gain(closest, free)?;
                Some(AgainstPhysicsFree {
                    physics_free: free.source.clone(),
                    closest: closest.source.clone(),
                    gain_m,
                    gain_interval_m,
                    probability_better,
                })
            })
            .collect()
    };
    Ok(SceneStitch {
        real_cube_displacement_m: train
            .reference
            .cube
            .as_ref()
            .map(|c| c.final_displacement_m),
        phases_s: train.phases_s.clone(),
        contact_onset_s,
        training_versus: versus(train),
        held_out_versus: held.map(versus).unwrap_or_default(),
        training_versus_physics_free: versus_physics_free(train),
        held_out_versus_physics_free: held.map(versus_physics_free).unwrap_or_default(),
        scene,
        automatic,
        proposed,
        rows,
    })
}

/// A plan against the single engine with the smallest error, over the
/// paired bootstrap replicates.
fn against_best(plan: &SourceSummary, singles: &[&SourceSummary]) -> Option<Versus> {
    let best = closest(singles)?;
    let (gain_m, gain_interval_m, probability_better) = gain(plan, best)?;
    Some(Versus {
        plan: plan.source.clone(),
        best_single: best.source.clone(),
        gain_m,
        gain_interval_m,
        probability_better,
    })
}

/// The source with the smallest finite accumulated error.
fn closest<'a>(sources: &[&'a SourceSummary]) -> Option<&'a SourceSummary> {
    sources
        .iter()
        .copied()
        .filter(|s| s.accumulated_error_m.is_some_and(f64::is_finite))
        .min_by(|a, b| {
            a.accumulated_error_m
                .partial_cmp(&b.accumulated_error_m)
                .unwrap_or(std::cmp::Ordering::Equal)
        })
}

/// `other`'s error minus `source`'s (positive: `source` is closer), the
/// interval of that difference over the paired bootstrap replicates, and
/// the probability that `source` is closer.
fn gain(source: &SourceSummary, other: &SourceSummary) -> Option<(f64, Option<Interval>, f64)> {
    let (p, b) = (source.accumulated_error_m?, other.accumulated_error_m?);
    let c: Option<PairedComparison> = paired(
        (&source.source, p, &source.bootstrap_replicates_m),
        (&other.source, b, &other.bootstrap_replicates_m),
        0.95,
    );
    Some((
        b - p,
        c.as_ref().and_then(|c| c.difference_interval_m),
        c.map_or(f64::NAN, |c| c.probability_closer),
    ))
}

fn fmt_score(s: Option<&Score>) -> String {
    match s.and_then(|s| s.error_m.map(|e| (e, s.interval_m))) {
        Some((e, i)) => format!("{e:.3} {}", fmt_interval(i)),
        None => "n/a".into(),
    }
}

fn fmt_phases(s: &Score) -> String {
    s.phase_errors_m
        .iter()
        .map(|v| format!("{v:.3}"))
        .collect::<Vec<_>>()
        .join(" / ")
}

/// The plain answer in one scene: does a plan beat the best single
/// engine on the held-out runs (else the training runs)?
pub fn answer(s: &SceneStitch) -> String {
    let (versus, runs) = if s.held_out_versus.is_empty() {
        (&s.training_versus, "training")
    } else {
        (&s.held_out_versus, "held-out")
    };
    let single = s
        .automatic
        .first()
        .filter(|e| s.automatic.iter().all(|x| x == *e));
    let prefix = match single {
        Some(e) => format!(
            "{}: the automatic plan is {e} in every phase (no phase is closer in another engine on the training runs)",
            s.scene
        ),
        None => format!("{}: the automatic plan is {}", s.scene, s.automatic.join(">")),
    };
    // The plans that hand over between different engines.
    let mixes = |v: &&Versus| {
        s.rows
            .iter()
            .find(|r| r.source == v.plan)
            .is_some_and(|r| r.plan.iter().any(|e| *e != r.plan[0]))
    };
    let best = versus
        .iter()
        .filter(mixes)
        .filter(|v| v.gain_m.is_finite())
        .max_by(|a, b| a.gain_m.total_cmp(&b.gain_m));
    let stitching = match best {
        Some(v) if v.gain_interval_m.is_some_and(|i| i.low_m > 0.0) => format!(
            "{prefix}; stitching beats the best single engine ({}) on the {runs} runs: {} is closer by {:.3} m {} (probability {:.3}).",
            v.best_single, v.plan, v.gain_m, fmt_interval(v.gain_interval_m), v.probability_better
        ),
        Some(v) => format!(
            "{prefix}; no plan mixing engines beats the best single engine ({}) on the {runs} runs: the best, {}, gains {:.3} m {} (probability {:.3} that it is closer).",
            v.best_single, v.plan, v.gain_m, fmt_interval(v.gain_interval_m), v.probability_better
        ),
        None => format!("{prefix}; no plan mixing engines was scored."),
    };
    let free = if s.held_out_versus_physics_free.is_empty() {
        &s.training_versus_physics_free
    } else {
        &s.held_out_versus_physics_free
    };
    let mut text = stitching;
    for v in free {
        let verdict = match v.gain_interval_m {
            Some(i) if i.low_m > 0.0 => "beats",
            Some(i) if i.high_m < 0.0 => "is further from the real arm than",
            _ => "cannot be told from",
        };
        text += &format!(
            " The closest source, {}, {verdict} {} (gain {:.3} m {}, probability {:.3} that it is closer).",
            v.closest,
            v.physics_free,
            v.gain_m,
            fmt_interval(v.gain_interval_m),
            v.probability_better
        );
    }
    text
}

/// The report's section on stitching: the answer per scene and the table
/// of every engine and plan.
pub fn report_section(result: &StitchStudy) -> ExtraSection {
    let mut rows = Vec::new();
    for s in &result.scenes {
        for r in &s.rows {
            let gain = s
                .held_out_versus
                .iter()
                .chain(&s.training_versus)
                .find(|v| v.plan == r.source)
                .map_or(String::new(), |v| {
                    format!(
                        "{:.3} {} (p {:.3})",
                        v.gain_m,
                        fmt_interval(v.gain_interval_m),
                        v.probability_better
                    )
                });
            rows.push(vec![
                s.scene.clone(),
                r.source.clone(),
                r.role.clone(),
                fmt_score(Some(&r.training)),
                fmt_score(r.held_out.as_ref()),
                gain,
                r.training
                    .cube_displacement_m
                    .map_or("-".into(), |d| format!("{d:.3}")),
            ]);
        }
    }
    let mut paragraphs = vec![format!(
        "Each phase of a scene simulated in the engine closest to the real arm in that phase on the training runs ({}), the state handed over at the phase boundaries; the study's proposed plan (stiff motors for free motion, MuJoCo from the phase the real cube starts to move) and any plan given with --plan beside it. Scored on the training runs and on the held-out runs ({}): accumulated wrist error, metres, 95 % bootstrap intervals; gain: best single engine's error minus the plan's on the held-out runs (positive: the plan is closer), with the probability that the plan is closer. The physics-free rows are baselines: each scene says whether its closest engine or plan beats them.",
        result.training_runs,
        result.held_out_runs.as_deref().unwrap_or("none")
    )];
    paragraphs.extend(result.scenes.iter().map(answer));
    ExtraSection {
        id: "stitching".into(),
        title: "Stitching engines per phase".into(),
        lead: Vec::new(),
        paragraphs,
        header: [
            "Scene",
            "Source",
            "Role",
            "Training",
            "Held out",
            "Gain (held out)",
            "Cube moved (m)",
        ]
        .map(String::from)
        .to_vec(),
        rows,
        figures: Vec::new(),
        replay: Vec::new(),
    }
}

/// The Markdown table of the outcome.
pub fn markdown(result: &StitchStudy) -> String {
    let mut md = format!(
        "# Stitched engines against single engines\n\nStudy {}; plans chosen on the training runs ({}); scored on the training runs and on the held-out runs ({}). Accumulated error of the mean wrist, metres, with 95 % bootstrap intervals. The physics-free rows (perfect tracking of the commands, and behind a tune's fitted actuator stage) are baselines, never a phase's engine: a simulation that does not beat them adds nothing to kinematics.\n",
        result.study,
        result.training_runs,
        result.held_out_runs.as_deref().unwrap_or("none")
    );
    md += "\n";
    for s in &result.scenes {
        md += &format!("- {}\n", answer(s));
    }
    for s in &result.scenes {
        md += &format!(
            "\n## {}\n\nPhases start at {:?} s; the real cube moves from {} ({} in all). Automatic plan: {}; proposed plan: {}.\n\n| Source | Role | Training | Per phase (training) | Held out | Cube moved (m) |\n|---|---|---:|---:|---:|---:|\n",
            s.scene,
            s.phases_s,
            s.contact_onset_s.map_or("never".into(), |t| format!("{t:.2} s")),
            s.real_cube_displacement_m.map_or("no cube".into(), |d| format!("{d:.3} m")),
            s.automatic.join(">"),
            s.proposed.join(">")
        );
        for r in &s.rows {
            md += &format!(
                "| {} | {} | {} | {} | {} | {} |\n",
                r.source,
                r.role,
                fmt_score(Some(&r.training)),
                fmt_phases(&r.training),
                fmt_score(r.held_out.as_ref()),
                r.training
                    .cube_displacement_m
                    .map_or("-".into(), |d| format!("{d:.3}"))
            );
        }
        md += "\n";
        for (what, list, free) in [
            (
                "training",
                &s.training_versus,
                &s.training_versus_physics_free,
            ),
            (
                "held-out",
                &s.held_out_versus,
                &s.held_out_versus_physics_free,
            ),
        ] {
            for v in list {
                md += &format!(
                    "- {what}: {} vs the best single engine {}: gain {:.3} m {} (probability {:.3} that the plan is closer)\n",
                    v.plan,
                    v.best_single,
                    v.gain_m,
                    fmt_interval(v.gain_interval_m),
                    v.probability_better
                );
            }
            for v in free {
                md += &format!(
                    "- {what}: the closest source {} vs {}: gain {:.3} m {} (probability {:.3} that the simulation is closer)\n",
                    v.closest,
                    v.physics_free,
                    v.gain_m,
                    fmt_interval(v.gain_interval_m),
                    v.probability_better
                );
            }
        }
    }
    md
}

fn write_outputs(out: &Path, result: &StitchStudy) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let md = out.join("stitch.md");
    std::fs::write(&md, markdown(result))
        .with_context(|| format!("cannot write {}", md.display()))?;
    let json = out.join("stitch.json");
    std::fs::write(&json, serde_json::to_string_pretty(result)? + "\n")
        .with_context(|| format!("cannot write {}", json.display()))
}
