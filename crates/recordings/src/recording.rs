//! [`Recording`]: one episode of a robot's joint recording as the importers
//! read it (joint names as recorded, absolute timestamps), and the step that
//! turns it into a run of the robot ([`Recording::to_trajectory`]): joints
//! matched against the URDF, times from the episode's start, end-effector
//! poses by forward kinematics.

use realitygap_core::robot::RobotModel;
use realitygap_core::trajectory::WRIST;
use realitygap_core::{BodyTrack, CommandKind, JointCommands, Pose, Trajectory};
use realitygap_data::ImportError;
use std::collections::BTreeMap;
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

/// Seconds (finite) to nanoseconds, rounded; `None` beyond ±292 years.
pub(crate) fn seconds_to_ns(t_s: f64) -> Option<i64> {
    let ns = (t_s * NS_PER_S).round();
    (ns.is_finite() && ns.abs() < 9.2e18).then_some(ns as i64)
}

/// How a recording's joints meet the robot's (`import --rename`,
/// `--hold`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointMatch {
    /// Recorded joint names replaced before matching: (as recorded, the
    /// URDF's name).
    pub rename: Vec<(String, String)>,
    /// Positions (rad, or m for prismatic joints) of the robot's moving
    /// joints that the recording does not name; any other such joint is
    /// held at 0.
    pub hold: BTreeMap<String, f64>,
}

/// The robot's joints a recording drives, and those it holds still.
#[derive(Debug, Clone, PartialEq)]
pub struct JointPlan {
    /// The recorded joints, as robot joint indices in the robot's
    /// actuated-joint order ([`RobotModel::actuated_joints`]).
    pub driven: Vec<usize>,
    /// The robot's moving joints the recording does not name, each held
    /// at its position (rad or m).
    pub held: BTreeMap<String, f64>,
    /// Mimic joints whose leader is held: they hold too, where the leader
    /// puts them.
    pub followers: Vec<String>,
}

impl JointPlan {
    /// Matches the recorded joint names (already renamed) against the
    /// robot's moving joints: every recorded name must be one, the others
    /// are held at `hold`'s position or 0. A `hold` entry must name a
    /// moving joint that the recording does not name.
    pub fn new(
        robot: &RobotModel,
        recorded: &[String],
        hold: &BTreeMap<String, f64>,
    ) -> Result<JointPlan, String> {
        let actuated = robot.actuated_joints();
        let names: Vec<&str> = actuated
            .iter()
            .map(|&j| robot.joints[j].name.as_str())
            .collect();
        let source = robot.source.display();
        for name in recorded {
            if !names.contains(&name.as_str()) {
                return Err(format!(
                    "the recording names joint '{name}', which robot '{}' ({source}) does not have as a moving joint; its moving joints are {}; the recording's joints are {} (--rename RECORDED=URDF maps a name)",
                    robot.name,
                    names.join(", "),
                    recorded.join(", ")
                ));
            }
        }
        for (name, value) in hold {
            if recorded.contains(name) {
                return Err(format!(
                    "--hold {name}={value}: the recording names joint '{name}', so it is not held"
                ));
            }
            if !names.contains(&name.as_str()) {
                return Err(format!(
                    "--hold {name}={value}: robot '{}' ({source}) has no moving joint '{name}'; its moving joints are {}",
                    robot.name,
                    names.join(", ")
                ));
            }
            if !value.is_finite() {
                return Err(format!("--hold {name}={value}: not a finite position"));
            }
        }
        let mut driven = Vec::new();
        let mut held = BTreeMap::new();
        for (&j, name) in actuated.iter().zip(&names) {
            if recorded.iter().any(|r| r == name) {
                driven.push(j);
            } else {
                held.insert(name.to_string(), hold.get(*name).copied().unwrap_or(0.0));
            }
        }
        let followers = robot
            .joints
            .iter()
            .filter(|j| {
                j.mimic
                    .as_ref()
                    .is_some_and(|m| held.contains_key(&robot.joints[m.joint].name))
            })
            .map(|j| j.name.clone())
            .collect();
        Ok(JointPlan {
            driven,
            held,
            followers,
        })
    }

    /// The one line that says which joints are held, when any is.
    pub fn warning(&self, robot: &RobotModel) -> Option<String> {
        if self.held.is_empty() {
            return None;
        }
        let held: Vec<String> = self
            .held
            .iter()
            .map(|(n, v)| format!("{n} at {v}"))
            .collect();
        Some(format!(
            "robot '{}' has moving joints the recording does not name: held still ({}){}; --hold JOINT=VALUE (rad or m) sets where",
            robot.name,
            held.join(", "),
            if self.followers.is_empty() {
                String::new()
            } else {
                format!(
                    ", with the mimic joints {} that follow them",
                    self.followers.join(", ")
                )
            }
        ))
    }

    /// Positions of every robot joint (indexed like `robot.joints`) with
    /// the held joints at theirs and the rest at 0.
    pub fn base_positions(&self, robot: &RobotModel) -> Vec<f64> {
        let mut full = vec![0.0; robot.joints.len()];
        for (name, &v) in &self.held {
            if let Some(j) = robot.joint_by_name(name) {
                full[j] = v;
            }
        }
        full
    }
}

impl Recording {
    /// Replaces recorded joint names (`--rename RECORDED=URDF`) in the
    /// states and the commands. A name the recording does not have is an
    /// error naming the file.
    pub fn rename_joints(&mut self, rename: &[(String, String)]) -> Result<(), ImportError> {
        for (from, to) in rename {
            let mut found = false;
            for n in self.states.names.iter_mut() {
                if n == from {
                    *n = to.clone();
                    found = true;
                }
            }
            if let Some(c) = &mut self.commands {
                for n in c.names.iter_mut() {
                    if n == from {
                        *n = to.clone();
                        found = true;
                    }
                }
            }
            if !found {
                return Err(ImportError::new(
                    &self.file,
                    format!(
                        "--rename {from}={to}: episode '{}' names no joint '{from}'; its joints are {}",
                        self.id,
                        self.states.names.join(", ")
                    ),
                ));
            }
        }
        for (i, n) in self.states.names.iter().enumerate() {
            if self.states.names[..i].contains(n) {
                return Err(ImportError::new(
                    &self.file,
                    format!(
                        "episode '{}' names joint '{n}' twice (after --rename)",
                        self.id
                    ),
                ));
            }
        }
        Ok(())
    }
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
    /// a base at the origin, as the body [`WRIST`]. The robot's moving
    /// joints that the recording does not name are held at 0 (see
    /// [`Recording::to_trajectory_planned`] to hold them elsewhere).
    ///
    /// Errors name both sides when the recording names a joint the URDF
    /// does not move, and refuse an episode without samples.
    pub fn to_trajectory(
        &self,
        robot: &RobotModel,
        link: usize,
    ) -> Result<Trajectory, ImportError> {
        let plan = JointPlan::new(robot, &self.states.names, &BTreeMap::new())
            .map_err(|e| ImportError::new(&self.file, e))?;
        self.to_trajectory_planned(robot, link, &plan)
    }

    /// [`Recording::to_trajectory`] with the joints driven and held as
    /// `plan` says: the episode must name exactly the plan's driven
    /// joints; the joint columns are theirs, and the held joints sit at
    /// their positions in the forward kinematics.
    pub fn to_trajectory_planned(
        &self,
        robot: &RobotModel,
        link: usize,
        plan: &JointPlan,
    ) -> Result<Trajectory, ImportError> {
        let file = &self.file;
        if self.states.time_ns.is_empty() {
            return Err(ImportError::new(
                file,
                format!("episode '{}' has no joint state sample", self.id),
            ));
        }
        let driven_names: Vec<&str> = plan
            .driven
            .iter()
            .map(|&j| robot.joints[j].name.as_str())
            .collect();
        let recorded = JointPlan::new(robot, &self.states.names, &BTreeMap::new())
            .map_err(|e| ImportError::new(file, e))?;
        if recorded.driven != plan.driven {
            return Err(ImportError::new(
                file,
                format!(
                    "episode '{}' records the joints {}, the other episodes {}: import them separately",
                    self.id,
                    self.states.names.join(", "),
                    driven_names.join(", ")
                ),
            ));
        }
        let urdf_names = driven_names.clone();
        let urdf_list = || urdf_names.join(", ");
        let source = robot.source.display();
        // For each driven joint, its column in the recording.
        let column: Vec<usize> = driven_names
            .iter()
            .map(|name| {
                self.states
                    .names
                    .iter()
                    .position(|n| n == name)
                    .unwrap_or_default()
            })
            .collect();
        let reorder = |rows: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
            rows.iter()
                .map(|r| column.iter().map(|&c| r[c]).collect())
                .collect()
        };
        let t0 = self.states.time_ns[0];
        let seconds = |t: i64| (t - t0) as f64 / NS_PER_S;
        let angles = reorder(&self.states.position);
        let mut full = plan.base_positions(robot);
        let poses = angles
            .iter()
            .map(|row| {
                for (&j, &q) in plan.driven.iter().zip(row) {
                    full[j] = q;
                }
                robot.link_pose(&Pose::IDENTITY, &full, link)
            })
            .collect();
        let commands = match &self.commands {
            None => None,
            Some(c) => {
                let mut joints = Vec::with_capacity(c.names.len());
                for name in &c.names {
                    let j = urdf_names.iter().position(|n| n == name).ok_or_else(|| {
                        ImportError::new(
                            file,
                            format!(
                                "the commands name joint '{name}', which robot '{}' ({source}) does not have as a recorded moving joint; the joints recorded are {}",
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
    end_effector_of(robot, name, &robot.actuated_joints())
}

/// [`end_effector`] of a recording that drives the joints `driven`
/// ([`JointPlan::driven`]): by default the child link of the last of them
/// (a held gripper's fingers are not the end effector), followed down
/// fixed joints while there is exactly one child.
pub fn end_effector_of(
    robot: &RobotModel,
    name: Option<&str>,
    driven: &[usize],
) -> Result<usize, String> {
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
    let last = driven
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
