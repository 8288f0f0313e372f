//! Run health: checks that decide whether a run can be trusted.
//!
//! A run is *flagged* when any check fails. In the default analysis mode
//! flagged runs are left out of a source's means and listed; in study mode
//! they are averaged in, as the reference study did.

use realitygap_core::instability::{self, InstabilityOptions};
use realitygap_core::Trajectory;
use serde::Serialize;

/// Thresholds of the health checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HealthOptions {
    /// A position component beyond this magnitude (metres) means the
    /// simulation diverged. Default 10 m: the arm reaches under 1 m.
    pub divergence_bound_m: f64,
    /// A stretch of bit-identical poses of every tracked body longer than
    /// this fraction of the run is flagged as frozen. Default 0.5: a
    /// simulator that locks its motors at rest (V-Rep does) legitimately
    /// repeats a pose for seconds at the end of a scene.
    pub frozen_min_fraction: f64,
    /// ... and at least this long, in seconds. Default 2 s.
    pub frozen_min_s: f64,
    /// Thresholds of the runtime instability signatures
    /// ([`realitygap_core::instability`]).
    pub instability: InstabilityOptions,
}

impl Default for HealthOptions {
    fn default() -> Self {
        HealthOptions {
            divergence_bound_m: 10.0,
            frozen_min_fraction: 0.5,
            frozen_min_s: 2.0,
            instability: InstabilityOptions::default(),
        }
    }
}

/// One failed check.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "flag", rename_all = "snake_case")]
pub enum HealthFlag {
    /// A NaN or infinite value in a pose.
    NonFinite {
        /// First sample with a non-finite value.
        first_sample: usize,
        /// Its time, seconds.
        t_s: f64,
    },
    /// A position beyond the divergence bound.
    Diverged {
        /// First sample beyond the bound.
        first_sample: usize,
        /// Its time, seconds.
        t_s: f64,
        /// Largest position magnitude seen in the run, metres.
        max_abs_m: f64,
    },
    /// The motion has a signature of numerical instability
    /// ([`realitygap_core::instability`]): a joint reversing direction at
    /// the sample rate (found here from the trajectory), or stalled
    /// against a saturated command with no load to explain it (found by
    /// the runner, which knows the servos and the robot, and recorded in
    /// the run's manifest entry as `extra.unstable`).
    Unstable {
        /// The joint, 1-based, in the trajectory's joint order.
        joint: usize,
        /// First sample of the signature.
        first_sample: usize,
        /// Its time, seconds.
        t_s: f64,
        /// What was seen.
        reason: String,
    },
    /// Samples where every tracked position is exactly zero (a simulator
    /// that wrote nothing).
    ZeroRows {
        /// How many such samples.
        count: usize,
        /// The first of them.
        first_sample: usize,
    },
    /// A long stretch of bit-identical poses: the simulation stopped.
    Frozen {
        /// First sample of the stretch.
        first_sample: usize,
        /// Length of the stretch in samples.
        samples: usize,
        /// Length in seconds.
        duration_s: f64,
    },
    /// Samples where a tracked body was not seen (lost marker).
    Gaps {
        /// Body role.
        body: String,
        /// Number of missing samples.
        count: usize,
    },
    /// The run ended before the analysis window (cut in default mode).
    Short {
        /// Samples available.
        samples: usize,
        /// Samples the scene needs.
        needed: usize,
    },
    /// The run was recorded as failed by the engine or importer.
    Failed {
        /// What went wrong.
        message: String,
    },
}

impl HealthFlag {
    /// Short name of the flag, e.g. `diverged`.
    pub fn name(&self) -> &'static str {
        match self {
            HealthFlag::NonFinite { .. } => "non_finite",
            HealthFlag::Diverged { .. } => "diverged",
            HealthFlag::Unstable { .. } => "unstable",
            HealthFlag::ZeroRows { .. } => "zero_rows",
            HealthFlag::Frozen { .. } => "frozen",
            HealthFlag::Gaps { .. } => "gaps",
            HealthFlag::Short { .. } => "short",
            HealthFlag::Failed { .. } => "failed",
        }
    }

    /// True when the flag makes the run unusable for means. Gaps are not:
    /// a run with a few lost markers still counts where it was seen.
    pub fn excludes(&self) -> bool {
        !matches!(self, HealthFlag::Gaps { .. } | HealthFlag::Short { .. })
    }

    /// One-line human description.
    pub fn describe(&self) -> String {
        match self {
            HealthFlag::NonFinite { first_sample, t_s } => {
                format!("non-finite value from sample {first_sample} (t = {t_s:.2} s)")
            }
            HealthFlag::Diverged { first_sample, t_s, max_abs_m } => format!(
                "diverged at sample {first_sample} (t = {t_s:.2} s), positions up to {max_abs_m:.3e} m"
            ),
            HealthFlag::Unstable {
                first_sample,
                t_s,
                reason,
                ..
            } => format!("unstable from sample {first_sample} (t = {t_s:.2} s): {reason}"),
            HealthFlag::ZeroRows { count, first_sample } => {
                format!("{count} all-zero samples, first at sample {first_sample}")
            }
            HealthFlag::Frozen { first_sample, samples, duration_s } => format!(
                "frozen for {samples} samples ({duration_s:.2} s) from sample {first_sample}"
            ),
            HealthFlag::Gaps { body, count } => format!("{count} missing samples of '{body}'"),
            HealthFlag::Short { samples, needed } => {
                format!("only {samples} of {needed} samples after alignment")
            }
            HealthFlag::Failed { message } => format!("failed: {message}"),
        }
    }
}

/// The health of one run: every failed check.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct RunHealth {
    /// Failed checks, in the order checked.
    pub flags: Vec<HealthFlag>,
}

impl RunHealth {
    /// True when some flag excludes the run from means.
    pub fn is_excluded(&self) -> bool {
        self.flags.iter().any(HealthFlag::excludes)
    }
    /// Names of the flags, comma-separated (empty when healthy).
    pub fn summary(&self) -> String {
        self.flags
            .iter()
            .map(|f| f.name())
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// Seconds at sample `i` (`NaN` past the end).
fn t_at(traj: &Trajectory, i: usize) -> f64 {
    traj.time_s.get(i).copied().unwrap_or(f64::NAN)
}

/// The first non-finite sample and the first diverged one (a position
/// beyond the bound), with the largest finite coordinate, metres.
fn non_finite_and_diverged(traj: &Trajectory, opts: &HealthOptions, flags: &mut Vec<HealthFlag>) {
    let t_at = |i: usize| t_at(traj, i);
    let n = traj.len();
    let mut first_nonfinite = None;
    let mut first_diverged = None;
    let mut max_abs = 0.0f64;
    for i in 0..n {
        for b in &traj.bodies {
            if let Some(p) = b.poses[i] {
                let finite = p.is_finite();
                if !finite && first_nonfinite.is_none() {
                    first_nonfinite = Some(i);
                }
                for c in p.position_m.to_array() {
                    if c.is_finite() {
                        max_abs = max_abs.max(c.abs());
                        if c.abs() > opts.divergence_bound_m && first_diverged.is_none() {
                            first_diverged = Some(i);
                        }
                    }
                }
            }
        }
        if let Some(q) = &traj.joint_angles_rad {
            if first_nonfinite.is_none() && q[i].iter().any(|v| !v.is_finite()) {
                first_nonfinite = Some(i);
            }
        }
    }
    if let Some(i) = first_nonfinite {
        flags.push(HealthFlag::NonFinite {
            first_sample: i,
            t_s: t_at(i),
        });
    }
    if let Some(i) = first_diverged {
        flags.push(HealthFlag::Diverged {
            first_sample: i,
            t_s: t_at(i),
            max_abs_m: max_abs,
        });
    }
}

/// Samples where every seen body is exactly at the origin.
fn zero_rows(traj: &Trajectory) -> Vec<usize> {
    let n = traj.len();
    (0..n)
        .filter(|&i| {
            let mut seen = false;
            let all_zero = traj.bodies.iter().all(|b| match b.poses[i] {
                Some(p) => {
                    seen = true;
                    p.position_m.to_array() == [0.0, 0.0, 0.0]
                }
                None => true,
            });
            seen && all_zero
        })
        .collect()
}

/// The longest stretch of bit-identical rows (zero rows excluded), flagged
/// when it lasts long enough, absolutely and as a share of the run.
fn frozen(
    traj: &Trajectory,
    opts: &HealthOptions,
    zero_rows: &[usize],
    flags: &mut Vec<HealthFlag>,
) {
    let t_at = |i: usize| t_at(traj, i);
    let n = traj.len();
    if n > 1 {
        let mut best = (0usize, 0usize); // (start, len in samples)
        let mut start = 0usize;
        for i in 1..=n {
            let same = i < n
                && traj.bodies.iter().all(|b| b.poses[i] == b.poses[i - 1])
                && zero_rows.binary_search(&i).is_err();
            if !same {
                let len = i - start;
                if len > best.1 {
                    best = (start, len);
                }
                start = i;
            }
        }
        let (s, len) = best;
        if len > 1 {
            let duration = t_at(s + len - 1) - t_at(s);
            let total = t_at(n - 1) - t_at(0);
            if duration >= opts.frozen_min_s
                && total > 0.0
                && duration >= opts.frozen_min_fraction * total
            {
                flags.push(HealthFlag::Frozen {
                    first_sample: s,
                    samples: len,
                    duration_s: duration,
                });
            }
        }
    }
}

/// Runs every health check on a trajectory.
pub fn check(traj: &Trajectory, opts: &HealthOptions) -> RunHealth {
    let mut flags = Vec::new();
    non_finite_and_diverged(traj, opts, &mut flags);
    // The trajectory alone cannot tell a stall from a load beyond the
    // servo: every stall counts as explained here.
    if let Some(found) = instability::detect(traj, &opts.instability, &|_, _| true) {
        flags.push(HealthFlag::Unstable {
            joint: found.joint,
            first_sample: found.first_sample,
            t_s: found.t_s,
            reason: found.reason,
        });
    }
    let zero_rows = zero_rows(traj);
    if let Some(&first) = zero_rows.first() {
        flags.push(HealthFlag::ZeroRows {
            count: zero_rows.len(),
            first_sample: first,
        });
    }

    frozen(traj, opts, &zero_rows, &mut flags);
    // Gaps.
    for b in &traj.bodies {
        let count = b.poses.iter().filter(|p| p.is_none()).count();
        if count > 0 {
            flags.push(HealthFlag::Gaps {
                body: b.role.clone(),
                count,
            });
        }
    }
    RunHealth { flags }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::{Pose, Quat, Vec3};

    fn traj(points: &[[f64; 3]]) -> Trajectory {
        let mut t = Trajectory::with_bodies(&["wrist"]);
        for (i, p) in points.iter().enumerate() {
            t.time_s.push(i as f64 * 0.05);
            t.bodies[0]
                .poses
                .push(Some(Pose::new(Vec3::from_array(*p), Quat::IDENTITY)));
        }
        t
    }

    #[test]
    fn healthy_run_has_no_flags() {
        let pts: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.001, 0.0, 0.8]).collect();
        assert!(check(&traj(&pts), &HealthOptions::default())
            .flags
            .is_empty());
    }

    #[test]
    fn nan_and_divergence_are_flagged() {
        let mut pts: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.001, 0.0, 0.8]).collect();
        pts[10] = [1e17, 0.0, 0.0];
        pts[20] = [f64::NAN, 0.0, 0.0];
        let h = check(&traj(&pts), &HealthOptions::default());
        assert_eq!(h.summary(), "non_finite,diverged");
        assert!(matches!(
            h.flags[1],
            HealthFlag::Diverged {
                first_sample: 10,
                ..
            }
        ));
        assert!(h.is_excluded());
    }

    #[test]
    fn zero_rows_and_freeze_are_flagged() {
        let mut pts: Vec<[f64; 3]> = vec![[0.0; 3]; 31];
        pts.extend(std::iter::repeat_n([1.12, -1.9, 1.08], 369));
        let h = check(&traj(&pts), &HealthOptions::default());
        assert_eq!(h.summary(), "zero_rows,frozen");
        assert!(matches!(
            h.flags[0],
            HealthFlag::ZeroRows {
                count: 31,
                first_sample: 0
            }
        ));
        assert!(matches!(
            h.flags[1],
            HealthFlag::Frozen {
                first_sample: 31,
                samples: 369,
                ..
            }
        ));
    }

    #[test]
    fn short_rest_is_not_frozen() {
        // 3 s of an exactly locked motor at the end of a 20 s run is normal.
        let mut pts: Vec<[f64; 3]> = (0..340).map(|i| [i as f64 * 0.001, 0.0, 0.8]).collect();
        pts.extend(std::iter::repeat_n([0.5, 0.0, 0.3], 60));
        assert!(check(&traj(&pts), &HealthOptions::default())
            .flags
            .is_empty());
    }

    #[test]
    fn gaps_do_not_exclude() {
        let mut t = traj(&[[0.0, 0.0, 0.8], [0.0, 0.0, 0.8], [0.1, 0.0, 0.8]]);
        t.bodies[0].poses[1] = None;
        let h = check(&t, &HealthOptions::default());
        assert_eq!(h.summary(), "gaps");
        assert!(!h.is_excluded());
    }
}
