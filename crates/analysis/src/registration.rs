//! Capture-frame registration: the rigid transform that carries positions
//! measured in the motion-capture system's frame into the simulation world.
//!
//! `world = R * capture + t`, with `R` a unit quaternion and `t` in metres.
//! It is written as `registration.json`:
//!
//! ```json
//! {"rotation_wxyz": [1.0, 0.0, 0.0, 0.0], "translation_m": [0.0, 0.0, 0.0]}
//! ```
//!
//! [`fit_rigid`] estimates it from corresponding points by Horn's
//! closed-form quaternion method (the eigenvector of the largest eigenvalue
//! of a symmetric 4x4 matrix), optionally trimming outlying pairs once.

use realitygap_core::{Pose, Quat, Trajectory, Vec3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A rigid transform from the capture frame into the world:
/// `world = rotation * capture + translation_m`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    /// Rotation, capture frame to world (unit quaternion).
    pub rotation: Quat,
    /// Translation, metres (world frame).
    pub translation_m: Vec3,
}

/// A registration file that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("registration file {file}: {message}")]
pub struct RegistrationError {
    /// The file (or `<text>`), as given.
    pub file: String,
    /// What is wrong, naming the field.
    pub message: String,
}

/// How far from 1 a quaternion's norm may be in a registration file.
pub const UNIT_TOLERANCE: f64 = 1e-6;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RegistrationFile {
    rotation_wxyz: Vec<serde_json::Value>,
    translation_m: Vec<serde_json::Value>,
}

impl Registration {
    /// The identity: the capture frame is the world.
    pub const IDENTITY: Registration = Registration {
        rotation: Quat::IDENTITY,
        translation_m: Vec3::ZERO,
    };

    /// Maps a capture-frame position (m) into the world (m).
    pub fn apply(&self, capture_m: Vec3) -> Vec3 {
        self.rotation.rotate(capture_m) + self.translation_m
    }

    /// Maps a capture-frame pose into the world: position as
    /// [`Registration::apply`], orientation pre-multiplied by the rotation.
    pub fn apply_pose(&self, pose: &Pose) -> Pose {
        Pose::new(
            self.apply(pose.position_m),
            self.rotation * pose.orientation,
        )
    }

    /// Applies the transform to every pose of every body of a trajectory.
    pub fn apply_trajectory(&self, traj: &mut Trajectory) {
        for body in &mut traj.bodies {
            for p in body.poses.iter_mut().flatten() {
                *p = self.apply_pose(p);
            }
        }
    }

    /// Rotation angle, degrees.
    pub fn angle_deg(&self) -> f64 {
        self.rotation.angle_to(Quat::IDENTITY).to_degrees()
    }

    /// Rotation as a unit axis and an angle in degrees (axis x when the
    /// angle is 0).
    pub fn axis_angle_deg(&self) -> (Vec3, f64) {
        let q = if self.rotation.w < 0.0 {
            Quat::new(
                -self.rotation.w,
                -self.rotation.x,
                -self.rotation.y,
                -self.rotation.z,
            )
        } else {
            self.rotation
        };
        let v = Vec3::new(q.x, q.y, q.z);
        let s = v.norm();
        let angle = 2.0 * s.atan2(q.w);
        if s < 1e-15 {
            (Vec3::new(1.0, 0.0, 0.0), 0.0)
        } else {
            (v.scale(1.0 / s), angle.to_degrees())
        }
    }

    /// The JSON text of `registration.json`.
    pub fn to_json(&self) -> String {
        let q = self.rotation;
        let t = self.translation_m;
        serde_json::to_string_pretty(&serde_json::json!({
            "rotation_wxyz": [q.w, q.x, q.y, q.z],
            "translation_m": [t.x, t.y, t.z],
        }))
        .unwrap_or_default()
            + "\n"
    }

    /// Parses `registration.json` text; `file` names it in errors. The
    /// quaternion must have unit norm within [`UNIT_TOLERANCE`] and every
    /// number must be finite.
    pub fn from_json_str(text: &str, file: &str) -> Result<Registration, RegistrationError> {
        let err = |message: String| RegistrationError {
            file: file.to_string(),
            message,
        };
        let raw: RegistrationFile = serde_json::from_str(text).map_err(|e| {
            err(format!(
                "{} (expected {{\"rotation_wxyz\": [w, x, y, z], \"translation_m\": [x, y, z]}})",
                e
            ))
        })?;
        let numbers = |field: &str, values: &[serde_json::Value], n: usize| {
            if values.len() != n {
                return Err(err(format!(
                    "`{field}` must hold {n} numbers, found {}",
                    values.len()
                )));
            }
            values
                .iter()
                .enumerate()
                .map(|(i, v)| match v.as_f64() {
                    Some(x) if x.is_finite() => Ok(x),
                    _ => Err(err(format!(
                        "`{field}`[{i}] must be a finite number, found {v}"
                    ))),
                })
                .collect::<Result<Vec<f64>, _>>()
        };
        let q = numbers("rotation_wxyz", &raw.rotation_wxyz, 4)?;
        let t = numbers("translation_m", &raw.translation_m, 3)?;
        let rotation = Quat::new(q[0], q[1], q[2], q[3]);
        let norm = rotation.norm();
        if (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Err(err(format!(
                "`rotation_wxyz` must be a unit quaternion, its norm is {norm}"
            )));
        }
        Ok(Registration {
            rotation: rotation.normalized().unwrap_or(Quat::IDENTITY),
            translation_m: Vec3::new(t[0], t[1], t[2]),
        })
    }

    /// Reads and checks `registration.json`; errors name the file.
    pub fn from_file(path: &Path) -> Result<Registration, RegistrationError> {
        let text = std::fs::read_to_string(path).map_err(|e| RegistrationError {
            file: path.display().to_string(),
            message: format!("cannot read: {e}"),
        })?;
        Registration::from_json_str(&text, &path.display().to_string())
    }
}

/// A fitted registration with its quality.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RigidFit {
    /// The transform found.
    pub registration: Registration,
    /// Root-mean-square distance of the kept pairs after the fit, metres.
    pub residual_rms_m: f64,
    /// Largest distance of a kept pair after the fit, metres.
    pub residual_max_m: f64,
    /// Pairs used in the final fit.
    pub pairs_used: usize,
    /// Pairs left out as outliers by the trimming pass.
    pub pairs_trimmed: usize,
}

/// Least-squares rigid transform taking `capture_m[i]` onto `world_m[i]`
/// (Horn 1987). Pairs with a non-finite coordinate are skipped. `None`
/// with fewer than 3 usable pairs or when the points are all collinear.
pub fn fit_rigid_once(capture_m: &[Vec3], world_m: &[Vec3]) -> Option<Registration> {
    let pairs: Vec<(Vec3, Vec3)> = capture_m
        .iter()
        .zip(world_m)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let ca = pairs.iter().fold(Vec3::ZERO, |s, p| s + p.0).scale(1.0 / n);
    let cb = pairs.iter().fold(Vec3::ZERO, |s, p| s + p.1).scale(1.0 / n);
    // Cross-covariance S[i][j] = sum a_i b_j of the centred points.
    let mut s = [[0.0f64; 3]; 3];
    for (a, b) in &pairs {
        let a = (*a - ca).to_array();
        let b = (*b - cb).to_array();
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += a[i] * b[j];
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let m = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (values, vectors) = jacobi_eigen4(m);
    let mut order = [0usize, 1, 2, 3];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    // Collinear (or coincident) points: the top eigenvalue is not unique.
    let scale = values.iter().map(|v| v.abs()).fold(0.0, f64::max);
    if scale.is_nan() || scale <= 0.0 || values[order[0]] - values[order[1]] < 1e-12 * scale {
        return None;
    }
    let v = vectors[order[0]];
    let rotation = Quat::new(v[0], v[1], v[2], v[3]).normalized()?;
    Some(Registration {
        rotation,
        translation_m: cb - rotation.rotate(ca),
    })
}

/// Passes of [`fit_rigid`]'s trimming.
const TRIM_PASSES: usize = 3;

/// [`fit_rigid_once`], then up to three trimming passes: pairs farther
/// than `3 x median distance`, clamped to `[trim_floor_m, trim_ceiling_m]`,
/// from their position under the current fit are left out and the
/// transform is fitted again on the rest, until the set kept stops
/// changing. Reports the residual of the pairs kept. (The ceiling keeps
/// deviations no frame error explains, such as a hand resting on an
/// object, out of the fit even when they pull the first fit towards them.)
pub fn fit_rigid(
    capture_m: &[Vec3],
    world_m: &[Vec3],
    trim_floor_m: f64,
    trim_ceiling_m: f64,
) -> Option<RigidFit> {
    let usable: Vec<(Vec3, Vec3)> = capture_m
        .iter()
        .zip(world_m)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    let (all_a, all_b): (Vec<Vec3>, Vec<Vec3>) = usable.iter().copied().unzip();
    let mut registration = fit_rigid_once(&all_a, &all_b)?;
    let mut keep = vec![true; usable.len()];
    for _ in 0..TRIM_PASSES {
        let d: Vec<f64> = usable
            .iter()
            .map(|(a, b)| registration.apply(*a).distance(*b))
            .collect();
        let mut sorted = d.clone();
        sorted.sort_by(f64::total_cmp);
        let limit = (3.0 * sorted[sorted.len() / 2])
            .min(trim_ceiling_m)
            .max(trim_floor_m);
        let next: Vec<bool> = d.iter().map(|d| *d <= limit).collect();
        if next == keep {
            break;
        }
        let (ka, kb): (Vec<Vec3>, Vec<Vec3>) = usable
            .iter()
            .zip(&next)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p)
            .unzip();
        match fit_rigid_once(&ka, &kb) {
            Some(r) => {
                registration = r;
                keep = next;
            }
            None => break,
        }
    }
    let kept: Vec<f64> = usable
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|((a, b), _)| registration.apply(*a).distance(*b))
        .collect();
    Some(RigidFit {
        registration,
        residual_rms_m: (kept.iter().map(|d| d * d).sum::<f64>() / kept.len().max(1) as f64).sqrt(),
        residual_max_m: kept.iter().copied().fold(0.0, f64::max),
        pairs_used: kept.len(),
        pairs_trimmed: usable.len() - kept.len(),
    })
}

/// Eigen-decomposition of a symmetric 4x4 matrix by cyclic Jacobi
/// rotations: the eigenvalues and, for each, its unit eigenvector.
fn jacobi_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (rp, rq) = (a[p], a[q]);
                for (k, (apk, aqk)) in rp.iter().zip(rq).enumerate() {
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let values = [a[0][0], a[1][1], a[2][2], a[3][3]];
    let mut vectors = [[0.0; 4]; 4];
    for (j, vec) in vectors.iter_mut().enumerate() {
        for (i, x) in vec.iter_mut().enumerate() {
            *x = v[i][j];
        }
    }
    (values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::controller::SplitMix64;

    /// A wrist-like path: a 3-D Lissajous curve over a 0.6 m box.
    fn path(n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.05;
                Vec3::new(
                    0.3 * (0.7 * t).sin(),
                    0.2 * (1.1 * t).cos(),
                    0.5 + 0.3 * (0.4 * t).sin(),
                )
            })
            .collect()
    }

    fn known() -> Registration {
        Registration {
            rotation: Quat::from_axis_angle(Vec3::new(0.2, -0.5, 1.0).scale(1.0 / 1.1358), 0.09),
            translation_m: Vec3::new(0.012, -0.007, 0.004),
        }
    }

    fn errors(found: &Registration, truth: &Registration) -> (f64, f64) {
        (
            found.translation_m.distance(truth.translation_m),
            found.rotation.angle_to(truth.rotation).to_degrees(),
        )
    }

    #[test]
    fn a_known_transform_is_recovered_exactly() {
        let truth = known();
        let world = path(400);
        let inv = truth.rotation.conjugate();
        let capture: Vec<Vec3> = world
            .iter()
            .map(|p| inv.rotate(*p - truth.translation_m))
            .collect();
        let fit = fit_rigid(&capture, &world, 0.005, 0.02).unwrap();
        let (dt, da) = errors(&fit.registration, &truth);
        assert!(dt < 1e-4 && da < 0.05, "{dt} m, {da} deg");
        assert!(dt < 1e-9 && da < 1e-6, "exact data: {dt} m, {da} deg");
        assert!(fit.residual_rms_m < 1e-9);
        assert_eq!((fit.pairs_used, fit.pairs_trimmed), (400, 0));
    }

    /// Tolerance with gaps and noise: 1 mm Gaussian noise per axis on 400
    /// points, every 7th point missing (NaN), 2 % gross outliers of 5 cm:
    /// the outliers are trimmed and the transform is within 0.5 mm and 0.1
    /// degrees.
    #[test]
    fn gaps_noise_and_outliers_stay_within_the_stated_tolerance() {
        let truth = known();
        let world = path(400);
        let inv = truth.rotation.conjugate();
        let mut rng = SplitMix64::new(17);
        let capture: Vec<Vec3> = world
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if i % 7 == 3 {
                    return Vec3::new(f64::NAN, 0.0, 0.0);
                }
                let mut c = inv.rotate(*p - truth.translation_m);
                c = c + Vec3::new(rng.normal(), rng.normal(), rng.normal()).scale(0.001);
                if i % 50 == 11 {
                    c = c + Vec3::new(0.05, 0.0, 0.0);
                }
                c
            })
            .collect();
        let fit = fit_rigid(&capture, &world, 0.005, 0.02).unwrap();
        let (dt, da) = errors(&fit.registration, &truth);
        assert!(dt < 5e-4 && da < 0.1, "{dt} m, {da} deg");
        // 8 outliers, one of them on a gap.
        assert_eq!(fit.pairs_trimmed, 7, "{fit:?}");
        assert!((fit.residual_rms_m - 0.0017).abs() < 0.0005, "{fit:?}");
    }

    #[test]
    fn degenerate_input_gives_none() {
        let line: Vec<Vec3> = (0..10).map(|i| Vec3::new(i as f64, 0.0, 0.0)).collect();
        assert!(fit_rigid_once(&line, &line).is_none());
        assert!(fit_rigid_once(&line[..2], &line[..2]).is_none());
    }

    #[test]
    fn json_round_trip_and_bad_files_name_file_and_field() {
        let r = known();
        let back = Registration::from_json_str(&r.to_json(), "r.json").unwrap();
        assert!(errors(&back, &r).0 < 1e-15 && errors(&back, &r).1 < 1e-9);
        let bad = |text: &str| {
            Registration::from_json_str(text, "reg.json")
                .unwrap_err()
                .to_string()
        };
        let e = bad(r#"{"rotation_wxyz": [1, 0.1, 0, 0], "translation_m": [0, 0, 0]}"#);
        assert!(
            e.contains("reg.json") && e.contains("unit quaternion"),
            "{e}"
        );
        let e = bad(r#"{"rotation_wxyz": [1, 0, 0, 0], "translation_m": [0, NaN, 0]}"#);
        assert!(e.contains("reg.json"), "{e}");
        let e = bad(r#"{"rotation_wxyz": [1, 0, 0, 0], "translation_m": [0, "NaN", 0]}"#);
        assert!(
            e.contains("translation_m`[1]") && e.contains("finite"),
            "{e}"
        );
        let e = bad(r#"{"rotation_wxyz": [1, 0, 0, 0]}"#);
        assert!(e.contains("reg.json") && e.contains("translation_m"), "{e}");
        let e = bad(r#"{"rotation_wxyz": [1, 0, 0], "translation_m": [0, 0, 0]}"#);
        assert!(e.contains("4 numbers"), "{e}");
        let e = Registration::from_file(Path::new("/nonexistent/reg.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/reg.json"), "{e}");
    }
}
