//! The density-robust point spacing of the separability search
//! (`membrane.prepare.local_spacing`): the non-data counts of a cuboid's
//! regions from the spacing of the points near it, not from one global δ.
//!
//! Eq. 4 estimates the non-data points of a region `r` as
//! `⌊Vol(r)/δ³⌋ − o_r`. With one global δ (Eq. 5, taken from the dense part of
//! the cloud) a surface sampled more thinly than δ reads as mostly empty
//! space: its samples fail the dense-side significance of the shift rule
//! ([`super::step`]) and the membrane stays off it. The paper's remedy is
//! the local δ_R of the merged region `R = r1 ∪ r2` (Eq. 6: the mean of the
//! `d_i` over the points of `R`, `prepare.search_delta = "local"`); on its
//! own it changes the calibration (the global δ is `delta_scale` × a
//! quantile of the `d_i`, not their mean) and follows every fluctuation of
//! the `d_i` of uniform clouds.
//!
//! Here each used point gets a spacing
//!
//! ```text
//! δ_i = δ · max(1, m_i / (t · m))
//! ```
//!
//! with δ the global spacing, `m` the median of all `d_i`, `m_i` the
//! median of the `d_i` of the point's `neighbours` nearest points (itself
//! included) and `t ≥ 1` the `tolerance`: the global δ scaled by how much sparser the point's
//! neighbourhood is than the cloud's typical one, never below δ. The search
//! then takes δ_R as the mean of `δ_i` over the points of `R` (the form of
//! Eq. 6). On a uniformly sampled surface `m_i ≈ m`, so δ_R stays close to
//! the global δ and today's calibration holds; where the density falls, δ_R
//! grows with the spacing.
//!
//! The same holds for the outlier filter of [`super::prepare`] (a point is
//! an outlier when its d_i exceeds `outlier_factor` × the median d_i): at
//! 8:1 the sparsest end's d_i lie just above twice the median, so the
//! filter cut a hole there, the occupancy grid of the inward force
//! ([`super::occupancy`]) leaked through it and the inward force flattened
//! that end (a non-uniform sphere: F 0.66; 1.00 without the filter). With the
//! local spacing a dropped point is kept again when its d_i is within
//! `outlier_factor` of its kept neighbours' (grown from the globally kept
//! points, [`kept_relative`]), and the
//! occupancy grid counts each point for the area it samples, `(δ_i/δ)²`.
//!
//! Measured (`sepmem bench --only table1 --datasets ../shared/datasets`,
//! seed 20250307, 18 shapes, 20,000 points), against the global δ:
//!
//! | tolerance | non-uniform F, genus 0 / > 0 | paper's four conditions, ΔF range |
//! |---|---|---|
//! | off | 0.636 / 0.531 | — |
//! | 1.0 | 0.930 / 0.806 | −0.0066 (surface outliers, genus > 0: the mug −0.025) … +0.0034 |
//! | **1.25** (default) | 0.916 / 0.802 | −0.0018 … +0.0047 |
//! | 1.5 | 0.897 / 0.742 | −0.0014 … +0.0047 |
//!
//! (uniform original: 0.948 / 0.857). Re-measured at c1a5e09 (same seed):
//! tolerance 1.0 gave 0.929 / 0.806, but surface outliers (genus > 0) 0.840
//! -> 0.831, and on the 45 sensor-true sequences of
//! `benches/robot_view_eval.sh` a mean last-third F of 0.823 against 0.830
//! (11 up, 17 down; the 360° ellipsoid 0.938 -> 0.712).
//!
//! With `m` the statistic a whole object's δ is taken from (the lower
//! quartile of the `d_i`, δ being 1.3 times it) instead of the median, the
//! sparse end's δ_R follows its own spacing by the global rule: non-uniform
//! F, genus 0, 0.916 -> 0.931, 0.911 -> 0.929 and 0.916 -> 0.932 over three
//! samplings (seeds 20250307, 7, 11; the fandisk 0.707 -> 0.831, the YCB
//! banana 0.887 -> 0.971), the paper's four conditions within −0.005 …
//! +0.006 but one (surface outliers, genus > 0, seed 7: −0.011). It was not
//! kept: neighbourhoods of an outlier shell grew δ_R too, and the sphere
//! sweep fell at σ 0.2 (0.974 -> 0.887) and 0.5 (0.892 -> 0.836), and
//! two tests of `tests/membrane.rs` fell below their bounds: the sphere at
//! σ 0.2 to 0.943 (0.95) and the uniform mug to 0.746 (0.75). With tolerance 1.5 beside it the sweep held (its
//! least F 0.923) but the gain went (seed 7: 0.913, surface outliers,
//! genus > 0, 0.854 -> 0.812).
//!
//! The paper's local δ_R alone
//! (`search_delta = "local"`) gave 0.691 / 0.602 on the non-uniform
//! condition: the filter's hole and the occupancy leak remain.
//!
//! On single views (`sepmem synth --motion turn|orbit --degrees 180 --frames
//! 30 --noise kinect`, seeds 4 and 7; mug, rounded box, bottle, ellipsoid,
//! torus, YCB banana: 12 sequences, `sepmem replay` defaults), tolerance 1.25
//! against off: the last third's whole-object F changes by a median of
//! +0.013 (9 of 12 up) and the median seen-side depth accuracy by +0.014
//! (9 of 12 up; the turning ellipsoid −0.108). Tolerance 1.0 scored higher
//! on the turning objects but lost the orbiting box's tracking (F 0.166 ->
//! 0.153 where 1.25 reached 0.488), through more failed warm starts.
//!
//! In the weighted mode (paper Eq. 9: `step.attributes`, or a spatial
//! weight other than 1) the search keeps the global δ and unit occupancy
//! counts; only the relative outlier filter applies. There the attribute
//! term separates layers of like density, and evening out their spatial
//! density works against it: a white sphere inside a dark clutter shell
//! 1.2× wider with as many points (`tests/membrane.rs`) gave weighted F
//! 0.894 with the local δ_R and 0.907 without.

use super::config::LocalSpacingConfig;
use crate::cloud::Vec3;
use crate::density::median_of;
use crate::spatial::KnnIndex;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZero;

/// The per-point spacing `δ_i` of the used `points` (see the module docs)
/// from their `d_i` (`d`, parallel to `points`), the global `delta`, the
/// neighbourhood size `cfg.neighbours` (clamped to the cloud) and
/// `cfg.tolerance` (`m` is taken times it). Empty when `points` is empty.
pub(crate) fn local_spacing(
    points: &[Vec3],
    d: &[f64],
    delta: f64,
    cfg: &LocalSpacingConfig,
) -> Vec<f64> {
    let neighbours = cfg.neighbours;
    let m = median_of(d) * cfg.tolerance;
    if points.is_empty() || d.len() != points.len() || !(m > 0.0 && m.is_finite()) {
        return vec![delta; points.len()];
    }
    let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&coords);
    let qty = NonZero::new(neighbours.clamp(1, points.len())).unwrap_or(NonZero::<usize>::MIN);
    coords
        .par_iter()
        .map_init(Vec::new, |near: &mut Vec<f64>, q| {
            near.clear();
            near.extend(
                tree.nearest_n::<SquaredEuclidean>(q, qty)
                    .iter()
                    .filter_map(|nn| d.get(nn.item as usize)),
            );
            let m_i = median_of(near);
            delta * (m_i / m).max(1.0)
        })
        .collect()
}

/// Passes of [`kept_relative`]'s growth from the globally kept points.
const RELATIVE_PASSES: usize = 16;

/// The outlier filter made density-relative: `keep[i]` for the points of
/// `points` whose `d_i` (`d`) is at most `limit` (the global rule,
/// `outlier_factor` × the median d_i), and, grown from them pass by pass
/// (at most [`RELATIVE_PASSES`]), for those whose `d_i` is at most `factor`
/// × the median d_j of their kept neighbours (among the `neighbours`
/// nearest points, when at least half of them are kept): a point as sparse
/// as the kept surface around it is part of that surface, not an outlier.
/// Outliers near a surface (their kept neighbours have the surface's
/// spacing) and in empty space (too few kept neighbours) stay dropped.
/// Growth needs half of a point's neighbours kept, so it fills holes and
/// frays at the end of a density gradient but stalls at a long frontier:
/// on a unit square whose density falls 32:1 the sparsest tenth stayed
/// mostly dropped (9 of 72 points kept; the unit test uses 8:1, the bench
/// condition).
pub(crate) fn kept_relative(
    index: &KnnIndex,
    d: &[f64],
    limit: f64,
    factor: f64,
    neighbours: usize,
) -> Vec<bool> {
    let mut keep: Vec<bool> = d.iter().map(|&v| v <= limit).collect();
    let points = index.points();
    if points.len() != d.len() || keep.iter().all(|&k| k) {
        return keep;
    }
    let qty = (neighbours + 1).min(points.len());
    let need = neighbours.div_ceil(2).max(1);
    let near: Vec<(usize, Vec<usize>)> = (0..points.len())
        .into_par_iter()
        .filter(|&i| !keep[i])
        .map(|i| {
            let nn = index.nearest_n(&points[i], qty);
            let others = nn.iter().map(|&(_, j)| j).filter(|&j| j != i);
            (i, others.collect())
        })
        .collect();
    let mut buf = Vec::new();
    for _ in 0..RELATIVE_PASSES {
        let grown: Vec<usize> = near
            .iter()
            .filter(|(i, _)| !keep[*i])
            .filter(|(i, nn)| {
                buf.clear();
                buf.extend(nn.iter().filter(|&&j| keep[j]).map(|&j| d[j]));
                buf.len() >= need && d[*i] <= factor * median_of(&buf)
            })
            .map(|(i, _)| *i)
            .collect();
        if grown.is_empty() {
            break;
        }
        for i in grown {
            keep[i] = true;
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::density::Density;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Points on the unit square (z = 0) with density ∝ ratio^(−x).
    fn falling(n: usize, ratio: f64, seed: u64) -> Vec<Vec3> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let (x, y): (f64, f64) = (rng.random(), rng.random());
            if rng.random::<f64>() < ratio.powf(-x) {
                out.push(Vec3::new(x, y, 0.0));
            }
        }
        out
    }

    fn field(points: &[Vec3]) -> (Vec<f64>, f64) {
        let d = Density::new(points, 8).unwrap();
        let delta = d.median();
        let cfg = LocalSpacingConfig::default();
        (local_spacing(points, d.per_point(), delta, &cfg), delta)
    }

    #[test]
    fn uniform_points_keep_about_the_global_spacing() {
        let pts = falling(8000, 1.0, 1);
        let (f, delta) = field(&pts);
        assert!(f.iter().all(|&v| v >= delta));
        let mean = f.iter().sum::<f64>() / f.len() as f64;
        assert!(mean < 1.08 * delta, "mean {mean} vs δ {delta}");
    }

    #[test]
    fn the_spacing_follows_a_falling_density() {
        // Density 8:1 from x = 0 to x = 1: the spacing grows by √8.
        let pts = falling(8000, 8.0, 2);
        let (f, delta) = field(&pts);
        let mean_where = |lo: f64, hi: f64| {
            let v: Vec<f64> = pts
                .iter()
                .zip(&f)
                .filter(|(p, _)| p.x >= lo && p.x < hi)
                .map(|(_, &v)| v)
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        // The dense end is clamped at δ (the median's spacing); the sparse
        // end grows by its spacing over the median's, √8^(0.95 − 0.28) ≈ 2.0
        // (the median point lies at x ≈ 0.28), over the tolerance.
        let (dense, sparse) = (mean_where(0.0, 0.1), mean_where(0.9, 1.0));
        assert!(dense < 1.05 * delta, "dense end {dense} vs δ {delta}");
        let grown = sparse / dense * LocalSpacingConfig::default().tolerance;
        assert!(
            grown > 1.6 && grown < 2.6,
            "sparse/dense spacing × tolerance {grown}"
        );
    }

    #[test]
    fn the_relative_filter_keeps_a_sparse_end_and_drops_isolated_points() {
        // Density 8:1 along x: the sparse end's d_i lie about twice the median.
        let mut pts = falling(6000, 8.0, 3);
        // Isolated outliers well above the square.
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let outliers = 100;
        for _ in 0..outliers {
            pts.push(Vec3::new(
                rng.random_range(0.0..1.0),
                rng.random_range(0.0..1.0),
                rng.random_range(0.3..1.0),
            ));
        }
        let d = Density::new(&pts, 8).unwrap();
        let limit = 2.0 * d.median();
        let keep = kept_relative(&KnnIndex::new(pts.clone()), d.per_point(), limit, 2.0, 32);
        let sparse_end =
            |k: &dyn Fn(usize) -> bool| (0..6000).filter(|&i| pts[i].x > 0.9 && k(i)).count();
        let global = sparse_end(&|i| d.per_point()[i] <= limit);
        let relative = sparse_end(&|i| keep[i]);
        let all = sparse_end(&|_| true);
        assert!(global < all, "global rule kept {global} of {all}");
        assert!(
            relative > global && relative >= all * 97 / 100,
            "relative rule kept {relative} of {all} (global {global})"
        );
        assert!((0..6000).all(|i| keep[i] || d.per_point()[i] > limit));
        let kept_outliers = keep[6000..].iter().filter(|&&k| k).count();
        assert!(kept_outliers <= 2, "{kept_outliers} isolated outliers kept");
    }

    #[test]
    fn degenerate_inputs_give_the_global_spacing() {
        let cfg = LocalSpacingConfig::default();
        assert!(local_spacing(&[], &[], 0.1, &cfg).is_empty());
        let pts = [Vec3::zeros(), Vec3::x()];
        assert_eq!(local_spacing(&pts, &[0.0, 0.0], 0.1, &cfg), vec![0.1, 0.1]);
        assert_eq!(local_spacing(&pts, &[1.0], 0.1, &cfg), vec![0.1, 0.1]);
    }
}
