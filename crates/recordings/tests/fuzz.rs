//! The fuzz campaign of the joint-recording importers: the independent
//! writer's seed files (`fuzz_seeds/` of `scripts/make-fixtures`: MCAP with
//! zstd chunks, MCAP with JointTrajectory messages, a sqlite3 bag, a CSV
//! file, a LeRobot dataset of parquet files; CDR payloads come through the
//! bags) damaged in several thousand deterministic ways: bit flips,
//! truncations, random bytes, and length fields (u32 and u64, little- and
//! big-endian, and parquet's varints) set to huge values, with the MCAP
//! records' own length fields found and damaged one by one.
//!
//! For every input: no panic (caught), and no single allocation larger than
//! 64 times the input and 64 MiB, counted by this binary's global
//! allocator. An allocation the system cannot serve would abort the
//! process, so each format runs in a child process (this binary, the
//! ignored test `fuzz_child`): the parent test fails, naming the input,
//! where the child aborted. Each child prints how many inputs it ran and
//! how many imported and how many were refused.
//!
//! `REALITYGAP_FUZZ_INPUTS` sets the inputs per seed (default 700);
//! `REALITYGAP_FUZZ_ONLY=LABEL` runs only the inputs whose label starts
//! so (`lerobot #2693:`, as a failure names it), showing panics.

use realitygap_core::testing::joint_recording_fixtures as fixtures;
use realitygap_recordings::csvfile::{parse_csv, CsvOptions};
use realitygap_recordings::lerobot::{import_lerobot, LeRobotOptions};
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, noting the largest single request.
struct Counting;

/// The largest request since the last reset, bytes.
static LARGEST: AtomicUsize = AtomicUsize::new(0);

fn note(size: usize) {
    LARGEST.fetch_max(size, Ordering::Relaxed);
}

// SAFETY: every call is passed on to `System` with the caller's arguments,
// which uphold `GlobalAlloc`'s contract; only a counter is updated besides.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: the caller's layout, as `GlobalAlloc::alloc` requires.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: the caller's layout, as `GlobalAlloc::alloc_zeroed` requires.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        // SAFETY: the caller's pointer, layout and size, as required.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's pointer and layout, as required.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The formats, each a child process.
const FORMATS: [&str; 5] = ["mcap_zstd", "mcap_trajectory", "sqlite3", "csv", "lerobot"];

/// A deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Huge values for a length field.
const HUGE: [u64; 7] = [
    u64::MAX,
    1 << 63,
    1 << 61,
    0x2C68_AF0B_B140_0000, // about 3.2 EB
    0xFFFF_FFFF,
    0x8000_0000,
    0x7FFF_FFFF,
];

/// The u32 and u64 length fields of an MCAP file's records: every
/// record's length, a chunk's sizes, and (outside compressed chunks) the
/// string and byte-array lengths of schema and channel records.
fn mcap_length_fields(data: &[u8]) -> Vec<(usize, usize)> {
    let u32_at = |p: usize| {
        data.get(p..p + 4)
            .map_or(0, |b| u32::from_le_bytes(b.try_into().unwrap()) as usize)
    };
    let u64_at = |p: usize| {
        data.get(p..p + 8)
            .map_or(0, |b| u64::from_le_bytes(b.try_into().unwrap()) as usize)
    };
    let mut out = Vec::new();
    let mut stack = vec![(8usize, data.len().saturating_sub(8))];
    while let Some((mut pos, end)) = stack.pop() {
        while pos + 9 <= end {
            let (op, len) = (data[pos], u64_at(pos + 1));
            out.push((pos + 1, 8));
            let body = pos + 9;
            match op {
                // Schema: id u16, name, encoding, data (u32 lengths).
                0x03 => {
                    let name = body + 2;
                    let encoding = name + 4 + u32_at(name);
                    let bytes = encoding + 4 + u32_at(encoding);
                    out.extend([(name, 4), (encoding, 4), (bytes, 4)]);
                }
                // Channel: id u16, schema id u16, topic, encoding, metadata.
                0x04 => {
                    let topic = body + 4;
                    let encoding = topic + 4 + u32_at(topic);
                    let meta = encoding + 4 + u32_at(encoding);
                    out.extend([(topic, 4), (encoding, 4), (meta, 4)]);
                }
                // Chunk: sizes, and the records inside when uncompressed.
                0x06 => {
                    let comp = u32_at(body + 28);
                    let records = body + 32 + comp;
                    out.extend([(body + 16, 8), (body + 28, 4), (records, 8)]);
                    if comp == 0 {
                        let inner_end = (records + 8).saturating_add(u64_at(records)).min(end);
                        stack.push((records + 8, inner_end));
                    }
                }
                _ => {}
            }
            pos = match body.checked_add(len) {
                Some(p) => p,
                None => break,
            };
        }
    }
    out.retain(|&(at, width)| at + width <= data.len());
    out
}

/// One damaged copy of `seed`, and what was done.
fn damage(seed: &[u8], fields: &[(usize, usize)], rng: &mut Rng, kind: usize) -> (Vec<u8>, String) {
    let mut b = seed.to_vec();
    let n = b.len().max(1);
    let what = match kind % 8 {
        0 => {
            let at = rng.below(n * 8);
            if let Some(x) = b.get_mut(at / 8) {
                *x ^= 1 << (at % 8);
            }
            format!("bit flip at byte {}, bit {}", at / 8, at % 8)
        }
        1 => {
            let flips = 2 + rng.below(15);
            for _ in 0..flips {
                let at = rng.below(n * 8);
                if let Some(x) = b.get_mut(at / 8) {
                    *x ^= 1 << (at % 8);
                }
            }
            format!("{flips} bit flips")
        }
        2 => {
            let keep = rng.below(n);
            b.truncate(keep);
            format!("truncated to {keep} bytes")
        }
        3 if !fields.is_empty() => {
            let (at, width) = fields[rng.below(fields.len())];
            let v = HUGE[rng.below(HUGE.len())];
            b[at..at + width].copy_from_slice(&v.to_le_bytes()[..width]);
            format!("length field at byte {at} ({width} bytes) set to {v:#x}")
        }
        3 | 4 => {
            let width = if rng.below(2) == 0 { 4 } else { 8 };
            let at = rng.below(n.saturating_sub(width).max(1)) & !(width - 1);
            let v = HUGE[rng.below(HUGE.len())];
            let bytes = if rng.below(2) == 0 {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            };
            if at + width <= b.len() {
                b[at..at + width].copy_from_slice(&bytes[..width]);
            }
            format!("{width}-byte field at byte {at} set to {v:#x}")
        }
        5 => {
            // A varint that never ends small (parquet's Thrift lengths).
            let at = rng.below(n);
            for (k, x) in b.iter_mut().skip(at).take(5).enumerate() {
                *x = if k < 4 { 0xFF } else { 0x0F };
            }
            format!("varint 0xFFFFFFFF0F at byte {at}")
        }
        6 => {
            let writes = 1 + rng.below(8);
            for _ in 0..writes {
                let at = rng.below(n);
                let v = rng.next() as u8;
                if let Some(x) = b.get_mut(at) {
                    *x = v;
                }
            }
            format!("{writes} random bytes")
        }
        _ => {
            // A truncation after damage elsewhere.
            let at = rng.below(n * 8);
            if let Some(x) = b.get_mut(at / 8) {
                *x ^= 1 << (at % 8);
            }
            let keep = n / 2 + rng.below(n / 2 + 1);
            b.truncate(keep);
            format!("bit flip at byte {}, truncated to {keep}", at / 8)
        }
    };
    (b, what)
}

fn rosbag_opts() -> RosbagOptions {
    RosbagOptions {
        robot_joints: (1..=7).map(|j| format!("lbr_iiwa_joint_{j}")).collect(),
        ..RosbagOptions::default()
    }
}

/// The one file with extension `ext` in a folder.
fn file_in(dir: &Path, ext: &str) -> PathBuf {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == ext))
        .unwrap_or_else(|| panic!("no .{ext} file in {}", dir.display()))
}

/// Every file under `dir`, relative, sorted.
fn files_under(dir: &Path, rel: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir.join(rel)).unwrap().flatten() {
        let r = rel.join(e.file_name());
        if e.path().is_dir() {
            files_under(dir, &r, out);
        } else {
            out.push(r);
        }
    }
    out.sort();
}

/// What one format's campaign saw.
#[derive(Default)]
struct Tally {
    inputs: usize,
    ok: usize,
    errors: usize,
    largest: usize,
    largest_ratio: f64,
    failures: Vec<String>,
}

impl Tally {
    /// Runs one input (`size` bytes in all) through `import`.
    fn run<T, E>(&mut self, label: &str, size: usize, import: impl FnOnce() -> Result<T, E>) {
        if only().is_some_and(|o| !label.starts_with(&o)) {
            return;
        }
        // The label goes out first: if the process aborts, the parent
        // shows the last one.
        println!("input {label}");
        self.inputs += 1;
        LARGEST.store(0, Ordering::Relaxed);
        let outcome = catch_unwind(AssertUnwindSafe(import));
        let largest = LARGEST.load(Ordering::Relaxed);
        let limit = size.saturating_mul(64).saturating_add(64 << 20);
        if largest > self.largest {
            self.largest = largest;
        }
        self.largest_ratio = self.largest_ratio.max(largest as f64 / size.max(1) as f64);
        match outcome {
            Ok(Ok(_)) => self.ok += 1,
            Ok(Err(_)) => self.errors += 1,
            Err(p) => {
                let message = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                self.failures.push(format!("{label}: panicked: {message}"));
            }
        }
        if largest > limit {
            self.failures.push(format!(
                "{label}: allocated {largest} bytes at once, more than 64 x {size} + 64 MiB"
            ));
        }
    }
}

/// `REALITYGAP_FUZZ_ONLY`: run only the inputs whose label starts so
/// (`lerobot #2693:`), with panic messages shown.
fn only() -> Option<String> {
    std::env::var("REALITYGAP_FUZZ_ONLY").ok()
}

/// Inputs beyond the default count that once failed, run every time:
/// (format, input number). `lerobot` 2693: nine bit flips in a data file
/// whose column then claimed BYTE_STREAM_SPLIT encoding; the parquet
/// crate's decoder indexed past its page and panicked.
const REGRESSIONS: &[(&str, usize)] = &[("lerobot", 2693)];

/// Inputs per seed.
fn inputs_per_seed() -> usize {
    std::env::var("REALITYGAP_FUZZ_INPUTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(700)
}

/// Runs one format's campaign and returns its tally.
fn campaign(format: &str) -> Tally {
    let seeds = fixtures().join("fuzz_seeds");
    let tmp = tempfile::tempdir().unwrap();
    let mut tally = Tally::default();
    let mut rng = Rng(0x5EED
        ^ format
            .bytes()
            .fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b))));
    let per_seed = inputs_per_seed();
    // Panics are caught and counted; their messages need not flood stderr.
    if only().is_none() {
        std::panic::set_hook(Box::new(|_| {}));
    }
    match format {
        "mcap_zstd" | "mcap_trajectory" | "sqlite3" => {
            let ext = if format == "sqlite3" { "db3" } else { "mcap" };
            let seed_file = file_in(&seeds.join(format), ext);
            let seed = std::fs::read(&seed_file).unwrap();
            let fields = if ext == "mcap" {
                mcap_length_fields(&seed)
            } else {
                Vec::new()
            };
            let out = tmp.path().join(format!("damaged.{ext}"));
            tally.run("the seed itself", seed.len(), || {
                std::fs::write(&out, &seed).unwrap();
                import_rosbag(&out, &rosbag_opts())
            });
            assert!(
                tally.ok == 1 || only().is_some(),
                "{format}: the seed imports"
            );
            // Every length field of the MCAP file at every huge value.
            for &(at, width) in &fields {
                for v in HUGE {
                    let mut b = seed.clone();
                    b[at..at + width].copy_from_slice(&v.to_le_bytes()[..width]);
                    let label = format!("{format}: length field at byte {at} set to {v:#x}");
                    tally.run(&label, b.len(), || {
                        std::fs::write(&out, &b).unwrap();
                        import_rosbag(&out, &rosbag_opts())
                    });
                }
            }
            for k in 0..per_seed {
                let (b, what) = damage(&seed, &fields, &mut rng, k);
                tally.run(&format!("{format} #{k}: {what}"), b.len(), || {
                    std::fs::write(&out, &b).unwrap();
                    import_rosbag(&out, &rosbag_opts())
                });
            }
        }
        "csv" => {
            let seed = std::fs::read(seeds.join("episode.csv")).unwrap();
            let path = Path::new("episode.csv");
            tally.run("the seed itself", seed.len(), || {
                parse_csv(&seed, path, &CsvOptions::default())
            });
            assert!(tally.ok == 1 || only().is_some(), "csv: the seed imports");
            for k in 0..per_seed {
                let (b, what) = damage(&seed, &[], &mut rng, k);
                tally.run(&format!("csv #{k}: {what}"), b.len(), || {
                    parse_csv(&b, path, &CsvOptions::default())
                });
            }
        }
        "lerobot" => {
            let src = seeds.join("lerobot");
            let mut files = Vec::new();
            files_under(&src, Path::new(""), &mut files);
            let originals: Vec<Vec<u8>> = files
                .iter()
                .map(|f| std::fs::read(src.join(f)).unwrap())
                .collect();
            let total: usize = originals.iter().map(Vec::len).sum();
            let dst = tmp.path().join("lerobot");
            let write_all = |damaged: Option<(usize, &[u8])>| {
                for (i, (rel, bytes)) in files.iter().zip(&originals).enumerate() {
                    let to = dst.join(rel);
                    std::fs::create_dir_all(to.parent().unwrap()).unwrap();
                    let b = match damaged {
                        Some((j, d)) if j == i => d,
                        _ => bytes.as_slice(),
                    };
                    std::fs::write(&to, b).unwrap();
                }
            };
            tally.run("the seed itself", total, || {
                write_all(None);
                import_lerobot(&dst, &LeRobotOptions::default())
            });
            assert!(
                tally.ok == 1 || only().is_some(),
                "lerobot: the seed imports"
            );
            // The data and episode-index files, and info.json.
            let targets: Vec<usize> = (0..files.len())
                .filter(|&i| {
                    let name = files[i].to_string_lossy();
                    name.ends_with(".parquet") && !name.contains("tasks")
                        || name.ends_with("info.json")
                })
                .collect();
            let last = REGRESSIONS
                .iter()
                .filter(|r| r.0 == format)
                .map(|r| r.1 + 1)
                .max()
                .unwrap_or(0);
            for k in 0..per_seed.max(last) {
                let i = targets[k % targets.len()];
                let (b, what) = damage(&originals[i], &[], &mut rng, k / targets.len());
                if k >= per_seed && !REGRESSIONS.contains(&(format, k)) {
                    continue;
                }
                let size = total - originals[i].len() + b.len();
                tally.run(
                    &format!("lerobot #{k}: {} {what}", files[i].display()),
                    size,
                    || {
                        write_all(Some((i, &b)));
                        import_lerobot(&dst, &LeRobotOptions::default())
                    },
                );
            }
        }
        other => panic!("unknown format {other}"),
    }
    if only().is_none() {
        let _ = std::panic::take_hook();
    }
    tally
}

/// One format's campaign (all of them without `REALITYGAP_FUZZ_FORMAT`),
/// run by [`fuzz_campaign`] in a child process.
#[test]
#[ignore = "run by fuzz_campaign in a child process, one per format"]
fn fuzz_child() {
    let formats: Vec<String> = match std::env::var("REALITYGAP_FUZZ_FORMAT") {
        Ok(f) => vec![f],
        Err(_) => FORMATS.iter().map(|s| s.to_string()).collect(),
    };
    let mut failures = Vec::new();
    for format in formats {
        let t = campaign(&format);
        println!(
            "FUZZ {format}: {} inputs, {} ok, {} errors, {} failures; largest single allocation {} bytes ({:.1} x its input at most)",
            t.inputs,
            t.ok,
            t.errors,
            t.failures.len(),
            t.largest,
            t.largest_ratio
        );
        failures.extend(t.failures);
    }
    assert!(
        failures.is_empty(),
        "{} inputs failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn fuzz_campaign() {
    let exe = std::env::current_exe().unwrap();
    let mut summary = Vec::new();
    let mut failed = Vec::new();
    for format in FORMATS {
        let out = std::process::Command::new(&exe)
            .args([
                "fuzz_child",
                "--exact",
                "--ignored",
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("REALITYGAP_FUZZ_FORMAT", format)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        summary.extend(
            stdout
                .lines()
                .filter(|l| l.starts_with("FUZZ "))
                .map(str::to_string),
        );
        if !out.status.success() {
            let last = stdout
                .lines()
                .rev()
                .find(|l| l.starts_with("input "))
                .unwrap_or("no input started");
            let shown: Vec<&str> = stderr.lines().filter(|l| !l.is_empty()).take(40).collect();
            failed.push(format!(
                "{format}: the child ended with {} (last {last}):\n{}",
                out.status,
                shown.join("\n")
            ));
        }
    }
    for line in &summary {
        println!("{line}");
    }
    assert!(failed.is_empty(), "{}", failed.join("\n\n"));
    assert_eq!(
        summary.len(),
        FORMATS.len(),
        "every format reported: {summary:?}"
    );
}
