//! Where a command's study recordings come from: the `--data` option.
//!
//! - `builtin` (the default): the study's recordings shipped with the
//!   project (`assets/study-data/paper-data.tar.zst`), unpacked once into
//!   the cache folder and verified there (see [`realitygap_data::builtin`]);
//! - `none`: no recordings (`reproduce` then compares the engines with each
//!   other);
//! - anything else: a folder, e.g. a copy of the study's recordings or a
//!   user's own.

use anyhow::{anyhow, bail, Result};
use realitygap_data::builtin::{self, CacheAction, StudyArchive};
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The value of `--data`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum DataSource {
    /// The study's recordings built into the project (the default).
    #[default]
    Builtin,
    /// No recordings.
    None,
    /// A folder given by the user.
    Dir(PathBuf),
}

impl FromStr for DataSource {
    type Err = String;

    /// `builtin`, `none` or a folder (write `./builtin` for a folder of
    /// that name).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "" => Err("expected builtin, none or a folder".into()),
            "builtin" => Ok(DataSource::Builtin),
            "none" => Ok(DataSource::None),
            dir => Ok(DataSource::Dir(PathBuf::from(dir))),
        }
    }
}

impl std::fmt::Display for DataSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DataSource::Builtin => f.write_str("builtin"),
            DataSource::None => f.write_str("none"),
            DataSource::Dir(d) => write!(f, "{}", d.display()),
        }
    }
}

impl DataSource {
    /// The folder to read: the unpacked built-in data, the user's folder
    /// (which must exist), or `None` for `none`.
    pub fn resolve(&self) -> Result<Option<PathBuf>> {
        match self {
            DataSource::Builtin => builtin_data_dir().map(Some),
            DataSource::None => Ok(None),
            DataSource::Dir(dir) => {
                if !dir.is_dir() {
                    bail!(
                        "--data {}: no such folder; pass the folder of the recordings (for the study's, the one holding MotionCapture/ and Simulation/), or leave --data out to use the study's recordings built in",
                        dir.display()
                    );
                }
                Ok(Some(dir.clone()))
            }
        }
    }
}

impl DataSource {
    /// A line for a report's provenance: where built-in recordings came
    /// from (a folder given by the user is in the report already).
    pub fn provenance(&self) -> Option<(String, String)> {
        match self {
            DataSource::Builtin => Some((
                "Recordings".into(),
                format!(
                    "built in: assets/{} (SHA-256 in assets/{}), the study's published recordings and kinova_description, 3-clause BSD licence, copyright 2018 J. Collins, CSIRO",
                    builtin::ARCHIVE_IN_ASSETS,
                    builtin::CHECKSUM_IN_ASSETS
                ),
            )),
            DataSource::None | DataSource::Dir(_) => None,
        }
    }
}

/// The project's assets folder: `REALITYGAP_ASSETS`, else the one this
/// binary was built from, else `./assets`.
pub fn assets_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("REALITYGAP_ASSETS") {
        return PathBuf::from(dir);
    }
    let built = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets"));
    if built.join("scenes").is_dir() {
        return built;
    }
    PathBuf::from("assets")
}

/// The study's recordings built in, unpacked and verified: the folder
/// holding `MotionCapture/`, `Simulation/` and `kinova_description/`.
/// Says on standard error when it unpacks (first use, or a damaged cache).
pub fn builtin_data_dir() -> Result<PathBuf> {
    builtin_data_dir_in(&assets_dir())
}

/// [`builtin_data_dir`] with the archive of the given assets folder.
pub fn builtin_data_dir_in(assets: &Path) -> Result<PathBuf> {
    let context = |e: builtin::BuiltinError| {
        anyhow!("the study's recordings built in (--data builtin): {e} (`reproduce --data none` runs without recordings)")
    };
    let archive = StudyArchive::in_assets(assets).map_err(context)?;
    let root = builtin::default_cache_root().map_err(context)?;
    let unpacked = builtin::open_or_unpack(&archive, &root).map_err(context)?;
    let what = format!(
        "{} files, {:.1} MB, into {} in {:.2} s",
        unpacked.files,
        unpacked.bytes as f64 / 1e6,
        unpacked.dir.display(),
        unpacked.elapsed_s
    );
    match &unpacked.action {
        CacheAction::Reused => {}
        CacheAction::Unpacked => {
            eprintln!("study data: unpacked the study's recordings built in ({what})")
        }
        CacheAction::Rebuilt(reason) => {
            eprintln!("study data: the cached copy was damaged ({reason}); unpacked again ({what})")
        }
    }
    Ok(unpacked.dir)
}

/// The tosses' archive in the assets folder (the second built-in study).
pub const TOSSES_ARCHIVE_IN_ASSETS: &str = "study-data/contactnets.tar.zst";
/// Its checksum file.
pub const TOSSES_CHECKSUM_IN_ASSETS: &str = "study-data/contactnets.tar.zst.sha256";

/// The ContactNets cube tosses built in, unpacked and verified as the
/// study's recordings are: the folder holding `tosses/N.pt`,
/// `experiment.json` and `LICENSE`.
pub fn builtin_tosses_dir_in(assets: &Path) -> Result<PathBuf> {
    let context = |e: builtin::BuiltinError| {
        anyhow!("the cube tosses built in (--data builtin): {e} (or pass --data DIR, a folder holding tosses/ and experiment.json)")
    };
    let archive = StudyArchive::at(
        &assets.join(TOSSES_ARCHIVE_IN_ASSETS),
        &assets.join(TOSSES_CHECKSUM_IN_ASSETS),
    )
    .map_err(context)?
    .requiring(&["tosses"]);
    let root = builtin::default_cache_root().map_err(context)?;
    let unpacked = builtin::open_or_unpack(&archive, &root).map_err(context)?;
    if unpacked.action != CacheAction::Reused {
        eprintln!(
            "study data: unpacked the cube tosses built in ({} files, {:.1} MB, into {} in {:.2} s)",
            unpacked.files,
            unpacked.bytes as f64 / 1e6,
            unpacked.dir.display(),
            unpacked.elapsed_s
        );
    }
    Ok(unpacked.dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_three_kinds() {
        assert_eq!("builtin".parse(), Ok(DataSource::Builtin));
        assert_eq!("none".parse(), Ok(DataSource::None));
        assert_eq!(
            "./builtin".parse(),
            Ok(DataSource::Dir(PathBuf::from("./builtin")))
        );
        assert!("".parse::<DataSource>().is_err());
        assert_eq!(DataSource::default(), DataSource::Builtin);
        assert_eq!(DataSource::Dir("a/b".into()).to_string(), "a/b");
    }

    #[test]
    fn a_missing_folder_is_named() {
        let e = DataSource::Dir("/does/not/exist".into())
            .resolve()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/does/not/exist") && e.contains("no such folder"),
            "{e}"
        );
        assert_eq!(DataSource::None.resolve().unwrap(), None);
    }

    #[test]
    fn missing_assets_name_the_archive() {
        let tmp = tempfile::tempdir().unwrap();
        let e = builtin_data_dir_in(tmp.path()).unwrap_err().to_string();
        assert!(e.contains("paper-data.tar.zst.sha256"), "{e}");
    }
}
