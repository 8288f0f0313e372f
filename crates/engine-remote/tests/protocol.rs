//! Bad engine processes: one that crashes, hangs, writes garbage, returns
//! NaN or a short vector, closes its output or refuses, at `hello`,
//! `load` or `step`. Each is a failed load or a diverged run with its
//! reason (and the process's last messages), never a hung or crashed
//! caller; the process is gone afterwards (but for a refusal: that
//! process waits for the next load). The misbehaving engine is
//! `tests/adapters/misbehave.py` (standard library only).

use realitygap_core::controller::{simulate, RunOptions, RunStatus};
use realitygap_core::engine::{Engine, EngineError, EngineSettings, ModelVariation, SettingValue};
use realitygap_core::testing;
use realitygap_engine_remote::child::Launch;
use realitygap_engine_remote::RemoteEngine;
use std::time::Instant;

fn misbehave(when: &str, what: &str) -> RemoteEngine {
    misbehave_with(when, what, Vec::new())
}

fn misbehave_with(when: &str, what: &str, env: Vec<(String, String)>) -> RemoteEngine {
    let script = testing::workspace().join("crates/engine-remote/tests/adapters/misbehave.py");
    RemoteEngine::new(
        "misbehave",
        Launch {
            command: vec![
                "python3".into(),
                script.display().to_string(),
                when.into(),
                what.into(),
            ],
            env,
        },
    )
}

/// Scene 1 for 0.5 s with a reply timeout of `timeout_s`.
fn run(engine: &RemoteEngine, timeout_s: f64) -> Result<RunStatus, String> {
    let mut scene = testing::scene("scene1_single_joint");
    scene.duration_s = 0.5;
    let robot = testing::mico2();
    let mut settings = EngineSettings::new();
    settings.insert("timeout_s".into(), SettingValue::Float(timeout_s));
    simulate(engine, &scene, &robot, &settings, &RunOptions::default())
        .map(|out| out.status)
        .map_err(|e| e.to_string())
}

fn diverged(status: Result<RunStatus, String>) -> String {
    match status {
        Ok(RunStatus::Diverged { reason, .. }) => reason,
        other => panic!("expected a diverged run, got {other:?}"),
    }
}

#[test]
fn a_well_behaved_process_runs_the_scene() {
    // The same script without misbehaviour: the baseline of the others.
    let status = run(&misbehave("never", "crash"), 30.0).unwrap();
    assert!(matches!(status, RunStatus::Completed), "{status:?}");
}

#[test]
fn a_crash_while_stepping_is_a_diverged_run_with_its_last_messages() {
    let reason = diverged(run(&misbehave("step", "crash"), 30.0));
    assert!(
        reason.contains("exited before replying to \"step\"")
            && reason.contains("(exit status 3)")
            && reason.contains("misbehave: simulated crash in step"),
        "{reason}"
    );
}

#[test]
fn a_hung_process_is_stopped_at_the_timeout() {
    let started = Instant::now();
    let reason = diverged(run(&misbehave("step", "hang"), 1.0));
    assert!(
        reason.contains("no reply to \"step\" within 1 s (timeout_s)"),
        "{reason}"
    );
    // Not a timing assertion: the wait is one timeout, not the hour the
    // process sleeps.
    assert!(started.elapsed().as_secs() < 600);
}

#[test]
fn garbage_is_a_failed_run_quoting_the_line() {
    let reason = diverged(run(&misbehave("step", "garbage"), 30.0));
    assert!(
        reason.contains("the reply to \"step\" is not JSON")
            && reason.contains("\"Segmentation fault (core dumped)\""),
        "{reason}"
    );
}

#[test]
fn nan_and_short_vectors_are_refused() {
    let reason = diverged(run(&misbehave("step", "nan"), 30.0));
    assert!(
        reason.contains("the reply to \"step\": q[0] is NaN (not finite)"),
        "{reason}"
    );
    let reason = diverged(run(&misbehave("step", "wrong"), 30.0));
    assert!(reason.contains("has 5 numbers, 6 expected"), "{reason}");
}

#[test]
fn a_process_that_closes_its_output_is_stopped() {
    let reason = diverged(run(&misbehave("step", "silent"), 30.0));
    assert!(
        reason.contains("exited before replying to \"step\""),
        "{reason}"
    );
}

#[test]
fn failures_at_load_and_hello_are_load_errors() {
    let e = run(&misbehave("load", "refuse"), 30.0).unwrap_err();
    assert_eq!(
        e,
        "engine misbehave: cannot load the scene: misbehave refuses to load"
    );
    let e = run(&misbehave("load", "crash"), 30.0).unwrap_err();
    assert!(
        e.starts_with("engine misbehave: cannot load the scene: the engine process exited before replying to \"load\""),
        "{e}"
    );
    let e = run(&misbehave("hello", "garbage"), 30.0).unwrap_err();
    assert!(e.contains("the reply to \"hello\" is not JSON"), "{e}");
    let engine = misbehave("hello", "crash");
    assert!(engine
        .version()
        .starts_with("unavailable: the engine process exited"));
}

/// A process that refuses a model is healthy: the next load reuses it
/// (starting one costs seconds: Newton's imports take 3.3 s), where a
/// process that crashed is replaced.
#[test]
fn a_refused_load_keeps_its_process_and_a_crash_does_not() {
    let dir = std::env::temp_dir().join(format!("realitygap-protocol-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let starts = |what: &str| {
        let file = dir.join(what);
        let _ = std::fs::remove_file(&file);
        let engine = misbehave_with(
            "load",
            what,
            vec![("MISBEHAVE_STARTS".into(), file.display().to_string())],
        );
        for _ in 0..3 {
            assert!(run(&engine, 30.0).is_err());
        }
        std::fs::read_to_string(&file).unwrap().lines().count()
    };
    assert_eq!(starts("refuse"), 1);
    assert_eq!(starts("crash"), 3);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn simulations_side_by_side_reuse_their_processes() {
    // Three simulations alive at once need three processes; once they
    // end, the next three take those back instead of starting new ones
    // (a handover, a reference beside a candidate), and a fourth alive at
    // once starts one more.
    let dir = std::env::temp_dir().join(format!("realitygap-side-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("starts");
    let engine = misbehave_with(
        "never",
        "crash",
        vec![("MISBEHAVE_STARTS".into(), file.display().to_string())],
    );
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let load = || {
        engine
            .load(
                &scene,
                &robot,
                &EngineSettings::new(),
                &ModelVariation::default(),
            )
            .unwrap()
    };
    let starts = || std::fs::read_to_string(&file).unwrap().lines().count();
    let alive: Vec<_> = (0..3).map(|_| load()).collect();
    assert_eq!(starts(), 3);
    drop(alive);
    let alive: Vec<_> = (0..3).map(|_| load()).collect();
    assert_eq!(starts(), 3);
    let fourth = load();
    assert_eq!(starts(), 4);
    drop((alive, fourth));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_missing_program_and_a_bad_timeout_are_clear() {
    let engine = RemoteEngine::new(
        "nowhere",
        Launch {
            command: vec!["/nonexistent/python".into()],
            env: Vec::new(),
        },
    );
    let e = engine.check_settings(&EngineSettings::new()).unwrap_err();
    assert!(
        matches!(&e, EngineError::Load { message, .. } if message.starts_with("cannot start `/nonexistent/python`")),
        "{e}"
    );
    let mut settings = EngineSettings::new();
    settings.insert("timeout_s".into(), SettingValue::Integer(0));
    let e = misbehave("never", "crash")
        .check_settings(&settings)
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "engine misbehave: setting `timeout_s`: must be a positive number of seconds, found 0"
    );
}

/// The processes alive whose command line names `marker` (zombies, which
/// have ended, left out).
fn alive_naming(marker: &str) -> usize {
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| {
            let dir = e.ok()?.path();
            let cmdline = std::fs::read(dir.join("cmdline")).ok()?;
            let stat = std::fs::read_to_string(dir.join("stat")).ok()?;
            let state = stat.rsplit_once(") ")?.1.chars().next()?;
            (String::from_utf8_lossy(&cmdline).contains(marker) && !matches!(state, 'Z' | 'X'))
                .then_some(())
        })
        .count()
}

/// An engine written with the Python SDK (MuJoCo 4's adapter, in its
/// kit environment) imports once: its first process becomes the zygote
/// and every child is a fork of it, a process of its own. A fork that
/// hangs past its timeout is killed through its pidfd like a started
/// child, and the others go on. A process this one starts (as a batch's
/// `__run-one`) finds the zygote in its environment.
#[test]
fn children_fork_from_the_engines_first_process() {
    use realitygap_engine_remote::{registry, zygote};
    let dir = std::env::temp_dir().join(format!("realitygap-fork-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let imports = dir.join("imports");
    // The adapter's module run by a line that counts its imports; the
    // file's path marks the processes.
    let mut launch = registry::for_kit("mujoco4").launch().clone();
    let m = launch.command.iter().position(|a| a == "-m").unwrap();
    let module = launch.command[m + 1].clone();
    launch.command.truncate(m);
    launch.command.extend([
        "-c".to_string(),
        format!(
            "import os, runpy\nopen({:?}, 'a').write('%d\\n' % os.getpid())\nrunpy.run_module({module:?}, run_name='__main__')",
            imports.display().to_string()
        ),
    ]);
    let marker = imports.display().to_string();
    let engine = RemoteEngine::new("mujoco4", launch.clone());
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let load = |settings: &EngineSettings| {
        engine.load(&scene, &robot, settings, &ModelVariation::default())
    };
    let count = || std::fs::read_to_string(&imports).unwrap().lines().count();
    let alive: Vec<_> = (0..3)
        .map(|_| load(&EngineSettings::new()).unwrap())
        .collect();
    assert_eq!(count(), 1, "one import");
    // The zygote and a child for each simulation alive.
    assert_eq!(alive_naming(&marker), 4);
    drop(alive);
    let mut tight = EngineSettings::new();
    tight.insert("timeout_s".into(), SettingValue::Float(1e-6));
    let e = match load(&tight) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a load answered within a microsecond"),
    };
    // (To `check_settings` or to `load`, whichever comes first.)
    assert!(
        e.contains("within 0.000001 s (timeout_s); the engine process was stopped"),
        "{e}"
    );
    // The child that timed out is gone; the zygote and two idle remain.
    assert_eq!(alive_naming(&marker), 3);
    // The others go on.
    let again: Vec<_> = (0..3)
        .map(|_| load(&EngineSettings::new()).unwrap())
        .collect();
    assert_eq!(alive_naming(&marker), 4);
    drop(again);
    assert_eq!(count(), 1, "still one import");
    let (name, handed) = zygote::handed_down().unwrap();
    assert_eq!(name, zygote::ZYGOTES_ENV);
    assert!(handed.contains(&zygote::key(&launch)), "{handed}");
    drop(engine);
    std::fs::remove_dir_all(&dir).unwrap();
}
