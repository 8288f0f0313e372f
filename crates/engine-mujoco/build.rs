//! Adds the directory of the MuJoCo shared library (MUJOCO_DYNAMIC_LINK_DIR,
//! set by the workspace's .cargo/config.toml) as an rpath of this crate's
//! tests and benchmarks, so they run without LD_LIBRARY_PATH.
fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
