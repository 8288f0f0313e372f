//! The study in joint space (`compare --joint-space`): every source's
//! joint angles against the real arm's, found by inverse kinematics of its
//! wrist capture ([`realitygap_analysis::ik`]).
//!
//! Per scene: the capture registration and the wrist marker's offset are
//! fitted on the fit runs (the study's `runs`, or `--runs`), every real run
//! is solved frame by frame, and each run is aligned to the scene's time 0
//! as the IK's prior was (the motion onset matched to the commanded
//! motion). The real arm's mean joint trajectory over the scored runs (the
//! held-out ones when there are) is then compared, control step by control
//! step, with each source's mean over its runs that completed (sources
//! without joint angles, such as the study's recorded simulators, are left
//! out) and with the physics-free model (the commanded angles with perfect
//! tracking). A row gives the RMS angle error per joint and over all
//! joints, degrees.

use crate::load::LoadedScene;
use anyhow::{anyhow, Result};
use realitygap_analysis::ik::{fit, solve_run, CaptureRun};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::WRIST;
use serde::Serialize;
use std::fmt::Write as _;

/// Name of the physics-free model's row.
pub const KINEMATIC_ROW: &str = "physics-free (perfect tracking)";

/// One source's joint-space errors in one scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointRow {
    /// The source.
    pub source: String,
    /// Runs averaged.
    pub runs: usize,
    /// RMS over all joints and steps, degrees.
    pub rms_all_deg: f64,
    /// RMS per joint, degrees.
    pub rms_deg: Vec<f64>,
}

/// One scene's joint-space table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointTable {
    /// The scene's name.
    pub scene: String,
    /// The controlled joints, in order.
    pub joints: Vec<String>,
    /// Real runs scored (their ids).
    pub scored_runs: Vec<String>,
    /// Real runs the registration was fitted on.
    pub fit_runs: Vec<String>,
    /// The IK's residual over the scored runs: position (mm) and
    /// orientation (degrees) RMS.
    pub ik_residual: (f64, f64),
    /// The IK's residual over the fit runs.
    pub ik_fit_residual: (f64, f64),
    /// The rows: the physics-free model first, then the sources.
    pub rows: Vec<JointRow>,
}

/// The joint-space table of one loaded scene (its spec's kinematic
/// reference must exist), with `scene`/`robot` the scene's kinematics, the
/// registration fitted on the real runs `fit` (indices into the
/// reference's runs) and the real arm scored on `score`.
pub fn joint_table(
    loaded: &LoadedScene,
    scene: &Scene,
    robot: &RobotModel,
    fit_runs: &[usize],
    score_runs: &[usize],
) -> Result<JointTable> {
    let name = loaded.spec.name.clone();
    let real = &loaded.reference.runs;
    let capture = |i: usize| CaptureRun {
        trajectory: &real[i].trajectory,
        role: WRIST,
    };
    let fitting: Vec<CaptureRun> = fit_runs.iter().map(|&i| capture(i)).collect();
    let fitted =
        fit(scene, robot, &fitting, 20).map_err(|e| anyhow!("scene '{name}': the IK fit: {e}"))?;
    let steps = loaded.spec.steps;
    let stride = (loaded.reference.rate_hz * loaded.spec.control_period_s)
        .round()
        .max(1.0) as usize;
    let dof = scene.actuators.len();
    let mut sum = vec![vec![0.0; dof]; steps];
    let mut count = vec![0usize; steps];
    let (mut sp, mut sa, mut n) = (0.0f64, 0.0f64, 0.0f64);
    let (mut fp, mut fa, mut fn_) = (0.0f64, 0.0f64, 0.0f64);
    for &i in fit_runs.iter().chain(score_runs) {
        let solved = solve_run(scene, robot, &fitted, &capture(i))
            .map_err(|e| anyhow!("scene '{name}': run '{}': {e}", real[i].id))?;
        let (p, a) = (solved.position_rms_mm(), solved.angle_rms_deg());
        if score_runs.contains(&i) {
            sp += p * p;
            sa += a * a;
            n += 1.0;
            for (k, (row, c)) in sum.iter_mut().zip(count.iter_mut()).enumerate() {
                if let Some(q) = solved.angles_rad.get(solved.start_frame + k * stride) {
                    for (s, v) in row.iter_mut().zip(q) {
                        *s += v;
                    }
                    *c += 1;
                }
            }
        }
        if fit_runs.contains(&i) {
            fp += p * p;
            fa += a * a;
            fn_ += 1.0;
        }
    }
    let real_mean: Vec<Option<Vec<f64>>> = sum
        .into_iter()
        .zip(&count)
        .map(|(row, &c)| (c > 0).then(|| row.into_iter().map(|v| v / c as f64).collect()))
        .collect();
    let mut rows = Vec::new();
    if let Some(k) = &loaded.spec.kinematic {
        rows.extend(row_of(KINEMATIC_ROW, 1, &k.angles_rad, &real_mean, dof));
    }
    for source in &loaded.sources {
        let runs: Vec<&Vec<Vec<f64>>> = source
            .runs
            .iter()
            .filter(|r| r.failed.is_none())
            .filter_map(|r| r.trajectory.joint_angles_rad.as_ref())
            .filter(|a| a.first().is_some_and(|q| q.len() == dof))
            .collect();
        if runs.is_empty() {
            continue;
        }
        let mean: Vec<Vec<f64>> = (0..steps)
            .map(|k| {
                let mut m = vec![0.0; dof];
                let mut c = 0;
                for r in &runs {
                    if let Some(q) = r.get(k) {
                        for (s, v) in m.iter_mut().zip(q) {
                            *s += v;
                        }
                        c += 1;
                    }
                }
                m.iter().map(|v| v / c.max(1) as f64).collect()
            })
            .collect();
        // A source that is the physics-free model itself (its angles are
        // the kinematic reference's) is the kinematic row: shown once.
        let kinematic = loaded.spec.kinematic.as_ref().is_some_and(|k| {
            k.angles_rad.len() >= steps
                && mean.iter().zip(&k.angles_rad).all(|(m, q)| {
                    m.len() == q.len() && m.iter().zip(q).all(|(a, b)| (a - b).abs() < 1e-9)
                })
        });
        if !kinematic {
            rows.extend(row_of(&source.name, runs.len(), &mean, &real_mean, dof));
        }
    }
    let id = |i: &usize| real[*i].id.clone();
    Ok(JointTable {
        scene: name,
        joints: scene
            .controlled_joints()
            .iter()
            .map(|s| s.to_string())
            .collect(),
        scored_runs: score_runs.iter().map(id).collect(),
        fit_runs: fit_runs.iter().map(id).collect(),
        ik_residual: ((sp / n.max(1.0)).sqrt(), (sa / n.max(1.0)).sqrt()),
        ik_fit_residual: ((fp / fn_.max(1.0)).sqrt(), (fa / fn_.max(1.0)).sqrt()),
        rows,
    })
}

/// The row of a source's mean angles (per step) against the real mean.
fn row_of(
    source: &str,
    runs: usize,
    mean: &[Vec<f64>],
    real: &[Option<Vec<f64>>],
    dof: usize,
) -> Option<JointRow> {
    let mut sq = vec![0.0; dof];
    let mut n = 0usize;
    for (m, r) in mean.iter().zip(real) {
        let Some(r) = r else { continue };
        for (j, s) in sq.iter_mut().enumerate() {
            *s += (m[j] - r[j]).to_degrees().powi(2);
        }
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let rms_deg: Vec<f64> = sq.iter().map(|s| (s / n as f64).sqrt()).collect();
    let all = (sq.iter().sum::<f64>() / (n * dof) as f64).sqrt();
    Some(JointRow {
        source: source.to_string(),
        runs,
        rms_all_deg: all,
        rms_deg,
    })
}

/// The tables as Markdown: one table per scene, joints as columns.
pub fn markdown(tables: &[JointTable]) -> String {
    let mut s = String::from("## Joint space (inverse kinematics of the real wrist)\n");
    for t in tables {
        let _ = writeln!(
            s,
            "\n### {}\n\nReal arm: {} scored runs; IK residual {:.2} mm, {:.2} deg RMS (fit runs: {:.2} mm, {:.2} deg). RMS joint-angle error of each source's mean against the real mean, degrees.\n",
            t.scene, t.scored_runs.len(), t.ik_residual.0, t.ik_residual.1, t.ik_fit_residual.0, t.ik_fit_residual.1
        );
        let _ = write!(s, "| source | runs | all joints |");
        for j in &t.joints {
            let _ = write!(s, " {j} |");
        }
        s.push_str("\n|---|---:|---:|");
        for _ in &t.joints {
            s.push_str("---:|");
        }
        s.push('\n');
        for r in &t.rows {
            let _ = write!(s, "| {} | {} | {:.2} |", r.source, r.runs, r.rms_all_deg);
            for v in &r.rms_deg {
                let _ = write!(s, " {v:.2} |");
            }
            s.push('\n');
        }
    }
    s
}

/// The joint-space tables of every scene of `study` that names its scene
/// file (`scene = ...`), with the runs `measure` selects (the study's
/// `runs`/`holdout` by default): the registration fitted on the fit runs,
/// the real arm scored on the scored runs.
pub fn study_tables(
    study: &crate::study::Study,
    roots: &crate::load::Roots,
    measure: &crate::measure::Measure,
) -> Result<Vec<JointTable>> {
    use anyhow::Context;
    let opts = measure.options(study)?;
    let loaded = study.load(roots)?;
    let most = loaded.iter().map(|l| l.reference.runs.len()).max();
    opts.runs
        .check_count(most.unwrap_or(0), "runs")
        .map_err(|e| anyhow!("{e}"))?;
    let mut tables = Vec::new();
    for (s, l) in study.scenes.iter().zip(&loaded) {
        let Some(file) = &s.scene else { continue };
        let path = study.folder.join(file);
        let scene = Scene::from_file(&path)?;
        let robot = scene
            .robot
            .model(&realitygap_core::robot::PackageResolver::from_env())
            .with_context(|| format!("robot of scene file {}", path.display()))?;
        let selected = opts
            .runs
            .select(&s.name, l.reference.runs.len())
            .map_err(|e| anyhow!("{e}"))?;
        tables.push(joint_table(
            l,
            &scene,
            &robot,
            &selected.fit,
            &selected.score,
        )?);
    }
    Ok(tables)
}
