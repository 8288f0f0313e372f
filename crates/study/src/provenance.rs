//! The provenance of a study's report: where each source's runs came
//! from (the format and files of recordings; the engine, settings and
//! seeds of results directories), for `report` and `reproduce`.

use crate::files::glob;
use crate::load::Roots;
use crate::measure::Measure;
use crate::study::{expand, SourceFormat, SourceSpec, Study};
use realitygap_analysis::compare::AnalysisMode;
use realitygap_data::RunStore;
use realitygap_report::{HandoverMarks, Provenance, SourceProvenance};
use std::path::Path;

/// Provenance of a report of `study`: the study's title, file and folders,
/// the mode, and per source (reference and sources, each once) where its
/// runs came from: the format and files for recordings, the engine,
/// settings and seeds from the manifest for results directories.
pub fn provenance_for_study(
    study: &Study,
    study_path: &Path,
    roots: &Roots,
    mode: AnalysisMode,
) -> Provenance {
    let mut p = Provenance::new(study.title.clone().unwrap_or_else(|| study.name.clone()));
    let absolute = |p: &Path| {
        std::fs::canonicalize(p)
            .unwrap_or_else(|_| p.to_path_buf())
            .display()
            .to_string()
    };
    p.study = Some(absolute(study_path));
    p.data_dir = Some(absolute(&roots.data));
    p.results_dir = Some(absolute(&roots.results));
    p.mode = mode;
    p.details.push((
        "Control period".into(),
        format!("{} s", study.control_period_s),
    ));
    for scene in &study.scenes {
        for spec in std::iter::once(&scene.reference)
            .chain(&study.sources)
            .chain(&scene.sources)
        {
            let entry = match p.sources.iter().position(|s| s.name == spec.name) {
                Some(i) => i,
                None => {
                    p.sources.push(source_header(spec));
                    p.sources.len() - 1
                }
            };
            if let Some(times_s) = handover_times(spec, &scene.vars, roots) {
                p.handovers.push(HandoverMarks {
                    scene: scene.name.clone(),
                    source: spec.name.clone(),
                    times_s,
                });
            }
            let details = scene_details(spec, &scene.vars, roots);
            for (k, v) in details {
                p.sources[entry]
                    .details
                    .push((format!("{}: {k}", scene.name), v));
            }
        }
    }
    p
}

/// The report's lines for what the user chose of the measure: the
/// alignment override, the registration, the runs and the held-out runs.
pub fn measure_details(m: &Measure) -> Vec<(String, String)> {
    let mut out = Vec::new();
    if let Some(a) = &m.alignment {
        out.push(("Alignment override".into(), a.clone()));
    }
    for (what, value) in [
        ("Registration", &m.registration),
        ("Runs", &m.runs),
        ("Held-out runs", &m.holdout),
    ] {
        if let Some(v) = value {
            out.push((what.into(), v.clone()));
        }
    }
    out
}

/// What is the same for a source in every scene.
fn source_header(spec: &SourceSpec) -> SourceProvenance {
    let mut s = SourceProvenance::new(&spec.name).with(
        "format",
        match spec.format {
            SourceFormat::Qualisys => "Qualisys 6DOF TSV (motion capture)",
            SourceFormat::Recorded => "recorded simulator CSV",
            SourceFormat::Store => "realitygap results directory",
        },
    );
    if let Some(about) = &spec.about {
        s = s.with("about", about.clone());
    }
    if let Some(q) = spec.quat_order {
        s = s.with("quaternion order", q.to_string());
    }
    s
}

/// What a source's runs in one scene came from.
fn scene_details(
    spec: &SourceSpec,
    vars: &std::collections::BTreeMap<String, String>,
    roots: &Roots,
) -> Vec<(String, String)> {
    let mut out = Vec::new();
    if let Some(a) = &spec.alignment {
        out.push(("alignment in the study file".into(), a.describe()));
    }
    match spec.format {
        SourceFormat::Qualisys | SourceFormat::Recorded => {
            let Some(pattern) = spec.files.as_deref().and_then(|f| expand(f, vars).ok()) else {
                return out;
            };
            let count = glob(&roots.data, &pattern).map(|f| f.len()).unwrap_or(0);
            out.push(("files".into(), format!("{pattern} ({count} files)")));
        }
        SourceFormat::Store => {
            let Some(dir) = spec.dir.as_deref().and_then(|d| expand(d, vars).ok()) else {
                return out;
            };
            let path = roots.results.join(&dir);
            out.push(("results directory".into(), dir));
            match RunStore::open(&path) {
                Ok(store) => {
                    let m = store.manifest();
                    if let Some(e) = &m.engine {
                        out.push(("engine".into(), format!("{} {}", e.name, e.version)));
                    }
                    out.push((
                        "written by".into(),
                        format!("realitygap {}", m.tool_version),
                    ));
                    if let serde_json::Value::Object(settings) = &m.settings {
                        for (k, v) in settings {
                            let v = match v {
                                serde_json::Value::String(s) => s.clone(),
                                other => other.to_string(),
                            };
                            out.push((k.clone(), v));
                        }
                    }
                    let mut seeds: Vec<u64> = m.runs.iter().filter_map(|r| r.seed).collect();
                    if !seeds.is_empty() {
                        seeds.sort_unstable();
                        seeds.dedup();
                        out.push(("seeds".into(), ranges(&seeds)));
                    }
                    out.push(("runs".into(), m.runs.len().to_string()));
                }
                Err(e) => out.push(("manifest".into(), format!("unreadable: {e}"))),
            }
        }
    }
    out
}

/// The handover times of a stitched results directory (its runs'
/// `handovers`, from the manifest); `None` for any other source.
fn handover_times(
    spec: &SourceSpec,
    vars: &std::collections::BTreeMap<String, String>,
    roots: &Roots,
) -> Option<Vec<f64>> {
    if spec.format != SourceFormat::Store {
        return None;
    }
    let dir = spec.dir.as_deref().and_then(|d| expand(d, vars).ok())?;
    let store = RunStore::open(&roots.results.join(dir)).ok()?;
    let mut times: Vec<f64> = store
        .manifest()
        .runs
        .iter()
        .filter_map(|r| r.extra.get("handovers")?.as_array())
        .flatten()
        .filter_map(|h| h.get("t_s")?.as_f64())
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    (!times.is_empty()).then_some(times)
}

/// Sorted distinct numbers as ranges: `0-19, 25, 30-31`.
fn ranges(v: &[u64]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < v.len() {
        let mut j = i;
        while j + 1 < v.len() && v[j + 1] == v[j] + 1 {
            j += 1;
        }
        parts.push(if i == j {
            v[i].to_string()
        } else {
            format!("{}-{}", v[i], v[j])
        });
        i = j + 1;
    }
    parts.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_ranges() {
        assert_eq!(ranges(&[0, 1, 2, 3, 7, 9, 10]), "0-3, 7, 9-10");
        assert_eq!(ranges(&[5]), "5");
        assert_eq!(ranges(&[]), "");
    }
}
