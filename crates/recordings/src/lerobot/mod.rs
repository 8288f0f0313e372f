//! LeRobot datasets (v3.0, and v2.x whose data files have the same
//! columns): `meta/info.json` and the parquet files under `data/`, read with
//! the `parquet` crate's record API (no Arrow).
//!
//! - **Joint names** come from `info.json`'s `features["observation.state"]
//!   .names` (a list, or `{"motors": [...]}` as v2 wrote it); a `.pos` or
//!   `.position` suffix (`shoulder_pan.pos`) is dropped.
//! - **Columns**: `observation.state` (joint positions), `action` (the
//!   command sent at that frame; by LeRobot's convention goal positions,
//!   else `--command-kind`), `timestamp` (seconds from the episode's start),
//!   `episode_index`; `observation.velocity` and `observation.effort` when
//!   the dataset has them (same joint names).
//! - **Episodes**: one run per `episode_index`, in order of appearance.

use crate::recording::{check_row, check_time, seconds_to_ns, Commands, JointStates, Recording};
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::record::Field;
use realitygap_core::CommandKind;
use realitygap_data::ImportError;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How to read a LeRobot dataset.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LeRobotOptions {
    /// The kind of `action` (default: position).
    pub command_kind: Option<CommandKind>,
}

/// The joint names of a feature in `info.json`.
fn feature_names(info: &Value, feature: &str) -> Option<Vec<String>> {
    let names = info.get("features")?.get(feature)?.get("names")?;
    let list = match names {
        Value::Array(a) => a,
        Value::Object(o) => o.values().find_map(Value::as_array)?,
        _ => return None,
    };
    list.iter()
        .map(|n| {
            n.as_str().map(|s| {
                s.strip_suffix(".pos")
                    .or_else(|| s.strip_suffix(".position"))
                    .unwrap_or(s)
                    .to_string()
            })
        })
        .collect()
}

/// Every parquet file under `dir`, sorted by path.
fn parquet_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "parquet") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// One frame being assembled.
#[derive(Default)]
struct Episode {
    time_ns: Vec<i64>,
    state: Vec<Vec<f64>>,
    action: Vec<Vec<f64>>,
    velocity: Vec<Vec<f64>>,
    effort: Vec<Vec<f64>>,
    files: Vec<PathBuf>,
}

/// A list cell as f64 values.
fn numbers(field: &Field) -> Option<Vec<f64>> {
    let one = |f: &Field| match f {
        Field::Float(x) => Some(f64::from(*x)),
        Field::Double(x) => Some(*x),
        Field::Float16(x) => Some(f64::from(*x)),
        _ => None,
    };
    match field {
        Field::ListInternal(list) => list.elements().iter().map(one).collect(),
        other => one(other).map(|x| vec![x]),
    }
}

/// Reads a LeRobot dataset folder into one recording per episode.
pub fn import_lerobot(dir: &Path, opts: &LeRobotOptions) -> Result<Vec<Recording>, ImportError> {
    let info_path = dir.join("meta/info.json");
    let text = std::fs::read_to_string(&info_path).map_err(|e| {
        ImportError::new(
            &info_path,
            format!(
                "cannot read the dataset's info ({e}); is {} a LeRobot dataset?",
                dir.display()
            ),
        )
    })?;
    let info: Value = serde_json::from_str(&text).map_err(|e| {
        ImportError::at_line(&info_path, e.line(), format!("not valid JSON: {e}"))
            .with_column(e.column())
    })?;
    let names = feature_names(&info, "observation.state").ok_or_else(|| {
        ImportError::new(
            &info_path,
            "features[\"observation.state\"].names lists no joint names",
        )
        .with_field("observation.state")
    })?;
    let action_names = feature_names(&info, "action").unwrap_or_else(|| names.clone());
    let has_velocity = info.pointer("/features/observation.velocity").is_some();
    let has_effort = info.pointer("/features/observation.effort").is_some();
    let files = parquet_files(&dir.join("data"));
    if files.is_empty() {
        return Err(ImportError::new(
            dir,
            "the dataset has no parquet file under data/",
        ));
    }
    let mut episodes: BTreeMap<i64, Episode> = BTreeMap::new();
    let mut order: Vec<i64> = Vec::new();
    for file in &files {
        read_file(
            file,
            &names,
            &action_names,
            (has_velocity, has_effort),
            &mut episodes,
            &mut order,
        )?;
    }
    let kind = opts.command_kind.unwrap_or(CommandKind::Position);
    let base = dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "lerobot".into());
    let mut out = Vec::with_capacity(order.len());
    for index in order {
        let e = episodes.remove(&index).unwrap_or_default();
        let mut meta = Map::new();
        meta.insert("format".into(), Value::from("lerobot"));
        meta.insert(
            "codebase_version".into(),
            info.get("codebase_version").cloned().unwrap_or(Value::Null),
        );
        meta.insert(
            "fps".into(),
            info.get("fps").cloned().unwrap_or(Value::Null),
        );
        meta.insert("episode_index".into(), Value::from(index));
        let mut warnings = Vec::new();
        if opts.command_kind.is_none() {
            warnings.push("action taken as goal joint positions (LeRobot's convention); give --command-kind otherwise".into());
        }
        out.push(Recording {
            file: e
                .files
                .first()
                .cloned()
                .unwrap_or_else(|| dir.to_path_buf()),
            id: format!("{base}-ep{index:03}"),
            states: JointStates {
                names: names.clone(),
                time_ns: e.time_ns.clone(),
                position: e.state,
                velocity: has_velocity.then_some(e.velocity),
                effort: has_effort.then_some(e.effort),
            },
            commands: Some(Commands {
                kind,
                names: action_names.clone(),
                time_ns: e.time_ns,
                values: e.action,
            }),
            info: meta,
            warnings,
        });
    }
    Ok(out)
}

/// Reads one parquet file's rows into their episodes.
fn read_file(
    file: &Path,
    names: &[String],
    action_names: &[String],
    (has_velocity, has_effort): (bool, bool),
    episodes: &mut BTreeMap<i64, Episode>,
    order: &mut Vec<i64>,
) -> Result<(), ImportError> {
    let err = |e: parquet::errors::ParquetError| {
        ImportError::new(file, format!("cannot read the parquet file: {e}"))
    };
    let handle = std::fs::File::open(file)
        .map_err(|e| ImportError::new(file, format!("cannot open: {e}")))?;
    let reader = SerializedFileReader::new(handle).map_err(err)?;
    let rows = reader.get_row_iter(None).map_err(err)?;
    for (r, row) in rows.enumerate() {
        let row = row.map_err(err)?;
        let at = |column: &str| format!("row {r}, column {column}");
        let mut cells: BTreeMap<&str, &Field> = BTreeMap::new();
        for (name, field) in row.get_column_iter() {
            cells.insert(name.as_str(), field);
        }
        let get = |column: &'static str| -> Result<&Field, ImportError> {
            cells.get(column).copied().ok_or_else(|| {
                ImportError::new(file, format!("the data has no column {column}"))
                    .with_field(format!("row {r}"))
            })
        };
        let vector = |column: &'static str, want: &[String]| -> Result<Vec<f64>, ImportError> {
            let values = numbers(get(column)?).ok_or_else(|| {
                ImportError::new(file, "expected a list of floats").with_field(at(column))
            })?;
            check_row(file, &at(column), column, want, &values)?;
            Ok(values)
        };
        let episode = match get("episode_index")? {
            Field::Long(i) => *i,
            Field::Int(i) => i64::from(*i),
            _ => {
                return Err(
                    ImportError::new(file, "expected an integer").with_field(at("episode_index"))
                )
            }
        };
        let t_s = numbers(get("timestamp")?)
            .and_then(|v| v.first().copied())
            .filter(|t| t.is_finite())
            .ok_or_else(|| {
                ImportError::new(file, "expected a finite number of seconds")
                    .with_field(at("timestamp"))
            })?;
        let t = seconds_to_ns(t_s).ok_or_else(|| {
            ImportError::new(file, format!("time {t_s} s is out of range"))
                .with_field(at("timestamp"))
        })?;
        let e = episodes.entry(episode).or_insert_with(|| {
            order.push(episode);
            Episode::default()
        });
        check_time(file, &at("timestamp"), e.time_ns.last().copied(), t)?;
        e.state.push(vector("observation.state", names)?);
        e.action.push(vector("action", action_names)?);
        if has_velocity {
            e.velocity.push(vector("observation.velocity", names)?);
        }
        if has_effort {
            e.effort.push(vector("observation.effort", names)?);
        }
        e.time_ns.push(t);
        if !e.files.iter().any(|f| f == file) {
            e.files.push(file.to_path_buf());
        }
    }
    Ok(())
}
