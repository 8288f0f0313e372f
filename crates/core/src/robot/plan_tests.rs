//! Tests of the shared model planning.

use super::*;
use crate::pose::Quat;
use crate::robot::PackageResolver;
use crate::scene::TrackTarget;
use crate::testing::{mico2, scene};
use std::f64::consts::FRAC_PI_2;

fn robot(xml: &str) -> RobotModel {
    RobotModel::from_urdf_str(xml, std::path::Path::new("."), &PackageResolver::new()).unwrap()
}

/// A link with a solid box's inertia (mass kg, edges m).
fn box_link(name: &str, m: f64, (x, y, z): (f64, f64, f64)) -> String {
    let (ixx, iyy, izz) = (
        m * (y * y + z * z) / 12.0,
        m * (x * x + z * z) / 12.0,
        m * (x * x + y * y) / 12.0,
    );
    format!(
        r#"<link name="{name}"><inertial><mass value="{m}"/><inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial></link>"#
    )
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

#[test]
fn two_boxes_merge_by_the_parallel_axis_theorem() {
    // Box a (1 kg) at the group frame; box b (3 kg) 0.2 m out along x,
    // turned a quarter turn about z (its x and y moments swap).
    let edges = (0.1, 0.2, 0.3);
    let xml = format!(
        r#"<robot name="pair">{}{}<joint name="ab" type="fixed"><parent link="a"/><child link="b"/><origin xyz="0.2 0 0" rpy="0 0 {FRAC_PI_2}"/></joint></robot>"#,
        box_link("a", 1.0, edges),
        box_link("b", 3.0, edges)
    );
    let r = robot(&xml);
    let g = rigid_groups(&r, &[], &[0.0], GroupSplit::AtActuatedJoints);
    assert_eq!(g.groups.len(), 1);
    assert_eq!(g.groups[0].links, vec![0, 1]);
    let m = group_mass(&r, &[0, 1], &g.link_in_group, 1.0).unwrap();
    assert!(close(m.mass_kg, 4.0));
    // Centre: (1 * 0 + 3 * 0.2) / 4 = 0.15 m.
    assert!(m.com_m.distance(Vec3::new(0.15, 0.0, 0.0)) < 1e-12, "{m:?}");
    let own = |mass: f64| {
        [
            mass * (0.04 + 0.09) / 12.0,
            mass * (0.01 + 0.09) / 12.0,
            mass * (0.01 + 0.04) / 12.0,
        ]
    };
    let (a, b) = (own(1.0), own(3.0));
    // Offsets from the centre: a -0.15 m, b +0.05 m along x; they add
    // 1 * 0.15^2 + 3 * 0.05^2 = 0.03 kg m^2 about y and z, none about x.
    let shift = 1.0 * 0.15 * 0.15 + 3.0 * 0.05 * 0.05;
    let i = m.inertia_kg_m2;
    assert!(close(i[0], a[0] + b[1]), "{i:?}");
    assert!(close(i[4], a[1] + b[0] + shift), "{i:?}");
    assert!(close(i[8], a[2] + b[2] + shift), "{i:?}");
    assert!(i[1].abs() < 1e-12 && i[2].abs() < 1e-12 && i[5].abs() < 1e-12);
    assert!(is_positive_definite(&i));
    // Scaled masses scale mass and inertia, not the centre.
    let s = group_mass(&r, &[0, 1], &g.link_in_group, 1.5).unwrap();
    assert!(close(s.mass_kg, 6.0) && close(s.inertia_kg_m2[8], 1.5 * i[8]));
    assert!(s.com_m.distance(m.com_m) < 1e-12);
}

#[test]
fn point_masses_and_rotated_inertias() {
    let zero = [0.0; 9];
    let m = combine_masses(&[
        (Vec3::new(1.0, 0.0, 0.0), 1.0, zero),
        (Vec3::new(3.0, 0.0, 0.0), 1.0, zero),
    ])
    .unwrap();
    assert!(close(m.com_m.x, 2.0) && close(m.inertia_kg_m2[4], 2.0));
    assert!(close(m.inertia_kg_m2[0], 0.0) && !is_positive_definite(&m.inertia_kg_m2));
    assert!(combine_masses(&[(Vec3::ZERO, 0.0, zero)]).is_none());
    let r = Quat::from_axis_angle(Vec3::new(0.0, 0.0, 1.0), FRAC_PI_2).to_rotation_matrix();
    let i = rotate_inertia(&r, &[1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0]);
    assert!(close(i[0], 2.0) && close(i[4], 1.0) && close(i[8], 3.0));
    let p = Pose::new(
        Vec3::new(0.1, -0.2, 0.3),
        Quat::from_euler_rpy(0.3, -0.4, 1.2),
    );
    let id = p.compose(&pose_inverse(&p));
    assert!(id.position_m.norm() < 1e-15 && id.orientation.angle_to(Quat::IDENTITY) < 1e-7);
}

/// base -fixed- a -j1 (actuated)- b -fixed- c -j2 (held)- d.
fn chain() -> RobotModel {
    let j = |name: &str, kind: &str, p: &str, c: &str| {
        format!(
            r#"<joint name="{name}" type="{kind}"><parent link="{p}"/><child link="{c}"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>"#
        )
    };
    robot(&format!(
        r#"<robot name="chain"><link name="base"/>{}{}{}{}{}{}{}{}</robot>"#,
        box_link("a", 1.0, (0.1, 0.1, 0.1)),
        box_link("b", 1.0, (0.1, 0.1, 0.1)),
        r#"<link name="c"/>"#,
        box_link("d", 0.5, (0.1, 0.1, 0.1)),
        j("fa", "fixed", "base", "a"),
        j("j1", "revolute", "a", "b"),
        j("fc", "fixed", "b", "c"),
        j("j2", "revolute", "c", "d"),
    ))
}

#[test]
fn a_chain_splits_at_actuated_joints_and_welds_the_rest() {
    let r = chain();
    let link = |n: &str| r.link_by_name(n).unwrap();
    let (j1, j2) = (
        r.joint_by_name("j1").unwrap(),
        r.joint_by_name("j2").unwrap(),
    );
    let mut positions = vec![0.0; r.joints.len()];
    positions[j2] = 0.5;
    let g = rigid_groups(&r, &[j1], &positions, GroupSplit::AtActuatedJoints);
    assert_eq!(g.groups.len(), 2);
    assert_eq!(g.groups[0].links, vec![link("base"), link("a")]);
    assert_eq!(g.groups[1].links, vec![link("b"), link("c"), link("d")]);
    assert_eq!(g.groups[1].parent, Some((j1, 0)));
    assert!(!g.groups[1].welded);
    // d sits on b through the fixed joint and j2 held at 0.5 rad.
    let want = r.joints[r.joint_by_name("fc").unwrap()]
        .transform(0.0)
        .compose(&r.joints[j2].transform(0.5));
    let got = g.link_in_group[link("d")];
    assert!(got.position_m.distance(want.position_m) < 1e-15);
    assert!(got.orientation.angle_to(want.orientation) < 1e-7);
    // The group's mass: b and d (c is massless).
    let m = group_mass(&r, &g.groups[1].links, &g.link_in_group, 1.0).unwrap();
    assert!(close(m.mass_kg, 1.5));
    // Splitting also at links with mass: a and d become groups welded to
    // their parents; the massless c stays with b.
    let g = rigid_groups(&r, &[j1], &positions, GroupSplit::AlsoAtLinksWithMass);
    let tops: Vec<usize> = g.groups.iter().map(|g| g.top_link).collect();
    assert_eq!(tops, vec![link("base"), link("a"), link("b"), link("d")]);
    let welded: Vec<bool> = g.groups.iter().map(|g| g.welded).collect();
    assert_eq!(welded, vec![false, true, false, true]);
    assert_eq!(g.group_of_link[link("c")], 2);
    assert_eq!(g.groups[3].parent, Some((j2, 2)));
}

#[test]
fn mico2_fingers_are_held_and_welded_to_the_hand() {
    let (s, r) = (scene("scene1_single_joint"), mico2());
    let mut s = s;
    s.robot
        .held_joints_rad
        .insert("m1n6s300_joint_finger_1".into(), 0.3);
    let p = plan_robot(&s, &r, GroupSplit::AtActuatedJoints).unwrap();
    assert_eq!(p.actuated.len(), 6);
    assert_eq!(p.groups.groups.len(), 7);
    let hand = r.link_by_name("m1n6s300_link_6").unwrap();
    let finger = r.link_by_name("m1n6s300_link_finger_1").unwrap();
    let g = p.groups.group_of_link[hand];
    assert_eq!(p.groups.groups[g].top_link, hand);
    assert_eq!(p.groups.group_of_link[finger], g);
    let fj = r.joint_by_name("m1n6s300_joint_finger_1").unwrap();
    assert_eq!(p.initial_positions[fj], 0.3);
    // The finger's pose in the hand's frame is the forward kinematics'.
    let world = r.forward_kinematics(&Pose::IDENTITY, &p.initial_positions);
    let want = pose_inverse(&world[hand]).compose(&world[finger]);
    let got = p.groups.link_in_group[finger];
    assert!(got.position_m.distance(want.position_m) < 1e-15);
    assert_eq!(p.tracked[0], TrackedRef::Link(hand));
}

#[test]
fn unknown_or_unfit_names_are_errors() {
    let r = mico2();
    let err = |s: &Scene| {
        plan_robot(s, &r, GroupSplit::AtActuatedJoints)
            .unwrap_err()
            .0
    };
    let mut s = scene("scene1_single_joint");
    s.actuators[0].joint = "m1n6s300_joint_9".into();
    assert!(
        err(&s).contains("has no joint \"m1n6s300_joint_9\""),
        "{}",
        err(&s)
    );
    let mut s = scene("scene1_single_joint");
    s.actuators[0].joint = "m1n6s300_joint_base".into();
    assert!(err(&s).contains("is fixed"), "{}", err(&s));
    let mut s = scene("scene1_single_joint");
    s.actuators[1].joint = s.actuators[0].joint.clone();
    assert!(err(&s).contains("has two actuators"), "{}", err(&s));
    let mut s = scene("scene1_single_joint");
    s.tracked[0].target = TrackTarget::Link("hand".into());
    assert!(err(&s).contains("tracked link \"hand\""), "{}", err(&s));
    let mut s = scene("scene1_single_joint");
    s.tracked[0].target = TrackTarget::Object("ball".into());
    assert!(err(&s).contains("tracked object \"ball\""), "{}", err(&s));
}
