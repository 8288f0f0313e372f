//! One scene: a reference and several sources, evaluated into a
//! [`SceneReport`].
//!
//! The steps, in order:
//! 1. health-check every run ([`crate::health`]);
//! 2. put every run on the control grid: simulated runs are cut (or padded)
//!    to the scene's step count; recordings (the real arm) are aligned
//!    ([`crate::align`]) from the recordings and the scene's kinematic
//!    reference alone, registered into the world
//!    ([`crate::registration`]) and resampled;
//! 3. per source, the per-step mean of the tracked bodies over its runs,
//!    leaving flagged runs out unless in [`AnalysisMode::Study`];
//! 4. the measures ([`crate::metrics`]) of each source against the
//!    reference's mean and against the goal, the lag of each source behind
//!    the kinematic reference, and the bootstrap intervals
//!    ([`crate::bootstrap`]).
//!
//! [`crate::study::evaluate_study`] runs this for every scene of a study
//! with one registration and one run selection; [`evaluate_scene`] is the
//! same for a single scene.

use crate::align::{self, Alignment, EndPolicy, RunStart};
use crate::bootstrap::{self, BootstrapOptions, Interval, PairedComparison, RunTracks};
use crate::health::{self, HealthFlag, HealthOptions};
use crate::kinematic::KinematicTrack;
use crate::metrics::{self, GoalMeasures};
use crate::registration::{Registration, RigidFit};
use crate::selection::RunSelection;
use crate::stats::{self, MeanTrack};
use realitygap_core::instability::Instability;
use realitygap_core::trajectory::{CUBE, WRIST};
use realitygap_core::{Quat, Trajectory, Vec3};
use serde::{Deserialize, Serialize};

/// How strictly runs are screened and recordings aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum AnalysisMode {
    /// Flagged runs are left out and listed; real runs are aligned to the
    /// scene's kinematic reference and registered into the world frame;
    /// runs that end early are cut; accumulated errors carry bootstrap
    /// intervals.
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
    /// The scene's kinematic reference (perfect velocity tracking through
    /// forward kinematics, [`crate::kinematic`]), when the scene file is
    /// known: what the real runs are aligned to, the registration is fitted
    /// against and every source's lag is measured from.
    #[serde(skip)]
    pub kinematic: Option<KinematicTrack>,
}

/// Which capture-frame registration to apply to recordings.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum RegistrationChoice {
    /// The mode's default: [`RegistrationChoice::Estimate`] in default mode,
    /// [`RegistrationChoice::None`] in study mode.
    #[default]
    Auto,
    /// Keep the raw capture frame.
    None,
    /// Estimate from the fit runs' settled poses against the kinematic
    /// reference.
    Estimate,
    /// Apply this transform (e.g. read from `registration.json`).
    Given {
        /// The transform.
        registration: Registration,
        /// Where it came from (the file), for the report.
        origin: String,
    },
}

/// Options of [`evaluate_scene`] and [`crate::study::evaluate_study`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CompareOptions {
    /// Screening and alignment mode.
    pub mode: AnalysisMode,
    /// Health-check thresholds.
    pub health: HealthOptions,
    /// Alignment to use for recordings instead of the mode's default
    /// (default mode: [`Alignment::estimate`]; study mode: the source's own).
    pub alignment: Option<Alignment>,
    /// Capture-frame registration of the recordings (never applied in
    /// study mode, which keeps the raw capture frame as the study did).
    pub registration: RegistrationChoice,
    /// Which real runs to fit on and to score on (default: all, both).
    pub runs: RunSelection,
    /// Bootstrap settings; `None` is the mode's default (1000 resamples in
    /// default mode, none in study mode).
    pub bootstrap: Option<BootstrapOptions>,
}

impl CompareOptions {
    /// The bootstrap settings in force (`None`: no intervals).
    pub fn bootstrap_in_force(&self) -> Option<BootstrapOptions> {
        match (self.bootstrap, self.mode) {
            (Some(b), _) if b.resamples > 0 => Some(b),
            (Some(_), _) | (None, AnalysisMode::Study) => None,
            (None, AnalysisMode::Default) => Some(BootstrapOptions::default()),
        }
    }
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
    /// Mean cube position, metres (empty without a cube).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cube_mean_m: Vec<Option<[f64; 3]>>,
    /// Mean cube orientation as a unit quaternion `[w, x, y, z]` (empty
    /// without a cube).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cube_mean_quat: Vec<Option<[f64; 4]>>,
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
    /// 95 % bootstrap interval of the accumulated error, metres (over the
    /// real runs, and over this source's runs when they differ).
    pub accumulated_error_interval_m: Option<Interval>,
    /// Whether the bootstrap drew this source's own runs too (they are not
    /// all identical).
    pub bootstrap_over_source_runs: bool,
    /// Bootstrap replicates of the accumulated error, metres (paired with
    /// every other source's by index; not serialised).
    #[serde(skip)]
    pub bootstrap_replicates_m: Vec<f64>,
    /// Time by which this source's mean wrist motion trails the scene's
    /// kinematic reference, seconds (positive: behind). A measure only: it
    /// is never used to shift the source.
    pub lag_s: Option<f64>,
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
    /// What the run is used for: `fit`, `score` or `fit+score`.
    pub used_for: String,
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
    /// Frames the group of runs was moved by to match the kinematic
    /// reference, after the runs were aligned to each other.
    pub group_shift_frames: Option<i64>,
}

/// The capture-frame registration applied to the reference's recordings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RegistrationReport {
    /// How it was obtained, in words.
    pub method: String,
    /// `world = R * capture + t`: R as a unit quaternion w, x, y, z.
    pub rotation_wxyz: [f64; 4],
    /// t, metres.
    pub translation_m: [f64; 3],
    /// Rotation angle, degrees.
    pub rotation_deg: f64,
    /// Rotation axis (unit vector, capture frame).
    pub rotation_axis: [f64; 3],
    /// The fit over all scenes' fit runs (absent for a given file).
    pub fit: Option<RigidFit>,
    /// RMS distance, after registration, between the fit runs' mean wrist
    /// and the kinematic reference at this scene's settled steps, metres.
    pub residual_fit_rms_m: Option<f64>,
    /// The same over the scored runs (the held-out runs when some are held
    /// out), metres.
    pub residual_scored_rms_m: Option<f64>,
    /// Settled steps of this scene that entered the residuals.
    pub settled_steps: usize,
}

impl RegistrationReport {
    /// The transform reported.
    pub fn registration(&self) -> Registration {
        let q = self.rotation_wxyz;
        Registration {
            rotation: Quat::new(q[0], q[1], q[2], q[3]),
            translation_m: Vec3::from_array(self.translation_m),
        }
    }
}

/// Which real runs the scene used.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunsReport {
    /// The selection, in words (e.g. `fit on runs 1-15, scored on 16-20`).
    pub selection: String,
    /// Runs fitted on (alignment template, registration), by identifier.
    pub fit: Vec<String>,
    /// Runs the sources were scored against, by identifier.
    pub scored: Vec<String>,
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
    /// The registration of the reference's recordings, when one was applied.
    pub registration: Option<RegistrationReport>,
    /// The real runs used.
    pub runs: Option<RunsReport>,
    /// The bootstrap settings, when intervals were computed.
    pub bootstrap: Option<BootstrapOptions>,
    /// The closest source against the runner-up, over the bootstrap
    /// replicates.
    pub closest_comparison: Option<PairedComparison>,
}

/// An interval as `[low, high]` in metres with 3 decimals, or `n/a`.
pub fn fmt_interval(i: Option<Interval>) -> String {
    i.map_or("n/a".into(), |i| {
        format!("[{:.3}, {:.3}]", i.low_m, i.high_m)
    })
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
    /// The closest source when it can be told apart from the runner-up (or
    /// no interval was computed); `None` when the two cannot be told apart
    /// or there is no source.
    pub fn winner(&self) -> Option<&SourceSummary> {
        match &self.closest_comparison {
            Some(c) if !c.distinguishable => None,
            _ => self.closest(),
        }
    }
    /// One sentence on the closest source: its name and the probability
    /// that it is closer than the runner-up, or that the two cannot be told
    /// apart.
    pub fn verdict(&self) -> String {
        let Some(best) = self.closest() else {
            return "no source could be compared".into();
        };
        match &self.closest_comparison {
            None => format!("closest source: {}", best.source),
            Some(c) if c.distinguishable => format!(
                "closest source: {} (closer than {} with probability {:.3}; difference {:.3} m, 95 % interval {})",
                c.closest,
                c.runner_up,
                c.probability_closer,
                c.difference_m,
                fmt_interval(c.difference_interval_m)
            ),
            Some(c) => format!(
                "{} and {} cannot be told apart (probability {:.3} that {} is closer; difference {:.3} m, 95 % interval {})",
                c.closest,
                c.runner_up,
                c.probability_closer,
                c.closest,
                c.difference_m,
                fmt_interval(c.difference_interval_m)
            ),
        }
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

/// The alignment in force for a recording source (`None` for data already
/// on the control grid).
fn alignment_for(src: &SourceRuns, opts: &CompareOptions) -> Option<Alignment> {
    src.alignment
        .as_ref()
        .map(|own| match (&opts.alignment, opts.mode) {
            (Some(a), _) => a.clone(),
            (None, AnalysisMode::Study) => own.clone(),
            (None, AnalysisMode::Default) => Alignment::estimate(),
        })
}

/// Capture frames per control step of a source.
fn stride_of(src: &SourceRuns, spec: &SceneSpec) -> usize {
    (src.rate_hz * spec.control_period_s).round().max(1.0) as usize
}

/// Start frames of the included runs by [`align::align_group`] against
/// the kinematic reference; `settings` are (stride, search frames, rest
/// window, onset threshold in metres). Returns the starts and the group
/// shift in frames.
fn group_starts(
    src: &SourceRuns,
    kin: &KinematicTrack,
    settings: (usize, usize, (usize, usize), f64),
    include: &[bool],
    fit: &[bool],
) -> (Vec<Option<RunStart>>, i64) {
    let (stride, search_frames, rest_frames, threshold_m) = settings;
    let positions: Vec<Vec<Option<Vec3>>> = src
        .runs
        .iter()
        .zip(include)
        .map(|(r, inc)| {
            if *inc {
                r.trajectory.positions(WRIST)
            } else {
                vec![]
            }
        })
        .collect();
    let fit: Vec<bool> = fit.iter().zip(include).map(|(f, i)| *f && *i).collect();
    let g = align::align_group(
        &positions,
        &fit,
        &kin.wrist_m,
        stride,
        rest_frames,
        threshold_m,
        search_frames,
    );
    let starts = g
        .starts
        .iter()
        .zip(&src.runs)
        .zip(&positions)
        .map(|((s, run), pos)| {
            let start = (*s).filter(|s| *s < run.trajectory.len())?;
            Some(RunStart {
                start_frame: start,
                start_s: run.trajectory.time_s[start] - run.trajectory.time_s[0],
                onset_frame: align::motion_onset(pos, rest_frames, threshold_m),
            })
        })
        .collect();
    (starts, g.group_shift_frames)
}

/// Chooses the start frame of every run of a recording source marked in
/// `include`, from the recordings and the scene's kinematic reference
/// alone; templates are fitted on the runs marked in `fit`. Returns the
/// start per run (input order) and the alignment report (`None` for a
/// source on the control grid).
pub(crate) fn align_runs(
    src: &SourceRuns,
    spec: &SceneSpec,
    opts: &CompareOptions,
    include: &[bool],
    fit: &[bool],
) -> (Vec<Option<RunStart>>, Option<AlignmentReport>) {
    let n = src.runs.len();
    let Some(alignment) = alignment_for(src, opts) else {
        return (vec![None; n], None);
    };
    let stride = stride_of(src, spec);
    let mut method = alignment.describe();
    let mut group_shift = None;
    let starts: Vec<Option<RunStart>> = match (&alignment, &spec.kinematic) {
        (
            Alignment::Estimate {
                search_frames,
                rest_frames,
                threshold_m,
            },
            Some(kin),
        ) => {
            let (starts, shift) = group_starts(
                src,
                kin,
                (stride, *search_frames, *rest_frames, *threshold_m),
                include,
                fit,
            );
            group_shift = Some(shift);
            starts
        }
        (a, kin) => {
            if matches!(a, Alignment::Estimate { .. }) && kin.is_none() {
                method = "motion onset, no lead (no kinematic reference: the study names no scene file for this scene)".into();
            }
            src.runs
                .iter()
                .zip(include)
                .map(|(r, inc)| {
                    inc.then(|| align::choose_start(&r.trajectory, WRIST, a, stride, None))
                        .flatten()
                })
                .collect()
        }
    };
    let mut report = AlignmentReport {
        method,
        runs: vec![],
        failed: vec![],
        group_shift_frames: group_shift,
    };
    for (i, run) in src.runs.iter().enumerate() {
        if !include[i] {
            continue;
        }
        match &starts[i] {
            Some(s) => report.runs.push(AlignedRun {
                run: run.id.clone(),
                start: s.clone(),
                steps_available: align::resample(
                    &run.trajectory,
                    s.start_frame,
                    src.rate_hz,
                    spec.control_period_s,
                    spec.steps,
                    EndPolicy::Cut,
                )
                .1,
                used_for: match (opts.runs.holdout.is_some(), fit[i]) {
                    (false, _) => "fit+score".into(),
                    (true, true) => "fit".into(),
                    (true, false) => "score".into(),
                },
            }),
            None => report.failed.push((
                run.id.clone(),
                "no motion onset found in the wrist track".into(),
            )),
        }
    }
    (starts, Some(report))
}

/// Puts every run of a source on the control grid, starting recordings at
/// `starts` (per run, input order), and checks their health.
fn to_grid(
    src: &SourceRuns,
    spec: &SceneSpec,
    opts: &CompareOptions,
    starts: &[Option<RunStart>],
) -> Gridded {
    let end = match opts.mode {
        AnalysisMode::Study => EndPolicy::RepeatLast,
        AnalysisMode::Default => EndPolicy::Cut,
    };
    let mut g = Gridded {
        runs: vec![],
        flagged: vec![],
        total: src.runs.len(),
    };
    for (i, run) in src.runs.iter().enumerate() {
        let mut flags = health::check(&run.trajectory, &opts.health).flags;
        match run
            .failed
            .as_deref()
            .map(|m| (m, Instability::from_message(m)))
        {
            // Stored as unstable by the runner: flagged like the health's
            // own finding (which it replaces).
            Some((_, Some(found))) => {
                flags.retain(|f| !matches!(f, HealthFlag::Unstable { .. }));
                flags.insert(
                    0,
                    HealthFlag::Unstable {
                        joint: found.joint,
                        first_sample: found.first_sample,
                        t_s: found.t_s,
                        reason: found.reason,
                    },
                );
            }
            Some((m, None)) => flags.insert(
                0,
                HealthFlag::Failed {
                    message: m.to_string(),
                },
            ),
            None => {}
        }
        let start = starts.get(i).cloned().flatten();
        if src.alignment.is_some() && start.is_none() {
            flags.push(HealthFlag::Failed {
                message: "could not be aligned: no motion onset".into(),
            });
        }
        let (grid, available) = align::resample(
            &run.trajectory,
            start.map_or(0, |s| s.start_frame),
            src.rate_hz,
            spec.control_period_s,
            spec.steps,
            end,
        );
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
    g
}

/// Largest lag searched for, control steps (2 s at 20 Hz).
const LAG_SEARCH_STEPS: usize = 40;

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
    series.cube_mean_m = track.mean_m.iter().map(|p| p.map(Vec3::to_array)).collect();
    series.cube_mean_quat = m
        .cube_rot
        .iter()
        .map(|q| q.map(|q| [q.w, q.x, q.y, q.z]))
        .collect();
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
        accumulated_error_interval_m: None,
        bootstrap_over_source_runs: false,
        bootstrap_replicates_m: vec![],
        lag_s: spec.kinematic.as_ref().and_then(|k| {
            align::lag_steps(&m.wrist.mean_m, &k.wrist_m, LAG_SEARCH_STEPS)
                .map(|l| l * spec.control_period_s)
        }),
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

/// The reference of one scene, ready to be scored against: its scored
/// runs (registered into the world), where each starts, and what was done
/// to them.
pub(crate) struct PreparedReference {
    /// The reference with only its scored runs, registered.
    pub runs: SourceRuns,
    /// Start per scored run.
    pub starts: Vec<Option<RunStart>>,
    /// Alignment of every aligned run (fit and scored).
    pub alignment: Option<AlignmentReport>,
    /// Registration applied.
    pub registration: Option<RegistrationReport>,
    /// Runs used.
    pub runs_report: Option<RunsReport>,
}

/// Evaluates one scene against a prepared reference: grids and screens
/// every source, computes the measures, each source's lag behind the
/// kinematic reference and the bootstrap intervals.
pub(crate) fn evaluate_prepared(
    spec: &SceneSpec,
    prepared: PreparedReference,
    sources: &[SourceRuns],
    opts: &CompareOptions,
) -> SceneReport {
    let gridded: Vec<Gridded> = sources
        .iter()
        .map(|s| {
            let all = vec![true; s.runs.len()];
            let (starts, _) = align_runs(s, spec, opts, &all, &all);
            to_grid(s, spec, opts, &starts)
        })
        .collect();
    let src_means: Vec<Means> = gridded.iter().map(|g| means(g, spec.steps)).collect();
    let ref_g = to_grid(&prepared.runs, spec, opts, &prepared.starts);
    let ref_means = means(&ref_g, spec.steps);
    let mut sources_out: Vec<SourceSummary> = sources
        .iter()
        .zip(&gridded)
        .zip(&src_means)
        .map(|((s, g), m)| summarize(s, g, m, spec, Some(&ref_means)))
        .collect();
    let bootstrap = opts.bootstrap_in_force();
    let closest_comparison = bootstrap.and_then(|b| {
        attach_intervals(&ref_g, &gridded, &mut sources_out, spec.steps, &b);
        compare_closest(&sources_out, b.level)
    });
    SceneReport {
        scene: spec.name.clone(),
        mode: opts.mode,
        steps: spec.steps,
        control_period_s: spec.control_period_s,
        goal_m: spec.goal_m,
        phases_s: spec.phases_s.clone(),
        reference: summarize(&prepared.runs, &ref_g, &ref_means, spec, None),
        alignment: prepared.alignment,
        sources: sources_out,
        registration: prepared.registration,
        runs: prepared.runs_report,
        bootstrap,
        closest_comparison,
    }
}

/// The wrist tracks of a gridded source, packed for the bootstrap.
fn run_tracks(g: &Gridded, steps: usize) -> RunTracks {
    let tracks: Vec<Vec<Option<Vec3>>> = g.runs.iter().map(|(_, t)| t.positions(WRIST)).collect();
    RunTracks::new(&tracks, steps)
}

/// Bootstrap replicates and intervals of every source with an accumulated
/// error.
fn attach_intervals(
    reference: &Gridded,
    gridded: &[Gridded],
    summaries: &mut [SourceSummary],
    steps: usize,
    opts: &BootstrapOptions,
) {
    let ref_tracks = run_tracks(reference, steps);
    let tracks: Vec<(usize, RunTracks)> = summaries
        .iter()
        .enumerate()
        .filter(|(_, s)| s.accumulated_error_m.is_some())
        .map(|(i, _)| (i, run_tracks(&gridded[i], steps)))
        .collect();
    let named: Vec<(&str, &RunTracks)> = tracks
        .iter()
        .map(|(i, t)| (summaries[*i].source.as_str(), t))
        .collect();
    let reps = bootstrap::replicates(&ref_tracks, &named, opts);
    for ((i, t), r) in tracks.iter().zip(reps) {
        let s = &mut summaries[*i];
        s.accumulated_error_interval_m = bootstrap::percentile_interval(&r, opts.level);
        s.bootstrap_over_source_runs = !t.all_identical();
        s.bootstrap_replicates_m = r;
    }
}

/// The paired comparison of the closest source with the runner-up.
fn compare_closest(sources: &[SourceSummary], level: f64) -> Option<PairedComparison> {
    let mut ranked: Vec<&SourceSummary> = sources
        .iter()
        .filter(|s| s.accumulated_error_m.is_some_and(f64::is_finite))
        .filter(|s| !s.bootstrap_replicates_m.is_empty())
        .collect();
    ranked.sort_by(|a, b| {
        a.accumulated_error_m
            .unwrap_or(f64::INFINITY)
            .total_cmp(&b.accumulated_error_m.unwrap_or(f64::INFINITY))
    });
    let (a, b) = (ranked.first()?, ranked.get(1)?);
    bootstrap::paired(
        (&a.source, a.accumulated_error_m?, &a.bootstrap_replicates_m),
        (&b.source, b.accumulated_error_m?, &b.bootstrap_replicates_m),
        level,
    )
}

/// Evaluates one scene: the reference and every source, as the module docs
/// describe, with the registration estimated from this scene alone. A run
/// selection in `opts` that selects nothing here leaves the reference
/// without runs; [`crate::study::evaluate_study`] reports it as an error.
pub fn evaluate_scene(
    spec: &SceneSpec,
    reference: &SourceRuns,
    sources: &[SourceRuns],
    opts: &CompareOptions,
) -> SceneReport {
    let input = crate::study::SceneInput {
        spec,
        reference,
        sources,
    };
    let selected = opts.runs.select_lenient(&spec.name, reference.runs.len());
    let prepared = crate::study::prepare_references(&[input], &[selected], opts);
    let mut reports = prepared
        .into_iter()
        .map(|p| evaluate_prepared(spec, p, sources, opts));
    reports.next().unwrap_or_else(|| {
        // prepare_references gives one reference per scene; this is the
        // reference without runs.
        let empty = SourceRuns {
            runs: vec![],
            ..reference.clone()
        };
        let prepared = PreparedReference {
            runs: empty,
            starts: vec![],
            alignment: None,
            registration: None,
            runs_report: None,
        };
        evaluate_prepared(spec, prepared, sources, opts)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematic::KinematicTrack;
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
            kinematic: None,
        }
    }

    /// The spec with a kinematic reference equal to the simulated motion
    /// (rest, then 0.5 m along x over 40 steps).
    fn spec_with_kinematic() -> SceneSpec {
        let wrist_m: Vec<Vec3> = run("k", 100, 1, 0, 0.5, 0.0)
            .trajectory
            .positions(WRIST)
            .into_iter()
            .take(100)
            .flatten()
            .collect();
        let settled = (0..100).map(|k| k == 0 || k >= 60).collect();
        SceneSpec {
            kinematic: Some(KinematicTrack {
                wrist_m,
                settled,
                angles_rad: Vec::new(),
            }),
            ..spec()
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
        let rep = evaluate_scene(
            &spec_with_kinematic(),
            &real,
            std::slice::from_ref(&sim),
            &CompareOptions::default(),
        );
        assert_eq!(
            rep.alignment.as_ref().unwrap().runs[0].start.start_frame,
            173
        );
        assert!(s_lag(&rep, 0).abs() < 0.01, "{:?}", rep.sources[0].lag_s);
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

    fn s_lag(r: &SceneReport, i: usize) -> f64 {
        r.sources[i].lag_s.unwrap()
    }

    /// The real arm: 6 runs at 100 Hz starting at different frames, with
    /// 1 mm run-to-run offsets.
    fn real_runs() -> SourceRuns {
        SourceRuns {
            name: "real".into(),
            kind: "real".into(),
            rate_hz: 100.0,
            alignment: Some(Alignment::estimate()),
            runs: (0..6)
                .map(|i| {
                    run(
                        &format!("r{i}"),
                        100,
                        5,
                        150 + 13 * i,
                        0.5,
                        0.001 * i as f64,
                    )
                })
                .collect(),
        }
    }

    fn sim(name: &str, delay_steps: usize, reach: f64) -> SourceRuns {
        SourceRuns {
            name: name.into(),
            kind: "recorded".into(),
            rate_hz: 20.0,
            alignment: None,
            runs: vec![run("a", 100, 1, delay_steps, reach, 0.0)],
        }
    }

    #[test]
    fn start_frames_do_not_depend_on_the_sources_and_lag_is_only_measured() {
        let spec = spec_with_kinematic();
        let real = real_runs();
        let late = sim("late", 6, 0.5);
        let near = sim("near", 0, 0.52);
        let opts = CompareOptions::default();
        let both = evaluate_scene(&spec, &real, &[late.clone(), near.clone()], &opts);
        let one = evaluate_scene(&spec, &real, std::slice::from_ref(&near), &opts);
        assert_eq!(both.alignment, one.alignment);
        let starts: Vec<usize> = one
            .alignment
            .as_ref()
            .unwrap()
            .runs
            .iter()
            .map(|r| r.start.start_frame)
            .collect();
        assert_eq!(starts, [150, 163, 176, 189, 202, 215]);
        // The late source is 6 steps (0.3 s) behind; its error is not shrunk
        // by it: 6 steps x 12.5 mm over the ramp, about 2 m.
        assert!(
            (s_lag(&both, 0) - 0.3).abs() < 0.02,
            "{:?}",
            both.sources[0].lag_s
        );
        assert!(both.sources[0].accumulated_error_m.unwrap() > 1.5);
        // Intervals bracket the estimates, the same with or without the
        // other source.
        for s in &both.sources {
            let i = s.accumulated_error_interval_m.unwrap();
            let e = s.accumulated_error_m.unwrap();
            assert!(
                i.low_m <= e && e <= i.high_m + 0.05,
                "{}: {e} {i:?}",
                s.source
            );
        }
        assert_eq!(
            both.sources[1].accumulated_error_interval_m,
            one.sources[0].accumulated_error_interval_m
        );
        let c = both.closest_comparison.as_ref().unwrap();
        assert_eq!((c.closest.as_str(), c.runner_up.as_str()), ("near", "late"));
        assert!(c.distinguishable && c.probability_closer > 0.99, "{c:?}");
        assert_eq!(both.winner().unwrap().source, "near");
        // Twins cannot be told apart, and no winner is named.
        let twins = evaluate_scene(
            &spec,
            &real,
            &[
                near.clone(),
                SourceRuns {
                    name: "twin".into(),
                    ..near
                },
            ],
            &opts,
        );
        assert!(twins.winner().is_none());
        assert!(
            twins.verdict().contains("cannot be told apart"),
            "{}",
            twins.verdict()
        );
    }

    #[test]
    fn a_shifted_capture_frame_is_registered_away() {
        let spec = spec_with_kinematic();
        let mut real = real_runs();
        for r in &mut real.runs {
            for p in r.trajectory.bodies[0].poses.iter_mut().flatten() {
                p.position_m = p.position_m + Vec3::new(0.0, 0.009, 0.004);
            }
        }
        let near = sim("near", 0, 0.5);
        let raw = CompareOptions {
            registration: RegistrationChoice::None,
            ..Default::default()
        };
        let given = CompareOptions {
            registration: RegistrationChoice::Given {
                registration: Registration {
                    rotation: Quat::IDENTITY,
                    translation_m: Vec3::new(0.0, -0.009, -0.004),
                },
                origin: "test".into(),
            },
            ..Default::default()
        };
        let e_raw = evaluate_scene(&spec, &real, std::slice::from_ref(&near), &raw).sources[0]
            .accumulated_error_m
            .unwrap();
        let rep = evaluate_scene(&spec, &real, &[near], &given);
        let e_reg = rep.sources[0].accumulated_error_m.unwrap();
        assert!(
            e_raw > 0.9 && e_reg < 0.3,
            "raw {e_raw}, registered {e_reg}"
        );
        let g = rep.registration.unwrap();
        assert!(g.residual_fit_rms_m.unwrap() < 0.003, "{g:?}");
        assert!(g.fit.is_none() && g.method.contains("test"));
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
            std::slice::from_ref(&sim),
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

    /// Sources with several runs that differ run by run, over a reference
    /// of several runs, so that the bootstrap has something to resample.
    fn spread_sources() -> (SourceRuns, Vec<SourceRuns>) {
        let runs = |name: &str, reach: f64| SourceRuns {
            name: name.into(),
            kind: "recorded".into(),
            rate_hz: 20.0,
            alignment: None,
            runs: (0..6)
                .map(|i| {
                    run(
                        &format!("{name}{i}"),
                        100,
                        1,
                        0,
                        reach + 0.002 * i as f64,
                        0.0,
                    )
                })
                .collect(),
        };
        (runs("ref", 0.5), vec![runs("near", 0.51), runs("far", 0.6)])
    }

    #[test]
    fn bootstrap_gives_intervals_around_the_value_and_a_verdict() {
        let (reference, sources) = spread_sources();
        let opts = CompareOptions {
            bootstrap: Some(BootstrapOptions {
                resamples: 200,
                ..BootstrapOptions::default()
            }),
            ..Default::default()
        };
        assert_eq!(opts.bootstrap_in_force().unwrap().resamples, 200);
        let rep = evaluate_scene(&spec(), &reference, &sources, &opts);
        for s in &rep.sources {
            let (v, i) = (
                s.accumulated_error_m.unwrap(),
                s.accumulated_error_interval_m.unwrap(),
            );
            assert!(
                i.low_m <= v && v <= i.high_m,
                "{}: {v} not in {i:?}",
                s.source
            );
            assert_eq!(s.bootstrap_replicates_m.len(), 200);
        }
        assert_eq!(rep.closest().unwrap().source, "near");
        let c = rep.closest_comparison.as_ref().unwrap();
        assert_eq!((c.closest.as_str(), c.runner_up.as_str()), ("near", "far"));
        assert!(c.distinguishable && c.probability_closer > 0.95, "{c:?}");
        assert_eq!(rep.winner().unwrap().source, "near");
        assert!(rep
            .verdict()
            .starts_with("closest source: near (closer than far with probability"));
        assert_eq!(
            rep.closest_per_phase(),
            [Some("near".to_string()), Some("near".to_string())]
        );
        // Study mode computes no interval unless asked.
        let study = CompareOptions {
            mode: AnalysisMode::Study,
            ..Default::default()
        };
        assert_eq!(study.bootstrap_in_force(), None);
        let rep = evaluate_scene(&spec(), &reference, &sources, &study);
        assert!(rep
            .sources
            .iter()
            .all(|s| s.accumulated_error_interval_m.is_none()));
        assert_eq!(rep.closest_comparison, None);
        assert_eq!(rep.verdict(), "closest source: near");
        // Zero resamples switch the bootstrap off in default mode too.
        let off = CompareOptions {
            bootstrap: Some(BootstrapOptions {
                resamples: 0,
                ..BootstrapOptions::default()
            }),
            ..Default::default()
        };
        assert_eq!(off.bootstrap_in_force(), None);
        assert_eq!(
            CompareOptions::default().bootstrap_in_force(),
            Some(BootstrapOptions::default())
        );
    }

    #[test]
    fn verdicts_name_the_closest_or_say_they_cannot_be_told_apart() {
        let mut r = crate::testing::scene();
        assert_eq!(r.closest().unwrap().source, "Alpha <&>");
        assert_eq!(r.winner().unwrap().source, "Alpha <&>");
        assert_eq!(
            r.verdict(),
            "closest source: Alpha <&> (closer than Beta with probability 1.000; difference 2.000 m, 95 % interval [1.500, 2.500])"
        );
        if let Some(c) = r.closest_comparison.as_mut() {
            c.distinguishable = false;
            c.probability_closer = 0.6;
            c.difference_interval_m = None;
        }
        assert!(r.winner().is_none());
        assert_eq!(
            r.verdict(),
            "Alpha <&> and Beta cannot be told apart (probability 0.600 that Alpha <&> is closer; difference 2.000 m, 95 % interval n/a)"
        );
        // A non-finite error is never the closest; no source at all: no verdict.
        r.sources[0].accumulated_error_m = Some(f64::NAN);
        assert_eq!(r.closest().unwrap().source, "Beta");
        r.sources.clear();
        assert_eq!(r.verdict(), "no source could be compared");
        assert_eq!(r.closest_per_phase(), [None, None]);
        assert_eq!(fmt_interval(None), "n/a");
        assert_eq!(
            fmt_interval(Some(Interval {
                low_m: -0.0001,
                high_m: 2.0
            })),
            "[-0.000, 2.000]"
        );
    }
}
