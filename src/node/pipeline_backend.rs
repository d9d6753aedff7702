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
//!
//! Each output goes to the node's [`OutputSink`] as soon as it is encoded,
//! the objects' meshes first: in `sepmem demo` the mesh waited about 3 ms (p50) for the
//! frame's later outputs, mostly the collision objects' simplification,
//! when the frame's outputs were published together.

use super::backend::{
    Backend, Frame, FrameResult, ObjectReport, Output, OutputKind, OutputSink, StatusEntry,
    TopicProcessor,
};
use super::reasons;
use super::stats::Level;
use crate::membrane::{ConfigError, MembraneConfig};
use crate::pipeline::collision::{CollisionConfig, CollisionObjects};
use crate::pipeline::engine::{DecodedSample, Engine, FrameOutput as EngineFrame, Shown};
use crate::pipeline::objects::Quality;
use crate::pipeline::reserve::Reserve;
use crate::pipeline::{
    outputs, Deadlines, FrameResult as PipelineResult, Membranes, PipelineConfig, StartPath,
};
use crate::transport::RosType;
use crate::wire::msgs::{
    CollisionObject, DiagnosticArray, DiagnosticStatus, FrameDiagnostics, Header, KeyValue, Marker,
    MarkerArray, PointCloud2, SurfaceMesh, Time,
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
    collision: Option<CollisionConfig>,
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
            collision: None,
        })
    }

    /// Also publish MoveIt collision objects (`node.outputs.collision_objects`).
    pub fn with_collision_objects(mut self, collision: Option<CollisionConfig>) -> Self {
        self.collision = collision;
        self
    }
}

struct EngineProcessor {
    engine: Engine,
    ns: String,
    last_header: Header,
    collision: Option<CollisionObjects>,
    /// What the frames' outputs took to make once their objects were done,
    /// kept before the objects' deadlines (`pipeline::reserve`).
    outputs_reserve: Reserve,
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

/// What a frame's objects produced so far; encoded outputs leave at once
/// through `sink`.
struct FrameOut<'s, 'a> {
    sink: &'s mut OutputSink<'a>,
    markers: Vec<Marker>,
    objects: Vec<ObjectReport>,
    errors: Vec<String>,
    counts: Vec<(&'static str, u64)>,
}

impl<'s, 'a> FrameOut<'s, 'a> {
    fn new(sink: &'s mut OutputSink<'a>) -> Self {
        Self {
            sink,
            markers: Vec::new(),
            objects: Vec::new(),
            errors: Vec::new(),
            counts: Vec::new(),
        }
    }

    fn encode<M: RosMessage>(&mut self, kind: OutputKind, msg: &M) {
        match wire::encode(msg) {
            Ok(payload) => (self.sink)(Output { kind, payload }),
            Err(e) => {
                self.errors.push(format!("encoding {}: {e}", M::TYPE_NAME));
                reasons::bump(&mut self.counts, reasons::OUTPUTS_FAILED, 1);
            }
        }
    }
}

impl EngineProcessor {
    /// The outputs of one evolved object: the mesh and marker the engine
    /// chose to show ([`crate::pipeline::objects`]), its frame diagnostics
    /// and its `/diagnostics` report. The marker, a TRIANGLE_LIST of the
    /// whole mesh, moves into the frame's MarkerArray instead of being
    /// copied (marker copies were 0.7 % of a warm frame's profile).
    fn emit(
        &self,
        r: &PipelineResult,
        shown: &mut Shown,
        sample: &DecodedSample,
        out: &mut FrameOut<'_, '_>,
    ) {
        let rep = &r.reconstruction.report;
        out.encode(OutputKind::Mesh, &shown.mesh);
        out.encode(
            OutputKind::FrameDiagnostics,
            &outputs::frame_diagnostics(r, &sample.header, sample.points_in, sample.dropped),
        );
        out.markers.push(std::mem::take(&mut shown.marker));
        let fitted = shown.verdict.is_fitted();
        if !fitted {
            reasons::bump(&mut out.counts, reasons::UNFITTED, 1);
        }
        let warm = r.path == StartPath::Warm;
        // A frame its deadline stopped is the live node's usual case (under
        // the default deadline a warm frame runs one to three of its
        // iterations) and says so in its message; only an unfitted surface
        // is a warning. Before, every such frame was WARN: a healthy 6 k-
        // or 20 k-point stream on an idle machine was never reported OK.
        let level = if fitted { Level::Ok } else { Level::Warn };
        let shown_note = if shown.quality == Quality::Held {
            "; showing the last fitted mesh"
        } else {
            ""
        };
        // The flying-pixel filter and the fused model take the cloud
        // frame's origin for the camera (pipeline::flying).
        let frame_note = if r.flying.not_an_image {
            reasons::bump(&mut out.counts, reasons::NOT_AN_IMAGE, 1);
            "; not one depth image seen from its frame's origin (publish it in the camera's optical frame)"
        } else {
            ""
        };
        if r.rebuild_starved {
            reasons::bump(&mut out.counts, reasons::REBUILDS_STARVED, 1);
        }
        let model_note = if r.model_reset {
            reasons::bump(&mut out.counts, reasons::MODELS_RESTARTED, 1);
            "; its view saw through the fused model, which restarted from it (the object changed or was swapped)"
        } else {
            ""
        };
        out.objects.push(ObjectReport {
            stream: r.stream.to_string(),
            eta_g: rep.eta_final,
            iterations: u32::try_from(r.iterations).unwrap_or(u32::MAX),
            warm,
            level,
            message: format!(
                "{} start ({}), stop: {}, surface {}{shown_note}{frame_note}{model_note}",
                if warm { "warm" } else { "cold" },
                r.reason,
                rep.stop,
                shown.verdict.as_str(),
            ),
            quality: Some(shown.quality.as_str()),
            model_bytes: r.model_bytes,
        });
    }

    /// MoveIt collision objects of the frame's fitted surfaces (ADD or
    /// MOVE), then REMOVE for the objects no longer tracked; an unfitted
    /// surface never reaches the planning scene.
    fn collision_objects(&mut self, frame: &EngineFrame, out: &mut FrameOut<'_, '_>) {
        let Some(co) = self.collision.as_mut() else {
            return;
        };
        let fitted: Vec<&PipelineResult> = frame
            .processed
            .iter()
            .filter(|p| p.shown.as_ref().is_some_and(|s| s.verdict.is_fitted()))
            .filter_map(|p| p.outcome.as_ref().ok())
            .collect();
        let objects = self.engine.objects();
        let (msgs, errs) = co.frame(&fitted, &frame.sample.header, |s| {
            objects.contains_stream(s)
        });
        for m in &msgs {
            out.encode(OutputKind::CollisionObjects, m);
        }
        out.errors.extend(errs);
    }

    /// The outputs of a processed frame, each handed to `out`'s sink as it
    /// is encoded (the objects' meshes and diagnostics first), and its
    /// counts.
    fn outputs(&mut self, frame: &mut EngineFrame, out: &mut FrameOut<'_, '_>) {
        reasons::bump(
            &mut out.counts,
            reasons::OBJECTS_SKIPPED,
            frame.skipped as u64,
        );
        let reid = frame.reidentified.len() as u64;
        reasons::bump(&mut out.counts, reasons::LABELS_REIDENTIFIED, reid);
        for p in &mut frame.processed {
            match (&p.outcome, &mut p.shown) {
                (Ok(r), Some(shown)) => self.emit(r, shown, &frame.sample, out),
                (Ok(_), None) => {}
                (Err(e), _) => {
                    reasons::bump(&mut out.counts, reasons::OBJECT_ERRORS, 1);
                    out.errors.push(e.to_string());
                }
            }
        }
        let evicted = frame.evicted.len() as u64;
        reasons::bump(&mut out.counts, reasons::LABELS_EVICTED, evicted);
        let header = &frame.sample.header;
        let markers = outputs::cleared_markers(std::mem::take(&mut out.markers), header, &self.ns);
        out.encode(OutputKind::Markers, &markers);
        self.collision_objects(frame, out);
        // The fused models last, after the collision objects MoveIt
        // depends on: the least urgent output. (Collision objects also
        // travel in their own zenoh lane, `OutputKind::lane`: in the shared
        // one, a loaded link dropped them behind the marker arrays.)
        if self.engine.pipeline.model.is_some() {
            let label = &self.engine.pipeline.label_channel;
            if let Some(m) = outputs::model_cloud(&frame.results(), header, label) {
                out.encode(OutputKind::Model, &m);
            }
        }
    }
}

impl TopicProcessor for EngineProcessor {
    fn process(&mut self, frame: &Frame, sink: &mut OutputSink<'_>) -> FrameResult {
        // The node's deadline runs from receipt; every object of a labelled
        // cloud shares it, however many compute waves the objects take, and
        // the frame's outputs are made by it too.
        let objects_by = self.outputs_reserve.before(frame.deadline);
        let deadlines = node_deadlines(&self.engine.pipeline, objects_by);
        let handled = self.engine.handle(
            &frame.topic,
            &frame.payload,
            Some(deadlines),
            frame.received_ns,
        );
        let mut done = match handled {
            Ok(done) => done,
            Err(e) => {
                let mut counts = Vec::new();
                reasons::bump(&mut counts, reasons::of_sample_error(&e), 1);
                return FrameResult {
                    error: Some(e.to_string()),
                    counts,
                    ..FrameResult::default()
                };
            }
        };
        self.last_header = done.sample.header.clone();
        let mut out = FrameOut::new(sink);
        let outputs_start = Instant::now();
        self.outputs(&mut done, &mut out);
        self.outputs_reserve.record(outputs_start.elapsed());
        FrameResult {
            objects: out.objects,
            error: (!out.errors.is_empty()).then(|| out.errors.join("; ")),
            counts: out.counts,
            evicted: done
                .evicted
                .iter()
                .chain(&done.reidentified)
                .map(ToString::to_string)
                .collect(),
        }
    }

    fn on_evict(&mut self) -> Vec<Output> {
        let mut kept = Vec::new();
        let mut keep = |o| kept.push(o);
        let mut out = FrameOut::new(&mut keep);
        out.encode(
            OutputKind::Markers,
            &outputs::marker_array(&[], &self.last_header, &self.ns),
        );
        if let Some(co) = self.collision.as_mut() {
            for m in co.retain(&self.last_header, |_| false) {
                out.encode(OutputKind::CollisionObjects, &m);
            }
        }
        kept
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
            OutputKind::Model => ty::<PointCloud2>(),
        }
    }

    fn publishes(&self, kind: OutputKind) -> bool {
        kind != OutputKind::Model || self.pipeline.model.is_some()
    }

    fn diagnostics_type(&self) -> RosType {
        ty::<DiagnosticArray>()
    }

    fn frame_deadline(&self) -> Option<Duration> {
        (self.pipeline.deadline_ms > 0.0)
            .then(|| Duration::from_secs_f64(self.pipeline.deadline_ms / 1e3))
    }

    fn max_message_bytes(&self) -> Option<usize> {
        // What `decode_pointcloud2_cdr` accepts (data plus 64 KiB of header
        // and fields), plus 4 KiB of zenoh framing (key, attachment).
        Some(self.limits.max_bytes.saturating_add((1 << 16) + 4096))
    }

    fn frame_budget(&self) -> Option<Duration> {
        (self.pipeline.deadline_ms > 0.0)
            .then(|| Duration::from_secs_f64(self.pipeline.cold_budget_ms() / 1e3))
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
            collision: self.collision.clone().map(CollisionObjects::new),
            outputs_reserve: Reserve::default(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::{PointCloud, Vec3};
    use crate::config::Config;
    use crate::wire::pointcloud2::encode_pointcloud2;

    /// The front of a sphere of radius 0.1 m at 0.8 m as a 640×480, f = 525
    /// camera sees it (one point per pixel), moved by `shift`.
    fn sphere_image(shift: Vec3) -> Vec<Vec3> {
        let view = crate::pipeline::flying::tests::sphere_view(Vec3::new(0.0, 0.0, 0.8), 0.1);
        view.into_iter().map(|(_, _, p)| p + shift).collect()
    }

    /// A frame's first object's `/diagnostics` message, and the frame's
    /// counts by reason.
    type Shown = (String, Vec<(&'static str, u64)>);

    /// The count of `reason` in a frame's counts.
    fn count(shown: &Shown, reason: &str) -> u64 {
        shown
            .1
            .iter()
            .filter(|(r, _)| *r == reason)
            .map(|(_, n)| n)
            .sum()
    }

    /// The `/diagnostics` message of one frame of `points`.
    fn message(points: Vec<Vec3>) -> Shown {
        let cloud = PointCloud::from_points(points);
        let payload = wire::encode(&encode_pointcloud2(&cloud, Header::default())).unwrap();
        messages("/sphere/points", &[payload], &[]).remove(0)
    }

    /// A processor of `topic` with the configuration changed by `sets`.
    fn processor(topic: &str, sets: &[String]) -> Box<dyn TopicProcessor> {
        let cfg = Config::load(None, sets).unwrap();
        let backend =
            PipelineBackend::new(&cfg.membrane, cfg.pipeline.clone(), cfg.wire.clone()).unwrap();
        backend.processor(topic)
    }

    /// A node frame of `payload` on `topic`, due at `deadline`.
    fn frame(topic: &str, payload: Vec<u8>, deadline: Instant) -> Frame {
        Frame {
            topic: topic.into(),
            payload,
            received_ns: 0,
            source_ns: None,
            sequence: None,
            deadline,
        }
    }

    /// The first `n` clouds on `topic` of the committed bag
    /// `tests/data/bags/robot_view/{name}.mcap`.
    fn robot_view_clouds(name: &str, topic: &str, n: usize) -> Vec<Vec<u8>> {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/bags/robot_view");
        let path = std::path::Path::new(dir).join(format!("{name}.mcap"));
        let bag = crate::bag::Bag::open(&path).unwrap();
        let messages = bag.read(&[topic]).unwrap().into_iter();
        messages.take(n).map(|m| m.data).collect()
    }

    /// The `/diagnostics` messages of the frames `payloads` (encoded
    /// PointCloud2) on `topic`, with the configuration changed by `sets`.
    fn messages(topic: &str, payloads: &[Vec<u8>], sets: &[String]) -> Vec<Shown> {
        let mut processor = processor(topic, sets);
        let mut message = |payload: &Vec<u8>| {
            let frame = frame(
                topic,
                payload.clone(),
                Instant::now() + Duration::from_secs(10),
            );
            let result = processor.process(&frame, &mut |_| {});
            assert_eq!(result.error, None);
            (result.objects[0].message.clone(), result.counts)
        };
        payloads.iter().map(&mut message).collect()
    }

    #[test]
    fn a_cloud_outside_the_cameras_frame_is_named_in_its_status() {
        let seen = message(sphere_image(Vec3::zeros()));
        assert!(!seen.0.contains("not one depth image"), "{seen:?}");
        assert_eq!(count(&seen, reasons::NOT_AN_IMAGE), 0);
        // The same points in a frame 0.5 m aside: not on one pixel grid
        // seen from that frame's origin.
        let aside = message(sphere_image(Vec3::new(0.5, 0.0, 0.0)));
        assert!(aside.0.contains("not one depth image"), "{aside:?}");
        assert_eq!(count(&aside, reasons::NOT_AN_IMAGE), 1);
    }

    #[test]
    fn a_fitted_frame_its_deadline_stopped_is_ok() {
        let topic = "/synth/capsule/points";
        // The first, cold frame gets 5 s: under load (the suite's other
        // tests beside an evaluation) its default 200 ms ran out and left
        // it unfitted, and the warm frames after it unconverged.
        let sets = ["pipeline.cold_deadline_ms=5000".to_owned()];
        let mut processor = processor(topic, &sets);
        let mut stopped = 0;
        for payload in robot_view_clouds("turn_capsule", topic, 6) {
            // A deadline already passed: each warm frame runs its one
            // iteration (warm_min_iterations) and stops at the deadline.
            let frame = frame(topic, payload, Instant::now());
            let result = processor.process(&frame, &mut |_| {});
            let o = &result.objects[0];
            if o.message.contains("stop: deadline") {
                stopped += 1;
                assert!(o.message.contains("surface fitted"), "{}", o.message);
                assert_eq!(o.level, Level::Ok, "{}", o.message);
            }
        }
        assert!(stopped >= 4, "{stopped} frames stopped at their deadline");
    }

    #[test]
    fn a_view_that_restarts_the_model_is_named_in_its_status() {
        // The committed swap (a box, a bottle from frame 10, a mug from
        // frame 20) with the track never lost (icp_min_inliers null): no
        // lost track restarts the model. The bottle's view sees past its
        // own silhouette where the box's model lies
        // (`model::ObjectModel::integrate`), and the model restarts within
        // 2 frames of that swap. The mug's view sees through 0.47 of the
        // bottle's model (tests/robot_view.rs), just below reset_share:
        // whether it restarts there depends on which background rebuild
        // the frame adopted under its deadline (CI restarted it in two runs
        // and not in a third), so only that no restart comes elsewhere is
        // asserted of it.
        let topic = "/synth/rounded_box_then_bottle_then_mug/points";
        let payloads = robot_view_clouds("swap", topic, 23);
        let sets = ["pipeline.icp_min_inliers=null".to_owned()];
        let shown = messages(topic, &payloads, &sets);
        let named = |m: &Shown| m.0.contains("fused model, which restarted");
        let at: Vec<usize> = (0..shown.len()).filter(|&i| named(&shown[i])).collect();
        assert!(
            at.iter().any(|f| (10..=12).contains(f)),
            "restarted at {at:?}: {shown:#?}"
        );
        let elsewhere = |f: &usize| !(10..=12).contains(f) && !(20..=22).contains(f);
        assert!(!at.iter().any(elsewhere), "restarted at {at:?}: {shown:#?}");
        // Counted under its own reason, once per frame that named it.
        for s in &shown {
            assert_eq!(count(s, reasons::MODELS_RESTARTED), u64::from(named(s)));
        }
    }
}
