//! Shared helpers of the engine's integration tests.
#![allow(dead_code)]

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::engine::EngineSettings;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_bullet::BulletEngine;
use std::path::{Path, PathBuf};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The study's recordings, or `None` (with a message) when they are absent.
pub fn paper_data() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/paper-data");
    if dir.join("Simulation").is_dir() {
        Some(dir)
    } else if std::env::var_os("REALITYGAP_REQUIRE_PAPER_DATA").is_some() {
        panic!(
            "paper data not found at {} and REALITYGAP_REQUIRE_PAPER_DATA is set",
            dir.display()
        );
    } else {
        eprintln!(
            "paper data not found at {}: skipping this test",
            dir.display()
        );
        None
    }
}

/// One of the project's scenes.
pub fn scene(name: &str) -> Scene {
    Scene::from_file(
        &workspace()
            .join("assets/scenes")
            .join(format!("{name}.toml")),
    )
    .unwrap()
}

/// A scene with the official Kinova URDF (meshes) as its robot.
pub fn official_scene(name: &str, paper: &Path) -> Scene {
    let mut s = scene(name);
    s.set_robot_urdf(paper.join("kinova_description/urdf/m1n6s300.urdf"));
    s
}

/// The official Kinova URDF, with its meshes resolved in the paper data.
pub fn official_robot(paper: &Path) -> RobotModel {
    let mut resolver = PackageResolver::new();
    resolver.insert("kinova_description", paper.join("kinova_description"));
    RobotModel::from_urdf_file(
        &paper.join("kinova_description/urdf/m1n6s300.urdf"),
        &resolver,
    )
    .unwrap()
}

/// The project's Mico2.
pub fn mico2() -> RobotModel {
    RobotModel::from_urdf_file(
        &workspace().join("assets/robots/mico2/mico2.urdf"),
        &PackageResolver::new(),
    )
    .unwrap()
}

/// Runs a scene through Bullet with the scene's own settings plus `extra`.
pub fn run_with(scene: &Scene, robot: &RobotModel, extra: &EngineSettings) -> RunOutcome {
    scene.validate(robot).unwrap();
    let mut settings = scene.settings_for("bullet");
    settings.extend(extra.clone());
    let out = simulate(
        &BulletEngine,
        scene,
        robot,
        &settings,
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(out.status, RunStatus::Completed, "{}", scene.name);
    out
}

/// Runs a scene through Bullet with the scene's own settings.
pub fn run(scene: &Scene, robot: &RobotModel) -> RunOutcome {
    run_with(scene, robot, &EngineSettings::new())
}

/// Wrist positions of a run.
pub fn wrist(out: &RunOutcome) -> Vec<Vec3> {
    out.trajectory
        .positions("wrist")
        .into_iter()
        .map(|p| p.unwrap())
        .collect()
}

/// Cube positions of a run.
pub fn cube(out: &RunOutcome) -> Vec<Vec3> {
    out.trajectory
        .positions("cube")
        .into_iter()
        .map(|p| p.unwrap())
        .collect()
}

/// A CSV written by tools/pybullet_reference.py: its '#' provenance lines,
/// column names and rows.
pub struct Reference {
    pub provenance: Vec<String>,
    pub columns: Vec<String>,
    pub rows: Vec<Vec<f64>>,
}

impl Reference {
    pub fn read(name: &str) -> Reference {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures")
            .join(name);
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut provenance = Vec::new();
        let mut columns = Vec::new();
        let mut rows = Vec::new();
        for (i, line) in text.lines().enumerate() {
            if let Some(p) = line.strip_prefix('#') {
                provenance.push(p.trim().to_string());
            } else if columns.is_empty() {
                columns = line.split(',').map(str::to_string).collect();
            } else if !line.trim().is_empty() {
                let row: Vec<f64> = line
                    .split(',')
                    .map(|v| {
                        v.parse().unwrap_or_else(|_| {
                            panic!("{}:{}: bad number {v}", path.display(), i + 1)
                        })
                    })
                    .collect();
                assert_eq!(row.len(), columns.len(), "{}:{}", path.display(), i + 1);
                rows.push(row);
            }
        }
        Reference {
            provenance,
            columns,
            rows,
        }
    }

    /// The values of three columns `PREFIX_x_m`, `_y_m`, `_z_m` per row.
    pub fn positions(&self, prefix: &str) -> Vec<Vec3> {
        let col = |c: &str| {
            let name = format!("{prefix}_{c}");
            self.columns
                .iter()
                .position(|n| *n == name)
                .unwrap_or_else(|| panic!("no column {name}"))
        };
        let (x, y, z) = (col("x_m"), col("y_m"), col("z_m"));
        self.rows
            .iter()
            .map(|r| Vec3::new(r[x], r[y], r[z]))
            .collect()
    }
}

/// Distances between two position sequences of equal length, m.
pub fn gaps(a: &[Vec3], b: &[Vec3]) -> Vec<f64> {
    assert_eq!(a.len(), b.len(), "sample counts differ");
    a.iter().zip(b).map(|(p, q)| p.distance(*q)).collect()
}

/// (index, value) of the largest element.
pub fn argmax(v: &[f64]) -> (usize, f64) {
    v.iter().copied().enumerate().fold(
        (0, f64::NEG_INFINITY),
        |a, (i, g)| if g > a.1 { (i, g) } else { a },
    )
}
