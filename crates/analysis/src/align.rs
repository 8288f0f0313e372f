//! Time alignment of recordings to the control-step grid.
//!
//! A real recording runs on its own clock: the arm starts moving 1-2.6 s
//! after the capture starts, at a different moment in every run. Before a
//! real run can be compared step by step with a simulation, a start frame
//! must be chosen, and the capture (e.g. 100 Hz) resampled to the control
//! rate (e.g. 20 Hz). This module offers three ways to choose the start
//! ([`Alignment`]) and one resampler ([`resample`]).

use realitygap_core::{Pose, Quat, Trajectory, Vec3};
use serde::{Deserialize, Serialize};

/// How to choose the first frame of a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case")]
pub enum Alignment {
    /// The same start frame for every run.
    Fixed {
        /// Start frame (0-based index into the recording).
        frame: usize,
    },
    /// Per run: the motion onset minus a lead. The onset is the first frame
    /// at or after `rest_frames.0` whose wrist lies more than `threshold_m`
    /// from the median wrist position over the rest window
    /// `rest_frames.0 .. rest_frames.1`.
    Onset {
        /// Frames to go back from the onset.
        lead_frames: usize,
        /// Rest window `[first, end)` in frames.
        #[serde(default = "default_rest")]
        rest_frames: (usize, usize),
        /// Onset threshold, metres.
        #[serde(default = "default_threshold")]
        threshold_m: f64,
    },
    /// The start frames that best match the scene's kinematic reference
    /// (see [`align_group`]): each run is matched to the reference, then the
    /// runs to their own mean, then the group as a whole to the reference,
    /// searched within `search_frames` before and after the motion onset.
    /// Matching compares displacements from each side's rest position, so
    /// a constant offset between the capture frame and the simulation frame
    /// does not bias it. No simulator is read.
    Estimate {
        /// Search half-width around the onset, frames.
        #[serde(default = "default_search")]
        search_frames: usize,
        /// Rest window used for the onset and the rest position.
        #[serde(default = "default_rest")]
        rest_frames: (usize, usize),
        /// Onset threshold, metres.
        #[serde(default = "default_threshold")]
        threshold_m: f64,
    },
}

fn default_rest() -> (usize, usize) {
    (20, 100)
}
fn default_threshold() -> f64 {
    0.01
}
fn default_search() -> usize {
    300
}

impl Alignment {
    /// The default estimate settings.
    pub fn estimate() -> Alignment {
        Alignment::Estimate {
            search_frames: default_search(),
            rest_frames: default_rest(),
            threshold_m: default_threshold(),
        }
    }
    /// Short description, e.g. `onset - 93 frames`.
    pub fn describe(&self) -> String {
        match self {
            Alignment::Fixed { frame } => format!("fixed start frame {frame}"),
            Alignment::Onset {
                lead_frames,
                threshold_m,
                ..
            } => {
                format!(
                    "motion onset ({:.0} mm) minus {lead_frames} frames",
                    threshold_m * 1000.0
                )
            }
            Alignment::Estimate { search_frames, .. } => {
                format!("estimated from the real runs and the scene alone: each run matched to the kinematic reference, the runs to each other, then the group to the kinematic reference (search +-{search_frames} frames around onset)")
            }
        }
    }
}

/// What to do when a run ends before the analysis window does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EndPolicy {
    /// Repeat the last sample (the study's procedure).
    RepeatLast,
    /// Stop at the last sample; the run contributes fewer steps.
    Cut,
}

/// Component-wise median of the seen positions in `frames` (clamped to the
/// recording); `None` when no position is seen there.
pub fn median_position(positions: &[Option<Vec3>], frames: (usize, usize)) -> Option<Vec3> {
    let end = frames.1.min(positions.len());
    let start = frames.0.min(end);
    let seen: Vec<Vec3> = positions[start..end].iter().flatten().copied().collect();
    if seen.is_empty() {
        return None;
    }
    let med = |f: fn(&Vec3) -> f64| {
        let mut v: Vec<f64> = seen.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        let m = v.len() / 2;
        if v.len() % 2 == 1 {
            v[m]
        } else {
            0.5 * (v[m - 1] + v[m])
        }
    };
    Some(Vec3::new(med(|p| p.x), med(|p| p.y), med(|p| p.z)))
}

/// The motion onset: first frame at or after `rest_frames.0` lying more
/// than `threshold_m` from the median of the rest window. `None` when the
/// body never moves that far (or is never seen in the rest window).
pub fn motion_onset(
    positions: &[Option<Vec3>],
    rest_frames: (usize, usize),
    threshold_m: f64,
) -> Option<usize> {
    let rest = median_position(positions, rest_frames)?;
    positions
        .iter()
        .enumerate()
        .skip(rest_frames.0)
        .find(|(_, p)| p.is_some_and(|p| p.distance(rest) > threshold_m))
        .map(|(i, _)| i)
}

/// Estimates the start frame of a recording against a template motion.
///
/// `template_m` is the template's wrist position per control step;
/// `stride` is capture frames per control step (e.g. 5 for 100 Hz to 20 Hz).
/// Returns the start frame minimising the mean squared distance between the
/// recording's displacement from its rest position and the template's
/// displacement from its first sample.
pub fn estimate_start(
    positions: &[Option<Vec3>],
    template_m: &[Vec3],
    stride: usize,
    rest_frames: (usize, usize),
    threshold_m: f64,
    search_frames: usize,
) -> Option<usize> {
    let rest = median_position(positions, rest_frames)?;
    let t0 = *template_m.first()?;
    let onset = motion_onset(positions, rest_frames, threshold_m).unwrap_or(rest_frames.1);
    let lo = onset.saturating_sub(search_frames);
    let hi = (onset + search_frames).min(positions.len().saturating_sub(1));
    let mut best: Option<(f64, usize)> = None;
    for start in lo..=hi {
        let mut cost = 0.0;
        let mut last = rest;
        for (i, tp) in template_m.iter().enumerate() {
            if let Some(Some(p)) = positions.get(start + i * stride) {
                last = *p;
            }
            let d = (last - rest) - (*tp - t0);
            cost += d.dot(d);
            if best.is_some_and(|(b, _)| cost >= b) {
                break;
            }
        }
        if best.is_none_or(|(b, _)| cost < b) {
            best = Some((cost, start));
        }
    }
    best.map(|(_, s)| s)
}

/// The displacement of a recording from `rest` at frames `start + k *
/// stride` for `steps` steps, holding the last seen sample over gaps and
/// past the end.
fn displacement_track(
    positions: &[Option<Vec3>],
    rest: Vec3,
    start: usize,
    stride: usize,
    steps: usize,
) -> Vec<Vec3> {
    let mut last = rest;
    (0..steps)
        .map(|k| {
            if let Some(Some(p)) = positions.get(start + k * stride) {
                last = *p;
            }
            last - rest
        })
        .collect()
}

/// The start frames of a group of recordings, from [`align_group`].
#[derive(Debug, Clone, PartialEq)]
pub struct GroupAlignment {
    /// Start frame per run (`None` when the run has no rest window or no
    /// motion).
    pub starts: Vec<Option<usize>>,
    /// Frames the whole group was moved by in the last stage (positive:
    /// later), after the runs were aligned to each other.
    pub group_shift_frames: i64,
}

/// Aligns a group of recordings (wrist positions per frame) to a reference
/// track on the control grid (e.g. the kinematic reference, metres per
/// step), from the recordings and the reference alone:
///
/// 1. each run is matched to the reference ([`estimate_start`]);
/// 2. twice: the mean displacement of the `fit` runs becomes a template and
///    every run is matched to it (the runs aligned to each other);
/// 3. the group is shifted as a whole by the number of frames (within
///    `search_frames / 2`) that best matches the `fit` runs' mean
///    displacement to the reference's.
///
/// `stride` is capture frames per control step. Runs outside `fit` are
/// aligned to the template of the `fit` runs and shifted with them.
pub fn align_group(
    runs: &[Vec<Option<Vec3>>],
    fit: &[bool],
    reference_m: &[Vec3],
    stride: usize,
    rest_frames: (usize, usize),
    threshold_m: f64,
    search_frames: usize,
) -> GroupAlignment {
    let stride = stride.max(1);
    let steps = reference_m.len();
    let rests: Vec<Option<Vec3>> = runs
        .iter()
        .map(|r| median_position(r, rest_frames))
        .collect();
    let estimate = |template: &[Vec3]| -> Vec<Option<usize>> {
        runs.iter()
            .map(|r| estimate_start(r, template, stride, rest_frames, threshold_m, search_frames))
            .collect()
    };
    let mut starts = estimate(reference_m);
    let fit_mean = |starts: &[Option<usize>], shift: i64| -> Option<Vec<Vec3>> {
        let mut sum = vec![Vec3::ZERO; steps];
        let mut n = 0usize;
        for (i, r) in runs.iter().enumerate() {
            let (Some(s), Some(rest), true) = (starts[i], rests[i], fit.get(i) == Some(&true))
            else {
                continue;
            };
            let s = s as i64 + shift;
            if s < 0 {
                return None;
            }
            for (acc, d) in sum
                .iter_mut()
                .zip(displacement_track(r, rest, s as usize, stride, steps))
            {
                *acc = *acc + d;
            }
            n += 1;
        }
        (n > 0).then(|| sum.into_iter().map(|p| p.scale(1.0 / n as f64)).collect())
    };
    for _ in 0..2 {
        let Some(template) = fit_mean(&starts, 0) else {
            return GroupAlignment {
                starts,
                group_shift_frames: 0,
            };
        };
        starts = estimate(&template);
    }
    let Some(k0) = reference_m.first().copied() else {
        return GroupAlignment {
            starts,
            group_shift_frames: 0,
        };
    };
    let half = (search_frames / 2) as i64;
    let mut best: Option<(f64, i64)> = None;
    for shift in -half..=half {
        let Some(mean) = fit_mean(&starts, shift) else {
            continue;
        };
        let cost: f64 = mean
            .iter()
            .zip(reference_m)
            .map(|(d, k)| {
                let e = *d - (*k - k0);
                e.dot(e)
            })
            .sum();
        if best.is_none_or(|(b, _)| cost < b) {
            best = Some((cost, shift));
        }
    }
    let shift = best.map_or(0, |(_, s)| s);
    GroupAlignment {
        starts: starts
            .into_iter()
            .map(|s| s.map(|s| (s as i64 + shift).max(0) as usize))
            .collect(),
        group_shift_frames: shift,
    }
}

/// Lag of a track behind a reference track (both per control step,
/// metres), in control steps with sub-step precision: the shift `s`
/// minimising the mean squared difference of the displacements from the
/// first sample, `a * track(k + s)` against `reference(k)` with the best
/// scale `a` for each shift (so that a track that stops short of the
/// reference's amplitude, e.g. an arm sagging under gravity, is not read as
/// early or late), searched within `+-max_steps` and refined by a parabola
/// through the best three shifts.
/// Positive: the track is behind. `None` when the tracks do not overlap
/// or the track has fewer than 8 leading samples (only the samples before
/// its first gap are used).
pub fn lag_steps(track: &[Option<Vec3>], reference: &[Vec3], max_steps: usize) -> Option<f64> {
    let track: Vec<Vec3> = track
        .iter()
        .map_while(|p| p.filter(|p| p.is_finite()))
        .collect();
    if track.len() < 8 {
        return None;
    }
    let (t0, r0) = (*track.first()?, *reference.first()?);
    let n = track.len().min(reference.len()) as i64;
    let max = (max_steps as i64).min(n / 4);
    let cost = |s: i64| -> f64 {
        let (mut tt, mut tr, mut rr, mut count) = (0.0, 0.0, 0.0, 0usize);
        for k in 0..n {
            let j = k + s;
            if j < 0 || j >= n {
                continue;
            }
            let t = track[j as usize] - t0;
            let r = reference[k as usize] - r0;
            tt += t.dot(t);
            tr += t.dot(r);
            rr += r.dot(r);
            count += 1;
        }
        // Residual of the best scale a = tr / tt: rr - tr^2 / tt.
        let residual = if tt > 0.0 { rr - tr * tr / tt } else { rr };
        residual.max(0.0) / count.max(1) as f64
    };
    let costs: Vec<(i64, f64)> = (-max..=max).map(|s| (s, cost(s))).collect();
    let (i, &(s, c)) = costs
        .iter()
        .enumerate()
        .filter(|(_, (_, c))| c.is_finite())
        .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1))?;
    if i == 0 || i + 1 == costs.len() {
        return Some(s as f64);
    }
    let (cm, cp) = (costs[i - 1].1, costs[i + 1].1);
    let denom = cm - 2.0 * c + cp;
    let offset = if denom > 0.0 {
        (0.5 * (cm - cp) / denom).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    Some(s as f64 + offset)
}

/// The start frame chosen for one run, with what it was derived from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunStart {
    /// Chosen start frame (0-based).
    pub start_frame: usize,
    /// Its time in the recording, seconds.
    pub start_s: f64,
    /// Motion onset frame, when found.
    pub onset_frame: Option<usize>,
}

/// Chooses the start frame of one recording.
///
/// `template_m` is needed for [`Alignment::Estimate`]; without it the
/// estimate falls back to the onset with no lead.
pub fn choose_start(
    traj: &Trajectory,
    body: &str,
    alignment: &Alignment,
    stride: usize,
    template_m: Option<&[Vec3]>,
) -> Option<RunStart> {
    let positions = traj.positions(body);
    if positions.is_empty() {
        return None;
    }
    let (start, onset) = match alignment {
        Alignment::Fixed { frame } => (
            *frame,
            motion_onset(&positions, default_rest(), default_threshold()),
        ),
        Alignment::Onset {
            lead_frames,
            rest_frames,
            threshold_m,
        } => {
            let onset = motion_onset(&positions, *rest_frames, *threshold_m)?;
            (onset.saturating_sub(*lead_frames), Some(onset))
        }
        Alignment::Estimate {
            search_frames,
            rest_frames,
            threshold_m,
        } => {
            let onset = motion_onset(&positions, *rest_frames, *threshold_m);
            let start = match template_m {
                Some(t) if !t.is_empty() => estimate_start(
                    &positions,
                    t,
                    stride.max(1),
                    *rest_frames,
                    *threshold_m,
                    *search_frames,
                )?,
                _ => onset?,
            };
            (start, onset)
        }
    };
    if start >= traj.len() {
        return None;
    }
    Some(RunStart {
        start_frame: start,
        start_s: traj.time_s[start] - traj.time_s[0],
        onset_frame: onset,
    })
}

/// Resamples a recording onto the control grid, starting at `start_frame`.
///
/// When `rate_hz * period_s` is a whole number `k`, every `k`-th frame is
/// taken; otherwise positions are interpolated linearly and orientations by
/// normalised linear interpolation at the grid times. Returns the resampled
/// trajectory (time from 0, one sample per step) and the number of steps
/// that had real data; with [`EndPolicy::RepeatLast`] the rest repeat the
/// last sample, with [`EndPolicy::Cut`] the trajectory stops there.
pub fn resample(
    traj: &Trajectory,
    start_frame: usize,
    rate_hz: f64,
    period_s: f64,
    steps: usize,
    end: EndPolicy,
) -> (Trajectory, usize) {
    let mut out = Trajectory::with_bodies(
        &traj
            .bodies
            .iter()
            .map(|b| b.role.as_str())
            .collect::<Vec<_>>(),
    );
    let k = rate_hz * period_s;
    let stride = k.round() as usize;
    let integer = stride >= 1 && (k - stride as f64).abs() < 1e-9;
    let n = traj.len();
    let mut available = 0;
    for i in 0..steps {
        let sample: Option<Vec<Option<Pose>>> = if integer {
            let f = start_frame + i * stride;
            (f < n).then(|| traj.bodies.iter().map(|b| b.poses[f]).collect())
        } else {
            let t = traj.time_s.get(start_frame).copied().unwrap_or(0.0) + i as f64 * period_s;
            interpolate_at(traj, t)
        };
        match sample {
            Some(poses) => {
                available += 1;
                out.time_s.push(i as f64 * period_s);
                for (b, p) in out.bodies.iter_mut().zip(poses) {
                    b.poses.push(p);
                }
            }
            None => match end {
                EndPolicy::Cut => break,
                EndPolicy::RepeatLast => {
                    out.time_s.push(i as f64 * period_s);
                    for b in out.bodies.iter_mut() {
                        let last = b.poses.last().copied().flatten();
                        b.poses.push(last);
                    }
                }
            },
        }
    }
    (out, available)
}

/// Poses of every body at time `t` (seconds, recording clock), by linear
/// interpolation between the two neighbouring frames; `None` outside the
/// recording.
fn interpolate_at(traj: &Trajectory, t: f64) -> Option<Vec<Option<Pose>>> {
    let times = &traj.time_s;
    if times.is_empty() || t < times[0] || t > *times.last()? {
        return None;
    }
    let j = times.partition_point(|&x| x <= t).clamp(1, times.len() - 1);
    let (t0, t1) = (times[j - 1], times[j]);
    let a = if t1 > t0 {
        ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    Some(
        traj.bodies
            .iter()
            .map(|b| match (b.poses[j - 1], b.poses[j]) {
                (Some(p0), Some(p1)) => Some(Pose::new(
                    p0.position_m.lerp(p1.position_m, a),
                    nlerp(p0.orientation, p1.orientation, a),
                )),
                (Some(p), None) if a < 0.5 => Some(p),
                (None, Some(p)) if a >= 0.5 => Some(p),
                _ => None,
            })
            .collect(),
    )
}

/// Normalised linear interpolation of unit quaternions along the short arc.
pub fn nlerp(a: Quat, b: Quat, t: f64) -> Quat {
    let b = if a.dot(b) < 0.0 {
        Quat::new(-b.w, -b.x, -b.y, -b.z)
    } else {
        b
    };
    Quat::new(
        a.w + (b.w - a.w) * t,
        a.x + (b.x - a.x) * t,
        a.y + (b.y - a.y) * t,
        a.z + (b.z - a.z) * t,
    )
    .normalized()
    .unwrap_or(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 100 Hz recording: rest for `rest` frames at z = 0.8, then moving
    /// along x at 0.1 m/s.
    fn ramp(rest: usize, frames: usize) -> Trajectory {
        let mut t = Trajectory::with_bodies(&["wrist"]);
        for i in 0..frames {
            t.time_s.push(i as f64 * 0.01);
            let x = if i < rest {
                0.0
            } else {
                (i - rest) as f64 * 0.001
            };
            t.bodies[0]
                .poses
                .push(Some(Pose::new(Vec3::new(x, 0.0, 0.8), Quat::IDENTITY)));
        }
        t
    }

    #[test]
    fn onset_is_first_frame_beyond_threshold() {
        let t = ramp(150, 400);
        // 10 mm at 1 mm per frame: frame 150 + 11 is the first > 10 mm.
        assert_eq!(
            motion_onset(&t.positions("wrist"), (20, 100), 0.01),
            Some(161)
        );
        let s = choose_start(
            &t,
            "wrist",
            &Alignment::Onset {
                lead_frames: 93,
                rest_frames: (20, 100),
                threshold_m: 0.01,
            },
            5,
            None,
        )
        .unwrap();
        assert_eq!((s.start_frame, s.onset_frame), (68, Some(161)));
    }

    #[test]
    fn estimate_recovers_a_known_offset() {
        let t = ramp(237, 1000);
        // Template: rest for 4 steps then the same ramp at 20 Hz (5 mm/step).
        let template: Vec<Vec3> = (0..100)
            .map(|i| Vec3::new(if i < 4 { 0.0 } else { (i - 4) as f64 * 0.005 }, 0.0, 0.5))
            .collect();
        let s = estimate_start(&t.positions("wrist"), &template, 5, (20, 100), 0.01, 300).unwrap();
        assert_eq!(s, 237 - 20);
    }

    #[test]
    fn group_alignment_recovers_each_runs_offset() {
        // Reference: rest 10 steps then the ramp (5 mm per step).
        let reference: Vec<Vec3> = (0..100)
            .map(|i| Vec3::new(if i < 10 { 0.0 } else { (i - 10) as f64 * 0.005 }, 0.0, 0.5))
            .collect();
        let rests = [237, 180, 301, 150];
        let runs: Vec<Vec<Option<Vec3>>> = rests
            .iter()
            .map(|&r| ramp(r, 1200).positions("wrist"))
            .collect();
        let g = align_group(
            &runs,
            &[true, true, true, false],
            &reference,
            5,
            (20, 100),
            0.01,
            300,
        );
        for (s, r) in g.starts.iter().zip(rests) {
            assert_eq!(*s, Some(r - 50), "{g:?}");
        }
        // A run whose capture is 20 mm off in z aligns the same.
        let shifted: Vec<Option<Vec3>> = runs[0]
            .iter()
            .map(|p| p.map(|p| p + Vec3::new(0.0, 0.0, 0.02)))
            .collect();
        let g2 = align_group(&[shifted], &[true], &reference, 5, (20, 100), 0.01, 300);
        assert_eq!(g2.starts[0], Some(237 - 50));
    }

    #[test]
    fn lag_is_found_with_sub_step_precision() {
        // At rest for 20 steps, then a smooth swing.
        let f = |x: f64| {
            if x < 20.0 {
                0.0
            } else {
                1.0 - ((x - 20.0) * 0.05).cos()
            }
        };
        let reference: Vec<Vec3> = (0..200).map(|i| Vec3::new(f(i as f64), 0.0, 0.0)).collect();
        let behind: Vec<Option<Vec3>> = (0..200)
            .map(|i| Some(Vec3::new(f(i as f64 - 3.4) + 0.1, 0.0, 0.0)))
            .collect();
        let lag = lag_steps(&behind, &reference, 40).unwrap();
        assert!((lag - 3.4).abs() < 0.1, "{lag}");
        let same: Vec<Option<Vec3>> = reference.iter().map(|p| Some(*p)).collect();
        let zero = lag_steps(&same, &reference, 40).unwrap();
        assert!(zero.abs() < 0.05, "{zero}");
        // Stopping short (80 % of the swing) is not a lag.
        let short: Vec<Option<Vec3>> = (0..200)
            .map(|i| Some(Vec3::new(0.8 * f(i as f64 - 3.4), 0.0, 0.0)))
            .collect();
        let lag = lag_steps(&short, &reference, 40).unwrap();
        assert!((lag - 3.4).abs() < 0.1, "{lag}");
        assert!(lag_steps(&[None], &reference, 40).is_none());
    }

    #[test]
    fn resample_strides_and_repeats() {
        let t = ramp(0, 50);
        let (r, avail) = resample(&t, 10, 100.0, 0.05, 12, EndPolicy::RepeatLast);
        assert_eq!((r.len(), avail), (12, 8));
        let x: Vec<f64> = r.positions("wrist").iter().map(|p| p.unwrap().x).collect();
        assert!((x[1] - 0.015).abs() < 1e-12);
        assert_eq!(x[11], x[7]);
        let (r, avail) = resample(&t, 10, 100.0, 0.05, 12, EndPolicy::Cut);
        assert_eq!((r.len(), avail), (8, 8));
    }

    #[test]
    fn resample_interpolates_when_rates_do_not_divide() {
        let mut t = ramp(0, 200);
        for (i, ts) in t.time_s.iter_mut().enumerate() {
            *ts = i as f64 / 120.0; // a 120 Hz capture
        }
        let (r, avail) = resample(&t, 0, 120.0, 0.05, 20, EndPolicy::Cut);
        assert_eq!(avail, 20);
        // x = frame * 1 mm; at t = 0.05*i the frame is 6*i exactly, at 0.025 it is 3.
        let x = r.positions("wrist")[3].unwrap().x;
        assert!((x - 0.018).abs() < 1e-9, "{x}");
        let (r, _) = resample(&t, 0, 120.0, 0.07, 3, EndPolicy::Cut);
        let x = r.positions("wrist")[1].unwrap().x;
        assert!((x - 0.0084).abs() < 1e-9, "{x}");
    }
}
