//! The URDF file Bullet loads.
//!
//! Bullet reads the URDF file itself and resolves mesh file names on its
//! own: relative to the URDF file's directory and its search paths, with
//! `package://NAME/` simply stripped, so ROS package URIs that the
//! [`RobotModel`]'s [`PackageResolver`](realitygap_core::robot::PackageResolver)
//! resolved elsewhere (e.g. `package://kinova_description/meshes/base.STL`)
//! would not be found. The engine therefore hands Bullet a temporary copy of
//! the URDF file in which
//! - every collision mesh `filename` attribute is the absolute path the
//!   robot model resolved; a COLLADA mesh is handed over as a temporary
//!   binary STL file of its triangles as realitygap's reader reads them
//!   (units and node transforms applied), because Bullet 3.08's COLLADA
//!   reader crashes on files it does not expect;
//! - the `<visual>` elements are blanked out (replaced by as many line
//!   breaks, so Bullet's line numbers still match the original file): they
//!   play no part in the physics, and in DIRECT mode Bullet would still
//!   read every visual mesh for its software renderer, including COLLADA
//!   files, whose reader crashes on files it does not expect.
//!
//! The copy (and the STL files) are deleted as soon as Bullet has loaded
//! it. A URDF file without
//! meshes and visuals is loaded as it is.

/// Escapes text for an XML attribute value (`<>&'"` as entities).
use quick_xml::escape::escape as xml_escape;
use realitygap_core::pose::{Pose, Vec3};
use realitygap_core::robot::{Geometry, JointKind, RobotModel};
use std::collections::BTreeMap;
use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Longest file name Bullet's URDF importer accepts (its 1024-byte
/// buffers, NUL included).
const BULLET_MAX_PATH: usize = 1023;

/// A URDF file for Bullet: the robot's own, or a temporary copy with
/// absolute mesh paths (removed on drop).
pub(crate) struct UrdfForBullet {
    path: PathBuf,
    temporary: bool,
    /// Temporary STL copies of COLLADA meshes, removed on drop.
    meshes: Vec<PathBuf>,
}

impl UrdfForBullet {
    /// Its path as a C string for Bullet.
    pub(crate) fn c_path(&self) -> Result<CString, String> {
        c_path(&self.path)
    }
}

impl Drop for UrdfForBullet {
    fn drop(&mut self) {
        if self.temporary {
            let _ = std::fs::remove_file(&self.path);
        }
        for m in &self.meshes {
            let _ = std::fs::remove_file(m);
        }
    }
}

/// A path as a C string, checked against Bullet's limits.
pub(crate) fn c_path(path: &Path) -> Result<CString, String> {
    use std::os::unix::ffi::OsStrExt;
    let bytes = path.as_os_str().as_bytes();
    if bytes.len() > BULLET_MAX_PATH {
        return Err(format!(
            "the path {} is longer than Bullet's limit of {BULLET_MAX_PATH} bytes",
            path.display()
        ));
    }
    CString::new(bytes).map_err(|_| format!("the path {} contains a NUL byte", path.display()))
}

/// Every collision mesh of the robot: URI as written -> the resolved
/// absolute path.
fn mesh_paths(robot: &RobotModel) -> BTreeMap<String, PathBuf> {
    let mut map = BTreeMap::new();
    for link in &robot.links {
        for c in &link.collisions {
            if let Geometry::Mesh { path, uri, .. } = &c.geometry {
                let absolute = if path.is_absolute() {
                    path.clone()
                } else {
                    std::env::current_dir()
                        .map(|d| d.join(path))
                        .unwrap_or_else(|_| path.clone())
                };
                map.insert(uri.clone(), absolute);
            }
        }
    }
    map
}

/// `text` with every `<visual>` element (outside comments) replaced by the
/// line breaks it contained; `None` when a `<visual>` element is not
/// closed.
fn blank_visuals(text: &str) -> Option<String> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    loop {
        let comment = rest.find("<!--");
        let visual = find_tag(rest, "<visual");
        match (comment, visual) {
            (Some(c), v) if v.is_none_or(|v| c < v) => {
                let end = rest[c..].find("-->").map(|e| c + e + 3)?;
                out.push_str(&rest[..end]);
                rest = &rest[end..];
            }
            (_, Some(v)) => {
                out.push_str(&rest[..v]);
                let after = &rest[v..];
                let open_end = after.find('>')?;
                let len = if after[..open_end].ends_with('/') {
                    open_end + 1
                } else {
                    let close = after.find("</visual")?;
                    close + after[close..].find('>')? + 1
                };
                out.extend(after[..len].chars().filter(|&c| c == '\n'));
                rest = &after[len..];
            }
            _ => {
                out.push_str(rest);
                return Some(out);
            }
        }
    }
}

/// Position of the start tag `tag` (e.g. `<visual`) followed by
/// whitespace, `>` or `/`.
fn find_tag(text: &str, tag: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(i) = text[from..].find(tag) {
        let at = from + i;
        match text[at + tag.len()..].chars().next() {
            Some(c) if c.is_whitespace() || c == '>' || c == '/' => return Some(at),
            _ => from = at + tag.len(),
        }
    }
    None
}

/// Decodes the five predefined XML entities and numeric character
/// references of an attribute value; `None` when it is malformed.
fn xml_unescape(value: &str) -> Option<String> {
    let mut out = String::with_capacity(value.len());
    let mut rest = value;
    while let Some(amp) = rest.find('&') {
        out.push_str(&rest[..amp]);
        let after = &rest[amp + 1..];
        let semi = after.find(';')?;
        let entity = &after[..semi];
        let ch = match entity {
            "amp" => '&',
            "lt" => '<',
            "gt" => '>',
            "quot" => '"',
            "apos" => '\'',
            _ => {
                let code = if let Some(hex) = entity.strip_prefix("#x") {
                    u32::from_str_radix(hex, 16).ok()?
                } else {
                    entity.strip_prefix('#')?.parse().ok()?
                };
                char::from_u32(code)?
            }
        };
        out.push(ch);
        rest = &after[semi + 1..];
    }
    out.push_str(rest);
    Some(out)
}

/// Replaces the value of every `filename` attribute found in `meshes` by
/// the mapped path; returns the new text and the URIs replaced.
fn rewrite(text: &str, meshes: &BTreeMap<String, PathBuf>) -> (String, Vec<String>) {
    let mut out = String::with_capacity(text.len() + 1024);
    let mut replaced = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("filename") {
        let (before, from_name) = rest.split_at(at);
        out.push_str(before);
        let preceded_by_space = before.chars().last().is_none_or(|c| c.is_whitespace());
        let after_name = &from_name["filename".len()..];
        let trimmed = after_name.trim_start();
        let parsed = trimmed
            .strip_prefix('=')
            .map(str::trim_start)
            .and_then(|v| {
                let quote = v.chars().next().filter(|&q| q == '"' || q == '\'')?;
                let end = v[1..].find(quote)?;
                Some((quote, &v[1..1 + end], &v[1 + end + 1..]))
            });
        match parsed {
            Some((quote, raw, tail)) if preceded_by_space => {
                match xml_unescape(raw).and_then(|uri| meshes.get(&uri).map(|p| (uri, p))) {
                    Some((uri, path)) => {
                        out.push_str("filename=");
                        out.push(quote);
                        out.push_str(&xml_escape(path.to_string_lossy()));
                        out.push(quote);
                        replaced.push(uri);
                    }
                    None => {
                        out.push_str(&from_name[..from_name.len() - tail.len()]);
                    }
                }
                rest = tail;
            }
            _ => {
                out.push_str("filename");
                rest = after_name;
            }
        }
    }
    out.push_str(rest);
    (out, replaced)
}

fn xyz(v: Vec3) -> String {
    format!("{:?} {:?} {:?}", v.x, v.y, v.z)
}

fn origin(pose: &Pose) -> String {
    let (r, p, y) = pose.orientation.to_euler_rpy();
    format!(
        "<origin xyz=\"{}\" rpy=\"{r:?} {p:?} {y:?}\"/>",
        xyz(pose.position_m)
    )
}

fn geometry(g: &Geometry) -> String {
    match g {
        Geometry::Box { size_m } => format!("<box size=\"{}\"/>", xyz(*size_m)),
        Geometry::Cylinder { radius_m, length_m } => {
            format!("<cylinder radius=\"{radius_m:?}\" length=\"{length_m:?}\"/>")
        }
        Geometry::Capsule { radius_m, length_m } => {
            format!("<capsule radius=\"{radius_m:?}\" length=\"{length_m:?}\"/>")
        }
        Geometry::Sphere { radius_m } => format!("<sphere radius=\"{radius_m:?}\"/>"),
        Geometry::Mesh { path, scale, .. } => format!(
            "<mesh filename=\"{}\" scale=\"{}\"/>",
            xml_escape(path.to_string_lossy()),
            xyz(*scale)
        ),
    }
}

/// A URDF text of `robot` for Bullet: links with their inertials and
/// collision shapes (absolute mesh paths), joints with their origin, axis,
/// limits and dynamics; no visuals. Numbers are written in Rust's
/// shortest round-trip form, orientations as roll-pitch-yaw.
pub(crate) fn from_model(robot: &RobotModel) -> String {
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<robot name=\"{}\">\n",
        xml_escape(&robot.name)
    );
    for link in &robot.links {
        out.push_str(&format!("  <link name=\"{}\">\n", xml_escape(&link.name)));
        if let Some(i) = &link.inertial {
            let [ixx, ixy, ixz, iyy, iyz, izz] = i.inertia;
            out.push_str(&format!(
                "    <inertial>{}<mass value=\"{:?}\"/><inertia ixx=\"{ixx:?}\" ixy=\"{ixy:?}\" ixz=\"{ixz:?}\" iyy=\"{iyy:?}\" iyz=\"{iyz:?}\" izz=\"{izz:?}\"/></inertial>\n",
                origin(&i.origin),
                i.mass_kg
            ));
        }
        for c in &link.collisions {
            out.push_str(&format!(
                "    <collision>{}<geometry>{}</geometry></collision>\n",
                origin(&c.origin),
                geometry(&c.geometry)
            ));
        }
        out.push_str("  </link>\n");
    }
    for j in &robot.joints {
        out.push_str(&format!(
            "  <joint name=\"{}\" type=\"{}\"><parent link=\"{}\"/><child link=\"{}\"/>{}<axis xyz=\"{}\"/>",
            xml_escape(&j.name),
            j.kind.urdf_name(),
            xml_escape(&robot.links[j.parent].name),
            xml_escape(&robot.links[j.child].name),
            origin(&j.origin),
            xyz(j.axis)
        ));
        if let Some(l) = &j.limits {
            let number = |v: f64| {
                if v.is_finite() {
                    format!("{v:?}")
                } else {
                    "0".into()
                }
            };
            let bounds = if j.kind == JointKind::Continuous {
                String::new()
            } else {
                format!(
                    "lower=\"{}\" upper=\"{}\" ",
                    number(l.lower),
                    number(l.upper)
                )
            };
            out.push_str(&format!(
                "<limit {bounds}effort=\"{}\" velocity=\"{}\"/>",
                number(l.effort),
                number(l.velocity)
            ));
        }
        out.push_str(&format!(
            "<dynamics damping=\"{:?}\" friction=\"{:?}\"/></joint>\n",
            j.damping, j.friction
        ));
    }
    out.push_str("</robot>\n");
    out
}

static COPIES: AtomicU64 = AtomicU64::new(0);

/// The URDF file Bullet should load for `robot` (see the module
/// documentation).
pub(crate) fn prepare(robot: &RobotModel) -> Result<UrdfForBullet, String> {
    if !robot.source.is_file() {
        // A model read from a string (e.g. the built-in Mico2, whose
        // `source` only names it): written from the model itself.
        return write_temporary(&from_model(robot));
    }
    let mut meshes = mesh_paths(robot);
    if meshes.is_empty() && robot.links.iter().all(|l| l.visuals.is_empty()) {
        return Ok(UrdfForBullet {
            path: robot.source.clone(),
            temporary: false,
            meshes: Vec::new(),
        });
    }
    // COLLADA meshes reach Bullet as STL files of the same triangles.
    let mut stl_copies = Vec::new();
    for path in meshes.values_mut() {
        if realitygap_core::robot::stl::mesh_format(path) == Some("dae") {
            let mesh =
                realitygap_core::robot::stl::TriangleMesh::read(path).map_err(|e| e.to_string())?;
            let copy = temporary_path("stl")?;
            std::fs::write(&copy, mesh.to_binary_stl()).map_err(|e| {
                format!(
                    "cannot write the STL copy {} of {}: {e}",
                    copy.display(),
                    path.display()
                )
            })?;
            stl_copies.push(copy.clone());
            *path = copy;
        }
    }
    let text = std::fs::read_to_string(&robot.source)
        .map_err(|e| format!("cannot read URDF file {}: {e}", robot.source.display()))?;
    let without_visuals = blank_visuals(&text).ok_or_else(|| {
        format!(
            "URDF file {}: a <visual> element or a comment is not closed",
            robot.source.display()
        )
    })?;
    let (copy, replaced) = rewrite(&without_visuals, &meshes);
    if let Some(missing) = meshes.keys().find(|uri| !replaced.contains(uri)) {
        return Err(format!(
            "URDF file {}: no collision mesh filename attribute \"{missing}\" found in the file (was it changed after it was read?)",
            robot.source.display()
        ));
    }
    let mut urdf = write_temporary(&copy)?;
    urdf.meshes = stl_copies;
    Ok(urdf)
}

/// A new, unused temporary file name with extension `ext`.
fn temporary_path(ext: &str) -> Result<PathBuf, String> {
    let dir = std::env::temp_dir();
    loop {
        let n = COPIES.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!(
            "realitygap-bullet-{}-{n}.{ext}",
            std::process::id()
        ));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(_) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                return Err(format!(
                    "cannot create a temporary file in {}: {e}",
                    dir.display()
                ))
            }
        }
    }
}

/// Writes `text` to a new temporary URDF file.
fn write_temporary(copy: &str) -> Result<UrdfForBullet, String> {
    let dir = std::env::temp_dir();
    loop {
        let n = COPIES.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!("realitygap-bullet-{}-{n}.urdf", std::process::id()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(mut file) => {
                use std::io::Write;
                let result = UrdfForBullet {
                    path,
                    temporary: true,
                    meshes: Vec::new(),
                };
                file.write_all(copy.as_bytes()).map_err(|e| {
                    format!(
                        "cannot write the temporary URDF copy {}: {e}",
                        result.path.display()
                    )
                })?;
                return Ok(result);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                return Err(format!(
                    "cannot create a temporary URDF copy in {}: {e}",
                    dir.display()
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(pairs: &[(&str, &str)]) -> BTreeMap<String, PathBuf> {
        pairs
            .iter()
            .map(|(u, p)| (u.to_string(), PathBuf::from(p)))
            .collect()
    }

    #[test]
    fn rewrites_only_known_mesh_names() {
        let text = r#"<robot><gazebo><plugin filename="libx.so"/></gazebo>
<mesh filename="package://kin/meshes/a.STL"/><mesh  filename = 'rel/b&amp;c.stl' scale="1 1 1"/>
<mesh filename="package://kin/meshes/a.STL"/><!-- myfilename="package://kin/meshes/a.STL" --></robot>"#;
        let m = map(&[
            ("package://kin/meshes/a.STL", "/data/kin/meshes/a.STL"),
            ("rel/b&c.stl", "/u/rel/b&c's.stl"),
        ]);
        let (out, replaced) = rewrite(text, &m);
        assert_eq!(
            out,
            r#"<robot><gazebo><plugin filename="libx.so"/></gazebo>
<mesh filename="/data/kin/meshes/a.STL"/><mesh  filename='/u/rel/b&amp;c&apos;s.stl' scale="1 1 1"/>
<mesh filename="/data/kin/meshes/a.STL"/><!-- myfilename="package://kin/meshes/a.STL" --></robot>"#
        );
        assert_eq!(replaced.len(), 3);
    }

    #[test]
    fn unterminated_attribute_is_left_alone() {
        let m = map(&[("a.stl", "/x/a.stl")]);
        let (out, replaced) = rewrite("<mesh filename=\"a.stl", &m);
        assert_eq!(out, "<mesh filename=\"a.stl");
        assert!(replaced.is_empty());
    }

    #[test]
    fn blanks_visuals_but_keeps_lines_and_comments() {
        let text = "<link>\n<visual name=\"a\">\n <geometry><mesh filename=\"v.dae\"/></geometry>\n</visual >\n<visualx/>\n<!-- <visual> -->\n<visual/><collision/>\n</link>";
        let out = blank_visuals(text).unwrap();
        assert_eq!(
            out,
            "<link>\n\n\n\n<visualx/>\n<!-- <visual> -->\n<collision/>\n</link>"
        );
        assert_eq!(out.lines().count(), text.lines().count());
        assert_eq!(blank_visuals("<visual><geometry/>"), None);
        assert_eq!(blank_visuals("<!-- open"), None);
    }

    #[test]
    fn unescapes_entities() {
        assert_eq!(
            xml_unescape("a&amp;b&#65;&#x42;&lt;").as_deref(),
            Some("a&bAB<")
        );
        assert_eq!(xml_unescape("a&bogus;"), None);
        assert_eq!(xml_unescape("a&amp"), None);
    }
}
