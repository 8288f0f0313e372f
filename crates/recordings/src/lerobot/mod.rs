//! LeRobot datasets (v3.0, and v2.x whose data files have the same
//! columns): `meta/info.json`, the episode index and the parquet files
//! under `data/`, read with the `parquet` crate's record API (no Arrow).
//!
//! - **Joint names** come from `info.json`'s `features["observation.state"]
//!   .names` (a list, or `{"motors": [...]}` as v2 wrote it); a `.pos` or
//!   `.position` suffix (`shoulder_pan.pos`) is dropped.
//! - **Columns**: `observation.state` (joint positions), `action` (the
//!   command sent at that frame; by LeRobot's convention goal positions,
//!   else `--command-kind`), `frame_index`, `timestamp`, `episode_index`;
//!   `observation.velocity` and `observation.effort` when the dataset has
//!   them (same joint names).
//! - **Times** are `frame_index / fps`, exactly: LeRobot writes `timestamp`
//!   as float32 (14.93999958 for 14.94), which would put a command a
//!   fraction of a microsecond off the frame. The written timestamp must
//!   agree within half a frame, else the frame is an error; a repeated
//!   frame index is an error too.
//! - **The metadata is checked, not trusted**: every episode of the episode
//!   index (`meta/episodes/` in v3, `meta/episodes.jsonl` in v2) must be in
//!   its data file (`data_path` of `info.json`), with as many frames as its
//!   `length`; `total_episodes` and `total_frames` must match. A missing
//!   data file or a frame count that differs is an error naming the file
//!   and the episode.
//! - **Episodes**: one run per `episode_index`, in order of appearance.

pub mod pages;

use crate::recording::{check_row, check_state_time, ns_text, Commands, JointStates, Recording};
use parquet::file::reader::FileReader;
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

/// One episode being assembled.
#[derive(Default)]
struct Episode {
    time_ns: Vec<i64>,
    frame_index: Vec<i64>,
    state: Vec<Vec<f64>>,
    action: Vec<Vec<f64>>,
    velocity: Vec<Vec<f64>>,
    effort: Vec<Vec<f64>>,
    files: Vec<PathBuf>,
}

/// One episode as the metadata lists it.
#[derive(Debug, Clone, PartialEq)]
struct EpisodeMeta {
    index: i64,
    length: i64,
    /// Its data file, when the metadata says which.
    file: Option<PathBuf>,
    /// Where the metadata says so, for messages.
    source: PathBuf,
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

/// An integer cell.
fn integer(field: &Field) -> Option<i64> {
    match field {
        Field::Long(i) => Some(*i),
        Field::Int(i) => Some(i64::from(*i)),
        Field::Short(i) => Some(i64::from(*i)),
        Field::ULong(i) => i64::try_from(*i).ok(),
        Field::UInt(i) => Some(i64::from(*i)),
        _ => None,
    }
}

/// Fills a Python format template as `info.json`'s `data_path` is written
/// (`data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet`): `{name}`
/// or `{name:0Nd}` with the integers of `values`.
fn fill_template(template: &str, values: &[(&str, i64)]) -> Result<String, String> {
    let mut out = String::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let close = rest[open..]
            .find('}')
            .ok_or_else(|| format!("unclosed {{ in {template:?}"))?;
        let spec = &rest[open + 1..open + close];
        let (name, format) = spec.split_once(':').unwrap_or((spec, ""));
        let value = values
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, v)| v)
            .ok_or_else(|| format!("{template:?} names {{{name}}}, which is not known"))?;
        let width: usize = match format.strip_suffix('d') {
            Some(w) if !w.is_empty() => w
                .trim_start_matches('0')
                .parse()
                .ok()
                .filter(|&w| w <= 32)
                .ok_or_else(|| format!("unknown format {{{spec}}} in {template:?}"))?,
            Some(_) => 0,
            None if format.is_empty() => 0,
            None => return Err(format!("unknown format {{{spec}}} in {template:?}")),
        };
        out.push_str(&format!("{value:0width$}"));
        rest = &rest[open + close + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The episode index of the dataset, if it has one: v3's
/// `meta/episodes/**/*.parquet` or v2's `meta/episodes.jsonl`, each episode
/// with its data file (from `data_path`).
fn episode_index(dir: &Path, info: &Value) -> Result<Option<Vec<EpisodeMeta>>, ImportError> {
    let info_path = dir.join("meta/info.json");
    let data_path = info.get("data_path").and_then(Value::as_str);
    let path_of = |values: &[(&str, i64)], source: &Path| -> Result<Option<PathBuf>, ImportError> {
        let Some(template) = data_path else {
            return Ok(None);
        };
        fill_template(template, values)
            .map(|p| Some(dir.join(p)))
            .map_err(|m| {
                ImportError::new(
                    &info_path,
                    format!("data_path: {m} (for {})", source.display()),
                )
                .with_field("data_path")
            })
    };
    let v3 = parquet_files(&dir.join("meta/episodes"));
    if !v3.is_empty() {
        let mut out = Vec::new();
        for file in &v3 {
            out.extend(pages::guarded(file, || episode_rows(file, &path_of))?);
        }
        return Ok(Some(out));
    }
    let jsonl = dir.join("meta/episodes.jsonl");
    let Ok(text) = std::fs::read_to_string(&jsonl) else {
        return Ok(None);
    };
    let chunks_size = info
        .get("chunks_size")
        .and_then(Value::as_i64)
        .filter(|&c| c > 0)
        .unwrap_or(1000);
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let located = |m: String| ImportError::at_line(&jsonl, k + 1, m);
        let v: Value =
            serde_json::from_str(line).map_err(|e| located(format!("not valid JSON: {e}")))?;
        let int = |name: &str| {
            v.get(name)
                .and_then(Value::as_i64)
                .ok_or_else(|| located(format!("no integer {name}")))
        };
        let index = int("episode_index")?;
        let length = int("length")?;
        let file = path_of(
            &[
                ("episode_chunk", index / chunks_size),
                ("chunk_index", index / chunks_size),
                ("episode_index", index),
            ],
            &jsonl,
        )?;
        out.push(EpisodeMeta {
            index,
            length,
            file,
            source: jsonl.clone(),
        });
    }
    Ok(Some(out))
}

/// The data file `data_path` names for these template values (and the
/// index file that asked, for messages).
type DataPathOf<'f> = dyn Fn(&[(&str, i64)], &Path) -> Result<Option<PathBuf>, ImportError> + 'f;

/// The episodes a v3 episode index file lists.
fn episode_rows(file: &Path, path_of: &DataPathOf<'_>) -> Result<Vec<EpisodeMeta>, ImportError> {
    let mut out = Vec::new();
    let reader = pages::open(file)?;
    let rows = reader
        .get_row_iter(None)
        .map_err(|e| ImportError::new(file, format!("cannot read the parquet file: {e}")))?;
    for (r, row) in rows.enumerate() {
        let row = row.map_err(|e| {
            ImportError::new(file, format!("cannot read the parquet file: {e}"))
                .with_field(format!("row {r}"))
        })?;
        let get = |name: &str| -> Result<Option<i64>, ImportError> {
            match row.get_column_iter().find(|(n, _)| n.as_str() == name) {
                None => Ok(None),
                Some((_, f)) => integer(f).map(Some).ok_or_else(|| {
                    ImportError::new(file, "expected an integer")
                        .with_field(format!("row {r}, column {name}"))
                }),
            }
        };
        let need = |name: &str| -> Result<i64, ImportError> {
            get(name)?.ok_or_else(|| {
                ImportError::new(file, format!("the episode index has no column {name}"))
                    .with_field(format!("row {r}"))
            })
        };
        let index = need("episode_index")?;
        let length = need("length")?;
        let data_file = match (get("data/chunk_index")?, get("data/file_index")?) {
            (Some(chunk), Some(f)) => path_of(
                &[
                    ("chunk_index", chunk),
                    ("file_index", f),
                    ("episode_chunk", chunk),
                    ("episode_index", index),
                ],
                file,
            )?,
            _ => None,
        };
        out.push(EpisodeMeta {
            index,
            length,
            file: data_file,
            source: file.to_path_buf(),
        });
    }
    Ok(out)
}

/// How frames become times: `frame_index / fps`.
#[derive(Debug, Clone, Copy)]
struct Clock {
    fps: Option<f64>,
}

impl Clock {
    /// The time of frame `frame` in ns: exact for an integer rate.
    fn frame_ns(self, frame: i64, written_ns: i64) -> i64 {
        match self.fps {
            Some(fps) if fps.fract() == 0.0 && fps <= 1e9 => {
                let fps = fps as i128;
                let ns = (i128::from(frame) * 1_000_000_000 * 2 + fps) / (2 * fps);
                i64::try_from(ns).unwrap_or(written_ns)
            }
            Some(fps) => crate::recording::seconds_to_ns(frame as f64 / fps).unwrap_or(written_ns),
            None => written_ns,
        }
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
    let fps = match info.get("fps") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            v.as_f64()
                .filter(|f| f.is_finite() && *f > 0.0)
                .ok_or_else(|| {
                    ImportError::new(&info_path, format!("fps is {v}, not a positive number"))
                        .with_field("fps")
                })?,
        ),
    };
    let clock = Clock { fps };
    let index = episode_index(dir, &info)?;
    if let (Some(total), Some(index)) = (info.get("total_episodes").and_then(Value::as_i64), &index)
    {
        if total != index.len() as i64 {
            return Err(ImportError::new(
                &info_path,
                format!(
                    "total_episodes is {total} but the episode index ({}) lists {}",
                    index.first().map_or_else(
                        || "meta/episodes".into(),
                        |m| m.source.display().to_string()
                    ),
                    index.len()
                ),
            )
            .with_field("total_episodes"));
        }
    }
    // Every data file the index names must be there.
    if let Some(index) = &index {
        let mut seen: Vec<&PathBuf> = Vec::new();
        for m in index {
            let Some(file) = &m.file else { continue };
            if seen.contains(&file) || file.is_file() {
                seen.push(file);
                continue;
            }
            let episodes: Vec<String> = index
                .iter()
                .filter(|o| o.file.as_ref() == Some(file))
                .map(|o| format!("{} ({} frames)", o.index, o.length))
                .collect();
            return Err(ImportError::new(
                file,
                format!(
                    "the data file is missing: {} lists episode{} {} in it",
                    m.source.display(),
                    if episodes.len() == 1 { "" } else { "s" },
                    episodes.join(", ")
                ),
            ));
        }
    }
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
            clock,
            &mut episodes,
            &mut order,
        )?;
    }
    let mut warnings_all = Vec::new();
    match &index {
        Some(index) => check_against_index(index, &episodes)?,
        None => {
            warnings_all.push("the dataset has no episode index (meta/episodes/ or meta/episodes.jsonl): episodes and frame counts are checked against info.json's totals only".to_string());
            if let Some(total) = info.get("total_episodes").and_then(Value::as_i64) {
                if total != episodes.len() as i64 {
                    return Err(ImportError::new(
                        &info_path,
                        format!(
                            "total_episodes is {total} but the data files under {} hold {}",
                            dir.join("data").display(),
                            episodes.len()
                        ),
                    )
                    .with_field("total_episodes"));
                }
            }
        }
    }
    if let Some(total) = info.get("total_frames").and_then(Value::as_i64) {
        let frames: usize = episodes.values().map(|e| e.time_ns.len()).sum();
        if total != frames as i64 {
            return Err(ImportError::new(
                &info_path,
                format!(
                    "total_frames is {total} but the data files under {} hold {frames}",
                    dir.join("data").display()
                ),
            )
            .with_field("total_frames"));
        }
    }
    if fps.is_none() {
        warnings_all.push("info.json gives no fps: times are the timestamps as written".into());
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
        meta.insert(
            "times".into(),
            Value::from(if fps.is_some() {
                "frame_index / fps"
            } else {
                "timestamp as written"
            }),
        );
        let mut warnings = warnings_all.clone();
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

/// Every indexed episode read with its length; no episode the index does
/// not list.
fn check_against_index(
    index: &[EpisodeMeta],
    episodes: &BTreeMap<i64, Episode>,
) -> Result<(), ImportError> {
    let mut listed: BTreeMap<i64, &EpisodeMeta> = BTreeMap::new();
    for m in index {
        if let Some(other) = listed.insert(m.index, m) {
            return Err(ImportError::new(
                &m.source,
                format!(
                    "episode {} is listed twice (also in {})",
                    m.index,
                    other.source.display()
                ),
            ));
        }
    }
    for m in index {
        let file = m
            .file
            .clone()
            .unwrap_or_else(|| m.source.parent().map(Path::to_path_buf).unwrap_or_default());
        match episodes.get(&m.index) {
            None => {
                return Err(ImportError::new(
                    &file,
                    format!(
                        "episode {} ({} frames in {}) is not in the data",
                        m.index,
                        m.length,
                        m.source.display()
                    ),
                ))
            }
            Some(e) if e.time_ns.len() as i64 != m.length => {
                let file = e.files.first().cloned().unwrap_or(file);
                return Err(ImportError::new(
                    &file,
                    format!(
                        "episode {} has {} frames, {} says {}",
                        m.index,
                        e.time_ns.len(),
                        m.source.display(),
                        m.length
                    ),
                ));
            }
            Some(e) => {
                if let (Some(want), Some(got)) = (&m.file, e.files.first()) {
                    if e.files.len() > 1 || want != got {
                        return Err(ImportError::new(
                            got,
                            format!(
                                "episode {} is here, {} puts it in {}",
                                m.index,
                                m.source.display(),
                                want.display()
                            ),
                        ));
                    }
                }
            }
        }
    }
    for (i, e) in episodes {
        if !listed.contains_key(i) {
            let file = e.files.first().cloned().unwrap_or_default();
            return Err(ImportError::new(
                &file,
                format!(
                    "episode {i} ({} frames) is not in the episode index ({})",
                    e.time_ns.len(),
                    index
                        .first()
                        .map_or_else(String::new, |m| m.source.display().to_string())
                ),
            ));
        }
    }
    Ok(())
}

/// Reads one parquet file's rows into their episodes ([`read_rows`], a
/// panic of the parquet crate an error naming the file).
fn read_file(
    file: &Path,
    names: &[String],
    action_names: &[String],
    has: (bool, bool),
    clock: Clock,
    episodes: &mut BTreeMap<i64, Episode>,
    order: &mut Vec<i64>,
) -> Result<(), ImportError> {
    pages::guarded(file, || {
        read_rows(file, names, action_names, has, clock, episodes, order)
    })
}

/// Reads one parquet file's rows into their episodes.
fn read_rows(
    file: &Path,
    names: &[String],
    action_names: &[String],
    (has_velocity, has_effort): (bool, bool),
    clock: Clock,
    episodes: &mut BTreeMap<i64, Episode>,
    order: &mut Vec<i64>,
) -> Result<(), ImportError> {
    let err = |e: parquet::errors::ParquetError| {
        ImportError::new(file, format!("cannot read the parquet file: {e}"))
    };
    let reader = pages::open(file)?;
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
        let episode = integer(get("episode_index")?).ok_or_else(|| {
            ImportError::new(file, "expected an integer").with_field(at("episode_index"))
        })?;
        let t_s = numbers(get("timestamp")?)
            .and_then(|v| v.first().copied())
            .filter(|t| t.is_finite())
            .ok_or_else(|| {
                ImportError::new(file, "expected a finite number of seconds")
                    .with_field(at("timestamp"))
            })?;
        let written = crate::recording::seconds_to_ns(t_s).ok_or_else(|| {
            ImportError::new(file, format!("time {t_s} s is out of range"))
                .with_field(at("timestamp"))
        })?;
        let e = episodes.entry(episode).or_insert_with(|| {
            order.push(episode);
            Episode::default()
        });
        let frame = match cells.get("frame_index") {
            Some(f) => integer(f).ok_or_else(|| {
                ImportError::new(file, "expected an integer").with_field(at("frame_index"))
            })?,
            None => e.frame_index.len() as i64,
        };
        if let Some(&previous) = e.frame_index.last() {
            if frame <= previous {
                return Err(ImportError::new(
                    file,
                    format!(
                        "episode {episode}: frame_index {frame} {} frame {previous}: two frames at one time",
                        if frame == previous { "repeats" } else { "comes after" }
                    ),
                )
                .with_field(at("frame_index")));
            }
        }
        let t = clock.frame_ns(frame, written);
        if let Some(fps) = clock.fps {
            let off_frames = (written - t) as f64 * 1e-9 * fps;
            if off_frames.abs() > 0.5 {
                return Err(ImportError::new(
                    file,
                    format!(
                        "episode {episode}: timestamp {} s is {off_frames:+.2} frames from frame_index {frame} / fps {fps} = {} s: the times disagree",
                        ns_text(written),
                        ns_text(t)
                    ),
                )
                .with_field(at("timestamp")));
            }
        }
        check_state_time(file, &at("timestamp"), e.time_ns.last().copied(), t)?;
        e.state.push(vector("observation.state", names)?);
        e.action.push(vector("action", action_names)?);
        if has_velocity {
            e.velocity.push(vector("observation.velocity", names)?);
        }
        if has_effort {
            e.effort.push(vector("observation.effort", names)?);
        }
        e.time_ns.push(t);
        e.frame_index.push(frame);
        if !e.files.iter().any(|f| f == file) {
            e.files.push(file.to_path_buf());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_fill_as_python_formats_them() {
        let v = [("chunk_index", 0), ("file_index", 12)];
        assert_eq!(
            fill_template(
                "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
                &v
            ),
            Ok("data/chunk-000/file-012.parquet".into())
        );
        assert_eq!(
            fill_template("e{file_index}.parquet", &v),
            Ok("e12.parquet".into())
        );
        assert!(fill_template("{nope:03d}", &v).is_err());
        assert!(fill_template("{file_index:x}", &v).is_err());
        assert!(fill_template("{file_index", &v).is_err());
    }

    #[test]
    fn a_v2_episode_index_names_each_episodes_file() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        std::fs::create_dir_all(dir.join("meta")).unwrap();
        let info = serde_json::json!({
            "codebase_version": "v2.1",
            "chunks_size": 2,
            "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        });
        std::fs::write(
            dir.join("meta/episodes.jsonl"),
            "{\"episode_index\": 0, \"tasks\": [\"t\"], \"length\": 5}\n\n{\"episode_index\": 3, \"tasks\": [\"t\"], \"length\": 7}\n",
        )
        .unwrap();
        let index = episode_index(dir, &info).unwrap().unwrap();
        assert_eq!(
            index
                .iter()
                .map(|m| (m.index, m.length, m.file.clone().unwrap()))
                .collect::<Vec<_>>(),
            [
                (0, 5, dir.join("data/chunk-000/episode_000000.parquet")),
                (3, 7, dir.join("data/chunk-001/episode_000003.parquet")),
            ]
        );
        std::fs::write(dir.join("meta/episodes.jsonl"), "{\"episode_index\": 0}\n").unwrap();
        let e = episode_index(dir, &info).unwrap_err().to_string();
        assert!(
            e.ends_with("meta/episodes.jsonl:1: no integer length"),
            "{e}"
        );
    }

    #[test]
    fn frames_become_exact_times() {
        let c = Clock { fps: Some(100.0) };
        assert_eq!(c.frame_ns(1494, 14_939_999_580), 14_940_000_000);
        let c = Clock { fps: Some(30.0) };
        assert_eq!(c.frame_ns(1, 0), 33_333_333);
        let c = Clock { fps: None };
        assert_eq!(c.frame_ns(7, 123), 123);
    }
}
