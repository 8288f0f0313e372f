//! Tests of the project's Mico2 description (`assets/robots/mico2/mico2.urdf`)
//! against the official Kinova m1n6s300 URDF and its meshes, and of the
//! primitive collision shapes against each other.

use super::stl::TriangleMesh;
use super::*;
use std::f64::consts::PI;
use std::io::BufRead;

pub(super) fn mico2_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/robots/mico2/mico2.urdf")
}

pub(super) fn mico2() -> RobotModel {
    RobotModel::from_urdf_file(&mico2_path(), &PackageResolver::new())
        .expect("the project's mico2.urdf loads")
}

/// The study's recordings and the official robot package: the project's
/// built-in archive (`assets/study-data/`), unpacked once into the cache by
/// `realitygap-data` (a dev-dependency) and reused. Always there, so these
/// tests never skip.
pub(crate) fn paper_data() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        use realitygap_data::builtin;
        let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets");
        let archive = builtin::StudyArchive::in_assets(&assets).unwrap_or_else(|e| panic!("{e}"));
        let cache = builtin::default_cache_root()
            .unwrap_or_else(|_| std::env::temp_dir().join("realitygap-test-cache"));
        builtin::open_or_unpack(&archive, &cache)
            .unwrap_or_else(|e| panic!("{e}"))
            .dir
    })
    .clone()
}

pub(super) fn official(data: &Path) -> RobotModel {
    let mut resolver = PackageResolver::new();
    resolver.insert("kinova_description", data.join("kinova_description"));
    RobotModel::from_urdf_file(
        &data.join("kinova_description/urdf/m1n6s300.urdf"),
        &resolver,
    )
    .expect("the official m1n6s300.urdf loads")
}

/// Signed distance (m) from a point in the shape's frame to a primitive:
/// negative inside.
fn sdf(g: &Geometry, p: Vec3) -> f64 {
    fn outside_inside(d: &[f64]) -> f64 {
        let outside = d.iter().map(|v| v.max(0.0).powi(2)).sum::<f64>().sqrt();
        let inside = d.iter().copied().fold(f64::NEG_INFINITY, f64::max).min(0.0);
        outside + inside
    }
    match g {
        Geometry::Sphere { radius_m } => p.norm() - radius_m,
        Geometry::Box { size_m } => outside_inside(&[
            p.x.abs() - size_m.x / 2.0,
            p.y.abs() - size_m.y / 2.0,
            p.z.abs() - size_m.z / 2.0,
        ]),
        Geometry::Cylinder { radius_m, length_m } => outside_inside(&[
            (p.x * p.x + p.y * p.y).sqrt() - radius_m,
            p.z.abs() - length_m / 2.0,
        ]),
        Geometry::Capsule { radius_m, length_m } => {
            let z = p.z.clamp(-length_m / 2.0, length_m / 2.0);
            (p - Vec3::new(0.0, 0.0, z)).norm() - radius_m
        }
        Geometry::Mesh { .. } => f64::INFINITY,
    }
}

/// Points on the surface of a primitive, about `spacing` m apart, in its frame.
fn surface_points(g: &Geometry, spacing: f64) -> Vec<Vec3> {
    let steps = |len: f64| ((len / spacing).ceil() as usize).max(1);
    let grid = |len: f64| -> Vec<f64> {
        let n = steps(len);
        (0..=n)
            .map(|i| -len / 2.0 + len * i as f64 / n as f64)
            .collect()
    };
    let mut pts = Vec::new();
    match g {
        Geometry::Box { size_m } => {
            let (xs, ys, zs) = (grid(size_m.x), grid(size_m.y), grid(size_m.z));
            let (hx, hy, hz) = (size_m.x / 2.0, size_m.y / 2.0, size_m.z / 2.0);
            for &x in &xs {
                for &y in &ys {
                    pts.push(Vec3::new(x, y, -hz));
                    pts.push(Vec3::new(x, y, hz));
                }
                for &z in &zs {
                    pts.push(Vec3::new(x, -hy, z));
                    pts.push(Vec3::new(x, hy, z));
                }
            }
            for &y in &ys {
                for &z in &zs {
                    pts.push(Vec3::new(-hx, y, z));
                    pts.push(Vec3::new(hx, y, z));
                }
            }
        }
        Geometry::Cylinder { radius_m, length_m } => {
            let around = steps(2.0 * PI * radius_m).max(8);
            for &z in &grid(*length_m) {
                for k in 0..around {
                    let a = 2.0 * PI * k as f64 / around as f64;
                    pts.push(Vec3::new(radius_m * a.cos(), radius_m * a.sin(), z));
                }
            }
            for &z in &[-length_m / 2.0, length_m / 2.0] {
                for &x in &grid(2.0 * radius_m) {
                    for &y in &grid(2.0 * radius_m) {
                        if x * x + y * y <= radius_m * radius_m {
                            pts.push(Vec3::new(x, y, z));
                        }
                    }
                }
            }
        }
        Geometry::Sphere { radius_m } | Geometry::Capsule { radius_m, .. } => {
            let half = match g {
                Geometry::Capsule { length_m, .. } => length_m / 2.0,
                _ => 0.0,
            };
            let rings = steps(PI * radius_m).max(6);
            for i in 0..=rings {
                let polar = PI * i as f64 / rings as f64;
                let around = steps(2.0 * PI * radius_m * polar.sin()).max(1);
                for k in 0..around {
                    let a = 2.0 * PI * k as f64 / around as f64;
                    let v = Vec3::new(polar.sin() * a.cos(), polar.sin() * a.sin(), polar.cos())
                        .scale(*radius_m);
                    let shift = if v.z >= 0.0 { half } else { -half };
                    pts.push(v + Vec3::new(0.0, 0.0, shift));
                }
            }
        }
        Geometry::Mesh { .. } => {}
    }
    pts
}

/// Radius (m) of a sphere about the shape's origin that contains it.
fn bounding_radius(g: &Geometry) -> f64 {
    match g {
        Geometry::Box { size_m } => size_m.norm() / 2.0,
        Geometry::Cylinder { radius_m, length_m } => radius_m.hypot(length_m / 2.0),
        Geometry::Capsule { radius_m, length_m } => radius_m + length_m / 2.0,
        Geometry::Sphere { radius_m } => *radius_m,
        Geometry::Mesh { .. } => f64::INFINITY,
    }
}

fn inverse(p: &Pose) -> Pose {
    let q = p.orientation.conjugate();
    Pose::new(-q.rotate(p.position_m), q)
}

/// Collision shapes of a model with surface points sampled once, for
/// checking many configurations.
struct Sampled<'a> {
    model: &'a RobotModel,
    /// Per link: (shape, points on its surface in the link frame).
    shapes: Vec<Vec<(&'a Collision, Vec<Vec3>)>>,
}

impl<'a> Sampled<'a> {
    fn new(model: &'a RobotModel, spacing: f64) -> Self {
        let shapes = model
            .links
            .iter()
            .map(|l| {
                l.collisions
                    .iter()
                    .map(|c| {
                        let pts = surface_points(&c.geometry, spacing)
                            .into_iter()
                            .map(|p| c.origin.transform_point(p));
                        (c, pts.collect())
                    })
                    .collect()
            })
            .collect();
        Sampled { model, shapes }
    }

    /// Deepest penetration (m, >= 0) between the shapes of links `a` and
    /// `b` at the given world poses of the link frames, sampled on both
    /// shapes' surfaces.
    fn penetration(&self, poses: &[Pose], a: usize, b: usize) -> f64 {
        let mut deepest: f64 = 0.0;
        for (x, y) in [(a, b), (b, a)] {
            for (cx, pts) in &self.shapes[x] {
                let world_x = poses[x].compose(&cx.origin);
                for (cy, _) in &self.shapes[y] {
                    let world_y = poses[y].compose(&cy.origin);
                    let reach_y = bounding_radius(&cy.geometry);
                    if world_x.position_m.distance(world_y.position_m)
                        > bounding_radius(&cx.geometry) + reach_y
                    {
                        continue;
                    }
                    let to_y = inverse(&world_y);
                    for &p in pts {
                        let local = to_y.transform_point(poses[x].transform_point(p));
                        if local.norm() < reach_y {
                            deepest = deepest.max(-sdf(&cy.geometry, local));
                        }
                    }
                }
            }
        }
        deepest
    }

    /// Every pair of links whose collision shapes interpenetrate at the
    /// given joint positions, with the depth (m). Only pairs with one link
    /// on each side of `across` (a joint index) are checked when it is given.
    fn overlapping_pairs(
        &self,
        positions: &[f64],
        across: Option<usize>,
    ) -> Vec<(String, String, f64)> {
        let model = self.model;
        let poses = model.forward_kinematics(&Pose::IDENTITY, positions);
        let beyond: Vec<bool> = (0..model.links.len())
            .map(|l| across.is_some_and(|j| model.chain_to(l).contains(&j)))
            .collect();
        let mut found = Vec::new();
        for a in 0..model.links.len() {
            for b in a + 1..model.links.len() {
                if across.is_some() && beyond[a] == beyond[b] {
                    continue;
                }
                let depth = self.penetration(&poses, a, b);
                if depth > 1e-9 {
                    found.push((
                        model.links[a].name.clone(),
                        model.links[b].name.clone(),
                        depth,
                    ));
                }
            }
        }
        found
    }
}

fn arm_positions(model: &RobotModel, arm_deg: [f64; 6]) -> Vec<f64> {
    model.positions_from_actuated(&arm_deg.map(f64::to_radians))
}

/// Joint angles (deg, joints 1-6) every 0.05 s of a scene run by an ideal
/// arm under the study's controller (each joint follows its velocity
/// command exactly): `v = clamp(10 * error_deg, -30, 30)` deg/s.
fn study_path(schedule: &[(f64, [f64; 6])], duration_s: f64) -> Vec<[f64; 6]> {
    let dt = 0.05;
    let mut angles = [0.0; 6];
    let mut path = Vec::new();
    let steps = (duration_s / dt).round() as usize;
    for k in 0..steps {
        let t = k as f64 * dt;
        let target = schedule
            .iter()
            .rev()
            .find(|(start, _)| *start <= t + 1e-9)
            .map(|(_, a)| *a)
            .unwrap_or([0.0; 6]);
        for j in 0..6 {
            angles[j] += (10.0 * (target[j] - angles[j])).clamp(-30.0, 30.0) * dt;
        }
        path.push(angles);
    }
    path
}

fn study_scenes() -> Vec<(&'static str, Vec<[f64; 6]>)> {
    let z = [0.0; 6];
    let with = |pairs: &[(usize, f64)]| {
        let mut a = z;
        for &(j, v) in pairs {
            a[j - 1] = v;
        }
        a
    };
    vec![
        (
            "single joint",
            study_path(&[(0.0, with(&[(2, -100.0)]))], 6.0),
        ),
        (
            "two joints",
            study_path(
                &[
                    (0.0, with(&[(2, -90.0), (5, -90.0)])),
                    (5.0, z),
                    (10.0, with(&[(2, -90.0), (5, 90.0)])),
                    (15.0, z),
                ],
                20.0,
            ),
        ),
        (
            "cube push",
            study_path(
                &[
                    (0.0, with(&[(2, 30.0), (3, 120.0), (4, 90.0)])),
                    (8.0, with(&[(2, -60.0), (3, 65.0), (4, 90.0)])),
                    (14.0, with(&[(2, -67.0), (3, 30.0), (4, 90.0)])),
                ],
                20.0,
            ),
        ),
    ]
}

#[test]
fn overlap_detector_measures_a_known_penetration() {
    let urdf = |gap_m: f64| {
        format!(
            r#"<robot name="two"><link name="a"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
            <link name="b"><collision><geometry><cylinder radius="0.05" length="0.1"/></geometry></collision></link>
            <joint name="j" type="fixed"><parent link="a"/><child link="b"/><origin xyz="{} 0 0"/></joint></robot>"#,
            0.1 + gap_m
        )
    };
    let overlapping =
        RobotModel::from_urdf_str(&urdf(-0.005), Path::new("."), &PackageResolver::new()).unwrap();
    let pairs = Sampled::new(&overlapping, 0.001).overlapping_pairs(&[], None);
    assert_eq!(pairs.len(), 1, "{pairs:?}");
    assert!((pairs[0].2 - 0.005).abs() < 0.0005, "depth {}", pairs[0].2);
    let clear =
        RobotModel::from_urdf_str(&urdf(0.001), Path::new("."), &PackageResolver::new()).unwrap();
    assert!(Sampled::new(&clear, 0.001)
        .overlapping_pairs(&[], None)
        .is_empty());
}

#[test]
fn mico2_shapes_are_clear_at_zero_and_along_the_study_scenes() {
    let m = mico2();
    let fine = Sampled::new(&m, 0.002);
    assert!(fine
        .overlapping_pairs(&m.positions_from_actuated(&[]), None)
        .is_empty());
    let coarse = Sampled::new(&m, 0.003);
    for (scene, path) in study_scenes() {
        for (k, angles) in path.iter().enumerate().step_by(4) {
            let found = coarse.overlapping_pairs(&arm_positions(&m, *angles), None);
            assert!(
                found.is_empty(),
                "scene {scene}, step {k}, joints {angles:?} deg: {found:?}"
            );
        }
    }
}

/// The range (deg) over which each actuated joint can move, the others at
/// 0, with no collision shape on one side of it touching one on the other
/// side. Documented in assets/robots/mico2/README.md.
const CLEAR_RANGE_DEG: [(&str, f64, f64); 9] = [
    ("m1n6s300_joint_1", -180.0, 180.0),
    ("m1n6s300_joint_2", -114.0, 114.0),
    ("m1n6s300_joint_3", -130.0, 130.0),
    ("m1n6s300_joint_4", -180.0, 180.0),
    ("m1n6s300_joint_5", -180.0, 180.0),
    ("m1n6s300_joint_6", -180.0, 180.0),
    ("m1n6s300_joint_finger_1", 0.0, 85.0),
    ("m1n6s300_joint_finger_2", 0.0, 85.0),
    ("m1n6s300_joint_finger_3", 0.0, 85.0),
];

#[test]
fn mico2_neighbours_stay_clear_over_the_documented_joint_ranges() {
    let m = mico2();
    let sampled = Sampled::new(&m, 0.003);
    let actuated: Vec<&str> = m
        .actuated_joints()
        .iter()
        .map(|&j| m.joints[j].name.as_str())
        .collect();
    assert_eq!(actuated, CLEAR_RANGE_DEG.map(|c| c.0));
    for (name, lo, hi) in CLEAR_RANGE_DEG {
        let j = m.joint_by_name(name).unwrap();
        let steps = ((hi - lo) / 5.0).round() as usize;
        for i in 0..=steps {
            let deg = lo + (hi - lo) * i as f64 / steps as f64;
            let mut q = vec![0.0; m.joints.len()];
            q[j] = deg.to_radians();
            let found = sampled.overlapping_pairs(&q, Some(j));
            assert!(found.is_empty(), "{name} at {deg} deg: {found:?}");
        }
    }
    // Just beyond the documented ranges the shapes do meet (as the real
    // links would, short of the joint limits): the check is not vacuous.
    for (name, deg) in [
        ("m1n6s300_joint_2", 120.0),
        ("m1n6s300_joint_3", -136.0),
        ("m1n6s300_joint_finger_1", 100.0),
    ] {
        let j = m.joint_by_name(name).unwrap();
        let mut q = vec![0.0; m.joints.len()];
        q[j] = f64::to_radians(deg);
        assert!(
            !sampled.overlapping_pairs(&q, Some(j)).is_empty(),
            "{name} at {deg} deg should collide"
        );
    }
}

/// Bounding boxes (mm, in the link frame) of the Kinova meshes, as listed in
/// assets/robots/mico2/README.md.
const MESH_AABB_MM: [(&str, [f64; 3], [f64; 3]); 8] = [
    ("base.STL", [-41.3, -41.3, 0.0], [41.3, 41.3, 156.8]),
    ("shoulder.STL", [-41.3, -41.3, -159.9], [41.3, 41.3, 0.0]),
    ("arm_mico.STL", [-41.3, -331.3, -43.8], [41.3, 41.3, 0.0]),
    (
        "forearm_mico.STL",
        [-41.3, -41.3, -43.0],
        [41.3, 123.1, 22.9],
    ),
    ("wrist.STL", [-31.5, -52.7, -91.4], [31.5, 31.5, 0.0]),
    (
        "hand_3finger.STL",
        [-46.4, -50.8, -121.0],
        [46.4, 54.3, 0.0],
    ),
    (
        "finger_proximal.STL",
        [-7.3, -21.3, -11.5],
        [50.6, 5.2, 11.5],
    ),
    ("finger_distal.STL", [-9.5, -14.6, -11.3], [43.7, 5.5, 11.3]),
];

/// Per mesh: the least share of mesh vertices within 5 mm of the link's
/// primitives, and the largest distance (mm) of a vertex outside them.
/// Documented in assets/robots/mico2/README.md.
const COVERAGE: [(&str, f64, f64); 8] = [
    ("base.STL", 0.999, 2.5),
    ("shoulder.STL", 0.999, 2.0),
    ("arm_mico.STL", 0.999, 3.5),
    ("forearm_mico.STL", 0.995, 6.0),
    ("wrist.STL", 0.999, 2.0),
    ("hand_3finger.STL", 0.95, 20.0),
    ("finger_proximal.STL", 0.86, 11.0),
    ("finger_distal.STL", 0.97, 7.0),
];

#[test]
fn mico2_primitives_fit_the_kinova_meshes() {
    let data = paper_data();
    let off = official(&data);
    let m = mico2();
    let mut checked = 0;
    for link in &off.links {
        let Some(Collision {
            geometry: Geometry::Mesh { path, .. },
            ..
        }) = link.collisions.first()
        else {
            continue;
        };
        let file = path.file_name().unwrap().to_string_lossy().to_string();
        let mesh = TriangleMesh::read(path).unwrap();
        let bb = mesh.aabb().unwrap();
        let (_, min_mm, max_mm) = MESH_AABB_MM
            .iter()
            .find(|e| e.0 == file)
            .expect("mesh listed");
        for k in 0..3 {
            assert!(
                (bb.min.to_array()[k] * 1e3 - min_mm[k]).abs() <= 0.051,
                "{file} min {:?}",
                bb.min
            );
            assert!(
                (bb.max.to_array()[k] * 1e3 - max_mm[k]).abs() <= 0.051,
                "{file} max {:?}",
                bb.max
            );
        }
        let ours = &m.links[m.link_by_name(&link.name).expect("same link names")];
        let to_shape: Vec<Pose> = ours.collisions.iter().map(|c| inverse(&c.origin)).collect();
        let distances: Vec<f64> = mesh
            .triangles
            .iter()
            .flatten()
            .map(|&v| {
                ours.collisions
                    .iter()
                    .zip(&to_shape)
                    .map(|(c, t)| sdf(&c.geometry, t.transform_point(v)))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let within =
            distances.iter().filter(|&&d| d <= 0.005).count() as f64 / distances.len() as f64;
        let worst_mm = distances.iter().copied().fold(f64::NEG_INFINITY, f64::max) * 1e3;
        let (_, min_share, max_mm) = COVERAGE.iter().find(|e| e.0 == file).unwrap();
        assert!(
            within >= *min_share,
            "{}: {:.1}% of {file} within 5 mm",
            link.name,
            within * 100.0
        );
        assert!(
            worst_mm <= *max_mm,
            "{}: a vertex of {file} is {worst_mm:.1} mm outside",
            link.name
        );
        // The primitives stay within the mesh's bounding box (+3 mm).
        for c in &ours.collisions {
            for p in surface_points(&c.geometry, 0.003) {
                let p = c.origin.transform_point(p);
                let outside = (bb.min - p)
                    .to_array()
                    .into_iter()
                    .chain((p - bb.max).to_array())
                    .fold(0.0, f64::max);
                assert!(
                    outside <= 0.003,
                    "{} {:?} reaches {:.1} mm beyond {file}",
                    link.name,
                    c.name,
                    outside * 1e3
                );
            }
        }
        checked += 1;
    }
    assert_eq!(
        checked, 13,
        "every arm, hand and finger link has a mesh to compare with"
    );
}

/// A small deterministic generator (64-bit LCG), uniform in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn mico2_matches_the_official_urdf() {
    let data = paper_data();
    let off = official(&data);
    let m = mico2();
    // Same joints with the same numbers.
    for j in &m.joints {
        let o = &off.joints[off
            .joint_by_name(&j.name)
            .expect("joint in the official URDF")];
        assert_eq!(
            (j.kind, &off.links[o.parent].name, &off.links[o.child].name),
            (o.kind, &m.links[j.parent].name, &m.links[j.child].name),
            "{}",
            j.name
        );
        assert!(
            j.origin.position_m.distance(o.origin.position_m) < 1e-12,
            "{}",
            j.name
        );
        assert!(
            j.origin.orientation.angle_to(o.origin.orientation) < 1e-9,
            "{}",
            j.name
        );
        if j.kind.is_movable() {
            assert!(j.axis.distance(o.axis) < 1e-12, "{}", j.name);
            assert_eq!(j.limits, o.limits, "{}", j.name);
            assert_eq!(
                (j.damping, j.friction),
                (o.damping, o.friction),
                "{}",
                j.name
            );
        }
    }
    // Same masses and inertias on every link that has any.
    for l in &m.links {
        let o = &off.links[off
            .link_by_name(&l.name)
            .expect("link in the official URDF")];
        assert_eq!(l.inertial, o.inertial, "{}", l.name);
    }
    assert!((m.total_mass_kg() - off.total_mass_kg()).abs() < 1e-12);
    assert!(
        (m.total_mass_kg() - 3.82522).abs() < 1e-9,
        "{}",
        m.total_mass_kg()
    );

    // Same link poses at 200 random joint configurations within limits.
    let wrist = m.link_by_name("m1n6s300_link_6").unwrap();
    let wrist_off = off.link_by_name("m1n6s300_link_6").unwrap();
    let base = Pose::new(Vec3::new(0.0, 0.0, 0.055), Quat::IDENTITY);
    let mut rng = Lcg(20190520);
    for sample in 0..200 {
        let values: Vec<f64> = m
            .actuated_joints()
            .iter()
            .map(|&j| {
                let l = m.joints[j].limits.unwrap();
                let (lo, hi) = (l.lower.max(-PI), l.upper.min(PI));
                lo + (hi - lo) * rng.next()
            })
            .collect();
        let ours = m.forward_kinematics(&base, &m.positions_from_actuated(&values));
        let theirs = off.forward_kinematics(&base, &off.positions_from_actuated(&values));
        let (a, b) = (ours[wrist], theirs[wrist_off]);
        assert!(
            a.position_m.distance(b.position_m) < 1e-4,
            "sample {sample}: {a:?} vs {b:?}"
        );
        assert!(
            a.orientation.angle_to(b.orientation) < 1e-6,
            "sample {sample}: {a:?} vs {b:?}"
        );
        for (l, pose) in m.links.iter().zip(&ours) {
            let other = theirs[off.link_by_name(&l.name).unwrap()];
            assert!(
                pose.position_m.distance(other.position_m) < 1e-9,
                "sample {sample}, {}",
                l.name
            );
        }
    }
}

/// Reads the numbers of one row of a recorded simulator file.
fn csv_row(path: &Path, row: usize) -> Vec<f64> {
    let file = std::fs::File::open(path).unwrap();
    let lines: Vec<String> = std::io::BufReader::new(file)
        .lines()
        .map(|l| l.unwrap())
        .collect();
    let line = if row == usize::MAX {
        lines.last().unwrap()
    } else {
        &lines[row]
    };
    line.split_whitespace()
        .map(|v| v.parse::<f64>().unwrap())
        .collect()
}

#[test]
fn official_fk_reproduces_the_study_mujoco_wrist() {
    let data = paper_data();
    let off = official(&data);
    let wrist = off.link_by_name("m1n6s300_link_6").unwrap();
    let file = data.join("Simulation/Experiment1/Single_Mujoco_0.csv");
    // Row 0: the arm at rest at the zero configuration.
    let first = csv_row(&file, 0);
    let recorded = Pose::new(
        Vec3::new(first[0], first[1], first[2]),
        Quat::new(first[3], first[4], first[5], first[6]),
    );
    let at_origin = off.forward_kinematics(&Pose::IDENTITY, &[])[wrist];
    // The base offset that puts FK's wrist on the recorded one.
    let offset = recorded.position_m - at_origin.position_m;
    println!("study base position (from Single_Mujoco_0.csv row 0): {offset:?}");
    assert!(
        offset.distance(Vec3::new(0.0, 0.0, 0.055)) < 1e-3,
        "base offset {offset:?}"
    );
    let base = Pose::new(Vec3::new(0.0, 0.0, 0.055), Quat::IDENTITY);
    let fk = off.forward_kinematics(&base, &[])[wrist];
    assert!(
        fk.position_m.distance(recorded.position_m) < 1e-3,
        "{fk:?} vs {recorded:?}"
    );
    assert!(
        fk.orientation.angle_to(recorded.orientation) < 1e-3,
        "{fk:?} vs {recorded:?}"
    );
    // Last row: at rest at the target joint 2 = -100 deg, held a little
    // beyond it by MuJoCo's velocity actuators (kv per joint) against
    // gravity: at rest kv * 10 * (target - q) + gravity torque = 0. Solving
    // that with the URDF's masses checks joint signs, inertials and reach.
    let last = csv_row(&file, usize::MAX);
    let recorded = Vec3::new(last[0], last[1], last[2]);
    let target = arm_positions(&off, [0.0, -100.0, 0.0, 0.0, 0.0, 0.0]);
    let kv = [10.0, 40.0, 10.0, 4.0, 4.0, 2.0];
    let arm = off.actuated_joints();
    let mut q = target.clone();
    for _ in 0..50 {
        let torque = off.gravity_torques(&base, &q, Vec3::new(0.0, 0.0, -9.81));
        for (k, &j) in arm.iter().take(6).enumerate() {
            q[j] = target[j] + torque[j] / (10.0 * kv[k]);
        }
    }
    let held = off.forward_kinematics(&base, &q)[wrist].position_m;
    let ideal = off.forward_kinematics(&base, &target)[wrist].position_m;
    println!(
        "scene 1 end: MuJoCo {recorded:?}; FK at the target {:.1} mm away, FK held against gravity {:.4} um away",
        ideal.distance(recorded) * 1e3,
        held.distance(recorded) * 1e6
    );
    println!(
        "held {held:?} q {:?}",
        arm.iter().map(|&j| q[j].to_degrees()).collect::<Vec<_>>()
    );
    assert!(
        ideal.distance(recorded) > 0.01,
        "the sag is real: the check below is not trivially met"
    );
    assert!(held.distance(recorded) < 1e-4, "{held:?} vs {recorded:?}");
}
