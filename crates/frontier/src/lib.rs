//! The speed-accuracy frontier of one engine (`realitygap frontier`; the
//! command parses arguments and prints, this crate does the work).
//!
//! Sweeps engine settings (by default a timestep grid times the engine's
//! integrator or solver choices, see [`default_grid`]; or the `--sweep`
//! lists, crossed), runs every scene at every setting, and measures per
//! setting:
//!
//! - the CPU time of the controller loop (stepping and control, not the
//!   model load), as the calling thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`),
//!   the minimum over `--repeats` runs, and from it the real-time factor
//!   (simulated seconds per CPU second);
//! - the largest and mean distance of every tracked body (wrist, cube) from
//!   the engine's *converged reference*, over the control-rate samples: the
//!   finest setting of the sweep (smallest timestep; the largest number of
//!   every other numeric key; the last value listed of every text key),
//!   rerun with its timestep halved until two successive runs differ by
//!   less than a tenth of the tolerance (at most `--max-halvings` times;
//!   each halving is timed once, the finest setting itself `--repeats`
//!   times);
//! - with `--data`, the accumulated gap to the real arm, by the same
//!   analysis as `compare` and `reproduce` (the study's scenes only);
//! - the status: `ok`, `diverged` (the run stopped at a non-finite or
//!   out-of-bounds state; its deviation covers the samples before) or
//!   `failed` (the engine refused the setting or panicked). Either way the
//!   sweep goes on.
//!
//! The scene's own setting is always measured too (and marked so).
//!
//! **In-process, by choice.** The points run one after the other in this
//! process, so that the thread's CPU time measures the engine alone (no
//! process start, no JSON) and nothing else of this sweep competes for the
//! core. A Rust panic inside an engine is caught and recorded as `failed`.
//! The price: a fatal error inside MuJoCo's C code (`mju_error`, which
//! exits the process) would end the sweep; MuJoCo's instabilities are
//! warnings, which the engine reports as a diverged run, and none of the
//! default grids has hit a fatal error. Use `realitygap run` (one child
//! process per run) to isolate a setting that does.
//!
//! **On Slurm** ([`FrontierSpec::executor`]), each stage of the sweep is
//! one job array and every simulation its own `realitygap __run-one`,
//! which times the control loop on its thread's CPU clock and returns the
//! time with the trajectory; the repeats are folded as here (see the
//! `slurm` module), so everything but the timings equals the local sweep.
//!
//! Outputs in `--out`: `frontier.json`, `frontier_deviation.svg/.png`,
//! with `--data` `frontier_gap.svg/.png`, `recommended.toml` (a parameters
//! file with the recommended setting as `[engine.NAME]`, for `run --params`)
//! and `reference/<scene>/<engine>/` (the converged reference's runs, in
//! the results-directory format).

#![forbid(unsafe_code)]

mod slurm;

use anyhow::{anyhow, bail, Context, Result};
use realitygap_analysis::bootstrap::BootstrapOptions;
use realitygap_analysis::compare::{CompareOptions, RunInput, SourceRuns};
use realitygap_core::controller::{
    load_prepared, run_scene_with, ControlParams, RunOptions, RunOutcome, RunStatus,
};
use realitygap_core::engine::{Engine, EngineSettings, SettingValue, TIMESTEP_KEY};
use realitygap_core::params::PhysicalParams;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::Trajectory;
use realitygap_data::runstore::{EngineInfo, RunEntry, RunStore, SourceKind};
use realitygap_report::frontier::{FrontierFigure, FrontierPoint};
use realitygap_runner::slurm::Executor;
use realitygap_runner::Launcher;
use realitygap_study::data_source::{assets_dir, DataSource};
use realitygap_study::{Roots, Study};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The study definition, built in (for the gap to the real arm).
const COLLINS2019: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../assets/studies/collins2019.toml"
));

/// Default of `--max-halvings`.
pub const MAX_HALVINGS: u32 = 3;

/// What a frontier sweep is asked to do (`realitygap frontier`'s
/// arguments, the engine aside).
pub struct FrontierSpec {
    /// Scene files (TOML).
    pub scenes: Vec<PathBuf>,
    /// `KEY=V1,V2,...` lists to cross; empty: the engine's own grid.
    pub sweep: Vec<String>,
    /// Largest deviation from the converged reference a recommended
    /// setting may have, millimetres.
    pub tolerance_mm: f64,
    /// The real arm's recordings for the gap; none: no gap.
    pub data: Option<DataSource>,
    /// Timed runs per setting and scene (the minimum CPU time is kept).
    pub repeats: u32,
    /// Most halvings of the finest timestep in search of convergence.
    pub max_halvings: u32,
    /// Output folder.
    pub out: PathBuf,
    /// Where the simulations run: in this process, one after the other
    /// (`Local`), or each stage of the sweep as one Slurm job array.
    pub executor: Executor,
    /// How a Slurm task runs one simulation (`realitygap __run-one`);
    /// unused locally.
    pub launcher: Launcher,
    /// Where progress lines go (the command prints them on standard
    /// error).
    pub say: Box<dyn Fn(String)>,
    /// Where the outcome goes: the output file and the recommendation
    /// (standard output).
    pub tell: Box<dyn Fn(String)>,
}

/// One point of the sweep: the settings it lays over each scene's own.
pub type Overlay = Vec<(String, SettingValue)>;

/// Parses `--sweep KEY=V1,V2,...` values, checking each key against the
/// engine's settings; the lists in order.
pub fn parse_sweeps(
    specs: &[String],
    engine: &dyn Engine,
) -> Result<Vec<(String, Vec<SettingValue>)>> {
    let known: Vec<&str> = engine.settings_help().iter().map(|s| s.key).collect();
    let mut out: Vec<(String, Vec<SettingValue>)> = Vec::new();
    for spec in specs {
        let (key, values) = spec
            .split_once('=')
            .ok_or_else(|| anyhow!("--sweep \"{spec}\": expected KEY=V1,V2,..."))?;
        let key = key.trim();
        if !known.contains(&key) {
            bail!(
                "--sweep \"{spec}\": {} has no setting \"{key}\" (it has: {})",
                engine.name(),
                known.join(", ")
            );
        }
        if out.iter().any(|(k, _)| k == key) {
            bail!("--sweep \"{spec}\": \"{key}\" is swept twice");
        }
        let values: Vec<SettingValue> = values
            .split(',')
            .map(str::trim)
            .filter(|v| !v.is_empty())
            .map(SettingValue::parse)
            .collect();
        if values.is_empty() {
            bail!("--sweep \"{spec}\": no values after '='");
        }
        out.push((key.to_string(), values));
    }
    Ok(out)
}

/// Every combination of the lists, the first list varying slowest.
pub fn cross(lists: &[(String, Vec<SettingValue>)]) -> Vec<Overlay> {
    let mut points: Vec<Overlay> = vec![vec![]];
    for (key, values) in lists {
        points = points
            .into_iter()
            .flat_map(|p| {
                values.iter().map(move |v| {
                    let mut q = p.clone();
                    q.push((key.clone(), v.clone()));
                    q
                })
            })
            .collect();
    }
    points
}

fn texts(values: &[&str]) -> Vec<SettingValue> {
    values
        .iter()
        .map(|v| SettingValue::Text(v.to_string()))
        .collect()
}

fn floats(values: &[f64]) -> Vec<SettingValue> {
    values.iter().map(|v| SettingValue::Float(*v)).collect()
}

fn ints(values: &[i64]) -> Vec<SettingValue> {
    values.iter().map(|v| SettingValue::Integer(*v)).collect()
}

/// The default sweep of an engine. Timesteps divide the study's 0.05 s
/// control period; choices are listed from cheapest to most exact, so the
/// last one is the reference's.
pub fn default_grid(engine: &str) -> Result<Vec<Overlay>> {
    let ts = |v: &[f64]| (TIMESTEP_KEY.to_string(), floats(v));
    let coarse = [0.01, 0.005, 0.0025, 0.001];
    Ok(match engine {
        "mujoco" => cross(&[
            (
                "integrator".into(),
                texts(&["euler", "implicitfast", "implicit", "rk4"]),
            ),
            ts(&[0.005, 0.002, 0.001, 0.0005, 0.0002, 0.0001]),
        ]),
        "bullet" => cross(&[
            ("solver_iterations".into(), ints(&[10, 50, 200])),
            ts(&coarse),
        ]),
        "rapier" => cross(&[("solver_iterations".into(), ints(&[1, 4, 8])), ts(&coarse)]),
        "physx" => cross(&[
            ("position_iterations".into(), ints(&[8, 32, 64])),
            ts(&coarse),
        ]),
        "dart" => cross(&[
            ("lcp_solver".into(), texts(&["dantzig", "pgs"])),
            ts(&coarse),
        ]),
        "ode" => {
            let mut points = cross(&[
                ("stepper".into(), texts(&["quick_step"])),
                ("quick_step_iterations".into(), ints(&[10, 20, 50])),
                ts(&coarse),
            ]);
            points.extend(cross(&[
                ("stepper".into(), texts(&["world_step"])),
                ts(&coarse),
            ]));
            points
        }
        other => bail!("no default sweep for engine \"{other}\": give --sweep KEY=V1,V2,..."),
    })
}

/// Sort key of a point's fineness (greater is finer): minus the timestep,
/// then per other key the value (numbers) or its position in the sweep
/// (text).
fn fineness(p: &Overlay, order: &[(String, Vec<SettingValue>)]) -> Vec<f64> {
    let mut key = vec![-p
        .iter()
        .find(|(k, _)| k == TIMESTEP_KEY)
        .and_then(|(_, v)| v.as_f64())
        .unwrap_or(f64::INFINITY)];
    for (k, values) in order.iter().filter(|(k, _)| k != TIMESTEP_KEY) {
        let v = p.iter().find(|(pk, _)| pk == k).map(|(_, v)| v);
        key.push(match v {
            Some(SettingValue::Text(_)) | Some(SettingValue::Bool(_)) => {
                values.iter().position(|x| Some(x) == v).unwrap_or(0) as f64
            }
            Some(v) => v.as_f64().unwrap_or(0.0),
            None => -1.0,
        });
    }
    key
}

/// The keys and values of a grid in first-seen order.
fn grid_order(points: &[Overlay]) -> Vec<(String, Vec<SettingValue>)> {
    let mut order: Vec<(String, Vec<SettingValue>)> = Vec::new();
    for p in points {
        for (k, v) in p {
            match order.iter_mut().find(|(ok, _)| ok == k) {
                Some((_, vs)) => {
                    if !vs.contains(v) {
                        vs.push(v.clone())
                    }
                }
                None => order.push((k.clone(), vec![v.clone()])),
            }
        }
    }
    order
}

/// The finest point of a grid (see the module documentation).
pub fn finest(points: &[Overlay]) -> Option<&Overlay> {
    let order = grid_order(points);
    points.iter().max_by(|a, b| {
        let (ka, kb) = (fineness(a, &order), fineness(b, &order));
        ka.partial_cmp(&kb).unwrap_or(std::cmp::Ordering::Equal)
    })
}

/// A loaded scene with its robot.
pub struct SceneCase {
    /// The scene (with the robot's model prepared for the engine).
    pub scene: Scene,
    /// Its robot.
    pub robot: RobotModel,
}

fn load_scenes(files: &[PathBuf], engine: &dyn Engine) -> Result<Vec<SceneCase>> {
    let resolver = PackageResolver::from_env();
    let mut out: Vec<SceneCase> = Vec::new();
    for file in files {
        let scene = Scene::from_file(file)?;
        let robot = scene
            .robot
            .model(&resolver)
            .with_context(|| format!("the robot of scene {}", file.display()))?;
        scene.validate(&robot)?;
        let (scene, robot) =
            realitygap_core::controller::prepare(engine, &scene, &robot, &PhysicalParams::none())
                .map_err(|e| anyhow!("scene {}: {e}", file.display()))?;
        if out.iter().any(|c| c.scene.name == scene.name) {
            bail!("scene \"{}\" is given twice", scene.name);
        }
        out.push(SceneCase { scene, robot });
    }
    Ok(out)
}

/// The settings of `point` laid over the scene's own, checked by the engine
/// and against the control period.
pub(crate) fn settings_for(
    case: &SceneCase,
    engine: &dyn Engine,
    point: &Overlay,
) -> Result<EngineSettings> {
    let mut settings = case.scene.settings_for(engine.name());
    settings.extend(point.iter().cloned());
    let timestep_s = engine
        .check_settings(&settings)
        .map_err(|e| anyhow!("{e}"))?;
    case.scene
        .steps_per_period(timestep_s)
        .map_err(|e| anyhow!("{e}"))?;
    Ok(settings)
}

/// `--set` form of a point, e.g. `mujoco.timestep_s=0.002`.
pub fn set_args(engine: &str, point: &Overlay) -> Vec<String> {
    point
        .iter()
        .map(|(k, v)| format!("{engine}.{k}={v}"))
        .collect()
}

fn label(point: &Overlay) -> (String, String) {
    let group: Vec<String> = point
        .iter()
        .filter(|(k, _)| k != TIMESTEP_KEY)
        .map(|(k, v)| match v {
            SettingValue::Text(t) => t.clone(),
            v => format!("{k}={v}"),
        })
        .collect();
    let group = if group.is_empty() {
        "timestep".to_string()
    } else {
        group.join(" ")
    };
    let ts = point
        .iter()
        .find(|(k, _)| k == TIMESTEP_KEY)
        .map(|(_, v)| format!(" {v} s"))
        .unwrap_or_default();
    (format!("{group}{ts}"), group)
}

/// Seconds on the clock the timings use: the thread's CPU time where the
/// platform has one, else wall time since the first call (the output says
/// which, [`clock_name`]).
fn thread_cpu_s() -> f64 {
    static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    realitygap_runner::cpu_clock::thread_cpu_s().unwrap_or_else(|| {
        START
            .get_or_init(std::time::Instant::now)
            .elapsed()
            .as_secs_f64()
    })
}

/// The clock [`thread_cpu_s`] reads, for the output.
fn clock_name() -> &'static str {
    if realitygap_runner::cpu_clock::thread_cpu_s().is_some() {
        "thread CPU time (CLOCK_THREAD_CPUTIME_ID)"
    } else {
        "wall time (no thread CPU clock on this platform)"
    }
}

/// One scene at one setting.
#[derive(Debug, Clone, Serialize)]
pub struct SceneResult {
    /// Scene name.
    pub scene: String,
    /// `ok`, `diverged` or `failed`.
    pub status: String,
    /// Why it diverged or failed.
    pub message: Option<String>,
    /// Smallest CPU time of the controller loop over the repeats, s.
    pub cpu_s: f64,
    /// Simulated time covered, s.
    pub simulated_s: f64,
    /// Engine steps of one run.
    pub engine_steps: u64,
    /// Largest distance of a tracked body from the reference, m.
    pub max_deviation_m: Option<f64>,
    /// Mean distance of the tracked bodies from the reference, m.
    pub mean_deviation_m: Option<f64>,
    /// Per tracked body: `[max, mean]` distance from the reference, m.
    pub deviation_by_body_m: BTreeMap<String, [f64; 2]>,
    /// Accumulated error against the real arm's mean wrist, m (with --data).
    pub gap_m: Option<f64>,
    #[serde(skip)]
    trajectory: Option<Trajectory>,
}

/// One timed simulation: its outcome and the CPU seconds of its control
/// loop, or why it failed.
pub(crate) type Attempt = std::result::Result<(RunOutcome, f64), String>;

/// Runs one scene at `settings` in this process, timed on this thread's
/// clock; a refused setting or a panic is an `Err` with the message.
fn run_once(case: &SceneCase, engine: &dyn Engine, settings: &EngineSettings) -> Attempt {
    let options = RunOptions::default();
    let control = ControlParams::from_params(&PhysicalParams::none(), &case.scene);
    let once = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut sim = load_prepared(
            engine,
            &case.scene,
            &case.robot,
            settings,
            &PhysicalParams::none(),
            &options,
        )?;
        let start = thread_cpu_s();
        let outcome = run_scene_with(sim.as_mut(), &case.scene, &options, &control)?;
        Ok::<_, realitygap_core::controller::RunError>((outcome, thread_cpu_s() - start))
    }));
    match once {
        Ok(Ok(done)) => Ok(done),
        Ok(Err(e)) => Err(e.to_string()),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "a panic".into());
            Err(format!("the engine panicked: {what}"))
        }
    }
}

/// Runs one scene at `settings`, `repeats` times; never fails: a refused
/// setting or a panic is a `failed` result.
fn run_case(
    case: &SceneCase,
    engine: &dyn Engine,
    settings: &EngineSettings,
    repeats: u32,
) -> SceneResult {
    fold_attempts(case, (0..repeats).map(|_| run_once(case, engine, settings)))
}

/// The result of one scene from its repeats' attempts, in order: the
/// smallest CPU time, the first run's trajectory and status; the first
/// failure makes it `failed` (the attempts after it are not drawn).
pub(crate) fn fold_attempts(
    case: &SceneCase,
    attempts: impl Iterator<Item = Attempt>,
) -> SceneResult {
    let mut result = SceneResult {
        status: "ok".into(),
        cpu_s: f64::INFINITY,
        ..not_run(case)
    };
    for attempt in attempts {
        let (outcome, cpu_s) = match attempt {
            Ok(done) => done,
            Err(message) => return failed(result, message),
        };
        result.cpu_s = result.cpu_s.min(cpu_s);
        if result.trajectory.is_none() {
            result.simulated_s = match &outcome.status {
                RunStatus::Completed => case.scene.duration_s,
                RunStatus::Diverged { t_s, .. } => *t_s,
            };
            if let RunStatus::Diverged { t_s, reason } = &outcome.status {
                result.status = "diverged".into();
                result.message = Some(format!("diverged at t = {t_s:.4} s: {reason}"));
            }
            result.engine_steps = outcome.engine_steps;
            result.trajectory = Some(outcome.trajectory);
        }
    }
    result
}

pub(crate) fn failed(mut result: SceneResult, message: String) -> SceneResult {
    result.status = "failed".into();
    result.message = Some(message);
    result.cpu_s = f64::NAN;
    result.trajectory = None;
    result
}

/// Per tracked body of `reference`, the largest and the mean distance of
/// `run`'s positions from it over the samples both have, m; `None` when
/// they share no sample.
pub fn deviation(run: &Trajectory, reference: &Trajectory) -> Option<BTreeMap<String, [f64; 2]>> {
    let n = run.len().min(reference.len());
    if n == 0 {
        return None;
    }
    let mut out = BTreeMap::new();
    for body in &reference.bodies {
        let (a, b) = (run.positions(&body.role), reference.positions(&body.role));
        let d: Vec<f64> = (0..n)
            .filter_map(|i| Some(a.get(i).copied()??.distance(b.get(i).copied()??)))
            .collect();
        if d.is_empty() {
            continue;
        }
        let max = d.iter().copied().fold(0.0, f64::max);
        let max = if d.iter().any(|x| x.is_nan()) {
            f64::INFINITY
        } else {
            max
        };
        out.insert(
            body.role.clone(),
            [max, d.iter().sum::<f64>() / d.len() as f64],
        );
    }
    Some(out)
}

fn set_deviation(r: &mut SceneResult, reference: &Trajectory) {
    let Some(by_body) = r.trajectory.as_ref().and_then(|t| deviation(t, reference)) else {
        return;
    };
    r.max_deviation_m = by_body.values().map(|v| v[0]).reduce(f64::max);
    r.mean_deviation_m =
        Some(by_body.values().map(|v| v[1]).sum::<f64>() / by_body.len().max(1) as f64);
    r.deviation_by_body_m = by_body;
}

/// One setting of the sweep, over all scenes.
#[derive(Debug, Clone, Serialize)]
pub struct Point {
    /// Short label, e.g. `implicitfast 0.002 s`.
    pub label: String,
    /// The group it is drawn with, e.g. `implicitfast`.
    pub group: String,
    /// The swept settings, by key.
    pub settings: BTreeMap<String, serde_json::Value>,
    /// The same as `realitygap run --set` arguments.
    pub set: Vec<String>,
    /// The scene's own setting (no sweep value changes it).
    pub scene_setting: bool,
    /// Sum over scenes of the smallest CPU time of a run, s.
    pub cpu_s: f64,
    /// Simulated time over all scenes, s.
    pub simulated_s: f64,
    /// CPU seconds per simulated second.
    pub cpu_s_per_simulated_s: f64,
    /// Simulated seconds per CPU second.
    pub real_time_factor: f64,
    /// Largest distance of a tracked body (wrist, cube) from the reference
    /// over every scene, m.
    pub max_deviation_m: Option<f64>,
    /// Mean over scenes of the mean distance from the reference, m.
    pub mean_deviation_m: Option<f64>,
    /// Sum over scenes of the accumulated error against the real arm, m
    /// (with --data, when every scene has one).
    pub gap_m: Option<f64>,
    /// `ok` (every scene completed), `diverged` or `failed`.
    pub status: String,
    /// Finished (`ok`) with a max deviation within the tolerance.
    pub within_tolerance: bool,
    /// Per scene.
    pub scenes: Vec<SceneResult>,
    #[serde(skip)]
    overlay: Overlay,
}

fn json_of(v: &SettingValue) -> serde_json::Value {
    match v {
        SettingValue::Bool(b) => serde_json::json!(b),
        SettingValue::Integer(i) => serde_json::json!(i),
        SettingValue::Float(f) => serde_json::json!(f),
        SettingValue::Text(s) => serde_json::json!(s),
    }
}

/// True when two points ran the same simulations: every scene the same
/// steps and, to the bit, the same deviations (the engines are
/// deterministic), as a sweep value equal to the scene's own setting does.
fn same_runs(a: &Point, b: &Point) -> bool {
    a.scenes.len() == b.scenes.len()
        && a.scenes.iter().zip(&b.scenes).all(|(x, y)| {
            x.status == y.status
                && x.engine_steps == y.engine_steps
                && x.max_deviation_m.map(f64::to_bits) == y.max_deviation_m.map(f64::to_bits)
                && x.mean_deviation_m.map(f64::to_bits) == y.mean_deviation_m.map(f64::to_bits)
        })
}

/// Runs every scene at one setting, in this process.
fn measure(cases: &[SceneCase], engine: &dyn Engine, overlay: &Overlay, repeats: u32) -> Point {
    let scenes: Vec<SceneResult> = cases
        .iter()
        .map(|case| match settings_for(case, engine, overlay) {
            Ok(settings) => run_case(case, engine, &settings, repeats),
            Err(e) => failed(not_run(case), e.to_string()),
        })
        .collect();
    point_of(engine, overlay, scenes)
}

/// The point of `overlay` from its scenes' results (deviations not yet
/// scored).
pub(crate) fn point_of(engine: &dyn Engine, overlay: &Overlay, scenes: Vec<SceneResult>) -> Point {
    let (label, group) = label(overlay);
    let cpu_s: f64 = scenes.iter().map(|s| s.cpu_s).sum();
    let simulated_s: f64 = scenes.iter().map(|s| s.simulated_s).sum();
    let status = ["failed", "diverged"]
        .into_iter()
        .find(|st| scenes.iter().any(|s| s.status == *st))
        .unwrap_or("ok")
        .to_string();
    Point {
        label,
        group,
        settings: overlay
            .iter()
            .map(|(k, v)| (k.clone(), json_of(v)))
            .collect(),
        set: set_args(engine.name(), overlay),
        scene_setting: overlay.is_empty(),
        cpu_s,
        simulated_s,
        cpu_s_per_simulated_s: cpu_s / simulated_s,
        real_time_factor: simulated_s / cpu_s,
        max_deviation_m: None,
        mean_deviation_m: None,
        gap_m: None,
        status,
        within_tolerance: false,
        scenes,
        overlay: overlay.clone(),
    }
}

/// A scene's result before any run: status `failed`, nothing measured
/// (what a run that never happens reports, and the start of a fold).
pub(crate) fn not_run(case: &SceneCase) -> SceneResult {
    SceneResult {
        scene: case.scene.name.clone(),
        status: "failed".into(),
        message: None,
        cpu_s: f64::NAN,
        simulated_s: 0.0,
        engine_steps: 0,
        max_deviation_m: None,
        mean_deviation_m: None,
        deviation_by_body_m: BTreeMap::new(),
        gap_m: None,
        trajectory: None,
    }
}

/// Fills a point's deviations from the reference trajectories (one per
/// scene) and its verdict.
fn score(point: &mut Point, reference: &[Trajectory], tolerance_m: f64) {
    for (s, r) in point.scenes.iter_mut().zip(reference) {
        set_deviation(s, r);
    }
    let all = |f: fn(&SceneResult) -> Option<f64>| -> Option<Vec<f64>> {
        point.scenes.iter().map(f).collect()
    };
    point.max_deviation_m = all(|s| s.max_deviation_m).and_then(|v| v.into_iter().reduce(f64::max));
    point.mean_deviation_m =
        all(|s| s.mean_deviation_m).map(|v| v.iter().sum::<f64>() / v.len().max(1) as f64);
    if point.status != "ok" {
        // Only the runs' own entries keep the deviation before the end.
        point.max_deviation_m = None;
        point.mean_deviation_m = None;
    }
    point.within_tolerance = point.max_deviation_m.is_some_and(|d| d <= tolerance_m);
}

/// The converged reference: the finest point, its timestep halved until a
/// run changes by less than `threshold_m` (largest distance over scenes and
/// bodies) from the one before.
#[derive(Debug, Clone, Serialize)]
pub struct Reference {
    /// The reference's settings (the finest point's, with the halved
    /// timestep).
    pub point: Point,
    /// The finest setting of the sweep it started from.
    pub finest_set: Vec<String>,
    /// Each halving, in order.
    pub halvings: Vec<Halving>,
    /// The last change fell below the threshold.
    pub converged: bool,
    /// The threshold: a tenth of the tolerance, m.
    pub threshold_m: f64,
    #[serde(skip)]
    trajectories: Vec<Trajectory>,
}

/// One halving of the reference's timestep.
#[derive(Debug, Clone, Serialize)]
pub struct Halving {
    /// The halved timestep, s.
    pub timestep_s: f64,
    /// Largest change of a tracked body from the run before, over the
    /// scenes, m.
    pub change_m: f64,
    /// The same per scene (in the order given), m.
    pub change_by_scene_m: Vec<f64>,
}

/// `measure(stage, overlay, repeats)` measures one point in every scene.
fn converge(
    cases: &[SceneCase],
    engine: &dyn Engine,
    finest: &Overlay,
    (repeats, threshold_m, max_halvings): (u32, f64, u32),
    measure: &dyn Fn(&str, &Overlay, u32) -> Result<Point>,
    say: &dyn Fn(String),
) -> Result<Reference> {
    let trajectories_of = |p: &Point| -> Result<Vec<Trajectory>> {
        p.scenes
            .iter()
            .map(|s| match (&s.trajectory, s.status.as_str()) {
                (Some(t), "ok") => Ok(t.clone()),
                _ => Err(anyhow!(
                    "the reference setting {} did not complete scene {}: {}",
                    p.label,
                    s.scene,
                    s.message.as_deref().unwrap_or("no run")
                )),
            })
            .collect()
    };
    let mut overlay = finest.clone();
    if !overlay.iter().any(|(k, _)| k == TIMESTEP_KEY) {
        let ts = cases
            .first()
            .map(|c| settings_for(c, engine, &overlay))
            .transpose()?
            .and_then(|s| engine.check_settings(&s).ok())
            .unwrap_or(engine.default_timestep_s());
        overlay.push((TIMESTEP_KEY.into(), SettingValue::Float(ts)));
    }
    let mut point = measure("reference", &overlay, repeats)?;
    let mut trajectories = trajectories_of(&point)?;
    let mut halvings = Vec::new();
    let mut converged = false;
    for halving in 1..=max_halvings {
        let finer: Overlay = overlay
            .iter()
            .map(|(k, v)| match (k.as_str(), v.as_f64()) {
                (key, Some(ts)) if key == TIMESTEP_KEY => {
                    (k.clone(), SettingValue::Float(ts / 2.0))
                }
                _ => (k.clone(), v.clone()),
            })
            .collect();
        let next = measure(&format!("halving-{halving}"), &finer, 1)?;
        let Ok(next_traj) = trajectories_of(&next) else {
            break;
        };
        let by_scene: Vec<f64> = next_traj
            .iter()
            .zip(&trajectories)
            .map(|(a, b)| {
                deviation(a, b).map_or(f64::INFINITY, |m| {
                    m.into_values().map(|v| v[0]).fold(0.0, f64::max)
                })
            })
            .collect();
        let change = by_scene.iter().copied().fold(0.0, f64::max);
        let ts = finer
            .iter()
            .find(|(k, _)| k == TIMESTEP_KEY)
            .and_then(|(_, v)| v.as_f64())
            .unwrap_or(f64::NAN);
        say(format!(
            "  reference: timestep {ts} s changes the runs by {change:.3e} m"
        ));
        halvings.push(Halving {
            timestep_s: ts,
            change_m: change,
            change_by_scene_m: by_scene,
        });
        (overlay, point, trajectories) = (finer, next, next_traj);
        if change < threshold_m {
            converged = true;
            break;
        }
    }
    Ok(Reference {
        finest_set: set_args(engine.name(), finest),
        point,
        halvings,
        converged,
        threshold_m,
        trajectories,
    })
}

/// Fills `gap_m` of every point (and the reference) that completed a
/// study scene: the accumulated error of its wrist against the real arm's
/// mean, by the analysis `compare` uses (default mode, no bootstrap).
/// Returns notes on what could not be measured.
fn measure_gaps(points: &mut [&mut Point], data: &Path, out: &Path) -> Result<Vec<String>> {
    let path = assets_dir().join("studies/collins2019.toml");
    let mut study = Study::from_toml_str(COLLINS2019, &path)?;
    study.sources.clear();
    let names: Vec<String> = points
        .first()
        .map(|p| p.scenes.iter().map(|s| s.scene.clone()).collect())
        .unwrap_or_default();
    let notes: Vec<String> = names
        .iter()
        .filter(|n| !study.scenes.iter().any(|s| &s.name == *n))
        .map(|n| format!("scene {n} is not one of the study's: no gap to the real arm"))
        .collect();
    for s in &mut study.scenes {
        s.sources.clear();
    }
    let roots = Roots {
        data: data.to_path_buf(),
        results: out.to_path_buf(),
    };
    let loaded = study.load(&roots)?;
    let opts = CompareOptions {
        bootstrap: Some(BootstrapOptions {
            resamples: 0,
            ..BootstrapOptions::default()
        }),
        ..CompareOptions::default()
    };
    // The capture frame is registered from every scene's real runs at
    // once, so all study scenes go in, those not swept without sources.
    let sources: Vec<Vec<SourceRuns>> = loaded
        .iter()
        .map(|l| match names.iter().position(|n| *n == l.spec.name) {
            Some(si) => gap_sources(points, si, study.control_period_s),
            None => vec![],
        })
        .collect();
    let inputs: Vec<_> = loaded
        .iter()
        .zip(&sources)
        .map(|(l, s)| realitygap_analysis::SceneInput {
            spec: &l.spec,
            reference: &l.reference,
            sources: s,
        })
        .collect();
    let reports = realitygap_analysis::evaluate_study(&inputs, &opts)?;
    for report in &reports {
        let Some(si) = names.iter().position(|n| *n == report.scene) else {
            continue;
        };
        for summary in &report.sources {
            let Some(pi) = summary
                .source
                .strip_prefix('p')
                .and_then(|i| i.parse::<usize>().ok())
            else {
                continue;
            };
            if let Some(p) = points.get_mut(pi) {
                p.scenes[si].gap_m = summary.accumulated_error_m;
            }
        }
    }
    // A point's gap is over the study's scenes it ran (the others have no
    // real arm to compare with); none when it ran none of them.
    let in_study: Vec<usize> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| study.scenes.iter().any(|s| &s.name == *n))
        .map(|(i, _)| i)
        .collect();
    for p in points.iter_mut() {
        p.gap_m = if in_study.is_empty() {
            None
        } else {
            in_study
                .iter()
                .map(|&si| p.scenes[si].gap_m)
                .sum::<Option<f64>>()
        };
    }
    Ok(notes)
}

/// The completed runs of scene `si`, one source per point (`p<index>`).
fn gap_sources(points: &[&mut Point], si: usize, period_s: f64) -> Vec<SourceRuns> {
    points
        .iter()
        .enumerate()
        .filter_map(|(pi, p)| {
            let s = &p.scenes[si];
            let t = s.trajectory.clone().filter(|_| s.status == "ok")?;
            Some(SourceRuns {
                name: format!("p{pi}"),
                kind: "simulated".into(),
                rate_hz: 1.0 / period_s,
                alignment: None,
                runs: vec![RunInput {
                    id: "run000".into(),
                    trajectory: t,
                    failed: None,
                }],
            })
        })
        .collect()
}

/// The fastest point within the tolerance.
fn recommend(points: &[Point]) -> Option<usize> {
    points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.within_tolerance && p.cpu_s.is_finite())
        .min_by(|a, b| a.1.cpu_s.total_cmp(&b.1.cpu_s))
        .map(|(i, _)| i)
}

fn figure(
    stem: &str,
    title: String,
    y_label: &str,
    points: &[Point],
    value: fn(&Point) -> Option<f64>,
    tolerance_m: Option<f64>,
    recommended: Option<usize>,
) -> FrontierFigure {
    // A diverged or failed point is drawn as a cross at the top of the plot.
    let top = points
        .iter()
        .filter_map(value)
        .filter(|v| v.is_finite())
        .fold(f64::NAN, f64::max);
    FrontierFigure {
        stem: stem.into(),
        title,
        y_label: y_label.into(),
        points: points
            .iter()
            .map(|p| FrontierPoint {
                label: p.label.clone(),
                group: p.group.clone(),
                real_time_factor: p.real_time_factor,
                value_m: if p.status == "ok" {
                    value(p)
                } else {
                    Some(top).filter(|t| t.is_finite())
                },
                diverged: p.status != "ok",
            })
            .collect(),
        tolerance_m,
        recommended,
    }
}

/// The grid of the command line, or the engine's default; every point
/// checked against every scene, so that a bad key or value is one error
/// naming `--sweep` before anything runs. Values the engine accepts but
/// that fail at run time (a diverging timestep) are measured and recorded.
fn grid(args: &FrontierSpec, engine: &dyn Engine, cases: &[SceneCase]) -> Result<Vec<Overlay>> {
    let points = if args.sweep.is_empty() {
        default_grid(engine.name())?
    } else {
        cross(&parse_sweeps(&args.sweep, engine)?)
    };
    for p in &points {
        for case in cases {
            settings_for(case, engine, p).with_context(|| {
                format!(
                    "--sweep: the setting {} in scene {}",
                    set_args(engine.name(), p).join(" "),
                    case.scene.name
                )
            })?;
        }
    }
    Ok(points)
}

/// Writes the reference's runs as results directories
/// `OUT/reference/<scene>/<engine>/` (run000.csv), to compare other runs
/// with.
fn write_reference(out: &Path, engine: &dyn Engine, reference: &Reference) -> Result<()> {
    for (s, t) in reference.point.scenes.iter().zip(&reference.trajectories) {
        let dir = out.join("reference").join(&s.scene).join(engine.name());
        let mut store =
            RunStore::create_or_open(&dir, engine.name(), SourceKind::Simulated, Some(&s.scene))?;
        store.set_engine(EngineInfo {
            name: engine.name().to_string(),
            version: engine.version(),
        })?;
        store.set_settings(serde_json::json!({ "set": reference.point.set }))?;
        store
            .write_run(RunEntry::new("run000"), t)
            .with_context(|| format!("writing the reference run into {}", dir.display()))?;
    }
    Ok(())
}

/// The recommended setting as a parameters file (`[engine.NAME]`).
fn params_file(engine: &str, point: &Point, tolerance_mm: f64) -> String {
    let mut params = PhysicalParams::none();
    params
        .engine_settings
        .insert(engine.to_string(), point.overlay.iter().cloned().collect());
    format!(
        "# realitygap frontier: the fastest {engine} setting within {tolerance_mm} mm of the converged reference\n# ({}); use with `realitygap run --params`.\n{}",
        point.label,
        params.to_toml_string()
    )
}

/// Runs the sweep with `engine` and writes every output into `args.out`.
pub fn run(args: &FrontierSpec, engine: &dyn Engine) -> Result<()> {
    if !(args.tolerance_mm.is_finite() && args.tolerance_mm > 0.0) {
        bail!(
            "--tolerance-mm {}: expected a positive number of millimetres",
            args.tolerance_mm
        );
    }
    let tolerance_m = args.tolerance_mm * 1e-3;
    let cases = load_scenes(&args.scenes, engine)?;
    let mut overlays = grid(args, engine, &cases)?;
    let finest = finest(&overlays).cloned().unwrap_or_default();
    overlays.push(vec![]); // the scene's own setting
    let data = match &args.data {
        Some(d) => d.resolve()?,
        None => None,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;

    let (reference, mut points) = sweep(args, engine, &cases, &overlays, &finest, tolerance_m)?;
    let mut reference = reference;
    score(
        &mut reference.point,
        &reference.trajectories.clone(),
        tolerance_m,
    );
    let notes = match &data {
        Some(d) => {
            let mut all: Vec<&mut Point> = points.iter_mut().collect();
            all.push(&mut reference.point);
            measure_gaps(&mut all, d, &args.out)?
        }
        None => vec![],
    };
    write_outputs(args, engine, &reference, &points, data.as_deref(), notes)
}

/// Measures the reference (converging) and then every point, here or on
/// Slurm (`args.executor`); the reference and the scored points.
fn sweep(
    args: &FrontierSpec,
    engine: &dyn Engine,
    cases: &[SceneCase],
    overlays: &[Overlay],
    finest: &Overlay,
    tolerance_m: f64,
) -> Result<(Reference, Vec<Point>)> {
    let slurm = match &args.executor {
        Executor::Slurm(options) => Some(slurm::SlurmSweep::new(
            options,
            &args.launcher,
            &args.out,
            &args.scenes,
            &*args.say,
        )?),
        Executor::Local => None,
    };
    let measure_one = |stage: &str, overlay: &Overlay, repeats: u32| -> Result<Point> {
        match &slurm {
            None => Ok(measure(cases, engine, overlay, repeats)),
            Some(s) => s
                .measure(stage, cases, engine, std::slice::from_ref(overlay), repeats)?
                .pop()
                .ok_or_else(|| anyhow!("the {stage} stage measured nothing")),
        }
    };
    (args.say)(format!(
        "frontier: {} in {} scene(s), reference from {}",
        engine.name(),
        cases.len(),
        set_args(engine.name(), finest).join(" ")
    ));
    let reference = converge(
        cases,
        engine,
        finest,
        (args.repeats, tolerance_m / 10.0, args.max_halvings),
        &measure_one,
        &args.say,
    )?;
    let measured: Box<dyn Iterator<Item = Point>> = match &slurm {
        None => Box::new(
            overlays
                .iter()
                .map(|o| measure(cases, engine, o, args.repeats)),
        ),
        Some(s) => Box::new(
            s.measure("points", cases, engine, overlays, args.repeats)?
                .into_iter(),
        ),
    };
    let points = score_points(args, overlays, measured, &reference, tolerance_m);
    Ok((reference, points))
}

/// Scores the measured points (in the order of `overlays`) against the
/// reference, saying each one's outcome as it comes.
fn score_points(
    args: &FrontierSpec,
    overlays: &[Overlay],
    measured: impl Iterator<Item = Point>,
    reference: &Reference,
    tolerance_m: f64,
) -> Vec<Point> {
    let mut points: Vec<Point> = Vec::new();
    for (i, (o, mut p)) in overlays.iter().zip(measured).enumerate() {
        if o.is_empty() {
            p.label = "scene's own setting".into();
            p.group = "scene's own".into();
        }
        score(&mut p, &reference.trajectories, tolerance_m);
        let outcome = match (p.status.as_str(), p.max_deviation_m) {
            ("ok", Some(d)) => format!("max deviation {d:.3e} m"),
            _ => p
                .scenes
                .iter()
                .find_map(|s| s.message.clone())
                .unwrap_or_else(|| p.status.clone()),
        };
        (args.say)(format!(
            "  [{}/{}] {}: {outcome}, {:.1}x real time",
            i + 1,
            overlays.len(),
            p.label,
            p.real_time_factor
        ));
        points.push(p);
    }
    points
}

/// Writes `frontier.json`, the reference runs, the figures and the
/// recommended parameters file into `--out`, and prints the outcome.
fn write_outputs(
    args: &FrontierSpec,
    engine: &dyn Engine,
    reference: &Reference,
    points: &[Point],
    data: Option<&Path>,
    notes: Vec<String>,
) -> Result<()> {
    let recommended = recommend(points);
    let json = frontier_json(args, engine, reference, points, data, notes, recommended);
    let out = &args.out;
    write_file(
        out,
        "frontier.json",
        serde_json::to_string_pretty(&json)? + "\n",
    )?;
    write_reference(out, engine, reference)?;
    write_figures(args, engine, points, data.is_some(), recommended)?;
    report_recommended(args, engine, reference, points, recommended)?;
    (args.tell)(format!("frontier: {}", out.join("frontier.json").display()));
    Ok(())
}

/// Writes `text` to `dir/name`.
fn write_file(dir: &Path, name: &str, text: String) -> Result<()> {
    std::fs::write(dir.join(name), text)
        .with_context(|| format!("cannot write {}", dir.join(name).display()))
}

/// CPU time of `over` divided by that of `p`.
fn speedup(over: &Point, p: &Point) -> f64 {
    over.cpu_s / p.cpu_s
}

/// The content of `frontier.json`.
fn frontier_json(
    args: &FrontierSpec,
    engine: &dyn Engine,
    reference: &Reference,
    points: &[Point],
    data: Option<&Path>,
    notes: Vec<String>,
    recommended: Option<usize>,
) -> serde_json::Value {
    let scene_setting = points.iter().position(|p| p.scene_setting);
    let rec_json = recommended.map(|i| {
        let p = &points[i];
        serde_json::json!({
            "point": i,
            "label": p.label,
            "settings": p.settings,
            "set": p.set,
            "cpu_s": p.cpu_s,
            "real_time_factor": p.real_time_factor,
            "max_deviation_m": p.max_deviation_m,
            "mean_deviation_m": p.mean_deviation_m,
            "gap_m": p.gap_m,
            "speedup_over_reference": speedup(&reference.point, p),
            "speedup_over_scene_setting": scene_setting.map(|s| speedup(&points[s], p)),
            "params_file": "recommended.toml",
        })
    });
    let r = &reference.point;
    serde_json::json!({
        "engine": engine.name(),
        "engine_version": engine.version(),
        "scenes": r.scenes.iter().map(|s| s.scene.clone()).collect::<Vec<_>>(),
        "tolerance_m": args.tolerance_mm * 1e-3,
        "repeats": args.repeats,
        "clock": clock_name(),
        "data": data.map(|d| d.display().to_string()),
        "reference": {
            "settings": r.settings,
            "set": r.set,
            "cpu_s": r.cpu_s,
            "real_time_factor": r.real_time_factor,
            "gap_m": r.gap_m,
            "finest_set": reference.finest_set,
            "repeats": if reference.halvings.is_empty() { args.repeats } else { 1 },
            "halvings": reference.halvings,
            "converged": reference.converged,
            "threshold_m": reference.threshold_m,
            "scenes": r.scenes,
        },
        "scene_setting": scene_setting,
        "points": points,
        "recommended": rec_json,
        "notes": notes,
    })
}

/// The deviation figure, and the gap figure when there is real data.
fn write_figures(
    args: &FrontierSpec,
    engine: &dyn Engine,
    points: &[Point],
    with_gap: bool,
    recommended: Option<usize>,
) -> Result<()> {
    let title = |what: &str| format!("{}: {what}", engine.name());
    figure(
        "frontier_deviation",
        title("max deviation from the converged reference"),
        "max deviation (m)",
        points,
        |p| p.max_deviation_m,
        Some(args.tolerance_mm * 1e-3),
        recommended,
    )
    .write(&args.out)?;
    if with_gap && points.iter().any(|p| p.gap_m.is_some()) {
        figure(
            "frontier_gap",
            title("gap to the real arm"),
            "accumulated error (m)",
            points,
            |p| p.gap_m,
            None,
            recommended,
        )
        .write(&args.out)?;
    }
    Ok(())
}

/// Writes `recommended.toml` and prints the recommendation, or says that
/// no setting is within the tolerance.
fn report_recommended(
    args: &FrontierSpec,
    engine: &dyn Engine,
    reference: &Reference,
    points: &[Point],
    recommended: Option<usize>,
) -> Result<()> {
    let Some(i) = recommended else {
        (args.tell)(format!(
            "no setting stays within {} mm of the reference; nothing recommended",
            args.tolerance_mm
        ));
        return Ok(());
    };
    let p = &points[i];
    write_file(
        &args.out,
        "recommended.toml",
        params_file(engine.name(), p, args.tolerance_mm),
    )?;
    let scene_setting = points.iter().position(|p| p.scene_setting);
    (args.tell)(format!(
        "recommended: {} ({}), max deviation {:.3} mm, {:.1}x faster than the reference{}",
        p.label,
        p.set.join(" "),
        p.max_deviation_m.unwrap_or(f64::NAN) * 1e3,
        speedup(&reference.point, p),
        scene_setting
            .filter(|&s| s != i)
            .map(|s| if same_runs(&points[s], p) {
                // A sweep value equal to the scene's own: two timings of
                // one simulation, not a speed-up.
                ", the same runs as the scene's own setting".to_string()
            } else {
                format!(
                    ", {:.1}x faster than the scene's own setting",
                    speedup(&points[s], p)
                )
            })
            .unwrap_or_default()
    ));
    Ok(())
}
