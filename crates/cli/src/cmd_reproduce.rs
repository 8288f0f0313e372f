//! `realitygap reproduce`: the whole study in one command.
//!
//! Stages, each timed:
//! 1. **simulate**: the three study scenes in every compiled engine,
//!    `--repeats` times each (20 by default), into `OUT/runs/` exactly as
//!    `realitygap run` does (parallel, resumable);
//! 2. **compare**: against the real arm's recordings, next to the study's
//!    recorded simulators (MuJoCo 1.5, PyBullet 2.1 and the V-Rep engines),
//!    from the recordings built in or `--data DIR`; with `--data none`, the
//!    engines against each other (the reference is the first engine, MuJoCo
//!    when compiled in);
//! 3. **report**: tables, figures and `OUT/report/index.html`.
//!
//! A rerun skips the finished simulations and redoes the (fast) rest.

use crate::cmd_engines;
use crate::cmd_report::provenance_for_study;
use crate::cmd_run;
use anyhow::{bail, Context, Result};
use realitygap::data_source::{assets_dir, DataSource};
use realitygap::study::{Roots, SourceFormat, SourceSpec, Study, StudyScene};
use realitygap_analysis::compare::{AnalysisMode, CompareOptions, CubeSpec};
use realitygap_analysis::table::{self, Format};
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::{Scene, TrackTarget};
use realitygap_core::trajectory::WRIST;
use realitygap_data::RunStore;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The study definition, built in.
const COLLINS2019: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../assets/studies/collins2019.toml"
));

/// Arguments of `realitygap reproduce`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The study's recordings: `builtin` (the default: shipped with the
    /// project, unpacked once into ~/.cache/realitygap or
    /// $REALITYGAP_CACHE_DIR), a folder with MotionCapture/ and
    /// Simulation/, or `none` to compare the engines with each other.
    #[arg(long, value_name = "builtin|none|DIR", default_value = "builtin")]
    pub data: DataSource,
    /// Output folder: runs/, report/, tables and timings.json.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Runs per scene and engine (the study made 20).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub repeats: u32,
    /// Engines (repeatable); default: every engine compiled in.
    #[arg(long = "engine", short = 'e', value_name = "NAME")]
    pub engines: Vec<String>,
    /// Scene files; default: the study's three scenes in assets/scenes.
    #[arg(long = "scene", value_name = "FILE")]
    pub scenes: Vec<PathBuf>,
    /// Simulations at a time (default: the number of cores).
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// `default` (flagged runs left out, estimated alignment) or `study`.
    #[arg(long, default_value = "default", value_parser = ["default", "study"])]
    pub mode: String,
    /// Give up on a simulation after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub timeout_s: Option<f64>,
    /// Physical parameters for every engine's runs (see `run --params`).
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let started = Instant::now();
    let mode = if args.mode == "study" {
        AnalysisMode::Study
    } else {
        AnalysisMode::Default
    };
    let data = args.data.resolve()?;
    if let Some(d) = &data {
        if !d.join("MotionCapture").is_dir() || !d.join("Simulation").is_dir() {
            bail!("--data {}: expected the study's recordings there (folders MotionCapture/ and Simulation/)", d.display());
        }
    }
    let scenes: Vec<PathBuf> = if args.scenes.is_empty() {
        let dir = assets_dir().join("scenes");
        [
            "scene1_single_joint",
            "scene2_two_joints",
            "scene3_cube_push",
        ]
        .iter()
        .map(|s| dir.join(format!("{s}.toml")))
        .collect()
    } else {
        args.scenes.clone()
    };
    let engines: Vec<String> = if args.engines.is_empty() {
        cmd_engines::compiled()
            .iter()
            .map(|e| e.name().to_string())
            .collect()
    } else {
        args.engines.clone()
    };
    if engines.is_empty() {
        bail!("no physics engine is compiled into this binary");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let runs_dir = args.out.join("runs");
    let mut timings: Vec<(String, f64)> = Vec::new();
    let mut problems: Vec<String> = Vec::new();

    // 1. Simulate.
    eprintln!(
        "[1/3] simulating {} scenes x {} engines ({}) x {} repeats -> {}",
        scenes.len(),
        engines.len(),
        engines.join(", "),
        args.repeats,
        runs_dir.display()
    );
    let t = Instant::now();
    let run_args = cmd_run::Args {
        scenes: scenes.clone(),
        engines: engines.clone(),
        repeats: args.repeats,
        out: runs_dir.clone(),
        robot: None,
        packages: vec![],
        jobs: args.jobs,
        seed: 0,
        perturb: vec![],
        set: vec![],
        timeout_s: args.timeout_s,
        params: args.params.clone(),
    };
    if let Err(e) = cmd_run::run(run_args) {
        // Failed runs are listed in the report; the comparison goes on with
        // the runs that finished.
        eprintln!("warning: {e:#}");
        problems.push(format!("{e:#}"));
    }
    timings.push(("simulate".into(), t.elapsed().as_secs_f64()));

    // 2. Compare.
    eprintln!("[2/3] comparing");
    let t = Instant::now();
    let loaded: Vec<Scene> = scenes
        .iter()
        .map(|p| Scene::from_file(p).map_err(anyhow::Error::from))
        .collect::<Result<_>>()?;
    let (study, study_path, roots) = match &data {
        Some(data) => {
            let path = assets_dir().join("studies/collins2019.toml");
            let mut study = Study::from_toml_str(COLLINS2019, &path)?;
            study
                .scenes
                .retain(|s| loaded.iter().any(|l| l.name == s.name));
            for s in &mut study.scenes {
                s.sources
                    .extend(engine_sources(&runs_dir, &s.name, &engines)?);
            }
            (
                study,
                path,
                Roots {
                    data: data.clone(),
                    results: runs_dir.clone(),
                },
            )
        }
        None => {
            let study = cross_engine_study(&loaded, &runs_dir, &engines)?;
            (
                study,
                args.out.join("study.toml"),
                Roots {
                    data: args.out.clone(),
                    results: runs_dir.clone(),
                },
            )
        }
    };
    if study.scenes.is_empty() {
        bail!(
            "none of the scenes is part of the study (expected scene names {:?})",
            [
                "scene1_single_joint",
                "scene2_two_joints",
                "scene3_cube_push"
            ]
        );
    }
    let opts = CompareOptions {
        mode,
        ..CompareOptions::default()
    };
    let scenes_in = study.load(&roots)?;
    let inputs: Vec<_> = scenes_in.iter().map(|s| s.input()).collect();
    let reports = realitygap_analysis::evaluate_study(&inputs, &opts)?;
    timings.push(("compare".into(), t.elapsed().as_secs_f64()));
    print!("{}", table::render(&reports, Format::Markdown));

    // 3. Report.
    eprintln!("[3/3] writing the report");
    let t = Instant::now();
    let mut provenance = provenance_for_study(&study, &study_path, &roots, mode);
    provenance.details.extend(args.data.provenance());
    provenance.details.push((
        "Command".into(),
        std::env::args().collect::<Vec<_>>().join(" "),
    ));
    provenance.details.push((
        "Repeats per scene and engine".into(),
        args.repeats.to_string(),
    ));
    let report_dir = args.out.join("report");
    let files = realitygap_report::write_report(&reports, &provenance, &report_dir)
        .with_context(|| format!("writing the report into {}", report_dir.display()))?;
    timings.push(("report".into(), t.elapsed().as_secs_f64()));

    let total = started.elapsed().as_secs_f64();
    timings.push(("total".into(), total));
    let timing_json: serde_json::Map<String, serde_json::Value> = timings
        .iter()
        .map(|(k, v)| (format!("{k}_s"), serde_json::json!(v)))
        .collect();
    std::fs::write(
        args.out.join("timings.json"),
        serde_json::to_string_pretty(&timing_json)? + "\n",
    )
    .with_context(|| format!("cannot write {}", args.out.join("timings.json").display()))?;
    eprintln!(
        "stage timings: {}",
        timings
            .iter()
            .map(|(k, v)| format!("{k} {v:.1} s"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    eprintln!("report: {}", files.index_html.display());
    if !problems.is_empty() {
        bail!(
            "the study finished, but not every simulation did: {}",
            problems.join("; ")
        );
    }
    Ok(())
}

/// One `store` source per engine results directory of a scene, named after
/// the engine and version in its manifest, e.g. `MuJoCo 3.17.0 (this tool)`.
fn engine_sources(runs_dir: &Path, scene: &str, engines: &[String]) -> Result<Vec<SourceSpec>> {
    let mut out = Vec::new();
    for engine in engines {
        let dir = runs_dir.join(scene).join(engine);
        if !dir.join("manifest.json").is_file() {
            continue;
        }
        let store = RunStore::open(&dir)?;
        let m = store.manifest();
        // "MuJoCo 3.17.0 (mujoco-rs 7.0.0)" -> "MuJoCo 3.17.0 (this tool)".
        let version = m
            .engine
            .as_ref()
            .map(|e| e.version.clone())
            .unwrap_or_default();
        let label = version.split(" (").next().unwrap_or_default().trim();
        out.push(SourceSpec {
            name: format!(
                "{} (this tool)",
                if label.is_empty() {
                    engine.as_str()
                } else {
                    label
                }
            ),
            about: Some(format!("simulated by this tool: {version}")),
            format: SourceFormat::Store,
            files: None,
            dir: Some(format!("{scene}/{engine}")),
            quat_order: None,
            alignment: None,
            frequency_hz: None,
            bodies: None,
            roles: None,
        });
    }
    Ok(out)
}

/// Without recordings: a study comparing the engines with the first one.
/// Each scene's goal is the wrist at the final targets, by forward
/// kinematics of the scene's robot.
fn cross_engine_study(scenes: &[Scene], runs_dir: &Path, engines: &[String]) -> Result<Study> {
    let mut out = Vec::new();
    for scene in scenes {
        let mut sources = engine_sources(runs_dir, &scene.name, engines)?;
        if sources.is_empty() {
            continue;
        }
        let reference = sources.remove(0);
        let robot = RobotModel::from_urdf_file(&scene.robot.urdf, &PackageResolver::from_env())
            .with_context(|| format!("scene {}", scene.name))?;
        let goal = final_wrist(scene, &robot);
        let cube = scene.objects.first().map(|o| CubeSpec {
            nominal_start_m: Some(o.pose.position_m.to_array()),
            contact_threshold_m: 0.005,
        });
        let mut phases: Vec<f64> = scene.schedule.iter().map(|e| e.t_s).collect();
        if phases.first() != Some(&0.0) {
            phases.insert(0, 0.0);
        }
        out.push(StudyScene {
            name: scene.name.clone(),
            steps: scene.sample_count(),
            goal_m: goal,
            goal_tolerance_m: 0.01,
            phases_s: phases,
            cube: if scene
                .tracked
                .iter()
                .any(|t| matches!(t.target, TrackTarget::Object(_)))
            {
                cube
            } else {
                None
            },
            scene: None,
            vars: BTreeMap::new(),
            reference,
            sources,
        });
    }
    Ok(Study {
        name: "cross-engine".into(),
        title: Some("The engines compared with each other (no real recordings given)".into()),
        control_period_s: scenes.first().map_or(0.05, |s| s.controller.period_s),
        sources: vec![],
        scenes: out,
        runs: None,
        holdout: None,
        folder: PathBuf::new(),
    })
}

/// The wrist's world position at the scene's final targets.
fn final_wrist(scene: &Scene, robot: &RobotModel) -> Option<[f64; 3]> {
    let link = scene
        .tracked
        .iter()
        .find(|t| t.role == WRIST)
        .and_then(|t| match &t.target {
            TrackTarget::Link(l) => robot.link_by_name(l),
            TrackTarget::Object(_) => None,
        })?;
    let last_tick = scene.sample_count().saturating_sub(1);
    let targets = scene.targets_deg_at_tick(last_tick);
    let mut q = vec![0.0; robot.joints.len()];
    for (name, deg) in scene.controlled_joints().iter().zip(targets) {
        q[robot.joint_by_name(name)?] = deg.to_radians();
    }
    for (name, rad) in &scene.robot.held_joints_rad {
        if let Some(j) = robot.joint_by_name(name) {
            q[j] = *rad;
        }
    }
    robot
        .link_pose(&scene.robot.base, &q, link)
        .map(|p| p.position_m.to_array())
}
