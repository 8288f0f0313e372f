//! The real arm in joint space: inverse kinematics of a tracked body's 6D
//! capture (`import qualisys --ik`).
//!
//! A motion capture gives a marker body's pose in the capture's own frame.
//! The robot's joint angles follow from it through the robot's kinematics
//! once two unknown transforms are known:
//!
//! - the **registration**, capture frame to world: a rotation about the
//!   vertical and a translation (`world = Rz(yaw) capture + t`). With a
//!   free tilt the fit trades tilt against the shoulder joint, so the tilt
//!   is not fitted (METHOD.md);
//! - the **marker offset**: the marker body's pose in the tracked link's
//!   frame (6 numbers).
//!
//! [`fit`] finds both on training runs by alternating two steps: per-frame
//! inverse kinematics with the transforms fixed ([`solve_frame`]), then a
//! Gauss-Newton step on the ten transform numbers with the joint angles
//! fixed. [`solve_run`] then solves every frame of any run with the fitted
//! transforms.
//!
//! Per frame the joint angles minimise the pose residual (position in
//! millimetres, orientation in degrees, weighted alike) plus a weak pull
//! towards a **prior**: the scene's commanded joint trajectory with perfect
//! tracking ([`crate::kinematic`]), aligned to the run's motion onset. The
//! pull is what keeps the solution on the arm's branch where the pose alone
//! cannot: at the upright start joints 1, 4 and 6 turn about one vertical
//! axis, so only their sum is seen, and the registration's yaw trades
//! against joint 1. Where the pose does determine the angles, the prior's
//! weight (1 mm of residual for 20 degrees) moves them by hundredths of a
//! degree at most.

use crate::align::{choose_start, Alignment};
use crate::kinematic::kinematic_track;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::{Scene, TrackTarget};
use realitygap_core::Trajectory;
use serde::Serialize;

/// Weight of the position residual: 1 mm counts 1.
const POSITION_SCALE_M: f64 = 1e-3;
/// Weight of the orientation residual: 1 degree counts 1.
const ANGLE_SCALE_RAD: f64 = std::f64::consts::PI / 180.0;
/// Weight of the prior while the commanded arm moves: 20 degrees from it
/// count 1.
const PRIOR_SCALE_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// Weight of the prior once the commanded arm has been still for a second
/// (`crate::kinematic::SETTLE_STEPS`): 2 degrees count 1. The real arm's
/// static offsets are under 1 degree (METHOD.md); where the pose decides
/// the angles this moves them by hundredths of a degree, where it does not
/// (the upright pose) the arm is where it was sent.
const SETTLED_PRIOR_SCALE_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Weight of the marker offset's translation in the fit: 2 cm count 1.
/// Where the motion cannot tell the offset from the registration (a scene
/// that turns one joint only), the smallest offset is taken.
const OFFSET_SCALE_M: f64 = 0.02;
/// Frames at the start of a capture that are not counted in its residual:
/// the study's captures have a 12-24 mm spike near frame 5.
pub const SKIP_FRAMES: usize = 20;

/// The capture-to-world registration: `world = Rz(yaw) capture + t`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Registration {
    /// Rotation about the world's vertical, rad.
    pub yaw_rad: f64,
    /// Translation, m.
    pub translation_m: Vec3,
}

impl Registration {
    /// The registration as a pose (capture frame in the world).
    pub fn pose(&self) -> Pose {
        Pose::new(
            self.translation_m,
            Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), self.yaw_rad),
        )
    }
}

/// What [`fit`] found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IkFit {
    /// Capture frame to world.
    pub registration: Registration,
    /// The marker body's pose in the tracked link's frame.
    pub marker_in_link: Pose,
    /// RMS position residual over the frames fitted on, mm.
    pub fit_position_rms_mm: f64,
    /// RMS orientation residual over the frames fitted on, degrees.
    pub fit_angle_rms_deg: f64,
    /// Frames fitted on (every `stride`-th of the training runs).
    pub frames: usize,
}

/// One run solved frame by frame.
#[derive(Debug, Clone, PartialEq)]
pub struct IkRun {
    /// The controlled joints' angles per frame (scene actuator order), rad.
    /// A frame without a pose holds the previous frame's angles.
    pub angles_rad: Vec<Vec<f64>>,
    /// Position residual per frame, mm (`None` without a pose).
    pub position_residual_mm: Vec<Option<f64>>,
    /// Orientation residual per frame, degrees.
    pub angle_residual_deg: Vec<Option<f64>>,
    /// The frame aligned with the scene's time 0 (the prior's start).
    pub start_frame: usize,
}

impl IkRun {
    /// RMS of the position residuals from frame [`SKIP_FRAMES`] on, mm.
    pub fn position_rms_mm(&self) -> f64 {
        rms(self
            .position_residual_mm
            .iter()
            .skip(SKIP_FRAMES)
            .flatten()
            .copied())
    }
    /// RMS of the orientation residuals from frame [`SKIP_FRAMES`] on,
    /// degrees.
    pub fn angle_rms_deg(&self) -> f64 {
        rms(self
            .angle_residual_deg
            .iter()
            .skip(SKIP_FRAMES)
            .flatten()
            .copied())
    }
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        s += v * v;
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// The robot's kinematics for the scene's tracked link and controlled
/// joints.
pub struct IkModel<'a> {
    robot: &'a RobotModel,
    base: Pose,
    link: usize,
    /// Robot joint index of each controlled joint.
    joints: Vec<usize>,
    /// Joint positions of the whole robot at 0 with the held joints set.
    template: Vec<f64>,
    /// Joint limits of the controlled joints, rad.
    limits: Vec<(f64, f64)>,
}

impl<'a> IkModel<'a> {
    /// The kinematics of `scene`'s tracked body `role` (a robot link).
    pub fn new(scene: &Scene, robot: &'a RobotModel, role: &str) -> Result<IkModel<'a>, String> {
        let link_name = scene
            .tracked
            .iter()
            .find(|t| t.role == role)
            .and_then(|t| match &t.target {
                TrackTarget::Link(l) => Some(l.clone()),
                TrackTarget::Object(_) => None,
            })
            .ok_or_else(|| format!("scene '{}' tracks no robot link as '{role}'", scene.name))?;
        let link = robot
            .link_by_name(&link_name)
            .ok_or_else(|| format!("robot '{}' has no link '{link_name}'", robot.name))?;
        let mut joints = Vec::new();
        let mut limits = Vec::new();
        for name in scene.controlled_joints() {
            let j = robot
                .joint_by_name(name)
                .ok_or_else(|| format!("robot '{}' has no joint '{name}'", robot.name))?;
            let l = robot.joints[j]
                .limits
                .map(|l| (l.lower, l.upper))
                .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
            joints.push(j);
            limits.push(l);
        }
        let mut template = vec![0.0; robot.joints.len()];
        for (name, rad) in &scene.robot.held_joints_rad {
            if let Some(j) = robot.joint_by_name(name) {
                template[j] = *rad;
            }
        }
        Ok(IkModel {
            robot,
            base: scene.robot.base,
            link,
            joints,
            template,
            limits,
        })
    }

    /// Number of controlled joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// The tracked link's world pose, and each controlled joint's world
    /// axis and a point on it, at angles `q`.
    fn kinematics(&self, q: &[f64]) -> (Pose, Vec<(Vec3, Vec3)>) {
        let mut full = self.template.clone();
        for (&j, &v) in self.joints.iter().zip(q) {
            full[j] = v;
        }
        let links = self.robot.forward_kinematics(&self.base, &full);
        let axes = self
            .joints
            .iter()
            .map(|&j| {
                let joint = &self.robot.joints[j];
                let child = links[joint.child];
                (child.orientation.rotate(joint.axis), child.position_m)
            })
            .collect();
        (links[self.link], axes)
    }
}

/// The rotation vector of a unit quaternion (axis times angle, rad).
fn rotation_vector(q: Quat) -> Vec3 {
    let q = if q.w < 0.0 {
        Quat::new(-q.w, -q.x, -q.y, -q.z)
    } else {
        q
    };
    let v = Vec3::new(q.x, q.y, q.z);
    let s = v.norm();
    if s < 1e-12 {
        return v.scale(2.0);
    }
    v.scale(2.0 * s.atan2(q.w) / s)
}

/// Residual of one frame: position (m) and orientation (rad, in the world
/// frame) of the marker as the model puts it against `measured` (world).
fn pose_residual(model: &Pose, measured: &Pose) -> (Vec3, Vec3) {
    let dp = model.position_m - measured.position_m;
    let dr = rotation_vector(model.orientation * measured.orientation.conjugate());
    (dp, dr)
}

/// A frame is solved once an accepted step moves no joint by more than
/// this, rad (50 nm at the wrist, far below the capture's noise). At 1e-9
/// the study's joint-space IK took 41 % more time (20.5 s against 14.4,
/// 6.9 against 5.9 million iterations for 477 772 frames) for tables that
/// differ by at most 3.7e-7 of a value.
const STEP_DONE_RAD: f64 = 1e-7;

/// Solves one frame: the controlled joints' angles that put the marker
/// (`marker_in_link` on the tracked link) at `measured` (world), pulled
/// weakly towards `prior`, starting from `start`. Returns the angles and
/// the position (mm) and orientation (degrees) residuals.
pub fn solve_frame(
    model: &IkModel,
    marker_in_link: &Pose,
    measured: &Pose,
    prior: &Prior,
    start: &[f64],
) -> (Vec<f64>, f64, f64) {
    let scale = prior.scale_rad;
    let prior = &prior.angles_rad;
    let n = model.dof();
    let mut q = start.to_vec();
    let mut lambda = 1e-3;
    let cost = |q: &[f64]| -> (f64, Vec<f64>, Vec<(Vec3, Vec3)>, Pose) {
        let (link, axes) = model.kinematics(q);
        let marker = link.compose(marker_in_link);
        let (dp, dr) = pose_residual(&marker, measured);
        let mut r = Vec::with_capacity(6 + n);
        for v in [dp.x, dp.y, dp.z] {
            r.push(v / POSITION_SCALE_M);
        }
        for v in [dr.x, dr.y, dr.z] {
            r.push(v / ANGLE_SCALE_RAD);
        }
        for (a, b) in q.iter().zip(prior) {
            r.push((a - b) / scale);
        }
        let c = r.iter().map(|x| x * x).sum();
        (c, r, axes, marker)
    };
    let (mut c, mut r, mut axes, mut marker) = cost(&q);
    for _ in 0..30 {
        // Jacobian: d(marker position)/dq_j = a_j x (p - o_j),
        // d(orientation)/dq_j = a_j (world), and the prior's identity.
        let rows = 6 + n;
        let mut jac = vec![0.0; rows * n];
        for (j, (a, o)) in axes.iter().enumerate() {
            let dp = a.cross(marker.position_m - *o);
            for (i, v) in [dp.x, dp.y, dp.z].into_iter().enumerate() {
                jac[i * n + j] = v / POSITION_SCALE_M;
            }
            for (i, v) in [a.x, a.y, a.z].into_iter().enumerate() {
                jac[(3 + i) * n + j] = v / ANGLE_SCALE_RAD;
            }
            jac[(6 + j) * n + j] = 1.0 / scale;
        }
        // Normal equations (J^T J + lambda diag) dq = -J^T r.
        let mut jtj = vec![0.0; n * n];
        let mut jtr = vec![0.0; n];
        for i in 0..rows {
            for a in 0..n {
                jtr[a] += jac[i * n + a] * r[i];
                for b in 0..n {
                    jtj[a * n + b] += jac[i * n + a] * jac[i * n + b];
                }
            }
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut m = jtj.clone();
            for a in 0..n {
                m[a * n + a] *= 1.0 + lambda;
                m[a * n + a] += 1e-12;
            }
            let Some(step) = solve_linear(&m, &jtr.iter().map(|v| -v).collect::<Vec<_>>(), n)
            else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = q
                .iter()
                .zip(&step)
                .zip(&model.limits)
                .map(|((v, d), (lo, hi))| (v + d).clamp(*lo, *hi))
                .collect();
            let (tc, tr, ta, tm) = cost(&trial);
            if tc < c {
                let small = step.iter().all(|d| d.abs() < STEP_DONE_RAD);
                q = trial;
                c = tc;
                r = tr;
                axes = ta;
                marker = tm;
                lambda = (lambda * 0.3).max(1e-9);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let (dp, dr) = (
        Vec3::new(r[0], r[1], r[2]).scale(POSITION_SCALE_M),
        Vec3::new(r[3], r[4], r[5]).scale(ANGLE_SCALE_RAD),
    );
    (q, dp.norm() * 1e3, dr.norm().to_degrees())
}

/// [`solve_frame`] from `start` and from `prior`, the better of the two
/// (lower pose residual plus pull): starting again from the prior brings a
/// frame back to the arm's branch when the previous frame's solution slid
/// to an equivalent one (a wrist flip) through a singular pose.
pub fn solve_frame_twice(
    model: &IkModel,
    marker_in_link: &Pose,
    measured: &Pose,
    prior: &Prior,
    start: &[f64],
) -> (Vec<f64>, f64, f64) {
    let a = solve_frame(model, marker_in_link, measured, prior, start);
    let b = solve_frame(model, marker_in_link, measured, prior, &prior.angles_rad);
    let cost = |r: &(Vec<f64>, f64, f64)| {
        let pull: f64 =
            r.0.iter()
                .zip(&prior.angles_rad)
                .map(|(x, y)| ((x - y) / prior.scale_rad).powi(2))
                .sum();
        r.1 * r.1 + r.2 * r.2 + pull
    };
    if cost(&b) < cost(&a) {
        b
    } else {
        a
    }
}

/// Solves `a x = b` for a square `n x n` row-major `a` by Gaussian
/// elimination with partial pivoting; `None` when singular.
fn solve_linear(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| m[i * n + c].abs().total_cmp(&m[j * n + c].abs()))?;
        if m[p * n + c].abs() < 1e-300 || !m[p * n + c].is_finite() {
            return None;
        }
        if p != c {
            for k in 0..n {
                m.swap(p * n + k, c * n + k);
            }
            x.swap(p, c);
        }
        for i in c + 1..n {
            let f = m[i * n + c] / m[c * n + c];
            for k in c..n {
                m[i * n + k] -= f * m[c * n + k];
            }
            x[i] -= f * x[c];
        }
    }
    for c in (0..n).rev() {
        let mut s = x[c];
        for k in c + 1..n {
            s -= m[c * n + k] * x[k];
        }
        x[c] = s / m[c * n + c];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// One recorded run for the fit: its capture of the marker body (capture
/// frame) and its frame rate.
pub struct CaptureRun<'a> {
    /// The run's trajectory (with the marker body's track).
    pub trajectory: &'a Trajectory,
    /// The marker body's role in it (`wrist`).
    pub role: &'a str,
}

/// A frame's prior: the commanded angles (rad) and how strongly they pull
/// (the angle that counts as 1 mm of residual, rad).
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    /// The commanded angles, rad.
    pub angles_rad: Vec<f64>,
    /// The pull's scale, rad.
    pub scale_rad: f64,
}

/// The prior of every frame of `run`: the scene's commanded joint
/// trajectory with perfect tracking (`track`, at the control rate,
/// interpolated; `settled` per tick), time 0 at `start_frame`; the initial
/// angles before it, the last ones after the end.
fn prior_per_frame(
    track: &[Vec<f64>],
    settled: &[bool],
    period_s: f64,
    times: &[f64],
    start_frame: usize,
) -> Vec<Prior> {
    let t0 = times.get(start_frame).copied().unwrap_or(0.0);
    let scale = |i: usize| {
        if settled.get(i).copied().unwrap_or(true) {
            SETTLED_PRIOR_SCALE_RAD
        } else {
            PRIOR_SCALE_RAD
        }
    };
    times
        .iter()
        .map(|&t| {
            if t < t0 {
                // Before the commanded motion: at rest where it starts.
                return Prior {
                    angles_rad: track.first().cloned().unwrap_or_default(),
                    scale_rad: scale(0),
                };
            }
            let tick = (t - t0) / period_s;
            let i = tick.floor() as usize;
            if i + 1 >= track.len() {
                return Prior {
                    angles_rad: track.last().cloned().unwrap_or_default(),
                    scale_rad: scale(track.len().saturating_sub(1)),
                };
            }
            let a = tick - i as f64;
            Prior {
                angles_rad: track[i]
                    .iter()
                    .zip(&track[i + 1])
                    .map(|(x, y)| x + a * (y - x))
                    .collect(),
                scale_rad: scale(i).max(scale(i + 1)),
            }
        })
        .collect()
}

/// What the prior and the alignment of one run are.
struct Prepared {
    priors: Vec<Prior>,
    start_frame: usize,
}

fn prepare_run(scene: &Scene, track: &Commanded, run: &CaptureRun) -> Result<Prepared, String> {
    let t = run.trajectory;
    let rate = if t.len() > 1 {
        (t.len() - 1) as f64 / (t.time_s[t.len() - 1] - t.time_s[0])
    } else {
        1.0
    };
    let stride = (rate * scene.controller.period_s).round().max(1.0) as usize;
    let start = choose_start(
        t,
        run.role,
        &Alignment::estimate(),
        stride,
        Some(&track.wrist_m),
    )
    .ok_or_else(|| "no motion onset found in the capture".to_string())?;
    Ok(Prepared {
        priors: prior_per_frame(
            &track.angles_rad,
            &track.settled,
            scene.controller.period_s,
            &t.time_s,
            start.start_frame,
        ),
        start_frame: start.start_frame,
    })
}

/// The scene's commanded trajectory with perfect tracking, long enough for
/// `longest_s` of capture.
type Commanded = crate::kinematic::KinematicTrack;

fn commanded(
    scene: &Scene,
    robot: &RobotModel,
    role: &str,
    longest_s: f64,
) -> Result<Commanded, String> {
    let steps = (longest_s / scene.controller.period_s).ceil() as usize + 2;
    kinematic_track(scene, robot, role, steps.max(scene.sample_count()))
}

/// Fits the registration and the marker offset on `runs` (see the module
/// documentation), using every `stride`-th frame. The error says which run
/// could not be used.
pub fn fit(
    scene: &Scene,
    robot: &RobotModel,
    runs: &[CaptureRun],
    stride: usize,
) -> Result<IkFit, String> {
    let role = runs.first().map_or("wrist", |r| r.role);
    let model = IkModel::new(scene, robot, role)?;
    let longest = runs
        .iter()
        .filter_map(|r| r.trajectory.time_s.last())
        .fold(0.0f64, |a, &b| a.max(b));
    let track = commanded(scene, robot, role, longest)?;
    // The frames fitted on: (measured capture pose, prior).
    let mut frames: Vec<(Pose, Prior)> = Vec::new();
    for (i, run) in runs.iter().enumerate() {
        let p = prepare_run(scene, &track, run).map_err(|e| format!("run {i}: {e}"))?;
        let poses = &run
            .trajectory
            .bodies
            .iter()
            .find(|b| b.role == run.role)
            .ok_or_else(|| format!("run {i} has no body '{}'", run.role))?
            .poses;
        for f in (p.start_frame.saturating_sub(50)..poses.len()).step_by(stride.max(1)) {
            if let Some(pose) = poses[f] {
                frames.push((pose, p.priors[f].clone()));
            }
        }
    }
    if frames.len() < 10 {
        return Err(format!(
            "only {} captured frames to fit the registration on",
            frames.len()
        ));
    }
    // Start: no offset; the yaw from a coarse scan at the prior's angles,
    // the translation in closed form for each yaw.
    let mut theta = [0.0f64; 10];
    let prior_links: Vec<Pose> = frames
        .iter()
        .map(|(_, q)| model.kinematics(&q.angles_rad).0)
        .collect();
    let mut best = (f64::INFINITY, 0.0, Vec3::ZERO);
    for k in 0..72 {
        let yaw = k as f64 * 5f64.to_radians();
        let r = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), yaw);
        let mut mean = Vec3::ZERO;
        for ((m, _), l) in frames.iter().zip(&prior_links) {
            mean = mean + (l.position_m - r.rotate(m.position_m));
        }
        let t = mean.scale(1.0 / frames.len() as f64);
        let cost: f64 = frames
            .iter()
            .zip(&prior_links)
            .map(|((m, _), l)| {
                let d = l.position_m - (r.rotate(m.position_m) + t);
                d.dot(d)
            })
            .sum();
        if cost < best.0 {
            best = (cost, yaw, t);
        }
    }
    theta[0] = best.1;
    theta[1] = best.2.x;
    theta[2] = best.2.y;
    theta[3] = best.2.z;
    // The marker's orientation in the link: from the prior at the rest pose.
    let reg = |th: &[f64; 10]| {
        Registration {
            yaw_rad: th[0],
            translation_m: Vec3::new(th[1], th[2], th[3]),
        }
        .pose()
    };
    let offset = |th: &[f64; 10]| {
        let rv = Vec3::new(th[7], th[8], th[9]);
        let angle = rv.norm();
        let q = if angle > 0.0 {
            Quat::from_axis_angle(rv.scale(1.0 / angle), angle)
        } else {
            Quat::IDENTITY
        };
        Pose::new(Vec3::new(th[4], th[5], th[6]), q)
    };
    {
        let world = reg(&theta).compose(&frames[0].0);
        let link = prior_links[0];
        // link ∘ offset = world  =>  offset = link^-1 ∘ world.
        let inv = link.orientation.conjugate();
        let o = Pose::new(
            inv.rotate(world.position_m - link.position_m),
            inv * world.orientation,
        );
        let rv = rotation_vector(o.orientation);
        theta[4] = 0.0;
        theta[5] = 0.0;
        theta[6] = 0.0;
        theta[7] = rv.x;
        theta[8] = rv.y;
        theta[9] = rv.z;
    }
    let mut angles: Vec<Vec<f64>> = frames.iter().map(|(_, q)| q.angles_rad.clone()).collect();
    let residuals = |th: &[f64; 10], angles: &[Vec<f64>]| -> Vec<f64> {
        let (rg, off) = (reg(th), offset(th));
        let mut r = Vec::with_capacity(6 * frames.len());
        for ((m, _), q) in frames.iter().zip(angles) {
            let world = rg.compose(m);
            let marker = model.kinematics(q).0.compose(&off);
            let (dp, dr) = pose_residual(&marker, &world);
            r.extend([dp.x, dp.y, dp.z].map(|v| v / POSITION_SCALE_M));
            r.extend([dr.x, dr.y, dr.z].map(|v| v / ANGLE_SCALE_RAD));
        }
        // The offset's translation, weakly towards none (see
        // OFFSET_SCALE_M), counted as one frame's worth per 100 frames.
        let w = (frames.len() as f64 / 100.0).sqrt() / OFFSET_SCALE_M;
        r.extend([th[4], th[5], th[6]].map(|v| v * w));
        r
    };
    for _round in 0..8 {
        // (a) the frames' angles with the transforms fixed.
        let (rg, off) = (reg(&theta), offset(&theta));
        for ((m, prior), q) in frames.iter().zip(angles.iter_mut()) {
            *q = solve_frame_twice(&model, &off, &rg.compose(m), prior, q).0;
        }
        // (b) Gauss-Newton steps on the transforms with the angles fixed.
        for _ in 0..4 {
            let r0 = residuals(&theta, &angles);
            let c0: f64 = r0.iter().map(|v| v * v).sum();
            let mut jac = vec![vec![0.0; r0.len()]; 10];
            for (k, col) in jac.iter_mut().enumerate() {
                let h = if k == 0 || k >= 7 { 1e-6 } else { 1e-7 };
                let mut t = theta;
                t[k] += h;
                let r1 = residuals(&t, &angles);
                for (c, (a, b)) in col.iter_mut().zip(r1.iter().zip(&r0)) {
                    *c = (a - b) / h;
                }
            }
            let mut jtj = vec![0.0; 100];
            let mut rhs = vec![0.0; 10];
            for a in 0..10 {
                rhs[a] = -jac[a].iter().zip(&r0).map(|(x, y)| x * y).sum::<f64>();
                for b in 0..10 {
                    jtj[a * 10 + b] = jac[a].iter().zip(&jac[b]).map(|(x, y)| x * y).sum();
                }
                jtj[a * 10 + a] *= 1.0 + 1e-6;
            }
            let Some(step) = solve_linear(&jtj, &rhs, 10) else {
                break;
            };
            let mut t = theta;
            for (v, d) in t.iter_mut().zip(&step) {
                *v += d;
            }
            let c1: f64 = residuals(&t, &angles).iter().map(|v| v * v).sum();
            if c1 < c0 {
                theta = t;
            } else {
                break;
            }
        }
    }
    let (rg, off) = (reg(&theta), offset(&theta));
    let (mut sp, mut sa) = (0.0, 0.0);
    for ((m, prior), q) in frames.iter().zip(angles.iter_mut()) {
        let (a, p, o) = solve_frame_twice(&model, &off, &rg.compose(m), prior, q);
        *q = a;
        sp += p * p;
        sa += o * o;
    }
    let n = frames.len() as f64;
    Ok(IkFit {
        registration: Registration {
            yaw_rad: theta[0],
            translation_m: Vec3::new(theta[1], theta[2], theta[3]),
        },
        marker_in_link: off,
        fit_position_rms_mm: (sp / n).sqrt(),
        fit_angle_rms_deg: (sa / n).sqrt(),
        frames: frames.len(),
    })
}

/// Solves every frame of `run` with the fitted transforms, each frame
/// starting from the previous one's angles.
pub fn solve_run(
    scene: &Scene,
    robot: &RobotModel,
    fit: &IkFit,
    run: &CaptureRun,
) -> Result<IkRun, String> {
    let model = IkModel::new(scene, robot, run.role)?;
    let longest = run.trajectory.time_s.last().copied().unwrap_or(0.0);
    let track = commanded(scene, robot, run.role, longest)?;
    let p = prepare_run(scene, &track, run)?;
    let poses = &run
        .trajectory
        .bodies
        .iter()
        .find(|b| b.role == run.role)
        .ok_or_else(|| format!("the run has no body '{}'", run.role))?
        .poses;
    let rg = fit.registration.pose();
    let mut q = p
        .priors
        .first()
        .map(|p| p.angles_rad.clone())
        .unwrap_or_default();
    let mut out = IkRun {
        angles_rad: Vec::with_capacity(poses.len()),
        position_residual_mm: Vec::with_capacity(poses.len()),
        angle_residual_deg: Vec::with_capacity(poses.len()),
        start_frame: p.start_frame,
    };
    for (f, pose) in poses.iter().enumerate() {
        match pose {
            Some(m) => {
                let (a, dp, da) = solve_frame_twice(
                    &model,
                    &fit.marker_in_link,
                    &rg.compose(m),
                    &p.priors[f],
                    &q,
                );
                q = a;
                out.position_residual_mm.push(Some(dp));
                out.angle_residual_deg.push(Some(da));
            }
            None => {
                out.position_residual_mm.push(None);
                out.angle_residual_deg.push(None);
            }
        }
        out.angles_rad.push(q.clone());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_vectors_of_known_rotations() {
        let axis = Vec3::new(0.0, 0.6, 0.8);
        let v = rotation_vector(Quat::from_axis_angle(axis, 0.3));
        assert!((v - axis.scale(0.3)).norm() < 1e-12, "{v:?}");
        let v = rotation_vector(Quat::from_axis_angle(axis, -2.9));
        assert!((v - axis.scale(-2.9)).norm() < 1e-9, "{v:?}");
        assert_eq!(rotation_vector(Quat::IDENTITY), Vec3::ZERO);
    }

    #[test]
    fn linear_systems_are_solved_and_singular_ones_refused() {
        let a = [2.0, 1.0, 1.0, 3.0];
        let x = solve_linear(&a, &[3.0, 5.0], 2).unwrap();
        assert!((x[0] - 0.8).abs() < 1e-12 && (x[1] - 1.4).abs() < 1e-12);
        assert!(solve_linear(&[1.0, 2.0, 2.0, 4.0], &[1.0, 1.0], 2).is_none());
    }

    #[test]
    fn priors_follow_the_commanded_track_from_the_start_frame() {
        let track = vec![vec![0.0], vec![1.0], vec![2.0]];
        let settled = [true, false, true];
        let times: Vec<f64> = (0..8).map(|i| i as f64 * 0.025).collect();
        let p = prior_per_frame(&track, &settled, 0.05, &times, 2);
        assert_eq!(
            p[0].angles_rad,
            vec![0.0],
            "before the start: the initial angles"
        );
        assert_eq!(p[0].scale_rad, SETTLED_PRIOR_SCALE_RAD);
        assert_eq!(p[2].angles_rad, vec![0.0]);
        assert!((p[3].angles_rad[0] - 0.5).abs() < 1e-12);
        assert_eq!(p[3].scale_rad, PRIOR_SCALE_RAD, "moving: the weak pull");
        assert_eq!(p[4].angles_rad, vec![1.0]);
        assert_eq!(p[7].angles_rad, vec![2.0], "after the end: the last angles");
    }
}
