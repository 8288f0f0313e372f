//! The reader and the import against three real published tosses
//! (`tests/data`, the independent writer's output: PyTorch's legacy
//! `torch.save`), and against damaged copies of them made here by changing
//! bytes: each a located error, and no results directory written.

use realitygap_contactnets::{import, read_pt, Experiment, Toss};
use realitygap_data::RunStore;
use std::path::{Path, PathBuf};

/// The committed tosses.
fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

fn fixture(number: u64) -> Vec<u8> {
    std::fs::read(data().join(format!("tosses/{number}.pt"))).unwrap()
}

/// The published values of a file, decoded here straight from its last
/// `8 T 19` bytes (the raw storage), without the reader.
fn raw_values(bytes: &[u8], samples: usize) -> Vec<[f64; 19]> {
    let tail = &bytes[bytes.len() - 8 * 19 * samples..];
    tail.chunks_exact(8 * 19)
        .map(|row| {
            std::array::from_fn(|c| f64::from_le_bytes(row[8 * c..8 * c + 8].try_into().unwrap()))
        })
        .collect()
}

/// Index of the first occurrence of `pattern` in `bytes`.
fn find(bytes: &[u8], pattern: &[u8]) -> usize {
    bytes
        .windows(pattern.len())
        .position(|w| w == pattern)
        .unwrap_or_else(|| panic!("pattern {pattern:?} not in the file"))
}

/// `bytes` with the first `old` replaced by `new`.
fn replaced(bytes: &[u8], old: &[u8], new: &[u8]) -> Vec<u8> {
    let i = find(bytes, old);
    let mut out = bytes[..i].to_vec();
    out.extend_from_slice(new);
    out.extend_from_slice(&bytes[i + old.len()..]);
    out
}

/// A folder of tosses: the fixtures 185 and 563 as they are, and `bad` as
/// `229.pt`; returns the temporary folder, the tosses' folder and the
/// results directory an import would write.
fn folder_with(bad: &[u8]) -> (tempfile::TempDir, PathBuf, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tosses");
    std::fs::create_dir(&dir).unwrap();
    for n in [185, 563] {
        std::fs::write(dir.join(format!("{n}.pt")), fixture(n)).unwrap();
    }
    std::fs::write(dir.join("229.pt"), bad).unwrap();
    let out = tmp.path().join("real");
    (tmp, dir, out)
}

/// Imports the folder, which must fail without writing anything; returns
/// the message with the folder's path replaced by `DIR`.
fn import_error(tmp: &tempfile::TempDir, dir: &Path, out: &Path) -> String {
    let e = import(dir, None, out, "real").unwrap_err().to_string();
    assert!(!out.exists(), "{} was written: {e}", out.display());
    e.replace(&tmp.path().display().to_string(), "DIR")
}

#[test]
fn the_published_tosses_read_as_published() {
    let experiment = Experiment::read(&data().join("experiment.json")).unwrap();
    assert_eq!(
        experiment,
        Experiment {
            file: experiment.file.clone(),
            ..Experiment::published()
        }
    );
    for (number, samples) in [(185, 84), (229, 80), (563, 367)] {
        let bytes = fixture(number);
        let path = data().join(format!("tosses/{number}.pt"));
        let tensor = read_pt(&bytes, &path).unwrap();
        assert_eq!(tensor.shape, vec![1, samples, 19]);
        assert_eq!(tensor.values_at, bytes.len() - 8 * 19 * samples);
        let raw = raw_values(&bytes, samples);
        let toss = Toss::from_tensor(&tensor, number, &path, &experiment).unwrap();
        assert_eq!(toss.len(), samples);
        assert!(toss.warnings.is_empty(), "{:?}", toss.warnings);
        assert!(toss.max_quat_norm_error < 1e-6);
        let half_width = 9.81 / 187.21374045801525;
        for (k, row) in raw.iter().enumerate() {
            assert_eq!(toss.time_s[k], k as f64 * 0.006756756756756757);
            let p = toss.poses[k];
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs().max(1.0);
            for (got, c) in [p.position_m.x, p.position_m.y, p.position_m.z]
                .into_iter()
                .zip(0..3)
            {
                assert!(
                    close(got, row[c] * half_width),
                    "toss {number} sample {k} column {c}"
                );
            }
            let q = p.orientation;
            for (got, c) in [q.w, q.x, q.y, q.z].into_iter().zip(3..7) {
                assert!(close(got, row[c]), "toss {number} sample {k} column {c}");
            }
            let w = toss.twists[k];
            let v = w.linear_m_s;
            for (got, c) in [v.x, v.y, v.z].into_iter().zip(7..10) {
                assert!(
                    close(got, row[c] * half_width),
                    "toss {number} sample {k} column {c}"
                );
            }
            let a = w.angular_body_rad_s;
            assert_eq!([a.x, a.y, a.z], [row[10], row[11], row[12]]);
            assert_eq!(row[13..], [0.0; 6]);
        }
    }
}

#[test]
fn import_writes_one_real_run_per_toss() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("real");
    let imported = import(&data().join("tosses"), None, &out, "real").unwrap();
    // The experiment beside the folder (the published layout) is used.
    assert_eq!(
        imported.experiment.file.as_deref(),
        Some(data().join("tosses/../experiment.json").as_path())
    );
    assert_eq!(
        imported.runs,
        vec![("185".into(), 84), ("229".into(), 80), ("563".into(), 367)]
    );
    assert_eq!(imported.replaced, 0);
    let store = RunStore::open(&out).unwrap();
    let m = store.manifest();
    assert_eq!(
        (
            m.source.as_str(),
            m.kind.to_string().as_str(),
            m.scene.as_deref()
        ),
        ("real", "real", None)
    );
    let s = &m.settings;
    assert_eq!(s["importer"], "contactnets");
    assert!(s["licence"].as_str().unwrap().starts_with("BSD-3-Clause"));
    assert_eq!(s["object"]["role"], "cube");
    assert_eq!(s["object"]["mass_kg"], 0.37);
    assert!((s["object"]["edge_m"].as_f64().unwrap() - 0.1048).abs() < 1e-12);
    assert!((s["units"]["half_width_m"].as_f64().unwrap() - 0.0524).abs() < 1e-12);
    assert_eq!(s["published"]["mu"], 0.18);
    assert_eq!(s["published"]["restitution"], 0.125);
    assert_eq!(s["frequency_hz"].as_f64().unwrap().round(), 148.0);

    let experiment = Experiment::published();
    for (id, samples) in [("185", 84), ("229", 80), ("563", 367)] {
        let entry = store.run(id).unwrap();
        assert_eq!(entry.file, format!("runs/{id}.csv"));
        assert_eq!(
            entry.velocities_file.as_deref(),
            Some(format!("runs/{id}.velocities.csv").as_str())
        );
        assert_eq!(entry.extra["samples"], samples);
        let toss = Toss::read(
            &data().join(format!("tosses/{id}.pt")),
            id.parse().unwrap(),
            &experiment,
        )
        .unwrap();
        let run = store.read_run(id).unwrap();
        assert_eq!(run, toss.trajectory());
        assert_eq!(run.bodies[0].role, "cube");
        assert_eq!(
            store.read_run_velocities(id).unwrap(),
            vec![toss.velocities()]
        );
    }
    let header = std::fs::read_to_string(out.join("runs/229.csv")).unwrap();
    assert!(
        header.starts_with("t_s,cube_x_m,cube_y_m,cube_z_m,cube_qw,cube_qx,cube_qy,cube_qz\n0,"),
        "{header:.80}"
    );

    // A second import replaces the runs.
    let again = import(&data().join("tosses"), None, &out, "real").unwrap();
    assert_eq!(again.replaced, 3);
    // Another source in the same directory is refused.
    let e = import(&data().join("tosses"), None, &out, "other")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("holds source 'real' (real), scene (none), not source 'other'"),
        "{e}"
    );
}

#[test]
fn an_experiment_file_sets_the_units() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("e.json");
    // g twice the published: half-widths are half as long in metres.
    std::fs::write(
        &file,
        "{\"dt\": 0.01, \"g\": 374.4274809160305, \"mass\": 0.5}",
    )
    .unwrap();
    let out = tmp.path().join("real");
    let imported = import(&data().join("tosses"), Some(&file), &out, "real").unwrap();
    assert!((imported.experiment.half_width_m() - 0.0262).abs() < 1e-12);
    let store = RunStore::open(&out).unwrap();
    let run = store.read_run("229").unwrap();
    assert!((run.time_s[1] - 0.01).abs() < 1e-15);
    let published =
        Toss::read(&data().join("tosses/229.pt"), 229, &Experiment::published()).unwrap();
    let z = run.bodies[0].poses[0].unwrap().position_m.z;
    assert!((z - published.poses[0].position_m.z / 2.0).abs() < 1e-15);
    assert!(store.manifest().settings["published"]["mu"].is_null());
    assert_eq!(store.manifest().settings["object"]["mass_kg"], 0.5);
    // A broken one stops the import before anything is written.
    std::fs::write(&file, "{\"dt\": 0.01}").unwrap();
    let out = tmp.path().join("real2");
    let e = import(&data().join("tosses"), Some(&file), &out, "real")
        .unwrap_err()
        .to_string();
    assert!(
        e.ends_with("e.json: g: missing: the gravity in half-widths/s²"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn a_truncated_toss_is_a_located_error() {
    let good = fixture(229);
    let (tmp, dir, out) = folder_with(&good[..good.len() - 100]);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 336 (storage): the file is truncated: the storage's 1520 float64 values need 12160 bytes, the file ends 12060 bytes later (at byte 12396)"
    );
    // Cut inside the pickles, or inside the element count.
    let (tmp, dir, out) = folder_with(&good[..241]);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 241 (tensor): the file is truncated: it ends inside a pickle (no STOP opcode)"
    );
    let (tmp, dir, out) = folder_with(&good[..200]);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 197 (tensor): the file is truncated: it ends inside a global's name (at byte 200)"
    );
    let (tmp, dir, out) = folder_with(&good[..330]);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 328 (storage element count): the file is truncated: storage element count needs 8 bytes, the file ends 2 bytes later (at byte 330)"
    );
    // Bytes after the storage are not silently dropped.
    let mut long = good.clone();
    long.extend_from_slice(&[0; 8]);
    let (tmp, dir, out) = folder_with(&long);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 12496 (end of file): 8 bytes after the storage's end; a legacy .pt file of one tensor ends there"
    );
}

#[test]
fn a_float_tensor_is_a_located_error() {
    let float = replaced(
        &fixture(229),
        b"torch\nDoubleStorage\n",
        b"torch\nFloatStorage\n",
    );
    let (tmp, dir, out) = folder_with(&float);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 190 (storage type): the tensor's storage is torch.FloatStorage (float32 values); expected torch.DoubleStorage (float64 values)"
    );
}

#[test]
fn a_wrong_shape_is_a_located_error() {
    let good = fixture(229);
    // size (1, 80, 19) and strides (1520, 19, 1) as a 2-D (80, 19) tensor
    let flat = replaced(&good, b"K\x01KPK\x13\x87", b"KPK\x13\x86");
    let flat = replaced(&flat, b"M\xf0\x05K\x13K\x01\x87", b"K\x13K\x01\x86");
    let (tmp, dir, out) = folder_with(&flat);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 248 (tensor size): expected a 1 x T x 19 tensor (one toss: T > 0 samples of 19 columns), found 80 x 19"
    );
    // (1, 76, 20), strides to match: 20 columns
    let wide = replaced(&good, b"K\x01KPK\x13\x87", b"K\x01KLK\x14\x87");
    let wide = replaced(
        &wide,
        b"M\xf0\x05K\x13K\x01\x87",
        b"M\xf0\x05K\x14K\x01\x87",
    );
    let (tmp, dir, out) = folder_with(&wide);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 248 (tensor size): expected a 1 x T x 19 tensor (one toss: T > 0 samples of 19 columns), found 1 x 76 x 20"
    );
    // A size that the storage does not hold.
    let more = replaced(&good, b"K\x01KPK\x13\x87", b"K\x01KQK\x13\x87");
    let (tmp, dir, out) = folder_with(&more);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 238 (storage size): the storage holds 1520 elements, the tensor's size [1, 81, 19] needs 1539"
    );
}

#[test]
fn a_layout_that_is_not_contiguous_is_a_located_error() {
    let good = fixture(229);
    let strided = replaced(
        &good,
        b"M\xf0\x05K\x13K\x01\x87",
        b"M\xf0\x05K\x13K\x02\x87",
    );
    let (tmp, dir, out) = folder_with(&strided);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 257 (tensor stride): strides [1520, 19, 2] for size [1, 80, 19] are not those of a contiguous tensor (1 expected in dimension 2)"
    );
    let offset = replaced(&good, b"QK\x00", b"QK\x05");
    let (tmp, dir, out) = folder_with(&offset);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/229.pt: byte 246 (storage offset): the tensor starts at element 5 of its storage; only a tensor from the storage's first element is read"
    );
}

#[test]
fn a_nan_in_a_pose_is_a_located_error() {
    let good = fixture(229);
    let values_at = good.len() - 8 * 19 * 80;
    // Sample 12 (0-based 11), qw (column 3).
    let at = values_at + 8 * (11 * 19 + 3);
    let mut nan = good.clone();
    nan[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let (tmp, dir, out) = folder_with(&nan);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        format!(
            "DIR/tosses/229.pt: byte {at} (sample 12 of 80, column qw): NaN in the cube's pose"
        )
    );
    // An infinite velocity, and a quaternion far from unit norm.
    let at = values_at + 8 * (79 * 19 + 8);
    let mut inf = good.clone();
    inf[at..at + 8].copy_from_slice(&f64::NEG_INFINITY.to_le_bytes());
    let (tmp, dir, out) = folder_with(&inf);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        format!("DIR/tosses/229.pt: byte {at} (sample 80 of 80, column vy): -inf in the cube's velocity")
    );
    let at = values_at + 8 * 3;
    let mut half = good.clone();
    let raw = raw_values(&good, 80);
    for (c, x) in raw[0][3..7].iter().enumerate() {
        half[at + 8 * c..at + 8 * c + 8].copy_from_slice(&(x * 0.5).to_le_bytes());
    }
    let (tmp, dir, out) = folder_with(&half);
    let e = import_error(&tmp, &dir, &out);
    assert!(
        e.starts_with(&format!("DIR/tosses/229.pt: byte {at} (sample 1 of 80, column qw): the orientation quaternion's norm is 0.500000, not 1 (within 0.001)")),
        "{e}"
    );
}

#[test]
fn an_unknown_opcode_is_a_located_error() {
    // NEWFALSE (requires_grad) replaced by BINFLOAT, which no such file uses.
    let good = fixture(229);
    let i = find(&good, b"\x89ccollections");
    let mut bad = good.clone();
    bad[i] = b'G';
    let (tmp, dir, out) = folder_with(&bad);
    assert_eq!(
        import_error(&tmp, &dir, &out),
        format!("DIR/tosses/229.pt: byte {i} (tensor): unknown pickle opcode 0x47 ('G'): not one a legacy .pt file of one tensor uses")
    );
    // Another magic number: not a legacy .pt file.
    let mut bad = good.clone();
    bad[4] ^= 0xff;
    let (tmp, dir, out) = folder_with(&bad);
    let e = import_error(&tmp, &dir, &out);
    assert!(
        e.starts_with(
            "DIR/tosses/229.pt: byte 2 (magic number): expected PyTorch's legacy magic number"
        ),
        "{e}"
    );
}

#[test]
fn bad_folders_are_located_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("real");
    let dir = tmp.path().join("tosses");
    std::fs::create_dir(&dir).unwrap();
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses: no toss files (N.pt) in this folder"
    );
    std::fs::write(dir.join("229.pt"), fixture(229)).unwrap();
    std::fs::write(dir.join("notes.txt"), "tosses").unwrap();
    assert_eq!(
        import_error(&tmp, &dir, &out),
        "DIR/tosses/notes.txt: not a toss file: a folder of tosses holds only N.pt files (N the toss's number) and an experiment.json"
    );
    std::fs::remove_file(dir.join("notes.txt")).unwrap();
    std::fs::write(dir.join("first.pt"), fixture(229)).unwrap();
    let e = import_error(&tmp, &dir, &out);
    assert!(e.starts_with("DIR/tosses/first.pt: not a toss file"), "{e}");
    std::fs::remove_file(dir.join("first.pt")).unwrap();
    std::fs::write(dir.join("0229.pt"), fixture(229)).unwrap();
    let e = import_error(&tmp, &dir, &out);
    assert!(e.contains("toss 229 again:"), "{e}");
    let e = import_error(&tmp, &tmp.path().join("nowhere"), &out);
    assert!(
        e.starts_with("DIR/nowhere: cannot read the folder of tosses:"),
        "{e}"
    );
}
