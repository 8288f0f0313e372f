//! The engine test kit (realitygap_core::testing::kit) on MuJoCo 4.0.1
//! out of process: the `mujoco4` adapter of the Python SDK
//! (`python/realitygap_engine/adapters/mujoco.py`) in its pinned
//! environment, through the engine protocol. The same checks as every
//! linked engine, unchanged; `scripts/setup --tests` installs the
//! environment (`realitygap engines --install mujoco4`), and without it
//! every check fails with that line.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::{Divergence, Effects, KitSpec, Push};
use realitygap_engine_remote::registry;

/// The adapter builds the model the linked MuJoCo 3.17 builds (the model
/// description carries the same bodies, masses and servos), so MuJoCo's
/// own tolerances hold, with these differences, each measured:
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [2e-3, 4e-3, 2e-3],
    position_law: PositionLaw::Pd,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 0.0],
    round_trip_m: [[0.0, 1e-9], [0.0, 1e-9]],
    handover_rad: 0.0,
    effects: Effects {
        damping_ratio: 0.5,
        armature_ratio: 0.5,
        frictionloss: [0.95, 0.02],
        contact_sink_m: 1e-4,
        own_contact_is_tau_0_02: true,
        ..Effects::CONTRACT
    },
    divergence: Divergence::Diverges(&["timestep_s=0.05"]),
    divergence_names_body: false,
    scene2_upright_m: 5e-3,
    scene2_angle_rad: 0.05,
    scene2_cube_m: 2e-4,
    push: Some(Push {
        min_x_m: 0.02,
        contact_s: Some((10.0, 20.0)),
        ends_on_a_face: true,
        max_sink_m: 0.003,
    }),
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(grouped: registry::for_kit("mujoco4"), SPEC);
