//! Builds the C++ shim (`shim/dart_shim.cc`) over DART's C++ API with
//! `cxx-build`, against the system's DART 6.12 (Debian's `libdart-dev`,
//! `libdart-collision-ode-dev`, `libdart-collision-bullet-dev`), found
//! through pkg-config (`dart`, `ode`, `bullet`).
//!
//! Also adds the MuJoCo library directory (MUJOCO_DYNAMIC_LINK_DIR, set by
//! the workspace's .cargo/config.toml) as an rpath of this crate's tests and
//! benchmarks, which compare against the MuJoCo engine.

fn probe(name: &str, version: &str, package: &str) -> pkg_config::Library {
    match pkg_config::Config::new()
        .atleast_version(version)
        .probe(name)
    {
        Ok(library) => library,
        Err(e) => {
            eprintln!(
                "realitygap-engine-dart needs {name} {version} or newer and its pkg-config file: \
                 on Debian, `apt-get install {package}` (scripts/setup does it).\n{e}"
            );
            std::process::exit(1);
        }
    }
}

fn main() {
    println!("cargo::rerun-if-changed=shim/dart_shim.h");
    println!("cargo::rerun-if-changed=shim/dart_shim.cc");
    println!("cargo::rerun-if-changed=src/ffi.rs");
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg-tests=-Wl,-rpath,{dir}");
        println!("cargo::rustc-link-arg-benches=-Wl,-rpath,{dir}");
    }
    let dart = probe(
        "dart",
        "6.12",
        "libdart-dev libdart-collision-ode-dev libdart-collision-bullet-dev",
    );
    let ode = probe("ode", "0.16", "libode-dev");
    let bullet = probe("bullet", "2.80", "libbullet-dev");
    println!(
        "cargo::rustc-env=REALITYGAP_DART_PKG_VERSION={}",
        dart.version
    );
    // The collision detectors beside DART's own and FCL: separate libraries
    // of the same Debian source package (no pkg-config file of their own).
    println!("cargo::rustc-link-lib=dart-collision-ode");
    println!("cargo::rustc-link-lib=dart-collision-bullet");

    let mut build = cxx_build::bridge("src/ffi.rs");
    build
        .file("shim/dart_shim.cc")
        .std("c++17")
        // DART's and Eigen's headers are noisy at -Wall; the shim's own
        // warnings are checked by building it with -Wall by hand.
        .warnings(false)
        .flag_if_supported("-Wno-deprecated-declarations");
    for include in dart
        .include_paths
        .iter()
        .chain(&ode.include_paths)
        .chain(&bullet.include_paths)
    {
        build.include(include);
    }
    build.compile("realitygap_dart_shim");
}
