//! Fidelity: the study's own MJCF (`m1n6s300.xml`) driven by the shared
//! controller through this engine reproduces the study's MuJoCo recordings
//! (`Simulation/Experiment{1,2,3}/*_Mujoco_0.csv`, wrist xyz in columns 1-3,
//! cube xyz in columns 8-10).
//!
//! The study ran MuJoCo 1.5; this is MuJoCo 3.17. The remaining gaps come
//! from the transients: the first 0.1-0.15 s (the arm starting from rest
//! while its mesh geoms touch permanently: root box / base / shoulder) and,
//! in scene 3, the slow lift of the forearm by joint 3 (kv 10). They shrink
//! to micrometres once the joints reach their targets. With contacts
//! disabled, scene 1's gap drops to 2.8 mm at most and the last row agrees
//! to nanometres, which points at the two versions' contact solvers.

mod common;

use common::*;
use realitygap_core::Vec3;
use std::path::Path;

struct Gap {
    max_m: f64,
    max_row: usize,
    max_after_settling_m: f64,
    last_m: f64,
    last_cube_m: f64,
}

fn compare(scene_name: &str, csv: &str, paper: &Path) -> Gap {
    let mut scene = scene(scene_name);
    scene.robot.mjcf = Some(paper.join("kinova_description/urdf/m1n6s300.xml"));
    let robot = official_robot(paper);
    let out = run(&scene, &robot);
    let study = read_study_csv(&paper.join("Simulation").join(csv));
    let ours = wrist(&out);
    let cubes = cube(&out);
    assert_eq!(ours.len(), study.len(), "{scene_name}: sample count");
    let gaps: Vec<f64> = ours
        .iter()
        .zip(&study)
        .map(|(p, r)| p.distance(Vec3::new(r[0], r[1], r[2])))
        .collect();
    let (max_row, max_m) = gaps
        .iter()
        .copied()
        .enumerate()
        .fold((0, 0.0), |a, (i, g)| if g > a.1 { (i, g) } else { a });
    let max_after_settling_m = gaps[4..].iter().copied().fold(0.0, f64::max);
    let last = study.last().unwrap();
    let gap = Gap {
        max_m,
        max_row,
        max_after_settling_m,
        last_m: *gaps.last().unwrap(),
        last_cube_m: cubes
            .last()
            .unwrap()
            .distance(Vec3::new(last[7], last[8], last[9])),
    };
    eprintln!(
        "{scene_name}: wrist gap max {:.3} mm (row {}), max from row 4 on {:.3} mm, last {:.4} mm; cube last {:.4} mm; {:.0} steps/s",
        gap.max_m * 1e3,
        gap.max_row,
        gap.max_after_settling_m * 1e3,
        gap.last_m * 1e3,
        gap.last_cube_m * 1e3,
        out.steps_per_second()
    );
    gap
}

#[test]
fn scene1_matches_the_study_recording() {
    let Some(paper) = paper_data() else { return };
    let g = compare(
        "scene1_single_joint",
        "Experiment1/Single_Mujoco_0.csv",
        &paper,
    );
    assert!(g.last_m < 1e-4, "last row {:.4} mm apart", g.last_m * 1e3);
    assert!(
        g.max_m < 6e-3,
        "row {} is {:.3} mm apart",
        g.max_row,
        g.max_m * 1e3
    );
    assert!(
        g.max_row < 3,
        "largest gap expected in the first 0.1 s, found at row {}",
        g.max_row
    );
}

#[test]
fn scene2_matches_the_study_recording() {
    let Some(paper) = paper_data() else { return };
    let g = compare(
        "scene2_two_joints",
        "Experiment2/Double_Mujoco_0.csv",
        &paper,
    );
    // Measured: max 3.25 mm (row 2), last 0.31 mm.
    assert!(g.last_m < 0.5e-3, "last row {:.4} mm apart", g.last_m * 1e3);
    assert!(
        g.max_m < 4e-3,
        "row {} is {:.3} mm apart",
        g.max_row,
        g.max_m * 1e3
    );
}

#[test]
fn scene3_matches_the_study_recording() {
    let Some(paper) = paper_data() else { return };
    let g = compare(
        "scene3_cube_push",
        "Experiment3/CubeExp_Mujoco_0.csv",
        &paper,
    );
    // Measured: max 8.64 mm (row 2; about 7-8 mm through the first 3 s
    // while joint 3, kv 10, lifts the forearm), last 0.007 mm; the cube,
    // tipped over by the hand as in the study, ends 1.04 mm from the
    // study's.
    assert!(g.last_m < 0.1e-3, "last row {:.4} mm apart", g.last_m * 1e3);
    assert!(
        g.max_m < 10e-3,
        "row {} is {:.3} mm apart",
        g.max_row,
        g.max_m * 1e3
    );
    assert!(
        g.last_cube_m < 2e-3,
        "cube ends {:.3} mm from the study's",
        g.last_cube_m * 1e3
    );
}
