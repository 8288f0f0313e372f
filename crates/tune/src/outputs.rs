//! After the search: the sensitivity of the objective to each parameter,
//! the untuned and the tuned engine scored on the training and held-out
//! runs with bootstrap intervals, and the files of `--out`:
//! `tuned.toml`, `registration.json`, `summary.json`, `summary.md` and
//! `convergence.svg`/`.png` (`history.csv` is written by the search).

use crate::objective::score_of;
use crate::search::SearchEnd;
use crate::space::{Dim, Scale};
use crate::Tuner;
use anyhow::{anyhow, Context, Result};
use rayon::prelude::*;
use realitygap_analysis::bootstrap::BootstrapOptions;
use realitygap_analysis::compare::{RegistrationChoice, SceneReport};
use realitygap_analysis::registration::Registration;
use realitygap_analysis::selection::RunSelection;
use realitygap_core::params::PhysicalParams;
use realitygap_report::convergence::{ConvergenceFigure, ConvergencePoint};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// How far each parameter moves from the optimum in the sensitivity
/// table, as a fraction of its value.
pub const SENSITIVITY_STEP: f64 = 0.10;

/// Bootstrap resamples of the final scores' intervals.
pub const RESAMPLES: usize = 1000;

/// The physics-free engine: perfect tracking of the commands through
/// forward kinematics, behind the actuator stage when one is given.
pub const PHYSICS_FREE: &str = "ideal";

/// The folder, inside a tune's `--out`, of its fitted physics-free row
/// (the physics-free model behind the fitted actuator stage).
pub const PHYSICS_FREE_DIR: &str = "physics-free-actuator";

/// The physics-free model behind its own actuator stage, fitted on the
/// tune's training runs.
pub struct Baseline {
    simulator: crate::objective::Simulator,
    params: PhysicalParams,
    registration: Registration,
    /// What the summary says of it.
    pub summary: BaselineSummary,
}

/// The fitted physics-free model in `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineSummary {
    /// Its folder (`OUT/physics-free-actuator`: history and parameters).
    pub folder: String,
    /// Its objective on the training runs, metres.
    pub objective_m: f64,
    /// Evaluations: search and polish.
    pub evaluations: usize,
    /// The fitted values with their 95 % intervals.
    pub parameters: Vec<crate::polish::ParamInterval>,
}

impl Baseline {
    /// The baseline of a fit of the physics-free engine with `spec`.
    pub fn new(
        target: &crate::objective::Target,
        simulator: &crate::objective::Simulator,
        spec: &crate::TuneSpec,
        fitted: crate::Fitted,
    ) -> Result<Baseline> {
        let pspec = fitted.polished_spec(spec);
        let t = Tuner {
            target,
            simulator,
            spec: &pspec,
        };
        let u = &fitted.polished.u;
        let params = t.params(u).map_err(|m| anyhow!(m))?;
        let registration = t.registration(u);
        let text = format!(
            "# The physics-free model behind its fitted actuator stage (realitygap tune).\n\n{}",
            params.to_toml_string()
        );
        let file = spec.out.join("tuned.toml");
        std::fs::write(&file, text).with_context(|| format!("writing {}", file.display()))?;
        std::fs::write(spec.out.join("registration.json"), registration.to_json())
            .with_context(|| format!("writing {}", spec.out.display()))?;
        let summary = BaselineSummary {
            folder: spec.out.display().to_string(),
            objective_m: fitted.polished.objective_m,
            evaluations: fitted.end.history.len() + fitted.polished.report.evaluations,
            parameters: fitted.polished.report.intervals.clone(),
        };
        // What `reproduce --tuned` reads: the engine and tuned.toml.
        let mut json = serde_json::to_value(&summary)?;
        json["engine"] = serde_json::json!(PHYSICS_FREE);
        let file = spec.out.join("summary.json");
        std::fs::write(&file, serde_json::to_string_pretty(&json)? + "\n")
            .with_context(|| format!("writing {}", file.display()))?;
        Ok(Baseline {
            simulator: simulator.clone(),
            params,
            registration,
            summary,
        })
    }
}

/// A physics-free row of a comparison.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineRow {
    /// `physics-free` or `physics-free + actuator (fitted)`.
    pub source: String,
    /// Its total, with the interval.
    pub total: Option<Scored>,
    /// Per scene, in study order.
    pub scenes: Vec<Option<Scored>>,
    /// The tuned engine's total minus this row's: value and 95 % paired
    /// bootstrap interval (negative: the tuned engine is closer).
    pub tuned_minus_m: Option<[f64; 3]>,
}

/// One parameter's result.
#[derive(Debug, Clone, Serialize)]
pub struct ParamResult {
    /// Key.
    pub key: String,
    /// Lower bound.
    pub low: f64,
    /// Upper bound.
    pub high: f64,
    /// Scale.
    pub scale: Scale,
    /// Where the search started.
    pub start: f64,
    /// The value found.
    pub value: f64,
    /// True when the value is within 1 % of the range from a bound.
    pub at_bound: bool,
}

/// The objective's rise when one parameter moves ±10 % from the optimum.
#[derive(Debug, Clone, Serialize)]
pub struct Sensitivity {
    /// Key.
    pub key: String,
    /// The optimum value.
    pub value: f64,
    /// The values tried (clamped to the bounds).
    pub tried: [f64; 2],
    /// The objectives there, metres.
    pub objectives_m: [f64; 2],
    /// The larger rise over the optimum, metres (negative: the optimum
    /// was not a minimum along this axis).
    pub rise_m: f64,
}

/// An accumulated error with its interval.
#[derive(Debug, Clone, Serialize)]
pub struct Scored {
    /// Metres.
    pub value_m: f64,
    /// 95 % bootstrap interval over the real runs, metres.
    pub interval_m: Option<[f64; 2]>,
}

/// One scene's untuned and tuned scores on one set of runs.
#[derive(Debug, Clone, Serialize)]
pub struct SceneComparison {
    /// Scene.
    pub scene: String,
    /// The untuned engine's accumulated error.
    pub untuned: Option<Scored>,
    /// The tuned engine's.
    pub tuned: Option<Scored>,
    /// The cube's final position error (distance), untuned and tuned,
    /// metres.
    pub cube_final_m: Option<[Option<f64>; 2]>,
    /// The cube's final displacement (m) and largest rotation change
    /// (degrees): real, untuned, tuned.
    pub cube_push: Option<[Option<[f64; 2]>; 3]>,
}

/// Untuned against tuned on one set of runs.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// The runs scored, e.g. `1-15`, or `all`.
    pub runs: String,
    /// Per scene.
    pub scenes: Vec<SceneComparison>,
    /// Sum over scenes of the accumulated error, untuned and tuned, with
    /// intervals (replicates summed across scenes).
    pub total_untuned: Option<Scored>,
    /// The tuned total.
    pub total_tuned: Option<Scored>,
    /// The objective (accumulated errors plus weighted cube error),
    /// untuned and tuned, metres.
    pub objective_m: [f64; 2],
    /// The physics-free rows.
    pub baselines: Vec<BaselineRow>,
    /// Per scene, where in time each source's error lies: its error per
    /// phase of the schedule, and (not serialised) its error against time.
    pub phases: Vec<ScenePhases>,
}

/// One scene's errors by phase and against time, per source.
#[derive(Debug, Clone, Serialize)]
pub struct ScenePhases {
    /// Scene.
    pub scene: String,
    /// Start times of the schedule's phases, s (the first is 0).
    pub phases_s: Vec<f64>,
    /// Step times, s.
    #[serde(skip)]
    pub t_s: Vec<f64>,
    /// `untuned`, `tuned`, then the physics-free rows.
    pub sources: Vec<SourcePhases>,
}

/// One source's share of [`ScenePhases`].
#[derive(Debug, Clone, Serialize)]
pub struct SourcePhases {
    /// The source, as the comparison names it.
    pub source: String,
    /// Accumulated wrist error per phase, metres (they sum to the
    /// scene's).
    pub phase_errors_m: Vec<f64>,
    /// Per step, the mean wrist's distance to the real mean wrist, m.
    #[serde(skip)]
    pub distance_m: Vec<Option<f64>>,
    /// Per step, the mean wrist's height minus the real mean wrist's, m
    /// (negative: below the real arm's wrist).
    #[serde(skip)]
    pub height_m: Vec<Option<f64>>,
}

impl SourcePhases {
    /// The source `name`'s measures in the scene report `r` (its first
    /// source), or `None` when it was not measured.
    fn of(name: &str, r: &SceneReport) -> Option<SourcePhases> {
        let s = r.sources.first()?;
        s.accumulated_error_m?;
        let real = &r.reference.series.wrist_mean_m;
        let height_m = s
            .series
            .wrist_mean_m
            .iter()
            .enumerate()
            .map(|(k, w)| Some(w.as_ref()?[2] - real.get(k)?.as_ref()?[2]))
            .collect();
        Some(SourcePhases {
            source: name.to_string(),
            phase_errors_m: s.phase_errors_m.clone(),
            distance_m: s.series.wrist_distance_to_reference_m.clone(),
            height_m,
        })
    }
}

/// The scenes' [`ScenePhases`] of the sources `named` (name, its reports).
fn scene_phases(named: &[(&str, &Reports)]) -> Vec<ScenePhases> {
    let Some((_, first)) = named.first() else {
        return Vec::new();
    };
    first
        .reports
        .iter()
        .enumerate()
        .map(|(i, r)| ScenePhases {
            scene: r.scene.clone(),
            phases_s: r.phases_s.clone(),
            t_s: r
                .sources
                .first()
                .map(|s| s.series.t_s.clone())
                .unwrap_or_default(),
            sources: named
                .iter()
                .filter_map(|(name, rep)| SourcePhases::of(name, rep.reports.get(i)?))
                .collect(),
        })
        .collect()
}

/// The tuned parameters simulated again at half the tuned timestep and
/// scored on the same runs (the held-out ones, else the training ones):
/// does the fit describe the arm, or also the integration at that step?
#[derive(Debug, Clone, Serialize)]
pub struct TimestepCheck {
    /// The engine's `timestep_s` the tune ran at.
    pub timestep_s: f64,
    /// Half of it, the step of the check.
    pub halved_s: f64,
    /// The runs scored, e.g. `16-20`.
    pub runs: String,
    /// The tuned total at the tuned timestep.
    pub tuned: Option<Scored>,
    /// The tuned total at half the timestep (`None`: a scene could not be
    /// simulated or scored there, see `failed`).
    pub halved: Option<Scored>,
    /// The total at half the timestep minus the tuned total: value and 95 %
    /// paired bootstrap interval over the same runs.
    pub halved_minus_m: Option<[f64; 3]>,
    /// The real runs' noise of the training objective at the optimum (the
    /// polish's), metres: the size of a change that matters.
    pub noise_m: Option<f64>,
    /// Whether the fit holds at half the step: the difference's interval
    /// covers zero or the difference is within the noise.
    pub holds: Option<bool>,
    /// Why there is no score at half the step, if there is none.
    pub failed: Option<String>,
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Engine.
    pub engine: String,
    /// The space file.
    pub space: String,
    /// Keys of the space file held at the scenes' own values, not searched
    /// (the objects' and the contact's when the objective does not weigh
    /// the cube).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<String>,
    /// Engine settings every evaluation ran at.
    pub settings: Vec<(String, String)>,
    /// The objective, in words.
    pub objective: String,
    /// Where the search started, in words (`--start`).
    pub start: String,
    /// Seed, budget, jobs.
    pub seed: u64,
    /// Evaluations asked for.
    pub budget: usize,
    /// Parallel evaluations.
    pub jobs: usize,
    /// Evaluations made (replayed ones included).
    pub evaluations: usize,
    /// Evaluations replayed from an earlier run.
    pub replayed: usize,
    /// Evaluations that failed (diverged, crashed).
    pub failed: usize,
    /// Why the search stopped.
    pub stop: String,
    /// Wall time of this command, seconds.
    pub wall_time_s: f64,
    /// Evaluations made (not replayed) in this command per wall second;
    /// `None` when every evaluation was replayed.
    pub evaluations_per_s: Option<f64>,
    /// Evaluations until the best objective was within 5 % of the final
    /// best.
    pub evaluations_to_5pct: Option<usize>,
    /// The best objective found on the training runs, metres.
    pub best_objective_m: f64,
    /// The parameters found.
    pub parameters: Vec<ParamResult>,
    /// The registration used by the tuned engine (capture frame to world).
    pub registration: RegistrationSummary,
    /// Sensitivity, largest rise first.
    pub sensitivity: Vec<Sensitivity>,
    /// Untuned against tuned on the training runs.
    pub training: Comparison,
    /// Untuned against tuned on the held-out runs.
    pub holdout: Option<Comparison>,
    /// The identifiability check before the search.
    pub identifiability_before: Option<crate::polish::IdentifiabilityReport>,
    /// The least-squares polish, with the intervals and the
    /// identifiability at the optimum.
    pub polish: crate::polish::PolishReport,
    /// The physics-free model behind its fitted actuator stage.
    pub baseline: Option<BaselineSummary>,
    /// The answer in words: does the tuned engine beat the physics-free
    /// rows on the held-out runs (on the training runs without)?
    pub verdict: String,
    /// The tuned parameters at half the timestep (`None`: the settings
    /// name no `timestep_s`, so each scene kept its own).
    pub timestep_check: Option<TimestepCheck>,
}

/// The registrations of a tune.
#[derive(Debug, Clone, Serialize)]
pub struct RegistrationSummary {
    /// True when the registration was fitted with the parameters.
    pub fitted: bool,
    /// The measurement's estimate (the untuned engine's registration).
    pub estimate_rotation_wxyz: [f64; 4],
    /// Its translation, m.
    pub estimate_translation_m: [f64; 3],
    /// The tuned engine's.
    pub tuned_rotation_wxyz: [f64; 4],
    /// Its translation, m.
    pub tuned_translation_m: [f64; 3],
    /// Angle between the two, degrees.
    pub moved_deg: f64,
    /// Distance between the two translations, mm.
    pub moved_mm: f64,
}

fn registration_summary(
    fitted: bool,
    base: &Registration,
    tuned: &Registration,
) -> RegistrationSummary {
    let q = |r: &Registration| [r.rotation.w, r.rotation.x, r.rotation.y, r.rotation.z];
    RegistrationSummary {
        fitted,
        estimate_rotation_wxyz: q(base),
        estimate_translation_m: base.translation_m.to_array(),
        tuned_rotation_wxyz: q(tuned),
        tuned_translation_m: tuned.translation_m.to_array(),
        moved_deg: base.rotation.angle_to(tuned.rotation).to_degrees(),
        moved_mm: base.translation_m.distance(tuned.translation_m) * 1000.0,
    }
}

/// The sensitivity of the objective around the optimum `u`.
pub(crate) fn sensitivity(tuner: &Tuner<'_>, u: &[f64], best: f64) -> Vec<Sensitivity> {
    let dims = &tuner.spec.space.dims;
    let optimum = tuner.spec.space.values(u);
    let jobs: Vec<(usize, usize, f64)> = dims
        .iter()
        .enumerate()
        .flat_map(|(i, d)| {
            let v = optimum[i];
            let step = if v != 0.0 {
                SENSITIVITY_STEP * v.abs()
            } else {
                SENSITIVITY_STEP * (d.high - d.low)
            };
            [
                (i, 0, (v - step).clamp(d.low, d.high)),
                (i, 1, (v + step).clamp(d.low, d.high)),
            ]
        })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(tuner.spec.search.jobs.max(1))
        .build();
    let run = || -> Vec<f64> {
        jobs.par_iter()
            .map(|&(i, _, v)| {
                // The search's own objective (with the pull toward the
                // physics-free fit, when asked), so that the probe compares
                // like with like.
                let mut x = u.to_vec();
                x[i] = dims[i].unit(v);
                tuner.evaluate(&x).objective
            })
            .collect()
    };
    let objectives = match pool {
        Ok(p) => p.install(run),
        Err(_) => run(),
    };
    let mut out: Vec<Sensitivity> = dims
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let o = [objectives[2 * i], objectives[2 * i + 1]];
            Sensitivity {
                key: d.key.clone(),
                value: optimum[i],
                tried: [jobs[2 * i].2, jobs[2 * i + 1].2],
                objectives_m: o,
                rise_m: o[0].max(o[1]) - best,
            }
        })
        .collect();
    out.sort_by(|a, b| b.rise_m.total_cmp(&a.rise_m));
    out
}

/// Scores of one source (per scene reports) for the comparison.
struct Reports {
    reports: Vec<SceneReport>,
}

fn scored(r: &SceneReport) -> Option<Scored> {
    let s = r.sources.first()?;
    Some(Scored {
        value_m: s.accumulated_error_m?,
        interval_m: s.accumulated_error_interval_m.map(|i| [i.low_m, i.high_m]),
    })
}

fn total(reports: &Reports) -> Option<Scored> {
    total_with_replicates(reports).map(|x| x.0)
}

fn total_with_replicates(reports: &Reports) -> Option<(Scored, Vec<f64>)> {
    let (value, reps) = summed(&reports.reports)?;
    let interval_m = realitygap_analysis::bootstrap::percentile_interval(
        &reps,
        BootstrapOptions::default().level,
    )
    .map(|i| [i.low_m, i.high_m]);
    Some((
        Scored {
            value_m: value,
            interval_m,
        },
        reps,
    ))
}

/// The accumulated error of one source's reports summed over the scenes,
/// with its bootstrap replicates summed replicate by replicate (empty
/// when the scenes' replicates do not pair up).
pub(crate) fn summed(reports: &[SceneReport]) -> Option<(f64, Vec<f64>)> {
    let mut value = 0.0;
    let mut reps: Vec<f64> = Vec::new();
    for r in reports {
        let s = r.sources.first()?;
        value += s.accumulated_error_m?;
        if reps.is_empty() {
            reps = s.bootstrap_replicates_m.clone();
        } else if reps.len() == s.bootstrap_replicates_m.len() {
            for (a, b) in reps.iter_mut().zip(&s.bootstrap_replicates_m) {
                *a += b;
            }
        } else {
            reps.clear();
        }
    }
    Some((value, reps))
}

/// The physics-free row `source` of `base`, against the tuned engine's
/// `tuned` on the same runs (paired: the same resamples of the real runs).
fn baseline_row(source: &str, base: &Reports, tuned: &Reports) -> BaselineRow {
    let b = total_with_replicates(base);
    let t = total_with_replicates(tuned);
    let diff = match (&b, &t) {
        (Some((bs, br)), Some((ts, tr))) if br.len() == tr.len() && !br.is_empty() => {
            let d: Vec<f64> = tr.iter().zip(br).map(|(x, y)| x - y).collect();
            realitygap_analysis::bootstrap::percentile_interval(
                &d,
                BootstrapOptions::default().level,
            )
            .map(|i| [ts.value_m - bs.value_m, i.low_m, i.high_m])
        }
        _ => None,
    };
    BaselineRow {
        source: source.to_string(),
        total: b.map(|x| x.0),
        scenes: base.reports.iter().map(scored).collect(),
        tuned_minus_m: diff,
    }
}

fn cube_push(r: &SceneReport) -> Option<[f64; 2]> {
    let c = r.sources.first()?.cube.as_ref()?;
    let rot = c.rpy_change_deg.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    Some([c.final_displacement_m, rot])
}

fn comparison(tuner: &Tuner<'_>, untuned: &Reports, tuned: &Reports, runs: String) -> Comparison {
    let scenes = tuner.target.scenes.iter().enumerate().map(|(i, s)| {
        let u = &untuned.reports[i];
        let t = &tuned.reports[i];
        let cube = |r: &SceneReport| {
            score_of(std::slice::from_ref(r), std::slice::from_ref(s))
                .scenes
                .first()
                .and_then(|x| x.cube_final_m)
        };
        let real = t.reference.cube.as_ref().map(|c| {
            [
                c.final_displacement_m,
                c.rpy_change_deg.iter().fold(0.0f64, |m, x| m.max(x.abs())),
            ]
        });
        SceneComparison {
            scene: s.name.clone(),
            untuned: scored(u),
            tuned: scored(t),
            cube_final_m: s.cube.then(|| [cube(u), cube(t)]),
            cube_push: s.cube.then(|| [real, cube_push(u), cube_push(t)]),
        }
    });
    Comparison {
        runs,
        scenes: scenes.collect(),
        total_untuned: total(untuned),
        total_tuned: total(tuned),
        objective_m: [
            score_of(&untuned.reports, &tuner.target.scenes).objective,
            score_of(&tuned.reports, &tuner.target.scenes).objective,
        ],
        baselines: Vec::new(),
        phases: Vec::new(),
    }
}

/// The untuned engine's parameters: the space's engine settings only.
fn untuned_params(tuner: &Tuner<'_>) -> PhysicalParams {
    let mut p = PhysicalParams::none();
    let mut s = tuner
        .spec
        .space
        .settings
        .get(&tuner.spec.engine)
        .cloned()
        .unwrap_or_default();
    s.extend(tuner.spec.set.iter().map(|(k, v)| (k.clone(), v.clone())));
    if !s.is_empty() {
        p.engine_settings.insert(tuner.spec.engine.clone(), s);
    }
    p
}

/// The source `name` (its trajectories `trajs`) scored on `selection`
/// under `registration` (`origin` says whose), with the final scores'
/// bootstrap intervals.
fn score_source(
    tuner: &Tuner<'_>,
    name: &str,
    trajs: Vec<realitygap_core::Trajectory>,
    registration: Registration,
    origin: &str,
    selection: &RunSelection,
) -> Result<Reports> {
    let t = tuner.target;
    let reports = t.evaluate(
        &t.sources(name, trajs),
        RegistrationChoice::Given {
            registration,
            origin: origin.into(),
        },
        selection,
        Some(RESAMPLES),
    )?;
    Ok(Reports { reports })
}

fn evaluate_both(
    tuner: &Tuner<'_>,
    untuned: &[realitygap_core::Trajectory],
    tuned: &[realitygap_core::Trajectory],
    registration: &Registration,
    selection: &RunSelection,
) -> Result<(Reports, Reports)> {
    let base = tuner.target.base_registration;
    let u = score_source(
        tuner,
        "untuned",
        untuned.to_vec(),
        base,
        "the measurement's estimate",
        selection,
    )?;
    let v = score_source(
        tuner,
        "tuned",
        tuned.to_vec(),
        *registration,
        "tuned",
        selection,
    )?;
    Ok((u, v))
}

fn param_results(dims: &[Dim], values: &[f64]) -> Vec<ParamResult> {
    dims.iter()
        .zip(values)
        .map(|(d, &v)| ParamResult {
            key: d.key.clone(),
            low: d.low,
            high: d.high,
            scale: d.scale,
            start: d.start,
            value: v,
            at_bound: d.unit(v) < 0.01 || d.unit(v) > 0.99,
        })
        .collect()
}

/// Evaluations until the running best came within 5 % of the final best.
fn to_within_5pct(end: &SearchEnd, best: f64) -> Option<usize> {
    let mut running = f64::INFINITY;
    for (i, e) in end.history.iter().enumerate() {
        if e.failed.is_none() {
            running = running.min(e.objective);
        }
        if running <= best * 1.05 {
            return Some(i + 1);
        }
    }
    None
}

/// Scores of the physics-free rows (`(name, trajectories, registration)`)
/// on `selection`, against the tuned engine's reports there.
/// The comparison of `untuned` and `tuned` on `selection` (its runs
/// named `runs`), with the physics-free `rows` scored on the same runs
/// and every source's errors by phase.
fn compared(
    tuner: &Tuner<'_>,
    (untuned, tuned): (&Reports, &Reports),
    rows: &[(String, Vec<realitygap_core::Trajectory>, Registration)],
    selection: &RunSelection,
    runs: String,
) -> Result<Comparison> {
    let mut c = comparison(tuner, untuned, tuned, runs);
    let scored: Vec<Reports> = rows
        .iter()
        .map(|(name, trajs, reg)| score_source(tuner, name, trajs.clone(), *reg, name, selection))
        .collect::<Result<_>>()?;
    c.baselines = rows
        .iter()
        .zip(&scored)
        .map(|((name, _, _), r)| baseline_row(name, r, tuned))
        .collect();
    let mut named: Vec<(&str, &Reports)> = vec![("untuned", untuned), ("tuned", tuned)];
    named.extend(rows.iter().map(|r| r.0.as_str()).zip(&scored));
    c.phases = scene_phases(&named);
    Ok(c)
}

/// The answer in words, on the held-out runs (else the training runs),
/// with a caution first when the tune ended worse than the engine's
/// defaults on the runs it was fitted on.
fn verdict_text(engine: &str, holdout: Option<&Comparison>, training: &Comparison) -> String {
    let [untuned, tuned] = training.objective_m;
    let answer = verdict_answer(engine, holdout.unwrap_or(training));
    if tuned > untuned {
        return format!(
            "Caution: on the runs it was fitted on, the tuned {engine} is worse than its own defaults (objective {tuned:.3} m against {untuned:.3} m untuned): the fit started away from them (the space's start values, or --start physics-free) and did not get back (a small --budget), or a pull (--prior-weight) held it back, and the defaults fit these runs better. {answer}"
        );
    }
    answer
}

/// Does the tuned engine beat the physics-free rows?
fn verdict_answer(engine: &str, c: &Comparison) -> String {
    let Some(tuned) = &c.total_tuned else {
        return format!("The tuned {engine} could not be scored.");
    };
    let on = if c.runs == "all" {
        "On all runs (none held out)".to_string()
    } else {
        format!("On runs {}", c.runs)
    };
    let mut parts = Vec::new();
    for b in &c.baselines {
        let Some([d, lo, hi]) = b.tuned_minus_m else {
            continue;
        };
        let word = if hi < 0.0 {
            "beats"
        } else if lo > 0.0 {
            "does not beat"
        } else {
            "is not distinguishable from"
        };
        parts.push(format!(
            "{word} {} ({:.3} m; tuned minus it {d:+.3} m [{lo:+.3}, {hi:+.3}])",
            b.source,
            b.total.as_ref().map_or(f64::NAN, |s| s.value_m)
        ));
    }
    if parts.is_empty() {
        return format!(
            "{on}, the tuned {engine} scores {:.3} m; no physics-free row was scored.",
            tuned.value_m
        );
    }
    format!(
        "{on}, the tuned {engine} ({:.3} m) {}.",
        tuned.value_m,
        parts.join(", and ")
    )
}

/// Writes every output and returns the summary and the files.
pub fn finish(
    tuner: &Tuner<'_>,
    fitted: &crate::Fitted,
    baseline: Option<&Baseline>,
    started: Instant,
) -> Result<(Summary, Vec<PathBuf>)> {
    let spec = tuner.spec;
    let end = &fitted.end;
    let polished = &fitted.polished;
    let u = polished.u.clone();
    let best_objective = polished.objective_m;
    let params = tuner.params(&u).map_err(|m| anyhow!(m))?;
    let registration = tuner.registration(&u);
    let sens = match &polished.probe {
        Some(p) => p.clone(),
        None => sensitivity(tuner, &u, best_objective),
    };
    realitygap_runner::interrupt::check()?;
    let untuned_p = untuned_params(tuner);
    let sim = |p: &PhysicalParams, what: &str| {
        tuner
            .simulator
            .simulate(&tuner.target.scenes, p)
            .map_err(|m| anyhow!("the {what} engine: {m}"))
    };
    let untuned = sim(&untuned_p, "untuned")?;
    let tuned = sim(&params, "tuned")?;
    // The physics-free rows: perfect tracking under the measurement's
    // registration (estimated against that very model), and behind its
    // fitted actuator stage under its own fitted registration.
    let mut rows = Vec::new();
    if spec.engine != PHYSICS_FREE {
        let free = crate::objective::Simulator {
            engine: PHYSICS_FREE.to_string(),
            ..tuner.simulator.clone()
        };
        let trajs = free
            .simulate(&tuner.target.scenes, &PhysicalParams::none())
            .map_err(|m| anyhow!("the physics-free model: {m}"))?;
        rows.push((
            "physics-free".to_string(),
            trajs,
            tuner.target.base_registration,
        ));
    }
    if let Some(b) = baseline {
        let trajs = b
            .simulator
            .simulate(&tuner.target.scenes, &b.params)
            .map_err(|m| anyhow!("the physics-free model with its actuator stage: {m}"))?;
        rows.push((
            "physics-free + actuator (fitted)".to_string(),
            trajs,
            b.registration,
        ));
    }
    let train_sel = tuner.target.train.clone();
    let (a, b) = evaluate_both(tuner, &untuned, &tuned, &registration, &train_sel)?;
    let runs_text = |r: &Option<realitygap_analysis::selection::RunRange>| {
        r.as_ref().map_or("all".to_string(), |r| r.text.clone())
    };
    let training = compared(
        tuner,
        (&a, &b),
        &rows,
        &train_sel,
        runs_text(&train_sel.runs),
    )?;
    let (holdout, held_out_tuned) = match tuner.target.holdout_selection() {
        Some(sel) => {
            let (a, b) = evaluate_both(tuner, &untuned, &tuned, &registration, &sel)?;
            let c = compared(tuner, (&a, &b), &rows, &sel, runs_text(&sel.holdout))?;
            (Some(c), Some((sel, b)))
        }
        None => (None, None),
    };
    realitygap_runner::interrupt::check()?;
    let noise_m = polished
        .report
        .identifiability
        .as_ref()
        .or(fitted.before.as_ref())
        .and_then(|r| r.noise_m);
    let (check_sel, check_tuned, check_runs) = match &held_out_tuned {
        Some((sel, b)) => (sel, b, runs_text(&sel.holdout)),
        None => (&train_sel, &b, runs_text(&train_sel.runs)),
    };
    let timestep_check = timestep_check(
        tuner,
        &params,
        &registration,
        check_sel,
        check_tuned,
        check_runs,
        noise_m,
    )?;
    let verdict = verdict_text(&spec.engine, holdout.as_ref(), &training);
    let wall = started.elapsed().as_secs_f64();
    let fresh = end.history.len().saturating_sub(end.replayed);
    let settings: Vec<(String, String)> = params
        .engine_settings
        .get(&spec.engine)
        .map(|s| s.iter().map(|(k, v)| (k.clone(), v.to_string())).collect())
        .unwrap_or_default();
    let summary = Summary {
        engine: spec.engine.clone(),
        space: spec.space.source.display().to_string(),
        held: spec.space.held.clone(),
        settings,
        objective: objective_text(tuner),
        start: if spec.start_from_baseline {
            "the physics-free model's fitted actuator stage and registration (--start physics-free; the parameters' `start`)".into()
        } else {
            "the space's start values".into()
        },
        seed: spec.search.seed,
        budget: spec.search.budget,
        jobs: spec.search.jobs,
        evaluations: end.history.len(),
        replayed: end.replayed,
        failed: end.history.iter().filter(|e| e.failed.is_some()).count(),
        stop: end.reason.clone(),
        wall_time_s: wall,
        evaluations_per_s: (fresh > 0)
            .then(|| (fresh + polished.report.evaluations) as f64 / wall.max(1e-9)),
        evaluations_to_5pct: end.best().and_then(|b| to_within_5pct(end, b.objective)),
        best_objective_m: best_objective,
        parameters: param_results(&spec.space.dims, &spec.space.values(&u)),
        registration: registration_summary(
            tuner.fits_registration(),
            &tuner.target.base_registration,
            &registration,
        ),
        sensitivity: sens.clone(),
        training,
        holdout,
        identifiability_before: fitted.before.clone(),
        polish: crate::polish::PolishReport {
            // Whatever the polish saw, the probe reported is the one here.
            probe_clean: polished.report.rounds > 0
                && sens.iter().all(|x| x.rise_m >= -1e-6 * best_objective),
            ..polished.report.clone()
        },
        baseline: baseline.map(|b| b.summary.clone()),
        verdict,
        timestep_check,
    };
    let files = write_files(tuner, end, &summary, &params, &registration)?;
    Ok((summary, files))
}

/// The engine setting a [`TimestepCheck`] halves.
pub use realitygap_core::engine::TIMESTEP_KEY;

/// Simulates the tuned `params` at half their timestep and scores them
/// on `selection` against `tuned` (the same runs at the tuned step).
fn timestep_check(
    tuner: &Tuner<'_>,
    params: &PhysicalParams,
    registration: &Registration,
    selection: &RunSelection,
    tuned: &Reports,
    runs: String,
    noise_m: Option<f64>,
) -> Result<Option<TimestepCheck>> {
    let engine = &tuner.spec.engine;
    let Some(timestep_s) = params
        .engine_settings
        .get(engine)
        .and_then(|s| s.get(TIMESTEP_KEY))
        .and_then(|v| v.as_f64())
    else {
        return Ok(None);
    };
    let halved_s = timestep_s / 2.0;
    let mut half = params.clone();
    if let Some(s) = half.engine_settings.get_mut(engine) {
        s.insert(
            TIMESTEP_KEY.to_string(),
            realitygap_core::engine::SettingValue::Float(halved_s),
        );
    }
    let mut check = TimestepCheck {
        timestep_s,
        halved_s,
        runs,
        tuned: total(tuned),
        halved: None,
        halved_minus_m: None,
        noise_m,
        holds: None,
        failed: None,
    };
    let trajs = match tuner.simulator.simulate(&tuner.target.scenes, &half) {
        Ok(t) => t,
        Err(m) => {
            check.failed = Some(m);
            return Ok(Some(check));
        }
    };
    let t = tuner.target;
    let reports = score_source(tuner, "tuned", trajs, *registration, "tuned", selection)?;
    let unscored: Vec<String> = reports
        .reports
        .iter()
        .zip(&t.scenes)
        .filter(|(r, _)| scored(r).is_none())
        .map(|(r, s)| {
            let why = r
                .sources
                .first()
                .and_then(|x| {
                    x.runs_flagged
                        .iter()
                        .flat_map(|f| &f.flags)
                        .find(|f| f.excludes())
                })
                .map_or("no score".to_string(), |f| f.describe());
            format!("{}: {why}", s.name)
        })
        .collect();
    if !unscored.is_empty() {
        check.failed = Some(unscored.join("; "));
        return Ok(Some(check));
    }
    // The row "tuned" of baseline_row is the halved run: its difference
    // is halved minus tuned.
    let row = baseline_row("halved", tuned, &reports);
    check.halved = total(&reports);
    check.halved_minus_m = row.tuned_minus_m;
    check.holds = row.tuned_minus_m.map(|d| fit_holds(d, noise_m));
    Ok(Some(check))
}

/// Whether a change `[value, low, high]` of the total (metres) leaves a
/// fit as it was: its paired interval covers zero, or it is within the
/// real runs' noise `noise_m`.
fn fit_holds([d, lo, hi]: [f64; 3], noise_m: Option<f64>) -> bool {
    (lo <= 0.0 && hi >= 0.0) || noise_m.is_some_and(|n| d.abs() <= n)
}

/// The timestep check in words.
pub fn timestep_text(c: &TimestepCheck) -> String {
    let at = format!(
        "at half the timestep ({} s instead of {} s)",
        c.halved_s, c.timestep_s
    );
    if let Some(why) = &c.failed {
        return format!(
            "Timestep check: {at} the tuned parameters could not be scored on runs {} ({why}). The fit depends on the timestep: use it at {} s only (tuned.toml carries it).",
            c.runs, c.timestep_s
        );
    }
    let (Some(h), Some([d, lo, hi])) = (&c.halved, c.halved_minus_m) else {
        return format!(
            "Timestep check: {at} the tuned parameters have no total on runs {}.",
            c.runs
        );
    };
    let noise = c.noise_m.map_or(String::new(), |n| {
        format!(", the real runs' noise {n:.2} m")
    });
    let head = format!(
        "Timestep check: {at} the tuned parameters score {:.3} m on runs {} ({d:+.3} m [{lo:+.3}, {hi:+.3}]{noise})",
        h.value_m, c.runs
    );
    if c.holds == Some(true) {
        format!("{head}: the fit holds at a finer step.")
    } else {
        format!(
            "{head}: the fit depends on the timestep, part of it is the integration at {} s. Use it at that step only (tuned.toml carries it), or tune at the step you will run.",
            c.timestep_s
        )
    }
}

/// `randomize.toml`: the fitted parameters' 95 % intervals as ranges for
/// `run --params tuned.toml --perturb randomize.toml`; `None` without
/// intervals (no polish).
fn randomize_toml(tuner: &Tuner<'_>, summary: &Summary) -> Option<String> {
    if summary.polish.intervals.is_empty() {
        return None;
    }
    let mut t = format!(
        "# Domain randomisation from `realitygap tune` ({} on runs {}): each\n\
         # parameter's 95 % interval from the polish's Jacobian. Use it over the\n\
         # tuned parameters:\n\
         #   realitygap run SCENE --engine {} --params tuned.toml \\\n\
         #       --perturb randomize.toml --repeats 20 --out DIR\n\
         # Each repeat draws every key uniformly in its range (in the logarithm\n\
         # for scale = \"log\"). An interval holds the values over which the\n\
         # training objective stays within the real runs' own noise of its optimum,\n\
         # the other parameters refitted (summary.md says which basis was used);\n\
         # where the data do not bound a parameter the range is the whole\n\
         # searched range.\n\n[params]\n",
        tuner.spec.engine, summary.training.runs, tuner.spec.engine
    );
    let mut left_out = Vec::new();
    for d in &tuner.spec.space.dims {
        let Some(i) = summary.polish.intervals.iter().find(|i| i.key == d.key) else {
            continue;
        };
        let [low, high] = i.interval.unwrap_or([d.low, d.high]);
        if high.partial_cmp(&low) != Some(std::cmp::Ordering::Greater) {
            left_out.push(d.key.clone());
            continue;
        }
        let log = d.scale == Scale::Log && low > 0.0;
        t.push_str(&format!(
            "\"{}\" = {{ low = {low:?}, high = {high:?}{}, value = {:?} }}{}\n",
            d.key,
            if log { ", scale = \"log\"" } else { "" },
            i.value,
            if i.interval.is_none() {
                "  # unbounded by the data: the searched range"
            } else {
                ""
            }
        ));
    }
    if !left_out.is_empty() {
        t.push_str(&format!(
            "# Not randomised (a zero-width interval): {}\n",
            left_out.join(", ")
        ));
    }
    Some(t)
}

fn objective_text(tuner: &Tuner<'_>) -> String {
    let cubes: Vec<String> = tuner
        .target
        .scenes
        .iter()
        .filter(|s| s.cube)
        .map(|s| {
            format!(
                "{} x the cube's final pose error in {} (the distance between the final positions plus the turn between the final rotations times half the cube's edge)",
                s.cube_weight, s.name
            )
        })
        .collect();
    let mut t =
        "the accumulated wrist error (m) summed over the scenes, on the training runs".to_string();
    if !cubes.is_empty() {
        t.push_str(&format!(", plus {}", cubes.join(" and ")));
    }
    if tuner.spec.prior_weight > 0.0 && !tuner.spec.prior.is_empty() {
        t.push_str(&format!(
            ", plus {} x the sum of the squared distances of {} keys from the physics-free model's fitted values, each as a fraction of its range (--prior-weight; {})",
            tuner.spec.prior_weight,
            tuner.spec.prior.len(),
            tuner
                .spec
                .prior
                .iter()
                .map(|p| format!("{} {}", p.key, p.centre))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    t
}

fn write_files(
    tuner: &Tuner<'_>,
    end: &SearchEnd,
    summary: &Summary,
    params: &PhysicalParams,
    registration: &Registration,
) -> Result<Vec<PathBuf>> {
    let out = &tuner.spec.out;
    let write = |name: &str, text: String| -> Result<PathBuf> {
        let p = out.join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
        Ok(p)
    };
    let mut files = Vec::new();
    let header = format!(
        "# Tuned by `realitygap tune` for {} on runs {} of the study: objective {:.4} m on them.\n# Use it as it is: realitygap run SCENE --engine {} --params tuned.toml\n\n",
        tuner.spec.engine,
        summary.training.runs,
        summary.best_objective_m,
        tuner.spec.engine
    );
    files.push(write("tuned.toml", header + &params.to_toml_string())?);
    files.push(write("registration.json", registration.to_json())?);
    files.push(write(
        "summary.json",
        serde_json::to_string_pretty(summary)? + "\n",
    )?);
    files.push(write("summary.md", crate::outputs::markdown(summary))?);
    if let Some(text) = randomize_toml(tuner, summary) {
        files.push(write("randomize.toml", text)?);
    }
    let fig = ConvergenceFigure {
        stem: "convergence".into(),
        title: format!("realitygap tune: {}", tuner.spec.engine),
        points: end
            .history
            .iter()
            .map(|e| ConvergencePoint {
                evaluation: e.index,
                objective_m: e.objective,
                failed: e.failed.is_some(),
            })
            .collect(),
        reference: Some((
            format!("untuned, {:.2} m", summary.training.objective_m[0]),
            summary.training.objective_m[0],
        )),
    };
    files.extend(fig.write(out).map_err(|e| anyhow!("{e}"))?);
    Ok(files)
}

fn fmt_interval(i: Option<&crate::polish::ParamInterval>) -> String {
    match i.and_then(|i| i.interval.map(|x| (x, i.clipped))) {
        Some(([a, b], clipped)) => format!(
            "[{a:.6}, {b:.6}]{}",
            if clipped { " (reaches a bound)" } else { "" }
        ),
        None => "none (unseen)".into(),
    }
}

fn fmt_scored(s: &Option<Scored>) -> String {
    match s {
        Some(Scored {
            value_m,
            interval_m: Some([a, b]),
        }) => format!("{value_m:.3} [{a:.3}, {b:.3}]"),
        Some(Scored { value_m, .. }) => format!("{value_m:.3}"),
        None => "n/a".into(),
    }
}

fn comparison_md(c: &Comparison) -> String {
    let mut t =
        "| scene | untuned (m, 95 % interval) | tuned (m, 95 % interval) |\n|---|---|---|\n"
            .to_string();
    for s in &c.scenes {
        t.push_str(&format!(
            "| {} | {} | {} |\n",
            s.scene,
            fmt_scored(&s.untuned),
            fmt_scored(&s.tuned)
        ));
    }
    t.push_str(&format!(
        "| **total** | {} | {} |\n",
        fmt_scored(&c.total_untuned),
        fmt_scored(&c.total_tuned),
    ));
    if !c.baselines.is_empty() {
        t.push_str("\n| physics-free row | total (m, 95 % interval) | tuned minus it (m, 95 % paired interval) |\n|---|---|---|\n");
        for b in &c.baselines {
            t.push_str(&format!(
                "| {} | {} | {} |\n",
                b.source,
                fmt_scored(&b.total),
                b.tuned_minus_m.map_or("n/a".into(), |[d, lo, hi]| format!(
                    "{d:+.3} [{lo:+.3}, {hi:+.3}]"
                ))
            ));
        }
    }
    t.push_str(&format!(
        "\nObjective (with the cube term): untuned {:.3} m, tuned {:.3} m.\n",
        c.objective_m[0], c.objective_m[1]
    ));
    for s in &c.scenes {
        if let Some([real, u, v]) = &s.cube_push {
            let f = |x: &Option<[f64; 2]>| {
                x.map_or("n/a".into(), |[d, r]| format!("{:.3} m, {r:.1} deg", d))
            };
            t.push_str(&format!(
                "\nCube push in {} (final displacement, largest rotation change): real {}, untuned {}, tuned {}.\n",
                s.scene,
                f(real),
                f(u),
                f(v)
            ));
            if let (Some([r, _]), Some([d, _])) = (real, v) {
                if *d > 3.0 * r + 0.05 {
                    t.push_str(&format!(
                        "\n**Warning:** the tuned cube moves {d:.3} m, {:.0} times the real {r:.3} m. The objective sees the cube only through its cube term (`--cube-weight`), so the tuned cube and contact values are not measurements of the real ones; do not reuse them for contact.\n",
                        d / r.max(1e-9)
                    ));
                }
            }
        }
    }
    t
}

/// `summary.md`: the search and the polish, the scores, the parameters
/// with their intervals, the identifiability and the sensitivity.
pub fn markdown(s: &Summary) -> String {
    let mut m = search_md(s);
    m.push_str(&scores_md(s));
    m.push_str(&parameters_md(s));
    m
}

/// `summary.md`'s account of the search and the polish.
fn search_md(s: &Summary) -> String {
    let mut m = format!("# Tune of {}\n\n", s.engine);
    m.push_str(&format!(
        "- Objective: {}.\n- Space: `{}`; engine settings: {}.\n- Search: CMA-ES from {}, seed {}, {} evaluations ({} replayed, {} failed) of a budget of {}, {} jobs; stopped by {}.\n- Wall time {:.1} s, {} evaluations/s; CMA-ES within 5 % of its best after {} evaluations.\n- Best objective {:.4} m on the training runs.\n\n",
        s.objective,
        s.space,
        if s.settings.is_empty() {
            "the scene's".to_string()
        } else {
            s.settings.iter().map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ")
        },
        s.start,
        s.seed,
        s.evaluations,
        s.replayed,
        s.failed,
        s.budget,
        s.jobs,
        s.stop,
        s.wall_time_s,
        s.evaluations_per_s
            .map_or("n/a (all replayed)".into(), |r| format!("{r:.2}")),
        s.evaluations_to_5pct.map_or("n/a".into(), |n| n.to_string()),
        s.best_objective_m,
    ));
    if !s.held.is_empty() {
        m.push_str(&format!(
            "- Held at the scenes' own values, not searched (the objective does not weigh the cube; give `--cube-weight` above 0 to fit them): {}.

",
            s.held.join(", ")
        ));
    }
    let p = &s.polish;
    if p.rounds > 0 {
        m.push_str(&format!(
            "- Polish: reweighted least squares, Levenberg-Marquardt passes (rounds: {}), {} iterations, {} evaluations, {:.1} s: {:.4} -> {:.4} m ({}); {}{}.\n",
            p.rounds,
            p.iterations,
            p.evaluations,
            p.wall_time_s,
            p.start_objective_m,
            p.objective_m,
            p.reason,
            if p.probe_clean {
                "the ±10 % probe found no better point".to_string()
            } else {
                format!(
                    "the ±10 % probe still finds a better point ({} restarts from one): not converged",
                    p.probe_restarts
                )
            },
            if p.widened.is_empty() {
                String::new()
            } else {
                format!(
                    "; bounds widened: {}",
                    p.widened
                        .iter()
                        .map(|w| format!("{} {} {} -> {}", w.key, w.side, w.from, w.to))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        ));
    }
    if let Some(b) = &s.baseline {
        m.push_str(&format!(
            "- Physics-free + actuator: fitted on the same runs ({} evaluations, objective {:.4} m), in `{}`.\n",
            b.evaluations, b.objective_m, b.folder
        ));
    }
    m
}

/// `summary.md`'s scores: the verdict, the training and the held-out runs.
fn scores_md(s: &Summary) -> String {
    let mut m = String::new();
    m.push_str(&format!("\n**{}**\n\n", s.verdict));
    m.push_str(&format!("## Training runs ({})\n\n", s.training.runs));
    m.push_str(&comparison_md(&s.training));
    if let Some(h) = &s.holdout {
        m.push_str(&format!("\n## Held-out runs ({})\n\n", h.runs));
        m.push_str(&comparison_md(h));
    }
    if let Some(c) = &s.timestep_check {
        m.push_str(&format!("\n{}\n", timestep_text(c)));
    }
    m
}

/// `summary.md`'s parameters with their intervals, the identifiability,
/// the registration and the sensitivity.
fn parameters_md(s: &Summary) -> String {
    let mut m = String::new();
    m.push_str(
        "\n## Parameters\n\n| key | value | 95 % interval | bounds searched | scale | start |\n|---|---|---|---|---|---|\n",
    );
    for p in &s.parameters {
        let iv = s.polish.intervals.iter().find(|i| i.key == p.key);
        m.push_str(&format!(
            "| {} | {:.6}{} | {} | [{}, {}] | {:?} | {} |\n",
            p.key,
            p.value,
            if p.at_bound { " (at a bound)" } else { "" },
            fmt_interval(iv),
            p.low,
            p.high,
            p.scale,
            p.start
        ));
    }
    if !s.polish.interval_basis.is_empty() {
        m.push_str(&format!("\nIntervals: {}.\n", s.polish.interval_basis));
    }
    let reg: Vec<_> = s
        .polish
        .intervals
        .iter()
        .filter(|i| i.key.starts_with("registration."))
        .collect();
    if !reg.is_empty() {
        m.push_str("\nRegistration offset fitted with them: ");
        m.push_str(
            &reg.iter()
                .map(|i| format!("{} {:.3} {}", i.key, i.value, fmt_interval(Some(i))))
                .collect::<Vec<_>>()
                .join("; "),
        );
        m.push_str(".\n");
    }
    m.push_str("\n## Identifiability\n\n");
    for r in s
        .identifiability_before
        .iter()
        .chain(s.polish.identifiability.iter())
    {
        m.push_str(&format!("- {}.\n", crate::polish::identifiability_text(r)));
    }
    if s.identifiability_before.is_none() && s.polish.identifiability.is_none() {
        m.push_str("- Not measured (no polish).\n");
    }
    if let Some(b) = &s.baseline {
        m.push_str("\n## Physics-free + actuator: the fitted stage\n\n| key | value | 95 % interval |\n|---|---|---|\n");
        for i in &b.parameters {
            m.push_str(&format!(
                "| {} | {:.6} | {} |\n",
                i.key,
                i.value,
                fmt_interval(Some(i))
            ));
        }
    }
    let r = &s.registration;
    m.push_str(&format!(
        "\nRegistration ({}): moved {:.2} deg and {:.1} mm from the measurement's estimate.\n",
        if r.fitted {
            "fitted with the parameters"
        } else {
            "the measurement's estimate"
        },
        r.moved_deg,
        r.moved_mm
    ));
    m.push_str(&format!(
        "\n## Sensitivity: the objective's rise when one parameter moves ±{:.0} % from the optimum\n\n| key | value | tried | objectives (m) | rise (m) |\n|---|---|---|---|---|\n",
        SENSITIVITY_STEP * 100.0
    ));
    for x in &s.sensitivity {
        m.push_str(&format!(
            "| {} | {:.6} | {:.6}, {:.6} | {:.4}, {:.4} | {:.4} |\n",
            x.key, x.value, x.tried[0], x.tried[1], x.objectives_m[0], x.objectives_m[1], x.rise_m
        ));
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_push(tuned_m: f64) -> Comparison {
        Comparison {
            runs: "16-20".into(),
            scenes: vec![SceneComparison {
                scene: "scene3_cube_push".into(),
                untuned: None,
                tuned: None,
                cube_final_m: None,
                cube_push: Some([
                    Some([0.098, 0.9]),
                    Some([0.114, 90.0]),
                    Some([tuned_m, 0.0]),
                ]),
            }],
            total_untuned: None,
            total_tuned: None,
            objective_m: [75.0, 12.0],
            baselines: vec![],
            phases: vec![],
        }
    }

    /// A tune that ended worse than the engine's defaults on its own
    /// training runs says so first (a budget too small, a pull); one that
    /// improved gives the answer alone.
    #[test]
    fn a_tune_worse_than_its_start_says_so_first() {
        let mut training = with_push(0.05);
        training.runs = "1-15".into();
        training.total_tuned = Some(Scored {
            value_m: 24.25,
            interval_m: None,
        });
        training.objective_m = [19.863, 24.250];
        let held = Comparison {
            runs: "16-20".into(),
            ..training.clone()
        };
        let v = verdict_text("ode", Some(&held), &training);
        assert!(
            v.starts_with("Caution: on the runs it was fitted on, the tuned ode is worse than its own defaults (objective 24.250 m against 19.863 m untuned)"),
            "{v}"
        );
        assert!(
            v.ends_with(
                "On runs 16-20, the tuned ode scores 24.250 m; no physics-free row was scored."
            ),
            "{v}"
        );
        training.objective_m = [19.863, 13.5];
        let v = verdict_text("ode", Some(&held), &training);
        assert!(v.starts_with("On runs 16-20"), "{v}");
    }

    fn check(d: [f64; 3], noise_m: Option<f64>) -> TimestepCheck {
        TimestepCheck {
            timestep_s: 0.001,
            halved_s: 0.0005,
            runs: "16-20".into(),
            tuned: None,
            halved: Some(Scored {
                value_m: 11.5 + d[0],
                interval_m: None,
            }),
            halved_minus_m: Some(d),
            noise_m,
            holds: Some(fit_holds(d, noise_m)),
            failed: None,
        }
    }

    /// The check's words: a change within the noise or with an interval
    /// over zero holds; DART's measured +1.20 m at 0.5 ms does not.
    #[test]
    fn a_fit_holds_at_half_the_step_only_within_the_noise() {
        let dart = timestep_text(&check([1.20, 1.05, 1.31], Some(0.28)));
        assert!(
            dart.contains("score 12.700 m on runs 16-20 (+1.200 m [+1.050, +1.310], the real runs' noise 0.28 m): the fit depends on the timestep, part of it is the integration at 0.001 s"),
            "{dart}"
        );
        for (d, noise) in [
            ([0.24, 0.20, 0.27], Some(0.28)),
            ([0.6, -0.1, 1.2], None),
            ([-0.05, -0.06, -0.04], Some(0.26)),
        ] {
            let t = timestep_text(&check(d, noise));
            assert!(t.ends_with("the fit holds at a finer step."), "{t}");
        }
        assert!(!fit_holds([0.3, 0.2, 0.4], None));
        assert!(!fit_holds([-0.5, -0.6, -0.4], Some(0.3)));
        let failed = TimestepCheck {
            failed: Some("scene3_cube_push: unstable from sample 285".into()),
            ..check([0.0; 3], None)
        };
        assert!(
            timestep_text(&failed).contains("could not be scored on runs 16-20 (scene3_cube_push: unstable from sample 285). The fit depends on the timestep"),
            "{}",
            timestep_text(&failed)
        );
    }

    /// A tuned cube that moves far more than the real one is flagged: its
    /// values are not measurements when the objective does not hold it.
    #[test]
    fn a_tuned_cube_that_flies_is_flagged_and_a_near_push_is_not() {
        let far = comparison_md(&with_push(6.143));
        assert!(
            far.contains("**Warning:** the tuned cube moves 6.143 m, 63 times the real 0.098 m"),
            "{far}"
        );
        for near in [0.033, 0.098, 0.3] {
            assert!(
                !comparison_md(&with_push(near)).contains("Warning"),
                "{near}"
            );
        }
    }
}
