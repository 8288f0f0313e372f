//! The gradient fits ([`crate::least_squares`]).
//!
//! - The study polish ([`crate::polish::polish`]) from CMA-ES's best point:
//!   rounds of iteratively reweighted Levenberg-Marquardt
//!   ([`irls_round`]), bounds widened where they hold a coordinate
//!   ([`widen_held`]), and the probe that restarts it ([`probe`]).
//! - The recordings tune (`recordings`) from the delay's scan: a fit,
//!   the delay's profile (`crate::stages::profile::delay_steps`), and
//!   the last fit from the profile's best point.

use crate::least_squares::{self, Fit, FitOptions};
use crate::polish::{widen, PolishOptions, PolishReport, Widened, IRLS_FLOOR_M, IRLS_PASSES};
use crate::recordings::Problem;
use crate::space::Space;
use crate::stages::profile;
use crate::{TuneSpec, Tuner};
use anyhow::{anyhow, Result};
use std::sync::Mutex;

/// A polish under way: the space searched (bounds widened where they
/// were), the point, its objective and the account so far.
pub struct Polishing {
    /// The space searched.
    pub space: Space,
    /// The point, normalised in `space`.
    pub u: Vec<f64>,
    /// Its objective, metres.
    pub objective: f64,
    /// The account.
    pub report: PolishReport,
    /// Rounds that widened bounds.
    pub widen_rounds: usize,
}

impl Polishing {
    /// At `u0` (objective `start_objective`; CMA-ES's best point, or the
    /// space's start when that scored lower) in the space of `spec`.
    pub fn new(spec: &TuneSpec, u0: &[f64], start_objective: f64) -> Polishing {
        Polishing {
            space: spec.space.clone(),
            u: u0.to_vec(),
            objective: start_objective,
            report: PolishReport {
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
            },
            widen_rounds: 0,
        }
    }

    /// The spec of the space searched now (no physics-free row).
    pub fn spec(&self, spec: &TuneSpec) -> TuneSpec {
        TuneSpec {
            baseline_space: None,
            ..spec.with_space(self.space.clone())
        }
    }
}

/// The polish's rounds until the probe finds no better point, a bound
/// cannot move, or the evaluations are spent: each round reweighted
/// least squares, then bounds widened, else the probe. Returns the last
/// probe around the optimum (`None`: the point moved after it).
pub fn polish_rounds(
    tuner: &Tuner<'_>,
    state: &mut Polishing,
    options: PolishOptions,
    fit_options: FitOptions,
    note: &(dyn Fn(String) + Sync),
) -> Result<Option<Vec<crate::outputs::Sensitivity>>> {
    loop {
        realitygap_runner::interrupt::check()?;
        let round_spec = state.spec(tuner.spec);
        let t = Tuner {
            target: tuner.target,
            simulator: tuner.simulator,
            spec: &round_spec,
        };
        state.report.rounds += 1;
        note(format!(
            "polish round {}: reweighted least squares from {:.4} m over {} coordinates",
            state.report.rounds,
            state.objective,
            state.u.len()
        ));
        irls_round(&t, state, options, fit_options, note)?;
        if state.report.evaluations >= options.max_evaluations {
            state.report.reason = format!(
                "{} (the polish's {} evaluations are spent)",
                state.report.reason, options.max_evaluations
            );
            return Ok(None);
        }
        // Parameters on a bound: widen, and go on from the same point.
        if state.widen_rounds < options.widen_rounds && widen_held(&t, state, note) {
            continue;
        }
        if let Some(last) = probe(&t, state, options, note) {
            return Ok(last);
        }
    }
}

/// One round of iteratively reweighted least squares: each pass fixes
/// weights at its start (each error's length to the power -1/2, so that
/// the squares sum to the objective there) and runs Levenberg-Marquardt on
/// the weighted error components, which are smooth where the square roots
/// of the lengths are not (near a good fit); passes go on while the
/// objective itself falls.
pub fn irls_round(
    t: &Tuner<'_>,
    state: &mut Polishing,
    options: PolishOptions,
    fit_options: FitOptions,
    note: &(dyn Fn(String) + Sync),
) -> Result<()> {
    let mut fit_reason = String::new();
    // The round's iterations (`--iterations`) are shared by its passes,
    // so that a round costs what one Levenberg-Marquardt run did and
    // the budget leaves room for the rounds after a widening.
    let mut round_iterations = fit_options.max_iterations;
    // The errors at `u`: simulated at the round's start, then those
    // the last pass ended on (its end is the next pass's start).
    let mut at_u: Option<crate::objective::Errors> = None;
    for pass in 0..IRLS_PASSES {
        let report = &mut state.report;
        let count = Mutex::new(0usize);
        let errors = match at_u.take() {
            Some(e) => e,
            None => {
                report.evaluations += 1;
                t.errors(&state.u)
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
            max_iterations: round_iterations.min((left / (state.u.len() + 1)).max(1)),
            ..fit_options
        };
        let fit = least_squares::levenberg_marquardt(&f, &state.u, round_options, &|_, _, _| {})
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
            Some(e) if e.objective() < state.objective => {
                let o = e.objective();
                let gain = (state.objective - o) / state.objective.max(f64::MIN_POSITIVE);
                state.u = fit.u.clone();
                state.objective = o;
                at_u = Some(e);
                gain
            }
            _ => 0.0,
        };
        note(format!(
            "  pass {}: {:.4} m after {} iterations ({})",
            pass + 1,
            state.objective,
            fit.iterations,
            fit.reason
        ));
        if gain < fit_options.tolerance
            || round_iterations == 0
            || state.report.evaluations + state.u.len() + 2 >= options.max_evaluations
        {
            break;
        }
    }
    state.report.reason = fit_reason;
    Ok(())
}

/// Widens the bounds that hold a coordinate (a step inward, 1 % of the
/// range, raises the objective: not the coordinates that sit there
/// because they do not matter), the point kept; true when one moved.
pub fn widen_held(t: &Tuner<'_>, state: &mut Polishing, note: &(dyn Fn(String) + Sync)) -> bool {
    let (space, u, objective) = (&state.space, &state.u, state.objective);
    let values = space.values(u);
    let mut next = space.clone();
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
        least_squares::pool(t.spec.search.jobs).install(|| {
            at_bound
                .par_iter()
                .map(|&(i, high)| {
                    let mut x = u.clone();
                    x[i] += if high { -0.01 } else { 0.01 };
                    match t.residuals(&x) {
                        Ok(r) => r.iter().map(|v| v * v).sum::<f64>() > objective * (1.0 + 1e-6),
                        Err(_) => false,
                    }
                })
                .collect()
        })
    };
    let report = &mut state.report;
    report.evaluations += at_bound.len();
    let mut moved = false;
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
    if !moved {
        return false;
    }
    state.widen_rounds += 1;
    for (i, d) in next.dims.iter().enumerate() {
        state.u[i] = d.unit(values[i]);
    }
    state.space = next;
    note(format!(
        "  widened: {}",
        state
            .report
            .widened
            .iter()
            .map(|w| format!("{} {} {} -> {}", w.key, w.side, w.from, w.to))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    true
}

/// The probe: 10 % either way of each parameter. `None`: a better point
/// was found and the polish goes on from it; `Some`: the polish ends,
/// with the last probe when the point did not move after it.
pub fn probe(
    t: &Tuner<'_>,
    state: &mut Polishing,
    options: PolishOptions,
    note: &(dyn Fn(String) + Sync),
) -> Option<Option<Vec<crate::outputs::Sensitivity>>> {
    let probe = crate::outputs::sensitivity(t, &state.u, state.objective);
    state.report.evaluations += 2 * probe.len();
    let objective = state.objective;
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
    let Some((key, o, v)) = better else {
        state.report.probe_clean = true;
        return Some(Some(probe));
    };
    let restart = state.report.probe_restarts < options.probe_restarts;
    if restart {
        state.report.probe_restarts += 1;
        note(format!(
            "  the probe found {o:.4} m at {key} = {v:.6}: not converged, going on from there"
        ));
    } else {
        // No restarts left: keep the better point, unpolished.
        state.report.probe_clean = false;
        note(format!(
            "  the probe found {o:.4} m at {key} = {v:.6}; no restarts left: the search has not converged"
        ));
    }
    if let Some(i) = state.space.dims.iter().position(|d| d.key == key) {
        state.u[i] = state.space.dims[i].unit(v);
    }
    state.objective = o;
    if restart {
        None
    } else {
        Some(None)
    }
}

/// The recordings tune's fit: its end, Jacobians computed by differences
/// over all its rounds, and why the last round stopped.
pub struct RecordingsFit {
    /// The last round's end.
    pub fit: Fit,
    /// Jacobians computed by differences, all rounds.
    pub iterations: usize,
    /// Why the last round stopped.
    pub reason: String,
}

/// The recordings tune's fit from `u` (the delay's scan's best point, its
/// residuals `start_residuals` when known): Levenberg-Marquardt on every
/// parameter; with a delay, its profile at whole engine steps around the
/// fit (`profile::delay_steps`) and the last fit, the delay free again,
/// from the profile's best point.
pub(crate) fn recordings(
    p: &Problem,
    u: &[f64],
    start_residuals: Option<Vec<f64>>,
) -> Result<RecordingsFit> {
    p.set_phase("Levenberg-Marquardt".into());
    let f = |x: &[f64]| -> Result<Vec<f64>, String> {
        let params = p.params(x)?;
        p.residuals(&params)
    };
    // Between Jacobians (one replay per coordinate each), accepted steps
    // update the last one (Broyden); convergence is declared on one
    // computed at the optimum, which also gives the intervals. With the
    // delay's profile to follow, the first fit need not be certified: the
    // last fit, from the profile's best point, is. A fit that ends within
    // a tenth of a standard deviation of its last Jacobian's point (in
    // every coordinate) is certified on that Jacobian: another one there
    // would move no interval by more than that.
    let options = FitOptions {
        max_iterations: p.spec.max_iterations,
        jobs: p.spec.jobs,
        secant: true,
        settle: 0.1,
        series: p.spec.prepared.replayed_joints().len(),
        ..FitOptions::default()
    };
    let first_options = FitOptions {
        certify: p.delay.is_none(),
        ..options
    };
    let record = |phase: &str, x: &[f64], cost: f64| p.record(phase, &p.values(x), cost);
    let fit = least_squares::levenberg_marquardt_from(
        &f,
        u,
        start_residuals,
        None,
        first_options,
        &record,
    )
    .map_err(|m| anyhow!("the fit failed: {m}"))?;
    let Some((c, d)) = p.delay_coordinate() else {
        return Ok(RecordingsFit {
            iterations: fit.iterations,
            reason: fit.reason.clone(),
            fit,
        });
    };
    // The last fit, with the delay free again, from the best point: the
    // profile's, or the first fit's.
    let (from, residuals, guess) = match profile::delay_steps(p, c, d, &fit)? {
        Some(best) if best.cost < fit.cost => (best.u, best.residuals, best.last_jacobian),
        _ => (
            fit.u.clone(),
            fit.residuals.clone(),
            fit.last_jacobian.clone(),
        ),
    };
    p.set_phase("Levenberg-Marquardt from the profile's best delay".into());
    let last = least_squares::levenberg_marquardt_from(
        &f,
        &from,
        Some(residuals),
        guess,
        options,
        &record,
    )
    .map_err(|m| anyhow!("the fit failed: {m}"))?;
    Ok(RecordingsFit {
        iterations: fit.iterations + last.iterations,
        reason: last.reason.clone(),
        fit: last,
    })
}
