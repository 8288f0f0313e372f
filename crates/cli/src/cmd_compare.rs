//! `realitygap compare`: the accumulated-error table and per-scene measures.

use anyhow::{bail, Context, Result};
use realitygap::data_source::DataSource;
use realitygap::study::{Roots, SourceFormat, Study};
use realitygap_analysis::align::Alignment;
use realitygap_analysis::compare::{evaluate_scene, AnalysisMode, CompareOptions, SceneReport};
use realitygap_analysis::table::{self, Format};
use std::path::{Path, PathBuf};

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
    /// `default`: leave flagged runs out, estimate each real run's time
    /// offset, cut runs that end early. `study`: the reference study's exact
    /// procedure (every run averaged in, the study file's alignment).
    #[arg(long, default_value = "default", value_parser = ["default", "study"])]
    pub mode: String,
    /// Override the alignment of recordings: `estimate`, `onset:LEAD` (motion
    /// onset minus LEAD frames) or `fixed:FRAME`.
    #[arg(long)]
    pub alignment: Option<String>,
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

/// Evaluates every scene of a study.
pub fn evaluate(study: &Study, roots: &Roots, opts: &CompareOptions) -> Result<Vec<SceneReport>> {
    let scenes = study.load(roots)?;
    Ok(scenes
        .iter()
        .map(|s| evaluate_scene(&s.spec, &s.reference, &s.sources, opts))
        .collect())
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let format: Format = args.format.parse().map_err(anyhow::Error::msg)?;
    let opts = CompareOptions {
        mode: if args.mode == "study" {
            AnalysisMode::Study
        } else {
            AnalysisMode::Default
        },
        alignment: args.alignment.as_deref().map(parse_alignment).transpose()?,
        ..CompareOptions::default()
    };
    let (study, roots) = load_study(&args.study, &args.data, args.results)?;
    let reports = evaluate(&study, &roots, &opts)?;
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
