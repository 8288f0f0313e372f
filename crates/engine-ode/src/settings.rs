//! The engine settings of ODE (`[engine.ode]` in a scene file, `--set
//! ode.KEY=VALUE` on the command line): what they are, their defaults, and
//! their checking.
//!
//! Defaults are ODE's own wherever ODE has one (ERP 0.2, CFM 1e-5, 20
//! QuickStep iterations, SOR 1.3, no contact correcting-velocity cap, no
//! surface layer); the timestep is the 0.01 s (the PyBullet rate
//! of the study), the stepper the exact `dWorldStep`.

use realitygap_core::engine::{
    EngineError, EngineSettings, SettingInfo, SettingsReader, TIMESTEP_KEY,
};

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = "ode";

/// The timestep used when the settings give none, s.
pub const DEFAULT_TIMESTEP_S: f64 = 0.01;

/// The settings accepted in `[engine.ode]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo { key: TIMESTEP_KEY, help: "integration timestep, s (> 0); default 0.01" },
    SettingInfo {
        key: "stepper",
        help: "world_step (dWorldStep: exact Dantzig LCP, O(n^3)) | quick_step (dWorldQuickStep: iterative SOR); default world_step",
    },
    SettingInfo { key: "quick_step_iterations", help: "SOR iterations of quick_step (>= 1); default 20 (ODE's)" },
    SettingInfo { key: "quick_step_sor", help: "SOR over-relaxation of quick_step (0 < w <= 2); default 1.3 (ODE's)" },
    SettingInfo { key: "erp", help: "error reduction parameter of joints and contacts (0..1); default 0.2 (ODE's)" },
    SettingInfo { key: "cfm", help: "constraint force mixing of joints and contacts (>= 0); default 1e-5 (ODE's, double precision)" },
    SettingInfo {
        key: "contact_mu",
        help: "Coulomb friction coefficient of surfaces the scene gives none for (>= 0); default 1.0; a contact uses the smaller of its two surfaces' values",
    },
    SettingInfo { key: "max_contacts", help: "most contact points per pair of touching shapes (1..=256); default 10" },
    SettingInfo {
        key: "contact_max_correcting_vel_m_s",
        help: "largest velocity with which contacts push shapes apart, m/s (> 0, `inf` = no cap); default inf (ODE's)",
    },
    SettingInfo { key: "contact_surface_layer_m", help: "penetration allowed before contacts push back, m (>= 0); default 0 (ODE's)" },
    SettingInfo {
        key: "contact_bounce_velocity_m_s",
        help: "approach speed below which a contact with restitution does not bounce (dContactBounce's bounce_vel), m/s (>= 0); default 0.01",
    },
    SettingInfo {
        key: "self_collision",
        help: "true: links of the arm collide with each other (except a link and its parent); default false (see the README)",
    },
    SettingInfo {
        key: "servo",
        help: "motor (ODE's velocity motor: exact target velocity while |torque| <= force limit; kv unused) | kv (the motor softened to torque = kv (v_target - v) through its CFM = 1/kv); default motor",
    },
    SettingInfo {
        key: "weld",
        help: "links joined by fixed or held (uncontrolled) joints: merge (one rigid ODE body, exact) | fixed_joint (one ODE body per link with mass, held by dJointSetFixed, as simulators that keep every URDF link do); default merge",
    },
    SettingInfo {
        key: "base",
        help: "fixed_joint (the base link is a body held to the world by a fixed joint) | static (the base link's shapes are static, joint 1 hinges on the world); default fixed_joint",
    },
];

/// Which constraint solver steps the world.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stepper {
    /// `dWorldStep`: builds the full constraint matrix and solves the LCP
    /// exactly (Dantzig).
    WorldStep,
    /// `dWorldQuickStep`: iterative successive over-relaxation.
    QuickStep,
}

/// How a scene's velocity servo becomes an ODE hinge motor (see the README).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Servo {
    /// ODE's own motor: a velocity constraint `v = v_target` whose force is
    /// bounded by the force limit; its softness is the world CFM.
    Motor,
    /// The same motor with its CFM set to `1 / kv`, which makes the motor
    /// torque `kv (v_target - v_next)` (an implicit damper), bounded by the
    /// force limit: the scene's servo as written.
    Kv,
}

/// How the robot's base is held at its pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Base {
    /// A body with the base's mass, attached to the world by a fixed joint
    /// (`dJointSetFixed`).
    FixedJoint,
    /// No body: the base link's shapes are static geometry and the first
    /// joint hinges on the world.
    Static,
}

/// How links joined by fixed or held joints are made rigid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weld {
    /// One ODE body for all of them (exact: nothing can flex).
    Merge,
    /// One ODE body per link with mass, joined by ODE fixed joints (soft
    /// constraints, like every other ODE joint).
    FixedJoint,
}

/// Checked settings, defaults filled in.
#[derive(Debug, Clone, PartialEq)]
pub struct OdeSettings {
    /// Timestep, s.
    pub timestep_s: f64,
    /// Solver.
    pub stepper: Stepper,
    /// QuickStep iterations.
    pub quick_step_iterations: u32,
    /// QuickStep SOR over-relaxation factor.
    pub quick_step_sor: f64,
    /// Global ERP.
    pub erp: f64,
    /// Global CFM.
    pub cfm: f64,
    /// Friction coefficient of surfaces without one in the scene.
    pub contact_mu: f64,
    /// Most contact points per touching pair.
    pub max_contacts: usize,
    /// Contact correcting-velocity cap, m/s (infinite: none).
    pub contact_max_correcting_vel_m_s: f64,
    /// Contact surface layer, m.
    pub contact_surface_layer_m: f64,
    /// Approach speed below which restitution is not applied, m/s
    /// (`bounce_vel` of `dContactBounce`).
    pub contact_bounce_velocity_m_s: f64,
    /// Whether links of the arm collide with each other.
    pub self_collision: bool,
    /// Servo mapping.
    pub servo: Servo,
    /// How fixed and held joints are made rigid.
    pub weld: Weld,
    /// How the base is held.
    pub base: Base,
}

impl Default for OdeSettings {
    fn default() -> Self {
        OdeSettings {
            timestep_s: DEFAULT_TIMESTEP_S,
            stepper: Stepper::WorldStep,
            quick_step_iterations: 20,
            quick_step_sor: 1.3,
            erp: 0.2,
            cfm: 1e-5,
            contact_mu: 1.0,
            max_contacts: 10,
            contact_max_correcting_vel_m_s: f64::INFINITY,
            contact_surface_layer_m: 0.0,
            contact_bounce_velocity_m_s: 0.01,
            self_collision: false,
            servo: Servo::Motor,
            weld: Weld::Merge,
            base: Base::FixedJoint,
        }
    }
}

impl OdeSettings {
    /// Checks `settings` through the workspace's one settings reader
    /// ([`SettingsReader`]) and fills in the defaults; an error names the
    /// engine, the key, the value and what is accepted.
    pub fn parse(settings: &EngineSettings) -> Result<OdeSettings, EngineError> {
        let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
        let d = OdeSettings::default();
        let finite = |v: f64| v.is_finite();
        Ok(OdeSettings {
            timestep_s: r
                .number(
                    TIMESTEP_KEY,
                    |v| finite(v) && v > 0.0,
                    "greater than 0 s and finite",
                )?
                .unwrap_or(d.timestep_s),
            stepper: r
                .choice(
                    "stepper",
                    &[
                        ("world_step", Stepper::WorldStep),
                        ("quick_step", Stepper::QuickStep),
                    ],
                )?
                .unwrap_or(d.stepper),
            quick_step_iterations: r
                .integer("quick_step_iterations", 1, 1_000_000)?
                .map_or(d.quick_step_iterations, |v| v as u32),
            quick_step_sor: r
                .number("quick_step_sor", |v| v > 0.0 && v <= 2.0, "in (0, 2]")?
                .unwrap_or(d.quick_step_sor),
            erp: r
                .number("erp", |v| (0.0..=1.0).contains(&v), "in [0, 1]")?
                .unwrap_or(d.erp),
            cfm: r
                .number("cfm", |v| finite(v) && v >= 0.0, ">= 0 and finite")?
                .unwrap_or(d.cfm),
            contact_mu: r
                .number("contact_mu", |v| v >= 0.0, ">= 0 (or inf)")?
                .unwrap_or(d.contact_mu),
            max_contacts: r
                .integer("max_contacts", 1, 256)?
                .map_or(d.max_contacts, |v| v as usize),
            contact_max_correcting_vel_m_s: r
                .number(
                    "contact_max_correcting_vel_m_s",
                    |v| v > 0.0,
                    "greater than 0 (or inf)",
                )?
                .unwrap_or(d.contact_max_correcting_vel_m_s),
            contact_surface_layer_m: r
                .number(
                    "contact_surface_layer_m",
                    |v| finite(v) && v >= 0.0,
                    ">= 0 m and finite",
                )?
                .unwrap_or(d.contact_surface_layer_m),
            contact_bounce_velocity_m_s: r
                .number(
                    "contact_bounce_velocity_m_s",
                    |v| finite(v) && v >= 0.0,
                    ">= 0 m/s and finite",
                )?
                .unwrap_or(d.contact_bounce_velocity_m_s),
            self_collision: r.boolean("self_collision")?.unwrap_or(d.self_collision),
            servo: r
                .choice("servo", &[("motor", Servo::Motor), ("kv", Servo::Kv)])?
                .unwrap_or(d.servo),
            weld: r
                .choice(
                    "weld",
                    &[("merge", Weld::Merge), ("fixed_joint", Weld::FixedJoint)],
                )?
                .unwrap_or(d.weld),
            base: r
                .choice(
                    "base",
                    &[("fixed_joint", Base::FixedJoint), ("static", Base::Static)],
                )?
                .unwrap_or(d.base),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::SettingValue;

    fn parse(pairs: &[(&str, &str)]) -> Result<OdeSettings, EngineError> {
        let settings: EngineSettings = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), SettingValue::parse(v)))
            .collect();
        OdeSettings::parse(&settings)
    }

    #[test]
    fn defaults_are_odes_own() {
        let o = parse(&[]).unwrap();
        assert_eq!(o, OdeSettings::default());
        assert_eq!(o.timestep_s, 0.01);
        assert_eq!(o.stepper, Stepper::WorldStep);
        assert_eq!((o.erp, o.cfm, o.quick_step_iterations), (0.2, 1e-5, 20));
    }

    #[test]
    fn every_documented_key_is_accepted() {
        let values = [
            ("timestep_s", "0.005"),
            ("stepper", "quick_step"),
            ("quick_step_iterations", "50"),
            ("quick_step_sor", "1.0"),
            ("erp", "0.5"),
            ("cfm", "0"),
            ("contact_mu", "inf"),
            ("max_contacts", "4"),
            ("contact_max_correcting_vel_m_s", "0.1"),
            ("contact_surface_layer_m", "0.001"),
            ("contact_bounce_velocity_m_s", "0.1"),
            ("self_collision", "true"),
            ("servo", "kv"),
            ("weld", "fixed_joint"),
            ("base", "static"),
        ];
        assert_eq!(values.len(), SETTINGS.len());
        for info in SETTINGS {
            assert!(
                values.iter().any(|(k, _)| *k == info.key),
                "{} untested",
                info.key
            );
        }
        let o = parse(&values).unwrap();
        assert_eq!(o.stepper, Stepper::QuickStep);
        assert_eq!(o.contact_mu, f64::INFINITY);
        assert_eq!(
            (o.servo, o.base, o.self_collision, o.max_contacts),
            (Servo::Kv, Base::Static, true, 4)
        );
        assert_eq!(o.weld, Weld::FixedJoint);
    }

    #[test]
    fn bad_values_name_the_key_and_what_is_accepted() {
        let cases: &[(&str, &str, &str)] = &[
            ("timestep_s", "0", "must be greater than 0 s"),
            ("timestep_s", "fast", "expected a number"),
            (
                "timestep_s",
                "inf",
                "greater than 0 s and finite, found inf",
            ),
            ("stepper", "euler", "is not one of world_step, quick_step"),
            ("quick_step_iterations", "2.5", "expected a whole number"),
            ("quick_step_iterations", "0", "from 1 to"),
            ("quick_step_sor", "3", "in (0, 2]"),
            ("erp", "1.5", "in [0, 1]"),
            ("cfm", "-1", ">= 0"),
            ("contact_mu", "-0.1", ">= 0"),
            ("max_contacts", "0", "from 1 to 256"),
            ("contact_max_correcting_vel_m_s", "0", "greater than 0"),
            ("contact_bounce_velocity_m_s", "-1", ">= 0 m/s"),
            ("self_collision", "1", "expected true or false"),
            ("servo", "pd", "is not one of motor, kv"),
            ("base", "floating", "is not one of fixed_joint, static"),
            ("weld", "glue", "is not one of merge, fixed_joint"),
            (
                "timestep",
                "0.01",
                "unknown setting (accepted: timestep_s, stepper",
            ),
        ];
        for (key, value, expected) in cases {
            let msg = parse(&[(key, value)]).unwrap_err().to_string();
            assert!(msg.contains(&format!("setting `{key}`")), "{msg}");
            assert!(msg.contains(expected), "{key}={value}: {msg}");
        }
    }
}
