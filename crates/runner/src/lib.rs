//! Batches of simulation runs, for `realitygap run` and `reproduce`.
//!
//! - [`plan`]: a batch ([`BatchSpec`]) becomes one results directory per
//!   (scene, engine), checked and opened before anything runs, with the
//!   repeats still to run: a rerun keeps the finished runs (resume);
//! - [`child`]: every run executes in a child process (the `realitygap`
//!   binary re-invoked with the hidden subcommand `__run-one`); a crash,
//!   abort or `exit` inside an engine's native code fails only that run;
//! - [`protocol`]: the job the child reads as JSON and the result it
//!   writes, numbers as IEEE bits so that the stored run is exactly the
//!   simulated one;
//! - [`batch`]: the local process pool; the parent alone writes the
//!   results directories, run by run, so an interrupted batch keeps every
//!   finished run. Deterministic repeats are simulated twice and, when
//!   identical, the rest are recorded as copies.
//!
//! The engines come from a [`Registry`]: the binary's compiled-in engines
//! (cargo features of the `realitygap` crate).

#![warn(missing_docs)]

pub mod batch;
pub mod child;
pub mod cpu_clock;
pub mod interrupt;
pub mod plan;
pub mod prepare;
pub mod protocol;
pub mod slurm;

pub use batch::{BatchStats, Progress};
pub use child::{run_child, run_one, ChildEnd, Launcher};
pub use plan::{run_id, BatchSpec, Done, Group, Plan};
pub use protocol::{ChildResult, Job};

/// The engines a program has: a function listing them, each newly made.
pub type Registry = fn() -> Vec<Box<dyn realitygap_core::engine::Engine>>;
