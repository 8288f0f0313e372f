//! The model description of `load` (docs/engine-protocol.md, "The model
//! description"): the scene and robot resolved by core's shared planning
//! ([`realitygap_core::robot::plan`]) into rigid bodies with merged masses,
//! welded held joints, read meshes and applied parameters, so that an
//! adapter only builds what it is given.

use realitygap_core::engine::{EngineError, EngineSettings, ModelVariation, SettingValue};
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::{Pose, Vec3};
use realitygap_core::robot::plan::{self as shared, GroupSplit, TrackedRef};
use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::{Geometry, JointKind, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene};
use serde_json::{json, Map, Value};
use std::collections::HashSet;

fn pose(p: &Pose) -> Value {
    let (v, q) = (p.position_m, p.orientation);
    json!([v.x, v.y, v.z, q.w, q.x, q.y, q.z])
}

fn vec3(v: Vec3) -> Value {
    json!([v.x, v.y, v.z])
}

/// A finite number, or `null` (unlimited, the engine's default).
fn finite_or_null(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

fn setting(v: &SettingValue) -> Value {
    match v {
        SettingValue::Bool(b) => json!(b),
        SettingValue::Integer(i) => json!(i),
        SettingValue::Float(f) if f.is_finite() => json!(f),
        // JSON has no infinity: the text reads back through the settings
        // reader's "inf".
        SettingValue::Float(f) => json!(f.to_string()),
        SettingValue::Text(t) => json!(t),
    }
}

/// The settings as JSON values.
pub fn settings_json(settings: &EngineSettings) -> Value {
    Value::Object(
        settings
            .iter()
            .map(|(k, v)| (k.clone(), setting(v)))
            .collect(),
    )
}

/// The collision shape of `geometry` at `at` (in the body frame); a mesh
/// is read and sent as its distinct scaled vertices.
fn shape(geometry: &Geometry, at: &Pose) -> Result<Value, String> {
    let mut s = match geometry {
        Geometry::Box { size_m } => json!({"type": "box", "size": vec3(*size_m)}),
        Geometry::Sphere { radius_m } => json!({"type": "sphere", "radius": radius_m}),
        Geometry::Cylinder { radius_m, length_m } => {
            json!({"type": "cylinder", "radius": radius_m, "length": length_m})
        }
        Geometry::Capsule { radius_m, length_m } => {
            json!({"type": "capsule", "radius": radius_m, "length": length_m})
        }
        Geometry::Mesh { path, uri, scale } => {
            let mesh = TriangleMesh::read(path).map_err(|e| format!("mesh \"{uri}\": {e}"))?;
            let mut seen = HashSet::new();
            let mut vertices = Vec::new();
            for corner in mesh.triangles.iter().flatten() {
                let v = [corner.x * scale.x, corner.y * scale.y, corner.z * scale.z];
                if seen.insert(v.map(f64::to_bits)) {
                    vertices.extend(v);
                }
            }
            if vertices.len() < 12 {
                return Err(format!(
                    "mesh \"{uri}\" ({}) has {} distinct vertices, a solid needs 4",
                    path.display(),
                    vertices.len() / 3
                ));
            }
            json!({"type": "mesh", "vertices": vertices, "file": path})
        }
    };
    s["pose"] = pose(at);
    Ok(s)
}

/// The error for a joint parameter set on a joint the model welds (held
/// or fixed: only the controlled joints are joints in the description),
/// where it would have no effect.
pub fn check_held_joint_params(
    engine: &str,
    scene: &Scene,
    robot: &RobotModel,
    params: &PhysicalParams,
) -> Result<(), EngineError> {
    for (name, j) in &params.joints {
        if scene.actuators.iter().any(|a| &a.joint == name) || robot.joint_by_name(name).is_none() {
            continue; // controlled, or unknown (`apply` reports those)
        }
        let set = [
            ("damping", j.damping),
            ("armature", j.armature),
            ("frictionloss", j.frictionloss),
        ];
        if let Some((key, _)) = set.iter().find(|(_, v)| v.is_some()) {
            return Err(EngineError::Param {
                engine: engine.to_string(),
                key: format!("joints.{name}.{key}"),
                message: format!(
                    "joint {name} is not controlled: held and fixed joints are welded in the model description, so the key has no effect"
                ),
            });
        }
    }
    Ok(())
}

/// The model description of `scene` with `robot` (see the module
/// documentation); the message says what cannot be described.
pub fn describe(
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
    variation: &ModelVariation,
    params: &PhysicalParams,
) -> Result<Value, String> {
    let plan = shared::plan_robot(scene, robot, GroupSplit::AtActuatedJoints)
        .map_err(|e| e.to_string())?;
    let groups = &plan.groups;
    let mut bodies = Vec::new();
    for g in &groups.groups {
        let top = &robot.links[g.top_link];
        let (parent, at, joint) = match g.parent {
            None => (-1i64, scene.robot.base, Value::Null),
            Some((j, parent_group)) => {
                let joint = &robot.joints[j];
                let at = groups.link_in_group[joint.parent].compose(&joint.origin);
                let kind = match joint.kind {
                    JointKind::Revolute | JointKind::Continuous => "hinge",
                    JointKind::Prismatic => "slide",
                    JointKind::Fixed => unreachable!("an actuated joint moves"),
                };
                let range = joint
                    .limits
                    .filter(|l| l.lower.is_finite() && l.upper.is_finite())
                    .map(|l| json!([l.lower, l.upper]))
                    .unwrap_or(Value::Null);
                let description = json!({
                    "name": joint.name, "type": kind, "axis": vec3(joint.axis),
                    "range": range, "damping": joint.damping, "frictionloss": joint.friction,
                });
                (parent_group as i64, at, description)
            }
        };
        let mass = shared::group_mass(robot, &g.links, &groups.link_in_group, variation.mass_scale);
        let (mass_kg, com, inertia) = match mass {
            Some(m) => (m.mass_kg, m.com_m, m.inertia_kg_m2),
            None => (0.0, Vec3::ZERO, [0.0; 9]),
        };
        let mut shapes = Vec::new();
        for &l in &g.links {
            for c in &robot.links[l].collisions {
                let at = groups.link_in_group[l].compose(&c.origin);
                shapes.push(
                    shape(&c.geometry, &at)
                        .map_err(|e| format!("link \"{}\": {e}", robot.links[l].name))?,
                );
            }
        }
        bodies.push(json!({
            "name": top.name, "parent": parent, "pose": pose(&at), "joint": joint,
            "mass_kg": mass_kg, "com": vec3(com), "inertia": inertia.to_vec(), "shapes": shapes,
        }));
    }
    let actuators: Vec<Value> = scene
        .actuators
        .iter()
        .zip(&plan.actuated)
        .map(|(a, &j)| {
            json!({
                "joint": a.joint,
                "body": groups.group_of_link[robot.joints[j].child],
                "kv": a.kv,
                "kp": a.kp,
                "force_limit": finite_or_null(a.force_limit),
            })
        })
        .collect();
    for o in &scene.objects {
        o.check_shape()?;
    }
    let objects: Vec<Value> = scene
        .objects
        .iter()
        .map(|o| {
            let ObjectShape::Box { size_m } = o.shape;
            json!({
                "name": o.name, "shape": "box", "size": vec3(size_m),
                "mass_kg": o.mass_kg * variation.mass_scale,
                "inertia": vec3(o.principal_inertia().scale(variation.mass_scale)),
                "pose": pose(&o.pose),
                "linear_velocity": vec3(o.linear_velocity_m_s),
                "angular_velocity": vec3(o.angular_velocity_rad_s),
                "friction": o.friction,
            })
        })
        .collect();
    let tracked: Vec<Value> = plan
        .tracked
        .iter()
        .map(|t| match *t {
            TrackedRef::Link(l) => json!({
                "body": groups.group_of_link[l],
                "offset": pose(&groups.link_in_group[l]),
            }),
            TrackedRef::Object(i) => json!({"object": i}),
        })
        .collect();
    let armature: Map<String, Value> = params
        .joints
        .iter()
        .filter_map(|(name, j)| j.armature.map(|a| (name.clone(), json!(a))))
        .collect();
    let restitution: Map<String, Value> = params
        .objects
        .iter()
        .filter_map(|(name, o)| o.restitution.map(|r| (name.clone(), json!(r))))
        .collect();
    let ground = scene
        .ground
        .map(|g| json!({"height_m": g.height_m, "friction": g.friction}))
        .unwrap_or(Value::Null);
    Ok(json!({
        "settings": settings_json(settings),
        "gravity": vec3(scene.gravity_m_s2),
        "ground": ground,
        "bodies": bodies,
        "actuators": actuators,
        "objects": objects,
        "tracked": tracked,
        "friction_scale": variation.friction_scale,
        "params": {
            "armature": armature,
            "restitution": restitution,
            "contact": {
                "time_constant_s": params.contact.time_constant_s,
                "damping_ratio": params.contact.damping_ratio,
            },
        },
    }))
}
