//! Figures and the HTML report of a reality-gap study.
//!
//! Input: the [`SceneReport`]s the analysis produced (one per scene) and a
//! [`Provenance`] saying what produced them. Output, by [`write_report`],
//! in one folder:
//!
//! - `figures/<scene>_<measure>.svg` and `.png`: per scene, each source's
//!   mean over time of the wrist's distance to the goal, its distance to the
//!   reference's mean, and for scenes with a cube the cube's displacement
//!   and pitch change ([`figures`]);
//! - `table.md`, `table.csv`, `table.json`, `table.tex`: the accumulated-
//!   error table and measures, rendered by `realitygap_analysis::table`;
//! - `series.json`: the same JSON with every per-step series, for
//!   re-plotting elsewhere; `provenance.json`; `registration.json` when the
//!   real runs were registered into the world frame;
//! - `index.html`: one self-contained page (figures inline as SVG, style
//!   and scripts inline, no network) that opens with the verdict in
//!   sentences ([`verdict`]) and a 3D replay ([`replay3d`]), then the table, per-scene figures,
//!   measures, the closest source per scene and phase, run-health flags,
//!   the alignment used and provenance ([`html`]).
//!
//! The `realitygap report` and `realitygap reproduce` commands both end
//! here.

#![forbid(unsafe_code)]

pub mod convergence;
pub mod figures;
pub mod frontier;
pub mod held_out;
pub mod html;
pub mod joint_space;
pub mod provenance;
mod render;
pub mod replay3d;
pub mod tosses;
pub mod verdict;

pub use figures::{Figure, FigureKind, SourceStyles};
pub use provenance::{HandoverMarks, Provenance, SourceProvenance};

use realitygap_analysis::table::{self, Format};
use realitygap_analysis::SceneReport;
use std::path::{Path, PathBuf};

/// Errors of [`write_report`].
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file or folder could not be written.
    #[error("cannot {action} {}: {reason}", path.display())]
    Io {
        /// What was being done (`create folder`, `write`).
        action: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        reason: std::io::Error,
    },
    /// A figure could not be drawn.
    #[error(transparent)]
    Figure(#[from] figures::FigureError),
    /// There is nothing to report.
    #[error("nothing to report: no scene was evaluated")]
    Empty,
}

/// The files [`write_report`] wrote.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReportFiles {
    /// The HTML report.
    pub index_html: PathBuf,
    /// Figures as SVG, in report order.
    pub figures_svg: Vec<PathBuf>,
    /// The same figures as PNG.
    pub figures_png: Vec<PathBuf>,
    /// `table.md`, `table.csv`, `table.json`, `table.tex`.
    pub tables: Vec<PathBuf>,
    /// `series.json`, `provenance.json` and, when a registration was
    /// applied, `registration.json`.
    pub data: Vec<PathBuf>,
}

fn write(path: &Path, bytes: impl AsRef<[u8]>) -> Result<PathBuf, ReportError> {
    std::fs::write(path, bytes).map_err(|reason| ReportError::Io {
        action: "write",
        path: path.to_path_buf(),
        reason,
    })?;
    Ok(path.to_path_buf())
}

/// Draws `figure` once, writes it as `fig_dir/<stem>.svg` and `.png` (the
/// paths go to `files`) and returns its SVG, for the page to inline.
fn draw_and_write(
    figure: &Figure,
    fig_dir: &Path,
    files: &mut ReportFiles,
) -> Result<String, ReportError> {
    let svg = figure.to_svg()?;
    let png = figure.to_png()?;
    let stem = &figure.stem;
    files
        .figures_svg
        .push(write(&fig_dir.join(format!("{stem}.svg")), &svg)?);
    files
        .figures_png
        .push(write(&fig_dir.join(format!("{stem}.png")), &png)?);
    Ok(svg)
}

/// Writes the figures, tables and `index.html` of `reports` into `out_dir`
/// (created if missing; files of an earlier report there are replaced).
pub fn write_report(
    reports: &[SceneReport],
    provenance: &Provenance,
    out_dir: &Path,
) -> Result<ReportFiles, ReportError> {
    write_report_with(reports, provenance, out_dir, &[])
}

/// Writes the table in every format into `out_dir`.
fn write_tables(
    reports: &[SceneReport],
    out_dir: &Path,
    files: &mut ReportFiles,
) -> Result<(), ReportError> {
    let tables = [
        ("table.md", Format::Markdown),
        ("table.csv", Format::Csv),
        ("table.json", Format::Json),
        ("table.tex", Format::Latex),
    ];
    for (name, format) in tables {
        files
            .tables
            .push(write(&out_dir.join(name), table::render(reports, format))?);
    }
    Ok(())
}

/// [`write_report`] with `extra` sections in `index.html`, after the
/// summary. With no scene `reports` (a study of tossed objects alone) the
/// page is the `extra` sections and the provenance, and no scene table or
/// series is written.
pub fn write_report_with(
    reports: &[SceneReport],
    provenance: &Provenance,
    out_dir: &Path,
    extra: &[html::ExtraSection],
) -> Result<ReportFiles, ReportError> {
    if reports.is_empty() && extra.is_empty() {
        return Err(ReportError::Empty);
    }
    let fig_dir = out_dir.join("figures");
    std::fs::create_dir_all(&fig_dir).map_err(|reason| ReportError::Io {
        action: "create folder",
        path: fig_dir.clone(),
        reason,
    })?;
    let mut files = ReportFiles::default();

    let styles = SourceStyles::for_reports(reports);
    let mut figures: Vec<Figure> = reports
        .iter()
        .flat_map(|r| figures::scene_figures(r, &styles))
        .collect();
    for f in &mut figures {
        f.add_handovers(&provenance.handovers);
    }
    let mut svgs = Vec::with_capacity(figures.len());
    let mut rel = Vec::with_capacity(figures.len());
    for f in &figures {
        let svg = draw_and_write(f, &fig_dir, &mut files)?;
        rel.push((
            format!("figures/{}.svg", f.stem),
            format!("figures/{}.png", f.stem),
        ));
        svgs.push(svg);
    }

    if !reports.is_empty() {
        write_tables(reports, out_dir, &mut files)?;
        let series = serde_json::to_string(&table::to_json(reports, true)).unwrap_or_default();
        files
            .data
            .push(write(&out_dir.join("series.json"), series + "\n")?);
    }
    let registration = reports
        .iter()
        .find_map(|r| r.registration.as_ref())
        .map(|r| r.registration());
    if let Some(r) = &registration {
        files
            .data
            .push(write(&out_dir.join("registration.json"), r.to_json())?);
    }
    let prov = serde_json::to_string_pretty(provenance).unwrap_or_default();
    files
        .data
        .push(write(&out_dir.join("provenance.json"), prov + "\n")?);

    let entries: Vec<html::FigureEntry<'_>> = figures
        .iter()
        .zip(&svgs)
        .zip(&rel)
        .map(|((figure, svg), (svg_file, png_file))| html::FigureEntry {
            figure,
            svg,
            svg_file,
            png_file,
        })
        .collect();
    let mut downloads: Vec<(String, String)> = if reports.is_empty() {
        Vec::new()
    } else {
        vec![
            ("table.md".into(), "table (Markdown)".into()),
            ("table.csv".into(), "table (CSV)".into()),
            ("table.json".into(), "measures (JSON)".into()),
            ("table.tex".into(), "table (LaTeX)".into()),
            ("series.json".into(), "per-step series (JSON)".into()),
        ]
    };
    downloads.push(("provenance.json".into(), "provenance (JSON)".into()));
    if registration.is_some() {
        downloads.push((
            "registration.json".into(),
            "capture-frame registration (JSON)".into(),
        ));
    }
    // The extra sections' figures, as files beside the scenes', each drawn
    // once: the SVG written is the one the page inlines.
    let mut extra_svgs = Vec::with_capacity(extra.len());
    for s in extra {
        let svgs = s
            .figures
            .iter()
            .map(|f| draw_and_write(f, &fig_dir, &mut files).map(Ok))
            .collect::<Result<Vec<_>, ReportError>>()?;
        extra_svgs.push(svgs);
    }
    let page = html::render_page(
        reports,
        &entries,
        provenance,
        &downloads,
        extra,
        &extra_svgs,
    );
    files.index_html = write(&out_dir.join("index.html"), page)?;
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_analysis::testing as testdata;

    #[test]
    fn write_report_writes_every_file() {
        let dir = std::env::temp_dir().join(format!("rg-report-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let reports = [testdata::scene()];
        let files = write_report(&reports, &Provenance::new("t"), &dir).unwrap();
        assert_eq!(files.figures_svg.len(), 2);
        assert_eq!(files.figures_png.len(), 2);
        for f in files
            .figures_svg
            .iter()
            .chain(&files.figures_png)
            .chain(&files.tables)
            .chain(&files.data)
        {
            let len = std::fs::metadata(f).unwrap().len();
            assert!(len > 100, "{}: {len} bytes", f.display());
        }
        let html = std::fs::read_to_string(&files.index_html).unwrap();
        assert!(html.contains("href=\"figures/scene_test_goal_distance.png\""));
        assert!(files.figures_png[0].ends_with("figures/scene_test_goal_distance.png"));
        assert!(matches!(
            write_report(&[], &Provenance::new("t"), &dir),
            Err(ReportError::Empty)
        ));
        // An output path that is a file is an error naming it.
        let blocker = dir.join("blocker");
        std::fs::write(&blocker, "x").unwrap();
        let e = write_report(&reports, &Provenance::new("t"), &blocker)
            .unwrap_err()
            .to_string();
        assert!(e.contains("blocker"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An extra section's figure is written as SVG and PNG, and the page
    /// inlines the very SVG written (drawn once).
    #[test]
    fn an_extra_sections_figure_is_written_and_inlined() {
        let dir = std::env::temp_dir().join(format!("rg-report-extra-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let scene = testdata::scene();
        let mut figure = figures::scene_figures(&scene, &SourceStyles::for_reports(&[]))
            .into_iter()
            .next()
            .unwrap();
        figure.stem = "extra_figure".into();
        let title = figure.title.clone();
        let section = html::ExtraSection {
            id: "extra".into(),
            title: "Extra".into(),
            figures: vec![figure],
            ..Default::default()
        };
        let files = write_report_with(&[], &Provenance::new("t"), &dir, &[section]).unwrap();
        assert_eq!(files.figures_svg, [dir.join("figures/extra_figure.svg")]);
        assert_eq!(files.figures_png, [dir.join("figures/extra_figure.png")]);
        let svg = std::fs::read_to_string(&files.figures_svg[0]).unwrap();
        let html = std::fs::read_to_string(&files.index_html).unwrap();
        assert!(
            html.contains(&html::inline_svg(&svg, &title)),
            "the written SVG is inlined"
        );
        assert!(html.contains("href=\"figures/extra_figure.png\""));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
