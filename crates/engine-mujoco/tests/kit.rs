//! The engine test kit (realitygap_core::testing::kit) on mujoco.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::KitSpec;

/// Tolerances: MuJoCo (Euler, dt = 1 ms): the first-order integrator lags the analytic response by about a step (1e-3 rad at 1 rad/s).
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [2e-3, 4e-3, 2e-3],
    position_law: PositionLaw::Pd,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 0.0],
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_mujoco::MujocoEngine, SPEC);
