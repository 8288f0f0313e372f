//! The `realitygap` command. A thin layer: argument parsing, progress bars
//! and printing; the work is done by the library crates.

#![forbid(unsafe_code)]

use clap::{Parser, Subcommand};

use std::process::ExitCode;

mod cmd_compare;
mod cmd_engines;
mod cmd_frontier;
mod cmd_import;
mod cmd_replay;
mod cmd_report;
mod cmd_reproduce;
mod cmd_run;
mod cmd_stitch;
mod cmd_tune;

/// Measure the reality gap: how far physics engines stray from a real robot
/// on the same scripted task.
#[derive(Parser)]
#[command(name = "realitygap", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Compare sources against a reference: the accumulated-error table and
    /// the per-scene measures.
    Compare(cmd_compare::Args),
    /// Import real (Qualisys) or recorded-simulator trajectories into a
    /// results directory.
    #[command(subcommand)]
    Import(cmd_import::ImportCommand),
    /// Simulate scenes in engines, in parallel, into a results directory;
    /// a rerun skips finished runs.
    Run(cmd_run::Args),
    /// Replay a robot's recorded episodes (from `import rosbag|csv|lerobot`)
    /// in every engine from their first joint state, with the recorded
    /// commands at their timestamps; the physics-free model beside them and
    /// the joint-space table.
    Replay(cmd_replay::Args),
    /// List the physics engines compiled in, with their versions.
    Engines(cmd_engines::Args),
    /// Write the figures (SVG, PNG), tables and a self-contained
    /// index.html of a study.
    Report(cmd_report::Args),
    /// The whole study in one command: every scene in every engine, the
    /// comparison against the real arm (the study's recordings, built in),
    /// the table, the figures and the report.
    Reproduce(cmd_reproduce::Args),
    /// The speed-accuracy frontier of an engine: sweep its settings, measure
    /// CPU time and deviation from the converged reference, recommend the
    /// fastest setting within a tolerance.
    Frontier(cmd_frontier::Args),
    /// Calibrate an engine against the real arm: fit its physical
    /// parameters (and the capture frame) on training runs with CMA-ES,
    /// then score untuned against tuned on held-out runs.
    Tune(cmd_tune::Args),
    /// Stitch engines per phase: choose per schedule phase the engine
    /// closest to the real arm on training runs, run the stitched scenes
    /// and score them against every single engine, with intervals.
    Stitch(cmd_stitch::Args),
    /// Internal: run one simulation (a job as JSON on standard input) and
    /// print its trajectory; `run` starts one such process per run.
    #[command(name = realitygap_runner::child::RUN_ONE, hide = true)]
    RunOne,
}

fn main() -> ExitCode {
    quiet_on_a_closed_pipe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Compare(args) => cmd_compare::run(args),
        Command::Import(cmd) => cmd_import::run(cmd),
        Command::Run(args) => cmd_run::run(args),
        Command::Replay(args) => cmd_replay::run(args),
        Command::Engines(args) => cmd_engines::run(args),
        Command::Report(args) => cmd_report::run(args),
        Command::Reproduce(args) => cmd_reproduce::run(args),
        Command::Frontier(args) => cmd_frontier::run(args),
        Command::Tune(args) => cmd_tune::run(args),
        Command::Stitch(args) => cmd_stitch::run(args),
        Command::RunOne => cmd_run::run_one(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            use std::io::Write;
            let mut err = anstream::stderr().lock();
            let _ = writeln!(
                err,
                "{}",
                realitygap::ui::paint(&format!("error: {}", realitygap::ui::error_text(&e)))
            );
            ExitCode::FAILURE
        }
    }
}

/// Output piped into a reader that stops early (`realitygap engines |
/// head -1`) ends the command quietly, as a closed pipe ends other Unix
/// tools, with 141 (128 + SIGPIPE), instead of `println!`'s panic and its
/// backtrace. Rust ignores SIGPIPE, so the write fails with EPIPE and the
/// print panics; the hook turns that one panic into the exit.
fn quiet_on_a_closed_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info.payload_as_str().unwrap_or_default();
        // std's message: "failed printing to stdout: Broken pipe (os error 32)".
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(141);
        }
        default(info)
    }));
}
