//! A study of tossed objects (`kind = "tosses"`): where its tosses are, and
//! which of them a tune may fit on. `assets/studies/contactnets2020.toml`
//! is the built-in one.
//!
//! ```toml
//! kind = "tosses"
//! name = "contactnets2020"
//! title = "..."
//! tosses = "tosses"              # relative to --data (builtin: the archive)
//! experiment = "experiment.json" # relative to --data
//! held_out_every = 5             # the 5th, 10th, ... toss by number is held out
//! start = "first"                # or "fit": where a toss's initial velocity comes from
//! budget = 96                    # the tune's evaluations unless --budget
//! ```

use crate::data_source::{assets_dir, builtin_tosses_dir_in, DataSource};
use crate::tosses::{read_toss_folder, TossSet, TossStart};
use anyhow::{anyhow, bail, Context, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The study file as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TossStudyFile {
    kind: String,
    name: String,
    title: String,
    tosses: PathBuf,
    experiment: Option<PathBuf>,
    held_out_every: usize,
    start: Option<String>,
    budget: Option<usize>,
}

/// A study of tossed objects.
#[derive(Debug, Clone, PartialEq)]
pub struct TossStudy {
    /// The study file.
    pub file: PathBuf,
    /// Its short name.
    pub name: String,
    /// Its title (the data's citation).
    pub title: String,
    /// The folder of `N.pt` files, relative to the data folder.
    pub tosses: PathBuf,
    /// The experiment's constants, relative to the data folder.
    pub experiment: Option<PathBuf>,
    /// Every `held_out_every`-th toss in number order is held out: never
    /// fitted on, scored on.
    pub held_out_every: usize,
    /// Where a toss's initial velocity comes from.
    pub start: TossStart,
    /// The tune's evaluations when `--budget` is not given.
    pub budget: usize,
}

/// The tune's evaluations when the study file sets none.
pub const DEFAULT_TOSS_BUDGET: usize = 96;

/// Whether `path` is a study file of tossed objects (`kind = "tosses"`).
pub fn is_toss_study(path: &Path) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|text| text.parse::<toml::Table>().ok())
        .is_some_and(|t| t.get("kind").and_then(|k| k.as_str()) == Some("tosses"))
}

impl TossStudy {
    /// Reads a study file of tossed objects; errors name the file, line and
    /// field.
    pub fn from_file(path: &Path) -> Result<TossStudy> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the study file {}", path.display()))?;
        let raw: TossStudyFile = toml::from_str(&text).map_err(|e| {
            let at = e
                .span()
                .map(|s| {
                    let line = text[..s.start].matches('\n').count() + 1;
                    format!(" (line {line})")
                })
                .unwrap_or_default();
            anyhow!("{}{at}: {}", path.display(), e.message())
        })?;
        let fail = |field: &str, what: String| anyhow!("{}: {field}: {what}", path.display());
        if raw.kind != "tosses" {
            return Err(fail(
                "kind",
                format!("\"{}\": a study of tosses has kind = \"tosses\"", raw.kind),
            ));
        }
        if raw.held_out_every < 2 {
            return Err(fail(
                "held_out_every",
                format!(
                    "{}: at least 2 (every second toss held out), or nothing would be left to fit on",
                    raw.held_out_every
                ),
            ));
        }
        let start = match raw.start.as_deref() {
            None | Some("first") => TossStart::First,
            Some("fit") => TossStart::Fit,
            Some(other) => {
                return Err(fail(
                    "start",
                    format!("\"{other}\": expected \"first\" or \"fit\""),
                ))
            }
        };
        if raw.budget == Some(0) {
            return Err(fail("budget", "0: at least one evaluation".into()));
        }
        Ok(TossStudy {
            file: path.to_path_buf(),
            name: raw.name,
            title: raw.title,
            tosses: raw.tosses,
            experiment: raw.experiment,
            held_out_every: raw.held_out_every,
            start,
            budget: raw.budget.unwrap_or(DEFAULT_TOSS_BUDGET),
        })
    }

    /// The study's tosses from `data`: the tosses built in, or a folder
    /// laid out as ContactNets publishes them.
    pub fn load(&self, data: &DataSource) -> Result<TossSet> {
        let root = match data {
            DataSource::Builtin => builtin_tosses_dir_in(&assets_dir())?,
            DataSource::Dir(dir) => {
                if !dir.is_dir() {
                    bail!(
                        "--data {}: no such folder; pass a folder holding {} (and {}), or leave --data out for the tosses built in",
                        dir.display(),
                        self.tosses.display(),
                        self.experiment
                            .as_deref()
                            .unwrap_or(Path::new("experiment.json"))
                            .display()
                    );
                }
                dir.clone()
            }
            DataSource::None => bail!(
                "--data none: a study of tosses needs its tosses; leave --data out for the ones built in"
            ),
        };
        let experiment = self.experiment.as_ref().map(|e| root.join(e));
        if let Some(e) = &experiment {
            if !e.is_file() {
                bail!(
                    "{}: experiment = {:?}: {} is not a file",
                    self.file.display(),
                    self.experiment.as_deref().unwrap_or(Path::new("")),
                    e.display()
                );
            }
        }
        read_toss_folder(&root.join(&self.tosses), experiment.as_deref(), self.start)
            .with_context(|| format!("the tosses of study {}", self.file.display()))
    }

    /// The indices of `set`'s tosses to fit on and to hold out: in number
    /// order, every `held_out_every`-th toss (the 5th, 10th, ...) is held
    /// out.
    pub fn split(&self, set: &TossSet) -> (Vec<usize>, Vec<usize>) {
        let mut order: Vec<usize> = (0..set.tosses.len()).collect();
        order.sort_by_key(|&i| {
            (
                set.tosses[i].id.parse::<u64>().unwrap_or(u64::MAX),
                set.tosses[i].id.clone(),
            )
        });
        let held_out = |k: usize| (k + 1).is_multiple_of(self.held_out_every);
        let pick = |want: bool| -> Vec<usize> {
            order
                .iter()
                .enumerate()
                .filter(|(k, _)| held_out(*k) == want)
                .map(|(_, &i)| i)
                .collect()
        };
        (pick(false), pick(true))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("s.toml");
        std::fs::write(&file, text).unwrap();
        (dir, file)
    }

    #[test]
    fn the_built_in_study_reads_and_splits_one_in_five() {
        let file = assets_dir().join("studies/contactnets2020.toml");
        assert!(is_toss_study(&file));
        let study = TossStudy::from_file(&file).unwrap();
        assert_eq!(study.held_out_every, 5);
        let set = TossSet {
            dir: PathBuf::new(),
            object: crate::tosses::TossedBox {
                role: "cube".into(),
                edge_m: 0.1,
                mass_kg: 0.37,
            },
            tosses: (1..=12)
                .rev()
                .map(|n| crate::tosses::Toss {
                    id: n.to_string(),
                    time_s: vec![0.0],
                    poses: vec![],
                    v0_m_s: Default::default(),
                    w0_rad_s: Default::default(),
                })
                .collect(),
        };
        let (fit, held) = study.split(&set);
        let ids = |v: &[usize]| {
            v.iter()
                .map(|&i| set.tosses[i].id.clone())
                .collect::<Vec<_>>()
        };
        assert_eq!(ids(&held), ["5", "10"]);
        assert_eq!(fit.len(), 10);
        assert!(!ids(&fit).contains(&"5".to_string()));
    }

    #[test]
    fn errors_name_the_file_and_field() {
        let (_d, f) = write(
            "kind = \"tosses\"\nname = \"x\"\ntitle = \"t\"\ntosses = \"t\"\nheld_out_every = 1\n",
        );
        let e = TossStudy::from_file(&f).unwrap_err().to_string();
        assert!(e.contains("s.toml: held_out_every: 1"), "{e}");
        let (_d, f) = write("kind = \"tosses\"\nname = \"x\"\ntitle = \"t\"\ntosses = \"t\"\nheld_out_every = 5\nstart = \"late\"\n");
        let e = TossStudy::from_file(&f).unwrap_err().to_string();
        assert!(e.contains("start: \"late\""), "{e}");
        let (_d, f) = write("kind = \"tosses\"\nname = \"x\"\ntitle = \"t\"\ntosses = \"t\"\nheld_out_every = 5\nspeed = 3\n");
        let e = TossStudy::from_file(&f).unwrap_err().to_string();
        assert!(e.contains("line 6") && e.contains("speed"), "{e}");
        let (_d, f) = write("name = \"x\"\n");
        assert!(!is_toss_study(&f));
    }
}
