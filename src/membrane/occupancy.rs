//! Inside/outside test independent of the membrane, for the gated inward force.
//!
//! The paper's external energy (Eq. 12, `E_sep = −η*`) only attracts the
//! membrane to point layers inside its search cuboid; across the empty
//! opening of a concavity (a bowl, the space between a mug and its handle)
//! nothing pulls it in. This grid supplies the missing inward force, but
//! only where the membrane is provably outside the object:
//!
//! 1. voxelise the cloud at `voxel = c·δ`;
//! 2. a voxel is *occupied* when its 3×3×3 neighbourhood holds at least
//!    `min_points` points (sparse outliers do not occupy); with the local
//!    spacing of [`super::spacing`] each point counts for the area it
//!    samples, `(δ_i/δ)²`, so a thinly sampled surface still closes the
//!    shell (one gap lets the flood fill below leak into the object, and the
//!    inward force then cuts through the thin part);
//! 3. occupied voxels are dilated once, then the empty voxels connected to
//!    the grid border (flood fill, 6-connectivity) are *outside*.
//!
//! Everything else (the shell and the cavity it encloses) is inside.

use crate::cloud::Vec3;

/// One point's count in the voxel sums (weights are counted in its multiples).
const WEIGHT_UNIT: u32 = 16;

/// Largest count of one point, in [`WEIGHT_UNIT`]s × 16 (keeps the 3×3×3
/// sums far from `u32::MAX`).
const MAX_WEIGHT: f64 = 65_536.0;

/// A voxel grid labelling space outside the object.
#[derive(Debug, Clone)]
pub struct OutsideGrid {
    origin: Vec3,
    inv_voxel: f64,
    dims: [usize; 3],
    outside: Vec<bool>,
}

impl OutsideGrid {
    /// Build from points with the given voxel edge and occupancy threshold.
    /// The grid is padded by two voxels around the points' bounding box; at
    /// most `max_cells` cells are used (the voxel is enlarged if needed).
    pub fn new(points: &[Vec3], voxel: f64, min_points: usize, max_cells: usize) -> Option<Self> {
        Self::weighted(points, None, voxel, min_points, max_cells)
    }

    /// [`Self::new`] with point `i` counting `weights[i]` times (in steps of
    /// 1/16) toward `min_points`: the area weights `(δ_i/δ)²` of the local
    /// spacing ([`super::spacing`]), so that a thinly sampled part of the
    /// surface occupies its voxels as a densely sampled one does (a surface
    /// crossing a block holds about `area/δ_i²` points). Without weights (or
    /// with a length mismatch) every point counts once.
    pub fn weighted(
        points: &[Vec3],
        weights: Option<&[f64]>,
        voxel: f64,
        min_points: usize,
        max_cells: usize,
    ) -> Option<Self> {
        if points.is_empty() || voxel.is_nan() || voxel <= 0.0 || !voxel.is_finite() {
            return None;
        }
        let weights = weights.filter(|w| w.len() == points.len());
        let unit = |i: usize| -> u32 {
            weights.map_or(WEIGHT_UNIT, |w| {
                let v = (w[i] * f64::from(WEIGHT_UNIT)).round();
                if v.is_finite() {
                    v.clamp(0.0, MAX_WEIGHT) as u32
                } else {
                    WEIGHT_UNIT
                }
            })
        };
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let mut voxel = voxel;
        let mut dims;
        loop {
            let ext = (hi - lo) / voxel;
            dims = [
                ext.x.ceil() as usize + 5,
                ext.y.ceil() as usize + 5,
                ext.z.ceil() as usize + 5,
            ];
            if dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]) <= max_cells.max(125) {
                break;
            }
            voxel *= 1.25;
        }
        let origin = lo - Vec3::repeat(2.0 * voxel);
        let inv_voxel = 1.0 / voxel;
        let [nx, ny, nz] = dims;
        let cells = nx * ny * nz;
        let id = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
        let mut count = vec![0u32; cells];
        for (i, p) in points.iter().enumerate() {
            let q = (p - origin) * inv_voxel;
            let (x, y, z) = (q.x as usize, q.y as usize, q.z as usize);
            if x < nx && y < ny && z < nz {
                let c = &mut count[id(x, y, z)];
                *c = c.saturating_add(unit(i));
            }
        }
        let need = (min_points as u64).saturating_mul(u64::from(WEIGHT_UNIT));
        let occupied: Vec<bool> = box_sum(count, dims)
            .iter()
            .map(|&c| u64::from(c) >= need)
            .collect();
        let solid = dilate(&occupied, dims);
        let outside = flood_outside(&solid, dims);
        Some(Self {
            origin,
            inv_voxel,
            dims,
            outside,
        })
    }

    /// True when `p` lies in empty space connected to the outside (points
    /// beyond the grid are outside).
    pub fn is_outside(&self, p: &Vec3) -> bool {
        self.label(p).unwrap_or(true)
    }

    /// The label of the cell holding `p`: `Some(true)` outside, `Some(false)`
    /// inside or occupied, `None` beyond the grid (where nothing was measured).
    pub fn label(&self, p: &Vec3) -> Option<bool> {
        let q = (p - self.origin) * self.inv_voxel;
        if !(q.x >= 0.0 && q.y >= 0.0 && q.z >= 0.0) {
            return None;
        }
        let (x, y, z) = (q.x as usize, q.y as usize, q.z as usize);
        let [nx, ny, nz] = self.dims;
        if x >= nx || y >= ny || z >= nz {
            return None;
        }
        Some(self.outside[(z * ny + y) * nx + x])
    }

    /// Distance from `p` along the unit direction `dir` to the first cell
    /// that is not outside (occupied, enclosed, or unseen for a single
    /// view), marching in half-voxel steps up to `max_dist`; `None` when
    /// the ray leaves the grid or reaches `max_dist` first.
    pub fn distance_to_solid(&self, p: &Vec3, dir: &Vec3, max_dist: f64) -> Option<f64> {
        let step = 0.5 / self.inv_voxel;
        let mut t = step;
        let mut entered = false;
        while t <= max_dist {
            match self.label(&(p + dir * t)) {
                Some(false) => return Some(t),
                Some(true) => entered = true,
                None if entered => return None,
                None => {}
            }
            t += step;
        }
        None
    }

    /// Keep the outside label only where `keep(cell centre)` holds (e.g. only
    /// in space a camera saw empty, [`super::view::ViewBuffer::is_seen_free`]).
    pub fn restrict(&mut self, keep: impl Fn(&Vec3) -> bool) {
        let [nx, ny, _] = self.dims;
        let voxel = 1.0 / self.inv_voxel;
        for (c, o) in self.outside.iter_mut().enumerate() {
            if *o {
                let (x, y, z) = (c % nx, (c / nx) % ny, c / (nx * ny));
                let centre =
                    self.origin + Vec3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * voxel;
                *o = keep(&centre);
            }
        }
    }

    /// Fraction of cells labelled outside (diagnostics).
    pub fn outside_fraction(&self) -> f64 {
        self.outside.iter().filter(|&&o| o).count() as f64 / self.outside.len().max(1) as f64
    }
}

/// Row-major cell index in a grid of `dims`.
fn cell(dims: [usize; 3], x: usize, y: usize, z: usize) -> usize {
    (z * dims[1] + y) * dims[0] + x
}

/// The 3×3×3 box sum of `count` over a grid of `dims`, separable along x, y, z.
fn box_sum(count: Vec<u32>, dims: [usize; 3]) -> Vec<u32> {
    let [nx, ny, nz] = dims;
    let id = |x: usize, y: usize, z: usize| cell(dims, x, y, z);
    // 3×3×3 box sum, separable along x, y, z.
    let mut a = count;
    let mut b = vec![0u32; a.len()];
    for axis in 0..3 {
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let c = [x, y, z];
                    let mut s = 0;
                    for d in [-1i64, 0, 1] {
                        let k = c[axis] as i64 + d;
                        if k < 0 || k >= dims[axis] as i64 {
                            continue;
                        }
                        let mut cc = c;
                        cc[axis] = k as usize;
                        s += a[id(cc[0], cc[1], cc[2])];
                    }
                    b[id(x, y, z)] = s;
                }
            }
        }
        std::mem::swap(&mut a, &mut b);
    }
    a
}

/// `occupied` dilated once (6-neighbourhood).
fn dilate(occupied: &[bool], dims: [usize; 3]) -> Vec<bool> {
    let [nx, ny, nz] = dims;
    let id = |x: usize, y: usize, z: usize| cell(dims, x, y, z);
    // Dilate once (6-neighbourhood).
    let mut solid = occupied.to_vec();
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                if occupied[id(x, y, z)] {
                    continue;
                }
                let near = (x > 0 && occupied[id(x - 1, y, z)])
                    || (x + 1 < nx && occupied[id(x + 1, y, z)])
                    || (y > 0 && occupied[id(x, y - 1, z)])
                    || (y + 1 < ny && occupied[id(x, y + 1, z)])
                    || (z > 0 && occupied[id(x, y, z - 1)])
                    || (z + 1 < nz && occupied[id(x, y, z + 1)]);
                solid[id(x, y, z)] = near;
            }
        }
    }
    solid
}

/// The empty cells connected to the grid's border (flood fill through
/// cells that are not `solid`).
fn flood_outside(solid: &[bool], dims: [usize; 3]) -> Vec<bool> {
    let [nx, ny, nz] = dims;
    let id = |x: usize, y: usize, z: usize| cell(dims, x, y, z);
    // Flood fill the empty space from the border.
    let mut outside = vec![false; solid.len()];
    let mut stack: Vec<(usize, usize, usize)> = Vec::new();
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let border =
                    x == 0 || y == 0 || z == 0 || x + 1 == nx || y + 1 == ny || z + 1 == nz;
                if border && !solid[id(x, y, z)] && !outside[id(x, y, z)] {
                    outside[id(x, y, z)] = true;
                    stack.push((x, y, z));
                }
            }
        }
    }
    while let Some((x, y, z)) = stack.pop() {
        let mut visit = |x: usize, y: usize, z: usize| {
            let c = id(x, y, z);
            if !solid[c] && !outside[c] {
                outside[c] = true;
                stack.push((x, y, z));
            }
        };
        if x > 0 {
            visit(x - 1, y, z);
        }
        if x + 1 < nx {
            visit(x + 1, y, z);
        }
        if y > 0 {
            visit(x, y - 1, z);
        }
        if y + 1 < ny {
            visit(x, y + 1, z);
        }
        if z > 0 {
            visit(x, y, z - 1);
        }
        if z + 1 < nz {
            visit(x, y, z + 1);
        }
    }
    outside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_interior_is_inside_and_far_space_outside() {
        let pts = crate::shapes::fibonacci_sphere(4000);
        let g = OutsideGrid::new(&pts, 0.1, 11, 1 << 20).unwrap();
        assert!(!g.is_outside(&Vec3::zeros()));
        assert!(!g.is_outside(&Vec3::new(0.5, 0.0, 0.0)));
        assert!(g.is_outside(&Vec3::new(1.3, 0.0, 0.0)));
        assert!(g.is_outside(&Vec3::new(5.0, 5.0, 5.0)));
        // Labels exist only on the grid: beyond it nothing was measured.
        assert_eq!(g.label(&Vec3::zeros()), Some(false));
        assert_eq!(g.label(&Vec3::new(5.0, 5.0, 5.0)), None);
        assert_eq!(g.label(&Vec3::new(-5.0, 0.0, 0.0)), None);
        // A bowl (lower hemisphere only): its opening is outside.
        let bowl: Vec<Vec3> = pts.iter().copied().filter(|p| p.z < 0.0).collect();
        let g = OutsideGrid::new(&bowl, 0.1, 11, 1 << 20).unwrap();
        assert!(g.is_outside(&Vec3::new(0.0, 0.0, -0.5)));
        // From inside the hollow, straight down meets the bowl's floor; up
        // leaves the grid through the opening.
        let p = Vec3::new(0.0, 0.0, -0.3);
        let down = g
            .distance_to_solid(&p, &Vec3::new(0.0, 0.0, -1.0), 2.0)
            .unwrap();
        assert!((down - 0.6).abs() < 0.25, "down {down}");
        assert_eq!(
            g.distance_to_solid(&p, &Vec3::new(0.0, 0.0, 1.0), 5.0),
            None
        );
        // A ray starting beyond the grid enters it and meets the shell; a
        // reach too short meets nothing.
        let far = Vec3::new(3.0, 0.0, -0.2);
        let west = Vec3::new(-1.0, 0.0, 0.0);
        let d = g.distance_to_solid(&far, &west, 5.0).unwrap();
        assert!((d - 2.0).abs() < 0.25, "from beyond the grid: {d}");
        assert_eq!(g.distance_to_solid(&far, &west, 1.0), None);
    }
}
