//! The physical parameters (`--params FILE`) in Bullet: which keys the
//! engine honours and how ([`SUPPORT`]), and the load-time code that
//! applies the ones Bullet reads from its own model rather than from the
//! URDF file (joint damping, link masses, joint friction, restitution,
//! contact softness). Nothing here runs per step.
//!
//! Every `unsafe` block of this module has its own SAFETY comment; the
//! argument they share: the commands are created
//! on the client passed in and submitted once, with the Bullet lock held.

use crate::build::BulletModel;
use crate::{dynamics_info, expect, ffi, ENGINE_NAME};
use realitygap_core::engine::EngineError;
use realitygap_core::params::{JointParams, ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::{ActuatorSpec, Scene};
use std::ffi::c_int;

/// The non-core keys Bullet honours and what each becomes.
pub const SUPPORT: &[ParamSupport] = &[
    ParamSupport {
        key: ParamKey::JointDamping,
        mapping: "changeDynamics jointDamping: torque -damping * qdot added before each step (PyBullet's URDF <dynamics damping>)",
    },
    ParamSupport {
        key: ParamKey::JointFrictionloss,
        mapping: "servo off (force_limit = 0) only: the joint's velocity motor holds velocity 0 with max force = frictionloss (PyBullet's joint friction); with the servo on it is an error (one motor per joint)",
    },
    ParamSupport {
        key: ParamKey::JointForceLimit,
        mapping: "VELOCITY_CONTROL motor force (wins over the max_force_n_m setting)",
    },
    ParamSupport {
        key: ParamKey::LinkMassScale,
        mapping: "changeDynamics mass and localInertiaDiagonal, scaled",
    },
    ParamSupport {
        key: ParamKey::ObjectMass,
        mapping: "createMultiBody baseMass (Bullet derives the box inertia)",
    },
    ParamSupport {
        key: ParamKey::ObjectFriction,
        mapping: "changeDynamics lateralFriction (Bullet multiplies the two bodies' coefficients; the ground's default is 0.5 unless the scene sets it)",
    },
    ParamSupport {
        key: ParamKey::ObjectRestitution,
        mapping: "changeDynamics restitution of the object; ground and robot links get 1 so the product Bullet uses is the object's value",
    },
    ParamSupport {
        key: ParamKey::ContactTimeConstant,
        mapping: "changeDynamics contactStiffness = m / (tc^2 z^2), m = the object's mass (Bullet: ERP = dt k / (dt k + c), CFM = 1 / (dt k + c))",
    },
    ParamSupport {
        key: ParamKey::ContactDampingRatio,
        mapping: "changeDynamics contactDamping = 2 m / tc - 0.1 (Bullet adds the partner's default 0.1 N s/m)",
    },
];

/// MuJoCo's default contact time constant, s, used when only the damping
/// ratio is given.
pub const DEFAULT_TIME_CONSTANT_S: f64 = 0.02;

/// MuJoCo's default damping ratio, used when only the time constant is
/// given.
pub const DEFAULT_DAMPING_RATIO: f64 = 1.0;

/// Bullet's default `contactDamping` of a collision object, N s/m: Bullet
/// adds the two bodies' values for a contact.
pub const PARTNER_CONTACT_DAMPING: f64 = 0.1;

fn param_error(key: String, message: String) -> EngineError {
    EngineError::Param {
        engine: ENGINE_NAME.to_string(),
        key,
        message,
    }
}

/// The dry friction of a controlled joint's motor, N m: `Some` when a
/// `frictionloss` parameter > 0 is set for a joint whose servo is off
/// (force limit 0); an error when the servo is on.
pub(crate) fn motor_friction(
    actuator: &ActuatorSpec,
    own: Option<&JointParams>,
) -> Result<Option<f64>, EngineError> {
    match own.and_then(|p| p.frictionloss).filter(|&f| f > 0.0) {
        None => Ok(None),
        Some(f) if actuator.force_limit == 0.0 => Ok(Some(f)),
        Some(_) => Err(param_error(
            format!("joints.{}.frictionloss", actuator.joint),
            format!(
                "Bullet models dry joint friction with the joint's velocity motor, which is the servo of this joint (force limit {} N m); it is honoured only with the servo off (force_limit = 0)",
                actuator.force_limit
            ),
        )),
    }
}

/// Fails for a `frictionloss` > 0 on a joint without a servo (held joints
/// are locked by their position motor, fixed joints do not move).
fn check_uncontrolled_friction(scene: &Scene, params: &PhysicalParams) -> Result<(), EngineError> {
    for (name, j) in &params.joints {
        let controlled = scene.actuators.iter().any(|a| &a.joint == name);
        if !controlled && j.frictionloss.is_some_and(|f| f > 0.0) {
            return Err(param_error(
                format!("joints.{name}.frictionloss"),
                "Bullet honours frictionloss only on a controlled joint with its servo off; this joint has no servo (a held joint is locked by its position motor)".into(),
            ));
        }
    }
    Ok(())
}

/// Joint damping and link masses from the robot model (which carries the
/// `damping` and `mass_scale` parameters) where they differ from what
/// Bullet read from the URDF file. Needs the Bullet lock (`lock`).
pub(crate) fn apply_robot_dynamics(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    body: c_int,
    robot: &RobotModel,
    model: &BulletModel,
) -> Result<(), EngineError> {
    for (j, name) in model.joint_names.iter().enumerate() {
        let Some(joint) = robot.joint_by_name(name).map(|i| &robot.joints[i]) else {
            continue;
        };
        if !model.is_movable(j) || joint.damping == model.infos[j].m_joint_damping {
            continue;
        }
        // SAFETY: the command is created on this simulation's client and
        // submitted once, with the Bullet lock held (`lock`); the pointers
        // passed point to live locals of the sizes Bullet expects.
        unsafe {
            let cmd = ffi::b3InitChangeDynamicsInfo(client.handle(lock));
            ffi::b3ChangeDynamicsInfoSetJointDamping(cmd, body, j as c_int, joint.damping);
            expect(
                client.submit(lock, cmd).kind,
                ffi::CMD_CLIENT_COMMAND_COMPLETED,
                "setting a joint damping",
            )?;
        }
    }
    for (l, link) in robot.links.iter().enumerate() {
        let Some(inertial) = &link.inertial else {
            continue;
        };
        let index = if l == robot.root_link {
            -1
        } else {
            match model.link_names.iter().position(|n| *n == link.name) {
                Some(i) => i as c_int,
                None => continue,
            }
        };
        let info = dynamics_info(lock, client, body, index)?;
        if info.m_mass > 0.0 && inertial.mass_kg > 0.0 && inertial.mass_kg != info.m_mass {
            crate::build::set_mass(
                lock,
                client,
                body,
                index,
                &info,
                inertial.mass_kg / info.m_mass,
            )?;
        }
    }
    Ok(())
}

/// Restitution and contact softness of the scene's objects.
pub(crate) struct ContactPlan {
    /// Per object (scene order): restitution, when set.
    restitution: Vec<Option<f64>>,
    /// Per object: (contactStiffness N/m, contactDamping N s/m), when the
    /// `[contact]` keys are set.
    softness: Vec<Option<(f64, f64)>>,
}

impl ContactPlan {
    /// Checks the parameters and computes the per-object values.
    pub fn new(scene: &Scene, params: &PhysicalParams) -> Result<ContactPlan, EngineError> {
        check_uncontrolled_friction(scene, params)?;
        let restitution = scene
            .objects
            .iter()
            .map(|o| params.restitution(&o.name))
            .collect();
        let c = &params.contact;
        let softness = if c.time_constant_s.is_none() && c.damping_ratio.is_none() {
            vec![None; scene.objects.len()]
        } else {
            let tc = c.time_constant_s.unwrap_or(DEFAULT_TIME_CONSTANT_S);
            let z = c.damping_ratio.unwrap_or(DEFAULT_DAMPING_RATIO);
            let mut out = Vec::new();
            for o in &scene.objects {
                let (k, d) = spring_damper(o.mass_kg, tc, z);
                if d <= 0.0 {
                    return Err(param_error(
                        "contact.time_constant_s".into(),
                        format!(
                            "object \"{}\" ({} kg): contact damping 2 m / tc = {} N s/m is not above the {PARTNER_CONTACT_DAMPING} N s/m Bullet's other body adds; use a shorter time constant",
                            o.name,
                            o.mass_kg,
                            d + PARTNER_CONTACT_DAMPING
                        ),
                    ));
                }
                out.push(Some((k, d)));
            }
            out
        };
        Ok(ContactPlan {
            restitution,
            softness,
        })
    }

    /// Applies the plan to the built world. Needs the Bullet lock (`lock`).
    pub fn apply(
        &self,
        lock: &ffi::BulletLock,
        client: &ffi::Client,
        ground: Option<c_int>,
        robot: c_int,
        model: &BulletModel,
        objects: &[c_int],
    ) -> Result<(), EngineError> {
        if self.restitution.iter().any(Option::is_some) {
            // Bullet's contact restitution is the product of the two
            // bodies'; partners at 1 make it the object's own value.
            let mut partners: Vec<(c_int, c_int)> = (-1..model.infos.len() as c_int)
                .map(|l| (robot, l))
                .collect();
            partners.extend(ground.map(|g| (g, -1)));
            for (body, link) in partners {
                set_restitution(lock, client, body, link, 1.0)?;
            }
        }
        for (i, &body) in objects.iter().enumerate() {
            if let Some(r) = self.restitution[i] {
                set_restitution(lock, client, body, -1, r)?;
            }
            if let Some((k, d)) = self.softness[i] {
                // SAFETY: the command is created on this simulation's client and
                // submitted once, with the Bullet lock held (`lock`); the pointers
                // passed point to live locals of the sizes Bullet expects.
                unsafe {
                    let cmd = ffi::b3InitChangeDynamicsInfo(client.handle(lock));
                    ffi::b3ChangeDynamicsInfoSetContactStiffnessAndDamping(cmd, body, -1, k, d);
                    expect(
                        client.submit(lock, cmd).kind,
                        ffi::CMD_CLIENT_COMMAND_COMPLETED,
                        "setting the contact stiffness and damping",
                    )?;
                }
            }
        }
        Ok(())
    }
}

/// The contact spring (N/m) and the damping (N s/m) to give a body of
/// `mass_kg` for time constant `tc` (s) and damping ratio `z`, MuJoCo's
/// convention per unit mass (stiffness 1/(tc^2 z^2), damping 2/tc), with
/// the partner's default damping taken off (Bullet adds it back).
pub fn spring_damper(mass_kg: f64, tc: f64, z: f64) -> (f64, f64) {
    let k = mass_kg / (tc * tc * z * z);
    let d = 2.0 * mass_kg / tc - PARTNER_CONTACT_DAMPING;
    (k, d)
}

fn set_restitution(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    body: c_int,
    link: c_int,
    value: f64,
) -> Result<(), EngineError> {
    // SAFETY: the command is created on this simulation's client and
    // submitted once, with the Bullet lock held (`lock`); the pointers
    // passed point to live locals of the sizes Bullet expects.
    unsafe {
        let cmd = ffi::b3InitChangeDynamicsInfo(client.handle(lock));
        ffi::b3ChangeDynamicsInfoSetRestitution(cmd, body, link, value);
        expect(
            client.submit(lock, cmd).kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "setting a restitution",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spring_damper_follows_mujocos_convention() {
        // m = 1 kg, tc = 0.1 s, z = 1: omega = 10 rad/s, zeta = 1.
        let (k, d) = spring_damper(1.0, 0.1, 1.0);
        assert!((k - 100.0).abs() < 1e-9);
        let c = d + PARTNER_CONTACT_DAMPING;
        assert!((c - 20.0).abs() < 1e-12);
        let zeta = c / (2.0 * (k * 1.0f64).sqrt());
        assert!((zeta - 1.0).abs() < 1e-12);
        // z = 0.5: omega = 1/(tc z) = 20 rad/s, zeta = 0.5.
        let (k, d) = spring_damper(1.0, 0.1, 0.5);
        assert!(((k / 1.0f64).sqrt() - 20.0).abs() < 1e-9);
        let zeta = (d + PARTNER_CONTACT_DAMPING) / (2.0 * k.sqrt());
        assert!((zeta - 0.5).abs() < 1e-12);
    }

    #[test]
    fn support_lists_no_core_key_and_no_unmapped_key() {
        for s in SUPPORT {
            assert!(!s.key.is_core(), "{}", s.key);
            assert!(!s.mapping.is_empty());
        }
        for missing in [ParamKey::JointArmature, ParamKey::JointKv] {
            assert!(SUPPORT.iter().all(|s| s.key != missing), "{missing}");
        }
    }
}
