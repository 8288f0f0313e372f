//! The kinematic reference: what the wrist would do with perfect velocity
//! tracking and no physics.
//!
//! From the scene alone (its schedule, its controller, its robot's
//! kinematics) and no simulator: the controlled joints start at 0, at every
//! control tick the scene's controller computes
//! `v_deg_s = clamp(gain * (target_deg - angle_deg), -max, +max)`, and every
//! joint then moves at exactly that speed for one period. The wrist's
//! position at each tick, by forward kinematics, is the reference the real
//! runs are aligned to (`crate::align`) and the registration is fitted
//! against (`crate::registration`).

use realitygap_core::robot::RobotModel;
use realitygap_core::scene::{Scene, TrackTarget};
use realitygap_core::Vec3;

/// The kinematic wrist track of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct KinematicTrack {
    /// Wrist position per control step, metres (world frame).
    pub wrist_m: Vec<Vec3>,
    /// Per step: true when no joint was commanded to move during the
    /// `settle_steps` steps before it (the arm is at rest in the model).
    pub settled: Vec<bool>,
    /// Per step: the controlled joints' angles (scene actuator order), rad.
    pub angles_rad: Vec<Vec<f64>>,
}

/// Steps of stillness (commanded speed zero) after which a step counts as
/// settled: 1 s at 20 Hz, time for a real arm's transient to die out.
pub const SETTLE_STEPS: usize = 20;

/// Speed below which a joint counts as still, deg/s.
const STILL_DEG_S: f64 = 1e-3;

/// Computes the kinematic track of `scene` over `steps` control steps with
/// `robot` (the scene's robot model). The tracked body with role `wrist`
/// must be a link of the robot.
pub fn kinematic_track(
    scene: &Scene,
    robot: &RobotModel,
    role: &str,
    steps: usize,
) -> Result<KinematicTrack, String> {
    let link_name = scene
        .tracked
        .iter()
        .find(|t| t.role == role)
        .and_then(|t| match &t.target {
            TrackTarget::Link(l) => Some(l.as_str()),
            TrackTarget::Object(_) => None,
        })
        .ok_or_else(|| {
            format!(
                "scene '{}' tracks no robot link with role '{role}'",
                scene.name
            )
        })?;
    let link = robot.link_by_name(link_name).ok_or_else(|| {
        format!(
            "scene '{}': robot '{}' has no link '{link_name}'",
            scene.name, robot.name
        )
    })?;
    let mut indices = Vec::new();
    for name in scene.controlled_joints() {
        indices.push(robot.joint_by_name(name).ok_or_else(|| {
            format!(
                "scene '{}': robot '{}' has no joint '{name}'",
                scene.name, robot.name
            )
        })?);
    }
    let mut q = vec![0.0; robot.joints.len()];
    for (name, rad) in &scene.robot.held_joints_rad {
        if let Some(j) = robot.joint_by_name(name) {
            q[j] = *rad;
        }
    }
    let c = &scene.controller;
    let mut out = KinematicTrack {
        wrist_m: Vec::with_capacity(steps),
        settled: Vec::with_capacity(steps),
        angles_rad: Vec::with_capacity(steps),
    };
    let mut still_for = usize::MAX / 2;
    for tick in 0..steps {
        let pose = robot
            .link_pose(&scene.robot.base, &q, link)
            .ok_or_else(|| format!("scene '{}': forward kinematics failed", scene.name))?;
        out.wrist_m.push(pose.position_m);
        out.angles_rad.push(indices.iter().map(|&j| q[j]).collect());
        let targets = scene.targets_deg_at_tick(tick);
        let mut moving = false;
        for (&j, target) in indices.iter().zip(&targets) {
            let v_deg_s = (c.gain_per_s * (target - q[j].to_degrees()))
                .clamp(-c.max_speed_deg_s, c.max_speed_deg_s);
            moving |= v_deg_s.abs() > STILL_DEG_S;
            q[j] += (v_deg_s * c.period_s).to_radians();
        }
        out.settled.push(still_for >= SETTLE_STEPS);
        still_for = if moving { 0 } else { still_for + 1 };
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
name = "k"
duration_s = 6.0
[robot]
urdf = "arm.urdf"
base_position_m = [0.0, 0.0, 0.0]
base_rpy_deg = [0.0, 0.0, 0.0]
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "j1"
kv = 1.0
force_limit = 10.0
[[schedule]]
t_s = 0.0
targets_deg = { j1 = 90.0 }
[[track]]
role = "wrist"
link = "tip"
"#;

    const URDF: &str = r#"<robot name="arm">
<link name="base"/><link name="tip"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="tip"/>
<origin xyz="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<link name="tool"/>
<joint name="fix" type="fixed"><parent link="tip"/><child link="tool"/><origin xyz="1 0 0"/></joint>
</robot>"#;

    #[test]
    fn a_joint_turns_at_the_clamped_speed_then_approaches_exponentially() {
        let dir = std::env::temp_dir().join(format!("rg-kin-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("arm.urdf"), URDF).unwrap();
        let path = dir.join("k.toml");
        let text = SCENE.replace("link = \"tip\"", "link = \"tool\"");
        std::fs::write(&path, &text).unwrap();
        let scene = Scene::from_file(&path).unwrap();
        let robot = scene
            .robot
            .model(&realitygap_core::robot::PackageResolver::new())
            .unwrap();
        let k = kinematic_track(&scene, &robot, "wrist", 120).unwrap();
        // 30 deg/s for 0.05 s: 1.5 degrees per step while the error is
        // above 3 degrees; the tool is 1 m from the axis.
        let angle = |i: usize| k.wrist_m[i].y.atan2(k.wrist_m[i].x).to_degrees();
        assert!(angle(0).abs() < 1e-12);
        assert!((angle(10) - 15.0).abs() < 1e-9, "{}", angle(10));
        assert!((angle(119) - 90.0).abs() < 1e-3, "{}", angle(119));
        // At rest before the first command and long after the last move.
        assert!(k.settled[0] && !k.settled[1] && !k.settled[60] && k.settled[119]);
        assert!(kinematic_track(&scene, &robot, "cube", 10).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
