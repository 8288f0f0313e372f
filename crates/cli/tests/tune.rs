//! `realitygap tune` end to end on a synthetic target: scene 1 simulated
//! in MuJoCo with known parameters stands in for the real arm (a study
//! whose reference is that results directory), and the tuner must find
//! the parameters again. Also: a rerun of the tuned parameters reproduces
//! the training objective, a killed tune resumes to the same history, a
//! diverging candidate is scored and survived, and bad space files are
//! clear errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(out: Output) -> Output {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn scene1() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/scenes/scene1_single_joint.toml")
        .canonicalize()
        .unwrap()
}

/// The settings every run of these tests uses (fast and stable).
const SETTINGS: &str = "[engine.mujoco]\nintegrator = \"implicitfast\"\ntimestep_s = 0.005\n";

/// The known parameters of the synthetic target: a gain that holds the
/// arm up at its target (at 15 it sags onto the cube).
const KNOWN_KV: f64 = 25.0;
const KNOWN_DELAY_S: f64 = 0.08;

/// A folder with the synthetic target: `runs/` (scene 1 in MuJoCo with
/// the known parameters) and `study.toml` whose reference it is, plus
/// `space.toml` searching kv of joint 2 and the delay.
fn synthetic() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let known = d.join("known.toml");
    std::fs::write(
        &known,
        format!(
            "[joints.m1n6s300_joint_2]\nkv = {KNOWN_KV}\n[controller]\ndelay_s = {KNOWN_DELAY_S}\n{SETTINGS}"
        ),
    )
    .unwrap();
    let scene = scene1();
    ok(realitygap(&[
        "run",
        scene.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--params",
        known.to_str().unwrap(),
        "--out",
        d.join("runs").to_str().unwrap(),
    ]));
    write_study(d, "mujoco");
    std::fs::write(
        d.join("space.toml"),
        format!(
            "{SETTINGS}[params]\n\"joints.m1n6s300_joint_2.kv\" = {{ low = 4.0, high = 400.0, scale = \"log\", start = 40.0 }}\n\
             \"controller.delay_s\" = {{ low = 0.0, high = 0.15, start = 0.0 }}\n"
        ),
    )
    .unwrap();
    tmp
}

/// Scene 1 without the cube (its object and its track), written into
/// `d`: the known-truth tunes in every engine fit the arm alone, and the
/// cube resting on the table cost DART a third of its time there.
fn scene1_without_cube(d: &Path) -> PathBuf {
    let text = std::fs::read_to_string(scene1()).unwrap();
    let robot = scene1()
        .parent()
        .unwrap()
        .join("../robots/mico2/mico2.urdf");
    let mut cut = text.replace(
        "urdf = \"../robots/mico2/mico2.urdf\"",
        &format!("urdf = {:?}", robot.to_str().unwrap()),
    );
    let object = cut.find("[[object]]").expect("scene 1 has the cube");
    let end = object + cut[object..].find("\n\n").unwrap() + 2;
    cut.replace_range(object..end, "");
    let track = "[[track]]\nrole = \"cube\"\nobject = \"cube\"\n";
    assert!(cut.contains(track) && cut.contains(&format!("urdf = {:?}", robot.to_str().unwrap())));
    let cut = cut.replace(track, "");
    assert!(!cut.contains("cube\""), "{cut}");
    let file = d.join("scene1_without_cube.toml");
    std::fs::write(&file, cut).unwrap();
    file
}

/// `d/study.toml`: scene 1 against the runs of `engine` in `d/runs`.
fn write_study(d: &Path, engine: &str) {
    write_study_of(d, engine, &scene1());
}

/// `d/study.toml`: `scene` (scene 1 or a cut of it) against the runs of
/// `engine` in `d/runs`.
fn write_study_of(d: &Path, engine: &str, scene: &Path) {
    std::fs::write(
        d.join("study.toml"),
        format!(
            "name = \"known-truth\"\n[[scenes]]\nname = \"scene1_single_joint\"\nscene = {:?}\nsteps = 120\n\
             [scenes.reference]\nname = \"known\"\nformat = \"store\"\ndir = \"runs/scene1_single_joint/{engine}\"\n",
            scene.to_str().unwrap()
        ),
    )
    .unwrap();
}

/// Six "real" runs of scene 1 in `engine` with `d/known.toml`, into
/// `d/runs`: they differ (initial offsets and reading noise), so that the
/// objective has a spread over them for the intervals.
fn noisy_known_runs(d: &Path, engine: &str) {
    noisy_known_runs_of(d, engine, &scene1());
}

/// [`noisy_known_runs`] of `scene`.
fn noisy_known_runs_of(d: &Path, engine: &str, scene: &Path) {
    ok(realitygap(&[
        "run",
        scene.to_str().unwrap(),
        "--engine",
        engine,
        "--params",
        d.join("known.toml").to_str().unwrap(),
        "--repeats",
        "6",
        "--perturb",
        "initial_offset_deg=0.3,sensor_noise_deg=0.05",
        "--out",
        d.join("runs").to_str().unwrap(),
    ]));
}

fn tune_args<'a>(d: &'a Path, out: &'a str, budget: &'a str) -> Vec<String> {
    [
        "tune",
        d.join("study.toml").to_str().unwrap(),
        "--engine",
        "mujoco",
        "--space",
        d.join("space.toml").to_str().unwrap(),
        "--out",
        out,
        "--budget",
        budget,
        "--jobs",
        "2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn tune(d: &Path, out: &str, budget: &str) -> serde_json::Value {
    let args = tune_args(d, out, budget);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(realitygap(&args));
    let text = std::fs::read_to_string(Path::new(out).join("summary.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn param(summary: &serde_json::Value, key: &str) -> f64 {
    summary["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["key"] == key)
        .unwrap()["value"]
        .as_f64()
        .unwrap()
}

/// Tolerances: the target is the engine itself, so the optimum is exact;
/// within 200 evaluations CMA-ES gets kv within 5 % and the delay within
/// 5 ms (one engine step; the delay acts continuously within a step, as an
/// average of the old and new command, so it is not exact either).
#[test]
fn recovers_known_parameters_and_the_tuned_file_reproduces_the_objective() {
    let tmp = synthetic();
    let d = tmp.path();
    let out = d.join("tuned");
    let s = tune(d, out.to_str().unwrap(), "200");
    let kv = param(&s, "joints.m1n6s300_joint_2.kv");
    let delay = param(&s, "controller.delay_s");
    assert!((kv - KNOWN_KV).abs() < 0.05 * KNOWN_KV, "kv {kv}");
    assert!((delay - KNOWN_DELAY_S).abs() <= 0.005, "delay {delay}");
    let best = s["best_objective_m"].as_f64().unwrap();
    let untuned = s["training"]["objective_m"][0].as_f64().unwrap();
    assert!(
        best < 0.05 * untuned,
        "best {best} against untuned {untuned}"
    );
    // Every output is there.
    for f in [
        "tuned.toml",
        "registration.json",
        "history.csv",
        "summary.md",
        "convergence.svg",
        "convergence.png",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // `run --params tuned.toml` as it is, then compare: the training
    // objective of summary.json, bit for bit (the tune's own settings are
    // in the file).
    let acc = rerun_scored(d, &out.join("tuned.toml"), "rerun", &[]);
    let tuned = s["training"]["scenes"][0]["tuned"]["value_m"]
        .as_f64()
        .unwrap();
    assert!(
        (acc - tuned).abs() < 1e-9,
        "rerun {acc} against tune {tuned}"
    );
    assert!((acc - best).abs() < 1e-9, "rerun {acc} against best {best}");

    // The timestep check scored the tuned parameters at half the space's
    // step: what `run --set mujoco.timestep_s=0.0025` and compare give.
    let check = &s["timestep_check"];
    assert_eq!(check["timestep_s"].as_f64(), Some(0.005), "{check}");
    assert_eq!(check["halved_s"].as_f64(), Some(0.0025), "{check}");
    assert!(check["holds"].is_boolean(), "{check}");
    let at_half = rerun_scored(
        d,
        &out.join("tuned.toml"),
        "half",
        &["--set", "mujoco.timestep_s=0.0025"],
    );
    let checked = check["halved"]["value_m"].as_f64().unwrap();
    assert!(
        (at_half - checked).abs() < 1e-9,
        "half step {at_half} against the check's {checked}"
    );
    // A finer step is another integration: the score moves.
    assert!((at_half - acc).abs() > 1e-6, "{at_half} against {acc}");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("Timestep check: at half the timestep (0.0025 s instead of 0.005 s)"),
        "{md}"
    );
}

/// A search cut short (`--budget 4`: one generation) whose every candidate
/// scores above the space's start, here the known truth itself, ends at
/// that start: the polish (none here, `--iterations 0`) starts from the
/// lower of the two, so a tune never ends above where it started. Before,
/// `tuned.toml` held the search's best candidate, worse than its start.
#[test]
fn a_search_that_ends_above_its_start_falls_back_to_it() {
    let tmp = synthetic();
    let d = tmp.path();
    std::fs::write(
        d.join("space.toml"),
        format!(
            "{SETTINGS}[params]\n\"joints.m1n6s300_joint_2.kv\" = {{ low = 4.0, high = 400.0, scale = \"log\", start = {KNOWN_KV} }}\n\
             \"controller.delay_s\" = {{ low = 0.0, high = 0.15, start = {KNOWN_DELAY_S} }}\n"
        ),
    )
    .unwrap();
    let out = d.join("tuned");
    let mut args = tune_args(d, out.to_str().unwrap(), "4");
    args.extend(["--iterations".to_string(), "0".to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = ok(realitygap(&args));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("the search ended above its start"),
        "{stderr}"
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let kv = param(&s, "joints.m1n6s300_joint_2.kv");
    let delay = param(&s, "controller.delay_s");
    assert!((kv - KNOWN_KV).abs() < 1e-9 * KNOWN_KV, "kv {kv}");
    assert!((delay - KNOWN_DELAY_S).abs() < 1e-12, "delay {delay}");
    // The start's one simulation is counted (no polish with --iterations 0).
    assert_eq!(s["polish"]["evaluations"], 1, "{}", s["polish"]);
    // Every candidate of the search, in its history, scored above the
    // tune's end.
    let end = s["best_objective_m"].as_f64().unwrap();
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    let searched: Vec<f64> = history
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert!(!searched.is_empty(), "{history}");
    assert!(searched.iter().all(|&o| o > end), "{end} {searched:?}");
}

/// After CMA-ES the polish gives intervals that cover the known kv, the
/// identifiability is checked before the search and at the optimum, both
/// physics-free rows are scored, and `randomize.toml` drives `run
/// --perturb`: every repeat draws its own parameters within the ranges.
#[test]
fn the_polish_gives_intervals_and_a_randomisation_file_that_run_accepts() {
    let tmp = synthetic();
    let d = tmp.path();
    // Six "real" runs that differ (initial offsets and reading noise), so
    // that the objective has a spread over them for the intervals.
    std::fs::remove_dir_all(d.join("runs")).unwrap();
    noisy_known_runs(d, "mujoco");
    let out = d.join("tuned");
    let s = tune(d, out.to_str().unwrap(), "40");
    let p = &s["polish"];
    assert!(p["rounds"].as_u64().unwrap() >= 1, "{p}");
    assert!(
        p["objective_m"].as_f64().unwrap() <= p["start_objective_m"].as_f64().unwrap(),
        "{p}"
    );
    let kv = p["intervals"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["key"] == "joints.m1n6s300_joint_2.kv")
        .unwrap();
    let value = kv["value"].as_f64().unwrap();
    assert!((value - KNOWN_KV).abs() < 0.05 * KNOWN_KV, "{kv}");
    let iv = kv["interval"].as_array().unwrap_or_else(|| panic!("{kv}"));
    let (lo, hi) = (iv[0].as_f64().unwrap(), iv[1].as_f64().unwrap());
    assert!(lo <= KNOWN_KV && KNOWN_KV <= hi, "{kv}");
    assert!(
        hi - lo < 0.5 * KNOWN_KV,
        "an interval that says something: {kv}"
    );
    assert!(
        p["interval_basis"].as_str().unwrap().contains("noise"),
        "the real runs' spread sets the intervals: {p}"
    );
    let noise = p["identifiability"]["noise_m"].as_f64().unwrap();
    assert!(noise > 0.0, "{p}");
    assert_eq!(s["identifiability_before"]["at"], "start", "{s}");
    assert_eq!(p["identifiability"]["at"], "optimum", "{p}");
    let rows: Vec<&str> = s["training"]["baselines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["source"].as_str().unwrap())
        .collect();
    assert_eq!(rows, ["physics-free", "physics-free + actuator (fitted)"]);
    assert!(
        s["verdict"].as_str().unwrap().contains("physics-free"),
        "{s}"
    );
    // The fitted physics-free row is a tune folder `reproduce --tuned` reads.
    let pfa = out.join("physics-free-actuator");
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(pfa.join("summary.json")).unwrap()).unwrap();
    assert_eq!(b["engine"], "ideal", "{b}");
    assert!(pfa.join("tuned.toml").is_file() && pfa.join("registration.json").is_file());
    // randomize.toml over tuned.toml in `run`.
    let r = out.join("randomize.toml");
    let text = std::fs::read_to_string(&r).unwrap();
    assert!(text.contains("\"joints.m1n6s300_joint_2.kv\""), "{text}");
    let runs = d.join("randomised");
    ok(realitygap(&[
        "run",
        scene1().to_str().unwrap(),
        "--engine",
        "mujoco",
        "--params",
        out.join("tuned.toml").to_str().unwrap(),
        "--perturb",
        r.to_str().unwrap(),
        "--repeats",
        "3",
        "--out",
        runs.to_str().unwrap(),
    ]));
    let dir = runs.join("scene1_single_joint/mujoco");
    let manifest = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    assert!(manifest.contains("\"randomize\""), "{manifest}");
    let a = std::fs::read_to_string(dir.join("runs/run000.csv")).unwrap();
    let b = std::fs::read_to_string(dir.join("runs/run001.csv")).unwrap();
    assert_ne!(a, b, "two repeats drew the same parameters");
    // A bad randomisation file is refused with its line before anything runs.
    let bad = d.join("bad.toml");
    std::fs::write(
        &bad,
        "[params]\n\"joints.m1n6s300_joint_2.kv\" = { low = 5.0 }\n",
    )
    .unwrap();
    let o = realitygap(&[
        "run",
        scene1().to_str().unwrap(),
        "--engine",
        "mujoco",
        "--perturb",
        bad.to_str().unwrap(),
        "--out",
        d.join("bad-runs").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("bad.toml:2") && e.contains("`high` is missing"),
        "{e}"
    );
}

/// `run --params PARAMS EXTRA` of scene 1 in MuJoCo into `d/NAME`, then
/// `compare` of it against the synthetic study's reference: its
/// accumulated error, metres.
fn rerun_scored(d: &Path, params: &Path, name: &str, extra: &[&str]) -> f64 {
    let dir = d.join(name);
    let scene = scene1();
    let mut args = vec![
        "run",
        scene.to_str().unwrap(),
        "--engine",
        "mujoco",
        "--params",
        params.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    ok(realitygap(&args));
    let study = d.join(format!("study-{name}.toml"));
    let text = std::fs::read_to_string(d.join("study.toml")).unwrap()
        + &format!(
            "[[scenes.sources]]\nname = \"{name}\"\nformat = \"store\"\ndir = \"{name}/scene1_single_joint/mujoco\"\n"
        );
    std::fs::write(&study, text).unwrap();
    let o = ok(realitygap(&[
        "compare",
        study.to_str().unwrap(),
        "--format",
        "json",
    ]));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    find_number(&v, "accumulated_error_m").unwrap_or_else(|| panic!("{v}"))
}

/// The first number under `key` in the sources of a compare JSON.
fn find_number(v: &serde_json::Value, key: &str) -> Option<f64> {
    match v {
        serde_json::Value::Object(m) => {
            if let Some(sources) = m.get("sources") {
                if let Some(x) = sources
                    .as_array()
                    .and_then(|a| a.first())
                    .and_then(|s| s.get(key))
                    .and_then(|x| x.as_f64())
                {
                    return Some(x);
                }
            }
            m.values().find_map(|x| find_number(x, key))
        }
        serde_json::Value::Array(a) => a.iter().find_map(|x| find_number(x, key)),
        _ => None,
    }
}

#[test]
fn a_killed_tune_resumes_to_the_same_history() {
    let tmp = synthetic();
    let d = tmp.path();
    let whole = d.join("whole");
    tune(d, whole.to_str().unwrap(), "60");
    let cut = d.join("cut");
    let args = tune_args(d, cut.to_str().unwrap(), "60");
    let mut child = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(&args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it once two generations (6 candidates each) are in the file.
    let history = cut.join("history.csv");
    let started = Instant::now();
    loop {
        let rows = std::fs::read_to_string(&history)
            .map(|t| t.lines().count().saturating_sub(1))
            .unwrap_or(0);
        if rows >= 12 {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "the tune wrote no history"
        );
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        !cut.join("summary.json").exists(),
        "the tune finished before the kill"
    );
    let s = tune(d, cut.to_str().unwrap(), "60");
    assert!(s["replayed"].as_u64().unwrap() >= 12, "{}", s["replayed"]);
    assert_eq!(
        std::fs::read_to_string(&history).unwrap(),
        std::fs::read_to_string(whole.join("history.csv")).unwrap()
    );
    // Another space in the same folder is refused.
    std::fs::write(
        d.join("space.toml"),
        format!("{SETTINGS}[params]\n\"controller.delay_s\" = {{ low = 0.0, high = 0.2 }}\n"),
    )
    .unwrap();
    let args = tune_args(d, cut.to_str().unwrap(), "60");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = realitygap(&args);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("holds a different tune"), "{e}");
}

/// Without a weighed cube (scene 1 has none), the space's object and
/// contact keys are held at the scenes' own values: not searched, not in
/// the tuned file, and named in the summary.
#[test]
fn object_and_contact_keys_are_held_when_the_cube_is_not_weighed() {
    let tmp = synthetic();
    let d = tmp.path();
    let space = std::fs::read_to_string(d.join("space.toml")).unwrap();
    std::fs::write(
        d.join("space.toml"),
        format!(
            "{space}\"contact.time_constant_s\" = {{ low = 0.01, high = 0.1, scale = \"log\", start = 0.02 }}\n\
             \"objects.cube.friction\" = {{ low = 0.1, high = 1.5, start = 1.0 }}\n"
        ),
    )
    .unwrap();
    let out = d.join("out");
    let s = tune(d, out.to_str().unwrap(), "12");
    assert_eq!(
        s["held"],
        serde_json::json!(["contact.time_constant_s", "objects.cube.friction"])
    );
    let keys: Vec<&str> = s["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["key"].as_str().unwrap())
        .collect();
    assert_eq!(keys, ["joints.m1n6s300_joint_2.kv", "controller.delay_s"]);
    let tuned = std::fs::read_to_string(out.join("tuned.toml")).unwrap();
    assert!(
        !tuned.contains("[contact]") && !tuned.contains("[objects"),
        "{tuned}"
    );
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("Held at the scenes' own values, not searched")
            && md.contains("contact.time_constant_s, objects.cube.friction"),
        "{md}"
    );
}

#[test]
fn a_diverging_candidate_is_scored_as_failed_and_the_search_goes_on() {
    let tmp = synthetic();
    let d = tmp.path();
    // Explicit Euler with servo gains up to 1e5 N m s/rad at 0.1 ms (the
    // study's setting): the stiff end is past the servo's stable bound,
    // refused before running (or, near the bound, diverges).
    std::fs::write(
        d.join("space.toml"),
        "[engine.mujoco]\nintegrator = \"euler\"\ntimestep_s = 0.0001\n[params]\n\
         \"joints.m1n6s300_joint_2.kv\" = { low = 4.0, high = 100000.0, scale = \"log\", start = 40.0 }\n",
    )
    .unwrap();
    let out = d.join("out");
    let s = tune(d, out.to_str().unwrap(), "30");
    let failed = s["failed"].as_u64().unwrap();
    assert!(failed > 0, "no candidate diverged");
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert!(
        history.contains("refused before running") || history.contains("diverged"),
        "{history}"
    );
    let kv = param(&s, "joints.m1n6s300_joint_2.kv");
    assert!(
        kv < 1000.0,
        "the best candidate {kv} should be a stable one"
    );
    assert!(s["best_objective_m"].as_f64().unwrap() < 1e3);
}

#[test]
fn bad_spaces_and_unsupported_keys_are_errors_before_anything_runs() {
    let tmp = synthetic();
    let d = tmp.path();
    let cases = [
        (
            "[params]\n\"joints.m1n6s300_joint_2.stiffness\" = { low = 0.0, high = 1.0 }\n",
            "space.toml:2:1: params.\"joints.m1n6s300_joint_2.stiffness\"",
        ),
        (
            "[params]\n\"controller.delay_s\" = { low = 0.2, high = 0.1 }\n",
            "low = 0.2 is not below high = 0.1",
        ),
        (
            "[params]\n\"controller.delay_s\" = { low = nan, high = 0.1 }\n",
            "low = NaN",
        ),
        (
            "[params]\n\"joints.no_such_joint.damping\" = { low = 0.0, high = 1.0 }\n",
            "no_such_joint",
        ),
        // The space's timestep, not the scene's own (1e-4 s, at its line).
        (
            "[engine.mujoco]\ntimestep_s = 0.03\n[params]\n\"controller.delay_s\" = { low = 0.0, high = 0.1 }\n",
            "the run's parameters, [engine.mujoco] timestep_s = 0.03 s does not divide the scene's control period (0.05 s, controller.period_s) into whole steps: try 0.025 s (2 steps a period)",
        ),
    ];
    for (text, want) in cases {
        std::fs::write(d.join("space.toml"), text).unwrap();
        let out = d.join("never");
        let args = tune_args(d, out.to_str().unwrap(), "10");
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = realitygap(&args);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{text}");
        assert!(e.contains(want), "{text}: {e}");
        assert!(!out.join("history.csv").exists(), "{text}: it ran");
    }
}

/// `tune --executor slurm` (one job array per generation, on the test
/// cluster that `scripts/test` starts with `scripts/slurm-local start`)
/// finds exactly what the local tune finds with the same seed.
#[test]
fn a_tune_on_slurm_equals_the_local_tune() {
    let started =
        Command::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/slurm-local"))
            .arg("start")
            .output()
            .unwrap();
    assert!(
        started.status.success(),
        "the test cluster did not start: {}",
        String::from_utf8_lossy(&started.stderr)
    );
    let conf = std::env::var("REALITYGAP_SLURM_DIR").unwrap_or("/tmp/realitygap-slurm".into())
        + "/slurm.conf";
    let tmp = synthetic();
    let d = tmp.path();
    let local = d.join("local");
    let on_slurm = d.join("slurm");
    // Without the physics-free baseline's fit: each batch waits about a
    // second for Slurm's scheduler (its main loop runs once a second, and
    // the polish's line searches and profiles send one or two simulations
    // at a time), and the baseline's fit would double the batches (62
    // arrays, 103 s, where the local tune takes 3 s).
    let mut args = tune_args(d, local.to_str().unwrap(), "24");
    args.push("--no-baseline".into());
    ok(realitygap(
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
    ));
    let mut args = tune_args(d, on_slurm.to_str().unwrap(), "24");
    args.extend(["--no-baseline", "--executor", "slurm"].map(String::from));
    let o = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(&args)
        .env("SLURM_CONF", &conf)
        .output()
        .unwrap();
    let o = ok(o);
    drop(o);
    assert_eq!(
        std::fs::read_to_string(local.join("history.csv")).unwrap(),
        std::fs::read_to_string(on_slurm.join("history.csv")).unwrap()
    );
    assert_eq!(
        std::fs::read_to_string(local.join("tuned.toml")).unwrap(),
        std::fs::read_to_string(on_slurm.join("tuned.toml")).unwrap()
    );
    // Candidates evaluated together go as one array: a generation (6
    // candidates for 2 parameters), a Jacobian's columns, the probe. So
    // there are far fewer arrays than evaluations (each of 1 scene).
    let arrays = std::fs::read_dir(on_slurm.join(".slurm")).unwrap().count();
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(on_slurm.join("summary.json")).unwrap())
            .unwrap();
    let evaluations = summary["evaluations"].as_u64().unwrap()
        + summary["polish"]["evaluations"].as_u64().unwrap();
    assert!(
        arrays >= 4 && 2 * arrays as u64 <= evaluations,
        "{arrays} arrays for {evaluations} evaluations"
    );
}

/// Known truth in every engine: each engine runs scene 1 with the actuator
/// stage and the delay that METHOD.md measured on the real arm (and, where
/// its servo has a gain, joint 2's `kv` = 25, which holds the arm up: at
/// 15 it sags 11 degrees past its target, where the cube would be), six
/// times (scene 1 without its cube) with initial offsets
/// and reading noise, and `tune` fits them back from the engine's
/// defaults. What each engine can tell apart must be covered by its 95 %
/// interval: all three of the stage and the delay behind the stiff motors
/// (ODE, Bullet), the gain where the servo has one (behind a soft servo the
/// search at this budget may end in a second optimum: tools/known-truth
/// reports those). An interval wider than the value itself says little and
/// fails too (the intervals of these 3-4 coordinates are profiled, which
/// follows the valley between the stage and the delay: 2-3 times the
/// width of the local model's).
fn known_truth_is_covered_by_the_intervals(engine: &str) {
    let mut failures = Vec::new();
    let has_kv = !matches!(engine, "ode" | "bullet");
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // MuJoCo and DART at the 5 ms step of their tuning spaces
    // (assets/tuning/*.toml); DART at its scene's 1 ms took 214 s here.
    let settings = match engine {
        "mujoco" => SETTINGS,
        "dart" => "[engine.dart]\ntimestep_s = 0.005\n",
        _ => "",
    };
    let mut known = format!(
        "[actuator]\nfrequency_rad_s = 20.0\ndamping_ratio = 0.5\n[controller]\ndelay_s = 0.05\n{settings}"
    );
    let mut space = format!(
        "{settings}[params]\n\"actuator.frequency_rad_s\" = {{ low = 5.0, high = 200.0, scale = \"log\", start = 60.0 }}\n\
         \"actuator.damping_ratio\" = {{ low = 0.1, high = 2.0, start = 1.0 }}\n\
         \"controller.delay_s\" = {{ low = 0.0, high = 0.15, start = 0.0 }}\n"
    );
    if has_kv {
        known += "[joints.m1n6s300_joint_2]\nkv = 25.0\n";
        space += "\"joints.m1n6s300_joint_2.kv\" = { low = 4.0, high = 400.0, scale = \"log\", start = 40.0 }\n";
    }
    std::fs::write(d.join("known.toml"), &known).unwrap();
    std::fs::write(d.join("space.toml"), &space).unwrap();
    let scene = scene1_without_cube(d);
    noisy_known_runs_of(d, engine, &scene);
    write_study_of(d, engine, &scene);
    let out = d.join("tuned");
    ok(realitygap(&[
        "tune",
        d.join("study.toml").to_str().unwrap(),
        "--engine",
        engine,
        "--space",
        d.join("space.toml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--budget",
        "150",
        "--jobs",
        "2",
        // Only the engine's intervals are checked here.
        "--no-baseline",
    ]));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let expected: &[(&str, f64)] = if has_kv {
        &[("joints.m1n6s300_joint_2.kv", 25.0)]
    } else {
        &[
            ("actuator.frequency_rad_s", 20.0),
            ("actuator.damping_ratio", 0.5),
            ("controller.delay_s", 0.05),
        ]
    };
    for &(key, truth) in expected {
        let iv = s["polish"]["intervals"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| i["key"] == key)
            .unwrap_or_else(|| panic!("{engine}: no interval for {key}: {s}"));
        match iv["interval"].as_array() {
            Some(b) => {
                let (lo, hi) = (b[0].as_f64().unwrap(), b[1].as_f64().unwrap());
                if !(lo <= truth && truth <= hi) {
                    failures.push(format!("{engine}: {key} = {truth} outside [{lo}, {hi}]"));
                } else if hi - lo > truth {
                    failures.push(format!(
                        "{engine}: {key}'s interval [{lo}, {hi}] says little about {truth}"
                    ));
                }
            }
            None => failures.push(format!("{engine}: {key} has no interval: {iv}")),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// One test per engine, so that a runner spreads them over the cores.
#[test]
fn known_truth_is_covered_by_the_intervals_in_ode() {
    known_truth_is_covered_by_the_intervals("ode");
}

#[test]
fn known_truth_is_covered_by_the_intervals_in_bullet() {
    known_truth_is_covered_by_the_intervals("bullet");
}

#[test]
fn known_truth_is_covered_by_the_intervals_in_mujoco() {
    known_truth_is_covered_by_the_intervals("mujoco");
}

#[test]
fn known_truth_is_covered_by_the_intervals_in_physx() {
    known_truth_is_covered_by_the_intervals("physx");
}

#[test]
fn known_truth_is_covered_by_the_intervals_in_rapier() {
    known_truth_is_covered_by_the_intervals("rapier");
}

#[test]
fn known_truth_is_covered_by_the_intervals_in_dart() {
    known_truth_is_covered_by_the_intervals("dart");
}

/// `--folds 3` on six known-truth runs: three tunes, each holding out two
/// consecutive runs, and their held-out scores gathered over the folds
/// (each fold's value is that fold's own summary's), with the differences
/// against both physics-free rows; folds that cannot split the runs are
/// refused before anything runs.
#[test]
fn folds_cross_validate_over_consecutive_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(
        d.join("known.toml"),
        format!("[joints.m1n6s300_joint_2]\nkv = {KNOWN_KV}\n[controller]\ndelay_s = {KNOWN_DELAY_S}\n{SETTINGS}"),
    )
    .unwrap();
    std::fs::write(
        d.join("space.toml"),
        format!(
            "{SETTINGS}[params]\n\"joints.m1n6s300_joint_2.kv\" = {{ low = 4.0, high = 400.0, scale = \"log\", start = 40.0 }}\n\
             \"controller.delay_s\" = {{ low = 0.0, high = 0.15, start = 0.0 }}\n"
        ),
    )
    .unwrap();
    noisy_known_runs(d, "mujoco");
    write_study(d, "mujoco");
    let out = d.join("cv");
    let mut args = tune_args(d, out.to_str().unwrap(), "16");
    args.extend(["--folds", "3", "--iterations", "1"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let stdout = String::from_utf8(ok(realitygap(&args)).stdout).unwrap();
    let cv: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("crossval.json")).unwrap()).unwrap();
    let holdouts: Vec<&str> = cv["folds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["fold"]["holdout"].as_str().unwrap())
        .collect();
    assert_eq!(holdouts, ["1-2", "3-4", "5-6"]);
    // The options that differ from the defaults name the tune.
    let space = format!("--space {}", d.join("space.toml").display());
    assert_eq!(
        cv["options"],
        serde_json::json!([space, "--budget 16", "--iterations 1"])
    );
    let md = std::fs::read_to_string(out.join("crossval.md")).unwrap();
    assert!(
        md.starts_with(&format!(
            "# Cross-validated tune of mujoco ({space} --budget 16 --iterations 1)\n"
        )),
        "{md}"
    );
    let row = |source: &str| {
        cv["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["source"] == source)
            .unwrap_or_else(|| panic!("no row {source}: {cv}"))
            .clone()
    };
    let tuned = row("tuned");
    for (i, f) in cv["folds"].as_array().unwrap().iter().enumerate() {
        let folder = Path::new(f["folder"].as_str().unwrap());
        assert_eq!(folder, out.join(format!("fold-{}", i + 1)));
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(folder.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(s["holdout"]["runs"], holdouts[i]);
        // Fitted on every other run, never on the held-out ones.
        assert_eq!(s["training"]["runs"], ["3-6", "1-2,5-6", "1-4"][i]);
        assert_eq!(
            tuned["total"]["folds"][i], s["holdout"]["total_tuned"]["value_m"],
            "fold {i}"
        );
        let free = s["holdout"]["baselines"]
            .as_array()
            .unwrap()
            .iter()
            .find(|b| b["source"] == "physics-free")
            .unwrap();
        assert_eq!(
            row("physics-free")["total"]["folds"][i],
            free["total"]["value_m"]
        );
    }
    let t = &tuned["total"];
    let mean = t["folds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .sum::<f64>()
        / 3.0;
    assert!((t["mean"].as_f64().unwrap() - mean).abs() < 1e-12);
    let lo = t["interval"][0].as_f64().unwrap();
    let hi = t["interval"][1].as_f64().unwrap();
    assert!(lo <= mean && mean <= hi);
    let against: Vec<&str> = cv["differences"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["against"].as_str().unwrap())
        .collect();
    assert_eq!(
        against,
        ["physics-free", "physics-free + actuator (fitted)"]
    );
    // Known truth in the engine itself: the tuned engine is closer than
    // perfect tracking of the commands in every fold.
    let diff = &cv["differences"][0]["total"];
    for v in diff["folds"].as_array().unwrap() {
        assert!(v.as_f64().unwrap() < 0.0, "{diff}");
    }
    let md = std::fs::read_to_string(out.join("crossval.md")).unwrap();
    assert!(
        md.contains("Cross-validated over 3 folds of runs 1-6"),
        "{md}"
    );
    assert!(stdout.contains("Cross-validated over 3 folds"), "{stdout}");
    // By phase of the schedule: each fold's phase errors sum to its
    // scene's, and the figures of the error against time are written.
    let phases = &cv["phases"][0];
    assert_eq!(phases["scene"], "scene1_single_joint");
    let tuned_phases = phases["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["source"] == "tuned")
        .expect("the tuned row by phase");
    for i in 0..3 {
        let sum: f64 = tuned_phases["phases"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["folds"][i].as_f64().unwrap())
            .sum();
        let scene = tuned["scenes"][0]["folds"][i].as_f64().unwrap();
        assert!(
            (sum - scene).abs() < 1e-9 * scene.max(1.0),
            "{sum} vs {scene}"
        );
    }
    assert_eq!(
        phases["t_s"].as_array().unwrap().len(),
        phases["curves"][0]["distance_m"].as_array().unwrap().len()
    );
    assert!(md.contains("## By phase of the schedule"), "{md}");
    for kind in ["distance", "height"] {
        for ext in ["svg", "png"] {
            let f = out.join(format!(
                "figures/crossval_mujoco_scene1_single_joint_held_out_{kind}.{ext}"
            ));
            assert!(f.is_file(), "{}", f.display());
        }
    }
    // A report given the cross-validation opens its verdict with it.
    let site = d.join("site");
    let study = d.join("study.toml");
    let o = realitygap(&[
        "report",
        study.to_str().unwrap(),
        "--data",
        "none",
        "--crossval",
        out.to_str().unwrap(),
        "--out",
        site.to_str().unwrap(),
    ]);
    let html = std::fs::read_to_string(site.join("index.html"))
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&o.stderr)));
    let first = html.find("<p class=\"verdict\">").expect("a verdict");
    assert!(
        html[first..]
            .starts_with("<p class=\"verdict\">Tuned and cross-validated (3 folds of runs 1-6"),
        "{}",
        &html[first..first + 300]
    );
    assert!(html.contains("<section id=\"crossval\">"));
    assert!(site
        .join("figures/crossval_mujoco_scene1_single_joint_held_out_distance.svg")
        .is_file());
    // A folder with no cross-validation is refused before anything is written.
    let site2 = d.join("site2");
    let o = realitygap(&[
        "report",
        study.to_str().unwrap(),
        "--data",
        "none",
        "--crossval",
        d.to_str().unwrap(),
        "--out",
        site2.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("crossval.json") && err.contains("tune --folds"),
        "{err}"
    );
    assert!(!site2.exists());
    // Seven folds of six runs, and folds with a held-out range.
    let out2 = d.join("cv7");
    let mut args = tune_args(d, out2.to_str().unwrap(), "16");
    args.extend(["--folds", "7"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = realitygap(&args);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--folds 7") && err.contains("at most 6 folds"),
        "{err}"
    );
    let mut args = tune_args(d, out2.to_str().unwrap(), "16");
    args.extend(["--folds", "2", "--holdout", "5-6"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = realitygap(&args);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--folds") && err.contains("--holdout"),
        "{err}"
    );
    assert!(!out2.join("fold-1").exists());
}

/// The synthetic study with noisy runs of known truth, and a space that
/// also searches the actuator stage's frequency: two keys (with the delay)
/// that the physics-free row's space shares.
fn known_runs_with_a_loop() -> tempfile::TempDir {
    let tmp = synthetic();
    let d = tmp.path();
    std::fs::remove_dir_all(d.join("runs")).unwrap();
    noisy_known_runs(d, "mujoco");
    let space = std::fs::read_to_string(d.join("space.toml")).unwrap();
    std::fs::write(
        d.join("space.toml"),
        format!("{space}\"actuator.frequency_rad_s\" = {{ low = 4.0, high = 200.0, scale = \"log\", start = 100.0 }}\n"),
    )
    .unwrap();
    tmp
}

/// A JSON file's value.
fn json_file(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// A summary's parameter `key`'s `field` (`value`, `start`, ...).
fn parameter(summary: &serde_json::Value, key: &str, field: &str) -> f64 {
    summary["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["key"] == key)
        .unwrap_or_else(|| panic!("no parameter {key}"))[field]
        .as_f64()
        .unwrap()
}

/// `--start physics-free`: the physics-free row is fitted first and the
/// engine's search starts at its fitted values of the keys both spaces
/// have (here the delay and the actuator's frequency), which the summary
/// says; `--no-baseline` leaves that row out, and cannot go with it.
#[test]
fn the_search_can_start_from_the_fitted_physics_free_row() {
    let tmp = known_runs_with_a_loop();
    let d = tmp.path();
    let out = d.join("seeded");
    let mut args = tune_args(d, out.to_str().unwrap(), "16");
    args.extend(["--start", "physics-free", "--iterations", "1"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let stderr = String::from_utf8(ok(realitygap(&args)).stderr).unwrap();
    assert!(
        stderr.contains("the search starts at the physics-free model's fitted controller.delay_s, actuator.frequency_rad_s"),
        "{stderr}"
    );
    let read = |p: PathBuf| json_file(&p);
    let s = read(out.join("summary.json"));
    assert!(
        s["start"].as_str().unwrap().contains("physics-free"),
        "{}",
        s["start"]
    );
    let b = read(out.join("physics-free-actuator/summary.json"));
    for key in ["controller.delay_s", "actuator.frequency_rad_s"] {
        let fitted = parameter(&b, key, "value");
        let start = parameter(&s, key, "start");
        assert!(
            (start - fitted).abs() <= 1e-9 * fitted.abs().max(1.0),
            "{key}: {start} against {fitted}"
        );
    }
    // The engine's own key keeps its start.
    let kv = s["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["key"] == "joints.m1n6s300_joint_2.kv")
        .unwrap();
    assert_eq!(kv["start"], 40.0);
    // Without the row.
    let plain = d.join("plain");
    let mut args = tune_args(d, plain.to_str().unwrap(), "8");
    args.extend(["--no-baseline", "--iterations", "0"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(realitygap(&args));
    let s = read(plain.join("summary.json"));
    assert!(s["baseline"].is_null(), "{}", s["baseline"]);
    assert!(!plain.join("physics-free-actuator").exists());
    let rows: Vec<&str> = s["training"]["baselines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["source"].as_str().unwrap())
        .collect();
    assert_eq!(rows, ["physics-free"]);
    let mut args = tune_args(d, d.join("both").to_str().unwrap(), "8");
    args.extend(["--no-baseline", "--start", "physics-free"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert!(!realitygap(&args).status.success());
}

/// `--prior-weight W`: the physics-free row is fitted first and the
/// engine's keys it shares are pulled toward its fitted values; with a
/// weight far above the wrist's errors the engine's delay and actuator
/// frequency end at the physics-free row's (the search starts at the
/// space's own start, far from them). The summary's objective names the
/// pull; a negative weight, or one with `--no-baseline`, is refused.
#[test]
fn a_prior_pulls_the_shared_keys_to_the_physics_free_row() {
    let tmp = known_runs_with_a_loop();
    let d = tmp.path();
    let out = d.join("pulled");
    let mut args = tune_args(d, out.to_str().unwrap(), "16");
    args.extend(["--prior-weight", "1e6", "--iterations", "3"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let stderr = String::from_utf8(ok(realitygap(&args)).stderr).unwrap();
    assert!(
        stderr.contains("pulled toward the physics-free model's fitted values with weight 1000000 m per range: controller.delay_s, actuator.frequency_rad_s"),
        "{stderr}"
    );
    let value = parameter;
    let s = json_file(&out.join("summary.json"));
    assert!(
        s["objective"].as_str().unwrap().contains("--prior-weight"),
        "{}",
        s["objective"]
    );
    let b = json_file(&out.join("physics-free-actuator/summary.json"));
    let delay = (
        value(&b, "controller.delay_s", "value"),
        value(&s, "controller.delay_s", "value"),
    );
    assert_eq!(value(&s, "controller.delay_s", "start"), 0.0);
    assert!(
        (delay.1 - delay.0).abs() < 0.01 * 0.15,
        "delay {delay:?}\n{}",
        std::fs::read_to_string(out.join("summary.md")).unwrap()
    );
    let f = (
        value(&b, "actuator.frequency_rad_s", "value"),
        value(&s, "actuator.frequency_rad_s", "value"),
    );
    assert!(
        (f.1 / f.0).ln().abs() < 0.01 * (200.0f64 / 4.0).ln(),
        "frequency {f:?}"
    );
    // Refused: a negative weight, and no physics-free row to pull toward.
    for extra in [
        &["--prior-weight=-1"][..],
        &["--prior-weight", "1", "--no-baseline"],
    ] {
        let mut args = tune_args(d, d.join("refused").to_str().unwrap(), "8");
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = realitygap(&args);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--prior-weight"), "{err}");
    }
    assert!(!d.join("refused").join("history.csv").exists());
}
