//! A whole study: every scene evaluated with one run selection and one
//! capture-frame registration.
//!
//! 1. Per scene, the real runs are selected ([`crate::selection`]): the runs
//!    to fit on and the runs to score on.
//! 2. Per scene, the selected real runs are aligned to the scene's
//!    kinematic reference ([`crate::compare`] via [`crate::align`]); the
//!    template is fitted on the fit runs. No simulated source is read, so
//!    adding or removing one moves no start frame.
//! 3. One registration for the capture frame: estimated from the fit runs
//!    of every scene (their mean wrist at the kinematic reference's settled
//!    steps, [`crate::registration::fit_rigid`]), or given, or none (study
//!    mode).
//! 4. Per scene, the scored runs are registered and every source is scored
//!    against them, with bootstrap intervals.

use crate::align::{self, EndPolicy, RunStart};
use crate::compare::{
    align_runs, evaluate_prepared, AlignmentReport, AnalysisMode, CompareOptions,
    PreparedReference, RegistrationChoice, RegistrationReport, RunsReport, SceneReport, SceneSpec,
    SourceRuns,
};
use crate::registration::{fit_rigid, Registration, RigidFit};
use crate::selection::{SelectedRuns, SelectionError};
use realitygap_core::trajectory::WRIST;
use realitygap_core::Vec3;

/// One scene of a study, as input.
#[derive(Debug, Clone, Copy)]
pub struct SceneInput<'a> {
    /// The scene.
    pub spec: &'a SceneSpec,
    /// Its reference (the real arm).
    pub reference: &'a SourceRuns,
    /// Its sources.
    pub sources: &'a [SourceRuns],
}

/// Settled pairs farther than 3 x the median distance from the fit, but at
/// least this far, are trimmed from the registration fit, metres.
const TRIM_FLOOR_M: f64 = 0.005;

/// Settled pairs farther than this from the fit are always trimmed from the
/// registration fit, metres: a capture frame is off by millimetres, while
/// the hand resting on the cube in scene 3 puts the wrist 40 mm from the
/// kinematic reference, which is physics, not the frame.
const TRIM_CEILING_M: f64 = 0.02;

/// Evaluates every scene of a study with `opts`; an error naming the
/// argument when the run selection selects no run of a scene.
pub fn evaluate_study(
    scenes: &[SceneInput<'_>],
    opts: &CompareOptions,
) -> Result<Vec<SceneReport>, SelectionError> {
    let aligned = align_references(scenes, opts)?;
    Ok(evaluate_study_aligned(scenes, &aligned, opts))
}

/// The selected reference runs of every scene with their alignment (steps
/// 1 and 2 of the module docs). It depends on the reference runs, the
/// scenes and the options' mode, alignment and run selection only, not on
/// the registration or the sources: a caller scoring many sources against
/// the same real runs (a tune) computes it once.
pub struct AlignedReferences {
    selected: Vec<SelectedRuns>,
    aligned: Vec<Aligned>,
}

/// The start of every run of a reference and the alignment report.
type Aligned = (Vec<Option<RunStart>>, Option<AlignmentReport>);

/// Selects and aligns the reference runs of every scene; an error naming
/// the argument when the run selection selects no run of a scene.
pub fn align_references(
    scenes: &[SceneInput<'_>],
    opts: &CompareOptions,
) -> Result<AlignedReferences, SelectionError> {
    let most = scenes.iter().map(|s| s.reference.runs.len()).max();
    opts.runs.check_count(most.unwrap_or(0), "runs")?;
    let selected = scenes
        .iter()
        .map(|s| opts.runs.select(&s.spec.name, s.reference.runs.len()))
        .collect::<Result<Vec<_>, _>>()?;
    let aligned = align_selected(scenes, &selected, opts);
    Ok(AlignedReferences { selected, aligned })
}

/// [`evaluate_study`] with the reference runs already aligned by
/// [`align_references`] for the same scenes, with options that differ at
/// most in the registration and the bootstrap.
pub fn evaluate_study_aligned(
    scenes: &[SceneInput<'_>],
    aligned: &AlignedReferences,
    opts: &CompareOptions,
) -> Vec<SceneReport> {
    let prepared = prepare_aligned(scenes, &aligned.selected, aligned.aligned.clone(), opts);
    scenes
        .iter()
        .zip(prepared)
        .map(|(s, p)| evaluate_prepared(s.spec, p, s.sources, opts))
        .collect()
}

/// Aligns the selected reference runs of every scene.
fn align_selected(
    scenes: &[SceneInput<'_>],
    selected: &[SelectedRuns],
    opts: &CompareOptions,
) -> Vec<Aligned> {
    scenes
        .iter()
        .zip(selected)
        .map(|(s, sel)| {
            let n = s.reference.runs.len();
            let fit = mask(n, &sel.fit);
            let include: Vec<bool> = mask(n, &sel.score)
                .iter()
                .zip(&fit)
                .map(|(a, b)| *a || *b)
                .collect();
            align_runs(s.reference, s.spec, opts, &include, &fit)
        })
        .collect()
}

/// Aligns, registers and selects the reference runs of every scene (steps
/// 1-3 of the module docs); one prepared reference per scene, in order.
pub(crate) fn prepare_references(
    scenes: &[SceneInput<'_>],
    selected: &[SelectedRuns],
    opts: &CompareOptions,
) -> Vec<PreparedReference> {
    let aligned = align_selected(scenes, selected, opts);
    prepare_aligned(scenes, selected, aligned, opts)
}

/// Registers and selects the aligned reference runs of every scene (step
/// 3 of the module docs).
fn prepare_aligned(
    scenes: &[SceneInput<'_>],
    selected: &[SelectedRuns],
    aligned: Vec<Aligned>,
    opts: &CompareOptions,
) -> Vec<PreparedReference> {
    let starts: Vec<&[Option<RunStart>]> = aligned.iter().map(|a| a.0.as_slice()).collect();
    let registration = resolve_registration(scenes, selected, &starts, opts);
    scenes
        .iter()
        .zip(selected)
        .zip(aligned)
        .map(|((s, sel), (starts, alignment))| {
            let report = registration.as_ref().and_then(|(r, method, fit)| {
                scene_registration_report(s, sel, &starts, r, method, fit.as_ref())
            });
            let reg: Option<Registration> = registration
                .as_ref()
                .filter(|_| report.is_some())
                .map(|r| r.0);
            PreparedReference {
                runs: SourceRuns {
                    runs: sel
                        .score
                        .iter()
                        .map(|&i| {
                            let mut run = s.reference.runs[i].clone();
                            if let Some(r) = &reg {
                                r.apply_trajectory(&mut run.trajectory);
                            }
                            run
                        })
                        .collect(),
                    name: s.reference.name.clone(),
                    kind: s.reference.kind.clone(),
                    rate_hz: s.reference.rate_hz,
                    alignment: s.reference.alignment.clone(),
                },
                starts: sel.score.iter().map(|&i| starts[i].clone()).collect(),
                alignment,
                registration: report,
                runs_report: Some(runs_report(s.reference, sel, opts)),
            }
        })
        .collect()
}

/// A boolean mask of `n` entries, true at `indices`.
fn mask(n: usize, indices: &[usize]) -> Vec<bool> {
    let mut m = vec![false; n];
    for &i in indices {
        if i < n {
            m[i] = true;
        }
    }
    m
}

/// The runs used, for the report.
fn runs_report(reference: &SourceRuns, sel: &SelectedRuns, opts: &CompareOptions) -> RunsReport {
    let ids = |v: &[usize]| -> Vec<String> {
        v.iter()
            .filter_map(|&i| reference.runs.get(i).map(|r| r.id.clone()))
            .collect()
    };
    let selection = match (&opts.runs.runs, &opts.runs.holdout) {
        (None, None) => format!("all {} runs, fitted and scored on", reference.runs.len()),
        (Some(r), None) => format!("runs {} ({}), fitted and scored on", r.text, r.origin),
        (r, Some(h)) => format!(
            "fitted on runs {}, scored on held-out runs {} ({})",
            r.as_ref()
                .map_or("not held out".to_string(), |r| r.text.clone()),
            h.text,
            h.origin
        ),
    };
    RunsReport {
        selection,
        fit: ids(&sel.fit),
        scored: ids(&sel.score),
    }
}

/// The registration in force: the transform, how it was obtained, and the
/// fit when estimated. `None` in study mode, with
/// [`RegistrationChoice::None`], when no reference is a recording, or when
/// no estimate is possible (no kinematic reference, too few settled poses).
fn resolve_registration(
    scenes: &[SceneInput<'_>],
    selected: &[SelectedRuns],
    starts: &[&[Option<RunStart>]],
    opts: &CompareOptions,
) -> Option<(Registration, String, Option<RigidFit>)> {
    if opts.mode == AnalysisMode::Study || !scenes.iter().any(|s| s.reference.alignment.is_some()) {
        return None;
    }
    match &opts.registration {
        RegistrationChoice::None => None,
        RegistrationChoice::Given {
            registration,
            origin,
        } => Some((*registration, format!("given: {origin}"), None)),
        RegistrationChoice::Auto | RegistrationChoice::Estimate => {
            let (mut capture, mut world) = (Vec::new(), Vec::new());
            for ((s, sel), st) in scenes.iter().zip(selected).zip(starts) {
                let (c, w) = settled_pairs(s, st, &sel.fit);
                capture.extend(c);
                world.extend(w);
            }
            let fit = fit_rigid(&capture, &world, TRIM_FLOOR_M, TRIM_CEILING_M)?;
            let method = format!(
                "estimated from the fit runs' mean wrist at the kinematic reference's settled steps ({} pairs over {} scenes, {} trimmed as outliers)",
                fit.pairs_used + fit.pairs_trimmed,
                scenes.len(),
                fit.pairs_trimmed
            );
            Some((fit.registration, method, Some(fit)))
        }
    }
}

/// Per settled step of the scene's kinematic reference, the mean raw
/// (capture-frame) wrist position of `runs` and the reference's position.
fn settled_pairs(
    s: &SceneInput<'_>,
    starts: &[Option<RunStart>],
    runs: &[usize],
) -> (Vec<Vec3>, Vec<Vec3>) {
    let (Some(kin), true) = (&s.spec.kinematic, s.reference.alignment.is_some()) else {
        return (vec![], vec![]);
    };
    let steps = s.spec.steps.min(kin.wrist_m.len());
    let mut sum = vec![Vec3::ZERO; steps];
    let mut count = vec![0usize; steps];
    for &i in runs {
        let (Some(run), Some(Some(start))) = (s.reference.runs.get(i), starts.get(i)) else {
            continue;
        };
        let (grid, _) = align::resample(
            &run.trajectory,
            start.start_frame,
            s.reference.rate_hz,
            s.spec.control_period_s,
            steps,
            EndPolicy::Cut,
        );
        for (k, p) in grid.positions(WRIST).into_iter().enumerate() {
            if let Some(p) = p.filter(|p| p.is_finite()) {
                sum[k] = sum[k] + p;
                count[k] += 1;
            }
        }
    }
    (0..steps)
        .filter(|&k| kin.settled[k] && count[k] > 0)
        .map(|k| (sum[k].scale(1.0 / count[k] as f64), kin.wrist_m[k]))
        .unzip()
}

/// RMS distance of registered pairs, metres; `None` without pairs.
fn rms(r: &Registration, pairs: &(Vec<Vec3>, Vec<Vec3>)) -> Option<f64> {
    let n = pairs.0.len();
    (n > 0).then(|| {
        (pairs
            .0
            .iter()
            .zip(&pairs.1)
            .map(|(c, w)| r.apply(*c).distance(*w).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt()
    })
}

/// The registration as reported for one scene, with its residuals on this
/// scene's fit and scored runs. `None` when the scene's reference is not a
/// recording (nothing is registered).
fn scene_registration_report(
    s: &SceneInput<'_>,
    sel: &SelectedRuns,
    starts: &[Option<RunStart>],
    r: &Registration,
    method: &str,
    fit: Option<&RigidFit>,
) -> Option<RegistrationReport> {
    s.reference.alignment.as_ref()?;
    let fit_pairs = settled_pairs(s, starts, &sel.fit);
    let scored_pairs = settled_pairs(s, starts, &sel.score);
    let (axis, angle) = r.axis_angle_deg();
    let q = r.rotation;
    Some(RegistrationReport {
        method: method.to_string(),
        rotation_wxyz: [q.w, q.x, q.y, q.z],
        translation_m: r.translation_m.to_array(),
        rotation_deg: angle,
        rotation_axis: axis.to_array(),
        fit: fit.cloned(),
        residual_fit_rms_m: rms(r, &fit_pairs),
        residual_scored_rms_m: rms(r, &scored_pairs),
        settled_steps: fit_pairs.0.len(),
    })
}
