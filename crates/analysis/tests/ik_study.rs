//! Inverse kinematics of the study's real runs (the wrist body's 6D
//! capture): the registration and marker offset fitted on runs 1-15 of each
//! scene, every frame of runs 16-20 solved with them. The residuals stay
//! under a couple of millimetres and degrees, and the joint angles are on
//! the arm's branch: where the commanded motion holds the arm still, they
//! are where it was sent (the real arm's static offsets are under a degree,
//! METHOD.md).

use realitygap_analysis::ik::{fit, solve_run, CaptureRun};
use realitygap_core::testing::{mico2, paper_data, scene};
use realitygap_core::Trajectory;
use realitygap_data::qualisys::{read, QualisysOptions};

fn runs(dir: &str, prefix: &str, ids: std::ops::RangeInclusive<u32>) -> Vec<Trajectory> {
    let Some(paper) = paper_data() else {
        return Vec::new();
    };
    ids.map(|i| {
        let f = paper.join(format!("MotionCapture/{dir}/{prefix}{i:04}_6D.tsv"));
        read(&f, &QualisysOptions::collins2019())
            .unwrap()
            .trajectory
    })
    .collect()
}

#[test]
fn the_real_runs_are_solved_to_millimetres_on_the_arms_branch() {
    let robot = mico2();
    // Scene, data, bound on the held-out residuals (mm, deg), and the
    // final angles the commanded motion ends at (deg).
    let cases = [
        (
            "scene1_single_joint",
            "Experiment1",
            "Single",
            (1.0, 1.0),
            [0.0, -100.0, 0.0, 0.0, 0.0, 0.0],
        ),
        (
            "scene2_two_joints",
            "Experiment2",
            "Double",
            (1.5, 1.0),
            [0.0; 6],
        ),
        (
            "scene3_cube_push",
            "Experiment3",
            "CubeExp",
            (1.5, 2.0),
            [0.0, -67.0, 30.0, 90.0, 0.0, 0.0],
        ),
    ];
    for (name, dir, prefix, (mm, deg), end) in cases {
        let s = scene(name);
        let train = runs(dir, prefix, 1..=15);
        if train.is_empty() {
            return;
        }
        let capture: Vec<CaptureRun> = train
            .iter()
            .map(|t| CaptureRun {
                trajectory: t,
                role: "wrist",
            })
            .collect();
        let f = fit(&s, &robot, &capture, 20).unwrap();
        println!(
            "{name}: fitted on {} frames: {:.2} mm, {:.2} deg RMS; yaw {:.2} deg; marker {:.1} mm from the link",
            f.frames,
            f.fit_position_rms_mm,
            f.fit_angle_rms_deg,
            f.registration.yaw_rad.to_degrees(),
            f.marker_in_link.position_m.norm() * 1e3
        );
        for (i, t) in runs(dir, prefix, 16..=20).iter().enumerate() {
            let r = solve_run(
                &s,
                &robot,
                &f,
                &CaptureRun {
                    trajectory: t,
                    role: "wrist",
                },
            )
            .unwrap();
            let last: Vec<f64> = r
                .angles_rad
                .last()
                .unwrap()
                .iter()
                .map(|a| a.to_degrees())
                .collect();
            println!(
                "  run {}: {:.2} mm, {:.2} deg RMS; final angles {:.1?} deg",
                16 + i,
                r.position_rms_mm(),
                r.angle_rms_deg(),
                last
            );
            assert!(
                r.position_rms_mm() < mm && r.angle_rms_deg() < deg,
                "{name} run {}",
                16 + i
            );
            // Scene 3 ends pushing the cube: joints 2 and 3 are held off
            // their targets by it; elsewhere the arm ends where it was sent,
            // within its overshoot and offsets.
            for (j, (a, e)) in last.iter().zip(end).enumerate() {
                let tolerance = if name == "scene3_cube_push" && (j == 1 || j == 2) {
                    10.0
                } else {
                    3.0
                };
                assert!(
                    (a - e).abs() < tolerance,
                    "{name} run {}: joint {} ends at {a:.1} deg, sent to {e}",
                    16 + i,
                    j + 1
                );
            }
        }
    }
}
