//! A cross-validated tune's figures: per scene, each source's error on
//! the runs it was not fitted on, against time, averaged over the folds,
//! with the schedule's phases marked. Two per scene: the wrist's distance
//! to the real wrist (what the accumulated error sums), and its height
//! minus the real wrist's (a servo that sags under gravity reads as a
//! negative height while the arm holds still).

use crate::figures::{y_range, Figure, FigureKind, Line, LineStyle, Omitted};

/// The legend's name of the physics-free model behind its fitted
/// actuator stage (a legend has room for about 18 characters).
pub const ACTUATOR_ONLY: &str = "actuator only";
/// The legend's name of the physics-free model itself.
pub const PERFECT_TRACKING: &str = "perfect tracking";

/// One source's curve: per step, its mean over the folds.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOutCurve {
    /// The source, as the cross-validation's table names it.
    pub source: String,
    /// Per step (at the scene's step times), metres; `None` where a fold
    /// has no value.
    pub values: Vec<Option<f64>>,
}

/// What the curves are, for the caption and the file names.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOutMaking<'a> {
    /// The scene.
    pub scene: &'a str,
    /// The tuned engine.
    pub engine: &'a str,
    /// The folds averaged.
    pub folds: usize,
    /// Step times, s.
    pub t_s: &'a [f64],
    /// Start times of the schedule's phases, s (the first is 0).
    pub phases_s: &'a [f64],
}

/// The figure of `kind` ([`FigureKind::HeldOutDistance`] or
/// [`FigureKind::HeldOutHeight`]) of `curves` in one scene; its file stem
/// is `crossval_<engine>_<scene>_<kind>`.
pub fn held_out_figure(kind: FigureKind, curves: &[HeldOutCurve], m: &HeldOutMaking) -> Figure {
    let lines: Vec<Line> = curves
        .iter()
        .enumerate()
        .map(|(i, c)| Line {
            name: c.source.clone(),
            style: LineStyle::for_source(i),
            points: m
                .t_s
                .iter()
                .copied()
                .zip(c.values.iter().copied())
                .collect(),
        })
        .collect();
    let omitted: Vec<Omitted> = lines
        .iter()
        .filter(|l| !l.points.iter().any(|p| p.1.is_some_and(f64::is_finite)))
        .map(|l| Omitted {
            source: l.name.clone(),
            reason: "not measured in every fold".into(),
        })
        .collect();
    let drawn: Vec<Line> = lines
        .into_iter()
        .filter(|l| !omitted.iter().any(|o| o.source == l.name))
        .collect();
    let (mut y, off_scale) = y_range(kind, &drawn, None);
    if kind == FigureKind::HeldOutHeight {
        // Above or below the real wrist must read at a glance: 0 in view.
        let pad = 0.05 * (y.1 - y.0);
        y = (y.0.min(-pad), y.1.max(pad));
    }
    let x_range = match (m.t_s.first(), m.t_s.last()) {
        (Some(a), Some(b)) if b > a => (*a, *b),
        _ => (0.0, 1.0),
    };
    let what = match kind {
        FigureKind::HeldOutHeight => {
            "the height of each source's mean wrist minus the real arm's mean wrist (negative: below it)"
        }
        _ => "the distance of each source's mean wrist to the real arm's mean wrist (its sum over the steps is the accumulated error)",
    };
    let mut caption = format!(
        "{}: on each fold's held-out real runs, {what}, averaged over the {} folds, against time; the {} was tuned and the physics-free model's actuator stage fitted on the other runs of each fold. Dashed vertical lines: the schedule's new targets.",
        kind.title(""),
        m.folds,
        m.engine
    );
    let named: Vec<String> = [
        (ACTUATOR_ONLY, "the physics-free model behind its fitted actuator stage (delay, second-order velocity loop, acceleration limit, encoder offsets)"),
        (PERFECT_TRACKING, "the physics-free model (the commanded motion, tracked perfectly)"),
    ]
    .iter()
    .filter(|(n, _)| drawn.iter().any(|l| l.name == *n))
    .map(|(n, what)| format!("'{n}' is {what}"))
    .collect();
    if !named.is_empty() {
        caption.push_str(&format!(" {}.", named.join("; ")));
    }
    caption.push_str(&crate::figures::caption_tail(&omitted, &off_scale, "m"));
    Figure {
        scene: m.scene.to_string(),
        kind,
        stem: stem(m.engine, m.scene, kind),
        title: kind.title(""),
        x_label: "time (s)".into(),
        y_label: kind.y_label().into(),
        x_range,
        y_range: y,
        band: None,
        lines: drawn,
        phase_boundaries_s: m
            .phases_s
            .iter()
            .copied()
            .filter(|t| *t > x_range.0 && *t < x_range.1)
            .collect(),
        handovers: Vec::new(),
        omitted,
        off_scale,
        caption,
    }
}

/// The file stem of a held-out figure.
pub fn stem(engine: &str, scene: &str, kind: FigureKind) -> String {
    format!("crossval_{engine}_{scene}_{}", kind.slug())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line per measured source over the scene's times, the phases
    /// inside the time range marked, the height figure's range holding 0,
    /// and a source with no value named as not plotted.
    #[test]
    fn a_line_per_source_the_phases_marked_and_zero_in_view() {
        let t: Vec<f64> = (0..100).map(|i| 0.05 * i as f64).collect();
        let m = HeldOutMaking {
            scene: "scene2_two_joints",
            engine: "mujoco",
            folds: 4,
            t_s: &t,
            phases_s: &[0.0, 2.0, 3.5],
        };
        let curves = [
            HeldOutCurve {
                source: "tuned".into(),
                values: t.iter().map(|x| Some(-0.01 - 0.002 * x)).collect(),
            },
            HeldOutCurve {
                source: ACTUATOR_ONLY.into(),
                values: t.iter().map(|x| Some(-0.002 * x)).collect(),
            },
            HeldOutCurve {
                source: "untuned".into(),
                values: vec![None; t.len()],
            },
        ];
        let f = held_out_figure(FigureKind::HeldOutHeight, &curves, &m);
        assert_eq!(f.stem, "crossval_mujoco_scene2_two_joints_held_out_height");
        assert_eq!(f.lines.len(), 2);
        assert_eq!(f.phase_boundaries_s, [2.0, 3.5]);
        assert!(
            f.y_range.0 < -0.0198 && f.y_range.1 > 0.0,
            "{:?}",
            f.y_range
        );
        assert!((f.x_range.1 - 4.95).abs() < 1e-9);
        assert!(f.caption.contains("averaged over the 4 folds"));
        assert!(f.caption.contains("Not plotted: untuned"), "{}", f.caption);
        let svg = f.to_svg().unwrap();
        assert!(svg.contains("actuator only"), "{svg}");
        assert!(f
            .caption
            .contains("'actuator only' is the physics-free model behind"));
        let distance = [HeldOutCurve {
            source: "tuned".into(),
            values: t.iter().map(|x| Some(0.01 + 0.002 * x)).collect(),
        }];
        let d = held_out_figure(FigureKind::HeldOutDistance, &distance, &m);
        assert_eq!(
            d.stem,
            "crossval_mujoco_scene2_two_joints_held_out_distance"
        );
        assert_eq!(d.y_range.0, 0.0);
        assert!(d.to_png().unwrap().starts_with(b"\x89PNG"));
    }
}
