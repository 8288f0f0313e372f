//! `realitygap import`: bring real (Qualisys motion capture) and recorded
//! simulator trajectories into a results directory, one run per file; a
//! robot's own joint recordings (ROS 2 bags, CSV, LeRobot datasets), one run
//! per episode; and the ContactNets cube tosses, one run of a free object
//! per toss.

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use realitygap_core::{CommandKind, RobotModel};
use realitygap_data::qualisys::{self, QualisysOptions};
use realitygap_data::recorded::{self, QuatOrder, RecordedOptions};
use realitygap_data::{ImportError, SourceKind};
use realitygap_recordings::csvfile::{parse_column_patterns, ColumnPattern, CsvOptions};
use realitygap_recordings::rosbag::RosbagOptions;
use realitygap_recordings::Recording;
use realitygap_study::import::{import_files, ImportTarget};
use serde_json::{json, Map, Value};
use std::path::PathBuf;

/// The file formats `import` reads.
#[derive(Subcommand)]
pub enum ImportCommand {
    /// Qualisys Track Manager 6DOF TSV exports (the real arm's motion
    /// capture), with or without their header. Defaults fit the reference
    /// study's files: 100 Hz, bodies RB2(Black), RB1(Orange), PCube.
    Qualisys(QualisysArgs),
    /// Simulator output recorded elsewhere: one row of 14 numbers per
    /// control step (wrist xyz, wrist quaternion, cube xyz, cube quaternion).
    Recorded(RecordedArgs),
    /// A ROS 2 bag (rosbag2 folder, or one .mcap or .db3 file): the
    /// sensor_msgs/msg/JointState topic and the commands ros2_control was
    /// sent (std_msgs/msg/Float64MultiArray or
    /// trajectory_msgs/msg/JointTrajectory). One run per bag, or per episode
    /// with --split-gap.
    ///
    /// Timestamps: a joint state's time is its header.stamp (the bag's log
    /// time, when the recorder received it, only where the stamp is zero);
    /// two joint states at one time are an error naming the message. A
    /// JointTrajectory point's time is its header.stamp (or log time) plus
    /// time_from_start; a Float64MultiArray has no stamp, so its log time is
    /// used. Commands may share a time: the later one in the bag holds.
    Rosbag(RosbagArgs),
    /// CSV joint recordings, one file per episode: a time column (a header
    /// stamp; or time_s, t_s, time, t, timestamp, stamp, __time in seconds;
    /// %time or *_ns in nanoseconds) and columns named <joint>/position,
    /// <joint>/velocity, <joint>/effort and <joint>/<kind>_command (any
    /// prefix before the joint, as PlotJuggler exports a bag), or a
    /// JointState flattened as `rostopic echo -p` or `ros2 topic echo --csv`
    /// write it; other names with --columns patterns. Two rows at one time
    /// are an error naming the line.
    Csv(CsvArgs),
    /// A LeRobot dataset (v3, or v2 with the same columns): one run per
    /// episode_index, observation.state as the joint positions and action
    /// as the commands.
    Lerobot(LerobotArgs),
    /// The ContactNets cube tosses (Pfrommer, Halm, Posa, CoRL 2020; BSD
    /// 3-Clause): a folder of N.pt files, PyTorch's legacy format, each a
    /// 1 x T x 19 tensor. One real run of the cube per toss, its id the
    /// toss's number: the pose in metres at t = k dt, and the linear (world
    /// frame, m/s) and angular (body frame, rad/s) velocity in
    /// runs/<id>.velocities.csv. Nothing is written unless every toss reads.
    Contactnets(ContactnetsArgs),
}

/// Arguments of `import contactnets`.
#[derive(Args)]
pub struct ContactnetsArgs {
    /// The folder of tosses: N.pt files (N the toss's number), and an
    /// experiment.json if any; nothing else.
    dir: PathBuf,
    /// Results directory to create or add to.
    #[arg(long)]
    out: PathBuf,
    /// The experiment's constants: dt (s), g (half-widths/s²), mass, mu,
    /// restitution [default: DIR/experiment.json, else
    /// DIR/../experiment.json, else the published values].
    #[arg(long, value_name = "FILE")]
    experiment: Option<PathBuf>,
    /// Source name written into the manifest.
    #[arg(long, default_value = "real")]
    source: String,
}

/// The robot a joint recording is of, and where its runs go.
#[derive(Args)]
pub struct RobotTarget {
    /// The robot's URDF: recorded joint names are matched against its
    /// moving joints, and the end effector's pose comes from its forward
    /// kinematics.
    #[arg(long, value_name = "URDF")]
    robot: PathBuf,
    /// Where a ROS package is, for package:// URIs in the URDF: NAME=DIR
    /// (repeatable; ROS_PACKAGE_PATH is searched too).
    #[arg(long = "package", value_name = "NAME=DIR")]
    packages: Vec<String>,
    /// The link whose pose is stored as the end effector (`wrist` body)
    /// [default: the child link of the last moving joint].
    #[arg(long, value_name = "NAME")]
    link: Option<String>,
    /// Results directory to create or add to.
    #[arg(long)]
    out: PathBuf,
    /// Source name written into the manifest.
    #[arg(long, default_value = "real")]
    source: String,
    /// Where to hold a moving joint of the URDF that the recording does
    /// not name (a gripper's finger, say): JOINT=VALUE in rad (m for a
    /// prismatic joint); repeatable. Such joints are held at 0 otherwise,
    /// with one warning line naming them; mimic joints follow their leader.
    #[arg(long = "hold", value_name = "JOINT=VALUE", value_parser = parse_hold)]
    hold: Vec<(String, f64)>,
    /// A recorded joint name to replace by the URDF's: RECORDED=URDF
    /// (repeatable).
    #[arg(long = "rename", value_name = "RECORDED=URDF", value_parser = parse_column)]
    rename: Vec<(String, String)>,
}

impl RobotTarget {
    /// The renames and held positions, checked against each other.
    fn joint_match(&self) -> Result<realitygap_recordings::JointMatch> {
        let mut hold = std::collections::BTreeMap::new();
        for (j, v) in &self.hold {
            if hold.insert(j.clone(), *v).is_some() {
                bail!("--hold names joint '{j}' twice");
            }
        }
        Ok(realitygap_recordings::JointMatch {
            rename: self.rename.clone(),
            hold,
        })
    }

    /// The robot's moving joints under the names the recording uses
    /// (the renames undone), for the importers' early checks.
    fn recorded_names(&self, urdf_names: &[String]) -> Vec<String> {
        urdf_names
            .iter()
            .map(|n| {
                self.rename
                    .iter()
                    .find(|(_, to)| to == n)
                    .map_or_else(|| n.clone(), |(from, _)| from.clone())
            })
            .collect()
    }
}

/// Parses `JOINT=VALUE` (a finite number).
fn parse_hold(s: &str) -> Result<(String, f64), String> {
    let (joint, value) = s
        .rsplit_once('=')
        .filter(|(j, _)| !j.trim().is_empty())
        .ok_or_else(|| {
            format!("expected JOINT=VALUE (e.g. \"panda_finger_joint1=0.04\"), found {s:?}")
        })?;
    let v: f64 = value.trim().parse().map_err(|_| {
        format!("{s:?}: {value:?} is not a number (rad, or m for a prismatic joint)")
    })?;
    if !v.is_finite() {
        return Err(format!("{s:?}: the position must be finite"));
    }
    Ok((joint.trim().to_string(), v))
}

/// Kind of recorded commands.
#[derive(Clone, Copy, ValueEnum)]
enum CommandKindArg {
    /// Joint positions (rad, m).
    Position,
    /// Joint velocities (rad/s, m/s).
    Velocity,
    /// Joint efforts (N m, N).
    Effort,
}

impl From<CommandKindArg> for CommandKind {
    fn from(k: CommandKindArg) -> CommandKind {
        match k {
            CommandKindArg::Position => CommandKind::Position,
            CommandKindArg::Velocity => CommandKind::Velocity,
            CommandKindArg::Effort => CommandKind::Effort,
        }
    }
}

/// Arguments of `import rosbag`.
#[derive(Args)]
pub struct RosbagArgs {
    /// The bags: rosbag2 folders (metadata.yaml with .mcap or .db3 files)
    /// or single .mcap/.db3 files; each is one run, or several with
    /// --split-gap.
    #[arg(required = true)]
    bags: Vec<PathBuf>,
    #[command(flatten)]
    target: RobotTarget,
    /// The sensor_msgs/msg/JointState topic [default: the only one, else
    /// /joint_states]. Its times are the header stamps (log times where a
    /// stamp is zero).
    #[arg(long, value_name = "TOPIC")]
    joint_states: Option<String>,
    /// The command topic [default: the only Float64MultiArray or
    /// JointTrajectory topic].
    #[arg(long, value_name = "TOPIC")]
    commands: Option<String>,
    /// Import the joint states alone, without commands.
    #[arg(long, conflicts_with = "commands")]
    no_commands: bool,
    /// What the commands are [default: from the message (JointTrajectory)
    /// or the topic's name (forward_position_controller, ...)].
    #[arg(long, value_enum)]
    command_kind: Option<CommandKindArg>,
    /// The joints of a Float64MultiArray's values, in order, comma-separated
    /// [default: the URDF's moving joints, when the count matches].
    #[arg(long, value_delimiter = ',', value_name = "J1,J2,...")]
    command_joints: Option<Vec<String>>,
    /// Split a bag into episodes where the joint states stop for longer
    /// than this many seconds.
    #[arg(long, value_name = "SECONDS")]
    split_gap: Option<f64>,
}

/// Arguments of `import csv`.
#[derive(Args)]
pub struct CsvArgs {
    /// The CSV files, one episode each (run id = file stem).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    #[command(flatten)]
    target: RobotTarget,
    /// Columns named by a pattern, comma-separated PATTERN=FIELD entries
    /// where {joint} stands for each joint's name and FIELD is position,
    /// velocity, effort or <kind>_command; time=NAME names the time column.
    /// E.g. 'q_{joint}_rad=position,qd_{joint}_rad_s=velocity,effort_{joint}_n_m=effort,cmd_q_{joint}_rad=position_command';
    /// repeatable.
    #[arg(long = "columns", value_name = "PATTERN=FIELD,...", value_parser = parse_patterns)]
    patterns: Vec<Patterns>,
    /// A column that follows no naming convention: ROLE=NAME, ROLE being
    /// `time` or <joint>/<field> (field position, velocity, effort,
    /// position_command, velocity_command, effort_command); repeatable.
    #[arg(long = "column", value_name = "ROLE=NAME", value_parser = parse_column)]
    columns: Vec<(String, String)>,
}

/// The patterns of one `--columns` list.
#[derive(Clone)]
struct Patterns(Vec<ColumnPattern>);

/// Parses a `--columns` list.
fn parse_patterns(s: &str) -> Result<Patterns, String> {
    parse_column_patterns(s).map(Patterns)
}

/// Arguments of `import lerobot`.
#[derive(Args)]
pub struct LerobotArgs {
    /// The dataset folder (with meta/info.json and data/).
    dataset: PathBuf,
    #[command(flatten)]
    target: RobotTarget,
    /// What `action` holds [default: position, LeRobot's convention].
    #[arg(long, value_enum)]
    command_kind: Option<CommandKindArg>,
}

/// Arguments of `import qualisys`.
#[derive(Args)]
pub struct QualisysArgs {
    /// The .tsv files; each is one run, named after its file stem.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// The scene the recordings are of.
    #[arg(long)]
    scene: String,
    /// Results directory to create or add to.
    #[arg(long)]
    out: PathBuf,
    /// Capture frequency in Hz, for files without a FREQUENCY header
    /// [default: 100].
    #[arg(long, value_name = "HZ")]
    frequency: Option<f64>,
    /// Rigid-body names in file order, comma-separated, for files without a
    /// BODY_NAMES header [default: RB2(Black),RB1(Orange),PCube].
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    bodies: Option<Vec<String>>,
    /// Role of a body, NAME=ROLE (wrist, cube, base or any name); repeat
    /// for several. Defaults: RB1(Orange)=wrist, RB2(Black)=base,
    /// PCube=cube. Bodies without a role keep their name.
    #[arg(long = "role", value_name = "NAME=ROLE", value_parser = parse_role)]
    roles: Vec<(String, String)>,
    /// Source name written into the manifest.
    #[arg(long, default_value = "real")]
    source: String,
    /// Also solve every run in joint space: inverse kinematics of the
    /// wrist body's 6D pose, with a capture registration (yaw and
    /// translation) and the marker's offset on the tracked link fitted on
    /// the training runs (--ik-fit); the joint angles are stored with the
    /// poses and the residual is printed per run. `--scene` must then name
    /// a scene file (or a scene of assets/scenes).
    #[arg(long)]
    ik: bool,
    /// The robot for --ik: mico2, official or a URDF file [default: the
    /// scene's].
    #[arg(long, value_name = "ROBOT", requires = "ik")]
    robot: Option<String>,
    /// Where a ROS package is, for package:// URIs: NAME=DIR (repeatable).
    #[arg(long = "package", value_name = "NAME=DIR", requires = "ik")]
    packages: Vec<String>,
    /// The runs the --ik registration is fitted on, by position among the
    /// runs sorted by id: A-B (1-based), N (the first N) or all [default:
    /// the first three quarters, the study's runs 1-15 of 20].
    #[arg(long, value_name = "A-B|N|all", requires = "ik")]
    ik_fit: Option<String>,
}

/// Quaternion order of a recorded file.
#[derive(Clone, Copy, ValueEnum)]
enum QuatOrderArg {
    /// w x y z (MuJoCo).
    Wxyz,
    /// x y z w (PyBullet, V-Rep).
    Xyzw,
}

/// Arguments of `import recorded`.
#[derive(Args)]
pub struct RecordedArgs {
    /// The recorded files; each is one run, named after its file stem.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Name of the simulator that produced them (e.g. VRepODE).
    #[arg(long)]
    source: String,
    /// Order of the quaternion numbers in each row.
    #[arg(long, value_enum)]
    quat_order: QuatOrderArg,
    /// Results directory to create or add to.
    #[arg(long)]
    out: PathBuf,
    /// The scene the runs are of.
    #[arg(long)]
    scene: Option<String>,
    /// Time between rows in seconds.
    #[arg(long, default_value_t = 0.05, value_name = "SECONDS")]
    control_period: f64,
    /// Largest accepted deviation of a quaternion's norm from 1.
    #[arg(long, default_value_t = 1e-3)]
    norm_tolerance: f64,
}

/// Parses `ROLE=NAME` (split at the first `=`).
fn parse_column(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((role, name)) if !role.trim().is_empty() && !name.trim().is_empty() => {
            Ok((role.trim().to_string(), name.trim().to_string()))
        }
        _ => Err(format!(
            "expected ROLE=NAME (e.g. \"time=stamp\" or \"joint1/position=q0\"), found {s:?}"
        )),
    }
}

/// Parses `NAME=ROLE` (split at the last `=`).
fn parse_role(s: &str) -> Result<(String, String), String> {
    match s.rsplit_once('=') {
        Some((name, role)) if !name.trim().is_empty() && !role.trim().is_empty() => {
            Ok((name.trim().to_string(), role.trim().to_string()))
        }
        _ => Err(format!(
            "expected NAME=ROLE (e.g. \"RB1(Orange)=wrist\"), found {s:?}"
        )),
    }
}

/// Runs `realitygap import ...`.
pub fn run(cmd: ImportCommand) -> Result<()> {
    match cmd {
        ImportCommand::Qualisys(args) => import_qualisys(args),
        ImportCommand::Recorded(args) => import_recorded(args),
        ImportCommand::Rosbag(args) => import_rosbag(args),
        ImportCommand::Csv(args) => import_csv(args),
        ImportCommand::Lerobot(args) => import_lerobot(args),
        ImportCommand::Contactnets(args) => import_contactnets(args),
    }
}

fn import_contactnets(args: ContactnetsArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let imported = realitygap_contactnets::import(
        &args.dir,
        args.experiment.as_deref(),
        &args.out,
        &args.source,
    )?;
    let e = &imported.experiment;
    println!(
        "constants from {}: dt {:.6} s ({:.0} Hz), g {:.2} half-widths/s², so one half-width is {:.4} m and the cube's edge {:.4} m",
        e.file
            .as_ref()
            .map_or("the published values".to_string(), |f| f.display().to_string()),
        e.dt_s,
        e.frequency_hz(),
        e.g_half_widths_s2,
        e.half_width_m(),
        e.edge_m()
    );
    for w in &imported.warnings {
        println!("warning: {w}");
    }
    let samples = imported.runs.iter().map(|r| r.1);
    let (shortest, longest) = (
        samples.clone().min().unwrap_or(0),
        samples.max().unwrap_or(0),
    );
    println!(
        "imported {} tosses ({shortest}-{longest} samples, {:.2}-{:.2} s) as real runs of the cube into {} (source '{}'{}) in {:.2} s",
        imported.runs.len(),
        shortest.saturating_sub(1) as f64 * e.dt_s,
        longest.saturating_sub(1) as f64 * e.dt_s,
        args.out.display(),
        args.source,
        if imported.replaced > 0 {
            format!(", {} replaced", imported.replaced)
        } else {
            String::new()
        },
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The robot of a joint recording, and its moving joints' names.
fn load_robot(target: &RobotTarget) -> Result<(RobotModel, Vec<String>)> {
    let packages = realitygap_runner::prepare::resolver(&target.packages)?;
    let robot = RobotModel::from_urdf_file(&target.robot, &packages)?;
    for n in &robot.notes {
        println!("note: {n}");
    }
    let names = robot
        .actuated_joints()
        .iter()
        .map(|&j| robot.joints[j].name.clone())
        .collect();
    Ok((robot, names))
}

/// Stores the episodes read, or nothing when any fails; says a line per run.
fn store_episodes(
    read: impl FnOnce(&[String]) -> Result<Vec<Recording>, ImportError>,
    target: &RobotTarget,
) -> Result<()> {
    let (robot, joints) = load_robot(target)?;
    let joint_match = target.joint_match()?;
    let recordings = read(&target.recorded_names(&joints))?;
    let (_, plan) =
        realitygap_recordings::plan_joints(&recordings, &robot, &target.robot, &joint_match)?;
    let link = realitygap_recordings::end_effector_of(&robot, target.link.as_deref(), &plan.driven)
        .map_err(|e| anyhow::anyhow!("{}: {e}", target.robot.display()))?;
    let stored = realitygap_recordings::store(
        &recordings,
        &realitygap_recordings::StoreTarget {
            out: &target.out,
            source: &target.source,
            urdf: &target.robot,
            robot: &robot,
            link,
            joints: &joint_match,
        },
    )?;
    if let Some(w) = stored.plan.warning(&robot) {
        println!("warning: {w}");
    }
    let runs = stored.runs;
    for (run, rec) in runs.iter().zip(&recordings) {
        let t = &run.trajectory;
        let duration = t.time_s.last().copied().unwrap_or(0.0);
        let rate = if duration > 0.0 {
            (t.len() - 1) as f64 / duration
        } else {
            0.0
        };
        let commands = match &t.commands {
            Some(c) => format!("{} {} commands", c.len(), c.kind),
            None => "no commands".into(),
        };
        println!(
            "{}: {} samples, {duration:.2} s at {rate:.0} Hz, {} joints{}{}, {commands}{} <- {}",
            run.id,
            t.len(),
            t.joint_count(),
            if t.joint_velocities_rad_s.is_some() {
                ", velocities"
            } else {
                ""
            },
            if t.joint_efforts_nm.is_some() {
                ", efforts"
            } else {
                ""
            },
            if run.replaced { " (replaced)" } else { "" },
            rec.file.display()
        );
        for w in &run.warnings {
            println!("  warning: {w}");
        }
    }
    println!(
        "imported {} episodes of robot '{}' into {} (source '{}', end effector {})",
        runs.len(),
        robot.name,
        target.out.display(),
        target.source,
        robot.links[link].name
    );
    Ok(())
}

fn import_rosbag(args: RosbagArgs) -> Result<()> {
    if let Some(g) = args.split_gap {
        if !(g.is_finite() && g > 0.0) {
            bail!("--split-gap must be a positive number of seconds, not {g}");
        }
    }
    let bags = args.bags.clone();
    store_episodes(
        |joints| {
            let opts = RosbagOptions {
                joint_states: args.joint_states.clone(),
                commands: args.commands.clone(),
                no_commands: args.no_commands,
                command_kind: args.command_kind.map(CommandKind::from),
                command_joints: args.command_joints.clone(),
                robot_joints: joints.to_vec(),
                split_gap_s: args.split_gap,
            };
            let mut all = Vec::new();
            for bag in &bags {
                all.extend(realitygap_recordings::rosbag::import_rosbag(bag, &opts)?);
            }
            Ok(all)
        },
        &args.target,
    )
}

fn import_csv(args: CsvArgs) -> Result<()> {
    let opts = CsvOptions {
        columns: args.columns.clone(),
        patterns: args.patterns.iter().flat_map(|p| p.0.clone()).collect(),
    };
    store_episodes(
        |_| {
            args.files
                .iter()
                .map(|f| realitygap_recordings::csvfile::import_csv(f, &opts))
                .collect()
        },
        &args.target,
    )
}

#[cfg(feature = "lerobot")]
fn import_lerobot(args: LerobotArgs) -> Result<()> {
    let opts = realitygap_recordings::lerobot::LeRobotOptions {
        command_kind: args.command_kind.map(CommandKind::from),
    };
    store_episodes(
        |_| realitygap_recordings::lerobot::import_lerobot(&args.dataset, &opts),
        &args.target,
    )
}

#[cfg(not(feature = "lerobot"))]
fn import_lerobot(args: LerobotArgs) -> Result<()> {
    let _ = (&args.dataset, &args.target, args.command_kind);
    bail!("this realitygap was built without LeRobot support (cargo feature `lerobot`)")
}

fn import_qualisys(args: QualisysArgs) -> Result<()> {
    let mut opts = QualisysOptions::collins2019();
    if let Some(f) = args.frequency {
        if !(f.is_finite() && f > 0.0) {
            bail!("--frequency must be a positive number of Hz, not {f}");
        }
        opts.frequency_hz = Some(f);
    }
    if let Some(bodies) = args.bodies {
        let bodies: Vec<String> = bodies.into_iter().map(|b| b.trim().to_string()).collect();
        if bodies.iter().any(String::is_empty) {
            bail!("--bodies has an empty name");
        }
        opts.body_names = Some(bodies);
    }
    // Later mappings win, so the user's roles override the defaults.
    opts.roles.extend(args.roles);
    let settings = json!({
        "importer": "qualisys",
        "frequency_hz": opts.frequency_hz,
        "body_names": opts.body_names,
        "roles": opts.roles.iter().map(|(n, r)| (n.clone(), Value::from(r.clone()))).collect::<Map<_, _>>(),
    });
    let target = ImportTarget {
        out: &args.out,
        source: &args.source,
        kind: SourceKind::Real,
        scene: Some(&args.scene),
    };
    // Everything --ik needs is checked before anything is imported.
    let ik = if args.ik {
        let file = realitygap_study::ik::scene_file(&args.scene)?;
        let mut scene = realitygap_core::Scene::from_file(&file)?;
        let resolver = realitygap_runner::prepare::resolver(&args.packages)?;
        let robot =
            match realitygap_runner::prepare::robot_override(args.robot.as_deref(), &resolver)? {
                Some((robot, path, _)) => {
                    scene.set_robot_urdf(path);
                    robot
                }
                None => scene
                    .robot
                    .model(&resolver)
                    .with_context(|| format!("the robot of scene {}", file.display()))?,
            };
        scene.validate(&robot)?;
        Some((scene, robot))
    } else {
        None
    };
    import_files(
        &args.files,
        &target,
        settings,
        |f| qualisys::read(f, &opts),
        &|l| println!("{l}"),
        &|l| eprintln!("{l}"),
    )?;
    let Some((scene, robot)) = ik else {
        return Ok(());
    };
    let started = std::time::Instant::now();
    let solved =
        realitygap_study::ik::solve_import(&args.out, &scene, &robot, args.ik_fit.as_deref())?;
    let f = &solved.fit;
    println!(
        "inverse kinematics of {} runs with robot '{}' ({:.1} s): registration fitted on {} runs ({} frames: {:.2} mm, {:.2} deg RMS): yaw {:.2} deg, translation ({:.1}, {:.1}, {:.1}) mm; marker {:.1} mm from the link's origin",
        solved.runs.len(),
        robot.name,
        started.elapsed().as_secs_f64(),
        solved.training.len(),
        f.frames,
        f.fit_position_rms_mm,
        f.fit_angle_rms_deg,
        f.registration.yaw_rad.to_degrees(),
        f.registration.translation_m.x * 1e3,
        f.registration.translation_m.y * 1e3,
        f.registration.translation_m.z * 1e3,
        f.marker_in_link.position_m.norm() * 1e3
    );
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (id, p, a) in &solved.runs {
        println!("  {id}: residual {p:.2} mm, {a:.2} deg RMS");
        if solved.training.contains(id) {
            train.push((*p, *a));
        } else {
            test.push((*p, *a));
        }
    }
    let mean = |v: &[(f64, f64)]| {
        let n = v.len().max(1) as f64;
        (
            v.iter().map(|x| x.0).sum::<f64>() / n,
            v.iter().map(|x| x.1).sum::<f64>() / n,
        )
    };
    let (tp, ta) = mean(&train);
    println!("  training runs: {tp:.2} mm, {ta:.2} deg RMS on average");
    if !test.is_empty() {
        let (hp, ha) = mean(&test);
        println!("  other runs: {hp:.2} mm, {ha:.2} deg RMS on average");
    }
    Ok(())
}

fn import_recorded(args: RecordedArgs) -> Result<()> {
    let quat_order = match args.quat_order {
        QuatOrderArg::Wxyz => QuatOrder::Wxyz,
        QuatOrderArg::Xyzw => QuatOrder::Xyzw,
    };
    if !(args.control_period.is_finite() && args.control_period > 0.0) {
        bail!(
            "--control-period must be a positive number of seconds, not {}",
            args.control_period
        );
    }
    if !(args.norm_tolerance.is_finite() && args.norm_tolerance >= 0.0) {
        bail!(
            "--norm-tolerance must be a number >= 0, not {}",
            args.norm_tolerance
        );
    }
    let opts = RecordedOptions {
        quat_order,
        control_period_s: args.control_period,
        norm_tolerance: args.norm_tolerance,
    };
    let settings = json!({
        "importer": "recorded",
        "quat_order": quat_order.to_string(),
        "control_period_s": opts.control_period_s,
        "norm_tolerance": opts.norm_tolerance,
    });
    let target = ImportTarget {
        out: &args.out,
        source: &args.source,
        kind: SourceKind::Recorded,
        scene: args.scene.as_deref(),
    };
    import_files(
        &args.files,
        &target,
        settings,
        |f| recorded::read(f, &opts),
        &|l| println!("{l}"),
        &|l| eprintln!("{l}"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_parse() {
        assert_eq!(
            parse_role("RB1(Orange)=wrist"),
            Ok(("RB1(Orange)".into(), "wrist".into()))
        );
        assert_eq!(parse_role("a=b=c"), Ok(("a=b".into(), "c".into())));
        assert!(parse_role("wrist").is_err());
        assert!(parse_role("=wrist").is_err());
        assert!(parse_role("x= ").is_err());
    }
}
