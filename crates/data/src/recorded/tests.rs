use super::*;
use crate::paper_data;
use std::path::PathBuf;

const ROW: [&str; 14] = [
    "0.1", "0.2", "0.8", "1.0", "0.0", "0.0", "0.0", "0.5", "0.0", "0.0375", "0.0", "0.0", "0.0",
    "1.0",
];

fn parse_str(s: &str, order: QuatOrder) -> Result<ImportedRun, ImportError> {
    parse(
        s.as_bytes(),
        Path::new("sim.csv"),
        &RecordedOptions::new(order),
    )
}

fn rows(sep: &str, eol: &str, n: usize) -> String {
    (0..n).map(|_| ROW.join(sep) + eol).collect()
}

#[test]
fn separators_and_line_ends_agree() {
    let reference = parse_str(&rows(" ", "\r\n", 3), QuatOrder::Wxyz).unwrap();
    assert!(reference.warnings.is_empty(), "{:?}", reference.warnings);
    for (sep, eol) in [
        (",", "\n"),
        ("\t", "\r\n"),
        ("  ", "\n"),
        (", ", "\n"),
        (" \t ", "\n"),
        (",", ",\r\n"),
    ] {
        let run = parse_str(&rows(sep, eol, 3), QuatOrder::Wxyz)
            .unwrap_or_else(|e| panic!("{sep:?} {eol:?}: {e}"));
        assert_eq!(run.trajectory, reference.trajectory, "{sep:?} {eol:?}");
    }
    // No final line end.
    let s = rows(" ", "\n", 3);
    assert_eq!(
        parse_str(s.trim_end(), QuatOrder::Wxyz).unwrap().trajectory,
        reference.trajectory
    );
    let t = &reference.trajectory;
    assert_eq!(t.time_s, vec![0.0, 0.05, 0.1]);
    assert_eq!(reference.frequency_hz, 20.0);
    let w = t.body("wrist").unwrap().poses[1].unwrap();
    assert_eq!(w.position_m, Vec3::new(0.1, 0.2, 0.8));
    assert_eq!(w.orientation, Quat::IDENTITY);
    assert_eq!(
        t.body("cube").unwrap().poses[2].unwrap().position_m,
        Vec3::new(0.5, 0.0, 0.0375)
    );
}

#[test]
fn quaternion_orders() {
    // Wxyz reads "1 0 0 0" as identity and "0 0 0 1" as z by pi.
    let run = parse_str(&rows(" ", "\n", 1), QuatOrder::Wxyz).unwrap();
    assert_eq!(
        run.trajectory.bodies[0].poses[0].unwrap().orientation,
        Quat::IDENTITY
    );
    assert_eq!(
        run.trajectory.bodies[1].poses[0].unwrap().orientation,
        Quat::new(0.0, 0.0, 0.0, 1.0)
    );
    let run = parse_str(&rows(" ", "\n", 1), QuatOrder::Xyzw).unwrap();
    assert_eq!(
        run.trajectory.bodies[0].poses[0].unwrap().orientation,
        Quat::new(0.0, 1.0, 0.0, 0.0)
    );
    assert_eq!(
        run.trajectory.bodies[1].poses[0].unwrap().orientation,
        Quat::IDENTITY
    );
    let q = QuatOrder::Xyzw.quat(&[0.1, 0.2, 0.3, 0.9]);
    assert_eq!(q, Quat::new(0.9, 0.1, 0.2, 0.3));
    assert_eq!("XYZW".parse::<QuatOrder>(), Ok(QuatOrder::Xyzw));
    assert_eq!(QuatOrder::Wxyz.to_string(), "wxyz");
    assert!("wxy".parse::<QuatOrder>().is_err());
}

#[test]
fn bad_norm_rows_are_flagged_and_normalised() {
    let mut bad = ROW;
    bad[3] = "2.0";
    let s = format!("{}\n{}\n{}\n", ROW.join(" "), bad.join(" "), ROW.join(" "));
    let run = parse_str(&s, QuatOrder::Wxyz).unwrap();
    assert_eq!(run.bad_norm_rows, vec![1]);
    assert!(run.zero_rows.is_empty());
    assert_eq!(
        run.trajectory.bodies[0].poses[1].unwrap().orientation,
        Quat::IDENTITY
    );
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("norm") && w.contains("samples 1")),
        "{:?}",
        run.warnings
    );
    // Within tolerance: not flagged.
    bad[3] = "1.0005";
    let s = format!("{}\n", bad.join(" "));
    assert!(parse_str(&s, QuatOrder::Wxyz)
        .unwrap()
        .bad_norm_rows
        .is_empty());
    // A zero quaternion in a non-zero row: identity, flagged.
    let mut zq = ROW;
    zq[3] = "0";
    let run = parse_str(&(zq.join(" ") + "\n"), QuatOrder::Wxyz).unwrap();
    assert_eq!(run.bad_norm_rows, vec![0]);
    assert_eq!(
        run.trajectory.bodies[0].poses[0].unwrap().orientation,
        Quat::IDENTITY
    );
}

#[test]
fn all_zero_rows_are_kept_and_listed() {
    let zero = ["0.0"; 14].join(" ");
    let s = format!(
        "{}\n{zero}\n{zero}\n{}\n{zero}\n",
        ROW.join(" "),
        ROW.join(" ")
    );
    let run = parse_str(&s, QuatOrder::Xyzw).unwrap();
    assert_eq!(run.zero_rows, vec![1, 2, 4]);
    assert!(run.bad_norm_rows.is_empty());
    assert_eq!(run.trajectory.len(), 5);
    assert_eq!(run.trajectory.bodies[0].poses[1], Some(Pose::IDENTITY));
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("3 rows are all zero (samples 1-2, 4)")),
        "{:?}",
        run.warnings
    );
}

#[test]
fn wrong_number_of_numbers() {
    let thirteen = ROW[..13].join(" ");
    let s = format!("{}\r\n{thirteen}\r\n", ROW.join(" "));
    let e = parse(
        s.as_bytes(),
        Path::new("d/x.csv"),
        &RecordedOptions::new(QuatOrder::Xyzw),
    )
    .unwrap_err();
    assert_eq!((e.line, e.column), (Some(2), Some(14)));
    assert!(e.message.contains("after 13, before cube qw"), "{e}");
    assert!(
        e.to_string()
            .starts_with("d/x.csv:2: column 14: expected 14 numbers"),
        "{e}"
    );
    let s = format!("{} 7\n", ROW.join(" "));
    let e = parse_str(&s, QuatOrder::Wxyz).unwrap_err();
    assert_eq!((e.line, e.column), (Some(1), Some(15)));
    assert!(e.message.contains("has 15"), "{e}");
    // An empty cell between commas.
    let s = ROW.join(",").replacen(",0.8,", ",,", 1) + "\n";
    let e = parse_str(&s, QuatOrder::Wxyz).unwrap_err();
    assert_eq!(
        (e.column, e.field.as_deref()),
        (Some(3), Some("wrist z")),
        "{e}"
    );
}

#[test]
fn garbage_cell_names_field() {
    let mut bad = ROW;
    bad[10] = "1.0.0";
    let s = format!("{}\n{}\n", ROW.join(" "), bad.join(" "));
    let e = parse_str(&s, QuatOrder::Xyzw).unwrap_err();
    assert_eq!(
        (e.line, e.column, e.field.as_deref()),
        (Some(2), Some(11), Some("cube qx"))
    );
    let e = parse_str(&s, QuatOrder::Wxyz).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("cube qw"));
    // A stray word in the data says which cell.
    let s = format!("{}\ngarbage\n", ROW.join(" "));
    let e = parse_str(&s, QuatOrder::Wxyz).unwrap_err();
    assert_eq!((e.line, e.column), (Some(2), Some(1)));
    assert!(e.message.contains("\"garbage\""), "{e}");
    // Non-UTF-8.
    let mut bytes = (ROW.join(" ") + "\n").into_bytes();
    bytes[1] = 0xff;
    let e = parse(
        &bytes,
        Path::new("x"),
        &RecordedOptions::new(QuatOrder::Wxyz),
    )
    .unwrap_err();
    assert_eq!(e.column, Some(1));
}

#[test]
fn non_finite_and_huge_values_are_kept() {
    let mut row = ROW;
    row[0] = "nan";
    row[1] = "inf";
    row[2] = "-inf";
    row[7] = "1e17";
    row[8] = "-1.5E+17";
    let mut row2 = ROW;
    row2[3] = "NaN";
    let s = format!(
        "{}\r\n{}\r\n{}\r\n",
        ROW.join(" "),
        row.join(" "),
        row2.join(" ")
    );
    let run = parse_str(&s, QuatOrder::Wxyz).unwrap();
    let w = run.trajectory.bodies[0].poses[1].unwrap().position_m;
    assert!(w.x.is_nan() && w.y == f64::INFINITY && w.z == f64::NEG_INFINITY);
    let c = run.trajectory.bodies[1].poses[1].unwrap().position_m;
    assert_eq!((c.x, c.y), (1e17, -1.5e17));
    assert_eq!(run.bad_norm_rows, vec![2]);
    assert!(
        run.trajectory.bodies[0].poses[2]
            .unwrap()
            .orientation
            .w
            .is_nan(),
        "kept as read"
    );
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("2 rows hold non-finite values")),
        "{:?}",
        run.warnings
    );
}

#[test]
fn headers_empty_files_and_cut_lines() {
    let s = format!(
        "End Effector\t\t\tCube\nPos:x\tPos:y\n{}",
        rows("\t", "\n", 2)
    );
    let run = parse_str(&s, QuatOrder::Xyzw).unwrap();
    assert_eq!(run.trajectory.len(), 2);
    assert!(
        run.warnings.iter().any(|w| w.contains("skipped 2 header")),
        "{:?}",
        run.warnings
    );
    assert!(parse_str("", QuatOrder::Wxyz)
        .unwrap_err()
        .message
        .contains("empty"));
    assert!(parse_str(" \r\n\t\n", QuatOrder::Wxyz)
        .unwrap_err()
        .message
        .contains("empty"));
    let e = parse_str("hello world\nfoo\n", QuatOrder::Wxyz).unwrap_err();
    assert!(e.message.contains("no data rows"), "{e}");
    // A last line cut in the middle: dropped with a warning.
    let full = rows(" ", "\n", 3);
    for cut in [5, 12, 30] {
        let run = parse_str(&full[..full.len() - cut], QuatOrder::Wxyz).unwrap();
        assert_eq!(run.trajectory.len(), 2, "cut {cut}");
        assert!(
            run.warnings
                .iter()
                .any(|w| w.contains("line 3") && w.contains("cut short")),
            "{:?}",
            run.warnings
        );
    }
    // ... but a short line with a line end is an error.
    let s = format!(
        "{}\n{}\n{}\n",
        ROW.join(" "),
        ROW[..10].join(" "),
        ROW.join(" ")
    );
    assert_eq!(parse_str(&s, QuatOrder::Wxyz).unwrap_err().line, Some(2));
    // A cut ending in an unparseable exponent.
    let s = format!("{}\n{} 1e", ROW.join(" "), ROW[..13].join(" "));
    assert_eq!(parse_str(&s, QuatOrder::Wxyz).unwrap().trajectory.len(), 1);
}

#[test]
fn options_are_checked() {
    let s = rows(" ", "\n", 1);
    let mut opts = RecordedOptions::new(QuatOrder::Wxyz);
    opts.control_period_s = 0.0;
    assert!(parse(s.as_bytes(), Path::new("x"), &opts).is_err());
    opts.control_period_s = 0.01;
    opts.norm_tolerance = f64::NAN;
    assert!(parse(s.as_bytes(), Path::new("x"), &opts).is_err());
    opts.norm_tolerance = 0.0;
    let run = parse(s.as_bytes(), Path::new("x"), &opts).unwrap();
    assert_eq!(run.frequency_hz, 100.0);
}

#[test]
fn ranges_are_compact() {
    assert_eq!(ranges(&[]), "");
    assert_eq!(ranges(&[4]), "4");
    assert_eq!(ranges(&[1, 2, 3, 7, 9, 10]), "1-3, 7, 9-10");
    assert_eq!(
        ranges(&[0, 2, 4, 6, 8, 10, 12, 14]),
        "0, 2, 4, 6, 8, 10, ..."
    );
}

// ---- The study's recordings -------------------------------------------------

/// All 420 simulator files with the quaternion order of their simulator.
pub(crate) fn simulator_files(root: &Path) -> Vec<(PathBuf, QuatOrder)> {
    let mut files = Vec::new();
    for exp in ["Experiment1", "Experiment2", "Experiment3"] {
        let mut v: Vec<PathBuf> = std::fs::read_dir(root.join("Simulation").join(exp))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "csv"))
            .collect();
        v.sort();
        files.extend(v.into_iter().map(|p| {
            let order = if p.to_string_lossy().contains("_Mujoco_") {
                QuatOrder::Wxyz
            } else {
                QuatOrder::Xyzw
            };
            (p, order)
        }));
    }
    files
}

#[test]
fn every_simulator_file_imports() {
    let root = paper_data();
    let files = simulator_files(&root);
    assert_eq!(files.len(), 420);
    for (f, order) in &files {
        let run = read(f, &RecordedOptions::new(*order)).unwrap_or_else(|e| panic!("{e}"));
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        let n = if name.starts_with("Single") { 120 } else { 400 };
        assert_eq!(run.trajectory.len(), n, "{name}");
        run.trajectory.validate().unwrap();
        if name == "Double_VRepBullet283_5.csv" {
            // 31 rows of zeros, then frozen far away.
            assert_eq!(run.zero_rows, (0..31).collect::<Vec<_>>());
            assert_eq!(run.zero_rows.len(), 31, "{name}");
            let last = run
                .trajectory
                .body("wrist")
                .unwrap()
                .poses
                .last()
                .unwrap()
                .unwrap()
                .position_m;
            assert!(
                last.distance(Vec3::new(1.12, -1.90, 1.08)) < 0.01,
                "{last:?}"
            );
        } else {
            assert!(run.zero_rows.is_empty(), "{name}: {:?}", run.zero_rows);
            // With the README's quaternion orders the cube starts at identity.
            let cube0 = run.trajectory.body("cube").unwrap().poses[0].unwrap();
            assert!(
                cube0.orientation.angle_to(Quat::IDENTITY) < 1e-3,
                "{name}: {:?}",
                cube0.orientation
            );
            assert!((cube0.position_m.x - 0.5).abs() < 1e-3, "{name}");
        }
        if !name.contains("VRepODE") && name != "Double_VRepBullet283_5.csv" {
            assert!(run.warnings.is_empty(), "{name}: {:?}", run.warnings);
        }
    }
}

#[test]
fn vrep_ode_runs_reach_huge_values() {
    let root = paper_data();
    let f = root.join("Simulation/Experiment1/Single_VRepODE_0.csv");
    let run = read(&f, &RecordedOptions::new(QuatOrder::Xyzw)).unwrap();
    assert!(
        run.warnings.iter().any(|w| w.contains("beyond 1000 m")),
        "{:?}",
        run.warnings
    );
    let biggest = run
        .trajectory
        .bodies
        .iter()
        .flat_map(|b| b.poses.iter().flatten())
        .map(|p| {
            p.position_m
                .x
                .abs()
                .max(p.position_m.y.abs())
                .max(p.position_m.z.abs())
        })
        .fold(0.0, f64::max);
    assert!(biggest > 1e10, "largest coordinate {biggest}");
}

#[test]
fn sim_data_format_header_file() {
    let root = paper_data();
    let run = read(
        &root.join("Simulation/Sim_Data_Format.csv"),
        &RecordedOptions::new(QuatOrder::Xyzw),
    )
    .unwrap();
    assert!(run.trajectory.len() > 2);
    assert!(
        run.warnings.iter().any(|w| w.contains("skipped 2 header")),
        "{:?}",
        run.warnings
    );
}
