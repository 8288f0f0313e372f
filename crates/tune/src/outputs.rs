//! After the search: the sensitivity of the objective to each parameter,
//! the untuned and the tuned engine scored on the training and held-out
//! runs with bootstrap intervals, and the files of `--out`:
//! `tuned.toml`, `registration.json`, `summary.json`, `summary.md` and
//! `convergence.svg`/`.png` (`history.csv` is written by the search).

use crate::objective::{score_of, FAILED_OBJECTIVE};
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
    /// The cube's final position error, untuned and tuned, metres.
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
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Engine.
    pub engine: String,
    /// The space file.
    pub space: String,
    /// Engine settings every evaluation ran at.
    pub settings: Vec<(String, String)>,
    /// The objective, in words.
    pub objective: String,
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
fn sensitivity(tuner: &Tuner<'_>, u: &[f64], best: f64) -> Vec<Sensitivity> {
    let dims = &tuner.spec.space.dims;
    let registration = tuner.registration(u);
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
                let mut values = optimum.clone();
                values[i] = v;
                match tuner
                    .spec
                    .space
                    .params(&values, &tuner.spec.engine, &tuner.spec.set)
                {
                    Ok(p) => tuner.score(&p, &registration).objective,
                    Err(_) => FAILED_OBJECTIVE,
                }
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
    let mut value = 0.0;
    let mut reps: Vec<f64> = Vec::new();
    for r in &reports.reports {
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
    let interval_m = realitygap_analysis::bootstrap::percentile_interval(
        &reps,
        BootstrapOptions::default().level,
    )
    .map(|i| [i.low_m, i.high_m]);
    Some(Scored {
        value_m: value,
        interval_m,
    })
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

fn evaluate_both(
    tuner: &Tuner<'_>,
    untuned: &[realitygap_core::Trajectory],
    tuned: &[realitygap_core::Trajectory],
    registration: &Registration,
    selection: &RunSelection,
) -> Result<(Reports, Reports)> {
    let t = tuner.target;
    let u = t.evaluate(
        &t.sources("untuned", untuned.to_vec()),
        RegistrationChoice::Given {
            registration: t.base_registration,
            origin: "the measurement's estimate".into(),
        },
        selection,
        Some(RESAMPLES),
    )?;
    let v = t.evaluate(
        &t.sources("tuned", tuned.to_vec()),
        RegistrationChoice::Given {
            registration: *registration,
            origin: "tuned".into(),
        },
        selection,
        Some(RESAMPLES),
    )?;
    Ok((Reports { reports: u }, Reports { reports: v }))
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

/// Writes every output and returns the summary and the files.
pub fn finish(
    tuner: &Tuner<'_>,
    end: &SearchEnd,
    started: Instant,
) -> Result<(Summary, Vec<PathBuf>)> {
    let spec = tuner.spec;
    let best = end.best().ok_or_else(|| {
        anyhow!(
            "every candidate failed; see {}",
            spec.out.join("history.csv").display()
        )
    })?;
    let u: Vec<f64> = best.x.iter().map(|x| crate::search::reflect(*x)).collect();
    let params = tuner.params(&u).map_err(|m| anyhow!(m))?;
    let registration = tuner.registration(&u);
    let sens = sensitivity(tuner, &u, best.objective);
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
    let train_sel = tuner.target.train.clone();
    let (a, b) = evaluate_both(tuner, &untuned, &tuned, &registration, &train_sel)?;
    let runs_text = |r: &Option<realitygap_analysis::selection::RunRange>| {
        r.as_ref().map_or("all".to_string(), |r| r.text.clone())
    };
    let training = comparison(tuner, &a, &b, runs_text(&train_sel.runs));
    let holdout = match tuner.target.holdout_selection() {
        Some(sel) => {
            let (a, b) = evaluate_both(tuner, &untuned, &tuned, &registration, &sel)?;
            Some(comparison(tuner, &a, &b, runs_text(&sel.holdout)))
        }
        None => None,
    };
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
        settings,
        objective: objective_text(tuner),
        seed: spec.search.seed,
        budget: spec.search.budget,
        jobs: spec.search.jobs,
        evaluations: end.history.len(),
        replayed: end.replayed,
        failed: end.history.iter().filter(|e| e.failed.is_some()).count(),
        stop: end.reason.clone(),
        wall_time_s: wall,
        evaluations_per_s: (fresh > 0).then(|| fresh as f64 / wall.max(1e-9)),
        evaluations_to_5pct: to_within_5pct(end, best.objective),
        best_objective_m: best.objective,
        parameters: param_results(&spec.space.dims, &spec.space.values(&u)),
        registration: registration_summary(
            tuner.fits_registration(),
            &tuner.target.base_registration,
            &registration,
        ),
        sensitivity: sens,
        training,
        holdout,
    };
    let files = write_files(tuner, end, &summary, &params, &registration)?;
    Ok((summary, files))
}

fn objective_text(tuner: &Tuner<'_>) -> String {
    let cubes: Vec<String> = tuner
        .target
        .scenes
        .iter()
        .filter(|s| s.cube)
        .map(|s| {
            format!(
                "{} x the cube's final position error in {}",
                s.cube_weight, s.name
            )
        })
        .collect();
    let mut t =
        "the accumulated wrist error (m) summed over the scenes, on the training runs".to_string();
    if !cubes.is_empty() {
        t.push_str(&format!(", plus {}", cubes.join(" and ")));
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
        "| **total** | {} | {} |\n\nObjective (with the cube term): untuned {:.3} m, tuned {:.3} m.\n",
        fmt_scored(&c.total_untuned),
        fmt_scored(&c.total_tuned),
        c.objective_m[0],
        c.objective_m[1]
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
        }
    }
    t
}

/// `summary.md`.
pub fn markdown(s: &Summary) -> String {
    let mut m = format!("# Tune of {}\n\n", s.engine);
    m.push_str(&format!(
        "- Objective: {}.\n- Space: `{}`; engine settings: {}.\n- Search: CMA-ES, seed {}, {} evaluations ({} replayed, {} failed) of a budget of {}, {} jobs; stopped by {}.\n- Wall time {:.1} s, {} evaluations/s; within 5 % of the final best after {} evaluations.\n- Best objective {:.4} m on the training runs.\n\n",
        s.objective,
        s.space,
        if s.settings.is_empty() {
            "the scene's".to_string()
        } else {
            s.settings.iter().map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ")
        },
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
    m.push_str(&format!("## Training runs ({})\n\n", s.training.runs));
    m.push_str(&comparison_md(&s.training));
    if let Some(h) = &s.holdout {
        m.push_str(&format!("\n## Held-out runs ({})\n\n", h.runs));
        m.push_str(&comparison_md(h));
    }
    m.push_str(
        "\n## Parameters\n\n| key | value | bounds | scale | start |\n|---|---|---|---|---|\n",
    );
    for p in &s.parameters {
        m.push_str(&format!(
            "| {} | {:.6}{} | [{}, {}] | {:?} | {} |\n",
            p.key,
            p.value,
            if p.at_bound { " (at a bound)" } else { "" },
            p.low,
            p.high,
            p.scale,
            p.start
        ));
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
