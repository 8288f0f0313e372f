//! Reading a rosbag2 bag's messages from either storage: MCAP files (the
//! `mcap` crate) or sqlite3 databases (`rusqlite` on the system's SQLite).
//!
//! A bag is a folder (`metadata.yaml` and one or more `.mcap` or `.db3`
//! files, split bags in name order) or one such file. Both storages carry
//! their own topic names and types, so `metadata.yaml` is not needed.

use realitygap_data::ImportError;
use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};

/// A topic of the bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topic {
    /// Name, e.g. `/joint_states`.
    pub name: String,
    /// ROS 2 type, e.g. `sensor_msgs/msg/JointState`.
    pub type_name: String,
    /// Serialisation (`cdr`).
    pub encoding: String,
}

/// One stored message.
#[derive(Debug, Clone, PartialEq)]
pub struct Stored {
    /// Index into [`Bag::topics`].
    pub topic: usize,
    /// When the recorder received it, nanoseconds since the epoch.
    pub log_time_ns: i64,
    /// Its serialised bytes.
    pub data: Vec<u8>,
    /// The file it is in.
    pub file: usize,
}

/// The messages of the chosen topics of a bag, in log-time order.
#[derive(Debug, Clone, PartialEq)]
pub struct Bag {
    /// The bag's storage files, in reading order.
    pub files: Vec<PathBuf>,
    /// Storage: `mcap` or `sqlite3`.
    pub storage: &'static str,
    /// Every topic of the bag.
    pub topics: Vec<Topic>,
    /// The messages kept (see [`read_bag`]).
    pub messages: Vec<Stored>,
}

impl Bag {
    /// The topic with this name.
    pub fn topic(&self, name: &str) -> Option<usize> {
        self.topics.iter().position(|t| t.name == name)
    }
}

/// The storage files of a bag given as a folder or a file.
fn storage_files(path: &Path) -> Result<(Vec<PathBuf>, &'static str), ImportError> {
    let kind = |p: &Path| match p.extension().and_then(|e| e.to_str()) {
        Some("mcap") => Some("mcap"),
        Some("db3") => Some("sqlite3"),
        _ => None,
    };
    let meta = fs::metadata(path)
        .map_err(|e| ImportError::new(path, format!("cannot read the bag: {e}")))?;
    if meta.is_file() {
        let storage = kind(path).ok_or_else(|| {
            ImportError::new(
                path,
                "not a rosbag2 storage file: expected a .mcap or .db3 file, or a bag folder",
            )
        })?;
        return Ok((vec![path.to_path_buf()], storage));
    }
    let mut files: Vec<(PathBuf, &'static str)> = fs::read_dir(path)
        .map_err(|e| ImportError::new(path, format!("cannot list the bag folder: {e}")))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .filter_map(|p| kind(&p).map(|k| (p, k)))
        .collect();
    if files.is_empty() {
        return Err(ImportError::new(
            path,
            "the bag folder holds no .mcap or .db3 file",
        ));
    }
    let storage = files[0].1;
    if let Some((other, k)) = files.iter().find(|(_, k)| *k != storage) {
        return Err(ImportError::new(
            other,
            format!("the bag folder mixes {storage} and {k} files; keep one bag per folder"),
        ));
    }
    // Split bags are named <bag>_0, <bag>_1, ..., <bag>_10: by number.
    let number = |p: &Path| -> (String, u64) {
        let stem = p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let n = stem[stem.len() - digits..].parse().unwrap_or(0);
        (stem[..stem.len() - digits].to_string(), n)
    };
    files.sort_by_key(|(p, _)| number(p));
    Ok((files.into_iter().map(|(p, _)| p).collect(), storage))
}

/// Reads a bag, keeping the messages of the topics `keep` accepts (by name
/// and type); every topic is listed whatever `keep` says.
pub fn read_bag(path: &Path, keep: &dyn Fn(&Topic) -> bool) -> Result<Bag, ImportError> {
    let (files, storage) = storage_files(path)?;
    let mut bag = Bag {
        files: files.clone(),
        storage,
        topics: Vec::new(),
        messages: Vec::new(),
    };
    for (index, file) in files.iter().enumerate() {
        match storage {
            "mcap" => read_mcap(file, index, &mut bag, keep)?,
            _ => read_sqlite(file, index, &mut bag, keep)?,
        }
    }
    // Stable: messages with equal times keep their stored order.
    bag.messages.sort_by_key(|m| m.log_time_ns);
    Ok(bag)
}

/// The index of a topic in `bag.topics`, adding it when new; an error when
/// a topic name comes back with another type.
fn topic_index(bag: &mut Bag, file: &Path, topic: Topic) -> Result<usize, ImportError> {
    match bag.topics.iter().position(|t| t.name == topic.name) {
        Some(i) if bag.topics[i].type_name == topic.type_name => Ok(i),
        Some(i) => Err(ImportError::new(
            file,
            format!(
                "topic {} has type {} here and {} in an earlier file",
                topic.name, topic.type_name, bag.topics[i].type_name
            ),
        )),
        None => {
            bag.topics.push(topic);
            Ok(bag.topics.len() - 1)
        }
    }
}

/// Nanoseconds (unsigned, as stored) as i64, or an error.
fn log_time(file: &Path, topic: &str, ns: u64) -> Result<i64, ImportError> {
    i64::try_from(ns).map_err(|_| {
        ImportError::new(file, format!("log time {ns} ns is beyond the year 2262"))
            .with_field(topic)
    })
}

/// The topic of an MCAP channel.
fn topic_of(channel: &mcap::Channel) -> Topic {
    Topic {
        name: channel.topic.clone(),
        type_name: channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default(),
        encoding: channel.message_encoding.clone(),
    }
}

/// Reads the messages of one MCAP file.
fn read_mcap(
    file: &Path,
    index: usize,
    bag: &mut Bag,
    keep: &dyn Fn(&Topic) -> bool,
) -> Result<(), ImportError> {
    let bytes = fs::read(file).map_err(|e| ImportError::new(file, format!("cannot read: {e}")))?;
    let stream = mcap::MessageStream::new(&bytes)
        .map_err(|e| ImportError::new(file, format!("not an MCAP file: {e}")))?;
    // Channel id -> (topic index, kept).
    let mut channels: HashMap<u16, (usize, bool)> = HashMap::new();
    for (count, message) in stream.enumerate() {
        let message = message.map_err(|e| {
            ImportError::new(
                file,
                format!("the MCAP file is damaged or incomplete after {count} messages: {e}"),
            )
        })?;
        let channel = &message.channel;
        let (topic, kept) = match channels.get(&channel.id) {
            Some(&known) => known,
            None => {
                let topic = topic_of(channel);
                let kept = keep(&topic);
                let i = topic_index(bag, file, topic)?;
                channels.insert(channel.id, (i, kept));
                (i, kept)
            }
        };
        if kept {
            let t = log_time(file, &channel.topic, message.log_time)?;
            bag.messages.push(Stored {
                topic,
                log_time_ns: t,
                data: message.data.into_owned(),
                file: index,
            });
        }
    }
    // Topics declared in the summary without messages are topics too.
    if let Ok(Some(summary)) = mcap::Summary::read(&bytes) {
        for channel in summary.channels.values() {
            let topic = topic_of(channel);
            topic_index(bag, file, topic)?;
        }
    }
    Ok(())
}

/// Reads the messages of one rosbag2 sqlite3 database.
fn read_sqlite(
    file: &Path,
    index: usize,
    bag: &mut Bag,
    keep: &dyn Fn(&Topic) -> bool,
) -> Result<(), ImportError> {
    use rusqlite::{Connection, OpenFlags};
    let err = |e: rusqlite::Error| {
        ImportError::new(
            file,
            format!("cannot read the rosbag2 sqlite3 database: {e}"),
        )
    };
    let db = Connection::open_with_flags(
        file,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(err)?;
    let mut ids: HashMap<i64, (usize, bool)> = HashMap::new();
    {
        let mut stmt = db
            .prepare("SELECT id, name, type, serialization_format FROM topics")
            .map_err(err)?;
        let rows = stmt
            .query_map([], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    Topic {
                        name: r.get(1)?,
                        type_name: r.get(2)?,
                        encoding: r.get(3)?,
                    },
                ))
            })
            .map_err(err)?;
        for row in rows {
            let (id, topic) = row.map_err(err)?;
            let kept = keep(&topic);
            let i = topic_index(bag, file, topic)?;
            ids.insert(id, (i, kept));
        }
    }
    let mut stmt = db
        .prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id")
        .map_err(err)?;
    let rows = stmt
        .query_map([], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                r.get::<_, i64>(1)?,
                r.get::<_, Vec<u8>>(2)?,
            ))
        })
        .map_err(err)?;
    for row in rows {
        let (topic_id, t, data) = row.map_err(err)?;
        let &(topic, kept) = ids.get(&topic_id).ok_or_else(|| {
            ImportError::new(
                file,
                format!("a message of topic id {topic_id}, which the topics table does not list"),
            )
        })?;
        if kept {
            bag.messages.push(Stored {
                topic,
                log_time_ns: t,
                data,
                file: index,
            });
        }
    }
    Ok(())
}
