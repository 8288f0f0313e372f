//! The engine settings (`[engine.physx]` in a scene file, `--set` on the
//! command line): parsing, checking, defaults.

use realitygap_core::engine::{
    EngineError, EngineSettings, SettingInfo, SettingsReader, TIMESTEP_KEY,
};

use crate::ENGINE_NAME;

/// The timestep used when the settings give none, s: 200 Hz, the physics
/// rate of Isaac Lab's manipulation environments (ten steps per 0.05 s
/// control period).
pub const DEFAULT_TIMESTEP_S: f64 = 0.005;

/// Default position iterations of the articulation's solver. PhysX's own
/// default is 4, with which the arm's six coupled drives sag by 24 degrees
/// on joint 3 in scene 1; 32 end within 0.2 degrees of where the servos
/// balance gravity (the crate README has the whole measurement).
pub const DEFAULT_POSITION_ITERATIONS: u32 = 32;

/// Default velocity iterations: PhysX's own default, 1.
pub const DEFAULT_VELOCITY_ITERATIONS: u32 = 1;

/// Largest accepted iteration count (PhysX's own limit is 255).
pub const MAX_ITERATIONS: i64 = 255;

/// PhysX's solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Solver {
    /// Projected Gauss-Seidel.
    Pgs,
    /// Temporal Gauss-Seidel (Isaac Sim's default).
    Tgs,
}

impl Solver {
    /// The setting's text for this choice.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Pgs => "pgs",
            Solver::Tgs => "tgs",
        }
    }
}

/// The settings accepted in `[engine.physx]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo {
        key: TIMESTEP_KEY,
        help: "integration timestep, s (> 0, at most 1); default 0.005",
    },
    SettingInfo {
        key: "solver",
        help: "pgs | tgs (temporal Gauss-Seidel); default pgs (TGS sags more at equal iterations)",
    },
    SettingInfo {
        key: "position_iterations",
        help: "position iterations of every actor's and the articulation's solver (1 to 255); default 32 (PhysX's 4 lets the arm sag 24 degrees)",
    },
    SettingInfo {
        key: "velocity_iterations",
        help: "velocity iterations (0 to 255); default 1 (PhysX's)",
    },
    SettingInfo {
        key: "contact_offset_m",
        help: "distance at which shapes start generating contacts, m (> 0, at most 0.1); default 0.002",
    },
    SettingInfo {
        key: "self_collision",
        help: "the robot's links collide with each other (an articulation's own rule: never a link with its parent): true | false; default true (PhysX's); false as in Bullet, ODE and DART",
    },
];

/// Checked engine settings, every field filled with its default when not
/// given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysxSettings {
    /// Integration timestep, s.
    pub timestep_s: f64,
    /// The solver.
    pub solver: Solver,
    /// Position iterations.
    pub position_iterations: u32,
    /// Velocity iterations.
    pub velocity_iterations: u32,
    /// Contact offset of every shape, m (rest offset 0).
    pub contact_offset_m: f64,
    /// Whether the robot's links collide with each other.
    pub self_collision: bool,
}

/// The default contact offset, m. PhysX's default (0.02 m for a length
/// scale of 1 m) is a third of the cube's edge and makes the arm's small
/// links touch before they do; 2 mm is the scale of its smallest parts.
pub const DEFAULT_CONTACT_OFFSET_M: f64 = 0.002;

impl Default for PhysxSettings {
    fn default() -> Self {
        PhysxSettings {
            timestep_s: DEFAULT_TIMESTEP_S,
            solver: Solver::Pgs,
            position_iterations: DEFAULT_POSITION_ITERATIONS,
            velocity_iterations: DEFAULT_VELOCITY_ITERATIONS,
            contact_offset_m: DEFAULT_CONTACT_OFFSET_M,
            self_collision: true,
        }
    }
}

impl PhysxSettings {
    /// Reads `settings` through the core's [`SettingsReader`], checking
    /// every key and value; unknown keys and bad values are errors naming
    /// the key and what is accepted.
    pub fn parse(settings: &EngineSettings) -> Result<PhysxSettings, EngineError> {
        let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
        let d = PhysxSettings::default();
        let count = |key: &str, min: i64, default: u32| -> Result<u32, EngineError> {
            Ok(r.integer(key, min, MAX_ITERATIONS)?
                .map_or(default, |v| v as u32))
        };
        Ok(PhysxSettings {
            timestep_s: r
                .number(TIMESTEP_KEY, |v| v > 0.0 && v <= 1.0, "> 0 and at most 1 s")?
                .unwrap_or(d.timestep_s),
            solver: r
                .choice("solver", &[("pgs", Solver::Pgs), ("tgs", Solver::Tgs)])?
                .unwrap_or(d.solver),
            position_iterations: count("position_iterations", 1, d.position_iterations)?,
            velocity_iterations: count("velocity_iterations", 0, d.velocity_iterations)?,
            contact_offset_m: r
                .number(
                    "contact_offset_m",
                    |v| v > 0.0 && v <= 0.1,
                    "> 0 and at most 0.1 m",
                )?
                .unwrap_or(d.contact_offset_m),
            self_collision: r.boolean("self_collision")?.unwrap_or(d.self_collision),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::SettingValue;

    fn set(pairs: &[(&str, &str)]) -> EngineSettings {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), SettingValue::parse(v)))
            .collect()
    }

    #[test]
    fn defaults_and_values() {
        assert_eq!(
            PhysxSettings::parse(&EngineSettings::new()).unwrap(),
            PhysxSettings::default()
        );
        let s = PhysxSettings::parse(&set(&[
            ("timestep_s", "0.001"),
            ("solver", "pgs"),
            ("position_iterations", "8"),
            ("velocity_iterations", "0"),
            ("contact_offset_m", "0.01"),
            ("self_collision", "false"),
        ]))
        .unwrap();
        assert_eq!(s.timestep_s, 0.001);
        assert_eq!(s.solver, Solver::Pgs);
        assert_eq!((s.position_iterations, s.velocity_iterations), (8, 0));
        assert_eq!(s.contact_offset_m, 0.01);
        assert!(!s.self_collision && PhysxSettings::default().self_collision);
    }

    #[test]
    fn bad_values_name_the_setting() {
        for (k, v, want) in [
            ("solver", "jacobi", "setting `solver`"),
            ("position_iterations", "0", "setting `position_iterations`"),
            (
                "position_iterations",
                "256",
                "setting `position_iterations`",
            ),
            ("timestep_s", "-1", "setting `timestep_s`"),
            ("contact_offset_m", "0", "setting `contact_offset_m`"),
            ("substeps", "2", "setting `substeps`: unknown setting"),
        ] {
            let e = PhysxSettings::parse(&set(&[(k, v)]))
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{k}={v}: {e}");
        }
    }
}
