//! A batch of runs (`realitygap run`, the first stage of `reproduce`):
//! planned, checked, executed with a progress bar and summed up. The work
//! is the runner's ([`realitygap_runner::Plan`]); this is the sequence the
//! command and the Python package share.

use crate::ui::Ui;
use anyhow::Result;
use realitygap_runner::prepare::resolver;
use realitygap_runner::slurm::Executor;
use realitygap_runner::{BatchSpec, BatchStats, Launcher, Plan};
use std::time::Instant;

/// A batch that ran: its plan (one group per results directory), counts
/// and wall time.
pub struct BatchOutcome {
    /// The plan, its groups' counts filled in.
    pub plan: Plan,
    /// The batch's counts.
    pub stats: BatchStats,
    /// Runs in the batch (kept ones included).
    pub total: usize,
    /// Wall time, seconds.
    pub wall_s: f64,
}

/// `--robot official` with no kinova_description package given or on
/// ROS_PACKAGE_PATH: adds the one of the study data built in. When that
/// cannot be had either, says why and leaves the batch as it is (loading
/// the robot then fails naming where it looked).
pub fn with_builtin_kinova(mut spec: BatchSpec, ui: &dyn Ui) -> Result<BatchSpec> {
    if spec.robot.as_deref() != Some("official")
        || resolver(&spec.packages)?.find("kinova_description").is_ok()
    {
        return Ok(spec);
    }
    match realitygap_study::data_source::builtin_data_dir() {
        Ok(dir) => spec.packages.push(format!(
            "kinova_description={}",
            dir.join("kinova_description").display()
        )),
        Err(e) => ui.note(format!(
            "warning: the built-in kinova_description cannot be used: {e:#}"
        )),
    }
    Ok(spec)
}

/// Plans `spec` with the engines compiled in, loads each model once, runs
/// the pending repeats with `launcher`'s child processes under a bar, and
/// records the batch in the manifests. An interruption
/// ([`realitygap_runner::interrupt`]) ends it with the finished runs kept.
pub fn run(
    spec: BatchSpec,
    executor: Executor,
    launcher: &Launcher,
    ui: &dyn Ui,
) -> Result<BatchOutcome> {
    let start = Instant::now();
    let spec = with_builtin_kinova(spec, ui)?;
    let mut plan = Plan::new(crate::engines, spec)?;
    plan.executor = executor;
    plan.check_loads(launcher);
    realitygap_runner::interrupt::check()?;
    let total = plan.total();
    let bar = ui.bar(total as u64, "runs");
    let skipped = plan.skipped();
    if skipped > 0 {
        bar.println(format!(
            "{skipped} finished runs kept from an earlier batch"
        ));
    }
    let stats = plan.execute(launcher, &*bar);
    bar.finish();
    let stats = stats?;
    let wall_s = start.elapsed().as_secs_f64();
    plan.record_batch(&stats, wall_s)?;
    Ok(BatchOutcome {
        plan,
        stats,
        total,
        wall_s,
    })
}

/// [`run`], then the summary's lines said and its error returned.
pub fn run_and_report(
    spec: BatchSpec,
    executor: Executor,
    launcher: &Launcher,
    ui: &dyn Ui,
) -> Result<BatchOutcome> {
    let outcome = run(spec, executor, launcher, ui)?;
    for line in outcome.summary() {
        ui.say(line);
    }
    outcome.check()?;
    Ok(outcome)
}

impl BatchOutcome {
    /// One line per results directory and one for the batch.
    pub fn summary(&self) -> Vec<String> {
        let plan = &self.plan;
        let mut lines = Vec::new();
        for g in &plan.groups {
            let dir = g.store.dir().display().to_string();
            match &g.load_error {
                Some(e) => lines.push(format!("{}/{}: not run: {e}", g.scene_name, g.source)),
                None => lines.push(format!(
                    "{}/{}: {} ok, {} diverged{}, {} failed, {} kept -> {dir}",
                    g.scene_name,
                    g.source,
                    g.done.ok,
                    g.done.diverged,
                    match g.done.unstable {
                        0 => String::new(),
                        n => format!(", {n} unstable"),
                    },
                    g.done.failed,
                    plan.kept(g)
                )),
            }
        }
        let stats = &self.stats;
        if stats.steps_total > 0 {
            lines.push(format!(
                "{} runs ({} simulated, {} copies of identical deterministic runs) in {:.1} s with {} jobs ({:.0} engine steps/s per run)",
                self.total,
                stats.simulated,
                self.total - stats.simulated,
                self.wall_s,
                plan.jobs,
                stats.steps_per_second()
            ));
        }
        lines
    }

    /// The short form of [`BatchOutcome::summary`]: only the results
    /// directories with a diverged, unstable or failed run or a model that
    /// did not load, then one line of totals.
    pub fn short_summary(&self) -> Vec<String> {
        let plan = &self.plan;
        let mut lines = Vec::new();
        let (mut ok, mut diverged, mut unstable, mut failed, mut kept) = (0, 0, 0, 0, 0);
        for g in &plan.groups {
            ok += g.done.ok;
            diverged += g.done.diverged;
            unstable += g.done.unstable;
            failed += g.done.failed;
            kept += plan.kept(g);
            match &g.load_error {
                Some(e) => lines.push(format!("{}/{}: not run: {e}", g.scene_name, g.source)),
                None if g.done.diverged + g.done.unstable + g.done.failed > 0 => {
                    lines.push(format!(
                        "{}/{}: {} ok, {} diverged, {} unstable, {} failed -> {}",
                        g.scene_name,
                        g.source,
                        g.done.ok,
                        g.done.diverged,
                        g.done.unstable,
                        g.done.failed,
                        g.store.dir().display()
                    ))
                }
                None => {}
            }
        }
        lines.push(format!(
            "{} runs: {ok} ok, {diverged} diverged, {unstable} unstable, {failed} failed, {kept} kept from an earlier batch ({} simulated in {:.1} s with {} jobs)",
            self.total, self.stats.simulated, self.wall_s, plan.jobs
        ));
        lines
    }

    /// An error when a model did not load or a run failed.
    pub fn check(&self) -> Result<()> {
        let load_failures: Vec<String> = self
            .plan
            .groups
            .iter()
            .filter(|g| g.load_error.is_some())
            .map(|g| format!("{}/{}", g.scene_name, g.source))
            .collect();
        if !load_failures.is_empty() {
            anyhow::bail!("the engine could not load {}", load_failures.join(", "));
        }
        if self.stats.failures > 0 {
            let first = self
                .first_failure()
                .map(|m| format!("; the first: {m}"))
                .unwrap_or_default();
            anyhow::bail!("{} of {} runs failed (their messages are in the manifests{first}); rerun the same command to retry them", self.stats.failures, self.total);
        }
        Ok(())
    }

    /// The message of the first failed run of the batch's results
    /// directories, for the final error (the progress bar's lines are not
    /// shown when standard error is not a terminal).
    fn first_failure(&self) -> Option<String> {
        self.plan
            .groups
            .iter()
            .flat_map(|g| g.store.runs())
            .find(|r| r.status == realitygap_data::runstore::RunStatus::Failed)
            .and_then(|r| r.message.clone())
    }
}
