//! The engine settings of MuJoCo (`[engine.mujoco]` and `--set`), typed
//! and checked through core's [`SettingsReader`].

use crate::ENGINE_NAME;
use mujoco_rs::mujoco_c;
use realitygap_core::engine::{
    EngineError, EngineSettings, SettingInfo, SettingsReader, TIMESTEP_KEY,
};

/// MuJoCo's own default timestep, s (used when the settings give none and
/// the model is built from URDF).
pub const MUJOCO_DEFAULT_TIMESTEP_S: f64 = 0.002;

/// The settings accepted in `[engine.mujoco]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[
    SettingInfo {
        key: TIMESTEP_KEY,
        help: "integration timestep, s (> 0); default 0.002, or the MJCF file's own",
    },
    SettingInfo {
        key: "integrator",
        help: "euler | rk4 | implicit | implicitfast; default euler",
    },
    SettingInfo {
        key: "solver",
        help: "constraint solver: pgs | cg | newton; default newton",
    },
    SettingInfo {
        key: "iterations",
        help: "maximum solver iterations (>= 1); default 100",
    },
    SettingInfo {
        key: "tolerance",
        help: "solver tolerance (>= 0); default 1e-8",
    },
    SettingInfo {
        key: "cone",
        help: "friction cone: pyramidal | elliptic; default pyramidal",
    },
    SettingInfo {
        key: "impratio",
        help: "frictional-to-normal impedance ratio (> 0); default 1",
    },
    SettingInfo {
        key: "noslip_iterations",
        help: "no-slip solver iterations (>= 0); default 0",
    },
    SettingInfo {
        key: "self_collision",
        help: "the robot's links collide with each other (never a link with its parent): true | false; default true (MuJoCo's own); false as in Bullet, ODE and DART",
    },
];

/// The MuJoCo settings of one run, checked; `None` keeps the model's own
/// value (MuJoCo's default, or the MJCF file's).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MujocoSettings {
    /// Integration timestep, s (> 0).
    pub timestep_s: Option<f64>,
    /// `mjtIntegrator` value.
    pub integrator: Option<i32>,
    /// `mjtSolver` value.
    pub solver: Option<i32>,
    /// Maximum solver iterations (>= 1).
    pub iterations: Option<i32>,
    /// Solver tolerance (>= 0).
    pub tolerance: Option<f64>,
    /// `mjtCone` value.
    pub cone: Option<i32>,
    /// Frictional-to-normal impedance ratio (> 0).
    pub impratio: Option<f64>,
    /// No-slip solver iterations (>= 0).
    pub noslip_iterations: Option<i32>,
    /// Whether the robot's links collide with each other (`None`: they
    /// do, MuJoCo's own rule).
    pub self_collision: Option<bool>,
}

impl MujocoSettings {
    /// Reads and checks `settings`; an unknown key, a wrong type or a value
    /// out of range is an [`EngineError::Setting`] naming the key.
    pub fn parse(settings: &EngineSettings) -> Result<MujocoSettings, EngineError> {
        let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        let whole = |key: &str, min: i64| -> Result<Option<i32>, EngineError> {
            Ok(r.integer(key, min, i32::MAX as i64)?.map(|v| v as i32))
        };
        Ok(MujocoSettings {
            timestep_s: r.number(TIMESTEP_KEY, positive, "> 0 s and finite")?,
            integrator: r.choice(
                "integrator",
                &[
                    ("euler", mujoco_c::mjtIntegrator::mjINT_EULER as i32),
                    ("rk4", mujoco_c::mjtIntegrator::mjINT_RK4 as i32),
                    ("implicit", mujoco_c::mjtIntegrator::mjINT_IMPLICIT as i32),
                    (
                        "implicitfast",
                        mujoco_c::mjtIntegrator::mjINT_IMPLICITFAST as i32,
                    ),
                ],
            )?,
            solver: r.choice(
                "solver",
                &[
                    ("pgs", mujoco_c::mjtSolver::mjSOL_PGS as i32),
                    ("cg", mujoco_c::mjtSolver::mjSOL_CG as i32),
                    ("newton", mujoco_c::mjtSolver::mjSOL_NEWTON as i32),
                ],
            )?,
            iterations: whole("iterations", 1)?,
            tolerance: r.number("tolerance", non_negative, ">= 0 and finite")?,
            cone: r.choice(
                "cone",
                &[
                    ("pyramidal", mujoco_c::mjtCone::mjCONE_PYRAMIDAL as i32),
                    ("elliptic", mujoco_c::mjtCone::mjCONE_ELLIPTIC as i32),
                ],
            )?,
            impratio: r.number("impratio", positive, "> 0 and finite")?,
            noslip_iterations: whole("noslip_iterations", 0)?,
            self_collision: r.boolean("self_collision")?,
        })
    }

    /// Writes the settings that are set into MuJoCo's options.
    pub fn apply(&self, opt: &mut mujoco_rs::prelude::MjOption) {
        if let Some(v) = self.timestep_s {
            opt.timestep = v;
        }
        if let Some(v) = self.integrator {
            opt.integrator = v;
        }
        if let Some(v) = self.solver {
            opt.solver = v;
        }
        if let Some(v) = self.iterations {
            opt.iterations = v;
        }
        if let Some(v) = self.tolerance {
            opt.tolerance = v;
        }
        if let Some(v) = self.cone {
            opt.cone = v;
        }
        if let Some(v) = self.impratio {
            opt.impratio = v;
        }
        if let Some(v) = self.noslip_iterations {
            opt.noslip_iterations = v;
        }
    }
}
