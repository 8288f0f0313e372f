//! The rotor's checks: each kind of joint command against its analytic
//! response, commands across a state round trip, bad commands.

use super::{report, settings, KitSpec};
use crate::conformance::{self, Subject};
use crate::engine::{Engine, EngineError};
use crate::trajectory::CommandKind;

/// [`step_response`] of a velocity command.
pub fn step_response_velocity(engine: &dyn Engine, spec: &KitSpec) {
    step_response(engine, spec, CommandKind::Velocity);
}

/// [`step_response`] of a position command.
pub fn step_response_position(engine: &dyn Engine, spec: &KitSpec) {
    step_response(engine, spec, CommandKind::Position);
}

/// [`step_response`] of an effort command.
pub fn step_response_effort(engine: &dyn Engine, spec: &KitSpec) {
    step_response(engine, spec, CommandKind::Effort);
}

/// Every kind of command on the rotor against its analytic response
/// ([`conformance::step_response`]), within the spec's tolerance.
pub fn step_response(engine: &dyn Engine, spec: &KitSpec, kind: CommandKind) {
    let settings = settings(spec.rotor_settings);
    if kind == CommandKind::Effort && !spec.takes_efforts {
        let (scene, robot) = conformance::rotor();
        let mut sim = engine
            .load(&scene, &robot, &settings, &Default::default())
            .unwrap();
        let e = sim
            .set_joint_commands(&[crate::engine::ServoCommand::effort(0.1)])
            .expect_err("an engine that takes no efforts refuses them");
        report(engine, "step_response_effort_refused", 0.0, 0.0);
        eprintln!("{}: {e}", engine.name());
        return;
    }
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
        let gap = conformance::command_round_trip_with(subject, portable, spec.takes_efforts);
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
