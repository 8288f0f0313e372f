//! Tests of the tables: snapshots of every format (expected files in
//! `tests/snapshots/`; rerun with `UPDATE_SNAPSHOTS=1` to rewrite them after
//! an intended change, and review the diff), and the helpers' rules.

use super::*;
use crate::bootstrap::Interval;
use crate::testing;
use std::path::Path;

/// Compares `actual` with `tests/snapshots/<name>`.
fn snapshot(name: &str, actual: &str) {
    testing::assert_snapshot(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/snapshots"),
        name,
        actual,
    );
}

/// Two scenes in default mode: intervals, a verdict, a registration, a run
/// selection and a source whose runs were all left out. Each source carries
/// four bootstrap replicates, so the totals have intervals too.
fn default_reports() -> Vec<SceneReport> {
    let first = testing::scene();
    let mut second = testing::scene();
    second.scene = "scene_two".into();
    second.closest_comparison = Some(crate::bootstrap::PairedComparison {
        closest: "Alpha <&>".into(),
        runner_up: "Beta".into(),
        difference_m: 0.1,
        difference_interval_m: Some(Interval {
            low_m: -0.2,
            high_m: 0.4,
        }),
        probability_closer: 0.7,
        distinguishable: false,
    });
    let mut reports = vec![first, second];
    for (k, r) in reports.iter_mut().enumerate() {
        for s in &mut r.sources {
            if let Some(a) = s.accumulated_error_m {
                s.accumulated_error_m = Some(a + k as f64 * 0.5);
                s.bootstrap_replicates_m = vec![0.9 * a, a, 1.05 * a, 1.1 * a];
            }
        }
    }
    reports
}

/// The study's own table: study mode, no intervals, no registration, no
/// run selection, one huge value.
fn study_reports() -> Vec<SceneReport> {
    let mut reports = default_reports();
    for r in &mut reports {
        r.mode = crate::AnalysisMode::Study;
        r.bootstrap = None;
        r.registration = None;
        r.runs = None;
        r.closest_comparison = None;
        for s in &mut r.sources {
            s.accumulated_error_interval_m = None;
            s.bootstrap_replicates_m.clear();
        }
    }
    reports[1].sources[1].accumulated_error_m = Some(2.5e7);
    reports
}

#[test]
fn markdown_snapshots() {
    snapshot("default.md", &render(&default_reports(), Format::Markdown));
    snapshot("study.md", &render(&study_reports(), Format::Markdown));
}

#[test]
fn latex_snapshots() {
    snapshot("default.tex", &render(&default_reports(), Format::Latex));
    snapshot("study.tex", &render(&study_reports(), Format::Latex));
}

#[test]
fn csv_snapshots() {
    snapshot("default.csv", &render(&default_reports(), Format::Csv));
    snapshot("study.csv", &render(&study_reports(), Format::Csv));
}

#[test]
fn json_snapshot() {
    snapshot("default.json", &render(&default_reports(), Format::Json));
}

#[test]
fn formats_are_read_by_their_names() {
    for (name, format) in [
        ("md", Format::Markdown),
        ("markdown", Format::Markdown),
        ("csv", Format::Csv),
        ("json", Format::Json),
        ("latex", Format::Latex),
        ("tex", Format::Latex),
    ] {
        assert_eq!(name.parse::<Format>(), Ok(format));
    }
    let e = "html".parse::<Format>().unwrap_err();
    assert!(e.contains("unknown format 'html'"), "{e}");
}

#[test]
fn metres_have_three_decimals_or_an_exponent() {
    assert_eq!(fmt_m(None), "n/a");
    assert_eq!(fmt_m(Some(1.23456)), "1.235");
    assert_eq!(fmt_m(Some(-0.0004)), "-0.000");
    assert_eq!(fmt_m(Some(999_999.0)), "999999.000");
    assert_eq!(fmt_m(Some(2.5e7)), "2.500e7");
    assert_eq!(fmt_m(Some(f64::INFINITY)), "inf");
    assert_eq!(fmt_m(Some(f64::NAN)), "NaN");
    assert_eq!(
        fmt_with_interval(
            Some(1.0),
            Some(Interval {
                low_m: 0.9,
                high_m: 1.1
            })
        ),
        "1.000 [0.900, 1.100]"
    );
    assert_eq!(
        fmt_with_interval(
            None,
            Some(Interval {
                low_m: 0.9,
                high_m: 1.1
            })
        ),
        "n/a"
    );
}

#[test]
fn totals_need_every_scene() {
    let mut reports = default_reports();
    assert_eq!(source_names(&reports), ["Alpha <&>", "Beta", "Dead"]);
    // Alpha: 1.0 + 1.5; Dead has no value.
    assert_eq!(total(&reports, "Alpha <&>"), Some(2.5));
    assert_eq!(total(&reports, "Dead"), None);
    assert_eq!(total(&reports, "nobody"), None);
    // Replicates summed index by index: 0.9+0.9, ..., 1.1+1.1 (x Alpha's 1.0).
    let i = total_interval(&reports, "Alpha <&>").unwrap();
    assert!(i.low_m >= 1.8 - 1e-12 && i.high_m <= 2.2 + 1e-12, "{i:?}");
    assert!(i.low_m < i.high_m);
    assert_eq!(total_interval(&reports, "Dead"), None);
    // A scene without replicates, or with another number of them: no interval.
    reports[1].sources[0].bootstrap_replicates_m.pop();
    assert_eq!(total_interval(&reports, "Alpha <&>"), None);
    reports[1].sources[0].bootstrap_replicates_m.clear();
    assert_eq!(total_interval(&reports, "Alpha <&>"), None);
    // A source missing from a scene has no total.
    reports[1].sources.remove(1);
    assert_eq!(total(&reports, "Beta"), None);
}

#[test]
fn csv_quotes_names_and_lists_flags() {
    let mut reports = study_reports();
    reports[0].sources[1].source = "Beta, \"B\"".into();
    let text = render(&reports, Format::Csv);
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap().split(',').collect::<Vec<_>>(),
        [
            "source",
            "scene",
            "accumulated_error_m",
            "mean_error_m",
            "final_error_m",
            "runs_used",
            "runs_total",
            "runs_excluded",
            "flagged_runs",
            "interval_low_m",
            "interval_high_m",
            "lag_s"
        ]
    );
    assert!(text.contains("\n\"Beta, \"\"B\"\"\",scene_test,"), "{text}");
    let dead = text
        .lines()
        .find(|l| l.starts_with("Dead,scene_test"))
        .unwrap();
    assert!(
        dead.starts_with("Dead,scene_test,,,,0,20,20,\"Dead_0:diverged Dead_1:diverged"),
        "{dead}"
    );
    // One total row per source; empty cells where there is no value.
    assert!(text.contains("\nAlpha <&>,total,2.5,,,,,,,,,\n"), "{text}");
    assert!(text.contains("\nDead,total,,,,,,,,,,\n"), "{text}");
    assert!(text.ends_with("\nBeta,total,,,,,,,,,,\n"), "{text}");
}

#[test]
fn latex_escapes_names_and_shrinks_intervals() {
    let mut reports = default_reports();
    reports[0].sources[1].source = "Beta_1 & 50% #2".into();
    let text = render(&reports, Format::Latex);
    assert!(text.contains("Beta\\_1 \\& 50\\% \\#2 & "), "{text}");
    assert!(
        text.contains("scene\\_test & scene\\_two & Total"),
        "{text}"
    );
    assert!(
        text.contains("1.000 {\\scriptsize [0.900, 1.100]}"),
        "{text}"
    );
    let study = render(&study_reports(), Format::Latex);
    assert!(study.contains("$2.50 \\times 10^{7}$"), "{study}");
    assert!(!study.contains("bootstrap") && !study.contains("Registration"));
}

#[test]
fn json_keeps_series_only_when_asked() {
    let reports = default_reports();
    let without = to_json(&reports, false);
    let with = to_json(&reports, true);
    assert!(!without.to_string().contains("\"series\""));
    assert!(with["scenes"]["scene_test"]["sources"][0]["series"].is_object());
    assert_eq!(without["rows"].as_array().unwrap().len(), 6);
    assert_eq!(without["totals"]["Alpha <&>"], json!(2.5));
    assert_eq!(without["totals"]["Dead"], Value::Null);
    assert_eq!(
        without["scenes"]["scene_test"]["closest_source"],
        json!("Alpha <&>")
    );
    // Cannot be told apart: no closest source, and the verdict says so.
    assert_eq!(
        without["scenes"]["scene_two"]["closest_source"],
        Value::Null
    );
    let verdict = without["scenes"]["scene_two"]["verdict"].as_str().unwrap();
    assert!(verdict.contains("cannot be told apart"), "{verdict}");
    let dead = &without["rows"][2];
    assert_eq!(dead["runs_flagged"].as_array().unwrap().len(), 20);
    assert_eq!(dead["runs_flagged"][0]["flags"], json!(["diverged"]));
    assert_eq!(dead["runs_flagged"][0]["excluded"], json!(true));
}

#[test]
fn markdown_notes_appear_only_with_intervals_registration_or_selection() {
    let default = render(&default_reports(), Format::Markdown);
    assert!(default.contains("\n[low, high]: 95 % bootstrap interval"));
    assert!(default.contains("\nRegistration: capture frame registered"));
    assert!(default.contains("| Dead | n/a (20 of 20 runs left out) |"));
    assert!(default.contains("- scene_two: Alpha <&> and Beta cannot be told apart"));
    let study = render(&study_reports(), Format::Markdown);
    assert!(!study.contains("[low, high]") && !study.contains("Registration"));
    assert!(study.contains("Closest source: Alpha <&>."));
}

/// The terminal summary: the table, the verdicts and each kind of flag
/// once, with its count and an example; not the per-scene measures.
#[test]
fn summary_lists_each_flag_kind_once_with_a_count() {
    let reports = default_reports();
    let text = summary(&reports);
    snapshot("summary_default.txt", &text);
    assert!(text.contains("| Alpha <&> |"), "{text}");
    assert!(!text.contains("Mean err"), "no measures table: {text}");
    // Dead's 20 diverged runs in each of the two scenes: one line.
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("- diverged:"))
        .collect();
    assert_eq!(lines.len(), 1, "{text}");
    assert!(
        lines[0].contains("40 runs (all left out) of Dead in scene_test, scene_two"),
        "{}",
        lines[0]
    );
    assert!(lines[0].contains("e.g. Dead / "), "{}", lines[0]);
    // The full Markdown still lists every flagged run.
    let full = render(&reports, Format::Markdown);
    assert!(full.matches("(left out): diverged").count() >= 40, "{full}");
}
