//! The engine test kit (realitygap_core::testing::kit) on the physics-free
//! model.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::{End, KitSpec};

/// Tolerances: perfect tracking leads the kv servo's velocity response by
/// I/kv x 1 rad/s = 0.1 rad (as Bullet's stiff motor does); the position
/// step is at its target at once, exactly; efforts are refused. No
/// dynamics (no gravity, contact or forces: the kit checks that their
/// parameters are refused), no geometry read (a robot with broken meshes
/// loads), and the servo does not yield to gravity: scene 1 ends at its
/// targets exactly.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [0.1001, 1e-12, 0.0],
    position_law: PositionLaw::Instant,
    takes_efforts: false,
    dynamics: false,
    reads_geometry: false,
    push: None,
    scene1_end: End::Targets(1e-9),
    command_round_trip_rad: [0.0, 0.0],
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_ideal::IdealEngine, SPEC);
