//! The engine test kit (realitygap_core::testing::kit) on rapier.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::KitSpec;

/// Tolerances: Rapier (f32): the force-based motor is implicit; errors are a fraction of a step.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [2e-4, 1e-3, 5e-4],
    position_law: PositionLaw::Pd,
    command_round_trip_rad: [0.0, 0.0],
};

realitygap_core::engine_test_kit!(realitygap_engine_rapier::RapierEngine, SPEC);
