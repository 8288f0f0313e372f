//! One engine child process: a request written as a line to its standard
//! input, one reply line read from its standard output within the
//! timeout. Its standard error is kept (the last lines) for the messages
//! of a child that fails. A child that exits, hangs past the timeout,
//! closes its output or writes a line that is not a reply is killed, and
//! every later request fails with the same reason.

use serde_json::{Map, Value};
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::fd::OwnedFd;
use std::process::{Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How an engine child is started.
#[derive(Debug, Clone, PartialEq)]
pub struct Launch {
    /// The program and its arguments.
    pub command: Vec<String>,
    /// Environment variables set for it.
    pub env: Vec<(String, String)>,
}

/// The standard error lines kept for messages.
const STDERR_LINES: usize = 12;

/// A request that did not get an `ok` reply.
#[derive(Debug, Clone, PartialEq)]
pub enum Failure {
    /// The child answered with an `error` reply.
    Engine {
        /// `setting`, `load`, `param`, `unstable`, `state` or `usage`.
        kind: String,
        /// The child's message.
        message: String,
        /// The setting or parameter key, when the reply gave one.
        key: Option<String>,
        /// For `unstable`: the simulated time it happened at, s, when the
        /// reply gave it.
        t_s: Option<f64>,
    },
    /// The child broke the protocol or died: the reason, with the last
    /// lines of its standard error.
    Broken(String),
}

impl Failure {
    /// The failure an `error` object reports (`kind`, `message`, and `key`
    /// and `t_s` when given), its kind `default_kind` when it names none.
    pub fn from_error(error: &Value, default_kind: &str) -> Failure {
        let text = |k: &str| error.get(k).and_then(Value::as_str).map(str::to_string);
        Failure::Engine {
            kind: text("kind").unwrap_or_else(|| default_kind.into()),
            message: text("message").unwrap_or_else(|| "(no message)".into()),
            key: text("key"),
            t_s: error.get("t_s").and_then(Value::as_f64),
        }
    }
}

/// An engine child's process.
enum Process {
    /// Started by this process.
    Spawned(std::process::Child),
    /// Forked by a zygote ([`crate::zygote`]): not this process's child,
    /// so it is killed and waited for through its pidfd.
    Forked(OwnedFd),
}

impl Process {
    /// Kills the process and waits for its end; its exit status when it
    /// was this process's child.
    fn kill_and_wait(&mut self) -> Option<std::process::ExitStatus> {
        match self {
            Process::Spawned(child) => {
                let _ = child.kill();
                child.wait().ok()
            }
            Process::Forked(pidfd) => {
                use rustix::io::Errno;
                match rustix::process::pidfd_send_signal(&*pidfd, rustix::process::Signal::KILL) {
                    // Sent, or the process had already ended: wait below.
                    Ok(()) | Err(Errno::SRCH) => {}
                    // Not ours to kill (it is always our own uid, so this
                    // should not happen): waiting could block for ever.
                    Err(_) => return None,
                }
                // A pidfd becomes readable when its process has ended. A
                // killed process ends at once unless the kernel holds it
                // (uninterruptible I/O); the wait is bounded all the same,
                // so a stuck process never hangs the batch.
                let bound = rustix::event::Timespec {
                    tv_sec: 10,
                    tv_nsec: 0,
                };
                let mut fds = [rustix::event::PollFd::new(
                    &*pidfd,
                    rustix::event::PollFlags::IN,
                )];
                while let Err(Errno::INTR) = rustix::event::poll(&mut fds, Some(&bound)) {}
                None
            }
        }
    }
}

/// A running engine child.
pub struct Child {
    process: Process,
    stdin: Option<Box<dyn Write + Send>>,
    lines: Receiver<std::io::Result<String>>,
    stderr: Arc<Mutex<VecDeque<String>>>,
    stderr_reader: Option<JoinHandle<()>>,
    timeout: Duration,
    broken: Option<String>,
}

impl Child {
    /// Starts the child, forked by the engine's zygote where it has one
    /// ([`crate::zygote`]); `timeout` bounds the wait for each reply.
    pub fn spawn(launch: &Launch, timeout: Duration) -> Result<Child, String> {
        crate::zygote::spawn(launch, timeout)
    }

    /// Starts the child as a process of its own.
    pub(crate) fn spawn_process(launch: &Launch, timeout: Duration) -> Result<Child, String> {
        let (program, args) = launch
            .command
            .split_first()
            .ok_or("the engine's command is empty")?;
        let mut process = Command::new(program)
            .args(args)
            .envs(launch.env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start `{}`: {e}", launch.command.join(" ")))?;
        let stdin = process.stdin.take().expect("piped");
        let stdout = process.stdout.take().expect("piped");
        let stderr = process.stderr.take().expect("piped");
        Ok(Child::over(
            Process::Spawned(process),
            Box::new(stdin),
            stdout,
            stderr,
            timeout,
        ))
    }

    /// A child forked by a zygote, over the pipes it took as its standard
    /// streams; `pidfd` is its handle.
    pub(crate) fn forked(
        pidfd: OwnedFd,
        stdin: impl Write + Send + 'static,
        stdout: impl Read + Send + 'static,
        stderr: impl Read + Send + 'static,
        timeout: Duration,
    ) -> Child {
        Child::over(
            Process::Forked(pidfd),
            Box::new(stdin),
            stdout,
            stderr,
            timeout,
        )
    }

    fn over(
        process: Process,
        stdin: Box<dyn Write + Send>,
        stdout: impl Read + Send + 'static,
        stderr_pipe: impl Read + Send + 'static,
        timeout: Duration,
    ) -> Child {
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stdout);
            loop {
                let mut line = String::new();
                match reader.read_line(&mut line) {
                    Ok(0) => break,
                    Ok(_) => {
                        if tx.send(Ok(line)).is_err() {
                            break;
                        }
                    }
                    Err(e) => {
                        let _ = tx.send(Err(e));
                        break;
                    }
                }
            }
        });
        let stderr = Arc::new(Mutex::new(VecDeque::new()));
        let kept = Arc::clone(&stderr);
        let stderr_reader = std::thread::spawn(move || {
            for line in BufReader::new(stderr_pipe).lines() {
                let Ok(line) = line else { break };
                let mut kept = kept.lock().unwrap_or_else(|e| e.into_inner());
                if kept.len() == STDERR_LINES {
                    kept.pop_front();
                }
                kept.push_back(line);
            }
        });
        Child {
            stdin: Some(stdin),
            process,
            lines,
            stderr,
            stderr_reader: Some(stderr_reader),
            timeout,
            broken: None,
        }
    }

    /// Whether the child failed (and was stopped).
    pub fn is_broken(&self) -> bool {
        self.broken.is_some()
    }

    /// Sets the wait for each reply.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// Kills the child and collects its standard error: `reason` with the
    /// last lines, which every later request repeats.
    fn fail(&mut self, reason: String) -> Failure {
        let status = self.process.kill_and_wait();
        // The standard error pipe closes with the process: its reader has
        // then kept everything the child wrote.
        if let Some(reader) = self.stderr_reader.take() {
            let _ = reader.join();
        }
        let mut message = reason;
        if let Some(code) = status.and_then(|s| s.code()) {
            message.push_str(&format!(" (exit status {code})"));
        }
        let tail = self.stderr.lock().unwrap_or_else(|e| e.into_inner());
        if !tail.is_empty() {
            message.push_str("; its last messages:\n  ");
            message.push_str(&tail.iter().cloned().collect::<Vec<_>>().join("\n  "));
        }
        self.broken = Some(message.clone());
        Failure::Broken(message)
    }

    /// Sends `request` (its `op` names it in messages) and returns the
    /// reply's `ok` object.
    pub fn call(&mut self, request: &Value) -> Result<Map<String, Value>, Failure> {
        if let Some(reason) = &self.broken {
            return Err(Failure::Broken(reason.clone()));
        }
        let op = request["op"].as_str().unwrap_or("?").to_string();
        let mut line = request.to_string();
        line.push('\n');
        // The reply must come within the timeout of the request's sending,
        // whenever this thread looks: a reply already waiting when it is
        // late (this thread slept) is late too, so a tight timeout fails the
        // same under any load.
        let deadline = Instant::now() + self.timeout;
        let written = match self.stdin.as_mut() {
            Some(stdin) => stdin.write_all(line.as_bytes()).and_then(|_| stdin.flush()),
            None => Err(std::io::Error::other("input closed")),
        };
        if let Err(e) = written {
            return Err(self.fail(format!(
                "the engine process stopped reading before \"{op}\" ({e})"
            )));
        }
        let received = self
            .lines
            .recv_timeout(deadline.saturating_duration_since(Instant::now()));
        let late = Instant::now() > deadline;
        let reply = match received {
            Ok(Ok(text)) if !late => text,
            Ok(Err(e)) => return Err(self.fail(format!("cannot read the reply to \"{op}\": {e}"))),
            Err(RecvTimeoutError::Disconnected) => {
                return Err(self.fail(format!(
                    "the engine process exited before replying to \"{op}\""
                )))
            }
            Ok(Ok(_)) | Err(RecvTimeoutError::Timeout) => {
                return Err(self.fail(format!(
                    "no reply to \"{op}\" within {} s (timeout_s); the engine process was stopped",
                    self.timeout.as_secs_f64()
                )))
            }
        };
        let parsed: Value = match serde_json::from_str(reply.trim_end()) {
            Ok(v) => v,
            Err(e) => {
                let shown: String = reply.trim_end().chars().take(120).collect();
                return Err(self.fail(format!(
                    "the reply to \"{op}\" is not JSON ({e}): \"{shown}\""
                )));
            }
        };
        if let Some(ok) = parsed.get("ok").and_then(Value::as_object) {
            return Ok(ok.clone());
        }
        if let Some(error) = parsed.get("error").filter(|e| e.is_object()) {
            return Err(Failure::from_error(error, "usage"));
        }
        let shown: String = reply.trim_end().chars().take(120).collect();
        Err(self.fail(format!(
            "the reply to \"{op}\" is neither {{\"ok\": ...}} nor {{\"error\": ...}}: \"{shown}\""
        )))
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        // Closing its input is the child's signal to exit; it is killed in
        // case it does not.
        self.stdin.take();
        self.process.kill_and_wait();
    }
}
