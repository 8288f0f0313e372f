//! Interrupting a long call from inside the process: a process-wide flag
//! that an embedding program (the Python package, on Ctrl-C) raises while
//! a batch, a replay or a tune runs on another thread.
//!
//! When it is raised, [`run_child`](crate::run_child) kills its child and
//! returns at once, the pools take no further job, and the callers return
//! [`Interrupted`] without storing the runs that the interruption cut short:
//! every run finished before is kept, as when the `realitygap` command is
//! stopped with Ctrl-C (its child processes die with it). The command
//! itself never raises the flag.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Asks every running batch, replay and tune of this process to stop.
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Lowers the flag, before a new call.
pub fn clear() {
    REQUESTED.store(false, Ordering::SeqCst);
}

/// Whether an interruption was asked for.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// The error of a call that stopped because an interruption was asked
/// for; the runs finished before it are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted; the runs finished before are kept (rerun to go on)")
    }
}

impl std::error::Error for Interrupted {}

/// `Err(Interrupted)` when an interruption was asked for.
pub fn check() -> anyhow::Result<()> {
    if requested() {
        return Err(Interrupted.into());
    }
    Ok(())
}

/// Whether `error` (or its cause) is an [`Interrupted`].
pub fn is_interrupted(error: &anyhow::Error) -> bool {
    error.chain().any(|e| e.is::<Interrupted>())
}
