//! `realitygap run`: simulate scenes in engines, in parallel, into results
//! directories.
//!
//! Layout: `OUT/<scene name>/<source>/` with `manifest.json` and
//! `runs/run000.csv ...`, where `<source>` is the engine's name, or
//! `<engine>-<robot>` when `--robot` replaces the scene's robot.
//!
//! Every run executes in a child process (this binary, re-invoked with the
//! hidden subcommand `__run-one`, reading its job as JSON on standard input
//! and writing its trajectory as JSON on standard output). A crash, abort or
//! `exit` inside an engine's native code therefore fails only that run: it
//! is recorded as `failed` with the engine's last words, and the batch goes
//! on. The parent alone writes the results directories (atomically, run by
//! run), so an interrupted batch keeps every finished run, and a rerun skips
//! them.

use crate::cmd_engines;
use anyhow::{anyhow, bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use realitygap_core::controller::{
    load_prepared, repeat_seed, run_scene_with, ControlParams, Perturbation, RunOptions, RunStatus,
};
use realitygap_core::engine::{Engine, EngineSettings, SettingValue};
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::{BodyTrack, Trajectory};
use realitygap_data::runstore::{
    EngineInfo, RunEntry, RunStatus as StoreStatus, RunStore, SourceKind,
};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

/// The project's Mico2 description, built into the binary for `--robot mico2`.
const MICO2_URDF: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../assets/robots/mico2/mico2.urdf"
));

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
    /// friction_scale (see the README). Off by default.
    #[arg(long = "perturb", value_name = "KEY=VALUE,...")]
    pub perturb: Vec<String>,
    /// Engine setting overriding the scene's: key=value for every engine,
    /// or engine.key=value (e.g. mujoco.timestep_s=0.0005).
    #[arg(long = "set", value_name = "[ENGINE.]KEY=VALUE")]
    pub set: Vec<String>,
    /// Give up on a run after this many seconds (recorded as failed).
    #[arg(long, value_name = "SECONDS")]
    pub timeout_s: Option<f64>,
    /// Physical parameters (TOML: [joints.NAME], [links.NAME],
    /// [objects.NAME], [contact], [controller], [engine.NAME]; see the
    /// README). `--set` still overrides its engine settings.
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
}

/// One run as the child process receives it.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Job {
    scene_file: PathBuf,
    engine: String,
    robot: Option<String>,
    packages: Vec<String>,
    set: Vec<String>,
    perturb: Vec<String>,
    seed: u64,
    /// The parameters file, absolute.
    #[serde(default)]
    params: Option<PathBuf>,
    /// Only load the model and report success.
    check_only: bool,
}

/// What the child process sends back. Numbers travel as their IEEE bits so
/// that the stored run is exactly the simulated one.
#[derive(Debug, Serialize, Deserialize)]
struct ChildResult {
    diverged: Option<(f64, String)>,
    engine_steps: u64,
    wall_time_s: f64,
    roles: Vec<String>,
    time_s: Vec<u64>,
    /// `[body][sample]`: x y z qw qx qy qz.
    poses: Vec<Vec<[u64; 7]>>,
    joint_angles_rad: Vec<Vec<u64>>,
    commands_rad_s: Vec<Vec<u64>>,
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn unbits(v: &[u64]) -> Vec<f64> {
    v.iter().map(|&b| f64::from_bits(b)).collect()
}

impl ChildResult {
    fn from_outcome(out: &realitygap_core::controller::RunOutcome) -> ChildResult {
        let t = &out.trajectory;
        ChildResult {
            diverged: match &out.status {
                RunStatus::Completed => None,
                RunStatus::Diverged { t_s, reason } => Some((*t_s, reason.clone())),
            },
            engine_steps: out.engine_steps,
            wall_time_s: out.wall_time_s,
            roles: t.bodies.iter().map(|b| b.role.clone()).collect(),
            time_s: bits(&t.time_s),
            poses: t
                .bodies
                .iter()
                .map(|b| {
                    b.poses
                        .iter()
                        .map(|p| {
                            let p = p.unwrap_or(Pose::IDENTITY);
                            let (v, q) = (p.position_m, p.orientation);
                            [v.x, v.y, v.z, q.w, q.x, q.y, q.z].map(f64::to_bits)
                        })
                        .collect()
                })
                .collect(),
            joint_angles_rad: t
                .joint_angles_rad
                .iter()
                .flatten()
                .map(|r| bits(r))
                .collect(),
            commands_rad_s: t
                .joint_velocity_commands_rad_s
                .iter()
                .flatten()
                .map(|r| bits(r))
                .collect(),
        }
    }

    fn trajectory(&self) -> Result<Trajectory> {
        let t = Trajectory {
            time_s: unbits(&self.time_s),
            bodies: self
                .roles
                .iter()
                .zip(&self.poses)
                .map(|(role, poses)| BodyTrack {
                    role: role.clone(),
                    poses: poses
                        .iter()
                        .map(|p| {
                            let v = p.map(f64::from_bits);
                            Some(Pose::new(
                                Vec3::new(v[0], v[1], v[2]),
                                Quat::new(v[3], v[4], v[5], v[6]),
                            ))
                        })
                        .collect(),
                })
                .collect(),
            joint_angles_rad: Some(self.joint_angles_rad.iter().map(|r| unbits(r)).collect()),
            joint_velocity_commands_rad_s: Some(
                self.commands_rad_s.iter().map(|r| unbits(r)).collect(),
            ),
        };
        t.validate()
            .map_err(|e| anyhow!("the run's trajectory is inconsistent: {e}"))?;
        Ok(t)
    }
}

/// A scene, robot, engine and settings, checked and ready to load.
struct Prepared {
    scene: Scene,
    robot: RobotModel,
    engine: Box<dyn Engine>,
    settings: EngineSettings,
    params: PhysicalParams,
    timestep_s: f64,
    steps_per_period: u64,
}

/// The robot a `--robot` value names, with a short label for directory
/// names; `None` keeps the scene's robot.
fn robot_override(
    choice: Option<&str>,
    resolver: &PackageResolver,
) -> Result<Option<(RobotModel, PathBuf, String)>> {
    let Some(choice) = choice else {
        return Ok(None);
    };
    match choice {
        "mico2" => {
            let source = PathBuf::from("mico2.urdf (built in)");
            let robot = RobotModel::from_urdf_str(MICO2_URDF, &source, resolver)
                .map_err(|e| anyhow!("the built-in Mico2 description: {e}"))?;
            Ok(Some((robot, source, "mico2".to_string())))
        }
        "official" => {
            let dir = resolver.find("kinova_description").map_err(|searched| {
                anyhow!(
                    "--robot official needs the kinova_description package (looked in: {}); pass --package kinova_description=DIR, e.g. a copy of the study data's kinova_description, or set ROS_PACKAGE_PATH",
                    if searched.is_empty() { "nowhere".to_string() } else { searched.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ") }
                )
            })?;
            let path = dir.join("urdf/m1n6s300.urdf");
            let robot = RobotModel::from_urdf_file(&path, resolver)?;
            Ok(Some((robot, path, "official".to_string())))
        }
        path => {
            let path = PathBuf::from(path);
            let robot = RobotModel::from_urdf_file(&path, resolver)?;
            let label = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "robot".into());
            let label: String = label
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || "_-.".contains(c) {
                        c
                    } else {
                        '_'
                    }
                })
                .collect();
            Ok(Some((robot, path, label)))
        }
    }
}

/// `--robot official` with no kinova_description package given or on
/// ROS_PACKAGE_PATH: adds the one of the study data built in. When that
/// cannot be had either, says why and leaves the arguments as they are
/// (loading the robot then fails naming where it looked).
fn with_builtin_kinova(mut args: Args) -> Result<Args> {
    if args.robot.as_deref() != Some("official")
        || resolver(&args.packages)?.find("kinova_description").is_ok()
    {
        return Ok(args);
    }
    match realitygap::data_source::builtin_data_dir() {
        Ok(dir) => args.packages.push(format!(
            "kinova_description={}",
            dir.join("kinova_description").display()
        )),
        Err(e) => eprintln!("warning: the built-in kinova_description cannot be used: {e:#}"),
    }
    Ok(args)
}

fn resolver(packages: &[String]) -> Result<PackageResolver> {
    let mut r = PackageResolver::from_env();
    for p in packages {
        r.insert_arg(p)?;
    }
    Ok(r)
}

/// The `--set` values that apply to `engine`, checked for form and for
/// engine prefixes that name no compiled-in engine.
fn overrides_for(set: &[String], engine: &str) -> Result<EngineSettings> {
    let known: Vec<String> = cmd_engines::compiled()
        .iter()
        .map(|e| e.name().to_string())
        .collect();
    let mut out = EngineSettings::new();
    for s in set {
        let (key, value) = s
            .split_once('=')
            .ok_or_else(|| anyhow!("--set \"{s}\": expected KEY=VALUE or ENGINE.KEY=VALUE"))?;
        let key = key.trim();
        let (target, key) = match key.split_once('.') {
            Some((e, k)) => {
                if !known.iter().any(|n| n == e) {
                    bail!(
                        "--set \"{s}\": \"{e}\" is not a compiled-in engine (compiled in: {})",
                        known.join(", ")
                    );
                }
                (Some(e), k)
            }
            None => (None, key),
        };
        if key.is_empty() {
            bail!("--set \"{s}\": the key is empty");
        }
        if target.is_none_or(|e| e == engine) {
            out.insert(key.to_string(), SettingValue::parse(value));
        }
    }
    Ok(out)
}

fn parse_perturbation(specs: &[String]) -> Result<Perturbation> {
    let mut p = Perturbation::default();
    for s in specs {
        p.parse_into(s)?;
    }
    Ok(p)
}

/// Reads a parameters file, or none.
pub(crate) fn read_params(path: Option<&Path>) -> Result<PhysicalParams> {
    match path {
        Some(p) => Ok(PhysicalParams::from_file(p)?),
        None => Ok(PhysicalParams::none()),
    }
}

fn prepare(
    scene_file: &Path,
    engine: &str,
    robot: Option<&str>,
    packages: &[String],
    set: &[String],
    params_file: Option<&Path>,
) -> Result<Prepared> {
    let engine = cmd_engines::find(engine)?;
    let mut scene = Scene::from_file(scene_file)?;
    let resolver = resolver(packages)?;
    let robot = match robot_override(robot, &resolver)? {
        Some((robot, path, _)) => {
            scene.set_robot_urdf(path);
            robot
        }
        None => RobotModel::from_urdf_file(&scene.robot.urdf, &resolver)
            .with_context(|| format!("the robot of scene {}", scene_file.display()))?,
    };
    scene.validate(&robot)?;
    let params = read_params(params_file)?;
    let (scene, robot) =
        realitygap_core::controller::prepare(engine.as_ref(), &scene, &robot, &params)
            .map_err(|e| anyhow!("{e}"))
            .with_context(|| format!("scene {} with --params", scene_file.display()))?;
    let mut settings = params.settings_over(engine.name(), &scene.settings_for(engine.name()));
    settings.extend(overrides_for(set, engine.name())?);
    let timestep_s = engine.check_settings(&settings).with_context(|| {
        format!(
            "scene {} ([engine.{}], --params and --set)",
            scene_file.display(),
            engine.name()
        )
    })?;
    let steps_per_period = scene.steps_per_period(timestep_s)?;
    Ok(Prepared {
        scene,
        robot,
        engine,
        settings,
        params,
        timestep_s,
        steps_per_period,
    })
}

/// `realitygap __run-one`: reads a [`Job`] as JSON on standard input, runs
/// it, writes a [`ChildResult`] as JSON on standard output.
pub fn run_one() -> Result<()> {
    #[cfg(target_os = "linux")]
    die_with_parent();
    cmd_engines::install_native_handlers();
    let mut input = String::new();
    std::io::stdin()
        .read_to_string(&mut input)
        .context("reading the job from standard input")?;
    let job: Job =
        serde_json::from_str(&input).context("the job on standard input is not valid")?;
    let p = prepare(
        &job.scene_file,
        &job.engine,
        job.robot.as_deref(),
        &job.packages,
        &job.set,
        job.params.as_deref(),
    )?;
    let perturbation = parse_perturbation(&job.perturb)?;
    let sample =
        (!perturbation.is_none()).then(|| perturbation.sample(job.seed, p.scene.actuators.len()));
    let options = RunOptions {
        perturbation: sample,
        ..RunOptions::default()
    };
    let mut sim = load_prepared(
        p.engine.as_ref(),
        &p.scene,
        &p.robot,
        &p.settings,
        &p.params,
        &options,
    )?;
    if job.check_only {
        return Ok(());
    }
    let control = ControlParams::from_params(&p.params, &p.scene);
    let outcome = run_scene_with(sim.as_mut(), &p.scene, &options, &control)?;
    let text = serde_json::to_string(&ChildResult::from_outcome(&outcome))?;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|_| out.flush())
        .context("writing the result to standard output")?;
    Ok(())
}

/// Ends this child process when the parent dies (Linux), so that killing a
/// batch does not leave simulations running.
#[cfg(target_os = "linux")]
fn die_with_parent() {
    extern "C" {
        fn prctl(option: i32, arg2: u64, arg3: u64, arg4: u64, arg5: u64) -> i32;
        fn getppid() -> i32;
    }
    const PR_SET_PDEATHSIG: i32 = 1;
    const SIGKILL: u64 = 9;
    // SAFETY: plain system calls with integer arguments.
    unsafe {
        prctl(PR_SET_PDEATHSIG, SIGKILL, 0, 0, 0);
        if getppid() == 1 {
            std::process::exit(1);
        }
    }
}

/// How one child process ended.
enum ChildEnd {
    Done(Box<ChildResult>),
    Failed(String),
}

fn last_lines(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(n)..].join(" | ")
}

fn describe_exit(status: std::process::ExitStatus) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(sig) = status.signal() {
            let name = match sig {
                4 => " (SIGILL)",
                6 => " (SIGABRT, abort)",
                7 => " (SIGBUS)",
                8 => " (SIGFPE)",
                9 => " (SIGKILL)",
                11 => " (SIGSEGV, invalid memory access)",
                15 => " (SIGTERM)",
                _ => "",
            };
            return format!("killed by signal {sig}{name}");
        }
    }
    match status.code() {
        Some(c) => format!("exited with code {c}"),
        None => "ended abnormally".to_string(),
    }
}

/// Runs `job` in a child process of this binary.
fn run_child(job: &Job, timeout_s: Option<f64>) -> ChildEnd {
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => return ChildEnd::Failed(format!("cannot find this program to start a run: {e}")),
    };
    let mut child = match Command::new(exe)
        .arg("__run-one")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
    {
        Ok(c) => c,
        Err(e) => return ChildEnd::Failed(format!("cannot start a child process: {e}")),
    };
    let input = serde_json::to_vec(job).expect("a job always serialises");
    if let Some(mut stdin) = child.stdin.take() {
        // A child that dies at once closes its stdin; its exit status says why.
        let _ = stdin.write_all(&input);
    }
    let mut stdout = child.stdout.take().expect("piped");
    let mut stderr = child.stderr.take().expect("piped");
    let out_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stdout.read_to_end(&mut buf);
        buf
    });
    let err_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stderr.read_to_end(&mut buf);
        buf
    });
    let start = Instant::now();
    let mut timed_out = false;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Some(status),
            Ok(None) => {}
            Err(e) => return ChildEnd::Failed(format!("waiting for the run: {e}")),
        }
        if timeout_s.is_some_and(|t| start.elapsed().as_secs_f64() > t) {
            let _ = child.kill();
            let _ = child.wait();
            timed_out = true;
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = out_reader.join().unwrap_or_default();
    let err = String::from_utf8_lossy(&err_reader.join().unwrap_or_default()).into_owned();
    if timed_out {
        return ChildEnd::Failed(format!("timed out after {} s", timeout_s.unwrap_or(0.0)));
    }
    let status = status.expect("set unless timed out");
    if status.success() {
        if job.check_only {
            return ChildEnd::Done(Box::new(ChildResult {
                diverged: None,
                engine_steps: 0,
                wall_time_s: 0.0,
                roles: vec![],
                time_s: vec![],
                poses: vec![],
                joint_angles_rad: vec![],
                commands_rad_s: vec![],
            }));
        }
        match serde_json::from_slice::<ChildResult>(&out) {
            Ok(r) => ChildEnd::Done(Box::new(r)),
            Err(e) => ChildEnd::Failed(format!(
                "the run's output could not be read ({e}); stderr: {}",
                last_lines(&err, 5)
            )),
        }
    } else {
        let err: String = err
            .lines()
            .map(|l| l.strip_prefix("error: ").unwrap_or(l))
            .collect::<Vec<_>>()
            .join("\n");
        let said = last_lines(&err, 5);
        let said = if said.is_empty() {
            "no message".to_string()
        } else {
            said
        };
        ChildEnd::Failed(format!("{}: {said}", describe_exit(status)))
    }
}

/// One (scene, engine) results directory of the batch.
struct Group {
    scene_file: PathBuf,
    scene_name: String,
    engine: String,
    source: String,
    store: RunStore,
    pending: Vec<u32>,
    load_error: Option<String>,
    done: [usize; 3],
}

fn run_id(repeat: u32) -> String {
    format!("run{repeat:03}")
}

/// `realitygap run`.
pub fn run(args: Args) -> Result<()> {
    let batch_start = Instant::now();
    let args = with_builtin_kinova(args)?;
    let engines: Vec<String> = if args.engines.is_empty() {
        let all: Vec<String> = cmd_engines::compiled()
            .iter()
            .map(|e| e.name().to_string())
            .collect();
        if all.is_empty() {
            bail!("no physics engine is compiled into this binary (build it with `--features mujoco`)");
        }
        all
    } else {
        let mut v = args.engines.clone();
        v.dedup();
        v
    };
    let perturbation = parse_perturbation(&args.perturb)?;
    let params_file = match &args.params {
        Some(p) => {
            Some(std::path::absolute(p).with_context(|| format!("--params {}", p.display()))?)
        }
        None => None,
    };
    let resolver = resolver(&args.packages)?;
    // Resolve the robot once, for its label and early errors.
    let robot_label = robot_override(args.robot.as_deref(), &resolver)?.map(|(_, _, label)| label);
    let jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);

    // Check everything and open the results directories before running.
    let mut groups: Vec<Group> = Vec::new();
    for scene_file in &args.scenes {
        for engine in &engines {
            let p = prepare(
                scene_file,
                engine,
                args.robot.as_deref(),
                &args.packages,
                &args.set,
                params_file.as_deref(),
            )?;
            let source = match &robot_label {
                Some(label) => format!("{engine}-{label}"),
                None => engine.clone(),
            };
            if groups
                .iter()
                .any(|g| g.scene_name == p.scene.name && g.source == source)
            {
                bail!(
                    "scene \"{}\" is given twice (scene names must be unique in a batch)",
                    p.scene.name
                );
            }
            let dir = args.out.join(&p.scene.name).join(&source);
            let mut store = RunStore::create_or_open(
                &dir,
                &source,
                SourceKind::Simulated,
                Some(&p.scene.name),
            )?;
            let config = serde_json::json!({
                "scene_file": p.scene.source.display().to_string(),
                "robot": {
                    "urdf": p.scene.robot.urdf.display().to_string(),
                    "mjcf": p.scene.robot.mjcf.as_ref().map(|m| m.display().to_string()),
                    "label": robot_label.clone().unwrap_or_else(|| "scene".to_string()),
                    "name": p.robot.name,
                },
                "engine_settings": p.settings.iter().map(|(k, v)| (k.clone(), setting_json(v))).collect::<serde_json::Map<_, _>>(),
                "timestep_s": p.timestep_s,
                "steps_per_control_period": p.steps_per_period,
                "controller": {
                    "gain_per_s": p.scene.controller.gain_per_s,
                    "max_speed_deg_s": p.scene.controller.max_speed_deg_s,
                    "period_s": p.scene.controller.period_s,
                },
                "duration_s": p.scene.duration_s,
                "samples_per_run": p.scene.sample_count(),
                "seed": args.seed,
                "params_file": params_file.as_ref().map(|p| p.display().to_string()),
                "params": serde_json::to_value(&p.params)?,
                "perturbation": perturbation.describe(),
                "deterministic": perturbation.is_none(),
            });
            let existing = store.manifest().settings.get("config").cloned();
            if let Some(old) = existing.filter(|_| !store.runs().is_empty()) {
                if old != config {
                    bail!(
                        "{} holds runs made with other settings (scene, robot, engine settings, seed or perturbation differ); use another --out directory or remove it",
                        dir.display()
                    );
                }
            }
            store.set_engine(EngineInfo {
                name: p.engine.name().to_string(),
                version: p.engine.version(),
            })?;
            let mut settings = store.manifest().settings.clone();
            if !settings.is_object() {
                settings = serde_json::json!({});
            }
            settings["config"] = config;
            settings["repeats"] = serde_json::json!(args
                .repeats
                .max(settings["repeats"].as_u64().unwrap_or(0) as u32));
            store.set_settings(settings)?;
            let pending: Vec<u32> = (0..args.repeats)
                .filter(|&r| !store.has_finished_run(&run_id(r)))
                .collect();
            groups.push(Group {
                scene_file: scene_file.clone(),
                scene_name: p.scene.name.clone(),
                engine: engine.clone(),
                source,
                store,
                pending,
                load_error: None,
                done: [0; 3],
            });
        }
    }

    let job_for = |g: &Group, repeat: u32, check_only: bool| Job {
        scene_file: g.scene_file.clone(),
        engine: g.engine.clone(),
        robot: args.robot.clone(),
        packages: args.packages.clone(),
        set: args.set.clone(),
        perturb: args.perturb.clone(),
        seed: repeat_seed(args.seed, repeat as u64),
        params: params_file.clone(),
        check_only,
    };

    // Load each model once in a child before its batch: a model the engine
    // rejects is one clear error, not one failure per repeat.
    for g in groups.iter_mut().filter(|g| !g.pending.is_empty()) {
        if let ChildEnd::Failed(message) = run_child(&job_for(g, 0, true), args.timeout_s) {
            g.load_error = Some(message);
        }
    }

    let skipped: usize = groups
        .iter()
        .map(|g| args.repeats as usize - g.pending.len())
        .sum();
    let total: usize = groups
        .iter()
        .filter(|g| g.load_error.is_none())
        .map(|g| g.pending.len())
        .sum();
    let bar = ProgressBar::new(total as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} runs ({eta} left) {msg}",
        )
        .expect("a valid template"),
    );
    if skipped > 0 {
        bar.println(format!(
            "{skipped} finished runs kept from an earlier batch"
        ));
    }
    let mut batch = Batch {
        groups: &mut groups,
        job_for: &job_for,
        workers: jobs,
        timeout_s: args.timeout_s,
        seed: (!perturbation.is_none()).then_some(args.seed),
        bar: &bar,
        stats: BatchStats::default(),
    };
    // Deterministic repeats are simulated twice; when the two are
    // identical, the others are recorded as copies of the first.
    let (first, deferred) = split_for_copies(batch.groups, perturbation.is_none());
    batch.execute(first)?;
    let rest = batch.copy_or_simulate(deferred)?;
    batch.execute(rest)?;
    let BatchStats {
        failures,
        steps_total,
        loop_time_total,
        simulated,
    } = batch.stats;
    bar.finish_and_clear();

    let batch_wall_s = batch_start.elapsed().as_secs_f64();
    let mut load_failures = Vec::new();
    for g in &mut groups {
        let mut settings = g.store.manifest().settings.clone();
        let ran = g.done.iter().sum::<usize>();
        if ran > 0 {
            settings["last_batch"] = serde_json::json!({
                "runs": ran,
                "jobs": jobs,
                "wall_time_s": batch_wall_s,
                "steps_per_second": if loop_time_total > 0.0 { (steps_total as f64 / loop_time_total).round() } else { 0.0 },
            });
            g.store.set_settings(settings)?;
        }
        let dir = g.store.dir().display().to_string();
        match &g.load_error {
            Some(e) => {
                say(format!("{}/{}: not run: {e}", g.scene_name, g.source));
                load_failures.push(format!("{}/{}", g.scene_name, g.source));
            }
            None => say(format!(
                "{}/{}: {} ok, {} diverged, {} failed, {} kept -> {dir}",
                g.scene_name,
                g.source,
                g.done[0],
                g.done[1],
                g.done[2],
                args.repeats as usize - g.pending.len()
            )),
        }
    }
    if steps_total > 0 {
        say(format!(
            "{total} runs ({simulated} simulated, {} copies of identical deterministic runs) in {batch_wall_s:.1} s with {jobs} jobs ({:.0} engine steps/s per run)",
            total - simulated,
            if loop_time_total > 0.0 {
                steps_total as f64 / loop_time_total
            } else {
                0.0
            }
        ));
    }
    if !load_failures.is_empty() {
        bail!("the engine could not load {}", load_failures.join(", "));
    }
    if failures > 0 {
        bail!("{failures} of {total} runs failed (their messages are in the manifests); rerun the same command to retry them");
    }
    Ok(())
}

/// Counts of one batch.
#[derive(Default)]
struct BatchStats {
    failures: usize,
    steps_total: u64,
    loop_time_total: f64,
    simulated: usize,
}

/// The runs of one `realitygap run` being executed: the results
/// directories, how to make a child's job, and the progress shown.
struct Batch<'a> {
    groups: &'a mut [Group],
    job_for: &'a dyn Fn(&Group, u32, bool) -> Job,
    workers: usize,
    timeout_s: Option<f64>,
    /// The batch seed, recorded per run when repeats are perturbed.
    seed: Option<u64>,
    bar: &'a ProgressBar,
    stats: BatchStats,
}

/// For a deterministic batch, the first two pending repeats of each group
/// (simulated now) and the rest (decided by [`Batch::copy_or_simulate`]);
/// otherwise every pending repeat now.
fn split_for_copies(
    groups: &[Group],
    deterministic: bool,
) -> (Vec<(usize, u32)>, Vec<(usize, Vec<u32>)>) {
    let mut first = Vec::new();
    let mut deferred = Vec::new();
    for (i, g) in groups
        .iter()
        .enumerate()
        .filter(|(_, g)| g.load_error.is_none())
    {
        let now = if deterministic {
            g.pending.len().min(2)
        } else {
            g.pending.len()
        };
        first.extend(g.pending[..now].iter().map(|&r| (i, r)));
        if now < g.pending.len() {
            deferred.push((i, g.pending[now..].to_vec()));
        }
    }
    (first, deferred)
}

impl Batch<'_> {
    /// Runs `runs` in child processes, `workers` at a time, storing each
    /// as it finishes.
    fn execute(&mut self, runs: Vec<(usize, u32)>) -> Result<()> {
        if runs.is_empty() {
            return Ok(());
        }
        let jobs: VecDeque<((usize, u32), Job)> = runs
            .iter()
            .map(|&(g, r)| ((g, r), (self.job_for)(&self.groups[g], r, false)))
            .collect();
        let count = jobs.len();
        let queue = Arc::new(Mutex::new(jobs));
        let (tx, rx) = mpsc::channel::<((usize, u32), ChildEnd, f64)>();
        let workers: Vec<_> = (0..self.workers.min(count))
            .map(|_| {
                let queue = Arc::clone(&queue);
                let tx = tx.clone();
                let timeout_s = self.timeout_s;
                std::thread::spawn(move || loop {
                    let next = queue.lock().map(|mut q| q.pop_front()).unwrap_or(None);
                    let Some((key, job)) = next else { break };
                    let start = Instant::now();
                    let end = run_child(&job, timeout_s);
                    if tx.send((key, end, start.elapsed().as_secs_f64())).is_err() {
                        break;
                    }
                })
            })
            .collect();
        drop(tx);
        for ((gi, repeat), end, elapsed_s) in rx {
            self.store(gi, repeat, end, elapsed_s)?;
        }
        for w in workers {
            let _ = w.join();
        }
        Ok(())
    }

    /// Stores one child's result in its group's results directory.
    fn store(&mut self, gi: usize, repeat: u32, end: ChildEnd, elapsed_s: f64) -> Result<()> {
        let g = &mut self.groups[gi];
        let id = run_id(repeat);
        let mut entry = RunEntry::new(&id);
        if let Some(seed) = self.seed {
            entry.seed = Some(repeat_seed(seed, repeat as u64));
        }
        entry
            .extra
            .insert("repeat".into(), serde_json::json!(repeat));
        self.stats.simulated += 1;
        let stored = match end {
            ChildEnd::Done(result) => match result.trajectory() {
                Ok(trajectory) => {
                    entry.wall_time_s = Some(result.wall_time_s);
                    let sps = if result.wall_time_s > 0.0 {
                        result.engine_steps as f64 / result.wall_time_s
                    } else {
                        0.0
                    };
                    for (k, v) in [
                        ("engine_steps", serde_json::json!(result.engine_steps)),
                        ("steps_per_second", serde_json::json!(sps.round())),
                        ("process_wall_time_s", serde_json::json!(elapsed_s)),
                        ("samples", serde_json::json!(trajectory.len())),
                    ] {
                        entry.extra.insert(k.into(), v);
                    }
                    self.stats.steps_total += result.engine_steps;
                    self.stats.loop_time_total += result.wall_time_s;
                    if let Some((t_s, reason)) = &result.diverged {
                        entry.status = StoreStatus::Diverged;
                        entry.message = Some(format!("diverged at t = {t_s:.4} s: {reason}"));
                        entry
                            .extra
                            .insert("diverged_at_s".into(), serde_json::json!(t_s));
                        g.done[1] += 1;
                    } else {
                        g.done[0] += 1;
                    }
                    g.store.write_run(entry, &trajectory)
                }
                Err(e) => {
                    entry.message = Some(e.to_string());
                    self.stats.failures += 1;
                    g.done[2] += 1;
                    g.store.record_failed_run(entry)
                }
            },
            ChildEnd::Failed(message) => {
                self.bar.println(format!(
                    "{}/{} {id}: failed: {message}",
                    g.scene_name, g.source
                ));
                entry.message = Some(message);
                entry.wall_time_s = Some(elapsed_s);
                self.stats.failures += 1;
                g.done[2] += 1;
                g.store.record_failed_run(entry)
            }
        };
        stored.with_context(|| format!("storing {id} in {}", g.store.dir().display()))?;
        self.bar.inc(1);
        if self.stats.failures > 0 {
            self.bar
                .set_message(format!("{} failed", self.stats.failures));
        }
        Ok(())
    }

    /// For each group's deferred repeats: when its two simulated repeats
    /// both completed with byte-identical runs, records the deferred ones as
    /// copies of the first (`copy_of` in the manifest); otherwise returns
    /// them to be simulated.
    fn copy_or_simulate(&mut self, deferred: Vec<(usize, Vec<u32>)>) -> Result<Vec<(usize, u32)>> {
        let mut simulate = Vec::new();
        for (gi, repeats) in deferred {
            let g = &mut self.groups[gi];
            let proven = g
                .pending
                .get(..2)
                .and_then(|pair| identical_runs(&g.store, pair[0], pair[1]));
            let Some((original, trajectory)) = proven else {
                simulate.extend(repeats.into_iter().map(|r| (gi, r)));
                continue;
            };
            for repeat in repeats {
                let mut entry = RunEntry::new(run_id(repeat));
                entry
                    .extra
                    .insert("repeat".into(), serde_json::json!(repeat));
                entry
                    .extra
                    .insert("copy_of".into(), serde_json::json!(run_id(original)));
                entry
                    .extra
                    .insert("samples".into(), serde_json::json!(trajectory.len()));
                g.store
                    .write_run(entry, &trajectory)
                    .with_context(|| format!("storing a copy in {}", g.store.dir().display()))?;
                g.done[0] += 1;
                self.bar.inc(1);
            }
        }
        Ok(simulate)
    }
}

/// The first repeat's trajectory when repeats `a` and `b` of a store both
/// completed and their run files are byte-identical.
fn identical_runs(store: &RunStore, a: u32, b: u32) -> Option<(u32, Trajectory)> {
    let ok = |r: u32| {
        store
            .run(&run_id(r))
            .is_some_and(|e| e.status == StoreStatus::Ok)
    };
    if !(ok(a) && ok(b)) {
        return None;
    }
    let file =
        |r: u32| std::fs::read(store.dir().join("runs").join(format!("{}.csv", run_id(r)))).ok();
    let (fa, fb) = (file(a)?, file(b)?);
    if fa != fb {
        return None;
    }
    store.read_run(&run_id(a)).ok().map(|t| (a, t))
}

/// Prints a line on standard output; a closed pipe (`| head`) is not an
/// error worth a panic.
fn say(line: String) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
}

fn setting_json(v: &SettingValue) -> serde_json::Value {
    match v {
        SettingValue::Bool(b) => serde_json::json!(b),
        SettingValue::Integer(i) => serde_json::json!(i),
        SettingValue::Float(f) => serde_json::json!(f),
        SettingValue::Text(s) => serde_json::json!(s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_overrides_apply_per_engine() {
        let all = overrides_for(&["timestep_s=0.001".into()], "mujoco").unwrap();
        assert_eq!(all.get("timestep_s"), Some(&SettingValue::Float(0.001)));
        assert!(overrides_for(&["nokey".into()], "mujoco").is_err());
        assert!(overrides_for(&["=3".into()], "mujoco").is_err());
        assert!(overrides_for(&["nosuchengine.timestep_s=1".into()], "mujoco").is_err());
    }

    #[test]
    fn child_results_round_trip_exactly() {
        let mut t = Trajectory::with_bodies(&["wrist"]);
        t.time_s = vec![0.0, 0.05];
        let x = 0.1 + 0.2;
        t.bodies[0].poses = vec![Some(Pose::new(Vec3::new(x, -0.0, 1e-300), Quat::IDENTITY)); 2];
        t.joint_angles_rad = Some(vec![vec![x], vec![f64::MIN_POSITIVE]]);
        t.joint_velocity_commands_rad_s = Some(vec![vec![1.0 / 3.0], vec![-2.5]]);
        let outcome = realitygap_core::controller::RunOutcome {
            trajectory: t.clone(),
            status: RunStatus::Completed,
            engine_steps: 10,
            wall_time_s: 0.5,
        };
        let text = serde_json::to_string(&ChildResult::from_outcome(&outcome)).unwrap();
        let back: ChildResult = serde_json::from_str(&text).unwrap();
        assert_eq!(back.trajectory().unwrap(), t);
    }
}
