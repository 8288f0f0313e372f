//! The simulation state ([`SimState`]) of a DART simulation: what it holds,
//! how it is restored.
//!
//! DART works in generalized coordinates: the robot's state is its
//! controlled joints' positions and velocities (the held joints are welded
//! into their bodies), each object's is its free joint's six coordinates
//! (rotation vector and translation) and six velocities. Nothing else
//! carries over a step: contacts are found afresh by the collision
//! detector every step, and neither of DART's LCP solvers (Dantzig, PGS)
//! starts warm. The servo laws are recomputed before every step from the
//! commands and the state.
//!
//! - **Native** (`NativeState { engine: "dart", data }`): the layout
//!   version, the joint and object counts, the time origin and step count,
//!   the joints' positions and velocities, and each object's twelve free
//!   joint numbers, all as DART holds them: restoring them gives DART
//!   exactly the state it had.
//! - **Portable**: the joint angles and velocities are DART's coordinates
//!   themselves, so the robot loads exactly; an object's pose and twist go
//!   through its free joint's `setTransform` and velocity setters (the
//!   rotation vector of the quaternion, to rounding).
//!
//! Either way the commands in force (servo targets, position or effort
//! commands) and the time are set too.

use crate::settings::ENGINE_NAME;
use crate::world::pose7;
use crate::DartSimulation;
use realitygap_core::engine::{EngineError, NativeState, ObjectState, SimState, Simulation};

/// The layout version of the native state (its first number).
pub const NATIVE_VERSION: f64 = 1.0;

/// Numbers before the joints: version, joint count, object count, time
/// origin (s), steps.
const HEADER_LEN: usize = 5;

/// Free joint numbers per object: 6 positions, 6 velocities.
const OBJECT_LEN: usize = 12;

fn state_error(message: impl Into<String>) -> EngineError {
    EngineError::State {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

fn whole(x: f64, max: f64) -> Option<u64> {
    (x.fract() == 0.0 && (0.0..=max).contains(&x)).then_some(x as u64)
}

impl DartSimulation {
    /// The native numbers (see the module documentation).
    fn native_data(&self) -> Vec<f64> {
        let n = self.q.len();
        let m = self.world.objects.len();
        let mut data = Vec::with_capacity(HEADER_LEN + 2 * n + OBJECT_LEN * m);
        data.extend_from_slice(&[
            NATIVE_VERSION,
            n as f64,
            m as f64,
            self.time_origin_s,
            self.steps as f64,
        ]);
        data.extend_from_slice(&self.q);
        data.extend_from_slice(&self.v);
        let mut coordinates = [0.0; OBJECT_LEN];
        for i in 0..m {
            self.world.raw().object_coordinates(i, &mut coordinates);
            data.extend_from_slice(&coordinates);
        }
        data
    }

    /// The current state, portable fields and native numbers.
    pub fn read_state(&self) -> SimState {
        let objects = self
            .world
            .objects
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let (pose, lin, ang) = self.world.object_state(i);
                ObjectState {
                    name: name.clone(),
                    pose,
                    linear_velocity_m_s: lin,
                    angular_velocity_rad_s: ang,
                }
            })
            .collect();
        SimState {
            time_s: self.time_s(),
            joint_angles_rad: self.q.clone(),
            joint_velocities_rad_s: self.v.clone(),
            joint_velocity_targets_rad_s: self.velocity_targets(),
            servo_commands: self.servo_commands(),
            objects,
            native: Some(NativeState {
                engine: ENGINE_NAME.to_string(),
                data: self.native_data(),
            }),
        }
    }

    /// Loads `state`: its native numbers when it has DART's, else its
    /// portable fields (see the module documentation).
    pub fn write_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let names: Vec<&str> = self.world.objects.iter().map(|o| o.as_str()).collect();
        state.check(self.q.len(), &names).map_err(state_error)?;
        if state
            .objects
            .iter()
            .any(|o| o.pose.orientation.normalized().is_none())
        {
            return Err(state_error("an object's orientation has zero norm"));
        }
        match &state.native {
            Some(native) if native.engine == ENGINE_NAME => self.load_native(&native.data)?,
            _ => self.load_portable(state)?,
        }
        if state.servo_commands.is_empty() {
            self.set_joint_velocity_targets(&state.joint_velocity_targets_rad_s);
        } else {
            self.set_joint_commands(&state.servo_commands)?;
        }
        let t = self.time_s();
        self.world.raw_mut().set_time(t);
        self.read_joints();
        crate::world::forward_messages();
        Ok(())
    }

    fn load_native(&mut self, data: &[f64]) -> Result<(), EngineError> {
        let n = self.q.len();
        let m = self.world.objects.len();
        if let Some(i) = data.iter().position(|x| !x.is_finite()) {
            return Err(state_error(format!("native value {i} is not finite")));
        }
        let header = data
            .get(..HEADER_LEN)
            .ok_or_else(|| state_error("the native state is truncated"))?;
        if header[0] != NATIVE_VERSION {
            return Err(state_error(format!(
                "native layout {} is not this engine's ({NATIVE_VERSION})",
                header[0]
            )));
        }
        if header[1] != n as f64 || header[2] != m as f64 {
            return Err(state_error(format!(
                "the native state has {} joints and {} objects, this simulation {n} and {m}",
                header[1], header[2]
            )));
        }
        if data.len() != HEADER_LEN + 2 * n + OBJECT_LEN * m {
            return Err(state_error("the native state has the wrong length"));
        }
        let steps = whole(header[4], 2f64.powi(53))
            .ok_or_else(|| state_error("the step count is not a whole number"))?;
        let joints = &data[HEADER_LEN..HEADER_LEN + 2 * n];
        self.world
            .raw_mut()
            .set_joint_state(&joints[..n], &joints[n..])
            .map_err(|e| state_error(e.what().to_string()))?;
        for (i, c) in data[HEADER_LEN + 2 * n..]
            .chunks_exact(OBJECT_LEN)
            .enumerate()
        {
            self.world
                .raw_mut()
                .set_object_coordinates(i, c)
                .map_err(|e| state_error(e.what().to_string()))?;
        }
        self.time_origin_s = header[3];
        self.steps = steps;
        Ok(())
    }

    fn load_portable(&mut self, state: &SimState) -> Result<(), EngineError> {
        self.world
            .raw_mut()
            .set_joint_state(&state.joint_angles_rad, &state.joint_velocities_rad_s)
            .map_err(|e| state_error(e.what().to_string()))?;
        for (i, o) in state.objects.iter().enumerate() {
            let mut s = [0.0; 13];
            s[..7].copy_from_slice(&pose7(&o.pose));
            let (v, w) = (o.linear_velocity_m_s, o.angular_velocity_rad_s);
            s[7..].copy_from_slice(&[v.x, v.y, v.z, w.x, w.y, w.z]);
            self.world
                .raw_mut()
                .set_object_state(i, &s)
                .map_err(|e| state_error(e.what().to_string()))?;
        }
        self.time_origin_s = state.time_s;
        self.steps = 0;
        Ok(())
    }
}
