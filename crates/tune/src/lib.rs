//! `realitygap tune`: fits an engine's physical parameters (and by default
//! the capture frame's registration) to the real arm's training runs, then
//! scores the untuned and the tuned engine on the training and the
//! held-out runs.
//!
//! - [`space`]: what is fitted ([`space::Space`], `assets/tuning/<engine>.toml`);
//! - [`objective`]: what is minimised and how a candidate is simulated;
//! - [`mod@search`]: CMA-ES with parallel, isolated, resumable evaluations;
//! - [`outputs`]: sensitivity, the final scores and the files written;
//! - [`recordings`]: `tune --recordings`, a robot's own recorded episodes
//!   fitted in joint space by [`least_squares`] (Levenberg-Marquardt with
//!   intervals and an identifiability report);
//! - [`crossval`]: a study tune cross-validated over folds of real runs;
//! - [`stages`]: the stages both tunes run, in order (prepare, scan, fit,
//!   profile, intervals, score, write), with one profile code and one
//!   Jacobian holder for both.

#![forbid(unsafe_code)]

pub mod crossval;
pub mod least_squares;
pub mod objective;
pub mod outputs;
pub mod polish;
pub mod recordings;
pub mod search;
pub mod slurm_batch;
pub mod space;
pub mod stages;
pub mod tosses;

use anyhow::{bail, Context, Result};
use objective::{offset_registration, Score, Simulator, Target};
use realitygap_analysis::registration::Registration;
use realitygap_core::engine::EngineSettings;
use realitygap_core::params::PhysicalParams;
use search::{Outcome, Progress, SearchEnd, SearchOptions};
use serde::Serialize;
use space::Space;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The tuning folder of the assets: `<assets>/tuning/<engine>.toml`.
pub fn default_space_file(assets: &Path, engine: &str) -> PathBuf {
    assets.join("tuning").join(format!("{engine}.toml"))
}

/// Everything a tune is asked to do.
#[derive(Clone)]
pub struct TuneSpec {
    /// The engine.
    pub engine: String,
    /// The space.
    pub space: Space,
    /// Fit the registration too (the space's bounds), or keep the
    /// measurement's estimate.
    pub fit_registration: bool,
    /// Engine settings given on the command line, over the space's.
    pub set: EngineSettings,
    /// Search settings.
    pub search: SearchOptions,
    /// The output folder.
    pub out: PathBuf,
    /// The least-squares polish after the search.
    pub polish: polish::PolishOptions,
    /// The physics-free model's actuator space (`assets/tuning/ideal.toml`):
    /// fitted on the same training runs, it is the "physics-free +
    /// actuator" row every tune is scored against. `None`: that row is
    /// left out (the physics-free row stays).
    pub baseline_space: Option<Space>,
    /// Fit the physics-free row first and start the engine's search at its
    /// fitted values: the keys both spaces have (the actuator stage, the
    /// delay, the acceleration limit, the encoder offsets) and the
    /// registration. `false`: the search starts at the space's `start`.
    pub start_from_baseline: bool,
    /// The weight of the pull toward the physics-free model's fitted
    /// values (`--prior-weight`): the objective adds `weight` x the sum,
    /// over the keys both fits share ([`TuneSpec::prior`]), of each key's
    /// squared distance from the physics-free model's value as a fraction
    /// of its range in the engine's space (in its scale). Metres of
    /// accumulated wrist error per key moved across its whole range. 0:
    /// no pull.
    pub prior_weight: f64,
    /// The keys pulled and their centres, set by [`tune`] from the
    /// physics-free model's fit when [`TuneSpec::prior_weight`] > 0.
    pub prior: Vec<PriorKey>,
}

/// One key of the pull toward the physics-free model's fitted values
/// ([`TuneSpec::prior_weight`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PriorKey {
    /// The key, as in [`Tuner::value_names`].
    pub key: String,
    /// The physics-free model's fitted value.
    pub centre: f64,
    /// The engine's range of the key (its bounds, in the engine's space
    /// before the polish widens any).
    pub low: f64,
    /// Upper end of that range.
    pub high: f64,
    /// Whether the key is searched in its logarithm.
    pub log: bool,
    /// The key's position in [`Tuner::values`] for the spec's space,
    /// resolved by [`prior_keys`] and again by [`TuneSpec::with_space`]
    /// so that an evaluation finds it without comparing names.
    index: usize,
}

impl PriorKey {
    /// The key's position in [`Tuner::values`] (the space's keys, then the
    /// registration's).
    pub fn index(&self) -> usize {
        self.index
    }

    /// The distance of `value` from the centre, as a fraction of the
    /// range (signed; not clamped, so a widened bound keeps pulling).
    pub fn distance(&self, value: f64) -> f64 {
        if self.log {
            (value.max(f64::MIN_POSITIVE).ln() - self.centre.max(f64::MIN_POSITIVE).ln())
                / (self.high.ln() - self.low.ln())
        } else {
            (value - self.centre) / (self.high - self.low)
        }
    }
}

/// The position of `key` among a tune's values over `space`: the space's
/// keys, then the registration's six when it is fitted.
fn place_of(space: &Space, fit_registration: bool, key: &str) -> Option<usize> {
    space.dims.iter().position(|d| d.key == key).or_else(|| {
        let i = space::REGISTRATION_KEYS.iter().position(|k| *k == key)?;
        (fit_registration && space.registration.is_some()).then_some(space.dims.len() + i)
    })
}

/// The keys of `space` (the registration's when `fit_registration`) that
/// `values` (the physics-free model's fit, by key) also has, centred on
/// those values: what [`TuneSpec::prior_weight`] pulls.
pub fn prior_keys(
    space: &Space,
    fit_registration: bool,
    values: &[(String, f64)],
) -> Vec<PriorKey> {
    // Each key with its range: the space's, then the registration's.
    let mut ranges: Vec<(String, f64, f64, bool)> = space
        .dims
        .iter()
        .map(|d| (d.key.clone(), d.low, d.high, d.scale == space::Scale::Log))
        .collect();
    if let Some(b) = space.registration.filter(|_| fit_registration) {
        for (i, k) in space::REGISTRATION_KEYS.iter().enumerate() {
            let bound = if i < 3 {
                b.rotation_deg
            } else {
                b.translation_mm
            };
            ranges.push((k.to_string(), -bound, bound, false));
        }
    }
    ranges
        .into_iter()
        .filter_map(|(key, low, high, log)| {
            let centre = values.iter().find(|(k, _)| *k == key)?.1;
            let index = place_of(space, fit_registration, &key)?;
            Some(PriorKey {
                key,
                centre,
                low,
                high,
                log,
                index,
            })
        })
        .collect()
}

impl TuneSpec {
    /// The same tune over another space.
    ///
    /// The pulled keys keep their centres and ranges, and are placed
    /// again among the new space's values.
    ///
    /// # Panics
    ///
    /// When the new space lacks a pulled key: the later spaces of a tune
    /// (the polish's widened bounds, the physics-free start) keep the
    /// first space's keys.
    pub fn with_space(&self, space: Space) -> TuneSpec {
        let prior = self
            .prior
            .iter()
            .map(|p| PriorKey {
                index: place_of(&space, self.fit_registration, &p.key).unwrap_or_else(|| {
                    panic!("the pulled key {} is not in the tune's new space", p.key)
                }),
                ..p.clone()
            })
            .collect();
        TuneSpec {
            space,
            prior,
            ..self.clone()
        }
    }
}

/// What the command prints and the files hold.
pub struct TuneResult {
    /// The search.
    pub end: SearchEnd,
    /// The summary written to `summary.json`.
    pub summary: outputs::Summary,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// The state a tune keeps in `OUT/tune.json`, which a rerun must match to
/// resume.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
struct Resume {
    engine: String,
    space: serde_json::Value,
    settings: Vec<(String, String)>,
    fit_registration: bool,
    seed: u64,
    /// Absent from the files of tunes made before restarts existed.
    #[serde(default)]
    restarts: bool,
    train: Option<String>,
    holdout: Option<String>,
    cube_weight_per_step: f64,
    /// Absent from the files of tunes made before the pull existed.
    #[serde(default)]
    prior_weight: f64,
}

/// A tune: the candidates' parameters and registrations, and their
/// evaluation.
pub struct Tuner<'a> {
    /// The real arm.
    pub target: &'a Target,
    /// How candidates are simulated.
    pub simulator: &'a Simulator,
    /// What is asked.
    pub spec: &'a TuneSpec,
}

impl Tuner<'_> {
    /// The physical parameters (with the engine settings) at normalised
    /// coordinates `u`.
    pub fn params(&self, u: &[f64]) -> Result<PhysicalParams, String> {
        let values = self.spec.space.values(u);
        self.spec
            .space
            .params(&values, &self.spec.engine, &self.spec.set)
    }

    /// The registration at normalised coordinates `u`.
    pub fn registration(&self, u: &[f64]) -> Registration {
        match self
            .spec
            .space
            .registration_offset(u)
            .filter(|_| self.spec.fit_registration)
        {
            Some((r, t)) => offset_registration(&self.target.base_registration, r, t),
            None => self.target.base_registration,
        }
    }

    /// Simulates and scores parameters `params` with `registration`.
    pub fn score(&self, params: &PhysicalParams, registration: &Registration) -> Score {
        match self.simulator.simulate(&self.target.scenes, params) {
            Ok(trajs) => self.target.score(trajs, registration),
            Err(m) => Score::failed(m),
        }
    }

    /// The polish's residuals at normalised coordinates `u`: the
    /// errors' ([`Tuner::errors`]), the pull's included.
    pub fn residuals(&self, u: &[f64]) -> Result<Vec<f64>, String> {
        Ok(self.errors(u)?.residuals(None))
    }

    /// The pull toward the physics-free model's values at `u`
    /// ([`TuneSpec::prior_weight`]): one residual per pulled key, whose
    /// squares sum to the objective's added term. Empty without a pull.
    pub fn prior_residuals(&self, u: &[f64]) -> Vec<f64> {
        if self.spec.prior_weight <= 0.0 || self.spec.prior.is_empty() {
            return Vec::new();
        }
        let values = self.values(u);
        let w = self.spec.prior_weight.sqrt();
        self.spec
            .prior
            .iter()
            .map(|p| w * p.distance(values[p.index]))
            .collect()
    }

    /// The errors at normalised coordinates `u`
    /// ([`objective::Target::errors`]): the polish's reweighted residuals.
    pub fn errors(&self, u: &[f64]) -> Result<objective::Errors, String> {
        let p = self.params(u)?;
        let trajs = self.simulator.simulate(&self.target.scenes, &p)?;
        let mut errors = self.target.errors(trajs, &self.registration(u))?;
        errors.prior = self.prior_residuals(u);
        Ok(errors)
    }

    /// The search's evaluation of normalised coordinates `u`.
    pub fn evaluate(&self, u: &[f64]) -> Outcome {
        let score = match self.params(u) {
            Ok(p) => self.score(&p, &self.registration(u)),
            Err(m) => Score::failed(m),
        };
        let pull: f64 = if score.failed.is_some() {
            0.0
        } else {
            self.prior_residuals(u).iter().map(|r| r * r).sum()
        };
        Outcome {
            objective: score.objective + pull,
            parts: self.parts(&score),
            failed: score.failed,
        }
    }

    /// Names of the per-scene history columns.
    pub fn part_names(&self) -> Vec<String> {
        let mut n = Vec::new();
        for s in &self.target.scenes {
            n.push(format!("{}_accumulated_m", s.name));
            if s.cube {
                n.push(format!("{}_cube_final_m", s.name));
                n.push(format!("{}_cube_turn_deg", s.name));
            }
        }
        n
    }

    fn parts(&self, score: &Score) -> Vec<f64> {
        let mut p = Vec::new();
        for s in &self.target.scenes {
            let sc = score.scenes.iter().find(|x| x.scene == s.name);
            p.push(sc.map_or(f64::NAN, |x| x.accumulated_m));
            if s.cube {
                p.push(sc.and_then(|x| x.cube_final_m).unwrap_or(f64::NAN));
                p.push(sc.and_then(|x| x.cube_turn_deg).unwrap_or(f64::NAN));
            }
        }
        p
    }

    /// Names of the recorded values: the parameters, then the
    /// registration offset when fitted.
    pub fn value_names(&self) -> Vec<String> {
        let mut n: Vec<String> = self.spec.space.dims.iter().map(|d| d.key.clone()).collect();
        if self.fits_registration() {
            n.extend(space::REGISTRATION_KEYS.map(String::from));
        }
        n
    }

    /// The values recorded for normalised coordinates `u`.
    pub fn values(&self, u: &[f64]) -> Vec<f64> {
        let mut v = self.spec.space.values(u);
        if self.fits_registration() {
            if let Some((r, t)) = self.spec.space.registration_offset(u) {
                v.extend(r);
                v.extend(t.map(|m| m * 1000.0));
            }
        }
        v
    }

    pub(crate) fn fits_registration(&self) -> bool {
        self.spec.fit_registration && self.spec.space.registration.is_some()
    }

    /// The search coordinates: the parameters, and the registration's six
    /// when fitted.
    pub fn dims(&self) -> usize {
        self.spec.space.dims.len() + if self.fits_registration() { 6 } else { 0 }
    }
}

fn resume_state(spec: &TuneSpec, target: &Target) -> Resume {
    Resume {
        engine: spec.engine.clone(),
        space: serde_json::to_value(&spec.space).unwrap_or_default(),
        settings: spec
            .set
            .iter()
            .map(|(k, v)| (k.clone(), v.to_string()))
            .collect(),
        fit_registration: spec.fit_registration,
        seed: spec.search.seed,
        restarts: spec.search.restarts,
        train: target.train.runs.as_ref().map(|r| r.text.clone()),
        holdout: target.holdout.as_ref().map(|r| r.text.clone()),
        cube_weight_per_step: target.cube_weight_per_step,
        prior_weight: spec.prior_weight,
    }
}

/// Checks `OUT/tune.json` against this tune (writing it when new): a
/// folder made by a different tune is an error, never mixed in.
pub(crate) fn check_resume(spec: &TuneSpec, target: &Target) -> Result<()> {
    std::fs::create_dir_all(&spec.out)
        .with_context(|| format!("creating {}", spec.out.display()))?;
    let path = spec.out.join("tune.json");
    let now = resume_state(spec, target);
    if path.exists() {
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let before: Resume = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a tune's state file", path.display()))?;
        if before != now {
            bail!(
                "{} holds a different tune (engine, space, settings, seed or runs differ): use another --out, or remove the folder to start again",
                spec.out.display()
            );
        }
        return Ok(());
    }
    std::fs::write(&path, serde_json::to_string_pretty(&now)? + "\n")
        .with_context(|| format!("writing {}", path.display()))
}

/// A fit: the search, the identifiability at its start, and the polish.
pub struct Fitted {
    /// The search.
    pub end: SearchEnd,
    /// The polish from the search's best point, or from the space's start
    /// when that scored lower.
    pub polished: polish::Polished,
    /// The identifiability check before the search.
    pub before: Option<polish::IdentifiabilityReport>,
}

impl Fitted {
    /// The spec of the polished space (bounds widened where they were).
    pub fn polished_spec(&self, spec: &TuneSpec) -> TuneSpec {
        TuneSpec {
            baseline_space: None,
            ..spec.with_space(self.polished.space.clone())
        }
    }
}

/// Fits `spec`, stage by stage ([`stages`]): the checks
/// ([`stages::prepare::study`]), the identifiability check
/// ([`stages::intervals::before`]), the search ([`stages::scan::study`],
/// resuming from `OUT/history.csv`) and the polish ([`polish::polish`]).
pub fn fit(
    target: &Target,
    simulator: &Simulator,
    spec: &TuneSpec,
    progress: &(dyn Fn(Progress) + Sync),
    note: &(dyn Fn(String) + Sync),
) -> Result<Fitted> {
    let tuner = Tuner {
        target,
        simulator,
        spec,
    };
    stages::prepare::study(&tuner)?;
    let before = stages::intervals::before(&tuner, note);
    let end = stages::scan::study(&tuner, before.as_ref(), progress)?;
    let best = end.best().ok_or_else(|| {
        anyhow::anyhow!(
            "every candidate failed; see {}",
            spec.out.join("history.csv").display()
        )
    })?;
    let (u, objective, start_evaluations) = polish_start(&tuner, best, note);
    let mut polished = polish::polish(&tuner, &u, objective, spec.polish, note)?;
    polished.report.evaluations += start_evaluations;
    Ok(Fitted {
        end,
        polished,
        before,
    })
}

/// Where the polish starts: the search's best point, or the space's own
/// start when that scores lower (a search cut short by a small
/// `--budget`, or a start already at the optimum): the polish only goes
/// down from where it starts, so a tune never ends above its start. With
/// the evaluations it made (one, at the start), for the polish's account.
fn polish_start(
    tuner: &Tuner<'_>,
    best: &search::Evaluation,
    note: &(dyn Fn(String) + Sync),
) -> (Vec<f64>, f64, usize) {
    let u: Vec<f64> = best.x.iter().map(|x| search::reflect(*x)).collect();
    let start = tuner.spec.space.start_unit()[..tuner.dims()].to_vec();
    let at_start = tuner.evaluate(&start);
    if at_start.failed.is_none() && at_start.objective < best.objective {
        note(format!(
            "the search ended above its start ({:.4} m against {:.4} m at the start): the tune goes on from the start",
            best.objective, at_start.objective
        ));
        return (start, at_start.objective, 1);
    }
    (u, best.objective, 1)
}

/// Whether a key belongs to the objects or the contact
/// (`objects.*`, `contact.*`).
pub fn is_object_or_contact_key(key: &str) -> bool {
    key.starts_with("objects.") || key.starts_with("contact.")
}

/// `space` with the objects' and the contact's keys held at the scenes'
/// own values when no scene of `target` weighs its cube (`--cube-weight
/// 0`, or no cube): the wrist alone then sees them only as far as the hand
/// touches the cube, below the real runs' noise on the study, and a search
/// that is free to move them ends where it likes (MuJoCo's wrist-only
/// tune flung the cube 6.1 m, against the real 0.1 m). `None` when the cube
/// is weighed or the space has none of those keys.
pub fn cube_unseen(target: &Target, space: &Space) -> Option<Space> {
    let weighed = target.scenes.iter().any(|s| s.cube && s.cube_weight > 0.0);
    let any = space.dims.iter().any(|d| is_object_or_contact_key(&d.key));
    (!weighed && any).then(|| space.holding(is_object_or_contact_key))
}

/// The physics-free model behind its own actuator stage (`space`) fitted
/// on `target` with the effort of `spec`, into `OUT/physics-free-actuator`;
/// with its fitted values by key (the registration's offset as
/// `registration.rx_deg` ... `registration.tz_mm`).
fn fit_baseline(
    target: &Target,
    simulator: &Simulator,
    spec: &TuneSpec,
    space: &Space,
) -> Result<(outputs::Baseline, Vec<(String, f64)>)> {
    let sim = Simulator {
        engine: outputs::PHYSICS_FREE.to_string(),
        ..simulator.clone()
    };
    let bspec = TuneSpec {
        engine: outputs::PHYSICS_FREE.to_string(),
        fit_registration: spec.fit_registration && space.registration.is_some(),
        space: space.clone(),
        set: EngineSettings::new(),
        // The same effort as the engine's own fit: the same budget,
        // polish, widening and probe.
        search: spec.search,
        out: spec.out.join(outputs::PHYSICS_FREE_DIR),
        polish: spec.polish,
        baseline_space: None,
        start_from_baseline: false,
        prior_weight: 0.0,
        prior: Vec::new(),
    };
    let b = fit(target, &sim, &bspec, &|_| {}, &|_| {})?;
    let pspec = b.polished_spec(&bspec);
    let t = Tuner {
        target,
        simulator: &sim,
        spec: &pspec,
    };
    let values = t
        .value_names()
        .into_iter()
        .zip(t.values(&b.polished.u))
        .collect();
    Ok((outputs::Baseline::new(target, &sim, &bspec, b)?, values))
}

/// Runs a whole tune: [`fit`], the physics-free model behind its own
/// fitted actuator stage ([`TuneSpec::baseline_space`], in
/// `OUT/physics-free-actuator/`), the final scores and every output file.
pub fn tune(
    target: &Target,
    simulator: &Simulator,
    spec: &TuneSpec,
    progress: &(dyn Fn(Progress) + Sync),
    note: &(dyn Fn(String) + Sync),
) -> Result<TuneResult> {
    let started = Instant::now();
    let held_spec;
    let spec = match cube_unseen(target, &spec.space) {
        Some(space) => {
            note(format!(
                "held at the scenes' own values, as the objective does not weigh a cube (--cube-weight 0, or no cube): {}",
                space.held.join(", ")
            ));
            held_spec = spec.with_space(space);
            &held_spec
        }
        None => spec,
    };
    let physics_free = spec
        .baseline_space
        .as_ref()
        .filter(|_| spec.engine != outputs::PHYSICS_FREE);
    if spec.prior_weight > 0.0 && physics_free.is_none() {
        bail!("--prior-weight pulls toward the physics-free model's fitted actuator stage, which this tune does not fit (--no-baseline, or the engine is the physics-free model)");
    }
    let (fitted, baseline, seeded) = match physics_free {
        Some(space) if spec.start_from_baseline || spec.prior_weight > 0.0 => {
            note("fitting the physics-free model's actuator stage first".into());
            let (baseline, values) = fit_baseline(target, simulator, spec, space)?;
            let mut seeded = spec.clone();
            if spec.start_from_baseline {
                let (space, moved) = spec.space.starting_at(&values);
                note(format!(
                    "the search starts at the physics-free model's fitted {}",
                    moved.join(", ")
                ));
                seeded = seeded.with_space(space);
            }
            if spec.prior_weight > 0.0 {
                seeded.prior = prior_keys(&seeded.space, seeded.fit_registration, &values);
                note(format!(
                    "pulled toward the physics-free model's fitted values with weight {} m per range: {}",
                    spec.prior_weight,
                    seeded
                        .prior
                        .iter()
                        .map(|p| p.key.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
            realitygap_runner::interrupt::check()?;
            let fitted = fit(target, simulator, &seeded, progress, note)?;
            (fitted, Some(baseline), Some(seeded))
        }
        Some(space) => {
            let fitted = fit(target, simulator, spec, progress, note)?;
            realitygap_runner::interrupt::check()?;
            note("fitting the physics-free model's actuator stage on the same runs".into());
            let baseline = fit_baseline(target, simulator, spec, space)?.0;
            (fitted, Some(baseline), None)
        }
        None => (fit(target, simulator, spec, progress, note)?, None, None),
    };
    let spec = seeded.as_ref().unwrap_or(spec);
    let polished_spec = fitted.polished_spec(spec);
    let final_tuner = Tuner {
        target,
        simulator,
        spec: &polished_spec,
    };
    let (summary, files) = outputs::finish(&final_tuner, &fitted, baseline.as_ref(), started)?;
    // Final scores cut short by an interruption are not a result.
    realitygap_runner::interrupt::check()?;
    Ok(TuneResult {
        end: fitted.end,
        summary,
        files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tune of `space` with nothing else asked.
    fn spec_over(space: Space) -> TuneSpec {
        TuneSpec {
            engine: "mujoco".into(),
            space,
            fit_registration: true,
            set: EngineSettings::new(),
            search: SearchOptions {
                budget: 1,
                seed: 0,
                jobs: 1,
                restarts: false,
                stall_m: None,
            },
            out: PathBuf::new(),
            polish: polish::PolishOptions::default(),
            baseline_space: None,
            start_from_baseline: false,
            prior_weight: 1.0,
            prior: Vec::new(),
        }
    }

    /// Each shared key is centred on the physics-free model's value and
    /// measured in the engine's range and scale; the registration in its
    /// bounds; keys the physics-free fit lacks are not pulled.
    #[test]
    fn the_pull_measures_each_shared_key_in_the_engines_range_and_scale() {
        let space = Space::from_toml_str(
            r#"
[registration]
rotation_deg = 2.0
translation_mm = 15.0

[params]
"controller.delay_s" = { low = 0.0, high = 0.15, start = 0.0 }
"actuator.frequency_rad_s" = { low = 4.0, high = 200.0, scale = "log", start = 100.0 }
"joints.j.damping" = { low = 0.0, high = 5.0, start = 0.0 }
"#,
            Path::new("space.toml"),
        )
        .unwrap();
        let fitted: Vec<(String, f64)> = [
            ("controller.delay_s", 0.03),
            ("actuator.frequency_rad_s", 20.0),
            ("registration.rx_deg", 0.5),
            ("registration.tz_mm", -3.0),
            ("something.else", 1.0),
        ]
        .iter()
        .map(|(k, v)| (k.to_string(), *v))
        .collect();
        let keys = prior_keys(&space, true, &fitted);
        let names: Vec<&str> = keys.iter().map(|k| k.key.as_str()).collect();
        assert_eq!(
            names,
            [
                "controller.delay_s",
                "actuator.frequency_rad_s",
                "registration.rx_deg",
                "registration.tz_mm"
            ]
        );
        // 15 ms past the centre is a tenth of the range.
        assert!((keys[0].distance(0.045) - 0.1).abs() < 1e-12);
        assert!((keys[0].distance(0.015) + 0.1).abs() < 1e-12);
        // Log scale: a factor of 50 (the range's) is the whole range.
        assert!((keys[1].distance(20.0 * 50.0) - 1.0).abs() < 1e-12);
        assert!((keys[1].distance(20.0 / 50.0f64.sqrt()) + 0.5).abs() < 1e-12);
        // The registration within its bounds (+-2 deg, +-15 mm).
        assert!((keys[2].distance(1.5) - 0.25).abs() < 1e-12);
        assert!((keys[3].distance(0.0) - 0.1).abs() < 1e-12);
        // Past a bound the pull keeps growing (a widened polish bound).
        assert!((keys[0].distance(0.33) - 2.0).abs() < 1e-12);
        // Each key's place among a tune's values: the space's keys, then
        // the registration's six (rx, ry, rz, tx, ty, tz).
        let index: Vec<usize> = keys.iter().map(|k| k.index()).collect();
        assert_eq!(index, [0, 1, 3, 8]);
        // A new space (here the registration's keys first among the
        // params' ordering changed) places the keys again.
        let reordered = Space::from_toml_str(
            r#"
[registration]
rotation_deg = 2.0
translation_mm = 15.0

[params]
"joints.j.damping" = { low = 0.0, high = 5.0, start = 0.0 }
"actuator.frequency_rad_s" = { low = 4.0, high = 200.0, scale = "log", start = 100.0 }
"controller.delay_s" = { low = 0.0, high = 0.15, start = 0.0 }
"#,
            Path::new("space.toml"),
        )
        .unwrap();
        let spec = TuneSpec {
            prior: keys.clone(),
            ..spec_over(space.clone())
        }
        .with_space(reordered);
        let index: Vec<usize> = spec.prior.iter().map(|k| k.index()).collect();
        assert_eq!(index, [2, 1, 3, 8]);
        assert_eq!(spec.prior[0].centre, keys[0].centre);
        // Without a fitted registration, no registration key.
        let keys = prior_keys(&space, false, &fitted);
        assert_eq!(keys.len(), 2);
    }
}
