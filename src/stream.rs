//! The identity of an object stream, shared by the frame pipeline (one
//! tracker per stream) and the simulator (which names the stream each
//! object's ground truth belongs to), so that neither depends on the other.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Identity of an object stream: a topic, and a segment label when the
/// topic's clouds carry several labelled objects.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct StreamKey {
    /// Topic name (ROS style, e.g. `/seg/points`).
    pub topic: String,
    /// Segment label, if the stream is one label of a labelled cloud.
    pub label: Option<i64>,
}

impl StreamKey {
    /// A stream for a whole topic.
    pub fn topic(topic: impl Into<String>) -> Self {
        Self {
            topic: topic.into(),
            label: None,
        }
    }
}

impl fmt::Display for StreamKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.label {
            Some(l) => write!(f, "{}#{l}", self.topic),
            None => f.write_str(&self.topic),
        }
    }
}
