//! `realitygap tune`: calibrate an engine against the real arm (the work
//! is in `realitygap-tune`, the sequence in [`realitygap::tune`]; this file
//! parses arguments).

use anyhow::Result;
use realitygap::tune::{tune, TuneRequest};
use realitygap_runner::Launcher;
use realitygap_study::DataSource;
use std::path::PathBuf;

/// Arguments of `realitygap tune`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The study file (TOML), e.g. assets/studies/collins2019.toml: its
    /// scenes are simulated and compared with its real runs; or a study of
    /// tosses, assets/studies/contactnets2020.toml: the contact (friction,
    /// restitution, softness; assets/tuning/tosses.toml) fitted on its
    /// tosses and scored on the ones it holds out. Not with --recordings.
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
    /// Levenberg-Marquardt iterations at most: with --recordings, the
    /// Jacobians each fit computes by differences (default 30; Broyden's
    /// updates between them are not counted); each round of the study tune's polish (its reweighting passes together)
    /// after CMA-ES (default 10; 0: no polish, no intervals).
    #[arg(long, value_name = "N")]
    pub iterations: Option<usize>,
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
    /// directory's order) to fit on, e.g. 1-15 (default: all, or with
    /// --holdout, every run it does not hold out; with --recordings and no
    /// --holdout, all but the last quarter).
    #[arg(long, value_name = "RANGE")]
    pub runs: Option<String>,
    /// Real runs to score on and never fit on, e.g. 16-20.
    #[arg(long, value_name = "RANGE")]
    pub holdout: Option<String>,
    /// Cross-validate: split the real runs into K folds of consecutive
    /// runs (20 runs in 4 folds: 1-5, 6-10, 11-15, 16-20), tune once per
    /// fold with that fold held out (OUT/fold-N, each a whole tune with
    /// the physics-free model's own actuator stage), and gather the
    /// held-out scores over the folds into OUT/crossval.md and .json (mean,
    /// spread, and the paired differences against both physics-free rows).
    /// K times a tune's time. Not with --runs, --holdout or --recordings.
    #[arg(long, value_name = "K", conflicts_with_all = ["runs", "holdout", "recordings"])]
    pub folds: Option<usize>,
    /// Evaluations (each simulates every scene of the study, or every toss
    /// fitted on), at least 1. Default 600; for a study of tosses, the
    /// study file's `budget` (96 for contactnets2020). A bound each stage
    /// stops at between its steps: the search finishes the generation
    /// under way, the polish its round.
    #[arg(long, value_name = "EVALUATIONS", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub budget: Option<usize>,
    /// Seed of the search.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Restart the search when it stalls before the budget is spent (its
    /// best falls by less than the real runs' noise over CMA-ES's history
    /// length, 10 + 30 n / lambda generations): from a random point of the
    /// space with twice the population (IPOP-CMA-ES), until the budget is
    /// spent. For an objective with more than one optimum; the polish
    /// starts from the best point of all the runs
    #[arg(long)]
    pub restarts: bool,
    /// Parallel evaluations (default: the number of cores).
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// Weight of the cube's final pose error in the objective, per
    /// compared step of its scene (0.1: a miss counts like a wrist error of
    /// the same size held through a tenth of the scene, so 1 cm in the
    /// study's scene 3 weighs about the real runs' noise; 0: the wrist
    /// alone, and the space's object and contact keys are then held at the
    /// scenes' values).
    /// The pose error is the distance between the simulated and the real
    /// cube's final positions plus the angle between their turns times
    /// half the cube's edge.
    #[arg(long, default_value_t = realitygap_tune::objective::CUBE_WEIGHT_PER_STEP, value_name = "W")]
    pub cube_weight: f64,
    /// Keep the measurement's registration estimate instead of fitting the
    /// capture frame with the parameters.
    #[arg(long)]
    pub keep_registration: bool,
    /// Leave out the row "physics-free + actuator (fitted)": the
    /// physics-free model behind its own actuator stage, fitted on the same
    /// runs with the same effort, which every study tune is otherwise
    /// scored against. Its fit costs about what the engine's does; leave it
    /// out when that comparison is not wanted (known-truth checks, a
    /// robot whose joints assets/tuning/ideal.toml does not name).
    #[arg(long)]
    pub no_baseline: bool,
    /// Where the engine's search starts: `space` (the space file's
    /// `start` values, the engine's defaults) or `physics-free` (fit the
    /// physics-free model behind its actuator stage first, then start the
    /// engine's search at its fitted actuator stage, delay, acceleration
    /// limit, encoder offsets and registration: the keys both spaces
    /// have).
    #[arg(long, value_name = "space|physics-free", default_value = "space", value_parser = ["space", "physics-free"], conflicts_with = "no_baseline")]
    pub start: String,
    /// Pull the engine's search toward the physics-free model's fit: the
    /// objective adds W x the sum, over the keys both fits share (the
    /// actuator stage, delay, acceleration limit, encoder offsets,
    /// registration), of each key's squared distance from the physics-free
    /// model's fitted value as a fraction of its range in the engine's
    /// space (in metres of accumulated wrist error per key moved across
    /// its whole range). The physics-free model is then fitted first.
    /// Choose W by cross-validation (--folds); 0 (the default): no pull.
    #[arg(
        long,
        value_name = "W",
        default_value_t = 0.0,
        conflicts_with = "no_baseline"
    )]
    pub prior_weight: f64,
    /// Engine settings over the space's: a parameters file's
    /// `[engine.NAME]` table, such as the `recommended.toml` that
    /// `realitygap frontier` writes. With --recordings: over the replay
    /// scene's and --params' settings.
    #[arg(long, value_name = "FILE")]
    pub settings: Option<PathBuf>,
    /// Engine setting over the space's and --settings: KEY=VALUE
    /// (repeatable). With --recordings: over the replay scene's, --params'
    /// and --settings.
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
    /// Print the whole summary (parameters, sensitivity), not only the
    /// scores; it is always in OUT/summary.md.
    #[arg(long, short = 'v')]
    pub verbose: bool,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let request = TuneRequest {
        study: args.study,
        recordings: args.recordings,
        params: args.params,
        scene: args.scene,
        efforts: args.efforts,
        iterations: args.iterations,
        data: args.data,
        engine: args.engine,
        out: args.out,
        space: args.space,
        runs: args.runs,
        holdout: args.holdout,
        folds: args.folds,
        budget: args.budget,
        seed: args.seed,
        restarts: args.restarts,
        jobs: args.jobs,
        cube_weight: args.cube_weight,
        keep_registration: args.keep_registration,
        no_baseline: args.no_baseline,
        start_from_baseline: args.start == "physics-free",
        prior_weight: args.prior_weight,
        settings: args.settings,
        set: args.set,
        robot: args.robot,
        packages: args.packages,
        executor: args.executor.executor()?,
        verbose: args.verbose,
    };
    tune(
        &request,
        &Launcher::this_executable(),
        &realitygap::ui::Terminal,
    )?;
    Ok(())
}
