//! `realitygap stitch`: stitched plans (one engine per schedule phase)
//! chosen on the training runs and scored against every single engine on
//! the training and held-out runs. The work is done by
//! `realitygap_study::stitch`.

use crate::cmd_compare::MeasureArgs;
use crate::cmd_engines;
use anyhow::Result;
use realitygap_runner::Launcher;
use realitygap_study::stitch::{markdown, stitch_study, Runner, StitchOptions};
use realitygap_study::DataSource;
use std::path::PathBuf;

/// Arguments of `realitygap stitch`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// A study file (TOML) whose scenes name their scene files, e.g.
    /// assets/studies/collins2019.toml.
    pub study: PathBuf,
    /// The real arm's recordings: `builtin` (the default) or a folder.
    #[arg(long, value_name = "builtin|DIR", default_value = "builtin")]
    pub data: DataSource,
    /// Output folder: the runs (`runs/`), `stitch.md`, `stitch.json` and
    /// the report (`report/`).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Engines taking part (repeatable); default: every engine compiled in.
    #[arg(long = "engine", short = 'e', value_name = "NAME")]
    pub engines: Vec<String>,
    /// The stiff-motor engine of the study's proposed plan (free motion).
    #[arg(long, default_value = "bullet", value_name = "NAME")]
    pub stiff: String,
    /// The contact engine of the study's proposed plan.
    #[arg(long, default_value = "mujoco", value_name = "NAME")]
    pub contact: String,
    /// Runs at a time (default: the number of cores).
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// Another plan to run and score, E1,E2,... (repeatable); used in the
    /// scenes with at least as many phases as engines named.
    #[arg(long = "plan", value_name = "E1,E2,...")]
    pub plans: Vec<String>,
    /// An engine with a parameters file of its own taking part beside the
    /// engines at their defaults: ENGINE=FILE, or the --out folder of a
    /// `realitygap tune` (its engine and tuned.toml); repeatable. A plan
    /// names it ENGINE@FILE. The first tune folder's fitted physics-free
    /// model (physics-free-actuator/) is scored as a baseline row, unless
    /// `ideal=FILE` is given.
    #[arg(long = "tuned", value_name = "ENGINE=FILE|TUNE_DIR")]
    pub tuned: Vec<String>,
    /// How the gap is measured (`--runs` choose the plans, `--holdout`
    /// scores them).
    #[command(flatten)]
    pub measure: MeasureArgs,
}

/// `realitygap stitch`.
pub fn run(args: Args) -> Result<()> {
    let opts = StitchOptions {
        study: args.study,
        data: args.data,
        out: args.out,
        measure: args.measure.measure(),
        engines: args.engines,
        stiff_engine: args.stiff,
        contact_engine: args.contact,
        jobs: args.jobs,
        plans: args.plans,
        tuned: args.tuned,
        physics_free_subdir: Some(realitygap_tune::outputs::PHYSICS_FREE_DIR.to_string()),
    };
    let runner = Runner {
        registry: cmd_engines::compiled,
        launcher: Launcher::this_executable(),
    };
    let result = stitch_study(&opts, &runner)?;
    print!("{}", markdown(&result));
    eprintln!(
        "wrote {} and {}",
        opts.out.join("stitch.md").display(),
        opts.out.join("stitch.json").display()
    );
    Ok(())
}
