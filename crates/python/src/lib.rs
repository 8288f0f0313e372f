//! `realitygap._native`: the Python package's extension module, a thin
//! layer over the library crates as the `realitygap` command is one. Each
//! function takes the command's options as keyword arguments, runs the
//! same sequence as the command ([`realitygap::batch`],
//! [`realitygap::compare`], [`realitygap::replay`], [`realitygap::tune`],
//! [`realitygap::reproduce`]) and returns plain Python values (strings,
//! lists, dicts, bytes of `f64`) that the pure-Python layer
//! (`python/realitygap/`) turns into pandas and numpy objects.
//!
//! Long calls run on a thread of their own with the GIL released; the
//! calling thread passes their progress on to a Python reporter (a tqdm
//! bar) and checks for Ctrl-C every 0.1 s. On Ctrl-C it raises the
//! runner's interrupt flag ([`realitygap_runner::interrupt`]): the running
//! child processes are killed and not stored, the finished runs are kept,
//! and the call raises `KeyboardInterrupt`. Errors raise
//! `realitygap.RealityGapError` with the command's message (`error: ...`
//! less the prefix).
//!
//! The simulations of `run`, `replay`, `tune` and `reproduce` run in child
//! processes, as the command's do: `python -m realitygap._child`, the same
//! interpreter importing this module and running [`realitygap::run_one`].

use pyo3::exceptions::{PyException, PyKeyboardInterrupt};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use realitygap::ui::{Bar, Ui};
use realitygap_analysis::table::Format;
use realitygap_runner::slurm::Executor;
use realitygap_runner::{BatchSpec, Launcher, Progress};
use realitygap_study::{parse_mode, DataSource, Measure};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::Mutex;
use std::time::Duration;

pyo3::create_exception!(
    realitygap,
    RealityGapError,
    PyException,
    "An error of realitygap, with the message the command prints."
);

/// An error of a library crate as Python's exception, with the message
/// the command prints (its causes, none repeated).
fn py_err(e: anyhow::Error) -> PyErr {
    RealityGapError::new_err(realitygap::ui::error_text(&e))
}

/// What a long call tells its caller's thread.
enum Event {
    /// A new bar.
    Bar(u64, u64, String),
    /// Items done on a bar, and where to say that the reporter has seen
    /// them.
    Inc(u64, u64, mpsc::Sender<()>),
    /// A bar's position.
    Position(u64, u64),
    /// A bar's message.
    Message(u64, String),
    /// A bar is done.
    Finish(u64),
    /// A note (the command's standard error).
    Note(String),
    /// A line of the result (the command's standard output).
    Say(String),
}

/// The [`Ui`] of a long call: events sent to the calling thread.
struct ChannelUi {
    tx: mpsc::Sender<Event>,
    next: AtomicU64,
}

/// A bar of a [`ChannelUi`].
struct ChannelBar {
    tx: mpsc::Sender<Event>,
    id: u64,
}

impl Progress for ChannelBar {
    fn println(&self, line: String) {
        let _ = self.tx.send(Event::Note(line));
    }
    /// Waits until the calling thread has passed the items on to the
    /// reporter: a Ctrl-C or a reporter that raises there stops the work
    /// before its next run, not some runs later.
    fn inc(&self, n: u64) {
        let (seen_tx, seen) = mpsc::channel();
        if self.tx.send(Event::Inc(self.id, n, seen_tx)).is_ok() {
            let _ = seen.recv();
        }
    }
    fn set_message(&self, message: String) {
        let _ = self.tx.send(Event::Message(self.id, message));
    }
}

impl Bar for ChannelBar {
    fn set_position(&self, n: u64) {
        let _ = self.tx.send(Event::Position(self.id, n));
    }
    fn finish(&self) {
        let _ = self.tx.send(Event::Finish(self.id));
    }
}

impl Ui for ChannelUi {
    fn note(&self, line: String) {
        let _ = self.tx.send(Event::Note(line));
    }
    fn say(&self, line: String) {
        let _ = self.tx.send(Event::Say(line));
    }
    fn bar(&self, total: u64, unit: &str) -> Box<dyn Bar + '_> {
        let id = self.next.fetch_add(1, Ordering::SeqCst);
        let _ = self.tx.send(Event::Bar(id, total, unit.to_string()));
        Box::new(ChannelBar {
            tx: self.tx.clone(),
            id,
        })
    }
}

/// Passes one event on to the Python reporter (methods `bar(id, total,
/// unit)`, `inc(id, n)`, `position(id, n)`, `message(id, text)`,
/// `finish(id)`, `note(line)`, `say(line)`).
fn dispatch(reporter: &Bound<'_, PyAny>, event: Event) -> PyResult<()> {
    match event {
        Event::Bar(id, total, unit) => reporter.call_method1("bar", (id, total, unit)),
        Event::Inc(id, n, _) => reporter.call_method1("inc", (id, n)),
        Event::Position(id, n) => reporter.call_method1("position", (id, n)),
        Event::Message(id, m) => reporter.call_method1("message", (id, m)),
        Event::Finish(id) => reporter.call_method1("finish", (id,)),
        Event::Note(line) => reporter.call_method1("note", (line,)),
        Event::Say(line) => reporter.call_method1("say", (line,)),
    }
    .map(|_| ())
}

/// Runs `work` on a thread of its own with the GIL released, passing its
/// progress to `reporter` and checking for Ctrl-C (and other signals)
/// every 0.1 s. On Ctrl-C, or when the reporter raises, asks the work to
/// stop ([`realitygap_runner::interrupt::request`]), waits for it (its
/// finished runs stored, the cut ones not) and raises.
fn long_call<T: Send>(
    py: Python<'_>,
    reporter: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(&dyn Ui) -> anyhow::Result<T> + Send,
) -> PyResult<T> {
    realitygap_runner::interrupt::clear();
    let (tx, rx) = mpsc::channel::<Event>();
    let rx = Mutex::new(rx);
    let mut raised: Option<PyErr> = None;
    let result = std::thread::scope(|scope| {
        let worker = scope.spawn(move || {
            let ui = ChannelUi {
                tx,
                next: AtomicU64::new(0),
            };
            work(&ui)
        });
        loop {
            let next = py.detach(|| {
                rx.lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .recv_timeout(Duration::from_millis(100))
            });
            let event = match next {
                Ok(event) => Some(event),
                Err(mpsc::RecvTimeoutError::Timeout) => None,
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            };
            // Said to the work once the reporter has seen the items and
            // the signals are checked (see `ChannelBar::inc`).
            let seen = match &event {
                Some(Event::Inc(_, _, seen)) => Some(seen.clone()),
                _ => None,
            };
            if let (Some(event), Some(r)) = (event, reporter) {
                if let Err(e) = dispatch(r, event) {
                    if raised.is_none() {
                        realitygap_runner::interrupt::request();
                        raised = Some(e);
                    }
                }
            }
            if raised.is_none() {
                if let Err(e) = py.check_signals() {
                    realitygap_runner::interrupt::request();
                    raised = Some(e);
                }
            }
            if let Some(seen) = seen {
                let _ = seen.send(());
            }
        }
        py.detach(|| worker.join())
    });
    let interrupted = realitygap_runner::interrupt::requested();
    realitygap_runner::interrupt::clear();
    let result = match result {
        Ok(r) => r,
        Err(_) => {
            return Err(RealityGapError::new_err(
                "the call panicked (a bug: please report it)",
            ))
        }
    };
    if let Some(e) = raised {
        if e.is_instance_of::<PyKeyboardInterrupt>(py) {
            return Err(PyKeyboardInterrupt::new_err(
                realitygap_runner::interrupt::Interrupted.to_string(),
            ));
        }
        return Err(e);
    }
    match result {
        Err(e) if interrupted || realitygap_runner::interrupt::is_interrupted(&e) => Err(
            PyKeyboardInterrupt::new_err(realitygap_runner::interrupt::Interrupted.to_string()),
        ),
        Err(e) => Err(py_err(e)),
        Ok(v) => Ok(v),
    }
}

/// The child processes of the simulations: this interpreter running
/// `python -m realitygap._child`.
fn launcher(py: Python<'_>) -> PyResult<Launcher> {
    let exe: String = py.import("sys")?.getattr("executable")?.extract()?;
    if exe.is_empty() {
        return Err(RealityGapError::new_err(
            "sys.executable is empty: the simulations' child processes need the Python interpreter's path",
        ));
    }
    Ok(Launcher {
        program: Some(PathBuf::from(exe)),
        args: vec!["-m".into(), "realitygap._child".into()],
    })
}

/// `--data builtin|none|DIR`.
fn data_source(data: &str) -> PyResult<DataSource> {
    data.parse()
        .map_err(|e: String| RealityGapError::new_err(format!("data={data:?}: {e}")))
}

/// The physics engines this package can run, in `realitygap engines`
/// order (compiled in, then the engines out of process that are
/// installed, such as `mujoco4`): per engine a dict of its name, version, default timestep, settings, the
/// physical parameters it honours and how it takes joint commands.
#[pyfunction]
fn engines(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let list = PyList::empty(py);
    for e in realitygap::engines() {
        let d = PyDict::new(py);
        d.set_item("name", e.name())?;
        d.set_item("version", e.version())?;
        d.set_item("default_timestep_s", e.default_timestep_s())?;
        let settings: Vec<(String, String)> = e
            .settings_help()
            .iter()
            .map(|s| (s.key.to_string(), s.help.to_string()))
            .collect();
        d.set_item("settings", settings)?;
        let params: Vec<(String, String)> = realitygap::param_table(e.as_ref())
            .into_iter()
            .map(|(k, m)| (k.pattern().to_string(), m))
            .collect();
        d.set_item("params", params)?;
        let commands: Vec<(String, String, String)> = e
            .command_support()
            .iter()
            .map(|c| {
                (
                    c.kind.name().to_string(),
                    c.kind.unit().to_string(),
                    c.mechanism.to_string(),
                )
            })
            .collect();
        d.set_item("commands", commands)?;
        list.append(d)?;
    }
    Ok(list)
}

/// The built-in study file (assets/studies/collins2019.toml of the
/// package's assets).
#[pyfunction]
fn builtin_study() -> String {
    realitygap_study::data_source::assets_dir()
        .join("studies")
        .join("collins2019.toml")
        .display()
        .to_string()
}

/// The project's assets folder (scenes, studies, tuning spaces, the
/// study's recordings).
#[pyfunction]
fn assets_dir() -> String {
    realitygap_study::data_source::assets_dir()
        .display()
        .to_string()
}

/// The version of the tool (as in every manifest).
#[pyfunction]
fn version() -> &'static str {
    realitygap_core::TOOL_VERSION
}

/// `realitygap compare`: returns a dict with `kind` (`study` or
/// `replay`), `csv` (the table as `--format csv` writes it), `markdown`
/// and `json` (`--format json`, with `series` the per-step series).
#[pyfunction]
#[pyo3(signature = (study, *, data="builtin", results=None, mode="default", alignment=None,
    registration=None, save_registration=None, runs=None, holdout=None, bootstrap=None,
    seed=2019, link=None, joint_space=false, series=false, physics_free=true,
    physics_free_params=None, reporter=None))]
#[allow(clippy::too_many_arguments)]
fn compare<'py>(
    py: Python<'py>,
    study: PathBuf,
    data: &str,
    results: Option<PathBuf>,
    mode: &str,
    alignment: Option<String>,
    registration: Option<String>,
    save_registration: Option<PathBuf>,
    runs: Option<String>,
    holdout: Option<String>,
    bootstrap: Option<usize>,
    seed: u64,
    link: Option<String>,
    joint_space: bool,
    series: bool,
    physics_free: bool,
    physics_free_params: Option<PathBuf>,
    reporter: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mode = parse_mode(mode).map_err(|e| RealityGapError::new_err(format!("mode: {e}")))?;
    let rows = match (physics_free, physics_free_params) {
        (false, _) => realitygap::compare::PhysicsFreeRows::None,
        (true, None) => realitygap::compare::PhysicsFreeRows::Default,
        (true, Some(params)) => realitygap::compare::PhysicsFreeRows::Asked(Some(params)),
    };
    let launcher = if rows == realitygap::compare::PhysicsFreeRows::None {
        None
    } else {
        Some(launcher(py)?)
    };
    let mut request = realitygap::compare::CompareRequest {
        study,
        link,
        data: data_source(data)?,
        results,
        measure: Measure {
            mode,
            alignment,
            registration,
            save_registration,
            runs,
            holdout,
            bootstrap,
            seed,
        },
        joint_space,
        added_sources: Vec::new(),
    };
    let (kind, csv, markdown, json) = long_call(py, reporter, move |ui| {
        // The physics-free runs live as long as the comparison.
        let mut _runs = None;
        if let Some(launcher) = &launcher {
            let (runs, sources) = rows.sources_in_temp(&request.study, launcher, ui)?;
            _runs = runs;
            request.added_sources = sources;
        }
        let c = realitygap::compare::evaluate(&request)?;
        let csv = match &c {
            realitygap::compare::Comparison::Study { reports, .. } => {
                realitygap_analysis::table::render(reports, Format::Csv)
            }
            replay => replay.render(Format::Csv, false)?,
        };
        let kind = match &c {
            realitygap::compare::Comparison::Study { .. } => "study",
            realitygap::compare::Comparison::Replay { .. } => "replay",
            realitygap::compare::Comparison::Tosses { .. } => "tosses",
        };
        Ok((
            kind,
            csv,
            c.render(Format::Markdown, false)?,
            c.render(Format::Json, series)?,
        ))
    })?;
    let d = PyDict::new(py);
    d.set_item("kind", kind)?;
    d.set_item("csv", csv)?;
    d.set_item("markdown", markdown)?;
    d.set_item("json", json)?;
    Ok(d)
}

/// One run of a results directory: a dict with `columns` (a list of
/// (name, bytes) pairs, the run CSV's columns as little-endian `f64`),
/// `entry` (its manifest entry as JSON) and `manifest` (the manifest as
/// JSON, runs left out). `run`: its id; default the first finished run.
#[pyfunction]
#[pyo3(signature = (dir, run=None))]
fn load_run<'py>(
    py: Python<'py>,
    dir: PathBuf,
    run: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    use realitygap_data::runstore::RunStore;
    let store = RunStore::open(&dir)
        .map_err(|e| RealityGapError::new_err(format!("{}: {e}", dir.display())))?;
    let id = match run {
        Some(id) => id,
        None => store
            .runs()
            .iter()
            .find(|r| !r.file.is_empty())
            .map(|r| r.id.clone())
            .ok_or_else(|| {
                RealityGapError::new_err(format!(
                    "{}: no run with a trajectory in its manifest",
                    dir.display()
                ))
            })?,
    };
    let trajectory = py
        .detach(|| store.read_run(&id))
        .map_err(|e| RealityGapError::new_err(e.to_string()))?;
    let columns = PyList::empty(py);
    for (name, values) in realitygap_data::runstore::run_columns(&trajectory) {
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        columns.append((name, PyBytes::new(py, &bytes)))?;
    }
    let entry = store.run(&id).expect("read_run found it");
    let mut manifest = store.manifest().clone();
    manifest.runs.clear();
    let d = PyDict::new(py);
    d.set_item("id", &id)?;
    d.set_item("columns", columns)?;
    d.set_item(
        "entry",
        serde_json::to_string(entry).map_err(|e| py_err(e.into()))?,
    )?;
    d.set_item(
        "manifest",
        serde_json::to_string(&manifest).map_err(|e| py_err(e.into()))?,
    )?;
    Ok(d)
}

/// `realitygap run`: simulates `scenes` in `engines`, `repeats` times,
/// into `out`. Returns a dict with `summary` (the command's lines) and
/// `groups` (per results directory: scene, source, engine, dir, ok,
/// diverged, unstable, failed, kept, load_error). Raises when a model did
/// not load or a run failed, as the command exits with an error.
#[pyfunction]
#[pyo3(signature = (scenes, *, out, engines=Vec::new(), repeats=1, robot=None, packages=Vec::new(),
    jobs=None, seed=0, perturb=Vec::new(), set=Vec::new(), timeout_s=None, params=None,
    stitch=None, allow_unstable=false, reporter=None))]
#[allow(clippy::too_many_arguments)]
fn run<'py>(
    py: Python<'py>,
    scenes: Vec<PathBuf>,
    out: PathBuf,
    engines: Vec<String>,
    repeats: u32,
    robot: Option<String>,
    packages: Vec<String>,
    jobs: Option<usize>,
    seed: u64,
    perturb: Vec<String>,
    set: Vec<String>,
    timeout_s: Option<f64>,
    params: Option<PathBuf>,
    stitch: Option<String>,
    allow_unstable: bool,
    reporter: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if scenes.is_empty() {
        return Err(RealityGapError::new_err("give at least one scene file"));
    }
    if !(1..=100_000).contains(&repeats) {
        return Err(RealityGapError::new_err(format!(
            "repeats={repeats}: expected 1 to 100000"
        )));
    }
    let spec = BatchSpec {
        scenes,
        engines,
        repeats,
        out,
        robot,
        packages,
        jobs,
        seed,
        perturb,
        set,
        timeout_s,
        params,
        stitch,
        allow_unstable,
    };
    let launcher = launcher(py)?;
    let (summary, groups, failure) = long_call(py, reporter, move |ui| {
        let outcome = realitygap::batch::run(spec, Executor::Local, &launcher, ui)?;
        let groups: Vec<serde_json::Value> = outcome
            .plan
            .groups
            .iter()
            .map(|g| {
                serde_json::json!({
                    "scene": g.scene_name,
                    "source": g.source,
                    "engine": g.engine,
                    "dir": g.store.dir().display().to_string(),
                    "ok": g.done.ok,
                    "diverged": g.done.diverged,
                    "unstable": g.done.unstable,
                    "failed": g.done.failed,
                    "kept": outcome.plan.kept(g),
                    "load_error": g.load_error,
                })
            })
            .collect();
        let failure = outcome
            .check()
            .err()
            .map(|e| realitygap::ui::error_text(&e));
        Ok((outcome.summary(), groups, failure))
    })?;
    if let Some(message) = failure {
        return Err(RealityGapError::new_err(message));
    }
    let d = PyDict::new(py);
    d.set_item("summary", summary)?;
    d.set_item(
        "groups",
        serde_json::to_string(&groups).map_err(|e| py_err(e.into()))?,
    )?;
    Ok(d)
}

/// `realitygap replay`: the recorded episodes of `real` replayed in every
/// engine. Returns a dict with `csv`, `markdown` and `json` of the
/// joint-space table and `report` (index.html). Raises when a replay
/// failed (after writing everything), as the command does.
#[pyfunction]
#[pyo3(signature = (real, *, out, robot=None, packages=Vec::new(), engines=Vec::new(),
    params=None, scene=None, jobs=None, reporter=None))]
#[allow(clippy::too_many_arguments)]
fn replay<'py>(
    py: Python<'py>,
    real: PathBuf,
    out: PathBuf,
    robot: Option<PathBuf>,
    packages: Vec<String>,
    engines: Vec<String>,
    params: Option<PathBuf>,
    scene: Option<PathBuf>,
    jobs: Option<usize>,
    reporter: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let options = realitygap::replay::ReplayOptions {
        real,
        robot,
        packages,
        engines,
        params,
        scene,
        out,
        jobs,
        executor: Executor::Local,
        toss_start: Default::default(),
    };
    let launcher = launcher(py)?;
    let (kind, csv, markdown, json, report) = long_call(py, reporter, move |ui| {
        let r = realitygap::replay::replay(&options, &launcher, ui)?;
        Ok((
            r.kind,
            r.csv,
            r.table,
            r.json,
            r.index_html.display().to_string(),
        ))
    })?;
    let d = PyDict::new(py);
    d.set_item("kind", kind)?;
    d.set_item("csv", csv)?;
    d.set_item("markdown", markdown)?;
    d.set_item("json", json)?;
    d.set_item("report", report)?;
    Ok(d)
}

/// `realitygap tune`: an engine calibrated against a study's real runs
/// (`study`) or a robot's recorded episodes (`recordings`), into `out`.
/// Returns a dict with `markdown` (the summary) and `files`.
#[pyfunction]
#[pyo3(signature = (*, engine, out, study=None, recordings=None, params=None, scene=None,
    efforts=false, iterations=None, data="builtin", space=None, runs=None, holdout=None,
    folds=None, budget=None, seed=1, restarts=false, jobs=None, cube_weight=None, keep_registration=false,
    baseline=true, start="space", prior_weight=0.0, settings=None, set=Vec::new(), robot=None, packages=Vec::new(), reporter=None))]
#[allow(clippy::too_many_arguments)]
fn tune<'py>(
    py: Python<'py>,
    engine: String,
    out: PathBuf,
    study: Option<PathBuf>,
    recordings: Option<PathBuf>,
    params: Option<PathBuf>,
    scene: Option<PathBuf>,
    efforts: bool,
    iterations: Option<usize>,
    data: &str,
    space: Option<PathBuf>,
    runs: Option<String>,
    holdout: Option<String>,
    folds: Option<usize>,
    budget: Option<usize>,
    seed: u64,
    restarts: bool,
    jobs: Option<usize>,
    cube_weight: Option<f64>,
    keep_registration: bool,
    baseline: bool,
    start: &str,
    prior_weight: f64,
    settings: Option<PathBuf>,
    set: Vec<String>,
    robot: Option<String>,
    packages: Vec<String>,
    reporter: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if study.is_some() && recordings.is_some() {
        return Err(RealityGapError::new_err(
            "give a study or recordings, not both",
        ));
    }
    let defaults = realitygap::tune::TuneRequest::default();
    let request = realitygap::tune::TuneRequest {
        study,
        recordings,
        params,
        scene,
        efforts,
        iterations,
        data: data_source(data)?,
        engine,
        out,
        space,
        runs,
        holdout,
        folds,
        budget,
        seed,
        restarts,
        jobs,
        cube_weight: cube_weight.unwrap_or(defaults.cube_weight),
        keep_registration,
        no_baseline: !baseline,
        start_from_baseline: match start {
            "space" => false,
            "physics-free" => true,
            other => {
                return Err(RealityGapError::new_err(format!(
                    "start={other:?}: expected \"space\" or \"physics-free\""
                )))
            }
        },
        prior_weight,
        settings,
        set,
        robot,
        packages,
        executor: Executor::Local,
        verbose: false,
    };
    let launcher = launcher(py)?;
    let tuned = long_call(py, reporter, move |ui| {
        realitygap::tune::tune(&request, &launcher, ui)
    })?;
    let d = PyDict::new(py);
    d.set_item("markdown", tuned.markdown)?;
    let files: Vec<String> = tuned
        .files
        .iter()
        .map(|f| f.display().to_string())
        .collect();
    d.set_item("files", files)?;
    Ok(d)
}

/// `realitygap reproduce`: the whole study into `out`. Returns a dict
/// with `csv`, `markdown` and `json` of the table, `joint_space`
/// (Markdown or None), `report` (index.html), `timings` and `problems`
/// (the simulations that did not all finish; the study went on).
#[pyfunction]
#[pyo3(signature = (*, out, data="builtin", repeats=20, engines=Vec::new(), scenes=Vec::new(),
    jobs=None, mode="default", timeout_s=None, params=None, tuned=Vec::new(),
    crossval=Vec::new(), joint_space=false, runs=None, holdout=None, tosses=true, reporter=None))]
#[allow(clippy::too_many_arguments)]
fn reproduce<'py>(
    py: Python<'py>,
    out: PathBuf,
    data: &str,
    repeats: u32,
    engines: Vec<String>,
    scenes: Vec<PathBuf>,
    jobs: Option<usize>,
    mode: &str,
    timeout_s: Option<f64>,
    params: Option<PathBuf>,
    tuned: Vec<PathBuf>,
    crossval: Vec<PathBuf>,
    joint_space: bool,
    runs: Option<String>,
    holdout: Option<String>,
    tosses: bool,
    reporter: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if !(1..=10_000).contains(&repeats) {
        return Err(RealityGapError::new_err(format!(
            "repeats={repeats}: expected 1 to 10000"
        )));
    }
    let request = realitygap::reproduce::ReproduceRequest {
        data: data_source(data)?,
        out,
        repeats,
        engines,
        scenes,
        jobs,
        mode: parse_mode(mode).map_err(|e| RealityGapError::new_err(format!("mode: {e}")))?,
        timeout_s,
        params,
        tuned,
        crossval,
        joint_space,
        runs,
        holdout,
        executor: Executor::Local,
        tosses,
        command: "realitygap.reproduce(...) (Python)".into(),
        verbose: false,
    };
    let launcher = launcher(py)?;
    let done = long_call(py, reporter, move |ui| {
        let r = realitygap::reproduce::reproduce_keeping_problems(&request, &launcher, ui)?;
        let csv = realitygap_analysis::table::render(&r.reports, Format::Csv);
        let json = serde_json::to_string(&realitygap_analysis::table::to_json(&r.reports, false))?;
        Ok((r, csv, json))
    })?;
    let (r, csv, json) = done;
    let d = PyDict::new(py);
    d.set_item("csv", csv)?;
    d.set_item("markdown", r.table)?;
    d.set_item("json", json)?;
    d.set_item("joint_space", r.joint_space)?;
    d.set_item("tosses", r.tosses)?;
    d.set_item("report", r.index_html.display().to_string())?;
    d.set_item("timings", r.timings)?;
    d.set_item("problems", r.problems)?;
    Ok(d)
}

/// A parameters file's text (TOML) from the JSON of a dict
/// (`{"joints": {"NAME": {"damping": 0.1}}, ...}`).
#[pyfunction]
fn params_toml(json: &str) -> PyResult<String> {
    let value: serde_json::Value = serde_json::from_str(json)
        .map_err(|e| RealityGapError::new_err(format!("parameters: {e}")))?;
    let text = toml::to_string(&value)
        .map_err(|e| RealityGapError::new_err(format!("parameters as TOML: {e}")))?;
    realitygap_core::params::PhysicalParams::from_toml_str(&text, std::path::Path::new("<dict>"))
        .map_err(|e| RealityGapError::new_err(e.to_string()))?;
    Ok(text)
}

/// A TOML file as JSON text (Python 3.9 and 3.10 have no tomllib).
#[pyfunction]
fn read_toml(path: PathBuf) -> PyResult<String> {
    let text = std::fs::read_to_string(&path)
        .map_err(|e| RealityGapError::new_err(format!("cannot read {}: {e}", path.display())))?;
    let value: toml::Value = toml::from_str(&text)
        .map_err(|e| RealityGapError::new_err(format!("{}: {e}", path.display())))?;
    serde_json::to_string(&value).map_err(|e| py_err(e.into()))
}

/// The child's side of a simulation (`python -m realitygap._child`): one
/// job read as JSON on standard input, its result written on standard
/// output. Returns the exit code; an error is written on standard error
/// as the command writes it.
#[pyfunction]
fn run_one(py: Python<'_>) -> i32 {
    match py.detach(realitygap::run_one) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {}", realitygap::ui::error_text(&e));
            1
        }
    }
}

/// The module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RealityGapError", m.py().get_type::<RealityGapError>())?;
    m.add_function(wrap_pyfunction!(engines, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_study, m)?)?;
    m.add_function(wrap_pyfunction!(assets_dir, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(load_run, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(replay, m)?)?;
    m.add_function(wrap_pyfunction!(tune, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce, m)?)?;
    m.add_function(wrap_pyfunction!(params_toml, m)?)?;
    m.add_function(wrap_pyfunction!(read_toml, m)?)?;
    m.add_function(wrap_pyfunction!(run_one, m)?)?;
    Ok(())
}
