//! URDFs in the wild use Wavefront OBJ and COLLADA meshes as well as STL.
//! The iiwa's collision meshes, written as OBJ and as COLLADA (some in
//! millimetres with their `<unit>`) by an independent writer (trimesh from
//! PyPI, `scripts/make-fixtures`), push the box of `iiwa_push` to where the
//! STL meshes push it, in every compiled engine; damaged OBJ and COLLADA
//! files are errors that name the file.

mod common;
use common::{path, realitygap, scratch, text};
use realitygap_core::Vec3;
use realitygap_data::RunStore;
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    let dir = realitygap_core::testing::workspace().join("third_party/fixtures/meshes");
    assert!(
        dir.join("meshes.json").is_file(),
        "{} is missing: run scripts/setup --tests (scripts/make-fixtures)",
        dir.display()
    );
    dir
}

/// Runs `iiwa_push` with the robot `urdf` in every compiled engine; the
/// box's final position per engine.
fn push(dir: &Path, urdf: &Path) -> Vec<(String, Vec3)> {
    let scene = realitygap_core::testing::workspace().join("assets/scenes/iiwa_push.toml");
    let out = realitygap(&[
        "run",
        &path(&scene),
        "--robot",
        &path(urdf),
        "--out",
        &path(dir),
    ]);
    assert!(
        out.status.success(),
        "{}: {}{}",
        urdf.display(),
        text(&out.stdout),
        text(&out.stderr)
    );
    realitygap::physics_engines()
        .iter()
        .map(|e| {
            // `<engine>-<robot>` when --robot replaces the scene's robot.
            let source = std::fs::read_dir(dir.join("iiwa_push"))
                .unwrap()
                .map(|d| d.unwrap().path())
                .find(|p| {
                    let n = p.file_name().unwrap().to_string_lossy().to_string();
                    n == e.name() || n.starts_with(&format!("{}-", e.name()))
                })
                .unwrap_or_else(|| panic!("no results of {} in {}", e.name(), dir.display()));
            let store = RunStore::open(&source).unwrap();
            let id = store.runs()[0].id.clone();
            let t = store.read_run(&id).unwrap();
            let b = t.bodies.iter().position(|b| b.role == "box").unwrap();
            let end = t.bodies[b].poses.last().unwrap().unwrap().position_m;
            (e.name().to_string(), end)
        })
        .collect()
}

#[test]
fn obj_and_collada_meshes_push_the_box_where_stl_does_in_every_engine() {
    let f = fixtures();
    let dir = scratch("mesh-tests", "push");
    let stl = push(&dir.join("stl"), &f.join("model_stl.urdf"));
    for variant in ["obj", "dae"] {
        let other = push(&dir.join(variant), &f.join(format!("model_{variant}.urdf")));
        for ((engine, a), (_, b)) in stl.iter().zip(&other) {
            let d = (*a - *b).norm();
            println!(
                "{engine}: box ends {:.6} mm from the STL run with {variant} meshes (at {:.4} {:.4} {:.4})",
                d * 1e3,
                b.x,
                b.y,
                b.z
            );
            // The geometry is the same to 1e-5 m (core's fixture test);
            // contacts amplify the last bits of a vertex or the order of
            // triangles: measured 9.6 mm in ODE (triangle-mesh contacts),
            // 5.4 mm in MuJoCo and 2.4 mm in PhysX (convex hulls), under
            // 0.1 mm in Bullet and Rapier. Meshes read in the wrong unit
            // moved the box 50-250 mm.
            assert!(d < 15e-3, "{engine} with {variant}: {a:?} vs {b:?}");
        }
    }
    // The push happened: the box moved along -y.
    for (engine, end) in &stl {
        assert!(end.y < -0.05, "{engine}: box at {end:?}");
    }
}

#[test]
fn damaged_obj_and_collada_meshes_are_errors_naming_the_file() {
    let f = fixtures();
    let scene = realitygap_core::testing::workspace().join("assets/scenes/iiwa_push.toml");
    for (urdf, file) in [
        ("model_truncated_dae.urdf", "truncated.dae"),
        ("model_not_xml_dae.urdf", "not_xml.dae"),
        ("model_bad_index_obj.urdf", "bad_index.obj"),
    ] {
        let dir = scratch("mesh-tests", urdf);
        for engine in realitygap::physics_engines() {
            let out = realitygap(&[
                "run",
                &path(&scene),
                "--robot",
                &path(&f.join(urdf)),
                "--engine",
                engine.name(),
                "--out",
                &path(&dir),
            ]);
            let all = format!("{}{}", text(&out.stdout), text(&out.stderr));
            assert!(
                !out.status.success(),
                "{} with {urdf}: {all}",
                engine.name()
            );
            assert!(all.contains(file), "{} with {urdf}: {all}", engine.name());
            assert!(
                !all.contains("panicked"),
                "{} with {urdf}: {all}",
                engine.name()
            );
        }
    }
}
