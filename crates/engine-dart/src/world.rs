//! Assembly: a [`Scene`] and its [`RobotModel`] become a DART world, built
//! through the C++ shim (`shim/dart_shim.cc`, reached through `src/ffi.rs`).
//!
//! 1. **Groups.** Core's shared planning ([`realitygap_core::robot::plan`])
//!    splits the robot's links into rigid groups: a group starts at the
//!    root link and below every controlled joint and takes in every link
//!    reached through fixed, held and mimic joints, at their fixed or held
//!    positions. Each group is one DART body node whose frame is its top
//!    link's frame, with the groups' merged URDF mass properties
//!    ([`shared::group_mass`]: mass, centre of mass and full inertia about
//!    it). The same masses, merged joints and held joints as the ODE,
//!    Rapier and PhysX engines, and no URDF loader of DART's own.
//! 2. **Joints.** The root group hangs on the world by a weld joint at the
//!    scene's base pose. Every controlled joint is a DART revolute joint
//!    (prismatic for a URDF prismatic joint) from the parent group's frame
//!    (the parent link's pose in its group composed with the URDF joint
//!    origin) to the child group's frame, about the URDF axis, with the
//!    URDF position limits enforced (DART's joint limit constraint; none
//!    for continuous joints) and the URDF dry friction as DART's joint
//!    Coulomb friction. Every controlled joint has DART's FORCE actuator
//!    (or SERVO, see [`crate::settings::Servo`]).
//! 3. **Shapes.** Every URDF `<collision>` of every member link: box,
//!    sphere, cylinder and capsule as DART's shapes; meshes (STL, OBJ,
//!    COLLADA, read by core's [`TriangleMesh`], scaled, equal vertices
//!    welded) as DART `MeshShape`s of their triangles, an aiScene built by
//!    the shim. Robot shapes have friction 1 (DART's default) and
//!    restitution 0; links do not collide with each other (DART's
//!    default: no self-collision).
//! 4. **World.** The ground is a static 20 m x 20 m box, 1 m thick, whose
//!    top face is at the ground's height (a box collides in every
//!    detector; DART's plane shape does not); each scene object is a
//!    skeleton of one body on a free joint, a uniform box. Gravity, the
//!    timestep, the collision detector and the LCP solver are the scene's
//!    and the settings'.
//!
//! The servo laws ([`JointModel::drive`]) run before every step on the
//! state DART reports.

use crate::ffi;
use crate::ffi::UniquePtr;
use crate::settings::{DartSettings, Detector, Servo};
use realitygap_core::engine::{CommandKind, ModelVariation, ServoCommand};
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::plan::{self as shared, GroupSplit, TrackedRef};
use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::{Geometry, JointKind, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene};
use std::collections::HashMap;

/// Friction of every robot shape and of the ground and objects when the
/// scene gives none (DART's default coefficient).
pub const DEFAULT_FRICTION: f64 = 1.0;

/// The lightest moving body DART is given, kg. Debian's DART 6.12 keeps
/// its assertions: the constraint solver asserts that its LCP matrix is
/// symmetric to an absolute 1e-6, and the matrix of a contact on a body of
/// 1e-300 kg (entries of 1/mass) fails that from rounding and aborts the
/// process. Lighter bodies are refused before DART sees them.
pub const MIN_MASS_KG: f64 = 1e-6;

/// A controlled joint's servo and passive terms.
#[derive(Debug, Clone)]
pub struct JointModel {
    /// The URDF joint's name.
    pub name: String,
    /// Velocity gain, N m s/rad.
    pub kv: f64,
    /// Position gain, N m/rad (0 when the scene gives none).
    pub kp: f64,
    /// Force limit, N m (0: servo off; may be infinite).
    pub force_limit: f64,
    /// Viscous damping, N m s/rad.
    pub damping: f64,
    /// Reflected rotor inertia, kg m^2.
    pub armature: f64,
}

/// What one controlled joint gets before a step: the actuator's command
/// (torque, or velocity for a SERVO actuator), the joint's damping
/// coefficient, spring stiffness and rest position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Actuator command.
    pub command: f64,
    /// Damping coefficient, N m s/rad.
    pub damping: f64,
    /// Spring stiffness, N m/rad.
    pub stiffness: f64,
    /// Spring rest position, rad.
    pub rest: f64,
}

impl JointModel {
    /// The drive of this joint for `command` at angle `q` and rate `v`,
    /// timestep `h` (see the README's servo table). DART integrates the
    /// joint's damping `D` and spring `K` implicitly: the joint force is
    /// `command - K (q_next - rest) - D v_next` with `v_next = v + h a` and
    /// `q_next = q + h v_next`. So:
    /// - velocity (`servo = "kv"`): damping `kv`, command `kv v_target`:
    ///   `kv (v_target - v_next)`;
    /// - position: stiffness `kp`, rest the target, damping `kv`:
    ///   `kp (target - q_next) - kv v_next`;
    /// - effort: the command.
    ///
    /// When the law's torque at the step's start (`kv (v_target - v)`, `kp
    /// (target - q) - kv v`) is beyond the force limit, the drive is the
    /// limit with that sign instead (explicit); with the limit 0 the servo
    /// is off. The joint's own damping adds to the damping. Armature `a`:
    /// damping `a/h` adds `a` to the joint's projected inertia in DART's
    /// implicit step, and the command `+ (a/h) v` cancels that damping's
    /// force: what remains is `a` times the joint's acceleration.
    /// `servo_actuator`: the joint has DART's SERVO actuator (velocity
    /// commands with `servo = "servo"`): the command is the target
    /// velocity.
    pub fn drive(
        &self,
        command: ServoCommand,
        q: f64,
        v: f64,
        h: f64,
        servo_actuator: bool,
    ) -> Drive {
        let limit = self.force_limit;
        let mut d = Drive {
            command: 0.0,
            damping: self.damping,
            stiffness: 0.0,
            rest: 0.0,
        };
        let target = command.value;
        match command.kind {
            CommandKind::Velocity if servo_actuator => {
                d.command = target;
                return d;
            }
            CommandKind::Velocity => {
                let explicit = self.kv * (target - v);
                if limit > 0.0 {
                    if explicit.abs() <= limit {
                        d.command = self.kv * target;
                        d.damping += self.kv;
                    } else {
                        d.command = limit.copysign(explicit);
                    }
                }
            }
            CommandKind::Position => {
                let explicit = self.kp * (target - q) - self.kv * v;
                if limit > 0.0 {
                    if explicit.abs() <= limit {
                        d.stiffness = self.kp;
                        d.rest = target;
                        d.damping += self.kv;
                    } else {
                        d.command = limit.copysign(explicit);
                    }
                }
            }
            CommandKind::Effort => d.command = target.clamp(-limit, limit),
        }
        if self.armature > 0.0 {
            let inertial = self.armature / h;
            d.damping += inertial;
            d.command += inertial * v;
        }
        d
    }
}

/// What a tracked body follows: a robot body and the link frame on it, or
/// an object.
#[derive(Debug, Clone, Copy)]
pub enum Tracked {
    /// Robot body `body`, frame `offset` on it.
    Link {
        /// Body index.
        body: usize,
        /// The link frame in the body frame.
        offset: Pose,
    },
    /// Object `i`.
    Object(usize),
}

/// A built DART world and what the simulation needs of it. Dropping it
/// destroys the DART objects (under the ODE lock with the ODE detector).
pub struct World {
    world: UniquePtr<ffi::World>,
    /// Whether DART's ODE collision detector is in use (its calls then
    /// hold the ODE engine's process-wide lock).
    pub uses_ode: bool,
    /// The controlled joints, in the scene's actuator order.
    pub joints: Vec<JointModel>,
    /// Tracked frames, in the scene's order.
    pub tracked: Vec<Tracked>,
    /// Every URDF link's body and frame on it, by name.
    pub links: HashMap<String, (usize, Pose)>,
    /// The objects' names, in the scene's order.
    pub objects: Vec<String>,
}

// SAFETY: a DART world, its skeletons and its collision detector belong to
// this value alone; DART keeps no per-thread state for them, the shim's
// message capture is per thread, and the ODE detector's process-wide
// caches are used only under the ODE engine's lock (see `ode_guard`).
unsafe impl Send for ffi::World {}

impl Drop for World {
    fn drop(&mut self) {
        let _guard = ode_guard(self.uses_ode);
        self.world = UniquePtr::null();
        forward_messages();
    }
}

/// The ODE engine's process-wide lock when DART's ODE collision detector is
/// in use (ODE 0.16's collision caches are not thread safe, and the ODE
/// engine uses the same library).
pub fn ode_guard(uses_ode: bool) -> Option<realitygap_engine_ode::world::OdeGuard> {
    uses_ode.then(realitygap_engine_ode::world::ode_lock)
}

/// Passes what DART printed on this thread to the `log` crate, and returns
/// it.
pub fn forward_messages() -> String {
    let raw = ffi::take_messages();
    if raw.is_empty() {
        return String::new();
    }
    // DART colours its messages with ANSI escapes (ESC [ ... m).
    let mut plain = String::with_capacity(raw.len());
    let mut chars = raw.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for d in chars.by_ref() {
                if d.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            plain.push(c);
        }
    }
    let said = plain.trim();
    if !said.is_empty() {
        log::warn!("DART: {said}");
    }
    said.to_string()
}

/// `p` as the shim's 7 numbers.
pub fn pose7(p: &Pose) -> [f64; 7] {
    let q = p.orientation;
    [
        p.position_m.x,
        p.position_m.y,
        p.position_m.z,
        q.w,
        q.x,
        q.y,
        q.z,
    ]
}

/// The shim's 7 numbers as a pose.
pub fn from7(v: &[f64]) -> Pose {
    Pose::new(
        Vec3::new(v[0], v[1], v[2]),
        Quat::new(v[3], v[4], v[5], v[6]),
    )
}

fn vec3(v: Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Everything a world is built from.
pub struct Recipe<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The robot (validated against the scene).
    pub robot: &'a RobotModel,
    /// The checked settings.
    pub settings: &'a DartSettings,
    /// The model variation.
    pub variation: &'a ModelVariation,
    /// The physical parameters (checked by [`crate::params::check`]).
    pub params: &'a PhysicalParams,
}

/// A mesh's vertices (x y z each) and triangles (three indices each):
/// scaled, equal vertices welded, degenerate triangles dropped, a
/// mirroring scale's triangles turned back outside out.
pub fn mesh_triangles(
    path: &std::path::Path,
    uri: &str,
    scale: Vec3,
) -> Result<(Vec<f64>, Vec<u32>), String> {
    realitygap_core::robot::stl::require_mesh_format(path, uri, "DART")?;
    let mesh = TriangleMesh::read(path).map_err(|e| e.to_string())?;
    if !(scale.x != 0.0 && scale.y != 0.0 && scale.z != 0.0 && scale.is_finite()) {
        return Err(format!("mesh \"{uri}\" has a zero or non-finite scale"));
    }
    let mirrored = scale.x * scale.y * scale.z < 0.0;
    let mut index_of: HashMap<[u64; 3], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut indices = Vec::with_capacity(mesh.triangles.len() * 3);
    for tri in &mesh.triangles {
        let corners = if mirrored {
            [tri[0], tri[2], tri[1]]
        } else {
            *tri
        };
        let mut ids = [0u32; 3];
        for (id, v) in ids.iter_mut().zip(corners) {
            let s = Vec3::new(v.x * scale.x, v.y * scale.y, v.z * scale.z);
            if !s.is_finite() {
                return Err(format!("mesh {} has a non-finite vertex", path.display()));
            }
            let key = [
                (s.x + 0.0).to_bits(),
                (s.y + 0.0).to_bits(),
                (s.z + 0.0).to_bits(),
            ];
            let next = u32::try_from(vertices.len() / 3)
                .map_err(|_| format!("mesh {} is too large", path.display()))?;
            *id = *index_of.entry(key).or_insert_with(|| {
                vertices.extend_from_slice(&[s.x, s.y, s.z]);
                next
            });
        }
        if ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2] {
            indices.extend_from_slice(&ids);
        }
    }
    if indices.is_empty() {
        return Err(format!(
            "mesh {} has no triangle with an area",
            path.display()
        ));
    }
    Ok((vertices, indices))
}

fn positive(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be positive and finite, found {v}"))
    }
}

fn nonnegative(what: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be >= 0 and finite, found {v}"))
    }
}

/// Builds the world of a recipe (see the module documentation). Errors
/// are messages for [`realitygap_core::EngineError::Load`].
pub fn build(recipe: &Recipe<'_>) -> Result<World, String> {
    recipe.variation.check()?;
    shared::check_servos(recipe.scene).map_err(|e| e.0)?;
    let scene = recipe.scene;
    let robot = recipe.robot;
    let settings = recipe.settings;
    let plan = shared::plan_robot(scene, robot, GroupSplit::AtActuatedJoints).map_err(|e| e.0)?;
    let uses_ode = settings.detector == Detector::Ode;
    if uses_ode {
        realitygap_engine_ode::install_message_handler();
    }
    let _guard = ode_guard(uses_ode);
    let friction_scale = recipe.variation.friction_scale;
    let mass_scale = recipe.variation.mass_scale;
    let created = ffi::new_world(
        settings.timestep_s,
        &vec3(scene.gravity_m_s2),
        settings.detector.name(),
        settings.lcp.name(),
    )
    .map_err(|e| e.what().to_string())?;
    let mut world = World {
        world: created,
        uses_ode,
        joints: Vec::new(),
        tracked: Vec::new(),
        links: HashMap::new(),
        objects: Vec::new(),
    };
    let groups = &plan.groups;
    // Stage 1 and 2: one body per group, parents first.
    let mut joint_of_group: HashMap<usize, usize> = HashMap::new();
    for (g, group) in groups.groups.iter().enumerate() {
        let top = &robot.links[group.top_link].name;
        let merged = shared::group_mass(robot, &group.links, &groups.link_in_group, mass_scale);
        let (mass, com, inertia) = match (g, merged) {
            (_, Some(m)) => (m.mass_kg, m.com_m, m.inertia_kg_m2),
            // The base is welded to the world: its mass moves nothing, but
            // DART wants one.
            (0, None) => (1.0, Vec3::ZERO, [1e-3, 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, 0.0, 1e-3]),
            (_, None) => {
                return Err(format!(
                    "link \"{top}\" and the links fixed to it have no mass; a moving body needs a positive mass \
                     (give it an <inertial> in {})",
                    robot.source.display()
                ))
            }
        };
        if g > 0 && mass < MIN_MASS_KG {
            return Err(format!(
                "link \"{top}\" and the links fixed to it weigh {mass:e} kg, below the {MIN_MASS_KG:e} kg DART is \
                 given (its constraint solver's symmetry assertion aborts the process on lighter bodies; check the \
                 <inertial> masses in {} and links.<link>.mass_scale)",
                robot.source.display()
            ));
        }
        if g > 0 && !(mass.is_finite() && mass > 0.0 && shared::is_positive_definite(&inertia)) {
            return Err(format!(
                "link \"{top}\" and the links fixed to it: mass {mass} kg and inertia {inertia:?} kg m^2 are not a \
                 positive mass with a positive-definite inertia, which DART needs on every moving body (check the \
                 <inertial> values in {} and the mass parameters)",
                robot.source.display()
            ));
        }
        let (parent, kind, joint_pose, axis) = match group.parent {
            None => (-1i64, 0u8, scene.robot.base, Vec3::new(0.0, 0.0, 1.0)),
            Some((j, pg)) => {
                let joint = &robot.joints[j];
                let kind = match joint.kind {
                    JointKind::Revolute | JointKind::Continuous => 1,
                    JointKind::Prismatic => 2,
                    JointKind::Fixed => {
                        return Err(format!(
                            "joint \"{}\" is fixed and cannot be driven",
                            joint.name
                        ))
                    }
                };
                let at = groups.link_in_group[joint.parent].compose(&joint.origin);
                (pg as i64, kind, at, joint.axis)
            }
        };
        let body = world
            .world
            .get_mut()
            .add_robot_body(
                top,
                parent,
                kind,
                &pose7(&joint_pose),
                &vec3(axis),
                mass,
                &vec3(com),
                &inertia,
            )
            .map_err(|e| format!("link \"{top}\": {}", e.what()))?;
        debug_assert_eq!(body, g);
        if kind != 0 {
            joint_of_group.insert(g, joint_of_group.len());
        }
        // Stage 3: the group's shapes.
        for &l in &group.links {
            let link = &robot.links[l];
            for (c, collision) in link.collisions.iter().enumerate() {
                let at = pose7(&groups.link_in_group[l].compose(&collision.origin));
                let context =
                    |e: String| format!("link \"{}\", collision {}: {e}", link.name, c + 1);
                let mu = DEFAULT_FRICTION * friction_scale;
                let primitive = |kind: u8, dims: Vec<f64>| (kind, dims);
                if settings.detector == Detector::Dart
                    && !matches!(collision.geometry, Geometry::Box { .. })
                {
                    return Err(context(
                        "DART's own collision detector (collision_detector = \"dart\") collides boxes only \
                         (it ignores spheres, cylinders, capsules and meshes, saying so at every step); use \
                         ode, fcl or bullet"
                            .to_string(),
                    ));
                }
                let shape = match &collision.geometry {
                    Geometry::Box { size_m } => primitive(
                        0,
                        vec![
                            positive("box size", size_m.x).map_err(context)?,
                            positive("box size", size_m.y).map_err(context)?,
                            positive("box size", size_m.z).map_err(context)?,
                        ],
                    ),
                    Geometry::Sphere { radius_m } => primitive(
                        1,
                        vec![positive("sphere radius", *radius_m).map_err(context)?],
                    ),
                    Geometry::Cylinder { radius_m, length_m } => primitive(
                        2,
                        vec![
                            positive("cylinder radius", *radius_m).map_err(context)?,
                            positive("cylinder length", *length_m).map_err(context)?,
                        ],
                    ),
                    Geometry::Capsule { radius_m, length_m } => primitive(
                        3,
                        vec![
                            positive("capsule radius", *radius_m).map_err(context)?,
                            nonnegative("capsule length", *length_m).map_err(context)?,
                        ],
                    ),
                    Geometry::Mesh { path, uri, scale } => {
                        let (vertices, indices) =
                            mesh_triangles(path, uri, *scale).map_err(context)?;
                        world
                            .world
                            .get_mut()
                            .add_mesh(g, &vertices, &indices, &at, mu)
                            .map_err(|e| context(e.what().to_string()))?;
                        continue;
                    }
                };
                world
                    .world
                    .get_mut()
                    .add_shape(false, g, shape.0, &shape.1, &at, mu, 0.0)
                    .map_err(|e| context(e.what().to_string()))?;
            }
        }
    }
    // The controlled joints' limits, friction, actuators.
    for (i, (spec, &j)) in scene.actuators.iter().zip(&plan.actuated).enumerate() {
        let joint = &robot.joints[j];
        let g = plan.groups.group_of_link[joint.child];
        debug_assert_eq!(joint_of_group.get(&g), Some(&i));
        let context = |e: String| format!("joint \"{}\": {e}", joint.name);
        let damping = nonnegative("damping", joint.damping).map_err(context)?;
        let friction = nonnegative("friction", joint.friction).map_err(context)?;
        let armature = nonnegative(
            "armature",
            recipe.params.armature(&joint.name).unwrap_or(0.0),
        )
        .map_err(context)?;
        if let Some(l) = joint.limits.filter(|_| joint.kind != JointKind::Continuous) {
            let lower = if l.lower.is_finite() {
                l.lower
            } else {
                f64::NEG_INFINITY
            };
            let upper = if l.upper.is_finite() {
                l.upper
            } else {
                f64::INFINITY
            };
            if lower.is_finite() || upper.is_finite() {
                world
                    .world
                    .get_mut()
                    .set_joint_limits(i, lower, upper)
                    .map_err(|e| context(e.what().to_string()))?;
            }
        }
        if friction > 0.0 {
            world
                .world
                .get_mut()
                .set_joint_friction(i, friction)
                .map_err(|e| context(e.what().to_string()))?;
        }
        if settings.servo == Servo::Servo {
            world
                .world
                .get_mut()
                .set_actuator(i, true, spec.force_limit)
                .map_err(|e| context(e.what().to_string()))?;
        }
        world.joints.push(JointModel {
            name: joint.name.clone(),
            kv: spec.kv,
            kp: spec.kp.unwrap_or(0.0),
            force_limit: spec.force_limit,
            damping,
            armature,
        });
    }
    // Stage 4: the ground and the objects.
    if let Some(ground) = &scene.ground {
        let mu = ground.friction.unwrap_or(DEFAULT_FRICTION) * friction_scale;
        world
            .world
            .get_mut()
            .add_ground(ground.height_m, mu, 1.0)
            .map_err(|e| format!("the ground: {}", e.what()))?;
    }
    for o in &scene.objects {
        let ObjectShape::Box { size_m } = o.shape;
        let context = |e: String| format!("object \"{}\": {e}", o.name);
        let mass = positive("mass", o.mass_kg * mass_scale).map_err(context)?;
        if mass < MIN_MASS_KG {
            return Err(context(format!(
                "mass {mass:e} kg is below the {MIN_MASS_KG:e} kg DART is given (its constraint solver's symmetry \
                 assertion aborts the process on lighter bodies; objects.<object>.mass_kg)"
            )));
        }
        let (x, y, z) = (size_m.x, size_m.y, size_m.z);
        let inertia = Vec3::new(y * y + z * z, x * x + z * z, x * x + y * y).scale(mass / 12.0);
        let i = world
            .world
            .get_mut()
            .add_object(&o.name, mass, &vec3(inertia), &pose7(&o.pose))
            .map_err(|e| context(e.what().to_string()))?;
        let restitution = recipe.params.restitution(&o.name).unwrap_or(0.0);
        let mu = o.friction.unwrap_or(DEFAULT_FRICTION) * friction_scale;
        world
            .world
            .get_mut()
            .add_shape(
                true,
                i,
                0,
                &[
                    positive("size", x).map_err(context)?,
                    positive("size", y).map_err(context)?,
                    positive("size", z).map_err(context)?,
                ],
                &pose7(&Pose::IDENTITY),
                mu,
                nonnegative("restitution", restitution).map_err(context)?,
            )
            .map_err(|e| context(e.what().to_string()))?;
        world.objects.push(o.name.clone());
    }
    world
        .world
        .get_mut()
        .finish()
        .map_err(|e| e.what().to_string())?;
    let link_frame = |l: usize| (plan.groups.group_of_link[l], plan.groups.link_in_group[l]);
    world.links = (0..robot.links.len())
        .map(|l| (robot.links[l].name.clone(), link_frame(l)))
        .collect();
    world.tracked = plan
        .tracked
        .iter()
        .map(|t| match *t {
            TrackedRef::Link(l) => {
                let (body, offset) = link_frame(l);
                Tracked::Link { body, offset }
            }
            TrackedRef::Object(i) => Tracked::Object(i),
        })
        .collect();
    forward_messages();
    Ok(world)
}

impl World {
    /// The shim's world.
    pub fn raw(&self) -> &ffi::World {
        &self.world
    }

    /// The shim's world, mutable.
    pub fn raw_mut(&mut self) -> &mut ffi::World {
        self.world.get_mut()
    }

    /// The world pose of robot body `b`'s frame.
    pub fn body_pose(&self, b: usize) -> Pose {
        let mut out = [0.0; 7];
        self.world.body_pose(b, &mut out);
        from7(&out)
    }

    /// Object `i`'s pose, linear and angular velocity (world).
    pub fn object_state(&self, i: usize) -> (Pose, Vec3, Vec3) {
        let mut out = [0.0; 13];
        self.world.object_state(i, &mut out);
        (
            from7(&out[..7]),
            Vec3::new(out[7], out[8], out[9]),
            Vec3::new(out[10], out[11], out[12]),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint() -> JointModel {
        JointModel {
            name: "j".into(),
            kv: 10.0,
            kp: 100.0,
            force_limit: 5.0,
            damping: 0.5,
            armature: 0.0,
        }
    }

    #[test]
    fn velocity_law_is_implicit_below_the_limit_and_the_limit_beyond() {
        let j = joint();
        let d = j.drive(ServoCommand::velocity(0.3), 0.0, 0.1, 1e-3, false);
        assert_eq!((d.command, d.damping, d.stiffness), (3.0, 10.5, 0.0));
        let d = j.drive(ServoCommand::velocity(3.0), 0.0, 0.0, 1e-3, false);
        assert_eq!((d.command, d.damping), (5.0, 0.5));
        let d = j.drive(ServoCommand::velocity(-3.0), 0.0, 0.0, 1e-3, false);
        assert_eq!(d.command, -5.0);
        let d = j.drive(ServoCommand::velocity(0.7), 0.0, 0.0, 1e-3, true);
        assert_eq!((d.command, d.damping), (0.7, 0.5));
    }

    #[test]
    fn position_and_effort_laws() {
        let j = joint();
        let d = j.drive(ServoCommand::position(0.01), 0.0, 0.0, 1e-3, false);
        assert_eq!(
            (d.command, d.stiffness, d.rest, d.damping),
            (0.0, 100.0, 0.01, 10.5)
        );
        let d = j.drive(ServoCommand::position(1.0), 0.0, 0.0, 1e-3, false);
        assert_eq!((d.command, d.stiffness), (5.0, 0.0));
        let d = j.drive(ServoCommand::effort(-9.0), 0.0, 0.0, 1e-3, false);
        assert_eq!((d.command, d.damping), (-5.0, 0.5));
        let off = JointModel {
            force_limit: 0.0,
            ..joint()
        };
        let d = off.drive(ServoCommand::velocity(1.0), 0.0, 0.0, 1e-3, false);
        assert_eq!((d.command, d.damping), (0.0, 0.5));
    }

    #[test]
    fn armature_adds_inertia_and_cancels_its_damping() {
        let j = JointModel {
            armature: 0.02,
            ..joint()
        };
        let d = j.drive(ServoCommand::effort(1.0), 0.0, 2.0, 1e-3, false);
        // Damping a/h = 20 and a torque 20 * 2 that cancels its force at
        // the step's start.
        assert_eq!(d.damping, 0.5 + 20.0);
        assert_eq!(d.command, 1.0 + 40.0);
    }
}
