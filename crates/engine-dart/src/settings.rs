//! The engine settings of DART (`[engine.dart]` in a scene file, `--set
//! dart.KEY=VALUE` on the command line): what they are, their defaults,
//! and their checking (through core's one [`SettingsReader`]).
//!
//! Defaults are Gazebo's where Gazebo chooses (its dartsim plugin: the ODE
//! collision detector, 1 ms steps) and DART's own otherwise (the Dantzig
//! LCP solver with PGS as its fallback).

use realitygap_core::engine::{
    EngineError, EngineSettings, SettingInfo, SettingsReader, TIMESTEP_KEY,
};

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = "dart";

/// The timestep used when the settings give none, s (Gazebo's default
/// `max_step_size`; the study's scenes run stably at it, see the README).
pub const DEFAULT_TIMESTEP_S: f64 = 0.001;

/// The settings accepted in `[engine.dart]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo {
        key: TIMESTEP_KEY,
        help: "integration timestep, s (> 0 and finite); default 0.001 (Gazebo's)",
    },
    SettingInfo {
        key: "collision_detector",
        help: "ode (DART's OdeCollisionDetector, Gazebo's choice) | fcl (DART's own default; primitives as meshes) | bullet | dart (DART's own: boxes only, other shapes are refused); default ode",
    },
    SettingInfo {
        key: "lcp_solver",
        help: "dantzig (exact pivoting, PGS when it fails: DART's default) | pgs (projected Gauss-Seidel alone); default dantzig",
    },
    SettingInfo {
        key: "servo",
        help: "kv (the scene's servo torque kv (v_target - v), implicit through DART's joint damping, clamped to the force limit) | servo (DART's SERVO actuator: a velocity constraint bounded by the force limit, no gain); default kv",
    },
];

/// The collision detector of the world's constraint solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Detector {
    /// `OdeCollisionDetector` (libdart-collision-ode, the system's ODE).
    Ode,
    /// `FCLCollisionDetector` (DART's default).
    Fcl,
    /// `BulletCollisionDetector` (libdart-collision-bullet).
    Bullet,
    /// `DARTCollisionDetector`, DART's own.
    Dart,
}

impl Detector {
    /// The name the shim takes.
    pub fn name(self) -> &'static str {
        match self {
            Detector::Ode => "ode",
            Detector::Fcl => "fcl",
            Detector::Bullet => "bullet",
            Detector::Dart => "dart",
        }
    }
}

/// The boxed LCP solver of the constraint solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lcp {
    /// `DantzigBoxedLcpSolver`, with `PgsBoxedLcpSolver` when it fails.
    Dantzig,
    /// `PgsBoxedLcpSolver` alone.
    Pgs,
}

impl Lcp {
    /// The name the shim takes.
    pub fn name(self) -> &'static str {
        match self {
            Lcp::Dantzig => "dantzig",
            Lcp::Pgs => "pgs",
        }
    }
}

/// How velocity commands drive a joint (see the README's servo table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Servo {
    /// FORCE actuator: the torque `kv (v_target - v_next)` through DART's
    /// implicit joint damping, clamped to the force limit.
    Kv,
    /// DART's SERVO actuator: a velocity constraint whose force is bounded
    /// by the force limit (stiff, no gain).
    Servo,
}

/// Checked settings, defaults filled in.
#[derive(Debug, Clone, PartialEq)]
pub struct DartSettings {
    /// Timestep, s.
    pub timestep_s: f64,
    /// Collision detector.
    pub detector: Detector,
    /// LCP solver.
    pub lcp: Lcp,
    /// Velocity servo.
    pub servo: Servo,
}

impl Default for DartSettings {
    fn default() -> Self {
        DartSettings {
            timestep_s: DEFAULT_TIMESTEP_S,
            detector: Detector::Ode,
            lcp: Lcp::Dantzig,
            servo: Servo::Kv,
        }
    }
}

impl DartSettings {
    /// Checks `settings` and fills in the defaults; an error names the
    /// engine, the key, the value and what is accepted.
    pub fn parse(settings: &EngineSettings) -> Result<DartSettings, EngineError> {
        let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
        let d = DartSettings::default();
        Ok(DartSettings {
            timestep_s: r
                .number(
                    TIMESTEP_KEY,
                    |v| v.is_finite() && v > 0.0,
                    "greater than 0 s and finite",
                )?
                .unwrap_or(d.timestep_s),
            detector: r
                .choice(
                    "collision_detector",
                    &[
                        ("ode", Detector::Ode),
                        ("fcl", Detector::Fcl),
                        ("bullet", Detector::Bullet),
                        ("dart", Detector::Dart),
                    ],
                )?
                .unwrap_or(d.detector),
            lcp: r
                .choice(
                    "lcp_solver",
                    &[("dantzig", Lcp::Dantzig), ("pgs", Lcp::Pgs)],
                )?
                .unwrap_or(d.lcp),
            servo: r
                .choice("servo", &[("kv", Servo::Kv), ("servo", Servo::Servo)])?
                .unwrap_or(d.servo),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::SettingValue;

    fn parse(pairs: &[(&str, &str)]) -> Result<DartSettings, EngineError> {
        let settings: EngineSettings = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), SettingValue::parse(v)))
            .collect();
        DartSettings::parse(&settings)
    }

    #[test]
    fn defaults_are_gazebos() {
        let s = parse(&[]).unwrap();
        assert_eq!(s, DartSettings::default());
        assert_eq!(s.timestep_s, 0.001);
        assert_eq!(
            (s.detector, s.lcp, s.servo),
            (Detector::Ode, Lcp::Dantzig, Servo::Kv)
        );
    }

    #[test]
    fn every_documented_key_is_accepted() {
        let values = [
            ("timestep_s", "0.002"),
            ("collision_detector", "fcl"),
            ("lcp_solver", "pgs"),
            ("servo", "servo"),
        ];
        assert_eq!(values.len(), SETTINGS.len());
        let s = parse(&values).unwrap();
        assert_eq!(
            (s.timestep_s, s.detector, s.lcp, s.servo),
            (0.002, Detector::Fcl, Lcp::Pgs, Servo::Servo)
        );
        for d in ["ode", "fcl", "bullet", "dart", "ODE"] {
            assert!(parse(&[("collision_detector", d)]).is_ok(), "{d}");
        }
    }

    #[test]
    fn bad_values_name_the_key_and_what_is_accepted() {
        let cases: &[(&str, &str, &str)] = &[
            ("timestep_s", "0", "must be greater than 0 s"),
            ("timestep_s", "-1e-3", "must be greater than 0 s"),
            (
                "timestep_s",
                "inf",
                "greater than 0 s and finite, found inf",
            ),
            ("timestep_s", "fast", "expected a number"),
            (
                "collision_detector",
                "physx",
                "is not one of ode, fcl, bullet, dart",
            ),
            ("lcp_solver", "lemke", "is not one of dantzig, pgs"),
            ("servo", "motor", "is not one of kv, servo"),
            (
                "timestep",
                "0.001",
                "unknown setting (accepted: timestep_s, collision_detector",
            ),
        ];
        for (key, value, expected) in cases {
            let msg = parse(&[(key, value)]).unwrap_err().to_string();
            assert!(msg.starts_with("engine dart: setting `"), "{msg}");
            assert!(msg.contains(&format!("setting `{key}`")), "{msg}");
            assert!(msg.contains(expected), "{key}={value}: {msg}");
        }
    }
}
