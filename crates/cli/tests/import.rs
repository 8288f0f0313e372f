//! End-to-end tests of `realitygap import` on the study's recordings and
//! on damaged files.

use realitygap_data::{read_run_csv, RunStatus, RunStore, SourceKind};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn realitygap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("import-tests")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn paper_data() -> Option<PathBuf> {
    realitygap::paper_data_for_tests()
}

#[test]
fn imports_real_captures() {
    let Some(data) = paper_data() else { return };
    let out = scratch("qualisys").join("real-scene3");
    let files: Vec<String> = ["CubeExp0001_6D.tsv", "CubeExp0002_6D.tsv"]
        .iter()
        .map(|f| {
            data.join("MotionCapture/Experiment3")
                .join(f)
                .display()
                .to_string()
        })
        .collect();
    let mut args = vec!["import", "qualisys"];
    args.extend(files.iter().map(String::as_str));
    args.extend([
        "--scene",
        "scene3_cube_push",
        "--out",
        out.to_str().unwrap(),
    ]);
    let o = realitygap(&args);
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        text(&o.stdout),
        text(&o.stderr)
    );
    let stdout = text(&o.stdout);
    assert!(stdout.contains("CubeExp0001_6D: 2000 samples"), "{stdout}");
    assert!(stdout.contains("imported 2 of 2 files"), "{stdout}");

    let store = RunStore::open(&out).unwrap();
    let m = store.manifest();
    assert_eq!(
        (m.source.as_str(), m.kind, m.scene.as_deref()),
        ("real", SourceKind::Real, Some("scene3_cube_push"))
    );
    assert_eq!(store.runs().len(), 2);
    assert_eq!(store.runs()[0].status, RunStatus::Ok);
    assert_eq!(store.runs()[0].extra["gaps"], 0);
    assert_eq!(store.runs()[0].extra["bodies"]["wrist"], "RB1(Orange)");
    let t = store.read_run("CubeExp0001_6D").unwrap();
    assert_eq!(t.len(), 2000);
    let roles: Vec<&str> = t.bodies.iter().map(|b| b.role.as_str()).collect();
    assert_eq!(roles, ["base", "wrist", "cube"]);
    // The CSV itself is plain: a header and 2000 rows.
    let csv = std::fs::read_to_string(out.join("runs/CubeExp0001_6D.csv")).unwrap();
    assert!(csv.starts_with("t_s,base_x_m,"));
    assert_eq!(csv.lines().count(), 2001);
    assert_eq!(
        read_run_csv(&out.join("runs/CubeExp0001_6D.csv")).unwrap(),
        t
    );

    // Importing again replaces the runs; another scene in the same
    // directory is refused.
    let o = realitygap(&args);
    assert!(o.status.success());
    assert!(text(&o.stdout).contains("(replaced)"));
    assert_eq!(RunStore::open(&out).unwrap().runs().len(), 2);
    let mut other = args.clone();
    let scene_at = other.iter().position(|a| *a == "scene3_cube_push").unwrap();
    other[scene_at] = "scene1_single_joint";
    let o = realitygap(&other);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("scene 'scene3_cube_push'"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn imports_recorded_simulators_and_reports_zero_rows() {
    let Some(data) = paper_data() else { return };
    let out = scratch("recorded").join("vrep-bullet283-scene2");
    let exp = data.join("Simulation/Experiment2");
    let f4 = exp.join("Double_VRepBullet283_4.csv").display().to_string();
    let f5 = exp.join("Double_VRepBullet283_5.csv").display().to_string();
    let o = realitygap(&[
        "import",
        "recorded",
        &f4,
        &f5,
        "--source",
        "VRepBullet283",
        "--quat-order",
        "xyzw",
        "--scene",
        "scene2_two_joints",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(
        stdout.contains("Double_VRepBullet283_5: 400 samples"),
        "{stdout}"
    );
    assert!(stdout.contains("31 rows are all zero"), "{stdout}");
    let store = RunStore::open(&out).unwrap();
    assert_eq!(store.manifest().kind, SourceKind::Recorded);
    assert_eq!(store.manifest().settings["quat_order"], "xyzw");
    let run5 = store.run("Double_VRepBullet283_5").unwrap();
    assert_eq!(run5.extra["zero_rows"], 31);
    assert!(run5.message.as_deref().unwrap().contains("all zero"));
    assert!(store
        .run("Double_VRepBullet283_4")
        .unwrap()
        .extra
        .get("zero_rows")
        .is_none());
    assert_eq!(store.read_run("Double_VRepBullet283_4").unwrap().len(), 400);
}

#[test]
fn garbage_file_fails_naming_file_and_line() {
    let dir = scratch("garbage");
    let good = dir.join("good.csv");
    let row = "0.1 0.2 0.8 1 0 0 0 0.5 0 0.0375 1 0 0 0\n";
    std::fs::write(&good, row.repeat(3)).unwrap();
    let bad = dir.join("bad.csv");
    std::fs::write(
        &bad,
        format!("{row}0.1 0.2 oops 1 0 0 0 0.5 0 0.0375 1 0 0 0\n"),
    )
    .unwrap();
    let out = dir.join("out");
    let o = realitygap(&[
        "import",
        "recorded",
        good.to_str().unwrap(),
        bad.to_str().unwrap(),
        "--source",
        "x",
        "--quat-order",
        "wxyz",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let stderr = text(&o.stderr);
    assert!(
        stderr.contains(&format!(
            "{}:2: column 3 (wrist z): expected a number, found \"oops\"",
            bad.display()
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("1 of 2 files could not be imported"),
        "{stderr}"
    );
    // The good file was still imported.
    assert_eq!(RunStore::open(&out).unwrap().runs().len(), 1);

    // A Qualisys file of garbage, and a missing file.
    let tsv = dir.join("noise.tsv");
    std::fs::write(&tsv, b"1\t0.0\t\xff\xfe garbage\n").unwrap();
    let o = realitygap(&[
        "import",
        "qualisys",
        tsv.to_str().unwrap(),
        "--scene",
        "s",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let stderr = text(&o.stderr);
    assert!(
        stderr.contains("source 'x'"),
        "the directory holds another source: {stderr}"
    );
    let out2 = dir.join("out2");
    let o = realitygap(&[
        "import",
        "qualisys",
        tsv.to_str().unwrap(),
        "--scene",
        "s",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains(&format!("{}:1: expected 53", tsv.display())),
        "{}",
        text(&o.stderr)
    );
    // No file could be read: no results directory is left behind.
    assert!(!out2.exists(), "{} was made", out2.display());
    let missing = dir.join("missing.tsv");
    let o = realitygap(&[
        "import",
        "qualisys",
        missing.to_str().unwrap(),
        "--scene",
        "s",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("missing.tsv: cannot read the file"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn bad_arguments_are_refused() {
    let dir = scratch("args");
    let f = dir.join("a.csv");
    std::fs::write(&f, "0 0 1 1 0 0 0 0.5 0 0.0375 1 0 0 0\n").unwrap();
    let out = dir.join("out");
    let o = realitygap(&[
        "import",
        "recorded",
        f.to_str().unwrap(),
        "--source",
        "x",
        "--quat-order",
        "wxz",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("wxyz"), "{}", text(&o.stderr));
    let o = realitygap(&[
        "import",
        "qualisys",
        f.to_str().unwrap(),
        "--scene",
        "s",
        "--role",
        "wrist",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("NAME=ROLE"), "{}", text(&o.stderr));
    // Two files that would be the same run.
    let sub = dir.join("sub");
    std::fs::create_dir_all(&sub).unwrap();
    let g = sub.join("a.csv");
    std::fs::copy(&f, &g).unwrap();
    let o = realitygap(&[
        "import",
        "recorded",
        f.to_str().unwrap(),
        g.to_str().unwrap(),
        "--source",
        "x",
        "--quat-order",
        "wxyz",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("would both be run 'a'"),
        "{}",
        text(&o.stderr)
    );
}

/// `import qualisys --ik`: scene 1's twenty captures solved in joint space
/// (the registration fitted on the first fifteen), the angles stored with
/// the poses, the residual printed and kept per run; bad requests refused
/// before anything is imported.
#[test]
fn imports_real_captures_in_joint_space() {
    let Some(data) = paper_data() else { return };
    let dir = scratch("qualisys-ik");
    let out = dir.join("real-scene1");
    let files: Vec<String> = (1..=20)
        .map(|i| {
            data.join(format!("MotionCapture/Experiment1/Single{i:04}_6D.tsv"))
                .display()
                .to_string()
        })
        .collect();
    let mut args = vec!["import", "qualisys"];
    args.extend(files.iter().map(String::as_str));
    args.extend([
        "--scene",
        "scene1_single_joint",
        "--ik",
        "--out",
        out.to_str().unwrap(),
    ]);
    let o = realitygap(&args);
    let stdout = text(&o.stdout);
    assert!(o.status.success(), "{stdout}{}", text(&o.stderr));
    assert!(
        stdout.contains("registration fitted on 15 runs") && stdout.contains("other runs:"),
        "{stdout}"
    );
    let store = RunStore::open(&out).unwrap();
    let ik = &store.manifest().settings["ik"];
    assert_eq!(ik["training_runs"].as_array().unwrap().len(), 15);
    assert!(ik["fit_position_rms_mm"].as_f64().unwrap() < 1.0, "{ik}");
    for run in store.runs() {
        let residual = run.extra["ik"]["position_rms_mm"].as_f64().unwrap();
        assert!(residual < 1.0, "{}: {residual} mm", run.id);
        let t = store.read_run(&run.id).unwrap();
        let q = t.joint_angles_rad.as_ref().expect("joint angles stored");
        assert_eq!(q.len(), t.len());
        assert_eq!(q[0].len(), 6);
        // Joint 2 ends near its -100 degree target.
        let last = q.last().unwrap()[1].to_degrees();
        assert!(
            (last + 100.0).abs() < 3.0,
            "{}: joint 2 ends at {last}",
            run.id
        );
    }
    // A scene that is no file and no scene of the assets, and the IK's
    // options without --ik, are refused before anything is imported.
    let bad = dir.join("bad");
    let mut a = vec!["import", "qualisys", files[0].as_str()];
    a.extend([
        "--scene",
        "no_such_scene",
        "--ik",
        "--out",
        bad.to_str().unwrap(),
    ]);
    let o = realitygap(&a);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("--scene no_such_scene"),
        "{}",
        text(&o.stderr)
    );
    assert!(!bad.exists(), "nothing imported");
    let mut a = vec!["import", "qualisys", files[0].as_str()];
    a.extend([
        "--scene",
        "scene1_single_joint",
        "--robot",
        "official",
        "--out",
        bad.to_str().unwrap(),
    ]);
    let o = realitygap(&a);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("--ik"), "{}", text(&o.stderr));
}
