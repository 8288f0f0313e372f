//! [`Trajectory`]: the motion of one run, whatever produced it.
//!
//! A trajectory is a sequence of samples at times `time_s` (seconds from the
//! start of the run). At each sample it holds the pose of every tracked body
//! (world frame of the source: the simulator's world, or the capture
//! system's own frame for real recordings), and, where the source knows
//! them, the joint angles and the commanded joint velocities.
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
