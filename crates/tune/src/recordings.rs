//! `realitygap tune --recordings`: fits an engine's physical parameters to
//! a robot's own recorded episodes (a results directory of `realitygap
//! import rosbag|csv|lerobot`) in joint space, then scores the untuned and
//! the tuned engine, and the physics-free model, on the training and the
//! held-out episodes.
//!
//! - **Space.** Built from the URDF for a robot the project has never
//!   seen ([`default_space`]: every moving joint's damping, armature and
//!   dry friction, the servo gains `kp` and `kv`, and the command delay),
//!   less what the engine cannot honour and what the user fixes with
//!   known parameters (`--params`: the ros2_control gains, say). A space
//!   file (`--space`, the format of [`crate::space`]) overrides it; the
//!   space used is written to `OUT/space.toml` to edit and pass back.
//! - **Objective.** The joint angles of every training episode replayed
//!   in the engine ([`realitygap_study::replay`]) against the recorded
//!   ones, degrees, sample by sample: a least-squares problem. With
//!   [`RecordingsSpec::use_efforts`] (where every training episode
//!   recorded efforts), the replay's servo efforts against them too, each
//!   joint's weighted so that its spread counts like the angles': from
//!   angles alone joint damping and the servo's `kv` cannot be told apart
//!   (both multiply the joint velocity); the recorded effort (the servo's,
//!   without the joint's damping) separates them. The replay's effort is
//!   `kv (v_target - qd)` at the step's start, the torque an explicitly
//!   integrated servo applies; an implicit one (MuJoCo's implicitfast)
//!   applies another, so efforts are for explicit-servo scenes.
//! - **Search.** The command delay first, scanned over its range at the
//!   untuned parameters, about 10 values and then the two midpoints beside
//!   the best (a gradient search from a delay far from the truth can
//!   settle where a wrong delay and wrong damping make up for each other);
//!   then Levenberg-Marquardt ([`crate::least_squares`]) on every
//!   parameter, the delay included (a replay is continuous in the delay:
//!   between two engine steps it blends them, [`realitygap_core::replay`]),
//!   and the delay's profile at whole engine steps around the fit.
//! - **Intervals.** Each fitted parameter's 95 % interval from the
//!   Jacobian at the optimum and the residuals there, told apart into
//!   white reading noise and the structure the engine cannot reproduce
//!   ([`least_squares::misfit`]): Gauss-Newton's interval for the noise,
//!   widened by how far an error as large as that structure could shift
//!   the parameter. The summary says in words what they rest on and what
//!   in the fit limits them ([`cautions`]). The identifiability report names
//!   parameters whose interval spans their
//!   whole range (the data do not see them) and pairs whose estimates are
//!   correlated beyond 0.95 (they trade against each other: joint damping
//!   and the servo's `kv` both multiply the joint velocity, and joint
//!   angles alone cannot tell them apart).
//! - **Scores.** Joint-space RMS over all joints and samples, per episode
//!   set, with a 95 % bootstrap interval over episodes (none from a single
//!   episode), for the untuned engine, the tuned engine, and the
//!   physics-free model (perfect tracking of the commands, undelayed and
//!   with the fitted delay).

use crate::least_squares;
use crate::space::{params_of, Dim, Scale, Space};
use crate::stages;
use anyhow::{anyhow, bail, Context, Result};
use realitygap_analysis::bootstrap::percentile_interval;
use realitygap_analysis::selection::RunSelection;
use realitygap_core::controller::{RunStatus, SplitMix64};
use realitygap_core::params::{ParamKey, PhysicalParams};
use realitygap_core::trajectory::CommandKind;
use realitygap_core::{Engine, Trajectory};
use realitygap_study::replay::{replay_one, Episode, Prepared};
use serde::Serialize;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

/// The space key of the command delay (scanned before the fit).
pub const DELAY_KEY: &str = "controller.delay_s";

/// Everything a tune against recordings is asked to do.
pub struct RecordingsSpec<'a> {
    /// The engine.
    pub engine: &'a dyn Engine,
    /// The recordings, the robot and the replay scene.
    pub prepared: &'a Prepared,
    /// Parameters known and fixed (`--params`): never searched.
    pub known: &'a PhysicalParams,
    /// The space; `None`: built from the URDF ([`default_space`]).
    pub space: Option<Space>,
    /// Episodes to fit on and to score on (1-based, in the results
    /// directory's order).
    pub selection: RunSelection,
    /// Output folder.
    pub out: PathBuf,
    /// Parallel evaluations.
    pub jobs: usize,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: usize,
    /// Fit the recorded efforts too, where every training episode has
    /// them (else the joint angles alone).
    pub use_efforts: bool,
}

/// Progress of a tune, reported after every evaluation.
#[derive(Debug, Clone)]
pub struct RecordingsProgress {
    /// Evaluations done (each replays every training episode).
    pub evaluations: usize,
    /// What the tune is doing.
    pub phase: String,
    /// The best training RMS so far, degrees.
    pub best_rms_deg: f64,
}

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FittedParam {
    /// The key, as in a parameters file.
    pub key: String,
    /// Its value before tuning (the engine's, from the URDF and the known
    /// parameters).
    pub start: f64,
    /// The fitted value.
    pub value: f64,
    /// Its 95 % interval, when the data give one.
    pub interval: Option<(f64, f64)>,
    /// The space's bounds.
    pub bounds: (f64, f64),
    /// True when the fit ended on a bound.
    pub at_bound: bool,
}

/// One scored source on one set of episodes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SetScore {
    /// RMS over all joints and samples of the set, degrees.
    pub rms_deg: f64,
    /// Its 95 % bootstrap interval over episodes (none from one episode).
    pub interval_deg: Option<(f64, f64)>,
    /// Per episode (id, RMS degrees).
    pub episodes: Vec<(String, f64)>,
    /// Per joint RMS, degrees.
    pub per_joint_deg: Vec<f64>,
}

/// A source's scores on the training and the held-out episodes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceScores {
    /// The source.
    pub source: String,
    /// On the training episodes.
    pub train: Option<SetScore>,
    /// On the held-out episodes (when any is held out).
    pub holdout: Option<SetScore>,
}

/// Identifiability: what the data cannot tell.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Identifiability {
    /// Parameters whose 95 % interval spans their whole range, or that
    /// have no effect at all on the joint angles.
    pub unseen: Vec<String>,
    /// Pairs of parameters whose estimates are correlated beyond 0.95
    /// (key, key, correlation).
    pub trading: Vec<(String, String, f64)>,
    /// Autocorrelation of the residuals at the optimum, from one sample
    /// to the next of each joint.
    pub residual_autocorrelation: f64,
    /// The residuals at the optimum, told apart into reading noise and
    /// structure.
    pub residuals: Residuals,
}

/// The residuals at the optimum (joint angles, degrees; with efforts, the
/// weighted effort residuals count alike): how much of them is white
/// noise and how much the engine cannot reproduce
/// ([`least_squares::misfit`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Residuals {
    /// One per joint and sample of the training episodes.
    pub count: usize,
    /// Their root mean square, degrees.
    pub rms_deg: f64,
    /// The white noise in them (a sensor's reading noise), standard
    /// deviation, degrees.
    pub noise_deg: f64,
    /// What is smooth in time (what the engine cannot reproduce), root
    /// mean square, degrees.
    pub structure_deg: f64,
    /// Samples averaged to measure the structure (40 ms of them).
    pub window_samples: usize,
}

/// Over how long the residuals are averaged to measure their structure,
/// s: far longer than a sample (white noise averages out), shorter than a
/// servo's response (the model's error stays).
pub const STRUCTURE_WINDOW_S: f64 = 0.04;

/// The median time between samples, s (`None` from fewer than two).
fn sample_period(time_s: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = time_s
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|x| *x > 0.0 && x.is_finite())
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

/// The tuned parameters replayed again at half the engine's timestep
/// (the held-out episodes, else the training ones): does the fit hold at
/// a finer step?
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordingsTimestepCheck {
    /// The timestep of the fit, s.
    pub timestep_s: f64,
    /// Half of it, s.
    pub halved_s: f64,
    /// `held-out` or `training`: the episodes scored.
    pub episodes: String,
    /// The tuned engine's score there at the fit's step.
    pub tuned: Option<SetScore>,
    /// Its score at half the step.
    pub halved: Option<SetScore>,
    /// Whether the fit holds: the RMS at half the step lies within the
    /// tuned RMS's 95 % interval over episodes (`None` without one).
    pub holds: Option<bool>,
    /// Episodes that could not be replayed at half the step, with why.
    pub failed: Vec<String>,
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct RecordingsSummary {
    /// Engine name and version.
    pub engine: String,
    /// The robot's name.
    pub robot: String,
    /// The recordings' folder.
    pub recordings: PathBuf,
    /// Training episodes (ids).
    pub train: Vec<String>,
    /// Held-out episodes (ids).
    pub holdout: Vec<String>,
    /// The known parameters' keys (fixed, never searched).
    pub known: Vec<String>,
    /// What the objective compares, in words.
    pub objective: String,
    /// The fitted parameters.
    pub params: Vec<FittedParam>,
    /// The identifiability report.
    pub identifiability: Identifiability,
    /// Scores: the engine untuned and tuned, the physics-free model.
    pub scores: Vec<SourceScores>,
    /// Residual evaluations (each replays every training episode).
    pub evaluations: usize,
    /// Jacobians computed by differences (Levenberg-Marquardt's
    /// iterations), all rounds; between them, accepted steps update the
    /// last one (Broyden).
    pub iterations: usize,
    /// Why the last fit stopped.
    pub reason: String,
    /// Wall time of the search, s: from the start to the intervals (the
    /// delay's scan, the fits, the profile, the Jacobian at the optimum).
    pub search_time_s: f64,
    /// Wall time, s: the search, then the scores and the timestep check.
    pub wall_time_s: f64,
    /// The answer in words: does the tuned engine beat the physics-free
    /// model on the held-out episodes?
    pub verdict: String,
    /// The tuned parameters at half the timestep.
    pub timestep_check: RecordingsTimestepCheck,
    /// How far the intervals can be trusted, in words: what they rest on,
    /// and what in this fit limits them.
    pub cautions: Vec<String>,
}

/// The result of a tune.
pub struct RecordingsResult {
    /// The summary (also in `summary.json`).
    pub summary: RecordingsSummary,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// The parameter space of a robot the project has never seen, from its
/// URDF: per moving joint, viscous damping, armature and dry friction,
/// and the replay servo's gains (`kp` for position commands, `kv`), then
/// the command delay; less the keys `known` sets and the keys `engine`
/// cannot honour. Bounds scale with each joint's effort limit (100 N m
/// where the URDF gives none); starts are the untuned values (the URDF's
/// damping and friction, no armature, the replay's default gains, no
/// delay).
pub fn default_space(
    prepared: &Prepared,
    engine: &dyn Engine,
    known: &PhysicalParams,
) -> Result<Space> {
    let supported: Vec<ParamKey> = engine.param_support().iter().map(|s| s.key).collect();
    let honours = |k: ParamKey| k.is_core() || supported.contains(&k);
    let kind = prepared
        .episodes
        .first()
        .and_then(|e| e.real.commands.as_ref())
        .map(|c| c.kind);
    let mut dims = Vec::new();
    for (j, &ji) in prepared.replayed_joints().iter().enumerate() {
        let joint = &prepared.robot.joints[ji];
        let name = &joint.name;
        let given = known.joints.get(name);
        let effort = joint
            .limits
            .as_ref()
            .map(|l| l.effort)
            .filter(|e| e.is_finite() && *e > 0.0 && *e < 1e5)
            .unwrap_or(100.0);
        let actuator = prepared.scene.actuators.get(j);
        let kv0 = given
            .and_then(|g| g.kv)
            .or(actuator.map(|a| a.kv))
            .unwrap_or(effort);
        let kp0 = given
            .and_then(|g| g.kp)
            .or(actuator.and_then(|a| a.kp))
            .unwrap_or(effort / 0.05);
        let mut push =
            |field: &str, key: ParamKey, low: f64, high: f64, scale: Scale, start: f64| {
                let set = match field {
                    "damping" => given.and_then(|g| g.damping).is_some(),
                    "armature" => given.and_then(|g| g.armature).is_some(),
                    "frictionloss" => given.and_then(|g| g.frictionloss).is_some(),
                    "kp" => given.and_then(|g| g.kp).is_some(),
                    "kv" => given.and_then(|g| g.kv).is_some(),
                    _ => false,
                };
                if set || !honours(key) {
                    return;
                }
                dims.push(Dim {
                    key: format!("joints.{name}.{field}"),
                    low,
                    high,
                    scale,
                    start: start.clamp(low, high),
                });
            };
        push(
            "damping",
            ParamKey::JointDamping,
            0.0,
            (0.1 * effort).max(10.0 * joint.damping),
            Scale::Linear,
            joint.damping,
        );
        push(
            "armature",
            ParamKey::JointArmature,
            0.0,
            (0.005 * effort).max(0.5),
            Scale::Linear,
            0.0,
        );
        push(
            "frictionloss",
            ParamKey::JointFrictionloss,
            0.0,
            (0.05 * effort).max(10.0 * joint.friction),
            Scale::Linear,
            joint.friction,
        );
        if kind == Some(CommandKind::Position) {
            push(
                "kp",
                ParamKey::JointKp,
                kp0 / 30.0,
                kp0 * 3.0,
                Scale::Log,
                kp0,
            );
        }
        if kind != Some(CommandKind::Effort) {
            push(
                "kv",
                ParamKey::JointKv,
                kv0 / 30.0,
                kv0 * 3.0,
                Scale::Log,
                kv0,
            );
        }
    }
    // Every kind of command can arrive late, efforts too.
    if known.controller.delay_s.is_none() {
        dims.push(Dim {
            key: DELAY_KEY.into(),
            low: 0.0,
            high: 0.1,
            scale: Scale::Linear,
            start: 0.0,
        });
    }
    if dims.is_empty() {
        bail!(
            "nothing to fit: the known parameters fix every parameter engine {} honours",
            engine.name()
        );
    }
    Ok(Space {
        source: PathBuf::from(format!("<built from the URDF of {}>", prepared.robot.name)),
        dims,
        settings: Default::default(),
        registration: None,
        held: Vec::new(),
        registration_start: None,
    })
}

/// The space as a TOML file a user can edit and pass back with `--space`.
pub fn space_toml(space: &Space, robot: &str, engine: &str) -> String {
    let mut s = format!(
        "# Parameter space of `realitygap tune --recordings` for robot '{robot}' in {engine}\n\
         # (built from the URDF; edit the bounds and pass this file back with --space).\n\
         # `start` is the untuned value; controller.delay_s is scanned over its range first.\n\n[params]\n"
    );
    for d in &space.dims {
        let scale = match d.scale {
            Scale::Linear => String::new(),
            Scale::Log => ", scale = \"log\"".into(),
        };
        let _ = writeln!(
            s,
            "{:?} = {{ low = {:?}, high = {:?}{scale}, start = {:?} }}",
            d.key, d.low, d.high, d.start
        );
    }
    s
}

/// The keys `known` sets, as written in a parameters file.
pub fn known_keys(known: &PhysicalParams) -> Vec<String> {
    known
        .set_keys()
        .iter()
        .map(|(k, name)| {
            let parts: Vec<&str> = k.pattern().split('.').collect();
            match (name, parts.as_slice()) {
                (Some(n), [section, _, field]) => format!("{section}.{n}.{field}"),
                _ => k.pattern().to_string(),
            }
        })
        .collect()
}

/// Sets `key` (a space key) to `value` in `params`.
pub(crate) fn set_key(params: &mut PhysicalParams, key: &str, value: f64) -> Result<(), String> {
    let parsed = params_of(std::iter::once((key, value)))?;
    for (name, j) in parsed.joints {
        let t = params.joints.entry(name).or_default();
        macro_rules! over {
            ($($f:ident),*) => { $( if j.$f.is_some() { t.$f = j.$f; } )* };
        }
        over!(
            damping,
            armature,
            frictionloss,
            kv,
            kp,
            force_limit,
            offset_deg
        );
    }
    for (name, l) in parsed.links {
        let t = params.links.entry(name).or_default();
        if l.mass_scale.is_some() {
            t.mass_scale = l.mass_scale;
        }
    }
    for (name, o) in parsed.objects {
        let t = params.objects.entry(name).or_default();
        if o.mass_kg.is_some() {
            t.mass_kg = o.mass_kg;
        }
        if o.friction.is_some() {
            t.friction = o.friction;
        }
        if o.restitution.is_some() {
            t.restitution = o.restitution;
        }
    }
    let c = parsed.contact;
    if c.time_constant_s.is_some() {
        params.contact.time_constant_s = c.time_constant_s;
    }
    if c.damping_ratio.is_some() {
        params.contact.damping_ratio = c.damping_ratio;
    }
    let c = parsed.controller;
    if c.delay_s.is_some() {
        params.controller.delay_s = c.delay_s;
    }
    if c.gain_per_s.is_some() {
        params.controller.gain_per_s = c.gain_per_s;
    }
    if c.max_speed_deg_s.is_some() {
        params.controller.max_speed_deg_s = c.max_speed_deg_s;
    }
    if c.max_accel_deg_s2.is_some() {
        params.controller.max_accel_deg_s2 = c.max_accel_deg_s2;
    }
    let a = parsed.actuator;
    if a.frequency_rad_s.is_some() {
        params.actuator.frequency_rad_s = a.frequency_rad_s;
    }
    if a.damping_ratio.is_some() {
        params.actuator.damping_ratio = a.damping_ratio;
    }
    if a.max_velocity_deg_s.is_some() {
        params.actuator.max_velocity_deg_s = a.max_velocity_deg_s;
    }
    if a.deadband_deg_s.is_some() {
        params.actuator.deadband_deg_s = a.deadband_deg_s;
    }
    Ok(())
}

/// The problem: which dims are continuous, the delay grid, the episodes.
pub(crate) struct Problem<'a> {
    pub(crate) spec: &'a RecordingsSpec<'a>,
    pub(crate) space: Space,
    /// Indices (into `space.dims`) of the coordinates (every parameter).
    pub(crate) continuous: Vec<usize>,
    /// The delay's dim, when it is searched (scanned first).
    pub(crate) delay: Option<Dim>,
    /// The engine's timestep, s.
    pub(crate) dt: f64,
    pub(crate) train: Vec<usize>,
    pub(crate) holdout: Vec<usize>,
    pub(crate) evaluations: Mutex<usize>,
    pub(crate) best: Mutex<f64>,
    pub(crate) history: Mutex<std::fs::File>,
    pub(crate) samples: usize,
    /// Per joint, the weight of an effort residual (deg per N m), when
    /// efforts are fitted.
    pub(crate) effort_weights: Option<Vec<f64>>,
    pub(crate) progress: &'a (dyn Fn(RecordingsProgress) + Sync),
    pub(crate) phase: Mutex<String>,
    /// `jobs` threads, for the evaluations made outside a Jacobian.
    pub(crate) pool: rayon::ThreadPool,
}

impl Problem<'_> {
    /// The parameters at coordinates `u`.
    pub(crate) fn params(&self, u: &[f64]) -> Result<PhysicalParams, String> {
        let mut p = self.spec.known.clone();
        for (&i, &x) in self.continuous.iter().zip(u) {
            let d = &self.space.dims[i];
            set_key(&mut p, &d.key, d.value(x))?;
        }
        Ok(p)
    }

    /// Replays one episode with `params`.
    pub(crate) fn replay(
        &self,
        episode: &Episode,
        params: &PhysicalParams,
    ) -> Result<Trajectory, String> {
        let engine = self.spec.engine;
        let prepared = self.spec.prepared;
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            replay_one(engine, prepared, episode, params)
        }))
        .map_err(|p| {
            let what = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "a panic".into());
            format!("engine {} panicked: {what}", engine.name())
        })?;
        let (trajectory, status, _) = outcome?;
        if let RunStatus::Diverged { t_s, reason } = status {
            return Err(format!(
                "episode '{}' diverged at {t_s:.3} s: {reason}",
                episode.id
            ));
        }
        Ok(trajectory)
    }

    /// Joint-angle residuals (degrees) of the training episodes, replayed
    /// in parallel: on the threads of the pool it is called from (a
    /// Jacobian's columns), else on the tune's own (`jobs`), so that a
    /// single evaluation (a step of the fit) uses every core too.
    pub(crate) fn residuals(&self, params: &PhysicalParams) -> Result<Vec<f64>, String> {
        use rayon::prelude::*;
        let replay_all = || -> Vec<Result<Trajectory, String>> {
            self.train
                .par_iter()
                .map(|&k| self.replay(&self.spec.prepared.episodes[k], params))
                .collect()
        };
        let sims = if rayon::current_thread_index().is_some() {
            replay_all()
        } else {
            self.pool.install(replay_all)
        };
        let mut r = Vec::with_capacity(self.samples);
        let result = (|| {
            for (&k, sim) in self.train.iter().zip(sims) {
                let e = &self.spec.prepared.episodes[k];
                push_residuals(&e.real, &sim?, self.effort_weights.as_deref(), &mut r)
                    .map_err(|m| format!("episode '{}': {m}", e.id))?;
            }
            Ok(())
        })();
        let n = {
            let mut n = self.evaluations.lock().unwrap_or_else(|p| p.into_inner());
            *n += 1;
            *n
        };
        (self.progress)(RecordingsProgress {
            evaluations: n,
            phase: self.phase.lock().map(|p| p.clone()).unwrap_or_default(),
            best_rms_deg: *self.best.lock().unwrap_or_else(|p| p.into_inner()),
        });
        result.map(|()| r)
    }

    /// Appends a point of the fit (not the Jacobian's columns) to
    /// `history.csv`.
    pub(crate) fn record(&self, phase: &str, values: &[f64], cost: f64) {
        let rms = (cost / self.samples.max(1) as f64).sqrt();
        let n = *self.evaluations.lock().unwrap_or_else(|p| p.into_inner());
        {
            let mut b = self.best.lock().unwrap_or_else(|p| p.into_inner());
            if rms < *b {
                *b = rms;
            }
        }
        let mut line = format!("{n},{phase},{rms:?}");
        for v in values {
            let _ = write!(line, ",{v:?}");
        }
        let mut f = self.history.lock().unwrap_or_else(|p| p.into_inner());
        let _ = writeln!(f, "{line}");
    }

    pub(crate) fn values(&self, u: &[f64]) -> Vec<f64> {
        self.continuous
            .iter()
            .zip(u)
            .map(|(&i, &x)| self.space.dims[i].value(x))
            .collect()
    }

    pub(crate) fn set_phase(&self, phase: String) {
        if let Ok(mut p) = self.phase.lock() {
            *p = phase;
        }
    }

    /// The residuals' blocks for [`least_squares::misfit`]: per training
    /// episode, its samples of every joint (with efforts, the effort
    /// residuals follow the angles').
    pub(crate) fn blocks(&self) -> Vec<least_squares::Block> {
        let prepared = self.spec.prepared;
        let joints = prepared.replayed_joints().len();
        self.train
            .iter()
            .flat_map(|&k| {
                let samples = prepared.episodes[k]
                    .real
                    .joint_angles_rad
                    .as_ref()
                    .map_or(0, |q| q.len());
                let block = least_squares::Block {
                    samples,
                    series: joints,
                };
                let kinds = if self.effort_weights.is_some() { 2 } else { 1 };
                std::iter::repeat_n(block, kinds)
            })
            .collect()
    }

    /// Samples in [`STRUCTURE_WINDOW_S`] of the first training episode
    /// (at least one).
    pub(crate) fn structure_window(&self) -> usize {
        let prepared = self.spec.prepared;
        self.train
            .first()
            .and_then(|&k| sample_period(&prepared.episodes[k].real.time_s))
            .map_or(1, |dt| ((STRUCTURE_WINDOW_S / dt).round() as usize).max(1))
    }

    /// The delay's coordinate, when it is searched.
    pub(crate) fn delay_coordinate(&self) -> Option<(usize, &Dim)> {
        let d = self.delay.as_ref()?;
        let c = self
            .continuous
            .iter()
            .position(|&i| self.space.dims[i].key == DELAY_KEY)?;
        Some((c, d))
    }
}

/// Appends the joint-angle differences (degrees) of `sim` against `real`,
/// sample by sample and joint by joint, then, with `effort_weights`, the
/// effort differences (N m) times each joint's weight.
pub(crate) fn push_residuals(
    real: &Trajectory,
    sim: &Trajectory,
    effort_weights: Option<&[f64]>,
    out: &mut Vec<f64>,
) -> Result<(), String> {
    let (Some(rq), Some(sq)) = (&real.joint_angles_rad, &sim.joint_angles_rad) else {
        return Err("no joint angles".into());
    };
    if sq.len() != rq.len() {
        return Err(format!(
            "the replay has {} samples, the recording {}",
            sq.len(),
            rq.len()
        ));
    }
    for (a, b) in sq.iter().zip(rq) {
        for (x, y) in a.iter().zip(b) {
            out.push((x - y).to_degrees());
        }
    }
    if let Some(w) = effort_weights {
        let (Some(re), Some(se)) = (&real.joint_efforts_nm, &sim.joint_efforts_nm) else {
            return Err("no efforts to compare".into());
        };
        for (a, b) in se.iter().zip(re) {
            for ((x, y), w) in a.iter().zip(b).zip(w) {
                out.push((x - y) * w);
            }
        }
    }
    Ok(())
}

/// Per joint, the weight that makes an effort residual (N m) count like an
/// angle residual (deg) of the same share of the recorded motion: the
/// spread of all recorded angles (deg, about each joint's mean) over the
/// spread of the joint's recorded effort. `None` when some episode has no
/// efforts or an effort never varies.
pub(crate) fn effort_weights(episodes: &[&Episode], joints: usize) -> Option<Vec<f64>> {
    let spread = |rows: &[&Vec<f64>], j: usize| -> f64 {
        let n = rows.len().max(1) as f64;
        let mean = rows.iter().map(|r| r[j]).sum::<f64>() / n;
        (rows.iter().map(|r| (r[j] - mean).powi(2)).sum::<f64>() / n).sqrt()
    };
    let mut angles = Vec::new();
    let mut efforts = Vec::new();
    for e in episodes {
        angles.extend(e.real.joint_angles_rad.as_ref()?.iter());
        efforts.extend(e.real.joint_efforts_nm.as_ref()?.iter());
    }
    let s_q = ((0..joints)
        .map(|j| spread(&angles, j).to_degrees().powi(2))
        .sum::<f64>()
        / joints as f64)
        .sqrt();
    let mut w = Vec::new();
    for j in 0..joints {
        let s_t = spread(&efforts, j);
        if !(s_t > 0.0 && s_t.is_finite()) {
            return None;
        }
        w.push(s_q / s_t);
    }
    Some(w)
}

/// Scores of `runs` (episode index, trajectory) against the recordings.
pub(crate) fn set_score(prepared: &Prepared, runs: &[(usize, Trajectory)]) -> Option<SetScore> {
    let joints = prepared.replayed_joints().len();
    let mut per_joint = vec![0.0; joints];
    let mut n = 0usize;
    let mut episodes = Vec::new();
    let mut sums = Vec::new();
    for (k, sim) in runs {
        let e = &prepared.episodes[*k];
        let (Some(rq), Some(sq)) = (&e.real.joint_angles_rad, &sim.joint_angles_rad) else {
            continue;
        };
        let len = rq.len().min(sq.len());
        if len == 0 {
            continue;
        }
        let mut s = 0.0;
        for i in 0..len {
            for j in 0..joints {
                let d = (sq[i][j] - rq[i][j]).to_degrees();
                per_joint[j] += d * d;
                s += d * d;
            }
        }
        n += len;
        episodes.push((e.id.clone(), (s / (len * joints) as f64).sqrt()));
        sums.push((s, len * joints));
    }
    if n == 0 {
        return None;
    }
    let total: f64 = sums.iter().map(|s| s.0).sum();
    let count: usize = sums.iter().map(|s| s.1).sum();
    let interval = (sums.len() > 1).then(|| {
        let mut rng = SplitMix64::new(2019);
        let reps: Vec<f64> = (0..1000)
            .map(|_| {
                let (mut s, mut c) = (0.0, 0usize);
                for _ in 0..sums.len() {
                    let k = ((rng.uniform() * sums.len() as f64) as usize).min(sums.len() - 1);
                    s += sums[k].0;
                    c += sums[k].1;
                }
                (s / c as f64).sqrt()
            })
            .collect();
        percentile_interval(&reps, 0.95).map(|i| (i.low_m, i.high_m))
    });
    Some(SetScore {
        rms_deg: (total / count as f64).sqrt(),
        interval_deg: interval.flatten(),
        episodes,
        per_joint_deg: per_joint.iter().map(|s| (s / n as f64).sqrt()).collect(),
    })
}

/// The episodes to fit on and to score on: the selection's, or (without
/// `--holdout` and `--runs`) the last quarter of the episodes held out.
pub(crate) fn split(selection: &RunSelection, count: usize) -> Result<(Vec<usize>, Vec<usize>)> {
    if selection.runs.is_none() && selection.holdout.is_none() {
        if count < 2 {
            return Ok(((0..count).collect(), Vec::new()));
        }
        let held = count.div_ceil(4);
        return Ok(((0..count - held).collect(), (count - held..count).collect()));
    }
    selection
        .check_count(count, "episodes")
        .map_err(|e| anyhow!("{}", e.message))?;
    let s = selection
        .select("recordings", count)
        .map_err(|e| anyhow!("{}", e.message))?;
    if selection.holdout.is_some() {
        Ok((s.fit, s.score))
    } else {
        Ok((s.fit, Vec::new()))
    }
}

/// Runs the tune, stage by stage ([`crate::stages`]): writes
/// `OUT/space.toml`, `OUT/history.csv`, `OUT/tune.json`, `OUT/tuned.toml`
/// (`summary.md` and `summary.json` by [`write_summary`]). A rerun whose
/// `tune.json` matches resumes from the best point of `history.csv`.
pub fn tune_recordings(
    spec: &RecordingsSpec,
    progress: &(dyn Fn(RecordingsProgress) + Sync),
) -> Result<RecordingsResult> {
    let started = Instant::now();
    let ready = stages::prepare::recordings(spec, progress)?;
    let p = &ready.problem;
    let (untuned, start_params) = stages::prepare::untuned(p)?;
    let (u, start_residuals) = stages::scan::delay(p, untuned, ready.resumed.as_deref())?;
    let fitted = stages::fit::recordings(p, &u, start_residuals)?;
    let u = fitted.fit.u.clone();
    let (params, identifiability) = stages::intervals::recordings(p, fitted.fit)?;
    let search_time_s = started.elapsed().as_secs_f64();
    let scored = stages::score::recordings(p, &u, &start_params)?;
    let evaluations = *p.evaluations.lock().unwrap_or_else(|e| e.into_inner());
    let prepared = spec.prepared;
    let ids = |set: &[usize]| -> Vec<String> {
        set.iter()
            .map(|&k| prepared.episodes[k].id.clone())
            .collect()
    };
    let summary = RecordingsSummary {
        engine: format!("{} {}", spec.engine.name(), spec.engine.version()),
        robot: prepared.robot.name.clone(),
        recordings: PathBuf::new(),
        train: ids(&p.train),
        holdout: ids(&p.holdout),
        known: known_keys(spec.known),
        objective: ready.objective.clone(),
        params,
        identifiability,
        scores: scored.scores,
        evaluations,
        iterations: fitted.iterations,
        reason: fitted.reason,
        search_time_s,
        wall_time_s: started.elapsed().as_secs_f64(),
        verdict: scored.verdict,
        timestep_check: scored.timestep_check,
        cautions: Vec::new(),
    };
    let summary = RecordingsSummary {
        cautions: cautions(&summary),
        ..summary
    };
    let mut files = ready.files;
    files.push(stages::write::recordings_tuned(
        &spec.out,
        &summary,
        &scored.tuned,
    )?);
    Ok(RecordingsResult { summary, files })
}

pub(crate) fn verdict(scores: &[SourceScores]) -> String {
    let get = |i: usize| {
        scores.get(i).and_then(|s| {
            s.holdout
                .as_ref()
                .or(s.train.as_ref())
                .map(|x| (x.rms_deg, x.interval_deg))
        })
    };
    let on = if scores.iter().any(|s| s.holdout.is_some()) {
        "on the held-out episodes"
    } else {
        "on the training episodes (none held out)"
    };
    let (Some(untuned), Some(tuned), Some(kin)) = (get(0), get(1), get(2)) else {
        return "no score: the engine could not replay the episodes".into();
    };
    let best_kin = scores
        .iter()
        .skip(2)
        .filter_map(|s| {
            s.holdout
                .as_ref()
                .or(s.train.as_ref())
                .map(|x| (s.source.clone(), x.rms_deg))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or(("physics-free".into(), kin.0));
    let beats = tuned.0 < best_kin.1;
    format!(
        "{on}, the tuned engine's joint RMS is {} deg (untuned {}, {:.1}x lower); it {} the best physics-free model ({}, {} deg).",
        degrees(tuned.0),
        degrees(untuned.0),
        untuned.0 / tuned.0.max(1e-12),
        if beats { "beats" } else { "does not beat" },
        best_kin.0,
        degrees(best_kin.1)
    )
}

/// An angle in degrees with three decimals, or three significant digits
/// below 0.01 (a tuned RMS of 0.00048 deg is not "0.000").
fn degrees(x: f64) -> String {
    let digits = if x.is_finite() && x != 0.0 {
        (2 - x.abs().log10().floor() as i64).clamp(3, 12) as usize
    } else {
        3
    };
    format!("{x:.digits$}")
}

fn fmt_interval(i: Option<(f64, f64)>, digits: usize) -> String {
    match i {
        Some((a, b)) => format!("[{a:.digits$}, {b:.digits$}]"),
        None => "n/a".into(),
    }
}

/// The timestep check in words.
pub fn recordings_timestep_text(c: &RecordingsTimestepCheck) -> String {
    let at = format!(
        "Timestep check: at half the step ({} s instead of {} s) the tuned parameters",
        c.halved_s, c.timestep_s
    );
    if !c.failed.is_empty() {
        return format!(
            "{at} could not replay every {} episode ({}): the fit depends on the timestep; use it at {} s only.",
            c.episodes,
            c.failed.join("; "),
            c.timestep_s
        );
    }
    let (Some(t), Some(h)) = (&c.tuned, &c.halved) else {
        return format!("{at} have no score on the {} episodes.", c.episodes);
    };
    let head = format!(
        "{at} replay the {} episodes at a joint RMS of {:.4} deg (at the fit's step {:.4} {})",
        c.episodes,
        h.rms_deg,
        t.rms_deg,
        fmt_interval(t.interval_deg, 4)
    );
    match c.holds {
        Some(true) => format!("{head}: the fit holds at a finer step."),
        Some(false) => format!(
            "{head}: the fit depends on the timestep, part of it is the integration at {} s; use it at that step (tuned.toml carries the engine's settings when you gave them), or tune at the step you will run.",
            c.timestep_s
        ),
        None => format!("{head}; with one episode there is no interval to tell."),
    }
}

/// How far the intervals of `s` can be trusted, in words: what they rest
/// on (the residuals' reading noise and structure), then what in this fit
/// limits them (parameters on a bound, a fit that does not carry over to
/// the held-out episodes, a search that did not converge).
pub fn cautions(s: &RecordingsSummary) -> Vec<String> {
    let mut out = Vec::new();
    let r = &s.identifiability.residuals;
    let structured = r.structure_deg > 3.0 * r.noise_deg;
    out.push(if structured {
        format!(
            "The residuals are mostly structure the engine cannot reproduce ({:.5} deg RMS, smooth in time) against {:.5} deg of white reading noise. Each interval is the range over which its parameter, the others refitted, moves the replay by no more than that structure (plus the noise's Gauss-Newton share): a bound on what such a model error shifts the fit by, provided the parameters took up no more of it than they left in the residuals. It is not a statistical spread: an error the parameters take up whole (commands applied at the wrong instant, an effect the engine lacks) can put the truth outside.",
            r.structure_deg, r.noise_deg
        )
    } else {
        format!(
            "The residuals are mostly white reading noise ({:.5} deg, against {:.5} deg RMS of structure the engine cannot reproduce): each interval is Gauss-Newton's for that noise, widened by what such a structure could shift the fit by.",
            r.noise_deg, r.structure_deg
        )
    });
    let bound: Vec<String> = s
        .params
        .iter()
        .filter(|p| p.at_bound)
        .map(|p| format!("{} ({})", p.key, p.value))
        .collect();
    if !bound.is_empty() {
        out.push(format!(
            "The fit ended on a bound of the space: {}. An interval is cut at its bound, and the parameters correlated with one that could not go on may have made up for it, so their intervals cannot be trusted either; widen the bound in space.toml and pass it back with --space.",
            bound.join(", ")
        ));
    }
    if let Some(tuned) = s.scores.get(1) {
        if let (Some(t), Some(h)) = (&tuned.train, &tuned.holdout) {
            if h.rms_deg > 2.0 * t.rms_deg {
                out.push(format!(
                    "The tuned engine's joint RMS on the held-out episodes ({:.5} deg) is more than twice its training RMS ({:.5} deg): what was fitted does not carry over to episodes it never saw, and the intervals describe the training episodes only.",
                    h.rms_deg, t.rms_deg
                ));
            }
        }
    }
    if s.reason.contains("iteration limit") || s.reason.contains("could not") {
        out.push(format!(
            "The last fit stopped at {}, not at a converged optimum: the intervals are those of where it stopped.",
            s.reason
        ));
    }
    out
}

/// `summary.md`.
pub fn summary_markdown(s: &RecordingsSummary) -> String {
    let mut m = format!(
        "# Tune of {} against the recordings of robot '{}'\n\n{}\n\nTraining episodes: {}. Held out: {}. Known and fixed: {}.\n\n",
        s.engine,
        s.robot,
        s.verdict,
        s.train.join(", "),
        if s.holdout.is_empty() {
            "none".into()
        } else {
            s.holdout.join(", ")
        },
        if s.known.is_empty() {
            "nothing".into()
        } else {
            s.known.join(", ")
        }
    );
    let _ = writeln!(m, "Objective: {}.\n", s.objective);
    m.push_str("## Joint-space RMS (degrees, 95 % bootstrap interval over episodes)\n\n| source | training | held out |\n|---|---:|---:|\n");
    for sc in &s.scores {
        let cell = |x: &Option<SetScore>| match x {
            Some(x) => format!("{:.4} {}", x.rms_deg, fmt_interval(x.interval_deg, 4)),
            None => "n/a".into(),
        };
        let _ = writeln!(
            m,
            "| {} | {} | {} |",
            sc.source,
            cell(&sc.train),
            cell(&sc.holdout)
        );
    }
    // Say why an interval is missing: the bootstrap over episodes needs two.
    let lone: Vec<String> = s
        .scores
        .first()
        .map(|sc| {
            [("training", &sc.train), ("held-out", &sc.holdout)]
                .into_iter()
                .filter_map(|(name, set)| {
                    set.as_ref()
                        .filter(|x| x.interval_deg.is_none() && x.episodes.len() < 2)
                        .map(|x| format!("the {name} set has {}", x.episodes.len()))
                })
                .collect()
        })
        .unwrap_or_default();
    if !lone.is_empty() {
        let _ = writeln!(
            m,
            "\nn/a: an interval over episodes needs at least two episodes; {} (--runs and --holdout choose them).",
            lone.join(", ")
        );
    }
    let _ = writeln!(m, "\n{}", recordings_timestep_text(&s.timestep_check));
    if !s.cautions.is_empty() {
        m.push_str("\n## How far to trust the intervals\n\n");
        for c in &s.cautions {
            let _ = writeln!(m, "- {c}");
        }
    }
    m.push_str("\n## Parameters (95 % intervals from the Jacobian at the optimum)\n\n| key | untuned | fitted | interval | bounds |\n|---|---:|---:|---|---|\n");
    for p in &s.params {
        let _ = writeln!(
            m,
            "| {} | {:.6} | {:.6} | {} | [{}, {}]{} |",
            p.key,
            p.start,
            p.value,
            fmt_interval(p.interval, 6),
            p.bounds.0,
            p.bounds.1,
            if p.at_bound { " (at a bound)" } else { "" }
        );
    }
    let i = &s.identifiability;
    m.push_str("\n## What the data cannot tell\n\n");
    if i.unseen.is_empty() && i.trading.is_empty() {
        m.push_str("Every fitted parameter is pinned by the data (no interval spans its range, no pair correlates beyond 0.95).\n");
    }
    if !i.unseen.is_empty() {
        let _ = writeln!(
            m,
            "- Not seen by the data (interval spans the whole range): {}.",
            i.unseen.join(", ")
        );
    }
    for (a, b, c) in &i.trading {
        let _ = writeln!(
            m,
            "- {a} and {b} trade against each other (correlation {c:.3})."
        );
    }
    let res = &i.residuals;
    let _ = writeln!(
        m,
        "\nResiduals: {} (one per joint and sample), RMS {:.5} deg: white noise {:.5} deg, and {:.5} deg RMS smooth in time (averaged over {} samples), what the engine cannot reproduce; autocorrelated {:.4} from one sample to the next.\n\n{} evaluations (each replays every training episode), {} Jacobians by differences (Levenberg-Marquardt, Broyden's updates between them), {:.1} s of search ({:.1} s with the scores and the timestep check); the last fit stopped at {}.",
        res.count, res.rms_deg, res.noise_deg, res.structure_deg, res.window_samples, i.residual_autocorrelation, s.evaluations, s.iterations, s.search_time_s, s.wall_time_s, s.reason
    );
    m
}

/// Writes `summary.md` and `summary.json` for `result`, with the
/// recordings' folder.
pub fn write_summary(out: &Path, recordings: &Path, result: &mut RecordingsResult) -> Result<()> {
    result.summary.recordings = recordings.to_path_buf();
    let md = out.join("summary.md");
    std::fs::write(&md, summary_markdown(&result.summary))
        .with_context(|| format!("writing {}", md.display()))?;
    let js = out.join("summary.json");
    std::fs::write(&js, serde_json::to_string_pretty(&result.summary)? + "\n")
        .with_context(|| format!("writing {}", js.display()))?;
    result.files.push(md);
    result.files.push(js);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_split_holds_out_the_last_quarter() {
        let none = RunSelection {
            runs: None,
            holdout: None,
        };
        assert_eq!(split(&none, 4).unwrap(), (vec![0, 1, 2], vec![3]));
        assert_eq!(
            split(&none, 8).unwrap(),
            (vec![0, 1, 2, 3, 4, 5], vec![6, 7])
        );
        assert_eq!(split(&none, 1).unwrap(), (vec![0], vec![]));
        let h = RunSelection {
            runs: None,
            holdout: Some(
                realitygap_analysis::selection::RunRange::parse("3-4", "--holdout").unwrap(),
            ),
        };
        assert_eq!(split(&h, 4).unwrap(), (vec![0, 1], vec![2, 3]));
        let bad = RunSelection {
            runs: None,
            holdout: Some(
                realitygap_analysis::selection::RunRange::parse("9", "--holdout").unwrap(),
            ),
        };
        let e = split(&bad, 4).unwrap_err().to_string();
        assert!(e.contains("--holdout") && e.contains("9"), "{e}");
    }

    #[test]
    fn small_angles_keep_three_significant_digits() {
        assert_eq!(degrees(0.721), "0.721");
        assert_eq!(degrees(1.8194), "1.819");
        assert_eq!(degrees(0.0123), "0.0123");
        assert_eq!(degrees(0.00047984), "0.000480");
        assert_eq!(degrees(0.0), "0.000");
    }

    #[test]
    fn set_key_overrides_only_the_given_field() {
        let mut p = PhysicalParams::none();
        p.joints.entry("j1".into()).or_default().kp = Some(700.0);
        set_key(&mut p, "joints.j1.damping", 2.0).unwrap();
        set_key(&mut p, "controller.delay_s", 0.02).unwrap();
        assert_eq!(p.joints["j1"].kp, Some(700.0));
        assert_eq!(p.joints["j1"].damping, Some(2.0));
        assert_eq!(p.controller.delay_s, Some(0.02));
        assert!(set_key(&mut p, "joints.j1.nosuch", 1.0).is_err());
    }
}
