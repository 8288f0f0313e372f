//! The extension finds MuJoCo's shared library in the `mujoco` wheel it
//! depends on: `realitygap/__init__.py` loads
//! `site-packages/mujoco/libmujoco.so.<version>` before the extension, and
//! as a fallback the extension's runpath names that folder relative to
//! itself (`$ORIGIN/../mujoco`, `realitygap/_native.abi3.so` being beside
//! `mujoco/` in site-packages). No copy of the library is shipped.
fn main() {
    println!("cargo::rustc-link-arg-cdylib=-Wl,-rpath,$ORIGIN/../mujoco");
}
