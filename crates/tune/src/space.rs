//! Parameter spaces: which physical parameters a tune fits, their bounds
//! and scales, the engine settings it runs at, and the capture-frame
//! registration's bounds.
//!
//! ```toml
//! # assets/tuning/mujoco.toml
//! [engine.mujoco]                 # settings every evaluation runs at
//! integrator = "implicitfast"
//! timestep_s = 0.005
//!
//! [registration]                  # fit the capture frame too (optional)
//! rotation_deg = 2.0              # each angle within +-2 deg of the estimate
//! translation_mm = 15.0           # each axis within +-15 mm
//!
//! [params]                        # keys as in a parameters file
//! "joints.m1n6s300_joint_2.damping" = { low = 0.0, high = 20.0 }
//! "controller.max_accel_deg_s2" = { low = 20.0, high = 2000.0, scale = "log", start = 2000.0 }
//! ```
//!
//! `start` is where the search begins (default: the middle of the range in
//! its scale). A key that a parameters file would reject, a bound that is
//! not a finite number, a lower bound not below the upper one, a log scale
//! that reaches zero, or a start outside the bounds is an error naming the
//! file, line and key.

use realitygap_core::engine::EngineSettings;
use realitygap_core::params::PhysicalParams;
use realitygap_core::scene::line_col;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// How a parameter's range is searched.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Scale {
    /// Uniformly between the bounds.
    Linear,
    /// Uniformly in the logarithm (both bounds > 0).
    Log,
}

/// One parameter of the space.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Dim {
    /// The key as in a parameters file, e.g. `joints.J.damping`.
    pub key: String,
    /// Lower bound.
    pub low: f64,
    /// Upper bound.
    pub high: f64,
    /// Scale.
    pub scale: Scale,
    /// Where the search starts.
    pub start: f64,
}

impl Dim {
    /// The value at normalised coordinate `u` in [0, 1].
    pub fn value(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        match self.scale {
            Scale::Linear => self.low + u * (self.high - self.low),
            Scale::Log => (self.low.ln() + u * (self.high.ln() - self.low.ln())).exp(),
        }
    }

    /// The normalised coordinate of `value` (clamped to [0, 1]).
    pub fn unit(&self, value: f64) -> f64 {
        let u = match self.scale {
            Scale::Linear => (value - self.low) / (self.high - self.low),
            Scale::Log => (value.ln() - self.low.ln()) / (self.high.ln() - self.low.ln()),
        };
        u.clamp(0.0, 1.0)
    }
}

/// Bounds of the capture-frame registration fitted with the parameters:
/// each rotation angle and translation axis around the measurement's own
/// estimate (from the training runs against the kinematic reference).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RegistrationBounds {
    /// Largest rotation about each axis, degrees.
    pub rotation_deg: f64,
    /// Largest translation along each axis, millimetres.
    pub translation_mm: f64,
}

/// The names of the registration offset's six values, as the tune records
/// them (after the space's parameters, when the registration is fitted):
/// rotations about x, y and z in degrees, then translations in mm.
pub const REGISTRATION_KEYS: [&str; 6] = [
    "registration.rx_deg",
    "registration.ry_deg",
    "registration.rz_deg",
    "registration.tx_mm",
    "registration.ty_mm",
    "registration.tz_mm",
];

/// A parameter space.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Space {
    /// The file it was read from.
    pub source: PathBuf,
    /// The parameters, in file order.
    pub dims: Vec<Dim>,
    /// Engine settings by engine (`[engine.NAME]`).
    #[serde(skip)]
    pub settings: BTreeMap<String, EngineSettings>,
    /// Keys of the file that are not searched but held at the scenes' own
    /// values ([`Space::holding`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<String>,
    /// The registration's bounds, when the registration is fitted too.
    pub registration: Option<RegistrationBounds>,
    /// Where the search starts in the registration: the offset from the
    /// measurement's estimate, rotation (degrees, 3) then translation (mm,
    /// 3); `None`: at the estimate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub registration_start: Option<[f64; 6]>,
}

/// A space file that cannot be used: file, line and column, and what is
/// wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct SpaceError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line, when known.
    pub line: Option<usize>,
    /// 1-based column, when known.
    pub column: Option<usize>,
    /// What is wrong, naming the key.
    pub message: String,
}

impl fmt::Display for SpaceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "parameter space {}", self.path.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
            if let Some(c) = self.column {
                write!(f, ":{c}")?;
            }
        }
        write!(f, ": {}", self.message)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SpaceFile {
    #[serde(default)]
    engine: BTreeMap<String, toml::Table>,
    #[serde(default)]
    registration: Option<Spanned<RegistrationFile>>,
    #[serde(default)]
    params: BTreeMap<Spanned<String>, Spanned<DimFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RegistrationFile {
    rotation_deg: f64,
    translation_mm: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DimFile {
    low: f64,
    high: f64,
    #[serde(default)]
    scale: Option<Scale>,
    #[serde(default)]
    start: Option<f64>,
}

impl Space {
    /// Reads a space file.
    pub fn from_file(path: &Path) -> Result<Space, SpaceError> {
        let text = std::fs::read_to_string(path).map_err(|e| SpaceError {
            path: path.to_path_buf(),
            line: None,
            column: None,
            message: format!("cannot read it: {e}"),
        })?;
        Space::from_toml_str(&text, path)
    }

    /// Parses a space from `text` (`path` names it in errors).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Space, SpaceError> {
        let at = |offset: Option<usize>, message: String| {
            let (line, column) = match offset {
                Some(o) => {
                    let (l, c) = line_col(text, o);
                    (Some(l), Some(c))
                }
                None => (None, None),
            };
            SpaceError {
                path: path.to_path_buf(),
                line,
                column,
                message,
            }
        };
        let file: SpaceFile = toml::from_str(text).map_err(|e| {
            at(
                e.span().map(|s| s.start),
                e.message().trim_end().to_string(),
            )
        })?;
        let mut dims = Vec::new();
        let mut entries: Vec<_> = file.params.into_iter().collect();
        entries.sort_by_key(|(k, _)| k.span().start);
        for (key, dim) in entries {
            let offset = Some(key.span().start);
            let key = key.into_inner();
            let d = dim.into_inner();
            let d = check_dim(&key, d).map_err(|m| at(offset, format!("params.\"{key}\": {m}")))?;
            for v in [d.low, d.high, d.start] {
                check_key(&key, v).map_err(|m| at(offset, format!("params.\"{key}\": {m}")))?;
            }
            dims.push(d);
        }
        let registration = match file.registration {
            None => None,
            Some(r) => {
                let offset = Some(r.span().start);
                let r = r.into_inner();
                for (name, v) in [
                    ("rotation_deg", r.rotation_deg),
                    ("translation_mm", r.translation_mm),
                ] {
                    if !v.is_finite() || v < 0.0 {
                        return Err(at(
                            offset,
                            format!("registration.{name} = {v}: expected a finite number >= 0"),
                        ));
                    }
                }
                Some(RegistrationBounds {
                    rotation_deg: r.rotation_deg,
                    translation_mm: r.translation_mm,
                })
            }
        };
        let mut settings = BTreeMap::new();
        for (engine, table) in file.engine {
            let mut s = EngineSettings::new();
            for (k, v) in table {
                let value = realitygap_core::scene::setting_value(&v).ok_or_else(|| {
                    at(
                        None,
                        format!("engine.{engine}.{k}: expected a number, a boolean or a string"),
                    )
                })?;
                s.insert(k, value);
            }
            settings.insert(engine, s);
        }
        if dims.is_empty() && registration.is_none() {
            return Err(at(
                None,
                "nothing to fit: no [params] entry and no [registration]".into(),
            ));
        }
        Ok(Space {
            source: path.to_path_buf(),
            dims,
            settings,
            registration,
            held: Vec::new(),
            registration_start: None,
        })
    }

    /// The space without the parameters whose keys `hold` picks: they are
    /// not searched, the scenes' own values stand, and their keys are
    /// listed in [`Space::held`].
    pub fn holding(&self, hold: impl Fn(&str) -> bool) -> Space {
        let (held, dims): (Vec<Dim>, Vec<Dim>) =
            self.dims.iter().cloned().partition(|d| hold(&d.key));
        let mut space = Space {
            dims,
            ..self.clone()
        };
        space.held.extend(held.into_iter().map(|d| d.key));
        space
    }

    /// Number of search coordinates: the parameters, then six for the
    /// registration when it is fitted.
    pub fn len(&self) -> usize {
        self.dims.len() + if self.registration.is_some() { 6 } else { 0 }
    }

    /// True when there is nothing to search.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The normalised start point.
    pub fn start_unit(&self) -> Vec<f64> {
        let mut u: Vec<f64> = self.dims.iter().map(|d| d.unit(d.start)).collect();
        if let Some(b) = self.registration {
            let at = self.registration_start.unwrap_or([0.0; 6]);
            let unit = |x: f64, bound: f64| (0.5 + 0.5 * x / bound).clamp(0.0, 1.0);
            u.extend((0..6).map(|i| {
                unit(
                    at[i],
                    if i < 3 {
                        b.rotation_deg
                    } else {
                        b.translation_mm
                    },
                )
            }));
        }
        u
    }

    /// The space with its search started at `values` (keys as in
    /// [`Dim::key`], and `registration.rx_deg` ... `registration.tz_mm`
    /// for the registration's offset), each clamped into its bounds; other
    /// coordinates start where they did. Returns the space and the keys
    /// whose start moved.
    pub fn starting_at(&self, values: &[(String, f64)]) -> (Space, Vec<String>) {
        let mut space = self.clone();
        let mut moved = Vec::new();
        for d in &mut space.dims {
            if let Some((_, v)) = values.iter().find(|(k, _)| *k == d.key) {
                d.start = v.clamp(d.low, d.high);
                moved.push(d.key.clone());
            }
        }
        if space.registration.is_some() {
            let found: Vec<f64> = REGISTRATION_KEYS
                .iter()
                .filter_map(|k| values.iter().find(|(n, _)| n == k).map(|(_, v)| *v))
                .collect();
            if let Ok(at) = <[f64; 6]>::try_from(found) {
                space.registration_start = Some(at);
                moved.push("registration".into());
            }
        }
        (space, moved)
    }

    /// The parameter values (in file order) at normalised coordinates `u`.
    pub fn values(&self, u: &[f64]) -> Vec<f64> {
        self.dims.iter().zip(u).map(|(d, &x)| d.value(x)).collect()
    }

    /// The registration offset at normalised coordinates `u`: rotation
    /// vector (degrees) and translation (metres), or `None` when the
    /// registration is not fitted.
    pub fn registration_offset(&self, u: &[f64]) -> Option<([f64; 3], [f64; 3])> {
        let b = self.registration?;
        let r = u.get(self.dims.len()..self.dims.len() + 6)?;
        let s = |x: f64| 2.0 * x.clamp(0.0, 1.0) - 1.0;
        Some((
            [0, 1, 2].map(|i| s(r[i]) * b.rotation_deg),
            [3, 4, 5].map(|i| s(r[i]) * b.translation_mm / 1000.0),
        ))
    }

    /// The physical parameters at `values` (in file order), with the
    /// engine settings of `engine` from the space (and `extra`, which
    /// overrides them).
    pub fn params(
        &self,
        values: &[f64],
        engine: &str,
        extra: &EngineSettings,
    ) -> Result<PhysicalParams, String> {
        let mut p = params_of(
            self.dims
                .iter()
                .map(|d| d.key.as_str())
                .zip(values.iter().copied()),
        )?;
        let mut s = self.settings.get(engine).cloned().unwrap_or_default();
        s.extend(extra.iter().map(|(k, v)| (k.clone(), v.clone())));
        if !s.is_empty() {
            p.engine_settings.insert(engine.to_string(), s);
        }
        Ok(p)
    }
}

fn check_dim(key: &str, d: DimFile) -> Result<Dim, String> {
    let _ = key;
    for (name, v) in [
        ("low", Some(d.low)),
        ("high", Some(d.high)),
        ("start", d.start),
    ] {
        if let Some(v) = v {
            if !v.is_finite() {
                return Err(format!("{name} = {v}: expected a finite number"));
            }
        }
    }
    if d.low >= d.high {
        return Err(format!("low = {} is not below high = {}", d.low, d.high));
    }
    let scale = d.scale.unwrap_or(Scale::Linear);
    if scale == Scale::Log && d.low <= 0.0 {
        return Err(format!("scale = \"log\" needs low > 0 (low = {})", d.low));
    }
    let mut dim = Dim {
        key: String::new(),
        low: d.low,
        high: d.high,
        scale,
        start: 0.0,
    };
    dim.start = match d.start {
        Some(s) if s < d.low || s > d.high => {
            return Err(format!("start = {s} is outside [{}, {}]", d.low, d.high))
        }
        Some(s) => s,
        None => dim.value(0.5),
    };
    dim.key = key.to_string();
    Ok(dim)
}

/// Checks that `key` is a parameter a parameters file accepts, with
/// `value` as its value.
fn check_key(key: &str, value: f64) -> Result<(), String> {
    params_of(std::iter::once((key, value))).map(|_| ())
}

/// A parameters file's text for `key = value` pairs (`joints.J.damping`,
/// `controller.delay_s`, ...), parsed as one: every error a parameters file
/// gives.
pub fn params_of<'a>(
    pairs: impl IntoIterator<Item = (&'a str, f64)>,
) -> Result<PhysicalParams, String> {
    let mut tables: BTreeMap<String, Vec<(String, f64)>> = BTreeMap::new();
    for (key, value) in pairs {
        let parts: Vec<&str> = key.split('.').collect();
        let (table, field) = match parts.as_slice() {
            [section @ ("joints" | "links" | "objects"), name, field] if !name.is_empty() => {
                (format!("{section}.{}", quote(name)), *field)
            }
            [section @ ("contact" | "controller" | "actuator"), field] => (section.to_string(), *field),
            _ => {
                return Err(format!(
                    "`{key}` is not a parameter key: expected joints.<joint>.<field>, links.<link>.<field>, objects.<object>.<field>, contact.<field>, controller.<field> or actuator.<field>"
                ))
            }
        };
        if field.is_empty() || !field.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(format!("`{key}`: `{field}` is not a field name"));
        }
        tables
            .entry(table)
            .or_default()
            .push((field.to_string(), value));
    }
    let mut text = String::new();
    for (table, fields) in &tables {
        text.push_str(&format!("[{table}]\n"));
        for (f, v) in fields {
            text.push_str(&format!("{f} = {v:?}\n"));
        }
    }
    PhysicalParams::from_toml_str(&text, Path::new("<space>")).map_err(|e| e.message)
}

fn quote(name: &str) -> String {
    if name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        name.to_string()
    } else {
        format!("{name:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Space, SpaceError> {
        Space::from_toml_str(text, Path::new("space.toml"))
    }

    #[test]
    fn a_space_parses_with_scales_starts_and_settings() {
        let s = parse(
            "[engine.mujoco]\ntimestep_s = 0.005\n[registration]\nrotation_deg = 1.0\ntranslation_mm = 10.0\n[params]\n\"joints.j2.damping\" = { low = 0.0, high = 4.0 }\n\"controller.max_accel_deg_s2\" = { low = 10.0, high = 1000.0, scale = \"log\", start = 1000.0 }\n",
        )
        .unwrap();
        assert_eq!(s.dims.len(), 2);
        assert_eq!(s.len(), 8);
        assert_eq!(s.dims[0].start, 2.0);
        assert_eq!(s.dims[1].scale, Scale::Log);
        assert!((s.dims[1].value(0.5) - 100.0).abs() < 1e-9);
        assert!((s.dims[1].unit(1000.0) - 1.0).abs() < 1e-12);
        let u = s.start_unit();
        assert_eq!(u, vec![0.5, 1.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]);
        let (r, t) = s
            .registration_offset(&[0.0, 0.0, 1.0, 0.5, 0.5, 0.0, 0.5, 1.0])
            .unwrap();
        assert_eq!(r, [1.0, 0.0, 0.0]);
        assert_eq!(t, [-0.01, 0.0, 0.01]);
        let p = s
            .params(&[1.5, 50.0], "mujoco", &EngineSettings::new())
            .unwrap();
        assert_eq!(p.joints["j2"].damping, Some(1.5));
        assert_eq!(p.controller.max_accel_deg_s2, Some(50.0));
        assert!(p.engine_settings.contains_key("mujoco"));
    }

    #[test]
    fn bad_spaces_name_the_file_line_and_key() {
        let cases = [
            (
                "[params]\n\"joints.j.nosuch\" = { low = 0.0, high = 1.0 }\n",
                2,
                "nosuch",
            ),
            (
                "[params]\n\"wheels.j.damping\" = { low = 0.0, high = 1.0 }\n",
                2,
                "not a parameter key",
            ),
            (
                "[params]\n\"joints.j.damping\" = { low = 2.0, high = 1.0 }\n",
                2,
                "low = 2 is not below high = 1",
            ),
            (
                "[params]\n\"joints.j.damping\" = { low = nan, high = 1.0 }\n",
                2,
                "low = NaN: expected a finite number",
            ),
            (
                "[params]\n\"joints.j.damping\" = { low = 0.0, high = 1.0, scale = \"log\" }\n",
                2,
                "needs low > 0",
            ),
            (
                "[params]\n\n\"joints.j.damping\" = { low = 0.0, high = 1.0, start = 3.0 }\n",
                3,
                "outside [0, 1]",
            ),
            (
                "[params]\n\"joints.j.damping\" = { low = 0.0, high = 1.0, stepsize = 3.0 }\n",
                2,
                "stepsize",
            ),
            (
                "[params]\n\"joints.j.damping\" = { low = -1.0, high = 1.0 }\n",
                2,
                "damping",
            ),
        ];
        for (text, line, want) in cases {
            let e = parse(text).unwrap_err();
            let shown = e.to_string();
            assert_eq!(e.line, Some(line), "{shown}");
            assert!(shown.starts_with("parameter space space.toml:"), "{shown}");
            assert!(shown.contains(want), "{text}: {shown}");
        }
        let e = parse("").unwrap_err().to_string();
        assert!(e.contains("nothing to fit"), "{e}");
        let e = parse("[registration]\nrotation_deg = -1.0\ntranslation_mm = 1.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("registration.rotation_deg"), "{e}");
    }

    #[test]
    fn holding_takes_the_picked_keys_out_and_names_them() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("space.toml");
        std::fs::write(
            &path,
            "[params]\n\"controller.delay_s\" = { low = 0.0, high = 0.1, start = 0.0 }\n\
             \"contact.time_constant_s\" = { low = 0.01, high = 0.1, start = 0.02 }\n\
             \"actuator.damping_ratio\" = { low = 0.2, high = 2.0, start = 1.0 }\n",
        )
        .unwrap();
        let space = Space::from_file(&path).unwrap();
        let held = space.holding(|k| k.starts_with("contact."));
        let keys: Vec<&str> = held.dims.iter().map(|d| d.key.as_str()).collect();
        assert_eq!(keys, ["controller.delay_s", "actuator.damping_ratio"]);
        assert_eq!(held.held, ["contact.time_constant_s"]);
        assert!(space.held.is_empty());
        // Holding nothing changes nothing.
        assert_eq!(space.holding(|_| false), space);
    }

    #[test]
    fn the_shipped_spaces_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tuning");
        for &engine in realitygap_core::engine::LINKED_ENGINES {
            let s = Space::from_file(&dir.join(format!("{engine}.toml"))).unwrap();
            assert!(s.dims.len() >= 10, "{engine}");
            assert!(s.settings.contains_key(engine), "{engine}");
            assert!(s.registration.is_some());
            for d in &s.dims {
                assert!((d.low..=d.high).contains(&d.start), "{engine} {}", d.key);
            }
        }
    }
}

#[cfg(test)]
mod starting_at_tests {
    use super::*;

    #[test]
    fn starting_at_moves_the_named_starts_and_the_registration() {
        let s = Space::from_toml_str(
            "[registration]\nrotation_deg = 2.0\ntranslation_mm = 10.0\n[params]\n\
             \"controller.delay_s\" = { low = 0.0, high = 0.15, start = 0.0 }\n\
             \"actuator.damping_ratio\" = { low = 0.2, high = 2.0, scale = \"log\", start = 1.0 }\n\
             \"joints.j.kv\" = { low = 1.0, high = 100.0, scale = \"log\", start = 10.0 }\n",
            Path::new("s.toml"),
        )
        .unwrap();
        let u0 = s.start_unit();
        assert_eq!(&u0[3..], &[0.5; 6]);
        let values: Vec<(String, f64)> = [
            ("controller.delay_s", 0.05),
            ("actuator.damping_ratio", 9.0),
            ("actuator.frequency_rad_s", 19.0),
            ("registration.rx_deg", 1.0),
            ("registration.ry_deg", -2.0),
            ("registration.rz_deg", 0.0),
            ("registration.tx_mm", 5.0),
            ("registration.ty_mm", -20.0),
            ("registration.tz_mm", 0.0),
        ]
        .iter()
        .map(|(k, v)| (k.to_string(), *v))
        .collect();
        let (moved, keys) = s.starting_at(&values);
        assert_eq!(
            keys,
            [
                "controller.delay_s",
                "actuator.damping_ratio",
                "registration"
            ]
        );
        assert_eq!(moved.dims[0].start, 0.05);
        // Clamped into the bounds; a key the space lacks is ignored.
        assert_eq!(moved.dims[1].start, 2.0);
        assert_eq!(moved.dims[2].start, 10.0);
        let u = moved.start_unit();
        assert!((u[0] - 0.05 / 0.15).abs() < 1e-12);
        assert_eq!(&u[3..], &[0.75, 0.0, 0.5, 0.75, 0.0, 0.5]);
        // Back through the registration's own mapping.
        let (r, t) = moved.registration_offset(&u).unwrap();
        assert_eq!(r, [1.0, -2.0, 0.0]);
        assert!((t[0] - 0.005).abs() < 1e-15 && (t[1] + 0.010).abs() < 1e-15);
        // Without the registration's six, it starts at the estimate.
        let (same, keys) = s.starting_at(&values[..2]);
        assert_eq!(keys.len(), 2);
        assert_eq!(&same.start_unit()[3..], &[0.5; 6]);
    }
}
