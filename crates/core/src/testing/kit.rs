//! The engine test kit: one suite of checks that every engine crate runs on
//! its own engine with one macro call, [`engine_test_kit!`](crate::engine_test_kit),
//! in a test file of its own (`tests/kit.rs`):
//!
//! ```ignore
//! realitygap_core::engine_test_kit!(realitygap_engine_ode::OdeEngine, SPEC);
//! ```
//!
//! Each check is a function here taking the engine and its [`KitSpec`]
//! (the engine's settings for the check and its tolerances, each with the
//! reason in the engine's README); the macro makes one `#[test]` of each.
//! The checks measure with [`crate::conformance`] and print what they
//! measured as `CONFORMANCE engine=<name> check=<check> value=<v>
//! tolerance=<t>`, so that a README's table can be regenerated from a test
//! run. Like the rest of [`crate::testing`], they panic on failure.

use crate::conformance::{self, PositionLaw, Subject};
use crate::engine::{Engine, EngineError, EngineSettings, SettingValue};
use crate::trajectory::CommandKind;

/// One engine's settings and tolerances for the kit's checks.
#[derive(Debug, Clone)]
pub struct KitSpec {
    /// Settings of the rotor's step responses and command round trips
    /// (`key=value` pairs; typically a 1 ms timestep).
    pub rotor_settings: &'static [&'static str],
    /// The largest gap from the analytic response over the second of each
    /// step command, rad: velocity, position, effort (the responses reach
    /// 0.9, 0.5 and 1 rad).
    pub step_tolerance_rad: [f64; 3],
    /// The largest gap between a run and its continuation from its own
    /// state, rad: native state (the engine's own), portable state.
    pub command_round_trip_rad: [f64; 2],
    /// The law the engine's position servo follows at its default
    /// settings.
    pub position_law: PositionLaw,
}

/// Settings from `key=value` pairs (values as on the command line).
pub fn settings(pairs: &[&str]) -> EngineSettings {
    pairs
        .iter()
        .map(|p| {
            let (k, v) = p
                .split_once('=')
                .unwrap_or_else(|| panic!("setting \"{p}\" is not key=value"));
            (k.to_string(), SettingValue::parse(v))
        })
        .collect()
}

/// Prints one measurement in the kit's format.
pub fn report(engine: &dyn Engine, check: &str, value: f64, tolerance: f64) {
    eprintln!(
        "CONFORMANCE engine={} check={check} value={value:e} tolerance={tolerance:e}",
        engine.name()
    );
}

/// Every kind of command on the rotor against its analytic response
/// ([`conformance::step_response`]), within the spec's tolerance.
pub fn step_response(engine: &dyn Engine, spec: &KitSpec, kind: CommandKind) {
    let settings = settings(spec.rotor_settings);
    let r = conformance::step_response_with(
        Subject {
            engine,
            settings: &settings,
        },
        kind,
        spec.position_law,
    );
    let k = CommandKind::ALL
        .iter()
        .position(|&c| c == kind)
        .unwrap_or(0);
    let tolerance = spec.step_tolerance_rad[[1, 0, 2][k]];
    report(
        engine,
        &format!("step_response_{}", kind.name()),
        r.max_error_rad,
        tolerance,
    );
    eprintln!(
        "{}: {} step: final gap {:.3e} rad of the analytic {:.6} rad, largest gap {:.3e} rad",
        engine.name(),
        kind.name(),
        r.final_error_rad,
        r.final_rad,
        r.max_error_rad
    );
    assert!(
        r.max_error_rad <= tolerance,
        "{}: the {} step response strays {:.3e} rad from the analytic one (tolerance {tolerance:e})",
        engine.name(),
        kind.name(),
        r.max_error_rad
    );
}

/// Commands of every kind survive a state round trip
/// ([`conformance::command_round_trip`]), native and portable.
pub fn command_round_trip(engine: &dyn Engine, spec: &KitSpec) {
    let settings = settings(spec.rotor_settings);
    let subject = Subject {
        engine,
        settings: &settings,
    };
    for (portable, tolerance, what) in [
        (false, spec.command_round_trip_rad[0], "native"),
        (true, spec.command_round_trip_rad[1], "portable"),
    ] {
        let gap = conformance::command_round_trip(subject, portable);
        report(
            engine,
            &format!("command_round_trip_{what}"),
            gap,
            tolerance,
        );
        assert!(
            gap <= tolerance,
            "{}: after a {what} state round trip the rotor strays {gap:e} rad (tolerance {tolerance:e})",
            engine.name()
        );
    }
}

/// A position command without a position gain, and a command list of the
/// wrong length, are errors that say why.
pub fn bad_commands(engine: &dyn Engine, spec: &KitSpec) {
    let settings = settings(spec.rotor_settings);
    let (no_gain, count) = conformance::bad_commands(Subject {
        engine,
        settings: &settings,
    });
    for (e, want) in [(&no_gain, "no position gain"), (&count, "2 servo commands")] {
        let text = e.to_string();
        assert!(
            matches!(e, EngineError::Usage { .. }) && text.contains(want),
            "{}: expected an error saying \"{want}\", got {text}",
            engine.name()
        );
    }
}

/// The kit: one `#[test]` per check, on `$engine` (an expression of a type
/// implementing [`Engine`]) with `$spec` (a [`KitSpec`]). Call it once in
/// an engine crate's `tests/kit.rs`.
#[macro_export]
macro_rules! engine_test_kit {
    ($engine:expr, $spec:expr) => {
        #[test]
        fn kit_step_response_velocity() {
            $crate::testing::kit::step_response(
                &$engine,
                &$spec,
                $crate::trajectory::CommandKind::Velocity,
            );
        }
        #[test]
        fn kit_step_response_position() {
            $crate::testing::kit::step_response(
                &$engine,
                &$spec,
                $crate::trajectory::CommandKind::Position,
            );
        }
        #[test]
        fn kit_step_response_effort() {
            $crate::testing::kit::step_response(
                &$engine,
                &$spec,
                $crate::trajectory::CommandKind::Effort,
            );
        }
        #[test]
        fn kit_command_round_trip() {
            $crate::testing::kit::command_round_trip(&$engine, &$spec);
        }
        #[test]
        fn kit_bad_commands() {
            $crate::testing::kit::bad_commands(&$engine, &$spec);
        }
    };
}
