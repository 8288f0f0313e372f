//! Speed-accuracy figures of `realitygap frontier`, in the style of
//! SimBenchmark (leggedrobotics): a measure (deviation from the converged
//! reference, or gap to the real arm, metres) against the real-time factor
//! (simulated seconds per CPU second), both axes logarithmic, one marker
//! shape and colour per group of settings (e.g. per integrator), the Pareto
//! front drawn as a black staircase and the recommended point named.
//!
//! The figure is plain data ([`FrontierFigure`]) rendered to SVG or PNG
//! with the same plotters backends and embedded font as [`crate::figures`]
//! (the crate's one rendering module).

use crate::render::FAMILY;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Width of a frontier figure, pixels (SVG user units and PNG pixels).
pub const WIDTH_PX: u32 = 720;
/// Height of a frontier figure, pixels.
pub const HEIGHT_PX: u32 = 450;
/// Width of the legend column, pixels.
const LEGEND_W: u32 = 170;
/// Okabe-Ito colours, as in the study figures.
const PALETTE: [(u8, u8, u8); 7] = [
    (0xE6, 0x9F, 0x00),
    (0x56, 0xB4, 0xE9),
    (0x00, 0x9E, 0x73),
    (0x00, 0x72, 0xB2),
    (0xD5, 0x5E, 0x00),
    (0xCC, 0x79, 0xA7),
    (0xC8, 0xB4, 0x00),
];

/// One swept setting as plotted.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrontierPoint {
    /// Short label of the setting, e.g. `implicitfast 0.002 s`.
    pub label: String,
    /// Group it is drawn with (same colour and marker), e.g. `implicitfast`.
    pub group: String,
    /// Simulated seconds per CPU second (> 0).
    pub real_time_factor: f64,
    /// The measure, metres; `None` when not measured (it is then not drawn).
    pub value_m: Option<f64>,
    /// The run diverged: drawn as a cross at the measure it reached, and
    /// never on the Pareto front.
    pub diverged: bool,
}

/// One log-log frontier figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrontierFigure {
    /// File stem, e.g. `frontier_deviation`.
    pub stem: String,
    /// Title above the plot.
    pub title: String,
    /// Y-axis label, e.g. `max deviation from the reference (m)`.
    pub y_label: String,
    /// The points.
    pub points: Vec<FrontierPoint>,
    /// A horizontal dashed line (the tolerance), metres.
    pub tolerance_m: Option<f64>,
    /// Index in `points` of the recommended setting.
    pub recommended: Option<usize>,
}

/// The Pareto front of `points` (faster and smaller is better): indices of
/// the finished points no other finished point beats on both axes, by
/// increasing real-time factor.
pub fn pareto_front(points: &[FrontierPoint]) -> Vec<usize> {
    let usable: Vec<(usize, f64, f64)> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.diverged && p.real_time_factor > 0.0)
        .filter_map(|(i, p)| p.value_m.map(|v| (i, p.real_time_factor, v)))
        .filter(|(_, r, v)| r.is_finite() && v.is_finite())
        .collect();
    let mut front: Vec<usize> = usable
        .iter()
        .filter(|(_, r, v)| {
            !usable
                .iter()
                .any(|(_, r2, v2)| r2 >= r && v2 <= v && (r2 > r || v2 < v))
        })
        .map(|(i, _, _)| *i)
        .collect();
    front.sort_by(|a, b| {
        points[*a]
            .real_time_factor
            .total_cmp(&points[*b].real_time_factor)
    });
    front
}

/// Smallest value drawn on the log axis, metres: a point exactly on the
/// reference (deviation 0) is drawn here.
pub const FLOOR_M: f64 = 1e-7;

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[error("frontier figure {figure}: {message}")]
pub struct FrontierFigureError {
    /// The figure's file stem.
    pub figure: String,
    /// What went wrong.
    pub message: String,
}

impl FrontierFigure {
    fn error(&self, message: impl Into<String>) -> FrontierFigureError {
        FrontierFigureError {
            figure: self.stem.clone(),
            message: message.into(),
        }
    }

    /// Axis ranges (x: real-time factor, y: metres), padded by a factor on
    /// each side; `None` when nothing can be drawn.
    fn ranges(&self) -> Option<((f64, f64), (f64, f64))> {
        let xs: Vec<f64> = self
            .points
            .iter()
            .map(|p| p.real_time_factor)
            .filter(|r| r.is_finite() && *r > 0.0)
            .collect();
        let ys: Vec<f64> = self
            .points
            .iter()
            .filter_map(|p| p.value_m)
            .filter(|v| v.is_finite())
            .map(|v| v.max(FLOOR_M))
            .chain(self.tolerance_m)
            .collect();
        let span = |v: &[f64]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(0.0, f64::max);
            (lo.is_finite() && hi > 0.0).then(|| (lo / 2.0, hi * 2.0))
        };
        Some((span(&xs)?, span(&ys)?))
    }

    /// The figure as an SVG document.
    pub fn to_svg(&self) -> Result<String, FrontierFigureError> {
        crate::render::svg(self, WIDTH_PX, HEIGHT_PX).map_err(|m| self.error(m))
    }

    /// The figure as a PNG file's bytes (RGB).
    pub fn to_png(&self) -> Result<Vec<u8>, FrontierFigureError> {
        crate::render::png(self, WIDTH_PX, HEIGHT_PX).map_err(|m| self.error(m))
    }

    /// Writes `DIR/<stem>.svg` and `DIR/<stem>.png`; the two paths.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, FrontierFigureError> {
        crate::render::write(self, dir, &self.stem, (WIDTH_PX, HEIGHT_PX))
            .map_err(|m| self.error(m))
    }

    fn groups(&self) -> Vec<&str> {
        let mut groups: Vec<&str> = Vec::new();
        for p in &self.points {
            if !groups.contains(&p.group.as_str()) {
                groups.push(&p.group);
            }
        }
        groups
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let Some(((x0, x1), (y0, y1))) = self.ranges() else {
            return Err("no point with a finite real-time factor and measure to draw".into());
        };
        let (w, _) = root.dim_in_pixel();
        let (main, legend) = root.split_horizontally(w.saturating_sub(LEGEND_W));
        let mut chart = ChartBuilder::on(&main)
            .caption(self.title.as_str(), (FAMILY, 16))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("real-time factor (simulated s per CPU s)")
            .y_desc(self.y_label.as_str())
            .axis_desc_style((FAMILY, 14))
            .label_style((FAMILY, 12))
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(220, 220, 220))
            .x_label_formatter(&|v| {
                if *v >= 1.0 {
                    format!("{v:.0}")
                } else {
                    format!("{v:.2}")
                }
            })
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(e)?;
        if let Some(t) = self.tolerance_m {
            chart
                .draw_series(std::iter::once(DashedPathElement::new(
                    vec![(x0, t), (x1, t)],
                    6,
                    4,
                    RGBColor(120, 120, 120).stroke_width(1),
                )))
                .map_err(e)?;
        }
        let front = pareto_front(&self.points);
        let line: Vec<(f64, f64)> = front
            .iter()
            .filter_map(|&i| {
                let p = &self.points[i];
                p.value_m.map(|v| (p.real_time_factor, v.max(FLOOR_M)))
            })
            .collect();
        chart
            .draw_series(std::iter::once(PathElement::new(
                line,
                BLACK.stroke_width(2),
            )))
            .map_err(e)?;
        let groups = self.groups();
        self.draw_points(&mut chart, &groups).map_err(e)?;
        if let Some(p) = self.recommended.and_then(|i| self.points.get(i)) {
            if let Some(v) = p.value_m {
                let at = (p.real_time_factor, v.max(FLOOR_M));
                chart
                    .draw_series(std::iter::once(Circle::new(at, 8, BLACK.stroke_width(2))))
                    .map_err(e)?;
                let style = TextStyle::from((FAMILY, 12).into_font())
                    .pos(Pos::new(HPos::Right, VPos::Bottom));
                chart
                    .draw_series(std::iter::once(Text::new(
                        format!("recommended: {}", p.label),
                        at,
                        style,
                    )))
                    .map_err(e)?;
            }
        }
        self.draw_legend(&legend, &groups).map_err(e)
    }

    /// One marker per point: a circle or triangle in its group's colour, a
    /// cross for a diverged one.
    fn draw_points<DB: DrawingBackend>(
        &self,
        chart: &mut ChartContext<'_, DB, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>,
        groups: &[&str],
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        for p in &self.points {
            let Some(v) = p.value_m.filter(|v| v.is_finite()) else {
                continue;
            };
            let at = (p.real_time_factor, v.max(FLOOR_M));
            let gi = groups.iter().position(|g| *g == p.group).unwrap_or(0);
            let (r, g, b) = PALETTE[gi % PALETTE.len()];
            let color = RGBColor(r, g, b);
            if p.diverged {
                chart.draw_series(std::iter::once(Cross::new(at, 5, color.stroke_width(2))))?;
            } else if gi % 2 == 0 {
                chart.draw_series(std::iter::once(Circle::new(at, 4, color.filled())))?;
            } else {
                chart.draw_series(std::iter::once(TriangleMarker::new(at, 5, color.filled())))?;
            }
        }
        Ok(())
    }

    fn draw_legend<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, plotters::coord::Shift>,
        groups: &[&str],
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let style =
            TextStyle::from((FAMILY, 12).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
        let mut y = 44;
        for (gi, g) in groups.iter().enumerate() {
            let (r, gr, b) = PALETTE[gi % PALETTE.len()];
            let color = RGBColor(r, gr, b);
            if gi % 2 == 0 {
                area.draw(&Circle::new((12, y), 4, color.filled()))?;
            } else {
                area.draw(&TriangleMarker::new((12, y), 5, color.filled()))?;
            }
            area.draw(&Text::new(g.to_string(), (24, y), style.clone()))?;
            y += 20;
        }
        area.draw(&PathElement::new(
            vec![(4, y), (20, y)],
            BLACK.stroke_width(2),
        ))?;
        area.draw(&Text::new("Pareto front", (24, y), style.clone()))?;
        y += 20;
        area.draw(&Cross::new((12, y), 5, BLACK.stroke_width(2)))?;
        area.draw(&Text::new("diverged", (24, y), style.clone()))?;
        if self.tolerance_m.is_some() {
            y += 20;
            area.draw(&DashedPathElement::new(
                vec![(4, y), (20, y)],
                4,
                3,
                RGBColor(120, 120, 120).stroke_width(1),
            ))?;
            area.draw(&Text::new("tolerance", (24, y), style))?;
        }
        Ok(())
    }
}

impl crate::render::Draw for FrontierFigure {
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

    fn point(label: &str, rtf: f64, v: f64, diverged: bool) -> FrontierPoint {
        FrontierPoint {
            label: label.into(),
            group: label[..1].into(),
            real_time_factor: rtf,
            value_m: Some(v),
            diverged,
        }
    }

    #[test]
    fn pareto_front_keeps_the_undominated_finished_points() {
        let pts = vec![
            point("a", 1.0, 1e-6, false),
            point("b", 10.0, 1e-4, false),
            point("c", 5.0, 1e-3, false),  // dominated by b
            point("d", 100.0, 1e-5, true), // diverged
            point("e", 50.0, 1e-2, false),
        ];
        assert_eq!(pareto_front(&pts), vec![0, 1, 4]);
    }

    #[test]
    fn renders_svg_and_png_with_the_recommended_point_named() {
        let fig = FrontierFigure {
            stem: "t".into(),
            title: "test".into(),
            y_label: "max deviation (m)".into(),
            points: vec![
                point("a 1", 1.0, 0.0, false),
                point("b 2", 10.0, 1e-4, false),
                point("c 3", 20.0, 0.5, true),
            ],
            tolerance_m: Some(1e-3),
            recommended: Some(1),
        };
        let svg = fig.to_svg().unwrap();
        assert!(svg.contains("recommended: b 2"), "{}", &svg[..200]);
        let png = fig.to_png().unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let empty = FrontierFigure {
            points: vec![],
            ..fig
        };
        assert!(empty.to_svg().unwrap_err().to_string().contains("no point"));
    }
}
