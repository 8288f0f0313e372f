//! Rendering scene reports: the accumulated-error table and the per-scene
//! measures, as Markdown, CSV, JSON and LaTeX.

use crate::compare::{SceneReport, SourceSummary};
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
                    json!(r.closest().map(|s| s.source.clone())),
                );
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

fn markdown(reports: &[SceneReport]) -> String {
    let mut out = String::new();
    let names = source_names(reports);
    let _ = writeln!(out, "## Accumulated error (m), summed over control steps\n");
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
                fmt_m(s.and_then(|s| s.accumulated_error_m)),
                s.map(flagged_note).unwrap_or_default()
            );
        }
        let _ = writeln!(out, "{line} {} |", fmt_m(total(reports, n)));
    }
    for r in reports {
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
        if let Some(c) = r.closest() {
            let _ = writeln!(out, "Closest source: {}.", c.source);
        }
        let _ = writeln!(out);
        let _ = writeln!(out, "| Source | Runs | Mean err (m) | Final err (m) | Goal dist (m) | Converged (s) | Overshoot (m) | Orient. err (deg) | Cube final dx (m) | Cube tilt (deg) | Contact (s) |");
        let _ = writeln!(
            out,
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        for s in std::iter::once(&r.reference).chain(&r.sources) {
            let g = s.goal.as_ref();
            let c = s.cube.as_ref();
            let _ = writeln!(
                out,
                "| {} | {}/{} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                s.source,
                s.runs_used,
                s.runs_total,
                fmt_m(s.mean_error_m),
                fmt_m(s.final_error_m),
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
    out
}

fn csv(reports: &[SceneReport]) -> String {
    let mut out = String::from("source,scene,accumulated_error_m,mean_error_m,final_error_m,runs_used,runs_total,runs_excluded,flagged_runs\n");
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
                "{},{},{},{},{},{},{},{},\"{}\"",
                csv_field(&s.source),
                csv_field(&r.scene),
                opt(s.accumulated_error_m),
                opt(s.mean_error_m),
                opt(s.final_error_m),
                s.runs_used,
                s.runs_total,
                s.runs_flagged.iter().filter(|f| f.excluded).count(),
                flagged.join(" ").replace('"', "'")
            );
        }
    }
    for n in source_names(reports) {
        let _ = writeln!(
            out,
            "{},total,{},,,,,,",
            csv_field(&n),
            opt(total(reports, &n))
        );
    }
    out
}

fn csv_field(s: &str) -> String {
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
                    _ => fmt_m(v),
                }
            })
            .collect();
        let _ = writeln!(
            out,
            "{} & {} & {} \\\\",
            latex_escape(&n),
            cells.join(" & "),
            fmt_m(total(reports, &n))
        );
    }
    let _ = writeln!(out, "\\bottomrule\n\\end{{tabular}}");
    out
}
