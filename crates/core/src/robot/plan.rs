//! Shared model planning: the engine-independent part of turning a
//! [`RobotModel`] and a [`Scene`] into an engine's model, worked out once
//! here instead of in every engine crate.
//!
//! - **Name resolution.** The scene's actuated joints, held joints and
//!   tracked links and objects become indices into the robot and the scene
//!   ([`actuated_joints`], [`initial_positions`], [`tracked_targets`]).
//! - **Rigid groups.** Links joined by a fixed joint, or by a movable joint
//!   the scene does not control (held, e.g. the fingers, at the scene's held
//!   position), move as one rigid body: a group starts at the root link and
//!   below every actuated joint ([`rigid_groups`]). An engine may also start
//!   a group at every link with mass ([`GroupSplit::AlsoAtLinksWithMass`])
//!   and weld it to its parent group itself. A group's frame is the frame of
//!   its top (root-most) link; every member link has a fixed pose in it
//!   ([`RigidGroups::link_in_group`]).
//! - **Mass merging.** The URDF `<inertial>`s of a group's links combine
//!   into one mass, centre of mass and inertia about that centre in the
//!   group frame, by the parallel-axis theorem ([`group_mass`]).
//!
//! Gravity is the scene's ([`Scene::gravity_m_s2`]). Everything here is
//! pure: plain data out, no engine types. Units: m, kg, kg m^2, rad.
//!
//! Mimic joints that are not actuated take the position of the joint they
//! follow (as in [`RobotModel::forward_kinematics`]); a mimic joint that
//! follows an actuated joint cannot be welded and is an error.

use super::RobotModel;
use crate::pose::{Pose, Vec3};
use crate::scene::{Scene, TrackTarget};
use std::fmt;

/// Why a scene and robot cannot be planned as one model; the message names
/// the joint, link or object.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlanError(pub String);

impl fmt::Display for PlanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PlanError {}

/// Mass properties of a rigid body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the body's frame, m.
    pub com_m: Vec3,
    /// Inertia about the centre of mass in the body's axes, kg m^2,
    /// row-major 3x3 (symmetric).
    pub inertia_kg_m2: [f64; 9],
}

/// One part of a body for [`combine_masses`]: its centre of mass (m, in
/// the body frame), its mass (kg) and its inertia about its own centre of
/// mass in the body's axes (kg m^2, row-major 3x3).
pub type MassPart = (Vec3, f64, [f64; 9]);

/// The inverse of a rigid pose.
pub fn pose_inverse(p: &Pose) -> Pose {
    let q = p.orientation.conjugate();
    Pose::new(-q.rotate(p.position_m), q)
}

/// `R I R^T` for a rotation matrix `r` (row-major): an inertia tensor `i`
/// given in rotated axes, expressed in the unrotated ones (kg m^2).
pub fn rotate_inertia(r: &[f64; 9], i: &[f64; 9]) -> [f64; 9] {
    let mut ri = [0.0; 9];
    let mut out = [0.0; 9];
    for a in 0..3 {
        for b in 0..3 {
            ri[3 * a + b] = (0..3).map(|k| r[3 * a + k] * i[3 * k + b]).sum();
        }
    }
    for a in 0..3 {
        for b in 0..3 {
            out[3 * a + b] = (0..3).map(|k| ri[3 * a + k] * r[3 * b + k]).sum();
        }
    }
    out
}

/// Combines parts into the total mass, the centre of mass `sum(m p) / M`
/// and the inertia about that centre: each part's own inertia plus `m (|d|^2
/// 1 - d d^T)` for its offset `d` from the centre (parallel-axis theorem).
/// `None` when the total mass is not positive.
pub fn combine_masses(parts: &[MassPart]) -> Option<MassProperties> {
    let mass: f64 = parts.iter().map(|p| p.1).sum();
    if mass <= 0.0 {
        return None;
    }
    let com = parts
        .iter()
        .fold(Vec3::ZERO, |acc, (p, m, _)| acc + p.scale(*m))
        .scale(1.0 / mass);
    let mut inertia = [0.0; 9];
    for (p, m, i) in parts {
        let d = *p - com;
        let dd = d.dot(d);
        let dv = [d.x, d.y, d.z];
        for a in 0..3 {
            for b in 0..3 {
                let delta = if a == b { 1.0 } else { 0.0 };
                inertia[3 * a + b] += i[3 * a + b] + m * (dd * delta - dv[a] * dv[b]);
            }
        }
    }
    Some(MassProperties {
        mass_kg: mass,
        com_m: com,
        inertia_kg_m2: inertia,
    })
}

/// Whether a symmetric 3x3 matrix is finite and positive definite
/// (Sylvester's criterion).
pub fn is_positive_definite(m: &[f64; 9]) -> bool {
    let d1 = m[0];
    let d2 = m[0] * m[4] - m[1] * m[3];
    let d3 = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
        + m[2] * (m[3] * m[7] - m[4] * m[6]);
    m.iter().all(|x| x.is_finite()) && d1 > 0.0 && d2 > 0.0 && d3 > 0.0
}

/// The `<inertial>`s of `links` (in that order) as parts in their group's
/// frame (`link_in_group`, indexed by link), masses and inertias scaled by
/// `mass_scale`. Links without an inertial or with zero mass add nothing.
pub fn link_mass_parts(
    robot: &RobotModel,
    links: &[usize],
    link_in_group: &[Pose],
    mass_scale: f64,
) -> Vec<MassPart> {
    let mut parts = Vec::new();
    for &l in links {
        if let Some(inertial) = &robot.links[l].inertial {
            if inertial.mass_kg > 0.0 {
                let frame = link_in_group[l].compose(&inertial.origin);
                let r = frame.orientation.to_rotation_matrix();
                let i = rotate_inertia(&r, &inertial.inertia_matrix());
                parts.push((
                    frame.position_m,
                    inertial.mass_kg * mass_scale,
                    i.map(|x| x * mass_scale),
                ));
            }
        }
    }
    parts
}

/// The merged mass properties of `links` (one rigid group) in the group's
/// frame, masses scaled by `mass_scale` ([`link_mass_parts`] combined by
/// [`combine_masses`], in the order of `links`). `None` when none of the
/// links has mass.
pub fn group_mass(
    robot: &RobotModel,
    links: &[usize],
    link_in_group: &[Pose],
    mass_scale: f64,
) -> Option<MassProperties> {
    combine_masses(&link_mass_parts(robot, links, link_in_group, mass_scale))
}

/// The servos' gains and force limits: `kv` positive and finite, the
/// force limit >= 0 (0 turns the servo off).
pub fn check_servos(scene: &Scene) -> Result<(), PlanError> {
    for a in &scene.actuators {
        if !(a.kv.is_finite() && a.kv > 0.0) {
            return Err(PlanError(format!(
                "actuator of joint \"{}\": kv must be positive and finite, found {}",
                a.joint, a.kv
            )));
        }
        if a.force_limit.is_nan() || a.force_limit < 0.0 {
            return Err(PlanError(format!(
                "actuator of joint \"{}\": force limit must be >= 0 (0 = servo off), found {}",
                a.joint, a.force_limit
            )));
        }
    }
    Ok(())
}

/// True when no joint of the scene's actuators lies between `link` and the
/// root: the link is part of the robot's fixed base.
pub fn in_fixed_base(scene: &Scene, robot: &RobotModel, link: usize) -> bool {
    let mut at = link;
    while let Some(j) = robot.parent_joint(at) {
        let joint = &robot.joints[j];
        if scene.actuators.iter().any(|a| a.joint == joint.name) {
            return false;
        }
        at = joint.parent;
    }
    true
}

/// The robot joints the scene's actuators drive, in actuator order. Each
/// must exist, be movable, not mimic another joint, and carry one actuator
/// only.
pub fn actuated_joints(scene: &Scene, robot: &RobotModel) -> Result<Vec<usize>, PlanError> {
    let mut actuated = Vec::with_capacity(scene.actuators.len());
    for a in &scene.actuators {
        let j = robot.joint_by_name(&a.joint).ok_or_else(|| {
            PlanError(format!(
                "robot \"{}\" has no joint \"{}\"",
                robot.name, a.joint
            ))
        })?;
        let joint = &robot.joints[j];
        if !joint.kind.is_movable() {
            return Err(PlanError(format!(
                "joint \"{}\" is fixed and cannot carry an actuator",
                a.joint
            )));
        }
        if joint.mimic.is_some() {
            return Err(PlanError(format!(
                "joint \"{}\" mimics another joint and cannot carry an actuator",
                a.joint
            )));
        }
        if actuated.contains(&j) {
            return Err(PlanError(format!(
                "joint \"{}\" has two actuators",
                a.joint
            )));
        }
        actuated.push(j);
    }
    Ok(actuated)
}

/// Joint positions of the initial configuration, indexed like
/// `robot.joints` (rad or m): actuated and fixed joints at 0, held joints
/// at the scene's held position (0 when the scene names none). A mimic
/// joint that follows an actuated joint is an error (it could not be
/// welded); other mimic joints follow their leader in
/// [`RobotModel::forward_kinematics`].
pub fn initial_positions(
    scene: &Scene,
    robot: &RobotModel,
    actuated: &[usize],
) -> Result<Vec<f64>, PlanError> {
    let mut positions = vec![0.0; robot.joints.len()];
    for (j, joint) in robot.joints.iter().enumerate() {
        if actuated.contains(&j) || !joint.kind.is_movable() {
            continue;
        }
        if let Some(m) = &joint.mimic {
            if actuated.contains(&m.joint) {
                return Err(PlanError(format!(
                    "joint \"{}\" mimics the actuated joint \"{}\"; mimic joints that follow a controlled joint are not supported",
                    joint.name, robot.joints[m.joint].name
                )));
            }
        }
        positions[j] = scene
            .robot
            .held_joints_rad
            .get(&joint.name)
            .copied()
            .unwrap_or(0.0);
    }
    Ok(positions)
}

/// Where groups start besides the root link and below actuated joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GroupSplit {
    /// Only there: every other link is welded into its parent's group.
    AtActuatedJoints,
    /// Also at every link with mass (the engine holds such a group to its
    /// parent group with a fixed joint); massless links still join their
    /// parent's group.
    AlsoAtLinksWithMass,
}

/// One rigid group of links.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidGroup {
    /// The top (root-most) link; its frame is the group's frame.
    pub top_link: usize,
    /// The member links, top link first, then depth-first in
    /// [`RobotModel::joints_in_tree_order`].
    pub links: Vec<usize>,
    /// The joint above the top link and the group it hangs on (`None` for
    /// the root group).
    pub parent: Option<(usize, usize)>,
    /// Whether that joint is not actuated (the group is welded to its
    /// parent; only with [`GroupSplit::AlsoAtLinksWithMass`]).
    pub welded: bool,
}

/// The robot's links split into rigid groups.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidGroups {
    /// The groups; group 0 holds the root link. A group's parent group
    /// always comes before it.
    pub groups: Vec<RigidGroup>,
    /// Each link's group (indexed like `robot.links`).
    pub group_of_link: Vec<usize>,
    /// Each link's frame in its group's frame (indexed like `robot.links`).
    pub link_in_group: Vec<Pose>,
}

/// Splits the robot's links into rigid groups (see the module
/// documentation) at the joint positions `positions` (indexed like
/// `robot.joints`, e.g. from [`initial_positions`]); `actuated` are the
/// joints that separate groups (any order). A link's pose in its group is
/// `inverse(top) * link` of their forward-kinematics poses from the
/// identity.
pub fn rigid_groups(
    robot: &RobotModel,
    actuated: &[usize],
    positions: &[f64],
    split: GroupSplit,
) -> RigidGroups {
    let has_mass = |l: usize| robot.links[l].inertial.is_some_and(|i| i.mass_kg > 0.0);
    let mut group_of_link = vec![usize::MAX; robot.links.len()];
    let mut groups = vec![RigidGroup {
        top_link: robot.root_link,
        links: vec![robot.root_link],
        parent: None,
        welded: false,
    }];
    group_of_link[robot.root_link] = 0;
    for &j in robot.joints_in_tree_order() {
        let joint = &robot.joints[j];
        let is_actuated = actuated.contains(&j);
        let weld_split = split == GroupSplit::AlsoAtLinksWithMass && has_mass(joint.child);
        let parent_group = group_of_link[joint.parent];
        if is_actuated || weld_split {
            group_of_link[joint.child] = groups.len();
            groups.push(RigidGroup {
                top_link: joint.child,
                links: vec![joint.child],
                parent: Some((j, parent_group)),
                welded: !is_actuated,
            });
        } else {
            group_of_link[joint.child] = parent_group;
            groups[parent_group].links.push(joint.child);
        }
    }
    let world = robot.forward_kinematics(&Pose::IDENTITY, positions);
    let link_in_group = (0..robot.links.len())
        .map(|l| pose_inverse(&world[groups[group_of_link[l]].top_link]).compose(&world[l]))
        .collect();
    RigidGroups {
        groups,
        group_of_link,
        link_in_group,
    }
}

/// What a tracked body of the scene follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackedRef {
    /// A robot link (index in `robot.links`).
    Link(usize),
    /// A scene object (index in `scene.objects`).
    Object(usize),
}

/// The scene's tracked bodies, in `[[track]]` order, resolved to links and
/// objects.
pub fn tracked_targets(scene: &Scene, robot: &RobotModel) -> Result<Vec<TrackedRef>, PlanError> {
    scene
        .tracked
        .iter()
        .map(|t| match &t.target {
            TrackTarget::Link(name) => {
                robot
                    .link_by_name(name)
                    .map(TrackedRef::Link)
                    .ok_or_else(|| {
                        PlanError(format!(
                            "tracked link \"{name}\" is not a link of robot \"{}\"",
                            robot.name
                        ))
                    })
            }
            TrackTarget::Object(name) => scene
                .objects
                .iter()
                .position(|o| &o.name == name)
                .map(TrackedRef::Object)
                .ok_or_else(|| {
                    PlanError(format!(
                        "tracked object \"{name}\" is not an object of the scene"
                    ))
                }),
        })
        .collect()
}

/// The engine-independent plan of a scene's robot.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotPlan {
    /// Actuated joints, in actuator order ([`actuated_joints`]).
    pub actuated: Vec<usize>,
    /// Initial joint positions ([`initial_positions`]), rad or m.
    pub initial_positions: Vec<f64>,
    /// The rigid groups at the initial positions ([`rigid_groups`]).
    pub groups: RigidGroups,
    /// Tracked bodies, in scene order ([`tracked_targets`]).
    pub tracked: Vec<TrackedRef>,
}

/// Resolves the scene's names and splits the robot into rigid groups.
pub fn plan_robot(
    scene: &Scene,
    robot: &RobotModel,
    split: GroupSplit,
) -> Result<RobotPlan, PlanError> {
    let actuated = actuated_joints(scene, robot)?;
    let initial_positions = initial_positions(scene, robot, &actuated)?;
    let groups = rigid_groups(robot, &actuated, &initial_positions, split);
    let tracked = tracked_targets(scene, robot)?;
    Ok(RobotPlan {
        actuated,
        initial_positions,
        groups,
        tracked,
    })
}

#[cfg(test)]
#[path = "plan_tests.rs"]
mod tests;
