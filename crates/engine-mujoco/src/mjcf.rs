//! MJCF text for a [`Scene`] with a URDF [`RobotModel`].
//!
//! The model, element by element:
//! - `<compiler angle="radian" inertiafromgeom="false">`: masses and
//!   inertias come only from the URDF's `<inertial>` elements (a link
//!   without one is massless, as in URDF); the scene's objects get theirs
//!   from their mass and size (uniform density).
//! - The ground: a plane `z = height_m`.
//! - The robot: one body per link, named like the link, whose frame is the
//!   URDF link frame, so a body's `xpos`/`xquat` is the link's pose. The
//!   root link is welded to the world at the scene's base pose. An actuated
//!   joint becomes a `hinge` (or `slide`) with the URDF axis, range, damping
//!   and friction loss; every other movable joint is held: its child body is
//!   welded to the parent at the held position. Fixed joints weld.
//! - Collision shapes: URDF `<collision>` boxes, cylinders, capsules,
//!   spheres and meshes (STL, OBJ; MuJoCo collides with a mesh's convex
//!   hull). Visuals are not loaded.
//! - Contacts between a link and its parent link are excluded (MuJoCo does
//!   so itself except for the links attached to the world-welded root).
//! - One `<velocity>` actuator per controlled joint with the scene's `kv`
//!   and force limit.
//! - Each scene object: a body named `object:NAME` with a free joint; when
//!   the scene gives its friction, its geom has `priority="1"` so that its
//!   coefficient is the contact's (MuJoCo otherwise takes the larger one).
//! - A zero force limit (servo off) is set on the compiled model, since
//!   MJCF rejects an empty `forcerange`.

/// Escapes text for an XML attribute value (`<>&'"` as entities).
use quick_xml::escape::escape as esc;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::plan;
use realitygap_core::robot::{Geometry, Inertial, Joint, JointKind, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene};
use std::fmt::Write;

/// Prefix of the body name of a scene object.
pub const OBJECT_BODY_PREFIX: &str = "object:";

/// Name of the MuJoCo body of a URDF link: the link's name, except that a
/// link named `world` (common in URDFs made for Gazebo) becomes
/// `urdf:world`, because MuJoCo reserves `world`.
pub fn body_name(link: &str) -> String {
    if link == "world" {
        "urdf:world".to_string()
    } else {
        link.to_string()
    }
}

/// Name of the MuJoCo actuator of a controlled joint.
pub fn actuator_name(joint: &str) -> String {
    format!("servo:{joint}")
}

/// Shortest text that reads back as the same f64.
fn num(x: f64) -> String {
    format!("{x:?}")
}

fn v3(v: Vec3) -> String {
    format!("{} {} {}", num(v.x), num(v.y), num(v.z))
}

fn quat(q: Quat) -> String {
    format!("{} {} {} {}", num(q.w), num(q.x), num(q.y), num(q.z))
}

fn pose_attrs(p: &Pose) -> String {
    format!(
        "pos=\"{}\" quat=\"{}\"",
        v3(p.position_m),
        quat(p.orientation)
    )
}

/// Why a scene and robot cannot be written as MJCF.
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfError(pub String);

/// Writes the MJCF model of `scene` with `robot` (see the module
/// documentation). The robot must have been validated against the scene.
pub fn scene_to_mjcf(scene: &Scene, robot: &RobotModel) -> Result<String, MjcfError> {
    // The scene's names and held positions, resolved by core's shared
    // planning (the MJCF keeps the tree, so the rigid groups are not used).
    let actuated = plan::actuated_joints(scene, robot).map_err(|e| MjcfError(e.0))?;
    let positions = plan::initial_positions(scene, robot, &actuated).map_err(|e| MjcfError(e.0))?;
    check_link_names(robot)?;

    let mut world = ground_xml(scene);
    // Robot bodies, depth first.
    let mut writer = RobotWriter {
        robot,
        positions: &positions,
        actuated: &actuated,
        assets: String::new(),
        mesh_count: 0,
        excludes: Vec::new(),
    };
    let mut body_xml = String::new();
    writer.write_link(&mut body_xml, robot.root_link, &scene.robot.base, None, 2)?;
    world.push_str(&body_xml);
    write_objects(&mut world, scene);
    let actuators = actuators_xml(scene);
    Ok(document(
        scene,
        robot,
        &writer.assets,
        &world,
        &writer.excludes,
        &actuators,
    ))
}

/// Refuses a robot link whose name clashes with the scene objects' bodies.
fn check_link_names(robot: &RobotModel) -> Result<(), MjcfError> {
    for link in &robot.links {
        if link.name.starts_with(OBJECT_BODY_PREFIX) || link.name == "urdf:world" {
            return Err(MjcfError(format!(
                "link name \"{}\" clashes with the names of scene objects",
                link.name
            )));
        }
    }
    Ok(())
}

/// The ground plane's `<geom>` line (empty without a ground).
fn ground_xml(scene: &Scene) -> String {
    let mut world = String::new();
    if let Some(g) = &scene.ground {
        let friction = g
            .friction
            .map(|f| format!(" friction=\"{} 0.005 0.0001\"", num(f)))
            .unwrap_or_default();
        writeln!(
            world,
            "    <geom name=\"ground\" type=\"plane\" size=\"0 0 1\" pos=\"0 0 {}\"{friction}/>",
            num(g.height_m)
        )
        .unwrap();
    }
    world
}

/// The scene objects' free bodies.
fn write_objects(world: &mut String, scene: &Scene) {
    for o in &scene.objects {
        let inertia = o.principal_inertia();
        // With priority 1 the object's coefficient is the contact's
        // (MuJoCo otherwise takes the larger of the two geoms').
        let friction = o
            .friction
            .map(|f| format!(" friction=\"{} 0.005 0.0001\" priority=\"1\"", num(f)))
            .unwrap_or_default();
        let geom = match o.shape {
            ObjectShape::Box { size_m } => {
                format!("type=\"box\" size=\"{}\"", v3(size_m.scale(0.5)))
            }
        };
        writeln!(
            world,
            "    <body name=\"{}{}\" {}>",
            OBJECT_BODY_PREFIX,
            esc(&o.name),
            pose_attrs(&o.pose)
        )
        .unwrap();
        writeln!(
            world,
            "      <freejoint name=\"{}{}\"/>",
            OBJECT_BODY_PREFIX,
            esc(&o.name)
        )
        .unwrap();
        writeln!(
            world,
            "      <inertial pos=\"0 0 0\" mass=\"{}\" diaginertia=\"{}\"/>",
            num(o.mass_kg),
            v3(inertia)
        )
        .unwrap();
        writeln!(world, "      <geom {geom}{friction}/>").unwrap();
        writeln!(world, "    </body>").unwrap();
    }
}

/// The `<velocity>` actuators of the scene's servos.
fn actuators_xml(scene: &Scene) -> String {
    let mut actuators = String::new();
    for a in &scene.actuators {
        // A zero limit (servo off) is set on the compiled model: MuJoCo
        // rejects an empty forcerange in MJCF.
        let limit = if a.force_limit.is_finite() && a.force_limit > 0.0 {
            format!(
                " forcelimited=\"true\" forcerange=\"{} {}\"",
                num(-a.force_limit),
                num(a.force_limit)
            )
        } else {
            String::new()
        };
        writeln!(
            actuators,
            "    <velocity name=\"{}\" joint=\"{}\" kv=\"{}\"{limit}/>",
            esc(actuator_name(&a.joint)),
            esc(&a.joint),
            num(a.kv)
        )
        .unwrap();
    }
    actuators
}

/// The whole `<mujoco>` document from its parts.
fn document(
    scene: &Scene,
    robot: &RobotModel,
    assets: &str,
    world: &str,
    excludes: &[(String, String)],
    actuators: &str,
) -> String {
    let mut xml = String::new();
    writeln!(
        xml,
        "<mujoco model=\"{}\">",
        esc(format!("{} ({})", scene.name, robot.name))
    )
    .unwrap();
    writeln!(
        xml,
        "  <compiler angle=\"radian\" inertiafromgeom=\"false\" autolimits=\"true\"/>"
    )
    .unwrap();
    if !assets.is_empty() {
        writeln!(xml, "  <asset>\n{assets}  </asset>").unwrap();
    }
    writeln!(xml, "  <worldbody>\n{world}  </worldbody>").unwrap();
    if !excludes.is_empty() {
        writeln!(xml, "  <contact>").unwrap();
        for (a, b) in excludes {
            writeln!(
                xml,
                "    <exclude body1=\"{}\" body2=\"{}\"/>",
                esc(a),
                esc(b)
            )
            .unwrap();
        }
        writeln!(xml, "  </contact>").unwrap();
    }
    writeln!(xml, "  <actuator>\n{actuators}  </actuator>").unwrap();
    writeln!(xml, "</mujoco>").unwrap();
    xml
}

/// Writes the robot's bodies and collects what they need elsewhere in the
/// document: the mesh assets and the parent-child contact exclusions.
struct RobotWriter<'a> {
    robot: &'a RobotModel,
    /// Initial joint positions (rad or m), by URDF joint index.
    positions: &'a [f64],
    /// URDF indices of the actuated joints.
    actuated: &'a [usize],
    /// The `<mesh>` assets written so far.
    assets: String,
    /// Meshes written so far (names the next one).
    mesh_count: usize,
    /// Parent-child body pairs whose contacts are excluded.
    excludes: Vec<(String, String)>,
}

impl RobotWriter<'_> {
    /// Writes the body of link `link_index` at `body_pose` (in its parent's
    /// frame), entered through joint `joint_index`, then its children.
    fn write_link(
        &mut self,
        out: &mut String,
        link_index: usize,
        body_pose: &Pose,
        joint_index: Option<usize>,
        depth: usize,
    ) -> Result<(), MjcfError> {
        let robot = self.robot;
        let link = &robot.links[link_index];
        let ind = "  ".repeat(depth);
        writeln!(
            out,
            "{ind}<body name=\"{}\" {}>",
            esc(body_name(&link.name)),
            pose_attrs(body_pose)
        )
        .unwrap();
        if let Some(j) = joint_index.filter(|j| self.actuated.contains(j)) {
            writeln!(out, "{ind}  <joint {}/>", joint_attrs(&robot.joints[j])).unwrap();
        }
        if let Some(line) = link.inertial.as_ref().and_then(inertial_xml) {
            writeln!(out, "{ind}  {line}").unwrap();
        }
        for c in &link.collisions {
            let shape = self.geom_shape(&link.name, &c.geometry)?;
            writeln!(out, "{ind}  <geom {shape} {}/>", pose_attrs(&c.origin)).unwrap();
        }
        for &j in robot.child_joints(link_index) {
            let joint = &robot.joints[j];
            let child_pose = if self.actuated.contains(&j) || joint.kind == JointKind::Fixed {
                joint.origin
            } else {
                // Held joint: welded at its held position.
                joint.transform(self.positions[j])
            };
            self.excludes.push((
                body_name(&link.name),
                body_name(&robot.links[joint.child].name),
            ));
            self.write_link(out, joint.child, &child_pose, Some(j), depth + 1)?;
        }
        writeln!(out, "{ind}</body>").unwrap();
        Ok(())
    }

    /// The `type`/`size` (or `mesh`) attributes of a collision geometry of
    /// link `link`; a mesh is added to the assets.
    fn geom_shape(&mut self, link: &str, geometry: &Geometry) -> Result<String, MjcfError> {
        Ok(match geometry {
            Geometry::Box { size_m } => format!("type=\"box\" size=\"{}\"", v3(size_m.scale(0.5))),
            Geometry::Cylinder { radius_m, length_m } => {
                format!(
                    "type=\"cylinder\" size=\"{} {}\"",
                    num(*radius_m),
                    num(length_m / 2.0)
                )
            }
            Geometry::Capsule { radius_m, length_m } => {
                format!(
                    "type=\"capsule\" size=\"{} {}\"",
                    num(*radius_m),
                    num(length_m / 2.0)
                )
            }
            Geometry::Sphere { radius_m } => format!("type=\"sphere\" size=\"{}\"", num(*radius_m)),
            Geometry::Mesh { path, uri, scale } => {
                let ext = path
                    .extension()
                    .and_then(|e| e.to_str())
                    .unwrap_or("")
                    .to_ascii_lowercase();
                let name = format!("mesh{}", self.mesh_count);
                if ext == "dae" {
                    // MuJoCo reads no COLLADA: its triangles go inline
                    // (realitygap's reader, units and transforms applied).
                    let mesh = realitygap_core::robot::stl::TriangleMesh::read(path)
                        .map_err(|e| MjcfError(format!("link \"{link}\": mesh \"{uri}\": {e}")))?;
                    let mut vertex = String::new();
                    let mut face = String::new();
                    for (k, t) in mesh.triangles.iter().enumerate() {
                        for v in t {
                            write!(vertex, "{} ", v3(*v)).unwrap();
                        }
                        write!(face, "{} {} {} ", 3 * k, 3 * k + 1, 3 * k + 2).unwrap();
                    }
                    self.mesh_count += 1;
                    writeln!(
                        self.assets,
                        "    <mesh name=\"{name}\" vertex=\"{}\" face=\"{}\" scale=\"{}\"/>",
                        vertex.trim_end(),
                        face.trim_end(),
                        v3(*scale)
                    )
                    .unwrap();
                    return Ok(format!("type=\"mesh\" mesh=\"{name}\""));
                }
                if !matches!(ext.as_str(), "stl" | "obj" | "msh") {
                    return Err(MjcfError(format!(
                        "link \"{link}\": mesh \"{uri}\" ({}) is not a mesh format read (STL, OBJ, COLLADA .dae, or MuJoCo's MSH)",
                        path.display()
                    )));
                }
                let file = path.to_str().ok_or_else(|| {
                    MjcfError(format!(
                        "link \"{link}\": mesh path {} is not valid UTF-8",
                        path.display()
                    ))
                })?;
                if ext != "msh" {
                    // MuJoCo's own readers accept some damaged files (an
                    // OBJ face naming a missing vertex): checked here.
                    realitygap_core::robot::stl::TriangleMesh::read(path)
                        .map_err(|e| MjcfError(format!("link \"{link}\": mesh \"{uri}\": {e}")))?;
                }
                self.mesh_count += 1;
                writeln!(
                    self.assets,
                    "    <mesh name=\"{name}\" file=\"{}\" scale=\"{}\"/>",
                    esc(file),
                    v3(*scale)
                )
                .unwrap();
                format!("type=\"mesh\" mesh=\"{name}\"")
            }
        })
    }
}

/// The attributes of an actuated joint's `<joint>` element.
fn joint_attrs(joint: &Joint) -> String {
    let kind = match joint.kind {
        JointKind::Revolute | JointKind::Continuous => "hinge",
        JointKind::Prismatic => "slide",
        JointKind::Fixed => {
            unreachable!("fixed joints are never actuated (core's plan refuses them)")
        }
    };
    let mut attrs = format!(
        "name=\"{}\" type=\"{kind}\" axis=\"{}\"",
        esc(&joint.name),
        v3(joint.axis)
    );
    if let Some(lim) = joint.limits {
        if lim.lower.is_finite() && lim.upper.is_finite() {
            write!(
                attrs,
                " limited=\"true\" range=\"{} {}\"",
                num(lim.lower),
                num(lim.upper)
            )
            .unwrap();
        }
    }
    if joint.damping > 0.0 {
        write!(attrs, " damping=\"{}\"", num(joint.damping)).unwrap();
    }
    if joint.friction > 0.0 {
        write!(attrs, " frictionloss=\"{}\"", num(joint.friction)).unwrap();
    }
    attrs
}

/// A link's `<inertial>` element (none for a massless link). MuJoCo's
/// fullinertia is in the body frame: the URDF tensor (given in the rotated
/// centre-of-mass frame) is rotated into it.
fn inertial_xml(inertial: &Inertial) -> Option<String> {
    // (also none for a NaN mass, as `> 0` is false)
    if inertial.mass_kg.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let r = inertial.origin.orientation.to_rotation_matrix();
    let i = inertial.inertia_matrix();
    let mut ri = [0.0; 9];
    let mut m = [0.0; 9];
    for a in 0..3 {
        for b in 0..3 {
            ri[3 * a + b] = (0..3).map(|k| r[3 * a + k] * i[3 * k + b]).sum();
        }
    }
    for a in 0..3 {
        for b in 0..3 {
            m[3 * a + b] = (0..3).map(|k| ri[3 * a + k] * r[3 * b + k]).sum();
        }
    }
    Some(format!(
        "<inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{} {} {} {} {} {}\"/>",
        v3(inertial.origin.position_m),
        num(inertial.mass_kg),
        num(m[0]),
        num(m[4]),
        num(m[8]),
        num(m[1]),
        num(m[2]),
        num(m[5])
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::robot::PackageResolver;
    use std::path::{Path, PathBuf};

    fn workspace() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
    }

    const ARM: &str = r#"<robot name="arm">
  <link name="world"/>
  <link name="a">
    <inertial><origin xyz="0 0 0.1" rpy="0 0 1.5707963267948966"/><mass value="1"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial>
    <collision><geometry><box size="0.1 0.2 0.3"/></geometry></collision>
  </link>
  <link name="b">
    <inertial><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
    <collision><geometry><capsule radius="0.02" length="0.2"/></geometry></collision>
  </link>
  <link name="c"/>
  <joint name="fix" type="fixed"><parent link="world"/><child link="a"/></joint>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/><dynamics damping="0.2"/></joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0 0 0.2"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
</robot>"#;

    const SCENE: &str = r#"
name = "t"
duration_s = 1.0
[robot]
urdf = "arm.urdf"
base_position_m = [0, 0, 0.5]
[robot.held_joints_deg]
j2 = 30.0
[ground]
height_m = 0.0
friction = 0.7
[[object]]
name = "block"
shape = "box"
size_m = [0.1, 0.1, 0.1]
mass_kg = 0.2
position_m = [1, 0, 0.05]
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "j1"
kv = 5.0
force_limit = 3.0
[[schedule]]
t_s = 0.0
targets_deg = { j1 = 10.0 }
"#;

    fn build() -> String {
        let robot =
            RobotModel::from_urdf_str(ARM, Path::new("/tmp"), &PackageResolver::new()).unwrap();
        let scene = Scene::from_toml_str(SCENE, Path::new("/tmp/t.toml")).unwrap();
        scene.validate(&robot).unwrap();
        scene_to_mjcf(&scene, &robot).unwrap()
    }

    #[test]
    fn writes_joints_servos_objects_and_excludes() {
        let xml = build();
        assert!(xml.contains("<body name=\"urdf:world\""), "{xml}");
        assert!(xml.contains("<joint name=\"j1\" type=\"hinge\" axis=\"0.0 1.0 0.0\" limited=\"true\" range=\"-1.0 1.0\" damping=\"0.2\"/>"), "{xml}");
        assert!(
            !xml.contains("name=\"j2\""),
            "held joint must be welded: {xml}"
        );
        assert!(xml.contains("<velocity name=\"servo:j1\" joint=\"j1\" kv=\"5.0\" forcelimited=\"true\" forcerange=\"-3.0 3.0\"/>"));
        assert!(xml.contains("<freejoint name=\"object:block\"/>"));
        assert!(xml.contains("<geom type=\"box\" size=\"0.05 0.05 0.05\"/>"));
        assert!(xml.contains("friction=\"0.7 0.005 0.0001\""));
        assert!(xml.contains("<exclude body1=\"a\" body2=\"b\"/>"));
        assert!(xml.contains("type=\"capsule\" size=\"0.02 0.1\""));
        // The inertia, rotated by 90 degrees about z, swaps ixx and iyy.
        assert!(xml.contains("fullinertia=\"0.02"), "{xml}");
    }

    #[test]
    fn collada_goes_inline_and_unknown_formats_are_refused() {
        let dir = std::env::temp_dir().join(format!("rg-dae-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("part.dae"), "<COLLADA/>").unwrap();
        std::fs::write(dir.join("part.ply"), "ply\n").unwrap();
        let with = |file: &str| {
            let urdf = ARM.replace(
                "<box size=\"0.1 0.2 0.3\"/>",
                &format!("<mesh filename=\"{file}\"/>"),
            );
            let robot = RobotModel::from_urdf_str(&urdf, &dir, &PackageResolver::new()).unwrap();
            let scene = Scene::from_toml_str(SCENE, &dir.join("t.toml")).unwrap();
            scene_to_mjcf(&scene, &robot)
        };
        let err = with("part.ply").unwrap_err();
        assert!(
            err.0.contains("part.ply") && err.0.contains("STL, OBJ, COLLADA .dae"),
            "{}",
            err.0
        );
        let err = with("part.dae").unwrap_err();
        assert!(
            err.0.contains("part.dae") && err.0.contains("not a valid COLLADA mesh"),
            "{}",
            err.0
        );
        // A tetrahedron in OBJ, written as COLLADA by hand: inline.
        std::fs::write(
            dir.join("tet.dae"),
            r##"<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1"><asset><unit meter="0.5"/><up_axis>Z_UP</up_axis></asset>
<library_geometries><geometry id="g"><mesh><source id="p"><float_array id="a" count="12">0 0 0 1 0 0 0 1 0 0 0 1</float_array><technique_common><accessor source="#a" count="4" stride="3"><param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
<vertices id="v"><input semantic="POSITION" source="#p"/></vertices><triangles count="4"><input semantic="VERTEX" source="#v" offset="0"/><p>0 2 1 0 1 3 0 3 2 1 2 3</p></triangles></mesh></geometry></library_geometries>
<library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#g"/></node></visual_scene></library_visual_scenes><scene><instance_visual_scene url="#s"/></scene></COLLADA>"##,
        )
        .unwrap();
        let xml = with("tet.dae").unwrap();
        assert!(xml.contains("face=\"0 1 2 3 4 5 6 7 8 9 10 11\""), "{xml}");
        assert!(
            xml.contains("vertex=\"0.0 0.0 0.0 0.0 0.5 0.0 0.5 0.0 0.0"),
            "{xml}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_project_scenes_build() {
        let robot = RobotModel::from_urdf_file(
            &workspace().join("assets/robots/mico2/mico2.urdf"),
            &PackageResolver::new(),
        )
        .unwrap();
        for name in [
            "scene1_single_joint",
            "scene2_two_joints",
            "scene3_cube_push",
        ] {
            let scene =
                Scene::from_file(&workspace().join(format!("assets/scenes/{name}.toml"))).unwrap();
            scene.validate(&robot).unwrap();
            let xml = scene_to_mjcf(&scene, &robot).unwrap();
            assert_eq!(xml.matches("<velocity ").count(), 6, "{name}");
        }
    }
}
