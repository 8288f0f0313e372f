//! `realitygap run`: simulate scenes in engines, in parallel, into results
//! directories.
//!
//! Layout: `OUT/<scene name>/<source>/` with `manifest.json` and
//! `runs/run000.csv ...`, where `<source>` is the engine's name, or
//! `<engine>-<robot>` when `--robot` replaces the scene's robot, or
//! `stitched-<E1>-<E2>-...` for a stitched run (`--stitch`), whose
//! manifest holds the plan (`settings.config.stitch`) and each run's
//! handovers (`runs[].extra.handovers`).
//!
//! Every run executes in a child process (this binary, re-invoked with the
//! hidden subcommand `__run-one`, reading its job as JSON on standard input
//! and writing its trajectory as JSON on standard output). A crash, abort or
//! `exit` inside an engine's native code therefore fails only that run: it
//! is recorded as `failed` with the engine's last words, and the batch goes
//! on. The parent alone writes the results directories (atomically, run by
//! run), so an interrupted batch keeps every finished run, and a rerun skips
//! them.

use anyhow::Result;
use realitygap_runner::slurm::{Executor, SlurmOptions};
use realitygap_runner::{BatchSpec, Launcher};
use std::path::PathBuf;

/// Arguments of `realitygap run`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Scene files (TOML), e.g. assets/scenes/*.toml.
    #[arg(required = true, value_name = "SCENE")]
    pub scenes: Vec<PathBuf>,
    /// Engines to run (repeatable); default: every engine compiled in.
    #[arg(long = "engine", short = 'e', value_name = "NAME")]
    pub engines: Vec<String>,
    /// Runs per scene and engine.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub repeats: u32,
    /// Results directory (created; reused by a rerun).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Robot instead of the scene's: `mico2` (the project's, built in),
    /// `official` (the Kinova URDF of the kinova_description package: from
    /// --package or ROS_PACKAGE_PATH, else the one in the study data built
    /// in), or a URDF file.
    #[arg(long, value_name = "mico2|official|PATH")]
    pub robot: Option<String>,
    /// Where a ROS package is, for `package://` URIs: NAME=DIR (repeatable).
    /// ROS_PACKAGE_PATH is searched too.
    #[arg(long = "package", value_name = "NAME=DIR")]
    pub packages: Vec<String>,
    /// Runs at a time (default: the number of cores).
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// Seed of the per-repeat perturbations.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Perturb each repeat: key=value[,key=value] with keys
    /// initial_offset_deg, sensor_noise_deg, delay_periods, mass_scale,
    /// friction_scale; or a randomisation file (randomize.toml, as `tune`
    /// writes it) whose parameter ranges each repeat draws from, over
    /// --params. Off by default.
    #[arg(long = "perturb", value_name = "KEY=VALUE,...|FILE")]
    pub perturb: Vec<String>,
    /// Engine setting overriding the scene's: key=value for every engine,
    /// or engine.key=value (e.g. mujoco.timestep_s=0.0005).
    #[arg(long = "set", value_name = "[ENGINE.]KEY=VALUE")]
    pub set: Vec<String>,
    /// Give up on a run after this many seconds (recorded as failed).
    #[arg(long, value_name = "SECONDS")]
    pub timeout_s: Option<f64>,
    /// Physical parameters (TOML: [joints.NAME], [links.NAME],
    /// [objects.NAME], [contact], [controller], [actuator],
    /// [engine.NAME]; see docs/simulate.md, "Physical parameters", and
    /// `realitygap engines --params`). `--set` still overrides its engine
    /// settings.
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// A stitched run: phase i of each scene's schedule in engine Ei,
    /// the state handed over at each phase boundary; fewer engines than
    /// phases repeat the last. Stored as the source `stitched E1>E2>...`
    /// in `OUT/<scene>/stitched-E1-E2-.../`. Not with --engine.
    #[arg(long, value_name = "E1,E2,...")]
    pub stitch: Option<String>,
    /// Run settings that the engine knows to be numerically unstable for
    /// the model (e.g. MuJoCo's Euler integrator with kv*dt/I_eff past its
    /// bound) instead of refusing them; each run records the issues in its
    /// manifest entry (`extra.allowed_unstable_settings`).
    #[arg(long)]
    pub allow_unstable: bool,
    /// Where the simulations run.
    #[command(flatten)]
    pub executor: ExecutorArgs,
}

/// `--executor local|slurm` and the Slurm options.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ExecutorArgs {
    /// `local`: child processes on this machine, --jobs at a time;
    /// `slurm`: one Slurm job array per batch (sbatch), each task running
    /// its share of the simulations; the results directory must be on a
    /// filesystem the compute nodes share.
    #[arg(long, value_name = "local|slurm", default_value = "local", value_parser = ["local", "slurm"])]
    pub executor: String,
    /// Slurm partition (`sbatch --partition`).
    #[arg(long, value_name = "NAME")]
    pub slurm_partition: Option<String>,
    /// Time limit of each array task (`sbatch --time`, e.g. 1:00:00).
    #[arg(long, value_name = "TIME")]
    pub slurm_time: Option<String>,
    /// Memory of each array task (`sbatch --mem`, e.g. 2G).
    #[arg(long, value_name = "SIZE")]
    pub slurm_mem: Option<String>,
    /// More sbatch arguments, passed as they are (repeatable).
    #[arg(long = "slurm-arg", value_name = "ARG", allow_hyphen_values = true)]
    pub slurm_args: Vec<String>,
    /// At most this many array tasks at once (`--array=...%N`).
    #[arg(long, value_name = "N")]
    pub slurm_max_tasks: Option<usize>,
    /// Simulations per array task.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub slurm_runs_per_task: usize,
}

impl ExecutorArgs {
    /// The executor these arguments choose.
    pub fn executor(&self) -> Result<Executor> {
        Ok(match self.executor.as_str() {
            "slurm" => {
                realitygap_runner::slurm::check_available()?;
                Executor::Slurm(SlurmOptions {
                    partition: self.slurm_partition.clone(),
                    time: self.slurm_time.clone(),
                    mem: self.slurm_mem.clone(),
                    args: self.slurm_args.clone(),
                    max_tasks: self.slurm_max_tasks,
                    runs_per_task: self.slurm_runs_per_task.max(1),
                })
            }
            _ => Executor::Local,
        })
    }
}

impl Args {
    /// The batch these arguments describe.
    fn into_spec(self) -> BatchSpec {
        BatchSpec {
            scenes: self.scenes,
            engines: self.engines,
            repeats: self.repeats,
            out: self.out,
            robot: self.robot,
            packages: self.packages,
            jobs: self.jobs,
            seed: self.seed,
            perturb: self.perturb,
            set: self.set,
            timeout_s: self.timeout_s,
            params: self.params,
            stitch: self.stitch,
            allow_unstable: self.allow_unstable,
        }
    }
}

/// `realitygap __run-one`: runs one job (JSON on standard input) with the
/// engines compiled in and writes its result on standard output.
pub fn run_one() -> Result<()> {
    realitygap::run_one()
}

/// `realitygap run`.
pub fn run(args: Args) -> Result<()> {
    let executor = args.executor.executor()?;
    realitygap::batch::run_and_report(
        args.into_spec(),
        executor,
        &Launcher::this_executable(),
        &realitygap::ui::Terminal,
    )?;
    Ok(())
}
