//! The scores of a tune: the untuned and the tuned engine and the
//! physics-free model on the training and the held-out episodes or runs.
//! The study tune's are computed by [`crate::outputs::finish`]; the
//! recordings tune's here (`recordings`), with the tuned parameters
//! replayed again at half the engine's timestep (`timestep_check`).

use crate::recordings::{set_score, verdict, Problem, RecordingsTimestepCheck, SourceScores};
use anyhow::{anyhow, Result};
use realitygap_core::params::PhysicalParams;
use realitygap_core::Trajectory;
use realitygap_study::replay::kinematic_run;

/// The recordings tune's scores.
pub struct Scored {
    /// The tuned parameters.
    pub tuned: PhysicalParams,
    /// The engine untuned and tuned, the physics-free model (undelayed,
    /// and with the fitted delay).
    pub scores: Vec<SourceScores>,
    /// The answer in words.
    pub verdict: String,
    /// The tuned parameters at half the timestep.
    pub timestep_check: RecordingsTimestepCheck,
}

/// Scores the untuned parameters `start_params` and the tuned point `u`,
/// and the physics-free model, on the training and the held-out episodes.
pub(crate) fn recordings(p: &Problem, u: &[f64], start_params: &PhysicalParams) -> Result<Scored> {
    p.set_phase("scoring".into());
    let prepared = p.spec.prepared;
    let tuned = p.params(u).map_err(|m| anyhow!(m))?;
    let delay_s = tuned.controller.delay_s.filter(|_| p.delay.is_some());
    let all: Vec<usize> = p.train.iter().chain(&p.holdout).copied().collect();
    let score_engine = |params: &PhysicalParams| -> Vec<(usize, Trajectory)> {
        all.iter()
            .filter_map(|&k| p.replay(&prepared.episodes[k], params).ok().map(|t| (k, t)))
            .collect()
    };
    let link = prepared
        .robot
        .link_by_name(&prepared.link)
        .ok_or_else(|| anyhow!("the robot has no link {}", prepared.link))?;
    let kin = |delay: f64| -> Vec<(usize, Trajectory)> {
        all.iter()
            .filter_map(|&k| {
                kinematic_run(&prepared.episodes[k], prepared, link, delay).map(|t| (k, t))
            })
            .collect()
    };
    let name = p.spec.engine.name();
    let mut scores = vec![
        sets(p, score_engine(start_params), format!("{name} untuned")),
        sets(p, score_engine(&tuned), format!("{name} tuned")),
        sets(p, kin(0.0), "physics-free (perfect tracking)".into()),
    ];
    if let Some(d) = delay_s.filter(|d| *d > 0.0) {
        scores.push(sets(
            p,
            kin(d),
            format!("physics-free, delayed {:.0} ms", d * 1e3),
        ));
    }
    let verdict = verdict(&scores);
    let timestep_check = timestep_check(p, &tuned, &scores[1]);
    Ok(Scored {
        tuned,
        scores,
        verdict,
        timestep_check,
    })
}

/// `runs` scored as `source` on the training and the held-out episodes.
fn sets(p: &Problem, runs: Vec<(usize, Trajectory)>, source: String) -> SourceScores {
    let pick = |which: &[usize]| {
        let chosen: Vec<(usize, Trajectory)> = runs
            .iter()
            .filter(|(k, _)| which.contains(k))
            .cloned()
            .collect();
        set_score(p.spec.prepared, &chosen)
    };
    SourceScores {
        source,
        train: pick(&p.train),
        holdout: if p.holdout.is_empty() {
            None
        } else {
            pick(&p.holdout)
        },
    }
}

/// The `tuned` parameters replayed at half the engine's timestep on the
/// held-out episodes (else the training ones), against the tuned engine's
/// scores at its own step (`at_step`).
fn timestep_check(
    p: &Problem,
    tuned: &PhysicalParams,
    at_step: &SourceScores,
) -> RecordingsTimestepCheck {
    let prepared = p.spec.prepared;
    let mut half = tuned.clone();
    half.engine_settings
        .entry(p.spec.engine.name().to_string())
        .or_default()
        .insert(
            realitygap_core::engine::TIMESTEP_KEY.to_string(),
            realitygap_core::engine::SettingValue::Float(p.dt / 2.0),
        );
    let on_holdout = !p.holdout.is_empty();
    let which = if on_holdout { &p.holdout } else { &p.train };
    let mut failed = Vec::new();
    let runs: Vec<(usize, Trajectory)> = which
        .iter()
        .filter_map(|&k| match p.replay(&prepared.episodes[k], &half) {
            Ok(t) => Some((k, t)),
            Err(m) => {
                failed.push(format!("{}: {m}", prepared.episodes[k].id));
                None
            }
        })
        .collect();
    let halved = if failed.is_empty() {
        set_score(prepared, &runs)
    } else {
        None
    };
    let tuned_score = if on_holdout {
        at_step.holdout.clone()
    } else {
        at_step.train.clone()
    };
    let holds = match (&tuned_score, &halved) {
        (Some(t), Some(h)) => t
            .interval_deg
            .map(|(lo, hi)| h.rms_deg >= lo && h.rms_deg <= hi),
        _ => Some(false).filter(|_| !failed.is_empty()),
    };
    RecordingsTimestepCheck {
        timestep_s: p.dt,
        halved_s: p.dt / 2.0,
        episodes: if on_holdout { "held-out" } else { "training" }.into(),
        tuned: tuned_score,
        halved,
        holds,
        failed,
    }
}
