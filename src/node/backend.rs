//! What the node hosts: the interface between the live transport and the
//! frame pipeline.
//!
//! The node is codec- and algorithm-agnostic. A [`Backend`] names the input
//! and output ROS types, creates one [`TopicProcessor`] per input topic (the
//! per-stream trackers with their warm-start state live inside it), and
//! encodes the periodic `/diagnostics` array. A processor turns one received
//! sample into encoded output messages plus one [`ObjectReport`] per object
//! (one object per topic, or one per segment label when the cloud carries
//! labels). Processors run on the rayon compute pool, never on tokio workers.

use super::stats::Level;
use crate::transport::RosType;
use std::time::{Duration, Instant};

/// The per-frame outputs a processor can produce (config names in snake_case).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum OutputKind {
    /// `visualization_msgs/MarkerArray` (TRIANGLE_LIST per object, DELETEALL first).
    Markers,
    /// sepmem's stamped mesh message (one per object).
    Mesh,
    /// sepmem's per-frame diagnostics message.
    FrameDiagnostics,
    /// `moveit_msgs/CollisionObject` (ADD / MOVE / REMOVE per object).
    CollisionObjects,
    /// `sensor_msgs/PointCloud2`: the fused model of every object of the
    /// frame (`pipeline.model`), labelled.
    Model,
}

impl OutputKind {
    /// All kinds, in publication order.
    pub const ALL: [OutputKind; 5] = [
        OutputKind::Mesh,
        OutputKind::Markers,
        OutputKind::FrameDiagnostics,
        OutputKind::CollisionObjects,
        OutputKind::Model,
    ];

    /// Whether one message of this kind carries the whole frame (every
    /// object's marker after a DELETEALL; the frame's diagnostics; every
    /// object's fused model), so that its last message is all a late joiner
    /// needs. Mesh and collision-object messages are one per object.
    pub fn whole_frame(self) -> bool {
        matches!(
            self,
            OutputKind::Markers | OutputKind::FrameDiagnostics | OutputKind::Model
        )
    }

    /// The zenoh lane of this kind: collision objects go in the urgent lane
    /// (a planning scene that misses an ADD never holds the object, and the
    /// MOVEs that follow refer to nothing), everything else where rmw_zenoh
    /// puts it.
    #[cfg(feature = "zenoh")]
    pub fn lane(self) -> crate::transport::Lane {
        match self {
            OutputKind::CollisionObjects => crate::transport::Lane::Urgent,
            _ => crate::transport::Lane::Data,
        }
    }
}

/// One encoded output message.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    /// Which output topic it goes to.
    pub kind: OutputKind,
    /// CDR bytes with encapsulation header.
    pub payload: Vec<u8>,
}

/// One received frame handed to a processor.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Input topic.
    pub topic: String,
    /// Serialized input message (CDR with encapsulation header).
    pub payload: Vec<u8>,
    /// Local receive time, ns on the node's monotonic clock
    /// ([`super::clock::mono_ns`]): compared only with that clock.
    pub received_ns: i64,
    /// Publisher's source timestamp from the rmw_zenoh attachment, if any.
    pub source_ns: Option<i64>,
    /// Publisher sequence number from the attachment, if any.
    pub sequence: Option<i64>,
    /// Compute must stop iterating by this instant (per-frame deadline).
    pub deadline: Instant,
}

/// How one object fared in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectReport {
    /// Object stream id: the topic, or `topic#label` for labelled segments.
    pub stream: String,
    /// Global separability η_g of the final surface.
    pub eta_g: f64,
    /// Membrane iterations used.
    pub iterations: u32,
    /// Warm-started from the previous frame (else cold start).
    pub warm: bool,
    /// Level the pipeline assigns (WARN for a low η_g, a budget stop …).
    pub level: Level,
    /// Short human-readable summary (stop reason, why cold …).
    pub message: String,
    /// Verdict on the published surface (e.g. `fitted`, `held`), if the
    /// backend gives one.
    pub quality: Option<&'static str>,
    /// Bytes of the object's fused model (`pipeline.model`), if it has one.
    pub model_bytes: Option<usize>,
}

/// The result of processing one frame (its outputs went to the
/// [`OutputSink`] as they were made).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameResult {
    /// One report per object in the frame.
    pub objects: Vec<ObjectReport>,
    /// Why the frame failed (malformed input, degenerate cloud …); the
    /// stream continues with the next frame.
    pub error: Option<String>,
    /// What this frame refused or discarded, by reason (see
    /// [`super::reasons`]): e.g. `("objects_skipped", 384)` for a label bomb
    /// over the per-frame cap, `("malformed_cdr", 1)` for undecodable bytes.
    /// The node adds them up per stream and reports them in `/diagnostics`.
    pub counts: Vec<(&'static str, u64)>,
    /// Object streams (`topic#label`) whose state the processor freed in
    /// this frame (silent labels); the node forgets their statuses.
    pub evicted: Vec<String>,
}

/// Where a processor hands each encoded output as soon as it is made. The
/// node publishes it while the frame's later outputs are still being made,
/// so an object's mesh does not wait for the frame's MarkerArray or the
/// collision objects' simplification (about 2 ms per object on a shape
/// frame, `node.outputs.collision_objects`).
pub type OutputSink<'a> = dyn FnMut(Output) + 'a;

/// Per-input-topic processing state (the trackers of its objects).
pub trait TopicProcessor: Send + 'static {
    /// Process one frame, handing its outputs to `sink` in publication
    /// order; must not panic on bad input (report it in
    /// [`FrameResult::error`]).
    fn process(&mut self, frame: &Frame, sink: &mut OutputSink<'_>) -> FrameResult;

    /// Outputs to publish when the stream is evicted or the node stops
    /// (e.g. a DELETEALL marker array so viewers clear the objects).
    fn on_evict(&mut self) -> Vec<Output>;
}

/// One status line of the `/diagnostics` array.
#[derive(Debug, Clone, PartialEq)]
pub struct StatusEntry {
    /// `<node>: <stream>`.
    pub name: String,
    /// Level.
    pub level: Level,
    /// Message.
    pub message: String,
    /// Hardware id (the node's host/zid).
    pub hardware_id: String,
    /// Key/value pairs (numbers as strings).
    pub values: Vec<(String, String)>,
}

/// The frame pipeline as seen by the node.
pub trait Backend: Send + Sync + 'static {
    /// Type of the input topics (normally `sensor_msgs/msg/PointCloud2`).
    fn input_type(&self) -> RosType;
    /// Type published on an output topic.
    fn output_type(&self, kind: OutputKind) -> RosType;
    /// Whether processors ever produce `kind` (the node declares no
    /// publisher for an output that never comes, e.g. the model without
    /// `pipeline.model`).
    fn publishes(&self, kind: OutputKind) -> bool {
        let _ = kind;
        true
    }
    /// `diagnostic_msgs/msg/DiagnosticArray`.
    fn diagnostics_type(&self) -> RosType;
    /// Per-frame deadline, measured from receipt (`None`: no deadline).
    fn frame_deadline(&self) -> Option<Duration> {
        None
    }
    /// The longest compute budget of one frame (e.g. a cold start's; `None`:
    /// the frame deadline). The stall bound is counted from it.
    fn frame_budget(&self) -> Option<Duration> {
        self.frame_deadline()
    }
    /// The largest input message the backend accepts (bytes), which the
    /// node sets as zenoh's receive limit (`None`: zenoh's default).
    fn max_message_bytes(&self) -> Option<usize> {
        None
    }
    /// A fresh processor for a newly seen input topic.
    fn processor(&self, topic: &str) -> Box<dyn TopicProcessor>;
    /// Encode a `DiagnosticArray` stamped `stamp_ns`.
    fn encode_diagnostics(&self, stamp_ns: i64, frame_id: &str, status: &[StatusEntry]) -> Vec<u8>;
}
