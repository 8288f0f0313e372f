use realitygap_core::controller::{simulate, RunOptions};
use realitygap_core::engine::{EngineSettings, SettingValue};
use realitygap_core::testing::{final_angles_deg, mico2, scene};
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
    let t = std::time::Instant::now();
    let out = simulate(&PhysxEngine, &s, &robot, &settings, &RunOptions::default()).unwrap();
    println!("{:?} {:.2?} in {:?}", out.status, final_angles_deg(&out), t.elapsed());
}
