//! The process-wide PhysX SDK: one foundation and one `PxPhysics` (PhysX
//! allows a single foundation per process), created on first use, with
//! PhysX's error callback routed to the `log` crate.
//!
//! PhysX reports errors, warnings and debug messages through a
//! `PxErrorCallback`. Its default one prints them on standard output,
//! which belongs to the program (`realitygap run` children write their
//! result there), so [`sdk`] installs a callback that logs them (target
//! `physx`: debug information as debug, warnings and performance warnings
//! as warn, everything else as error) and keeps the most recent ones of the
//! calling thread, which the engine puts into its error messages
//! ([`take_messages`]). Every simulation steps on the thread that calls it
//! (a CPU dispatcher without worker threads), so a thread's messages are
//! those of its own simulation.
//!
//! PhysX's scenes are not independent: materials belong to the whole
//! SDK, and each scene's `simulate` reads the SDK's material table. So
//! the SDK has a readers-writer lock: creating and releasing objects takes
//! it exclusively ([`Sdk::lock`]), stepping a scene takes it shared
//! ([`Sdk::stepping`]); scenes step in parallel with each other, never
//! while another thread builds or releases a world.
//!
//! PhysX's assertions (its debug build checks) go to the log and standard
//! error, then abort the process as PhysX's own handler does, but without
//! its print on standard output.

use physx_sys::*;
use std::cell::{Cell, RefCell};
use std::ffi::{c_void, CStr};
use std::sync::{OnceLock, RwLock, RwLockReadGuard, RwLockWriteGuard};

/// PhysX's version, as `PX_PHYSICS_VERSION_MAJOR.MINOR.BUGFIX` of the
/// sources `physx-sys` builds.
pub const PHYSX_VERSION: (u32, u32, u32) = (5, 1, 3);

/// `PX_PHYSICS_VERSION`: what `PxCreatePhysics` checks its headers against.
const PX_PHYSICS_VERSION: u32 =
    (PHYSX_VERSION.0 << 24) + (PHYSX_VERSION.1 << 16) + (PHYSX_VERSION.2 << 8);

/// Most messages kept per thread between two [`take_messages`] calls.
const KEPT: usize = 32;

thread_local! {
    static MESSAGES: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
    /// Whether this thread holds the SDK lock (it is not reentrant).
    static HELD: Cell<bool> = const { Cell::new(false) };
}

/// The messages PhysX reported on this thread since the last call, oldest
/// first (at most the last 32).
pub fn take_messages() -> Vec<String> {
    MESSAGES.with(|m| std::mem::take(&mut *m.borrow_mut()))
}

/// The messages of [`take_messages`] as one clause for an error message
/// (`"; PhysX said: ..."`), or nothing.
pub fn said() -> String {
    let m = take_messages();
    if m.is_empty() {
        String::new()
    } else {
        format!("; PhysX said: {}", m.join(" | "))
    }
}

fn text(p: *const i8) -> String {
    if p.is_null() {
        return String::new();
    }
    // SAFETY: PhysX passes NUL-terminated strings valid during the call.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

/// PhysX's error callback: to the log, and kept for error messages.
unsafe extern "C" fn on_error(
    code: PxErrorCode,
    message: *const i8,
    file: *const i8,
    line: u32,
    _user: *const c_void,
) {
    let file = text(file);
    let short = file.rsplit('/').next().unwrap_or(&file).to_string();
    let line_text = format!("{} ({short}:{line})", text(message));
    match code {
        PxErrorCode::DebugInfo | PxErrorCode::NoError => {
            log::debug!(target: "physx", "{line_text}")
        }
        PxErrorCode::DebugWarning | PxErrorCode::PerfWarning => {
            log::warn!(target: "physx", "{line_text}")
        }
        _ => log::error!(target: "physx", "{line_text}"),
    }
    // `try_with`: PhysX may report while this thread's locals are being
    // destroyed; the message is logged anyway.
    let _ = MESSAGES.try_with(|m| {
        let mut m = m.borrow_mut();
        if m.len() == KEPT {
            m.remove(0);
        }
        m.push(line_text);
    });
}

/// PhysX's assertion handler: a failed internal check is a bug in PhysX or
/// in how it is called, so the process stops, as with PhysX's own handler,
/// after saying so on standard error and in the log (never on standard
/// output).
unsafe extern "C" fn on_assert(
    expression: *const i8,
    file: *const i8,
    line: u32,
    _ignore: *mut bool,
    _user: *const c_void,
) {
    let file = text(file);
    let short = file.rsplit('/').next().unwrap_or(&file).to_string();
    let message = format!(
        "PhysX assertion failed: {} ({short}:{line})",
        text(expression)
    );
    log::error!(target: "physx", "{message}");
    eprintln!("{message}");
    std::process::abort();
}

/// The SDK's objects. They live for the whole process.
pub struct Sdk {
    physics: *mut PxPhysics,
    /// Cooking parameters for convex meshes (PhysX's defaults for the
    /// SDK's tolerance scale).
    pub cooking: PxCookingParams,
    lock: RwLock<()>,
}

// SAFETY: `physics` is only used while `lock` is held exclusively (see
// `Sdk::lock`), and scenes created from it step only while it is held
// shared (`Sdk::stepping`); the cooking parameters are plain data.
unsafe impl Send for Sdk {}
// SAFETY: as above: shared access goes through the lock.
unsafe impl Sync for Sdk {}

/// Holds the SDK's lock exclusively; gives the `PxPhysics`.
pub struct Locked<'a> {
    _guard: RwLockWriteGuard<'a, ()>,
    /// The SDK's `PxPhysics`.
    pub physics: *mut PxPhysics,
}

/// Holds the SDK's lock shared, for stepping a scene.
pub struct Stepping<'a> {
    _guard: RwLockReadGuard<'a, ()>,
}

impl Drop for Locked<'_> {
    fn drop(&mut self) {
        HELD.with(|h| h.set(false));
    }
}

impl Sdk {
    /// Locks the SDK for creating or releasing objects (the thread must
    /// not hold it already: see [`Sdk::lock_unless_held`]).
    pub fn lock(&self) -> Locked<'_> {
        let guard = self.lock.write().unwrap_or_else(|e| e.into_inner());
        HELD.with(|h| h.set(true));
        Locked {
            _guard: guard,
            physics: self.physics,
        }
    }

    /// The lock held shared while a scene steps (see the module
    /// documentation).
    pub fn stepping(&self) -> Stepping<'_> {
        Stepping {
            _guard: self.lock.read().unwrap_or_else(|e| e.into_inner()),
        }
    }

    /// [`Sdk::lock`], or `None` when this thread holds the lock already
    /// (a world released while another is being built on the same thread,
    /// e.g. a half-built world dropped on a load error).
    pub fn lock_unless_held(&self) -> Option<Locked<'_>> {
        if HELD.with(|h| h.get()) {
            None
        } else {
            Some(self.lock())
        }
    }
}

static SDK: OnceLock<Result<Sdk, String>> = OnceLock::new();

/// The SDK, created on first use; an error message when PhysX refused to
/// start (with what it said).
pub fn sdk() -> Result<&'static Sdk, String> {
    SDK.get_or_init(create).as_ref().map_err(Clone::clone)
}

fn create() -> Result<Sdk, String> {
    // SAFETY: plain FFI calls creating the process's single foundation and
    // physics; every pointer is checked before use and the objects are
    // never released (they live as long as the process).
    unsafe {
        phys_PxSetAssertHandler(create_assert_handler(on_assert, std::ptr::null_mut()));
        let callback = create_error_callback(on_error, std::ptr::null_mut());
        let allocator = get_default_allocator() as *mut PxAllocatorCallback;
        let foundation = phys_PxCreateFoundation(PX_PHYSICS_VERSION, allocator, callback);
        if foundation.is_null() {
            return Err(format!("PhysX could not create its foundation{}", said()));
        }
        let scale = PxTolerancesScale_new(1.0, 10.0);
        let physics = phys_PxCreatePhysics(
            PX_PHYSICS_VERSION,
            foundation,
            &scale,
            false,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        if physics.is_null() {
            return Err(format!("PhysX could not create its physics{}", said()));
        }
        let cooking = PxCookingParams_new(&scale);
        Ok(Sdk {
            physics,
            cooking,
            lock: RwLock::new(()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sdk_starts_once() {
        let a = sdk().expect("PhysX starts") as *const Sdk;
        let b = sdk().expect("PhysX starts") as *const Sdk;
        assert_eq!(a, b);
    }

    /// A call PhysX refuses (a material with negative friction) reaches
    /// this module's callback, which keeps it for the engine's errors and
    /// logs it, instead of PhysX's default callback printing it. PhysX
    /// checks parameters in its checked build, which `physx-sys` makes for
    /// the debug profile.
    #[test]
    fn physx_errors_reach_the_callback() {
        let sdk = sdk().expect("PhysX starts");
        take_messages();
        let locked = sdk.lock();
        // SAFETY: a plain creation call; a refused material is null.
        let m = unsafe { PxPhysics_createMaterial_mut(locked.physics, -1.0, -1.0, 0.0) };
        drop(locked);
        let said = take_messages();
        if cfg!(debug_assertions) {
            assert!(m.is_null(), "PhysX accepted a negative friction");
            assert!(
                said.iter().any(|s| s.to_lowercase().contains("friction")),
                "{said:?}"
            );
        }
        if !m.is_null() {
            // SAFETY: releases the material just created.
            unsafe { PxRefCounted_release_mut(m as *mut PxRefCounted) };
        }
    }

    #[test]
    fn messages_are_kept_per_thread_and_taken_once() {
        take_messages();
        let msg = c"a test message";
        // SAFETY: calls the callback as PhysX would, with valid strings.
        unsafe {
            on_error(
                PxErrorCode::InvalidParameter,
                msg.as_ptr(),
                c"/x/y/file.cpp".as_ptr(),
                7,
                std::ptr::null(),
            )
        };
        let other = std::thread::spawn(take_messages).join().unwrap();
        assert!(other.is_empty());
        assert_eq!(take_messages(), vec!["a test message (file.cpp:7)"]);
        assert!(take_messages().is_empty());
    }
}
