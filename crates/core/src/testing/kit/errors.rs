//! Bad input gives a clear error naming what is wrong, never a panic; a
//! diverging simulation ends its run as diverged.

use super::{load, non_finite, report, settings, settings_for, KitSpec, TempDir};
use crate::conformance;
use crate::controller::{run_scene, RunOptions, RunStatus};
use crate::engine::{Engine, EngineError, ModelVariation, NativeState, SimState};
use crate::params::PhysicalParams;
use crate::pose::Vec3;
use crate::robot::RobotModel;
use crate::scene::{ObjectShape, Scene, TrackTarget};
use crate::testing;

/// Bad settings are errors in one style (`engine NAME: setting `KEY`:
/// ...`), the same from [`Engine::check_settings`] as from loading: an
/// unknown key (the error lists the accepted ones), a negative timestep,
/// and the spec's [`KitSpec::bad_settings`]. A timestep that does not
/// divide the control period is the controller's error naming the scene's
/// field.
pub fn bad_settings(engine: &dyn Engine, spec: &KitSpec) {
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let mut cases: Vec<(&str, String)> = vec![
        (
            "no_such_setting=1",
            format!(
                "setting `no_such_setting`: unknown setting (accepted: {})",
                engine
                    .settings_help()
                    .iter()
                    .map(|i| i.key)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ),
        ("timestep_s=-0.01", "setting `timestep_s`: must be".into()),
    ];
    cases.extend(spec.bad_settings.iter().map(|(p, w)| (*p, w.to_string())));
    for (pair, want) in &cases {
        let s = settings_for(engine, spec, &scene, &[pair]);
        let e = engine
            .load(&scene, &robot, &s, &ModelVariation::default())
            .err()
            .unwrap_or_else(|| panic!("{}: {pair} was accepted", engine.name()));
        let text = e.to_string();
        assert!(
            matches!(e, EngineError::Setting { .. })
                && text.starts_with(&format!("engine {}: setting `", engine.name()))
                && text.contains(want.as_str()),
            "{}: {pair}: expected \"{want}\", got {text}",
            engine.name()
        );
        assert_eq!(engine.check_settings(&s).unwrap_err(), e, "{pair}");
        eprintln!("{}: {pair}: {text}", engine.name());
    }
    // 0.03 s does not divide the 0.05 s control period.
    let s = settings_for(engine, spec, &scene, &["timestep_s=0.03"]);
    let mut sim = engine
        .load(&scene, &robot, &s, &ModelVariation::default())
        .unwrap();
    let e = run_scene(sim.as_mut(), &scene, &RunOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("controller.period_s") && e.contains("not a whole number of engine timesteps"),
        "{e}"
    );
    report(engine, "bad_settings", cases.len() as f64, 0.0);
}

/// A scene that does not fit its robot (not validated first): an actuator
/// on a joint the robot lacks or on a fixed joint, a tracked link the robot
/// lacks, a flat box; and a bad model variation. Each is a load error
/// naming what is wrong.
pub fn scene_mismatches(engine: &dyn Engine, spec: &KitSpec) {
    let robot = testing::mico2();
    let base = testing::scene("scene1_single_joint");
    let settings = settings_for(engine, spec, &base, &[]);
    let load_error =
        |s: &Scene, what: &str| match engine.load(s, &robot, &settings, &ModelVariation::default())
        {
            Ok(_) => panic!("{}: the scene with {what} loaded", engine.name()),
            Err(e @ EngineError::Load { .. }) => e.to_string(),
            Err(e) => panic!("{}: unexpected error kind: {e}", engine.name()),
        };
    let mut s = base.clone();
    s.actuators[0].joint = "m1n6s300_joint_9".into();
    let e = load_error(&s, "an actuator on joint 9");
    assert!(e.contains("\"m1n6s300_joint_9\""), "{e}");
    let mut s = base.clone();
    s.actuators[0].joint = "m1n6s300_joint_base".into();
    let e = load_error(&s, "an actuator on the fixed base joint");
    assert!(
        e.contains("m1n6s300_joint_base") && e.contains("fixed"),
        "{e}"
    );
    let mut s = base.clone();
    s.tracked[0].target = TrackTarget::Link("hand".into());
    let e = load_error(&s, "a tracked link \"hand\"");
    assert!(e.contains("link \"hand\""), "{e}");
    if spec.reads_geometry {
        let mut s = base.clone();
        s.objects[0].shape = ObjectShape::Box {
            size_m: Vec3::new(0.075, 0.0, 0.075),
        };
        let e = load_error(&s, "a flat box");
        assert!(e.contains("\"cube\"") && e.contains("size"), "{e}");
    }
    for (variation, want) in [
        (
            ModelVariation {
                mass_scale: 0.0,
                friction_scale: 1.0,
            },
            "the mass factor must be positive",
        ),
        (
            ModelVariation {
                mass_scale: 1.0,
                friction_scale: -1.0,
            },
            "the friction factor must be >= 0",
        ),
    ] {
        let e = engine
            .load(&base, &robot, &settings, &variation)
            .err()
            .unwrap_or_else(|| panic!("{}: {variation:?} was accepted", engine.name()))
            .to_string();
        assert!(e.contains(want), "{e}");
    }
    report(engine, "scene_mismatches", 0.0, 0.0);
}

/// Replaces the first `<collision>` geometry of `link` with `geometry`.
pub fn replace_first_collision(text: String, link: &str, geometry: &str) -> String {
    let start = text.find(&format!("<link name=\"{link}\"")).unwrap();
    let g = start + text[start..].find("<collision").unwrap();
    let open = g + text[g..].find("<geometry>").unwrap() + "<geometry>".len();
    let close = open + text[open..].find("</geometry>").unwrap();
    format!("{}{geometry}{}", &text[..open], &text[close..])
}

/// The Mico2 without the inertials of `links` (their names contain one of
/// the given parts).
fn without_inertials(text: String, links: &[&str]) -> String {
    let mut out = String::new();
    let mut rest = text.as_str();
    while let Some(i) = rest.find("<inertial>") {
        let link_start = rest[..i].rfind("<link name=\"").unwrap();
        let name_end = rest[link_start + 12..].find('"').unwrap();
        let name = &rest[link_start + 12..link_start + 12 + name_end];
        let end = i + rest[i..].find("</inertial>").unwrap() + "</inertial>".len();
        out.push_str(&rest[..i]);
        if !links.iter().any(|l| name.contains(l)) {
            out.push_str(&rest[i..end]);
        }
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// Robots an engine cannot take, read by core (which finds no fault) and
/// refused at load with an error naming the link and the file: a collision
/// mesh that is not COLLADA or STL, one removed after the robot was read,
/// a moving link without mass, an inertia with a zero principal moment.
/// An engine that reads no geometry ([`KitSpec::reads_geometry`] false)
/// loads them all.
pub fn bad_robots(engine: &dyn Engine, spec: &KitSpec) {
    let tmp = TempDir::new(engine.name(), "robots");
    let scene = testing::scene("scene1_single_joint");
    let settings = settings_for(engine, spec, &scene, &[]);
    let link6 = "m1n6s300_link_6";
    std::fs::write(tmp.path("hand.dae"), "<COLLADA/>").unwrap();
    std::fs::write(
        tmp.path("hand.stl"),
        "solid hand\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0\n",
    )
    .unwrap();
    std::fs::write(tmp.path("gone.stl"), "solid x\nendsolid x\n").unwrap();
    let mesh = |link: &str, file: &str| {
        let (link, file) = (link.to_string(), file.to_string());
        move |t: String| replace_first_collision(t, &link, &format!("<mesh filename=\"{file}\"/>"))
    };
    let cases: Vec<(&str, RobotModel, Vec<&str>)> = vec![
        (
            "COLLADA",
            tmp.mico2_with(mesh(link6, "hand.dae")),
            vec![link6, "hand.dae", "not a valid COLLADA mesh"],
        ),
        (
            "STL",
            tmp.mico2_with(mesh(link6, "hand.stl")),
            vec![link6, "hand.stl"],
        ),
        (
            "removed",
            {
                let r = tmp.mico2_with(mesh("m1n6s300_link_2", "gone.stl"));
                std::fs::remove_file(tmp.path("gone.stl")).unwrap();
                r
            },
            vec!["m1n6s300_link_2", "gone.stl"],
        ),
        (
            "massless",
            tmp.mico2_with(|t| without_inertials(t, &[link6, "finger"])),
            vec![link6, "mass"],
        ),
        (
            "inertia",
            tmp.mico2_with(|t| {
                let start = t.find("<link name=\"m1n6s300_link_3\"").unwrap();
                let i = start + t[start..].find("ixx=\"").unwrap() + "ixx=\"".len();
                let end = i + t[i..].find('"').unwrap();
                format!("{}0{}", &t[..i], &t[end..])
            }),
            vec!["m1n6s300_link_3", "inerti"],
        ),
    ];
    for (what, robot, wants) in cases {
        let result = engine.load(&scene, &robot, &settings, &ModelVariation::default());
        if !spec.reads_geometry {
            result.unwrap_or_else(|e| {
                panic!(
                    "{}: reads no geometry, but refused the {what} robot: {e}",
                    engine.name()
                )
            });
            continue;
        }
        let e = match result {
            Ok(mut sim)
                if (what == "inertia" && !spec.refuses_singular_inertia)
                    || (what == "massless" && !spec.refuses_massless_links) =>
            {
                let out = crate::controller::run_scene(sim.as_mut(), &scene, &Default::default())
                    .unwrap_or_else(|e| panic!("{}: {what}: {e}", engine.name()));
                assert_eq!(non_finite(&out), None, "{}: {what}", engine.name());
                continue;
            }
            Ok(_) => panic!("{}: the {what} robot loaded", engine.name()),
            Err(e @ EngineError::Load { .. }) => e.to_string(),
            Err(e) => panic!("{}: {what}: unexpected error kind: {e}", engine.name()),
        };
        eprintln!("{}: {what}: {e}", engine.name());
        assert!(
            e.starts_with(&format!("engine {}: cannot load the scene", engine.name())),
            "{e}"
        );
        for want in wants {
            assert!(e.contains(want), "{what}: \"{want}\" missing from: {e}");
        }
    }
    report(engine, "bad_robots", 0.0, 0.0);
}

/// Joint angles of the wrong length or not finite are usage errors naming
/// the joint; velocity targets of the wrong length do not panic; states
/// that do not fit (a joint short, a NaN, another model's native numbers)
/// are state errors that change nothing; another engine's native numbers
/// are ignored (the portable fields load).
pub fn bad_angles_and_states(engine: &dyn Engine, spec: &KitSpec) {
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let settings = settings_for(engine, spec, &scene, &[]);
    let fresh = || load(engine, &scene, &robot, &settings, &PhysicalParams::none()).unwrap();
    let mut sim = fresh();
    assert!(matches!(
        sim.set_joint_angles_rad(&[0.0; 3]),
        Err(EngineError::Usage { .. })
    ));
    let e = sim
        .set_joint_angles_rad(&[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0])
        .unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(e, EngineError::Usage { .. })
            && text.contains("m1n6s300_joint_2")
            && text.contains("not finite"),
        "{text}"
    );
    sim.set_joint_velocity_targets(&[0.1]);
    sim.set_joint_velocity_targets(&[0.1; 9]);
    sim.step().unwrap();

    let mut sim = fresh();
    sim.set_joint_velocity_targets(&[0.0, -0.3, 0.0, 0.0, 0.0, 0.0]);
    sim.step_n(10).unwrap();
    let good = sim.state().unwrap();
    let state_error =
        |sim: &mut Box<dyn crate::Simulation>, state: &SimState| match sim.set_state(state) {
            Err(e @ EngineError::State { .. }) => e.to_string(),
            Err(other) => panic!("{}: expected a state error, got {other}", engine.name()),
            Ok(()) => panic!("{}: the state loaded", engine.name()),
        };
    let mut short = good.portable();
    short.joint_angles_rad.pop();
    let e = state_error(&mut sim, &short);
    assert!(
        e.contains(&format!("engine {}", engine.name()))
            && e.contains("joint_angles_rad has 5 values"),
        "{e}"
    );
    // The portable numbers: a native state may carry a serial number of
    // the engine's own (Bullet's saved-state id) that each reading bumps.
    let unchanged = |sim: &dyn crate::Simulation, what: &str| {
        assert_eq!(
            sim.state().unwrap().portable(),
            good.portable(),
            "{}: the refused {what} changed the simulation",
            engine.name()
        );
    };
    unchanged(sim.as_ref(), "short state");
    let mut nan = good.portable();
    nan.joint_angles_rad[1] = f64::NAN;
    assert!(state_error(&mut sim, &nan).contains("not finite"));
    unchanged(sim.as_ref(), "NaN angle");
    let mut nan = good.portable();
    nan.objects[0].linear_velocity_m_s.x = f64::NAN;
    assert!(state_error(&mut sim, &nan).contains("non-finite"));
    unchanged(sim.as_ref(), "NaN velocity");
    if let Some(native) = &good.native {
        let mut cut = good.clone();
        cut.native = Some(NativeState {
            engine: native.engine.clone(),
            data: native.data[..native.data.len() / 2].to_vec(),
        });
        state_error(&mut sim, &cut);
    }
    unchanged(sim.as_ref(), "cut native state");
    let mut foreign = good.portable();
    foreign.native = Some(NativeState {
        engine: "another-engine".into(),
        data: vec![1.0, 2.0, 3.0],
    });
    let mut a = fresh();
    a.set_state(&foreign).unwrap();
    let mut b = fresh();
    b.set_state(&good.portable()).unwrap();
    assert_eq!(
        a.state().unwrap().portable(),
        b.state().unwrap().portable(),
        "{}: another engine's native state is not read as portable",
        engine.name()
    );
    report(engine, "bad_angles_and_states", 0.0, 0.0);
}

/// Scene 1 with the spec's diverging settings ends as diverged (or, for
/// an engine that no setting makes diverge, completes with finite numbers
/// or diverges); the cube launched at 1e15 m/s ends the run as diverged
/// within a control period, naming the cube (an engine without dynamics
/// leaves the cube where the state puts it and completes).
pub fn divergence(engine: &dyn Engine, spec: &KitSpec) {
    use super::Divergence;
    let (pairs, want) = match spec.divergence {
        Divergence::Diverges(p) => (p, "diverges"),
        Divergence::Completes(p) => (p, "completes"),
        Divergence::CompletesOrDiverges(p) => (p, "completes or diverges"),
    };
    let mut s = super::study_settings(engine, spec);
    s.extend(settings(pairs));
    let out = conformance::diverges(engine, &s);
    eprintln!("{}: {pairs:?}: {:?} ({want})", engine.name(), out.status);
    let diverged = matches!(out.status, RunStatus::Diverged { .. });
    report(
        engine,
        &format!("{want} {pairs:?}"),
        diverged as u8 as f64,
        0.0,
    );
    match spec.divergence {
        Divergence::Diverges(_) => {
            assert!(diverged, "{}: {pairs:?}: {:?}", engine.name(), out.status)
        }
        Divergence::Completes(_) => {
            assert_eq!(out.status, RunStatus::Completed, "{pairs:?}");
        }
        Divergence::CompletesOrDiverges(_) => {}
    }
    if !diverged {
        assert_eq!(non_finite(&out), None, "{}: {pairs:?}", engine.name());
    }

    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let settings = settings_for(engine, spec, &scene, &[]);
    let mut sim = load(engine, &scene, &robot, &settings, &PhysicalParams::none()).unwrap();
    let mut state = sim.state().unwrap().portable();
    state.objects[0].linear_velocity_m_s = Vec3::new(1e15, 0.0, 0.0);
    if let Err(e) = sim.set_state(&state) {
        // An engine may see at once that the state cannot run.
        eprintln!("{}: cube at 1e15 m/s: {e}", engine.name());
        assert!(
            spec.dynamics && matches!(e, EngineError::Unstable { .. }),
            "{}: {e}",
            engine.name()
        );
        report(engine, "diverges_cube_at_1e15_m_s", 0.0, 0.05);
        return;
    }
    let out = run_scene(sim.as_mut(), &scene, &RunOptions::default()).unwrap();
    eprintln!("{}: cube at 1e15 m/s: {:?}", engine.name(), out.status);
    match (&out.status, spec.dynamics) {
        (RunStatus::Diverged { t_s, reason }, true) => {
            report(engine, "diverges_cube_at_1e15_m_s", *t_s, 0.05);
            assert!(
                *t_s <= 0.05 && (reason.contains("cube") || !spec.divergence_names_body),
                "{t_s} {reason}"
            );
        }
        (RunStatus::Completed, false) => {
            let c = testing::cube(&out);
            assert!(c.iter().all(|p| p.distance(c[0]) == 0.0));
        }
        (status, _) => panic!("{}: cube at 1e15 m/s: {status:?}", engine.name()),
    }
}
