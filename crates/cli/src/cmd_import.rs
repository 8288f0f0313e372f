//! `realitygap import`: bring real (Qualisys motion capture) and recorded
//! simulator trajectories into a results directory, one run per file.

use anyhow::{bail, Result};
use clap::{Args, Subcommand, ValueEnum};
use realitygap_data::qualisys::{self, QualisysOptions};
use realitygap_data::recorded::{self, QuatOrder, RecordedOptions};
use realitygap_data::SourceKind;
use realitygap_study::import::{import_files, ImportTarget};
use serde_json::{json, Map, Value};
use std::path::PathBuf;

/// The file formats `import` reads.
#[derive(Subcommand)]
pub enum ImportCommand {
    /// Qualisys Track Manager 6DOF TSV exports (the real arm's motion
    /// capture), with or without their header. Defaults fit the reference
    /// study's files: 100 Hz, bodies RB2(Black), RB1(Orange), PCube.
    Qualisys(QualisysArgs),
    /// Simulator output recorded elsewhere: one row of 14 numbers per
    /// control step (wrist xyz, wrist quaternion, cube xyz, cube quaternion).
    Recorded(RecordedArgs),
}

/// Arguments of `import qualisys`.
#[derive(Args)]
pub struct QualisysArgs {
    /// The .tsv files; each is one run, named after its file stem.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// The scene the recordings are of.
    #[arg(long)]
    scene: String,
    /// Results directory to create or add to.
    #[arg(long)]
    out: PathBuf,
    /// Capture frequency in Hz, for files without a FREQUENCY header
    /// [default: 100].
    #[arg(long, value_name = "HZ")]
    frequency: Option<f64>,
    /// Rigid-body names in file order, comma-separated, for files without a
    /// BODY_NAMES header [default: RB2(Black),RB1(Orange),PCube].
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    bodies: Option<Vec<String>>,
    /// Role of a body, NAME=ROLE (wrist, cube, base or any name); repeat
    /// for several. Defaults: RB1(Orange)=wrist, RB2(Black)=base,
    /// PCube=cube. Bodies without a role keep their name.
    #[arg(long = "role", value_name = "NAME=ROLE", value_parser = parse_role)]
    roles: Vec<(String, String)>,
    /// Source name written into the manifest.
    #[arg(long, default_value = "real")]
    source: String,
}

/// Quaternion order of a recorded file.
#[derive(Clone, Copy, ValueEnum)]
enum QuatOrderArg {
    /// w x y z (MuJoCo).
    Wxyz,
    /// x y z w (PyBullet, V-Rep).
    Xyzw,
}

/// Arguments of `import recorded`.
#[derive(Args)]
pub struct RecordedArgs {
    /// The recorded files; each is one run, named after its file stem.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Name of the simulator that produced them (e.g. VRepODE).
    #[arg(long)]
    source: String,
    /// Order of the quaternion numbers in each row.
    #[arg(long, value_enum)]
    quat_order: QuatOrderArg,
    /// Results directory to create or add to.
    #[arg(long)]
    out: PathBuf,
    /// The scene the runs are of.
    #[arg(long)]
    scene: Option<String>,
    /// Time between rows in seconds.
    #[arg(long, default_value_t = 0.05, value_name = "SECONDS")]
    control_period: f64,
    /// Largest accepted deviation of a quaternion's norm from 1.
    #[arg(long, default_value_t = 1e-3)]
    norm_tolerance: f64,
}

/// Parses `NAME=ROLE` (split at the last `=`).
fn parse_role(s: &str) -> Result<(String, String), String> {
    match s.rsplit_once('=') {
        Some((name, role)) if !name.trim().is_empty() && !role.trim().is_empty() => {
            Ok((name.trim().to_string(), role.trim().to_string()))
        }
        _ => Err(format!(
            "expected NAME=ROLE (e.g. \"RB1(Orange)=wrist\"), found {s:?}"
        )),
    }
}

/// Runs `realitygap import ...`.
pub fn run(cmd: ImportCommand) -> Result<()> {
    match cmd {
        ImportCommand::Qualisys(args) => import_qualisys(args),
        ImportCommand::Recorded(args) => import_recorded(args),
    }
}

fn import_qualisys(args: QualisysArgs) -> Result<()> {
    let mut opts = QualisysOptions::collins2019();
    if let Some(f) = args.frequency {
        if !(f.is_finite() && f > 0.0) {
            bail!("--frequency must be a positive number of Hz, not {f}");
        }
        opts.frequency_hz = Some(f);
    }
    if let Some(bodies) = args.bodies {
        let bodies: Vec<String> = bodies.into_iter().map(|b| b.trim().to_string()).collect();
        if bodies.iter().any(String::is_empty) {
            bail!("--bodies has an empty name");
        }
        opts.body_names = Some(bodies);
    }
    // Later mappings win, so the user's roles override the defaults.
    opts.roles.extend(args.roles);
    let settings = json!({
        "importer": "qualisys",
        "frequency_hz": opts.frequency_hz,
        "body_names": opts.body_names,
        "roles": opts.roles.iter().map(|(n, r)| (n.clone(), Value::from(r.clone()))).collect::<Map<_, _>>(),
    });
    let target = ImportTarget {
        out: &args.out,
        source: &args.source,
        kind: SourceKind::Real,
        scene: Some(&args.scene),
    };
    import_files(
        &args.files,
        &target,
        settings,
        |f| qualisys::read(f, &opts),
        &|l| println!("{l}"),
        &|l| eprintln!("{l}"),
    )
}

fn import_recorded(args: RecordedArgs) -> Result<()> {
    let quat_order = match args.quat_order {
        QuatOrderArg::Wxyz => QuatOrder::Wxyz,
        QuatOrderArg::Xyzw => QuatOrder::Xyzw,
    };
    if !(args.control_period.is_finite() && args.control_period > 0.0) {
        bail!(
            "--control-period must be a positive number of seconds, not {}",
            args.control_period
        );
    }
    if !(args.norm_tolerance.is_finite() && args.norm_tolerance >= 0.0) {
        bail!(
            "--norm-tolerance must be a number >= 0, not {}",
            args.norm_tolerance
        );
    }
    let opts = RecordedOptions {
        quat_order,
        control_period_s: args.control_period,
        norm_tolerance: args.norm_tolerance,
    };
    let settings = json!({
        "importer": "recorded",
        "quat_order": quat_order.to_string(),
        "control_period_s": opts.control_period_s,
        "norm_tolerance": opts.norm_tolerance,
    });
    let target = ImportTarget {
        out: &args.out,
        source: &args.source,
        kind: SourceKind::Recorded,
        scene: args.scene.as_deref(),
    };
    import_files(
        &args.files,
        &target,
        settings,
        |f| recorded::read(f, &opts),
        &|l| println!("{l}"),
        &|l| eprintln!("{l}"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_parse() {
        assert_eq!(
            parse_role("RB1(Orange)=wrist"),
            Ok(("RB1(Orange)".into(), "wrist".into()))
        );
        assert_eq!(parse_role("a=b=c"), Ok(("a=b".into(), "c".into())));
        assert!(parse_role("wrist").is_err());
        assert!(parse_role("=wrist").is_err());
        assert!(parse_role("x= ").is_err());
    }
}
