//! `realitygap reproduce`: the whole study in one command (the stages are
//! in [`realitygap::reproduce`]).

use crate::cmd_compare::mode_parser;
use crate::cmd_run;
use anyhow::Result;
use realitygap::reproduce::{reproduce, ReproduceRequest};
use realitygap_analysis::compare::AnalysisMode;
use realitygap_runner::Launcher;
use realitygap_study::DataSource;
use std::path::PathBuf;

/// Arguments of `realitygap reproduce`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The study's recordings: `builtin` (the default: shipped with the
    /// project, unpacked once into ~/.cache/realitygap or
    /// $REALITYGAP_CACHE_DIR), a folder with MotionCapture/ and
    /// Simulation/, or `none` to compare the engines with each other.
    #[arg(long, value_name = "builtin|none|DIR", default_value = "builtin")]
    pub data: DataSource,
    /// Output folder: runs/, report/, tables and timings.json.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Runs per scene and engine (the study made 20).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub repeats: u32,
    /// Engines (repeatable); default: every engine compiled in.
    #[arg(long = "engine", short = 'e', value_name = "NAME")]
    pub engines: Vec<String>,
    /// Scene files; default: the study's three scenes in assets/scenes.
    #[arg(long = "scene", value_name = "FILE")]
    pub scenes: Vec<PathBuf>,
    /// Simulations at a time (default: the number of cores).
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// `default` (flagged runs left out, estimated alignment) or `study`.
    #[arg(long, default_value = "default", value_parser = mode_parser())]
    pub mode: AnalysisMode,
    /// Give up on a simulation after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub timeout_s: Option<f64>,
    /// Physical parameters for every engine's runs (see `run --params`).
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// The output folder of a `realitygap tune` (repeatable): its engine
    /// runs again with tuned.toml and shows as "<engine> (tuned)" next to
    /// the untuned rows; the physics-free row fitted beside it
    /// (DIR/physics-free-actuator) shows as "physics-free (tuned)".
    #[arg(long, value_name = "DIR")]
    pub tuned: Vec<PathBuf>,
    /// The output folder of a cross-validated tune (`tune STUDY --folds K
    /// --out DIR`; repeatable): the report's verdict opens with whether
    /// any tuned engine beats the physics-free model behind its fitted
    /// actuator stage on runs it did not see, and a section holds their
    /// table and figures.
    #[arg(long, value_name = "DIR")]
    pub crossval: Vec<PathBuf>,
    /// Also compare in joint space (`compare --joint-space`): every
    /// engine's joint angles against the real arm's, found by inverse
    /// kinematics of its wrist capture; written to joint_space.md and
    /// joint_space.json (needs the recordings). `--runs` and `--holdout`
    /// choose the real runs the registration is fitted on and scored on.
    #[arg(long)]
    pub joint_space: bool,
    /// With --joint-space: the real runs to fit the IK registration on,
    /// e.g. 1-15 (default: all).
    #[arg(long, value_name = "RANGE", requires = "joint_space")]
    pub runs: Option<String>,
    /// With --joint-space: the real runs to score on, never fitted on,
    /// e.g. 16-20 (default: none held out).
    #[arg(long, value_name = "RANGE", requires = "joint_space")]
    pub holdout: Option<String>,
    /// Leave out the second study: the 456 real cube tosses built in
    /// (assets/studies/contactnets2020.toml), replayed in every engine at
    /// its defaults beside the physics-free row into OUT/tosses/ (about
    /// 25 s on 2 cores). Never with --data none.
    #[arg(long)]
    pub no_tosses: bool,
    /// Where the simulations run (as for `run`).
    #[command(flatten)]
    pub executor: cmd_run::ExecutorArgs,
    /// Print a line per scene and engine, and the full tables (every
    /// measure and flagged run) instead of the summary; they are always in
    /// OUT/report/table.md.
    #[arg(long, short = 'v')]
    pub verbose: bool,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let request = ReproduceRequest {
        data: args.data,
        out: args.out,
        repeats: args.repeats,
        engines: args.engines,
        scenes: args.scenes,
        jobs: args.jobs,
        mode: args.mode,
        timeout_s: args.timeout_s,
        params: args.params,
        tuned: args.tuned,
        crossval: args.crossval,
        joint_space: args.joint_space,
        runs: args.runs,
        holdout: args.holdout,
        // `--executor slurm` without Slurm is an error now, not a warning per batch.
        executor: args.executor.executor()?,
        tosses: !args.no_tosses,
        command: std::env::args().collect::<Vec<_>>().join(" "),
        verbose: args.verbose,
    };
    reproduce(
        &request,
        &Launcher::this_executable(),
        &realitygap::ui::Terminal,
    )?;
    Ok(())
}
