//! The physical parameters ([`PhysicalParams`]) on a compiled MuJoCo model.
//!
//! Two model paths, one mapping:
//! - the model written from URDF + scene ([`crate::mjcf`]) already carries
//!   what [`PhysicalParams::apply`] wrote into the scene and robot (servo
//!   `kv` and force limits, joint damping and friction loss, link and
//!   object masses, object friction); here it gets the engine-mapped keys:
//!   armature and contact softness;
//! - an MJCF file loaded as is (`scene.robot.mjcf`) ignores the scene and
//!   robot, so every key is written here onto the model by joint, actuator
//!   and body name.
//!
//! A key that names something the model lacks (a joint welded in the
//! model built from URDF, a body absent from the MJCF file) or that cannot
//! be honoured with its value is an [`EngineError::Param`].

use crate::{mjcf, ENGINE_NAME};
use mujoco_rs::mujoco_c;
use mujoco_rs::prelude::*;
use realitygap_core::engine::EngineError;
use realitygap_core::params::{ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::scene::Scene;

/// The keys MuJoCo honours beyond the controller's, and how each maps.
pub fn param_support() -> Vec<ParamSupport> {
    let s = |key, mapping| ParamSupport { key, mapping };
    vec![
        s(ParamKey::JointDamping, "dof_damping of the joint's DOF"),
        s(ParamKey::JointArmature, "dof_armature of the joint's DOF"),
        s(ParamKey::JointFrictionloss, "dof_frictionloss of the joint's DOF"),
        s(
            ParamKey::JointKv,
            "velocity actuator gain: gainprm[0] = kv, biasprm[2] = -kv",
        ),
        s(
            ParamKey::JointForceLimit,
            "actuator forcerange [-F, F], forcelimited (F = 0: the servo gives no torque)",
        ),
        s(
            ParamKey::LinkMassScale,
            "body_mass and body_inertia of the link's body",
        ),
        s(
            ParamKey::ObjectMass,
            "body_mass of the object's body (body_inertia scaled with it)",
        ),
        s(
            ParamKey::ObjectFriction,
            "geom_friction[0] of the object's geoms, with geom_priority 1 so that it is the contact's coefficient",
        ),
        s(
            ParamKey::ObjectRestitution,
            "solref[1] (dampratio) of the object's geoms = -ln e / sqrt(pi^2 + ln^2 e), the damping ratio of a linear spring-damper with restitution e, and geom_priority 1 (e < 1)",
        ),
        s(
            ParamKey::ContactTimeConstant,
            "solref[0] (timeconst) of every geom and contact pair (>= 2 timesteps)",
        ),
        s(
            ParamKey::ContactDampingRatio,
            "solref[1] (dampratio) of every geom and contact pair",
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

/// Where the model came from, for the parameters it still needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ModelSource<'a> {
    /// Written from URDF + scene: it already has the scene and robot keys.
    Generated,
    /// The MJCF file at this path, loaded as is.
    AsIs(&'a std::path::Path),
}

impl ModelSource<'_> {
    /// ` in the MJCF file PATH`, or nothing for the generated model.
    fn place(&self) -> String {
        match self {
            ModelSource::Generated => String::new(),
            ModelSource::AsIs(p) => format!(" in the MJCF file {}", p.display()),
        }
    }

    fn missing(&self, what: &str) -> String {
        match self {
            ModelSource::Generated => format!(
                "{what} is not a joint of the model built from URDF: held and fixed joints are welded there; MuJoCo honours joint parameters on the controlled joints"
            ),
            ModelSource::AsIs(p) => format!("the MJCF file {} has no {what}", p.display()),
        }
    }
}

/// Writes `params` onto `model` (see the module documentation). Call after
/// the engine settings (the contact time constant is checked against the
/// timestep). Returns true when masses or inertias changed, so that the
/// caller recomputes MuJoCo's derived constants (`mj_setConst`).
pub fn apply(
    model: &mut MjModel,
    scene: &Scene,
    params: &PhysicalParams,
    source: ModelSource<'_>,
) -> Result<bool, EngineError> {
    let mut changed = apply_joints(model, params, source)?;
    if let ModelSource::AsIs(_) = source {
        changed |= apply_links(model, params, source)?;
        changed |= apply_objects(model, scene, params, source)?;
    }
    apply_contact(model, params)?;
    apply_restitution(model, params, source)?;
    Ok(changed)
}

/// The hinge or slide joint named `name`.
fn dof_of(model: &MjModel, name: &str) -> Option<usize> {
    let j = model.name_to_id(MjtObjBase::mjOBJ_JOINT, name)?;
    let t = model.jnt_type()[j];
    (t == mujoco_c::mjtJoint::mjJNT_HINGE || t == mujoco_c::mjtJoint::mjJNT_SLIDE)
        .then(|| model.jnt_dofadr()[j] as usize)
}

/// The actuator whose transmission is joint `name`.
pub fn actuator_of(model: &MjModel, name: &str) -> Option<usize> {
    let j = model.name_to_id(MjtObjBase::mjOBJ_JOINT, name)?;
    (0..model.ffi().nu as usize).find(|&u| {
        model.actuator_trntype()[u] == mujoco_c::mjtTrn::mjTRN_JOINT
            && model.actuator_trnid()[u][0] as usize == j
    })
}

fn apply_joints(
    model: &mut MjModel,
    params: &PhysicalParams,
    source: ModelSource<'_>,
) -> Result<bool, EngineError> {
    let as_is = matches!(source, ModelSource::AsIs(_));
    let mut changed = false;
    for (name, j) in &params.joints {
        let dof_keys = [
            ("damping", j.damping),
            ("armature", j.armature),
            ("frictionloss", j.frictionloss),
        ];
        if let Some((first, _)) = dof_keys.iter().find(|(_, v)| v.is_some()) {
            let dof = dof_of(model, name).ok_or_else(|| {
                param_error(
                    format!("joints.{name}.{first}"),
                    source.missing(&format!("hinge or slide joint \"{name}\"")),
                )
            })?;
            if let Some(a) = j.armature {
                model.dof_armature_mut()[dof] = a;
                changed = true;
            }
            if as_is {
                if let Some(d) = j.damping {
                    model.dof_damping_mut()[dof] = d;
                }
                if let Some(f) = j.frictionloss {
                    model.dof_frictionloss_mut()[dof] = f;
                }
            }
        }
        if as_is && (j.kv.is_some() || j.force_limit.is_some()) {
            set_servo(model, name, j.kv, j.force_limit, source)?;
        }
    }
    Ok(changed)
}

/// Sets the gain and force limit of the velocity servo on joint `joint`
/// (`force_limit` 0: no torque at all).
pub fn set_servo(
    model: &mut MjModel,
    joint: &str,
    kv: Option<f64>,
    force_limit: Option<f64>,
    source: ModelSource<'_>,
) -> Result<(), EngineError> {
    let first = if kv.is_some() { "kv" } else { "force_limit" };
    let key = format!("joints.{joint}.{first}");
    let u = actuator_of(model, joint).ok_or_else(|| {
        param_error(
            key.clone(),
            source.missing(&format!("actuator on joint \"{joint}\"")),
        )
    })?;
    if let Some(kv) = kv {
        let gain = model.actuator_gainprm()[u];
        let bias = model.actuator_biasprm()[u];
        let velocity_servo = model.actuator_gaintype()[u] == MjtGain::mjGAIN_FIXED
            && model.actuator_biastype()[u] == MjtBias::mjBIAS_AFFINE
            && model.actuator_dyntype()[u] == MjtDyn::mjDYN_NONE
            && bias[0] == 0.0
            && bias[1] == 0.0
            && bias[2] == -gain[0];
        if !velocity_servo {
            return Err(param_error(
                format!("joints.{joint}.kv"),
                format!(
                    "the actuator on joint \"{joint}\"{} is not a velocity servo (<velocity kv=...>); kv applies only to one",
                    source.place()
                ),
            ));
        }
        // SAFETY: only the gain value changes, not the gain type or any
        // index MuJoCo reads unchecked.
        let gains = unsafe { model.actuator_gainprm_mut() };
        gains[u][0] = kv;
        model.actuator_biasprm_mut()[u][2] = -kv;
    }
    if let Some(f) = force_limit {
        model.actuator_forcelimited_mut()[u] = true;
        model.actuator_forcerange_mut()[u] = [-f, f];
    }
    Ok(())
}

fn apply_links(
    model: &mut MjModel,
    params: &PhysicalParams,
    source: ModelSource<'_>,
) -> Result<bool, EngineError> {
    let mut changed = false;
    for (name, l) in &params.links {
        let Some(s) = l.mass_scale else { continue };
        let b = model
            .name_to_id(MjtObjBase::mjOBJ_BODY, &mjcf::body_name(name))
            .ok_or_else(|| {
                param_error(
                    format!("links.{name}.mass_scale"),
                    source.missing(&format!("body \"{name}\"")),
                )
            })?;
        model.body_mass_mut()[b] *= s;
        for c in model.body_inertia_mut()[b].iter_mut() {
            *c *= s;
        }
        changed = true;
    }
    Ok(changed)
}

/// The body of scene object `name`: `object:NAME` (the model built from
/// URDF) or `NAME` (an MJCF file).
pub fn object_body(model: &MjModel, name: &str) -> Option<usize> {
    let generated = format!("{}{name}", mjcf::OBJECT_BODY_PREFIX);
    model
        .name_to_id(MjtObjBase::mjOBJ_BODY, &generated)
        .or_else(|| model.name_to_id(MjtObjBase::mjOBJ_BODY, name))
}

fn apply_objects(
    model: &mut MjModel,
    scene: &Scene,
    params: &PhysicalParams,
    source: ModelSource<'_>,
) -> Result<bool, EngineError> {
    let mut changed = false;
    for (name, o) in &params.objects {
        let field = if o.mass_kg.is_some() {
            "mass_kg"
        } else {
            "friction"
        };
        let key = format!("objects.{name}.{field}");
        if !scene.objects.iter().any(|x| &x.name == name) {
            return Err(param_error(
                key,
                format!("the scene {} has no object \"{name}\"", scene.name),
            ));
        }
        let b = object_body(model, name)
            .ok_or_else(|| param_error(key.clone(), source.missing(&format!("body \"{name}\""))))?;
        if let Some(m) = o.mass_kg {
            let old = model.body_mass()[b];
            if old <= 0.0 {
                return Err(param_error(
                    key,
                    format!("the body \"{name}\" has no mass to scale in the model"),
                ));
            }
            let ratio = m / old;
            model.body_mass_mut()[b] = m;
            for c in model.body_inertia_mut()[b].iter_mut() {
                *c *= ratio;
            }
            changed = true;
        }
        if let Some(f) = o.friction {
            let first = model.body_geomadr()[b].max(0) as usize;
            let count = model.body_geomnum()[b].max(0) as usize;
            for g in first..first + count {
                model.geom_friction_mut()[g][0] = f;
                model.geom_priority_mut()[g] = 1;
            }
        }
    }
    Ok(changed)
}

/// Sets solref of every geom and contact pair; the value left unset keeps
/// each geom's own (when it is in the (timeconst, dampratio) form).
fn apply_contact(model: &mut MjModel, params: &PhysicalParams) -> Result<(), EngineError> {
    let tc = params.contact.time_constant_s;
    let dr = params.contact.damping_ratio;
    if tc.is_none() && dr.is_none() {
        return Ok(());
    }
    let dt = model.opt().timestep;
    if let Some(tc) = tc {
        if tc < 2.0 * dt {
            return Err(param_error(
                "contact.time_constant_s".into(),
                format!(
                    "{tc} s is below two timesteps ({} s at timestep {dt} s): MuJoCo would clamp it to that; use a larger value or a smaller timestep",
                    2.0 * dt
                ),
            ));
        }
    }
    let set = |solref: &mut [f64; 2], what: &str| -> Result<(), EngineError> {
        let partial = tc.is_none() || dr.is_none();
        if partial && (solref[0] <= 0.0 || solref[1] <= 0.0) {
            let key = if tc.is_some() {
                "time_constant_s"
            } else {
                "damping_ratio"
            };
            return Err(param_error(
                format!("contact.{key}"),
                format!(
                    "{what} has a direct solref (-stiffness, -damping); set both time_constant_s and damping_ratio to replace it"
                ),
            ));
        }
        *solref = [tc.unwrap_or(solref[0]), dr.unwrap_or(solref[1])];
        Ok(())
    };
    for g in 0..model.ffi().ngeom as usize {
        set(&mut model.geom_solref_mut()[g], &format!("geom {g}"))?;
    }
    for p in 0..model.ffi().npair as usize {
        set(
            &mut model.pair_solref_mut()[p],
            &format!("contact pair {p}"),
        )?;
    }
    Ok(())
}

/// The damping ratio of a linear mass-spring-damper contact whose
/// coefficient of restitution is `e` (in `[0, 1)`): the contact's
/// half-period response scales the approach speed by
/// `e = exp(-pi zeta / sqrt(1 - zeta^2))`, so
/// `zeta = -ln e / sqrt(pi^2 + ln^2 e)`; `e = 0` gives 1 (critical).
pub fn damping_ratio_for_restitution(e: f64) -> f64 {
    if e <= 0.0 {
        return 1.0;
    }
    let l = e.ln();
    -l / (std::f64::consts::PI.powi(2) + l * l).sqrt()
}

/// Sets the damping ratio of each object's geoms from its restitution,
/// and gives them priority so their solref is the contacts'.
fn apply_restitution(
    model: &mut MjModel,
    params: &PhysicalParams,
    source: ModelSource<'_>,
) -> Result<(), EngineError> {
    for (name, o) in &params.objects {
        let Some(e) = o.restitution else { continue };
        let key = format!("objects.{name}.restitution");
        if !(0.0..1.0).contains(&e) {
            return Err(param_error(
                key,
                format!("{e} is not below 1: MuJoCo's contact needs a damping ratio above 0 (restitution 1 would be an infinitely stiff contact)"),
            ));
        }
        let b = object_body(model, name)
            .ok_or_else(|| param_error(key.clone(), source.missing(&format!("body \"{name}\""))))?;
        let zeta = damping_ratio_for_restitution(e);
        let first = model.body_geomadr()[b].max(0) as usize;
        let count = model.body_geomnum()[b].max(0) as usize;
        for g in first..first + count {
            let solref = &mut model.geom_solref_mut()[g];
            if solref[0] <= 0.0 {
                return Err(param_error(
                    key,
                    format!("the geoms of \"{name}\"{} have a direct solref (-stiffness, -damping), which has no damping ratio", source.place()),
                ));
            }
            solref[1] = zeta;
            model.geom_priority_mut()[g] = 1;
        }
    }
    Ok(())
}
