//! The controller loop shared by every engine, and the seeded per-run
//! perturbations.
//!
//! [`run_scene`] drives a [`Simulation`] through a [`Scene`] exactly as the
//! study drove its simulators and the real arm (METHOD.md):
//!
//! ```text
//! for tick k in 0 .. duration/period:
//!     t = k * period
//!     read joint angles q and tracked poses          (state at time t)
//!     for every controlled joint j:
//!         error_deg = target_deg[j](t) - degrees(q[j] + sensor noise)
//!         v_deg_s   = clamp(gain * error_deg, -max_speed, +max_speed)
//!         command   = radians(v_deg_s)
//!     send the command (or the one from `delay` periods ago)
//!     record t, q, the command sent, the poses
//!     step period/timestep times
//! ```
//!
//! So a 6 s scene at 0.05 s records 120 samples, the first one the initial
//! state at t = 0, like the study's recordings. The loop stops early when
//! the state diverges: a non-finite angle or pose, a tracked body farther
//! than [`RunOptions::divergence_bound_m`] from the origin, or an engine
//! that reports itself unstable. The run then ends as
//! [`RunStatus::Diverged`] with the samples recorded so far.

use crate::engine::{Engine, EngineError, EngineSettings, ModelVariation, Simulation};
use crate::pose::Pose;
use crate::robot::RobotModel;
use crate::scene::{Scene, SceneError};
use crate::trajectory::Trajectory;
use std::collections::{BTreeMap, VecDeque};
use std::time::Instant;

/// Perturbations of a batch of runs, each drawn per repeat from a seed. All
/// zero (the default) means every repeat is identical for a deterministic
/// engine.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Perturbation {
    /// Standard deviation of a Gaussian offset added to every controlled
    /// joint's initial angle, degrees.
    pub initial_offset_std_deg: f64,
    /// Standard deviation of Gaussian noise added to every joint-angle
    /// reading the controller uses (not to the recorded angles), degrees.
    pub sensor_noise_std_deg: f64,
    /// Commands take effect this many control periods after they are
    /// computed (the servos hold 0 rad/s until the first one arrives).
    pub control_delay_periods: u32,
    /// Masses and inertias are scaled by a factor drawn uniformly from
    /// `[1 - s, 1 + s]`; `s` in `[0, 1)`.
    pub mass_scale_spread: f64,
    /// Friction coefficients are scaled by a factor drawn uniformly from
    /// `[1 - s, 1 + s]`; `s` in `[0, 1)`.
    pub friction_scale_spread: f64,
}

/// A `--perturb` specification that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid perturbation \"{spec}\": {message}")]
pub struct PerturbationError {
    /// The text given.
    pub spec: String,
    /// What is wrong and what is accepted.
    pub message: String,
}

/// Keys accepted by [`Perturbation::parse`], with their meaning.
pub const PERTURBATION_KEYS: &[(&str, &str)] = &[
    (
        "initial_offset_deg",
        "std. dev. of the initial joint-angle offsets, degrees",
    ),
    (
        "sensor_noise_deg",
        "std. dev. of the joint-angle reading noise, degrees",
    ),
    ("delay_periods", "control delay, whole control periods"),
    (
        "mass_scale",
        "mass and inertia scaled by U[1-s, 1+s], 0 <= s < 1",
    ),
    (
        "friction_scale",
        "friction scaled by U[1-s, 1+s], 0 <= s < 1",
    ),
];

impl Perturbation {
    /// True when nothing is perturbed.
    pub fn is_none(&self) -> bool {
        *self == Perturbation::default()
    }

    /// Parses `key=value[,key=value...]` (keys in [`PERTURBATION_KEYS`]),
    /// adding to `self`.
    pub fn parse_into(&mut self, spec: &str) -> Result<(), PerturbationError> {
        let err = |message: String| PerturbationError {
            spec: spec.to_string(),
            message,
        };
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| err(format!("\"{part}\" is not key=value")))?;
            let (key, value) = (key.trim(), value.trim());
            let number: f64 = value
                .parse()
                .map_err(|_| err(format!("the value of {key} is not a number: \"{value}\"")))?;
            if !number.is_finite() || number < 0.0 {
                return Err(err(format!(
                    "{key} must be a finite number >= 0, found {value}"
                )));
            }
            match key {
                "initial_offset_deg" => self.initial_offset_std_deg = number,
                "sensor_noise_deg" => self.sensor_noise_std_deg = number,
                "delay_periods" => {
                    if number.fract() != 0.0 || number > 1000.0 {
                        return Err(err(format!(
                            "delay_periods must be a whole number <= 1000, found {value}"
                        )));
                    }
                    self.control_delay_periods = number as u32;
                }
                "mass_scale" | "friction_scale" => {
                    if number >= 1.0 {
                        return Err(err(format!(
                            "{key} must be below 1 (a factor in [1-s, 1+s]), found {value}"
                        )));
                    }
                    if key == "mass_scale" {
                        self.mass_scale_spread = number;
                    } else {
                        self.friction_scale_spread = number;
                    }
                }
                other => {
                    return Err(err(format!(
                        "unknown key \"{other}\" (expected one of: {})",
                        PERTURBATION_KEYS
                            .iter()
                            .map(|(k, _)| *k)
                            .collect::<Vec<_>>()
                            .join(", ")
                    )))
                }
            }
        }
        Ok(())
    }

    /// The settings as key/value pairs for a manifest.
    pub fn describe(&self) -> BTreeMap<String, f64> {
        BTreeMap::from([
            (
                "initial_offset_deg".to_string(),
                self.initial_offset_std_deg,
            ),
            ("sensor_noise_deg".to_string(), self.sensor_noise_std_deg),
            (
                "delay_periods".to_string(),
                self.control_delay_periods as f64,
            ),
            ("mass_scale".to_string(), self.mass_scale_spread),
            ("friction_scale".to_string(), self.friction_scale_spread),
        ])
    }

    /// Draws the perturbation of one run from `seed` for `joint_count`
    /// controlled joints. The same seed gives the same draw in every engine
    /// and scene with that many joints.
    pub fn sample(&self, seed: u64, joint_count: usize) -> PerturbationSample {
        let mut rng = SplitMix64::new(seed);
        let initial_offsets_rad = (0..joint_count)
            .map(|_| (self.initial_offset_std_deg * rng.normal()).to_radians())
            .collect();
        let mass_scale = 1.0 + self.mass_scale_spread * (2.0 * rng.uniform() - 1.0);
        let friction_scale = 1.0 + self.friction_scale_spread * (2.0 * rng.uniform() - 1.0);
        PerturbationSample {
            initial_offsets_rad,
            sensor_noise_std_rad: self.sensor_noise_std_deg.to_radians(),
            control_delay_periods: self.control_delay_periods,
            variation: ModelVariation {
                mass_scale,
                friction_scale,
            },
            noise_seed: rng.next_u64(),
        }
    }
}

/// The perturbation of one run, drawn by [`Perturbation::sample`].
#[derive(Debug, Clone, PartialEq)]
pub struct PerturbationSample {
    /// Offsets added to the controlled joints' initial angles, rad.
    pub initial_offsets_rad: Vec<f64>,
    /// Std. dev. of the reading noise, rad.
    pub sensor_noise_std_rad: f64,
    /// Control delay, periods.
    pub control_delay_periods: u32,
    /// Mass and friction factors for [`Engine::load`].
    pub variation: ModelVariation,
    /// Seed of the reading-noise sequence.
    pub noise_seed: u64,
}

/// The seed of repeat `repeat` of a batch seeded with `batch_seed`.
pub fn repeat_seed(batch_seed: u64, repeat: u64) -> u64 {
    let mut r = SplitMix64::new(batch_seed ^ repeat.wrapping_mul(0xA076_1D64_78BD_642F));
    r.next_u64()
}

/// A small, fast, seedable generator (SplitMix64; Steele et al. 2014): good
/// enough statistics for perturbations, no dependency, identical on every
/// platform.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        SplitMix64 { state: seed }
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Options of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    /// The perturbation of this run; `None` for the unperturbed scene.
    pub perturbation: Option<PerturbationSample>,
    /// A tracked body farther than this from the world origin (any
    /// coordinate, m) means the run diverged.
    pub divergence_bound_m: f64,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            perturbation: None,
            divergence_bound_m: 10.0,
        }
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub enum RunStatus {
    /// All samples were recorded.
    Completed,
    /// The state became unusable at `t_s`; the trajectory holds the samples
    /// before it.
    Diverged {
        /// Simulated time at which it was noticed, s.
        t_s: f64,
        /// What was seen.
        reason: String,
    },
}

/// The result of [`run_scene`].
#[derive(Debug, Clone, PartialEq)]
pub struct RunOutcome {
    /// Samples at the control rate: time, tracked poses (scene order), joint
    /// angles (rad) and the velocity commands sent (rad/s).
    pub trajectory: Trajectory,
    /// Completed or diverged.
    pub status: RunStatus,
    /// Engine steps taken.
    pub engine_steps: u64,
    /// Wall time of the loop (stepping and control), s.
    pub wall_time_s: f64,
}

impl RunOutcome {
    /// Engine steps per second of wall time (0 when nothing ran).
    pub fn steps_per_second(&self) -> f64 {
        if self.wall_time_s > 0.0 {
            self.engine_steps as f64 / self.wall_time_s
        } else {
            0.0
        }
    }
}

/// Why a run could not be carried out (as opposed to a run that diverged).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The scene does not fit the engine (e.g. its control period is not a
    /// whole number of timesteps).
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The engine failed.
    #[error(transparent)]
    Engine(#[from] EngineError),
}

/// Checks the state read at one tick; the reason when it is unusable.
fn divergence(angles: &[f64], poses: &[Pose], roles: &[String], bound_m: f64) -> Option<String> {
    if let Some(j) = angles.iter().position(|a| !a.is_finite()) {
        return Some(format!("joint {} angle is not finite", j + 1));
    }
    for (pose, role) in poses.iter().zip(roles) {
        if !pose.is_finite() {
            return Some(format!("pose of '{role}' is not finite"));
        }
        let p = pose.position_m;
        if p.x.abs() > bound_m || p.y.abs() > bound_m || p.z.abs() > bound_m {
            return Some(format!(
                "'{role}' is at ({:.3}, {:.3}, {:.3}) m, beyond the {bound_m} m bound",
                p.x, p.y, p.z
            ));
        }
    }
    None
}

/// Runs `scene` on a freshly loaded `sim` (see the module documentation).
pub fn run_scene(
    sim: &mut dyn Simulation,
    scene: &Scene,
    options: &RunOptions,
) -> Result<RunOutcome, RunError> {
    let engine_name = "simulation";
    let steps_per_period = scene.steps_per_period(sim.timestep_s())?;
    let joints = scene.actuators.len();
    if sim.joint_count() != joints || sim.tracked_count() != scene.tracked.len() {
        return Err(EngineError::Usage {
            engine: engine_name.to_string(),
            message: format!(
                "the simulation has {} joints and {} tracked bodies, the scene {} and {}",
                sim.joint_count(),
                sim.tracked_count(),
                joints,
                scene.tracked.len()
            ),
        }
        .into());
    }
    let roles: Vec<String> = scene.tracked.iter().map(|t| t.role.clone()).collect();
    let samples = scene.sample_count();
    let period = scene.controller.period_s;
    let gain = scene.controller.gain_per_s;
    let max_speed = scene.controller.max_speed_deg_s;

    let (noise_std, delay, mut noise) = match &options.perturbation {
        Some(p) => {
            if p.initial_offsets_rad.iter().any(|&o| o != 0.0) {
                let start: Vec<f64> = (0..joints)
                    .map(|j| p.initial_offsets_rad.get(j).copied().unwrap_or(0.0))
                    .collect();
                sim.set_joint_angles_rad(&start)?;
            }
            (
                p.sensor_noise_std_rad,
                p.control_delay_periods as usize,
                SplitMix64::new(p.noise_seed),
            )
        }
        None => (0.0, 0, SplitMix64::new(0)),
    };

    let mut trajectory = Trajectory::with_bodies(&roles);
    let mut angle_rows = Vec::with_capacity(samples);
    let mut command_rows = Vec::with_capacity(samples);
    let mut angles = vec![0.0; joints];
    let mut poses = vec![Pose::IDENTITY; roles.len()];
    let mut pending: VecDeque<Vec<f64>> = (0..delay).map(|_| vec![0.0; joints]).collect();
    let mut status = RunStatus::Completed;
    let mut engine_steps = 0u64;
    let mut targets_deg = scene.targets_deg_at_tick(0);
    let mut entry_in_force = usize::MAX;

    let start = Instant::now();
    for tick in 0..samples {
        let t_s = tick as f64 * period;
        sim.joint_angles_rad(&mut angles);
        sim.tracked_poses(&mut poses);
        if let Some(reason) = divergence(&angles, &poses, &roles, options.divergence_bound_m) {
            status = RunStatus::Diverged { t_s, reason };
            break;
        }
        let entry = scene
            .schedule
            .iter()
            .rposition(|e| e.t_s <= t_s + 1e-9)
            .unwrap_or(usize::MAX);
        if entry != entry_in_force {
            targets_deg = scene.targets_deg_at_tick(tick);
            entry_in_force = entry;
        }
        let command: Vec<f64> = (0..joints)
            .map(|j| {
                let reading = if noise_std > 0.0 {
                    angles[j] + noise_std * noise.normal()
                } else {
                    angles[j]
                };
                let error_deg = targets_deg[j] - reading.to_degrees();
                (gain * error_deg).clamp(-max_speed, max_speed).to_radians()
            })
            .collect();
        let sent = if delay == 0 {
            command
        } else {
            pending.push_back(command);
            pending.pop_front().unwrap_or_else(|| vec![0.0; joints])
        };
        sim.set_joint_velocity_targets(&sent);
        trajectory.time_s.push(t_s);
        for (track, pose) in trajectory.bodies.iter_mut().zip(&poses) {
            track.poses.push(Some(*pose));
        }
        angle_rows.push(angles.clone());
        command_rows.push(sent);
        match sim.step_n(steps_per_period) {
            Ok(()) => engine_steps += steps_per_period,
            Err(EngineError::Unstable { t_s, message, .. }) => {
                // Steps taken in this period, up to and including the bad one.
                let into_period = ((t_s - tick as f64 * period) / sim.timestep_s())
                    .round()
                    .max(0.0) as u64;
                engine_steps += (into_period + 1).min(steps_per_period);
                status = RunStatus::Diverged {
                    t_s,
                    reason: message,
                };
                break;
            }
            Err(e) => return Err(e.into()),
        }
    }
    let wall_time_s = start.elapsed().as_secs_f64();
    trajectory.joint_angles_rad = Some(angle_rows);
    trajectory.joint_velocity_commands_rad_s = Some(command_rows);
    Ok(RunOutcome {
        trajectory,
        status,
        engine_steps,
        wall_time_s,
    })
}

/// Loads `scene` into `engine` (with the perturbation's mass and friction
/// factors) and runs it: [`Engine::load`] then [`run_scene`].
pub fn simulate(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
    options: &RunOptions,
) -> Result<RunOutcome, RunError> {
    let variation = options
        .perturbation
        .as_ref()
        .map(|p| p.variation)
        .unwrap_or_default();
    let mut sim = engine.load(scene, robot, settings, &variation)?;
    run_scene(sim.as_mut(), scene, options)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::{Quat, Vec3};
    use std::path::Path;

    const SCENE: &str = r#"
name = "t"
duration_s = 1.0
[robot]
urdf = "arm.urdf"
base_position_m = [0, 0, 0]
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "j1"
kv = 10.0
[[actuator]]
joint = "j2"
kv = 10.0
[[schedule]]
t_s = 0.0
targets_deg = { j1 = -10.0, j2 = 1.0 }
[[schedule]]
t_s = 0.5
targets_deg = { j2 = 2.0 }
[[track]]
role = "tip"
link = "l2"
"#;

    /// A perfect velocity servo: each joint moves at exactly its target
    /// velocity; the tip is at (angle1, angle2, 0).
    struct Ideal {
        dt: f64,
        t: f64,
        q: Vec<f64>,
        v: Vec<f64>,
        blow_up_at: Option<f64>,
    }

    impl Simulation for Ideal {
        fn timestep_s(&self) -> f64 {
            self.dt
        }
        fn time_s(&self) -> f64 {
            self.t
        }
        fn joint_count(&self) -> usize {
            2
        }
        fn tracked_count(&self) -> usize {
            1
        }
        fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
            self.q.copy_from_slice(rad);
            Ok(())
        }
        fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
            self.v.copy_from_slice(rad_s);
        }
        fn step(&mut self) -> Result<(), EngineError> {
            for (q, v) in self.q.iter_mut().zip(&self.v) {
                *q += v * self.dt;
            }
            self.t += self.dt;
            if let Some(t) = self.blow_up_at {
                if self.t >= t {
                    self.q[0] = f64::NAN;
                }
            }
            Ok(())
        }
        fn joint_angles_rad(&self, out: &mut [f64]) {
            out.copy_from_slice(&self.q);
        }
        fn tracked_poses(&self, out: &mut [Pose]) {
            out[0] = Pose::new(Vec3::new(self.q[0], self.q[1], 0.0), Quat::IDENTITY);
        }
    }

    fn ideal(dt: f64) -> Ideal {
        Ideal {
            dt,
            t: 0.0,
            q: vec![0.0; 2],
            v: vec![0.0; 2],
            blow_up_at: None,
        }
    }

    fn scene() -> Scene {
        Scene::from_toml_str(SCENE, Path::new("/s/t.toml")).unwrap()
    }

    #[test]
    fn records_one_sample_per_period_starting_at_zero() {
        let scene = scene();
        let mut sim = ideal(0.01);
        let out = run_scene(&mut sim, &scene, &RunOptions::default()).unwrap();
        assert_eq!(out.status, RunStatus::Completed);
        let t = &out.trajectory;
        t.validate().unwrap();
        assert_eq!(t.len(), 20);
        assert_eq!(t.time_s[0], 0.0);
        assert!((t.time_s[19] - 0.95).abs() < 1e-12);
        assert_eq!(out.engine_steps, 100);
        // First command: error -10 deg -> -100 deg/s clamped to -30 deg/s;
        // joint 2: error 1 deg -> 10 deg/s.
        let c0 = &t.joint_velocity_commands_rad_s.as_ref().unwrap()[0];
        assert!((c0[0] - (-30f64).to_radians()).abs() < 1e-15);
        assert!((c0[1] - 10f64.to_radians()).abs() < 1e-15);
        // After one period joint 1 moved -1.5 deg.
        let q1 = &t.joint_angles_rad.as_ref().unwrap()[1];
        assert!(
            (q1[0].to_degrees() + 1.5).abs() < 1e-9,
            "{}",
            q1[0].to_degrees()
        );
        // From 0.5 s joint 1 targets 0 (not named) and joint 2 targets 2 deg.
        let c10 = &t.joint_velocity_commands_rad_s.as_ref().unwrap()[10];
        assert!(c10[0] > 0.0);
        let q_last = t.joint_angles_rad.as_ref().unwrap()[19].clone();
        assert!(
            (q_last[1].to_degrees() - 2.0).abs() < 0.05,
            "{}",
            q_last[1].to_degrees()
        );
        assert_eq!(t.positions("tip")[1].unwrap().x, q1[0]);
    }

    #[test]
    fn rejects_timestep_that_does_not_divide_the_period() {
        let err = run_scene(&mut ideal(0.03), &scene(), &RunOptions::default()).unwrap_err();
        assert!(
            err.to_string()
                .contains("not a whole number of engine timesteps"),
            "{err}"
        );
    }

    #[test]
    fn divergence_stops_the_run() {
        let mut sim = ideal(0.01);
        sim.blow_up_at = Some(0.3);
        let out = run_scene(&mut sim, &scene(), &RunOptions::default()).unwrap();
        match &out.status {
            RunStatus::Diverged { t_s, reason } => {
                assert!((t_s - 0.3).abs() < 1e-9, "{t_s}");
                assert!(reason.contains("not finite"), "{reason}");
            }
            s => panic!("expected divergence, got {s:?}"),
        }
        assert_eq!(out.trajectory.len(), 6);
        out.trajectory.validate().unwrap();
    }

    #[test]
    fn delay_and_offsets_are_applied() {
        let p = Perturbation {
            initial_offset_std_deg: 1.0,
            control_delay_periods: 2,
            ..Default::default()
        };
        let sample = p.sample(7, 2);
        assert_eq!(sample, p.sample(7, 2), "same seed, same draw");
        assert_ne!(
            sample.initial_offsets_rad,
            p.sample(8, 2).initial_offsets_rad
        );
        let opts = RunOptions {
            perturbation: Some(sample.clone()),
            ..Default::default()
        };
        let out = run_scene(&mut ideal(0.01), &scene(), &opts).unwrap();
        let t = &out.trajectory;
        let q0 = &t.joint_angles_rad.as_ref().unwrap()[0];
        assert_eq!(q0, &sample.initial_offsets_rad);
        let cmds = t.joint_velocity_commands_rad_s.as_ref().unwrap();
        assert_eq!(cmds[0], vec![0.0, 0.0]);
        assert_eq!(cmds[1], vec![0.0, 0.0]);
        assert!(cmds[2][0] < 0.0);
    }

    #[test]
    fn sensor_noise_changes_commands_but_not_recorded_angles_at_start() {
        let p = Perturbation {
            sensor_noise_std_deg: 0.5,
            ..Default::default()
        };
        let opts = RunOptions {
            perturbation: Some(p.sample(1, 2)),
            ..Default::default()
        };
        let noisy = run_scene(&mut ideal(0.01), &scene(), &opts).unwrap();
        let clean = run_scene(&mut ideal(0.01), &scene(), &RunOptions::default()).unwrap();
        let n = noisy.trajectory.joint_velocity_commands_rad_s.unwrap();
        let c = clean.trajectory.joint_velocity_commands_rad_s.unwrap();
        assert_eq!(
            noisy.trajectory.joint_angles_rad.unwrap()[0],
            vec![0.0, 0.0]
        );
        assert_ne!(n[0][1], c[0][1]);
    }

    #[test]
    fn parses_perturbation_specs() {
        let mut p = Perturbation::default();
        assert!(p.is_none());
        p.parse_into("initial_offset_deg=0.5, delay_periods=1")
            .unwrap();
        p.parse_into("mass_scale=0.1").unwrap();
        assert_eq!(p.initial_offset_std_deg, 0.5);
        assert_eq!(p.control_delay_periods, 1);
        assert_eq!(p.mass_scale_spread, 0.1);
        assert!(!p.is_none());
        for bad in [
            "bogus=1",
            "mass_scale=1.5",
            "delay_periods=0.5",
            "sensor_noise_deg=x",
            "x",
            "initial_offset_deg=-1",
        ] {
            assert!(Perturbation::default().parse_into(bad).is_err(), "{bad}");
        }
        let s = Perturbation {
            mass_scale_spread: 0.2,
            ..Default::default()
        }
        .sample(3, 6);
        assert!((0.8..=1.2).contains(&s.variation.mass_scale));
        assert_eq!(s.variation.friction_scale, 1.0);
    }

    #[test]
    fn normal_samples_have_unit_variance() {
        let mut r = SplitMix64::new(42);
        let n = 20000;
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.03, "{mean}");
        assert!((var - 1.0).abs() < 0.05, "{var}");
        assert_ne!(repeat_seed(0, 0), repeat_seed(0, 1));
    }
}
