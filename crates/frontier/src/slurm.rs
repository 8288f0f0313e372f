//! The sweep on Slurm (`frontier --executor slurm`): each stage of the
//! sweep (the reference's finest setting, each halving of its timestep,
//! then every point x scene x repeat) is one job array, submitted through
//! the runner's machinery (`realitygap_runner::slurm::run_array`) into
//! `OUT/.slurm/<stage>/`.
//!
//! Every array task runs its simulations with `realitygap __run-one`, the
//! run's own child process, which times the control loop on its thread's
//! CPU clock as the local sweep does and returns the time with the
//! trajectory. The coordinator folds the repeats exactly as the local sweep
//! does (the minimum CPU time, the first run's trajectory and status, the
//! first failure fails the scene), so the deviations, statuses and gaps are
//! the local ones; only the timings differ (other machines, other loads).
//! A setting the engine refuses is found here before anything is submitted,
//! as locally.

use crate::{
    failed, fold_attempts, not_run, point_of, set_args, settings_for, Attempt, Overlay, Point,
    SceneCase,
};
use anyhow::{anyhow, Context, Result};
use realitygap_core::controller::{RunOutcome, RunStatus};
use realitygap_core::engine::Engine;
use realitygap_runner::slurm::{run_array, SlurmOptions};
use realitygap_runner::{ChildEnd, ChildResult, Job, Launcher};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A simulation of a stage: (point, scene, repeat).
type Key = (usize, usize, u32);

/// What the Slurm stages of one sweep share.
pub(crate) struct SlurmSweep<'a> {
    options: &'a SlurmOptions,
    launcher: &'a Launcher,
    /// `OUT/.slurm`: one folder per stage.
    dir: PathBuf,
    /// The scene files, absolute (the tasks may start elsewhere).
    scene_files: Vec<PathBuf>,
    say: &'a dyn Fn(String),
}

impl<'a> SlurmSweep<'a> {
    /// The Slurm stages of a sweep writing into `out`.
    pub(crate) fn new(
        options: &'a SlurmOptions,
        launcher: &'a Launcher,
        out: &Path,
        scenes: &[PathBuf],
        say: &'a dyn Fn(String),
    ) -> Result<SlurmSweep<'a>> {
        let scene_files = scenes
            .iter()
            .map(|s| std::path::absolute(s).with_context(|| format!("scene {}", s.display())))
            .collect::<Result<_>>()?;
        Ok(SlurmSweep {
            options,
            launcher,
            dir: out.join(".slurm"),
            scene_files,
            say,
        })
    }

    /// Measures every point of `overlays` in every scene, `repeats` times,
    /// as one job array named `stage`; the points in order, not yet scored.
    pub(crate) fn measure(
        &self,
        stage: &str,
        cases: &[SceneCase],
        engine: &dyn Engine,
        overlays: &[Overlay],
        repeats: u32,
    ) -> Result<Vec<Point>> {
        let mut jobs: Vec<(Key, Job)> = Vec::new();
        for (pi, overlay) in overlays.iter().enumerate() {
            for (si, case) in cases.iter().enumerate() {
                if settings_for(case, engine, overlay).is_ok() {
                    let job = self.job(engine.name(), si, overlay);
                    jobs.extend((0..repeats).map(|r| ((pi, si, r), job.clone())));
                }
            }
        }
        let mut ends = self.run(stage, jobs)?;
        let mut take = |key: Key| -> Attempt {
            attempt(
                ends.remove(&key)
                    .ok_or_else(|| "the Slurm array returned nothing for it".to_string())?,
            )
        };
        Ok(overlays
            .iter()
            .enumerate()
            .map(|(pi, overlay)| {
                let scenes = cases
                    .iter()
                    .enumerate()
                    .map(|(si, case)| match settings_for(case, engine, overlay) {
                        Ok(_) => fold_attempts(case, (0..repeats).map(|r| take((pi, si, r)))),
                        Err(e) => failed(not_run(case), e.to_string()),
                    })
                    .collect();
                point_of(engine, overlay, scenes)
            })
            .collect())
    }

    /// The job of scene `si` at `overlay`: the scene's settings with the
    /// overlay as `--set`, no parameters, no perturbation; settings the
    /// engine knows to be unstable are run, as the local sweep runs them.
    fn job(&self, engine: &str, si: usize, overlay: &Overlay) -> Job {
        Job {
            scene_file: self.scene_files[si].clone(),
            engine: engine.to_string(),
            robot: None,
            packages: vec![],
            set: set_args(engine, overlay),
            perturb: vec![],
            seed: 0,
            params: None,
            params_text: None,
            check_only: false,
            stitch: None,
            allow_unstable: true,
            replay: None,
        }
    }

    /// Runs `jobs` as one array in a fresh `OUT/.slurm/<stage>/`, saying
    /// how far it is; every job's end.
    fn run(&self, stage: &str, jobs: Vec<(Key, Job)>) -> Result<BTreeMap<Key, ChildEnd>> {
        let mut ends = BTreeMap::new();
        if jobs.is_empty() {
            return Ok(ends);
        }
        let dir = self.dir.join(stage);
        // A folder of an earlier sweep holds its results: they are not this
        // sweep's (other settings, other timings).
        match std::fs::remove_dir_all(&dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(anyhow!("cannot clear {}: {e}", dir.display()))
            }
            _ => {}
        }
        let total = jobs.len();
        (self.say)(format!(
            "  slurm: {stage}: {total} simulation(s) as one job array in {}",
            dir.display()
        ));
        let started = std::time::Instant::now();
        let mut shown = 0;
        run_array(
            jobs,
            &dir,
            self.launcher,
            self.options,
            &mut |key, end, _| {
                ends.insert(key, end);
                // About ten progress lines per array.
                let tenth = ends.len() * 10 / total;
                if tenth > shown {
                    shown = tenth;
                    (self.say)(format!(
                        "  slurm: {stage}: {}/{total} done after {:.1} s",
                        ends.len(),
                        started.elapsed().as_secs_f64()
                    ));
                }
                Ok(())
            },
        )
        .with_context(|| format!("frontier: the Slurm array of {stage}"))?;
        Ok(ends)
    }
}

/// A worker's end as the local sweep sees a run: the outcome and its CPU
/// time (wall time where the worker had no thread clock), or the failure.
fn attempt(end: ChildEnd) -> Attempt {
    let r: Box<ChildResult> = match end {
        ChildEnd::Done(r) => r,
        ChildEnd::Failed(message) => return Err(message),
    };
    let trajectory = r
        .trajectory()
        .map_err(|e| format!("the worker's result is not a run: {e:#}"))?;
    let status = match &r.diverged {
        None => RunStatus::Completed,
        Some((t_s, reason)) => RunStatus::Diverged {
            t_s: *t_s,
            reason: reason.clone(),
        },
    };
    let cpu_s = r.cpu_s.unwrap_or(r.wall_time_s);
    Ok((
        RunOutcome {
            trajectory,
            status,
            engine_steps: r.engine_steps,
            wall_time_s: r.wall_time_s,
        },
        cpu_s,
    ))
}
