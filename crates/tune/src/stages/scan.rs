//! A global look before the gradient fit. The study tune's ([`study`]) is
//! CMA-ES ([`crate::search`]); the recordings tune's (`delay`) scans the command delay over its range at the untuned
//! parameters: a gradient search from a delay far from the truth can
//! settle where a wrong delay and wrong damping make up for each other.

use crate::polish::IdentifiabilityReport;
use crate::recordings::Problem;
use crate::search::{self, History, Progress, SearchEnd};
use crate::space::{Dim, Space};
use crate::Tuner;
use anyhow::Result;

/// The study tune's search: CMA-ES over the space (and the registration
/// when fitted), resuming from `OUT/history.csv`. The objective's own
/// noise at the start (`before`) tells a stalled search (with restarts),
/// unless the caller gave one.
pub fn study(
    tuner: &Tuner<'_>,
    before: Option<&IdentifiabilityReport>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SearchEnd> {
    let spec = tuner.spec;
    let mut history = History::open(
        &spec.out.join("history.csv"),
        &tuner.part_names(),
        &tuner.value_names(),
        tuner.dims(),
    )?;
    let space = if tuner.fits_registration() {
        spec.space.clone()
    } else {
        Space {
            registration: None,
            ..spec.space.clone()
        }
    };
    let options = search::SearchOptions {
        stall_m: spec
            .search
            .stall_m
            .or_else(|| before.and_then(|r| r.noise_m)),
        ..spec.search
    };
    search::search(
        &space,
        &mut history,
        options,
        &|u| tuner.evaluate(u),
        &|u| tuner.values(u),
        progress,
    )
}

/// The recordings tune's start for its fit from the untuned point `u`:
/// the history's best point when `resumed` (its values), else `u` with
/// the delay at the best of a coarse grid and then the midpoints beside
/// its best value (the resolution of a grid twice as fine, for about half
/// its replays), with the residuals there; `u` itself without a delay to
/// scan.
pub(crate) fn delay(
    p: &Problem,
    mut u: Vec<f64>,
    resumed: Option<&[f64]>,
) -> Result<(Vec<f64>, Option<Vec<f64>>)> {
    if let Some(values) = resumed {
        u = p
            .continuous
            .iter()
            .zip(values)
            .map(|(&i, &v)| p.space.dims[i].unit(v))
            .collect();
        p.set_phase("resumed from the history's best point".into());
        return Ok((u, None));
    }
    let Some((c, d)) = p.delay_coordinate() else {
        return Ok((u, None));
    };
    let grid = delay_grid(d, p.dt);
    p.set_phase(format!("the delay over {} values", grid.len()));
    let mut scanned: Vec<(f64, Vec<f64>)> = grid
        .iter()
        .zip(delay_residuals(p, &u, c, &grid)?)
        .filter_map(|(g, r)| r.map(|r| (*g, r)))
        .collect();
    if let Some(i) = best_of(&scanned).and_then(|b| grid.iter().position(|g| *g == b.0)) {
        let mid = |a: f64, b: f64| ((a + b) / 2.0 / p.dt).round() * p.dt;
        let refine: Vec<f64> = [i.checked_sub(1), Some(i + 1).filter(|&j| j < grid.len())]
            .into_iter()
            .flatten()
            .map(|j| mid(grid[i], grid[j]))
            .filter(|x| !grid.iter().any(|g| (g - x).abs() < 1e-12))
            .collect();
        p.set_phase(format!(
            "the delay, {} values beside the best",
            refine.len()
        ));
        scanned.extend(
            refine
                .iter()
                .zip(delay_residuals(p, &u, c, &refine)?)
                .filter_map(|(g, r)| r.map(|r| (*g, r))),
        );
    }
    let mut start_residuals = None;
    if let Some((best, r)) = best_of(&scanned) {
        u[c] = d.unit(*best);
        start_residuals = Some(r.clone());
    }
    Ok((u, start_residuals))
}

/// The delays of the first scan: the range in about 10 steps, on the
/// engine-step grid.
fn delay_grid(d: &Dim, dt: f64) -> Vec<f64> {
    let snap = |x: f64| (x / dt).round() * dt;
    let (lo, hi) = (snap(d.low).max(d.low), snap(d.high).min(d.high));
    let step = snap(((hi - lo) / 10.0).max(dt)).max(dt);
    let mut grid = Vec::new();
    let mut x = lo;
    while x <= hi + 1e-12 {
        grid.push(snap(x).clamp(d.low, d.high));
        x += step;
    }
    grid.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
    grid
}

/// The training residuals at `u` with coordinate `c` (the delay) at each
/// of `grid`, in parallel on the tune's threads; `None` where the replay
/// failed.
fn delay_residuals(
    p: &Problem,
    u: &[f64],
    c: usize,
    grid: &[f64],
) -> Result<Vec<Option<Vec<f64>>>> {
    use rayon::prelude::*;
    let d = &p.space.dims[p.continuous[c]];
    Ok(p.pool.install(|| {
        grid.par_iter()
            .map(|&delay| {
                let mut x = u.to_vec();
                x[c] = d.unit(delay);
                let params = p.params(&x).ok()?;
                match p.residuals(&params) {
                    Ok(r) => {
                        let cost: f64 = r.iter().map(|v| v * v).sum();
                        p.record("delay scan", &p.values(&x), cost);
                        Some(r)
                    }
                    Err(_) => {
                        p.record("delay scan failed", &p.values(&x), f64::INFINITY);
                        None
                    }
                }
            })
            .collect()
    }))
}

/// The scanned delay with the lowest cost, and its residuals.
fn best_of(scanned: &[(f64, Vec<f64>)]) -> Option<&(f64, Vec<f64>)> {
    let cost = |r: &[f64]| -> f64 { r.iter().map(|v| v * v).sum() };
    scanned
        .iter()
        .min_by(|a, b| cost(&a.1).total_cmp(&cost(&b.1)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recordings::DELAY_KEY;
    use crate::space::Scale;

    #[test]
    fn the_delay_grid_lies_on_engine_steps_within_bounds() {
        let d = Dim {
            key: DELAY_KEY.into(),
            low: 0.0,
            high: 0.1,
            scale: Scale::Linear,
            start: 0.0,
        };
        let grid = delay_grid(&d, 1e-3);
        assert_eq!(grid.len(), 11);
        assert!((grid[1] - 0.01).abs() < 1e-12);
        for x in grid {
            assert!(((x / 1e-3).round() * 1e-3 - x).abs() < 1e-12);
        }
    }
}
