//! Bounded Levenberg-Marquardt on a residual vector, with the Jacobian by
//! forward differences (its columns evaluated in parallel), and the
//! confidence intervals and identifiability of the fitted coordinates
//! from that Jacobian.
//!
//! Coordinates live in the unit box `[0, 1]^n` (a [`crate::space::Space`]'s
//! normalised coordinates): a step that would leave the box is projected
//! back onto it, and a coordinate held at a bound by the gradient is
//! reported as such.
//!
//! Two spreads of the fitted coordinates come from that Jacobian:
//!
//! - [`spread`], the Gauss-Newton covariance `s^2 (J^T J)^-1` (what
//!   `mujoco.sysid` gives) with the residual count reduced for the
//!   residuals' lag-1 autocorrelation `rho` (`n_eff = n (1 - rho) / (1 +
//!   rho)`, the AR(1) effective sample size): the polish's intervals, the
//!   correlations of pairs, and the standard deviations a fit settles in;
//! - [`misfit`], the intervals of `tune --recordings`: the residuals told
//!   apart into white noise (Gauss-Newton's share) and structure the model
//!   cannot reproduce, which bounds how far such an error could have
//!   shifted each coordinate. Reading noise drives `rho`, and with it the
//!   first's width, to nothing while the model's error stays; the second
//!   does not depend on `rho`.

use cmaes::DVector;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Serialize;

/// A residual function: coordinates in `[0, 1]^n` to the residual
/// vector (always the same length), or why it could not be evaluated.
pub type Residuals<'a> = dyn Fn(&[f64]) -> Result<Vec<f64>, String> + Sync + 'a;

/// Settings of a fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Iterations (Jacobians) at most.
    pub max_iterations: usize,
    /// Forward-difference step in normalised units.
    pub step: f64,
    /// The fit has converged when an accepted step lowers the cost by less
    /// than this fraction.
    pub tolerance: f64,
    /// Parallel evaluations of the Jacobian's columns.
    pub jobs: usize,
    /// Between Jacobians computed by differences (`n` evaluations each),
    /// update the last one after each accepted step by Broyden's rule (no
    /// evaluation). A Jacobian is computed afresh when a step from an
    /// updated one is rejected, after `n` updates, and (with `certify`)
    /// before the fit is declared converged.
    pub secant: bool,
    /// With `secant`, declare convergence only on a Jacobian computed at
    /// the point: off, an updated one may end the fit (a rough fit, such
    /// as one point of a profile).
    pub certify: bool,
    /// With `certify`: a fit whose every coordinate lies within this many
    /// of its standard deviations of the point of the last Jacobian
    /// computed by differences is certified on that Jacobian (it would
    /// give the same intervals) instead of computing another one. 0: off.
    pub settle: f64,
    /// The residuals interleave this many series (joints, sample by
    /// sample): the lag of their autocorrelation, for the standard
    /// deviations `settle` measures in (see [`spread`]).
    pub series: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            max_iterations: 30,
            step: 1e-3,
            tolerance: 1e-6,
            jobs: 1,
            secant: false,
            certify: true,
            settle: 0.0,
            series: 1,
        }
    }
}

/// The end of a fit.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The best coordinates found.
    pub u: Vec<f64>,
    /// Their residuals.
    pub residuals: Vec<f64>,
    /// Sum of squared residuals there.
    pub cost: f64,
    /// Sum of squared residuals at the start.
    pub start_cost: f64,
    /// The Jacobian at `u` (residuals x coordinates), when one was
    /// computed there.
    pub jacobian: Option<DMatrix<f64>>,
    /// The Jacobian the fit ended with: `jacobian`, or else the last one
    /// computed or updated (an approximation at `u`, a guess for a
    /// neighbouring fit).
    pub last_jacobian: Option<DMatrix<f64>>,
    /// Iterations (Jacobians) done.
    pub iterations: usize,
    /// Residual evaluations done.
    pub evaluations: usize,
    /// Why it stopped.
    pub reason: String,
}

fn cost_of(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// The Jacobian of `f` at `u` (with residuals `r0` there) by forward
/// differences of `step` (backward at the upper bound), its columns in
/// parallel on `jobs` threads. `Err` names the first coordinate whose
/// perturbation could not be evaluated.
pub fn jacobian(
    f: &Residuals,
    u: &[f64],
    r0: &[f64],
    step: f64,
    jobs: usize,
) -> Result<DMatrix<f64>, String> {
    let columns: Vec<Result<Vec<f64>, String>> = pool(jobs).install(|| {
        (0..u.len())
            .into_par_iter()
            .map(|i| column(f, u, r0, step, i).map_err(|m| format!("coordinate {i}: {m}")))
            .collect()
    });
    let mut j = DMatrix::zeros(r0.len(), u.len());
    for (i, c) in columns.into_iter().enumerate() {
        j.set_column(i, &DVector::from_vec(c?));
    }
    Ok(j)
}

/// Columns `which` of the Jacobian at `u` (as [`jacobian`] computes them).
fn columns(
    f: &Residuals,
    u: &[f64],
    r0: &[f64],
    step: f64,
    jobs: usize,
    which: &[usize],
) -> Result<Vec<Vec<f64>>, String> {
    pool(jobs).install(|| {
        which
            .par_iter()
            .map(|&i| column(f, u, r0, step, i).map_err(|m| format!("coordinate {i}: {m}")))
            .collect()
    })
}

/// [`jacobian`] for a report: a coordinate whose column cannot be
/// evaluated either way (the engine diverges on both sides) gets a zero
/// column (the data then say nothing of it) and is listed with why.
pub fn jacobian_or_blind(
    f: &Residuals,
    u: &[f64],
    r0: &[f64],
    step: f64,
    jobs: usize,
) -> (DMatrix<f64>, Vec<(usize, String)>) {
    let columns: Vec<Result<Vec<f64>, String>> = pool(jobs).install(|| {
        (0..u.len())
            .into_par_iter()
            .map(|i| column(f, u, r0, step, i))
            .collect()
    });
    let mut j = DMatrix::zeros(r0.len(), u.len());
    let mut blind = Vec::new();
    for (i, c) in columns.into_iter().enumerate() {
        match c {
            Ok(c) => j.set_column(i, &DVector::from_vec(c)),
            Err(m) => blind.push((i, m)),
        }
    }
    (j, blind)
}

/// The residuals linearised at a point: the point, its residuals and the
/// Jacobian there (residuals x coordinates), with the coordinates whose
/// column could not be evaluated (their columns are zero). The one holder
/// of a Jacobian for both tunes: the fit's anchor ([`FitOptions::settle`]),
/// and the intervals and identifiability at the optimum
/// ([`crate::stages::intervals`]).
#[derive(Debug, Clone)]
pub struct Linearised {
    /// The point, normalised.
    pub u: Vec<f64>,
    /// The residuals there.
    pub residuals: Vec<f64>,
    /// The Jacobian there.
    pub jacobian: DMatrix<f64>,
    /// Coordinates whose column could not be evaluated either way, with
    /// why (only from [`Linearised::at_or_blind`]).
    pub blind: Vec<(usize, String)>,
}

impl Linearised {
    /// A Jacobian already at hand (a fit's) at `u`, residuals `r`.
    pub fn new(u: Vec<f64>, residuals: Vec<f64>, jacobian: DMatrix<f64>) -> Linearised {
        Linearised {
            u,
            residuals,
            jacobian,
            blind: Vec::new(),
        }
    }

    /// [`jacobian`] at `u` (residuals `r`), or the fit's own there when
    /// it has one (`given`).
    pub fn at(
        f: &Residuals,
        u: &[f64],
        r: &[f64],
        step: f64,
        jobs: usize,
        given: Option<DMatrix<f64>>,
    ) -> Result<Linearised, String> {
        let j = match given {
            Some(j) => j,
            None => jacobian(f, u, r, step, jobs)?,
        };
        Ok(Linearised::new(u.to_vec(), r.to_vec(), j))
    }

    /// [`jacobian_or_blind`] at `u` (residuals `r`).
    pub fn at_or_blind(f: &Residuals, u: &[f64], r: &[f64], step: f64, jobs: usize) -> Linearised {
        let (jacobian, blind) = jacobian_or_blind(f, u, r, step, jobs);
        Linearised {
            u: u.to_vec(),
            residuals: r.to_vec(),
            jacobian,
            blind,
        }
    }

    /// The spread of the coordinates ([`spread`]).
    pub fn spread(&self, lag: usize) -> Spread {
        spread(&self.jacobian, &self.residuals, lag)
    }

    /// The misfit's intervals ([`misfit`]).
    pub fn misfit(&self, blocks: &[Block], window: usize) -> Misfit {
        misfit(&self.jacobian, &self.residuals, blocks, window)
    }
}

/// Column `i` of the Jacobian: forward, or backward at the upper bound or
/// where the forward point cannot be evaluated (a diverging engine).
fn column(f: &Residuals, u: &[f64], r0: &[f64], step: f64, i: usize) -> Result<Vec<f64>, String> {
    let first = if u[i] + step <= 1.0 { step } else { -step };
    let mut last = String::new();
    for h in [first, -first] {
        if !(0.0..=1.0).contains(&(u[i] + h)) {
            continue;
        }
        let mut x = u.to_vec();
        x[i] += h;
        match f(&x) {
            Ok(r) if r.len() != r0.len() => {
                return Err(format!("{} residuals, {} at the centre", r.len(), r0.len()))
            }
            Ok(r) => return Ok(r.iter().zip(r0).map(|(a, b)| (a - b) / h).collect()),
            Err(m) => last = m,
        }
    }
    Err(last)
}

/// A pool of `jobs` threads (one when it cannot be built).
pub(crate) fn pool(jobs: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .unwrap_or_else(|_| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .expect("a one-thread pool")
        })
}

/// Levenberg-Marquardt from `u0` in the unit box. `on_evaluation` is told
/// the cost of every evaluation at the fit's own points (not the
/// Jacobian's columns), with a label of the phase.
pub fn levenberg_marquardt(
    f: &Residuals,
    u0: &[f64],
    options: FitOptions,
    on_evaluation: &(dyn Fn(&str, &[f64], f64) + Sync),
) -> Result<Fit, String> {
    levenberg_marquardt_from(f, u0, None, None, options, on_evaluation)
}

/// [`levenberg_marquardt`] with a first guess of the Jacobian at `u0`
/// (residuals x coordinates; used with [`FitOptions::secant`], as an
/// updated Jacobian is): a neighbouring fit's, say. Columns of the guess
/// that are not finite are computed by differences at the start; a guess
/// of the wrong shape is ignored. `r0`, the residuals at `u0` when they
/// are known (a scan's best point), saves the first evaluation; they are
/// ignored when `u0` lies outside the unit box.
pub fn levenberg_marquardt_from(
    f: &Residuals,
    u0: &[f64],
    r0: Option<Vec<f64>>,
    guess: Option<DMatrix<f64>>,
    options: FitOptions,
    on_evaluation: &(dyn Fn(&str, &[f64], f64) + Sync),
) -> Result<Fit, String> {
    let mut lm = Lm::start(f, u0, r0, options, on_evaluation)?;
    let start_cost = lm.cost;
    if lm.u.is_empty() {
        return Ok(lm.end(start_cost, "nothing to fit".into()));
    }
    lm.take_guess(guess);
    let reason = loop {
        if let Some(reason) = lm.iterate() {
            break reason;
        }
    };
    Ok(lm.end(start_cost, reason))
}

/// A Levenberg-Marquardt fit under way ([`levenberg_marquardt_from`]).
struct Lm<'f, 'a> {
    f: &'f Residuals<'a>,
    options: FitOptions,
    on_evaluation: &'f (dyn Fn(&str, &[f64], f64) + Sync),
    u: Vec<f64>,
    r: Vec<f64>,
    cost: f64,
    lambda: f64,
    iterations: usize,
    evaluations: usize,
    /// The Jacobian in use.
    jac: Option<DMatrix<f64>>,
    /// `jac` was computed by differences at `u` (a rejected trial leaves
    /// it so).
    fresh: bool,
    /// The next step needs a Jacobian computed by differences.
    refresh: bool,
    /// Broyden updates since the last Jacobian computed by differences.
    updates: usize,
    /// With `settle`: the last Jacobian computed by differences, its point
    /// and the standard deviations it gives the coordinates.
    anchor: Option<Anchor>,
}

/// The linear model of one iteration: the free coordinates (those no
/// bound holds), their normal matrix and gradient.
struct Model {
    free: Vec<usize>,
    a: DMatrix<f64>,
    g: DVector<f64>,
    /// What an updated Jacobian cannot conclude, one computed at `u` (or,
    /// with `settle`, near enough) decides.
    unsure: bool,
}

impl<'f, 'a> Lm<'f, 'a> {
    /// At `u0` clamped to the box, its residuals evaluated unless given.
    fn start(
        f: &'f Residuals<'a>,
        u0: &[f64],
        r0: Option<Vec<f64>>,
        options: FitOptions,
        on_evaluation: &'f (dyn Fn(&str, &[f64], f64) + Sync),
    ) -> Result<Self, String> {
        let u: Vec<f64> = u0.iter().map(|x| x.clamp(0.0, 1.0)).collect();
        let mut evaluations = 0usize;
        let r = match r0.filter(|_| u == u0) {
            Some(r) => r,
            None => {
                evaluations += 1;
                f(&u).map_err(|m| format!("at the start: {m}"))?
            }
        };
        let cost = cost_of(&r);
        on_evaluation("start", &u, cost);
        Ok(Lm {
            f,
            options,
            on_evaluation,
            u,
            r,
            cost,
            lambda: 1e-3,
            iterations: 0,
            evaluations,
            jac: None,
            fresh: false,
            refresh: true,
            updates: 0,
            anchor: None,
        })
    }

    /// Starts from `guess` (with `secant`, of the right shape), its
    /// columns that are not finite computed by differences.
    fn take_guess(&mut self, guess: Option<DMatrix<f64>>) {
        let n = self.u.len();
        let secant = self.options.secant;
        self.jac = guess.filter(|j| j.nrows() == self.r.len() && j.ncols() == n && secant);
        self.refresh = self.jac.is_none();
        let Some(j) = self.jac.as_mut() else {
            return;
        };
        let missing: Vec<usize> = (0..n)
            .filter(|&i| j.column(i).iter().any(|x| !x.is_finite()))
            .collect();
        if missing.is_empty() {
            return;
        }
        let (step, jobs) = (self.options.step, self.options.jobs);
        match columns(self.f, &self.u, &self.r, step, jobs, &missing) {
            Ok(cols) => {
                self.evaluations += missing.len();
                for (i, c) in missing.iter().zip(cols) {
                    j.set_column(*i, &DVector::from_vec(c));
                }
            }
            Err(_) => self.refresh = true,
        }
    }

    /// One iteration: a Jacobian when one is needed, then damped steps
    /// until one is accepted. `Some`: why the fit stops.
    fn iterate(&mut self) -> Option<String> {
        if self.refresh {
            if let Err(reason) = self.recompute() {
                return Some(reason);
            }
        }
        let model = match self.model() {
            Ok(model) => model,
            Err(reason) => return reason,
        };
        self.damped_steps(&model)
    }

    /// A Jacobian computed by differences at `u`; `Err`: why the fit
    /// stops.
    fn recompute(&mut self) -> Result<(), String> {
        let o = self.options;
        if self.iterations >= o.max_iterations {
            return Err("the iteration limit".to_string());
        }
        let j = jacobian(self.f, &self.u, &self.r, o.step, o.jobs)
            .map_err(|m| format!("the Jacobian could not be evaluated ({m})"))?;
        self.evaluations += self.u.len();
        self.iterations += 1;
        self.fresh = true;
        self.updates = 0;
        if o.secant && o.certify && o.settle > 0.0 {
            let sd = spread(&j, &self.r, o.series).sd_u;
            self.anchor = Some(Anchor {
                at: Linearised::new(self.u.clone(), self.r.clone(), j.clone()),
                sd,
            });
        }
        self.jac = Some(j);
        Ok(())
    }

    /// The iteration's linear model; `Err(Some)`: why the fit stops,
    /// `Err(None)`: a Jacobian is needed first.
    fn model(&mut self) -> Result<Model, Option<String>> {
        let Some(j) = self.jac.as_ref() else {
            return Err(Some("no Jacobian".to_string()));
        };
        let n = self.u.len();
        let jt = j.transpose();
        let a = &jt * j;
        let g = &jt * DVector::from_column_slice(&self.r);
        // Coordinates held at a bound by the gradient stay there this
        // iteration (an active set): a step computed as if they could
        // cross the bound, then clipped, is a poor step.
        let u = &self.u;
        let free: Vec<usize> = (0..n)
            .filter(|&i| !((u[i] <= 0.0 && g[i] > 0.0) || (u[i] >= 1.0 && g[i] < 0.0)))
            .collect();
        let unsure =
            !self.fresh && self.options.certify && !settled(u, &self.anchor, self.options.settle);
        if free.is_empty() {
            return Err(self.unless_unsure(unsure, "every coordinate is held at a bound"));
        }
        let nf = free.len();
        let af = DMatrix::from_fn(nf, nf, |r, c| a[(free[r], free[c])]);
        let gf = DVector::from_fn(nf, |r, _| g[free[r]]);
        Ok(Model {
            free,
            a: af,
            g: gf,
            unsure,
        })
    }

    /// `None` (and a Jacobian computed at `u` next) when `unsure`, else
    /// `reason` to stop.
    fn unless_unsure(&mut self, unsure: bool, reason: &str) -> Option<String> {
        if unsure {
            self.refresh = true;
            None
        } else {
            Some(reason.to_string())
        }
    }

    /// Damped steps on `model` until one is accepted (`None`: the next
    /// iteration) or the fit stops (`Some`: why).
    fn damped_steps(&mut self, model: &Model) -> Option<String> {
        let (af, gf, nf) = (&model.a, &model.g, model.free.len());
        loop {
            let mut m = af.clone();
            for i in 0..nf {
                m[(i, i)] += self.lambda * af[(i, i)].max(1e-12) + 1e-12;
            }
            let Some(chol) = m.cholesky() else {
                self.lambda *= 10.0;
                if self.lambda > 1e12 {
                    if !self.fresh {
                        self.refresh = true;
                        return None;
                    }
                    return Some("the normal equations are singular".to_string());
                }
                continue;
            };
            let step = chol.solve(&(-gf));
            let trial = self.trial(&model.free, &step);
            let moved = trial
                .iter()
                .zip(&self.u)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            if moved < 1e-10 {
                return self
                    .unless_unsure(model.unsure, "the step vanished (at a bound or a minimum)");
            }
            // The cost's fall the linear model predicts for this step
            // (-2 g'd - d'Ad): the damping only shrinks it, so once it is
            // below the tolerance no trial can gain more than that and
            // the fit has converged (without spending the evaluations of
            // a chain of rejected trials on it).
            let predicted = -2.0 * gf.dot(&step) - step.dot(&(af * &step));
            if predicted < self.options.tolerance * self.cost {
                let reason = format!(
                    "converged (the linear model predicts a gain of {:.1e} of the cost)",
                    predicted / self.cost.max(f64::MIN_POSITIVE)
                );
                return self.unless_unsure(model.unsure, &reason);
            }
            if let Some(next) = self.try_step(trial, model.unsure) {
                return next;
            }
        }
    }

    /// The point `step` (over the free coordinates) leads to, in the box.
    fn trial(&self, free: &[usize], step: &DVector<f64>) -> Vec<f64> {
        let mut delta = vec![0.0; self.u.len()];
        for (k, &i) in free.iter().enumerate() {
            delta[i] = step[k];
        }
        self.u
            .iter()
            .zip(&delta)
            .map(|(x, d)| (x + d).clamp(0.0, 1.0))
            .collect()
    }

    /// Evaluates `trial`: accepted when it lowers the cost. `None`: damp
    /// more and try again; `Some(None)`: the next iteration;
    /// `Some(Some)`: the fit stops, and why.
    fn try_step(&mut self, trial: Vec<f64>, unsure: bool) -> Option<Option<String>> {
        self.evaluations += 1;
        match (self.f)(&trial) {
            Ok(rt) if rt.len() == self.r.len() && cost_of(&rt) < self.cost => {
                return Some(self.accept(trial, rt, unsure));
            }
            Ok(rt) => {
                if rt.len() == self.r.len() {
                    (self.on_evaluation)("rejected", &trial, cost_of(&rt));
                }
            }
            Err(_) => {
                (self.on_evaluation)("failed", &trial, f64::INFINITY);
            }
        }
        // A rejected step from an updated Jacobian says more of the
        // Jacobian than of the damping.
        if !self.fresh {
            self.refresh = true;
            return Some(None);
        }
        self.lambda *= 4.0;
        if self.lambda > 1e10 {
            return Some(Some("no step lowers the cost (converged)".to_string()));
        }
        None
    }

    /// Moves to the accepted `trial` (residuals `rt`); `Some`: the fit
    /// has converged.
    fn accept(&mut self, trial: Vec<f64>, rt: Vec<f64>, unsure: bool) -> Option<String> {
        let new_cost = cost_of(&rt);
        (self.on_evaluation)("step", &trial, new_cost);
        let gain = (self.cost - new_cost) / self.cost.max(f64::MIN_POSITIVE);
        if self.options.secant {
            // Broyden's rank-one update: the Jacobian now maps this step
            // to the change of the residuals it made.
            if let Some(j) = self.jac.as_mut() {
                broyden(j, &trial, &self.u, &rt, &self.r);
            }
            self.updates += 1;
            // A Jacobian updated as many times as there are coordinates
            // is computed afresh.
            self.refresh = self.updates >= self.u.len();
        } else {
            self.refresh = true;
        }
        self.fresh = false;
        self.u = trial;
        self.r = rt;
        self.cost = new_cost;
        self.lambda = (self.lambda / 3.0).max(1e-9);
        if gain < self.options.tolerance {
            let settled = settled(&self.u, &self.anchor, self.options.settle);
            let reason = format!("converged (the last step gained {gain:.1e} of the cost)");
            return self.unless_unsure(unsure && !settled, &reason);
        }
        None
    }

    /// The fit's end. A fit certified near its last Jacobian computed by
    /// differences ends on that one.
    fn end(self, start_cost: f64, reason: String) -> Fit {
        let o = self.options;
        let (jacobian, reason) = if self.fresh {
            (self.jac.clone(), reason)
        } else if o.certify && settled(&self.u, &self.anchor, o.settle) {
            let within = format!(
                "{reason}; every coordinate within {} standard deviations of the last Jacobian's point",
                o.settle
            );
            (self.anchor.map(|a| a.at.jacobian), within)
        } else {
            (None, reason)
        };
        Fit {
            u: self.u,
            residuals: self.r,
            cost: self.cost,
            start_cost,
            jacobian,
            last_jacobian: self.jac,
            iterations: self.iterations,
            evaluations: self.evaluations,
            reason,
        }
    }
}

/// The last Jacobian computed by differences (for [`FitOptions::settle`])
/// and the standard deviations it gives the coordinates.
struct Anchor {
    at: Linearised,
    sd: Vec<f64>,
}

/// Whether every coordinate of `u` lies within `settle` standard
/// deviations of the anchor's point (never when `settle` is 0 or a
/// deviation is not finite).
fn settled(u: &[f64], anchor: &Option<Anchor>, settle: f64) -> bool {
    settle > 0.0
        && anchor.as_ref().is_some_and(|a| {
            u.iter()
                .zip(&a.at.u)
                .zip(&a.sd)
                .all(|((x, y), sd)| sd.is_finite() && (x - y).abs() <= settle * sd)
        })
}

/// Broyden's update of `j` (at `u0`, residuals `r0`) with the step to `u1`
/// (residuals `r1`): `j += (dr - j du) du' / |du|^2`.
fn broyden(j: &mut DMatrix<f64>, u1: &[f64], u0: &[f64], r1: &[f64], r0: &[f64]) {
    let du = DVector::from_iterator(u0.len(), u1.iter().zip(u0).map(|(a, b)| a - b));
    let norm2 = du.norm_squared();
    if norm2 <= 0.0 {
        return;
    }
    let dr = DVector::from_iterator(r0.len(), r1.iter().zip(r0).map(|(a, b)| a - b));
    let miss = dr - &*j * &du;
    // In place: no residuals-by-coordinates outer product is allocated.
    j.ger(1.0 / norm2, &miss, &du, 1.0);
}

/// The spread of the fitted coordinates: their covariance in normalised
/// units, and what it says about identifiability.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spread {
    /// Residuals.
    pub n: usize,
    /// Autocorrelation of the residuals, from one sample to the next.
    pub rho: f64,
    /// Effective number of independent residuals.
    pub n_eff: f64,
    /// Residual variance `cost / (n_eff - p)` (the noise the intervals
    /// assume), in the residuals' units squared.
    pub variance: f64,
    /// Standard deviation of each coordinate, normalised units (infinite
    /// where the data say nothing of it).
    pub sd_u: Vec<f64>,
    /// Correlation of each pair of coordinates.
    pub correlation: Vec<Vec<f64>>,
}

/// Autocorrelation of `r` at lag `lag` (for residuals that interleave
/// several series, such as joints sample by sample, `lag` is the number of
/// series: each series' lag-1 autocorrelation, pooled).
pub fn autocorrelation(r: &[f64], lag: usize) -> f64 {
    let lag = lag.max(1);
    if r.len() < lag + 2 {
        return 0.0;
    }
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let var: f64 = r.iter().map(|x| (x - mean) * (x - mean)).sum();
    if var <= 0.0 {
        return 0.0;
    }
    let cov: f64 = r
        .iter()
        .zip(&r[lag..])
        .map(|(a, b)| (a - mean) * (b - mean))
        .sum();
    (cov / var).clamp(-0.999, 0.999)
}

/// `(J^T J)^-1` of a Jacobian, as far as the data see it: per coordinate
/// the square root of its diagonal element (infinite for a coordinate on
/// a direction the data do not see, or without effect), and the
/// correlation of each pair.
struct NormalInverse {
    sqrt_diag: Vec<f64>,
    correlation: Vec<Vec<f64>>,
}

fn normal_inverse(j: &DMatrix<f64>) -> NormalInverse {
    let p = j.ncols();
    // J^T J is first scaled to unit diagonal, so that its conditioning
    // measures what the data tell apart, not the parameters' units.
    let a = j.transpose() * j;
    let d: Vec<f64> = (0..p).map(|i| a[(i, i)].max(0.0).sqrt()).collect();
    let seen: Vec<usize> = (0..p).filter(|&i| d[i] > 0.0).collect();
    let mut sqrt_diag = vec![f64::INFINITY; p];
    let mut correlation = vec![vec![f64::NAN; p]; p];
    let m = seen.len();
    if m > 0 {
        let sm = DMatrix::from_fn(m, m, |r, c| {
            a[(seen[r], seen[c])] / (d[seen[r]] * d[seen[c]])
        });
        let eig = sm.clone().symmetric_eigen();
        let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
        // Directions the data do not see: parameters moving along them
        // leave the residuals unchanged, so their spread is unbounded and
        // they trade against each other (correlation +-1).
        let mut blind = vec![false; m];
        let mut inv = DMatrix::zeros(m, m);
        for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
            let v = eig.eigenvectors.column(k);
            if lambda <= 1e-10 * top {
                for r in 0..m {
                    if v[r].abs() > 0.1 {
                        blind[r] = true;
                        for c in 0..m {
                            if v[c].abs() > 0.1 && r != c {
                                correlation[seen[r]][seen[c]] = (v[r] * v[c]).signum();
                            }
                        }
                    }
                }
            } else {
                inv += (v * v.transpose()) / lambda;
            }
        }
        for r in 0..m {
            if blind[r] {
                continue;
            }
            sqrt_diag[seen[r]] = inv[(r, r)].max(0.0).sqrt() / d[seen[r]];
            for c in 0..m {
                if blind[c] {
                    continue;
                }
                let den = (inv[(r, r)] * inv[(c, c)]).sqrt();
                if den > 0.0 {
                    correlation[seen[r]][seen[c]] = (inv[(r, c)] / den).clamp(-1.0, 1.0);
                }
            }
        }
    }
    NormalInverse {
        sqrt_diag,
        correlation,
    }
}

/// The spread of a fit with residuals `r` and Jacobian `j` there; `lag` as
/// for [`autocorrelation`].
pub fn spread(j: &DMatrix<f64>, r: &[f64], lag: usize) -> Spread {
    let n = r.len();
    let p = j.ncols();
    let rho = autocorrelation(r, lag).max(0.0);
    let n_eff = (n as f64 * (1.0 - rho) / (1.0 + rho)).max(p as f64 + 1.0);
    let variance = cost_of(r) / (n_eff - p as f64).max(1.0);
    // Covariance of the coordinates: variance * (J^T J)^-1, with the
    // residual count reduced to n_eff: scaled by n / n_eff.
    let scale = n as f64 / n_eff;
    let inv = normal_inverse(j);
    let sd_u = inv
        .sqrt_diag
        .iter()
        .map(|s| (variance * scale).max(0.0).sqrt() * s)
        .collect();
    Spread {
        n,
        rho,
        n_eff,
        variance,
        sd_u,
        correlation: inv.correlation,
    }
}

/// A run of residuals: `samples` rows of `series` values each, row by
/// row (an episode's joint angles, sample by sample and joint by joint).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block {
    /// Rows (samples in time).
    pub samples: usize,
    /// Values per row (series side by side: joints).
    pub series: usize,
}

/// The residuals at an optimum told apart into white noise (what differs
/// from one sample to the next at random: a sensor's reading noise) and
/// structure (what is smooth in time: what the model cannot reproduce),
/// and the 95 % interval of each coordinate that both allow.
///
/// - **Noise**: the variogram of each series, `g(l) = mean (r[t] -
///   r[t-l])^2 / 2` at lags 1 and 2, extrapolated linearly to lag 0 (`2
///   g(1) - g(2)`, its nugget): a smooth error adds nothing there, white
///   noise its variance `s_n^2`. Its share of an interval is the
///   Gauss-Newton one, `1.96 s_n sqrt((J^T J)^-1_ii)`.
/// - **Structure**: the residuals averaged over `window` samples (which
///   keeps a smooth error and leaves white noise `s_n^2 / window`), less
///   that noise: a mean square `s_m^2` per residual, a norm `|r_m| = s_m
///   sqrt(n)`. An error of the model shifts the fit by `(J^T J)^-1 J^T e`;
///   the part of `e` the coordinates absorb is what shifts them, at most
///   `|P e| sqrt((J^T J)^-1_ii)` for coordinate `i` (Cauchy-Schwarz), and
///   it is not seen in the residuals. Taking it as no larger than the part
///   left in them (`|r_m|`) bounds the shift by `|r_m| sqrt((J^T
///   J)^-1_ii)`: the values of the coordinate over which the fit moves
///   the replay by no more than what it cannot reproduce.
///
/// The half-width is the root sum of squares of the two. Unlike a count
/// of independent residuals from their autocorrelation (which reading
/// noise drives to zero while the model error stays), neither share
/// depends on how correlated the residuals are.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Misfit {
    /// Residuals.
    pub n: usize,
    /// Their root mean square.
    pub rms: f64,
    /// The white noise's standard deviation per residual.
    pub noise_sd: f64,
    /// The structure's root mean square per residual.
    pub structure_rms: f64,
    /// Samples averaged to measure the structure.
    pub window: usize,
    /// Half-width of each coordinate's 95 % interval, normalised units
    /// (infinite where the data do not see the coordinate).
    pub half_width_u: Vec<f64>,
    /// Correlation of each pair of coordinates.
    pub correlation: Vec<Vec<f64>>,
}

/// The [`Misfit`] of residuals `r` (laid out as `blocks`, in order) with
/// Jacobian `j` there, the structure measured over `window` samples (at
/// least 1). Residuals past the blocks, or all of them when the blocks
/// do not cover them, count as one series.
pub fn misfit(j: &DMatrix<f64>, r: &[f64], blocks: &[Block], window: usize) -> Misfit {
    let n = r.len();
    let window = window.max(1);
    let covered: usize = blocks.iter().map(|b| b.samples * b.series).sum();
    let mut layout: Vec<Block> = if covered <= n {
        blocks.to_vec()
    } else {
        Vec::new()
    };
    let used: usize = layout.iter().map(|b| b.samples * b.series).sum();
    if used < n {
        layout.push(Block {
            samples: n - used,
            series: 1,
        });
    }
    // Sums over every series of every block: squared differences at lags
    // 1 and 2, and the squared moving averages over `window`.
    let (mut d1, mut c1, mut d2, mut c2, mut avg, mut ca) = (0.0, 0usize, 0.0, 0usize, 0.0, 0usize);
    let mut at = 0;
    for b in &layout {
        let value = |t: usize, s: usize| r[at + t * b.series + s];
        for s in 0..b.series {
            for t in 1..b.samples {
                d1 += (value(t, s) - value(t - 1, s)).powi(2);
                c1 += 1;
                if t >= 2 {
                    d2 += (value(t, s) - value(t - 2, s)).powi(2);
                    c2 += 1;
                }
            }
            if b.samples >= window {
                let mut sum: f64 = (0..window).map(|t| value(t, s)).sum();
                for t in window..=b.samples {
                    avg += (sum / window as f64).powi(2);
                    ca += 1;
                    if t < b.samples {
                        sum += value(t, s) - value(t - window, s);
                    }
                }
            }
        }
        at += b.samples * b.series;
    }
    let mean_square = cost_of(r) / n.max(1) as f64;
    let g = |d: f64, c: usize| if c > 0 { d / (2.0 * c as f64) } else { 0.0 };
    let noise_var = if c2 > 0 {
        (2.0 * g(d1, c1) - g(d2, c2)).clamp(0.0, mean_square)
    } else {
        0.0
    };
    let structure_var = if ca > 0 {
        (avg / ca as f64 - noise_var / window as f64).clamp(0.0, mean_square)
    } else {
        (mean_square - noise_var).max(0.0)
    };
    let inv = normal_inverse(j);
    let per = ((1.96f64.powi(2) * noise_var) + structure_var * n as f64).sqrt();
    Misfit {
        n,
        rms: mean_square.sqrt(),
        noise_sd: noise_var.sqrt(),
        structure_rms: structure_var.sqrt(),
        window,
        half_width_u: inv.sqrt_diag.iter().map(|s| per * s).collect(),
        correlation: inv.correlation,
    }
}

/// Pairs of coordinates (named `names`) whose estimates are correlated
/// beyond 0.95 in `s`: they trade against each other. Coordinates for
/// which `skip` is true are left out.
pub fn trading_pairs(
    names: &[String],
    s: &Spread,
    skip: &dyn Fn(usize) -> bool,
) -> Vec<(String, String, f64)> {
    let mut out = Vec::new();
    for a in (0..names.len()).filter(|&a| !skip(a)) {
        for b in (a + 1..names.len()).filter(|&b| !skip(b)) {
            let c = s.correlation[a][b];
            if c.is_finite() && c.abs() > 0.95 {
                out.push((names[a].clone(), names[b].clone(), c));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_column_the_engine_fails_either_way_is_blind_not_an_error() {
        // Coordinate 1 fails whenever it moves (a diverging engine on both
        // sides); coordinate 0 is linear.
        let f = |x: &[f64]| {
            if (x[1] - 0.5).abs() > 1e-12 {
                Err("diverged".to_string())
            } else {
                Ok(vec![2.0 * x[0], 3.0 * x[0]])
            }
        };
        let u = [0.3, 0.5];
        let r0 = f(&u).unwrap();
        assert!(jacobian(&f, &u, &r0, 1e-3, 2)
            .unwrap_err()
            .contains("coordinate 1"));
        let (j, blind) = jacobian_or_blind(&f, &u, &r0, 1e-3, 2);
        assert_eq!(blind, [(1, "diverged".to_string())]);
        assert!((j[(0, 0)] - 2.0).abs() < 1e-9 && (j[(1, 0)] - 3.0).abs() < 1e-9);
        assert_eq!((j[(0, 1)], j[(1, 1)]), (0.0, 0.0));
        assert!(spread(&j, &r0, 1).sd_u[1].is_infinite());
        // The holder of both tunes: the same Jacobian, strict or blind.
        assert!(Linearised::at(&f, &u, &r0, 1e-3, 2, None)
            .unwrap_err()
            .contains("coordinate 1"));
        let lin = Linearised::at_or_blind(&f, &u, &r0, 1e-3, 2);
        assert_eq!(
            (&lin.jacobian, &lin.blind, &lin.u[..]),
            (&j, &blind, &u[..])
        );
        // (Compared as text: the blind coordinate's correlations are NaN.)
        assert_eq!(
            format!("{:?}", lin.spread(1)),
            format!("{:?}", spread(&j, &r0, 1))
        );
        // A fit's own Jacobian is taken as it is, with no evaluation.
        let never = |_: &[f64]| -> Result<Vec<f64>, String> { Err("evaluated".into()) };
        let given = Linearised::at(&never, &u, &r0, 1e-3, 2, Some(j.clone())).unwrap();
        assert_eq!(given.jacobian, j);
        assert!(given.blind.is_empty());
    }

    /// y = a exp(-b t) + c on a grid, coordinates mapped a = 4u0,
    /// b = 2u1, c = u2 - 0.5.
    fn model(u: &[f64], t: f64) -> f64 {
        4.0 * u[0] * (-(2.0 * u[1]) * t).exp() + u[2] - 0.5
    }

    /// The curve's true coordinates.
    const TRUTH: [f64; 3] = [0.6, 0.35, 0.7];

    /// 200 samples of the curve at `TRUTH` over 4 s, with uniform reading
    /// noise of 0.01 (seeded).
    fn noisy_curve(seed: u64) -> Vec<(f64, f64)> {
        let mut noise = realitygap_core::controller::SplitMix64::new(seed);
        (0..200)
            .map(|i| {
                let t = i as f64 * 0.02;
                (t, model(&TRUTH, t) + 0.01 * (noise.uniform() - 0.5))
            })
            .collect()
    }

    #[test]
    fn fits_a_curve_and_its_intervals_cover_the_truth() {
        let data = noisy_curve(3);
        let f = |u: &[f64]| -> Result<Vec<f64>, String> {
            Ok(data.iter().map(|(t, y)| model(u, *t) - y).collect())
        };
        let fit = levenberg_marquardt(
            &f,
            &[0.2, 0.8, 0.2],
            FitOptions {
                jobs: 2,
                ..FitOptions::default()
            },
            &|_, _, _| {},
        )
        .unwrap();
        assert!(fit.cost < fit.start_cost * 1e-3, "{fit:?}");
        let r = f(&fit.u).unwrap();
        let j = jacobian(&f, &fit.u, &r, 1e-6, 1).unwrap();
        let s = spread(&j, &r, 1);
        for (i, want) in TRUTH.iter().enumerate() {
            assert!(
                (fit.u[i] - want).abs() < 3.0 * s.sd_u[i] + 1e-4,
                "coordinate {i}: {} vs {want} (sd {})",
                fit.u[i],
                s.sd_u[i]
            );
            assert!(s.sd_u[i] < 0.01, "{s:?}");
            assert!(s.correlation[i][i] > 0.999, "{s:?}");
        }
    }

    /// White noise and a smooth error, told apart: the noise by the
    /// variogram's nugget, the structure by averaging over the window;
    /// blocks (episodes, series side by side) are kept apart.
    #[test]
    fn the_misfit_tells_white_noise_from_structure() {
        let mut noise = realitygap_core::controller::SplitMix64::new(11);
        let blocks = [
            Block {
                samples: 2000,
                series: 3,
            },
            Block {
                samples: 1500,
                series: 3,
            },
        ];
        let (sigma, amplitude) = (0.02, 0.05);
        let mut r = Vec::new();
        for b in &blocks {
            for t in 0..b.samples {
                for s in 0..b.series {
                    // Uniform noise of standard deviation sigma; a sine of
                    // 100 samples per period, another phase per series.
                    let white = sigma * 12f64.sqrt() * (noise.uniform() - 0.5);
                    let smooth = amplitude
                        * (2.0 * std::f64::consts::PI * t as f64 / 100.0 + s as f64).sin();
                    r.push(white + smooth);
                }
            }
        }
        let j = DMatrix::from_fn(r.len(), 1, |i, _| (i % 7) as f64);
        let m = misfit(&j, &r, &blocks, 5);
        assert!((m.noise_sd / sigma - 1.0).abs() < 0.05, "{m:?}");
        // The structure's RMS, less what averaging 5 samples of a
        // 100-sample period takes off it (1.6 %).
        let want = amplitude / 2f64.sqrt();
        assert!((m.structure_rms / want - 1.0).abs() < 0.05, "{m:?}");
        assert_eq!(m.window, 5);
        // Without noise, no nugget; a white series has no structure.
        let smooth: Vec<f64> = (0..3000)
            .map(|t| amplitude * (t as f64 / 30.0).sin())
            .collect();
        let j = DMatrix::from_element(smooth.len(), 1, 1.0);
        let m = misfit(&j, &smooth, &[], 5);
        assert!(m.noise_sd < 1e-4 * amplitude, "{m:?}");
        let white: Vec<f64> = (0..3000).map(|_| noise.uniform() - 0.5).collect();
        let m = misfit(&j, &white, &[], 5);
        assert!(m.structure_rms < 0.05 * m.noise_sd, "{m:?}");
    }

    /// A model error the parameters cannot follow, under reading noise:
    /// the noise drives the residuals' autocorrelation to nothing, so the
    /// count of independent residuals takes every one and the intervals
    /// shrink to the noise's, while the bias of the model error stays. The
    /// misfit's interval keeps room for it, and covers the truth.
    #[test]
    fn intervals_keep_room_for_a_model_error_under_reading_noise() {
        let mut noise = realitygap_core::controller::SplitMix64::new(7);
        let n = 2000;
        let data: Vec<(f64, f64)> = (0..n)
            .map(|i| {
                let t = i as f64 * 0.002;
                // The model's curve, a slow error it has no term for, and
                // reading noise.
                let error = 0.004 * (2.0 * std::f64::consts::PI * 0.6 * t).sin();
                (t, model(&TRUTH, t) + error + 0.01 * (noise.uniform() - 0.5))
            })
            .collect();
        let f = |u: &[f64]| -> Result<Vec<f64>, String> {
            Ok(data.iter().map(|(t, y)| model(u, *t) - y).collect())
        };
        let fit = levenberg_marquardt(&f, &[0.2, 0.8, 0.2], FitOptions::default(), &|_, _, _| {})
            .unwrap();
        let r = f(&fit.u).unwrap();
        let j = jacobian(&f, &fit.u, &r, 1e-6, 1).unwrap();
        let old = spread(&j, &r, 1);
        let new = misfit(
            &j,
            &r,
            &[Block {
                samples: n,
                series: 1,
            }],
            10,
        );
        let off = |i: usize| (fit.u[i] - TRUTH[i]).abs();
        assert!(
            (0..3).any(|i| off(i) > 1.96 * old.sd_u[i]),
            "the count of independent residuals covers: {fit:?} {old:?}"
        );
        for i in 0..3 {
            assert!(off(i) <= new.half_width_u[i], "{i}: {fit:?} {new:?}");
        }
        assert!(
            (new.noise_sd / (0.01 / 12f64.sqrt()) - 1.0).abs() < 0.1,
            "{new:?}"
        );
        assert!(new.structure_rms > 0.0, "{new:?}");
    }

    #[test]
    fn names_coordinates_that_trade_against_each_other() {
        // Only the sum u0 + u1 matters.
        let f = |u: &[f64]| -> Result<Vec<f64>, String> {
            Ok((0..50)
                .map(|i| {
                    (u[0] + u[1]) * i as f64 * 0.1 - 0.8 * i as f64 * 0.1 + 0.001 * (i % 3) as f64
                })
                .collect())
        };
        let fit =
            levenberg_marquardt(&f, &[0.1, 0.1], FitOptions::default(), &|_, _, _| {}).unwrap();
        assert!((fit.u[0] + fit.u[1] - 0.8).abs() < 1e-3, "{fit:?}");
        let r = f(&fit.u).unwrap();
        let j = jacobian(&f, &fit.u, &r, 1e-4, 1).unwrap();
        let s = spread(&j, &r, 1);
        assert!(s.correlation[0][1] < -0.99, "{s:?}");
        assert!(s.sd_u.iter().all(|x| x.is_infinite()), "{s:?}");
    }

    #[test]
    fn a_failing_start_is_an_error_and_failing_steps_are_rejected() {
        let f = |_: &[f64]| -> Result<Vec<f64>, String> { Err("diverged".into()) };
        let e = levenberg_marquardt(&f, &[0.5], FitOptions::default(), &|_, _, _| {}).unwrap_err();
        assert!(e.contains("diverged"), "{e}");
        // Evaluations fail past u = 0.6; the minimum at 0.9 is beyond.
        let g = |u: &[f64]| -> Result<Vec<f64>, String> {
            if u[0] > 0.6 {
                Err("diverged".into())
            } else {
                Ok(vec![u[0] - 0.9])
            }
        };
        let fit = levenberg_marquardt(&g, &[0.1], FitOptions::default(), &|_, _, _| {}).unwrap();
        assert!(fit.u[0] <= 0.6 && fit.u[0] > 0.5, "{fit:?}");
    }

    /// Broyden's updates between Jacobians reach the same optimum on fewer
    /// evaluations, and a certified fit ends on a Jacobian computed at it.
    #[test]
    fn secant_steps_reach_the_same_optimum_on_fewer_evaluations() {
        let truth = [0.6, 0.35, 0.7];
        let data: Vec<(f64, f64)> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.02;
                (t, model(&truth, t) + 0.002 * ((i * 7 % 11) as f64 - 5.0))
            })
            .collect();
        let f = |u: &[f64]| -> Result<Vec<f64>, String> {
            Ok(data.iter().map(|(t, y)| model(u, *t) - y).collect())
        };
        let start = [0.2, 0.8, 0.2];
        let plain = levenberg_marquardt(&f, &start, FitOptions::default(), &|_, _, _| {}).unwrap();
        let secant = FitOptions {
            secant: true,
            ..FitOptions::default()
        };
        let fit = levenberg_marquardt(&f, &start, secant, &|_, _, _| {}).unwrap();
        for i in 0..3 {
            assert!((fit.u[i] - plain.u[i]).abs() < 1e-4, "{fit:?} vs {plain:?}");
        }
        assert!(
            fit.evaluations < plain.evaluations,
            "{} vs {}",
            fit.evaluations,
            plain.evaluations
        );
        assert!(fit.iterations < plain.iterations, "{fit:?}");
        let j = fit
            .jacobian
            .expect("a certified fit ends on a fresh Jacobian");
        let r = f(&fit.u).unwrap();
        let fd = jacobian(&f, &fit.u, &r, FitOptions::default().step, 1).unwrap();
        assert!((j - fd).norm() < 1e-12);
        // From a neighbour's Jacobian with an unknown column, the missing
        // column is computed and the rest reused: a rough fit without a
        // fresh Jacobian at all.
        let mut guess = plain.last_jacobian.clone().unwrap();
        guess.set_column(1, &DVector::from_element(guess.nrows(), f64::NAN));
        let rough = levenberg_marquardt_from(
            &f,
            &[0.58, 0.37, 0.68],
            None,
            Some(guess),
            FitOptions {
                max_iterations: 0,
                certify: false,
                ..secant
            },
            &|_, _, _| {},
        )
        .unwrap();
        assert_eq!(rough.iterations, 0, "{rough:?}");
        assert!(
            rough.cost < 1.01 * plain.cost,
            "{} vs {}",
            rough.cost,
            plain.cost
        );
        assert!(rough.jacobian.is_none() && rough.last_jacobian.is_some());
    }

    /// With `settle`, a secant fit that ends within a tenth of a standard
    /// deviation of its last Jacobian's point is certified on that one:
    /// the same optimum and intervals for fewer evaluations. Residuals
    /// known at the start save its evaluation.
    #[test]
    fn a_fit_ending_near_its_last_jacobian_is_certified_on_it() {
        let data = noisy_curve(5);
        let f = |u: &[f64]| -> Result<Vec<f64>, String> {
            Ok(data.iter().map(|(t, y)| model(u, *t) - y).collect())
        };
        let start = [0.2, 0.8, 0.2];
        // A tight tolerance: after its last Jacobian, the fit still takes
        // steps whose gains are far below what the data can resolve.
        let secant = FitOptions {
            secant: true,
            tolerance: 1e-10,
            ..FitOptions::default()
        };
        let full = levenberg_marquardt(&f, &start, secant, &|_, _, _| {}).unwrap();
        let settled = levenberg_marquardt(
            &f,
            &start,
            FitOptions {
                settle: 0.1,
                ..secant
            },
            &|_, _, _| {},
        )
        .unwrap();
        assert!(
            settled.reason.contains("standard deviations"),
            "{}",
            settled.reason
        );
        assert!(
            settled.evaluations < full.evaluations,
            "{} vs {}",
            settled.evaluations,
            full.evaluations
        );
        let a = spread(full.jacobian.as_ref().unwrap(), &full.residuals, 1);
        let b = spread(settled.jacobian.as_ref().unwrap(), &settled.residuals, 1);
        for i in 0..3 {
            assert!((settled.u[i] - full.u[i]).abs() < 0.1 * a.sd_u[i], "{i}");
            assert!((b.sd_u[i] / a.sd_u[i] - 1.0).abs() < 0.05, "{a:?} vs {b:?}");
        }
        // Off (0), the same fit computes a Jacobian at its end.
        assert!(full.reason.starts_with("converged") && !full.reason.contains("deviations"));
        let r0 = f(&start).unwrap();
        let known =
            levenberg_marquardt_from(&f, &start, Some(r0), None, secant, &|_, _, _| {}).unwrap();
        assert_eq!(known.evaluations + 1, full.evaluations);
        assert_eq!(known.u, full.u);
    }

    /// At an optimum with a residual the parameters cannot remove, the
    /// linear model predicts no gain worth a trial: the fit stops there,
    /// with the Jacobian at its point, instead of spending a chain of
    /// rejected trials (one per rise of the damping) on it.
    #[test]
    fn at_an_optimum_the_fit_stops_on_the_predicted_gain_without_rejected_trials() {
        let f = |u: &[f64]| -> Result<Vec<f64>, String> {
            let d = u[0] - 0.3;
            Ok(vec![d, u[1] - 0.6, 0.1 + 0.5 * d * d])
        };
        let labels = std::sync::Mutex::new(Vec::new());
        let fit = levenberg_marquardt(&f, &[0.3, 0.6], FitOptions::default(), &|label, _, _| {
            labels.lock().unwrap().push(label.to_string())
        })
        .unwrap();
        assert!(fit.reason.contains("predicts"), "{}", fit.reason);
        assert_eq!(*labels.lock().unwrap(), ["start"]);
        assert_eq!(fit.evaluations, 3);
        assert!(fit.jacobian.is_some());
        assert_eq!(fit.u, [0.3, 0.6]);
        // From elsewhere it still finds the optimum.
        let fit =
            levenberg_marquardt(&f, &[0.1, 0.9], FitOptions::default(), &|_, _, _| {}).unwrap();
        assert!(
            (fit.u[0] - 0.3).abs() < 1e-3 && (fit.u[1] - 0.6).abs() < 1e-3,
            "{fit:?}"
        );
    }
}
