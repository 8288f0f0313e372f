//! What is PhysX's own (the rest is the kit, tests/kit.rs, and the
//! command's cross-engine tests): unwrapped continuous joints, and the
//! drive off with the servo off.

use realitygap_core::engine::{EngineSettings, ModelVariation, Simulation};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_core::testing::{mico2, scene};
use realitygap_engine_physx::PhysxSimulation;

fn load(scene: &Scene, robot: &RobotModel) -> PhysxSimulation {
    scene.validate(robot).unwrap();
    PhysxSimulation::load(
        scene,
        robot,
        &EngineSettings::new(),
        &ModelVariation::default(),
    )
    .unwrap()
}

/// Continuous joints (the Mico2's joints 1, 4, 5 and 6) are PhysX's
/// unwrapped revolute joints: an angle beyond a full turn is set and read
/// back as it is, not wrapped (PhysX's `eREVOLUTE` wraps at 2 pi).
#[test]
fn continuous_joints_turn_past_a_full_turn() {
    let s = scene("scene1_single_joint");
    let mut sim = load(&s, &mico2());
    let angles = [7.0, 0.3, -0.2, -8.0, 6.5, 13.0];
    sim.set_joint_angles_rad(&angles).unwrap();
    let mut read = [0.0; 6];
    sim.joint_angles_rad(&mut read);
    for (r, a) in read.iter().zip(&angles) {
        assert!((r - a).abs() < 1e-5, "{a} rad read back as {r}");
    }
}

/// With the servo off (force limit 0) the drive is the joint's damping
/// alone: a velocity target changes nothing.
#[test]
fn with_the_servo_off_a_target_velocity_does_nothing() {
    let fall = |target: f64| {
        let mut s = scene("scene1_single_joint");
        for a in &mut s.actuators {
            a.force_limit = 0.0;
        }
        let mut robot = mico2();
        let j = robot.joint_by_name("m1n6s300_joint_2").unwrap();
        robot.joints[j].damping = 2.0;
        let mut sim = load(&s, &robot);
        sim.set_joint_velocity_targets(&[0.0, target, 0.0, 0.0, 0.0, 0.0]);
        sim.step_n(40).unwrap();
        let mut q = [0.0; 6];
        sim.joint_angles_rad(&mut q);
        q[1]
    };
    let (still, pushed) = (fall(0.0), fall(1.0));
    assert!(still.abs() > 1e-3, "joint 2 did not move: {still}");
    assert_eq!(still, pushed);
}
