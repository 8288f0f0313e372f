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

use crate::actuator::{ActuatorStage, StageParams, StageUnit};
use crate::engine::{Engine, EngineError, EngineSettings, ModelVariation, Simulation};
use crate::params::PhysicalParams;
use crate::pose::{Pose, Vec3};
use crate::robot::RobotModel;
use crate::scene::{Scene, SceneError, TrackTarget};
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

/// Keys accepted by [`Perturbation::parse_into`], with their meaning.
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
    /// Run even when the loaded simulation reports settings known to be
    /// numerically unstable ([`Simulation::stability_issues`]); otherwise
    /// [`refuse_unstable`] (called by [`simulate_with`] and the runner)
    /// refuses them with [`EngineError::UnstableSettings`].
    pub allow_unstable: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            perturbation: None,
            divergence_bound_m: 10.0,
            allow_unstable: false,
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
    /// A parameters file names a joint, link or object the robot or scene
    /// lacks.
    #[error(transparent)]
    Params(#[from] crate::params::ParamsError),
}

/// Checks the state read at one tick; the reason when it is unusable.
pub(crate) fn divergence(
    angles: &[f64],
    poses: &[Pose],
    roles: &[String],
    bound_m: f64,
) -> Option<String> {
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

/// How deep an object may sink into the ground before the run counts as
/// diverged, as a fraction of its smallest half-extent: contacts in every
/// engine are a little soft (a resting cube sinks micrometres to a few
/// millimetres, more with softened contact parameters), but a cube half
/// inside the table is a contact that failed, not a softer one.
pub const PENETRATION_LIMIT_FRACTION: f64 = 0.5;

/// How long an object may stay deeper than the limit, s: an impact at a
/// coarse timestep may carry a fast object's corner deep into the ground
/// for a step or two before the contact pushes it out; staying there is a
/// failed contact.
pub const PENETRATION_SPELL_S: f64 = 0.1;

/// Checks that no tracked object has stayed sunk into the ground by more
/// than [`PENETRATION_LIMIT_FRACTION`] of its smallest half-extent for
/// [`PENETRATION_SPELL_S`]; the reason when one has. `grounded[i]`: the
/// half-extents of role `i`'s object and the ground's height, when role
/// `i` is an object over a ground; `sunk_since_s[i]`: when role `i`'s
/// current spell too deep began (updated here).
pub(crate) fn penetration(
    poses: &[Pose],
    roles: &[String],
    grounded: &[Option<(Vec3, f64)>],
    sunk_since_s: &mut [Option<f64>],
    t_s: f64,
) -> Option<String> {
    for (((pose, role), g), since) in poses.iter().zip(roles).zip(grounded).zip(sunk_since_s) {
        let Some((half, ground_m)) = g else { continue };
        let depth = ground_m - lowest_point_z(pose, *half);
        let limit = PENETRATION_LIMIT_FRACTION * half.x.min(half.y).min(half.z);
        if depth <= limit {
            *since = None;
            continue;
        }
        let start = *since.get_or_insert(t_s);
        if t_s - start >= PENETRATION_SPELL_S - 1e-9 {
            return Some(format!(
                "'{role}' has been {:.1} mm or more inside the ground since t = {start:.3} s (its lowest corner at z = {:.4} m, the ground at {ground_m} m), more than the {:.1} mm allowed (half its smallest half-extent): the contact failed",
                limit * 1e3,
                ground_m - depth,
                limit * 1e3
            ));
        }
    }
    None
}

/// The height of a box's lowest corner, m: its centre's height less the
/// vertical reach of its half-extents along its rotated axes.
pub fn lowest_point_z(pose: &Pose, half_extents_m: Vec3) -> f64 {
    let q = pose.orientation;
    let reach = half_extents_m.x * q.rotate(Vec3::new(1.0, 0.0, 0.0)).z.abs()
        + half_extents_m.y * q.rotate(Vec3::new(0.0, 1.0, 0.0)).z.abs()
        + half_extents_m.z * q.rotate(Vec3::new(0.0, 0.0, 1.0)).z.abs();
    pose.position_m.z - reach
}

/// The controller's own state during a run, which outlives any one
/// [`Simulation`]: the tick reached, the commands waiting out the actuation
/// delay, the reading-noise generator, the targets in force and the samples
/// recorded so far. A run is one loop driving one or several simulations in
/// turn ([`ControllerLoop::advance`]); handing a run from one engine to
/// another at a tick is `advance(a, tick)`, `b.set_state(&a.state()?)`,
/// `advance(b, end)`.
#[derive(Debug, Clone)]
pub struct ControllerLoop {
    roles: Vec<String>,
    samples: usize,
    period_s: f64,
    gain_per_s: f64,
    max_speed_deg_s: f64,
    schedule_times_s: Vec<f64>,
    scene_targets: Vec<Vec<f64>>,
    joints: usize,
    divergence_bound_m: f64,
    /// Per tracked role: the object's half-extents and the ground's height
    /// when the role is an object over a ground ([`penetration`]).
    grounded: Vec<Option<(Vec3, f64)>>,
    /// Per tracked role: when it was first seen too deep in the ground, in
    /// the spell that lasts to now.
    sunk_since_s: Vec<Option<f64>>,
    /// The objects that start moving: name, velocity (m/s), angular
    /// velocity (rad/s), world frame.
    initial_twists: Vec<(String, Vec3, Vec3)>,
    noise_std_rad: f64,
    noise: SplitMix64,
    offsets_rad: Vec<f64>,
    initial_offsets_rad: Vec<f64>,
    delay_s: f64,
    /// Largest change of a servo target per control period, rad/s
    /// (infinite: unlimited).
    max_step_rad_s: f64,
    /// Commands waiting to reach the servos: (due time s, rad/s).
    pending: VecDeque<(f64, Vec<f64>)>,
    /// The servo targets in force, rad/s.
    in_force: Vec<f64>,
    /// The actuator stage from `in_force` to the servos' targets.
    stage: ActuatorStage,
    tick: usize,
    trajectory: Trajectory,
    angle_rows: Vec<Vec<f64>>,
    command_rows: Vec<Vec<f64>>,
    status: Option<RunStatus>,
    engine_steps: u64,
    wall_time_s: f64,
}

/// How the physical parameters change the controller: encoder offsets and
/// actuation latency (see [`crate::params`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ControlParams {
    /// Encoder zero offsets per controlled joint, rad (true = measured +
    /// offset); empty means none.
    pub offsets_rad: Vec<f64>,
    /// Actuation latency, s, added to the perturbation's whole periods.
    pub delay_s: f64,
    /// Acceleration limit of the velocity loop, rad/s^2 (`None`: none).
    pub max_accel_rad_s2: Option<f64>,
    /// The actuator stage between the command in force and the servo's
    /// target ([`crate::actuator`]).
    pub stage: StageParams,
}

impl ControlParams {
    /// The controller's share of `params` for `scene`.
    pub fn from_params(params: &PhysicalParams, scene: &Scene) -> ControlParams {
        ControlParams {
            offsets_rad: params.offsets_rad(scene),
            delay_s: params.delay_s(),
            max_accel_rad_s2: Some(params.max_accel_rad_s2()).filter(|a| a.is_finite()),
            stage: StageParams::from_params(params),
        }
    }
}

impl ControllerLoop {
    /// A loop for `scene` at tick 0 with nothing recorded.
    pub fn new(scene: &Scene, options: &RunOptions, control: &ControlParams) -> ControllerLoop {
        let joints = scene.actuators.len();
        let roles: Vec<String> = scene.tracked.iter().map(|t| t.role.clone()).collect();
        let period_s = scene.controller.period_s;
        let (noise_std_rad, periods, noise, initial) = match &options.perturbation {
            Some(p) => (
                p.sensor_noise_std_rad,
                p.control_delay_periods,
                SplitMix64::new(p.noise_seed),
                (0..joints)
                    .map(|j| p.initial_offsets_rad.get(j).copied().unwrap_or(0.0))
                    .collect(),
            ),
            None => (0.0, 0, SplitMix64::new(0), vec![0.0; joints]),
        };
        let samples = scene.sample_count();
        ControllerLoop {
            samples,
            period_s,
            gain_per_s: scene.controller.gain_per_s,
            max_speed_deg_s: scene.controller.max_speed_deg_s,
            schedule_times_s: scene.schedule.iter().map(|e| e.t_s).collect(),
            scene_targets: Vec::new(),
            joints,
            divergence_bound_m: options.divergence_bound_m,
            grounded: scene
                .tracked
                .iter()
                .map(|t| match (&t.target, scene.ground) {
                    (TrackTarget::Object(name), Some(g)) => {
                        scene.object(name).map(|o| (o.half_extents_m(), g.height_m))
                    }
                    _ => None,
                })
                .collect(),
            sunk_since_s: vec![None; scene.tracked.len()],
            initial_twists: scene
                .objects
                .iter()
                .filter(|o| {
                    o.linear_velocity_m_s != Vec3::ZERO || o.angular_velocity_rad_s != Vec3::ZERO
                })
                .map(|o| {
                    (
                        o.name.clone(),
                        o.linear_velocity_m_s,
                        o.angular_velocity_rad_s,
                    )
                })
                .collect(),
            noise_std_rad,
            noise,
            offsets_rad: if control.offsets_rad.len() == joints {
                control.offsets_rad.clone()
            } else {
                vec![0.0; joints]
            },
            initial_offsets_rad: initial,
            delay_s: periods as f64 * period_s + control.delay_s,
            max_step_rad_s: control
                .max_accel_rad_s2
                .map_or(f64::INFINITY, |a| a * period_s),
            pending: VecDeque::new(),
            in_force: vec![0.0; joints],
            stage: ActuatorStage::new(control.stage, StageUnit::Velocity, &vec![0.0; joints]),
            tick: 0,
            trajectory: Trajectory::with_bodies(&roles),
            roles,
            angle_rows: Vec::with_capacity(samples),
            command_rows: Vec::with_capacity(samples),
            status: None,
            engine_steps: 0,
            wall_time_s: 0.0,
        }
        .with_targets(scene)
    }

    fn with_targets(mut self, scene: &Scene) -> ControllerLoop {
        // The targets of each schedule entry, in actuator order (degrees).
        self.scene_targets = (0..scene.schedule.len())
            .map(|i| {
                let t = scene.schedule[i].t_s;
                let tick = (t / self.period_s).round() as usize;
                scene.targets_deg_at_tick(tick)
            })
            .collect();
        self
    }

    /// The next tick to run (= samples recorded so far).
    pub fn tick(&self) -> usize {
        self.tick
    }

    /// The number of ticks of the whole run.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// True once the run has ended (all ticks, or diverged).
    pub fn is_done(&self) -> bool {
        self.status.is_some()
    }

    /// Places a fresh simulation at the perturbation's initial joint
    /// angles, and gives the scene's objects their initial velocities
    /// (through [`Simulation::set_state`], the one path every engine has
    /// for an object's twist). Call once, before the first
    /// [`ControllerLoop::advance`] of a run that starts at tick 0.
    pub fn start(&mut self, sim: &mut dyn Simulation) -> Result<(), RunError> {
        self.check_shape(sim)?;
        if self.initial_offsets_rad.iter().any(|&o| o != 0.0) {
            sim.set_joint_angles_rad(&self.initial_offsets_rad)?;
        }
        if !self.initial_twists.is_empty() {
            // The portable state: the engine's own (native) state, which
            // it would load in preference, does not carry the change.
            let mut state = sim.state()?.portable();
            for object in &mut state.objects {
                if let Some((_, v, w)) = self.initial_twists.iter().find(|t| t.0 == object.name) {
                    object.linear_velocity_m_s = *v;
                    object.angular_velocity_rad_s = *w;
                }
            }
            sim.set_state(&state)?;
        }
        Ok(())
    }

    fn check_shape(&self, sim: &dyn Simulation) -> Result<(), RunError> {
        if sim.joint_count() != self.joints || sim.tracked_count() != self.roles.len() {
            return Err(EngineError::Usage {
                engine: "simulation".to_string(),
                message: format!(
                    "the simulation has {} joints and {} tracked bodies, the scene {} and {}",
                    sim.joint_count(),
                    sim.tracked_count(),
                    self.joints,
                    self.roles.len()
                ),
            }
            .into());
        }
        Ok(())
    }

    /// The schedule entry in force at time `t_s` (its targets are
    /// `scene_targets[entry]`, degrees).
    fn entry_at(&self, t_s: f64) -> usize {
        self.schedule_times_s
            .iter()
            .rposition(|&e| e <= t_s + 1e-9)
            .unwrap_or(0)
    }

    /// The controller's command at one tick from the joint angles read, rad/s.
    fn command(&mut self, t_s: f64, angles: &[f64]) -> Vec<f64> {
        let entry = self.entry_at(t_s);
        let mut command = Vec::with_capacity(self.joints);
        for (j, &angle) in angles.iter().enumerate() {
            let mut reading = angle - self.offsets_rad[j];
            if self.noise_std_rad > 0.0 {
                reading += self.noise_std_rad * self.noise.normal();
            }
            let error_deg = self.scene_targets[entry][j] - reading.to_degrees();
            command.push(
                (self.gain_per_s * error_deg)
                    .clamp(-self.max_speed_deg_s, self.max_speed_deg_s)
                    .to_radians(),
            );
        }
        command
    }

    /// Sends every pending command due at or before `t_s` (the last one
    /// wins); true when the targets changed.
    fn release_due(&mut self, t_s: f64) -> bool {
        let mut changed = false;
        while let Some((due, _)) = self.pending.front() {
            if *due > t_s + 1e-9 {
                break;
            }
            if let Some((_, c)) = self.pending.pop_front() {
                let step = self.max_step_rad_s;
                for (now, new) in self.in_force.iter_mut().zip(c) {
                    // The velocity loop's acceleration limit: the target
                    // moves toward the command by at most one period's
                    // worth of acceleration per release.
                    *now = if step.is_finite() {
                        *now + (new - *now).clamp(-step, step)
                    } else {
                        new
                    };
                }
                changed = true;
            }
        }
        changed
    }

    /// Runs ticks on `sim` until tick `end_tick` (exclusive, at most the
    /// run's length) or until the run diverges. `sim` must be at the
    /// loop's time: fresh for tick 0, or given the state of the simulation
    /// that ran the ticks before. Returns true while ticks remain.
    pub fn advance(&mut self, sim: &mut dyn Simulation, end_tick: usize) -> Result<bool, RunError> {
        self.check_shape(sim)?;
        let steps_per_period = steps_per_period(sim.timestep_s(), self.period_s)?;
        let end = end_tick.min(self.samples);
        let started = Instant::now();
        let mut angles = vec![0.0; self.joints];
        let mut poses = vec![Pose::IDENTITY; self.roles.len()];
        while self.status.is_none() && self.tick < end {
            let tick = self.tick;
            let t_s = tick as f64 * self.period_s;
            sim.joint_angles_rad(&mut angles);
            sim.tracked_poses(&mut poses);
            if let Some(reason) = divergence(&angles, &poses, &self.roles, self.divergence_bound_m)
                .or_else(|| {
                    penetration(
                        &poses,
                        &self.roles,
                        &self.grounded,
                        &mut self.sunk_since_s,
                        t_s,
                    )
                })
            {
                self.status = Some(RunStatus::Diverged { t_s, reason });
                break;
            }
            let command = self.command(t_s, &angles);
            self.pending.push_back((t_s + self.delay_s, command));
            self.release_due(t_s);
            let targets = self.targets(0.0);
            sim.set_joint_velocity_targets(&targets);
            self.trajectory.time_s.push(t_s);
            for (track, pose) in self.trajectory.bodies.iter_mut().zip(&poses) {
                track.poses.push(Some(*pose));
            }
            self.angle_rows.push(angles.clone());
            self.command_rows.push(targets);
            self.tick += 1;
            if let Some(status) = self.step_period(sim, t_s, steps_per_period)? {
                self.status = Some(status);
                break;
            }
            if self.tick == self.samples {
                self.status = Some(RunStatus::Completed);
            }
        }
        self.wall_time_s += started.elapsed().as_secs_f64();
        Ok(self.status.is_none())
    }

    /// Steps one control period, releasing delayed commands at the engine
    /// step where they fall due (averaged over the step they fall inside).
    /// `Some` diverged status when the engine
    /// reports itself unstable; an error when it fails otherwise.
    fn step_period(
        &mut self,
        sim: &mut dyn Simulation,
        t_s: f64,
        steps: u64,
    ) -> Result<Option<RunStatus>, RunError> {
        let dt = sim.timestep_s();
        let dynamic = self.stage.params().is_dynamic(StageUnit::Velocity);
        // A moving stage is integrated, and its target set, about every
        // millisecond (at least every engine step).
        let chunk = if dynamic {
            ((1e-3 / dt).round() as u64).max(1)
        } else {
            steps
        };
        let mut done = 0u64;
        while done < steps {
            if done > 0 {
                let released = self.release_due(t_s + done as f64 * dt);
                if released && !dynamic {
                    let targets = self.targets(0.0);
                    sim.set_joint_velocity_targets(&targets);
                }
            }
            // A command falling due inside the coming engine step: that step
            // runs on the time-average of the old and the new command, so a
            // delay acts continuously instead of rounded up to the engine's
            // step (and a fit sees it move the run).
            if let Some(weight) = self.due_inside_step(t_s, done, dt) {
                let old = self.in_force.clone();
                if let Some(&(due, _)) = self.pending.front() {
                    self.release_due(due);
                }
                let blended = old
                    .iter()
                    .zip(&self.in_force)
                    .map(|(o, n)| o + weight * (n - o))
                    .collect();
                let new = std::mem::replace(&mut self.in_force, blended);
                if dynamic {
                    self.stage.advance(&self.in_force, dt);
                    let targets = self.stage.targets().to_vec();
                    sim.set_joint_velocity_targets(&targets);
                } else {
                    let targets = self.targets(0.0);
                    sim.set_joint_velocity_targets(&targets);
                }
                self.in_force = new;
                if let Some(status) = self.take_steps(sim, t_s, done, done + 1)? {
                    return Ok(Some(status));
                }
                done += 1;
                if !dynamic {
                    let targets = self.targets(0.0);
                    sim.set_joint_velocity_targets(&targets);
                }
                continue;
            }
            // Step up to the engine step where the next command falls due,
            // or the one it falls inside (or the stage's next update).
            let next = match self.pending.front() {
                Some((due, _)) => ((due - t_s) / dt + 1e-9).floor().max(0.0) as u64,
                None => steps,
            }
            .min(done + chunk)
            .clamp(done + 1, steps);
            if dynamic {
                // The stage moves over the steps now taken.
                self.stage
                    .advance(&self.in_force, (next - done) as f64 * dt);
                let targets = self.stage.targets().to_vec();
                sim.set_joint_velocity_targets(&targets);
            }
            if let Some(status) = self.take_steps(sim, t_s, done, next)? {
                return Ok(Some(status));
            }
            done = next;
        }
        Ok(None)
    }

    /// The share of the engine step from `done` (steps into the period
    /// that started at `t_s`) that the next pending command is in force
    /// for, when it falls due strictly inside that step.
    fn due_inside_step(&self, t_s: f64, done: u64, dt: f64) -> Option<f64> {
        let (due, _) = self.pending.front()?;
        let x = (due - t_s) / dt - done as f64;
        (x > 1e-9 && x < 1.0 - 1e-9).then_some(1.0 - x)
    }

    /// Takes the engine from step `from` to step `to` of the period that
    /// started at `t_s`. `Some` diverged status when the engine reports
    /// itself unstable; an error when it fails otherwise.
    fn take_steps(
        &mut self,
        sim: &mut dyn Simulation,
        t_s: f64,
        from: u64,
        to: u64,
    ) -> Result<Option<RunStatus>, RunError> {
        match sim.step_n(to - from) {
            Ok(()) => {
                self.engine_steps += to - from;
                Ok(None)
            }
            Err(EngineError::Unstable {
                t_s: at, message, ..
            }) => {
                // Steps taken, up to and including the bad one.
                let dt = sim.timestep_s();
                let into = ((at - t_s) / dt).round().max(0.0) as u64;
                self.engine_steps += (into + 1).clamp(from, to) - from;
                Ok(Some(RunStatus::Diverged {
                    t_s: at,
                    reason: message,
                }))
            }
            Err(e) => Err(e.into()),
        }
    }

    /// The servos' targets from the commands in force through the actuator
    /// stage, advanced by `h_s` (0 for a stage without dynamics, which
    /// then only applies its deadband and limit; a dynamic stage reports
    /// its current targets and is advanced in [`Self::step_period`]).
    fn targets(&mut self, h_s: f64) -> Vec<f64> {
        let params = *self.stage.params();
        if params.is_identity() {
            return self.in_force.clone();
        }
        if params.is_dynamic(StageUnit::Velocity) {
            return self.stage.targets().to_vec();
        }
        self.stage.advance(&self.in_force, h_s).to_vec()
    }

    /// Ends the run: the samples recorded, how it ended, the steps taken
    /// and the wall time of the loop.
    pub fn finish(self) -> RunOutcome {
        let mut trajectory = self.trajectory;
        trajectory.joint_angles_rad = Some(self.angle_rows);
        trajectory.joint_velocity_commands_rad_s = Some(self.command_rows);
        RunOutcome {
            trajectory,
            status: self.status.unwrap_or(RunStatus::Completed),
            engine_steps: self.engine_steps,
            wall_time_s: self.wall_time_s,
        }
    }
}

fn steps_per_period(timestep_s: f64, period_s: f64) -> Result<u64, SceneError> {
    let ratio = period_s / timestep_s;
    if timestep_s.is_nan()
        || timestep_s <= 0.0
        || ratio < 1.0 - 1e-9
        || (ratio - ratio.round()).abs() > 1e-6 * ratio
    {
        return Err(SceneError::Parse {
            path: std::path::PathBuf::new(),
            line: None,
            column: None,
            message: format!(
                "the control period {period_s} s is not a whole number of engine timesteps of {timestep_s} s"
            ),
        });
    }
    Ok(ratio.round() as u64)
}

/// Runs `scene` on a freshly loaded `sim` (see the module documentation).
pub fn run_scene(
    sim: &mut dyn Simulation,
    scene: &Scene,
    options: &RunOptions,
) -> Result<RunOutcome, RunError> {
    run_scene_with(sim, scene, options, &ControlParams::default())
}

/// [`run_scene`] with the controller's share of the physical parameters.
pub fn run_scene_with(
    sim: &mut dyn Simulation,
    scene: &Scene,
    options: &RunOptions,
    control: &ControlParams,
) -> Result<RunOutcome, RunError> {
    scene.steps_per_period(sim.timestep_s())?;
    let mut run = ControllerLoop::new(scene, options, control);
    run.start(sim)?;
    run.advance(sim, usize::MAX)?;
    Ok(run.finish())
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
    simulate_with(
        engine,
        scene,
        robot,
        settings,
        &PhysicalParams::none(),
        options,
    )
}

/// Loads `scene` into `engine` with physical parameters and runs it:
/// [`prepare`], [`Engine::load_with`], [`refuse_unstable`], then the
/// controller loop with the parameters' encoder offsets and latency.
pub fn simulate_with(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
    params: &PhysicalParams,
    options: &RunOptions,
) -> Result<RunOutcome, RunError> {
    let (scene, robot) = prepare(engine, scene, robot, params)?;
    let mut sim = load_prepared(engine, &scene, &robot, settings, params, options)?;
    refuse_unstable(engine, sim.as_ref(), options)?;
    run_scene_with(
        sim.as_mut(),
        &scene,
        options,
        &ControlParams::from_params(params, &scene),
    )
}

/// Checks that `engine` honours every key of `params` and writes the
/// scene and robot keys into copies of `scene` and `robot`
/// ([`PhysicalParams::apply`]).
pub fn prepare(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    params: &PhysicalParams,
) -> Result<(Scene, RobotModel), RunError> {
    params.check_support(engine.name(), &engine.param_support())?;
    Ok(params.apply(scene, robot)?)
}

/// Loads a scene prepared by [`prepare`] with the perturbation's mass and
/// friction factors. It does not refuse unstable settings (a sweep over
/// settings such as `realitygap frontier` measures them): callers that run
/// a user's settings follow it with [`refuse_unstable`].
pub fn load_prepared(
    engine: &dyn Engine,
    scene: &Scene,
    robot: &RobotModel,
    settings: &EngineSettings,
    params: &PhysicalParams,
    options: &RunOptions,
) -> Result<Box<dyn Simulation>, RunError> {
    let variation = options
        .perturbation
        .as_ref()
        .map(|p| p.variation)
        .unwrap_or_default();
    Ok(engine.load_with(scene, robot, settings, &variation, params)?)
}

/// [`EngineError::UnstableSettings`] when `sim` reports settings known to
/// be numerically unstable for its model
/// ([`Simulation::stability_issues`]) and `options` do not allow them:
/// the worst issue in full, the others by joint and value.
pub fn refuse_unstable(
    engine: &dyn Engine,
    sim: &dyn Simulation,
    options: &RunOptions,
) -> Result<(), RunError> {
    let issues = sim.stability_issues();
    if issues.is_empty() || options.allow_unstable {
        return Ok(());
    }
    let mut message = issues[0].message.clone();
    if issues.len() > 1 {
        let others: Vec<String> = issues[1..]
            .iter()
            .map(|i| {
                let joint = i.joint.as_deref().unwrap_or("the model");
                format!("\"{joint}\" ({} = {:.3})", i.quantity, i.value)
            })
            .collect();
        message.push_str(&format!("; also past the bound: {}", others.join(", ")));
    }
    Err(EngineError::UnstableSettings {
        engine: engine.name().to_string(),
        message,
    }
    .into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::SimState;
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
        fn state(&self) -> Result<SimState, EngineError> {
            Ok(SimState {
                time_s: self.t,
                joint_angles_rad: self.q.clone(),
                joint_velocities_rad_s: self.v.clone(),
                joint_velocity_targets_rad_s: self.v.clone(),
                servo_commands: vec![],
                objects: Vec::new(),
                native: None,
            })
        }
        fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
            self.t = state.time_s;
            self.q.copy_from_slice(&state.joint_angles_rad);
            self.v.copy_from_slice(&state.joint_velocity_targets_rad_s);
            Ok(())
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
    fn a_run_handed_over_at_a_tick_equals_one_run() {
        let scene = scene();
        let whole = run_scene(&mut ideal(0.01), &scene, &RunOptions::default()).unwrap();
        let mut a = ideal(0.01);
        let mut run =
            ControllerLoop::new(&scene, &RunOptions::default(), &ControlParams::default());
        run.start(&mut a).unwrap();
        assert!(run.advance(&mut a, 7).unwrap());
        assert_eq!(run.tick(), 7);
        let mut b = ideal(0.01);
        b.set_state(&a.state().unwrap()).unwrap();
        assert!(!run.advance(&mut b, usize::MAX).unwrap());
        assert!(run.is_done());
        let split = run.finish();
        assert_eq!(split.trajectory, whole.trajectory);
        assert_eq!(split.engine_steps, whole.engine_steps);
    }

    #[test]
    fn a_delay_in_seconds_acts_continuously_within_an_engine_step() {
        let scene = scene();
        let control = ControlParams {
            offsets_rad: Vec::new(),
            delay_s: 0.025,
            ..Default::default()
        };
        let out =
            run_scene_with(&mut ideal(0.01), &scene, &RunOptions::default(), &control).unwrap();
        let q = out.trajectory.joint_angles_rad.as_ref().unwrap();
        // The first command (-30 deg/s) reaches the servo at 0.025 s, half
        // way through the third of the period's five steps: that step at
        // the average (-15 deg/s), the last two at -30 deg/s: 0.025 s at
        // -30 deg/s in all.
        assert!(
            (q[1][0].to_degrees() + 0.75).abs() < 1e-9,
            "{}",
            q[1][0].to_degrees()
        );
        // Whole periods as seconds equal the perturbation's whole periods.
        let by_periods = RunOptions {
            perturbation: Some(
                Perturbation {
                    control_delay_periods: 2,
                    ..Default::default()
                }
                .sample(1, 2),
            ),
            ..Default::default()
        };
        let a = run_scene(&mut ideal(0.01), &scene, &by_periods).unwrap();
        let b = run_scene_with(
            &mut ideal(0.01),
            &scene,
            &RunOptions::default(),
            &ControlParams {
                offsets_rad: Vec::new(),
                delay_s: 0.1,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(a.trajectory.joint_angles_rad, b.trajectory.joint_angles_rad);
    }

    #[test]
    fn an_acceleration_limit_ramps_the_servo_targets() {
        let scene = scene();
        let free = run_scene(&mut ideal(0.01), &scene, &RunOptions::default()).unwrap();
        // 100 deg/s^2 at a 0.05 s period: at most 5 deg/s more per period.
        let control = ControlParams {
            max_accel_rad_s2: Some(100f64.to_radians()),
            ..Default::default()
        };
        let out =
            run_scene_with(&mut ideal(0.01), &scene, &RunOptions::default(), &control).unwrap();
        let limited = out.trajectory.joint_velocity_commands_rad_s.unwrap();
        let unlimited = free.trajectory.joint_velocity_commands_rad_s.unwrap();
        // Unlimited, the first command is the clamp (-30 deg/s) at once.
        assert!((unlimited[0][0].to_degrees() + 30.0).abs() < 1e-9);
        for (k, row) in limited.iter().enumerate().take(6) {
            let want = -(5.0 * (k + 1) as f64).min(30.0);
            assert!(
                (row[0].to_degrees() - want).abs() < 1e-9,
                "tick {k}: {} deg/s, want {want}",
                row[0].to_degrees()
            );
        }
        for pair in limited.windows(2) {
            for (a, b) in pair[0].iter().zip(&pair[1]) {
                assert!((b - a).abs().to_degrees() <= 5.0 + 1e-9);
            }
        }
    }

    #[test]
    fn the_actuator_stage_gives_the_servo_a_second_order_response() {
        let scene = scene();
        // The real arm's loop (METHOD.md): w = 19 rad/s, zeta = 0.5.
        let control = ControlParams {
            stage: StageParams {
                frequency_rad_s: Some(19.0),
                damping_ratio: 0.5,
                ..StageParams::default()
            },
            ..Default::default()
        };
        let free = run_scene(&mut ideal(0.001), &scene, &RunOptions::default()).unwrap();
        let out =
            run_scene_with(&mut ideal(0.001), &scene, &RunOptions::default(), &control).unwrap();
        let sent = out.trajectory.joint_velocity_commands_rad_s.unwrap();
        // The target overshoots the command's clamp of 30 deg/s...
        let fastest = sent
            .iter()
            .map(|r| r[0].to_degrees().abs())
            .fold(0.0, f64::max);
        assert!(fastest > 31.0 && fastest < 36.0, "{fastest}");
        // ... and joint 1 overshoots its -10 degree target, and 0 on the
        // way back (sent back to 0 at 0.5 s).
        let q: Vec<f64> = out
            .trajectory
            .joint_angles_rad
            .unwrap()
            .iter()
            .map(|r| r[0].to_degrees())
            .collect();
        let lowest = q.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(lowest < -10.5, "{lowest}");
        assert!(q[q.len() - 1] > 0.5, "{}", q[q.len() - 1]);
        let q_free: Vec<f64> = free
            .trajectory
            .joint_angles_rad
            .unwrap()
            .iter()
            .map(|r| r[0].to_degrees())
            .collect();
        assert!(
            q_free.iter().all(|&a| (-10.0 - 1e-9..=1e-9).contains(&a)),
            "no stage, no overshoot: {q_free:?}"
        );
    }

    #[test]
    fn an_encoder_offset_shifts_where_the_joint_settles() {
        let scene = scene();
        let control = ControlParams {
            offsets_rad: vec![0.0, 1f64.to_radians()],
            delay_s: 0.0,
            ..Default::default()
        };
        let out =
            run_scene_with(&mut ideal(0.01), &scene, &RunOptions::default(), &control).unwrap();
        let last = out.trajectory.joint_angles_rad.unwrap()[19].clone();
        // Target 2 deg measured, so 3 deg true.
        assert!(
            (last[1].to_degrees() - 3.0).abs() < 0.05,
            "{}",
            last[1].to_degrees()
        );
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
    fn an_object_that_stays_deep_in_the_ground_diverges() {
        use crate::pose::Quat;
        let roles = vec!["cube".to_string()];
        let half = Vec3::new(0.0375, 0.0375, 0.0375);
        let grounded = vec![Some((half, 0.0))];
        let at = |z: f64, q: Quat| vec![Pose::new(Vec3::new(0.5, 0.0, z), q)];
        let mut since = vec![None];
        // Resting, and a few millimetres soft: fine.
        for t in [0.0, 0.05, 0.1, 0.2] {
            assert_eq!(
                penetration(
                    &at(0.0375 - 0.004, Quat::IDENTITY),
                    &roles,
                    &grounded,
                    &mut since,
                    t
                ),
                None
            );
        }
        // 21 mm deep (the tuned Rapier cube): flagged once it lasts 0.1 s.
        let deep = at(0.0375 - 0.021, Quat::IDENTITY);
        assert_eq!(penetration(&deep, &roles, &grounded, &mut since, 1.0), None);
        assert_eq!(
            penetration(&deep, &roles, &grounded, &mut since, 1.05),
            None
        );
        let why = penetration(&deep, &roles, &grounded, &mut since, 1.1).unwrap();
        assert!(
            why.contains("'cube' has been 18.8 mm or more inside the ground since t = 1.000 s"),
            "{why}"
        );
        // A spell broken by a sample above the limit starts again.
        let mut since = vec![None];
        assert_eq!(penetration(&deep, &roles, &grounded, &mut since, 0.0), None);
        assert_eq!(
            penetration(
                &at(0.05, Quat::IDENTITY),
                &roles,
                &grounded,
                &mut since,
                0.05
            ),
            None
        );
        assert_eq!(penetration(&deep, &roles, &grounded, &mut since, 0.1), None);
        // A cube on its edge reaches sqrt(2) half-edges down.
        let edge = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 0.0), std::f64::consts::FRAC_PI_4);
        let low = lowest_point_z(&Pose::new(Vec3::new(0.0, 0.0, 0.1), edge), half);
        assert!((low - (0.1 - 0.0375 * 2f64.sqrt())).abs() < 1e-12, "{low}");
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
