//! The engine test kit (realitygap_core::testing::kit) on physx.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::KitSpec;

/// Tolerances: PhysX (f32, PGS): the drive is implicit; the position step lags by about 2e-3 rad.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [5e-4, 4e-3, 2e-3],
    position_law: PositionLaw::Pd,
    command_round_trip_rad: [0.0, 0.0],
};

realitygap_core::engine_test_kit!(realitygap_engine_physx::PhysxEngine, SPEC);
