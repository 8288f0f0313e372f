//! `--executor slurm` against a real single-node Slurm cluster
//! (`scripts/slurm-local start`, which `scripts/test` runs; `scripts/setup
//! --tests` installs Slurm): the same runs byte for byte as the local pool,
//! a cancelled array keeps its finished runs and a rerun completes the
//! rest, and the errors (no sbatch, an unknown partition) are clear.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Starts the test cluster once for this test binary; its `SLURM_CONF`.
fn cluster() -> &'static str {
    static CONF: OnceLock<String> = OnceLock::new();
    CONF.get_or_init(|| {
        let out = Command::new(workspace().join("scripts/slurm-local"))
            .arg("start")
            .output()
            .expect("scripts/slurm-local runs");
        assert!(
            out.status.success(),
            "the test cluster did not start (run scripts/setup --tests, as root): {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let dir = std::env::var("REALITYGAP_SLURM_DIR").unwrap_or("/tmp/realitygap-slurm".into());
        format!("{dir}/slurm.conf")
    })
}

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .env("SLURM_CONF", cluster())
        .output()
        .unwrap()
}

fn scene(name: &str) -> String {
    workspace()
        .join(format!("assets/scenes/{name}.toml"))
        .display()
        .to_string()
}

/// `run` of scenes 1 and 2 in ODE, `repeats` perturbed repeats (so that
/// every run is simulated, not copied), with `extra` arguments.
fn run_args(out: &Path, repeats: u32, extra: &[&str]) -> Vec<String> {
    let mut a: Vec<String> = vec![
        "run".into(),
        scene("scene1_single_joint"),
        scene("scene2_two_joints"),
        "--engine".into(),
        "ode".into(),
        "--repeats".into(),
        repeats.to_string(),
        "--perturb".into(),
        "sensor_noise_deg=0.1".into(),
        "--out".into(),
        out.display().to_string(),
    ];
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

fn csvs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for scene in ["scene1_single_joint", "scene2_two_joints"] {
        let runs = dir.join(scene).join("ode/runs");
        let mut names: Vec<_> = std::fs::read_dir(&runs)
            .map(|r| {
                r.flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default();
        names.sort();
        for n in names.into_iter().filter(|n| n.ends_with(".csv")) {
            out.push((
                format!("{scene}/{n}"),
                std::fs::read(runs.join(&n)).unwrap(),
            ));
        }
    }
    out
}

#[test]
fn slurm_and_local_store_the_same_runs_byte_for_byte() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("slurm"), tmp.path().join("local"));
    let args = run_args(
        &a,
        2,
        &["--executor", "slurm", "--slurm-runs-per-task", "2"],
    );
    let o = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let args = run_args(&b, 2, &[]);
    let o = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (sa, sb) = (csvs(&a), csvs(&b));
    assert_eq!(sa.len(), 4);
    assert_eq!(
        sa.iter().map(|x| &x.0).collect::<Vec<_>>(),
        sb.iter().map(|x| &x.0).collect::<Vec<_>>()
    );
    for (x, y) in sa.iter().zip(&sb) {
        assert!(x.1 == y.1, "{} differs between slurm and local", x.0);
    }
    // The submitted script is kept for the user.
    let arrays: Vec<_> = std::fs::read_dir(a.join(".slurm"))
        .unwrap()
        .flatten()
        .collect();
    assert!(!arrays.is_empty());
    let script = std::fs::read_to_string(arrays[0].path().join("submit.sh")).unwrap();
    assert!(
        script.contains("__run-one") && script.contains("SLURM_ARRAY_TASK_ID"),
        "{script}"
    );
}

/// The job id of the array writing into `out`, once Slurm lists it.
fn job_id(out: &Path) -> Option<String> {
    let o = Command::new("squeue")
        .args(["-h", "-o", "%F %o"])
        .env("SLURM_CONF", cluster())
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let needle = out.display().to_string();
    text.lines()
        .find(|l| l.contains(&needle))
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
}

#[test]
fn a_cancelled_array_keeps_its_finished_runs_and_a_rerun_completes_them() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cancel");
    // One task at a time, so that the array is cancelled midway.
    let args = run_args(&out, 4, &["--executor", "slurm", "--slurm-max-tasks", "1"]);
    let child = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(&args)
        .env("SLURM_CONF", cluster())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    let job = loop {
        if let (Some(id), n) = (job_id(&out), csvs(&out).len()) {
            if n >= 2 {
                break id;
            }
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no run finished under Slurm"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let status = Command::new("scancel")
        .arg(&job)
        .env("SLURM_CONF", cluster())
        .status()
        .unwrap();
    assert!(status.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned() + &String::from_utf8_lossy(&o.stdout);
    let kept = csvs(&out);
    assert!(kept.len() < 8, "the array finished before it was cancelled");
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("rerun the same command"), "{err}");
    let manifest = std::fs::read_to_string(out.join("scene2_two_joints/ode/manifest.json"))
        .unwrap_or_default()
        + &std::fs::read_to_string(out.join("scene1_single_joint/ode/manifest.json")).unwrap();
    assert!(
        manifest.contains(&format!("slurm job {job}")),
        "the failed runs name the Slurm job: {manifest}"
    );
    // In Slurm's terms, and the tasks that never started are not taken
    // for a directory they could not write.
    assert!(manifest.contains("CANCELLED"), "{manifest}");
    assert!(!manifest.contains("without a log"), "{manifest}");
    // The rerun resubmits only what is missing and leaves the rest as it was.
    let args = run_args(&out, 4, &["--executor", "slurm"]);
    let o = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let after = csvs(&out);
    assert_eq!(after.len(), 8);
    for (name, bytes) in &kept {
        let now = after.iter().find(|x| &x.0 == name).unwrap();
        assert!(&now.1 == bytes, "{name} changed on the rerun");
    }
}

#[test]
fn slurm_errors_are_clear() {
    let tmp = tempfile::tempdir().unwrap();
    // No sbatch on the PATH.
    let args = run_args(&tmp.path().join("a"), 1, &["--executor", "slurm"]);
    let o = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(&args)
        .env("PATH", tmp.path())
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(e.contains("`sbatch` is not on the PATH"), "{e}");
    assert!(!tmp.path().join("a").exists(), "it wrote before failing");
    // A partition that does not exist: Slurm's own message, passed on.
    let args = run_args(
        &tmp.path().join("b"),
        1,
        &[
            "--executor",
            "slurm",
            "--slurm-partition",
            "nosuchpartition",
        ],
    );
    let o = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        e.contains("sbatch refused the job array") && e.contains("artition"),
        "{e}"
    );
}

/// Every run CSV below `dir`, by path relative to it.
fn all_csvs(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() && e.file_name() != ".slurm" {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "csv")
                && p.parent().is_some_and(|q| q.ends_with("runs"))
            {
                out.push((
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn reproduce_on_slurm_equals_reproduce_locally() {
    let tmp = tempfile::tempdir().unwrap();
    let mut tables = Vec::new();
    let mut runs = Vec::new();
    for executor in ["slurm", "local"] {
        let out = tmp.path().join(executor);
        let o = realitygap(&[
            "reproduce",
            "--data",
            "none",
            "--engine",
            "ode",
            "--engine",
            "rapier",
            "--repeats",
            "2",
            "--executor",
            executor,
            "--slurm-runs-per-task",
            "3",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            o.status.success(),
            "{executor}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        tables.push(std::fs::read_to_string(out.join("report/table.md")).unwrap());
        runs.push(all_csvs(&out.join("runs")));
    }
    assert_eq!(runs[0].len(), 12, "3 scenes x 2 engines x 2 repeats");
    assert!(
        runs[0] == runs[1],
        "the run CSVs differ between slurm and local"
    );
    assert!(tables[0].contains("Rapier"), "{}", tables[0]);
    assert_eq!(tables[0], tables[1]);
    assert!(tmp.path().join("slurm/runs/.slurm").is_dir());
    assert!(!tmp.path().join("local/runs/.slurm").exists());
}

/// What a frontier sweep measures that does not depend on timing: per
/// point its label, status, deviations, gap and per scene the same with
/// the engine steps; the reference's halvings and gap.
fn deterministic_frontier(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("frontier.json")).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let scenes = |p: &serde_json::Value| -> Vec<serde_json::Value> {
        p["scenes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| {
                serde_json::json!([
                    s["scene"],
                    s["status"],
                    s["engine_steps"],
                    s["simulated_s"],
                    s["deviation_by_body_m"],
                    s["gap_m"]
                ])
            })
            .collect()
    };
    let points: Vec<serde_json::Value> = j["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            assert!(p["cpu_s"].as_f64().unwrap() > 0.0, "{p}");
            serde_json::json!([
                p["label"],
                p["status"],
                p["max_deviation_m"],
                p["mean_deviation_m"],
                p["gap_m"],
                p["within_tolerance"],
                scenes(p)
            ])
        })
        .collect();
    let r = &j["reference"];
    serde_json::json!({
        "points": points,
        "reference": [r["set"], r["halvings"], r["converged"], r["gap_m"], scenes(r)],
    })
}

#[test]
fn frontier_on_slurm_gives_the_local_deviations_statuses_and_gaps() {
    let tmp = tempfile::tempdir().unwrap();
    let mut measured = Vec::new();
    for executor in ["slurm", "local"] {
        let out = tmp.path().join(executor);
        let o = realitygap(&[
            "frontier",
            &scene("scene1_single_joint"),
            &scene("scene2_two_joints"),
            "--engine",
            "ode",
            "--sweep",
            "stepper=quick_step,world_step",
            "--sweep",
            "timestep_s=0.01,0.005",
            "--repeats",
            "2",
            "--data",
            "builtin",
            "--executor",
            executor,
            "--slurm-runs-per-task",
            "3",
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{executor}: {err}");
        assert_eq!(err.contains("slurm: points:"), executor == "slurm", "{err}");
        assert!(out.join("recommended.toml").is_file());
        assert!(out.join("frontier_gap.svg").is_file());
        measured.push(deterministic_frontier(&out));
    }
    let (slurm, local) = (&measured[0], &measured[1]);
    assert_eq!(slurm["points"].as_array().unwrap().len(), 5, "{slurm}");
    assert!(
        slurm["points"][2][4].as_f64().is_some(),
        "world_step 0.01 s has a gap: {slurm}"
    );
    assert_eq!(slurm, local);
    // One array per stage, each script kept for the user.
    for stage in ["reference", "halving-1", "points"] {
        let script = tmp
            .path()
            .join("slurm/.slurm")
            .join(stage)
            .join("submit.sh");
        assert!(script.is_file(), "{}", script.display());
    }
    assert!(!tmp.path().join("local/.slurm").exists());
}

#[test]
fn a_results_directory_the_workers_cannot_write_is_a_clear_error() {
    // The tests run as root, which writes anywhere: the tasks run as
    // `nobody` instead (root may submit for another user), into a folder
    // only root can write. The binary stays readable for them.
    use std::os::unix::fs::PermissionsExt;
    let tmp = tempfile::tempdir().unwrap();
    std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let out = tmp.path().join("out");
    let args = run_args(
        &out,
        1,
        &["--executor", "slurm", "--slurm-arg=--uid=nobody"],
    );
    let o = realitygap(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "{err}");
    let array = std::fs::read_dir(out.join(".slurm"))
        .unwrap()
        .flatten()
        .next()
        .unwrap()
        .path();
    for needed in [
        "ended without a result (FAILED".to_string(),
        "without a log".to_string(),
        format!("Slurm could not write {}/logs/task_", array.display()),
        "must be on a filesystem the compute nodes share, writable by the job's user (nobody"
            .to_string(),
        "rerun the same command".to_string(),
    ] {
        assert!(err.contains(&needed), "missing \"{needed}\" in: {err}");
    }
    // Both runs are marked failed, each naming its Slurm job and task.
    let mut tasks = Vec::new();
    for scene in ["scene1_single_joint", "scene2_two_joints"] {
        let text = std::fs::read_to_string(out.join(scene).join("ode/manifest.json")).unwrap();
        let m: serde_json::Value = serde_json::from_str(&text).unwrap();
        let run = &m["runs"][0];
        assert_eq!(run["status"], "failed", "{run}");
        let message = run["message"].as_str().unwrap();
        let task = message
            .strip_prefix("slurm job ")
            .and_then(|t| t.split_whitespace().next())
            .unwrap_or_else(|| panic!("no job and task id: {message}"));
        assert!(task.contains('_'), "{message}");
        tasks.push(task.to_string());
    }
    assert_ne!(tasks[0], tasks[1]);
}

/// `replay --executor slurm`: the independent writer's recorded episodes
/// replayed in ODE and MuJoCo as a Slurm job array give the same runs,
/// byte for byte, as the local pool of child processes.
#[test]
fn replay_through_slurm_gives_the_local_pools_runs() {
    let tmp = std::env::temp_dir().join(format!("rg-slurm-replay-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let fixtures = realitygap_core::testing::joint_recording_fixtures();
    let real = tmp.join("real");
    let o = realitygap(&[
        "import",
        "rosbag",
        &fixtures.join("mcap/episode_000").display().to_string(),
        &fixtures.join("mcap/episode_001").display().to_string(),
        "--robot",
        &realitygap_core::testing::iiwa_urdf().display().to_string(),
        "--out",
        &real.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let replay = |out: &Path, extra: &[&str]| {
        let mut a = vec![
            "replay".to_string(),
            real.display().to_string(),
            "--engine".into(),
            "ode".into(),
            "--engine".into(),
            "mujoco".into(),
            "--out".into(),
            out.display().to_string(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let o = realitygap(&a);
        assert!(
            o.status.success(),
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let local = tmp.join("local");
    let slurm = tmp.join("slurm");
    replay(&local, &[]);
    let said = replay(&slurm, &["--executor", "slurm"]);
    assert!(said.contains("4 runs, 0 kept"), "{said}");
    assert!(slurm.join("slurm/submit.sh").is_file());
    for engine in ["ode", "mujoco"] {
        for e in ["episode_000", "episode_001"] {
            let file = |d: &Path| {
                let runs = d.join(engine).join("runs");
                let name = std::fs::read_dir(&runs)
                    .unwrap()
                    .flatten()
                    .map(|f| f.file_name().to_string_lossy().into_owned())
                    .find(|n| n.starts_with(e) && n.ends_with(".csv") && !n.contains("commands"))
                    .unwrap_or_else(|| panic!("no run {e} in {}", runs.display()));
                std::fs::read(runs.join(name)).unwrap()
            };
            assert!(
                file(&local) == file(&slurm),
                "{engine} {e}: the Slurm run differs from the local one"
            );
        }
    }
    // A rerun keeps them all.
    let again = replay(&slurm, &["--executor", "slurm"]);
    assert!(again.contains("4 kept"), "{again}");
    let _ = std::fs::remove_dir_all(&tmp);
}
