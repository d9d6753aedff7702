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
use crate::membrane::MembraneConfig;
use crate::membrane::StopReason;
use crate::pipeline::collision::{CollisionConfig, CollisionObjects};
use crate::pipeline::engine::{decode_sample, Processed, StreamCloud};
use crate::pipeline::{outputs, PipelineConfig, StartPath, StreamKey, Tracker};
use crate::transport::RosType;
use crate::wire::msgs::{
    CollisionObject, DiagnosticArray, DiagnosticStatus, FrameDiagnostics, Header, KeyValue,
    MarkerArray, PointCloud2, SurfaceMesh, Time,
};
use crate::wire::pointcloud2::WireConfig;
use crate::wire::{self, RosMessage};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

fn ty<M: RosMessage>() -> RosType {
    RosType::new(M::TYPE_NAME, M::TYPE_HASH)
}

/// The production backend.
#[derive(Debug, Clone)]
pub struct PipelineBackend {
    membrane: MembraneConfig,
    pipeline: PipelineConfig,
    limits: WireConfig,
    collision: Option<CollisionConfig>,
}

impl PipelineBackend {
    /// A backend from the configuration sections it needs.
    pub fn new(membrane: MembraneConfig, pipeline: PipelineConfig, limits: WireConfig) -> Self {
        Self {
            membrane,
            pipeline,
            limits,
            collision: None,
        }
    }

    /// Also publish MoveIt collision objects (`node.outputs.collision_objects`).
    pub fn with_collision_objects(mut self, collision: Option<CollisionConfig>) -> Self {
        self.collision = collision;
        self
    }

    /// A backend from the whole configuration.
    pub fn from_config(cfg: &crate::config::Config) -> Self {
        Self::new(cfg.membrane.clone(), cfg.pipeline.clone(), cfg.wire.clone())
            .with_collision_objects(cfg.node.outputs.collision_objects.clone())
    }
}

struct EngineProcessor {
    membrane: MembraneConfig,
    pipeline: PipelineConfig,
    limits: WireConfig,
    trackers: BTreeMap<StreamKey, Tracker>,
    ns: String,
    last_header: Header,
    collision: Option<CollisionObjects>,
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
        let mut sample =
            match decode_sample(&frame.topic, &frame.payload, &self.limits, &self.pipeline) {
                Ok(s) => s,
                Err(e) => {
                    return FrameResult {
                        error: Some(e.to_string()),
                        ..FrameResult::default()
                    }
                }
            };
        self.last_header = sample.header.clone();
        let streams = std::mem::take(&mut sample.streams);
        // The node's deadline runs from receipt. The objects of a labelled
        // cloud are evolved in parallel, each with what is left of it, but
        // never less than a quarter of the configured budget (so that a late
        // frame still gets a few iterations; it is then counted as late).
        let mut pipeline = self.pipeline.clone();
        // A cold start's longer budget shrinks by the same time already spent.
        if pipeline.deadline_ms > 0.0 {
            let remaining = frame.deadline.saturating_duration_since(Instant::now());
            let left = (remaining.as_secs_f64() * 1e3).max(0.25 * pipeline.deadline_ms);
            pipeline.cold_deadline_ms = pipeline.cold_budget_ms() - (pipeline.deadline_ms - left);
            pipeline.deadline_ms = left;
        }
        let mut work: Vec<(Tracker, StreamCloud)> = streams
            .into_iter()
            .map(|s| {
                let t = self
                    .trackers
                    .remove(&s.key)
                    .unwrap_or_else(|| Tracker::new(s.key.clone()));
                (t, s)
            })
            .collect();
        let membrane = &self.membrane;
        let outcomes: Vec<Processed> = work
            .par_iter_mut()
            .map(|(t, s)| Processed {
                key: s.key.clone(),
                points: s.cloud.len(),
                outcome: t.process(&s.cloud, membrane, &pipeline),
            })
            .collect();
        for (t, s) in work {
            self.trackers.insert(s.key, t);
        }
        let processed = outcomes;
        let mut outs = Vec::with_capacity(2 * processed.len() + 1);
        let mut errors = Vec::new();
        let mut objects = Vec::with_capacity(processed.len());
        let mut ok = Vec::with_capacity(processed.len());
        for p in &processed {
            match &p.outcome {
                Ok(r) => {
                    let rep = &r.reconstruction.report;
                    encode(
                        OutputKind::Mesh,
                        &outputs::surface_mesh(r, &sample.header),
                        &mut outs,
                        &mut errors,
                    );
                    encode(
                        OutputKind::FrameDiagnostics,
                        &outputs::frame_diagnostics(
                            r,
                            &sample.header,
                            sample.points_in,
                            sample.dropped,
                        ),
                        &mut outs,
                        &mut errors,
                    );
                    let warm = r.path == StartPath::Warm;
                    let level = if rep.stop == StopReason::Deadline {
                        Level::Warn
                    } else {
                        Level::Ok
                    };
                    objects.push(ObjectReport {
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
                    });
                    ok.push(r);
                }
                Err(e) => errors.push(e.to_string()),
            }
        }
        let markers: MarkerArray = outputs::marker_array(&ok, &sample.header, &self.ns);
        encode(OutputKind::Markers, &markers, &mut outs, &mut errors);
        if let Some(co) = self.collision.as_mut() {
            let trackers = &self.trackers;
            let alive = |s: &str| trackers.keys().any(|k| k.to_string() == s);
            let (msgs, errs) = co.frame(&ok, &sample.header, alive);
            for m in &msgs {
                encode(OutputKind::CollisionObjects, m, &mut outs, &mut errors);
            }
            errors.extend(errs);
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
        let mut outs = Vec::new();
        let mut errors = Vec::new();
        encode(OutputKind::Markers, &markers, &mut outs, &mut errors);
        if let Some(co) = self.collision.as_mut() {
            for m in co.retain(&self.last_header, |_| false) {
                encode(OutputKind::CollisionObjects, &m, &mut outs, &mut errors);
            }
        }
        outs
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
            OutputKind::CollisionObjects => ty::<CollisionObject>(),
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
            membrane: self.membrane.clone(),
            pipeline: self.pipeline.clone(),
            limits: self.limits.clone(),
            trackers: BTreeMap::new(),
            ns: self.pipeline.marker_namespace.clone(),
            last_header: Header::default(),
            collision: self.collision.clone().map(CollisionObjects::new),
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
