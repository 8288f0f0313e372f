//! `realitygap run --params` end to end in every compiled-in engine: a
//! lower force limit on joint 2 moves the wrist, the manifest records the
//! parameters, and unknown, unsupported or malformed keys are clear errors;
//! `realitygap engines --params` lists every key per engine.

use realitygap_core::trajectory::WRIST;
use realitygap_data::runstore::RunStore;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .unwrap()
}

fn scene1() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/scenes/scene1_single_joint.toml")
}

fn engines() -> Vec<String> {
    let out = realitygap(&["engines"]);
    assert!(out.status.success());
    // The built-in adapters not installed are listed with their install
    // line, and are no engine to run.
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| !l.contains("not installed: "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

/// Runs scene 1 in `engine` (with `--params` when given) and returns the
/// run's wrist position at 1.5 s and the manifest's config.
fn wrist_at_1_5_s(
    engine: &str,
    params: Option<&Path>,
    out: &Path,
) -> ([f64; 3], serde_json::Value) {
    let scene = scene1();
    let mut args = vec![
        "run",
        scene.to_str().unwrap(),
        "--engine",
        engine,
        "--out",
        out.to_str().unwrap(),
    ];
    if let Some(p) = params {
        args.extend(["--params", p.to_str().unwrap()]);
    }
    let o = realitygap(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let store = RunStore::open(&out.join("scene1_single_joint").join(engine)).unwrap();
    let t = store.read_run("run000").unwrap();
    let p = t.positions(WRIST)[30].unwrap();
    ([p.x, p.y, p.z], store.manifest().settings["config"].clone())
}

#[test]
fn a_lower_force_limit_on_joint_2_moves_the_wrist_in_every_engine() {
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("weak.toml");
    std::fs::write(&params, "[joints.m1n6s300_joint_2]\nforce_limit = 2.0\n").unwrap();
    // The physics-free model has no forces: it refuses the key (below).
    let engines: Vec<String> = realitygap::physics_engines()
        .iter()
        .map(|e| e.name().to_string())
        .collect();
    assert!(!engines.is_empty());
    for engine in &engines {
        let (plain, _) = wrist_at_1_5_s(engine, None, &tmp.path().join(format!("plain-{engine}")));
        let (weak, config) = wrist_at_1_5_s(
            engine,
            Some(&params),
            &tmp.path().join(format!("weak-{engine}")),
        );
        let d = ((plain[0] - weak[0]).powi(2)
            + (plain[1] - weak[1]).powi(2)
            + (plain[2] - weak[2]).powi(2))
        .sqrt();
        eprintln!(
            "PARAMS engine={engine} wrist difference at 1.5 s with force_limit 2.0: {:.4} m",
            d
        );
        assert!(d > 0.005, "{engine}: the wrist moved only {d} m");
        assert_eq!(
            config["params"]["joints"]["m1n6s300_joint_2"]["force_limit"],
            serde_json::json!(2.0),
            "{engine}: {config}"
        );
        assert!(config["params_file"]
            .as_str()
            .unwrap()
            .ends_with("weak.toml"));
    }
}

#[test]
fn unknown_unsupported_and_malformed_keys_are_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = scene1();
    let run = |params: &Path, engine: &str| {
        realitygap(&[
            "run",
            scene.to_str().unwrap(),
            "--engine",
            engine,
            "--params",
            params.to_str().unwrap(),
            "--out",
            tmp.path().join("out").to_str().unwrap(),
        ])
    };
    let engine = &engines()[0];

    let unknown = tmp.path().join("unknown.toml");
    std::fs::write(&unknown, "[joints.m1n6s300_joint_2]\nstiffness = 2.0\n").unwrap();
    let o = run(&unknown, engine);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("unknown.toml:2:1") && e.contains("stiffness"),
        "{e}"
    );

    let malformed = tmp.path().join("malformed.toml");
    std::fs::write(&malformed, "[joints.m1n6s300_joint_2]\ndamping = = 1\n").unwrap();
    let o = run(&malformed, engine);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("malformed.toml:2:"), "{e}");

    let no_joint = tmp.path().join("nojoint.toml");
    std::fs::write(&no_joint, "[joints.elbow]\ndamping = 1.0\n").unwrap();
    let o = run(&no_joint, engine);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("nojoint.toml:1:9") && e.contains("no joint"),
        "{e}"
    );

    // A misspelt [engine.NAME] table, in the parameters file or in the
    // scene, is an error at its line, not settings ignored in silence.
    let typo = tmp.path().join("typo.toml");
    std::fs::write(&typo, "# settings\n[engine.odee]\ntimestep_s = 0.5\n").unwrap();
    let o = run(&typo, engine);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("typo.toml:2: [engine.odee]: no engine is called \"odee\"; did you mean [engine.ode]? (engines here: ")
            && e.contains(engine.as_str()),
        "{e}"
    );
    // The scene, copied out of the source tree with its robot's path made
    // absolute.
    let urdf = scene.parent().unwrap().join("../robots/mico2/mico2.urdf");
    let scene_text = std::fs::read_to_string(&scene).unwrap().replace(
        "urdf = \"../robots/mico2/mico2.urdf\"",
        &format!("urdf = {:?}", urdf.display().to_string()),
    );
    assert!(scene_text.contains("\n[engine.mujoco]\n"));
    let bad_scene = tmp.path().join("typo-scene.toml");
    std::fs::write(
        &bad_scene,
        scene_text.replace("\n[engine.mujoco]\n", "\n[engine.mujocoo]\n"),
    )
    .unwrap();
    let o = realitygap(&[
        "run",
        bad_scene.to_str().unwrap(),
        "--engine",
        engine,
        "--out",
        tmp.path().join("out").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains(
            "[engine.mujocoo]: no engine is called \"mujocoo\"; did you mean [engine.mujoco]?"
        ),
        "{e}"
    );
    // A misspelt key of the scene's own engine table: at its line.
    if engines().iter().any(|e| e == "mujoco") {
        assert!(scene_text.contains("\n[engine.mujoco]\ntimestep_s = "));
        std::fs::write(
            &bad_scene,
            scene_text.replace(
                "\n[engine.mujoco]\ntimestep_s = ",
                "\n[engine.mujoco]\ntimestep = ",
            ),
        )
        .unwrap();
        let o = realitygap(&[
            "run",
            bad_scene.to_str().unwrap(),
            "--engine",
            "mujoco",
            "--out",
            tmp.path().join("out").to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr);
        let line = scene_text
            .lines()
            .position(|l| l == "[engine.mujoco]")
            .unwrap()
            + 2;
        assert!(
            e.contains(&format!(".toml:{line}:1: engine.mujoco.timestep: engine mujoco: setting `timestep`: unknown setting")),
            "{e}"
        );
        // A timestep that does not divide the control period is blamed on
        // the timestep where it was given (not on controller.period_s),
        // with one that fits: the scene's table at its line, or --set.
        let lines: Vec<String> = scene_text
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i + 1 == line {
                    "timestep_s = 1.0".to_string()
                } else {
                    l.to_string()
                }
            })
            .collect();
        std::fs::write(&bad_scene, lines.join("\n")).unwrap();
        let out = tmp.path().join("out");
        let fails = |scene: &Path, set: &[&str]| {
            let mut args = vec!["run", scene.to_str().unwrap(), "--engine", "mujoco"];
            args.extend(set);
            args.extend(["--out", out.to_str().unwrap()]);
            let o = realitygap(&args);
            assert!(!o.status.success());
            String::from_utf8_lossy(&o.stderr).into_owned()
        };
        let e = fails(&bad_scene, &[]);
        assert!(
            e.contains(&format!(".toml:{line}:1: engine.mujoco.timestep_s: timestep_s = 1 s does not divide the scene's control period (0.05 s, controller.period_s) into whole steps: try 0.05 s (1 step a period)")),
            "{e}"
        );
        let e = fails(&scene1(), &["--set", "mujoco.timestep_s=0.03"]);
        assert!(
            e.contains("--set: timestep_s = 0.03 s does not divide the scene's control period (0.05 s, controller.period_s) into whole steps: try 0.025 s (2 steps a period)"),
            "{e}"
        );
    }
    // A built-in adapter's table is no typo, installed or not; nor is an
    // engine this machine lacks whose name is no near miss.
    let adapter = tmp.path().join("adapter.toml");
    std::fs::write(
        &adapter,
        "[engine.newton]\nbackend = \"c\"\n[engine.vortex]\nsolver = 1\n",
    )
    .unwrap();
    let o = run(&adapter, engine);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    // Every engine that lacks a key says so, naming itself and the key.
    let list = realitygap(&["engines", "--params"]);
    let table = String::from_utf8_lossy(&list.stdout).to_string();
    let mut unsupported_seen = 0;
    let mut current = String::new();
    for line in table.lines() {
        if !line.starts_with(' ') {
            current = line
                .split_whitespace()
                .next()
                .unwrap_or_default()
                .to_string();
            continue;
        }
        if !line.contains("not supported") {
            continue;
        }
        let key = line.split_whitespace().next().unwrap();
        let text = match key {
            "joints.<joint>.armature" => "[joints.m1n6s300_joint_2]\narmature = 0.01\n",
            "joints.<joint>.kv" => "[joints.m1n6s300_joint_2]\nkv = 20.0\n",
            "joints.<joint>.damping" => "[joints.m1n6s300_joint_2]\ndamping = 0.1\n",
            "joints.<joint>.frictionloss" => "[joints.m1n6s300_joint_2]\nfrictionloss = 0.1\n",
            "objects.<object>.restitution" => "[objects.cube]\nrestitution = 0.5\n",
            "contact.time_constant_s" => "[contact]\ntime_constant_s = 0.02\n",
            "contact.damping_ratio" => "[contact]\ndamping_ratio = 1.0\n",
            _ => continue,
        };
        let f = tmp.path().join(format!("{current}-unsupported.toml"));
        std::fs::write(&f, text).unwrap();
        let o = run(&f, &current);
        assert!(!o.status.success(), "{current} accepted {key}");
        let e = String::from_utf8_lossy(&o.stderr);
        let full = key
            .replace("<joint>", "m1n6s300_joint_2")
            .replace("<object>", "cube");
        assert!(
            e.contains(&format!("engine {current}")) && e.contains(&full),
            "{e}"
        );
        unsupported_seen += 1;
    }
    eprintln!("unsupported keys checked: {unsupported_seen}");
}

#[test]
fn engines_lists_every_parameter_key_per_engine() {
    let o = realitygap(&["engines", "--params"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    for key in [
        "joints.<joint>.damping",
        "joints.<joint>.armature",
        "joints.<joint>.frictionloss",
        "joints.<joint>.kv",
        "joints.<joint>.force_limit",
        "joints.<joint>.offset_deg",
        "links.<link>.mass_scale",
        "objects.<object>.mass_kg",
        "objects.<object>.friction",
        "objects.<object>.restitution",
        "contact.time_constant_s",
        "contact.damping_ratio",
        "controller.delay_s",
        "controller.gain_per_s",
        "controller.max_speed_deg_s",
    ] {
        assert_eq!(
            text.matches(key).count(),
            engines().len(),
            "{key} not listed once per engine:\n{text}"
        );
    }
}

/// `engines --commands`: every compiled engine says how it takes each kind
/// of joint command.
#[test]
fn every_engine_lists_its_mechanism_for_each_command_kind() {
    let list = realitygap(&["engines", "--commands"]);
    assert!(list.status.success());
    let table = String::from_utf8_lossy(&list.stdout).to_string();
    let engines: Vec<&str> = table
        .lines()
        .filter(|l| !l.starts_with(' ') && !l.contains("not installed: "))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert!(!engines.is_empty(), "{table}");
    for kind in ["velocity (rad/s)", "position (rad)", "effort (N m)"] {
        assert_eq!(
            table
                .lines()
                .filter(|l| l.trim_start().starts_with(kind))
                .count(),
            engines.len(),
            "one {kind} line per engine:\n{table}"
        );
    }
}
