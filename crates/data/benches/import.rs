//! Import benchmark: reads the study's 60 motion-capture files and 420
//! recorded simulator files (from `../shared/paper-data`, else the built-in
//! archive unpacked into the cache), single-threaded
//! and on all cores, and prints files, MB, wall seconds and MB/s.
//!
//! Run with `cargo bench -p realitygap-data --bench import`.

use realitygap_data::qualisys::{self, QualisysOptions};
use realitygap_data::recorded::{self, QuatOrder, RecordedOptions};
use realitygap_data::{builtin, format_run_csv, parse_run_csv, ImportedRun};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// A file to import and how.
enum Job {
    Capture(PathBuf),
    Recorded(PathBuf, QuatOrder),
}

impl Job {
    fn path(&self) -> &Path {
        match self {
            Job::Capture(p) | Job::Recorded(p, _) => p,
        }
    }

    fn parse(&self, bytes: &[u8]) -> ImportedRun {
        let result = match self {
            Job::Capture(p) => qualisys::parse(bytes, p, &QualisysOptions::collins2019()),
            Job::Recorded(p, order) => recorded::parse(bytes, p, &RecordedOptions::new(*order)),
        };
        result.unwrap_or_else(|e| panic!("{e}"))
    }
}

fn list(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .collect();
    v.sort();
    v
}

fn jobs(root: &Path) -> Vec<Job> {
    let mut jobs = Vec::new();
    for exp in ["Experiment1", "Experiment2", "Experiment3"] {
        jobs.extend(
            list(&root.join("MotionCapture").join(exp), "tsv")
                .into_iter()
                .map(Job::Capture),
        );
        jobs.extend(
            list(&root.join("Simulation").join(exp), "csv")
                .into_iter()
                .map(|p| {
                    let order = if p.to_string_lossy().contains("_Mujoco_") {
                        QuatOrder::Wxyz
                    } else {
                        QuatOrder::Xyzw
                    };
                    Job::Recorded(p, order)
                }),
        );
    }
    jobs
}

/// CPU time this thread has run, in seconds (Linux: from
/// `/proc/thread-self/schedstat`); `None` elsewhere.
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns / 1e9)
}

/// Wall and CPU seconds of one timed run.
#[derive(Clone, Copy)]
struct Timing {
    wall_s: f64,
    cpu_s: Option<f64>,
}

/// Runs `work(i)` for every job index on `threads` threads.
fn timed(n: usize, threads: usize, work: &(dyn Fn(usize) + Sync)) -> Timing {
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    let cpu: Vec<Option<f64>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let c0 = thread_cpu_s();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= n {
                            break;
                        }
                        work(i);
                    }
                    Some(thread_cpu_s()? - c0?)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let wall_s = start.elapsed().as_secs_f64();
    Timing {
        wall_s,
        cpu_s: cpu.into_iter().sum(),
    }
}

/// The run with the shortest wall time among `repeats` (the machine may be
/// shared; the best run is the one least disturbed).
fn best(repeats: usize, mut f: impl FnMut() -> Timing) -> Timing {
    (0..repeats)
        .map(|_| f())
        .min_by(|a, b| a.wall_s.total_cmp(&b.wall_s))
        .unwrap()
}

fn report(what: &str, files: usize, bytes: usize, t: Timing) {
    let mb = bytes as f64 / 1e6;
    let cpu = t.cpu_s.map_or("-".to_string(), |c| {
        format!("cpu {c:.4} s {:>5.0} MB/cpu-s", mb / c)
    });
    println!(
        "{what:<38} {files:>4} files {mb:>6.1} MB  wall {:>7.4} s {:>6.0} MB/s  {cpu}",
        t.wall_s,
        mb / t.wall_s
    );
}

/// The study's recordings: `../shared/paper-data` when it is there, else
/// the built-in archive unpacked into the cache.
fn paper_data() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/paper-data");
    if root.join("MotionCapture").is_dir() {
        return root;
    }
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let archive = builtin::StudyArchive::in_assets(&assets).unwrap_or_else(|e| panic!("{e}"));
    let cache = builtin::default_cache_root().unwrap_or_else(|e| panic!("{e}"));
    builtin::open_or_unpack(&archive, &cache)
        .unwrap_or_else(|e| panic!("{e}"))
        .dir
}

/// Times the importers: read + parse and parse only, on 1 and all threads,
/// then each format alone.
fn bench_imports(jobs: &[Job], contents: &[Vec<u8>], threads: usize) {
    let n = jobs.len();
    let total: usize = contents.iter().map(Vec::len).sum();
    let capture_bytes: usize = jobs
        .iter()
        .zip(contents)
        .filter(|(j, _)| matches!(j, Job::Capture(_)))
        .map(|(_, c)| c.len())
        .sum();
    let captures = jobs.iter().filter(|j| matches!(j, Job::Capture(_))).count();
    let repeats = 10;
    let read_and_parse = |i: usize| {
        let bytes = std::fs::read(jobs[i].path()).unwrap();
        std::hint::black_box(jobs[i].parse(&bytes));
    };
    let parse_only = |i: usize| {
        std::hint::black_box(jobs[i].parse(&contents[i]));
    };
    report(
        "read + parse, 1 thread",
        n,
        total,
        best(repeats, || timed(n, 1, &read_and_parse)),
    );
    report(
        &format!("read + parse, {threads} threads"),
        n,
        total,
        best(repeats, || timed(n, threads, &read_and_parse)),
    );
    report(
        "parse only, 1 thread",
        n,
        total,
        best(repeats, || timed(n, 1, &parse_only)),
    );
    report(
        &format!("parse only, {threads} threads"),
        n,
        total,
        best(repeats, || timed(n, threads, &parse_only)),
    );

    let capture_idx: Vec<usize> = (0..n)
        .filter(|&i| matches!(jobs[i], Job::Capture(_)))
        .collect();
    let recorded_idx: Vec<usize> = (0..n)
        .filter(|&i| matches!(jobs[i], Job::Recorded(..)))
        .collect();
    let subset = |idx: &[usize]| best(repeats, || timed(idx.len(), 1, &|k| parse_only(idx[k])));
    report(
        "  Qualisys TSV parse only, 1 thread",
        captures,
        capture_bytes,
        subset(&capture_idx),
    );
    report(
        "  recorded CSV parse only, 1 thread",
        n - captures,
        total - capture_bytes,
        subset(&recorded_idx),
    );
}

/// Times the results-directory format: every trajectory written as run CSV
/// and read back.
fn bench_run_csv(jobs: &[Job], contents: &[Vec<u8>]) {
    let n = jobs.len();
    let repeats = 10;
    let runs: Vec<ImportedRun> = (0..n).map(|i| jobs[i].parse(&contents[i])).collect();
    let texts: Vec<String> = runs
        .iter()
        .map(|r| format_run_csv(&r.trajectory).unwrap())
        .collect();
    let csv_bytes: usize = texts.iter().map(String::len).sum();
    let format_s = best(repeats, || {
        timed(n, 1, &|i| {
            std::hint::black_box(format_run_csv(&runs[i].trajectory).unwrap());
        })
    });
    report("run CSV format, 1 thread", n, csv_bytes, format_s);
    let parse_s = best(repeats, || {
        timed(n, 1, &|i| {
            std::hint::black_box(parse_run_csv(texts[i].as_bytes(), Path::new("bench")).unwrap());
        })
    });
    report("run CSV parse, 1 thread", n, csv_bytes, parse_s);
}

fn main() {
    let root = paper_data();
    let jobs = jobs(&root);
    let threads = std::thread::available_parallelism().map_or(1, |p| p.get());
    let contents: Vec<Vec<u8>> = jobs
        .iter()
        .map(|j| std::fs::read(j.path()).unwrap())
        .collect();
    let captures = jobs.iter().filter(|j| matches!(j, Job::Capture(_))).count();
    println!(
        "paper-data: {} capture + {} simulator files, {} threads available",
        captures,
        jobs.len() - captures,
        threads
    );
    bench_imports(&jobs, &contents, threads);
    bench_run_csv(&jobs, &contents);
}
