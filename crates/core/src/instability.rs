//! Runtime signatures of numerical instability in a simulated run, beyond
//! NaN and divergence, read from the joint angles and the controller's
//! velocity commands at the sample rate.
//!
//! Two signatures, each of one joint:
//! - **stall against a saturated command**: the controller asks the joint
//!   for its full speed in one direction for a whole window (the command at
//!   the run's largest magnitude, the clamp), yet the joint covers less than
//!   [`InstabilityOptions::stall_fraction`] of the commanded travel in that
//!   direction. A velocity servo whose damping is integrated past its
//!   stable bound chatters at the step rate: the mean velocity that
//!   reaches the samples is near zero whatever the command (MuJoCo's Euler
//!   on the iiwa's wrist, issue 18), and a step too coarse for the arm's
//!   coupling leaves a joint stuck against its command (Bullet at 0.05 s
//!   on scene 2). A gravity sag does not saturate the command: its error
//!   is `load / (gain * kv)`, a few degrees.
//! - **sign flips at the sample rate**: consecutive per-sample displacements
//!   of more than [`InstabilityOptions::flip_amplitude_rad`] alternating in
//!   sign [`InstabilityOptions::flip_count`] times in a row. The study's
//!   controller (gain 10/s at 20 Hz removes half the error per period)
//!   never overshoots, so a joint swinging back and forth at the sample
//!   rate is the aliased image of a step-rate oscillation.
//!
//! Both need the joint angles and commands of the trajectory (simulated
//! runs and recorded runs that carry them); a trajectory without them is
//! not checked. A stall can also be physics: a joint whose load (gravity)
//! is beyond what its servo gives at the commanded speed, `kv |v_cmd|`
//! capped at the force limit, does not move. So [`detect`] counts a stall
//! only where the caller's `stall_explained` says the load cannot explain
//! it: the runner, which knows the scene's servos and the robot, calls
//! [`gravity_explains`] (a load below half the servo's capacity leaves the
//! joint at least half the commanded speed, `v >= v_cmd - load / kv`, so a
//! stall below a tenth of it is not the load's); the run health, which
//! sees only the trajectory, checks the sign flips alone.

use crate::robot::RobotModel;
use crate::scene::Scene;
use crate::trajectory::Trajectory;

/// Thresholds of the instability signatures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InstabilityOptions {
    /// Length of the stall window, s. Default 1 s (20 samples at 20 Hz).
    pub window_s: f64,
    /// A stall covers less than this share of the commanded travel in the
    /// commanded direction. Default 0.1.
    pub stall_fraction: f64,
    /// A command counts as saturated at this share of the run's largest
    /// command magnitude or more. Default 0.999.
    pub saturation_share: f64,
    /// Smallest per-sample displacement that counts in a sign flip, rad.
    /// Default 0.2 degree.
    pub flip_amplitude_rad: f64,
    /// Sign flips in a row that make the signature. Default 6.
    pub flip_count: usize,
}

impl Default for InstabilityOptions {
    fn default() -> Self {
        InstabilityOptions {
            window_s: 1.0,
            stall_fraction: 0.1,
            saturation_share: 0.999,
            flip_amplitude_rad: 0.2_f64.to_radians(),
            flip_count: 6,
        }
    }
}

/// The first signature found in a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Instability {
    /// Joint number, 1-based, in the trajectory's joint order.
    pub joint: usize,
    /// First sample of the signature.
    pub first_sample: usize,
    /// Its time, s.
    pub t_s: f64,
    /// What was seen, with the numbers.
    pub reason: String,
}

/// How a run message starts when the run was stored as unstable.
pub const MESSAGE_PREFIX: &str = "unstable: joint ";

impl Instability {
    /// The run message of a run stored as unstable:
    /// `unstable: joint J at sample S (t = T s): REASON`, read back by
    /// [`Instability::from_message`].
    pub fn to_message(&self) -> String {
        format!(
            "{MESSAGE_PREFIX}{} at sample {} (t = {} s): {}",
            self.joint, self.first_sample, self.t_s, self.reason
        )
    }

    /// The instability of a message written by [`Instability::to_message`];
    /// `None` for any other message.
    pub fn from_message(message: &str) -> Option<Instability> {
        let rest = message.strip_prefix(MESSAGE_PREFIX)?;
        let (joint, rest) = rest.split_once(" at sample ")?;
        let (sample, rest) = rest.split_once(" (t = ")?;
        let (t_s, reason) = rest.split_once(" s): ")?;
        Some(Instability {
            joint: joint.parse().ok()?,
            first_sample: sample.parse().ok()?,
            t_s: t_s.parse().ok()?,
            reason: reason.to_string(),
        })
    }
}

/// Joint `j`'s column of a `[sample][joint]` table.
fn column(rows: &[Vec<f64>], j: usize) -> Vec<f64> {
    rows.iter()
        .map(|r| r.get(j).copied().unwrap_or(f64::NAN))
        .collect()
}

/// Whether a load explains a stall of joint `j` (0-based) at sample `i`.
pub type StallExplained<'a> = &'a dyn Fn(usize, usize) -> bool;

/// The first stall of joint `j` (0-based): `(first sample, commanded
/// travel, covered travel)`, rad.
fn stall(
    t: &[f64],
    (q, cmd): (&[f64], &[f64]),
    (j, v_max, window): (usize, f64, usize),
    opts: &InstabilityOptions,
    explained: StallExplained<'_>,
) -> Option<(usize, f64, f64)> {
    let n = t.len().min(q.len()).min(cmd.len());
    let mut run = 0usize;
    for i in 0..n.saturating_sub(1) {
        let saturated =
            v_max > 0.0 && cmd[i].abs() >= opts.saturation_share * v_max && !explained(i, j);
        run = match (
            saturated,
            run > 0 && i > 0 && cmd[i].signum() == cmd[i - 1].signum(),
        ) {
            (false, _) => 0,
            (true, true) => run + 1,
            (true, false) => 1,
        };
        if run >= window {
            let s = i + 1 - window;
            let wanted: f64 = (s..=i).map(|k| cmd[k] * (t[k + 1] - t[k])).sum();
            let covered = (q[i + 1] - q[s]) * wanted.signum();
            if covered < opts.stall_fraction * wanted.abs() {
                return Some((s, wanted, q[i + 1] - q[s]));
            }
        }
    }
    None
}

/// The first run of `flip_count` sign flips of joint angle steps larger
/// than the amplitude: the sample where it starts.
fn flips(q: &[f64], opts: &InstabilityOptions) -> Option<usize> {
    let d: Vec<f64> = q.windows(2).map(|w| w[1] - w[0]).collect();
    let mut count = 0usize;
    for i in 1..d.len() {
        let flip = d[i].abs() > opts.flip_amplitude_rad
            && d[i - 1].abs() > opts.flip_amplitude_rad
            && d[i] * d[i - 1] < 0.0;
        count = if flip { count + 1 } else { 0 };
        if count >= opts.flip_count {
            return Some(i - count);
        }
    }
    None
}

/// The earliest instability signature of `traj` (see the module
/// documentation), counting stalls only at samples and joints where
/// `stall_explained` is false; `None` when it has none or lacks joint
/// angles or commands.
pub fn detect(
    traj: &Trajectory,
    opts: &InstabilityOptions,
    stall_explained: StallExplained<'_>,
) -> Option<Instability> {
    let (Some(angles), Some(commands)) =
        (&traj.joint_angles_rad, &traj.joint_velocity_commands_rad_s)
    else {
        return None;
    };
    let t = &traj.time_s;
    if t.len() < 3 {
        return None;
    }
    let period = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    let window = ((opts.window_s / period).round() as usize).max(2);
    let joints = angles.first().map_or(0, Vec::len);
    let v_max = commands
        .iter()
        .flatten()
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let mut found: Vec<Instability> = Vec::new();
    for j in 0..joints {
        let q = column(angles, j);
        let cmd = column(commands, j);
        let found_stall = stall(t, (&q, &cmd), (j, v_max, window), opts, stall_explained);
        if let Some((s, wanted, covered)) = found_stall {
            found.push(Instability {
                joint: j + 1,
                first_sample: s,
                t_s: t[s],
                reason: format!(
                    "joint {} stalled against a saturated command: asked for {:.1} deg over {:.2} s, moved {:.1} deg",
                    j + 1,
                    wanted.to_degrees(),
                    window as f64 * period,
                    covered.to_degrees()
                ),
            });
        }
        if let Some(s) = flips(&q, opts) {
            found.push(Instability {
                joint: j + 1,
                first_sample: s,
                t_s: t[s],
                reason: format!(
                    "joint {} reversed direction at {} samples in a row (steps over {:.2} deg)",
                    j + 1,
                    opts.flip_count + 1,
                    opts.flip_amplitude_rad.to_degrees()
                ),
            });
        }
    }
    found.into_iter().min_by(|a, b| {
        a.first_sample
            .cmp(&b.first_sample)
            .then(a.joint.cmp(&b.joint))
    })
}

/// The stall test of a run of `scene` with `robot`: joint `j` (the
/// scene's actuator order) at sample `i` of `traj` is explained when the
/// gravity torque on it at the sampled angles is at least half of what
/// its servo gives at the commanded speed (`kv |v_cmd|`, capped at the
/// force limit). Held joints are at their scene angles.
pub fn gravity_explains<'a>(
    scene: &'a Scene,
    robot: &'a RobotModel,
    traj: &'a Trajectory,
) -> impl Fn(usize, usize) -> bool + 'a {
    let joint_index: Vec<Option<usize>> = scene
        .actuators
        .iter()
        .map(|a| robot.joint_by_name(&a.joint))
        .collect();
    let mut held = vec![0.0; robot.joints.len()];
    for (name, rad) in &scene.robot.held_joints_rad {
        if let Some(k) = robot.joint_by_name(name) {
            held[k] = *rad;
        }
    }
    move |i: usize, j: usize| {
        let (Some(angles), Some(commands), Some(Some(k))) = (
            traj.joint_angles_rad.as_ref().and_then(|a| a.get(i)),
            traj.joint_velocity_commands_rad_s
                .as_ref()
                .and_then(|c| c.get(i)),
            joint_index.get(j),
        ) else {
            return true;
        };
        let mut positions = held.clone();
        for (jj, q) in angles.iter().enumerate() {
            if let Some(Some(kk)) = joint_index.get(jj) {
                positions[*kk] = *q;
            }
        }
        let tau = robot.gravity_torques(&scene.robot.base, &positions, scene.gravity_m_s2)[*k];
        let servo = &scene.actuators[j];
        let capacity =
            (servo.kv * commands.get(j).copied().unwrap_or(0.0).abs()).min(servo.force_limit);
        tau.abs() >= 0.5 * capacity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One joint following `cmd` with its angle from `q`, at 20 Hz.
    fn traj(q: &[f64], cmd: &[f64]) -> Trajectory {
        let mut t = Trajectory::with_bodies::<&str>(&[]);
        t.time_s = (0..q.len()).map(|i| i as f64 * 0.05).collect();
        t.joint_angles_rad = Some(q.iter().map(|v| vec![0.0, *v]).collect());
        t.joint_velocity_commands_rad_s = Some(cmd.iter().map(|v| vec![0.0, *v]).collect());
        t
    }

    #[test]
    fn the_run_message_reads_back() {
        let i = Instability {
            joint: 7,
            first_sample: 12,
            t_s: 0.6000000000000001,
            reason: "joint 7 stalled (asked for 30.0 deg)".into(),
        };
        assert_eq!(Instability::from_message(&i.to_message()), Some(i));
        assert_eq!(Instability::from_message("diverged at t = 1 s"), None);
    }

    #[test]
    fn a_load_beyond_the_servo_explains_a_stall() {
        let mut cmd = vec![0.0; 10];
        cmd.extend(vec![-0.5; 30]);
        let q = vec![0.3; 40];
        let explained = |_: usize, j: usize| j == 1;
        assert_eq!(
            detect(&traj(&q, &cmd), &InstabilityOptions::default(), &explained),
            None
        );
    }

    #[test]
    fn a_tracking_joint_is_healthy() {
        // Saturated at 0.5 rad/s for 2 s, the joint follows.
        let cmd = vec![0.5; 41];
        let q: Vec<f64> = (0..41).map(|i| i as f64 * 0.05 * 0.5).collect();
        assert_eq!(
            detect(&traj(&q, &cmd), &InstabilityOptions::default(), &|_, _| {
                false
            }),
            None
        );
    }

    #[test]
    fn a_gravity_sag_is_not_a_stall() {
        // 2.4 deg below the target: command 24 deg/s, below the clamp of 30
        // reached at the start; the joint does not move.
        let mut cmd = vec![30f64.to_radians(); 5];
        cmd.extend(vec![24f64.to_radians(); 60]);
        let q = vec![0.7; 65];
        assert_eq!(
            detect(&traj(&q, &cmd), &InstabilityOptions::default(), &|_, _| {
                false
            }),
            None
        );
    }

    #[test]
    fn a_stall_is_found_with_joint_and_time() {
        let mut cmd = vec![0.0; 10];
        cmd.extend(vec![-0.5; 30]);
        let q = vec![0.3; 40];
        let found = detect(&traj(&q, &cmd), &InstabilityOptions::default(), &|_, _| {
            false
        })
        .unwrap();
        assert_eq!((found.joint, found.first_sample), (2, 10));
        assert!((found.t_s - 0.5).abs() < 1e-12);
        assert!(found.reason.contains("joint 2 stalled"), "{}", found.reason);
    }

    #[test]
    fn sample_rate_flips_are_found() {
        let q: Vec<f64> = (0..30)
            .map(|i| if i >= 12 && i % 2 == 1 { 0.05 } else { 0.0 })
            .collect();
        let cmd = vec![0.0; 30];
        let found = detect(&traj(&q, &cmd), &InstabilityOptions::default(), &|_, _| {
            false
        })
        .unwrap();
        assert_eq!((found.joint, found.first_sample), (2, 12));
        assert!(found.reason.contains("reversed direction"));
        // Below the amplitude: jitter of a settled joint is no signature.
        let small: Vec<f64> = q.iter().map(|v| v * 0.01).collect();
        assert_eq!(
            detect(
                &traj(&small, &cmd),
                &InstabilityOptions::default(),
                &|_, _| false
            ),
            None
        );
    }
}
