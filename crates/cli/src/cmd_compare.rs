//! `realitygap compare`: the accumulated-error table and per-scene measures.

use anyhow::{Context, Result};
use realitygap_analysis::compare::AnalysisMode;
use realitygap_analysis::table::{self, Format};
use realitygap_study::{evaluate_measured, load_study, parse_mode, DataSource, Measure, MODES};
use std::path::PathBuf;

/// How the gap is measured: mode, alignment, registration, runs and
/// intervals (shared by `compare` and `report`).
#[derive(clap::Args, Debug, Clone)]
pub struct MeasureArgs {
    /// `default`: leave flagged runs out, align the real runs to the
    /// scene's kinematic reference, register the capture frame, cut runs
    /// that end early, give bootstrap intervals. `study`: the reference
    /// study's exact procedure (every run averaged in, the study file's
    /// alignment, the raw capture frame).
    #[arg(long, default_value = "default", value_parser = mode_parser())]
    pub mode: AnalysisMode,
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

/// `--mode`: one of [`MODES`], as an [`AnalysisMode`].
pub fn mode_parser() -> impl clap::builder::TypedValueParser<Value = AnalysisMode> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(MODES).try_map(|s| parse_mode(&s))
}

impl MeasureArgs {
    /// The measure these arguments give.
    pub fn measure(&self) -> Measure {
        Measure {
            mode: self.mode,
            alignment: self.alignment.clone(),
            registration: self.registration.clone(),
            save_registration: self.save_registration.clone(),
            runs: self.runs.clone(),
            holdout: self.holdout.clone(),
            bootstrap: self.bootstrap,
            seed: self.seed,
        }
    }
}

/// Arguments of `realitygap compare`.
#[derive(clap::Args)]
pub struct Args {
    /// A study file (TOML), or the output folder of `realitygap replay`
    /// (the joint-space comparison of a robot's own recordings).
    pub study: PathBuf,
    /// With a replay's folder: the link whose position error is measured by
    /// forward kinematics (default: the replay's end effector).
    #[arg(long, value_name = "NAME")]
    pub link: Option<String>,
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
    /// Also compare in joint space: the real runs' joint angles by inverse
    /// kinematics of the wrist capture (registration and marker offset
    /// fitted on the fit runs), against every source that recorded joint
    /// angles and the physics-free model; per scene, the RMS angle error per
    /// joint (md and json).
    #[arg(long)]
    pub joint_space: bool,
    /// Write the output to this file instead of standard output.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let format: Format = args.format.parse().map_err(anyhow::Error::msg)?;
    if args
        .study
        .join(realitygap_study::replay::RECORD_FILE)
        .is_file()
    {
        return joint_space(&args, format);
    }
    if args.link.is_some() {
        anyhow::bail!("--link belongs to the comparison of a replay's folder (the output of `realitygap replay`)");
    }
    let (study, roots) = load_study(&args.study, &args.data, args.results)?;
    let measure = args.measure.measure();
    let reports = evaluate_measured(&args.study, &study, &roots, &measure)?;
    let joint = if args.joint_space {
        Some(realitygap_study::joint_space::study_tables(
            &study, &roots, &measure,
        )?)
    } else {
        None
    };
    let text = match (&joint, format) {
        (Some(tables), Format::Json) => {
            let mut v = table::to_json(&reports, args.series);
            v["joint_space"] = serde_json::to_value(tables)?;
            serde_json::to_string_pretty(&v)? + "\n"
        }
        (Some(tables), Format::Markdown) => {
            table::render(&reports, format)
                + "\n"
                + &realitygap_study::joint_space::markdown(tables)
        }
        (Some(_), other) => anyhow::bail!(
            "--joint-space is written as md or json, not {}",
            format!("{other:?}").to_lowercase()
        ),
        (None, _) if format == Format::Json && args.series => {
            serde_json::to_string_pretty(&table::to_json(&reports, true))? + "\n"
        }
        (None, _) => table::render(&reports, format),
    };
    match args.output {
        Some(p) => {
            std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => print!("{text}"),
    }
    Ok(())
}

/// `compare OUT` of a replay: the joint-space table of every source.
fn joint_space(args: &Args, format: Format) -> Result<()> {
    use realitygap_study::replay::{
        compare_replay, joint_space_csv, joint_space_json, joint_space_markdown,
    };
    let (rows, names, link) = compare_replay(&args.study, args.link.as_deref())?;
    let text = match format {
        Format::Markdown => joint_space_markdown(&rows, &names),
        Format::Csv => joint_space_csv(&rows, &names),
        Format::Json => {
            serde_json::to_string_pretty(&joint_space_json(&rows, &names, &link))? + "\n"
        }
        other => anyhow::bail!(
            "--format {}: the joint-space comparison is written as md, csv or json",
            format!("{other:?}").to_lowercase()
        ),
    };
    match &args.output {
        Some(p) => {
            std::fs::write(p, text).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => print!("{text}"),
    }
    Ok(())
}
