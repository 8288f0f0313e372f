//! The self-contained HTML report: one `index.html` with the figures inline
//! as SVG, the style sheet inline, and one inline script (the 3D replay's
//! renderer); no network references.

use crate::figures::Figure;
use crate::provenance::Provenance;
use realitygap_analysis::compare::{fmt_interval, AlignmentReport, SceneReport, SourceSummary};
use realitygap_analysis::table::{
    describe_registration, fmt_m, source_names, total, total_interval,
};
use std::fmt::Write;

/// A figure as placed in the report.
#[derive(Debug, Clone, Copy)]
pub struct FigureEntry<'a> {
    /// The figure (title, caption, scene).
    pub figure: &'a Figure,
    /// Its SVG document, inlined.
    pub svg: &'a str,
    /// Path of the SVG file relative to `index.html`.
    pub svg_file: &'a str,
    /// Path of the PNG file relative to `index.html`.
    pub png_file: &'a str,
}

/// Escapes text for HTML content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// An `id` attribute value derived from a name: ASCII letters and digits
/// kept, anything else `-`.
pub fn anchor(prefix: &str, name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect();
    format!("{prefix}-{s}")
}

/// Prepares an SVG document for inlining: drops an XML prolog and the
/// namespace declaration (implied in HTML), and labels it for screen
/// readers.
pub fn inline_svg(svg: &str, label: &str) -> String {
    let mut s = svg.trim();
    if s.starts_with("<?xml") {
        s = s.find("?>").map_or(s, |i| s[i + 2..].trim_start());
    }
    let s = s.replacen(" xmlns=\"http://www.w3.org/2000/svg\"", "", 1);
    s.replacen(
        "<svg ",
        &format!("<svg role=\"img\" aria-label=\"{}\" ", escape(label)),
        1,
    )
}

const CSS: &str = "
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,'DejaVu Sans',sans-serif;color:#1a1a1a;max-width:1340px;margin:0 auto;padding:1rem 1.5rem 3rem;line-height:1.45}
h1{font-size:1.6rem;margin-bottom:.2rem}h2{margin-top:2.2rem;border-bottom:2px solid #ddd;padding-bottom:.2rem}h3{margin-top:1.5rem}
.meta{color:#555;margin-top:0}
nav ul{list-style:none;padding:0;display:flex;flex-wrap:wrap;gap:.4rem 1.2rem}
table{border-collapse:collapse;margin:.6rem 0;font-size:.92rem;display:block;overflow-x:auto;max-width:100%}
th[scope=row]{white-space:nowrap}
th,td{border:1px solid #d0d0d0;padding:.25rem .55rem;vertical-align:top}
th{background:#f3f3f3;text-align:left}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
td.best{background:#dff0e3;font-weight:bold}
tr.reference td{background:#f7f7f7;font-style:italic}
.note{color:#555;font-size:.9rem}
.flag-excluded{color:#a03000;font-weight:bold}
.figures{display:grid;grid-template-columns:repeat(auto-fill,minmax(540px,1fr));gap:1rem 1.5rem}
figure{margin:0 0 1rem}
figure svg{max-width:100%;height:auto;border:1px solid #e5e5e5}
figcaption{font-size:.88rem;color:#333;max-width:640px;margin-top:.3rem}
dl.kv{display:grid;grid-template-columns:max-content 1fr;gap:.2rem 1rem}dl.kv dt{font-weight:bold}dl.kv dd{margin:0;word-break:break-all}
code{font-size:.9em}
details{margin:.4rem 0}summary{cursor:pointer}
";

/// Renders `index.html`. `figures` are placed in their scene's section
/// (matched by scene name) in the order given; `downloads` are (relative
/// path, description) links listed under the summary.
pub fn render_index(
    reports: &[SceneReport],
    figures: &[FigureEntry<'_>],
    provenance: &Provenance,
    downloads: &[(String, String)],
) -> String {
    render_index_with(reports, figures, provenance, downloads, &[])
}

/// A section of the report besides the scenes, placed after the summary:
/// a title, paragraphs (plain text), figures and a table (plain-text
/// cells).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExtraSection {
    /// The section's anchor (`id`), e.g. `stitching`.
    pub id: String,
    /// Its heading.
    pub title: String,
    /// Sentences the page's verdict opens with, before the scenes' own
    /// (empty: none).
    pub lead: Vec<String>,
    /// Paragraphs before the table.
    pub paragraphs: Vec<String>,
    /// The table's column headings (no table when empty).
    pub header: Vec<String>,
    /// The table's rows.
    pub rows: Vec<Vec<String>>,
    /// Figures after the paragraphs, inlined, each also written as
    /// `figures/<stem>.svg` and `.png` by [`crate::write_report_with`].
    pub figures: Vec<Figure>,
    /// Scenes the 3D replay adds after the study's (its scene menu).
    pub replay: Vec<crate::replay3d::ExtraScene>,
}

/// An extra section; `lead_elsewhere`: its lead sentences already open the
/// page's verdict, else they open the section (a page with no scenes has
/// no verdict).
/// `svgs`: each of its figures' SVG, or why it cannot be drawn.
fn extra_section(
    h: &mut String,
    s: &ExtraSection,
    lead_elsewhere: bool,
    svgs: &[Result<String, String>],
) {
    let _ = writeln!(
        h,
        "<section id=\"{}\">\n<h2>{}</h2>",
        escape(&s.id),
        escape(&s.title)
    );
    if !lead_elsewhere {
        for l in &s.lead {
            let _ = writeln!(h, "<p class=\"lead\"><strong>{}</strong></p>", escape(l));
        }
    }
    for p in &s.paragraphs {
        let _ = writeln!(h, "<p>{}</p>", escape(p));
    }
    if !s.figures.is_empty() {
        h.push_str("<div class=\"figures\">\n");
        for (f, svg) in s.figures.iter().zip(svgs) {
            // A figure that cannot be drawn is named, not left out silently.
            let svg = match svg {
                Ok(svg) => inline_svg(svg, &f.title),
                Err(e) => format!("<p>{}</p>", escape(e)),
            };
            let _ = writeln!(
                h,
                "<figure id=\"{}\">\n{}\n<figcaption>{} <a href=\"figures/{}.svg\">SVG</a> &middot; <a href=\"figures/{}.png\">PNG</a></figcaption>\n</figure>",
                anchor("fig", &f.stem),
                svg,
                escape(&f.caption),
                escape(&f.stem),
                escape(&f.stem)
            );
        }
        h.push_str("</div>\n");
    }
    if !s.header.is_empty() {
        h.push_str("<table>\n<thead><tr>");
        for c in &s.header {
            let _ = write!(h, "<th>{}</th>", escape(c));
        }
        h.push_str("</tr></thead>\n<tbody>\n");
        for row in &s.rows {
            h.push_str("<tr>");
            for c in row {
                let _ = write!(h, "<td>{}</td>", escape(c));
            }
            h.push_str("</tr>\n");
        }
        h.push_str("</tbody></table>\n");
    }
    h.push_str("</section>\n");
}

/// [`render_index`] with `extra` sections after the summary (their
/// figures drawn here).
pub fn render_index_with(
    reports: &[SceneReport],
    figures: &[FigureEntry<'_>],
    provenance: &Provenance,
    downloads: &[(String, String)],
    extra: &[ExtraSection],
) -> String {
    let svgs: Vec<Vec<Result<String, String>>> = extra
        .iter()
        .map(|s| {
            s.figures
                .iter()
                .map(|f| f.to_svg().map_err(|e| e.to_string()))
                .collect()
        })
        .collect();
    render_page(reports, figures, provenance, downloads, extra, &svgs)
}

/// [`render_index_with`] with each extra section's figures already drawn
/// (`extra_svgs[section][figure]`), so that a report that writes the SVG
/// files draws each figure once.
pub(crate) fn render_page(
    reports: &[SceneReport],
    figures: &[FigureEntry<'_>],
    provenance: &Provenance,
    downloads: &[(String, String)],
    extra: &[ExtraSection],
    extra_svgs: &[Vec<Result<String, String>>],
) -> String {
    let mut h = String::new();
    let title = if provenance.title.is_empty() {
        "Reality-gap report"
    } else {
        provenance.title.as_str()
    };
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>{}</title>\n<style>{CSS}{}</style>\n</head>\n<body>\n",
        escape(title),
        crate::replay3d::CSS
    );
    let mode = reports.first().map_or(provenance.mode, |r| r.mode);
    let _ = writeln!(
        h,
        "<header>\n<h1>{}</h1>\n<p class=\"meta\">realitygap {} &middot; generated {} &middot; analysis mode <code>{}</code></p>\n</header>",
        escape(title),
        escape(&provenance.tool_version),
        escape(&provenance.generated_utc),
        escape(mode_name(mode)),
    );
    // Contents.
    let replay: Vec<crate::replay3d::ExtraScene> = extra
        .iter()
        .flat_map(|x| x.replay.iter().cloned())
        .collect();
    // Without scenes (a study of tossed objects alone) the page is the
    // extra sections: no verdict or table of scenes.
    let scenes = !reports.is_empty();
    h.push_str("<nav><ul>\n");
    if scenes {
        h.push_str("<li><a href=\"#verdict\">Verdict</a></li>\n<li><a href=\"#summary\">Accumulated error</a></li>\n");
    }
    if scenes || !replay.is_empty() {
        h.push_str("<li><a href=\"#replay\">3D replay</a></li>\n");
    }
    for x in extra {
        let _ = writeln!(
            h,
            "<li><a href=\"#{}\">{}</a></li>",
            escape(&x.id),
            escape(&x.title)
        );
    }
    for r in reports {
        let _ = writeln!(
            h,
            "<li><a href=\"#{}\">{}</a></li>",
            anchor("scene", &r.scene),
            escape(&r.scene)
        );
    }
    h.push_str("<li><a href=\"#provenance\">Provenance</a></li>\n</ul></nav>\n");

    if scenes {
        let lead: Vec<&str> = extra
            .iter()
            .flat_map(|x| x.lead.iter().map(String::as_str))
            .collect();
        verdict_section(&mut h, reports, &lead);
        summary(&mut h, reports, downloads);
    } else {
        files_note(&mut h, downloads);
    }
    if scenes || !replay.is_empty() {
        h.push_str(&crate::replay3d::section(
            reports,
            &crate::figures::SourceStyles::for_reports(reports),
            &replay,
        ));
    }
    for (x, svgs) in extra.iter().zip(extra_svgs) {
        extra_section(&mut h, x, scenes, svgs);
    }
    for r in reports {
        let figs: Vec<&FigureEntry<'_>> = figures
            .iter()
            .filter(|f| f.figure.scene == r.scene)
            .collect();
        scene_section(&mut h, r, &figs);
    }
    provenance_section(&mut h, provenance);
    h.push_str("</body>\n</html>\n");
    h
}

/// The verdict in sentences, first in the page.
fn verdict_section(h: &mut String, reports: &[SceneReport], lead: &[&str]) {
    let v = crate::verdict::verdict(reports);
    h.push_str("<section id=\"verdict\">\n<h2>Verdict</h2>\n");
    for line in lead
        .iter()
        .copied()
        .chain(v.overall.iter().map(String::as_str))
    {
        let _ = writeln!(h, "<p class=\"verdict\">{}</p>", escape(line));
    }
    h.push_str("<ul>\n");
    for (scene, lines) in &v.scenes {
        let _ = writeln!(
            h,
            "<li><a href=\"#{}\"><strong>{}</strong></a>: {}</li>",
            anchor("scene", scene),
            escape(scene),
            escape(&lines.join(" "))
        );
    }
    h.push_str("</ul>\n<p class=\"note\">Generated from the numbers below: intervals are 95 % bootstrap intervals over the real runs; the physics-free model is the commanded motion with perfect tracking, through forward kinematics.</p>\n</section>\n");
}

fn mode_name(m: realitygap_analysis::AnalysisMode) -> &'static str {
    match m {
        realitygap_analysis::AnalysisMode::Default => "default",
        realitygap_analysis::AnalysisMode::Study => "study",
    }
}

/// Index of the smallest finite value.
fn best_index(values: &[Option<f64>]) -> Option<usize> {
    values
        .iter()
        .enumerate()
        .filter_map(|(i, v)| v.filter(|v| v.is_finite()).map(|v| (i, v)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

fn num_cell(h: &mut String, text: &str, best: bool) {
    let _ = write!(
        h,
        "<td class=\"num{}\">{}</td>",
        if best { " best" } else { "" },
        escape(text)
    );
}

fn summary(h: &mut String, reports: &[SceneReport], downloads: &[(String, String)]) {
    h.push_str("<section id=\"summary\">\n<h2>Accumulated error</h2>\n");
    let reference: Vec<String> = {
        let mut v: Vec<String> = reports.iter().map(|r| r.reference.source.clone()).collect();
        v.dedup();
        v
    };
    let _ = writeln!(
        h,
        "<p>Per scene, the sum over control steps of the distance between a source's mean wrist position and the mean wrist position of the reference (<strong>{}</strong>) at the same step, in metres. Smaller is closer; the best per column is highlighted.{}</p>",
        escape(&reference.join(", ")),
        reports.iter().find_map(|r| r.bootstrap).map_or(String::new(), |b| format!(
            " In brackets: the {:.0} % bootstrap interval over the real runs (and a source's own runs where they differ), {} resamples, seed {}.",
            b.level * 100.0,
            b.resamples,
            b.seed
        ))
    );
    let names = source_names(reports);
    h.push_str("<table id=\"accumulated-error\">\n<thead><tr><th>Source</th>");
    for r in reports {
        let _ = write!(h, "<th>{}</th>", escape(&r.scene));
    }
    h.push_str("<th>Total</th></tr></thead>\n<tbody>\n");
    fn cell<'r>(r: &'r SceneReport, n: &str) -> Option<&'r SourceSummary> {
        r.sources.iter().find(|s| s.source == n)
    }
    let best_per_scene: Vec<Option<usize>> = reports
        .iter()
        .map(|r| {
            best_index(
                &names
                    .iter()
                    .map(|n| cell(r, n).and_then(|s| s.accumulated_error_m))
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let totals: Vec<Option<f64>> = names.iter().map(|n| total(reports, n)).collect();
    let best_total = best_index(&totals);
    for (i, n) in names.iter().enumerate() {
        let _ = write!(h, "<tr><th scope=\"row\">{}</th>", escape(n));
        for (r, best) in reports.iter().zip(&best_per_scene) {
            let s = cell(r, n);
            let mut text = fmt_m(s.and_then(|s| s.accumulated_error_m));
            if let Some(i) = s.and_then(|s| s.accumulated_error_interval_m) {
                let _ = write!(text, " {}", fmt_interval(Some(i)));
            }
            if let Some(s) = s {
                let excluded = s.runs_flagged.iter().filter(|f| f.excluded).count();
                if excluded > 0 {
                    let _ = write!(text, " ({excluded} of {} runs left out)", s.runs_total);
                }
            }
            num_cell(h, &text, *best == Some(i));
        }
        let mut text = fmt_m(totals[i]);
        if let Some(iv) = total_interval(reports, n) {
            let _ = write!(text, " {}", fmt_interval(Some(iv)));
        }
        num_cell(h, &text, best_total == Some(i));
        h.push_str("</tr>\n");
    }
    h.push_str("</tbody>\n</table>\n");
    h.push_str("<p><strong>Closest per scene:</strong> ");
    let closest: Vec<String> = reports
        .iter()
        .map(|r| format!("{}: {}", escape(&r.scene), escape(&r.verdict())))
        .collect();
    h.push_str(&closest.join("; "));
    h.push_str(".</p>\n");
    if let Some(text) = describe_registration(reports) {
        let _ = writeln!(
            h,
            "<p id=\"registration\"><strong>Registration:</strong> {}.</p>",
            escape(&text)
        );
    }
    if let Some(runs) = reports.iter().find_map(|r| r.runs.as_ref()) {
        let _ = writeln!(
            h,
            "<p id=\"runs\"><strong>Real runs:</strong> {}.</p>",
            escape(&runs.selection)
        );
    }
    files_note(h, downloads);
    h.push_str("</section>\n");
}

/// The line of links to the report's files (none when `downloads` is
/// empty).
fn files_note(h: &mut String, downloads: &[(String, String)]) {
    if !downloads.is_empty() {
        h.push_str("<p class=\"note\">Files: ");
        let links: Vec<String> = downloads
            .iter()
            .map(|(href, what)| format!("<a href=\"{}\">{}</a>", escape(href), escape(what)))
            .collect();
        h.push_str(&links.join(" &middot; "));
        h.push_str("</p>\n");
    }
}

fn phase_label(r: &SceneReport, i: usize) -> String {
    let start = r.phases_s[i];
    let end = r
        .phases_s
        .get(i + 1)
        .copied()
        .unwrap_or(r.steps as f64 * r.control_period_s);
    format!(
        "phase {} ({}\u{2013}{} s)",
        i + 1,
        trim_num(start),
        trim_num(end)
    )
}

fn trim_num(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => String::new(),
    }
}

/// The scene's real runs (fitted on, scored on) and the registration's
/// residuals there.
fn runs_and_registration(h: &mut String, r: &SceneReport) {
    if let Some(runs) = &r.runs {
        let _ = writeln!(
            h,
            "<p>Real runs fitted on: {}. Scored on: {}.</p>",
            escape(&runs.fit.join(", ")),
            escape(&runs.scored.join(", "))
        );
    }
    if let Some(g) = &r.registration {
        let _ = writeln!(
            h,
            "<p>Registration residual at this scene's {} settled steps: {} mm on the fit runs, {} mm on the scored runs.</p>",
            g.settled_steps,
            g.residual_fit_rms_m.map_or("n/a".into(), |v| format!("{:.1}", v * 1000.0)),
            g.residual_scored_rms_m.map_or("n/a".into(), |v| format!("{:.1}", v * 1000.0))
        );
    }
}

fn scene_section(h: &mut String, r: &SceneReport, figures: &[&FigureEntry<'_>]) {
    let _ = writeln!(
        h,
        "<section id=\"{}\" class=\"scene\">\n<h2>{}</h2>",
        anchor("scene", &r.scene),
        escape(&r.scene)
    );
    let reference = &r.reference;
    let _ = write!(
        h,
        "<p>Reference: <strong>{}</strong> ({} of {} runs used). {} control steps of {} s",
        escape(&reference.source),
        reference.runs_used,
        reference.runs_total,
        r.steps,
        trim_num(r.control_period_s)
    );
    if let Some(g) = r.goal_m {
        let _ = write!(h, "; goal ({:.4}, {:.4}, {:.4}) m", g[0], g[1], g[2]);
    }
    let _ = writeln!(h, ". {}.</p>", escape(&capitalise(&r.verdict())));
    runs_and_registration(h, r);

    // Closest per phase.
    if !r.phases_s.is_empty() {
        h.push_str("<h3>Closest per phase</h3>\n<p>Accumulated error per phase of the schedule (m); the closest source per phase is highlighted.</p>\n");
        let closest = r.closest_per_phase();
        h.push_str("<table class=\"phases\">\n<thead><tr><th>Source</th>");
        for i in 0..r.phases_s.len() {
            let _ = write!(h, "<th>{}</th>", escape(&phase_label(r, i)));
        }
        h.push_str("</tr></thead>\n<tbody>\n");
        for s in &r.sources {
            let _ = write!(h, "<tr><th scope=\"row\">{}</th>", escape(&s.source));
            for (i, best) in closest.iter().enumerate() {
                let v = if s.accumulated_error_m.is_some() {
                    s.phase_errors_m.get(i).copied()
                } else {
                    None
                };
                num_cell(h, &fmt_m(v), best.as_deref() == Some(s.source.as_str()));
            }
            h.push_str("</tr>\n");
        }
        h.push_str("</tbody>\n</table>\n<p>");
        let names: Vec<String> = closest
            .iter()
            .enumerate()
            .map(|(i, c)| {
                format!(
                    "{}: <strong>{}</strong>",
                    escape(&phase_label(r, i)),
                    c.as_deref().map_or("none".into(), escape)
                )
            })
            .collect();
        h.push_str(&names.join("; "));
        h.push_str(".</p>\n");
    }

    // Figures.
    if !figures.is_empty() {
        h.push_str("<h3>Figures</h3>\n<div class=\"figures\">\n");
        for f in figures {
            let _ = writeln!(
                h,
                "<figure id=\"{}\">\n{}\n<figcaption>{} <a href=\"{}\">SVG</a> &middot; <a href=\"{}\">PNG</a></figcaption>\n</figure>",
                anchor("fig", &f.figure.stem),
                inline_svg(f.svg, &f.figure.title),
                escape(&f.figure.caption),
                escape(f.svg_file),
                escape(f.png_file)
            );
        }
        h.push_str("</div>\n");
    }

    measures_table(h, r);
    if std::iter::once(reference)
        .chain(&r.sources)
        .any(|s| s.cube.is_some())
    {
        cube_table(h, r);
    }
    health_section(h, r);
    alignment_section(h, r.alignment.as_ref());
    h.push_str("</section>\n");
}

/// Fixed decimals without a minus sign on values that round to zero.
fn fixed(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

fn opt_num(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(v) if v.is_finite() => fixed(v, decimals),
        Some(v) => format!("{v}"),
        None => "n/a".into(),
    }
}

fn measures_table(h: &mut String, r: &SceneReport) {
    h.push_str("<h3>Measures</h3>\n<table class=\"measures\">\n<thead><tr><th>Source</th><th>Kind</th><th>Runs used</th><th>Accumulated error (m)</th><th>95 % interval (m)</th><th>Lag behind kinematic reference (s)</th><th>Mean error (m)</th><th>Max error (m)</th><th>Final error (m)</th><th>Orientation error (deg)</th><th>Final distance to goal (m)</th><th>Converged (s)</th><th>Overshoot (m)</th><th>Goal crossings</th></tr></thead>\n<tbody>\n");
    let rows: Vec<&SourceSummary> = std::iter::once(&r.reference).chain(&r.sources).collect();
    let best = best_index(
        &rows
            .iter()
            .map(|s| s.accumulated_error_m)
            .collect::<Vec<_>>(),
    );
    for (i, s) in rows.iter().enumerate() {
        // Without usable runs the goal measures of an empty mean say nothing.
        let g = s.goal.as_ref().filter(|_| s.runs_used > 0);
        let _ = write!(
            h,
            "<tr{}><th scope=\"row\">{}</th><td>{}</td>",
            if i == 0 { " class=\"reference\"" } else { "" },
            escape(&s.source),
            escape(if i == 0 { "reference" } else { &s.kind })
        );
        num_cell(h, &format!("{} of {}", s.runs_used, s.runs_total), false);
        num_cell(h, &fmt_m(s.accumulated_error_m), best == Some(i));
        num_cell(h, &fmt_interval(s.accumulated_error_interval_m), false);
        num_cell(h, &opt_num(s.lag_s, 2), false);
        num_cell(h, &fmt_m(s.mean_error_m), false);
        num_cell(h, &fmt_m(s.max_error_m), false);
        num_cell(h, &fmt_m(s.final_error_m), false);
        num_cell(h, &opt_num(s.orientation_error_deg, 1), false);
        num_cell(h, &fmt_m(g.and_then(|g| g.final_distance_m)), false);
        num_cell(
            h,
            &g.map_or("n/a".into(), |g| {
                g.convergence_time_s
                    .map_or("never".into(), |t| format!("{t:.2}"))
            }),
            false,
        );
        num_cell(h, &fmt_m(g.and_then(|g| g.overshoot_m)), false);
        num_cell(
            h,
            &g.map_or("n/a".into(), |g| g.goal_crossings.to_string()),
            false,
        );
        h.push_str("</tr>\n");
    }
    h.push_str("</tbody>\n</table>\n");
    if let Some(g) = r
        .reference
        .goal
        .as_ref()
        .or_else(|| r.sources.iter().find_map(|s| s.goal.as_ref()))
    {
        let _ = writeln!(
            h,
            "<p class=\"note\">Errors are distances to the reference's mean wrist position. Lag: the time shift that best aligns a source's mean wrist motion with the scene's kinematic reference; reported only, never used to shift a source. Converged: the time from which the mean wrist stays within {} m of the goal. Orientation error: mean angle between the wrist's rotation since the start and the reference's.</p>",
            trim_num(g.tolerance_m)
        );
    }
}

fn vec3(v: Option<[f64; 3]>, decimals: usize) -> String {
    v.map_or("n/a".into(), |v| {
        format!(
            "({}, {}, {})",
            fixed(v[0], decimals),
            fixed(v[1], decimals),
            fixed(v[2], decimals)
        )
    })
}

fn cube_table(h: &mut String, r: &SceneReport) {
    h.push_str("<h3>Cube</h3>\n<table class=\"cube\">\n<thead><tr><th>Source</th><th>Final position (m)</th><th>Final minus nominal start (m)</th><th>Final displacement (m)</th><th>Roll, pitch, yaw change (deg)</th><th>Largest tilt (deg)</th><th>Contact from (s)</th></tr></thead>\n<tbody>\n");
    for (i, s) in std::iter::once(&r.reference).chain(&r.sources).enumerate() {
        let _ = write!(
            h,
            "<tr{}><th scope=\"row\">{}</th>",
            if i == 0 { " class=\"reference\"" } else { "" },
            escape(&s.source)
        );
        match &s.cube {
            Some(c) => {
                num_cell(h, &vec3(Some(c.final_position_m), 3), false);
                num_cell(h, &vec3(c.final_offset_from_nominal_m, 3), false);
                num_cell(h, &fmt_m(Some(c.final_displacement_m)), false);
                num_cell(h, &vec3(Some(c.rpy_change_deg), 1), false);
                num_cell(h, &opt_num(Some(c.max_tilt_deg), 1), false);
                num_cell(
                    h,
                    &c.contact_onset_s
                        .map_or("none".into(), |t| format!("{t:.2}")),
                    false,
                );
            }
            None => {
                let _ = write!(h, "<td colspan=\"6\">no cube data</td>");
            }
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</tbody>\n</table>\n");
}

fn health_section(h: &mut String, r: &SceneReport) {
    h.push_str("<h3>Run health</h3>\n");
    let sources: Vec<&SourceSummary> = std::iter::once(&r.reference).chain(&r.sources).collect();
    let flagged: usize = sources.iter().map(|s| s.runs_flagged.len()).sum();
    if flagged == 0 {
        h.push_str("<p>No run was flagged.</p>\n");
        return;
    }
    h.push_str("<ul>\n");
    for s in sources.iter().filter(|s| !s.runs_flagged.is_empty()) {
        let excluded = s.runs_flagged.iter().filter(|f| f.excluded).count();
        let mut counts: Vec<(&str, usize)> = Vec::new();
        for f in &s.runs_flagged {
            for x in &f.flags {
                match counts.iter_mut().find(|c| c.0 == x.name()) {
                    Some(c) => c.1 += 1,
                    None => counts.push((x.name(), 1)),
                }
            }
        }
        let what: Vec<String> = counts
            .iter()
            .map(|(n, k)| format!("{} &times;{k}", escape(&n.replace('_', " "))))
            .collect();
        let _ = writeln!(
            h,
            "<li><strong>{}</strong>: {} of {} runs flagged ({}); {}</li>",
            escape(&s.source),
            s.runs_flagged.len(),
            s.runs_total,
            what.join(", "),
            if excluded > 0 {
                format!("<span class=\"flag-excluded\">{excluded} left out of the means</span>")
            } else {
                "all kept in the means".to_string()
            }
        );
    }
    h.push_str("</ul>\n");
    let _ = writeln!(
        h,
        "<details><summary>Every flagged run ({flagged})</summary>"
    );
    h.push_str("<table class=\"health\">\n<thead><tr><th>Source</th><th>Run</th><th>Status</th><th>Why</th></tr></thead>\n<tbody>\n");
    for s in &sources {
        for f in &s.runs_flagged {
            let why: Vec<String> = f.flags.iter().map(|x| escape(&x.describe())).collect();
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(&s.source),
                escape(&f.run),
                if f.excluded {
                    "<span class=\"flag-excluded\">left out</span>"
                } else {
                    "kept"
                },
                why.join("; ")
            );
        }
    }
    h.push_str("</tbody>\n</table>\n</details>\n");
}

fn alignment_section(h: &mut String, a: Option<&AlignmentReport>) {
    let Some(a) = a else { return };
    h.push_str("<h3>Alignment of the reference</h3>\n");
    let _ = writeln!(h, "<p>Method: {}.", escape(&a.method));
    let starts: Vec<usize> = a.runs.iter().map(|r| r.start.start_frame).collect();
    let leads: Vec<i64> = a
        .runs
        .iter()
        .filter_map(|r| {
            r.start
                .onset_frame
                .map(|o| o as i64 - r.start.start_frame as i64)
        })
        .collect();
    if let (Some(lo), Some(hi)) = (starts.iter().min(), starts.iter().max()) {
        let _ = write!(h, " Start frames {lo}\u{2013}{hi}");
        if let (Some(l0), Some(l1)) = (leads.iter().min(), leads.iter().max()) {
            let _ = write!(h, "; onset minus start {l0}\u{2013}{l1} frames");
        }
        h.push('.');
    }
    h.push_str("</p>\n");
    if !a.failed.is_empty() {
        h.push_str("<p>Not aligned:</p>\n<ul>\n");
        for (run, why) in &a.failed {
            let _ = writeln!(h, "<li>{}: {}</li>", escape(run), escape(why));
        }
        h.push_str("</ul>\n");
    }
    if a.runs.is_empty() {
        return;
    }
    let _ = writeln!(
        h,
        "<details><summary>Start of every run ({})</summary>",
        a.runs.len()
    );
    h.push_str("<table class=\"alignment\">\n<thead><tr><th>Run</th><th>Start frame</th><th>Start (s)</th><th>Motion onset frame</th><th>Onset minus start (frames)</th><th>Steps available</th></tr></thead>\n<tbody>\n");
    for r in &a.runs {
        let _ = write!(h, "<tr><td>{}</td>", escape(&r.run));
        num_cell(h, &r.start.start_frame.to_string(), false);
        num_cell(h, &format!("{:.2}", r.start.start_s), false);
        num_cell(
            h,
            &r.start.onset_frame.map_or("none".into(), |o| o.to_string()),
            false,
        );
        num_cell(
            h,
            &r.start.onset_frame.map_or("n/a".into(), |o| {
                (o as i64 - r.start.start_frame as i64).to_string()
            }),
            false,
        );
        num_cell(h, &r.steps_available.to_string(), false);
        h.push_str("</tr>\n");
    }
    h.push_str("</tbody>\n</table>\n</details>\n");
}

fn provenance_section(h: &mut String, p: &Provenance) {
    h.push_str("<section id=\"provenance\">\n<h2>Provenance</h2>\n<dl class=\"kv\">\n");
    let mut kv: Vec<(String, String)> = vec![
        ("Tool".into(), format!("realitygap {}", p.tool_version)),
        ("Generated (UTC)".into(), p.generated_utc.clone()),
        ("Command line".into(), p.command_line.clone()),
        ("Analysis mode".into(), mode_name(p.mode).into()),
    ];
    if let Some(s) = &p.study {
        kv.push(("Study file".into(), s.clone()));
    }
    if let Some(s) = &p.data_dir {
        kv.push(("Data folder".into(), s.clone()));
    }
    if let Some(s) = &p.results_dir {
        kv.push(("Results folder".into(), s.clone()));
    }
    kv.extend(p.details.iter().cloned());
    for (k, v) in &kv {
        let _ = writeln!(
            h,
            "<dt>{}</dt><dd><code>{}</code></dd>",
            escape(k),
            escape(v)
        );
    }
    h.push_str("</dl>\n");
    if !p.sources.is_empty() {
        h.push_str("<h3>Sources</h3>\n<table class=\"sources\">\n<thead><tr><th>Source</th><th>Details</th></tr></thead>\n<tbody>\n");
        for s in &p.sources {
            let _ = write!(h, "<tr><th scope=\"row\">{}</th><td>", escape(&s.name));
            if s.details.is_empty() {
                h.push_str("none recorded");
            } else {
                h.push_str("<dl class=\"kv\">");
                for (k, v) in &s.details {
                    let _ = write!(h, "<dt>{}</dt><dd>{}</dd>", escape(k), escape(v));
                }
                h.push_str("</dl>");
            }
            h.push_str("</td></tr>\n");
        }
        h.push_str("</tbody>\n</table>\n");
    }
    h.push_str("</section>\n");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::{build_figure, FigureKind, SourceStyles};
    use realitygap_analysis::testing as testdata;

    fn page() -> (String, usize) {
        let report = testdata::scene();
        let reports = [report];
        let styles = SourceStyles::for_reports(&reports);
        let figs: Vec<_> = [FigureKind::GoalDistance, FigureKind::ReferenceDistance]
            .into_iter()
            .map(|k| build_figure(&reports[0], k, &styles))
            .collect();
        let svgs: Vec<String> = figs.iter().map(|f| f.to_svg().unwrap()).collect();
        let names: Vec<(String, String)> = figs
            .iter()
            .map(|f| {
                (
                    format!("figures/{}.svg", f.stem),
                    format!("figures/{}.png", f.stem),
                )
            })
            .collect();
        let entries: Vec<FigureEntry<'_>> = figs
            .iter()
            .zip(&svgs)
            .zip(&names)
            .map(|((figure, svg), (s, p))| FigureEntry {
                figure,
                svg,
                svg_file: s,
                png_file: p,
            })
            .collect();
        let mut prov = Provenance::new("A <b>study</b> & co");
        prov.command_line = "realitygap report 'x<y>.toml'".into();
        prov.sources
            .push(crate::SourceProvenance::new("Alpha <&>").with("engine", "alpha \"1.0\""));
        (
            render_index(
                &reports,
                &entries,
                &prov,
                &[("table.md".into(), "table".into())],
            ),
            figs.len(),
        )
    }

    /// The `<tbody>` of the element with this id.
    fn tbody<'a>(html: &'a str, id: &str) -> &'a str {
        let start = html.find(&format!("id=\"{id}\"")).unwrap();
        let rest = &html[start..];
        let body = &rest[rest.find("<tbody>").unwrap()..];
        &body[..body.find("</tbody>").unwrap()]
    }

    /// The element `<table ... id="{id}" ...>` .. `</table>`, or the
    /// `class` one when `id` is not found.
    fn table<'a>(html: &'a str, marker: &str) -> &'a str {
        let at = html.find(marker).unwrap();
        let start = html[..at].rfind("<table").unwrap();
        let end = at + html[at..].find("</table>").unwrap() + "</table>".len();
        &html[start..end]
    }

    /// Snapshots of the HTML tables (`tests/snapshots/`; rerun with
    /// `UPDATE_SNAPSHOTS=1` after an intended change).
    #[test]
    fn html_table_snapshots() {
        let (html, _) = page();
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/snapshots");
        for (name, marker) in [
            ("accumulated-error.html", "id=\"accumulated-error\""),
            ("phases.html", "class=\"phases\""),
            ("measures.html", "class=\"measures\""),
            ("health.html", "class=\"health\""),
            ("alignment.html", "class=\"alignment\""),
        ] {
            testdata::assert_snapshot(&dir, name, &format!("{}\n", table(&html, marker)));
        }
    }

    #[test]
    fn everything_is_escaped() {
        assert_eq!(
            (fixed(-0.0001, 3), fixed(-0.001, 3), fixed(-0.0, 1)),
            ("0.000".into(), "-0.001".into(), "0.0".into())
        );
        let (html, _) = page();
        assert!(html.contains("<title>A &lt;b&gt;study&lt;/b&gt; &amp; co</title>"));
        assert!(html.contains("Alpha &lt;&amp;&gt;"));
        assert!(!html.contains("Alpha <&>"));
        assert!(!html.contains("<b>study"));
        assert!(html.contains("&#39;x&lt;y&gt;.toml&#39;"));
        assert!(html.contains("alpha &quot;1.0&quot;"));
        assert_eq!(
            escape("<a href='x'>&\"</a>"),
            "&lt;a href=&#39;x&#39;&gt;&amp;&quot;&lt;/a&gt;"
        );
    }

    #[test]
    fn the_table_has_a_row_per_source_and_highlights_the_best() {
        let (html, _) = page();
        let body = tbody(&html, "accumulated-error");
        assert_eq!(body.matches("<tr>").count(), 3);
        // Alpha (1.0 m) is best in the scene and in total; Dead has no value.
        let alpha_row = body.lines().find(|l| l.contains("Alpha")).unwrap();
        assert_eq!(
            alpha_row.matches("class=\"num best\"").count(),
            2,
            "{alpha_row}"
        );
        let dead_row = body.lines().find(|l| l.contains("Dead")).unwrap();
        assert!(
            dead_row.contains("n/a (20 of 20 runs left out)"),
            "{dead_row}"
        );
        // Per phase, Alpha is closest in both.
        assert!(html.contains("phase 1 (0\u{2013}2.5 s): <strong>Alpha &lt;&amp;&gt;</strong>"));
        // Intervals next to the values, the verdict and the registration.
        assert!(alpha_row.contains("1.000 [0.900, 1.100]"), "{alpha_row}");
        assert!(html.contains(
            "closest source: Alpha &lt;&amp;&gt; (closer than Beta with probability 1.000"
        ));
        assert!(html.contains("translation (1.0, -2.0, 9.0) mm"));
        assert!(html.contains("estimated &lt;test&gt;"));
        assert_eq!(tbody(&html, "scene-scene-test").matches("<tr>").count(), 3);
    }

    #[test]
    fn figures_are_inline_and_nothing_is_fetched() {
        let (html, n) = page();
        assert_eq!(html.matches("<svg ").count(), n);
        assert_eq!(html.matches("</svg>").count(), n);
        assert_eq!(html.matches("<figure ").count(), n);
        assert!(html.contains("id=\"fig-scene-test-goal-distance\""));
        assert!(html.contains("aria-label=\"Wrist distance to the goal\""));
        assert!(
            !html.contains("http://") && !html.contains("https://"),
            "a network reference"
        );
        // The only scripts are the 3D replay's data and renderer, inline.
        assert_eq!(html.matches("<script").count(), 2);
        assert!(!html.contains("<script src") && !html.contains("<link") && !html.contains("<img"));
        assert!(!html.contains("xmlns"));
    }

    #[test]
    fn health_alignment_and_provenance_are_listed() {
        let (html, _) = page();
        assert!(html.contains("<strong>Dead</strong>: 20 of 20 runs flagged (diverged &times;20)"));
        assert!(html.contains("20 left out of the means"));
        assert!(html.contains("diverged at sample 3 (t = 0.15 s), positions up to 1.000e17 m"));
        assert!(html.contains("Method: fixed start frame 39."));
        assert!(html.contains("Start frames 39\u{2013}39; onset minus start 93\u{2013}93 frames."));
        assert!(html.contains("<dt>Command line</dt>"));
        assert!(html.contains(&format!("realitygap {}", realitygap_core::TOOL_VERSION)));
    }

    #[test]
    fn extra_sections_follow_the_summary_escaped_and_in_the_contents() {
        let reports = [testdata::scene()];
        let extra = ExtraSection {
            id: "stitching".into(),
            title: "Stitching <engines>".into(),
            lead: Vec::new(),
            paragraphs: vec!["a>b & c".into()],
            header: vec!["Source".into(), "Error".into()],
            rows: vec![vec!["stitched ode>mujoco".into(), "1.0".into()]],
            figures: Vec::new(),
            replay: Vec::new(),
        };
        let html = render_index_with(&reports, &[], &Provenance::new("t"), &[], &[extra]);
        assert!(html.contains("<li><a href=\"#stitching\">Stitching &lt;engines&gt;</a></li>"));
        assert!(html.contains("<h2>Stitching &lt;engines&gt;</h2>\n<p>a&gt;b &amp; c</p>"));
        assert!(html.contains("<tr><td>stitched ode&gt;mujoco</td><td>1.0</td></tr>"));
        let (summary, section) = (html.find("id=\"summary\""), html.find("id=\"stitching\""));
        assert!(summary < section, "the section follows the summary");
    }

    /// A lead opens the verdict on a page with scenes, and its own section
    /// on a page without (no verdict there): shown once either way.
    #[test]
    fn a_sections_lead_is_shown_once_with_or_without_scenes() {
        let extra = ExtraSection {
            id: "crossval".into(),
            title: "Does physics pay?".into(),
            lead: vec!["No tuned engine beats <it>.".into()],
            paragraphs: vec!["Folds.".into()],
            header: Vec::new(),
            rows: Vec::new(),
            figures: Vec::new(),
            replay: Vec::new(),
        };
        let escaped = "No tuned engine beats &lt;it&gt;.";
        let with = render_index_with(
            &[testdata::scene()],
            &[],
            &Provenance::new("t"),
            &[],
            std::slice::from_ref(&extra),
        );
        assert_eq!(with.matches(escaped).count(), 1, "{with}");
        assert!(with.find(escaped) < with.find("id=\"crossval\""));
        let without = render_index_with(&[], &[], &Provenance::new("t"), &[], &[extra]);
        assert_eq!(without.matches(escaped).count(), 1);
        assert!(without.contains(&format!(
            "<h2>Does physics pay?</h2>\n<p class=\"lead\"><strong>{escaped}</strong></p>\n<p>Folds.</p>"
        )));
    }
}
