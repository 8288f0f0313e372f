//! Provenance: what produced a report, so that a reader can reproduce it.

use realitygap_analysis::AnalysisMode;
use serde::Serialize;
use std::time::{SystemTime, UNIX_EPOCH};

/// Where a report's numbers came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Provenance {
    /// Title of the report (e.g. the study's title).
    pub title: String,
    /// Version of realitygap that made the report.
    pub tool_version: String,
    /// When the report was made, UTC, ISO 8601 (`2025-01-31T12:00:00Z`).
    pub generated_utc: String,
    /// The command line that made it, shell-quoted.
    pub command_line: String,
    /// The study file, when there is one.
    pub study: Option<String>,
    /// The data folder the recordings were read from.
    pub data_dir: Option<String>,
    /// The results folder simulated runs were read from.
    pub results_dir: Option<String>,
    /// The analysis mode.
    pub mode: AnalysisMode,
    /// Other facts about the whole report, as (key, value).
    pub details: Vec<(String, String)>,
    /// Per source: engine and version, parameters, seeds, files, ...
    pub sources: Vec<SourceProvenance>,
    /// The handovers of stitched sources, drawn in their figures.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub handovers: Vec<HandoverMarks>,
}

/// When a stitched source handed its run from one engine to the next in
/// one scene (from its results directory's manifest).
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct HandoverMarks {
    /// The scene.
    pub scene: String,
    /// The source's name, as in the reports.
    pub source: String,
    /// Handover times, seconds.
    pub times_s: Vec<f64>,
}

/// Free-form facts about one source, as (key, value) pairs in display
/// order, e.g. `("engine", "mujoco 3.1.6")`, `("timestep_s", "0.0001")`,
/// `("seeds", "0-19")`.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct SourceProvenance {
    /// Source name, as in the reports.
    pub name: String,
    /// (key, value) pairs.
    pub details: Vec<(String, String)>,
}

impl SourceProvenance {
    /// A source with no details yet.
    pub fn new(name: impl Into<String>) -> SourceProvenance {
        SourceProvenance {
            name: name.into(),
            details: Vec::new(),
        }
    }

    /// Adds a (key, value) pair; returns `self` for chaining.
    pub fn with(mut self, key: impl Into<String>, value: impl Into<String>) -> SourceProvenance {
        self.details.push((key.into(), value.into()));
        self
    }
}

impl Provenance {
    /// Provenance of a report made now by this process: the tool version,
    /// the current time and this process's command line; no folders, no
    /// sources, default mode.
    pub fn new(title: impl Into<String>) -> Provenance {
        Provenance {
            title: title.into(),
            tool_version: realitygap_core::TOOL_VERSION.to_string(),
            generated_utc: utc_timestamp(SystemTime::now()),
            command_line: shell_join(std::env::args()),
            study: None,
            data_dir: None,
            results_dir: None,
            mode: AnalysisMode::Default,
            details: Vec::new(),
            sources: Vec::new(),
            handovers: Vec::new(),
        }
    }
}

/// Joins arguments into one command line, quoting those that a POSIX shell
/// would split or expand.
pub fn shell_join<I: IntoIterator<Item = S>, S: AsRef<str>>(args: I) -> String {
    args.into_iter()
        .map(|a| {
            let a = a.as_ref();
            let plain = !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
            if plain {
                a.to_string()
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Formats a time as UTC ISO 8601 with seconds (`1970-01-01T00:00:00Z`);
/// times before 1970 print as the epoch.
pub fn utc_timestamp(t: SystemTime) -> String {
    let secs = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Days since 1970-01-01 to (year, month, day) in the proleptic Gregorian
/// calendar (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn timestamps() {
        assert_eq!(utc_timestamp(UNIX_EPOCH), "1970-01-01T00:00:00Z");
        // 2000-02-29 12:34:56 UTC (a leap day).
        assert_eq!(
            utc_timestamp(UNIX_EPOCH + Duration::from_secs(951_827_696)),
            "2000-02-29T12:34:56Z"
        );
        // 2024-12-31 23:59:59 UTC.
        assert_eq!(
            utc_timestamp(UNIX_EPOCH + Duration::from_secs(1_735_689_599)),
            "2024-12-31T23:59:59Z"
        );
    }

    #[test]
    fn quoting() {
        assert_eq!(
            shell_join(["realitygap", "report", "a b.toml", "--out", "x"]),
            "realitygap report 'a b.toml' --out x"
        );
        assert_eq!(shell_join(["it's"]), "'it'\\''s'");
        assert_eq!(shell_join([""]), "''");
    }

    #[test]
    fn new_fills_the_tool_version_and_time() {
        let mut p = Provenance::new("t");
        p.sources
            .push(SourceProvenance::new("s").with("engine", "x 1"));
        assert_eq!(p.tool_version, realitygap_core::TOOL_VERSION);
        assert!(
            p.generated_utc.ends_with('Z') && p.generated_utc.len() == 20,
            "{}",
            p.generated_utc
        );
        assert_eq!(
            p.sources[0].details,
            [("engine".to_string(), "x 1".to_string())]
        );
    }
}
