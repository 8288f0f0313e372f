//! The contact tune of a study of tossed objects
//! (`realitygap tune assets/studies/contactnets2020.toml --engine E`), in
//! the same stages as the arm's tune:
//!
//! - **prepare**: the space's keys must be object or contact keys that the
//!   engine honours; one toss is loaded with the start point to say so
//!   before anything runs;
//! - **scan and fit**: CMA-ES over the space ([`crate::search::search`],
//!   resumable from `history.csv`); a candidate's objective is the
//!   headline measure (the box centre's mean distance from the recorded
//!   one, in box edges) averaged over the tosses it may fit on, each toss
//!   simulated from its recorded start at 1 ms;
//! - **intervals**: a bootstrap over the fitted tosses of the search's own
//!   candidates ([`candidate_intervals`]): each resample of tosses picks
//!   the evaluated candidate with the lowest mean on it, and the 2.5 and
//!   97.5 percentiles of the picks' values are the interval. No extra
//!   simulation; it is bounded by where the search looked, which the
//!   summary says;
//! - **score**: the engine at its defaults, tuned, and the physics-free row
//!   on the held-out tosses, every measure with its 95 % interval over
//!   tosses, and the paired differences (tuned against defaults, tuned
//!   against physics-free);
//! - **write**: `tuned.toml` (what `replay --params` takes),
//!   `summary.md`, `summary.json`, `history.csv`.

use crate::objective::FAILED_OBJECTIVE;
use crate::search::{search, Evaluation, History, Outcome, Progress, SearchOptions};
use crate::space::Space;
use anyhow::{anyhow, bail, Context, Result};
use rayon::prelude::*;
use realitygap_core::controller::SplitMix64;
use realitygap_core::engine::{Engine, EngineSettings, PHYSICS_FREE_ENGINE};
use realitygap_core::params::PhysicalParams;
use realitygap_study::tosses::{
    ballistic_toss, check_toss_replay, mean_interval, simulate_toss, toss_error_edges,
    toss_markdown, toss_row, toss_row_json, TossRow, TossRun, TossSet,
};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Bootstrap resamples of the parameters' intervals.
pub const INTERVAL_RESAMPLES: usize = 1000;

/// What to tune.
pub struct TossTune<'a> {
    /// The engine.
    pub engine: &'a dyn Engine,
    /// Every toss of the study.
    pub set: &'a TossSet,
    /// Indices of the tosses to fit on.
    pub training: &'a [usize],
    /// Indices of the tosses to score on, never fitted on.
    pub held_out: &'a [usize],
    /// The parameter space.
    pub space: &'a Space,
    /// Engine settings over the space's (`--set`).
    pub settings: &'a EngineSettings,
    /// The search's settings.
    pub options: SearchOptions,
    /// The output folder.
    pub out: &'a Path,
    /// The study, for the summary (its file).
    pub study: String,
}

/// One fitted parameter: its key, its value and its 95 % interval.
pub type FittedValue = (String, f64, Option<(f64, f64)>);

/// What a toss tune found.
#[derive(Debug, Clone)]
pub struct TossTuned {
    /// The summary (Markdown, also in `summary.md`).
    pub markdown: String,
    /// The files written.
    pub files: Vec<PathBuf>,
    /// The tuned parameters (`tuned.toml`).
    pub params: PhysicalParams,
    /// The held-out rows: the engine at its defaults, tuned, physics-free.
    pub rows: Vec<TossRow>,
    /// The best candidate's mean error on the fitted tosses, edges.
    pub training_edges: f64,
    /// Evaluations in the history.
    pub evaluations: usize,
    /// Per parameter: key, tuned value, 95 % interval.
    pub intervals: Vec<FittedValue>,
}

/// The headline error of each toss at `indices` with `params`; the first
/// toss that cannot be simulated is the error, naming it.
pub fn toss_errors(
    engine: &dyn Engine,
    set: &TossSet,
    indices: &[usize],
    params: &PhysicalParams,
) -> Result<Vec<f64>, String> {
    indices
        .iter()
        .map(|&i| {
            let toss = &set.tosses[i];
            let (run, ..) = simulate_toss(engine, &set.object, toss, params)
                .map_err(|e| format!("toss {}: {e}", toss.id))?;
            toss_error_edges(&set.object, toss, &run)
                .ok_or_else(|| format!("toss {}: the run has no sample", toss.id))
        })
        .collect()
}

/// The space without the keys `engine` has no equivalent for (PhysX has no
/// contact softness): they are held, listed in [`Space::held`].
pub fn supported_space(engine: &dyn Engine, space: &Space) -> Space {
    let support = engine.param_support();
    space.holding(|key| {
        let start = space
            .dims
            .iter()
            .find(|d| d.key == key)
            .map_or(0.0, |d| d.start);
        crate::space::params_of(std::iter::once((key, start)))
            .map(|p| p.check_support(engine.name(), &support).is_err())
            .unwrap_or(false)
    })
}

/// Prepare: the space holds only keys of the tossed box and the contact,
/// and the engine loads a toss at the search's start.
fn prepare(t: &TossTune) -> Result<PhysicalParams> {
    if t.space.is_empty() {
        bail!("{}: the space has no parameter", t.space.source.display());
    }
    let role = &t.set.object.role;
    for d in &t.space.dims {
        let ok = d.key.starts_with("contact.") || d.key.starts_with(&format!("objects.{role}."));
        if !ok {
            bail!(
                "{}: `{}` is not a parameter of a toss: a toss tune fits objects.{role}.* and contact.* keys",
                t.space.source.display(),
                d.key
            );
        }
    }
    if t.space.registration.is_some() {
        bail!(
            "{}: [registration] belongs to the arm's tune; a toss has no capture frame to fit",
            t.space.source.display()
        );
    }
    if t.training.is_empty() || t.held_out.is_empty() {
        bail!(
            "{} tosses to fit on and {} to hold out: both must be at least one",
            t.training.len(),
            t.held_out.len()
        );
    }
    let start = t
        .space
        .params(
            &t.space.values(&t.space.start_unit()),
            t.engine.name(),
            t.settings,
        )
        .map_err(|e| anyhow!(e))?;
    check_toss_replay(t.engine, t.set, &start)?;
    Ok(start)
}

/// Fit: CMA-ES over the space on the fitted tosses, resuming `history.csv`.
fn fit(t: &TossTune, progress: &(dyn Fn(Progress) + Sync)) -> Result<Vec<Evaluation>> {
    let parts: Vec<String> = t
        .training
        .iter()
        .map(|&i| format!("toss_{}_edges", t.set.tosses[i].id))
        .collect();
    let names: Vec<String> = t.space.dims.iter().map(|d| d.key.clone()).collect();
    let mut history = History::open(&t.out.join("history.csv"), &parts, &names, t.space.len())?;
    let evaluate = |u: &[f64]| -> Outcome {
        let values = t.space.values(u);
        let failed = |m: String| Outcome {
            objective: FAILED_OBJECTIVE,
            parts: vec![f64::NAN; t.training.len()],
            failed: Some(m),
        };
        let params = match t.space.params(&values, t.engine.name(), t.settings) {
            Ok(p) => p,
            Err(m) => return failed(m),
        };
        match toss_errors(t.engine, t.set, t.training, &params) {
            Ok(e) => Outcome {
                objective: e.iter().sum::<f64>() / e.len() as f64,
                parts: e,
                failed: None,
            },
            Err(m) => failed(m),
        }
    };
    let end = search(
        t.space,
        &mut history,
        t.options,
        &evaluate,
        &|u| t.space.values(u),
        progress,
    )?;
    Ok(end.history)
}

/// Intervals: per parameter, the 2.5 and 97.5 percentiles of the best
/// evaluated candidate over [`INTERVAL_RESAMPLES`] bootstrap resamples of
/// the fitted tosses; `None` without two usable candidates.
pub fn candidate_intervals(history: &[Evaluation], seed: u64) -> Vec<Option<(f64, f64)>> {
    let usable: Vec<&Evaluation> = history
        .iter()
        .filter(|e| e.failed.is_none() && !e.parts.is_empty())
        .filter(|e| e.parts.iter().all(|p| p.is_finite()))
        .collect();
    let dims = history.first().map_or(0, |e| e.values.len());
    if usable.len() < 2 {
        return vec![None; dims];
    }
    let n = usable[0].parts.len();
    let mut rng = SplitMix64::new(seed ^ 0x1e55);
    let mut picks: Vec<Vec<f64>> = vec![Vec::with_capacity(INTERVAL_RESAMPLES); dims];
    let mut counts = vec![0u32; n];
    for _ in 0..INTERVAL_RESAMPLES {
        counts.iter_mut().for_each(|c| *c = 0);
        for _ in 0..n {
            counts[(rng.next_u64() % n as u64) as usize] += 1;
        }
        let best = usable
            .iter()
            .map(|e| {
                let s: f64 = e
                    .parts
                    .iter()
                    .zip(&counts)
                    .map(|(p, &c)| p * f64::from(c))
                    .sum();
                (s, *e)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, e)| e);
        if let Some(e) = best {
            for (d, v) in e.values.iter().enumerate() {
                picks[d].push(*v);
            }
        }
    }
    picks
        .into_iter()
        .map(|mut v| {
            v.sort_by(f64::total_cmp);
            let q = |f: f64| v[((f * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
            (!v.is_empty()).then(|| (q(0.025), q(0.975)))
        })
        .collect()
}

/// Score: the held-out tosses at `params`, in parallel.
fn replay_held_out(
    t: &TossTune,
    held: &TossSet,
    params: &PhysicalParams,
    done: &(dyn Fn() + Sync),
) -> Result<(Vec<Result<TossRun, String>>, f64)> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(t.options.jobs.max(1))
        .build()
        .map_err(|e| anyhow!("a pool of {} threads: {e}", t.options.jobs))?;
    let started = Instant::now();
    let runs = pool.install(|| {
        held.tosses
            .par_iter()
            .map(|toss| {
                let r = simulate_toss(t.engine, &held.object, toss, params);
                done();
                r
            })
            .collect()
    });
    Ok((runs, started.elapsed().as_secs_f64()))
}

/// The per-toss headline errors of `runs` (NaN where a toss failed).
fn per_toss(held: &TossSet, runs: &[Result<TossRun, String>]) -> Vec<f64> {
    held.tosses
        .iter()
        .zip(runs)
        .map(|(toss, r)| {
            r.as_ref()
                .ok()
                .and_then(|(run, ..)| toss_error_edges(&held.object, toss, run))
                .unwrap_or(f64::NAN)
        })
        .collect()
}

/// The mean difference `a - b` over tosses both measured, with its 95 %
/// bootstrap interval over tosses.
fn paired(a: &[f64], b: &[f64]) -> Option<(f64, f64, f64)> {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| x - y)
        .filter(|d| d.is_finite())
        .collect();
    mean_interval(&d)
}

/// Tunes `t.engine`'s contact on the fitted tosses and scores it on the
/// held-out ones; `progress` follows the search, `scored` each held-out
/// toss replayed (twice as many as held out: defaults, then tuned).
pub fn tune_tosses(
    t: &TossTune,
    progress: &(dyn Fn(Progress) + Sync),
    scored: &(dyn Fn() + Sync),
) -> Result<TossTuned> {
    prepare(t)?;
    std::fs::create_dir_all(t.out).with_context(|| format!("creating {}", t.out.display()))?;
    let started = Instant::now();
    let history = fit(t, progress)?;
    let fit_s = started.elapsed().as_secs_f64();
    let best = history
        .iter()
        .filter(|e| e.failed.is_none())
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .ok_or_else(|| {
            let why = history
                .iter()
                .rev()
                .find_map(|e| e.failed.clone())
                .unwrap_or_else(|| "no evaluation".into());
            anyhow!("every candidate failed; the last: {why}")
        })?;
    let params = t
        .space
        .params(&best.values, t.engine.name(), t.settings)
        .map_err(|e| anyhow!(e))?;
    let intervals: Vec<FittedValue> = t
        .space
        .dims
        .iter()
        .zip(&best.values)
        .zip(candidate_intervals(&history, t.options.seed))
        .map(|((d, v), i)| (d.key.clone(), *v, i))
        .collect();

    let held = t.set.subset(t.held_out);
    let mut defaults = PhysicalParams::default();
    if !t.settings.is_empty() {
        defaults
            .engine_settings
            .insert(t.engine.name().to_string(), t.settings.clone());
    }
    let (default_runs, default_s) = replay_held_out(t, &held, &defaults, scored)?;
    let (tuned_runs, tuned_s) = replay_held_out(t, &held, &params, scored)?;
    let ideal_runs: Vec<Result<TossRun, String>> = held
        .tosses
        .iter()
        .map(|toss| {
            Ok((
                ballistic_toss(&held.object, toss),
                realitygap_core::controller::RunStatus::Completed,
                0.0,
                0,
            ))
        })
        .collect();
    let name = t.engine.name();
    let rows = vec![
        toss_row(
            &format!("{name} at its defaults"),
            &held,
            &default_runs,
            Some(default_s),
        ),
        toss_row(&format!("{name} tuned"), &held, &tuned_runs, Some(tuned_s)),
        toss_row(PHYSICS_FREE_ENGINE, &held, &ideal_runs, None),
    ];
    let (d, tu, id) = (
        per_toss(&held, &default_runs),
        per_toss(&held, &tuned_runs),
        per_toss(&held, &ideal_runs),
    );
    let against_defaults = paired(&tu, &d);
    let against_ideal = paired(&tu, &id);
    let tuned = TossTuned {
        markdown: String::new(),
        files: Vec::new(),
        params,
        rows,
        training_edges: best.objective,
        evaluations: history.len(),
        intervals,
    };
    write(t, tuned, fit_s, against_defaults, against_ideal)
}

/// Write: `tuned.toml`, `summary.md`, `summary.json`.
fn write(
    t: &TossTune,
    mut tuned: TossTuned,
    fit_s: f64,
    against_defaults: Option<(f64, f64, f64)>,
    against_ideal: Option<(f64, f64, f64)>,
) -> Result<TossTuned> {
    let name = t.engine.name();
    let file = t.out.join("tuned.toml");
    let text = format!(
        "# {name}'s contact tuned on {} tosses of {} (realitygap tune; {} evaluations).\n\
         # Use it with: realitygap replay REAL --engine {name} --params {}\n\n{}",
        t.training.len(),
        t.study,
        tuned.evaluations,
        file.display(),
        tuned.params.to_toml_string()
    );
    std::fs::write(&file, text).with_context(|| format!("writing {}", file.display()))?;
    let held = t.set.subset(t.held_out);
    let mut md = format!(
        "# {name}: contact tuned on real tosses\n\n\
         Study {}: fitted on {} tosses, scored on {} held out (never fitted on). {} evaluations in {:.0} s; the best candidate's mean error on the fitted tosses is {:.4} edges.\n\n\
         ## Fitted parameters\n\n\
         {}Intervals: the 2.5-97.5 percentiles of the best evaluated candidate over {INTERVAL_RESAMPLES} bootstrap resamples of the fitted tosses (bounded by where the search looked). The data's experiment.json gives friction 0.18 and restitution 0.125, values its authors used, not measurements.\n\n\
         | parameter | tuned | 95 % interval | bounds |\n|---|---:|---|---|\n",
        t.study,
        t.training.len(),
        t.held_out.len(),
        tuned.evaluations,
        fit_s,
        tuned.training_edges,
        if t.space.held.is_empty() {
            String::new()
        } else {
            format!(
                "Not fitted, {name} has no equivalent: {}.\n\n",
                t.space.held.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", ")
            )
        }
    );
    for ((key, v, i), d) in tuned.intervals.iter().zip(&t.space.dims) {
        let near = |b: f64| (v - b).abs() <= 1e-3 * (d.high - d.low);
        let flag = if near(d.low) || near(d.high) {
            " (at a bound)"
        } else {
            ""
        };
        md += &format!(
            "| `{key}` | {v:.4}{flag} | {} | [{}, {}] |\n",
            i.map_or("n/a".into(), |(lo, hi)| format!("[{lo:.4}, {hi:.4}]")),
            d.low,
            d.high
        );
    }
    md += "\n## Held-out tosses\n\n";
    md += &toss_markdown(&tuned.rows, &held)
        .lines()
        .skip(2)
        .collect::<Vec<_>>()
        .join("\n");
    let diff = |v: Option<(f64, f64, f64)>| {
        v.map_or("n/a".into(), |(m, lo, hi)| {
            format!("{m:+.4} [{lo:+.4}, {hi:+.4}]")
        })
    };
    md += &format!(
        "\n\nPaired over the held-out tosses (edges; negative: tuned is closer): tuned minus defaults {}, tuned minus physics-free {}.\n",
        diff(against_defaults),
        diff(against_ideal)
    );
    let md_file = t.out.join("summary.md");
    std::fs::write(&md_file, &md).with_context(|| format!("writing {}", md_file.display()))?;
    let json_file = t.out.join("summary.json");
    let pair =
        |v: Option<(f64, f64, f64)>| v.map(|(m, lo, hi)| json!({"mean": m, "ci95": [lo, hi]}));
    let summary = json!({
        "engine": name,
        "engine_version": t.engine.version(),
        "study": t.study,
        "kind": "tosses",
        "fitted_tosses": t.training.iter().map(|&i| &t.set.tosses[i].id).collect::<Vec<_>>(),
        "held_out_tosses": t.held_out.iter().map(|&i| &t.set.tosses[i].id).collect::<Vec<_>>(),
        "evaluations": tuned.evaluations,
        "held_keys": t.space.held,
        "fit_wall_s": fit_s,
        "training_edges": tuned.training_edges,
        "parameters": tuned.intervals.iter().map(|(k, v, i)| json!({
            "key": k, "value": v, "ci95": i.map(|(lo, hi)| [lo, hi]),
        })).collect::<Vec<_>>(),
        "held_out": tuned.rows.iter().map(toss_row_json).collect::<Vec<_>>(),
        "tuned_minus_defaults_edges": pair(against_defaults),
        "tuned_minus_physics_free_edges": pair(against_ideal),
    });
    std::fs::write(&json_file, serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("writing {}", json_file.display()))?;
    tuned.markdown = md;
    tuned.files = vec![file, md_file, json_file, t.out.join("history.csv")];
    Ok(tuned)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(values: Vec<f64>, parts: Vec<f64>) -> Evaluation {
        Evaluation {
            index: 0,
            generation: 0,
            objective: parts.iter().sum::<f64>() / parts.len() as f64,
            parts,
            failed: None,
            values,
            x: vec![],
        }
    }

    #[test]
    fn a_candidate_best_on_every_toss_is_the_whole_interval() {
        let h = vec![
            candidate(vec![0.2], vec![0.1, 0.2, 0.3]),
            candidate(vec![0.5], vec![0.4, 0.5, 0.6]),
        ];
        assert_eq!(candidate_intervals(&h, 1), vec![Some((0.2, 0.2))]);
    }

    #[test]
    fn candidates_that_split_the_tosses_widen_the_interval() {
        // Each candidate is best on half the tosses: resamples pick both.
        let h = vec![
            candidate(vec![0.1], vec![0.0, 0.0, 1.0, 1.0]),
            candidate(vec![0.9], vec![1.0, 1.0, 0.0, 0.0]),
            candidate(vec![0.5], vec![2.0, 2.0, 2.0, 2.0]),
        ];
        assert_eq!(candidate_intervals(&h, 1), vec![Some((0.1, 0.9))]);
        let mut failed = h[0].clone();
        failed.failed = Some("x".into());
        assert_eq!(candidate_intervals(&[failed], 1), vec![None]);
    }
}
