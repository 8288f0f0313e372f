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

use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::plan;
use realitygap_core::robot::{Geometry, JointKind, RobotModel};
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

/// Escapes text for an XML attribute value.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
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
    for link in &robot.links {
        if link.name.starts_with(OBJECT_BODY_PREFIX) || link.name == "urdf:world" {
            return Err(MjcfError(format!(
                "link name \"{}\" clashes with the names of scene objects",
                link.name
            )));
        }
    }

    let mut assets = String::new();
    let mut mesh_count = 0usize;
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

    // Robot bodies, depth first.
    let mut excludes = Vec::new();
    let mut body_xml = String::new();
    write_link(
        robot,
        robot.root_link,
        &scene.robot.base,
        None,
        2,
        &positions,
        &actuated,
        &mut body_xml,
        &mut assets,
        &mut mesh_count,
        &mut excludes,
    )?;
    world.push_str(&body_xml);

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
            esc(&actuator_name(&a.joint)),
            esc(&a.joint),
            num(a.kv)
        )
        .unwrap();
    }

    let mut xml = String::new();
    writeln!(
        xml,
        "<mujoco model=\"{}\">",
        esc(&format!("{} ({})", scene.name, robot.name))
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
        for (a, b) in &excludes {
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
    Ok(xml)
}

#[allow(clippy::too_many_arguments)]
fn write_link(
    robot: &RobotModel,
    link_index: usize,
    body_pose: &Pose,
    joint_index: Option<usize>,
    depth: usize,
    positions: &[f64],
    actuated: &[usize],
    out: &mut String,
    assets: &mut String,
    mesh_count: &mut usize,
    excludes: &mut Vec<(String, String)>,
) -> Result<(), MjcfError> {
    let link = &robot.links[link_index];
    let ind = "  ".repeat(depth);
    writeln!(
        out,
        "{ind}<body name=\"{}\" {}>",
        esc(&body_name(&link.name)),
        pose_attrs(body_pose)
    )
    .unwrap();
    if let Some(j) = joint_index.filter(|j| actuated.contains(j)) {
        let joint = &robot.joints[j];
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
        writeln!(out, "{ind}  <joint {attrs}/>").unwrap();
    }
    if let Some(inertial) = &link.inertial {
        if inertial.mass_kg > 0.0 {
            // MuJoCo's fullinertia is in the body frame: rotate the URDF
            // tensor (given in the rotated centre-of-mass frame) into it.
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
            writeln!(
                out,
                "{ind}  <inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{} {} {} {} {} {}\"/>",
                v3(inertial.origin.position_m),
                num(inertial.mass_kg),
                num(m[0]),
                num(m[4]),
                num(m[8]),
                num(m[1]),
                num(m[2]),
                num(m[5])
            )
            .unwrap();
        }
    }
    for c in &link.collisions {
        let shape = match &c.geometry {
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
                if !matches!(ext.as_str(), "stl" | "obj" | "msh") {
                    return Err(MjcfError(format!(
                        "link \"{}\": mesh \"{uri}\" ({}) is not a format MuJoCo reads (STL, OBJ or MSH)",
                        link.name,
                        path.display()
                    )));
                }
                let file = path.to_str().ok_or_else(|| {
                    MjcfError(format!(
                        "link \"{}\": mesh path {} is not valid UTF-8",
                        link.name,
                        path.display()
                    ))
                })?;
                let name = format!("mesh{}", *mesh_count);
                *mesh_count += 1;
                writeln!(
                    assets,
                    "    <mesh name=\"{name}\" file=\"{}\" scale=\"{}\"/>",
                    esc(file),
                    v3(*scale)
                )
                .unwrap();
                format!("type=\"mesh\" mesh=\"{name}\"")
            }
        };
        writeln!(out, "{ind}  <geom {shape} {}/>", pose_attrs(&c.origin)).unwrap();
    }
    for &j in robot.child_joints(link_index) {
        let joint = &robot.joints[j];
        let child_pose = if actuated.contains(&j) || joint.kind == JointKind::Fixed {
            joint.origin
        } else {
            // Held joint: welded at its held position.
            joint.transform(positions[j])
        };
        excludes.push((
            body_name(&link.name),
            body_name(&robot.links[joint.child].name),
        ));
        write_link(
            robot,
            joint.child,
            &child_pose,
            Some(j),
            depth + 1,
            positions,
            actuated,
            out,
            assets,
            mesh_count,
            excludes,
        )?;
    }
    writeln!(out, "{ind}</body>").unwrap();
    Ok(())
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
    fn rejects_mesh_formats_mujoco_cannot_read() {
        let dir = std::env::temp_dir().join(format!("rg-dae-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("part.dae"), "<COLLADA/>").unwrap();
        let urdf = ARM.replace(
            "<box size=\"0.1 0.2 0.3\"/>",
            "<mesh filename=\"part.dae\"/>",
        );
        let robot = RobotModel::from_urdf_str(&urdf, &dir, &PackageResolver::new()).unwrap();
        let scene = Scene::from_toml_str(SCENE, &dir.join("t.toml")).unwrap();
        let err = scene_to_mjcf(&scene, &robot).unwrap_err();
        assert!(
            err.0.contains("part.dae") && err.0.contains("STL, OBJ or MSH"),
            "{}",
            err.0
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
