//! From a job's strings to a checked, loadable run: the scene, the robot
//! (`--robot`), the engine and its settings (`[engine.NAME]`, `--params`,
//! `--set`), the perturbation.

use crate::Registry;
use anyhow::{anyhow, bail, Context, Result};
use realitygap_core::controller::Perturbation;
use realitygap_core::engine::{Engine, EngineSettings, SettingValue, TIMESTEP_KEY};
use realitygap_core::params::PhysicalParams;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::{Scene, SceneError};
use std::path::{Path, PathBuf};

/// The project's Mico2 description, built in for `--robot mico2`.
const MICO2_URDF: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../assets/robots/mico2/mico2.urdf"
));

/// A scene, robot, engine and settings, checked and ready to load.
pub struct Prepared {
    /// The scene, with `--params` applied.
    pub scene: Scene,
    /// The robot, with `--params` applied.
    pub robot: RobotModel,
    /// The engine.
    pub engine: Box<dyn Engine>,
    /// The engine settings: the scene's, then `--params`, then `--set`.
    pub settings: EngineSettings,
    /// The physical parameters (none without `--params`).
    pub params: PhysicalParams,
    /// The engine's timestep, seconds.
    pub timestep_s: f64,
    /// Engine steps per control period.
    pub steps_per_period: u64,
}

/// The compiled-in engine called `name`.
pub fn find_engine(registry: Registry, name: &str) -> Result<Box<dyn Engine>> {
    let engines = registry();
    let names: Vec<&str> = engines.iter().map(|e| e.name()).collect();
    if names.is_empty() {
        bail!("no physics engine is compiled into this binary (build it with a feature such as `--features mujoco`)");
    }
    let list = names.join(", ");
    match engines.into_iter().find(|e| e.name() == name) {
        Some(e) => {
            // An engine out of process starts here (its `hello`), once per
            // process: the runs this command hands to `__run-one` children
            // then fork from its zygote instead of each importing the
            // engine (realitygap_engine_remote::zygote). A linked engine
            // just names its version.
            let _ = e.version();
            Ok(e)
        }
        None => match realitygap_engine_remote::registry::adapter(name) {
            Some(_) => bail!(
                "engine \"{name}\" is not installed: `{}` makes its environment (available: {list})",
                realitygap_engine_remote::registry::install_line(name)
            ),
            None => bail!("unknown engine \"{name}\" (compiled in: {list})"),
        },
    }
}

/// Every engine name realitygap knows, whether or not this build or this
/// machine has it: the linked engines (each behind a cargo feature), the
/// physics-free model and the built-in adapters (installed or not).
fn engine_names_anywhere() -> impl Iterator<Item = &'static str> {
    use realitygap_core::engine::{LINKED_ENGINES, PHYSICS_FREE_ENGINE};
    LINKED_ENGINES
        .iter()
        .copied()
        .chain([PHYSICS_FREE_ENGINE])
        .chain(
            realitygap_engine_remote::registry::ADAPTERS
                .iter()
                .map(|a| a.name),
        )
}

/// [`read_params`] with its `[engine.NAME]` tables checked for typos
/// against `registry` ([`check_engine_tables`]), for the commands that
/// read a parameters file themselves (`replay`, `tune --recordings`).
pub fn read_params_checked(registry: Registry, path: Option<&Path>) -> Result<PhysicalParams> {
    let params = read_params(path)?;
    if let Some(file) = path {
        check_engine_tables(&engine_names(registry), params.engine_settings.keys(), file)?;
    }
    Ok(params)
}

/// Checks the `[engine.NAME]` tables of `file` (a scene or a parameters
/// file; `names` its tables' names) for typos: a name that is no engine
/// here (`known`, [`engine_names`]) nor anywhere realitygap knows of, but
/// one or two letters from one (`[engine.mujocoo]`, `[engine.odee]`), is
/// an error at its line; its settings would otherwise be ignored in
/// silence. Any other name passes: a scene shared between machines may
/// carry the settings of an engine this build or machine lacks (a
/// feature left out, an adapter or a user's engine not installed here).
pub fn check_engine_tables<'a>(
    known: &[String],
    names: impl IntoIterator<Item = &'a String>,
    file: &Path,
) -> Result<()> {
    for name in names {
        if known.iter().any(|k| k == name) || engine_names_anywhere().any(|k| k == name) {
            continue;
        }
        let Some(meant) = engine_names_anywhere()
            .map(String::from)
            .chain(known.iter().cloned())
            .filter(|k| strsim::levenshtein(k, name) <= 2)
            .min_by_key(|k| strsim::levenshtein(k, name))
        else {
            continue;
        };
        let line = std::fs::read_to_string(file)
            .ok()
            .and_then(|text| table_line(&text, name))
            .map_or(String::new(), |l| format!(":{l}"));
        bail!(
            "{}{line}: [engine.{name}]: no engine is called \"{name}\"; did you mean [engine.{meant}]? (engines here: {})",
            file.display(),
            known.join(", ")
        );
    }
    Ok(())
}

/// The line (from 1) where `text`, TOML, opens the table of engine `name`:
/// `[engine.NAME]`, `[engine."NAME"]` or a dotted `engine.NAME.key = ...`.
fn table_line(text: &str, name: &str) -> Option<usize> {
    let heads = [
        format!("[engine.{name}]"),
        format!("[engine.\"{name}\"]"),
        format!("engine.{name}."),
    ];
    text.lines()
        .position(|l| {
            let l: String = l.chars().filter(|c| !c.is_whitespace()).collect();
            heads.iter().any(|h| l.starts_with(h.as_str()))
        })
        .map(|i| i + 1)
}

/// The names of the engines in `registry`, in its order.
pub fn engine_names(registry: Registry) -> Vec<String> {
    registry().iter().map(|e| e.name().to_string()).collect()
}

/// A package resolver: `ROS_PACKAGE_PATH`, then the `NAME=DIR` arguments.
pub fn resolver(packages: &[String]) -> Result<PackageResolver> {
    let mut r = PackageResolver::from_env();
    for p in packages {
        r.insert_arg(p)?;
    }
    Ok(r)
}

/// A file stem made safe for a directory name.
fn label_of(path: &Path) -> String {
    let label = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "robot".into());
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "_-.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The robot a `--robot` value names, with its path and a short label for
/// directory names; `None` keeps the scene's robot.
pub fn robot_override(
    choice: Option<&str>,
    resolver: &PackageResolver,
) -> Result<Option<(RobotModel, PathBuf, String)>> {
    let Some(choice) = choice else {
        return Ok(None);
    };
    match choice {
        "mico2" => {
            let source = PathBuf::from("mico2.urdf (built in)");
            let robot = RobotModel::from_urdf_str(MICO2_URDF, &source, resolver)
                .map_err(|e| anyhow!("the built-in Mico2 description: {e}"))?;
            Ok(Some((robot, source, "mico2".to_string())))
        }
        "official" => {
            let dir = resolver.find("kinova_description").map_err(|searched| {
                anyhow!(
                    "--robot official needs the kinova_description package (looked in: {}); pass --package kinova_description=DIR, e.g. a copy of the study data's kinova_description, or set ROS_PACKAGE_PATH",
                    if searched.is_empty() { "nowhere".to_string() } else { searched.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ") }
                )
            })?;
            let path = dir.join("urdf/m1n6s300.urdf");
            let robot = RobotModel::from_urdf_file(&path, resolver)?;
            Ok(Some((robot, path, "official".to_string())))
        }
        path => {
            let path = PathBuf::from(path);
            let robot = RobotModel::from_urdf_file(&path, resolver)?;
            let label = label_of(&path);
            Ok(Some((robot, path, label)))
        }
    }
}

/// The `--set` values that apply to `engine`, checked for form and for
/// engine prefixes that name no engine of `known`.
pub fn overrides_for(set: &[String], engine: &str, known: &[String]) -> Result<EngineSettings> {
    let mut out = EngineSettings::new();
    for s in set {
        let (key, value) = s
            .split_once('=')
            .ok_or_else(|| anyhow!("--set \"{s}\": expected KEY=VALUE or ENGINE.KEY=VALUE"))?;
        let key = key.trim();
        let (target, key) = match key.split_once('.') {
            Some((e, k)) => {
                if !known.iter().any(|n| n == e) {
                    bail!(
                        "--set \"{s}\": \"{e}\" is not a compiled-in engine (compiled in: {})",
                        known.join(", ")
                    );
                }
                (Some(e), k)
            }
            None => (None, key),
        };
        if key.is_empty() {
            bail!("--set \"{s}\": the key is empty");
        }
        if target.is_none_or(|e| e == engine) {
            out.insert(key.to_string(), SettingValue::parse(value));
        }
    }
    Ok(out)
}

/// True when a `--perturb` value names a randomisation file (it has no
/// `=`), not `KEY=VALUE,...` settings.
pub fn is_randomization_file(spec: &str) -> bool {
    !spec.contains('=')
}

/// The perturbation of `KEY=VALUE,...` specs (none when empty); specs
/// that name randomisation files are [`parse_randomization`]'s.
pub fn parse_perturbation(specs: &[String]) -> Result<Perturbation> {
    let mut p = Perturbation::default();
    for s in specs.iter().filter(|s| !is_randomization_file(s)) {
        p.parse_into(s)?;
    }
    Ok(p)
}

/// The randomisation file among `--perturb` values (`randomize.toml`, as
/// `tune` writes it), if any; two are an error.
pub fn parse_randomization(
    specs: &[String],
) -> Result<Option<realitygap_core::randomize::Randomization>> {
    let files: Vec<&String> = specs.iter().filter(|s| is_randomization_file(s)).collect();
    match files.as_slice() {
        [] => Ok(None),
        [f] => Ok(Some(realitygap_core::randomize::Randomization::from_file(
            Path::new(f.as_str()),
        )?)),
        _ => anyhow::bail!(
            "--perturb: give one randomisation file, not {} ({})",
            files.len(),
            files
                .iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Reads a parameters file, or none.
pub fn read_params(path: Option<&Path>) -> Result<PhysicalParams> {
    match path {
        Some(p) => Ok(PhysicalParams::from_file(p)?),
        None => Ok(PhysicalParams::none()),
    }
}

/// What a run is made of, as the command line gives it.
#[derive(Debug, Clone, Copy)]
pub struct RunSource<'a> {
    /// The scene file.
    pub scene_file: &'a Path,
    /// The engine's name.
    pub engine: &'a str,
    /// The `--robot` value.
    pub robot: Option<&'a str>,
    /// `NAME=DIR` package locations.
    pub packages: &'a [String],
    /// `[ENGINE.]KEY=VALUE` settings.
    pub set: &'a [String],
    /// The parameters file.
    pub params_file: Option<&'a Path>,
}

/// The scene of `src` with its robot (the scene's, or `--robot`), checked.
fn scene_and_robot(src: &RunSource<'_>) -> Result<(Scene, RobotModel)> {
    let mut scene = Scene::from_file(src.scene_file)?;
    let resolver = resolver(src.packages)?;
    let robot = match robot_override(src.robot, &resolver)? {
        Some(_) if !scene.robot.is_some() => bail!(
            "--robot: scene {} has no [robot] (free objects alone): there is no robot to replace",
            src.scene_file.display()
        ),
        Some((robot, path, _)) => {
            scene.set_robot_urdf(path);
            robot
        }
        None => scene
            .robot
            .model(&resolver)
            .with_context(|| format!("the robot of scene {}", src.scene_file.display()))?,
    };
    scene.validate(&robot)?;
    Ok((scene, robot))
}

/// Where an engine setting in force came from, the last given winning.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Origin<'a> {
    /// `--set`.
    Set,
    /// The run's parameters: `--params` (the file), or those a tune or a
    /// replay builds (`None`).
    Params(Option<&'a Path>),
    /// The scene's own `[engine.NAME]` table.
    Scene,
    /// The engine's default.
    Default,
}

/// Where `key` came from, as `settings` is built in [`prepare_with`]: the
/// scene's table, over it the parameters', over them `--set`.
fn origin<'a>(
    key: &str,
    own: &EngineSettings,
    params: Option<&EngineSettings>,
    params_file: Option<&'a Path>,
    overrides: &EngineSettings,
) -> Origin<'a> {
    if overrides.contains_key(key) {
        Origin::Set
    } else if params.is_some_and(|t| t.contains_key(key)) {
        Origin::Params(params_file)
    } else if own.contains_key(key) {
        Origin::Scene
    } else {
        Origin::Default
    }
}

/// A control period that is not a whole number of engine steps, blamed on
/// the timestep where the user gave one (`--set`, the parameters, or the
/// scene's engine table at its line), with the nearest timestep that fits;
/// else `e`, on the scene's `controller.period_s`.
fn period_error(
    scene: &Scene,
    engine: &str,
    timestep_s: f64,
    from: Origin<'_>,
    e: SceneError,
) -> anyhow::Error {
    if !(timestep_s.is_finite() && timestep_s > 0.0) {
        return e.into();
    }
    let period = scene.controller.period_s;
    let n = (period / timestep_s).round().max(1.0);
    let what = format!(
        "{TIMESTEP_KEY} = {timestep_s} s does not divide the scene's control period ({period} s, controller.period_s) into whole steps: try {} s ({n} step{} a period)",
        period / n,
        if n == 1.0 { "" } else { "s" }
    );
    match from {
        Origin::Set => anyhow!("--set: {what}"),
        Origin::Params(Some(file)) => anyhow!("{}: [engine.{engine}] {what}", file.display()),
        Origin::Params(None) => anyhow!("the run's parameters, [engine.{engine}] {what}"),
        Origin::Scene => scene
            .error(&format!("engine.{engine}.{TIMESTEP_KEY}"), what)
            .into(),
        Origin::Default => e.into(),
    }
}

/// Checks a run and makes it ready to load: every error a run can find
/// before simulating.
pub fn prepare(registry: Registry, src: &RunSource<'_>) -> Result<Prepared> {
    prepare_with(registry, src, read_params(src.params_file)?)
}

/// [`prepare`] with the physical parameters given instead of read from
/// `src.params_file`.
pub fn prepare_with(
    registry: Registry,
    src: &RunSource<'_>,
    params: PhysicalParams,
) -> Result<Prepared> {
    let engine = find_engine(registry, src.engine)?;
    let (scene, robot) = scene_and_robot(src)?;
    let known = engine_names(registry);
    check_engine_tables(&known, scene.engine_settings.keys(), src.scene_file)?;
    if let Some(file) = src.params_file {
        check_engine_tables(&known, params.engine_settings.keys(), file)?;
    }
    let scene_file = src.scene_file;
    let (scene, robot) =
        realitygap_core::controller::prepare(engine.as_ref(), &scene, &robot, &params)
            .map_err(|e| anyhow!("{e}"))
            .with_context(|| format!("scene {} with --params", scene_file.display()))?;
    let own = scene.settings_for(engine.name());
    let mut settings = params.settings_over(engine.name(), &own);
    let overrides = overrides_for(src.set, engine.name(), &known)?;
    settings.extend(overrides.clone());
    let from = |key: &str| {
        origin(
            key,
            &own,
            params.engine_settings.get(engine.name()),
            src.params_file,
            &overrides,
        )
    };
    let timestep_s = match engine.check_settings(&settings) {
        Ok(t) => t,
        // A setting the scene's own table gives (neither --params nor
        // --set replaced it): the error at its line in the scene.
        Err(realitygap_core::engine::EngineError::Setting {
            engine: e,
            key,
            message,
        }) if from(&key) == Origin::Scene => {
            return Err(scene
                .error(
                    &format!("engine.{e}.{key}"),
                    format!("engine {e}: setting `{key}`: {message}"),
                )
                .into());
        }
        Err(e) => {
            return Err(anyhow::Error::new(e).context(format!(
                "scene {} ([engine.{}], --params and --set)",
                scene_file.display(),
                engine.name()
            )))
        }
    };
    let steps_per_period = scene
        .steps_per_period(timestep_s)
        .map_err(|e| period_error(&scene, engine.name(), timestep_s, from(TIMESTEP_KEY), e))?;
    Ok(Prepared {
        scene,
        robot,
        engine,
        settings,
        params,
        timestep_s,
        steps_per_period,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn known() -> Vec<String> {
        vec!["mujoco".into(), "ode".into()]
    }

    #[test]
    fn set_overrides_apply_per_engine() {
        let all = overrides_for(&["timestep_s=0.001".into()], "mujoco", &known()).unwrap();
        assert_eq!(all.get("timestep_s"), Some(&SettingValue::Float(0.001)));
        let other = overrides_for(&["ode.timestep_s=0.001".into()], "mujoco", &known()).unwrap();
        assert!(other.is_empty());
        assert!(overrides_for(&["nokey".into()], "mujoco", &known()).is_err());
        assert!(overrides_for(&["=3".into()], "mujoco", &known()).is_err());
        let e = overrides_for(&["nosuchengine.timestep_s=1".into()], "mujoco", &known())
            .unwrap_err()
            .to_string();
        assert!(e.contains("compiled in: mujoco, ode"), "{e}");
    }

    #[test]
    fn robot_labels_are_safe_directory_names() {
        assert_eq!(label_of(Path::new("/a/my robot+1.urdf")), "my_robot_1");
        assert_eq!(label_of(Path::new("x/m1n6s300.urdf")), "m1n6s300");
    }

    #[test]
    fn the_built_in_mico2_loads() {
        let (robot, path, label) = robot_override(Some("mico2"), &PackageResolver::new())
            .unwrap()
            .unwrap();
        assert_eq!(label, "mico2");
        assert_eq!(path, PathBuf::from("mico2.urdf (built in)"));
        assert!(!robot.joints.is_empty());
        assert!(robot_override(None, &PackageResolver::new())
            .unwrap()
            .is_none());
    }

    #[test]
    fn an_empty_registry_says_so() {
        fn none() -> Vec<Box<dyn Engine>> {
            Vec::new()
        }
        let e = find_engine(none, "mujoco").err().unwrap().to_string();
        assert!(e.contains("no physics engine"), "{e}");
        assert!(parse_perturbation(&[]).unwrap().is_none());
        assert!(read_params(None).is_ok());
    }
}
