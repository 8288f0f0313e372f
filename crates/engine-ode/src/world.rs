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
use crate::settings::{OdeSettings, Stepper};
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

/// Numbers per moving body in the native state (position 3, quaternion 4,
/// linear velocity 3, angular velocity 3).
pub const BODY_STATE_LEN: usize = 13;

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
    // SAFETY: `buf` is writable for its length, which vsnprintf is told and
    // never exceeds (it NUL-terminates within it); `fmt` and `ap` match, as
    // this function's contract says.
    let n = unsafe { vsnprintf(buf.as_mut_ptr(), buf.len() as _, fmt, ap) };
    if n < 0 {
        // SAFETY: `fmt` is a non-null NUL-terminated string (contract).
        return unsafe { CStr::from_ptr(fmt) }
            .to_string_lossy()
            .into_owned();
    }
    // SAFETY: vsnprintf succeeded, so `buf` holds a NUL-terminated string.
    unsafe { CStr::from_ptr(buf.as_ptr()) }
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
    // SAFETY: ODE calls its message handlers with a printf format and the
    // matching argument list.
    let text = unsafe { format_message(fmt, ap) };
    record(format!("ODE message {num}: {text}"));
}

unsafe extern "C" fn on_error(num: c_int, fmt: *const c_char, ap: *mut __va_list_tag) {
    // SAFETY: as in on_message.
    let text = unsafe { format_message(fmt, ap) };
    // ODE ends the process when this returns: the parent reads this line.
    eprintln!("ODE error {num}: {text}");
    record(format!("ODE error {num}: {text}"));
}

unsafe extern "C" fn on_debug(num: c_int, fmt: *const c_char, ap: *mut __va_list_tag) {
    // SAFETY: as in on_message.
    let text = unsafe { format_message(fmt, ap) };
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

/// The surface of one geom, as contacts see it.
#[derive(Debug, Clone, Copy)]
struct GeomSurface {
    /// Owner slot: 0 ground, 1.. robot bodies, then objects.
    slot: usize,
    /// Coulomb friction coefficient.
    mu: f64,
    /// Coefficient of restitution; negative when none is set.
    restitution: f64,
}

/// What the collision callback needs; lives in a Box so its address is
/// stable while ODE calls back.
struct CollideContext {
    world: dWorldID,
    group: dJointGroupID,
    /// Every geom's surface, indexed by the geom's user data minus 1.
    geoms: Vec<GeomSurface>,
    /// Whether two owner slots may touch, `slots x slots`.
    may_touch: Vec<bool>,
    /// Soft ERP and the CFM of one contact point per pair of owner slots,
    /// `slots x slots` (the `[contact]` parameters); empty when not set.
    soft: Vec<(f64, f64)>,
    /// Approach speed below which restitution is not applied, m/s.
    bounce_velocity_m_s: f64,
    slots: usize,
    buffer: Vec<dContact>,
    contacts: usize,
    /// Owner slots of the pairs that touched in the last step.
    pairs: Vec<(usize, usize)>,
}

impl CollideContext {
    /// The surface parameters of the `n` contact points between two geoms.
    fn surface(&self, a: &GeomSurface, b: &GeomSurface, n: usize) -> dSurfaceParameters {
        let mut surface = dSurfaceParameters {
            mode: dContactApprox1 as c_int,
            mu: a.mu.min(b.mu),
            ..Default::default()
        };
        let restitution = a.restitution.max(b.restitution);
        if restitution >= 0.0 {
            surface.mode |= dContactBounce as c_int;
            surface.bounce = restitution;
            surface.bounce_vel = self.bounce_velocity_m_s;
        }
        if let Some(&(erp, cfm)) = self.soft.get(a.slot * self.slots + b.slot) {
            surface.mode |= (dContactSoftERP | dContactSoftCFM) as c_int;
            surface.soft_erp = erp;
            surface.soft_cfm = cfm * n as f64;
        }
        surface
    }
}

/// A collision callback that does nothing: `dSpaceCollide` with it only
/// brings the space's bounding boxes up to date (see
/// [`OdeWorld::restore_move_order`]).
unsafe extern "C" fn no_contacts(_data: *mut c_void, _o1: dGeomID, _o2: dGeomID) {}

unsafe extern "C" fn near_callback(data: *mut c_void, o1: dGeomID, o2: dGeomID) {
    // SAFETY: `data` is the CollideContext passed to dSpaceCollide by
    // OdeWorld::step, alive and exclusively ours for the call.
    let ctx = unsafe { &mut *(data as *mut CollideContext) };
    // SAFETY: o1 and o2 are live geoms of the space being collided.
    let index = |g: dGeomID| (unsafe { dGeomGetData(g) } as usize).wrapping_sub(1);
    let (i1, i2) = (index(o1), index(o2));
    let (Some(&g1), Some(&g2)) = (ctx.geoms.get(i1), ctx.geoms.get(i2)) else {
        return;
    };
    let (s1, s2) = (g1.slot, g2.slot);
    if !ctx.may_touch[s1 * ctx.slots + s2] {
        return;
    }
    // SAFETY: o1 and o2 are live geoms of the space being collided.
    let (b1, b2) = unsafe { (dGeomGetBody(o1), dGeomGetBody(o2)) };
    if b1.is_null() && b2.is_null() {
        return;
    }
    let max = ctx.buffer.len() as c_int;
    let stride = std::mem::size_of::<dContact>() as c_int;
    let Some(first) = ctx.buffer.first_mut() else {
        return;
    };
    // SAFETY: the buffer holds `max` contacts `stride` bytes apart, and
    // dCollide writes at most `max` of them.
    let n = unsafe { dCollide(o1, o2, max, &mut first.geom, stride) };
    let surface = ctx.surface(&g1, &g2, n.max(0) as usize);
    for c in ctx.buffer.iter_mut().take(n.max(0) as usize) {
        c.surface = surface;
        // SAFETY: world and contact group are this world's, alive during
        // the step; b1 and b2 are the geoms' bodies (or null: the world).
        unsafe {
            let joint = dJointCreateContact(ctx.world, ctx.group, c);
            dJointAttach(joint, b1, b2);
        }
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

/// Gives body `id` (live) this mass (kg) and inertia (kg m^2, about its
/// centre, body axes); ODE's own check (`dMassCheck`) decides whether it is
/// usable.
fn set_mass(id: dBodyID, mass_kg: f64, i: &[f64; 9]) -> Result<(), String> {
    let mut m = dMass::default();
    // SAFETY: `m` is a local dMass that ODE fills and checks.
    let ok = unsafe {
        dMassSetParameters(
            &mut m, mass_kg, 0.0, 0.0, 0.0, i[0], i[4], i[8], i[1], i[2], i[5],
        );
        dMassCheck(&m) != 0
    };
    if !ok {
        let said = take_messages().join("; ");
        return Err(format!(
            "ODE rejects the mass {mass_kg} kg with inertia {i:?} kg m^2: {said}"
        ));
    }
    // SAFETY: `id` is a live body (caller); ODE copies the mass.
    unsafe { dBodySetMass(id, &m) };
    Ok(())
}

/// Puts static geom `geom` at `pose` in the world.
fn place_geom(geom: dGeomID, pose: &Pose) {
    let p = pose.position_m;
    // SAFETY: `geom` is a live geom without a body; ODE copies the numbers.
    unsafe {
        dGeomSetPosition(geom, p.x, p.y, p.z);
        dGeomSetQuaternion(geom, quat(pose.orientation).as_ptr());
    }
}

/// Attaches `geom` to body `id` at `offset` from the body frame.
fn attach_geom(geom: dGeomID, id: dBodyID, offset: &Pose) {
    let p = offset.position_m;
    // SAFETY: `geom` and `id` are live and of the same world; ODE copies
    // the numbers.
    unsafe {
        dGeomSetBody(geom, id);
        dGeomSetOffsetPosition(geom, p.x, p.y, p.z);
        dGeomSetOffsetQuaternion(geom, quat(offset.orientation).as_ptr());
    }
}

/// Which owner slots may touch (`slots x slots`, slot 0 the ground, then
/// the robot bodies, then the objects): not the ground with itself, not a
/// robot body with itself, nor with any other unless `self_collision`,
/// never a body with the one it hinges or is welded on, never the ground
/// with the base or what is welded to it (held at its pose: the floor
/// cannot push it).
fn contact_mask(plan: &ModelPlan, self_collision: bool) -> Vec<bool> {
    let robot_slots = plan.bodies.len();
    let slots = 1 + robot_slots + plan.objects.len();
    let mut may_touch = vec![true; slots * slots];
    let mut forbid = |a: usize, b: usize| {
        may_touch[a * slots + b] = false;
        may_touch[b * slots + a] = false;
    };
    forbid(0, 0);
    for a in 0..robot_slots {
        for b in 0..robot_slots {
            if a == b || !self_collision {
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
    let mut anchored = vec![false; robot_slots];
    anchored[0] = true;
    for &(child, parent) in &plan.welds {
        anchored[child] = anchored[child] || anchored[parent];
    }
    for (b, _) in anchored.iter().enumerate().filter(|(_, &a)| a) {
        forbid(0, 1 + b);
    }
    may_touch
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
    /// The passive rows of hinges with armature: (angular motor, hinge
    /// index, factor): each step the motor's target velocity is the factor
    /// times the hinge rate at the step start (see
    /// [`crate::plan::HingePlan::passive_row`]).
    inertial_motors: Vec<(dJointID, usize, f64)>,
    /// Every moving body: the robot's (plan order, static ones left out),
    /// then the objects'. The native state lists bodies in this order.
    moving: Vec<dBodyID>,
    /// The index in `moving` of each owner slot's body (none for the
    /// ground and a static base).
    moving_of_slot: Vec<Option<usize>>,
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

/// The 3 numbers at `p`.
///
/// # Safety
/// `p` points to at least 3 readable `dReal`s (ODE's pointers to a live
/// body's position and velocities are).
unsafe fn vec3(p: *const dReal) -> Vec3 {
    // SAFETY: the caller's promise.
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
        let mut w = Self::empty(plan, settings);
        w.configure(plan, settings);
        if let Some((height, mu)) = plan.ground {
            w.add_ground(height, mu, settings.self_collision);
        }
        for (b, pose) in body_poses.iter().enumerate().take(plan.bodies.len()) {
            w.add_robot_body(plan, b, pose, settings.self_collision)?;
        }
        w.hold_base_and_welds(plan);
        for (h, frame) in plan.hinges.iter().zip(joint_frames) {
            w.add_hinge(h, frame, settings);
        }
        for (i, o) in plan.objects.iter().enumerate() {
            w.add_object(plan, i, o, settings.self_collision)?;
        }
        w.ctx.slots = 1 + plan.bodies.len() + plan.objects.len();
        w.ctx.may_touch = contact_mask(plan, settings.self_collision);
        w.index_moving_bodies(plan);
        if let Some(softness) = plan.contact_softness {
            w.ctx.soft = w.soft_contact_table(plan, &softness, settings);
        }
        Ok(w)
    }

    /// A world, a space and a contact group with nothing in them.
    fn empty(plan: &ModelPlan, settings: &OdeSettings) -> OdeWorld {
        // SAFETY: ODE is initialised and the lock is held (build's caller);
        // these create new objects and return their handles.
        let (world, space, contact_group) = unsafe {
            (
                dWorldCreate(),
                dHashSpaceCreate(std::ptr::null_mut()),
                dJointGroupCreate(0),
            )
        };
        let ctx = Box::new(CollideContext {
            world,
            group: contact_group,
            geoms: Vec::new(),
            may_touch: Vec::new(),
            slots: 0,
            soft: Vec::new(),
            bounce_velocity_m_s: settings.contact_bounce_velocity_m_s,
            buffer: vec![dContact::default(); settings.max_contacts],
            contacts: 0,
            pairs: Vec::new(),
        });
        OdeWorld {
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
            inertial_motors: Vec::new(),
            moving: Vec::new(),
            moving_of_slot: Vec::new(),
            trimeshes: Vec::new(),
            ctx,
            stepper: settings.stepper,
            timestep_s: settings.timestep_s,
            rng_seed: 0,
        }
    }

    /// The world's gravity (the scene's), ERP, CFM, solver and contact
    /// settings; bodies never fall asleep.
    fn configure(&mut self, plan: &ModelPlan, settings: &OdeSettings) {
        let (world, g) = (self.world, plan.gravity_m_s2);
        // SAFETY: `world` is this world's; setters copy plain numbers.
        unsafe {
            dWorldSetGravity(world, g.x, g.y, g.z);
            dWorldSetERP(world, settings.erp);
            dWorldSetCFM(world, settings.cfm);
            dWorldSetQuickStepNumIterations(world, settings.quick_step_iterations as c_int);
            dWorldSetQuickStepW(world, settings.quick_step_sor);
            dWorldSetContactMaxCorrectingVel(world, settings.contact_max_correcting_vel_m_s);
            dWorldSetContactSurfaceLayer(world, settings.contact_surface_layer_m);
            dWorldSetAutoDisableFlag(world, 0);
        }
    }

    /// The ground plane at `height` m with friction `mu`.
    fn add_ground(&mut self, height: f64, mu: f64, self_collision: bool) {
        // SAFETY: the space is this world's; the plane is placed in it.
        let geom = unsafe { dCreatePlane(self.space, 0.0, 0.0, 1.0, height) };
        let surface = GeomSurface {
            slot: 0,
            mu,
            restitution: -1.0,
        };
        self.register_geom(geom, surface, Owner::Ground, self_collision);
    }

    /// Robot body `b` of the plan at `pose` (its centre of mass), with its
    /// shapes; a static body only places its shapes.
    fn add_robot_body(
        &mut self,
        plan: &ModelPlan,
        b: usize,
        pose: &Pose,
        self_collision: bool,
    ) -> Result<(), String> {
        let body = &plan.bodies[b];
        let id = if body.is_static {
            std::ptr::null_mut()
        } else {
            let Some(m) = body.mass else {
                return Err(format!(
                    "the body of link {} has no mass and cannot move",
                    body.name
                ));
            };
            let id = self
                .new_body(m.mass_kg, &m.inertia, pose)
                .map_err(|e| format!("the body of link {}: {e}", body.name))?;
            id
        };
        self.robot_bodies.push(id);
        for g in &body.geoms {
            let geom = self.create_geom(&g.shape);
            if id.is_null() {
                place_geom(geom, &pose.compose(&g.offset));
            } else {
                attach_geom(geom, id, &g.offset);
            }
            let surface = GeomSurface {
                slot: 1 + b,
                mu: plan.robot_mu,
                restitution: -1.0,
            };
            self.register_geom(geom, surface, Owner::Robot(b), self_collision);
        }
        Ok(())
    }

    /// A body with this mass (kg) and inertia (kg m^2, about its centre,
    /// body axes) at `pose`, at rest.
    fn new_body(
        &mut self,
        mass_kg: f64,
        inertia: &[f64; 9],
        pose: &Pose,
    ) -> Result<dBodyID, String> {
        // SAFETY: the world is this world's; the new body belongs to it
        // and is destroyed with it.
        let id = unsafe { dBodyCreate(self.world) };
        set_mass(id, mass_kg, inertia)?;
        Self::set_body_state(id, pose, Vec3::ZERO, Vec3::ZERO);
        Ok(id)
    }

    /// The base held to the world by a fixed joint (unless it is static),
    /// and the bodies of `weld = "fixed_joint"` held to their parents.
    fn hold_base_and_welds(&mut self, plan: &ModelPlan) {
        let base = self.robot_bodies[0];
        let mut pairs = plan
            .welds
            .iter()
            .map(|&(child, parent)| (self.robot_bodies[child], self.robot_bodies[parent]))
            .collect::<Vec<_>>();
        if !base.is_null() {
            pairs.insert(0, (base, std::ptr::null_mut()));
        }
        for (a, b) in pairs {
            // SAFETY: the world and the bodies (or null: the world frame)
            // are this world's; the joint fixes their current relative pose.
            unsafe {
                let fixed = dJointCreateFixed(self.world, std::ptr::null_mut());
                dJointAttach(fixed, a, b);
                dJointSetFixed(fixed);
            }
        }
    }

    /// The hinge of a controlled joint with its stops and motor, and its
    /// friction and passive (damping, armature) rows; `frame` is the world
    /// pose of the joint's child link frame and the unit axis in it.
    fn add_hinge(
        &mut self,
        h: &crate::plan::HingePlan,
        frame: &(Pose, Vec3),
        settings: &OdeSettings,
    ) {
        let (child, parent) = (
            self.robot_bodies[h.child_body],
            self.robot_bodies[h.parent_body],
        );
        let (at, a) = (frame.0.position_m, frame.0.orientation.rotate(frame.1));
        // SAFETY: the world and bodies are this world's; the hinge joins
        // them; the setters copy plain numbers.
        let joint = unsafe {
            let joint = dJointCreateHinge(self.world, std::ptr::null_mut());
            dJointAttach(joint, child, parent);
            dJointSetHingeAnchor(joint, at.x, at.y, at.z);
            dJointSetHingeAxis(joint, a.x, a.y, a.z);
            joint
        };
        let set = |param: u32, value: f64| {
            // SAFETY: `joint` is the hinge just made, of this world.
            unsafe { dJointSetHingeParam(joint, param as c_int, value) }
        };
        if let Some(lo) = h.stops_rad.0 {
            set(dParamLoStop, lo);
        }
        if let Some(hi) = h.stops_rad.1 {
            set(dParamHiStop, hi);
        }
        set(dParamVel, 0.0);
        set(dParamFMax, h.force_limit_nm);
        if settings.servo == crate::settings::Servo::Kv {
            // torque = kv (v_target - v_next): the motor row's CFM is the
            // inverse of the damper gain (see the README).
            if h.kv > 0.0 {
                set(dParamCFM, 1.0 / h.kv);
            } else {
                set(dParamFMax, 0.0);
            }
        }
        if h.friction_nm > 0.0 {
            // Coulomb joint friction: a second motor holding zero velocity
            // with at most the friction torque.
            self.axis_motor(h, a, 0.0, h.friction_nm, None);
        }
        if let Some((gain, inertial)) = h.passive_row(settings.timestep_s) {
            // Damping and armature: one unbounded, softened motor row (see
            // HingePlan::passive_row).
            let motor = self.axis_motor(h, a, 0.0, f64::INFINITY, Some(1.0 / gain));
            if inertial > 0.0 {
                self.inertial_motors
                    .push((motor, self.hinges.len(), inertial / gain));
            }
        }
        self.hinges.push(joint);
    }

    /// Scene object `i` (a box) at its pose, at rest.
    fn add_object(
        &mut self,
        plan: &ModelPlan,
        i: usize,
        o: &crate::plan::ObjectPlan,
        self_collision: bool,
    ) -> Result<(), String> {
        let id = self
            .new_body(o.mass.mass_kg, &o.mass.inertia, &o.pose)
            .map_err(|e| format!("object \"{}\": {e}", o.name))?;
        // SAFETY: the space and the body are this world's.
        let geom = unsafe {
            let geom = dCreateBox(self.space, o.size_m.x, o.size_m.y, o.size_m.z);
            dGeomSetBody(geom, id);
            geom
        };
        let surface = GeomSurface {
            slot: 1 + plan.bodies.len() + i,
            mu: o.mu,
            restitution: o.restitution.unwrap_or(-1.0),
        };
        self.register_geom(geom, surface, Owner::Object(i), self_collision);
        self.object_bodies.push(id);
        Ok(())
    }

    /// A one-axis angular motor (`dAMotorUser`) on hinge `h`'s bodies about
    /// its world axis `axis`, the axis fixed in the child body (so it turns
    /// with the joint), with target velocity `vel` (rad/s), torque bound
    /// `fmax` (N m) and, when given, its own CFM.
    fn axis_motor(
        &self,
        h: &crate::plan::HingePlan,
        axis: Vec3,
        vel: f64,
        fmax: f64,
        cfm: Option<f64>,
    ) -> dJointID {
        let (child, parent) = (
            self.robot_bodies[h.child_body],
            self.robot_bodies[h.parent_body],
        );
        // SAFETY: the world and both bodies (or null for the world) are
        // this world's, alive; the motor joins them like the hinge does;
        // the setters copy plain numbers.
        unsafe {
            let motor = dJointCreateAMotor(self.world, std::ptr::null_mut());
            dJointAttach(motor, child, parent);
            dJointSetAMotorMode(motor, dAMotorUser as c_int);
            dJointSetAMotorNumAxes(motor, 1);
            // rel = 1: the axis is anchored to the first (child) body.
            dJointSetAMotorAxis(motor, 0, 1, axis.x, axis.y, axis.z);
            dJointSetAMotorParam(motor, dParamVel as c_int, vel);
            dJointSetAMotorParam(motor, dParamFMax as c_int, fmax);
            if let Some(cfm) = cfm {
                dJointSetAMotorParam(motor, dParamCFM as c_int, cfm);
            }
            motor
        }
    }

    /// Fills `moving` (the robot's moving bodies, then the objects') and
    /// which owner slot each belongs to.
    fn index_moving_bodies(&mut self, plan: &ModelPlan) {
        let slots = 1 + self.robot_bodies.len() + plan.objects.len();
        self.moving_of_slot = vec![None; slots];
        for (b, &id) in self.robot_bodies.iter().enumerate() {
            if !id.is_null() {
                self.moving_of_slot[1 + b] = Some(self.moving.len());
                self.moving.push(id);
            }
        }
        for (i, &id) in self.object_bodies.iter().enumerate() {
            self.moving_of_slot[1 + self.robot_bodies.len() + i] = Some(self.moving.len());
            self.moving.push(id);
        }
    }

    /// Soft ERP and one contact point's CFM for every pair of owner slots
    /// (see [`crate::plan::ContactSoftness::erp_cfm`]), from the pair's
    /// reduced mass: `1 / (1 / m1 + 1 / m2)`, the ground and a static
    /// base counting as immovable. Pairs of two immovable owners get the
    /// world's ERP and CFM (they never touch).
    fn soft_contact_table(
        &self,
        plan: &ModelPlan,
        softness: &crate::plan::ContactSoftness,
        settings: &OdeSettings,
    ) -> Vec<(f64, f64)> {
        let h_s = settings.timestep_s;
        let mut inverse_mass = vec![0.0; self.moving_of_slot.len()];
        for (b, body) in plan.bodies.iter().enumerate() {
            if let (false, Some(m)) = (self.robot_bodies[b].is_null(), body.mass) {
                inverse_mass[1 + b] = 1.0 / m.mass_kg;
            }
        }
        for (i, o) in plan.objects.iter().enumerate() {
            inverse_mass[1 + plan.bodies.len() + i] = 1.0 / o.mass.mass_kg;
        }
        let n = inverse_mass.len();
        let mut table = Vec::with_capacity(n * n);
        for a in 0..n {
            for b in 0..n {
                let pair = softness.erp_cfm(h_s, inverse_mass[a] + inverse_mass[b]);
                table.push(pair.unwrap_or((settings.erp, settings.cfm)));
            }
        }
        table
    }

    /// A shape of the plan in this world's space (not yet on a body).
    /// Called while building, with the lock held.
    fn create_geom(&mut self, shape: &ShapePlan) -> dGeomID {
        let space = self.space;
        match shape {
            // SAFETY: `space` is this world's space; the new geom is
            // placed in it and destroyed with it (the same below).
            ShapePlan::Box(s) => unsafe { dCreateBox(space, s.x, s.y, s.z) },
            // SAFETY: as above.
            ShapePlan::Sphere(r) => unsafe { dCreateSphere(space, *r) },
            // SAFETY: as above.
            ShapePlan::Cylinder(r, l) => unsafe { dCreateCylinder(space, *r, *l) },
            // SAFETY: as above.
            ShapePlan::Capsule(r, l) => unsafe { dCreateCapsule(space, *r, *l) },
            ShapePlan::Mesh(m) => {
                let vertices = m.vertices.clone();
                let indices = m.indices.clone();
                // SAFETY: ODE keeps pointers to `vertices` and `indices`,
                // whose heap buffers live (unmoved) in `self.trimeshes`
                // until the world is dropped, after the space; the counts
                // and strides describe them (3 f64 per vertex, 3 u32 per
                // triangle, sizes checked in plan::mesh_plan).
                let (data, geom) = unsafe {
                    let data = dGeomTriMeshDataCreate();
                    dGeomTriMeshDataBuildDouble(
                        data,
                        vertices.as_ptr() as *const c_void,
                        (3 * std::mem::size_of::<f64>()) as c_int,
                        (vertices.len() / 3) as c_int,
                        indices.as_ptr() as *const c_void,
                        indices.len() as c_int,
                        (3 * std::mem::size_of::<u32>()) as c_int,
                    );
                    (data, dCreateTriMesh(space, data, None, None, None))
                };
                self.trimeshes.push(TriMeshStore {
                    data,
                    _vertices: vertices,
                    _indices: indices,
                });
                geom
            }
        }
    }

    /// Records `geom`'s surface for the collision callback (its user data
    /// is its index + 1) and sets its collision categories.
    fn register_geom(
        &mut self,
        geom: dGeomID,
        surface: GeomSurface,
        owner: Owner,
        self_collision: bool,
    ) {
        self.ctx.geoms.push(surface);
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
        // SAFETY: `geom` is a live geom of this world's space; the user
        // data is a number, never dereferenced.
        unsafe {
            dGeomSetData(geom, self.ctx.geoms.len() as *mut c_void);
            dGeomSetCategoryBits(geom, category);
            dGeomSetCollideBits(geom, collide);
        }
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

    /// Sets hinge `i`'s motor: target velocity (rad/s), largest torque
    /// (N m; 0 switches it off) and, when given, its constraint force
    /// mixing (`Some(1/kv)`: the implicit damper `kv (v_target - v_next)`).
    pub fn set_hinge_motor(&mut self, i: usize, rad_s: f64, fmax_nm: f64, cfm: Option<f64>) {
        let joint = self.hinges[i];
        // SAFETY: the hinge belongs to this world; setting its parameters
        // touches only that joint.
        unsafe {
            dJointSetHingeParam(joint, dParamVel as c_int, rad_s);
            dJointSetHingeParam(joint, dParamFMax as c_int, fmax_nm);
            if let Some(cfm) = cfm {
                dJointSetHingeParam(joint, dParamCFM as c_int, cfm);
            }
        }
    }

    /// Hinge `i`'s motor's constraint force mixing and largest torque.
    pub fn hinge_motor(&self, i: usize) -> (f64, f64) {
        // SAFETY: reads parameters of this world's hinge.
        unsafe {
            (
                dJointGetHingeParam(self.hinges[i], dParamCFM as c_int),
                dJointGetHingeParam(self.hinges[i], dParamFMax as c_int),
            )
        }
    }

    /// Adds a torque about hinge `i`'s axis, N m (on the child body, and
    /// the opposite on the parent), for the next step only.
    pub fn add_hinge_torque(&mut self, i: usize, nm: f64) {
        // SAFETY: the hinge belongs to this world; ODE adds the torque to
        // its two bodies' accumulators.
        unsafe { dJointAddHingeTorque(self.hinges[i], nm) };
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

    /// One step: the armature rows' reference velocities, collision, the
    /// solver (with this world's random-generator state), contacts removed.
    /// `false` when ODE's stepper reports a failure (out of memory). Must
    /// be called with [`ode_lock`] held.
    pub fn step(&mut self) -> bool {
        for &(motor, hinge, factor) in &self.inertial_motors {
            let rate = self.hinge_rate(hinge);
            // SAFETY: the motor is a joint of this world; setting its
            // parameter touches only that joint.
            unsafe { dJointSetAMotorParam(motor, dParamVel as c_int, factor * rate) };
        }
        // SAFETY: lock held (caller); the context is boxed, alive and not
        // otherwise borrowed during dSpaceCollide.
        unsafe {
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
        self.set_robot_body_state(b, pose, Vec3::ZERO, Vec3::ZERO);
    }

    /// Puts robot body `b` at `pose` (its centre of mass) moving with `v`
    /// (m/s, of the centre of mass) and `w` (rad/s), world frame (static
    /// bodies stay).
    pub fn set_robot_body_state(&mut self, b: usize, pose: &Pose, v: Vec3, w: Vec3) {
        let id = self.robot_bodies[b];
        if !id.is_null() {
            Self::set_body_state(id, pose, v, w);
        }
    }

    /// Puts object `i` at `pose` (its centre) moving with `v` (m/s) and `w`
    /// (rad/s), world frame.
    pub fn set_object_state(&mut self, i: usize, pose: &Pose, v: Vec3, w: Vec3) {
        Self::set_body_state(self.object_bodies[i], pose, v, w);
    }

    fn set_body_state(id: dBodyID, pose: &Pose, v: Vec3, w: Vec3) {
        let p = pose.position_m;
        // SAFETY: `id` is a live body of this world; the quaternion array
        // outlives the call, which copies it.
        unsafe {
            dBodySetPosition(id, p.x, p.y, p.z);
            dBodySetQuaternion(id, quat(pose.orientation).as_ptr());
            dBodySetLinearVel(id, v.x, v.y, v.z);
            dBodySetAngularVel(id, w.x, w.y, w.z);
        }
    }

    fn body_velocity_of(id: dBodyID) -> (Vec3, Vec3) {
        // SAFETY: `id` is a live body of this world.
        unsafe { (vec3(dBodyGetLinearVel(id)), vec3(dBodyGetAngularVel(id))) }
    }

    /// Object `i`'s velocity (of its centre, m/s) and angular velocity
    /// (rad/s), world frame.
    pub fn object_velocity(&self, i: usize) -> (Vec3, Vec3) {
        Self::body_velocity_of(self.object_bodies[i])
    }

    /// Hinge `i`'s rate (child relative to parent about the axis), rad/s.
    pub fn hinge_rate(&self, i: usize) -> f64 {
        // SAFETY: reads the joint's bodies of this world.
        unsafe { dJointGetHingeAngleRate(self.hinges[i]) }
    }

    /// Hinge `i`'s motor target velocity, rad/s.
    pub fn hinge_velocity_target(&self, i: usize) -> f64 {
        // SAFETY: reads a parameter of a joint of this world.
        unsafe { dJointGetHingeParam(self.hinges[i], dParamVel as c_int) }
    }

    /// Number of moving bodies (robot bodies that are not static, then
    /// objects): the bodies of the native state.
    pub fn moving_count(&self) -> usize {
        self.moving.len()
    }

    /// Appends every moving body's state, [`BODY_STATE_LEN`] numbers each:
    /// position (m), quaternion (w x y z), linear velocity (m/s), angular
    /// velocity (rad/s), world frame, exactly as ODE holds them.
    pub fn write_moving_states(&self, out: &mut Vec<f64>) {
        for &id in &self.moving {
            let pose = Self::body_pose_of(id);
            let (v, w) = Self::body_velocity_of(id);
            let q = pose.orientation;
            out.extend_from_slice(&pose.position_m.to_array());
            out.extend_from_slice(&[q.w, q.x, q.y, q.z]);
            out.extend_from_slice(&v.to_array());
            out.extend_from_slice(&w.to_array());
        }
    }

    /// Sets every moving body from numbers written by
    /// [`OdeWorld::write_moving_states`] (`data.len()` must be
    /// `BODY_STATE_LEN * moving_count()`).
    pub fn read_moving_states(&mut self, data: &[f64]) {
        for (&id, b) in self.moving.iter().zip(data.chunks_exact(BODY_STATE_LEN)) {
            let v3 = |k: usize| Vec3::new(b[k], b[k + 1], b[k + 2]);
            let pose = Pose::new(v3(0), Quat::new(b[3], b[4], b[5], b[6]));
            Self::set_body_state(id, &pose, v3(7), v3(10));
            Self::set_quaternion_exactly(id, [b[3], b[4], b[5], b[6]]);
        }
    }

    /// Gives body `id` exactly the quaternion `q` (w x y z), which ODE
    /// held before: `dBodySetQuaternion` normalises what it is given, and
    /// normalising a unit quaternion again may change its last bits. So
    /// the input is corrected by what ODE changed (a few tries), then
    /// scaled copies of `q` are tried (normalised, they differ from `q`
    /// only in rounding) until ODE keeps `q`; if none does (not seen in the
    /// tests), `q` as ODE normalises it.
    fn set_quaternion_exactly(id: dBodyID, q: [f64; 4]) {
        let try_input = |input: &[f64; 4]| {
            // SAFETY: `id` is a live body of this world; ODE copies the 4
            // numbers in and returns a pointer to its own 4.
            unsafe {
                dBodySetQuaternion(id, input.as_ptr());
                let p = dBodyGetQuaternion(id);
                [*p, *p.add(1), *p.add(2), *p.add(3)]
            }
        };
        let mut input = q;
        for _ in 0..4 {
            let got = try_input(&input);
            if got == q {
                return;
            }
            for k in 0..4 {
                input[k] += q[k] - got[k];
            }
        }
        // Scaled copies of q normalise to q up to rounding, which differs
        // from one scale to the next: try scales until one rounds to q.
        for j in 1..=1000 {
            let scale = 1.0 + f64::from(j) * if j % 2 == 0 { 1e-12 } else { -1e-12 };
            if try_input(&q.map(|x| x * scale)) == q {
                return;
            }
        }
        try_input(&q);
    }

    /// This world's state of ODE's random generator (what
    /// `dWorldQuickStep` draws from next).
    pub fn rng_seed(&self) -> u64 {
        // c_ulong is u64 here, u32 on some platforms.
        #[allow(clippy::useless_conversion)]
        u64::from(self.rng_seed)
    }

    /// Sets this world's random-generator state.
    pub fn set_rng_seed(&mut self, seed: u64) {
        self.rng_seed = seed as std::ffi::c_ulong;
    }

    /// The moving bodies (indices as in [`OdeWorld::write_moving_states`])
    /// in the order ODE last moved them, first moved first. ODE keeps the
    /// shapes of a space in a list and puts a moved shape at its front;
    /// the list's order is the order in which collision detection visits
    /// pairs, which orders the contacts and so the solver's rows. A step
    /// moves the bodies in its own order, which a restore must repeat to
    /// continue identically ([`OdeWorld::restore_move_order`]).
    pub fn move_order(&self) -> Vec<usize> {
        let mut seen = vec![false; self.moving.len()];
        let mut order = Vec::with_capacity(self.moving.len());
        // SAFETY: reads this world's space and its geoms (dSpaceGetGeom
        // walks the space's list; nothing is changed but its cursor).
        let count = unsafe { dSpaceGetNumGeoms(self.space) };
        for i in 0..count {
            // SAFETY: as above; `i` is below the number of geoms.
            let data = unsafe { dGeomGetData(dSpaceGetGeom(self.space, i)) } as usize;
            let slot = self.ctx.geoms.get(data.wrapping_sub(1)).map(|g| g.slot);
            if let Some(m) = slot.and_then(|s| self.moving_of_slot[s]) {
                if !seen[m] {
                    seen[m] = true;
                    order.push(m);
                }
            }
        }
        order.reverse();
        order
    }

    /// Moves the bodies in `order` (from [`OdeWorld::move_order`]) where
    /// they are, so that the space's list is as it was when the order was
    /// read: first brings every bounding box up to date (a collision pass
    /// without contacts), then touches each body's position, which moves
    /// its shapes to the list's front as a step does. Must be called with
    /// [`ode_lock`] held.
    pub fn restore_move_order(&mut self, order: &[usize]) {
        // SAFETY: lock held (caller); the callback ignores its arguments.
        unsafe { dSpaceCollide(self.space, std::ptr::null_mut(), Some(no_contacts)) };
        for &m in order {
            let Some(&id) = self.moving.get(m) else {
                continue;
            };
            let p = Self::body_pose_of(id).position_m;
            // SAFETY: `id` is a live body of this world; the position is
            // its own (only its shapes are marked as moved).
            unsafe { dBodySetPosition(id, p.x, p.y, p.z) };
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
