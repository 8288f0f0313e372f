//! The recording importers' damage campaign (see
//! `realitygap_core::testing::fuzz` and docs/testing.md): the Qualisys TSV
//! reader gets damaged copies of the study's motion capture (whole files and
//! their first lines, headerless and with Qualisys' header block), the
//! `recorded` reader damaged copies of the study's simulator files (every
//! simulator, both quaternion orders). Every input must give a run or an
//! error naming the file, with no panic and no allocation beyond 64 x its
//! size + 64 MiB.

use realitygap_core::testing::fuzz::{run_campaign_test, Campaign, Damage, Seed};
use realitygap_data::builtin;
use realitygap_data::qualisys::{self, QualisysOptions};
use realitygap_data::recorded::{self, QuatOrder, RecordedOptions};
use std::path::{Path, PathBuf};

realitygap_core::counting_global_allocator!();

/// The study's recordings: the built-in archive, unpacked into the cache
/// once (as the crate's own tests do).
fn paper_data() -> PathBuf {
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let archive = builtin::StudyArchive::in_assets(&assets).unwrap_or_else(|e| panic!("{e}"));
    let cache = builtin::default_cache_root()
        .unwrap_or_else(|_| std::env::temp_dir().join("realitygap-test-cache"));
    builtin::open_or_unpack(&archive, &cache)
        .unwrap_or_else(|e| panic!("{e}"))
        .dir
}

fn text_damages() -> Vec<(Damage, u32)> {
    vec![
        (Damage::BitFlip, 3),
        (Damage::Byte, 2),
        (Damage::Insert, 3),
        (Damage::Delete, 2),
        (Damage::Truncate, 2),
        (Damage::DuplicateSpan, 1),
        (Damage::Number, 6),
        (Damage::DeleteLine, 2),
        (Damage::DuplicateLine, 2),
        (Damage::SwapLines, 2),
    ]
}

/// The first `n` lines of a file, as a seed named after it.
fn head(seed: &Seed, n: usize) -> Seed {
    let end = seed
        .bytes
        .iter()
        .enumerate()
        .filter(|(_, &b)| b == b'\n')
        .nth(n - 1)
        .map_or(seed.bytes.len(), |(i, _)| i + 1);
    Seed {
        name: format!("{} (first {n} lines)", seed.name),
        bytes: seed.bytes[..end].to_vec(),
        ..seed.clone()
    }
}

/// Every `step`th file of a folder with this extension, sorted.
fn every(dir: &Path, ext: &str, step: usize) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .collect();
    out.sort();
    out.into_iter().step_by(step).collect()
}

#[test]
fn qualisys() {
    run_campaign_test(
        "qualisys",
        || {
            let mocap = paper_data().join("MotionCapture");
            // The header-block sample and 3 runs of each experiment, whole
            // and cut to their first lines (where a header is hit often).
            let mut seeds = vec![Seed::file(&mocap.join("Data_Format.tsv"))];
            for experiment in ["Experiment1", "Experiment2", "Experiment3"] {
                seeds.extend(
                    every(&mocap.join(experiment), "tsv", 7)
                        .iter()
                        .map(|p| Seed::file(p)),
                );
            }
            let heads: Vec<Seed> = seeds.iter().map(|s| head(s, 40)).collect();
            seeds.extend(heads);
            Campaign {
                format: "qualisys".into(),
                seeds,
                per_seed: 75,
                damages: text_damages(),
            }
        },
        |bytes, path| {
            qualisys::parse(bytes, path, &QualisysOptions::collins2019())
                .map(drop)
                .map_err(|e| e.to_string())
        },
    );
}

#[test]
fn recorded() {
    run_campaign_test(
        "recorded",
        || {
            let sim = paper_data().join("Simulation");
            let mut seeds = Vec::new();
            for experiment in ["Experiment1", "Experiment2", "Experiment3"] {
                seeds.extend(
                    every(&sim.join(experiment), "csv", 20)
                        .iter()
                        .map(|p| Seed::file(p)),
                );
            }
            // The format description's two header lines are skipped as a
            // header.
            seeds.push(Seed::file(&sim.join("Sim_Data_Format.csv")));
            Campaign {
                format: "recorded".into(),
                seeds,
                per_seed: 70,
                damages: text_damages(),
            }
        },
        |bytes, path| {
            let name = path.file_name().unwrap().to_string_lossy();
            let order = if name.contains("Mujoco") {
                QuatOrder::Wxyz
            } else {
                QuatOrder::Xyzw
            };
            recorded::parse(bytes, path, &RecordedOptions::new(order))
                .map(drop)
                .map_err(|e| e.to_string())
        },
    );
}
