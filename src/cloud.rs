//! Point clouds: positions plus named per-point scalar attributes.
//!
//! This is the actual-point set 𝒫 of the paper (§III-A/B): only measured
//! points are stored. Non-data points ℬ are never created; the separability
//! code estimates their *count* from the local density instead.
//!
//! Attributes (intensity, colour channels, any named float field of the
//! input) are kept as named `f32` channels of the same length as the points,
//! so that the weighted separability (paper Eq. 9) can pick them by name.
//! Colour is stored as the channels `r`, `g`, `b` in `[0, 1]`; [`PointCloud::luma`]
//! derives the Rec. 601 luma from them.
//!
//! A cloud can carry a closed surface only if it spreads in three
//! dimensions. [`check_spread`] measures that by principal component
//! analysis (the eigenvalues of the covariance matrix), independent of the
//! orientation: the axis-aligned box alone let a plane tilted by 45° and
//! 2,000 collinear points along a diagonal through (a 4.7 m³ "watertight"
//! mesh with η_g 0, exit 0).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use thiserror::Error;

/// The one thinning of sepmem (the frame pipeline's `pipeline.max_points`
/// and the membrane's `membrane.prepare.max_points`, `density_sample`): the
/// increasing indices of exactly `cap` of `n` items (all of them when `cap`
/// is 0 or at least `n`), those whose SplitMix64 key of the index (mixed
/// with `salt`) is among the `cap` smallest. Deterministic, independent of
/// the points' values, and without the stripes a fixed stride leaves in an
/// organised, row-major cloud.
pub fn thin_indices(n: usize, cap: usize, salt: u64) -> Vec<usize> {
    if cap == 0 || n <= cap {
        return (0..n).collect();
    }
    let key = thin_key(salt);
    // The keys are uniform on u64 and distinct (SplitMix64 is a bijection),
    // so the `cap` smallest lie below about cap/n of the range: select among
    // the keys below a bound six standard deviations above that, and among
    // all of them only when the bound caught too few. One pass over the
    // points instead of a selection among all n keys.
    let share = cap as f64 / n as f64;
    let spread = 6.0 * (n as f64 * share * (1.0 - share)).sqrt() + 16.0;
    let bound_share = (cap as f64 + spread) / n as f64;
    let bound = if bound_share >= 1.0 {
        u64::MAX
    } else {
        (bound_share * 2f64.powi(64)) as u64
    };
    let mut keyed: Vec<(u64, usize)> = (0..n)
        .map(|i| (key(i), i))
        .filter(|&(k, _)| k <= bound)
        .collect();
    if keyed.len() < cap {
        keyed = (0..n).map(|i| (key(i), i)).collect();
    }
    keyed.select_nth_unstable(cap - 1);
    let mut out: Vec<usize> = keyed[..cap].iter().map(|&(_, i)| i).collect();
    out.sort_unstable();
    out
}

/// The SplitMix64 key of index `i` under `salt` ([`thin_indices`]).
fn thin_key(salt: u64) -> impl Fn(usize) -> u64 {
    let mix = salt.wrapping_mul(0xD1B5_4A32_D192_ED03);
    move |i: usize| -> u64 {
        let mut z = (i as u64 ^ mix).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// 3-vector of `f64` used for every position and direction in sepmem.
pub type Vec3 = Vector3<f64>;

/// Two unit vectors that make a right-handed orthonormal frame with the
/// unit vector `dir`: `u = dir × h` (normalised, `h` the x axis unless
/// `dir` is near it, then the y axis) and `w = dir × u`.
pub fn perpendicular_pair(dir: &Vec3) -> (Vec3, Vec3) {
    let helper = if dir.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let u = dir.cross(&helper).normalize();
    (u, dir.cross(&u))
}

/// Errors about the content of a point cloud.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CloudError {
    /// The cloud has no (finite) points.
    #[error("point cloud is empty (no finite points)")]
    Empty,
    /// Too few points to do what was asked.
    #[error("point cloud has {got} points, at least {need} are needed")]
    TooFewPoints {
        /// Points present.
        got: usize,
        /// Points required.
        need: usize,
    },
    /// Too few of a cloud's points are left to carry a surface once the
    /// unusable ones are dropped.
    #[error(
        "{usable} of the cloud's {points} points are usable ({non_finite} non-finite, \
         {duplicate} duplicates, {detached} detached from its main body), at least {need} are needed"
    )]
    TooFewUsable {
        /// Points left.
        usable: usize,
        /// Points in the cloud.
        points: usize,
        /// Points with a non-finite coordinate.
        non_finite: usize,
        /// Points equal to an earlier one.
        duplicate: usize,
        /// Points in groups detached from the main body.
        detached: usize,
        /// Points required.
        need: usize,
    },
    /// The cloud is too large or too small to be an object a camera sees
    /// ([`EXTENT_RANGE`]).
    #[error(
        "point cloud is {longest:.3e} m across, outside the supported {:e}..{:e} m (coordinates are metres)",
        EXTENT_RANGE.start(),
        EXTENT_RANGE.end()
    )]
    OutOfRange {
        /// The longest edge of its bounding box.
        longest: f64,
    },
    /// All points lie on (nearly) a plane, a line or a single point.
    #[error("point cloud is degenerate: its extent is {extent:?}")]
    Degenerate {
        /// Bounding-box edge lengths.
        extent: [f64; 3],
    },
    /// The points lie on (nearly) a plane or a line in some orientation:
    /// the smallest principal spread is below [`MIN_RELATIVE_SPREAD`] of the
    /// largest.
    #[error("point cloud is degenerate: it lies on a plane or a line (standard deviations along its principal axes {spread:?})")]
    Flat {
        /// Standard deviations along the principal axes, largest first.
        spread: [f64; 3],
    },
    /// An attribute channel does not have one value per point.
    #[error("attribute `{name}` has {got} values for {points} points")]
    AttributeLength {
        /// Attribute name.
        name: String,
        /// Number of values.
        got: usize,
        /// Number of points.
        points: usize,
    },
}

/// Smallest accepted ratio of the smallest to the largest standard
/// deviation along the principal axes (far above the ~10⁻⁸ floor of the
/// eigen-solver's rounding, far below a thin real object: a sheet 0.1 mm
/// thick and 0.3 m wide has ~3·10⁻⁴).
pub const MIN_RELATIVE_SPREAD: f64 = 1e-5;

/// Standard deviations of `points` along their principal axes, largest
/// first (square roots of the covariance eigenvalues); zeros for fewer than
/// two points.
pub fn principal_spread(points: &[Vec3]) -> [f64; 3] {
    if points.len() < 2 {
        return [0.0; 3];
    }
    let n = points.len() as f64;
    let mean: Vec3 = points.iter().sum::<Vec3>() / n;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p - mean;
        cov += d * d.transpose();
    }
    cov /= n;
    let mut s = SymmetricEigen::new(cov)
        .eigenvalues
        .map(|l| l.max(0.0).sqrt());
    s.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    [s[0], s[1], s[2]]
}

/// The longest bounding-box edge a cloud may have, in metres: from a
/// nanometre to a million kilometres. Beyond it the membrane's volumes
/// (Eq. 4's `Vol(r)/δ³`) and spreads leave the range of f64: a sphere of
/// radius 1e150 gave η 0 everywhere and an empty "converged" surface, and
/// one of 1e200 or 1e-200 read as flat (its covariance overflowed or
/// underflowed).
pub const EXTENT_RANGE: std::ops::RangeInclusive<f64> = 1e-9..=1e9;

/// Check a bounding box's edge lengths `e`.
///
/// # Errors
/// [`CloudError::OutOfRange`] when the longest edge lies outside
/// [`EXTENT_RANGE`], [`CloudError::Degenerate`] when it is not positive or
/// the shortest is below 1e-6 of it.
pub fn check_extent(e: &Vec3) -> Result<(), CloudError> {
    let longest = e.max();
    if longest > 0.0 && !EXTENT_RANGE.contains(&longest) {
        return Err(CloudError::OutOfRange { longest });
    }
    if longest.is_nan() || longest <= 0.0 || e.min() < 1e-6 * longest {
        return Err(CloudError::Degenerate {
            extent: [e.x, e.y, e.z],
        });
    }
    Ok(())
}

/// Check that `points` spread in three dimensions, in any orientation.
///
/// # Errors
/// [`CloudError::Flat`] when the smallest principal spread is below
/// [`MIN_RELATIVE_SPREAD`] times the largest (a plane, a line, a point, or a
/// spread that is not finite).
pub fn check_spread(points: &[Vec3]) -> Result<(), CloudError> {
    let spread = principal_spread(points);
    let ok = spread.iter().all(|s| s.is_finite())
        && spread[0] > 0.0
        && spread[2] >= MIN_RELATIVE_SPREAD * spread[0];
    if ok {
        Ok(())
    } else {
        Err(CloudError::Flat { spread })
    }
}

/// A named scalar channel, one value per point.
#[derive(Debug, Clone, PartialEq)]
pub struct Attribute {
    /// Channel name (`intensity`, `r`, `g`, `b`, or the input field's name).
    pub name: String,
    /// One value per point.
    pub values: Vec<f32>,
}

/// Axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: Vec3,
    /// Maximum corner.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (min = +∞, max = −∞); growing it by a point gives that point.
    pub fn empty() -> Self {
        Self {
            min: Vec3::repeat(f64::INFINITY),
            max: Vec3::repeat(f64::NEG_INFINITY),
        }
    }

    /// Bounding box of a set of points (empty box for no points).
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Vec3>) -> Self {
        let mut b = Self::empty();
        for p in points {
            b.grow(p);
        }
        b
    }

    /// Enlarge the box to contain `p`.
    pub fn grow(&mut self, p: &Vec3) {
        self.min = self.min.inf(p);
        self.max = self.max.sup(p);
    }

    /// True when no point was added.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }

    /// Edge lengths (zero for the empty box).
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::zeros()
        } else {
            self.max - self.min
        }
    }

    /// Length of the longest edge.
    pub fn longest_edge(&self) -> f64 {
        self.extent().max()
    }

    /// Euclidean distance from `p` to the box (0 inside it, +∞ for the
    /// empty box).
    pub fn distance_to(&self, p: &Vec3) -> f64 {
        if self.is_empty() {
            return f64::INFINITY;
        }
        (self.min - p)
            .sup(&(p - self.max))
            .sup(&Vec3::zeros())
            .norm()
    }

    /// Centre of the box.
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f64 {
        self.extent().norm()
    }

    /// The box enlarged by `margin` on every side.
    pub fn inflated(&self, margin: f64) -> Self {
        Self {
            min: self.min - Vec3::repeat(margin),
            max: self.max + Vec3::repeat(margin),
        }
    }

    /// True when `p` lies inside or on the box.
    pub fn contains(&self, p: &Vec3) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}

/// A point cloud: finite positions and optional named attributes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// Point positions.
    pub points: Vec<Vec3>,
    /// Named per-point channels, each as long as `points`.
    pub attributes: Vec<Attribute>,
}

impl PointCloud {
    /// A cloud of positions only.
    pub fn from_points(points: Vec<Vec3>) -> Self {
        Self {
            points,
            attributes: Vec::new(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Bounding box of the points.
    pub fn aabb(&self) -> Aabb {
        Aabb::from_points(&self.points)
    }

    /// Mean of the positions (`None` for an empty cloud).
    pub fn centroid(&self) -> Option<Vec3> {
        if self.points.is_empty() {
            return None;
        }
        let sum: Vec3 = self.points.iter().sum();
        Some(sum / self.points.len() as f64)
    }

    /// The attribute channel named `name`, if present.
    pub fn attribute(&self, name: &str) -> Option<&[f32]> {
        self.attributes
            .iter()
            .find(|a| a.name == name)
            .map(|a| a.values.as_slice())
    }

    /// The colour channels `r`, `g`, `b` (when all three exist) and every
    /// other channel, in order: how the PLY and PCD writers lay out a cloud.
    pub fn rgb_and_other_channels(&self) -> (Option<[&[f32]; 3]>, Vec<&Attribute>) {
        let rgb = match (
            self.attribute("r"),
            self.attribute("g"),
            self.attribute("b"),
        ) {
            (Some(r), Some(g), Some(b)) => Some([r, g, b]),
            _ => None,
        };
        let others = self
            .attributes
            .iter()
            .filter(|a| rgb.is_none() || !matches!(a.name.as_str(), "r" | "g" | "b"))
            .collect();
        (rgb, others)
    }

    /// Add (or replace) a named attribute channel.
    ///
    /// # Errors
    /// [`CloudError::AttributeLength`] when `values` does not have one value per point.
    pub fn set_attribute(&mut self, name: &str, values: Vec<f32>) -> Result<(), CloudError> {
        if values.len() != self.points.len() {
            return Err(CloudError::AttributeLength {
                name: name.to_string(),
                got: values.len(),
                points: self.points.len(),
            });
        }
        if let Some(a) = self.attributes.iter_mut().find(|a| a.name == name) {
            a.values = values;
        } else {
            self.attributes.push(Attribute {
                name: name.to_string(),
                values,
            });
        }
        Ok(())
    }

    /// Rec. 601 luma `0.299 r + 0.587 g + 0.114 b` from the `r`, `g`, `b`
    /// channels, or `None` when the cloud carries no colour.
    pub fn luma(&self) -> Option<Vec<f32>> {
        let (r, g, b) = (
            self.attribute("r")?,
            self.attribute("g")?,
            self.attribute("b")?,
        );
        Some(
            r.iter()
                .zip(g)
                .zip(b)
                .map(|((r, g), b)| 0.299 * r + 0.587 * g + 0.114 * b)
                .collect(),
        )
    }

    /// Keep only the points for which `keep(i)` is true, in all channels.
    pub fn retain_indices(&mut self, mut keep: impl FnMut(usize) -> bool) {
        let mask: Vec<bool> = (0..self.points.len()).map(&mut keep).collect();
        let mut it = mask.iter();
        self.points.retain(|_| *it.next().unwrap_or(&false));
        for a in &mut self.attributes {
            let mut it = mask.iter();
            a.values.retain(|_| *it.next().unwrap_or(&false));
        }
    }

    /// Drop every point whose position is NaN or infinite; return how many were dropped.
    pub fn drop_non_finite(&mut self) -> usize {
        let before = self.points.len();
        let finite: Vec<bool> = self
            .points
            .iter()
            .map(|p| p.iter().all(|c| c.is_finite()))
            .collect();
        self.retain_indices(|i| finite[i]);
        before - self.points.len()
    }

    /// At most `cap` of the points (0: all), picked by [`thin_indices`]
    /// with `salt`; borrowed when nothing is dropped.
    pub fn thinned(&self, cap: usize, salt: u64) -> std::borrow::Cow<'_, Self> {
        if cap == 0 || self.len() <= cap {
            return std::borrow::Cow::Borrowed(self);
        }
        std::borrow::Cow::Owned(self.select(&thin_indices(self.len(), cap, salt)))
    }

    /// A new cloud holding the points at `indices` (with their attributes).
    pub fn select(&self, indices: &[usize]) -> Self {
        Self {
            points: indices.iter().map(|&i| self.points[i]).collect(),
            attributes: self
                .attributes
                .iter()
                .map(|a| Attribute {
                    name: a.name.clone(),
                    values: indices.iter().map(|&i| a.values[i]).collect(),
                })
                .collect(),
        }
    }

    /// Check that the cloud can carry a surface: enough points and a 3D extent.
    ///
    /// # Errors
    /// [`CloudError::Empty`], [`CloudError::TooFewPoints`],
    /// [`CloudError::OutOfRange`], [`CloudError::Degenerate`] (flat bounding
    /// box) or [`CloudError::Flat`]
    /// (flat in some other orientation, see [`check_spread`]).
    pub fn validate(&self, min_points: usize) -> Result<Aabb, CloudError> {
        if self.points.is_empty() {
            return Err(CloudError::Empty);
        }
        if self.points.len() < min_points {
            return Err(CloudError::TooFewPoints {
                got: self.points.len(),
                need: min_points,
            });
        }
        for a in &self.attributes {
            if a.values.len() != self.points.len() {
                return Err(CloudError::AttributeLength {
                    name: a.name.clone(),
                    got: a.values.len(),
                    points: self.points.len(),
                });
            }
        }
        let bb = self.aabb();
        check_extent(&bb.extent())?;
        check_spread(&self.points)?;
        Ok(bb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `cap` indices with the smallest keys, by sorting all of them.
    fn thin_reference(n: usize, cap: usize, salt: u64) -> Vec<usize> {
        if cap == 0 || n <= cap {
            return (0..n).collect();
        }
        let key = thin_key(salt);
        let mut all: Vec<(u64, usize)> = (0..n).map(|i| (key(i), i)).collect();
        all.sort_unstable();
        let mut out: Vec<usize> = all[..cap].iter().map(|&(_, i)| i).collect();
        out.sort_unstable();
        out
    }

    #[test]
    fn thinning_keeps_the_cap_smallest_keys() {
        for (n, cap) in [
            (20_000, 2_500),
            (10, 9),
            (1000, 1),
            (5000, 4999),
            (3, 0),
            (7, 7),
            (64, 32),
        ] {
            for salt in [0, 1, 0xDEAD_BEEF] {
                let got = thin_indices(n, cap, salt);
                assert_eq!(
                    got,
                    thin_reference(n, cap, salt),
                    "n {n} cap {cap} salt {salt}"
                );
                assert_eq!(got.len(), if cap == 0 { n } else { cap.min(n) });
            }
        }
    }

    #[test]
    fn distance_to_a_box_is_zero_inside_and_euclidean_outside() {
        let b = Aabb::from_points(&[Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 2.0, 3.0)]);
        assert_eq!(b.distance_to(&Vec3::new(0.5, 1.0, 1.0)), 0.0);
        assert_eq!(b.distance_to(&Vec3::new(-3.0, 1.0, 1.0)), 3.0);
        assert!((b.distance_to(&Vec3::new(4.0, 6.0, 3.0)) - 5.0).abs() < 1e-12);
        assert_eq!(Aabb::empty().distance_to(&Vec3::zeros()), f64::INFINITY);
    }

    #[test]
    fn drop_non_finite_keeps_attributes_aligned() {
        let mut c = PointCloud::from_points(vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(f64::NAN, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(0.0, f64::INFINITY, 0.0),
        ]);
        c.set_attribute("intensity", vec![1.0, 2.0, 3.0, 4.0])
            .unwrap();
        assert_eq!(c.drop_non_finite(), 2);
        assert_eq!(c.len(), 2);
        assert_eq!(c.attribute("intensity").unwrap(), &[1.0, 3.0]);
    }

    #[test]
    fn validate_rejects_empty_and_planar() {
        assert_eq!(PointCloud::default().validate(1), Err(CloudError::Empty));
        let planar = PointCloud::from_points(
            (0..100)
                .map(|i| Vec3::new(i as f64, (i * 7 % 13) as f64, 0.0))
                .collect(),
        );
        assert!(matches!(
            planar.validate(4),
            Err(CloudError::Degenerate { .. })
        ));
    }

    /// Rotation taking the z axis to the direction (1, 1, 1)/√3 (45° tilts about two axes).
    fn tilt(p: Vec3) -> Vec3 {
        let r = nalgebra::Rotation3::rotation_between(&Vec3::z(), &Vec3::new(1.0, 1.0, 1.0))
            .unwrap_or_else(nalgebra::Rotation3::identity);
        r * p
    }

    #[test]
    fn tilted_plane_and_diagonal_line_are_rejected() {
        let plane: Vec<Vec3> = (0..2000)
            .map(|i| {
                tilt(Vec3::new(
                    (i % 40) as f64 * 0.01,
                    (i / 40) as f64 * 0.01,
                    0.0,
                ))
            })
            .collect();
        // The box of the tilted plane is not flat: the old check let it through.
        let e = Aabb::from_points(&plane).extent();
        assert!(e.min() > 0.1 * e.max(), "{e}");
        let err = PointCloud::from_points(plane).validate(4).unwrap_err();
        assert!(matches!(err, CloudError::Flat { .. }), "{err}");
        let line: Vec<Vec3> = (0..2000)
            .map(|i| Vec3::new(1.0, 2.0, 3.0) * (i as f64 * 1e-3))
            .collect();
        let err = PointCloud::from_points(line).validate(4).unwrap_err();
        assert!(
            matches!(err, CloudError::Flat { spread } if spread[1] < 1e-6 * spread[0]),
            "{err}"
        );
        // A tilted box of points (a thin but real slab) passes.
        let slab: Vec<Vec3> = (0..2000)
            .map(|i| {
                let (a, b, c) = (i % 20, (i / 20) % 20, i / 400);
                tilt(Vec3::new(
                    a as f64 * 0.05,
                    b as f64 * 0.05,
                    c as f64 * 0.002,
                ))
            })
            .collect();
        assert!(PointCloud::from_points(slab).validate(4).is_ok());
    }

    #[test]
    fn luma_from_rgb() {
        let mut c = PointCloud::from_points(vec![Vec3::zeros(); 2]);
        c.set_attribute("r", vec![1.0, 0.0]).unwrap();
        c.set_attribute("g", vec![1.0, 0.0]).unwrap();
        c.set_attribute("b", vec![1.0, 1.0]).unwrap();
        let l = c.luma().unwrap();
        assert!((l[0] - 1.0).abs() < 1e-6);
        assert!((l[1] - 0.114).abs() < 1e-6);
    }
}
