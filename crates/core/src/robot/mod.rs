//! Robot descriptions: a kinematic tree of links and joints read from URDF,
//! with inertias, collision and visual geometry, and forward kinematics.
//!
//! Every engine loads the same [`RobotModel`], so the arm's frames, masses
//! and shapes are identical across engines, and the wrist pose an engine
//! reports can be checked against [`RobotModel::forward_kinematics`].
//!
//! Conventions (URDF's, kept as they are):
//! - Every link has a frame. A joint's `origin` is the pose of the child
//!   link's frame in the parent link's frame when the joint position is zero;
//!   the joint moves the child about (revolute, continuous) or along
//!   (prismatic) its `axis`, a unit vector in the child (joint) frame.
//! - Joint positions are radians for revolute and continuous joints and
//!   metres for prismatic joints; fixed joints have none.
//! - Lengths in metres, masses in kilograms, inertias in kg m^2, effort
//!   limits in N m (revolute) or N (prismatic), velocity limits in rad/s or
//!   m/s.
//! - `package://NAME/...` URIs are resolved by a [`PackageResolver`];
//!   relative mesh paths against the URDF file's directory.
//!
//! Limitations, stated rather than hidden: `floating`, `planar` and
//! `spherical` joints are rejected with [`RobotError::UnsupportedJoint`].
//! `<mimic>` is read into [`Joint::mimic`]; mimic joints are not actuated
//! ([`RobotModel::actuated_joints`] leaves them out) and forward kinematics
//! sets them from the joint they follow. Gazebo, transmission and other
//! non-URDF elements are ignored.

mod package;
pub mod stl;
mod urdf;

pub use package::PackageResolver;

use crate::pose::{Pose, Quat, Vec3};
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// A robot: its links and joints as a tree rooted at [`RobotModel::root_link`].
///
/// Links and joints are stored in the order of the URDF file; indices into
/// [`RobotModel::links`] and [`RobotModel::joints`] are stable for the life of
/// the model and are what every method takes and returns.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotModel {
    /// The `name` attribute of `<robot>`.
    pub name: String,
    /// Every link, in file order.
    pub links: Vec<Link>,
    /// Every joint, in file order.
    pub joints: Vec<Joint>,
    /// Index of the root link (the one link that is no joint's child).
    pub root_link: usize,
    /// The URDF file this model was read from; for a model read from a
    /// string, the base directory that relative paths were resolved against.
    pub source: PathBuf,
    /// For each link, the joint whose child it is (`None` for the root).
    parent_joint: Vec<Option<usize>>,
    /// For each link, the joints whose parent it is, in file order.
    child_joints: Vec<Vec<usize>>,
    /// All joints, depth-first from the root (children in file order).
    tree_order: Vec<usize>,
}

/// A rigid body of the robot with its own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// The link's name.
    pub name: String,
    /// Mass properties; `None` when the URDF gives none (a massless frame).
    pub inertial: Option<Inertial>,
    /// Shapes to draw, in the link frame.
    pub visuals: Vec<Visual>,
    /// Shapes for contact, in the link frame.
    pub collisions: Vec<Collision>,
}

/// Mass properties of a link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Pose of the centre-of-mass frame in the link frame (position in m).
    pub origin: Pose,
    /// Inertia tensor about the centre of mass, in the centre-of-mass frame
    /// (`origin`'s orientation), kg m^2: `[ixx, ixy, ixz, iyy, iyz, izz]`.
    pub inertia: [f64; 6],
}

impl Inertial {
    /// The full symmetric 3x3 inertia matrix, row-major, kg m^2, in the
    /// centre-of-mass frame.
    pub fn inertia_matrix(&self) -> [f64; 9] {
        let [ixx, ixy, ixz, iyy, iyz, izz] = self.inertia;
        [ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz]
    }
}

/// A visual shape of a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Visual {
    /// The optional `name` attribute.
    pub name: Option<String>,
    /// Pose of the shape's frame in the link frame.
    pub origin: Pose,
    /// The shape.
    pub geometry: Geometry,
    /// Colour as red, green, blue, alpha in `[0, 1]`, from the visual's
    /// material or a robot-level material of the same name.
    pub rgba: Option<[f64; 4]>,
}

/// A collision shape of a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Collision {
    /// The optional `name` attribute.
    pub name: Option<String>,
    /// Pose of the shape's frame in the link frame.
    pub origin: Pose,
    /// The shape.
    pub geometry: Geometry,
}

/// A shape, centred on its own frame's origin.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// A box with full edge lengths `size_m` (m) along the frame's x, y, z.
    Box {
        /// Full edge lengths, m.
        size_m: Vec3,
    },
    /// A cylinder along the frame's z axis.
    Cylinder {
        /// Radius, m.
        radius_m: f64,
        /// Full length along z, m.
        length_m: f64,
    },
    /// A capsule along the frame's z axis: a cylinder of `length_m` capped
    /// by two half-spheres (total length `length_m + 2 radius_m`).
    Capsule {
        /// Radius, m.
        radius_m: f64,
        /// Length of the cylindrical part along z, m.
        length_m: f64,
    },
    /// A sphere.
    Sphere {
        /// Radius, m.
        radius_m: f64,
    },
    /// A triangle mesh file (STL, DAE, OBJ, ...), scaled per axis.
    Mesh {
        /// The resolved absolute path of the mesh file (it exists).
        path: PathBuf,
        /// The filename as written in the URDF (e.g. `package://pkg/x.stl`).
        uri: String,
        /// Scale factors along x, y, z (1 when the URDF gives none).
        scale: Vec3,
    },
}

/// The kind of a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum JointKind {
    /// Rotation about the axis within position limits (rad).
    Revolute,
    /// Rotation about the axis without position limits (rad).
    Continuous,
    /// Translation along the axis within position limits (m).
    Prismatic,
    /// No motion.
    Fixed,
}

impl JointKind {
    /// True for joints with a position (every kind but [`JointKind::Fixed`]).
    pub fn is_movable(self) -> bool {
        !matches!(self, JointKind::Fixed)
    }
    /// The URDF `type` attribute of this kind.
    pub fn urdf_name(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Continuous => "continuous",
            JointKind::Prismatic => "prismatic",
            JointKind::Fixed => "fixed",
        }
    }
}

impl fmt::Display for JointKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.urdf_name())
    }
}

/// Limits of a movable joint. Units follow the joint kind: radians (N m,
/// rad/s) for revolute and continuous joints, metres (N, m/s) for prismatic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lowest position (rad or m); `-inf` for a continuous joint.
    pub lower: f64,
    /// Highest position (rad or m); `+inf` for a continuous joint.
    pub upper: f64,
    /// Largest effort the actuator may apply (N m or N); `+inf` when unlimited.
    pub effort: f64,
    /// Largest speed (rad/s or m/s); `+inf` when unlimited.
    pub velocity: f64,
}

impl JointLimits {
    /// The position clamped into `[lower, upper]`.
    pub fn clamp_position(&self, position: f64) -> f64 {
        position.clamp(self.lower, self.upper)
    }
}

/// A joint that copies another joint's motion:
/// `position = multiplier * position(joint) + offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mimic {
    /// Index of the joint that is followed.
    pub joint: usize,
    /// Factor on the followed joint's position (1 by default).
    pub multiplier: f64,
    /// Offset added, rad or m (0 by default).
    pub offset: f64,
}

/// A joint connecting a parent link to a child link.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// The joint's name.
    pub name: String,
    /// What motion the joint allows.
    pub kind: JointKind,
    /// Index of the parent link in [`RobotModel::links`].
    pub parent: usize,
    /// Index of the child link in [`RobotModel::links`].
    pub child: usize,
    /// Pose of the child link frame in the parent link frame at position 0.
    pub origin: Pose,
    /// Unit axis of motion in the joint (child) frame. For fixed joints the
    /// URDF default `(1, 0, 0)` when the file gives none or a zero vector.
    pub axis: Vec3,
    /// Position, effort and velocity limits; `None` for fixed joints.
    /// Continuous joints have infinite position limits.
    pub limits: Option<JointLimits>,
    /// Viscous damping, N m s/rad (or N s/m); 0 when not given.
    pub damping: f64,
    /// Coulomb friction, N m (or N); 0 when not given.
    pub friction: f64,
    /// Set when the joint mimics another one (see [`Mimic`]).
    pub mimic: Option<Mimic>,
}

impl Joint {
    /// The pose of the child link frame in the parent link frame at the
    /// given joint position (rad or m; ignored for fixed joints).
    pub fn transform(&self, position: f64) -> Pose {
        let motion = match self.kind {
            JointKind::Fixed => return self.origin,
            JointKind::Revolute | JointKind::Continuous => {
                Pose::new(Vec3::ZERO, Quat::from_axis_angle(self.axis, position))
            }
            JointKind::Prismatic => Pose::new(self.axis.scale(position), Quat::IDENTITY),
        };
        self.origin.compose(&motion)
    }
}

/// Why a robot description could not be loaded or used.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The URDF file could not be read.
    #[error("cannot read URDF file {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The XML is malformed or does not have the shape URDF requires.
    #[error("{}{}: {message}", source_file.display(), fmt_line_col(*line, *column))]
    Xml {
        /// The URDF file (or base directory, for a string).
        source_file: PathBuf,
        /// 1-based line of the problem, when known.
        line: Option<usize>,
        /// 1-based column of the problem, when known.
        column: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A value is out of range or not finite (e.g. a negative mass, a zero
    /// joint axis, an unknown mimic joint).
    #[error("{}{}: {element}: {message}", source_file.display(), fmt_line_col(*line, None))]
    InvalidValue {
        /// The URDF file.
        source_file: PathBuf,
        /// 1-based line of the element, when known.
        line: Option<usize>,
        /// Which element, e.g. `joint "elbow" <axis>`.
        element: String,
        /// What is wrong.
        message: String,
    },
    /// Two links or two joints share a name.
    #[error("{}{}: duplicate {what} name \"{name}\"", source_file.display(), fmt_line_col(*line, None))]
    DuplicateName {
        /// The URDF file.
        source_file: PathBuf,
        /// 1-based line of the second occurrence, when known.
        line: Option<usize>,
        /// `"link"` or `"joint"`.
        what: &'static str,
        /// The repeated name.
        name: String,
    },
    /// A joint names a parent or child link that does not exist.
    #[error(
        "{}{}: joint \"{joint}\" names {role} link \"{link}\", which is not defined (links: {})",
        source_file.display(), fmt_line_col(*line, None), known_links.join(", ")
    )]
    UnknownLink {
        /// The URDF file.
        source_file: PathBuf,
        /// 1-based line of the joint, when known.
        line: Option<usize>,
        /// The joint's name.
        joint: String,
        /// `"parent"` or `"child"`.
        role: &'static str,
        /// The missing link's name.
        link: String,
        /// The links that are defined.
        known_links: Vec<String>,
    },
    /// A joint type this model does not support (floating, planar, spherical).
    #[error(
        "{}{}: joint \"{joint}\" has type \"{kind}\", which is not supported (use revolute, continuous, prismatic or fixed)",
        source_file.display(), fmt_line_col(*line, None)
    )]
    UnsupportedJoint {
        /// The URDF file.
        source_file: PathBuf,
        /// 1-based line of the joint, when known.
        line: Option<usize>,
        /// The joint's name.
        joint: String,
        /// The URDF type.
        kind: String,
    },
    /// A link is the child of more than one joint.
    #[error("{}: link \"{link}\" is the child of several joints ({}); a URDF must be a tree",
        source_file.display(), joints.join(", "))]
    MultipleParents {
        /// The URDF file.
        source_file: PathBuf,
        /// The link.
        link: String,
        /// The joints that name it as their child.
        joints: Vec<String>,
    },
    /// The joints form a loop.
    #[error("{}: the joints form a cycle through links {}; a URDF must be a tree",
        source_file.display(), links.join(" -> "))]
    Cycle {
        /// The URDF file.
        source_file: PathBuf,
        /// The links on the cycle, in order.
        links: Vec<String>,
    },
    /// More than one link has no parent joint.
    #[error("{}: several links have no parent joint ({}); a URDF must have exactly one root link",
        source_file.display(), roots.join(", "))]
    MultipleRoots {
        /// The URDF file.
        source_file: PathBuf,
        /// The parentless links.
        roots: Vec<String>,
    },
    /// The URDF defines no link.
    #[error("{}: the robot has no links", source_file.display())]
    NoLinks {
        /// The URDF file.
        source_file: PathBuf,
    },
    /// A `package://` URI names a package that cannot be found.
    #[error(
        "{}: link \"{link}\": mesh \"{uri}\": package \"{package}\" not found (looked in: {}); \
         set ROS_PACKAGE_PATH to a directory that contains it, or pass --package {package}=DIR",
        source_file.display(),
        if searched.is_empty() { "nowhere, no package directories are configured".to_string() }
        else { searched.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ") }
    )]
    PackageNotFound {
        /// The URDF file.
        source_file: PathBuf,
        /// The link whose geometry refers to the package.
        link: String,
        /// The mesh URI as written.
        uri: String,
        /// The package name.
        package: String,
        /// Every directory that was searched.
        searched: Vec<PathBuf>,
    },
    /// A mesh file does not exist where its URI points.
    #[error("{}: link \"{link}\": mesh \"{uri}\" not found at {}", source_file.display(), looked_at.display())]
    MeshNotFound {
        /// The URDF file.
        source_file: PathBuf,
        /// The link whose geometry refers to the mesh.
        link: String,
        /// The mesh URI as written.
        uri: String,
        /// The path the URI resolved to.
        looked_at: PathBuf,
    },
    /// A mesh URI uses a scheme other than `package://`, `file://` or a path.
    #[error("{}: link \"{link}\": mesh \"{uri}\" has an unsupported URI scheme (use package://, file:// or a path)", source_file.display())]
    UnsupportedUri {
        /// The URDF file.
        source_file: PathBuf,
        /// The link.
        link: String,
        /// The URI.
        uri: String,
    },
    /// A `--package` argument is not of the form `NAME=DIR`.
    #[error("invalid package mapping \"{arg}\": expected NAME=DIR, e.g. kinova_description=/path/to/kinova_description")]
    InvalidPackageArg {
        /// The argument as given.
        arg: String,
    },
    /// A joint name given to forward kinematics is not in the model.
    #[error("robot \"{robot}\" has no joint named \"{joint}\"")]
    UnknownJoint {
        /// The robot's name.
        robot: String,
        /// The name that was asked for.
        joint: String,
    },
    /// A fixed joint was given a position.
    #[error("joint \"{joint}\" of robot \"{robot}\" is fixed and has no position")]
    FixedJointPosition {
        /// The robot's name.
        robot: String,
        /// The joint.
        joint: String,
    },
}

fn fmt_line_col(line: Option<usize>, column: Option<usize>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!(":{l}:{c}"),
        (Some(l), None) => format!(":{l}"),
        _ => String::new(),
    }
}

impl RobotModel {
    /// Reads a URDF file. Relative mesh paths are resolved against the
    /// file's directory and `package://` URIs through `resolver`; every mesh
    /// must exist.
    pub fn from_urdf_file(path: &Path, resolver: &PackageResolver) -> Result<Self, RobotError> {
        let xml = std::fs::read_to_string(path)
            .map_err(|source| RobotError::Io { path: path.to_path_buf(), source })?;
        let base_dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        urdf::build(&xml, path, &base_dir, resolver)
    }

    /// Reads URDF text. Relative mesh paths are resolved against `base_dir`,
    /// which also names the source in error messages.
    pub fn from_urdf_str(xml: &str, base_dir: &Path, resolver: &PackageResolver) -> Result<Self, RobotError> {
        urdf::build(xml, base_dir, base_dir, resolver)
    }

    /// Assembles a model from links and joints whose indices are already
    /// consistent, checking that they form one tree. `source` names the
    /// description in errors.
    pub(crate) fn from_parts(
        name: String,
        links: Vec<Link>,
        joints: Vec<Joint>,
        source: PathBuf,
    ) -> Result<Self, RobotError> {
        if links.is_empty() {
            return Err(RobotError::NoLinks { source_file: source });
        }
        let mut parent_joint: Vec<Option<usize>> = vec![None; links.len()];
        let mut child_joints: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
        for (j, joint) in joints.iter().enumerate() {
            if let Some(previous) = parent_joint[joint.child] {
                return Err(RobotError::MultipleParents {
                    source_file: source,
                    link: links[joint.child].name.clone(),
                    joints: vec![joints[previous].name.clone(), joint.name.clone()],
                });
            }
            parent_joint[joint.child] = Some(j);
            child_joints[joint.parent].push(j);
        }
        let roots: Vec<usize> = (0..links.len()).filter(|&l| parent_joint[l].is_none()).collect();
        if roots.len() > 1 {
            return Err(RobotError::MultipleRoots {
                source_file: source,
                roots: roots.iter().map(|&l| links[l].name.clone()).collect(),
            });
        }
        let Some(&root_link) = roots.first() else {
            return Err(RobotError::Cycle { source_file: source, links: find_cycle(&links, &joints, &parent_joint) });
        };
        // Depth-first from the root, children in file order.
        let mut tree_order = Vec::with_capacity(joints.len());
        let mut stack: Vec<usize> = child_joints[root_link].iter().rev().copied().collect();
        while let Some(j) = stack.pop() {
            tree_order.push(j);
            stack.extend(child_joints[joints[j].child].iter().rev().copied());
        }
        if tree_order.len() != joints.len() {
            // Every link has one parent, so links not reached from the root
            // hang off a loop.
            return Err(RobotError::Cycle { source_file: source, links: find_cycle(&links, &joints, &parent_joint) });
        }
        Ok(RobotModel { name, links, joints, root_link, source, parent_joint, child_joints, tree_order })
    }

    /// Index of the link with this name.
    pub fn link_by_name(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// Index of the joint with this name.
    pub fn joint_by_name(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The joint whose child is `link` (`None` for the root link or an
    /// index out of range).
    pub fn parent_joint(&self, link: usize) -> Option<usize> {
        self.parent_joint.get(link).copied().flatten()
    }

    /// The joints whose parent is `link`, in file order (empty for a leaf or
    /// an index out of range).
    pub fn child_joints(&self, link: usize) -> &[usize] {
        self.child_joints.get(link).map(Vec::as_slice).unwrap_or(&[])
    }

    /// Every joint, depth-first from the root link (each link's child joints
    /// in file order). A parent link's joint always comes before its
    /// children's joints.
    pub fn joints_in_tree_order(&self) -> &[usize] {
        &self.tree_order
    }

    /// The joints an actuator drives: revolute, continuous and prismatic
    /// joints that do not mimic another joint, depth-first from the root.
    /// For the Mico2 (m1n6s300): joints 1 to 6, then the three fingers.
    pub fn actuated_joints(&self) -> Vec<usize> {
        self.tree_order
            .iter()
            .copied()
            .filter(|&j| self.joints[j].kind.is_movable() && self.joints[j].mimic.is_none())
            .collect()
    }

    /// The joints from the root link down to `link`, root first (empty for
    /// the root link or an index out of range).
    pub fn chain_to(&self, link: usize) -> Vec<usize> {
        let mut chain = Vec::new();
        let mut current = link;
        while let Some(j) = self.parent_joint(current) {
            chain.push(j);
            current = self.joints[j].parent;
        }
        chain.reverse();
        chain
    }

    /// A full joint-position vector (indexed by joint index, zeros for fixed
    /// joints and for actuated joints beyond `values`) from positions given in
    /// [`RobotModel::actuated_joints`] order.
    pub fn positions_from_actuated(&self, values: &[f64]) -> Vec<f64> {
        let mut positions = vec![0.0; self.joints.len()];
        for (&j, &v) in self.actuated_joints().iter().zip(values) {
            positions[j] = v;
        }
        positions
    }

    /// A full joint-position vector (indexed by joint index) from positions
    /// by joint name; joints not named are at 0. Errors on an unknown name
    /// or a fixed joint.
    pub fn positions_from_names(&self, named: &HashMap<String, f64>) -> Result<Vec<f64>, RobotError> {
        let mut positions = vec![0.0; self.joints.len()];
        for (name, &value) in named {
            let j = self
                .joint_by_name(name)
                .ok_or_else(|| RobotError::UnknownJoint { robot: self.name.clone(), joint: name.clone() })?;
            if !self.joints[j].kind.is_movable() {
                return Err(RobotError::FixedJointPosition { robot: self.name.clone(), joint: name.clone() });
            }
            positions[j] = value;
        }
        Ok(positions)
    }

    /// The position each joint actually takes: `joint_positions[j]` (0 when
    /// the slice is shorter), or for a mimic joint the position derived from
    /// the joint it follows.
    fn effective_position(&self, joint_positions: &[f64], j: usize) -> f64 {
        let own = |k: usize| joint_positions.get(k).copied().unwrap_or(0.0);
        match &self.joints[j].mimic {
            Some(m) => m.multiplier * own(m.joint) + m.offset,
            None => own(j),
        }
    }

    /// World pose of every link frame (indexed like [`RobotModel::links`]),
    /// with the root link frame at `base` and joint positions indexed by
    /// joint index (rad or m; entries of fixed joints are ignored, missing
    /// entries are 0, mimic joints follow their leader).
    pub fn forward_kinematics(&self, base: &Pose, joint_positions: &[f64]) -> Vec<Pose> {
        let mut poses = vec![*base; self.links.len()];
        for &j in &self.tree_order {
            let joint = &self.joints[j];
            let q = self.effective_position(joint_positions, j);
            poses[joint.child] = poses[joint.parent].compose(&joint.transform(q));
        }
        poses
    }

    /// World pose of one link frame (see [`RobotModel::forward_kinematics`]);
    /// only the joints on the chain to `link` are evaluated. `None` when
    /// `link` is out of range.
    pub fn link_pose(&self, base: &Pose, joint_positions: &[f64], link: usize) -> Option<Pose> {
        if link >= self.links.len() {
            return None;
        }
        let mut pose = *base;
        for j in self.chain_to(link) {
            pose = pose.compose(&self.joints[j].transform(self.effective_position(joint_positions, j)));
        }
        Some(pose)
    }

    /// The generalised force gravity exerts on each joint (indexed by joint
    /// index) with the robot at rest in the given configuration: N m about
    /// a revolute or continuous joint's axis, N along a prismatic joint's
    /// axis, 0 for fixed joints. `gravity_m_s2` is in the world frame (e.g.
    /// `(0, 0, -9.81)`). An actuator holding the robot still must apply the
    /// opposite.
    pub fn gravity_torques(&self, base: &Pose, joint_positions: &[f64], gravity_m_s2: Vec3) -> Vec<f64> {
        let poses = self.forward_kinematics(base, joint_positions);
        // Mass and first moment (mass-weighted centre of mass) of each
        // link's subtree, accumulated from the leaves up.
        let mut mass = vec![0.0; self.links.len()];
        let mut moment = vec![Vec3::ZERO; self.links.len()];
        for (l, link) in self.links.iter().enumerate() {
            if let Some(i) = link.inertial {
                mass[l] = i.mass_kg;
                moment[l] = poses[l].transform_point(i.origin.position_m).scale(i.mass_kg);
            }
        }
        for &j in self.tree_order.iter().rev() {
            let (p, c) = (self.joints[j].parent, self.joints[j].child);
            mass[p] += mass[c];
            moment[p] = moment[p] + moment[c];
        }
        self.joints
            .iter()
            .map(|joint| {
                let child = joint.child;
                let axis = poses[child].orientation.rotate(joint.axis);
                match joint.kind {
                    JointKind::Fixed => 0.0,
                    JointKind::Prismatic => axis.dot(gravity_m_s2.scale(mass[child])),
                    JointKind::Revolute | JointKind::Continuous => {
                        // Sum over the subtree of (c - p) x (m g) = (M c_mean - M p) x g.
                        let lever = moment[child] - poses[child].position_m.scale(mass[child]);
                        axis.dot(lever.cross(gravity_m_s2))
                    }
                }
            })
            .collect()
    }

    /// Total mass of all links, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.links.iter().filter_map(|l| l.inertial.map(|i| i.mass_kg)).sum()
    }
}

/// Follows parent links from a link that is not reachable from any root
/// until a link repeats, and returns the loop.
fn find_cycle(links: &[Link], joints: &[Joint], parent_joint: &[Option<usize>]) -> Vec<String> {
    // Links reachable from a parentless link are not on a loop.
    let mut on_tree = vec![false; links.len()];
    let mut stack: Vec<usize> = (0..links.len()).filter(|&l| parent_joint[l].is_none()).collect();
    while let Some(l) = stack.pop() {
        on_tree[l] = true;
        for j in joints.iter().filter(|j| j.parent == l) {
            if !on_tree[j.child] {
                stack.push(j.child);
            }
        }
    }
    let Some(start) = (0..links.len()).find(|&l| !on_tree[l]) else {
        return Vec::new();
    };
    let mut visited_at: HashMap<usize, usize> = HashMap::new();
    let mut path = Vec::new();
    let mut current = start;
    while let Some(j) = parent_joint[current] {
        if let Some(&i) = visited_at.get(&current) {
            let mut cycle: Vec<String> = path[i..].iter().map(|&l: &usize| links[l].name.clone()).collect();
            cycle.reverse(); // parent -> child order
            cycle.push(cycle[0].clone());
            return cycle;
        }
        visited_at.insert(current, path.len());
        path.push(current);
        current = joints[j].parent;
    }
    Vec::new()
}

#[cfg(test)]
mod mico2_tests;
