//! The engine test kit (realitygap_core::testing::kit) on dart.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::KitSpec;

/// Tolerances: DART with its default servo = "kv" at 1 ms. The laws run
/// through DART's implicit joint damping and spring, integrated by
/// semi-implicit Euler: measured gaps 1.8e-4 rad (velocity), 1.9e-3 rad
/// (position: the step's lag on a 10 rad/s oscillation) and 1.0e-3 rad
/// (effort: the first-order integration of t^2/2). The state is DART's
/// generalized coordinates, so both round trips are exact (0 measured).
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [3e-4, 3e-3, 1.5e-3],
    position_law: PositionLaw::Pd,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 0.0],
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_dart::DartEngine, SPEC);
