//! Bullet's own messages, routed away from standard output.
//!
//! Bullet prints its `b3Printf`, `b3Warning` and `b3Error` messages with
//! `printf` unless hooks are installed (`b3SetCustomPrintfFunc`,
//! `b3SetCustomWarningMessageFunc`, `b3SetCustomErrorMessageFunc` of
//! `Bullet3Common/b3Logging.h`). Standard output belongs to the program
//! (`realitygap run` children write their result there), so
//! [`install_message_handler`] routes the three streams to the `log` crate
//! (target `bullet`: printf as debug, warnings as warn, errors as error) and
//! keeps the most recent ones, which the engine puts into its error
//! messages (e.g. why Bullet refused a URDF file).
//!
//! Bullet writes a warning or an error in two calls: a location line
//! (`b3Warning[file,line]:`) and then the message; they are joined here.

use crate::ffi;
use std::ffi::{c_char, CStr};
use std::sync::Mutex;

/// How serious a Bullet message is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// `b3Printf`: information.
    Info,
    /// `b3Warning`.
    Warning,
    /// `b3Error`.
    Error,
}

/// One message Bullet reported.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BulletMessage {
    /// Its level.
    pub level: Level,
    /// The text, with the source location Bullet gave (`file:line: text`).
    pub text: String,
}

impl std::fmt::Display for BulletMessage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let level = match self.level {
            Level::Info => "info",
            Level::Warning => "warning",
            Level::Error => "error",
        };
        write!(f, "Bullet {level}: {}", self.text)
    }
}

/// Most messages kept between two [`take_messages`] calls.
const KEPT: usize = 64;

struct Log {
    kept: Vec<BulletMessage>,
    /// Location line of a warning/error whose text comes in the next call.
    pending_location: Option<String>,
    /// A printf line not finished yet.
    partial_line: String,
}

static LOG: Mutex<Log> = Mutex::new(Log {
    kept: Vec::new(),
    pending_location: None,
    partial_line: String::new(),
});

fn with_log<R>(f: impl FnOnce(&mut Log) -> R) -> R {
    let mut log = LOG.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    f(&mut log)
}

fn keep(log: &mut Log, level: Level, text: String) {
    let text = text.trim().to_string();
    if text.is_empty() {
        return;
    }
    match level {
        Level::Info => log::debug!(target: "bullet", "{text}"),
        Level::Warning => log::warn!(target: "bullet", "{text}"),
        Level::Error => log::error!(target: "bullet", "{text}"),
    }
    if log.kept.len() == KEPT {
        log.kept.remove(0);
    }
    log.kept.push(BulletMessage { level, text });
}

/// `b3Warning[examples/Importers/X.cpp,126]:` -> `X.cpp:126`.
fn location(fragment: &str) -> Option<String> {
    let rest = fragment
        .strip_prefix("b3Warning[")
        .or_else(|| fragment.strip_prefix("b3Error["))?;
    let inside = rest.trim_end().strip_suffix("]:")?;
    let (file, line) = inside.rsplit_once(',')?;
    let file = file.rsplit('/').next().unwrap_or(file);
    Some(format!("{file}:{line}"))
}

/// Takes one fragment Bullet wrote.
fn record(level: Level, fragment: &str) {
    with_log(|log| match level {
        Level::Info => {
            log.partial_line.push_str(fragment);
            while let Some(end) = log.partial_line.find('\n') {
                let line: String = log.partial_line.drain(..=end).collect();
                keep(log, Level::Info, line);
            }
        }
        Level::Warning | Level::Error => {
            if let Some(loc) = location(fragment) {
                log.pending_location = Some(loc);
            } else {
                let text = match log.pending_location.take() {
                    Some(loc) => format!("{loc}: {}", fragment.trim()),
                    None => fragment.to_string(),
                };
                keep(log, level, text);
            }
        }
    })
}

fn fragment(message: *const c_char) -> String {
    if message.is_null() {
        return String::new();
    }
    // SAFETY: Bullet passes a NUL-terminated buffer valid for this call.
    unsafe { CStr::from_ptr(message) }
        .to_string_lossy()
        .into_owned()
}

unsafe extern "C" fn on_printf(message: *const c_char) {
    record(Level::Info, &fragment(message));
}

unsafe extern "C" fn on_warning(message: *const c_char) {
    record(Level::Warning, &fragment(message));
}

unsafe extern "C" fn on_error(message: *const c_char) {
    record(Level::Error, &fragment(message));
}

/// Routes Bullet's printf, warning and error output to the `log` crate
/// (target `bullet`) and to [`take_messages`], never to standard output.
/// The engine calls it before it creates a Bullet world; calling it again
/// does nothing.
pub fn install_message_handler() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _guard = ffi::lock();
        // SAFETY: the hooks are plain function pointers with the signature
        // b3Logging.h expects; the Bullet lock is held.
        unsafe {
            ffi::b3SetCustomPrintfFunc(Some(on_printf));
            ffi::b3SetCustomWarningMessageFunc(Some(on_warning));
            ffi::b3SetCustomErrorMessageFunc(Some(on_error));
        }
    });
}

/// The Bullet messages kept since the last call (at most 64, oldest first).
pub fn take_messages() -> Vec<BulletMessage> {
    with_log(|log| {
        if !log.partial_line.is_empty() {
            let line = std::mem::take(&mut log.partial_line);
            keep(log, Level::Info, line);
        }
        log.pending_location = None;
        std::mem::take(&mut log.kept)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joins_locations_and_lines() {
        let _guard = crate::ffi::lock();
        take_messages();
        record(
            Level::Warning,
            "b3Warning[examples/Importers/ImportURDFDemo/BulletUrdfImporter.cpp,126]:\n",
        );
        record(Level::Warning, "No inertial data for link, using mass=1");
        record(Level::Info, "first ");
        record(Level::Info, "line\nsecond");
        record(Level::Error, "b3Error[examples/X.cpp,7]:\n");
        record(Level::Error, "bad\n");
        let m = take_messages();
        assert_eq!(
            m,
            vec![
                BulletMessage {
                    level: Level::Warning,
                    text: "BulletUrdfImporter.cpp:126: No inertial data for link, using mass=1"
                        .into()
                },
                BulletMessage {
                    level: Level::Info,
                    text: "first line".into()
                },
                BulletMessage {
                    level: Level::Error,
                    text: "X.cpp:7: bad".into()
                },
                BulletMessage {
                    level: Level::Info,
                    text: "second".into()
                },
            ]
        );
        assert!(take_messages().is_empty());
        assert_eq!(m[2].to_string(), "Bullet error: X.cpp:7: bad");
    }

    #[test]
    fn keeps_the_most_recent_messages() {
        let _guard = crate::ffi::lock();
        take_messages();
        for i in 0..100 {
            record(Level::Warning, &format!("w{i}"));
        }
        let m = take_messages();
        assert_eq!(m.len(), KEPT);
        assert_eq!(m[0].text, "w36");
        assert_eq!(m[63].text, "w99");
    }
}
