//! Assembly: a [`Scene`] and its [`RobotModel`] become a PhysX scene.
//!
//! The stages, in order:
//!
//! 1. **Groups.** The robot's links are split into rigid groups by core's
//!    shared planning ([`realitygap_core::robot::plan`], which also resolves
//!    the scene's joint, link and object names): a group starts at the root
//!    link or at the child of an actuated joint and takes in every link
//!    reached through fixed, held and mimic joints, at their fixed or held
//!    positions. A group is one articulation link whose frame is the frame
//!    of its top link.
//! 2. **Articulation.** One `PxArticulationReducedCoordinate` with a fixed
//!    base: the root group is its root link at the scene's base pose; every
//!    other group is a link with the URDF mass properties of its links
//!    combined by core ([`shared::group_mass`]): the mass, the centre of mass
//!    and the principal axes and moments of the combined inertia tensor
//!    (`PxDiagonalize`). Links get no linear or angular damping (PhysX's
//!    default is 0.05) and never sleep.
//! 3. **Shapes.** Every URDF `<collision>` shape of every member link, at
//!    the link's offset composed with the shape's origin (see
//!    [`crate::shapes`]), with friction 0.5 and restitution 0. PhysX does
//!    not collide a link with its parent link; other links may touch.
//! 4. **Joints.** Every actuated joint is the inbound joint of its child's
//!    link: revolute (about the joint frame's x axis, turned onto the URDF
//!    axis; `eLIMITED` with the URDF limits; continuous joints and limits
//!    beyond a turn are `eREVOLUTE_UNWRAPPED`, whose angle does not wrap)
//!    or prismatic. The scene's servo is the joint's drive on that axis:
//!    stiffness 0, damping `kv`, maximum force the force limit, target
//!    velocity set by the controller, force drive type; PhysX solves it
//!    implicitly with the rest. Viscous joint damping `d` (URDF `damping`,
//!    the `damping` parameter) has no separate term in PhysX 5.1, so it is
//!    folded into the same drive: damping `kv + d` and target velocity
//!    `kv v / (kv + d)` give exactly `kv (v - q') - d q'`; with a finite
//!    force limit the damping's share counts towards the limit. With the
//!    servo off (limit 0) the drive is the damping alone. The `armature`
//!    parameter is the joint's armature.
//! 5. **World.** A static plane at the ground's height, one dynamic box per
//!    scene object (mass from the scene, inertia of a uniform box), the
//!    scene's gravity and the solver settings.

use crate::sdk::{said, Locked, Sdk};
use crate::settings::{PhysxSettings, Solver};
use crate::shapes;
use physx_sys::*;
use realitygap_core::engine::ModelVariation;
use realitygap_core::params::PhysicalParams;
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::robot::plan::{self as shared, GroupSplit, RigidGroups, TrackedRef};
use realitygap_core::robot::{Collision, JointKind, RobotModel};
use realitygap_core::scene::{ObjectShape, Scene};
use std::collections::HashMap;
use std::f64::consts::TAU;

/// Impacts slower than this do not bounce, m/s (PhysX needs a positive
/// threshold; its default is 2 m/s at this tolerance scale).
pub const BOUNCE_THRESHOLD_M_S: f32 = 0.05;

/// Friction of every robot shape, and of the ground and objects when the
/// scene gives none (Bullet's and Rapier's default).
pub const DEFAULT_FRICTION: f64 = 0.5;

/// A controlled joint's drive.
#[derive(Debug, Clone)]
pub struct Drive {
    /// The URDF joint's name.
    pub name: String,
    /// The PhysX joint.
    pub joint: *mut PxArticulationJointReducedCoordinate,
    /// The drive's axis (`eTWIST` for revolute joints, `eX` for prismatic).
    pub axis: PxArticulationAxis,
    /// The servo's velocity gain, N m s/rad.
    pub kv: f64,
    /// The PD servo's position gain for position commands, N m/rad (0
    /// when the scene gives none).
    pub kp: f64,
    /// The drive's largest force, N m (`f32::MAX` when unlimited).
    pub max_force: f64,
    /// The joint's viscous damping folded into the drive, N m s/rad.
    pub damping: f64,
}

impl Drive {
    /// The drive's target velocity for a servo target `v`, rad/s (see the
    /// module documentation).
    pub fn target(&self, v: f64) -> f32 {
        if self.kv + self.damping > 0.0 {
            (self.kv * v / (self.kv + self.damping)) as f32
        } else {
            0.0
        }
    }
}

/// Where a frame sits: an actor and the frame's pose in the actor's frame.
#[derive(Debug, Clone, Copy)]
pub struct ActorFrame {
    /// The actor (an articulation link or an object).
    pub actor: *mut PxRigidActor,
    /// The frame's pose in the actor's frame.
    pub offset: Pose,
}

/// A built PhysX scene and what the simulation needs of it. Dropping it
/// releases everything it created.
pub struct World {
    /// The scene.
    pub scene: *mut PxScene,
    dispatcher: *mut PxDefaultCpuDispatcher,
    /// The robot.
    pub articulation: *mut PxArticulationReducedCoordinate,
    /// The controlled joints, in the scene's actuator order.
    pub drives: Vec<Drive>,
    /// The tracked frames, in the scene's `[[track]]` order.
    pub tracked: Vec<ActorFrame>,
    /// Every URDF link's frame, by link name.
    pub links: HashMap<String, ActorFrame>,
    /// The scene objects' actors, in the scene's order.
    pub objects: Vec<*mut PxRigidDynamic>,
    /// The articulation's cache, for joint forces (effort commands);
    /// null until the first one.
    pub cache: *mut PxArticulationCache,
    statics: Vec<*mut PxRigidStatic>,
    materials: Vec<*mut PxMaterial>,
}

impl Drop for World {
    fn drop(&mut self) {
        let Ok(sdk) = crate::sdk::sdk() else { return };
        // Held already when a half-built world is dropped on a load error.
        let _locked = sdk.lock_unless_held();
        // SAFETY: every pointer was created by this world and is released
        // once, actors and the articulation before their scene, under the
        // SDK lock.
        unsafe {
            for &o in &self.objects {
                PxActor_release_mut(o as *mut PxActor);
            }
            for &s in &self.statics {
                PxActor_release_mut(s as *mut PxActor);
            }
            if !self.cache.is_null() {
                PxArticulationCache_release_mut(self.cache);
            }
            if !self.articulation.is_null() {
                PxArticulationReducedCoordinate_release_mut(self.articulation);
            }
            if !self.scene.is_null() {
                PxScene_release_mut(self.scene);
            }
            if !self.dispatcher.is_null() {
                PxDefaultCpuDispatcher_release_mut(self.dispatcher);
            }
            for &m in &self.materials {
                PxRefCounted_release_mut(m as *mut PxRefCounted);
            }
        }
    }
}

/// `p` as a PhysX transform (single precision).
pub fn to_px(p: &Pose) -> PxTransform {
    let q = p.orientation.normalized().unwrap_or(Quat::IDENTITY);
    PxTransform {
        q: PxQuat {
            x: q.x as f32,
            y: q.y as f32,
            z: q.z as f32,
            w: q.w as f32,
        },
        p: vec_to_px(p.position_m),
    }
}

/// A PhysX transform as a pose.
pub fn from_px(t: &PxTransform) -> Pose {
    Pose::new(
        vec_from_px(t.p),
        Quat::new(t.q.w as f64, t.q.x as f64, t.q.y as f64, t.q.z as f64),
    )
}

/// `v` as a PhysX vector.
pub fn vec_to_px(v: Vec3) -> PxVec3 {
    PxVec3 {
        x: v.x as f32,
        y: v.y as f32,
        z: v.z as f32,
    }
}

/// A PhysX vector as a vector.
pub fn vec_from_px(v: PxVec3) -> Vec3 {
    Vec3::new(v.x as f64, v.y as f64, v.z as f64)
}

/// Everything a world is built from.
pub struct Recipe<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The robot (already validated against the scene).
    pub robot: &'a RobotModel,
    /// The checked settings.
    pub settings: &'a PhysxSettings,
    /// The model variation.
    pub variation: &'a ModelVariation,
    /// The physical parameters (already checked by [`crate::params::check`]).
    pub params: &'a PhysicalParams,
}

/// Builds the world of a recipe (see the module documentation). Errors are
/// messages for [`realitygap_core::EngineError::Load`].
pub fn build(recipe: &Recipe<'_>) -> Result<World, String> {
    recipe.variation.check()?;
    shared::check_servos(recipe.scene).map_err(|e| e.0)?;
    let plan = shared::plan_robot(recipe.scene, recipe.robot, GroupSplit::AtActuatedJoints)
        .map_err(|e| e.0)?;
    let sdk = crate::sdk::sdk()?;
    let locked = sdk.lock();
    crate::sdk::take_messages();
    let mut world = empty_world(&locked, recipe)?;
    let mut b = Builder {
        sdk,
        locked: &locked,
        recipe,
        world: &mut world,
    };
    let links = b.articulation(&plan.groups, &plan.initial_positions)?;
    b.drives(&plan.actuated, &plan.groups, &links)?;
    b.ground()?;
    b.objects()?;
    // SAFETY: the articulation is complete; adding it to its scene is the
    // last step of building.
    let added = unsafe { PxScene_addArticulation_mut(world.scene, world.articulation) };
    if !added {
        return Err(format!("PhysX refused the articulation{}", said()));
    }
    let link_frame = |l: usize| ActorFrame {
        actor: links[plan.groups.group_of_link[l]] as *mut PxRigidActor,
        offset: plan.groups.link_in_group[l],
    };
    world.links = (0..recipe.robot.links.len())
        .map(|l| (recipe.robot.links[l].name.clone(), link_frame(l)))
        .collect();
    world.tracked = plan
        .tracked
        .iter()
        .map(|t| match *t {
            TrackedRef::Link(l) => link_frame(l),
            TrackedRef::Object(i) => ActorFrame {
                actor: world.objects[i] as *mut PxRigidActor,
                offset: Pose::IDENTITY,
            },
        })
        .collect();
    Ok(world)
}

/// A scene with the recipe's gravity and solver, stepping on the calling
/// thread, and an empty fixed-base articulation.
fn empty_world(locked: &Locked<'_>, recipe: &Recipe<'_>) -> Result<World, String> {
    let s = recipe.settings;
    let g = recipe.scene.gravity_m_s2;
    // SAFETY: FFI calls creating a dispatcher, a scene and an articulation
    // under the SDK lock; each result is checked, and `World`'s drop
    // releases whatever was created if a later step fails.
    unsafe {
        let mut world = World {
            scene: std::ptr::null_mut(),
            dispatcher: phys_PxDefaultCpuDispatcherCreate(
                0,
                std::ptr::null_mut(),
                PxDefaultCpuDispatcherWaitForWorkMode::WaitForWork,
                0,
            ),
            articulation: std::ptr::null_mut(),
            drives: vec![],
            tracked: vec![],
            links: HashMap::new(),
            objects: vec![],
            cache: std::ptr::null_mut(),
            statics: vec![],
            materials: vec![],
        };
        if world.dispatcher.is_null() {
            return Err(format!("PhysX could not create a CPU dispatcher{}", said()));
        }
        let scale = *PxPhysics_getTolerancesScale(locked.physics);
        let mut desc = PxSceneDesc_new(&scale);
        desc.gravity = vec_to_px(g);
        desc.cpuDispatcher = world.dispatcher as *mut PxCpuDispatcher;
        desc.filterShader = get_default_simulation_filter_shader();
        // Impacts slower than this do not bounce: PhysX's default is 2 m/s
        // at this tolerance scale, which would make a restitution
        // parameter do nothing in a drop of 0.2 m.
        desc.bounceThresholdVelocity = BOUNCE_THRESHOLD_M_S;
        desc.solverType = match s.solver {
            Solver::Pgs => PxSolverType::Pgs,
            Solver::Tgs => PxSolverType::Tgs,
        };
        world.scene = PxPhysics_createScene_mut(locked.physics, &desc);
        if world.scene.is_null() {
            return Err(format!("PhysX could not create a scene{}", said()));
        }
        world.articulation = PxPhysics_createArticulationReducedCoordinate_mut(locked.physics);
        if world.articulation.is_null() {
            return Err(format!("PhysX could not create an articulation{}", said()));
        }
        let a = world.articulation;
        PxArticulationReducedCoordinate_setArticulationFlag_mut(
            a,
            PxArticulationFlag::FixBase,
            true,
        );
        if !s.self_collision {
            PxArticulationReducedCoordinate_setArticulationFlag_mut(
                a,
                PxArticulationFlag::DisableSelfCollision,
                true,
            );
        }
        // Drive force limits in newtons and newton metres (PhysX's default
        // reads them as impulses per step).
        PxArticulationReducedCoordinate_setArticulationFlag_mut(
            a,
            PxArticulationFlag::DriveLimitsAreForces,
            true,
        );
        PxArticulationReducedCoordinate_setSolverIterationCounts_mut(
            a,
            s.position_iterations,
            s.velocity_iterations,
        );
        PxArticulationReducedCoordinate_setSleepThreshold_mut(a, 0.0);
        Ok(world)
    }
}

struct Builder<'a, 'l> {
    sdk: &'a Sdk,
    locked: &'a Locked<'l>,
    recipe: &'a Recipe<'a>,
    world: &'a mut World,
}

impl Builder<'_, '_> {
    /// A material with friction `f` (static and dynamic) and restitution
    /// `r`, owned by the world.
    fn material(&mut self, f: f64, r: Option<f64>) -> Result<*mut PxMaterial, String> {
        let f = (f * self.recipe.variation.friction_scale) as f32;
        // SAFETY: creates a material under the SDK lock; checked below.
        let m = unsafe {
            PxPhysics_createMaterial_mut(self.locked.physics, f, f, r.unwrap_or(0.0) as f32)
        };
        if m.is_null() {
            return Err(format!("PhysX could not create a material{}", said()));
        }
        if r.is_some() {
            // SAFETY: `m` is a valid material.
            unsafe { PxMaterial_setRestitutionCombineMode_mut(m, PxCombineMode::Max) };
        }
        self.world.materials.push(m);
        Ok(m)
    }

    /// Creates a shape of `geometry` at `pose` (actor frame) and attaches
    /// it to `actor`.
    fn attach(
        &mut self,
        actor: *mut PxRigidActor,
        geometry: &shapes::ShapeGeometry,
        pose: &Pose,
        material: *mut PxMaterial,
    ) -> Result<(), String> {
        let flags = PxShapeFlags::SimulationShape | PxShapeFlags::SceneQueryShape;
        // SAFETY: the geometry, material and actor are valid; the shape is
        // exclusive and released with its actor.
        unsafe {
            let shape = PxPhysics_createShape_mut(
                self.locked.physics,
                geometry.as_ptr(),
                material,
                true,
                flags,
            );
            if shape.is_null() {
                return Err(format!("PhysX refused the shape{}", said()));
            }
            PxShape_setLocalPose_mut(shape, &to_px(pose));
            PxShape_setContactOffset_mut(shape, self.recipe.settings.contact_offset_m as f32);
            PxShape_setRestOffset_mut(shape, 0.0);
            let attached = PxRigidActor_attachShape_mut(actor, shape);
            PxShape_release_mut(shape); // the actor holds it now
            if !attached {
                return Err(format!("PhysX could not attach a shape{}", said()));
            }
        }
        Ok(())
    }

    fn collision(
        &mut self,
        actor: *mut PxRigidActor,
        link: usize,
        index: usize,
        collision: &Collision,
        offset: &Pose,
        material: *mut PxMaterial,
    ) -> Result<(), String> {
        let robot = self.recipe.robot;
        let context = |e: String| {
            let name = collision
                .name
                .as_deref()
                .map(|n| format!(" \"{n}\""))
                .unwrap_or_default();
            format!(
                "link \"{}\", collision {}{name}: {e}",
                robot.links[link].name,
                index + 1
            )
        };
        let (geometry, shape_pose) =
            shapes::geometry(self.sdk, self.locked, &collision.geometry).map_err(context)?;
        let pose = offset.compose(&collision.origin).compose(&shape_pose);
        self.attach(actor, &geometry, &pose, material)
            .map_err(context)
    }

    /// Stages 2 and 3: one link per group, with its mass and shapes.
    fn articulation(
        &mut self,
        plan: &RigidGroups,
        positions: &[f64],
    ) -> Result<Vec<*mut PxArticulationLink>, String> {
        let robot = self.recipe.robot;
        let world_poses = robot.forward_kinematics(&self.recipe.scene.robot.base, positions);
        let material = self.material(DEFAULT_FRICTION, None)?;
        let mut links: Vec<*mut PxArticulationLink> = Vec::with_capacity(plan.groups.len());
        for (g, group) in plan.groups.iter().enumerate() {
            let parent = group
                .parent
                .map_or(std::ptr::null_mut(), |(_, pg)| links[pg]);
            let pose = to_px(&world_poses[group.top_link]);
            // SAFETY: the parent link was created before (groups come
            // parents first); the result is checked.
            let link = unsafe {
                PxArticulationReducedCoordinate_createLink_mut(
                    self.world.articulation,
                    parent,
                    &pose,
                )
            };
            if link.is_null() {
                return Err(format!(
                    "PhysX refused the link of \"{}\"{}",
                    robot.links[group.top_link].name,
                    said()
                ));
            }
            self.link_mass(link, g, plan)?;
            for &l in &group.links {
                for (c, collision) in robot.links[l].collisions.iter().enumerate() {
                    let offset = plan.link_in_group[l];
                    self.collision(
                        link as *mut PxRigidActor,
                        l,
                        c,
                        collision,
                        &offset,
                        material,
                    )?;
                }
            }
            links.push(link);
        }
        Ok(links)
    }

    /// The combined mass of group `g` on its link: mass, centre of mass and
    /// principal inertia. The root group (fixed) may have none.
    fn link_mass(
        &mut self,
        link: *mut PxArticulationLink,
        g: usize,
        plan: &RigidGroups,
    ) -> Result<(), String> {
        let robot = self.recipe.robot;
        let group = &plan.groups[g];
        let merged = shared::group_mass(
            robot,
            &group.links,
            &plan.link_in_group,
            self.recipe.variation.mass_scale,
        );
        let top = &robot.links[group.top_link].name;
        let Some(m) = merged else {
            if g == 0 {
                return Ok(());
            }
            return Err(format!(
                "link \"{top}\" and the links fixed to it have no mass; a moving body needs a positive mass \
                 (give it an <inertial> in {})",
                robot.source.display()
            ));
        };
        if !(m.mass_kg as f32).is_normal()
            || m.inertia_kg_m2.iter().any(|v| !(*v as f32).is_finite())
        {
            return Err(format!(
                "link \"{top}\" and the links fixed to it: mass {} kg is out of single-precision range",
                m.mass_kg
            ));
        }
        let i = m.inertia_kg_m2.map(|v| v as f32);
        let body = link as *mut PxRigidBody;
        // SAFETY: `link` is a valid link; the matrix is built from finite
        // numbers.
        unsafe {
            let matrix = PxMat33 {
                column0: PxVec3 {
                    x: i[0],
                    y: i[3],
                    z: i[6],
                },
                column1: PxVec3 {
                    x: i[1],
                    y: i[4],
                    z: i[7],
                },
                column2: PxVec3 {
                    x: i[2],
                    y: i[5],
                    z: i[8],
                },
            };
            let mut axes = PxQuat_new_1(PxIDENTITY::PxIdentity);
            let diagonal = phys_PxDiagonalize(&matrix, &mut axes);
            let moments = [diagonal.x, diagonal.y, diagonal.z];
            if moments.iter().any(|m| !(m.is_finite() && *m > 0.0)) {
                return Err(format!(
                    "link \"{top}\" and the links fixed to it: the principal moments of inertia {moments:?} kg m^2 \
                     are not all positive; PhysX needs a positive-definite inertia on every moving link (check the \
                     <inertia> values in {})",
                    robot.source.display()
                ));
            }
            PxRigidBody_setMass_mut(body, m.mass_kg as f32);
            let com = PxTransform_new_5(&vec_to_px(m.com_m), &axes);
            PxRigidBody_setCMassLocalPose_mut(body, &com);
            PxRigidBody_setMassSpaceInertiaTensor_mut(body, &diagonal);
            PxRigidBody_setLinearDamping_mut(body, 0.0);
            PxRigidBody_setAngularDamping_mut(body, 0.0);
        }
        Ok(())
    }

    /// Stage 4: each actuated joint's type, frames, limits and drive.
    fn drives(
        &mut self,
        actuated: &[usize],
        plan: &RigidGroups,
        links: &[*mut PxArticulationLink],
    ) -> Result<(), String> {
        let robot = self.recipe.robot;
        let scene = self.recipe.scene;
        for (a, &j) in actuated.iter().enumerate() {
            let joint = &robot.joints[j];
            let spec = &scene.actuators[a];
            let child = links[plan.group_of_link[joint.child]];
            // SAFETY: every non-root link has an inbound joint.
            let px = unsafe { PxArticulationLink_getInboundJoint(child) };
            if px.is_null() {
                return Err(format!("joint \"{}\" has no PhysX joint", joint.name));
            }
            let limited = joint.limits.filter(|l| {
                l.lower.is_finite() && l.upper.is_finite() && joint.kind != JointKind::Continuous
            });
            let (kind, axis) = match joint.kind {
                // PhysX's eREVOLUTE wraps its angle into (-2 pi, 2 pi]: a
                // joint free to turn further is eREVOLUTE_UNWRAPPED.
                JointKind::Revolute | JointKind::Continuous => match limited {
                    Some(l) if l.lower > -TAU && l.upper < TAU => {
                        (PxArticulationJointType::Revolute, PxArticulationAxis::Twist)
                    }
                    _ => (
                        PxArticulationJointType::RevoluteUnwrapped,
                        PxArticulationAxis::Twist,
                    ),
                },
                JointKind::Prismatic => (PxArticulationJointType::Prismatic, PxArticulationAxis::X),
                JointKind::Fixed => {
                    return Err(format!(
                        "joint \"{}\" is fixed and cannot be driven",
                        joint.name
                    ))
                }
            };
            let basis = Pose::new(Vec3::ZERO, Quat::x_onto(joint.axis));
            let parent_pose = plan.link_in_group[joint.parent]
                .compose(&joint.origin)
                .compose(&basis);
            if joint.damping.is_nan() || joint.damping < 0.0 {
                return Err(format!(
                    "joint \"{}\": damping must be >= 0, found {}",
                    joint.name, joint.damping
                ));
            }
            let damping = joint.damping;
            // With the servo off (limit 0) the drive is the damping alone,
            // towards rest: no gain, so no target velocity.
            let servo_on = spec.force_limit > 0.0;
            let (stiffness_damping, max_force) = if servo_on {
                (spec.kv + damping, spec.force_limit.min(f32::MAX as f64))
            } else {
                (damping, f32::MAX as f64)
            };
            let drive = Drive {
                name: spec.joint.clone(),
                joint: px,
                axis,
                kv: if servo_on { spec.kv } else { 0.0 },
                kp: if servo_on {
                    spec.kp.unwrap_or(0.0)
                } else {
                    0.0
                },
                max_force: if servo_on { max_force } else { 0.0 },
                damping,
            };
            let armature = self.recipe.params.armature(&joint.name).unwrap_or(0.0);
            // SAFETY: `px` is the valid inbound joint of `child`.
            unsafe {
                PxArticulationJointReducedCoordinate_setJointType_mut(px, kind);
                PxArticulationJointReducedCoordinate_setParentPose_mut(px, &to_px(&parent_pose));
                PxArticulationJointReducedCoordinate_setChildPose_mut(px, &to_px(&basis));
                match limited {
                    Some(l) => {
                        PxArticulationJointReducedCoordinate_setMotion_mut(
                            px,
                            axis,
                            PxArticulationMotion::Limited,
                        );
                        let limit = PxArticulationLimit_new_1(l.lower as f32, l.upper as f32);
                        PxArticulationJointReducedCoordinate_setLimitParams_mut(px, axis, &limit);
                    }
                    None => PxArticulationJointReducedCoordinate_setMotion_mut(
                        px,
                        axis,
                        PxArticulationMotion::Free,
                    ),
                }
                let d = PxArticulationDrive_new_1(
                    0.0,
                    stiffness_damping as f32,
                    max_force as f32,
                    PxArticulationDriveType::Force,
                );
                PxArticulationJointReducedCoordinate_setDriveParams_mut(px, axis, &d);
                PxArticulationJointReducedCoordinate_setDriveVelocity_mut(px, axis, 0.0, true);
                PxArticulationJointReducedCoordinate_setArmature_mut(px, axis, armature as f32);
                // PhysX's default joint friction coefficient is 0.05 of the
                // force the joint transmits: a drag the URDF does not have.
                PxArticulationJointReducedCoordinate_setFrictionCoefficient_mut(px, 0.0);
            }
            self.world.drives.push(drive);
        }
        Ok(())
    }

    /// Stage 5: the ground's plane.
    fn ground(&mut self) -> Result<(), String> {
        let Some(ground) = &self.recipe.scene.ground else {
            return Ok(());
        };
        let material = self.material(ground.friction.unwrap_or(DEFAULT_FRICTION), None)?;
        // SAFETY: creates a static plane under the SDK lock; checked.
        unsafe {
            let plane = PxPlane_new_1(0.0, 0.0, 1.0, -(ground.height_m as f32));
            let actor = phys_PxCreatePlane(self.locked.physics, &plane, material);
            if actor.is_null() {
                return Err(format!("PhysX could not create the ground plane{}", said()));
            }
            self.world.statics.push(actor);
            let mut shape: *mut PxShape = std::ptr::null_mut();
            if PxRigidActor_getShapes(actor as *const PxRigidActor, &mut shape, 1, 0) == 1 {
                PxShape_setContactOffset_mut(shape, self.recipe.settings.contact_offset_m as f32);
                PxShape_setRestOffset_mut(shape, 0.0);
            }
            if !PxScene_addActor_mut(self.world.scene, actor as *mut PxActor, std::ptr::null()) {
                return Err(format!("PhysX refused the ground plane{}", said()));
            }
        }
        Ok(())
    }

    /// Stage 5: the scene's objects, in the scene's order.
    fn objects(&mut self) -> Result<(), String> {
        let scene = self.recipe.scene;
        for o in &scene.objects {
            let ObjectShape::Box { size_m } = o.shape;
            let mass = o.mass_kg * self.recipe.variation.mass_scale;
            if !(mass.is_finite() && mass > 0.0 && (mass as f32).is_normal()) {
                return Err(format!(
                    "object \"{}\": mass {mass} kg is not a positive single-precision number",
                    o.name
                ));
            }
            let (geometry, _) = shapes::geometry(
                self.sdk,
                self.locked,
                &realitygap_core::robot::Geometry::Box { size_m },
            )
            .map_err(|e| format!("object \"{}\": {e}", o.name))?;
            let restitution = self.recipe.params.restitution(&o.name);
            let material = self.material(o.friction.unwrap_or(DEFAULT_FRICTION), restitution)?;
            if o.friction.is_some() {
                // A friction given for the object is the contact's when the
                // other surface is at least as rough (`Min` outranks the
                // ground's `Average`; as in ODE and DART): with `Average`
                // the ground's 0.5 kept every contact above 0.25.
                // SAFETY: `material` is a valid material.
                unsafe { PxMaterial_setFrictionCombineMode_mut(material, PxCombineMode::Min) };
            }
            // SAFETY: creates a dynamic actor under the SDK lock; checked.
            let actor =
                unsafe { PxPhysics_createRigidDynamic_mut(self.locked.physics, &to_px(&o.pose)) };
            if actor.is_null() {
                return Err(format!(
                    "PhysX could not create object \"{}\"{}",
                    o.name,
                    said()
                ));
            }
            self.world.objects.push(actor);
            self.attach(
                actor as *mut PxRigidActor,
                &geometry,
                &Pose::IDENTITY,
                material,
            )
            .map_err(|e| format!("object \"{}\": {e}", o.name))?;
            let (x, y, z) = (size_m.x, size_m.y, size_m.z);
            let inertia = Vec3::new(y * y + z * z, x * x + z * z, x * x + y * y).scale(mass / 12.0);
            let s = self.recipe.settings;
            // SAFETY: `actor` is a valid dynamic actor.
            unsafe {
                let body = actor as *mut PxRigidBody;
                PxRigidBody_setMass_mut(body, mass as f32);
                PxRigidBody_setMassSpaceInertiaTensor_mut(body, &vec_to_px(inertia));
                PxRigidBody_setLinearDamping_mut(body, 0.0);
                PxRigidBody_setAngularDamping_mut(body, 0.0);
                // A free body's rotation needs the gyroscopic term
                // (w x I w): without it PhysX holds a spinning body's
                // angular velocity and turns its angular momentum (28 %
                // in 2 s in the kit's torque-free check).
                PxRigidBody_setRigidBodyFlag_mut(
                    body,
                    PxRigidBodyFlag::EnableGyroscopicForces,
                    true,
                );
                PxRigidDynamic_setSleepThreshold_mut(actor, 0.0);
                PxRigidDynamic_setSolverIterationCounts_mut(
                    actor,
                    s.position_iterations,
                    s.velocity_iterations,
                );
                if !PxScene_addActor_mut(self.world.scene, actor as *mut PxActor, std::ptr::null())
                {
                    return Err(format!("PhysX refused object \"{}\"{}", o.name, said()));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_round_trip() {
        let p = Pose::new(
            Vec3::new(0.1, -0.2, 0.3),
            Quat::from_euler_rpy(0.3, -0.2, 1.1),
        );
        let back = from_px(&to_px(&p));
        assert!(back.position_m.distance(p.position_m) < 1e-7);
        assert!(back.orientation.angle_to(p.orientation) < 1e-6);
    }

    #[test]
    fn folded_damping_gives_the_servo_and_the_damping() {
        let d = Drive {
            name: "j".into(),
            joint: std::ptr::null_mut(),
            axis: PxArticulationAxis::Twist,
            kv: 10.0,
            kp: 0.0,
            max_force: 5.0,
            damping: 2.0,
        };
        // (kv + d) (t - w) == kv (v - w) - d w for every joint speed w.
        let v = 0.7;
        for w in [-1.0, 0.0, 0.3] {
            let folded = (d.kv + d.damping) * (d.target(v) as f64 - w);
            let want = d.kv * (v - w) - d.damping * w;
            assert!((folded - want).abs() < 1e-6, "{folded} vs {want}");
        }
    }
}
