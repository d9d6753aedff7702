//! An angular range image of points seen from an eye: the gnomonic
//! projection on the plane perpendicular to a view direction, in square
//! bins, each bin keeping the nearest range seen in its pixel cone.
//!
//! One type for the two places that ask "what did the camera see in the
//! direction of this point": the single-view visibility of the membrane
//! (`membrane::view`, a z-buffer in `f64`) and the free-space evidence of the
//! fused model (`model::views`, depth images kept over many frames in `f32`).
//! Each chooses its own bin size and acceptance of a view; the projection,
//! the binning and the 3×3 nearest-range query are this module's.

use crate::cloud::Vec3;

/// A camera at `eye` looking along the unit `dir`, with the unit `u`, `w`
/// completing a right-handed frame.
#[derive(Debug, Clone, Copy)]
pub struct ViewFrame {
    eye: Vec3,
    dir: Vec3,
    u: Vec3,
    w: Vec3,
}

impl ViewFrame {
    /// The frame at `eye` looking at `target`; `None` when they coincide.
    pub fn looking_at(eye: Vec3, target: Vec3) -> Option<Self> {
        let dir = (target - eye).try_normalize(1e-12)?;
        let (u, w) = crate::cloud::perpendicular_pair(&dir);
        Some(Self { eye, dir, u, w })
    }

    /// The eye.
    pub fn eye(&self) -> Vec3 {
        self.eye
    }

    /// The view direction (unit).
    pub fn dir(&self) -> Vec3 {
        self.dir
    }

    /// Depth of `p` along the view direction.
    pub fn depth(&self, p: &Vec3) -> f64 {
        (p - self.eye).dot(&self.dir)
    }

    /// The lateral offsets of `p` from the eye along `u` and `w`.
    pub fn lateral(&self, p: &Vec3) -> [f64; 2] {
        let d = p - self.eye;
        [d.dot(&self.u), d.dot(&self.w)]
    }

    /// Range from the eye.
    pub fn range(&self, p: &Vec3) -> f64 {
        (p - self.eye).norm()
    }

    /// The gnomonic coordinates of `p` (lateral offsets over depth) with
    /// its depth; `None` when `p` is not in front of the eye.
    pub fn project(&self, p: &Vec3) -> Option<([f64; 2], f64)> {
        let along = self.depth(p);
        if along.is_nan() || along <= 0.0 {
            return None;
        }
        let [a, b] = self.lateral(p);
        Some(([a / along, b / along], along))
    }

    /// The gnomonic window `(lo, hi)` that holds every point of `points`;
    /// `None` when one lies outside the cone whose cosine with the view
    /// direction is `min_cos` (its depth is at most `min_cos` times its
    /// range), or has a NaN coordinate. Each caller states how far off axis
    /// a view it accepts may reach.
    pub fn window(&self, points: &[Vec3], min_cos: f64) -> Option<([f64; 2], [f64; 2])> {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in points {
            let along = self.depth(p);
            let inside = along.partial_cmp(&(min_cos * self.range(p)));
            // `None` for a NaN coordinate.
            if inside != Some(std::cmp::Ordering::Greater) {
                return None;
            }
            let [a0, a1] = self.lateral(p);
            let a = [a0 / along, a1 / along];
            for k in 0..2 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(a[k]);
            }
        }
        Some((lo, hi))
    }
}

/// A range stored in a bin: `f64` or `f32`.
pub trait Range: Copy + PartialOrd {
    /// Nothing seen.
    const NONE: Self;
    /// The smaller of two ranges.
    fn min_of(self, other: Self) -> Self;
}

impl Range for f64 {
    const NONE: Self = f64::INFINITY;
    fn min_of(self, other: Self) -> Self {
        self.min(other)
    }
}

impl Range for f32 {
    const NONE: Self = f32::INFINITY;
    fn min_of(self, other: Self) -> Self {
        self.min(other)
    }
}

/// The nearest range seen per bin over the gnomonic window `[lo, hi]`,
/// with one spare bin (and one more at the high end) on each side.
#[derive(Debug, Clone)]
pub struct RangeImage<T> {
    frame: ViewFrame,
    lo: [f64; 2],
    inv_bin: f64,
    dims: [usize; 2],
    near: Vec<T>,
}

impl<T: Range> RangeImage<T> {
    /// Bins per side for the window `[lo, hi]` with bins of edge `bin`.
    pub fn dims_for(lo: [f64; 2], hi: [f64; 2], bin: f64) -> [usize; 2] {
        [
            ((hi[0] - lo[0]) / bin).ceil() as usize + 3,
            ((hi[1] - lo[1]) / bin).ceil() as usize + 3,
        ]
    }

    /// An empty image of the window `[lo, hi]` with bins of edge `bin`.
    pub fn new(frame: ViewFrame, lo: [f64; 2], hi: [f64; 2], bin: f64) -> Self {
        let dims = Self::dims_for(lo, hi, bin);
        Self {
            frame,
            lo: [lo[0] - bin, lo[1] - bin],
            inv_bin: 1.0 / bin,
            dims,
            near: vec![T::NONE; dims[0] * dims[1]],
        }
    }

    /// An empty image on the same bins.
    pub fn empty_like(&self) -> Self {
        Self {
            frame: self.frame,
            lo: self.lo,
            inv_bin: self.inv_bin,
            dims: self.dims,
            near: vec![T::NONE; self.near.len()],
        }
    }

    /// The camera.
    pub fn frame(&self) -> &ViewFrame {
        &self.frame
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.near.len()
    }

    /// Whether the image has no bins.
    pub fn is_empty(&self) -> bool {
        self.near.is_empty()
    }

    /// Bin of `p` (`None` when behind the eye or beyond the image).
    pub fn cell(&self, p: &Vec3) -> Option<usize> {
        let [x, y] = self.bin_coords(p)?;
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (x, y) = (x as usize, y as usize);
        (x < self.dims[0] && y < self.dims[1]).then_some(y * self.dims[0] + x)
    }

    /// The bin coordinates of `p`, floored, whether in the image or not
    /// (`None` behind the eye or not finite).
    fn bin_coords(&self, p: &Vec3) -> Option<[f64; 2]> {
        let d = p - self.frame.eye;
        let along = d.dot(&self.frame.dir);
        if along.is_nan() || along <= 0.0 {
            return None;
        }
        let x = ((d.dot(&self.frame.u) / along - self.lo[0]) * self.inv_bin).floor();
        let y = ((d.dot(&self.frame.w) / along - self.lo[1]) * self.inv_bin).floor();
        (x.is_finite() && y.is_finite()).then_some([x, y])
    }

    /// The bin edge at range `r`, in metres across the view.
    pub fn bin_width_at(&self, r: f64) -> f64 {
        r / self.inv_bin
    }

    /// The nearest range seen over the bins within `reach` bins of `p`'s
    /// (its `(2·reach + 1)²` block, clipped to the image): `None` behind
    /// the eye or when the block lies wholly beyond the image;
    /// [`Range::NONE`] where nothing was seen.
    pub fn nearest_within(&self, p: &Vec3, reach: usize) -> Option<T> {
        let [x, y] = self.bin_coords(p)?;
        let span = |c: f64, dim: usize| {
            let lo = (c - reach as f64).max(0.0);
            let hi = (c + reach as f64).min(dim as f64 - 1.0);
            (lo <= hi).then_some((lo as usize, hi as usize))
        };
        let ((x0, x1), (y0, y1)) = (span(x, self.dims[0])?, span(y, self.dims[1])?);
        let mut best = T::NONE;
        for yy in y0..=y1 {
            for xx in x0..=x1 {
                best = best.min_of(self.near[yy * self.dims[0] + xx]);
            }
        }
        Some(best)
    }

    /// Record a range `r` seen in bin `c` (the nearest is kept).
    pub fn record(&mut self, c: usize, r: T) {
        if let Some(n) = self.near.get_mut(c) {
            *n = n.min_of(r);
        }
    }

    /// The nearest range seen over the bin of `p` and the 8 around it
    /// (`None` outside the image; [`Range::NONE`] where nothing was seen).
    pub fn nearest_around(&self, p: &Vec3) -> Option<T> {
        let c = self.cell(p)?;
        let (x, y) = (c % self.dims[0], c / self.dims[0]);
        let mut best = T::NONE;
        for yy in y.saturating_sub(1)..=(y + 1).min(self.dims[1] - 1) {
            for xx in x.saturating_sub(1)..=(x + 1).min(self.dims[0] - 1) {
                best = best.min_of(self.near[yy * self.dims[0] + xx]);
            }
        }
        Some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wider_block_finds_what_lies_bins_away_even_beyond_the_image() {
        let frame = ViewFrame::looking_at(Vec3::zeros(), Vec3::new(0.0, 0.0, 1.0)).unwrap();
        let mut img: RangeImage<f64> = RangeImage::new(frame, [-0.5, -0.5], [0.5, 0.5], 0.1);
        // At depth 1, `x` bins of 0.1 across the view.
        let at = |x: f64| frame.u * (x + 0.05) + frame.dir;
        let p = at(0.4);
        img.record(img.cell(&p).unwrap(), 1.0);
        // Three bins over: beyond a 3 × 3 block, within a 7 × 7 one.
        let over = at(0.1);
        assert_eq!(img.nearest_within(&over, 1), Some(f64::INFINITY));
        assert_eq!(img.nearest_within(&over, 3), Some(1.0));
        // Beyond the image's edge by two bins: the block still reaches it.
        let outside = at(0.8);
        assert_eq!(img.cell(&outside), None);
        assert_eq!(img.nearest_within(&outside, 4), Some(1.0));
        assert_eq!(img.nearest_within(&at(5.0), 4), None);
        // Behind the eye.
        assert_eq!(img.nearest_within(&Vec3::new(0.0, 0.0, -1.0), 4), None);
        assert!((img.bin_width_at(2.0) - 0.2).abs() < 1e-12);
    }

    #[test]
    fn a_point_is_binned_and_found_by_its_neighbours() {
        let frame = ViewFrame::looking_at(Vec3::zeros(), Vec3::new(0.0, 0.0, 1.0)).unwrap();
        let mut img: RangeImage<f64> = RangeImage::new(frame, [-0.5, -0.5], [0.5, 0.5], 0.1);
        let p = Vec3::new(0.1, -0.25, 2.0);
        let c = img.cell(&p).unwrap();
        img.record(c, 2.5);
        img.record(c, 3.0);
        // The nearest range is kept, and a point one bin over sees it.
        assert_eq!(img.nearest_around(&p), Some(2.5));
        let beside = Vec3::new(0.3, -0.25, 2.0);
        assert_eq!(img.nearest_around(&beside), Some(2.5));
        // Far off the side: nothing seen; behind the eye: outside the image.
        assert_eq!(img.nearest_around(&Vec3::new(2.0, 2.0, 2.0)), None);
        assert_eq!(img.cell(&Vec3::new(0.0, 0.0, -1.0)), None);
        let mid = Vec3::new(-0.3, 0.3, 1.0);
        assert_eq!(img.nearest_around(&mid), Some(f64::INFINITY));
    }

    #[test]
    fn the_frame_is_orthonormal_and_projects_depth() {
        let eye = Vec3::new(1.0, 2.0, 3.0);
        let f = ViewFrame::looking_at(eye, Vec3::new(4.0, 6.0, 3.0)).unwrap();
        assert!((f.dir().norm() - 1.0).abs() < 1e-12);
        let p = eye + f.dir() * 2.0;
        let (a, along) = f.project(&p).unwrap();
        assert!((along - 2.0).abs() < 1e-12 && a[0].abs() < 1e-12 && a[1].abs() < 1e-12);
        assert!(f.project(&(eye - f.dir())).is_none());
        assert!(ViewFrame::looking_at(eye, eye).is_none());
    }
}
