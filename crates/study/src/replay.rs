//! `realitygap replay`: a robot's recorded episodes (a results directory
//! of `realitygap import rosbag|csv|lerobot`) replayed in every engine, and
//! the gap measured in joint space.
//!
//! For each episode and engine: a scene of the recording's robot (the URDF,
//! its base at the origin, one servo per moving joint with the typed gains
//! `joints.<joint>.kp` and `joints.<joint>.kv`, its end effector tracked as
//! `wrist`; written to `OUT/replay.toml`, or the user's `--scene`), the
//! engine started from the episode's first joint state, and the recorded
//! commands applied at their timestamps ([`realitygap_core::replay`]). One
//! results directory per engine (`OUT/<engine>/`, a run per episode, rerun
//! skips finished runs), and the physics-free model (`OUT/ideal/`: the
//! commands with perfect tracking), then the joint-space table.

use anyhow::{anyhow, bail, Context, Result};
use realitygap_core::controller::{load_prepared, prepare, refuse_unstable, RunOptions, RunStatus};
use realitygap_core::replay::{
    default_gains, fill_default_gains, kinematic_angles, replay, ReplayPlan,
};
use realitygap_core::robot::RobotModel;
use realitygap_core::trajectory::WRIST;
use realitygap_core::{BodyTrack, Engine, PhysicalParams, Pose, Scene, Trajectory};
use realitygap_data::{EngineInfo, RunEntry, RunStatus as StoredStatus, RunStore, SourceKind};
use realitygap_runner::protocol::{Job, ReplayJob};
use realitygap_runner::slurm::SlurmOptions;
use realitygap_runner::{run_child, ChildEnd, Launcher};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Name of the scene written into the output folder.
pub const SCENE_FILE: &str = "replay.toml";
/// What a replay was of (the recordings, the robot), written into the
/// output folder so that `compare OUT` can measure it again.
pub const RECORD_FILE: &str = "replay.json";
/// Source name of the physics-free model, the same name as in every study
/// table and in `tune --engine ideal`: the recorded commands with perfect
/// tracking ([`kinematic_run`], its one definition in a replay).
pub const KINEMATIC: &str = realitygap_core::engine::PHYSICS_FREE_ENGINE;
/// Engine timestep of the generated scene, s (every engine).
pub const TIMESTEP_S: f64 = 1e-3;

/// What to replay, where, and how.
pub struct ReplayRequest<'a> {
    /// The recorded episodes (a results directory of an import).
    pub real_dir: &'a Path,
    /// The robot's URDF; `None`: the one the import recorded.
    pub urdf: Option<&'a Path>,
    /// ROS packages for `package://` URIs (NAME=DIR).
    pub packages: &'a [String],
    /// Typed physical parameters (servo gains, damping, delay, ...).
    pub params: &'a PhysicalParams,
    /// A scene to use instead of the generated one.
    pub scene: Option<&'a Path>,
    /// The output folder.
    pub out: &'a Path,
}

/// One recorded episode.
pub struct Episode {
    /// Its run id.
    pub id: String,
    /// Its trajectory (joint angles, commands, end-effector poses).
    pub real: Trajectory,
}

/// Everything a replay needs, read and checked before any engine runs.
pub struct Prepared {
    /// The robot.
    pub robot: RobotModel,
    /// The scene every engine runs.
    pub scene: Scene,
    /// The episodes.
    pub episodes: Vec<Episode>,
    /// The end-effector link's name.
    pub link: String,
    /// The scene's file (the generated `OUT/replay.toml` or `--scene`),
    /// absolute: what the child processes read.
    pub scene_file: PathBuf,
    /// The robot's URDF, absolute.
    pub urdf: PathBuf,
    /// `NAME=DIR` ROS package locations.
    pub packages: Vec<String>,
    /// The recorded episodes' results directory, absolute.
    pub real_dir: PathBuf,
    /// The robot's moving joints the recording does not name, held still
    /// at these positions (rad or m) in the generated scene.
    pub held: BTreeMap<String, f64>,
}

impl Prepared {
    /// One line per joint whose position servo `params` gives only in
    /// part (`kp` without `kv`, or `kv` without `kp`), naming the default
    /// that fills the rest: a stiff `kp` behind the default `kv` lags.
    pub fn partial_gain_warnings(&self, params: &PhysicalParams) -> Vec<String> {
        let mut lines = Vec::new();
        for a in &self.scene.actuators {
            let Some(p) = params.joints.get(&a.joint) else {
                continue;
            };
            let (kp, kv) = default_gains(a.force_limit);
            let kp = a.kp.unwrap_or(kp);
            let kv = if a.kv > 0.0 { a.kv } else { kv };
            match (p.kp, p.kv) {
                (Some(given), None) => lines.push(format!(
                    "joints.{}: kp = {given} is given without kv: the scene's kv = {kv} N m s/rad fills it in (its default is kp / 10 of the effort limit's gains); give kv too, or the servo may lag or ring",
                    a.joint
                )),
                (None, Some(given)) => lines.push(format!(
                    "joints.{}: kv = {given} is given without kp: the scene's kp = {kp} N m/rad fills it in (its default: the effort limit over 0.05 rad); give kp too",
                    a.joint
                )),
                _ => {}
            }
        }
        lines
    }

    /// The one line that says which of the robot's joints are held still
    /// because the recording does not name them, when any is.
    pub fn held_warning(&self) -> Option<String> {
        if self.held.is_empty() {
            return None;
        }
        let held: Vec<String> = self
            .held
            .iter()
            .map(|(n, v)| format!("{n} at {v}"))
            .collect();
        Some(format!(
            "robot '{}' has moving joints the recordings do not name, held still: {} (rad or m; set at import with --hold)",
            self.robot.name,
            held.join(", ")
        ))
    }

    /// The robot's joints the replay drives, in the scene's actuator
    /// order: every moving joint for the generated scene, the controlled
    /// joints of a scene of the user's.
    pub fn replayed_joints(&self) -> Vec<usize> {
        self.scene
            .controlled_joints()
            .iter()
            .filter_map(|name| self.robot.joint_by_name(name))
            .collect()
    }

    /// World poses of `link` for rows of the replayed joints' angles (rad):
    /// forward kinematics from the scene's base, its held joints at their
    /// angles.
    pub fn link_poses(&self, rows: &[Vec<f64>], link: usize) -> Vec<Option<Pose>> {
        let mut full = vec![0.0; self.robot.joints.len()];
        for (name, &a) in &self.scene.robot.held_joints_rad {
            if let Some(j) = self.robot.joint_by_name(name) {
                full[j] = a;
            }
        }
        let joints = self.replayed_joints();
        rows.iter()
            .map(|row| {
                for (&j, &q) in joints.iter().zip(row) {
                    full[j] = q;
                }
                self.robot.link_pose(&self.scene.robot.base, &full, link)
            })
            .collect()
    }
}

/// The TOML of the generated replay scene.
pub fn scene_toml(
    robot: &RobotModel,
    urdf: &Path,
    link: &str,
    duration_s: f64,
    held: &BTreeMap<String, f64>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# The scene of `realitygap replay`: robot {} ({}), every moving joint\n\
         # servoed, the end effector {link} tracked. Gains: kv is the servo's\n\
         # velocity gain (N m s/rad) and kp the position gain of its PD law\n\
         # for position commands (N m/rad): defaults from each joint's effort\n\
         # limit; joints.<joint>.kp and .kv in --params replace them.",
        robot.name,
        urdf.display()
    );
    let _ = writeln!(s, "name = \"replay\"");
    let _ = writeln!(
        s,
        "description = \"Replay of recorded joint commands on {}\"",
        robot.name
    );
    let _ = writeln!(s, "duration_s = {duration_s:?}\n");
    let _ = writeln!(
        s,
        "[robot]\nurdf = {:?}\nbase_position_m = [0.0, 0.0, 0.0]\nbase_rpy_deg = [0.0, 0.0, 0.0]\n",
        urdf.display().to_string()
    );
    if !held.is_empty() {
        let _ = writeln!(
            s,
            "# The robot's moving joints the recording does not name, held still.\n[robot.held_joints_deg]"
        );
        for (name, rad) in held {
            let _ = writeln!(s, "{name:?} = {:?}", rad.to_degrees());
        }
        s.push('\n');
    }
    let _ = writeln!(s, "# Unused by a replay (the recorded commands drive the servos).\n[controller]\ngain_per_s = 1.0\nmax_speed_deg_s = 1.0\nperiod_s = {TIMESTEP_S:?}\n");
    for &j in &robot.actuated_joints() {
        let joint = &robot.joints[j];
        if held.contains_key(&joint.name) {
            continue;
        }
        let effort = joint.limits.as_ref().map_or(0.0, |l| l.effort);
        let force = if effort.is_finite() && effort > 0.0 {
            effort
        } else {
            1e6
        };
        let (kp, kv) = default_gains(force);
        let _ = writeln!(
            s,
            "[[actuator]]\njoint = {:?}\nkv = {kv:?}\nkp = {kp:?}\nforce_limit = {force:?}\n",
            joint.name
        );
    }
    let _ = writeln!(s, "[[schedule]]\nt_s = 0.0\ntargets_deg = {{}}\n");
    let _ = writeln!(s, "[[track]]\nrole = \"wrist\"\nlink = {link:?}\n");
    // The linked engines, then every built-in adapter out of process
    // (every engine has `timestep_s`): mujoco4 with MuJoCo's settings.
    let adapters = realitygap_engine_remote::registry::ADAPTERS
        .iter()
        .map(|a| a.name);
    for engine in realitygap_core::engine::LINKED_ENGINES
        .iter()
        .copied()
        .chain(adapters)
    {
        let _ = writeln!(s, "[engine.{engine}]\ntimestep_s = {TIMESTEP_S:?}");
        match engine {
            // Implicit servo damping: stiff gains at 1 ms stay stable. The
            // links do not collide with each other, as in Bullet, ODE and
            // DART: the recorded arm did not, and a URDF's collision meshes
            // of non-adjacent links may overlap.
            "mujoco" | "mujoco4" => {
                let _ = writeln!(s, "integrator = \"implicitfast\"\nself_collision = false");
            }
            // The kv servo (motor CFM = 1/kv), so that kv and the PD law hold;
            // ODE's default motor is stiff and has no gain.
            "ode" => {
                let _ = writeln!(s, "servo = \"kv\"");
            }
            // No self-collision, as MuJoCo above (Bullet, ODE and DART have
            // none by default; Drake's and Newton's adapters do).
            "rapier" | "physx" | "drake" | "newton" => {
                let _ = writeln!(s, "self_collision = false");
            }
            _ => {}
        }
        s.push('\n');
    }
    s
}

/// Reads the episodes and the robot, and writes or reads the scene.
pub fn prepare_replay(req: &ReplayRequest) -> Result<Prepared> {
    let store = RunStore::open(req.real_dir).with_context(|| {
        format!(
            "reading the recorded episodes in {}",
            req.real_dir.display()
        )
    })?;
    let settings = &store.manifest().settings;
    let urdf: PathBuf = match req.urdf {
        Some(u) => u.to_path_buf(),
        None => settings
            .get("urdf")
            .and_then(Value::as_str)
            .map(PathBuf::from)
            .ok_or_else(|| {
                anyhow!(
                    "{}: the manifest names no URDF (not an import of joint recordings?): give --robot",
                    req.real_dir.display()
                )
            })?,
    };
    let resolver = realitygap_runner::prepare::resolver(req.packages)?;
    let robot = RobotModel::from_urdf_file(&urdf, &resolver)?;
    let recorded: Vec<String> = settings
        .get("joints")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    // The joints replayed: the user's scene's controlled joints (the rest
    // of the robot held as the scene says), else every moving joint.
    let user_scene = match req.scene {
        Some(path) => Some(Scene::from_file(path)?),
        None => None,
    };
    // The robot's moving joints the recording does not name are held:
    // where the import held them, else at 0.
    let mut held: BTreeMap<String, f64> = settings
        .get("held_joints")
        .and_then(Value::as_object)
        .map(|m| {
            m.iter()
                .filter_map(|(k, v)| v.as_f64().map(|v| (k.clone(), v)))
                .collect()
        })
        .unwrap_or_default();
    if user_scene.is_none() && !recorded.is_empty() {
        for &j in &robot.actuated_joints() {
            let name = &robot.joints[j].name;
            if !recorded.contains(name) {
                held.entry(name.clone()).or_insert(0.0);
            }
        }
        held.retain(|name, _| {
            robot
                .joint_by_name(name)
                .is_some_and(|j| robot.joints[j].kind.is_movable())
                && !recorded.contains(name)
        });
    } else {
        held.clear();
    }
    let moving: Vec<String> = match &user_scene {
        Some(s) => s
            .controlled_joints()
            .iter()
            .map(|j| j.to_string())
            .collect(),
        None => robot
            .actuated_joints()
            .iter()
            .map(|&j| robot.joints[j].name.clone())
            .filter(|n| !held.contains_key(n))
            .collect(),
    };
    if !recorded.is_empty() && recorded != moving {
        bail!(
            "{}: the episodes are of the joints {}, {} {}",
            req.real_dir.display(),
            recorded.join(", "),
            match req.scene {
                Some(p) => format!("the scene {} controls the joints", p.display()),
                None => format!(
                    "robot '{}' ({}) has the moving joints",
                    robot.name,
                    urdf.display()
                ),
            },
            moving.join(", ")
        );
    }
    let link = settings
        .get("end_effector_link")
        .and_then(Value::as_str)
        .map(String::from)
        .unwrap_or_else(|| {
            robot.links[robot.joints[*robot.actuated_joints().last().unwrap_or(&0)].child]
                .name
                .clone()
        });
    let mut episodes = Vec::new();
    for run in store.runs() {
        if run.status != StoredStatus::Ok {
            continue;
        }
        let real = store.read_run(&run.id)?;
        if real.commands.is_none() {
            bail!(
                "{}: run '{}' has no recorded commands to replay (import it with its command topic or columns)",
                req.real_dir.display(),
                run.id
            );
        }
        if real.joint_count() != moving.len() {
            bail!(
                "{}: run '{}' has {} joints, robot '{}' (or the scene) {}",
                req.real_dir.display(),
                run.id,
                real.joint_count(),
                robot.name,
                moving.len()
            );
        }
        episodes.push(Episode {
            id: run.id.clone(),
            real,
        });
    }
    if episodes.is_empty() {
        bail!("{}: no recorded episode to replay", req.real_dir.display());
    }
    let duration = episodes
        .iter()
        .map(|e| e.real.time_s.last().copied().unwrap_or(0.0))
        .fold(0.0, f64::max);
    let duration_s = ((duration / TIMESTEP_S).ceil().max(1.0)) * TIMESTEP_S;
    std::fs::create_dir_all(req.out).with_context(|| format!("creating {}", req.out.display()))?;
    let absolute = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let abs_urdf = absolute(&urdf);
    let (scene, scene_file) = match (req.scene, user_scene) {
        (Some(path), Some(scene)) => (scene, absolute(path)),
        _ => {
            let text = scene_toml(&robot, &abs_urdf, &link, duration_s, &held);
            let path = req.out.join(SCENE_FILE);
            std::fs::write(&path, &text).with_context(|| format!("writing {}", path.display()))?;
            (Scene::from_toml_str(&text, &path)?, absolute(&path))
        }
    };
    scene.validate(&robot)?;
    // A joint without a position gain (a scene of the user's) gets the
    // default one: joints without a command hold their first angle
    // through the PD servo.
    let mut scene = scene;
    fill_default_gains(&mut scene);
    let mut prepared = Prepared {
        robot,
        scene,
        episodes: Vec::new(),
        link,
        scene_file,
        urdf: abs_urdf,
        packages: req.packages.to_vec(),
        real_dir: absolute(req.real_dir),
        held,
    };
    // The recorded end effector by forward kinematics of the recorded
    // angles in the scene's world (a motion capture's own bodies are in
    // the capture's frame).
    let link_index = prepared.robot.link_by_name(&prepared.link);
    for mut e in episodes {
        if let (Some(l), Some(q)) = (link_index, &e.real.joint_angles_rad) {
            let poses = prepared.link_poses(q, l);
            e.real.bodies = vec![BodyTrack {
                role: WRIST.into(),
                poses,
            }];
        }
        prepared.episodes.push(e);
    }
    // The parameters' names (joints, links, objects) against this robot
    // and scene, once, before anything runs: every replay would fail alike.
    req.params.apply(&prepared.scene, &prepared.robot)?;
    Ok(prepared)
}

/// The replay plan of one episode in `scene` (its actuators carrying
/// `params` and a position gain) with `params`.
pub fn plan_for(episode: &Episode, scene: &Scene, params: &PhysicalParams) -> Result<ReplayPlan> {
    ReplayPlan::for_recording(&episode.real, scene, params)
        .map_err(|e| anyhow!("run '{}': {e}", episode.id))
}

/// The physics-free model of an episode: the commands with perfect tracking
/// through forward kinematics (`None` for effort commands).
pub fn kinematic_run(
    episode: &Episode,
    prepared: &Prepared,
    link: usize,
    delay_s: f64,
) -> Option<Trajectory> {
    let real = &episode.real;
    let commands = real.commands.as_ref()?;
    let first = real.joint_angles_rad.as_ref()?.first()?;
    let angles = kinematic_angles(commands, first, &real.time_s, delay_s)?;
    let poses = prepared.link_poses(&angles, link);
    Some(Trajectory {
        time_s: real.time_s.clone(),
        bodies: vec![BodyTrack {
            role: WRIST.into(),
            poses,
        }],
        joint_angles_rad: Some(angles),
        ..Trajectory::default()
    })
}

/// The outcome of one replayed episode in one engine.
pub struct Replayed {
    /// The run id (the episode's).
    pub id: String,
    /// The engine's name.
    pub engine: String,
    /// What happened: the trajectory stored, or why not.
    pub result: Result<(Trajectory, RunStatus, f64), String>,
    /// True when the run was already stored (not simulated again).
    pub reused: bool,
}

/// Replays one episode in one engine.
pub fn replay_one(
    engine: &dyn Engine,
    prepared: &Prepared,
    episode: &Episode,
    params: &PhysicalParams,
) -> Result<(Trajectory, RunStatus, f64), String> {
    let options = RunOptions::default();
    let (scene, robot) =
        prepare(engine, &prepared.scene, &prepared.robot, params).map_err(|e| e.to_string())?;
    // The scene's settings with the parameters' `[engine.NAME]` over them,
    // as `replay --params` runs them.
    let settings = params.settings_over(engine.name(), &scene.settings_for(engine.name()));
    let mut sim = load_prepared(engine, &scene, &robot, &settings, params, &options)
        .map_err(|e| e.to_string())?;
    refuse_unstable(engine, sim.as_ref(), &options).map_err(|e| e.to_string())?;
    let plan = plan_for(episode, &scene, params).map_err(|e| e.to_string())?;
    let outcome = replay(sim.as_mut(), &plan).map_err(|e| e.to_string())?;
    Ok((outcome.trajectory, outcome.status, outcome.wall_time_s))
}

/// Stores one replayed run in `OUT/<engine>/`.
pub fn store_replayed(out: &Path, engine: &dyn Engine, run: &Replayed) -> Result<()> {
    let dir = out.join(engine.name());
    let mut store =
        RunStore::create_or_open(&dir, engine.name(), SourceKind::Simulated, Some("replay"))?;
    store.set_engine(EngineInfo {
        name: engine.name().to_string(),
        version: engine.version(),
    })?;
    let mut entry = RunEntry::new(&run.id);
    match &run.result {
        Ok((trajectory, status, wall)) => {
            entry.wall_time_s = Some(*wall);
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
    Ok(())
}

/// Stores the physics-free runs in `OUT/ideal/`.
pub fn store_kinematic(out: &Path, prepared: &Prepared, delay_s: f64) -> Result<usize> {
    let link = prepared
        .robot
        .link_by_name(&prepared.link)
        .ok_or_else(|| anyhow!("robot has no link {}", prepared.link))?;
    let mut store = RunStore::create_or_open(
        &out.join(KINEMATIC),
        KINEMATIC,
        SourceKind::Simulated,
        Some("replay"),
    )?;
    store.set_settings(json!({"model": "the recorded commands with perfect tracking, through forward kinematics", "delay_s": delay_s}))?;
    let mut count = 0;
    for e in &prepared.episodes {
        if let Some(t) = kinematic_run(e, prepared, link, delay_s) {
            store.write_run(RunEntry::new(&e.id), &t)?;
            count += 1;
        }
    }
    Ok(count)
}

/// Joint-space errors of one source against the recordings.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointSpaceRow {
    /// Source name (an engine, or `ideal`: the physics-free model).
    pub source: String,
    /// Episodes compared.
    pub episodes: usize,
    /// Per joint: RMS angle error over every sample of every episode, deg.
    pub rms_deg: Vec<f64>,
    /// Per joint: largest absolute angle error, deg.
    pub max_deg: Vec<f64>,
    /// Per joint: the accumulated error, the absolute angle error summed
    /// over the samples of an episode, averaged over the episodes, deg.
    pub accumulated_deg: Vec<f64>,
    /// RMS over all joints and samples, deg.
    pub rms_all_deg: f64,
    /// The per-episode all-joint RMS, smallest and largest, deg.
    pub episode_range_deg: (f64, f64),
    /// RMS end-effector position error, mm.
    pub end_effector_rms_mm: f64,
    /// Per joint: the tracking delay against the recording, ms: the shift
    /// of the source's angles (whole samples, within ±`MAX_DELAY_S`) that
    /// fits the recorded angles best; positive when the source lags.
    pub delay_ms: Vec<f64>,
}

/// The largest tracking delay looked for, s.
pub const MAX_DELAY_S: f64 = 0.2;

/// Accumulates, per joint and per shift of `sim` against `real` (in whole
/// samples, `-max_shift..=max_shift`), the squared angle differences and
/// their count: `costs[j][shift + max_shift]`.
fn add_shift_costs(
    real: &[Vec<f64>],
    sim: &[Vec<f64>],
    max_shift: usize,
    costs: &mut [Vec<(f64, usize)>],
) {
    let len = real.len().min(sim.len());
    for (j, cost) in costs.iter_mut().enumerate() {
        for (k, slot) in cost.iter_mut().enumerate() {
            let shift = k as isize - max_shift as isize;
            // The source lags by `shift` samples: sim[i + shift] ~ real[i].
            for (i, real_row) in real.iter().enumerate().take(len) {
                let t = i as isize + shift;
                if t < 0 || t >= len as isize {
                    continue;
                }
                let d = sim[t as usize][j] - real_row[j];
                slot.0 += d * d;
                slot.1 += 1;
            }
        }
    }
}

/// The joint-space comparison of `runs` (episode id -> trajectory) with the
/// recordings; `None` when no episode was comparable.
pub fn joint_space_row(
    source: &str,
    prepared: &Prepared,
    runs: &[(String, Trajectory)],
) -> Option<JointSpaceRow> {
    let joints = prepared.replayed_joints().len();
    let mut sum = vec![0.0; joints];
    let mut abs_sum = vec![0.0; joints];
    let mut max = vec![0.0f64; joints];
    let mut n = 0usize;
    let mut ee_sum = 0.0;
    let mut ee_n = 0usize;
    let mut per_episode = Vec::new();
    let spacing = prepared
        .episodes
        .first()
        .and_then(|e| {
            let t = &e.real.time_s;
            (t.len() > 1).then(|| (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64)
        })
        .filter(|s| *s > 0.0)
        .unwrap_or(1.0);
    let max_shift = (MAX_DELAY_S / spacing).round() as usize;
    let mut costs = vec![vec![(0.0, 0usize); 2 * max_shift + 1]; joints];
    for (id, sim) in runs {
        let Some(e) = prepared.episodes.iter().find(|e| &e.id == id) else {
            continue;
        };
        let (Some(real_q), Some(sim_q)) = (&e.real.joint_angles_rad, &sim.joint_angles_rad) else {
            continue;
        };
        let len = real_q.len().min(sim_q.len());
        if len == 0 {
            continue;
        }
        let mut ep_sum = 0.0;
        for i in 0..len {
            for j in 0..joints {
                let d = (sim_q[i][j] - real_q[i][j]).to_degrees();
                sum[j] += d * d;
                abs_sum[j] += d.abs();
                ep_sum += d * d;
                max[j] = max[j].max(d.abs());
            }
            let real_p = e.real.bodies.first().and_then(|b| b.poses[i]);
            let sim_p = sim
                .bodies
                .first()
                .and_then(|b| b.poses.get(i).copied().flatten());
            if let (Some(a), Some(b)) = (real_p, sim_p) {
                let d = a.position_m - b.position_m;
                ee_sum += d.dot(d);
                ee_n += 1;
            }
        }
        n += len;
        per_episode.push((ep_sum / (len * joints) as f64).sqrt());
        add_shift_costs(&real_q[..len], &sim_q[..len], max_shift, &mut costs);
    }
    if n == 0 {
        return None;
    }
    let rms_deg: Vec<f64> = sum.iter().map(|s| (s / n as f64).sqrt()).collect();
    let rms_all_deg = (sum.iter().sum::<f64>() / (n * joints) as f64).sqrt();
    let lo = per_episode.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = per_episode.iter().copied().fold(0.0, f64::max);
    Some(JointSpaceRow {
        source: source.to_string(),
        episodes: per_episode.len(),
        rms_deg,
        max_deg: max,
        accumulated_deg: abs_sum
            .iter()
            .map(|s| s / per_episode.len() as f64)
            .collect(),
        rms_all_deg,
        episode_range_deg: (lo, hi),
        end_effector_rms_mm: if ee_n > 0 {
            (ee_sum / ee_n as f64).sqrt() * 1e3
        } else {
            f64::NAN
        },
        delay_ms: costs
            .iter()
            .map(|c| {
                let mean = |k: usize| c[k].0 / c[k].1 as f64;
                let best = (0..c.len())
                    .filter(|&k| c[k].1 > 0)
                    .min_by(|&a, &b| mean(a).total_cmp(&mean(b)))
                    .unwrap_or(max_shift);
                (best as f64 - max_shift as f64) * spacing * 1e3
            })
            .collect(),
    })
}

/// The joint-space table as Markdown.
pub fn joint_space_markdown(rows: &[JointSpaceRow], joint_names: &[String]) -> String {
    let mut s = String::from("| source | episodes | RMS all joints (deg) | per-episode range (deg) | end effector RMS (mm) | delay per joint (ms) |");
    for j in joint_names {
        let _ = write!(s, " {j} RMS (deg) |");
    }
    s.push('\n');
    s.push_str("|---|---:|---:|---:|---:|---|");
    for _ in joint_names {
        s.push_str("---:|");
    }
    s.push('\n');
    for r in rows {
        let _ = write!(
            s,
            "| {} | {} | {:.3} | [{:.3}, {:.3}] | {:.2} | {} |",
            r.source,
            r.episodes,
            r.rms_all_deg,
            r.episode_range_deg.0,
            r.episode_range_deg.1,
            r.end_effector_rms_mm,
            r.delay_ms
                .iter()
                .map(|d| format!("{d:.0}"))
                .collect::<Vec<_>>()
                .join(" / ")
        );
        for x in &r.rms_deg {
            let _ = write!(s, " {x:.3} |");
        }
        s.push('\n');
    }
    s
}

/// Writes `OUT/replay.json`: the recordings' folder, the URDF and the ROS
/// packages, as absolute paths.
pub fn write_record(req: &ReplayRequest, prepared: &Prepared) -> Result<()> {
    let abs = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let record = json!({
        "recordings": abs(req.real_dir),
        "urdf": abs(&prepared.robot.source),
        "scene": prepared.scene_file,
        "packages": req.packages,
        "link": prepared.link,
    });
    let path = req.out.join(RECORD_FILE);
    std::fs::write(&path, serde_json::to_string_pretty(&record)? + "\n")
        .with_context(|| format!("writing {}", path.display()))
}

/// The joint-space comparison of a replay's output folder (`OUT` of
/// `realitygap replay`): every results directory in it (the engines and
/// the physics-free model) against the recordings, with the end effector
/// taken as `link` (default: the replay's); the rows, the joint names and
/// the link measured.
pub fn compare_replay(
    dir: &Path,
    link: Option<&str>,
) -> Result<(Vec<JointSpaceRow>, Vec<String>, String)> {
    let record_path = dir.join(RECORD_FILE);
    let text = std::fs::read_to_string(&record_path).with_context(|| {
        format!(
            "{}: not the output of `realitygap replay` (no {RECORD_FILE})",
            dir.display()
        )
    })?;
    let record: Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", record_path.display()))?;
    let field = |k: &str| -> Result<PathBuf> {
        record
            .get(k)
            .and_then(Value::as_str)
            .map(PathBuf::from)
            .ok_or_else(|| anyhow!("{}: no \"{k}\"", record_path.display()))
    };
    let packages: Vec<String> = record
        .get("packages")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    let real_dir = field("recordings")?;
    let urdf = field("urdf")?;
    // The replay's scene: the one it recorded (a scene of the user's),
    // else the generated one in the folder.
    let scene = record
        .get("scene")
        .and_then(Value::as_str)
        .map(PathBuf::from)
        .filter(|p| p.is_file())
        .unwrap_or_else(|| dir.join(SCENE_FILE));
    let params = PhysicalParams::none();
    let mut prepared = prepare_replay(&ReplayRequest {
        real_dir: &real_dir,
        urdf: Some(&urdf),
        packages: &packages,
        params: &params,
        scene: scene.is_file().then_some(scene.as_path()),
        out: dir,
    })?;
    let link_name = link
        .map(String::from)
        .unwrap_or_else(|| prepared.link.clone());
    let link_index = prepared.robot.link_by_name(&link_name).ok_or_else(|| {
        anyhow!(
            "--link {link_name}: robot '{}' has no such link (its links: {})",
            prepared.robot.name,
            prepared
                .robot
                .links
                .iter()
                .map(|l| l.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    })?;
    let with_link = |t: &mut Trajectory, prepared: &Prepared| {
        if let Some(q) = &t.joint_angles_rad {
            t.bodies = vec![BodyTrack {
                role: WRIST.into(),
                poses: prepared.link_poses(q, link_index),
            }];
        }
    };
    let mut episodes = std::mem::take(&mut prepared.episodes);
    for e in &mut episodes {
        with_link(&mut e.real, &prepared);
    }
    prepared.episodes = episodes;
    prepared.link = link_name;
    let mut sources: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("manifest.json").is_file())
        .collect();
    sources.sort();
    // The physics-free model first, as replay prints it.
    sources.sort_by_key(|p| p.file_name().map(|n| n != KINEMATIC));
    let mut rows = Vec::new();
    for source in sources {
        let store = RunStore::open(&source)?;
        let mut runs = Vec::new();
        for r in store.runs() {
            if r.status != StoredStatus::Ok {
                continue;
            }
            let mut t = store.read_run(&r.id)?;
            with_link(&mut t, &prepared);
            runs.push((r.id.clone(), t));
        }
        let name = source
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        rows.extend(joint_space_row(&name, &prepared, &runs));
    }
    let names = prepared
        .replayed_joints()
        .iter()
        .map(|&j| prepared.robot.joints[j].name.clone())
        .collect();
    Ok((rows, names, prepared.link))
}

/// The joint-space table as CSV: one row per source and joint.
pub fn joint_space_csv(rows: &[JointSpaceRow], joint_names: &[String]) -> String {
    let mut s = String::from(
        "source,joint,episodes,rms_deg,max_deg,accumulated_deg,delay_ms,end_effector_rms_mm\n",
    );
    for r in rows {
        for (j, name) in joint_names.iter().enumerate() {
            let _ = writeln!(
                s,
                "{},{},{},{:?},{:?},{:?},{:?},{:?}",
                realitygap_analysis::table::csv_field(&r.source),
                realitygap_analysis::table::csv_field(name),
                r.episodes,
                r.rms_deg[j],
                r.max_deg[j],
                r.accumulated_deg[j],
                r.delay_ms[j],
                r.end_effector_rms_mm
            );
        }
    }
    s
}

/// The joint-space rows as JSON: per source, per joint by name.
pub fn joint_space_json(rows: &[JointSpaceRow], joint_names: &[String], link: &str) -> Value {
    json!({
        "end_effector_link": link,
        "sources": rows.iter().map(|r| json!({
            "source": r.source,
            "episodes": r.episodes,
            "rms_all_deg": r.rms_all_deg,
            "episode_range_deg": [r.episode_range_deg.0, r.episode_range_deg.1],
            "end_effector_rms_mm": r.end_effector_rms_mm,
            "joints": joint_names.iter().enumerate().map(|(j, n)| json!({
                "joint": n,
                "rms_deg": r.rms_deg[j],
                "max_deg": r.max_deg[j],
                "accumulated_deg": r.accumulated_deg[j],
                "delay_ms": r.delay_ms[j],
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    })
}

/// The report's figures: per moving joint, the first episode's recorded
/// angle and each source's (`sources`: name, runs by episode id), degrees.
pub fn joint_figures(
    prepared: &Prepared,
    sources: &[(String, Vec<(String, Trajectory)>)],
) -> Vec<realitygap_report::joint_space::JointFigure> {
    use realitygap_report::joint_space::{AngleSeries, JointFigure};
    let Some(episode) = prepared.episodes.first() else {
        return Vec::new();
    };
    let series = |source: &str, t: &Trajectory, j: usize| -> Option<AngleSeries> {
        let q = t.joint_angles_rad.as_ref()?;
        Some(AngleSeries {
            source: source.to_string(),
            points: t
                .time_s
                .iter()
                .zip(q)
                .filter_map(|(&time, row)| row.get(j).map(|a| (time, a.to_degrees())))
                .collect(),
        })
    };
    prepared
        .replayed_joints()
        .iter()
        .enumerate()
        .map(|(j, &ji)| {
            let mut all: Vec<AngleSeries> =
                series("recorded", &episode.real, j).into_iter().collect();
            for (name, runs) in sources {
                if let Some((_, t)) = runs.iter().find(|(id, _)| id == &episode.id) {
                    all.extend(series(name, t, j));
                }
            }
            JointFigure {
                joint: prepared.robot.joints[ji].name.clone(),
                episode: episode.id.clone(),
                series: all,
            }
        })
        .collect()
}

/// Replays every episode in every engine, in parallel over the machine's
/// cores, storing each run as it finishes (an interrupted batch loses no
/// finished run; a rerun skips runs already stored). `done` is told of
/// Where `replay_all` runs the replays: every one in a child process of
/// `launcher` (the `realitygap` binary's `__run-one`), so that an engine
/// that aborts fails only its run.
pub enum ReplayExecutor<'a> {
    /// Child processes on this machine, `jobs` at a time.
    Local {
        /// How to start a child.
        launcher: &'a Launcher,
        /// Child processes at once (at least 1).
        jobs: usize,
    },
    /// One Slurm job array (`OUT/slurm/`): the results directory must be on
    /// a filesystem the compute nodes share.
    Slurm {
        /// How a task starts the binary.
        launcher: &'a Launcher,
        /// `sbatch` options.
        options: &'a SlurmOptions,
    },
}

/// The child job of one episode in one engine.
fn replay_job(engine: &str, prepared: &Prepared, params: &PhysicalParams, episode: &str) -> Job {
    // A file's parameters travel as the file (its errors name file, line
    // and column); built ones as text.
    let (file, text) = match &params.source {
        Some(f) => (Some(std::fs::canonicalize(f).unwrap_or(f.clone())), None),
        None if *params == PhysicalParams::none() => (None, None),
        None => (None, Some(params.to_toml_string())),
    };
    Job {
        scene_file: prepared.scene_file.clone(),
        engine: engine.to_string(),
        robot: Some(prepared.urdf.display().to_string()),
        packages: prepared.packages.clone(),
        set: Vec::new(),
        perturb: Vec::new(),
        seed: 0,
        params: file,
        params_text: text,
        check_only: false,
        stitch: None,
        allow_unstable: false,
        replay: Some(ReplayJob {
            real_dir: prepared.real_dir.clone(),
            episode: episode.to_string(),
        }),
    }
}

/// What a child's end says of the replayed run.
fn replayed_result(end: ChildEnd) -> Result<(Trajectory, RunStatus, f64), String> {
    match end {
        ChildEnd::Done(r) => {
            let trajectory = r.trajectory().map_err(|e| e.to_string())?;
            let status = match &r.diverged {
                Some((t_s, reason)) => RunStatus::Diverged {
                    t_s: *t_s,
                    reason: reason.clone(),
                },
                None => RunStatus::Completed,
            };
            Ok((trajectory, status, r.wall_time_s))
        }
        ChildEnd::Failed(m) => Err(m),
    }
}

/// Replays every episode in every engine (each in a child process, see
/// [`ReplayExecutor`]), storing each run in `OUT/<engine>/` as it ends; a
/// run already stored is kept (resume). `done` is called for every run.
pub fn replay_all(
    engines: &[Box<dyn Engine>],
    prepared: &Prepared,
    params: &PhysicalParams,
    out: &Path,
    executor: &ReplayExecutor<'_>,
    done: &(dyn Fn(&Replayed) + Sync),
) -> Result<Vec<Replayed>> {
    let mut runs = Vec::new();
    let mut todo: Vec<(usize, usize)> = Vec::new();
    for (e, engine) in engines.iter().enumerate() {
        let store = RunStore::open(&out.join(engine.name())).ok();
        for (k, episode) in prepared.episodes.iter().enumerate() {
            match &store {
                Some(s) if s.has_finished_run(&episode.id) => {
                    let run = Replayed {
                        id: episode.id.clone(),
                        engine: engine.name().to_string(),
                        result: Ok((s.read_run(&episode.id)?, RunStatus::Completed, 0.0)),
                        reused: true,
                    };
                    done(&run);
                    runs.push(run);
                }
                _ => todo.push((e, k)),
            }
        }
    }
    let jobs: Vec<((usize, usize), Job)> = todo
        .iter()
        .map(|&(e, k)| {
            let job = replay_job(
                engines[e].name(),
                prepared,
                params,
                &prepared.episodes[k].id,
            );
            ((e, k), job)
        })
        .collect();
    let finished = std::sync::Mutex::new(Vec::new());
    let mut keep = |(e, k): (usize, usize), end: ChildEnd| -> Result<()> {
        let engine = engines[e].as_ref();
        let run = Replayed {
            id: prepared.episodes[k].id.clone(),
            engine: engine.name().to_string(),
            result: replayed_result(end),
            reused: false,
        };
        // The parent alone writes the results directories, run by run, so
        // that an interrupted batch keeps every finished run.
        let mut f = finished.lock().unwrap_or_else(|p| p.into_inner());
        store_replayed(out, engine, &run)?;
        done(&run);
        f.push(run);
        Ok(())
    };
    match executor {
        ReplayExecutor::Local { launcher, jobs: n } => {
            let queue = std::sync::Mutex::new(jobs.into_iter());
            let keep = std::sync::Mutex::new(&mut keep);
            let errors = std::sync::Mutex::new(Vec::new());
            std::thread::scope(|scope| {
                for _ in 0..(*n).max(1) {
                    scope.spawn(|| loop {
                        let next = queue.lock().unwrap_or_else(|p| p.into_inner()).next();
                        let Some((key, job)) = next else { break };
                        let end = run_child(launcher, &job, None);
                        if realitygap_runner::interrupt::requested() {
                            // Cut short: not stored; the finished runs are.
                            break;
                        }
                        let keep = keep.lock().unwrap_or_else(|p| p.into_inner());
                        if let Err(e) = (*keep)(key, end) {
                            errors.lock().unwrap_or_else(|p| p.into_inner()).push(e);
                            break;
                        }
                    });
                }
            });
            if let Some(e) = errors.into_inner().unwrap_or_default().into_iter().next() {
                return Err(e);
            }
            realitygap_runner::interrupt::check()?;
        }
        ReplayExecutor::Slurm { launcher, options } => {
            if !jobs.is_empty() {
                realitygap_runner::slurm::run_array(
                    jobs,
                    &out.join("slurm"),
                    launcher,
                    options,
                    &mut |key, end, _| keep(key, end),
                )?;
            }
        }
    }
    runs.extend(finished.into_inner().unwrap_or_default());
    Ok(runs)
}
