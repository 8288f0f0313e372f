//! Mesh files as triangle soups: STL (binary and ASCII) and COLLADA
//! (`.dae`: its `<unit>` and node transforms applied, `<up_axis>` not; see
//! `collada.rs`) read here, Wavefront OBJ with the `mesh-loader` crate, so
//! that every engine that builds its own collision shapes reads the three
//! formats URDFs in the wild use, and an engine that reads files itself
//! can be given a format it knows ([`TriangleMesh::to_binary_stl`]).

use crate::pose::Vec3;
use std::path::{Path, PathBuf};

mod collada;

/// A triangle soup read from an STL file, in the file's units (URDF meshes
/// are in metres).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriangleMesh {
    /// Triangle corners, three per triangle, counter-clockwise seen from
    /// outside (as STL stores them).
    pub triangles: Vec<[Vec3; 3]>,
}

/// Why a mesh file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum StlError {
    /// The file could not be read.
    #[error("cannot read mesh file {}: {reason}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The content is not a valid mesh of its format.
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

fn malformed(path: &Path, message: String) -> StlError {
    StlError::Malformed {
        path: path.to_path_buf(),
        line: None,
        message,
    }
}

/// The deepest nesting of COLLADA elements read: a document's scene graph
/// nests a few dozen levels at most (20 000 levels overflowed the stack of
/// the reader this project used before, `mesh-loader`).
pub const MAX_COLLADA_DEPTH: usize = 256;

/// 1-based line of a byte offset.
fn line_at(bytes: &[u8], offset: usize) -> usize {
    bytes[..offset.min(bytes.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Refuses COLLADA elements nested deeper than [`MAX_COLLADA_DEPTH`]
/// before the XML is parsed into a tree. Malformed XML is left to that
/// parser, which names it.
fn check_collada(bytes: &[u8], path: &Path) -> Result<(), StlError> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_reader(bytes);
    let mut buf = Vec::new();
    let mut depth = 0usize;
    loop {
        let before = reader.buffer_position() as usize;
        buf.clear();
        match reader.read_event_into(&mut buf) {
            Ok(Event::Start(_)) => {
                depth += 1;
                if depth > MAX_COLLADA_DEPTH {
                    return Err(StlError::Malformed {
                        path: path.to_path_buf(),
                        line: Some(line_at(bytes, before)),
                        message: format!(
                            "not a valid COLLADA mesh: elements nested more than {MAX_COLLADA_DEPTH} levels deep"
                        ),
                    });
                }
            }
            Ok(Event::End(_)) => depth = depth.saturating_sub(1),
            Ok(Event::Eof) | Err(_) => return Ok(()),
            Ok(_) => {}
        }
    }
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

/// The mesh formats read, by file extension (lower case).
pub const MESH_FORMATS: [&str; 3] = ["stl", "obj", "dae"];

/// The format of a mesh file by its extension: `stl`, `obj` or `dae`.
pub fn mesh_format(path: &Path) -> Option<&'static str> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    MESH_FORMATS.iter().copied().find(|f| *f == ext)
}

/// Refuses a mesh file whose format (by its extension) is not read: the
/// message names the mesh as the URDF wrote it (`uri`), the resolved path
/// and the engine.
pub fn require_mesh_format(path: &Path, uri: &str, engine: &str) -> Result<(), String> {
    match mesh_format(path) {
        Some(_) => Ok(()),
        None => Err(format!(
            "mesh \"{uri}\" ({}) is not a mesh format the {engine} engine reads (STL, OBJ, COLLADA .dae)",
            path.display()
        )),
    }
}

impl TriangleMesh {
    /// Reads a mesh file by its extension: STL (binary or ASCII; also any
    /// extension that is not `.obj` or `.dae`), Wavefront OBJ, COLLADA.
    pub fn read(path: &Path) -> Result<Self, StlError> {
        let bytes = std::fs::read(path).map_err(|reason| StlError::Io {
            path: path.to_path_buf(),
            reason,
        })?;
        match mesh_format(path) {
            Some("obj") => Self::parse_obj(&bytes, path),
            Some("dae") => Self::parse_collada(&bytes, path),
            _ => Self::parse(&bytes, path),
        }
    }

    /// Parses Wavefront OBJ content (its material library is not read);
    /// `path` names it in errors.
    pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<Self, StlError> {
        let scene = mesh_loader::obj::from_slice::<Vec<u8>, _>(bytes, Some(path), |_| {
            Err(std::io::Error::other("materials are not read"))
        })
        .map_err(|e| malformed(path, format!("not a valid Wavefront OBJ mesh: {e}")))?;
        Self::from_scene(scene, path)
    }

    /// Parses COLLADA content (`<unit>`, `<up_axis>` and node transforms
    /// applied); `path` names it in errors.
    pub fn parse_collada(bytes: &[u8], path: &Path) -> Result<Self, StlError> {
        check_collada(bytes, path)?;
        collada::parse(bytes, path)
    }

    fn from_scene(scene: mesh_loader::Scene, path: &Path) -> Result<Self, StlError> {
        let mut triangles = Vec::new();
        for mesh in &scene.meshes {
            for (k, face) in mesh.faces.iter().enumerate() {
                let mut corner = [Vec3::ZERO; 3];
                for (c, &i) in corner.iter_mut().zip(face) {
                    let v = mesh.vertices.get(i as usize).ok_or_else(|| {
                        malformed(
                            path,
                            format!(
                                "mesh \"{}\": face {} names vertex {} of {}",
                                mesh.name,
                                k + 1,
                                i as usize + 1,
                                mesh.vertices.len()
                            ),
                        )
                    })?;
                    *c = Vec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
                    if !(c.x.is_finite() && c.y.is_finite() && c.z.is_finite()) {
                        return Err(malformed(
                            path,
                            format!("mesh \"{}\": vertex {} is not finite", mesh.name, i + 1),
                        ));
                    }
                }
                triangles.push(corner);
            }
        }
        if triangles.is_empty() {
            return Err(malformed(path, "holds no triangle".into()));
        }
        Ok(TriangleMesh { triangles })
    }

    /// The mesh as a binary STL file's bytes (f32 corners, zero normals),
    /// for an engine that reads STL but not the mesh's own format.
    pub fn to_binary_stl(&self) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b[..22].copy_from_slice(b"realitygap binary STL ");
        b.extend_from_slice(&(self.triangles.len() as u32).to_le_bytes());
        for t in &self.triangles {
            b.extend_from_slice(&[0u8; 12]);
            for v in t {
                for c in [v.x, v.y, v.z] {
                    b.extend_from_slice(&(c as f32).to_le_bytes());
                }
            }
            b.extend_from_slice(&[0u8; 2]);
        }
        b
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

    const OBJ: &str = "# a tetrahedron\nmtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

    fn collada(unit: f64, up: &str, scale: f64) -> String {
        let p: Vec<String> = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
            .iter()
            .map(|x| format!("{}", x * scale))
            .collect();
        format!(
            r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><unit meter="{unit}"/><up_axis>{up}</up_axis></asset>
<library_geometries><geometry id="g"><mesh>
<source id="g-pos"><float_array id="g-arr" count="9">{}</float_array>
<technique_common><accessor source="#g-arr" count="3" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
<vertices id="g-v"><input semantic="POSITION" source="#g-pos"/></vertices>
<triangles count="1"><input semantic="VERTEX" source="#g-v" offset="0"/><p>0 1 2</p></triangles>
</mesh></geometry></library_geometries>
<library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#g"/></node></visual_scene></library_visual_scenes>
<scene><instance_visual_scene url="#s"/></scene>
</COLLADA>"##,
            p.join(" ")
        )
    }

    #[test]
    fn reads_obj_and_collada_with_units() {
        let dir = std::env::temp_dir().join(format!("rg-mesh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let obj = dir.join("t.OBJ");
        std::fs::write(&obj, OBJ).unwrap();
        let m = TriangleMesh::read(&obj).unwrap();
        assert_eq!(m.triangles.len(), 4);
        assert_eq!(m.aabb().unwrap().max, Vec3::new(1.0, 1.0, 1.0));
        // The same triangle in metres, and in millimetres with its unit.
        let a = dir.join("m.dae");
        std::fs::write(&a, collada(1.0, "Z_UP", 1.0)).unwrap();
        let b = dir.join("mm.dae");
        std::fs::write(&b, collada(0.001, "Z_UP", 1000.0)).unwrap();
        let (a, b) = (
            TriangleMesh::read(&a).unwrap(),
            TriangleMesh::read(&b).unwrap(),
        );
        assert_eq!(a.triangles.len(), 1);
        for (p, q) in a.triangles[0].iter().zip(&b.triangles[0]) {
            assert!((*p - *q).norm() < 1e-9, "{p:?} {q:?}");
        }
        // Written as STL, read back: the same triangles (f32).
        let stl = dir.join("back.stl");
        std::fs::write(&stl, m.to_binary_stl()).unwrap();
        assert_eq!(TriangleMesh::read(&stl).unwrap(), m);
        // Damaged files name the file and what is wrong.
        let bad = dir.join("bad.obj");
        std::fs::write(&bad, OBJ.replace("f 2 3 4", "f 2 3 99")).unwrap();
        let e = TriangleMesh::read(&bad).unwrap_err().to_string();
        assert!(
            e.contains("bad.obj") && e.contains("face index out of bounds"),
            "{e}"
        );
        let bad = dir.join("bad.dae");
        let text = collada(1.0, "Z_UP", 1.0);
        std::fs::write(&bad, &text[..text.len() / 2]).unwrap();
        let e = TriangleMesh::read(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.dae") && e.contains("COLLADA"), "{e}");
        let empty = dir.join("empty.obj");
        std::fs::write(&empty, "# nothing\n").unwrap();
        let e = TriangleMesh::read(&empty).unwrap_err().to_string();
        assert!(e.contains("no triangle"), "{e}");
        assert!(
            require_mesh_format(Path::new("x.ply"), "package://p/x.ply", "ODE")
                .unwrap_err()
                .contains("(STL, OBJ, COLLADA .dae)")
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

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

/// The independent writer's OBJ, COLLADA and ASCII STL copies of the
/// iiwa's binary STL meshes (`scripts/make-fixtures`, trimesh) read as the
/// same triangles.
#[cfg(test)]
mod fixture_tests {
    use super::*;

    #[test]
    fn the_writers_obj_and_collada_copies_are_the_stl_meshes() {
        let dir = crate::testing::workspace().join("third_party/fixtures/meshes");
        let info: String = std::fs::read_to_string(dir.join("meshes.json"))
            .unwrap_or_else(|e| panic!("{}: {e}: run scripts/setup --tests", dir.display()));
        let names: Vec<String> = info
            .lines()
            .filter_map(|l| l.trim().strip_prefix("\"stl\": \""))
            .map(|l| l.trim_end_matches("\",").to_string())
            .collect();
        assert_eq!(names.len(), 8, "{info}");
        for stl in names {
            let stl = Path::new(&stl);
            let stem = stl.file_stem().unwrap().to_str().unwrap();
            let a = TriangleMesh::read(stl).unwrap();
            for other in [
                dir.join(format!("obj/{stem}.obj")),
                dir.join(format!("dae/{stem}.dae")),
                dir.join(format!("stl_ascii/{stem}.stl")),
            ] {
                let b = TriangleMesh::read(&other).unwrap();
                assert_eq!(a.triangles.len(), b.triangles.len(), "{}", other.display());
                let (x, y) = (a.aabb().unwrap(), b.aabb().unwrap());
                let d = (x.min - y.min).norm().max((x.max - y.max).norm());
                assert!(d < 1e-5, "{}: bounds {x:?} vs {y:?}", other.display());
            }
        }
        for (bad, want) in [
            ("truncated.dae", "not a valid COLLADA mesh"),
            ("not_xml.dae", "not a valid COLLADA mesh"),
            ("bad_index.obj", "face index out of bounds"),
        ] {
            let path = dir.join("bad").join(bad);
            let e = TriangleMesh::read(&path).unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains(want), "{e}");
        }
    }
}
