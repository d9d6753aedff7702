//! Writing rosbag2 MCAP bags.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use super::metadata::{render_bag_metadata, render_metadata, Qos, TopicEntry};
use super::BagError;
use crate::wire::{self, msgdef, msgs, RosMessage};

struct Topic {
    channel: u16,
    type_name: String,
    qos: Qos,
    type_hash: String,
    count: u64,
}

/// What a finished bag holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagSummary {
    /// The `.mcap` file written.
    pub mcap_path: PathBuf,
    /// `metadata.yaml`, when the bag is a directory.
    pub metadata_path: Option<PathBuf>,
    /// Messages per topic.
    pub counts: BTreeMap<String, u64>,
}

/// Writes a rosbag2 MCAP bag (see the module docs of [`crate::bag`]).
///
/// `path` ending in `.mcap` writes that single file (playable with
/// `ros2 bag play -s mcap FILE`); any other path is a bag directory holding
/// `<dir name>_0.mcap` and `metadata.yaml`.
pub struct BagWriter {
    writer: mcap::Writer<BufWriter<File>>,
    mcap_path: PathBuf,
    dir: Option<PathBuf>,
    schemas: HashMap<String, u16>,
    topics: BTreeMap<String, Topic>,
    start: u64,
    end: u64,
    scratch: Vec<u8>,
}

impl BagWriter {
    /// Create the bag at `path` (zstd-compressed chunks).
    ///
    /// # Errors
    /// [`BagError::Io`] when the directory or file cannot be created.
    pub fn create(path: &Path) -> Result<Self, BagError> {
        let (mcap_path, dir) = if path.extension().is_some_and(|e| e == "mcap") {
            if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent).map_err(|source| BagError::Io {
                    path: parent.to_path_buf(),
                    source,
                })?;
            }
            (path.to_path_buf(), None)
        } else {
            std::fs::create_dir_all(path).map_err(|source| BagError::Io {
                path: path.to_path_buf(),
                source,
            })?;
            let stem = path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or("bag")
                .to_string();
            (
                path.join(format!("{stem}_0.mcap")),
                Some(path.to_path_buf()),
            )
        };
        let file = File::create(&mcap_path).map_err(|source| BagError::Io {
            path: mcap_path.clone(),
            source,
        })?;
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("sepmem-", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .create(BufWriter::new(file))
            .map_err(|e| mcap_error(&mcap_path, e))?;
        Ok(Self {
            writer,
            mcap_path,
            dir,
            schemas: HashMap::new(),
            topics: BTreeMap::new(),
            start: u64::MAX,
            end: 0,
            scratch: Vec::new(),
        })
    }

    /// Declare `topic` with message type `type_name` (must be registered in
    /// [`crate::wire::msgdef`]) and QoS. Adding the same topic and type again
    /// is a no-op.
    ///
    /// # Errors
    /// [`BagError::TopicTypeConflict`], [`BagError::Wire`] for an unknown type,
    /// [`BagError::Mcap`] on write failure.
    pub fn add_topic(&mut self, topic: &str, type_name: &str, qos: Qos) -> Result<(), BagError> {
        if let Some(t) = self.topics.get(topic) {
            if t.type_name == type_name {
                return Ok(());
            }
            return Err(BagError::TopicTypeConflict {
                topic: topic.to_string(),
                existing: t.type_name.clone(),
                requested: type_name.to_string(),
            });
        }
        let type_hash = msgs::type_hash(type_name)
            .ok_or_else(|| wire::WireError::UnknownType(type_name.to_string()))?
            .to_string();
        let schema = match self.schemas.get(type_name) {
            Some(&id) => id,
            None => {
                let text = msgdef::full_definition(type_name)?;
                let id = self
                    .writer
                    .add_schema(type_name, "ros2msg", text.as_bytes())
                    .map_err(|e| mcap_error(&self.mcap_path, e))?;
                self.schemas.insert(type_name.to_string(), id);
                id
            }
        };
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), qos.yaml_string());
        meta.insert("topic_type_hash".to_string(), type_hash.clone());
        let channel = self
            .writer
            .add_channel(schema, topic, "cdr", &meta)
            .map_err(|e| mcap_error(&self.mcap_path, e))?;
        self.topics.insert(
            topic.to_string(),
            Topic {
                channel,
                type_name: type_name.to_string(),
                qos,
                type_hash,
                count: 0,
            },
        );
        Ok(())
    }

    /// Write CDR bytes (with encapsulation header) to an added topic.
    ///
    /// # Errors
    /// [`BagError::UnknownTopic`] or [`BagError::Mcap`].
    pub fn write_raw(
        &mut self,
        topic: &str,
        log_time: u64,
        publish_time: u64,
        cdr: &[u8],
    ) -> Result<(), BagError> {
        let t = self
            .topics
            .get_mut(topic)
            .ok_or_else(|| BagError::UnknownTopic(topic.to_string()))?;
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: t.channel,
                    sequence: 0,
                    log_time,
                    publish_time,
                },
                cdr,
            )
            .map_err(|e| mcap_error(&self.mcap_path, e))?;
        t.count += 1;
        self.start = self.start.min(log_time);
        self.end = self.end.max(log_time);
        Ok(())
    }

    /// Encode `msg` and write it to `topic` (added with the default QoS on
    /// first use), with `publish_time = log_time`.
    ///
    /// # Errors
    /// As [`BagWriter::add_topic`], [`BagWriter::write_raw`], or an encoding error.
    pub fn write<M: RosMessage>(
        &mut self,
        topic: &str,
        log_time: u64,
        msg: &M,
    ) -> Result<(), BagError> {
        self.add_topic(topic, M::TYPE_NAME, Qos::default())?;
        let mut buf = std::mem::take(&mut self.scratch);
        let r = wire::encode_into(msg, &mut buf)
            .map_err(BagError::from)
            .and_then(|()| self.write_raw(topic, log_time, log_time, &buf));
        self.scratch = buf;
        r
    }

    /// Finish the MCAP file (summary, `rosbag2` metadata record) and write
    /// `metadata.yaml` for a bag directory.
    ///
    /// # Errors
    /// [`BagError::Mcap`] or [`BagError::Io`].
    pub fn finish(mut self) -> Result<BagSummary, BagError> {
        let file_name = self
            .mcap_path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("bag_0.mcap")
            .to_string();
        let (start, duration) = if self.start == u64::MAX {
            (0, 0)
        } else {
            (self.start, self.end - self.start)
        };
        let entries: Vec<TopicEntry<'_>> = self
            .topics
            .iter()
            .map(|(name, t)| TopicEntry {
                name,
                type_name: &t.type_name,
                qos: t.qos,
                type_hash: &t.type_hash,
                count: t.count,
            })
            .collect();
        let mut meta = BTreeMap::new();
        meta.insert(
            "serialized_metadata".to_string(),
            render_bag_metadata(&file_name, start, duration, &entries),
        );
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: "rosbag2".to_string(),
                metadata: meta,
            })
            .map_err(|e| mcap_error(&self.mcap_path, e))?;
        self.writer
            .finish()
            .map_err(|e| mcap_error(&self.mcap_path, e))?;
        let metadata_path = match &self.dir {
            Some(dir) => {
                let p = dir.join("metadata.yaml");
                let yaml = render_metadata(&file_name, start, duration, &entries);
                std::fs::write(&p, yaml).map_err(|source| BagError::Io {
                    path: p.clone(),
                    source,
                })?;
                Some(p)
            }
            None => None,
        };
        Ok(BagSummary {
            mcap_path: self.mcap_path.clone(),
            metadata_path,
            counts: self
                .topics
                .iter()
                .map(|(n, t)| (n.clone(), t.count))
                .collect(),
        })
    }
}

fn mcap_error(path: &Path, e: mcap::McapError) -> BagError {
    BagError::Mcap {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}
