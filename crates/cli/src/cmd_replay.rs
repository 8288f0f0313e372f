//! `realitygap replay`: a robot's recorded episodes replayed in every
//! engine, with the physics-free model beside them, and the joint-space
//! table.

use anyhow::{bail, Result};
use clap::Args as ClapArgs;
use indicatif::{ProgressBar, ProgressStyle};
use realitygap_runner::slurm::Executor;
use realitygap_runner::Launcher;
use realitygap_study::replay::{
    joint_space_markdown, joint_space_row, prepare_replay, replay_all, store_kinematic,
    ReplayExecutor, ReplayRequest, KINEMATIC,
};
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
    /// Engines to replay in (repeatable) [default: every compiled engine].
    #[arg(long = "engine", value_name = "NAME")]
    engines: Vec<String>,
    /// Typed physical parameters: the servo gains (joints.<joint>.kp, kv),
    /// damping, armature, frictionloss, force limits, controller.delay_s.
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// A scene to use instead of the generated OUT/replay.toml (ground,
    /// engine settings, actuators).
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// Output folder: OUT/<engine>/ and OUT/kinematic/ results directories,
    /// OUT/replay.toml, OUT/replay.json (what was replayed: `compare OUT`
    /// measures it again), OUT/joint_space.md, .json, OUT/report/.
    #[arg(long)]
    out: PathBuf,
    /// Replays at a time, each in a child process (default: the number of
    /// cores).
    #[arg(long, short = 'j', value_name = "N")]
    jobs: Option<usize>,
    /// Where the replays run.
    #[command(flatten)]
    executor: crate::cmd_run::ExecutorArgs,
}

/// `realitygap replay`.
pub fn run(args: Args) -> Result<()> {
    let params = realitygap_runner::prepare::read_params(args.params.as_deref())?;
    let all = crate::cmd_engines::compiled();
    let engines: Vec<_> = if args.engines.is_empty() {
        all
    } else {
        let mut chosen = Vec::new();
        for name in &args.engines {
            chosen.push(realitygap_runner::prepare::find_engine(
                crate::cmd_engines::compiled,
                name,
            )?);
        }
        chosen
    };
    if engines.is_empty() {
        bail!("no physics engine is compiled into this binary");
    }
    let request = ReplayRequest {
        real_dir: &args.real,
        urdf: args.robot.as_deref(),
        packages: &args.packages,
        params: &params,
        scene: args.scene.as_deref(),
        out: &args.out,
    };
    let prepared = prepare_replay(&request)?;
    realitygap_study::replay::write_record(&request, &prepared)?;
    let kinematic = store_kinematic(&args.out, &prepared, params.delay_s())?;
    let total = engines.len() * prepared.episodes.len();
    let bar = ProgressBar::new(total as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} replays ({eta} left) {msg}",
        )
        .expect("a valid template"),
    );
    let launcher = Launcher::this_executable();
    let slurm;
    let executor = match args.executor.executor()? {
        Executor::Local => ReplayExecutor::Local {
            launcher: &launcher,
            jobs: args
                .jobs
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        },
        Executor::Slurm(options) => {
            slurm = options;
            ReplayExecutor::Slurm {
                launcher: &launcher,
                options: &slurm,
            }
        }
    };
    let runs = replay_all(&engines, &prepared, &params, &args.out, &executor, &|r| {
        bar.inc(1);
        if let Err(e) = &r.result {
            bar.suspend(|| eprintln!("{} in {}: failed: {e}", r.id, r.engine));
        }
    })?;
    bar.finish_and_clear();
    let mut rows = Vec::new();
    let kin: Vec<_> = prepared
        .episodes
        .iter()
        .filter_map(|e| {
            let link = prepared.robot.link_by_name(&prepared.link)?;
            realitygap_study::replay::kinematic_run(e, &prepared, link, params.delay_s())
                .map(|t| (e.id.clone(), t))
        })
        .collect();
    rows.extend(joint_space_row(KINEMATIC, &prepared, &kin));
    let mut sources = vec![(KINEMATIC.to_string(), kin.clone())];
    let mut failed = 0;
    for engine in &engines {
        let mine: Vec<_> = runs
            .iter()
            .filter(|r| r.engine == engine.name())
            .filter_map(|r| match &r.result {
                Ok((t, _, _)) => Some((r.id.clone(), t.clone())),
                Err(_) => {
                    failed += 1;
                    None
                }
            })
            .collect();
        rows.extend(joint_space_row(engine.name(), &prepared, &mine));
        sources.push((engine.name().to_string(), mine));
    }
    let names: Vec<String> = prepared
        .replayed_joints()
        .iter()
        .map(|&j| prepared.robot.joints[j].name.clone())
        .collect();
    let table = joint_space_markdown(&rows, &names);
    std::fs::write(args.out.join("joint_space.md"), &table)?;
    std::fs::write(
        args.out.join("joint_space.json"),
        serde_json::to_string_pretty(&rows)? + "\n",
    )?;
    let report = args.out.join("report");
    realitygap_report::joint_space::write_joint_space_report(
        &report,
        &format!("Replay of the recordings of robot '{}'", prepared.robot.name),
        &[format!(
            "{} episodes from {} replayed in {}, beside the physics-free model (the commands with perfect tracking). The table compares every episode; the figures show the first, {}.",
            prepared.episodes.len(),
            args.real.display(),
            engines.iter().map(|e| e.name()).collect::<Vec<_>>().join(", "),
            prepared.episodes.first().map_or("", |e| e.id.as_str())
        )],
        &table,
        &realitygap_study::replay::joint_figures(&prepared, &sources),
    )
    .map_err(|m| anyhow::anyhow!("the report in {}: {m}", report.display()))?;
    let reused = runs.iter().filter(|r| r.reused).count();
    println!("{table}");
    println!(
        "replayed {} episodes of robot '{}' in {} engines ({} runs, {reused} kept from an earlier batch, {failed} failed); the physics-free model on {kinematic} episodes; {}; the report {}",
        prepared.episodes.len(),
        prepared.robot.name,
        engines.len(),
        runs.len(),
        args.out.join("joint_space.md").display(),
        report.join("index.html").display()
    );
    if failed > 0 {
        bail!(
            "{failed} of {} replays failed (see the messages above and the manifests)",
            runs.len()
        );
    }
    Ok(())
}
