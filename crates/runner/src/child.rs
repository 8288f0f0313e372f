//! Child processes: the parent starts one per run ([`run_child`]) and the
//! child runs it ([`run_one`]). A crash, abort or `exit` inside an engine's
//! native code therefore fails only that run, with the engine's last words
//! as its message.

use crate::prepare::{
    engine_names, parse_perturbation, prepare, prepare_with, Prepared, RunSource,
};
use crate::protocol::{ChildResult, Job, ReplayJob};
use crate::Registry;
use anyhow::{Context, Result};
use realitygap_core::controller::{
    load_prepared, refuse_unstable, run_scene_with, ControlParams, RunError, RunOptions,
};
use realitygap_core::controller::{RunOutcome, RunStatus};
use realitygap_core::engine::Simulation;
use realitygap_core::instability::{detect, gravity_explains, Instability, InstabilityOptions};
use realitygap_core::params::PhysicalParams;
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_core::stitch::{phase_ticks, run_stitched, split_entry, StitchPlan};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::Duration;
use wait_timeout::ChildExt;

/// The hidden subcommand of the `realitygap` binary that runs one job.
pub const RUN_ONE: &str = "__run-one";

/// How to start a child process that reads a [`Job`] on standard input and
/// writes a [`ChildResult`] on standard output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Launcher {
    /// The program; `None`: this executable (`std::env::current_exe`).
    pub program: Option<PathBuf>,
    /// Its arguments.
    pub args: Vec<String>,
}

impl Launcher {
    /// This executable with the [`RUN_ONE`] subcommand.
    pub fn this_executable() -> Launcher {
        Launcher {
            program: None,
            args: vec![RUN_ONE.to_string()],
        }
    }
}

/// How one child process ended.
#[derive(Debug)]
pub enum ChildEnd {
    /// It wrote a result (empty for a check-only job).
    Done(Box<ChildResult>),
    /// It failed, timed out or could not start: the message.
    Failed(String),
}

/// The child's side, `realitygap __run-one`: reads a [`Job`] as JSON on
/// standard input, runs it, writes a [`ChildResult`] as JSON on standard
/// output. `setup` prepares the engines' native libraries first.
pub fn run_one(registry: Registry, setup: fn()) -> Result<()> {
    #[cfg(target_os = "linux")]
    die_with_parent();
    setup();
    let mut input = String::new();
    std::io::stdin()
        .read_to_string(&mut input)
        .context("reading the job from standard input")?;
    let job: Job =
        serde_json::from_str(&input).context("the job on standard input is not valid")?;
    let Some(result) = simulate(registry, &job)? else {
        return Ok(());
    };
    let text = serde_json::to_string(&result)?;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|_| out.flush())
        .context("writing the result to standard output")?;
    Ok(())
}

/// The run of `job` in `entry` (an engine, or `ENGINE@PARAMS` with a
/// parameters file of its own instead of the job's), checked and ready to
/// load. The job's parameters text, when it has one, stands for its file.
fn prepare_for(registry: Registry, job: &Job, entry: &str) -> Result<Prepared> {
    let (engine, params) = split_entry(entry);
    let src = RunSource {
        scene_file: &job.scene_file,
        engine,
        robot: job.robot.as_deref(),
        packages: &job.packages,
        set: &job.set,
        params_file: params.map(Path::new).or(job.params.as_deref()),
    };
    let randomization = crate::prepare::parse_randomization(&job.perturb)?;
    let base = match (&job.params_text, params, &randomization) {
        (Some(text), None, _) => {
            PhysicalParams::from_toml_str(text, Path::new("<job parameters>"))?
        }
        (_, _, Some(_)) => {
            crate::prepare::read_params(params.map(Path::new).or(job.params.as_deref()))?
        }
        _ => return prepare(registry, &src),
    };
    match &randomization {
        Some(r) => {
            let drawn = r.apply(&base, job.seed).with_context(|| {
                format!(
                    "--perturb {}: the draw of seed {}",
                    r.source.display(),
                    job.seed
                )
            })?;
            prepare_with(registry, &src, drawn)
        }
        None => prepare_with(registry, &src, base),
    }
}

/// The run options of `job` for a scene with `joints` controlled joints.
fn run_options(job: &Job, joints: usize) -> Result<RunOptions> {
    let perturbation = parse_perturbation(&job.perturb)?;
    let sample = (!perturbation.is_none()).then(|| perturbation.sample(job.seed, joints));
    Ok(RunOptions {
        perturbation: sample,
        allow_unstable: job.allow_unstable,
        ..RunOptions::default()
    })
}

/// Runs `job` in this process; `None` for a check-only job whose model
/// loaded.
pub fn simulate(registry: Registry, job: &Job) -> Result<Option<ChildResult>> {
    if let Some(plan) = &job.stitch {
        return simulate_stitched(registry, job, plan);
    }
    if let Some(episode) = &job.replay {
        return simulate_replay(registry, job, episode);
    }
    let p = prepare_for(registry, job, &job.engine)?;
    let options = run_options(job, p.scene.actuators.len())?;
    let mut sim = load_prepared(
        p.engine.as_ref(),
        &p.scene,
        &p.robot,
        &p.settings,
        &p.params,
        &options,
    )?;
    refuse_unstable(p.engine.as_ref(), sim.as_ref(), &options)?;
    if job.check_only {
        return Ok(None);
    }
    let control = ControlParams::from_params(&p.params, &p.scene);
    let issues = sim.stability_issues();
    let start = crate::cpu_clock::thread_cpu_s();
    let outcome = run_scene_with(sim.as_mut(), &p.scene, &options, &control)?;
    let end = crate::cpu_clock::thread_cpu_s();
    let mut result = ChildResult::from_outcome(&outcome);
    result.cpu_s = start.zip(end).map(|(a, b)| b - a);
    result.stability_issues = issues;
    result.instability = instability_of(&p.scene, &p.robot, &outcome);
    Ok(Some(result))
}

/// Runs a replay job: the episode's recorded commands replayed in the
/// job's engine on the job's scene (`realitygap_core::replay`), every
/// actuator without a position gain given the default one.
fn simulate_replay(
    registry: Registry,
    job: &Job,
    episode: &ReplayJob,
) -> Result<Option<ChildResult>> {
    use realitygap_core::replay::{fill_default_gains, replay, ReplayPlan};
    let mut p = prepare_for(registry, job, &job.engine)?;
    fill_default_gains(&mut p.scene);
    let store = realitygap_data::RunStore::open(&episode.real_dir).with_context(|| {
        format!(
            "reading the recorded episodes in {}",
            episode.real_dir.display()
        )
    })?;
    let real = store.read_run(&episode.episode)?;
    let plan = ReplayPlan::for_recording(&real, &p.scene, &p.params).map_err(|e| {
        anyhow::anyhow!(
            "{}: run '{}': {e}",
            episode.real_dir.display(),
            episode.episode
        )
    })?;
    let options = RunOptions {
        allow_unstable: job.allow_unstable,
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
    refuse_unstable(p.engine.as_ref(), sim.as_ref(), &options)?;
    if job.check_only {
        return Ok(None);
    }
    let issues = sim.stability_issues();
    let start = crate::cpu_clock::thread_cpu_s();
    let outcome = replay(sim.as_mut(), &plan)?;
    let end = crate::cpu_clock::thread_cpu_s();
    let mut result = ChildResult::from_outcome(&outcome);
    result.cpu_s = start.zip(end).map(|(a, b)| b - a);
    result.stability_issues = issues;
    Ok(Some(result))
}

/// Runs a stitched job: the scene prepared in every engine of the plan,
/// then [`run_stitched`] loading a fresh simulation at every phase. The
/// controller's share of the parameters (encoder offsets, latency) is the
/// first phase's.
fn simulate_stitched(
    registry: Registry,
    job: &Job,
    plan: &[String],
) -> Result<Option<ChildResult>> {
    let plan = StitchPlan::parse(&plan.join(","), &engine_names(registry))?;
    let mut prepared: Vec<(String, Prepared)> = Vec::new();
    for engine in &plan.engines {
        if !prepared.iter().any(|(e, _)| e == engine) {
            prepared.push((engine.clone(), prepare_for(registry, job, engine)?));
        }
    }
    let first = &prepared[0].1;
    let scene = first.scene.clone();
    let engines = plan
        .per_phase(phase_ticks(&scene).len())
        .with_context(|| format!("scene {}", job.scene_file.display()))?;
    let options = run_options(job, scene.actuators.len())?;
    let control = ControlParams::from_params(&first.params, &scene);
    let mut load = |engine: &str| -> Result<Box<dyn Simulation>, RunError> {
        let (_, p) = prepared
            .iter()
            .find(|(e, _)| e == engine)
            .expect("every engine of the plan is prepared");
        let sim = load_prepared(
            p.engine.as_ref(),
            &p.scene,
            &p.robot,
            &p.settings,
            &p.params,
            &options,
        )?;
        refuse_unstable(p.engine.as_ref(), sim.as_ref(), &options)?;
        Ok(sim)
    };
    if job.check_only {
        for engine in &plan.engines {
            load(engine)?;
        }
        return Ok(None);
    }
    let run = run_stitched(&scene, &engines, &options, &control, &mut load)?;
    let mut result = ChildResult::from_outcome(&run.outcome);
    result.handovers = run.handovers;
    result.instability = instability_of(&scene, &first.robot, &run.outcome);
    Ok(Some(result))
}

/// The first signature of a numerical instability in a completed run
/// (none for a diverged one), with stalls judged against the scene's
/// servos and the robot's gravity torques.
fn instability_of(scene: &Scene, robot: &RobotModel, outcome: &RunOutcome) -> Option<Instability> {
    if outcome.status != RunStatus::Completed {
        return None;
    }
    let traj = &outcome.trajectory;
    let explained = gravity_explains(scene, robot, traj);
    detect(traj, &InstabilityOptions::default(), &explained)
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
    // SAFETY: plain system calls with integer arguments, declared with
    // their C signatures; neither touches memory of this process.
    unsafe {
        prctl(PR_SET_PDEATHSIG, SIGKILL, 0, 0, 0);
        if getppid() == 1 {
            std::process::exit(1);
        }
    }
}

/// The last `n` non-blank lines of `text`, joined by ` | `.
pub fn last_lines(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(n)..].join(" | ")
}

/// How a process ended, in words: `exited with code 3`, `killed by signal
/// 11 (SIGSEGV, invalid memory access)`.
pub fn describe_exit(status: ExitStatus) -> String {
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

/// Reads a pipe to its end on a thread of its own.
fn drain<R: Read + Send + 'static>(mut pipe: R) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = pipe.read_to_end(&mut buf);
        buf
    })
}

/// What the child's standard output and error and exit status mean.
fn interpret(job: &Job, status: ExitStatus, out: &[u8], err: &str) -> ChildEnd {
    if status.success() {
        if job.check_only {
            return ChildEnd::Done(Box::default());
        }
        return match serde_json::from_slice::<ChildResult>(out) {
            Ok(r) => ChildEnd::Done(Box::new(r)),
            Err(e) => ChildEnd::Failed(format!(
                "the run's output could not be read ({e}); stderr: {}",
                last_lines(err, 5)
            )),
        };
    }
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

/// Runs `job` in a child process started by `launcher`, killed after
/// `timeout_s` seconds if given.
pub fn run_child(launcher: &Launcher, job: &Job, timeout_s: Option<f64>) -> ChildEnd {
    if crate::interrupt::requested() {
        return ChildEnd::Failed(INTERRUPTED.to_string());
    }
    let program = match &launcher.program {
        Some(p) => p.clone(),
        None => match std::env::current_exe() {
            Ok(e) => e,
            Err(e) => {
                return ChildEnd::Failed(format!("cannot find this program to start a run: {e}"))
            }
        },
    };
    let mut child = match Command::new(program)
        .args(&launcher.args)
        // A run forks its engine's children from this process's zygote.
        .envs(realitygap_engine_remote::zygote::handed_down())
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
    let out_reader = drain(child.stdout.take().expect("piped"));
    let err_reader = drain(child.stderr.take().expect("piped"));
    // A limit too large for a `Duration` (or NaN) never comes, as before.
    let limit = timeout_s
        .filter(|t| !t.is_nan())
        .and_then(|t| Duration::try_from_secs_f64(t.max(0.0)).ok());
    let status = match wait_or_interrupt(&mut child, limit) {
        Ok(Waited::Exited(status)) => Some(status),
        Ok(end) => {
            let _ = child.kill();
            let _ = child.wait();
            if end == Waited::Interrupted {
                let _ = out_reader.join();
                let _ = err_reader.join();
                return ChildEnd::Failed(INTERRUPTED.to_string());
            }
            None
        }
        Err(e) => return ChildEnd::Failed(format!("waiting for the run: {e}")),
    };
    let out = out_reader.join().unwrap_or_default();
    let err = String::from_utf8_lossy(&err_reader.join().unwrap_or_default()).into_owned();
    match status {
        None => ChildEnd::Failed(format!("timed out after {} s", timeout_s.unwrap_or(0.0))),
        Some(status) => interpret(job, status, &out, &err),
    }
}

/// The message of a run cut short by [`crate::interrupt::request`] (never
/// stored: the callers drop such runs).
pub const INTERRUPTED: &str = "interrupted";

/// How waiting for a child ended.
#[derive(Debug, PartialEq)]
enum Waited {
    /// It exited.
    Exited(ExitStatus),
    /// The time limit passed.
    TimedOut,
    /// An interruption was asked for.
    Interrupted,
}

/// Waits for `child` until it exits, `limit` passes or an interruption is
/// asked for (checked every 50 ms).
fn wait_or_interrupt(
    child: &mut std::process::Child,
    limit: Option<Duration>,
) -> std::io::Result<Waited> {
    let start = std::time::Instant::now();
    let tick = Duration::from_millis(50);
    loop {
        if crate::interrupt::requested() {
            return Ok(Waited::Interrupted);
        }
        let wait = match limit {
            Some(limit) => match limit.checked_sub(start.elapsed()) {
                Some(left) => left.min(tick),
                None => return Ok(Waited::TimedOut),
            },
            None => tick,
        };
        if let Some(status) = child.wait_timeout(wait)? {
            return Ok(Waited::Exited(status));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    fn job(check_only: bool) -> Job {
        Job {
            scene_file: "s.toml".into(),
            engine: "mujoco".into(),
            robot: None,
            packages: vec![],
            set: vec![],
            perturb: vec![],
            seed: 0,
            params: None,
            params_text: None,
            check_only,
            stitch: None,
            allow_unstable: false,
            replay: None,
        }
    }

    fn sh(script: &str) -> Launcher {
        Launcher {
            program: Some("sh".into()),
            args: vec!["-c".into(), script.into()],
        }
    }

    fn failed(end: ChildEnd) -> String {
        match end {
            ChildEnd::Failed(m) => m,
            ChildEnd::Done(r) => panic!("expected a failure, got {r:?}"),
        }
    }

    #[test]
    fn a_result_on_standard_output_is_read() {
        let r = ChildResult {
            engine_steps: 42,
            ..ChildResult::default()
        };
        let text = serde_json::to_string(&r).unwrap();
        let end = run_child(
            &sh(&format!("cat >/dev/null; echo '{text}'")),
            &job(false),
            None,
        );
        match end {
            ChildEnd::Done(back) => assert_eq!(*back, r),
            ChildEnd::Failed(m) => panic!("{m}"),
        }
        assert!(matches!(
            run_child(&sh("cat >/dev/null"), &job(true), None),
            ChildEnd::Done(_)
        ));
    }

    #[test]
    fn a_failing_child_gives_its_last_words() {
        let m = failed(run_child(
            &sh("cat >/dev/null; echo one >&2; echo 'error: two' >&2; exit 3"),
            &job(false),
            None,
        ));
        assert_eq!(m, "exited with code 3: one | two");
        let m = failed(run_child(&sh("exit 1"), &job(false), None));
        assert_eq!(m, "exited with code 1: no message");
        let m = failed(run_child(&sh("kill -SEGV $$"), &job(false), None));
        assert_eq!(
            m,
            "killed by signal 11 (SIGSEGV, invalid memory access): no message"
        );
        let m = failed(run_child(
            &sh("echo garbage; echo why >&2"),
            &job(false),
            None,
        ));
        assert!(
            m.starts_with("the run's output could not be read") && m.ends_with("stderr: why"),
            "{m}"
        );
    }

    #[test]
    fn a_slow_child_times_out_promptly() {
        let start = Instant::now();
        let m = failed(run_child(&sh("exec sleep 30"), &job(false), Some(0.3)));
        assert_eq!(m, "timed out after 0.3 s");
        assert!(start.elapsed().as_secs_f64() < 10.0);
    }

    #[test]
    fn a_missing_program_is_named() {
        let launcher = Launcher {
            program: Some("/does/not/exist".into()),
            args: vec![],
        };
        let m = failed(run_child(&launcher, &job(false), None));
        assert!(m.starts_with("cannot start a child process"), "{m}");
        assert_eq!(last_lines("a\n\n b\nc\n", 2), " b | c");
    }
}
