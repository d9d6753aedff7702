//! Nearest-neighbour queries over a fixed point set, built once and
//! queried many times. Two index types, one per kind of query:
//!
//! - [`KnnIndex`] (a `kiddo` k-d tree): the k nearest neighbours of the
//!   set's own points or of points close to it. One per frame serves the
//!   membrane's density (paper Eqs. 5–6: d_i, δ, local δ_R) and its k-NN
//!   outlier filter ([`crate::membrane`]'s `prepare`), the PCA normals
//!   ([`crate::normals`]) and, built once per stored surface, the warm
//!   start's ICP (`pipeline::align`).
//! - [`PointIndex`] (an R*-tree, `rstar`): the nearest point to queries
//!   that may lie far from the set, shared by the algorithm (the membrane's
//!   pole-axis choice, [`crate::membrane::pole`]) and its evaluation
//!   ([`crate::metrics`], replay scoring), so that neither depends on the
//!   other. The R*-tree prunes by the exact distance to each node's box, so
//!   a query costs O(log n) wherever it lies. kiddo's k-d tree bounds a far
//!   query's distance by the last split offset per axis only and visited
//!   most of the tree for queries outside it: `eval` of a sphere against
//!   the same sphere offset by 10 took 10 s, one triangle against a sphere
//!   36 s.

use crate::cloud::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, DefaultHasher};
use std::num::NonZero;

/// A hash map with fixed keys (SipHash with zero keys), for maps keyed by
/// grid cell whose iteration order reaches an output. The fused model's
/// points come out in its voxel map's order and the membrane's thinning
/// keeps points by index; with std's per-process random keys the same bag
/// gave a differently ordered fused cloud in every run, so replays with
/// `pipeline.model` were not repeatable and the node's model output
/// differed from `replay`'s.
pub type FixedMap<K, V> = HashMap<K, V, BuildHasherDefault<DefaultHasher>>;

/// The integer coordinates of the cell of edge `edge` (cells aligned with
/// the origin) holding `p`.
pub fn cell_key(p: &Vec3, edge: f64) -> [i32; 3] {
    let q = p / edge;
    [q.x.floor() as i32, q.y.floor() as i32, q.z.floor() as i32]
}

/// The offsets of the 26 cells around a cell of a regular 3D grid (its
/// 26-neighbourhood), for grids keyed by integer cell coordinates.
pub const CELL_NEIGHBOURS: [[i32; 3]; 26] = cell_neighbours();

const fn cell_neighbours() -> [[i32; 3]; 26] {
    let mut out = [[0; 3]; 26];
    let (mut i, mut n) = (0, 0);
    while i < 27 {
        if i != 13 {
            out[n] = [i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1];
            n += 1;
        }
        i += 1;
    }
    out
}

/// A k-d tree over a finite point set, for k-nearest-neighbour queries of
/// points in or near the set (see the module docs).
#[derive(Debug, Clone)]
pub struct KnnIndex {
    tree: ImmutableKdTree<f64, 3>,
    points: Vec<Vec3>,
}

impl KnnIndex {
    /// Index `points` (which should be finite); item `i` is `points[i]`.
    pub fn new(points: Vec<Vec3>) -> Self {
        let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        Self {
            tree: ImmutableKdTree::new_from_slice(&coords),
            points,
        }
    }

    /// The indexed points, in their item order.
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether no point is indexed.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The `n` (at least 1) indexed points nearest to `q`, nearest first,
    /// as (squared distance, index); fewer when the set holds fewer. One
    /// allocation (kiddo's result, reused in place).
    pub fn nearest_n(&self, q: &Vec3, n: usize) -> Vec<(f64, usize)> {
        if self.is_empty() {
            return Vec::new();
        }
        let qty = NonZero::new(n).unwrap_or(NonZero::<usize>::MIN);
        self.tree
            .nearest_n::<SquaredEuclidean>(&[q.x, q.y, q.z], qty)
            .into_iter()
            .map(|nn| (nn.distance, nn.item as usize))
            .collect()
    }

    /// Squared distance to, and index of, the indexed point nearest to `q`
    /// (`(∞, 0)` for an empty index).
    pub fn nearest_one(&self, q: &Vec3) -> (f64, usize) {
        if self.is_empty() {
            return (f64::INFINITY, 0);
        }
        let nn = self.tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z]);
        (nn.distance, nn.item as usize)
    }
}

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

    /// `n` deterministic points spread over [-1, 1]² × [0, 1).
    fn spread(n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|k| {
                let t = k as f64;
                Vec3::new((t * 0.37).sin(), (t * 0.91).cos(), (t * 0.13).fract())
            })
            .collect()
    }

    #[test]
    fn knn_index_matches_a_brute_force_scan() {
        let pts = spread(400);
        let index = KnnIndex::new(pts.clone());
        assert_eq!((index.len(), index.points()), (pts.len(), &pts[..]));
        for q in pts.iter().step_by(7).chain(&[Vec3::new(0.3, -2.0, 0.5)]) {
            let mut brute: Vec<(f64, usize)> = pts
                .iter()
                .enumerate()
                .map(|(j, p)| ((p - q).norm_squared(), j))
                .collect();
            brute.sort_by(|a, b| a.0.total_cmp(&b.0));
            let got = index.nearest_n(q, 9);
            assert_eq!(got.len(), 9);
            for (g, b) in got.iter().zip(&brute) {
                assert!((g.0 - b.0).abs() < 1e-12, "{g:?} vs {b:?}");
                assert!(((pts[g.1] - q).norm_squared() - g.0).abs() < 1e-12);
            }
            let (d2, i) = index.nearest_one(q);
            assert!((d2 - brute[0].0).abs() < 1e-12 && (pts[i] - q).norm_squared() == d2);
        }
        // More neighbours than points: all of them; an empty index: none.
        assert_eq!(
            KnnIndex::new(pts[..3].to_vec()).nearest_n(&pts[0], 8).len(),
            3
        );
        let empty = KnnIndex::new(Vec::new());
        assert!(empty.is_empty() && empty.nearest_n(&pts[0], 4).is_empty());
        assert_eq!(empty.nearest_one(&pts[0]), (f64::INFINITY, 0));
    }

    #[test]
    fn nearest_matches_a_brute_force_scan() {
        let pts = spread(500);
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
