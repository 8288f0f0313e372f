//! Every published toss against the facts of the data's README: 80-442
//! samples, unit quaternions, the linear velocity the backward difference
//! of position (world frame), the angular velocity that of the orientation
//! in the body frame, the cube at rest one half-width above the ground
//! (about 1 mm lower). On `../shared/contactnets/tosses` (456 files) when
//! it is beside the project; on the three committed tosses otherwise (a
//! clone without `../shared`), with the same checks. Prints the numbers.

use realitygap_contactnets::{list_tosses, read_tosses, Experiment, Toss};
use realitygap_core::{Quat, Vec3};
use std::path::PathBuf;

/// The crate's folder at run time (cargo sets it; so does
/// scripts/test-without-shared for a copy of the project), else at build
/// time: the copy's `../shared` is what counts, not the build's.
fn crate_dir() -> PathBuf {
    std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .filter(|d| d.join("../../Cargo.toml").is_file())
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")))
}

/// `../shared/contactnets/tosses` beside the project, when it is there.
fn published_tosses() -> Option<PathBuf> {
    let dir = crate_dir().join("../../../shared/contactnets/tosses");
    dir.is_dir().then_some(dir)
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
    if s < 1e-15 {
        return v.scale(2.0);
    }
    v.scale(2.0 * s.atan2(q.w) / s)
}

/// Each component's median of three vectors.
fn median3(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let m = |x: f64, y: f64, z: f64| x.max(y).min(x.min(y).max(z));
    Vec3::new(m(a.x, b.x, c.x), m(a.y, b.y, c.y), m(a.z, b.z, c.z))
}

/// Mean |estimate - recorded| of the angular velocity (rad/s) over the
/// inner samples, with the relative rotation of each step taken in the
/// body frame (`q(k-1)^-1 q(k)`) or in the world frame (`q(k) q(k-1)^-1`),
/// then a 3-sample median filter, as the README describes.
fn angular_error(toss: &Toss, dt: f64, body_frame: bool) -> f64 {
    let q = |k: usize| toss.poses[k].orientation;
    let step: Vec<Vec3> = (1..toss.len())
        .map(|k| {
            let rel = if body_frame {
                q(k - 1).conjugate() * q(k)
            } else {
                q(k) * q(k - 1).conjugate()
            };
            rotation_vector(rel).scale(1.0 / dt)
        })
        .collect();
    let mut sum = 0.0;
    let mut n = 0;
    for i in 1..step.len() - 1 {
        let estimate = median3(step[i - 1], step[i], step[i + 1]);
        // step[i] is the rotation from sample i to i + 1.
        let recorded = toss.twists[i + 1].angular_body_rad_s;
        sum += estimate.distance(recorded);
        n += 1;
    }
    sum / n as f64
}

#[test]
fn every_toss_has_the_published_facts() {
    let (dir, all) = match published_tosses() {
        Some(d) => (d, true),
        None => (crate_dir().join("tests/data/tosses"), false),
    };
    if !all {
        println!(
            "../shared/contactnets/tosses is not beside the project: checking the committed tosses instead"
        );
    }
    let experiment = Experiment::published();
    let files = list_tosses(&dir).unwrap();
    let tosses = read_tosses(&files, &experiment).unwrap();
    if all {
        assert_eq!(tosses.len(), 456, "the README's 456 tosses");
    }
    let dt = experiment.dt_s;
    let half_width = experiment.half_width_m();
    let (mut t_min, mut t_max) = (usize::MAX, 0);
    let mut norm_error: f64 = 0.0;
    let mut velocity_errors = Vec::new();
    let mut filtered_errors = Vec::new();
    let mut rest_low_mm = Vec::new();
    let (mut body_sum, mut world_sum, mut w_sum) = (0.0, 0.0, 0.0);
    for toss in &tosses {
        let n = toss.len();
        t_min = t_min.min(n);
        t_max = t_max.max(n);
        assert!((80..=442).contains(&n), "toss {}: {n} samples", toss.number);
        assert_eq!(toss.time_s[n - 1], (n - 1) as f64 * dt);
        norm_error = norm_error.max(toss.max_quat_norm_error);
        // Linear velocity: the backward difference of position, world
        // frame: mean |v - (p(k) - p(k-1)) / dt| over mean |v|.
        let (mut e, mut v) = (0.0, 0.0);
        for k in 1..n {
            let diff = (toss.poses[k].position_m - toss.poses[k - 1].position_m).scale(1.0 / dt);
            e += diff.distance(toss.twists[k].linear_m_s);
            v += toss.twists[k].linear_m_s.norm();
        }
        velocity_errors.push(e / v);
        // The same, the difference through a 3-sample median filter (as
        // the angular velocity's): closer still.
        let diff =
            |k: usize| (toss.poses[k].position_m - toss.poses[k - 1].position_m).scale(1.0 / dt);
        let (mut e, mut v) = (0.0, 0.0);
        for k in 2..n - 1 {
            let filtered = median3(diff(k - 1), diff(k), diff(k + 1));
            e += filtered.distance(toss.twists[k].linear_m_s);
            v += toss.twists[k].linear_m_s.norm();
        }
        filtered_errors.push(e / v);
        // At rest (the last sample) the centre is one half-width up.
        let z = toss.poses[n - 1].position_m.z;
        rest_low_mm.push((half_width - z) * 1e3);
        body_sum += angular_error(toss, dt, true);
        world_sum += angular_error(toss, dt, false);
        w_sum += toss
            .twists
            .iter()
            .map(|w| w.angular_body_rad_s.norm())
            .sum::<f64>()
            / n as f64;
    }
    let count = tosses.len() as f64;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let max = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    println!("{} tosses from {}", tosses.len(), dir.display());
    println!("samples: {t_min}-{t_max}");
    println!("largest |quaternion norm - 1|: {norm_error:.1e}");
    println!(
        "linear velocity against the backward difference of position: relative error {:.4} on average, {:.4} at most (per toss: mean |error| / mean |v|)",
        mean(&velocity_errors),
        max(&velocity_errors)
    );
    println!(
        "  through a 3-sample median filter: {:.4} on average, {:.4} at most",
        mean(&filtered_errors),
        max(&filtered_errors)
    );
    println!(
        "angular velocity against the body-frame rotation per step (median of 3): {:.4} rad/s mean error; world frame: {:.4} rad/s; mean |w| {:.3} rad/s",
        body_sum / count,
        world_sum / count,
        w_sum / count
    );
    println!(
        "at rest, the centre below one half-width ({:.2} mm): {:.2} mm on average, {:.2} to {:.2} mm",
        half_width * 1e3,
        mean(&rest_low_mm),
        min(&rest_low_mm),
        max(&rest_low_mm)
    );
    assert!(norm_error < 1e-6, "{norm_error}");
    assert!(mean(&velocity_errors) < 0.03, "{velocity_errors:?}");
    assert!(max(&velocity_errors) < 0.08, "{velocity_errors:?}");
    assert!(mean(&filtered_errors) < mean(&velocity_errors));
    assert!(body_sum / count < 0.05 * w_sum / count);
    assert!(world_sum > 10.0 * body_sum);
    assert!((0.3..2.0).contains(&mean(&rest_low_mm)), "{rest_low_mm:?}");
    assert!(
        min(&rest_low_mm) > -1.0 && max(&rest_low_mm) < 3.0,
        "{rest_low_mm:?}"
    );
}
