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
    let points = index.points();
    check(points, k)?;
    let qty = k.min(points.len());
    Ok(points
        .par_iter()
        .enumerate()
        .map(|(i, q)| match wanted.get(i) {
            Some(true) => normal_at(index, q, qty),
            _ => Vec3::zeros(),
        })
        .collect())
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
