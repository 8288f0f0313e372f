//! Synthetic scene reports for the tests of the tables (here) and of the
//! figures and HTML report (`realitygap-report`). Not for production code.

use crate::align::RunStart;
use crate::bootstrap::{BootstrapOptions, Interval, PairedComparison};
use crate::compare::{
    AlignedRun, AlignmentReport, FlaggedRun, RegistrationReport, RunsReport, SceneReport, Series,
    SourceSummary,
};
use crate::metrics::GoalMeasures;
use crate::{AnalysisMode, HealthFlag};
use std::path::Path;

/// A source whose distance to the goal is `f(t)` over 0..5 s at 20 Hz
/// (100 steps), with a constant 5 mm spread and a distance to the
/// reference of `0.01 * scale`.
pub fn source(name: &str, runs: usize, f: impl Fn(f64) -> f64, scale: f64) -> SourceSummary {
    let t_s: Vec<f64> = (0..100).map(|i| i as f64 * 0.05).collect();
    let goal: Vec<Option<f64>> = t_s.iter().map(|t| Some(f(*t))).collect();
    let usable = runs > 0;
    let some = |v: Vec<Option<f64>>| if usable { v } else { vec![None; v.len()] };
    let series = Series {
        wrist_mean_m: t_s
            .iter()
            .map(|t| usable.then(|| [f(*t), 0.0, 0.5]))
            .collect(),
        wrist_spread_m: some(vec![Some(0.005); 100]),
        wrist_distance_to_goal_m: some(goal),
        wrist_distance_to_reference_m: some(vec![Some(0.01 * scale); 100]),
        cube_displacement_m: vec![],
        cube_pitch_change_deg: vec![],
        cube_mean_m: vec![],
        cube_mean_quat: vec![],
        runs: vec![runs; 100],
        t_s,
    };
    let acc = usable.then_some(scale);
    SourceSummary {
        source: name.into(),
        kind: "simulated".into(),
        runs_total: 20,
        runs_used: runs,
        runs_flagged: if usable {
            vec![]
        } else {
            (0..20)
                .map(|i| FlaggedRun {
                    run: format!("{name}_{i}"),
                    flags: vec![HealthFlag::Diverged {
                        first_sample: 3,
                        t_s: 0.15,
                        max_abs_m: 1e17,
                    }],
                    excluded: true,
                })
                .collect()
        },
        accumulated_error_m: acc,
        accumulated_error_interval_m: acc.map(|a| Interval {
            low_m: 0.9 * a,
            high_m: 1.1 * a,
        }),
        bootstrap_over_source_runs: false,
        bootstrap_replicates_m: vec![],
        lag_s: usable.then_some(0.05),
        steps_compared: if usable { 100 } else { 0 },
        mean_error_m: acc.map(|a| a / 100.0),
        max_error_m: acc.map(|a| a / 100.0),
        final_error_m: acc.map(|a| a / 100.0),
        phase_errors_m: if usable {
            vec![scale * 0.25, scale * 0.75]
        } else {
            vec![]
        },
        orientation_error_deg: usable.then_some(1.5),
        goal: usable.then(|| GoalMeasures {
            final_distance_m: Some(f(4.95)),
            convergence_time_s: Some(3.0),
            tolerance_m: 0.01,
            overshoot_m: Some(0.0),
            goal_crossings: 0,
        }),
        cube: None,
        series,
    }
}

/// A scene with the reference `real`, two sources (`Alpha <&>` with the
/// smaller error, `Beta`), and `Dead` whose 20 runs all diverged.
pub fn scene() -> SceneReport {
    let mut reference = source("real", 20, |t| (0.6 - 0.2 * t).max(0.0), 0.0);
    reference.kind = "real".into();
    reference.accumulated_error_m = None;
    reference.series.wrist_distance_to_reference_m = vec![];
    SceneReport {
        scene: "scene_test".into(),
        mode: AnalysisMode::Default,
        steps: 100,
        control_period_s: 0.05,
        goal_m: Some([0.5, 0.0, 0.5]),
        phases_s: vec![0.0, 2.5],
        reference,
        alignment: Some(AlignmentReport {
            method: "fixed start frame 39".into(),
            runs: vec![AlignedRun {
                run: "Single0001_6D".into(),
                start: RunStart {
                    start_frame: 39,
                    start_s: 0.39,
                    onset_frame: Some(132),
                },
                steps_available: 100,
                used_for: "fit+score".into(),
            }],
            failed: vec![],
            group_shift_frames: Some(-2),
        }),
        registration: Some(RegistrationReport {
            method: "estimated <test>".into(),
            rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
            translation_m: [0.001, -0.002, 0.009],
            rotation_deg: 0.0,
            rotation_axis: [1.0, 0.0, 0.0],
            fit: None,
            residual_fit_rms_m: Some(0.004),
            residual_scored_rms_m: Some(0.005),
            settled_steps: 18,
        }),
        runs: Some(RunsReport {
            selection: "all 1 runs, fitted and scored on".into(),
            fit: vec!["Single0001_6D".into()],
            scored: vec!["Single0001_6D".into()],
        }),
        bootstrap: Some(BootstrapOptions::default()),
        closest_comparison: Some(PairedComparison {
            closest: "Alpha <&>".into(),
            runner_up: "Beta".into(),
            difference_m: 2.0,
            difference_interval_m: Some(Interval {
                low_m: 1.5,
                high_m: 2.5,
            }),
            probability_closer: 1.0,
            distinguishable: true,
        }),
        sources: vec![
            source("Alpha <&>", 20, |t| (0.62 - 0.21 * t).max(0.0), 1.0),
            source("Beta", 20, |t| (0.65 - 0.15 * t).max(0.02), 3.0),
            source("Dead", 0, |_| 0.0, 0.0),
        ],
    }
}

/// Compares `actual` with the snapshot file `dir/name` and panics with the
/// first differing line when they differ. The tool's version is replaced by
/// `<version>` first, so that a release does not change the files. With the
/// environment variable `UPDATE_SNAPSHOTS` set, writes the file instead
/// (review the diff before committing it).
pub fn assert_snapshot(dir: &Path, name: &str, actual: &str) {
    let path = dir.join(name);
    let v = realitygap_core::TOOL_VERSION;
    let actual = actual
        .replace(&format!("realitygap {v}"), "realitygap <version>")
        .replace(
            &format!("\"tool_version\": \"{v}\""),
            "\"tool_version\": \"<version>\"",
        );
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(&path, &actual).unwrap();
        return;
    }
    let expected = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; run with UPDATE_SNAPSHOTS=1 to create it",
            path.display()
        )
    });
    if expected != actual {
        let line = expected
            .lines()
            .zip(actual.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(expected.lines().count().min(actual.lines().count()));
        panic!(
            "{} differs from the output first at line {}:\n  expected: {:?}\n  actual:   {:?}\n(rerun with UPDATE_SNAPSHOTS=1 if the change is intended)\n--- actual ---\n{actual}",
            path.display(),
            line + 1,
            expected.lines().nth(line),
            actual.lines().nth(line)
        );
    }
}
