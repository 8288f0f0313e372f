//! The parts of Bullet's C API (PyBullet's `PhysicsClientC_API.h`) this
//! engine uses: the bindings of `rubullet-sys`, the constants that crate
//! does not export (copied from `SharedMemoryPublic.h` of the Bullet 3.08
//! sources it bundles), the logging hooks of `b3Logging.h`, and a client
//! handle whose calls are serialized by a process-wide lock.

use std::ffi::{c_char, c_int};
use std::marker::PhantomData;

use parking_lot::{ReentrantMutex, ReentrantMutexGuard};

pub(crate) use rubullet_sys::{
    b3ChangeDynamicsInfoSetAngularDamping, b3ChangeDynamicsInfoSetContactStiffnessAndDamping,
    b3ChangeDynamicsInfoSetJointDamping, b3ChangeDynamicsInfoSetLateralFriction,
    b3ChangeDynamicsInfoSetLinearDamping, b3ChangeDynamicsInfoSetLocalInertiaDiagonal,
    b3ChangeDynamicsInfoSetMass, b3ChangeDynamicsInfoSetRestitution, b3ConnectPhysicsDirect,
    b3ContactInformation, b3CreateCollisionShapeAddBox, b3CreateCollisionShapeAddPlane,
    b3CreateCollisionShapeCommandInit, b3CreateMultiBodyBase, b3CreateMultiBodyCommandInit,
    b3CreatePoseCommandInit, b3CreatePoseCommandSetBaseAngularVelocity,
    b3CreatePoseCommandSetBaseLinearVelocity, b3CreatePoseCommandSetBaseOrientation,
    b3CreatePoseCommandSetBasePosition, b3CreatePoseCommandSetJointPosition,
    b3CreatePoseCommandSetJointVelocity, b3DisconnectSharedMemory, b3DynamicsInfo,
    b3GetContactPointInformation, b3GetDynamicsInfo, b3GetDynamicsInfoCommandInit, b3GetJointInfo,
    b3GetLinkState, b3GetNumJoints, b3GetStatusAABB, b3GetStatusActualState, b3GetStatusBodyIndex,
    b3GetStatusCollisionShapeUniqueId, b3GetStatusPhysicsSimulationParameters, b3GetStatusType,
    b3InitChangeDynamicsInfo, b3InitPhysicsParamCommand, b3InitRequestContactPointInformation,
    b3InitRequestPhysicsParamCommand, b3InitStepSimulationCommand, b3JointControlCommandInit2,
    b3JointControlSetDesiredForceTorque, b3JointControlSetDesiredPosition,
    b3JointControlSetDesiredVelocity, b3JointControlSetKd, b3JointControlSetKp,
    b3JointControlSetMaximumForce, b3JointInfo, b3LinkState, b3LoadStateCommandInit,
    b3LoadStateSetFileName, b3LoadUrdfCommandInit, b3LoadUrdfCommandSetFlags,
    b3LoadUrdfCommandSetStartOrientation, b3LoadUrdfCommandSetStartPosition,
    b3LoadUrdfCommandSetUseFixedBase, b3PhysicsClientHandle,
    b3PhysicsParamSetContactBreakingThreshold, b3PhysicsParamSetDefaultContactERP,
    b3PhysicsParamSetDefaultFrictionERP, b3PhysicsParamSetDefaultGlobalCFM,
    b3PhysicsParamSetDefaultNonContactERP, b3PhysicsParamSetEnableConeFriction,
    b3PhysicsParamSetGravity, b3PhysicsParamSetNumSolverIterations, b3PhysicsParamSetNumSubSteps,
    b3PhysicsParamSetSolverResidualThreshold, b3PhysicsParamSetSplitImpulsePenetrationThreshold,
    b3PhysicsParamSetTimeStep, b3PhysicsParamSetUseSplitImpulse, b3PhysicsSimulationParameters,
    b3RequestActualStateCommandComputeForwardKinematics, b3RequestActualStateCommandInit,
    b3RequestCollisionInfoCommandInit, b3SaveBulletCommandInit, b3SharedMemoryCommandHandle,
    b3SharedMemoryStatusHandle, b3SubmitClientCommandAndWaitStatus, eURDF_Flags,
    EnumSharedMemoryServerStatus as Status,
};

// Server status codes (SharedMemoryPublic.h, enum EnumSharedMemoryServerStatus;
// rubullet-sys declares the enum in the same order, checked by a test).
pub(crate) const CMD_CLIENT_COMMAND_COMPLETED: c_int =
    Status::CMD_CLIENT_COMMAND_COMPLETED as c_int;
pub(crate) const CMD_URDF_LOADING_COMPLETED: c_int = Status::CMD_URDF_LOADING_COMPLETED as c_int;
pub(crate) const CMD_ACTUAL_STATE_UPDATE_COMPLETED: c_int =
    Status::CMD_ACTUAL_STATE_UPDATE_COMPLETED as c_int;
pub(crate) const CMD_DESIRED_STATE_RECEIVED_COMPLETED: c_int =
    Status::CMD_DESIRED_STATE_RECEIVED_COMPLETED as c_int;
pub(crate) const CMD_STEP_FORWARD_SIMULATION_COMPLETED: c_int =
    Status::CMD_STEP_FORWARD_SIMULATION_COMPLETED as c_int;
pub(crate) const CMD_CONTACT_POINT_INFORMATION_COMPLETED: c_int =
    Status::CMD_CONTACT_POINT_INFORMATION_COMPLETED as c_int;
pub(crate) const CMD_REQUEST_COLLISION_INFO_COMPLETED: c_int =
    Status::CMD_REQUEST_COLLISION_INFO_COMPLETED as c_int;
pub(crate) const CMD_GET_DYNAMICS_INFO_COMPLETED: c_int =
    Status::CMD_GET_DYNAMICS_INFO_COMPLETED as c_int;
pub(crate) const CMD_CREATE_COLLISION_SHAPE_COMPLETED: c_int =
    Status::CMD_CREATE_COLLISION_SHAPE_COMPLETED as c_int;
pub(crate) const CMD_CREATE_MULTI_BODY_COMPLETED: c_int =
    Status::CMD_CREATE_MULTI_BODY_COMPLETED as c_int;
pub(crate) const CMD_REQUEST_PHYSICS_SIMULATION_PARAMETERS_COMPLETED: c_int =
    Status::CMD_REQUEST_PHYSICS_SIMULATION_PARAMETERS_COMPLETED as c_int;
pub(crate) const CMD_BULLET_SAVING_COMPLETED: c_int = Status::CMD_BULLET_SAVING_COMPLETED as c_int;
pub(crate) const CMD_RESTORE_STATE_COMPLETED: c_int = Status::CMD_RESTORE_STATE_COMPLETED as c_int;

// Joint control modes (SharedMemoryPublic.h, the anonymous enum after
// `struct b3LinkState`; not exported by rubullet-sys).
/// `CONTROL_MODE_VELOCITY`: a velocity motor (PyBullet's VELOCITY_CONTROL).
pub(crate) const CONTROL_MODE_VELOCITY: c_int = 0;
/// `CONTROL_MODE_TORQUE`: PyBullet's TORQUE_CONTROL (a joint torque for
/// the next step).
pub(crate) const CONTROL_MODE_TORQUE: c_int = 1;
/// `CONTROL_MODE_POSITION_VELOCITY_PD`: PyBullet's POSITION_CONTROL.
pub(crate) const CONTROL_MODE_POSITION_VELOCITY_PD: c_int = 2;
/// `CONTROL_MODE_PD`: PyBullet's PD_CONTROL, the explicit PD law of the
/// pdControl plugin (`kp (q_d - q) + kd (v_d - v)`, clamped to the maximum
/// force, applied before every step).
pub(crate) const CONTROL_MODE_PD: c_int = 3;

// Joint types (SharedMemoryPublic.h, enum JointType; not exported).
/// `eRevoluteType`.
pub(crate) const JOINT_REVOLUTE: c_int = 0;
/// `ePrismaticType`.
pub(crate) const JOINT_PRISMATIC: c_int = 1;

// URDF loading flags (SharedMemoryPublic.h, enum eURDF_Flags).
pub(crate) const URDF_USE_INERTIA_FROM_FILE: c_int =
    eURDF_Flags::URDF_USE_INERTIA_FROM_FILE as c_int;
pub(crate) const URDF_USE_SELF_COLLISION: c_int = eURDF_Flags::URDF_USE_SELF_COLLISION as c_int;
pub(crate) const URDF_USE_SELF_COLLISION_EXCLUDE_PARENT: c_int =
    eURDF_Flags::URDF_USE_SELF_COLLISION_EXCLUDE_PARENT as c_int;
pub(crate) const URDF_USE_IMPLICIT_CYLINDER: c_int =
    eURDF_Flags::URDF_USE_IMPLICIT_CYLINDER as c_int;

/// Bullet's clamp on every generalized velocity of a multibody
/// (`btMultiBody::m_maxCoordinateVelocity`, 100 rad/s or m/s by default):
/// a velocity at this bound means Bullet cut off a blow-up.
pub(crate) const MAX_COORDINATE_VELOCITY: f64 = 100.0;

/// A Bullet logging hook (`b3PrintfFunc`, `b3WarningMessageFunc`,
/// `b3ErrorMessageFunc` of `Bullet3Common/b3Logging.h`).
pub(crate) type MessageFunc = unsafe extern "C" fn(message: *const c_char);

extern "C" {
    // Bullet3Common/b3Logging.h (extern "C"; linked through rubullet-sys's
    // static Bullet3Common library, not declared by rubullet-sys).
    pub(crate) fn b3SetCustomPrintfFunc(func: Option<MessageFunc>);
    pub(crate) fn b3SetCustomWarningMessageFunc(func: Option<MessageFunc>);
    pub(crate) fn b3SetCustomErrorMessageFunc(func: Option<MessageFunc>);
}

/// Every call into Bullet holds this lock. Bullet keeps process-wide state
/// (the logging hooks, the profiler's per-thread tables and counters, the
/// allocator's statistics) that is not meant for concurrent use, so two
/// simulations in two threads take turns; `realitygap run` runs simulations
/// in parallel in separate processes instead. Reentrant
/// (`parking_lot::ReentrantMutex`): a [`Client`] dropped while its owner
/// holds the lock (a load that fails half-way) takes it again.
static BULLET: ReentrantMutex<()> = ReentrantMutex::new(());

/// Proof that this thread holds the process-wide Bullet lock, until dropped.
/// Every function that calls into Bullet takes one (`&BulletLock`), so a
/// call without the lock does not compile. Not `Send`: the lock belongs to
/// the thread that took it.
pub(crate) struct BulletLock {
    _guard: ReentrantMutexGuard<'static, ()>,
}

/// Takes the process-wide Bullet lock (a no-op count if this thread holds
/// it already).
pub(crate) fn lock() -> BulletLock {
    BulletLock {
        _guard: BULLET.lock(),
    }
}

/// A connection to an in-process (DIRECT mode) Bullet physics server.
pub(crate) struct Client {
    handle: b3PhysicsClientHandle,
}

// SAFETY: a DIRECT client owns its physics server; it has no thread
// affinity, and every use needs a `BulletLock` of the thread using it.
unsafe impl Send for Client {}

/// The answer of the server to one command. It borrows the client that
/// gave it and the lock held while it was given, so it cannot outlive
/// either; its status handle is valid until the client's next command.
pub(crate) struct Reply<'c> {
    /// The status handle (valid until the next command is submitted).
    handle: b3SharedMemoryStatusHandle,
    /// Its type, a `CMD_*` status code (-1 when there was no status).
    pub kind: c_int,
    _borrows: PhantomData<(&'c Client, &'c BulletLock)>,
}

impl Reply<'_> {
    /// The status handle, for the C API's status readers.
    pub(crate) fn handle(&self) -> b3SharedMemoryStatusHandle {
        self.handle
    }
}

impl Client {
    /// Starts a DIRECT-mode physics server.
    pub(crate) fn connect(_lock: &BulletLock) -> Option<Client> {
        // SAFETY: plain constructor, called with the Bullet lock held;
        // returns None when it fails.
        let handle = unsafe { b3ConnectPhysicsDirect() }?;
        Some(Client { handle })
    }

    /// The raw handle, for the C API's command builders (which need the
    /// lock as long as the handle is used).
    pub(crate) fn handle(&self, _lock: &BulletLock) -> b3PhysicsClientHandle {
        self.handle
    }

    /// Submits a command built on this client and waits for its status.
    ///
    /// # Safety
    /// `command` must have been created by a `b3*CommandInit` function of
    /// this client and not submitted before.
    pub(crate) unsafe fn submit<'c>(
        &'c self,
        _lock: &'c BulletLock,
        command: b3SharedMemoryCommandHandle,
    ) -> Reply<'c> {
        // SAFETY: `self.handle` is this client's live connection and
        // `command` one of its unsubmitted commands (this fn's contract);
        // the lock is held (`_lock`).
        let handle = unsafe { b3SubmitClientCommandAndWaitStatus(self.handle, command) };
        let kind = if handle.is_null() {
            -1
        } else {
            // SAFETY: a non-null status handle just returned by this client.
            unsafe { b3GetStatusType(handle) }
        };
        Reply {
            handle,
            kind,
            _borrows: PhantomData,
        }
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        let _guard = lock();
        // SAFETY: the handle came from b3ConnectPhysicsDirect and is
        // disconnected exactly once.
        unsafe { b3DisconnectSharedMemory(self.handle) };
    }
}

/// The name of a status code, for error messages.
pub(crate) fn status_name(kind: c_int) -> String {
    let names: &[(c_int, &str)] = &[
        (-1, "no status"),
        (
            Status::CMD_URDF_LOADING_FAILED as c_int,
            "CMD_URDF_LOADING_FAILED",
        ),
        (
            Status::CMD_CREATE_COLLISION_SHAPE_FAILED as c_int,
            "CMD_CREATE_COLLISION_SHAPE_FAILED",
        ),
        (
            Status::CMD_CREATE_MULTI_BODY_FAILED as c_int,
            "CMD_CREATE_MULTI_BODY_FAILED",
        ),
        (
            Status::CMD_ACTUAL_STATE_UPDATE_FAILED as c_int,
            "CMD_ACTUAL_STATE_UPDATE_FAILED",
        ),
        (
            Status::CMD_GET_DYNAMICS_INFO_FAILED as c_int,
            "CMD_GET_DYNAMICS_INFO_FAILED",
        ),
        (
            Status::CMD_UNKNOWN_COMMAND_FLUSHED as c_int,
            "CMD_UNKNOWN_COMMAND_FLUSHED",
        ),
        (Status::CMD_INVALID_STATUS as c_int, "CMD_INVALID_STATUS"),
        (
            Status::CMD_BULLET_SAVING_FAILED as c_int,
            "CMD_BULLET_SAVING_FAILED",
        ),
        (
            Status::CMD_RESTORE_STATE_FAILED as c_int,
            "CMD_RESTORE_STATE_FAILED",
        ),
    ];
    match names.iter().find(|(k, _)| *k == kind) {
        Some((_, name)) => name.to_string(),
        None => format!("status {kind}"),
    }
}

/// A NUL-terminated C string buffer as text (lossy).
pub(crate) fn c_text(buffer: &[c_char]) -> String {
    let bytes: Vec<u8> = buffer
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The status codes rubullet-sys declares are those of the bundled
    /// SharedMemoryPublic.h (counted from CMD_SHARED_MEMORY_NOT_INITIALIZED = 0).
    #[test]
    fn status_codes_match_the_bundled_header() {
        assert_eq!(CMD_CLIENT_COMMAND_COMPLETED, 2);
        assert_eq!(CMD_URDF_LOADING_COMPLETED, 6);
        assert_eq!(CMD_ACTUAL_STATE_UPDATE_COMPLETED, 21);
        assert_eq!(CMD_DESIRED_STATE_RECEIVED_COMPLETED, 25);
        assert_eq!(CMD_STEP_FORWARD_SIMULATION_COMPLETED, 26);
        assert_eq!(CMD_CONTACT_POINT_INFORMATION_COMPLETED, 39);
        assert_eq!(CMD_GET_DYNAMICS_INFO_COMPLETED, 77);
        assert_eq!(CMD_CREATE_COLLISION_SHAPE_COMPLETED, 80);
        assert_eq!(CMD_CREATE_MULTI_BODY_COMPLETED, 84);
        assert_eq!(CMD_REQUEST_COLLISION_INFO_COMPLETED, 85);
        assert_eq!(CMD_REQUEST_PHYSICS_SIMULATION_PARAMETERS_COMPLETED, 91);
        assert_eq!(CMD_BULLET_SAVING_COMPLETED, 10);
        assert_eq!(CMD_RESTORE_STATE_COMPLETED, 95);
    }

    #[test]
    fn c_text_stops_at_nul() {
        let buf: Vec<c_char> = b"link_6\0junk".iter().map(|&b| b as c_char).collect();
        assert_eq!(c_text(&buf), "link_6");
    }
}
