//! URDF text to [`RobotModel`]: parsing through `urdf-rs`, then the checks
//! and conversions `urdf-rs` leaves to its users (link references, tree
//! shape, value ranges, mesh and package resolution), with errors that name
//! the file and, where it can be found, the line.

use super::{
    Collision, Geometry, Inertial, Joint, JointKind, JointLimits, Link, LinkRole, Mimic,
    PackageResolver, RobotError, RobotModel, Visual,
};
use crate::pose::{Pose, Quat, Vec3};
use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Parses `xml` and builds the model. `source` names the description in
/// errors; `base_dir` resolves relative mesh paths.
pub(super) fn build(
    xml: &str,
    source: &Path,
    base_dir: &Path,
    resolver: &PackageResolver,
) -> Result<RobotModel, RobotError> {
    check_well_formed(xml).map_err(|(offset, message)| {
        let (line, column) = line_col_at(xml, offset);
        RobotError::Xml {
            source_file: source.to_path_buf(),
            line: Some(line),
            column: Some(column),
            message,
        }
    })?;
    let robot = urdf_rs::read_from_string(xml).map_err(|e| xml_error(source, &e.to_string()))?;
    let ctx = Ctx {
        xml,
        source,
        base_dir,
        resolver,
        notes: RefCell::new(Vec::new()),
    };

    let mut link_index: HashMap<&str, usize> = HashMap::new();
    for (i, l) in robot.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), i).is_some() {
            return Err(RobotError::DuplicateName {
                source_file: source.to_path_buf(),
                line: ctx.nth_element_line("link", &l.name, 1),
                what: "link",
                name: l.name.clone(),
            });
        }
    }
    let mut joint_index: HashMap<&str, usize> = HashMap::new();
    for (i, j) in robot.joints.iter().enumerate() {
        if joint_index.insert(j.name.as_str(), i).is_some() {
            return Err(RobotError::DuplicateName {
                source_file: source.to_path_buf(),
                line: ctx.nth_element_line("joint", &j.name, 1),
                what: "joint",
                name: j.name.clone(),
            });
        }
    }

    let materials: HashMap<&str, [f64; 4]> = robot
        .materials
        .iter()
        .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), c.rgba.0)))
        .collect();

    let mut links = Vec::with_capacity(robot.links.len());
    for l in &robot.links {
        links.push(ctx.link(l, &materials)?);
    }

    let mut joints = Vec::with_capacity(robot.joints.len());
    for j in &robot.joints {
        joints.push(ctx.joint(j, &link_index, &robot.links)?);
    }
    // Mimic references need every joint's index and kind.
    ctx.mimics(&robot.joints, &joint_index, &mut joints)?;

    let mut model =
        RobotModel::from_parts(robot.name.clone(), links, joints, source.to_path_buf())?;
    // The root link's inertia moves nothing on a fixed base: no note.
    let root = format!("link \"{}\" has mass 0", model.links[model.root_link].name);
    model.notes = ctx.notes.into_inner();
    model.notes.retain(|n| !n.starts_with(&root));
    Ok(model)
}

struct Ctx<'a> {
    xml: &'a str,
    source: &'a Path,
    base_dir: &'a Path,
    resolver: &'a PackageResolver,
    /// What was noticed without refusing the file, one line each.
    notes: RefCell<Vec<String>>,
}

impl Ctx<'_> {
    /// Where `package://PACKAGE/INNER` is when no package of that name is
    /// known, as pybullet, Isaac and MuJoCo's tools look: `PACKAGE/INNER`
    /// beside the URDF (`package://meshes/...` with `meshes/` there), or
    /// `INNER` in a folder above the URDF named `PACKAGE`.
    fn beside_urdf(&self, package: &str, inner: &str) -> Option<PathBuf> {
        let beside = self.base_dir.join(package).join(inner);
        if beside.is_file() {
            return Some(beside);
        }
        self.base_dir
            .ancestors()
            .find(|d| d.file_name().is_some_and(|n| n == package))
            .map(|d| d.join(inner))
            .filter(|p| p.is_file())
    }

    fn element_line(&self, tag: &str, name: &str) -> Option<usize> {
        self.nth_element_line(tag, name, 0)
    }

    fn nth_element_line(&self, tag: &str, name: &str, n: usize) -> Option<usize> {
        element_lines(self.xml, tag, name).into_iter().nth(n)
    }

    fn invalid(&self, tag: &str, name: &str, element: String, message: String) -> RobotError {
        RobotError::InvalidValue {
            source_file: self.source.to_path_buf(),
            line: self.element_line(tag, name),
            element,
            message,
        }
    }

    fn pose(
        &self,
        tag: &str,
        name: &str,
        what: &str,
        p: &urdf_rs::Pose,
    ) -> Result<Pose, RobotError> {
        let (xyz, rpy) = (p.xyz.0, p.rpy.0);
        if !xyz.iter().chain(rpy.iter()).all(|v| v.is_finite()) {
            return Err(self.invalid(
                tag,
                name,
                format!("{tag} \"{name}\" {what}"),
                format!("origin xyz {xyz:?} rpy {rpy:?} must be finite numbers"),
            ));
        }
        Ok(Pose::new(
            Vec3::from_array(xyz),
            Quat::from_euler_rpy(rpy[0], rpy[1], rpy[2]),
        ))
    }

    fn link(
        &self,
        l: &urdf_rs::Link,
        materials: &HashMap<&str, [f64; 4]>,
    ) -> Result<Link, RobotError> {
        let name = l.name.as_str();
        let i = &l.inertial;
        let inertia = [
            i.inertia.ixx,
            i.inertia.ixy,
            i.inertia.ixz,
            i.inertia.iyy,
            i.inertia.iyz,
            i.inertia.izz,
        ];
        let mass = i.mass.value;
        // urdf-rs gives an all-zero inertial when the element is absent.
        let inertial = if mass == 0.0 && inertia.iter().all(|&v| v == 0.0) {
            None
        } else {
            if !(mass.is_finite() && mass >= 0.0) {
                return Err(self.invalid(
                    "link",
                    name,
                    format!("link \"{name}\" <inertial><mass>"),
                    format!("mass {mass} must be a finite number >= 0 kg"),
                ));
            }
            if !inertia.iter().all(|v| v.is_finite())
                || inertia[0] < 0.0
                || inertia[3] < 0.0
                || inertia[5] < 0.0
            {
                return Err(self.invalid(
                    "link",
                    name,
                    format!("link \"{name}\" <inertial><inertia>"),
                    format!("inertia {inertia:?} must be finite with ixx, iyy, izz >= 0 kg m^2"),
                ));
            }
            if mass == 0.0 {
                self.notes.borrow_mut().push(format!(
                    "link \"{name}\" has mass 0 and the inertia {inertia:?}: a massless link carries no inertia here (MuJoCo's URDF import would keep it)"
                ));
            }
            Some(Inertial {
                mass_kg: mass,
                origin: self.pose("link", name, "<inertial><origin>", &i.origin)?,
                inertia,
            })
        };
        let mut visuals = Vec::with_capacity(l.visual.len());
        for v in &l.visual {
            let rgba = v.material.as_ref().and_then(|m| {
                m.color
                    .as_ref()
                    .map(|c| c.rgba.0)
                    .or_else(|| materials.get(m.name.as_str()).copied())
            });
            visuals.push(Visual {
                name: v.name.clone(),
                origin: self.pose("link", name, "<visual><origin>", &v.origin)?,
                geometry: self.geometry(name, "<visual>", &v.geometry)?,
                rgba,
            });
        }
        let mut collisions = Vec::with_capacity(l.collision.len());
        for c in &l.collision {
            collisions.push(Collision {
                name: c.name.clone(),
                origin: self.pose("link", name, "<collision><origin>", &c.origin)?,
                geometry: self.geometry(name, "<collision>", &c.geometry)?,
            });
        }
        Ok(Link {
            name: l.name.clone(),
            inertial,
            visuals,
            collisions,
        })
    }

    fn geometry(
        &self,
        link: &str,
        what: &str,
        g: &urdf_rs::Geometry,
    ) -> Result<Geometry, RobotError> {
        let bad = |message: String| {
            self.invalid(
                "link",
                link,
                format!("link \"{link}\" {what} <geometry>"),
                message,
            )
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        Ok(match g {
            urdf_rs::Geometry::Box { size } => {
                if !size.0.iter().all(|&v| positive(v)) {
                    return Err(bad(format!(
                        "box size {:?} must be three numbers > 0 m",
                        size.0
                    )));
                }
                Geometry::Box {
                    size_m: Vec3::from_array(size.0),
                }
            }
            urdf_rs::Geometry::Cylinder { radius, length }
            | urdf_rs::Geometry::Capsule { radius, length } => {
                let capsule = matches!(g, urdf_rs::Geometry::Capsule { .. });
                let length_ok = if capsule {
                    length.is_finite() && *length >= 0.0
                } else {
                    positive(*length)
                };
                if !(positive(*radius) && length_ok) {
                    return Err(bad(format!(
                        "radius {radius} m and length {length} m must be > 0"
                    )));
                }
                if capsule {
                    Geometry::Capsule {
                        radius_m: *radius,
                        length_m: *length,
                    }
                } else {
                    Geometry::Cylinder {
                        radius_m: *radius,
                        length_m: *length,
                    }
                }
            }
            urdf_rs::Geometry::Sphere { radius } => {
                if !positive(*radius) {
                    return Err(bad(format!("sphere radius {radius} must be > 0 m")));
                }
                Geometry::Sphere { radius_m: *radius }
            }
            urdf_rs::Geometry::Mesh { filename, scale } => {
                let scale = scale
                    .map(|s| Vec3::from_array(s.0))
                    .unwrap_or(Vec3::new(1.0, 1.0, 1.0));
                if !scale.is_finite() {
                    return Err(bad(format!("mesh scale {scale:?} must be finite")));
                }
                Geometry::Mesh {
                    path: self.resolve_mesh(link, filename)?,
                    uri: filename.clone(),
                    scale,
                }
            }
        })
    }

    fn resolve_mesh(&self, link: &str, uri: &str) -> Result<PathBuf, RobotError> {
        let path = if let Some(rest) = uri.strip_prefix("package://") {
            let (package, inner) = rest.split_once('/').unwrap_or((rest, ""));
            match self.resolver.find(package) {
                Ok(dir) => dir.join(inner),
                Err(_) if self.beside_urdf(package, inner).is_some() => {
                    let found = self.beside_urdf(package, inner).unwrap_or_default();
                    let mut notes = self.notes.borrow_mut();
                    let line = format!(
                        "package '{package}' of the URDF's package:// meshes is not known: found beside the URDF ({}); --package {package}=DIR names another place",
                        self.base_dir.display()
                    );
                    if !notes.contains(&line) {
                        notes.push(line);
                    }
                    found
                }
                Err(searched) => {
                    return Err(RobotError::PackageNotFound {
                        source_file: self.source.to_path_buf(),
                        link: link.to_string(),
                        uri: uri.to_string(),
                        package: package.to_string(),
                        searched,
                    })
                }
            }
        } else if let Some(rest) = uri.strip_prefix("file://") {
            PathBuf::from(rest)
        } else if uri.contains("://") {
            return Err(RobotError::UnsupportedUri {
                source_file: self.source.to_path_buf(),
                link: link.to_string(),
                uri: uri.to_string(),
            });
        } else {
            self.base_dir.join(uri)
        };
        let path = std::path::absolute(&path).unwrap_or(path);
        if !path.is_file() {
            return Err(RobotError::MeshNotFound {
                source_file: self.source.to_path_buf(),
                link: link.to_string(),
                uri: uri.to_string(),
                looked_at: path,
            });
        }
        Ok(path)
    }

    /// A joint's unit axis (any axis for a fixed joint, which has none).
    fn joint_axis(&self, j: &urdf_rs::Joint, kind: JointKind) -> Result<Vec3, RobotError> {
        let name = j.name.as_str();
        let raw_axis = Vec3::from_array(j.axis.xyz.0);
        let axis = if !raw_axis.is_finite() {
            None
        } else if raw_axis.norm() > 1e-12 {
            Some(raw_axis.scale(1.0 / raw_axis.norm()))
        } else {
            None
        };
        match (axis, kind) {
            (Some(a), _) => Ok(a),
            (None, JointKind::Fixed) => Ok(Vec3::new(1.0, 0.0, 0.0)),
            (None, _) => Err(self.invalid(
                "joint",
                name,
                format!("joint \"{name}\" <axis>"),
                format!(
                    "axis {:?} must be a finite, non-zero vector for a {kind} joint",
                    j.axis.xyz.0
                ),
            )),
        }
    }

    /// A joint's limits: none for a fixed joint, infinite positions for a
    /// continuous one, required for revolute and prismatic joints; effort
    /// and velocity >= 0.
    fn joint_limits(
        &self,
        j: &urdf_rs::Joint,
        kind: JointKind,
    ) -> Result<Option<JointLimits>, RobotError> {
        let name = j.name.as_str();
        let l = &j.limit;
        let absent = l.lower == 0.0 && l.upper == 0.0 && l.effort == 0.0 && l.velocity == 0.0;
        let or_inf = |v: f64| if absent { f64::INFINITY } else { v };
        let limits = match kind {
            JointKind::Fixed => None,
            JointKind::Continuous => Some(JointLimits {
                lower: f64::NEG_INFINITY,
                upper: f64::INFINITY,
                effort: or_inf(l.effort),
                velocity: or_inf(l.velocity),
            }),
            JointKind::Revolute | JointKind::Prismatic => {
                if absent {
                    return Err(self.invalid(
                        "joint",
                        name,
                        format!("joint \"{name}\" <limit>"),
                        format!("a {kind} joint needs <limit lower=.. upper=.. effort=.. velocity=..> (none or all zero given)"),
                    ));
                }
                if l.lower.is_nan() || l.upper.is_nan() || l.lower > l.upper {
                    return Err(self.invalid(
                        "joint",
                        name,
                        format!("joint \"{name}\" <limit>"),
                        format!("lower {} must not exceed upper {}", l.lower, l.upper),
                    ));
                }
                Some(JointLimits {
                    lower: l.lower,
                    upper: l.upper,
                    effort: l.effort,
                    velocity: l.velocity,
                })
            }
        };
        if let Some(lim) = &limits {
            if lim.effort.is_nan()
                || lim.effort < 0.0
                || lim.velocity.is_nan()
                || lim.velocity < 0.0
            {
                return Err(self.invalid(
                    "joint",
                    name,
                    format!("joint \"{name}\" <limit>"),
                    format!(
                        "effort {} and velocity {} must be >= 0",
                        lim.effort, lim.velocity
                    ),
                ));
            }
        }
        Ok(limits)
    }

    /// Resolves `<mimic>` references: the leader must exist, move and not
    /// mimic another joint; multiplier and offset must be finite.
    fn mimics(
        &self,
        urdf_joints: &[urdf_rs::Joint],
        joint_index: &HashMap<&str, usize>,
        joints: &mut [Joint],
    ) -> Result<(), RobotError> {
        for (i, j) in urdf_joints.iter().enumerate() {
            let Some(m) = &j.mimic else { continue };
            let line = self.element_line("joint", &j.name);
            let invalid = |message: String| RobotError::InvalidValue {
                source_file: self.source.to_path_buf(),
                line,
                element: format!("joint \"{}\" <mimic>", j.name),
                message,
            };
            let Some(&leader) = joint_index.get(m.joint.as_str()) else {
                return Err(invalid(format!(
                    "mimics joint \"{}\", which is not defined",
                    m.joint
                )));
            };
            if !joints[leader].kind.is_movable()
                || urdf_joints[leader].mimic.is_some()
                || leader == i
            {
                return Err(invalid(format!(
                    "mimics joint \"{}\", which is fixed or itself a mimic joint (not supported)",
                    m.joint
                )));
            }
            let multiplier = m.multiplier.unwrap_or(1.0);
            let offset = m.offset.unwrap_or(0.0);
            if !(multiplier.is_finite() && offset.is_finite()) {
                return Err(invalid(
                    "multiplier and offset must be finite numbers".into(),
                ));
            }
            if joints[i].kind.is_movable() {
                joints[i].mimic = Some(Mimic {
                    joint: leader,
                    multiplier,
                    offset,
                });
            }
        }
        Ok(())
    }

    fn joint(
        &self,
        j: &urdf_rs::Joint,
        link_index: &HashMap<&str, usize>,
        urdf_links: &[urdf_rs::Link],
    ) -> Result<Joint, RobotError> {
        let name = j.name.as_str();
        let line = self.element_line("joint", name);
        let kind = match j.joint_type {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            ref other => {
                return Err(RobotError::UnsupportedJoint {
                    source_file: self.source.to_path_buf(),
                    line,
                    joint: j.name.clone(),
                    kind: format!("{other:?}").to_lowercase(),
                })
            }
        };
        let find_link = |role: LinkRole, link: &str| {
            link_index
                .get(link)
                .copied()
                .ok_or_else(|| RobotError::UnknownLink {
                    source_file: self.source.to_path_buf(),
                    line,
                    joint: j.name.clone(),
                    role,
                    link: link.to_string(),
                    known_links: urdf_links.iter().map(|l| l.name.clone()).collect(),
                })
        };
        let parent = find_link(LinkRole::Parent, &j.parent.link)?;
        let child = find_link(LinkRole::Child, &j.child.link)?;
        if parent == child {
            return Err(RobotError::Cycle {
                source_file: self.source.to_path_buf(),
                links: vec![j.parent.link.clone(), j.child.link.clone()],
            });
        }
        let origin = self.pose("joint", name, "<origin>", &j.origin)?;

        let axis = self.joint_axis(j, kind)?;
        let limits = self.joint_limits(j, kind)?;
        let (damping, friction) = j
            .dynamics
            .as_ref()
            .map(|d| (d.damping, d.friction))
            .unwrap_or((0.0, 0.0));
        if !(damping.is_finite() && damping >= 0.0 && friction.is_finite() && friction >= 0.0) {
            return Err(self.invalid(
                "joint",
                name,
                format!("joint \"{name}\" <dynamics>"),
                format!("damping {damping} and friction {friction} must be finite and >= 0"),
            ));
        }
        Ok(Joint {
            name: j.name.clone(),
            kind,
            parent,
            child,
            origin,
            axis,
            limits,
            damping,
            friction,
            mimic: None,
        })
    }
}

/// The deepest nesting of elements read. A URDF nests 4 or 5 levels (its
/// extensions a few more); the XML reader and deserializer behind urdf-rs
/// recurse per level, and some thousands of levels overflow the stack.
pub(crate) const MAX_XML_DEPTH: usize = 256;

/// Checks that `xml` is well-formed XML (tags nest and close, attributes
/// parse) and nests at most [`MAX_XML_DEPTH`] levels, returning the byte
/// offset and a description of the first problem. urdf-rs reports such
/// problems without a position.
fn check_well_formed(xml: &str) -> Result<(), (usize, String)> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(xml);
    reader.config_mut().check_end_names = true;
    let mut open: Vec<(String, usize)> = Vec::new();
    let mut roots = 0;
    loop {
        let before = reader.buffer_position() as usize;
        let event = reader
            .read_event()
            .map_err(|e| (reader.error_position() as usize, e.to_string()))?;
        let check_attributes =
            |e: &quick_xml::events::BytesStart<'_>| -> Result<(), (usize, String)> {
                for attribute in e.attributes() {
                    attribute.map_err(|err| (before, format!("malformed attribute: {err}")))?;
                }
                Ok(())
            };
        match event {
            Event::Start(e) => {
                check_attributes(&e)?;
                if open.is_empty() {
                    roots += 1;
                }
                if open.len() >= MAX_XML_DEPTH {
                    return Err((
                        before,
                        format!("elements nested more than {MAX_XML_DEPTH} levels deep"),
                    ));
                }
                open.push((
                    String::from_utf8_lossy(e.name().as_ref()).into_owned(),
                    before,
                ));
            }
            Event::Empty(e) => {
                check_attributes(&e)?;
                if open.is_empty() {
                    roots += 1;
                }
            }
            Event::End(_) => {
                open.pop();
            }
            Event::Eof => break,
            _ => {}
        }
        if roots > 1 {
            return Err((
                before,
                "more than one top-level element (a URDF has one <robot>)".into(),
            ));
        }
    }
    if let Some((name, at)) = open.last() {
        return Err((*at, format!("<{name}> is never closed")));
    }
    if roots == 0 {
        return Err((0, "no <robot> element".into()));
    }
    Ok(())
}

/// 1-based line and column (in characters) of a byte offset.
fn line_col_at(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    (line, before[line_start..].chars().count() + 1)
}

/// Turns an error of `urdf-rs` into [`RobotError::Xml`], pulling out a line
/// and column when the message carries one.
fn xml_error(source: &Path, message: &str) -> RobotError {
    let (line, column) = line_col_in_message(message);
    RobotError::Xml {
        source_file: source.to_path_buf(),
        line,
        column,
        message: message.trim().to_string(),
    }
}

/// Finds `Line: L, Column: C` (as RustyXml reports positions) in a message.
fn line_col_in_message(message: &str) -> (Option<usize>, Option<usize>) {
    let number_after = |key: &str| {
        let start = message.find(key)? + key.len();
        let digits: String = message[start..]
            .trim_start()
            .chars()
            .take_while(|c| c.is_ascii_digit())
            .collect();
        digits.parse::<usize>().ok()
    };
    match (number_after("Line:"), number_after("Column:")) {
        (Some(l), Some(c)) => (Some(l), Some(c)),
        _ => (None, None),
    }
}

/// 1-based lines of every `<tag ... name="NAME" ...>` start tag, skipping
/// comments, in document order.
pub(super) fn element_lines(xml: &str, tag: &str, name: &str) -> Vec<usize> {
    let bytes = xml.as_bytes();
    let mut lines = Vec::new();
    let mut i = 0;
    while let Some(off) = xml[i..].find('<') {
        let start = i + off;
        if xml[start..].starts_with("<!--") {
            match xml[start + 4..].find("-->") {
                Some(end) => {
                    i = start + 4 + end + 3;
                    continue;
                }
                None => break,
            }
        }
        let after = start + 1;
        let end_tag = xml[after..]
            .find('>')
            .map(|e| after + e)
            .unwrap_or(xml.len());
        if xml[after..].starts_with(tag)
            && bytes
                .get(after + tag.len())
                .is_some_and(|b| b.is_ascii_whitespace())
            && attribute(&xml[after + tag.len()..end_tag], "name") == Some(name)
        {
            lines.push(xml[..start].bytes().filter(|&b| b == b'\n').count() + 1);
        }
        i = after;
    }
    lines
}

/// The value of attribute `key` in the text of a start tag.
fn attribute<'a>(tag_text: &'a str, key: &str) -> Option<&'a str> {
    let mut rest = tag_text;
    while let Some(eq) = rest.find('=') {
        let k = rest[..eq].trim();
        let k = k
            .rsplit(|c: char| c.is_ascii_whitespace())
            .next()
            .unwrap_or(k);
        let after = rest[eq + 1..].trim_start();
        let quote = after.chars().next()?;
        if quote != '"' && quote != '\'' {
            return None;
        }
        let value_end = after[1..].find(quote)?;
        let value = &after[1..1 + value_end];
        if k == key {
            return Some(value);
        }
        rest = &after[1 + value_end + 1..];
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn element_lines_skip_comments_and_match_names() {
        let xml = "<robot>\n<!-- <joint name=\"a\"> -->\n<!-->\n<joint name=\"x\"/>\n<-->\n<joint type='fixed' name='a'>\n</joint>\n<jointx name=\"a\"/>\n</robot>";
        assert_eq!(element_lines(xml, "joint", "a"), vec![6]);
        assert_eq!(element_lines(xml, "joint", "x"), Vec::<usize>::new());
        assert_eq!(element_lines(xml, "link", "a"), Vec::<usize>::new());
    }

    /// Found by the damage campaign (crates/core/tests/fuzz.rs): a URDF
    /// element wrapped in 20 000 others overflowed urdf-rs' stack (an
    /// abort). Deeper than MAX_XML_DEPTH is an error with the place; up to
    /// it, urdf-rs reads the file on a test thread's stack.
    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let nested = |depth: usize| {
            format!(
                "<robot name=\"r\">\n<link name=\"a\">\n{}{}</link>\n</robot>\n",
                "<x>".repeat(depth),
                "</x>".repeat(depth)
            )
        };
        let resolver = PackageResolver::new();
        let e = build(
            &nested(20_000),
            Path::new("deep.urdf"),
            Path::new("."),
            &resolver,
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "deep.urdf:3:763: elements nested more than 256 levels deep",
        );
        let model = build(
            &nested(MAX_XML_DEPTH - 2),
            Path::new("deep.urdf"),
            Path::new("."),
            &resolver,
        )
        .unwrap();
        assert_eq!(model.links.len(), 1);
    }

    #[test]
    fn line_col_is_read_from_parser_messages() {
        assert_eq!(
            line_col_in_message("Parse error; Line: 3, Column: 17, Reason: Unexpected token"),
            (Some(3), Some(17))
        );
        assert_eq!(
            line_col_in_message("missing field `velocity`"),
            (None, None)
        );
    }

    #[test]
    fn well_formedness_problems_have_positions() {
        let at = |xml: &str| check_well_formed(xml).map_err(|(o, m)| (line_col_at(xml, o), m));
        assert_eq!(
            at("<robot>\n  <link>\n  </lnk>\n</robot>")
                .unwrap_err()
                .0
                 .0,
            3
        );
        let (pos, message) = at("<robot>\n<link name=\"a\">\n</robot>").unwrap_err();
        assert_eq!(pos.0, 3, "{message}");
        let (pos, message) = at("<robot>\n  <link name=\"a\">").unwrap_err();
        assert_eq!((pos, message.as_str()), ((2, 3), "<link> is never closed"));
        assert!(at("<robot>\n<link name=a/></robot>").is_err());
        assert!(at("<robot/><robot/>").is_err());
        assert!(at("").is_err());
        assert!(at(
            "<?xml version=\"1.0\"?>\n<!-- c --><robot name=\"r\"><link name=\"a\"/></robot>\n"
        )
        .is_ok());
        assert_eq!(line_col_at("ab\ncd\u{e9}f", 7), (2, 4));
        assert_eq!(
            line_col_at("ab\ncd\u{e9}f", 6),
            (2, 3),
            "inside a character: its start"
        );
    }
}
