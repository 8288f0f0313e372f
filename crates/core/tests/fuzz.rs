//! The robot description readers' damage campaign (see
//! `realitygap_core::testing::fuzz` and docs/testing.md): the URDF parser
//! and the mesh readers (binary and ASCII STL, Wavefront OBJ, COLLADA) get
//! damaged copies of real files (the project's Mico2, Kinova's m1n6s300
//! from the study's data, pybullet's KUKA iiwa and its STL and OBJ meshes,
//! the independent writer's OBJ, COLLADA and ASCII STL copies). Every input
//! must give a model or an error naming the file, with no panic and no
//! allocation beyond 64 x its size + 64 MiB.

use realitygap_core::robot::stl::TriangleMesh;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::testing::fuzz::{
    in_campaign_child, run_campaign_test, Campaign, Damage, Seed,
};
use realitygap_core::testing::workspace;
use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

realitygap_core::counting_global_allocator!();

/// The study's recordings with Kinova's `kinova_description`: the built-in
/// archive, unpacked into the cache once (as realitygap-data's tests do).
fn paper_data() -> PathBuf {
    use realitygap_data::builtin;
    let archive = builtin::StudyArchive::in_assets(&workspace().join("assets"))
        .unwrap_or_else(|e| panic!("{e}"));
    let cache = builtin::default_cache_root()
        .unwrap_or_else(|_| std::env::temp_dir().join("realitygap-test-cache"));
    builtin::open_or_unpack(&archive, &cache)
        .unwrap_or_else(|e| panic!("{e}"))
        .dir
}

fn files(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}: run scripts/setup --tests", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case(ext)))
        .collect();
    out.sort();
    assert!(!out.is_empty(), "no .{ext} files in {}", dir.display());
    out
}

fn seeds(paths: &[PathBuf]) -> Vec<Seed> {
    paths.iter().map(|p| Seed::file(p)).collect()
}

/// The damages for every format, with weights.
fn common() -> Vec<(Damage, u32)> {
    vec![
        (Damage::BitFlip, 3),
        (Damage::Byte, 2),
        (Damage::Insert, 2),
        (Damage::Delete, 2),
        (Damage::Truncate, 2),
        (Damage::DuplicateSpan, 1),
    ]
}

fn text() -> Vec<(Damage, u32)> {
    let mut d = common();
    d.extend([
        (Damage::Number, 6),
        (Damage::DeleteLine, 2),
        (Damage::DuplicateLine, 2),
        (Damage::SwapLines, 1),
    ]);
    d
}

fn xml() -> Vec<(Damage, u32)> {
    let mut d = common();
    d.extend([
        (Damage::Number, 6),
        (Damage::DeleteElement, 4),
        (Damage::DuplicateElement, 4),
        (Damage::DeleteAttribute, 4),
        (Damage::AttributeNumber, 6),
        (Damage::DuplicateAttribute, 2),
        (Damage::DeepNesting, 1),
    ]);
    d
}

fn meshes_fixture() -> PathBuf {
    workspace().join("third_party/fixtures/meshes")
}

fn iiwa_meshes() -> PathBuf {
    workspace().join("third_party/pybullet_data/kuka_iiwa/meshes")
}

#[test]
fn stl() {
    run_campaign_test(
        "stl",
        || {
            let mut paths = files(&iiwa_meshes(), "stl");
            paths.extend(files(
                &paper_data().join("kinova_description/meshes"),
                "stl",
            ));
            paths.extend(files(&meshes_fixture().join("stl_ascii"), "stl"));
            let mut damages = text();
            damages.extend([(Damage::LengthField(80), 12), (Damage::Float32(84), 6)]);
            Campaign {
                format: "stl".into(),
                seeds: seeds(&paths),
                per_seed: 50,
                damages,
            }
        },
        |bytes, path| {
            TriangleMesh::parse(bytes, path)
                .map(drop)
                .map_err(|e| e.to_string())
        },
    );
}

#[test]
fn obj() {
    run_campaign_test(
        "obj",
        || {
            let mut paths = files(&iiwa_meshes(), "obj");
            paths.extend(files(&meshes_fixture().join("obj"), "obj"));
            let mut seeds = seeds(&paths);
            let mut bad = Seed::file(&meshes_fixture().join("bad/bad_index.obj"));
            bad.valid = false;
            seeds.push(bad);
            Campaign {
                format: "obj".into(),
                seeds,
                per_seed: 90,
                damages: text(),
            }
        },
        |bytes, path| {
            TriangleMesh::parse_obj(bytes, path)
                .map(drop)
                .map_err(|e| e.to_string())
        },
    );
}

#[test]
fn collada() {
    run_campaign_test(
        "collada",
        || {
            let mut seeds = seeds(&files(&meshes_fixture().join("dae"), "dae"));
            for bad in ["truncated.dae", "not_xml.dae"] {
                let mut s = Seed::file(&meshes_fixture().join("bad").join(bad));
                s.valid = false;
                seeds.push(s);
            }
            Campaign {
                format: "collada".into(),
                seeds,
                per_seed: 150,
                damages: xml(),
            }
        },
        |bytes, path| {
            TriangleMesh::parse_collada(bytes, path)
                .map(drop)
                .map_err(|e| e.to_string())
        },
    );
}

/// Writes each damaged URDF where the reader finds it as a user's file:
/// in a scratch folder beside links to everything in the original's
/// folder (its meshes), under the original's name.
struct UrdfWriter {
    scratch: PathBuf,
    mirrors: RefCell<HashMap<PathBuf, PathBuf>>,
}

impl UrdfWriter {
    fn new() -> Self {
        let scratch =
            std::env::temp_dir().join(format!("realitygap-fuzz-urdf-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&scratch);
        std::fs::create_dir_all(&scratch).unwrap();
        UrdfWriter {
            scratch,
            mirrors: RefCell::new(HashMap::new()),
        }
    }

    fn write(&self, original: &Path, bytes: &[u8]) -> PathBuf {
        let dir = original.parent().unwrap().to_path_buf();
        let mut mirrors = self.mirrors.borrow_mut();
        let n = mirrors.len();
        let mirror = mirrors
            .entry(dir.clone())
            .or_insert_with(|| {
                let m = self.scratch.join(n.to_string());
                std::fs::create_dir_all(&m).unwrap();
                for entry in std::fs::read_dir(&dir).unwrap() {
                    let p = entry.unwrap().path();
                    if p.extension().is_some_and(|x| x == "urdf") {
                        continue;
                    }
                    std::os::unix::fs::symlink(&p, m.join(p.file_name().unwrap())).unwrap();
                }
                m
            })
            .clone();
        let path = mirror.join(original.file_name().unwrap());
        std::fs::write(&path, bytes).unwrap();
        path
    }
}

impl Drop for UrdfWriter {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.scratch);
    }
}

#[test]
fn urdf() {
    let paper = std::env::var_os("REALITYGAP_FUZZ_CHILD").map(|_| paper_data());
    let mut resolver = PackageResolver::new();
    if let Some(paper) = &paper {
        resolver.insert("kinova_description", paper.join("kinova_description"));
    }
    let writer = UrdfWriter::new();
    run_campaign_test(
        "urdf",
        || {
            let paper = paper.clone().unwrap();
            let fixtures = meshes_fixture();
            let paths = [
                workspace().join("assets/robots/mico2/mico2.urdf"),
                paper.join("kinova_description/urdf/m1n6s300.urdf"),
                workspace().join("third_party/pybullet_data/kuka_iiwa/model.urdf"),
                fixtures.join("model_obj.urdf"),
                fixtures.join("model_dae.urdf"),
            ];
            let mut damages = xml();
            damages.extend([(Damage::DeleteLine, 1), (Damage::DuplicateLine, 1)]);
            Campaign {
                format: "urdf".into(),
                seeds: seeds(&paths),
                per_seed: 300,
                damages,
            }
        },
        |bytes, original| {
            let path = writer.write(original, bytes);
            RobotModel::from_urdf_file(&path, &resolver)
                .map(drop)
                .map_err(|e| e.to_string())
        },
    );
}

/// A campaign of three damaged copies of one tiny seed, whose reader
/// panics on the seed and makes one allocation of `bytes` bytes on every
/// other input (refusing it with an error naming the file).
fn faulty_campaign(test: &str, bytes: usize) {
    let seed = Seed {
        path: PathBuf::from("x.bin"),
        name: "x.bin".into(),
        bytes: b"abcdef".to_vec(),
        valid: true,
    };
    run_campaign_test(
        test,
        || Campaign {
            format: "harness".into(),
            seeds: vec![seed.clone()],
            per_seed: 3,
            damages: vec![(Damage::BitFlip, 1)],
        },
        |input, _| {
            if input == b"abcdef" {
                panic!("boom");
            }
            let v: Vec<u8> = Vec::with_capacity(bytes);
            std::hint::black_box(&v);
            Err("x.bin: refused".into())
        },
    );
}

fn panic_message(test: impl FnOnce() + std::panic::UnwindSafe) -> String {
    let e = std::panic::catch_unwind(test).unwrap_err();
    e.downcast_ref::<String>()
        .cloned()
        .unwrap_or_else(|| format!("{:?}", e.downcast_ref::<&str>()))
}

/// The campaign's checks can fail: a panic and allocations over 64 x the
/// input + 64 MiB (here 200 MiB for 6 bytes) fail the test, naming each
/// input.
#[test]
fn the_harness_fails_on_panics_and_oversized_allocations() {
    let test = "the_harness_fails_on_panics_and_oversized_allocations";
    if in_campaign_child() {
        return faulty_campaign(test, 200 << 20);
    }
    let message = panic_message(|| faulty_campaign(test, 200 << 20));
    assert!(
        message.contains("harness:0 (seed x.bin; undamaged): panicked: boom at "),
        "{message}"
    );
    for i in 1..=3 {
        assert!(
            message.contains(&format!("harness:{i} (seed x.bin; flip bit")),
            "{message}"
        );
    }
    assert!(
        message.contains(": an allocation of 209715200 bytes for an input of 6 bytes"),
        "{message}"
    );
}

/// An allocation beyond 1 GiB is refused: the child process aborts, and
/// the test fails with the input it was reading.
#[test]
fn the_harness_fails_on_an_abort_naming_the_input() {
    let test = "the_harness_fails_on_an_abort_naming_the_input";
    if in_campaign_child() {
        return faulty_campaign(test, 3 << 30);
    }
    let message = panic_message(|| faulty_campaign(test, 3 << 30));
    assert!(
        message.contains("child process failed (signal: 6"),
        "{message}"
    );
    assert!(
        message.contains("input harness:1 (seed x.bin; flip bit"),
        "{message}"
    );
    assert!(
        message.contains("fuzz: refusing an allocation of 3221225472 bytes"),
        "{message}"
    );
}
