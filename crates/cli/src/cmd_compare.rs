//! `realitygap compare`: the accumulated-error table and per-scene measures.

use anyhow::{bail, Context, Result};
use realitygap::data_source::DataSource;
use realitygap::study::{Roots, SourceFormat, Study};
use realitygap_analysis::align::Alignment;
use realitygap_analysis::bootstrap::BootstrapOptions;
use realitygap_analysis::compare::{
    AnalysisMode, CompareOptions, RegistrationChoice, RegistrationReport, SceneReport,
};
use realitygap_analysis::registration::Registration;
use realitygap_analysis::selection::{RunRange, RunSelection};
use realitygap_analysis::table::{self, Format};
use std::path::{Path, PathBuf};

/// How the gap is measured: mode, alignment, registration, runs and
/// intervals (shared by `compare` and `report`).
#[derive(clap::Args, Debug, Clone)]
pub struct MeasureArgs {
    /// `default`: leave flagged runs out, align the real runs to the
    /// scene's kinematic reference, register the capture frame, cut runs
    /// that end early, give bootstrap intervals. `study`: the reference
    /// study's exact procedure (every run averaged in, the study file's
    /// alignment, the raw capture frame).
    #[arg(long, default_value = "default", value_parser = ["default", "study"])]
    pub mode: String,
    /// Override the alignment of recordings: `estimate`, `onset:LEAD` (motion
    /// onset minus LEAD frames) or `fixed:FRAME`.
    #[arg(long)]
    pub alignment: Option<String>,
    /// Capture-frame registration (default mode): `estimate` (the default:
    /// fitted on the fit runs' settled poses against the kinematic
    /// reference), `none` (the raw capture frame), or a registration.json
    /// file (`{"rotation_wxyz": [w, x, y, z], "translation_m": [x, y, z]}`,
    /// world = R * capture + t).
    #[arg(long, value_name = "FILE|estimate|none")]
    pub registration: Option<String>,
    /// Write the registration applied (estimated or given) to this file as
    /// registration.json.
    #[arg(long, value_name = "FILE")]
    pub save_registration: Option<PathBuf>,
    /// Real runs to fit on (and to score on without --holdout), numbered
    /// from 1 in file order: e.g. `1-15` or `1-5,8`. Default: the study
    /// file's `runs`, else all.
    #[arg(long, value_name = "RANGE")]
    pub runs: Option<String>,
    /// Real runs to score on, never fitted on: e.g. `16-20`. Default: the
    /// study file's `holdout`, else none held out.
    #[arg(long, value_name = "RANGE")]
    pub holdout: Option<String>,
    /// Bootstrap resamples for the intervals (0: no intervals). Default
    /// 1000 in default mode, none in study mode.
    #[arg(long, value_name = "N")]
    pub bootstrap: Option<usize>,
    /// Seed of the bootstrap draws.
    #[arg(long, default_value_t = 2019)]
    pub seed: u64,
}

impl MeasureArgs {
    /// The analysis mode.
    pub fn analysis_mode(&self) -> AnalysisMode {
        if self.mode == "study" {
            AnalysisMode::Study
        } else {
            AnalysisMode::Default
        }
    }

    /// The comparison options, with the study file's run selection where
    /// the command line gives none.
    pub fn options(&self, study: &Study) -> Result<CompareOptions> {
        let mode = self.analysis_mode();
        let registration = match self.registration.as_deref() {
            None => RegistrationChoice::Auto,
            Some(_) if mode == AnalysisMode::Study => bail!(
                "--registration does not apply to --mode study: the study's procedure keeps the raw capture frame"
            ),
            Some("estimate") => RegistrationChoice::Estimate,
            Some("none") => RegistrationChoice::None,
            Some(file) => RegistrationChoice::Given {
                registration: Registration::from_file(Path::new(file))
                    .context("--registration")?,
                origin: file.to_string(),
            },
        };
        let range = |cli: &Option<String>, file: &Option<String>, flag: &str, field: &str| match (
            cli, file,
        ) {
            (Some(v), _) => RunRange::parse(v, flag).map(Some),
            (None, Some(v)) => RunRange::parse(v, &format!("study file `{field}`")).map(Some),
            (None, None) => Ok(None),
        };
        let runs = RunSelection {
            runs: range(&self.runs, &study.runs, "--runs", "runs")?,
            holdout: range(&self.holdout, &study.holdout, "--holdout", "holdout")?,
        };
        Ok(CompareOptions {
            mode,
            alignment: self.alignment.as_deref().map(parse_alignment).transpose()?,
            registration,
            runs,
            bootstrap: match (self.bootstrap, mode) {
                (None, AnalysisMode::Study) => None,
                (n, _) => Some(BootstrapOptions {
                    resamples: n.unwrap_or(BootstrapOptions::default().resamples),
                    seed: self.seed,
                    ..BootstrapOptions::default()
                }),
            },
            ..CompareOptions::default()
        })
    }

    /// Writes the registration of `reports` to `--save-registration`, if
    /// asked; an error when none was applied.
    pub fn save_registration(&self, reports: &[SceneReport]) -> Result<()> {
        let Some(path) = &self.save_registration else {
            return Ok(());
        };
        let Some(r) = reports.iter().find_map(|r| r.registration.as_ref()) else {
            bail!(
                "--save-registration {}: no registration was applied (study mode, --registration none, or no real reference)",
                path.display()
            );
        };
        std::fs::write(path, RegistrationReport::registration(r).to_json())
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

/// Arguments of `realitygap compare`.
#[derive(clap::Args)]
pub struct Args {
    /// A study file (TOML).
    pub study: PathBuf,
    /// Folder that the study's file patterns are relative to: `builtin`
    /// (the default: the study's recordings built into the project,
    /// unpacked once into ~/.cache/realitygap or $REALITYGAP_CACHE_DIR), a
    /// folder such as your own copy of the recordings, or `none` for a
    /// study of results directories only.
    #[arg(long, value_name = "builtin|none|DIR", default_value = "builtin")]
    pub data: DataSource,
    /// Folder that the study's results directories (`store` sources) are
    /// relative to. Default: the study file's folder.
    #[arg(long)]
    pub results: Option<PathBuf>,
    /// Output format: md, csv, json or latex.
    #[arg(long, default_value = "md")]
    pub format: String,
    /// How the gap is measured.
    #[command(flatten)]
    pub measure: MeasureArgs,
    /// Include per-step series in JSON output.
    #[arg(long)]
    pub series: bool,
    /// Write the output to this file instead of standard output.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
}

/// Parses `--alignment`.
pub fn parse_alignment(s: &str) -> Result<Alignment> {
    let (method, arg) = s.split_once(':').map_or((s, None), |(m, a)| (m, Some(a)));
    let num = |what: &str| -> Result<usize> {
        arg.with_context(|| format!("--alignment {method} needs a number: {method}:{what}"))?
            .parse()
            .with_context(|| format!("--alignment {s}: {what} must be a whole number"))
    };
    Ok(match method {
        "estimate" => Alignment::estimate(),
        "onset" => Alignment::Onset {
            lead_frames: num("LEAD")?,
            rest_frames: (20, 100),
            threshold_m: 0.01,
        },
        "fixed" => Alignment::Fixed {
            frame: num("FRAME")?,
        },
        _ => bail!("unknown --alignment '{s}' (expected estimate, onset:LEAD or fixed:FRAME)"),
    })
}

/// Reads a study file and finds the folders its sources are relative to:
/// `--data` for file patterns (resolved only when the study reads
/// recordings; the built-in ones are unpacked on first use), `--results`
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
fn reads_recordings(study: &Study) -> Option<String> {
    study
        .scenes
        .iter()
        .flat_map(|s| std::iter::once(&s.reference).chain(&s.sources))
        .chain(&study.sources)
        .find(|s| s.format != SourceFormat::Store)
        .map(|s| format!("{}: {}", s.name, s.files.as_deref().unwrap_or("")))
}

/// Evaluates every scene of a study (read from `study_path`) with the
/// options `measure` gives for it, and saves the registration if asked.
pub fn evaluate(
    study_path: &Path,
    study: &Study,
    roots: &Roots,
    measure: &MeasureArgs,
) -> Result<Vec<SceneReport>> {
    let opts = measure.options(study)?;
    let scenes = study.load(roots)?;
    let inputs: Vec<_> = scenes.iter().map(|s| s.input()).collect();
    let reports = realitygap_analysis::evaluate_study(&inputs, &opts)
        .with_context(|| format!("study {}", study_path.display()))?;
    measure.save_registration(&reports)?;
    Ok(reports)
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let format: Format = args.format.parse().map_err(anyhow::Error::msg)?;
    let (study, roots) = load_study(&args.study, &args.data, args.results)?;
    let reports = evaluate(&args.study, &study, &roots, &args.measure)?;
    let text = if format == Format::Json && args.series {
        serde_json::to_string_pretty(&table::to_json(&reports, true))? + "\n"
    } else {
        table::render(&reports, format)
    };
    match args.output {
        Some(p) => {
            std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => print!("{text}"),
    }
    Ok(())
}
