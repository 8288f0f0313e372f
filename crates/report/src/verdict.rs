//! The report's first section: the verdict in sentences, generated from the
//! numbers of the comparison (never written by hand).
//!
//! Per scene: the closest source with its interval, the closest engine
//! simulated here, and per phase of the schedule which source is closest and
//! whether that phase is contact (the reference's cube moves during it),
//! motion against gravity (the reference's wrist rises or falls more than
//! 5 cm) or free motion. Then, over all scenes, whether any
//! engine beats the physics-free model (perfect tracking through forward
//! kinematics): the paired bootstrap difference of the two accumulated
//! errors, with its interval and the probability that the engine is closer.

use realitygap_analysis::bootstrap::Interval;
use realitygap_analysis::compare::{fmt_interval, SceneReport, SourceSummary};

/// Sources whose name starts with this are the physics-free model.
pub const PHYSICS_FREE_PREFIX: &str = "physics-free";

/// Whether a source is the physics-free model.
pub fn is_physics_free(source: &str) -> bool {
    source.starts_with(PHYSICS_FREE_PREFIX)
}

/// An engine simulated by this tool (not a recording, not the baseline).
fn is_engine(s: &SourceSummary) -> bool {
    s.kind == "simulated" && !is_physics_free(&s.source)
}

/// The verdict: one paragraph per scene and the overall sentences.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Verdict {
    /// Sentences about all scenes together.
    pub overall: Vec<String>,
    /// Per scene: its name and its sentences.
    pub scenes: Vec<(String, Vec<String>)>,
}

fn with_interval(v: f64, i: Option<Interval>) -> String {
    match i {
        Some(_) => format!("{v:.2} m {}", fmt_interval(i)),
        None => format!("{v:.2} m"),
    }
}

fn usable(s: &SourceSummary) -> Option<f64> {
    s.accumulated_error_m.filter(|v| v.is_finite())
}

fn best<'a>(it: impl Iterator<Item = &'a SourceSummary>) -> Option<(&'a SourceSummary, f64)> {
    it.filter_map(|s| usable(s).map(|v| (s, v)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Percentile of sorted values (nearest rank).
/// The paired bootstrap comparison of `a` against `b` summed over scenes:
/// (difference a - b, 95 % interval, probability a < b), when both have
/// replicates in every scene.
fn paired(
    reports: &[SceneReport],
    a: &str,
    b: &str,
) -> Option<(f64, Option<Interval>, Option<f64>)> {
    let mut diff = 0.0;
    let mut reps: Option<Vec<f64>> = Some(Vec::new());
    for r in reports {
        let sa = r.sources.iter().find(|s| s.source == a)?;
        let sb = r.sources.iter().find(|s| s.source == b)?;
        diff += usable(sa)? - usable(sb)?;
        let (ra, rb) = (&sa.bootstrap_replicates_m, &sb.bootstrap_replicates_m);
        match reps.as_mut() {
            Some(v) if !ra.is_empty() && ra.len() == rb.len() => {
                if v.is_empty() {
                    v.resize(ra.len(), 0.0);
                }
                if v.len() != ra.len() {
                    reps = None;
                    continue;
                }
                for (k, x) in v.iter_mut().enumerate() {
                    *x += ra[k] - rb[k];
                }
            }
            _ => reps = None,
        }
    }
    match reps.filter(|v| !v.is_empty()) {
        Some(v) => {
            let p = v.iter().filter(|d| **d < 0.0).count() as f64 / v.len() as f64;
            let i = realitygap_analysis::bootstrap::percentile_interval(
                &v,
                realitygap_analysis::bootstrap::BootstrapOptions::default().level,
            );
            Some((diff, i, Some(p)))
        }
        None => Some((diff, None, None)),
    }
}

/// Whether the reference's cube moves during each phase (more than the
/// displacement that counts as contact, 5 mm, from the phase's start).
fn contact_phases(r: &SceneReport) -> Vec<bool> {
    let disp = &r.reference.series.cube_displacement_m;
    let t = &r.reference.series.t_s;
    (0..r.phases_s.len())
        .map(|i| {
            if disp.is_empty() {
                return false;
            }
            let start = r.phases_s[i];
            let end = r.phases_s.get(i + 1).copied().unwrap_or(f64::INFINITY);
            let vals: Vec<f64> = t
                .iter()
                .zip(disp)
                .filter(|(t, _)| **t >= start && **t < end)
                .filter_map(|(_, d)| *d)
                .collect();
            match (vals.first(), vals.iter().copied().reduce(f64::max)) {
                (Some(first), Some(max)) => max - first > 0.005,
                _ => false,
            }
        })
        .collect()
}

/// Whether the reference's wrist rises or falls more than 5 cm during each
/// phase: the arm's weight moves against gravity.
fn vertical_phases(r: &SceneReport) -> Vec<bool> {
    let w = &r.reference.series.wrist_mean_m;
    let t = &r.reference.series.t_s;
    (0..r.phases_s.len())
        .map(|i| {
            let start = r.phases_s[i];
            let end = r.phases_s.get(i + 1).copied().unwrap_or(f64::INFINITY);
            let z: Vec<f64> = t
                .iter()
                .zip(w)
                .filter(|(t, _)| **t >= start && **t < end)
                .filter_map(|(_, p)| p.map(|p| p[2]))
                .collect();
            let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            hi - lo > 0.05
        })
        .collect()
}

/// Builds the verdict of a set of scene reports.
pub fn verdict(reports: &[SceneReport]) -> Verdict {
    let mut v = Verdict::default();
    let reference = reports
        .first()
        .map(|r| r.reference.source.clone())
        .unwrap_or_default();
    for r in reports {
        let mut lines = Vec::new();
        match best(r.sources.iter()) {
            Some((s, e)) => {
                let mut line = format!(
                    "The closest source to {reference} is {}, {}",
                    s.source,
                    with_interval(e, s.accumulated_error_interval_m)
                );
                match &r.closest_comparison {
                    Some(c) if c.distinguishable => line.push_str(&format!(
                        "; it is closer than {} with probability {:.3}.",
                        c.runner_up, c.probability_closer
                    )),
                    Some(c) => line.push_str(&format!(
                        "; it cannot be told apart from {} (probability {:.3} that it is closer).",
                        c.runner_up, c.probability_closer
                    )),
                    None => line.push('.'),
                }
                lines.push(line);
                if !is_engine(s) {
                    if let Some((e_s, e_v)) = best(r.sources.iter().filter(|s| is_engine(s))) {
                        lines.push(format!(
                            "Of the engines simulated here, {} is closest, {}.",
                            e_s.source,
                            with_interval(e_v, e_s.accumulated_error_interval_m)
                        ));
                    }
                }
            }
            None => lines.push("No source could be compared in this scene.".into()),
        }
        let contact = contact_phases(r);
        let vertical = vertical_phases(r);
        let phases: Vec<String> = (0..r.phases_s.len())
            .filter_map(|i| {
                let (s, e) = r
                    .sources
                    .iter()
                    .filter_map(|s| s.phase_errors_m.get(i).map(|e| (s, *e)))
                    .filter(|(_, e)| e.is_finite())
                    .min_by(|a, b| a.1.total_cmp(&b.1))?;
                let engine = r
                    .sources
                    .iter()
                    .filter(|s| is_engine(s))
                    .filter_map(|s| s.phase_errors_m.get(i).map(|e| (s, *e)))
                    .filter(|(_, e)| e.is_finite())
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                let kind = if contact[i] {
                    "contact"
                } else if vertical[i] {
                    "against gravity"
                } else {
                    "free motion"
                };
                let mut text = format!(
                    "phase {} ({kind}, from {:.1} s): {} ({e:.2} m)",
                    i + 1,
                    r.phases_s[i],
                    s.source
                );
                if let Some((es, ee)) = engine.filter(|(es, _)| es.source != s.source) {
                    text.push_str(&format!(", best engine {} ({ee:.2} m)", es.source));
                }
                Some(text)
            })
            .collect();
        if !phases.is_empty() {
            lines.push(format!("Closest per phase: {}.", phases.join("; ")));
        }
        if contact.iter().any(|c| *c) {
            if let (Some(real), true) = (r.reference.cube.as_ref(), r.reference.kind == "real") {
                let pushes: Vec<String> = r
                    .sources
                    .iter()
                    .filter(|s| is_engine(s))
                    .filter_map(|s| {
                        s.cube
                            .as_ref()
                            .map(|c| format!("{} {:.3} m", s.source, c.final_displacement_m))
                    })
                    .collect();
                if !pushes.is_empty() {
                    lines.push(format!(
                        "In contact the real cube ends {:.3} m from its start; the engines move it: {}.",
                        real.final_displacement_m,
                        pushes.join(", ")
                    ));
                }
            }
        }
        v.scenes.push((r.scene.clone(), lines));
    }

    // Over all scenes.
    let names = realitygap_analysis::table::source_names(reports);
    let totals: Vec<(String, f64)> = names
        .iter()
        .filter_map(|n| realitygap_analysis::table::total(reports, n).map(|t| (n.clone(), t)))
        .filter(|(_, t)| t.is_finite())
        .collect();
    let kind_of = |n: &str| {
        reports
            .iter()
            .find_map(|r| r.sources.iter().find(|s| s.source == n))
            .map(|s| s.kind.clone())
            .unwrap_or_default()
    };
    let engines: Vec<&(String, f64)> = totals
        .iter()
        .filter(|(n, _)| kind_of(n) == "simulated" && !is_physics_free(n))
        .collect();
    if let Some((n, t)) = totals.iter().min_by(|a, b| a.1.total_cmp(&b.1)) {
        v.overall.push(format!(
            "Over all {} scenes the closest source is {n}, {}.",
            reports.len(),
            with_interval(*t, realitygap_analysis::table::total_interval(reports, n))
        ));
    }
    let baseline = totals.iter().find(|(n, _)| is_physics_free(n));
    match (baseline, engines.iter().min_by(|a, b| a.1.total_cmp(&b.1))) {
        (Some((b, bt)), Some((e, et))) => {
            let (diff, interval, p) = paired(reports, e, b).unwrap_or((et - bt, None, None));
            let detail = match (interval, p) {
                (Some(i), Some(p)) => format!(
                    "difference {diff:+.3} m, 95 % interval {}, probability {p:.3} that the engine is closer",
                    fmt_interval(Some(i))
                ),
                _ => format!("difference {diff:+.3} m"),
            };
            let beaten_everywhere = interval.is_some_and(|i| i.high_m < 0.0);
            let sentence = if beaten_everywhere {
                format!(
                    "{e} beats the physics-free model (perfect tracking, {bt:.2} m): {et:.2} m ({detail})."
                )
            } else if diff < 0.0 {
                format!(
                    "The best engine, {e} ({et:.2} m), is ahead of the physics-free model ({bt:.2} m) but not beyond doubt ({detail})."
                )
            } else {
                format!(
                    "No engine beats the physics-free model (perfect tracking through forward kinematics, {bt:.2} m): the best, {e}, is {et:.2} m ({detail})."
                )
            };
            v.overall.push(sentence);
        }
        (None, Some((e, et))) => v.overall.push(format!(
            "The closest engine simulated here is {e}, {et:.2} m (the physics-free model was not run: add --engine ideal to compare with it)."
        )),
        _ => {}
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_analysis::testing as testdata;

    #[test]
    fn the_verdict_names_the_closest_and_compares_with_the_baseline() {
        let mut r = testdata::scene();
        // Make one source the physics-free model, simulated.
        for s in &mut r.sources {
            s.kind = "simulated".into();
        }
        let names: Vec<String> = r.sources.iter().map(|s| s.source.clone()).collect();
        r.sources[0].source = "physics-free (this tool)".into();
        let v = verdict(std::slice::from_ref(&r));
        assert_eq!(v.scenes.len(), 1);
        let all = v.overall.join(" ");
        assert!(all.contains("physics-free"), "{all}");
        assert!(
            all.contains("beats") || all.contains("No engine") || all.contains("ahead"),
            "{all}"
        );
        // The scene's lines name a source that exists.
        let scene = v.scenes[0].1.join(" ");
        assert!(
            names.iter().skip(1).any(|n| scene.contains(n.as_str()))
                || scene.contains("physics-free"),
            "{scene}"
        );
    }

    #[test]
    fn paired_differences_come_from_the_replicates() {
        let mut r = testdata::scene();
        r.sources[0].accumulated_error_m = Some(1.0);
        r.sources[1].accumulated_error_m = Some(2.0);
        r.sources[0].bootstrap_replicates_m = vec![1.0, 1.1, 0.9, 1.2];
        r.sources[1].bootstrap_replicates_m = vec![2.0, 0.5, 2.2, 2.1];
        let a = r.sources[0].source.clone();
        let b = r.sources[1].source.clone();
        let (d, i, p) = paired(std::slice::from_ref(&r), &a, &b).unwrap();
        assert!((d + 1.0).abs() < 1e-12);
        assert_eq!(p, Some(0.75));
        let i = i.unwrap();
        // The 2.5 % and 97.5 % quantiles of -1.3, -1.0, -0.9, 0.6 (interpolated).
        assert!(i.low_m < -1.25 && i.high_m > 0.45, "{i:?}");
    }
}
