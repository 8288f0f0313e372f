//! The physical parameters (`--params FILE`) in DART: which keys the engine
//! honours and how ([`PARAM_SUPPORT`]), and the settings it cannot honour
//! on this model ([`check`]).
//!
//! [`PhysicalParams::apply`] (core) writes `damping`, `frictionloss`, `kv`,
//! `force_limit`, `mass_scale`, `mass_kg` and `friction` into the scene and
//! robot before the engine loads; the `world` module turns them into the
//! joints and bodies, and takes `armature` and `restitution` from the
//! parameters itself.
//!
//! Not honoured, and refused with a reason when set:
//! - `[contact]` (time constant, damping ratio): DART 6.12's contact
//!   softness is one ERP and CFM for the whole process (static members of
//!   `ContactConstraint`), not a spring-damper per simulation;
//! - `armature` and `kv` with `servo = "servo"`: DART's SERVO actuator is a
//!   velocity constraint with no gain, and it takes no force of ours, so
//!   the armature's compensating torque (see [`crate::world`]) cannot act.

use crate::settings::{DartSettings, Servo, ENGINE_NAME};
use realitygap_core::engine::EngineError;
use realitygap_core::params::{ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;

/// Every parameter DART honours beyond core's, and what it becomes.
pub const PARAM_SUPPORT: &[ParamSupport] = &[
    ParamSupport {
        key: ParamKey::JointDamping,
        mapping: "joint damping coefficient (setDampingCoefficient; DART integrates it implicitly) of the controlled joint",
    },
    ParamSupport {
        key: ParamKey::JointArmature,
        mapping: "reflected inertia on the joint axis: DART 6.12 has no setArmature, so damping armature/dt is added (DART adds dt*damping to the joint's projected inertia: + armature) and its force cancelled by a torque +armature/dt * qd before each step; contacts and limits do not see it",
    },
    ParamSupport {
        key: ParamKey::JointFrictionloss,
        mapping: "joint Coulomb friction (setCoulombFriction: DART's velocity constraint bounded by the friction torque)",
    },
    ParamSupport {
        key: ParamKey::JointKv,
        mapping: "the servo's gain: implicit joint damping kv with a torque kv*v_target (servo = \"kv\"); an error with servo = \"servo\"",
    },
    ParamSupport {
        key: ParamKey::JointForceLimit,
        mapping: "the clamp of every servo law (with servo = \"servo\": the SERVO actuator's force limits); 0 = servo off",
    },
    ParamSupport {
        key: ParamKey::LinkMassScale,
        mapping: "mass and inertia of the link in its rigid group's body node (Inertia)",
    },
    ParamSupport {
        key: ParamKey::ObjectMass,
        mapping: "the object's body node mass, inertia of a uniform box",
    },
    ParamSupport {
        key: ParamKey::ObjectFriction,
        mapping: "the object shape's friction coefficient (DynamicsAspect); a contact takes the smaller of its two shapes'",
    },
    ParamSupport {
        key: ParamKey::ObjectRestitution,
        mapping: "the object shape's restitution coefficient; a contact takes the product of its two shapes' (the ground's is 1, the robot's 0), bouncing above 0.1 m/s",
    },
];

fn param_error(key: String, message: impl Into<String>) -> EngineError {
    EngineError::Param {
        engine: ENGINE_NAME.to_string(),
        key,
        message: message.into(),
    }
}

/// Refuses what DART cannot honour on the model of `scene` (see the module
/// documentation), and keys that would have no effect: joint `damping`,
/// `armature` or `frictionloss` on a joint the scene does not control (it
/// is welded into its parent's body) and `mass_scale` on a link of the
/// fixed base.
pub fn check(
    scene: &Scene,
    robot: &RobotModel,
    settings: &DartSettings,
    params: &PhysicalParams,
) -> Result<(), EngineError> {
    let controlled = |name: &str| scene.actuators.iter().any(|a| a.joint == name);
    for (name, j) in &params.joints {
        if settings.servo == Servo::Servo {
            for (field, set) in [("kv", j.kv.is_some()), ("armature", j.armature.is_some())] {
                if set {
                    return Err(param_error(
                        format!("joints.{name}.{field}"),
                        "with servo = \"servo\" a velocity command is DART's SERVO actuator, a velocity \
                         constraint with no gain that takes no torque of ours; set servo = \"kv\" to use it",
                    ));
                }
            }
        }
        if controlled(name) {
            continue;
        }
        let set = [
            ("damping", j.damping),
            ("armature", j.armature),
            ("frictionloss", j.frictionloss),
        ];
        if let Some((field, _)) = set.iter().find(|(_, v)| v.is_some()) {
            return Err(param_error(
                format!("joints.{name}.{field}"),
                format!(
                    "joint {name} is not controlled in scene {}: DART keeps it rigid at its held position \
                     (welded into its parent's body), so {field} has no effect; set it on a controlled joint ({})",
                    scene.name,
                    scene.controlled_joints().join(", ")
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
    if params.contact.time_constant_s.is_some() || params.contact.damping_ratio.is_some() {
        let key = if params.contact.time_constant_s.is_some() {
            "contact.time_constant_s"
        } else {
            "contact.damping_ratio"
        };
        return Err(param_error(
            key.to_string(),
            "DART 6.12's contact softness is one ERP and CFM for the whole process (ContactConstraint's \
             static members), not a spring-damper per simulation",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn engine_keys_are_listed_once_and_contact_keys_not_at_all() {
        for k in ParamKey::ALL.into_iter().filter(|k| !k.is_core()) {
            let n = PARAM_SUPPORT.iter().filter(|s| s.key == k).count();
            let unsupported = matches!(
                k,
                ParamKey::ContactTimeConstant | ParamKey::ContactDampingRatio
            );
            assert_eq!(n, usize::from(!unsupported), "{k}");
        }
    }
}
