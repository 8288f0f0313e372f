//! The physical parameters (`--params FILE`) in Rapier: which keys the
//! engine honours and how ([`support`]), the settings that would have no
//! effect on this model ([`check`]) and the contact softness
//! ([`apply_contact`]).
//!
//! [`PhysicalParams::apply`] (core) writes `damping`, `frictionloss`, `kv`,
//! `force_limit`, `mass_scale`, `mass_kg` and `friction` into the scene and
//! robot before the engine loads; [`crate::assemble`] turns them into the
//! multibody's damping and friction, the motors and the bodies' mass
//! properties, and applies `armature`, `restitution` and `[contact]` itself.

use crate::ENGINE_NAME;
use rapier3d::dynamics::{IntegrationParameters, SpringCoefficients};
use realitygap_core::engine::EngineError;
use realitygap_core::params::{ContactParams, ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;

/// The keys Rapier honours (besides the core ones) and what each becomes.
pub fn support() -> Vec<ParamSupport> {
    let s = |key, mapping| ParamSupport { key, mapping };
    vec![
        s(
            ParamKey::JointDamping,
            "multibody per-DoF viscous damping (Multibody::damping_mut), implicit",
        ),
        s(
            ParamKey::JointArmature,
            "multibody per-DoF armature (Multibody::armature_mut), added to the mass-matrix diagonal",
        ),
        s(
            ParamKey::JointFrictionloss,
            "multibody per-DoF dry joint friction (Multibody::frictions_mut)",
        ),
        s(
            ParamKey::JointKv,
            "force-based joint motor damping: motor_velocity(target, damping = kv), stiffness 0",
        ),
        s(
            ParamKey::JointForceLimit,
            "joint motor motor_max_force (0 = servo off)",
        ),
        s(
            ParamKey::LinkMassScale,
            "mass and inertia of the link in its rigid group's body (additional_mass_properties)",
        ),
        s(
            ParamKey::ObjectMass,
            "object collider mass (uniform density)",
        ),
        s(
            ParamKey::ObjectFriction,
            "object collider friction, combine rule Min when given (a contact takes the smaller of the object's and the other collider's; ground and robot 0.5 unless the scene sets the ground's), Rapier's Average otherwise",
        ),
        s(
            ParamKey::ObjectRestitution,
            "object collider restitution, combine rule Max (every other collider has 0, so the contact's coefficient is the object's)",
        ),
        s(
            ParamKey::ContactTimeConstant,
            "IntegrationParameters contact_softness and static_contact_softness: natural_frequency = 1 / (2 pi tau zeta) Hz",
        ),
        s(
            ParamKey::ContactDampingRatio,
            "IntegrationParameters contact_softness and static_contact_softness: damping_ratio = zeta",
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

/// Refuses settings that would have no effect on the Rapier model of
/// `scene`: joint `damping`, `armature` or `frictionloss` on a joint that
/// is not a degree of freedom here (fixed, held or mimic joints are rigid
/// in a group body), and `mass_scale` on a link of the fixed base.
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
        let set = [
            ("damping", j.damping),
            ("armature", j.armature),
            ("frictionloss", j.frictionloss),
        ];
        if let Some((field, _)) = set.iter().find(|(_, v)| v.is_some()) {
            return Err(param_error(
                format!("joints.{name}.{field}"),
                format!(
                    "joint {name} is not controlled in scene {}: Rapier keeps it rigid at its held position \
                     (no degree of freedom), so {field} has no effect; set it on a controlled joint ({})",
                    scene.name,
                    scene.controlled_joints().join(", ")
                ),
            ));
        }
    }
    for (name, l) in &params.links {
        let Some(link) = robot.link_by_name(name) else {
            continue; // `apply` reports unknown names.
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

/// One contact class's softness with the `[contact]` keys laid over
/// Rapier's own. The keys describe a mass-spring-damper as MuJoCo's
/// `solref` does: time constant `tau = 1 / (zeta omega)` (the decay time of
/// the oscillation's envelope; the damping per unit mass is `2 / tau`) and
/// damping ratio `zeta`, so `omega = 1 / (tau zeta)` rad/s. A key not set
/// keeps Rapier's own value of that quantity: its `zeta` (10) and its
/// `tau = 1 / (zeta omega)` (0.53 ms for contacts between moving bodies at
/// 30 Hz, 0.27 ms against fixed ones at 60 Hz).
pub fn softness(own: SpringCoefficients<f32>, contact: &ContactParams) -> SpringCoefficients<f32> {
    let own_zeta = own.damping_ratio as f64;
    let own_omega = own.angular_frequency() as f64;
    let zeta = contact.damping_ratio.unwrap_or(own_zeta);
    let tau = contact
        .time_constant_s
        .unwrap_or(1.0 / (own_zeta * own_omega));
    let omega = 1.0 / (tau * zeta);
    SpringCoefficients::new((omega / std::f64::consts::TAU) as f32, zeta as f32)
}

/// Sets Rapier's contact softness (both contacts between moving bodies and
/// against fixed ones) from `[contact]`; nothing when neither key is set.
/// Rapier solves the contact as this spring-damper implicitly: bias
/// `omega / (dt omega + 2 zeta)` times the penetration and the impulse
/// softened by `1 / (dt omega (dt omega + 2 zeta))` of the effective mass.
pub fn apply_contact(p: &mut IntegrationParameters, contact: &ContactParams) {
    if contact.time_constant_s.is_none() && contact.damping_ratio.is_none() {
        return;
    }
    p.contact_softness = softness(p.contact_softness, contact);
    p.static_contact_softness = softness(p.static_contact_softness, contact);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softness_follows_the_solref_convention() {
        let own = SpringCoefficients::<f32>::contact_defaults();
        let c = ContactParams {
            time_constant_s: Some(0.02),
            damping_ratio: Some(1.0),
        };
        let s = softness(own, &c);
        // omega = 1 / 0.02 = 50 rad/s.
        assert!((s.angular_frequency() - 50.0).abs() < 1e-3, "{s:?}");
        assert_eq!(s.damping_ratio, 1.0);
        // Only zeta: tau stays Rapier's own 1 / (10 * 2 pi 30).
        let z = softness(
            own,
            &ContactParams {
                time_constant_s: None,
                damping_ratio: Some(2.0),
            },
        );
        let tau_own = 1.0 / (10.0 * std::f64::consts::TAU * 30.0);
        let want = 1.0 / (tau_own * 2.0);
        assert!(
            ((z.angular_frequency() as f64) - want).abs() < 1e-2 * want,
            "{z:?}"
        );
        // Nothing set: Rapier's own values.
        let same = softness(own, &ContactParams::default());
        assert!((same.natural_frequency - 30.0).abs() < 1e-3 && same.damping_ratio == 10.0);
    }

    #[test]
    fn every_engine_key_is_listed_once() {
        let keys: Vec<ParamKey> = support().iter().map(|s| s.key).collect();
        for k in ParamKey::ALL.into_iter().filter(|k| !k.is_core()) {
            assert_eq!(keys.iter().filter(|x| **x == k).count(), 1, "{k}");
        }
    }
}
