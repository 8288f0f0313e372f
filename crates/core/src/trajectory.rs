//! [`Trajectory`]: the motion of one run, whatever produced it.
//!
//! A trajectory is a sequence of samples at times `time_s` (seconds from the
//! start of the run). At each sample it holds the pose of every tracked body
//! (world frame of the source: the simulator's world, or the capture
//! system's own frame for real recordings), and, where the source knows
//! them, the joint angles, the commanded joint velocities, and for joint
//! recordings (a robot's own `/joint_states`) the measured joint velocities
//! and efforts. A run driven by recorded commands also carries those
//! commands, at their own timestamps ([`JointCommands`]).
//!
//! Tracked bodies are named by role: `wrist` (the frame of the arm's last
//! link, or the wrist marker body on the real arm), `cube`, `base`.
//! A pose may be missing at a sample (a lost marker in a capture): that is a
//! gap, `None`, never a pose at the origin.

use crate::pose::{Pose, Vec3};
use serde::{Deserialize, Serialize};

/// Role name of the wrist body.
pub const WRIST: &str = "wrist";
/// Role name of the cube.
pub const CUBE: &str = "cube";
/// Role name of the marker base next to the arm.
pub const BASE: &str = "base";

/// The samples of one tracked body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BodyTrack {
    /// Role of the body (`wrist`, `cube`, `base`, or a user name).
    pub role: String,
    /// One entry per sample; `None` where the body was not seen (a gap).
    pub poses: Vec<Option<Pose>>,
}

/// The motion of one run. All per-sample vectors have the same length as
/// `time_s`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Trajectory {
    /// Sample times in seconds from the start of the run, non-decreasing.
    pub time_s: Vec<f64>,
    /// Tracked bodies, each with one pose (or gap) per sample.
    pub bodies: Vec<BodyTrack>,
    /// Joint angles in radians, `[sample][joint]`, joints in order from the
    /// base (joint 1 first), when the source knows them.
    pub joint_angles_rad: Option<Vec<Vec<f64>>>,
    /// Commanded joint velocities in rad/s, `[sample][joint]`, when known.
    pub joint_velocity_commands_rad_s: Option<Vec<Vec<f64>>>,
    /// Measured joint velocities in rad/s (m/s for prismatic joints),
    /// `[sample][joint]`, when recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_velocities_rad_s: Option<Vec<Vec<f64>>>,
    /// Measured joint efforts in N m (N for prismatic joints),
    /// `[sample][joint]`, when recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_efforts_nm: Option<Vec<Vec<f64>>>,
    /// The joint commands the run was driven by, at their own timestamps,
    /// when known (a recording's commands; not the study's P controller).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commands: Option<JointCommands>,
}

/// What a joint command asks of the joint's servo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CommandKind {
    /// A joint position (rad, or m for prismatic joints): a position
    /// servo (PD) tracks it.
    Position,
    /// A joint velocity (rad/s, or m/s): a velocity servo (`kv`) tracks it.
    Velocity,
    /// A joint effort (N m, or N): applied as is.
    Effort,
}

impl CommandKind {
    /// Every kind, in a fixed order.
    pub const ALL: [CommandKind; 3] = [
        CommandKind::Position,
        CommandKind::Velocity,
        CommandKind::Effort,
    ];

    /// The lower-case name (`position`, `velocity`, `effort`).
    pub fn name(self) -> &'static str {
        match self {
            CommandKind::Position => "position",
            CommandKind::Velocity => "velocity",
            CommandKind::Effort => "effort",
        }
    }

    /// The kind with this lower-case name.
    pub fn from_name(name: &str) -> Option<CommandKind> {
        CommandKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Unit of a command value of this kind for a revolute joint.
    pub fn unit(self) -> &'static str {
        match self {
            CommandKind::Position => "rad",
            CommandKind::Velocity => "rad/s",
            CommandKind::Effort => "N m",
        }
    }
}

impl std::fmt::Display for CommandKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Two times closer than this are one instant, s: the resolution of a
/// ROS timestamp (1 ns), far above the rounding of seconds in `f64` (about
/// 2e-15 s at 10 s) and far below any engine's step.
pub const TIME_TIE_S: f64 = 1e-9;

/// Joint commands of one kind at their own timestamps: what a recording's
/// controller sent (ros2_control's command topic, a dataset's `action`).
/// Between two samples the command holds (zero-order hold).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointCommands {
    /// What the values ask of the servo.
    pub kind: CommandKind,
    /// The commanded joints, as 0-based indices into the trajectory's
    /// joint columns (the robot's actuated joints, in order from the base).
    pub joints: Vec<usize>,
    /// Time of each command, seconds from the start of the run,
    /// non-decreasing; may start before or after the first sample.
    pub time_s: Vec<f64>,
    /// `[command][commanded joint]`, in the unit of `kind`.
    pub values: Vec<Vec<f64>>,
}

impl JointCommands {
    /// Number of commands.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when there is no command.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// The command in force at time `t_s` (the latest at or before it),
    /// `None` before the first. A command within [`TIME_TIE_S`] after
    /// `t_s` counts as at it: times in seconds computed two ways (a
    /// command's timestamp, an engine step's `k dt` less a delay) differ
    /// by rounding where they are the same instant, and the command must
    /// then be in force, as in a controller that counts its ticks.
    pub fn held_at(&self, t_s: f64) -> Option<&[f64]> {
        let i = self.time_s.partition_point(|&c| c <= t_s + TIME_TIE_S);
        i.checked_sub(1).map(|i| self.values[i].as_slice())
    }

    /// Checks lengths, widths, finite non-decreasing times and joint
    /// indices below `joint_count` (when the trajectory has joints).
    pub fn validate(&self, joint_count: usize) -> Result<(), TrajectoryError> {
        let what = || format!("{} commands", self.kind);
        if self.values.len() != self.time_s.len() {
            return Err(TrajectoryError::LengthMismatch {
                what: what(),
                expected: self.time_s.len(),
                found: self.values.len(),
            });
        }
        if let Some((sample, r)) = self
            .values
            .iter()
            .enumerate()
            .find(|(_, r)| r.len() != self.joints.len())
        {
            return Err(TrajectoryError::JointCount {
                what: what(),
                sample,
                expected: self.joints.len(),
                found: r.len(),
            });
        }
        if let Some(i) = self
            .time_s
            .windows(2)
            .position(|w| w[0] > w[1] || w[0].is_nan() || w[1].is_nan())
            .or_else(|| self.time_s.iter().position(|t| !t.is_finite()))
        {
            return Err(TrajectoryError::Commands(format!(
                "command {i}: time is not finite or goes backwards"
            )));
        }
        if joint_count > 0 {
            if let Some(&j) = self.joints.iter().find(|&&j| j >= joint_count) {
                return Err(TrajectoryError::Commands(format!(
                    "commanded joint index {j} is beyond the {joint_count} joints"
                )));
            }
        }
        Ok(())
    }
}

/// A trajectory whose parts do not fit together.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// A per-sample vector has another length than `time_s`.
    #[error("{what} has {found} samples but the trajectory has {expected}")]
    LengthMismatch {
        /// Which part.
        what: String,
        /// Length of `time_s`.
        expected: usize,
        /// Length found.
        found: usize,
    },
    /// Joint rows differ in length.
    #[error("{what} sample {sample} has {found} joints, expected {expected}")]
    JointCount {
        /// Which part.
        what: String,
        /// Sample index.
        sample: usize,
        /// Expected joint count.
        expected: usize,
        /// Joint count found.
        found: usize,
    },
    /// Two bodies have the same role.
    #[error("body role '{0}' appears twice")]
    DuplicateRole(String),
    /// The commands do not fit (times, joint indices).
    #[error("commands: {0}")]
    Commands(String),
}

impl Trajectory {
    /// An empty trajectory with the given body roles.
    pub fn with_bodies<S: AsRef<str>>(roles: &[S]) -> Self {
        Trajectory {
            time_s: Vec::new(),
            bodies: roles
                .iter()
                .map(|r| BodyTrack {
                    role: r.as_ref().to_string(),
                    poses: Vec::new(),
                })
                .collect(),
            joint_angles_rad: None,
            joint_velocity_commands_rad_s: None,
            joint_velocities_rad_s: None,
            joint_efforts_nm: None,
            commands: None,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when there is no sample.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// The track of the body with this role.
    pub fn body(&self, role: &str) -> Option<&BodyTrack> {
        self.bodies.iter().find(|b| b.role == role)
    }

    /// Index of the body with this role.
    pub fn body_index(&self, role: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.role == role)
    }

    /// Positions (metres) of the body with this role, `None` at gaps; empty
    /// when the body is not tracked.
    pub fn positions(&self, role: &str) -> Vec<Option<Vec3>> {
        self.body(role)
            .map(|b| b.poses.iter().map(|p| p.map(|p| p.position_m)).collect())
            .unwrap_or_default()
    }

    /// Number of joints recorded (0 when none).
    pub fn joint_count(&self) -> usize {
        self.joint_angles_rad
            .as_ref()
            .or(self.joint_velocity_commands_rad_s.as_ref())
            .or(self.joint_velocities_rad_s.as_ref())
            .or(self.joint_efforts_nm.as_ref())
            .and_then(|rows| rows.first())
            .map_or(0, |r| r.len())
    }

    /// Checks that every part has one entry per sample and that roles are
    /// unique.
    pub fn validate(&self) -> Result<(), TrajectoryError> {
        let n = self.time_s.len();
        for (i, b) in self.bodies.iter().enumerate() {
            if b.poses.len() != n {
                return Err(TrajectoryError::LengthMismatch {
                    what: format!("body '{}'", b.role),
                    expected: n,
                    found: b.poses.len(),
                });
            }
            if self.bodies[..i].iter().any(|o| o.role == b.role) {
                return Err(TrajectoryError::DuplicateRole(b.role.clone()));
            }
        }
        for (what, rows) in [
            ("joint angles", &self.joint_angles_rad),
            (
                "joint velocity commands",
                &self.joint_velocity_commands_rad_s,
            ),
            ("joint velocities", &self.joint_velocities_rad_s),
            ("joint efforts", &self.joint_efforts_nm),
        ] {
            if let Some(rows) = rows {
                if rows.len() != n {
                    return Err(TrajectoryError::LengthMismatch {
                        what: what.to_string(),
                        expected: n,
                        found: rows.len(),
                    });
                }
                let expected = rows.first().map_or(0, |r| r.len());
                if let Some((sample, r)) =
                    rows.iter().enumerate().find(|(_, r)| r.len() != expected)
                {
                    return Err(TrajectoryError::JointCount {
                        what: what.to_string(),
                        sample,
                        expected,
                        found: r.len(),
                    });
                }
            }
        }
        if let Some(c) = &self.commands {
            c.validate(self.joint_count())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_catches_mismatch() {
        let mut t = Trajectory::with_bodies(&[WRIST, CUBE]);
        t.time_s = vec![0.0, 0.05];
        t.bodies[0].poses = vec![Some(Pose::IDENTITY), None];
        t.bodies[1].poses = vec![None];
        assert!(matches!(
            t.validate(),
            Err(TrajectoryError::LengthMismatch { .. })
        ));
        t.bodies[1].poses.push(None);
        assert_eq!(t.validate(), Ok(()));
        t.joint_angles_rad = Some(vec![vec![0.0; 6], vec![0.0; 5]]);
        assert!(matches!(
            t.validate(),
            Err(TrajectoryError::JointCount { sample: 1, .. })
        ));
        assert_eq!(t.positions(WRIST), vec![Some(Vec3::ZERO), None]);
    }
}
