//! The assembled model: links where the URDF's forward kinematics puts
//! them, no contacts at rest but the cube's, clear errors for bad input,
//! instabilities reported.

mod common;

use common::*;
use realitygap_core::controller::{run_scene, RunOptions, RunStatus, SplitMix64};
use realitygap_core::engine::{
    Engine, EngineError, EngineSettings, ModelVariation, SettingValue, Simulation,
};
use realitygap_core::pose::Pose;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_engine_rapier::{RapierEngine, RapierSimulation};
use std::collections::HashMap;
use std::path::PathBuf;

fn load(scene: &Scene, robot: &RobotModel) -> RapierSimulation {
    scene.validate(robot).unwrap();
    RapierSimulation::load(
        scene,
        robot,
        &EngineSettings::new(),
        &ModelVariation::default(),
    )
    .unwrap()
}

/// Places the arm at random configurations and compares every link's pose
/// with the URDF forward kinematics (fingers held at their scene
/// positions); single precision allows a few micrometres.
fn check_kinematics(scene: &Scene, robot: &RobotModel) {
    let mut sim = load(scene, robot);
    let mut rng = SplitMix64::new(7);
    let controlled = scene.controlled_joints();
    for round in 0..20 {
        let angles: Vec<f64> = controlled
            .iter()
            .map(|name| {
                let lim = robot.joints[robot.joint_by_name(name).unwrap()]
                    .limits
                    .unwrap();
                let (lo, hi) = (lim.lower.max(-3.0), lim.upper.min(3.0));
                lo + (hi - lo) * rng.uniform()
            })
            .collect();
        sim.set_joint_angles_rad(&angles).unwrap();
        let mut read = vec![0.0; angles.len()];
        sim.joint_angles_rad(&mut read);
        for (r, a) in read.iter().zip(&angles) {
            assert!(
                (r - a).abs() < 1e-5,
                "round {round}: joint angle {r} read back for {a}"
            );
        }
        let mut named: HashMap<String, f64> = controlled
            .iter()
            .zip(&angles)
            .map(|(n, &a)| (n.to_string(), a))
            .collect();
        for (n, &a) in &scene.robot.held_joints_rad {
            named.insert(n.clone(), a);
        }
        let fk = robot.forward_kinematics(
            &scene.robot.base,
            &robot.positions_from_names(&named).unwrap(),
        );
        for (link, expected) in robot.links.iter().zip(&fk) {
            let got: Pose = sim.link_pose(&link.name).unwrap();
            let d = got.position_m.distance(expected.position_m);
            let a = got.orientation.angle_to(expected.orientation);
            assert!(
                d < 1e-5 && a < 1e-5,
                "{}: link {} off by {d} m, {a} rad",
                robot.name,
                link.name
            );
        }
        let mut tracked = [Pose::IDENTITY; 2];
        sim.tracked_poses(&mut tracked);
        let w = fk[robot.link_by_name("m1n6s300_link_6").unwrap()];
        assert!(tracked[0].position_m.distance(w.position_m) < 1e-5);
        assert!(
            tracked[1]
                .position_m
                .distance(scene.objects[0].pose.position_m)
                < 1e-6,
            "the cube has not moved"
        );
    }
}

#[test]
fn mico2_links_follow_urdf_kinematics() {
    check_kinematics(&scene("scene1_single_joint"), &mico2());
}

#[test]
fn official_links_follow_urdf_kinematics() {
    let Some(paper) = paper_data() else { return };
    check_kinematics(
        &official_scene("scene1_single_joint", &paper),
        &official_robot(&paper),
    );
}

/// The state is valid before the first step: the arm upright at the URDF
/// zero, the cube where the scene puts it, time 0.
#[test]
fn initial_state_is_the_scene_at_rest() {
    let s = scene("scene3_cube_push");
    let robot = mico2();
    let sim = load(&s, &robot);
    assert_eq!(
        (
            sim.joint_count(),
            sim.tracked_count(),
            sim.time_s(),
            sim.timestep_s()
        ),
        (6, 2, 0.0, 0.01)
    );
    let mut angles = [1.0; 6];
    sim.joint_angles_rad(&mut angles);
    assert_eq!(angles, [0.0; 6]);
    let mut poses = [Pose::IDENTITY; 2];
    sim.tracked_poses(&mut poses);
    let fk = robot.forward_kinematics(&s.robot.base, &vec![0.0; robot.joints.len()]);
    assert!(
        poses[0]
            .position_m
            .distance(fk[robot.link_by_name("m1n6s300_link_6").unwrap()].position_m)
            < 1e-6
    );
    assert!(poses[1].position_m.distance(s.objects[0].pose.position_m) < 1e-7);
}

/// At rest, upright, no two robot bodies touch, and nothing touches the
/// cube but the ground.
fn check_rest_contacts(scene: &Scene, robot: &RobotModel) {
    let mut sim = load(scene, robot);
    sim.step_raw(20);
    let contacts = sim.contacts();
    assert!(
        contacts.contains(&("ground".to_string(), "object:cube".to_string())),
        "{contacts:?}"
    );
    for (a, b) in contacts {
        let pair = [a.as_str(), b.as_str()];
        assert!(
            pair.contains(&"object:cube") && pair.contains(&"ground"),
            "unexpected contact {a} - {b}"
        );
    }
}

#[test]
fn mico2_no_contacts_at_rest_but_the_cube_on_the_ground() {
    check_rest_contacts(&scene("scene1_single_joint"), &mico2());
}

#[test]
fn official_no_contacts_at_rest_but_the_cube_on_the_ground() {
    let Some(paper) = paper_data() else { return };
    check_rest_contacts(
        &official_scene("scene1_single_joint", &paper),
        &official_robot(&paper),
    );
}

/// A URDF in a temporary directory (removed on drop).
struct TempUrdf {
    dir: PathBuf,
}

impl TempUrdf {
    fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("rg-rapier-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempUrdf { dir }
    }

    /// The project's Mico2 URDF with `edit` applied, read as a model.
    fn mico2_with(&self, edit: impl Fn(String) -> String) -> RobotModel {
        let text =
            std::fs::read_to_string(workspace().join("assets/robots/mico2/mico2.urdf")).unwrap();
        let path = self.dir.join("mico2.urdf");
        std::fs::write(&path, edit(text)).unwrap();
        RobotModel::from_urdf_file(&path, &PackageResolver::new()).unwrap()
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

impl Drop for TempUrdf {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

fn load_error(scene: &Scene, robot: &RobotModel, settings: &EngineSettings) -> String {
    match RapierEngine.load(scene, robot, settings, &ModelVariation::default()) {
        Ok(_) => panic!("the model loaded"),
        Err(e @ (EngineError::Load { .. } | EngineError::Setting { .. })) => e.to_string(),
        Err(e) => panic!("unexpected error kind: {e}"),
    }
}

/// Replaces the first `<collision>` geometry of `link` with `geometry`.
fn replace_first_collision(text: String, link: &str, geometry: &str) -> String {
    let start = text.find(&format!("<link name=\"{link}\"")).unwrap();
    let g = start + text[start..].find("<collision").unwrap();
    let open = g + text[g..].find("<geometry>").unwrap() + "<geometry>".len();
    let close = open + text[open..].find("</geometry>").unwrap();
    format!("{}{geometry}{}", &text[..open], &text[close..])
}

#[test]
fn bad_meshes_are_load_errors_naming_link_and_file() {
    let tmp = TempUrdf::new("meshes");
    let s = scene("scene1_single_joint");
    // A COLLADA file that is not one.
    std::fs::write(tmp.path("hand.dae"), "<COLLADA/>").unwrap();
    let robot = tmp.mico2_with(|t| {
        replace_first_collision(t, "m1n6s300_link_6", "<mesh filename=\"hand.dae\"/>")
    });
    let e = load_error(&s, &robot, &EngineSettings::new());
    assert!(
        e.contains("engine rapier: cannot load the scene")
            && e.contains("m1n6s300_link_6")
            && e.contains("hand.dae")
            && e.contains("not a valid COLLADA mesh"),
        "{e}"
    );
    // An STL file that is not one.
    std::fs::write(
        tmp.path("hand.stl"),
        "solid hand\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0\n",
    )
    .unwrap();
    let robot = tmp.mico2_with(|t| {
        replace_first_collision(t, "m1n6s300_link_6", "<mesh filename=\"hand.stl\"/>")
    });
    let e = load_error(&s, &robot, &EngineSettings::new());
    assert!(
        e.contains("m1n6s300_link_6") && e.contains("hand.stl"),
        "{e}"
    );
    // A mesh that disappeared after the model was read.
    std::fs::write(tmp.path("gone.stl"), "solid x\nendsolid x\n").unwrap();
    let robot = tmp.mico2_with(|t| {
        replace_first_collision(t, "m1n6s300_link_2", "<mesh filename=\"gone.stl\"/>")
    });
    std::fs::remove_file(tmp.path("gone.stl")).unwrap();
    let e = load_error(&s, &robot, &EngineSettings::new());
    assert!(
        e.contains("m1n6s300_link_2") && e.contains("gone.stl"),
        "{e}"
    );
}

#[test]
fn a_massless_moving_link_is_a_load_error() {
    let tmp = TempUrdf::new("massless");
    let robot = tmp.mico2_with(|t| {
        // Drop link 6's inertial and the fingers' (they move with it).
        let mut out = String::new();
        let mut rest = t.as_str();
        while let Some(i) = rest.find("<inertial>") {
            let link_start = rest[..i].rfind("<link name=\"").unwrap();
            let name_end = rest[link_start + 12..].find('"').unwrap();
            let name = &rest[link_start + 12..link_start + 12 + name_end];
            let end = i + rest[i..].find("</inertial>").unwrap() + "</inertial>".len();
            out.push_str(&rest[..i]);
            if !(name == "m1n6s300_link_6" || name.contains("finger")) {
                out.push_str(&rest[i..end]);
            }
            rest = &rest[end..];
        }
        out.push_str(rest);
        out
    });
    let e = load_error(
        &scene("scene1_single_joint"),
        &robot,
        &EngineSettings::new(),
    );
    assert!(
        e.contains("m1n6s300_link_6") && e.contains("no mass"),
        "{e}"
    );
}

#[test]
fn bad_settings_are_errors_naming_the_key() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let mut settings = EngineSettings::new();
    settings.insert("substeps".into(), SettingValue::Integer(4));
    let e = load_error(&s, &robot, &settings);
    assert!(
        e.contains("setting `substeps`") && e.contains("internal_pgs_iterations"),
        "{e}"
    );
    let mut settings = EngineSettings::new();
    settings.insert(
        "internal_pgs_iterations".into(),
        SettingValue::Text("many".into()),
    );
    let e = RapierEngine
        .check_settings(&settings)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("internal_pgs_iterations") && e.contains("whole number"),
        "{e}"
    );
    // A timestep that does not divide the control period is the
    // controller's error, naming the scene field.
    let mut settings = EngineSettings::new();
    settings.insert("timestep_s".into(), SettingValue::Float(0.003));
    let mut sim = RapierEngine
        .load(&s, &robot, &settings, &ModelVariation::default())
        .unwrap();
    let e = run_scene(sim.as_mut(), &s, &RunOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("controller.period_s"), "{e}");
}

#[test]
fn scene_and_robot_mismatches_are_errors() {
    let robot = mico2();
    // An actuator on a joint the robot lacks (a scene not validated).
    let mut s = scene("scene1_single_joint");
    s.actuators[0].joint = "m1n6s300_joint_9".into();
    let e = load_error(&s, &robot, &EngineSettings::new());
    assert!(e.contains("no joint \"m1n6s300_joint_9\""), "{e}");
    // A fixed joint cannot carry an actuator.
    let mut s = scene("scene1_single_joint");
    s.actuators[0].joint = "m1n6s300_joint_base".into();
    assert!(load_error(&s, &robot, &EngineSettings::new()).contains("fixed"));
    // A tracked link that does not exist.
    let mut s = scene("scene1_single_joint");
    s.tracked[0].target = realitygap_core::scene::TrackTarget::Link("hand".into());
    assert!(load_error(&s, &robot, &EngineSettings::new()).contains("tracked link \"hand\""));
    // A flat box.
    let mut s = scene("scene1_single_joint");
    s.objects[0].shape = realitygap_core::scene::ObjectShape::Box {
        size_m: realitygap_core::Vec3::new(0.075, 0.0, 0.075),
    };
    assert!(load_error(&s, &robot, &EngineSettings::new()).contains("object \"cube\": box size"));
    // A bad variation.
    let s = scene("scene1_single_joint");
    let e = RapierEngine
        .load(
            &s,
            &robot,
            &EngineSettings::new(),
            &ModelVariation {
                mass_scale: 0.0,
                friction_scale: 1.0,
            },
        )
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("mass factor"), "{e}");
}

#[test]
fn wrong_length_or_non_finite_angles_are_usage_errors() {
    let s = scene("scene1_single_joint");
    let mut sim = load(&s, &mico2());
    assert!(matches!(
        sim.set_joint_angles_rad(&[0.0; 3]),
        Err(EngineError::Usage { .. })
    ));
    let e = sim
        .set_joint_angles_rad(&[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("m1n6s300_joint_2") && e.contains("not finite"),
        "{e}"
    );
    // Short or long command vectors do not panic.
    sim.set_joint_velocity_targets(&[0.1]);
    sim.set_joint_velocity_targets(&[0.1; 9]);
    sim.step().unwrap();
}

/// A non-finite state (here a cube flung at NaN speed) is reported as
/// unstable, and the controller ends the run as diverged.
#[test]
fn non_finite_state_is_reported_unstable() {
    let s = scene("scene1_single_joint");
    let mut sim = load(&s, &mico2());
    sim.step_n(3).unwrap();
    let cube = sim.object_body("cube").unwrap();
    sim.world_mut().bodies[cube].set_linvel(rapier3d::math::Vector::new(f32::NAN, 0.0, 0.0), true);
    match sim.step() {
        Err(EngineError::Unstable {
            engine,
            t_s,
            message,
        }) => {
            assert_eq!(engine, "rapier");
            assert!((t_s - 0.04).abs() < 1e-12, "{t_s}");
            assert!(message.contains("non-finite"), "{message}");
        }
        other => panic!("expected Unstable, got {other:?}"),
    }

    let mut sim = load(&s, &mico2());
    let cube = sim.object_body("cube").unwrap();
    sim.world_mut().bodies[cube]
        .set_linvel(rapier3d::math::Vector::new(0.0, f32::INFINITY, 0.0), true);
    let out = run_scene(&mut sim, &s, &RunOptions::default()).unwrap();
    match out.status {
        RunStatus::Diverged { t_s, reason } => assert!(
            t_s < 0.05 && reason.contains("non-finite"),
            "{t_s} {reason}"
        ),
        RunStatus::Completed => panic!("the run completed"),
    }
}
