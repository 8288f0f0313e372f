//! The study's scenes in ODE: the targets are reached with the default
//! settings, the wrist ends where the MuJoCo engine's does when both use the
//! scene's servo law, all three scenes run with both robots, the hand
//! pushes the cube, the base stays put, and an unstable setting is reported
//! as diverged rather than as numbers.

mod common;

use common::*;
use realitygap_core::controller::RunStatus;
use realitygap_core::controller::{simulate, RunOptions};
use realitygap_core::engine::{ModelVariation, Simulation};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use realitygap_engine_ode::OdeSimulation;

/// The robots to test with: the project's Mico2, and the official Kinova
/// model when the paper data is there.
fn robots(s: &Scene) -> Vec<(Scene, RobotModel, &'static str)> {
    let mut v = vec![(s.clone(), mico2(), "mico2")];
    if let Some(paper) = paper_data() {
        let (s, r) = with_official_robot(s, &paper);
        v.push((s, r, "official"));
    }
    v
}

/// Issue: in scene 1 with the default settings, joint 2 ends within 1
/// degree of -100 and the other joints within 1 degree of 0.
#[test]
fn scene1_default_settings_reach_the_targets() {
    for (s, robot, label) in robots(&scene("scene1_single_joint")) {
        let out = run_ode(&s, &robot, &[]);
        assert_eq!(out.status, RunStatus::Completed, "{label}");
        assert_eq!(out.trajectory.len(), 120);
        let q = final_angles_deg(&out);
        eprintln!("{label}: final joint angles {q:.4?} deg");
        assert!(
            (q[1] + 100.0).abs() < 1.0,
            "{label}: joint 2 ends at {} deg",
            q[1]
        );
        for (j, a) in q.iter().enumerate().filter(|(j, _)| *j != 1) {
            assert!(a.abs() < 1.0, "{label}: joint {} ends at {a} deg", j + 1);
        }
    }
}

/// Issue: the final wrist is within 5 mm of the MuJoCo engine's on the same
/// model. The same model includes the servo: MuJoCo's `<velocity kv>`
/// actuator yields under load (joint 2 ends 1.36 degrees below -100, joint
/// 3 1.94 degrees off), ODE's own motor does not; with `servo = "kv"` ODE
/// applies the scene's servo law and the wrists agree.
#[test]
fn scene1_wrist_ends_where_mujoco_puts_it() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    s.validate(&robot).unwrap();
    let mujoco = simulate(
        &realitygap_engine_mujoco::MujocoEngine,
        &s,
        &robot,
        &s.settings_for("mujoco"),
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(mujoco.status, RunStatus::Completed);
    let reference = *wrist(&mujoco).last().unwrap();

    let kv = run_ode(&s, &robot, &["servo=kv"]);
    let gap_kv = wrist(&kv).last().unwrap().distance(reference);
    let motor = run_ode(&s, &robot, &[]);
    let gap_motor = wrist(&motor).last().unwrap().distance(reference);
    let (qm, qk) = (final_angles_deg(&mujoco), final_angles_deg(&kv));
    eprintln!(
        "final wrist vs MuJoCo: servo=kv {:.3} mm, servo=motor (default) {:.1} mm; joints MuJoCo {qm:.3?} deg, ODE kv {qk:.3?} deg",
        gap_kv * 1e3,
        gap_motor * 1e3
    );
    assert!(
        gap_kv < 0.005,
        "ODE (servo=kv) ends {:.2} mm from MuJoCo",
        gap_kv * 1e3
    );
    for (a, b) in qm.iter().zip(&qk) {
        assert!(
            (a - b).abs() < 0.05,
            "joint angles differ: MuJoCo {qm:?}, ODE {qk:?}"
        );
    }
    // The default motor does not sag: it ends nearer the target than MuJoCo.
    assert!(gap_motor > gap_kv);
    let q = final_angles_deg(&motor);
    assert!((q[1] + 100.0).abs() < (qm[1] + 100.0).abs());
}

/// All three scenes run to the end with both robots and both steppers' exact
/// variant, ending at their last targets.
#[test]
fn all_scenes_run_with_both_robots() {
    for name in [
        "scene1_single_joint",
        "scene2_two_joints",
        "scene3_cube_push",
    ] {
        let base = scene(name);
        let last_targets = base.targets_deg_at_tick(base.sample_count() - 1);
        for (s, robot, label) in robots(&base) {
            let out = run_ode(&s, &robot, &[]);
            assert_eq!(out.status, RunStatus::Completed, "{name} {label}");
            assert_eq!(out.trajectory.len(), s.sample_count());
            out.trajectory.validate().unwrap();
            let q = final_angles_deg(&out);
            for (j, (a, t)) in q.iter().zip(&last_targets).enumerate() {
                assert!(
                    (a - t).abs() < 1.0,
                    "{name} {label}: joint {} ends at {a} deg, target {t}",
                    j + 1
                );
            }
            eprintln!("{name} {label}: {:.0} steps/s", out.steps_per_second());
        }
    }
}

/// Scene 3: the hand reaches the cube and pushes it along +x over the floor,
/// without tipping it over or pressing it through the floor.
#[test]
fn scene3_hand_pushes_the_cube_over_the_floor() {
    for (s, robot, label) in robots(&scene("scene3_cube_push")) {
        for pairs in [&[][..], &["servo=kv"][..]] {
            let out = run_ode(&s, &robot, pairs);
            assert_eq!(out.status, RunStatus::Completed);
            let c = cube(&out);
            let (start, end) = (c[0], *c.last().unwrap());
            let rot = out.trajectory.bodies[1].poses[0]
                .unwrap()
                .orientation
                .angle_to(
                    out.trajectory.bodies[1]
                        .poses
                        .last()
                        .unwrap()
                        .unwrap()
                        .orientation,
                );
            eprintln!(
                "{label} {pairs:?}: cube moved {:.1} mm along x, {:.1} mm along y, turned {:.2} deg",
                (end.x - start.x) * 1e3,
                (end.y - start.y) * 1e3,
                rot.to_degrees()
            );
            assert!(
                end.x - start.x > 0.002,
                "{label} {pairs:?}: the cube did not move along +x ({start:?} -> {end:?})"
            );
            let (zmin, zmax) = c.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
                (lo.min(p.z), hi.max(p.z))
            });
            eprintln!("{label} {pairs:?}: cube centre between z = {zmin:.4} m and {zmax:.4} m");
            // Pressed into the floor by less than 2 mm, resting on it at the end
            // (the hand may tilt it up on the way).
            assert!(
                zmin > 0.0375 - 0.002,
                "{label} {pairs:?}: the cube sank to z = {zmin} m"
            );
            assert!(
                (end.z - 0.0375).abs() < 0.001,
                "{label} {pairs:?}: the cube ends at z = {} m",
                end.z
            );
            assert!(
                rot.to_degrees() < 10.0,
                "{label}: the cube turned {} deg",
                rot.to_degrees()
            );
        }
    }
}

/// Largest distance (m) and angle (rad) of the base link from the scene's
/// base pose over scene 2 (the arm swinging), with `pairs` as settings. (A
/// small controller loop here, to read the base between control steps.)
fn base_motion(pairs: &[&str]) -> (f64, f64) {
    let s = scene("scene2_two_joints");
    let robot = mico2();
    s.validate(&robot).unwrap();
    let mut sim =
        OdeSimulation::load(&s, &robot, &settings(pairs), &ModelVariation::default()).unwrap();
    let base_link = &robot.links[robot.root_link].name;
    let (mut worst_m, mut worst_rad): (f64, f64) = (0.0, 0.0);
    for tick in 0..s.sample_count() {
        let targets: Vec<f64> = s
            .targets_deg_at_tick(tick)
            .iter()
            .map(|t| t.to_radians())
            .collect();
        let mut q = vec![0.0; 6];
        sim.joint_angles_rad(&mut q);
        let command: Vec<f64> = q
            .iter()
            .zip(&targets)
            .map(|(a, t)| (10.0 * (t - a)).clamp(-0.52, 0.52))
            .collect();
        sim.set_joint_velocity_targets(&command);
        sim.step_n(5).unwrap();
        let p = sim.link_pose(base_link).unwrap();
        worst_m = worst_m.max(p.position_m.distance(s.robot.base.position_m));
        worst_rad = worst_rad.max(p.orientation.angle_to(s.robot.base.orientation));
    }
    (worst_m, worst_rad)
}

/// The base is held at the scene's base pose: by a fixed joint (default),
/// as soft as any ODE constraint (CFM), it gives way by micrometres under
/// the swinging arm; as static geometry it does not move at all.
#[test]
fn base_stays_at_the_base_pose() {
    let (m, rad) = base_motion(&[]);
    eprintln!("fixed-joint base moved at most {m:.3e} m and turned at most {rad:.3e} rad");
    assert!(
        m < 1e-4 && rad < 1e-3,
        "the base moved {m} m, turned {rad} rad"
    );
    let (m, rad) = base_motion(&["base=static"]);
    assert!(
        m < 1e-12 && rad < 1e-7,
        "the static base moved {m} m, turned {rad} rad"
    );
}

/// ODE's iterative solver is the setting that fails on this arm: with its
/// default 20 iterations the joints drift degrees off (and scene 3 blows
/// up), with more iterations it approaches dWorldStep.
#[test]
fn quick_step_converges_to_world_step_with_iterations() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let exact = final_angles_deg(&run_ode(&s, &robot, &[]));
    let error = |pairs: &[&str]| {
        let q = final_angles_deg(&run_ode(&s, &robot, pairs));
        q.iter()
            .zip(&exact)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    };
    let coarse = error(&["stepper=quick_step"]);
    let fine = error(&["stepper=quick_step", "quick_step_iterations=1000"]);
    eprintln!("quick_step vs world_step, largest joint difference: 20 iterations {coarse:.2} deg, 1000 iterations {fine:.3} deg");
    assert!(coarse > 1.0, "{coarse}");
    assert!(fine < 0.5 && fine < coarse / 10.0, "{fine}");
}

/// dWorldQuickStep reorders constraints with ODE's process-wide random
/// generator; each simulation keeps its own generator state, so a run does
/// not depend on other simulations stepping in the same process.
#[test]
fn quick_step_runs_do_not_depend_on_each_other() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    s.validate(&robot).unwrap();
    let quick = settings(&["stepper=quick_step"]);
    let load = || OdeSimulation::load(&s, &robot, &quick, &ModelVariation::default()).unwrap();
    let targets = [0.2, -0.5, 0.1, 0.3, -0.3, 0.5];
    let (mut alone, mut a, mut b) = (load(), load(), load());
    for sim in [&mut alone, &mut a, &mut b] {
        sim.set_joint_velocity_targets(&targets);
    }
    alone.step_n(200).unwrap();
    for _ in 0..4 {
        a.step_n(50).unwrap();
        b.step_n(37).unwrap();
    }
    let (mut qa, mut qb) = ([0.0; 6], [0.0; 6]);
    alone.joint_angles_rad(&mut qa);
    a.joint_angles_rad(&mut qb);
    assert_eq!(qa, qb);
}

/// A deliberately unstable setting (the iterative solver with one
/// iteration at the largest timestep the control period allows) ends the
/// run as diverged, with the time and the reason, and the samples before.
#[test]
fn unstable_setting_is_reported_as_diverged() {
    let s = scene("scene1_single_joint");
    let robot = mico2();
    let out = run_ode(
        &s,
        &robot,
        &[
            "timestep_s=0.05",
            "stepper=quick_step",
            "quick_step_iterations=1",
        ],
    );
    match &out.status {
        RunStatus::Diverged { t_s, reason } => {
            eprintln!("diverged at {t_s} s: {reason}");
            assert!(*t_s > 0.0 && *t_s < s.duration_s, "{t_s}");
            assert!(
                reason.contains("moves at")
                    || reason.contains("spins at")
                    || reason.contains("not finite"),
                "{reason}"
            );
            assert!(out.trajectory.len() < s.sample_count());
            assert!(out.trajectory.len() as f64 * s.controller.period_s <= t_s + 1e-9);
        }
        RunStatus::Completed => panic!("the unstable setting completed"),
    }
    // The same scene with the defaults completes (the divergence is the
    // setting's).
    assert_eq!(run_ode(&s, &robot, &[]).status, RunStatus::Completed);
}
