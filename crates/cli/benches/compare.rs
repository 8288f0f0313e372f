//! Benchmark: import every recording of the reference study (60 capture
//! files, 420 simulator files) and compute the full comparison, as
//! `realitygap compare assets/studies/collins2019.toml` does.
//!
//! Run: `cargo bench -p realitygap --bench compare [-- PAPER_DATA_DIR]`.
//! Prints wall time per stage, MB parsed and MB/s, for the default mode
//! (alignment to the kinematic reference, registration estimated on the
//! training runs, 1000 bootstrap resamples), the default mode without
//! intervals, a fit-on-1-15 / score-on-16-20 run, and the study mode, best
//! of several repetitions. The analysis of the default mode must stay under
//! 0.3 s.

use realitygap_analysis::bootstrap::BootstrapOptions;
use realitygap_analysis::compare::{AnalysisMode, CompareOptions};
use realitygap_analysis::selection::{RunRange, RunSelection};
use realitygap_study::{evaluate_scenes, Roots, Study};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn dir_bytes(dir: &Path) -> u64 {
    let mut total = 0;
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                total += dir_bytes(&p);
            } else if p.extension().is_some_and(|x| x == "csv" || x == "tsv")
                && !p.to_string_lossy().contains("Format")
            {
                total += e.metadata().map(|m| m.len()).unwrap_or(0);
            }
        }
    }
    total
}

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let data = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .map(PathBuf::from)
        .or_else(realitygap_core::testing::paper_data)
        .expect("the study's recordings (pass their path as an argument)");
    if !data.join("MotionCapture").is_dir() {
        eprintln!(
            "paper-data not found at {}; pass its path as an argument",
            data.display()
        );
        std::process::exit(1);
    }
    let study =
        Study::from_file(&root.join("assets/studies/collins2019.toml")).expect("study file");
    let roots = Roots {
        data: data.clone(),
        results: root.clone(),
    };
    let mb =
        (dir_bytes(&data.join("MotionCapture")) + dir_bytes(&data.join("Simulation"))) as f64 / 1e6;
    println!("threads: {}", rayon::current_num_threads());
    println!("data: {mb:.1} MB in {}", data.display());
    let holdout = RunSelection {
        runs: Some(RunRange::parse("1-15", "--runs").expect("range")),
        holdout: Some(RunRange::parse("16-20", "--holdout").expect("range")),
    };
    let cases = [
        (
            "default mode, registration + 1000 bootstrap resamples",
            CompareOptions::default(),
        ),
        (
            "default mode, no intervals",
            CompareOptions {
                bootstrap: Some(BootstrapOptions {
                    resamples: 0,
                    ..BootstrapOptions::default()
                }),
                ..CompareOptions::default()
            },
        ),
        (
            "default mode, fit on runs 1-15, scored on 16-20, 1000 resamples",
            CompareOptions {
                runs: holdout,
                ..CompareOptions::default()
            },
        ),
        (
            "study mode",
            CompareOptions {
                mode: AnalysisMode::Study,
                ..CompareOptions::default()
            },
        ),
    ];
    for (name, opts) in cases {
        let mut best = (f64::MAX, f64::MAX);
        for _ in 0..5 {
            let t0 = Instant::now();
            let scenes = study.load(&roots).expect("load");
            let t1 = Instant::now();
            let reports = evaluate_scenes(&scenes, &opts).expect("evaluate");
            let t2 = Instant::now();
            std::hint::black_box(&reports);
            let (l, a) = ((t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
            if l + a < best.0 + best.1 {
                best = (l, a);
            }
        }
        println!(
            "{name}: total {:.3} s = import {:.3} s ({:.0} MB/s) + analysis {:.3} s   (best of 5)",
            best.0 + best.1,
            best.0,
            mb / best.0,
            best.1
        );
        if name.contains("registration + 1000") {
            println!(
                "  analysis with registration and 1000 bootstrap resamples: {:.3} s, {} the 0.3 s budget",
                best.1,
                if best.1 < 0.3 { "within" } else { "OVER" }
            );
        }
    }
}
