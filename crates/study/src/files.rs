//! The files a source's pattern names: `*` wildcards in the last
//! component, matched by `globset`, taken in natural order (`_2` before
//! `_10`). The order numbers the runs (`--runs 1-15` counts in it), so it
//! is part of the contract.

use anyhow::{anyhow, bail, Context, Result};
use globset::{GlobBuilder, GlobMatcher};
use std::cmp::Ordering;
use std::path::{Path, PathBuf};

/// Files matching a pattern whose last component may hold `*`, in natural
/// order. An error when the folder is missing or nothing matches.
pub fn glob(root: &Path, pattern: &str) -> Result<Vec<PathBuf>> {
    let full = root.join(pattern);
    let name = full
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| anyhow!("bad file pattern '{pattern}'"))?
        .to_string();
    let dir = full.parent().map(Path::to_path_buf).unwrap_or_default();
    if !name.contains('*') {
        if full.is_file() {
            return Ok(vec![full]);
        }
        bail!("file not found: {}", full.display());
    }
    let matcher = wildcard(&name)?;
    let entries = std::fs::read_dir(&dir).with_context(|| {
        format!(
            "cannot list folder {} (for pattern '{pattern}')",
            dir.display()
        )
    })?;
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().map(|t| t.is_file()).unwrap_or(false))
        .filter(|e| e.file_name().to_str().is_some_and(|n| matcher.is_match(n)))
        .map(|e| e.path())
        .collect();
    if out.is_empty() {
        bail!("no file matches {}", full.display());
    }
    out.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    Ok(out)
}

/// A matcher of file names for `pattern`, where `*` matches any run of
/// characters and everything else (`?`, `[`, `{`, `\` too) stands for
/// itself.
pub fn wildcard(pattern: &str) -> Result<GlobMatcher> {
    let mut glob = String::with_capacity(pattern.len() + 8);
    for c in pattern.chars() {
        match c {
            // `**` would mean "any folders" to globset: one `*` is the same here.
            '*' if glob.ends_with('*') => {}
            '?' | '[' | ']' | '{' | '}' | '\\' => {
                glob.push('\\');
                glob.push(c);
            }
            c => glob.push(c),
        }
    }
    Ok(GlobBuilder::new(&glob)
        .literal_separator(true)
        .backslash_escape(true)
        .build()
        .with_context(|| format!("bad file pattern '{pattern}'"))?
        .compile_matcher())
}

/// Whether `name` matches `pattern` (see [`wildcard`]).
pub fn wildcard_match(pattern: &str, name: &str) -> bool {
    wildcard(pattern).is_ok_and(|m| m.is_match(name))
}

/// Compares strings with digit runs as numbers (`a2` < `a10`); equal
/// numbers with more leading zeros come after (`a2` < `a02`); everything
/// else byte by byte.
///
/// Hand-written (30 lines) rather than a crate: no natural-order crate is
/// among the project's vetted packages, and the exact order is a contract
/// (it numbers the runs), pinned by the tests below.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, _) => return Ordering::Less,
            (_, None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let na = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let nb = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let ord = number_cmp(&a[..na], &b[..nb]);
                if ord != Ordering::Equal {
                    return ord;
                }
                a = &a[na..];
                b = &b[nb..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

/// Two runs of ASCII digits by value, of any length; then the shorter
/// (fewer leading zeros) first.
fn number_cmp(da: &[u8], db: &[u8]) -> Ordering {
    let strip = |d: &[u8]| -> usize { d.iter().take_while(|c| **c == b'0').count() };
    let (sa, sb) = (&da[strip(da)..], &db[strip(db)..]);
    sa.len()
        .cmp(&sb.len())
        .then(sa.cmp(sb))
        .then(da.len().cmp(&db.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcards() {
        assert!(wildcard_match(
            "Single_Mujoco_*.csv",
            "Single_Mujoco_12.csv"
        ));
        assert!(!wildcard_match(
            "Single_Mujoco_*.csv",
            "Single_PyBullet_1.csv"
        ));
        assert!(wildcard_match("Single*_6D.tsv", "Single0001_6D.tsv"));
        assert!(!wildcard_match("a*b*c", "acb"));
        assert!(wildcard_match("a*b*c", "axxbyyc"));
        assert!(wildcard_match("a**c", "abc"));
        assert!(wildcard_match("*", ".hidden"));
        assert!(wildcard_match("ab*", "ab"));
        assert!(!wildcard_match("ab*b", "ab"));
        assert!(wildcard_match("exact.csv", "exact.csv"));
        assert!(!wildcard_match("exact.csv", "exact.csvx"));
    }

    #[test]
    fn only_the_star_is_special() {
        assert!(wildcard_match("run?[1]{a,b}\\*.csv", "run?[1]{a,b}\\x.csv"));
        assert!(!wildcard_match("run?.csv", "run1.csv"));
        assert!(!wildcard_match("run[12].csv", "run1.csv"));
        assert!(!wildcard_match("{a,b}.csv", "a.csv"));
    }

    #[test]
    fn natural_order() {
        let mut v = vec!["x_10", "x_2", "x_1", "x_02", "x_", "x_1a", "w_3"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["w_3", "x_", "x_1", "x_1a", "x_2", "x_02", "x_10"]);
        assert_eq!(natural_cmp("a", "a"), Ordering::Equal);
        let big = "f_123456789012345678901234567890";
        assert_eq!(natural_cmp(big, "f_99"), Ordering::Greater);
        let mut files = [
            "Single0010_6D.tsv",
            "Single0002_6D.tsv",
            "Single0001_6D.tsv",
        ];
        files.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(files[0], "Single0001_6D.tsv");
    }

    #[test]
    fn glob_lists_matches_in_natural_order_and_names_failures() {
        let dir = tempfile::tempdir().unwrap();
        for n in ["r_10.csv", "r_2.csv", "r_1.csv", "other.txt"] {
            std::fs::write(dir.path().join(n), "").unwrap();
        }
        std::fs::create_dir(dir.path().join("r_3.csv")).unwrap();
        let names: Vec<String> = glob(dir.path(), "r_*.csv")
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["r_1.csv", "r_2.csv", "r_10.csv"]);
        assert_eq!(glob(dir.path(), "other.txt").unwrap().len(), 1);
        let e = glob(dir.path(), "none_*.csv").unwrap_err().to_string();
        assert!(e.starts_with("no file matches"), "{e}");
        let e = glob(dir.path(), "missing.csv").unwrap_err().to_string();
        assert!(e.starts_with("file not found"), "{e}");
        let e = glob(dir.path(), "nodir/*.csv").unwrap_err().to_string();
        assert!(e.starts_with("cannot list folder"), "{e}");
    }
}
