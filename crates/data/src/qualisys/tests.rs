use super::*;
use crate::paper_data;
use std::path::PathBuf;

/// Rotation matrix `Rx(roll) Ry(pitch) Rz(yaw)` (angles in degrees),
/// row-major.
fn rxyz(roll: f64, pitch: f64, yaw: f64) -> [f64; 9] {
    let (sr, cr) = roll.to_radians().sin_cos();
    let (sp, cp) = pitch.to_radians().sin_cos();
    let (sy, cy) = yaw.to_radians().sin_cos();
    [
        cp * cy,
        -cp * sy,
        sp,
        cr * sy + sr * sp * cy,
        cr * cy - sr * sp * sy,
        -sr * cp,
        sr * sy - cr * sp * cy,
        sr * cy + cr * sp * sy,
        cr * cp,
    ]
}

/// The 16 cells of a body at `xyz_mm` with orientation `rpy_deg`, Rot[]
/// written column-major as Qualisys does.
fn body(xyz_mm: [f64; 3], rpy_deg: [f64; 3]) -> Vec<String> {
    let m = rxyz(rpy_deg[0], rpy_deg[1], rpy_deg[2]);
    let mut cells: Vec<String> = xyz_mm
        .iter()
        .chain(rpy_deg.iter())
        .map(|v| format!("{v:.5}"))
        .collect();
    cells.push("0.45000".into());
    for c in 0..3 {
        for r in 0..3 {
            cells.push(format!("{:.5}", m[3 * r + c]));
        }
    }
    cells
}

/// Joins bodies into a row: optional frame/time, each body followed by
/// an empty cell, the last one only when `trailing`.
fn row(frame_time: Option<(u64, f64)>, bodies: &[Vec<String>], trailing: bool) -> String {
    let mut cells: Vec<String> = Vec::new();
    if let Some((f, t)) = frame_time {
        cells.push(f.to_string());
        cells.push(format!("{t:.5}"));
    }
    for b in bodies {
        cells.extend(b.iter().cloned());
        cells.push(String::new());
    }
    if !trailing {
        cells.pop();
    }
    cells.join("\t")
}

fn two_bodies() -> QualisysOptions {
    QualisysOptions {
        frequency_hz: Some(100.0),
        body_names: Some(vec!["Wrist".into(), "Cube".into()]),
        roles: vec![
            ("Wrist".into(), "wrist".into()),
            ("Cube".into(), "cube".into()),
        ],
    }
}

fn parse_str(s: &str, opts: &QualisysOptions) -> Result<ImportedRun, ImportError> {
    parse(s.as_bytes(), Path::new("test.tsv"), opts)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

const HEADER: &str = "NO_OF_FRAMES\t3\r\nNO_OF_CAMERAS\t24\r\nNO_OF_BODIES\t2\r\nFREQUENCY\t200\r\n\
    NO_OF_ANALOG\t0\r\nANALOG_FREQUENCY\t0\r\nDESCRIPTION\t--\r\nTIME_STAMP\t2018-09-03, 18:14:00\t1826597.5\r\n\
    DATA_INCLUDED\t6D\r\nBODY_NAMES\tWrist\tCube\r\n";

fn column_names(frame_time: bool) -> String {
    let mut cells: Vec<String> = Vec::new();
    if frame_time {
        cells.extend(["Frame".to_string(), "Time".to_string()]);
    }
    for name in ["Wrist", "Cube"] {
        cells.push(format!("{name} X"));
        cells.extend(CELL_NAMES[1..].iter().map(|s| s.to_string()));
        cells.push(String::new());
    }
    cells.join("\t")
}

#[test]
fn header_file_crlf_trailing_tab() {
    let wrist = body([-12.0, 61.5, 871.875], [126.9, -86.5, 127.6]);
    let cube = body([501.08185, 6.15862, 41.2039], [1.0, -0.8, -0.3]);
    let mut s = format!("{HEADER}{}\r\n", column_names(false));
    for _ in 0..3 {
        s.push_str(&row(None, &[wrist.clone(), cube.clone()], true));
        s.push_str("\r\n");
    }
    // Options disagree with the header: the header wins, with warnings.
    let run = parse_str(&s, &two_bodies()).unwrap();
    assert_eq!(run.frequency_hz, 200.0);
    assert_eq!(run.trajectory.time_s, vec![0.0, 0.005, 0.01]);
    assert_eq!(run.body_names, vec!["Wrist", "Cube"]);
    assert_eq!(run.trajectory.bodies[0].role, "wrist");
    assert_eq!(run.warnings.len(), 1, "{:?}", run.warnings);
    assert!(run.warnings[0].contains("FREQUENCY 200"));
    run.trajectory.validate().unwrap();
    let cube_pose = run.trajectory.body("cube").unwrap().poses[2].unwrap();
    assert!(close(cube_pose.position_m.x, 0.50108185, 1e-12));
    assert!(close(cube_pose.position_m.z, 0.0412039, 1e-12));
    let wrist_pose = run.trajectory.body("wrist").unwrap().poses[0].unwrap();
    let m = rxyz(126.9, -86.5, 127.6);
    let expected = Quat::from_rotation_matrix(&m);
    assert!(
        wrist_pose.orientation.angle_to(expected) < 1e-4,
        "{:?} vs {expected:?}",
        wrist_pose.orientation
    );
    // Same data, header options absent: still fine (the header has them).
    let run2 = parse_str(&s, &QualisysOptions::default()).unwrap();
    assert!(run2.warnings.is_empty(), "{:?}", run2.warnings);
    assert_eq!(
        run2.trajectory.bodies[0].role, "Wrist",
        "no role mapping: the name is the role"
    );
}

#[test]
fn header_with_frame_and_time_columns() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let mut s = format!("{HEADER}{}\n", column_names(true));
    for i in 0..3u64 {
        s.push_str(&row(
            Some((i + 1, i as f64 * 0.005)),
            &[b.clone(), b.clone()],
            false,
        ));
        s.push('\n');
    }
    let run = parse_str(&s, &QualisysOptions::default()).unwrap();
    assert_eq!(run.trajectory.len(), 3);
    assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    assert_eq!(
        run.trajectory.bodies[1].poses[0].unwrap().position_m,
        Vec3::new(0.001, 0.002, 0.003)
    );
}

#[test]
fn headerless_lf_without_trailing_tab_and_time_column() {
    let w = body([10.0, 20.0, 30.0], [10.0, 20.0, 30.0]);
    let c = body([500.0, 0.0, 37.5], [0.0, 0.0, 0.0]);
    let s: String = (0..4u64)
        .map(|i| {
            row(
                Some((i + 5, 0.04 + i as f64 * 0.01)),
                &[w.clone(), c.clone()],
                false,
            ) + "\n"
        })
        .collect();
    let run = parse_str(&s, &two_bodies()).unwrap();
    assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    let t = &run.trajectory.time_s;
    assert_eq!(t.len(), 4);
    assert_eq!(t[0], 0.0);
    assert!(close(t[3], 0.03, 1e-12));
    let p = run.trajectory.body("cube").unwrap().poses[1].unwrap();
    assert_eq!(p.position_m, Vec3::new(0.5, 0.0, 0.0375));
    assert_eq!(p.orientation, Quat::IDENTITY);
    // The same rows with CRLF and a trailing tab give the same trajectory.
    let s2: String = (0..4u64)
        .map(|i| {
            row(
                Some((i + 5, 0.04 + i as f64 * 0.01)),
                &[w.clone(), c.clone()],
                true,
            ) + "\r\n"
        })
        .collect();
    assert_eq!(
        parse_str(&s2, &two_bodies()).unwrap().trajectory,
        run.trajectory
    );
}

#[test]
fn headerless_needs_frequency_and_names() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let s = row(Some((1, 0.0)), &[b.clone(), b], true) + "\r\n";
    let no_freq = QualisysOptions {
        frequency_hz: None,
        ..two_bodies()
    };
    let e = parse_str(&s, &no_freq).unwrap_err();
    assert!(
        e.message.contains("FREQUENCY") && e.message.contains("--frequency"),
        "{e}"
    );
    let no_names = QualisysOptions {
        body_names: None,
        ..two_bodies()
    };
    let e = parse_str(&s, &no_names).unwrap_err();
    assert!(
        e.message.contains("BODY_NAMES") && e.message.contains("--bodies"),
        "{e}"
    );
    let e = parse_str(&s, &QualisysOptions::default()).unwrap_err();
    assert!(e.message.contains("frequency"), "{e}");
}

#[test]
fn lost_markers_are_gaps_never_origin() {
    let good = body([100.0, 200.0, 300.0], [5.0, 6.0, 7.0]);
    let mut empty = good.clone();
    for c in empty.iter_mut().take(3) {
        c.clear();
    }
    let mut zero = good.clone();
    for c in zero.iter_mut().take(3) {
        *c = "0".into();
    }
    let mut nan = good.clone();
    for c in nan.iter_mut() {
        *c = "NaN".into();
    }
    let mut rot_zero = good.clone();
    for c in rot_zero.iter_mut().skip(7) {
        *c = "0.00000".into();
    }
    let mut all_empty = good.clone();
    for c in all_empty.iter_mut() {
        c.clear();
    }
    let rows = [
        (good.clone(), empty),
        (zero, good.clone()),
        (nan, rot_zero),
        (all_empty.clone(), all_empty),
        (good.clone(), good.clone()),
    ];
    let s: String = rows
        .iter()
        .enumerate()
        .map(|(i, (a, b))| {
            row(
                Some((i as u64 + 1, i as f64 / 100.0)),
                &[a.clone(), b.clone()],
                true,
            ) + "\r\n"
        })
        .collect();
    let run = parse_str(&s, &two_bodies()).unwrap();
    let wrist: Vec<bool> = run.trajectory.bodies[0]
        .poses
        .iter()
        .map(Option::is_some)
        .collect();
    let cube: Vec<bool> = run.trajectory.bodies[1]
        .poses
        .iter()
        .map(Option::is_some)
        .collect();
    assert_eq!(wrist, vec![true, false, false, false, true]);
    assert_eq!(cube, vec![false, true, false, false, true]);
    assert_eq!(run.gap_count(), 6);
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("'Wrist'") && w.contains("3 of 5")),
        "{:?}",
        run.warnings
    );
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("'Cube'") && w.contains("3 of 5")),
        "{:?}",
        run.warnings
    );
    // Without frame/time columns, a first row starting with an empty or
    // NaN cell is data, not a header line.
    let s: String = rows
        .iter()
        .map(|(a, b)| row(None, &[a.clone(), b.clone()], true) + "\n")
        .collect();
    let blank = vec![String::new(); 16];
    let s = format!("{}\n{s}", row(None, &[blank.clone(), blank], true));
    let run = parse_str(&s, &two_bodies()).unwrap();
    assert_eq!(run.trajectory.len(), 6);
    assert_eq!(run.gap_count(), 8);
    let s: String = rows[2..]
        .iter()
        .map(|(a, b)| row(None, &[a.clone(), b.clone()], true) + "\n")
        .collect();
    assert_eq!(parse_str(&s, &two_bodies()).unwrap().trajectory.len(), 3);
}

#[test]
fn non_rotation_matrix_is_a_gap_with_warning() {
    let mut b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    b[7] = "2.00000".into();
    let s = row(
        Some((1, 0.0)),
        &[b, body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0])],
        true,
    ) + "\n";
    let run = parse_str(&s, &two_bodies()).unwrap();
    assert_eq!(run.trajectory.bodies[0].poses[0], None);
    assert!(
        run.warnings.iter().any(|w| w.contains("not a rotation")),
        "{:?}",
        run.warnings
    );
}

#[test]
fn garbage_cell_names_line_column_field() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let mut bad = b.clone();
    bad[1] = "abc".into();
    let s = [
        row(Some((1, 0.0)), &[b.clone(), b.clone()], true),
        row(Some((2, 0.01)), &[b.clone(), bad], true),
    ]
    .join("\r\n");
    let e = parse(s.as_bytes(), Path::new("path/to/file.tsv"), &two_bodies()).unwrap_err();
    assert_eq!((e.line, e.column), (Some(2), Some(2 + 17 + 2)));
    assert_eq!(e.field.as_deref(), Some("Cube Y"));
    assert_eq!(
        e.to_string(),
        "path/to/file.tsv:2: column 21 (Cube Y): expected a number, found \"abc\""
    );
}

#[test]
fn bad_frame_numbers_and_times() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let r = |f: u64, t: f64| row(Some((f, t)), &[b.clone(), b.clone()], true);
    let s = [r(1, 0.0), r(2, 0.01), r(2, 0.02)].join("\n");
    let e = parse_str(&s, &two_bodies()).unwrap_err();
    assert_eq!((e.line, e.column), (Some(3), Some(1)));
    assert!(e.message.contains("frame 2 follows frame 2"), "{e}");
    let s = [r(1, 0.0), r(2, 0.01)]
        .join("\n")
        .replacen("2\t0.01000", "2.5\t0.01000", 1);
    let e = parse_str(&s, &two_bodies()).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("Frame"), "{e}");
    // A time column going backwards is not used: frames give the time.
    let s = [r(1, 0.0), r(2, 0.05), r(4, 0.02)].join("\n");
    let run = parse_str(&s, &two_bodies()).unwrap();
    assert_eq!(run.trajectory.time_s, vec![0.0, 0.01, 0.03]);
    assert!(
        run.warnings.iter().any(|w| w.contains("frame numbers")),
        "{:?}",
        run.warnings
    );
    // A time column at another rate than the frequency is used, with a warning.
    let s = [r(1, 0.0), r(2, 0.02), r(3, 0.04)].join("\n");
    let run = parse_str(&s, &two_bodies()).unwrap();
    assert_eq!(run.trajectory.time_s, vec![0.0, 0.02, 0.04]);
    assert!(
        run.warnings.iter().any(|w| w.contains("time column spans")),
        "{:?}",
        run.warnings
    );
}

#[test]
fn empty_and_header_only_files() {
    let e = parse_str("", &two_bodies()).unwrap_err();
    assert!(e.message.contains("empty"), "{e}");
    let e = parse_str("\r\n  \n", &two_bodies()).unwrap_err();
    assert!(e.message.contains("empty"), "{e}");
    let e = parse_str(
        &format!("{HEADER}{}\r\n", column_names(false)),
        &two_bodies(),
    )
    .unwrap_err();
    assert!(e.message.contains("no data"), "{e}");
    let e = parse_str(HEADER, &two_bodies()).unwrap_err();
    assert!(e.message.contains("no data"), "{e}");
    let e = parse_str("hello world\n1\t2\n", &two_bodies()).unwrap_err();
    assert_eq!(e.line, Some(1), "{e}");
}

#[test]
fn wrong_column_count() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let good = row(Some((1, 0.0)), &[b.clone(), b.clone()], true);
    // First row: says what fits.
    let three = row(Some((1, 0.0)), &[b.clone(), b.clone(), b.clone()], true);
    let e = parse_str(&(three.clone() + "\n"), &two_bodies()).unwrap_err();
    assert_eq!(e.line, Some(1));
    assert!(
        e.message.contains("found 53") && e.message.contains("3 bodies"),
        "{e}"
    );
    // A later row.
    let short = row(Some((2, 0.01)), std::slice::from_ref(&b), true);
    let s = format!("{good}\r\n{short}\r\n{good}\r\n");
    let e = parse_str(&s, &two_bodies()).unwrap_err();
    assert_eq!(e.line, Some(2));
    assert!(
        e.message.contains("expected 36 columns") && e.message.contains("found 19"),
        "{e}"
    );
    // Too many in a later row.
    let s = format!("{good}\n{good}\textra\n");
    let e = parse_str(&s, &two_bodies()).unwrap_err();
    assert!(e.message.contains("found 37"), "{e}");
    // A non-empty separator column.
    let s = good.replacen("\t\t", "\t7\t", 1);
    let e = parse_str(&s, &two_bodies()).unwrap_err();
    assert!(e.message.contains("empty column between bodies"), "{e}");
    assert_eq!(e.field.as_deref(), Some("separator after Wrist"));
}

#[test]
fn truncated_last_line_is_dropped_with_warning() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let r = |f: u64| {
        row(
            Some((f, (f - 1) as f64 / 100.0)),
            &[b.clone(), b.clone()],
            true,
        )
    };
    let full = format!("{}\r\n{}\r\n{}", r(1), r(2), r(3));
    let cut = &full[..full.len() - 30];
    let run = parse_str(cut, &two_bodies()).unwrap();
    assert_eq!(run.trajectory.len(), 2);
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("line 3") && w.contains("cut short")),
        "{:?}",
        run.warnings
    );
    // Without a line end but complete: kept.
    assert_eq!(parse_str(&full, &two_bodies()).unwrap().trajectory.len(), 3);
    // A short line that is not the last is an error.
    let s = format!("{}\r\n{}\r\n", r(1), &r(2)[..40]);
    assert!(parse_str(&s, &two_bodies()).is_err());
}

#[test]
fn non_utf8_bytes_are_errors_not_panics() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let mut bad = b.clone();
    bad[0] = "@@".into();
    let text = format!(
        "{}\r\n{}\r\n",
        row(Some((1, 0.0)), &[b.clone(), b.clone()], true),
        row(Some((2, 0.01)), &[bad, b.clone()], true)
    );
    let at = text.find("@@").unwrap();
    let mut bytes = text.into_bytes();
    bytes[at] = 0xff;
    bytes[at + 1] = 0xfe;
    let e = parse(&bytes, Path::new("x.tsv"), &two_bodies()).unwrap_err();
    assert_eq!((e.line, e.column), (Some(2), Some(3)));
    assert!(e.to_string().contains('\u{fffd}'), "{e}");
    let e = parse(b"\xff\xfe\x00\x01", Path::new("x.tsv"), &two_bodies()).unwrap_err();
    assert_eq!(e.line, Some(1));
    // A header with invalid UTF-8 in a body name is read lossily.
    let header = b"FREQUENCY\t100\nBODY_NAMES\tA\xff\tB\n";
    let mut bytes = header.to_vec();
    bytes.extend_from_slice(row(Some((1, 0.0)), &[b.clone(), b], true).as_bytes());
    let run = parse(&bytes, Path::new("x.tsv"), &QualisysOptions::default()).unwrap();
    assert_eq!(run.body_names[0], "A\u{fffd}");
}

#[test]
fn header_values_are_checked() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let data = row(None, &[b.clone(), b.clone()], true);
    let e = parse_str(
        &format!("FREQUENCY\tfast\nBODY_NAMES\tA\tB\n{data}"),
        &QualisysOptions::default(),
    )
    .unwrap_err();
    assert_eq!(
        (e.line, e.column, e.field.as_deref()),
        (Some(1), Some(2), Some("FREQUENCY")),
        "{e}"
    );
    let e = parse_str(
        &format!("FREQUENCY\t100\nDATA_INCLUDED\t3D\n{data}"),
        &two_bodies(),
    )
    .unwrap_err();
    assert!(e.message.contains("6D"), "{e}");
    let e = parse_str(&format!("BODY_NAMES\tA\tA\n{data}"), &two_bodies()).unwrap_err();
    assert!(e.message.contains("twice"), "{e}");
    let run = parse_str(&format!("NO_OF_FRAMES\t5\n{data}"), &two_bodies()).unwrap();
    assert!(
        run.warnings
            .iter()
            .any(|w| w.contains("NO_OF_FRAMES says 5")),
        "{:?}",
        run.warnings
    );
    // A column-name line that does not fit the bodies.
    let s = format!("FREQUENCY\t100\nBODY_NAMES\tWrist\tCube\nWrist X\tY\tZ\tRoll\tPitch\tYaw\tResidual\tRot[0]\n{data}");
    let e = parse_str(&s, &QualisysOptions::default()).unwrap_err();
    assert_eq!(e.line, Some(3));
    let s = format!(
        "BODY_NAMES\tWrist\tCube\n{}\n{data}",
        column_names(false).replace("Cube X", "Box X")
    );
    let e = parse_str(&s, &two_bodies()).unwrap_err();
    assert!(
        e.message.contains("Cube X") && e.message.contains("Box X"),
        "{e}"
    );
}

#[test]
fn duplicate_roles_are_an_error() {
    let b = body([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]);
    let opts = QualisysOptions {
        roles: vec![
            ("Wrist".into(), "wrist".into()),
            ("Cube".into(), "wrist".into()),
        ],
        ..two_bodies()
    };
    let e = parse_str(&row(None, &[b.clone(), b], true), &opts).unwrap_err();
    assert!(e.message.contains("both have the role 'wrist'"), "{e}");
}

// ---- The study's recordings -------------------------------------------------

fn capture_files(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for exp in ["Experiment1", "Experiment2", "Experiment3"] {
        let mut v: Vec<PathBuf> = std::fs::read_dir(root.join("MotionCapture").join(exp))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "tsv"))
            .collect();
        v.sort();
        files.extend(v);
    }
    files
}

#[test]
fn every_capture_file_imports_without_gaps() {
    let root = paper_data();
    let files = capture_files(&root);
    assert_eq!(files.len(), 60);
    let opts = QualisysOptions::collins2019();
    for f in &files {
        let run = read(f, &opts).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(run.gap_count(), 0, "{}", f.display());
        assert!(
            run.warnings.is_empty(),
            "{}: {:?}",
            f.display(),
            run.warnings
        );
        run.trajectory.validate().unwrap();
        let n = run.trajectory.len();
        let name = f.file_name().unwrap().to_string_lossy();
        let range = match &name[..4] {
            "Sing" => 714..=799,
            "Doub" => 2126..=2402,
            _ => 2000..=2000,
        };
        assert!(range.contains(&n), "{name}: {n} frames");
        assert!(
            close(run.trajectory.time_s[n - 1], (n - 1) as f64 * 0.01, 1e-9),
            "{name}"
        );
        let roles: Vec<&str> = run
            .trajectory
            .bodies
            .iter()
            .map(|b| b.role.as_str())
            .collect();
        assert_eq!(roles, vec!["base", "wrist", "cube"]);
        // The wrist starts upright, near z = 872 mm.
        let z = run.trajectory.body("wrist").unwrap().poses[50]
            .unwrap()
            .position_m
            .z;
        assert!((0.85..0.90).contains(&z), "{name}: wrist z {z}");
    }
}

#[test]
fn experiment3_real_cube_slides_about_a_decimetre() {
    let root = paper_data();
    let files: Vec<PathBuf> = capture_files(&root)
        .into_iter()
        .filter(|f| f.to_string_lossy().contains("CubeExp"))
        .collect();
    assert_eq!(files.len(), 20);
    let opts = QualisysOptions::collins2019();
    let mean: f64 = files
        .iter()
        .map(|f| {
            let run = read(f, &opts).unwrap();
            run.trajectory
                .body("cube")
                .unwrap()
                .poses
                .last()
                .unwrap()
                .unwrap()
                .position_m
                .x
                - 0.5
        })
        .sum::<f64>()
        / files.len() as f64;
    assert!(
        close(mean, 0.0975, 5e-4),
        "mean final cube x - 0.5 m = {mean}"
    );
}

/// Reads a real file's Rot[] both ways and compares with Rx Ry Rz from the
/// Euler cells: the column-major reading must agree on every row (to the
/// printed precision), the row-major one must not.
#[test]
fn rotation_matrix_is_column_major_on_real_data() {
    let root = paper_data();
    for rel in [
        "MotionCapture/Experiment1/Single0001_6D.tsv",
        "MotionCapture/Experiment3/CubeExp0005_6D.tsv",
    ] {
        let bytes = std::fs::read(root.join(rel)).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let (mut worst_col, mut worst_row) = (0.0f64, 0.0f64);
        for line in text.lines() {
            let cells: Vec<f64> = line
                .split('\t')
                .filter(|c| !c.is_empty())
                .map(|c| c.parse().unwrap())
                .collect();
            for b in 0..3 {
                let v = &cells[2 + 16 * b..2 + 16 * (b + 1)];
                let m = rxyz(v[3], v[4], v[5]);
                let r = &v[7..16];
                for i in 0..3 {
                    for j in 0..3 {
                        worst_col = worst_col.max((m[3 * i + j] - r[3 * j + i]).abs());
                        worst_row = worst_row.max((m[3 * i + j] - r[3 * i + j]).abs());
                    }
                }
            }
        }
        assert!(
            worst_col < 2e-4,
            "{rel}: column-major reading off by {worst_col}"
        );
        assert!(
            worst_row > 1e-2,
            "{rel}: row-major reading would also fit ({worst_row})"
        );
        // And the importer's orientation is that matrix.
        let run = read(&root.join(rel), &QualisysOptions::collins2019()).unwrap();
        let line = text.lines().nth(300).unwrap();
        let cells: Vec<f64> = line
            .split('\t')
            .filter(|c| !c.is_empty())
            .map(|c| c.parse().unwrap())
            .collect();
        let v = &cells[2 + 16..2 + 32];
        let q = Quat::from_rotation_matrix(&rxyz(v[3], v[4], v[5]));
        let got = run.trajectory.body("wrist").unwrap().poses[300]
            .unwrap()
            .orientation;
        assert!(got.angle_to(q) < 5e-4, "{rel}: {got:?} vs {q:?}");
    }
}

#[test]
fn data_format_file_with_header() {
    let root = paper_data();
    let run = read(
        &root.join("MotionCapture/Data_Format.tsv"),
        &QualisysOptions::collins2019(),
    )
    .unwrap();
    assert_eq!(run.trajectory.len(), 2280);
    assert_eq!(run.frequency_hz, 100.0);
    assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    assert_eq!(run.gap_count(), 0);
    assert!(close(run.trajectory.time_s[2279], 22.79, 1e-9));
    // The same recording as Double0001 (another export setting): the cube
    // positions agree.
    let double = read(
        &root.join("MotionCapture/Experiment2/Double0001_6D.tsv"),
        &QualisysOptions::collins2019(),
    )
    .unwrap();
    let a = run.trajectory.body("cube").unwrap().poses[100]
        .unwrap()
        .position_m;
    let b = double.trajectory.body("cube").unwrap().poses[100]
        .unwrap()
        .position_m;
    assert!(a.distance(b) < 0.01, "{a:?} vs {b:?}");
}
