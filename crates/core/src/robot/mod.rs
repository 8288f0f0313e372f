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
pub mod plan;
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
    /// What reading the URDF noticed without refusing it (a `package://`
    /// found beside the file), one line each.
    pub notes: Vec<String>,
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

/// The role a link plays for a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkRole {
    /// The joint's parent link.
    Parent,
    /// The joint's child link.
    Child,
}

impl fmt::Display for LinkRole {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            LinkRole::Parent => "parent",
            LinkRole::Child => "child",
        })
    }
}

/// Why a robot description could not be loaded or used.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The URDF file could not be read.
    #[error("cannot read URDF file {}: {reason}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
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
        /// Whether the joint names it as its parent or its child.
        role: LinkRole,
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
        let xml = std::fs::read_to_string(path).map_err(|reason| RobotError::Io {
            path: path.to_path_buf(),
            reason,
        })?;
        let base_dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        urdf::build(&xml, path, &base_dir, resolver)
    }

    /// The robot of a scene without one: a single fixed link named `world`
    /// with no mass, no shape and no joint. Every engine builds it as
    /// nothing, so the scene's free objects and ground are all there is.
    pub fn world() -> RobotModel {
        const WORLD: &str = "<robot name=\"world\"><link name=\"world\"/></robot>";
        // Reading this fixed text cannot fail: a test checks it.
        match RobotModel::from_urdf_str(WORLD, Path::new("(no robot)"), &PackageResolver::new()) {
            Ok(model) => model,
            Err(e) => unreachable!("the built-in world model does not read: {e}"),
        }
    }

    /// Reads URDF text. Relative mesh paths are resolved against `base_dir`,
    /// which also names the source in error messages.
    pub fn from_urdf_str(
        xml: &str,
        base_dir: &Path,
        resolver: &PackageResolver,
    ) -> Result<Self, RobotError> {
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
            return Err(RobotError::NoLinks {
                source_file: source,
            });
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
        let roots: Vec<usize> = (0..links.len())
            .filter(|&l| parent_joint[l].is_none())
            .collect();
        if roots.len() > 1 {
            return Err(RobotError::MultipleRoots {
                source_file: source,
                roots: roots.iter().map(|&l| links[l].name.clone()).collect(),
            });
        }
        let Some(&root_link) = roots.first() else {
            return Err(RobotError::Cycle {
                source_file: source,
                links: find_cycle(&links, &joints, &parent_joint),
            });
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
            return Err(RobotError::Cycle {
                source_file: source,
                links: find_cycle(&links, &joints, &parent_joint),
            });
        }
        Ok(RobotModel {
            name,
            links,
            joints,
            root_link,
            source,
            notes: Vec::new(),
            parent_joint,
            child_joints,
            tree_order,
        })
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
        self.child_joints
            .get(link)
            .map(Vec::as_slice)
            .unwrap_or(&[])
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
    pub fn positions_from_names(
        &self,
        named: &HashMap<String, f64>,
    ) -> Result<Vec<f64>, RobotError> {
        let mut positions = vec![0.0; self.joints.len()];
        for (name, &value) in named {
            let j = self
                .joint_by_name(name)
                .ok_or_else(|| RobotError::UnknownJoint {
                    robot: self.name.clone(),
                    joint: name.clone(),
                })?;
            if !self.joints[j].kind.is_movable() {
                return Err(RobotError::FixedJointPosition {
                    robot: self.name.clone(),
                    joint: name.clone(),
                });
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

    /// World poses of `link` for each row of positions in
    /// [`RobotModel::actuated_joints`] order (a joint recording's samples),
    /// with the root link frame at `base`; `None` when `link` is out of
    /// range.
    pub fn link_poses_from_actuated(
        &self,
        base: &Pose,
        rows: &[Vec<f64>],
        link: usize,
    ) -> Vec<Option<Pose>> {
        let actuated = self.actuated_joints();
        let mut full = vec![0.0; self.joints.len()];
        rows.iter()
            .map(|row| {
                for (&j, &q) in actuated.iter().zip(row) {
                    full[j] = q;
                }
                self.link_pose(base, &full, link)
            })
            .collect()
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
            pose = pose
                .compose(&self.joints[j].transform(self.effective_position(joint_positions, j)));
        }
        Some(pose)
    }

    /// The generalised force gravity exerts on each joint (indexed by joint
    /// index) with the robot at rest in the given configuration: N m about
    /// a revolute or continuous joint's axis, N along a prismatic joint's
    /// axis, 0 for fixed joints. `gravity_m_s2` is in the world frame (e.g.
    /// `(0, 0, -9.81)`). An actuator holding the robot still must apply the
    /// opposite.
    pub fn gravity_torques(
        &self,
        base: &Pose,
        joint_positions: &[f64],
        gravity_m_s2: Vec3,
    ) -> Vec<f64> {
        let poses = self.forward_kinematics(base, joint_positions);
        // Mass and first moment (mass-weighted centre of mass) of each
        // link's subtree, accumulated from the leaves up.
        let mut mass = vec![0.0; self.links.len()];
        let mut moment = vec![Vec3::ZERO; self.links.len()];
        for (l, link) in self.links.iter().enumerate() {
            if let Some(i) = link.inertial {
                mass[l] = i.mass_kg;
                moment[l] = poses[l]
                    .transform_point(i.origin.position_m)
                    .scale(i.mass_kg);
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
        self.links
            .iter()
            .filter_map(|l| l.inertial.map(|i| i.mass_kg))
            .sum()
    }
}

/// Follows parent links from a link that is not reachable from any root
/// until a link repeats, and returns the loop.
fn find_cycle(links: &[Link], joints: &[Joint], parent_joint: &[Option<usize>]) -> Vec<String> {
    // Links reachable from a parentless link are not on a loop.
    let mut on_tree = vec![false; links.len()];
    let mut stack: Vec<usize> = (0..links.len())
        .filter(|&l| parent_joint[l].is_none())
        .collect();
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
            let mut cycle: Vec<String> = path[i..]
                .iter()
                .map(|&l: &usize| links[l].name.clone())
                .collect();
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
pub(crate) mod mico2_tests;

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    const ARM: &str = r#"<?xml version="1.0"?>
<robot name="toy">
  <material name="red"><color rgba="1 0 0 1"/></material>
  <link name="base">
    <visual><geometry><box size="0.2 0.2 0.1"/></geometry><material name="red"/></visual>
    <collision name="plate"><origin xyz="0 0 0.05"/><geometry><box size="0.2 0.2 0.1"/></geometry></collision>
  </link>
  <link name="upper">
    <inertial>
      <origin xyz="0.1 0 0" rpy="0 0 0"/>
      <mass value="2"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/>
    </inertial>
    <collision><origin xyz="0.1 0 0" rpy="0 1.5707963267948966 0"/><geometry><cylinder radius="0.03" length="0.2"/></geometry></collision>
    <collision><geometry><capsule radius="0.02" length="0.1"/></geometry></collision>
  </link>
  <link name="slider">
    <visual><geometry><sphere radius="0.01"/></geometry><material name="own"><color rgba="0 0 1 0.5"/></material></visual>
  </link>
  <link name="tool"/>
  <link name="twin"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
    <axis xyz="0 0 2"/>
    <limit lower="-1.5" upper="1.5" effort="10" velocity="2"/>
    <dynamics damping="0.5" friction="0.1"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="upper"/><child link="slider"/>
    <origin xyz="0.2 0 0"/>
    <axis xyz="1 0 0"/>
    <limit lower="0" upper="0.1" effort="50" velocity="0.2"/>
  </joint>
  <joint name="mount" type="fixed">
    <parent link="slider"/><child link="tool"/>
    <origin xyz="0 0 -0.05" rpy="3.141592653589793 0 0"/>
  </joint>
  <joint name="spin" type="continuous">
    <parent link="base"/><child link="twin"/>
    <axis xyz="0 0 1"/>
    <mimic joint="shoulder" multiplier="-2" offset="0.1"/>
  </joint>
</robot>
"#;

    fn toy() -> RobotModel {
        RobotModel::from_urdf_str(ARM, Path::new("/toy"), &PackageResolver::new()).unwrap()
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        a.distance(b) < 1e-12
    }

    fn temp_dir(tag: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("realitygap-robot-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn parses_links_joints_geometry_and_inertia() {
        let m = toy();
        assert_eq!(m.name, "toy");
        assert_eq!(m.links[m.root_link].name, "base");
        assert_eq!(m.source, PathBuf::from("/toy"));
        let upper = &m.links[m.link_by_name("upper").unwrap()];
        let inertial = upper.inertial.unwrap();
        assert_eq!(inertial.mass_kg, 2.0);
        assert_eq!(inertial.inertia, [0.01, 0.0, 0.0, 0.02, 0.0, 0.03]);
        assert_eq!(inertial.inertia_matrix()[4], 0.02);
        assert!(close(inertial.origin.position_m, Vec3::new(0.1, 0.0, 0.0)));
        assert_eq!(
            upper.collisions[0].geometry,
            Geometry::Cylinder {
                radius_m: 0.03,
                length_m: 0.2
            }
        );
        assert_eq!(
            upper.collisions[1].geometry,
            Geometry::Capsule {
                radius_m: 0.02,
                length_m: 0.1
            }
        );
        let base = &m.links[m.link_by_name("base").unwrap()];
        assert!(base.inertial.is_none());
        assert_eq!(base.collisions[0].name.as_deref(), Some("plate"));
        assert_eq!(
            base.visuals[0].rgba,
            Some([1.0, 0.0, 0.0, 1.0]),
            "robot-level material by name"
        );
        let slider = &m.links[m.link_by_name("slider").unwrap()];
        assert_eq!(
            slider.visuals[0].rgba,
            Some([0.0, 0.0, 1.0, 0.5]),
            "inline material colour"
        );
        assert_eq!(
            slider.visuals[0].geometry,
            Geometry::Sphere { radius_m: 0.01 }
        );

        let shoulder = &m.joints[m.joint_by_name("shoulder").unwrap()];
        assert_eq!(shoulder.kind, JointKind::Revolute);
        assert!(
            close(shoulder.axis, Vec3::new(0.0, 0.0, 1.0)),
            "axis is normalised"
        );
        assert_eq!(
            shoulder.limits,
            Some(JointLimits {
                lower: -1.5,
                upper: 1.5,
                effort: 10.0,
                velocity: 2.0
            })
        );
        assert_eq!((shoulder.damping, shoulder.friction), (0.5, 0.1));
        let mount = &m.joints[m.joint_by_name("mount").unwrap()];
        assert_eq!(
            (mount.kind, mount.limits, mount.axis),
            (JointKind::Fixed, None, Vec3::new(1.0, 0.0, 0.0))
        );
        let spin = &m.joints[m.joint_by_name("spin").unwrap()];
        let lim = spin.limits.unwrap();
        assert!(
            lim.lower == f64::NEG_INFINITY
                && lim.upper == f64::INFINITY
                && lim.effort == f64::INFINITY
        );
        assert_eq!(
            spin.mimic,
            Some(Mimic {
                joint: m.joint_by_name("shoulder").unwrap(),
                multiplier: -2.0,
                offset: 0.1
            })
        );
        assert!((m.total_mass_kg() - 2.0).abs() < 1e-15);
    }

    #[test]
    fn tree_queries_follow_the_kinematic_tree() {
        let m = toy();
        let names = |js: &[usize]| {
            js.iter()
                .map(|&j| m.joints[j].name.clone())
                .collect::<Vec<_>>()
        };
        assert_eq!(
            names(m.joints_in_tree_order()),
            ["shoulder", "slide", "mount", "spin"]
        );
        assert_eq!(
            names(&m.actuated_joints()),
            ["shoulder", "slide"],
            "mimic joints are not actuated"
        );
        assert_eq!(
            names(&m.chain_to(m.link_by_name("tool").unwrap())),
            ["shoulder", "slide", "mount"]
        );
        assert!(m.chain_to(m.root_link).is_empty());
        assert!(m.chain_to(999).is_empty());
        assert_eq!(
            m.parent_joint(m.link_by_name("twin").unwrap()),
            m.joint_by_name("spin")
        );
        assert_eq!(names(m.child_joints(m.root_link)), ["shoulder", "spin"]);
        assert!(m.child_joints(999).is_empty());
        assert_eq!(m.joint_by_name("nope"), None);
        assert_eq!(m.link_by_name("nope"), None);
    }

    #[test]
    fn forward_kinematics_composes_joint_motions() {
        let m = toy();
        let base = Pose::new(Vec3::new(1.0, 0.0, 0.0), Quat::IDENTITY);
        let q = m.positions_from_actuated(&[FRAC_PI_2, 0.05]);
        let poses = m.forward_kinematics(&base, &q);
        let at = |name: &str| poses[m.link_by_name(name).unwrap()];
        // Shoulder turns +90 deg about z: the arm's x axis points along world y.
        assert!(close(at("upper").position_m, Vec3::new(1.0, 0.0, 0.1)));
        assert!(close(at("slider").position_m, Vec3::new(1.0, 0.25, 0.1)));
        assert!(close(at("tool").position_m, Vec3::new(1.0, 0.25, 0.05)));
        assert!(
            at("tool").orientation.angle_to(Quat::from_euler_rpy(
                std::f64::consts::PI,
                0.0,
                FRAC_PI_2
            )) < 1e-12
        );
        // The mimic joint follows: -2 * pi/2 + 0.1.
        let twin = at("twin").orientation;
        assert!(
            twin.angle_to(Quat::from_axis_angle(
                Vec3::new(0.0, 0.0, 1.0),
                -std::f64::consts::PI + 0.1
            )) < 1e-12
        );
        // link_pose agrees with the full pass; short position slices mean 0.
        let tool = m.link_by_name("tool").unwrap();
        assert_eq!(m.link_pose(&base, &q, tool), Some(at("tool")));
        assert_eq!(m.link_pose(&base, &q, 999), None);
        let rest = m.forward_kinematics(&base, &[]);
        assert!(close(rest[tool].position_m, Vec3::new(1.2, 0.0, 0.05)));

        let mut named = HashMap::new();
        named.insert("shoulder".to_string(), FRAC_PI_2);
        named.insert("slide".to_string(), 0.05);
        assert_eq!(m.positions_from_names(&named).unwrap(), q);
        named.insert("elbow".to_string(), 1.0);
        let e = m.positions_from_names(&named).unwrap_err();
        assert_eq!(e.to_string(), "robot \"toy\" has no joint named \"elbow\"");
        named.remove("elbow");
        named.insert("mount".to_string(), 1.0);
        assert!(matches!(
            m.positions_from_names(&named),
            Err(RobotError::FixedJointPosition { .. })
        ));
    }

    #[test]
    fn gravity_torques_of_a_horizontal_arm() {
        let m = toy();
        let g = Vec3::new(0.0, 0.0, -9.81);
        // Shoulder axis is vertical: gravity exerts no torque about it.
        let t = m.gravity_torques(&Pose::IDENTITY, &[], g);
        assert!(t[m.joint_by_name("shoulder").unwrap()].abs() < 1e-12);
        // Tip the whole robot on its side (base rotated -90 deg about x): the
        // shoulder axis is now world +y, the 2 kg at 0.1 m along x hangs
        // off it: torque about +y of r x F = 0.1 * 2 * 9.81.
        let tipped = Pose::new(
            Vec3::ZERO,
            Quat::from_axis_angle(Vec3::new(1.0, 0.0, 0.0), -FRAC_PI_2),
        );
        let t = m.gravity_torques(&tipped, &[], g);
        assert!(
            (t[m.joint_by_name("shoulder").unwrap()] - 0.1 * 2.0 * 9.81).abs() < 1e-12,
            "{t:?}"
        );
        // The prismatic slider carries no mass; fixed joints report 0.
        assert_eq!(t[m.joint_by_name("slide").unwrap()], 0.0);
        assert_eq!(t[m.joint_by_name("mount").unwrap()], 0.0);
    }

    fn load_err(xml: &str) -> RobotError {
        RobotModel::from_urdf_str(xml, Path::new("/models/bad.urdf"), &PackageResolver::new())
            .unwrap_err()
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = RobotModel::from_urdf_file(
            Path::new("/nonexistent/robot.urdf"),
            &PackageResolver::new(),
        )
        .unwrap_err();
        assert!(matches!(e, RobotError::Io { .. }));
        assert!(
            e.to_string()
                .starts_with("cannot read URDF file /nonexistent/robot.urdf: "),
            "{e}"
        );
        // The system's reason is in the message and not also its cause,
        // which `{:#}` and error chains would print a second time.
        assert!(std::error::Error::source(&e).is_none());
    }

    #[test]
    fn malformed_xml_names_file_line_and_column() {
        let e = load_err("<robot name=\"r\">\n  <link name=\"a\">\n  </lnk>\n</robot>\n");
        let RobotError::Xml { line, column, .. } = &e else {
            panic!("{e:?}")
        };
        assert_eq!(*line, Some(3), "{e}");
        assert!(column.is_some(), "{e}");
        assert!(e.to_string().starts_with("/models/bad.urdf:3:"), "{e}");
        // Well-formed XML that is not URDF: no position, but the reason.
        let e = load_err("<robot name=\"r\"><link name=\"a\"/><joint name=\"j\" type=\"revolute\"><parent link=\"a\"/></joint></robot>");
        assert!(matches!(e, RobotError::Xml { .. }), "{e:?}");
        assert!(e.to_string().starts_with("/models/bad.urdf: "), "{e}");
    }

    #[test]
    fn unknown_links_and_bad_trees_are_reported() {
        let e = load_err(
            "<robot name=\"r\">\n<link name=\"a\"/>\n<joint name=\"j\" type=\"fixed\">\n<parent link=\"a\"/><child link=\"b\"/>\n</joint>\n</robot>",
        );
        assert_eq!(
            e.to_string(),
            "/models/bad.urdf:3: joint \"j\" names child link \"b\", which is not defined (links: a)"
        );
        let e = load_err("<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/></robot>");
        assert_eq!(e.to_string(), "/models/bad.urdf: several links have no parent joint (a, b); a URDF must have exactly one root link");
        let e = load_err(
            r#"<robot name="r"><link name="root"/><link name="a"/><link name="b"/>
            <joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>
            <joint name="j2" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"#,
        );
        assert!(matches!(e, RobotError::Cycle { .. }), "{e:?}");
        assert!(e.to_string().contains("cycle through links"), "{e}");
        let e = load_err(
            r#"<robot name="r"><link name="a"/><link name="b"/>
            <joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>
            <joint name="j2" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"#,
        );
        assert!(matches!(e, RobotError::Cycle { .. }), "{e:?}");
        let e = load_err(
            r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
            <joint name="j1" type="fixed"><parent link="a"/><child link="c"/></joint>
            <joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint></robot>"#,
        );
        assert_eq!(e.to_string(), "/models/bad.urdf: link \"c\" is the child of several joints (j1, j2); a URDF must be a tree");
        let e = load_err("<robot name=\"r\">\n<link name=\"a\"/>\n<link name=\"a\"/>\n</robot>");
        assert_eq!(
            e.to_string(),
            "/models/bad.urdf:3: duplicate link name \"a\""
        );
        let e = load_err("<robot name=\"r\"></robot>");
        assert_eq!(e.to_string(), "/models/bad.urdf: the robot has no links");
        let e = load_err(
            "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/>\n<joint name=\"free\" type=\"floating\"><parent link=\"a\"/><child link=\"b\"/></joint></robot>",
        );
        assert!(
            e.to_string().starts_with(
                "/models/bad.urdf:2: joint \"free\" has type \"floating\", which is not supported"
            ),
            "{e}"
        );
    }

    #[test]
    fn out_of_range_values_are_reported() {
        let joint = |body: &str| {
            format!("<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/>\n<joint name=\"j\" type=\"revolute\"><parent link=\"a\"/><child link=\"b\"/>{body}</joint></robot>")
        };
        let e = load_err(&joint(
            "<axis xyz=\"0 0 0\"/><limit lower=\"0\" upper=\"1\" effort=\"1\" velocity=\"1\"/>",
        ));
        assert!(e.to_string().starts_with("/models/bad.urdf:2: joint \"j\" <axis>: axis [0.0, 0.0, 0.0] must be a finite, non-zero vector"), "{e}");
        let e = load_err(&joint("<axis xyz=\"0 0 1\"/>"));
        assert!(
            e.to_string().contains("a revolute joint needs <limit"),
            "{e}"
        );
        let e = load_err(&joint(
            "<limit lower=\"1\" upper=\"0\" effort=\"1\" velocity=\"1\"/>",
        ));
        assert!(
            e.to_string().contains("lower 1 must not exceed upper 0"),
            "{e}"
        );
        let e = load_err(&joint(
            "<limit lower=\"0\" upper=\"1\" effort=\"-1\" velocity=\"1\"/>",
        ));
        assert!(
            e.to_string()
                .contains("effort -1 and velocity 1 must be >= 0"),
            "{e}"
        );
        let e = load_err(&joint(
            "<origin xyz=\"0 nan 0\"/><limit lower=\"0\" upper=\"1\" effort=\"1\" velocity=\"1\"/>",
        ));
        assert!(e.to_string().contains("must be finite"), "{e}");
        let e = load_err(&joint(
            "<limit lower=\"0\" upper=\"1\" effort=\"1\" velocity=\"1\"/><mimic joint=\"x\"/>",
        ));
        assert!(
            e.to_string()
                .contains("mimics joint \"x\", which is not defined"),
            "{e}"
        );
        let e = load_err(
            "<robot name=\"r\">\n<link name=\"a\"><inertial><mass value=\"-1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link></robot>",
        );
        assert_eq!(e.to_string(), "/models/bad.urdf:2: link \"a\" <inertial><mass>: mass -1 must be a finite number >= 0 kg");
        let e = load_err("<robot name=\"r\">\n<link name=\"a\"><collision><geometry><sphere radius=\"0\"/></geometry></collision></link></robot>");
        assert_eq!(
            e.to_string(),
            "/models/bad.urdf:2: link \"a\" <collision> <geometry>: sphere radius 0 must be > 0 m"
        );
    }

    #[test]
    fn meshes_resolve_through_packages_and_relative_paths() {
        let root = temp_dir("mesh");
        std::fs::create_dir_all(root.join("ws/my_robot/meshes")).unwrap();
        std::fs::write(
            root.join("ws/my_robot/meshes/arm.stl"),
            b"solid x\nendsolid x\n",
        )
        .unwrap();
        std::fs::create_dir_all(root.join("urdf/parts")).unwrap();
        std::fs::write(root.join("urdf/parts/local.stl"), b"solid x\nendsolid x\n").unwrap();
        let urdf = root.join("urdf/robot.urdf");
        let write = |mesh: &str| {
            std::fs::write(
                &urdf,
                format!("<robot name=\"r\">\n<link name=\"a\">\n<visual><geometry><mesh filename=\"{mesh}\" scale=\"0.001 0.001 0.001\"/></geometry></visual>\n</link>\n</robot>\n"),
            )
            .unwrap();
        };
        let mut search = PackageResolver::new();
        search.add_search_path(&format!(
            "{}:{}",
            root.join("nowhere").display(),
            root.join("ws").display()
        ));

        write("package://my_robot/meshes/arm.stl");
        let m = RobotModel::from_urdf_file(&urdf, &search).unwrap();
        let Geometry::Mesh { path, uri, scale } = &m.links[0].visuals[0].geometry else {
            panic!()
        };
        assert_eq!(path, &root.join("ws/my_robot/meshes/arm.stl"));
        assert_eq!(uri, "package://my_robot/meshes/arm.stl");
        assert_eq!(*scale, Vec3::new(0.001, 0.001, 0.001));

        // An explicit mapping wins; the package is found without a search path.
        let mut explicit = PackageResolver::new();
        explicit
            .insert_arg(&format!("my_robot={}", root.join("ws/my_robot").display()))
            .unwrap();
        assert!(RobotModel::from_urdf_file(&urdf, &explicit).is_ok());

        // Unknown package: where it looked, and how to fix it.
        let e = RobotModel::from_urdf_file(&urdf, &PackageResolver::new()).unwrap_err();
        assert!(matches!(e, RobotError::PackageNotFound { .. }));
        assert!(
            e.to_string()
                .contains("package \"my_robot\" not found (looked in: nowhere"),
            "{e}"
        );
        assert!(
            e.to_string().contains("set ROS_PACKAGE_PATH")
                && e.to_string().contains("--package my_robot=DIR"),
            "{e}"
        );
        write("package://other_robot/meshes/arm.stl");
        let e = RobotModel::from_urdf_file(&urdf, &search).unwrap_err();
        let RobotError::PackageNotFound { searched, link, .. } = &e else {
            panic!("{e:?}")
        };
        assert_eq!(searched, &vec![root.join("nowhere"), root.join("ws")]);
        assert_eq!(link, "a");
        assert!(
            e.to_string()
                .contains(&root.join("ws").display().to_string()),
            "{e}"
        );

        // Package found, file missing: which link, which URI, where.
        write("package://my_robot/meshes/missing.stl");
        let e = RobotModel::from_urdf_file(&urdf, &search).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: link \"a\": mesh \"package://my_robot/meshes/missing.stl\" not found at {}",
                urdf.display(),
                root.join("ws/my_robot/meshes/missing.stl").display()
            )
        );

        // Relative paths are relative to the URDF file; file:// is a path.
        write("parts/local.stl");
        let m = RobotModel::from_urdf_file(&urdf, &PackageResolver::new()).unwrap();
        assert!(
            matches!(&m.links[0].visuals[0].geometry, Geometry::Mesh { path, .. } if *path == root.join("urdf/parts/local.stl"))
        );
        write(&format!(
            "file://{}",
            root.join("urdf/parts/local.stl").display()
        ));
        assert!(RobotModel::from_urdf_file(&urdf, &PackageResolver::new()).is_ok());
        write("parts/none.stl");
        let e = RobotModel::from_urdf_file(&urdf, &PackageResolver::new()).unwrap_err();
        assert!(matches!(e, RobotError::MeshNotFound { .. }), "{e:?}");
        write("http://example.com/arm.stl");
        let e = RobotModel::from_urdf_file(&urdf, &PackageResolver::new()).unwrap_err();
        assert!(matches!(e, RobotError::UnsupportedUri { .. }), "{e:?}");
        let _ = std::fs::remove_dir_all(&root);
    }

    proptest::proptest! {
        #[test]
        fn mutilated_urdf_never_panics(cut in 0usize..2000, len in 0usize..40, insert in "[<>/=\"a-z0-9 .-]{0,6}") {
            let start = cut.min(ARM.len());
            let end = (start + len).min(ARM.len());
            if ARM.is_char_boundary(start) && ARM.is_char_boundary(end) {
                let text = format!("{}{}{}", &ARM[..start], insert, &ARM[end..]);
                let _ = RobotModel::from_urdf_str(&text, Path::new("x"), &PackageResolver::new());
            }
        }
    }

    #[test]
    fn arbitrary_text_never_panics() {
        for text in [
            "",
            "<",
            "<robot",
            "<robot/>",
            "<?xml version=\"1.0\"?>",
            "\u{0}\u{1}",
            "<robot><link/></robot>",
            "<a><b></a>",
        ] {
            let _ = RobotModel::from_urdf_str(text, Path::new("x"), &PackageResolver::new());
        }
    }
}
