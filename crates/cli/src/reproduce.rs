//! `realitygap reproduce`: the whole study in one call.
//!
//! Stages, each timed:
//! 1. **simulate**: the three study scenes in every compiled engine,
//!    `repeats` times each (20 by default), into `OUT/runs/` exactly as
//!    `realitygap run` does (parallel, resumable);
//! 2. **compare**: against the real arm's recordings, next to the study's
//!    recorded simulators (MuJoCo 1.5, PyBullet 2.1 and the V-Rep engines),
//!    from the recordings built in or `--data DIR`; with `--data none`, the
//!    engines against each other (the reference is the first engine, MuJoCo
//!    when compiled in);
//! 3. **report**: tables, figures and `OUT/report/index.html`.
//!
//! A rerun skips the finished simulations and redoes the (fast) rest.
//! Shared by the command and the Python package.

use crate::ui::Ui;
use anyhow::{bail, Context, Result};
use realitygap_analysis::compare::{AnalysisMode, CompareOptions, SceneReport};
use realitygap_analysis::table::{self, Format};
use realitygap_report::html::ExtraSection;
use realitygap_runner::slurm::Executor;
use realitygap_runner::{BatchSpec, Launcher};
use realitygap_study::provenance::provenance_for_study;
use realitygap_study::reproduce::{
    reproduction_study, study_recordings, study_scene_files, TunedEngine,
};
use realitygap_study::{evaluate, DataSource, Roots, Study};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `reproduce` does (its options).
#[derive(Debug, Clone)]
pub struct ReproduceRequest {
    /// The study's recordings: built in, none, or a folder.
    pub data: DataSource,
    /// Output folder: runs/, report/, tables and timings.json.
    pub out: PathBuf,
    /// Runs per scene and engine.
    pub repeats: u32,
    /// Engines; empty: every engine compiled in.
    pub engines: Vec<String>,
    /// Scene files; empty: the study's three scenes.
    pub scenes: Vec<PathBuf>,
    /// Simulations at a time (default: the number of cores).
    pub jobs: Option<usize>,
    /// The analysis mode.
    pub mode: AnalysisMode,
    /// Give up on a simulation after this many seconds.
    pub timeout_s: Option<f64>,
    /// Physical parameters for every engine's runs.
    pub params: Option<PathBuf>,
    /// Output folders of `realitygap tune`: each engine again with its
    /// tuned.toml, as "`<engine> (tuned)`".
    pub tuned: Vec<PathBuf>,
    /// Output folders of `realitygap tune --folds K`: the report's verdict
    /// opens with whether any tuned engine beats the physics-free model
    /// behind its fitted actuator stage on runs it did not see, and a
    /// section holds their table and figures.
    pub crossval: Vec<PathBuf>,
    /// Also compare in joint space.
    pub joint_space: bool,
    /// With `joint_space`: the real runs to fit the IK registration on.
    pub runs: Option<String>,
    /// With `joint_space`: the real runs to score on.
    pub holdout: Option<String>,
    /// Where the simulations run.
    pub executor: Executor,
    /// Also replay the cube tosses built in (the second study,
    /// contactnets2020) in every engine beside the physics-free row, into
    /// `OUT/tosses/` (not with `data` none).
    pub tosses: bool,
    /// The command line, for the report's provenance.
    pub command: String,
    /// Say everything: a line per scene and engine, and the full tables
    /// (every measure and flagged run) instead of the summary.
    pub verbose: bool,
}

impl Default for ReproduceRequest {
    fn default() -> Self {
        ReproduceRequest {
            data: DataSource::Builtin,
            out: PathBuf::from("results"),
            repeats: 20,
            engines: Vec::new(),
            scenes: Vec::new(),
            jobs: None,
            mode: AnalysisMode::Default,
            timeout_s: None,
            params: None,
            tuned: Vec::new(),
            crossval: Vec::new(),
            joint_space: false,
            runs: None,
            holdout: None,
            executor: Executor::Local,
            tosses: true,
            command: String::new(),
            verbose: false,
        }
    }
}

/// What `reproduce` made.
pub struct Reproduced {
    /// Per scene, the comparison.
    pub reports: Vec<SceneReport>,
    /// The table in Markdown (as printed).
    pub table: String,
    /// The toss table in Markdown, when the tosses were replayed.
    pub tosses: Option<String>,
    /// The joint-space tables in Markdown, when asked for.
    pub joint_space: Option<String>,
    /// `OUT/report/index.html`.
    pub index_html: PathBuf,
    /// Stage timings, seconds, in order.
    pub timings: Vec<(String, f64)>,
    /// The simulations that did not all finish (the study went on).
    pub problems: Vec<String>,
}

/// Runs the study; says the table (and the joint-space tables) on `ui`.
/// An error after the report when not every simulation finished.
pub fn reproduce(
    request: &ReproduceRequest,
    launcher: &Launcher,
    ui: &dyn Ui,
) -> Result<Reproduced> {
    let done = reproduce_keeping_problems(request, launcher, ui)?;
    if !done.problems.is_empty() {
        bail!(
            "the study finished, but not every simulation did: {}",
            done.problems.join("; ")
        );
    }
    Ok(done)
}

/// [`reproduce`], the unfinished simulations returned instead of an error.
pub fn reproduce_keeping_problems(
    request: &ReproduceRequest,
    launcher: &Launcher,
    ui: &dyn Ui,
) -> Result<Reproduced> {
    let args = request;
    let started = Instant::now();
    let data = study_recordings(&args.data)?;
    let scenes: Vec<PathBuf> = if args.scenes.is_empty() {
        study_scene_files()
    } else {
        args.scenes.clone()
    };
    let engines: Vec<String> = if args.engines.is_empty() {
        let missing: Vec<&str> = realitygap_engine_remote::registry::ADAPTERS
            .iter()
            .filter(|a| !realitygap_engine_remote::registry::is_installed(a))
            .map(|a| a.name)
            .collect();
        if !missing.is_empty() {
            println!(
                "engines out of process not installed, left out: {} (each adds with `{}`)",
                missing.join(", "),
                realitygap_engine_remote::registry::install_line("NAME")
            );
        }
        crate::engines()
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
    let mut timings: Vec<(String, f64)> = Vec::new();

    // Each tune, and the physics-free row fitted beside it (both rows of
    // the physics-free model then show, untuned and tuned).
    let tuned =
        TunedEngine::with_physics_free(&args.tuned, realitygap_tune::outputs::PHYSICS_FREE_DIR)?;
    // Read before the long work, so a wrong folder fails at once.
    let crossval = crate::compare::crossval_section(&args.crossval)?;
    let t = Instant::now();
    let mut problems = simulate(args, &scenes, &engines, &runs_dir, None, launcher, ui)?;
    for te in &tuned {
        problems.extend(simulate(
            args,
            &scenes,
            std::slice::from_ref(&te.engine),
            &runs_dir.join(&te.runs_subdir),
            Some(&te.params),
            launcher,
            ui,
        )?);
    }
    timings.push(("simulate".into(), t.elapsed().as_secs_f64()));

    ui.note("[2/3] comparing".into());
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
    let table = table::render(&reports, Format::Markdown);
    if args.verbose {
        ui.say(table.trim_end_matches('\n').to_string());
    } else {
        ui.say(table::summary(&reports).trim_end_matches('\n').to_string());
    }
    let physics_free = realitygap_core::engine::PHYSICS_FREE_ENGINE;
    if data.is_some()
        && !engines.iter().any(|e| e == physics_free)
        && !tuned.iter().any(|t| t.engine == physics_free)
    {
        // The closest source named above is then the closest engine, not
        // the closest model: say what the table lacks.
        ui.say(format!(
            "The physics-free model was not run, so the table has no baseline: add --engine {physics_free} to see whether an engine beats perfect tracking."
        ));
    }
    let mut joint_space = None;
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
        ui.say(format!("\n{}", md.trim_end_matches('\n')));
        joint_space = Some(md);
        timings.push(("joint space".into(), t.elapsed().as_secs_f64()));
    }

    let mut tosses = None;
    let mut sections = Vec::new();
    if args.tosses && data.is_some() {
        let t = Instant::now();
        let (md, line, failed, section) = replay_builtin_tosses(args, &engines, ui)?;
        problems.extend(failed);
        sections.push(section);
        if args.verbose {
            ui.say(format!("\n{}", md.trim_end_matches('\n')));
        } else {
            ui.say(line);
        }
        tosses = Some(md);
        timings.push(("tosses".into(), t.elapsed().as_secs_f64()));
    }

    sections.extend(crossval);
    ui.note("[3/3] writing the report".into());
    let t = Instant::now();
    let index_html = write_report(args, &reports, &study, &study_path, &roots, &sections)?;
    timings.push(("report".into(), t.elapsed().as_secs_f64()));

    timings.push(("total".into(), started.elapsed().as_secs_f64()));
    write_timings(&args.out, &timings, ui)?;
    ui.say(format!(
        "\nreport: {}\ntables: {} (every measure and flagged run; also .csv, .json, .tex)\nruns: {}",
        index_html.display(),
        index_html.with_file_name("table.md").display(),
        runs_dir.display()
    ));
    Ok(Reproduced {
        reports,
        table,
        tosses,
        joint_space,
        index_html,
        timings,
        problems,
    })
}

/// Stage 1: every scene in every engine, `repeats` times, into
/// `runs_dir`, exactly as `realitygap run` does. Failed runs are listed in
/// the report and the comparison goes on with the runs that finished, so
/// a failure is a problem to report at the end, not an error now (an
/// interruption is an error).
fn simulate(
    args: &ReproduceRequest,
    scenes: &[PathBuf],
    engines: &[String],
    runs_dir: &Path,
    params: Option<&Path>,
    launcher: &Launcher,
    ui: &dyn Ui,
) -> Result<Vec<String>> {
    ui.note(format!(
        "[1/3] simulating {} scenes x {} engines ({}) x {} repeats -> {}",
        scenes.len(),
        engines.len(),
        engines.join(", "),
        args.repeats,
        runs_dir.display()
    ));
    let spec = BatchSpec {
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
    };
    let outcome = crate::batch::run(spec, args.executor.clone(), launcher, ui).and_then(|o| {
        let lines = if args.verbose {
            o.summary()
        } else {
            o.short_summary()
        };
        for line in lines {
            ui.say(line);
        }
        o.check()
    });
    match outcome {
        Ok(()) => Ok(Vec::new()),
        Err(e) if realitygap_runner::interrupt::is_interrupted(&e) => Err(e),
        Err(e) => {
            ui.note(format!("warning: {e:#}"));
            Ok(vec![format!("{e:#}")])
        }
    }
}

/// The second study: the cube tosses built in replayed in `engines` (the
/// physics-free one as the ballistic row) at their defaults into
/// `OUT/tosses/`; the table, the summary's line, the tosses that failed as
/// problems, and the report's section.
fn replay_builtin_tosses(
    args: &ReproduceRequest,
    engines: &[String],
    ui: &dyn Ui,
) -> Result<(String, String, Vec<String>, ExtraSection)> {
    use realitygap_study::toss_study::TossStudy;
    use realitygap_study::tosses::{replay_tosses, toss_markdown};
    let file = realitygap_study::data_source::assets_dir().join(CONTACTNETS_STUDY);
    let study = TossStudy::from_file(&file)?;
    let set = study.load(&DataSource::Builtin)?;
    let mut chosen = Vec::new();
    for name in engines {
        let engine = realitygap_runner::prepare::find_engine(crate::engines, name)?;
        if engine.name() != realitygap_core::engine::PHYSICS_FREE_ENGINE {
            chosen.push(engine);
        }
    }
    let refs: Vec<&dyn realitygap_core::Engine> = chosen.iter().map(|e| e.as_ref()).collect();
    ui.note(format!(
        "tosses: {} real cube tosses ({}) in {} engines and the physics-free row",
        set.tosses.len(),
        study.name,
        refs.len()
    ));
    let jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let bar = ui.bar((refs.len() * set.tosses.len()) as u64, "tosses");
    let out = args.out.join("tosses");
    let rows = replay_tosses(
        &refs,
        &set,
        &realitygap_core::PhysicalParams::default(),
        &out,
        jobs,
        &|engine, id, failed| {
            bar.inc(1);
            if let Some(why) = failed {
                bar.println(format!("toss {id} in {engine}: failed: {why}"));
            }
        },
    )?;
    bar.finish();
    let failed = rows
        .iter()
        .filter(|r| r.tosses < set.tosses.len())
        .map(|r| {
            format!(
                "{} of {} tosses failed in {} (see {})",
                set.tosses.len() - r.tosses,
                set.tosses.len(),
                r.source,
                out.join(&r.source).join("manifest.json").display()
            )
        })
        .collect();
    let mut sorted: Vec<_> = rows.iter().filter(|r| r.error_edges.is_some()).collect();
    sorted.sort_by(|a, b| {
        let e =
            |r: &realitygap_study::tosses::TossRow| r.error_edges.map_or(f64::INFINITY, |e| e.0);
        e(a).total_cmp(&e(b))
    });
    let line = format!(
        "tosses: {} real cube tosses, each engine at its defaults (the cube centre's mean error, cube edges): {}; the table: {}",
        set.tosses.len(),
        sorted
            .iter()
            .map(|r| {
                let name = if r.source == realitygap_core::engine::PHYSICS_FREE_ENGINE {
                    "physics-free"
                } else {
                    r.source.as_str()
                };
                format!("{name} {:.3}", r.error_edges.map_or(f64::NAN, |e| e.0))
            })
            .collect::<Vec<_>>()
            .join(", "),
        out.join("tosses.md").display()
    );
    let replay = realitygap_study::tosses::replay_scenes(&rows, &set, &out)?;
    let section = realitygap_study::tosses::report_section(
        &rows,
        &set,
        realitygap_study::tosses::ReplayedWith::Defaults,
        "tosses/tosses.md in the output folder",
        replay,
    );
    Ok((toss_markdown(&rows, &set), line, failed, section))
}

/// The second built-in study, in the assets folder.
pub const CONTACTNETS_STUDY: &str = "studies/contactnets2020.toml";

/// Stage 3: tables, figures and `OUT/report/index.html`, with the
/// provenance of every source and of this call, and `sections` (the
/// tosses') after the summary; the page's path.
fn write_report(
    args: &ReproduceRequest,
    reports: &[SceneReport],
    study: &Study,
    study_path: &Path,
    roots: &Roots,
    sections: &[ExtraSection],
) -> Result<PathBuf> {
    let mut provenance = provenance_for_study(study, study_path, roots, args.mode);
    provenance.details.extend(args.data.provenance());
    provenance
        .details
        .push(("Command".into(), args.command.clone()));
    provenance.details.push((
        "Repeats per scene and engine".into(),
        args.repeats.to_string(),
    ));
    let report_dir = args.out.join("report");
    let files = realitygap_report::write_report_with(reports, &provenance, &report_dir, sections)
        .with_context(|| format!("writing the report into {}", report_dir.display()))?;
    Ok(files.index_html)
}

/// Writes `OUT/timings.json` and notes the timings.
fn write_timings(out: &Path, timings: &[(String, f64)], ui: &dyn Ui) -> Result<()> {
    let timing_json: serde_json::Map<String, serde_json::Value> = timings
        .iter()
        .map(|(k, v)| (format!("{k}_s"), serde_json::json!(v)))
        .collect();
    std::fs::write(
        out.join("timings.json"),
        serde_json::to_string_pretty(&timing_json)? + "\n",
    )
    .with_context(|| format!("cannot write {}", out.join("timings.json").display()))?;
    ui.note(format!(
        "stage timings: {}",
        timings
            .iter()
            .map(|(k, v)| format!("{k} {v:.1} s"))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    Ok(())
}
