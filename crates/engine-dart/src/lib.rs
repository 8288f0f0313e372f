//! DART engine (work in progress).
mod ffi;

/// DART's version.
pub fn dart_version() -> String {
    ffi::dart_version()
}
