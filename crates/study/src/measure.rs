//! How the gap is measured, from the words of the command line and the
//! study file to the analysis' [`CompareOptions`]: the mode, the alignment
//! override, the capture-frame registration, the run selection and the
//! bootstrap intervals.

use crate::study::Study;
use anyhow::{bail, Context, Result};
use realitygap_analysis::align::Alignment;
use realitygap_analysis::bootstrap::BootstrapOptions;
use realitygap_analysis::compare::{
    AnalysisMode, CompareOptions, RegistrationChoice, RegistrationReport, SceneReport,
};
use realitygap_analysis::registration::Registration;
use realitygap_analysis::selection::{RunRange, RunSelection};
use std::path::{Path, PathBuf};

/// The words for the analysis modes, as `--mode` takes them.
pub const MODES: [&str; 2] = ["default", "study"];

/// The analysis mode a word names (one of [`MODES`]).
pub fn parse_mode(s: &str) -> Result<AnalysisMode, String> {
    match s {
        "default" => Ok(AnalysisMode::Default),
        "study" => Ok(AnalysisMode::Study),
        _ => Err(format!("unknown mode '{s}' (expected default or study)")),
    }
}

/// How the gap is measured, as the user gives it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Measure {
    /// The analysis mode.
    pub mode: AnalysisMode,
    /// Alignment override: `estimate`, `onset:LEAD` or `fixed:FRAME`.
    pub alignment: Option<String>,
    /// Registration: `estimate`, `none` or a registration.json file.
    pub registration: Option<String>,
    /// Where to write the registration applied.
    pub save_registration: Option<PathBuf>,
    /// Real runs to fit on, e.g. `1-15` (else the study file's `runs`).
    pub runs: Option<String>,
    /// Real runs to score on only, e.g. `16-20` (else the study file's).
    pub holdout: Option<String>,
    /// Bootstrap resamples (default 1000 in default mode, none in study
    /// mode; 0: no intervals).
    pub bootstrap: Option<usize>,
    /// Seed of the bootstrap draws.
    pub seed: u64,
}

impl Measure {
    /// The comparison options, with the study file's run selection where
    /// the command line gives none.
    pub fn options(&self, study: &Study) -> Result<CompareOptions> {
        let mode = self.mode;
        Ok(CompareOptions {
            mode,
            alignment: self.alignment.as_deref().map(parse_alignment).transpose()?,
            registration: self.registration_choice()?,
            runs: self.selection(study)?,
            bootstrap: match (self.bootstrap, mode) {
                (None, AnalysisMode::Study) => None,
                (n, _) => Some(BootstrapOptions {
                    resamples: n.unwrap_or(BootstrapOptions::default().resamples),
                    seed: self.seed,
                    ..BootstrapOptions::default()
                }),
            },
            ..CompareOptions::default()
        })
    }

    /// `--registration`: none given is the mode's default.
    fn registration_choice(&self) -> Result<RegistrationChoice> {
        Ok(match self.registration.as_deref() {
            None => RegistrationChoice::Auto,
            Some(_) if self.mode == AnalysisMode::Study => bail!(
                "--registration does not apply to --mode study: the study's procedure keeps the raw capture frame"
            ),
            Some("estimate") => RegistrationChoice::Estimate,
            Some("none") => RegistrationChoice::None,
            Some(file) => RegistrationChoice::Given {
                registration: Registration::from_file(Path::new(file))
                    .context("--registration")?,
                origin: file.to_string(),
            },
        })
    }

    /// The run selection: `--runs` / `--holdout`, else the study file's.
    fn selection(&self, study: &Study) -> Result<RunSelection> {
        let range = |cli: &Option<String>, file: &Option<String>, flag: &str, field: &str| match (
            cli, file,
        ) {
            (Some(v), _) => RunRange::parse(v, flag).map(Some),
            (None, Some(v)) => RunRange::parse(v, &format!("study file `{field}`")).map(Some),
            (None, None) => Ok(None),
        };
        Ok(RunSelection {
            runs: range(&self.runs, &study.runs, "--runs", "runs")?,
            holdout: range(&self.holdout, &study.holdout, "--holdout", "holdout")?,
        })
    }

    /// Writes the registration of `reports` to `save_registration`, if
    /// asked; an error when none was applied.
    pub fn save_registration(&self, reports: &[SceneReport]) -> Result<()> {
        let Some(path) = &self.save_registration else {
            return Ok(());
        };
        let Some(r) = reports.iter().find_map(|r| r.registration.as_ref()) else {
            bail!(
                "--save-registration {}: no registration was applied (study mode, --registration none, or no real reference)",
                path.display()
            );
        };
        std::fs::write(path, RegistrationReport::registration(r).to_json())
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

/// Parses `--alignment`: `estimate`, `onset:LEAD` (motion onset minus LEAD
/// frames) or `fixed:FRAME`.
pub fn parse_alignment(s: &str) -> Result<Alignment> {
    let (method, arg) = s.split_once(':').map_or((s, None), |(m, a)| (m, Some(a)));
    let num = |what: &str| -> Result<usize> {
        arg.with_context(|| format!("--alignment {method} needs a number: {method}:{what}"))?
            .parse()
            .with_context(|| format!("--alignment {s}: {what} must be a whole number"))
    };
    Ok(match method {
        "estimate" => Alignment::estimate(),
        "onset" => Alignment::Onset {
            lead_frames: num("LEAD")?,
            rest_frames: (20, 100),
            threshold_m: 0.01,
        },
        "fixed" => Alignment::Fixed {
            frame: num("FRAME")?,
        },
        _ => bail!("unknown --alignment '{s}' (expected estimate, onset:LEAD or fixed:FRAME)"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn study(runs: Option<&str>, holdout: Option<&str>) -> Study {
        let mut s = Study::from_toml_str(
            "name = \"x\"\n[[scenes]]\nname = \"s\"\nsteps = 3\n[scenes.reference]\nname = \"r\"\nformat = \"store\"\ndir = \"d\"\n",
            Path::new("x.toml"),
        )
        .unwrap();
        s.runs = runs.map(str::to_string);
        s.holdout = holdout.map(str::to_string);
        s
    }

    #[test]
    fn modes_parse_in_one_place() {
        for word in MODES {
            assert!(parse_mode(word).is_ok());
        }
        assert_eq!(parse_mode("study"), Ok(AnalysisMode::Study));
        assert_eq!(parse_mode("default"), Ok(AnalysisMode::Default));
        assert!(parse_mode("Study").is_err());
    }

    #[test]
    fn the_command_line_overrides_the_study_file() {
        let s = study(Some("1-15"), Some("16-20"));
        let m = Measure {
            runs: Some("1-5".into()),
            ..Measure::default()
        };
        let o = m.options(&s).unwrap();
        assert_eq!(o.runs.runs, Some(RunRange::parse("1-5", "--runs").unwrap()));
        let from_file = RunRange::parse("16-20", "study file `holdout`").unwrap();
        assert_eq!(o.runs.holdout, Some(from_file));
        assert_eq!(o.bootstrap.unwrap().resamples, 1000);
        let e = Measure {
            runs: Some("1-".into()),
            ..Measure::default()
        };
        assert!(format!("{:#}", e.options(&s).unwrap_err()).contains("--runs"));
    }

    #[test]
    fn study_mode_has_no_intervals_and_no_registration() {
        let s = study(None, None);
        let m = Measure {
            mode: AnalysisMode::Study,
            ..Measure::default()
        };
        let o = m.options(&s).unwrap();
        assert!(o.bootstrap.is_none());
        assert!(matches!(o.registration, RegistrationChoice::Auto));
        let m = Measure {
            registration: Some("none".into()),
            ..m
        };
        assert!(m
            .options(&s)
            .unwrap_err()
            .to_string()
            .contains("--mode study"));
        let none = Measure {
            save_registration: Some("r.json".into()),
            ..Measure::default()
        };
        assert!(none.save_registration(&[]).is_err());
    }

    #[test]
    fn alignments() {
        assert!(matches!(
            parse_alignment("fixed:12").unwrap(),
            Alignment::Fixed { frame: 12 }
        ));
        assert!(matches!(
            parse_alignment("onset:93").unwrap(),
            Alignment::Onset {
                lead_frames: 93,
                ..
            }
        ));
        assert!(parse_alignment("onset").is_err());
        assert!(parse_alignment("fixed:x").is_err());
        assert!(parse_alignment("other").is_err());
    }
}
