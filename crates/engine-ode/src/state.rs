//! The state of an ODE simulation ([`SimState`]): what it holds, how it is
//! restored.
//!
//! ODE works in maximal coordinates: every body has its own position,
//! orientation and velocities, and the joints are constraints between
//! them. So:
//!
//! - **Native** (`NativeState { engine: "ode", data }`): every moving
//!   body's position, quaternion, linear and angular velocity exactly as
//!   ODE holds them, the hinges' motor targets, the unwrapped joint angles,
//!   the time, the state of ODE's random generator (which `quick_step`
//!   draws from) and the order in which ODE last moved the bodies (which
//!   fixes the order of collision pairs, contacts and solver rows; see
//!   [`crate::world::OdeWorld::move_order`]). Nothing else carries over a
//!   step in this build: contact joints are made afresh each step,
//!   `world_step` (Dantzig) has no warm start, and `quick_step`'s warm
//!   start is compiled out of ODE 0.16 (`WARM_STARTING` is not defined in
//!   its `quickstep.cpp`). The one loss: `dBodySetQuaternion` normalises
//!   the quaternion again, which may change its last bit.
//! - **Portable**: the controlled joints' angles and rates become every
//!   robot body's pose (forward kinematics of the URDF, as
//!   [`crate::plan::ModelPlan::body_poses`]) and twist (propagated down the
//!   tree, [`crate::plan::ModelPlan::body_twists`]), held joints at their
//!   scene positions; objects take their pose and twist; the random
//!   generator starts afresh. What the joint angles cannot say is lost:
//!   ODE's joints are soft constraints (CFM), so a loaded arm's bodies sit
//!   slightly off their joints' ideal places, and a fixed-joint base gives
//!   way by micrometres; a portable state puts them back exactly.

use crate::settings::ENGINE_NAME;
use crate::world::{ode_lock, BODY_STATE_LEN};
use crate::OdeSimulation;
use realitygap_core::engine::{EngineError, NativeState, ObjectState, SimState};

/// The layout version of the native state (its first number).
pub const NATIVE_VERSION: f64 = 1.0;

/// Numbers before the bodies: version, body count, hinge count, time
/// origin (s), steps, random-generator state.
const HEADER_LEN: usize = 6;

fn state_error(message: impl Into<String>) -> EngineError {
    EngineError::State {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

/// A native state taken apart (checked against a simulation's sizes).
struct Native<'a> {
    time_origin_s: f64,
    steps: u64,
    rng_seed: u64,
    bodies: &'a [f64],
    /// Per hinge: motor target (rad/s), unwrapped angle (rad), ODE's angle
    /// at the last update (rad).
    hinges: &'a [f64],
    move_order: Vec<usize>,
}

fn whole(x: f64, max: f64) -> Option<u64> {
    (x.fract() == 0.0 && (0.0..=max).contains(&x)).then_some(x as u64)
}

impl<'a> Native<'a> {
    fn parse(data: &'a [f64], bodies: usize, hinges: usize) -> Result<Native<'a>, String> {
        if let Some(i) = data.iter().position(|x| !x.is_finite()) {
            return Err(format!("native value {i} is not finite"));
        }
        let header = data
            .get(..HEADER_LEN)
            .ok_or("the native state is truncated")?;
        if header[0] != NATIVE_VERSION {
            return Err(format!(
                "native layout {} is not this engine's ({NATIVE_VERSION})",
                header[0]
            ));
        }
        if header[1] != bodies as f64 || header[2] != hinges as f64 {
            return Err(format!(
                "the native state has {} moving bodies and {} hinges, this simulation {bodies} and {hinges} \
                 (another model or other settings)",
                header[1], header[2]
            ));
        }
        let steps =
            whole(header[4], 2f64.powi(53)).ok_or("the step count is not a whole number")?;
        let rng_seed =
            whole(header[5], u32::MAX as f64).ok_or("the generator state is not valid")?;
        let body_end = HEADER_LEN + BODY_STATE_LEN * bodies;
        let hinge_end = body_end + 3 * hinges;
        let count = data
            .get(hinge_end)
            .copied()
            .ok_or("the native state is truncated")?;
        let order = data.get(hinge_end + 1..).unwrap_or_default();
        if whole(count, bodies as f64) != Some(order.len() as u64) {
            return Err("the native state's body order does not fit".to_string());
        }
        let move_order = order
            .iter()
            .map(|&m| whole(m, bodies.saturating_sub(1) as f64).map(|m| m as usize))
            .collect::<Option<Vec<_>>>()
            .ok_or("the native state's body order names unknown bodies")?;
        Ok(Native {
            time_origin_s: header[3],
            steps,
            rng_seed,
            bodies: &data[HEADER_LEN..body_end],
            hinges: &data[body_end..hinge_end],
            move_order,
        })
    }
}

impl OdeSimulation {
    /// The native numbers (see the module documentation).
    fn native_data(&self) -> Vec<f64> {
        let bodies = self.world.moving_count();
        let hinges = self.angles_rad.len();
        let order = self.world.move_order();
        let mut data =
            Vec::with_capacity(HEADER_LEN + BODY_STATE_LEN * bodies + 3 * hinges + 1 + order.len());
        data.extend_from_slice(&[
            NATIVE_VERSION,
            bodies as f64,
            hinges as f64,
            self.time_origin_s,
            self.steps as f64,
            self.world.rng_seed() as f64,
        ]);
        self.world.write_moving_states(&mut data);
        for i in 0..hinges {
            data.extend_from_slice(&[
                self.world.hinge_velocity_target(i),
                self.angles_rad[i],
                self.last_raw_rad[i],
            ]);
        }
        data.push(order.len() as f64);
        data.extend(order.iter().map(|&m| m as f64));
        data
    }

    /// The current state, portable fields and native numbers.
    pub(crate) fn sim_state(&self) -> SimState {
        let n = self.angles_rad.len();
        let objects = self
            .plan
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let (v, w) = self.world.object_velocity(i);
                ObjectState {
                    name: o.name.clone(),
                    pose: self.world.object_pose(i),
                    linear_velocity_m_s: v,
                    angular_velocity_rad_s: w,
                }
            })
            .collect();
        SimState {
            time_s: realitygap_core::engine::Simulation::time_s(self),
            joint_angles_rad: self.angles_rad.clone(),
            joint_velocities_rad_s: (0..n).map(|i| self.world.hinge_rate(i)).collect(),
            joint_velocity_targets_rad_s: (0..n)
                .map(|i| self.world.hinge_velocity_target(i))
                .collect(),
            servo_commands: self.servo_commands(),
            objects,
            native: Some(NativeState {
                engine: ENGINE_NAME.to_string(),
                data: self.native_data(),
            }),
        }
    }

    /// Loads `state`: its native numbers when it has ODE's, else its
    /// portable fields (see the module documentation).
    pub(crate) fn load_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let names: Vec<&str> = self.plan.objects.iter().map(|o| o.name.as_str()).collect();
        state
            .check(self.angles_rad.len(), &names)
            .map_err(state_error)?;
        let _guard = ode_lock();
        match &state.native {
            Some(native) if native.engine == ENGINE_NAME => self.load_native(&native.data)?,
            _ => self.load_portable(state),
        }
        if !state.servo_commands.is_empty() {
            realitygap_core::engine::Simulation::set_joint_commands(self, &state.servo_commands)?;
        } else if !self.commands.is_empty() {
            realitygap_core::engine::Simulation::set_joint_velocity_targets(
                self,
                &state.joint_velocity_targets_rad_s,
            );
        }
        Ok(())
    }

    fn load_native(&mut self, data: &[f64]) -> Result<(), EngineError> {
        let native = Native::parse(data, self.world.moving_count(), self.angles_rad.len())
            .map_err(state_error)?;
        self.world.read_moving_states(native.bodies);
        for (i, h) in native.hinges.chunks_exact(3).enumerate() {
            self.world.set_hinge_velocity(i, h[0]);
            self.angles_rad[i] = h[1];
            self.last_raw_rad[i] = h[2];
        }
        self.world.set_rng_seed(native.rng_seed);
        self.world.restore_move_order(&native.move_order);
        self.time_origin_s = native.time_origin_s;
        self.steps = native.steps;
        Ok(())
    }

    fn load_portable(&mut self, state: &SimState) {
        let angles = &state.joint_angles_rad;
        let poses = self.plan.body_poses(&self.robot, &self.base, angles);
        let twists = self.plan.body_twists(
            &self.robot,
            &self.base,
            angles,
            &state.joint_velocities_rad_s,
        );
        for (b, (pose, (v, w))) in poses.iter().zip(twists).enumerate() {
            self.world.set_robot_body_state(b, pose, v, w);
        }
        for (i, o) in state.objects.iter().enumerate() {
            self.world.set_object_state(
                i,
                &o.pose,
                o.linear_velocity_m_s,
                o.angular_velocity_rad_s,
            );
        }
        for (i, (&a, &target)) in angles
            .iter()
            .zip(&state.joint_velocity_targets_rad_s)
            .enumerate()
        {
            self.world.set_hinge_velocity(i, target);
            self.angles_rad[i] = a;
            self.last_raw_rad[i] = self.world.hinge_angle(i);
        }
        self.world.set_rng_seed(0);
        self.time_origin_s = state.time_s;
        self.steps = 0;
    }
}
