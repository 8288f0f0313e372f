//! [`SimState`] for MuJoCo: reading it, restoring it exactly from the
//! engine's own [`NativeState`], and loading its portable fields.
//!
//! The reported body poses belong to the current `qpos` (see the crate
//! documentation), and a loaded state reports them the same way: native
//! restores the poses saved with it, portable computes them with
//! `mj_forward`.

use crate::{MujocoSimulation, ENGINE_NAME};
use mujoco_rs::mujoco_c;
use realitygap_core::engine::{EngineError, NativeState, ObjectState, SimState};
use realitygap_core::pose::{Pose, Quat, Vec3};

/// What `mj_getState` saves: everything `mj_step` reads (time, qpos,
/// qvel, act, history, warm start, ctrl, applied forces, equality
/// activations, mocap, user data, plugin state).
const NATIVE_SPEC: u32 = mujoco_c::mjtState::mjSTATE_INTEGRATION as u32;

/// Layout version of [`NativeState::data`]:
/// `[VERSION, spec, state size, nbody, state..., xpos (3 nbody), xquat (4 nbody)]`.
const NATIVE_VERSION: f64 = 1.0;
const HEADER: usize = 4;

fn state_error(message: impl Into<String>) -> EngineError {
    EngineError::State {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

impl MujocoSimulation {
    fn object_names(&self) -> Vec<&str> {
        self.objects.iter().map(|o| o.name.as_str()).collect()
    }

    /// The current state; the native part holds MuJoCo's complete state.
    pub(crate) fn read_state(&self) -> Result<SimState, EngineError> {
        let qpos = self.data.qpos();
        let qvel = self.data.qvel();
        let ctrl = self.data.ctrl();
        let mut objects = Vec::with_capacity(self.objects.len());
        for o in &self.objects {
            let (qa, da) = o.free.ok_or_else(|| {
                state_error(format!(
                    "object '{}' is not a free-floating body of the model",
                    o.name
                ))
            })?;
            let q = Quat::new(qpos[qa + 3], qpos[qa + 4], qpos[qa + 5], qpos[qa + 6]);
            let unit = q.normalized().unwrap_or(Quat::IDENTITY);
            objects.push(ObjectState {
                name: o.name.clone(),
                pose: Pose::new(Vec3::new(qpos[qa], qpos[qa + 1], qpos[qa + 2]), q),
                linear_velocity_m_s: Vec3::new(qvel[da], qvel[da + 1], qvel[da + 2]),
                // MuJoCo's free joint: angular velocity in the body frame.
                angular_velocity_rad_s: unit.rotate(Vec3::new(
                    qvel[da + 3],
                    qvel[da + 4],
                    qvel[da + 5],
                )),
            });
        }
        Ok(SimState {
            time_s: self.data.ffi().time,
            joint_angles_rad: self.qpos_adr.iter().map(|&a| qpos[a]).collect(),
            joint_velocities_rad_s: self.dof_adr.iter().map(|&a| qvel[a]).collect(),
            joint_velocity_targets_rad_s: self.ctrl_index.iter().map(|&u| ctrl[u]).collect(),
            servo_commands: self.servo_commands(),
            objects,
            native: Some(NativeState {
                engine: ENGINE_NAME.to_string(),
                data: self.native_data(),
            }),
        })
    }

    fn native_data(&self) -> Vec<f64> {
        let state = self.data.state(NATIVE_SPEC);
        let nbody = self.data.model().ffi().nbody as usize;
        let mut out = Vec::with_capacity(HEADER + state.len() + 7 * nbody);
        out.extend([
            NATIVE_VERSION,
            NATIVE_SPEC as f64,
            state.len() as f64,
            nbody as f64,
        ]);
        out.extend_from_slice(&state);
        for p in self.data.xpos() {
            out.extend_from_slice(p);
        }
        for q in self.data.xquat() {
            out.extend_from_slice(q);
        }
        out
    }

    /// Sets `state`: exactly from a MuJoCo native state, else from the
    /// portable fields (see [`realitygap_core::engine::Simulation::set_state`]).
    pub(crate) fn write_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        state
            .check(self.qpos_adr.len(), &self.object_names())
            .map_err(state_error)?;
        match &state.native {
            Some(n) if n.engine == ENGINE_NAME => self.restore_native(state, &n.data)?,
            _ => self.load_portable(state)?,
        }
        // The actuators' laws are the model's, not the data's: set them
        // (and the controls, to the same values) from the commands.
        if state.servo_commands.is_empty() {
            realitygap_core::engine::Simulation::set_joint_velocity_targets(
                self,
                &state.joint_velocity_targets_rad_s,
            );
        } else {
            realitygap_core::engine::Simulation::set_joint_commands(self, &state.servo_commands)?;
        }
        Ok(())
    }

    fn restore_native(&mut self, state: &SimState, native: &[f64]) -> Result<(), EngineError> {
        let size = self.data.model().state_size(NATIVE_SPEC);
        let nbody = self.data.model().ffi().nbody as usize;
        let expected = [
            NATIVE_VERSION,
            NATIVE_SPEC as f64,
            size as f64,
            nbody as f64,
        ];
        if native.len() != HEADER + size + 7 * nbody || native[..HEADER] != expected {
            return Err(state_error(format!(
                "the native MuJoCo state does not fit this model (header {:?}, {} numbers; this model: {expected:?}, {} numbers); load its portable part instead",
                &native[..HEADER.min(native.len())],
                native.len(),
                HEADER + size + 7 * nbody
            )));
        }
        let body = &native[HEADER..HEADER + size];
        // mj_getState writes the time first, then qpos.
        let nq = self.data.model().ffi().nq as usize;
        let qpos = &body[1..1 + nq];
        let edited = body[0] != state.time_s
            || self
                .qpos_adr
                .iter()
                .zip(&state.joint_angles_rad)
                .any(|(&a, &v)| qpos[a] != v);
        if edited {
            return Err(state_error(
                "the time or joint angles differ from those in the native MuJoCo state; to load edited values, drop the native part (SimState::portable)",
            ));
        }
        self.data
            .set_state(body, NATIVE_SPEC)
            .map_err(|e| state_error(format!("mj_setState: {e}")))?;
        self.data.forward();
        let poses = &native[HEADER + size..];
        let (xpos, xquat) = poses.split_at(3 * nbody);
        // SAFETY: xpos and xquat are nbody x 3 and nbody x 4 arrays of this
        // data, and the slices above hold exactly that many numbers.
        unsafe {
            let d = self.data.ffi_mut();
            std::ptr::copy_nonoverlapping(xpos.as_ptr(), d.xpos, 3 * nbody);
            std::ptr::copy_nonoverlapping(xquat.as_ptr(), d.xquat, 4 * nbody);
        }
        Ok(())
    }

    fn load_portable(&mut self, state: &SimState) -> Result<(), EngineError> {
        self.data.reset();
        self.place_held_joints();
        {
            let qpos = self.data.qpos_mut();
            for (&a, &v) in self.qpos_adr.iter().zip(&state.joint_angles_rad) {
                qpos[a] = v;
            }
        }
        {
            let qvel = self.data.qvel_mut();
            for (&a, &v) in self.dof_adr.iter().zip(&state.joint_velocities_rad_s) {
                qvel[a] = v;
            }
        }
        self.set_controls(&state.joint_velocity_targets_rad_s);
        for (slot, o) in self.objects.clone().iter().zip(&state.objects) {
            let (qa, da) = slot.free.ok_or_else(|| {
                state_error(format!(
                    "object '{}' is not a free-floating body of the model",
                    o.name
                ))
            })?;
            let q =
                o.pose.orientation.normalized().ok_or_else(|| {
                    state_error(format!("object '{}' has a zero quaternion", o.name))
                })?;
            let p = o.pose.position_m;
            let v = o.linear_velocity_m_s;
            let w = q.conjugate().rotate(o.angular_velocity_rad_s);
            self.data.qpos_mut()[qa..qa + 7].copy_from_slice(&[p.x, p.y, p.z, q.w, q.x, q.y, q.z]);
            self.data.qvel_mut()[da..da + 6].copy_from_slice(&[v.x, v.y, v.z, w.x, w.y, w.z]);
        }
        // SAFETY: writes a plain field of this simulation's own data.
        unsafe { self.data.ffi_mut().time = state.time_s };
        self.data.forward();
        self.warnings_seen = self.warning_counts();
        Ok(())
    }
}
