//! Where engines out of process come from:
//!
//! - **Built-in adapters**, Python modules of the SDK (`realitygap_engine`,
//!   embedded in this binary and written out once to the engines folder),
//!   each with its pinned environment: `python/engines/NAME.txt` lists its
//!   packages, and `realitygap engines --install NAME` (or `scripts/setup
//!   --engines NAME`) makes `ENGINES/NAME/venv` from it. An adapter whose
//!   environment is not there, or was made from another list, is not
//!   installed: it is left out of the engine list, and naming it says the
//!   line that installs it.
//! - **A user's own engines**, any program that speaks the protocol, in
//!   `ENGINES/engines.toml` (or the file `REALITYGAP_ENGINES_FILE` names):
//!
//!   ```toml
//!   [engine.myengine]
//!   command = ["/home/me/venv/bin/python", "-m", "my_adapter"]
//!   env = { MY_SETTING = "1" }    # optional
//!   ```
//!
//! `ENGINES` is `REALITYGAP_ENGINES_DIR`, else `engines/` in the cache
//! (`REALITYGAP_CACHE_DIR`, else `$XDG_CACHE_HOME/realitygap`, else
//! `~/.cache/realitygap`). Every child gets the SDK on its `PYTHONPATH`.

use crate::child::Launch;
use crate::RemoteEngine;
use realitygap_core::fingerprint::Fingerprint;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A built-in Python adapter.
#[derive(Debug, Clone, Copy)]
pub struct Adapter {
    /// Its engine name (`--engine`).
    pub name: &'static str,
    /// The SDK module that serves it.
    pub module: &'static str,
    /// Its environment's pinned packages (a pip requirements file).
    pub requirements: &'static str,
}

include!(concat!(env!("OUT_DIR"), "/embedded.rs"));

/// The folder of engine environments and the SDK (see the module
/// documentation).
pub fn engines_dir() -> PathBuf {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    if let Some(dir) = var("REALITYGAP_ENGINES_DIR") {
        return dir;
    }
    let cache = var("REALITYGAP_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("realitygap")))
        .or_else(|| var("HOME").map(|d| d.join(".cache/realitygap")))
        .unwrap_or_else(|| PathBuf::from(".realitygap-cache"));
    cache.join("engines")
}

/// A short fingerprint of the SDK's text (FNV-1a), naming its folder so
/// that binaries of different SDKs never share one.
fn sdk_stamp() -> String {
    let mut h = Fingerprint::new();
    for (path, text) in SDK {
        h.eat(path.as_bytes()).eat(text.as_bytes());
    }
    h.hex()
}

/// The folder holding the SDK, written out on first use; the message says
/// what could not be written.
pub fn sdk_dir() -> Result<PathBuf, String> {
    let dir = engines_dir().join(format!("sdk-{}", sdk_stamp()));
    if dir.join(".complete").is_file() {
        return Ok(dir);
    }
    // Written beside and renamed into place, so that processes starting
    // at once never see a half-written SDK.
    let staging = engines_dir().join(format!("sdk-{}.{}", sdk_stamp(), std::process::id()));
    let write = || -> std::io::Result<()> {
        for (path, text) in SDK {
            let file = staging.join(path);
            std::fs::create_dir_all(file.parent().expect("has a folder"))?;
            std::fs::write(file, text)?;
        }
        std::fs::write(staging.join(".complete"), "")?;
        match std::fs::rename(&staging, &dir) {
            Ok(()) => Ok(()),
            // Another process got there first.
            Err(_) if dir.join(".complete").is_file() => {
                std::fs::remove_dir_all(&staging).ok();
                Ok(())
            }
            Err(e) => Err(e),
        }
    };
    write().map_err(|e| {
        format!(
            "cannot write the engine SDK into {}: {e}",
            staging.display()
        )
    })?;
    Ok(dir)
}

/// The folder where `scripts/setup --tests` installs the adapters that the
/// first command does not (for the engine test kit alone, so that the
/// rest of the suite sees the engines a user has after `scripts/setup`):
/// `REALITYGAP_KIT_ENGINES_DIR`, else `engines-kit/` beside
/// [`engines_dir`].
pub fn kit_engines_dir() -> PathBuf {
    std::env::var_os("REALITYGAP_KIT_ENGINES_DIR")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let dir = engines_dir();
            dir.parent()
                .map_or_else(|| PathBuf::from("engines-kit"), |p| p.join("engines-kit"))
        })
}

/// The environment of a built-in adapter.
pub fn venv_dir(adapter: &Adapter) -> PathBuf {
    venv_dir_in(adapter, &engines_dir())
}

/// The adapter's folder in the engines folder `root`: its environment
/// (`venv`), the stamp of its requirements and its children's byte code.
fn adapter_dir_in(adapter: &Adapter, root: &Path) -> PathBuf {
    root.join(adapter.name)
}

fn venv_dir_in(adapter: &Adapter, root: &Path) -> PathBuf {
    adapter_dir_in(adapter, root).join("venv")
}

/// The stamp that says the environment in `root` was made from these
/// requirements.
fn stamp_file_in(adapter: &Adapter, root: &Path) -> PathBuf {
    adapter_dir_in(adapter, root).join("requirements.txt")
}

fn stamp_file(adapter: &Adapter) -> PathBuf {
    stamp_file_in(adapter, &engines_dir())
}

/// Whether the adapter's environment is made from its current list.
pub fn is_installed(adapter: &Adapter) -> bool {
    is_installed_in(adapter, &engines_dir())
}

/// Whether the adapter's environment in the engines folder `root` is made
/// from its current list.
pub fn is_installed_in(adapter: &Adapter, root: &Path) -> bool {
    venv_dir_in(adapter, root).join("bin/python").is_file()
        && std::fs::read_to_string(stamp_file_in(adapter, root))
            .ok()
            .as_deref()
            == Some(adapter.requirements)
}

/// The line that installs an adapter.
pub fn install_line(name: &str) -> String {
    format!("realitygap engines --install {name}")
}

/// Makes the adapter's environment (a Python venv with its pinned
/// packages, from the package index pip is configured with), printing
/// pip's progress.
pub fn install(adapter: &Adapter) -> Result<(), String> {
    let dir = adapter_dir_in(adapter, &engines_dir());
    let venv = venv_dir(adapter);
    std::fs::remove_file(stamp_file(adapter)).ok();
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot make {}: {e}", dir.display()))?;
    let run = |cmd: &mut Command, what: &str| -> Result<(), String> {
        let status = cmd
            .status()
            .map_err(|e| format!("cannot run {what}: {e}"))?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("{what} failed ({status})"))
        }
    };
    if !venv.join("bin/python").is_file() {
        run(
            Command::new("python3").args(["-m", "venv"]).arg(&venv),
            "python3 -m venv (Debian: apt install python3-venv)",
        )?;
    }
    let requirements = dir.join("requirements.pending.txt");
    std::fs::write(&requirements, adapter.requirements)
        .map_err(|e| format!("cannot write {}: {e}", requirements.display()))?;
    run(
        Command::new(venv.join("bin/pip"))
            // No byte-compiling here: the children keep their own
            // (`python_launch`), so pip's would never be read.
            .args([
                "install",
                "--quiet",
                "--no-compile",
                "--disable-pip-version-check",
                "-r",
            ])
            .arg(&requirements),
        "pip install",
    )?;
    std::fs::rename(&requirements, stamp_file(adapter))
        .map_err(|e| format!("cannot write {}: {e}", stamp_file(adapter).display()))
}

/// How a Python adapter module is started with `python`, its compiled
/// bytecode kept in `pycache`.
///
/// Every module's `.pyc` goes to the adapter's own folder
/// (`PYTHONPYCACHEPREFIX`), never beside the shared SDK's sources, and is
/// written even where the caller's environment says not to
/// (`PYTHONDONTWRITEBYTECODE`): without it each child compiles its
/// engine's Python again when it starts (about 1.6 s for Newton and Warp,
/// 0.4 s for Drake, 0.3 s for MuJoCo 4, measured 2026-12-03), and the
/// engine test kit and a tune start many children.
fn python_launch(
    python: &Path,
    module: &str,
    name: &str,
    pycache: &Path,
) -> Result<Launch, String> {
    Ok(Launch {
        command: vec![python.display().to_string(), "-m".into(), module.into()],
        env: vec![
            ("PYTHONPATH".into(), sdk_path()?),
            ("REALITYGAP_ENGINE_NAME".into(), name.into()),
            ("PYTHONPYCACHEPREFIX".into(), pycache.display().to_string()),
            ("PYTHONDONTWRITEBYTECODE".into(), String::new()),
        ],
    })
}

/// `PYTHONPATH` for a child: the SDK first, then the caller's.
fn sdk_path() -> Result<String, String> {
    let sdk = sdk_dir()?.display().to_string();
    Ok(match std::env::var("PYTHONPATH") {
        Ok(p) if !p.is_empty() => format!("{sdk}:{p}"),
        _ => sdk,
    })
}

/// A built-in adapter by name.
pub fn adapter(name: &str) -> Option<&'static Adapter> {
    ADAPTERS.iter().find(|a| a.name == name)
}

/// The engine of a built-in adapter for the engine test kit: the one in
/// [`engines_dir`] when it is installed there, else the one in
/// [`kit_engines_dir`].
pub fn for_kit(name: &str) -> RemoteEngine {
    let adapter = adapter(name).unwrap_or_else(|| panic!("\"{name}\" is not a built-in adapter"));
    built_in_in(adapter, &kit_dir_of(adapter))
}

/// The engines folder a test takes an adapter from: the command's
/// ([`engines_dir`]) when the adapter is installed there, else the kit's
/// ([`kit_engines_dir`], where `scripts/setup --tests` installs every
/// adapter). A test that runs the `realitygap` binary passes it as
/// `REALITYGAP_ENGINES_DIR`.
pub fn kit_dir_of(adapter: &Adapter) -> PathBuf {
    if is_installed(adapter) {
        engines_dir()
    } else {
        kit_engines_dir()
    }
}

/// The engine of a built-in adapter: runnable when installed, else one
/// whose every load says the line that installs it.
pub fn built_in(adapter: &Adapter) -> RemoteEngine {
    built_in_in(adapter, &engines_dir())
}

/// [`built_in`] with its environment in the engines folder `root`.
pub fn built_in_in(adapter: &Adapter, root: &Path) -> RemoteEngine {
    if !is_installed_in(adapter, root) {
        return RemoteEngine::unavailable(
            adapter.name,
            format!(
                "engine \"{}\" is not installed: `{}` makes its environment ({})",
                adapter.name,
                install_line(adapter.name),
                venv_dir_in(adapter, root).display()
            ),
        );
    }
    match python_launch(
        &venv_dir_in(adapter, root).join("bin/python"),
        adapter.module,
        adapter.name,
        &adapter_dir_in(adapter, root).join("pycache"),
    ) {
        Ok(launch) => RemoteEngine::new(adapter.name, launch),
        Err(e) => RemoteEngine::unavailable(adapter.name, e),
    }
}

/// The user's engines file: `REALITYGAP_ENGINES_FILE`, else
/// `ENGINES/engines.toml`.
pub fn engines_file() -> PathBuf {
    std::env::var_os("REALITYGAP_ENGINES_FILE")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| engines_dir().join("engines.toml"))
}

/// The user's own engines of [`engines_file`] (none when it does not
/// exist); the message names the file and the entry that is wrong.
pub fn user_engines() -> Result<Vec<RemoteEngine>, String> {
    let path = engines_file();
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
    };
    let table: toml::Table =
        toml::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let Some(engines) = table.get("engine") else {
        return Ok(Vec::new());
    };
    let engines = engines
        .as_table()
        .ok_or_else(|| format!("{}: `engine` must be a table of engines", path.display()))?;
    let mut out = Vec::new();
    for (name, entry) in engines {
        let bad = |what: &str| format!("{}: [engine.{name}]: {what}", path.display());
        let valid_name = !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '-');
        if !valid_name {
            return Err(bad("a name is lowercase letters, digits, '_' and '-'"));
        }
        let command: Vec<String> = entry
            .get("command")
            .and_then(|c| c.as_array())
            .map(|a| {
                a.iter()
                    .filter_map(|v| v.as_str().map(str::to_string))
                    .collect()
            })
            .filter(|c: &Vec<String>| !c.is_empty())
            .ok_or_else(|| bad("`command` must be a non-empty list of strings"))?;
        let mut env = vec![
            ("PYTHONPATH".to_string(), sdk_path()?),
            ("REALITYGAP_ENGINE_NAME".to_string(), name.clone()),
        ];
        if let Some(vars) = entry.get("env") {
            let vars = vars
                .as_table()
                .ok_or_else(|| bad("`env` must be a table of strings"))?;
            for (k, v) in vars {
                let v = v
                    .as_str()
                    .ok_or_else(|| bad("`env` values must be strings"))?;
                env.push((k.clone(), v.to_string()));
            }
        }
        out.push(RemoteEngine::new(name, Launch { command, env }));
    }
    Ok(out)
}

/// Every engine out of process that can run: the installed built-in
/// adapters and the user's own engines (an unreadable engines file is
/// reported on standard error and adds none), found once per process.
pub fn available() -> Vec<RemoteEngine> {
    static AVAILABLE: std::sync::OnceLock<Vec<RemoteEngine>> = std::sync::OnceLock::new();
    AVAILABLE.get_or_init(find_available).clone()
}

fn find_available() -> Vec<RemoteEngine> {
    let mut engines: Vec<RemoteEngine> = ADAPTERS
        .iter()
        .filter(|a| is_installed(a))
        .map(built_in)
        .collect();
    match user_engines() {
        Ok(user) => engines.extend(user),
        Err(e) => eprintln!("warning: {e}"),
    }
    engines
}
