//! The ContactNets cube tosses (Pfrommer, Halm and Posa, CoRL 2020; BSD
//! 3-Clause) as real runs of a free object.
//!
//! An acrylic cube tossed by hand onto a flat surface, tracked in 6D at
//! 148 Hz: each toss an `N.pt` file, PyTorch's legacy serialisation of a
//! 1 x T x 19 float64 tensor, in cube half-widths. The pipeline, stage by
//! stage:
//!
//! ```text
//! N.pt ──> pt::read_pt (pickles + raw storage, no Python) ──> PtTensor
//!   ──> toss::Toss::from_tensor (checked, SI units: experiment.json's g) ──> Toss
//!   ──> import::store (one real run per toss: runs/<N>.csv, runs/<N>.velocities.csv)
//! ```
//!
//! Every error names the file, the byte offset and the field (and the
//! sample and column for a value), and nothing is written until every toss
//! of the folder has been read: a bad input leaves no partial results
//! directory.

#![forbid(unsafe_code)]

pub mod import;
pub mod pt;
pub mod toss;

pub use import::{
    default_experiment_file, import, list_tosses, read_tosses, store, ContactNetsError, Imported,
    TossFile,
};
pub use pt::{read_pt, PtTensor};
pub use toss::{Experiment, Toss};
