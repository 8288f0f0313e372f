//! Analysis of trajectories: the measures of the reality-gap study.
//!
//! The pipeline, one module per stage:
//! 1. [`health`]: per-run checks (non-finite values, divergence, all-zero
//!    rows, frozen stretches, gaps) that decide whether a run may be averaged.
//! 2. [`align`]: turning a real recording (capture rate, free-running
//!    clock) into samples on the control-step grid of the simulations: a
//!    fixed start frame, the motion onset minus a lead, or an estimated
//!    offset; then resampling.
//! 3. [`stats`]: per-step mean and spread of a body's position across the
//!    runs of one source.
//! 4. [`metrics`]: distances to a goal and to a reference, accumulated
//!    error, convergence, overshoot, cube displacement and rotation, contact
//!    onset, orientation error.
//! 5. [`compare`]: one scene, one reference and many sources, evaluated
//!    into a [`compare::SceneReport`]; [`study`] does it for every scene of
//!    a study with one run selection ([`selection`]) and one capture-frame
//!    registration ([`registration`]), aligning the real runs to the
//!    scene's [`kinematic`] reference; [`bootstrap`] gives the intervals;
//!    [`table`] renders reports as Markdown, CSV, JSON and LaTeX.
//!
//! Everything here is pure computation on [`realitygap_core::Trajectory`];
//! reading files is the `realitygap-data` crate's job.

#![forbid(unsafe_code)]

pub mod align;
pub mod bootstrap;
pub mod compare;
pub mod health;
pub mod ik;
pub mod kinematic;
pub mod metrics;
pub mod registration;
pub mod selection;
pub mod stats;
pub mod study;
pub mod table;
pub mod testing;

pub use compare::{AnalysisMode, SceneReport, SourceRuns, SourceSummary};
pub use health::{HealthFlag, HealthOptions, RunHealth};
pub use study::{
    align_references, evaluate_study, evaluate_study_aligned, AlignedReferences, SceneInput,
};
