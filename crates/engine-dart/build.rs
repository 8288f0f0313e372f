//! Builds the C++ shim (`shim/dart_shim.cc` and its C entry points
//! `shim/dart_capi.cc`) over DART's C++ API into a shared library of its
//! own, against the system's DART 6.12 (Debian's `libdart-dev`,
//! `libdart-collision-ode-dev`, `libdart-collision-bullet-dev`), found
//! through pkg-config (`dart`, `ode`, `bullet`). The crate embeds that
//! library and loads it when a DART world is first made (`src/ffi.rs`):
//! DART and FCL bind about 70 000 symbols when they load (18 of a
//! process's 21.5 ms start), so a process that makes no DART world does
//! not pay for them. The version of DART's headers (`DART_VERSION` in
//! `dart/config.hpp`) becomes a constant, so naming it loads nothing.
//!
//! Also adds the MuJoCo library directory (MUJOCO_DYNAMIC_LINK_DIR, set by
//! the workspace's .cargo/config.toml) as an rpath of this crate's tests and
//! benchmarks, which compare against the MuJoCo engine.

use std::path::PathBuf;
use std::process::Command;

fn probe(name: &str, version: &str, package: &str) -> pkg_config::Library {
    match pkg_config::Config::new()
        .atleast_version(version)
        // Only the shim's library links these, not the crate.
        .cargo_metadata(false)
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

/// `DART_VERSION` of the first `dart/config.hpp` under `includes`, or
/// under the compiler's usual folders (Debian's `dart.pc` names
/// `/usr/include/dart`, whose `dart/config.hpp` is one level up).
fn header_version(includes: &[PathBuf]) -> String {
    let usual = [
        PathBuf::from("/usr/include"),
        PathBuf::from("/usr/local/include"),
    ];
    let parents = includes
        .iter()
        .filter_map(|d| d.parent().map(PathBuf::from));
    let folders: Vec<PathBuf> = includes
        .iter()
        .cloned()
        .chain(parents)
        .chain(usual)
        .collect();
    for dir in &folders {
        let path = dir.join("dart/config.hpp");
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue;
        };
        for line in text.lines() {
            let mut words = line.split_whitespace();
            if let (Some("#define"), Some("DART_VERSION"), Some(v)) =
                (words.next(), words.next(), words.next())
            {
                return v.trim_matches('"').to_string();
            }
        }
        eprintln!("{} has no DART_VERSION", path.display());
        std::process::exit(1);
    }
    eprintln!("no dart/config.hpp under {folders:?}");
    std::process::exit(1);
}

fn main() {
    println!("cargo::rerun-if-changed=shim/dart_shim.h");
    println!("cargo::rerun-if-changed=shim/dart_shim.cc");
    println!("cargo::rerun-if-changed=shim/dart_capi.cc");
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
    println!(
        "cargo::rustc-env=REALITYGAP_DART_HEADER_VERSION={}",
        header_version(&dart.include_paths)
    );

    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"))
        .join("librealitygap_dart.so");
    // The profile's optimisation, as the shim had when cxx-build compiled
    // it; no debug information (the library is embedded in every binary).
    let compiler = cc::Build::new().cpp(true).debug(false).get_compiler();
    let mut cmd: Command = compiler.to_command();
    // Default visibility, as when the shim was linked into the binary: the
    // DART templates it instantiates stay shared with libdart's.
    cmd.args(["-std=c++17", "-shared", "-fPIC", "-w"])
        .args(["shim/dart_shim.cc", "shim/dart_capi.cc", "-o"])
        .arg(&out)
        .arg("-Wl,--no-undefined");
    for include in dart
        .include_paths
        .iter()
        .chain(&ode.include_paths)
        .chain(&bullet.include_paths)
    {
        cmd.arg("-I").arg(include);
    }
    for dir in dart
        .link_paths
        .iter()
        .chain(&ode.link_paths)
        .chain(&bullet.link_paths)
    {
        cmd.arg("-L").arg(dir);
    }
    // The collision detectors beside DART's own and FCL: separate libraries
    // of the same Debian source package (no pkg-config file of their own).
    for lib in ["dart-collision-ode", "dart-collision-bullet"]
        .iter()
        .map(|s| s.to_string())
        .chain(dart.libs.iter().cloned())
        .chain(ode.libs.iter().cloned())
        .chain(bullet.libs.iter().cloned())
    {
        cmd.arg(format!("-l{lib}"));
    }
    let shown = format!(
        "{} {}",
        cmd.get_program().to_string_lossy(),
        cmd.get_args()
            .map(|a| a.to_string_lossy())
            .collect::<Vec<_>>()
            .join(" ")
    );
    match cmd.status() {
        Ok(s) if s.success() => {}
        Ok(s) => {
            eprintln!("building the DART shim failed ({s}): {shown}");
            std::process::exit(1);
        }
        Err(e) => {
            eprintln!("could not run the C++ compiler ({e}): {shown}");
            std::process::exit(1);
        }
    }
}
