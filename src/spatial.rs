//! Nearest-neighbour queries over a fixed point set: an R*-tree (`rstar`)
//! behind one small type, shared by the algorithm (the membrane's pole-axis
//! choice, [`crate::membrane::pole`]) and its evaluation
//! ([`crate::metrics`], replay scoring), so that neither depends on the
//! other.
//!
//! The R*-tree prunes by the exact distance to each node's box, so a query
//! costs O(log n) wherever it lies. kiddo's k-d tree bounds a far query's
//! distance by the last split offset per axis only and visited most of the
//! tree for queries outside it: `eval` of a sphere against the same sphere
//! offset by 10 took 10 s, one triangle against a sphere 36 s.

use crate::cloud::Vec3;
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;

/// An R*-tree over a point set, built once and queried many times.
#[derive(Debug)]
pub struct PointIndex {
    tree: RTree<GeomWithData<[f64; 3], usize>>,
}

impl PointIndex {
    /// Index `points` (which should be finite).
    pub fn new(points: &[Vec3]) -> Self {
        let items = points
            .iter()
            .enumerate()
            .map(|(i, p)| GeomWithData::new([p.x, p.y, p.z], i))
            .collect();
        Self {
            tree: RTree::bulk_load(items),
        }
    }

    /// Distance to, and index of, the indexed point nearest to `q`
    /// (`(∞, 0)` for an empty index).
    pub fn nearest(&self, q: &Vec3) -> (f64, usize) {
        match self.tree.nearest_neighbor(&[q.x, q.y, q.z]) {
            Some(n) => {
                let [x, y, z] = *n.geom();
                ((Vec3::new(x, y, z) - q).norm(), n.data)
            }
            None => (f64::INFINITY, 0),
        }
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
