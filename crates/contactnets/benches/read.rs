//! Read speed: every toss of `../shared/contactnets/tosses` (the 456
//! published files) when that folder is there, else the three committed
//! ones; best of 5 passes, in files per second and MB/s, for the reader
//! alone (bytes already in memory: `read_pt` and the SI conversion) and
//! for a whole pass from disk (listing, reading, converting). Printed, not
//! asserted.
//!
//!     cargo bench -p realitygap-contactnets --bench read

use realitygap_contactnets::{list_tosses, read_pt, read_tosses, Experiment, Toss};
use realitygap_core::testing::workspace;
use std::time::Instant;

fn main() {
    let shared = workspace().join("../shared/contactnets/tosses");
    let dir = if shared.is_dir() {
        shared
    } else {
        workspace().join("crates/contactnets/tests/data/tosses")
    };
    let experiment = Experiment::published();
    let files = list_tosses(&dir).unwrap();
    let bytes: Vec<Vec<u8>> = files
        .iter()
        .map(|f| std::fs::read(&f.path).unwrap())
        .collect();
    let total: usize = bytes.iter().map(Vec::len).sum();
    let samples: usize = read_tosses(&files, &experiment)
        .unwrap()
        .iter()
        .map(Toss::len)
        .sum();
    println!(
        "{} tosses from {} ({:.2} MB, {samples} samples)",
        files.len(),
        dir.display(),
        total as f64 / 1e6
    );
    let best = |f: &mut dyn FnMut()| {
        (0..5)
            .map(|_| {
                let start = Instant::now();
                f();
                start.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let in_memory = best(&mut || {
        for (f, b) in files.iter().zip(&bytes) {
            let t = read_pt(b, &f.path).unwrap();
            std::hint::black_box(Toss::from_tensor(&t, f.number, &f.path, &experiment).unwrap());
        }
    });
    let from_disk = best(&mut || {
        let listed = list_tosses(&dir).unwrap();
        std::hint::black_box(read_tosses(&listed, &experiment).unwrap());
    });
    for (what, s) in [
        ("reader (in memory)", in_memory),
        ("listing + reading from disk", from_disk),
    ] {
        println!(
            "{what:<28} {:>9.4} s  {:>10.0} files/s  {:>8.0} MB/s",
            s,
            files.len() as f64 / s,
            total as f64 / 1e6 / s
        );
    }
}
