//! Bad input gives a clear error, never a panic, and Bullet writes nothing
//! on standard output, even when it complains.

mod common;

use common::*;
use realitygap_core::engine::{
    Engine, EngineError, EngineSettings, ModelVariation, SettingValue, Simulation,
};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::testing::rerun_in_child;
use realitygap_engine_bullet::{BulletEngine, BulletSimulation};
use std::path::Path;

/// A fresh directory under the system's temporary directory, removed
/// when dropped.
struct TempDir(tempfile::TempDir);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

fn temp_dir(name: &str) -> TempDir {
    TempDir(
        tempfile::Builder::new()
            .prefix(&format!("realitygap-bullet-test-{name}-"))
            .tempdir()
            .unwrap(),
    )
}

/// A two-link arm whose upper link is a mesh `mesh_file`, as URDF text.
fn arm_urdf(mesh_file: &str) -> String {
    format!(
        r#"<?xml version="1.0"?>
<robot name="arm">
  <link name="base"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="upper">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision><geometry><mesh filename="{mesh_file}"/></geometry></collision>
  </link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
</robot>
"#
    )
}

const ARM_SCENE: &str = r#"
name = "arm"
duration_s = 0.2
[robot]
urdf = "arm.urdf"
base_position_m = [0, 0, 0.1]
[ground]
height_m = 0.0
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "j1"
kv = 10.0
force_limit = 10.0
[[schedule]]
t_s = 0.0
targets_deg = { j1 = 10.0 }
[[track]]
role = "tip"
link = "upper"
"#;

/// A binary STL with one triangle.
fn one_triangle_stl() -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&1u32.to_le_bytes());
    for v in [
        [0.0f32, 0.0, 1.0],
        [0.0, 0.0, 0.0],
        [0.1, 0.0, 0.0],
        [0.0, 0.1, 0.0],
    ] {
        for c in v {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    b.extend_from_slice(&[0, 0]);
    b
}

/// Writes the arm (URDF, a mesh file with `mesh_bytes`, scene) into `dir`
/// and reads the robot model.
fn arm(dir: &Path, mesh_bytes: &[u8]) -> (Scene, RobotModel) {
    std::fs::write(dir.join("upper.stl"), mesh_bytes).unwrap();
    std::fs::write(dir.join("arm.urdf"), arm_urdf("upper.stl")).unwrap();
    let scene = Scene::from_toml_str(ARM_SCENE, &dir.join("arm.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&dir.join("arm.urdf"), &PackageResolver::new()).unwrap();
    scene.validate(&robot).unwrap();
    (scene, robot)
}

fn load(scene: &Scene, robot: &RobotModel) -> Result<BulletSimulation, EngineError> {
    BulletSimulation::load(
        scene,
        robot,
        &EngineSettings::new(),
        &ModelVariation::default(),
    )
}

fn load_error(result: Result<BulletSimulation, EngineError>) -> String {
    match result {
        Ok(_) => panic!("expected an error"),
        Err(e) => {
            assert!(matches!(e, EngineError::Load { .. }), "{e:?}");
            eprintln!("error: {e}");
            e.to_string()
        }
    }
}

#[test]
fn a_good_mesh_arm_loads_and_moves() {
    let dir = temp_dir("good");
    let (scene, robot) = arm(&dir, &one_triangle_stl());
    let mut sim = load(&scene, &robot).unwrap();
    sim.set_joint_velocity_targets(&[0.5]);
    sim.step_n(10).unwrap();
    let mut q = [0.0];
    sim.joint_angles_rad(&mut q);
    assert!((q[0] - 0.05).abs() < 1e-3, "{}", q[0]);
    // The temporary URDF copy was removed.
    let leftovers: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with(&format!("realitygap-bullet-{}-", std::process::id()))
        })
        .collect();
    assert!(
        leftovers.is_empty(),
        "temporary URDF copies left: {leftovers:?}"
    );
}

#[test]
fn unreadable_mesh_is_a_clear_error() {
    let dir = temp_dir("garbage");
    let (scene, robot) = arm(&dir, b"this is not an STL file\n");
    let msg = load_error(load(&scene, &robot));
    assert!(
        msg.contains("engine bullet: cannot load the scene"),
        "{msg}"
    );
    assert!(msg.contains("arm.urdf"), "{msg}");
    assert!(msg.contains("upper"), "{msg}");
}

/// The arm with its upper link's mesh in a file `name` holding `content`.
fn arm_with_mesh_file(dir: &Path, name: &str, content: &str) -> (Scene, RobotModel) {
    std::fs::write(dir.join(name), content).unwrap();
    std::fs::write(dir.join("arm.urdf"), arm_urdf(name)).unwrap();
    let scene = Scene::from_toml_str(ARM_SCENE, &dir.join("arm.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&dir.join("arm.urdf"), &PackageResolver::new()).unwrap();
    (scene, robot)
}

/// A Wavefront OBJ file without geometry (Bullet would accept it silently
/// as an empty shape).
#[test]
fn empty_obj_mesh_is_a_clear_error() {
    let dir = temp_dir("obj");
    let (scene, robot) = arm_with_mesh_file(&dir, "upper.obj", "this is not a mesh\n");
    let msg = load_error(load(&scene, &robot));
    assert!(
        msg.contains("arm.urdf: link \"upper\": collision mesh"),
        "{msg}"
    );
    assert!(
        msg.contains("upper.obj") && msg.contains("holds no triangle"),
        "{msg}"
    );
}

/// A damaged COLLADA collision mesh is a clear error before Bullet sees it
/// (Bullet's own COLLADA reader dereferences missing elements and crashes
/// on a malformed file; well-formed ones reach it as STL).
#[test]
fn damaged_collada_mesh_is_a_clear_error() {
    let dir = temp_dir("dae");
    let (scene, robot) = arm_with_mesh_file(&dir, "upper.dae", "<COLLADA>not a mesh</COLLADA>\n");
    let msg = load_error(load(&scene, &robot));
    assert!(
        msg.contains("arm.urdf: link \"upper\": collision mesh"),
        "{msg}"
    );
    assert!(msg.contains("upper.dae: not a valid COLLADA mesh"), "{msg}");
}

/// A mesh format the engine leaves to Bullet (here an unknown extension):
/// Bullet's own complaint is caught.
#[test]
fn unknown_mesh_format_is_a_clear_error() {
    let dir = temp_dir("ply");
    let (scene, robot) =
        arm_with_mesh_file(&dir, "upper.ply", "ply\nformat ascii 1.0\nend_header\n");
    let msg = load_error(load(&scene, &robot));
    assert!(msg.contains("arm.urdf"), "{msg}");
    assert!(msg.contains("upper"), "{msg}");
}

/// A COLLADA *visual* mesh, even a malformed one, is never read: the
/// visuals are blanked out of the copy Bullet loads.
#[test]
fn malformed_collada_visual_is_ignored() {
    let dir = temp_dir("visual");
    std::fs::write(dir.join("upper.dae"), "<COLLADA>not a mesh</COLLADA>\n").unwrap();
    let urdf = arm_urdf("upper.dae").replace(
        "<collision><geometry><mesh filename=\"upper.dae\"/></geometry></collision>",
        "<visual><geometry><mesh filename=\"upper.dae\"/></geometry></visual><collision><geometry><sphere radius=\"0.05\"/></geometry></collision>",
    );
    std::fs::write(dir.join("arm.urdf"), urdf).unwrap();
    let scene = Scene::from_toml_str(ARM_SCENE, &dir.join("arm.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&dir.join("arm.urdf"), &PackageResolver::new()).unwrap();
    assert_eq!(robot.links[1].visuals.len(), 1);
    let mut sim = load(&scene, &robot).unwrap();
    sim.step_n(5).unwrap();
}

#[test]
fn mesh_removed_after_reading_the_model_is_a_clear_error() {
    let dir = temp_dir("removed");
    let (scene, robot) = arm(&dir, &one_triangle_stl());
    std::fs::remove_file(dir.join("upper.stl")).unwrap();
    let msg = load_error(load(&scene, &robot));
    assert!(msg.contains("arm.urdf"), "{msg}");
    assert!(msg.contains("upper"), "{msg}");
}

#[test]
fn urdf_malformed_after_reading_the_model_is_a_clear_error() {
    let dir = temp_dir("malformed");
    let (scene, robot) = arm(&dir, &one_triangle_stl());
    // An unclosed <link>: Bullet's XML parser rejects it.
    std::fs::write(dir.join("arm.urdf"), MALFORMED_ARM).unwrap();
    let msg = load_error(load(&scene, &robot));
    assert!(msg.contains("Bullet could not load URDF file"), "{msg}");
    assert!(msg.contains("arm.urdf"), "{msg}");
    assert!(msg.contains("Bullet said:"), "{msg}");
    // A URDF that no longer names the model's mesh.
    std::fs::write(
        dir.join("arm.urdf"),
        "<robot name=\"arm\"><link name=\"base\"></robot>",
    )
    .unwrap();
    let msg = load_error(load(&scene, &robot));
    assert!(msg.contains("arm.urdf"), "{msg}");
    assert!(
        msg.contains("no collision mesh filename attribute \"upper.stl\""),
        "{msg}"
    );
}

const MALFORMED_ARM: &str = r#"<robot name="arm"><link name="base">
<collision><geometry><mesh filename="upper.stl"/></geometry></collision>
</robot>"#;

/// A URDF file gone after the model was read (or a model read from a
/// string, such as the CLI's built-in Mico2): Bullet gets a URDF written
/// from the model itself.
#[test]
fn urdf_removed_after_reading_the_model_loads_from_the_model() {
    let dir = temp_dir("gone");
    std::fs::write(
        dir.join("arm.urdf"),
        arm_urdf("upper.stl").replace(
            r#"<mesh filename="upper.stl"/>"#,
            r#"<sphere radius="0.05"/>"#,
        ),
    )
    .unwrap();
    let scene = Scene::from_toml_str(ARM_SCENE, &dir.join("arm.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&dir.join("arm.urdf"), &PackageResolver::new()).unwrap();
    let mut from_file = load(&scene, &robot).unwrap();
    std::fs::remove_file(dir.join("arm.urdf")).unwrap();
    let mut from_model = load(&scene, &robot).unwrap();
    for sim in [&mut from_file, &mut from_model] {
        sim.set_joint_velocity_targets(&[0.5]);
        sim.step_n(20).unwrap();
    }
    let (mut a, mut b) = ([0.0], [0.0]);
    from_file.joint_angles_rad(&mut a);
    from_model.joint_angles_rad(&mut b);
    assert!((a[0] - b[0]).abs() < 1e-12, "{a:?} {b:?}");
}

#[test]
fn bad_settings_are_rejected_before_loading() {
    let dir = temp_dir("settings");
    let (scene, robot) = arm(&dir, &one_triangle_stl());
    let bad: EngineSettings = [("solver".to_string(), SettingValue::Text("dantzig".into()))]
        .into_iter()
        .collect();
    let e = BulletEngine
        .load(&scene, &robot, &bad, &ModelVariation::default())
        .err()
        .unwrap();
    assert!(matches!(e, EngineError::Setting { .. }), "{e:?}");
    assert!(e.to_string().contains("unknown setting"), "{e}");
    let bad: EngineSettings = [("timestep_s".to_string(), SettingValue::Float(-0.01))]
        .into_iter()
        .collect();
    assert!(BulletEngine.check_settings(&bad).is_err());
}

#[test]
fn wrong_vector_length_is_a_usage_error() {
    let mut sim = load(&scene("scene1_single_joint"), &mico2()).unwrap();
    let e = sim.set_joint_angles_rad(&[0.0; 3]).unwrap_err();
    assert!(matches!(e, EngineError::Usage { .. }), "{e:?}");
}

/// The lines the test harness itself writes with `-q`.
fn is_harness_line(line: &str) -> bool {
    line.is_empty()
        || line.starts_with("running ")
        || line.starts_with("test result: ")
        || line.chars().all(|c| c == '.')
}

const CHILD_ENV: &str = "REALITYGAP_BULLET_STDOUT_CHILD";

/// Runs itself again in a child process (this test binary, this test
/// only, with `REALITYGAP_BULLET_STDOUT_CHILD` set), where it makes Bullet
/// complain about the official URDF's massless root link, an unreadable
/// mesh and a malformed URDF; then checks that the child's standard output
/// holds nothing but the test harness's lines (Bullet's warnings and errors
/// must have been routed away from standard output). A single test, so
/// that no part of it can pass without checking anything.
#[test]
fn bullet_writes_nothing_to_stdout() {
    let Some(out) = rerun_in_child("bullet_writes_nothing_to_stdout", CHILD_ENV) else {
        make_bullet_complain();
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child failed:\n{stdout}\n{stderr}");
    assert!(
        stderr.contains("stdout_child: done"),
        "the child did not run: {stderr}"
    );
    let foreign: Vec<&str> = stdout.lines().filter(|l| !is_harness_line(l)).collect();
    assert!(
        foreign.is_empty(),
        "Bullet wrote to standard output: {foreign:?}"
    );
}

/// The child's work in `bullet_writes_nothing_to_stdout`: loads that make
/// Bullet print warnings and errors.
fn make_bullet_complain() {
    let dir = temp_dir("stdout");
    // Errors (the assertions on them are in the tests above; here they only
    // have to make Bullet complain).
    let (arm_scene, arm_robot) = arm(&dir, b"garbage");
    let _ = load(&arm_scene, &arm_robot);
    std::fs::write(dir.join("upper.stl"), one_triangle_stl()).unwrap();
    std::fs::write(dir.join("arm.urdf"), MALFORMED_ARM).unwrap();
    let _ = load(&arm_scene, &arm_robot);
    let mut sim = load(&scene("scene3_cube_push"), &mico2()).unwrap();
    sim.step_n(50).unwrap();
    if let Some(paper) = paper_data() {
        let s = official_scene("scene3_cube_push", &paper);
        let mut sim = load(&s, &official_robot(&paper)).unwrap();
        sim.set_joint_velocity_targets(&[0.0, 0.5, 0.5, 0.5, 0.0, 0.0]);
        sim.step_n(100).unwrap();
    }
    eprintln!("stdout_child: done");
}
