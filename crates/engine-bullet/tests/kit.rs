//! The engine test kit (realitygap_core::testing::kit) on bullet.

use realitygap_core::conformance::PositionLaw;
use realitygap_core::testing::kit::KitSpec;

/// Tolerances: Bullet: its velocity motor is a stiff constraint (no gain: kv is not used), so the velocity step leads the kv servo's response by I/kv x 1 rad/s = 0.1 rad; its POSITION_CONTROL motor (positionGain kp dt / kv) follows the first-order law v = (kp/kv)(q - angle) to 9e-4 rad; its multibody keeps PyBullet's default link drag I w (0.04 + 0.04 |w|), 0.025 rad short of the effort step's 1 rad. The explicit PD law (position_servo = "pd_control") is checked in tests/conformance.rs.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [0.11, 2e-3, 0.03],
    position_law: PositionLaw::FirstOrder,
    takes_efforts: true,
    command_round_trip_rad: [0.0, 0.0],
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(realitygap_engine_bullet::BulletEngine, SPEC);
