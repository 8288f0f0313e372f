//! The convergence figure of a tune: every evaluation's objective against
//! its number, with the best so far drawn as a line; failed evaluations
//! are crosses at the top. SVG and PNG.

use crate::render::FAMILY;
use plotters::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Width of the figure, pixels.
pub const WIDTH_PX: u32 = 720;
/// Height of the figure, pixels.
pub const HEIGHT_PX: u32 = 420;

/// One evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConvergencePoint {
    /// Its number (0-based).
    pub evaluation: usize,
    /// Its objective, metres.
    pub objective_m: f64,
    /// It failed (diverged or crashed).
    pub failed: bool,
}

/// A convergence figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConvergenceFigure {
    /// File stem.
    pub stem: String,
    /// Title.
    pub title: String,
    /// The evaluations, in order.
    pub points: Vec<ConvergencePoint>,
    /// A horizontal line to compare with, e.g. the untuned engine's
    /// objective: its label and value, metres.
    pub reference: Option<(String, f64)>,
}

/// A figure that cannot be drawn or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("figure {stem}: {message}")]
pub struct ConvergenceError {
    /// The figure's stem.
    pub stem: String,
    /// What went wrong.
    pub message: String,
}

impl ConvergenceFigure {
    fn error(&self, message: impl Into<String>) -> ConvergenceError {
        ConvergenceError {
            stem: self.stem.clone(),
            message: message.into(),
        }
    }

    /// The best objective so far after each evaluation (failed ones
    /// skipped); `None` before the first finished one.
    pub fn best_so_far(&self) -> Vec<Option<f64>> {
        let mut best: Option<f64> = None;
        self.points
            .iter()
            .map(|p| {
                if !p.failed && p.objective_m.is_finite() {
                    best = Some(best.map_or(p.objective_m, |b: f64| b.min(p.objective_m)));
                }
                best
            })
            .collect()
    }

    /// The finished evaluations (drawn as dots).
    fn finished(&self) -> Vec<&ConvergencePoint> {
        self.points
            .iter()
            .filter(|p| !p.failed && p.objective_m.is_finite() && p.objective_m >= 0.0)
            .collect()
    }

    /// The reference line's value, when drawable.
    fn reference_m(&self) -> Option<f64> {
        self.reference
            .as_ref()
            .map(|r| r.1)
            .filter(|v| v.is_finite() && *v > 0.0)
    }

    /// The top of the linear y axis: 1.5 x the reference (or just above the
    /// largest objective), so that the early, far-off candidates sit at the
    /// top edge.
    fn top(&self) -> Result<f64, String> {
        let ok = self.finished();
        let (Some(lo), Some(hi)) = (
            ok.iter().map(|p| p.objective_m).reduce(f64::min),
            ok.iter().map(|p| p.objective_m).reduce(f64::max),
        ) else {
            return Err("no finished evaluation to draw".into());
        };
        Ok(self
            .reference_m()
            .map_or(hi * 1.05, |v| (v * 1.5).max(lo * 1.2)))
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let ok = self.finished();
        let y1 = self.top()?;
        let r = self.reference_m();
        let n = self.points.len().max(2);
        let clip = |v: f64| v.min(y1);
        let mut chart = ChartBuilder::on(root)
            .caption(self.title.as_str(), (FAMILY, 16))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(64)
            .build_cartesian_2d(0f64..n as f64, 0f64..y1 * 1.02)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("evaluation")
            .y_desc("objective (m; above the top edge: at it)")
            .label_style((FAMILY, 12))
            .draw()
            .map_err(e)?;
        let grey = RGBColor(0x99, 0x99, 0x99);
        chart
            .draw_series(
                ok.iter().map(|p| {
                    Circle::new((p.evaluation as f64, clip(p.objective_m)), 2, grey.filled())
                }),
            )
            .map_err(e)?
            .label("an evaluation")
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, grey.filled()));
        let red = RGBColor(0xD5, 0x5E, 0x00);
        let failed: Vec<f64> = self
            .points
            .iter()
            .filter(|p| p.failed || !p.objective_m.is_finite())
            .map(|p| p.evaluation as f64)
            .collect();
        if !failed.is_empty() {
            chart
                .draw_series(
                    failed
                        .iter()
                        .map(|&x| Cross::new((x, y1), 4, red.stroke_width(2))),
                )
                .map_err(e)?
                .label("failed (diverged or crashed)")
                .legend(move |(x, y)| Cross::new((x + 10, y), 4, red.stroke_width(2)));
        }
        if let (Some((label, _)), Some(v)) = (&self.reference, r) {
            let green = RGBColor(0x00, 0x9E, 0x73);
            chart
                .draw_series(std::iter::once(plotters::element::DashedPathElement::new(
                    vec![(0.0, v), (n as f64, v)],
                    6,
                    4,
                    green.stroke_width(2),
                )))
                .map_err(e)?
                .label(label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], green.stroke_width(2))
                });
        }
        let blue = RGBColor(0x00, 0x72, 0xB2);
        let line: Vec<(f64, f64)> = self
            .best_so_far()
            .iter()
            .zip(&self.points)
            .filter_map(|(b, p)| b.map(|b| (p.evaluation as f64, clip(b))))
            .collect();
        chart
            .draw_series(LineSeries::new(line, blue.stroke_width(2)))
            .map_err(e)?
            .label("best so far")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], blue.stroke_width(2))
            });
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FAMILY, 12))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(e)?;
        Ok(())
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> Result<String, ConvergenceError> {
        crate::render::svg(self, WIDTH_PX, HEIGHT_PX).map_err(|m| self.error(m))
    }

    /// The figure as PNG bytes (RGB).
    pub fn to_png(&self) -> Result<Vec<u8>, ConvergenceError> {
        crate::render::png(self, WIDTH_PX, HEIGHT_PX).map_err(|m| self.error(m))
    }

    /// Writes `DIR/<stem>.svg` and `DIR/<stem>.png`.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, ConvergenceError> {
        crate::render::write(self, dir, &self.stem, (WIDTH_PX, HEIGHT_PX))
            .map_err(|m| self.error(m))
    }
}

impl crate::render::Draw for ConvergenceFigure {
    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), String> {
        self.draw(root)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_so_far_skips_failures_and_the_figure_draws() {
        let f = ConvergenceFigure {
            stem: "c".into(),
            title: "t".into(),
            points: [(5.0, false), (1e6, true), (3.0, false), (4.0, false)]
                .iter()
                .enumerate()
                .map(|(i, &(o, failed))| ConvergencePoint {
                    evaluation: i,
                    objective_m: o,
                    failed,
                })
                .collect(),
            reference: Some(("untuned".into(), 6.0)),
        };
        assert_eq!(
            f.best_so_far(),
            vec![Some(5.0), Some(5.0), Some(3.0), Some(3.0)]
        );
        let svg = f.to_svg().unwrap();
        assert!(svg.contains("best so far") && svg.contains("failed") && svg.contains("untuned"));
        assert!(f.to_png().unwrap().starts_with(b"\x89PNG"));
        let empty = ConvergenceFigure {
            points: vec![],
            ..f
        };
        assert!(empty
            .to_svg()
            .unwrap_err()
            .to_string()
            .contains("no finished evaluation"));
    }
}
