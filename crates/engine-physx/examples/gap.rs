use realitygap_core::controller::{simulate, RunOptions};
use realitygap_core::engine::{EngineSettings, SettingValue};
use realitygap_core::testing::{mico2, scene, wrist};
use realitygap_engine_mujoco::MujocoEngine;
use realitygap_engine_physx::PhysxEngine;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let s = scene(&args[0]);
    let robot = mico2();
    let settings: EngineSettings = args[1..]
        .iter()
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap();
            (k.to_string(), SettingValue::parse(v))
        })
        .collect();
    let p = simulate(&PhysxEngine, &s, &robot, &settings, &RunOptions::default()).unwrap();
    let m = simulate(&MujocoEngine, &s, &robot, &s.settings_for("mujoco"), &RunOptions::default()).unwrap();
    let (wp, wm) = (wrist(&p), wrist(&m));
    for i in (0..wp.len()).step_by(5) {
        println!("{:5.2} s gap {:7.2} mm  physx z {:.4} mujoco z {:.4}", i as f64 * 0.05, wp[i].distance(wm[i]) * 1e3, wp[i].z, wm[i].z);
    }
}
