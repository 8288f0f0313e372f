//! `realitygap replay`: a robot's recorded episodes replayed in every
//! engine, with the physics-free model beside them, and the joint-space
//! table.

use anyhow::Result;
use clap::Args as ClapArgs;
use realitygap::replay::{replay, ReplayOptions};
use realitygap_runner::Launcher;
use std::path::PathBuf;

/// Arguments of `realitygap replay`.
#[derive(ClapArgs)]
pub struct Args {
    /// The recorded episodes: a results directory written by `realitygap
    /// import rosbag|csv|lerobot`.
    real: PathBuf,
    /// The robot's URDF [default: the one the import recorded].
    #[arg(long, value_name = "URDF")]
    robot: Option<PathBuf>,
    /// Where a ROS package is, for package:// URIs: NAME=DIR (repeatable).
    #[arg(long = "package", value_name = "NAME=DIR")]
    packages: Vec<String>,
    /// Engines to replay in (repeatable) [default: every compiled engine];
    /// `all-except:A,B` or `-A` leaves engines out. The physics-free model
    /// (`ideal`) is a row of every replay. An engine that cannot honour a
    /// key of --params is not replayed: its row says why.
    #[arg(long = "engine", value_name = "NAME", allow_hyphen_values = true)]
    engines: Vec<String>,
    /// Typed physical parameters: the servo gains (joints.<joint>.kp, kv),
    /// damping, armature, frictionloss, force limits, controller.delay_s.
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// A scene to use instead of the generated OUT/replay.toml (ground,
    /// engine settings, actuators).
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// Output folder: OUT/<engine>/ and OUT/ideal/ (the physics-free model) results directories,
    /// OUT/replay.toml, OUT/replay.json (what was replayed: `compare OUT`
    /// measures it again), OUT/joint_space.md, .json, OUT/report/.
    #[arg(long)]
    out: PathBuf,
    /// Replays at a time, each in a child process (default: the number of
    /// cores).
    #[arg(long, short = 'j', value_name = "N")]
    jobs: Option<usize>,
    /// Tossed objects (from `import contactnets`): the initial velocity is
    /// the first sample's recorded one (`first`), or a fit of free flight
    /// over the first 5 samples (`fit`: better over the first 0.1 s, worse
    /// over the whole toss).
    #[arg(long, value_name = "HOW", default_value = "first", value_parser = ["first", "fit"])]
    toss_start: String,
    /// Where the replays run.
    #[command(flatten)]
    executor: crate::cmd_run::ExecutorArgs,
}

/// `realitygap replay`.
pub fn run(args: Args) -> Result<()> {
    let options = ReplayOptions {
        real: args.real,
        robot: args.robot,
        packages: args.packages,
        engines: args.engines,
        params: args.params,
        scene: args.scene,
        out: args.out,
        jobs: args.jobs,
        executor: args.executor.executor()?,
        toss_start: if args.toss_start == "fit" {
            realitygap_study::tosses::TossStart::Fit
        } else {
            realitygap_study::tosses::TossStart::First
        },
    };
    replay(
        &options,
        &Launcher::this_executable(),
        &realitygap::ui::Terminal,
    )?;
    Ok(())
}
