//! Random damage to every importer's input: never a panic, whatever the
//! bytes. The inputs are the independent writer's fixtures
//! (`scripts/make-fixtures`), cut, flipped and overwritten at random.

use proptest::prelude::*;
use realitygap_core::testing::joint_recording_fixtures as fixtures;
use realitygap_recordings::csvfile::{parse_csv, CsvOptions};
use realitygap_recordings::lerobot::{import_lerobot, LeRobotOptions};
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use std::path::{Path, PathBuf};

/// The one storage file of a bag folder with this extension.
fn storage_file(rel: &str, ext: &str) -> PathBuf {
    std::fs::read_dir(fixtures().join(rel))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == ext))
        .unwrap()
}

/// A damage: cut at a fraction, then overwrite bytes at fractions.
#[derive(Debug, Clone)]
struct Damage {
    cut: Option<f64>,
    writes: Vec<(f64, u8)>,
}

fn damage() -> impl Strategy<Value = Damage> {
    (
        proptest::option::of(0.0f64..1.0),
        proptest::collection::vec((0.0f64..1.0, any::<u8>()), 0..12),
    )
        .prop_map(|(cut, writes)| Damage { cut, writes })
}

fn apply(bytes: &[u8], d: &Damage) -> Vec<u8> {
    let mut b = bytes.to_vec();
    if let Some(c) = d.cut {
        b.truncate((b.len() as f64 * c) as usize);
    }
    for &(at, v) in &d.writes {
        if !b.is_empty() {
            let i = ((b.len() - 1) as f64 * at) as usize;
            b[i] = v;
        }
    }
    b
}

fn opts() -> RosbagOptions {
    RosbagOptions {
        robot_joints: (1..=7).map(|j| format!("lbr_iiwa_joint_{j}")).collect(),
        ..RosbagOptions::default()
    }
}

/// Writes damaged bytes as `name` in a fresh folder.
fn damaged_copy(original: &Path, d: &Damage) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join(original.file_name().unwrap());
    std::fs::write(&out, apply(&std::fs::read(original).unwrap(), d)).unwrap();
    (tmp, out)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn damaged_mcap_never_panics(d in damage()) {
        let (_tmp, file) = damaged_copy(&storage_file("mcap_trajectory/episode_000", "mcap"), &d);
        let _ = import_rosbag(&file, &opts());
    }

    #[test]
    fn damaged_sqlite3_never_panics(d in damage()) {
        let (_tmp, file) = damaged_copy(&storage_file("sqlite3/episode_000", "db3"), &d);
        let _ = import_rosbag(&file, &opts());
    }

    #[test]
    fn damaged_csv_never_panics(d in damage()) {
        let bytes = std::fs::read(fixtures().join("csv/episode_000.csv")).unwrap();
        let _ = parse_csv(&apply(&bytes, &d), Path::new("episode_000.csv"), &CsvOptions::default());
    }

    #[test]
    fn damaged_lerobot_never_panics(d in damage(), which in 0usize..2) {
        let src = fixtures().join("lerobot");
        let tmp = tempfile::tempdir().unwrap();
        let dst = tmp.path().join("lerobot");
        for rel in ["meta/info.json", "data/chunk-000/file-000.parquet"] {
            let to = dst.join(rel);
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            let bytes = std::fs::read(src.join(rel)).unwrap();
            let is_target = rel.ends_with(if which == 0 { ".json" } else { ".parquet" });
            std::fs::write(&to, if is_target { apply(&bytes, &d) } else { bytes }).unwrap();
        }
        let _ = import_lerobot(&dst, &LeRobotOptions::default());
    }
}
