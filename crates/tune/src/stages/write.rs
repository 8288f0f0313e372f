//! The files a tune writes. The study tune's are written by
//! [`crate::outputs::finish`]; the recordings tune's here (and its
//! summaries by [`crate::recordings::write_summary`]).

use crate::recordings::{space_toml, RecordingsSummary};
use crate::space::Space;
use anyhow::{Context, Result};
use realitygap_core::params::PhysicalParams;
use realitygap_core::Engine;
use realitygap_study::replay::Prepared;
use std::path::{Path, PathBuf};

/// `OUT/space.toml`: the space a recordings tune searches, to edit and
/// pass back with `--space` (the folder made first).
pub fn recordings_space(
    out: &Path,
    space: &Space,
    prepared: &Prepared,
    engine: &dyn Engine,
) -> Result<PathBuf> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join("space.toml");
    std::fs::write(
        &path,
        space_toml(space, &prepared.robot.name, engine.name()),
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// `OUT/tuned.toml`: the known and the fitted parameters of a recordings
/// tune, for `realitygap replay --params`.
pub fn recordings_tuned(
    out: &Path,
    summary: &RecordingsSummary,
    tuned: &PhysicalParams,
) -> Result<PathBuf> {
    let path = out.join("tuned.toml");
    let mut file = tuned.clone();
    file.source = None;
    std::fs::write(
        &path,
        format!(
            "# Tuned by `realitygap tune --recordings` ({}, robot '{}'): the known\n# parameters and the fitted ones; pass it to `realitygap replay --params`.\n{}",
            summary.engine,
            summary.robot,
            file.to_toml_string()
        ),
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}
