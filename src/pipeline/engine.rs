//! The one frame path: decode → track → reconstruct → output messages.
//!
//! [`Engine::handle`] takes a raw CDR `PointCloud2` sample, decodes and
//! splits it into object streams, runs each stream's [`Tracker`] (the
//! streams of one sample in parallel: they share no state) and
//! [`FrameOutput::messages`] builds the messages of the frame. The live
//! node (`node::pipeline_backend`), `sepmem replay` and the scored replay of
//! [`crate::eval`] all go through it, so they publish the same meshes for
//! the same samples.

use super::{outputs, Deadlines, Membranes, PipelineConfig, PipelineError, StreamKey, Tracker};
use crate::cloud::PointCloud;
use crate::membrane::{ConfigError, MembraneConfig};
use crate::wire::msgs::{FrameDiagnostics, Header, MarkerArray, SurfaceMesh};
use crate::wire::pointcloud2::{
    decode_pointcloud2_cdr, split_by_label, PointCloud2Error, WireConfig,
};
use rayon::prelude::*;
use std::collections::BTreeMap;
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
    Ok(DecodedSample {
        header: decoded.header,
        points_in: decoded.points_in,
        dropped: decoded.dropped_non_finite,
        streams: split_streams(topic, decoded.cloud, cfg),
    })
}

/// One stream per topic, or per (topic, label) when the cloud carries the
/// configured label channel; ignored labels are left out.
pub fn split_streams(topic: &str, cloud: PointCloud, cfg: &PipelineConfig) -> Vec<StreamCloud> {
    if cfg.split_by_label {
        if let Some(parts) = split_by_label(&cloud, &cfg.label_channel) {
            return parts
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
        }
    }
    vec![StreamCloud {
        key: StreamKey::topic(topic),
        cloud,
    }]
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
}

/// Trackers for every stream seen so far, processed one after the other.
#[derive(Debug, Clone)]
pub struct Engine {
    /// The membranes (built once from the membrane parameters).
    pub membranes: Membranes,
    /// Pipeline parameters.
    pub pipeline: PipelineConfig,
    /// Input limits.
    pub limits: WireConfig,
    trackers: BTreeMap<StreamKey, Tracker>,
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
            trackers: BTreeMap::new(),
        }
    }

    /// Decode one sample and process each of its streams (in parallel)
    /// under `deadlines` (`None`: each tracker's own, from the pipeline
    /// configuration, measured from its start).
    ///
    /// # Errors
    /// [`SampleError`] when the sample cannot be decoded; per-stream failures
    /// are reported inside the returned [`Processed`] items instead.
    pub fn handle(
        &mut self,
        topic: &str,
        cdr: &[u8],
        deadlines: Option<Deadlines>,
    ) -> Result<FrameOutput, SampleError> {
        let sample = decode_sample(topic, cdr, &self.limits, &self.pipeline)?;
        let mut work: Vec<(Tracker, &StreamCloud)> = sample
            .streams
            .iter()
            .map(|s| {
                let t = self
                    .trackers
                    .remove(&s.key)
                    .unwrap_or_else(|| Tracker::new(s.key.clone()));
                (t, s)
            })
            .collect();
        let (membranes, pipeline) = (&self.membranes, &self.pipeline);
        let processed = work
            .par_iter_mut()
            .map(|(t, s)| Processed {
                key: s.key.clone(),
                points: s.cloud.len(),
                outcome: match deadlines {
                    Some(d) => t.process_by(&s.cloud, membranes, pipeline, d),
                    None => t.process(&s.cloud, membranes, pipeline),
                },
            })
            .collect();
        for (t, s) in work {
            self.trackers.insert(s.key.clone(), t);
        }
        Ok(FrameOutput { sample, processed })
    }

    /// Process one stream's cloud on its own.
    pub fn process(&mut self, s: StreamCloud) -> Processed {
        self.process_ref(&s)
    }

    /// Process one stream's cloud on its own, leaving it to the caller.
    pub fn process_ref(&mut self, s: &StreamCloud) -> Processed {
        let tracker = self
            .trackers
            .entry(s.key.clone())
            .or_insert_with(|| Tracker::new(s.key.clone()));
        let outcome = tracker.process(&s.cloud, &self.membranes, &self.pipeline);
        Processed {
            key: s.key.clone(),
            points: s.cloud.len(),
            outcome,
        }
    }

    /// The trackers, by stream.
    pub fn trackers(&self) -> &BTreeMap<StreamKey, Tracker> {
        &self.trackers
    }
}

/// One sample through the frame path: the decoded sample (its streams'
/// clouds kept, e.g. for scoring) and one outcome per stream, in order.
#[derive(Debug)]
pub struct FrameOutput {
    /// The decoded sample.
    pub sample: DecodedSample,
    /// One outcome per stream of `sample.streams`.
    pub processed: Vec<Processed>,
}

/// The messages of one frame.
#[derive(Debug, Clone)]
pub struct FrameMessages {
    /// One mesh and one diagnostics message per reconstructed object.
    pub objects: Vec<(SurfaceMesh, FrameDiagnostics)>,
    /// DELETEALL, then a TRIANGLE_LIST per reconstructed object.
    pub markers: MarkerArray,
}

impl FrameOutput {
    /// The successful frames, in stream order.
    pub fn results(&self) -> Vec<&super::FrameResult> {
        self.processed
            .iter()
            .filter_map(|p| p.outcome.as_ref().ok())
            .collect()
    }

    /// The output messages of the frame (marker namespace `ns`).
    pub fn messages(&self, ns: &str) -> FrameMessages {
        let header = &self.sample.header;
        let ok = self.results();
        FrameMessages {
            objects: ok
                .iter()
                .map(|r| {
                    (
                        outputs::surface_mesh(r, header),
                        outputs::frame_diagnostics(
                            r,
                            header,
                            self.sample.points_in,
                            self.sample.dropped,
                        ),
                    )
                })
                .collect(),
            markers: outputs::marker_array(&ok, header, ns),
        }
    }
}
