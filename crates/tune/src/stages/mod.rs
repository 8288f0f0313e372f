//! The stages of a tune, shared by the study tune ([`crate::tune`]) and
//! the recordings tune ([`crate::recordings::tune_recordings`]), in the
//! order they run:
//!
//! 1. [`prepare`]: the space, the episodes or runs, the output folder and
//!    the state a rerun resumes from;
//! 2. [`scan`]: a global look before the gradient fit (the study tune's
//!    CMA-ES, [`crate::search`]; the recordings tune's scan of the delay);
//! 3. [`fit`]: Levenberg-Marquardt ([`crate::least_squares`]): the study
//!    polish's reweighted rounds, widened bounds and probe; the recordings
//!    tune's fits before and after the delay's profile;
//! 4. [`profile`]: one coordinate held and the others refitted
//!    ([`profile::Held`]), the one profile code of both tunes: the
//!    study's interval ends and the recordings' delay at whole engine
//!    steps;
//! 5. [`intervals`]: the Jacobian at the optimum
//!    ([`crate::least_squares::Linearised`], the one Jacobian holder of
//!    both tunes), the intervals and the identifiability read from it;
//! 6. [`score`]: the untuned and the tuned engine and the physics-free
//!    model on the training and the held-out episodes or runs;
//! 7. [`mod@write`]: the files (`tuned.toml`, `summary.md`, ...).
//!
//! A cross-validation runs stages 1 to 6 once per fold; each stage is a
//! function of the stage before's result, so that one can be changed or
//! replaced alone.

pub mod fit;
pub mod intervals;
pub mod prepare;
pub mod profile;
pub mod scan;
pub mod score;
pub mod write;
