//! The one evaluation every command shares: a study, per scene, per
//! source, to the analysis' reports.

use crate::data_source::DataSource;
use crate::load::{LoadedScene, Roots};
use crate::measure::Measure;
use crate::study::{SourceFormat, Study};
use anyhow::{bail, Context, Result};
use realitygap_analysis::compare::{CompareOptions, SceneReport};
use std::path::{Path, PathBuf};

/// Measures the gap in every scene of `scenes` (loaded by
/// [`Study::load`]): the reports, scene by scene.
pub fn evaluate_scenes(scenes: &[LoadedScene], opts: &CompareOptions) -> Result<Vec<SceneReport>> {
    let inputs: Vec<_> = scenes.iter().map(|s| s.input()).collect();
    Ok(realitygap_analysis::evaluate_study(&inputs, opts)?)
}

/// Loads every scene of `study` and measures the gap in each: study → per
/// scene → per source → reports.
pub fn evaluate(study: &Study, roots: &Roots, opts: &CompareOptions) -> Result<Vec<SceneReport>> {
    evaluate_scenes(&study.load(roots)?, opts)
}

/// [`evaluate`] with the options `measure` gives for the study (read from
/// `study_path`), saving the registration if asked.
pub fn evaluate_measured(
    study_path: &Path,
    study: &Study,
    roots: &Roots,
    measure: &Measure,
) -> Result<Vec<SceneReport>> {
    let opts = measure.options(study)?;
    let scenes = study.load(roots)?;
    let reports = evaluate_scenes(&scenes, &opts)
        .with_context(|| format!("study {}", study_path.display()))?;
    measure.save_registration(&reports)?;
    Ok(reports)
}

/// Reads a study file and finds the folders its sources are relative to:
/// `data` for file patterns (resolved only when the study reads
/// recordings; the built-in ones are unpacked on first use), `results`
/// else the study file's folder for results directories.
pub fn load_study(
    study_path: &Path,
    data: &DataSource,
    results: Option<PathBuf>,
) -> Result<(Study, Roots)> {
    let study = Study::from_file(study_path)?;
    let base = study_path.parent().map(PathBuf::from).unwrap_or_default();
    let reads = reads_recordings(&study);
    let data = match (&reads, data) {
        (Some(_), _) | (None, DataSource::Dir(_)) => match data.resolve()? {
            Some(dir) => dir,
            None => bail!(
                "{}: the study reads recordings ({}), but --data none gives none; leave --data out for the study's recordings built in, or pass --data DIR",
                study_path.display(),
                reads.as_deref().unwrap_or_default()
            ),
        },
        // Only results directories: no recordings to find.
        (None, _) => base.clone(),
    };
    let roots = Roots {
        data,
        results: results.unwrap_or(base),
    };
    Ok((study, roots))
}

/// The first source of the study that reads recording files (`qualisys`
/// or `recorded`), as `name: pattern`; `None` when all are results
/// directories.
pub fn reads_recordings(study: &Study) -> Option<String> {
    study
        .scenes
        .iter()
        .flat_map(|s| std::iter::once(&s.reference).chain(&s.sources))
        .chain(&study.sources)
        .find(|s| s.format != SourceFormat::Store)
        .map(|s| format!("{}: {}", s.name, s.files.as_deref().unwrap_or("")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_study_of_results_directories_needs_no_recordings() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        std::fs::write(&path, "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = 3\n[scenes.reference]\nname = \"r\"\nformat = \"store\"\ndir = \"d\"\n").unwrap();
        let (study, roots) = load_study(&path, &DataSource::None, None).unwrap();
        assert_eq!(reads_recordings(&study), None);
        assert_eq!(
            (roots.data.as_path(), roots.results.as_path()),
            (dir.path(), dir.path())
        );
        let e = evaluate(&study, &roots, &CompareOptions::default()).unwrap_err();
        assert!(format!("{e:#}").contains("results directory"), "{e:#}");
    }

    #[test]
    fn recordings_with_data_none_are_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        std::fs::write(&path, "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = 3\n[scenes.reference]\nname = \"r\"\nformat = \"qualisys\"\nfiles = \"a/*.tsv\"\n").unwrap();
        let e = load_study(&path, &DataSource::None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("r: a/*.tsv") && e.contains("--data none"), "{e}");
    }
}
