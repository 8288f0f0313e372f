//! Shared helpers of the engine's integration tests.
#![allow(dead_code, unused_imports)]

pub use realitygap_core::testing::{
    cube, mico2, official_robot, official_scene, paper_data, scene, workspace, wrist,
};

use realitygap_core::controller::{simulate, RunOptions, RunOutcome, RunStatus};
use realitygap_core::engine::EngineSettings;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_bullet::BulletEngine;
use std::path::{Path, PathBuf};

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
