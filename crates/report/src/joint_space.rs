//! The report of a replay of a robot's own recordings (`realitygap
//! replay`): the joint-space table, and per joint a figure of one
//! episode's recorded angle against each source's (every engine, and the
//! physics-free model), in one self-contained `index.html` with the
//! figures inlined as SVG (and written beside it as SVG and PNG).

use crate::figures::{file_stem, LineStyle};
use crate::html::{escape, inline_svg};
use crate::render::{Draw, FAMILY};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Figure size, px.
const WIDTH_PX: u32 = 760;
/// Figure height, px.
const HEIGHT_PX: u32 = 300;

/// One source's angle of one joint over one episode.
#[derive(Debug, Clone, PartialEq)]
pub struct AngleSeries {
    /// The source (`recorded`, an engine, `kinematic`).
    pub source: String,
    /// (time s, angle deg) per sample.
    pub points: Vec<(f64, f64)>,
}

/// One joint's figure: the recorded angle (first) and each source's.
#[derive(Debug, Clone, PartialEq)]
pub struct JointFigure {
    /// The joint's name.
    pub joint: String,
    /// The episode shown.
    pub episode: String,
    /// The series, the recording first.
    pub series: Vec<AngleSeries>,
}

impl JointFigure {
    /// The figure's file stem.
    pub fn stem(&self) -> String {
        file_stem(&format!("{}_{}", self.episode, self.joint))
    }

    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let mut x = (f64::INFINITY, f64::NEG_INFINITY);
        let mut y = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &self.series {
            for &(t, v) in &s.points {
                if t.is_finite() && v.is_finite() {
                    x = (x.0.min(t), x.1.max(t));
                    y = (y.0.min(v), y.1.max(v));
                }
            }
        }
        if x.0.partial_cmp(&x.1) != Some(std::cmp::Ordering::Less) {
            x = (0.0, 1.0);
        }
        if y.0.partial_cmp(&y.1) != Some(std::cmp::Ordering::Less) {
            y = (y.0.min(0.0) - 1.0, y.1.max(0.0) + 1.0);
        }
        let pad = 0.05 * (y.1 - y.0);
        (x, (y.0 - pad, y.1 + pad))
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> Result<String, String> {
        crate::render::svg(self, WIDTH_PX, HEIGHT_PX)
    }

    /// The figure as PNG bytes.
    pub fn to_png(&self) -> Result<Vec<u8>, String> {
        crate::render::png(self, WIDTH_PX, HEIGHT_PX)
    }
}

impl Draw for JointFigure {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let ((x0, x1), (y0, y1)) = self.ranges();
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!("{}: {} (deg)", self.episode, self.joint),
                (FAMILY, 15),
            )
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc("angle (deg)")
            .label_style((FAMILY, 11))
            .draw()
            .map_err(e)?;
        for (i, s) in self.series.iter().enumerate() {
            let style = if i == 0 {
                RGBColor(0, 0, 0).stroke_width(3)
            } else {
                let (r, g, b) = LineStyle::for_source(i - 1).rgb;
                RGBColor(r, g, b).stroke_width(1)
            };
            let points: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(points, style))
                .map_err(e)?
                .label(s.source.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FAMILY, 11))
            .draw()
            .map_err(e)?;
        Ok(())
    }
}

/// Writes `OUT/index.html` with `table_md` (the joint-space table, as
/// Markdown) and the figures, each also as `OUT/<stem>.svg` and `.png`.
/// `title` heads the page; `notes` are paragraphs under it.
pub fn write_joint_space_report(
    out: &Path,
    title: &str,
    notes: &[String],
    table_md: &str,
    figures: &[JointFigure],
) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("creating {}: {e}", out.display()))?;
    let mut files = Vec::new();
    let mut html = String::new();
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\
         <style>body{{font-family:system-ui,sans-serif;max-width:1100px;margin:0 auto;padding:1rem}}\
         table{{border-collapse:collapse;font-size:.9rem;display:block;overflow-x:auto}}\
         th,td{{border:1px solid #ccc;padding:.2rem .5rem}}td{{text-align:right}}\
         figure{{margin:0 0 1rem}}svg{{max-width:100%;height:auto}}</style></head><body>\n<h1>{t}</h1>\n",
        t = escape(title)
    );
    for n in notes {
        let _ = writeln!(html, "<p>{}</p>", escape(n));
    }
    html.push_str("<h2>Joint space</h2>\n<table>\n");
    for (i, line) in table_md.lines().enumerate() {
        if i == 1 || !line.starts_with('|') {
            continue;
        }
        let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
        let tag = if i == 0 { "th" } else { "td" };
        html.push_str("<tr>");
        for (k, c) in cells.iter().enumerate() {
            let tag = if k == 0 && i > 0 { "th" } else { tag };
            let _ = write!(html, "<{tag}>{}</{tag}>", escape(c));
        }
        html.push_str("</tr>\n");
    }
    html.push_str("</table>\n<h2>Joint angles</h2>\n");
    for f in figures {
        let svg = f
            .to_svg()
            .map_err(|m| format!("figure {}: {m}", f.stem()))?;
        let png = f
            .to_png()
            .map_err(|m| format!("figure {}: {m}", f.stem()))?;
        for (ext, bytes) in [("svg", svg.as_bytes()), ("png", png.as_slice())] {
            let path = out.join(format!("{}.{ext}", f.stem()));
            std::fs::write(&path, bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
            files.push(path);
        }
        let _ = writeln!(
            html,
            "<figure>{}<figcaption>{}: the recorded angle (black) and each source's.</figcaption></figure>",
            inline_svg(&svg, &format!("{} {}", f.episode, f.joint)),
            escape(&f.joint)
        );
    }
    html.push_str("</body></html>\n");
    let index = out.join("index.html");
    std::fs::write(&index, html).map_err(|e| format!("writing {}: {e}", index.display()))?;
    files.push(index);
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_page_with_the_table_and_a_figure_per_joint() {
        let dir = std::env::temp_dir().join(format!("rg-js-report-{}", std::process::id()));
        let series = |name: &str, k: f64| AngleSeries {
            source: name.into(),
            points: (0..50)
                .map(|i| (i as f64 * 0.1, (i as f64 * 0.1 * k).sin()))
                .collect(),
        };
        let figures = vec![JointFigure {
            joint: "j1".into(),
            episode: "episode_000".into(),
            series: vec![series("recorded", 1.0), series("mujoco", 1.1)],
        }];
        let table = "| source | RMS |\n|---|---:|\n| mujoco | 0.1 |\n";
        let files =
            write_joint_space_report(&dir, "Replay <robot>", &["a note".into()], table, &figures)
                .unwrap();
        assert_eq!(files.len(), 3);
        let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
        assert!(html.contains("Replay &lt;robot&gt;"), "{html}");
        assert!(
            html.contains("<td>0.1</td>") && html.contains("<th>mujoco</th>"),
            "{html}"
        );
        assert!(html.contains("<svg role=\"img\""), "{html}");
        assert!(dir.join("episode_000_j1.png").is_file());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
