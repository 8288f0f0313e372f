//! Rendering scene reports: the accumulated-error table and the per-scene
//! measures, as Markdown, CSV, JSON and LaTeX.

use crate::bootstrap::{self, Interval};
use crate::compare::{fmt_interval, SceneReport, SourceSummary};
use serde::Serialize;
use serde_json::{json, Value};
use std::fmt::Write;

/// Output formats of [`render`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// GitHub-flavoured Markdown.
    Markdown,
    /// Comma-separated values, one row per source and scene.
    Csv,
    /// A JSON object (see [`to_json`]).
    Json,
    /// A LaTeX `tabular` (booktabs).
    Latex,
}

impl std::str::FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "md" | "markdown" => Ok(Format::Markdown),
            "csv" => Ok(Format::Csv),
            "json" => Ok(Format::Json),
            "latex" | "tex" => Ok(Format::Latex),
            _ => Err(format!(
                "unknown format '{s}' (expected md, csv, json or latex)"
            )),
        }
    }
}

/// Renders reports in a format.
pub fn render(reports: &[SceneReport], format: Format) -> String {
    match format {
        Format::Markdown => markdown(reports),
        Format::Csv => csv(reports),
        Format::Json => {
            serde_json::to_string_pretty(&to_json(reports, false)).unwrap_or_default() + "\n"
        }
        Format::Latex => latex(reports),
    }
}

/// Source names in first-seen order over all scenes.
pub fn source_names(reports: &[SceneReport]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for r in reports {
        for s in &r.sources {
            if !names.contains(&s.source) {
                names.push(s.source.clone());
            }
        }
    }
    names
}

/// Total accumulated error of a source over all scenes, metres; `None`
/// when the source lacks a scene or a value.
pub fn total(reports: &[SceneReport], source: &str) -> Option<f64> {
    reports.iter().try_fold(0.0, |acc, r| {
        r.sources
            .iter()
            .find(|s| s.source == source)
            .and_then(|s| s.accumulated_error_m)
            .map(|v| acc + v)
    })
}

/// The bootstrap interval of a source's total over all scenes, metres:
/// the replicates of the scenes (drawn independently) summed index by
/// index. `None` when a scene lacks the source or its replicates.
pub fn total_interval(reports: &[SceneReport], source: &str) -> Option<Interval> {
    let mut sum: Option<Vec<f64>> = None;
    let mut level = 0.95;
    for r in reports {
        let s = r.sources.iter().find(|s| s.source == source)?;
        if s.bootstrap_replicates_m.is_empty() {
            return None;
        }
        level = r.bootstrap.map_or(level, |b| b.level);
        sum = Some(match sum {
            None => s.bootstrap_replicates_m.clone(),
            Some(acc) if acc.len() == s.bootstrap_replicates_m.len() => acc
                .iter()
                .zip(&s.bootstrap_replicates_m)
                .map(|(a, b)| a + b)
                .collect(),
            Some(_) => return None,
        });
    }
    bootstrap::percentile_interval(&sum?, level)
}

/// A value with its interval when there is one: `5.326 [5.102, 5.551]`.
fn fmt_with_interval(v: Option<f64>, i: Option<Interval>) -> String {
    match (v, i) {
        (Some(_), Some(_)) => format!("{} {}", fmt_m(v), fmt_interval(i)),
        _ => fmt_m(v),
    }
}

/// The interval of a source's accumulated error in a scene.
fn interval_of(r: &SceneReport, source: &str) -> Option<Interval> {
    r.sources
        .iter()
        .find(|s| s.source == source)
        .and_then(|s| s.accumulated_error_interval_m)
}

/// Formats metres for tables: fixed 3 decimals, or scientific beyond 1e6.
pub fn fmt_m(v: Option<f64>) -> String {
    match v {
        None => "n/a".into(),
        Some(v) if !v.is_finite() => format!("{v}"),
        Some(v) if v.abs() >= 1e6 => format!("{v:.3e}"),
        Some(v) => format!("{v:.3}"),
    }
}

fn flagged_note(s: &SourceSummary) -> String {
    let excluded = s.runs_flagged.iter().filter(|f| f.excluded).count();
    if excluded > 0 {
        format!(" ({} of {} runs left out)", excluded, s.runs_total)
    } else {
        String::new()
    }
}

#[derive(Serialize)]
struct FlagRow<'a> {
    run: &'a str,
    flags: Vec<&'static str>,
    excluded: bool,
    details: Vec<String>,
}

/// The JSON form: `{mode, rows: [{source, scene, accumulated_error_m,
/// runs_used, runs_flagged}], totals: {source: m}, scenes: {name: {...}}}`.
/// With `series`, each source carries its per-step series too.
pub fn to_json(reports: &[SceneReport], series: bool) -> Value {
    let mut rows = Vec::new();
    for r in reports {
        for s in &r.sources {
            rows.push(json!({
                "source": s.source,
                "scene": r.scene,
                "accumulated_error_m": s.accumulated_error_m,
                "accumulated_error_interval_m": s.accumulated_error_interval_m,
                "lag_s": s.lag_s,
                "runs_used": s.runs_used,
                "runs_total": s.runs_total,
                "runs_flagged": s.runs_flagged.iter().map(|f| FlagRow {
                    run: &f.run,
                    flags: f.flags.iter().map(|x| x.name()).collect(),
                    excluded: f.excluded,
                    details: f.flags.iter().map(|x| x.describe()).collect(),
                }).collect::<Vec<_>>(),
            }));
        }
    }
    let totals: serde_json::Map<String, Value> = source_names(reports)
        .into_iter()
        .map(|n| {
            let t = total(reports, &n);
            (n, json!(t))
        })
        .collect();
    let totals_interval: serde_json::Map<String, Value> = source_names(reports)
        .into_iter()
        .map(|n| {
            let t = total_interval(reports, &n);
            (n, json!(t))
        })
        .collect();
    let scenes: serde_json::Map<String, Value> = reports
        .iter()
        .map(|r| {
            let mut v = serde_json::to_value(r).unwrap_or(Value::Null);
            if !series {
                strip_series(&mut v);
            }
            if let Value::Object(o) = &mut v {
                o.insert(
                    "closest_source".into(),
                    json!(r.winner().map(|s| s.source.clone())),
                );
                o.insert("verdict".into(), json!(r.verdict()));
                o.insert("closest_per_phase".into(), json!(r.closest_per_phase()));
            }
            (r.scene.clone(), v)
        })
        .collect();
    json!({
        "tool_version": realitygap_core::TOOL_VERSION,
        "mode": reports.first().map(|r| r.mode),
        "rows": rows,
        "totals": totals,
        "totals_interval_m": totals_interval,
        "bootstrap": reports.iter().find_map(|r| r.bootstrap),
        "registration": reports.iter().find_map(|r| r.registration.as_ref()).map(|g| json!({
            "method": g.method,
            "rotation_wxyz": g.rotation_wxyz,
            "translation_m": g.translation_m,
            "rotation_deg": g.rotation_deg,
            "rotation_axis": g.rotation_axis,
            "fit": g.fit,
        })),
        "runs": reports.iter().find_map(|r| r.runs.as_ref().map(|x| x.selection.clone())),
        "scenes": scenes,
    })
}

fn strip_series(v: &mut Value) {
    if let Value::Object(o) = v {
        o.remove("series");
        for (_, c) in o.iter_mut() {
            strip_series(c);
        }
    } else if let Value::Array(a) = v {
        a.iter_mut().for_each(strip_series);
    }
}

/// The short form for a terminal: the accumulated-error table with its
/// intervals, the closest source per scene, and each kind of run flag once,
/// with how many runs carry it, of which sources and scenes, and one
/// example. The full lists are in [`render`]'s Markdown (`table.md`).
pub fn summary(reports: &[SceneReport]) -> String {
    let mut out = String::new();
    accumulated_table(&mut out, reports);
    if let Some(b) = reports.iter().find_map(|r| r.bootstrap) {
        let _ = writeln!(
            out,
            "\n[low, high]: {:.0} % bootstrap interval over the real runs.",
            b.level * 100.0
        );
    }
    for r in reports {
        let _ = writeln!(out, "- {}: {}.", r.scene, r.verdict());
    }
    let flags = flag_summary(reports);
    if !flags.is_empty() {
        let _ = writeln!(
            out,
            "\nFlagged runs (each kind once; the full tables list every run):"
        );
        for f in flags {
            let _ = writeln!(out, "- {f}");
        }
    }
    out
}

/// Each kind of flag once: `short: 20 runs (left in) of real in
/// scene3_cube_push, e.g. CubeExp0011_6D: only 366 of 400 samples after
/// alignment`.
pub fn flag_summary(reports: &[SceneReport]) -> Vec<String> {
    struct Kind {
        name: &'static str,
        runs: usize,
        excluded: usize,
        sources: Vec<String>,
        scenes: Vec<String>,
        example: String,
    }
    let mut kinds: Vec<Kind> = Vec::new();
    for r in reports {
        for s in std::iter::once(&r.reference).chain(&r.sources) {
            for f in &s.runs_flagged {
                for flag in &f.flags {
                    let i = match kinds.iter().position(|k| k.name == flag.name()) {
                        Some(i) => i,
                        None => {
                            kinds.push(Kind {
                                name: flag.name(),
                                runs: 0,
                                excluded: 0,
                                sources: Vec::new(),
                                scenes: Vec::new(),
                                example: format!(
                                    "{} / {} in {}: {}",
                                    s.source,
                                    f.run,
                                    r.scene,
                                    flag.describe()
                                ),
                            });
                            kinds.len() - 1
                        }
                    };
                    let k = &mut kinds[i];
                    k.runs += 1;
                    k.excluded += usize::from(f.excluded);
                    if !k.sources.contains(&s.source) {
                        k.sources.push(s.source.clone());
                    }
                    if !k.scenes.contains(&r.scene) {
                        k.scenes.push(r.scene.clone());
                    }
                }
            }
        }
    }
    kinds
        .into_iter()
        .map(|k| {
            let left = if k.excluded == k.runs {
                "all left out".to_string()
            } else if k.excluded == 0 {
                "kept".to_string()
            } else {
                format!("{} left out", k.excluded)
            };
            format!(
                "{}: {} run{} ({left}) of {} in {}; e.g. {}",
                k.name,
                k.runs,
                if k.runs == 1 { "" } else { "s" },
                k.sources.join(", "),
                k.scenes.join(", "),
                k.example
            )
        })
        .collect()
}

fn accumulated_table(out: &mut String, reports: &[SceneReport]) {
    let names = source_names(reports);
    let mut head = String::from("| Source |");
    let mut rule = String::from("|---|");
    for r in reports {
        let _ = write!(head, " {} |", r.scene);
        rule.push_str("---:|");
    }
    let _ = writeln!(out, "{head} Total |\n{rule}---:|");
    for n in &names {
        let mut line = format!("| {n} |");
        for r in reports {
            let s = r.sources.iter().find(|s| &s.source == n);
            let _ = write!(
                line,
                " {}{} |",
                fmt_with_interval(s.and_then(|s| s.accumulated_error_m), interval_of(r, n)),
                s.map(flagged_note).unwrap_or_default()
            );
        }
        let _ = writeln!(
            out,
            "{line} {} |",
            fmt_with_interval(total(reports, n), total_interval(reports, n))
        );
    }
}

fn markdown(reports: &[SceneReport]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "## Accumulated error (m), summed over control steps\n");
    accumulated_table(&mut out, reports);
    markdown_notes(&mut out, reports);
    for r in reports {
        markdown_scene(&mut out, r);
    }
    out
}

/// A scene's section of the Markdown: heading, reference, alignment,
/// notes, the measures table and the flagged runs.
fn markdown_scene(out: &mut String, r: &SceneReport) {
    let _ = writeln!(out, "\n### {}\n", r.scene);
    let _ = writeln!(
        out,
        "Reference: {} ({} of {} runs used).",
        r.reference.source, r.reference.runs_used, r.reference.runs_total
    );
    if let Some(a) = &r.alignment {
        let starts: Vec<String> = a
            .runs
            .iter()
            .map(|x| x.start.start_frame.to_string())
            .collect();
        let _ = writeln!(
            out,
            "Alignment: {}; start frames {}.",
            a.method,
            starts.join(", ")
        );
    }
    scene_notes(out, r);
    let _ = writeln!(out);
    let _ = writeln!(out, "| Source | Runs | Mean err (m) | Final err (m) | Lag (s) | Goal dist (m) | Converged (s) | Overshoot (m) | Orient. err (deg) | Cube final dx (m) | Cube tilt (deg) | Contact (s) |");
    let _ = writeln!(
        out,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for s in std::iter::once(&r.reference).chain(&r.sources) {
        let g = s.goal.as_ref();
        let c = s.cube.as_ref();
        let _ = writeln!(
            out,
            "| {} | {}/{} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            s.source,
            s.runs_used,
            s.runs_total,
            fmt_m(s.mean_error_m),
            fmt_m(s.final_error_m),
            s.lag_s.map_or("n/a".into(), |v| format!("{v:.2}")),
            fmt_m(g.and_then(|g| g.final_distance_m)),
            g.and_then(|g| g.convergence_time_s)
                .map_or("never".into(), |t| format!("{t:.2}")),
            fmt_m(g.and_then(|g| g.overshoot_m)),
            s.orientation_error_deg
                .map_or("n/a".into(), |v| format!("{v:.1}")),
            fmt_m(c.and_then(|c| c.final_offset_from_nominal_m.map(|o| o[0]))),
            c.map_or("n/a".into(), |c| format!("{:.1}", c.max_tilt_deg)),
            c.and_then(|c| c.contact_onset_s)
                .map_or("n/a".into(), |t| format!("{t:.2}")),
        );
    }
    let flagged: Vec<String> = std::iter::once(&r.reference)
        .chain(&r.sources)
        .flat_map(|s| {
            s.runs_flagged.iter().map(move |f| {
                let what: Vec<String> = f.flags.iter().map(|x| x.describe()).collect();
                format!(
                    "- {} / {}{}: {}",
                    s.source,
                    f.run,
                    if f.excluded { " (left out)" } else { "" },
                    what.join("; ")
                )
            })
        })
        .collect();
    if !flagged.is_empty() {
        let _ = writeln!(out, "\nFlagged runs:\n{}", flagged.join("\n"));
    }
}

/// The lines under a scene's heading: runs, group shift, registration
/// residuals and the verdict on the closest source.
fn scene_notes(out: &mut String, r: &SceneReport) {
    if let Some(runs) = r
        .runs
        .as_ref()
        .filter(|x| x.fit != x.scored || !x.selection.starts_with("all "))
    {
        let _ = writeln!(
            out,
            "Runs: {} (fit: {}; scored: {}).",
            runs.selection,
            runs.fit.join(", "),
            runs.scored.join(", ")
        );
    }
    if let Some(a) = r.alignment.as_ref().and_then(|a| a.group_shift_frames) {
        let _ = writeln!(out, "Group shift to the kinematic reference: {a} frames.");
    }
    if let Some(g) = &r.registration {
        let _ = writeln!(
            out,
            "Registration residual at this scene's {} settled steps: {} mm on the fit runs, {} mm on the scored runs.",
            g.settled_steps,
            g.residual_fit_rms_m.map_or("n/a".into(), |v| format!("{:.1}", v * 1000.0)),
            g.residual_scored_rms_m.map_or("n/a".into(), |v| format!("{:.1}", v * 1000.0))
        );
    }
    if r.closest_comparison.is_some() {
        let _ = writeln!(out, "{}.", capitalise(&r.verdict()));
    } else if let Some(c) = r.closest() {
        let _ = writeln!(out, "Closest source: {}.", c.source);
    }
}

fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => String::new(),
    }
}

/// The registration, in words: rotation in degrees, translation in mm.
pub fn describe_registration(reports: &[SceneReport]) -> Option<String> {
    let g = reports.iter().find_map(|r| r.registration.as_ref())?;
    let t = g.translation_m;
    let a = g.rotation_axis;
    let mut text = format!(
        "capture frame registered into the world ({}): rotation {:.3} deg about ({:.3}, {:.3}, {:.3}), translation ({:.1}, {:.1}, {:.1}) mm",
        g.method,
        g.rotation_deg,
        a[0],
        a[1],
        a[2],
        t[0] * 1000.0,
        t[1] * 1000.0,
        t[2] * 1000.0
    );
    if let Some(f) = &g.fit {
        text.push_str(&format!(
            ", residual {:.1} mm RMS (largest {:.1} mm) over {} settled poses",
            f.residual_rms_m * 1000.0,
            f.residual_max_m * 1000.0,
            f.pairs_used
        ));
    }
    Some(text)
}

/// The lines under the Markdown table: intervals, verdicts, registration,
/// runs. Nothing when no interval, registration or selection is in force
/// (the study's own table stays as it was).
fn markdown_notes(out: &mut String, reports: &[SceneReport]) {
    if let Some(b) = reports.iter().find_map(|r| r.bootstrap) {
        let _ = writeln!(
            out,
            "\n[low, high]: {:.0} % bootstrap interval over the real runs (and a source's own runs where they differ), {} resamples, seed {}.",
            b.level * 100.0,
            b.resamples,
            b.seed
        );
        for r in reports {
            let _ = writeln!(out, "- {}: {}.", r.scene, r.verdict());
        }
    }
    if let Some(text) = describe_registration(reports) {
        let _ = writeln!(out, "\nRegistration: {text}.");
    }
    if let Some(runs) = reports.iter().find_map(|r| r.runs.as_ref()) {
        if reports
            .iter()
            .any(|r| r.bootstrap.is_some() || r.registration.is_some())
        {
            let _ = writeln!(out, "\nReal runs: {}.", runs.selection);
        }
    }
}

fn csv(reports: &[SceneReport]) -> String {
    let mut out = String::from("source,scene,accumulated_error_m,mean_error_m,final_error_m,runs_used,runs_total,runs_excluded,flagged_runs,interval_low_m,interval_high_m,lag_s\n");
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
    for r in reports {
        for s in &r.sources {
            let flagged: Vec<String> = s
                .runs_flagged
                .iter()
                .map(|f| {
                    format!(
                        "{}:{}",
                        f.run,
                        f.flags
                            .iter()
                            .map(|x| x.name())
                            .collect::<Vec<_>>()
                            .join("+")
                    )
                })
                .collect();
            let _ = writeln!(
                out,
                "{},{},{},{},{},{},{},{},\"{}\",{},{},{}",
                csv_field(&s.source),
                csv_field(&r.scene),
                opt(s.accumulated_error_m),
                opt(s.mean_error_m),
                opt(s.final_error_m),
                s.runs_used,
                s.runs_total,
                s.runs_flagged.iter().filter(|f| f.excluded).count(),
                flagged.join(" ").replace('"', "'"),
                opt(s.accumulated_error_interval_m.map(|i| i.low_m)),
                opt(s.accumulated_error_interval_m.map(|i| i.high_m)),
                opt(s.lag_s)
            );
        }
    }
    for n in source_names(reports) {
        let i = total_interval(reports, &n);
        let _ = writeln!(
            out,
            "{},total,{},,,,,,,{},{},",
            csv_field(&n),
            opt(total(reports, &n)),
            opt(i.map(|i| i.low_m)),
            opt(i.map(|i| i.high_m))
        );
    }
    out
}

/// A CSV field, quoted (with doubled quotes) when it holds a comma, a
/// quote or a newline.
pub fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn latex_escape(s: &str) -> String {
    s.replace('\\', "\\textbackslash{}")
        .replace('_', "\\_")
        .replace('&', "\\&")
        .replace('%', "\\%")
        .replace('#', "\\#")
}

fn latex(reports: &[SceneReport]) -> String {
    let mut out = String::new();
    let cols = "l".to_string() + &"r".repeat(reports.len() + 1);
    let _ = writeln!(
        out,
        "% Accumulated error (m); generated by realitygap {}",
        realitygap_core::TOOL_VERSION
    );
    let _ = writeln!(out, "\\begin{{tabular}}{{{cols}}}\n\\toprule");
    let scenes: Vec<String> = reports.iter().map(|r| latex_escape(&r.scene)).collect();
    let _ = writeln!(
        out,
        "Source & {} & Total \\\\\n\\midrule",
        scenes.join(" & ")
    );
    for n in source_names(reports) {
        let cells: Vec<String> = reports
            .iter()
            .map(|r| {
                let v = r
                    .sources
                    .iter()
                    .find(|s| s.source == n)
                    .and_then(|s| s.accumulated_error_m);
                match v {
                    Some(v) if v.is_finite() && v.abs() >= 1e6 => {
                        let e = v.abs().log10().floor();
                        format!("${:.2} \\times 10^{{{}}}$", v / 10f64.powf(e), e)
                    }
                    _ => latex_interval(fmt_with_interval(v, interval_of(r, &n))),
                }
            })
            .collect();
        let _ = writeln!(
            out,
            "{} & {} & {} \\\\",
            latex_escape(&n),
            cells.join(" & "),
            latex_interval(fmt_with_interval(
                total(reports, &n),
                total_interval(reports, &n)
            ))
        );
    }
    let _ = writeln!(out, "\\bottomrule\n\\end{{tabular}}");
    if let Some(b) = reports.iter().find_map(|r| r.bootstrap) {
        let _ = writeln!(
            out,
            "% [low, high]: {:.0} % bootstrap interval, {} resamples, seed {}.",
            b.level * 100.0,
            b.resamples,
            b.seed
        );
        for r in reports {
            let _ = writeln!(out, "% {}: {}.", r.scene, r.verdict());
        }
    }
    if let Some(text) = describe_registration(reports) {
        let _ = writeln!(out, "% Registration: {text}.");
    }
    out
}

/// A table cell with an interval, the interval in a smaller font.
fn latex_interval(cell: String) -> String {
    match cell.split_once(' ') {
        Some((v, i)) => format!("{v} {{\\scriptsize {i}}}"),
        None => cell,
    }
}

#[cfg(test)]
mod tests;
