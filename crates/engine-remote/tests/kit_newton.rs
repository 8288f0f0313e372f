//! The engine test kit (realitygap_core::testing::kit) on Newton 1.8.0
//! (Warp 1.19.0, CPU) out of process: the `newton` adapter of the Python
//! SDK (`python/realitygap_engine/adapters/newton.py`) in its pinned
//! environment (`python/engines/newton.txt`), through the engine protocol.
//! The same checks as every linked engine, unchanged; without the
//! environment (`realitygap engines --install newton`) every check fails
//! with that line.
//!
//! The suite runs the kit with `backend = "c"` (the same SolverMuJoCo
//! model stepped by MuJoCo's C library: about 2 100 steps/s on scene 2,
//! against MuJoCo Warp's 89-111 on this CPU; 40 of 40 in 162 s of test time, grouped,
//! where MuJoCo Warp, the adapter's default, took 17.6 minutes for 40 of
//! 40 at the tolerances below, measured on it).
//!
//! With `backend = "c"` only the kernels Newton itself uses are compiled
//! on first use, about 20 s on this 2-core machine: with an empty Warp
//! kernel cache the first group took 28 s instead of 7, the whole kit 113
//! s of wall time, and passed. MuJoCo Warp's own kernels, which the
//! adapter's default backend needs, take 2 to 4 minutes to compile, longer
//! than a protocol reply may take (`timeout_s`, 120 s): with that backend
//! the cache must be warm first (any load and step of the adapter fills
//! it).

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::{Divergence, Effects, Kinematics, KitSpec, Push};
use realitygap_engine_remote::registry;

/// Newton's SolverMuJoCo on MuJoCo Warp at the adapter's defaults (2 ms,
/// implicitfast, Newton's constraint solver). MuJoCo's model and soft
/// contacts, computed in single precision, so MuJoCo's own tolerances hold
/// where they are about the model, and float32's where they are about
/// rounding. Each deviation from [`KitSpec::CONTRACT`], measured:
///
/// - `kinematics`: Newton keeps joint coordinates and body transforms in
///   float32. Link frames within 1.74e-7 m and 4.45e-7 rad of the URDF's
///   double-precision kinematics (both robot models; the wrist at rest
///   5.7e-9 m); angles read back within half a float32 step at |q| < 8 rad
///   (2.33e-7 rad, the bound 2.38e-7); the cube placed at its centre
///   rounded to float32 (1.49e-9 m: 0.0375 m is not a float32).
/// - `round_trip_m`: the native state (every state array, MuJoCo's warm
///   start, the commands) restores the run bit for bit (0 measured, scene 1
///   and 3). The portable state resets the warm start, so MuJoCo Warp's
///   Newton solver starts from zero accelerations and stops, in float32,
///   elsewhere: scene 1 1.5e-7 m (within the contract's 1e-6), scene 3 at
///   12 s, the hand pushing the cube (a push that amplifies the contact's
///   first step, see the README), 4.2e-3 m.
/// - `effects.frictionloss`: MuJoCo's friction loss is a soft constraint
///   (default solref): under 50 N m joint 2 still creeps 0.0134 rad in 0.3
///   s (MuJoCo 4's 0.013).
/// - `effects.contact_sink_m`, `own_contact_is_tau_0_02`: SolverMuJoCo
///   turns Newton's default contact stiffness and damping (ke 2500, kd 100)
///   into MuJoCo's default solref (0.02 s, 1), so the kit's first softer
///   contact is the engine's own (rest height unchanged, 0 measured); a
///   damping ratio of 2 raises the resting cube by 0.259 mm (MuJoCo's rest
///   depth follows solimp's impedance too; MuJoCo 4: 0.26 mm).
/// - `divergence`: Newton's default integrator (implicitfast) makes the
///   servos' damping implicit, and at the longest timestep the control
///   period allows (0.05 s) scene 1 completes; with the explicit Euler
///   integrator the kv servos are far beyond their stable step and the run
///   diverges (joint coordinates past MuJoCo's bound 1e10, mjMAXVAL, which
///   the adapter checks after every step; the cube at 1e15 m/s is refused
///   when the state is set, naming the cube).
/// - `scene2_cube_m`: the untouched cube settles 0.108 mm into MuJoCo's
///   soft contact over the run (MuJoCo 4: 0.11 mm).
/// - `push.max_sink_m`: MuJoCo's soft contact lets the official hand press
///   the cube 2.18 mm into the table (MuJoCo 4: 2.6 mm); it pushes it 2.27
///   cm (the Mico2 4.17 cm), from 11.35 s.
const SPEC: KitSpec = KitSpec {
    settings: &["backend=c"],
    rotor_settings: &["timestep_s=0.001", "backend=c"],
    step_tolerance_rad: [2e-3, 4e-3, 2e-3],
    position_law: PositionLaw::Pd,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 0.0],
    kinematics: Kinematics {
        position_m: 1.8e-7,
        angle_rad: 4.5e-7,
        readback_rad: 2.4e-7,
        object_m: 1.5e-9,
        turn_rad: 5.0,
        after_step_rad: None,
    },
    round_trip_m: [[0.0, 1e-6], [0.0, 4.3e-3]],
    effects: Effects {
        frictionloss: [0.95, 0.014],
        contact_sink_m: 2.5e-4,
        own_contact_is_tau_0_02: true,
        ..Effects::CONTRACT
    },
    divergence: Divergence::Diverges(&["timestep_s=0.05", "integrator=euler"]),
    scene2_cube_m: 1.1e-4,
    push: Some(Push {
        min_x_m: 0.02,
        contact_s: Some((10.0, 20.0)),
        ends_on_a_face: true,
        max_sink_m: 2.2e-3,
    }),
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(grouped: registry::for_kit("newton"), SPEC);
