//! One scene: a reference and several sources, evaluated into a
//! [`SceneReport`].
//!
//! The steps, in order:
//! 1. health-check every run ([`crate::health`]);
//! 2. put every run on the control grid: simulated runs are cut (or padded)
//!    to the scene's step count; recordings (the real arm) are aligned
//!    ([`crate::align`]) and resampled;
//! 3. per source, the per-step mean of the tracked bodies over its runs,
//!    leaving flagged runs out unless in [`AnalysisMode::Study`];
//! 4. the measures ([`crate::metrics`]) of each source against the
//!    reference's mean and against the goal.

use crate::align::{self, Alignment, EndPolicy, RunStart};
use crate::health::{self, HealthFlag, HealthOptions};
use crate::metrics::{self, GoalMeasures};
use crate::stats::{self, MeanTrack};
use realitygap_core::trajectory::{CUBE, WRIST};
use realitygap_core::{Quat, Trajectory, Vec3};
use serde::{Deserialize, Serialize};

/// How strictly runs are screened and recordings aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum AnalysisMode {
    /// Flagged runs are left out and listed; real runs are aligned by an
    /// estimated offset; runs that end early are cut.
    #[default]
    Default,
    /// Exactly the reference study's procedure: every run averaged in, the
    /// study file's alignment, runs that end early repeat their last sample.
    Study,
}

/// One run as input to the analysis.
#[derive(Debug, Clone)]
pub struct RunInput {
    /// Run identifier (e.g. the file stem).
    pub id: String,
    /// Its trajectory, at the source's rate.
    pub trajectory: Trajectory,
    /// Set when the producer recorded the run as failed or diverged.
    pub failed: Option<String>,
}

/// All runs of one source (an engine, the real arm, a recorded simulator).
#[derive(Debug, Clone)]
pub struct SourceRuns {
    /// Display name, e.g. `MuJoCo` or `real`.
    pub name: String,
    /// `real`, `simulated` or `recorded`.
    pub kind: String,
    /// Sample rate of the runs, Hz (20 for control-rate data, 100 for the capture).
    pub rate_hz: f64,
    /// The alignment this source needs, for recordings on their own clock
    /// (the real arm); `None` for data already on the control grid.
    pub alignment: Option<Alignment>,
    /// The runs.
    pub runs: Vec<RunInput>,
}

/// Cube measures of a scene with a cube.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CubeSpec {
    /// The cube's nominal start position, metres (scene 3: 0.5, 0, 0.0375).
    pub nominal_start_m: Option<[f64; 3]>,
    /// Displacement that counts as contact, metres. Default 5 mm.
    #[serde(default = "default_contact")]
    pub contact_threshold_m: f64,
}

fn default_contact() -> f64 {
    0.005
}

/// What the analysis needs to know of a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSpec {
    /// Scene name.
    pub name: String,
    /// Number of control steps compared.
    pub steps: usize,
    /// Control period, seconds.
    pub control_period_s: f64,
    /// Wrist position at the final target configuration, metres.
    pub goal_m: Option<[f64; 3]>,
    /// Tolerance for convergence to the goal, metres.
    pub goal_tolerance_m: f64,
    /// Start times of the schedule's phases, seconds (first is 0).
    pub phases_s: Vec<f64>,
    /// Cube measures, for scenes with a cube.
    pub cube: Option<CubeSpec>,
}

/// Options of [`evaluate_scene`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CompareOptions {
    /// Screening and alignment mode.
    pub mode: AnalysisMode,
    /// Health-check thresholds.
    pub health: HealthOptions,
    /// Alignment to use for recordings instead of the mode's default
    /// (default mode: [`Alignment::estimate`]; study mode: the source's own).
    pub alignment: Option<Alignment>,
}

/// A run with its health flags.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlaggedRun {
    /// Run identifier.
    pub run: String,
    /// Flags raised.
    pub flags: Vec<HealthFlag>,
    /// Whether the run was left out of the means.
    pub excluded: bool,
}

/// Cube measures of one source.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CubeMeasures {
    /// Mean final cube position, metres.
    pub final_position_m: [f64; 3],
    /// Mean final position minus the nominal start, metres (the study's
    /// "final displacement"; x is the push direction).
    pub final_offset_from_nominal_m: Option<[f64; 3]>,
    /// Distance of the mean final position from the mean start, metres.
    pub final_displacement_m: f64,
    /// Change of roll, pitch, yaw from start to end, degrees.
    pub rpy_change_deg: [f64; 3],
    /// Largest tilt of the cube's z axis from its start, degrees.
    pub max_tilt_deg: f64,
    /// Time the cube first moved more than the contact threshold, seconds.
    pub contact_onset_s: Option<f64>,
}

/// Per-step series of one source, for figures.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Series {
    /// Step times, seconds.
    pub t_s: Vec<f64>,
    /// Mean wrist position, metres.
    pub wrist_mean_m: Vec<Option<[f64; 3]>>,
    /// RMS spread of the runs around the mean wrist, metres.
    pub wrist_spread_m: Vec<Option<f64>>,
    /// Distance of the mean wrist to the goal, metres.
    pub wrist_distance_to_goal_m: Vec<Option<f64>>,
    /// Distance of the mean wrist to the reference's mean, metres.
    pub wrist_distance_to_reference_m: Vec<Option<f64>>,
    /// Displacement of the mean cube from its start, metres.
    pub cube_displacement_m: Vec<Option<f64>>,
    /// Cube pitch change from its start, degrees.
    pub cube_pitch_change_deg: Vec<Option<f64>>,
    /// Runs averaged at each step.
    pub runs: Vec<usize>,
}

/// The measures of one source in one scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceSummary {
    /// Source name.
    pub source: String,
    /// `real`, `simulated` or `recorded`.
    pub kind: String,
    /// Runs given.
    pub runs_total: usize,
    /// Runs averaged.
    pub runs_used: usize,
    /// Runs with flags (excluded or not).
    pub runs_flagged: Vec<FlaggedRun>,
    /// Sum over steps of the distance between this source's mean wrist and
    /// the reference's, metres (`None` for the reference itself or when
    /// either has no usable run).
    pub accumulated_error_m: Option<f64>,
    /// Steps that entered the sum.
    pub steps_compared: usize,
    /// Mean distance to the reference over the steps, metres.
    pub mean_error_m: Option<f64>,
    /// Largest distance to the reference, metres.
    pub max_error_m: Option<f64>,
    /// Distance to the reference at the last step, metres.
    pub final_error_m: Option<f64>,
    /// Accumulated error per phase of the schedule, metres.
    pub phase_errors_m: Vec<f64>,
    /// Mean geodesic angle between the wrist's world-frame rotation since
    /// the start and the reference's, degrees.
    pub orientation_error_deg: Option<f64>,
    /// Goal measures of the mean wrist.
    pub goal: Option<GoalMeasures>,
    /// Cube measures, for scenes with a cube.
    pub cube: Option<CubeMeasures>,
    /// Per-step series (for figures).
    pub series: Series,
}

/// The alignment of one recording.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlignedRun {
    /// Run identifier.
    pub run: String,
    /// The start chosen.
    #[serde(flatten)]
    pub start: RunStart,
    /// Steps with data after the start.
    pub steps_available: usize,
}

/// How the reference was aligned.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlignmentReport {
    /// Method, in words.
    pub method: String,
    /// Per run.
    pub runs: Vec<AlignedRun>,
    /// Runs that could not be aligned (no motion found), with the reason.
    pub failed: Vec<(String, String)>,
}

/// Everything measured in one scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneReport {
    /// Scene name.
    pub scene: String,
    /// Mode used.
    pub mode: AnalysisMode,
    /// Steps compared.
    pub steps: usize,
    /// Control period, seconds.
    pub control_period_s: f64,
    /// Goal position, metres.
    pub goal_m: Option<[f64; 3]>,
    /// Start times of the phases, seconds.
    pub phases_s: Vec<f64>,
    /// The reference's own measures.
    pub reference: SourceSummary,
    /// Alignment of the reference (when it is a recording).
    pub alignment: Option<AlignmentReport>,
    /// The sources' measures, in input order.
    pub sources: Vec<SourceSummary>,
}

impl SceneReport {
    /// The source with the smallest accumulated error, if any.
    pub fn closest(&self) -> Option<&SourceSummary> {
        self.sources
            .iter()
            .filter(|s| s.accumulated_error_m.is_some_and(f64::is_finite))
            .min_by(|a, b| {
                a.accumulated_error_m
                    .partial_cmp(&b.accumulated_error_m)
                    .unwrap()
            })
    }
    /// Per phase, the name of the source with the smallest error.
    pub fn closest_per_phase(&self) -> Vec<Option<String>> {
        (0..self.phases_s.len())
            .map(|i| {
                self.sources
                    .iter()
                    .filter(|s| {
                        s.accumulated_error_m.is_some()
                            && s.phase_errors_m.get(i).is_some_and(|v| v.is_finite())
                    })
                    .min_by(|a, b| a.phase_errors_m[i].total_cmp(&b.phase_errors_m[i]))
                    .map(|s| s.source.clone())
            })
            .collect()
    }
}

/// A source on the control grid: its runs resampled, their flags.
struct Gridded {
    runs: Vec<(String, Trajectory)>,
    flagged: Vec<FlaggedRun>,
    total: usize,
}

fn to_grid(
    src: &SourceRuns,
    spec: &SceneSpec,
    opts: &CompareOptions,
    template: Option<&[Vec3]>,
) -> (Gridded, Option<AlignmentReport>) {
    let end = match opts.mode {
        AnalysisMode::Study => EndPolicy::RepeatLast,
        AnalysisMode::Default => EndPolicy::Cut,
    };
    let alignment = src
        .alignment
        .as_ref()
        .map(|own| match (&opts.alignment, opts.mode) {
            (Some(a), _) => a.clone(),
            (None, AnalysisMode::Study) => own.clone(),
            (None, AnalysisMode::Default) => Alignment::estimate(),
        });
    let stride = (src.rate_hz * spec.control_period_s).round().max(1.0) as usize;
    let mut report = alignment.as_ref().map(|a| AlignmentReport {
        method: a.describe(),
        runs: vec![],
        failed: vec![],
    });
    let mut g = Gridded {
        runs: vec![],
        flagged: vec![],
        total: src.runs.len(),
    };
    for run in &src.runs {
        let mut flags = health::check(&run.trajectory, &opts.health).flags;
        if let Some(m) = &run.failed {
            flags.insert(0, HealthFlag::Failed { message: m.clone() });
        }
        let start = match (&alignment, report.as_mut()) {
            (Some(a), Some(rep)) => {
                match align::choose_start(&run.trajectory, WRIST, a, stride, template) {
                    Some(s) => Some((s, rep)),
                    None => {
                        rep.failed.push((
                            run.id.clone(),
                            "no motion onset found in the wrist track".into(),
                        ));
                        flags.push(HealthFlag::Failed {
                            message: "could not be aligned: no motion onset".into(),
                        });
                        None
                    }
                }
            }
            _ => None,
        };
        let start_frame = start.as_ref().map_or(0, |(s, _)| s.start_frame);
        let (grid, available) = align::resample(
            &run.trajectory,
            start_frame,
            src.rate_hz,
            spec.control_period_s,
            spec.steps,
            end,
        );
        if let Some((s, rep)) = start {
            rep.runs.push(AlignedRun {
                run: run.id.clone(),
                start: s,
                steps_available: available,
            });
        }
        if available < spec.steps && !run.trajectory.is_empty() {
            flags.push(HealthFlag::Short {
                samples: available,
                needed: spec.steps,
            });
        }
        let excluded = flags.iter().any(HealthFlag::excludes) || run.trajectory.is_empty();
        if !flags.is_empty() {
            g.flagged.push(FlaggedRun {
                run: run.id.clone(),
                flags,
                excluded: excluded && opts.mode == AnalysisMode::Default,
            });
        }
        if opts.mode == AnalysisMode::Study || !excluded {
            g.runs.push((run.id.clone(), grid));
        }
    }
    (g, report)
}

/// Per-source means on the grid.
struct Means {
    wrist: MeanTrack,
    wrist_rot: Vec<Option<Quat>>,
    cube: Option<MeanTrack>,
    cube_rot: Vec<Option<Quat>>,
}

fn means(g: &Gridded, steps: usize) -> Means {
    let pos = |role: &str| -> Vec<Vec<Option<Vec3>>> {
        g.runs.iter().map(|(_, t)| t.positions(role)).collect()
    };
    let rot = |role: &str| -> Vec<Vec<Option<Quat>>> {
        g.runs
            .iter()
            .map(|(_, t)| {
                t.body(role)
                    .map(|b| b.poses.iter().map(|p| p.map(|p| p.orientation)).collect())
                    .unwrap_or_default()
            })
            .collect()
    };
    let has_cube = g.runs.iter().any(|(_, t)| t.body(CUBE).is_some());
    Means {
        wrist: stats::mean_positions(&pos(WRIST), steps),
        wrist_rot: stats::mean_orientations(&rot(WRIST), steps),
        cube: has_cube.then(|| stats::mean_positions(&pos(CUBE), steps)),
        cube_rot: stats::mean_orientations(&rot(CUBE), steps),
    }
}

fn cube_measures(
    m: &Means,
    spec: &SceneSpec,
    cube: &CubeSpec,
    series: &mut Series,
) -> Option<CubeMeasures> {
    let track = m.cube.as_ref()?;
    let start = track.mean_m.iter().flatten().next().copied()?;
    let end = track.mean_m.iter().rev().flatten().next().copied()?;
    let disp = metrics::displacement_series(&track.mean_m, start);
    let q0 = m.cube_rot.iter().flatten().next().copied();
    let q1 = m.cube_rot.iter().rev().flatten().next().copied();
    series.cube_displacement_m = disp.clone();
    series.cube_pitch_change_deg = match q0 {
        Some(q0) => m
            .cube_rot
            .iter()
            .map(|q| q.map(|q| metrics::rpy_change_deg(q0, q)[1]))
            .collect(),
        None => vec![None; m.cube_rot.len()],
    };
    let max_tilt = match q0 {
        Some(q0) => m
            .cube_rot
            .iter()
            .flatten()
            .map(|q| metrics::tilt_deg(q0, *q))
            .fold(0.0, f64::max),
        None => 0.0,
    };
    Some(CubeMeasures {
        final_position_m: end.to_array(),
        final_offset_from_nominal_m: cube
            .nominal_start_m
            .map(|n| (end - Vec3::from_array(n)).to_array()),
        final_displacement_m: end.distance(start),
        rpy_change_deg: match (q0, q1) {
            (Some(a), Some(b)) => metrics::rpy_change_deg(a, b),
            _ => [f64::NAN; 3],
        },
        max_tilt_deg: max_tilt,
        contact_onset_s: metrics::first_exceeding(&disp, cube.contact_threshold_m)
            .map(|i| i as f64 * spec.control_period_s),
    })
}

fn summarize(
    src: &SourceRuns,
    g: &Gridded,
    m: &Means,
    spec: &SceneSpec,
    reference: Option<&Means>,
) -> SourceSummary {
    let t_s: Vec<f64> = (0..spec.steps)
        .map(|i| i as f64 * spec.control_period_s)
        .collect();
    let goal = spec.goal_m.map(Vec3::from_array);
    let mut series = Series {
        t_s,
        wrist_mean_m: m
            .wrist
            .mean_m
            .iter()
            .map(|p| p.map(Vec3::to_array))
            .collect(),
        wrist_spread_m: m.wrist.spread_m.clone(),
        wrist_distance_to_goal_m: goal
            .map(|g| metrics::distance_to_point(&m.wrist.mean_m, g))
            .unwrap_or_default(),
        runs: m.wrist.runs.clone(),
        ..Series::default()
    };
    let mut out = SourceSummary {
        source: src.name.clone(),
        kind: src.kind.clone(),
        runs_total: g.total,
        runs_used: g.runs.len(),
        runs_flagged: g.flagged.clone(),
        accumulated_error_m: None,
        steps_compared: 0,
        mean_error_m: None,
        max_error_m: None,
        final_error_m: None,
        phase_errors_m: vec![],
        orientation_error_deg: None,
        goal: goal.map(|g| {
            metrics::goal_measures(
                &m.wrist.mean_m,
                g,
                spec.goal_tolerance_m,
                spec.control_period_s,
            )
        }),
        cube: None,
        series: Series::default(),
    };
    if let Some(r) = reference {
        let d = metrics::distance_series(&m.wrist.mean_m, &r.wrist.mean_m);
        let (sum, n) = metrics::accumulate(&d);
        if n > 0 {
            out.accumulated_error_m = Some(sum);
            out.steps_compared = n;
            out.mean_error_m = Some(sum / n as f64);
            out.max_error_m = d.iter().flatten().copied().reduce(f64::max);
            out.final_error_m = metrics::last_value(&d);
            let bounds: Vec<usize> = spec
                .phases_s
                .iter()
                .map(|t| (t / spec.control_period_s).round() as usize)
                .chain([spec.steps])
                .collect();
            out.phase_errors_m = bounds
                .windows(2)
                .map(|w| metrics::accumulate_range(&d, w[0]..w[1]))
                .collect();
            out.orientation_error_deg = metrics::mean_angle_deg(
                &metrics::rotation_since_start(&m.wrist_rot),
                &metrics::rotation_since_start(&r.wrist_rot),
            );
        }
        series.wrist_distance_to_reference_m = d;
    }
    if let Some(c) = &spec.cube {
        out.cube = cube_measures(m, spec, c, &mut series);
    }
    out.series = series;
    out
}

/// Evaluates one scene: the reference and every source, as the module docs
/// describe. The template for estimated alignment is the mean, over the
/// sources that are on the control grid and have usable runs, of their mean
/// wrist tracks.
pub fn evaluate_scene(
    spec: &SceneSpec,
    reference: &SourceRuns,
    sources: &[SourceRuns],
    opts: &CompareOptions,
) -> SceneReport {
    // Sources first: they give the template for the reference's alignment.
    let gridded: Vec<(Gridded, Option<AlignmentReport>)> = sources
        .iter()
        .map(|s| to_grid(s, spec, opts, None))
        .collect();
    let src_means: Vec<Means> = gridded.iter().map(|(g, _)| means(g, spec.steps)).collect();
    let template = template(&src_means, sources, spec.steps);
    let (ref_g, alignment) = to_grid(reference, spec, opts, template.as_deref());
    let ref_means = means(&ref_g, spec.steps);
    let sources_out = sources
        .iter()
        .zip(&gridded)
        .zip(&src_means)
        .map(|((s, (g, _)), m)| summarize(s, g, m, spec, Some(&ref_means)))
        .collect();
    SceneReport {
        scene: spec.name.clone(),
        mode: opts.mode,
        steps: spec.steps,
        control_period_s: spec.control_period_s,
        goal_m: spec.goal_m,
        phases_s: spec.phases_s.clone(),
        reference: summarize(reference, &ref_g, &ref_means, spec, None),
        alignment,
        sources: sources_out,
    }
}

/// Mean over control-grid sources of their complete mean wrist tracks.
fn template(means: &[Means], sources: &[SourceRuns], steps: usize) -> Option<Vec<Vec3>> {
    let full: Vec<Vec<Vec3>> = means
        .iter()
        .zip(sources)
        .filter(|(_, s)| s.alignment.is_none())
        .filter_map(|(m, _)| {
            m.wrist
                .mean_m
                .iter()
                .copied()
                .collect::<Option<Vec<Vec3>>>()
        })
        .filter(|t| {
            t.len() == steps && steps > 0 && t.iter().all(|p| p.is_finite() && p.norm() < 10.0)
        })
        .collect();
    if full.is_empty() {
        return None;
    }
    let n = full.len() as f64;
    Some(
        (0..steps)
            .map(|i| full.iter().fold(Vec3::ZERO, |a, t| a + t[i]).scale(1.0 / n))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::Pose;

    /// A run on the control grid: the wrist moves along x from 0 to `reach`
    /// over `move_steps`, then rests; z = 0.8.
    fn run(
        id: &str,
        steps: usize,
        rate_steps_per_control: usize,
        rest: usize,
        reach: f64,
        offset: f64,
    ) -> RunInput {
        let mut t = Trajectory::with_bodies(&[WRIST]);
        let n = (steps + 20) * rate_steps_per_control + rest;
        for i in 0..n {
            t.time_s
                .push(i as f64 * 0.05 / rate_steps_per_control as f64);
            let k = i.saturating_sub(rest) as f64 / rate_steps_per_control as f64;
            // A slow drift keeps the rest from being bit-identical (frozen).
            let x = offset + reach * (k / 40.0).min(1.0) + 1e-6 * k;
            t.bodies[0]
                .poses
                .push(Some(Pose::new(Vec3::new(x, 0.0, 0.8), Quat::IDENTITY)));
        }
        RunInput {
            id: id.into(),
            trajectory: t,
            failed: None,
        }
    }

    fn spec() -> SceneSpec {
        SceneSpec {
            name: "s".into(),
            steps: 100,
            control_period_s: 0.05,
            goal_m: Some([0.5, 0.0, 0.8]),
            goal_tolerance_m: 0.01,
            phases_s: vec![0.0, 2.5],
            cube: None,
        }
    }

    #[test]
    fn identical_sources_have_zero_error_and_estimate_finds_the_onset() {
        let sim = SourceRuns {
            name: "sim".into(),
            kind: "recorded".into(),
            rate_hz: 20.0,
            alignment: None,
            runs: vec![run("a", 100, 1, 0, 0.5, 0.0), run("b", 100, 1, 0, 0.5, 0.0)],
        };
        // The real arm starts moving 173 frames in, at 100 Hz.
        let real = SourceRuns {
            name: "real".into(),
            kind: "real".into(),
            rate_hz: 100.0,
            alignment: Some(Alignment::Onset {
                lead_frames: 0,
                rest_frames: (20, 100),
                threshold_m: 0.01,
            }),
            runs: vec![run("r1", 100, 5, 173, 0.5, 0.0)],
        };
        let rep = evaluate_scene(&spec(), &real, &[sim.clone()], &CompareOptions::default());
        assert_eq!(
            rep.alignment.as_ref().unwrap().runs[0].start.start_frame,
            173
        );
        let s = &rep.sources[0];
        assert!(
            s.accumulated_error_m.unwrap() < 1e-9,
            "{:?}",
            s.accumulated_error_m
        );
        assert_eq!(s.runs_used, 2);
        assert_eq!(s.phase_errors_m.len(), 2);
        assert!(s.goal.as_ref().unwrap().final_distance_m.unwrap() < 1e-3);
        assert!(rep.reference.accumulated_error_m.is_none());
        assert_eq!(rep.closest().unwrap().source, "sim");
    }

    #[test]
    fn flagged_runs_are_excluded_by_default_and_kept_in_study_mode() {
        let mut bad = run("bad", 100, 1, 0, 0.5, 0.0);
        bad.trajectory.bodies[0].poses[50]
            .as_mut()
            .unwrap()
            .position_m
            .x = 1e17;
        let sim = SourceRuns {
            name: "sim".into(),
            kind: "recorded".into(),
            rate_hz: 20.0,
            alignment: None,
            runs: vec![run("a", 100, 1, 0, 0.5, 0.0), bad],
        };
        let reference = SourceRuns {
            name: "ref".into(),
            runs: vec![run("r", 100, 1, 0, 0.5, 0.0)],
            ..sim.clone()
        };
        let rep = evaluate_scene(
            &spec(),
            &reference,
            &[sim.clone()],
            &CompareOptions::default(),
        );
        let s = &rep.sources[0];
        assert_eq!((s.runs_used, s.runs_flagged.len()), (1, 1));
        assert!(s.runs_flagged[0].excluded);
        assert_eq!(s.runs_flagged[0].flags[0].name(), "diverged");
        let study = CompareOptions {
            mode: AnalysisMode::Study,
            ..Default::default()
        };
        let rep = evaluate_scene(&spec(), &reference, &[sim], &study);
        assert_eq!(rep.sources[0].runs_used, 2);
        assert!(rep.sources[0].accumulated_error_m.unwrap() > 1e15);
    }
}
