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
    /// Per run: the start frame that best matches a template motion (the
    /// mean of the simulated sources), searched within `search_frames`
    /// before and after the motion onset. Matching compares displacements
    /// from each side's rest position, so a constant offset between the
    /// capture frame and the simulation frame does not bias it.
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
                format!("estimated per run against the simulated mean (search +-{search_frames} frames around onset)")
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
