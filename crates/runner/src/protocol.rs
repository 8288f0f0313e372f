//! The child-process protocol: a [`Job`] goes to the child as JSON on its
//! standard input, a [`ChildResult`] comes back as JSON on its standard
//! output. Numbers travel as their IEEE bits so that the stored run is
//! exactly the simulated one.

use anyhow::{anyhow, Result};
use realitygap_core::controller::{RunOutcome, RunStatus};
use realitygap_core::engine::StabilityIssue;
use realitygap_core::instability::Instability;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::stitch::Handover;
use realitygap_core::trajectory::{BodyTrack, Trajectory};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// One run as the child process receives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Job {
    /// The scene file (TOML).
    pub scene_file: PathBuf,
    /// The engine's name.
    pub engine: String,
    /// The `--robot` value, if any (`mico2`, `official` or a URDF path).
    pub robot: Option<String>,
    /// `NAME=DIR` ROS package locations.
    pub packages: Vec<String>,
    /// `[ENGINE.]KEY=VALUE` engine settings.
    pub set: Vec<String>,
    /// `KEY=VALUE,...` perturbation specs.
    pub perturb: Vec<String>,
    /// This repeat's seed (see `realitygap_core::controller::repeat_seed`).
    pub seed: u64,
    /// The parameters file, absolute.
    #[serde(default)]
    pub params: Option<PathBuf>,
    /// Parameters as the text of a parameters file, used instead of
    /// `params` (a tune's candidates travel this way, without a file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub params_text: Option<String>,
    /// Only load the model and report success.
    pub check_only: bool,
    /// A stitched run: the engines of the phases (`engine` is the first);
    /// `None` for a run in `engine` alone.
    #[serde(default)]
    pub stitch: Option<Vec<String>>,
    /// Run even with settings the engine knows to be unstable for the
    /// model (`--allow-unstable`); the issues are then recorded in the run's
    /// manifest entry.
    #[serde(default)]
    pub allow_unstable: bool,
    /// A recorded episode to replay instead of the scene's schedule
    /// (`realitygap replay`): the scene file is then the replay's scene.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replay: Option<ReplayJob>,
}

/// The recorded episode a replay job drives the engine with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReplayJob {
    /// The results directory of the import that holds the episode.
    pub real_dir: PathBuf,
    /// The episode's run id.
    pub episode: String,
}

/// What the child process sends back.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ChildResult {
    /// When the run diverged: the time (seconds) and the reason.
    pub diverged: Option<(f64, String)>,
    /// Engine steps taken.
    pub engine_steps: u64,
    /// Wall time of the control loop, seconds.
    pub wall_time_s: f64,
    /// The tracked bodies' roles.
    pub roles: Vec<String>,
    /// Sample times (seconds), as IEEE bits.
    pub time_s: Vec<u64>,
    /// `[body][sample]`: x y z (metres) qw qx qy qz, as IEEE bits.
    pub poses: Vec<Vec<[u64; 7]>>,
    /// `[sample][joint]` joint angles (radians), as IEEE bits.
    pub joint_angles_rad: Vec<Vec<u64>>,
    /// `[sample][joint]` velocity commands (rad/s), as IEEE bits.
    pub commands_rad_s: Vec<Vec<u64>>,
    /// `[sample][joint]` joint velocities (rad/s), as IEEE bits, when the
    /// run recorded them (a replay).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_velocities_rad_s: Option<Vec<Vec<u64>>>,
    /// `[sample][joint]` servo efforts (N m), as IEEE bits, when the run
    /// recorded them (a replay).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_efforts_nm: Option<Vec<Vec<u64>>>,
    /// The handovers of a stitched run (empty otherwise).
    #[serde(default)]
    pub handovers: Vec<Handover>,
    /// The unstable settings the run was allowed to run with
    /// (`--allow-unstable`), empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stability_issues: Vec<StabilityIssue>,
    /// The signature of a numerical instability in the run's motion
    /// (`realitygap_core::instability`, stalls judged against the servos
    /// and gravity), when the run completed with one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instability: Option<Instability>,
    /// CPU time of the control loop (stepping and control, not the model
    /// load) on the worker's thread clock (`CLOCK_THREAD_CPUTIME_ID`), s;
    /// `None` where the platform has no such clock. `frontier` times its
    /// runs on Slurm with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_s: Option<f64>,
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn unbits(v: &[u64]) -> Vec<f64> {
    v.iter().map(|&b| f64::from_bits(b)).collect()
}

fn pose_bits(p: &Option<Pose>) -> [u64; 7] {
    let p = p.unwrap_or(Pose::IDENTITY);
    let (v, q) = (p.position_m, p.orientation);
    [v.x, v.y, v.z, q.w, q.x, q.y, q.z].map(f64::to_bits)
}

fn pose_from_bits(p: &[u64; 7]) -> Option<Pose> {
    let v = p.map(f64::from_bits);
    Some(Pose::new(
        Vec3::new(v[0], v[1], v[2]),
        Quat::new(v[3], v[4], v[5], v[6]),
    ))
}

impl ChildResult {
    /// The result of a finished run.
    pub fn from_outcome(out: &RunOutcome) -> ChildResult {
        let t = &out.trajectory;
        ChildResult {
            diverged: match &out.status {
                RunStatus::Completed => None,
                RunStatus::Diverged { t_s, reason } => Some((*t_s, reason.clone())),
            },
            engine_steps: out.engine_steps,
            wall_time_s: out.wall_time_s,
            roles: t.bodies.iter().map(|b| b.role.clone()).collect(),
            time_s: bits(&t.time_s),
            poses: t
                .bodies
                .iter()
                .map(|b| b.poses.iter().map(pose_bits).collect())
                .collect(),
            joint_angles_rad: t
                .joint_angles_rad
                .iter()
                .flatten()
                .map(|r| bits(r))
                .collect(),
            commands_rad_s: t
                .joint_velocity_commands_rad_s
                .iter()
                .flatten()
                .map(|r| bits(r))
                .collect(),
            joint_velocities_rad_s: t
                .joint_velocities_rad_s
                .as_ref()
                .map(|rows| rows.iter().map(|r| bits(r)).collect()),
            joint_efforts_nm: t
                .joint_efforts_nm
                .as_ref()
                .map(|rows| rows.iter().map(|r| bits(r)).collect()),
            handovers: Vec::new(),
            stability_issues: Vec::new(),
            instability: None,
            cpu_s: None,
        }
    }

    /// The trajectory, bit for bit the simulated one; an error when it is
    /// inconsistent.
    pub fn trajectory(&self) -> Result<Trajectory> {
        let t = Trajectory {
            time_s: unbits(&self.time_s),
            bodies: self
                .roles
                .iter()
                .zip(&self.poses)
                .map(|(role, poses)| BodyTrack {
                    role: role.clone(),
                    poses: poses.iter().map(pose_from_bits).collect(),
                })
                .collect(),
            joint_angles_rad: Some(self.joint_angles_rad.iter().map(|r| unbits(r)).collect()),
            // A replay of position or effort commands records no velocity
            // commands (and says so by an empty list with samples).
            joint_velocity_commands_rad_s: (self.time_s.is_empty()
                || !self.commands_rad_s.is_empty())
            .then(|| self.commands_rad_s.iter().map(|r| unbits(r)).collect()),
            joint_velocities_rad_s: self
                .joint_velocities_rad_s
                .as_ref()
                .map(|rows| rows.iter().map(|r| unbits(r)).collect()),
            joint_efforts_nm: self
                .joint_efforts_nm
                .as_ref()
                .map(|rows| rows.iter().map(|r| unbits(r)).collect()),
            ..Trajectory::default()
        };
        t.validate()
            .map_err(|e| anyhow!("the run's trajectory is inconsistent: {e}"))?;
        Ok(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn child_results_round_trip_exactly() {
        let mut t = Trajectory::with_bodies(&["wrist"]);
        t.time_s = vec![0.0, 0.05];
        let x = 0.1 + 0.2;
        t.bodies[0].poses = vec![Some(Pose::new(Vec3::new(x, -0.0, 1e-300), Quat::IDENTITY)); 2];
        t.joint_angles_rad = Some(vec![vec![x], vec![f64::MIN_POSITIVE]]);
        t.joint_velocity_commands_rad_s = Some(vec![vec![1.0 / 3.0], vec![-2.5]]);
        t.joint_velocities_rad_s = Some(vec![vec![0.1], vec![x]]);
        t.joint_efforts_nm = Some(vec![vec![-7.0], vec![1e-310]]);
        let outcome = RunOutcome {
            trajectory: t.clone(),
            status: RunStatus::Completed,
            engine_steps: 10,
            wall_time_s: 0.5,
        };
        let text = serde_json::to_string(&ChildResult::from_outcome(&outcome)).unwrap();
        let back: ChildResult = serde_json::from_str(&text).unwrap();
        assert_eq!(back.trajectory().unwrap(), t);
        assert!(back.trajectory().unwrap().time_s[1].to_bits() == 0.05f64.to_bits());
        // A replay of position commands: no velocity commands.
        let mut p = t.clone();
        p.joint_velocity_commands_rad_s = None;
        let outcome = RunOutcome {
            trajectory: p.clone(),
            ..outcome
        };
        let text = serde_json::to_string(&ChildResult::from_outcome(&outcome)).unwrap();
        let back: ChildResult = serde_json::from_str(&text).unwrap();
        assert_eq!(back.trajectory().unwrap(), p);
    }

    #[test]
    fn divergence_travels_and_bad_results_are_errors() {
        let outcome = RunOutcome {
            trajectory: Trajectory::with_bodies(&["wrist"]),
            status: RunStatus::Diverged {
                t_s: 1.25,
                reason: "NaN".into(),
            },
            engine_steps: 3,
            wall_time_s: 0.0,
        };
        let r = ChildResult::from_outcome(&outcome);
        assert_eq!(r.diverged, Some((1.25, "NaN".to_string())));
        let bad = ChildResult {
            roles: vec!["wrist".into()],
            time_s: bits(&[0.0, 0.05]),
            poses: vec![vec![pose_bits(&None)]],
            ..ChildResult::default()
        };
        assert!(bad
            .trajectory()
            .unwrap_err()
            .to_string()
            .contains("inconsistent"));
    }

    #[test]
    fn jobs_without_params_still_parse() {
        let text = r#"{"scene_file":"s.toml","engine":"mujoco","robot":null,"packages":[],"set":[],"perturb":[],"seed":7,"check_only":false}"#;
        let job: Job = serde_json::from_str(text).unwrap();
        assert_eq!((job.seed, job.params, job.stitch), (7, None, None));
    }
}
