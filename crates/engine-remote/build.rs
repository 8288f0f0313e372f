//! Embeds the Python side of the engine protocol into the crate, so that
//! the binary carries it wherever it is installed:
//!
//! - every `.py` file under `python/realitygap_engine/` (the SDK and its
//!   adapters), written out once at run time to the folder the children
//!   get on `PYTHONPATH` (`registry::sdk_dir`);
//! - every `python/engines/NAME.txt`: the built-in adapter `NAME`, its
//!   pinned requirements, and the module that serves it (its line
//!   `# module: realitygap_engine.adapters.X`).
//!
//! A new adapter is thus its module and its requirements file; no Rust
//! changes.

use std::fmt::Write;
use std::path::{Path, PathBuf};

fn python_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.expect("a directory entry").path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            if path.file_name().is_some_and(|n| n != "__pycache__") {
                python_files(&path, out);
            }
        } else if path.extension().is_some_and(|x| x == "py") {
            out.push(path);
        }
    }
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let python = manifest
        .join("../../python")
        .canonicalize()
        .expect("python/ exists");
    let sdk_root = python.join("realitygap_engine");
    let engines = python.join("engines");
    println!("cargo:rerun-if-changed={}", sdk_root.display());
    println!("cargo:rerun-if-changed={}", engines.display());

    let mut code = String::from("/// The SDK's files, relative to the folder on `PYTHONPATH`.\npub const SDK: &[(&str, &str)] = &[\n");
    let mut files = Vec::new();
    python_files(&sdk_root, &mut files);
    for f in &files {
        let rel = f.strip_prefix(&python).expect("under python/");
        writeln!(
            code,
            "    ({:?}, include_str!({:?})),",
            rel.display().to_string(),
            f.display().to_string()
        )
        .unwrap();
    }
    code.push_str("];\n\n/// The built-in adapters (`python/engines/NAME.txt`).\npub const ADAPTERS: &[Adapter] = &[\n");
    let mut lists: Vec<PathBuf> = std::fs::read_dir(&engines)
        .expect("python/engines/ exists")
        .map(|e| e.expect("a directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "txt"))
        .collect();
    lists.sort();
    for list in lists {
        let name = list.file_stem().unwrap().to_string_lossy().to_string();
        let text = std::fs::read_to_string(&list).unwrap();
        let module = text
            .lines()
            .find_map(|l| l.strip_prefix("# module:"))
            .unwrap_or_else(|| panic!("{} has no line `# module: ...`", list.display()))
            .trim()
            .to_string();
        let module_file = python.join(module.replace('.', "/") + ".py");
        assert!(
            module_file.is_file(),
            "{}: module {module} has no file {}",
            list.display(),
            module_file.display()
        );
        writeln!(
            code,
            "    Adapter {{ name: {name:?}, module: {module:?}, requirements: include_str!({:?}) }},",
            list.display().to_string()
        )
        .unwrap();
    }
    code.push_str("];\n");
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap()).join("embedded.rs");
    std::fs::write(out, code).unwrap();
}
