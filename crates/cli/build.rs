//! With the `mujoco` feature, adds the directory of the MuJoCo shared
//! library (MUJOCO_DYNAMIC_LINK_DIR, set by the workspace's
//! .cargo/config.toml) as an rpath of the binary, its tests and benchmarks,
//! so that `realitygap` runs without LD_LIBRARY_PATH.
fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_some() {
        if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
            println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
        }
    }
}
