//! The C++ shim (`shim/dart_shim.cc`), reached through its C entry points
//! (`shim/dart_capi.cc`).
//!
//! The shim is a shared library of its own, linked against DART and FCL,
//! which build.rs compiles and this crate embeds. It is loaded when a DART
//! world is first made, from memory (`memfd_create`) or else from a
//! temporary file: the ~70 000 symbols DART and FCL bind at load cost a
//! process 18 ms, which every run of another engine, every test binary and
//! every command used to pay at start (`realitygap --version`: 21.5 ms
//! with DART linked, 3.4-3.7 ms now). A machine without DART's libraries gets a
//! clear error when a DART world is asked for, not a binary that will not
//! start.
//!
//! Every function that can fail returns an [`Exception`]: the shim catches
//! DART's exceptions and its own checks as C++ exceptions and hands over
//! their message (with what DART printed during the call appended). Poses
//! cross as 7 numbers (x y z, then the quaternion w x y z), vectors as 3.

use std::ffi::{c_char, c_void, CStr};
use std::ptr::NonNull;
use std::sync::OnceLock;

/// The shim's shared library, as build.rs made it.
static LIBRARY: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/librealitygap_dart.so"));

/// An error of the shim: a C++ exception's message, or why the shim's
/// library could not be loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct Exception(String);

impl Exception {
    /// The message.
    pub fn what(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for Exception {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Exception {}

/// What one step saw (the shim's `StepReport`, the same layout).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct StepReport {
    pub objects_finite: bool,
    pub max_speed: f64,
    pub max_spin: f64,
    pub said: bool,
}

/// A returned message: NULL, or text from the shim's malloc, which this
/// side frees with `rgdart_free`.
type Message = *mut c_char;

macro_rules! entry_points {
    ($($name:ident: fn($($arg:ty),*) $(-> $ret:ty)?;)*) => {
        /// The shim's entry points, looked up by name once.
        #[allow(non_snake_case)]
        struct Api {
            $($name: unsafe extern "C" fn($($arg),*) $(-> $ret)?,)*
        }

        impl Api {
            /// Looks up every entry point in the library `handle`.
            fn find(handle: *mut c_void) -> Result<Api, String> {
                Ok(Api {
                    $($name: {
                        let name = concat!(stringify!($name), "\0");
                        // SAFETY: `handle` is a loaded library and `name` ends in NUL.
                        let p = unsafe { libc::dlsym(handle, name.as_ptr().cast()) };
                        if p.is_null() {
                            return Err(format!(
                                "the DART shim has no entry point {}",
                                stringify!($name)
                            ));
                        }
                        // SAFETY: the symbol is the shim's function of this
                        // signature (shim/dart_capi.cc).
                        unsafe { std::mem::transmute::<*mut c_void, unsafe extern "C" fn($($arg),*) $(-> $ret)?>(p) }
                    },)*
                })
            }
        }
    };
}

entry_points! {
    rgdart_free: fn(*mut c_char);
    rgdart_take_messages: fn() -> Message;
    rgdart_say: fn(*const c_char, usize);
    rgdart_new_world: fn(f64, *const f64, usize, *const c_char, usize, *const c_char, usize, *mut *mut c_void) -> Message;
    rgdart_delete_world: fn(*mut c_void);
    rgdart_add_robot_body: fn(*mut c_void, *const c_char, usize, i64, u8, *const f64, usize, *const f64, usize, f64, *const f64, usize, *const f64, usize, *mut usize) -> Message;
    rgdart_set_joint_limits: fn(*mut c_void, usize, f64, f64) -> Message;
    rgdart_set_joint_friction: fn(*mut c_void, usize, f64) -> Message;
    rgdart_set_actuator: fn(*mut c_void, usize, bool, f64) -> Message;
    rgdart_set_drives: fn(*mut c_void, *const f64, usize, *const f64, usize, *const f64, usize, *const f64, usize) -> Message;
    rgdart_add_shape: fn(*mut c_void, bool, usize, u8, *const f64, usize, *const f64, usize, f64, f64) -> Message;
    rgdart_add_mesh: fn(*mut c_void, usize, *const f64, usize, *const u32, usize, *const f64, usize, f64) -> Message;
    rgdart_add_object: fn(*mut c_void, *const c_char, usize, f64, *const f64, usize, *const f64, usize, *mut usize) -> Message;
    rgdart_add_ground: fn(*mut c_void, f64, f64, f64) -> Message;
    rgdart_finish: fn(*mut c_void) -> Message;
    rgdart_step: fn(*mut c_void) -> Message;
    rgdart_advance: fn(*mut c_void, *const f64, usize, *const f64, usize, *const f64, usize, *const f64, usize, *mut f64, usize, *mut f64, usize, *mut StepReport) -> Message;
    rgdart_step_raw: fn(*mut c_void, u64) -> Message;
    rgdart_joint_state: fn(*const c_void, *mut f64, usize, *mut f64, usize);
    rgdart_set_joint_state: fn(*mut c_void, *const f64, usize, *const f64, usize) -> Message;
    rgdart_body_pose: fn(*const c_void, usize, *mut f64, usize);
    rgdart_object_state: fn(*const c_void, usize, *mut f64, usize);
    rgdart_set_object_state: fn(*mut c_void, usize, *const f64, usize) -> Message;
    rgdart_object_coordinates: fn(*const c_void, usize, *mut f64, usize);
    rgdart_set_object_coordinates: fn(*mut c_void, usize, *const f64, usize) -> Message;
    rgdart_set_time: fn(*mut c_void, f64);
    rgdart_contact_count: fn(*const c_void) -> usize;
}

/// The last `dlerror`, or `what` when there is none.
fn dl_error(what: &str) -> String {
    // SAFETY: dlerror returns NULL or a NUL-terminated string.
    let e = unsafe { libc::dlerror() };
    if e.is_null() {
        what.to_string()
    } else {
        // SAFETY: as above.
        unsafe { CStr::from_ptr(e) }.to_string_lossy().into_owned()
    }
}

/// Opens the library at `path`.
fn open(path: &CStr) -> Result<*mut c_void, String> {
    // SAFETY: `path` is NUL-terminated; the library's initialisers are
    // DART's and the C++ runtime's.
    let handle = unsafe { libc::dlopen(path.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL) };
    if handle.is_null() {
        Err(dl_error("dlopen failed"))
    } else {
        Ok(handle)
    }
}

/// Writes the embedded library to an anonymous file in memory and opens it.
fn open_from_memory() -> Result<*mut c_void, String> {
    use std::io::Write;
    use std::os::fd::FromRawFd;
    // SAFETY: the name is NUL-terminated; the result is checked.
    let fd = unsafe { libc::memfd_create(c"realitygap-dart-shim".as_ptr(), libc::MFD_CLOEXEC) };
    if fd < 0 {
        return Err(format!("memfd_create: {}", std::io::Error::last_os_error()));
    }
    // SAFETY: `fd` was just created and is owned here.
    let mut file = unsafe { std::fs::File::from_raw_fd(fd) };
    file.write_all(LIBRARY)
        .map_err(|e| format!("writing the library to memory: {e}"))?;
    let path = std::ffi::CString::new(format!("/proc/self/fd/{fd}")).expect("no NUL");
    let handle = open(&path)?;
    // The loader knows the library by this path: the descriptor stays open
    // for the life of the process, so that no other file takes its number.
    std::mem::forget(file);
    Ok(handle)
}

/// Whether a loader's error says a library is missing.
fn missing_library(e: &str) -> bool {
    e.contains("cannot open shared object file")
}

/// Writes the embedded library to a temporary file, opens it and removes
/// the file.
fn open_from_file() -> Result<*mut c_void, String> {
    use std::io::Write;
    let mut file = tempfile::Builder::new()
        .prefix("realitygap-dart-shim-")
        .suffix(".so")
        .tempfile()
        .map_err(|e| format!("making a temporary file: {e}"))?;
    file.write_all(LIBRARY)
        .and_then(|_| file.flush())
        .map_err(|e| format!("writing {}: {e}", file.path().display()))?;
    let path = std::ffi::CString::new(file.path().as_os_str().as_encoded_bytes())
        .map_err(|_| "the temporary folder's path holds a NUL".to_string())?;
    open(&path)
}

/// Loads the embedded library: from an anonymous file in memory, or, where
/// that fails for another reason than a missing library of DART's, from a
/// temporary file removed once loaded.
fn load() -> Result<Api, String> {
    let handle = open_from_memory().or_else(|memory| {
        let tried = if missing_library(&memory) {
            Err(memory)
        } else {
            open_from_file().map_err(|file| {
                let both = format!("from memory: {memory}; from a temporary file: {file}");
                if missing_library(&file) {
                    file
                } else {
                    both
                }
            })
        };
        tried.map_err(|e| {
            let hint = if missing_library(&e) {
                "; on Debian, `apt-get install libdart6.12 libdart-collision-ode6.12 \
                 libdart-collision-bullet6.12` installs DART and what it needs \
                 (scripts/setup does)"
            } else {
                ""
            };
            format!("the DART engine could not load its library ({e}){hint}")
        })
    })?;
    // The library stays loaded for the life of the process.
    Api::find(handle)
}

/// The shim's entry points once loaded, or why they could not be.
static API: OnceLock<Result<Api, String>> = OnceLock::new();

/// The shim's entry points, loaded on first use.
fn api() -> Result<&'static Api, Exception> {
    API.get_or_init(load)
        .as_ref()
        .map_err(|e| Exception(e.clone()))
}

/// Takes a returned message: `Ok` for none.
fn check(api: &Api, m: Message) -> Result<(), Exception> {
    if m.is_null() {
        return Ok(());
    }
    // SAFETY: a non-NULL message is a NUL-terminated string from malloc,
    // freed once here.
    let text = unsafe { CStr::from_ptr(m) }.to_string_lossy().into_owned();
    // SAFETY: as above; the text was copied out.
    unsafe { (api.rgdart_free)(m) };
    Err(Exception(text))
}

/// A returned string (empty for NULL).
fn take(api: &Api, m: Message) -> String {
    check(api, m).err().map(|e| e.0).unwrap_or_default()
}

/// What DART printed on this thread since the last call (nothing when the
/// shim was never loaded: nothing of DART ran).
pub fn take_messages() -> String {
    match API.get() {
        // SAFETY: no arguments.
        Some(Ok(a)) => take(a, unsafe { (a.rgdart_take_messages)() }),
        _ => String::new(),
    }
}

/// Prints `text` the ways DART prints (a test of the capture).
pub fn say(text: &str) -> Result<(), Exception> {
    let a = api()?;
    // SAFETY: the text's bytes and length.
    unsafe { (a.rgdart_say)(text.as_ptr().cast(), text.len()) };
    Ok(())
}

/// A new DART world.
pub fn new_world(
    timestep_s: f64,
    gravity: &[f64],
    detector: &str,
    lcp: &str,
) -> Result<UniquePtr<World>, Exception> {
    let a = api()?;
    let mut raw = std::ptr::null_mut();
    // SAFETY: every pointer comes with its length; `raw` receives the world.
    check(a, unsafe {
        (a.rgdart_new_world)(
            timestep_s,
            gravity.as_ptr(),
            gravity.len(),
            detector.as_ptr().cast(),
            detector.len(),
            lcp.as_ptr().cast(),
            lcp.len(),
            &mut raw,
        )
    })?;
    let raw = NonNull::new(raw).ok_or_else(|| Exception("the shim made no world".into()))?;
    Ok(UniquePtr(Some(World { raw, api: a })))
}

/// A world of the shim, owned: dropping it destroys it.
pub struct World {
    raw: NonNull<c_void>,
    api: &'static Api,
}

impl Drop for World {
    fn drop(&mut self) {
        // SAFETY: the world was made by rgdart_new_world and is deleted once.
        unsafe { (self.api.rgdart_delete_world)(self.raw.as_ptr()) }
    }
}

/// An owned world or none (what `cxx::UniquePtr` was to the bridge).
pub struct UniquePtr<T>(Option<T>);

impl<T> UniquePtr<T> {
    /// None: what the old value was is dropped.
    pub fn null() -> Self {
        UniquePtr(None)
    }

    /// The value, mutable.
    ///
    /// # Panics
    /// When there is none (a world is dropped only with its owner).
    pub fn get_mut(&mut self) -> &mut T {
        self.0
            .as_mut()
            .expect("a DART world is used after it was dropped")
    }
}

impl<T> std::ops::Deref for UniquePtr<T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.0
            .as_ref()
            .expect("a DART world is used after it was dropped")
    }
}

impl World {
    fn w(&mut self) -> *mut c_void {
        self.raw.as_ptr()
    }

    fn r(&self) -> *const c_void {
        self.raw.as_ptr()
    }

    /// Adds a robot body and its joint to its parent (-1: the world).
    #[allow(clippy::too_many_arguments)]
    pub fn add_robot_body(
        &mut self,
        name: &str,
        parent: i64,
        kind: u8,
        joint_pose: &[f64],
        axis: &[f64],
        mass_kg: f64,
        com: &[f64],
        inertia: &[f64],
    ) -> Result<usize, Exception> {
        let mut body = 0;
        // SAFETY: every pointer comes with its length; `body` receives the index.
        let m = unsafe {
            (self.api.rgdart_add_robot_body)(
                self.w(),
                name.as_ptr().cast(),
                name.len(),
                parent,
                kind,
                joint_pose.as_ptr(),
                joint_pose.len(),
                axis.as_ptr(),
                axis.len(),
                mass_kg,
                com.as_ptr(),
                com.len(),
                inertia.as_ptr(),
                inertia.len(),
                &mut body,
            )
        };
        check(self.api, m).map(|_| body)
    }

    /// A joint's position limits.
    pub fn set_joint_limits(
        &mut self,
        joint: usize,
        lower: f64,
        upper: f64,
    ) -> Result<(), Exception> {
        // SAFETY: plain values.
        let m = unsafe { (self.api.rgdart_set_joint_limits)(self.w(), joint, lower, upper) };
        check(self.api, m)
    }

    /// A joint's Coulomb friction torque.
    pub fn set_joint_friction(&mut self, joint: usize, friction: f64) -> Result<(), Exception> {
        // SAFETY: plain values.
        let m = unsafe { (self.api.rgdart_set_joint_friction)(self.w(), joint, friction) };
        check(self.api, m)
    }

    /// A joint's actuator.
    pub fn set_actuator(&mut self, joint: usize, servo: bool, limit: f64) -> Result<(), Exception> {
        // SAFETY: plain values.
        let m = unsafe { (self.api.rgdart_set_actuator)(self.w(), joint, servo, limit) };
        check(self.api, m)
    }

    /// The drives' commands, damping, stiffness and rest positions.
    pub fn set_drives(
        &mut self,
        command: &[f64],
        damping: &[f64],
        stiffness: &[f64],
        rest: &[f64],
    ) -> Result<(), Exception> {
        // SAFETY: every pointer comes with its length.
        let m = unsafe {
            (self.api.rgdart_set_drives)(
                self.w(),
                command.as_ptr(),
                command.len(),
                damping.as_ptr(),
                damping.len(),
                stiffness.as_ptr(),
                stiffness.len(),
                rest.as_ptr(),
                rest.len(),
            )
        };
        check(self.api, m)
    }

    /// A primitive shape on a robot body or an object.
    #[allow(clippy::too_many_arguments)]
    pub fn add_shape(
        &mut self,
        object: bool,
        body: usize,
        kind: u8,
        dims: &[f64],
        pose: &[f64],
        friction: f64,
        restitution: f64,
    ) -> Result<(), Exception> {
        // SAFETY: every pointer comes with its length.
        let m = unsafe {
            (self.api.rgdart_add_shape)(
                self.w(),
                object,
                body,
                kind,
                dims.as_ptr(),
                dims.len(),
                pose.as_ptr(),
                pose.len(),
                friction,
                restitution,
            )
        };
        check(self.api, m)
    }

    /// A triangle mesh on a robot body.
    pub fn add_mesh(
        &mut self,
        body: usize,
        vertices: &[f64],
        indices: &[u32],
        pose: &[f64],
        friction: f64,
    ) -> Result<(), Exception> {
        // SAFETY: every pointer comes with its length.
        let m = unsafe {
            (self.api.rgdart_add_mesh)(
                self.w(),
                body,
                vertices.as_ptr(),
                vertices.len(),
                indices.as_ptr(),
                indices.len(),
                pose.as_ptr(),
                pose.len(),
                friction,
            )
        };
        check(self.api, m)
    }

    /// A free object; its index.
    pub fn add_object(
        &mut self,
        name: &str,
        mass_kg: f64,
        inertia: &[f64],
        pose: &[f64],
    ) -> Result<usize, Exception> {
        let mut object = 0;
        // SAFETY: every pointer comes with its length; `object` receives the index.
        let m = unsafe {
            (self.api.rgdart_add_object)(
                self.w(),
                name.as_ptr().cast(),
                name.len(),
                mass_kg,
                inertia.as_ptr(),
                inertia.len(),
                pose.as_ptr(),
                pose.len(),
                &mut object,
            )
        };
        check(self.api, m).map(|_| object)
    }

    /// The ground plane.
    pub fn add_ground(
        &mut self,
        height: f64,
        friction: f64,
        restitution: f64,
    ) -> Result<(), Exception> {
        // SAFETY: plain values.
        let m = unsafe { (self.api.rgdart_add_ground)(self.w(), height, friction, restitution) };
        check(self.api, m)
    }

    /// Ends the building.
    pub fn finish(&mut self) -> Result<(), Exception> {
        // SAFETY: the world.
        let m = unsafe { (self.api.rgdart_finish)(self.w()) };
        check(self.api, m)
    }

    /// One step.
    pub fn step(&mut self) -> Result<(), Exception> {
        // SAFETY: the world.
        let m = unsafe { (self.api.rgdart_step)(self.w()) };
        check(self.api, m)
    }

    /// Sets the drives, steps once and reads the joints.
    pub fn advance(
        &mut self,
        command: &[f64],
        damping: &[f64],
        stiffness: &[f64],
        rest: &[f64],
        positions: &mut [f64],
        velocities: &mut [f64],
    ) -> Result<StepReport, Exception> {
        let mut report = StepReport::default();
        // SAFETY: every pointer comes with its length; `report` receives the report.
        let m = unsafe {
            (self.api.rgdart_advance)(
                self.w(),
                command.as_ptr(),
                command.len(),
                damping.as_ptr(),
                damping.len(),
                stiffness.as_ptr(),
                stiffness.len(),
                rest.as_ptr(),
                rest.len(),
                positions.as_mut_ptr(),
                positions.len(),
                velocities.as_mut_ptr(),
                velocities.len(),
                &mut report,
            )
        };
        check(self.api, m).map(|_| report)
    }

    /// `n` steps with the drives as they are.
    pub fn step_raw(&mut self, n: u64) -> Result<(), Exception> {
        // SAFETY: plain values.
        let m = unsafe { (self.api.rgdart_step_raw)(self.w(), n) };
        check(self.api, m)
    }

    /// The controlled joints' positions and velocities.
    pub fn joint_state(&self, positions: &mut [f64], velocities: &mut [f64]) {
        // SAFETY: every pointer comes with its length.
        unsafe {
            (self.api.rgdart_joint_state)(
                self.r(),
                positions.as_mut_ptr(),
                positions.len(),
                velocities.as_mut_ptr(),
                velocities.len(),
            )
        }
    }

    /// Sets the controlled joints' positions and velocities.
    pub fn set_joint_state(
        &mut self,
        positions: &[f64],
        velocities: &[f64],
    ) -> Result<(), Exception> {
        // SAFETY: every pointer comes with its length.
        let m = unsafe {
            (self.api.rgdart_set_joint_state)(
                self.w(),
                positions.as_ptr(),
                positions.len(),
                velocities.as_ptr(),
                velocities.len(),
            )
        };
        check(self.api, m)
    }

    /// A robot body's world pose (7 numbers).
    pub fn body_pose(&self, body: usize, out: &mut [f64]) {
        // SAFETY: the pointer comes with its length.
        unsafe { (self.api.rgdart_body_pose)(self.r(), body, out.as_mut_ptr(), out.len()) }
    }

    /// An object's pose and velocities (13 numbers).
    pub fn object_state(&self, i: usize, out: &mut [f64]) {
        // SAFETY: the pointer comes with its length.
        unsafe { (self.api.rgdart_object_state)(self.r(), i, out.as_mut_ptr(), out.len()) }
    }

    /// Sets an object's pose and velocities.
    pub fn set_object_state(&mut self, i: usize, state: &[f64]) -> Result<(), Exception> {
        // SAFETY: the pointer comes with its length.
        let m =
            unsafe { (self.api.rgdart_set_object_state)(self.w(), i, state.as_ptr(), state.len()) };
        check(self.api, m)
    }

    /// An object's free joint's coordinates, exactly.
    pub fn object_coordinates(&self, i: usize, out: &mut [f64]) {
        // SAFETY: the pointer comes with its length.
        unsafe { (self.api.rgdart_object_coordinates)(self.r(), i, out.as_mut_ptr(), out.len()) }
    }

    /// Sets an object's free joint's coordinates.
    pub fn set_object_coordinates(&mut self, i: usize, values: &[f64]) -> Result<(), Exception> {
        // SAFETY: the pointer comes with its length.
        let m = unsafe {
            (self.api.rgdart_set_object_coordinates)(self.w(), i, values.as_ptr(), values.len())
        };
        check(self.api, m)
    }

    /// The world's clock.
    pub fn set_time(&mut self, t_s: f64) {
        // SAFETY: plain values.
        unsafe { (self.api.rgdart_set_time)(self.w(), t_s) }
    }

    /// The contacts of the last step.
    pub fn contact_count(&self) -> usize {
        // SAFETY: the world.
        unsafe { (self.api.rgdart_contact_count)(self.r()) }
    }
}
