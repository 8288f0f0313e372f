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
fn log_time_ns(file: &Path, topic: &str, ns: u64) -> Result<i64, ImportError> {
    i64::try_from(ns).map_err(|_| {
        ImportError::new(file, format!("log time {ns} ns is beyond the year 2262"))
            .with_field(topic)
    })
}

/// The largest record an MCAP file of `file_len` bytes is allowed to hold,
/// once decompressed: 16 times the file and 16 MiB more. Every length the
/// file states (records, chunks, their compressed and decompressed sizes,
/// the strings and byte arrays inside records) is checked against it, or
/// against the record that holds it, before anything is allocated for it: a
/// damaged length field is an error, never a huge allocation.
pub fn mcap_record_limit(file_len: usize) -> usize {
    file_len.saturating_mul(16).saturating_add(16 << 20)
}

/// The MCAP magic, at both ends of a file.
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// MCAP record opcodes read here.
mod op {
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
}

fn u64_at(b: &[u8], p: usize) -> u64 {
    b.get(p..p + 8)
        .map_or(0, |b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
}

/// Checks the length fields of an MCAP file's records outside chunks
/// before they are read: every record fits in the file, and every chunk's
/// compression name and records fit in the chunk, its uncompressed size in
/// [`mcap_record_limit`] (an uncompressed chunk's size is its records'
/// length). A file without the magic is left to the reader to refuse, a
/// truncated one to say where it ends.
pub fn check_mcap_lengths(bytes: &[u8]) -> Result<(), String> {
    if !bytes.starts_with(MCAP_MAGIC) {
        return Ok(());
    }
    let limit = mcap_record_limit(bytes.len()) as u64;
    let mut pos = MCAP_MAGIC.len();
    while bytes.len() - pos >= 9 {
        let opcode = bytes[pos];
        let len = u64_at(bytes, pos + 1);
        let body = pos + 9;
        let left = (bytes.len() - body) as u64;
        if len > left {
            return Err(format!(
                "the record at byte {pos} (opcode {opcode:#04x}) claims {len} bytes, {left} are left in the file"
            ));
        }
        let record = &bytes[body..body + len as usize];
        if opcode == op::CHUNK {
            let at = |m: String| format!("the chunk at byte {pos}: {m}");
            if record.len() < 40 {
                return Err(at(format!(
                    "{} bytes, shorter than a chunk's header",
                    record.len()
                )));
            }
            let uncompressed = u64_at(record, 16);
            let name_len = u64::from(u32::from_le_bytes(
                record[28..32].try_into().unwrap_or([0; 4]),
            ));
            if 32 + name_len + 8 > record.len() as u64 {
                return Err(at(format!(
                    "its compression name claims {name_len} bytes of its {}",
                    record.len()
                )));
            }
            let name_end = 32 + name_len as usize;
            let records = u64_at(record, name_end);
            let room = (record.len() - name_end - 8) as u64;
            if records > room {
                return Err(at(format!(
                    "its records claim {records} bytes, it holds {room}"
                )));
            }
            if name_len == 0 && uncompressed != records {
                return Err(at(format!(
                    "its {records} bytes of records are not compressed, but it claims {uncompressed} bytes uncompressed"
                )));
            }
            if uncompressed > limit {
                return Err(at(format!(
                    "it claims {uncompressed} bytes uncompressed, more than this {}-byte file can hold (at most {limit})",
                    bytes.len()
                )));
            }
        }
        pos = body + len as usize;
        if opcode == op::FOOTER {
            // The closing magic follows.
            break;
        }
    }
    Ok(())
}

/// The fields of an MCAP record, read in order, each within the record.
struct Fields<'a> {
    record: &'a [u8],
    pos: usize,
}

impl<'a> Fields<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let bytes = self
            .pos
            .checked_add(n)
            .and_then(|end| self.record.get(self.pos..end))
            .ok_or_else(|| {
                format!(
                    "its {what} claims {n} bytes, {} are left in the record",
                    self.record.len().saturating_sub(self.pos)
                )
            })?;
        self.pos += n;
        Ok(bytes)
    }

    fn u16(&mut self, what: &str) -> Result<u16, String> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A u32 length, then that many bytes.
    fn prefixed(&mut self, what: &str) -> Result<&'a [u8], String> {
        let n = self.u32(what)? as usize;
        self.take(n, what)
    }

    fn text(&mut self, what: &str) -> Result<String, String> {
        let b = self.prefixed(what)?;
        std::str::from_utf8(b)
            .map(str::to_string)
            .map_err(|_| format!("its {what} is not UTF-8"))
    }
}

/// Reads the messages of one MCAP file.
///
/// The file is checked first ([`check_mcap_lengths`]); then `mcap`'s
/// linear reader, with [`mcap_record_limit`] on every record, splits it
/// into records and decompresses the chunks, and the schema, channel and
/// message records are parsed here, every length within its record (the
/// crate's own parsers allocate a string's stated length first: up to 4
/// GiB from a damaged field).
fn read_mcap(
    file: &Path,
    index: usize,
    bag: &mut Bag,
    keep: &dyn Fn(&Topic) -> bool,
) -> Result<(), ImportError> {
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let bytes = fs::read(file).map_err(|e| ImportError::new(file, format!("cannot read: {e}")))?;
    check_mcap_lengths(&bytes)
        .map_err(|m| ImportError::new(file, format!("the MCAP file is damaged: {m}")))?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(mcap_record_limit(bytes.len())),
    );
    let mut rest: &[u8] = &bytes;
    let mut schemas: HashMap<u16, String> = HashMap::new();
    // Channel id -> (topic index, kept).
    let mut channels: HashMap<u16, (usize, bool)> = HashMap::new();
    let mut count = 0usize;
    let damaged = |count: usize, at: usize, m: String| {
        ImportError::new(
            file,
            format!(
                "the MCAP file is damaged or incomplete after {count} messages (read up to byte {at} of {}): {m}",
                bytes.len()
            ),
        )
    };
    while let Some(event) = reader.next_event() {
        let at = bytes.len() - rest.len();
        let (opcode, data) = match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
                continue;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => (opcode, data),
            Err(e) if count == 0 && at <= MCAP_MAGIC.len() => {
                return Err(ImportError::new(file, format!("not an MCAP file: {e}")))
            }
            Err(e) => return Err(damaged(count, at, e.to_string())),
        };
        let mut f = Fields {
            record: data,
            pos: 0,
        };
        match opcode {
            op::SCHEMA => {
                let parsed = (|| {
                    let id = f.u16("id")?;
                    let name = f.text("name")?;
                    f.text("encoding")?;
                    f.prefixed("data")?;
                    Ok::<_, String>((id, name))
                })()
                .map_err(|m| damaged(count, at, format!("a schema record: {m}")))?;
                schemas.insert(parsed.0, parsed.1);
            }
            op::CHANNEL => {
                let (id, topic) = (|| {
                    let id = f.u16("id")?;
                    let schema = f.u16("schema id")?;
                    let name = f.text("topic")?;
                    let encoding = f.text("message encoding")?;
                    f.prefixed("metadata")?;
                    let type_name = match schema {
                        0 => String::new(),
                        s => schemas
                            .get(&s)
                            .cloned()
                            .ok_or_else(|| format!("channel {id} ({name}) names schema {s}, which no schema record before it defines"))?,
                    };
                    Ok::<_, String>((
                        id,
                        Topic {
                            name,
                            type_name,
                            encoding,
                        },
                    ))
                })()
                .map_err(|m| damaged(count, at, format!("a channel record: {m}")))?;
                let i = topic_index(bag, file, topic.clone())?;
                let kept = keep(&topic);
                match channels.get(&id) {
                    Some(&(j, _)) if j != i => {
                        return Err(damaged(
                            count,
                            at,
                            format!(
                                "channel {id} is defined twice, as {} and as {}",
                                bag.topics[j].name, topic.name
                            ),
                        ))
                    }
                    _ => {
                        channels.insert(id, (i, kept));
                    }
                }
            }
            op::MESSAGE => {
                let (channel, log_time) = (|| {
                    let channel = f.u16("channel id")?;
                    f.take(4, "sequence")?;
                    let log_time = u64_at(f.take(8, "log time")?, 0);
                    f.take(8, "publish time")?;
                    Ok::<_, String>((channel, log_time))
                })()
                .map_err(|m| damaged(count, at, format!("a message record: {m}")))?;
                let &(topic, kept) = channels.get(&channel).ok_or_else(|| {
                    damaged(
                        count,
                        at,
                        format!("a message of channel {channel}, which no channel record before it defines"),
                    )
                })?;
                if kept {
                    let t = log_time_ns(file, &bag.topics[topic].name, log_time)?;
                    bag.messages.push(Stored {
                        topic,
                        log_time_ns: t,
                        data: data[f.pos..].to_vec(),
                        file: index,
                    });
                }
                count += 1;
            }
            _ => {}
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
    // A message's length is read (from its record header, without its
    // bytes) and checked against the file's size before its bytes are
    // copied: a damaged database cannot make a copy larger than itself.
    let file_len = fs::metadata(file).map(|m| m.len()).unwrap_or(0);
    let mut stmt = db
        .prepare(
            "SELECT topic_id, timestamp, length(data), data, id FROM messages ORDER BY timestamp, id",
        )
        .map_err(err)?;
    let mut rows = stmt.query([]).map_err(err)?;
    while let Some(r) = rows.next().map_err(err)? {
        let topic_id = r.get::<_, i64>(0).map_err(err)?;
        let t = r.get::<_, i64>(1).map_err(err)?;
        let id = r.get::<_, Option<i64>>(4).map_err(err)?.unwrap_or(-1);
        let &(topic, kept) = ids.get(&topic_id).ok_or_else(|| {
            ImportError::new(
                file,
                format!("message id {id} is of topic id {topic_id}, which the topics table does not list"),
            )
        })?;
        if !kept {
            continue;
        }
        let len = r.get::<_, Option<i64>>(2).map_err(err)?.unwrap_or(0);
        if u64::try_from(len).map_or(true, |l| l > file_len) {
            return Err(ImportError::new(
                file,
                format!(
                    "message id {id} claims {len} bytes, more than the whole file ({file_len} bytes): the database is damaged"
                ),
            ));
        }
        let data = r.get::<_, Vec<u8>>(3).map_err(err)?;
        bag.messages.push(Stored {
            topic,
            log_time_ns: t,
            data,
            file: index,
        });
    }
    Ok(())
}
