//! The ODE model of a scene, worked out in plain Rust before any ODE object
//! exists: which URDF links become one rigid ODE body, each body's mass,
//! centre of mass and inertia, where its collision shapes sit, which joints
//! become hinges, and where each tracked link frame is on its body.
//!
//! Rules:
//! - Links joined by a fixed joint, or by a movable joint the scene does not
//!   control (held, e.g. the fingers, at the scene's held position), form
//!   one rigid body (setting `weld = "merge"`, the default). This is exact
//!   for a held joint (it cannot move) and keeps the 10 g finger links from
//!   being separate bodies. With `weld = "fixed_joint"` every link with mass
//!   is its own body instead, held to its parent by an ODE fixed joint
//!   ([`ModelPlan::welds`]); massless links still merge into their parent.
//! - Every controlled joint becomes an ODE hinge between two bodies.
//! - An ODE body's frame is at its centre of mass (ODE requires it) with
//!   the axes of its first link (the link nearest the root), so a link
//!   frame is found on its body by composing the body pose with
//!   `translate(-com) * link_in_root` ([`BodyPlan::link_in_body`]).
//! - Masses and inertias come from the URDF `<inertial>`s only, combined
//!   with the parallel-axis theorem; a moving body without mass is an
//!   error (ODE cannot integrate it). A massless base is static.

use crate::settings::{Base, OdeSettings, Weld};
use realitygap_core::engine::ModelVariation;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::plan::{self as shared, GroupSplit, TrackedRef};
pub use realitygap_core::robot::plan::{is_positive_definite, pose_inverse};
use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::{Geometry, JointKind, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene};
use std::collections::HashMap;
use std::f64::consts::PI;

/// Why a scene and robot cannot be built as an ODE model.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanError(pub String);

/// A pure translation.
fn translation(v: Vec3) -> Pose {
    Pose::new(v, Quat::IDENTITY)
}

/// Mass properties of a body about its centre of mass, in the body axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassPlan {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Inertia about the centre of mass, body axes, kg m^2, row-major 3x3.
    pub inertia: [f64; 9],
}

/// A collision shape, centred on its own frame.
#[derive(Debug, Clone, PartialEq)]
pub enum ShapePlan {
    /// Full edge lengths along x, y, z, m.
    Box(Vec3),
    /// Radius, m.
    Sphere(f64),
    /// Along z: radius and full length, m.
    Cylinder(f64, f64),
    /// Along z: radius and length of the cylindrical part, m.
    Capsule(f64, f64),
    /// A triangle mesh (scaled, vertices welded).
    Mesh(MeshPlan),
}

/// A triangle mesh ready for `dGeomTriMeshDataBuildDouble`.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshPlan {
    /// The file it came from (for messages).
    pub uri: String,
    /// Vertex coordinates, x y z per vertex, m.
    pub vertices: Vec<f64>,
    /// Three vertex indices per triangle, counter-clockwise from outside.
    pub indices: Vec<u32>,
}

/// A collision shape on a body.
#[derive(Debug, Clone, PartialEq)]
pub struct GeomPlan {
    /// The link it belongs to (index in the robot), for messages.
    pub link: usize,
    /// The shape.
    pub shape: ShapePlan,
    /// Pose of the shape's frame in the body frame (centre of mass).
    pub offset: Pose,
}

/// One rigid ODE body of the robot: one or more URDF links.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyPlan {
    /// The name of its first link, for messages.
    pub name: String,
    /// The first (root-most) link of the body.
    pub root_link: usize,
    /// All links of the body.
    pub links: Vec<usize>,
    /// Mass properties; `None` for a massless body (only allowed for a
    /// static base).
    pub mass: Option<MassPlan>,
    /// Centre of mass in the root link's frame, m (0 when massless).
    pub com_in_root_m: Vec3,
    /// Collision shapes.
    pub geoms: Vec<GeomPlan>,
    /// Whether the body has no ODE body (a static base): its shapes are
    /// fixed in the world.
    pub is_static: bool,
}

impl BodyPlan {
    /// The pose of the body frame (centre of mass) given the world pose of
    /// its root link frame.
    pub fn body_pose_from_root(&self, root_link_world: &Pose) -> Pose {
        root_link_world.compose(&translation(self.com_in_root_m))
    }

    /// The pose of a link frame on this body (`link_in_root`: the link in
    /// the root link's frame) relative to the body frame.
    pub fn link_in_body(&self, link_in_root: &Pose) -> Pose {
        translation(-self.com_in_root_m).compose(link_in_root)
    }
}

/// A controlled joint, as an ODE hinge.
#[derive(Debug, Clone, PartialEq)]
pub struct HingePlan {
    /// The joint's index in the robot.
    pub joint: usize,
    /// The body the joint moves (its child link's body).
    pub child_body: usize,
    /// The body it hangs on (its parent link's body).
    pub parent_body: usize,
    /// Lower and upper stops, rad, each within [-pi, pi]; `None` where the
    /// joint has no limit (or one ODE's hinge cannot express).
    pub stops_rad: (Option<f64>, Option<f64>),
    /// Viscous damping, N m s/rad.
    pub damping: f64,
    /// Coulomb friction torque, N m.
    pub friction_nm: f64,
    /// Servo gain, N m s/rad.
    pub kv: f64,
    /// Servo torque limit, N m (may be infinite).
    pub force_limit_nm: f64,
    /// Reflected rotor inertia on the joint axis, kg m^2 (the `armature`
    /// parameter; 0 when none).
    pub armature_kg_m2: f64,
}

impl HingePlan {
    /// The joint's passive row (viscous damping and armature) as one
    /// implicit ODE motor row, at timestep `h_s`: `(gain, inertial)` where
    /// the row's torque is `-gain * v_next + inertial * v_start` (N m, with
    /// the joint rates at the end and the start of the step). Damping `d`
    /// gives `-d v_next`; armature `a` gives `-a (v_next - v_start) / h`,
    /// minus the armature times the joint's angular acceleration. So `gain
    /// = d + a / h` and `inertial = a / h`. ODE realises the row as an
    /// angular motor with `dParamCFM = 1 / gain` and target velocity
    /// `inertial / gain * v_start` (its torque is `(v_target - v_next) /
    /// CFM`). `None` when the joint has neither.
    pub fn passive_row(&self, h_s: f64) -> Option<(f64, f64)> {
        let inertial = self.armature_kg_m2 / h_s;
        let gain = self.damping + inertial;
        (gain > 0.0 && gain.is_finite()).then_some((gain, inertial))
    }
}

/// Contact softness from the `[contact]` parameters: every contact between
/// two bodies behaves as a spring-damper with time constant `tc` and
/// damping ratio `zeta`, in MuJoCo's convention (its `solref`): for the
/// pair's effective mass `m`, stiffness `k = m / (zeta tc)^2` and damping
/// `c = 2 m / tc` (natural frequency `1 / (zeta tc)`, decay rate `1 / tc`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSoftness {
    /// Time constant, s.
    pub time_constant_s: f64,
    /// Damping ratio (1 = critically damped).
    pub damping_ratio: f64,
}

impl ContactSoftness {
    /// MuJoCo's default time constant (`solref` 0.02 s), used when only the
    /// damping ratio is given, s.
    pub const DEFAULT_TIME_CONSTANT_S: f64 = 0.02;
    /// MuJoCo's default damping ratio, used when only the time constant is
    /// given.
    pub const DEFAULT_DAMPING_RATIO: f64 = 1.0;

    /// ODE's soft ERP and the CFM of ONE contact point (kg^-1 s) for a pair
    /// of bodies with inverse masses summing to `inverse_mass` (1/kg; 0 for
    /// two immovable bodies: `None`) at timestep `h_s`.
    ///
    /// ODE integrates a constraint with error reduction ERP and force
    /// mixing CFM like an implicit spring-damper with `ERP = h k / (h k +
    /// c)` and `CFM = 1 / (h k + c)` (ODE manual, "how to use ERP and CFM").
    /// With `k` and `c` from the effective (reduced) mass `m = 1 /
    /// inverse_mass`: `ERP = h / (h + 2 zeta^2 tc)` and `CFM = 1 / (m (h /
    /// (zeta tc)^2 + 2 / tc))`. A pair touching at `n` points splits the
    /// spring and the damper between them (`k / n`, `c / n` each: the same
    /// ERP, `n` times the CFM), so the pair as a whole has the stiffness
    /// and damping above whatever the number of points.
    pub fn erp_cfm(&self, h_s: f64, inverse_mass: f64) -> Option<(f64, f64)> {
        if !(inverse_mass > 0.0 && inverse_mass.is_finite()) {
            return None;
        }
        let (tc, zeta) = (self.time_constant_s, self.damping_ratio);
        let k_per_mass = 1.0 / (zeta * tc).powi(2);
        let c_per_mass = 2.0 / tc;
        let erp = h_s * k_per_mass / (h_s * k_per_mass + c_per_mass);
        let cfm = inverse_mass / (h_s * k_per_mass + c_per_mass);
        Some((erp, cfm))
    }
}

/// A free object of the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectPlan {
    /// The object's name.
    pub name: String,
    /// Full box edges, m.
    pub size_m: Vec3,
    /// Mass (scaled by the variation).
    pub mass: MassPlan,
    /// Initial pose of its centre.
    pub pose: Pose,
    /// Friction coefficient (scene's or default, scaled).
    pub mu: f64,
    /// Coefficient of restitution (the `restitution` parameter), when set.
    pub restitution: Option<f64>,
}

/// What a tracked body follows on the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackedPlan {
    /// A link frame at `link_in_body` on robot body `body`.
    Link {
        /// Robot body index.
        body: usize,
        /// The link frame relative to the body frame.
        link_in_body: Pose,
    },
    /// Object `index` (its centre).
    Object(usize),
}

/// The whole model.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelPlan {
    /// Robot bodies; body 0 holds the root link.
    pub bodies: Vec<BodyPlan>,
    /// The body of every link (indexed like `robot.links`).
    pub body_of_link: Vec<usize>,
    /// Every link's frame relative to its body's root link frame.
    pub link_in_root: Vec<Pose>,
    /// One hinge per controlled joint, in the scene's actuator order.
    pub hinges: Vec<HingePlan>,
    /// Bodies held to their parent body by a fixed joint (child, parent),
    /// with `weld = "fixed_joint"`.
    pub welds: Vec<(usize, usize)>,
    /// Free objects, in scene order.
    pub objects: Vec<ObjectPlan>,
    /// Ground height, m, and friction, when there is a ground.
    pub ground: Option<(f64, f64)>,
    /// Friction coefficient of the robot's surfaces.
    pub robot_mu: f64,
    /// Tracked bodies, in scene order.
    pub tracked: Vec<TrackedPlan>,
    /// Joint positions (indexed like `robot.joints`) of the initial
    /// configuration: controlled joints 0, held joints at their positions.
    pub initial_positions: Vec<f64>,
    /// Gravity in the world frame, m/s^2 (the scene's).
    pub gravity_m_s2: Vec3,
    /// Contact softness (the `[contact]` parameters), when set; else the
    /// world ERP and CFM apply to contacts.
    pub contact_softness: Option<ContactSoftness>,
}

/// Reads an STL mesh, scales it, and welds equal vertices.
pub fn mesh_plan(
    path: &std::path::Path,
    uri: &str,
    scale: Vec3,
    link_name: &str,
) -> Result<MeshPlan, PlanError> {
    realitygap_core::robot::stl::require_mesh_format(path, uri, "ODE")
        .map_err(|e| PlanError(format!("link \"{link_name}\": {e}")))?;
    let mesh =
        TriangleMesh::read(path).map_err(|e| PlanError(format!("link \"{link_name}\": {e}")))?;
    if mesh.triangles.is_empty() {
        return Err(PlanError(format!(
            "link \"{link_name}\": mesh {} has no triangles",
            path.display()
        )));
    }
    if !(scale.x != 0.0 && scale.y != 0.0 && scale.z != 0.0 && scale.is_finite()) {
        return Err(PlanError(format!(
            "link \"{link_name}\": mesh \"{uri}\" has a zero or non-finite scale"
        )));
    }
    // A mirroring scale turns the triangles inside out: swap two corners.
    let mirrored = scale.x * scale.y * scale.z < 0.0;
    let mut index_of: HashMap<[u64; 3], u32> = HashMap::new();
    let mut vertices: Vec<f64> = Vec::new();
    let mut indices: Vec<u32> = Vec::with_capacity(mesh.triangles.len() * 3);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let corners = if mirrored {
            [tri[0], tri[2], tri[1]]
        } else {
            *tri
        };
        let mut ids = [0u32; 3];
        for (id, v) in ids.iter_mut().zip(corners) {
            let s = Vec3::new(v.x * scale.x, v.y * scale.y, v.z * scale.z);
            if !s.is_finite() {
                return Err(PlanError(format!(
                    "link \"{link_name}\": mesh {} triangle {t} has a non-finite vertex",
                    path.display()
                )));
            }
            // +0.0 and -0.0 are the same vertex.
            let key = [
                (s.x + 0.0).to_bits(),
                (s.y + 0.0).to_bits(),
                (s.z + 0.0).to_bits(),
            ];
            let next = (vertices.len() / 3) as u32;
            *id = *index_of.entry(key).or_insert_with(|| {
                vertices.extend_from_slice(&[s.x, s.y, s.z]);
                next
            });
        }
        // Degenerate triangles (two equal corners) carry no surface.
        if ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2] {
            indices.extend_from_slice(&ids);
        }
    }
    if indices.is_empty() {
        return Err(PlanError(format!(
            "link \"{link_name}\": mesh {} has only degenerate triangles",
            path.display()
        )));
    }
    if vertices.len() / 3 > i32::MAX as usize || indices.len() > i32::MAX as usize {
        return Err(PlanError(format!(
            "link \"{link_name}\": mesh {} is too large for ODE",
            path.display()
        )));
    }
    Ok(MeshPlan {
        uri: uri.to_string(),
        vertices,
        indices,
    })
}

fn shape_plan(geometry: &Geometry, link_name: &str) -> Result<ShapePlan, PlanError> {
    let positive = |what: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(PlanError(format!(
                "link \"{link_name}\": collision {what} must be positive and finite, found {v}"
            )))
        }
    };
    Ok(match geometry {
        Geometry::Box { size_m } => ShapePlan::Box(Vec3::new(
            positive("box size", size_m.x)?,
            positive("box size", size_m.y)?,
            positive("box size", size_m.z)?,
        )),
        Geometry::Sphere { radius_m } => ShapePlan::Sphere(positive("sphere radius", *radius_m)?),
        Geometry::Cylinder { radius_m, length_m } => ShapePlan::Cylinder(
            positive("cylinder radius", *radius_m)?,
            positive("cylinder length", *length_m)?,
        ),
        Geometry::Capsule { radius_m, length_m } => {
            let length = if *length_m == 0.0 {
                0.0
            } else {
                positive("capsule length", *length_m)?
            };
            ShapePlan::Capsule(positive("capsule radius", *radius_m)?, length)
        }
        Geometry::Mesh { path, uri, scale } => {
            ShapePlan::Mesh(mesh_plan(path, uri, *scale, link_name)?)
        }
    })
}

/// Combines point masses with inertias (position, mass, inertia about its
/// own centre in common axes) into total mass, centre and inertia about
/// that centre (the shared [`shared::combine_masses`]). `None` when the
/// total mass is 0.
pub fn combine_masses(parts: &[shared::MassPart]) -> Option<(MassPlan, Vec3)> {
    shared::combine_masses(parts).map(|m| {
        (
            MassPlan {
                mass_kg: m.mass_kg,
                inertia: m.inertia_kg_m2,
            },
            m.com_m,
        )
    })
}

/// Works out the ODE model of `scene` with `robot` (validated against the
/// scene), configured by `settings` and changed by `variation`. The rigid
/// groups, their masses and the scene's names come from core's shared
/// planning ([`realitygap_core::robot::plan`]).
pub fn plan(
    scene: &Scene,
    robot: &RobotModel,
    settings: &OdeSettings,
    variation: &ModelVariation,
) -> Result<ModelPlan, PlanError> {
    let actuated = actuated_joints(scene, robot)?;
    check_variation(variation)?;
    let initial_positions =
        shared::initial_positions(scene, robot, &actuated).map_err(|e| PlanError(e.0))?;
    let split = match settings.weld {
        Weld::FixedJoint => GroupSplit::AlsoAtLinksWithMass,
        Weld::Merge => GroupSplit::AtActuatedJoints,
    };
    let groups = shared::rigid_groups(robot, &actuated, &initial_positions, split);
    let welds = groups
        .groups
        .iter()
        .enumerate()
        .filter_map(|(b, g)| g.parent.filter(|_| g.welded).map(|(_, parent)| (b, parent)))
        .collect();
    let parts = Parts {
        robot,
        body_of_link: &groups.group_of_link,
        link_in_root: &groups.link_in_group,
    };
    let bodies = groups
        .groups
        .iter()
        .enumerate()
        .map(|(b, g)| parts.body(b, g, settings, variation))
        .collect::<Result<Vec<_>, _>>()?;
    let hinges = hinge_plans(scene, robot, &actuated, &groups.group_of_link);
    let friction = |f: Option<f64>| f.unwrap_or(settings.contact_mu) * variation.friction_scale;
    let objects = object_plans(scene, variation, &friction);
    let tracked = tracked_plans(scene, &parts, &bodies)?;
    Ok(ModelPlan {
        bodies,
        body_of_link: groups.group_of_link,
        link_in_root: groups.link_in_group,
        hinges,
        welds,
        objects,
        ground: scene.ground.map(|g| (g.height_m, friction(g.friction))),
        robot_mu: friction(None),
        tracked,
        initial_positions,
        gravity_m_s2: scene.gravity_m_s2,
        contact_softness: None,
    })
}

/// The controlled joints (actuator order, resolved by core), which must be
/// revolute or continuous.
fn actuated_joints(scene: &Scene, robot: &RobotModel) -> Result<Vec<usize>, PlanError> {
    let actuated = shared::actuated_joints(scene, robot).map_err(|e| PlanError(e.0))?;
    for &j in &actuated {
        let joint = &robot.joints[j];
        if !matches!(joint.kind, JointKind::Revolute | JointKind::Continuous) {
            return Err(PlanError(format!(
                "joint \"{}\" is {}; the ODE engine drives revolute and continuous joints only",
                joint.name, joint.kind
            )));
        }
    }
    Ok(actuated)
}

fn check_variation(variation: &ModelVariation) -> Result<(), PlanError> {
    let usable = variation.mass_scale.is_finite()
        && variation.mass_scale > 0.0
        && variation.friction_scale.is_finite()
        && variation.friction_scale >= 0.0;
    if !usable {
        return Err(PlanError(format!(
            "the model variation must scale masses by a positive and friction by a non-negative factor, found {} and {}",
            variation.mass_scale, variation.friction_scale
        )));
    }
    Ok(())
}

/// The robot and how its links are grouped into bodies.
struct Parts<'a> {
    robot: &'a RobotModel,
    body_of_link: &'a [usize],
    link_in_root: &'a [Pose],
}

impl Parts<'_> {
    /// Body `b` (rigid group `group`): merged mass, centre and inertia, and
    /// its shapes, its links in index order.
    fn body(
        &self,
        b: usize,
        group: &shared::RigidGroup,
        settings: &OdeSettings,
        variation: &ModelVariation,
    ) -> Result<BodyPlan, PlanError> {
        let robot = self.robot;
        let root = group.top_link;
        let mut links = group.links.clone();
        links.sort_unstable();
        let parts = shared::link_mass_parts(robot, &links, self.link_in_root, variation.mass_scale);
        let (mass, com) = match combine_masses(&parts) {
            Some((m, c)) => (Some(m), c),
            None => (None, Vec3::ZERO),
        };
        let is_static = b == 0 && (settings.base == Base::Static || mass.is_none());
        self.check_mass(&links, root, mass.as_ref(), is_static)?;
        let body = BodyPlan {
            name: robot.links[root].name.clone(),
            root_link: root,
            links: links.clone(),
            mass,
            com_in_root_m: com,
            geoms: Vec::new(),
            is_static,
        };
        let mut geoms = Vec::new();
        for &l in &links {
            for c in &robot.links[l].collisions {
                let shape = shape_plan(&c.geometry, &robot.links[l].name)?;
                let offset = body.link_in_body(&self.link_in_root[l]).compose(&c.origin);
                geoms.push(GeomPlan {
                    link: l,
                    shape,
                    offset,
                });
            }
        }
        Ok(BodyPlan { geoms, ..body })
    }

    /// A moving body needs a mass and a positive definite inertia.
    fn check_mass(
        &self,
        links: &[usize],
        root: usize,
        mass: Option<&MassPlan>,
        is_static: bool,
    ) -> Result<(), PlanError> {
        let robot = self.robot;
        let link_names = || {
            links
                .iter()
                .map(|&l| robot.links[l].name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        if let Some(m) = mass {
            if !is_static && !is_positive_definite(&m.inertia) {
                return Err(PlanError(format!(
                    "the links {} (one rigid body) have an inertia that is not positive definite ({:?} kg m^2); ODE cannot integrate it",
                    link_names(),
                    m.inertia
                )));
            }
        } else if !is_static {
            let joint = robot
                .parent_joint(root)
                .map(|j| robot.joints[j].name.as_str())
                .unwrap_or("?");
            return Err(PlanError(format!(
                "the links {} moved by joint \"{joint}\" have no mass (no <inertial>); ODE cannot simulate a massless moving body",
                link_names()
            )));
        }
        Ok(())
    }
}

/// One hinge per controlled joint (actuator order), with the URDF limits
/// ODE's hinge can express as stops.
fn hinge_plans(
    scene: &Scene,
    robot: &RobotModel,
    actuated: &[usize],
    body_of_link: &[usize],
) -> Vec<HingePlan> {
    let mut hinges = Vec::with_capacity(actuated.len());
    for (a, &j) in scene.actuators.iter().zip(actuated) {
        let joint = &robot.joints[j];
        let mut stops = (None, None);
        if let Some(lim) = joint.limits {
            if lim.lower.is_finite() && lim.lower >= -PI {
                stops.0 = Some(lim.lower);
            }
            if lim.upper.is_finite() && lim.upper <= PI {
                stops.1 = Some(lim.upper);
            }
        }
        hinges.push(HingePlan {
            joint: j,
            child_body: body_of_link[joint.child],
            parent_body: body_of_link[joint.parent],
            stops_rad: stops,
            damping: joint.damping,
            friction_nm: joint.friction,
            kv: a.kv,
            force_limit_nm: a.force_limit,
            armature_kg_m2: 0.0,
        });
    }
    hinges
}

/// The scene's objects (masses scaled, friction from `friction`).
fn object_plans(
    scene: &Scene,
    variation: &ModelVariation,
    friction: &dyn Fn(Option<f64>) -> f64,
) -> Vec<ObjectPlan> {
    scene
        .objects
        .iter()
        .map(|o| {
            let ObjectShape::Box { size_m } = o.shape;
            let p = o.principal_inertia();
            let s = variation.mass_scale;
            ObjectPlan {
                name: o.name.clone(),
                size_m,
                mass: MassPlan {
                    mass_kg: o.mass_kg * s,
                    inertia: [p.x * s, 0.0, 0.0, 0.0, p.y * s, 0.0, 0.0, 0.0, p.z * s],
                },
                pose: o.pose,
                mu: friction(o.friction),
                restitution: None,
            }
        })
        .collect()
}

/// What each of the scene's tracked bodies follows on the model.
fn tracked_plans(
    scene: &Scene,
    parts: &Parts<'_>,
    bodies: &[BodyPlan],
) -> Result<Vec<TrackedPlan>, PlanError> {
    let targets = shared::tracked_targets(scene, parts.robot).map_err(|e| PlanError(e.0))?;
    Ok(targets
        .into_iter()
        .map(|t| match t {
            TrackedRef::Link(l) => {
                let b = parts.body_of_link[l];
                TrackedPlan::Link {
                    body: b,
                    link_in_body: bodies[b].link_in_body(&parts.link_in_root[l]),
                }
            }
            TrackedRef::Object(i) => TrackedPlan::Object(i),
        })
        .collect())
}

impl ModelPlan {
    /// World poses of the robot bodies' frames (centres of mass) with the
    /// controlled joints at `angles_rad` (actuator order) and the base at
    /// `base`.
    pub fn body_poses(&self, robot: &RobotModel, base: &Pose, angles_rad: &[f64]) -> Vec<Pose> {
        let mut positions = self.initial_positions.clone();
        for (h, &a) in self.hinges.iter().zip(angles_rad) {
            positions[h.joint] = a;
        }
        let world = robot.forward_kinematics(base, &positions);
        self.bodies
            .iter()
            .map(|b| b.body_pose_from_root(&world[b.root_link]))
            .collect()
    }

    /// World velocities of the robot bodies (linear velocity of each body's
    /// centre of mass, m/s, and angular velocity, rad/s) with the
    /// controlled joints at `angles_rad` turning at `rates_rad_s` (actuator
    /// order), the base at rest at `base` and held joints still.
    ///
    /// Propagated down the tree: a child link turns with its parent plus
    /// the joint rate about the joint's world axis, `w_c = w_p + axis q'`;
    /// its frame origin lies on the joint axis, so it moves with the
    /// parent's rigid motion, `v_c = v_p + w_p x (p_c - p_p)`; a body's
    /// centre of mass moves as `v_root + w x (com - p_root)`.
    pub fn body_twists(
        &self,
        robot: &RobotModel,
        base: &Pose,
        angles_rad: &[f64],
        rates_rad_s: &[f64],
    ) -> Vec<(Vec3, Vec3)> {
        let mut positions = self.initial_positions.clone();
        let mut rates = vec![0.0; robot.joints.len()];
        for ((h, &a), &r) in self.hinges.iter().zip(angles_rad).zip(rates_rad_s) {
            positions[h.joint] = a;
            rates[h.joint] = r;
        }
        let world = robot.forward_kinematics(base, &positions);
        let mut lin = vec![Vec3::ZERO; robot.links.len()];
        let mut ang = vec![Vec3::ZERO; robot.links.len()];
        for &j in robot.joints_in_tree_order() {
            let joint = &robot.joints[j];
            let (p, c) = (joint.parent, joint.child);
            let r = world[c].position_m - world[p].position_m;
            let axis = world[c].orientation.rotate(joint.axis);
            ang[c] = ang[p] + axis.scale(rates[j]);
            lin[c] = lin[p] + ang[p].cross(r);
        }
        self.bodies
            .iter()
            .map(|b| {
                let root = &world[b.root_link];
                let com = b.body_pose_from_root(root).position_m;
                let w = ang[b.root_link];
                (lin[b.root_link] + w.cross(com - root.position_m), w)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_stl(dir: &std::path::Path, name: &str, tris: &[[[f32; 3]; 3]]) -> std::path::PathBuf {
        let mut b = vec![0u8; 80];
        b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
        for t in tris {
            b.extend_from_slice(&[0u8; 12]);
            for v in t {
                for c in v {
                    b.extend_from_slice(&c.to_le_bytes());
                }
            }
            b.extend_from_slice(&[0u8; 2]);
        }
        let p = dir.join(name);
        std::fs::write(&p, b).unwrap();
        p
    }

    #[test]
    fn meshes_are_welded_scaled_and_checked() {
        let dir = std::env::temp_dir().join(format!("realitygap-ode-plan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Two triangles sharing an edge, and one degenerate triangle.
        let p = write_stl(
            &dir,
            "quad.stl",
            &[
                [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
                [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
                [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            ],
        );
        let m = mesh_plan(&p, "quad.stl", Vec3::new(2.0, 1.0, 1.0), "l").unwrap();
        assert_eq!(m.vertices.len(), 4 * 3);
        assert_eq!(m.indices, vec![0, 1, 2, 0, 2, 3]);
        assert_eq!(m.vertices[3], 2.0);
        // A mirroring scale keeps the outside out.
        let m = mesh_plan(&p, "quad.stl", Vec3::new(-1.0, 1.0, 1.0), "l").unwrap();
        assert_eq!(&m.indices[..3], &[0, 1, 2]);
        assert_eq!(&m.vertices[3..6], &[-1.0, 1.0, 0.0]);
        let e = mesh_plan(&p, "quad.stl", Vec3::new(0.0, 1.0, 1.0), "l").unwrap_err();
        assert!(e.0.contains("zero or non-finite scale"), "{}", e.0);
        let bad = dir.join("quad.dae");
        std::fs::write(&bad, "<COLLADA/>").unwrap();
        let e = mesh_plan(
            &bad,
            "package://x/quad.dae",
            Vec3::new(1.0, 1.0, 1.0),
            "hand",
        )
        .unwrap_err();
        assert!(
            e.0.contains("link \"hand\"") && e.0.contains("not a valid COLLADA mesh"),
            "{}",
            e.0
        );
        let broken = dir.join("broken.stl");
        std::fs::write(
            &broken,
            b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0\n",
        )
        .unwrap();
        let e = mesh_plan(&broken, "broken.stl", Vec3::new(1.0, 1.0, 1.0), "hand").unwrap_err();
        assert!(e.0.contains("broken.stl"), "{}", e.0);
        std::fs::remove_dir_all(&dir).ok();
    }
}
