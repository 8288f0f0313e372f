use super::*;
use proptest::prelude::*;
use realitygap_core::{Pose, Quat, Vec3};

fn sample_trajectory() -> Trajectory {
    let mut t = Trajectory::with_bodies(&["wrist", "cube"]);
    t.time_s = vec![0.0, 0.05, 0.1, 0.15000000000000002];
    t.bodies[0].poses = vec![
        Some(Pose::new(
            Vec3::new(0.0670618953, 0.8718789057, -0.0),
            Quat::IDENTITY,
        )),
        None,
        Some(Pose::new(
            Vec3::new(1e17, -1.5e-19, f64::INFINITY),
            Quat::new(0.5, -0.5, 0.5, 0.5),
        )),
        Some(Pose::new(
            Vec3::new(1.0 / 3.0, 2e-5, 9_999_999_999_999_998.0),
            Quat::new(0.0, 1.0, 0.0, 0.0),
        )),
    ];
    t.bodies[1].poses = vec![
        Some(Pose::new(Vec3::new(0.5, 0.0, 0.0375), Quat::IDENTITY)),
        Some(Pose::new(
            Vec3::new(0.5, 2.07310114618026e-19, 0.0417051962),
            Quat::new(1.0, 2.39e-18, 0.0, 0.0),
        )),
        None,
        Some(Pose::new(
            Vec3::new(f64::NEG_INFINITY, 5e-324, f64::MAX),
            Quat::IDENTITY,
        )),
    ];
    t.joint_angles_rad = Some(vec![vec![0.0, -1.5, 3.0]; 4]);
    t.joint_velocity_commands_rad_s = Some(vec![vec![0.1, -0.5235987755982988, 0.0]; 4]);
    t
}

fn parse_text(s: &str) -> Result<Trajectory, ImportError> {
    parse_run_csv(s.as_bytes(), Path::new("runs/r.csv"))
}

#[test]
fn csv_round_trip_is_exact() {
    let t = sample_trajectory();
    let text = format_run_csv(&t).unwrap();
    let header = text.lines().next().unwrap();
    assert_eq!(
        header,
        "t_s,wrist_x_m,wrist_y_m,wrist_z_m,wrist_qw,wrist_qx,wrist_qy,wrist_qz,\
         cube_x_m,cube_y_m,cube_z_m,cube_qw,cube_qx,cube_qy,cube_qz,q1_rad,q2_rad,q3_rad,\
         qd_cmd1_rad_s,qd_cmd2_rad_s,qd_cmd3_rad_s"
    );
    assert!(
        text.lines()
            .nth(2)
            .unwrap()
            .starts_with("0.05,,,,,,,,0.5,2.07310114618026e-19,"),
        "{text}"
    );
    assert!(text.contains("1e17") && text.contains("inf") && text.contains("-inf"));
    let back = parse_text(&text).unwrap();
    assert_eq!(back, t);
    // Without joints: the columns are absent and read back as None.
    let mut t2 = t.clone();
    t2.joint_angles_rad = None;
    t2.joint_velocity_commands_rad_s = None;
    assert_eq!(parse_text(&format_run_csv(&t2).unwrap()).unwrap(), t2);
    // CRLF (after a spreadsheet) reads the same.
    assert_eq!(parse_text(&text.replace('\n', "\r\n")).unwrap(), t);
}

#[test]
fn nan_round_trips() {
    let mut t = Trajectory::with_bodies(&["wrist"]);
    t.time_s = vec![0.0];
    t.bodies[0].poses = vec![Some(Pose::new(
        Vec3::new(f64::NAN, 1.0, 2.0),
        Quat::IDENTITY,
    ))];
    let text = format_run_csv(&t).unwrap();
    assert!(text.contains("NaN"));
    let back = parse_text(&text).unwrap();
    assert!(back.bodies[0].poses[0].unwrap().position_m.x.is_nan());
    assert_eq!(format_run_csv(&back).unwrap(), text);
}

#[test]
fn unwritable_trajectories() {
    let mut t = Trajectory::with_bodies(&["a,b"]);
    t.time_s = vec![0.0];
    t.bodies[0].poses = vec![None];
    assert!(format_run_csv(&t).is_err());
    t.bodies[0].role = "ok".into();
    t.time_s = vec![f64::NAN];
    assert!(format_run_csv(&t).is_err());
    t.time_s = vec![0.0, 1.0];
    assert!(format_run_csv(&t).is_err(), "length mismatch");
}

#[test]
fn csv_errors_name_line_and_column() {
    let good = format_run_csv(&sample_trajectory()).unwrap();
    assert!(parse_text("").unwrap_err().message.contains("empty"));
    let e = parse_text("time,wrist_x_m\n").unwrap_err();
    assert_eq!((e.line, e.column), (Some(1), Some(1)));
    let e = parse_text("t_s,wrist_x_m,wrist_y_m,wrist_z_m,wrist_qw,wrist_qx,wrist_qz,wrist_qy\n")
        .unwrap_err();
    assert_eq!(e.column, Some(7), "{e}");
    let e = parse_text("t_s,wrist_x_m,wrist_y_m\n").unwrap_err();
    assert!(e.message.contains("ends before"), "{e}");
    let e = parse_text("t_s,q2_rad\n").unwrap_err();
    assert!(e.message.contains("unexpected column name"), "{e}");
    // A garbage cell.
    let bad = good.replacen("0.0375", "0.03x75", 1);
    let e = parse_text(&bad).unwrap_err();
    assert_eq!(
        (e.line, e.column, e.field.as_deref()),
        (Some(2), Some(11), Some("cube_z_m")),
        "{e}"
    );
    // A partial pose.
    let bad = good.replacen(",0.5,0,0.0375,", ",0.5,,0.0375,", 1);
    let e = parse_text(&bad).unwrap_err();
    assert!(e.message.contains("all seven"), "{e}");
    assert_eq!(e.field.as_deref(), Some("cube_y_m"));
    // A row too short.
    let e = parse_text("t_s,q1_rad\n0,1\n0.1\n").unwrap_err();
    assert_eq!(e.line, Some(3));
    // Time going backwards.
    let e = parse_text("t_s,q1_rad\n0.1,1\n0.0,1\n").unwrap_err();
    assert_eq!((e.line, e.column), (Some(3), Some(1)));
    // Empty joint cell.
    let e = parse_text("t_s,q1_rad\n0.1,\n").unwrap_err();
    assert_eq!(e.field.as_deref(), Some("q1_rad"));
    // A header only: an empty trajectory.
    assert_eq!(parse_text("t_s,q1_rad\n").unwrap().len(), 0);
    // Quoted header names (as some tools write them).
    assert_eq!(
        parse_text("\"t_s\",\"q1_rad\"\n0,1\n")
            .unwrap()
            .joint_angles_rad,
        Some(vec![vec![1.0]])
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// Any finite or non-finite value, any gap pattern: written then read
    /// back bit for bit (NaN payloads aside).
    #[test]
    fn any_values_round_trip(
        values in prop::collection::vec((any::<f64>(), any::<f64>(), any::<f64>(), any::<bool>()), 1..20),
        t0 in 0.0f64..1e6,
    ) {
        let mut t = Trajectory::with_bodies(&["wrist"]);
        let mut time = t0;
        for (x, y, q, gap) in &values {
            t.time_s.push(time);
            time += 0.05;
            t.bodies[0].poses.push(if *gap { None } else {
                Some(Pose::new(Vec3::new(*x, *y, -*x), Quat::new(*q, *y, 0.0, -0.0)))
            });
        }
        t.joint_angles_rad = Some(values.iter().map(|v| vec![v.0, v.2]).collect());
        let text = format_run_csv(&t).unwrap();
        let back = parse_text(&text).unwrap();
        prop_assert_eq!(format_run_csv(&back).unwrap(), text.clone());
        let bits = |t: &Trajectory| -> Vec<u64> {
            t.bodies[0].poses.iter().flatten().flat_map(|p| {
                [p.position_m.x, p.position_m.y, p.position_m.z, p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z]
            }).chain(t.time_s.iter().copied()).chain(t.joint_angles_rad.iter().flatten().flatten().copied())
              .map(|v| if v.is_nan() { 1 } else { v.to_bits() }).collect()
        };
        prop_assert_eq!(bits(&back), bits(&t));
    }
}

// ---- The store ----------------------------------------------------------------

#[test]
fn store_writes_reopens_and_reads_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("results/mujoco-scene1");
    let mut store =
        RunStore::create_or_open(&dir, "mujoco", SourceKind::Simulated, Some("scene1")).unwrap();
    store
        .set_engine(EngineInfo {
            name: "mujoco".into(),
            version: "3.1.6".into(),
        })
        .unwrap();
    store
        .set_settings(serde_json::json!({"timestep_s": 1e-4}))
        .unwrap();
    assert!(!store.has_finished_run("r0"));
    let t = sample_trajectory();
    let mut entry = RunEntry::new("r0");
    entry.seed = Some(7);
    entry.wall_time_s = Some(1.25);
    entry.extra.insert("gaps".into(), serde_json::json!(2));
    store.write_run(entry, &t).unwrap();
    assert!(store.has_finished_run("r0"));
    let mut failed = RunEntry::new("r1");
    failed.message = Some("the engine crashed".into());
    store.record_failed_run(failed).unwrap();
    assert!(!store.has_finished_run("r1"));

    let reopened = RunStore::open(&dir).unwrap();
    assert_eq!(reopened.manifest(), store.manifest());
    assert_eq!(reopened.runs().len(), 2);
    assert_eq!(reopened.runs()[0].file, "runs/r0.csv");
    assert_eq!(reopened.runs()[1].status, RunStatus::Failed);
    assert_eq!(reopened.read_run("r0").unwrap(), t);
    assert!(matches!(
        reopened.read_run("r1"),
        Err(StoreError::NoTrajectory { .. })
    ));
    assert!(matches!(
        reopened.read_run("nope"),
        Err(StoreError::UnknownRun { .. })
    ));
    assert!(reopened.has_finished_run("r0"));
    assert_eq!(
        reopened.manifest().engine.as_ref().unwrap().version,
        "3.1.6"
    );

    // The JSON is what a person expects.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(MANIFEST_FILE)).unwrap()).unwrap();
    assert_eq!(json["kind"], "simulated");
    assert_eq!(json["scene"], "scene1");
    assert_eq!(json["runs"][0]["status"], "ok");
    assert_eq!(json["runs"][0]["seed"], 7);
    assert_eq!(json["runs"][1]["status"], "failed");
    assert_eq!(json["tool_version"], realitygap_core::TOOL_VERSION);

    // No temporary files left behind.
    for d in [dir.clone(), dir.join(RUNS_DIR)] {
        for e in std::fs::read_dir(&d).unwrap() {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            assert!(!name.starts_with('.'), "left over: {name}");
        }
    }

    // Rewriting a run replaces its entry; a failure after success removes
    // the stale CSV.
    let mut store =
        RunStore::create_or_open(&dir, "mujoco", SourceKind::Simulated, Some("scene1")).unwrap();
    let mut entry = RunEntry::new("r1");
    entry.status = RunStatus::Diverged;
    store.write_run(entry, &t).unwrap();
    assert_eq!(store.runs().len(), 2);
    assert!(store.has_finished_run("r1"));
    store.record_failed_run(RunEntry::new("r0")).unwrap();
    assert!(!dir.join("runs/r0.csv").exists());
    assert_eq!(RunStore::open(&dir).unwrap().runs().len(), 2);
}

#[test]
fn store_refuses_another_source_or_scene() {
    let tmp = tempfile::tempdir().unwrap();
    RunStore::create_or_open(tmp.path(), "real", SourceKind::Real, Some("scene3")).unwrap();
    let e =
        RunStore::create_or_open(tmp.path(), "real", SourceKind::Real, Some("scene1")).unwrap_err();
    assert!(
        e.to_string().contains("scene 'scene3'") && e.to_string().contains("scene 'scene1'"),
        "{e}"
    );
    assert!(
        RunStore::create_or_open(tmp.path(), "mujoco", SourceKind::Simulated, Some("scene3"))
            .is_err()
    );
    assert!(RunStore::create_or_open(tmp.path(), "real", SourceKind::Real, Some("scene3")).is_ok());
}

#[test]
fn bad_manifest_names_file_line_column() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(
        tmp.path().join(MANIFEST_FILE),
        "{\n  \"tool_version\": \"0.1.0\",\n  \"source\": 3\n}\n",
    )
    .unwrap();
    let e = RunStore::open(tmp.path()).unwrap_err();
    match &e {
        StoreError::Manifest { path, line, .. } => {
            assert!(path.ends_with(MANIFEST_FILE));
            assert_eq!(*line, 3);
        }
        other => panic!("{other:?}"),
    }
    assert!(e.to_string().contains("manifest.json:3:"), "{e}");
    std::fs::write(tmp.path().join(MANIFEST_FILE), "not json").unwrap();
    assert!(RunStore::open(tmp.path())
        .unwrap_err()
        .to_string()
        .contains(":1:"));
    let e = RunStore::open(&tmp.path().join("missing")).unwrap_err();
    assert!(e.to_string().starts_with("cannot read"), "{e}");
}

#[test]
fn manifest_paths_cannot_escape_the_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let mut store = RunStore::create_or_open(tmp.path(), "x", SourceKind::Recorded, None).unwrap();
    store
        .write_run(RunEntry::new("a"), &sample_trajectory())
        .unwrap();
    let path = tmp.path().join(MANIFEST_FILE);
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("runs/a.csv", "../../etc/passwd");
    std::fs::write(&path, text).unwrap();
    let store = RunStore::open(tmp.path()).unwrap();
    assert!(matches!(
        store.read_run("a"),
        Err(StoreError::NoTrajectory { .. })
    ));
}

#[test]
fn run_ids_are_checked_and_sanitised() {
    for ok in ["Single0001_6D", "CubeExp_VRepODE_3", "a.b-c+d=e@f"] {
        assert!(validate_run_id(ok).is_ok(), "{ok}");
    }
    for bad in ["", ".hidden", "a/b", "a\\b", "..", "a b", "é"] {
        assert!(validate_run_id(bad).is_err(), "{bad}");
    }
    assert_eq!(sanitize_run_id("run 1/é"), "run_1__");
    assert_eq!(sanitize_run_id("..."), "run");
    assert!(validate_run_id(&sanitize_run_id(&"x".repeat(500))).is_ok());
    let tmp = tempfile::tempdir().unwrap();
    let mut store = RunStore::create_or_open(tmp.path(), "x", SourceKind::Recorded, None).unwrap();
    assert!(matches!(
        store.write_run(RunEntry::new("../x"), &sample_trajectory()),
        Err(StoreError::InvalidRunId { .. })
    ));
}

#[test]
fn discover_finds_results_directories() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    for d in ["a", "b/c", "b/d/e", "f/g/h/i", ".hidden/x"] {
        RunStore::create_or_open(&root.join(d), "s", SourceKind::Real, None).unwrap();
    }
    std::fs::create_dir_all(root.join("empty/dir")).unwrap();
    let found: Vec<String> = discover(root)
        .iter()
        .map(|p| {
            p.strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect();
    assert_eq!(
        found,
        vec!["a", "b/c", "b/d/e"],
        "depth 4 and hidden are not searched"
    );
    assert_eq!(discover(&root.join("a")), vec![root.join("a")]);
    assert!(discover(&root.join("missing")).is_empty());
}

#[test]
fn store_keeps_velocities_beside_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("real");
    let mut store = RunStore::create_or_open(&dir, "real", SourceKind::Real, None).unwrap();
    let t = sample_trajectory();
    let twist = |a: f64| {
        Some(BodyTwist {
            linear_m_s: Vec3::new(a, -1.0, 1.0 / 3.0),
            angular_body_rad_s: Vec3::new(0.5, a, -2e-9),
        })
    };
    let cube = VelocityTrack {
        role: "cube".into(),
        twists: vec![twist(1.0), twist(2.0), None, twist(-4.0)],
    };
    store
        .write_run_with_velocities(RunEntry::new("7"), &t, std::slice::from_ref(&cube))
        .unwrap();
    assert_eq!(
        store.run("7").unwrap().velocities_file.as_deref(),
        Some("runs/7.velocities.csv")
    );
    // The run CSV is the one write_run writes: every reader reads it as before.
    assert_eq!(
        std::fs::read_to_string(dir.join("runs/7.csv")).unwrap(),
        format_run_csv(&t).unwrap()
    );
    let reopened = RunStore::open(&dir).unwrap();
    assert_eq!(reopened.read_run("7").unwrap(), t);
    assert_eq!(
        reopened.read_run_velocities("7").unwrap(),
        vec![cube.clone()]
    );

    // Velocities that do not fit the trajectory are refused, naming the run.
    let mut short = cube.clone();
    short.twists.pop();
    let e = store
        .write_run_with_velocities(RunEntry::new("8"), &t, &[short])
        .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("run '8': velocities of body 'cube' have 3 samples"),
        "{e}"
    );
    let ghost = VelocityTrack {
        role: "ball".into(),
        ..cube.clone()
    };
    let e = store
        .write_run_with_velocities(RunEntry::new("8"), &t, &[ghost])
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("'ball', which the trajectory does not track"),
        "{e}"
    );
    assert!(store.run("8").is_none());

    // A velocities file whose times are not the run's is a located error.
    let path = dir.join("runs/7.velocities.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("\n0.05,", "\n0.06,", 1)).unwrap();
    let e = reopened.read_run_velocities("7").unwrap_err().to_string();
    assert!(
        e.ends_with(
            "7.velocities.csv:3: column 1 (t_s): time 0.06 s, but the run's sample 1 is at 0.05 s"
        ),
        "{e}"
    );

    // Rewritten without velocities, or failed: no stale file.
    store
        .write_run_with_velocities(RunEntry::new("7"), &t, std::slice::from_ref(&cube))
        .unwrap();
    store.write_run(RunEntry::new("7"), &t).unwrap();
    assert!(!path.exists());
    assert_eq!(store.read_run_velocities("7").unwrap(), vec![]);
    store
        .write_run_with_velocities(RunEntry::new("7"), &t, std::slice::from_ref(&cube))
        .unwrap();
    store.record_failed_run(RunEntry::new("7")).unwrap();
    assert!(!path.exists());
}
