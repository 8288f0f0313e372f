//! The process pool, storage, resume bookkeeping and copies of identical
//! deterministic runs, with a stand-in child (a shell script) instead of
//! an engine: what a batch does with its children's answers.

use realitygap_core::controller::{Perturbation, RunOutcome, RunStatus};
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::trajectory::Trajectory;
use realitygap_data::runstore::{RunStatus as StoreStatus, RunStore, SourceKind};
use realitygap_runner::batch::{identical_runs, split_for_copies};
use realitygap_runner::{BatchSpec, ChildResult, Done, Group, Launcher, Plan};
use std::path::Path;

fn spec(out: &Path, repeats: u32) -> BatchSpec {
    BatchSpec {
        scenes: vec!["scene.toml".into()],
        engines: vec!["fake".into()],
        repeats,
        out: out.to_path_buf(),
        robot: None,
        packages: vec![],
        jobs: Some(2),
        seed: 0,
        perturb: vec![],
        set: vec![],
        timeout_s: Some(30.0),
        params: None,
        stitch: None,
        allow_unstable: false,
    }
}

fn group(dir: &Path, name: &str, pending: Vec<u32>) -> Group {
    let store =
        RunStore::create_or_open(&dir.join(name), "fake", SourceKind::Simulated, Some(name))
            .unwrap();
    Group {
        scene_file: "scene.toml".into(),
        scene_name: name.into(),
        engine: "fake".into(),
        source: "fake".into(),
        store,
        pending,
        load_error: None,
        done: Done::default(),
        stitch: None,
    }
}

fn plan(dir: &Path, groups: Vec<Group>, repeats: u32, perturbation: Perturbation) -> Plan {
    Plan {
        spec: spec(dir, repeats),
        groups,
        jobs: 2,
        params_file: None,
        perturbation,
        randomization: None,
        executor: Default::default(),
    }
}

/// A child that ignores its job and answers with one fixed run.
fn answering(result: &ChildResult) -> Launcher {
    let text = serde_json::to_string(result).unwrap();
    Launcher {
        program: Some("sh".into()),
        args: vec!["-c".into(), format!("cat >/dev/null; printf '%s' '{text}'")],
    }
}

fn result() -> ChildResult {
    let mut t = Trajectory::with_bodies(&["wrist"]);
    t.time_s = vec![0.0, 0.05, 0.1];
    t.bodies[0].poses = (0..3)
        .map(|i| {
            Some(Pose::new(
                Vec3::new(0.1 * i as f64, 0.2, 0.3),
                Quat::IDENTITY,
            ))
        })
        .collect();
    t.joint_angles_rad = Some(vec![vec![0.0]; 3]);
    t.joint_velocity_commands_rad_s = Some(vec![vec![0.5]; 3]);
    ChildResult::from_outcome(&RunOutcome {
        trajectory: t,
        status: RunStatus::Completed,
        engine_steps: 30,
        wall_time_s: 0.01,
    })
}

#[test]
fn deterministic_repeats_after_two_identical_ones_are_copies() {
    let tmp = tempfile::tempdir().unwrap();
    let mut p = plan(
        tmp.path(),
        vec![group(tmp.path(), "a", (0..5).collect())],
        5,
        Perturbation::default(),
    );
    let stats = p.execute(&answering(&result()), &()).unwrap();
    assert_eq!(
        (stats.simulated, stats.failures, stats.steps_total),
        (2, 0, 60)
    );
    let g = &p.groups[0];
    assert_eq!(
        g.done,
        Done {
            ok: 5,
            diverged: 0,
            unstable: 0,
            failed: 0
        }
    );
    let store = RunStore::open(g.store.dir()).unwrap();
    assert_eq!(store.runs().len(), 5);
    for r in 2..5 {
        let e = store.run(&format!("run00{r}")).unwrap();
        assert_eq!(e.extra["copy_of"], "run000");
        assert_eq!(store.read_run(&e.id).unwrap().len(), 3);
    }
    assert!(identical_runs(&store, 0, 1).is_some());
    let dir = g.store.dir().to_path_buf();
    p.record_batch(&stats, 1.5).unwrap();
    let m = RunStore::open(&dir).unwrap();
    assert_eq!(m.manifest().settings["last_batch"]["runs"], 5);
}

#[test]
fn perturbed_repeats_are_all_simulated_with_their_seeds() {
    let tmp = tempfile::tempdir().unwrap();
    let mut perturbation = Perturbation::default();
    perturbation.parse_into("initial_offset_deg=1").unwrap();
    let mut p = plan(
        tmp.path(),
        vec![group(tmp.path(), "a", vec![0, 1, 2])],
        3,
        perturbation,
    );
    let stats = p.execute(&answering(&result()), &()).unwrap();
    assert_eq!(stats.simulated, 3);
    let store = RunStore::open(p.groups[0].store.dir()).unwrap();
    assert!(store
        .runs()
        .iter()
        .all(|e| e.seed.is_some() && !e.extra.contains_key("copy_of")));
}

#[test]
fn failures_are_recorded_and_divergence_is_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let failing = Launcher {
        program: Some("sh".into()),
        args: vec![
            "-c".into(),
            "cat >/dev/null; echo 'error: boom' >&2; exit 2".into(),
        ],
    };
    let mut p = plan(
        tmp.path(),
        vec![group(tmp.path(), "a", vec![0, 1, 2])],
        3,
        Perturbation::default(),
    );
    let stats = p.execute(&failing, &()).unwrap();
    // Two failed simulations prove nothing: the third is simulated too.
    assert_eq!((stats.simulated, stats.failures), (3, 3));
    let store = RunStore::open(p.groups[0].store.dir()).unwrap();
    let e = store.run("run000").unwrap();
    assert_eq!(e.status, StoreStatus::Failed);
    assert_eq!(e.message.as_deref(), Some("exited with code 2: boom"));
    assert!(!store.has_finished_run("run000"));

    let mut diverged = result();
    diverged.diverged = Some((0.1, "NaN".into()));
    let mut p = plan(
        tmp.path(),
        vec![group(tmp.path(), "b", vec![0])],
        1,
        Perturbation::default(),
    );
    p.execute(&answering(&diverged), &()).unwrap();
    assert_eq!(p.groups[0].done.diverged, 1);
    let store = RunStore::open(p.groups[0].store.dir()).unwrap();
    let e = store.run("run000").unwrap();
    assert_eq!(e.message.as_deref(), Some("diverged at t = 0.1000 s: NaN"));
}

#[test]
fn split_for_copies_holds_back_all_but_two_and_skips_models_that_failed() {
    let tmp = tempfile::tempdir().unwrap();
    let mut broken = group(tmp.path(), "b", vec![0, 1]);
    broken.load_error = Some("no".into());
    let groups = vec![group(tmp.path(), "a", vec![1, 3, 4, 5]), broken];
    let (first, deferred) = split_for_copies(&groups, true);
    assert_eq!(first, [(0, 1), (0, 3)]);
    assert_eq!(deferred, [(0, vec![4, 5])]);
    let (first, deferred) = split_for_copies(&groups, false);
    assert_eq!(first.len(), 4);
    assert!(deferred.is_empty());
    let p = plan(tmp.path(), groups, 6, Perturbation::default());
    assert_eq!((p.total(), p.skipped()), (4, 2 + 4));
}
