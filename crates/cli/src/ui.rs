//! Where the commands' long calls report: [`Ui`]. The command draws
//! progress bars on standard error and prints results on standard output
//! ([`Terminal`]); the Python package passes them on to Python (a tqdm bar
//! and its own streams).

use indicatif::{ProgressBar, ProgressStyle};
use realitygap_runner::Progress;
use std::io::Write;

/// A progress bar of a long call: the runner's [`Progress`] (lines, steps,
/// message) and a position.
pub trait Bar: Progress + Sync {
    /// Sets the position (items done).
    fn set_position(&self, n: u64);
    /// Removes the bar.
    fn finish(&self);
}

/// Where a long call reports.
pub trait Ui: Sync {
    /// A note on the call's progress (the command: standard error).
    fn note(&self, line: String);
    /// A line of the call's result (the command: standard output).
    fn say(&self, line: String);
    /// A new bar over `total` items named `unit` (`runs`, `replays`,
    /// `evaluations`; 0: a spinner with no known end).
    fn bar(&self, total: u64, unit: &str) -> Box<dyn Bar + '_>;
}

/// The command's terminal: indicatif bars on standard error.
pub struct Terminal;

/// An indicatif bar.
pub struct TerminalBar(pub ProgressBar);

impl Progress for TerminalBar {
    fn println(&self, line: String) {
        // Above the bar, and on standard error also when the bar is hidden
        // (not a terminal), where indicatif's own println writes nothing.
        self.0.suspend(|| eprintln!("{line}"));
    }
    fn inc(&self, n: u64) {
        self.0.inc(n);
    }
    fn set_message(&self, message: String) {
        self.0.set_message(message);
    }
}

impl Bar for TerminalBar {
    fn set_position(&self, n: u64) {
        self.0.set_position(n);
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

/// An error with its causes, `a: b: c`, as `{:#}` prints it, but without
/// a cause that the message before it already ends with (an error that
/// shows its source in its own message, as `thiserror`'s `{source}` does,
/// and also hands it on as its cause, would otherwise print it twice).
pub fn error_text(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out == text || out.ends_with(&format!(": {text}")) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// Colours a line for a terminal by what it says: warnings and errors,
/// the closest-source verdicts, the flag kinds, the verdict on the
/// physics-free model, where the files are. anstream's streams drop the
/// styles when the stream is not a terminal, or NO_COLOR is set
/// (CLICOLOR_FORCE forces them).
pub fn paint(line: &str) -> String {
    use anstyle::{AnsiColor, Style};
    let warn = Style::new().fg_color(Some(AnsiColor::Yellow.into())).bold();
    let err = Style::new().fg_color(Some(AnsiColor::Red.into())).bold();
    let good = Style::new().fg_color(Some(AnsiColor::Green.into())).bold();
    let path = Style::new().fg_color(Some(AnsiColor::Cyan.into()));
    let bold = Style::new().bold();
    let styled = |style: Style, head: &str, rest: &str| format!("{style}{head}{style:#}{rest}");
    for (prefix, style) in [("warning:", warn), ("error:", err)] {
        if let Some(rest) = line.strip_prefix(prefix) {
            return styled(style, prefix, rest);
        }
    }
    for prefix in ["report: ", "tables: ", "runs: "] {
        if let Some(rest) = line.strip_prefix(prefix) {
            return format!("{bold}{prefix}{bold:#}{path}{rest}{path:#}");
        }
    }
    if let Some(at) = line.find(": closest source: ") {
        let (head, rest) = line.split_at(at + ": closest source: ".len());
        let end = rest.find(" (closer").unwrap_or(rest.len());
        return format!("{head}{good}{}{good:#}{}", &rest[..end], &rest[end..]);
    }
    if line.starts_with("- ") {
        if let Some(at) = line.find(": ") {
            let name = &line[2..at];
            if !name.contains(' ') && name.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
                return format!("- {warn}{name}{warn:#}{}", &line[at..]);
            }
        }
    }
    if line.starts_with("Flagged runs") {
        return styled(warn, line, "");
    }
    line.to_string()
}

impl Ui for Terminal {
    fn note(&self, line: String) {
        let mut err = anstream::stderr().lock();
        let _ = writeln!(err, "{}", paint(&line));
    }
    fn say(&self, line: String) {
        // A closed pipe (`| head`) is not an error worth a panic.
        let mut out = anstream::stdout().lock();
        for l in line.split('\n') {
            let _ = writeln!(out, "{}", paint(l));
        }
    }
    fn bar(&self, total: u64, unit: &str) -> Box<dyn Bar + '_> {
        let bar = if total == 0 {
            let bar = ProgressBar::new_spinner();
            bar.set_style(
                ProgressStyle::with_template(&format!(
                    "{{spinner}} {{elapsed_precise}} {{pos}} {unit}, {{msg}}"
                ))
                .expect("a valid template"),
            );
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            bar
        } else if unit == "evaluations" {
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(
                    "{elapsed_precise} [{bar:30}] {pos}/{len} evaluations, {msg}",
                )
                .expect("a valid template")
                .progress_chars("=> "),
            );
            bar
        } else {
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(&format!(
                    "{{spinner}} [{{elapsed_precise}}] {{wide_bar}} {{pos}}/{{len}} {unit} ({{eta}} left) {{msg}}"
                ))
                .expect("a valid template"),
            );
            bar
        };
        Box::new(TerminalBar(bar))
    }
}

#[cfg(test)]
mod error_text_tests {
    use super::error_text;

    /// An error that shows its source in its message and hands it on.
    #[derive(Debug)]
    struct Shows {
        source: std::io::Error,
    }
    impl std::fmt::Display for Shows {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "cannot read URDF file nope.urdf: {}", self.source)
        }
    }
    impl std::error::Error for Shows {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.source)
        }
    }

    #[test]
    fn a_cause_already_in_its_message_is_said_once() {
        let io = || std::io::Error::from(std::io::ErrorKind::NotFound);
        let shown = anyhow::Error::new(Shows { source: io() }).context("importing");
        let text = error_text(&shown);
        assert_eq!(text.matches(&io().to_string()).count(), 1, "{text}");
        assert!(
            text.starts_with("importing: cannot read URDF file nope.urdf: "),
            "{text}"
        );
        // A cause not in the message before it stays.
        let plain = anyhow::Error::new(io()).context("reading x.toml");
        assert_eq!(error_text(&plain), format!("reading x.toml: {}", io()));
    }
}
