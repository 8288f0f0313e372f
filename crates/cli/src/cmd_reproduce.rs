//! `realitygap reproduce`: the whole study in one command.
//!
//! Stages, each timed:
//! 1. **simulate**: the three study scenes in every compiled engine,
//!    `--repeats` times each (20 by default), into `OUT/runs/` exactly as
//!    `realitygap run` does (parallel, resumable);
//! 2. **compare**: against the real arm's recordings, next to the study's
//!    recorded simulators (MuJoCo 1.5, PyBullet 2.1 and the V-Rep engines),
//!    from the recordings built in or `--data DIR`; with `--data none`, the
//!    engines against each other (the reference is the first engine, MuJoCo
//!    when compiled in);
//! 3. **report**: tables, figures and `OUT/report/index.html`.
//!
//! A rerun skips the finished simulations and redoes the (fast) rest.

use crate::cmd_compare::mode_parser;
use crate::cmd_engines;
use crate::cmd_run;
use anyhow::{bail, Context, Result};
use realitygap_analysis::compare::{AnalysisMode, CompareOptions, SceneReport};
use realitygap_analysis::table::{self, Format};
use realitygap_study::provenance::provenance_for_study;
use realitygap_study::reproduce::{
    reproduction_study, study_recordings, study_scene_files, TunedEngine,
};
use realitygap_study::{evaluate, DataSource, Roots, Study};
use std::path::{Path, PathBuf};
use std::time::Instant;

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
    /// the untuned rows.
    #[arg(long, value_name = "DIR")]
    pub tuned: Vec<PathBuf>,
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
    /// Where the simulations run (as for `run`).
    #[command(flatten)]
    pub executor: cmd_run::ExecutorArgs,
}

/// Stage timings, seconds, in order.
type Timings = Vec<(String, f64)>;

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let started = Instant::now();
    // `--executor slurm` without Slurm is an error now, not a warning per batch.
    args.executor.executor()?;
    let data = study_recordings(&args.data)?;
    let scenes: Vec<PathBuf> = if args.scenes.is_empty() {
        study_scene_files()
    } else {
        args.scenes.clone()
    };
    let engines: Vec<String> = if args.engines.is_empty() {
        cmd_engines::compiled()
            .iter()
            .map(|e| e.name().to_string())
            .collect()
    } else {
        args.engines.clone()
    };
    if engines.is_empty() {
        bail!("no physics engine is compiled into this binary");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let runs_dir = args.out.join("runs");
    let mut timings: Timings = Vec::new();

    let tuned: Vec<TunedEngine> = args
        .tuned
        .iter()
        .map(|d| TunedEngine::from_dir(d))
        .collect::<Result<_>>()?;
    let t = Instant::now();
    let mut problems = simulate(&args, &scenes, &engines, &runs_dir, None);
    for te in &tuned {
        problems.extend(simulate(
            &args,
            &scenes,
            std::slice::from_ref(&te.engine),
            &runs_dir.join(&te.runs_subdir),
            Some(&te.params),
        ));
    }
    timings.push(("simulate".into(), t.elapsed().as_secs_f64()));

    eprintln!("[2/3] comparing");
    let t = Instant::now();
    let (mut study, study_path, roots) =
        reproduction_study(&scenes, data.as_deref(), &args.out, &runs_dir, &engines)?;
    for s in &mut study.scenes {
        for te in &tuned {
            s.sources.extend(te.source(&runs_dir, &s.name)?);
        }
    }
    let opts = CompareOptions {
        mode: args.mode,
        ..CompareOptions::default()
    };
    let reports = evaluate(&study, &roots, &opts)?;
    timings.push(("compare".into(), t.elapsed().as_secs_f64()));
    print!("{}", table::render(&reports, Format::Markdown));
    if args.joint_space {
        if data.is_none() {
            bail!("--joint-space needs the real arm's recordings (leave --data out, or give a folder)");
        }
        let t = Instant::now();
        let measure = realitygap_study::Measure {
            runs: args.runs.clone(),
            holdout: args.holdout.clone(),
            ..realitygap_study::Measure::default()
        };
        let tables = realitygap_study::joint_space::study_tables(&study, &roots, &measure)?;
        let md = realitygap_study::joint_space::markdown(&tables);
        std::fs::write(args.out.join("joint_space.md"), &md)?;
        std::fs::write(
            args.out.join("joint_space.json"),
            serde_json::to_string_pretty(&tables)? + "\n",
        )?;
        print!("\n{md}");
        timings.push(("joint space".into(), t.elapsed().as_secs_f64()));
    }

    eprintln!("[3/3] writing the report");
    let t = Instant::now();
    let index_html = write_report(&args, &reports, &study, &study_path, &roots)?;
    timings.push(("report".into(), t.elapsed().as_secs_f64()));

    timings.push(("total".into(), started.elapsed().as_secs_f64()));
    write_timings(&args.out, &timings)?;
    eprintln!("report: {}", index_html.display());
    if !problems.is_empty() {
        bail!(
            "the study finished, but not every simulation did: {}",
            problems.join("; ")
        );
    }
    Ok(())
}

/// Stage 1: every scene in every engine, `--repeats` times, into
/// `runs_dir`, exactly as `realitygap run` does. Failed runs are listed in
/// the report and the comparison goes on with the runs that finished, so
/// a failure is a problem to report at the end, not an error now.
fn simulate(
    args: &Args,
    scenes: &[PathBuf],
    engines: &[String],
    runs_dir: &Path,
    params: Option<&Path>,
) -> Vec<String> {
    eprintln!(
        "[1/3] simulating {} scenes x {} engines ({}) x {} repeats -> {}",
        scenes.len(),
        engines.len(),
        engines.join(", "),
        args.repeats,
        runs_dir.display()
    );
    let run_args = cmd_run::Args {
        scenes: scenes.to_vec(),
        engines: engines.to_vec(),
        repeats: args.repeats,
        out: runs_dir.to_path_buf(),
        robot: None,
        packages: vec![],
        jobs: args.jobs,
        seed: 0,
        perturb: vec![],
        set: vec![],
        timeout_s: args.timeout_s,
        params: params
            .map(Path::to_path_buf)
            .or_else(|| args.params.clone()),
        stitch: None,
        allow_unstable: false,
        executor: args.executor.clone(),
    };
    match cmd_run::run(run_args) {
        Ok(()) => Vec::new(),
        Err(e) => {
            eprintln!("warning: {e:#}");
            vec![format!("{e:#}")]
        }
    }
}

/// Stage 3: tables, figures and `OUT/report/index.html`, with the
/// provenance of every source and of this command; the page's path.
fn write_report(
    args: &Args,
    reports: &[SceneReport],
    study: &Study,
    study_path: &Path,
    roots: &Roots,
) -> Result<PathBuf> {
    let mut provenance = provenance_for_study(study, study_path, roots, args.mode);
    provenance.details.extend(args.data.provenance());
    provenance.details.push((
        "Command".into(),
        std::env::args().collect::<Vec<_>>().join(" "),
    ));
    provenance.details.push((
        "Repeats per scene and engine".into(),
        args.repeats.to_string(),
    ));
    let report_dir = args.out.join("report");
    let files = realitygap_report::write_report(reports, &provenance, &report_dir)
        .with_context(|| format!("writing the report into {}", report_dir.display()))?;
    Ok(files.index_html)
}

/// Writes `OUT/timings.json` and says the timings on standard error.
fn write_timings(out: &Path, timings: &Timings) -> Result<()> {
    let timing_json: serde_json::Map<String, serde_json::Value> = timings
        .iter()
        .map(|(k, v)| (format!("{k}_s"), serde_json::json!(v)))
        .collect();
    std::fs::write(
        out.join("timings.json"),
        serde_json::to_string_pretty(&timing_json)? + "\n",
    )
    .with_context(|| format!("cannot write {}", out.join("timings.json").display()))?;
    eprintln!(
        "stage timings: {}",
        timings
            .iter()
            .map(|(k, v)| format!("{k} {v:.1} s"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
