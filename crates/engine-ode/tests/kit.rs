//! The engine test kit (realitygap_core::testing::kit) on ode.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::{Divergence, Effects, End, Kinematics, KitSpec, Push};

/// Tolerances: ODE with the kv servo (the replay scene's): the motor row is the implicit damper kv (v - v_next), a step's lag; the portable state rebuilds the bodies from the angle (a few nanoradians).
///
/// The study's scenes at ODE's defaults (the stiff motor, dt = 0.01 s):
///
/// - `kinematics`: ODE measures the joint angles from its bodies: one
///   step at rest, the servos holding, moves them less than 1e-3 rad (no
///   jump, no sign flip); the model is checked as built by default and
///   with the welds as fixed joints and the base as static geometry.
/// - `round_trip_m`, `handover_m`: ODE's native state restores the run
///   exactly (every body's numbers, the collision list's order, the random
///   generator). The portable state rebuilds the bodies from the joint
///   angles and rates: ODE's joints are soft, velocity-level constraints,
///   so a moving, loaded arm's bodies sit off their joints' ideal places by
///   a constraint error that grows with the timestep and shrinks with ERP
///   (tests/conformance.rs `portable_gap_is_odes_constraint_error`): 66 um
///   at the default dt, ERP 0.2 (1e-4 m). The joint angles arrive exactly.
/// - `scene1_end`: ODE's default motor is a stiff constraint: the joints
///   end within 1 degree of their targets (with `servo = "kv"` they end
///   where MuJoCo's do: the command's cross-engine test).
/// - `effects.frictionloss`: dry friction is a motor constraint with ODE's
///   constraint force mixing: under 50 N m the joint creeps 6.4e-6 rad in
///   0.3 s (1e-5).
/// - `effects.cube_mass_push_m`: the hand pushes the cube 4.0 mm, a 5 kg
///   cube 3.1 mm: 0.84 mm apart (5e-4; the contract's 5 mm is for engines
///   whose hand pushes the cube centimetres).
/// - `push`: the hand pushes the cube at least 2 mm along +x (4.0 mm with
///   the Mico2, 8.0 mm with the official model).
/// - `divergence`: the iterative solver with one iteration at dt = 0.05 s
///   blows up.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001", "servo=kv"],
    step_tolerance_rad: [2e-3, 2e-3, 2e-3],
    position_law: PositionLaw::Pd,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 1e-8],
    kinematics: Kinematics {
        after_step_rad: Some(1e-3),
        ..KitSpec::CONTRACT.kinematics
    },
    kinematics_settings: &[&["weld=fixed_joint"], &["weld=fixed_joint", "base=static"]],
    round_trip_m: [[0.0, 1e-4], [0.0, 1e-4]],
    handover_m: [1e-4, 1e-4],
    scene1_end: End::Targets(1.0),
    effects: Effects {
        frictionloss: [0.95, 1e-5],
        cube_mass_push_m: 5e-4,
        ..Effects::CONTRACT
    },
    push: Some(Push {
        min_x_m: 0.002,
        contact_s: Some((10.0, 20.0)),
        ends_on_a_face: true,
        max_sink_m: 0.002,
    }),
    divergence: Divergence::Diverges(&[
        "timestep_s=0.05",
        "stepper=quick_step",
        "quick_step_iterations=1",
    ]),
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_ode::OdeEngine, SPEC);
