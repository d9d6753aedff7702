//! The 3D separability filter: a separability map of a cloud (paper §IV-A, Fig. 6).
//!
//! At every point `p` a cuboid centred on `p` is split by one boundary plane
//! through `p` perpendicular to a direction `v` into two adjacent regions
//! (the paper's `r1`, `r2` at `sp` along `v`, Fig. 5b), and the separability
//! of the two halves is evaluated: η_p (Eq. 7), or the weighted η_w (Eq. 9)
//! when attribute weights are given. This is the oriented search primitive
//! with `K = 1`. With several directions the map keeps the maximum; with
//! [`FilterDirection::Normal`] each point uses its own PCA normal
//! ([`crate::normals`]; [`separability_map_of`] takes them from the k-NN
//! index the caller built for the cloud's density). The map is high where
//! density or attributes change: region boundaries.
//!
//! Evaluated in parallel over points (rayon, one scratch per worker).

use crate::cloud::Vec3;
use crate::normals::{estimate_normals, estimate_normals_from};
use crate::separability::attribute::AttributeSet;
use crate::separability::grid::SpatialIndex;
use crate::separability::search::{Cuboid, Delta, SearchError, SearchScratch, Searcher};
use crate::spatial::KnnIndex;
use rayon::prelude::*;
use thiserror::Error;

/// Errors of the separability filter.
#[derive(Debug, Error)]
pub enum FilterError {
    /// Bad δ, cuboid size or attribute set.
    #[error(transparent)]
    Search(#[from] SearchError),
    /// The per-point normals could not be estimated.
    #[error(transparent)]
    Normals(#[from] crate::normals::NormalsError),
}

/// Directions along which the filter compares the two halves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterDirection {
    /// The x axis.
    X,
    /// The y axis.
    Y,
    /// The z axis.
    Z,
    /// The maximum over x, y and z.
    All,
    /// Each point's own unit normal, estimated by PCA over its `k` nearest
    /// neighbours (unoriented: Eq. 7 is symmetric in the two regions).
    Normal {
        /// Neighbours of the PCA (at least 3).
        k: usize,
    },
}

impl FilterDirection {
    fn axes(self) -> &'static [Vec3] {
        const X: [Vec3; 1] = [Vec3::new(1.0, 0.0, 0.0)];
        const Y: [Vec3; 1] = [Vec3::new(0.0, 1.0, 0.0)];
        const Z: [Vec3; 1] = [Vec3::new(0.0, 0.0, 1.0)];
        const ALL: [Vec3; 3] = [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ];
        match self {
            Self::X => &X,
            Self::Y => &Y,
            Self::Z => &Z,
            Self::All => &ALL,
            Self::Normal { .. } => &[],
        }
    }
}

/// Cuboid size of the filter, in absolute lengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterSize {
    /// Extent across the direction (first axis).
    pub width: f64,
    /// Extent across the direction (second axis).
    pub height: f64,
    /// Extent along the direction (both halves together).
    pub depth: f64,
}

/// The separability map: one value in [0, 1] per point of `points`
/// (non-finite points get 0).
///
/// # Errors
/// [`FilterError`] for a bad δ, size or attribute set, or a normal
/// estimation that cannot run (fewer than 3 finite points, `k < 3`).
pub fn separability_map(
    points: &[Vec3],
    delta: f64,
    size: FilterSize,
    direction: FilterDirection,
    attributes: Option<&AttributeSet>,
) -> Result<Vec<f32>, FilterError> {
    let normals = |k| finite_normals(points, k);
    map_with(points, normals, delta, size, direction, attributes)
}

/// [`separability_map`] of the points of `knn` (which must be finite), whose
/// index also serves the [`FilterDirection::Normal`] normals.
///
/// # Errors
/// As [`separability_map`].
pub fn separability_map_of(
    knn: &KnnIndex,
    delta: f64,
    size: FilterSize,
    direction: FilterDirection,
    attributes: Option<&AttributeSet>,
) -> Result<Vec<f32>, FilterError> {
    let normals = |k| Ok(estimate_normals_from(knn, k)?);
    map_with(knn.points(), normals, delta, size, direction, attributes)
}

/// The map of [`separability_map`]; `normals(k)` gives every point's
/// normal when the direction is [`FilterDirection::Normal`].
fn map_with(
    points: &[Vec3],
    normals: impl FnOnce(usize) -> Result<Vec<Vec3>, FilterError>,
    delta: f64,
    size: FilterSize,
    direction: FilterDirection,
    attributes: Option<&AttributeSet>,
) -> Result<Vec<f32>, FilterError> {
    let index = SpatialIndex::with_cell_size(points, size.width.max(size.depth) * 0.5)
        .or_else(|_| SpatialIndex::new(points))
        .map_err(|_| SearchError::BadExtent {
            what: "width",
            value: size.width,
        })?;
    let mut searcher = Searcher::new(&index, Delta::Global(delta), 1)?;
    if let Some(a) = attributes {
        searcher = searcher.with_attributes(a)?;
    }
    // Validate the size once, so the per-point loop cannot fail.
    Cuboid::new(
        Vec3::zeros(),
        Vec3::x(),
        size.width,
        size.height,
        size.depth,
    )
    .oriented_box()?;
    let axes = direction.axes();
    let normals = match direction {
        FilterDirection::Normal { k } => Some(normals(k)?),
        _ => None,
    };
    Ok(points
        .par_iter()
        .enumerate()
        .map_init(SearchScratch::new, |scratch, (i, p)| {
            if !p.iter().all(|c| c.is_finite()) {
                return 0.0;
            }
            let own;
            let dirs = match &normals {
                Some(n) => {
                    own = [n[i]];
                    &own[..]
                }
                None => axes,
            };
            let mut best = 0.0f64;
            for &v in dirs {
                let cuboid = Cuboid::new(*p, v, size.width, size.height, size.depth);
                if searcher.search(&cuboid, scratch).is_ok() {
                    if let Some(b) = scratch.profile().first() {
                        best = best.max(b.eta);
                    }
                }
            }
            best as f32
        })
        .collect())
}

/// PCA normals of the finite points, in `points` order (the z axis at
/// non-finite points, which the map skips).
fn finite_normals(points: &[Vec3], k: usize) -> Result<Vec<Vec3>, FilterError> {
    let finite: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].iter().all(|c| c.is_finite()))
        .collect();
    let pts: Vec<Vec3> = finite.iter().map(|&i| points[i]).collect();
    let normals = estimate_normals(&pts, k)?;
    let mut out = vec![Vec3::z(); points.len()];
    for (&i, n) in finite.iter().zip(normals) {
        out[i] = n;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Planar cloud on z = 0 over [0, 1]²: spacing 0.01 for x < 0.35 and
    /// 0.02 beyond (a density boundary at x = 0.35); luma 0.2 for x < 0.65
    /// and 0.8 beyond (a colour boundary at x = 0.65).
    fn planar_regions() -> (Vec<Vec3>, Vec<f32>) {
        let mut pts = Vec::new();
        let mut luma = Vec::new();
        let mut push = |x: f64, y: f64| {
            pts.push(Vec3::new(x, y, 0.0));
            luma.push(if x < 0.65 { 0.2 } else { 0.8 });
        };
        for i in 0..35 {
            for j in 0..100 {
                push(0.005 + 0.01 * f64::from(i), 0.005 + 0.01 * f64::from(j));
            }
        }
        for i in 0..33 {
            for j in 0..50 {
                push(
                    0.35 + 0.01 + 0.02 * f64::from(i),
                    0.01 + 0.02 * f64::from(j),
                );
            }
        }
        (pts, luma)
    }

    /// Largest map value over the points selected by `keep` (away from the
    /// cloud's outer edges in y).
    fn max_where(pts: &[Vec3], map: &[f32], keep: impl Fn(&Vec3) -> bool) -> f64 {
        let (s, n) = pts
            .iter()
            .zip(map)
            .filter(|(p, _)| keep(p) && p.y > 0.15 && p.y < 0.85)
            .fold((0.0f64, 0usize), |(s, n), (_, &m)| {
                (s.max(f64::from(m)), n + 1)
            });
        assert!(n > 0);
        s
    }

    #[test]
    fn map_peaks_at_density_and_colour_boundaries() {
        let (pts, luma) = planar_regions();
        // Thin across the plane (height along z for direction x), so that a
        // fully sampled half is a full region: δ³ capacity matches the sheet.
        let size = FilterSize {
            width: 0.06,
            height: 0.012,
            depth: 0.07,
        };
        let delta = 0.012;
        let near = |x0: f64| move |p: &Vec3| (p.x - x0).abs() < 0.025;
        let dense_flat = |p: &Vec3| p.x > 0.12 && p.x < 0.25;
        let sparse_flat = |p: &Vec3| (p.x > 0.45 && p.x < 0.55) || (p.x > 0.75 && p.x < 0.88);
        let summary = |map: &[f32]| {
            (
                max_where(&pts, map, near(0.35)),
                max_where(&pts, map, near(0.65)),
                max_where(&pts, map, dense_flat),
                max_where(&pts, map, sparse_flat),
            )
        };
        // η_p alone: the density boundary stands out, the colour one does not
        // (it looks like the sparse region it lies in).
        let map = separability_map(&pts, delta, size, FilterDirection::X, None).unwrap();
        assert_eq!(map.len(), pts.len());
        assert!(map.iter().all(|m| (0.0..=1.0).contains(m)));
        let (dens, col, fd, fs) = summary(&map);
        let msg = format!("density {dens} colour {col} dense-flat {fd} sparse-flat {fs}");
        assert!(dens > 2.0 * fd.max(fs) + 0.02, "{msg}");
        assert!(col < 1.2 * fs + 0.01, "{msg}");
        // With luma weighted in, the colour boundary peaks too.
        let set = AttributeSet::new(1.0, &[("luma", &luma, 1.0)]).unwrap();
        let map = separability_map(&pts, delta, size, FilterDirection::X, Some(&set)).unwrap();
        let (dens, col, fd, fs) = summary(&map);
        let msg = format!("weighted: density {dens} colour {col} dense-flat {fd} sparse-flat {fs}");
        assert!(dens > 2.0 * fd.max(fs) + 0.02, "{msg}");
        assert!(col > 2.0 * fs + 0.1, "{msg}");
    }

    #[test]
    fn normal_direction_follows_each_point_normal() {
        // The planar cloud tilted by 30° about x: every PCA normal is the
        // tilted plane normal, so the normal map of the tilted cloud matches
        // the z map of the untilted one (and not its x map).
        // A small deterministic jitter across the plane, so that no point
        // lies exactly on a boundary plane (where rounding would pick its side).
        let (mut pts, _) = planar_regions();
        for (i, p) in pts.iter_mut().enumerate() {
            p.z = 0.001 * ((i as f64) * 0.7).sin();
        }
        let size = FilterSize {
            width: 0.06,
            height: 0.06,
            depth: 0.06,
        };
        let z = separability_map(&pts, 0.012, size, FilterDirection::Z, None).unwrap();
        let rot = nalgebra::Rotation3::from_axis_angle(&Vec3::x_axis(), 30f64.to_radians());
        let tilted: Vec<Vec3> = pts.iter().map(|p| rot * p).collect();
        let n =
            separability_map(&tilted, 0.012, size, FilterDirection::Normal { k: 8 }, None).unwrap();
        let x = separability_map(&tilted, 0.012, size, FilterDirection::X, None).unwrap();
        let mean = |m: &[f32]| m.iter().map(|&v| f64::from(v)).sum::<f64>() / m.len() as f64;
        let diff: Vec<f32> = z.iter().zip(&n).map(|(a, b)| (a - b).abs()).collect();
        let msg = format!(
            "mean z {} normal {} x {} |diff| {}",
            mean(&z),
            mean(&n),
            mean(&x),
            mean(&diff)
        );
        assert!(
            mean(&z) > 0.05,
            "the z split must see the two sheets: {msg}"
        );
        // PCA normals of a jittered sheet are tilted by a few degrees and of
        // either sign, so the maps agree statistically, not point by point.
        assert!((mean(&n) - mean(&z)).abs() < 0.5 * mean(&z), "{msg}");
        assert!(mean(&diff) < 0.7 * mean(&z), "{msg}");
        assert!(mean(&n) > 3.0 * mean(&x), "{msg}");
        // A non-finite point gets 0 and does not break the normals of the rest.
        let mut with_nan = tilted.clone();
        with_nan.push(Vec3::new(f64::NAN, 0.0, 0.0));
        let n = separability_map(
            &with_nan,
            0.012,
            size,
            FilterDirection::Normal { k: 8 },
            None,
        )
        .unwrap();
        assert_eq!(n.last().copied(), Some(0.0));
        // The caller's k-NN index gives the same map.
        let knn = KnnIndex::new(tilted.clone());
        let of = separability_map_of(&knn, 0.012, size, FilterDirection::Normal { k: 8 }, None);
        let plain = separability_map(&tilted, 0.012, size, FilterDirection::Normal { k: 8 }, None);
        assert_eq!(of.unwrap(), plain.unwrap());
        assert!(separability_map(
            &tilted[..2],
            0.012,
            size,
            FilterDirection::Normal { k: 8 },
            None
        )
        .is_err());
    }
}
