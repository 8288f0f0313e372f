//! Collision shapes: a URDF [`Geometry`] becomes a Rapier [`SharedShape`]
//! and the pose of that shape in the geometry's own frame.
//!
//! - box, sphere, capsule (along z): Rapier's cuboid, ball, `capsule_z`;
//! - cylinder: Rapier's cylinders stand along y, URDF's along z, so the
//!   shape is turned by +90 degrees about x;
//! - mesh: an STL file (read by [`TriangleMesh`]) scaled per axis, as its
//!   convex hull or as a triangle mesh ([`MeshShape`]). Other mesh formats
//!   are refused with an error naming the link and the file. A file used by
//!   several links is read once per model.

use crate::settings::MeshShape;
use rapier3d::math::{Pose as RPose, Vector};
use rapier3d::prelude::{SharedShape, TriMeshFlags};
use realitygap_core::pose::Vec3;
use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::Geometry;
use std::collections::HashMap;
use std::f32::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

/// Flags of triangle-mesh shapes: STL stores every corner separately, so
/// duplicate vertices are merged (and degenerate or repeated triangles
/// dropped) to give the mesh a topology.
fn trimesh_flags() -> TriMeshFlags {
    TriMeshFlags::MERGE_DUPLICATE_VERTICES
        | TriMeshFlags::DELETE_DEGENERATE_TRIANGLES
        | TriMeshFlags::DELETE_DUPLICATE_TRIANGLES
}

/// Builds shapes for one model, reading each mesh file once.
#[derive(Default)]
pub struct ShapeBuilder {
    cache: HashMap<(PathBuf, [u64; 3], MeshShape), SharedShape>,
}

impl ShapeBuilder {
    /// A builder with an empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// The shape of `geometry` and its pose in the geometry's frame, or an
    /// error naming the file and what is wrong (the caller adds the link).
    pub fn shape(
        &mut self,
        geometry: &Geometry,
        mesh_shape: MeshShape,
    ) -> Result<(SharedShape, RPose), String> {
        let positive = |what: &str, v: f64| -> Result<f32, String> {
            if v.is_finite() && v > 0.0 {
                Ok(v as f32)
            } else {
                Err(format!("{what} must be positive and finite, found {v}"))
            }
        };
        Ok(match geometry {
            Geometry::Box { size_m } => (
                SharedShape::cuboid(
                    positive("box size x", size_m.x)? / 2.0,
                    positive("box size y", size_m.y)? / 2.0,
                    positive("box size z", size_m.z)? / 2.0,
                ),
                RPose::IDENTITY,
            ),
            Geometry::Sphere { radius_m } => (
                SharedShape::ball(positive("sphere radius", *radius_m)?),
                RPose::IDENTITY,
            ),
            Geometry::Cylinder { radius_m, length_m } => (
                SharedShape::cylinder(
                    positive("cylinder length", *length_m)? / 2.0,
                    positive("cylinder radius", *radius_m)?,
                ),
                RPose::rotation(Vector::X * FRAC_PI_2),
            ),
            Geometry::Capsule { radius_m, length_m } => {
                if !(length_m.is_finite() && *length_m >= 0.0) {
                    return Err(format!(
                        "capsule length must be >= 0 and finite, found {length_m}"
                    ));
                }
                (
                    SharedShape::capsule_z(
                        *length_m as f32 / 2.0,
                        positive("capsule radius", *radius_m)?,
                    ),
                    RPose::IDENTITY,
                )
            }
            Geometry::Mesh { path, uri, scale } => {
                (self.mesh(path, uri, *scale, mesh_shape)?, RPose::IDENTITY)
            }
        })
    }

    fn mesh(
        &mut self,
        path: &Path,
        uri: &str,
        scale: Vec3,
        mesh_shape: MeshShape,
    ) -> Result<SharedShape, String> {
        let key = (
            path.to_path_buf(),
            [scale.x.to_bits(), scale.y.to_bits(), scale.z.to_bits()],
            mesh_shape,
        );
        if let Some(shape) = self.cache.get(&key) {
            return Ok(shape.clone());
        }
        realitygap_core::robot::stl::require_mesh_format(path, uri, "Rapier")?;
        if !(scale.is_finite() && scale.x != 0.0 && scale.y != 0.0 && scale.z != 0.0) {
            return Err(format!(
                "mesh \"{uri}\": scale ({}, {}, {}) must be finite and non-zero",
                scale.x, scale.y, scale.z
            ));
        }
        let mesh = TriangleMesh::read(path).map_err(|e| format!("mesh \"{uri}\": {e}"))?;
        if mesh.triangles.is_empty() {
            return Err(format!(
                "mesh \"{uri}\" ({}) has no triangles",
                path.display()
            ));
        }
        if let Some(i) = mesh
            .triangles
            .iter()
            .position(|t| t.iter().any(|p| !p.is_finite()))
        {
            return Err(format!(
                "mesh \"{uri}\" ({}): triangle {} has a non-finite vertex",
                path.display(),
                i + 1
            ));
        }
        let to_vector = |p: &Vec3| {
            Vector::new(
                (p.x * scale.x) as f32,
                (p.y * scale.y) as f32,
                (p.z * scale.z) as f32,
            )
        };
        // A negative scale product mirrors the mesh: swap two corners to
        // keep the triangles facing outwards.
        let mirrored = scale.x * scale.y * scale.z < 0.0;
        let shape = match mesh_shape {
            MeshShape::ConvexHull => {
                let points: Vec<Vector> = mesh
                    .triangles
                    .iter()
                    .flat_map(|t| t.iter().map(to_vector))
                    .collect();
                SharedShape::convex_hull(&points).ok_or_else(|| {
                    format!("mesh \"{uri}\" ({}) is degenerate (its points lie on a line or a point): it has no convex hull", path.display())
                })?
            }
            MeshShape::TriMesh => {
                let mut vertices = Vec::with_capacity(mesh.triangles.len() * 3);
                let mut indices = Vec::with_capacity(mesh.triangles.len());
                for t in &mesh.triangles {
                    let i = vertices.len() as u32;
                    vertices.extend(t.iter().map(to_vector));
                    indices.push(if mirrored {
                        [i, i + 2, i + 1]
                    } else {
                        [i, i + 1, i + 2]
                    });
                }
                SharedShape::trimesh_with_flags(vertices, indices, trimesh_flags()).map_err(
                    |e| {
                        format!(
                            "mesh \"{uri}\" ({}): not a usable triangle mesh: {e}",
                            path.display()
                        )
                    },
                )?
            }
        };
        self.cache.insert(key, shape.clone());
        Ok(shape)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rapier3d::prelude::ShapeType;

    fn write_stl(dir: &std::path::Path, name: &str, tris: &[[[f32; 3]; 3]]) -> PathBuf {
        let mut bytes = vec![0u8; 80];
        bytes.extend((tris.len() as u32).to_le_bytes());
        for t in tris {
            bytes.extend([0u8; 12]);
            for v in t {
                for c in v {
                    bytes.extend(c.to_le_bytes());
                }
            }
            bytes.extend([0u8; 2]);
        }
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    fn tetrahedron() -> Vec<[[f32; 3]; 3]> {
        let (a, b, c, d) = (
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        );
        vec![[a, c, b], [a, b, d], [a, d, c], [b, c, d]]
    }

    fn mesh(path: PathBuf, scale: f64) -> Geometry {
        Geometry::Mesh {
            uri: path.display().to_string(),
            path,
            scale: Vec3::new(scale, scale, scale),
        }
    }

    #[test]
    fn primitives_have_urdf_sizes_and_axes() {
        let mut b = ShapeBuilder::new();
        let (s, p) = b
            .shape(
                &Geometry::Box {
                    size_m: Vec3::new(0.2, 0.4, 0.6),
                },
                MeshShape::ConvexHull,
            )
            .unwrap();
        assert_eq!(
            s.as_cuboid().unwrap().half_extents,
            Vector::new(0.1, 0.2, 0.3)
        );
        assert_eq!(p, RPose::IDENTITY);
        // A cylinder of length 0.5 along z: its half height lies along z
        // once turned.
        let (s, p) = b
            .shape(
                &Geometry::Cylinder {
                    radius_m: 0.1,
                    length_m: 0.5,
                },
                MeshShape::ConvexHull,
            )
            .unwrap();
        let c = s.as_cylinder().unwrap();
        assert!((c.half_height - 0.25).abs() < 1e-7 && (c.radius - 0.1).abs() < 1e-7);
        let axis = p.rotation * Vector::Y;
        assert!((axis - Vector::Z).length() < 1e-6, "{axis:?}");
        let (s, _) = b
            .shape(
                &Geometry::Capsule {
                    radius_m: 0.05,
                    length_m: 0.2,
                },
                MeshShape::ConvexHull,
            )
            .unwrap();
        let c = s.as_capsule().unwrap();
        assert!((c.segment.b - c.segment.a - Vector::new(0.0, 0.0, 0.2)).length() < 1e-6);
        let (s, _) = b
            .shape(&Geometry::Sphere { radius_m: 0.3 }, MeshShape::ConvexHull)
            .unwrap();
        assert_eq!(s.shape_type(), ShapeType::Ball);
    }

    #[test]
    fn rejects_bad_primitive_sizes() {
        let mut b = ShapeBuilder::new();
        let err = b
            .shape(
                &Geometry::Box {
                    size_m: Vec3::new(0.0, 1.0, 1.0),
                },
                MeshShape::ConvexHull,
            )
            .unwrap_err();
        assert!(err.contains("box size x must be positive"), "{err}");
        let err = b
            .shape(
                &Geometry::Sphere { radius_m: f64::NAN },
                MeshShape::ConvexHull,
            )
            .unwrap_err();
        assert!(err.contains("sphere radius"), "{err}");
    }

    #[test]
    fn meshes_as_hull_or_trimesh_scaled() {
        let dir = std::env::temp_dir().join(format!("rg-rapier-shapes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = write_stl(&dir, "tet.stl", &tetrahedron());
        let mut b = ShapeBuilder::new();
        let (hull, _) = b
            .shape(&mesh(path.clone(), 2.0), MeshShape::ConvexHull)
            .unwrap();
        assert_eq!(hull.shape_type(), ShapeType::ConvexPolyhedron);
        let aabb = hull.compute_local_aabb();
        assert!((aabb.maxs - Vector::splat(2.0)).length() < 1e-6, "{aabb:?}");
        let (tri, _) = b
            .shape(&mesh(path.clone(), 1.0), MeshShape::TriMesh)
            .unwrap();
        let tri = tri.as_trimesh().unwrap();
        assert_eq!(tri.num_triangles(), 4);
        assert_eq!(tri.vertices().len(), 4, "duplicate corners are merged");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn mesh_errors_name_the_file() {
        let dir =
            std::env::temp_dir().join(format!("rg-rapier-shape-errors-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut b = ShapeBuilder::new();
        let dae = dir.join("arm.dae");
        std::fs::write(&dae, "<COLLADA/>").unwrap();
        let err = b.shape(&mesh(dae, 1.0), MeshShape::ConvexHull).unwrap_err();
        assert!(
            err.contains("arm.dae") && err.contains("not a valid COLLADA mesh"),
            "{err}"
        );
        let missing = dir.join("gone.stl");
        let err = b
            .shape(&mesh(missing, 1.0), MeshShape::ConvexHull)
            .unwrap_err();
        assert!(err.contains("gone.stl"), "{err}");
        // A flat mesh is a plate; points on one line have no hull.
        let flat = write_stl(
            &dir,
            "flat.stl",
            &[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]],
        );
        assert!(b.shape(&mesh(flat, 1.0), MeshShape::ConvexHull).is_ok());
        let line = write_stl(
            &dir,
            "line.stl",
            &[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]],
        );
        let err = b
            .shape(&mesh(line, 1.0), MeshShape::ConvexHull)
            .unwrap_err();
        assert!(
            err.contains("line.stl") && err.contains("no convex hull"),
            "{err}"
        );
        let garbage = dir.join("garbage.stl");
        std::fs::write(&garbage, b"this is not an stl file").unwrap();
        let err = b
            .shape(&mesh(garbage, 1.0), MeshShape::TriMesh)
            .unwrap_err();
        assert!(err.contains("garbage.stl"), "{err}");
        let nan = write_stl(
            &dir,
            "nan.stl",
            &[[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]],
        );
        for shape in [MeshShape::ConvexHull, MeshShape::TriMesh] {
            let err = b.shape(&mesh(nan.clone(), 1.0), shape).unwrap_err();
            assert!(
                err.contains("nan.stl") && err.contains("triangle 1 has a non-finite vertex"),
                "{err}"
            );
        }
        let path = write_stl(&dir, "tet2.stl", &tetrahedron());
        let err = b.shape(&mesh(path, 0.0), MeshShape::TriMesh).unwrap_err();
        assert!(err.contains("non-zero"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
