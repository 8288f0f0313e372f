//! End-to-end: `realitygap tune --recordings` on the independent writer's
//! recordings of a simulated KUKA iiwa (`scripts/make-fixtures`), whose
//! physical parameters are known (`truth.json`): with the servo gains given
//! as known, MuJoCo recovers the joints' damping, armature (less the
//! implicit servo's dt kv) and dry friction and the command delay, and the
//! held-out joint RMS falls well below the untuned engine's and the
//! physics-free model's.

mod common;
use common::{import_bags, path, realitygap, scratch, text, truth, truth_params};
use serde_json::Value;

fn summary(out: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

fn param<'a>(s: &'a Value, key: &str) -> &'a Value {
    s["params"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["key"] == key)
        .unwrap_or_else(|| panic!("no fitted {key}: {s}"))
}

fn holdout_rms(s: &Value, source_prefix: &str) -> f64 {
    s["scores"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["source"].as_str().unwrap().starts_with(source_prefix))
        .unwrap_or_else(|| panic!("no score {source_prefix}: {s}"))["holdout"]["rms_deg"]
        .as_f64()
        .unwrap()
}

/// How the intervals of a tune cover the truth.
struct Coverage {
    /// Parameters whose interval holds the truth.
    covered: usize,
    /// Parameters.
    of: usize,
    /// The farthest truth from its interval's centre, in half-widths, and
    /// its key.
    worst: (f64, String),
    /// The parameters missed: key, truth, interval.
    misses: Vec<String>,
}

impl Coverage {
    fn line(&self) -> String {
        format!(
            "{} of {} intervals cover the truth; the farthest truth {:.2} half-widths from its interval's centre ({}){}",
            self.covered,
            self.of,
            self.worst.0,
            self.worst.1,
            if self.misses.is_empty() {
                String::new()
            } else {
                format!("; missed: {}", self.misses.join("; "))
            }
        )
    }
}

/// The coverage of `summary`'s intervals against the truth: the joints'
/// `damping`, `armature` (less `dt kd`: MuJoCo's implicitfast integrates
/// the replay's velocity servo implicitly) and `frictionloss` by name, and
/// the delay.
fn coverage(s: &Value, joints: &Value, delay_s: f64, dt: f64) -> Coverage {
    let mut c = Coverage {
        covered: 0,
        of: 0,
        worst: (0.0, String::new()),
        misses: Vec::new(),
    };
    for p in s["params"].as_array().unwrap() {
        let key = p["key"].as_str().unwrap();
        let want = match key.split('.').collect::<Vec<_>>().as_slice() {
            ["controller", "delay_s"] => delay_s,
            ["joints", name, field] => {
                let v = joints[name][field].as_f64().unwrap();
                if *field == "armature" {
                    v - dt * joints[name]["kd"].as_f64().unwrap()
                } else {
                    v
                }
            }
            _ => panic!("unexpected key {key}"),
        };
        let (lo, hi) = (
            p["interval"][0].as_f64().unwrap(),
            p["interval"][1].as_f64().unwrap(),
        );
        let off = (want - (lo + hi) / 2.0).abs() / ((hi - lo) / 2.0);
        c.of += 1;
        if lo <= want && want <= hi {
            c.covered += 1;
        } else {
            c.misses.push(format!("{key} {want} not in [{lo}, {hi}]"));
        }
        if off > c.worst.0 {
            c.worst = (off, key.to_string());
        }
    }
    c
}

#[test]
fn mujoco_recovers_the_writers_parameters_with_the_gains_known() {
    recovers_the_writers_parameters("mujoco");
}

/// MuJoCo 4.0.1 out of process (the `mujoco4` adapter, through the engine
/// protocol): the same recovery, the same tolerances.
#[test]
fn mujoco4_recovers_the_writers_parameters_with_the_gains_known() {
    recovers_the_writers_parameters("mujoco4");
}

fn recovers_the_writers_parameters(engine: &str) {
    let dir = scratch("tune-recordings-tests", &format!("truth-{engine}"));
    let real = import_bags(&dir, 4);
    // Known: the servo gains (kp, and kd as kv). Searched: damping,
    // armature, frictionloss per joint, and the delay.
    let known = truth_params(&dir, &["damping", "armature", "frictionloss", "delay_s"]);
    let out = dir.join("tune");
    let args = [
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        engine,
        "--params",
        &path(&known),
        "--runs",
        "1-2",
        "--holdout",
        "3-4",
        "--out",
        &path(&out),
    ];
    // An engine out of process from wherever it is installed: the
    // command's engines folder, or the kit's (`scripts/setup --tests`).
    let engines_dir = realitygap_engine_remote::registry::adapter(engine)
        .map(realitygap_engine_remote::registry::kit_dir_of);
    let run = match engines_dir {
        None => realitygap(&args),
        Some(dir) => std::process::Command::new(env!("CARGO_BIN_EXE_realitygap"))
            .args(args)
            .env("REALITYGAP_ENGINES_DIR", dir)
            .output()
            .unwrap(),
    };
    let stdout = text(&run.stdout);
    assert!(run.status.success(), "{stdout}{}", text(&run.stderr));
    println!("{stdout}");
    let s = summary(&out);
    let t = truth();
    // MuJoCo integrates the replay's velocity servo implicitly (implicitfast,
    // the generated scene's integrator): its kv enters the mass matrix as
    // M + dt kv, so the armature it fits is the writer's (an explicit PD
    // through qfrc_applied) less dt kv. The timestep of the scene is 1 ms.
    let dt = 1e-3;
    let mut worst = (0.0f64, String::new());
    for (name, j) in t["joints"].as_object().unwrap() {
        for field in ["damping", "armature"] {
            let want = j[field].as_f64().unwrap();
            let mut got = param(&s, &format!("joints.{name}.{field}"))["value"]
                .as_f64()
                .unwrap();
            if field == "armature" {
                got += dt * j["kd"].as_f64().unwrap();
            }
            let rel = (got - want).abs() / want;
            if rel > worst.0 {
                worst = (rel, format!("{name}.{field}: {got} vs {want}"));
            }
            assert!(rel < 0.10, "{name}.{field}: fitted {got}, truth {want}");
        }
        let want = j["frictionloss"].as_f64().unwrap();
        let got = param(&s, &format!("joints.{name}.frictionloss"))["value"]
            .as_f64()
            .unwrap();
        assert!(
            (got - want).abs() < 0.05 * want,
            "{name}.frictionloss: fitted {got}, truth {want}"
        );
    }
    println!("worst relative error of damping and armature: {worst:?}");
    // Every 95 % interval covers the truth (the armature's shifted by
    // dt kv, as its value): the intervals keep room for the remaining
    // model error.
    let c = coverage(&s, &t["joints"], t["delay_s"].as_f64().unwrap(), dt);
    println!("first writer (rosbags): {}", c.line());
    assert_eq!(c.covered, c.of, "{}", c.line());
    // The delay within one joint-state sample (5 ms).
    let delay = param(&s, "controller.delay_s");
    let got = delay["value"].as_f64().unwrap();
    let want = t["delay_s"].as_f64().unwrap();
    assert!((got - want).abs() <= 0.005 + 1e-9, "delay {got} vs {want}");
    // Held out: at least 5x below the untuned engine, and below the
    // physics-free model.
    let untuned = holdout_rms(&s, &format!("{engine} untuned"));
    let tuned = holdout_rms(&s, &format!("{engine} tuned"));
    let kinematic = holdout_rms(&s, "physics-free (perfect");
    assert!(
        tuned * 5.0 <= untuned,
        "held out: tuned {tuned}, untuned {untuned}"
    );
    assert!(
        tuned < kinematic,
        "held out: tuned {tuned}, physics-free {kinematic}"
    );
    assert!(
        s["verdict"].as_str().unwrap().contains(" beats "),
        "{}",
        s["verdict"]
    );
    for f in ["tuned.toml", "space.toml", "history.csv", "summary.md"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // The search's replays (deterministic: Broyden's updates between
    // Jacobians, a coarse delay scan refined beside its best, the last
    // Jacobian kept when the fit ends within a tenth of a standard
    // deviation of it; 111 measured, 473 with a Jacobian per step): fewer
    // than the 131 parameter vectors `mujoco.sysid` needs on this problem
    // with the delay given (tools/sysid-compare). And its time within the
    // whole.
    let evaluations = s["evaluations"].as_u64().unwrap();
    assert!(evaluations < 131, "{evaluations} replays");
    let (search, wall) = (
        s["search_time_s"].as_f64().unwrap(),
        s["wall_time_s"].as_f64().unwrap(),
    );
    assert!(search > 0.0 && search <= wall, "{search} s of {wall} s");
    // The timestep check replayed the held-out episodes at half the
    // scene's 1 ms; its score at the fit's step is the held-out one.
    let c = &s["timestep_check"];
    println!("timestep check: {c}");
    assert_eq!(c["timestep_s"].as_f64(), Some(dt), "{c}");
    assert_eq!(c["halved_s"].as_f64(), Some(dt / 2.0), "{c}");
    assert_eq!(c["episodes"], "held-out", "{c}");
    assert_eq!(c["tuned"]["rms_deg"].as_f64(), Some(tuned), "{c}");
    let halved = c["halved"]["rms_deg"].as_f64().unwrap();
    assert!(halved.is_finite() && halved != tuned, "{c}");
    // And it does not hold: the fitted armature took in dt kv (above), so
    // at half the step the arm is lighter than the recordings' by dt kv / 2.
    assert_eq!(c["holds"], false, "{c}");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("Timestep check: at half the step (0.0005 s instead of 0.001 s)"),
        "{md}"
    );
    // The tuned file replays: `replay --params tuned.toml` on the held-out
    // episodes gives the tune's held-out figure.
    let tuned_file = std::fs::read_to_string(out.join("tuned.toml")).unwrap();
    assert!(tuned_file.contains("damping"), "{tuned_file}");
}

#[test]
fn recorded_efforts_separate_damping_from_the_servo_gain_and_angles_alone_cannot() {
    let dir = scratch("tune-recordings-tests", "unknown-gains");
    let real = import_bags(&dir, 2);
    // Searched: damping and kv of the first two joints; everything else
    // from the truth. From angles alone the joint's damping and the
    // servo's kv trade against each other (both multiply its velocity);
    // the recorded effort (the servo's, without the damping) tells them
    // apart.
    let t = truth();
    let names: Vec<String> = t["joints"]
        .as_object()
        .unwrap()
        .keys()
        .take(2)
        .cloned()
        .collect();
    let space = dir.join("space.toml");
    let mut toml = String::from("[params]\n");
    for name in &names {
        toml.push_str(&format!(
            "\"joints.{name}.damping\" = {{ low = 0.0, high = 10.0, start = 0.5 }}\n\"joints.{name}.kv\" = {{ low = 5.0, high = 60.0, start = 40.0 }}\n"
        ));
    }
    std::fs::write(&space, toml).unwrap();
    // Known: the truth, less the damping and kv of the first two joints.
    let mut known_text = std::fs::read_to_string(truth_params(&dir, &["damping", "kv"])).unwrap();
    for (name, j) in t["joints"].as_object().unwrap().iter().skip(2) {
        known_text = known_text.replace(
            &format!("[joints.{name}]\n"),
            &format!(
                "[joints.{name}]\ndamping = {}\nkv = {}\n",
                j["damping"], j["kd"]
            ),
        );
    }
    let known = dir.join("known.toml");
    std::fs::write(&known, known_text).unwrap();
    let tune = |out: &str, extra: &[&str]| {
        let out = dir.join(out);
        let mut args = vec![
            "tune".to_string(),
            "--recordings".into(),
            path(&real),
            "--engine".into(),
            "mujoco".into(),
            "--params".into(),
            path(&known),
            "--space".into(),
            path(&space),
            "--runs".into(),
            "1".into(),
            "--holdout".into(),
            "2".into(),
            "--out".into(),
            path(&out),
        ];
        args.extend(extra.iter().map(|x| x.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let run = realitygap(&args);
        let stdout = text(&run.stdout);
        assert!(run.status.success(), "{stdout}{}", text(&run.stderr));
        (summary(&out), stdout)
    };
    // From the angles alone: each joint's pair is named.
    let (s, stdout) = tune("angles-only", &["--iterations", "4", "--verbose"]);
    let trading = s["identifiability"]["trading"].as_array().unwrap();
    for name in &names {
        assert!(
            trading.iter().any(|p| {
                p[0] == format!("joints.{name}.damping") && p[1] == format!("joints.{name}.kv")
            }),
            "{name}: {trading:?}\n{stdout}"
        );
    }
    assert!(stdout.contains("trade against each other"), "{stdout}");
    // With the efforts, in a scene whose servo MuJoCo integrates
    // explicitly (Euler, like the writer's PD): both found, nothing trades.
    let generated = std::fs::read_to_string(dir.join("angles-only/replay.toml")).unwrap();
    assert!(
        generated.contains("integrator = \"implicitfast\""),
        "{generated}"
    );
    let euler = dir.join("euler.toml");
    std::fs::write(
        &euler,
        generated.replace("integrator = \"implicitfast\"", "integrator = \"Euler\""),
    )
    .unwrap();
    let (s, stdout) = tune("with-efforts", &["--efforts", "--scene", &path(&euler)]);
    assert!(
        s["objective"]
            .as_str()
            .unwrap()
            .contains("recorded efforts"),
        "{stdout}"
    );
    for name in &names {
        for (field, theirs) in [("damping", "damping"), ("kv", "kd")] {
            let want = t["joints"][name][theirs].as_f64().unwrap();
            let got = param(&s, &format!("joints.{name}.{field}"))["value"]
                .as_f64()
                .unwrap();
            assert!(
                (got - want).abs() < 0.1 * want,
                "{name}.{field}: {got} vs {want}\n{stdout}"
            );
        }
    }
    assert!(
        s["identifiability"]["trading"]
            .as_array()
            .unwrap()
            .is_empty(),
        "{stdout}"
    );
}

#[test]
fn bad_requests_are_named() {
    let dir = scratch("tune-recordings-tests", "bad");
    // --params belongs to --recordings.
    let run = realitygap(&[
        "tune",
        "assets/studies/collins2019.toml",
        "--engine",
        "mujoco",
        "--params",
        "x.toml",
        "--out",
        &path(&dir.join("x")),
    ]);
    assert!(!run.status.success());
    assert!(
        text(&run.stderr).contains("--recordings"),
        "{}",
        text(&run.stderr)
    );
    // A folder that is not an import.
    let run = realitygap(&[
        "tune",
        "--recordings",
        &path(&dir),
        "--engine",
        "mujoco",
        "--out",
        &path(&dir.join("y")),
    ]);
    assert!(!run.status.success());
    assert!(
        text(&run.stderr).contains(&path(&dir)),
        "{}",
        text(&run.stderr)
    );
    // Known parameters that fix every key of the space.
    let real = import_bags(&dir, 1);
    let known = truth_params(&dir, &[]);
    let space = dir.join("space.toml");
    std::fs::write(
        &space,
        "[params]\n\"joints.lbr_iiwa_joint_1.damping\" = { low = 0.0, high = 5.0 }\n",
    )
    .unwrap();
    let run = realitygap(&[
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        "mujoco",
        "--params",
        &path(&known),
        "--space",
        &path(&space),
        "--out",
        &path(&dir.join("z")),
    ]);
    let stderr = text(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("nothing to fit"), "{stderr}");
    // A held-out range past the episodes.
    let run = realitygap(&[
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        "mujoco",
        "--holdout",
        "5",
        "--out",
        &path(&dir.join("w")),
    ]);
    let stderr = text(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("--holdout \"5\""), "{stderr}");
    // --set reaches the replay's engine (it was once ignored with
    // --recordings): a value the engine refuses is a load error naming it.
    let run = realitygap(&[
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        "mujoco",
        "--params",
        &path(&truth_params(&dir, &["damping"])),
        "--set",
        "integrator=sideways",
        "--out",
        &path(&dir.join("v")),
    ]);
    let stderr = text(&run.stderr);
    assert!(!run.status.success(), "{stderr}");
    assert!(stderr.contains("sideways"), "{stderr}");
}

#[test]
fn a_rerun_resumes_from_the_best_point_of_its_history() {
    let dir = scratch("tune-recordings-tests", "resume");
    let real = import_bags(&dir, 1);
    let t = truth();
    let names: Vec<String> = t["joints"]
        .as_object()
        .unwrap()
        .keys()
        .take(2)
        .cloned()
        .collect();
    let mut known_text = std::fs::read_to_string(truth_params(&dir, &["damping"])).unwrap();
    for (name, j) in t["joints"].as_object().unwrap().iter().skip(2) {
        known_text = known_text.replace(
            &format!("[joints.{name}]\n"),
            &format!("[joints.{name}]\ndamping = {}\n", j["damping"]),
        );
    }
    let known = dir.join("known.toml");
    std::fs::write(&known, known_text).unwrap();
    let space = dir.join("space.toml");
    let mut toml = String::from("[params]\n");
    for name in &names {
        toml.push_str(&format!(
            "\"joints.{name}.damping\" = {{ low = 0.0, high = 10.0, start = 0.5 }}\n"
        ));
    }
    std::fs::write(&space, toml).unwrap();
    let out = dir.join("tune");
    let tune = || {
        let run = realitygap(&[
            "tune",
            "--recordings",
            &path(&real),
            "--engine",
            "mujoco",
            "--params",
            &path(&known),
            "--space",
            &path(&space),
            "--iterations",
            "1",
            "--out",
            &path(&out),
        ]);
        assert!(run.status.success(), "{}", text(&run.stderr));
        let s = summary(&out);
        s["scores"][1]["train"]["rms_deg"].as_f64().unwrap()
    };
    let first = tune();
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert!(!history.contains("# resumed"), "{history}");
    let second = tune();
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert!(history.contains("# resumed"), "{history}");
    assert!(second <= first, "resumed {second}, first {first}");
    // Another space starts afresh.
    std::fs::write(
        &space,
        std::fs::read_to_string(&space)
            .unwrap()
            .replace("high = 10.0", "high = 9.0"),
    )
    .unwrap();
    tune();
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    assert!(!history.contains("# resumed"), "{history}");
}

/// The second writer's recordings of the iiwa (`scripts/make-fixtures`:
/// `tools/fixtures/make_second_writer.py`, Foxglove's `mcap_ros2` writer,
/// JointTrajectory commands, header stamps and a recorder's log times).
fn second_writer() -> std::path::PathBuf {
    let dir = realitygap_core::testing::joint_recording_fixtures()
        .parent()
        .unwrap()
        .join("second-writer");
    assert!(
        dir.join("truth.json").is_file(),
        "the second writer's recordings are missing at {}: run scripts/make-fixtures (scripts/setup --tests does)",
        dir.display()
    );
    dir
}

/// Known truth from another writer: `varied/` simulated again with other
/// joint parameters, other gains and a 17 ms delay, `noisy/` the first
/// writer's simulation with white reading noise of 0.002 deg on every
/// position (about as large as what the replay cannot reproduce of the
/// writer's model). MuJoCo, the gains known, episodes 1-2 fitted and 3-4
/// held out: every interval covers the truth, and the summary says what
/// the intervals rest on. (Before commands were put in force at their
/// step's instant whatever the rounding, `varied/` had 9 of 22 covered,
/// every damping 12-35 % high; before the intervals kept room for the
/// model error under reading noise, `noisy/` had 10 of 22.)
#[test]
fn intervals_cover_the_truth_on_a_second_writers_recordings() {
    let sw = second_writer();
    let t: Value =
        serde_json::from_str(&std::fs::read_to_string(sw.join("truth.json")).unwrap()).unwrap();
    let dir = scratch("tune-recordings-tests", "second-writer");
    let urdf = realitygap_core::testing::iiwa_urdf();
    let mut lines = Vec::new();
    let mut missed = Vec::new();
    for layout in ["varied", "noisy"] {
        let l = &t["layouts"][layout];
        let (joints, delay) = match l.get("joints") {
            Some(j) => (j, l["delay_s"].as_f64().unwrap()),
            None => (&t["joints"], t["delay_s"].as_f64().unwrap()),
        };
        let real = dir.join(layout).join("real");
        let mut args = vec!["import".to_string(), "rosbag".into()];
        for e in 0..4 {
            args.push(path(&sw.join(layout).join(format!("episode_{e:03}.mcap"))));
        }
        args.extend(["--robot".into(), path(&urdf), "--out".into(), path(&real)]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let run = realitygap(&args);
        assert!(run.status.success(), "{}", text(&run.stderr));
        let mut known = String::new();
        for (name, j) in joints.as_object().unwrap() {
            known.push_str(&format!(
                "[joints.{name}]\nkp = {}\nkv = {}\n",
                j["kp"], j["kd"]
            ));
        }
        let known_file = dir.join(layout).join("known.toml");
        std::fs::write(&known_file, known).unwrap();
        let out = dir.join(layout).join("tune");
        let run = realitygap(&[
            "tune",
            "--recordings",
            &path(&real),
            "--engine",
            "mujoco",
            "--params",
            &path(&known_file),
            "--runs",
            "1-2",
            "--holdout",
            "3-4",
            "--out",
            &path(&out),
        ]);
        let stdout = text(&run.stdout);
        assert!(run.status.success(), "{stdout}{}", text(&run.stderr));
        let s = summary(&out);
        let c = coverage(&s, joints, delay, 1e-3);
        lines.push(format!("second writer, {layout}/: {}", c.line()));
        if c.covered < c.of {
            missed.push(layout);
        }
        // What the intervals rest on, in words, on the terminal too.
        let res = &s["identifiability"]["residuals"];
        let (noise, structure) = (
            res["noise_deg"].as_f64().unwrap(),
            res["structure_deg"].as_f64().unwrap(),
        );
        let first = s["cautions"][0].as_str().unwrap();
        assert!(
            stdout.contains("How far to trust the intervals"),
            "{stdout}"
        );
        if layout == "noisy" {
            // The reading noise is found in the residuals.
            let known_noise = l["position_noise_deg"].as_f64().unwrap();
            assert!(
                (noise / known_noise - 1.0).abs() < 0.1,
                "noise {noise} deg, written {known_noise}"
            );
            assert!(first.contains("mostly white reading noise"), "{first}");
        } else {
            assert!(noise < structure / 3.0, "{res}");
            assert!(
                first.contains("mostly structure the engine cannot reproduce"),
                "{first}"
            );
        }
        let tuned = holdout_rms(&s, "mujoco tuned");
        let kinematic = holdout_rms(&s, "physics-free (perfect");
        assert!(tuned * 100.0 < kinematic, "{tuned} vs {kinematic}");
    }
    println!("{}", lines.join("\n"));
    assert!(missed.is_empty(), "{}", lines.join("\n"));
}

/// A fit that ends on a bound of its space says that its intervals cannot
/// be trusted, and which parameter.
#[test]
fn a_fit_on_a_bound_says_its_intervals_cannot_be_trusted() {
    let dir = scratch("tune-recordings-tests", "bound");
    let real = import_bags(&dir, 1);
    let t = truth();
    let mut known_text = std::fs::read_to_string(truth_params(&dir, &["damping"])).unwrap();
    for (name, j) in t["joints"].as_object().unwrap().iter().skip(2) {
        known_text = known_text.replace(
            &format!("[joints.{name}]\n"),
            &format!("[joints.{name}]\ndamping = {}\n", j["damping"]),
        );
    }
    let known = dir.join("known.toml");
    std::fs::write(&known, known_text).unwrap();
    // Joint 1's damping (truth 2) may not exceed 1.
    let space = dir.join("space.toml");
    std::fs::write(
        &space,
        "[params]\n\"joints.lbr_iiwa_joint_1.damping\" = { low = 0.0, high = 1.0, start = 0.5 }\n\"joints.lbr_iiwa_joint_2.damping\" = { low = 0.0, high = 10.0, start = 0.5 }\n",
    )
    .unwrap();
    let out = dir.join("tune");
    let run = realitygap(&[
        "tune",
        "--recordings",
        &path(&real),
        "--engine",
        "mujoco",
        "--params",
        &path(&known),
        "--space",
        &path(&space),
        "--out",
        &path(&out),
    ]);
    let stdout = text(&run.stdout);
    assert!(run.status.success(), "{stdout}{}", text(&run.stderr));
    let s = summary(&out);
    assert_eq!(
        param(&s, "joints.lbr_iiwa_joint_1.damping")["at_bound"],
        true,
        "{s}"
    );
    let cautions: Vec<&str> = s["cautions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    assert!(
        cautions
            .iter()
            .any(|c| c.contains("ended on a bound")
                && c.contains("joints.lbr_iiwa_joint_1.damping (1)")),
        "{cautions:?}"
    );
    assert!(stdout.contains("ended on a bound"), "{stdout}");
}
