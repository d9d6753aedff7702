//! rosbag2 bags: reading MCAP and sqlite3 (`.db3`) storage, writing MCAP.
//!
//! A bag is either a single `.mcap` / `.db3` file or a bag directory holding
//! `metadata.yaml` plus its storage files (as `ros2 bag record` writes it).
//!
//! * [`Bag::open`] lists the topics (name, type, count, QoS, type hash);
//!   [`Bag::read`] returns the messages `(topic, type, log_time,
//!   publish_time, CDR bytes)` sorted by log time (stable, so per-topic file
//!   order is kept for equal stamps), optionally for a subset of topics.
//!   MCAP channels must use message encoding `cdr`; other channels are
//!   skipped and reported in [`Bag::skipped_topics`].
//! * [`BagWriter`] writes the MCAP layout of `rosbag2_storage_mcap`:
//!   profile `ros2`, one `ros2msg` schema per type carrying the full
//!   concatenated definition ([`crate::wire::msgdef::full_definition`]),
//!   channels with encoding `cdr` and metadata `offered_qos_profiles` (YAML)
//!   and `topic_type_hash` (RIHS01), CDR data with the encapsulation header,
//!   a `rosbag2` metadata record, and, for a bag directory, a version-9
//!   `metadata.yaml`, so the output opens in Foxglove, `ros2 bag info/play`,
//!   and the Python `rosbags` / `mcap` readers (checked by
//!   `tests/python/check_bag.py`).

mod bounded;
mod metadata;
mod read;
mod write;

pub use metadata::Qos;
pub use read::{parse_mcap, Bag, BagMessage, Storage, TopicInfo};
pub use write::{BagSummary, BagWriter};

use std::path::PathBuf;
use thiserror::Error;

/// Errors reading or writing a bag.
#[derive(Debug, Error)]
pub enum BagError {
    /// A file could not be read or written.
    #[error("bag {path}: {source}")]
    Io {
        /// File involved.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The MCAP layer failed (bad magic, CRC, truncated records, …).
    #[error("bag {path}: MCAP error: {message}")]
    Mcap {
        /// File involved.
        path: PathBuf,
        /// mcap crate message.
        message: String,
    },
    /// The sqlite3 storage failed or has an unexpected schema.
    #[error("bag {path}: sqlite3 error: {message}")]
    Sqlite {
        /// File involved.
        path: PathBuf,
        /// rusqlite message.
        message: String,
    },
    /// No storage file was found for the path.
    #[error("{path} is not a rosbag2 bag (no .mcap or .db3 file, no usable metadata.yaml)")]
    NotABag {
        /// Path given.
        path: PathBuf,
    },
    /// A message was written to a topic that was not added.
    #[error("topic `{0}` was not added to the bag writer")]
    UnknownTopic(String),
    /// A topic was added twice with different types.
    #[error("topic `{topic}` already has type {existing}, cannot add it as {requested}")]
    TopicTypeConflict {
        /// Topic.
        topic: String,
        /// Type it has.
        existing: String,
        /// Type requested.
        requested: String,
    },
    /// A message type has no registered definition.
    #[error(transparent)]
    Wire(#[from] crate::wire::WireError),
}
