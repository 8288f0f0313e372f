//! Engine children forked from a zygote: the engine's process starts (and
//! imports its libraries) once, and every later child is a fork of it.
//!
//! Starting a Python engine costs seconds (`import newton` alone takes
//! 4.6 s of CPU), and a batch runs each simulation in a process of its own
//! (`realitygap __run-one`), which starts the engine again. So the first
//! child of an engine in a process is asked to become a *zygote* (the
//! protocol's optional `zygote` request, docs/engine-protocol.md): it
//! listens on a Unix socket and stops serving requests itself. Each child
//! after that is a fork of it: realitygap makes the child's three pipes,
//! sends their far ends over the socket (SCM_RIGHTS), and gets back the
//! child's process id and a pidfd (its handle to kill the child, which is
//! the zygote's and not its own). The socket's path goes to the processes
//! a batch starts in `REALITYGAP_ENGINE_ZYGOTES` ([`handed_down`], set by
//! the runner on each command), so a batch's runs fork from their parent's
//! zygote too.
//!
//! - An engine that does not answer `zygote` with its socket (an adapter
//!   in another language, or an older SDK) keeps the old way: that first
//!   child serves as an ordinary one and every child is started afresh.
//! - A zygote that cannot be reached (gone, or on another machine, as a
//!   Slurm task's parent's) is passed over: the child is started afresh.
//! - A zygote ends when the process that started it ends (its standard
//!   input closes), and removes its socket.
//! - `REALITYGAP_ENGINE_NO_ZYGOTE=1` starts every child afresh.

use crate::child::{Child, Failure, Launch};
use realitygap_core::fingerprint::Fingerprint;
use serde_json::{json, Map, Value};
use std::collections::HashMap;
use std::io::{IoSlice, IoSliceMut};
use std::mem::MaybeUninit;
use std::os::fd::AsFd;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

/// The zygotes' sockets a process hands to the processes it starts: a
/// JSON object from each engine launch's key to its socket's path.
pub const ZYGOTES_ENV: &str = "REALITYGAP_ENGINE_ZYGOTES";

/// Set (to anything but empty or `0`), every child is started afresh.
pub const NO_ZYGOTE_ENV: &str = "REALITYGAP_ENGINE_NO_ZYGOTE";

/// What this process knows of an engine launch's zygote.
enum State {
    /// Listening at the path; the zygote's own child handle is kept for
    /// the process's life (its input closing ends the zygote).
    Ready(PathBuf, #[allow(dead_code)] Child),
    /// The engine does not fork: children are started afresh.
    Unsupported,
}

fn states() -> &'static Mutex<HashMap<String, State>> {
    static STATES: OnceLock<Mutex<HashMap<String, State>>> = OnceLock::new();
    STATES.get_or_init(Default::default)
}

/// A launch's key: FNV-1a over its command and environment (the same in
/// every process of a batch, whatever the build).
pub fn key(launch: &Launch) -> String {
    let mut h = Fingerprint::new();
    for part in &launch.command {
        h.field(part.as_bytes());
    }
    h.field(b"env");
    for (k, v) in &launch.env {
        h.field(k.as_bytes()).field(v.as_bytes());
    }
    h.hex()
}

/// The zygotes handed down by the process that started this one, read
/// once (realitygap never changes its own environment).
fn inherited() -> &'static Map<String, Value> {
    static INHERITED: OnceLock<Map<String, Value>> = OnceLock::new();
    INHERITED.get_or_init(|| {
        std::env::var(ZYGOTES_ENV)
            .ok()
            .and_then(|text| serde_json::from_str::<Value>(&text).ok())
            .and_then(|v| v.as_object().cloned())
            .unwrap_or_default()
    })
}

fn disabled() -> bool {
    std::env::var(NO_ZYGOTE_ENV).is_ok_and(|v| !v.is_empty() && v != "0")
}

/// A child of `launch`: forked from its zygote (the parent process's, or
/// this one's, which its first child becomes), else started afresh.
pub(crate) fn spawn(launch: &Launch, timeout: Duration) -> Result<Child, String> {
    if disabled() {
        return Child::spawn_process(launch, timeout);
    }
    let key = key(launch);
    if let Some(path) = inherited().get(&key).and_then(Value::as_str) {
        if let Ok(child) = fork_from(Path::new(path), timeout) {
            return Ok(child);
        }
    }
    // The lock is held while a zygote starts, so that a launch gets one.
    let mut states = states().lock().unwrap_or_else(|e| e.into_inner());
    match states.get(&key) {
        Some(State::Ready(path, _)) => {
            let path = path.clone();
            drop(states);
            return fork_from(&path, timeout).or_else(|_| Child::spawn_process(launch, timeout));
        }
        Some(State::Unsupported) => {
            drop(states);
            return Child::spawn_process(launch, timeout);
        }
        None => {}
    }
    let mut first = Child::spawn_process(launch, timeout)?;
    let path = socket_path();
    let asked = path.display().to_string();
    match first.call(&json!({"op": "zygote", "socket": asked})) {
        Ok(ok) if ok.get("socket").and_then(Value::as_str) == Some(asked.as_str()) => {
            states.insert(key, State::Ready(path.clone(), first));
            drop(states);
            fork_from(&path, timeout).or_else(|_| Child::spawn_process(launch, timeout))
        }
        // It answered as a child that does not fork: it serves as one.
        Ok(_) | Err(Failure::Engine { .. }) => {
            states.insert(key, State::Unsupported);
            Ok(first)
        }
        Err(Failure::Broken(_)) => {
            states.insert(key, State::Unsupported);
            drop(states);
            drop(first);
            Child::spawn_process(launch, timeout)
        }
    }
}

/// A fresh socket path in the temporary folder (short: a Unix socket's
/// path has at most 107 bytes).
fn socket_path() -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let name = format!("rg-zygote-{}-{n}.sock", std::process::id());
    let dir = std::env::temp_dir();
    if dir.join(&name).as_os_str().len() < 100 {
        dir.join(name)
    } else {
        Path::new("/tmp").join(name)
    }
}

/// The environment variable (name and value) that hands this process's
/// zygotes, and those it inherited, to a process it starts; `None` when it
/// knows of none. Whoever starts realitygap processes that may run an
/// engine out of process (the runner's batches) sets it on their command:
/// kept apart from the process's own environment, which a process with
/// threads must not change (a native library may be reading it).
pub fn handed_down() -> Option<(&'static str, String)> {
    let mut all = inherited().clone();
    let states = states().lock().unwrap_or_else(|e| e.into_inner());
    for (key, state) in states.iter() {
        if let State::Ready(path, _) = state {
            all.insert(key.clone(), Value::String(path.display().to_string()));
        }
    }
    (!all.is_empty()).then(|| (ZYGOTES_ENV, Value::Object(all).to_string()))
}

/// Asks the zygote at `path` for a child over three new pipes.
fn fork_from(path: &Path, timeout: Duration) -> Result<Child, String> {
    use rustix::net::{
        recvmsg, sendmsg, RecvAncillaryBuffer, RecvAncillaryMessage, RecvFlags,
        SendAncillaryBuffer, SendAncillaryMessage, SendFlags,
    };
    let e = |what: &str, err: std::io::Error| format!("{what} ({}): {err}", path.display());
    let socket = UnixStream::connect(path).map_err(|err| e("cannot reach the zygote", err))?;
    socket
        .set_read_timeout(Some(timeout))
        .and_then(|_| socket.set_write_timeout(Some(timeout)))
        .map_err(|err| e("zygote socket", err))?;
    let (in_read, in_write) = std::io::pipe().map_err(|err| e("pipe", err))?;
    let (out_read, out_write) = std::io::pipe().map_err(|err| e("pipe", err))?;
    let (err_read, err_write) = std::io::pipe().map_err(|err| e("pipe", err))?;
    {
        let fds = [in_read.as_fd(), out_write.as_fd(), err_write.as_fd()];
        let mut space = [MaybeUninit::uninit(); rustix::cmsg_space!(ScmRights(3))];
        let mut control = SendAncillaryBuffer::new(&mut space);
        control.push(SendAncillaryMessage::ScmRights(&fds));
        sendmsg(
            &socket,
            &[IoSlice::new(b"fork\n")],
            &mut control,
            SendFlags::empty(),
        )
        .map_err(|err| e("cannot ask the zygote for a child", err.into()))?;
    }
    // The child holds its ends now; ours close, so that its end of input
    // and ours of its output follow the child alone.
    drop((in_read, out_write, err_write));
    let mut text = [0u8; 64];
    let mut space = [MaybeUninit::uninit(); rustix::cmsg_space!(ScmRights(1))];
    let mut control = RecvAncillaryBuffer::new(&mut space);
    let got = recvmsg(
        &socket,
        &mut [IoSliceMut::new(&mut text)],
        &mut control,
        RecvFlags::CMSG_CLOEXEC,
    )
    .map_err(|err| e("no answer from the zygote", err.into()))?;
    let mut pidfd = None;
    for message in control.drain() {
        if let RecvAncillaryMessage::ScmRights(fds) = message {
            for fd in fds {
                pidfd.get_or_insert(fd);
            }
        }
    }
    let answer = String::from_utf8_lossy(&text[..got.bytes]);
    let pidfd = pidfd.ok_or_else(|| {
        format!(
            "the zygote ({}) answered {:?} without the child's pidfd",
            path.display(),
            answer.trim()
        )
    })?;
    Ok(Child::forked(pidfd, in_write, out_read, err_read, timeout))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_launch_key_follows_its_command_and_environment() {
        let a = Launch {
            command: vec!["python".into(), "-m".into(), "x".into()],
            env: vec![("A".into(), "1".into())],
        };
        let mut b = a.clone();
        assert_eq!(key(&a), key(&b));
        b.env[0].1 = "2".into();
        assert_ne!(key(&a), key(&b));
        // Parts are delimited: ["ab", "c"] is not ["a", "bc"].
        let c = Launch {
            command: vec!["ab".into(), "c".into()],
            env: vec![],
        };
        let d = Launch {
            command: vec!["a".into(), "bc".into()],
            env: vec![],
        };
        assert_ne!(key(&c), key(&d));
        assert_eq!(key(&a).len(), 16);
    }
}
