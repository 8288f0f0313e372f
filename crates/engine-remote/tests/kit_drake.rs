//! The engine test kit (realitygap_core::testing::kit) on Drake 1.51.1 out
//! of process: the `drake` adapter of the Python SDK
//! (`python/realitygap_engine/adapters/drake.py`) in its pinned
//! environment (`python/engines/drake.txt`), through the engine protocol.
//! The same checks as every linked engine, unchanged; `scripts/setup
//! --tests` installs the environment (`realitygap engines --install
//! drake`), and without it every check fails with that line.

use realitygap_core::testing::kit::free::FreeBody;
use realitygap_core::testing::kit::{Divergence, KitSpec};
use realitygap_engine_remote::registry;

/// Drake against the contract ([`KitSpec::CONTRACT`]), at the adapter's
/// defaults (Drake's own: a discrete plant at 1 ms, the `lagged` contact
/// approximation with implicit PD servos, hydroelastic contact with point
/// fallback: the objects compliant, the robot and the ground rigid):
///
/// - `refuses_singular_inertia`: Drake refuses a spatial inertia that
///   cannot be physical (link 3 with a zero moment and the other two
///   unequal fails `SpatialInertia::IsPhysicallyValid()`): a load error
///   naming the link. (`refuses_massless_links` stays the contract's:
///   Drake's first step finds the massless hand's articulated inertia
///   singular, and the adapter makes that check at load.)
/// - `divergence`: at one step per control period (0.05 s) the `tamsi`
///   approximation, which has no PD controllers (the adapter runs the
///   servo laws explicitly, kv dt / I_eff up to some 700), makes Drake's
///   solver fail to converge at 0.15 s. (Measured at 0.05 s too: the
///   default `lagged` completes scene 1; `sap`, and `similar` with point
///   contact, hold the arm with their implicit servos but let the resting
///   cube sink through the table, which the run reports as diverged.)
/// - `bad_settings`: the adapter's own settings, each a refused value.
/// - `free.slide_friction_factor`: Drake combines two shapes' friction
///   coefficients as `2 mu1 mu2 / (mu1 + mu2)`: the cube's 0.2 on the
///   ground's Drake default 0.5 slides as 0.2857 (1.4286 times 0.2);
///   measured 0.2850.
///
/// Everything else holds at the contract's tolerances. (Parameters: Drake
/// maps `joints.*.armature` only; `objects.*.restitution`,
/// `contact.time_constant_s` and `contact.damping_ratio` have no Drake
/// mechanism, so the kit checks that realitygap refuses them.)
const SPEC: KitSpec = KitSpec {
    refuses_singular_inertia: true,
    divergence: Divergence::Diverges(&["timestep_s=0.05", "discrete_contact_approximation=tamsi"]),
    bad_settings: &[
        (
            "contact_model=soft",
            "\"soft\" is not one of point, hydroelastic_with_fallback",
        ),
        (
            "discrete_contact_approximation=fast",
            "\"fast\" is not one of tamsi, sap, similar, lagged",
        ),
        (
            "hydroelastic_modulus=0",
            "setting `hydroelastic_modulus`: must be > 0 Pa",
        ),
        ("self_collision=2", "expected true or false"),
    ],
    free: FreeBody {
        slide_friction_factor: 2.0 * 0.5 / (0.2 + 0.5),
        ..FreeBody::CONTRACT
    },
    ..KitSpec::CONTRACT
};

realitygap_core::engine_test_kit!(grouped: registry::for_kit("drake"), SPEC);
