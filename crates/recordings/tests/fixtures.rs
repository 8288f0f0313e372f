//! The importers against recordings made by an independent writer: the
//! KUKA iiwa simulated in MuJoCo (Python) and written as ROS 2 bags by
//! `rosbags`, as CSV by Python's csv module and as a LeRobot dataset by
//! pyarrow (`tools/fixtures/make_joint_recordings.py`, run by
//! `scripts/make-fixtures`, which `scripts/setup --tests` calls).

use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::{CommandKind, Trajectory};
use realitygap_recordings::csvfile::{import_csv, CsvOptions};
use realitygap_recordings::lerobot::{import_lerobot, LeRobotOptions};
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use realitygap_recordings::{end_effector, store, Recording, StoreTarget};
use std::path::PathBuf;

use realitygap_core::testing::{iiwa_urdf as urdf, joint_recording_fixtures as fixtures};

fn iiwa() -> RobotModel {
    RobotModel::from_urdf_file(&urdf(), &PackageResolver::new()).unwrap()
}

fn joint_names() -> Vec<String> {
    (1..=7).map(|j| format!("lbr_iiwa_joint_{j}")).collect()
}

fn rosbag_opts() -> RosbagOptions {
    RosbagOptions {
        robot_joints: joint_names(),
        ..RosbagOptions::default()
    }
}

fn bag(rel: &str) -> Vec<Recording> {
    import_rosbag(&fixtures().join(rel), &rosbag_opts()).unwrap_or_else(|e| panic!("{e}"))
}

fn run_of(r: &Recording) -> Trajectory {
    let robot = iiwa();
    let link = end_effector(&robot, None).unwrap();
    r.to_trajectory(&robot, link)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn truth() -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(fixtures().join("truth.json")).unwrap()).unwrap()
}

#[test]
fn a_bag_becomes_one_run_of_the_iiwa() {
    let recs = bag("mcap/episode_000");
    assert_eq!(recs.len(), 1);
    let r = &recs[0];
    assert_eq!(r.states.names, joint_names());
    let t = run_of(r);
    let truth = truth();
    let rate = truth["state_rate_hz"].as_f64().unwrap();
    assert_eq!(t.len(), 2000);
    assert_eq!(t.time_s[0], 0.0);
    assert!((t.time_s[1] - 1.0 / rate).abs() < 1e-12);
    assert_eq!(t.joint_count(), 7);
    assert!(t.joint_velocities_rad_s.is_some() && t.joint_efforts_nm.is_some());
    let c = t.commands.as_ref().unwrap();
    assert_eq!(c.kind, CommandKind::Position);
    assert_eq!(c.joints, (0..7).collect::<Vec<_>>());
    assert_eq!(c.len(), 1000);
    // The arm starts at rest on its first command.
    assert_eq!(t.joint_angles_rad.as_ref().unwrap()[0], c.values[0]);
    // The end effector is the iiwa's last link, by forward kinematics.
    let robot = iiwa();
    assert_eq!(
        robot.links[end_effector(&robot, None).unwrap()].name,
        "lbr_iiwa_link_7"
    );
    let wrist = t.bodies[0].poses[0].unwrap().position_m;
    assert!(wrist.z > 0.5 && wrist.z < 1.4, "{wrist:?}");
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("carries no joint names")),
        "{:?}",
        r.warnings
    );
}

#[test]
fn mcap_sqlite3_csv_and_lerobot_give_the_same_runs() {
    for e in 0..4 {
        let name = format!("episode_{e:03}");
        let mcap = run_of(&bag(&format!("mcap/{name}"))[0]);
        let sqlite = run_of(&bag(&format!("sqlite3/{name}"))[0]);
        assert_eq!(mcap, sqlite, "{name}: MCAP and sqlite3");
        let csv = import_csv(
            &fixtures().join(format!("csv/{name}.csv")),
            &CsvOptions::default(),
        )
        .unwrap_or_else(|err| panic!("{err}"));
        let csv = run_of(&csv);
        assert_eq!(csv.time_s, mcap.time_s, "{name}: CSV times");
        assert_eq!(
            csv.joint_angles_rad, mcap.joint_angles_rad,
            "{name}: CSV angles"
        );
        assert_eq!(csv.joint_velocities_rad_s, mcap.joint_velocities_rad_s);
        assert_eq!(csv.joint_efforts_nm, mcap.joint_efforts_nm);
        assert_eq!(csv.bodies, mcap.bodies);
        // The CSV holds the command in force at each row: the same signal.
        let (cc, mc) = (csv.commands.unwrap(), mcap.commands.clone().unwrap());
        for &t in &csv.time_s {
            assert_eq!(cc.held_at(t), mc.held_at(t), "{name}: command at {t} s");
        }
    }
    let lerobot = import_lerobot(&fixtures().join("lerobot"), &LeRobotOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(lerobot.len(), 4);
    for (e, rec) in lerobot.iter().enumerate() {
        assert_eq!(rec.id, format!("lerobot-ep{e:03}"));
        let lr = run_of(rec);
        let mcap = run_of(&bag(&format!("mcap/episode_{e:03}"))[0]);
        let (mq, mc) = (mcap.joint_angles_rad.unwrap(), mcap.commands.unwrap());
        let lq = lr.joint_angles_rad.unwrap();
        let lc = lr.commands.unwrap();
        assert_eq!(lr.time_s.len(), 1000);
        for (i, &t) in lr.time_s.iter().enumerate() {
            // The dataset's frames are every other state, in float32.
            let k = mcap
                .time_s
                .iter()
                .position(|&m| (m - t).abs() < 1e-6)
                .unwrap();
            for j in 0..7 {
                assert!((lq[i][j] - mq[k][j]).abs() <= 1e-6 * mq[k][j].abs().max(1.0));
                let want = mc.held_at(mcap.time_s[k]).unwrap()[j];
                assert!((lc.values[i][j] - want).abs() <= 1e-6 * want.abs().max(1.0));
            }
        }
    }
}

#[test]
fn a_joint_trajectory_with_its_own_joint_order_gives_the_same_commands() {
    let traj = run_of(&bag("mcap_trajectory/episode_000")[0]);
    let plain = run_of(&bag("mcap/episode_000")[0]);
    let (tc, pc) = (traj.commands.unwrap(), plain.commands.unwrap());
    assert_eq!(tc.kind, CommandKind::Position);
    assert_eq!(tc.joints, (0..7).rev().collect::<Vec<_>>());
    for &t in &plain.time_s {
        let (a, b) = (tc.held_at(t).unwrap(), pc.held_at(t).unwrap());
        for (k, &j) in tc.joints.iter().enumerate() {
            assert_eq!(a[k], b[j], "t {t} joint {j}");
        }
    }
}

#[test]
fn one_bag_of_four_episodes_splits_at_its_gaps() {
    let dir = fixtures().join("mcap_gaps/all");
    let none = import_rosbag(&dir, &rosbag_opts()).unwrap();
    assert_eq!(none.len(), 1, "no split without --split-gap");
    let opts = RosbagOptions {
        split_gap_s: Some(1.0),
        ..rosbag_opts()
    };
    let parts = import_rosbag(&dir, &opts).unwrap();
    assert_eq!(parts.len(), 4);
    for (e, part) in parts.iter().enumerate() {
        assert_eq!(part.id, format!("all-ep{e:03}"));
        let own = run_of(&bag(&format!("mcap/episode_{e:03}"))[0]);
        assert_eq!(run_of(part), own, "episode {e}");
    }
}

/// The message of an import that must fail.
fn bag_error(rel: &str, opts: &RosbagOptions) -> String {
    match import_rosbag(&fixtures().join(rel), opts) {
        Ok(recs) => {
            let robot = iiwa();
            let link = end_effector(&robot, None).unwrap();
            recs.iter()
                .find_map(|r| r.to_trajectory(&robot, link).err())
                .unwrap_or_else(|| panic!("{rel} was imported"))
                .to_string()
        }
        Err(e) => e.to_string(),
    }
}

#[test]
fn damaged_bags_are_errors_that_say_where() {
    let opts = rosbag_opts();
    let e = bag_error("bad/backwards", &opts);
    assert!(
        e.contains("/joint_states message 100: the timestamp goes backwards by 0.5"),
        "{e}"
    );
    let e = bag_error("bad/nan", &opts);
    assert!(
        e.contains("/joint_states message 50: position of joint 'lbr_iiwa_joint_3' is NaN"),
        "{e}"
    );
    let e = bag_error("bad/empty", &opts);
    assert!(
        e.contains("topic /joint_states has no message: the episode is empty"),
        "{e}"
    );
    let e = bag_error("bad/unknown_type", &opts);
    assert!(
        e.contains("topic /forward_position_controller/commands has type geometry_msgs/msg/Twist, an unknown command message"),
        "{e}"
    );
    let e = bag_error("bad/wrong_names", &opts);
    assert!(
        e.contains("the recording names joint 'joint_a', which the robot does not have")
            && e.contains("its moving joints are lbr_iiwa_joint_1, "),
        "{e}"
    );
    assert!(e.contains("bad/wrong_names"), "names the bag: {e}");
    // Given explicitly, a topic of another type is refused by name.
    let opts = RosbagOptions {
        joint_states: Some("/forward_position_controller/commands".into()),
        ..rosbag_opts()
    };
    let e = bag_error("mcap/episode_000", &opts);
    assert!(e.contains("has type std_msgs/msg/Float64MultiArray; joint states must be sensor_msgs/msg/JointState"), "{e}");
    let opts = RosbagOptions {
        commands: Some("/nope".into()),
        ..rosbag_opts()
    };
    let e = bag_error("mcap/episode_000", &opts);
    assert!(
        e.contains("the bag has no topic /nope; its topics are /"),
        "{e}"
    );
}

/// A copy of a bag's storage file cut to `keep` of its bytes.
fn truncated(rel: &str, ext: &str, keep: f64) -> (tempfile::TempDir, PathBuf) {
    let dir = fixtures().join(rel);
    let file = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == ext))
        .unwrap();
    let bytes = std::fs::read(&file).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join(file.file_name().unwrap());
    std::fs::write(&out, &bytes[..(bytes.len() as f64 * keep) as usize]).unwrap();
    (tmp, out)
}

#[test]
fn truncated_bags_are_errors_naming_the_file() {
    for (rel, ext) in [("mcap/episode_000", "mcap"), ("sqlite3/episode_000", "db3")] {
        for keep in [0.0, 0.01, 0.5, 0.99] {
            let (_tmp, file) = truncated(rel, ext, keep);
            let e = import_rosbag(&file, &rosbag_opts())
                .unwrap_err()
                .to_string();
            assert!(e.starts_with(&file.display().to_string()), "{keep}: {e}");
        }
    }
}

#[test]
fn damaged_csv_files_are_errors_at_their_line() {
    let e = import_csv(
        &fixtures().join("bad/csv_missing_cell.csv"),
        &CsvOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("csv_missing_cell.csv:11: column"), "{e}");
    assert!(e.contains("the cell is empty"), "{e}");
    let e = import_csv(
        &fixtures().join("bad/csv_backwards.csv"),
        &CsvOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("csv_backwards.csv:21: column 1 (time_s): the timestamp goes backwards"),
        "{e}"
    );
}

#[test]
fn a_bad_episode_leaves_no_results_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("results");
    let robot = iiwa();
    let link = end_effector(&robot, None).unwrap();
    let mut recs = bag("mcap/episode_000");
    // Read without the robot's names, the bag is read; its run is not.
    let unchecked = RosbagOptions {
        no_commands: true,
        ..RosbagOptions::default()
    };
    recs.extend(import_rosbag(&fixtures().join("bad/wrong_names"), &unchecked).unwrap());
    let target = StoreTarget {
        out: &out,
        source: "real",
        urdf: &urdf(),
        robot: &robot,
        link,
        joints: &Default::default(),
    };
    let e = store(&recs, &target).unwrap_err().to_string();
    assert!(e.contains("joint_a"), "{e}");
    assert!(!out.exists(), "nothing is written when an episode fails");
    // Good episodes are stored and read back as they were.
    let good = bag("mcap/episode_000");
    let runs = store(&good, &target).unwrap().runs;
    let back = realitygap_data::RunStore::open(&out).unwrap();
    let read = back.read_run(&runs[0].id).unwrap();
    assert_eq!(read, runs[0].trajectory);
    assert!(out.join("runs/episode_000.commands.csv").is_file());
}
