//! `realitygap frontier`: argument parsing and printing; the sweep is
//! `realitygap_frontier` (see its documentation for what is measured).

use crate::cmd_engines;
use crate::cmd_run::ExecutorArgs;
use anyhow::{Context, Result};
use realitygap_frontier::{FrontierSpec, MAX_HALVINGS};
use realitygap_study::data_source::DataSource;
use std::path::PathBuf;

/// Arguments of `realitygap frontier`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene files (TOML).
    #[arg(required = true, value_name = "SCENE")]
    pub scenes: Vec<PathBuf>,
    /// The engine to sweep (see `realitygap engines`).
    #[arg(long, short = 'e', value_name = "NAME")]
    pub engine: String,
    /// A setting and the values to sweep it over, KEY=V1,V2,... (repeatable;
    /// the lists are crossed). Keys: `realitygap engines --settings`.
    /// Default: the engine's own grid (docs/frontier.md, "Default sweeps").
    #[arg(long = "sweep", value_name = "KEY=V1,V2,...")]
    pub sweep: Vec<String>,
    /// Largest deviation from the converged reference a recommended setting
    /// may have, millimetres.
    #[arg(long, default_value_t = 1.0, value_name = "MM")]
    pub tolerance_mm: f64,
    /// The real arm's recordings for the gap (`builtin` or a paper-data
    /// folder); off when not given.
    #[arg(long, value_name = "builtin|DIR")]
    pub data: Option<DataSource>,
    /// Timed runs per setting and scene; the minimum CPU time is kept.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeats: u32,
    /// Most times the finest setting's timestep is halved in search of a
    /// converged reference (each halving doubles its cost; contact scenes
    /// may need many).
    #[arg(long, default_value_t = MAX_HALVINGS, value_parser = clap::value_parser!(u32).range(0..=10))]
    pub max_halvings: u32,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Where the simulations run (as for `run`): with `slurm`, the
    /// reference's setting, each halving of its timestep, then every
    /// setting x scene x repeat are job arrays, each simulation timed by
    /// the task on its own thread's CPU clock; `--out` must be on a
    /// filesystem the compute nodes share.
    #[command(flatten)]
    pub executor: ExecutorArgs,
}

/// `realitygap frontier`.
pub fn run(args: Args) -> Result<()> {
    realitygap::install_native_handlers();
    let engine = realitygap_runner::prepare::find_engine(cmd_engines::compiled, &args.engine)
        .context("--engine")?;
    let executor = args.executor.executor()?;
    let spec = FrontierSpec {
        scenes: args.scenes,
        sweep: args.sweep,
        tolerance_mm: args.tolerance_mm,
        data: args.data,
        repeats: args.repeats,
        max_halvings: args.max_halvings,
        out: args.out,
        executor,
        launcher: realitygap_runner::Launcher::this_executable(),
        say: Box::new(|line| eprintln!("{line}")),
        tell: Box::new(|line| println!("{line}")),
    };
    realitygap_frontier::run(&spec, engine.as_ref())
}
