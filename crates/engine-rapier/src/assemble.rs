//! Assembly: a [`Scene`] and its [`RobotModel`] become a Rapier world.
//!
//! The stages, in order:
//!
//! 1. **Groups.** The robot's links are split into rigid groups by core's
//!    shared planning ([`realitygap_core::robot::plan`], which also resolves
//!    the scene's joint, link and object names): a group starts at the root
//!    link or at the child of an actuated joint, and takes in every link
//!    reached through fixed, held (non-actuated) and mimic joints, each at
//!    its fixed or held position. A group is one Rapier rigid body whose
//!    frame is the frame of its top link; every member link keeps its
//!    offset from that frame.
//! 2. **Bodies.** The root group is a fixed body at the scene's base pose;
//!    every other group is a dynamic body with the URDF mass properties of
//!    its links combined by core ([`shared::group_mass`]: masses summed,
//!    centre of mass, inertia tensors rotated into the group frame and moved
//!    by the parallel-axis theorem).
//!    Colliders carry no mass of their own. Robot bodies never sleep: they
//!    are driven by motors whose targets change from outside.
//! 3. **Colliders.** Every URDF `<collision>` shape of every member link,
//!    at the link's offset composed with the shape's origin (see
//!    [`crate::shapes`]), with Rapier's default friction (0.5) and
//!    restitution (0).
//! 4. **Joints.** Every actuated joint becomes a multibody joint (reduced
//!    coordinates) from its parent's group to its child's group: revolute
//!    (continuous joints without limits) or prismatic along the URDF axis,
//!    with the URDF position limits, a force-based velocity motor (damping =
//!    the scene's `kv`, target velocity 0, maximum force = the scene's force
//!    limit), the URDF damping as the multibody's viscous joint damping
//!    (replacing Rapier's default 0.1 N m s/rad) and the URDF friction as its
//!    dry joint friction. Contacts between the two bodies a joint connects
//!    are disabled; other robot bodies may touch.
//! 5. **World.** A fixed half-space `z >= height_m` for the ground, one
//!    dynamic box per scene object (mass from the scene, uniform density),
//!    the scene's gravity, and the solver settings.
//!
//! The physical parameters that [`PhysicalParams::apply`] cannot write into
//! the scene and robot are applied here, at load: joint `armature` (the
//! multibody's per-DoF armature), object `restitution` (the collider's,
//! combine rule `Max`) and `[contact]` softness (see [`crate::params`]).

use crate::settings::RapierSettings;
use crate::shapes::ShapeBuilder;
use rapier3d::dynamics::{GenericJointBuilder, JointAxesMask, JointAxis, MotorModel};
use rapier3d::math::{Pose as RPose, Rotation, Vector};
use rapier3d::prelude::{
    CoefficientCombineRule, ColliderBuilder, Group, InteractionGroups, InteractionTestMode,
    MassProperties, MultibodyJointHandle, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};
use realitygap_core::engine::ModelVariation;
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::plan::{self as shared, GroupSplit, RigidGroups, TrackedRef};
use realitygap_core::robot::{JointKind, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene};
use std::collections::HashMap;

/// The robot's colliders without self-collision: members of group 2 that
/// interact with every group but 2. Everything else keeps Rapier's default
/// (every group, with every group), so the robot touches the ground and
/// the objects, never itself.
const ROBOT_WITHOUT_SELF_COLLISION: InteractionGroups = InteractionGroups::new(
    Group::GROUP_2,
    Group::ALL.difference(Group::GROUP_2),
    InteractionTestMode::And,
);

/// A controlled joint in the assembled world.
#[derive(Debug, Clone)]
pub struct ControlledJoint {
    /// The URDF joint's name.
    pub name: String,
    /// The multibody joint (its handle is the child body's).
    pub handle: MultibodyJointHandle,
    /// The motor's free axis: `AngX` (revolute) or `LinX` (prismatic).
    pub axis: JointAxis,
    /// Index of the joint coordinate in Rapier's 6-vector of joint
    /// coordinates (3 for `AngX`, 0 for `LinX`).
    pub coordinate: usize,
    /// The servo's velocity gain, N m s/rad (the motor's damping).
    pub kv: f32,
    /// The PD servo's position gain for position commands, N m/rad (the
    /// motor's stiffness); 0 when the scene gives none.
    pub kp: f32,
    /// The actuator's force limit, N m (or N), infinite when none.
    pub force_limit: f64,
    /// The bodies the joint connects: the parent's and the child's.
    pub parent_body: RigidBodyHandle,
    /// See `parent_body`.
    pub child_body: RigidBodyHandle,
    /// Index of the joint's degree of freedom in the multibody's
    /// generalized velocity vector.
    pub dof: usize,
}

impl ControlledJoint {
    /// The motor's largest force for the velocity and position servos: the
    /// force limit (`f32::MAX` when unlimited).
    pub fn max_motor_force(&self) -> f32 {
        if self.force_limit.is_finite() {
            self.force_limit as f32
        } else {
            f32::MAX
        }
    }
}

/// Where a frame sits: a body and the frame's pose in the body frame.
#[derive(Debug, Clone, Copy)]
pub struct BodyFrame {
    /// The rigid body.
    pub body: RigidBodyHandle,
    /// The frame's pose in the body's frame (m, unit quaternion).
    pub offset: Pose,
}

/// The assembled world and the handles the simulation needs.
pub struct Assembly {
    /// The Rapier world.
    pub world: PhysicsWorld,
    /// The controlled joints, in the scene's actuator order.
    pub joints: Vec<ControlledJoint>,
    /// The tracked frames, in the scene's `[[track]]` order.
    pub tracked: Vec<BodyFrame>,
    /// Every URDF link's frame, by link name.
    pub links: HashMap<String, BodyFrame>,
    /// A name for every body: the top link's name for a robot body,
    /// `object:NAME` for a scene object, `ground` for the ground.
    pub body_names: HashMap<RigidBodyHandle, String>,
    /// The scene objects' bodies, in the scene's order.
    pub objects: Vec<RigidBodyHandle>,
}

pub(crate) fn to_rapier_pose(p: &Pose) -> RPose {
    let q = p.orientation.normalized().unwrap_or(Quat::IDENTITY);
    RPose::from_parts(
        Vector::new(
            p.position_m.x as f32,
            p.position_m.y as f32,
            p.position_m.z as f32,
        ),
        Rotation::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32).normalize(),
    )
}

pub(crate) fn from_rapier_pose(p: &RPose) -> Pose {
    let t = p.translation;
    let q = p.rotation;
    Pose::new(
        Vec3::new(t.x as f64, t.y as f64, t.z as f64),
        Quat::new(q.w as f64, q.x as f64, q.y as f64, q.z as f64),
    )
}

/// Builds the world of `scene` with `robot` (see the module documentation),
/// with the engine-mapped keys of `params` (already checked by
/// [`crate::params::check`]). Errors are messages for
/// [`realitygap_core::EngineError::Load`].
pub fn assemble(
    scene: &Scene,
    robot: &RobotModel,
    settings: &RapierSettings,
    variation: &ModelVariation,
    params: &PhysicalParams,
) -> Result<Assembly, String> {
    variation.check()?;
    let shared_plan =
        shared::plan_robot(scene, robot, GroupSplit::AtActuatedJoints).map_err(|e| e.0)?;
    shared::check_servos(scene).map_err(|e| e.0)?;
    let plan = &shared_plan.groups;
    let world_poses = robot.forward_kinematics(&scene.robot.base, &shared_plan.initial_positions);
    let mut world = new_world(scene, settings, params);
    let bodies = add_bodies(&mut world, robot, plan, &world_poses, settings, variation)?;
    let handles = add_joints(
        &mut world,
        scene,
        robot,
        &shared_plan.actuated,
        plan,
        &bodies,
    )?;
    set_dof_parameters(&mut world, robot, &handles, params);
    let joints = controlled_joints(&world, scene, robot, &shared_plan.actuated, &handles);
    let link_frame = |l: usize| BodyFrame {
        body: bodies[plan.group_of_link[l]],
        offset: plan.link_in_group[l],
    };
    let links: HashMap<String, BodyFrame> = robot
        .links
        .iter()
        .enumerate()
        .map(|(l, link)| (link.name.clone(), link_frame(l)))
        .collect();
    let mut body_names: HashMap<RigidBodyHandle, String> = plan
        .groups
        .iter()
        .zip(&bodies)
        .map(|(g, &b)| (b, robot.links[g.top_link].name.clone()))
        .collect();
    add_ground(&mut world, scene, variation, &mut body_names);
    let objects = add_objects(&mut world, scene, variation, params, &mut body_names)?;
    let tracked = shared_plan
        .tracked
        .iter()
        .map(|t| match *t {
            TrackedRef::Link(l) => link_frame(l),
            TrackedRef::Object(i) => BodyFrame {
                body: objects[i],
                offset: Pose::IDENTITY,
            },
        })
        .collect();
    Ok(Assembly {
        world,
        joints,
        tracked,
        links,
        body_names,
        objects,
    })
}

/// An empty world with the scene's gravity, the solver settings and the
/// contact softness of `params`.
fn new_world(scene: &Scene, settings: &RapierSettings, params: &PhysicalParams) -> PhysicsWorld {
    let mut world = PhysicsWorld::new();
    let g = scene.gravity_m_s2;
    world.gravity = Vector::new(g.x as f32, g.y as f32, g.z as f32);
    crate::params::apply_contact(&mut world.integration_parameters, &params.contact);
    let p = &mut world.integration_parameters;
    p.dt = settings.timestep_s as f32;
    p.num_solver_iterations = settings.solver_iterations;
    p.num_internal_pgs_iterations = settings.internal_pgs_iterations;
    p.num_internal_stabilization_iterations = settings.stabilization_iterations;
    world
}

/// A friction coefficient (Rapier's default when `None`) times the
/// variation's factor.
fn friction(f: Option<f64>, variation: &ModelVariation) -> f32 {
    (f.unwrap_or(ColliderBuilder::default_friction() as f64) * variation.friction_scale) as f32
}

/// Stages 2 and 3: one body per group with its colliders.
fn add_bodies(
    world: &mut PhysicsWorld,
    robot: &RobotModel,
    plan: &RigidGroups,
    world_poses: &[Pose],
    settings: &RapierSettings,
    variation: &ModelVariation,
) -> Result<Vec<RigidBodyHandle>, String> {
    let mut shapes = ShapeBuilder::new();
    let mut bodies = Vec::with_capacity(plan.groups.len());
    for (g, group) in plan.groups.iter().enumerate() {
        let top = &robot.links[group.top_link].name;
        let world_pose = world_poses[group.top_link];
        let builder = if g == 0 {
            RigidBodyBuilder::fixed().pose(to_rapier_pose(&world_pose))
        } else {
            let merged = shared::group_mass(
                robot,
                &group.links,
                &plan.link_in_group,
                variation.mass_scale,
            );
            let Some(shared::MassProperties {
                mass_kg: mass,
                com_m: com,
                inertia_kg_m2: inertia,
            }) = merged
            else {
                return Err(format!(
                    "link \"{top}\" and the links fixed to it have no mass; a moving body needs a positive mass \
                     (give it an <inertial> in {})",
                    robot.source.display()
                ));
            };
            if !(mass as f32).is_normal() || inertia.iter().any(|v| !(*v as f32).is_finite()) {
                return Err(format!(
                    "link \"{top}\" and the links fixed to it: mass {mass} kg is out of single-precision range"
                ));
            }
            let m = rapier3d::math::Matrix::from_cols_array(&inertia.map(|v| v as f32));
            let props = MassProperties::with_inertia_matrix(
                Vector::new(com.x as f32, com.y as f32, com.z as f32),
                mass as f32,
                m,
            );
            RigidBodyBuilder::dynamic()
                .pose(to_rapier_pose(&world_pose))
                .additional_mass_properties(props)
                .can_sleep(false)
        };
        let body = world.bodies.insert(builder.build());
        for &link in &group.links {
            let link_offset = plan.link_in_group[link];
            for (c, collision) in robot.links[link].collisions.iter().enumerate() {
                let (shape, shape_pose) = shapes
                    .shape(&collision.geometry, settings.mesh_shape)
                    .map_err(|e| {
                        let name = collision
                            .name
                            .as_deref()
                            .map(|n| format!(" \"{n}\""))
                            .unwrap_or_default();
                        format!(
                            "link \"{}\", collision {}{name}: {e}",
                            robot.links[link].name,
                            c + 1
                        )
                    })?;
                let pose = to_rapier_pose(&link_offset.compose(&collision.origin)) * shape_pose;
                let mut collider = ColliderBuilder::new(shape)
                    .position(pose)
                    .density(0.0)
                    .friction(friction(None, variation));
                if !settings.self_collision {
                    collider = collider.collision_groups(ROBOT_WITHOUT_SELF_COLLISION);
                }
                world
                    .colliders
                    .insert_with_parent(collider.build(), body, &mut world.bodies);
            }
        }
        bodies.push(body);
    }
    Ok(bodies)
}

/// Stage 4: the multibody joints, parents first.
fn add_joints(
    world: &mut PhysicsWorld,
    scene: &Scene,
    robot: &RobotModel,
    actuated: &[usize],
    plan: &RigidGroups,
    bodies: &[RigidBodyHandle],
) -> Result<HashMap<usize, MultibodyJointHandle>, String> {
    let mut handles: HashMap<usize, MultibodyJointHandle> = HashMap::new();
    for &j in robot.joints_in_tree_order() {
        let Some(a) = actuated.iter().position(|&k| k == j) else {
            continue;
        };
        let joint = &robot.joints[j];
        let spec = &scene.actuators[a];
        let basis = Pose::new(Vec3::ZERO, Quat::x_onto(joint.axis));
        let frame1 = plan.link_in_group[joint.parent]
            .compose(&joint.origin)
            .compose(&basis);
        let (locked, axis) = match joint.kind {
            JointKind::Revolute | JointKind::Continuous => {
                (JointAxesMask::LOCKED_REVOLUTE_AXES, JointAxis::AngX)
            }
            JointKind::Prismatic => (JointAxesMask::LOCKED_PRISMATIC_AXES, JointAxis::LinX),
            JointKind::Fixed => unreachable!("fixed joints were refused above"),
        };
        let max_force = if spec.force_limit.is_finite() {
            spec.force_limit as f32
        } else {
            f32::MAX
        };
        let mut builder = GenericJointBuilder::new(locked)
            .local_frame1(to_rapier_pose(&frame1))
            .local_frame2(to_rapier_pose(&basis))
            .contacts_enabled(false)
            .motor_model(axis, MotorModel::ForceBased)
            .motor_velocity(axis, 0.0, spec.kv as f32)
            .motor_max_force(axis, max_force);
        if let Some(lim) = joint.limits {
            if lim.lower.is_finite() && lim.upper.is_finite() {
                builder = builder.limits(axis, [lim.lower as f32, lim.upper as f32]);
            }
        }
        let handle = world
            .multibody_joints
            .insert(
                bodies[plan.group_of_link[joint.parent]],
                bodies[plan.group_of_link[joint.child]],
                builder.build(),
                true,
            )
            .ok_or_else(|| format!("Rapier refused the multibody joint \"{}\"", joint.name))?;
        handles.insert(j, handle);
    }
    Ok(handles)
}

/// Fixes the multibody's root, places every link, then sets the per-DoF
/// damping, armature and friction (DoF indices are final only once the
/// root is known to be fixed).
fn set_dof_parameters(
    world: &mut PhysicsWorld,
    robot: &RobotModel,
    handles: &HashMap<usize, MultibodyJointHandle>,
    params: &PhysicalParams,
) {
    if let Some(first) = handles.values().next() {
        let (mb, _) = world
            .multibody_joints
            .get_mut(*first)
            .expect("the handle was just inserted");
        mb.forward_kinematics(&world.bodies, true);
        mb.update_rigid_bodies(&mut world.bodies, true);
    }
    for (&j, &handle) in handles {
        let joint = &robot.joints[j];
        let (mb, link_id) = world
            .multibody_joints
            .get_mut(handle)
            .expect("the handle was just inserted");
        let dof = mb.link(link_id).expect("the link exists").assembly_id();
        mb.damping_mut()[dof] = joint.damping as f32;
        mb.armature_mut()[dof] = params.armature(&joint.name).unwrap_or(0.0) as f32;
        mb.frictions_mut()[dof] = joint.friction as f32;
    }
}

/// The controlled joints in the scene's actuator order.
fn controlled_joints(
    world: &PhysicsWorld,
    scene: &Scene,
    robot: &RobotModel,
    actuated: &[usize],
    handles: &HashMap<usize, MultibodyJointHandle>,
) -> Vec<ControlledJoint> {
    scene
        .actuators
        .iter()
        .zip(actuated)
        .map(|(a, &j)| {
            let axis = if robot.joints[j].kind == JointKind::Prismatic {
                JointAxis::LinX
            } else {
                JointAxis::AngX
            };
            let handle = handles[&j];
            let (mb, link_id) = world
                .multibody_joints
                .get(handle)
                .expect("controlled joints exist");
            let link = mb.link(link_id).expect("controlled joints have a link");
            let parent = link
                .parent_id()
                .and_then(|p| mb.link(p))
                .unwrap_or_else(|| mb.root());
            ControlledJoint {
                name: a.joint.clone(),
                handle,
                axis,
                coordinate: axis as usize,
                kv: a.kv as f32,
                kp: a.kp.unwrap_or(0.0) as f32,
                force_limit: a.force_limit,
                parent_body: parent.rigid_body_handle(),
                child_body: link.rigid_body_handle(),
                dof: link.assembly_id(),
            }
        })
        .collect()
}

/// Stage 5: the ground's half-space.
fn add_ground(
    world: &mut PhysicsWorld,
    scene: &Scene,
    variation: &ModelVariation,
    body_names: &mut HashMap<RigidBodyHandle, String>,
) {
    if let Some(ground) = &scene.ground {
        let body = world
            .bodies
            .insert(RigidBodyBuilder::fixed().translation(Vector::new(
                0.0,
                0.0,
                ground.height_m as f32,
            )));
        let collider = ColliderBuilder::halfspace(rapier3d::na::Unit::new_unchecked(Vector::Z))
            .friction(friction(ground.friction, variation));
        world
            .colliders
            .insert_with_parent(collider.build(), body, &mut world.bodies);
        body_names.insert(body, "ground".to_string());
    }
}

/// Stage 5: the scene's objects, their bodies in the scene's order.
fn add_objects(
    world: &mut PhysicsWorld,
    scene: &Scene,
    variation: &ModelVariation,
    params: &PhysicalParams,
    body_names: &mut HashMap<RigidBodyHandle, String>,
) -> Result<Vec<RigidBodyHandle>, String> {
    let mut object_bodies = Vec::with_capacity(scene.objects.len());
    for o in &scene.objects {
        let shape = match o.shape {
            ObjectShape::Box { size_m }
                if !(size_m.is_finite() && size_m.x > 0.0 && size_m.y > 0.0 && size_m.z > 0.0) =>
            {
                return Err(format!(
                    "object \"{}\": box size ({}, {}, {}) m must be positive",
                    o.name, size_m.x, size_m.y, size_m.z
                ));
            }
            ObjectShape::Box { size_m } => ColliderBuilder::cuboid(
                (size_m.x / 2.0) as f32,
                (size_m.y / 2.0) as f32,
                (size_m.z / 2.0) as f32,
            ),
        };
        let body = world
            .bodies
            .insert(RigidBodyBuilder::dynamic().pose(to_rapier_pose(&o.pose)));
        let mass = (o.mass_kg * variation.mass_scale) as f32;
        if !mass.is_normal() || mass < 0.0 {
            return Err(format!(
                "object \"{}\": mass {} kg is not a positive single-precision number",
                o.name,
                o.mass_kg * variation.mass_scale
            ));
        }
        let mut collider = shape.mass(mass).friction(friction(o.friction, variation));
        if o.friction.is_some() {
            // A friction given for the object is the contact's when the
            // other surface is at least as rough (`Min`, as in ODE and
            // DART): with Rapier's `Average` the ground's 0.5 kept every
            // contact above 0.25 whatever the object's coefficient.
            collider = collider.friction_combine_rule(CoefficientCombineRule::Min);
        }
        if let Some(r) = params.restitution(&o.name) {
            // The other colliders' restitution is 0: with `Max` the
            // object's coefficient is the contact's.
            collider = collider
                .restitution(r as f32)
                .restitution_combine_rule(CoefficientCombineRule::Max);
        }
        world
            .colliders
            .insert_with_parent(collider.build(), body, &mut world.bodies);
        object_bodies.push(body);
        body_names.insert(body, format!("object:{}", o.name));
    }
    Ok(object_bodies)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rapier_pose_round_trip() {
        let p = Pose::new(
            Vec3::new(0.1, -0.2, 0.3),
            Quat::from_euler_rpy(0.3, -0.2, 1.1),
        );
        let back = from_rapier_pose(&to_rapier_pose(&p));
        assert!(back.position_m.distance(p.position_m) < 1e-7);
        assert!(back.orientation.angle_to(p.orientation) < 1e-6);
    }
}
