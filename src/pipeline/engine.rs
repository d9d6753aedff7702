//! The one frame path: decode → track → reconstruct → output messages.
//!
//! [`Engine::handle`] takes a raw CDR `PointCloud2` sample, decodes and
//! splits it into object streams, keeps the largest
//! `pipeline.objects.max_per_frame`, takes their entries out of the
//! [`ObjectBook`] (re-identifying relabelled objects), runs each object's
//! [`super::Tracker`] (the objects of one sample in parallel: they share no
//! state), gives each surface its quality verdict (an unfitted surface
//! never replaces the object's last fitted mesh), and evicts silent labels.
//! [`FrameOutput::messages`] builds the messages of the frame. The live
//! node (`node::pipeline_backend`), `sepmem replay` and the scored replay of
//! [`crate::eval`] all go through it, so they publish the same meshes for
//! the same samples.

use super::objects::{cap_objects, ObjectBook, Quality};
use super::{outputs, Deadlines, Membranes, PipelineConfig, PipelineError, StreamKey};
use crate::cloud::{PointCloud, Vec3};
use crate::membrane::{ConfigError, MembraneConfig};
use crate::wire::msgs::{FrameDiagnostics, Header, Marker, MarkerArray, PointCloud2, SurfaceMesh};
use crate::wire::pointcloud2::{
    decode_pointcloud2_cdr, split_by_label, PointCloud2Error, WireConfig,
};
use rayon::prelude::*;
use thiserror::Error;

/// A sample that could not be turned into clouds.
#[derive(Debug, Error)]
pub enum SampleError {
    /// The bytes are not a valid CDR PointCloud2, or it is over the limits.
    #[error("topic {topic}: {source}")]
    Invalid {
        /// Topic.
        topic: String,
        /// Cause.
        source: PointCloud2Error,
    },
}

/// One stream's share of a decoded sample.
#[derive(Debug, Clone)]
pub struct StreamCloud {
    /// The stream.
    pub key: StreamKey,
    /// Its points.
    pub cloud: PointCloud,
}

/// A decoded sample, split into streams.
#[derive(Debug, Clone)]
pub struct DecodedSample {
    /// Header of the PointCloud2.
    pub header: Header,
    /// `width · height` of the message.
    pub points_in: usize,
    /// Non-finite points skipped while decoding.
    pub dropped: usize,
    /// One cloud per object stream.
    pub streams: Vec<StreamCloud>,
    /// Every point of a cloud split by label (ignored labels, the
    /// background, included): what else each object's camera saw, which
    /// may hide it ([`super::Tracker::process_among`]); empty for a cloud
    /// of one object.
    pub seen: Vec<Vec3>,
}

/// Decode a CDR PointCloud2 and split it into object streams.
///
/// # Errors
/// [`SampleError`] for bytes that are not a valid PointCloud2.
pub fn decode_sample(
    topic: &str,
    cdr: &[u8],
    limits: &WireConfig,
    cfg: &PipelineConfig,
) -> Result<DecodedSample, SampleError> {
    let decoded = decode_pointcloud2_cdr(cdr, limits).map_err(|source| SampleError::Invalid {
        topic: topic.to_string(),
        source,
    })?;
    let (streams, seen) = split_streams(topic, decoded.cloud, cfg);
    Ok(DecodedSample {
        header: decoded.header,
        points_in: decoded.points_in,
        dropped: decoded.dropped_non_finite,
        streams,
        seen,
    })
}

/// One stream per topic, or per (topic, label) when the cloud carries the
/// configured label channel; ignored labels are left out. With labels, the
/// cloud's points come back too (what each object's camera saw besides it).
pub fn split_streams(
    topic: &str,
    cloud: PointCloud,
    cfg: &PipelineConfig,
) -> (Vec<StreamCloud>, Vec<Vec3>) {
    if cfg.split_by_label {
        if let Some(parts) = split_by_label(&cloud, &cfg.label_channel) {
            let streams = parts
                .into_iter()
                .filter(|(label, _)| !cfg.ignore_labels.contains(label))
                .map(|(label, cloud)| StreamCloud {
                    key: StreamKey {
                        topic: topic.to_string(),
                        label: Some(label),
                    },
                    cloud,
                })
                .collect();
            return (streams, cloud.points);
        }
    }
    let one = StreamCloud {
        key: StreamKey::topic(topic),
        cloud,
    };
    (vec![one], Vec::new())
}

/// What a frame publishes for one object.
#[derive(Debug, Clone)]
pub struct Shown {
    /// The verdict on this frame's surface, given the object's history.
    pub verdict: Quality,
    /// The quality of what is shown: the verdict, or [`Quality::Held`] when
    /// the object's last fitted mesh is shown instead.
    pub quality: Quality,
    /// The mesh published.
    pub mesh: SurfaceMesh,
    /// Its marker (a TRIANGLE_LIST coloured by separability or verdict).
    pub marker: Marker,
}

/// The outcome of one stream of one sample.
#[derive(Debug)]
pub struct Processed {
    /// Stream.
    pub key: StreamKey,
    /// Points of this stream in the sample.
    pub points: usize,
    /// The frame result or why it failed.
    pub outcome: Result<super::FrameResult, PipelineError>,
    /// What is published for it (`None` when the outcome is an error).
    pub shown: Option<Shown>,
}

/// Every object stream's state, and the frame path over it.
#[derive(Debug, Clone)]
pub struct Engine {
    /// The membranes (built once from the membrane parameters).
    pub membranes: Membranes,
    /// Pipeline parameters.
    pub pipeline: PipelineConfig,
    /// Input limits.
    pub limits: WireConfig,
    objects: ObjectBook,
}

impl Engine {
    /// An engine with no streams yet.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first bad membrane key.
    pub fn new(
        membrane: &MembraneConfig,
        pipeline: PipelineConfig,
        limits: WireConfig,
    ) -> Result<Self, ConfigError> {
        let membranes = Membranes::new(membrane, &pipeline)?;
        Ok(Self::with_membranes(membranes, pipeline, limits))
    }

    /// An engine on membranes built before (a node shares them, with their
    /// fit cache, between its topics).
    pub fn with_membranes(
        membranes: Membranes,
        pipeline: PipelineConfig,
        limits: WireConfig,
    ) -> Self {
        Self {
            membranes,
            pipeline,
            limits,
            objects: ObjectBook::default(),
        }
    }

    /// Decode one sample received at `now_ns` (the clock of
    /// `pipeline.objects.forget_after_ms`: receipt time live, the bag's log
    /// time in a replay) and process its objects (in parallel) under
    /// `deadlines` (`None`: each tracker's own, from the pipeline
    /// configuration, measured from its start).
    ///
    /// # Errors
    /// [`SampleError`] when the sample cannot be decoded; per-object failures
    /// are reported inside the returned [`Processed`] items instead.
    pub fn handle(
        &mut self,
        topic: &str,
        cdr: &[u8],
        deadlines: Option<Deadlines>,
        now_ns: i64,
    ) -> Result<FrameOutput, SampleError> {
        let mut sample = decode_sample(topic, cdr, &self.limits, &self.pipeline)?;
        let objects_cfg = &self.pipeline.objects;
        let skipped = cap_objects(&mut sample.streams, objects_cfg.max_per_frame);
        let (mut entries, reidentified) = self
            .objects
            .checkout_frame(&sample.streams, objects_cfg.reidentify.as_ref());
        let (membranes, pipeline) = (&self.membranes, &self.pipeline);
        let seen = &sample.seen;
        let outcomes: Vec<_> = entries
            .par_iter_mut()
            .zip(&sample.streams)
            .map(|(e, s)| match deadlines {
                Some(d) => e
                    .tracker
                    .process_among(&s.cloud, seen, membranes, pipeline, d),
                None => {
                    let d = super::Deadlines::from_config(std::time::Instant::now(), pipeline);
                    e.tracker
                        .process_among(&s.cloud, seen, membranes, pipeline, d)
                }
            })
            .collect();
        let mut processed = Vec::with_capacity(outcomes.len());
        for ((mut entry, s), outcome) in entries.into_iter().zip(&sample.streams).zip(outcomes) {
            let shown = outcome.as_ref().ok().map(|r| {
                let verdict = entry.verdict(r, &self.pipeline.objects);
                let ns = &self.pipeline.marker_namespace;
                let (mesh, marker, quality) = entry.publish(
                    verdict,
                    outputs::surface_mesh(r, &sample.header),
                    outputs::separability_marker(r, &sample.header, ns),
                );
                Shown {
                    verdict,
                    quality,
                    mesh,
                    marker,
                }
            });
            self.objects.checkin(entry, now_ns);
            processed.push(Processed {
                key: s.key.clone(),
                points: s.cloud.len(),
                outcome,
                shown,
            });
        }
        let evicted = self.objects.evict(now_ns, &self.pipeline.objects);
        Ok(FrameOutput {
            sample,
            processed,
            skipped,
            reidentified,
            evicted,
        })
    }

    /// The objects tracked.
    pub fn objects(&self) -> &ObjectBook {
        &self.objects
    }
}

/// One sample through the frame path: the decoded sample (its evolved
/// streams' clouds kept, e.g. for scoring) and one outcome per stream, in
/// order.
#[derive(Debug)]
pub struct FrameOutput {
    /// The decoded sample; `streams` holds the objects evolved (the largest
    /// `pipeline.objects.max_per_frame`).
    pub sample: DecodedSample,
    /// One outcome per stream of `sample.streams`.
    pub processed: Vec<Processed>,
    /// Objects of the sample beyond `pipeline.objects.max_per_frame`, not evolved.
    pub skipped: usize,
    /// The labels whose trackers new labels took over (re-identified).
    pub reidentified: Vec<StreamKey>,
    /// The labels forgotten after this frame (silent, or beyond `max_tracked`).
    pub evicted: Vec<StreamKey>,
}

/// The messages of one frame.
#[derive(Debug, Clone)]
pub struct FrameMessages {
    /// One mesh and one diagnostics message per reconstructed object.
    pub objects: Vec<(SurfaceMesh, FrameDiagnostics)>,
    /// DELETEALL, then a TRIANGLE_LIST per reconstructed object.
    pub markers: MarkerArray,
    /// The objects' fused models (`pipeline.model`), labelled by the
    /// label channel.
    pub model: Option<PointCloud2>,
}

impl FrameOutput {
    /// The successful frames, in stream order.
    pub fn results(&self) -> Vec<&super::FrameResult> {
        self.processed
            .iter()
            .filter_map(|p| p.outcome.as_ref().ok())
            .collect()
    }

    /// The output messages of the frame (marker namespace `ns`, the fused
    /// models' object labels in channel `label`).
    pub fn messages(&self, ns: &str, label: &str) -> FrameMessages {
        let header = &self.sample.header;
        let shown = || {
            self.processed
                .iter()
                .filter_map(|p| Some((p.outcome.as_ref().ok()?, p.shown.as_ref()?)))
        };
        FrameMessages {
            objects: shown()
                .map(|(r, s)| {
                    let diag = outputs::frame_diagnostics(
                        r,
                        header,
                        self.sample.points_in,
                        self.sample.dropped,
                    );
                    (s.mesh.clone(), diag)
                })
                .collect(),
            markers: outputs::cleared_markers(
                shown().map(|(_, s)| s.marker.clone()).collect(),
                header,
                ns,
            ),
            model: outputs::model_cloud(&self.results(), header, label),
        }
    }
}
