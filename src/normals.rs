//! Per-point normal estimation by local principal component analysis.
//!
//! The normal of a point is the eigenvector of the smallest eigenvalue of the
//! covariance of its `k` nearest neighbours (itself included), found with the
//! cloud's [`KnnIndex`], the same index that serves its density (paper
//! §III-A, [`crate::density::Density::from_index`]). The sign is not
//! oriented: the separability of two regions (paper Eq. 7) is symmetric in
//! `r1 ↔ r2`, so the separability filter (`--direction normal`) does not need
//! it. Runs in parallel over points (rayon).

use crate::cloud::Vec3;
use crate::spatial::KnnIndex;
use nalgebra::{Matrix3, SymmetricEigen};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors of the normal estimation.
#[derive(Debug, Error, PartialEq)]
pub enum NormalsError {
    /// Fewer than three points: no plane can be fitted.
    #[error("normal estimation needs at least 3 points, got {got}")]
    TooFewPoints {
        /// Points given.
        got: usize,
    },
    /// `k` below 3.
    #[error("normal estimation needs k >= 3 neighbours, got {k}")]
    SmallK {
        /// The `k` given.
        k: usize,
    },
    /// A NaN or infinite coordinate.
    #[error("point {index} is not finite")]
    NonFinite {
        /// Index of the point.
        index: usize,
    },
}

/// How many nearest neighbours give a point's normal: at least 3 (a
/// plane), checked when the configuration is parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "usize", into = "usize")]
pub struct NeighbourCount(usize);

impl NeighbourCount {
    /// The count.
    pub fn get(self) -> usize {
        self.0
    }
}

impl Default for NeighbourCount {
    /// 20 neighbours.
    fn default() -> Self {
        Self(20)
    }
}

impl TryFrom<usize> for NeighbourCount {
    type Error = String;

    fn try_from(k: usize) -> Result<Self, Self::Error> {
        if k >= 3 {
            Ok(Self(k))
        } else {
            Err(format!("{k} neighbours cannot give a normal (at least 3)"))
        }
    }
}

impl From<NeighbourCount> for usize {
    fn from(k: NeighbourCount) -> Self {
        k.0
    }
}

/// Unit normal of every point from its `k` nearest neighbours (`k` is clamped
/// to the cloud size). A degenerate neighbourhood (all neighbours on one
/// point) gets the z axis.
///
/// # Errors
/// [`NormalsError`] for fewer than 3 points, `k < 3` or a non-finite point.
pub fn estimate_normals(points: &[Vec3], k: usize) -> Result<Vec<Vec3>, NormalsError> {
    check(points, k)?;
    estimate_normals_from(&KnnIndex::new(points.to_vec()), k)
}

/// [`estimate_normals`] of the points of `index`, with their index.
///
/// # Errors
/// As [`estimate_normals`].
pub fn estimate_normals_from(index: &KnnIndex, k: usize) -> Result<Vec<Vec3>, NormalsError> {
    let points = index.points();
    check(points, k)?;
    let qty = k.min(points.len());
    Ok(points
        .par_iter()
        .map(|q| normal_at(index, q, qty))
        .collect())
}

/// [`estimate_normals_from`] at the points of `index` whose entry in
/// `wanted` is true; the others get the zero vector. `wanted` shorter than
/// the points leaves the rest out.
///
/// # Errors
/// As [`estimate_normals`].
pub fn estimate_normals_where(
    index: &KnnIndex,
    k: usize,
    wanted: &[bool],
) -> Result<Vec<Vec3>, NormalsError> {
    let mut normals = NormalsOnDemand::new(index, k)?;
    normals.cover(wanted);
    Ok(normals.normals)
}

/// The normals of an index's points, each estimated the first time it is
/// asked for and then kept (the zero vector until then): a registration
/// in passes on the same points (a coarse one, then a finer one on more of
/// a frame's points, `pipeline.model_icp.refine`) estimates each point's
/// normal once. A `prior` may know some normals already (those kept from
/// earlier frames, `pipeline.model_icp.keep_normals`); those are taken
/// as they are.
pub struct NormalsOnDemand<'a> {
    index: &'a KnnIndex,
    qty: usize,
    normals: Vec<Vec3>,
    known: Vec<bool>,
    prior: Option<&'a dyn Fn(usize) -> Option<Vec3>>,
    estimated: Vec<usize>,
}

impl<'a> NormalsOnDemand<'a> {
    /// No normal yet of the points of `index`, each to come from its `k`
    /// nearest points.
    ///
    /// # Errors
    /// As [`estimate_normals`].
    pub fn new(index: &'a KnnIndex, k: usize) -> Result<Self, NormalsError> {
        let points = index.points();
        check(points, k)?;
        Ok(Self {
            index,
            qty: k.min(points.len()),
            normals: vec![Vec3::zeros(); points.len()],
            known: vec![false; points.len()],
            prior: None,
            estimated: Vec::new(),
        })
    }

    /// Take point `i`'s normal from `prior(i)` where it gives one.
    pub fn with_prior(self, prior: &'a dyn Fn(usize) -> Option<Vec3>) -> Self {
        Self {
            prior: Some(prior),
            ..self
        }
    }

    /// The indexed points.
    pub fn index(&self) -> &'a KnnIndex {
        self.index
    }

    /// Give a normal to the points whose entry in `wanted` is true and
    /// that have none yet: the prior's, or one estimated (in parallel).
    pub fn cover(&mut self, wanted: &[bool]) {
        let wanted = wanted.iter().enumerate().filter(|(_, w)| **w);
        self.cover_points(wanted.map(|(i, _)| i));
    }

    /// [`Self::cover`] of the points `indices` (out-of-range ones left out).
    pub fn cover_points(&mut self, indices: impl IntoIterator<Item = usize>) {
        let mut todo = Vec::new();
        for i in indices {
            if self.known.get(i) != Some(&false) {
                continue;
            }
            self.known[i] = true;
            match self.prior.and_then(|p| p(i)) {
                Some(n) => self.normals[i] = n,
                None => todo.push(i),
            }
        }
        let (index, qty) = (self.index, self.qty);
        let found: Vec<Vec3> = todo
            .par_iter()
            .map(|&i| normal_at(index, &index.points()[i], qty))
            .collect();
        for (&i, n) in todo.iter().zip(found) {
            self.normals[i] = n;
        }
        self.estimated.extend(todo);
    }

    /// Every point's normal: the zero vector where none was asked for.
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// The points whose normal was estimated (not the prior's), with it.
    pub fn estimated(&self) -> impl Iterator<Item = (usize, Vec3)> + '_ {
        self.estimated.iter().map(|&i| (i, self.normals[i]))
    }
}

impl std::fmt::Debug for NormalsOnDemand<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NormalsOnDemand")
            .field("points", &self.known.len())
            .field("known", &self.known.iter().filter(|k| **k).count())
            .field("estimated", &self.estimated.len())
            .finish()
    }
}

/// The unit normal at `q` from its `qty` nearest points of `index`.
fn normal_at(index: &KnnIndex, q: &Vec3, qty: usize) -> Vec3 {
    let points = index.points();
    let nn = index.nearest_n(q, qty);
    let mut mean = Vec3::zeros();
    for &(_, m) in &nn {
        mean += points[m];
    }
    mean /= nn.len() as f64;
    let mut cov = Matrix3::<f64>::zeros();
    for &(_, m) in &nn {
        let d = points[m] - mean;
        cov += d * d.transpose();
    }
    smallest_eigenvector(cov)
}

/// The checks of [`estimate_normals`]: `k ≥ 3`, three points or more, all finite.
fn check(points: &[Vec3], k: usize) -> Result<(), NormalsError> {
    if k < 3 {
        return Err(NormalsError::SmallK { k });
    }
    if points.len() < 3 {
        return Err(NormalsError::TooFewPoints { got: points.len() });
    }
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(index) => Err(NormalsError::NonFinite { index }),
        None => Ok(()),
    }
}

/// Unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix
/// (the z axis when the matrix is zero or not finite).
fn smallest_eigenvector(cov: Matrix3<f64>) -> Vec3 {
    if !cov.iter().all(|c| c.is_finite()) || cov.abs().max() == 0.0 {
        return Vec3::z();
    }
    let eig = SymmetricEigen::new(cov);
    let i = eig.eigenvalues.imin();
    let v: Vec3 = eig.eigenvectors.column(i).into_owned();
    let norm = v.norm();
    if norm > 0.0 && norm.is_finite() {
        v / norm
    } else {
        Vec3::z()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_normals_are_radial_and_plane_normals_vertical() {
        let pts = crate::shapes::fibonacci_sphere(2000);
        let normals = estimate_normals(&pts, 10).unwrap();
        let worst = pts
            .iter()
            .zip(&normals)
            .map(|(p, n)| n.dot(p).abs())
            .fold(1.0f64, f64::min);
        assert!(worst > 0.98, "least radial normal |cos| = {worst}");
        let plane: Vec<Vec3> = (0..400)
            .map(|i| Vec3::new(f64::from(i % 20), f64::from(i / 20), 0.0))
            .collect();
        for n in estimate_normals(&plane, 8).unwrap() {
            assert!((n.z.abs() - 1.0).abs() < 1e-9, "{n:?}");
        }
    }

    #[test]
    fn only_the_wanted_points_get_a_normal() {
        let pts = crate::shapes::fibonacci_sphere(500);
        let index = KnnIndex::new(pts);
        let all = estimate_normals_from(&index, 10).unwrap();
        let wanted: Vec<bool> = (0..400).map(|i| i % 3 == 0).collect();
        let some = estimate_normals_where(&index, 10, &wanted).unwrap();
        assert_eq!(some.len(), all.len());
        for (i, (n, m)) in some.iter().zip(&all).enumerate() {
            if wanted.get(i) == Some(&true) {
                assert_eq!(n, m, "point {i}");
            } else {
                assert_eq!(*n, Vec3::zeros(), "point {i}");
            }
        }
        assert_eq!(
            NeighbourCount::try_from(2),
            Err("2 neighbours cannot give a normal (at least 3)".to_string())
        );
    }

    #[test]
    fn normals_on_demand_are_estimated_once_and_kept() {
        let index = KnnIndex::new(crate::shapes::fibonacci_sphere(500));
        let all = estimate_normals_from(&index, 10).unwrap();
        let mut lazy = NormalsOnDemand::new(&index, 10).unwrap();
        let first: Vec<bool> = (0..500).map(|i| i % 3 == 0).collect();
        let second: Vec<bool> = (0..500).map(|i| i % 2 == 0).collect();
        lazy.cover(&first);
        let after_first = lazy.normals().to_vec();
        lazy.cover(&second);
        for (i, (n, m)) in lazy.normals().iter().zip(&all).enumerate() {
            if first[i] || second[i] {
                assert_eq!(n, m, "point {i}");
            } else {
                assert_eq!(*n, Vec3::zeros(), "point {i}");
            }
            if first[i] {
                assert_eq!(*n, after_first[i], "point {i} changed");
            }
        }
        // Each estimated once: a third and the half not in it.
        let once = (0..500).filter(|i| first[*i] || second[*i]).count();
        assert_eq!(lazy.estimated().count(), once);
        // A prior's normals are taken as they are, the others estimated.
        let prior = |i: usize| (i % 5 == 0).then_some(Vec3::x());
        let mut lazy = NormalsOnDemand::new(&index, 10).unwrap().with_prior(&prior);
        lazy.cover(&vec![true; 500]);
        for (i, (n, m)) in lazy.normals().iter().zip(&all).enumerate() {
            assert_eq!(*n, if i % 5 == 0 { Vec3::x() } else { *m }, "point {i}");
        }
        assert_eq!(lazy.estimated().count(), 400);
    }

    #[test]
    fn a_shared_index_gives_the_same_normals() {
        let pts: Vec<Vec3> = (0..300)
            .map(|i| {
                let t = f64::from(i);
                Vec3::new((t * 0.37).sin(), (t * 0.91).cos(), 0.1 * (t * 0.13).fract())
            })
            .collect();
        let index = KnnIndex::new(pts.clone());
        assert_eq!(
            estimate_normals_from(&index, 8).unwrap(),
            estimate_normals(&pts, 8).unwrap()
        );
        assert_eq!(
            estimate_normals_from(&KnnIndex::new(pts[..2].to_vec()), 8),
            Err(NormalsError::TooFewPoints { got: 2 })
        );
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let p = Vec3::new(0.0, 0.0, 0.0);
        assert_eq!(
            estimate_normals(&[p, p], 8),
            Err(NormalsError::TooFewPoints { got: 2 })
        );
        assert_eq!(
            estimate_normals(&[p, p, p], 2),
            Err(NormalsError::SmallK { k: 2 })
        );
        let nan = Vec3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(
            estimate_normals(&[p, p, nan], 3),
            Err(NormalsError::NonFinite { index: 2 })
        );
        // Coincident points: a defined (z) normal, no NaN.
        assert_eq!(estimate_normals(&[p, p, p], 3).unwrap(), vec![Vec3::z(); 3]);
    }
}
