//! The second study's figure: the tossed cube's centre error against the
//! time from each toss's recorded first impact, one line per source, the
//! impact marked, so that flight, impact and what follows read apart.

use crate::figures::{y_range, Figure, FigureKind, Line, LineStyle};

/// One source's curve: (time from the recorded first impact, s; the mean
/// over the tosses of the centre error, cube edges) per time bin, `None`
/// where too few tosses have a sample.
#[derive(Debug, Clone, PartialEq)]
pub struct TossCurve {
    /// The source's name as the table shows it.
    pub source: String,
    /// (bin centre, s; mean error, edges).
    pub points: Vec<(f64, Option<f64>)>,
}

/// How the curves were made, for the caption.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveMaking {
    /// The bins' width, s.
    pub bin_s: f64,
    /// Tosses a bin needs at least to be drawn.
    pub min_tosses: usize,
    /// The impact phase's length from the first touch, s.
    pub impact_window_s: f64,
    /// The tosses measured.
    pub tosses: usize,
}

/// The figure of `curves` (in the table's order), its file stem
/// `tosses_centre_error`.
pub fn toss_figure(curves: &[TossCurve], making: CurveMaking) -> Figure {
    let kind = FigureKind::TossCentreError;
    let lines: Vec<Line> = curves
        .iter()
        .enumerate()
        .map(|(i, c)| Line {
            name: c.source.clone(),
            style: LineStyle::for_source(i),
            points: c.points.clone(),
        })
        .collect();
    let omitted: Vec<crate::figures::Omitted> = lines
        .iter()
        .filter(|l| !l.points.iter().any(|p| p.1.is_some_and(f64::is_finite)))
        .map(|l| crate::figures::Omitted {
            source: l.name.clone(),
            reason: "no toss measured".into(),
        })
        .collect();
    let drawn: Vec<Line> = lines
        .into_iter()
        .filter(|l| !omitted.iter().any(|o| o.source == l.name))
        .collect();
    let (y_range, off_scale) = y_range(kind, &drawn, None);
    let times = drawn
        .iter()
        .flat_map(|l| l.points.iter().filter(|p| p.1.is_some()).map(|p| p.0));
    let (x0, x1) = times.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
        (a.min(t), b.max(t))
    });
    let x_range = if x0.is_finite() && x1 > x0 {
        (x0, x1)
    } else {
        (-0.2, 1.0)
    };
    let mut caption = format!(
        "{}: per source, the mean over the {} real tosses of the cube centre's distance from the recorded one, in cube edges, against the time from each toss's recorded first impact (bins of {:.0} ms; a bin with fewer than {} tosses is left out). Left of 0 the cube flies; the dashed lines mark the impact ({:.0} ms from the first touch); after it the cube slides, tumbles and comes to rest.",
        kind.title(""),
        making.tosses,
        making.bin_s * 1e3,
        making.min_tosses,
        making.impact_window_s * 1e3
    );
    caption.push_str(&crate::figures::caption_tail(&omitted, &off_scale, "edges"));
    Figure {
        scene: "tosses".into(),
        kind,
        stem: "tosses_centre_error".into(),
        title: kind.title(""),
        x_label: "time from the recorded first impact (s)".into(),
        y_label: kind.y_label().into(),
        x_range,
        y_range,
        band: None,
        lines: drawn,
        phase_boundaries_s: vec![0.0, making.impact_window_s],
        handovers: Vec::new(),
        omitted,
        off_scale,
        caption,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(source: &str, f: impl Fn(f64) -> Option<f64>) -> TossCurve {
        TossCurve {
            source: source.into(),
            points: (0..60)
                .map(|i| {
                    let t = -0.3 + 0.02 * i as f64;
                    (t, f(t))
                })
                .collect(),
        }
    }

    const MAKING: CurveMaking = CurveMaking {
        bin_s: 0.02,
        min_tosses: 10,
        impact_window_s: 0.05,
        tosses: 456,
    };

    /// A line per measured source, the impact's two dashed lines, the
    /// axes from the data; a source with no bin is named as not plotted.
    #[test]
    fn a_line_per_source_the_impact_marked_and_an_empty_source_named() {
        let curves = [
            curve("mujoco", |t| Some(0.1 + t.max(0.0))),
            curve("physics-free", |t| Some(if t < 0.0 { 0.05 } else { 1.2 })),
            curve("broken", |_| None),
        ];
        let f = toss_figure(&curves, MAKING);
        assert_eq!(f.lines.len(), 2);
        assert_eq!(f.phase_boundaries_s, vec![0.0, 0.05]);
        assert!((f.x_range.0 + 0.3).abs() < 1e-9 && f.x_range.1 > 0.8);
        assert!(f.y_range.0 == 0.0 && f.y_range.1 >= 1.2, "{:?}", f.y_range);
        assert!(f.caption.contains("Not plotted: broken (no toss measured)"));
        assert!(f.caption.contains("456 real tosses"), "{}", f.caption);
        let svg = f.to_svg().unwrap();
        assert!(svg.contains("mujoco") && svg.contains("physics-free"));
        assert!(svg.contains("time from the recorded first impact (s)"));
        assert!(f.to_png().unwrap().starts_with(b"\x89PNG"));
    }
}
