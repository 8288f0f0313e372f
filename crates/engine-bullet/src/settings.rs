//! The engine's settings (`[engine.bullet]`, `--set bullet.KEY=VALUE`),
//! typed, read through core's one parse path ([`SettingsReader`]).

use crate::{DEFAULT_TIMESTEP_S, ENGINE_NAME};
use realitygap_core::engine::{
    EngineError, EngineSettings, SettingInfo, SettingsReader, TIMESTEP_KEY,
};

/// The settings accepted in `[engine.bullet]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo { key: TIMESTEP_KEY, help: "fixed timestep, s (> 0); default 0.01 (the study's PyBullet)" },
    SettingInfo {
        key: "solver_iterations",
        help: "numSolverIterations: constraint solver iterations per step (>= 1); default 50",
    },
    SettingInfo {
        key: "solver_residual_threshold",
        help: "solverResidualThreshold: the solver stops when the residual falls below it (>= 0); default 1e-7",
    },
    SettingInfo { key: "contact_erp", help: "defaultContactERP: contact error reduction per step, 0..1; default 0.08" },
    SettingInfo {
        key: "non_contact_erp",
        help: "defaultNonContactERP: error reduction of joint limits and motors, 0..1; default 0.2",
    },
    SettingInfo { key: "friction_erp", help: "frictionERP: error reduction of friction anchors, 0..1; default 0.2" },
    SettingInfo { key: "global_cfm", help: "defaultGlobalCFM: constraint force mixing (>= 0); default 0" },
    SettingInfo { key: "split_impulse", help: "useSplitImpulse: true | false; default true" },
    SettingInfo {
        key: "split_impulse_penetration_threshold_m",
        help: "splitImpulsePenetrationThreshold: penetration beyond which split impulse is used, m; default -0.04",
    },
    SettingInfo {
        key: "contact_breaking_threshold_m",
        help: "contactBreakingThreshold: contact points farther apart are dropped, m (> 0); default 0.01",
    },
    SettingInfo { key: "cone_friction", help: "enableConeFriction: true | false; default true" },
    SettingInfo {
        key: "max_force_n_m",
        help: "maximum motor force of every controlled joint, N m (> 0); default: the scene's force limits (the study's PyBullet used 10); a joint's force_limit parameter wins over it",
    },
    SettingInfo {
        key: "velocity_gain",
        help: "velocityGain of the velocity motors: share of the velocity error removed per step, (0, 1]; default 1",
    },
    SettingInfo {
        key: "inertia_from_file",
        help: "use the URDF's inertia tensors (true), or let Bullet compute them from the collision shapes (false, PyBullet's default without URDF_USE_INERTIA_FROM_FILE); default true",
    },
    SettingInfo {
        key: "self_collision",
        help: "collisions between the robot's links, neighbouring links excepted: true | false; default false",
    },
    SettingInfo {
        key: "implicit_cylinders",
        help: "URDF cylinders as exact cylinders (true) or as convex hulls (false, Bullet's default); default false",
    },
    SettingInfo {
        key: "position_servo",
        help: "how position commands drive a joint: position_control (PyBullet's POSITION_CONTROL motor, a constraint with positionGain = kp dt / kv: the first-order response v = (kp/kv)(q - angle), stable at any gain) or pd_control (PyBullet's PD_CONTROL: the explicit law kp (q - angle) - kv qd, exact, unstable past kv dt / I = 2); default position_control",
    },
];

/// How position commands drive a joint in Bullet (the `position_servo`
/// setting).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PositionServo {
    /// `POSITION_CONTROL`: the joint motor's constraint towards the target.
    PositionControl,
    /// `PD_CONTROL`: the explicit PD law of the pdControl plugin.
    PdControl,
}

/// The engine's settings, checked. `None` keeps Bullet's own default
/// (read back from the server by a test; the values are in [`SETTINGS`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BulletSettings {
    /// Fixed timestep, s (> 0).
    pub timestep_s: f64,
    /// `numSolverIterations` (>= 1).
    pub solver_iterations: Option<i32>,
    /// `solverResidualThreshold` (>= 0).
    pub solver_residual_threshold: Option<f64>,
    /// `defaultContactERP`, 0..1.
    pub contact_erp: Option<f64>,
    /// `defaultNonContactERP`, 0..1.
    pub non_contact_erp: Option<f64>,
    /// `frictionERP`, 0..1.
    pub friction_erp: Option<f64>,
    /// `defaultGlobalCFM` (>= 0).
    pub global_cfm: Option<f64>,
    /// `useSplitImpulse`.
    pub split_impulse: Option<bool>,
    /// `splitImpulsePenetrationThreshold`, m.
    pub split_impulse_penetration_threshold_m: Option<f64>,
    /// `contactBreakingThreshold`, m (> 0).
    pub contact_breaking_threshold_m: Option<f64>,
    /// `enableConeFriction`.
    pub cone_friction: Option<bool>,
    /// Motor force of every controlled joint, N m (> 0); `None`: the
    /// scene's force limits.
    pub max_force_n_m: Option<f64>,
    /// Motor `velocityGain`, (0, 1].
    pub velocity_gain: f64,
    /// `URDF_USE_INERTIA_FROM_FILE`.
    pub inertia_from_file: bool,
    /// How position commands drive a joint.
    pub position_servo: PositionServo,
    /// `URDF_USE_SELF_COLLISION` (+ `_EXCLUDE_PARENT`).
    pub self_collision: bool,
    /// `URDF_USE_IMPLICIT_CYLINDER`.
    pub implicit_cylinders: bool,
}

impl Default for BulletSettings {
    fn default() -> Self {
        BulletSettings {
            timestep_s: DEFAULT_TIMESTEP_S,
            solver_iterations: None,
            solver_residual_threshold: None,
            contact_erp: None,
            non_contact_erp: None,
            friction_erp: None,
            global_cfm: None,
            split_impulse: None,
            split_impulse_penetration_threshold_m: None,
            contact_breaking_threshold_m: None,
            cone_friction: None,
            max_force_n_m: None,
            velocity_gain: 1.0,
            inertia_from_file: true,
            self_collision: false,
            implicit_cylinders: false,
            position_servo: PositionServo::PositionControl,
        }
    }
}

impl BulletSettings {
    /// Reads and checks `settings`; an unknown key or a bad value is an
    /// [`EngineError::Setting`] naming the key and what is accepted.
    pub fn parse(settings: &EngineSettings) -> Result<BulletSettings, EngineError> {
        let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
        let d = BulletSettings::default();
        let positive = |x: f64| x.is_finite() && x > 0.0;
        let non_negative = |x: f64| x.is_finite() && x >= 0.0;
        let unit = |x: f64| (0.0..=1.0).contains(&x);
        Ok(BulletSettings {
            timestep_s: r
                .number(TIMESTEP_KEY, positive, "a number > 0 (s)")?
                .unwrap_or(d.timestep_s),
            solver_iterations: r
                .integer("solver_iterations", 1, i32::MAX as i64)?
                .map(|v| v as i32),
            solver_residual_threshold: r.number(
                "solver_residual_threshold",
                non_negative,
                "a number >= 0",
            )?,
            contact_erp: r.number("contact_erp", unit, "a number >= 0 and <= 1")?,
            non_contact_erp: r.number("non_contact_erp", unit, "a number >= 0 and <= 1")?,
            friction_erp: r.number("friction_erp", unit, "a number >= 0 and <= 1")?,
            global_cfm: r.number("global_cfm", non_negative, "a number >= 0")?,
            split_impulse: r.boolean("split_impulse")?,
            split_impulse_penetration_threshold_m: r.number(
                "split_impulse_penetration_threshold_m",
                f64::is_finite,
                "a finite number (m)",
            )?,
            contact_breaking_threshold_m: r.number(
                "contact_breaking_threshold_m",
                positive,
                "a number > 0 (m)",
            )?,
            cone_friction: r.boolean("cone_friction")?,
            max_force_n_m: r.number("max_force_n_m", positive, "a number > 0 (N m)")?,
            velocity_gain: r
                .number(
                    "velocity_gain",
                    |x| x > 0.0 && x <= 1.0,
                    "a number > 0 and <= 1",
                )?
                .unwrap_or(d.velocity_gain),
            inertia_from_file: r
                .boolean("inertia_from_file")?
                .unwrap_or(d.inertia_from_file),
            self_collision: r.boolean("self_collision")?.unwrap_or(d.self_collision),
            implicit_cylinders: r
                .boolean("implicit_cylinders")?
                .unwrap_or(d.implicit_cylinders),
            position_servo: r
                .choice(
                    "position_servo",
                    &[
                        ("position_control", PositionServo::PositionControl),
                        ("pd_control", PositionServo::PdControl),
                    ],
                )?
                .unwrap_or(d.position_servo),
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
    fn parses_settings() {
        let o = BulletSettings::parse(&settings(&[
            ("timestep_s", SettingValue::Float(0.005)),
            ("solver_iterations", SettingValue::Integer(100)),
            ("max_force_n_m", SettingValue::Integer(10)),
            ("velocity_gain", SettingValue::Float(0.5)),
            ("split_impulse", SettingValue::Bool(false)),
            (
                "split_impulse_penetration_threshold_m",
                SettingValue::Float(-0.02),
            ),
        ]))
        .unwrap();
        assert_eq!(o.timestep_s, 0.005);
        assert_eq!(o.solver_iterations, Some(100));
        assert_eq!(o.max_force_n_m, Some(10.0));
        assert_eq!(o.velocity_gain, 0.5);
        assert_eq!(o.split_impulse, Some(false));
        assert_eq!(o.split_impulse_penetration_threshold_m, Some(-0.02));
        assert!(o.inertia_from_file);
        assert_eq!(
            BulletSettings::parse(&EngineSettings::new()).unwrap(),
            BulletSettings::default()
        );
    }

    #[test]
    fn rejects_bad_settings() {
        let cases: &[(&str, SettingValue, &str)] = &[
            (
                "timestep_s",
                SettingValue::Float(0.0),
                "must be a number > 0",
            ),
            (
                "timestep_s",
                SettingValue::Text("fast".into()),
                "expected a number",
            ),
            (
                "solver_iterations",
                SettingValue::Integer(0),
                "whole number from 1",
            ),
            (
                "solver_iterations",
                SettingValue::Float(2.5),
                "expected a whole number",
            ),
            ("contact_erp", SettingValue::Float(1.5), "<= 1"),
            ("velocity_gain", SettingValue::Float(0.0), "> 0"),
            ("max_force_n_m", SettingValue::Float(-1.0), "> 0"),
            (
                "split_impulse",
                SettingValue::Integer(1),
                "expected true or false",
            ),
            (
                "split_impulse_penetration_threshold_m",
                SettingValue::Float(f64::NAN),
                "finite",
            ),
            (
                "integrator",
                SettingValue::Text("rk4".into()),
                "unknown setting (accepted: timestep_s",
            ),
        ];
        for (key, value, expected) in cases {
            let e = BulletSettings::parse(&settings(&[(key, value.clone())])).unwrap_err();
            let text = e.to_string();
            assert!(
                text.starts_with(&format!("engine bullet: setting `{key}`:")),
                "{text}"
            );
            assert!(text.contains(expected), "{key}={value}: {text}");
        }
    }

    #[test]
    fn every_setting_is_documented_and_accepted() {
        for s in SETTINGS {
            let value = match s.key {
                "split_impulse" | "cone_friction" | "inertia_from_file" | "self_collision"
                | "implicit_cylinders" => SettingValue::Bool(true),
                "solver_iterations" => SettingValue::Integer(10),
                "position_servo" => SettingValue::Text("pd_control".into()),
                _ => SettingValue::Float(0.5),
            };
            BulletSettings::parse(&settings(&[(s.key, value)]))
                .unwrap_or_else(|e| panic!("{}: {e}", s.key));
            assert!(!s.help.is_empty());
        }
    }
}
