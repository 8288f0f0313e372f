//! A folder of tosses into a results directory: one real run of the cube
//! per `N.pt`, its id the toss's number, and nothing written unless every
//! toss reads.

use crate::toss::{Experiment, Toss};
use realitygap_core::trajectory::CUBE;
use realitygap_data::{ImportError, RunEntry, RunStore, SourceKind, StoreError};
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};

/// The name of the experiment's constants file.
pub const EXPERIMENT_FILE: &str = "experiment.json";

/// What went wrong importing tosses.
#[derive(Debug, thiserror::Error)]
pub enum ContactNetsError {
    /// A file could not be read as a toss (or an `experiment.json`).
    #[error(transparent)]
    Import(#[from] ImportError),
    /// The results directory could not be written.
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// One toss file of a folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TossFile {
    /// The toss's number (the file's stem).
    pub number: u64,
    /// The file.
    pub path: PathBuf,
}

/// The toss files of `dir` (`N.pt`, N the toss's number), by number. An
/// `experiment.json` beside them is allowed; any other entry is an error
/// naming it, and so is a folder without toss files.
pub fn list_tosses(dir: &Path) -> Result<Vec<TossFile>, ImportError> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| ImportError::new(dir, format!("cannot read the folder of tosses: {e}")))?;
    let mut files: Vec<TossFile> = Vec::new();
    for entry in entries {
        let entry =
            entry.map_err(|e| ImportError::new(dir, format!("cannot read the folder: {e}")))?;
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name == EXPERIMENT_FILE {
            continue;
        }
        let number = name
            .strip_suffix(".pt")
            .filter(|stem| !stem.is_empty() && stem.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|stem| stem.parse::<u64>().ok());
        let Some(number) = number.filter(|_| path.is_file()) else {
            return Err(ImportError::new(
                &path,
                "not a toss file: a folder of tosses holds only N.pt files (N the toss's number) and an experiment.json",
            ));
        };
        if let Some(other) = files.iter().find(|f| f.number == number) {
            return Err(ImportError::new(
                &path,
                format!(
                    "toss {number} again: {} is toss {number} too",
                    other.path.display()
                ),
            ));
        }
        files.push(TossFile { number, path });
    }
    if files.is_empty() {
        return Err(ImportError::new(dir, "no toss files (N.pt) in this folder"));
    }
    files.sort_by_key(|f| f.number);
    Ok(files)
}

/// The experiment file to use for a folder of tosses when none is given:
/// `DIR/experiment.json`, else `DIR/../experiment.json` (the published
/// layout: `tosses/` beside it), else none (the published constants).
pub fn default_experiment_file(dir: &Path) -> Option<PathBuf> {
    [
        dir.join(EXPERIMENT_FILE),
        dir.join("..").join(EXPERIMENT_FILE),
    ]
    .into_iter()
    .find(|p| p.is_file())
}

/// Reads every toss; the first that cannot be read is the error.
pub fn read_tosses(files: &[TossFile], experiment: &Experiment) -> Result<Vec<Toss>, ImportError> {
    files
        .iter()
        .map(|f| Toss::read(&f.path, f.number, experiment))
        .collect()
}

/// What an import did.
#[derive(Debug, Clone)]
pub struct Imported {
    /// The constants used.
    pub experiment: Experiment,
    /// The runs stored, by toss number: id and sample count.
    pub runs: Vec<(String, usize)>,
    /// How many of them replaced a run of the same id.
    pub replaced: usize,
    /// Warnings, each prefixed with its toss's file.
    pub warnings: Vec<String>,
}

/// The manifest's settings for tosses imported with `experiment`.
pub fn settings(experiment: &Experiment) -> Value {
    let half_width = experiment.half_width_m();
    json!({
        "importer": "contactnets",
        "dataset": "ContactNets cube tosses: Pfrommer, Halm and Posa, \"ContactNets: Learning Discontinuous Contact Dynamics with Smooth, Implicit Representations\", CoRL 2020; github.com/DAIRLab/contact-nets, data/",
        "licence": "BSD-3-Clause (the data's LICENSE)",
        "experiment_file": experiment.file.as_ref().map(|f| {
            std::fs::canonicalize(f).unwrap_or_else(|_| f.clone()).display().to_string()
        }),
        "dt_s": experiment.dt_s,
        "frequency_hz": experiment.frequency_hz(),
        "units": {
            "length": "the files' lengths are cube half-widths; metres = half-widths x 9.81 / g",
            "g_half_widths_s2": experiment.g_half_widths_s2,
            "standard_gravity_m_s2": crate::toss::STANDARD_GRAVITY_M_S2,
            "half_width_m": half_width,
        },
        "object": {
            "role": CUBE,
            "shape": "box",
            "edge_m": experiment.edge_m(),
            "mass_kg": experiment.mass_kg,
        },
        "published": {
            "mu": experiment.mu,
            "restitution": experiment.restitution,
            "note": "the friction and restitution in the data's experiment.json: values the authors used, not measurements",
        },
        "velocities": "runs/<id>.velocities.csv: linear velocity world frame (m/s), angular velocity body frame (rad/s), as recorded",
        "not_read": "the tensor's 6 control-input columns (zero: the cube is free)",
    })
}

/// Stores every toss as a real run of the cube in `out` (source `source`,
/// kind real, no scene): the pose in `runs/<id>.csv`, the velocities in
/// `runs/<id>.velocities.csv`, the constants in the manifest's settings.
pub fn store(
    tosses: &[Toss],
    experiment: &Experiment,
    out: &Path,
    source: &str,
) -> Result<Imported, StoreError> {
    let mut store = RunStore::create_or_open(out, source, SourceKind::Real, None)?;
    store.set_settings(settings(experiment))?;
    let mut imported = Imported {
        experiment: experiment.clone(),
        runs: Vec::with_capacity(tosses.len()),
        replaced: 0,
        warnings: Vec::new(),
    };
    for toss in tosses {
        let id = toss.number.to_string();
        let mut entry = RunEntry::new(&id);
        let origin = std::fs::canonicalize(&toss.file).unwrap_or_else(|_| toss.file.clone());
        entry.origin = vec![origin.display().to_string()];
        if !toss.warnings.is_empty() {
            entry.message = Some(toss.warnings.join("; "));
        }
        let mut bodies = Map::new();
        bodies.insert(CUBE.into(), Value::from(CUBE));
        let extra = &mut entry.extra;
        extra.insert("samples".into(), toss.len().into());
        extra.insert("frequency_hz".into(), experiment.frequency_hz().into());
        extra.insert("bodies".into(), Value::Object(bodies));
        extra.insert("gaps".into(), 0.into());
        extra.insert(
            "max_quat_norm_error".into(),
            toss.max_quat_norm_error.into(),
        );
        if store.run(&id).is_some() {
            imported.replaced += 1;
        }
        store.write_run_with_velocities(entry, &toss.trajectory(), &[toss.velocities()])?;
        imported.runs.push((id, toss.len()));
        imported.warnings.extend(
            toss.warnings
                .iter()
                .map(|w| format!("{}: {w}", toss.file.display())),
        );
    }
    Ok(imported)
}

/// `realitygap import contactnets DIR --out OUT`: lists the tosses, reads
/// the experiment's constants (`experiment`, else
/// [`default_experiment_file`], else [`Experiment::published`]), reads
/// every toss, and only then writes the results directory.
pub fn import(
    dir: &Path,
    experiment: Option<&Path>,
    out: &Path,
    source: &str,
) -> Result<Imported, ContactNetsError> {
    let experiment = match experiment
        .map(Path::to_path_buf)
        .or_else(|| default_experiment_file(dir))
    {
        Some(file) => Experiment::read(&file)?,
        None => Experiment::published(),
    };
    let files = list_tosses(dir)?;
    let tosses = read_tosses(&files, &experiment)?;
    Ok(store(&tosses, &experiment, out, source)?)
}
