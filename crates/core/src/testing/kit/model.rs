//! The model an engine builds: every link where the URDF's forward
//! kinematics puts it, and the scene's initial state.

use super::{load, report, robot, settings_for, KitSpec};
use crate::controller::SplitMix64;
use crate::engine::Engine;
use crate::params::PhysicalParams;
use crate::pose::Pose;
use crate::robot::{JointKind, RobotModel};
use crate::scene::{Scene, TrackTarget, TrackedBody};
use crate::testing;
use std::collections::HashMap;

/// [`kinematics`] with the project's Mico2.
pub fn kinematics_mico2(engine: &dyn Engine, spec: &KitSpec) {
    kinematics(engine, spec, "mico2");
}

/// [`kinematics`] with the official Kinova model (meshes).
pub fn kinematics_official(engine: &dyn Engine, spec: &KitSpec) {
    kinematics(engine, spec, "official");
}

/// Scene 1 without ground and objects (a random pose may put the hand
/// through the floor), every link of the robot tracked: at 20 random
/// configurations (continuous joints up to [`super::Kinematics::turn_rad`]),
/// the joint angles read back as set and every tracked link frame is where
/// the URDF's forward kinematics puts it (held joints at their scene
/// angles); one step later, for an engine that measures the angles from
/// its bodies, they have not jumped ([`super::Kinematics::after_step_rad`]).
/// With the spec's settings and each of its
/// [`KitSpec::kinematics_settings`].
pub fn kinematics(engine: &dyn Engine, spec: &KitSpec, label: &str) {
    let Some((scene, robot)) = robot(label, &testing::scene("scene1_single_joint")) else {
        return;
    };
    let mut scene = scene;
    scene.ground = None;
    scene.objects.clear();
    scene.tracked = robot
        .links
        .iter()
        .map(|l| TrackedBody {
            role: l.name.clone(),
            target: TrackTarget::Link(l.name.clone()),
        })
        .collect();
    let k = spec.kinematics;
    let variants: Vec<&[&str]> = std::iter::once(&[][..])
        .chain(spec.kinematics_settings.iter().copied())
        .collect();
    let (mut worst_m, mut worst_rad, mut worst_read): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for extra in variants {
        let settings = settings_for(engine, spec, &scene, extra);
        let mut sim = load(engine, &scene, &robot, &settings, &PhysicalParams::none())
            .unwrap_or_else(|e| panic!("{label} {extra:?}: {e}"));
        let mut rng = SplitMix64::new(7);
        let controlled = scene.controlled_joints();
        for round in 0..20 {
            let angles: Vec<f64> = controlled
                .iter()
                .map(|name| {
                    let joint = &robot.joints[robot.joint_by_name(name).unwrap()];
                    let (lo, hi) = match (joint.kind, joint.limits) {
                        (JointKind::Continuous, _) | (_, None) => (-k.turn_rad, k.turn_rad),
                        (_, Some(l)) => (l.lower.max(-3.0), l.upper.min(3.0)),
                    };
                    lo + (hi - lo) * rng.uniform()
                })
                .collect();
            sim.set_joint_angles_rad(&angles).unwrap();
            let mut read = vec![0.0; angles.len()];
            sim.joint_angles_rad(&mut read);
            for (a, b) in angles.iter().zip(&read) {
                worst_read = worst_read.max((a - b).abs());
                assert!(
                    (a - b).abs() <= k.readback_rad,
                    "{} {label} {extra:?} round {round}: set {a} rad, read {b} rad",
                    engine.name()
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
            let mut poses = vec![Pose::IDENTITY; scene.tracked.len()];
            sim.tracked_poses(&mut poses);
            for ((link, expected), got) in robot.links.iter().zip(&fk).zip(&poses) {
                let d = got.position_m.distance(expected.position_m);
                let a = got.orientation.angle_to(expected.orientation);
                worst_m = worst_m.max(d);
                worst_rad = worst_rad.max(a);
                assert!(
                    d <= k.position_m && a <= k.angle_rad,
                    "{} {label} {extra:?} round {round}: link {} off by {d} m, {a} rad",
                    engine.name(),
                    link.name
                );
            }
            if let Some(tolerance) = k.after_step_rad {
                sim.set_joint_velocity_targets(&vec![0.0; angles.len()]);
                sim.step().unwrap();
                sim.joint_angles_rad(&mut read);
                for (a, b) in angles.iter().zip(&read) {
                    assert!(
                        (a - b).abs() < tolerance,
                        "{} {label} {extra:?} round {round}: after a step {a} rad became {b} rad",
                        engine.name()
                    );
                }
            }
        }
    }
    report(
        engine,
        &format!("kinematics_{label}_m"),
        worst_m,
        k.position_m,
    );
    report(
        engine,
        &format!("kinematics_{label}_rad"),
        worst_rad,
        k.angle_rad,
    );
    report(
        engine,
        &format!("kinematics_{label}_readback_rad"),
        worst_read,
        k.readback_rad,
    );
}

/// Scene 3 loaded and not stepped: time 0, the engine's timestep for the
/// settings, every controlled joint at 0 rad and at rest, the wrist at the
/// upright arm's forward kinematics, the cube at its scene pose; the state
/// says the same, and a native state names the engine.
pub fn initial_state(engine: &dyn Engine, spec: &KitSpec) {
    let scene = testing::scene("scene3_cube_push");
    let robot = testing::mico2();
    let settings = settings_for(engine, spec, &scene, &[]);
    let sim = load(engine, &scene, &robot, &settings, &PhysicalParams::none()).unwrap();
    let timestep = engine.check_settings(&settings).unwrap();
    assert_eq!(
        (
            sim.joint_count(),
            sim.tracked_count(),
            sim.time_s(),
            sim.timestep_s()
        ),
        (6, 2, 0.0, timestep),
        "{}",
        engine.name()
    );
    let mut angles = [1.0; 6];
    sim.joint_angles_rad(&mut angles);
    assert_eq!(angles, [0.0; 6], "{}", engine.name());
    let mut poses = [Pose::IDENTITY; 2];
    sim.tracked_poses(&mut poses);
    let wrist = wrist_at_zero(&scene, &robot);
    let d_wrist = poses[0].position_m.distance(wrist.position_m);
    let d_cube = poses[1]
        .position_m
        .distance(scene.objects[0].pose.position_m);
    report(
        engine,
        "initial_wrist_m",
        d_wrist,
        spec.kinematics.position_m,
    );
    report(engine, "initial_cube_m", d_cube, spec.kinematics.object_m);
    assert!(d_wrist <= spec.kinematics.position_m, "{d_wrist}");
    assert!(d_cube <= spec.kinematics.object_m, "{d_cube}");
    let state = sim.state().unwrap();
    assert_eq!(state.time_s, 0.0);
    assert_eq!(state.joint_angles_rad, vec![0.0; 6]);
    assert_eq!(state.joint_velocities_rad_s, vec![0.0; 6]);
    assert_eq!(state.objects.len(), 1);
    assert_eq!(state.objects[0].name, "cube");
    assert!(
        state.objects[0]
            .pose
            .position_m
            .distance(scene.objects[0].pose.position_m)
            <= spec.kinematics.object_m
    );
    if let Some(native) = &state.native {
        assert_eq!(native.engine, engine.name());
    }
}

/// The wrist's pose with every joint at 0 (held joints at their scene
/// angles).
fn wrist_at_zero(scene: &Scene, robot: &RobotModel) -> Pose {
    let mut named: HashMap<String, f64> = HashMap::new();
    for (n, &a) in &scene.robot.held_joints_rad {
        named.insert(n.clone(), a);
    }
    let fk = robot.forward_kinematics(
        &scene.robot.base,
        &robot.positions_from_names(&named).unwrap(),
    );
    fk[robot.link_by_name("m1n6s300_link_6").unwrap()]
}
