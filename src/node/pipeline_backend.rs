//! The node's production backend: sepmem's frame pipeline (one warm-started
//! [`crate::pipeline::Tracker`] per object stream, paper §III-D..F run per
//! frame) and the wire codecs.
//!
//! Per frame it decodes the `sensor_msgs/PointCloud2`, splits it into object
//! streams (per segment label when present), evolves the objects' membranes
//! in parallel under the frame's remaining deadline, and encodes one `sepmem_msgs/SurfaceMesh` and
//! one `sepmem_msgs/FrameDiagnostics` per object plus one
//! `visualization_msgs/MarkerArray` (DELETEALL, then a TRIANGLE_LIST per
//! object). `/diagnostics` is a `diagnostic_msgs/DiagnosticArray`.

use super::backend::{
    Backend, Frame, FrameResult, ObjectReport, Output, OutputKind, StatusEntry, TopicProcessor,
};
use super::stats::Level;
use crate::membrane::{ConfigError, MembraneConfig, StopReason};
use crate::pipeline::engine::Engine;
use crate::pipeline::{outputs, Deadlines, Membranes, PipelineConfig, StartPath};
use crate::transport::RosType;
use crate::wire::msgs::{
    DiagnosticArray, DiagnosticStatus, FrameDiagnostics, Header, KeyValue, MarkerArray,
    PointCloud2, SurfaceMesh, Time,
};
use crate::wire::pointcloud2::WireConfig;
use crate::wire::{self, RosMessage};
use std::time::{Duration, Instant};

fn ty<M: RosMessage>() -> RosType {
    RosType::new(M::TYPE_NAME, M::TYPE_HASH)
}

/// The production backend.
#[derive(Debug, Clone)]
pub struct PipelineBackend {
    membranes: Membranes,
    pipeline: PipelineConfig,
    limits: WireConfig,
}

impl PipelineBackend {
    /// A backend from the configuration sections it needs.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first bad membrane key.
    pub fn new(
        membrane: &MembraneConfig,
        pipeline: PipelineConfig,
        limits: WireConfig,
    ) -> Result<Self, ConfigError> {
        Ok(Self {
            membranes: Membranes::new(membrane, &pipeline)?,
            pipeline,
            limits,
        })
    }

    /// A backend from the whole configuration.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first bad membrane key.
    pub fn from_config(cfg: &crate::config::Config) -> Result<Self, ConfigError> {
        Self::new(&cfg.membrane, cfg.pipeline.clone(), cfg.wire.clone())
    }
}

struct EngineProcessor {
    engine: Engine,
    ns: String,
    last_header: Header,
}

/// The deadlines of a frame whose node deadline is `deadline` (from its
/// receipt): what is left of it, but never less than a quarter of the
/// configured budget (so that a late frame still gets a few iterations; it
/// is then counted as late); a cold start's longer budget shrinks by the
/// same time already spent.
fn node_deadlines(p: &PipelineConfig, deadline: Instant) -> Deadlines {
    let now = Instant::now();
    if p.deadline_ms <= 0.0 {
        return Deadlines::default();
    }
    let remaining = deadline.saturating_duration_since(now);
    let left = (remaining.as_secs_f64() * 1e3).max(0.25 * p.deadline_ms);
    Deadlines::after(now, left, p.cold_budget_ms() - (p.deadline_ms - left))
}

/// The node's per-object report of a frame result.
fn object_report(r: &crate::pipeline::FrameResult) -> ObjectReport {
    let rep = &r.reconstruction.report;
    let warm = r.path == StartPath::Warm;
    let level = if rep.stop == StopReason::Deadline {
        Level::Warn
    } else {
        Level::Ok
    };
    ObjectReport {
        stream: r.stream.to_string(),
        eta_g: rep.eta_final,
        iterations: u32::try_from(r.iterations).unwrap_or(u32::MAX),
        warm,
        level,
        message: format!(
            "{} start ({}), stop: {}",
            if warm { "warm" } else { "cold" },
            r.reason,
            rep.stop
        ),
    }
}

fn encode<M: RosMessage>(
    kind: OutputKind,
    msg: &M,
    out: &mut Vec<Output>,
    errors: &mut Vec<String>,
) {
    match wire::encode(msg) {
        Ok(payload) => out.push(Output { kind, payload }),
        Err(e) => errors.push(format!("encoding {}: {e}", M::TYPE_NAME)),
    }
}

impl TopicProcessor for EngineProcessor {
    fn process(&mut self, frame: &Frame) -> FrameResult {
        // The node's deadline runs from receipt; the objects of a labelled
        // cloud are evolved in parallel, each with what is left of it.
        let deadlines = node_deadlines(&self.engine.pipeline, frame.deadline);
        let out = match self
            .engine
            .handle(&frame.topic, &frame.payload, Some(deadlines))
        {
            Ok(o) => o,
            Err(e) => {
                return FrameResult {
                    error: Some(e.to_string()),
                    ..FrameResult::default()
                }
            }
        };
        self.last_header = out.sample.header.clone();
        let msgs = out.messages(&self.ns);
        let mut outs = Vec::with_capacity(2 * msgs.objects.len() + 1);
        let mut errors = Vec::new();
        for (mesh, diag) in &msgs.objects {
            encode(OutputKind::Mesh, mesh, &mut outs, &mut errors);
            encode(OutputKind::FrameDiagnostics, diag, &mut outs, &mut errors);
        }
        encode(OutputKind::Markers, &msgs.markers, &mut outs, &mut errors);
        let mut objects = Vec::with_capacity(out.processed.len());
        for p in &out.processed {
            match &p.outcome {
                Ok(r) => objects.push(object_report(r)),
                Err(e) => errors.push(e.to_string()),
            }
        }
        FrameResult {
            outputs: outs,
            objects,
            error: if errors.is_empty() {
                None
            } else {
                Some(errors.join("; "))
            },
        }
    }

    fn on_evict(&mut self) -> Vec<Output> {
        let markers = outputs::marker_array(&[], &self.last_header, &self.ns);
        wire::encode(&markers)
            .map(|payload| {
                vec![Output {
                    kind: OutputKind::Markers,
                    payload,
                }]
            })
            .unwrap_or_default()
    }
}

impl Backend for PipelineBackend {
    fn input_type(&self) -> RosType {
        ty::<PointCloud2>()
    }

    fn output_type(&self, kind: OutputKind) -> RosType {
        match kind {
            OutputKind::Markers => ty::<MarkerArray>(),
            OutputKind::Mesh => ty::<SurfaceMesh>(),
            OutputKind::FrameDiagnostics => ty::<FrameDiagnostics>(),
        }
    }

    fn diagnostics_type(&self) -> RosType {
        ty::<DiagnosticArray>()
    }

    fn frame_deadline(&self) -> Option<Duration> {
        (self.pipeline.deadline_ms > 0.0)
            .then(|| Duration::from_secs_f64(self.pipeline.deadline_ms / 1e3))
    }

    fn processor(&self, _topic: &str) -> Box<dyn TopicProcessor> {
        Box::new(EngineProcessor {
            engine: Engine::with_membranes(
                self.membranes.clone(),
                self.pipeline.clone(),
                self.limits.clone(),
            ),
            ns: self.pipeline.marker_namespace.clone(),
            last_header: Header::default(),
        })
    }

    fn encode_diagnostics(&self, stamp_ns: i64, frame_id: &str, status: &[StatusEntry]) -> Vec<u8> {
        encode_diagnostic_array(stamp_ns, frame_id, status)
    }
}

/// Encode `/diagnostics` entries as a `diagnostic_msgs/DiagnosticArray`.
pub fn encode_diagnostic_array(stamp_ns: i64, frame_id: &str, status: &[StatusEntry]) -> Vec<u8> {
    let msg = DiagnosticArray {
        header: Header {
            stamp: Time::from_nanos(stamp_ns),
            frame_id: frame_id.to_string(),
        },
        status: status
            .iter()
            .map(|s| DiagnosticStatus {
                level: s.level.byte(),
                name: s.name.clone(),
                message: s.message.clone(),
                hardware_id: s.hardware_id.clone(),
                values: s
                    .values
                    .iter()
                    .map(|(k, v)| KeyValue {
                        key: k.clone(),
                        value: v.clone(),
                    })
                    .collect(),
            })
            .collect(),
    };
    // Strings and numbers only: encoding cannot fail for this type.
    wire::encode(&msg).unwrap_or_default()
}
