//! `realitygap compare`: a study's accumulated-error table and measures,
//! the joint-space table of a replay's folder, or the toss table of a
//! replay of tosses, evaluated once and written in any format. Shared by
//! the command and the Python package.

use anyhow::Result;
use realitygap_analysis::compare::SceneReport;
use realitygap_analysis::table::{self, Format};
use realitygap_study::joint_space::JointTable;
use realitygap_study::replay::JointSpaceRow;
use realitygap_study::{evaluate_measured, load_study, DataSource, Measure, SourceSpec, Study};
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
    /// Sources added to the study's scenes (scene name, source with an
    /// absolute results directory): the physics-free rows of
    /// `--physics-free` ([`physics_free_sources`]).
    pub added_sources: AddedSources,
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
    /// A replay of tosses: per source, the toss table's row.
    Tosses {
        /// The rows.
        rows: Vec<realitygap_study::tosses::TossRow>,
        /// The real tosses.
        set: realitygap_study::tosses::TossSet,
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
    if realitygap_study::tosses::is_toss_replay_folder(&request.study) {
        if request.joint_space {
            anyhow::bail!("--joint-space belongs to a study of the arm, not to a replay of tosses");
        }
        let (rows, set) = realitygap_study::tosses::compare_toss_replay(&request.study)?;
        return Ok(Comparison::Tosses { rows, set });
    }
    let (mut study, roots) = load_study(&request.study, &request.data, request.results.clone())?;
    add_sources(&mut study, &request.added_sources);
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
            Comparison::Tosses { rows, set } => {
                use realitygap_study::tosses::{toss_csv, toss_json, toss_markdown};
                Ok(match format {
                    Format::Markdown => toss_markdown(rows, set),
                    Format::Csv => toss_csv(rows, set),
                    Format::Json => toss_json(rows),
                    other => anyhow::bail!(
                        "--format {}: the toss table is written as md, csv or json",
                        format!("{other:?}").to_lowercase()
                    ),
                })
            }
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

/// Adds `sources` (scene name, source) to the study's scenes.
pub fn add_sources(study: &mut Study, sources: &[(String, SourceSpec)]) {
    for (scene, source) in sources {
        if let Some(s) = study.scenes.iter_mut().find(|s| s.name == *scene) {
            s.sources.push(source.clone());
        }
    }
}

/// The physics-free rows of `compare --physics-free`: the physics-free
/// model (perfect tracking of the commands, the `ideal` engine) run once in
/// every scene of the study at `study_path` that names a scene file, into
/// `runs_dir/perfect`; with `params` (a parameters file, or the `--out`
/// folder of a `realitygap tune`, whose fitted physics-free model
/// `physics-free-actuator/tuned.toml` is taken), the model behind those
/// parameters too, into `runs_dir/tuned`. Returned as sources to add
/// ([`CompareRequest::added_sources`]): "physics-free (this tool)" and
/// "physics-free (tuned)", as `reproduce` names them.
pub fn physics_free_sources(
    study_path: &Path,
    params: Option<&Path>,
    runs_dir: &Path,
    launcher: &realitygap_runner::Launcher,
    ui: &dyn crate::ui::Ui,
) -> Result<AddedSources> {
    use anyhow::{bail, Context};
    use realitygap_core::engine::PHYSICS_FREE_ENGINE;
    if !crate::engines()
        .iter()
        .any(|e| e.name() == PHYSICS_FREE_ENGINE)
    {
        bail!("--physics-free: the physics-free model ({PHYSICS_FREE_ENGINE}) is not compiled into this binary");
    }
    let study = Study::from_file(study_path)?;
    let scenes: Vec<(String, PathBuf)> = study
        .scenes
        .iter()
        .filter_map(|s| Some((s.name.clone(), study.folder.join(s.scene.as_ref()?))))
        .collect();
    if scenes.is_empty() {
        bail!(
            "--physics-free: no scene of {} names a scene file (`scene = ...`), so the physics-free model has no commands to follow",
            study_path.display()
        );
    }
    let tuned = params.map(fitted_physics_free).transpose()?;
    let mut out = Vec::new();
    for (folder, file) in [("perfect", None), ("tuned", tuned.as_ref())] {
        if folder == "tuned" && file.is_none() {
            continue;
        }
        // Absolute: the sources' folders are read relative to the study's
        // results root (the study file's folder by default), not to where
        // the command runs.
        let dir = std::path::absolute(runs_dir.join(folder))
            .with_context(|| format!("--physics-free: the folder {}", runs_dir.display()))?;
        let spec = realitygap_runner::BatchSpec {
            scenes: scenes.iter().map(|(_, f)| f.clone()).collect(),
            engines: vec![PHYSICS_FREE_ENGINE.to_string()],
            repeats: 1,
            out: dir.clone(),
            robot: None,
            packages: vec![],
            jobs: None,
            seed: 0,
            perturb: vec![],
            set: vec![],
            timeout_s: None,
            params: file.cloned(),
            stitch: None,
            allow_unstable: false,
        };
        crate::batch::run(
            spec,
            realitygap_runner::slurm::Executor::Local,
            launcher,
            ui,
        )
        .and_then(|o| o.check())
        .with_context(|| {
            format!(
                "--physics-free: running the physics-free model into {}",
                dir.display()
            )
        })?;
        for (scene, _) in &scenes {
            for mut source in realitygap_study::reproduce::engine_sources(
                &dir,
                scene,
                &[PHYSICS_FREE_ENGINE.to_string()],
            )? {
                if let Some(f) = file {
                    source.name = source.name.replace("(this tool)", "(tuned)");
                    source.about = Some(format!(
                        "{}, with the parameters of {}",
                        source.about.unwrap_or_default(),
                        f.display()
                    ));
                }
                source.dir = source.dir.map(|d| dir.join(d).display().to_string());
                out.push((scene.clone(), source));
            }
        }
    }
    Ok(out)
}

/// Sources added to a study's scenes: (scene name, source).
pub type AddedSources = Vec<(String, SourceSpec)>;

/// Which physics-free rows `compare` and `report` add to a study.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PhysicsFreeRows {
    /// None (`--no-physics-free`).
    None,
    /// Perfect tracking, when the study can have it ([`Self::applies`]);
    /// nothing otherwise.
    Default,
    /// Perfect tracking, and with a parameters file or tune folder the
    /// fitted model too (`--physics-free [FILE|TUNE_DIR]`); an error when
    /// they cannot be made.
    Asked(Option<PathBuf>),
}

impl PhysicsFreeRows {
    /// Whether the default row applies to the study file at `study_path`:
    /// the physics-free model is compiled in, some scene names a scene
    /// file, and no scene has a physics-free source yet (a `reproduce`
    /// folder's study has them). A replay's folder, or a study that cannot
    /// be read, gets none (the comparison then reports what is wrong).
    pub fn applies(study_path: &Path) -> bool {
        use realitygap_core::engine::PHYSICS_FREE_ENGINE;
        if is_replay_folder(study_path)
            || !crate::engines()
                .iter()
                .any(|e| e.name() == PHYSICS_FREE_ENGINE)
        {
            return false;
        }
        let Ok(study) = Study::from_file(study_path) else {
            return false;
        };
        study.scenes.iter().any(|s| s.scene.is_some())
            && !study
                .scenes
                .iter()
                .flat_map(|s| &s.sources)
                .any(|source| realitygap_report::verdict::is_physics_free(&source.name))
    }

    /// Whether these rows are made for the study at `study_path`.
    fn made_for(&self, study_path: &Path) -> bool {
        match self {
            Self::None => false,
            Self::Default => Self::applies(study_path),
            Self::Asked(_) => true,
        }
    }

    /// The parameters of the fitted row, when it is asked for.
    fn params(&self) -> Option<&Path> {
        match self {
            Self::Asked(params) => params.as_deref(),
            _ => None,
        }
    }

    /// The rows' sources for the study at `study_path`, their runs under
    /// `runs_dir` ([`physics_free_sources`]).
    pub fn sources(
        &self,
        study_path: &Path,
        runs_dir: &Path,
        launcher: &realitygap_runner::Launcher,
        ui: &dyn crate::ui::Ui,
    ) -> Result<AddedSources> {
        if !self.made_for(study_path) {
            return Ok(Vec::new());
        }
        physics_free_sources(study_path, self.params(), runs_dir, launcher, ui)
    }

    /// [`Self::sources`] with the runs in a temporary folder (made only
    /// when there are rows), which the caller keeps as long as it compares
    /// them.
    pub fn sources_in_temp(
        &self,
        study_path: &Path,
        launcher: &realitygap_runner::Launcher,
        ui: &dyn crate::ui::Ui,
    ) -> Result<(Option<tempfile::TempDir>, AddedSources)> {
        if !self.made_for(study_path) {
            return Ok((None, Vec::new()));
        }
        let runs = tempfile::Builder::new()
            .prefix("realitygap-physics-free-")
            .tempdir()?;
        let sources = physics_free_sources(study_path, self.params(), runs.path(), launcher, ui)?;
        Ok((Some(runs), sources))
    }
}

/// The parameters file of `--physics-free FILE|TUNE_DIR`: a file as it is;
/// a tune of the physics-free model, its `tuned.toml`; another tune, the
/// physics-free model fitted beside it
/// (`physics-free-actuator/tuned.toml`).
fn fitted_physics_free(given: &Path) -> Result<PathBuf> {
    use anyhow::bail;
    if given.is_file() {
        return Ok(std::path::absolute(given)?);
    }
    if !given.is_dir() {
        bail!(
            "--physics-free {}: no such parameters file or tune folder",
            given.display()
        );
    }
    let te = realitygap_study::reproduce::TunedEngine::from_dir(given)?;
    let file = if te.engine == realitygap_core::engine::PHYSICS_FREE_ENGINE {
        te.params
    } else {
        let fitted = given
            .join(realitygap_tune::outputs::PHYSICS_FREE_DIR)
            .join("tuned.toml");
        if !fitted.is_file() {
            bail!(
                "--physics-free {}: the tune of {} holds no fitted physics-free model ({} is missing; `realitygap tune` writes it beside its own tune)",
                given.display(),
                te.engine,
                fitted.display()
            );
        }
        fitted
    };
    Ok(std::path::absolute(file)?)
}

/// The report's section of the cross-validated tunes in `folders` (each
/// `tune --folds K`'s output folder, or its `crossval.json`); none when
/// `folders` is empty.
pub fn crossval_section(
    folders: &[std::path::PathBuf],
) -> anyhow::Result<Option<realitygap_report::html::ExtraSection>> {
    if folders.is_empty() {
        return Ok(None);
    }
    let cvs: Vec<realitygap_tune::crossval::CrossValidation> = folders
        .iter()
        .map(|f| realitygap_tune::crossval::read(f))
        .collect::<anyhow::Result<_>>()?;
    Ok(Some(realitygap_tune::crossval::report_section(&cvs)))
}
