//! `realitygap replay`: a robot's recorded episodes replayed in every
//! engine, with the physics-free model beside them, and the joint-space
//! table. Shared by the command and the Python package.

use crate::ui::Ui;
use anyhow::{bail, Result};
use realitygap_runner::slurm::Executor;
use realitygap_runner::Launcher;
use realitygap_study::replay::{
    joint_space_markdown, joint_space_row, prepare_replay, replay_all, store_kinematic,
    JointSpaceRow, ReplayExecutor, ReplayRequest, KINEMATIC,
};
use std::path::PathBuf;

/// What `replay` does (its options).
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// The recorded episodes: a results directory of `realitygap import`.
    pub real: PathBuf,
    /// The robot's URDF (default: the one the import recorded).
    pub robot: Option<PathBuf>,
    /// Where ROS packages are: NAME=DIR.
    pub packages: Vec<String>,
    /// Engines to replay in; empty: every engine compiled in.
    pub engines: Vec<String>,
    /// Typed physical parameters (servo gains, damping, ...).
    pub params: Option<PathBuf>,
    /// A scene instead of the generated OUT/replay.toml.
    pub scene: Option<PathBuf>,
    /// Output folder.
    pub out: PathBuf,
    /// Replays at a time (default: the number of cores).
    pub jobs: Option<usize>,
    /// Where the replays run.
    pub executor: Executor,
}

/// What a replay made.
pub struct Replayed {
    /// Per source (the physics-free model first), the joint-space row.
    pub rows: Vec<JointSpaceRow>,
    /// The replayed joints' names.
    pub joints: Vec<String>,
    /// The joint-space table in Markdown (OUT/joint_space.md).
    pub table: String,
    /// `OUT/report/index.html`.
    pub index_html: PathBuf,
}

/// Replays the episodes in every engine; says the table and a summary on
/// `ui`. An error when a replay failed (after everything is written).
pub fn replay(args: &ReplayOptions, launcher: &Launcher, ui: &dyn Ui) -> Result<Replayed> {
    let params = realitygap_runner::prepare::read_params(args.params.as_deref())?;
    let engines: Vec<_> = if args.engines.is_empty() {
        crate::compiled_engines()
    } else {
        let mut chosen = Vec::new();
        for name in &args.engines {
            chosen.push(realitygap_runner::prepare::find_engine(
                crate::compiled_engines,
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
    let bar = ui.bar(total as u64, "replays");
    let executor = match &args.executor {
        Executor::Local => ReplayExecutor::Local {
            launcher,
            jobs: args
                .jobs
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        },
        Executor::Slurm(options) => ReplayExecutor::Slurm { launcher, options },
    };
    let runs = replay_all(&engines, &prepared, &params, &args.out, &executor, &|r| {
        bar.inc(1);
        if let Err(e) = &r.result {
            bar.println(format!("{} in {}: failed: {e}", r.id, r.engine));
        }
    });
    bar.finish();
    let runs = runs?;
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
    ui.say(table.clone());
    ui.say(format!(
        "replayed {} episodes of robot '{}' in {} engines ({} runs, {reused} kept from an earlier batch, {failed} failed); the physics-free model on {kinematic} episodes; {}; the report {}",
        prepared.episodes.len(),
        prepared.robot.name,
        engines.len(),
        runs.len(),
        args.out.join("joint_space.md").display(),
        report.join("index.html").display()
    ));
    if failed > 0 {
        bail!(
            "{failed} of {} replays failed (see the messages above and the manifests)",
            runs.len()
        );
    }
    Ok(Replayed {
        rows,
        joints: names,
        table,
        index_html: report.join("index.html"),
    })
}
