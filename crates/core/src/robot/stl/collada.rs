//! COLLADA (`.dae`) meshes as triangles: the document's geometries as its
//! visual scene instantiates them (node transforms: `matrix`, `translate`,
//! `rotate`, `scale`; `instance_node`), in metres by its `<unit>`.
//! `<up_axis>` is not applied: robot meshes are exported `Z_UP`, as the
//! URDF's frames are.
//!
//! Read here rather than by a general 3D-model crate so that every damaged
//! file is an error naming the file and the line: counts and indices are
//! checked against what the file holds before anything is allocated for
//! them, references to missing elements and out-of-range indices are
//! errors, nesting is bounded, and a document cannot instantiate more
//! triangles than its size could describe.

use super::{StlError, TriangleMesh, MAX_COLLADA_DEPTH};
use crate::pose::Vec3;
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::Path;

/// A 4x4 transform, row-major, acting on column vectors.
type Matrix = [[f64; 4]; 4];

const IDENTITY: Matrix = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

fn mul(a: &Matrix, b: &Matrix) -> Matrix {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..4).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(m: &Matrix, v: [f64; 3]) -> Vec3 {
    let row = |i: usize| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2] + m[i][3];
    Vec3::new(row(0), row(1), row(2))
}

fn det3(m: &Matrix) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// A reader of one document, for errors with the file and line.
struct Reader<'a, 'input> {
    doc: &'a Document<'input>,
    path: &'a Path,
    /// Elements by `id`.
    ids: HashMap<&'a str, Node<'a, 'input>>,
}

/// A geometry's triangles as indices into its positions.
struct Geometry {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl<'a, 'input> Reader<'a, 'input> {
    fn error(&self, node: Node<'_, '_>, message: String) -> StlError {
        let line = self.doc.text_pos_at(node.range().start).row as usize;
        StlError::Malformed {
            path: self.path.to_path_buf(),
            line: Some(line),
            message: format!("not a valid COLLADA mesh: {message}"),
        }
    }

    /// The element a `#id` URL names.
    fn target(
        &self,
        node: Node<'a, 'input>,
        attribute: &str,
    ) -> Result<Node<'a, 'input>, StlError> {
        let url = node.attribute(attribute).ok_or_else(|| {
            self.error(
                node,
                format!("<{}> has no {attribute}", node.tag_name().name()),
            )
        })?;
        let id = url.strip_prefix('#').ok_or_else(|| {
            self.error(
                node,
                format!("{attribute} \"{url}\" is not a reference within the file (#id)"),
            )
        })?;
        self.ids.get(id).copied().ok_or_else(|| {
            self.error(
                node,
                format!("{attribute} \"{url}\" names no element of the file"),
            )
        })
    }

    fn child(&self, node: Node<'a, 'input>, name: &str) -> Option<Node<'a, 'input>> {
        node.children().find(|c| c.has_tag_name(name))
    }

    /// A non-negative integer attribute, `default` when absent.
    fn count(
        &self,
        node: Node<'_, '_>,
        attribute: &str,
        default: Option<u64>,
    ) -> Result<u64, StlError> {
        match node.attribute(attribute) {
            Some(v) => v.trim().parse::<u64>().map_err(|_| {
                self.error(
                    node,
                    format!(
                        "<{}> {attribute}=\"{v}\" is not a non-negative integer",
                        node.tag_name().name()
                    ),
                )
            }),
            None => default.ok_or_else(|| {
                self.error(
                    node,
                    format!("<{}> has no {attribute}", node.tag_name().name()),
                )
            }),
        }
    }

    /// The numbers of an element's text.
    fn floats(&self, node: Node<'_, '_>) -> Result<Vec<f64>, StlError> {
        let text = node.text().unwrap_or("");
        text.split_ascii_whitespace()
            .enumerate()
            .map(|(i, w)| {
                w.parse::<f64>().map_err(|_| {
                    self.error(
                        node,
                        format!(
                            "value {} of <{}> (\"{w}\") is not a number",
                            i + 1,
                            node.tag_name().name()
                        ),
                    )
                })
            })
            .collect()
    }

    /// The indices of an element's text.
    fn indices(&self, node: Node<'_, '_>) -> Result<Vec<u32>, StlError> {
        let text = node.text().unwrap_or("");
        text.split_ascii_whitespace()
            .enumerate()
            .map(|(i, w)| {
                w.parse::<u32>().map_err(|_| {
                    self.error(
                        node,
                        format!(
                            "index {} of <{}> (\"{w}\") is not a non-negative integer",
                            i + 1,
                            node.tag_name().name()
                        ),
                    )
                })
            })
            .collect()
    }

    /// The positions of a `<source>`: its float array read through its
    /// accessor (the params named X, Y, Z, else the first three).
    fn positions(&self, source: Node<'a, 'input>) -> Result<Vec<[f64; 3]>, StlError> {
        let accessor = self
            .child(source, "technique_common")
            .and_then(|t| self.child(t, "accessor"))
            .ok_or_else(|| {
                self.error(
                    source,
                    "the position <source> has no <technique_common><accessor>".into(),
                )
            })?;
        let array = self.target(accessor, "source")?;
        if !array.has_tag_name("float_array") {
            return Err(self.error(
                accessor,
                "the accessor's source is not a <float_array>".into(),
            ));
        }
        let values = self.floats(array)?;
        let declared = self.count(array, "count", None)?;
        if declared != values.len() as u64 {
            return Err(self.error(
                array,
                format!(
                    "<float_array> count=\"{declared}\" but it holds {} values",
                    values.len()
                ),
            ));
        }
        let count = self.count(accessor, "count", None)?;
        let stride = self.count(accessor, "stride", Some(1))?;
        let offset = self.count(accessor, "offset", Some(0))?;
        let params: Vec<Node> = accessor
            .children()
            .filter(|c| c.has_tag_name("param"))
            .collect();
        let named = |axis: &str| {
            params
                .iter()
                .position(|p| p.attribute("name") == Some(axis))
        };
        let slots: Vec<usize> = match (named("X"), named("Y"), named("Z")) {
            (Some(x), Some(y), Some(z)) => vec![x, y, z],
            _ if params.len() >= 3 => vec![0, 1, 2],
            _ => {
                return Err(self.error(
                    accessor,
                    "a position accessor needs three <param>s (X, Y, Z)".into(),
                ))
            }
        };
        if stride < params.len() as u64 {
            return Err(self.error(
                accessor,
                format!(
                    "stride {stride} is smaller than its {} <param>s",
                    params.len()
                ),
            ));
        }
        // The last value read must be in the array (u128: no overflow).
        let needed = if count == 0 {
            0
        } else {
            u128::from(offset) + u128::from(count - 1) * u128::from(stride) + params.len() as u128
        };
        if needed > values.len() as u128 {
            return Err(self.error(
                accessor,
                format!(
                    "count {count}, stride {stride} and offset {offset} read past the {} values of its array",
                    values.len()
                ),
            ));
        }
        let (offset, stride) = (offset as usize, stride as usize);
        Ok((0..count as usize)
            .map(|i| {
                let base = offset + i * stride;
                [
                    values[base + slots[0]],
                    values[base + slots[1]],
                    values[base + slots[2]],
                ]
            })
            .collect())
    }

    /// A `<geometry>`'s triangles (its `<mesh>`; other kinds hold none).
    fn geometry(&self, geometry: Node<'a, 'input>) -> Result<Geometry, StlError> {
        let mut out = Geometry {
            positions: Vec::new(),
            triangles: Vec::new(),
        };
        let Some(mesh) = self.child(geometry, "mesh") else {
            return Ok(out);
        };
        let vertices = self
            .child(mesh, "vertices")
            .ok_or_else(|| self.error(mesh, "<mesh> has no <vertices>".into()))?;
        let position = vertices
            .children()
            .find(|c| c.has_tag_name("input") && c.attribute("semantic") == Some("POSITION"))
            .ok_or_else(|| self.error(vertices, "<vertices> has no POSITION input".into()))?;
        let source = self.target(position, "source")?;
        out.positions = self.positions(source)?;
        let vertex_count = out.positions.len();
        for primitive in mesh.children().filter(|c| c.is_element()) {
            let kind = primitive.tag_name().name();
            if !matches!(
                kind,
                "triangles" | "polylist" | "polygons" | "trifans" | "tristrips"
            ) {
                continue; // lines, linestrips, sources, vertices, extras
            }
            let inputs: Vec<Node> = primitive
                .children()
                .filter(|c| c.has_tag_name("input"))
                .collect();
            let mut stride = 0u64;
            let mut vertex_offset = None;
            for input in &inputs {
                let offset = self.count(*input, "offset", None)?;
                stride = stride.max(offset + 1);
                if input.attribute("semantic") == Some("VERTEX") {
                    let target = self.target(*input, "source")?;
                    if target != vertices {
                        return Err(self.error(
                            *input,
                            "the VERTEX input does not name the mesh's <vertices>".into(),
                        ));
                    }
                    vertex_offset = Some(offset);
                }
            }
            let vertex_offset = vertex_offset
                .ok_or_else(|| self.error(primitive, format!("<{kind}> has no VERTEX input")))?;
            let count = self.count(primitive, "count", None)?;
            // Vertex indices, and the sizes of the polygons, strips or fans
            // they make in order.
            let mut runs: Vec<(Vec<u32>, Vec<u32>)> = Vec::new();
            let vertex_of = |p: &[u32], node: Node<'_, '_>| -> Result<Vec<u32>, StlError> {
                if !(p.len() as u64).is_multiple_of(stride) {
                    return Err(self.error(
                        node,
                        format!(
                            "{} indices do not make whole vertices of {stride} indices each (by the inputs' offsets)",
                            p.len()
                        ),
                    ));
                }
                p.chunks(stride as usize)
                    .map(|tuple| {
                        let v = tuple[vertex_offset as usize];
                        if v as usize >= vertex_count {
                            Err(self.error(
                                node,
                                format!("index {v} names a vertex past the last ({vertex_count})"),
                            ))
                        } else {
                            Ok(v)
                        }
                    })
                    .collect()
            };
            let ps: Vec<Node> = primitive
                .children()
                .filter(|c| c.has_tag_name("p"))
                .collect();
            match kind {
                "triangles" | "polylist" => {
                    let Some(&p) = ps.first() else {
                        if count == 0 {
                            continue;
                        }
                        return Err(
                            self.error(primitive, format!("<{kind}> count=\"{count}\" has no <p>"))
                        );
                    };
                    let v = vertex_of(&self.indices(p)?, p)?;
                    let sizes: Vec<u32> = if kind == "triangles" {
                        if count.checked_mul(3) != Some(v.len() as u64) {
                            return Err(self.error(
                                p,
                                format!(
                                    "<triangles> count=\"{count}\" but <p> holds {} vertices",
                                    v.len()
                                ),
                            ));
                        }
                        vec![3; count as usize]
                    } else {
                        let vcount = self.child(primitive, "vcount").ok_or_else(|| {
                            self.error(primitive, "<polylist> has no <vcount>".into())
                        })?;
                        let sizes = self.indices(vcount)?;
                        if sizes.len() as u64 != count {
                            return Err(self.error(
                                vcount,
                                format!(
                                    "<polylist> count=\"{count}\" but <vcount> holds {}",
                                    sizes.len()
                                ),
                            ));
                        }
                        let total: u64 = sizes.iter().map(|&n| u64::from(n)).sum();
                        if total != v.len() as u64 {
                            return Err(self.error(
                                p,
                                format!(
                                    "<vcount> adds up to {total} vertices but <p> holds {}",
                                    v.len()
                                ),
                            ));
                        }
                        sizes
                    };
                    runs.push((v, sizes));
                }
                _ => {
                    if kind == "polygons" && primitive.children().any(|c| c.has_tag_name("ph")) {
                        return Err(self.error(
                            primitive,
                            "<polygons> with holes (<ph>) are not supported".into(),
                        ));
                    }
                    if ps.len() as u64 != count {
                        return Err(self.error(
                            primitive,
                            format!("<{kind}> count=\"{count}\" but it holds {} <p>", ps.len()),
                        ));
                    }
                    for p in ps {
                        let v = vertex_of(&self.indices(p)?, p)?;
                        let n = v.len() as u32;
                        runs.push((v, vec![n]));
                    }
                }
            }
            for (v, sizes) in runs {
                let mut at = 0;
                for n in sizes {
                    let run = &v[at..at + n as usize];
                    at += n as usize;
                    if run.len() < 3 {
                        return Err(self.error(
                            primitive,
                            format!(
                                "a polygon, strip or fan of <{kind}> has {} vertices (at least 3)",
                                run.len()
                            ),
                        ));
                    }
                    for i in 0..run.len() - 2 {
                        out.triangles.push(match kind {
                            "tristrips" if i % 2 == 1 => [run[i + 1], run[i], run[i + 2]],
                            "tristrips" => [run[i], run[i + 1], run[i + 2]],
                            _ => [run[0], run[i + 1], run[i + 2]],
                        });
                    }
                }
            }
        }
        Ok(out)
    }

    /// A node's own transform: its transform elements in document order.
    fn local(&self, node: Node<'_, '_>) -> Result<Matrix, StlError> {
        let mut m = IDENTITY;
        for t in node.children().filter(|c| c.is_element()) {
            let name = t.tag_name().name();
            let expected = match name {
                "matrix" => 16,
                "translate" | "scale" => 3,
                "rotate" => 4,
                "lookat" | "skew" => {
                    return Err(
                        self.error(t, format!("the node transform <{name}> is not supported"))
                    );
                }
                _ => continue,
            };
            let v = self.floats(t)?;
            if v.len() != expected || !v.iter().all(|x| x.is_finite()) {
                return Err(self.error(
                    t,
                    format!("<{name}> needs {expected} finite numbers, found {:?}", v),
                ));
            }
            let step = match name {
                "matrix" => std::array::from_fn(|i| std::array::from_fn(|j| v[4 * i + j])),
                "translate" => {
                    let mut s = IDENTITY;
                    (s[0][3], s[1][3], s[2][3]) = (v[0], v[1], v[2]);
                    s
                }
                "scale" => {
                    let mut s = IDENTITY;
                    (s[0][0], s[1][1], s[2][2]) = (v[0], v[1], v[2]);
                    s
                }
                _ => {
                    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                    if n < 1e-12 {
                        return Err(self.error(t, "<rotate> has a zero axis".into()));
                    }
                    let (x, y, z) = (v[0] / n, v[1] / n, v[2] / n);
                    let (s, c) = v[3].to_radians().sin_cos();
                    let k = 1.0 - c;
                    [
                        [c + x * x * k, x * y * k - z * s, x * z * k + y * s, 0.0],
                        [y * x * k + z * s, c + y * y * k, y * z * k - x * s, 0.0],
                        [z * x * k - y * s, z * y * k + x * s, c + z * z * k, 0.0],
                        [0.0, 0.0, 0.0, 1.0],
                    ]
                }
            };
            m = mul(&m, &step);
        }
        Ok(m)
    }

    /// Every geometry instance under `root` with its transform (depth
    /// first, `instance_node` followed), at most [`MAX_COLLADA_DEPTH`]
    /// levels and `max_instances` instances.
    fn instances(
        &self,
        root: Node<'a, 'input>,
        base: Matrix,
        max_instances: usize,
    ) -> Result<Vec<(Node<'a, 'input>, Matrix)>, StlError> {
        let mut out = Vec::new();
        let mut stack: Vec<(Node<'a, 'input>, Matrix, usize)> = root
            .children()
            .filter(|c| c.has_tag_name("node"))
            .map(|c| (c, base, 1))
            .collect();
        stack.reverse();
        while let Some((node, parent, depth)) = stack.pop() {
            if depth > MAX_COLLADA_DEPTH {
                return Err(self.error(
                    node,
                    format!(
                        "nodes nest (with instance_node) more than {MAX_COLLADA_DEPTH} levels deep"
                    ),
                ));
            }
            let world = mul(&parent, &self.local(node)?);
            let mut children = Vec::new();
            for c in node.children().filter(|c| c.is_element()) {
                match c.tag_name().name() {
                    "instance_geometry" => {
                        let g = self.target(c, "url")?;
                        if !g.has_tag_name("geometry") {
                            return Err(self.error(
                                c,
                                "<instance_geometry> does not name a <geometry>".into(),
                            ));
                        }
                        if out.len() == max_instances {
                            return Err(self.error(
                                c,
                                format!("more than {max_instances} geometry instances"),
                            ));
                        }
                        out.push((g, world));
                    }
                    "instance_node" => {
                        let n = self.target(c, "url")?;
                        if !n.has_tag_name("node") {
                            return Err(
                                self.error(c, "<instance_node> does not name a <node>".into())
                            );
                        }
                        children.push((n, world, depth + 1));
                    }
                    "node" => children.push((c, world, depth + 1)),
                    _ => {}
                }
            }
            stack.extend(children.into_iter().rev());
        }
        Ok(out)
    }
}

/// Parses COLLADA text; `path` names it in errors.
pub(super) fn parse(bytes: &[u8], path: &Path) -> Result<TriangleMesh, StlError> {
    let bad = |line: Option<usize>, message: String| StlError::Malformed {
        path: path.to_path_buf(),
        line,
        message: format!("not a valid COLLADA mesh: {message}"),
    };
    let text = std::str::from_utf8(bytes).map_err(|e| {
        bad(
            Some(super::line_at(bytes, e.valid_up_to())),
            "not UTF-8 text".into(),
        )
    })?;
    let doc = Document::parse(text).map_err(|e| bad(Some(e.pos().row as usize), e.to_string()))?;
    let root = doc.root_element();
    if !root.has_tag_name("COLLADA") {
        return Err(bad(
            Some(1),
            format!(
                "the root element is <{}>, not <COLLADA>",
                root.tag_name().name()
            ),
        ));
    }
    let reader = Reader {
        doc: &doc,
        path,
        ids: doc
            .descendants()
            .filter_map(|n| Some((n.attribute("id")?, n)))
            .collect(),
    };
    let unit = match root
        .children()
        .find(|c| c.has_tag_name("asset"))
        .and_then(|a| reader.child(a, "unit"))
    {
        Some(u) => {
            let meter = u.attribute("meter").unwrap_or("1");
            match meter.trim().parse::<f64>() {
                Ok(m) if m.is_finite() && m > 0.0 => m,
                _ => {
                    return Err(reader.error(
                        u,
                        format!("<unit meter=\"{meter}\"> is not a positive number"),
                    ))
                }
            }
        }
        None => 1.0,
    };
    let mut base = IDENTITY;
    for (i, row) in base.iter_mut().take(3).enumerate() {
        row[i] = unit;
    }
    // Which geometries, where: the visual scene's instances, else (a
    // document whose scene instantiates none) every geometry once.
    let max_instances = 1 << 16;
    let scene = root
        .children()
        .find(|c| c.has_tag_name("scene"))
        .and_then(|s| reader.child(s, "instance_visual_scene"));
    let mut instances = match scene {
        Some(s) => reader.instances(reader.target(s, "url")?, base, max_instances)?,
        None => Vec::new(),
    };
    if instances.is_empty() {
        instances = doc
            .descendants()
            .filter(|n| n.has_tag_name("geometry"))
            .map(|g| (g, base))
            .collect();
    }
    let mut geometries: HashMap<roxmltree::NodeId, Geometry> = HashMap::new();
    let mut total: u64 = 0;
    for (g, _) in &instances {
        let geometry = match geometries.entry(g.id()) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => e.insert(reader.geometry(*g)?),
        };
        total += geometry.triangles.len() as u64;
    }
    // Instancing multiplies triangles: at most one per two bytes of file,
    // what a file without instances could describe.
    let most = bytes.len() as u64 / 2;
    if total > most {
        return Err(bad(
            None,
            format!(
                "its scene instantiates {total} triangles, more than a file of {} bytes describes",
                bytes.len()
            ),
        ));
    }
    let mut triangles = Vec::with_capacity(total as usize);
    for (g, m) in &instances {
        let geometry = &geometries[&g.id()];
        let flip = det3(m) < 0.0;
        for t in &geometry.triangles {
            let id = || g.attribute("id").unwrap_or("");
            for &i in t {
                let [x, y, z] = geometry.positions[i as usize];
                if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                    return Err(reader.error(
                        *g,
                        format!(
                            "geometry \"{}\": vertex {i} is not finite ({x}, {y}, {z})",
                            id()
                        ),
                    ));
                }
            }
            let mut corner = t.map(|i| apply(m, geometry.positions[i as usize]));
            if flip {
                corner.swap(1, 2);
            }
            if let Some(v) = corner.iter().find(|c| !c.is_finite()) {
                return Err(reader.error(
                    *g,
                    format!(
                        "geometry \"{}\": a vertex is not finite ({}, {}, {}) once transformed",
                        id(),
                        v.x,
                        v.y,
                        v.z
                    ),
                ));
            }
            triangles.push(corner);
        }
    }
    if triangles.is_empty() {
        return Err(bad(None, "holds no triangle".into()));
    }
    Ok(TriangleMesh { triangles })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A document with one geometry (`primitives` inside its `<mesh>`, over
    /// the 4 positions of a unit tetrahedron's corners) and `scene` inside
    /// its visual scene (by default one node instancing it).
    fn doc(primitives: &str, scene: &str, extra: &str) -> String {
        format!(
            r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><unit meter="0.5"/><up_axis>Y_UP</up_axis></asset>
<library_geometries><geometry id="g"><mesh>
<source id="pos"><float_array id="arr" count="12">0 0 0 1 0 0 0 1 0 0 0 1</float_array>
<technique_common><accessor source="#arr" count="4" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
<vertices id="v"><input semantic="POSITION" source="#pos"/></vertices>
{primitives}
</mesh></geometry></library_geometries>
{extra}
<library_visual_scenes><visual_scene id="s">{scene}</visual_scene></library_visual_scenes>
<scene><instance_visual_scene url="#s"/></scene>
</COLLADA>"##
        )
    }

    const TRIANGLE: &str = r##"<triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>"##;
    const NODE: &str = r##"<node id="n"><instance_geometry url="#g"/></node>"##;

    fn read(text: &str) -> Result<TriangleMesh, String> {
        TriangleMesh::parse_collada(text.as_bytes(), Path::new("m.dae")).map_err(|e| e.to_string())
    }

    #[test]
    fn reads_primitives_units_and_transforms() {
        // The unit (0.5 m) scales; Y_UP is not applied.
        let m = read(&doc(TRIANGLE, NODE, "")).unwrap();
        assert_eq!(
            m.triangles,
            vec![[
                Vec3::ZERO,
                Vec3::new(0.5, 0.0, 0.0),
                Vec3::new(0.0, 0.5, 0.0)
            ]]
        );
        // A polylist of a quad and a triangle, with a second input: fans.
        let polylist = r##"<polylist count="2"><input semantic="VERTEX" source="#v" offset="0"/><input semantic="NORMAL" source="#v" offset="1"/><vcount>4 3</vcount><p>0 9 1 9 2 9 3 9 1 9 2 9 3 9</p></polylist>"##;
        let m = read(&doc(polylist, NODE, "")).unwrap();
        assert_eq!(m.triangles.len(), 3);
        // Strips alternate their winding; fans turn about their first vertex.
        let strips = r##"<tristrips count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2 3</p></tristrips><trifans count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>3 0 1 2</p></trifans>"##;
        let m = read(&doc(strips, NODE, "")).unwrap();
        let h = 0.5;
        let [o, x, y, z] = [
            Vec3::ZERO,
            Vec3::new(h, 0.0, 0.0),
            Vec3::new(0.0, h, 0.0),
            Vec3::new(0.0, 0.0, h),
        ];
        assert_eq!(
            m.triangles,
            vec![[o, x, y], [y, x, z], [z, o, x], [z, x, y]]
        );
        // Node transforms in document order, through instance_node: a
        // translation, then a rotation of 90 degrees about z, then a scale.
        let scene = r##"<node><translate>1 2 3</translate><rotate>0 0 1 90</rotate><instance_node url="#lib"/></node>"##;
        let library = r##"<library_nodes><node id="lib"><scale>2 2 2</scale><instance_geometry url="#g"/></node></library_nodes>"##;
        let m = read(&doc(TRIANGLE, scene, library)).unwrap();
        let want = [
            Vec3::new(0.5, 1.0, 1.5),
            Vec3::new(0.5, 2.0, 1.5),
            Vec3::new(-0.5, 1.0, 1.5),
        ];
        for (got, want) in m.triangles[0].iter().zip(want) {
            assert!((*got - want).norm() < 1e-12, "{got:?} {want:?}");
        }
        // A mirroring matrix keeps the triangle's outside: its winding flips.
        let mirror = r##"<node><matrix>-1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</matrix><instance_geometry url="#g"/></node>"##;
        let m = read(&doc(TRIANGLE, mirror, "")).unwrap();
        assert_eq!(
            m.triangles[0],
            [o, Vec3::new(0.0, h, 0.0), Vec3::new(-h, 0.0, 0.0)]
        );
        // A scene that instantiates nothing: every geometry, as it is.
        assert_eq!(read(&doc(TRIANGLE, "", "")).unwrap().triangles.len(), 1);
    }

    /// Each damage the campaign (crates/core/tests/fuzz.rs) found in the
    /// `mesh-loader` crate this reader replaces, which panicked (a missing
    /// accessor, an index past the last vertex, an accessor reading past
    /// its array), allocated what a count said (16 GB for
    /// count="4294967295") or overflowed its stack (20 000 nested
    /// elements): an error naming the file and the line.
    #[test]
    fn damaged_documents_are_located_errors() {
        let good = doc(TRIANGLE, NODE, "");
        let cases: Vec<(String, &str)> = vec![
            (
                good.replace(
                    r##"<technique_common><accessor source="#arr" count="4" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common>"##,
                    "",
                ),
                "m.dae:5: not a valid COLLADA mesh: the position <source> has no <technique_common><accessor>",
            ),
            (
                good.replace("<p>0 1 2</p>", "<p>0 1 4294967295</p>"),
                "m.dae:8: not a valid COLLADA mesh: index 4294967295 names a vertex past the last (4)",
            ),
            (
                good.replace(r#"count="4" stride="3""#, r#"count="4294967295" stride="3""#),
                "m.dae:6: not a valid COLLADA mesh: count 4294967295, stride 3 and offset 0 read past the 12 values of its array",
            ),
            (
                good.replace(r#"count="12""#, r#"count="4294967295""#),
                "m.dae:5: not a valid COLLADA mesh: <float_array> count=\"4294967295\" but it holds 12 values",
            ),
            (
                good.replace(r#"<triangles count="1""#, r#"<triangles count="4294967295""#),
                "m.dae:8: not a valid COLLADA mesh: <triangles> count=\"4294967295\" but <p> holds 3 vertices",
            ),
            (
                good.replace(r#"offset="0"/><p>"#, r#"offset="4294967295"/><p>"#),
                "m.dae:8: not a valid COLLADA mesh: 3 indices do not make whole vertices of 4294967296 indices each (by the inputs' offsets)",
            ),
            (
                good.replace(r##"url="#g""##, r##"url="#nothing""##),
                "m.dae:11: not a valid COLLADA mesh: url \"#nothing\" names no element of the file",
            ),
            (
                good.replace(r#"meter="0.5""#, r#"meter="NaN""#),
                "m.dae:3: not a valid COLLADA mesh: <unit meter=\"NaN\"> is not a positive number",
            ),
            (
                good.replace("0 1 0 0 0 1</float_array>", "0 1e309 0 0 0 1</float_array>"),
                "m.dae:4: not a valid COLLADA mesh: geometry \"g\": vertex 2 is not finite (0, inf, 0)",
            ),
            (
                good.replace(NODE, &format!("{}{NODE}{}", "<node>".repeat(20_000), "</node>".repeat(20_000))),
                "m.dae:11: not a valid COLLADA mesh: elements nested more than 256 levels deep",
            ),
        ];
        for (text, want) in cases {
            assert_eq!(read(&text).unwrap_err(), want);
        }
        // Truncated: the XML parser's message, with the place.
        let e = read(&good[..good.len() / 2]).unwrap_err();
        assert!(
            e.starts_with("m.dae:") && e.contains("not a valid COLLADA mesh"),
            "{e}"
        );
    }

    /// Instancing multiplies triangles: nodes that instance each other 8
    /// times over, 5 levels, would make 32 768 copies of a 3-triangle
    /// geometry from 2 kB (1.8 MB of triangles; 8 levels, 100 GB), and 6
    /// levels pass the limit on instances.
    #[test]
    fn instancing_cannot_multiply_triangles_beyond_the_file() {
        let primitives = r##"<triangles count="3"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2 0 1 3 1 2 3</p></triangles>"##;
        let nested = |levels: usize| {
            let mut library = String::from(r#"<library_nodes><node id="l0">"#);
            library.push_str(&r##"<instance_geometry url="#g"/>"##.repeat(8));
            library.push_str("</node>");
            for l in 1..levels {
                library.push_str(&format!(r#"<node id="l{l}">"#));
                library.push_str(&format!(r##"<instance_node url="#l{}"/>"##, l - 1).repeat(8));
                library.push_str("</node>");
            }
            library.push_str("</library_nodes>");
            let scene = format!(r##"<node><instance_node url="#l{}"/></node>"##, levels - 1);
            doc(primitives, &scene, &library)
        };
        assert_eq!(read(&nested(2)).unwrap().triangles.len(), 3 * 64);
        let text = nested(5);
        assert_eq!(
            read(&text).unwrap_err(),
            format!(
                "m.dae: not a valid COLLADA mesh: its scene instantiates 98304 triangles, more than a file of {} bytes describes",
                text.len()
            )
        );
        assert_eq!(
            read(&nested(6)).unwrap_err(),
            "m.dae:10: not a valid COLLADA mesh: more than 65536 geometry instances"
        );
    }
}
