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
//!   ([`crate::stages::profile::profiled_ends`]), which follows a valley the quadratic model does
//!   not.
//! - **Identifiability.** The same Jacobian, at the start point before the
//!   search and at the optimum after it, names the parameters whose effect
//!   is below the noise (their interval spans the whole range) and the
//!   pairs that trade against each other (correlation beyond 0.95).

use crate::least_squares::FitOptions;
use crate::space::{Dim, Scale, Space};
use crate::stages;
use crate::Tuner;
use anyhow::Result;
use serde::Serialize;

pub use crate::stages::intervals::identifiability;
pub use crate::stages::profile::PROFILE_MAX_COORDINATES;

/// The forward-difference step (normalised units) of the Jacobians the
/// identifiability and the intervals are read from: 1 % of each range,
/// wide enough that a difference does not hinge on one contact event or
/// engine step.
pub const REPORT_STEP: f64 = 0.01;

/// Reweighting passes per polish round, at most ([`polish`]'s iteratively
/// reweighted least squares).
pub(crate) const IRLS_PASSES: usize = 6;

/// The error length below which the reweighting's weights stop growing,
/// metres: a tenth of a millimetre, under any capture's noise.
pub(crate) const IRLS_FLOOR_M: f64 = 1e-4;

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
    /// The objective the polish started from, metres: CMA-ES's best, or
    /// the space's start when that scored lower.
    pub start_objective_m: f64,
    /// The objective after the polish, metres.
    pub objective_m: f64,
    /// Simulations of the polish: the one at the space's start that picks
    /// where it starts ([`crate::fit`]), Jacobians, steps, probes.
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
/// object's mass and friction are none: the mass is weighed, not fitted,
/// and the friction is its material's, whose range the space states (a
/// block's on a table in the default spaces). A search that lightens the
/// cube (MuJoCo's and DART's wrist-only tunes took the study's 88 g cube
/// down to 1 g, which then flew 4.8 m) or makes it slippery as ice (the
/// tunes' 0.014-0.07) is buying wrist error with an impossible object;
/// their bounds stay where the space puts them.
pub fn physical_limits(key: &str) -> Option<(f64, f64)> {
    let field = key.rsplit('.').next().unwrap_or(key);
    if key.starts_with("objects.") && matches!(field, "mass_kg" | "friction") {
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
pub(crate) fn widen(d: &Dim, high_side: bool) -> Option<Dim> {
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

/// Polishes from `u0` (objective `start_objective`; the search's best
/// point, or the space's start when that scored lower):
/// the fit's rounds ([`stages::fit::polish_rounds`]), then the intervals
/// and the identifiability at the optimum
/// ([`stages::intervals::polish`]). `note` hears what the polish is doing.
pub fn polish(
    tuner: &Tuner<'_>,
    u0: &[f64],
    start_objective: f64,
    options: PolishOptions,
    note: &(dyn Fn(String) + Sync),
) -> Result<Polished> {
    let started = std::time::Instant::now();
    let mut state = stages::fit::Polishing::new(tuner.spec, u0, start_objective);
    let probe = if options.iterations == 0 {
        None
    } else {
        let fit_options = FitOptions {
            max_iterations: options.iterations,
            step: 1e-3,
            tolerance: 1e-4,
            jobs: tuner.spec.search.jobs,
            ..FitOptions::default()
        };
        let probe = stages::fit::polish_rounds(tuner, &mut state, options, fit_options, note)?;
        stages::intervals::polish(tuner, &mut state, fit_options, note)?;
        state.report.objective_m = state.objective;
        state.report.wall_time_s = started.elapsed().as_secs_f64();
        probe
    };
    Ok(Polished {
        space: state.space,
        u: state.u,
        objective_m: state.objective,
        report: state.report,
        probe,
    })
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
        let friction = dim("objects.cube.friction", 0.15, 1.0, Scale::Log);
        assert!(
            widen(&friction, false).is_none(),
            "a material's friction stays"
        );
        assert!(
            widen(&friction, true).is_none(),
            "a material's friction stays"
        );
        let joint = dim("joints.j2.frictionloss", 0.0, 2.0, Scale::Linear);
        assert!(
            widen(&joint, true).is_some(),
            "a joint's friction loss widens"
        );
        let delay = dim("controller.delay_s", 0.0, 0.15, Scale::Linear);
        assert_eq!(widen(&delay, true).unwrap().high, 0.3);
    }
}
