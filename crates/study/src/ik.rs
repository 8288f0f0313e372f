//! `import qualisys --ik`: the real runs of a results directory in joint
//! space, by inverse kinematics of the tracked body's 6D capture
//! ([`realitygap_analysis::ik`]).
//!
//! The registration and the marker offset are fitted on the training runs
//! (by default the first three quarters by run id, as the study's runs
//! 1-15 of 20), then every frame of every run is solved with them. Each
//! run is stored again with its joint angles (the run CSV's `q<j>_rad`
//! columns) and its residual in its manifest entry (`extra.ik`); the fit
//! is in the manifest's settings (`ik`), with the robot's URDF, the joints
//! and the tracked link.
//!
//! The study's velocity commands are not reconstructed from the solved
//! angles: the controller's gain (10 per second) turns the angles' error
//! where the pose barely determines them (a few degrees at the upright
//! pose) into saturated commands. The study is compared in joint space
//! with the scenes run under their own controller (`compare
//! --joint-space`).

use anyhow::{anyhow, bail, Context, Result};
use realitygap_analysis::ik::{fit, solve_run, CaptureRun, IkFit, SKIP_FRAMES};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::WRIST;
use realitygap_data::{RunStatus, RunStore};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// The scene file a `--scene` value names: a file, else
/// `assets/scenes/<name>.toml`.
pub fn scene_file(name: &str) -> Result<PathBuf> {
    let p = PathBuf::from(name);
    if p.is_file() {
        return Ok(p);
    }
    let f = crate::data_source::assets_dir()
        .join("scenes")
        .join(format!("{name}.toml"));
    if f.is_file() {
        return Ok(f);
    }
    bail!(
        "--scene {name}: no such scene file, and no {} (give the scene's TOML file)",
        f.display()
    )
}

/// Which runs the registration is fitted on: `spec` (`all`, `N` for the
/// first N by run id, or `A-B` for the A-th to the B-th, 1-based) of
/// `ids` (sorted); default: the first three quarters (at least one).
pub fn training_runs(ids: &[String], spec: Option<&str>) -> Result<Vec<String>> {
    let n = ids.len();
    let (a, b) = match spec.map(str::trim) {
        None => (1, (n * 3 / 4).max(1)),
        Some("all") => (1, n),
        Some(s) => match s.split_once('-') {
            Some((a, b)) => (
                a.trim()
                    .parse::<usize>()
                    .map_err(|_| anyhow!("--ik-fit {s}: expected A-B, N or all"))?,
                b.trim()
                    .parse::<usize>()
                    .map_err(|_| anyhow!("--ik-fit {s}: expected A-B, N or all"))?,
            ),
            None => (
                1,
                s.parse::<usize>()
                    .map_err(|_| anyhow!("--ik-fit {s}: expected A-B, N or all"))?,
            ),
        },
    };
    if a == 0 || a > b || b > n {
        bail!("--ik-fit: runs {a} to {b} of {n} is not a range of the imported runs (1-based)");
    }
    Ok(ids[a - 1..b].to_vec())
}

/// What the inverse kinematics of one import found.
pub struct IkImport {
    /// The fit of registration and marker offset.
    pub fit: IkFit,
    /// The runs fitted on.
    pub training: Vec<String>,
    /// Per run: id, position and orientation residual RMS (mm, degrees).
    pub runs: Vec<(String, f64, f64)>,
}

/// Solves every finished run of the results directory `out` in joint
/// space (see the module documentation) with `robot`, for `scene`'s
/// controlled joints, the registration fitted on the runs `fit_spec`
/// names.
pub fn solve_import(
    out: &Path,
    scene: &Scene,
    robot: &RobotModel,
    fit_spec: Option<&str>,
) -> Result<IkImport> {
    let mut store = RunStore::open(out)?;
    let mut ids: Vec<String> = store
        .runs()
        .iter()
        .filter(|r| r.status == RunStatus::Ok)
        .map(|r| r.id.clone())
        .collect();
    ids.sort();
    if ids.is_empty() {
        bail!("{}: no imported run to solve", out.display());
    }
    let training = training_runs(&ids, fit_spec)?;
    let mut trajectories = Vec::with_capacity(ids.len());
    for id in &ids {
        let t = store.read_run(id)?;
        if !t.bodies.iter().any(|b| b.role == WRIST) {
            bail!(
                "{}: run '{id}' has no '{WRIST}' body (give the marker body's role with --role NAME=wrist)",
                out.display()
            );
        }
        trajectories.push(t);
    }
    let capture: Vec<CaptureRun> = ids
        .iter()
        .zip(&trajectories)
        .filter(|(id, _)| training.contains(id))
        .map(|(_, t)| CaptureRun {
            trajectory: t,
            role: WRIST,
        })
        .collect();
    let fitted = fit(scene, robot, &capture, 20)
        .map_err(|e| anyhow!("{}: the registration fit: {e}", out.display()))?;
    let mut runs = Vec::new();
    for (id, t) in ids.iter().zip(trajectories) {
        let solved = solve_run(
            scene,
            robot,
            &fitted,
            &CaptureRun {
                trajectory: &t,
                role: WRIST,
            },
        )
        .map_err(|e| anyhow!("{}: run '{id}': {e}", out.display()))?;
        let (p, a) = (solved.position_rms_mm(), solved.angle_rms_deg());
        let mut entry = store
            .run(id)
            .cloned()
            .ok_or_else(|| anyhow!("run '{id}' vanished from {}", out.display()))?;
        entry.extra.insert(
            "ik".into(),
            json!({
                "position_rms_mm": p,
                "angle_rms_deg": a,
                "start_frame": solved.start_frame,
                "skipped_frames": SKIP_FRAMES,
                "training": training.contains(id),
            }),
        );
        let mut t = t;
        t.joint_angles_rad = Some(solved.angles_rad);
        store
            .write_run(entry, &t)
            .with_context(|| format!("storing run '{id}' with its joint angles"))?;
        runs.push((id.clone(), p, a));
    }
    let mut settings = store.manifest().settings.clone();
    if let Value::Object(map) = &mut settings {
        // What `replay` and `tune --recordings` read of an import.
        if robot.source.is_file() {
            let urdf = std::fs::canonicalize(&robot.source).unwrap_or(robot.source.clone());
            map.insert("urdf".into(), json!(urdf.display().to_string()));
        }
        map.insert("joints".into(), json!(scene.controlled_joints()));
        if let Some(link) = scene
            .tracked
            .iter()
            .find(|t| t.role == WRIST)
            .and_then(|t| match &t.target {
                realitygap_core::scene::TrackTarget::Link(l) => Some(l.clone()),
                realitygap_core::scene::TrackTarget::Object(_) => None,
            })
        {
            map.insert("end_effector_link".into(), json!(link));
        }
        map.insert(
            "ik".into(),
            json!({
                "robot": robot.name,
                "urdf": robot.source.display().to_string(),
                "joints": scene.controlled_joints(),
                "training_runs": training,
                "registration": {
                    "yaw_deg": fitted.registration.yaw_rad.to_degrees(),
                    "translation_m": fitted.registration.translation_m.to_array(),
                    "meaning": "world = Rz(yaw) capture + translation",
                },
                "marker_in_link": {
                    "position_m": fitted.marker_in_link.position_m.to_array(),
                    "orientation_wxyz": [
                        fitted.marker_in_link.orientation.w,
                        fitted.marker_in_link.orientation.x,
                        fitted.marker_in_link.orientation.y,
                        fitted.marker_in_link.orientation.z,
                    ],
                },
                "fit_position_rms_mm": fitted.fit_position_rms_mm,
                "fit_angle_rms_deg": fitted.fit_angle_rms_deg,
                "fit_frames": fitted.frames,
            }),
        );
    }
    store.set_settings(settings)?;
    Ok(IkImport {
        fit: fitted,
        training,
        runs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_runs_are_chosen_by_range() {
        let ids: Vec<String> = (1..=20).map(|i| format!("r{i:02}")).collect();
        assert_eq!(training_runs(&ids, None).unwrap().len(), 15);
        assert_eq!(training_runs(&ids, Some("all")).unwrap().len(), 20);
        assert_eq!(training_runs(&ids, Some("3")).unwrap(), ids[..3].to_vec());
        assert_eq!(
            training_runs(&ids, Some("16-20")).unwrap(),
            ids[15..].to_vec()
        );
        assert!(training_runs(&ids, Some("0-3")).is_err());
        assert!(training_runs(&ids, Some("5-21")).is_err());
        assert!(training_runs(&ids, Some("x")).is_err());
        assert_eq!(training_runs(&ids[..1], None).unwrap().len(), 1);
    }
}
