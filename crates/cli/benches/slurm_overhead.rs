//! Benchmark: the overhead of `--executor slurm` against the local pool,
//! on the single-node test cluster (`scripts/slurm-local`, started here
//! when it is not running and stopped again afterwards; needs root and
//! `scripts/setup --tests`).
//!
//! For each batch size N (perturbed ODE runs of the three study scenes, so
//! that every run is simulated) it times `realitygap run` locally (`--jobs`
//! = the cores) and on Slurm at each number of runs per array task R, and
//! prints per batch: the array tasks submitted (read back from the
//! submitted script), the wall time, the overhead per simulation
//! ((Slurm - local) / N), per task ((Slurm - local) / tasks), and the
//! ratio Slurm / local. Figures only, no timed assertion.
//!
//!     cargo bench -p realitygap --bench slurm_overhead
//!     BATCHES=12,48 RUNS_PER_TASK=1,6 cargo bench -p realitygap --bench slurm_overhead

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const SCENES: [&str; 3] = [
    "scene1_single_joint",
    "scene2_two_joints",
    "scene3_cube_push",
];

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A comma-separated list of numbers from the environment, or `default`.
fn list(var: &str, default: &[usize]) -> Vec<usize> {
    std::env::var(var)
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .filter(|v: &Vec<usize>| !v.is_empty())
        .unwrap_or_else(|| default.to_vec())
}

/// `slurm.conf` of the test cluster.
fn slurm_conf() -> String {
    let dir = std::env::var("REALITYGAP_SLURM_DIR").unwrap_or("/tmp/realitygap-slurm".into());
    format!("{dir}/slurm.conf")
}

/// Whether the test cluster answers.
fn cluster_up() -> bool {
    Command::new("sinfo")
        .args(["-h", "-o", "%T"])
        .env("SLURM_CONF", slurm_conf())
        .output()
        .is_ok_and(|o| o.status.success() && !o.stdout.is_empty())
}

fn slurm_local(what: &str) {
    let out = Command::new(workspace().join("scripts/slurm-local"))
        .arg(what)
        .output()
        .expect("scripts/slurm-local runs");
    assert!(
        out.status.success(),
        "scripts/slurm-local {what}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Wall time of one batch of `runs` simulations into `out`, s.
fn batch(runs: usize, out: &Path, executor: &[String]) -> f64 {
    let scenes = workspace().join("assets/scenes");
    let start = Instant::now();
    let result = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .arg("run")
        .args(SCENES.map(|s| scenes.join(format!("{s}.toml"))))
        .args(["--engine", "ode", "--perturb", "sensor_noise_deg=0.1"])
        .args(["--repeats", &(runs / SCENES.len()).to_string(), "--out"])
        .arg(out)
        .args(executor)
        .env("SLURM_CONF", slurm_conf())
        .output()
        .expect("realitygap starts");
    let seconds = start.elapsed().as_secs_f64();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    seconds
}

/// The array tasks of every array a Slurm batch in `out` submitted, from
/// the comment of its `submit.sh` (`sbatch --array=0-LAST ...`).
fn tasks_submitted(out: &Path) -> usize {
    let Ok(arrays) = std::fs::read_dir(out.join(".slurm")) else {
        return 0;
    };
    arrays
        .flatten()
        .filter_map(|a| std::fs::read_to_string(a.path().join("submit.sh")).ok())
        .filter_map(|s| {
            let last = s.split("--array=0-").nth(1)?;
            let digits: String = last.chars().take_while(char::is_ascii_digit).collect();
            digits.parse::<usize>().ok().map(|l| l + 1)
        })
        .sum()
}

fn main() {
    let batches = list("BATCHES", &[12, 48, 96]);
    let per_task = list("RUNS_PER_TASK", &[1, 4, 12]);
    let started_here = !cluster_up();
    if started_here {
        slurm_local("start");
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "Slurm overhead: perturbed ODE runs of the 3 study scenes, local --jobs {cores} against the single-node test cluster ({cores} cores)\n"
    );
    println!("| runs | executor | runs/task | array tasks | wall s | s/run | overhead s/run | overhead s/task | Slurm/local |");
    println!("|---:|---|---:|---:|---:|---:|---:|---:|---:|");
    for &n in &batches {
        let n = n.div_ceil(SCENES.len()) * SCENES.len();
        let tmp = tempfile::tempdir().expect("a temporary folder");
        let local = batch(n, &tmp.path().join("local"), &[]);
        println!(
            "| {n} | local | - | - | {local:.2} | {:.3} | - | - | 1.0 |",
            local / n as f64
        );
        for &r in &per_task {
            let out = tmp.path().join(format!("slurm{r}"));
            let args = [
                "--executor",
                "slurm",
                "--slurm-runs-per-task",
                &r.to_string(),
            ]
            .map(String::from);
            let slurm = batch(n, &out, &args);
            let tasks = tasks_submitted(&out);
            println!(
                "| {n} | slurm | {r} | {tasks} | {slurm:.2} | {:.3} | {:.3} | {:.3} | {:.1} |",
                slurm / n as f64,
                (slurm - local) / n as f64,
                (slurm - local) / tasks.max(1) as f64,
                slurm / local
            );
        }
    }
    println!("\nArray tasks = ceil(runs / runs-per-task): linear in the batch size at a fixed runs-per-task.");
    if started_here {
        slurm_local("stop");
    }
}
