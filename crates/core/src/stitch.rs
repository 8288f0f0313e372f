//! Stitched runs: one run of a scene whose schedule phases are simulated
//! in different engines, the state handed from one to the next at each
//! phase boundary.
//!
//! A [`StitchPlan`] names one engine per phase of the scene's schedule
//! (phase `i` runs from schedule entry `i`'s time to entry `i + 1`'s);
//! naming fewer engines than phases repeats the last. [`run_stitched`]
//! drives one [`ControllerLoop`] through all of them, so the controller's
//! own state (pending delayed commands, reading noise, targets in force,
//! the samples recorded) carries over untouched. At the boundary tick `k`
//! (the schedule entry's time over the control period, rounded):
//!
//! ```text
//! advance(a, k)                      phase i in engine A, ticks < k
//! s = a.state()
//! b = load(B)                        a fresh simulation of the scene
//! b.set_state(s or its portable part)
//! apply the resting rule             only between different engines
//! advance(b, next boundary)          phase i + 1 in engine B
//! ```
//!
//! **What carries over.** Between two simulations of the same engine the
//! whole state, [`NativeState`](crate::engine::NativeState) included, so
//! the run continues as if never cut (exactly for MuJoCo, Bullet and ODE;
//! Rapier keeps no contact warm starts, see its README). Between different
//! engines only the portable part: joint angles, velocities and servo
//! targets, the objects' poses and twists, the time. What does not carry
//! over (contact caches, solver warm starts, the constraint error of soft
//! joints, the force a stiff motor is exerting) shows in the
//! [`Handover`] measured: the largest difference between what engine A
//! reported and what engine B reports right after loading.
//!
//! **The resting rule.** Engines disagree about contact: a cube at rest on
//! the table sits slightly inside it in an engine with soft contacts
//! (MuJoCo, ODE) and on it or slightly above in another. Loaded as is into
//! an engine with stiff contacts, a cube inside the table is pushed out
//! with a jolt. So, between different engines, an object whose lowest
//! point lies below the ground plane is lifted straight up until that
//! point is on the plane, and the part of its velocity pointing down into
//! the table is removed; its orientation, horizontal position and the rest
//! of its twist are kept. Each change is reported in
//! [`Handover::corrections`]. An object above the plane is left where it
//! is (it falls, as it would). Contacts between the robot and an object are
//! not resolved: the state is loaded as the engine that ran the phase
//! left it.

use crate::controller::{ControlParams, ControllerLoop, RunError, RunOptions, RunOutcome};
use crate::engine::{EngineError, SimState, Simulation};
use crate::pose::{Pose, Vec3};
use crate::scene::{ObjectShape, Scene};
use serde::{Deserialize, Serialize};

/// The word that starts a stitched source's display name.
pub const STITCHED: &str = "stitched";

/// A plan that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid stitch plan \"{spec}\": {message}")]
pub struct PlanError {
    /// The plan as given.
    pub spec: String,
    /// What is wrong and what is accepted.
    pub message: String,
}

/// One engine per phase of a scene's schedule.
///
/// An entry is an engine's name (`mujoco`) or an engine with a physical
/// parameters file of its own (`mujoco@tuned/mujoco.toml`, e.g. the
/// output of a tune), which then replaces the run's parameters file in
/// that engine's phases.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StitchPlan {
    /// The entries as given (at least one, at most one per phase).
    pub engines: Vec<String>,
}

/// The engine of a plan entry (`ENGINE` or `ENGINE@PARAMS`) and its
/// parameters file, if it names one.
pub fn split_entry(entry: &str) -> (&str, Option<&str>) {
    match entry.split_once('@') {
        Some((engine, params)) => (engine.trim(), Some(params.trim())),
        None => (entry.trim(), None),
    }
}

/// A short label of a plan entry for names: `mujoco`, or for an entry
/// with a parameters file `mujoco+<file stem>` (`mujoco+tuned`), made
/// safe for a directory name.
pub fn entry_label(entry: &str) -> String {
    let (engine, params) = split_entry(entry);
    let label = match params {
        Some(p) => {
            let stem = std::path::Path::new(p)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "params".into());
            format!("{engine}+{stem}")
        }
        None => engine.to_string(),
    };
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "_-.+".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

impl StitchPlan {
    /// Parses `E1,E2,...`: names of `known` engines, each optionally
    /// followed by `@PARAMS` (a parameters file for its phases); spaces
    /// around them are ignored. An empty plan, an empty entry, an engine
    /// not in `known` or an empty file after `@` is an error naming the
    /// plan.
    pub fn parse(spec: &str, known: &[String]) -> Result<StitchPlan, PlanError> {
        let err = |message: String| PlanError {
            spec: spec.to_string(),
            message,
        };
        if spec.trim().is_empty() {
            return Err(err(
                "the plan is empty (expected engine names separated by commas, e.g. bullet,bullet,mujoco)".into(),
            ));
        }
        let mut engines = Vec::new();
        for (i, entry) in spec.split(',').map(str::trim).enumerate() {
            let (name, params) = split_entry(entry);
            if name.is_empty() {
                return Err(err(format!("engine {} of the plan is empty", i + 1)));
            }
            if !known.iter().any(|k| k == name) {
                return Err(err(format!(
                    "unknown engine \"{name}\" (compiled in: {})",
                    known.join(", ")
                )));
            }
            if params.is_some_and(str::is_empty) {
                return Err(err(format!(
                    "engine {} of the plan has an empty parameters file after @ (expected ENGINE@FILE)",
                    i + 1
                )));
            }
            engines.push(match params {
                Some(p) => format!("{name}@{p}"),
                None => name.to_string(),
            });
        }
        Ok(StitchPlan { engines })
    }

    /// The engine of each of the `phases` phases: the plan's, the last one
    /// repeated. An error when the plan names more engines than there are
    /// phases (the extra ones would never run) or names none.
    pub fn per_phase(&self, phases: usize) -> Result<Vec<String>, PlanError> {
        let spec = self.engines.join(",");
        let Some(last) = self.engines.last() else {
            return Err(PlanError {
                spec,
                message: "the plan is empty".into(),
            });
        };
        if self.engines.len() > phases {
            return Err(PlanError {
                spec,
                message: format!(
                    "it names {} engines but the scene has {phases} phase{} (one engine per schedule entry)",
                    self.engines.len(),
                    if phases == 1 { "" } else { "s" }
                ),
            });
        }
        let mut v = self.engines.clone();
        v.resize(phases, last.clone());
        Ok(v)
    }

    /// The display name of the source for a scene of `phases` phases, e.g.
    /// `stitched ode>ode>mujoco` (the plan expanded to every phase; an
    /// entry with a parameters file by its [`entry_label`]).
    pub fn display_name(&self, phases: usize) -> Result<String, PlanError> {
        let labels: Vec<String> = self
            .per_phase(phases)?
            .iter()
            .map(|e| entry_label(e))
            .collect();
        Ok(format!("{STITCHED} {}", labels.join(">")))
    }

    /// A directory name for the source: `stitched-ode-ode-mujoco`.
    pub fn dir_name(&self, phases: usize) -> Result<String, PlanError> {
        let labels: Vec<String> = self
            .per_phase(phases)?
            .iter()
            .map(|e| entry_label(e))
            .collect();
        Ok(format!("{STITCHED}-{}", labels.join("-")))
    }
}

/// The phases of `scene`: per schedule entry, the tick it starts at (the
/// first phase always at tick 0) and the tick it ends at (exclusive; the
/// last one at the end of the run).
pub fn phase_ticks(scene: &Scene) -> Vec<(usize, usize)> {
    let samples = scene.sample_count();
    let period = scene.controller.period_s;
    let starts: Vec<usize> = scene
        .schedule
        .iter()
        .enumerate()
        .map(|(i, e)| {
            if i == 0 {
                0
            } else {
                ((e.t_s / period).round().max(0.0) as usize).min(samples)
            }
        })
        .collect();
    let starts = if starts.is_empty() { vec![0] } else { starts };
    (0..starts.len())
        .map(|i| (starts[i], starts.get(i + 1).copied().unwrap_or(samples)))
        .collect()
}

/// What the resting rule changed in one object at a handover.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Correction {
    /// The object's name.
    pub object: String,
    /// The rule applied, in words.
    pub rule: String,
    /// How far it was lifted, m.
    pub lift_m: f64,
    /// The downward velocity removed, m/s (0 when it was not moving down).
    pub removed_down_velocity_m_s: f64,
}

/// One handover between two phases, with the state difference measured
/// across it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Handover {
    /// Time of the handover on the controller's clock (the tick times the
    /// control period), s.
    pub t_s: f64,
    /// The time the engine handing over reported, s (its own sum of
    /// timesteps: MuJoCo's is 13.999999999986 s at 14 s).
    #[serde(default)]
    pub engine_time_s: f64,
    /// The control tick the receiving engine starts at.
    pub tick: usize,
    /// The engine that ran the phase before.
    pub from: String,
    /// The engine that runs the phase after.
    pub to: String,
    /// Whether the whole (native) state was handed over (same engine) or
    /// only its portable part.
    pub native: bool,
    /// Largest joint angle difference between the two engines' states
    /// after loading, rad.
    pub joint_angle_diff_rad: f64,
    /// Largest joint velocity difference, rad/s.
    pub joint_velocity_diff_rad_s: f64,
    /// Largest object position difference (resting-rule lift included), m.
    pub object_position_diff_m: f64,
    /// Largest object linear velocity difference, m/s.
    pub object_velocity_diff_m_s: f64,
    /// Largest difference between the tracked bodies' positions (wrist,
    /// cube) the two engines report, m.
    pub tracked_position_diff_m: f64,
    /// What the resting rule changed.
    pub corrections: Vec<Correction>,
}

/// A stitched run: the run itself and its handovers.
#[derive(Debug, Clone, PartialEq)]
pub struct StitchedRun {
    /// The samples and how the run ended, as for a single engine.
    pub outcome: RunOutcome,
    /// The engine of each phase.
    pub engines: Vec<String>,
    /// One per phase boundary reached (none after a divergence).
    pub handovers: Vec<Handover>,
}

/// Loads a fresh simulation of the scene in the engine named.
pub type Loader<'a> = dyn FnMut(&str) -> Result<Box<dyn Simulation>, RunError> + 'a;

/// Runs `scene` with phase `i` in engine `engines[i]` (one per phase, see
/// [`StitchPlan::per_phase`]), loading each phase's simulation with `load`
/// and handing the state over at every phase boundary (see the module
/// documentation).
pub fn run_stitched(
    scene: &Scene,
    engines: &[String],
    options: &RunOptions,
    control: &ControlParams,
    load: &mut Loader<'_>,
) -> Result<StitchedRun, RunError> {
    let phases = phase_ticks(scene);
    if engines.len() != phases.len() {
        return Err(EngineError::Usage {
            engine: STITCHED.to_string(),
            message: format!(
                "{} engines given for the {} phases of scene {}",
                engines.len(),
                phases.len(),
                scene.name
            ),
        }
        .into());
    }
    let mut run = ControllerLoop::new(scene, options, control);
    let mut sim = load(&engines[0])?;
    run.start(sim.as_mut())?;
    run.advance(sim.as_mut(), phases[0].1)?;
    let mut handovers = Vec::new();
    for (i, &(start, end)) in phases.iter().enumerate().skip(1) {
        if run.is_done() || start >= run.samples() {
            break;
        }
        let mut next = load(&engines[i])?;
        let handover = hand_over(
            scene,
            sim.as_ref(),
            next.as_mut(),
            (&engines[i - 1], &engines[i]),
            start,
        )?;
        handovers.push(handover);
        sim = next;
        run.advance(sim.as_mut(), end)?;
    }
    Ok(StitchedRun {
        outcome: run.finish(),
        engines: engines.to_vec(),
        handovers,
    })
}

/// Hands the state of `a` to `b` (see the module documentation) and
/// measures what changed.
pub fn hand_over(
    scene: &Scene,
    a: &dyn Simulation,
    b: &mut dyn Simulation,
    (from, to): (&str, &str),
    tick: usize,
) -> Result<Handover, RunError> {
    let before = a.state()?;
    let native = from == to;
    let mut corrections = Vec::new();
    let load = if native {
        before.clone()
    } else {
        let mut portable = before.portable();
        corrections = rest_on_ground(scene, &mut portable);
        portable
    };
    b.set_state(&load)?;
    let after = b.state()?;
    let mut pa = vec![Pose::IDENTITY; a.tracked_count()];
    let mut pb = vec![Pose::IDENTITY; b.tracked_count()];
    a.tracked_poses(&mut pa);
    b.tracked_poses(&mut pb);
    Ok(Handover {
        t_s: tick as f64 * scene.controller.period_s,
        engine_time_s: before.time_s,
        tick,
        from: from.to_string(),
        to: to.to_string(),
        native,
        joint_angle_diff_rad: max_diff(&before.joint_angles_rad, &after.joint_angles_rad),
        joint_velocity_diff_rad_s: max_diff(
            &before.joint_velocities_rad_s,
            &after.joint_velocities_rad_s,
        ),
        object_position_diff_m: object_diff(&before, &after, |o| o.pose.position_m),
        object_velocity_diff_m_s: object_diff(&before, &after, |o| o.linear_velocity_m_s),
        tracked_position_diff_m: pa
            .iter()
            .zip(&pb)
            .map(|(p, q)| p.position_m.distance(q.position_m))
            .fold(0.0, f64::max),
        corrections,
    })
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn object_diff(a: &SimState, b: &SimState, f: impl Fn(&crate::engine::ObjectState) -> Vec3) -> f64 {
    a.objects
        .iter()
        .zip(&b.objects)
        .map(|(x, y)| f(x).distance(f(y)))
        .fold(0.0, f64::max)
}

/// The height of the lowest point of `shape` at `pose`, m.
pub fn lowest_point_m(shape: &ObjectShape, pose: &Pose) -> f64 {
    match shape {
        ObjectShape::Box { size_m } => {
            let r = pose.orientation.to_rotation_matrix();
            // Row 2 of the rotation: the world z of each body axis.
            let reach = r[6].abs() * size_m.x / 2.0
                + r[7].abs() * size_m.y / 2.0
                + r[8].abs() * size_m.z / 2.0;
            pose.position_m.z - reach
        }
    }
}

/// The resting rule (see the module documentation): lifts every object of
/// `state` whose lowest point is below the scene's ground onto it and
/// removes its velocity into the ground; what it changed, per object.
pub fn rest_on_ground(scene: &Scene, state: &mut SimState) -> Vec<Correction> {
    let Some(ground) = scene.ground else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for o in &mut state.objects {
        let Some(spec) = scene.object(&o.name) else {
            continue;
        };
        let depth = ground.height_m - lowest_point_m(&spec.shape, &o.pose);
        if depth <= 0.0 {
            continue;
        }
        o.pose.position_m.z += depth;
        let down = (-o.linear_velocity_m_s.z).max(0.0);
        o.linear_velocity_m_s.z += down;
        out.push(Correction {
            object: o.name.clone(),
            rule: "lowest point below the ground: lifted onto it, downward velocity removed".into(),
            lift_m: depth,
            removed_down_velocity_m_s: down,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::ObjectState;
    use crate::pose::Quat;

    fn known() -> Vec<String> {
        ["mujoco", "bullet", "ode"].map(String::from).to_vec()
    }

    #[test]
    fn plans_parse_expand_and_name_themselves() {
        let p = StitchPlan::parse(" ode, mujoco ", &known()).unwrap();
        assert_eq!(p.per_phase(3).unwrap(), ["ode", "mujoco", "mujoco"]);
        assert_eq!(p.display_name(3).unwrap(), "stitched ode>mujoco>mujoco");
        assert_eq!(p.dir_name(3).unwrap(), "stitched-ode-mujoco-mujoco");
        let e = p.per_phase(1).unwrap_err().to_string();
        assert_eq!(
            e,
            "invalid stitch plan \"ode,mujoco\": it names 2 engines but the scene has 1 phase (one engine per schedule entry)"
        );
        let e = StitchPlan::parse("", &known()).unwrap_err().to_string();
        assert!(e.contains("the plan is empty"), "{e}");
        let e = StitchPlan::parse("ode,,mujoco", &known())
            .unwrap_err()
            .to_string();
        assert!(e.contains("engine 2 of the plan is empty"), "{e}");
        let tuned = StitchPlan::parse("ode, mujoco@ out/tuned mujoco.toml", &known()).unwrap();
        assert_eq!(tuned.engines, ["ode", "mujoco@out/tuned mujoco.toml"]);
        assert_eq!(
            split_entry(&tuned.engines[1]),
            ("mujoco", Some("out/tuned mujoco.toml"))
        );
        assert_eq!(
            tuned.display_name(3).unwrap(),
            "stitched ode>mujoco+tuned_mujoco>mujoco+tuned_mujoco"
        );
        assert_eq!(
            tuned.dir_name(2).unwrap(),
            "stitched-ode-mujoco+tuned_mujoco"
        );
        let e = StitchPlan::parse("ode,mujoco@", &known())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("engine 2 of the plan has an empty parameters file"),
            "{e}"
        );
        let e = StitchPlan::parse("ode,vortex", &known())
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "invalid stitch plan \"ode,vortex\": unknown engine \"vortex\" (compiled in: mujoco, bullet, ode)"
        );
    }

    #[test]
    fn phases_start_at_the_schedule_entries() {
        let scene = crate::testing::scene("scene3_cube_push");
        assert_eq!(phase_ticks(&scene), [(0, 160), (160, 280), (280, 400)]);
        let scene = crate::testing::scene("scene1_single_joint");
        assert_eq!(phase_ticks(&scene), [(0, 120)]);
    }

    /// A perfect velocity servo in 6 joints; the wrist is at (q1, q2, 0),
    /// the cube rests `sunk_m` inside the table; NaN from `blow_up_s` on.
    struct Toy {
        name: &'static str,
        t: f64,
        q: Vec<f64>,
        v: Vec<f64>,
        cube: Pose,
        blow_up_s: Option<f64>,
    }

    impl Toy {
        fn new(name: &'static str, sunk_m: f64) -> Toy {
            Toy {
                name,
                t: 0.0,
                q: vec![0.0; 6],
                v: vec![0.0; 6],
                cube: Pose::new(Vec3::new(0.5, 0.0, 0.0375 - sunk_m), Quat::IDENTITY),
                blow_up_s: None,
            }
        }
    }

    impl Simulation for Toy {
        fn timestep_s(&self) -> f64 {
            0.01
        }
        fn time_s(&self) -> f64 {
            self.t
        }
        fn joint_count(&self) -> usize {
            6
        }
        fn tracked_count(&self) -> usize {
            2
        }
        fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
            self.q.copy_from_slice(rad);
            Ok(())
        }
        fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
            self.v.copy_from_slice(rad_s);
        }
        fn set_joint_commands(
            &mut self,
            commands: &[crate::engine::ServoCommand],
        ) -> Result<(), EngineError> {
            // A perfect velocity servo takes velocity commands only.
            for (v, c) in self.v.iter_mut().zip(commands) {
                if c.kind != crate::trajectory::CommandKind::Velocity {
                    return Err(EngineError::Usage {
                        engine: "toy".into(),
                        message: "velocity commands only".into(),
                    });
                }
                *v = c.value;
            }
            Ok(())
        }
        fn step(&mut self) -> Result<(), EngineError> {
            for (q, v) in self.q.iter_mut().zip(&self.v) {
                *q += v * 0.01;
            }
            self.t += 0.01;
            if self.blow_up_s.is_some_and(|t| self.t >= t) {
                self.q[0] = f64::NAN;
            }
            Ok(())
        }
        fn joint_angles_rad(&self, out: &mut [f64]) {
            out.copy_from_slice(&self.q);
        }
        fn tracked_poses(&self, out: &mut [Pose]) {
            out[0] = Pose::new(Vec3::new(self.q[0], self.q[1], 0.0), Quat::IDENTITY);
            out[1] = self.cube;
        }
        fn state(&self) -> Result<SimState, EngineError> {
            Ok(SimState {
                time_s: self.t,
                joint_angles_rad: self.q.clone(),
                joint_velocities_rad_s: self.v.clone(),
                joint_velocity_targets_rad_s: self.v.clone(),
                servo_commands: vec![],
                objects: vec![ObjectState {
                    name: "cube".into(),
                    pose: self.cube,
                    linear_velocity_m_s: Vec3::new(0.0, 0.0, 0.0),
                    angular_velocity_rad_s: Vec3::new(0.0, 0.0, 0.0),
                }],
                native: Some(crate::engine::NativeState {
                    engine: self.name.into(),
                    data: vec![],
                }),
            })
        }
        fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
            self.t = state.time_s;
            self.q.copy_from_slice(&state.joint_angles_rad);
            self.v.copy_from_slice(&state.joint_velocity_targets_rad_s);
            self.cube = state.objects[0].pose;
            Ok(())
        }
    }

    fn plan(names: &[&str]) -> Vec<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    fn run(scene: &Scene, names: &[&str], blow_up_s: Option<f64>) -> StitchedRun {
        let mut load = |name: &str| -> Result<Box<dyn Simulation>, RunError> {
            let mut toy = Toy::new(if name == "a" { "a" } else { "b" }, 1e-4);
            toy.blow_up_s = blow_up_s;
            Ok(Box::new(toy))
        };
        let options = RunOptions::default();
        run_stitched(
            scene,
            &plan(names),
            &options,
            &ControlParams::default(),
            &mut load,
        )
        .unwrap()
    }

    #[test]
    fn a_stitched_run_is_one_controller_run_with_a_handover_per_boundary() {
        let scene = crate::testing::scene("scene3_cube_push");
        let mut whole = Toy::new("a", 1e-4);
        let plain =
            crate::controller::run_scene(&mut whole, &scene, &RunOptions::default()).unwrap();
        let same = run(&scene, &["a", "a", "a"], None);
        assert_eq!(same.outcome.trajectory, plain.trajectory);
        assert_eq!(same.outcome.engine_steps, plain.engine_steps);
        let ticks: Vec<(usize, f64, bool)> = same
            .handovers
            .iter()
            .map(|h| (h.tick, h.t_s, h.native))
            .collect();
        assert_eq!(ticks, [(160, 8.0, true), (280, 14.0, true)]);
        assert!(same.handovers.iter().all(|h| h.corrections.is_empty()));
        // To another engine: the same arm, the sunk cube lifted by 1e-4 m.
        let mixed = run(&scene, &["a", "b", "b"], None);
        let h = &mixed.handovers[0];
        assert_eq!(
            (h.from.as_str(), h.to.as_str(), h.native),
            ("a", "b", false)
        );
        assert_eq!(h.joint_angle_diff_rad, 0.0);
        assert!((h.corrections[0].lift_m - 1e-4).abs() < 1e-12, "{h:?}");
        assert!((h.object_position_diff_m - 1e-4).abs() < 1e-12, "{h:?}");
        let q = |o: &RunOutcome| o.trajectory.joint_angles_rad.clone();
        assert_eq!(q(&mixed.outcome), q(&plain));
        let cube = mixed.outcome.trajectory.positions("cube");
        assert!((cube[200].unwrap().z - 0.0375).abs() < 1e-12);
        assert!(mixed.handovers[1].native);
        assert_eq!(mixed.engines, ["a", "b", "b"]);
    }

    #[test]
    fn a_run_that_diverges_hands_nothing_over() {
        let scene = crate::testing::scene("scene3_cube_push");
        let out = run(&scene, &["a", "b", "b"], Some(5.0));
        assert!(matches!(
            out.outcome.status,
            crate::controller::RunStatus::Diverged { .. }
        ));
        assert!(out.handovers.is_empty());
        // Stopped at about 5 s, before the first boundary (8 s).
        let rows = out.outcome.trajectory.len();
        assert!((99..=101).contains(&rows), "{rows}");
        let e = run_stitched(
            &scene,
            &plan(&["a", "b"]),
            &RunOptions::default(),
            &ControlParams::default(),
            &mut |_: &str| -> Result<Box<dyn Simulation>, RunError> {
                Ok(Box::new(Toy::new("a", 0.0)))
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("2 engines given for the 3 phases"), "{e}");
    }

    #[test]
    fn the_resting_rule_lifts_a_sunk_cube_and_leaves_a_floating_one() {
        let scene = crate::testing::scene("scene3_cube_push");
        let tilted = Quat::from_axis_angle(Vec3::new(0.0, 1.0, 0.0), 45f64.to_radians());
        let cube = |z: f64, q: Quat, vz: f64| ObjectState {
            name: "cube".into(),
            pose: Pose::new(Vec3::new(0.5, 0.0, z), q),
            linear_velocity_m_s: Vec3::new(0.1, 0.0, vz),
            angular_velocity_rad_s: Vec3::new(0.0, 0.0, 0.0),
        };
        let mut state = SimState {
            time_s: 14.0,
            joint_angles_rad: vec![0.0; 6],
            joint_velocities_rad_s: vec![0.0; 6],
            joint_velocity_targets_rad_s: vec![0.0; 6],
            servo_commands: vec![],
            objects: vec![cube(0.0375 - 1e-4, Quat::IDENTITY, -0.02)],
            native: None,
        };
        let c = rest_on_ground(&scene, &mut state);
        assert_eq!(c.len(), 1);
        assert!((c[0].lift_m - 1e-4).abs() < 1e-12, "{}", c[0].lift_m);
        assert!((c[0].removed_down_velocity_m_s - 0.02).abs() < 1e-15);
        assert!((state.objects[0].pose.position_m.z - 0.0375).abs() < 1e-12);
        assert_eq!(
            state.objects[0].linear_velocity_m_s,
            Vec3::new(0.1, 0.0, 0.0)
        );
        // On its edge, the lowest point is half the face diagonal down.
        let edge = 0.075 * std::f64::consts::SQRT_2 / 2.0;
        state.objects[0] = cube(edge - 2e-3, tilted, 0.0);
        let c = rest_on_ground(&scene, &mut state);
        assert!((c[0].lift_m - 2e-3).abs() < 1e-9, "{}", c[0].lift_m);
        state.objects[0] = cube(0.04, Quat::IDENTITY, 0.0);
        assert!(rest_on_ground(&scene, &mut state).is_empty());
        assert_eq!(state.objects[0].pose.position_m.z, 0.04);
    }
}
