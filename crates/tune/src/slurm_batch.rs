//! A tune's evaluations on Slurm: the candidates of a generation, which
//! the search evaluates in parallel threads, are gathered and submitted as
//! one job array.
//!
//! Each evaluating thread hands its jobs (one per scene) to the
//! [`Gatherer`] and waits. Requests arriving within a short window of each
//! other go into the same array: the thread that finds the window closed
//! submits everything pending (`realitygap_runner::slurm::run_array`) and
//! hands every thread its results. A generation's candidates arrive
//! together (the search starts them at once), so a generation is one
//! array; candidates replayed from the history never reach it.

use realitygap_runner::slurm::{run_array, SlurmOptions};
use realitygap_runner::{ChildEnd, Job, Launcher};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// How long after the last request the gathered jobs are submitted.
pub const WINDOW: Duration = Duration::from_millis(300);

#[derive(Default)]
struct State {
    pending: Vec<(u64, Job)>,
    results: HashMap<u64, ChildEnd>,
    next_ticket: u64,
    last_arrival: Option<Instant>,
    submitting: bool,
    arrays: usize,
}

/// Gathers jobs from many threads into Slurm job arrays.
pub struct Gatherer {
    launcher: Launcher,
    options: SlurmOptions,
    dir: PathBuf,
    state: Mutex<State>,
    wake: Condvar,
}

impl Gatherer {
    /// A gatherer submitting arrays into `dir/<n>/`.
    pub fn new(launcher: Launcher, options: SlurmOptions, dir: PathBuf) -> Gatherer {
        Gatherer {
            launcher,
            options,
            dir,
            state: Mutex::new(State::default()),
            wake: Condvar::new(),
        }
    }

    /// Arrays submitted so far.
    pub fn arrays(&self) -> usize {
        self.lock().arrays
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Runs `jobs` in the next array; their ends, in order.
    pub fn run(&self, jobs: Vec<Job>) -> Vec<ChildEnd> {
        let mut st = self.lock();
        let tickets: Vec<u64> = jobs
            .into_iter()
            .map(|job| {
                let t = st.next_ticket;
                st.next_ticket += 1;
                st.pending.push((t, job));
                t
            })
            .collect();
        st.last_arrival = Some(Instant::now());
        self.wake.notify_all();
        loop {
            if tickets.iter().all(|t| st.results.contains_key(t)) {
                return tickets
                    .iter()
                    .filter_map(|t| st.results.remove(t))
                    .collect();
            }
            let quiet = st.last_arrival.is_none_or(|t| t.elapsed() >= WINDOW);
            if !st.submitting && !st.pending.is_empty() && quiet {
                let batch = std::mem::take(&mut st.pending);
                st.submitting = true;
                let n = st.arrays;
                st.arrays += 1;
                drop(st);
                let ends = self.submit(batch, n);
                st = self.lock();
                st.results.extend(ends);
                st.submitting = false;
                self.wake.notify_all();
                continue;
            }
            st = self
                .wake
                .wait_timeout(st, WINDOW / 3)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }

    /// Submits one array; every job's end (failed with the reason when the
    /// array could not be submitted at all).
    fn submit(&self, batch: Vec<(u64, Job)>, n: usize) -> Vec<(u64, ChildEnd)> {
        let tickets: Vec<u64> = batch.iter().map(|(t, _)| *t).collect();
        let mut ends: Vec<(u64, ChildEnd)> = Vec::with_capacity(batch.len());
        let dir = self.dir.join(format!("{n}"));
        let done = run_array(
            batch,
            &dir,
            &self.launcher,
            &self.options,
            &mut |t, end, _| {
                ends.push((t, end));
                Ok(())
            },
        );
        if let Err(e) = done {
            let message = format!("{e:#}");
            for t in tickets {
                if !ends.iter().any(|(x, _)| *x == t) {
                    ends.push((t, ChildEnd::Failed(message.clone())));
                }
            }
        }
        ends
    }
}
