//! The engine test kit (realitygap_core::testing::kit) on ode.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::KitSpec;

/// Tolerances: ODE with the kv servo (the replay scene's): the motor row is the implicit damper kv (v - v_next), a step's lag; the portable state rebuilds the bodies from the angle (a few nanoradians).
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001", "servo=kv"],
    step_tolerance_rad: [2e-3, 2e-3, 2e-3],
    position_law: PositionLaw::Pd,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 1e-8],
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_ode::OdeEngine, SPEC);
