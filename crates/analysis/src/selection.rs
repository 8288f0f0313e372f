//! Which real runs are used: the runs a registration, an alignment template
//! or a tuning result is fitted on, and the runs it is scored on.
//!
//! Runs are numbered from 1 in the natural order of their files (the
//! study's `Single0001_6D.tsv` .. `Single0020_6D.tsv` are runs 1-20). A
//! range is written `1-15`, `16-20`, `1-5,8,10-12`.

use serde::Serialize;

/// A set of run numbers (1-based), as written on the command line or in
/// a study file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct RunRange {
    /// Where it was given, for errors: e.g. `--runs` or `study file runs`.
    pub origin: String,
    /// The text as given, e.g. `1-15`.
    pub text: String,
    /// Inclusive ranges of run numbers.
    ranges: Vec<(usize, usize)>,
}

/// A run selection that cannot be used; the message names the argument.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct SelectionError {
    /// What is wrong, naming the argument or field and its value.
    pub message: String,
}

impl RunRange {
    /// Parses `1-15`, `3`, `1-5,8,10-12`. `origin` names the argument in
    /// errors.
    pub fn parse(text: &str, origin: &str) -> Result<RunRange, SelectionError> {
        let err = |why: String| SelectionError {
            message: format!(
                "{origin} \"{text}\": {why} (expected run numbers from 1 such as 1-15 or 1-5,8)"
            ),
        };
        let mut ranges = Vec::new();
        for part in text.split(',').map(str::trim) {
            if part.is_empty() {
                return Err(err("an empty entry".into()));
            }
            let (a, b) = part.split_once('-').unwrap_or((part, part));
            let num = |s: &str| -> Result<usize, SelectionError> {
                s.trim()
                    .parse::<usize>()
                    .map_err(|_| err(format!("\"{}\" is not a whole number", s.trim())))
            };
            let (a, b) = (num(a)?, num(b)?);
            if a == 0 {
                return Err(err("runs are numbered from 1".into()));
            }
            if b < a {
                return Err(err(format!("the range {a}-{b} runs backwards")));
            }
            ranges.push((a, b));
        }
        Ok(RunRange {
            origin: origin.to_string(),
            text: text.to_string(),
            ranges,
        })
    }

    /// True when run `number` (1-based) is in the set.
    pub fn contains(&self, number: usize) -> bool {
        self.ranges.iter().any(|&(a, b)| a <= number && number <= b)
    }

    /// The runs of `1..=count` not in this set, as a range written like
    /// one given (`1-5,11-20`); `None` when every run is in it.
    pub fn complement(&self, count: usize) -> Option<RunRange> {
        let mut ranges: Vec<(usize, usize)> = Vec::new();
        for n in (1..=count).filter(|n| !self.contains(*n)) {
            match ranges.last_mut() {
                Some((_, b)) if *b + 1 == n => *b = n,
                _ => ranges.push((n, n)),
            }
        }
        if ranges.is_empty() {
            return None;
        }
        let text = ranges
            .iter()
            .map(|&(a, b)| {
                if a == b {
                    a.to_string()
                } else {
                    format!("{a}-{b}")
                }
            })
            .collect::<Vec<_>>()
            .join(",");
        Some(RunRange {
            origin: format!("the runs not in {} \"{}\"", self.origin, self.text),
            text,
            ranges,
        })
    }
}

/// The runs to fit on and to score on. Without `holdout`, both are
/// `runs` (all runs when `runs` is not given); with it, the runs are
/// fitted on `runs` (default: every run not held out) and scored on
/// `holdout`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
pub struct RunSelection {
    /// Runs to fit on (and to score on without `holdout`).
    pub runs: Option<RunRange>,
    /// Runs to score on, never fitted on.
    pub holdout: Option<RunRange>,
}

/// The selected runs of one source, as 0-based indices in run order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SelectedRuns {
    /// Runs that alignment templates and registrations are fitted on.
    pub fit: Vec<usize>,
    /// Runs the sources are scored against.
    pub score: Vec<usize>,
}

impl RunSelection {
    /// An error when a range names a run past `most`, the most runs any
    /// scene has: a mistake, not a request to cut the range short (its
    /// label would name runs that were not used). A scene with fewer runs
    /// takes those of a range it has.
    /// `what` names them in the message (`runs`, `episodes`).
    pub fn check_count(&self, most: usize, what: &str) -> Result<(), SelectionError> {
        for r in [&self.runs, &self.holdout].into_iter().flatten() {
            if let Some(last) = r.ranges.iter().map(|&(_, b)| b).max().filter(|&b| b > most) {
                return Err(SelectionError {
                    message: format!(
                        "{} \"{}\" names run {last}, but there are {most} {what} (numbered 1-{most})",
                        r.origin, r.text
                    ),
                });
            }
        }
        Ok(())
    }

    /// True when no run is held out.
    pub fn is_all(&self) -> bool {
        self.runs.is_none() && self.holdout.is_none()
    }

    /// Selects among `count` runs of scene `scene`; an error naming the
    /// argument when a set would be empty or the sets overlap.
    pub fn select(&self, scene: &str, count: usize) -> Result<SelectedRuns, SelectionError> {
        let pick = |r: &RunRange| -> Result<Vec<usize>, SelectionError> {
            let v: Vec<usize> = (0..count).filter(|i| r.contains(i + 1)).collect();
            if v.is_empty() {
                return Err(SelectionError {
                    message: format!(
                        "{} \"{}\" selects no run of scene '{scene}' (it has {count} runs, numbered 1-{count})",
                        r.origin, r.text
                    ),
                });
            }
            Ok(v)
        };
        let all: Vec<usize> = (0..count).collect();
        let Some(holdout) = &self.holdout else {
            let fit = match &self.runs {
                Some(r) => pick(r)?,
                None => all,
            };
            return Ok(SelectedRuns {
                score: fit.clone(),
                fit,
            });
        };
        let score = pick(holdout)?;
        let fit = match &self.runs {
            Some(r) => {
                let fit = pick(r)?;
                let shared: Vec<String> = fit
                    .iter()
                    .filter(|i| score.contains(i))
                    .map(|i| (i + 1).to_string())
                    .collect();
                if !shared.is_empty() {
                    return Err(SelectionError {
                        message: format!(
                            "{} \"{}\" and {} \"{}\" share runs {} of scene '{scene}': a held-out run must not be fitted on",
                            r.origin, r.text, holdout.origin, holdout.text, shared.join(", ")
                        ),
                    });
                }
                fit
            }
            None => all.into_iter().filter(|i| !score.contains(i)).collect(),
        };
        if fit.is_empty() {
            return Err(SelectionError {
                message: format!(
                    "{} \"{}\" holds out every run of scene '{scene}': no run is left to fit on",
                    holdout.origin, holdout.text
                ),
            });
        }
        Ok(SelectedRuns { fit, score })
    }

    /// Like [`RunSelection::select`], but a selection that cannot be used
    /// selects nothing instead of failing.
    pub fn select_lenient(&self, scene: &str, count: usize) -> SelectedRuns {
        self.select(scene, count).unwrap_or(SelectedRuns {
            fit: vec![],
            score: vec![],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_complement_is_every_other_run_written_as_a_range() {
        let h = RunRange::parse("6-10", "--holdout").unwrap();
        let c = h.complement(20).unwrap();
        assert_eq!(c.text, "1-5,11-20");
        assert!(c.contains(5) && !c.contains(6) && c.contains(11) && c.contains(20));
        assert!(c.origin.contains("--holdout \"6-10\""));
        let h = RunRange::parse("1,3", "--holdout").unwrap();
        assert_eq!(h.complement(4).unwrap().text, "2,4");
        assert!(RunRange::parse("1-20", "--holdout")
            .unwrap()
            .complement(20)
            .is_none());
    }

    fn sel(runs: Option<&str>, holdout: Option<&str>) -> RunSelection {
        RunSelection {
            runs: runs.map(|r| RunRange::parse(r, "--runs").unwrap()),
            holdout: holdout.map(|r| RunRange::parse(r, "--holdout").unwrap()),
        }
    }

    #[test]
    fn ranges_select_fit_and_score_runs() {
        let s = sel(Some("1-15"), Some("16-20")).select("s", 20).unwrap();
        assert_eq!(s.fit, (0..15).collect::<Vec<_>>());
        assert_eq!(s.score, (15..20).collect::<Vec<_>>());
        let s = sel(None, Some("16-20")).select("s", 20).unwrap();
        assert_eq!(s.fit.len(), 15);
        let s = sel(Some("1-5,8, 10-11"), None).select("s", 20).unwrap();
        assert_eq!(s.fit, [0, 1, 2, 3, 4, 7, 9, 10]);
        assert_eq!(s.fit, s.score);
        let s = sel(None, None).select("s", 3).unwrap();
        assert_eq!((s.fit.len(), s.score.len()), (3, 3));
    }

    #[test]
    fn bad_selections_name_the_argument() {
        let e = sel(Some("25-30"), None).select("scene1", 20).unwrap_err();
        assert!(
            e.message
                .contains("--runs \"25-30\" selects no run of scene 'scene1'"),
            "{e}"
        );
        let e = sel(None, Some("1-20")).select("s", 20).unwrap_err();
        assert!(e.message.contains("--holdout"), "{e}");
        // Past the last run: not cut short in silence.
        let e = sel(Some("1-25"), None).check_count(20, "runs").unwrap_err();
        assert_eq!(
            e.message,
            "--runs \"1-25\" names run 25, but there are 20 runs (numbered 1-20)"
        );
        let e = sel(None, Some("16-21"))
            .check_count(20, "runs")
            .unwrap_err();
        assert!(
            e.message.starts_with("--holdout \"16-21\" names run 21"),
            "{e}"
        );
        assert!(sel(Some("1-15"), Some("16-20"))
            .check_count(20, "runs")
            .is_ok());
        // A scene with fewer runs than the most takes those it has.
        assert_eq!(
            sel(Some("5-20"), None).select("s", 18).unwrap().fit.len(),
            14
        );
        let e = sel(Some("1-16"), Some("16-20"))
            .select("s", 20)
            .unwrap_err();
        assert!(e.message.contains("share runs 16"), "{e}");
        for bad in ["", "0-3", "5-2", "a", "1-", "1,,2"] {
            let e = RunRange::parse(bad, "--runs").unwrap_err();
            assert!(e.message.starts_with("--runs"), "{bad}: {e}");
        }
    }
}
