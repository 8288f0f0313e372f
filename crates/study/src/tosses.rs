//! Tossed objects replayed in every engine: each recorded toss (a real run
//! of one free box, as `realitygap import contactnets` stores it) becomes a
//! scene of that box alone over the ground, started at the toss's first
//! recorded pose and twist, simulated at a 1 ms step and sampled at the
//! recorded times; the physics-free row flies the box ballistically and
//! freezes it where it first touches the ground.
//!
//! The headline measure: the box centre's distance from the recorded one,
//! averaged over the toss's samples, in box edges; then averaged over the
//! tosses, with a 95 % bootstrap interval over tosses.

use anyhow::{anyhow, bail, Context, Result};
use rayon::prelude::*;
use realitygap_analysis::bootstrap::percentile_interval;
use realitygap_core::controller::{
    load_prepared, lowest_point_z, prepare, refuse_unstable, ControlParams, ControllerLoop,
    RunOptions, RunStatus, SplitMix64,
};
use realitygap_core::engine::PHYSICS_FREE_ENGINE;
use realitygap_core::engine::{Engine, EngineSettings, SettingValue, TIMESTEP_KEY};
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_core::trajectory::Trajectory;
use realitygap_data::{EngineInfo, RunEntry, RunStatus as StoredStatus, RunStore, SourceKind};
use realitygap_report::html::ExtraSection;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The engine step of every toss replay, s: a tenth of the 148 Hz
/// recording's sample period or less in every engine.
pub const TOSS_TIMESTEP_S: f64 = 0.001;

/// The free box of a set of tosses, from the import's manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct TossedBox {
    /// The role of its pose columns (`cube`).
    pub role: String,
    /// Its edge, m.
    pub edge_m: f64,
    /// Its mass, kg.
    pub mass_kg: f64,
}

/// One recorded toss.
#[derive(Debug, Clone, PartialEq)]
pub struct Toss {
    /// The run id (the toss's number).
    pub id: String,
    /// Sample times, s, from 0.
    pub time_s: Vec<f64>,
    /// The box's recorded poses.
    pub poses: Vec<Pose>,
    /// The recorded velocity at the first sample, world frame, m/s.
    pub v0_m_s: Vec3,
    /// The recorded angular velocity at the first sample, world frame,
    /// rad/s.
    pub w0_rad_s: Vec3,
}

/// The tosses of a results directory of `import contactnets`.
#[derive(Debug, Clone)]
pub struct TossSet {
    /// The directory.
    pub dir: PathBuf,
    /// The box.
    pub object: TossedBox,
    /// The tosses, in the store's order.
    pub tosses: Vec<Toss>,
}

/// Where a replayed toss's initial velocity comes from (its initial pose
/// is always the first recorded one, its angular velocity the first
/// recorded one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TossStart {
    /// The first sample's recorded velocity (the data's backward
    /// difference): the better headline on the 456 visible tosses in 10
    /// of 12 engine rows (six engines, at their defaults and with
    /// friction 0.18).
    #[default]
    First,
    /// A least-squares fit of free flight over the first samples
    /// ([`fitted_velocity`]): better over the first 0.1 s in every engine
    /// (at their defaults MuJoCo 0.032 -> 0.027 edges, Bullet 0.027 ->
    /// 0.020), worse over the whole toss in most (MuJoCo 0.939 -> 0.975,
    /// Bullet 0.392 -> 0.427; with friction 0.18 better only in MuJoCo,
    /// 0.284 -> 0.266, and Bullet).
    Fit,
}

impl TossSet {
    /// The tosses at `indices`, in that order, of the same box.
    pub fn subset(&self, indices: &[usize]) -> TossSet {
        TossSet {
            dir: self.dir.clone(),
            object: self.object.clone(),
            tosses: indices.iter().map(|&i| self.tosses[i].clone()).collect(),
        }
    }
}

/// Whether `dir` is a results directory of tossed objects (its manifest's
/// settings name an `object`, and it records no robot).
pub fn is_toss_store(dir: &Path) -> bool {
    RunStore::open(dir).is_ok_and(|s| {
        let settings = &s.manifest().settings;
        settings.get("object").is_some() && settings.get("robot").is_none()
    })
}

/// The scene name of the results directories `replay` writes for tosses.
pub const TOSS_SCENE: &str = "tosses";

/// The results directories of `dir` that `replay` wrote for tosses (each
/// subfolder whose manifest's scene is [`TOSS_SCENE`]), by name.
fn toss_replay_stores(dir: &Path) -> Vec<RunStore> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut stores: Vec<RunStore> = entries
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .filter_map(|e| RunStore::open(&e.path()).ok())
        .filter(|s| s.manifest().scene.as_deref() == Some(TOSS_SCENE))
        .collect();
    stores.sort_by(|a, b| a.manifest().source.cmp(&b.manifest().source));
    stores
}

/// What the engines of a toss table ran with, as its report says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplayedWith {
    /// Every engine at its defaults (`reproduce`, `replay` without
    /// `--params`).
    Defaults,
    /// The parameters of a `--params` file (recorded in each engine's
    /// manifest, `settings.params`).
    Params,
}

impl ReplayedWith {
    /// "at its defaults" / "with the given parameters", after an
    /// engine's name.
    fn engine_phrase(self) -> &'static str {
        match self {
            ReplayedWith::Defaults => "at its defaults",
            ReplayedWith::Params => "with the given parameters",
        }
    }

    /// "at the defaults" / "with these parameters", after "contact physics".
    fn physics_phrase(self) -> &'static str {
        match self {
            ReplayedWith::Defaults => "at the defaults",
            ReplayedWith::Params => "with these parameters",
        }
    }

    /// What a replay with `params` runs with (the file they came from
    /// aside).
    pub fn of_params(params: &PhysicalParams) -> ReplayedWith {
        let json = |p: &PhysicalParams| serde_json::to_value(p).unwrap_or(Value::Null);
        if json(params) == json(&PhysicalParams::default()) {
            ReplayedWith::Defaults
        } else {
            ReplayedWith::Params
        }
    }

    /// What a replay's folder of tosses ran with: [`ReplayedWith::Defaults`]
    /// when every engine's manifest records the default parameters.
    pub fn of_folder(dir: &Path) -> ReplayedWith {
        let defaults = serde_json::to_value(PhysicalParams::default()).unwrap_or(Value::Null);
        let all_default = toss_replay_stores(dir)
            .iter()
            .filter(|s| s.manifest().engine.is_some())
            .all(|s| s.manifest().settings.get("params") == Some(&defaults));
        if all_default {
            ReplayedWith::Defaults
        } else {
            ReplayedWith::Params
        }
    }
}

/// Whether `dir` is the output folder of `replay` of tosses.
pub fn is_toss_replay_folder(dir: &Path) -> bool {
    !toss_replay_stores(dir).is_empty()
}

/// Measures the output folder of `replay` of tosses again (`compare`):
/// the real tosses from the folder its manifests name (`settings.real`),
/// every source's stored runs against them. A toss a source has no
/// finished run of counts as failed. Returns the rows and the tosses.
pub fn compare_toss_replay(dir: &Path) -> Result<(Vec<TossRow>, TossSet)> {
    let stores = toss_replay_stores(dir);
    if stores.is_empty() {
        bail!(
            "{}: no results directory of replayed tosses in it",
            dir.display()
        );
    }
    let mut real: Option<(PathBuf, String)> = None;
    for store in &stores {
        let named = store
            .manifest()
            .settings
            .get("real")
            .and_then(Value::as_str)
            .ok_or_else(|| {
                anyhow!(
                    "{}: manifest.json: settings.real (the real tosses' folder) is missing",
                    store.dir().display()
                )
            })?;
        match &real {
            None => real = Some((PathBuf::from(named), store.manifest().source.clone())),
            Some((first, source)) if first != Path::new(named) => bail!(
                "{}: the sources replayed different tosses: {source} those of {}, {} those of {named}",
                dir.display(),
                first.display(),
                store.manifest().source
            ),
            Some(_) => {}
        }
    }
    let (real, _) = real.expect("at least one store");
    let set = read_tosses(&real, TossStart::First)
        .with_context(|| format!("the real tosses of {} (settings.real)", dir.display()))?;
    let mut rows = Vec::new();
    for store in &stores {
        let runs: Vec<Result<TossRun, String>> = set
            .tosses
            .iter()
            .map(|toss| {
                let entry = store
                    .run(&toss.id)
                    .ok_or_else(|| format!("toss {} was not replayed", toss.id))?;
                let status = match entry.status {
                    StoredStatus::Ok | StoredStatus::Unstable => RunStatus::Completed,
                    StoredStatus::Diverged => RunStatus::Diverged {
                        t_s: f64::NAN,
                        reason: entry.message.clone().unwrap_or_default(),
                    },
                    StoredStatus::Failed => {
                        return Err(entry.message.clone().unwrap_or_else(|| "failed".into()))
                    }
                };
                let run = store.read_run(&toss.id).map_err(|e| e.to_string())?;
                Ok((run, status, entry.wall_time_s.unwrap_or(0.0), 0))
            })
            .collect();
        rows.push(toss_row(&store.manifest().source, &set, &runs, None));
    }
    Ok((rows, set))
}

/// Reads every finished toss of `dir`: poses, and the first sample's twist
/// from `runs/<id>.velocities.csv`.
pub fn read_tosses(dir: &Path, start: TossStart) -> Result<TossSet> {
    let store = RunStore::open(dir)?;
    let settings = &store.manifest().settings;
    let object = settings
        .get("object")
        .ok_or_else(|| anyhow!("{}: the manifest's settings name no object", dir.display()))?;
    let number = |key: &str| {
        object.get(key).and_then(Value::as_f64).ok_or_else(|| {
            anyhow!(
                "{}: manifest.json: settings.object.{key} is missing or not a number",
                dir.display()
            )
        })
    };
    let object = TossedBox {
        role: object
            .get("role")
            .and_then(Value::as_str)
            .unwrap_or("cube")
            .to_string(),
        edge_m: number("edge_m")?,
        mass_kg: number("mass_kg")?,
    };
    if !(object.edge_m > 0.0 && object.mass_kg > 0.0) {
        bail!(
            "{}: manifest.json: the object's edge ({} m) and mass ({} kg) must be positive",
            dir.display(),
            object.edge_m,
            object.mass_kg
        );
    }
    let mut tosses = Vec::new();
    for entry in store.runs() {
        if entry.status != StoredStatus::Ok {
            continue;
        }
        tosses.push(read_toss(&store, &entry.id, &object.role, start)?);
    }
    if tosses.is_empty() {
        bail!("{}: no finished toss to replay", dir.display());
    }
    Ok(TossSet {
        dir: dir.to_path_buf(),
        object,
        tosses,
    })
}

/// The tosses of a folder of published `N.pt` files (ContactNets' layout,
/// read directly, no results directory): `experiment` is its
/// `experiment.json` (default: beside the files or one folder up, else the
/// published constants). The box's mass is the experiment's (the published
/// 0.37 kg when it gives none).
pub fn read_toss_folder(
    dir: &Path,
    experiment: Option<&Path>,
    start: TossStart,
) -> Result<TossSet> {
    use realitygap_contactnets::{import, Experiment};
    let experiment = match experiment
        .map(Path::to_path_buf)
        .or_else(|| import::default_experiment_file(dir))
    {
        Some(file) => Experiment::read(&file)?,
        None => Experiment::published(),
    };
    let files = import::list_tosses(dir)?;
    let read = import::read_tosses(&files, &experiment)?;
    let object = TossedBox {
        role: realitygap_core::trajectory::CUBE.to_string(),
        edge_m: experiment.edge_m(),
        mass_kg: experiment
            .mass_kg
            .or(Experiment::published().mass_kg)
            .unwrap_or(0.37),
    };
    let tosses = read
        .into_iter()
        .map(|t| {
            let twist = t.twists[0];
            let v0_m_s = match start {
                TossStart::First => twist.linear_m_s,
                TossStart::Fit => fitted_velocity(&t.time_s, &t.poses).unwrap_or(twist.linear_m_s),
            };
            Toss {
                id: t.number.to_string(),
                v0_m_s,
                w0_rad_s: twist.angular_world_rad_s(t.poses[0].orientation),
                time_s: t.time_s,
                poses: t.poses,
            }
        })
        .collect();
    Ok(TossSet {
        dir: dir.to_path_buf(),
        object,
        tosses,
    })
}

fn read_toss(store: &RunStore, id: &str, role: &str, start: TossStart) -> Result<Toss> {
    let where_ = || format!("{}: run {id}", store.dir().display());
    let trajectory = store.read_run(id).with_context(where_)?;
    let track = trajectory
        .body(role)
        .ok_or_else(|| anyhow!("{}: no `{role}` pose columns", where_()))?;
    let mut poses = Vec::with_capacity(track.poses.len());
    for (i, p) in track.poses.iter().enumerate() {
        poses.push(p.ok_or_else(|| anyhow!("{}: sample {i} has no pose", where_()))?);
    }
    if poses.len() < 2 {
        bail!("{}: a toss needs two samples or more", where_());
    }
    let velocities = store.read_run_velocities(id).with_context(where_)?;
    let twist = velocities
        .iter()
        .find(|v| v.role == role)
        .and_then(|v| v.twists.first().copied().flatten())
        .ok_or_else(|| {
            anyhow!(
                "{}: runs/{id}.velocities.csv gives no `{role}` velocity at the first sample",
                store.dir().display()
            )
        })?;
    let t0 = trajectory.time_s[0];
    let time_s: Vec<f64> = trajectory.time_s.iter().map(|t| t - t0).collect();
    let v0_m_s = match start {
        TossStart::First => twist.linear_m_s,
        TossStart::Fit => fitted_velocity(&time_s, &poses).unwrap_or(twist.linear_m_s),
    };
    Ok(Toss {
        id: id.to_string(),
        time_s,
        v0_m_s,
        w0_rad_s: twist.angular_world_rad_s(poses[0].orientation),
        poses,
    })
}

/// Samples of a toss's start fitted by [`fitted_velocity`]: 5 samples,
/// 27 ms of flight at 148 Hz.
pub const START_FIT_SAMPLES: usize = 5;

/// The velocity at the first sample from a least-squares fit of free
/// flight, `p(t) = p0 + v0 t - g t^2 / 2` per axis, over the first
/// [`START_FIT_SAMPLES`] samples (the cube leaves the hand in flight);
/// `None` for a shorter toss.
pub fn fitted_velocity(time_s: &[f64], poses: &[Pose]) -> Option<Vec3> {
    let n = START_FIT_SAMPLES;
    if time_s.len() < n || poses.len() < n {
        return None;
    }
    let g = realitygap_core::scene::STANDARD_GRAVITY_M_S2;
    let t: Vec<f64> = time_s[..n].to_vec();
    let mean_t = t.iter().sum::<f64>() / n as f64;
    let stt: f64 = t.iter().map(|x| (x - mean_t).powi(2)).sum();
    if stt <= 0.0 {
        return None;
    }
    let slope = |y: &dyn Fn(usize) -> f64| {
        let mean_y = (0..n).map(y).sum::<f64>() / n as f64;
        (0..n)
            .map(|k| (t[k] - mean_t) * (y(k) - mean_y))
            .sum::<f64>()
            / stt
    };
    Some(Vec3::new(
        slope(&|k| poses[k].position_m.x),
        slope(&|k| poses[k].position_m.y),
        slope(&|k| poses[k].position_m.z + 0.5 * g * t[k] * t[k]),
    ))
}

/// The scene of one toss: the box alone over the ground at z = 0, at the
/// toss's first pose and twist, sampled every engine step until the last
/// recorded sample.
pub fn toss_scene(object: &TossedBox, toss: &Toss) -> Result<Scene> {
    let last = toss.time_s.last().copied().unwrap_or(0.0);
    let steps = (last / TOSS_TIMESTEP_S).ceil().max(1.0) as u64 + 1;
    let p = toss.poses[0];
    let (roll, pitch, yaw) = p.orientation.to_euler_rpy();
    let v = |a: Vec3| format!("[{:?}, {:?}, {:?}]", a.x, a.y, a.z);
    let text = format!(
        "name = \"toss_{id}\"\nduration_s = {dur:?}\n[ground]\nheight_m = 0.0\n[controller]\nperiod_s = {h:?}\n\
         [[object]]\nname = \"{role}\"\nshape = \"box\"\nsize_m = [{e:?}, {e:?}, {e:?}]\nmass_kg = {m:?}\n\
         position_m = {pos}\nrpy_deg = {rpy}\nlinear_velocity_m_s = {lin}\nangular_velocity_rad_s = {ang}\n\
         [[track]]\nrole = \"{role}\"\nobject = \"{role}\"\n",
        id = realitygap_data::sanitize_run_id(&toss.id),
        dur = steps as f64 * TOSS_TIMESTEP_S,
        h = TOSS_TIMESTEP_S,
        role = object.role,
        e = object.edge_m,
        m = object.mass_kg,
        pos = v(p.position_m),
        rpy = v(Vec3::new(roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees())),
        lin = v(toss.v0_m_s),
        ang = v(toss.w0_rad_s),
    );
    Scene::from_toml_str(&text, Path::new(&format!("(toss {})", toss.id)))
        .map_err(|e| anyhow!("toss {}: {e}", toss.id))
}

/// A trajectory sampled every step, resampled at `times` (positions
/// linearly, orientations by normalised linear interpolation).
fn resample(stepped: &Trajectory, role: &str, times: &[f64], h: f64) -> Trajectory {
    let mut out = Trajectory::with_bodies(&[role]);
    let poses = &stepped.bodies[0].poses;
    for &t in times {
        // Nothing is invented past the last step (a run that diverged).
        let k = (t / h + 1e-9).floor() as usize;
        if k >= poses.len() {
            break;
        }
        let frac = (t / h - k as f64).clamp(0.0, 1.0);
        let pose = match (
            poses.get(k).copied().flatten(),
            poses.get(k + 1).copied().flatten(),
        ) {
            (Some(a), Some(b)) => Some(interpolate(&a, &b, frac)),
            (Some(a), None) => Some(a),
            _ => None,
        };
        if pose.is_none() {
            break;
        }
        out.time_s.push(t);
        out.bodies[0].poses.push(pose);
    }
    out
}

fn interpolate(a: &Pose, b: &Pose, f: f64) -> Pose {
    let qb = if a.orientation.dot(b.orientation) < 0.0 {
        Quat::new(
            -b.orientation.w,
            -b.orientation.x,
            -b.orientation.y,
            -b.orientation.z,
        )
    } else {
        b.orientation
    };
    let qa = a.orientation;
    let q = Quat::new(
        qa.w + f * (qb.w - qa.w),
        qa.x + f * (qb.x - qa.x),
        qa.y + f * (qb.y - qa.y),
        qa.z + f * (qb.z - qa.z),
    );
    Pose::new(
        a.position_m.lerp(b.position_m, f),
        q.normalized().unwrap_or(qa),
    )
}

/// One replayed toss: the trajectory at the recorded times, how the run
/// ended, the wall time of its loop (s) and the engine steps taken.
pub type TossRun = (Trajectory, RunStatus, f64, u64);

/// Checks that `engine` can replay the tosses of `set` with `params` (the
/// parameters' keys, objects and settings) by loading the first toss,
/// before anything is written; the error names the engine.
pub fn check_toss_replay(
    engine: &dyn Engine,
    set: &TossSet,
    params: &PhysicalParams,
) -> Result<()> {
    let toss = &set.tosses[0];
    let scene = toss_scene(&set.object, toss)?;
    let options = RunOptions::default();
    let fail = |e: String| anyhow!("{}: {e}", engine.name());
    let (scene, robot) =
        prepare(engine, &scene, &RobotModel::world(), params).map_err(|e| fail(e.to_string()))?;
    let settings = toss_settings(engine, params);
    let sim = load_prepared(engine, &scene, &robot, &settings, params, &options)
        .map_err(|e| fail(e.to_string()))?;
    refuse_unstable(engine, sim.as_ref(), &options).map_err(|e| fail(e.to_string()))?;
    let h = sim.timestep_s();
    if (h - TOSS_TIMESTEP_S).abs() > 1e-12 {
        return Err(fail(format!(
            "a toss is replayed at a {TOSS_TIMESTEP_S} s step; the parameters set {h} s"
        )));
    }
    Ok(())
}

/// A 1 ms step, with the parameters' `[engine.NAME]` over it.
fn toss_settings(engine: &dyn Engine, params: &PhysicalParams) -> EngineSettings {
    let mut base = EngineSettings::new();
    base.insert(TIMESTEP_KEY.into(), SettingValue::Float(TOSS_TIMESTEP_S));
    params.settings_over(engine.name(), &base)
}

/// Simulates one toss in `engine` with `params` (the scene's settings with
/// the parameters' `[engine.NAME]` over a 1 ms step).
pub fn simulate_toss(
    engine: &dyn Engine,
    object: &TossedBox,
    toss: &Toss,
    params: &PhysicalParams,
) -> Result<TossRun, String> {
    let scene = toss_scene(object, toss).map_err(|e| e.to_string())?;
    let options = RunOptions::default();
    let (scene, robot) =
        prepare(engine, &scene, &RobotModel::world(), params).map_err(|e| e.to_string())?;
    let settings = toss_settings(engine, params);
    let mut sim = load_prepared(engine, &scene, &robot, &settings, params, &options)
        .map_err(|e| e.to_string())?;
    refuse_unstable(engine, sim.as_ref(), &options).map_err(|e| e.to_string())?;
    let h = sim.timestep_s();
    if (h - TOSS_TIMESTEP_S).abs() > 1e-12 {
        return Err(format!(
            "a toss is replayed at a {TOSS_TIMESTEP_S} s step; the parameters set {h} s"
        ));
    }
    let mut run = ControllerLoop::new(&scene, &options, &ControlParams::default());
    run.start(sim.as_mut()).map_err(|e| e.to_string())?;
    run.advance(sim.as_mut(), usize::MAX)
        .map_err(|e| e.to_string())?;
    let outcome = run.finish();
    let sampled = resample(&outcome.trajectory, &object.role, &toss.time_s, h);
    Ok((
        sampled,
        outcome.status,
        outcome.wall_time_s,
        outcome.engine_steps,
    ))
}

/// The physics-free toss: the box flies ballistically from its first
/// recorded pose and twist (gravity only, spinning at its first angular
/// velocity) and freezes where its lowest corner first reaches the ground.
pub fn ballistic_toss(object: &TossedBox, toss: &Toss) -> Trajectory {
    let half = Vec3::new(0.5, 0.5, 0.5).scale(object.edge_m);
    let g = Vec3::new(0.0, 0.0, -realitygap_core::scene::STANDARD_GRAVITY_M_S2);
    let p0 = toss.poses[0];
    let w = toss.w0_rad_s;
    let at = |t: f64| {
        let turn = if w.norm() > 0.0 {
            Quat::from_axis_angle(w.scale(1.0 / w.norm()), w.norm() * t)
        } else {
            Quat::IDENTITY
        };
        let orientation = (turn * p0.orientation)
            .normalized()
            .unwrap_or(p0.orientation);
        Pose::new(
            p0.position_m + toss.v0_m_s.scale(t) + g.scale(0.5 * t * t),
            orientation,
        )
    };
    let mut out = Trajectory::with_bodies(&[object.role.as_str()]);
    let mut frozen: Option<Pose> = None;
    for &t in &toss.time_s {
        let pose = match frozen {
            Some(p) => p,
            None => {
                let p = at(t);
                if t > 0.0 && lowest_point_z(&p, half) <= 0.0 {
                    frozen = Some(p);
                }
                p
            }
        };
        out.time_s.push(t);
        out.bodies[0].poses.push(Some(pose));
    }
    out
}

/// Per toss, the headline error: the mean distance of the box centre from
/// the recorded one over the samples both have, in box edges; `None` when
/// the run has no sample.
pub fn toss_error_edges(object: &TossedBox, toss: &Toss, run: &Trajectory) -> Option<f64> {
    let held = held_poses(object, toss, run)?;
    let sum: f64 = held
        .iter()
        .zip(&toss.poses)
        .map(|(s, r)| s.position_m.distance(r.position_m))
        .sum();
    Some(sum / toss.poses.len() as f64 / object.edge_m)
}

/// The run's pose at each of the toss's samples, a run that ended early
/// (diverged) holding its last pose for the rest; `None` when the run has
/// no sample.
fn held_poses(object: &TossedBox, toss: &Toss, run: &Trajectory) -> Option<Vec<Pose>> {
    let track = run.body(&object.role)?;
    let mut last = None;
    (0..toss.poses.len())
        .map(|k| {
            if let Some(p) = track.poses.get(k).copied().flatten() {
                last = Some(p);
            }
            last
        })
        .collect()
}

/// The secondary measures of one toss: the centre's error at 0.1 s and
/// 0.3 s after the first sample (edges; `None` for a shorter toss), at the
/// last sample (the rest pose, edges), and the orientation's mean error
/// over the samples (degrees). A run that ended early holds its last pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TossMeasures {
    /// Centre error 0.1 s in, edges.
    pub at_0_1_edges: Option<f64>,
    /// Centre error 0.3 s in, edges.
    pub at_0_3_edges: Option<f64>,
    /// Centre error at the last sample, edges.
    pub rest_edges: f64,
    /// Mean orientation error, degrees.
    pub orientation_deg: f64,
    /// The first impact's time, simulated minus recorded, s (`None` when
    /// either never comes within [`CONTACT_HEIGHT_EDGES`] of the ground).
    pub impact_error_s: Option<f64>,
    /// The time of rest, simulated minus recorded, s.
    pub rest_time_error_s: f64,
    /// Bounces, simulated minus recorded.
    pub bounce_error: f64,
    /// The centre's mean error over the samples of each of the recorded
    /// toss's [`PHASES`], edges (`None` for a phase it has no sample in).
    pub phase_edges: [Option<f64>; 4],
    /// The centre's mean error in each of the [`CURVE_BINS`] time bins
    /// from the recorded first impact ([`curve_bin`]), edges (`None`: no
    /// sample there, or a toss that never touches the ground).
    pub curve: [Option<f64>; CURVE_BINS],
}

/// The figure's time bins, from the recorded first impact: the first
/// starts this long before it, s (most tosses fly 0.1-0.3 s before it).
pub const CURVE_FROM_S: f64 = -0.3;
/// Each bin's width, s (3 of the motion capture's samples at 148 Hz).
pub const CURVE_BIN_S: f64 = 0.02;
/// Bins: to 1.5 s after the first impact.
pub const CURVE_BINS: usize = 90;
/// A bin is drawn when at least this many tosses have a sample in it, and
/// a tenth of the tosses ([`curve_min_tosses`]): the tosses end 0.5-2.5 s
/// after their impact, and a bin of a few tosses is noise.
pub const CURVE_MIN_TOSSES: usize = 10;

/// The tosses a bin of a set of `tosses` needs to be drawn.
pub fn curve_min_tosses(tosses: usize) -> usize {
    CURVE_MIN_TOSSES.max(tosses / 10)
}

/// The bin of a time `dt_s` from the recorded first impact, if any.
pub fn curve_bin(dt_s: f64) -> Option<usize> {
    // A hair's allowance: a sample at a bin's edge (the impact's own, at
    // 0.3 s / 0.02 s = 14.999...) falls in the bin it starts.
    let k = ((dt_s - CURVE_FROM_S) / CURVE_BIN_S + 1e-9).floor();
    (k >= 0.0 && k < CURVE_BINS as f64).then_some(k as usize)
}

/// The phases of a toss, from the recorded toss's events: flight until its
/// first impact, the impact ([`IMPACT_WINDOW_S`] from the first touch),
/// sliding and tumbling until it comes to rest, and rest. A toss that
/// never touches the ground is all flight.
pub const PHASES: [&str; 4] = ["flight", "impact", "slide and tumble", "rest"];
/// How long the impact phase lasts from the first touch, s: about 7 of the
/// motion capture's samples at 148 Hz, the first bounce's contact.
pub const IMPACT_WINDOW_S: f64 = 0.05;

/// The phase (an index of [`PHASES`]) of the time `t_s` of a toss whose
/// recorded events are `events`.
pub fn phase_of(events: &TossEvents, t_s: f64) -> usize {
    match events.impact_s {
        Some(impact) if t_s >= impact => {
            if t_s >= events.rest_s {
                3
            } else if t_s < impact + IMPACT_WINDOW_S {
                1
            } else {
                2
            }
        }
        _ => 0,
    }
}

/// A box whose lowest corner is this close to the ground (in edges, 5 mm
/// for the tossed cube) touches it: the motion capture's noise and the
/// ground's registration are a few millimetres.
pub const CONTACT_HEIGHT_EDGES: f64 = 0.05;
/// After touching the ground, a box whose lowest corner rises this high
/// (edges) and comes down again has bounced once.
pub const BOUNCE_HEIGHT_EDGES: f64 = 0.1;
/// A box is at rest from the first sample after which its centre stays
/// this close to where it ends (edges) ...
pub const REST_RADIUS_EDGES: f64 = 0.02;
/// ... and its orientation this close to its last, degrees.
pub const REST_ANGLE_DEG: f64 = 2.0;

/// The contact events of a box's poses at the times `time_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TossEvents {
    /// The first sample at which the lowest corner is within
    /// [`CONTACT_HEIGHT_EDGES`] of the ground, s; `None` if none is.
    pub impact_s: Option<f64>,
    /// The first sample from which the box stays within
    /// [`REST_RADIUS_EDGES`] and [`REST_ANGLE_DEG`] of its last pose, s.
    pub rest_s: f64,
    /// Bounces: after the first impact, how often the lowest corner rose
    /// above [`BOUNCE_HEIGHT_EDGES`] and came back within
    /// [`CONTACT_HEIGHT_EDGES`].
    pub bounces: usize,
}

/// [`TossEvents`] of `poses` (one per time of `time_s`, at least one) of
/// `object`.
pub fn toss_events(object: &TossedBox, time_s: &[f64], poses: &[Pose]) -> TossEvents {
    let half = Vec3::new(0.5, 0.5, 0.5).scale(object.edge_m);
    let contact = CONTACT_HEIGHT_EDGES * object.edge_m;
    let bounce = BOUNCE_HEIGHT_EDGES * object.edge_m;
    let mut impact_s = None;
    let mut bounces = 0;
    let mut aloft = false;
    for (t, p) in time_s.iter().zip(poses) {
        let z = lowest_point_z(p, half);
        match impact_s {
            None if z <= contact => impact_s = Some(*t),
            None => {}
            Some(_) if z > bounce => aloft = true,
            Some(_) if aloft && z <= contact => {
                aloft = false;
                bounces += 1;
            }
            Some(_) => {}
        }
    }
    let last = poses[poses.len() - 1];
    let still = |p: &Pose| {
        p.position_m.distance(last.position_m) <= REST_RADIUS_EDGES * object.edge_m
            && p.orientation.angle_to(last.orientation).to_degrees() <= REST_ANGLE_DEG
    };
    let moving = poses.iter().rposition(|p| !still(p));
    let rest = moving.map_or(0, |k| k + 1).min(poses.len() - 1);
    TossEvents {
        impact_s,
        rest_s: time_s[rest],
        bounces,
    }
}

/// [`TossMeasures`] of `run` against `toss`; `None` when the run has no
/// sample.
pub fn toss_measures(object: &TossedBox, toss: &Toss, run: &Trajectory) -> Option<TossMeasures> {
    let held = held_poses(object, toss, run)?;
    let gap = |k: usize| held[k].position_m.distance(toss.poses[k].position_m) / object.edge_m;
    let at = |t: f64| toss.time_s.iter().position(|&s| s >= t - 1e-9).map(gap);
    let orientation_deg = held
        .iter()
        .zip(&toss.poses)
        .map(|(s, r)| s.orientation.angle_to(r.orientation).to_degrees())
        .sum::<f64>()
        / held.len() as f64;
    let real = toss_events(object, &toss.time_s, &toss.poses);
    let sim = toss_events(object, &toss.time_s, &held);
    let mut sums = [(0.0, 0usize); 4];
    let mut bins = [(0.0, 0usize); CURVE_BINS];
    for (k, &t) in toss.time_s.iter().enumerate() {
        let phase = &mut sums[phase_of(&real, t)];
        phase.0 += gap(k);
        phase.1 += 1;
        if let Some(b) = real.impact_s.and_then(|i| curve_bin(t - i)) {
            bins[b].0 += gap(k);
            bins[b].1 += 1;
        }
    }
    let mean = |(sum, n): (f64, usize)| (n > 0).then(|| sum / n as f64);
    Some(TossMeasures {
        phase_edges: sums.map(mean),
        curve: bins.map(mean),
        impact_error_s: sim.impact_s.zip(real.impact_s).map(|(s, r)| s - r),
        rest_time_error_s: sim.rest_s - real.rest_s,
        bounce_error: sim.bounces as f64 - real.bounces as f64,
        at_0_1_edges: at(0.1),
        at_0_3_edges: at(0.3),
        rest_edges: gap(held.len() - 1),
        orientation_deg,
    })
}

/// The mean of `values` and its 95 % bootstrap interval over them
/// (2000 resamples, a fixed seed).
pub fn mean_interval(values: &[f64]) -> Option<(f64, f64, f64)> {
    if values.is_empty() {
        return None;
    }
    let n = values.len();
    let mean = values.iter().sum::<f64>() / n as f64;
    let mut rng = SplitMix64::new(0x7055);
    let reps: Vec<f64> = (0..2000)
        .map(|_| {
            (0..n)
                .map(|_| values[(rng.next_u64() % n as u64) as usize])
                .sum::<f64>()
                / n as f64
        })
        .collect();
    let i = percentile_interval(&reps, 0.95)?;
    Some((mean, i.low_m, i.high_m))
}

/// One source's row of the toss table.
#[derive(Debug, Clone, PartialEq)]
pub struct TossRow {
    /// The engine (or `ideal`).
    pub source: String,
    /// Tosses replayed and measured.
    pub tosses: usize,
    /// Tosses that diverged or failed.
    pub failed: usize,
    /// The headline: mean over tosses of the mean centre error, edges,
    /// with its 95 % interval.
    pub error_edges: Option<(f64, f64, f64)>,
    /// The centre's error 0.1 s in, edges, over the tosses that long.
    pub at_0_1_edges: Option<(f64, f64, f64)>,
    /// The centre's error 0.3 s in, edges.
    pub at_0_3_edges: Option<(f64, f64, f64)>,
    /// The rest pose's centre error (the last sample), edges.
    pub rest_edges: Option<(f64, f64, f64)>,
    /// The mean orientation error, degrees.
    pub orientation_deg: Option<(f64, f64, f64)>,
    /// The first impact's time, simulated minus recorded, ms.
    pub impact_error_ms: Option<(f64, f64, f64)>,
    /// The time of rest, simulated minus recorded, s.
    pub rest_time_error_s: Option<(f64, f64, f64)>,
    /// Bounces, simulated minus recorded.
    pub bounce_error: Option<(f64, f64, f64)>,
    /// The centre's error in each of the recorded tosses' [`PHASES`],
    /// edges: the mean over the tosses that have the phase of each toss's
    /// mean over the phase's samples.
    pub phase_edges: [Option<(f64, f64, f64)>; 4],
    /// Tosses simulated per second of wall time (engines only).
    pub tosses_per_s: Option<f64>,
    /// The centre's error against the time from the recorded first
    /// impact: per bin of [`curve_bin`], the mean over the tosses with a
    /// sample there of each toss's mean, edges; `None` in a bin with fewer
    /// tosses than [`curve_min_tosses`].
    pub curve: Vec<Option<f64>>,
    /// Each toss's headline error, in the set's order (`None`: it failed
    /// or has no sample).
    pub per_toss_edges: Vec<Option<f64>>,
}

/// Replays every toss of `set` in each engine and the physics-free model,
/// writes `OUT/<engine>/` (a manifest, `runs/<id>.csv`), and measures.
/// `progress` is called after each toss.
pub fn replay_tosses(
    engines: &[&dyn Engine],
    set: &TossSet,
    params: &PhysicalParams,
    out: &Path,
    jobs: usize,
    progress: &(dyn Fn(&str, &str, Option<&str>) + Sync),
) -> Result<Vec<TossRow>> {
    for engine in engines {
        check_toss_replay(*engine, set, params)?;
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut rows = Vec::new();
    let ideal: Vec<Trajectory> = set
        .tosses
        .iter()
        .map(|t| ballistic_toss(&set.object, t))
        .collect();
    let mut store = open_store(out, PHYSICS_FREE_ENGINE, None, set)?;
    store.set_settings(json!({
        "model": "ballistic flight from the first recorded pose and twist, frozen where the box first touches the ground",
        "real": set.dir.display().to_string(),
    }))?;
    for (toss, t) in set.tosses.iter().zip(&ideal) {
        store.write_run(RunEntry::new(&toss.id), t)?;
    }
    rows.push(toss_row(
        PHYSICS_FREE_ENGINE,
        set,
        &ideal
            .iter()
            .map(|t| Ok((t.clone(), RunStatus::Completed, 0.0, 0)))
            .collect::<Vec<_>>(),
        None,
    ));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .map_err(|e| anyhow!("a pool of {jobs} threads: {e}"))?;
    for engine in engines {
        let started = Instant::now();
        let runs: Vec<Result<TossRun, String>> = pool.install(|| {
            set.tosses
                .par_iter()
                .map(|t| {
                    let r = simulate_toss(*engine, &set.object, t, params);
                    progress(engine.name(), &t.id, r.as_ref().err().map(String::as_str));
                    r
                })
                .collect()
        });
        let wall = started.elapsed().as_secs_f64();
        let mut store = open_store(out, engine.name(), Some(*engine), set)?;
        store.set_settings(json!({
            "timestep_s": TOSS_TIMESTEP_S,
            "initial_state": "the first recorded pose and twist",
            "ground_height_m": 0.0,
            "real": set.dir.display().to_string(),
            // What the engine ran with (`--params`; every field unset: its
            // defaults), for `compare` and `report` of this folder.
            "params": serde_json::to_value(params).unwrap_or(Value::Null),
        }))?;
        for (toss, r) in set.tosses.iter().zip(&runs) {
            let mut entry = RunEntry::new(&toss.id);
            match r {
                Ok((trajectory, status, w, _)) => {
                    entry.wall_time_s = Some(*w);
                    if let RunStatus::Diverged { t_s, reason } = status {
                        entry.status = StoredStatus::Diverged;
                        entry.message = Some(format!("diverged at {t_s:.3} s: {reason}"));
                    }
                    store.write_run(entry, trajectory)?;
                }
                Err(message) => {
                    entry.message = Some(message.clone());
                    store.record_failed_run(entry)?;
                }
            }
        }
        rows.push(toss_row(engine.name(), set, &runs, Some(wall)));
    }
    let table = toss_markdown(&rows, set);
    std::fs::write(out.join("tosses.md"), &table)
        .with_context(|| format!("writing {}", out.join("tosses.md").display()))?;
    std::fs::write(out.join("tosses.json"), toss_json(&rows))
        .with_context(|| format!("writing {}", out.join("tosses.json").display()))?;
    Ok(rows)
}

fn open_store(
    out: &Path,
    name: &str,
    engine: Option<&dyn Engine>,
    _set: &TossSet,
) -> Result<RunStore> {
    let mut store = RunStore::create_or_open(
        &out.join(name),
        name,
        SourceKind::Simulated,
        Some(TOSS_SCENE),
    )?;
    if let Some(engine) = engine {
        store.set_engine(EngineInfo {
            name: engine.name().to_string(),
            version: engine.version(),
        })?;
    }
    Ok(store)
}

/// One source's row of the toss table from its runs of `set`'s tosses (in
/// order); `wall` is the wall time of those runs, s.
pub fn toss_row(
    source: &str,
    set: &TossSet,
    runs: &[Result<TossRun, String>],
    wall: Option<f64>,
) -> TossRow {
    let mut errors = Vec::new();
    let mut per_toss_edges = Vec::with_capacity(set.tosses.len());
    let mut measures = Vec::new();
    let mut failed = 0;
    for (toss, r) in set.tosses.iter().zip(runs) {
        match r {
            Ok((t, status, _, _)) => {
                if !matches!(status, RunStatus::Completed) {
                    failed += 1;
                }
                let e = toss_error_edges(&set.object, toss, t);
                errors.extend(e);
                per_toss_edges.push(e);
                measures.extend(toss_measures(&set.object, toss, t));
            }
            Err(_) => {
                failed += 1;
                per_toss_edges.push(None);
            }
        }
    }
    let pick = |f: &dyn Fn(&TossMeasures) -> Option<f64>| {
        mean_interval(&measures.iter().filter_map(f).collect::<Vec<f64>>())
    };
    TossRow {
        source: source.to_string(),
        tosses: errors.len(),
        failed,
        error_edges: mean_interval(&errors),
        at_0_1_edges: pick(&|m| m.at_0_1_edges),
        at_0_3_edges: pick(&|m| m.at_0_3_edges),
        rest_edges: pick(&|m| Some(m.rest_edges)),
        orientation_deg: pick(&|m| Some(m.orientation_deg)),
        impact_error_ms: pick(&|m| m.impact_error_s.map(|e| 1e3 * e)),
        rest_time_error_s: pick(&|m| Some(m.rest_time_error_s)),
        bounce_error: pick(&|m| Some(m.bounce_error)),
        phase_edges: [0, 1, 2, 3].map(|i| pick(&|m| m.phase_edges[i])),
        tosses_per_s: wall.filter(|w| *w > 0.0).map(|w| runs.len() as f64 / w),
        curve: (0..CURVE_BINS)
            .map(|b| {
                let v: Vec<f64> = measures.iter().filter_map(|m| m.curve[b]).collect();
                (v.len() >= curve_min_tosses(set.tosses.len()))
                    .then(|| v.iter().sum::<f64>() / v.len() as f64)
            })
            .collect(),
        per_toss_edges,
    }
}

/// The toss table as `tosses.json` holds it: an array of
/// [`toss_row_json`], pretty-printed, ending in a newline.
pub fn toss_json(rows: &[TossRow]) -> String {
    let rows: Vec<Value> = rows.iter().map(toss_row_json).collect();
    serde_json::to_string_pretty(&rows).unwrap_or_else(|_| "[]".into()) + "\n"
}

/// A row of the toss table as JSON.
pub fn toss_row_json(r: &TossRow) -> Value {
    json!({
        "source": r.source,
        "tosses": r.tosses,
        "failed": r.failed,
        "position_error_edges": r.error_edges.map(|(m, _, _)| m),
        "position_error_edges_ci95": r.error_edges.map(|(_, lo, hi)| [lo, hi]),
        "at_0_1_s_edges": r.at_0_1_edges.map(|(m, _, _)| m),
        "at_0_3_s_edges": r.at_0_3_edges.map(|(m, _, _)| m),
        "rest_edges": r.rest_edges.map(|(m, _, _)| m),
        "rest_edges_ci95": r.rest_edges.map(|(_, lo, hi)| [lo, hi]),
        "orientation_deg": r.orientation_deg.map(|(m, _, _)| m),
        "orientation_deg_ci95": r.orientation_deg.map(|(_, lo, hi)| [lo, hi]),
        "impact_error_ms": r.impact_error_ms.map(|(m, _, _)| m),
        "impact_error_ms_ci95": r.impact_error_ms.map(|(_, lo, hi)| [lo, hi]),
        "rest_time_error_s": r.rest_time_error_s.map(|(m, _, _)| m),
        "rest_time_error_s_ci95": r.rest_time_error_s.map(|(_, lo, hi)| [lo, hi]),
        "bounce_error": r.bounce_error.map(|(m, _, _)| m),
        "bounce_error_ci95": r.bounce_error.map(|(_, lo, hi)| [lo, hi]),
        "phases": PHASES.iter().zip(&r.phase_edges).map(|(name, v)| json!({
            "phase": name,
            "position_error_edges": v.map(|(m, _, _)| m),
            "position_error_edges_ci95": v.map(|(_, lo, hi)| [lo, hi]),
        })).collect::<Vec<_>>(),
        "tosses_per_s": r.tosses_per_s,
        "error_from_first_impact": {
            "bin_s": CURVE_BIN_S,
            // One entry per toss of the set: the threshold the curve used.
            "min_tosses": curve_min_tosses(r.per_toss_edges.len()),
            "points": curve_points(r).iter().map(|(t, v)| json!([t, v])).collect::<Vec<_>>(),
        },
    })
}

/// A row's curve as (bin centre from the recorded first impact, s; mean
/// error, edges).
pub fn curve_points(r: &TossRow) -> Vec<(f64, Option<f64>)> {
    r.curve
        .iter()
        .enumerate()
        .map(|(b, v)| (CURVE_FROM_S + (b as f64 + 0.5) * CURVE_BIN_S, *v))
        .collect()
}

/// The toss table as CSV, best first: one row per source, each measure's
/// mean and its 95 % interval's ends (empty where not measured).
pub fn toss_csv(rows: &[TossRow], set: &TossSet) -> String {
    /// A measure's mean and interval in a row.
    type Pick = fn(&TossRow) -> Option<(f64, f64, f64)>;
    let mut header = vec!["source".to_string(), "tosses".into(), "failed".into()];
    let mut measures: Vec<(String, Pick)> = vec![
        ("position_error_edges".into(), |r| r.error_edges),
        ("at_0_1_s_edges".into(), |r| r.at_0_1_edges),
        ("at_0_3_s_edges".into(), |r| r.at_0_3_edges),
        ("rest_edges".into(), |r| r.rest_edges),
        ("orientation_deg".into(), |r| r.orientation_deg),
        ("impact_error_ms".into(), |r| r.impact_error_ms),
        ("rest_time_error_s".into(), |r| r.rest_time_error_s),
        ("bounce_error".into(), |r| r.bounce_error),
    ];
    let phases: [Pick; 4] = [
        |r| r.phase_edges[0],
        |r| r.phase_edges[1],
        |r| r.phase_edges[2],
        |r| r.phase_edges[3],
    ];
    for (name, f) in PHASES.iter().zip(phases) {
        measures.push((format!("{}_edges", name.replace(' ', "_")), f));
    }
    for (name, _) in &measures {
        header.extend([name.clone(), format!("{name}_low"), format!("{name}_high")]);
    }
    let mut out = header.join(",") + "\n";
    for r in sorted_rows(rows, set) {
        let mut cells = vec![
            short_label(r).to_string(),
            r.tosses.to_string(),
            r.failed.to_string(),
        ];
        for (_, f) in &measures {
            match f(r) {
                Some((m, lo, hi)) => cells.extend([m, lo, hi].map(|v| v.to_string())),
                None => cells.extend(["", "", ""].map(String::from)),
            }
        }
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    out
}

/// The rows best first: by the headline, every source measured on all the
/// tosses before any that failed on some.
fn sorted_rows<'r>(rows: &'r [TossRow], set: &TossSet) -> Vec<&'r TossRow> {
    let mut sorted: Vec<&TossRow> = rows.iter().collect();
    sorted.sort_by(|a, b| {
        // A source that failed on some tosses is measured on fewer: it is
        // listed after every source measured on all of them.
        let k = |r: &TossRow| {
            (
                r.tosses < set.tosses.len(),
                r.error_edges.map_or(f64::INFINITY, |e| e.0),
            )
        };
        let (ka, kb) = (k(a), k(b));
        ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
    });
    sorted
}

/// The toss table in Markdown, best first.
pub fn toss_markdown(rows: &[TossRow], set: &TossSet) -> String {
    let sorted = sorted_rows(rows, set);
    let mut s = format!(
        "# Tosses: {} real tosses of a {:.4} m, {} kg box ({})\n\n\
         Position error of the box centre, averaged over each toss's recorded samples, in box edges (the headline); the same at 0.1 s and 0.3 s after the first sample and at the last (the rest pose); the orientation's mean error in degrees. Each is the mean over tosses with its 95 % bootstrap interval over tosses. Lower is closer.\n\n\
         | source | position error (edges) | at 0.1 s | at 0.3 s | at rest | orientation (deg) | tosses | diverged or failed | tosses/s |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        set.tosses.len(),
        set.object.edge_m,
        set.object.mass_kg,
        set.dir.display()
    );
    for r in &sorted {
        let label = if r.source == PHYSICS_FREE_ENGINE {
            "physics-free (ballistic, frozen at first contact)".to_string()
        } else {
            r.source.clone()
        };
        let cell = |v: Option<(f64, f64, f64)>, digits: usize| {
            v.map_or("n/a".to_string(), |(m, lo, hi)| {
                format!("{m:.digits$} [{lo:.digits$}, {hi:.digits$}]")
            })
        };
        let err = format!(
            "{} | {} | {} | {} | {}",
            cell(r.error_edges, 3),
            cell(r.at_0_1_edges, 3),
            cell(r.at_0_3_edges, 3),
            cell(r.rest_edges, 3),
            cell(r.orientation_deg, 1)
        );
        let speed = r
            .tosses_per_s
            .map_or("-".to_string(), |v| format!("{v:.1}"));
        s.push_str(&format!(
            "| {label} | {err} | {} | {} | {speed} |\n",
            r.tosses, r.failed
        ));
    }
    let real: Vec<TossEvents> = set
        .tosses
        .iter()
        .map(|t| toss_events(&set.object, &t.time_s, &t.poses))
        .collect();
    s.push_str(&phases_markdown(&sorted, set, &real));
    s.push_str(&events_markdown(&sorted, &real));
    s
}

/// The tosses' section of the report (`reproduce`'s index.html): the
/// verdict in sentences made from the rows, the figure of the centre's
/// error against the time from the first impact, and the table with the
/// error by phase. `table` names the full Markdown table's file.
pub fn report_section(
    rows: &[TossRow],
    set: &TossSet,
    with: ReplayedWith,
    table: &str,
    replay: Vec<realitygap_report::replay3d::ExtraScene>,
) -> ExtraSection {
    let sorted = sorted_rows(rows, set);
    let cell = |v: Option<(f64, f64, f64)>, digits: usize| {
        v.map_or("n/a".to_string(), |(m, lo, hi)| {
            format!("{m:.digits$} [{lo:.digits$}, {hi:.digits$}]")
        })
    };
    let mut paragraphs = verdict(&sorted, set, with);
    paragraphs.push(format!(
        "Each toss starts from its first recorded pose and twist; every engine {}, the physics-free row a ballistic flight frozen where the cube first touches the ground. The centre's error is averaged over a toss's recorded samples, in cube edges ({:.4} m), then over the tosses, with its 95 % bootstrap interval over tosses; the phases are the recorded toss's own (the impact: {:.0} ms from the first touch). Every measure, the contact events and the speeds: {table}.",
        with.engine_phrase(),
        set.object.edge_m,
        1e3 * IMPACT_WINDOW_S
    ));
    let mut header = vec!["Source".to_string(), "Centre error (edges)".to_string()];
    header.extend(PHASES.iter().map(|p| {
        let mut p = p.to_string();
        p[..1].make_ascii_uppercase();
        p
    }));
    header.extend(["Rest pose (edges)", "Orientation (deg)", "Tosses (failed)"].map(String::from));
    let rows: Vec<Vec<String>> = sorted
        .iter()
        .map(|r| {
            let mut row = vec![short_label(r).to_string(), cell(r.error_edges, 3)];
            row.extend(r.phase_edges.iter().map(|v| cell(*v, 3)));
            row.push(cell(r.rest_edges, 3));
            row.push(cell(r.orientation_deg, 1));
            row.push(format!("{} ({})", r.tosses, r.failed));
            row
        })
        .collect();
    let curves: Vec<realitygap_report::tosses::TossCurve> = sorted
        .iter()
        .map(|r| realitygap_report::tosses::TossCurve {
            source: short_label(r).to_string(),
            points: curve_points(r),
        })
        .collect();
    let figure = realitygap_report::tosses::toss_figure(
        &curves,
        realitygap_report::tosses::CurveMaking {
            bin_s: CURVE_BIN_S,
            min_tosses: curve_min_tosses(set.tosses.len()),
            impact_window_s: IMPACT_WINDOW_S,
            tosses: set.tosses.len(),
        },
    );
    ExtraSection {
        id: "tosses".into(),
        title: format!(
            "The cube tosses: {} real tosses in every engine",
            set.tosses.len()
        ),
        lead: Vec::new(),
        paragraphs,
        header,
        rows,
        figures: vec![figure],
        replay,
    }
}

/// A report of the tosses replayed into `replay_dir` (as [`replay_tosses`]
/// wrote them, measured as `rows`): `report_dir/index.html`, a page of the
/// toss section alone (the verdict, the figure, the table, the 3D replay of
/// three tosses), its figure under `report_dir/figures/`. `table` names
/// where the full table is; the page's path.
pub fn write_toss_report(
    rows: &[TossRow],
    set: &TossSet,
    replay_dir: &Path,
    report_dir: &Path,
    with: ReplayedWith,
    table: &str,
) -> Result<PathBuf> {
    let replay = replay_scenes(rows, set, replay_dir)?;
    let section = report_section(rows, set, with, table, replay);
    let mut provenance =
        realitygap_report::Provenance::new(format!("Cube tosses: {}", replay_dir.display()));
    provenance.results_dir = Some(replay_dir.display().to_string());
    provenance.data_dir = Some(set.dir.display().to_string());
    provenance.details.push((
        "tosses".into(),
        format!("{} real tosses of {}", set.tosses.len(), set.dir.display()),
    ));
    let files = realitygap_report::write_report_with(&[], &provenance, report_dir, &[section])
        .with_context(|| format!("writing the report into {}", report_dir.display()))?;
    Ok(files.index_html)
}

/// The tosses the report's 3D replay shows: those at the quartiles and the
/// median of the closest engine's error (the engine first in `rows`' best
/// order), each with the real cube and every source's, read back from
/// `out/<source>/` (as [`replay_tosses`] wrote them).
pub fn replay_scenes(
    rows: &[TossRow],
    set: &TossSet,
    out: &Path,
) -> Result<Vec<realitygap_report::replay3d::ExtraScene>> {
    use realitygap_report::replay3d::{ExtraScene, ExtraSource};
    let sorted = sorted_rows(rows, set);
    let Some(best) = sorted
        .iter()
        .find(|r| r.source != PHYSICS_FREE_ENGINE && r.error_edges.is_some())
    else {
        return Ok(Vec::new());
    };
    let mut ranked: Vec<(usize, f64)> = best
        .per_toss_edges
        .iter()
        .enumerate()
        .filter_map(|(i, e)| e.map(|e| (i, e)))
        .collect();
    ranked.sort_by(|a, b| a.1.total_cmp(&b.1));
    if ranked.is_empty() {
        return Ok(Vec::new());
    }
    let track = |name: &str, kind: &str, poses: &[Pose]| ExtraSource {
        name: name.into(),
        kind: kind.into(),
        position_m: poses
            .iter()
            .map(|p| Some([p.position_m.x, p.position_m.y, p.position_m.z]))
            .collect(),
        orientation: poses
            .iter()
            .map(|p| {
                let q = p.orientation;
                Some([q.w, q.x, q.y, q.z])
            })
            .collect(),
    };
    let mut scenes = Vec::new();
    let mut chosen: Vec<(usize, &str)> = Vec::new();
    for (q, what) in [
        (0.5, "median"),
        (0.25, "lower quartile"),
        (0.75, "upper quartile"),
    ] {
        let k = ((ranked.len() - 1) as f64 * q).round() as usize;
        if !chosen.iter().any(|c| c.0 == ranked[k].0) {
            chosen.push((ranked[k].0, what));
        }
    }
    let stores = sorted
        .iter()
        .map(|r| {
            let dir = out.join(&r.source);
            RunStore::open(&dir).with_context(|| format!("reading the tosses of {}", dir.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    for (i, what) in chosen {
        let toss = &set.tosses[i];
        let mut sources = vec![track("real", "recorded", &toss.poses)];
        for (r, store) in sorted.iter().zip(&stores) {
            // A toss that failed in this source has no run: no box drawn.
            let Ok(run) = store.read_run(&toss.id) else {
                continue;
            };
            let Some(poses) = held_poses(&set.object, toss, &run) else {
                continue;
            };
            let kind = if r.source == PHYSICS_FREE_ENGINE {
                "physics-free"
            } else {
                "simulated"
            };
            sources.push(track(short_label(r), kind, &poses));
        }
        let dt_s = if toss.time_s.len() > 1 {
            (toss.time_s[toss.time_s.len() - 1] - toss.time_s[0]) / (toss.time_s.len() - 1) as f64
        } else {
            1.0 / 148.0
        };
        scenes.push(ExtraScene {
            name: format!(
                "toss {} ({} of {}: {:.2} edges)",
                toss.id,
                what,
                best.source,
                best.per_toss_edges[i].unwrap_or(f64::NAN)
            ),
            dt_s,
            edge_m: set.object.edge_m,
            sources,
        });
    }
    Ok(scenes)
}

/// The tosses' verdict, in sentences made from the rows (best first): the
/// closest source, whether the engines beat the physics-free row (their
/// intervals apart from its interval), and where the closest engine and
/// the physics-free row differ by phase.
fn verdict(sorted: &[&TossRow], set: &TossSet, with: ReplayedWith) -> Vec<String> {
    let fmt = |v: (f64, f64, f64)| format!("{:.3} [{:.3}, {:.3}]", v.0, v.1, v.2);
    let free = sorted.iter().find(|r| r.source == PHYSICS_FREE_ENGINE);
    let engines: Vec<&&TossRow> = sorted
        .iter()
        .filter(|r| r.source != PHYSICS_FREE_ENGINE && r.error_edges.is_some())
        .collect();
    let Some(best) = engines.first() else {
        return vec!["No engine replayed a toss: nothing to compare.".into()];
    };
    let best_e = best.error_edges.expect("filtered on it");
    let mut first = format!(
        "On {} real cube tosses, the engine closest to the real cube {} is {}: its centre strays {} cube edges on average over a toss",
        set.tosses.len(),
        with.engine_phrase(),
        best.source,
        fmt(best_e)
    );
    let Some(free_e) = free.and_then(|f| f.error_edges) else {
        first.push('.');
        return vec![first];
    };
    first.push_str(&format!(", the physics-free row's {}.", fmt(free_e)));
    let ahead: Vec<&str> = engines
        .iter()
        .filter(|r| r.error_edges.is_some_and(|e| e.2 < free_e.1))
        .map(|r| r.source.as_str())
        .collect();
    let behind: Vec<&str> = engines
        .iter()
        .filter(|r| r.error_edges.is_some_and(|e| e.1 > free_e.2))
        .map(|r| r.source.as_str())
        .collect();
    let n = engines.len();
    let are = |k: usize| if k == 1 { "is" } else { "are" };
    let second = match (ahead.len(), behind.len()) {
        (0, 0) => format!("No engine of {n} is clearly closer or farther than the physics-free row: every interval overlaps its interval, so contact physics {} does not pay on these tosses.", with.physics_phrase()),
        (0, b) => format!("No engine of {n} beats the physics-free row: {b} {} clearly farther from the real cube ({}), the rest overlap it. Contact physics {} does not pay here.", are(b), behind.join(", "), with.physics_phrase()),
        (a, 0) => format!("{a} of {n} engines {} clearly closer than the physics-free row (their intervals lie below its interval): {}.", are(a), ahead.join(", ")),
        (a, b) => format!("{a} of {n} engines {} clearly closer than the physics-free row (their intervals lie below its interval): {}; {b} {} clearly farther: {}.", are(a), ahead.join(", "), are(b), behind.join(", ")),
    };
    let mut out = vec![first, second];
    if let Some(free) = free {
        let phases: Vec<String> = PHASES
            .iter()
            .zip(best.phase_edges.iter().zip(&free.phase_edges))
            .filter_map(|(p, (b, f))| {
                let (b, f) = ((*b)?.0, (*f)?.0);
                Some(format!("{p} {b:.3} against {f:.3}"))
            })
            .collect();
        if !phases.is_empty() {
            out.push(format!(
                "By phase of the recorded toss, {} against the physics-free row (edges): {}.",
                best.source,
                phases.join(", ")
            ));
        }
    }
    out
}

/// A source's name in the secondary tables: `physics-free` for the
/// physics-free row.
fn short_label(r: &TossRow) -> &str {
    if r.source == PHYSICS_FREE_ENGINE {
        "physics-free"
    } else {
        &r.source
    }
}

/// The table of errors by phase: each source's centre error in the
/// recorded tosses' flight, impact, slide and tumble, and rest.
fn phases_markdown(sorted: &[&TossRow], set: &TossSet, real: &[TossEvents]) -> String {
    let mut samples = [0usize; 4];
    for (t, events) in set.tosses.iter().zip(real) {
        for &time in &t.time_s {
            samples[phase_of(events, time)] += 1;
        }
    }
    let total = samples.iter().sum::<usize>().max(1) as f64;
    let shares: Vec<String> = PHASES
        .iter()
        .zip(samples)
        .map(|(p, n)| format!("{p} {:.0} %", 100.0 * n as f64 / total))
        .collect();
    let mut s = format!(
        "\n## Error by phase\n\n\
         Each recorded toss split at its own events: flight until its first impact, the impact ({:.0} ms from the first touch), slide and tumble until it comes to rest, then rest (of the recorded samples: {}). The box centre's error in each phase, averaged over the phase's samples, then over the tosses that have the phase, in box edges, with its 95 % interval:\n\n\
         | source | {} |\n|---|---:|---:|---:|---:|\n",
        1e3 * IMPACT_WINDOW_S,
        shares.join(", "),
        PHASES.join(" | ")
    );
    for r in sorted {
        let label = short_label(r);
        let cells: Vec<String> = r
            .phase_edges
            .iter()
            .map(|v| {
                v.map_or("n/a".to_string(), |(m, lo, hi)| {
                    format!("{m:.3} [{lo:.3}, {hi:.3}]")
                })
            })
            .collect();
        s.push_str(&format!("| {label} | {} |\n", cells.join(" | ")));
    }
    s
}

/// The contact events' table: each source's impact time, time of rest and
/// bounces against the recorded ones.
fn events_markdown(sorted: &[&TossRow], real: &[TossEvents]) -> String {
    let n = real.len().max(1) as f64;
    let impacts: Vec<f64> = real.iter().filter_map(|e| e.impact_s).collect();
    let mut s = format!(
        "\n## Contact events\n\n\
         The recorded tosses first touch the ground (lowest corner within {:.0} % of an edge) at {:.3} s on average ({} of {}), come to rest (centre within {:.0} % of an edge and {REST_ANGLE_DEG}° of its last pose) at {:.2} s, and bounce (the corner {:.0} % of an edge up and down again) {:.2} times. Per source, simulated minus recorded, mean over tosses with its 95 % interval:\n\n\
         | source | first impact (ms) | time of rest (s) | bounces |\n|---|---:|---:|---:|\n",
        100.0 * CONTACT_HEIGHT_EDGES,
        impacts.iter().sum::<f64>() / impacts.len().max(1) as f64,
        impacts.len(),
        real.len(),
        100.0 * REST_RADIUS_EDGES,
        real.iter().map(|e| e.rest_s).sum::<f64>() / n,
        100.0 * BOUNCE_HEIGHT_EDGES,
        real.iter().map(|e| e.bounces as f64).sum::<f64>() / n,
    );
    let cell = |v: Option<(f64, f64, f64)>, digits: usize| {
        v.map_or("n/a".to_string(), |(m, lo, hi)| {
            format!("{m:+.digits$} [{lo:+.digits$}, {hi:+.digits$}]")
        })
    };
    for r in sorted {
        let label = short_label(r);
        s.push_str(&format!(
            "| {label} | {} | {} | {} |\n",
            cell(r.impact_error_ms, 1),
            cell(r.rest_time_error_s, 2),
            cell(r.bounce_error, 2)
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> TossedBox {
        TossedBox {
            role: "cube".into(),
            edge_m: 0.1,
            mass_kg: 0.37,
        }
    }

    /// A toss recorded from the analytic parabola (no spin) until it
    /// would sink into the ground.
    fn parabola(v0: Vec3, samples: usize) -> Toss {
        let p0 = Vec3::new(0.0, 0.0, 0.3);
        let g = Vec3::new(0.0, 0.0, -9.81);
        let time_s: Vec<f64> = (0..samples).map(|k| k as f64 / 148.0).collect();
        let poses = time_s
            .iter()
            .map(|&t| Pose::new(p0 + v0.scale(t) + g.scale(0.5 * t * t), Quat::IDENTITY))
            .collect();
        Toss {
            id: "1".into(),
            time_s,
            poses,
            v0_m_s: v0,
            w0_rad_s: Vec3::ZERO,
        }
    }

    #[test]
    fn the_ballistic_toss_follows_the_parabola_then_freezes_on_the_ground() {
        let toss = parabola(Vec3::new(1.0, 0.0, 0.5), 60);
        let run = ballistic_toss(&cube(), &toss);
        let poses: Vec<Pose> = run.bodies[0].poses.iter().map(|p| p.unwrap()).collect();
        // Contact when the centre is half an edge up: 0.3 + 0.5 t - 4.905 t^2 = 0.05.
        let t_contact = (0.5 + (0.25f64 + 4.0 * 4.905 * 0.25).sqrt()) / (2.0 * 4.905);
        for (k, (&t, p)) in run.time_s.iter().zip(&poses).enumerate() {
            if t < t_contact {
                assert!(
                    p.position_m.distance(toss.poses[k].position_m) < 1e-12,
                    "{t}"
                );
            } else {
                assert_eq!(*p, *poses.last().unwrap(), "frozen from {t_contact} s");
            }
        }
        let rest = poses.last().unwrap().position_m;
        assert!(rest.z <= 0.05 && rest.z > 0.05 - 0.1, "{rest:?}");
        assert_eq!(
            toss_error_edges(&cube(), &toss, &run).map(|e| e > 0.0),
            Some(true)
        );
    }

    #[test]
    fn events_are_the_first_touch_the_bounces_and_the_rest() {
        // Lowest corner heights (m) of a 0.1 m cube: flight, a touch, up
        // 2 cm (a bounce: above 1 cm), down to 4 mm (within the 5 mm of a
        // touch), then still on the ground.
        let heights = [0.3, 0.1, 0.002, 0.02, 0.004, 0.0, 0.0, 0.0];
        let time_s: Vec<f64> = (0..heights.len()).map(|k| k as f64 * 0.01).collect();
        let poses: Vec<Pose> = heights
            .iter()
            .map(|h| Pose::new(Vec3::new(0.0, 0.0, 0.05 + h), Quat::IDENTITY))
            .collect();
        let e = toss_events(&cube(), &time_s, &poses);
        assert_eq!(e.impact_s, Some(0.02));
        assert_eq!(e.bounces, 1);
        assert_eq!(e.rest_s, 0.05);
        // Never near the ground: no impact, no bounce; still throughout:
        // at rest from the first sample.
        let aloft = vec![Pose::new(Vec3::new(0.0, 0.0, 1.0), Quat::IDENTITY); 3];
        let e = toss_events(&cube(), &[0.0, 0.1, 0.2], &aloft);
        assert_eq!((e.impact_s, e.bounces, e.rest_s), (None, 0, 0.0));
    }

    #[test]
    fn each_phase_is_measured_on_its_own_samples() {
        // A 0.1 m cube dropped onto the ground, where it lands at 0.2 s at
        // 1 m/s along x and slides to a stop at 0.45 s (samples every
        // 0.01 s): flight, impact (0.2-0.25 s), slide (until it is within
        // 2 mm of its end, 0.42 s), rest.
        let time_s: Vec<f64> = (0..60).map(|k| k as f64 / 100.0).collect();
        let poses: Vec<Pose> = time_s
            .iter()
            .map(|&t| {
                let z = (0.35 - 7.5 * t * t).max(0.05);
                let s = (t - 0.2).clamp(0.0, 0.25);
                Pose::new(Vec3::new(s - 2.0 * s * s, 0.0, z), Quat::IDENTITY)
            })
            .collect();
        let toss = Toss {
            id: "1".into(),
            time_s: time_s.clone(),
            poses: poses.clone(),
            v0_m_s: Vec3::ZERO,
            w0_rad_s: Vec3::ZERO,
        };
        let events = toss_events(&cube(), &time_s, &poses);
        let (impact, rest) = (events.impact_s.unwrap(), events.rest_s);
        assert!(
            (impact - 0.2).abs() < 1e-9 && (rest - 0.42).abs() < 1e-9,
            "{events:?}"
        );
        let phases: Vec<usize> = time_s.iter().map(|&t| phase_of(&events, t)).collect();
        assert_eq!(
            [0, 1, 2, 3].map(|p| phases.iter().filter(|&&q| q == p).count()),
            [20, 5, 17, 18]
        );
        assert!(phases.windows(2).all(|w| w[0] <= w[1]), "{phases:?}");
        for (&t, &p) in time_s.iter().zip(&phases) {
            let expected = if t < impact {
                0
            } else if t >= rest {
                3
            } else if t < impact + IMPACT_WINDOW_S {
                1
            } else {
                2
            };
            assert_eq!(p, expected, "at {t} s");
        }
        // A run off by 1 cm in flight and 3 cm from the impact on.
        let mut run = Trajectory::with_bodies(&["cube"]);
        for (&t, p) in time_s.iter().zip(&poses) {
            let dx = if t < impact { 0.01 } else { 0.03 };
            run.time_s.push(t);
            run.bodies[0].poses.push(Some(Pose::new(
                p.position_m + Vec3::new(dx, 0.0, 0.0),
                p.orientation,
            )));
        }
        let m = toss_measures(&cube(), &toss, &run).unwrap();
        let close = |v: Option<f64>, e: f64| v.is_some_and(|v| (v - e).abs() < 1e-12);
        assert!(close(m.phase_edges[0], 0.1), "{:?}", m.phase_edges);
        for v in &m.phase_edges[1..] {
            assert!(close(*v, 0.3), "{:?}", m.phase_edges);
        }
        // The curve from the impact (0.2 s): 0.1 edges in the bins from
        // 0.2 s before it, 0.3 from it to 0.39 s after, nothing elsewhere.
        for (b, v) in m.curve.iter().enumerate() {
            let expected = match b {
                5..=14 => Some(0.1),
                15..=34 => Some(0.3),
                _ => None,
            };
            assert_eq!(v.is_some(), expected.is_some(), "bin {b}: {v:?}");
            if let Some(e) = expected {
                assert!(close(*v, e), "bin {b}: {v:?}");
            }
        }
        assert_eq!(curve_bin(-0.3), Some(0));
        assert_eq!(curve_bin(0.0), Some(15));
        assert_eq!(curve_bin(-0.31), None);
        assert_eq!(curve_bin(1.5), None);
        // Never near the ground: all flight.
        let aloft = TossEvents {
            impact_s: None,
            rest_s: 0.0,
            bounces: 0,
        };
        assert_eq!(phase_of(&aloft, 5.0), 0);
    }

    #[test]
    fn the_error_is_the_mean_centre_distance_in_edges() {
        let toss = parabola(Vec3::new(1.0, 0.0, 3.0), 10);
        let mut run = Trajectory::with_bodies(&["cube"]);
        for (t, p) in toss.time_s.iter().zip(&toss.poses) {
            run.time_s.push(*t);
            run.bodies[0].poses.push(Some(Pose::new(
                p.position_m + Vec3::new(0.02, 0.0, 0.0),
                p.orientation,
            )));
        }
        let e = toss_error_edges(&cube(), &toss, &run).unwrap();
        assert!((e - 0.2).abs() < 1e-12, "{e}");
        // A run that stopped half way counts its last gap for the rest.
        run.time_s.truncate(5);
        run.bodies[0].poses.truncate(5);
        let e = toss_error_edges(&cube(), &toss, &run).unwrap();
        assert!(e > 0.2, "{e}");
        let (m, lo, hi) = mean_interval(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert!((m - 2.5).abs() < 1e-12 && lo < m && m < hi, "{lo} {m} {hi}");
    }

    #[test]
    fn the_start_fit_recovers_the_velocity_of_free_flight() {
        let v0 = Vec3::new(1.2, -0.4, 2.5);
        let toss = parabola(v0, 12);
        let v = fitted_velocity(&toss.time_s, &toss.poses).unwrap();
        assert!(v.distance(v0) < 1e-9, "{v:?}");
        assert_eq!(fitted_velocity(&toss.time_s[..3], &toss.poses[..3]), None);
    }

    #[test]
    fn resampling_interpolates_between_steps() {
        let mut stepped = Trajectory::with_bodies(&["cube"]);
        for k in 0..3 {
            stepped.time_s.push(k as f64 * 0.001);
            stepped.bodies[0].poses.push(Some(Pose::new(
                Vec3::new(k as f64, 0.0, 0.0),
                Quat::IDENTITY,
            )));
        }
        let r = resample(&stepped, "cube", &[0.0, 0.0015, 0.002], 0.001);
        let x: Vec<f64> = r.bodies[0]
            .poses
            .iter()
            .map(|p| p.unwrap().position_m.x)
            .collect();
        assert!(
            (x[0] - 0.0).abs() < 1e-9 && (x[1] - 1.5).abs() < 1e-9 && (x[2] - 2.0).abs() < 1e-9,
            "{x:?}"
        );
    }

    /// A row of the toss table with the headline `e` and the flight and
    /// rest phases' errors.
    fn row(source: &str, e: (f64, f64, f64), flight: f64, rest: f64) -> TossRow {
        TossRow {
            source: source.into(),
            tosses: 40,
            failed: 0,
            error_edges: Some(e),
            at_0_1_edges: None,
            at_0_3_edges: None,
            rest_edges: Some((rest, rest, rest)),
            orientation_deg: Some((10.0, 9.0, 11.0)),
            impact_error_ms: None,
            rest_time_error_s: None,
            bounce_error: None,
            phase_edges: [
                Some((flight, flight, flight)),
                None,
                None,
                Some((rest, rest, rest)),
            ],
            tosses_per_s: None,
            curve: (0..CURVE_BINS).map(|b| (b > 3).then_some(e.0)).collect(),
            per_toss_edges: vec![Some(e.0); 40],
        }
    }

    /// The report's section: the verdict from the numbers (closest
    /// engine, who beats the physics-free row, by phase), the table best
    /// first with a column per phase, and the figure with a line per row.
    #[test]
    fn the_report_section_says_who_beats_the_physics_free_row() {
        let set = TossSet {
            dir: PathBuf::from("tosses"),
            object: cube(),
            tosses: (0..40).map(|_| parabola(Vec3::ZERO, 10)).collect(),
        };
        let free = row(PHYSICS_FREE_ENGINE, (1.5, 1.4, 1.6), 0.05, 1.8);
        let rows = [
            row("ode", (2.0, 1.8, 2.2), 0.05, 2.1),
            free.clone(),
            row("mujoco", (0.3, 0.25, 0.35), 0.04, 0.2),
            row("rapier", (1.45, 1.3, 1.7), 0.05, 1.6),
        ];
        let s = report_section(
            &rows,
            &set,
            ReplayedWith::Defaults,
            "tosses/tosses.md",
            Vec::new(),
        );
        assert_eq!(s.id, "tosses");
        let text = s.paragraphs.join("\n");
        assert!(
            text.contains("the engine closest to the real cube at its defaults is mujoco: its centre strays 0.300 [0.250, 0.350] cube edges")
                && text.contains("the physics-free row's 1.500 [1.400, 1.600]"),
            "{text}"
        );
        assert!(
            text.contains("1 of 3 engines is clearly closer than the physics-free row (their intervals lie below its interval): mujoco; 1 is clearly farther: ode."),
            "{text}"
        );
        assert!(
            text.contains("mujoco against the physics-free row (edges): flight 0.040 against 0.050, rest 0.200 against 1.800."),
            "{text}"
        );
        assert!(text.contains("tosses/tosses.md"), "{text}");
        let order: Vec<&str> = s.rows.iter().map(|r| r[0].as_str()).collect();
        assert_eq!(order, ["mujoco", "rapier", "physics-free", "ode"]);
        assert_eq!(s.header.len(), 2 + 4 + 3);
        assert_eq!(s.header[2], "Flight");
        assert!(s.rows.iter().all(|r| r.len() == s.header.len()));
        assert_eq!(s.rows[0][3], "n/a", "mujoco has no impact phase here");
        assert_eq!(s.figures.len(), 1);
        assert_eq!(s.figures[0].lines.len(), 4);
        assert_eq!(s.figures[0].lines[0].name, "mujoco");
        // No engine ahead and none behind: said so.
        let close = [row("mujoco", (1.45, 1.3, 1.7), 0.05, 1.6), free];
        let text = report_section(&close, &set, ReplayedWith::Params, "t.md", Vec::new())
            .paragraphs
            .join("\n");
        assert!(
            text.contains("No engine of 1 is clearly closer or farther than the physics-free row")
                && text.contains("the real cube with the given parameters is mujoco")
                && text.contains("so contact physics with these parameters does not pay")
                && !text.contains("defaults"),
            "{text}"
        );
    }
}
