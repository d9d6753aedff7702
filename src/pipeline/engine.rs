//! A sequential frame engine: raw CDR `PointCloud2` samples in, processed
//! frames out, one [`Tracker`] per object stream.
//!
//! `sepmem replay` drives it from a bag; the live node uses the same pieces
//! ([`split_streams`], [`Tracker`], [`super::outputs`]) but runs the trackers
//! of different streams in parallel.

use super::{PipelineConfig, PipelineError, StreamKey, Tracker};
use crate::cloud::PointCloud;
use crate::membrane::MembraneConfig;
use crate::wire::msgs::Header;
use crate::wire::pointcloud2::{
    decode_pointcloud2_cdr, split_by_label, PointCloud2Error, WireConfig,
};
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
    /// Membrane parameters.
    pub membrane: MembraneConfig,
    /// Pipeline parameters.
    pub pipeline: PipelineConfig,
    /// Input limits.
    pub limits: WireConfig,
    trackers: BTreeMap<StreamKey, Tracker>,
}

impl Engine {
    /// An engine with no streams yet.
    pub fn new(membrane: MembraneConfig, pipeline: PipelineConfig, limits: WireConfig) -> Self {
        Self {
            membrane,
            pipeline,
            limits,
            trackers: BTreeMap::new(),
        }
    }

    /// Decode one sample and process each of its streams.
    ///
    /// # Errors
    /// [`SampleError`] when the sample cannot be decoded; per-stream failures
    /// are reported inside the returned [`Processed`] items instead.
    pub fn handle(
        &mut self,
        topic: &str,
        cdr: &[u8],
    ) -> Result<(DecodedSample, Vec<Processed>), SampleError> {
        let mut sample = decode_sample(topic, cdr, &self.limits, &self.pipeline)?;
        let streams = std::mem::take(&mut sample.streams);
        let out = streams.into_iter().map(|s| self.process(s)).collect();
        Ok((sample, out))
    }

    /// Process one stream's cloud.
    pub fn process(&mut self, s: StreamCloud) -> Processed {
        self.process_ref(&s)
    }

    /// Process one stream's cloud, leaving it to the caller (e.g. to score
    /// the result against the points afterwards).
    pub fn process_ref(&mut self, s: &StreamCloud) -> Processed {
        let tracker = self
            .trackers
            .entry(s.key.clone())
            .or_insert_with(|| Tracker::new(s.key.clone()));
        let outcome = tracker.process(&s.cloud, &self.membrane, &self.pipeline);
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
