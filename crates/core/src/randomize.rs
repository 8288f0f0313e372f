//! Domain randomisation over physical parameters: a `randomize.toml`
//! gives ranges of parameter keys, and each repeat of `run --perturb
//! randomize.toml` draws every key within its range from the repeat's
//! seed, over the run's own parameters (`--params`).
//!
//! ```toml
//! # randomize.toml, as `realitygap tune` writes it from its intervals
//! [params]
//! "joints.m1n6s300_joint_2.kv" = { low = 180.0, high = 410.0, scale = "log" }
//! "controller.delay_s" = { low = 0.03, high = 0.06 }
//! ```
//!
//! Keys are those of a parameters file (`joints.<joint>.<field>`,
//! `links.<link>.<field>`, `objects.<object>.<field>`, `contact.<field>`,
//! `controller.<field>`, `actuator.<field>`). A draw is uniform between
//! `low` and `high`, in the logarithm for `scale = "log"`. A key that a
//! parameters file would refuse, a bound that is not a finite number, or
//! `low` above `high` is an error naming the file, line and key.

use crate::controller::SplitMix64;
use crate::params::{ParamsError, PhysicalParams};
use crate::scene::line_col;
use std::path::{Path, PathBuf};

/// One randomised key.
#[derive(Debug, Clone, PartialEq)]
pub struct Range {
    /// The key, as in a parameters file.
    pub key: String,
    /// Lower bound.
    pub low: f64,
    /// Upper bound.
    pub high: f64,
    /// Uniform in the logarithm.
    pub log: bool,
}

/// A randomisation file.
#[derive(Debug, Clone, PartialEq)]
pub struct Randomization {
    /// Where it was read.
    pub source: PathBuf,
    /// Its ranges, in file order.
    pub ranges: Vec<Range>,
}

/// A randomisation file that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{}: {message}", path.display(), line.map_or(String::new(), |l| format!(":{l}")))]
pub struct RandomizeError {
    /// The file.
    pub path: PathBuf,
    /// The line, when known.
    pub line: Option<usize>,
    /// What is wrong.
    pub message: String,
}

/// The TOML table path of a parameter key: `joints.J.kv` is
/// `["joints", "J", "kv"]`.
fn path_of(key: &str) -> Option<Vec<String>> {
    let parts: Vec<&str> = key.split('.').collect();
    match parts.as_slice() {
        [s @ ("joints" | "links" | "objects"), name, field]
            if !name.is_empty() && !field.is_empty() =>
        {
            Some(vec![s.to_string(), name.to_string(), field.to_string()])
        }
        [s @ ("contact" | "controller" | "actuator"), field] if !field.is_empty() => {
            Some(vec![s.to_string(), field.to_string()])
        }
        _ => None,
    }
}

impl Randomization {
    /// Reads `path`.
    pub fn from_file(path: &Path) -> Result<Randomization, RandomizeError> {
        let text = std::fs::read_to_string(path).map_err(|e| RandomizeError {
            path: path.to_path_buf(),
            line: None,
            message: format!("cannot read it: {e}"),
        })?;
        Randomization::from_toml_str(&text, path)
    }

    /// Parses `text`, read from `path`.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Randomization, RandomizeError> {
        let err = |line: Option<usize>, message: String| RandomizeError {
            path: path.to_path_buf(),
            line,
            message,
        };
        let doc: toml::Spanned<toml::Table> = toml::from_str(text).map_err(|e| {
            err(
                e.span().map(|s| line_col(text, s.start).0),
                e.message().to_string(),
            )
        })?;
        let line_of = |needle: &str| text.find(needle).map(|i| line_col(text, i).0);
        let doc = doc.into_inner();
        for k in doc.keys() {
            if k != "params" {
                return Err(err(
                    line_of(k),
                    format!("unknown table [{k}] (a randomisation file has [params] only)"),
                ));
            }
        }
        let Some(params) = doc.get("params") else {
            return Err(err(None, "no [params] table: nothing to randomise".into()));
        };
        let Some(params) = params.as_table() else {
            return Err(err(line_of("params"), "`params` must be a table".into()));
        };
        let mut ranges = Vec::new();
        for (key, v) in params {
            let line = line_of(&format!("\"{key}\"")).or_else(|| line_of(key));
            let at = |m: String| err(line, format!("{key}: {m}"));
            let Some(t) = v.as_table() else {
                return Err(at("expected { low = ..., high = ... }".into()));
            };
            for f in t.keys() {
                if !matches!(f.as_str(), "low" | "high" | "scale" | "value") {
                    return Err(at(format!(
                        "unknown field `{f}` (expected low, high, scale, value)"
                    )));
                }
            }
            let num = |f: &str| -> Result<f64, RandomizeError> {
                let x = t.get(f).ok_or_else(|| at(format!("`{f}` is missing")))?;
                let x = x
                    .as_float()
                    .or_else(|| x.as_integer().map(|i| i as f64))
                    .ok_or_else(|| at(format!("`{f}` must be a number")))?;
                if !x.is_finite() {
                    return Err(at(format!("`{f}` = {x}: expected a finite number")));
                }
                Ok(x)
            };
            let (low, high) = (num("low")?, num("high")?);
            if low > high {
                return Err(at(format!("low = {low} is above high = {high}")));
            }
            let log = match t.get("scale").map(|s| s.as_str()) {
                None => false,
                Some(Some("linear")) => false,
                Some(Some("log")) => true,
                Some(_) => return Err(at("`scale` must be \"linear\" or \"log\"".into())),
            };
            if log && low <= 0.0 {
                return Err(at(format!("scale = \"log\" needs low > 0 (low = {low})")));
            }
            if path_of(key).is_none() {
                return Err(at(
                    "not a parameter key: expected joints.<joint>.<field>, links.<link>.<field>, objects.<object>.<field>, contact.<field>, controller.<field> or actuator.<field>".into(),
                ));
            }
            let range = Range {
                key: key.clone(),
                low,
                high,
                log,
            };
            // The key must be one a parameters file takes, with these values.
            for x in [low, high] {
                overlay(&PhysicalParams::none(), &[(key.clone(), x)])
                    .map_err(|e| at(format!("{e}")))?;
            }
            ranges.push(range);
        }
        Ok(Randomization {
            source: path.to_path_buf(),
            ranges,
        })
    }

    /// The values of one repeat, drawn from `seed`.
    pub fn sample(&self, seed: u64) -> Vec<(String, f64)> {
        // A stream of its own, apart from the perturbation's.
        let mut rng = SplitMix64::new(seed ^ 0x005E_ED0F_D0A1_2A11);
        self.ranges
            .iter()
            .map(|r| {
                let u = rng.uniform();
                let v = if r.log {
                    (r.low.ln() + u * (r.high.ln() - r.low.ln())).exp()
                } else {
                    r.low + u * (r.high - r.low)
                };
                (r.key.clone(), v.clamp(r.low, r.high))
            })
            .collect()
    }

    /// `base` with the draw of `seed` over it.
    pub fn apply(&self, base: &PhysicalParams, seed: u64) -> Result<PhysicalParams, ParamsError> {
        overlay(base, &self.sample(seed))
    }
}

/// `base` with `values` (parameter keys) set over it, checked as a
/// parameters file is.
pub fn overlay(
    base: &PhysicalParams,
    values: &[(String, f64)],
) -> Result<PhysicalParams, ParamsError> {
    let mut doc: toml::Table = toml::from_str(&base.to_toml_string()).unwrap_or_default();
    for (key, value) in values {
        let Some(path) = path_of(key) else {
            continue;
        };
        let mut t = &mut doc;
        for p in &path[..path.len() - 1] {
            let entry = t
                .entry(p.clone())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            if !entry.is_table() {
                *entry = toml::Value::Table(toml::Table::new());
            }
            t = entry.as_table_mut().expect("a table");
        }
        t.insert(path[path.len() - 1].clone(), toml::Value::Float(*value));
    }
    let text = toml::to_string(&doc).unwrap_or_default();
    PhysicalParams::from_toml_str(&text, Path::new("<randomised parameters>"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_within_the_ranges_and_over_the_base() {
        let text = "[params]\n\"joints.j2.kv\" = { low = 10.0, high = 1000.0, scale = \"log\" }\n\"controller.delay_s\" = { low = 0.02, high = 0.06 }\n";
        let r = Randomization::from_toml_str(text, Path::new("r.toml")).unwrap();
        assert_eq!(r.ranges.len(), 2);
        let base = PhysicalParams::from_toml_str(
            "[joints.j2]\ndamping = 0.5\n[joints.j3]\nkv = 7.0\n",
            Path::new("b.toml"),
        )
        .unwrap();
        let mut seen = Vec::new();
        for seed in 0..50 {
            let p = r.apply(&base, seed).unwrap();
            let kv = p.joints["j2"].kv.unwrap();
            assert!((10.0..=1000.0).contains(&kv), "{kv}");
            let d = p.controller.delay_s.unwrap();
            assert!((0.02..=0.06).contains(&d), "{d}");
            assert_eq!(p.joints["j2"].damping, Some(0.5), "the base stays");
            assert_eq!(p.joints["j3"].kv, Some(7.0), "the base stays");
            seen.push(kv);
        }
        // Log-uniform: about half the draws below the geometric middle.
        let below = seen.iter().filter(|k| **k < 100.0).count();
        assert!((12..=38).contains(&below), "{below} of 50");
        assert_eq!(r.sample(3), r.sample(3), "the same seed draws the same");
        assert_ne!(r.sample(3), r.sample(4));
    }

    #[test]
    fn bad_files_name_the_line_and_key() {
        let bad = [
            (
                "[params]\n\"joints.j2.kv\" = { low = 10.0 }\n",
                "`high` is missing",
                2,
            ),
            (
                "[params]\n\"joints.j2.kv\" = { low = 10.0, high = 1.0 }\n",
                "above high",
                2,
            ),
            (
                "[params]\n\"joints.j2.wobble\" = { low = 1.0, high = 2.0 }\n",
                "wobble",
                2,
            ),
            (
                "[params]\n\"gravity\" = { low = 1.0, high = 2.0 }\n",
                "not a parameter key",
                2,
            ),
            (
                "[params]\n\"joints.j2.kv\" = { low = 0.0, high = 2.0, scale = \"log\" }\n",
                "low > 0",
                2,
            ),
            (
                "[params]\n\"joints.j2.kv\" = { low = 1.0, high = nan }\n",
                "finite",
                2,
            ),
            (
                "[params]\n\n\"joints.j2.kv\" = { low = 1.0, hgh = 2.0 }\n",
                "unknown field",
                3,
            ),
            ("[parms]\n", "unknown table", 1),
        ];
        for (text, want, line) in bad {
            let e = Randomization::from_toml_str(text, Path::new("r.toml")).unwrap_err();
            let m = e.to_string();
            assert!(m.contains(want), "{text}: {m}");
            assert_eq!(e.line, Some(line), "{text}: {m}");
            assert!(m.starts_with("r.toml:"), "{m}");
        }
    }
}
