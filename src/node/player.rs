//! Replaying a rosbag2 bag over zenoh as a ROS 2 publisher would
//! (`sepmem play`, the player half of `sepmem demo`).
//!
//! Every topic of the bag gets a publisher on the participant (rmw_zenoh key
//! with the type's RIHS01 hash, `MP` liveliness token, 33-byte attachment in
//! `ros2` mode); messages are put in log-time order at their recorded
//! spacing divided by `rate` (`rate <= 0` puts them back to back).

use crate::bag::{Bag, BagError, BagMessage};
use crate::transport::keys::HASH_NOT_SUPPORTED;
use crate::transport::liveliness::{Durability, Qos, Reliability};
use crate::transport::{Participant, RosPublisher, RosType, TransportError};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};
use thiserror::Error;

/// The players' QoS: reliable, keep all. Over zenoh this maps to blocking
/// congestion control, so that a burst of large clouds (several topics
/// recorded at the same instant) is not dropped by the sender; the node's
/// keep-latest slots still bound what is processed.
pub const PLAYER_QOS: Qos = Qos {
    reliability: Reliability::Reliable,
    durability: Durability::Volatile,
    keep_last: None,
};

/// Errors of the player.
#[derive(Debug, Error)]
pub enum PlayError {
    /// The bag cannot be read.
    #[error(transparent)]
    Bag(#[from] BagError),
    /// Publishing failed.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The bag has none of the requested topics.
    #[error("bag {0} has no messages on the requested topics")]
    Empty(String),
}

/// Replay options.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayOptions {
    /// Speed factor (2 = twice as fast); `<= 0` publishes as fast as possible.
    pub rate: f64,
    /// Start again at the end (until stopped).
    pub looped: bool,
    /// Only these topics (all when empty).
    pub topics: Vec<String>,
    /// Publish bag topic `t` as `remap_prefix + t` (empty: unchanged).
    pub remap_prefix: String,
    /// Record the time of every put in [`PlaySummary::put_times`].
    pub record_times: bool,
}

impl Default for PlayOptions {
    fn default() -> Self {
        Self {
            rate: 1.0,
            looped: false,
            topics: Vec::new(),
            remap_prefix: String::new(),
            record_times: false,
        }
    }
}

/// What was played.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlaySummary {
    /// Messages put, per published topic.
    pub per_topic: BTreeMap<String, u64>,
    /// Passes over the bag.
    pub passes: u64,
    /// (index in [`LoadedBag::messages`], put time in ns since the epoch)
    /// of every put, when [`PlayOptions::record_times`] is set.
    pub put_times: Vec<(usize, i64)>,
}

/// A bag loaded in memory, ready to be played.
#[derive(Debug, Clone)]
pub struct LoadedBag {
    /// Messages in log-time order.
    pub messages: Vec<BagMessage>,
    /// Type (with hash) of each topic.
    pub types: BTreeMap<String, RosType>,
}

/// Read the messages of `topics` (all when empty) from a bag.
///
/// # Errors
/// [`PlayError`] when the bag cannot be read or has no such messages.
pub fn load(path: &Path, topics: &[String]) -> Result<LoadedBag, PlayError> {
    let bag = Bag::open(path)?;
    let sel: Vec<&str> = topics.iter().map(String::as_str).collect();
    let messages = bag.read(&sel)?;
    if messages.is_empty() {
        return Err(PlayError::Empty(path.display().to_string()));
    }
    let mut types = BTreeMap::new();
    for t in &bag.topics {
        let hash = if t.type_hash.is_empty() {
            crate::wire::msgs::type_hash(&t.type_name)
                .unwrap_or(HASH_NOT_SUPPORTED)
                .to_string()
        } else {
            t.type_hash.clone()
        };
        types.insert(t.name.clone(), RosType::new(t.type_name.clone(), hash));
    }
    Ok(LoadedBag { messages, types })
}

/// Play `bag` on `participant` until done (or, when looping, until `stop`
/// returns true; it is checked between messages).
///
/// # Errors
/// [`PlayError::Transport`] when a publisher cannot be declared or a put fails.
pub async fn play<F: Fn() -> bool>(
    participant: &Participant,
    bag: &LoadedBag,
    opts: &PlayOptions,
    stop: F,
) -> Result<PlaySummary, PlayError> {
    let mut pubs: BTreeMap<String, RosPublisher> = BTreeMap::new();
    let name = |t: &str| format!("{}{t}", opts.remap_prefix.trim_end_matches('/'));
    for m in &bag.messages {
        if !pubs.contains_key(&m.topic) {
            let ty = bag
                .types
                .get(&m.topic)
                .cloned()
                .unwrap_or_else(|| RosType::new(m.type_name.clone(), HASH_NOT_SUPPORTED));
            let p = participant
                .publisher(&name(&m.topic), &ty, PLAYER_QOS)
                .await?;
            pubs.insert(m.topic.clone(), p);
        }
    }
    let mut summary = PlaySummary::default();
    let first = bag.messages.first().map_or(0, |m| m.log_time);
    'passes: loop {
        let start = Instant::now();
        for (i, m) in bag.messages.iter().enumerate() {
            if stop() {
                break 'passes;
            }
            if opts.rate > 0.0 {
                let offset = (m.log_time.saturating_sub(first)) as f64 * 1e-9 / opts.rate;
                let at = start + Duration::from_secs_f64(offset);
                tokio::time::sleep_until(at.into()).await;
            }
            if let Some(p) = pubs.get(&m.topic) {
                if opts.record_times {
                    summary
                        .put_times
                        .push((i, crate::transport::attachment::now_ns()));
                }
                p.put(m.data.clone()).await?;
                *summary.per_topic.entry(name(&m.topic)).or_default() += 1;
            }
        }
        summary.passes += 1;
        if !opts.looped || stop() {
            break;
        }
    }
    for (_, p) in pubs {
        p.undeclare().await?;
    }
    Ok(summary)
}
