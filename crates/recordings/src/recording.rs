//! [`Recording`]: one episode of a robot's joint recording as the importers
//! read it (joint names as recorded, absolute timestamps), and the step that
//! turns it into a run of the robot ([`Recording::to_trajectory`]): joints
//! matched against the URDF, times from the episode's start, end-effector
//! poses by forward kinematics.

use realitygap_core::robot::RobotModel;
use realitygap_core::trajectory::WRIST;
use realitygap_core::{BodyTrack, CommandKind, JointCommands, Pose, Trajectory};
use realitygap_data::ImportError;
use std::path::{Path, PathBuf};

/// Nanoseconds per second.
pub const NS_PER_S: f64 = 1e9;

/// Measured joint states: one row per sample, joints in `names` order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointStates {
    /// Joint names as recorded.
    pub names: Vec<String>,
    /// Sample times, nanoseconds (any epoch), non-decreasing.
    pub time_ns: Vec<i64>,
    /// Joint positions, rad (m for prismatic joints), `[sample][joint]`.
    pub position: Vec<Vec<f64>>,
    /// Joint velocities, rad/s (m/s), `[sample][joint]`, when recorded.
    pub velocity: Option<Vec<Vec<f64>>>,
    /// Joint efforts, N m (N), `[sample][joint]`, when recorded.
    pub effort: Option<Vec<Vec<f64>>>,
}

/// Commands sent to the joints: one row per command, joints in `names`
/// order, each holding until the next.
#[derive(Debug, Clone, PartialEq)]
pub struct Commands {
    /// What the values ask of the servos.
    pub kind: CommandKind,
    /// The commanded joints' names.
    pub names: Vec<String>,
    /// Command times, nanoseconds (the states' epoch), non-decreasing.
    pub time_ns: Vec<i64>,
    /// `[command][joint]`, in the unit of `kind`.
    pub values: Vec<Vec<f64>>,
}

/// One episode of a joint recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The file (or folder) it was read from.
    pub file: PathBuf,
    /// The run id it becomes (the file stem, with the episode number when a
    /// file holds several).
    pub id: String,
    /// What was measured.
    pub states: JointStates,
    /// What was commanded, when the recording holds commands.
    pub commands: Option<Commands>,
    /// How it was read (format, topics or columns, rates), for the manifest.
    pub info: serde_json::Map<String, serde_json::Value>,
    /// What the importer noticed without refusing the data.
    pub warnings: Vec<String>,
}

/// Checks a row of values read at `place` (`"/joint_states message 12"`,
/// `"line 40"`) of `file`: every value finite, and as many as `names`.
pub(crate) fn check_row(
    file: &Path,
    place: &str,
    what: &str,
    names: &[String],
    row: &[f64],
) -> Result<(), ImportError> {
    if row.len() != names.len() {
        return Err(ImportError::new(
            file,
            format!(
                "{} {what} values for {} joint names",
                row.len(),
                names.len()
            ),
        )
        .with_field(place));
    }
    if let Some(j) = row.iter().position(|x| !x.is_finite()) {
        return Err(ImportError::new(
            file,
            format!("{what} of joint '{}' is {}", names[j], row[j]),
        )
        .with_field(place));
    }
    Ok(())
}

/// Checks that time `t_ns` read at `place` does not go back from `previous`.
pub(crate) fn check_time(
    file: &Path,
    place: &str,
    previous: Option<i64>,
    t_ns: i64,
) -> Result<(), ImportError> {
    if let Some(p) = previous.filter(|&p| t_ns < p) {
        return Err(ImportError::new(
            file,
            format!(
                "the timestamp goes backwards by {} s (from {} to {} s)",
                (p - t_ns) as f64 / NS_PER_S,
                p as f64 / NS_PER_S,
                t_ns as f64 / NS_PER_S
            ),
        )
        .with_field(place));
    }
    Ok(())
}

/// Seconds (finite) to nanoseconds, rounded; `None` beyond ±292 years.
/// Checks that joint-state time `t_ns` read at `place` comes after
/// `previous`: going back is an error ([`check_time`]), and so is a
/// repeated time, since two samples 0 s apart are no motion a replay could
/// follow (commands may repeat a time: the later one holds).
pub(crate) fn check_state_time(
    file: &Path,
    place: &str,
    previous: Option<i64>,
    t_ns: i64,
) -> Result<(), ImportError> {
    check_time(file, place, previous, t_ns)?;
    if previous == Some(t_ns) {
        return Err(ImportError::new(
            file,
            format!(
                "the timestamp {} s repeats the previous sample's: two joint states at one time",
                ns_text(t_ns)
            ),
        )
        .with_field(place));
    }
    Ok(())
}

/// Nanoseconds as seconds in decimal, exactly (`1700000000.495`, `-0.5`,
/// `12`), for messages: a stamp since the epoch as f64 would print
/// `1700000000.4950001`.
pub(crate) fn ns_text(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let abs = ns.unsigned_abs();
    let (s, frac) = (abs / 1_000_000_000, abs % 1_000_000_000);
    if frac == 0 {
        return format!("{sign}{s}");
    }
    let digits = format!("{frac:09}");
    format!("{sign}{s}.{}", digits.trim_end_matches('0'))
}

pub(crate) fn seconds_to_ns(t_s: f64) -> Option<i64> {
    let ns = (t_s * NS_PER_S).round();
    (ns.is_finite() && ns.abs() < 9.2e18).then_some(ns as i64)
}

impl Recording {
    /// Splits the recording into episodes wherever the joint states stop
    /// for more than `gap_s` seconds. Commands go to the episode whose span
    /// (from its first state to the next episode's first state) holds them;
    /// commands before the first state go to the first episode. One episode
    /// keeps its id; several get `-ep000`, `-ep001`, ... appended.
    pub fn split_by_gap(self, gap_s: f64) -> Vec<Recording> {
        let gap_ns = seconds_to_ns(gap_s).unwrap_or(i64::MAX);
        let t = &self.states.time_ns;
        let mut starts = vec![0usize];
        starts.extend((1..t.len()).filter(|&i| t[i] - t[i - 1] > gap_ns));
        if starts.len() == 1 {
            return vec![self];
        }
        let bounds: Vec<(usize, usize)> = starts
            .iter()
            .enumerate()
            .map(|(k, &s)| (s, starts.get(k + 1).copied().unwrap_or(t.len())))
            .collect();
        bounds
            .iter()
            .enumerate()
            .map(|(k, &(from, to))| {
                let rows = |v: &Vec<Vec<f64>>| v[from..to].to_vec();
                let states = JointStates {
                    names: self.states.names.clone(),
                    time_ns: t[from..to].to_vec(),
                    position: rows(&self.states.position),
                    velocity: self.states.velocity.as_ref().map(rows),
                    effort: self.states.effort.as_ref().map(rows),
                };
                let commands = self.commands.as_ref().map(|c| {
                    let lo = if k == 0 { i64::MIN } else { t[from] };
                    let hi = bounds.get(k + 1).map_or(i64::MAX, |&(next, _)| t[next]);
                    let keep: Vec<usize> = (0..c.time_ns.len())
                        .filter(|&i| c.time_ns[i] >= lo && c.time_ns[i] < hi)
                        .collect();
                    Commands {
                        kind: c.kind,
                        names: c.names.clone(),
                        time_ns: keep.iter().map(|&i| c.time_ns[i]).collect(),
                        values: keep.iter().map(|&i| c.values[i].clone()).collect(),
                    }
                });
                let mut info = self.info.clone();
                info.insert("episode".into(), k.into());
                Recording {
                    file: self.file.clone(),
                    id: format!("{}-ep{k:03}", self.id),
                    states,
                    commands,
                    info,
                    warnings: self.warnings.clone(),
                }
            })
            .collect()
    }

    /// The run of `robot` this episode is: joint columns in the robot's
    /// actuated-joint order ([`RobotModel::actuated_joints`]), times in
    /// seconds from the first joint state, the commands on the same clock,
    /// and the pose of `link` (the end effector) by forward kinematics from
    /// a base at the origin, as the body [`WRIST`].
    ///
    /// Errors name both sides when the recording's joints and the URDF's do
    /// not match, and refuse an episode without samples.
    pub fn to_trajectory(
        &self,
        robot: &RobotModel,
        link: usize,
    ) -> Result<Trajectory, ImportError> {
        let file = &self.file;
        if self.states.time_ns.is_empty() {
            return Err(ImportError::new(
                file,
                format!("episode '{}' has no joint state sample", self.id),
            ));
        }
        let actuated = robot.actuated_joints();
        let urdf_names: Vec<&str> = actuated
            .iter()
            .map(|&j| robot.joints[j].name.as_str())
            .collect();
        let urdf_list = || urdf_names.join(", ");
        let source = robot.source.display();
        // For each URDF actuated joint, its column in the recording.
        let mut column = Vec::with_capacity(actuated.len());
        for name in &self.states.names {
            if !urdf_names.contains(&name.as_str()) {
                return Err(ImportError::new(
                    file,
                    format!(
                        "the recording names joint '{name}', which robot '{}' ({source}) does not have as a moving joint; its moving joints are {}; the recording's joints are {}",
                        robot.name,
                        urdf_list(),
                        self.states.names.join(", ")
                    ),
                ));
            }
        }
        for name in &urdf_names {
            match self.states.names.iter().position(|n| n == name) {
                Some(c) => column.push(c),
                None => {
                    return Err(ImportError::new(
                        file,
                        format!(
                            "robot '{}' ({source}) has the moving joint '{name}', which the recording does not name; the recording's joints are {}; the robot's are {}",
                            robot.name,
                            self.states.names.join(", "),
                            urdf_list()
                        ),
                    ))
                }
            }
        }
        let reorder = |rows: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
            rows.iter()
                .map(|r| column.iter().map(|&c| r[c]).collect())
                .collect()
        };
        let t0 = self.states.time_ns[0];
        let seconds = |t: i64| (t - t0) as f64 / NS_PER_S;
        let angles = reorder(&self.states.position);
        let poses = robot.link_poses_from_actuated(&Pose::IDENTITY, &angles, link);
        let commands = match &self.commands {
            None => None,
            Some(c) => {
                let mut joints = Vec::with_capacity(c.names.len());
                for name in &c.names {
                    let j = urdf_names.iter().position(|n| n == name).ok_or_else(|| {
                        ImportError::new(
                            file,
                            format!(
                                "the commands name joint '{name}', which robot '{}' ({source}) does not have as a moving joint; its moving joints are {}",
                                robot.name,
                                urdf_list()
                            ),
                        )
                    })?;
                    joints.push(j);
                }
                Some(JointCommands {
                    kind: c.kind,
                    joints,
                    time_s: c.time_ns.iter().map(|&t| seconds(t)).collect(),
                    values: c.values.clone(),
                })
            }
        };
        let trajectory = Trajectory {
            time_s: self.states.time_ns.iter().map(|&t| seconds(t)).collect(),
            bodies: vec![BodyTrack {
                role: WRIST.to_string(),
                poses,
            }],
            joint_angles_rad: Some(angles),
            joint_velocity_commands_rad_s: None,
            joint_velocities_rad_s: self.states.velocity.as_ref().map(reorder),
            joint_efforts_nm: self.states.effort.as_ref().map(reorder),
            commands,
        };
        trajectory
            .validate()
            .map_err(|e| ImportError::new(file, format!("episode '{}': {e}", self.id)))?;
        Ok(trajectory)
    }
}

/// The end-effector link of `robot` for `name` (a link name), or by
/// default the child link of its last actuated joint, followed down fixed
/// joints while there is exactly one child.
pub fn end_effector(robot: &RobotModel, name: Option<&str>) -> Result<usize, String> {
    if let Some(name) = name {
        return robot.link_by_name(name).ok_or_else(|| {
            let links: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
            format!(
                "robot '{}' has no link '{name}'; its links are {}",
                robot.name,
                links.join(", ")
            )
        });
    }
    let last = robot
        .actuated_joints()
        .last()
        .copied()
        .ok_or_else(|| format!("robot '{}' has no moving joint", robot.name))?;
    let mut link = robot.joints[last].child;
    while let [only] = robot.child_joints(link) {
        if robot.joints[*only].kind.is_movable() {
            break;
        }
        link = robot.joints[*only].child;
    }
    Ok(link)
}
