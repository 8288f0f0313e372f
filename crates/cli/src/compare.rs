//! `realitygap compare`: a study's accumulated-error table and measures,
//! or the joint-space table of a replay's folder, evaluated once and
//! written in any format. Shared by the command and the Python package.

use anyhow::Result;
use realitygap_analysis::compare::SceneReport;
use realitygap_analysis::table::{self, Format};
use realitygap_study::joint_space::JointTable;
use realitygap_study::replay::JointSpaceRow;
use realitygap_study::{evaluate_measured, load_study, DataSource, Measure};
use std::path::{Path, PathBuf};

/// What `compare` compares and how.
#[derive(Debug, Clone, Default)]
pub struct CompareRequest {
    /// A study file, or the output folder of `realitygap replay`.
    pub study: PathBuf,
    /// With a replay's folder: the link measured by forward kinematics.
    pub link: Option<String>,
    /// Where the study's recordings are (`--data`).
    pub data: DataSource,
    /// Where the study's results directories are (`--results`).
    pub results: Option<PathBuf>,
    /// How the gap is measured.
    pub measure: Measure,
    /// Also in joint space (`--joint-space`).
    pub joint_space: bool,
}

/// An evaluated comparison.
pub enum Comparison {
    /// A study: per scene, the report; with `--joint-space`, the tables.
    Study {
        /// Per scene.
        reports: Vec<SceneReport>,
        /// The joint-space tables, when asked for.
        joint: Option<Vec<JointTable>>,
    },
    /// A replay's folder: per source, the joint-space row.
    Replay {
        /// The rows.
        rows: Vec<JointSpaceRow>,
        /// The replayed joints' names.
        joints: Vec<String>,
        /// The link whose position error is measured.
        link: String,
    },
}

/// Whether `path` is the output folder of `realitygap replay`.
pub fn is_replay_folder(path: &Path) -> bool {
    path.join(realitygap_study::replay::RECORD_FILE).is_file()
}

/// Evaluates `request`.
pub fn evaluate(request: &CompareRequest) -> Result<Comparison> {
    if is_replay_folder(&request.study) {
        let (rows, joints, link) =
            realitygap_study::replay::compare_replay(&request.study, request.link.as_deref())?;
        return Ok(Comparison::Replay { rows, joints, link });
    }
    if request.link.is_some() {
        anyhow::bail!("--link belongs to the comparison of a replay's folder (the output of `realitygap replay`)");
    }
    let (study, roots) = load_study(&request.study, &request.data, request.results.clone())?;
    let reports = evaluate_measured(&request.study, &study, &roots, &request.measure)?;
    let joint = if request.joint_space {
        Some(realitygap_study::joint_space::study_tables(
            &study,
            &roots,
            &request.measure,
        )?)
    } else {
        None
    };
    Ok(Comparison::Study { reports, joint })
}

impl Comparison {
    /// The comparison as `compare --format` writes it; `series`: per-step
    /// series in JSON.
    pub fn render(&self, format: Format, series: bool) -> Result<String> {
        match self {
            Comparison::Study { reports, joint } => Ok(match (joint, format) {
                (Some(tables), Format::Json) => {
                    let mut v = table::to_json(reports, series);
                    v["joint_space"] = serde_json::to_value(tables)?;
                    serde_json::to_string_pretty(&v)? + "\n"
                }
                (Some(tables), Format::Markdown) => {
                    table::render(reports, format)
                        + "\n"
                        + &realitygap_study::joint_space::markdown(tables)
                }
                (Some(_), other) => anyhow::bail!(
                    "--joint-space is written as md or json, not {}",
                    format!("{other:?}").to_lowercase()
                ),
                (None, _) if format == Format::Json && series => {
                    serde_json::to_string_pretty(&table::to_json(reports, true))? + "\n"
                }
                (None, _) => table::render(reports, format),
            }),
            Comparison::Replay { rows, joints, link } => {
                use realitygap_study::replay::{
                    joint_space_csv, joint_space_json, joint_space_markdown,
                };
                Ok(match format {
                    Format::Markdown => joint_space_markdown(rows, joints),
                    Format::Csv => joint_space_csv(rows, joints),
                    Format::Json => {
                        serde_json::to_string_pretty(&joint_space_json(rows, joints, link))? + "\n"
                    }
                    other => anyhow::bail!(
                        "--format {}: the joint-space comparison is written as md, csv or json",
                        format!("{other:?}").to_lowercase()
                    ),
                })
            }
        }
    }
}
