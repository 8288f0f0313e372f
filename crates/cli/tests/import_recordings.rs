//! End-to-end: `realitygap import rosbag|csv|lerobot` on the independent
//! writer's recordings of a simulated KUKA iiwa (`scripts/make-fixtures`),
//! and on damaged ones.

mod common;
use common::{path, realitygap, scratch, text};
use realitygap_core::testing::{iiwa_urdf, joint_recording_fixtures as fixtures, workspace};
use realitygap_data::{RunStore, SourceKind};
use std::path::PathBuf;

fn urdf() -> String {
    iiwa_urdf().display().to_string()
}

#[test]
fn every_format_imports_through_the_command() {
    let f = fixtures();
    let base = scratch("import-recordings-tests", "formats");
    let urdf = urdf();
    let bag_out = base.join("bag");
    let out = realitygap(&[
        "import",
        "rosbag",
        &path(&f.join("mcap_gaps/all")),
        "--split-gap",
        "1",
        "--robot",
        &urdf,
        "--out",
        &path(&bag_out),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(
        stdout.contains("all-ep000: 2000 samples, 9.99 s at 200 Hz, 7 joints, velocities, efforts, 1000 position commands"),
        "{stdout}"
    );
    assert!(
        stdout.contains("imported 4 episodes of robot 'lbr_iiwa'")
            && stdout.contains("end effector lbr_iiwa_link_7"),
        "{stdout}"
    );
    let store = RunStore::open(&bag_out).unwrap();
    assert_eq!(store.manifest().kind, SourceKind::Real);
    assert_eq!(store.runs().len(), 4);
    assert_eq!(store.manifest().settings["joints"][6], "lbr_iiwa_joint_7");
    let run = store.read_run("all-ep002").unwrap();
    assert_eq!(run.commands.as_ref().unwrap().len(), 1000);

    let csv_out = base.join("csv");
    let csvs: Vec<String> = (0..4)
        .map(|e| path(&f.join(format!("csv/episode_{e:03}.csv"))))
        .collect();
    let mut args = vec!["import", "csv"];
    args.extend(csvs.iter().map(String::as_str));
    let csv_out_s = path(&csv_out);
    args.extend(["--robot", &urdf, "--out", &csv_out_s]);
    let out = realitygap(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let csv_store = RunStore::open(&csv_out).unwrap();
    let from_csv = csv_store.read_run("episode_002").unwrap();
    assert_eq!(
        from_csv.joint_angles_rad, run.joint_angles_rad,
        "CSV and bag agree"
    );

    let lr_out = base.join("lerobot");
    let out = realitygap(&[
        "import",
        "lerobot",
        &path(&f.join("lerobot")),
        "--robot",
        &urdf,
        "--out",
        &path(&lr_out),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(stdout.contains("lerobot-ep003: 1000 samples"), "{stdout}");
    assert!(
        stdout.contains("warning: action taken as goal joint positions"),
        "{stdout}"
    );
}

#[test]
fn bad_recordings_fail_with_a_located_message_and_write_nothing() {
    let f = fixtures();
    let base = scratch("import-recordings-tests", "bad");
    let urdf = urdf();
    let cases: [(&str, PathBuf, &str); 4] = [
        (
            "rosbag",
            f.join("bad/nan"),
            "/joint_states message 50: position of joint 'lbr_iiwa_joint_3' is NaN",
        ),
        (
            "rosbag",
            f.join("bad/wrong_names"),
            "the recording names joint 'joint_a'",
        ),
        ("rosbag", f.join("bad/empty"), "the episode is empty"),
        (
            "csv",
            f.join("bad/csv_missing_cell.csv"),
            "csv_missing_cell.csv:11: column",
        ),
    ];
    for (k, (format, input, want)) in cases.iter().enumerate() {
        let out_dir = base.join(format!("out{k}"));
        let out = realitygap(&[
            "import",
            format,
            &path(input),
            "--robot",
            &urdf,
            "--out",
            &path(&out_dir),
        ]);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{format} {}", input.display());
        assert!(stderr.contains(want), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(
            !out_dir.exists(),
            "no partial results directory for {}",
            input.display()
        );
    }
    // A robot whose joints are not the recording's: both sides named.
    let mico = workspace().join("assets/robots/mico2/mico2.urdf");
    let out = realitygap(&[
        "import",
        "rosbag",
        &path(&f.join("mcap/episode_000")),
        "--robot",
        &path(&mico),
        "--out",
        &path(&base.join("mico")),
    ]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("names joint 'lbr_iiwa_joint_1'")
            && stderr.contains("its moving joints are"),
        "{stderr}"
    );
}

/// The checks of issue 45 as a user types them: the CSV of 29 columns
/// with one `--columns` pattern, a LeRobot dataset missing a data file, a
/// bag and a CSV with repeated times, an MCAP file with a bit flipped in a
/// chunk's size (it aborted the process), and `--help` saying which
/// timestamp a bag's joint states take.
#[test]
fn the_issue_45_checks_as_a_user_types_them() {
    let f = fixtures();
    let base = scratch("import-recordings-tests", "issue45");
    let urdf = urdf();
    let out_dir = base.join("pattern");
    let out = realitygap(&[
        "import",
        "csv",
        &path(&f.join("csv_styles/pattern.csv")),
        "--columns",
        "q_{joint}_rad=position,qd_{joint}_rad_s=velocity,effort_{joint}_n_m=effort,cmd_q_{joint}_rad=position_command",
        "--robot",
        &urdf,
        "--out",
        &path(&out_dir),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(
        stdout.contains("pattern: 200 samples, 0.99 s at 200 Hz, 7 joints, velocities, efforts, 200 position commands"),
        "{stdout}"
    );
    let cases: [(&str, PathBuf, &str); 4] = [
        (
            "lerobot",
            f.join("bad/lerobot_missing_file"),
            "data/chunk-000/file-001.parquet: the data file is missing",
        ),
        (
            "csv",
            f.join("bad/csv_duplicate_time.csv"),
            "csv_duplicate_time.csv:32: column 1 (time_s): the timestamp 0.145 s repeats the previous sample's",
        ),
        (
            "rosbag",
            f.join("bad/duplicate_stamp"),
            "/joint_states message 100: its header stamp 1700000000.495 s repeats message 99's",
        ),
        (
            "rosbag",
            f.join("bad/mcap_chunk_bitflip/record_length_bit61.mcap"),
            "record_length_bit61.mcap: the MCAP file is damaged: the record at byte 43 (opcode 0x06) claims 2305843009213734904 bytes",
        ),
    ];
    for (k, (format, input, want)) in cases.iter().enumerate() {
        let out_dir = base.join(format!("bad{k}"));
        let out = realitygap(&[
            "import",
            format,
            &path(input),
            "--robot",
            &urdf,
            "--out",
            &path(&out_dir),
        ]);
        let stderr = text(&out.stderr);
        assert_eq!(
            out.status.code(),
            Some(1),
            "{format} {}: {stderr}",
            input.display()
        );
        assert!(stderr.contains(want), "{stderr}");
        assert!(!out_dir.exists(), "nothing written for {}", input.display());
    }
    let help = text(&realitygap(&["import", "rosbag", "--help"]).stdout);
    assert!(
        help.contains("a joint state's time is its header.stamp (the bag's log time, when the recorder received it, only where the stamp is zero)"),
        "{help}"
    );
}
