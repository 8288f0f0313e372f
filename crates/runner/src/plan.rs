//! Batch planning and resume: one results directory per (scene, engine),
//! opened (or created) and checked before anything runs, with the repeats
//! still to run. A rerun of the same batch finds its finished runs and
//! keeps them.

use crate::prepare::{engine_names, parse_perturbation, prepare, resolver, robot_override};
use crate::prepare::{Prepared, RunSource};
use crate::protocol::Job;
use crate::Registry;
use anyhow::{bail, Context, Result};
use realitygap_core::controller::{repeat_seed, Perturbation};
use realitygap_core::engine::SettingValue;
use realitygap_core::stitch::{phase_ticks, split_entry, StitchPlan};
use realitygap_data::runstore::{EngineInfo, RunStore, SourceKind};
use std::path::PathBuf;

/// A batch as the command line gives it (`realitygap run`).
#[derive(Debug, Clone, PartialEq)]
pub struct BatchSpec {
    /// Scene files (TOML).
    pub scenes: Vec<PathBuf>,
    /// Engines to run; empty: every engine of the registry.
    pub engines: Vec<String>,
    /// Runs per scene and engine.
    pub repeats: u32,
    /// Results directory.
    pub out: PathBuf,
    /// Robot instead of the scene's: `mico2`, `official` or a URDF file.
    pub robot: Option<String>,
    /// `NAME=DIR` ROS package locations.
    pub packages: Vec<String>,
    /// Runs at a time; `None`: the number of cores.
    pub jobs: Option<usize>,
    /// Seed of the per-repeat perturbations.
    pub seed: u64,
    /// Perturbation specs, `KEY=VALUE,...`.
    pub perturb: Vec<String>,
    /// Engine settings, `[ENGINE.]KEY=VALUE`.
    pub set: Vec<String>,
    /// Give up on a run after this many seconds.
    pub timeout_s: Option<f64>,
    /// Physical parameters file.
    pub params: Option<PathBuf>,
    /// A stitched run instead of single engines: `E1,E2,...`, one engine
    /// per schedule phase (see `realitygap_core::stitch`); `engines` must
    /// then be empty.
    pub stitch: Option<String>,
    /// Run settings the engine knows to be unstable for the model instead
    /// of refusing them (`--allow-unstable`); recorded in the manifest.
    pub allow_unstable: bool,
}

/// Runs of one results directory that ended each way in this batch.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Done {
    /// Completed (simulated or copied).
    pub ok: usize,
    /// Diverged.
    pub diverged: usize,
    /// Completed with the signature of a numerical instability.
    pub unstable: usize,
    /// Failed.
    pub failed: usize,
}

impl Done {
    /// Every run of the batch in this directory.
    pub fn total(&self) -> usize {
        self.ok + self.diverged + self.unstable + self.failed
    }
}

/// One (scene, engine) results directory of the batch.
pub struct Group {
    /// The scene file.
    pub scene_file: PathBuf,
    /// The scene's name.
    pub scene_name: String,
    /// The engine's name.
    pub engine: String,
    /// The source's name: the engine's, or `<engine>-<robot label>`.
    pub source: String,
    /// The results directory.
    pub store: RunStore,
    /// Repeats still to run, in order.
    pub pending: Vec<u32>,
    /// Why the engine could not load the model, if it could not.
    pub load_error: Option<String>,
    /// How this batch's runs ended.
    pub done: Done,
    /// The engine of every phase, for a stitched source.
    pub stitch: Option<Vec<String>>,
}

/// A planned batch: its groups and what its jobs are made of.
pub struct Plan {
    /// The batch as given.
    pub spec: BatchSpec,
    /// The results directories, scene by scene, engine by engine.
    pub groups: Vec<Group>,
    /// Runs at a time.
    pub jobs: usize,
    /// The parameters file, absolute.
    pub params_file: Option<PathBuf>,
    /// The repeats' perturbation (none: a deterministic batch).
    pub perturbation: Perturbation,
    /// The repeats' randomised parameters (`--perturb randomize.toml`).
    pub randomization: Option<realitygap_core::randomize::Randomization>,
    /// Where the simulations run: this machine (default) or a Slurm job
    /// array.
    pub executor: crate::slurm::Executor,
}

/// The names and configuration of a stitched group.
struct Stitched {
    /// Display name, `stitched ode>ode>mujoco`.
    name: String,
    /// Directory name, `stitched-ode-ode-mujoco`.
    dir: String,
    /// The manifest's engine: `stitched`, the versions joined by `>`.
    engine: EngineInfo,
    /// The manifest's `config.stitch`.
    config: serde_json::Value,
    /// The engine of every phase.
    engines: Vec<String>,
}

/// A plan entry with its parameters file (if any) made absolute, as the
/// child process needs it.
fn absolute_entry(entry: &str) -> Result<String> {
    Ok(match split_entry(entry) {
        (engine, Some(params)) => {
            let path = std::path::absolute(params)
                .with_context(|| format!("--stitch: the parameters file {params}"))?;
            format!("{engine}@{}", path.display())
        }
        (engine, None) => engine.to_string(),
    })
}

/// The id of a repeat's run: `run000`, `run001`, ...
pub fn run_id(repeat: u32) -> String {
    format!("run{repeat:03}")
}

fn setting_json(v: &SettingValue) -> serde_json::Value {
    match v {
        SettingValue::Bool(b) => serde_json::json!(b),
        SettingValue::Integer(i) => serde_json::json!(i),
        SettingValue::Float(f) => serde_json::json!(f),
        SettingValue::Text(s) => serde_json::json!(s),
    }
}

/// The engines to run: the requested ones (repeats next to each other
/// dropped), else every engine of the registry.
pub fn engines_to_run(registry: Registry, requested: &[String]) -> Result<Vec<String>> {
    if requested.is_empty() {
        let all = engine_names(registry);
        if all.is_empty() {
            bail!("no physics engine is compiled into this binary (build it with `--features mujoco`)");
        }
        return Ok(all);
    }
    let mut v = requested.to_vec();
    v.dedup();
    Ok(v)
}

/// A randomisation in a results directory's configuration.
fn randomization_json(r: &realitygap_core::randomize::Randomization) -> serde_json::Value {
    serde_json::json!({
        "file": r.source.display().to_string(),
        "ranges": r.ranges.iter().map(|x| serde_json::json!({
            "key": x.key, "low": x.low, "high": x.high,
            "scale": if x.log { "log" } else { "linear" },
        })).collect::<Vec<_>>(),
    })
}

/// What a results directory's runs were made with; a rerun must match it.
fn config_json(
    p: &Prepared,
    spec: &BatchSpec,
    robot_label: Option<&str>,
    params_file: Option<&PathBuf>,
    perturbation: &Perturbation,
) -> Result<serde_json::Value> {
    let mut config = serde_json::json!({
        "scene_file": p.scene.source.display().to_string(),
        "robot": {
            "urdf": p.scene.robot.urdf.as_ref().map(|u| u.display().to_string()),
            "mjcf": p.scene.robot.mjcf.as_ref().map(|m| m.display().to_string()),
            "label": robot_label.unwrap_or("scene"),
            "name": p.robot.name,
        },
        "engine_settings": p.settings.iter().map(|(k, v)| (k.clone(), setting_json(v))).collect::<serde_json::Map<_, _>>(),
        "timestep_s": p.timestep_s,
        "steps_per_control_period": p.steps_per_period,
        "controller": {
            "gain_per_s": p.scene.controller.gain_per_s,
            "max_speed_deg_s": p.scene.controller.max_speed_deg_s,
            "period_s": p.scene.controller.period_s,
        },
        "duration_s": p.scene.duration_s,
        "samples_per_run": p.scene.sample_count(),
        "seed": spec.seed,
        "params_file": params_file.map(|p| p.display().to_string()),
        "params": serde_json::to_value(&p.params)?,
        "perturbation": perturbation.describe(),
        "deterministic": perturbation.is_none(),
    });
    if spec.allow_unstable {
        // Only when set, so that directories written before the option
        // existed keep their configuration.
        config["allow_unstable"] = serde_json::json!(true);
    }
    Ok(config)
}

/// Opens (or creates) a group's results directory, checks that its runs
/// were made with `config`, and records the engine, config and repeats.
fn open_store(
    dir: &std::path::Path,
    source: &str,
    p: &Prepared,
    config: serde_json::Value,
    repeats: u32,
) -> Result<RunStore> {
    let mut store =
        RunStore::create_or_open(dir, source, SourceKind::Simulated, Some(&p.scene.name))?;
    let existing = store.manifest().settings.get("config").cloned();
    if let Some(old) = existing.filter(|_| !store.runs().is_empty()) {
        if old != config {
            bail!(
                "{} holds runs made with other settings (scene, robot, engine settings, seed or perturbation differ); use another --out directory or remove it",
                dir.display()
            );
        }
    }
    store.set_engine(EngineInfo {
        name: p.engine.name().to_string(),
        version: p.engine.version(),
    })?;
    let mut settings = store.manifest().settings.clone();
    if !settings.is_object() {
        settings = serde_json::json!({});
    }
    settings["config"] = config;
    settings["repeats"] =
        serde_json::json!(repeats.max(settings["repeats"].as_u64().unwrap_or(0) as u32));
    store.set_settings(settings)?;
    Ok(store)
}

impl Plan {
    /// Checks everything and opens the results directories before
    /// running: every scene with every engine is prepared, so that a
    /// mistake is one error before any simulation.
    pub fn new(registry: Registry, spec: BatchSpec) -> Result<Plan> {
        let stitch = match &spec.stitch {
            Some(text) => {
                if !spec.engines.is_empty() {
                    bail!("--stitch and --engine cannot be given together (the plan names the engines)");
                }
                let plan = StitchPlan::parse(text, &engine_names(registry)).context("--stitch")?;
                Some(StitchPlan {
                    engines: plan
                        .engines
                        .iter()
                        .map(|e| absolute_entry(e))
                        .collect::<Result<_>>()?,
                })
            }
            None => None,
        };
        let engines = match &stitch {
            Some(plan) => vec![plan.engines[0].clone()],
            None => engines_to_run(registry, &spec.engines)?,
        };
        let perturbation = parse_perturbation(&spec.perturb)?;
        let randomization = crate::prepare::parse_randomization(&spec.perturb)?;
        // The children read the randomisation file wherever they run.
        let mut spec = spec;
        for s in spec.perturb.iter_mut() {
            if crate::prepare::is_randomization_file(s) {
                *s = std::path::absolute(s.as_str())
                    .with_context(|| format!("--perturb {s}"))?
                    .display()
                    .to_string();
            }
        }
        let params_file = match &spec.params {
            Some(p) => {
                Some(std::path::absolute(p).with_context(|| format!("--params {}", p.display()))?)
            }
            None => None,
        };
        let resolver = resolver(&spec.packages)?;
        // Resolve the robot once, for its label and early errors.
        let robot_label =
            robot_override(spec.robot.as_deref(), &resolver)?.map(|(_, _, label)| label);
        let jobs = spec
            .jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1);
        let mut plan = Plan {
            spec,
            groups: Vec::new(),
            jobs,
            params_file,
            perturbation,
            randomization,
            executor: crate::slurm::Executor::Local,
        };
        for scene_file in plan.spec.scenes.clone() {
            for engine in &engines {
                let group = plan.group(
                    registry,
                    &scene_file,
                    engine,
                    robot_label.as_deref(),
                    stitch.as_ref(),
                )?;
                plan.groups.push(group);
            }
        }
        Ok(plan)
    }

    /// Prepares one scene in `engine` (or a stitch plan's entry
    /// `ENGINE@PARAMS`, whose parameters file replaces `--params`).
    fn prepare(
        &self,
        registry: Registry,
        scene_file: &std::path::Path,
        engine: &str,
    ) -> Result<Prepared> {
        let spec = &self.spec;
        let (engine, params) = split_entry(engine);
        prepare(
            registry,
            &RunSource {
                scene_file,
                engine,
                robot: spec.robot.as_deref(),
                packages: &spec.packages,
                set: &spec.set,
                params_file: params
                    .map(std::path::Path::new)
                    .or(self.params_file.as_deref()),
            },
        )
    }

    /// Prepares one scene with one engine (or every engine of a stitch
    /// plan) and opens its results directory.
    fn group(
        &self,
        registry: Registry,
        scene_file: &std::path::Path,
        engine: &str,
        robot_label: Option<&str>,
        stitch: Option<&StitchPlan>,
    ) -> Result<Group> {
        let spec = &self.spec;
        let p = self.prepare(registry, scene_file, engine)?;
        let stitched = match stitch {
            Some(plan) => Some(self.stitched(registry, scene_file, &p, plan)?),
            None => None,
        };
        let base = match &stitched {
            Some(s) => s.dir.clone(),
            None => engine.to_string(),
        };
        let source = match robot_label {
            Some(label) => format!("{base}-{label}"),
            None => base,
        };
        if self
            .groups
            .iter()
            .any(|g| g.scene_name == p.scene.name && g.source == source)
        {
            bail!(
                "scene \"{}\" is given twice (scene names must be unique in a batch)",
                p.scene.name
            );
        }
        let dir = spec.out.join(&p.scene.name).join(&source);
        let mut config = config_json(
            &p,
            spec,
            robot_label,
            self.params_file.as_ref(),
            &self.perturbation,
        )?;
        if let Some(s) = &stitched {
            config["stitch"] = s.config.clone();
        }
        if let Some(r) = &self.randomization {
            config["randomize"] = randomization_json(r);
            config["deterministic"] = serde_json::json!(false);
        }
        let display = stitched.as_ref().map(|s| s.name.clone());
        let store = open_store(
            &dir,
            display.as_deref().unwrap_or(&source),
            &p,
            config,
            spec.repeats,
        )?;
        let mut store = store;
        if let Some(s) = &stitched {
            store.set_engine(s.engine.clone())?;
        }
        let pending: Vec<u32> = (0..spec.repeats)
            .filter(|&r| !store.has_finished_run(&run_id(r)))
            .collect();
        Ok(Group {
            scene_file: scene_file.to_path_buf(),
            scene_name: p.scene.name.clone(),
            engine: engine.to_string(),
            source,
            store,
            pending,
            load_error: None,
            done: Done::default(),
            stitch: stitched.map(|s| s.engines),
        })
    }

    /// A stitched group's names and configuration: every engine of the
    /// plan prepared (so that a mistake is an error before any run), the
    /// plan expanded to the scene's phases.
    fn stitched(
        &self,
        registry: Registry,
        scene_file: &std::path::Path,
        first: &Prepared,
        plan: &StitchPlan,
    ) -> Result<Stitched> {
        let phases = phase_ticks(&first.scene);
        let context = || format!("--stitch for scene {}", scene_file.display());
        let engines = plan.per_phase(phases.len()).with_context(context)?;
        let mut versions = Vec::new();
        let mut configs = serde_json::Map::new();
        for engine in &plan.engines {
            if configs.contains_key(engine) {
                continue;
            }
            let p = self.prepare(registry, scene_file, engine)?;
            versions.push(p.engine.version());
            let c = config_json(&p, &self.spec, None, None, &self.perturbation)?;
            configs.insert(
                engine.clone(),
                serde_json::json!({
                    "version": p.engine.version(),
                    "params_file": split_entry(engine).1,
                    "params": c["params"],
                    "engine_settings": c["engine_settings"],
                    "timestep_s": c["timestep_s"],
                    "steps_per_control_period": c["steps_per_control_period"],
                }),
            );
        }
        let period = first.scene.controller.period_s;
        Ok(Stitched {
            name: plan.display_name(phases.len()).with_context(context)?,
            dir: plan.dir_name(phases.len()).with_context(context)?,
            engine: EngineInfo {
                name: realitygap_core::stitch::STITCHED.to_string(),
                version: versions.join(" > "),
            },
            config: serde_json::json!({
                "plan": plan.engines,
                "engines_per_phase": engines,
                "phases_start_s": phases.iter().map(|(s, _)| *s as f64 * period).collect::<Vec<_>>(),
                "handover_ticks": phases.iter().skip(1).map(|(s, _)| *s).collect::<Vec<_>>(),
                "engines": configs,
            }),
            engines,
        })
    }

    /// The job of repeat `repeat` of group `g`.
    pub fn job(&self, g: &Group, repeat: u32, check_only: bool) -> Job {
        let spec = &self.spec;
        Job {
            scene_file: g.scene_file.clone(),
            engine: g.engine.clone(),
            robot: spec.robot.clone(),
            packages: spec.packages.clone(),
            set: spec.set.clone(),
            perturb: spec.perturb.clone(),
            seed: repeat_seed(spec.seed, repeat as u64),
            params: self.params_file.clone(),
            params_text: None,
            check_only,
            stitch: g.stitch.clone(),
            allow_unstable: spec.allow_unstable,
            replay: None,
        }
    }

    /// Whether every repeat is the same simulation (no perturbation).
    pub fn deterministic(&self) -> bool {
        self.perturbation.is_none() && self.randomization.is_none()
    }

    /// Runs kept from an earlier batch.
    pub fn kept(&self, g: &Group) -> usize {
        self.spec.repeats as usize - g.pending.len()
    }

    /// Runs kept from an earlier batch, in every group.
    pub fn skipped(&self) -> usize {
        self.groups.iter().map(|g| self.kept(g)).sum()
    }

    /// Runs to do now: the pending runs of groups whose model loads.
    pub fn total(&self) -> usize {
        self.groups
            .iter()
            .filter(|g| g.load_error.is_none())
            .map(|g| g.pending.len())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::engine::Engine;

    #[test]
    fn run_ids_sort_as_numbers_up_to_a_thousand() {
        assert_eq!(run_id(0), "run000");
        assert_eq!(run_id(42), "run042");
        assert_eq!(run_id(1234), "run1234");
    }

    #[test]
    fn engines_default_to_the_registry_and_lose_adjacent_repeats() {
        fn none() -> Vec<Box<dyn Engine>> {
            Vec::new()
        }
        assert!(engines_to_run(none, &[]).is_err());
        let asked = ["a".to_string(), "a".into(), "b".into()];
        assert_eq!(engines_to_run(none, &asked).unwrap(), ["a", "b"]);
        assert_eq!(
            Done {
                ok: 1,
                diverged: 2,
                unstable: 4,
                failed: 3
            }
            .total(),
            10
        );
    }
}
