//! `realitygap compare`: the accumulated-error table and per-scene measures.

use anyhow::{Context, Result};
use realitygap::compare::{evaluate, CompareRequest};
use realitygap_analysis::compare::AnalysisMode;
use realitygap_analysis::table::Format;
use realitygap_study::{parse_mode, DataSource, Measure, MODES};
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

/// `--physics-free [FILE|TUNE_DIR]` and `--no-physics-free` (shared by
/// `compare` and `report`).
#[derive(clap::Args, Debug, Clone)]
pub struct PhysicsFreeArg {
    /// The physics-free rows. By default every study whose scenes name
    /// scene files gets the model with no physics (perfect tracking of the
    /// commands, "physics-free (this tool)"), unless it already has a
    /// physics-free source. With this option that row is required (an
    /// error when it cannot be made), and, given a parameters file or the
    /// --out folder of a `realitygap tune`, the model behind the tune's
    /// fitted actuator stage is added ("physics-free (tuned)"). An engine
    /// that does not beat them predicts the real arm no better than
    /// kinematics.
    #[arg(long, value_name = "FILE|TUNE_DIR", num_args = 0..=1)]
    pub physics_free: Option<Option<PathBuf>>,
    /// Leave the physics-free rows out.
    #[arg(long, conflicts_with = "physics_free")]
    pub no_physics_free: bool,
}

impl PhysicsFreeArg {
    /// Which rows these options ask for.
    pub fn rows(&self) -> realitygap::compare::PhysicsFreeRows {
        use realitygap::compare::PhysicsFreeRows;
        match (&self.physics_free, self.no_physics_free) {
            (_, true) => PhysicsFreeRows::None,
            (Some(params), false) => PhysicsFreeRows::Asked(params.clone()),
            (None, false) => PhysicsFreeRows::Default,
        }
    }

    /// The rows' sources for the study at `study`, their runs in
    /// `runs_dir`.
    pub fn sources(
        &self,
        study: &std::path::Path,
        runs_dir: &std::path::Path,
    ) -> Result<realitygap::compare::AddedSources> {
        self.rows().sources(
            study,
            runs_dir,
            &realitygap_runner::Launcher::this_executable(),
            &realitygap::ui::Terminal,
        )
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
    /// Output format: md, csv, json or latex. Without it, standard output
    /// gets a summary (the table, the closest source per scene, each kind
    /// of run flag once) and `--output` the full Markdown.
    #[arg(long)]
    pub format: Option<String>,
    /// Without --format: print the full Markdown (every measure and flagged
    /// run), not the summary.
    #[arg(long, short = 'v')]
    pub verbose: bool,
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
    /// The physics-free rows.
    #[command(flatten)]
    pub physics_free: PhysicsFreeArg,
    /// Write the output to this file instead of standard output.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let format: Format = args
        .format
        .as_deref()
        .unwrap_or("md")
        .parse()
        .map_err(anyhow::Error::msg)?;
    // The physics-free runs live as long as the comparison.
    let (_runs, added_sources) = args.physics_free.rows().sources_in_temp(
        &args.study,
        &realitygap_runner::Launcher::this_executable(),
        &realitygap::ui::Terminal,
    )?;
    let request = CompareRequest {
        study: args.study,
        link: args.link,
        data: args.data,
        results: args.results,
        measure: args.measure.measure(),
        joint_space: args.joint_space,
        added_sources,
    };
    let comparison = evaluate(&request)?;
    let short = args.format.is_none() && !args.verbose && args.output.is_none();
    let text = match (&comparison, short) {
        (realitygap::compare::Comparison::Study { reports, joint }, true) => {
            let mut text = realitygap_analysis::table::summary(reports);
            if let Some(tables) = joint {
                text.push('\n');
                text.push_str(&realitygap_study::joint_space::markdown(tables));
            }
            text.push_str(
                "\nThe full tables (every measure and flagged run): --verbose, or --output FILE.\n",
            );
            text
        }
        _ => comparison.render(format, args.series)?,
    };
    if short {
        use realitygap::ui::Ui;
        realitygap::ui::Terminal.say(text.trim_end_matches('\n').to_string());
        return Ok(());
    }
    match args.output {
        Some(p) => {
            std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?
        }
        None => print!("{text}"),
    }
    Ok(())
}
