//! `realitygap tune`: calibrate an engine against the real arm (the work
//! is in `realitygap-tune`; this file parses arguments and draws the
//! progress bar).

use crate::cmd_engines;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use realitygap_analysis::selection::RunRange;
use realitygap_core::params::PhysicalParams;
use realitygap_runner::prepare::{engine_names, find_engine, overrides_for};
use realitygap_runner::slurm::Executor;
use realitygap_runner::Launcher;
use realitygap_study::data_source::assets_dir;
use realitygap_study::{load_study, DataSource};
use realitygap_tune::objective::{Simulator, Target};
use realitygap_tune::search::{Progress, SearchOptions};
use realitygap_tune::slurm_batch::Gatherer;
use realitygap_tune::space::Space;
use realitygap_tune::{default_space_file, tune, TuneSpec};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `realitygap tune`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The study file (TOML), e.g. assets/studies/collins2019.toml: its
    /// scenes are simulated and compared with its real runs. Not with
    /// --recordings.
    #[arg(required_unless_present = "recordings", conflicts_with = "recordings")]
    pub study: Option<PathBuf>,
    /// Tune against a robot's own recorded episodes instead of a study: a
    /// results directory written by `realitygap import rosbag|csv|lerobot`
    /// (joint space; --robot is then the URDF, default the one the import
    /// recorded).
    #[arg(long, value_name = "DIR")]
    pub recordings: Option<PathBuf>,
    /// With --recordings: parameters known and fixed, never searched (the
    /// servo gains of your ros2_control configuration, say), as a
    /// parameters file.
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// With --recordings: a replay scene to use instead of the generated
    /// one (engine settings, actuators), as for `replay --scene`.
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// With --recordings: fit the recorded efforts too (the servo's effort
    /// in the replay, `kv (v_target - qd)` at the engine's state, against
    /// the recorded one), which tells joint damping from the servo's kv.
    /// Meant for a scene whose servo the engine integrates explicitly (the
    /// recorded effort is the one applied over the next control period):
    /// MuJoCo's implicitfast integrates the servo implicitly, so the torque
    /// it applies is not the one computed from the state (use --scene with
    /// integrator = "Euler").
    #[arg(long)]
    pub efforts: bool,
    /// With --recordings: Levenberg-Marquardt iterations at most.
    #[arg(long, default_value_t = 30, value_name = "N")]
    pub iterations: usize,
    /// Folder of the study's recordings: `builtin` (default) or a folder.
    #[arg(long, value_name = "builtin|DIR", default_value = "builtin")]
    pub data: DataSource,
    /// The engine to tune.
    #[arg(long, short = 'e', value_name = "NAME")]
    pub engine: String,
    /// Output folder (created; a rerun of the same command resumes in it).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Parameter space (TOML); default assets/tuning/<engine>.toml.
    #[arg(long, value_name = "FILE")]
    pub space: Option<PathBuf>,
    /// Real runs (or recorded episodes, numbered from 1 in the results
    /// directory's order) to fit on, e.g. 1-15 (default: all; with
    /// --recordings and no --holdout, all but the last quarter).
    #[arg(long, value_name = "RANGE")]
    pub runs: Option<String>,
    /// Real runs to score on and never fit on, e.g. 16-20.
    #[arg(long, value_name = "RANGE")]
    pub holdout: Option<String>,
    /// Evaluations (each simulates every scene of the study).
    #[arg(long, default_value_t = 600, value_name = "EVALUATIONS")]
    pub budget: usize,
    /// Seed of the search.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Parallel evaluations (default: the number of cores).
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// Weight of the cube's final position error in the objective, per
    /// compared step of its scene (1: a miss counts like a wrist error of
    /// the same size held through the scene; 0: the wrist alone).
    #[arg(long, default_value_t = realitygap_tune::objective::CUBE_WEIGHT_PER_STEP, value_name = "W")]
    pub cube_weight: f64,
    /// Keep the measurement's registration estimate instead of fitting the
    /// capture frame with the parameters.
    #[arg(long)]
    pub keep_registration: bool,
    /// Engine settings over the space's: a parameters file's
    /// `[engine.NAME]` table, such as the `recommended.toml` that
    /// `realitygap frontier` writes.
    #[arg(long, value_name = "FILE")]
    pub settings: Option<PathBuf>,
    /// Engine setting over the space's and --settings: KEY=VALUE
    /// (repeatable).
    #[arg(long = "set", value_name = "[ENGINE.]KEY=VALUE")]
    pub set: Vec<String>,
    /// Robot instead of the scenes' (as for `run`).
    #[arg(long, value_name = "mico2|official|PATH")]
    pub robot: Option<String>,
    /// Where a ROS package is: NAME=DIR (repeatable).
    #[arg(long = "package", value_name = "NAME=DIR")]
    pub packages: Vec<String>,
    /// Where the simulations run (as for `run`): with `slurm`, each
    /// generation's candidates are submitted together as one job array.
    #[command(flatten)]
    pub executor: crate::cmd_run::ExecutorArgs,
}

/// Evaluation threads with `--executor slurm`: enough for every candidate
/// of a generation to wait on its array at once (CMA-ES's population is
/// 4 + 3 ln n, 17 for 60 parameters).
const SLURM_THREADS: usize = 64;

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if let Some(recordings) = args.recordings.clone() {
        return run_recordings(args, &recordings);
    }
    for (given, flag) in [
        (args.params.is_some(), "--params"),
        (args.scene.is_some(), "--scene"),
        (args.efforts, "--efforts"),
    ] {
        if given {
            anyhow::bail!("{flag} belongs to a tune against recordings: give --recordings DIR");
        }
    }
    let study_file = args
        .study
        .clone()
        .context("give a study file, or --recordings DIR")?;
    let registry = cmd_engines::compiled;
    let engine = find_engine(registry, &args.engine)?;
    let space_file = args
        .space
        .clone()
        .unwrap_or_else(|| default_space_file(&assets_dir(), engine.name()));
    let space = Space::from_file(&space_file)?;
    let mut set = match &args.settings {
        Some(f) => PhysicalParams::from_file(f)?
            .engine_settings
            .remove(engine.name())
            .with_context(|| {
                format!(
                    "--settings {}: no [engine.{}] table",
                    f.display(),
                    engine.name()
                )
            })?,
        None => Default::default(),
    };
    set.extend(overrides_for(
        &args.set,
        engine.name(),
        &engine_names(registry),
    )?);
    let (study, roots) = load_study(&study_file, &args.data, None)?;
    let range = |v: &Option<String>, flag: &str| -> Result<Option<RunRange>> {
        Ok(match v {
            Some(v) => Some(RunRange::parse(v, flag)?),
            None => None,
        })
    };
    let target = Target::new(
        &study,
        &roots,
        range(&args.runs, "--runs")?,
        range(&args.holdout, "--holdout")?,
        args.cube_weight,
    )
    .with_context(|| format!("study {}", study_file.display()))?;
    let executor = args.executor.executor()?;
    let gatherer = match &executor {
        Executor::Slurm(opts) => Some(std::sync::Arc::new(Gatherer::new(
            Launcher::this_executable(),
            opts.clone(),
            args.out.join(".slurm"),
        ))),
        Executor::Local => None,
    };
    let jobs = match gatherer {
        Some(_) => SLURM_THREADS,
        None => args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
    };
    let spec = TuneSpec {
        engine: engine.name().to_string(),
        fit_registration: !args.keep_registration && space.registration.is_some(),
        space,
        set,
        search: SearchOptions {
            budget: args.budget,
            seed: args.seed,
            jobs,
        },
        out: args.out.clone(),
    };
    say_settings(&spec, &space_file);
    let simulator = Simulator {
        launcher: Launcher::this_executable(),
        engine: spec.engine.clone(),
        robot: args.robot.clone(),
        packages: args.packages.clone(),
        slurm: gatherer.clone(),
    };
    let bar = progress_bar(args.budget);
    let started = Instant::now();
    let on_progress = |p: Progress| show(&bar, started, p);
    let result = tune(&target, &simulator, &spec, &on_progress)?;
    bar.finish_and_clear();
    print!("{}", realitygap_tune::outputs::markdown(&result.summary));
    eprintln!("\nwrote:");
    for f in &result.files {
        eprintln!("  {}", f.display());
    }
    eprintln!("  {}", args.out.join("history.csv").display());
    Ok(())
}

/// `tune --recordings`: the engine fitted to a robot's own episodes in
/// joint space.
fn run_recordings(args: Args, recordings: &std::path::Path) -> Result<()> {
    use realitygap_tune::recordings::{
        summary_markdown, tune_recordings, write_summary, RecordingsSpec,
    };
    if !matches!(args.executor.executor()?, Executor::Local) {
        anyhow::bail!("--recordings runs on this machine only (--executor local)");
    }
    let engine = find_engine(cmd_engines::compiled, &args.engine)?;
    let known = realitygap_runner::prepare::read_params(args.params.as_deref())?;
    let urdf = args.robot.as_ref().map(PathBuf::from);
    let prepared =
        realitygap_study::replay::prepare_replay(&realitygap_study::replay::ReplayRequest {
            real_dir: recordings,
            urdf: urdf.as_deref(),
            packages: &args.packages,
            params: &known,
            scene: args.scene.as_deref(),
            out: &args.out,
        })?;
    let space = match &args.space {
        Some(f) => Some(Space::from_file(f)?),
        None => None,
    };
    let range = |v: &Option<String>, flag: &str| -> Result<Option<RunRange>> {
        Ok(match v {
            Some(v) => Some(RunRange::parse(v, flag)?),
            None => None,
        })
    };
    let spec = RecordingsSpec {
        engine: engine.as_ref(),
        prepared: &prepared,
        known: &known,
        space,
        selection: realitygap_analysis::selection::RunSelection {
            runs: range(&args.runs, "--runs")?,
            holdout: range(&args.holdout, "--holdout")?,
        },
        out: args.out.clone(),
        jobs: args
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        max_iterations: args.iterations,
        use_efforts: args.efforts,
    };
    eprintln!(
        "tuning {} against {} recorded episodes of robot '{}' in joint space",
        engine.name(),
        prepared.episodes.len(),
        prepared.robot.name
    );
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {elapsed_precise} {pos} evaluations, {msg}")
            .expect("a valid template"),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let on_progress = |p: realitygap_tune::recordings::RecordingsProgress| {
        bar.set_position(p.evaluations as u64);
        bar.set_message(format!(
            "{}; best training RMS {:.4} deg",
            p.phase, p.best_rms_deg
        ));
    };
    let mut result = tune_recordings(&spec, &on_progress)?;
    bar.finish_and_clear();
    write_summary(&args.out, recordings, &mut result)?;
    print!("{}", summary_markdown(&result.summary));
    eprintln!("\nwrote:");
    for f in &result.files {
        eprintln!("  {}", f.display());
    }
    Ok(())
}

/// Says which settings the tune runs at, and where they come from.
fn say_settings(spec: &TuneSpec, space_file: &std::path::Path) {
    let mut in_force = spec
        .space
        .settings
        .get(&spec.engine)
        .cloned()
        .unwrap_or_default();
    in_force.extend(spec.set.clone());
    let settings: Vec<String> = in_force.iter().map(|(k, v)| format!("{k}={v}")).collect();
    eprintln!(
        "tuning {} ({} parameters{}) at settings {} ({}; the space's are the speed-accuracy frontier's recommendation)",
        spec.engine,
        spec.space.dims.len(),
        if spec.fit_registration { " + the registration's 6" } else { "" },
        if settings.is_empty() { "of the scenes".to_string() } else { settings.join(" ") },
        if spec.set.is_empty() {
            format!("from {}", space_file.display())
        } else {
            format!("from {} with --settings/--set over it", space_file.display())
        },
    );
}

fn progress_bar(budget: usize) -> ProgressBar {
    let bar = ProgressBar::new(budget as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} evaluations, {msg}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar
}

/// The bar's position and message: the best objective so far and the
/// evaluations per second (replayed ones aside).
fn show(bar: &ProgressBar, started: Instant, p: Progress) {
    bar.set_position(p.done as u64);
    let fresh = p.done.saturating_sub(p.replayed);
    bar.set_message(format!(
        "best {:.4} m, {:.2} evaluations/s{}",
        p.best,
        fresh as f64 / started.elapsed().as_secs_f64().max(1e-9),
        if p.replayed > 0 {
            format!(" ({} replayed)", p.replayed)
        } else {
            String::new()
        }
    ));
}
