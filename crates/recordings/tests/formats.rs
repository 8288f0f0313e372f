//! The importers against more files of the independent writer
//! (`tools/fixtures/make_joint_recordings.py`): CSV as other tools export
//! joint states, column patterns, LeRobot datasets whose metadata and data
//! disagree, float32 timestamps, repeated timestamps, and MCAP files whose
//! length fields are damaged. Each test checks the message a user sees.

use realitygap_core::testing::joint_recording_fixtures as fixtures;
use realitygap_core::CommandKind;
use realitygap_recordings::csvfile::{import_csv, parse_column_patterns, CsvOptions};
use realitygap_recordings::lerobot::{import_lerobot, LeRobotOptions};
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use realitygap_recordings::Recording;
use std::path::{Path, PathBuf};

fn joint_names() -> Vec<String> {
    (1..=7).map(|j| format!("lbr_iiwa_joint_{j}")).collect()
}

fn rosbag_opts() -> RosbagOptions {
    RosbagOptions {
        robot_joints: joint_names(),
        ..RosbagOptions::default()
    }
}

fn bag(rel: &str) -> Recording {
    let mut r =
        import_rosbag(&fixtures().join(rel), &rosbag_opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(r.len(), 1);
    r.remove(0)
}

/// The first `n` joint states of episode 0's MCAP bag.
fn reference(n: usize) -> Recording {
    let mut r = bag("mcap/episode_000");
    r.states.time_ns.truncate(n);
    r.states.position.truncate(n);
    for v in [&mut r.states.velocity, &mut r.states.effort]
        .into_iter()
        .flatten()
    {
        v.truncate(n);
    }
    r
}

fn csv(rel: &str, opts: &CsvOptions) -> Result<Recording, String> {
    import_csv(&fixtures().join(rel), opts).map_err(|e| e.to_string())
}

/// The CLI's form of `--columns`, exactly as the guide shows it.
const PATTERNS: &str = "q_{joint}_rad=position,qd_{joint}_rad_s=velocity,effort_{joint}_n_m=effort,cmd_q_{joint}_rad=position_command";

fn patterns(list: &str) -> CsvOptions {
    CsvOptions {
        patterns: parse_column_patterns(list).unwrap_or_else(|e| panic!("{e}")),
        ..CsvOptions::default()
    }
}

#[test]
fn one_columns_pattern_reads_a_csv_of_29_unconventional_columns() {
    let r = csv("csv_styles/pattern.csv", &patterns(PATTERNS)).unwrap();
    let want = reference(200);
    assert_eq!(r.states.names, joint_names());
    assert_eq!(r.info["time_column"], "t_s");
    // t_s counts from the episode's start; the bag's stamps from the epoch.
    let t0 = want.states.time_ns[0];
    let rel: Vec<i64> = want.states.time_ns.iter().map(|t| t - t0).collect();
    assert_eq!(r.states.time_ns, rel);
    assert_eq!(r.states.position, want.states.position);
    assert_eq!(r.states.velocity, want.states.velocity);
    assert_eq!(r.states.effort, want.states.effort);
    let c = r.commands.as_ref().unwrap();
    assert_eq!(c.kind, CommandKind::Position);
    assert_eq!(c.names, joint_names());
    assert!(
        r.warnings.iter().all(|w| !w.contains("ignored")),
        "{:?}",
        r.warnings
    );
    // time=t_s in the same list says the same.
    let with_time = csv(
        "csv_styles/pattern.csv",
        &patterns(&format!("time=t_s,{PATTERNS}")),
    )
    .unwrap();
    assert_eq!(with_time.states, r.states);
}

#[test]
fn patterns_that_match_nothing_or_leave_a_joint_without_position_are_errors() {
    let e = csv("csv_styles/pattern.csv", &patterns("pos_{joint}=position")).unwrap_err();
    println!("{e}");
    assert!(e.contains("pattern.csv:1: --columns pattern \"pos_{joint}\" (position) matches no column; the columns are t_s, q_lbr_iiwa_joint_1_rad, "), "{e}");
    let e = csv(
        "csv_styles/pattern.csv",
        &patterns("qd_{joint}_rad_s=velocity"),
    )
    .unwrap_err();
    println!("{e}");
    assert!(
        e.contains("pattern.csv:1: joint 'lbr_iiwa_joint_1' has value columns (qd_lbr_iiwa_joint_1_rad_s) but no position column; the columns are t_s, "),
        "{e}"
    );
    // Without a pattern the file names no joint the importer knows.
    let e = csv("csv_styles/pattern.csv", &CsvOptions::default()).unwrap_err();
    assert!(
        e.contains("no joint column") && e.contains("--columns"),
        "{e}"
    );
    for bad in [
        "q_rad=position",
        "q_{joint}_rad=angle",
        "q_{joint}_{joint}=position",
        "time=t_{joint}",
        "",
    ] {
        let e = parse_column_patterns(bad).unwrap_err();
        println!("{bad:?}: {e}");
    }
}

#[test]
fn exports_of_other_tools_read_as_the_bag() {
    let want = reference(200);
    for (file, style) in [
        ("plotjuggler.csv", None),
        (
            "rostopic_echo_p.csv",
            Some("flattened JointState (rostopic echo -p)"),
        ),
        ("ros2_topic_echo.csv", Some("ros2 topic echo --csv")),
        ("list_cells.csv", Some("JointState with list cells")),
    ] {
        let r = csv(&format!("csv_styles/{file}"), &CsvOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.states.names, joint_names(), "{file}");
        if file == "plotjuggler.csv" {
            // Seconds since the epoch as a double: 0.24 us apart at most.
            for (a, b) in r.states.time_ns.iter().zip(&want.states.time_ns) {
                assert!((a - b).abs() <= 240, "{file}: {a} ns for {b}");
            }
        } else {
            assert_eq!(
                r.states.time_ns, want.states.time_ns,
                "{file}: the header stamps"
            );
        }
        assert_eq!(r.states.position, want.states.position, "{file}");
        assert_eq!(r.states.velocity, want.states.velocity, "{file}");
        assert_eq!(r.states.effort, want.states.effort, "{file}");
        assert_eq!(
            r.info.get("style").and_then(|s| s.as_str()),
            style,
            "{file}"
        );
        println!("{file}: {:?} {:?}", r.info["time_column"], r.warnings);
    }
    // rostopic's %time is when the message arrived (1 us late here): the
    // header stamp is used, as for bags.
    let r = csv("csv_styles/rostopic_echo_p.csv", &CsvOptions::default()).unwrap();
    assert_eq!(r.info["time_column"], "field.header.stamp");
}

#[test]
fn repeated_timestamps_are_errors_in_every_importer() {
    let e = csv("bad/csv_duplicate_time.csv", &CsvOptions::default()).unwrap_err();
    println!("{e}");
    assert!(
        e.contains("csv_duplicate_time.csv:32: column 1 (time_s): the timestamp 0.145 s repeats the previous sample's: two joint states at one time"),
        "{e}"
    );
    for rel in ["bad/duplicate_stamp", "bad/duplicate_stamp_sqlite3"] {
        let e = import_rosbag(&fixtures().join(rel), &rosbag_opts())
            .unwrap_err()
            .to_string();
        println!("{e}");
        assert!(
            e.contains("/joint_states message 100: its header stamp 1700000000.495 s repeats message 99's: two joint states at one time"),
            "{e}"
        );
        assert!(e.contains(rel.rsplit('/').next().unwrap()), "{e}");
    }
    let e = lerobot_error("bad/lerobot_repeated_frame");
    println!("{e}");
    assert!(
        e.contains("file-002.parquet: row 100, column frame_index: episode 2: frame_index 99 repeats frame 99: two frames at one time"),
        "{e}"
    );
}

fn lerobot_error(rel: &str) -> String {
    match import_lerobot(&fixtures().join(rel), &LeRobotOptions::default()) {
        Ok(r) => panic!("{rel} imported: {} episodes", r.len()),
        Err(e) => e.to_string(),
    }
}

/// A copy of a fixture folder.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(e.file_name()));
        } else {
            std::fs::copy(&p, to.join(e.file_name())).unwrap();
        }
    }
}

#[test]
fn lerobot_metadata_is_checked_against_the_data() {
    let good = import_lerobot(
        &fixtures().join("lerobot_files"),
        &LeRobotOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(good.len(), 3);
    for (e, r) in good.iter().enumerate() {
        assert_eq!(r.states.time_ns.len(), 200);
        assert!(
            r.file
                .ends_with(format!("data/chunk-000/file-{e:03}.parquet")),
            "{}",
            r.file.display()
        );
    }
    let e = lerobot_error("bad/lerobot_missing_file");
    println!("{e}");
    assert!(
        e.contains("data/chunk-000/file-001.parquet: the data file is missing: ")
            && e.contains(
                "meta/episodes/chunk-000/file-000.parquet lists episode 1 (200 frames) in it"
            ),
        "{e}"
    );
    let e = lerobot_error("bad/lerobot_short_episode");
    println!("{e}");
    assert!(
        e.contains("data/chunk-000/file-001.parquet: episode 1 has 199 frames, ")
            && e.contains("meta/episodes/chunk-000/file-000.parquet says 200"),
        "{e}"
    );
    // The same damage done here to a copy: a file deleted, the totals changed.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    copy_dir(&fixtures().join("lerobot_files"), &dir);
    let info_path = dir.join("meta/info.json");
    let info = std::fs::read_to_string(&info_path).unwrap();
    std::fs::write(
        &info_path,
        info.replace("\"total_episodes\": 3", "\"total_episodes\": 4"),
    )
    .unwrap();
    let e = import_lerobot(&dir, &LeRobotOptions::default())
        .unwrap_err()
        .to_string();
    println!("{e}");
    assert!(
        e.contains("meta/info.json: total_episodes: total_episodes is 4 but the episode index")
            && e.ends_with("lists 3"),
        "{e}"
    );
    std::fs::write(
        &info_path,
        info.replace("\"total_frames\": 600", "\"total_frames\": 601"),
    )
    .unwrap();
    let e = import_lerobot(&dir, &LeRobotOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("total_frames: total_frames is 601 but the data files under"),
        "{e}"
    );
    std::fs::write(&info_path, &info).unwrap();
    std::fs::remove_file(dir.join("data/chunk-000/file-002.parquet")).unwrap();
    let e = import_lerobot(&dir, &LeRobotOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("file-002.parquet: the data file is missing")
            && e.contains("episode 2 (200 frames)"),
        "{e}"
    );
}

#[test]
fn lerobot_times_are_frame_index_over_fps() {
    let lr = import_lerobot(&fixtures().join("lerobot"), &LeRobotOptions::default()).unwrap();
    let mcap = bag("mcap/episode_000");
    let t0 = mcap.states.time_ns[0];
    // Frame f is state sample 2 f (200 Hz states, 100 fps): 10 ms apart
    // exactly, where the float32 timestamps are off by up to 0.5 us.
    for (f, &t) in lr[0].states.time_ns.iter().enumerate() {
        assert_eq!(t, f as i64 * 10_000_000, "frame {f}");
        assert_eq!(t, mcap.states.time_ns[2 * f] - t0);
    }
    assert_eq!(lr[0].info["times"], "frame_index / fps");
    let e = lerobot_error("bad/lerobot_timestamp_off");
    println!("{e}");
    assert!(
        e.contains("file-000.parquet: row 50, column timestamp: episode 0: timestamp 0.507000029 s is +0.70 frames from frame_index 50 / fps 100 = 0.5 s: the times disagree"),
        "{e}"
    );
}

/// The offsets of the u64 length fields of every chunk record of an MCAP
/// file: its record length, uncompressed size and compressed length.
fn chunk_length_fields(data: &[u8]) -> Vec<(&'static str, usize)> {
    let u64_at = |p: usize| u64::from_le_bytes(data[p..p + 8].try_into().unwrap());
    let u32_at = |p: usize| u32::from_le_bytes(data[p..p + 4].try_into().unwrap());
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= data.len() {
        let (op, len) = (data[pos], u64_at(pos + 1) as usize);
        if op == 0x06 {
            let body = pos + 9;
            let comp = u32_at(body + 28) as usize;
            out.push(("record length", pos + 1));
            out.push(("uncompressed size", body + 16));
            out.push(("compressed length", body + 32 + comp));
        }
        pos += 9 + len;
    }
    out
}

fn storage_file(rel: &str, ext: &str) -> PathBuf {
    std::fs::read_dir(fixtures().join(rel))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == ext))
        .unwrap()
}

#[test]
fn damaged_mcap_length_fields_are_errors_not_aborts() {
    // Bit flips written by the fixture generator (Python).
    let dir = fixtures().join("bad/mcap_chunk_bitflip");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    assert_eq!(files.len(), 12);
    for f in &files {
        let e = import_rosbag(f, &rosbag_opts()).unwrap_err().to_string();
        println!("{e}");
        assert!(e.starts_with(&f.display().to_string()), "{e}");
        assert!(e.contains("the MCAP file is damaged"), "{e}");
    }
    // Every chunk length field of the full episodes (zstd and plain
    // chunks), set here to huge values.
    for (rel, ext) in [
        ("mcap/episode_000", "mcap"),
        ("mcap_trajectory/episode_000", "mcap"),
    ] {
        let file = storage_file(rel, ext);
        let bytes = std::fs::read(&file).unwrap();
        let fields = chunk_length_fields(&bytes);
        assert!(fields.len() >= 3, "{rel}: {} fields", fields.len());
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("damaged.mcap");
        for &(what, at) in fields.iter().take(12) {
            for value in [
                u64::MAX,
                1 << 61,
                0xC000_0000_0000_0000 | 12345,
                u64::from(u32::MAX),
            ] {
                let mut b = bytes.clone();
                b[at..at + 8].copy_from_slice(&value.to_le_bytes());
                std::fs::write(&out, &b).unwrap();
                let e = import_rosbag(&out, &rosbag_opts()).unwrap_err().to_string();
                assert!(
                    e.starts_with(&out.display().to_string()),
                    "{rel} {what} {value}: {e}"
                );
            }
        }
    }
}
