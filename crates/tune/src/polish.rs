//! After CMA-ES: the least-squares polish of a study tune, with the
//! identifiability check that runs before the search, the bounds it
//! widens, the probe that restarts it, and the parameters' intervals.
//!
//! - **Residuals.** The objective is the accumulated wrist error, a sum of
//!   per-step distances `d_k = |e_k| >= 0` (`e_k` the wrist error), plus
//!   `w * c` for a cube's final pose error `c` (position, and turn times
//!   half the cube's edge). The polish minimises
//!   it by iteratively reweighted least squares: each pass fixes weights
//!   `1 / sqrt(max(d_k, floor))` at its start and runs
//!   Levenberg-Marquardt ([`crate::least_squares`]) on the weighted error
//!   components, whose squares sum to the objective at the pass's start;
//!   passes go on while the objective itself falls. The plain residuals
//!   `sqrt(d_k)` (whose squares also sum to the objective) have a Jacobian
//!   that degrades where `d_k` is small, near a good fit; the reports
//!   below use them with a wider step.
//! - **Bounds.** A parameter that ends on a bound of the space is widened
//!   within its physical limits ([`physical_limits`]): a linear range by
//!   its own width on that side, a log range by a factor of 4, and the
//!   polish goes on from the same point ([`PolishOptions::widen_rounds`]
//!   rounds at most). A bound that is already the physical limit stays and
//!   is reported.
//! - **Probe.** Each parameter is then moved 10 % either way from the
//!   optimum ([`crate::outputs::SENSITIVITY_STEP`]); a probe that scores
//!   better means the search had not converged, and the polish restarts
//!   from it (twice at most).
//! - **Intervals.** From the Jacobian `J` at the optimum: the objective
//!   there rises by `d^T J^T J d` for a move `d`, so the values of one
//!   parameter over which it rises by less than `T` (the others refitted)
//!   lie within `sqrt(T (J^T J)^-1_ii)`. `T` is 1.96 times the objective's
//!   bootstrap standard deviation over the training runs: the interval is
//!   what the real runs' own spread cannot tell apart. Without that spread
//!   (a single reference run), the Gauss-Newton covariance `s^2 (J^T J)^-1`
//!   with the residuals' autocorrelation counted
//!   ([`crate::least_squares::spread`]) gives 1.96 standard deviations.
//!   Both are local (a quadratic model at the optimum), clipped to the
//!   bounds searched. In a space of at most [`PROFILE_MAX_COORDINATES`]
//!   coordinates, with the real runs' spread, each end is then profiled:
//!   the parameter is held there, the others are refitted, and the end
//!   moves to where the objective itself has risen by `T`
//!   (`profiled_ends`), which follows a valley the quadratic model does
//!   not.
//! - **Identifiability.** The same Jacobian, at the start point before the
//!   search and at the optimum after it, names the parameters whose effect
//!   is below the noise (their interval spans the whole range) and the
//!   pairs that trade against each other (correlation beyond 0.95).

use crate::least_squares::{self, FitOptions};
use crate::space::{Dim, Scale, Space};
use crate::{TuneSpec, Tuner};
use anyhow::{anyhow, Result};
use serde::Serialize;
use std::sync::Mutex;

/// The forward-difference step (normalised units) of the Jacobians the
/// identifiability and the intervals are read from: 1 % of each range,
/// wide enough that a difference does not hinge on one contact event or
/// engine step.
pub const REPORT_STEP: f64 = 0.01;

/// Reweighting passes per polish round, at most ([`polish`]'s iteratively
/// reweighted least squares).
const IRLS_PASSES: usize = 6;

/// The error length below which the reweighting's weights stop growing,
/// metres: a tenth of a millimetre, under any capture's noise.
const IRLS_FLOOR_M: f64 = 1e-4;

/// Settings of the polish.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolishOptions {
    /// Levenberg-Marquardt iterations per round at most, over its
    /// reweighting passes (0: no polish).
    pub iterations: usize,
    /// Rounds that widen bounds at most (0: the space's bounds are kept).
    pub widen_rounds: usize,
    /// Restarts from a better probe point at most.
    pub probe_restarts: usize,
    /// No new round starts once the polish has made this many evaluations
    /// (a round under way finishes).
    pub max_evaluations: usize,
}

impl Default for PolishOptions {
    fn default() -> Self {
        PolishOptions {
            iterations: 12,
            widen_rounds: 2,
            probe_restarts: 2,
            max_evaluations: 600,
        }
    }
}

/// A bound the polish moved.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Widened {
    /// The parameter.
    pub key: String,
    /// `low` or `high`.
    pub side: String,
    /// The space's bound.
    pub from: f64,
    /// The bound the polish searched to.
    pub to: f64,
}

/// A fitted parameter with its interval.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamInterval {
    /// The key (a parameter, or `registration.*`).
    pub key: String,
    /// The value at the optimum.
    pub value: f64,
    /// Its 95 % interval, clipped to the (widened) bounds; `None` when
    /// the data say nothing of it.
    pub interval: Option<[f64; 2]>,
    /// True when the interval reaches a bound (it would be wider).
    pub clipped: bool,
}

/// What the data cannot tell apart, at one point.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentifiabilityReport {
    /// Where: `start` (before the search) or `optimum`.
    pub at: String,
    /// Parameters whose effect is below the noise: moving one a tenth of
    /// its range either way changes the objective (to second order, from
    /// the Jacobian) by less than the objective's own spread over
    /// resamples of the real runs.
    pub unseen: Vec<String>,
    /// Coordinates whose effect could not be measured here: the engine
    /// failed (diverged) a small step either way from the point. Their
    /// effect counts as zero and they get no interval.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unmeasured: Vec<(String, String)>,
    /// That spread: the bootstrap standard deviation of the wrist total
    /// over the training runs, metres (`None`: not measured).
    pub noise_m: Option<f64>,
    /// Each coordinate's effect: the objective's larger change when it
    /// moves a tenth of its range either way, metres.
    pub effects_m: Vec<(String, f64)>,
    /// Pairs whose estimates are correlated beyond 0.95 (key, key,
    /// correlation).
    pub trading: Vec<(String, String, f64)>,
    /// Autocorrelation of the residuals from one step to the next.
    pub residual_autocorrelation: f64,
    /// Residuals, and the independent ones they count as.
    pub residuals: (usize, f64),
}

/// The polish's account, in `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PolishReport {
    /// The objective CMA-ES ended at, metres.
    pub start_objective_m: f64,
    /// The objective after the polish, metres.
    pub objective_m: f64,
    /// Simulations of the polish (Jacobians, steps, probes).
    pub evaluations: usize,
    /// Levenberg-Marquardt iterations, all rounds.
    pub iterations: usize,
    /// Rounds of the polish (each of reweighting passes).
    pub rounds: usize,
    /// Why the last round stopped.
    pub reason: String,
    /// Bounds widened.
    pub widened: Vec<Widened>,
    /// Parameters that end on a bound that is their physical limit, or
    /// that could not be widened further.
    pub at_limit: Vec<String>,
    /// Restarts from a better probe point.
    pub probe_restarts: usize,
    /// True when the last probe found no better point.
    pub probe_clean: bool,
    /// Every coordinate with its interval.
    pub intervals: Vec<ParamInterval>,
    /// What the intervals mean.
    pub interval_basis: String,
    /// At the optimum.
    pub identifiability: Option<IdentifiabilityReport>,
    /// Wall time, s.
    pub wall_time_s: f64,
}

/// The identifiability report in a few lines.
pub fn identifiability_text(r: &IdentifiabilityReport) -> String {
    let mut t = format!(
        "identifiability at the {}: {} residuals counting as {:.0} independent ones (step-to-step autocorrelation {:.2})",
        r.at, r.residuals.0, r.residuals.1, r.residual_autocorrelation
    );
    let noise = r.noise_m.map_or("n/a".to_string(), |n| format!("{n:.3} m"));
    if r.unseen.is_empty() {
        t.push_str(&format!(
            "; every coordinate moves the objective more than the real runs' noise ({noise}) when it moves a tenth of its range"
        ));
    } else {
        t.push_str(&format!(
            "; {} of {} coordinates move the objective less than the real runs' noise ({noise}) when they move a tenth of their range: {}",
            r.unseen.len(),
            r.effects_m.len(),
            r.unseen.join(", ")
        ));
    }
    if !r.unmeasured.is_empty() {
        t.push_str(&format!(
            "; not measured (the engine fails a small step either way): {}",
            r.unmeasured
                .iter()
                .map(|(k, why)| format!("{k} ({why})"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if r.trading.is_empty() {
        t.push_str("; no pair trades against another");
    } else {
        t.push_str(&format!(
            "; trading against each other: {}",
            r.trading
                .iter()
                .map(|(a, b, c)| format!("{a} ~ {b} ({c:+.2})"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    t
}

/// The polish's end.
pub struct Polished {
    /// The space searched last (bounds widened where they were).
    pub space: Space,
    /// The optimum's coordinates in that space.
    pub u: Vec<f64>,
    /// Its objective, metres.
    pub objective_m: f64,
    /// The account.
    pub report: PolishReport,
    /// The last probe around the optimum (none without a polish).
    pub probe: Option<Vec<crate::outputs::Sensitivity>>,
}

/// The physical limits a parameter's bounds may be widened to, from its
/// key's last part; `None` for a key without one (never widened). An
/// object's mass is none: it is weighed, not fitted, and a search that
/// lightens it (MuJoCo's and DART's wrist-only tunes took the study's
/// 88 g cube down to 1 g, which then flew 4.8 m) is buying wrist error with
/// an impossible object; its bounds stay where the space puts them.
pub fn physical_limits(key: &str) -> Option<(f64, f64)> {
    let field = key.rsplit('.').next().unwrap_or(key);
    if key.starts_with("objects.") && field == "mass_kg" {
        return None;
    }
    Some(match (key, field) {
        ("controller.delay_s", _) => (0.0, 0.5),
        ("controller.max_accel_deg_s2", _) => (1.0, 1.0e5),
        ("actuator.frequency_rad_s", _) => (0.5, 2000.0),
        ("actuator.damping_ratio", _) => (0.05, 10.0),
        ("actuator.max_velocity_deg_s", _) => (1.0, 1000.0),
        ("actuator.deadband_deg_s", _) => (0.0, 30.0),
        (_, "damping" | "frictionloss") => (0.0, 1.0e3),
        (_, "armature") => (0.0, 10.0),
        (_, "kv" | "kp" | "max_force" | "stiffness") => (1.0e-3, 1.0e6),
        (_, "offset_deg") => (-10.0, 10.0),
        (_, "mass_kg") => (1.0e-3, 100.0),
        (_, "friction") => (1.0e-3, 5.0),
        (_, "time_constant_s") => (1.0e-3, 1.0),
        (_, "damping_ratio") => (0.05, 10.0),
        _ => return None,
    })
}

/// `d` with its `side` bound widened within the physical limits; `None`
/// when it cannot move.
fn widen(d: &Dim, high_side: bool) -> Option<Dim> {
    let (lo, hi) = physical_limits(&d.key)?;
    let mut w = d.clone();
    match (d.scale, high_side) {
        (Scale::Linear, true) => w.high = (d.high + (d.high - d.low)).min(hi),
        (Scale::Linear, false) => w.low = (d.low - (d.high - d.low)).max(lo),
        (Scale::Log, true) => w.high = (d.high * 4.0).min(hi),
        (Scale::Log, false) => w.low = (d.low / 4.0).max(lo.max(f64::MIN_POSITIVE)),
    }
    let moved = if high_side {
        w.high > d.high * (1.0 + 1e-12) + 1e-300
    } else {
        w.low < d.low - d.low.abs() * 1e-12 - 1e-300
    };
    moved.then_some(w)
}

/// The tuner of `spec` with another space (and no physics-free row).
fn with_space(spec: &TuneSpec, space: Space) -> TuneSpec {
    TuneSpec {
        baseline_space: None,
        ..spec.with_space(space)
    }
}

/// The Jacobian's report at `u`: identifiability, and the spread.
pub fn identifiability(
    tuner: &Tuner<'_>,
    u: &[f64],
    at: &str,
    jac: Option<nalgebra::DMatrix<f64>>,
    r: Option<Vec<f64>>,
) -> Result<(IdentifiabilityReport, least_squares::Spread, usize)> {
    let f = |x: &[f64]| tuner.residuals(x);
    let mut evaluations = 0;
    let r = match r {
        Some(r) => r,
        None => {
            evaluations += 1;
            f(u).map_err(|m| anyhow!("{at}: {m}"))?
        }
    };
    let names = tuner.value_names();
    let (j, unmeasured) = match jac {
        Some(j) => (j, Vec::new()),
        None => {
            evaluations += u.len();
            let (j, blind) =
                least_squares::jacobian_or_blind(&f, u, &r, REPORT_STEP, tuner.spec.search.jobs);
            let unmeasured: Vec<(String, String)> = blind
                .into_iter()
                .map(|(i, why)| (names[i].clone(), why))
                .collect();
            (j, unmeasured)
        }
    };
    let s = least_squares::spread(&j, &r, 1);
    let noise_m = objective_noise(tuner, u);
    if noise_m.is_some() {
        evaluations += 1;
    }
    // The objective's change for a move of h = 0.1 (normalised) either
    // way: 2 h (J^T r)_i + h^2 (J^T J)_ii.
    let h = 0.1;
    let effects_m: Vec<(String, f64)> = names
        .iter()
        .enumerate()
        .map(|(c, k)| {
            let col = j.column(c);
            let g: f64 = col.iter().zip(&r).map(|(a, b)| a * b).sum();
            let q = col.norm_squared();
            let up = 2.0 * h * g + h * h * q;
            let down = -2.0 * h * g + h * h * q;
            (k.clone(), up.abs().max(down.abs()))
        })
        .collect();
    let threshold = noise_m.unwrap_or(0.0);
    let unseen: Vec<String> = effects_m
        .iter()
        .filter(|(_, e)| e.partial_cmp(&threshold) != Some(std::cmp::Ordering::Greater))
        .map(|(k, _)| k.clone())
        .collect();
    let trading = least_squares::trading_pairs(&names, &s, &|i| unseen.contains(&names[i]));
    Ok((
        IdentifiabilityReport {
            at: at.to_string(),
            unseen,
            unmeasured,
            noise_m,
            effects_m,
            trading,
            residual_autocorrelation: s.rho,
            residuals: (s.n, s.n_eff),
        },
        s,
        evaluations,
    ))
}

/// The bootstrap standard deviation of the wrist total at `u` over the
/// training runs (200 resamples of the real runs), metres.
fn objective_noise(tuner: &Tuner<'_>, u: &[f64]) -> Option<f64> {
    let p = tuner.params(u).ok()?;
    let trajs = tuner.simulator.simulate(&tuner.target.scenes, &p).ok()?;
    let t = tuner.target;
    let reports = t
        .evaluate(
            &t.sources("noise", trajs),
            realitygap_analysis::compare::RegistrationChoice::Given {
                registration: tuner.registration(u),
                origin: "identifiability".into(),
            },
            &t.train,
            Some(200),
        )
        .ok()?;
    let (_, reps) = crate::outputs::summed(&reports)?;
    let reps: Vec<f64> = reps.into_iter().filter(|x| x.is_finite()).collect();
    if reps.len() < 10 {
        return None;
    }
    let mean = reps.iter().sum::<f64>() / reps.len() as f64;
    let var = reps.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (reps.len() - 1) as f64;
    Some(var.sqrt())
}

/// Polishes the search's best point `u0` (objective `start_objective`).
/// `note` hears what the polish is doing.
pub fn polish(
    tuner: &Tuner<'_>,
    u0: &[f64],
    start_objective: f64,
    options: PolishOptions,
    note: &(dyn Fn(String) + Sync),
) -> Result<Polished> {
    let started = std::time::Instant::now();
    let spec = tuner.spec;
    let mut space = spec.space.clone();
    let mut u = u0.to_vec();
    let mut objective = start_objective;
    let mut report = PolishReport {
        start_objective_m: start_objective,
        objective_m: start_objective,
        evaluations: 0,
        iterations: 0,
        rounds: 0,
        reason: "no polish asked for".into(),
        widened: Vec::new(),
        at_limit: Vec::new(),
        probe_restarts: 0,
        probe_clean: false,
        intervals: Vec::new(),
        interval_basis: String::new(),
        identifiability: None,
        wall_time_s: 0.0,
    };
    if options.iterations == 0 {
        return Ok(Polished {
            space,
            u,
            objective_m: objective,
            report,
            probe: None,
        });
    }
    let fit_options = FitOptions {
        max_iterations: options.iterations,
        step: 1e-3,
        tolerance: 1e-4,
        jobs: spec.search.jobs,
        ..FitOptions::default()
    };
    let mut widen_rounds = 0;
    let mut last_probe;
    loop {
        realitygap_runner::interrupt::check()?;
        let round_spec = with_space(spec, space.clone());
        let t = Tuner {
            target: tuner.target,
            simulator: tuner.simulator,
            spec: &round_spec,
        };
        report.rounds += 1;
        note(format!(
            "polish round {}: reweighted least squares from {:.4} m over {} coordinates",
            report.rounds,
            objective,
            u.len()
        ));
        // Iteratively reweighted least squares: each pass fixes weights at
        // its start (each error's length to the power -1/2, so that the
        // squares sum to the objective there) and runs Levenberg-Marquardt
        // on the weighted error components, which are smooth where the
        // square roots of the lengths are not (near a good fit); passes go
        // on while the objective itself falls.
        let mut fit_reason = String::new();
        // The round's iterations (`--iterations`) are shared by its passes,
        // so that a round costs what one Levenberg-Marquardt run did and
        // the budget leaves room for the rounds after a widening.
        let mut round_iterations = fit_options.max_iterations;
        // The errors at `u`: simulated at the round's start, then those
        // the last pass ended on (its end is the next pass's start).
        let mut at_u: Option<crate::objective::Errors> = None;
        for pass in 0..IRLS_PASSES {
            let count = Mutex::new(0usize);
            let errors = match at_u.take() {
                Some(e) => e,
                None => {
                    report.evaluations += 1;
                    t.errors(&u)
                        .map_err(|m| anyhow!("the polish, at its start: {m}"))?
                }
            };
            let weights = errors.weights(IRLS_FLOOR_M);
            let f = |x: &[f64]| {
                *count.lock().unwrap_or_else(|e| e.into_inner()) += 1;
                t.errors(x).map(|e| e.residuals(Some(&weights)))
            };
            // Iterations this pass: what is left of the polish's
            // evaluations, a Jacobian and a step each, at least one.
            let left = options
                .max_evaluations
                .saturating_sub(report.evaluations + 2);
            let round_options = FitOptions {
                max_iterations: round_iterations.min((left / (u.len() + 1)).max(1)),
                ..fit_options
            };
            let fit = least_squares::levenberg_marquardt(&f, &u, round_options, &|_, _, _| {})
                .map_err(|m| anyhow!("the polish: {m}"))?;
            // The fit's evaluations, and the pass's end below.
            report.evaluations += count.into_inner().unwrap_or_else(|e| e.into_inner()) + 1;
            report.iterations += fit.iterations;
            round_iterations = round_iterations.saturating_sub(fit.iterations.max(1));
            fit_reason = fit.reason.clone();
            // The objective itself at the pass's end (the weighted cost is
            // only its model).
            let reached = t.errors(&fit.u).ok();
            let gain = match reached {
                Some(e) if e.objective() < objective => {
                    let o = e.objective();
                    let gain = (objective - o) / objective.max(f64::MIN_POSITIVE);
                    u = fit.u.clone();
                    objective = o;
                    at_u = Some(e);
                    gain
                }
                _ => 0.0,
            };
            note(format!(
                "  pass {}: {:.4} m after {} iterations ({})",
                pass + 1,
                objective,
                fit.iterations,
                fit.reason
            ));
            if gain < fit_options.tolerance
                || round_iterations == 0
                || report.evaluations + u.len() + 2 >= options.max_evaluations
            {
                break;
            }
        }
        report.reason = fit_reason;
        if report.evaluations >= options.max_evaluations {
            report.reason = format!(
                "{} (the polish's {} evaluations are spent)",
                report.reason, options.max_evaluations
            );
            last_probe = None;
            break;
        }
        // Parameters on a bound: widen, and go on from the same point.
        let mut moved = false;
        if widen_rounds < options.widen_rounds {
            let values = space.values(&u);
            let mut next = space.clone();
            // A bound holds a coordinate when a step inward (1 % of the
            // range) raises the objective: only those are widened, not the
            // ones that sit there because they do not matter.
            let at_bound: Vec<(usize, bool)> = (0..space.dims.len())
                .filter_map(|i| {
                    if u[i] <= 1e-6 {
                        Some((i, false))
                    } else if u[i] >= 1.0 - 1e-6 {
                        Some((i, true))
                    } else {
                        None
                    }
                })
                .collect();
            let held: Vec<bool> = {
                use rayon::prelude::*;
                least_squares::pool(spec.search.jobs).install(|| {
                    at_bound
                        .par_iter()
                        .map(|&(i, high)| {
                            let mut x = u.clone();
                            x[i] += if high { -0.01 } else { 0.01 };
                            match t.residuals(&x) {
                                Ok(r) => {
                                    r.iter().map(|v| v * v).sum::<f64>() > objective * (1.0 + 1e-6)
                                }
                                Err(_) => false,
                            }
                        })
                        .collect()
                })
            };
            report.evaluations += at_bound.len();
            for (&(i, side), held) in at_bound.iter().zip(held) {
                let d = &space.dims[i];
                if !held {
                    continue;
                }
                if let Some(w) = widen(d, side) {
                    report.widened.push(Widened {
                        key: d.key.clone(),
                        side: if side { "high" } else { "low" }.into(),
                        from: if side { d.high } else { d.low },
                        to: if side { w.high } else { w.low },
                    });
                    next.dims[i] = w;
                    moved = true;
                }
            }
            if moved {
                widen_rounds += 1;
                for (i, d) in next.dims.iter().enumerate() {
                    u[i] = d.unit(values[i]);
                }
                space = next;
                note(format!(
                    "  widened: {}",
                    report
                        .widened
                        .iter()
                        .map(|w| format!("{} {} {} -> {}", w.key, w.side, w.from, w.to))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
                continue;
            }
        }
        // The probe: 10 % either way of each parameter.
        let probe = crate::outputs::sensitivity(&t, &u, objective);
        report.evaluations += 2 * probe.len();
        last_probe = Some(probe.clone());
        let better = probe
            .iter()
            .flat_map(|s| {
                s.objectives_m
                    .iter()
                    .zip(s.tried)
                    .map(move |(o, v)| (s.key.clone(), *o, v))
            })
            .filter(|(_, o, _)| *o < objective * (1.0 - 1e-6))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        match better {
            Some((key, o, v)) if report.probe_restarts < options.probe_restarts => {
                report.probe_restarts += 1;
                note(format!(
                    "  the probe found {o:.4} m at {key} = {v:.6}: not converged, going on from there"
                ));
                if let Some(i) = space.dims.iter().position(|d| d.key == key) {
                    u[i] = space.dims[i].unit(v);
                }
                objective = o;
                continue;
            }
            Some((key, o, v)) => {
                // No restarts left: keep the better point, unpolished.
                report.probe_clean = false;
                note(format!(
                    "  the probe found {o:.4} m at {key} = {v:.6}; no restarts left: the search has not converged"
                ));
                if let Some(i) = space.dims.iter().position(|d| d.key == key) {
                    u[i] = space.dims[i].unit(v);
                }
                objective = o;
                last_probe = None;
                break;
            }
            None => {
                report.probe_clean = true;
                break;
            }
        }
    }
    // Intervals and identifiability at the optimum.
    let final_spec = with_space(spec, space.clone());
    let t = Tuner {
        target: tuner.target,
        simulator: tuner.simulator,
        spec: &final_spec,
    };
    // A Jacobian of its own, with the report's wider step (the fit's is
    // for the steps, and a simulator's small differences can straddle a
    // contact event).
    let (ident, spread, n) = identifiability(&t, &u, "optimum", None, None)?;
    report.evaluations += n;
    let names = t.value_names();
    let values = t.values(&u);
    // The half-width per unit of `sd_u`: with the real runs' noise, the
    // values over which the objective rises by less than 1.96 times its
    // bootstrap standard deviation (the local quadratic model, the other
    // coordinates refitted); without it, 1.96 standard deviations of the
    // Gauss-Newton covariance.
    let gn = spread.variance * spread.n as f64 / spread.n_eff;
    let (k, basis) = match ident.noise_m {
        Some(n) if n > 0.0 && gn > 0.0 => (
            (1.96 * n).sqrt() / gn.sqrt(),
            format!("the objective within 1.96 x the real runs' noise ({n:.3} m) of its optimum"),
        ),
        _ => (
            1.96,
            "the Gauss-Newton covariance (the real runs' noise unknown)".to_string(),
        ),
    };
    report.interval_basis = basis;
    // In a small space, with the real runs' noise, each end is profiled:
    // the objective itself, the others refitted ([`profiled_ends`]).
    let ends = match ident.noise_m {
        Some(n) if n > 0.0 && gn > 0.0 && u.len() <= PROFILE_MAX_COORDINATES => {
            note(format!(
                "profiling the intervals' ends: {} coordinates",
                u.len()
            ));
            let (ends, evaluations) =
                profiled_ends(&t, &u, objective, 1.96 * n, k, &spread, fit_options);
            report.evaluations += evaluations;
            report.interval_basis.push_str(
                "; each end profiled: where the objective, the other parameters refitted, has risen by that much",
            );
            ends
        }
        _ => vec![[None, None]; u.len()],
    };
    for (c, key) in names.iter().enumerate() {
        let sd = spread.sd_u[c];
        let (interval, clipped) = if sd.is_finite() {
            let (a, b) = (
                ends[c][0].unwrap_or(u[c] - k * sd),
                ends[c][1].unwrap_or(u[c] + k * sd),
            );
            // An end profiled all the way to a bound lies on it.
            let clipped = a <= 1e-12 || b >= 1.0 - 1e-12;
            let at = |x: f64| {
                let mut v = u.to_vec();
                v[c] = x.clamp(0.0, 1.0);
                t.values(&v)[c]
            };
            let (lo, hi) = (at(a), at(b));
            (Some([lo.min(hi), lo.max(hi)]), clipped)
        } else {
            (None, true)
        };
        report.intervals.push(ParamInterval {
            key: key.clone(),
            value: values[c],
            interval,
            clipped,
        });
    }
    for (i, d) in space.dims.iter().enumerate() {
        if u[i] <= 1e-6 || u[i] >= 1.0 - 1e-6 {
            report.at_limit.push(d.key.clone());
        }
    }
    report.identifiability = Some(ident);
    report.objective_m = objective;
    report.wall_time_s = started.elapsed().as_secs_f64();
    Ok(Polished {
        space,
        u,
        objective_m: objective,
        report,
        probe: last_probe,
    })
}

/// Spaces of at most this many coordinates get profiled intervals
/// (`profiled_ends`); larger ones keep the local model's, as a profile
/// costs a few refits per end.
pub const PROFILE_MAX_COORDINATES: usize = 6;

/// Trials per profiled end at most.
const PROFILE_TRIALS: usize = 3;

/// Levenberg-Marquardt iterations of each profile point's refit at most.
const PROFILE_ITERATIONS: usize = 8;

/// A profiled point: its distance from the optimum and the objective's
/// rise there.
type Point = (f64, f64);

/// One end of an interval being profiled: the distance `h` (normalised
/// units of its coordinate) from the optimum to try next, and the rises
/// measured (infinite: the engine failed there).
#[derive(Debug, Clone, PartialEq)]
struct End {
    h: f64,
    /// The distance to the bound on this side.
    room: f64,
    /// (distance, rise) measured, in order.
    points: Vec<Point>,
    done: bool,
}

impl End {
    fn new(h: f64, room: f64) -> End {
        End {
            h: h.min(room),
            room,
            points: Vec::new(),
            done: false,
        }
    }

    /// The rise's power of the distance, from the last two finite
    /// positive rises measured (2, a quadratic, with fewer), within 1 and
    /// 3.
    fn power(&self) -> f64 {
        let ok: Vec<&Point> = self
            .points
            .iter()
            .filter(|(_, r)| r.is_finite() && *r > 0.0)
            .collect();
        match ok.as_slice() {
            [.., (h1, r1), (h2, r2)] if (h2 / h1).ln().abs() > 1e-9 => {
                ((r2 / r1).ln() / (h2 / h1).ln()).clamp(1.0, 3.0)
            }
            _ => 2.0,
        }
    }

    /// The farthest distance where the rise stayed within `t`, and the
    /// nearest where it did not.
    fn bracket(&self, t: f64) -> (Option<Point>, Option<Point>) {
        let inside = self
            .points
            .iter()
            .filter(|(_, r)| *r <= t)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .copied();
        let outside = self
            .points
            .iter()
            .filter(|(_, r)| *r > t)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .copied();
        (inside, outside)
    }

    /// Records the rise `rise` at the current distance for the threshold
    /// `t`, and moves to the next distance to try: where the rise, as a
    /// power of the distance ([`End::power`]), reaches `t`, within a
    /// quarter and four times the distance, and inside what is bracketed.
    fn record(&mut self, rise: f64, t: f64) {
        let h = self.h;
        self.points.push((h, rise));
        if (rise <= t && h >= self.room) || (rise.is_finite() && (rise - t).abs() <= 0.1 * t) {
            // Within the threshold all the way to the bound, or within 10 %
            // of the threshold: no other point is needed.
            self.done = true;
            return;
        }
        let next = if !rise.is_finite() {
            h / 2.0
        } else if rise > 0.0 {
            h * (t / rise).powf(1.0 / self.power())
        } else {
            4.0 * h
        };
        let mut next = next.clamp(h / 4.0, 4.0 * h).min(self.room);
        if let (Some((a, _)), Some((b, _))) = self.bracket(t) {
            if !(next > a && next < b) {
                next = 0.5 * (a + b);
            }
        }
        self.h = next;
    }

    /// The end's distance: between the farthest point inside and the
    /// nearest outside, where the power law through them reaches `t`; the
    /// farthest point inside when none was outside (no farther than what
    /// was shown); short of the nearest outside by the rise's power when
    /// none was inside.
    fn distance(&self, t: f64) -> f64 {
        let p = self.power();
        match self.bracket(t) {
            (Some((a, ra)), Some((b, rb))) => {
                if rb.is_finite() && ra > 0.0 {
                    let q = ((rb / ra).ln() / (b / a).ln()).max(1e-9);
                    (a * (t / ra).powf(1.0 / q)).clamp(a, b)
                } else if rb.is_finite() {
                    (b * (t / rb).powf(1.0 / p)).clamp(a, b)
                } else {
                    a
                }
            }
            // Nothing measured beyond: the end is no farther than shown.
            (Some((a, _)), None) => a,
            (None, Some((b, rb))) if rb.is_finite() => b * (t / rb).powf(1.0 / p),
            (None, Some((b, _))) => b / 2.0,
            (None, None) => self.h,
        }
    }
}

/// The objective's rise over `objective` at `x` with coordinate `c` held
/// and the others refitted from `x` (one reweighted Levenberg-Marquardt
/// pass of [`PROFILE_ITERATIONS`] iterations at most): the lowest
/// objective of any point the refit simulated, infinite where the engine
/// fails at `x`; and the evaluations made.
fn profile_rise(
    t: &Tuner<'_>,
    x: &[f64],
    c: usize,
    objective: f64,
    options: FitOptions,
) -> (f64, usize) {
    let Ok(start) = t.errors(x) else {
        return (f64::INFINITY, 1);
    };
    let others: Vec<usize> = (0..x.len()).filter(|&o| o != c).collect();
    if others.is_empty() {
        return (start.objective() - objective, 1);
    }
    let weights = start.weights(IRLS_FLOOR_M);
    let full = |y: &[f64]| -> Vec<f64> {
        let mut z = x.to_vec();
        for (i, &o) in others.iter().enumerate() {
            z[o] = y[i];
        }
        z
    };
    // Every point the refit simulates holds `c` where the profile puts
    // it, so the lowest objective among them all (the Jacobian's columns
    // too) bounds the profile from above: the refit's end needs no
    // simulation of its own.
    let seen = Mutex::new((0usize, start.objective()));
    let f = |y: &[f64]| {
        let e = t.errors(&full(y));
        let mut seen = seen.lock().unwrap_or_else(|e| e.into_inner());
        seen.0 += 1;
        let e = e?;
        seen.1 = seen.1.min(e.objective());
        Ok(e.residuals(Some(&weights)))
    };
    let y0: Vec<f64> = others.iter().map(|&o| x[o]).collect();
    let options = FitOptions {
        max_iterations: PROFILE_ITERATIONS,
        ..options
    };
    // The start's residuals are known: the refit does not simulate it again.
    let r0 = Some(start.residuals(Some(&weights)));
    let _ = least_squares::levenberg_marquardt_from(&f, &y0, r0, None, options, &|_, _, _| {});
    let (count, lowest) = seen.into_inner().unwrap_or_else(|e| e.into_inner());
    (lowest - objective, 1 + count)
}

/// Profiles each interval's ends: coordinate `c` is held at a distance
/// from the optimum `u` and the others refitted ([`profile_rise`]),
/// starting where the local model refits them (`corr[o][c] sd_o / sd_c`
/// per unit of `c`); the end is where the objective has risen by
/// `threshold`. The model's end (`k sd_c`) is tried first, then where the
/// rise, as a power of the distance, reaches the threshold
/// ([`PROFILE_TRIALS`] at most). Returns each coordinate's ends in
/// normalised units (`None`: no interval) and the evaluations made.
fn profiled_ends(
    t: &Tuner<'_>,
    u: &[f64],
    objective: f64,
    threshold: f64,
    k: f64,
    spread: &least_squares::Spread,
    options: FitOptions,
) -> (Vec<[Option<f64>; 2]>, usize) {
    use rayon::prelude::*;
    let n = u.len();
    let sd = &spread.sd_u;
    let mut ends = vec![[None, None]; n];
    // (coordinate, slot, side, the end at the model's distance, the
    // direction the others move in).
    let mut tasks: Vec<(usize, usize, f64, End, Vec<f64>)> = Vec::new();
    for c in 0..n {
        let h = k * sd[c];
        if !(h.is_finite() && h > 0.0) {
            continue;
        }
        let w: Vec<f64> = (0..n)
            .map(|o| {
                let w = if o == c {
                    1.0
                } else {
                    spread.correlation[o][c] * sd[o] / sd[c]
                };
                if w.is_finite() {
                    w
                } else {
                    0.0
                }
            })
            .collect();
        for (slot, side) in [(0usize, -1.0f64), (1, 1.0)] {
            let room = if side > 0.0 { 1.0 - u[c] } else { u[c] };
            if room <= 0.0 {
                ends[c][slot] = Some(u[c]);
            } else {
                tasks.push((c, slot, side, End::new(h, room), w.clone()));
            }
        }
    }
    // The ends are profiled side by side: `--jobs` at a time here, all at
    // once on Slurm (so that their evaluations gather into arrays), each
    // refit's Jacobian one column at a time.
    let threads = if t.simulator.slurm.is_some() {
        tasks.len()
    } else {
        t.spec.search.jobs
    };
    let options = FitOptions { jobs: 1, ..options };
    let profiled: Vec<(f64, usize)> = least_squares::pool(threads).install(|| {
        tasks
            .par_iter()
            .map(|(c, _, side, end, w)| {
                let (c, side, mut end) = (*c, *side, end.clone());
                let mut evaluations = 0;
                for _ in 0..PROFILE_TRIALS {
                    if end.done {
                        break;
                    }
                    let x: Vec<f64> = u
                        .iter()
                        .zip(w)
                        .map(|(a, b)| (a + side * end.h * b).clamp(0.0, 1.0))
                        .collect();
                    let (rise, used) = profile_rise(t, &x, c, objective, options);
                    evaluations += used;
                    end.record(rise, threshold);
                }
                (u[c] + side * end.distance(threshold), evaluations)
            })
            .collect()
    });
    let mut evaluations = 0;
    for ((c, slot, _, _, _), (at, used)) in tasks.iter().zip(profiled) {
        ends[*c][*slot] = Some(at);
        evaluations += used;
    }
    (ends, evaluations)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dim(key: &str, low: f64, high: f64, scale: Scale) -> Dim {
        Dim {
            key: key.into(),
            low,
            high,
            scale,
            start: low,
        }
    }

    /// Profiles one end against `rise` (the objective's rise at a
    /// distance) from the model's distance `h0`, as [`profiled_ends`] does.
    fn profile(rise: &dyn Fn(f64) -> f64, h0: f64, room: f64, t: f64) -> (f64, usize) {
        let mut end = End::new(h0, room);
        let mut n = 0;
        while n < PROFILE_TRIALS && !end.done {
            end.record(rise(end.h), t);
            n += 1;
        }
        (end.distance(t), n)
    }

    #[test]
    fn a_profiled_end_is_where_the_rise_reaches_the_threshold() {
        let t = 0.1;
        // A quadratic rise reaching t at 0.2: from a model twice too wide
        // or twice too narrow, the second point is the end.
        let quad = |h: f64| t * (h / 0.2).powi(2);
        for h0 in [0.4, 0.1] {
            let (d, n) = profile(&quad, h0, 1.0, t);
            assert!((d - 0.2).abs() < 1e-12, "{h0}: {d}");
            assert_eq!(n, 2);
        }
        // The model right: one point.
        assert_eq!(profile(&quad, 0.205, 1.0, t).1, 1);
        // A rise linear in the distance (not the model's quadratic).
        let v = |h: f64| t * h / 0.2;
        for h0 in [0.1, 0.5] {
            let (d, _) = profile(&v, h0, 1.0, t);
            assert!((d - 0.2).abs() < 0.02, "{h0}: {d}");
        }
        // Flat to the bound: the end is the bound.
        assert_eq!(profile(&|_| 0.0, 0.1, 0.3, t), (0.3, 2));
        // Within the threshold at the bound after a rise: the bound.
        assert_eq!(profile(&|h: f64| t * (h / 0.4).powi(2), 0.1, 0.3, t).0, 0.3);
        // The engine fails beyond 0.15: the end stays before the failure.
        let fails = |h: f64| {
            if h > 0.15 {
                f64::INFINITY
            } else {
                t * (h / 0.5).powi(2)
            }
        };
        assert!(profile(&fails, 0.2, 1.0, t).0 <= 0.15);
    }

    #[test]
    fn widening_stays_within_physical_limits() {
        let d = dim("joints.j2.damping", 0.0, 5.0, Scale::Linear);
        assert!(widen(&d, false).is_none(), "damping cannot go below 0");
        assert_eq!(widen(&d, true).unwrap().high, 10.0);
        let k = dim("joints.j2.kv", 4.0, 4000.0, Scale::Log);
        assert_eq!(widen(&k, true).unwrap().high, 16000.0);
        assert_eq!(widen(&k, false).unwrap().low, 1.0);
        let o = dim("joints.j2.offset_deg", -3.0, 3.0, Scale::Linear);
        assert_eq!(widen(&o, true).unwrap().high, 9.0);
        let o2 = dim("joints.j2.offset_deg", -3.0, 9.0, Scale::Linear);
        assert_eq!(widen(&o2, true).unwrap().high, 10.0);
        let o3 = dim("joints.j2.offset_deg", -3.0, 10.0, Scale::Linear);
        assert!(widen(&o3, true).is_none(), "already at the limit");
        assert!(widen(&dim("objects.cube.unknown", 0.0, 1.0, Scale::Linear), true).is_none());
        let mass = dim("objects.cube.mass_kg", 0.05, 0.15, Scale::Linear);
        assert!(widen(&mass, false).is_none(), "a weighed mass stays");
        assert!(widen(&mass, true).is_none(), "a weighed mass stays");
        let delay = dim("controller.delay_s", 0.0, 0.15, Scale::Linear);
        assert_eq!(widen(&delay, true).unwrap().high, 0.3);
    }
}
