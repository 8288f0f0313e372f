//! DART in a process: its printing goes to the `log` crate and never to
//! standard output or error, and simulations on parallel threads (DART's
//! ODE collision detector beside the ODE engine, both on Debian's one
//! libode) give the same numbers as alone.

mod common;

use common::*;
use realitygap_core::controller::RunOutcome;
use realitygap_core::engine::EngineSettings;
use realitygap_core::testing::rerun_in_child;
use realitygap_engine_dart::DartEngine;
use std::sync::Mutex;

static LOGGED: Mutex<Vec<String>> = Mutex::new(Vec::new());

struct Collect;

impl log::Log for Collect {
    fn enabled(&self, _: &log::Metadata<'_>) -> bool {
        true
    }
    fn log(&self, record: &log::Record<'_>) {
        LOGGED.lock().unwrap().push(record.args().to_string());
    }
    fn flush(&self) {}
}

static COLLECT: Collect = Collect;

const CHILD: &str = "REALITYGAP_DART_OUTPUT_CHILD";

/// The child's part: DART's printing, through the shim's test hook (its
/// `dtmsg`, `dtwarn`, `dterr` and std::cout), and a run of the iiwa with
/// each collision detector that takes meshes; it must arrive in the log.
fn child() {
    log::set_logger(&COLLECT).unwrap();
    log::set_max_level(log::LevelFilter::Trace);
    let said = realitygap_engine_dart::say_through_dart("probe-7f3a");
    assert_eq!(said.matches("probe-7f3a").count(), 5, "{said}");
    let mut s = scene("iiwa_reach");
    let robot = iiwa(&s);
    s.duration_s = 0.2;
    for detector in ["ode", "fcl", "bullet"] {
        let set = settings(&[&format!("collision_detector={detector}")]);
        let out = run_with_settings(&DartEngine, &s, &robot, &set);
        assert!(out.trajectory.len() > 1);
    }
    let logged = LOGGED.lock().unwrap();
    let dart: Vec<&String> = logged.iter().filter(|m| m.starts_with("DART:")).collect();
    // Only a count goes to stdout: the parent looks for DART's words there.
    println!(
        "CHILD-LOGGED {} messages, {} probes",
        dart.len(),
        dart.iter()
            .map(|m| m.matches("probe-7f3a").count())
            .sum::<usize>()
    );
}

#[test]
fn dart_printing_goes_to_the_log_not_the_streams() {
    let Some(out) = rerun_in_child("dart_printing_goes_to_the_log_not_the_streams", CHILD) else {
        child();
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child failed:\n{stdout}\n{stderr}");
    let line = stdout
        .lines()
        .find_map(|l| l.split_once("CHILD-LOGGED ").map(|(_, r)| r))
        .expect("the child reports");
    eprintln!("DART said {line} (to the log)");
    assert!(
        line.ends_with(" 5 probes"),
        "the probe did not reach the log: {line}"
    );
    for text in [&stdout, &stderr] {
        for word in ["probe-7f3a", "Warning", "Error [", "[Msg]"] {
            assert!(
                !text.contains(word),
                "DART's \"{word}\" reached a stream:\n{text}"
            );
        }
    }
}

fn final_state(out: &RunOutcome) -> Vec<f64> {
    let mut v = final_angles_deg(out);
    v.extend(wrist(out).last().map(|p| [p.x, p.y, p.z]).unwrap());
    v
}

/// DART with its ODE collision detector on the iiwa's meshes, twice in
/// parallel threads, beside the ODE engine on the same scene: every run
/// ends exactly as it does alone (the ODE detector steps under the ODE
/// engine's process-wide lock; ODE's trimesh collision keeps global
/// caches).
#[test]
fn parallel_runs_match_serial_runs() {
    let mut s = scene("iiwa_push");
    s.duration_s = 2.0;
    let robot = iiwa(&s);
    let set = EngineSettings::new();
    let ode_settings = s.settings_for("ode");
    let dart_alone = final_state(&run_with_settings(&DartEngine, &s, &robot, &set));
    let ode_alone = final_state(&run_with_settings(
        &realitygap_engine_ode::OdeEngine,
        &s,
        &robot,
        &ode_settings,
    ));
    let (a, b, c) = std::thread::scope(|scope| {
        let a = scope.spawn(|| final_state(&run_with_settings(&DartEngine, &s, &robot, &set)));
        let b = scope.spawn(|| final_state(&run_with_settings(&DartEngine, &s, &robot, &set)));
        let c = scope.spawn(|| {
            final_state(&run_with_settings(
                &realitygap_engine_ode::OdeEngine,
                &s,
                &robot,
                &ode_settings,
            ))
        });
        (a.join().unwrap(), b.join().unwrap(), c.join().unwrap())
    });
    assert_eq!(a, dart_alone);
    assert_eq!(b, dart_alone);
    assert_eq!(c, ode_alone);
}
