//! The engine test kit (realitygap_core::testing::kit) on bullet.

use realitygap_core::testing::kit::KitSpec;

/// Tolerances: Bullet: its velocity motor is a stiff constraint (no gain: kv is not used), so the velocity step leads the kv servo's response by I/kv x 1 rad/s = 0.1 rad; its multibody keeps PyBullet's default link drag I w (0.04 + 0.04 |w|), 0.025 rad short of the effort step's 1 rad.
const SPEC: KitSpec = KitSpec {
    rotor_settings: &["timestep_s=0.001"],
    step_tolerance_rad: [0.11, 6e-3, 0.03],
    command_round_trip_rad: [0.0, 0.0],
};

realitygap_core::engine_test_kit!(realitygap_engine_bullet::BulletEngine, SPEC);
