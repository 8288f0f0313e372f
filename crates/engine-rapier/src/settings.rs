//! The engine settings (`[engine.rapier]` in a scene file, `--set` on the
//! command line): parsing, checking, defaults.

use realitygap_core::engine::{
    EngineError, EngineSettings, SettingInfo, SettingsReader, TIMESTEP_KEY,
};

use crate::ENGINE_NAME;

/// The timestep used when the settings give none, s (the choice:
/// the study's PyBullet step, five steps per 0.05 s control period).
pub const DEFAULT_TIMESTEP_S: f64 = 0.01;

/// Default number of solver iterations (Rapier's substeps per step). Rapier's
/// own default, kept.
pub const DEFAULT_SOLVER_ITERATIONS: usize = 4;

/// Default number of projected Gauss-Seidel iterations inside each solver
/// iteration. Rapier's default is 1, which leaves the six coupled joint
/// motors of the arm far from converged: the arm sags by tens of degrees
/// under gravity. 20 converges them (see the crate README).
pub const DEFAULT_INTERNAL_PGS_ITERATIONS: usize = 20;

/// Default number of stabilization (position-correction) iterations per
/// solver iteration. Rapier's own default, kept.
pub const DEFAULT_STABILIZATION_ITERATIONS: usize = 1;

/// Largest accepted iteration count of any kind (a typo guard: more than
/// this would run for hours).
pub const MAX_ITERATIONS: i64 = 10_000;

/// How a URDF mesh becomes a collision shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeshShape {
    /// The convex hull of the mesh's vertices (what MuJoCo collides with).
    ConvexHull,
    /// The triangle mesh itself (a hollow surface: contacts only where
    /// surfaces cross).
    TriMesh,
}

impl MeshShape {
    /// The setting's text for this choice.
    pub fn name(self) -> &'static str {
        match self {
            MeshShape::ConvexHull => "convex_hull",
            MeshShape::TriMesh => "trimesh",
        }
    }
}

/// The settings accepted in `[engine.rapier]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo { key: TIMESTEP_KEY, help: "integration timestep, s (> 0, at most 1); default 0.01" },
    SettingInfo {
        key: "solver_iterations",
        help: "solver iterations (substeps) per step (1 to 10000); default 4 (Rapier's)",
    },
    SettingInfo {
        key: "internal_pgs_iterations",
        help: "Gauss-Seidel iterations per solver iteration (1 to 10000); default 20 (Rapier's 1 lets the arm sag)",
    },
    SettingInfo {
        key: "stabilization_iterations",
        help: "position-stabilization iterations per solver iteration (0 to 10000); default 1 (Rapier's)",
    },
    SettingInfo {
        key: "mesh_shape",
        help: "collision shape of URDF meshes: convex_hull | trimesh; default convex_hull",
    },
    SettingInfo {
        key: "self_collision",
        help: "the robot's links collide with each other (never two joined by a joint): true | false; default true (Rapier's); false as in Bullet, ODE and DART",
    },
];

/// Checked engine settings, every field filled with its default when not
/// given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RapierSettings {
    /// Integration timestep, s.
    pub timestep_s: f64,
    /// Rapier's `num_solver_iterations` (substeps per step).
    pub solver_iterations: usize,
    /// Rapier's `num_internal_pgs_iterations`.
    pub internal_pgs_iterations: usize,
    /// Rapier's `num_internal_stabilization_iterations`.
    pub stabilization_iterations: usize,
    /// Collision shape of URDF meshes.
    pub mesh_shape: MeshShape,
    /// Whether the robot's links collide with each other.
    pub self_collision: bool,
}

impl Default for RapierSettings {
    fn default() -> Self {
        RapierSettings {
            timestep_s: DEFAULT_TIMESTEP_S,
            solver_iterations: DEFAULT_SOLVER_ITERATIONS,
            internal_pgs_iterations: DEFAULT_INTERNAL_PGS_ITERATIONS,
            stabilization_iterations: DEFAULT_STABILIZATION_ITERATIONS,
            mesh_shape: MeshShape::ConvexHull,
            self_collision: true,
        }
    }
}

impl RapierSettings {
    /// Reads `settings` through the core's [`SettingsReader`], checking
    /// every key and value; unknown keys and bad values are errors naming
    /// the key and what is accepted.
    pub fn parse(settings: &EngineSettings) -> Result<RapierSettings, EngineError> {
        let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
        let d = RapierSettings::default();
        let count = |key: &str, min: i64, default: usize| -> Result<usize, EngineError> {
            Ok(r.integer(key, min, MAX_ITERATIONS)?
                .map_or(default, |v| v as usize))
        };
        Ok(RapierSettings {
            timestep_s: r
                .number(TIMESTEP_KEY, |v| v > 0.0 && v <= 1.0, "> 0 and at most 1 s")?
                .unwrap_or(d.timestep_s),
            solver_iterations: count("solver_iterations", 1, d.solver_iterations)?,
            internal_pgs_iterations: count(
                "internal_pgs_iterations",
                1,
                d.internal_pgs_iterations,
            )?,
            stabilization_iterations: count(
                "stabilization_iterations",
                0,
                d.stabilization_iterations,
            )?,
            mesh_shape: r
                .choice(
                    "mesh_shape",
                    &[
                        ("convex_hull", MeshShape::ConvexHull),
                        ("trimesh", MeshShape::TriMesh),
                    ],
                )?
                .unwrap_or(d.mesh_shape),
            self_collision: r.boolean("self_collision")?.unwrap_or(d.self_collision),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::SettingValue;

    fn settings(pairs: &[(&str, SettingValue)]) -> EngineSettings {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn defaults_when_empty() {
        let s = RapierSettings::parse(&EngineSettings::new()).unwrap();
        assert_eq!(s, RapierSettings::default());
        assert_eq!(s.timestep_s, 0.01);
        assert_eq!(s.internal_pgs_iterations, 20);
        assert_eq!(s.mesh_shape, MeshShape::ConvexHull);
    }

    #[test]
    fn reads_every_setting() {
        let s = RapierSettings::parse(&settings(&[
            ("timestep_s", SettingValue::Float(0.005)),
            ("solver_iterations", SettingValue::Integer(8)),
            ("internal_pgs_iterations", SettingValue::Integer(3)),
            ("stabilization_iterations", SettingValue::Integer(0)),
            ("mesh_shape", SettingValue::Text("TriMesh".into())),
            ("self_collision", SettingValue::Bool(false)),
        ]))
        .unwrap();
        assert_eq!(
            s,
            RapierSettings {
                timestep_s: 0.005,
                solver_iterations: 8,
                internal_pgs_iterations: 3,
                stabilization_iterations: 0,
                mesh_shape: MeshShape::TriMesh,
                self_collision: false,
            }
        );
        // An integer timestep is a number too.
        assert_eq!(
            RapierSettings::parse(&settings(&[("timestep_s", SettingValue::Integer(1))]))
                .unwrap()
                .timestep_s,
            1.0
        );
    }

    #[test]
    fn rejects_bad_values_naming_the_key() {
        let cases: &[(&str, SettingValue, &str)] = &[
            ("timestep_s", SettingValue::Float(0.0), "must be > 0"),
            ("timestep_s", SettingValue::Float(f64::NAN), "must be > 0"),
            ("timestep_s", SettingValue::Float(2.0), "at most 1"),
            (
                "timestep_s",
                SettingValue::Text("fast".into()),
                "expected a number",
            ),
            ("solver_iterations", SettingValue::Integer(0), "from 1 to"),
            (
                "solver_iterations",
                SettingValue::Float(4.5),
                "whole number",
            ),
            (
                "internal_pgs_iterations",
                SettingValue::Integer(1_000_000),
                "from 1 to 10000",
            ),
            (
                "stabilization_iterations",
                SettingValue::Integer(-1),
                "from 0 to",
            ),
            (
                "mesh_shape",
                SettingValue::Text("voxels".into()),
                "convex_hull, trimesh",
            ),
            (
                "mesh_shape",
                SettingValue::Bool(true),
                "convex_hull, trimesh",
            ),
            (
                "iterations",
                SettingValue::Integer(3),
                "unknown setting (accepted: timestep_s",
            ),
        ];
        for (key, value, expected) in cases {
            let err = RapierSettings::parse(&settings(&[(key, value.clone())])).unwrap_err();
            let text = err.to_string();
            assert!(
                text.contains(&format!("setting `{key}`")) && text.contains(expected),
                "{key}={value}: {text}"
            );
        }
    }
}
