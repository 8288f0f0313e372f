//! Toss replay overhead: `simulate_toss` (the toss's scene loaded, its
//! initial twist set, every 1 ms step sampled by the controller loop with
//! its divergence and penetration checks, then resampled at the recorded
//! times) against the raw engine loop on the same start (the scene loaded
//! and started the same way, then the same number of `step` calls and
//! nothing else), per compiled engine, on the first `TOSSES` (default 40)
//! of the 456 tosses built in, at each engine's defaults. Thread CPU time,
//! best of `REPEATS` (default 3); also the loads' share of the replay.
//!
//!     cargo bench -p realitygap --bench tosses

use realitygap_core::controller::{
    load_prepared, prepare, ControlParams, ControllerLoop, RunOptions,
};
use realitygap_core::engine::{EngineSettings, SettingValue, PHYSICS_FREE_ENGINE, TIMESTEP_KEY};
use realitygap_core::robot::RobotModel;
use realitygap_core::testing::bench::thread_cpu_s;
use realitygap_core::PhysicalParams;
use realitygap_study::data_source::assets_dir;
use realitygap_study::toss_study::TossStudy;
use realitygap_study::tosses::{simulate_toss, toss_scene, TOSS_TIMESTEP_S};
use realitygap_study::DataSource;

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let repeats = env("REPEATS", 3);
    let count = env("TOSSES", 40);
    let study = TossStudy::from_file(&assets_dir().join("studies/contactnets2020.toml")).unwrap();
    let set = study.load(&DataSource::Builtin).unwrap();
    let tosses = &set.tosses[..count.min(set.tosses.len())];
    let params = PhysicalParams::default();
    let mut settings = EngineSettings::new();
    settings.insert(TIMESTEP_KEY.into(), SettingValue::Float(TOSS_TIMESTEP_S));
    println!(
        "{:<8} {:>7} {:>8} {:>15} {:>12} {:>9} {:>13}",
        "engine", "tosses", "steps", "replay steps/s", "raw steps/s", "overhead", "load / replay"
    );
    for engine in realitygap::compiled_engines() {
        if engine.name() == PHYSICS_FREE_ENGINE {
            continue;
        }
        let engine = engine.as_ref();
        let (mut best_replay, mut best_raw, mut best_load) = (f64::INFINITY, f64::INFINITY, 0.0);
        let mut steps: Vec<u64> = Vec::new();
        for _ in 0..repeats {
            let t0 = thread_cpu_s();
            steps = tosses
                .iter()
                .map(|t| simulate_toss(engine, &set.object, t, &params).unwrap().3)
                .collect();
            best_replay = f64::min(best_replay, thread_cpu_s() - t0);
            let (mut raw, mut load) = (0.0, 0.0);
            for (t, &n) in tosses.iter().zip(&steps) {
                let scene = toss_scene(&set.object, t).unwrap();
                let (scene, robot) =
                    prepare(engine, &scene, &RobotModel::world(), &params).unwrap();
                let t0 = thread_cpu_s();
                let mut sim = load_prepared(
                    engine,
                    &scene,
                    &robot,
                    &settings,
                    &params,
                    &RunOptions::default(),
                )
                .unwrap();
                load += thread_cpu_s() - t0;
                let mut run =
                    ControllerLoop::new(&scene, &RunOptions::default(), &ControlParams::default());
                run.start(sim.as_mut()).unwrap();
                let t0 = thread_cpu_s();
                sim.step_n(n).unwrap();
                raw += thread_cpu_s() - t0;
            }
            if raw < best_raw {
                best_raw = raw;
                best_load = load;
            }
        }
        let total: u64 = steps.iter().sum();
        let (r, w) = (total as f64 / best_replay, total as f64 / best_raw);
        println!(
            "{:<8} {:>7} {total:>8} {r:>15.0} {w:>12.0} {:>8.1}% {:>13.2}",
            engine.name(),
            tosses.len(),
            100.0 * (w / r - 1.0),
            best_load / best_replay
        );
    }
}
