//! Importing recordings into a results directory: one run per file, the
//! manifest entry of each, the run ids from file names (`realitygap
//! import`; the command parses arguments and prints).

use anyhow::{bail, Context, Result};
use realitygap_data::{
    sanitize_run_id, ImportError, ImportedRun, RunEntry, RunStatus, RunStore, SourceKind,
};
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where the imported runs go.
pub struct ImportTarget<'a> {
    /// The results directory.
    pub out: &'a Path,
    /// The source's name.
    pub source: &'a str,
    /// What the runs are.
    pub kind: SourceKind,
    /// The scene they belong to, if any.
    pub scene: Option<&'a str>,
}

/// Imports every file into the results directory, one run each; says a
/// line per file and a summary through `say`, and why a file could not be
/// read through `complain`. Such a file is skipped; the import then fails
/// after importing the others.
pub fn import_files(
    files: &[PathBuf],
    target: &ImportTarget,
    settings: Value,
    import: impl Fn(&Path) -> Result<ImportedRun, ImportError>,
    say: &dyn Fn(String),
    complain: &dyn Fn(String),
) -> Result<()> {
    // Run ids come from file stems: two files must not share one.
    let mut ids: BTreeMap<String, &Path> = BTreeMap::new();
    let mut planned = Vec::with_capacity(files.len());
    for f in files {
        let stem = f
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let id = sanitize_run_id(&stem);
        if let Some(other) = ids.insert(id.clone(), f) {
            bail!(
                "{} and {} would both be run '{id}': import them into different directories",
                other.display(),
                f.display()
            );
        }
        planned.push((f, id));
    }

    // A new store is made at the first file read, so that an import of
    // which no file could be read leaves no results directory behind; an
    // existing one is opened (and checked against the source) first.
    let open = || -> Result<RunStore> {
        let mut s = RunStore::create_or_open(target.out, target.source, target.kind, target.scene)?;
        s.set_settings(settings.clone())?;
        Ok(s)
    };
    let mut store: Option<RunStore> = if target
        .out
        .join(realitygap_data::runstore::MANIFEST_FILE)
        .exists()
    {
        Some(open()?)
    } else {
        None
    };
    let mut failed = 0usize;
    for (file, id) in planned {
        let run = match import(file) {
            Ok(run) => run,
            Err(e) => {
                complain(format!("error: {e}"));
                failed += 1;
                continue;
            }
        };
        let store = match &mut store {
            Some(s) => s,
            None => store.insert(open()?),
        };
        let entry = entry_for(&id, file, &run);
        let status = entry.status;
        let replaced = store.run(&id).is_some();
        store.write_run(entry, &run.trajectory).with_context(|| {
            format!(
                "storing run '{id}' (from {}) in {}",
                file.display(),
                target.out.display()
            )
        })?;
        let t = &run.trajectory;
        say(format!(
            "{id}: {} samples, {:.2} s at {} Hz, {} bodies, {} gaps{}{} <- {}",
            t.len(),
            t.time_s.last().copied().unwrap_or(0.0),
            run.frequency_hz,
            t.bodies.len(),
            run.gap_count(),
            if status == RunStatus::Diverged {
                ", diverged (non-finite values)"
            } else {
                ""
            },
            if replaced { " (replaced)" } else { "" },
            file.display()
        ));
        for w in &run.warnings {
            say(format!("  warning: {w}"));
        }
    }
    let imported = files.len() - failed;
    say(format!(
        "imported {imported} of {} files into {} (source '{}', {}, scene {})",
        files.len(),
        target.out.display(),
        target.source,
        target.kind,
        target.scene.unwrap_or("not set")
    ));
    if failed > 0 {
        bail!(
            "{failed} of {} files could not be imported (see the errors above)",
            files.len()
        );
    }
    Ok(())
}

/// The manifest entry of an imported run: warnings as message, counts in
/// `extra`; `diverged` when a pose holds non-finite numbers.
pub fn entry_for(id: &str, file: &Path, run: &ImportedRun) -> RunEntry {
    let t = &run.trajectory;
    let mut entry = RunEntry::new(id);
    let origin = std::fs::canonicalize(file).unwrap_or_else(|_| file.to_path_buf());
    entry.origin = vec![origin.display().to_string()];
    let non_finite = t
        .bodies
        .iter()
        .flat_map(|b| b.poses.iter().flatten())
        .any(|p| !p.is_finite());
    if non_finite {
        entry.status = RunStatus::Diverged;
    }
    if !run.warnings.is_empty() {
        entry.message = Some(run.warnings.join("; "));
    }
    let bodies: Map<String, Value> = run
        .body_names
        .iter()
        .zip(&t.bodies)
        .map(|(name, b)| (b.role.clone(), Value::from(name.clone())))
        .collect();
    let extra = &mut entry.extra;
    extra.insert("samples".into(), t.len().into());
    extra.insert("frequency_hz".into(), run.frequency_hz.into());
    extra.insert("bodies".into(), Value::Object(bodies));
    extra.insert("gaps".into(), run.gap_count().into());
    if !run.zero_rows.is_empty() {
        extra.insert("zero_rows".into(), run.zero_rows.len().into());
    }
    if !run.bad_norm_rows.is_empty() {
        extra.insert("bad_norm_rows".into(), run.bad_norm_rows.len().into());
    }
    entry
}
