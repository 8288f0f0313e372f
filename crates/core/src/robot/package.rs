//! Finding ROS packages for `package://NAME/...` URIs without ROS.

use super::RobotError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Maps ROS package names to directories, for `package://NAME/rest` URIs.
///
/// Two sources, explicit entries first:
/// 1. explicit `NAME -> DIR` entries ([`PackageResolver::insert`], the
///    command line's `--package NAME=DIR`);
/// 2. search directories, in order (from `ROS_PACKAGE_PATH`, colon
///    separated). In each search directory `D`, package `NAME` is `D` itself
///    when `D`'s last component is `NAME` or `D/package.xml` names it, else
///    `D/NAME` when that is a directory, else a direct subdirectory of `D`
///    whose `package.xml` names it. (ROS searches deeper; one level covers
///    the usual `src/` layouts and keeps lookups fast.)
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PackageResolver {
    explicit: BTreeMap<String, PathBuf>,
    search_dirs: Vec<PathBuf>,
}

impl PackageResolver {
    /// A resolver that knows no package.
    pub fn new() -> Self {
        Self::default()
    }

    /// A resolver searching the directories of the `ROS_PACKAGE_PATH`
    /// environment variable (none when it is unset).
    pub fn from_env() -> Self {
        let mut r = Self::new();
        if let Some(v) = std::env::var_os("ROS_PACKAGE_PATH") {
            r.add_search_path(&v.to_string_lossy());
        }
        r
    }

    /// Appends the directories of a colon-separated list such as
    /// `ROS_PACKAGE_PATH`; empty entries are skipped.
    pub fn add_search_path(&mut self, list: &str) -> &mut Self {
        for part in list.split(':').filter(|p| !p.trim().is_empty()) {
            self.search_dirs.push(PathBuf::from(part.trim()));
        }
        self
    }

    /// Appends one search directory.
    pub fn add_search_dir(&mut self, dir: impl Into<PathBuf>) -> &mut Self {
        self.search_dirs.push(dir.into());
        self
    }

    /// Maps a package name to its directory explicitly; explicit entries win
    /// over search directories, and a later entry replaces an earlier one.
    pub fn insert(&mut self, name: impl Into<String>, dir: impl Into<PathBuf>) -> &mut Self {
        self.explicit.insert(name.into(), dir.into());
        self
    }

    /// Parses a command-line mapping `NAME=DIR` and inserts it.
    pub fn insert_arg(&mut self, arg: &str) -> Result<&mut Self, RobotError> {
        let (name, dir) = Self::parse_arg(arg)?;
        Ok(self.insert(name, dir))
    }

    /// Parses a command-line mapping `NAME=DIR` into its parts.
    pub fn parse_arg(arg: &str) -> Result<(String, PathBuf), RobotError> {
        match arg.split_once('=') {
            Some((name, dir)) if !name.trim().is_empty() && !dir.trim().is_empty() => {
                Ok((name.trim().to_string(), PathBuf::from(dir.trim())))
            }
            _ => Err(RobotError::InvalidPackageArg {
                arg: arg.to_string(),
            }),
        }
    }

    /// The search directories, in order.
    pub fn search_dirs(&self) -> &[PathBuf] {
        &self.search_dirs
    }

    /// The explicit entries, by name.
    pub fn explicit(&self) -> &BTreeMap<String, PathBuf> {
        &self.explicit
    }

    /// The directory of package `name`, or every place that was searched.
    pub fn find(&self, name: &str) -> Result<PathBuf, Vec<PathBuf>> {
        let mut searched = Vec::new();
        if let Some(dir) = self.explicit.get(name) {
            if dir.is_dir() {
                return Ok(dir.clone());
            }
            searched.push(dir.clone());
        }
        for dir in &self.search_dirs {
            searched.push(dir.clone());
            if !dir.is_dir() {
                continue;
            }
            if dir.file_name().is_some_and(|n| n == name) || package_xml_names(dir, name) {
                return Ok(dir.clone());
            }
            let sub = dir.join(name);
            if sub.is_dir() {
                return Ok(sub);
            }
            let Ok(entries) = std::fs::read_dir(dir) else {
                continue;
            };
            let mut subdirs: Vec<PathBuf> = entries
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| p.is_dir())
                .collect();
            subdirs.sort();
            if let Some(found) = subdirs.into_iter().find(|s| package_xml_names(s, name)) {
                return Ok(found);
            }
        }
        Err(searched)
    }
}

/// True when `dir/package.xml` exists and its `<name>` is `name`.
fn package_xml_names(dir: &Path, name: &str) -> bool {
    let Ok(text) = std::fs::read_to_string(dir.join("package.xml")) else {
        return false;
    };
    let Some(start) = text.find("<name>") else {
        return false;
    };
    let rest = &text[start + "<name>".len()..];
    rest.find("</name>")
        .is_some_and(|end| rest[..end].trim() == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("realitygap-pkg-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn finds_packages_by_dir_name_package_xml_and_explicit_map() {
        let root = temp_dir("find");
        // ws/src/alpha (directory named like the package)
        std::fs::create_dir_all(root.join("ws/src/alpha/meshes")).unwrap();
        // ws/src/beta_repo with package.xml naming "beta"
        std::fs::create_dir_all(root.join("ws/src/beta_repo")).unwrap();
        std::fs::write(
            root.join("ws/src/beta_repo/package.xml"),
            "<?xml version=\"1.0\"?>\n<package format=\"2\">\n  <name> beta </name>\n</package>\n",
        )
        .unwrap();
        // a search dir that is itself the package
        std::fs::create_dir_all(root.join("other/gamma")).unwrap();
        std::fs::create_dir_all(root.join("elsewhere/alpha")).unwrap();

        let mut r = PackageResolver::new();
        let list = format!(
            "{}::{}",
            root.join("ws/src").display(),
            root.join("other/gamma").display()
        );
        r.add_search_path(&list);
        assert_eq!(r.search_dirs().len(), 2, "empty entries are skipped");
        assert_eq!(r.find("alpha").unwrap(), root.join("ws/src/alpha"));
        assert_eq!(r.find("beta").unwrap(), root.join("ws/src/beta_repo"));
        assert_eq!(r.find("gamma").unwrap(), root.join("other/gamma"));
        let searched = r.find("delta").unwrap_err();
        assert_eq!(
            searched,
            vec![root.join("ws/src"), root.join("other/gamma")]
        );

        // Explicit entries win over the search path.
        r.insert_arg(&format!("alpha={}", root.join("elsewhere/alpha").display()))
            .unwrap();
        assert_eq!(r.find("alpha").unwrap(), root.join("elsewhere/alpha"));
        // An explicit entry that does not exist falls back to the search path
        // and is listed among the places searched.
        r.insert("beta", root.join("missing"));
        assert_eq!(r.find("beta").unwrap(), root.join("ws/src/beta_repo"));
        r.insert("delta", root.join("missing"));
        assert_eq!(r.find("delta").unwrap_err()[0], root.join("missing"));
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn package_arguments_must_be_name_equals_dir() {
        assert_eq!(
            PackageResolver::parse_arg("kinova_description=/data/kd").unwrap(),
            ("kinova_description".to_string(), PathBuf::from("/data/kd"))
        );
        for bad in ["kinova_description", "=/x", "name=", ""] {
            let e = PackageResolver::parse_arg(bad).unwrap_err();
            assert!(matches!(e, RobotError::InvalidPackageArg { .. }), "{bad}");
            assert!(e.to_string().contains("NAME=DIR"), "{e}");
        }
    }
}
