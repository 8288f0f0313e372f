//! Collision shapes: a URDF [`Geometry`] becomes a PhysX shape, exclusive
//! to one actor, at a pose in the actor's frame.
//!
//! - box, sphere: PhysX's box and sphere;
//! - capsule: PhysX's capsules lie along x, URDF's along z, so the shape is
//!   turned by -90 degrees about y;
//! - cylinder: PhysX has no cylinder; a convex mesh of two 32-gons (a
//!   prism whose faces are within 0.5 % of the radius of the cylinder);
//! - mesh: an STL file (read by [`TriangleMesh`]) cooked as the convex
//!   hull of its vertices, scaled per axis. PhysX keeps at most 255 hull
//!   vertices: a larger hull is cropped to that by its bounding box, which
//!   makes the shape slightly larger than the true hull. Every shape here belongs to an
//!   articulation link or a dynamic object, and PhysX collides triangle
//!   meshes only on static and kinematic actors, so a mesh is always its
//!   convex hull (MuJoCo collides with the hull too). Other mesh formats are
//!   refused with an error naming the file.
//!
//! Cooked meshes are kept for the life of the process, one per file (and
//! one per cylinder size): tuning loads the same model thousands of times.

use crate::sdk::{said, Locked, Sdk};
use physx_sys::*;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::Geometry;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Sides of the prism that stands for a cylinder.
const CYLINDER_SIDES: usize = 32;

/// A cooked convex mesh, shared by every simulation of the process.
#[derive(Clone, Copy)]
struct Cooked(*mut PxConvexMesh);

// SAFETY: a cooked convex mesh is immutable and reference counted by
// PhysX; shapes on any thread may refer to it. It is only used while the
// SDK lock is held (creating shapes).
unsafe impl Send for Cooked {}

/// Cooked meshes by source: a file path, or a cylinder's radius and length
/// (bits of the f64s).
#[derive(Hash, PartialEq, Eq, Clone)]
enum MeshKey {
    File(PathBuf),
    Cylinder(u64, u64),
}

static COOKED: Mutex<Option<HashMap<MeshKey, Cooked>>> = Mutex::new(None);

/// A shape's geometry, ready for `PxPhysics::createShape`.
pub enum ShapeGeometry {
    /// A box.
    Box(PxBoxGeometry),
    /// A sphere.
    Sphere(PxSphereGeometry),
    /// A capsule along x.
    Capsule(PxCapsuleGeometry),
    /// A convex mesh with its scale.
    Convex(PxConvexMeshGeometry),
}

impl ShapeGeometry {
    /// The geometry as PhysX's base type.
    pub fn as_ptr(&self) -> *const PxGeometry {
        match self {
            ShapeGeometry::Box(g) => g as *const _ as *const PxGeometry,
            ShapeGeometry::Sphere(g) => g as *const _ as *const PxGeometry,
            ShapeGeometry::Capsule(g) => g as *const _ as *const PxGeometry,
            ShapeGeometry::Convex(g) => g as *const _ as *const PxGeometry,
        }
    }
}

fn positive(what: &str, v: f64) -> Result<f32, String> {
    if v.is_finite() && v > 0.0 && (v as f32).is_normal() {
        Ok(v as f32)
    } else {
        Err(format!("{what} must be positive and finite, found {v}"))
    }
}

/// The PhysX geometry of `geometry` and its pose in the geometry's own
/// frame, or an error naming what is wrong (the caller adds the link).
pub fn geometry(
    sdk: &Sdk,
    locked: &Locked<'_>,
    geometry: &Geometry,
) -> Result<(ShapeGeometry, Pose), String> {
    // SAFETY: constructors of plain geometry structs.
    Ok(unsafe {
        match geometry {
            Geometry::Box { size_m } => (
                ShapeGeometry::Box(PxBoxGeometry_new(
                    positive("box size x", size_m.x)? / 2.0,
                    positive("box size y", size_m.y)? / 2.0,
                    positive("box size z", size_m.z)? / 2.0,
                )),
                Pose::IDENTITY,
            ),
            Geometry::Sphere { radius_m } => (
                ShapeGeometry::Sphere(PxSphereGeometry_new(positive("sphere radius", *radius_m)?)),
                Pose::IDENTITY,
            ),
            Geometry::Capsule { radius_m, length_m } => {
                if !(length_m.is_finite() && *length_m >= 0.0) {
                    return Err(format!(
                        "capsule length must be >= 0 and finite, found {length_m}"
                    ));
                }
                let r = positive("capsule radius", *radius_m)?;
                (
                    ShapeGeometry::Capsule(PxCapsuleGeometry_new(r, *length_m as f32 / 2.0)),
                    Pose::new(Vec3::ZERO, x_to_z()),
                )
            }
            Geometry::Cylinder { radius_m, length_m } => {
                let r = positive("cylinder radius", *radius_m)?;
                let l = positive("cylinder length", *length_m)?;
                let key = MeshKey::Cylinder(radius_m.to_bits(), length_m.to_bits());
                let mesh = cooked(sdk, locked, key, || Ok(cylinder_points(r, l)))?;
                (convex(mesh, Vec3::new(1.0, 1.0, 1.0)), Pose::IDENTITY)
            }
            Geometry::Mesh { path, uri, scale } => {
                for (axis, s) in [("x", scale.x), ("y", scale.y), ("z", scale.z)] {
                    positive(&format!("mesh \"{uri}\": scale {axis}"), s)?;
                }
                let key = MeshKey::File(path.clone());
                let mesh = cooked(sdk, locked, key, || mesh_points(path, uri))?;
                (convex(mesh, *scale), Pose::IDENTITY)
            }
        }
    })
}

/// The rotation that turns PhysX's capsule axis (x) onto URDF's (z):
/// -90 degrees about y.
fn x_to_z() -> Quat {
    let h = std::f64::consts::FRAC_PI_4;
    Quat::new(h.cos(), 0.0, -h.sin(), 0.0)
}

fn convex(mesh: Cooked, scale: Vec3) -> ShapeGeometry {
    // SAFETY: `mesh` is a valid cooked mesh kept for the process's life;
    // the scale was checked positive.
    unsafe {
        let s = PxVec3_new_3(scale.x as f32, scale.y as f32, scale.z as f32);
        let q = PxQuat_new_1(PxIDENTITY::PxIdentity);
        let scale = PxMeshScale_new_3(&s, &q);
        ShapeGeometry::Convex(PxConvexMeshGeometry_new(
            mesh.0,
            &scale,
            PxConvexMeshGeometryFlags::empty(),
        ))
    }
}

/// The vertices of a prism of [`CYLINDER_SIDES`] sides around z: its
/// corners on the cylinder's circles, its side faces at most 0.5 % of the
/// radius inside the cylinder's surface.
fn cylinder_points(radius: f32, length: f32) -> Vec<PxVec3> {
    let mut points = Vec::with_capacity(2 * CYLINDER_SIDES);
    for i in 0..CYLINDER_SIDES {
        let a = i as f32 * std::f32::consts::TAU / CYLINDER_SIDES as f32;
        for z in [-length / 2.0, length / 2.0] {
            points.push(PxVec3 {
                x: radius * a.cos(),
                y: radius * a.sin(),
                z,
            });
        }
    }
    points
}

/// The vertices of a mesh file (STL, OBJ, COLLADA), or an error naming
/// the file.
fn mesh_points(path: &Path, uri: &str) -> Result<Vec<PxVec3>, String> {
    realitygap_core::robot::stl::require_mesh_format(path, uri, "PhysX")?;
    let mesh = TriangleMesh::read(path).map_err(|e| format!("mesh \"{uri}\": {e}"))?;
    let points: Vec<PxVec3> = mesh
        .triangles
        .iter()
        .flatten()
        .map(|v| PxVec3 {
            x: v.x as f32,
            y: v.y as f32,
            z: v.z as f32,
        })
        .collect();
    if points.len() < 4 {
        return Err(format!(
            "mesh \"{uri}\" ({}) has {} vertices; a convex hull needs at least 4",
            path.display(),
            points.len()
        ));
    }
    Ok(points)
}

/// The cooked mesh of `key`, cooking the convex hull of `points()` on
/// first use.
fn cooked(
    sdk: &Sdk,
    locked: &Locked<'_>,
    key: MeshKey,
    points: impl FnOnce() -> Result<Vec<PxVec3>, String>,
) -> Result<Cooked, String> {
    let mut cache = COOKED.lock().unwrap_or_else(|e| e.into_inner());
    let cache = cache.get_or_insert_with(HashMap::new);
    if let Some(&mesh) = cache.get(&key) {
        return Ok(mesh);
    }
    let points = points()?;
    // SAFETY: the descriptor points into `points`, alive during the call;
    // the physics' insertion callback registers the mesh with the SDK
    // (under the SDK lock held by `locked`).
    let mesh = unsafe {
        let mut desc = PxConvexMeshDesc_new();
        desc.points.count = points.len() as u32;
        desc.points.stride = std::mem::size_of::<PxVec3>() as u32;
        desc.points.data = points.as_ptr() as *const std::ffi::c_void;
        desc.flags = PxConvexFlags::ComputeConvex;
        let mut result = PxConvexMeshCookingResult::Success;
        let insertion = PxPhysics_getPhysicsInsertionCallback_mut(locked.physics);
        phys_PxCreateConvexMesh(&sdk.cooking, &desc, insertion, &mut result)
    };
    if mesh.is_null() {
        let what = match &key {
            MeshKey::File(p) => format!("the mesh {}", p.display()),
            MeshKey::Cylinder(..) => "a cylinder".to_string(),
        };
        return Err(format!(
            "PhysX could not cook the convex hull of {what} ({} vertices){}",
            points.len(),
            said()
        ));
    }
    cache.insert(key, Cooked(mesh));
    Ok(Cooked(mesh))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn x_to_z_turns_the_capsule_axis() {
        let z = x_to_z().rotate(Vec3::new(1.0, 0.0, 0.0));
        assert!(z.distance(Vec3::new(0.0, 0.0, 1.0)) < 1e-12, "{z:?}");
    }

    #[test]
    fn cylinder_prism_has_both_caps() {
        let p = cylinder_points(0.1, 0.4);
        assert_eq!(p.len(), 2 * CYLINDER_SIDES);
        assert!(p.iter().all(|v| (v.x.hypot(v.y) - 0.1).abs() < 1e-6));
        assert!(p.iter().all(|v| (v.z.abs() - 0.2).abs() < 1e-6));
    }

    #[test]
    fn unknown_mesh_formats_are_refused_naming_the_file() {
        let Err(e) = mesh_points(Path::new("/x/arm.ply"), "package://p/arm.ply") else {
            panic!("a PLY file was read");
        };
        assert!(
            e.contains("package://p/arm.ply") && e.contains("STL, OBJ, COLLADA .dae"),
            "{e}"
        );
    }
}
