//! Finds the system's ODE (Debian's `libode-dev`, 0.16, double precision)
//! through pkg-config and generates Rust bindings to the part of its C API
//! this crate uses, with bindgen, into `$OUT_DIR/ode_bindings.rs`.
//!
//! Also adds the MuJoCo library directory (MUJOCO_DYNAMIC_LINK_DIR, set by
//! the workspace's .cargo/config.toml) as an rpath of this crate's tests and
//! benchmarks, which compare against the MuJoCo engine.

use std::path::PathBuf;

fn main() {
    println!("cargo::rerun-if-changed=wrapper.h");
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg-tests=-Wl,-rpath,{dir}");
        println!("cargo::rustc-link-arg-benches=-Wl,-rpath,{dir}");
    }

    let library = match pkg_config::Config::new()
        .atleast_version("0.16")
        .probe("ode")
    {
        Ok(library) => library,
        Err(e) => {
            eprintln!(
                "realitygap-engine-ode needs the Open Dynamics Engine 0.16 or newer (double precision) \
                 and its pkg-config file: on Debian, `apt-get install libode-dev` (scripts/setup does it).\n{e}"
            );
            std::process::exit(1);
        }
    };
    println!(
        "cargo::rustc-env=REALITYGAP_ODE_PKG_VERSION={}",
        library.version
    );

    let mut builder = bindgen::Builder::default()
        .header("wrapper.h")
        .parse_callbacks(Box::new(bindgen::CargoCallbacks::new()))
        // ODE selects double precision unless dIDESINGLE is defined; say so
        // explicitly so that a header change cannot silently switch dReal.
        .clang_arg("-DdIDEDOUBLE")
        .allowlist_function("dInitODE2")
        .allowlist_function("dAllocateODEDataForThread")
        .allowlist_function("dCheckConfiguration")
        .allowlist_function("dGetConfiguration")
        .allowlist_function("dSet(Error|Debug|Message)Handler")
        .allowlist_function("dWorld.*")
        .allowlist_function("dBody.*")
        .allowlist_function("dJoint.*")
        .allowlist_function("dGeom.*")
        .allowlist_function("dSpace.*")
        .allowlist_function("dSimpleSpaceCreate")
        .allowlist_function("dHashSpaceCreate")
        .allowlist_function("dCreate(Plane|Box|Sphere|Cylinder|Capsule|TriMesh)")
        .allowlist_function("dMass.*")
        .allowlist_function("dCollide")
        .allowlist_function("dRand(Get|Set)Seed")
        .allowlist_function("vsnprintf")
        .allowlist_type("dContact.*")
        .allowlist_type("dSurfaceParameters")
        .allowlist_type("dMass")
        .allowlist_type("dTriIndex")
        .allowlist_var("dContact.*")
        .allowlist_var("dParam.*")
        .allowlist_var("dAMotor.*")
        .allowlist_type("dAllocateODEDataFlags")
        .allowlist_var("dODE_VERSION")
        .layout_tests(false)
        .derive_default(true);
    for include in &library.include_paths {
        builder = builder.clang_arg(format!("-I{}", include.display()));
    }
    let bindings = match builder.generate() {
        Ok(b) => b,
        Err(e) => {
            eprintln!("bindgen could not read the ODE headers (is libclang installed? apt-get install libclang-dev): {e}");
            std::process::exit(1);
        }
    };
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"))
        .join("ode_bindings.rs");
    if let Err(e) = bindings.write_to_file(&out) {
        eprintln!("cannot write {}: {e}", out.display());
        std::process::exit(1);
    }
}
