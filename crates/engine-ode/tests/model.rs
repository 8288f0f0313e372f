//! The ODE model built from URDF: link frames where forward kinematics puts
//! them, joint angles read back exactly (also past +-pi), the velocity
//! servo's two mappings, force limits and joint stops measured on a
//! pendulum, and clear errors for models ODE cannot take.

mod common;

use common::*;
use realitygap_core::engine::{Engine, EngineError, ModelVariation, Simulation};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_ode::{OdeEngine, OdeSimulation};
use std::path::{Path, PathBuf};

fn load(scene: &Scene, robot: &RobotModel, pairs: &[&str]) -> OdeSimulation {
    scene.validate(robot).unwrap();
    OdeSimulation::load(scene, robot, &settings(pairs), &ModelVariation::default()).unwrap()
}

/// A continuous joint turned past +-pi keeps counting (ODE's own hinge
/// angle wraps at +-pi).
#[test]
fn continuous_joint_angles_are_unwrapped() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let mut sim = load(&s, &robot, &[]);
    // Joint 6 (continuous) at 1 rad/s for 7 s, the others held.
    sim.set_joint_velocity_targets(&[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    sim.step_n(700).unwrap();
    let mut q = [0.0; 6];
    sim.joint_angles_rad(&mut q);
    assert!(
        (q[5] - 7.0).abs() < 1e-3,
        "joint 6 at {} rad after 7 s at 1 rad/s",
        q[5]
    );
    assert!(q[..5].iter().all(|a| a.abs() < 1e-3), "{q:?}");
    assert!((sim.time_s() - 7.0).abs() < 1e-9);
}

/// `servo = "kv"`: the motor yields like a damper, so a load torque makes
/// the joint creep at torque / kv; `servo = "motor"` (ODE's own motor)
/// holds the target velocity up to the world CFM.
#[test]
fn servo_mappings_behave_as_documented() {
    let p = pendulum("servo", 100.0, 1.0);
    let mut kv = load(&p.scene, &p.robot, &["servo=kv"]);
    kv.set_joint_velocity_targets(&[0.0]);
    kv.step_n(10).unwrap();
    let v = velocity_over(&mut kv, 10);
    let expected = PENDULUM_TORQUE_NM / 10.0;
    assert!(
        (v - expected).abs() < 0.01 * expected,
        "kv servo creeps at {v} rad/s, expected {expected}"
    );

    // A target velocity adds to the creep.
    kv.set_joint_velocity_targets(&[-0.5]);
    kv.step_n(5).unwrap();
    let v = velocity_over(&mut kv, 5);
    assert!(
        (v - (expected - 0.5)).abs() < 0.01,
        "kv servo at {v} rad/s, expected {}",
        expected - 0.5
    );

    let mut motor = load(&p.scene, &p.robot, &[]);
    motor.set_joint_velocity_targets(&[0.0]);
    motor.step_n(10).unwrap();
    let v = velocity_over(&mut motor, 10);
    // The motor row's softness is the world CFM (1e-5): v = torque * CFM.
    assert!(v.abs() < 2e-5, "motor servo creeps at {v} rad/s");
    motor.set_joint_velocity_targets(&[-0.5]);
    motor.step_n(1).unwrap();
    let v = velocity_over(&mut motor, 5);
    assert!(
        (v + 0.5).abs() < 1e-4,
        "motor servo at {v} rad/s, target -0.5"
    );
}

/// The force limit bounds the motor torque: with 0.5 N m against 0.981 N m
/// of gravity the pendulum falls with the difference.
#[test]
fn force_limit_bounds_the_motor() {
    let p = pendulum("force", 0.5, 1.0);
    let mut sim = load(&p.scene, &p.robot, &[]);
    sim.set_joint_velocity_targets(&[0.0]);
    let v1 = velocity_over(&mut sim, 1);
    let v5 = velocity_over(&mut sim, 4);
    // Mean velocity over steps 2-5 minus that of step 1, over 2.5 steps of
    // constant acceleration (semi-implicit Euler: v_n = n a dt).
    let accel = (v5 - v1) / (2.5 * sim.timestep_s());
    let expected = (PENDULUM_TORQUE_NM - 0.5) / PENDULUM_INERTIA;
    assert!(
        (accel - expected).abs() < 0.02 * expected,
        "accelerates at {accel} rad/s^2, expected {expected}"
    );
}

/// The joint's upper limit is an ODE stop: the falling pendulum rests on it.
#[test]
fn joint_limits_stop_the_joint() {
    let p = pendulum("stop", 0.1, 0.3);
    let mut sim = load(&p.scene, &p.robot, &[]);
    sim.set_joint_velocity_targets(&[0.0]);
    sim.step_n(300).unwrap();
    let q = angle(&sim);
    assert!((q - 0.3).abs() < 0.01, "rests at {q} rad, stop at 0.3 rad");
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Loads scene 1 with the pendulum-like robot in `urdf` (joint names of
/// the scene's actuators replaced) and returns the load error.
fn load_error(urdf: &str, tag: &str) -> String {
    let dir = std::env::temp_dir().join(format!("realitygap-ode-bad-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    write(&dir, "hand.dae", "<COLLADA/>");
    write(
        &dir,
        "broken.stl",
        "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0\nendloop\n",
    );
    let urdf_path = write(&dir, "arm.urdf", urdf);
    let toml = format!(
        "name = \"bad\"\nduration_s = 1.0\n[robot]\nurdf = {:?}\nbase_position_m = [0, 0, 0]\n[controller]\ngain_per_s = 10.0\nmax_speed_deg_s = 30.0\nperiod_s = 0.05\n[[actuator]]\njoint = \"hinge\"\nkv = 10.0\n[[schedule]]\nt_s = 0.0\n",
        urdf_path.display().to_string()
    );
    let scene = Scene::from_toml_str(&toml, &dir.join("bad.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&urdf_path, &PackageResolver::new()).unwrap();
    scene.validate(&robot).unwrap();
    let result = OdeEngine.load(&scene, &robot, &settings(&[]), &ModelVariation::default());
    std::fs::remove_dir_all(&dir).ok();
    match result {
        Err(e @ EngineError::Load { .. }) => e.to_string(),
        Err(other) => panic!("expected a load error, got {other}"),
        Ok(_) => panic!("the model loaded"),
    }
}

fn arm_urdf(arm_link_body: &str) -> String {
    format!(
        r#"<robot name="bad">
  <link name="stand"><inertial><mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link>
  <joint name="hinge" type="continuous"><parent link="stand"/><child link="arm"/><axis xyz="0 1 0"/></joint>
  <link name="arm">{arm_link_body}</link>
</robot>"#
    )
}

#[test]
fn models_ode_cannot_take_are_clear_errors() {
    let inertial = r#"<inertial><mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>"#;
    let e = load_error(
        &arm_urdf(&format!(
            r#"{inertial}<collision><geometry><mesh filename="hand.dae"/></geometry></collision>"#
        )),
        "dae",
    );
    assert!(
        e.contains("engine ode")
            && e.contains("link \"arm\"")
            && e.contains("hand.dae")
            && e.contains("not a valid COLLADA mesh"),
        "{e}"
    );
    assert!(e.contains("arm.urdf"), "{e}");

    let e = load_error(
        &arm_urdf(&format!(
            r#"{inertial}<collision><geometry><mesh filename="broken.stl"/></geometry></collision>"#
        )),
        "stl",
    );
    assert!(
        e.contains("link \"arm\"") && e.contains("broken.stl"),
        "{e}"
    );

    let e = load_error(
        &arm_urdf(r#"<collision><geometry><sphere radius="0.1"/></geometry></collision>"#),
        "massless",
    );
    assert!(
        e.contains("the links arm moved by joint \"hinge\" have no mass"),
        "{e}"
    );

    let bad_inertia = r#"<inertial><mass value="1"/><inertia ixx="1e-3" ixy="5e-3" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>"#;
    let e = load_error(&arm_urdf(bad_inertia), "inertia");
    assert!(e.contains("not positive definite"), "{e}");
}

#[test]
fn bad_settings_are_clear_errors() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let cases: &[(&[&str], &str)] = &[
        (
            &["integrator=rk4"],
            "engine ode: setting `integrator`: unknown setting (accepted: timestep_s",
        ),
        (
            &["stepper=pgs"],
            "setting `stepper`: \"pgs\" is not one of world_step, quick_step",
        ),
        (
            &["timestep_s=-0.01"],
            "setting `timestep_s`: must be greater than 0 s",
        ),
        (&["erp=2"], "setting `erp`: must be in [0, 1]"),
    ];
    for (pairs, expected) in cases {
        let e = OdeEngine
            .load(&s, &robot, &settings(pairs), &ModelVariation::default())
            .err()
            .unwrap();
        assert!(matches!(e, EngineError::Setting { .. }), "{e}");
        assert!(e.to_string().contains(expected), "{}", e);
        assert_eq!(OdeEngine.check_settings(&settings(pairs)).unwrap_err(), e);
    }
    // A timestep that does not divide the control period is the scene's
    // error, found by the controller loop.
    let mut sim = OdeEngine
        .load(
            &s,
            &robot,
            &settings(&["timestep_s=0.03"]),
            &ModelVariation::default(),
        )
        .unwrap();
    let e =
        realitygap_core::controller::run_scene(sim.as_mut(), &s, &Default::default()).unwrap_err();
    assert!(
        e.to_string()
            .contains("not a whole number of engine timesteps"),
        "{e}"
    );
    // Wrong-length or non-finite joint angles.
    let mut sim = load(&s, &robot, &[]);
    assert!(matches!(
        sim.set_joint_angles_rad(&[0.0; 3]),
        Err(EngineError::Usage { .. })
    ));
    assert!(matches!(
        sim.set_joint_angles_rad(&[f64::NAN; 6]),
        Err(EngineError::Usage { .. })
    ));
}

/// At rest, upright, nothing touches but the cube and the ground, even with
/// self-collision on and every link its own body.
#[test]
fn no_contacts_at_rest_but_the_cube_on_the_ground() {
    let s = scene("scene1_single_joint");
    let mut robots = vec![(s.clone(), mico2())];
    if let Some(paper) = paper_data() {
        robots.push(with_official_robot(&s, &paper));
    }
    for (s, robot) in &robots {
        for pairs in [&[][..], &["self_collision=true", "weld=fixed_joint"][..]] {
            let mut sim = load(s, robot, pairs);
            sim.step_raw(1);
            let contacts = sim.last_contacts();
            assert!(
                !contacts.is_empty(),
                "{}: the cube does not touch the ground",
                robot.name
            );
            for (a, b) in contacts {
                assert!(
                    (a == "object:cube" && b == "ground") || (a == "ground" && b == "object:cube"),
                    "{} {pairs:?}: unexpected contact {a} - {b}",
                    robot.name
                );
            }
        }
    }
}

/// Masses are scaled by the variation: heavier links sag the kv servo more.
#[test]
fn model_variation_scales_masses() {
    let p = pendulum("variation", 100.0, 1.0);
    let heavy = ModelVariation {
        mass_scale: 2.0,
        friction_scale: 1.0,
    };
    let mut sim =
        OdeSimulation::load(&p.scene, &p.robot, &settings(&["servo=kv"]), &heavy).unwrap();
    sim.set_joint_velocity_targets(&[0.0]);
    sim.step_n(10).unwrap();
    let v = velocity_over(&mut sim, 10);
    let expected = 2.0 * PENDULUM_TORQUE_NM / 10.0;
    assert!(
        (v - expected).abs() < 0.01 * expected,
        "creeps at {v} rad/s, expected {expected}"
    );
    let bad = ModelVariation {
        mass_scale: 0.0,
        friction_scale: 1.0,
    };
    let e = OdeSimulation::load(&p.scene, &p.robot, &settings(&[]), &bad)
        .err()
        .unwrap();
    assert!(e.to_string().contains("positive"), "{e}");
}
