//! The engine test kit (realitygap_core::testing::kit) on bullet.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::free::FreeBody;
use realitygap_core::testing::kit::{Divergence, Effects, End, Kinematics, KitSpec, Push};

/// Bullet against the contract ([`KitSpec::CONTRACT`]).
///
/// Rotor: Bullet: its velocity motor is a stiff constraint (no gain: kv is not used), so the velocity step leads the kv servo's response by I/kv x 1 rad/s = 0.1 rad; its POSITION_CONTROL motor (positionGain kp dt / kv) follows the first-order law v = (kp/kv)(q - angle) to 9e-4 rad; its multibody keeps PyBullet's default link drag I w (0.04 + 0.04 |w|), 0.025 rad short of the effort step's 1 rad. The explicit PD law (position_servo = "pd_control") is checked in tests/conformance.rs.
///
/// - `kinematics`: the link frames are the URDF's to 1e-12 m (Bullet
///   computes them as core does, in double precision) and the angles read
///   back exactly.
/// - `round_trip_m`: the native state is exact; the portable state carries
///   no contact manifolds (warm starts), and Bullet solves every
///   constraint of the world in one loop, so the arm's motors see the
///   cube's contact restart: 5.0e-4 m in scene 1 (1e-3, as before), 1e-3
///   in scene 3.
/// - `scene1_end`: the velocity motor is a stiff constraint with a force
///   bound: the joints end near their targets, not where a kv servo
///   balances gravity (measured: 2.14 deg at most, joint 3 0.84 deg; the
///   crate's own tests checked no end angle; tests/pybullet_reference.rs
///   checks the run against PyBullet's).
/// - `divergence`: Bullet's multibody solver is hard to blow up (0.05 s
///   steps, ERP 1, one solver iteration all complete scene 1): a
///   constraint force mixing so large that no constraint holds sinks the
///   cube through the table. A cube at 1e15 m/s is refused when the state
///   is set (Bullet's velocity clamp), an Unstable error.
/// - `refuses_massless_links`: like PyBullet, Bullet gives a link without
///   `<inertial>` a mass of its own (the official URDF's root has none).
/// - `held_joints_rigid`: the held fingers are joints held by their motors,
///   so damping there is honoured.
/// - `push`: Bullet's stiff motors hold the hand about 2 cm higher than
///   MuJoCo's servos do and it only grazes the cube, as in the study's
///   PyBullet recording (0.1 mm): the cube must move, and stay on the
///   table (the graze presses it 3.3 mm into the table through the contact
///   ERP: 4 mm); `tests/models.rs` checks that a sweeping hand pushes it. The
///   cube's mass then changes the graze by 0.16 mm (any change). The
///   untouched cube of scene 2 settles 0.4 mm into the table (contact
///   ERP).
/// - `free.slide_friction_factor`: Bullet multiplies the two bodies'
///   friction coefficients and its ground's is 0.5, so a cube given 0.2
///   slides as on 0.1 (measured 0.1001); every other engine's contact
///   takes the object's coefficient against a rougher ground.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [0.11, 2e-3, 0.03],
    position_law: PositionLaw::FirstOrder,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 0.0],
    kinematics: Kinematics {
        position_m: 1e-12,
        readback_rad: 0.0,
        ..KitSpec::CONTRACT.kinematics
    },
    round_trip_m: [[0.0, 1e-3], [0.0, 1e-3]],
    scene1_end: End::Targets(2.5),
    divergence: Divergence::Diverges(&["global_cfm=1e6"]),
    refuses_massless_links: false,
    held_joints_rigid: false,
    effects: Effects {
        cube_mass_push_m: 0.0,
        ..Effects::CONTRACT
    },
    free: FreeBody {
        slide_friction_factor: 0.5,
        ..FreeBody::CONTRACT
    },
    scene2_cube_m: 5e-4,
    push: Some(Push {
        min_x_m: 0.0,
        contact_s: None,
        ends_on_a_face: true,
        max_sink_m: 0.004,
    }),
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_bullet::BulletEngine, SPEC);
