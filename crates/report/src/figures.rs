//! The study's figures: per scene, one line plot per available measure
//! over time, each source a line, drawn with `plotters` to SVG and PNG.
//!
//! Building a figure has two stages with plain data in between:
//! 1. [`scene_figures`] turns a [`SceneReport`] into [`Figure`]s: the lines
//!    (with their [`LineStyle`]), the reference's spread band, the phase
//!    boundaries, the axis ranges (clipped to the sane data, see
//!    [`Figure::off_scale`]) and a caption;
//! 2. [`Figure::to_svg`] and [`Figure::to_png`] draw one.
//!
//! Which figures a scene gets depends on what its report holds: the wrist's
//! distance to the goal when the scene has a goal, the distance to the
//! reference's mean when sources were compared with a reference, and the
//! cube's displacement and pitch change when the scene has a cube.

use crate::render::FAMILY;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::{DashedPathElement, Drawable, PointCollection};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters_backend::{BackendCoord, DrawingErrorKind};
use realitygap_analysis::compare::{SceneReport, Series, SourceSummary};
use serde::Serialize;

/// Width of a figure, pixels (SVG user units and PNG pixels).
pub const WIDTH_PX: u32 = 640;
/// Height of a figure, pixels.
pub const HEIGHT_PX: u32 = 400;
/// Width of the legend column at the right of a figure, pixels.
const LEGEND_W: u32 = 158;
/// The Okabe-Ito colour-blind-safe palette without black (black is the
/// reference's colour), as RGB. The yellow is darkened slightly so that a
/// thin line stays visible on white.
pub const PALETTE: [(u8, u8, u8); 7] = [
    (0xE6, 0x9F, 0x00), // orange
    (0x56, 0xB4, 0xE9), // sky blue
    (0x00, 0x9E, 0x73), // bluish green
    (0x00, 0x72, 0xB2), // blue
    (0xD5, 0x5E, 0x00), // vermillion
    (0xCC, 0x79, 0xA7), // reddish purple
    (0xC8, 0xB4, 0x00), // yellow, darkened
];

/// Dash patterns cycled over sources: `None` is a solid line, else
/// (dash, gap) lengths in pixels.
const DASHES: [Option<(u32, u32)>; 5] = [
    None,
    Some((8, 4)),
    Some((3, 3)),
    Some((14, 4)),
    Some((6, 2)),
];

/// Marker drawn at regular steps along a line, so that lines stay apart in
/// grey-scale print.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Marker {
    /// No marker (the reference).
    None,
    /// A filled circle.
    Circle,
    /// A filled triangle.
    Triangle,
    /// A filled square.
    Square,
    /// A cross (x).
    Cross,
    /// A filled diamond.
    Diamond,
    /// An open circle.
    Ring,
}

const MARKERS: [Marker; 6] = [
    Marker::Circle,
    Marker::Triangle,
    Marker::Square,
    Marker::Cross,
    Marker::Diamond,
    Marker::Ring,
];

/// How one source's line is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct LineStyle {
    /// Colour, RGB.
    pub rgb: (u8, u8, u8),
    /// Dash and gap lengths, pixels; `None` for a solid line.
    pub dash: Option<(u32, u32)>,
    /// Marker shape.
    pub marker: Marker,
    /// Line width, pixels.
    pub width_px: u32,
}

impl LineStyle {
    /// The reference's style: solid black, wider, no markers.
    pub const REFERENCE: LineStyle = LineStyle {
        rgb: (0, 0, 0),
        dash: None,
        marker: Marker::None,
        width_px: 2,
    };

    /// The style of the `index`-th source (0-based): palette colour, dash
    /// pattern and marker each cycle with their own period, so that up to
    /// 7 sources differ in all three and any two sources differ in one.
    pub fn for_source(index: usize) -> LineStyle {
        LineStyle {
            rgb: PALETTE[index % PALETTE.len()],
            dash: DASHES[index % DASHES.len()],
            marker: MARKERS[index % MARKERS.len()],
            width_px: 2,
        }
    }

    /// The colour as a CSS/SVG hex string, e.g. `#E69F00`.
    pub fn hex(&self) -> String {
        format!("#{:02X}{:02X}{:02X}", self.rgb.0, self.rgb.1, self.rgb.2)
    }

    fn color(&self) -> RGBColor {
        RGBColor(self.rgb.0, self.rgb.1, self.rgb.2)
    }
}

/// Line styles of every source of a set of reports, fixed by the order in
/// which sources first appear so that a source looks the same in every
/// figure of a report.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SourceStyles {
    names: Vec<String>,
}

impl SourceStyles {
    /// Styles for the sources of these reports.
    pub fn for_reports(reports: &[SceneReport]) -> SourceStyles {
        SourceStyles {
            names: realitygap_analysis::table::source_names(reports),
        }
    }

    /// The style of a source; a source not seen in the reports gets the
    /// next free style.
    pub fn get(&self, source: &str) -> LineStyle {
        let i = self
            .names
            .iter()
            .position(|n| n == source)
            .unwrap_or(self.names.len());
        LineStyle::for_source(i)
    }
}

/// What a figure shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FigureKind {
    /// Distance of each source's mean wrist position to the goal, metres.
    GoalDistance,
    /// Distance of each source's mean wrist position to the reference's
    /// mean at the same step, metres.
    ReferenceDistance,
    /// Displacement of the mean cube position from its start, metres.
    CubeDisplacement,
    /// Change of the mean cube pitch since the start, degrees.
    CubePitch,
    /// The tossed cube's centre error against the time from the recorded
    /// first impact, cube edges (the second study's figure,
    /// [`crate::tosses::toss_figure`]; not one of a scene's, [`FigureKind::ALL`]).
    TossCentreError,
    /// A cross-validated tune's held-out wrist error against time, the
    /// mean over the folds, metres ([`crate::held_out`]; not one of a
    /// scene's).
    HeldOutDistance,
    /// A cross-validated tune's held-out wrist height minus the real
    /// wrist's, the mean over the folds, metres (negative: below).
    HeldOutHeight,
}

impl FigureKind {
    /// Every kind, in the order figures are shown.
    pub const ALL: [FigureKind; 4] = [
        FigureKind::GoalDistance,
        FigureKind::ReferenceDistance,
        FigureKind::CubeDisplacement,
        FigureKind::CubePitch,
    ];

    /// Short name used in file names, e.g. `goal_distance`.
    pub fn slug(self) -> &'static str {
        match self {
            FigureKind::GoalDistance => "goal_distance",
            FigureKind::ReferenceDistance => "reference_distance",
            FigureKind::CubeDisplacement => "cube_displacement",
            FigureKind::CubePitch => "cube_pitch",
            FigureKind::TossCentreError => "toss_centre_error",
            FigureKind::HeldOutDistance => "held_out_distance",
            FigureKind::HeldOutHeight => "held_out_height",
        }
    }

    /// Title of the figure; `reference` is the reference source's name.
    pub fn title(self, reference: &str) -> String {
        match self {
            FigureKind::GoalDistance => "Wrist distance to the goal".into(),
            FigureKind::ReferenceDistance => format!("Wrist distance to the mean of '{reference}'"),
            FigureKind::CubeDisplacement => "Cube displacement from its start".into(),
            FigureKind::CubePitch => "Cube pitch change".into(),
            FigureKind::TossCentreError => "Cube centre error from the first impact".into(),
            FigureKind::HeldOutDistance => "Held-out wrist error, mean over the folds".into(),
            FigureKind::HeldOutHeight => "Held-out wrist height error, mean over the folds".into(),
        }
    }

    /// Label of the y axis, with its unit.
    pub fn y_label(self) -> &'static str {
        match self {
            FigureKind::GoalDistance => "distance to goal (m)",
            FigureKind::ReferenceDistance => "distance to reference (m)",
            FigureKind::CubeDisplacement => "cube displacement (m)",
            FigureKind::CubePitch => "pitch change (deg)",
            FigureKind::TossCentreError => "centre error (cube edges)",
            FigureKind::HeldOutDistance => "distance to the real wrist (m)",
            FigureKind::HeldOutHeight => "height minus the real wrist's (m)",
        }
    }

    /// Unit of the y values, for captions.
    pub fn unit(self) -> &'static str {
        match self {
            FigureKind::CubePitch => "deg",
            FigureKind::TossCentreError => "edges",
            _ => "m",
        }
    }

    /// The per-step values of this kind in a source's series.
    pub fn values(self, series: &Series) -> &[Option<f64>] {
        match self {
            FigureKind::GoalDistance => &series.wrist_distance_to_goal_m,
            FigureKind::ReferenceDistance => &series.wrist_distance_to_reference_m,
            FigureKind::CubeDisplacement => &series.cube_displacement_m,
            FigureKind::CubePitch => &series.cube_pitch_change_deg,
            // A scene's series has none: the tosses' figure is built from
            // the toss table's curves, the held-out ones from a
            // cross-validation's folds.
            FigureKind::TossCentreError
            | FigureKind::HeldOutDistance
            | FigureKind::HeldOutHeight => &[],
        }
    }

    /// Whether the reference itself is drawn (its distance to itself is 0,
    /// so not for [`FigureKind::ReferenceDistance`]).
    fn shows_reference(self) -> bool {
        self != FigureKind::ReferenceDistance
    }

    /// Whether values are non-negative by nature (the y axis starts at 0).
    fn non_negative(self) -> bool {
        !matches!(self, FigureKind::CubePitch | FigureKind::HeldOutHeight)
    }

    /// Largest value a sane series may reach, given a typical scale of the
    /// data: beyond it a series is taken to have diverged and is clipped.
    fn cap(self, typical: f64) -> f64 {
        match self {
            // Angles cannot exceed a full turn.
            FigureKind::CubePitch => 360.0,
            // Ten times the typical size, at least 1 m, at most 20 m (two
            // positions within the health check's 10 m divergence bound).
            _ => (10.0 * typical).clamp(1.0, 20.0),
        }
    }
}

/// One line of a figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Line {
    /// Legend name (the source's name).
    pub name: String,
    /// How it is drawn.
    pub style: LineStyle,
    /// (time s, value) per step; `None` where the source has no value.
    pub points: Vec<(f64, Option<f64>)>,
}

impl Line {
    fn finite_values(&self) -> impl Iterator<Item = f64> + '_ {
        self.points
            .iter()
            .filter_map(|p| p.1)
            .filter(|v| v.is_finite())
    }
    fn max_abs(&self) -> Option<f64> {
        let mut it = self.points.iter().filter_map(|p| p.1);
        let first = it.next()?;
        Some(it.fold(first.abs(), |m, v| {
            if v.is_nan() || m.is_nan() {
                f64::NAN
            } else {
                m.max(v.abs())
            }
        }))
    }
}

/// A shaded band (the reference's spread).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Band {
    /// Legend text.
    pub label: String,
    /// (time s, lower, upper) per step where defined.
    pub points: Vec<(f64, Option<(f64, f64)>)>,
}

/// A source not drawn, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Omitted {
    /// Source name.
    pub source: String,
    /// Why it is not drawn.
    pub reason: String,
}

/// A source drawn but leaving the y range (clipped at the edge).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OffScale {
    /// Source name.
    pub source: String,
    /// Its largest magnitude, in the figure's unit (may be NaN or infinite).
    pub max_abs: f64,
}

/// One figure, ready to draw.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure {
    /// Scene name.
    pub scene: String,
    /// What it shows.
    pub kind: FigureKind,
    /// File stem, e.g. `scene1_single_joint_goal_distance`.
    pub stem: String,
    /// Title drawn at the top.
    pub title: String,
    /// Label of the x axis, with its unit.
    pub x_label: String,
    /// Label of the y axis, with its unit.
    pub y_label: String,
    /// x range, seconds.
    pub x_range: (f64, f64),
    /// y range, in the figure's unit.
    pub y_range: (f64, f64),
    /// The reference's spread band, when shown.
    pub band: Option<Band>,
    /// Lines, the reference (when shown) first.
    pub lines: Vec<Line>,
    /// Phase start times after the first, seconds (thin vertical lines).
    pub phase_boundaries_s: Vec<f64>,
    /// Handovers of stitched sources drawn (solid vertical ticks in the
    /// source's colour hanging from the top, one row per source).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub handovers: Vec<HandoverMark>,
    /// Sources not drawn (no usable runs or no values of this kind).
    pub omitted: Vec<Omitted>,
    /// Sources drawn but clipped at the edge of the y range.
    pub off_scale: Vec<OffScale>,
    /// Caption: what is shown, and which sources are missing or clipped.
    pub caption: String,
}

/// One handover of a stitched source, as a figure draws it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HandoverMark {
    /// The source's name.
    pub source: String,
    /// Time, seconds.
    pub t_s: f64,
    /// The source's line style (its colour is used).
    pub style: LineStyle,
}

impl Figure {
    /// Adds the handovers of the stitched sources drawn in this figure
    /// (the marks of this scene whose source is one of its lines) and
    /// names them in the caption.
    pub fn add_handovers(&mut self, marks: &[crate::provenance::HandoverMarks]) {
        let mut named = Vec::new();
        for m in marks.iter().filter(|m| m.scene == self.scene) {
            let Some(line) = self.lines.iter().find(|l| l.name == m.source) else {
                continue;
            };
            let times: Vec<f64> = m
                .times_s
                .iter()
                .copied()
                .filter(|t| *t > self.x_range.0 && *t < self.x_range.1)
                .collect();
            if times.is_empty() {
                continue;
            }
            named.push(format!(
                "{} at {}",
                m.source,
                times
                    .iter()
                    .map(|t| format!("{t} s"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            self.handovers
                .extend(times.into_iter().map(|t_s| HandoverMark {
                    source: m.source.clone(),
                    t_s,
                    style: line.style,
                }));
        }
        if !named.is_empty() {
            self.caption.push_str(&format!(
                " Solid vertical ticks at the top in a source's colour: its handovers from one engine to the next ({}).",
                named.join("; ")
            ));
        }
    }
}

/// Errors of drawing a figure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot draw figure {figure}: {message}")]
pub struct FigureError {
    /// The figure's file stem.
    pub figure: String,
    /// What went wrong.
    pub message: String,
}

/// Turns a name into a file-name-safe stem: ASCII letters, digits, `-`
/// and `_` are kept, anything else becomes `_`.
pub fn file_stem(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        "scene".into()
    } else {
        s
    }
}

/// The figure kinds a scene report has data for, in display order.
pub fn available_kinds(report: &SceneReport) -> Vec<FigureKind> {
    let all = || std::iter::once(&report.reference).chain(&report.sources);
    let has = |k: FigureKind| all().any(|s| k.values(&s.series).iter().any(Option::is_some));
    let cube_scene = all().any(|s| s.cube.is_some() || !s.series.cube_displacement_m.is_empty());
    FigureKind::ALL
        .into_iter()
        .filter(|k| match k {
            FigureKind::GoalDistance => report.goal_m.is_some(),
            FigureKind::ReferenceDistance => report
                .sources
                .iter()
                .any(|s| !s.series.wrist_distance_to_reference_m.is_empty()),
            FigureKind::CubeDisplacement | FigureKind::CubePitch => cube_scene && has(*k),
            // Not a scene's figures.
            FigureKind::TossCentreError
            | FigureKind::HeldOutDistance
            | FigureKind::HeldOutHeight => false,
        })
        .collect()
}

/// Why a source has nothing to draw, or `None` when it has.
fn omission_reason(s: &SourceSummary, kind: FigureKind) -> Option<String> {
    if s.runs_used == 0 {
        let excluded: Vec<&realitygap_analysis::compare::FlaggedRun> =
            s.runs_flagged.iter().filter(|f| f.excluded).collect();
        if excluded.is_empty() {
            return Some(format!("no usable runs ({} given)", s.runs_total));
        }
        let mut names: Vec<&str> = excluded
            .iter()
            .flat_map(|f| f.flags.iter().map(|x| x.name()))
            .collect();
        names.sort_unstable();
        names.dedup();
        return Some(format!(
            "no usable runs: {} of {} left out ({})",
            excluded.len(),
            s.runs_total,
            names.join(", ").replace('_', " ")
        ));
    }
    if kind.values(&s.series).iter().all(Option::is_none) {
        return Some("no values of this measure".into());
    }
    None
}

fn line_of(s: &SourceSummary, kind: FigureKind, style: LineStyle) -> Line {
    let t = &s.series.t_s;
    let v = kind.values(&s.series);
    Line {
        name: s.source.clone(),
        style,
        points: t
            .iter()
            .enumerate()
            .map(|(i, t)| (*t, v.get(i).copied().flatten()))
            .collect(),
    }
}

/// Formats a magnitude for captions: 3 significant digits, scientific
/// beyond 1e4.
pub(crate) fn fmt_mag(v: f64) -> String {
    if !v.is_finite() {
        format!("{v}")
    } else if v.abs() >= 1e4 {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}

/// Builds the figures of one scene.
pub fn scene_figures(report: &SceneReport, styles: &SourceStyles) -> Vec<Figure> {
    available_kinds(report)
        .into_iter()
        .map(|k| build_figure(report, k, styles))
        .collect()
}

/// The reference's spread as a band: around its curve for the goal
/// distance, from zero for the distance to the reference; `None` for one
/// run, no spread, or another kind of figure.
fn spread_band(reference: &SourceSummary, kind: FigureKind) -> Option<Band> {
    let spread = &reference.series.wrist_spread_m;
    if reference.runs_used <= 1 || !spread.iter().any(Option::is_some) {
        return None;
    }
    let ref_goal = &reference.series.wrist_distance_to_goal_m;
    let t = &reference.series.t_s;
    match kind {
        FigureKind::GoalDistance if ref_goal.iter().any(Option::is_some) => Some(Band {
            label: format!("{} \u{b1} RMS spread", reference.source),
            points: t
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let b = match (
                        ref_goal.get(i).copied().flatten(),
                        spread.get(i).copied().flatten(),
                    ) {
                        (Some(d), Some(s)) if d.is_finite() && s.is_finite() => {
                            Some(((d - s).max(0.0), d + s))
                        }
                        _ => None,
                    };
                    (*t, b)
                })
                .collect(),
        }),
        FigureKind::ReferenceDistance => Some(Band {
            label: format!("{} RMS spread", reference.source),
            points: t
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    (
                        *t,
                        spread
                            .get(i)
                            .copied()
                            .flatten()
                            .filter(|s| s.is_finite())
                            .map(|s| (0.0, s)),
                    )
                })
                .collect(),
        }),
        _ => None,
    }
}

/// Builds one figure of a scene (also for a kind the scene lacks data
/// for: then every source is listed as omitted).
pub fn build_figure(report: &SceneReport, kind: FigureKind, styles: &SourceStyles) -> Figure {
    let reference = &report.reference;
    let mut lines = Vec::new();
    let mut omitted = Vec::new();
    if kind.shows_reference() {
        match omission_reason(reference, kind) {
            Some(reason) => omitted.push(Omitted {
                source: reference.source.clone(),
                reason,
            }),
            None => lines.push(line_of(reference, kind, LineStyle::REFERENCE)),
        }
    }
    let band = spread_band(reference, kind);
    for s in &report.sources {
        match omission_reason(s, kind) {
            Some(reason) => omitted.push(Omitted {
                source: s.source.clone(),
                reason,
            }),
            None => lines.push(line_of(s, kind, styles.get(&s.source))),
        }
    }
    let (y_range, off_scale) = y_range(kind, &lines, band.as_ref());
    let t_end = report
        .sources
        .iter()
        .chain([reference])
        .filter_map(|s| s.series.t_s.last().copied())
        .fold(
            (report.steps.max(1) - 1) as f64 * report.control_period_s,
            f64::max,
        );
    // The whole scene: up to steps x period, so the last tick is labelled.
    let x_end = t_end.max(report.steps as f64 * report.control_period_s);
    let x_range = (0.0, if x_end > 0.0 { x_end } else { 1.0 });
    let phase_boundaries_s: Vec<f64> = report
        .phases_s
        .iter()
        .copied()
        .filter(|t| *t > x_range.0 && *t < x_range.1)
        .collect();
    let title = kind.title(&reference.source);
    let caption = caption(
        report,
        kind,
        &title,
        band.as_ref(),
        &phase_boundaries_s,
        &omitted,
        &off_scale,
    );
    Figure {
        scene: report.scene.clone(),
        kind,
        stem: format!("{}_{}", file_stem(&report.scene), kind.slug()),
        title,
        x_label: "time (s)".into(),
        y_label: kind.y_label().into(),
        x_range,
        y_range,
        band,
        lines,
        phase_boundaries_s,
        handovers: Vec::new(),
        omitted,
        off_scale,
        caption,
    }
}

fn caption(
    report: &SceneReport,
    kind: FigureKind,
    title: &str,
    band: Option<&Band>,
    phases: &[f64],
    omitted: &[Omitted],
    off_scale: &[OffScale],
) -> String {
    let mut c = format!(
        "{title}, scene {}: per source, the mean over its runs at each control step",
        report.scene
    );
    if let Some(b) = band {
        c.push_str(&format!("; shaded: {}", b.label));
    }
    if !phases.is_empty() {
        let p: Vec<String> = phases.iter().map(|t| format!("{t} s")).collect();
        c.push_str(&format!(
            "; vertical lines: new targets at {}",
            p.join(", ")
        ));
    }
    c.push('.');
    c.push_str(&caption_tail(omitted, off_scale, kind.unit()));
    c
}

/// The end of a figure's caption: the sources not plotted, with why, and
/// those clipped at the plot's edge, with how far they reach (`unit`).
/// Empty when every source is drawn within the plot.
pub(crate) fn caption_tail(omitted: &[Omitted], off_scale: &[OffScale], unit: &str) -> String {
    let mut c = String::new();
    if !omitted.is_empty() {
        let o: Vec<String> = omitted
            .iter()
            .map(|o| format!("{} ({})", o.source, o.reason))
            .collect();
        c.push_str(&format!(" Not plotted: {}.", o.join("; ")));
    }
    if !off_scale.is_empty() {
        let o: Vec<String> = off_scale
            .iter()
            .map(|o| format!("{} (up to {} {unit})", o.source, fmt_mag(o.max_abs)))
            .collect();
        c.push_str(&format!(
            " Clipped at the edge of the plot: {}.",
            o.join("; ")
        ));
    }
    c
}

/// The y range of a figure: from the data of the lines that stay within
/// [`FigureKind::cap`] of the typical magnitude (the median of the lines'
/// largest magnitudes), with 5 % headroom; lines beyond it are returned as
/// off-scale and will be clipped.
pub(crate) fn y_range(
    kind: FigureKind,
    lines: &[Line],
    band: Option<&Band>,
) -> ((f64, f64), Vec<OffScale>) {
    let mut maxima: Vec<f64> = lines
        .iter()
        .filter_map(Line::max_abs)
        .filter(|v| v.is_finite())
        .collect();
    maxima.sort_by(f64::total_cmp);
    let typical = if maxima.is_empty() {
        0.0
    } else {
        maxima[(maxima.len() - 1) / 2]
    };
    let cap = kind.cap(typical);
    let mut off = Vec::new();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for l in lines {
        match l.max_abs() {
            Some(m) if m.is_finite() && m <= cap => {
                for v in l.finite_values() {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            Some(m) => off.push(OffScale {
                source: l.name.clone(),
                max_abs: m,
            }),
            None => {}
        }
    }
    if let Some(b) = band {
        for (lower, upper) in b.points.iter().filter_map(|p| p.1) {
            if upper.is_finite() && upper.abs() <= cap {
                lo = lo.min(lower);
                hi = hi.max(upper);
            }
        }
    }
    if !lo.is_finite() || !hi.is_finite() {
        // Nothing sane to show: a unit range.
        return (
            if kind.non_negative() {
                (0.0, 1.0)
            } else {
                (-1.0, 1.0)
            },
            off,
        );
    }
    if kind.non_negative() {
        lo = lo.min(0.0);
    }
    let span = hi - lo;
    let span = if span > 0.0 { span } else { hi.abs().max(1e-3) };
    let lo = if kind.non_negative() && lo >= 0.0 {
        0.0
    } else {
        lo - 0.05 * span
    };
    ((lo, hi + 0.05 * span), off)
}

/// Clips a polyline with gaps (`None`) to the box `x` by `y`: returns the
/// visible pieces, each with at least two points. Segments crossing the
/// edge are cut at the edge.
pub fn clip_polyline(
    points: &[(f64, Option<f64>)],
    x: (f64, f64),
    y: (f64, f64),
) -> Vec<Vec<(f64, f64)>> {
    let mut pieces: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    let flush = |current: &mut Vec<(f64, f64)>, pieces: &mut Vec<Vec<(f64, f64)>>| {
        if current.len() >= 2 {
            pieces.push(std::mem::take(current));
        } else {
            current.clear();
        }
    };
    let mut prev: Option<(f64, f64)> = None;
    for &(t, v) in points {
        let p = v
            .filter(|v| v.is_finite())
            .map(|v| (t, v))
            .filter(|p| p.0.is_finite());
        match (prev, p) {
            (Some(a), Some(b)) => match clip_segment(a, b, x, y) {
                Some((c, d)) => {
                    if current.last() != Some(&c) {
                        flush(&mut current, &mut pieces);
                        current.push(c);
                    }
                    current.push(d);
                    if d != b {
                        flush(&mut current, &mut pieces);
                    }
                }
                None => flush(&mut current, &mut pieces),
            },
            (None, Some(b)) => {
                flush(&mut current, &mut pieces);
                if b.0 >= x.0 && b.0 <= x.1 && b.1 >= y.0 && b.1 <= y.1 {
                    current.push(b);
                }
            }
            (_, None) => flush(&mut current, &mut pieces),
        }
        prev = p;
    }
    flush(&mut current, &mut pieces);
    pieces
}

/// Liang-Barsky clipping of segment a-b to the box; `None` when it misses.
fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    x: (f64, f64),
    y: (f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - x.0),
        (dx, x.1 - a.0),
        (-dy, a.1 - y.0),
        (dy, y.1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| {
        if t == 0.0 {
            a
        } else if t == 1.0 {
            b
        } else {
            (a.0 + t * dx, a.1 + t * dy)
        }
    };
    Some((at(t0), at(t1)))
}

/// The text with its first letter in lower case (for "scene: title").
fn lower_first(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_lowercase().chain(c).collect(),
        None => String::new(),
    }
}

/// Decimals for tick labels of a range.
fn tick_decimals(span: f64) -> usize {
    if span.is_nan() || span <= 0.0 {
        return 2;
    }
    let step = span / 6.0;
    (-(step.log10().floor())).clamp(0.0, 6.0) as usize
}

impl crate::render::Draw for Figure {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        self.draw(root)
    }
}

impl Figure {
    /// The figure as an SVG document (`WIDTH_PX` x `HEIGHT_PX`).
    pub fn to_svg(&self) -> Result<String, FigureError> {
        crate::render::svg(self, WIDTH_PX, HEIGHT_PX).map_err(|m| self.error(m))
    }

    /// The figure as a PNG file's bytes (RGB, `WIDTH_PX` x `HEIGHT_PX`).
    pub fn to_png(&self) -> Result<Vec<u8>, FigureError> {
        crate::render::png(self, WIDTH_PX, HEIGHT_PX).map_err(|m| self.error(m))
    }

    /// Writes `DIR/<stem>.svg` and `DIR/<stem>.png`; the two paths.
    pub fn write(&self, dir: &std::path::Path) -> Result<Vec<std::path::PathBuf>, FigureError> {
        crate::render::write(self, dir, &self.stem, (WIDTH_PX, HEIGHT_PX))
            .map_err(|m| self.error(m))
    }

    fn error(&self, message: String) -> FigureError {
        FigureError {
            figure: self.stem.clone(),
            message,
        }
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let (w, _) = root.dim_in_pixel();
        let (main, legend) = root.split_horizontally(w.saturating_sub(LEGEND_W));
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_range;
        let (main_w, _) = main.dim_in_pixel();
        let title_font = (FAMILY, 16).into_font();
        let title = fit_text(
            &main,
            &format!("{}: {}", self.scene, lower_first(&self.title)),
            &title_font,
            main_w as i32 - 8,
        );
        let mut chart = ChartBuilder::on(&main)
            .caption(title, title_font)
            .margin_top(6)
            .margin_left(4)
            .margin_right(12)
            .margin_bottom(6)
            .x_label_area_size(40)
            .y_label_area_size(62)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e)?;
        let decimals = tick_decimals(y1 - y0);
        let y_fmt =
            move |v: &f64| format!("{:.*}", decimals, if v.abs() < 1e-12 { 0.0 } else { *v });
        let x_fmt = |v: &f64| {
            let r = v.round();
            if (v - r).abs() < 1e-9 {
                format!("{r:.0}")
            } else {
                format!("{v:.1}")
            }
        };
        let grid = RGBColor(225, 225, 225);
        chart
            .configure_mesh()
            .x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .axis_desc_style((FAMILY, 15))
            .label_style((FAMILY, 13))
            .bold_line_style(grid.stroke_width(1))
            .max_light_lines(0)
            .axis_style(BLACK.stroke_width(1))
            .x_labels(9)
            .y_labels(7)
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt)
            .draw()
            .map_err(e)?;

        let band_color = RGBAColor(0, 0, 0, 0.13);
        if let Some(b) = &self.band {
            for piece in band_pieces(&b.points, (y0, y1)) {
                chart
                    .draw_series(std::iter::once(Polygon::new(piece, band_color.filled())))
                    .map_err(e)?;
            }
        }
        let phase_style = RGBColor(110, 110, 110).stroke_width(1);
        for t in &self.phase_boundaries_s {
            chart
                .draw_series(std::iter::once(DashedPathElement::new(
                    vec![(*t, y0), (*t, y1)],
                    4,
                    3,
                    phase_style,
                )))
                .map_err(e)?;
        }
        self.draw_handovers(&mut chart)?;
        self.draw_lines(&mut chart)?;
        let omitted: Vec<String> = self.omitted.iter().map(|o| o.source.clone()).collect();
        let clipped: Vec<String> = self.off_scale.iter().map(|o| o.source.clone()).collect();
        draw_legend(
            &legend,
            &self.lines,
            self.band.as_ref(),
            band_color,
            &omitted,
            &clipped,
        )
        .map_err(e)?;
        Ok(())
    }

    /// Draws each stitched source's handovers: a solid tick in its colour
    /// hanging from the top, one below the other per source.
    fn draw_handovers<DB: DrawingBackend>(
        &self,
        chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    ) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        let (y0, y1) = self.y_range;
        let mut sources: Vec<&str> = Vec::new();
        for h in &self.handovers {
            let k = match sources.iter().position(|s| *s == h.source) {
                Some(k) => k,
                None => {
                    sources.push(&h.source);
                    sources.len() - 1
                }
            };
            let tick = (y1 - y0) * 0.08;
            let top = y1 - k as f64 * tick;
            let style = h.style.color().stroke_width(3);
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(h.t_s, top), (h.t_s, top - tick)],
                    style,
                )))
                .map_err(e)?;
        }
        Ok(())
    }

    /// Draws the lines, sources first and the reference on top, with about
    /// ten markers per line, staggered between lines.
    fn draw_lines<DB: DrawingBackend>(
        &self,
        chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    ) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        let ((x0, x1), (y0, y1)) = (self.x_range, self.y_range);
        let order: Vec<&Line> = self
            .lines
            .iter()
            .skip(1)
            .chain(self.lines.first())
            .collect();
        let source_count = self.lines.len();
        for (k, line) in order.into_iter().enumerate() {
            let style = line.style.color().stroke_width(line.style.width_px);
            for piece in clip_polyline(&line.points, (x0, x1), (y0, y1)) {
                match line.style.dash {
                    None => chart
                        .draw_series(std::iter::once(PathElement::new(piece, style)))
                        .map_err(e)?,
                    Some((d, g)) => chart
                        .draw_series(std::iter::once(DashedPathElement::new(piece, d, g, style)))
                        .map_err(e)?,
                };
            }
            // About 10 markers per line, staggered between lines.
            let n = line.points.len();
            if line.style.marker != Marker::None && n > 0 {
                let step = (n / 10).max(1);
                let offset = (k * step) / source_count.max(1);
                let pts: Vec<(f64, f64)> = line
                    .points
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| i % step == offset % step)
                    .filter_map(|(_, (t, v))| v.map(|v| (*t, v)))
                    .filter(|(t, v)| v.is_finite() && *v >= y0 && *v <= y1 && *t >= x0 && *t <= x1)
                    .collect();
                chart
                    .draw_series(pts.into_iter().map(|p| MarkerElement {
                        at: p,
                        style: line.style,
                    }))
                    .map_err(e)?;
            }
        }
        Ok(())
    }
}

/// Pieces of a band as closed polygons (upper edge forward, lower edge
/// back), with values clamped to the y range.
fn band_pieces(points: &[(f64, Option<(f64, f64)>)], y: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let clamp = |v: f64| v.clamp(y.0, y.1);
    let mut out = Vec::new();
    let mut run: Vec<(f64, f64, f64)> = Vec::new();
    let mut flush = |run: &mut Vec<(f64, f64, f64)>| {
        if run.len() >= 2 {
            let mut poly: Vec<(f64, f64)> = run.iter().map(|(t, _, u)| (*t, clamp(*u))).collect();
            poly.extend(run.iter().rev().map(|(t, l, _)| (*t, clamp(*l))));
            out.push(poly);
        }
        run.clear();
    };
    for (t, b) in points {
        match b {
            Some((l, u)) if l.is_finite() && u.is_finite() && t.is_finite() => {
                run.push((*t, *l, *u))
            }
            _ => flush(&mut run),
        }
    }
    flush(&mut run);
    out
}

/// A marker centred at a point (data or pixel coordinates), drawn
/// directly on the backend.
struct MarkerElement<C> {
    at: C,
    style: LineStyle,
}

impl<'a, C: 'a> PointCollection<'a, C> for &'a MarkerElement<C> {
    type Point = &'a C;
    type IntoIter = std::iter::Once<&'a C>;
    fn point_iter(self) -> Self::IntoIter {
        std::iter::once(&self.at)
    }
}

impl<C, DB: DrawingBackend> Drawable<DB> for MarkerElement<C> {
    fn draw<I: Iterator<Item = BackendCoord>>(
        &self,
        mut pos: I,
        backend: &mut DB,
        _parent: (u32, u32),
    ) -> Result<(), DrawingErrorKind<DB::ErrorType>> {
        let Some((x, y)) = pos.next() else {
            return Ok(());
        };
        let color = self.style.color();
        let thick = color.stroke_width(2);
        match self.style.marker {
            Marker::None => Ok(()),
            Marker::Circle => backend.draw_circle((x, y), 4, &color, true),
            Marker::Ring => backend.draw_circle((x, y), 4, &thick, false),
            Marker::Triangle => {
                backend.fill_polygon([(x, y - 4), (x + 4, y + 3), (x - 4, y + 3)], &color)
            }
            Marker::Square => backend.draw_rect((x - 3, y - 3), (x + 3, y + 3), &color, true),
            Marker::Diamond => {
                backend.fill_polygon([(x, y - 4), (x + 4, y), (x, y + 4), (x - 4, y)], &color)
            }
            Marker::Cross => {
                backend.draw_line((x - 3, y - 3), (x + 3, y + 3), &thick)?;
                backend.draw_line((x - 3, y + 3), (x + 3, y - 3), &thick)
            }
        }
    }
}

/// The legend in its column: a line sample with marker and the name per
/// line (the reference first), then the band.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    lines: &[Line],
    band: Option<&Band>,
    band_color: RGBAColor,
    omitted: &[String],
    clipped: &[String],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (w, _) = area.dim_in_pixel();
    let font = (FAMILY, 13).into_font();
    let text_style = TextStyle::from(font.clone())
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    let (sample_x0, sample_x1, text_x) = (2, 32, 38);
    let max_text = w as i32 - text_x - 2;
    let row = 21;
    let mut y = 44;
    for line in lines {
        let style = line.style.color().stroke_width(line.style.width_px);
        match line.style.dash {
            None => area.draw(&PathElement::new(
                vec![(sample_x0, y), (sample_x1, y)],
                style,
            ))?,
            Some((d, g)) => area.draw(&DashedPathElement::new(
                vec![(sample_x0, y), (sample_x1, y)],
                d,
                g,
                style,
            ))?,
        }
        area.draw(&MarkerElement {
            at: ((sample_x0 + sample_x1) / 2, y),
            style: line.style,
        })?;
        let name = fit_text(area, &line.name, &font, max_text);
        area.draw(&Text::new(name, (text_x, y), text_style.clone()))?;
        y += row;
    }
    if let Some(b) = band {
        area.draw(&Rectangle::new(
            [(sample_x0, y - 6), (sample_x1, y + 6)],
            band_color.filled(),
        ))?;
        let label = fit_text(area, &b.label, &font, max_text);
        area.draw(&Text::new(label, (text_x, y), text_style))?;
        y += row;
    }
    // Sources missing from the plot or leaving it, named under the legend.
    let note_font = (FAMILY, 12).into_font();
    let note_style = TextStyle::from(note_font.clone())
        .color(&RGBColor(90, 90, 90))
        .pos(Pos::new(HPos::Left, VPos::Center));
    let max_note = w as i32 - sample_x0 - 2;
    for (head, names) in [("not plotted:", omitted), ("clipped at the edge:", clipped)] {
        if names.is_empty() {
            continue;
        }
        y += row / 2;
        area.draw(&Text::new(
            head.to_string(),
            (sample_x0, y),
            note_style.clone(),
        ))?;
        for n in names {
            y += row - 4;
            area.draw(&Text::new(
                fit_text(area, n, &note_font, max_note - 8),
                (sample_x0 + 8, y),
                note_style.clone(),
            ))?;
        }
        y += row - 4;
    }
    Ok(())
}

/// Shortens `text` with an ellipsis until it fits `max_px`.
fn fit_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    font: &FontDesc<'_>,
    max_px: i32,
) -> String {
    let style = TextStyle::from(font.clone());
    let width = |s: &str| {
        area.estimate_text_size(s, &style)
            .map(|(w, _)| w as i32)
            .unwrap_or(0)
    };
    if width(text) <= max_px {
        return text.to_string();
    }
    let chars: Vec<char> = text.chars().collect();
    for n in (1..chars.len()).rev() {
        let s: String = chars[..n].iter().collect::<String>() + "\u{2026}";
        if width(&s) <= max_px {
            return s;
        }
    }
    "\u{2026}".into()
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_analysis::testing as testdata;

    /// `(stroke colour, point count)` of every `<polyline>` in an SVG.
    fn polylines(svg: &str) -> Vec<(String, usize)> {
        svg.split("<polyline")
            .skip(1)
            .map(|p| {
                let attr = |name: &str| {
                    p.split(&format!(" {name}=\""))
                        .nth(1)
                        .and_then(|r| r.split('"').next())
                        .unwrap_or("")
                        .to_string()
                };
                (attr("stroke"), attr("points").split_whitespace().count())
            })
            .collect()
    }

    #[test]
    fn svg_has_the_legend_the_axis_labels_and_a_line_per_source() {
        let report = testdata::scene();
        let styles = SourceStyles::for_reports(std::slice::from_ref(&report));
        let fig = build_figure(&report, FigureKind::GoalDistance, &styles);
        let svg = fig.to_svg().unwrap();
        for text in [
            "real",
            "Alpha &lt;&amp;&gt;",
            "Beta",
            "time (s)",
            "distance to goal (m)",
            "real \u{b1} RMS spread",
        ] {
            assert!(svg.contains(text), "missing {text:?} in the SVG");
        }
        let lines = polylines(&svg);
        // The reference is solid black; the first source solid orange: one
        // polyline each with every step.
        let alpha = styles.get("Alpha <&>");
        assert_eq!(alpha.dash, None);
        for colour in ["#000000", alpha.hex().as_str()] {
            // (Axes and ticks are 2-point lines.)
            let l: Vec<&(String, usize)> =
                lines.iter().filter(|l| l.0 == colour && l.1 > 2).collect();
            assert_eq!(l.len(), 1, "{colour}: {l:?}");
            assert!(l[0].1 >= 90, "{colour}: {} points", l[0].1);
        }
        // Beta is dashed: many short pieces in its colour.
        let beta = styles.get("Beta");
        assert!(beta.dash.is_some());
        assert!(lines.iter().filter(|l| l.0 == beta.hex()).count() > 10);
        // Exactly three data colours: real, Alpha, Beta.
        let mut colours: Vec<&str> = lines
            .iter()
            .map(|l| l.0.as_str())
            .filter(|c| {
                *c == "#000000"
                    || PALETTE
                        .iter()
                        .any(|p| LineStyle { rgb: *p, ..alpha }.hex() == *c)
            })
            .collect();
        colours.sort_unstable();
        colours.dedup();
        assert_eq!(colours.len(), 3, "{colours:?}");
        assert_eq!(fig.lines.len(), 3);
        assert!(fig.band.is_some());
        assert_eq!(fig.phase_boundaries_s, [2.5]);
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    }

    #[test]
    fn a_source_without_usable_runs_is_omitted_and_named() {
        let report = testdata::scene();
        let styles = SourceStyles::for_reports(std::slice::from_ref(&report));
        for kind in [FigureKind::GoalDistance, FigureKind::ReferenceDistance] {
            let fig = build_figure(&report, kind, &styles);
            assert!(fig.lines.iter().all(|l| l.name != "Dead"));
            assert_eq!(fig.omitted.len(), 1);
            assert_eq!(fig.omitted[0].source, "Dead");
            assert!(
                fig.omitted[0]
                    .reason
                    .contains("20 of 20 left out (diverged)"),
                "{}",
                fig.omitted[0].reason
            );
            assert!(
                fig.caption.contains("Not plotted: Dead (no usable runs"),
                "{}",
                fig.caption
            );
            let svg = fig.to_svg().unwrap();
            let dead = styles.get("Dead").hex();
            assert!(
                polylines(&svg).iter().all(|l| l.0 != dead),
                "Dead's colour {dead} drawn"
            );
            assert!(svg.contains("not plotted:") && svg.contains("Dead"));
        }
        // The reference is not drawn against itself.
        let fig = build_figure(&report, FigureKind::ReferenceDistance, &styles);
        assert!(fig.lines.iter().all(|l| l.name != "real"));
        assert_eq!(fig.band.as_ref().unwrap().points[0].1, Some((0.0, 0.005)));
    }

    #[test]
    fn a_diverged_series_does_not_wreck_the_axis() {
        let mut report = testdata::scene();
        report.sources.push(testdata::source(
            "Wild",
            20,
            |t| if t < 1.0 { 0.6 } else { 1e17 },
            1e17,
        ));
        let styles = SourceStyles::for_reports(std::slice::from_ref(&report));
        let fig = build_figure(&report, FigureKind::GoalDistance, &styles);
        let (lo, hi) = fig.y_range;
        assert_eq!(lo, 0.0);
        assert!(hi > 0.6 && hi < 0.8, "y range {:?}", fig.y_range);
        assert_eq!(fig.off_scale.len(), 1);
        assert_eq!(
            (fig.off_scale[0].source.as_str(), fig.off_scale[0].max_abs),
            ("Wild", 1e17)
        );
        assert!(
            fig.caption
                .contains("Clipped at the edge of the plot: Wild (up to 1.00e17 m)"),
            "{}",
            fig.caption
        );
        // Wild is drawn up to where it leaves the plot, every point inside the image.
        let svg = fig.to_svg().unwrap();
        let wild = polylines(&svg)
            .into_iter()
            .filter(|l| l.0 == styles.get("Wild").hex())
            .count();
        assert!(wild >= 1);
        for p in svg.split(" points=\"").skip(1) {
            for xy in p.split('"').next().unwrap().split_whitespace() {
                let (x, y) = xy.split_once(',').unwrap();
                let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
                assert!(
                    (0.0..=WIDTH_PX as f64).contains(&x) && (0.0..=HEIGHT_PX as f64).contains(&y),
                    "point {x},{y}"
                );
            }
        }
    }

    #[test]
    fn png_is_a_valid_image_with_lines_and_text() {
        let report = testdata::scene();
        let styles = SourceStyles::for_reports(std::slice::from_ref(&report));
        let fig = build_figure(&report, FigureKind::GoalDistance, &styles);
        let bytes = fig.to_png().unwrap();
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (WIDTH_PX, HEIGHT_PX));
        let px = |x: u32, y: u32| {
            let i = ((y * WIDTH_PX + x) * 3) as usize;
            (buf[i], buf[i + 1], buf[i + 2])
        };
        let alpha = styles.get("Alpha <&>").rgb;
        let alpha_pixels = (0..HEIGHT_PX)
            .flat_map(|y| (0..WIDTH_PX).map(move |x| (x, y)))
            .filter(|&(x, y)| px(x, y) == alpha)
            .count();
        assert!(
            alpha_pixels > 300,
            "{alpha_pixels} pixels of Alpha's colour"
        );
        // The title is rendered text: dark pixels in the top rows.
        let dark_title = (0..24)
            .flat_map(|y| (0..WIDTH_PX).map(move |x| (x, y)))
            .filter(|&(x, y)| px(x, y).0 < 100)
            .count();
        assert!(dark_title > 50, "{dark_title} dark pixels in the title");
    }

    #[test]
    fn clipping_cuts_segments_at_the_edge_and_splits_at_gaps() {
        let pts = [
            (0.0, Some(0.0)),
            (1.0, Some(2.0)),
            (2.0, Some(0.0)),
            (3.0, None),
            (4.0, Some(0.5)),
            (5.0, Some(f64::NAN)),
            (6.0, Some(0.2)),
            (7.0, Some(0.3)),
        ];
        let pieces = clip_polyline(&pts, (0.0, 7.0), (0.0, 1.0));
        assert_eq!(pieces.len(), 3, "{pieces:?}");
        assert_eq!(pieces[0], [(0.0, 0.0), (0.5, 1.0)]);
        assert_eq!(pieces[1], [(1.5, 1.0), (2.0, 0.0)]);
        assert_eq!(pieces[2], [(6.0, 0.2), (7.0, 0.3)]);
        // A segment from far below to far above keeps its middle.
        let pieces = clip_polyline(
            &[(0.0, Some(-1e17)), (1.0, Some(1e17))],
            (0.0, 1.0),
            (0.0, 1.0),
        );
        assert_eq!(pieces.len(), 1);
        assert!((pieces[0][0].0 - 0.5).abs() < 1e-9 && (pieces[0][1].0 - 0.5).abs() < 1e-9);
    }

    #[test]
    fn kinds_follow_the_data_and_pitch_may_be_negative() {
        let mut report = testdata::scene();
        assert_eq!(
            available_kinds(&report),
            [FigureKind::GoalDistance, FigureKind::ReferenceDistance]
        );
        report.goal_m = None;
        for s in std::iter::once(&mut report.reference).chain(&mut report.sources) {
            let n = s.series.t_s.len();
            s.series.cube_displacement_m = vec![Some(0.01); n];
            s.series.cube_pitch_change_deg = (0..n).map(|i| Some(-(i as f64) * 0.9)).collect();
        }
        let kinds = available_kinds(&report);
        assert_eq!(
            kinds,
            [
                FigureKind::ReferenceDistance,
                FigureKind::CubeDisplacement,
                FigureKind::CubePitch
            ]
        );
        let fig = build_figure(
            &report,
            FigureKind::CubePitch,
            &SourceStyles::for_reports(std::slice::from_ref(&report)),
        );
        assert!(
            fig.y_range.0 < -89.0 && fig.y_range.1 >= 0.0,
            "{:?}",
            fig.y_range
        );
        assert!(fig.to_svg().unwrap().contains("pitch change (deg)"));
    }

    #[test]
    fn styles_are_stable_and_distinct() {
        let a: Vec<LineStyle> = (0..7).map(LineStyle::for_source).collect();
        for i in 0..7 {
            for j in 0..i {
                assert!(
                    a[i].rgb != a[j].rgb && a[i].marker != a[j].marker || a[i].dash != a[j].dash
                );
            }
        }
        assert_eq!(file_stem("scene 1/ä"), "scene_1__");
        assert_eq!(tick_decimals(0.8), 1);
        assert_eq!(tick_decimals(0.05), 3);
        assert_eq!(tick_decimals(90.0), 0);
    }

    #[test]
    fn handovers_of_a_drawn_source_become_ticks_in_its_colour() {
        let report = testdata::scene();
        let styles = SourceStyles::for_reports(std::slice::from_ref(&report));
        let mut fig = build_figure(&report, FigureKind::GoalDistance, &styles);
        let mark = |scene: &str, source: &str, times_s: Vec<f64>| crate::HandoverMarks {
            scene: scene.into(),
            source: source.into(),
            times_s,
        };
        fig.add_handovers(&[
            mark(&report.scene, "Beta", vec![2.5, 99.0]),
            mark("another scene", "Beta", vec![1.0]),
            mark(&report.scene, "not drawn", vec![1.0]),
        ]);
        assert_eq!(fig.handovers.len(), 1, "{:?}", fig.handovers);
        assert_eq!(fig.handovers[0].t_s, 2.5);
        assert!(
            fig.caption
                .contains("handovers from one engine to the next (Beta at 2.5 s)"),
            "{}",
            fig.caption
        );
        let svg = fig.to_svg().unwrap();
        let beta = styles.get("Beta").hex();
        let ticks = svg
            .split("<polyline")
            .filter(|p| {
                p.contains(&format!("stroke=\"{beta}\"")) && p.contains("stroke-width=\"3\"")
            })
            .count();
        assert_eq!(ticks, 1, "{svg}");
    }
}
