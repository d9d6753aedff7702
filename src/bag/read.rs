//! Reading rosbag2 bags (MCAP and sqlite3 storage).
//!
//! A truncated or incomplete MCAP (a recording cut off before its footer)
//! is reported as such, with the byte where the data ends and the record it
//! ends in; the mcap crate alone only said "Bad magic number".

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::metadata::storage_files;
use super::BagError;

/// Storage plugin of a bag file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// `rosbag2_storage_mcap`.
    Mcap,
    /// `rosbag2_storage_sqlite3`.
    Sqlite3,
}

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub name: String,
    /// Message type (`pkg/msg/Name`).
    pub type_name: String,
    /// Messages on the topic (over all files).
    pub message_count: u64,
    /// `offered_qos_profiles` as stored (YAML), empty when absent.
    pub offered_qos_profiles: String,
    /// RIHS01 type hash as stored, empty when absent (Humble bags).
    pub type_hash: String,
}

/// One recorded message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagMessage {
    /// Topic name.
    pub topic: String,
    /// Message type (`pkg/msg/Name`).
    pub type_name: String,
    /// Receive time, ns since the epoch.
    pub log_time: u64,
    /// Send time, ns since the epoch (sqlite3 bags: same as `log_time`).
    pub publish_time: u64,
    /// CDR bytes including the encapsulation header.
    pub data: Vec<u8>,
}

/// An opened bag: its storage files and topics.
#[derive(Debug, Clone)]
pub struct Bag {
    /// Path given to [`Bag::open`].
    pub path: PathBuf,
    /// Storage plugin.
    pub storage: Storage,
    /// Storage files, in order.
    pub files: Vec<PathBuf>,
    /// Topics with message encoding `cdr`, sorted by name.
    pub topics: Vec<TopicInfo>,
    /// Topics skipped because their encoding is not `cdr`.
    pub skipped_topics: Vec<String>,
}

fn storage_of(path: &Path) -> Option<Storage> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("mcap") => Some(Storage::Mcap),
        Some("db3") => Some(Storage::Sqlite3),
        _ => None,
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> BagError + '_ {
    move |source| BagError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The 8-byte magic that opens and closes an MCAP file.
const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Why `buf` is an incomplete MCAP file, if it is one: where the data ends
/// (inside which record, after how many whole ones). `None` when it has
/// both magics or is no MCAP at all. Linear in the number of records.
fn mcap_truncation(buf: &[u8]) -> Option<String> {
    if !buf.starts_with(MCAP_MAGIC) {
        return (buf.len() < 8 && MCAP_MAGIC.starts_with(buf)).then(|| {
            format!(
                "truncated MCAP: the file has {} bytes, less than the 8-byte magic",
                buf.len()
            )
        });
    }
    if buf.len() >= 16 && buf.ends_with(MCAP_MAGIC) {
        return None;
    }
    let (mut pos, mut records) = (8usize, 0usize);
    let end = buf.len();
    let whole = |records: usize| format!("after {records} complete records");
    loop {
        if pos == end {
            return Some(format!(
                "truncated or incomplete MCAP: the data ends at byte {end} {}, without the footer and end magic (the recording was cut off)",
                whole(records)
            ));
        }
        let Some(head) = buf.get(pos..pos + 9) else {
            return Some(format!(
                "truncated MCAP: the data ends at byte {end} inside the header of the record at byte {pos}, {}",
                whole(records)
            ));
        };
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let len = u64::from_le_bytes(len);
        let next = (pos as u64 + 9).saturating_add(len);
        if next > end as u64 {
            return Some(format!(
                "truncated MCAP: the data ends at byte {end} inside the record (opcode 0x{:02x}) at byte {pos} that announces {len} bytes, {}",
                head[0],
                whole(records)
            ));
        }
        if head[0] == 0x02 {
            return Some(format!(
                "incomplete MCAP: the footer at byte {pos} is not followed by the end magic (file of {end} bytes)"
            ));
        }
        pos = next as usize;
        records += 1;
    }
}

fn mcap_err<'a>(path: &'a Path, buf: &'a [u8]) -> impl Fn(mcap::McapError) -> BagError + 'a {
    move |e| BagError::Mcap {
        path: path.to_path_buf(),
        message: match mcap_truncation(buf) {
            Some(why) => format!("{why} ({e})"),
            None => e.to_string(),
        },
    }
}

fn sql_err(path: &Path) -> impl Fn(rusqlite::Error) -> BagError + '_ {
    move |e| BagError::Sqlite {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

impl Bag {
    /// Open a bag file (`.mcap`, `.db3`) or bag directory and list its topics.
    ///
    /// # Errors
    /// [`BagError`] when the path is not a readable rosbag2 bag.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let (storage, files) = if path.is_dir() {
            Self::directory_files(path)?
        } else {
            let s = storage_of(path).ok_or_else(|| BagError::NotABag {
                path: path.to_path_buf(),
            })?;
            if !path.is_file() {
                return Err(BagError::Io {
                    path: path.to_path_buf(),
                    source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
                });
            }
            (s, vec![path.to_path_buf()])
        };
        let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut skipped = Vec::new();
        for f in &files {
            let found = match storage {
                Storage::Mcap => mcap_topics(f, &mut skipped)?,
                Storage::Sqlite3 => sqlite_topics(f)?,
            };
            for t in found {
                topics
                    .entry(t.name.clone())
                    .and_modify(|e| e.message_count += t.message_count)
                    .or_insert(t);
            }
        }
        skipped.sort();
        skipped.dedup();
        Ok(Self {
            path: path.to_path_buf(),
            storage,
            files,
            topics: topics.into_values().collect(),
            skipped_topics: skipped,
        })
    }

    fn directory_files(dir: &Path) -> Result<(Storage, Vec<PathBuf>), BagError> {
        let meta = dir.join("metadata.yaml");
        if meta.is_file() {
            let text = std::fs::read_to_string(&meta).map_err(io_err(&meta))?;
            let (id, rel) = storage_files(&text);
            let files: Vec<PathBuf> = rel.iter().map(|r| dir.join(r)).collect();
            let storage = match id.as_deref() {
                Some("mcap") => Some(Storage::Mcap),
                Some("sqlite3") => Some(Storage::Sqlite3),
                _ => files.first().and_then(|f| storage_of(f)),
            };
            if let Some(s) = storage {
                if !files.is_empty() && files.iter().all(|f| f.is_file()) {
                    return Ok((s, files));
                }
            }
        }
        // No (usable) metadata.yaml: take the storage files in name order.
        let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io_err(dir))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| storage_of(p).is_some())
            .collect();
        found.sort();
        let storage =
            found
                .first()
                .and_then(|f| storage_of(f))
                .ok_or_else(|| BagError::NotABag {
                    path: dir.to_path_buf(),
                })?;
        found.retain(|f| storage_of(f) == Some(storage));
        Ok((storage, found))
    }

    /// The topic named `name`.
    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// Total message count over the readable topics.
    pub fn message_count(&self) -> u64 {
        self.topics.iter().map(|t| t.message_count).sum()
    }

    /// Every message of `topics` (all readable topics when empty), sorted by
    /// log time (stable).
    ///
    /// # Errors
    /// [`BagError`] when a storage file is unreadable or corrupt.
    pub fn read(&self, topics: &[&str]) -> Result<Vec<BagMessage>, BagError> {
        let wanted = |t: &str| topics.is_empty() || topics.contains(&t);
        let mut out = Vec::new();
        for f in &self.files {
            match self.storage {
                Storage::Mcap => read_mcap(f, &wanted, &mut out)?,
                Storage::Sqlite3 => read_sqlite(f, &wanted, &mut out)?,
            }
        }
        out.sort_by_key(|m| m.log_time);
        Ok(out)
    }
}

struct ChannelInfo {
    topic: String,
    type_name: String,
    message_encoding: String,
    qos: String,
    hash: String,
}

impl ChannelInfo {
    fn of(ch: &mcap::Channel<'_>) -> Self {
        let meta = |k: &str| ch.metadata.get(k).cloned().unwrap_or_default();
        Self {
            topic: ch.topic.clone(),
            type_name: ch
                .schema
                .as_ref()
                .map(|s| s.name.clone())
                .unwrap_or_default(),
            message_encoding: ch.message_encoding.clone(),
            qos: meta("offered_qos_profiles"),
            hash: meta("topic_type_hash"),
        }
    }
}

/// The topics and messages of MCAP bytes held in memory (`path` names them
/// in errors): what [`Bag::open`] and [`Bag::read`] do with one file, for
/// the fuzz targets and for callers that already hold the bytes.
///
/// # Errors
/// [`BagError::Mcap`] for corrupt or truncated MCAP.
pub fn parse_mcap(path: &Path, buf: &[u8]) -> Result<(Vec<TopicInfo>, Vec<BagMessage>), BagError> {
    let topics = mcap_topics_in(path, buf, &mut Vec::new())?;
    let mut messages = Vec::new();
    read_mcap_in(path, buf, &|_| true, &mut messages)?;
    Ok((topics, messages))
}

fn mcap_topics(path: &Path, skipped: &mut Vec<String>) -> Result<Vec<TopicInfo>, BagError> {
    let buf = std::fs::read(path).map_err(io_err(path))?;
    mcap_topics_in(path, &buf, skipped)
}

fn mcap_topics_in(
    path: &Path,
    buf: &[u8],
    skipped: &mut Vec<String>,
) -> Result<Vec<TopicInfo>, BagError> {
    let mut counts: BTreeMap<u16, u64> = BTreeMap::new();
    let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
    match super::bounded::summary(buf).map_err(mcap_err(path, buf))? {
        Some(summary) if summary.stats.is_some() => {
            if let Some(stats) = &summary.stats {
                counts = stats.channel_message_counts.clone();
            }
            for (id, ch) in &summary.channels {
                channels.insert(*id, ChannelInfo::of(ch));
            }
        }
        _ => {
            for m in super::bounded::Messages::new(buf) {
                let m = m.map_err(mcap_err(path, buf))?;
                *counts.entry(m.channel.id).or_default() += 1;
                channels
                    .entry(m.channel.id)
                    .or_insert_with(|| ChannelInfo::of(&m.channel));
            }
        }
    }
    let mut out = Vec::new();
    for (id, ch) in channels {
        if ch.message_encoding != "cdr" {
            skipped.push(ch.topic.clone());
            continue;
        }
        out.push(TopicInfo {
            name: ch.topic,
            type_name: ch.type_name,
            message_count: counts.get(&id).copied().unwrap_or(0),
            offered_qos_profiles: ch.qos,
            type_hash: ch.hash,
        });
    }
    // Several channels may share a topic (e.g. after a restart): merge.
    let mut merged: BTreeMap<String, TopicInfo> = BTreeMap::new();
    for t in out {
        merged
            .entry(t.name.clone())
            .and_modify(|e| e.message_count += t.message_count)
            .or_insert(t);
    }
    Ok(merged.into_values().collect())
}

fn read_mcap(
    path: &Path,
    wanted: &dyn Fn(&str) -> bool,
    out: &mut Vec<BagMessage>,
) -> Result<(), BagError> {
    let buf = std::fs::read(path).map_err(io_err(path))?;
    read_mcap_in(path, &buf, wanted, out)
}

fn read_mcap_in(
    path: &Path,
    buf: &[u8],
    wanted: &dyn Fn(&str) -> bool,
    out: &mut Vec<BagMessage>,
) -> Result<(), BagError> {
    for m in super::bounded::Messages::new(buf) {
        let m = m.map_err(mcap_err(path, buf))?;
        if m.channel.message_encoding != "cdr" || !wanted(&m.channel.topic) {
            continue;
        }
        out.push(BagMessage {
            topic: m.channel.topic.clone(),
            type_name: m
                .channel
                .schema
                .as_ref()
                .map(|s| s.name.clone())
                .unwrap_or_default(),
            log_time: m.log_time,
            publish_time: m.publish_time,
            data: m.data.into_owned(),
        });
    }
    Ok(())
}

fn open_sqlite(path: &Path) -> Result<rusqlite::Connection, BagError> {
    rusqlite::Connection::open_with_flags(path, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .map_err(sql_err(path))
}

fn has_column(conn: &rusqlite::Connection, table: &str, column: &str) -> bool {
    conn.prepare(&format!("SELECT {column} FROM {table} LIMIT 0"))
        .is_ok()
}

fn sqlite_topics(path: &Path) -> Result<Vec<TopicInfo>, BagError> {
    let conn = open_sqlite(path)?;
    let hash_col = if has_column(&conn, "topics", "type_description_hash") {
        "t.type_description_hash"
    } else {
        "''"
    };
    let qos_col = if has_column(&conn, "topics", "offered_qos_profiles") {
        "t.offered_qos_profiles"
    } else {
        "''"
    };
    let sql = format!(
        "SELECT t.name, t.type, t.serialization_format, {qos_col}, {hash_col}, \
         (SELECT COUNT(*) FROM messages m WHERE m.topic_id = t.id) FROM topics t ORDER BY t.name"
    );
    let mut stmt = conn.prepare(&sql).map_err(sql_err(path))?;
    let rows = stmt
        .query_map([], |r| {
            Ok((
                TopicInfo {
                    name: r.get(0)?,
                    type_name: r.get(1)?,
                    offered_qos_profiles: r.get(3)?,
                    type_hash: r.get(4)?,
                    message_count: r.get::<_, i64>(5)?.max(0) as u64,
                },
                r.get::<_, String>(2)?,
            ))
        })
        .map_err(sql_err(path))?;
    let mut out = Vec::new();
    for row in rows {
        let (t, fmt) = row.map_err(sql_err(path))?;
        if fmt == "cdr" {
            out.push(t);
        }
    }
    Ok(out)
}

fn read_sqlite(
    path: &Path,
    wanted: &dyn Fn(&str) -> bool,
    out: &mut Vec<BagMessage>,
) -> Result<(), BagError> {
    let conn = open_sqlite(path)?;
    let mut stmt = conn
        .prepare(
            "SELECT t.name, t.type, m.timestamp, m.data FROM messages m \
             JOIN topics t ON m.topic_id = t.id WHERE t.serialization_format = 'cdr' \
             ORDER BY m.timestamp, m.id",
        )
        .map_err(sql_err(path))?;
    let rows = stmt
        .query_map([], |r| {
            Ok((
                r.get::<_, String>(0)?,
                r.get::<_, String>(1)?,
                r.get::<_, i64>(2)?,
                r.get::<_, Vec<u8>>(3)?,
            ))
        })
        .map_err(sql_err(path))?;
    for row in rows {
        let (topic, type_name, ts, data) = row.map_err(sql_err(path))?;
        if !wanted(&topic) {
            continue;
        }
        let t = ts.max(0) as u64;
        out.push(BagMessage {
            topic,
            type_name,
            log_time: t,
            publish_time: t,
            data,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn committed_bag() -> Vec<u8> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags/synth_ellipsoid.mcap");
        std::fs::read(p).unwrap()
    }

    #[test]
    fn a_truncated_mcap_says_where_it_ends() {
        let full = committed_bag();
        assert_eq!(mcap_truncation(&full), None);
        let dir = tempfile::tempdir().unwrap();
        for cut in [full.len() / 2, full.len() - 3, 12, 5] {
            let f = dir.path().join(format!("cut{cut}.mcap"));
            std::fs::write(&f, &full[..cut]).unwrap();
            let e = Bag::open(&f).unwrap_err().to_string();
            assert!(
                e.contains("truncated") || e.contains("incomplete"),
                "{cut}: {e}"
            );
            assert!(e.contains(&format!("{cut}")), "{cut}: {e}");
            assert!(e.contains(&format!("cut{cut}.mcap")), "{e}");
        }
        // The cut in the middle names the record it falls in.
        let e = mcap_truncation(&full[..full.len() / 2]).unwrap();
        assert!(e.contains("inside the record (opcode 0x"), "{e}");
        // A chunk that lies about its uncompressed size is an error, not an
        // abort on the allocation (the fuzz pass's finding, rebuilt here).
        let mut pos = 8;
        while full[pos] != 0x06 {
            let len = u64::from_le_bytes(full[pos + 1..pos + 9].try_into().unwrap());
            pos += 9 + len as usize;
        }
        let mut lie = full.clone();
        lie[pos + 25..pos + 33].copy_from_slice(&3_467_835_911_653_498_921u64.to_le_bytes());
        let e = parse_mcap(Path::new("lie.mcap"), &lie)
            .unwrap_err()
            .to_string();
        assert!(e.contains("lie.mcap"), "{e}");
        // Not an MCAP at all: no truncation story.
        assert_eq!(mcap_truncation(b"PAR1 something else"), None);
    }

    /// An uncompressed-chunk bag with one message on `/t`.
    fn plain_chunk_bag() -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new()
            .compression(None)
            .create(&mut out)
            .unwrap();
        let schema = w.add_schema("std_msgs/msg/Empty", "ros2msg", b"").unwrap();
        let ch = w
            .add_channel(schema, "/t", "cdr", &BTreeMap::new())
            .unwrap();
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: 1,
            log_time: 1,
            publish_time: 1,
        };
        w.write_to_known_channel(&header, &[0, 1, 0, 0, 0, 0, 0, 0])
            .unwrap();
        w.finish().unwrap();
        drop(w);
        out.into_inner()
    }

    /// The fuzz pass's abort, rebuilt: a message record inside a chunk that
    /// declares 3.4·10¹⁸ bytes made the mcap crate's chunk reader reserve
    /// that much and abort the process. It is a typed error now.
    #[test]
    fn a_record_inside_a_chunk_that_lies_about_its_length_is_an_error() {
        let bag = plain_chunk_bag();
        let (topics, messages) = parse_mcap(Path::new("ok.mcap"), &bag).unwrap();
        assert_eq!((topics.len(), messages.len()), (1, 1));
        let at = bag
            .windows(9)
            .position(|w| w[0] == 0x05 && w[1..] == 30u64.to_le_bytes())
            .expect("the message record");
        let mut lie = bag.clone();
        lie[at + 1..at + 9].copy_from_slice(&3_467_835_911_653_498_921u64.to_le_bytes());
        let e = parse_mcap(Path::new("lie.mcap"), &lie)
            .unwrap_err()
            .to_string();
        assert!(e.contains("lie.mcap"), "{e}");
    }
}
