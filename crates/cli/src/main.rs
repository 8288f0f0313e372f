//! The `realitygap` command. A thin layer: argument parsing, progress bars
//! and printing; the work is done by the library crates.

use clap::{Parser, Subcommand};

use std::process::ExitCode;

mod cmd_compare;
mod cmd_import;

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
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Compare(args) => cmd_compare::run(args),
        Command::Import(cmd) => cmd_import::run(cmd),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
