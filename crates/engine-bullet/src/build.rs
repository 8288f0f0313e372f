//! The steps of building a Bullet world from a scene (called by
//! [`BulletSimulation::load_with`](crate::BulletSimulation::load_with) with
//! the Bullet lock held).
//!
//! Every `unsafe` block of this module has its own SAFETY comment; the
//! argument they share:
//! the commands are created on the client passed in and submitted once,
//! with the Bullet lock held; the pointers passed point to live arrays of
//! the sizes the C API reads.

use super::*;

/// Bullet's joints of the robot, by Bullet joint index (= link index).
pub(crate) struct BulletModel {
    /// `b3GetJointInfo` of every joint.
    pub infos: Vec<ffi::b3JointInfo>,
    /// Each joint's URDF name.
    pub joint_names: Vec<String>,
    /// Each joint's child link's URDF name.
    pub link_names: Vec<String>,
}

impl BulletModel {
    /// Reads the joints of body `robot`. Needs the Bullet lock (`lock`).
    pub fn read(lock: &ffi::BulletLock, client: &ffi::Client, robot: c_int) -> BulletModel {
        let h = client.handle(lock);
        // SAFETY: `h` is the live handle of `client`, used with the Bullet
        // lock held (`lock`); `robot` is a body id Bullet returned.
        let count = unsafe { ffi::b3GetNumJoints(h, robot) };
        let mut infos = Vec::with_capacity(count.max(0) as usize);
        for j in 0..count {
            let mut info = ffi::b3JointInfo::default();
            // SAFETY: `info` is a b3JointInfo of the C layout (checked by a test).
            unsafe { ffi::b3GetJointInfo(h, robot, j, &mut info) };
            infos.push(info);
        }
        BulletModel {
            joint_names: infos.iter().map(|i| ffi::c_text(&i.m_joint_name)).collect(),
            link_names: infos.iter().map(|i| ffi::c_text(&i.m_link_name)).collect(),
            infos,
        }
    }

    /// True when joint `j` is revolute or prismatic.
    pub fn is_movable(&self, j: usize) -> bool {
        let t = self.infos[j].m_joint_type;
        t == ffi::JOINT_REVOLUTE || t == ffi::JOINT_PRISMATIC
    }
}

/// Gravity (from the scene), timestep and solver settings. Needs the Bullet lock (`lock`).
pub(crate) fn set_physics(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    options: &BulletSettings,
    gravity_m_s2: Vec3,
) -> Result<(), EngineError> {
    // SAFETY: the command is created on this simulation's client and
    // submitted once, with the Bullet lock held (`lock`); the pointers
    // passed point to live locals of the sizes Bullet expects.
    unsafe {
        let cmd = ffi::b3InitPhysicsParamCommand(client.handle(lock));
        let g = gravity_m_s2;
        ffi::b3PhysicsParamSetGravity(cmd, g.x, g.y, g.z);
        ffi::b3PhysicsParamSetTimeStep(cmd, options.timestep_s);
        ffi::b3PhysicsParamSetNumSubSteps(cmd, 0);
        if let Some(v) = options.solver_iterations {
            ffi::b3PhysicsParamSetNumSolverIterations(cmd, v);
        }
        if let Some(v) = options.solver_residual_threshold {
            ffi::b3PhysicsParamSetSolverResidualThreshold(cmd, v);
        }
        if let Some(v) = options.contact_erp {
            ffi::b3PhysicsParamSetDefaultContactERP(cmd, v);
        }
        if let Some(v) = options.non_contact_erp {
            ffi::b3PhysicsParamSetDefaultNonContactERP(cmd, v);
        }
        if let Some(v) = options.friction_erp {
            ffi::b3PhysicsParamSetDefaultFrictionERP(cmd, v);
        }
        if let Some(v) = options.global_cfm {
            ffi::b3PhysicsParamSetDefaultGlobalCFM(cmd, v);
        }
        if let Some(v) = options.split_impulse {
            ffi::b3PhysicsParamSetUseSplitImpulse(cmd, v as c_int);
        }
        if let Some(v) = options.split_impulse_penetration_threshold_m {
            ffi::b3PhysicsParamSetSplitImpulsePenetrationThreshold(cmd, v);
        }
        if let Some(v) = options.contact_breaking_threshold_m {
            ffi::b3PhysicsParamSetContactBreakingThreshold(cmd, v);
        }
        if let Some(v) = options.cone_friction {
            ffi::b3PhysicsParamSetEnableConeFriction(cmd, v as c_int);
        }
        expect(
            client.submit(lock, cmd).kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "setting the physics parameters",
        )
    }
}

/// The ground plane, when the scene has one. Needs the Bullet lock (`lock`).
pub(crate) fn create_ground(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    scene: &Scene,
) -> Result<Option<c_int>, EngineError> {
    let Some(g) = &scene.ground else {
        return Ok(None);
    };
    // SAFETY: the command is created on this simulation's client and
    // submitted once, with the Bullet lock held (`lock`); the pointers
    // passed point to live locals of the sizes Bullet expects.
    let shape = unsafe {
        let cmd = ffi::b3CreateCollisionShapeCommandInit(client.handle(lock));
        ffi::b3CreateCollisionShapeAddPlane(cmd, [0.0, 0.0, 1.0].as_ptr(), 0.0);
        let r = client.submit(lock, cmd);
        expect(
            r.kind,
            ffi::CMD_CREATE_COLLISION_SHAPE_COMPLETED,
            "creating the ground plane",
        )?;
        ffi::b3GetStatusCollisionShapeUniqueId(r.handle())
    };
    let body = create_body(
        lock,
        client,
        0.0,
        shape,
        Pose::new(Vec3::new(0.0, 0.0, g.height_m), Quat::IDENTITY),
        "the ground",
    )?;
    if let Some(f) = g.friction {
        set_friction(lock, client, body, -1, f)?;
    }
    Ok(Some(body))
}

/// Loads the URDF file `urdf` with a fixed base at the scene's base pose.
/// Needs the Bullet lock (`lock`).
pub(crate) fn load_robot(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    options: &BulletSettings,
    scene: &Scene,
    robot: &RobotModel,
    urdf: &std::ffi::CStr,
) -> Result<c_int, EngineError> {
    let mut flags = 0;
    if options.inertia_from_file {
        flags |= ffi::URDF_USE_INERTIA_FROM_FILE;
    }
    if options.self_collision {
        flags |= ffi::URDF_USE_SELF_COLLISION | ffi::URDF_USE_SELF_COLLISION_EXCLUDE_PARENT;
    }
    if options.implicit_cylinders {
        flags |= ffi::URDF_USE_IMPLICIT_CYLINDER;
    }
    let base = scene.robot.base;
    // SAFETY: the command is created on this simulation's client and
    // submitted once, with the Bullet lock held (`lock`); the pointers
    // passed point to live locals of the sizes Bullet expects.
    //; `urdf` is NUL-terminated.
    unsafe {
        let cmd = ffi::b3LoadUrdfCommandInit(client.handle(lock), urdf.as_ptr());
        let p = base.position_m;
        let q = base.orientation;
        ffi::b3LoadUrdfCommandSetStartPosition(cmd, p.x, p.y, p.z);
        ffi::b3LoadUrdfCommandSetStartOrientation(cmd, q.x, q.y, q.z, q.w);
        ffi::b3LoadUrdfCommandSetUseFixedBase(cmd, 1);
        ffi::b3LoadUrdfCommandSetFlags(cmd, flags);
        let r = client.submit(lock, cmd);
        if r.kind != ffi::CMD_URDF_LOADING_COMPLETED {
            return Err(load_error(format!(
                "Bullet could not load URDF file {} ({}){}",
                robot.source.display(),
                ffi::status_name(r.kind),
                bullet_said()
            )));
        }
        Ok(ffi::b3GetStatusBodyIndex(r.handle()))
    }
}

/// Fails when Bullet warned that it could not read a mesh.
pub(crate) fn check_mesh_messages(robot: &RobotModel) -> Result<(), EngineError> {
    let messages = take_messages();
    match messages.iter().find(|m| {
        m.level != Level::Info
            && (m.text.contains("cannot extract")
                || m.text.contains("Cannot find")
                || m.text.contains("filesize mismatch")
                || m.text.contains("unknown collision geometry"))
    }) {
        Some(m) => Err(load_error(format!(
            "URDF file {}: Bullet could not read a mesh: {}",
            robot.source.display(),
            m.text
        ))),
        None => Ok(()),
    }
}

/// Every scene object as a box body with its mass, pose and friction: body
/// ids and names in scene order. Needs the Bullet lock (`lock`).
pub(crate) fn create_objects(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    scene: &Scene,
) -> Result<(Vec<c_int>, Vec<String>), EngineError> {
    let mut objects = Vec::new();
    let mut names = Vec::new();
    for object in &scene.objects {
        let ObjectShape::Box { size_m } = object.shape;
        // SAFETY: the command is created on this simulation's client and
        // submitted once, with the Bullet lock held (`lock`); the pointers
        // passed point to live locals of the sizes Bullet expects.
        let shape = unsafe {
            let cmd = ffi::b3CreateCollisionShapeCommandInit(client.handle(lock));
            let half = [size_m.x / 2.0, size_m.y / 2.0, size_m.z / 2.0];
            ffi::b3CreateCollisionShapeAddBox(cmd, half.as_ptr());
            let r = client.submit(lock, cmd);
            expect(
                r.kind,
                ffi::CMD_CREATE_COLLISION_SHAPE_COMPLETED,
                &format!("creating the shape of object \"{}\"", object.name),
            )?;
            ffi::b3GetStatusCollisionShapeUniqueId(r.handle())
        };
        let what = format!("object \"{}\"", object.name);
        let body = create_body(lock, client, object.mass_kg, shape, object.pose, &what)?;
        // Bullet's multibodies carry a quadratic air drag by default (0.04
        // on the base's linear and angular velocity): a thrown box then
        // leaves the parabola and a spinning one loses 37 % of its angular
        // momentum in 2 s (the kit's free-body checks). The scene has no
        // air: no drag.
        // SAFETY: as in `create_body`: one command on this simulation's
        // client, submitted once with the Bullet lock held.
        unsafe {
            let cmd = ffi::b3InitChangeDynamicsInfo(client.handle(lock));
            ffi::b3ChangeDynamicsInfoSetLinearDamping(cmd, body, 0.0);
            ffi::b3ChangeDynamicsInfoSetAngularDamping(cmd, body, 0.0);
            expect(
                client.submit(lock, cmd).kind,
                ffi::CMD_CLIENT_COMMAND_COMPLETED,
                &format!("removing the air drag of {what}"),
            )?;
        }
        if let Some(f) = object.friction {
            set_friction(lock, client, body, -1, f)?;
        }
        objects.push(body);
        names.push(object.name.clone());
    }
    Ok((objects, names))
}

/// The controlled joints, in actuator order, with their motor forces: the
/// scene's force limit (with a `force_limit` parameter already in it), or
/// the `max_force_n_m` setting for joints without that parameter.
pub(crate) fn motor_joints(
    scene: &Scene,
    params: &PhysicalParams,
    options: &BulletSettings,
    model: &BulletModel,
    robot: &RobotModel,
) -> Result<Vec<MotorJoint>, EngineError> {
    let mut joints = Vec::new();
    for a in &scene.actuators {
        let j = model
            .joint_names
            .iter()
            .position(|n| *n == a.joint)
            .ok_or_else(|| {
                load_error(format!(
                    "Bullet's model of {} has no joint \"{}\"",
                    robot.source.display(),
                    a.joint
                ))
            })?;
        if !model.is_movable(j) {
            return Err(load_error(format!(
                "joint \"{}\" is not a revolute or prismatic joint in Bullet (fixed joints cannot be actuated)",
                a.joint
            )));
        }
        let own = params.joints.get(&a.joint);
        let limit = match (own.and_then(|p| p.force_limit), options.max_force_n_m) {
            (None, Some(setting)) => setting,
            _ => a.force_limit,
        };
        let info = &model.infos[j];
        joints.push(MotorJoint {
            index: j as c_int,
            q_index: info.m_q_index as usize,
            u_index: info.m_u_index,
            max_force: if limit.is_finite() {
                limit
            } else {
                UNLIMITED_FORCE_N_M
            },
            friction: params::motor_friction(a, own)?,
            kp: a.kp.unwrap_or(0.0),
            kv: a.kv,
        });
    }
    Ok(joints)
}

/// Puts every movable joint that is not controlled at its held angle and
/// locks it there with a position motor (gains 1, force = its URDF effort
/// limit). Needs the Bullet lock (`lock`).
pub(crate) fn hold_joints(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    scene: &Scene,
    robot: c_int,
    model: &BulletModel,
) -> Result<Vec<HeldJoint>, EngineError> {
    let h = client.handle(lock);
    let held: Vec<HeldJoint> = (0..model.infos.len())
        .filter(|&j| {
            model.is_movable(j)
                && !scene
                    .actuators
                    .iter()
                    .any(|a| a.joint == model.joint_names[j])
        })
        .map(|j| HeldJoint {
            index: j as c_int,
            position: scene
                .robot
                .held_joints_rad
                .get(&model.joint_names[j])
                .copied()
                .unwrap_or(0.0),
        })
        .collect();
    if held.is_empty() {
        return Ok(held);
    }
    // SAFETY: the command is created on this simulation's client and
    // submitted once, with the Bullet lock held (`lock`); the pointers
    // passed point to live locals of the sizes Bullet expects.
    unsafe {
        if held.iter().any(|j| j.position != 0.0) {
            let cmd = ffi::b3CreatePoseCommandInit(h, robot);
            for j in &held {
                ffi::b3CreatePoseCommandSetJointPosition(h, cmd, j.index, j.position);
                ffi::b3CreatePoseCommandSetJointVelocity(h, cmd, j.index, 0.0);
            }
            expect(
                client.submit(lock, cmd).kind,
                ffi::CMD_CLIENT_COMMAND_COMPLETED,
                "setting the held joints",
            )?;
        }
        let cmd = ffi::b3JointControlCommandInit2(h, robot, ffi::CONTROL_MODE_POSITION_VELOCITY_PD);
        for j in &held {
            let info = &model.infos[j.index as usize];
            let force = if info.m_joint_max_force > 0.0 {
                info.m_joint_max_force
            } else {
                HELD_JOINT_DEFAULT_FORCE_N_M
            };
            ffi::b3JointControlSetDesiredPosition(cmd, info.m_q_index, j.position);
            ffi::b3JointControlSetKp(cmd, info.m_u_index, 1.0);
            ffi::b3JointControlSetDesiredVelocity(cmd, info.m_u_index, 0.0);
            ffi::b3JointControlSetKd(cmd, info.m_u_index, 1.0);
            ffi::b3JointControlSetMaximumForce(cmd, info.m_u_index, force);
        }
        expect(
            client.submit(lock, cmd).kind,
            ffi::CMD_DESIRED_STATE_RECEIVED_COMPLETED,
            "locking the held joints",
        )?;
    }
    Ok(held)
}

/// Scales every mass and inertia, and every friction coefficient by the
/// square root of the factor (Bullet multiplies the two coefficients of a
/// contact). Needs the Bullet lock (`lock`).
pub(crate) fn apply_variation(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    variation: &ModelVariation,
    robot: c_int,
    model: &BulletModel,
    objects: &[c_int],
    ground: Option<c_int>,
) -> Result<(), EngineError> {
    let mut bodies: Vec<(c_int, c_int)> = (-1..model.infos.len() as c_int)
        .map(|l| (robot, l))
        .collect();
    bodies.extend(objects.iter().map(|&b| (b, -1)));
    if variation.mass_scale != 1.0 {
        for &(body, link) in &bodies {
            let info = dynamics_info(lock, client, body, link)?;
            if info.m_mass > 0.0 {
                set_mass(lock, client, body, link, &info, variation.mass_scale)?;
            }
        }
    }
    if variation.friction_scale != 1.0 {
        bodies.extend(ground.map(|g| (g, -1)));
        let factor = variation.friction_scale.sqrt();
        for &(body, link) in &bodies {
            let info = dynamics_info(lock, client, body, link)?;
            set_friction(
                lock,
                client,
                body,
                link,
                info.m_lateralFrictionCoeff * factor,
            )?;
        }
    }
    Ok(())
}

/// Multiplies a body link's mass and inertia diagonal by `factor`. Needs the Bullet lock (`lock`).
pub(crate) fn set_mass(
    lock: &ffi::BulletLock,
    client: &ffi::Client,
    body: c_int,
    link: c_int,
    info: &ffi::b3DynamicsInfo,
    factor: f64,
) -> Result<(), EngineError> {
    let inertia = info.m_localInertialDiagonal.map(|i| i * factor);
    // SAFETY: the command is created on this simulation's client and
    // submitted once, with the Bullet lock held (`lock`); the pointers
    // passed point to live locals of the sizes Bullet expects.
    unsafe {
        let cmd = ffi::b3InitChangeDynamicsInfo(client.handle(lock));
        ffi::b3ChangeDynamicsInfoSetMass(cmd, body, link, info.m_mass * factor);
        ffi::b3ChangeDynamicsInfoSetLocalInertiaDiagonal(cmd, body, link, inertia.as_ptr());
        expect(
            client.submit(lock, cmd).kind,
            ffi::CMD_CLIENT_COMMAND_COMPLETED,
            "scaling masses",
        )
    }
}

/// What each of the scene's tracked bodies is in Bullet.
pub(crate) fn tracked_bodies(
    scene: &Scene,
    robot: &RobotModel,
    root_link_name: &str,
    model: &BulletModel,
    object_names: &[String],
) -> Result<Vec<Tracked>, EngineError> {
    let mut tracked = Vec::new();
    for t in &scene.tracked {
        tracked.push(match &t.target {
            TrackTarget::Link(name) if name == root_link_name => Tracked::Root(scene.robot.base),
            TrackTarget::Link(name) => {
                let l = model
                    .link_names
                    .iter()
                    .position(|n| n == name)
                    .ok_or_else(|| {
                        load_error(format!(
                            "tracked link \"{name}\" is not a link of Bullet's model of {}",
                            robot.source.display()
                        ))
                    })?;
                Tracked::Link(l as c_int)
            }
            TrackTarget::Object(name) => {
                let i = object_names.iter().position(|n| n == name).ok_or_else(|| {
                    load_error(format!("tracked object \"{name}\" is not in the scene"))
                })?;
                Tracked::Object(i)
            }
        });
    }
    Ok(tracked)
}
