//! `realitygap tune`: an engine calibrated against a study's real runs or
//! a robot's own recorded episodes (the work is `realitygap-tune`'s; this
//! is the sequence the command and the Python package share: options,
//! settings, the progress bar, the summary).

use crate::ui::Ui;
use anyhow::{Context, Result};
use realitygap_analysis::selection::RunRange;
use realitygap_core::engine::EngineSettings;
use realitygap_core::params::PhysicalParams;
use realitygap_runner::prepare::{engine_names, find_engine, overrides_for};
use realitygap_runner::slurm::Executor;
use realitygap_runner::Launcher;
use realitygap_runner::Registry;
use realitygap_study::data_source::assets_dir;
use realitygap_study::toss_study::is_toss_study;
use realitygap_study::{load_study, DataSource};
use realitygap_tune::objective::{Simulator, Target};
use realitygap_tune::search::SearchOptions;
use realitygap_tune::slurm_batch::Gatherer;
use realitygap_tune::space::Space;
use realitygap_tune::{default_space_file, TuneSpec};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `tune` does (its options).
#[derive(Debug, Clone)]
pub struct TuneRequest {
    /// The study file (not with `recordings`).
    pub study: Option<PathBuf>,
    /// A results directory of recorded episodes (not with `study`).
    pub recordings: Option<PathBuf>,
    /// With `recordings`: known parameters, never searched.
    pub params: Option<PathBuf>,
    /// With `recordings`: a replay scene instead of the generated one.
    pub scene: Option<PathBuf>,
    /// With `recordings`: fit the recorded efforts too.
    pub efforts: bool,
    /// Levenberg-Marquardt iterations at most: the Jacobians each fit of
    /// `recordings` computes by differences (default 30), each round of the study tune's polish (default 10).
    pub iterations: Option<usize>,
    /// The study's recordings.
    pub data: DataSource,
    /// The engine to tune.
    pub engine: String,
    /// Output folder (a rerun resumes in it).
    pub out: PathBuf,
    /// Parameter space; default `assets/tuning/<engine>.toml`.
    pub space: Option<PathBuf>,
    /// Runs (or episodes) to fit on.
    pub runs: Option<String>,
    /// Runs to score on and never fit on.
    pub holdout: Option<String>,
    /// Cross-validate over this many folds of consecutive real runs
    /// (not with `runs` or `holdout`).
    pub folds: Option<usize>,
    /// Evaluations (default 600; a study of tosses: the study file's).
    pub budget: Option<usize>,
    /// Seed of the search.
    pub seed: u64,
    /// Restart a stalled search (IPOP-CMA-ES).
    pub restarts: bool,
    /// Parallel evaluations (default: the number of cores).
    pub jobs: Option<usize>,
    /// Weight of the cube's final pose error (position, and turn times
    /// half the cube's edge).
    pub cube_weight: f64,
    /// Keep the measurement's registration estimate.
    pub keep_registration: bool,
    /// Leave out the physics-free model behind its own fitted actuator
    /// stage (its fit costs about what the engine's does).
    pub no_baseline: bool,
    /// Start the engine's search at the physics-free model's fitted
    /// actuator stage and registration (fitted first).
    pub start_from_baseline: bool,
    /// Pull the engine's keys that the physics-free model's fit shares
    /// toward its fitted values ([`TuneSpec::prior_weight`]); 0: none.
    pub prior_weight: f64,
    /// Engine settings over the space's (a parameters file).
    pub settings: Option<PathBuf>,
    /// Engine settings over the space's and `settings`: KEY=VALUE.
    pub set: Vec<String>,
    /// Robot instead of the scenes'.
    pub robot: Option<String>,
    /// Where ROS packages are: NAME=DIR.
    pub packages: Vec<String>,
    /// Where the simulations run.
    pub executor: Executor,
    /// Say the whole summary (parameters, sensitivity) on standard output,
    /// not only its scores; it is always in OUT/summary.md.
    pub verbose: bool,
}

impl Default for TuneRequest {
    fn default() -> Self {
        TuneRequest {
            study: None,
            recordings: None,
            params: None,
            scene: None,
            efforts: false,
            iterations: None,
            data: DataSource::Builtin,
            engine: String::new(),
            out: PathBuf::from("tune"),
            space: None,
            runs: None,
            holdout: None,
            folds: None,
            budget: None,
            seed: 1,
            restarts: false,
            jobs: None,
            cube_weight: realitygap_tune::objective::CUBE_WEIGHT_PER_STEP,
            keep_registration: false,
            no_baseline: false,
            start_from_baseline: false,
            prior_weight: 0.0,
            settings: None,
            set: Vec::new(),
            robot: None,
            packages: Vec::new(),
            executor: Executor::Local,
            verbose: false,
        }
    }
}

/// What a tune made.
pub struct Tuned {
    /// The summary in Markdown (as printed).
    pub markdown: String,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Evaluation threads with `--executor slurm`: enough for every candidate
/// of a generation to wait on its array at once (CMA-ES's population is
/// 4 + 3 ln n, 17 for 60 parameters).
const SLURM_THREADS: usize = 64;

/// The study tune's evaluations when `--budget` is not given.
pub const STUDY_BUDGET: usize = 600;

/// The cores of this machine.
pub(crate) fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// A run range option, parsed.
fn range(v: &Option<String>, flag: &str) -> Result<Option<RunRange>> {
    Ok(match v {
        Some(v) => Some(RunRange::parse(v, flag)?),
        None => None,
    })
}

/// The options of a study tune that differ from the defaults, as typed,
/// to name a cross-validation among others of the same engine.
///
/// Every field of the request is named below, without `..`: a new option
/// does not compile until it is either written into the label or said
/// not to change the fit.
fn non_default_options(args: &TuneRequest) -> Vec<String> {
    let TuneRequest {
        // What is tuned, on which runs, where it goes: the run's identity,
        // named by the cross-validation itself.
        study: _,
        data: _,
        engine: _,
        out: _,
        runs: _,
        holdout: _,
        folds: _,
        // Where and how verbosely it runs: the same fit.
        jobs: _,
        executor: _,
        verbose: _,
        // A recordings tune's options, refused with a study.
        recordings: _,
        params: _,
        scene: _,
        efforts: _,
        robot: _,
        packages: _,
        // Leaves a row out of the comparison; the engine's fit is the same.
        no_baseline: _,
        space,
        settings,
        set,
        cube_weight,
        start_from_baseline,
        prior_weight,
        keep_registration,
        budget,
        iterations,
        seed,
        restarts,
    } = args;
    let d = TuneRequest::default();
    let mut o = Vec::new();
    if let Some(s) = space {
        o.push(format!("--space {}", s.display()));
    }
    if let Some(s) = settings {
        o.push(format!("--settings {}", s.display()));
    }
    o.extend(set.iter().map(|s| format!("--set {s}")));
    if *cube_weight != d.cube_weight {
        o.push(format!("--cube-weight {cube_weight}"));
    }
    if *start_from_baseline {
        o.push("--start physics-free".into());
    }
    if *prior_weight > 0.0 {
        o.push(format!("--prior-weight {prior_weight}"));
    }
    if *keep_registration {
        o.push("--keep-registration".into());
    }
    if let Some(b) = budget {
        o.push(format!("--budget {b}"));
    }
    if let Some(i) = iterations {
        o.push(format!("--iterations {i}"));
    }
    if *seed != d.seed {
        o.push(format!("--seed {seed}"));
    }
    if *restarts {
        o.push("--restarts".into());
    }
    o
}

/// Runs the tune `request` asks for; says the summary on `ui`.
pub fn tune(request: &TuneRequest, launcher: &Launcher, ui: &dyn Ui) -> Result<Tuned> {
    if !request.prior_weight.is_finite() || request.prior_weight < 0.0 {
        anyhow::bail!(
            "--prior-weight {}: expected a finite number >= 0",
            request.prior_weight
        );
    }
    if request.budget == Some(0) {
        anyhow::bail!("--budget 0: a tune needs at least one evaluation");
    }
    if request.prior_weight > 0.0 && request.recordings.is_some() {
        anyhow::bail!("--prior-weight belongs to a tune against a study's real runs (it pulls toward the physics-free model's fit): leave it out with --recordings");
    }
    if let Some(recordings) = &request.recordings {
        return tune_recordings(request, recordings, ui);
    }
    if let Some(study) = request.study.as_deref().filter(|s| is_toss_study(s)) {
        if request.prior_weight > 0.0 {
            anyhow::bail!("--prior-weight pulls an arm's tune toward the physics-free model's fit; a study of tosses has none: leave it out");
        }
        return crate::tune_tosses::tune_tosses(request, study, ui);
    }
    let args = request;
    let budget = args.budget.unwrap_or(STUDY_BUDGET);
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
    let registry = crate::engines;
    let engine = find_engine(registry, &args.engine)?;
    let space_file = args
        .space
        .clone()
        .unwrap_or_else(|| default_space_file(&assets_dir(), engine.name()));
    let space = Space::from_file(&space_file)?;
    let set = settings_over(args, engine.name(), registry)?;
    let (study, roots) = load_study(&study_file, &args.data, None)?;
    let target_for = |runs: Option<RunRange>, holdout: Option<RunRange>| {
        Target::new(&study, &roots, runs, holdout, args.cube_weight)
            .with_context(|| format!("study {}", study_file.display()))
    };
    let gatherer = match &args.executor {
        Executor::Slurm(opts) => Some(std::sync::Arc::new(Gatherer::new(
            launcher.clone(),
            opts.clone(),
            args.out.join(".slurm"),
        ))),
        Executor::Local => None,
    };
    let jobs = match gatherer {
        Some(_) => SLURM_THREADS,
        None => args.jobs.unwrap_or_else(cores),
    };
    let spec = TuneSpec {
        engine: engine.name().to_string(),
        fit_registration: !args.keep_registration && space.registration.is_some(),
        space,
        set,
        search: SearchOptions {
            budget,
            seed: args.seed,
            jobs,
            restarts: args.restarts,
            stall_m: None,
        },
        out: args.out.clone(),
        polish: realitygap_tune::polish::PolishOptions {
            iterations: args.iterations.unwrap_or(10),
            // The polish spends about what the search did.
            max_evaluations: budget,
            ..Default::default()
        },
        baseline_space: if engine.name() == realitygap_tune::outputs::PHYSICS_FREE
            || args.no_baseline
        {
            None
        } else {
            let f = default_space_file(&assets_dir(), realitygap_tune::outputs::PHYSICS_FREE);
            Some(Space::from_file(&f)?)
        },
        start_from_baseline: args.start_from_baseline,
        prior_weight: args.prior_weight,
        prior: Vec::new(),
    };
    ui.note(settings_line(&spec, &space_file));
    let simulator = Simulator {
        launcher: launcher.clone(),
        engine: spec.engine.clone(),
        robot: args.robot.clone(),
        packages: args.packages.clone(),
        slurm: gatherer.clone(),
    };
    if let Some(k) = args.folds {
        return cross_validate(args, k, &target_for, &simulator, &spec, ui);
    }
    let target = target_for(
        range(&args.runs, "--runs")?,
        range(&args.holdout, "--holdout")?,
    )?;
    let result = tune_with_bar(&target, &simulator, &spec, ui, "")?;
    let markdown = realitygap_tune::outputs::markdown(&result.summary);
    ui.say(shortened(&markdown, args.verbose, &args.out));
    let mut files = result.files;
    files.push(args.out.join("history.csv"));
    say_files(ui, &files);
    Ok(Tuned { markdown, files })
}

/// One study tune with its progress bar (`label` before the bar's
/// message: which fold).
fn tune_with_bar(
    target: &Target,
    simulator: &Simulator,
    spec: &TuneSpec,
    ui: &dyn Ui,
    label: &str,
) -> Result<realitygap_tune::TuneResult> {
    let bar = ui.bar(spec.search.budget as u64, "evaluations");
    let started = Instant::now();
    let on_progress = |p: realitygap_tune::search::Progress| {
        bar.set_position(p.done as u64);
        let fresh = p.done.saturating_sub(p.replayed);
        bar.set_message(format!(
            "{label}best {:.4} m, {:.2} evaluations/s{}",
            p.best,
            fresh as f64 / started.elapsed().as_secs_f64().max(1e-9),
            if p.replayed > 0 {
                format!(" ({} replayed)", p.replayed)
            } else {
                String::new()
            }
        ));
    };
    let on_note = |line: String| bar.println(line);
    let result = realitygap_tune::tune(target, simulator, spec, &on_progress, &on_note);
    bar.finish();
    result
}

fn say_files(ui: &dyn Ui, files: &[PathBuf]) {
    ui.note("\nwrote:".into());
    for f in files {
        ui.note(format!("  {}", f.display()));
    }
}

/// `tune --folds K`: the tune run once per fold of consecutive real runs,
/// each fold held out once, into `OUT/fold-N`; the held-out scores
/// gathered into `OUT/crossval.md` and `OUT/crossval.json`.
fn cross_validate(
    args: &TuneRequest,
    k: usize,
    target_for: &dyn Fn(Option<RunRange>, Option<RunRange>) -> Result<Target>,
    simulator: &Simulator,
    spec: &TuneSpec,
    ui: &dyn Ui,
) -> Result<Tuned> {
    use realitygap_tune::crossval;
    for (given, flag) in [
        (args.runs.is_some(), "--runs"),
        (args.holdout.is_some(), "--holdout"),
    ] {
        if given {
            anyhow::bail!("{flag} does not go with --folds: the folds choose the runs to fit on and to hold out");
        }
    }
    let runs = target_for(None, None)?.run_count();
    let folds = crossval::folds(runs, k)?;
    let mut summaries = Vec::new();
    let mut folders = Vec::new();
    let mut files = Vec::new();
    for f in &folds {
        let holdout = RunRange::parse(&f.holdout, "--holdout")?;
        let held = (1..=runs).filter(|r| holdout.contains(*r)).count();
        ui.note(format!(
            "fold {} of {k}: runs {} held out, the other {} fitted on",
            f.number,
            f.holdout,
            runs - held
        ));
        let target = target_for(None, Some(holdout))?;
        let out = args.out.join(format!("fold-{}", f.number));
        let fold_spec = TuneSpec {
            out: out.clone(),
            ..spec.clone()
        };
        let label = format!("fold {}/{k}: ", f.number);
        let result = tune_with_bar(&target, simulator, &fold_spec, ui, &label)?;
        ui.note(format!("  fold {}: {}", f.number, result.summary.verdict));
        folders.push(out.display().to_string());
        files.push(out.join("summary.md"));
        summaries.push(result.summary);
    }
    let mut cv = crossval::gather(&spec.engine, runs, &folds, &folders, &summaries)?;
    cv.options = non_default_options(args);
    let markdown = crossval::markdown(&cv);
    let written = crossval::write(&cv, &args.out)?;
    ui.say(markdown.trim_end().to_string());
    files.splice(0..0, written);
    say_files(ui, &files);
    Ok(Tuned { markdown, files })
}

/// The engine settings of `--settings` (its `[engine.NAME]` table) with
/// `--set` over them.
fn settings_over(args: &TuneRequest, engine: &str, registry: Registry) -> Result<EngineSettings> {
    let mut set = match &args.settings {
        Some(f) => PhysicalParams::from_file(f)?
            .engine_settings
            .remove(engine)
            .with_context(|| format!("--settings {}: no [engine.{engine}] table", f.display()))?,
        None => Default::default(),
    };
    set.extend(overrides_for(&args.set, engine, &engine_names(registry))?);
    Ok(set)
}

/// `tune --recordings`: the engine fitted to a robot's own episodes in
/// joint space.
fn tune_recordings(args: &TuneRequest, recordings: &Path, ui: &dyn Ui) -> Result<Tuned> {
    use realitygap_tune::recordings::{
        summary_markdown, tune_recordings, write_summary, RecordingsSpec,
    };
    if !matches!(args.executor, Executor::Local) {
        anyhow::bail!("--recordings runs on this machine only (--executor local)");
    }
    let engine = find_engine(crate::engines, &args.engine)?;
    let mut known =
        realitygap_runner::prepare::read_params_checked(crate::engines, args.params.as_deref())?;
    // --settings and --set over the scene's and --params' settings: the
    // replay takes the engine settings of the known parameters.
    let set = settings_over(args, engine.name(), crate::engines)?;
    if !set.is_empty() {
        known
            .engine_settings
            .entry(engine.name().to_string())
            .or_default()
            .extend(set);
    }
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
    if let Some(w) = prepared.held_warning() {
        ui.note(format!("warning: {w}"));
    }
    for w in prepared.partial_gain_warnings(&known) {
        ui.note(format!("warning: {w}"));
    }
    let space = match &args.space {
        Some(f) => Some(Space::from_file(f)?),
        None => None,
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
        jobs: args.jobs.unwrap_or_else(cores),
        max_iterations: args.iterations.unwrap_or(30),
        use_efforts: args.efforts,
    };
    ui.note(format!(
        "tuning {} against {} recorded episodes of robot '{}' in joint space",
        engine.name(),
        prepared.episodes.len(),
        prepared.robot.name
    ));
    let bar = ui.bar(0, "evaluations");
    let on_progress = |p: realitygap_tune::recordings::RecordingsProgress| {
        bar.set_position(p.evaluations as u64);
        bar.set_message(format!(
            "{}; best training RMS {:.4} deg",
            p.phase, p.best_rms_deg
        ));
    };
    let result = tune_recordings(&spec, &on_progress);
    bar.finish();
    let mut result = result?;
    write_summary(&args.out, recordings, &mut result)?;
    let markdown = summary_markdown(&result.summary);
    ui.say(shortened(&markdown, args.verbose, &args.out));
    say_files(ui, &result.files);
    Ok(Tuned {
        markdown,
        files: result.files.clone(),
    })
}

/// Which settings the tune runs at, and where they come from.
fn settings_line(spec: &TuneSpec, space_file: &Path) -> String {
    let mut in_force = spec
        .space
        .settings
        .get(&spec.engine)
        .cloned()
        .unwrap_or_default();
    in_force.extend(spec.set.clone());
    let settings: Vec<String> = in_force.iter().map(|(k, v)| format!("{k}={v}")).collect();
    format!(
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
    )
}

/// The summary for the terminal: everything before its parameters section
/// (the search, the scores, the verdict) and where the rest is; all of it
/// with `verbose`.
fn shortened(markdown: &str, verbose: bool, out: &Path) -> String {
    let full = markdown.trim_end_matches('\n');
    if verbose {
        return full.to_string();
    }
    match full.find("\n## Parameters") {
        Some(at) => format!(
            "{}\n\nThe parameters with their bounds, intervals and sensitivity: {} (or --verbose).",
            full[..at].trim_end(),
            out.join("summary.md").display()
        ),
        None => full.to_string(),
    }
}
