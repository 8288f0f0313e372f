//! The ODE objects of one simulation, built from a [`ModelPlan`], and the
//! process-wide parts of ODE: initialisation, message handlers, the lock.
//!
//! Every raw ODE call of the crate is in this module.
//!
//! Process-wide facts about Debian's ODE 0.16 build (`dGetConfiguration`:
//! `ODE_EXT_trimesh ODE_EXT_opcode ODE_EXT_threading ODE_double_precision`,
//! no `ODE_EXT_mt_collisions`): collision detection keeps global caches and
//! is not thread safe, so building, stepping and dropping a world hold
//! [`ode_lock`]; reading a body's state does not (it touches only that
//! world's memory).
//!
//! ODE reports trouble through three handlers: messages (warnings such as
//! "LCP internal error"), errors (`dError`, after which ODE calls `exit`)
//! and debug messages (`dDebug`, failed internal assertions, after which
//! ODE calls `abort`). [`init`] routes all three here: messages are kept
//! for [`take_messages`], errors and debug messages are also printed to
//! standard error as `ODE error: ...` before ODE ends the process (the
//! `realitygap run` command runs each simulation in a child process, so
//! that ends one run only, with that message).

use crate::ffi::*;
use crate::plan::{ModelPlan, ShapePlan};
use crate::settings::{Base, OdeSettings, Stepper};
use realitygap_core::pose::{Pose, Quat, Vec3};
use std::cell::Cell;
use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::{Mutex, MutexGuard, OnceLock};

const _: () = assert!(
    std::mem::size_of::<dReal>() == 8,
    "ODE must be built with double precision"
);
const _: () = assert!(
    std::mem::size_of::<dTriIndex>() == 4,
    "ODE triangle indices must be 32-bit"
);

/// The messages ODE reported since the last [`take_messages`] (at most 64).
static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());
/// Serialises the calls that are not thread safe (see the module docs).
static ODE_LOCK: Mutex<()> = Mutex::new(());

thread_local! {
    static THREAD_READY: Cell<bool> = const { Cell::new(false) };
    static LOCK_HELD: Cell<bool> = const { Cell::new(false) };
}

/// Formats an ODE message (printf format and its arguments).
///
/// # Safety
/// `fmt` is null or a NUL-terminated format string matching `ap`.
unsafe fn format_message(fmt: *const c_char, ap: *mut __va_list_tag) -> String {
    if fmt.is_null() {
        return String::new();
    }
    let mut buf = [0 as c_char; 1024];
    let n = vsnprintf(buf.as_mut_ptr(), buf.len() as _, fmt, ap);
    if n < 0 {
        return CStr::from_ptr(fmt).to_string_lossy().into_owned();
    }
    CStr::from_ptr(buf.as_ptr())
        .to_string_lossy()
        .trim()
        .to_string()
}

fn record(text: String) {
    if let Ok(mut m) = MESSAGES.lock() {
        if m.len() < 64 {
            m.push(text);
        }
    }
}

unsafe extern "C" fn on_message(num: c_int, fmt: *const c_char, ap: *mut __va_list_tag) {
    record(format!("ODE message {num}: {}", format_message(fmt, ap)));
}

unsafe extern "C" fn on_error(num: c_int, fmt: *const c_char, ap: *mut __va_list_tag) {
    let text = format_message(fmt, ap);
    // ODE ends the process when this returns: the parent reads this line.
    eprintln!("ODE error {num}: {text}");
    record(format!("ODE error {num}: {text}"));
}

unsafe extern "C" fn on_debug(num: c_int, fmt: *const c_char, ap: *mut __va_list_tag) {
    let text = format_message(fmt, ap);
    eprintln!("ODE error (internal check {num} failed, ODE aborts): {text}");
    record(format!("ODE internal error {num}: {text}"));
}

/// The messages ODE reported since the last call.
pub fn take_messages() -> Vec<String> {
    MESSAGES
        .lock()
        .map(|mut m| std::mem::take(&mut *m))
        .unwrap_or_default()
}

/// Initialises ODE once per process (`dInitODE2`), installs the message
/// handlers and checks that the library uses double precision. Later calls
/// return the first call's result.
pub fn init() -> Result<(), String> {
    static RESULT: OnceLock<Result<(), String>> = OnceLock::new();
    RESULT
        .get_or_init(|| {
            // SAFETY: called once (OnceLock), before any other ODE call of
            // this crate; the handlers are 'static functions.
            unsafe {
                if dInitODE2(0) == 0 {
                    return Err("dInitODE2 failed".to_string());
                }
                dSetMessageHandler(Some(on_message));
                dSetErrorHandler(Some(on_error));
                dSetDebugHandler(Some(on_debug));
                if dCheckConfiguration(c"ODE_double_precision".as_ptr()) == 0 {
                    return Err(format!(
                        "the ODE library in use is not built with double precision (configuration: {}); install Debian's libode-dev 0.16",
                        configuration()
                    ));
                }
            }
            Ok(())
        })
        .clone()
}

/// ODE's configuration string (`dGetConfiguration`).
pub fn configuration() -> String {
    // SAFETY: returns a static NUL-terminated string; needs no initialisation.
    unsafe { CStr::from_ptr(dGetConfiguration()) }
        .to_string_lossy()
        .into_owned()
}

/// Holds the process-wide ODE lock (see [`ode_lock`]).
pub struct OdeGuard {
    guard: Option<MutexGuard<'static, ()>>,
}

impl Drop for OdeGuard {
    fn drop(&mut self) {
        if self.guard.is_some() {
            LOCK_HELD.with(|h| h.set(false));
        }
    }
}

/// Takes the process-wide ODE lock and makes sure this thread has ODE's
/// per-thread data. Re-entrant: a thread that already holds it gets a
/// guard that releases nothing.
pub fn ode_lock() -> OdeGuard {
    if LOCK_HELD.with(|h| h.get()) {
        return OdeGuard { guard: None };
    }
    let guard = ODE_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    LOCK_HELD.with(|h| h.set(true));
    THREAD_READY.with(|ready| {
        if !ready.get() {
            // SAFETY: ODE is initialised (every caller went through init()).
            unsafe { dAllocateODEDataForThread(dAllocateODEDataFlags_dAllocateMaskAll as u32) };
            ready.set(true);
        }
    });
    OdeGuard { guard: Some(guard) }
}

const CATEGORY_GROUND: std::ffi::c_ulong = 1;
const CATEGORY_ROBOT: std::ffi::c_ulong = 2;
const CATEGORY_OBJECT: std::ffi::c_ulong = 4;

/// What a collision shape belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Owner {
    /// The ground plane.
    Ground,
    /// A robot body (index in the plan's bodies).
    Robot(usize),
    /// A scene object (index in the scene's objects).
    Object(usize),
}

/// What the collision callback needs; lives in a Box so its address is
/// stable while ODE calls back.
struct CollideContext {
    world: dWorldID,
    group: dJointGroupID,
    /// Owner slot (0 ground, 1.. robot bodies, then objects) and friction
    /// of every geom, indexed by the geom's user data minus 1.
    geoms: Vec<(usize, f64)>,
    /// Whether two owner slots may touch, `slots x slots`.
    may_touch: Vec<bool>,
    slots: usize,
    buffer: Vec<dContact>,
    contacts: usize,
    /// Owner slots of the pairs that touched in the last step.
    pairs: Vec<(usize, usize)>,
}

unsafe extern "C" fn near_callback(data: *mut c_void, o1: dGeomID, o2: dGeomID) {
    // SAFETY: `data` is the CollideContext passed to dSpaceCollide by
    // OdeWorld::step, alive and exclusively ours for the call.
    let ctx = &mut *(data as *mut CollideContext);
    let index = |g: dGeomID| (dGeomGetData(g) as usize).wrapping_sub(1);
    let (i1, i2) = (index(o1), index(o2));
    let (Some(&(s1, mu1)), Some(&(s2, mu2))) = (ctx.geoms.get(i1), ctx.geoms.get(i2)) else {
        return;
    };
    if !ctx.may_touch[s1 * ctx.slots + s2] {
        return;
    }
    let (b1, b2) = (dGeomGetBody(o1), dGeomGetBody(o2));
    if b1.is_null() && b2.is_null() {
        return;
    }
    let max = ctx.buffer.len() as c_int;
    let stride = std::mem::size_of::<dContact>() as c_int;
    let Some(first) = ctx.buffer.first_mut() else {
        return;
    };
    let n = dCollide(o1, o2, max, &mut first.geom, stride);
    let mu = mu1.min(mu2);
    for c in ctx.buffer.iter_mut().take(n.max(0) as usize) {
        c.surface = dSurfaceParameters {
            mode: dContactApprox1 as c_int,
            mu,
            ..Default::default()
        };
        let joint = dJointCreateContact(ctx.world, ctx.group, c);
        dJointAttach(joint, b1, b2);
    }
    if n > 0 {
        ctx.contacts += n as usize;
        ctx.pairs.push((s1, s2));
    }
}

/// Keeps a triangle mesh's buffers alive as long as ODE uses them.
struct TriMeshStore {
    data: dTriMeshDataID,
    _vertices: Vec<f64>,
    _indices: Vec<u32>,
}

/// The ODE objects of one simulation. Dropping it destroys them.
pub struct OdeWorld {
    world: dWorldID,
    space: dSpaceID,
    contact_group: dJointGroupID,
    /// Robot bodies (null for a static base), plan order.
    robot_bodies: Vec<dBodyID>,
    /// Object bodies, scene order.
    object_bodies: Vec<dBodyID>,
    /// Names of the robot bodies then the objects, for messages.
    names: Vec<String>,
    /// One hinge per controlled joint, actuator order.
    hinges: Vec<dJointID>,
    /// Viscous damping per hinge, N m s/rad.
    damping: Vec<f64>,
    trimeshes: Vec<TriMeshStore>,
    ctx: Box<CollideContext>,
    stepper: Stepper,
    timestep_s: f64,
    /// This world's state of ODE's random generator (process-wide in ODE;
    /// dWorldQuickStep draws from it to reorder constraints), so that a
    /// simulation does not depend on what other simulations in the process
    /// did.
    rng_seed: std::ffi::c_ulong,
}

// SAFETY: the ODE objects are owned by this value alone and are only used
// through it; the calls that touch process-wide state hold the ODE lock,
// and the thread that steps gets its per-thread ODE data in ode_lock().
unsafe impl Send for OdeWorld {}

fn vec3(p: *const dReal) -> Vec3 {
    // SAFETY: ODE returns pointers to at least 3 dReals for positions and
    // velocities, valid while the body exists.
    unsafe { Vec3::new(*p, *p.add(1), *p.add(2)) }
}

fn quat(q: Quat) -> [dReal; 4] {
    [q.w, q.x, q.y, q.z]
}

impl OdeWorld {
    /// Builds the ODE world of `plan` with the bodies at `body_poses` (the
    /// initial configuration) and hinges along the links' joint frames
    /// `joint_frames` (world poses of each hinge's child link frame, and its
    /// unit axis in that frame). Must be called with [`ode_lock`] held.
    pub fn build(
        plan: &ModelPlan,
        settings: &OdeSettings,
        body_poses: &[Pose],
        joint_frames: &[(Pose, Vec3)],
    ) -> Result<OdeWorld, String> {
        // SAFETY: ODE is initialised and the lock is held (caller); every
        // pointer handed to ODE is either one ODE returned or a buffer kept
        // alive in the returned value (trimesh data, collision context).
        unsafe {
            let world = dWorldCreate();
            let space = dHashSpaceCreate(std::ptr::null_mut());
            let contact_group = dJointGroupCreate(0);
            let ctx = Box::new(CollideContext {
                world,
                group: contact_group,
                geoms: Vec::new(),
                may_touch: Vec::new(),
                slots: 0,
                buffer: vec![dContact::default(); settings.max_contacts],
                contacts: 0,
                pairs: Vec::new(),
            });
            let mut w = OdeWorld {
                world,
                space,
                contact_group,
                robot_bodies: Vec::new(),
                object_bodies: Vec::new(),
                names: plan
                    .bodies
                    .iter()
                    .map(|b| format!("the body of link {}", b.name))
                    .chain(plan.objects.iter().map(|o| format!("object {}", o.name)))
                    .collect(),
                hinges: Vec::new(),
                damping: Vec::new(),
                trimeshes: Vec::new(),
                ctx,
                stepper: settings.stepper,
                timestep_s: settings.timestep_s,
                rng_seed: 0,
            };
            dWorldSetGravity(world, 0.0, 0.0, -9.81);
            dWorldSetERP(world, settings.erp);
            dWorldSetCFM(world, settings.cfm);
            dWorldSetQuickStepNumIterations(world, settings.quick_step_iterations as c_int);
            dWorldSetQuickStepW(world, settings.quick_step_sor);
            dWorldSetContactMaxCorrectingVel(world, settings.contact_max_correcting_vel_m_s);
            dWorldSetContactSurfaceLayer(world, settings.contact_surface_layer_m);
            dWorldSetAutoDisableFlag(world, 0);

            let robot_slots = plan.bodies.len();
            let slots = 1 + robot_slots + plan.objects.len();
            let slot_of = |o: Owner| match o {
                Owner::Ground => 0,
                Owner::Robot(b) => 1 + b,
                Owner::Object(i) => 1 + robot_slots + i,
            };

            if let Some((height, mu)) = plan.ground {
                let g = dCreatePlane(space, 0.0, 0.0, 1.0, height);
                w.register_geom(
                    g,
                    slot_of(Owner::Ground),
                    mu,
                    Owner::Ground,
                    settings.self_collision,
                );
            }

            for (b, body) in plan.bodies.iter().enumerate() {
                let pose = body_poses[b];
                let id = if body.is_static {
                    std::ptr::null_mut()
                } else {
                    let Some(m) = body.mass else {
                        return Err(format!(
                            "the body of link {} has no mass and cannot move",
                            body.name
                        ));
                    };
                    let id = dBodyCreate(world);
                    w.set_mass(id, m.mass_kg, &m.inertia)
                        .map_err(|e| format!("the body of link {}: {e}", body.name))?;
                    dBodySetPosition(id, pose.position_m.x, pose.position_m.y, pose.position_m.z);
                    dBodySetQuaternion(id, quat(pose.orientation).as_ptr());
                    id
                };
                w.robot_bodies.push(id);
                for g in &body.geoms {
                    let geom = w.create_geom(&g.shape);
                    if id.is_null() {
                        let at = pose.compose(&g.offset);
                        dGeomSetPosition(geom, at.position_m.x, at.position_m.y, at.position_m.z);
                        dGeomSetQuaternion(geom, quat(at.orientation).as_ptr());
                    } else {
                        dGeomSetBody(geom, id);
                        dGeomSetOffsetPosition(
                            geom,
                            g.offset.position_m.x,
                            g.offset.position_m.y,
                            g.offset.position_m.z,
                        );
                        dGeomSetOffsetQuaternion(geom, quat(g.offset.orientation).as_ptr());
                    }
                    w.register_geom(
                        geom,
                        slot_of(Owner::Robot(b)),
                        plan.robot_mu,
                        Owner::Robot(b),
                        settings.self_collision,
                    );
                }
            }
            let base_is_body = !w.robot_bodies[0].is_null();
            if base_is_body {
                debug_assert_eq!(settings.base, Base::FixedJoint);
                let fixed = dJointCreateFixed(world, std::ptr::null_mut());
                dJointAttach(fixed, w.robot_bodies[0], std::ptr::null_mut());
                dJointSetFixed(fixed);
            }

            for &(child, parent) in &plan.welds {
                let fixed = dJointCreateFixed(world, std::ptr::null_mut());
                dJointAttach(fixed, w.robot_bodies[child], w.robot_bodies[parent]);
                dJointSetFixed(fixed);
            }

            for (h, (frame, axis)) in plan.hinges.iter().zip(joint_frames) {
                let joint = dJointCreateHinge(world, std::ptr::null_mut());
                dJointAttach(
                    joint,
                    w.robot_bodies[h.child_body],
                    w.robot_bodies[h.parent_body],
                );
                let a = frame.orientation.rotate(*axis);
                dJointSetHingeAnchor(
                    joint,
                    frame.position_m.x,
                    frame.position_m.y,
                    frame.position_m.z,
                );
                dJointSetHingeAxis(joint, a.x, a.y, a.z);
                if let Some(lo) = h.stops_rad.0 {
                    dJointSetHingeParam(joint, dParamLoStop as c_int, lo);
                }
                if let Some(hi) = h.stops_rad.1 {
                    dJointSetHingeParam(joint, dParamHiStop as c_int, hi);
                }
                dJointSetHingeParam(joint, dParamVel as c_int, 0.0);
                dJointSetHingeParam(joint, dParamFMax as c_int, h.force_limit_nm);
                if settings.servo == crate::settings::Servo::Kv {
                    // torque = kv (v_target - v_next): the motor row's CFM is
                    // the inverse of the damper gain (see the README).
                    let cfm = if h.kv > 0.0 {
                        1.0 / h.kv
                    } else {
                        f64::INFINITY
                    };
                    if cfm.is_finite() {
                        dJointSetHingeParam(joint, dParamCFM as c_int, cfm);
                    } else {
                        dJointSetHingeParam(joint, dParamFMax as c_int, 0.0);
                    }
                }
                if h.friction_nm > 0.0 {
                    // Coulomb joint friction: a second motor holding zero
                    // velocity with at most the friction torque.
                    let motor = dJointCreateAMotor(world, std::ptr::null_mut());
                    dJointAttach(
                        motor,
                        w.robot_bodies[h.child_body],
                        w.robot_bodies[h.parent_body],
                    );
                    dJointSetAMotorMode(motor, dAMotorUser as c_int);
                    dJointSetAMotorNumAxes(motor, 1);
                    dJointSetAMotorAxis(motor, 0, 0, a.x, a.y, a.z);
                    dJointSetAMotorParam(motor, dParamVel as c_int, 0.0);
                    dJointSetAMotorParam(motor, dParamFMax as c_int, h.friction_nm);
                }
                w.hinges.push(joint);
                w.damping.push(h.damping);
            }

            for (i, o) in plan.objects.iter().enumerate() {
                let id = dBodyCreate(world);
                w.set_mass(id, o.mass.mass_kg, &o.mass.inertia)
                    .map_err(|e| format!("object \"{}\": {e}", o.name))?;
                dBodySetPosition(
                    id,
                    o.pose.position_m.x,
                    o.pose.position_m.y,
                    o.pose.position_m.z,
                );
                dBodySetQuaternion(id, quat(o.pose.orientation).as_ptr());
                let geom = dCreateBox(space, o.size_m.x, o.size_m.y, o.size_m.z);
                dGeomSetBody(geom, id);
                w.register_geom(
                    geom,
                    slot_of(Owner::Object(i)),
                    o.mu,
                    Owner::Object(i),
                    settings.self_collision,
                );
                w.object_bodies.push(id);
            }

            // Which owners may touch.
            let mut may_touch = vec![true; slots * slots];
            let mut forbid = |a: usize, b: usize| {
                may_touch[a * slots + b] = false;
                may_touch[b * slots + a] = false;
            };
            forbid(0, 0);
            for a in 0..robot_slots {
                for b in 0..robot_slots {
                    if a == b || !settings.self_collision {
                        forbid(1 + a, 1 + b);
                    }
                }
            }
            for h in &plan.hinges {
                forbid(1 + h.child_body, 1 + h.parent_body);
            }
            for &(child, parent) in &plan.welds {
                forbid(1 + child, 1 + parent);
            }
            // The base, and whatever is welded to it, is held at its pose:
            // the floor cannot push it.
            let mut anchored = vec![false; robot_slots];
            anchored[0] = true;
            for &(child, parent) in &plan.welds {
                anchored[child] = anchored[child] || anchored[parent];
            }
            for (b, _) in anchored.iter().enumerate().filter(|(_, &a)| a) {
                forbid(0, 1 + b);
            }
            w.ctx.may_touch = may_touch;
            w.ctx.slots = slots;
            Ok(w)
        }
    }

    /// # Safety
    /// `id` is a body of this world.
    unsafe fn set_mass(&self, id: dBodyID, mass_kg: f64, i: &[f64; 9]) -> Result<(), String> {
        let mut m = dMass::default();
        dMassSetParameters(
            &mut m, mass_kg, 0.0, 0.0, 0.0, i[0], i[4], i[8], i[1], i[2], i[5],
        );
        if dMassCheck(&m) == 0 {
            let said = take_messages().join("; ");
            return Err(format!(
                "ODE rejects the mass {mass_kg} kg with inertia {i:?} kg m^2: {said}"
            ));
        }
        dBodySetMass(id, &m);
        Ok(())
    }

    /// # Safety
    /// Called during build, with the lock held.
    unsafe fn create_geom(&mut self, shape: &ShapePlan) -> dGeomID {
        match shape {
            ShapePlan::Box(s) => dCreateBox(self.space, s.x, s.y, s.z),
            ShapePlan::Sphere(r) => dCreateSphere(self.space, *r),
            ShapePlan::Cylinder(r, l) => dCreateCylinder(self.space, *r, *l),
            ShapePlan::Capsule(r, l) => dCreateCapsule(self.space, *r, *l),
            ShapePlan::Mesh(m) => {
                let data = dGeomTriMeshDataCreate();
                let vertices = m.vertices.clone();
                let indices = m.indices.clone();
                dGeomTriMeshDataBuildDouble(
                    data,
                    vertices.as_ptr() as *const c_void,
                    (3 * std::mem::size_of::<f64>()) as c_int,
                    (vertices.len() / 3) as c_int,
                    indices.as_ptr() as *const c_void,
                    indices.len() as c_int,
                    (3 * std::mem::size_of::<u32>()) as c_int,
                );
                let geom = dCreateTriMesh(self.space, data, None, None, None);
                self.trimeshes.push(TriMeshStore {
                    data,
                    _vertices: vertices,
                    _indices: indices,
                });
                geom
            }
        }
    }

    /// # Safety
    /// `geom` is a geom of this world's space.
    unsafe fn register_geom(
        &mut self,
        geom: dGeomID,
        slot: usize,
        mu: f64,
        owner: Owner,
        self_collision: bool,
    ) {
        self.ctx.geoms.push((slot, mu));
        dGeomSetData(geom, self.ctx.geoms.len() as *mut c_void);
        // Category bits let the space skip pairs that never touch before it
        // compares bounding boxes; the callback decides the rest.
        let (category, collide) = match owner {
            Owner::Ground => (CATEGORY_GROUND, CATEGORY_ROBOT | CATEGORY_OBJECT),
            Owner::Robot(_) if self_collision => (
                CATEGORY_ROBOT,
                CATEGORY_GROUND | CATEGORY_ROBOT | CATEGORY_OBJECT,
            ),
            Owner::Robot(_) => (CATEGORY_ROBOT, CATEGORY_GROUND | CATEGORY_OBJECT),
            Owner::Object(_) => (
                CATEGORY_OBJECT,
                CATEGORY_GROUND | CATEGORY_ROBOT | CATEGORY_OBJECT,
            ),
        };
        dGeomSetCategoryBits(geom, category);
        dGeomSetCollideBits(geom, collide);
    }

    /// The timestep, s.
    pub fn timestep_s(&self) -> f64 {
        self.timestep_s
    }

    /// Sets the velocity target of hinge `i`, rad/s.
    pub fn set_hinge_velocity(&mut self, i: usize, rad_s: f64) {
        // SAFETY: the hinge belongs to this world; setting a joint parameter
        // touches only that joint.
        unsafe { dJointSetHingeParam(self.hinges[i], dParamVel as c_int, rad_s) };
    }

    /// The hinge's angle as ODE measures it, in (-pi, pi], rad.
    pub fn hinge_angle(&self, i: usize) -> f64 {
        // SAFETY: reads the joint's bodies of this world.
        unsafe { dJointGetHingeAngle(self.hinges[i]) }
    }

    /// Number of hinges.
    pub fn hinge_count(&self) -> usize {
        self.hinges.len()
    }

    /// One step: joint damping torques, collision, the solver (with this
    /// world's random-generator state), contacts removed. `false` when
    /// ODE's stepper reports a failure (out of memory). Must be called with
    /// [`ode_lock`] held.
    pub fn step(&mut self) -> bool {
        // SAFETY: lock held (caller); the context is boxed, alive and not
        // otherwise borrowed during dSpaceCollide.
        unsafe {
            for (&j, &d) in self.hinges.iter().zip(&self.damping) {
                if d > 0.0 {
                    dJointAddHingeTorque(j, -d * dJointGetHingeAngleRate(j));
                }
            }
            self.ctx.contacts = 0;
            self.ctx.pairs.clear();
            let ctx: *mut CollideContext = &mut *self.ctx;
            dRandSetSeed(self.rng_seed);
            dSpaceCollide(self.space, ctx as *mut c_void, Some(near_callback));
            let ok = match self.stepper {
                Stepper::WorldStep => dWorldStep(self.world, self.timestep_s),
                Stepper::QuickStep => dWorldQuickStep(self.world, self.timestep_s),
            };
            self.rng_seed = dRandGetSeed();
            dJointGroupEmpty(self.contact_group);
            ok != 0
        }
    }

    /// Contact points created in the last step.
    pub fn last_contact_count(&self) -> usize {
        self.ctx.contacts
    }

    /// The pairs of owners that touched in the last step.
    pub fn last_contact_pairs(&self) -> Vec<(Owner, Owner)> {
        let robot = self.robot_bodies.len();
        let owner = |slot: usize| match slot {
            0 => Owner::Ground,
            s if s <= robot => Owner::Robot(s - 1),
            s => Owner::Object(s - 1 - robot),
        };
        self.ctx
            .pairs
            .iter()
            .map(|&(a, b)| (owner(a), owner(b)))
            .collect()
    }

    fn body_pose_of(id: dBodyID) -> Pose {
        // SAFETY: `id` is a live body of this world.
        unsafe {
            let p = vec3(dBodyGetPosition(id));
            let q = dBodyGetQuaternion(id);
            Pose::new(p, Quat::new(*q, *q.add(1), *q.add(2), *q.add(3)))
        }
    }

    /// World pose of robot body `b`'s frame (centre of mass); `fallback` for
    /// a static body.
    pub fn robot_body_pose(&self, b: usize, fallback: &Pose) -> Pose {
        let id = self.robot_bodies[b];
        if id.is_null() {
            *fallback
        } else {
            Self::body_pose_of(id)
        }
    }

    /// World pose of object `i`'s centre.
    pub fn object_pose(&self, i: usize) -> Pose {
        Self::body_pose_of(self.object_bodies[i])
    }

    /// Puts robot body `b` at `pose`, at rest (static bodies stay).
    pub fn place_robot_body(&mut self, b: usize, pose: &Pose) {
        let id = self.robot_bodies[b];
        if id.is_null() {
            return;
        }
        // SAFETY: `id` is a live body of this world.
        unsafe {
            dBodySetPosition(id, pose.position_m.x, pose.position_m.y, pose.position_m.z);
            dBodySetQuaternion(id, quat(pose.orientation).as_ptr());
            dBodySetLinearVel(id, 0.0, 0.0, 0.0);
            dBodySetAngularVel(id, 0.0, 0.0, 0.0);
        }
    }

    /// The first body whose state is not finite or moves implausibly fast
    /// (beyond `max_speed_m_s` or `max_spin_rad_s`), described.
    pub fn unusable_state(&self, max_speed_m_s: f64, max_spin_rad_s: f64) -> Option<String> {
        let ids = self.robot_bodies.iter().chain(&self.object_bodies);
        for (name, &id) in self.names.iter().zip(ids) {
            if id.is_null() {
                continue;
            }
            let pose = Self::body_pose_of(id);
            // SAFETY: `id` is a live body of this world.
            let (v, w) = unsafe { (vec3(dBodyGetLinearVel(id)), vec3(dBodyGetAngularVel(id))) };
            if !pose.is_finite() || !v.is_finite() || !w.is_finite() {
                return Some(format!(
                    "{name}: position, orientation or velocity is not finite"
                ));
            }
            if v.norm() > max_speed_m_s {
                return Some(format!(
                    "{name} moves at {:.3e} m/s (bound {max_speed_m_s} m/s)",
                    v.norm()
                ));
            }
            if w.norm() > max_spin_rad_s {
                return Some(format!(
                    "{name} spins at {:.3e} rad/s (bound {max_spin_rad_s} rad/s)",
                    w.norm()
                ));
            }
        }
        None
    }
}

impl Drop for OdeWorld {
    fn drop(&mut self) {
        let _guard = ode_lock();
        // SAFETY: every object was created by this world and is destroyed
        // once: the space (with its geoms, cleanup is ODE's default), then
        // the trimesh data the geoms used, the contact group, the world
        // (with its bodies and joints).
        unsafe {
            dSpaceDestroy(self.space);
            for t in &self.trimeshes {
                dGeomTriMeshDataDestroy(t.data);
            }
            dJointGroupDestroy(self.contact_group);
            dWorldDestroy(self.world);
        }
    }
}
