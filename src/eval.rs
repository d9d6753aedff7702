//! Evaluation of the frame pipeline against ground truth: per-frame scoring
//! of a stream's mesh (replay of bags that carry the
//! `sepmem_msgs/msg/GroundTruth` side channel written by [`crate::synth`]),
//! the cold references of the warm-versus-cold check, and a scored replay.
//! It sits above the pipeline and the simulator, which know nothing of it.
//!
//! The scores follow the ONet / SAP protocol of [`crate::metrics`] (paper
//! §IV-C): both meshes are normalised by the ground truth's bounding box
//! (longest edge 1), sampled by area with `metrics.samples` (100 000)
//! points, and compared by nearest neighbours with the threshold τ. To keep
//! scoring cheap, only a random subset of `pipeline.score_samples` (10 000)
//! samples of each mesh is queried against the other mesh's full sample
//! set: an unbiased estimate of the protocol's precision, recall and
//! Chamfer-L1 (binomial standard error ≤ 0.005 at 10 000 queries). Querying
//! a sparse sample set instead would not do: at 10 000 samples the spacing
//! of the samples exceeds τ and even a perfect mesh scores F ≈ 0.5.
//!
//! Partial views (a depth camera sees one side of the object) get two
//! one-sided scores besides F:
//! - **precision**: share of predicted-surface samples within τ of the
//!   *full* ground-truth surface (the accuracy side of F: nothing invented);
//! - **visible recall**: among ground-truth samples the camera saw — those
//!   within `pipeline.score_visible_radius` (a fraction of the object size)
//!   of an observed point — the share within τ of the prediction.
//!
//! and two closure measures of the unseen side, which has no data at all
//! (the membrane must wrap 𝒫 and close the back, not collapse onto the
//! visible shell): the ratio of the predicted to the true extent along the
//! viewing ray (camera at the origin of the cloud frame, looking at the
//! ground truth's centre) and the ratio of the enclosed volumes.
//!
//! The warm-versus-cold check compares a warm-started frame with cold
//! starts of the same frame ([`cold_references`]), optionally several on
//! different thinning subsets, whose spread is the resolution of the
//! cold reference itself.

use crate::cloud::{Aabb, Vec3};
use crate::mesh::TriMesh;
use crate::metrics::{sample_surface, MetricsError, Normalization};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;

pub mod view;

/// Parameters of the per-frame score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoreConfig {
    /// Query samples per mesh (precision, recall and Chamfer are averaged over them).
    pub samples: usize,
    /// Reference samples per mesh (the queries' nearest neighbours are
    /// searched among them; the benchmark protocol's 100 000).
    pub reference_samples: usize,
    /// F-score threshold τ, as a fraction of the ground truth's size.
    pub tau: f64,
    /// A ground-truth sample counts as seen when an observed point lies
    /// within this fraction of the ground truth's size.
    pub visible_radius: f64,
    /// Seed of the surface sampling.
    pub seed: u64,
}

impl ScoreConfig {
    /// From the configuration: τ and seed of `metrics`, sample count and
    /// visibility radius of `pipeline`.
    pub fn from_config(cfg: &crate::config::Config) -> Self {
        Self {
            samples: cfg.pipeline.score_samples,
            reference_samples: cfg.metrics.samples,
            tau: cfg.metrics.tau,
            visible_radius: cfg.pipeline.score_visible_radius,
            seed: cfg.metrics.seed,
        }
    }
}

/// Scores of one frame of one stream.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameScore {
    /// F-score at τ against the full ground truth.
    pub fscore: f64,
    /// Chamfer-L1 in the normalised frame.
    pub chamfer_l1: f64,
    /// Share of predicted samples within τ of the full ground truth.
    pub precision: f64,
    /// Share of all ground-truth samples within τ of the prediction.
    pub recall: f64,
    /// Share of the *seen* ground-truth samples within τ of the prediction.
    pub recall_visible: f64,
    /// Share of ground-truth samples counted as seen.
    pub visible_fraction: f64,
    /// Predicted / true extent along the viewing ray.
    pub depth_ratio: f64,
    /// Predicted / true enclosed volume.
    pub volume_ratio: f64,
}

/// Extent of `points` along the unit vector `axis`.
fn extent_along(points: &[Vec3], axis: &Vec3) -> f64 {
    let (lo, hi) = points
        .iter()
        .map(|p| p.dot(axis))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
            (lo.min(d), hi.max(d))
        });
    (hi - lo).max(0.0)
}

/// Score `pred` against the posed ground truth `gt`, `observed` being the
/// points the camera measured of this object in this frame (same frame as
/// both meshes).
///
/// # Errors
/// [`MetricsError`] for an empty or degenerate ground truth, bad indices or
/// bad parameters.
pub fn score_frame(
    pred: &TriMesh,
    gt: &TriMesh,
    observed: &[Vec3],
    cfg: &ScoreConfig,
) -> Result<FrameScore, MetricsError> {
    if cfg.samples == 0 {
        return Err(MetricsError::BadParameter {
            what: "samples",
            value: 0.0,
        });
    }
    if !(cfg.visible_radius.is_finite() && cfg.visible_radius > 0.0) {
        return Err(MetricsError::BadParameter {
            what: "visible_radius",
            value: cfg.visible_radius,
        });
    }
    let bb = Aabb::from_points(&gt.vertices);
    let norm = Normalization::from_aabb(&bb)?;
    let n_ref = cfg.reference_samples.max(cfg.samples);
    let gt_s = sample_surface(&norm.mesh(gt), n_ref, cfg.seed)?.points;
    if gt_s.is_empty() {
        return Err(MetricsError::EmptyGroundTruth);
    }
    let pred_s = sample_surface(&norm.mesh(pred), n_ref, cfg.seed.wrapping_add(1))?.points;
    // The samples are independent, so the first `samples` of each set are a
    // random subset: the queries.
    let gt_q = &gt_s[..cfg.samples.min(gt_s.len())];
    let pred_q = &pred_s[..cfg.samples.min(pred_s.len())];
    let tree_of = |pts: &[Vec3]| -> ImmutableKdTree<f64, 3> {
        let coords: Vec<[f64; 3]> = pts.iter().map(|p| [p.x, p.y, p.z]).collect();
        ImmutableKdTree::new_from_slice(&coords)
    };
    let dist = |tree: &ImmutableKdTree<f64, 3>, q: &Vec3| {
        tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z])
            .distance
            .max(0.0)
            .sqrt()
    };
    let gt_tree = tree_of(&gt_s);
    let pred_tree = (!pred_s.is_empty()).then(|| tree_of(&pred_s));
    let (mut acc, mut precise) = (0.0, 0usize);
    for q in pred_q {
        let d = dist(&gt_tree, q);
        acc += d;
        precise += usize::from(d <= cfg.tau);
    }
    // Completeness of every ground-truth query, and whether the camera saw it.
    let obs: Vec<Vec3> = observed
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .map(|p| norm.apply(p))
        .collect();
    let obs_tree = (!obs.is_empty()).then(|| tree_of(&obs));
    let (mut comp, mut recalled, mut seen, mut seen_hit) = (0.0, 0usize, 0usize, 0usize);
    for q in gt_q {
        let d = pred_tree.as_ref().map_or(3f64.sqrt(), |t| dist(t, q));
        comp += d;
        let hit = d <= cfg.tau;
        recalled += usize::from(hit);
        if obs_tree
            .as_ref()
            .is_some_and(|t| dist(t, q) <= cfg.visible_radius)
        {
            seen += 1;
            seen_hit += usize::from(hit);
        }
    }
    let ratio = |a: usize, b: usize| if b > 0 { a as f64 / b as f64 } else { 0.0 };
    let precision = ratio(precise, pred_q.len());
    let recall = ratio(recalled, gt_q.len());
    let fscore = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    let chamfer_l1 = if pred_q.is_empty() {
        3f64.sqrt()
    } else {
        0.5 * (acc / pred_q.len() as f64 + comp / gt_q.len() as f64)
    };
    let recall_visible = ratio(seen_hit, seen);
    // Closure of the unseen side.
    let centre = bb.center();
    let axis = if centre.norm() > 0.0 {
        centre / centre.norm()
    } else {
        Vec3::z()
    };
    let gt_depth = extent_along(&gt.vertices, &axis);
    let depth_ratio = if gt_depth > 0.0 {
        extent_along(&pred.vertices, &axis) / gt_depth
    } else {
        f64::NAN
    };
    let gt_vol = gt.signed_volume();
    let volume_ratio = if gt_vol.abs() > 0.0 {
        pred.signed_volume() / gt_vol
    } else {
        f64::NAN
    };
    Ok(FrameScore {
        fscore,
        chamfer_l1,
        precision,
        recall,
        recall_visible,
        visible_fraction: ratio(seen, gt_q.len()),
        depth_ratio,
        volume_ratio,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::uv_sphere;

    fn cfg() -> ScoreConfig {
        ScoreConfig {
            samples: 5_000,
            reference_samples: 100_000,
            tau: 0.01,
            visible_radius: 0.02,
            seed: 0,
        }
    }

    /// Points of the front half (z < centre) of a sphere, as a camera at the origin sees it.
    fn front_half(c: Vec3, r: f64) -> Vec<Vec3> {
        let m = uv_sphere(c, r, 40, 80);
        m.vertices.into_iter().filter(|v| v.z < c.z).collect()
    }

    #[test]
    fn perfect_prediction_scores_one_and_sees_half() {
        let c = Vec3::new(0.0, 0.0, 1.0);
        let gt = uv_sphere(c, 0.1, 40, 80);
        let s = score_frame(&gt, &gt, &front_half(c, 0.1), &cfg()).unwrap();
        assert!(s.fscore > 0.99, "{s:?}");
        assert!(s.precision > 0.99 && s.recall_visible > 0.99, "{s:?}");
        // About half the sphere faces the camera.
        assert!((0.4..0.65).contains(&s.visible_fraction), "{s:?}");
        assert!((s.depth_ratio - 1.0).abs() < 1e-9 && (s.volume_ratio - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_collapsed_back_keeps_visible_recall_but_not_the_closure() {
        // Prediction: the sphere flattened onto its visible (front) half.
        let c = Vec3::new(0.0, 0.0, 1.0);
        let gt = uv_sphere(c, 0.1, 40, 80);
        let mut shell = gt.clone();
        for v in &mut shell.vertices {
            if v.z > c.z {
                v.z = c.z + 0.1 * (v.z - c.z);
            }
        }
        let s = score_frame(&shell, &gt, &front_half(c, 0.1), &cfg()).unwrap();
        assert!(s.recall_visible > 0.95, "{s:?}");
        assert!(s.recall < 0.7 && s.fscore < 0.8, "{s:?}");
        assert!(s.depth_ratio < 0.6 && s.volume_ratio < 0.6, "{s:?}");
        // A shifted prediction loses precision and visible recall.
        let mut moved = gt.clone();
        for v in &mut moved.vertices {
            v.x += 0.01;
        }
        let s = score_frame(&moved, &gt, &front_half(c, 0.1), &cfg()).unwrap();
        assert!(s.precision < 0.6 && s.recall_visible < 0.6, "{s:?}");
    }

    #[test]
    fn bad_inputs_are_errors_not_panics() {
        let gt = uv_sphere(Vec3::new(0.0, 0.0, 1.0), 0.1, 8, 16);
        let mut c = cfg();
        c.samples = 0;
        assert!(score_frame(&gt, &gt, &[], &c).is_err());
        let mut c = cfg();
        c.visible_radius = f64::NAN;
        assert!(score_frame(&gt, &gt, &[], &c).is_err());
        assert!(score_frame(&gt, &TriMesh::default(), &[], &cfg()).is_err());
        // No observed point: nothing counted as seen.
        let s = score_frame(&gt, &gt, &[], &cfg()).unwrap();
        assert_eq!(s.visible_fraction, 0.0);
    }
}

/// The cold references of a frame: `repeats` cold starts of `cloud` with
/// the pipeline's cold membrane, taken as the pipeline takes a frame (no
/// deadline, the cold iteration cap), each on another thinning subset
/// ([`crate::pipeline::thinned_subset`]; the first is the pipeline's own). With more
/// than one, their spread measures how reproducible a cold start of the
/// frame is: a single view's unseen side is not determined by the data,
/// and which 2,500 of 20,000 points were kept moves a cold start's F-score
/// by about ±0.02 (synth ellipsoid). A cloud that is not thinned gives
/// `repeats` identical references.
///
/// # Errors
/// The first failing reconstruction's [`crate::membrane::MembraneError`].
pub fn cold_references(
    cloud: &crate::cloud::PointCloud,
    membranes: &crate::pipeline::Membranes,
    pipeline: &crate::pipeline::PipelineConfig,
    repeats: usize,
) -> Result<Vec<crate::membrane::Reconstruction>, crate::membrane::MembraneError> {
    let membrane = &membranes.cold;
    let budget =
        crate::membrane::Budget::iterations(crate::pipeline::cold_cap(membrane.config(), pipeline));
    // As the pipeline takes its frames: without their flying pixels and
    // detached groups, capped.
    let (cloud, _) = crate::pipeline::frame_points(cloud, pipeline);
    let thin = crate::pipeline::thinned(&cloud, pipeline);
    let detached = membranes.detached.as_ref();
    let (cloud, _, _) = crate::pipeline::without_detached(&cloud, thin, detached, None, pipeline);
    (0..repeats as u64)
        .map(|k| {
            let thinned = crate::pipeline::thinned_subset(&cloud, pipeline, k);
            let mut rec = membrane.reconstruct(&thinned, &budget, &crate::membrane::Start::Cold)?;
            // As the pipeline publishes its frames (`membrane.step.unbias`,
            // `pipeline.snap`).
            rec.unbias_mesh();
            crate::pipeline::snap::apply(&mut rec, &cloud.points, false, pipeline.snap.as_ref());
            Ok(rec)
        })
        .collect()
}

/// One frame of one stream of a scored replay ([`replay_scored`]).
#[derive(Debug, Clone)]
pub struct ScoredFrame {
    /// Stream.
    pub key: crate::pipeline::StreamKey,
    /// Stamp of the cloud (ns since the epoch).
    pub stamp_ns: i64,
    /// Points of the stream in the frame.
    pub points: usize,
    /// The pipeline's result (mesh, path, iterations, latency…).
    pub result: crate::pipeline::FrameResult,
    /// Score against the ground truth, when the bag has it for this frame.
    pub score: Option<FrameScore>,
    /// The cold references of the same frame ([`cold_references`]; empty
    /// without them): their iterations and scores.
    pub cold: Vec<(usize, Option<FrameScore>)>,
}

/// Errors of a scored replay.
#[derive(Debug, thiserror::Error)]
pub enum ScoredReplayError {
    /// Reading the bag failed.
    #[error(transparent)]
    Bag(#[from] crate::bag::BagError),
    /// The ground truth is malformed.
    #[error(transparent)]
    Truth(#[from] crate::synth::truth::TruthError),
    /// A sample did not decode.
    #[error(transparent)]
    Sample(#[from] crate::pipeline::engine::SampleError),
    /// The pipeline failed on a frame.
    #[error(transparent)]
    Frame(#[from] crate::pipeline::PipelineError),
    /// The cold reference failed.
    #[error("cold reference: {0}")]
    Cold(#[from] crate::membrane::MembraneError),
    /// The membrane configuration is invalid.
    #[error(transparent)]
    Config(#[from] crate::membrane::ConfigError),
    /// Scoring failed.
    #[error("scoring: {0}")]
    Score(#[from] MetricsError),
}

/// Replay every PointCloud2 of `bag` through the pipeline (one tracker per
/// stream, as `sepmem replay` does) and score every frame that has ground
/// truth; with `cold_repeats > 0`, also reconstruct each frame cold
/// (untimed) that many times ([`cold_references`]).
///
/// # Errors
/// [`ScoredReplayError`] on the first unreadable sample or failed frame.
pub fn replay_scored(
    bag: &crate::bag::Bag,
    cfg: &crate::config::Config,
    cold_repeats: usize,
) -> Result<Vec<ScoredFrame>, ScoredReplayError> {
    use crate::pipeline::engine::Engine;
    let truth = crate::synth::truth::GroundTruthIndex::from_bag(bag)?;
    let sc = ScoreConfig::from_config(cfg);
    let topics: Vec<&str> = bag
        .topics
        .iter()
        .filter(|t| t.type_name == "sensor_msgs/msg/PointCloud2")
        .map(|t| t.name.as_str())
        .collect();
    let mut engine = Engine::new(&cfg.membrane, cfg.pipeline.clone(), cfg.wire.clone())?;
    let mut out = Vec::new();
    for m in bag.read(&topics)? {
        let now = i64::try_from(m.log_time).unwrap_or(i64::MAX);
        let frame = engine.handle(&m.topic, &m.data, None, now)?;
        let stamp_ns = frame.sample.header.stamp.to_nanos();
        for (s, p) in frame.sample.streams.iter().zip(frame.processed) {
            let result = p.outcome?;
            let gt = truth.posed_mesh(&s.key.to_string(), stamp_ns);
            let score = gt
                .as_ref()
                .map(|gt| score_frame(&result.reconstruction.mesh, gt, &s.cloud.points, &sc))
                .transpose()?;
            let cold = cold_references(&s.cloud, &engine.membranes, &cfg.pipeline, cold_repeats)?
                .iter()
                .map(|rec| {
                    let cs = gt
                        .as_ref()
                        .map(|gt| score_frame(&rec.mesh, gt, &s.cloud.points, &sc))
                        .transpose()?;
                    Ok((rec.report.iterations, cs))
                })
                .collect::<Result<Vec<_>, MetricsError>>()?;
            out.push(ScoredFrame {
                key: s.key.clone(),
                stamp_ns,
                points: s.cloud.len(),
                result,
                score,
                cold,
            });
        }
    }
    Ok(out)
}
