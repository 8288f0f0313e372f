//! The simulation state beyond the conformance suite: a portable state
//! arrives with the joint rates and object twists it carries, states that
//! do not fit are `EngineError::State`, a native state of another engine
//! is read as portable.

mod common;

use common::*;
use realitygap_core::engine::{EngineError, ModelVariation, NativeState, SimState, Simulation};
use realitygap_core::pose::Vec3;
use realitygap_engine_ode::OdeSimulation;

fn load(pairs: &[&str]) -> OdeSimulation {
    let s = scene("scene1_single_joint");
    OdeSimulation::load(&s, &mico2(), &settings(pairs), &ModelVariation::default()).unwrap()
}

/// A state of scene 1 mid-motion: every joint turning, the cube sliding
/// and spinning (made up, then loaded).
fn moving_state() -> SimState {
    let mut state = load(&[]).state().unwrap().portable();
    state.time_s = 1.25;
    state.joint_angles_rad = vec![0.3, -0.6, 0.4, -0.2, 0.5, 1.0];
    state.joint_velocities_rad_s = vec![0.2, -0.3, 0.25, -0.4, 0.35, 0.5];
    state.joint_velocity_targets_rad_s = vec![0.1, -0.2, 0.3, -0.1, 0.2, 0.4];
    let cube = &mut state.objects[0];
    cube.pose.position_m.z += 0.05;
    cube.linear_velocity_m_s = Vec3::new(0.1, -0.05, 0.02);
    cube.angular_velocity_rad_s = Vec3::new(0.0, 0.3, -1.0);
    state
}

/// The joint rates come back as ODE measures them from the bodies'
/// twists (the forward propagation of velocities is right), with the
/// angles, targets, object twist and time.
#[test]
fn portable_state_arrives_as_given() {
    let given = moving_state();
    let mut sim = load(&[]);
    sim.set_state(&given).unwrap();
    let read = sim.state().unwrap();
    let largest = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    let rates = largest(&read.joint_velocities_rad_s, &given.joint_velocities_rad_s);
    eprintln!("joint rates read back within {rates:e} rad/s");
    assert!(rates < 1e-12, "{rates}");
    assert!(largest(&read.joint_angles_rad, &given.joint_angles_rad) < 1e-12);
    assert_eq!(
        read.joint_velocity_targets_rad_s,
        given.joint_velocity_targets_rad_s
    );
    assert_eq!(
        read.objects[0].linear_velocity_m_s,
        given.objects[0].linear_velocity_m_s
    );
    assert_eq!(
        read.objects[0].angular_velocity_rad_s,
        given.objects[0].angular_velocity_rad_s
    );
    assert!(
        read.objects[0]
            .pose
            .position_m
            .distance(given.objects[0].pose.position_m)
            < 1e-15
    );
    assert_eq!(sim.time_s(), 1.25);
    sim.step().unwrap();
    assert!((sim.time_s() - 1.26).abs() < 1e-12);
}

/// A native state restores the same numbers, time included.
#[test]
fn native_state_restores_its_numbers() {
    let mut a = load(&[]);
    a.set_state(&moving_state()).unwrap();
    a.step_n(7).unwrap();
    let saved = a.state().unwrap();
    let mut b = load(&[]);
    b.set_state(&saved).unwrap();
    assert_eq!(b.state().unwrap(), saved);
    assert_eq!(b.time_s(), a.time_s());
}

fn state_error(sim: &mut OdeSimulation, state: &SimState) -> String {
    match sim.set_state(state) {
        Err(e @ EngineError::State { .. }) => e.to_string(),
        Err(other) => panic!("expected a state error, got {other}"),
        Ok(()) => panic!("the state loaded"),
    }
}

/// States that do not fit are errors naming the engine and what is wrong.
#[test]
fn unfit_states_are_errors() {
    let mut sim = load(&[]);
    let good = sim.state().unwrap();

    let mut short = good.portable();
    short.joint_angles_rad.pop();
    let e = state_error(&mut sim, &short);
    assert!(
        e.contains("engine ode") && e.contains("joint_angles_rad has 5 values"),
        "{e}"
    );

    let mut nan = good.portable();
    nan.objects[0].linear_velocity_m_s.x = f64::NAN;
    assert!(state_error(&mut sim, &nan).contains("non-finite"));

    // A native state of another model (a static base: one body fewer).
    let other = load(&["base=static"]).state().unwrap();
    let e = state_error(&mut sim, &other);
    assert!(e.contains("another model or other settings"), "{e}");

    let mut truncated = good.clone();
    if let Some(n) = truncated.native.as_mut() {
        n.data.truncate(20);
    }
    assert!(state_error(&mut sim, &truncated).contains("native"));

    let mut bad_order = good.clone();
    if let Some(n) = bad_order.native.as_mut() {
        let last = n.data.len() - 1;
        n.data[last] = 99.0;
    }
    assert!(state_error(&mut sim, &bad_order).contains("body order"));
    // Nothing was changed by the refused states.
    assert_eq!(sim.state().unwrap(), good);
}

/// Another engine's native numbers are not ODE's: the portable fields
/// are loaded.
#[test]
fn a_foreign_native_state_loads_as_portable() {
    let mut given = moving_state();
    given.native = Some(NativeState {
        engine: "mujoco".to_string(),
        data: vec![1.0, 2.0, 3.0],
    });
    let mut a = load(&[]);
    a.set_state(&given).unwrap();
    let mut b = load(&[]);
    b.set_state(&given.portable()).unwrap();
    assert_eq!(a.state().unwrap(), b.state().unwrap());
}
