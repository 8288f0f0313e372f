//! The simulation state in Bullet ([`Simulation::state`] /
//! [`Simulation::set_state`]).
//!
//! - **Native** (same engine): Bullet's own serialization of the whole
//!   world (`saveBullet` / `restoreState` from a file, the mechanism of
//!   PyBullet's `saveState`/`restoreState`): every multibody's base pose and
//!   twist, joint positions and velocities (held finger joints included),
//!   and the contact manifolds with their accumulated impulses, which
//!   Bullet's solver warm-starts from. Bullet writes it to a file; the
//!   engine keeps the file's bytes in [`NativeState::data`] (four bytes per
//!   number) after a header with the wrapper's own state (time, motor
//!   targets) and a fingerprint of the world, checked before Bullet sees the
//!   bytes (Bullet's importer prints to standard output on a mismatch).
//! - **Portable**: `resetJointState` (angle and velocity) of the controlled
//!   joints, held joints at their scene positions at rest,
//!   `resetBasePositionAndOrientation` + `resetBaseVelocity` of the objects
//!   (world frame, the box's centre), the motor targets, the time. Bullet's
//!   C API offers no way to drop contact manifolds: a simulation that had
//!   contacts keeps the points that still touch after the reset (with their
//!   impulses) and drops the others at its next collision pass; a fresh
//!   simulation has none.
//!
//! Every `unsafe` block of this module has its own SAFETY comment; the
//! argument they share: the commands are created
//! on this simulation's client and submitted once, with the Bullet lock
//! held by the caller; the pointers passed point to live arrays of the
//! sizes the C API reads, or to NUL-terminated paths.

use crate::{check_status, ffi, BulletSimulation, ENGINE_NAME};
use realitygap_core::engine::{EngineError, NativeState, ObjectState, SimState, Simulation};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

/// Layout version of the native data.
const LAYOUT: f64 = 1.0;

static FILES: AtomicU64 = AtomicU64::new(0);

/// A temporary file path for a `.bullet` state, removed on drop.
struct TempFile(PathBuf);

impl TempFile {
    fn new() -> TempFile {
        let n = FILES.fetch_add(1, Ordering::Relaxed);
        TempFile(std::env::temp_dir().join(format!(
            "realitygap-bullet-state-{}-{n}.bullet",
            std::process::id()
        )))
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn state_error(message: impl Into<String>) -> EngineError {
    EngineError::State {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

/// Bytes as numbers, four little-endian bytes per number (exact in f64).
fn pack(bytes: &[u8]) -> Vec<f64> {
    bytes
        .chunks(4)
        .map(|c| {
            let mut b = [0u8; 4];
            b[..c.len()].copy_from_slice(c);
            u32::from_le_bytes(b) as f64
        })
        .collect()
}

/// The inverse of [`pack`] for `len` bytes; `None` when a number is not a
/// packed word or the count does not fit.
fn unpack(words: &[f64], len: usize) -> Option<Vec<u8>> {
    if words.len() != len.div_ceil(4) {
        return None;
    }
    let mut out = Vec::with_capacity(words.len() * 4);
    for &w in words {
        if !(0.0..=u32::MAX as f64).contains(&w) || w.fract() != 0.0 {
            return None;
        }
        out.extend_from_slice(&(w as u32).to_le_bytes());
    }
    out.truncate(len);
    Some(out)
}

impl BulletSimulation {
    /// The fingerprint of this world in native data: robot body id, its
    /// joint count, object count, first object body id.
    fn fingerprint(&self) -> [f64; 4] {
        [
            self.robot as f64,
            self.link_names.len() as f64,
            self.objects.len() as f64,
            self.objects.first().map_or(-1.0, |&b| b as f64),
        ]
    }

    /// The state now (see the module documentation). Needs the Bullet lock (`lock`).
    pub(crate) fn take_state(&self, lock: &ffi::BulletLock) -> Result<SimState, EngineError> {
        let objects = self
            .object_names
            .iter()
            .zip(&self.object_states)
            .map(|(name, &(pose, v, w))| ObjectState {
                name: name.clone(),
                pose,
                linear_velocity_m_s: v,
                angular_velocity_rad_s: w,
            })
            .collect();
        Ok(SimState {
            time_s: self.time_s(),
            joint_angles_rad: self.angles_rad.clone(),
            joint_velocities_rad_s: self.velocities_rad_s.clone(),
            joint_velocity_targets_rad_s: self.targets_rad_s.clone(),
            servo_commands: self.commands.clone(),
            objects,
            native: Some(self.native(lock)?),
        })
    }

    /// Bullet's serialized world with the wrapper's header. Needs the Bullet lock (`lock`).
    fn native(&self, lock: &ffi::BulletLock) -> Result<NativeState, EngineError> {
        let file = TempFile::new();
        let path = crate::urdf_file::c_path(&file.0).map_err(state_error)?;
        // SAFETY: the command is created on this simulation's client and
        // submitted once, with the Bullet lock held (`lock`); the pointers
        // passed point to live locals of the sizes Bullet expects.
        let kind = unsafe {
            self.client
                .submit(
                    lock,
                    ffi::b3SaveBulletCommandInit(self.client.handle(lock), path.as_ptr()),
                )
                .kind
        };
        check_status(kind, ffi::CMD_BULLET_SAVING_COMPLETED, "saving the world")
            .map_err(state_error)?;
        let bytes = std::fs::read(&file.0).map_err(|e| {
            state_error(format!(
                "cannot read Bullet's saved world {}: {e}",
                file.0.display()
            ))
        })?;
        let mut data = vec![LAYOUT];
        data.extend(self.fingerprint());
        data.push(self.steps as f64);
        data.push(self.time_origin_s);
        data.push(self.targets_rad_s.len() as f64);
        data.extend(&self.targets_rad_s);
        data.push(bytes.len() as f64);
        data.extend(pack(&bytes));
        Ok(NativeState {
            engine: ENGINE_NAME.to_string(),
            data,
        })
    }

    /// Loads `state` (see the module documentation). Needs the Bullet lock (`lock`).
    pub(crate) fn put_state(
        &mut self,
        lock: &ffi::BulletLock,
        state: &SimState,
    ) -> Result<(), EngineError> {
        let names: Vec<&str> = self.object_names.iter().map(String::as_str).collect();
        state
            .check(self.joints.len(), &names)
            .map_err(state_error)?;
        match &state.native {
            Some(n) if n.engine == ENGINE_NAME => self.put_native(lock, &n.data)?,
            _ => self.put_portable(lock, state)?,
        }
        self.commands.clone_from(&state.servo_commands);
        // The pdControl plugin's laws are not part of the saved world.
        self.pd_active = true;
        self.kinds_sent.clear();
        self.send_targets(lock)?;
        self.refresh(lock)?;
        self.check_stability()
    }

    /// Restores Bullet's serialized world and the wrapper's header.
    fn put_native(&mut self, lock: &ffi::BulletLock, data: &[f64]) -> Result<(), EngineError> {
        let bad = |what: &str| state_error(format!("the native Bullet state is {what}"));
        let n = self.joints.len();
        let header = 1 + 4 + 3;
        if data.len() < header + n + 1 || data[0] != LAYOUT {
            return Err(bad("of another layout or truncated"));
        }
        if data[1..5] != self.fingerprint() {
            return Err(bad("of another world (robot, joints or objects differ)"));
        }
        if data[7] != n as f64 {
            return Err(bad("for another number of joints"));
        }
        let (steps, origin) = (data[5], data[6]);
        if !(steps >= 0.0 && steps.fract() == 0.0 && origin.is_finite()) {
            return Err(bad("damaged (time)"));
        }
        let targets = &data[header..header + n];
        let len = data[header + n];
        let bytes = if len >= 0.0 && len.fract() == 0.0 {
            unpack(&data[header + n + 1..], len as usize)
        } else {
            None
        }
        .ok_or_else(|| bad("damaged (world bytes)"))?;
        let file = TempFile::new();
        std::fs::write(&file.0, &bytes)
            .map_err(|e| state_error(format!("cannot write {}: {e}", file.0.display())))?;
        let path = crate::urdf_file::c_path(&file.0).map_err(state_error)?;
        // SAFETY: the command is created on this simulation's client and
        // submitted once, with the Bullet lock held (`lock`); the pointers
        // passed point to live locals of the sizes Bullet expects.
        let kind = unsafe {
            let cmd = ffi::b3LoadStateCommandInit(self.client.handle(lock));
            ffi::b3LoadStateSetFileName(cmd, path.as_ptr());
            self.client.submit(lock, cmd).kind
        };
        check_status(
            kind,
            ffi::CMD_RESTORE_STATE_COMPLETED,
            "restoring the world",
        )
        .map_err(state_error)?;
        self.steps = steps as u64;
        self.time_origin_s = origin;
        self.targets_rad_s.copy_from_slice(targets);
        Ok(())
    }

    /// Loads the portable fields.
    fn put_portable(
        &mut self,
        lock: &ffi::BulletLock,
        state: &SimState,
    ) -> Result<(), EngineError> {
        let h = self.client.handle(lock);
        // SAFETY: the command is created on this simulation's client and
        // submitted once, with the Bullet lock held (`lock`); the pointers
        // passed point to live locals of the sizes Bullet expects.
        let kind = unsafe {
            let cmd = ffi::b3CreatePoseCommandInit(h, self.robot);
            for (i, joint) in self.joints.iter().enumerate() {
                let (q, v) = (state.joint_angles_rad[i], state.joint_velocities_rad_s[i]);
                ffi::b3CreatePoseCommandSetJointPosition(h, cmd, joint.index, q);
                ffi::b3CreatePoseCommandSetJointVelocity(h, cmd, joint.index, v);
            }
            for j in &self.held {
                ffi::b3CreatePoseCommandSetJointPosition(h, cmd, j.index, j.position);
                ffi::b3CreatePoseCommandSetJointVelocity(h, cmd, j.index, 0.0);
            }
            self.client.submit(lock, cmd).kind
        };
        check_status(
            kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "setting the joints",
        )
        .map_err(state_error)?;
        for (o, &body) in state.objects.iter().zip(&self.objects) {
            let (p, q) = (o.pose.position_m, o.pose.orientation);
            let v = o.linear_velocity_m_s.to_array();
            let w = o.angular_velocity_rad_s.to_array();
            // SAFETY: the command is created on this simulation's client and
            // submitted once, with the Bullet lock held (`lock`); the pointers
            // passed point to live locals of the sizes Bullet expects.
            let kind = unsafe {
                let cmd = ffi::b3CreatePoseCommandInit(h, body);
                ffi::b3CreatePoseCommandSetBasePosition(cmd, p.x, p.y, p.z);
                ffi::b3CreatePoseCommandSetBaseOrientation(cmd, q.x, q.y, q.z, q.w);
                ffi::b3CreatePoseCommandSetBaseLinearVelocity(cmd, v.as_ptr());
                ffi::b3CreatePoseCommandSetBaseAngularVelocity(cmd, w.as_ptr());
                self.client.submit(lock, cmd).kind
            };
            check_status(kind, ffi::CMD_CLIENT_COMMAND_COMPLETED, "setting an object")
                .map_err(state_error)?;
        }
        self.steps = 0;
        self.time_origin_s = state.time_s;
        self.targets_rad_s
            .copy_from_slice(&state.joint_velocity_targets_rad_s);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packs_bytes_exactly() {
        for len in [0usize, 1, 3, 4, 5, 1001] {
            let bytes: Vec<u8> = (0..len).map(|i| (i * 37 % 256) as u8).collect();
            assert_eq!(unpack(&pack(&bytes), len).unwrap(), bytes);
        }
        assert!(unpack(&[0.5], 4).is_none());
        assert!(unpack(&[-1.0], 4).is_none());
        assert!(unpack(&[1.0, 2.0], 4).is_none());
    }
}
