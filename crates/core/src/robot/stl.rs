//! A small STL reader (binary and ASCII), enough to measure meshes and to
//! hand their triangles to an engine that cannot read STL itself.

use crate::pose::Vec3;
use std::path::{Path, PathBuf};

/// A triangle soup read from an STL file, in the file's units (URDF meshes
/// are in metres).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriangleMesh {
    /// Triangle corners, three per triangle, counter-clockwise seen from
    /// outside (as STL stores them).
    pub triangles: Vec<[Vec3; 3]>,
}

/// Why an STL file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum StlError {
    /// The file could not be read.
    #[error("cannot read STL file {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The content is neither valid binary nor valid ASCII STL.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// 1-based line, for ASCII files.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
}

/// An axis-aligned bounding box, in the mesh's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Smallest x, y, z.
    pub min: Vec3,
    /// Largest x, y, z.
    pub max: Vec3,
}

impl Aabb {
    /// Edge lengths along x, y, z.
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }
    /// Centre point.
    pub fn center(&self) -> Vec3 {
        self.min.lerp(self.max, 0.5)
    }
}

/// Refuses a mesh file that is not STL (by its extension), for engines
/// that read STL meshes only: the message names the mesh as the URDF wrote
/// it (`uri`), the resolved path and the engine.
pub fn require_stl(path: &Path, uri: &str, engine: &str) -> Result<(), String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext == "stl" {
        Ok(())
    } else {
        Err(format!(
            "mesh \"{uri}\" ({}) is not an STL file; the {engine} engine reads STL meshes only",
            path.display()
        ))
    }
}

impl TriangleMesh {
    /// Reads an STL file, binary or ASCII.
    pub fn read(path: &Path) -> Result<Self, StlError> {
        let bytes = std::fs::read(path).map_err(|source| StlError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&bytes, path)
    }

    /// Parses STL content; `path` names it in errors.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self, StlError> {
        // A binary STL's size is fixed by its triangle count; an ASCII file
        // starts with "solid" (binary headers sometimes do too, so the size
        // test comes first).
        if bytes.len() >= 84 {
            let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
            if n.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()) {
                return Ok(Self::parse_binary(&bytes[84..], n));
            }
        }
        let text = std::str::from_utf8(bytes).map_err(|_| StlError::Malformed {
            path: path.to_path_buf(),
            line: None,
            message:
                "neither a binary STL (size does not match the triangle count) nor UTF-8 ASCII STL"
                    .into(),
        })?;
        if !text.trim_start().starts_with("solid") {
            return Err(StlError::Malformed {
                path: path.to_path_buf(),
                line: Some(1),
                message: "ASCII STL must start with \"solid\"".into(),
            });
        }
        Self::parse_ascii(text, path)
    }

    fn parse_binary(body: &[u8], n: usize) -> Self {
        let f =
            |b: &[u8], k: usize| f32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]) as f64;
        let triangles = body
            .chunks_exact(50)
            .take(n)
            .map(|t| {
                let v =
                    |k: usize| Vec3::new(f(t, 12 + 12 * k), f(t, 16 + 12 * k), f(t, 20 + 12 * k));
                [v(0), v(1), v(2)]
            })
            .collect();
        TriangleMesh { triangles }
    }

    fn parse_ascii(text: &str, path: &Path) -> Result<Self, StlError> {
        let mut triangles = Vec::new();
        let mut corners: Vec<Vec3> = Vec::with_capacity(3);
        for (i, line) in text.lines().enumerate() {
            let mut words = line.split_whitespace();
            if words.next() != Some("vertex") {
                continue;
            }
            let coords: Vec<f64> = words.filter_map(|w| w.parse::<f64>().ok()).collect();
            if coords.len() != 3 || !coords.iter().all(|c| c.is_finite()) {
                return Err(StlError::Malformed {
                    path: path.to_path_buf(),
                    line: Some(i + 1),
                    message: format!(
                        "expected \"vertex X Y Z\" with three finite numbers, found \"{}\"",
                        line.trim()
                    ),
                });
            }
            corners.push(Vec3::new(coords[0], coords[1], coords[2]));
            if corners.len() == 3 {
                triangles.push([corners[0], corners[1], corners[2]]);
                corners.clear();
            }
        }
        if !corners.is_empty() {
            return Err(StlError::Malformed {
                path: path.to_path_buf(),
                line: None,
                message: "the number of vertices is not a multiple of 3".into(),
            });
        }
        Ok(TriangleMesh { triangles })
    }

    /// The bounding box of all vertices, `None` for an empty mesh.
    pub fn aabb(&self) -> Option<Aabb> {
        let mut it = self.triangles.iter().flatten();
        let first = *it.next()?;
        let (mut min, mut max) = (first, first);
        for v in it {
            min = Vec3::new(min.x.min(v.x), min.y.min(v.y), min.z.min(v.z));
            max = Vec3::new(max.x.max(v.x), max.y.max(v.y), max.z.max(v.z));
        }
        Some(Aabb { min, max })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binary_stl(tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b[..5].copy_from_slice(b"solid"); // a misleading header, as some exporters write
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
        b
    }

    #[test]
    fn reads_binary_and_ascii() {
        let bin = binary_stl(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, -1.0]]]);
        let m = TriangleMesh::parse(&bin, Path::new("t.stl")).unwrap();
        assert_eq!(m.triangles.len(), 1);
        let bb = m.aabb().unwrap();
        assert_eq!(bb.min, Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(bb.max, Vec3::new(1.0, 2.0, 0.0));

        let ascii = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0.5\nendloop\nendfacet\nendsolid x\n";
        let m = TriangleMesh::parse(ascii.as_bytes(), Path::new("a.stl")).unwrap();
        assert_eq!(m.aabb().unwrap().size(), Vec3::new(1.0, 1.0, 0.5));
    }

    #[test]
    fn rejects_garbage_with_file_and_line() {
        let e = TriangleMesh::parse(b"solid x\nvertex 0 0\n", Path::new("bad.stl")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "bad.stl:2: expected \"vertex X Y Z\" with three finite numbers, found \"vertex 0 0\""
        );
        let e = TriangleMesh::parse(&[0xff; 90], Path::new("bin.stl")).unwrap_err();
        assert!(
            e.to_string().starts_with("bin.stl: neither a binary STL"),
            "{e}"
        );
        let e = TriangleMesh::read(Path::new("/nonexistent/x.stl")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/x.stl"), "{e}");
    }
}
