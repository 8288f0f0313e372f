//! The intervals and the identifiability at the optimum, read from the
//! Jacobian there ([`Linearised`], the one Jacobian holder of both tunes).
//!
//! - The study tune's check at the start ([`before`]), before CMA-ES.
//! - The study polish ([`polish`]): the Jacobian with the report's wider
//!   step ([`REPORT_STEP`]), the local model's interval per unit of
//!   standard deviation set by the real runs' noise, and each end
//!   profiled in a small space ([`crate::stages::profile::profiled_ends`]).
//! - The recordings tune (`recordings`): the fit's own Jacobian at the
//!   optimum (or one computed there), the residuals told apart into
//!   reading noise and structure ([`least_squares::misfit`]).

use crate::least_squares::{self, FitOptions, Linearised};
use crate::polish::{IdentifiabilityReport, ParamInterval, REPORT_STEP};
use crate::recordings::{FittedParam, Identifiability, Problem, Residuals};
use crate::stages::fit::Polishing;
use crate::stages::profile::{profiled_ends, PROFILE_MAX_COORDINATES};
use crate::Tuner;
use anyhow::{anyhow, Result};

/// The identifiability check of a study tune before its long search, at
/// the space's start (only with a polish); `None` when it could not be
/// measured (said in `note`).
pub fn before(tuner: &Tuner<'_>, note: &(dyn Fn(String) + Sync)) -> Option<IdentifiabilityReport> {
    let spec = tuner.spec;
    if spec.polish.iterations == 0 {
        return None;
    }
    note(format!(
        "identifiability at the start ({}): a Jacobian of {} coordinates",
        spec.engine,
        tuner.dims()
    ));
    let u0 = &spec.space.start_unit()[..tuner.dims()];
    match identifiability(tuner, u0, "start", None, None) {
        Ok((r, _, _)) => {
            note(crate::polish::identifiability_text(&r));
            Some(r)
        }
        Err(e) => {
            note(format!(
                "identifiability at the start: not measured ({e:#})"
            ));
            None
        }
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
    let lin = match jac {
        Some(j) => Linearised::new(u.to_vec(), r, j),
        None => {
            evaluations += u.len();
            Linearised::at_or_blind(&f, u, &r, REPORT_STEP, tuner.spec.search.jobs)
        }
    };
    let unmeasured: Vec<(String, String)> = lin
        .blind
        .iter()
        .map(|(i, why)| (names[*i].clone(), why.clone()))
        .collect();
    let s = lin.spread(1);
    let (j, r) = (&lin.jacobian, &lin.residuals);
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
            let g: f64 = col.iter().zip(r).map(|(a, b)| a * b).sum();
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

/// The polish's intervals and identifiability at the optimum of `state`,
/// and the parameters that end on a bound, into its report.
pub fn polish(
    tuner: &Tuner<'_>,
    state: &mut Polishing,
    fit_options: FitOptions,
    note: &(dyn Fn(String) + Sync),
) -> Result<()> {
    let final_spec = state.spec(tuner.spec);
    let t = Tuner {
        target: tuner.target,
        simulator: tuner.simulator,
        spec: &final_spec,
    };
    let (u, objective) = (state.u.clone(), state.objective);
    let report = &mut state.report;
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
    for (i, d) in state.space.dims.iter().enumerate() {
        if u[i] <= 1e-6 || u[i] >= 1.0 - 1e-6 {
            state.report.at_limit.push(d.key.clone());
        }
    }
    state.report.identifiability = Some(ident);
    Ok(())
}

/// The recordings tune's fitted parameters with their intervals and the
/// identifiability report at the fit's end `fit`: the residuals told apart
/// into reading noise and what the engine cannot reproduce
/// ([`least_squares::misfit`]), the structure measured over
/// [`crate::recordings::STRUCTURE_WINDOW_S`] of samples.
pub(crate) fn recordings(
    p: &Problem,
    fit: least_squares::Fit,
) -> Result<(Vec<FittedParam>, Identifiability)> {
    p.set_phase("intervals".into());
    let f = |x: &[f64]| -> Result<Vec<f64>, String> { p.residuals(&p.params(x)?) };
    let u = &fit.u;
    let lin = Linearised::at(
        &f,
        u,
        &fit.residuals,
        FitOptions::default().step,
        p.spec.jobs,
        fit.jacobian,
    )
    .map_err(|m| anyhow!("the Jacobian at the optimum: {m}"))?;
    let joints = p.spec.prepared.replayed_joints().len();
    let spread = lin.spread(joints);
    let misfit = lin.misfit(&p.blocks(), p.structure_window());
    let mut params_out = Vec::new();
    for (c, &i) in p.continuous.iter().enumerate() {
        let d = &p.space.dims[i];
        let value = d.value(u[c]);
        let half = misfit.half_width_u[c];
        let interval = half.is_finite().then(|| {
            let lo = d.value((u[c] - half).max(0.0));
            let hi = d.value((u[c] + half).min(1.0));
            (lo, hi)
        });
        params_out.push(FittedParam {
            key: d.key.clone(),
            start: d.start,
            value,
            interval,
            bounds: (d.low, d.high),
            at_bound: u[c] <= 1e-6 || u[c] >= 1.0 - 1e-6,
        });
    }
    let keys: Vec<String> = p
        .continuous
        .iter()
        .map(|&i| p.space.dims[i].key.clone())
        .collect();
    let mut unseen = Vec::new();
    for (c, k) in keys.iter().enumerate() {
        let col = lin.jacobian.column(c).norm();
        let width = 2.0 * misfit.half_width_u[c];
        if col == 0.0 || !width.is_finite() || width >= 1.0 {
            unseen.push(k.clone());
        }
    }
    let trading = least_squares::trading_pairs(&keys, &spread, &|_| false);
    let identifiability = Identifiability {
        unseen,
        trading,
        residual_autocorrelation: spread.rho,
        residuals: Residuals {
            count: misfit.n,
            rms_deg: misfit.rms,
            noise_deg: misfit.noise_sd,
            structure_deg: misfit.structure_rms,
            window_samples: misfit.window,
        },
    };
    Ok((params_out, identifiability))
}
