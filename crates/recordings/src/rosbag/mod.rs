//! ROS 2 bags (rosbag2, MCAP or sqlite3 storage): `/joint_states` and the
//! commands ros2_control was sent, as [`Recording`]s.
//!
//! - **Joint states**: the `sensor_msgs/msg/JointState` topic (the only one,
//!   else `/joint_states`, else `--joint-states`). Times are the messages'
//!   header stamps (the bag's log time, when the recorder received the
//!   message, only where a stamp is zero). Positions are required;
//!   velocities and efforts are kept when every message has them. Two joint
//!   states at one time are an error naming the message.
//! - **Commands**: the one topic of type `std_msgs/msg/Float64MultiArray`
//!   (a forward command controller's `~/commands`) or
//!   `trajectory_msgs/msg/JointTrajectory`, else `--commands`. A
//!   Float64MultiArray carries no names and no stamp: its time is the log
//!   time; its kind comes from the topic name when it says exactly one of
//!   `position`, `velocity`, `effort` (ros2_control's
//!   `forward_position_controller` and the like), else `--command-kind`; its
//!   joints are `--command-joints`, else the URDF's moving joints in order
//!   when the count matches (a warning says so). A JointTrajectory names its
//!   joints; each point is a command at header stamp (or log time) plus
//!   `time_from_start`, of the kind of its first non-empty field (positions,
//!   velocities, efforts); a new message replaces the points of earlier ones
//!   from its first point on, as a trajectory controller does. Commands may
//!   share a time: the later one in the bag holds.
//! - **Episodes**: one per bag, or split where the joint states stop for
//!   more than `--split-gap` seconds.

pub mod msgs;
pub mod storage;

use crate::recording::{check_row, check_time, ns_text, Commands, JointStates, Recording};
use msgs::{decode, Float64MultiArray, JointState, JointTrajectory};
use realitygap_core::CommandKind;
use realitygap_data::ImportError;
use serde_json::{Map, Value};
use std::path::Path;
use storage::{read_bag, Bag, Topic};

/// How to read a bag; `None` means "find it by convention".
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosbagOptions {
    /// The JointState topic.
    pub joint_states: Option<String>,
    /// The command topic.
    pub commands: Option<String>,
    /// Read no commands even when there are some.
    pub no_commands: bool,
    /// The kind of the commands.
    pub command_kind: Option<CommandKind>,
    /// The joints of a Float64MultiArray's values, in order.
    pub command_joints: Option<Vec<String>>,
    /// The robot's moving joints in order: the default joints of a
    /// Float64MultiArray of the same length.
    pub robot_joints: Vec<String>,
    /// Split into episodes where the joint states stop for longer, seconds.
    pub split_gap_s: Option<f64>,
}

/// Command topic types that realitygap reads.
const COMMAND_TYPES: [&str; 2] = [msgs::FLOAT64_MULTI_ARRAY, msgs::JOINT_TRAJECTORY];

/// Reads a bag (folder or storage file) into its episodes.
pub fn import_rosbag(path: &Path, opts: &RosbagOptions) -> Result<Vec<Recording>, ImportError> {
    // First pass over the topics only (cheap for sqlite3; MCAP lists its
    // channels as it goes), then the messages of the chosen two.
    let listing = read_bag(path, &|_| false)?;
    let states_topic = choose_states_topic(path, &listing, opts)?;
    let command_topic = choose_command_topic(path, &listing, opts)?;
    let bag = read_bag(path, &|t: &Topic| {
        t.name == states_topic || command_topic.as_deref() == Some(t.name.as_str())
    })?;
    let states_index = bag.topic(&states_topic).unwrap_or(usize::MAX);
    let states = read_states(path, &bag, states_index)?;
    // Joints the robot lacks make every later question (command joints)
    // moot: say so first.
    if !opts.robot_joints.is_empty() {
        if let Some(n) = states.names.iter().find(|n| !opts.robot_joints.contains(n)) {
            return Err(ImportError::new(
                path,
                format!(
                    "the recording names joint '{n}', which the robot does not have as a moving joint; its moving joints are {}; the recording's joints are {}",
                    opts.robot_joints.join(", "),
                    states.names.join(", ")
                ),
            )
            .with_field(states_topic));
        }
    }
    let mut warnings = Vec::new();
    let commands = match &command_topic {
        None => {
            warnings.push(format!(
                "no command topic (types {}): the runs cannot be replayed",
                COMMAND_TYPES.join(", ")
            ));
            None
        }
        Some(name) => {
            let index = bag.topic(name).unwrap_or(usize::MAX);
            // Unnamed command values are the recorded joints', in URDF
            // order: a robot's joints the bag does not record (a
            // gripper's fingers) are held, not commanded.
            let recorded = RosbagOptions {
                robot_joints: opts
                    .robot_joints
                    .iter()
                    .filter(|j| states.names.contains(j))
                    .cloned()
                    .collect(),
                ..opts.clone()
            };
            Some(read_commands(path, &bag, index, &recorded, &mut warnings)?)
        }
    };
    let mut info = Map::new();
    info.insert("format".into(), Value::from("rosbag2"));
    info.insert("storage".into(), Value::from(bag.storage));
    info.insert(
        "joint_states_topic".into(),
        Value::from(states_topic.clone()),
    );
    if let Some(c) = &command_topic {
        info.insert("commands_topic".into(), Value::from(c.clone()));
        let type_name = &bag.topics[bag.topic(c).unwrap_or(0)].type_name;
        info.insert("commands_type".into(), Value::from(type_name.clone()));
    }
    let id = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "bag".into());
    let recording = Recording {
        file: path.to_path_buf(),
        id,
        states,
        commands,
        info,
        warnings,
    };
    Ok(match opts.split_gap_s {
        Some(gap) => recording.split_by_gap(gap),
        None => vec![recording],
    })
}

/// Lists topics for a message: `name (type)`, comma-separated.
fn list_topics(bag: &Bag, filter: &dyn Fn(&Topic) -> bool) -> String {
    let list: Vec<String> = bag
        .topics
        .iter()
        .filter(|t| filter(t))
        .map(|t| format!("{} ({})", t.name, t.type_name))
        .collect();
    if list.is_empty() {
        "none".into()
    } else {
        list.join(", ")
    }
}

/// The topic called `name`, or an error listing the bag's topics.
fn named_topic<'a>(path: &Path, bag: &'a Bag, name: &str) -> Result<&'a Topic, ImportError> {
    bag.topic(name).map(|i| &bag.topics[i]).ok_or_else(|| {
        ImportError::new(
            path,
            format!(
                "the bag has no topic {name}; its topics are {}",
                list_topics(bag, &|_| true)
            ),
        )
    })
}

/// The JointState topic.
fn choose_states_topic(
    path: &Path,
    bag: &Bag,
    opts: &RosbagOptions,
) -> Result<String, ImportError> {
    if let Some(name) = &opts.joint_states {
        let t = named_topic(path, bag, name)?;
        if t.type_name != msgs::JOINT_STATE {
            return Err(ImportError::new(
                path,
                format!(
                    "topic {name} has type {}; joint states must be {}",
                    t.type_name,
                    msgs::JOINT_STATE
                ),
            ));
        }
        return Ok(name.clone());
    }
    let candidates: Vec<&Topic> = bag
        .topics
        .iter()
        .filter(|t| t.type_name == msgs::JOINT_STATE)
        .collect();
    match candidates.as_slice() {
        [only] => Ok(only.name.clone()),
        [] => Err(ImportError::new(
            path,
            format!(
                "the bag has no topic of type {}; its topics are {}",
                msgs::JOINT_STATE,
                list_topics(bag, &|_| true)
            ),
        )),
        several => several
            .iter()
            .find(|t| t.name == "/joint_states")
            .map(|t| t.name.clone())
            .ok_or_else(|| {
                ImportError::new(
                    path,
                    format!(
                        "the bag has several {} topics ({}): choose one with --joint-states",
                        msgs::JOINT_STATE,
                        list_topics(bag, &|t| t.type_name == msgs::JOINT_STATE)
                    ),
                )
            }),
    }
}

/// The command topic, if any.
fn choose_command_topic(
    path: &Path,
    bag: &Bag,
    opts: &RosbagOptions,
) -> Result<Option<String>, ImportError> {
    if opts.no_commands {
        return Ok(None);
    }
    let is_command = |t: &Topic| COMMAND_TYPES.contains(&t.type_name.as_str());
    if let Some(name) = &opts.commands {
        let t = named_topic(path, bag, name)?;
        if !is_command(t) {
            return Err(ImportError::new(
                path,
                format!(
                    "topic {name} has type {}, an unknown command message: realitygap reads commands of type {}",
                    t.type_name,
                    COMMAND_TYPES.join(" or ")
                ),
            ));
        }
        return Ok(Some(name.clone()));
    }
    let candidates: Vec<&Topic> = bag.topics.iter().filter(|t| is_command(t)).collect();
    match candidates.as_slice() {
        [] => {
            // A topic named like commands, of a type realitygap cannot read,
            // is more likely a mistake than a bag without commands.
            let looks_like = |t: &Topic| {
                let n = t.name.to_ascii_lowercase();
                n.ends_with("/commands") || n.ends_with("/joint_trajectory")
            };
            match bag.topics.iter().find(|t| looks_like(t)) {
                Some(t) => Err(ImportError::new(
                    path,
                    format!(
                        "topic {} has type {}, an unknown command message: realitygap reads commands of type {}; give --commands TOPIC, or --no-commands to import the joint states alone",
                        t.name,
                        t.type_name,
                        COMMAND_TYPES.join(" or ")
                    ),
                )),
                None => Ok(None),
            }
        }
        [only] => Ok(Some(only.name.clone())),
        _ => Err(ImportError::new(
            path,
            format!(
                "the bag has several command topics ({}): choose one with --commands",
                list_topics(bag, &is_command)
            ),
        )),
    }
}

/// Where a message is, for errors: `"/joint_states message 12"`.
fn place(bag: &Bag, topic: usize, index: usize) -> String {
    format!("{} message {index}", bag.topics[topic].name)
}

/// The path of the storage file a message is in.
fn file_of<'a>(bag: &'a Bag, m: &storage::Stored) -> &'a Path {
    &bag.files[m.file]
}

/// Decodes the joint states.
fn read_states(path: &Path, bag: &Bag, topic: usize) -> Result<JointStates, ImportError> {
    let mut states = JointStates::default();
    let mut velocity = Vec::new();
    let mut effort = Vec::new();
    let (mut has_velocity, mut has_effort) = (true, true);
    for (index, m) in bag.messages.iter().filter(|m| m.topic == topic).enumerate() {
        let file = file_of(bag, m);
        let at = place(bag, topic, index);
        let msg: JointState = decode(&m.data).map_err(|e| {
            ImportError::new(file, format!("{}: {e}", msgs::JOINT_STATE)).with_field(at.clone())
        })?;
        if index == 0 {
            states.names = msg.name.clone();
            if states.names.is_empty() {
                return Err(ImportError::new(file, "the joint state names no joint").with_field(at));
            }
            has_velocity = !msg.velocity.is_empty();
            has_effort = !msg.effort.is_empty();
        }
        // Values in the first message's joint order.
        let order: Vec<usize> = if msg.name == states.names {
            (0..msg.name.len()).collect()
        } else {
            let mut order = Vec::with_capacity(states.names.len());
            for n in &states.names {
                let k = msg.name.iter().position(|m| m == n).ok_or_else(|| {
                    ImportError::new(
                        file,
                        format!(
                            "joint '{n}' of the first message is missing here (names: {})",
                            msg.name.join(", ")
                        ),
                    )
                    .with_field(at.clone())
                })?;
                order.push(k);
            }
            order
        };
        let pick = |v: &[f64], what: &str| -> Result<Vec<f64>, ImportError> {
            if v.len() != msg.name.len() {
                return Err(ImportError::new(
                    file,
                    format!("{} {what} values for {} names", v.len(), msg.name.len()),
                )
                .with_field(at.clone()));
            }
            Ok(order.iter().map(|&k| v[k]).collect())
        };
        let (t, clock) = if msg.header.stamp.ns() != 0 {
            (msg.header.stamp.ns(), "header stamp")
        } else {
            (m.log_time_ns, "log time")
        };
        let previous = states.time_ns.last().copied();
        check_time(file, &at, previous, t)?;
        if previous == Some(t) {
            return Err(ImportError::new(
                file,
                format!(
                    "its {clock} {} s repeats message {}'s: two joint states at one time",
                    ns_text(t),
                    index - 1
                ),
            )
            .with_field(at));
        }
        let position = pick(&msg.position, "position")?;
        check_row(file, &at, "position", &states.names, &position)?;
        if has_velocity {
            let v = pick(&msg.velocity, "velocity")?;
            check_row(file, &at, "velocity", &states.names, &v)?;
            velocity.push(v);
        }
        if has_effort {
            let e = pick(&msg.effort, "effort")?;
            check_row(file, &at, "effort", &states.names, &e)?;
            effort.push(e);
        }
        states.time_ns.push(t);
        states.position.push(position);
    }
    if states.time_ns.is_empty() {
        return Err(ImportError::new(
            path,
            format!(
                "topic {} has no message: the episode is empty",
                bag.topics[topic].name
            ),
        ));
    }
    states.velocity = has_velocity.then_some(velocity);
    states.effort = has_effort.then_some(effort);
    Ok(states)
}

/// The kind of a Float64MultiArray topic from its name, when unambiguous.
fn kind_from_topic_name(name: &str) -> Option<CommandKind> {
    let lower = name.to_ascii_lowercase();
    let found: Vec<CommandKind> = CommandKind::ALL
        .into_iter()
        .filter(|k| lower.contains(k.name()))
        .collect();
    match found.as_slice() {
        [only] => Some(*only),
        _ => None,
    }
}

/// Decodes the commands.
fn read_commands(
    path: &Path,
    bag: &Bag,
    topic: usize,
    opts: &RosbagOptions,
    warnings: &mut Vec<String>,
) -> Result<Commands, ImportError> {
    let name = &bag.topics[topic].name;
    if bag.topics[topic].type_name == msgs::FLOAT64_MULTI_ARRAY {
        read_array_commands(path, bag, topic, opts, warnings)
    } else {
        read_trajectory_commands(path, bag, topic, opts).map_err(|e| {
            if e.field.is_none() {
                e.with_field(name.clone())
            } else {
                e
            }
        })
    }
}

/// Commands from a forward command controller's Float64MultiArray.
fn read_array_commands(
    path: &Path,
    bag: &Bag,
    topic: usize,
    opts: &RosbagOptions,
    warnings: &mut Vec<String>,
) -> Result<Commands, ImportError> {
    let name = &bag.topics[topic].name;
    let kind = opts.command_kind.or_else(|| kind_from_topic_name(name)).ok_or_else(|| {
        ImportError::new(
            path,
            format!(
                "the kind of the commands on {name} is not in its name (position, velocity or effort): give --command-kind"
            ),
        )
    })?;
    let mut commands = Commands {
        kind,
        names: opts.command_joints.clone().unwrap_or_default(),
        time_ns: Vec::new(),
        values: Vec::new(),
    };
    for (index, m) in bag.messages.iter().filter(|m| m.topic == topic).enumerate() {
        let file = file_of(bag, m);
        let at = place(bag, topic, index);
        let msg: Float64MultiArray = decode(&m.data).map_err(|e| {
            ImportError::new(file, format!("{}: {e}", msgs::FLOAT64_MULTI_ARRAY))
                .with_field(at.clone())
        })?;
        let offset = msg.layout.data_offset as usize;
        let data = msg.data.get(offset..).unwrap_or_default();
        if commands.names.is_empty() {
            if data.len() != opts.robot_joints.len() {
                return Err(ImportError::new(
                    file,
                    format!(
                        "{} values and no joint names: give --command-joints (the robot has {} moving joints: {})",
                        data.len(),
                        opts.robot_joints.len(),
                        opts.robot_joints.join(", ")
                    ),
                )
                .with_field(at));
            }
            commands.names = opts.robot_joints.clone();
            warnings.push(format!(
                "{name} carries no joint names: its {} values taken as the robot's moving joints in URDF order ({}); give --command-joints otherwise",
                data.len(),
                commands.names.join(", ")
            ));
        }
        check_row(file, &at, &format!("{kind} command"), &commands.names, data)?;
        check_time(file, &at, commands.time_ns.last().copied(), m.log_time_ns)?;
        commands.time_ns.push(m.log_time_ns);
        commands.values.push(data.to_vec());
    }
    Ok(commands)
}

/// Commands from a joint trajectory controller's JointTrajectory.
fn read_trajectory_commands(
    path: &Path,
    bag: &Bag,
    topic: usize,
    opts: &RosbagOptions,
) -> Result<Commands, ImportError> {
    let mut commands: Option<Commands> = None;
    for (index, m) in bag.messages.iter().filter(|m| m.topic == topic).enumerate() {
        let file = file_of(bag, m);
        let at = place(bag, topic, index);
        let msg: JointTrajectory = decode(&m.data).map_err(|e| {
            ImportError::new(file, format!("{}: {e}", msgs::JOINT_TRAJECTORY))
                .with_field(at.clone())
        })?;
        let Some(first) = msg.points.first() else {
            continue; // An empty trajectory stops nothing we can replay.
        };
        let c = commands.get_or_insert_with(|| {
            let kind = opts.command_kind.unwrap_or(if !first.positions.is_empty() {
                CommandKind::Position
            } else if !first.velocities.is_empty() {
                CommandKind::Velocity
            } else {
                CommandKind::Effort
            });
            Commands {
                kind,
                names: msg.joint_names.clone(),
                time_ns: Vec::new(),
                values: Vec::new(),
            }
        });
        let order: Vec<usize> = c
            .names
            .iter()
            .map(|n| {
                msg.joint_names.iter().position(|m| m == n).ok_or_else(|| {
                    ImportError::new(
                        file,
                        format!(
                            "joint '{n}' of the first trajectory is missing here (joint_names: {})",
                            msg.joint_names.join(", ")
                        ),
                    )
                    .with_field(at.clone())
                })
            })
            .collect::<Result<_, _>>()?;
        let start = if msg.header.stamp.ns() != 0 {
            msg.header.stamp.ns()
        } else {
            m.log_time_ns
        };
        let mut previous = None;
        for (k, point) in msg.points.iter().enumerate() {
            let values = match c.kind {
                CommandKind::Position => &point.positions,
                CommandKind::Velocity => &point.velocities,
                CommandKind::Effort => &point.effort,
            };
            let point_at = format!("{at} point {k}");
            if values.len() != msg.joint_names.len() {
                return Err(ImportError::new(
                    file,
                    format!(
                        "{} {} values for {} joint names",
                        values.len(),
                        c.kind,
                        msg.joint_names.len()
                    ),
                )
                .with_field(point_at));
            }
            let row: Vec<f64> = order.iter().map(|&i| values[i]).collect();
            check_row(
                file,
                &point_at,
                &format!("{} command", c.kind),
                &c.names,
                &row,
            )?;
            let t = start.saturating_add(point.time_from_start.ns());
            check_time(file, &point_at, previous, t)?;
            if k == 0 {
                // A new trajectory replaces what was left of the last one.
                let keep = c.time_ns.partition_point(|&old| old < t);
                c.time_ns.truncate(keep);
                c.values.truncate(keep);
            }
            previous = Some(t);
            c.time_ns.push(t);
            c.values.push(row);
        }
    }
    commands.ok_or_else(|| ImportError::new(path, "the command topic holds no trajectory point"))
}
