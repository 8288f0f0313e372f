//! How the physical parameters of a run (`--params FILE`, see
//! [`realitygap_core::params`]) map onto ODE, and the part of them the
//! engine applies itself when it loads a scene.
//!
//! Core writes `kv`, `force_limit`, `damping`, `frictionloss`,
//! `mass_scale`, `mass_kg` and `friction` into the scene and robot before
//! the engine loads them; the model ([`crate::plan`]) takes them from
//! there. This module adds the rest to the [`ModelPlan`]: `armature`,
//! `restitution` and `[contact]`, and rejects settings that make a key
//! meaningless in ODE. Everything happens at load; a step does no
//! parameter work (the armature row's reference velocity, the joint rate
//! at the step start, is set each step like a motor target).

use crate::plan::{ContactSoftness, ModelPlan};
use crate::settings::{OdeSettings, Servo, ENGINE_NAME};
use realitygap_core::engine::EngineError;
use realitygap_core::params::{ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::robot::RobotModel;

/// Every parameter ODE honours beyond core's, and what it becomes.
pub const PARAM_SUPPORT: &[ParamSupport] = &[
    ParamSupport {
        key: ParamKey::JointDamping,
        mapping: "implicit viscous damper: an angular motor on the hinge axis, target 0 rad/s, unbounded, dParamCFM = 1/damping (controlled joints)",
    },
    ParamSupport {
        key: ParamKey::JointArmature,
        mapping: "implicit reflected inertia: the damper's angular motor with dParamCFM = 1/(damping + armature/dt), target = armature/dt * CFM * joint rate at the step start (torque -armature * angular acceleration; controlled joints)",
    },
    ParamSupport {
        key: ParamKey::JointFrictionloss,
        mapping: "angular motor on the hinge axis holding 0 rad/s with dParamFMax = frictionloss (controlled joints)",
    },
    ParamSupport {
        key: ParamKey::JointKv,
        mapping: "hinge motor dParamCFM = 1/kv (torque kv (v_target - v)); only with servo = \"kv\", an error with the default stiff servo = \"motor\"",
    },
    ParamSupport {
        key: ParamKey::JointForceLimit,
        mapping: "hinge motor dParamFMax (0 = motor off)",
    },
    ParamSupport {
        key: ParamKey::LinkMassScale,
        mapping: "dMass (mass and inertia) of the rigid ODE body the link is merged into",
    },
    ParamSupport {
        key: ParamKey::ObjectMass,
        mapping: "dMass of the object's body (uniform box inertia)",
    },
    ParamSupport {
        key: ParamKey::ObjectFriction,
        mapping: "contact mu (Coulomb pyramid, dContactApprox1); a contact takes the smaller of its two surfaces' mu",
    },
    ParamSupport {
        key: ParamKey::ObjectRestitution,
        mapping: "contact bounce (dContactBounce) for approach speeds above contact_bounce_velocity_m_s (default 0.01 m/s); a contact takes the larger of its surfaces' values",
    },
    ParamSupport {
        key: ParamKey::ContactTimeConstant,
        mapping: "per-contact dContactSoftERP/SoftCFM of a spring-damper k = m/(zeta tc)^2, c = 2m/tc (m: the pair's reduced mass; split over its contact points); damping_ratio defaults to 1",
    },
    ParamSupport {
        key: ParamKey::ContactDampingRatio,
        mapping: "zeta of the contact spring-damper above; time_constant_s defaults to 0.02 s",
    },
];

fn param_error(key: String, message: impl Into<String>) -> EngineError {
    EngineError::Param {
        engine: ENGINE_NAME.to_string(),
        key,
        message: message.into(),
    }
}

/// Adds the engine-mapped parameters of `params` to `plan` (built from the
/// scene and `robot` that core already changed) and checks the ones core
/// applied: `kv` needs `servo = "kv"`; `damping`, `armature` and
/// `frictionloss` need a controlled joint (ODE welds held joints rigid).
pub fn apply(
    plan: &mut ModelPlan,
    robot: &RobotModel,
    settings: &OdeSettings,
    params: &PhysicalParams,
) -> Result<(), EngineError> {
    for (name, j) in &params.joints {
        let hinge = plan
            .hinges
            .iter_mut()
            .find(|h| robot.joints[h.joint].name == *name);
        if j.kv.is_some() && settings.servo == Servo::Motor {
            return Err(param_error(
                format!("joints.{name}.kv"),
                "the default servo = \"motor\" is ODE's stiff velocity motor, which has no gain; \
                 set the engine setting servo = \"kv\" (motor CFM = 1/kv) to use kv",
            ));
        }
        let passive = [
            ("damping", j.damping),
            ("armature", j.armature),
            ("frictionloss", j.frictionloss),
        ];
        match hinge {
            Some(h) => h.armature_kg_m2 = j.armature.unwrap_or(h.armature_kg_m2),
            None => {
                if let Some((field, _)) = passive.iter().find(|(_, v)| v.is_some()) {
                    return Err(param_error(
                        format!("joints.{name}.{field}"),
                        "ODE holds a joint the scene does not control rigid (welded into one body), \
                         so it has no motion to damp; set it on a controlled joint",
                    ));
                }
            }
        }
    }
    for o in &mut plan.objects {
        if let Some(r) = params.restitution(&o.name) {
            o.restitution = Some(r);
        }
    }
    let (tc, zeta) = (params.contact.time_constant_s, params.contact.damping_ratio);
    if tc.is_some() || zeta.is_some() {
        plan.contact_softness = Some(ContactSoftness {
            time_constant_s: tc.unwrap_or(ContactSoftness::DEFAULT_TIME_CONSTANT_S),
            damping_ratio: zeta.unwrap_or(ContactSoftness::DEFAULT_DAMPING_RATIO),
        });
    }
    Ok(())
}
