//! Per-step statistics across the runs of one source.

use realitygap_core::{Quat, Vec3};
use serde::Serialize;

/// Mean and spread of a body's position at every step, over several runs.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct MeanTrack {
    /// Mean position per step, metres; `None` where no run has a sample.
    pub mean_m: Vec<Option<Vec3>>,
    /// Per-axis standard deviation per step (population, ddof = 0, as
    /// numpy's default), metres.
    pub std_m: Vec<Option<Vec3>>,
    /// Root-mean-square distance of the runs from the mean per step, metres:
    /// one number for the spread, used as the band in figures.
    pub spread_m: Vec<Option<f64>>,
    /// How many runs contributed at each step.
    pub runs: Vec<usize>,
}

impl MeanTrack {
    /// Number of steps.
    pub fn len(&self) -> usize {
        self.mean_m.len()
    }
    /// True when there is no step.
    pub fn is_empty(&self) -> bool {
        self.mean_m.is_empty()
    }
}

/// Per-step mean and spread of positions over runs. Each run is a slice of
/// per-step samples (`None` for a gap, and a run may be shorter than
/// `steps`); a step's statistics use the runs that have a sample there.
pub fn mean_positions(runs: &[Vec<Option<Vec3>>], steps: usize) -> MeanTrack {
    let mut out = MeanTrack::default();
    for i in 0..steps {
        let seen: Vec<Vec3> = runs
            .iter()
            .filter_map(|r| r.get(i).copied().flatten())
            .collect();
        out.runs.push(seen.len());
        if seen.is_empty() {
            out.mean_m.push(None);
            out.std_m.push(None);
            out.spread_m.push(None);
            continue;
        }
        let n = seen.len() as f64;
        let mean = seen.iter().fold(Vec3::ZERO, |a, p| a + *p).scale(1.0 / n);
        let var = seen.iter().fold(Vec3::ZERO, |a, p| {
            let d = *p - mean;
            a + Vec3::new(d.x * d.x, d.y * d.y, d.z * d.z)
        });
        let var = var.scale(1.0 / n);
        out.mean_m.push(Some(mean));
        out.std_m
            .push(Some(Vec3::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt())));
        out.spread_m.push(Some((var.x + var.y + var.z).sqrt()));
    }
    out
}

/// Per-step mean orientation over runs: the normalised sum of the
/// quaternions after flipping each into the hemisphere of the first (a good
/// approximation of the rotation mean when runs are close, as here).
pub fn mean_orientations(runs: &[Vec<Option<Quat>>], steps: usize) -> Vec<Option<Quat>> {
    (0..steps)
        .map(|i| {
            let mut seen = runs.iter().filter_map(|r| r.get(i).copied().flatten());
            let first = seen.next()?;
            let mut acc = first;
            for q in seen {
                let s = if q.dot(first) < 0.0 { -1.0 } else { 1.0 };
                acc = Quat::new(
                    acc.w + s * q.w,
                    acc.x + s * q.x,
                    acc.y + s * q.y,
                    acc.z + s * q.z,
                );
            }
            acc.normalized()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_std_of_two_runs() {
        let a = vec![
            Some(Vec3::new(0.0, 0.0, 0.0)),
            Some(Vec3::new(1.0, 0.0, 0.0)),
        ];
        let b = vec![Some(Vec3::new(2.0, 0.0, 0.0))];
        let m = mean_positions(&[a, b], 3);
        assert_eq!(m.mean_m[0], Some(Vec3::new(1.0, 0.0, 0.0)));
        assert_eq!(m.std_m[0], Some(Vec3::new(1.0, 0.0, 0.0)));
        assert_eq!(m.runs, vec![2, 1, 0]);
        assert_eq!(m.mean_m[1], Some(Vec3::new(1.0, 0.0, 0.0)));
        assert_eq!(m.spread_m[1], Some(0.0));
        assert_eq!(m.mean_m[2], None);
    }

    #[test]
    fn mean_orientation_ignores_sign() {
        let q = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), 0.5);
        let neg = Quat::new(-q.w, -q.x, -q.y, -q.z);
        let m = mean_orientations(&[vec![Some(q)], vec![Some(neg)]], 1);
        assert!(m[0].unwrap().angle_to(q) < 1e-12);
    }
}
