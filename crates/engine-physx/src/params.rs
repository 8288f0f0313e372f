//! The physical parameters (`--params FILE`) in PhysX: which keys the
//! engine honours and how ([`support`]), and the settings that would have
//! no effect or that PhysX cannot honour on this model ([`check`]).
//!
//! [`PhysicalParams::apply`] (core) writes `damping`, `frictionloss`, `kv`,
//! `force_limit`, `mass_scale`, `mass_kg` and `friction` into the scene and
//! robot before the engine loads; the `world` module turns them into the
//! drives and the links' mass properties, and applies `armature` and
//! `restitution` itself.
//!
//! Not honoured, and refused with a reason when set:
//! - joint `frictionloss` (and a URDF `friction` on a controlled joint):
//!   PhysX 5.1's joint friction is a coefficient of the force the joint
//!   transmits, not a constant torque;
//! - `[contact]`: PhysX's rigid contacts are hard constraints; its
//!   compliant-contact material mode is a spring in newtons per metre, not
//!   a time constant and damping ratio.

use crate::ENGINE_NAME;
use realitygap_core::engine::EngineError;
use realitygap_core::params::{ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;

/// The keys PhysX honours (besides the core ones) and what each becomes.
pub fn support() -> Vec<ParamSupport> {
    let s = |key, mapping| ParamSupport { key, mapping };
    vec![
        s(
            ParamKey::JointDamping,
            "folded into the joint's drive: damping kv + d, target velocity kv v / (kv + d) (exact below the force limit)",
        ),
        s(
            ParamKey::JointArmature,
            "articulation joint armature (PxArticulationJointReducedCoordinate::setArmature)",
        ),
        s(
            ParamKey::JointKv,
            "articulation drive damping (stiffness 0, force drive), target velocity from the controller",
        ),
        s(
            ParamKey::JointForceLimit,
            "articulation drive maxForce (0 = servo off)",
        ),
        s(
            ParamKey::LinkMassScale,
            "mass and inertia of the link in its rigid group's articulation link",
        ),
        s(ParamKey::ObjectMass, "object actor mass, inertia of a uniform box"),
        s(
            ParamKey::ObjectFriction,
            "object material static and dynamic friction, combine mode Min when given (a contact takes the smaller of the object's and the other shape's; robot and ground 0.5 unless the scene sets the ground's), PhysX's Average otherwise",
        ),
        s(
            ParamKey::ObjectRestitution,
            "object material restitution, combine mode Max (every other material has 0)",
        ),
    ]
}

fn param_error(key: String, message: impl Into<String>) -> EngineError {
    EngineError::Param {
        engine: ENGINE_NAME.to_string(),
        key,
        message: message.into(),
    }
}

/// Refuses settings that would have no effect on the PhysX model of
/// `scene` (joint `damping` or `armature` on a joint that is not a degree
/// of freedom here, `mass_scale` on a link of the fixed base) and a URDF
/// joint friction PhysX cannot honour.
pub fn check(
    scene: &Scene,
    robot: &RobotModel,
    params: &PhysicalParams,
) -> Result<(), EngineError> {
    let controlled = |name: &str| scene.actuators.iter().any(|a| a.joint == name);
    for (name, j) in &params.joints {
        if controlled(name) {
            continue;
        }
        let set = [("damping", j.damping), ("armature", j.armature)];
        if let Some((field, _)) = set.iter().find(|(_, v)| v.is_some()) {
            return Err(param_error(
                format!("joints.{name}.{field}"),
                format!(
                    "joint {name} is not controlled in scene {}: PhysX keeps it rigid at its held position \
                     (no degree of freedom), so {field} has no effect; set it on a controlled joint ({})",
                    scene.name,
                    scene.controlled_joints().join(", ")
                ),
            ));
        }
    }
    for a in &scene.actuators {
        let Some(j) = robot.joint_by_name(&a.joint) else {
            continue; // the shared planning names unknown joints
        };
        let friction = robot.joints[j].friction;
        if friction != 0.0 {
            return Err(param_error(
                format!("joints.{}.frictionloss", a.joint),
                format!(
                    "joint {} has a dry friction of {friction} N m (URDF <dynamics friction> or the \
                     frictionloss parameter): PhysX 5.1 has no constant joint friction torque (its joint \
                     friction is a coefficient of the transmitted force); set it to 0 for PhysX",
                    a.joint
                ),
            ));
        }
    }
    for (name, l) in &params.links {
        let Some(link) = robot.link_by_name(name) else {
            continue;
        };
        if l.mass_scale.is_some() && realitygap_core::robot::plan::in_fixed_base(scene, robot, link)
        {
            return Err(param_error(
                format!("links.{name}.mass_scale"),
                format!(
                    "link {name} is part of the robot's fixed base (no controlled joint between it and the root), \
                     so its mass has no effect"
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn engine_keys_are_listed_once_and_unsupported_ones_not_at_all() {
        let keys: Vec<ParamKey> = support().iter().map(|s| s.key).collect();
        for k in ParamKey::ALL.into_iter().filter(|k| !k.is_core()) {
            let n = keys.iter().filter(|x| **x == k).count();
            let unsupported = matches!(
                k,
                ParamKey::JointFrictionloss
                    | ParamKey::ContactTimeConstant
                    | ParamKey::ContactDampingRatio
            );
            assert_eq!(n, usize::from(!unsupported), "{k}");
        }
    }
}
