//! The study's measures, on per-step series.
//!
//! All series are per control step; `None` marks a step without data, which
//! every measure skips (and counts where it matters).

use realitygap_core::{Quat, Vec3};
use serde::Serialize;

/// Distance between two position series at the same step, metres.
pub fn distance_series(a: &[Option<Vec3>], b: &[Option<Vec3>]) -> Vec<Option<f64>> {
    a.iter()
        .zip(b)
        .map(|(p, q)| match (p, q) {
            (Some(p), Some(q)) => Some(p.distance(*q)),
            _ => None,
        })
        .collect()
}

/// Distance of every step's position to a fixed point, metres.
pub fn distance_to_point(a: &[Option<Vec3>], point: Vec3) -> Vec<Option<f64>> {
    a.iter().map(|p| p.map(|p| p.distance(point))).collect()
}

/// Sum of a series over its steps with data (the study's accumulated
/// error), with the number of steps summed.
pub fn accumulate(series: &[Option<f64>]) -> (f64, usize) {
    series
        .iter()
        .flatten()
        .fold((0.0, 0), |(s, n), v| (s + v, n + 1))
}

/// Sum of a series over the steps `range` (clamped to the series).
pub fn accumulate_range(series: &[Option<f64>], range: std::ops::Range<usize>) -> f64 {
    let end = range.end.min(series.len());
    let start = range.start.min(end);
    series[start..end].iter().flatten().sum()
}

/// The last value of a series that has data.
pub fn last_value(series: &[Option<f64>]) -> Option<f64> {
    series.iter().rev().flatten().next().copied()
}

/// Time at which the distance to a goal enters `tolerance_m` and stays
/// within it to the end: the first step of the final stretch within
/// tolerance, times `period_s`. `None` when the last sample is outside.
pub fn convergence_time(
    distance_m: &[Option<f64>],
    tolerance_m: f64,
    period_s: f64,
) -> Option<f64> {
    let last = distance_m.iter().rposition(|d| d.is_some())?;
    if distance_m[last]? > tolerance_m {
        return None;
    }
    let mut first = last;
    while first > 0 {
        match distance_m[first - 1] {
            Some(d) if d > tolerance_m => break,
            _ => first -= 1,
        }
    }
    Some(first as f64 * period_s)
}

/// Overshoot past a goal, metres: the largest signed distance beyond the
/// goal along the direction of approach (from `start_m` to `goal_m`); 0 when
/// the motion never passes the goal.
pub fn overshoot(positions: &[Option<Vec3>], start_m: Vec3, goal_m: Vec3) -> f64 {
    let dir = goal_m - start_m;
    let len = dir.norm();
    if len == 0.0 {
        return 0.0;
    }
    let dir = dir.scale(1.0 / len);
    positions
        .iter()
        .flatten()
        .map(|p| (*p - goal_m).dot(dir))
        .fold(0.0, f64::max)
}

/// Number of times the wrist crosses the goal plane (normal to the approach
/// direction) once it has come within `band_m` of the goal: a count of
/// oscillations about the goal.
pub fn goal_crossings(
    positions: &[Option<Vec3>],
    start_m: Vec3,
    goal_m: Vec3,
    band_m: f64,
) -> usize {
    let dir = goal_m - start_m;
    let len = dir.norm();
    if len == 0.0 {
        return 0;
    }
    let dir = dir.scale(1.0 / len);
    let mut near = false;
    let mut side = 0.0f64; // sign of the last non-zero signed distance
    let mut crossings = 0;
    for p in positions.iter().flatten() {
        if p.distance(goal_m) <= band_m {
            near = true;
        }
        let s = (*p - goal_m).dot(dir);
        if s != 0.0 {
            if near && side != 0.0 && s.signum() != side {
                crossings += 1;
            }
            side = s.signum();
        }
    }
    crossings
}

/// Displacement of every step's position from a start point, metres.
pub fn displacement_series(positions: &[Option<Vec3>], start_m: Vec3) -> Vec<Option<f64>> {
    distance_to_point(positions, start_m)
}

/// First step at which the displacement exceeds `threshold_m`: contact
/// onset for a body that is still until pushed.
pub fn first_exceeding(series: &[Option<f64>], threshold_m: f64) -> Option<usize> {
    series
        .iter()
        .position(|d| d.is_some_and(|d| d > threshold_m))
}

/// Change of roll, pitch and yaw between two orientations, degrees, each
/// wrapped into (-180, 180].
pub fn rpy_change_deg(start: Quat, end: Quat) -> [f64; 3] {
    let (r0, p0, y0) = start.to_euler_rpy();
    let (r1, p1, y1) = end.to_euler_rpy();
    [r1 - r0, p1 - p0, y1 - y0].map(|d| realitygap_core::pose::wrap_angle(d).to_degrees())
}

/// Tilt of an orientation relative to a start orientation: the angle, in
/// degrees, between the start's and the current body z axes (a cube that
/// slides flat has 0; one tipped on its side has 90).
pub fn tilt_deg(start: Quat, now: Quat) -> f64 {
    let z = Vec3::new(0.0, 0.0, 1.0);
    let a = start.rotate(z);
    let b = now.rotate(z);
    a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
}

/// World-frame rotation since the first sample, per step: `q(t) q(0)^-1`.
/// Independent of how the tracked frame is mounted on the body, so a
/// marker body and a link frame can be compared.
pub fn rotation_since_start(orientations: &[Option<Quat>]) -> Vec<Option<Quat>> {
    let Some(q0) = orientations.iter().flatten().next().copied() else {
        return vec![None; orientations.len()];
    };
    orientations
        .iter()
        .map(|q| q.map(|q| q * q0.conjugate()))
        .collect()
}

/// Mean geodesic angle, degrees, between two series of orientations, over
/// the steps where both exist; `None` when there is none.
pub fn mean_angle_deg(a: &[Option<Quat>], b: &[Option<Quat>]) -> Option<f64> {
    let (sum, n) = a
        .iter()
        .zip(b)
        .fold((0.0, 0usize), |(s, n), (p, q)| match (p, q) {
            (Some(p), Some(q)) => (s + p.angle_to(*q), n + 1),
            _ => (s, n),
        });
    (n > 0).then(|| (sum / n as f64).to_degrees())
}

/// Summary of a goal-reaching motion.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GoalMeasures {
    /// Distance to the goal at the last step, metres.
    pub final_distance_m: Option<f64>,
    /// Time to enter and stay within the tolerance, seconds.
    pub convergence_time_s: Option<f64>,
    /// Tolerance used, metres.
    pub tolerance_m: f64,
    /// Overshoot past the goal along the approach, metres; `None` when the
    /// motion ends where it started (closer than 5 tolerances), where an
    /// approach direction is not defined.
    pub overshoot_m: Option<f64>,
    /// Crossings of the goal plane after first coming near it.
    pub goal_crossings: usize,
}

/// Computes [`GoalMeasures`] for a mean position series.
pub fn goal_measures(
    positions: &[Option<Vec3>],
    goal_m: Vec3,
    tolerance_m: f64,
    period_s: f64,
) -> GoalMeasures {
    let dist = distance_to_point(positions, goal_m);
    let start = positions.iter().flatten().next().copied().unwrap_or(goal_m);
    GoalMeasures {
        final_distance_m: last_value(&dist),
        convergence_time_s: convergence_time(&dist, tolerance_m, period_s),
        tolerance_m,
        overshoot_m: (start.distance(goal_m) > 5.0 * tolerance_m)
            .then(|| overshoot(positions, start, goal_m)),
        goal_crossings: goal_crossings(positions, start, goal_m, tolerance_m),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[f64]) -> Vec<Option<f64>> {
        v.iter().map(|x| Some(*x)).collect()
    }

    #[test]
    fn accumulate_skips_gaps() {
        assert_eq!(accumulate(&[Some(1.0), None, Some(2.5)]), (3.5, 2));
        assert_eq!(accumulate_range(&s(&[1.0, 2.0, 3.0, 4.0]), 1..3), 5.0);
        assert_eq!(accumulate_range(&s(&[1.0]), 3..9), 0.0);
    }

    #[test]
    fn convergence_needs_to_stay_inside() {
        let d = s(&[0.5, 0.2, 0.005, 0.02, 0.008, 0.004, 0.001]);
        assert_eq!(convergence_time(&d, 0.01, 0.05), Some(4.0 * 0.05));
        assert_eq!(convergence_time(&s(&[0.5, 0.2]), 0.01, 0.05), None);
        assert_eq!(convergence_time(&s(&[0.001, 0.002]), 0.01, 0.05), Some(0.0));
    }

    #[test]
    fn overshoot_and_crossings() {
        let goal = Vec3::new(1.0, 0.0, 0.0);
        let path: Vec<Option<Vec3>> = [0.0, 0.5, 0.95, 1.1, 0.97, 1.02, 1.0]
            .iter()
            .map(|x| Some(Vec3::new(*x, 0.0, 0.0)))
            .collect();
        assert!((overshoot(&path, Vec3::ZERO, goal) - 0.1).abs() < 1e-12);
        assert_eq!(goal_crossings(&path, Vec3::ZERO, goal, 0.06), 3);
        let g = goal_measures(&path, goal, 0.05, 0.05);
        assert_eq!(g.final_distance_m, Some(0.0));
        assert_eq!(g.convergence_time_s, Some(4.0 * 0.05));
    }

    #[test]
    fn tilt_of_a_tipped_cube() {
        let q = Quat::from_axis_angle(Vec3::new(0.0, 1.0, 0.0), std::f64::consts::FRAC_PI_2);
        assert!((tilt_deg(Quat::IDENTITY, q) - 90.0).abs() < 1e-9);
        let yawed = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), 1.0);
        assert!(tilt_deg(Quat::IDENTITY, yawed).abs() < 1e-6);
        let c = rpy_change_deg(Quat::IDENTITY, yawed);
        assert!((c[2] - 1.0f64.to_degrees()).abs() < 1e-9);
    }

    #[test]
    fn rotation_since_start_is_mounting_independent() {
        let mount = Quat::from_axis_angle(Vec3::new(1.0, 1.0, 0.0), 0.7);
        let motion: Vec<Option<Quat>> = (0..5)
            .map(|i| {
                Some(Quat::from_axis_angle(
                    Vec3::new(0.0, 1.0, 0.0),
                    i as f64 * 0.2,
                ))
            })
            .collect();
        let marker: Vec<Option<Quat>> = motion.iter().map(|q| q.map(|q| q * mount)).collect();
        let a = rotation_since_start(&motion);
        let b = rotation_since_start(&marker);
        assert!(mean_angle_deg(&a, &b).unwrap() < 1e-9);
    }
}
