//! The reasons under which the node counts what it refused, discarded or
//! could not deliver, one counter per reason in `/diagnostics`.
//!
//! Each hostile input found when the node was attacked (issue 22) lands
//! under a reason of its own, so an operator can tell a buggy segmenter
//! (`objects_skipped`, `labels_evicted`, `labels_reidentified`) from a broken bridge
//! (`malformed_cdr`), a size lie (`too_large`, `invalid_layout`) or an
//! overloaded node (`over_budget`, `outputs_failed`, `drops`), and a fused
//! model that keeps being discarded (`models_restarted`), clouds
//! published outside the camera's frame (`not_an_image`) and a machine too
//! busy for the fused model's background rebuilds (`rebuilds_starved`). Counters are
//! plain `u64` sums per stream; the node status adds them over all streams,
//! evicted ones included.

use crate::pipeline::engine::SampleError;
use crate::wire::pointcloud2::PointCloud2Error;

/// Bytes that are not a CDR `PointCloud2` (truncated, bad encapsulation,
/// lengths past the end).
pub const MALFORMED_CDR: &str = "malformed_cdr";
/// A cloud over `wire.max_points` / `wire.max_bytes`.
pub const TOO_LARGE: &str = "too_large";
/// A CDR-valid cloud whose layout is inconsistent or unsupported (fields
/// outside the point, a row step or data length that does not match, a
/// field count no point can hold …): the poisoned PointCloud2s.
pub const INVALID_LAYOUT: &str = "invalid_layout";
/// Objects of a frame beyond `pipeline.objects.max_per_frame` (the smallest
/// segments), not evolved.
pub const OBJECTS_SKIPPED: &str = "objects_skipped";
/// Per-label trackers freed after `pipeline.objects.forget_after_ms` of
/// silence or because `pipeline.objects.max_tracked` were held.
pub const LABELS_EVICTED: &str = "labels_evicted";
/// Labels new to their stream that continued an object whose label had
/// just gone (`pipeline.objects.reidentify`): its tracker was taken over.
pub const LABELS_REIDENTIFIED: &str = "labels_reidentified";
/// Object frames whose surface did not converge (published with their
/// verdict, or replaced by the object's last good mesh).
pub const UNFITTED: &str = "unfitted";
/// Frames the stream was not given compute for, because it used more than
/// its share of the compute pool (`node.compute_share`).
pub const OVER_BUDGET: &str = "over_budget";
/// Output messages that could not be encoded or published.
pub const OUTPUTS_FAILED: &str = "outputs_failed";
/// Object frames that failed in the pipeline (too few points, membrane error).
pub const OBJECT_ERRORS: &str = "object_errors";
/// Object frames whose view saw through more than `pipeline.model.reset_share`
/// of the object's fused model, which was discarded and restarted from
/// that view: the object changed or was swapped, or a view disagreed
/// with what earlier views had fused. A tracker that keeps restarting its
/// model never completes the object's unseen side.
pub const MODELS_RESTARTED: &str = "models_restarted";
/// Object frames whose cloud was not one depth image seen from its frame's
/// origin: the flying-pixel filter kept every point and the fused model
/// took a wrong camera position (publish the cloud in the camera's optical
/// frame).
pub const NOT_AN_IMAGE: &str = "not_an_image";

/// Object frames that found their stream's background rebuild of the fused
/// model (`pipeline.rebuild`) starved at the lowest priority and restarted
/// it at a higher one: the machine has no idle time for the rebuilds, and
/// the object's surface follows the fused model later than it could.
pub const REBUILDS_STARVED: &str = "rebuilds_starved";

/// Every reason, in the order `/diagnostics` lists them.
pub const ALL: [&str; 13] = [
    MALFORMED_CDR,
    TOO_LARGE,
    INVALID_LAYOUT,
    OBJECTS_SKIPPED,
    LABELS_EVICTED,
    LABELS_REIDENTIFIED,
    UNFITTED,
    OVER_BUDGET,
    OUTPUTS_FAILED,
    OBJECT_ERRORS,
    MODELS_RESTARTED,
    NOT_AN_IMAGE,
    REBUILDS_STARVED,
];

/// The reason a sample was rejected.
pub fn of_sample_error(e: &SampleError) -> &'static str {
    match e {
        SampleError::Invalid { source, .. } => of_cloud_error(source),
    }
}

/// The reason a `PointCloud2` was rejected.
pub fn of_cloud_error(e: &PointCloud2Error) -> &'static str {
    match e {
        PointCloud2Error::Cdr(_) => MALFORMED_CDR,
        PointCloud2Error::TooManyPoints { .. } | PointCloud2Error::TooManyBytes { .. } => TOO_LARGE,
        _ => INVALID_LAYOUT,
    }
}

/// Add `n` to the counter of `reason` in a list of `(reason, count)`.
pub fn bump(counts: &mut Vec<(&'static str, u64)>, reason: &'static str, n: u64) {
    if n == 0 {
        return;
    }
    match counts.iter_mut().find(|(r, _)| *r == reason) {
        Some((_, c)) => *c += n,
        None => counts.push((reason, n)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bump_adds_up_per_reason_and_ignores_zero() {
        let mut c = Vec::new();
        bump(&mut c, TOO_LARGE, 2);
        bump(&mut c, MALFORMED_CDR, 0);
        bump(&mut c, TOO_LARGE, 3);
        bump(&mut c, MALFORMED_CDR, 1);
        assert_eq!(c, vec![(TOO_LARGE, 5), (MALFORMED_CDR, 1)]);
    }

    #[test]
    fn cloud_errors_map_to_their_reason() {
        let big = PointCloud2Error::TooManyBytes { bytes: 2, max: 1 };
        assert_eq!(of_cloud_error(&big), TOO_LARGE);
        let layout = PointCloud2Error::RowStep {
            row_step: 1,
            width: 2,
            point_step: 3,
        };
        assert_eq!(of_cloud_error(&layout), INVALID_LAYOUT);
        let cdr = PointCloud2Error::Cdr(crate::wire::WireError::UnknownType("x".into()));
        assert_eq!(of_cloud_error(&cdr), MALFORMED_CDR);
    }
}
