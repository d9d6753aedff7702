//! Point density of a cloud (paper §III-A, Eqs. 5 and 6).
//!
//! For every actual point `p_i` the mean distance to its `k` nearest
//! neighbours (itself excluded) is
//!
//! ```text
//! d_i = (1/k) Σ_{j=1..k} ‖p_i − q_j‖₂                       (paper Eq. 5)
//! ```
//!
//! computed once per cloud with the cloud's [`KnnIndex`] (a k-d tree that a
//! caller building one anyway, like the membrane's preparation or the
//! separability filter, passes in with [`Density::from_index`], so that
//! one index serves the density, the outlier filter and the normals). From
//! the `d_i` two spacing
//! estimates δ are derived:
//!
//! * the **global** δ of the whole cloud: the median of the `d_i` by default
//!   (robust to outliers, see the prototype findings), or their mean as the
//!   paper writes it;
//! * the **local** δ_R of a merged region `R = r1 ∪ r2`: the mean of the `d_i`
//!   over the actual points of `R` (paper Eq. 6), see [`Density::local`].
//!
//! δ is the edge of the cube that one point occupies, so `Vol(r)/δ³` is the
//! number of points that a fully occupied region `r` would hold (paper Eq. 4,
//! [`crate::separability::point`]).

use crate::cloud::Vec3;
use crate::spatial::KnnIndex;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors while estimating the density of a cloud.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DensityError {
    /// Fewer than two points: no point has a neighbour.
    #[error("density needs at least 2 points, the cloud has {got}")]
    TooFewPoints {
        /// Points in the cloud.
        got: usize,
    },
    /// `k` must be at least 1.
    #[error("density: k = 0 nearest neighbours is meaningless (use k >= 1)")]
    ZeroK,
    /// A point position is NaN or infinite.
    #[error("density: point {index} is not finite ({point:?})")]
    NonFinite {
        /// Index of the offending point.
        index: usize,
        /// Its coordinates.
        point: [f64; 3],
    },
}

/// How the single global δ of a cloud is taken from the per-point `d_i`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum DeltaEstimator {
    /// Median of the `d_i` (default: robust to outliers).
    #[default]
    Median,
    /// Mean of the `d_i` (the paper's Eq. 6 over the whole cloud).
    Mean,
}

/// The `density` configuration section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DensityConfig {
    /// Number of nearest neighbours `k` in Eq. 5.
    pub k: usize,
    /// Estimator of the global δ: `median` or `mean`.
    pub estimator: DeltaEstimator,
}

impl Default for DensityConfig {
    fn default() -> Self {
        Self {
            k: 8,
            estimator: DeltaEstimator::Median,
        }
    }
}

/// Per-point mean k-NN distances of one cloud, and the δ estimates derived from them.
#[derive(Debug, Clone, PartialEq)]
pub struct Density {
    k: usize,
    per_point: Vec<f64>,
    mean: f64,
    median: f64,
}

impl Density {
    /// Compute `d_i` (Eq. 5) for every point, using `k` neighbours.
    ///
    /// When the cloud has `k` points or fewer, every other point is used
    /// (`k` is clamped to `len − 1`). Runs in parallel over points (rayon).
    ///
    /// # Errors
    /// [`DensityError::TooFewPoints`] for fewer than two points,
    /// [`DensityError::ZeroK`] for `k = 0`, [`DensityError::NonFinite`] for a
    /// NaN/infinite point.
    pub fn new(points: &[Vec3], k: usize) -> Result<Self, DensityError> {
        Self::indexed(points.to_vec(), k).map(|(density, _)| density)
    }

    /// [`Density::new`], and the [`KnnIndex`] of `points` it built, for the
    /// caller's other k-NN queries of the same points (normals).
    ///
    /// # Errors
    /// As [`Density::new`].
    pub fn indexed(points: Vec<Vec3>, k: usize) -> Result<(Self, KnnIndex), DensityError> {
        check(&points, k)?;
        let index = KnnIndex::new(points);
        Ok((Self::from_index(&index, k)?, index))
    }

    /// [`Density::new`] of the points of `index`, with their index.
    ///
    /// # Errors
    /// As [`Density::new`].
    pub fn from_index(index: &KnnIndex, k: usize) -> Result<Self, DensityError> {
        let points = index.points();
        check(points, k)?;
        let k = k.min(points.len() - 1);
        let per_point = knn_mean_distances(index, points, k);
        let mean = per_point.iter().sum::<f64>() / per_point.len() as f64;
        let median = median_of(&per_point);
        Ok(Self {
            k,
            per_point,
            mean,
            median,
        })
    }

    /// The number of neighbours actually used (`k` clamped to `len − 1`).
    pub fn k(&self) -> usize {
        self.k
    }

    /// The per-point mean k-NN distances `d_i`, in the cloud's point order.
    pub fn per_point(&self) -> &[f64] {
        &self.per_point
    }

    /// Mean of all `d_i`.
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Median of all `d_i` (the mean of the two middle values for an even count).
    pub fn median(&self) -> f64 {
        self.median
    }

    /// The global δ by the chosen estimator.
    pub fn global(&self, estimator: DeltaEstimator) -> f64 {
        match estimator {
            DeltaEstimator::Median => self.median,
            DeltaEstimator::Mean => self.mean,
        }
    }

    /// Local δ_R (paper Eq. 6): the mean of `d_i` over the points `indices`
    /// of a merged region R. `None` when `indices` is empty.
    ///
    /// Indices out of range are ignored (they do not belong to this cloud).
    pub fn local<I>(&self, indices: I) -> Option<f64>
    where
        I: IntoIterator,
        I::Item: Into<usize>,
    {
        local_mean(&self.per_point, indices)
    }
}

/// The checks of [`Density::new`]: `k ≥ 1`, two points or more, all finite.
fn check(points: &[Vec3], k: usize) -> Result<(), DensityError> {
    if k == 0 {
        return Err(DensityError::ZeroK);
    }
    if points.len() < 2 {
        return Err(DensityError::TooFewPoints { got: points.len() });
    }
    match points
        .iter()
        .enumerate()
        .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
    {
        Some((index, p)) => Err(DensityError::NonFinite {
            index,
            point: [p.x, p.y, p.z],
        }),
        None => Ok(()),
    }
}

/// Paper Eq. 5 for the points `queries`, with neighbours taken from the
/// points of `index` (`k` nearest, a query point present in the index
/// excluded as its own neighbour at distance 0). The indexed points must be
/// finite and more than `k`; runs in parallel over the queries (rayon).
pub(crate) fn knn_mean_distances(index: &KnnIndex, queries: &[Vec3], k: usize) -> Vec<f64> {
    // k + 1 neighbours include the query point itself (or an exact
    // duplicate of it) at distance 0, which contributes nothing.
    queries
        .par_iter()
        .map(|q| {
            let sum: f64 = index
                .nearest_n(q, k + 1)
                .into_iter()
                .map(|(d2, _)| d2.max(0.0).sqrt())
                .sum();
            sum / k.max(1) as f64
        })
        .collect()
}

/// Mean of `per_point[i]` over `indices` (ignoring out-of-range ones);
/// `None` when no index is valid.
pub(crate) fn local_mean<I>(per_point: &[f64], indices: I) -> Option<f64>
where
    I: IntoIterator,
    I::Item: Into<usize>,
{
    let (mut sum, mut n) = (0.0, 0usize);
    for i in indices {
        if let Some(d) = per_point.get(i.into()) {
            sum += d;
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as f64)
}

/// The upper median of non-empty `values` (the upper one of the middle
/// pair), reordering them in place. The completions' profile rings, axis
/// tilt and misfits (`membrane::revolution`, `membrane::sphere`) use it, not
/// [`median_of`], which averages the middle pair: with that the 39
/// sequences' median last-third F read 0.807, not 0.840.
pub(crate) fn upper_median(values: &mut [f64]) -> f64 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Median of a non-empty slice (mean of the middle pair for even lengths); 0 for empty.
pub(crate) fn median_of(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    let mid = v.len() / 2;
    let (_, upper, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    let upper = *upper;
    if v.len() % 2 == 1 {
        upper
    } else {
        let lower = v[..mid].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn brute_force(points: &[Vec3], k: usize) -> Vec<f64> {
        points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mut d: Vec<f64> = points
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, q)| (p - q).norm())
                    .collect();
                d.sort_by(f64::total_cmp);
                d[..k].iter().sum::<f64>() / k as f64
            })
            .collect()
    }

    fn random_cloud(n: usize, seed: u64) -> Vec<Vec3> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-2.0..2.0),
                    rng.random_range(0.0..0.5),
                )
            })
            .collect()
    }

    #[test]
    fn matches_brute_force_oracle_on_random_clouds() {
        for (seed, n, k) in [(1, 300, 8), (2, 500, 16), (3, 50, 1), (4, 200, 3)] {
            let pts = random_cloud(n, seed);
            let d = Density::new(&pts, k).unwrap();
            let oracle = brute_force(&pts, k);
            for (i, (a, b)) in d.per_point().iter().zip(&oracle).enumerate() {
                assert!((a - b).abs() < 1e-12, "seed {seed} point {i}: {a} vs {b}");
            }
            let mean = oracle.iter().sum::<f64>() / n as f64;
            assert!((d.mean() - mean).abs() < 1e-12);
            let mut sorted = oracle.clone();
            sorted.sort_by(f64::total_cmp);
            let median = if n % 2 == 1 {
                sorted[n / 2]
            } else {
                0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
            };
            assert!((d.median() - median).abs() < 1e-12);
            assert_eq!(d.global(DeltaEstimator::Median), d.median());
            assert_eq!(d.global(DeltaEstimator::Mean), d.mean());
        }
    }

    #[test]
    fn a_shared_index_gives_the_same_density() {
        let pts = random_cloud(300, 5);
        let (d, index) = Density::indexed(pts.clone(), 8).unwrap();
        assert_eq!(index.points(), &pts[..]);
        assert_eq!(d, Density::new(&pts, 8).unwrap());
        assert_eq!(d, Density::from_index(&index, 8).unwrap());
        let sub: Vec<Vec3> = pts.iter().step_by(10).copied().collect();
        let d_sub = knn_mean_distances(&index, &sub, 8);
        for (a, i) in d_sub.iter().zip((0..pts.len()).step_by(10)) {
            assert_eq!(*a, d.per_point()[i]);
        }
        assert!(matches!(
            Density::indexed(vec![Vec3::zeros(), Vec3::new(f64::NAN, 0.0, 0.0)], 1),
            Err(DensityError::NonFinite { index: 1, .. })
        ));
    }

    #[test]
    fn regular_grid_has_spacing_as_density() {
        // Interior points of a unit-spacing cubic lattice have 6 neighbours at 1.
        let mut pts = Vec::new();
        for x in 0..7 {
            for y in 0..7 {
                for z in 0..7 {
                    pts.push(Vec3::new(x as f64, y as f64, z as f64) * 0.5);
                }
            }
        }
        let d = Density::new(&pts, 6).unwrap();
        let centre = (3 * 7 + 3) * 7 + 3;
        assert!((d.per_point()[centre] - 0.5).abs() < 1e-12);
        // A corner has 3 neighbours at 0.5 and 3 at 0.5·√2.
        let corner = (1.5 + 1.5 * 2f64.sqrt()) / 6.0;
        assert!((d.per_point()[0] - corner).abs() < 1e-12);
    }

    #[test]
    fn local_delta_is_mean_over_region_points() {
        let pts = random_cloud(100, 7);
        let d = Density::new(&pts, 8).unwrap();
        let idx = [3usize, 10, 42, 99];
        let want = idx.iter().map(|&i| d.per_point()[i]).sum::<f64>() / 4.0;
        assert!((d.local(idx).unwrap() - want).abs() < 1e-15);
        assert_eq!(d.local(Vec::<usize>::new()), None);
        // Out-of-range indices are ignored.
        assert!((d.local([3usize, 10, 42, 99, 1000]).unwrap() - want).abs() < 1e-15);
        let idx32 = [3u32, 10, 42, 99];
        assert!((d.local(idx32.iter().map(|&i| i as usize)).unwrap() - want).abs() < 1e-15);
    }

    #[test]
    fn small_duplicate_and_bad_clouds() {
        assert_eq!(
            Density::new(&[Vec3::zeros()], 8),
            Err(DensityError::TooFewPoints { got: 1 })
        );
        assert_eq!(
            Density::new(&[Vec3::zeros(), Vec3::x()], 0),
            Err(DensityError::ZeroK)
        );
        assert!(matches!(
            Density::new(&[Vec3::zeros(), Vec3::new(f64::NAN, 0.0, 0.0)], 1),
            Err(DensityError::NonFinite { index: 1, .. })
        ));
        // k larger than the cloud: clamped to len - 1.
        let d = Density::new(&[Vec3::zeros(), Vec3::x() * 2.0, Vec3::x() * 4.0], 8).unwrap();
        assert_eq!(d.k(), 2);
        assert!((d.per_point()[0] - 3.0).abs() < 1e-12);
        assert!((d.per_point()[1] - 2.0).abs() < 1e-12);
        // Many exact duplicates do not break the tree; their d_i is 0.
        let mut pts = vec![Vec3::new(0.5, 0.5, 0.5); 100];
        pts.push(Vec3::zeros());
        let d = Density::new(&pts, 8).unwrap();
        assert_eq!(d.per_point()[0], 0.0);
        assert_eq!(d.median(), 0.0);
    }
}
