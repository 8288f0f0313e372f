//! `realitygap report`: the figures, tables and `index.html` of a study.

use crate::cmd_compare::MeasureArgs;
use anyhow::{Context, Result};
use realitygap_study::provenance::{measure_details, provenance_for_study};
use realitygap_study::{evaluate_measured, load_study, DataSource};
use std::path::{Path, PathBuf};

/// Arguments of `realitygap report`.
#[derive(clap::Args)]
pub struct Args {
    /// A study file (TOML), or the output folder of `replay` of tosses
    /// (then its stored runs are measured again, as `compare` does, and
    /// the other options are not used).
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
    /// How the gap is measured.
    #[command(flatten)]
    pub measure: MeasureArgs,
    /// The physics-free rows (their runs go to OUT/physics-free/).
    #[command(flatten)]
    pub physics_free: crate::cmd_compare::PhysicsFreeArg,
    /// Folder to write the report into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// The output folder of a cross-validated tune (`tune STUDY --folds K
    /// --out DIR`), or its crossval.json; repeat it for each engine. The
    /// verdict then opens with whether any tuned engine beats the
    /// physics-free model behind its fitted actuator stage on runs it did
    /// not see, and a section holds their table and figures.
    #[arg(long, value_name = "DIR")]
    pub crossval: Vec<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if realitygap_study::tosses::is_toss_replay_folder(&args.study) {
        if let Some(first) = args.crossval.first() {
            anyhow::bail!(
                "--crossval {}: a cross-validated tune of the arm belongs to the study's report; {} holds replayed tosses",
                first.display(),
                args.study.display()
            );
        }
        return toss_report(&args.study, &args.out);
    }
    let measure = args.measure.measure();
    let sections: Vec<_> = realitygap::compare::crossval_section(&args.crossval)?
        .into_iter()
        .collect();
    let (mut study, roots) = load_study(&args.study, &args.data, args.results.clone())?;
    let added = args
        .physics_free
        .sources(&args.study, &args.out.join("physics-free"))?;
    realitygap::compare::add_sources(&mut study, &added);
    let reports = evaluate_measured(&args.study, &study, &roots, &measure)?;
    let mut provenance = provenance_for_study(&study, &args.study, &roots, measure.mode);
    provenance.details.extend(args.data.provenance());
    provenance.details.extend(measure_details(&measure));
    let files = realitygap_report::write_report_with(&reports, &provenance, &args.out, &sections)
        .with_context(|| format!("writing the report into {}", args.out.display()))?;
    eprintln!(
        "report: {} figures (SVG and PNG), tables and {}",
        files.figures_svg.len(),
        files.index_html.display()
    );
    println!("{}", files.index_html.display());
    Ok(())
}

/// The report of a replay's folder of tosses: its toss table (also as
/// `tosses.md`, `.csv` and `.json` beside the page), the verdict, the
/// error against time from the first impact, and the 3D replay of three
/// tosses.
fn toss_report(dir: &Path, out: &Path) -> Result<()> {
    use realitygap_study::tosses::{self, ReplayedWith};
    let (rows, set) = tosses::compare_toss_replay(dir)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for (name, text) in [
        ("tosses.md", tosses::toss_markdown(&rows, &set)),
        ("tosses.csv", tosses::toss_csv(&rows, &set)),
        ("tosses.json", tosses::toss_json(&rows)),
    ] {
        let path = out.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    let index = tosses::write_toss_report(
        &rows,
        &set,
        dir,
        out,
        ReplayedWith::of_folder(dir),
        "tosses.md, tosses.csv and tosses.json beside this page",
    )?;
    eprintln!(
        "report: {} tosses, {} sources: the figure (SVG and PNG), the table and {}",
        set.tosses.len(),
        rows.len(),
        index.display()
    );
    println!("{}", index.display());
    Ok(())
}
