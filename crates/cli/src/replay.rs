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
    /// Tossed objects: where the initial velocity comes from.
    pub toss_start: realitygap_study::tosses::TossStart,
}

/// What a replay made.
pub struct Replayed {
    /// `replay` (a robot's episodes) or `tosses` (tossed objects), as
    /// `compare` of the folder names it.
    pub kind: &'static str,
    /// The table as CSV: the joint-space table, or the toss table.
    pub csv: String,
    /// The rows as JSON: [`Replayed::rows`], or the toss table's rows.
    pub json: String,
    /// Per source (the physics-free model first), the joint-space row
    /// (none for tosses).
    pub rows: Vec<JointSpaceRow>,
    /// The replayed joints' names.
    pub joints: Vec<String>,
    /// The table in Markdown (OUT/joint_space.md, or OUT/tosses.md).
    pub table: String,
    /// `OUT/report/index.html`.
    pub index_html: PathBuf,
}

/// Replays the episodes in every engine; says the table and a summary on
/// `ui`. An error when a replay failed (after everything is written).
pub fn replay(args: &ReplayOptions, launcher: &Launcher, ui: &dyn Ui) -> Result<Replayed> {
    let params =
        realitygap_runner::prepare::read_params_checked(crate::engines, args.params.as_deref())?;
    // The physics-free model is the `ideal` row of every replay, computed
    // from its one definition (`kinematic_run`), never stepped as an engine.
    let chosen = select_engines(crate::engines, &args.engines)?;
    let mut engines = Vec::new();
    let mut refused: Vec<(String, String)> = Vec::new();
    let mut ideal_chosen = false;
    for engine in chosen {
        if engine.name() == KINEMATIC {
            ideal_chosen = true;
            continue;
        }
        // A key of the user's parameters the engine cannot honour: its row
        // is marked with the reason, the others run.
        match params.check_support(engine.name(), &engine.param_support()) {
            Ok(()) => engines.push(engine),
            Err(e) => refused.push((engine.name().to_string(), e.to_string())),
        }
    }
    for (name, why) in &refused {
        ui.note(format!("{name}: not replayed: {why}"));
    }
    if engines.is_empty() && refused.is_empty() && !ideal_chosen {
        bail!("no physics engine is compiled into this binary");
    }
    if realitygap_study::tosses::is_toss_store(&args.real) {
        let engines: Vec<&dyn realitygap_core::Engine> =
            engines.iter().map(|e| e.as_ref()).collect();
        return replay_tosses(args, &engines, &params, ui);
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
    for n in &prepared.robot.notes {
        ui.note(format!("note: {n}"));
    }
    if let Some(w) = prepared.held_warning() {
        ui.note(format!("warning: {w}"));
    }
    for w in prepared.partial_gain_warnings(&params) {
        ui.note(format!("warning: {w}"));
    }
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
    let mut table = joint_space_markdown(&rows, &names);
    for (name, why) in &refused {
        table.push_str(&refused_row(name, why, names.len()));
    }
    std::fs::write(args.out.join("joint_space.md"), &table)?;
    let mut json = serde_json::to_value(&rows)?;
    if let Some(list) = json.as_array_mut() {
        for (name, why) in &refused {
            list.push(serde_json::json!({"source": name, "refused": why}));
        }
    }
    std::fs::write(
        args.out.join("joint_space.json"),
        serde_json::to_string_pretty(&json)? + "\n",
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
        "replayed {} episodes of robot '{}' in {} engines ({} runs, {reused} kept from an earlier batch, {failed} failed{}); the physics-free model ({KINEMATIC}) on {kinematic} episodes; {}; the report {}",
        prepared.episodes.len(),
        prepared.robot.name,
        engines.len(),
        runs.len(),
        if refused.is_empty() {
            String::new()
        } else {
            format!(
                "; not replayed, for keys of the parameters they cannot honour: {}",
                refused
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
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
        kind: "replay",
        csv: realitygap_study::replay::joint_space_csv(&rows, &names),
        json: serde_json::to_string(&rows)?,
        rows,
        joints: names,
        table,
        index_html: report.join("index.html"),
    })
}

/// `replay` of tossed objects (a results directory of `import
/// contactnets`): every toss in every engine and the physics-free model,
/// `OUT/<engine>/runs/<id>.csv`, and the toss table `OUT/tosses.md`.
fn replay_tosses(
    args: &ReplayOptions,
    engines: &[&dyn realitygap_core::Engine],
    params: &realitygap_core::PhysicalParams,
    ui: &dyn Ui,
) -> Result<Replayed> {
    if args.robot.is_some() || args.scene.is_some() || !args.packages.is_empty() {
        bail!(
            "{} holds tossed objects, not a robot's episodes: --robot, --scene and --package do not apply",
            args.real.display()
        );
    }
    if !matches!(args.executor, Executor::Local) {
        bail!("tossed objects are replayed on this machine: --executor slurm does not apply");
    }
    let set = realitygap_study::tosses::read_tosses(&args.real, args.toss_start)?;
    let jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let bar = ui.bar((engines.len() * set.tosses.len()) as u64, "tosses");
    let rows = realitygap_study::tosses::replay_tosses(
        engines,
        &set,
        params,
        &args.out,
        jobs,
        &|engine, id, failed| {
            bar.inc(1);
            if let Some(why) = failed {
                bar.println(format!("toss {id} in {engine}: failed: {why}"));
            }
        },
    )?;
    bar.finish();
    use realitygap_study::tosses::{toss_csv, toss_json, write_toss_report, ReplayedWith};
    let table = realitygap_study::tosses::toss_markdown(&rows, &set);
    ui.say(table.clone());
    let index_html = write_toss_report(
        &rows,
        &set,
        &args.out,
        &args.out.join("report"),
        ReplayedWith::of_params(params),
        "tosses.md and tosses.json in the replay's folder",
    )?;
    let failed: usize = rows.iter().map(|r| r.failed).sum();
    ui.say(format!(
        "replayed {} tosses in {} engines and the physics-free model ({KINEMATIC}): {failed} diverged or failed; the table {}, the report {}",
        set.tosses.len(),
        engines.len(),
        args.out.join("tosses.md").display(),
        index_html.display()
    ));
    let errors: usize = rows.iter().map(|r| set.tosses.len() - r.tosses).sum();
    if errors > 0 {
        bail!(
            "{errors} toss replays failed (see the messages above and the manifests in {})",
            args.out.display()
        );
    }
    Ok(Replayed {
        kind: "tosses",
        csv: toss_csv(&rows, &set),
        json: toss_json(&rows),
        rows: Vec::new(),
        joints: Vec::new(),
        table,
        index_html,
    })
}

/// A row of the joint-space table for an engine that was not replayed.
fn refused_row(name: &str, why: &str, joints: usize) -> String {
    let why = why.replace('|', "/").replace('\n', " ");
    let mut row = format!("| {name} | 0 | — | — | — | not replayed: {why} |");
    for _ in 0..joints {
        row.push_str(" — |");
    }
    row.push('\n');
    row
}

/// The engines `--engine` chooses from `registry`: every one when none is
/// named (or `all`); the named ones; or every one but those named
/// `all-except:A,B` or `-A` / `!A`.
pub fn select_engines(
    registry: realitygap_runner::Registry,
    names: &[String],
) -> Result<Vec<Box<dyn realitygap_core::Engine>>> {
    let all = registry();
    if all.is_empty() {
        bail!("no physics engine is compiled into this binary");
    }
    let known: Vec<String> = all.iter().map(|e| e.name().to_string()).collect();
    let mut include = Vec::new();
    let mut exclude = Vec::new();
    for n in names {
        let n = n.trim();
        if let Some(list) = n
            .strip_prefix("all-except:")
            .or_else(|| n.strip_prefix("all-except="))
        {
            exclude.extend(list.split(',').map(|x| x.trim().to_string()));
        } else if let Some(x) = n.strip_prefix('-').or_else(|| n.strip_prefix('!')) {
            exclude.push(x.trim().to_string());
        } else if n == "all" {
            include.extend(known.iter().cloned());
        } else {
            include.push(n.to_string());
        }
    }
    for n in include.iter().chain(&exclude) {
        if !known.contains(n) {
            if realitygap_engine_remote::registry::adapter(n).is_some() {
                bail!(
                    "engine \"{n}\" is not installed: `{}` makes its environment",
                    realitygap_engine_remote::registry::install_line(n)
                );
            }
            bail!(
                "unknown engine \"{n}\" in --engine (compiled in: {}; all-except:A,B or -A leaves engines out)",
                known.join(", ")
            );
        }
    }
    Ok(all
        .into_iter()
        .filter(|e| {
            let n = e.name().to_string();
            (include.is_empty() || include.contains(&n)) && !exclude.contains(&n)
        })
        .collect())
}
