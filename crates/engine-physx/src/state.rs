//! The simulation state ([`SimState`]) of a PhysX simulation: reading it,
//! and setting it by rebuilding the world and loading the state into it.
//!
//! The state is portable only: joint angles and velocities, servo targets,
//! and each object's pose and twist, all single-precision numbers that
//! round-trip exactly through `f64`. PhysX keeps more that cannot be read
//! or written through its API (the contact manifolds of its persistent
//! contact manifold collision and their friction anchors), so setting a
//! state rebuilds the world from the scene first: a state set mid-run then
//! continues exactly as the same state loaded into a freshly loaded
//! simulation, and a state taken while nothing touches continues exactly as
//! the original run. Held joints sit at their scene positions, at rest (they
//! are rigid in their link's group).

use crate::world::{from_px, to_px, vec_from_px, vec_to_px};
use crate::{usage_error, PhysxSimulation, ENGINE_NAME};
use physx_sys::*;
use realitygap_core::engine::{EngineError, ObjectState, SimState, Simulation};

impl PhysxSimulation {
    /// The current state (see the module documentation).
    pub fn read_state(&self) -> SimState {
        let n = self.world.drives.len();
        let objects = self
            .inputs
            .scene
            .objects
            .iter()
            .zip(&self.world.objects)
            .map(|(o, &actor)| {
                // SAFETY: the actor belongs to this simulation's scene.
                unsafe {
                    ObjectState {
                        name: o.name.clone(),
                        pose: from_px(&PxRigidActor_getGlobalPose(actor as *const PxRigidActor)),
                        linear_velocity_m_s: vec_from_px(PxRigidDynamic_getLinearVelocity(actor)),
                        angular_velocity_rad_s: vec_from_px(PxRigidDynamic_getAngularVelocity(
                            actor,
                        )),
                    }
                }
            })
            .collect();
        SimState {
            time_s: self.time_s(),
            joint_angles_rad: (0..n).map(|i| self.joint_position(i)).collect(),
            joint_velocities_rad_s: (0..n).map(|i| self.joint_velocity(i)).collect(),
            joint_velocity_targets_rad_s: self.targets.clone(),
            servo_commands: self.servo_commands(),
            objects,
            native: None,
        }
    }

    /// Sets `state` (see the module documentation); a state of another
    /// engine loads the same way (its native part is ignored).
    pub fn write_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let names: Vec<&str> = self
            .inputs
            .scene
            .objects
            .iter()
            .map(|o| o.name.as_str())
            .collect();
        state
            .check(self.world.drives.len(), &names)
            .map_err(|message| EngineError::State {
                engine: ENGINE_NAME.to_string(),
                message,
            })?;
        if state
            .objects
            .iter()
            .any(|o| o.pose.orientation.normalized().is_none())
        {
            return Err(usage_error("an object's orientation has zero norm"));
        }
        self.world = Self::build(&self.inputs, &self.settings)?;
        // What PhysX said while releasing the old world is not news.
        crate::sdk::take_messages();
        for (i, d) in self.world.drives.iter().enumerate() {
            // SAFETY: the joint belongs to the new articulation, in its
            // scene, not simulating.
            unsafe {
                PxArticulationJointReducedCoordinate_setJointPosition_mut(
                    d.joint,
                    d.axis,
                    state.joint_angles_rad[i] as f32,
                );
                PxArticulationJointReducedCoordinate_setJointVelocity_mut(
                    d.joint,
                    d.axis,
                    state.joint_velocities_rad_s[i] as f32,
                );
            }
        }
        for (o, &actor) in state.objects.iter().zip(&self.world.objects) {
            // SAFETY: the actor belongs to the new scene.
            unsafe {
                PxRigidActor_setGlobalPose_mut(actor as *mut PxRigidActor, &to_px(&o.pose), true);
                PxRigidDynamic_setLinearVelocity_mut(
                    actor,
                    &vec_to_px(o.linear_velocity_m_s),
                    true,
                );
                PxRigidDynamic_setAngularVelocity_mut(
                    actor,
                    &vec_to_px(o.angular_velocity_rad_s),
                    true,
                );
            }
        }
        self.targets = vec![0.0; self.world.drives.len()];
        self.commands.clear();
        self.dof_start.clear();
        self.set_joint_velocity_targets(&state.joint_velocity_targets_rad_s);
        if !state.servo_commands.is_empty() {
            self.set_joint_commands(&state.servo_commands)?;
        }
        self.time_origin_s = state.time_s;
        self.steps = 0;
        self.update_kinematics();
        Ok(())
    }
}
