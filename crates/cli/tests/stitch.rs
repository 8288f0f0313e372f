//! Stitched runs (issue 13): a run handed from engine to engine at the
//! phase boundaries of scene 3 (8 s and 14 s). Handing over to the same
//! engine loses nothing; handing over to another engine keeps the arm's
//! motion continuous; every engine hands over to every other; the command
//! line runs and stores them; bad plans are clear errors.

use realitygap_core::controller::{
    load_prepared, prepare, simulate, ControlParams, RunError, RunOptions, RunOutcome, RunStatus,
};
use realitygap_core::engine::{Engine, Simulation};
use realitygap_core::scene::Scene;
use realitygap_core::stitch::{run_stitched, StitchedRun};
use realitygap_core::testing;
use realitygap_core::Vec3;
use std::path::Path;
use std::process::Command;

fn engines() -> Vec<Box<dyn Engine>> {
    realitygap::physics_engines()
}

fn engine(name: &str) -> Option<Box<dyn Engine>> {
    engines().into_iter().find(|e| e.name() == name)
}

/// Scene 3 stitched with one engine per phase, in this process.
fn stitched(scene: &Scene, plan: &[&str]) -> StitchedRun {
    let robot = testing::mico2();
    let all = engines();
    let mut load = |name: &str| -> Result<Box<dyn Simulation>, RunError> {
        let e = all.iter().find(|e| e.name() == name).expect("compiled in");
        let params = realitygap_core::PhysicalParams::none();
        let (scene, robot) = prepare(e.as_ref(), scene, &robot, &params)?;
        load_prepared(
            e.as_ref(),
            &scene,
            &robot,
            &scene.settings_for(name),
            &params,
            &RunOptions::default(),
        )
    };
    let plan: Vec<String> = plan.iter().map(|s| s.to_string()).collect();
    run_stitched(
        scene,
        &plan,
        &RunOptions::default(),
        &ControlParams::default(),
        &mut load,
    )
    .unwrap()
}

fn plain(scene: &Scene, e: &dyn Engine) -> RunOutcome {
    simulate(
        e,
        scene,
        &testing::mico2(),
        &scene.settings_for(e.name()),
        &RunOptions::default(),
    )
    .unwrap()
}

/// Tracked positions per row.
fn rows(out: &RunOutcome) -> Vec<Vec<Vec3>> {
    let t = &out.trajectory;
    (0..t.len())
        .map(|i| {
            t.bodies
                .iter()
                .map(|b| b.poses[i].expect("a pose").position_m)
                .collect()
        })
        .collect()
}

/// The largest distance between the two runs' tracked positions over
/// rows `0..n` (every row of both when `n` is `None`).
fn max_gap(a: &RunOutcome, b: &RunOutcome, n: Option<usize>) -> f64 {
    let (ra, rb) = (rows(a), rows(b));
    if n.is_none() {
        assert_eq!(ra.len(), rb.len(), "row counts differ");
    }
    let n = n.unwrap_or(ra.len());
    ra[..n]
        .iter()
        .zip(&rb[..n])
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| p.distance(*q)))
        .fold(0.0, f64::max)
}

/// The largest distance between body `body`'s positions, every row.
fn max_gap_of(a: &RunOutcome, b: &RunOutcome, body: usize, n: usize) -> f64 {
    rows(a)
        .iter()
        .zip(rows(b))
        .take(n)
        .map(|(x, y)| x[body].distance(y[body]))
        .fold(0.0, f64::max)
}

/// Handing over to the same engine at 8 s and 14 s: the whole (native)
/// state carries over. MuJoCo, Bullet and ODE restore it exactly and the
/// stitched run equals the plain one on every row (1e-9 m; measured 0).
/// Rapier keeps no contact warm starts in its state (its README: the
/// native round trip of scene 3 during the push is 2.6 cm): at 8 s the
/// cube resting on the table restarts its contact from zero impulse and
/// settles again (1.2e-4 m before 14 s, the wrist 6.4e-6 m; tolerance
/// 2e-4 m), and at 14 s, with the hand about to press on the cube, the
/// push that follows tips the cube differently (2.6e-2 m; tolerance
/// 0.03 m). PhysX's state has no native part at all (its contact
/// manifolds cannot be read) and setting it rebuilds the world: 4.3e-4 m
/// before 14 s (the resting cube's contact restarts; the wrist 8.6e-5 m),
/// 1.3e-2 m after the push (tolerances 1e-3 m and 0.02 m).
#[test]
fn a_run_stitched_to_the_same_engine_equals_the_plain_run() {
    let scene = testing::scene("scene3_cube_push");
    for e in engines() {
        let name = e.name();
        let s = stitched(&scene, &[name, name, name]);
        assert_eq!(s.outcome.status, RunStatus::Completed, "{name}");
        assert_eq!(s.handovers.len(), 2);
        assert!(s.handovers.iter().all(|h| h.native), "{name}");
        let p = plain(&scene, e.as_ref());
        let whole = max_gap(&s.outcome, &p, None);
        let before_push = max_gap(&s.outcome, &p, Some(280));
        let wrist = max_gap_of(&s.outcome, &p, 0, 400);
        let wrist_before = max_gap_of(&s.outcome, &p, 0, 280);
        eprintln!(
            "STITCH {name}: wrist alone, every row {wrist:.3e} m, before 14 s {wrist_before:.3e} m"
        );
        eprintln!(
            "STITCH {name}>{name}>{name} vs {name}: every row {whole:.3e} m, rows before 14 s {before_push:.3e} m"
        );
        let (tolerance_m, before_tolerance_m) = match name {
            "rapier" => (0.03, 2e-4),
            "physx" => (0.02, 1e-3),
            _ => (1e-9, 1e-9),
        };
        assert!(whole <= tolerance_m, "{name}: {whole} m");
        assert!(before_push <= before_tolerance_m, "{name}: {before_push} m");
        for h in &s.handovers {
            assert_eq!(h.joint_angle_diff_rad, 0.0, "{name} {h:?}");
            assert!(h.corrections.is_empty(), "{name} {h:?}");
        }
    }
}

/// The study's proposal on scene 3: Bullet's stiff motors for the free
/// motion, MuJoCo for the push. Before 14 s it is Bullet's own run
/// (1e-6 m); every value is finite; the wrist does not jump at the
/// handover more than it moves between the rows around it.
#[test]
fn bullet_then_mujoco_continues_bullets_run() {
    let (Some(bullet), Some(_)) = (engine("bullet"), engine("mujoco")) else {
        return;
    };
    let scene = testing::scene("scene3_cube_push");
    let s = stitched(&scene, &["bullet", "bullet", "mujoco"]);
    assert_eq!(s.outcome.status, RunStatus::Completed);
    let b = plain(&scene, bullet.as_ref());
    let before = max_gap(&s.outcome, &b, Some(280));
    assert!(before <= 1e-6, "rows before 14 s differ by {before} m");
    let r = rows(&s.outcome);
    assert_eq!(r.len(), 400);
    assert!(r.iter().flatten().all(|p| p.is_finite()));
    let wrist: Vec<Vec3> = r.iter().map(|row| row[0]).collect();
    let jump = |i: usize| wrist[i + 1].distance(wrist[i]);
    // Rows 279 -> 280 (Bullet's last, MuJoCo's first) and 280 -> 281
    // (MuJoCo's first period) against the jumps of the 10 rows around.
    let at_boundary = jump(279).max(jump(280));
    let around = (274..279).chain(281..286).map(jump).fold(0.0, f64::max);
    let h = &s.handovers[1];
    eprintln!(
        "STITCH bullet>bullet>mujoco: before 14 s {before:.3e} m; wrist jump at 14 s {at_boundary:.4e} m, largest around {around:.4e} m; handover {h:?}"
    );
    assert!(at_boundary <= around, "{at_boundary} > {around}");
    assert_eq!(
        (h.from.as_str(), h.to.as_str(), h.native),
        ("bullet", "mujoco", false)
    );
    assert!(h.joint_angle_diff_rad <= 1e-9, "{h:?}");
    assert!(h.tracked_position_diff_m <= 1e-3, "{h:?}");
}

/// Every engine hands the run to every other at 8 s (the arm moving):
/// the run completes with finite values, the joint angles and
/// velocities arrive (1e-6), and the objects move only by the resting
/// rule's lift (ODE's soft joints add their constraint error to the
/// tracked positions, 2e-4 m; see the handover test).
#[test]
fn every_engine_hands_a_run_to_every_other() {
    let scene = testing::scene("scene3_cube_push");
    let names: Vec<&str> = engines().iter().map(|e| e.name()).collect();
    for from in &names {
        for to in &names {
            if from == to {
                continue;
            }
            let s = stitched(&scene, &[from, to, to]);
            let h = &s.handovers[0];
            eprintln!(
                "STITCH {from}>{to} at 8 s: {:?}; angles {:.2e} rad, velocities {:.2e} rad/s, objects {:.2e} m, tracked {:.2e} m, lift {:?}",
                s.outcome.status,
                h.joint_angle_diff_rad,
                h.joint_velocity_diff_rad_s,
                h.object_position_diff_m,
                h.tracked_position_diff_m,
                h.corrections.iter().map(|c| c.lift_m).collect::<Vec<_>>()
            );
            assert_eq!(s.outcome.status, RunStatus::Completed, "{from}>{to}");
            assert!(rows(&s.outcome).iter().flatten().all(|p| p.is_finite()));
            assert!(h.joint_angle_diff_rad <= 1e-6, "{from}>{to} {h:?}");
            assert!(h.joint_velocity_diff_rad_s <= 1e-6, "{from}>{to} {h:?}");
            let lift = h.corrections.iter().map(|c| c.lift_m).fold(0.0, f64::max);
            assert!(h.object_position_diff_m <= lift + 1e-6, "{from}>{to} {h:?}");
            let tolerance_m = if *from == "ode" { 2e-4 } else { 1e-6 } + lift;
            assert!(
                h.tracked_position_diff_m <= tolerance_m,
                "{from}>{to} {h:?}"
            );
        }
    }
}

fn scene_file(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(format!("../../assets/scenes/{name}.toml"))
        .display()
        .to_string()
}

fn realitygap(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .unwrap()
}

/// `run --stitch` end to end: the stored source, its manifest, rows equal
/// to the in-process stitched run, and `compare` reading it.
#[test]
fn the_command_runs_stores_and_compares_a_stitched_source() {
    if engine("bullet").is_none() || engine("mujoco").is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("r");
    let scene3 = scene_file("scene3_cube_push");
    for extra in [["--stitch", "bullet,bullet,mujoco"], ["--engine", "bullet"]] {
        let o = realitygap(&[
            "run",
            &scene3,
            "--out",
            out.to_str().unwrap(),
            extra[0],
            extra[1],
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let dir = out.join("scene3_cube_push/stitched-bullet-bullet-mujoco");
    let store = realitygap_data::RunStore::open(&dir).unwrap();
    let m = store.manifest();
    assert_eq!(m.source, "stitched bullet>bullet>mujoco");
    let cfg = &m.settings["config"]["stitch"];
    assert_eq!(
        cfg["engines_per_phase"],
        serde_json::json!(["bullet", "bullet", "mujoco"])
    );
    assert_eq!(cfg["phases_start_s"], serde_json::json!([0.0, 8.0, 14.0]));
    let handovers = &m.runs[0].extra["handovers"];
    assert_eq!(handovers[1]["t_s"], serde_json::json!(14.0));
    assert_eq!(handovers[1]["to"], serde_json::json!("mujoco"));
    let stored = store.read_run("run000").unwrap();
    let scene = testing::scene("scene3_cube_push");
    let s = stitched(&scene, &["bullet", "bullet", "mujoco"]);
    assert_eq!(
        stored, s.outcome.trajectory,
        "the child's run is the in-process one"
    );
    let study = tmp.path().join("study.toml");
    std::fs::write(
        &study,
        r#"name = "stitched"
[[scenes]]
name = "scene3_cube_push"
steps = 400
phases_s = [0.0, 8.0, 14.0]
cube = { nominal_start_m = [0.5, 0.0, 0.0375], contact_threshold_m = 0.005 }
[scenes.reference]
name = "Bullet"
format = "store"
dir = "scene3_cube_push/bullet"
[[scenes.sources]]
name = "stitched bullet>bullet>mujoco"
format = "store"
dir = "scene3_cube_push/stitched-bullet-bullet-mujoco"
"#,
    )
    .unwrap();
    let o = realitygap(&[
        "compare",
        study.to_str().unwrap(),
        "--data",
        "none",
        "--results",
        out.to_str().unwrap(),
        "--format",
        "json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("stitched bullet>bullet>mujoco"), "{text}");
    report_draws_the_handovers(&study, &out, tmp.path());
}

/// `report` on `study` (results in `results`) draws the stitched source's
/// handovers (from its manifest) in its figures.
fn report_draws_the_handovers(study: &Path, out: &Path, tmp: &Path) {
    let study = study.to_path_buf();
    // `report` draws the handovers (from the manifest) in the figures.
    let report = tmp.join("report");
    let o = realitygap(&[
        "report",
        study.to_str().unwrap(),
        "--data",
        "none",
        "--results",
        out.to_str().unwrap(),
        "--out",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let svg =
        std::fs::read_to_string(report.join("figures/scene3_cube_push_cube_displacement.svg"))
            .unwrap();
    let ticks = svg
        .split("<polyline")
        .filter(|p| p.contains("stroke-width=\"3\""))
        .count();
    assert_eq!(ticks, 2, "one tick per handover (8 s, 14 s)");
    let prov = std::fs::read_to_string(report.join("provenance.json")).unwrap();
    let prov: serde_json::Value = serde_json::from_str(&prov).unwrap();
    assert_eq!(
        prov["handovers"][0]["times_s"],
        serde_json::json!([8.0, 14.0])
    );
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains("its handovers from one engine to the next (stitched bullet&gt;bullet&gt;mujoco at 8 s, 14 s)"));
}

/// Bad plans are errors naming the plan before anything runs.
#[test]
fn bad_plans_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("bad");
    let out_s = out.to_str().unwrap();
    let scene3 = scene_file("scene3_cube_push");
    let scene1 = scene_file("scene1_single_joint");
    let first = engines().first().map(|e| e.name()).unwrap_or("mujoco");
    let two = format!("{first},{first}");
    let cases: [(&[&str], &str); 7] = [
        (
            &["--stitch", "mujoco,vortex"],
            "unknown engine \"vortex\" (compiled in:",
        ),
        (&["--stitch", ""], "the plan is empty"),
        (
            &["--stitch", "mujoco,,ode"],
            "engine 2 of the plan is empty",
        ),
        (
            &["--stitch", first, "--engine", first],
            "--stitch and --engine cannot be given together",
        ),
        (
            &["--stitch", &two],
            "it names 2 engines but the scene has 1 phase",
        ),
        (
            &["--stitch", "ode,mujoco@"],
            "engine 2 of the plan has an empty parameters file",
        ),
        (
            &["--stitch", "ode,ode@/no/such/params.toml"],
            "/no/such/params.toml",
        ),
    ];
    for (i, (args, expected)) in cases.iter().enumerate() {
        let scene = if i == 4 { &scene1 } else { &scene3 };
        let mut all = vec!["run", scene.as_str(), "--out", out_s];
        all.extend_from_slice(args);
        let o = realitygap(&all);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(err.starts_with("error: "), "{args:?}: {err}");
    }
    assert!(
        !out.join("scene3_cube_push").exists(),
        "nothing was created"
    );
}

/// `realitygap stitch` on the study's recordings: plans chosen on runs
/// 1-15, scored on 1-15 and 16-20. The automatic plan is, per phase, the
/// engine with the smallest training error in that phase; a plan of one
/// engine throughout scores exactly as that engine (stitching to the
/// same engine loses nothing, through the whole pipeline); the proposed
/// plan of scene 3 is Bullet until the real cube moves (14.2 s, in the
/// third phase), MuJoCo after.
#[test]
fn the_stitch_command_chooses_runs_and_scores_plans() {
    let Some(data) = realitygap::paper_data_for_tests() else {
        return;
    };
    if engine("bullet").is_none() || engine("mujoco").is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let study = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/studies/collins2019.toml");
    // A tune's output folder for ODE (its engine and tuned.toml), with the
    // physics-free model fitted beside it (a slow actuator stage behind a
    // delay, as `realitygap tune` writes it).
    let tune = tmp.path().join("tune-ode");
    let fitted = tune.join("physics-free-actuator");
    std::fs::create_dir_all(&fitted).unwrap();
    std::fs::write(tune.join("summary.json"), r#"{"engine": "ode"}"#).unwrap();
    let damped = tune.join("tuned.toml");
    std::fs::write(&damped, "[joints.m1n6s300_joint_2]\ndamping = 0.5\n").unwrap();
    std::fs::write(fitted.join("summary.json"), r#"{"engine": "ideal"}"#).unwrap();
    std::fs::write(
        fitted.join("tuned.toml"),
        "[controller]\ndelay_s = 0.05\n\n[actuator]\nfrequency_rad_s = 20.0\ndamping_ratio = 0.5\n",
    )
    .unwrap();
    let out = tmp.path().join("out");

    let o = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .arg("stitch")
        .arg(&study)
        .arg("--data")
        .arg(&data)
        .args(["--runs", "1-15", "--holdout", "16-20", "--bootstrap", "200"])
        .args(["--plan", "ode,ode,mujoco"])
        .arg("--tuned")
        .arg(&tune)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(out.join("stitch.md")).unwrap();
    assert_eq!(md, String::from_utf8_lossy(&o.stdout));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stitch.json")).unwrap()).unwrap();
    let scenes = v["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 3);
    for s in scenes {
        let rows = s["rows"].as_array().unwrap();
        let engines: Vec<&serde_json::Value> =
            rows.iter().filter(|r| r["role"] == "engine").collect();
        // Every engine at its defaults but the physics-free model (those
        // out of process that are installed too), and ODE with its own
        // parameters.
        let physics = realitygap::engines()
            .iter()
            .filter(|e| e.name() != "ideal")
            .count();
        assert_eq!(engines.len(), physics + 1);
        let tuned = engines
            .iter()
            .find(|r| r["source"] == "ODE 0.16.2 (this tool, tuned)")
            .expect("the --tuned candidate");
        let entry = format!("ode@{}", damped.display());
        assert_eq!(tuned["plan"][0].as_str(), Some(entry.as_str()));
        let plain = engines.iter().find(|r| r["plan"][0] == "ode").unwrap();
        assert_ne!(tuned["training"]["error_m"], plain["training"]["error_m"]);
        // The physics-free rows: perfect tracking, and the tune's fitted
        // one (slower, so another error); baselines, never a phase's engine.
        let free: Vec<&serde_json::Value> = rows
            .iter()
            .filter(|r| r["role"] == "physics-free")
            .collect();
        let names: Vec<&str> = free.iter().map(|r| r["source"].as_str().unwrap()).collect();
        assert_eq!(
            names,
            [
                "physics-free (this tool)",
                "physics-free (this tool, tuned)"
            ],
            "{}",
            s["scene"]
        );
        let fitted_entry = format!("ideal@{}", fitted.join("tuned.toml").display());
        assert_eq!(free[1]["plan"][0].as_str(), Some(fitted_entry.as_str()));
        for set in ["training", "held_out"] {
            let e = |r: &serde_json::Value| r[set]["error_m"].as_f64().unwrap();
            assert!(e(free[0]).is_finite() && e(free[1]).is_finite());
            assert!((e(free[0]) - e(free[1])).abs() > 1e-3, "{}", s["scene"]);
        }
        assert!(!s["automatic"].to_string().contains("ideal"));
        // Each says whether the closest engine or plan beats it, with the
        // gain as the rows' errors give it.
        let against = s["held_out_versus_physics_free"].as_array().unwrap();
        assert_eq!(against.len(), 2);
        for a in against {
            let row = |name: &serde_json::Value| {
                rows.iter().find(|r| r["source"] == *name).unwrap()["held_out"]["error_m"]
                    .as_f64()
                    .unwrap()
            };
            let gain = row(&a["physics_free"]) - row(&a["closest"]);
            assert!((a["gain_m"].as_f64().unwrap() - gain).abs() < 1e-9);
            let closest = row(&a["closest"]);
            for r in rows.iter().filter(|r| r["role"] != "physics-free") {
                assert!(r["held_out"]["error_m"].as_f64().unwrap() >= closest);
            }
        }
        let phases = s["phases_s"].as_array().unwrap().len();
        let automatic: Vec<&str> = s["automatic"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e.as_str().unwrap())
            .collect();
        assert_eq!(automatic.len(), phases);
        for (i, chosen) in automatic.iter().enumerate() {
            let best = engines
                .iter()
                .min_by(|a, b| {
                    let e = |r: &serde_json::Value| {
                        r["training"]["phase_errors_m"][i].as_f64().unwrap()
                    };
                    e(a).total_cmp(&e(b))
                })
                .unwrap();
            assert_eq!(
                best["plan"][0].as_str(),
                Some(*chosen),
                "{} phase {i}",
                s["scene"]
            );
        }
        for r in rows
            .iter()
            .filter(|r| r["role"] != "engine" && r["role"] != "physics-free")
        {
            let plan = r["plan"].as_array().unwrap();
            assert!(r["held_out"]["error_m"].as_f64().unwrap().is_finite());
            assert!(r["training"]["interval_m"]["low_m"].as_f64().is_some());
            if plan.iter().all(|e| *e == plan[0]) {
                let single = engines.iter().find(|e| e["plan"][0] == plan[0]).unwrap();
                for set in ["training", "held_out"] {
                    assert_eq!(r[set]["error_m"], single[set]["error_m"], "{}", r["source"]);
                }
            }
        }
        assert!(s["held_out_versus"].as_array().unwrap().len() >= 2);
    }
    let scene3 = &scenes[2];
    assert_eq!(scene3["scene"], "scene3_cube_push");
    assert_eq!(
        scene3["proposed"],
        serde_json::json!(["bullet", "bullet", "mujoco"])
    );
    let onset = scene3["contact_onset_s"].as_f64().unwrap();
    assert!((14.0..20.0).contains(&onset), "{onset}");
    assert_eq!(scenes[0]["proposed"], serde_json::json!(["bullet"]));
    // The three-engine plan applies to scenes 2 (the last repeated) and
    // 3, not to scene 1 (one phase).
    let given = |k: usize| -> Vec<String> {
        scenes[k]["rows"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["role"] == "given")
            .map(|r| r["source"].as_str().unwrap().to_string())
            .collect()
    };
    assert!(given(0).is_empty());
    assert_eq!(given(1), ["stitched ode>ode>mujoco>mujoco"]);
    assert_eq!(given(2), ["stitched ode>ode>mujoco"]);
    assert!(md.contains("## scene3_cube_push"), "{md}");
    // The report has the stitching section, with one answer per scene.
    let html = std::fs::read_to_string(out.join("report/index.html")).unwrap();
    assert!(html.contains("<section id=\"stitching\">"));
    for s in scenes {
        let scene = s["scene"].as_str().unwrap();
        assert!(
            md.contains(&format!("- {scene}: the automatic plan is ")),
            "{md}"
        );
        assert!(html.contains(&format!("<p>{scene}: the automatic plan is ")));
    }
    assert!(
        md.contains("The closest source, ") && md.contains(" physics-free (this tool, tuned): "),
        "{md}"
    );
}
