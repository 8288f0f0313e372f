//! Before anything is fitted: the space, the episodes or runs, the output
//! folder and the state a rerun resumes from (the study tune, [`study`];
//! the recordings tune, [`recordings`]).

use crate::least_squares;
use crate::recordings::{
    default_space, effort_weights, known_keys, split, Problem, RecordingsProgress, RecordingsSpec,
    DELAY_KEY,
};
use crate::space::Space;
use crate::stages::write;
use crate::Tuner;
use anyhow::{anyhow, bail, Context, Result};
use realitygap_core::params::PhysicalParams;
use realitygap_study::replay::Episode;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// A recordings tune ready to run.
pub struct Ready<'a> {
    /// The problem: the space, the episodes, the residuals.
    pub(crate) problem: Problem<'a>,
    /// Files written so far.
    pub files: Vec<PathBuf>,
    /// The best point of the history a rerun resumes from (values).
    pub resumed: Option<Vec<f64>>,
    /// What the objective compares, in words.
    pub objective: String,
}

/// The space of a recordings tune: the given one less the known keys, or
/// the URDF's ([`default_space`]).
fn space(spec: &RecordingsSpec) -> Result<Space> {
    match &spec.space {
        Some(s) => {
            // The known parameters are fixed: never searched.
            let fixed = known_keys(spec.known);
            let mut s = s.clone();
            s.dims.retain(|d| !fixed.contains(&d.key));
            if s.dims.is_empty() {
                bail!(
                    "{}: nothing to fit: the known parameters fix every key of the space",
                    s.source.display()
                );
            }
            Ok(s)
        }
        None => default_space(spec.prepared, spec.engine, spec.known),
    }
}

/// The objective in words.
fn objective_text(weights: &Option<Vec<f64>>, use_efforts: bool) -> String {
    match weights {
        Some(w) => format!(
            "joint angles (deg) and recorded efforts (N m, weighted {} deg per N m by joint, so that each counts like the angles' spread)",
            w.iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>().join(" / ")
        ),
        None if use_efforts => "joint angles (deg); the training episodes hold no usable efforts".into(),
        None => "joint angles (deg) (recorded efforts are fitted with --efforts)".into(),
    }
}

/// Prepares a recordings tune: the space (written to `OUT/space.toml`),
/// the episodes split, the engine's settings checked, the objective's
/// weights, and `OUT/tune.json` and `OUT/history.csv` (resumed when the
/// state matches).
pub fn recordings<'a>(
    spec: &'a RecordingsSpec<'a>,
    progress: &'a (dyn Fn(RecordingsProgress) + Sync),
) -> Result<Ready<'a>> {
    let prepared = spec.prepared;
    let engine = spec.engine;
    let space = space(spec)?;
    let (train, holdout) = split(&spec.selection, prepared.episodes.len())?;
    let mut files = vec![write::recordings_space(
        &spec.out, &space, prepared, engine,
    )?];
    let settings = spec
        .known
        .settings_over(engine.name(), &prepared.scene.settings_for(engine.name()));
    let dt = engine
        .check_settings(&settings)
        .map_err(|e| anyhow!("{e}"))?;
    let continuous: Vec<usize> = (0..space.dims.len()).collect();
    let delay = space.dims.iter().find(|d| d.key == DELAY_KEY).cloned();
    let joints = prepared.replayed_joints().len();
    let samples: usize = train
        .iter()
        .map(|&k| {
            prepared.episodes[k]
                .real
                .joint_angles_rad
                .as_ref()
                .map_or(0, |q| q.len() * joints)
        })
        .sum();
    let weights = if spec.use_efforts {
        let chosen: Vec<&Episode> = train.iter().map(|&k| &prepared.episodes[k]).collect();
        effort_weights(&chosen, joints)
    } else {
        None
    };
    let samples = samples * if weights.is_some() { 2 } else { 1 };
    let objective = objective_text(&weights, spec.use_efforts);
    // A rerun of the same tune (same engine, space, episodes, known
    // parameters, objective, scene) resumes from the best point of its
    // history; anything else starts afresh.
    let state = serde_json::json!({
        "engine": engine.name(),
        "space": serde_json::to_value(&space)?,
        "train": train,
        "holdout": holdout,
        "known": spec.known.to_toml_string(),
        "efforts": spec.use_efforts,
        "scene": format!("{:?}", prepared.scene.engine_settings),
        "samples": samples,
    });
    let (history, resumed) = history(&spec.out, &space, &state)?;
    files.push(spec.out.join("history.csv"));
    let problem = Problem {
        spec,
        continuous,
        delay,
        dt,
        train,
        holdout,
        evaluations: Mutex::new(0),
        best: Mutex::new(f64::INFINITY),
        history: Mutex::new(history),
        samples,
        effort_weights: weights,
        progress,
        phase: Mutex::new("start".into()),
        space,
        pool: least_squares::pool(spec.jobs),
    };
    Ok(Ready {
        problem,
        files,
        resumed,
        objective,
    })
}

/// `OUT/tune.json` written with `state`, and `OUT/history.csv` opened:
/// appended to, with the best point of its history, when the state
/// written before matches; else started afresh.
fn history(
    out: &Path,
    space: &Space,
    state: &serde_json::Value,
) -> Result<(std::fs::File, Option<Vec<f64>>)> {
    let history_path = out.join("history.csv");
    // One row per point of the fit: `evaluation` is the count of training
    // replays so far (the Jacobians' included).
    let mut header = String::from("evaluation,phase,train_rms_deg");
    for d in &space.dims {
        let _ = write!(header, ",{}", d.key);
    }
    let state_path = out.join("tune.json");
    let resumed = match std::fs::read_to_string(&state_path) {
        Ok(text)
            if serde_json::from_str::<serde_json::Value>(&text)
                .ok()
                .as_ref()
                == Some(state) =>
        {
            best_of_history(&history_path, &header, space.dims.len())
        }
        _ => None,
    };
    std::fs::write(&state_path, serde_json::to_string_pretty(state)? + "\n")
        .with_context(|| format!("writing {}", state_path.display()))?;
    let mut history = if resumed.is_some() {
        std::fs::OpenOptions::new()
            .append(true)
            .open(&history_path)
            .with_context(|| format!("appending to {}", history_path.display()))?
    } else {
        let mut f = std::fs::File::create(&history_path)
            .with_context(|| format!("writing {}", history_path.display()))?;
        writeln!(f, "{header}")?;
        f
    };
    if resumed.is_some() {
        writeln!(history, "# resumed from the best point above")?;
    }
    Ok((history, resumed))
}

/// The untuned start (every key at its start value) and its parameters;
/// an error, with the engine's own message, when it cannot replay the
/// training episodes.
pub(crate) fn untuned(p: &Problem) -> Result<(Vec<f64>, PhysicalParams)> {
    let u: Vec<f64> = p
        .continuous
        .iter()
        .map(|&i| p.space.dims[i].unit(p.space.dims[i].start))
        .collect();
    let start_params = p.params(&u).map_err(|m| anyhow!(m))?;
    // Fail early, with the engine's own message, when the start cannot run.
    p.residuals(&start_params)
        .map_err(|m| anyhow!("the untuned engine cannot replay the training episodes: {m}"))?;
    Ok((u, start_params))
}

/// The values of the best point of a tune's `history.csv` (written with
/// `header`), when it has one.
fn best_of_history(path: &Path, header: &str, dims: usize) -> Option<Vec<f64>> {
    let text = std::fs::read_to_string(path).ok()?;
    let mut lines = text.lines();
    if lines.next()? != header {
        return None;
    }
    lines
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            let rms: f64 = cells.get(2)?.parse().ok()?;
            let values: Vec<f64> = cells
                .get(3..)?
                .iter()
                .map(|c| c.parse::<f64>())
                .collect::<Result<_, _>>()
                .ok()?;
            (values.len() == dims && rms.is_finite() && !cells[1].contains("failed"))
                .then_some((rms, values))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|b| b.1)
}

/// Checks a study tune before its search: the space's start runs in the
/// engine, and `OUT/tune.json` matches this tune (written when new).
pub fn study(tuner: &Tuner<'_>) -> Result<()> {
    let spec = tuner.spec;
    let start = tuner
        .params(&spec.space.start_unit())
        .map_err(|m| anyhow!("{}: {m}", spec.space.source.display()))?;
    tuner
        .simulator
        .check(&tuner.target.scenes, &start)
        .with_context(|| format!("parameter space {}", spec.space.source.display()))?;
    realitygap_runner::interrupt::check()?;
    crate::check_resume(spec, tuner.target)
}
