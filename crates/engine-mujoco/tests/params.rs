//! Physical parameters through MuJoCo: the must-show force limit, each
//! engine-mapped key's measurable effect, both model paths (URDF + scene
//! and the study's MJCF loaded as is) and the errors.

mod common;

use common::*;
use mujoco_rs::prelude::MjtObjBase;
use realitygap_core::controller::{prepare, simulate_with, RunOptions, RunStatus};
use realitygap_core::engine::{EngineError, ModelVariation, Simulation};
use realitygap_core::params::PhysicalParams;
use realitygap_core::scene::Scene;
use realitygap_core::{Pose, RobotModel, Vec3};
use realitygap_engine_mujoco::{MujocoEngine, MujocoSimulation};
use std::path::Path;

fn params(text: &str) -> PhysicalParams {
    PhysicalParams::from_toml_str(text, Path::new("/test/params.toml")).unwrap()
}

/// Loads `scene` the way `simulate_with` does: parameters checked and
/// written into scene and robot, then `load_with`.
fn load(
    scene: &Scene,
    robot: &RobotModel,
    p: &PhysicalParams,
) -> Result<MujocoSimulation, EngineError> {
    let (scene, robot) = match prepare(&MujocoEngine, scene, robot, p) {
        Ok(x) => x,
        Err(realitygap_core::controller::RunError::Engine(e)) => return Err(e),
        Err(e) => panic!("{e}"),
    };
    MujocoSimulation::load_with(
        &scene,
        &robot,
        &scene.settings_for("mujoco"),
        &ModelVariation::default(),
        p,
    )
}

fn wrist_at_1_5_s(scene: &Scene, robot: &RobotModel, p: &PhysicalParams) -> Vec3 {
    let mut scene = scene.clone();
    scene.duration_s = 1.55;
    let out = simulate_with(
        &MujocoEngine,
        &scene,
        robot,
        &scene.settings_for("mujoco"),
        p,
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(out.status, RunStatus::Completed);
    wrist(&out)[30]
}

const FORCE_LIMIT: &str = "[joints.m1n6s300_joint_2]\nforce_limit = 2.0\n";

#[test]
fn force_limit_file_moves_the_wrist_urdf() {
    let s = scene("scene1_single_joint");
    let r = mico2();
    let gap = wrist_at_1_5_s(&s, &r, &params(FORCE_LIMIT)).distance(wrist_at_1_5_s(
        &s,
        &r,
        &PhysicalParams::none(),
    ));
    eprintln!(
        "URDF model: force_limit 2 N m moves the wrist at 1.5 s by {:.1} mm",
        gap * 1e3
    );
    assert!(gap > 5e-3, "{gap} m");
}

#[test]
fn force_limit_file_moves_the_wrist_mjcf() {
    let Some(paper) = paper_data() else { return };
    let mut s = scene("scene1_single_joint");
    s.robot.mjcf = Some(paper.join("kinova_description/urdf/m1n6s300.xml"));
    let r = official_robot(&paper);
    let gap = wrist_at_1_5_s(&s, &r, &params(FORCE_LIMIT)).distance(wrist_at_1_5_s(
        &s,
        &r,
        &PhysicalParams::none(),
    ));
    eprintln!(
        "study MJCF: force_limit 2 N m moves the wrist at 1.5 s by {:.1} mm",
        gap * 1e3
    );
    assert!(gap > 5e-3, "{gap} m");
}

/// Servos off, joint 2 started at -0.5 rad: its angle change in 0.3 s.
fn fall(extra: &str) -> f64 {
    let s = scene("scene1_single_joint");
    let mut text = String::new();
    for j in 1..=6 {
        text.push_str(&format!("[joints.m1n6s300_joint_{j}]\nforce_limit = 0.0\n"));
        if j == 2 {
            text.push_str(extra);
        }
    }
    let mut sim = load(&s, &mico2(), &params(&text)).unwrap();
    let mut q = [0.0, -0.5, 0.0, 0.0, 0.0, 0.0];
    sim.set_joint_angles_rad(&q).unwrap();
    sim.set_joint_velocity_targets(&[0.0; 6]);
    sim.step_n((0.3 / sim.timestep_s()).round() as u64).unwrap();
    sim.joint_angles_rad(&mut q);
    (q[1] + 0.5).abs()
}

#[test]
fn armature_slows_the_fall() {
    let free = fall("");
    let heavy = fall("armature = 0.5\n");
    eprintln!("joint 2 falls {free:.4} rad without armature, {heavy:.4} rad with 0.5 kg m^2");
    assert!(heavy < 0.5 * free, "{heavy} vs {free}");
}

#[test]
fn frictionloss_holds_the_joint() {
    let free = fall("");
    let held = fall("frictionloss = 50.0\n");
    eprintln!("joint 2 falls {free:.4} rad, {held:.6} rad with 50 N m friction loss");
    assert!(held < 0.1 * free, "{held} vs {free}");
}

/// The cube dropped from `height_m` (its bottom above the table) under
/// the contact parameters `contact`: its centre height after every
/// timestep for 0.5 s.
fn drop_cube(contact: &str, height_m: f64) -> Vec<f64> {
    let s = scene("scene1_single_joint");
    let mut sim = load(&s, &mico2(), &params(contact)).unwrap();
    let mut state = sim.state().unwrap().portable();
    state.objects[0].pose.position_m.z += height_m;
    sim.set_state(&state).unwrap();
    let steps = (0.5 / sim.timestep_s()).round() as usize;
    let mut z = Vec::with_capacity(steps);
    let mut poses = [Pose::IDENTITY; 2];
    for _ in 0..steps {
        sim.step().unwrap();
        sim.tracked_poses(&mut poses);
        z.push(poses[1].position_m.z);
    }
    z
}

#[test]
fn contact_time_constant_sets_the_penetration() {
    let stiff = *drop_cube("[contact]\ntime_constant_s = 0.005\n", 0.0)
        .last()
        .unwrap();
    let soft = *drop_cube("[contact]\ntime_constant_s = 0.1\n", 0.0)
        .last()
        .unwrap();
    // Resting depth grows with the time constant squared (k ~ 1/tc^2).
    let (d_stiff, d_soft) = (0.0375 - stiff, 0.0375 - soft);
    eprintln!(
        "cube rests {:.3} mm deep at tc 0.005 s, {:.3} mm at 0.1 s",
        d_stiff * 1e3,
        d_soft * 1e3
    );
    assert!(
        d_soft > 10.0 * d_stiff && d_soft > 1e-3,
        "{d_soft} vs {d_stiff}"
    );
}

#[test]
fn contact_damping_ratio_sets_the_rebound() {
    let rebound = |ratio: f64| {
        let z = drop_cube(&format!("[contact]\ndamping_ratio = {ratio:?}\n"), 0.05);
        // Highest point after the first touch (the lowest point so far).
        let bottom = z
            .iter()
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |a, (i, &v)| if v < a.1 { (i, v) } else { a },
            )
            .0;
        z[bottom..]
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
            - 0.0375
    };
    let (bouncy, damped) = (rebound(0.05), rebound(1.0));
    eprintln!(
        "rebound above rest: {:.3} mm at damping ratio 0.05, {:.3} mm at 1",
        bouncy * 1e3,
        damped * 1e3
    );
    assert!(bouncy > damped + 1e-3, "{bouncy} vs {damped}");
}

/// The cube dropped from 5 cm: its restitution from the rebound height,
/// `sqrt(rebound / drop)`.
fn measured_restitution(object_params: &str) -> f64 {
    let drop_m = 0.05;
    let z = drop_cube(&format!("[objects.cube]\n{object_params}"), drop_m);
    let bottom = z
        .iter()
        .enumerate()
        .fold(
            (0, f64::INFINITY),
            |a, (i, &v)| if v < a.1 { (i, v) } else { a },
        )
        .0;
    let apex = z[bottom..]
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    ((apex - 0.0375).max(0.0) / drop_m).sqrt()
}

#[test]
fn restitution_sets_the_rebound() {
    for e in [0.0, 0.2, 0.4, 0.6, 0.8, 0.9] {
        let measured = measured_restitution(&format!("restitution = {e:?}\n"));
        eprintln!(
            "restitution {e}: damping ratio {:.4}, measured {measured:.4}",
            realitygap_engine_mujoco::model_params::damping_ratio_for_restitution(e)
        );
        // Measured: 0.000, 0.241, 0.439, 0.620, 0.805, 0.903. Above the
        // linear model's value because MuJoCo's contact force cannot pull:
        // the cube leaves before the spring has given back its damping.
        assert!(
            (measured - e).abs() <= 0.05,
            "restitution {e}: measured {measured}"
        );
    }
    let e = load(
        &scene("scene1_single_joint"),
        &mico2(),
        &params("[objects.cube]\nrestitution = 1.0\n"),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("objects.cube.restitution") && e.contains("not below 1"),
        "{e}"
    );
}

#[test]
fn contact_time_constant_below_two_steps_is_an_error() {
    let e = load(
        &scene("scene1_single_joint"),
        &mico2(),
        &params("[contact]\ntime_constant_s = 1e-4\n"),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("mujoco")
            && e.contains("contact.time_constant_s")
            && e.contains("two timesteps"),
        "{e}"
    );
}

#[test]
fn joint_keys_on_a_welded_joint_are_errors() {
    let e = load(
        &scene("scene1_single_joint"),
        &mico2(),
        &params("[joints.m1n6s300_joint_finger_1]\narmature = 0.01\n"),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("joints.m1n6s300_joint_finger_1.armature") && e.contains("welded"),
        "{e}"
    );
}

const EVERY_KEY: &str = r#"
[joints.m1n6s300_joint_2]
damping = 0.5
armature = 0.01
frictionloss = 0.2
kv = 30.0
force_limit = 25.0
[links.m1n6s300_link_3]
mass_scale = 1.5
[objects.cube]
mass_kg = 0.2
friction = 0.3
[contact]
time_constant_s = 0.03
damping_ratio = 0.8
"#;

#[test]
fn every_key_reaches_both_models() {
    let mut models = vec![("URDF", scene("scene1_single_joint"), mico2())];
    if let Some(paper) = paper_data() {
        let mut s = scene("scene1_single_joint");
        s.robot.mjcf = Some(paper.join("kinova_description/urdf/m1n6s300.xml"));
        models.push(("MJCF", s, official_robot(&paper)));
    }
    for (label, s, r) in models {
        let base = load(&s, &r, &PhysicalParams::none()).unwrap();
        let sim = load(&s, &r, &params(EVERY_KEY)).unwrap();
        let m = sim.model();
        let id = |kind, name: &str| m.name_to_id(kind, name).unwrap();
        let dof = m.jnt_dofadr()[id(MjtObjBase::mjOBJ_JOINT, "m1n6s300_joint_2")] as usize;
        assert_eq!(m.dof_damping()[dof], 0.5, "{label}");
        assert_eq!(m.dof_armature()[dof], 0.01, "{label}");
        assert_eq!(m.dof_frictionloss()[dof], 0.2, "{label}");
        let u = (0..m.ffi().nu as usize)
            .find(|&u| {
                m.actuator_trnid()[u][0] as usize == id(MjtObjBase::mjOBJ_JOINT, "m1n6s300_joint_2")
            })
            .unwrap();
        assert_eq!(m.actuator_gainprm()[u][0], 30.0, "{label}");
        assert_eq!(m.actuator_biasprm()[u][2], -30.0, "{label}");
        assert_eq!(m.actuator_forcerange()[u], [-25.0, 25.0], "{label}");
        let link = id(MjtObjBase::mjOBJ_BODY, "m1n6s300_link_3");
        let ratio = m.body_mass()[link] / base.model().body_mass()[link];
        assert!((ratio - 1.5).abs() < 1e-12, "{label}: link mass x{ratio}");
        let cube = (0..m.ffi().nbody as usize)
            .find(|&b| {
                m.id_to_name(MjtObjBase::mjOBJ_BODY, b)
                    .is_some_and(|n| n.ends_with("cube"))
            })
            .unwrap();
        assert!((m.body_mass()[cube] - 0.2).abs() < 1e-12, "{label}");
        let g = m.body_geomadr()[cube] as usize;
        assert_eq!(m.geom_friction()[g][0], 0.3, "{label}");
        assert_eq!(m.geom_priority()[g], 1, "{label}");
        assert!(m.geom_solref().iter().all(|r| *r == [0.03, 0.8]), "{label}");
    }
}

/// A small MJCF arm with the Mico2's joint and link names: joint 2 is
/// driven by a motor (no kv), the others by velocity servos; no base link.
fn toy_mjcf() -> std::path::PathBuf {
    let mut bodies = String::new();
    for j in 1..=6 {
        bodies.push_str(&format!(
            "<body name=\"m1n6s300_link_{j}\" pos=\"0 0 0.1\"><joint name=\"m1n6s300_joint_{j}\" axis=\"0 1 0\"/><geom size=\"0.02\" mass=\"0.1\"/>"
        ));
    }
    bodies.push_str(&"</body>".repeat(6));
    let mut actuators = String::new();
    for j in 1..=6 {
        if j == 2 {
            actuators.push_str("<motor joint=\"m1n6s300_joint_2\"/>");
        } else {
            actuators.push_str(&format!(
                "<velocity joint=\"m1n6s300_joint_{j}\" kv=\"1\"/>"
            ));
        }
    }
    let xml = format!(
        "<mujoco><worldbody><geom type=\"plane\" size=\"0 0 1\"/>{bodies}<body name=\"cube\" pos=\"0.5 0 0.0375\"><freejoint/><geom type=\"box\" size=\"0.0375 0.0375 0.0375\" mass=\"0.0884\"/></body></worldbody><actuator>{actuators}</actuator></mujoco>"
    );
    let dir = std::env::temp_dir().join(format!("rg-mujoco-params-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("toy.xml");
    std::fs::write(&file, xml).unwrap();
    file
}

#[test]
fn mjcf_keys_without_a_target_are_errors() {
    let mut s = scene("scene1_single_joint");
    s.robot.mjcf = Some(toy_mjcf());
    let r = mico2();
    load(&s, &r, &PhysicalParams::none()).unwrap();
    let cases = [
        (
            "[joints.m1n6s300_joint_2]\nkv = 10.0\n",
            "joints.m1n6s300_joint_2.kv",
            "not a velocity servo",
        ),
        (
            "[links.m1n6s300_link_base]\nmass_scale = 2.0\n",
            "links.m1n6s300_link_base.mass_scale",
            "has no body",
        ),
        (
            "[joints.m1n6s300_joint_finger_1]\ndamping = 1.0\n",
            "joints.m1n6s300_joint_finger_1.damping",
            "has no hinge or slide joint",
        ),
    ];
    for (text, key, why) in cases {
        let e = load(&s, &r, &params(text)).err().unwrap().to_string();
        assert!(
            e.contains("mujoco") && e.contains(key) && e.contains(why) && e.contains("toy.xml"),
            "{e}"
        );
    }
    // What it has, it takes: the motor's force limit and joint 3's kv.
    let sim = load(
        &s,
        &r,
        &params(
            "[joints.m1n6s300_joint_2]\nforce_limit = 3.0\n[joints.m1n6s300_joint_3]\nkv = 7.0\n",
        ),
    )
    .unwrap();
    assert_eq!(sim.model().actuator_forcerange()[1], [-3.0, 3.0]);
    assert_eq!(sim.model().actuator_gainprm()[2][0], 7.0);
    let _ = std::fs::remove_dir_all(s.robot.mjcf.unwrap().parent().unwrap());
}
