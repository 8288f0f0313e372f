//! Import speed: `import_rosbag` on the fixtures' bags (MCAP with zstd
//! chunks, sqlite3, and the four-episode MCAP bag), best of 5 wall times,
//! in messages per second; then Python `rosbags` (the peer) on the same
//! bags when the fixtures' virtual environment is there, and the ratio.
//!
//!     cargo bench -p realitygap-recordings --bench import

use realitygap_core::testing::workspace;
use realitygap_recordings::rosbag::{import_rosbag, RosbagOptions};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

fn main() {
    let fixtures = workspace().join("third_party/fixtures/joint-recordings");
    assert!(
        fixtures.join("truth.json").is_file(),
        "run scripts/make-fixtures first"
    );
    let opts = RosbagOptions {
        robot_joints: (1..=7).map(|j| format!("lbr_iiwa_joint_{j}")).collect(),
        ..RosbagOptions::default()
    };
    let venv = std::env::var_os("REALITYGAP_FIXTURES_VENV")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .map(|h| PathBuf::from(h).join(".cache/realitygap/fixtures-venv"))
        });
    let python = venv.map(|v| v.join("bin/python")).filter(|p| p.is_file());
    let peer = workspace().join("tools/fixtures/bench_rosbags_read.py");
    println!(
        "{:<28} {:>9} {:>12} {:>14} {:>14} {:>7}",
        "bag", "messages", "best s", "messages/s", "rosbags msg/s", "ratio"
    );
    for rel in ["mcap/episode_000", "sqlite3/episode_000", "mcap_gaps/all"] {
        let bag = fixtures.join(rel);
        let mut best = f64::INFINITY;
        let mut messages = 0;
        for _ in 0..5 {
            let start = Instant::now();
            let recs = import_rosbag(&bag, &opts).unwrap();
            best = best.min(start.elapsed().as_secs_f64());
            messages = recs
                .iter()
                .map(|r| {
                    r.states.time_ns.len() + r.commands.as_ref().map_or(0, |c| c.time_ns.len())
                })
                .sum();
        }
        let ours = messages as f64 / best;
        let theirs = python.as_ref().and_then(|py| peer_rate(py, &peer, &bag));
        let (peer_text, ratio) = match theirs {
            Some(r) => (format!("{r:.0}"), format!("{:.1}x", ours / r)),
            None => ("-".into(), "-".into()),
        };
        println!("{rel:<28} {messages:>9} {best:>12.4} {ours:>14.0} {peer_text:>14} {ratio:>7}");
    }
}

/// Messages per second of the Python peer, from its output line.
fn peer_rate(python: &Path, script: &Path, bag: &Path) -> Option<f64> {
    let out = Command::new(python).arg(script).arg(bag).output().ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    text.split(", ")
        .last()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}
