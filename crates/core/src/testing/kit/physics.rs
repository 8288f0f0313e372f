//! The state across a round trip and a handover, and what each physical
//! parameter does: measured where the engine honours the key, refused
//! (an error naming the engine and the key) where it does not.

use super::{
    assert_refused, honours, load, params, report, run, settings_for, static_equilibrium_deg,
    study_settings, with_subject, KitSpec, TempDir,
};
use crate::conformance;
use crate::controller::RunOutcome;
use crate::engine::{Engine, EngineError, ModelVariation, ServoCommand};
use crate::params::{ParamKey, PhysicalParams};
use crate::pose::{Pose, Vec3};
use crate::testing;

/// The round trips' and handovers' scenes and ticks: scene 1 at 2 s (the
/// arm moving, the cube resting on the table) and scene 3 at 12 s (the
/// hand pushing the cube).
pub const TAKEN: [(&str, usize); 2] = [("scene1_single_joint", 40), ("scene3_cube_push", 240)];

/// A run saved at [`TAKEN`] and continued, against a fresh simulation
/// given its state (native, then portable) and continued with the same
/// controller ([`conformance::state_round_trip`]): within
/// [`KitSpec::round_trip_m`].
pub fn state_round_trips(engine: &dyn Engine, spec: &KitSpec) {
    for (i, (name, k)) in TAKEN.into_iter().enumerate() {
        // Both states from one run to tick k (conformance::state_round_trips).
        let (native, portable) = with_subject(engine, spec, |s| {
            conformance::state_round_trips(s, &testing::scene(name), &testing::mico2(), k)
        });
        for (j, (what, gap)) in [("native", native), ("portable", portable)]
            .into_iter()
            .enumerate()
        {
            let tolerance = spec.round_trip_m[i][j];
            report(
                engine,
                &format!("round_trip_{name}_{what}_m"),
                gap,
                tolerance,
            );
            assert!(
                gap <= tolerance,
                "{}: {name}: {what} round trip moved {gap} m (tolerance {tolerance})",
                engine.name()
            );
        }
    }
}

/// The portable state at [`TAKEN`] loaded into a fresh simulation of the
/// same engine ([`conformance::handover_gap`]): the tracked positions
/// within [`KitSpec::handover_m`], the joint angles within
/// [`KitSpec::handover_rad`]. (Handovers between engines: the command's
/// crate, which compiles them all.)
pub fn handover(engine: &dyn Engine, spec: &KitSpec) {
    for (i, (name, k)) in TAKEN.into_iter().enumerate() {
        let (gap, angles) = with_subject(engine, spec, |s| {
            conformance::handover_gap(s, s, &testing::scene(name), &testing::mico2(), k)
        });
        report(
            engine,
            &format!("handover_{name}_m"),
            gap,
            spec.handover_m[i],
        );
        report(
            engine,
            &format!("handover_{name}_rad"),
            angles,
            spec.handover_rad,
        );
        assert!(
            gap <= spec.handover_m[i],
            "{}: {name}: positions {gap} m apart",
            engine.name()
        );
        assert!(
            angles <= spec.handover_rad,
            "{}: {name}: angles {angles} rad apart",
            engine.name()
        );
    }
}

/// Joint 2 of scene 1 started at -0.5 rad with every servo off (force
/// limit 0) and `extra` (TOML lines) on joint 2: how far it falls in
/// 0.3 s, rad.
fn fall(engine: &dyn Engine, spec: &KitSpec, extra: &str) -> f64 {
    let scene = testing::scene("scene1_single_joint");
    let mut text = String::new();
    for a in &scene.actuators {
        text.push_str(&format!("[joints.{}]\nforce_limit = 0.0\n", a.joint));
        if a.joint == "m1n6s300_joint_2" {
            text.push_str(extra);
        }
    }
    let settings = study_settings(engine, spec);
    let mut sim = load(engine, &scene, &testing::mico2(), &settings, &params(&text))
        .unwrap_or_else(|e| panic!("{extra}: {e}"));
    let mut q = [0.0, -0.5, 0.0, 0.0, 0.0, 0.0];
    sim.set_joint_angles_rad(&q).unwrap();
    sim.set_joint_velocity_targets(&[0.0; 6]);
    sim.step_n((0.3 / sim.timestep_s()).round() as u64).unwrap();
    sim.joint_angles_rad(&mut q);
    (q[1] + 0.5).abs()
}

/// The check can run: the engine honours `key`; otherwise setting it is
/// checked to be refused (`text` sets it as `field`) and the check ends.
fn measurable(engine: &dyn Engine, key: ParamKey, text: &str, field: &str) -> bool {
    if honours(engine, key) {
        return true;
    }
    assert_refused(engine, text, field);
    false
}

const JOINT_2: &str = "joints.m1n6s300_joint_2";

/// Damping 5 N m s/rad on joint 2 slows its fall with the servos off
/// ([`conformance::falling_angle_rad`]): by the spec's ratio at least; the
/// free fall is over 0.05 rad.
pub fn damping(engine: &dyn Engine, spec: &KitSpec) {
    let (text, field) = ("[joints.m1n6s300_joint_2]\ndamping = 5.0\n", "damping");
    if !measurable(
        engine,
        ParamKey::JointDamping,
        text,
        &format!("{JOINT_2}.{field}"),
    ) {
        return;
    }
    let (free, damped) = with_subject(engine, spec, |s| {
        (
            conformance::falling_angle_rad(s, 0.0),
            conformance::falling_angle_rad(s, 5.0),
        )
    });
    let ratio = spec.effects.damping_ratio;
    report(engine, "falling_angle_damping0_rad", free, 0.05);
    report(engine, "falling_angle_ratio_damping5", damped / free, ratio);
    assert!(free > 0.05, "joint 2 fell only {free} rad without damping");
    assert!(
        damped < free * ratio,
        "damping 5: {damped} rad, none: {free} rad"
    );
}

/// A parameters file (read from disk) limiting joint 2 to 2 N m makes the
/// wrist lag scene 1's: more than 5 mm apart at 1.5 s.
pub fn force_limit(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[joints.m1n6s300_joint_2]\nforce_limit = 2.0\n";
    if !measurable(
        engine,
        ParamKey::JointForceLimit,
        text,
        &format!("{JOINT_2}.force_limit"),
    ) {
        return;
    }
    let tmp = TempDir::new(engine.name(), "force-limit");
    let file = tmp.path("params.toml");
    std::fs::write(&file, text).unwrap();
    let limited = PhysicalParams::from_file(&file).unwrap();
    // Without the cube: the limited joint lets the arm fall onto it, and
    // in Bullet the falling arm presses it 2 cm into the table, a failed
    // contact that the run-time penetration check reports as divergence;
    // the force limit's effect on the wrist is what is measured here.
    let mut scene = testing::scene("scene1_single_joint");
    scene.objects.clear();
    scene
        .tracked
        .retain(|t| !matches!(t.target, crate::scene::TrackTarget::Object(_)));
    let robot = testing::mico2();
    let wrist = |p: &PhysicalParams| testing::wrist(&run(engine, spec, &scene, &robot, p, &[]))[30];
    let d = wrist(&limited).distance(wrist(&PhysicalParams::none()));
    report(engine, "force_limit_effect_m", d, 0.005);
    assert!(d > 0.005, "force limit 2 N m moved the wrist {d} m");
}

/// Scene 3 with the cube's friction at 0 and at 1
/// ([`conformance::cube_push_m`]): the pushes differ by the spec's least
/// distance.
pub fn cube_friction(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[objects.cube]\nfriction = 0.0\n";
    if !measurable(
        engine,
        ParamKey::ObjectFriction,
        text,
        "objects.cube.friction",
    ) {
        return;
    }
    let (slippery, rough) = with_subject(engine, spec, |s| {
        (
            conformance::cube_push_m(s, 0.0),
            conformance::cube_push_m(s, 1.0),
        )
    });
    let least = spec.effects.friction_push_m;
    report(engine, "cube_push_friction0_m", slippery, least);
    report(engine, "cube_push_friction1_m", rough, least);
    report(
        engine,
        "cube_push_difference_m",
        (slippery - rough).abs(),
        least,
    );
    assert!(
        (slippery - rough).abs() > least,
        "friction 0: {slippery} m, friction 1: {rough} m"
    );
}

/// Every key the engine does not honour is an error naming the engine and
/// the key ([`conformance::unsupported_key_error`] for each); a key set
/// where it has no effect (damping on a held finger joint, a mass factor
/// on the fixed base link) is the engine's error naming the key.
pub fn unsupported_keys(engine: &dyn Engine, spec: &KitSpec) {
    let examples = [
        (
            ParamKey::JointDamping,
            "[joints.m1n6s300_joint_2]\ndamping = 1.0\n",
        ),
        (
            ParamKey::JointArmature,
            "[joints.m1n6s300_joint_2]\narmature = 0.01\n",
        ),
        (
            ParamKey::JointFrictionloss,
            "[joints.m1n6s300_joint_2]\nfrictionloss = 0.1\n",
        ),
        (ParamKey::JointKv, "[joints.m1n6s300_joint_2]\nkv = 40.0\n"),
        (
            ParamKey::JointForceLimit,
            "[joints.m1n6s300_joint_2]\nforce_limit = 30.0\n",
        ),
        (
            ParamKey::LinkMassScale,
            "[links.m1n6s300_link_3]\nmass_scale = 1.1\n",
        ),
        (ParamKey::ObjectMass, "[objects.cube]\nmass_kg = 0.1\n"),
        (ParamKey::ObjectFriction, "[objects.cube]\nfriction = 0.5\n"),
        (
            ParamKey::ObjectRestitution,
            "[objects.cube]\nrestitution = 0.1\n",
        ),
        (
            ParamKey::ContactTimeConstant,
            "[contact]\ntime_constant_s = 0.02\n",
        ),
        (
            ParamKey::ContactDampingRatio,
            "[contact]\ndamping_ratio = 1.0\n",
        ),
    ];
    let mut refused = 0;
    for (key, text) in examples {
        if honours(engine, key) {
            continue;
        }
        let field = key
            .pattern()
            .replace("<joint>", "m1n6s300_joint_2")
            .replace("<link>", "m1n6s300_link_3")
            .replace("<object>", "cube");
        assert_refused(engine, text, &field);
        refused += 1;
    }
    if refused > 0 {
        let (key, e) = conformance::unsupported_key_error(engine).expect("an unsupported key");
        assert!(!honours(engine, key), "{key}: {e}");
    }
    report(engine, "unsupported_keys", refused as f64, 0.0);
    let scene = testing::scene("scene1_single_joint");
    let settings = study_settings(engine, spec);
    for (key, text, field) in [
        (
            ParamKey::JointDamping,
            "[joints.m1n6s300_joint_finger_1]\ndamping = 1.0\n",
            "joints.m1n6s300_joint_finger_1.damping",
        ),
        (
            ParamKey::LinkMassScale,
            "[links.m1n6s300_link_base]\nmass_scale = 2.0\n",
            "links.m1n6s300_link_base.mass_scale",
        ),
    ] {
        if !honours(engine, key) || (key == ParamKey::JointDamping && !spec.held_joints_rigid) {
            continue;
        }
        let e = load(engine, &scene, &testing::mico2(), &settings, &params(text))
            .err()
            .unwrap_or_else(|| panic!("{}: {field} was accepted", engine.name()));
        eprintln!("{}: {field}: {e}", engine.name());
        match &e {
            EngineError::Param {
                engine: name, key, ..
            } => {
                assert_eq!((name.as_str(), key.as_str()), (engine.name(), field));
            }
            other => panic!("{}: {field}: {other}", engine.name()),
        }
    }
}

/// With every servo off, joint 2 does not move without gravity and falls
/// with it ([`conformance::gravity_effect_rad`]). An engine without
/// dynamics refuses the force limit the check switches the servos off
/// with.
pub fn gravity(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[joints.m1n6s300_joint_2]\nforce_limit = 0.0\n";
    if !measurable(
        engine,
        ParamKey::JointForceLimit,
        text,
        &format!("{JOINT_2}.force_limit"),
    ) {
        return;
    }
    let (without, with) = with_subject(engine, spec, conformance::gravity_effect_rad);
    let [still, moves] = spec.effects.gravity_rad;
    report(engine, "gravity_zero_moved_rad", without, still);
    report(engine, "gravity_default_moved_rad", with, moves);
    assert!(without < still, "moved {without} rad without gravity");
    assert!(with > moves, "moved only {with} rad with gravity");
}

/// Armature 0.5 kg m^2 on joint 2 slows its fall with the servos off by
/// the spec's ratio, with and without dry friction on the joint (where
/// the engine honours `frictionloss`); on the rotor under a constant torque, an armature
/// equal to its inertia halves the angle turned in a second (reflected
/// inertia), to the spec's tolerance.
pub fn armature(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[joints.m1n6s300_joint_2]\narmature = 0.5\n";
    if !measurable(
        engine,
        ParamKey::JointArmature,
        text,
        &format!("{JOINT_2}.armature"),
    ) {
        return;
    }
    let plain = fall(engine, spec, "");
    let heavy = fall(engine, spec, "armature = 0.5\n");
    let ratio = spec.effects.armature_ratio;
    report(engine, "armature_fall_ratio", heavy / plain, ratio);
    assert!(
        heavy < plain * ratio,
        "armature 0.5: {heavy} rad, none: {plain} rad"
    );
    // The same with dry friction on the joint: an engine that models it
    // as a second element on the joint (Drake's second actuator) keeps
    // the armature.
    if honours(engine, ParamKey::JointFrictionloss) {
        let rubbing = "frictionloss = 1.0\n";
        let plain = fall(engine, spec, rubbing);
        let heavy = fall(engine, spec, &format!("armature = 0.5\n{rubbing}"));
        report(
            engine,
            "armature_fall_ratio_with_friction",
            heavy / plain,
            ratio,
        );
        assert!(
            heavy < plain * ratio,
            "armature 0.5 and frictionloss 1: {heavy} rad, frictionloss alone: {plain} rad"
        );
    }
    if !spec.takes_efforts {
        return;
    }
    let (rotor, robot) = conformance::rotor();
    let settings = super::settings(spec.rotor_settings);
    let angle = |armature: f64| {
        let p = params(&format!("[joints.spin]\narmature = {armature:?}\n"));
        let mut sim = load(engine, &rotor, &robot, &settings, &p).unwrap();
        sim.set_joint_commands(&[ServoCommand::effort(0.02)])
            .unwrap();
        sim.step_n((1.0 / sim.timestep_s()).round() as u64).unwrap();
        let mut q = [0.0];
        sim.joint_angles_rad(&mut q);
        q[0]
    };
    let (free, loaded) = (angle(0.0), angle(conformance::ROTOR_INERTIA_KG_M2));
    let gap = (loaded / free - 0.5).abs();
    report(
        engine,
        "armature_rotor_ratio_gap",
        gap,
        spec.effects.armature_rotor_ratio,
    );
    assert!(
        gap <= spec.effects.armature_rotor_ratio,
        "rotor with armature turns {loaded} rad, without {free} rad"
    );
}

/// Dry friction on joint 2 (its servo off): 1 N m slows the fall, 50 N m
/// (more than gravity's torque) holds the joint.
pub fn frictionloss(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[joints.m1n6s300_joint_2]\nfrictionloss = 1.0\n";
    if !measurable(
        engine,
        ParamKey::JointFrictionloss,
        text,
        &format!("{JOINT_2}.frictionloss"),
    ) {
        return;
    }
    let free = fall(engine, spec, "");
    let some = fall(engine, spec, "frictionloss = 1.0\n");
    let stuck = fall(engine, spec, "frictionloss = 50.0\n");
    let [ratio, held] = spec.effects.frictionloss;
    report(engine, "frictionloss_fall_ratio_1", some / free, ratio);
    report(engine, "frictionloss_fall_50_rad", stuck, held);
    assert!(some < free * ratio, "{some} vs {free}");
    assert!(stuck < held, "{stuck}");
}

/// Scene 3's cube dropped from 0.2 m above its rest with `toml`: the
/// highest it climbs after its first impact within 1.5 s, m above rest.
fn bounce_m(engine: &dyn Engine, spec: &KitSpec, toml: &str) -> f64 {
    let scene = testing::scene("scene3_cube_push");
    let settings = study_settings(engine, spec);
    let mut sim = load(engine, &scene, &testing::mico2(), &settings, &params(toml)).unwrap();
    let mut state = sim.state().unwrap().portable();
    let rest = state.objects[0].pose.position_m.z;
    state.objects[0].pose.position_m.z = rest + 0.2;
    sim.set_state(&state).unwrap();
    let (mut fell, mut top) = (false, f64::NEG_INFINITY);
    let mut poses = [Pose::IDENTITY; 2];
    for _ in 0..(1.5 / sim.timestep_s()).round() as usize {
        sim.step().unwrap();
        sim.tracked_poses(&mut poses);
        let z = poses[1].position_m.z - rest;
        if z < 0.01 {
            fell = true;
        } else if fell {
            top = top.max(z);
        }
    }
    top.max(0.0)
}

/// The cube dropped from 0.2 m: without restitution it stays down; with
/// 0.5 and 0.8 it climbs back to the elastic model's `e^2 h` within the
/// spec's ratios.
pub fn restitution(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[objects.cube]\nrestitution = 0.5\n";
    if !measurable(
        engine,
        ParamKey::ObjectRestitution,
        text,
        "objects.cube.restitution",
    ) {
        return;
    }
    let dead = bounce_m(engine, spec, "");
    report(
        engine,
        "bounce_restitution0_m",
        dead,
        spec.effects.dead_bounce_m,
    );
    assert!(dead < spec.effects.dead_bounce_m, "{dead} m");
    let [lo, hi] = spec.effects.bounce_ratio;
    for e in [0.5, 0.8] {
        let up = bounce_m(
            engine,
            spec,
            &format!("[objects.cube]\nrestitution = {e:?}\n"),
        );
        let ratio = up / (e * e * 0.2);
        report(engine, &format!("bounce_ratio_restitution{e}"), ratio, lo);
        assert!(
            (lo..=hi).contains(&ratio),
            "restitution {e}: up {up} m, {ratio} of e^2 h"
        );
    }
}

/// Scene 3's cube resting on the table for 1 s with `toml`: its height, m.
fn rest_z(engine: &dyn Engine, spec: &KitSpec, toml: &str) -> f64 {
    let scene = testing::scene("scene3_cube_push");
    let settings = study_settings(engine, spec);
    let mut sim = load(engine, &scene, &testing::mico2(), &settings, &params(toml)).unwrap();
    sim.set_joint_velocity_targets(&[0.0; 6]);
    sim.step_n((1.0 / sim.timestep_s()).round() as u64).unwrap();
    sim.state().unwrap().objects[0].pose.position_m.z
}

/// Softer contacts (`[contact]` time constant 0.02 s with damping ratio 1,
/// then 2: a spring-damper of natural frequency 1 / (tau zeta), 50 then 25
/// rad/s) let the resting cube sink deeper, each by the spec's least
/// distance. (Each engine's own mapping of the two keys is checked against
/// its law in the engine's tests.)
pub fn contact_softness(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[contact]\ntime_constant_s = 0.02\n";
    if !measurable(
        engine,
        ParamKey::ContactTimeConstant,
        text,
        "contact.time_constant_s",
    ) {
        return;
    }
    let stiff = rest_z(engine, spec, "");
    let soft = rest_z(
        engine,
        spec,
        "[contact]\ntime_constant_s = 0.02\ndamping_ratio = 1.0\n",
    );
    let softer = rest_z(
        engine,
        spec,
        "[contact]\ntime_constant_s = 0.02\ndamping_ratio = 2.0\n",
    );
    let least = spec.effects.contact_sink_m;
    if spec.effects.own_contact_is_tau_0_02 {
        report(engine, "contact_sink_tau0.02_zeta1_m", stiff - soft, 1e-12);
        assert!(
            (stiff - soft).abs() <= 1e-12,
            "default {stiff} m, tau 0.02 s {soft} m"
        );
    } else {
        report(engine, "contact_sink_tau0.02_zeta1_m", stiff - soft, least);
        assert!(stiff - soft > least, "default {stiff} m, soft {soft} m");
    }
    report(engine, "contact_sink_tau0.02_zeta2_m", soft - softer, least);
    if spec.effects.own_contact_is_tau_0_02 {
        // MuJoCo's rest depth follows its impedance (`solimp`) as well as
        // the spring: the damping ratio changes it, in either direction.
        assert!(
            (soft - softer).abs() > least,
            "zeta 1 {soft} m, zeta 2 {softer} m"
        );
    } else {
        assert!(soft - softer > least, "zeta 1 {soft} m, zeta 2 {softer} m");
    }
}

/// A 5 kg cube moves differently under scene 3's push than the scene's
/// 0.0884 kg one, by the spec's least distance.
pub fn cube_mass(engine: &dyn Engine, spec: &KitSpec) {
    let text = "[objects.cube]\nmass_kg = 5.0\n";
    if !measurable(engine, ParamKey::ObjectMass, text, "objects.cube.mass_kg") {
        return;
    }
    let scene = testing::scene("scene3_cube_push");
    let robot = testing::mico2();
    let push = |p: &PhysicalParams| {
        let c = testing::cube(&run(engine, spec, &scene, &robot, p, &[]));
        c.last().unwrap().x - c[0].x
    };
    let light = push(&PhysicalParams::none());
    let heavy = push(&params(text));
    let least = spec.effects.cube_mass_push_m;
    report(
        engine,
        "cube_mass_push_difference_m",
        (light - heavy).abs(),
        least,
    );
    assert!((light - heavy).abs() > least, "{light} vs {heavy}");
}

/// Heavier links droop more: with every mass 1.5 times larger (a model
/// variation) and with link 3's mass doubled (`links.L.mass_scale`),
/// scene 1 ends where the servos balance the heavier arm (for a stiff
/// servo: still at its targets), within the spec's scene 1 tolerance.
pub fn masses(engine: &dyn Engine, spec: &KitSpec) {
    let scene = testing::scene("scene1_single_joint");
    let robot = testing::mico2();
    let targets = scene.targets_deg_at_tick(scene.sample_count() - 1);
    let mut heavy = robot.clone();
    for link in &mut heavy.links {
        if let Some(i) = &mut link.inertial {
            i.mass_kg *= 1.5;
        }
    }
    let mut link3 = robot.clone();
    let l3 = link3.link_by_name("m1n6s300_link_3").unwrap();
    if let Some(i) = &mut link3.links[l3].inertial {
        i.mass_kg *= 2.0;
    }
    let settings = settings_for(engine, spec, &scene, &[]);
    let variation = ModelVariation {
        mass_scale: 1.5,
        friction_scale: 1.0,
    };
    let mut sim = engine.load(&scene, &robot, &settings, &variation).unwrap();
    let varied = crate::controller::run_scene(sim.as_mut(), &scene, &Default::default()).unwrap();
    let mut runs: Vec<(&str, RunOutcome, &crate::RobotModel)> =
        vec![("masses x1.5", varied, &heavy)];
    let text = "[links.m1n6s300_link_3]\nmass_scale = 2.0\n";
    if measurable(
        engine,
        ParamKey::LinkMassScale,
        text,
        "links.m1n6s300_link_3.mass_scale",
    ) {
        runs.push((
            "link 3 x2",
            run(engine, spec, &scene, &robot, &params(text), &[]),
            &link3,
        ));
    }
    for (what, out, model) in runs {
        let got = testing::final_angles_deg(&out);
        let (want, tolerance) = match spec.scene1_end {
            super::End::Equilibrium(t) => (static_equilibrium_deg(&scene, model, &targets), t),
            super::End::Targets(t) => (targets.clone(), t),
        };
        let gap = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{}: {what}: final {got:.3?} deg, expected {want:.3?} deg",
            engine.name()
        );
        report(engine, &format!("scene1 {what} end_deg"), gap, tolerance);
        assert!(gap <= tolerance, "{what}: {gap} deg from {want:?}");
    }
}

/// The cube's displacement between the first and last sample of a run.
pub fn cube_moved(out: &RunOutcome) -> Vec3 {
    let c = testing::cube(out);
    *c.last().unwrap() - c[0]
}

/// Two links of a robot that are not joined by a joint, overlapping by
/// 5 mm at rest: the base's box and the tip's box, the tip held by a
/// velocity servo on a horizontal joint 0.1 m beside the overlap, without
/// gravity. Where they collide, the contact pushes the tip up and turns its
/// joint; where they do not, it stays at rest.
pub const OVERLAP_URDF: &str = r#"<?xml version="1.0"?>
<robot name="overlap">
  <link name="base">
    <inertial><mass value="5.0"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.05"/><geometry><box size="0.4 0.4 0.1"/></geometry></collision>
  </link>
  <joint name="lift" type="revolute">
    <parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.0" upper="3.0" effort="50" velocity="10"/>
  </joint>
  <link name="arm">
    <inertial><mass value="0.5"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="fold" type="revolute">
    <parent link="arm"/><child link="tip"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-3.0" upper="3.0" effort="50" velocity="10"/>
  </joint>
  <link name="tip">
    <inertial><origin xyz="0 0.1 -0.155"/><mass value="0.5"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0.1 -0.155"/><geometry><box size="0.1 0.1 0.1"/></geometry></collision>
  </link>
</robot>
"#;

/// Self-collision: a robot's links that are not joined by a joint collide
/// with `self_collision = true` and pass through each other with `false`
/// (the setting where the engine has it; an engine without it must never
/// collide a robot with itself). Measured on [`OVERLAP_URDF`] over 0.5 s:
/// the held joint's largest angle.
pub fn self_collision(engine: &dyn Engine, spec: &KitSpec) {
    if !spec.dynamics {
        return;
    }
    let dir = TempDir::new(engine.name(), "self-collision");
    let urdf = dir.path("overlap.urdf");
    std::fs::write(&urdf, OVERLAP_URDF).unwrap();
    let text = r#"
name = "overlap"
description = "two links not joined by a joint, overlapping at rest"
duration_s = 0.5
gravity_m_s2 = [0.0, 0.0, 0.0]
[robot]
urdf = "overlap.urdf"
base_position_m = [0.0, 0.0, 0.0]
[controller]
gain_per_s = 1.0
max_speed_deg_s = 1.0
period_s = 0.01
[[actuator]]
joint = "lift"
kv = 5.0
force_limit = 50.0
[[actuator]]
joint = "fold"
kv = 0.2
force_limit = 50.0
[[schedule]]
t_s = 0.0
targets_deg = {}
[[track]]
role = "tip"
link = "tip"
"#;
    let scene = crate::scene::Scene::from_toml_str(text, &dir.path("overlap.toml")).unwrap();
    let robot =
        crate::robot::RobotModel::from_urdf_file(&urdf, &crate::robot::PackageResolver::new())
            .unwrap();
    let has = engine
        .settings_help()
        .iter()
        .any(|i| i.key == "self_collision");
    let largest = |extra: &[&str]| -> f64 {
        let settings = settings_for(engine, spec, &scene, extra);
        let mut sim = engine
            .load(&scene, &robot, &settings, &ModelVariation::default())
            .unwrap_or_else(|e| panic!("{}: {e}", engine.name()));
        let steps = (0.5 / sim.timestep_s()).round() as u64;
        let mut q = vec![0.0; sim.joint_count()];
        let mut most: f64 = 0.0;
        for _ in 0..steps {
            sim.set_joint_velocity_targets(&[0.0, 0.0]);
            sim.step().unwrap();
            sim.joint_angles_rad(&mut q);
            most = most.max(q[1].abs());
        }
        most
    };
    let apart = largest(if has { &["self_collision=false"] } else { &[] });
    report(engine, "self_collision_off_rad", apart, 1e-6);
    assert!(
        apart <= 1e-6,
        "{}: without self-collision the overlapping links moved the held joint {apart:e} rad",
        engine.name()
    );
    if has {
        let pushed = largest(&["self_collision=true"]);
        report(engine, "self_collision_on_rad", pushed, 1e-3);
        assert!(
            pushed > 1e-3,
            "{}: with self-collision the overlapping links did not push each other apart ({pushed:e} rad)",
            engine.name()
        );
    }
}
