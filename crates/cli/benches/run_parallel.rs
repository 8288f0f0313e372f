//! Benchmark: wall time of `realitygap run` on the three study scenes x
//! REPEATS repeats (default 20) in MuJoCo, with --jobs 1 and with --jobs 2,
//! and the parallel speed-up. Each batch writes into a fresh temporary
//! directory, so nothing is skipped.
//!
//!     cargo bench -p realitygap --bench run_parallel
//!     REPEATS=5 cargo bench -p realitygap --bench run_parallel

use std::path::Path;
use std::process::Command;
use std::time::Instant;

fn batch(jobs: usize, repeats: u32, out: &Path) -> f64 {
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/scenes");
    let start = Instant::now();
    let result = Command::new(env!("CARGO_BIN_EXE_realitygap"))
        .arg("run")
        .args(
            [
                "scene1_single_joint",
                "scene2_two_joints",
                "scene3_cube_push",
            ]
            .map(|s| scenes.join(format!("{s}.toml"))),
        )
        .args([
            "--engine",
            "mujoco",
            "--repeats",
            &repeats.to_string(),
            "--jobs",
            &jobs.to_string(),
            "--out",
        ])
        .arg(out)
        .output()
        .expect("realitygap starts");
    let seconds = start.elapsed().as_secs_f64();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    print!("{}", String::from_utf8_lossy(&result.stdout));
    seconds
}

/// The 1-minute load average (Linux), to warn when other work competes for
/// the cores and the speed-up cannot be measured.
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// A fixed CPU-bound task (integer hashing), s.
fn spin() -> f64 {
    let start = Instant::now();
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    for i in 0..400_000_000u64 {
        x = (x ^ i).wrapping_mul(0xBF58_476D_1CE4_E5B9).rotate_left(17);
    }
    std::hint::black_box(x);
    start.elapsed().as_secs_f64()
}

/// How many cores this process can use right now: the same task run once
/// alone and then on `n` threads at once.
fn cores_available(n: usize) -> f64 {
    let alone = spin();
    let together: Vec<f64> = std::thread::scope(|s| {
        (0..n)
            .map(|_| s.spawn(spin))
            .collect::<Vec<_>>()
            .into_iter()
            .map(|h| h.join().unwrap())
            .collect()
    });
    let slowest = together.iter().copied().fold(0.0, f64::max);
    n as f64 * alone / slowest
}

fn main() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if let Some(load) = load_average() {
        println!("load average before the benchmark: {load:.2} on {cores} cores");
        if load > 0.5 {
            println!(
                "warning: other processes are using the cores; the speed-up will be understated"
            );
        }
    }
    let usable = cores_available(cores);
    println!("a CPU-bound reference task can use {usable:.2} of the {cores} cores now");
    let repeats: u32 = std::env::var("REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20);
    let tmp = std::env::temp_dir().join(format!("realitygap-bench-{}", std::process::id()));
    let one = batch(1, repeats, &tmp.join("jobs1"));
    let two = batch(2, repeats, &tmp.join("jobs2"));
    let _ = std::fs::remove_dir_all(&tmp);
    println!("3 scenes x {repeats} repeats, MuJoCo, study settings (dt = 1e-4 s):");
    println!(
        "  --jobs 1: {one:.1} s ({:.2} s per repeat of the three scenes)",
        one / repeats as f64
    );
    println!(
        "  --jobs 2: {two:.1} s ({:.2} s per repeat of the three scenes)",
        two / repeats as f64
    );
    println!(
        "  speed-up: {:.2}x (target: at least 1.8x on 2 cores)",
        one / two
    );
    if let Some(load) = load_average() {
        println!("load average after: {load:.2}");
    }
    let usable_after = cores_available(cores);
    println!(
        "the reference task could use {usable:.2} cores before and {usable_after:.2} after: a speed-up above that is not possible"
    );
}
