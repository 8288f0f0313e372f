//! Pose maths: [`Vec3`], [`Quat`] and [`Pose`].
//!
//! Conventions, stated once and used everywhere:
//! - Quaternions are Hamilton quaternions `w + xi + yj + zk`, stored as
//!   `(w, x, y, z)`; a unit quaternion `q` rotates a vector `v` as `q v q*`.
//!   They represent the orientation of a body frame in the world frame, i.e.
//!   they map body coordinates to world coordinates (active rotation).
//! - Rotation matrices are row-major `[r00, r01, r02, r10, ..., r22]` and map
//!   body coordinates to world coordinates (`v_world = R v_body`).
//! - Euler angles (roll, pitch, yaw) are the aerospace / URDF `rpy`
//!   convention: `R = Rz(yaw) * Ry(pitch) * Rx(roll)`, i.e. rotations about
//!   the fixed X, then Y, then Z axes, in radians.

use serde::{Deserialize, Serialize};
use std::ops::{Add, Mul, Neg, Sub};

/// A 3-vector (metres when it is a position).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vec3 {
    /// X component.
    pub x: f64,
    /// Y component.
    pub y: f64,
    /// Z component.
    pub z: f64,
}

impl Vec3 {
    /// The zero vector.
    pub const ZERO: Vec3 = Vec3 {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    };

    /// Makes a vector from its components.
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Vec3 { x, y, z }
    }
    /// Components as an array `[x, y, z]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    /// Vector from an array `[x, y, z]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Vec3::new(a[0], a[1], a[2])
    }
    /// Dot product.
    pub fn dot(self, o: Vec3) -> f64 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product.
    pub fn cross(self, o: Vec3) -> Vec3 {
        Vec3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Euclidean norm.
    pub fn norm(self) -> f64 {
        self.dot(self).sqrt()
    }
    /// Euclidean distance to another point.
    pub fn distance(self, o: Vec3) -> f64 {
        (self - o).norm()
    }
    /// Multiplies every component by `s`.
    pub fn scale(self, s: f64) -> Vec3 {
        Vec3::new(self.x * s, self.y * s, self.z * s)
    }
    /// True when every component is finite (not NaN, not infinite).
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
    /// Linear interpolation: `self` at `t = 0`, `o` at `t = 1`.
    pub fn lerp(self, o: Vec3, t: f64) -> Vec3 {
        self + (o - self).scale(t)
    }
}

impl Add for Vec3 {
    type Output = Vec3;
    fn add(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl Sub for Vec3 {
    type Output = Vec3;
    fn sub(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl Neg for Vec3 {
    type Output = Vec3;
    fn neg(self) -> Vec3 {
        Vec3::new(-self.x, -self.y, -self.z)
    }
}

/// A quaternion `(w, x, y, z)`, Hamilton convention (see the module docs).
/// Orientation values are unit quaternions; [`Quat::normalized`] makes one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quat {
    /// Scalar part.
    pub w: f64,
    /// i component.
    pub x: f64,
    /// j component.
    pub y: f64,
    /// k component.
    pub z: f64,
}

impl Default for Quat {
    fn default() -> Self {
        Quat::IDENTITY
    }
}

impl Quat {
    /// The rotation that takes the x axis onto the direction of `axis`: the
    /// shortest arc, a half turn about z when `axis` is -x, none when
    /// `axis` is zero. Engines whose revolute joints turn about their
    /// frame's x axis (Rapier, PhysX) turn that frame onto a URDF axis
    /// with it.
    pub fn x_onto(axis: Vec3) -> Quat {
        let x = Vec3::new(1.0, 0.0, 0.0);
        let n = axis.norm();
        let a = if n > 0.0 { axis.scale(1.0 / n) } else { x };
        let d = x.dot(a);
        if d < -1.0 + 1e-12 {
            return Quat::new(0.0, 0.0, 0.0, 1.0);
        }
        let c = x.cross(a);
        Quat::new(1.0 + d, c.x, c.y, c.z)
            .normalized()
            .unwrap_or(Quat::IDENTITY)
    }

    /// The identity rotation.
    pub const IDENTITY: Quat = Quat {
        w: 1.0,
        x: 0.0,
        y: 0.0,
        z: 0.0,
    };

    /// Makes a quaternion from `(w, x, y, z)`; no normalisation.
    pub const fn new(w: f64, x: f64, y: f64, z: f64) -> Self {
        Quat { w, x, y, z }
    }
    /// Rotation of `angle_rad` about the unit `axis`.
    pub fn from_axis_angle(axis: Vec3, angle_rad: f64) -> Quat {
        let n = axis.norm();
        if n == 0.0 {
            return Quat::IDENTITY;
        }
        let (s, c) = (angle_rad * 0.5).sin_cos();
        let a = axis.scale(s / n);
        Quat::new(c, a.x, a.y, a.z)
    }
    /// Euclidean norm of the 4 components.
    pub fn norm(self) -> f64 {
        (self.w * self.w + self.x * self.x + self.y * self.y + self.z * self.z).sqrt()
    }
    /// The unit quaternion in the same direction; `None` when the norm is
    /// zero or not finite.
    pub fn normalized(self) -> Option<Quat> {
        let n = self.norm();
        if !(n.is_finite() && n > 0.0) {
            return None;
        }
        Some(Quat::new(self.w / n, self.x / n, self.y / n, self.z / n))
    }
    /// The conjugate (the inverse rotation for a unit quaternion).
    pub fn conjugate(self) -> Quat {
        Quat::new(self.w, -self.x, -self.y, -self.z)
    }
    /// 4-component dot product.
    pub fn dot(self, o: Quat) -> f64 {
        self.w * o.w + self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// True when every component is finite.
    pub fn is_finite(self) -> bool {
        self.w.is_finite() && self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
    /// Rotates a vector by this (unit) quaternion.
    pub fn rotate(self, v: Vec3) -> Vec3 {
        let u = Vec3::new(self.x, self.y, self.z);
        let t = u.cross(v).scale(2.0);
        v + t.scale(self.w) + u.cross(t)
    }

    /// Quaternion from a row-major rotation matrix (body to world), using
    /// Shepperd's method (stable for every rotation). The matrix is assumed
    /// to be close to orthonormal; the result is normalised and has `w >= 0`.
    pub fn from_rotation_matrix(m: &[f64; 9]) -> Quat {
        let (r00, r01, r02, r10, r11, r12, r20, r21, r22) =
            (m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8]);
        let trace = r00 + r11 + r22;
        let q = if trace > r00 && trace > r11 && trace > r22 {
            let s = (1.0 + trace).sqrt() * 2.0;
            Quat::new(0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
        } else if r00 > r11 && r00 > r22 {
            let s = (1.0 + r00 - r11 - r22).sqrt() * 2.0;
            Quat::new((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
        } else if r11 > r22 {
            let s = (1.0 + r11 - r00 - r22).sqrt() * 2.0;
            Quat::new((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
        } else {
            let s = (1.0 + r22 - r00 - r11).sqrt() * 2.0;
            Quat::new((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
        };
        let q = q.normalized().unwrap_or(Quat::IDENTITY);
        if q.w < 0.0 {
            Quat::new(-q.w, -q.x, -q.y, -q.z)
        } else {
            q
        }
    }

    /// Row-major rotation matrix (body to world) of this unit quaternion.
    pub fn to_rotation_matrix(self) -> [f64; 9] {
        let Quat { w, x, y, z } = self;
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ]
    }

    /// Quaternion from roll, pitch, yaw in radians (URDF `rpy`:
    /// `R = Rz(yaw) Ry(pitch) Rx(roll)`).
    pub fn from_euler_rpy(roll: f64, pitch: f64, yaw: f64) -> Quat {
        let (sr, cr) = (roll * 0.5).sin_cos();
        let (sp, cp) = (pitch * 0.5).sin_cos();
        let (sy, cy) = (yaw * 0.5).sin_cos();
        Quat::new(
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        )
    }

    /// Roll, pitch, yaw in radians (same convention as
    /// [`Quat::from_euler_rpy`]); roll and yaw in `(-pi, pi]`, pitch in
    /// `[-pi/2, pi/2]`. At pitch = +-pi/2 (gimbal lock) roll is set to 0.
    pub fn to_euler_rpy(self) -> (f64, f64, f64) {
        let Quat { w, x, y, z } = self;
        let sinp = 2.0 * (w * y - z * x);
        let pitch = sinp.clamp(-1.0, 1.0).asin();
        if sinp.abs() >= 1.0 - 1e-12 {
            // Gimbal lock: only yaw - roll (or yaw + roll) is defined.
            let yaw = -2.0 * x.atan2(w) * sinp.signum();
            return (0.0, pitch, wrap_angle(yaw));
        }
        let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
        let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
        (roll, pitch, yaw)
    }

    /// Geodesic angle in radians, in `[0, pi]`, between two orientations:
    /// the angle of the smallest rotation taking one to the other
    /// (`q` and `-q` are the same orientation).
    pub fn angle_to(self, o: Quat) -> f64 {
        // atan2 of the relative rotation's vector and scalar parts keeps full
        // precision near 0 (where acos of the dot product loses half the digits).
        let r = self.conjugate() * o;
        let v = (r.x * r.x + r.y * r.y + r.z * r.z).sqrt();
        2.0 * v.atan2(r.w.abs())
    }
}

impl Mul for Quat {
    type Output = Quat;
    /// Hamilton product: `(a * b).rotate(v) == a.rotate(b.rotate(v))`.
    fn mul(self, o: Quat) -> Quat {
        Quat::new(
            self.w * o.w - self.x * o.x - self.y * o.y - self.z * o.z,
            self.w * o.x + self.x * o.w + self.y * o.z - self.z * o.y,
            self.w * o.y - self.x * o.z + self.y * o.w + self.z * o.x,
            self.w * o.z + self.x * o.y - self.y * o.x + self.z * o.w,
        )
    }
}

/// Wraps an angle in radians into `(-pi, pi]`.
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut r = a % two_pi;
    if r <= -std::f64::consts::PI {
        r += two_pi;
    } else if r > std::f64::consts::PI {
        r -= two_pi;
    }
    r
}

/// A rigid pose: the position of a body frame's origin in the world frame
/// (metres) and its orientation (unit quaternion, body to world).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// Position of the frame origin, metres.
    pub position_m: Vec3,
    /// Orientation, body to world.
    pub orientation: Quat,
}

impl Pose {
    /// The identity pose.
    pub const IDENTITY: Pose = Pose {
        position_m: Vec3::ZERO,
        orientation: Quat::IDENTITY,
    };

    /// Makes a pose.
    pub fn new(position_m: Vec3, orientation: Quat) -> Self {
        Pose {
            position_m,
            orientation,
        }
    }
    /// Composition: the pose of a frame given relative to `self`.
    pub fn compose(&self, child: &Pose) -> Pose {
        Pose {
            position_m: self.position_m + self.orientation.rotate(child.position_m),
            orientation: self.orientation * child.orientation,
        }
    }
    /// Maps a point from this frame to the parent frame.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.position_m + self.orientation.rotate(p)
    }
    /// True when position and orientation are finite.
    pub fn is_finite(&self) -> bool {
        self.position_m.is_finite() && self.orientation.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn x_onto_maps_x_to_the_axis() {
        for axis in [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.3, -0.4, 0.5),
        ] {
            let got = Quat::x_onto(axis).rotate(Vec3::new(1.0, 0.0, 0.0));
            let want = axis.scale(1.0 / axis.norm());
            assert!(got.distance(want) < 1e-12, "{axis:?} -> {got:?}");
        }
    }
    use std::f64::consts::{FRAC_PI_2, PI};

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn rpy_of_basic_rotations() {
        let q = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 0.0), 0.3);
        let (r, p, y) = q.to_euler_rpy();
        assert!(close(r, 0.3, 1e-12) && close(p, 0.0, 1e-12) && close(y, 0.0, 1e-12));
        let q = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), -2.0);
        let (r, p, y) = q.to_euler_rpy();
        assert!(close(r, 0.0, 1e-12) && close(p, 0.0, 1e-12) && close(y, -2.0, 1e-12));
    }

    #[test]
    fn matrix_of_quarter_turn_about_z() {
        let q = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), FRAC_PI_2);
        let v = q.rotate(Vec3::new(1.0, 0.0, 0.0));
        assert!(v.distance(Vec3::new(0.0, 1.0, 0.0)) < 1e-12);
        let m = q.to_rotation_matrix();
        // Column 0 is the image of the x axis.
        assert!(close(m[0], 0.0, 1e-12) && close(m[3], 1.0, 1e-12));
    }

    #[test]
    fn gimbal_lock_round_trips() {
        for &p in &[FRAC_PI_2, -FRAC_PI_2] {
            let q = Quat::from_euler_rpy(0.4, p, -1.1);
            let (r2, p2, y2) = q.to_euler_rpy();
            let q2 = Quat::from_euler_rpy(r2, p2, y2);
            assert!(q.angle_to(q2) < 1e-6, "{q:?} vs {q2:?}");
        }
    }

    #[test]
    fn wrap_angle_range() {
        assert!(close(wrap_angle(3.0 * PI), PI, 1e-12));
        assert!(close(wrap_angle(-PI), PI, 1e-12));
        assert!(close(wrap_angle(0.5), 0.5, 0.0));
    }

    fn arb_quat() -> impl Strategy<Value = Quat> {
        (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0).prop_filter_map(
            "non-zero",
            |(w, x, y, z)| {
                let q = Quat::new(w, x, y, z);
                if q.norm() > 0.1 {
                    q.normalized()
                } else {
                    None
                }
            },
        )
    }

    proptest! {
        #[test]
        fn matrix_round_trip(q in arb_quat()) {
            let q2 = Quat::from_rotation_matrix(&q.to_rotation_matrix());
            prop_assert!(q.angle_to(q2) < 1e-9);
            prop_assert!(close(q2.norm(), 1.0, 1e-12));
        }

        #[test]
        fn euler_round_trip(roll in -3.1f64..3.1, pitch in -1.55f64..1.55, yaw in -3.1f64..3.1) {
            let q = Quat::from_euler_rpy(roll, pitch, yaw);
            let (r, p, y) = q.to_euler_rpy();
            prop_assert!(close(r, roll, 1e-9) && close(p, pitch, 1e-9) && close(y, yaw, 1e-9));
        }

        #[test]
        fn euler_matches_matrix_product(roll in -3.1f64..3.1, pitch in -1.55f64..1.55, yaw in -3.1f64..3.1) {
            let rx = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 0.0), roll);
            let ry = Quat::from_axis_angle(Vec3::new(0.0, 1.0, 0.0), pitch);
            let rz = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), yaw);
            let q = rz * ry * rx;
            prop_assert!(q.angle_to(Quat::from_euler_rpy(roll, pitch, yaw)) < 1e-9);
        }

        #[test]
        fn geodesic_angle_properties(a in arb_quat(), b in arb_quat(), angle in 0.0f64..3.1) {
            // Symmetric, in [0, pi], zero on itself and on -q.
            let d = a.angle_to(b);
            prop_assert!((0.0..=PI + 1e-12).contains(&d));
            prop_assert!(close(d, b.angle_to(a), 1e-9));
            prop_assert!(a.angle_to(a) < 1e-6);
            prop_assert!(a.angle_to(Quat::new(-a.w, -a.x, -a.y, -a.z)) < 1e-6);
            // A rotation by `angle` about any axis moves it by exactly `angle`.
            let r = Quat::from_axis_angle(Vec3::new(0.3, -0.5, 0.8), angle);
            prop_assert!(close(a.angle_to(r * a), angle, 1e-6));
        }

        #[test]
        fn rotation_preserves_length(q in arb_quat(), x in -5.0f64..5.0, y in -5.0f64..5.0, z in -5.0f64..5.0) {
            let v = Vec3::new(x, y, z);
            prop_assert!(close(q.rotate(v).norm(), v.norm(), 1e-9));
            let m = q.to_rotation_matrix();
            let mv = Vec3::new(m[0]*x + m[1]*y + m[2]*z, m[3]*x + m[4]*y + m[5]*z, m[6]*x + m[7]*y + m[8]*z);
            prop_assert!(mv.distance(q.rotate(v)) < 1e-9);
        }
    }
}
