//! Nearest-neighbour queries over a fixed point set: a `kiddo` kd-tree
//! behind one small type, shared by the algorithm (the membrane's pole-axis
//! choice, [`crate::membrane::pole`]) and its evaluation
//! ([`crate::metrics`], replay scoring), so that neither depends on the
//! other.

use crate::cloud::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// A kd-tree over a point set, built once and queried many times.
#[derive(Debug)]
pub struct PointIndex {
    tree: ImmutableKdTree<f64, 3>,
}

impl PointIndex {
    /// Index `points` (which should be finite).
    pub fn new(points: &[Vec3]) -> Self {
        let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        Self {
            tree: ImmutableKdTree::new_from_slice(&coords),
        }
    }

    /// Distance to, and index of, the indexed point nearest to `q`.
    pub fn nearest(&self, q: &Vec3) -> (f64, usize) {
        let nn = self.tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z]);
        (nn.distance.max(0.0).sqrt(), nn.item as usize)
    }

    /// [`Self::nearest`] of every query, in parallel (rayon).
    pub fn nearest_all(&self, queries: &[Vec3]) -> Vec<(f64, usize)> {
        queries.par_iter().map(|q| self.nearest(q)).collect()
    }
}

/// For every query point, the distance to and the index of its nearest
/// reference point (one [`PointIndex`] of `reference`).
pub fn nearest(reference: &[Vec3], queries: &[Vec3]) -> Vec<(f64, usize)> {
    PointIndex::new(reference).nearest_all(queries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_matches_a_brute_force_scan() {
        let pts: Vec<Vec3> = (0..500)
            .map(|k| {
                let t = k as f64;
                Vec3::new((t * 0.37).sin(), (t * 0.91).cos(), (t * 0.13).fract())
            })
            .collect();
        let queries: Vec<Vec3> = (0..50)
            .map(|k| Vec3::new(k as f64 * 0.03 - 0.7, 0.2, 0.5))
            .collect();
        for (q, (d, i)) in queries.iter().zip(nearest(&pts, &queries)) {
            let (bd, bi) = pts
                .iter()
                .enumerate()
                .map(|(j, p)| ((p - q).norm(), j))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            assert!(
                (d - bd).abs() < 1e-12 && (pts[i] - q).norm() - bd < 1e-12,
                "{i} vs {bi}"
            );
        }
    }
}
