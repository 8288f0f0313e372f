//! The engine test kit (realitygap_core::testing::kit) on rapier.

use realitygap_core::testing::kit::free::FreeBody;
use realitygap_core::testing::kit::{Divergence, Effects, Kinematics, KitSpec, Push};

/// Rapier against the contract ([`KitSpec::CONTRACT`]):
///
/// - `step_tolerance_rad`: the force-based motor is implicit; the errors
///   are a fraction of a step.
/// - `kinematics`: single precision: link frames a few micrometres from the
///   URDF's double-precision kinematics; continuous joints are read back
///   within a turn.
/// - `round_trip_m`: scene 1 at 2 s: the arm carries over bit for bit; the
///   cube resting on the table, asleep in the first run, is awake for one
///   step in the second and settles again without the contact's warm-start
///   impulses (4.5e-8 m). Scene 3 at 12 s, while the hand pushes the cube:
///   the contact manifolds and their warm-start impulses are not numbers of
///   the state, so the first period after the restore differs by 0.2 mm
///   (cube) and 1.3e-4 rad (joints); the cube then tips over a little
///   differently and ends 2.6 cm away (the push is that sensitive: see the
///   README).
/// - `handover_rad`: single precision: the joint angles arrive to f32
///   rounding.
/// - `effects.contact_sink_m`: softer contacts (omega = 1 / (tau zeta): 50
///   rad/s, then 25 rad/s against Rapier's own 377 rad/s on the table) sink
///   the cube by 3.6 mm and 7.4 mm more (Rapier's soft-constraint
///   discretisation, not the continuous g / omega^2 of 3.9 mm and 15.7 mm).
/// - `divergence`: no Rapier setting makes scene 1 diverge: the servo and
///   joint damping are implicit, the solver works on velocities and clamps
///   them, and the harshest accepted settings (the longest timestep the
///   control period allows, one iteration of everything, no stabilization)
///   still complete.
/// - `stock_settings`: Rapier's stock solver (4 iterations of 1
///   Gauss-Seidel sweep) leaves the six coupled motors far from converged.
/// - `free.rest_drift_m`: a cube dropped flat slides 2.2 mm sideways as
///   it lands (the others: 0 to 0.9 mm): Rapier's solver takes the four
///   corner contacts one after another, in single precision, so their
///   friction impulses do not cancel in the first steps of the impact.
/// - `push`: the hand first lands on the cube's near edge (from about 11.3
///   s, tilting it by some 9 degrees, in MuJoCo too) and pushes it in the
///   last phase, where Rapier tips it over onto its side.
const SPEC: KitSpec = KitSpec {
    step_tolerance_rad: [2e-4, 1e-3, 5e-4],
    kinematics: Kinematics {
        position_m: 1e-5,
        angle_rad: 1e-5,
        readback_rad: 1e-5,
        object_m: 1e-7,
        turn_rad: 3.0,
        after_step_rad: None,
    },
    round_trip_m: [[1e-6, 1e-6], [0.03, 0.03]],
    handover_rad: 1e-6,
    effects: Effects {
        contact_sink_m: 2e-3,
        ..Effects::CONTRACT
    },
    divergence: Divergence::Completes(&[
        "timestep_s=0.05",
        "solver_iterations=1",
        "internal_pgs_iterations=1",
        "stabilization_iterations=0",
    ]),
    bad_settings: &[
        ("internal_pgs_iterations=many", "whole number"),
        (
            "internal_pgs_iterations=0",
            "setting `internal_pgs_iterations`: must be a whole number from 1",
        ),
        (
            "mesh_shape=voxels",
            "\"voxels\" is not one of convex_hull, trimesh",
        ),
    ],
    stock_settings: &["solver_iterations=4", "internal_pgs_iterations=1"],
    push: Some(Push {
        min_x_m: 0.05,
        contact_s: Some((10.0, 20.0)),
        ends_on_a_face: true,
        max_sink_m: 0.002,
    }),
    free: FreeBody {
        rest_drift_m: 3e-3,
        ..FreeBody::CONTRACT
    },
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_rapier::RapierEngine, SPEC);
