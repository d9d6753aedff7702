//! The live node: point-cloud topics in, meshes and diagnostics out.
//!
//! `sepmem node` subscribes to topic patterns over zenoh (rmw_zenoh,
//! zenoh-bridge-ros2dds or plain keys, see [`crate::transport`]); every
//! matching topic becomes an object stream with its own keep-latest slot
//! ([`slot`]) and processor ([`backend`]). Compute runs on a rayon pool,
//! results come back to tokio through oneshot channels, so tokio workers
//! never block. Streams run in parallel; each frame has a deadline; silent
//! streams are evicted and reported STALE; `/diagnostics` is published about
//! once a second ([`stats`]); streams are split between instances by
//! [`shard`]. See [`runtime`] for the task structure and shutdown.

pub mod backend;
pub mod budget;
pub mod clock;
#[cfg(feature = "zenoh")]
pub mod loopback;
pub mod pipeline_backend;
#[cfg(feature = "zenoh")]
pub mod player;
pub mod reasons;
#[cfg(feature = "ros2")]
pub mod ros2;
#[cfg(feature = "zenoh")]
pub mod runtime;
pub mod shard;
pub mod slot;
pub mod stats;

pub use backend::{
    Backend, Frame, FrameResult, ObjectReport, Output, OutputKind, OutputSink, StatusEntry,
    TopicProcessor,
};
pub use pipeline_backend::PipelineBackend;
pub use shard::Shard;
pub use stats::Level;

use crate::transport::TransportConfig;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors of the node.
#[derive(Debug, Error)]
pub enum NodeError {
    /// Transport failure (zenoh session, keys, tokens).
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportError),
    /// Invalid shard settings.
    #[error(transparent)]
    Shard(#[from] shard::ShardError),
    /// Invalid node settings.
    #[error("invalid node configuration: {0}")]
    Config(String),
    /// ROS 2 (r2r / rcl) failure.
    #[error("ROS 2: {0}")]
    Ros(String),
    /// The compute pool could not be created.
    #[error("cannot create the compute thread pool: {0}")]
    Pool(String),
}

/// Output topic names (`node.outputs`); `{topic}` is replaced by the input topic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputTopics {
    /// MarkerArray topic template.
    pub markers: String,
    /// sepmem mesh message topic template.
    pub mesh: String,
    /// sepmem per-frame diagnostics topic template.
    pub frame_diagnostics: String,
    /// Fused-model topic template (published with `pipeline.model` only).
    pub model: String,
    /// DiagnosticArray topic (about 1 Hz, all streams).
    pub diagnostics: String,
    /// MoveIt collision objects (`None`: not published).
    pub collision_objects: Option<crate::pipeline::collision::CollisionConfig>,
    /// Outputs published TRANSIENT_LOCAL for late joiners (`None`: all VOLATILE).
    pub transient_local: Option<TransientLocal>,
}

/// TRANSIENT_LOCAL outputs (`node.outputs.transient_local`): each publisher
/// keeps its last `depth` samples in a zenoh-ext advanced-publisher cache,
/// as rmw_zenoh does, and advertises the durability in its token's QoS.
/// A kind whose message holds the whole frame ([`OutputKind::whole_frame`]:
/// the MarkerArray) keeps only its last one: with `depth` arrays the
/// marker caches held ~120 MiB of encoded markers in the 10-minute soak
/// (heaptrack), and their churn made the node's heap grow ~2.5 MiB/min.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransientLocal {
    /// Which outputs.
    pub outputs: Vec<OutputKind>,
    /// Samples kept per publisher (the advertised KEEP_LAST depth).
    pub depth: u32,
}

impl OutputTopics {
    /// Whether `topic` is an output of a node with these templates
    /// subscribed to `inputs`: some template's `{topic}` filled with a
    /// topic `inputs` match (e.g. `/seg/cam/points/model` under `/seg/**`,
    /// a `sensor_msgs/PointCloud2` like the inputs). Such a node (this one,
    /// or another shard) must never take it for an input: bench-node's
    /// looped replay with the model on fed every stream's `/model` back in
    /// as a second stream.
    pub fn is_output(&self, topic: &str, inputs: &[String]) -> bool {
        OutputKind::ALL
            .iter()
            .filter_map(|&k| self.template(k))
            .any(|t| match t.split_once("{topic}") {
                Some((pre, post)) => topic
                    .strip_prefix(pre)
                    .and_then(|r| r.strip_suffix(post))
                    .is_some_and(|input| inputs.iter().any(|p| topic_matches(p, input))),
                None => t == topic,
            })
    }

    /// The template for one output kind (`None`: that output is off).
    pub fn template(&self, kind: OutputKind) -> Option<&str> {
        match kind {
            OutputKind::Markers => Some(&self.markers),
            OutputKind::Mesh => Some(&self.mesh),
            OutputKind::FrameDiagnostics => Some(&self.frame_diagnostics),
            OutputKind::Model => Some(&self.model),
            OutputKind::CollisionObjects => {
                self.collision_objects.as_ref().map(|c| c.topic.as_str())
            }
        }
    }
}

/// The `node` section of the configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeConfig {
    /// Input topic patterns (`*` = one name component, `**` = any number).
    pub topics: Vec<String>,
    /// Output topic names.
    pub outputs: OutputTopics,
    /// Output QoS: `false` = RELIABLE + KEEP_LAST(10), which rmw_zenoh maps
    /// to zenoh's "drop" congestion control (an output the link cannot take
    /// within about a millisecond is dropped; the node never waits); `true`
    /// = RELIABLE + KEEP_ALL, mapped to "block" (nothing is dropped, but a
    /// congested link slows that stream).
    pub outputs_keep_all: bool,
    /// Period of the `/diagnostics` array, in milliseconds.
    pub diagnostics_period_ms: u64,
    /// A stream silent this long is evicted (state freed, reported STALE).
    pub evict_after_ms: u64,
    /// Maximum number of concurrent streams (samples of further topics are counted and ignored).
    pub max_streams: usize,
    /// Compute threads (0 = one per core).
    pub compute_threads: usize,
    /// How much of the compute pool one stream may use (`None`: no limit).
    pub compute_share: Option<budget::ComputeShareConfig>,
    /// A frame in compute for longer than the cold-start budget plus this
    /// (ms) is reported stalled (ERROR).
    pub stall_after_ms: u64,
    /// Bound on graceful shutdown (in-flight frames are abandoned after it).
    pub shutdown_timeout_ms: u64,
    /// This instance's shard of the streams.
    pub shard: Shard,
    /// Transport (key mode, domain, zenoh session).
    pub transport: TransportConfig,
}

impl NodeConfig {
    /// The QoS of the node's publishers (`outputs_keep_all`).
    pub fn output_qos(&self) -> crate::transport::liveliness::Qos {
        use crate::transport::liveliness::Qos;
        if self.outputs_keep_all {
            Qos {
                keep_last: None,
                ..Qos::DEFAULT_10
            }
        } else {
            Qos::DEFAULT_10
        }
    }

    /// The QoS of one output kind: [`NodeConfig::output_qos`], made
    /// TRANSIENT_LOCAL when `outputs.transient_local` lists it, with
    /// KEEP_LAST of its cache depth ([`NodeConfig::output_cache_of`]), or
    /// KEEP_ALL with `outputs_keep_all`: a transient-local output then
    /// blocks like the others rather than dropping (its cache stays at the
    /// configured depth). Before, KEEP_LAST won there, and under two busy
    /// cores the lock-step test lost a mesh or a MarkerArray in 3 of 8 runs.
    pub fn output_qos_of(&self, kind: OutputKind) -> crate::transport::liveliness::Qos {
        use crate::transport::liveliness::{Durability, Qos};
        match self.output_cache_of(kind) {
            Some(depth) => Qos {
                durability: Durability::TransientLocal,
                keep_last: (!self.outputs_keep_all).then_some(depth),
                ..self.output_qos()
            },
            None => self.output_qos(),
        }
    }

    /// How many samples a transient-local output's publisher keeps for late
    /// joiners: `outputs.transient_local.depth`, or 1 for a kind whose
    /// message holds the whole frame; `None` for a volatile output.
    pub fn output_cache_of(&self, kind: OutputKind) -> Option<u32> {
        match &self.outputs.transient_local {
            Some(tl) if tl.outputs.contains(&kind) => {
                Some(if kind.whole_frame() { 1 } else { tl.depth })
            }
            _ => None,
        }
    }

    /// Configured input topics without wildcards (their subscriptions are
    /// declared at start, before any sample).
    pub fn exact_topics(&self) -> Vec<String> {
        self.topics
            .iter()
            .filter(|t| !t.contains('*'))
            .map(|t| format!("/{}", t.trim_matches('/')))
            .collect()
    }

    /// The rayon pool the frames are computed on (`compute_threads`, 0 = one
    /// per core), so that compute never runs on the transport's threads.
    ///
    /// # Errors
    /// [`NodeError::Pool`] when the pool cannot be built.
    pub fn compute_pool(&self) -> Result<std::sync::Arc<rayon::ThreadPool>, NodeError> {
        let threads = if self.compute_threads == 0 {
            std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
        } else {
            self.compute_threads
        };
        Ok(std::sync::Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(|i| format!("sepmem-compute-{i}"))
                .build()
                .map_err(|e| NodeError::Pool(e.to_string()))?,
        ))
    }

    /// Check the values that serde cannot.
    ///
    /// # Errors
    /// [`NodeError`] naming the key at fault.
    pub fn validate(&self) -> Result<(), NodeError> {
        self.shard.validate()?;
        if self.topics.is_empty() {
            return Err(NodeError::Config("node.topics is empty".into()));
        }
        if self.diagnostics_period_ms == 0 {
            return Err(NodeError::Config(
                "node.diagnostics_period_ms must be > 0".into(),
            ));
        }
        if self.max_streams == 0 {
            return Err(NodeError::Config("node.max_streams must be > 0".into()));
        }
        if let Some(share) = &self.compute_share {
            share.validate().map_err(NodeError::Config)?;
        }
        if let Some(tl) = &self.outputs.transient_local {
            if tl.depth == 0 {
                return Err(NodeError::Config(
                    "node.outputs.transient_local.depth must be > 0".into(),
                ));
            }
        }
        if let Some(c) = &self.outputs.collision_objects {
            if c.max_triangles < 4 {
                return Err(NodeError::Config(
                    "node.outputs.collision_objects.max_triangles must be >= 4".into(),
                ));
            }
            if c.move_tolerance_m.is_nan() || c.move_tolerance_m < 0.0 {
                return Err(NodeError::Config(
                    "node.outputs.collision_objects.move_tolerance_m must be >= 0".into(),
                ));
            }
        }
        Ok(())
    }
}

/// Whether a ROS topic matches a `node.topics` pattern: `*` matches one name
/// component, `**` any number (zero included), as in zenoh key expressions.
pub fn topic_matches(pattern: &str, topic: &str) -> bool {
    fn rec(p: &[&str], t: &[&str]) -> bool {
        match (p.first(), t.first()) {
            (None, None) => true,
            (Some(&"**"), _) => rec(&p[1..], t) || (!t.is_empty() && rec(p, &t[1..])),
            (Some(&"*"), Some(_)) => rec(&p[1..], &t[1..]),
            (Some(a), Some(b)) if a == b => rec(&p[1..], &t[1..]),
            _ => false,
        }
    }
    let split = |s: &str| -> Vec<String> {
        s.split('/')
            .filter(|c| !c.is_empty())
            .map(str::to_string)
            .collect()
    };
    let (p, t) = (split(pattern), split(topic));
    let p: Vec<&str> = p.iter().map(String::as_str).collect();
    let t: Vec<&str> = t.iter().map(String::as_str).collect();
    rec(&p, &t)
}

#[cfg(test)]
mod tests {
    use super::topic_matches;

    #[test]
    fn topic_patterns_match_like_key_expressions() {
        assert!(topic_matches("/seg/**", "/seg/a/points"));
        assert!(topic_matches("/seg/**", "/seg"));
        assert!(topic_matches("/seg/*/points", "/seg/a/points"));
        assert!(!topic_matches("/seg/*/points", "/seg/a/b/points"));
        assert!(topic_matches("/**/points", "/a/b/points"));
        assert!(!topic_matches("/seg/**", "/other/points"));
        assert!(topic_matches("/exact", "/exact/"));
        assert!(!topic_matches("/exact", "/exactly"));
    }

    #[test]
    fn the_node_never_takes_its_own_outputs_for_inputs() {
        let outputs = crate::config::Config::defaults().unwrap().node.outputs;
        let inputs = vec!["/seg/**".to_string()];
        // The default templates under the default input pattern.
        assert!(outputs.is_output("/seg/cam/points/model", &inputs));
        assert!(outputs.is_output("/seg/cam/points/mesh", &inputs));
        assert!(!outputs.is_output("/seg/cam/points", &inputs));
        // The would-be input must itself be one: `/other/x` is not.
        assert!(!outputs.is_output("/other/x/model", &inputs));
        let exact = vec!["/cam/points".to_string()];
        assert!(outputs.is_output("/cam/points/model", &exact));
        assert!(!outputs.is_output("/cam/other/model", &exact));
    }

    #[test]
    fn keep_all_outputs_block_even_when_latched_and_keep_a_bounded_cache() {
        use super::OutputKind;
        use crate::transport::liveliness::Durability;
        let mut cfg = crate::config::Config::defaults().unwrap().node;
        let latched = cfg.outputs.transient_local.clone().unwrap();
        assert!(latched.outputs.contains(&OutputKind::Mesh));
        assert!(latched.outputs.contains(&OutputKind::Markers));
        for keep_all in [false, true] {
            cfg.outputs_keep_all = keep_all;
            let mesh = cfg.output_qos_of(OutputKind::Mesh);
            let markers = cfg.output_qos_of(OutputKind::Markers);
            assert_eq!(mesh.durability, Durability::TransientLocal);
            assert_eq!(markers.durability, Durability::TransientLocal);
            // KEEP_ALL (no depth) is what maps to zenoh's "block".
            let mesh_depth = (!keep_all).then_some(latched.depth);
            assert_eq!(mesh.keep_last, mesh_depth, "keep_all {keep_all}");
            assert_eq!(markers.keep_last, (!keep_all).then_some(1));
            assert_eq!(cfg.output_qos().keep_last.is_none(), keep_all);
            // The cache depth does not follow KEEP_ALL.
            assert_eq!(cfg.output_cache_of(OutputKind::Mesh), Some(latched.depth));
            assert_eq!(cfg.output_cache_of(OutputKind::Markers), Some(1));
        }
        cfg.outputs.transient_local = None;
        assert_eq!(cfg.output_cache_of(OutputKind::Mesh), None);
        assert_eq!(cfg.output_qos_of(OutputKind::Mesh), cfg.output_qos());
    }
}
