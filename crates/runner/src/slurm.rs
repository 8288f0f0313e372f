//! The Slurm executor: a batch's simulations as one Slurm job array.
//!
//! The coordinating process writes every job of the batch as JSON into
//! `OUT/.slurm/<batch>/jobs/`, and a submission script `submit.sh` (kept for
//! the user to read and rerun) that runs `realitygap __run-one` on each of
//! a task's jobs. `sbatch --array` submits it; each task writes one result
//! file per job, atomically (`<i>.tmp` renamed to `<i>.json`; a failing
//! child leaves `<i>.failed` with its last words). The coordinator polls the
//! folder, stores every result as it appears exactly as the local pool
//! does, and once Slurm no longer lists the job (`squeue`), reports the
//! jobs that produced nothing with their job and task id and log path.
//! The results directory must be on a filesystem the compute nodes share.

use crate::child::{last_lines, ChildEnd, Launcher};
use crate::protocol::{ChildResult, Job};
use anyhow::{anyhow, bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// What `--executor slurm` passes to `sbatch`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SlurmOptions {
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time` (Slurm's format, e.g. `1:00:00`) of each array task.
    pub time: Option<String>,
    /// `--mem` of each array task (e.g. `2G`).
    pub mem: Option<String>,
    /// More `sbatch` arguments, passed as they are.
    pub args: Vec<String>,
    /// Array throttle: at most this many tasks at once (`%N`).
    pub max_tasks: Option<usize>,
    /// Simulations per array task (default 1).
    pub runs_per_task: usize,
}

/// How a batch's simulations are executed.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Executor {
    /// Child processes on this machine (`--jobs` at a time).
    #[default]
    Local,
    /// One Slurm job array per batch.
    Slurm(SlurmOptions),
}

/// Checks that `sbatch` and `squeue` can be run; a clear error otherwise.
pub fn check_available() -> Result<()> {
    for tool in ["sbatch", "squeue"] {
        let found = std::env::var_os("PATH")
            .map(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
            .unwrap_or(false);
        if !found {
            bail!(
                "--executor slurm: `{tool}` is not on the PATH; run on a machine with Slurm's client tools (or use --executor local)"
            );
        }
    }
    Ok(())
}

/// The submission script of an array of `count` jobs in `dir`.
fn script(dir: &Path, program: &Path, args: &[String], count: usize, per_task: usize) -> String {
    let q = |p: &Path| shell_quote(&p.display().to_string());
    let args: Vec<String> = args.iter().map(|a| shell_quote(a)).collect();
    format!(
        "#!/bin/bash\n\
         # realitygap: {count} simulations, {per_task} per array task. Rerun by hand with\n\
         #   sbatch --array=0-{last} {script}\n\
         set -u\n\
         dir={dir}\n\
         if [ ! -w \"$dir/results\" ]; then\n\
         \x20 echo \"realitygap: $(id -un) cannot write into $dir/results on $(hostname): the results directory must be on a filesystem the compute nodes share, writable by the job's user\" >&2\n\
         \x20 exit 1\n\
         fi\n\
         first=$((SLURM_ARRAY_TASK_ID * {per_task}))\n\
         for ((i = first; i < first + {per_task} && i < {count}; i++)); do\n\
         \x20 [ -e \"$dir/results/$i.json\" ] && continue\n\
         \x20 if {program} {args} < \"$dir/jobs/$i.json\" > \"$dir/results/$i.tmp\" 2> \"$dir/results/$i.err\"; then\n\
         \x20   mv \"$dir/results/$i.tmp\" \"$dir/results/$i.json\"\n\
         \x20 else\n\
         \x20   echo \"exit status $?\" >> \"$dir/results/$i.err\"\n\
         \x20   mv \"$dir/results/$i.err\" \"$dir/results/$i.failed\"\n\
         \x20 fi\n\
         done\n",
        last = count.div_ceil(per_task).saturating_sub(1),
        script = q(&dir.join("submit.sh")),
        dir = q(dir),
        program = q(program),
        args = args.join(" "),
    )
}

fn shell_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// A submitted array.
struct Submitted {
    job_id: String,
    dir: PathBuf,
    per_task: usize,
}

impl Submitted {
    /// Whether Slurm still lists the job (pending or running).
    fn listed(&self) -> Result<bool> {
        let out = Command::new("squeue")
            .args(["-h", "-j", &self.job_id, "-o", "%i"])
            .output()
            .context("running squeue")?;
        // An unknown (finished and purged) job id is an error for squeue.
        Ok(out.status.success() && !String::from_utf8_lossy(&out.stdout).trim().is_empty())
    }

    fn log(&self, task: usize) -> PathBuf {
        self.dir.join("logs").join(format!("task_{task}.log"))
    }

    /// The jobs of `pending` whose result or failure is there, with their
    /// ends: one listing of the results folder per poll, files read only
    /// for the jobs it shows finished.
    fn finished<K>(&self, pending: &BTreeMap<usize, K>) -> Vec<(usize, ChildEnd)> {
        let Ok(entries) = std::fs::read_dir(self.dir.join("results")) else {
            return Vec::new();
        };
        let mut ready: Vec<usize> = entries
            .flatten()
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let stem = name
                    .strip_suffix(".json")
                    .or(name.strip_suffix(".failed"))?;
                stem.parse::<usize>().ok()
            })
            .filter(|i| pending.contains_key(i))
            .collect();
        ready.sort_unstable();
        ready.dedup();
        ready
            .into_iter()
            .filter_map(|i| self.collect(i).map(|e| (i, e)))
            .collect()
    }

    /// Why array task `task` left no result, in Slurm's terms: its job
    /// and task id, Slurm's state and reason when it still knows them, the
    /// task's last words and log; without a log (Slurm could not open it,
    /// as when the job's user cannot write the results directory or the
    /// compute node does not see it), what the directory must be.
    fn missing(&self, task: usize, states: &BTreeMap<usize, TaskState>) -> String {
        let log = self.log(task);
        let state = states.get(&task);
        let slurm_said = state.map_or(" (cancelled, timed out or failed)".to_string(), |s| {
            format!(" ({}, reason {})", s.state, s.reason)
        });
        let head = format!(
            "slurm job {}_{task} ended without a result{slurm_said}",
            self.job_id
        );
        match std::fs::read_to_string(&log) {
            Ok(text) => {
                let said = last_lines(&text, 3);
                let said = if said.is_empty() { String::new() } else { format!(": {said}") };
                format!("{head}{said}; log {}", log.display())
            }
            Err(_) if state.is_some_and(|s| s.state == "CANCELLED") => {
                format!("{head}: cancelled before it started; no log {}", log.display())
            }
            Err(_) => format!(
                "{head} and without a log: Slurm could not write {}. The results directory holding {} must be on a filesystem the compute nodes share, writable by the job's user{}; give --out such a directory (or fix its permissions) and rerun",
                log.display(),
                self.dir.display(),
                state.map(|s| format!(" ({})", s.user)).unwrap_or_default()
            ),
        }
    }

    /// The end of job `i`, when its result or failure is there.
    fn collect(&self, i: usize) -> Option<ChildEnd> {
        let results = self.dir.join("results");
        let ok = results.join(format!("{i}.json"));
        if let Ok(text) = std::fs::read_to_string(&ok) {
            return Some(match serde_json::from_str::<ChildResult>(&text) {
                Ok(r) => ChildEnd::Done(Box::new(r)),
                Err(e) => ChildEnd::Failed(format!("{}: not a result: {e}", ok.display())),
            });
        }
        let failed = results.join(format!("{i}.failed"));
        std::fs::read_to_string(&failed).ok().map(|t| {
            ChildEnd::Failed(format!(
                "slurm job {}_{}: {} (log {})",
                self.job_id,
                i / self.per_task,
                last_lines(&t, 5),
                self.log(i / self.per_task).display()
            ))
        })
    }
}

/// What Slurm says of one finished array task.
#[derive(Debug, Clone, PartialEq)]
struct TaskState {
    /// `JobState`, e.g. `FAILED`, `CANCELLED`, `TIMEOUT`.
    state: String,
    /// `Reason`, e.g. `JobLaunchFailure`.
    reason: String,
    /// `UserId`, e.g. `nobody(65534)`.
    user: String,
}

/// Slurm's record of every task of array `job_id` (`scontrol -o show
/// job`), by task id; empty once Slurm has forgotten the job (`MinJobAge`)
/// or when scontrol cannot be run.
fn task_states(job_id: &str) -> BTreeMap<usize, TaskState> {
    let Ok(out) = Command::new("scontrol")
        .args(["-o", "show", "job", job_id])
        .output()
    else {
        return BTreeMap::new();
    };
    parse_task_states(&String::from_utf8_lossy(&out.stdout))
}

/// [`task_states`] of scontrol's one-line-per-task output.
fn parse_task_states(text: &str) -> BTreeMap<usize, TaskState> {
    text.lines()
        .filter_map(|line| {
            let field = |key: &str| {
                line.split_whitespace()
                    .find_map(|f| f.strip_prefix(key)?.strip_prefix('='))
                    .map(str::to_string)
            };
            let tasks = task_ids(&field("ArrayTaskId")?);
            let state = TaskState {
                state: field("JobState")?,
                reason: field("Reason").unwrap_or_default(),
                user: field("UserId").unwrap_or_default(),
            };
            Some(tasks.into_iter().map(move |t| (t, state.clone())))
        })
        .flatten()
        .collect()
}

/// The task ids of scontrol's `ArrayTaskId` (`3`, or for the tasks that
/// never started `1-5%1`, `1,3,5-7`, `0-9:2`).
fn task_ids(spec: &str) -> Vec<usize> {
    let spec = spec.split('%').next().unwrap_or_default();
    spec.split(',')
        .flat_map(|part| {
            let (range, step) = part.split_once(':').unwrap_or((part, "1"));
            let step = step.parse::<usize>().unwrap_or(1).max(1);
            let (a, b) = range.split_once('-').unwrap_or((range, range));
            match (a.parse::<usize>(), b.parse::<usize>()) {
                (Ok(a), Ok(b)) => (a..=b).step_by(step).collect(),
                _ => Vec::new(),
            }
        })
        .collect()
}

/// Submits `jobs` as one job array in `dir` and stores each as its result
/// appears (`store(key, end, elapsed)`); jobs that end without a result are
/// stored as failed with Slurm's job and task id and the task's log.
pub fn run_array<K: Copy + Ord>(
    jobs: Vec<(K, Job)>,
    dir: &Path,
    launcher: &Launcher,
    opts: &SlurmOptions,
    store: &mut dyn FnMut(K, ChildEnd, f64) -> Result<()>,
) -> Result<()> {
    check_available()?;
    // Absolute, so that the script and the messages name it wherever the
    // tasks start and the user reruns it.
    let dir = &std::path::absolute(dir)
        .with_context(|| format!("--executor slurm: the folder {}", dir.display()))?;
    let submitted = submit(&jobs, dir, launcher, opts)?;
    let started = Instant::now();
    let mut pending: BTreeMap<usize, K> =
        jobs.iter().enumerate().map(|(i, (k, _))| (i, *k)).collect();
    loop {
        let listed = submitted.listed()?;
        let done = submitted.finished(&pending);
        for (i, end) in done {
            if let Some(k) = pending.remove(&i) {
                store(k, end, started.elapsed().as_secs_f64())?;
            }
        }
        if pending.is_empty() {
            return Ok(());
        }
        if !listed {
            // One last look: a result may have landed after the listing.
            let late = submitted.finished(&pending);
            for (i, end) in late {
                if let Some(k) = pending.remove(&i) {
                    store(k, end, started.elapsed().as_secs_f64())?;
                }
            }
            let states = task_states(&submitted.job_id);
            for (i, k) in std::mem::take(&mut pending) {
                let message = submitted.missing(i / submitted.per_task, &states);
                store(
                    k,
                    ChildEnd::Failed(message),
                    started.elapsed().as_secs_f64(),
                )?;
            }
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Writes the jobs and the script into `dir` and submits the array.
fn submit<K>(
    jobs: &[(K, Job)],
    dir: &Path,
    launcher: &Launcher,
    opts: &SlurmOptions,
) -> Result<Submitted> {
    for sub in ["jobs", "results", "logs"] {
        std::fs::create_dir_all(dir.join(sub)).with_context(|| {
            format!(
                "--executor slurm: cannot create {}",
                dir.join(sub).display()
            )
        })?;
    }
    for (i, (_, job)) in jobs.iter().enumerate() {
        let path = dir.join("jobs").join(format!("{i}.json"));
        std::fs::write(&path, serde_json::to_vec(job)?)
            .with_context(|| format!("--executor slurm: cannot write {}", path.display()))?;
    }
    let program = match &launcher.program {
        Some(p) => p.clone(),
        None => std::env::current_exe().context("finding this program for the Slurm tasks")?,
    };
    let per_task = opts.runs_per_task.max(1);
    let tasks = jobs.len().div_ceil(per_task);
    let script_path = dir.join("submit.sh");
    std::fs::write(
        &script_path,
        script(dir, &program, &launcher.args, jobs.len(), per_task),
    )
    .with_context(|| format!("--executor slurm: cannot write {}", script_path.display()))?;
    let mut array = format!("0-{}", tasks.saturating_sub(1));
    if let Some(m) = opts.max_tasks {
        array.push_str(&format!("%{}", m.max(1)));
    }
    let mut cmd = Command::new("sbatch");
    // sbatch exports its environment to the tasks: on this machine's node
    // they fork their engine's children from this process's zygote (a task
    // elsewhere cannot reach it and starts its own).
    cmd.envs(realitygap_engine_remote::zygote::handed_down());
    cmd.args(["--parsable", "--job-name=realitygap", "--cpus-per-task=1"])
        .arg(format!("--array={array}"))
        .arg(format!(
            "--output={}",
            dir.join("logs").join("task_%a.log").display()
        ));
    for (flag, v) in [
        ("--partition", &opts.partition),
        ("--time", &opts.time),
        ("--mem", &opts.mem),
    ] {
        if let Some(v) = v {
            cmd.arg(format!("{flag}={v}"));
        }
    }
    cmd.args(&opts.args).arg(&script_path);
    let out = cmd.output().context("running sbatch")?;
    if !out.status.success() {
        return Err(anyhow!(
            "sbatch refused the job array: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let job_id = String::from_utf8_lossy(&out.stdout)
        .trim()
        .split(';')
        .next()
        .unwrap_or_default()
        .to_string();
    if job_id.is_empty() {
        bail!("sbatch printed no job id");
    }
    Ok(Submitted {
        job_id,
        dir: dir.to_path_buf(),
        per_task,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_script_runs_each_tasks_share_and_quotes_paths() {
        let s = script(
            Path::new("/r/it's here"),
            Path::new("/bin/realitygap"),
            &["__run-one".into()],
            5,
            2,
        );
        assert!(s.contains("dir='/r/it'\\''s here'"), "{s}");
        assert!(s.contains("first=$((SLURM_ARRAY_TASK_ID * 2))"), "{s}");
        assert!(s.contains("i < first + 2 && i < 5"), "{s}");
        assert!(s.contains("sbatch --array=0-2"), "{s}");
        assert!(s.contains("'/bin/realitygap' '__run-one'"), "{s}");
        assert!(s.contains("if [ ! -w \"$dir/results\" ]"), "{s}");
    }

    #[test]
    fn scontrol_records_are_read_per_task() {
        let text = "JobId=405 ArrayJobId=404 ArrayTaskId=1 JobName=realitygap UserId=nobody(65534) GroupId=root(0) JobState=FAILED Reason=JobLaunchFailure Dependency=(null)\n\
                    JobId=404 ArrayJobId=404 ArrayTaskId=0 JobName=realitygap UserId=me(1000) GroupId=me(1000) JobState=CANCELLED Reason=None\n\
                    JobId=404 ArrayJobId=404 ArrayTaskId=2-5%1 JobState=CANCELLED Reason=JobArrayTaskLimit\n\
                    JobId=407 ArrayJobId=404 ArrayTaskId=bogus JobState=FAILED\n";
        let states = parse_task_states(text);
        assert_eq!(states.len(), 6, "{states:?}");
        assert_eq!(states[&5].reason, "JobArrayTaskLimit");
        assert_eq!(task_ids("1,3,6-10:2"), [1, 3, 6, 8, 10]);
        assert_eq!(
            states[&1],
            TaskState {
                state: "FAILED".into(),
                reason: "JobLaunchFailure".into(),
                user: "nobody(65534)".into()
            }
        );
        assert_eq!(states[&0].state, "CANCELLED");
    }
}
