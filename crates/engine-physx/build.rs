//! The tests and benchmarks run the MuJoCo engine (a dev-dependency) next to
//! PhysX: add the directory of the MuJoCo shared library
//! (MUJOCO_DYNAMIC_LINK_DIR, set by the workspace's .cargo/config.toml) as an
//! rpath so they run without LD_LIBRARY_PATH. The library crate itself does
//! not use MuJoCo.
fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg-tests=-Wl,-rpath,{dir}");
        println!("cargo::rustc-link-arg-benches=-Wl,-rpath,{dir}");
    }
}
