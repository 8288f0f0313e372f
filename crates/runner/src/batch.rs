//! Running a planned batch: the local process pool, storing each run as it
//! finishes, and the copies of identical deterministic runs.

use crate::child::{run_child, ChildEnd, Launcher};
use crate::plan::{run_id, Group, Plan};
use crate::protocol::{ChildResult, Job};
use crate::slurm::{run_array, Executor};
use anyhow::{Context, Result};
use realitygap_core::controller::repeat_seed;
use realitygap_core::trajectory::Trajectory;
use realitygap_data::runstore::{RunEntry, RunStatus, RunStore};
use std::collections::VecDeque;
use std::sync::{mpsc, Mutex};
use std::time::Instant;

/// Where a batch reports its progress (a progress bar, or nothing).
pub trait Progress {
    /// A line for the user (above the bar).
    fn println(&self, line: String);
    /// `n` more runs are done.
    fn inc(&self, n: u64);
    /// The bar's message (the failures so far).
    fn set_message(&self, message: String);
}

/// No progress shown.
impl Progress for () {
    fn println(&self, _: String) {}
    fn inc(&self, _: u64) {}
    fn set_message(&self, _: String) {}
}

/// Counts of one batch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BatchStats {
    /// Runs that failed.
    pub failures: usize,
    /// Engine steps of the simulated runs.
    pub steps_total: u64,
    /// Wall time of their control loops, seconds.
    pub loop_time_total: f64,
    /// Runs simulated (the others were copies).
    pub simulated: usize,
}

impl BatchStats {
    /// Engine steps per second of control-loop time (0 when none ran).
    pub fn steps_per_second(&self) -> f64 {
        if self.loop_time_total > 0.0 {
            self.steps_total as f64 / self.loop_time_total
        } else {
            0.0
        }
    }
}

/// The runs of one batch being executed.
struct Batch<'a> {
    plan: &'a mut Plan,
    launcher: &'a Launcher,
    progress: &'a dyn Progress,
    stats: BatchStats,
}

/// Runs as (group index, repeat).
pub type Runs = Vec<(usize, u32)>;

/// Repeats of groups (by index) decided later.
pub type Deferred = Vec<(usize, Vec<u32>)>;

/// For a deterministic batch, the first two pending repeats of each group
/// (simulated now) and the rest (decided after them: copied when the two
/// are identical, else simulated); otherwise every pending repeat now.
pub fn split_for_copies(groups: &[Group], deterministic: bool) -> (Runs, Deferred) {
    let mut first = Vec::new();
    let mut deferred = Vec::new();
    for (i, g) in groups
        .iter()
        .enumerate()
        .filter(|(_, g)| g.load_error.is_none())
    {
        let now = if deterministic {
            g.pending.len().min(2)
        } else {
            g.pending.len()
        };
        first.extend(g.pending[..now].iter().map(|&r| (i, r)));
        if now < g.pending.len() {
            deferred.push((i, g.pending[now..].to_vec()));
        }
    }
    (first, deferred)
}

impl Plan {
    /// Loads each model once in a child before its batch: a model the
    /// engine rejects is one clear error, not one failure per repeat.
    pub fn check_loads(&mut self, launcher: &Launcher) {
        let timeout_s = self.spec.timeout_s;
        for gi in 0..self.groups.len() {
            if self.groups[gi].pending.is_empty() {
                continue;
            }
            let job = self.job(&self.groups[gi], 0, true);
            if let ChildEnd::Failed(message) = run_child(launcher, &job, timeout_s) {
                if crate::interrupt::requested() {
                    return;
                }
                self.groups[gi].load_error = Some(message);
            }
        }
    }

    /// Runs every pending repeat of the groups whose model loads, storing
    /// each as it finishes. Deterministic repeats are simulated twice; when
    /// the two are identical, the others are recorded as copies of the
    /// first. When an interruption is asked for
    /// ([`crate::interrupt::request`]), stops at once with
    /// [`crate::interrupt::Interrupted`], the runs finished before stored.
    pub fn execute(&mut self, launcher: &Launcher, progress: &dyn Progress) -> Result<BatchStats> {
        let (first, deferred) = split_for_copies(&self.groups, self.deterministic());
        let mut batch = Batch {
            plan: self,
            launcher,
            progress,
            stats: BatchStats::default(),
        };
        batch.execute(first)?;
        crate::interrupt::check()?;
        let rest = batch.copy_or_simulate(deferred)?;
        batch.execute(rest)?;
        crate::interrupt::check()?;
        Ok(batch.stats)
    }

    /// Records `last_batch` (runs, jobs, wall time, speed) in the manifest
    /// of every group that ran something.
    pub fn record_batch(&mut self, stats: &BatchStats, wall_time_s: f64) -> Result<()> {
        for g in &mut self.groups {
            let ran = g.done.total();
            if ran == 0 {
                continue;
            }
            let mut settings = g.store.manifest().settings.clone();
            settings["last_batch"] = serde_json::json!({
                "runs": ran,
                "jobs": self.jobs,
                "wall_time_s": wall_time_s,
                "steps_per_second": stats.steps_per_second().round(),
            });
            g.store.set_settings(settings)?;
        }
        Ok(())
    }
}

/// A fresh folder for one Slurm array of the batch: `OUT/.slurm/<unix
/// time>-<n>`, the first `n` not yet taken.
fn slurm_dir(out: &std::path::Path) -> std::path::PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    (0..)
        .map(|n| out.join(".slurm").join(format!("{secs}-{n}")))
        .find(|d| !d.exists())
        .unwrap_or_else(|| out.join(".slurm").join("batch"))
}

/// A run's outcome on its way from a worker to the storing thread, with
/// the channel on which the storing thread says it is stored.
type Finished = ((usize, u32), ChildEnd, f64, mpsc::Sender<()>);

/// Runs jobs from `queue` in child processes until it is empty. A worker
/// takes its next job only once its last run is stored and reported
/// ([`Progress::inc`]): an interruption asked for while the run was being
/// stored or reported (a Ctrl-C seen by the progress display, a Python
/// reporter that raises) then starts no further run, whatever the timing.
fn worker(
    queue: &Mutex<VecDeque<((usize, u32), Job)>>,
    launcher: &Launcher,
    timeout_s: Option<f64>,
    tx: mpsc::Sender<Finished>,
) {
    loop {
        if crate::interrupt::requested() {
            break;
        }
        let next = queue.lock().map(|mut q| q.pop_front()).unwrap_or(None);
        let Some((key, job)) = next else { break };
        let start = Instant::now();
        let end = run_child(launcher, &job, timeout_s);
        if crate::interrupt::requested() && matches!(end, ChildEnd::Failed(_)) {
            // Cut short by the interruption: not a failure of the run.
            break;
        }
        let (stored_tx, stored) = mpsc::channel();
        if tx
            .send((key, end, start.elapsed().as_secs_f64(), stored_tx))
            .is_err()
        {
            break;
        }
        if stored.recv().is_err() {
            break;
        }
    }
}

impl Batch<'_> {
    /// Runs `runs` in child processes, `jobs` at a time, storing each as
    /// it finishes.
    fn execute(&mut self, runs: Runs) -> Result<()> {
        if runs.is_empty() {
            return Ok(());
        }
        let jobs: VecDeque<((usize, u32), Job)> = runs
            .iter()
            .map(|&(g, r)| ((g, r), self.plan.job(&self.plan.groups[g], r, false)))
            .collect();
        if let Executor::Slurm(opts) = &self.plan.executor {
            let opts = opts.clone();
            let dir = slurm_dir(&self.plan.spec.out);
            let launcher = self.launcher;
            return run_array(
                jobs.into(),
                &dir,
                launcher,
                &opts,
                &mut |(gi, repeat), end, s| self.store(gi, repeat, end, s),
            );
        }
        let workers = self.plan.jobs.min(jobs.len());
        let queue = Mutex::new(jobs);
        let (launcher, timeout_s) = (self.launcher, self.plan.spec.timeout_s);
        std::thread::scope(|scope| {
            let (tx, rx) = mpsc::channel::<Finished>();
            for _ in 0..workers {
                let (queue, tx) = (&queue, tx.clone());
                scope.spawn(move || worker(queue, launcher, timeout_s, tx));
            }
            drop(tx);
            for ((gi, repeat), end, elapsed_s, stored) in rx {
                self.store(gi, repeat, end, elapsed_s)?;
                let _ = stored.send(());
            }
            Ok(())
        })
    }

    /// Stores one child's result in its group's results directory.
    fn store(&mut self, gi: usize, repeat: u32, end: ChildEnd, elapsed_s: f64) -> Result<()> {
        let id = run_id(repeat);
        let mut entry = RunEntry::new(&id);
        if let Some(seed) = (!self.plan.deterministic()).then_some(self.plan.spec.seed) {
            entry.seed = Some(repeat_seed(seed, repeat as u64));
        }
        entry
            .extra
            .insert("repeat".into(), serde_json::json!(repeat));
        self.stats.simulated += 1;
        let stored = match end {
            ChildEnd::Done(result) => self.store_result(gi, entry, &result, elapsed_s),
            ChildEnd::Failed(message) => {
                let g = &self.plan.groups[gi];
                self.progress.println(format!(
                    "{}/{} {id}: failed: {message}",
                    g.scene_name, g.source
                ));
                entry.message = Some(message);
                entry.wall_time_s = Some(elapsed_s);
                self.record_failure(gi, entry)
            }
        };
        let dir = self.plan.groups[gi].store.dir().display().to_string();
        stored.with_context(|| format!("storing {id} in {dir}"))?;
        self.progress.inc(1);
        if self.stats.failures > 0 {
            self.progress
                .set_message(format!("{} failed", self.stats.failures));
        }
        Ok(())
    }

    /// Records a failed run.
    fn record_failure(
        &mut self,
        gi: usize,
        entry: RunEntry,
    ) -> Result<(), realitygap_data::runstore::StoreError> {
        let g = &mut self.plan.groups[gi];
        self.stats.failures += 1;
        g.done.failed += 1;
        g.store.record_failed_run(entry)
    }

    /// Stores a child's result: its run, with its speed and divergence.
    fn store_result(
        &mut self,
        gi: usize,
        mut entry: RunEntry,
        result: &ChildResult,
        elapsed_s: f64,
    ) -> Result<(), realitygap_data::runstore::StoreError> {
        let trajectory = match result.trajectory() {
            Ok(t) => t,
            Err(e) => {
                entry.message = Some(e.to_string());
                return self.record_failure(gi, entry);
            }
        };
        entry.wall_time_s = Some(result.wall_time_s);
        let sps = if result.wall_time_s > 0.0 {
            result.engine_steps as f64 / result.wall_time_s
        } else {
            0.0
        };
        for (k, v) in [
            ("engine_steps", serde_json::json!(result.engine_steps)),
            ("steps_per_second", serde_json::json!(sps.round())),
            ("process_wall_time_s", serde_json::json!(elapsed_s)),
            ("samples", serde_json::json!(trajectory.len())),
        ] {
            entry.extra.insert(k.into(), v);
        }
        if !result.handovers.is_empty() {
            let handovers = serde_json::to_value(&result.handovers).unwrap_or_default();
            entry.extra.insert("handovers".into(), handovers);
        }
        if !result.stability_issues.is_empty() {
            let issues = serde_json::to_value(&result.stability_issues).unwrap_or_default();
            entry
                .extra
                .insert("allowed_unstable_settings".into(), issues);
        }
        self.stats.steps_total += result.engine_steps;
        self.stats.loop_time_total += result.wall_time_s;
        let g = &mut self.plan.groups[gi];
        if let Some((t_s, reason)) = &result.diverged {
            entry.status = RunStatus::Diverged;
            entry.message = Some(format!("diverged at t = {t_s:.4} s: {reason}"));
            entry
                .extra
                .insert("diverged_at_s".into(), serde_json::json!(t_s));
            g.done.diverged += 1;
        } else if let Some(found) = &result.instability {
            entry.status = RunStatus::Unstable;
            entry.message = Some(found.to_message());
            let json = serde_json::to_value(found).unwrap_or_default();
            entry.extra.insert("unstable".into(), json);
            g.done.unstable += 1;
        } else {
            g.done.ok += 1;
        }
        g.store.write_run(entry, &trajectory)
    }

    /// For each group's deferred repeats: when its two simulated repeats
    /// both completed with byte-identical runs, records the deferred ones as
    /// copies of the first (`copy_of` in the manifest); otherwise returns
    /// them to be simulated.
    fn copy_or_simulate(&mut self, deferred: Deferred) -> Result<Runs> {
        let mut simulate = Vec::new();
        for (gi, repeats) in deferred {
            let g = &mut self.plan.groups[gi];
            let proven = g
                .pending
                .get(..2)
                .and_then(|pair| identical_runs(&g.store, pair[0], pair[1]));
            let Some((original, trajectory)) = proven else {
                simulate.extend(repeats.into_iter().map(|r| (gi, r)));
                continue;
            };
            for repeat in repeats {
                write_copy(&mut g.store, repeat, original, &trajectory)?;
                g.done.ok += 1;
                self.progress.inc(1);
            }
        }
        Ok(simulate)
    }
}

/// Records repeat `repeat` as a copy of repeat `original`.
fn write_copy(
    store: &mut RunStore,
    repeat: u32,
    original: u32,
    trajectory: &Trajectory,
) -> Result<()> {
    let mut entry = RunEntry::new(run_id(repeat));
    entry
        .extra
        .insert("repeat".into(), serde_json::json!(repeat));
    entry
        .extra
        .insert("copy_of".into(), serde_json::json!(run_id(original)));
    entry
        .extra
        .insert("samples".into(), serde_json::json!(trajectory.len()));
    store
        .write_run(entry, trajectory)
        .with_context(|| format!("storing a copy in {}", store.dir().display()))
}

/// The first repeat's trajectory when repeats `a` and `b` of a store both
/// completed and their run files are byte-identical.
pub fn identical_runs(store: &RunStore, a: u32, b: u32) -> Option<(u32, Trajectory)> {
    let ok = |r: u32| {
        store
            .run(&run_id(r))
            .is_some_and(|e| e.status == RunStatus::Ok)
    };
    if !(ok(a) && ok(b)) {
        return None;
    }
    let file =
        |r: u32| std::fs::read(store.dir().join("runs").join(format!("{}.csv", run_id(r)))).ok();
    let (fa, fb) = (file(a)?, file(b)?);
    if fa != fb {
        return None;
    }
    store.read_run(&run_id(a)).ok().map(|t| (a, t))
}
