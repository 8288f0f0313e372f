//! The simulation state ([`SimState`]) of a Rapier world: reading it and
//! setting it, portably or natively.
//!
//! Setting a state always starts from the world as it was loaded (a clone
//! of every Rapier set taken at load, `Pristine`), so a state set into a
//! running simulation continues exactly as in a freshly loaded one, and
//! contact caches, warm starts, islands and broad-phase pairs are reset.
//!
//! The portable part sets the controlled joints' coordinates and
//! generalized velocities (held joints are rigid in their group body, at
//! their scene positions), the objects' poses and twists (world frame,
//! linear velocity of the centre, which is the centre of mass of a uniform
//! box), the servo targets and the time.
//!
//! The native part ([`NativeState`] of engine `rapier`, version
//! [`NATIVE_VERSION`]) adds what makes the continuation bit-identical as
//! far as numbers can carry it: the exact single-precision joint
//! coordinates, the whole generalized velocity vector, and every dynamic
//! body's pose, velocity and sleep state (the link bodies' velocities too).
//! What does not carry over: the narrow phase's contact manifolds and
//! their warm-start impulses, the islands and the sleep check's previous
//! pose; the README gives the difference this makes.

use crate::assemble::from_rapier_pose;
use crate::{RapierSimulation, ENGINE_NAME};
use rapier3d::math::{Pose as RPose, Rotation, Vector};
use rapier3d::prelude::{
    BroadPhaseBvh, CCDSolver, ColliderSet, CollisionPipeline, ImpulseJointSet, IslandManager,
    MultibodyJointSet, NarrowPhase, PhysicsPipeline, PhysicsWorld, RigidBodySet, SoftBodySet,
};
use realitygap_core::engine::{EngineError, NativeState, ObjectState, SimState};
use realitygap_core::pose::{Pose, Vec3};

/// Layout version of the native state's numbers (its first number).
pub const NATIVE_VERSION: f64 = 1.0;

/// Numbers per dynamic body in the native state: position (3), rotation
/// quaternion x y z w (4), linear velocity (3), angular velocity (3),
/// sleeping (1 or 0), time it has been still (s).
const PER_BODY: usize = 15;

/// Every Rapier set of a world as loaded, before its first step.
pub(crate) struct Pristine {
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    ccd_solver: CCDSolver,
}

impl Pristine {
    /// A copy of `world`'s sets.
    pub(crate) fn of(world: &PhysicsWorld) -> Pristine {
        Pristine {
            islands: world.islands.clone(),
            broad_phase: world.broad_phase.clone(),
            narrow_phase: world.narrow_phase.clone(),
            bodies: world.bodies.clone(),
            colliders: world.colliders.clone(),
            impulse_joints: world.impulse_joints.clone(),
            multibody_joints: world.multibody_joints.clone(),
            soft_bodies: world.soft_bodies.clone(),
            ccd_solver: world.ccd_solver.clone(),
        }
    }

    /// Puts `world` back as it was loaded (fresh pipelines too: they hold
    /// only workspaces and memos).
    fn restore(&self, world: &mut PhysicsWorld) {
        world.islands = self.islands.clone();
        world.broad_phase = self.broad_phase.clone();
        world.narrow_phase = self.narrow_phase.clone();
        world.bodies = self.bodies.clone();
        world.colliders = self.colliders.clone();
        world.impulse_joints = self.impulse_joints.clone();
        world.multibody_joints = self.multibody_joints.clone();
        world.soft_bodies = self.soft_bodies.clone();
        world.ccd_solver = self.ccd_solver.clone();
        world.physics_pipeline = PhysicsPipeline::new();
        world.collision_pipeline = CollisionPipeline::new();
    }
}

fn state_error(message: impl Into<String>) -> EngineError {
    EngineError::State {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

fn vec3(v: Vector) -> Vec3 {
    Vec3::new(v.x as f64, v.y as f64, v.z as f64)
}

fn vector(v: Vec3) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// A Rapier pose from a state's pose, keeping single-precision values
/// exactly (a quaternion is renormalized only when it is more than f32
/// rounding away from unit length).
fn rapier_pose(p: &Pose) -> RPose {
    let q = p.orientation;
    let n = (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
    let r = Rotation::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32);
    let r = if (n - 1.0).abs() > 1e-6 {
        r.normalize()
    } else {
        r
    };
    RPose::from_parts(vector(p.position_m), r)
}

/// The native numbers decoded: (joint coordinates, generalized velocity,
/// per-body blocks).
struct Native<'a> {
    coords: &'a [f64],
    velocities: &'a [f64],
    bodies: &'a [f64],
}

impl RapierSimulation {
    fn dynamic_bodies(&self) -> Vec<rapier3d::prelude::RigidBodyHandle> {
        self.world
            .bodies
            .iter()
            .filter(|(_, b)| b.is_dynamic())
            .map(|(h, _)| h)
            .collect()
    }

    pub(crate) fn generalized_velocity(&self) -> Vec<f32> {
        self.joints
            .first()
            .and_then(|j| self.world.multibody_joints.get(j.handle))
            .map(|(mb, _)| mb.generalized_velocity().iter().copied().collect())
            .unwrap_or_default()
    }

    /// The state now (see the module documentation).
    pub(crate) fn read_state(&self) -> SimState {
        let qd = self.generalized_velocity();
        let mut angles = vec![0.0; self.joints.len()];
        realitygap_core::engine::Simulation::joint_angles_rad(self, &mut angles);
        let velocities = self
            .joints
            .iter()
            .map(|j| qd.get(j.dof).map_or(f64::NAN, |&v| v as f64))
            .collect();
        let objects = self
            .objects
            .iter()
            .map(|(name, h)| {
                let b = &self.world.bodies[*h];
                ObjectState {
                    name: name.clone(),
                    pose: from_rapier_pose(b.position()),
                    linear_velocity_m_s: vec3(b.linvel()),
                    angular_velocity_rad_s: vec3(b.angvel()),
                }
            })
            .collect();
        SimState {
            time_s: realitygap_core::engine::Simulation::time_s(self),
            joint_angles_rad: angles,
            joint_velocities_rad_s: velocities,
            joint_velocity_targets_rad_s: self.targets.clone(),
            servo_commands: self.servo_commands(),
            objects,
            native: Some(NativeState {
                engine: ENGINE_NAME.to_string(),
                data: self.native_data(&qd),
            }),
        }
    }

    fn native_data(&self, qd: &[f32]) -> Vec<f64> {
        let mut data = vec![NATIVE_VERSION, self.joints.len() as f64];
        data.extend(self.joints.iter().map(|j| self.exact_coordinate(j)));
        data.push(qd.len() as f64);
        data.extend(qd.iter().map(|&v| v as f64));
        let bodies = self.dynamic_bodies();
        data.push(bodies.len() as f64);
        for h in bodies {
            let b = &self.world.bodies[h];
            let (t, q) = (b.translation(), b.rotation());
            let (v, w) = (b.linvel(), b.angvel());
            let a = b.activation();
            let sleeping = if a.sleeping { 1.0 } else { 0.0 };
            data.extend(
                [
                    t.x, t.y, t.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z, w.x, w.y, w.z,
                ]
                .iter()
                .map(|&x| x as f64),
            );
            data.extend([sleeping, a.time_since_can_sleep as f64]);
        }
        data
    }

    fn exact_coordinate(&self, joint: &crate::ControlledJoint) -> f64 {
        match self.world.multibody_joints.get(joint.handle) {
            Some((mb, link)) => mb
                .link(link)
                .map_or(f64::NAN, |l| l.joint().coords()[joint.coordinate] as f64),
            None => f64::NAN,
        }
    }

    /// Splits and checks a native state of this engine against this world.
    fn decode<'a>(&self, data: &'a [f64]) -> Result<Native<'a>, EngineError> {
        let bad = |what: &str| {
            state_error(format!(
                "the native Rapier state does not fit this simulation: {what} \
                 (load its portable part instead: SimState::portable)"
            ))
        };
        if data.first() != Some(&NATIVE_VERSION) {
            return Err(bad(&format!(
                "layout version {:?}, expected {NATIVE_VERSION}",
                data.first()
            )));
        }
        if let Some(i) = data.iter().position(|x| !x.is_finite()) {
            return Err(bad(&format!("number {i} is not finite")));
        }
        let mut at = 1;
        let mut take = |n_expected: usize, what: &str| -> Result<&'a [f64], EngineError> {
            let n = *data
                .get(at)
                .ok_or_else(|| bad(&format!("it ends before the {what}")))?;
            let per = if what == "bodies" { PER_BODY } else { 1 };
            if n != n_expected as f64 || data.len() < at + 1 + n_expected * per {
                return Err(bad(&format!(
                    "{n} {what}, this simulation has {n_expected}"
                )));
            }
            let slice = &data[at + 1..at + 1 + n_expected * per];
            at += 1 + n_expected * per;
            Ok(slice)
        };
        let coords = take(self.joints.len(), "joint coordinates")?;
        let velocities = take(self.generalized_velocity().len(), "generalized velocities")?;
        let bodies = take(self.dynamic_bodies().len(), "bodies")?;
        if at != data.len() {
            return Err(bad(&format!("{} numbers left over", data.len() - at)));
        }
        Ok(Native {
            coords,
            velocities,
            bodies,
        })
    }

    /// Sets `state` (see the module documentation and
    /// [`realitygap_core::Simulation::set_state`]).
    pub(crate) fn write_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let names: Vec<&str> = self.objects.iter().map(|(n, _)| n.as_str()).collect();
        state
            .check(self.joints.len(), &names)
            .map_err(state_error)?;
        let native = match &state.native {
            Some(n) if n.engine == ENGINE_NAME => Some(self.decode(&n.data)?),
            _ => None,
        };
        // Checked: from here on nothing fails.
        let coords: Vec<f32> = match &native {
            Some(n) => n.coords.iter().map(|&c| c as f32).collect(),
            None => state.joint_angles_rad.iter().map(|&a| a as f32).collect(),
        };
        let velocities: Vec<f32> = match &native {
            Some(n) => n.velocities.iter().map(|&v| v as f32).collect(),
            None => {
                let mut qd = vec![0.0f32; self.generalized_velocity().len()];
                for (j, &v) in self.joints.iter().zip(&state.joint_velocities_rad_s) {
                    if let Some(slot) = qd.get_mut(j.dof) {
                        *slot = v as f32;
                    }
                }
                qd
            }
        };
        self.pristine.restore(&mut self.world);
        self.place_joints(&coords, &velocities);
        match &native {
            Some(n) => self.place_bodies(n.bodies),
            None => self.place_objects(&state.objects),
        }
        self.time_origin_s = state.time_s;
        self.steps = 0;
        self.commands.clear();
        realitygap_core::engine::Simulation::set_joint_velocity_targets(
            self,
            &state.joint_velocity_targets_rad_s,
        );
        if !state.servo_commands.is_empty() {
            realitygap_core::engine::Simulation::set_joint_commands(self, &state.servo_commands)?;
        }
        Ok(())
    }

    /// Sets every controlled joint's coordinate exactly (single precision)
    /// and the generalized velocity, then places the link bodies.
    fn place_joints(&mut self, coords: &[f32], velocities: &[f32]) {
        let world = &mut self.world;
        for (joint, &target) in self.joints.iter().zip(coords) {
            let Some((mb, link_id)) = world.multibody_joints.get_mut(joint.handle) else {
                continue;
            };
            let Some(link) = mb.link_mut(link_id) else {
                continue;
            };
            // `coords += target - current` can miss `target` by a rounding;
            // a second correction lands on it.
            for _ in 0..4 {
                let current = link.joint.coords()[joint.coordinate];
                if current == target {
                    break;
                }
                link.joint.apply_displacement(&[target - current]);
            }
        }
        if let Some(joint) = self.joints.first() {
            if let Some((mb, _)) = world.multibody_joints.get_mut(joint.handle) {
                let mut qd = mb.generalized_velocity_mut();
                for (slot, &v) in qd.iter_mut().zip(velocities) {
                    *slot = v;
                }
                mb.forward_kinematics(&world.bodies, false);
                mb.update_rigid_bodies(&mut world.bodies, true);
            }
        }
    }

    /// Portable: the objects' poses and twists, awake.
    fn place_objects(&mut self, objects: &[ObjectState]) {
        for ((_, h), o) in self.objects.iter().zip(objects) {
            let body = &mut self.world.bodies[*h];
            body.set_position(rapier_pose(&o.pose), true);
            body.set_linvel(vector(o.linear_velocity_m_s), true);
            body.set_angvel(vector(o.angular_velocity_rad_s), true);
        }
    }

    /// Native: every dynamic body's pose, velocity and sleep state.
    fn place_bodies(&mut self, blocks: &[f64]) {
        let handles = self.dynamic_bodies();
        for (h, b) in handles.into_iter().zip(blocks.chunks_exact(PER_BODY)) {
            let f = |i: usize| b[i] as f32;
            let pose = RPose::from_parts(
                Vector::new(f(0), f(1), f(2)),
                Rotation::from_xyzw(f(3), f(4), f(5), f(6)),
            );
            let body = &mut self.world.bodies[h];
            body.set_position(pose, false);
            body.set_linvel(Vector::new(f(7), f(8), f(9)), false);
            body.set_angvel(Vector::new(f(10), f(11), f(12)), false);
            // The stillness timer carries over, so a body that slept falls
            // asleep again after its first step. The sleep flag itself
            // (number 13) is recorded but not set: Rapier puts a body to
            // sleep through its island manager, and a body flagged asleep
            // before its island exists is woken by its first new contact
            // and settles anew (0.3 mm off for the cube of scene 1).
            body.activation_mut().time_since_can_sleep = f(14);
        }
    }
}
