//! Profiles: one coordinate held at a value and the others refitted
//! ([`Held`]), the one profile code of both tunes.
//!
//! - The study polish profiles each interval's ends ([`profiled_ends`]):
//!   the coordinate is held at a distance from the optimum and the end
//!   moves to where the objective itself, the others refitted, has risen
//!   by the threshold (`End`).
//! - The recordings tune profiles its delay at whole engine steps around
//!   the fit (`delay_steps`): a wrong delay and wrong damping can make up
//!   for each other, a valley a gradient search may stop in.

use crate::least_squares::{self, Fit, FitOptions, Residuals};
use crate::polish::IRLS_FLOOR_M;
use crate::recordings::Problem;
use crate::space::Dim;
use crate::Tuner;
use anyhow::Result;
use nalgebra::DMatrix;
use std::sync::Mutex;

/// Coordinate `c` held at `at` (normalised) while the others are refitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Held {
    /// The coordinate held.
    pub c: usize,
    /// Where, normalised.
    pub at: f64,
}

impl Held {
    /// The whole point from the others' coordinates `y`.
    pub fn full(&self, y: &[f64]) -> Vec<f64> {
        let mut v = y.to_vec();
        v.insert(self.c, self.at);
        v
    }

    /// The others' coordinates of the whole point `x`.
    pub fn others(&self, x: &[f64]) -> Vec<f64> {
        let mut v = x.to_vec();
        v.remove(self.c);
        v
    }

    /// A whole Jacobian's columns of the others.
    pub fn drop_column(&self, j: &DMatrix<f64>) -> DMatrix<f64> {
        j.clone().remove_column(self.c)
    }

    /// The others' Jacobian as a whole one: the held coordinate's column
    /// unknown (not finite, which a fit that takes it as a guess computes).
    pub fn restore_column(&self, j: &DMatrix<f64>) -> DMatrix<f64> {
        j.clone().insert_column(self.c, f64::NAN)
    }

    /// Refits the others from the whole point `from` (its residuals `r0`
    /// with the coordinate held, when known; a whole Jacobian `guess`, as
    /// [`least_squares::levenberg_marquardt_from`] takes one), `f` the
    /// whole point's residuals. The fit comes back whole: its point with
    /// the held coordinate, its Jacobians with that column unknown;
    /// `on_evaluation` hears whole points.
    pub fn refit(
        &self,
        f: &Residuals,
        from: &[f64],
        r0: Option<Vec<f64>>,
        guess: Option<&DMatrix<f64>>,
        options: FitOptions,
        on_evaluation: &(dyn Fn(&str, &[f64], f64) + Sync),
    ) -> Result<Fit, String> {
        let g = |y: &[f64]| f(&self.full(y));
        let fit = least_squares::levenberg_marquardt_from(
            &g,
            &self.others(from),
            r0,
            guess.map(|j| self.drop_column(j)),
            options,
            &|phase, y, cost| on_evaluation(phase, &self.full(y), cost),
        )?;
        Ok(Fit {
            u: self.full(&fit.u),
            jacobian: fit.jacobian.as_ref().map(|j| self.restore_column(j)),
            last_jacobian: fit.last_jacobian.as_ref().map(|j| self.restore_column(j)),
            ..fit
        })
    }
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
/// pass of [`PROFILE_ITERATIONS`] iterations at most, [`Held::refit`]):
/// the lowest objective of any point the refit simulated, infinite where
/// the engine fails at `x`; and the evaluations made.
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
    if x.len() < 2 {
        return (start.objective() - objective, 1);
    }
    let weights = start.weights(IRLS_FLOOR_M);
    // Every point the refit simulates holds `c` where the profile puts
    // it, so the lowest objective among them all (the Jacobian's columns
    // too) bounds the profile from above: the refit's end needs no
    // simulation of its own.
    let seen = Mutex::new((0usize, start.objective()));
    let f = |z: &[f64]| {
        let e = t.errors(z);
        let mut seen = seen.lock().unwrap_or_else(|e| e.into_inner());
        seen.0 += 1;
        let e = e?;
        seen.1 = seen.1.min(e.objective());
        Ok(e.residuals(Some(&weights)))
    };
    let options = FitOptions {
        max_iterations: PROFILE_ITERATIONS,
        ..options
    };
    let held = Held { c, at: x[c] };
    // The start's residuals are known: the refit does not simulate it again.
    let r0 = Some(start.residuals(Some(&weights)));
    let _ = held.refit(&f, x, r0, None, options, &|_, _, _| {});
    let (count, lowest) = seen.into_inner().unwrap_or_else(|e| e.into_inner());
    (lowest - objective, 1 + count)
}

/// Profiles each interval's ends: coordinate `c` is held at a distance
/// from the optimum `u` and the others refitted (`profile_rise`),
/// starting where the local model refits them (`corr[o][c] sd_o / sd_c`
/// per unit of `c`); the end is where the objective has risen by
/// `threshold`. The model's end (`k sd_c`) is tried first, then where the
/// rise, as a power of the distance, reaches the threshold
/// (`PROFILE_TRIALS` at most). Returns each coordinate's ends in
/// normalised units (`None`: no interval) and the evaluations made.
pub fn profiled_ends(
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

/// The recordings tune's profile of its delay (coordinate `c`, dim `d`)
/// around the fit `fit`: at whole engine steps, every other parameter is
/// fitted again ([`Held::refit`], a rough fit of one iteration from the
/// neighbour's point and Jacobian); the walk goes down from the step
/// nearest the fitted delay, then up only when down did not improve on
/// that step, and stops where the cost rises. Returns the best point
/// (whole: the delay's Jacobian column unknown); `None` when no step
/// could be fitted.
pub(crate) fn delay_steps(p: &Problem, c: usize, d: &Dim, fit: &Fit) -> Result<Option<Fit>> {
    let mut walk = DelayWalk {
        p,
        c,
        d,
        fitted: Vec::new(),
    };
    let centre = (d.value(fit.u[c]) / p.dt).round() as i64;
    // The walk starts from the first fit's point and Jacobian.
    let first = Fit {
        cost: f64::INFINITY,
        residuals: Vec::new(),
        jacobian: None,
        ..fit.clone()
    };
    let mut best = match walk.at(centre, &first) {
        Some(point) => (centre, point),
        None => (centre, first),
    };
    // Down first; up only when down did not improve on the centre (a
    // minimum below the centre is not also above it).
    for dir in [-1i64, 1] {
        if dir == 1 && best.0 != centre {
            break;
        }
        let mut k = centre;
        loop {
            k += dir;
            let from = best.1.clone();
            match walk.at(k, &from) {
                Some(point) if point.cost < best.1.cost => best = (k, point),
                _ => break,
            }
        }
    }
    Ok(best.1.cost.is_finite().then_some(best.1))
}

/// The delay's profile under way: the steps fitted so far.
struct DelayWalk<'p, 'a> {
    p: &'p Problem<'a>,
    c: usize,
    d: &'p Dim,
    fitted: Vec<(i64, Fit)>,
}

impl DelayWalk<'_, '_> {
    /// The fit with the delay held at `k` engine steps, from the point and
    /// the Jacobian of `from` (a neighbour); `None` outside the delay's
    /// range or where the fit fails.
    fn at(&mut self, k: i64, from: &Fit) -> Option<Fit> {
        let (p, d) = (self.p, self.d);
        let delay = k as f64 * p.dt;
        if delay < d.low - 1e-12 || delay > d.high + 1e-12 {
            return None;
        }
        if let Some((_, point)) = self.fitted.iter().find(|e| e.0 == k) {
            return Some(point.clone());
        }
        p.set_phase(format!("the delay's profile: {:.1} ms", delay * 1e3));
        let held = Held {
            c: self.c,
            at: d.unit(delay),
        };
        let f = |x: &[f64]| -> Result<Vec<f64>, String> { p.residuals(&p.params(x)?) };
        // A rough fit: it starts from the neighbour's Jacobian, updated
        // step by step, and computes one afresh only when that cannot
        // find a step down; the profile compares whole steps, whose
        // costs differ by far more than the fit's last gains.
        let options = FitOptions {
            max_iterations: 1,
            jobs: p.spec.jobs,
            secant: true,
            certify: false,
            ..FitOptions::default()
        };
        let record = |phase: &str, x: &[f64], cost: f64| {
            p.record(&format!("profile {phase}"), &p.values(x), cost)
        };
        let point = held
            .refit(
                &f,
                &from.u,
                None,
                from.last_jacobian.as_ref(),
                options,
                &record,
            )
            .ok()?;
        self.fitted.push((k, point.clone()));
        Some(point)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn a_held_coordinate_stays_while_the_others_are_refitted() {
        let held = Held { c: 1, at: 0.25 };
        assert_eq!(held.full(&[0.1, 0.9]), [0.1, 0.25, 0.9]);
        assert_eq!(held.others(&[0.1, 0.25, 0.9]), [0.1, 0.9]);
        let j = DMatrix::from_row_slice(2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let back = held.restore_column(&held.drop_column(&j));
        assert_eq!(held.drop_column(&back), held.drop_column(&j));
        assert!(back.column(1).iter().all(|x| x.is_nan()));
        // Residuals whose minimum is at (0.6, 0.5, 0.3): with the middle
        // coordinate held at 0.25 the others still reach theirs, and every
        // point the fit evaluates holds it.
        let evaluated = Mutex::new(Vec::new());
        let f = |x: &[f64]| -> Result<Vec<f64>, String> {
            evaluated.lock().unwrap().push(x[1]);
            Ok(vec![x[0] - 0.6, x[1] - 0.5, 2.0 * (x[2] - 0.3)])
        };
        let heard = Mutex::new(Vec::new());
        let fit = held
            .refit(
                &f,
                &[0.1, 0.25, 0.9],
                None,
                Some(&j),
                FitOptions::default(),
                &|_, x, _| heard.lock().unwrap().push(x.len()),
            )
            .unwrap();
        assert!(
            (fit.u[0] - 0.6).abs() < 1e-6 && (fit.u[2] - 0.3).abs() < 1e-6,
            "{fit:?}"
        );
        assert_eq!(fit.u[1], 0.25);
        assert!(evaluated.lock().unwrap().iter().all(|&x| x == 0.25));
        assert!(heard.lock().unwrap().iter().all(|&n| n == 3));
        let last = fit.last_jacobian.expect("a Jacobian");
        assert_eq!(last.shape(), (3, 3));
        assert!(last.column(1).iter().all(|x| x.is_nan()));
        assert!((fit.cost - 0.0625).abs() < 1e-9, "{}", fit.cost);
    }
}
