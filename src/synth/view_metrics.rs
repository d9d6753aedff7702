//! How well a reconstruction matches what a depth camera could know of the
//! true object (issue 20, deliver 6), as pure functions of meshes, poses and
//! intrinsics:
//!
//! - [`seen_side_accuracy`]: the share of the camera's rays that hit the true
//!   object and whose first hit on the reconstructed mesh lies within τ of
//!   the true depth (the visible side, where the data are), with the
//!   failed rays by kind: the mesh in front of the true surface, behind it
//!   (the object stands out of the mesh) or missed;
//! - [`volume_iou`]: the volume intersection over union of two closed meshes,
//!   by inside tests at the centres of a regular grid (the closure of the
//!   unseen side);
//! - [`pose_error`]: the rotation angle and translation between two poses
//!   (tracking drift);
//! - [`SurfaceSamples::pose_surface_error`]: the pose error as the true
//!   surface sees it (ADD-S): zero for a turn about an axis of symmetry;
//! - [`Coverage`]: the share of the object's surface seen so far over a
//!   sequence of views, on area-uniform surface samples.
//!
//! All ray queries use the first-hit caster of [`super::raycast`]; the
//! `_of` forms take meshes whose casters ([`CastMesh`]) are built once for
//! all the metrics of a frame.

use nalgebra::{Isometry3, Point3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::raycast::{MeshCaster, RaycastError};
use super::render::pixel_rect;
use super::Camera;
use crate::cloud::{Aabb, Vec3};
use crate::mesh::TriMesh;

/// A mesh with its ray-casting hierarchy, built once for every metric of
/// one frame ([`TruthRays`], [`points_outside_of`], [`volume_iou_of`]).
pub struct CastMesh<'a> {
    /// The mesh.
    pub mesh: &'a TriMesh,
    /// Its first-hit caster.
    pub caster: MeshCaster,
}

impl<'a> CastMesh<'a> {
    /// Build the caster of `mesh`.
    ///
    /// # Errors
    /// [`RaycastError`] when the mesh cannot be ray cast.
    pub fn new(mesh: &'a TriMesh) -> Result<Self, RaycastError> {
        Ok(Self {
            mesh,
            caster: MeshCaster::new(mesh)?,
        })
    }
}

/// Result of [`seen_side_accuracy`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SeenSide {
    /// Pixel rays whose first hit is on the true mesh (within the depth range).
    pub rays: usize,
    /// Of those, the rays whose first hit on the reconstruction is within τ
    /// of the true depth.
    pub within: usize,
    /// The rays on the silhouette's rim: one of the pixel's 8 neighbours
    /// misses the true object. There the ray grazes the surface, and a
    /// lateral error of a fraction of a millimetre is a depth error beyond
    /// τ (on the turning capsule, 11 % of the rays, and most of the misses).
    pub rim_rays: usize,
    /// Of those, the rays within τ.
    pub rim_within: usize,
    /// Failed rays whose first hit on the reconstruction lies more than τ
    /// in front of the true surface: the mesh bulges towards the camera.
    pub in_front: usize,
    /// Failed rays whose first hit lies more than τ behind the true
    /// surface: there the object stands out of the mesh (what a planner
    /// would collide with).
    pub behind: usize,
}

impl SeenSide {
    /// `within / rays`, `None` when the camera does not see the object.
    pub fn accuracy(&self) -> Option<f64> {
        share(self.within, self.rays)
    }

    /// The accuracy on the silhouette's rim alone.
    pub fn rim_accuracy(&self) -> Option<f64> {
        share(self.rim_within, self.rim_rays)
    }

    /// The accuracy inside the rim.
    pub fn inner_accuracy(&self) -> Option<f64> {
        share(self.within - self.rim_within, self.rays - self.rim_rays)
    }

    /// Failed rays that miss the reconstruction altogether (its
    /// silhouette is narrower than the object's there).
    pub fn missed(&self) -> usize {
        self.rays - self.within - self.in_front - self.behind
    }
}

/// The counts of both (the rays of two rows, or of two frames).
impl std::ops::Add for SeenSide {
    type Output = Self;

    fn add(self, o: Self) -> Self {
        Self {
            rays: self.rays + o.rays,
            within: self.within + o.within,
            rim_rays: self.rim_rays + o.rim_rays,
            rim_within: self.rim_within + o.rim_within,
            in_front: self.in_front + o.in_front,
            behind: self.behind + o.behind,
        }
    }
}

/// `part / of`, `None` for `of = 0`.
fn share(part: usize, of: usize) -> Option<f64> {
    (of > 0).then(|| part as f64 / of as f64)
}

/// Seen-side depth accuracy of `recon` against `truth`, both in the camera's
/// optical frame: over the pixel rays of `camera` that hit `truth` within the
/// camera's depth range, the share whose first hit on `recon` has a depth
/// (camera z) within `tau` of the true one.
///
/// # Errors
/// [`RaycastError`] when either mesh cannot be ray cast.
pub fn seen_side_accuracy(
    camera: &Camera,
    truth: &TriMesh,
    recon: &TriMesh,
    tau: f64,
) -> Result<SeenSide, RaycastError> {
    let (truth, recon) = (CastMesh::new(truth)?, CastMesh::new(recon)?);
    Ok(seen_side_accuracy_of(camera, &truth, &recon, tau))
}

/// [`seen_side_accuracy`] on meshes whose casters are built.
pub fn seen_side_accuracy_of(
    camera: &Camera,
    truth: &CastMesh<'_>,
    recon: &CastMesh<'_>,
    tau: f64,
) -> SeenSide {
    TruthRays::new(camera, truth, recon).seen_side(recon, tau)
}

/// The true object's first hit on each pixel ray of `camera` over the
/// image rectangle of the true object and a reconstruction, cast once for
/// the frame's [`SeenSide`] and [`SilhouetteExcess`].
pub struct TruthRays<'c> {
    camera: &'c Camera,
    /// The pixel rectangle `(i0, i1, j0, j1)`, `None` when out of view.
    rect: Option<(usize, usize, usize, usize)>,
    /// Row by row over `rect`: the ray parameter of the true first hit,
    /// when it lies within the camera's depth range.
    hits: Vec<Vec<Option<f64>>>,
}

impl<'c> TruthRays<'c> {
    /// Cast `truth` (in the camera's optical frame) over the rectangle of
    /// both `truth` and `recon`.
    pub fn new(camera: &'c Camera, truth: &CastMesh<'_>, recon: &CastMesh<'_>) -> Self {
        let mut bounds = truth.mesh.aabb();
        let r = recon.mesh.aabb();
        bounds.min = bounds.min.inf(&r.min);
        bounds.max = bounds.max.sup(&r.max);
        let rect = pixel_rect(camera, &Isometry3::identity(), &bounds);
        let hits = rect.map_or_else(Vec::new, |(i0, i1, j0, j1)| {
            (j0..=j1)
                .into_par_iter()
                .map(|j| (i0..=i1).map(|i| first_hit(camera, truth, i, j)).collect())
                .collect()
        });
        Self { camera, rect, hits }
    }

    /// The seen-side accuracy of `recon` ([`seen_side_accuracy`]).
    pub fn seen_side(&self, recon: &CastMesh<'_>, tau: f64) -> SeenSide {
        let Some((i0, _, j0, _)) = self.rect else {
            return SeenSide::default();
        };
        let origin = Vec3::zeros();
        self.hits
            .par_iter()
            .enumerate()
            .map(|(b, row)| {
                let mut c = SeenSide::default();
                for (a, t) in row.iter().enumerate() {
                    let Some(t) = *t else { continue };
                    let d = self.camera.pixel_ray(i0 + a, j0 + b);
                    let near = recon.caster.first_hit(&origin, &d, f64::INFINITY);
                    let off = near.map(|g| g.t - t);
                    let ok = off.is_some_and(|e| e.abs() <= tau);
                    let rim = self.on_rim(a, b);
                    c.rays += 1;
                    c.within += usize::from(ok);
                    c.rim_rays += usize::from(rim);
                    c.rim_within += usize::from(rim && ok);
                    c.in_front += usize::from(off.is_some_and(|e| e < -tau));
                    c.behind += usize::from(off.is_some_and(|e| e > tau));
                }
                c
            })
            .reduce(SeenSide::default, |a, b| a + b)
    }

    /// Whether the true hit at `(a, b)` of the rectangle has a neighbour
    /// (of 8, beyond the rectangle included) that misses the true object.
    fn on_rim(&self, a: usize, b: usize) -> bool {
        self.around(a, b).any(|hit| !hit)
    }

    /// Whether the true object is hit at `(a, b)` of the rectangle or one
    /// of its 8 neighbours.
    fn near_truth(&self, a: usize, b: usize) -> bool {
        self.around(a, b).any(|hit| hit)
    }

    /// Whether each ray of the 3×3 block around `(a, b)` of the rectangle
    /// hits the true object (none beyond the rectangle does).
    fn around(&self, a: usize, b: usize) -> impl Iterator<Item = bool> + '_ {
        let hit = |x: Option<usize>, y: Option<usize>| {
            let row = y.and_then(|y| self.hits.get(y));
            row.and_then(|r| r.get(x?)).is_some_and(Option::is_some)
        };
        (-1..=1).flat_map(move |dy: isize| {
            (-1..=1).map(move |dx: isize| hit(a.checked_add_signed(dx), b.checked_add_signed(dy)))
        })
    }

    /// The silhouette excess of `recon` ([`silhouette_excess_of`]).
    pub fn silhouette_excess(&self, recon: &CastMesh<'_>) -> SilhouetteExcess {
        let Some((i0, i1, j0, _)) = self.rect else {
            return SilhouetteExcess {
                silhouette: 0,
                excess: 0,
            };
        };
        let (width, rows) = (i1 - i0 + 1, self.hits.len());
        let excess = (0..rows)
            .into_par_iter()
            .map(|b| {
                (0..width)
                    .filter(|&a| {
                        !self.near_truth(a, b)
                            && first_hit(self.camera, recon, i0 + a, j0 + b).is_some()
                    })
                    .count()
            })
            .sum();
        let silhouette = self.hits.iter().flatten().filter(|h| h.is_some()).count();
        SilhouetteExcess { silhouette, excess }
    }
}

/// The ray parameter of `mesh`'s first hit on the ray of pixel `(i, j)`,
/// when it lies within the camera's depth range.
fn first_hit(camera: &Camera, mesh: &CastMesh<'_>, i: usize, j: usize) -> Option<f64> {
    let d = camera.pixel_ray(i, j);
    mesh.caster
        .first_hit(&Vec3::zeros(), &d, camera.max_depth)
        .map(|h| h.t)
        .filter(|&t| t >= camera.min_depth)
}

/// Result of [`silhouette_excess_of`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SilhouetteExcess {
    /// Pixel rays that hit the true object within the depth range.
    pub silhouette: usize,
    /// Pixel rays that hit the reconstruction while neither they nor any of
    /// their 8 neighbours hit the true object.
    pub excess: usize,
}

impl SilhouetteExcess {
    /// `excess / silhouette`, `None` when the camera does not see the object.
    pub fn share(&self) -> Option<f64> {
        share(self.excess, self.silhouette)
    }
}

/// The reconstruction's projection beyond the true object's silhouette in
/// `camera`'s view (the robot's-view issue: "the mesh's projection stays
/// inside the object's silhouette in every view"): the pixel rays that hit
/// `recon` within the camera's depth range while neither they nor their 8
/// neighbours hit `truth` (one pixel of slack for the silhouette's own
/// sampling), against the rays that hit `truth`. Both meshes are in the
/// camera's optical frame.
pub fn silhouette_excess_of(
    camera: &Camera,
    truth: &CastMesh<'_>,
    recon: &CastMesh<'_>,
) -> SilhouetteExcess {
    TruthRays::new(camera, truth, recon).silhouette_excess(recon)
}

/// Result of [`points_outside`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointsOutside {
    /// Points on the true surface: within `k`·σ(z) of it (the others are
    /// the sensor's outliers and flying pixels).
    pub on_surface: usize,
    /// Of those, the points outside the mesh by more than `k`·σ(z).
    pub outside: usize,
    /// The largest distance outside the mesh of any of them, in units of
    /// its σ(z) (0 when none lies outside the mesh).
    pub worst_sigmas: f64,
}

impl PointsOutside {
    /// The share of the on-surface points outside the mesh by more than
    /// `k`·σ(z) (`None` without on-surface points).
    pub fn share(&self) -> Option<f64> {
        (self.on_surface > 0).then(|| self.outside as f64 / self.on_surface as f64)
    }
}

/// The visible points that the mesh leaves out (issue 20: "no visible point
/// may lie outside the mesh by more than the noise"): of `points` (cloud
/// frame, the camera at the origin looking along +z) those within
/// `k`·σ(z) of the true surface `truth`, the ones outside the closed `mesh`
/// and farther than `k`·σ(z) from it, with `sigma` the sensor's axial noise
/// at depth z.
///
/// # Errors
/// [`RaycastError`] when either mesh cannot be ray cast.
pub fn points_outside(
    points: &[Vec3],
    truth: &TriMesh,
    mesh: &TriMesh,
    sigma: impl Fn(f64) -> f64 + Sync,
    k: f64,
) -> Result<PointsOutside, RaycastError> {
    let (truth, mesh) = (CastMesh::new(truth)?, CastMesh::new(mesh)?);
    Ok(points_outside_of(points, &truth, &mesh, sigma, k))
}

/// [`points_outside`] on meshes whose casters are built.
pub fn points_outside_of(
    points: &[Vec3],
    truth: &CastMesh<'_>,
    mesh: &CastMesh<'_>,
    sigma: impl Fn(f64) -> f64 + Sync,
    k: f64,
) -> PointsOutside {
    let (truth, mesh) = (&truth.caster, &mesh.caster);
    let per_point = |p: &Vec3| -> (usize, usize, f64) {
        let s = sigma(p.z).max(f64::MIN_POSITIVE);
        if !(p.iter().all(|c| c.is_finite()) && truth.distance(p) <= k * s) {
            return (0, 0, 0.0);
        }
        if mesh.contains(p) {
            return (1, 0, 0.0);
        }
        let d = mesh.distance(p) / s;
        (1, usize::from(d > k), d)
    };
    let (on_surface, outside, worst_sigmas) = points
        .par_iter()
        .map(per_point)
        .reduce(|| (0, 0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1, a.2.max(b.2)));
    PointsOutside {
        on_surface,
        outside,
        worst_sigmas,
    }
}

/// Result of [`volume_iou`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeIou {
    /// Volume inside `a` (m³, grid estimate).
    pub volume_a: f64,
    /// Volume inside `b`.
    pub volume_b: f64,
    /// Volume inside both.
    pub intersection: f64,
}

impl VolumeIou {
    /// Intersection over union, `None` when both are empty.
    pub fn iou(&self) -> Option<f64> {
        let union = self.volume_a + self.volume_b - self.intersection;
        (union > 0.0).then(|| self.intersection / union)
    }
}

/// Volume IoU of the closed meshes `a` and `b` (same frame), by inside tests
/// at the cell centres of a grid over their joint bounding box with `cells`
/// cells along its longest edge (the error falls as 1/`cells`).
///
/// # Errors
/// [`RaycastError`] when either mesh cannot be ray cast, or `cells` is 0 or
/// above 1000.
pub fn volume_iou(a: &TriMesh, b: &TriMesh, cells: usize) -> Result<VolumeIou, RaycastError> {
    volume_iou_of(&CastMesh::new(a)?, &CastMesh::new(b)?, cells)
}

/// [`volume_iou`] on meshes whose casters are built.
///
/// # Errors
/// As [`volume_iou`], for the grid.
pub fn volume_iou_of(
    a: &CastMesh<'_>,
    b: &CastMesh<'_>,
    cells: usize,
) -> Result<VolumeIou, RaycastError> {
    if cells == 0 || cells > 1000 {
        return Err(RaycastError::BadMesh(format!(
            "grid of {cells} cells: need 1..=1000"
        )));
    }
    let (ca, cb) = (&a.caster, &b.caster);
    let mut bb: Aabb = a.mesh.aabb();
    b.mesh.vertices.iter().for_each(|v| bb.grow(v));
    let h = bb.longest_edge() / cells as f64;
    if !(h > 0.0 && h.is_finite()) {
        return Err(RaycastError::BadMesh("meshes without extent".into()));
    }
    let n = bb.extent().map(|e| ((e / h).ceil() as usize).max(1));
    let counts = (0..n.z)
        .into_par_iter()
        .map(|k| {
            let mut c = [0usize; 3];
            for j in 0..n.y {
                for i in 0..n.x {
                    let p = bb.min + Vec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * h;
                    let (ia, ib) = (ca.contains(&p), cb.contains(&p));
                    c[0] += usize::from(ia);
                    c[1] += usize::from(ib);
                    c[2] += usize::from(ia && ib);
                }
            }
            c
        })
        .reduce(|| [0; 3], |x, y| [x[0] + y[0], x[1] + y[1], x[2] + y[2]]);
    let cell = h * h * h;
    Ok(VolumeIou {
        volume_a: counts[0] as f64 * cell,
        volume_b: counts[1] as f64 * cell,
        intersection: counts[2] as f64 * cell,
    })
}

/// Rotation and translation between an estimated and a true pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// Angle of `R_est⁻¹ · R_true` (rad, in `[0, π]`).
    pub rotation_rad: f64,
    /// `|t_est − t_true|` (m).
    pub translation_m: f64,
}

/// The error of `estimate` against `truth` (both object frame → same frame).
pub fn pose_error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> PoseError {
    PoseError {
        rotation_rad: estimate.rotation.angle_to(&truth.rotation),
        translation_m: (estimate.translation.vector - truth.translation.vector).norm(),
    }
}

/// Area-uniform samples of a true surface (object frame), with their
/// triangles' normals, and the surface's caster.
#[derive(Debug, Clone)]
pub struct SurfaceSamples {
    caster: MeshCaster,
    samples: Vec<(Vec3, Vec3)>,
}

impl SurfaceSamples {
    /// `samples` area-uniform points of `mesh` (deterministic for `seed`).
    ///
    /// # Errors
    /// [`RaycastError`] when the mesh cannot be ray cast or has no area.
    pub fn new(mesh: &TriMesh, samples: usize, seed: u64) -> Result<Self, RaycastError> {
        let caster = MeshCaster::new(mesh)?;
        let mut cumulative = Vec::with_capacity(mesh.triangles.len());
        let mut total = 0.0;
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(t);
            total += 0.5 * (b - a).cross(&(c - a)).norm();
            cumulative.push(total);
        }
        if !(total > 0.0 && total.is_finite()) {
            return Err(RaycastError::BadMesh("no surface area".into()));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let samples = (0..samples)
            .map(|_| {
                let x = rng.random::<f64>() * total;
                let t = cumulative
                    .partition_point(|&c| c < x)
                    .min(cumulative.len() - 1);
                let [a, b, c] = mesh.corners(t);
                let (mut u, mut v) = (rng.random::<f64>(), rng.random::<f64>());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                (a + (b - a) * u + (c - a) * v, caster.normal(t as u32))
            })
            .collect();
        Ok(Self { caster, samples })
    }

    /// The samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// ADD-S of `estimate` against `truth` (both object frame → camera; the
    /// symmetric average distance of Xiang et al. 2018, PoseCNN): the mean
    /// distance from each sample, placed by `estimate` and taken back by
    /// `truth`, to the true surface. A tracked pose that differs from the
    /// truth only by a turn about an axis of symmetry (a bottle about its
    /// own axis) places the surface where it is and scores 0, where
    /// [`pose_error`] reports the turn; 0 without samples.
    pub fn pose_surface_error(&self, estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> f64 {
        if self.samples.is_empty() {
            return 0.0;
        }
        let back = truth.inverse() * estimate;
        let sum: f64 = self
            .samples
            .par_iter()
            .map(|(p, _)| self.caster.distance(&(back * Point3::from(*p)).coords))
            .sum();
        sum / self.samples.len() as f64
    }
}

/// The share of an object's surface seen so far: area-uniform samples of
/// the mesh (object frame), each marked once a view sees it (in the image,
/// within the depth range, not beyond `max_incidence_deg`, and the first
/// surface along its pixel ray).
#[derive(Debug, Clone)]
pub struct Coverage {
    surface: SurfaceSamples,
    seen: Vec<bool>,
    cos_min: f64,
}

impl Coverage {
    /// `samples` area-uniform points of `mesh` (deterministic for `seed`).
    ///
    /// # Errors
    /// [`RaycastError`] when the mesh cannot be ray cast or has no area.
    pub fn new(
        mesh: &TriMesh,
        samples: usize,
        max_incidence_deg: f64,
        seed: u64,
    ) -> Result<Self, RaycastError> {
        let surface = SurfaceSamples::new(mesh, samples, seed)?;
        Ok(Self {
            seen: vec![false; surface.len()],
            surface,
            cos_min: max_incidence_deg.to_radians().cos().max(1e-9),
        })
    }

    /// The surface samples the coverage marks.
    pub fn surface(&self) -> &SurfaceSamples {
        &self.surface
    }

    /// Mark the samples that `camera` sees with the object at `pose`
    /// (object frame → optical frame). Returns how many this view saw.
    pub fn observe(&mut self, camera: &Camera, pose: &Isometry3<f64>) -> usize {
        let inv = pose.inverse();
        let eye = inv.translation.vector;
        let (w, h) = (camera.width as f64, camera.height as f64);
        let mut n = 0;
        let SurfaceSamples { caster, samples } = &self.surface;
        for ((p, normal), seen) in samples.iter().zip(self.seen.iter_mut()) {
            let q = (pose * Point3::from(*p)).coords;
            let Some((u, v)) = camera.project(&q) else {
                continue;
            };
            if !(0.0..w).contains(&u) || !(0.0..h).contains(&v) {
                continue;
            }
            if q.z < camera.min_depth || q.z > camera.max_depth {
                continue;
            }
            let dir = p - eye;
            let cos = (normal.dot(&dir) / dir.norm()).abs();
            if cos.is_nan() || cos < self.cos_min {
                continue;
            }
            // Unit parameter at the sample: a nearer hit hides it.
            let first = caster.first_hit(&eye, &dir, 1.0 + 1e-9);
            if first.is_some_and(|f| f.t >= 1.0 - 1e-6) {
                n += 1;
                *seen = true;
            }
        }
        n
    }

    /// Share of the samples seen by any view so far.
    pub fn share(&self) -> f64 {
        if self.seen.is_empty() {
            return 0.0;
        }
        self.seen.iter().filter(|&&s| s).count() as f64 / self.seen.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A sphere of radius `r` centred at `c` (cube-lattice tessellation).
    fn sphere(r: f64, c: Vec3) -> TriMesh {
        let mut m = crate::shapes::sphere(96).unwrap().mesh;
        for v in &mut m.vertices {
            *v = c + *v * (2.0 * r);
        }
        m
    }

    #[test]
    fn points_outside_count_the_surface_points_a_smaller_mesh_leaves_out() {
        let c = Vec3::new(0.0, 0.0, 1.0);
        let truth = sphere(0.1, c);
        // The camera-side cap of the true sphere, and two outliers 5 cm off.
        let mut points: Vec<Vec3> = crate::shapes::fibonacci_sphere(400)
            .into_iter()
            .filter(|d| d.z < 0.0)
            .map(|d| c + d * 0.1)
            .collect();
        let cap = points.len();
        points.push(c + Vec3::new(0.0, 0.0, -0.15));
        points.push(c + Vec3::new(0.15, 0.0, 0.0));
        let sigma = |_z: f64| 0.002;
        // The true mesh leaves nothing out (the lattice's flat facets lie
        // within 0.1 mm of the sphere).
        let exact = points_outside(&points, &truth, &truth, sigma, 3.0).unwrap();
        assert_eq!(exact.on_surface, cap);
        assert_eq!((exact.outside, exact.share()), (0, Some(0.0)));
        // 5 mm smaller (2.5 σ): outside, but within 3 σ; 8 mm smaller (4 σ):
        // every point is left out, by about 4 σ.
        let near = points_outside(&points, &truth, &sphere(0.095, c), sigma, 3.0).unwrap();
        assert_eq!(near.outside, 0);
        assert!((near.worst_sigmas - 2.5).abs() < 0.1, "{near:?}");
        let far = points_outside(&points, &truth, &sphere(0.092, c), sigma, 3.0).unwrap();
        assert_eq!((far.outside, far.share()), (cap, Some(1.0)));
        assert!((far.worst_sigmas - 4.0).abs() < 0.1, "{far:?}");
        // A larger mesh holds every point.
        let big = points_outside(&points, &truth, &sphere(0.11, c), sigma, 3.0).unwrap();
        assert_eq!((big.outside, big.worst_sigmas), (0, 0.0));
    }

    #[test]
    fn seen_side_of_a_sphere_against_itself_offsets_and_a_shrunk_copy() {
        let cam = Camera::kinect();
        let c = Vec3::new(0.0, 0.0, 1.0);
        let truth = sphere(0.1, c);
        let exact = seen_side_accuracy(&cam, &truth, &truth, 1e-6).unwrap();
        // The disc of pixels seen: π (f r / √(d² − r²))².
        let disc = PI * (525.0 * 0.1 / (1.0f64 - 0.01).sqrt()).powi(2);
        assert!(
            (exact.rays as f64 - disc).abs() < 0.02 * disc,
            "{exact:?} vs {disc}"
        );
        assert_eq!(exact.accuracy(), Some(1.0));
        // A sphere 2 mm smaller: every central ray is 2 mm off, so τ = 1 mm
        // rejects the rays where the depth gap exceeds it (all of them: the
        // gap is ≥ 2 mm along every ray) and τ = 3 mm accepts the rays whose
        // gap is ≤ 3 mm, i.e. those whose ray meets the small sphere at
        // angles where 0.1·cosθ − √(0.098² − 0.1² sin²θ) ≤ 0.003.
        let small = sphere(0.098, c);
        let tight = seen_side_accuracy(&cam, &truth, &small, 0.001).unwrap();
        assert_eq!(tight.rays, exact.rays);
        assert_eq!(tight.accuracy(), Some(0.0));
        let loose = seen_side_accuracy(&cam, &truth, &small, 0.003).unwrap();
        let a = loose.accuracy().unwrap();
        // Analytic share (parallel-ray approximation at 1 m): the gap along a
        // ray at image radius ρ (m on the sphere) is √(R² − ρ²) − √(r² − ρ²);
        // it is ≤ 3 mm for ρ² ≤ ρ₀² with ρ₀² solved below.
        let (rr, r2, g) = (0.1f64, 0.098f64, 0.003f64);
        // √(R² − ρ²) − √(r² − ρ²) = g  ⇒  ρ₀² = R² − ((R² − r² + g²)/(2g))².
        let rho0_sq = rr * rr - ((rr * rr - r2 * r2 + g * g) / (2.0 * g)).powi(2);
        let want = rho0_sq / (rr * rr);
        assert!((a - want).abs() < 0.05, "{a} vs {want}");
        // Offset by 5 mm along the view axis: no ray within 1 mm.
        let behind = sphere(0.1, c + Vec3::new(0.0, 0.0, 0.005));
        assert_eq!(
            seen_side_accuracy(&cam, &truth, &behind, 0.001)
                .unwrap()
                .within,
            0
        );
    }

    #[test]
    fn silhouette_excess_counts_the_mesh_seen_beyond_the_true_outline() {
        let cam = Camera::kinect();
        let c = Vec3::new(0.0, 0.0, 1.0);
        let truth = sphere(0.1, c);
        let cast = |m: &TriMesh| {
            let (t, r) = (CastMesh::new(&truth).unwrap(), CastMesh::new(m).unwrap());
            silhouette_excess_of(&cam, &t, &r)
        };
        let exact = cast(&truth);
        assert_eq!(exact.excess, 0, "{exact:?}");
        // The disc of pixels seen: π (f r / √(d² − r²))².
        let disc = PI * (525.0 * 0.1 / (1.0f64 - 0.01).sqrt()).powi(2);
        assert!((exact.silhouette as f64 - disc).abs() < 0.02 * disc);
        // Smaller, or behind the object within its outline: nothing beyond.
        assert_eq!(cast(&sphere(0.09, c)).excess, 0);
        assert_eq!(cast(&sphere(0.05, c + Vec3::new(0.0, 0.0, 0.2))).excess, 0);
        // 20 % larger: the ring between the outlines, less one pixel, about
        // 1.2² − 1 of the disc.
        let big = cast(&sphere(0.12, c)).share().unwrap();
        assert!((0.38..0.46).contains(&big), "{big}");
        // A lobe beside the object: all of its disc.
        let lobe = sphere(0.03, c + Vec3::new(0.2, 0.0, 0.0));
        let share = cast(&lobe).share().unwrap();
        let want = (0.03f64 / 0.1).powi(2);
        assert!((share - want).abs() < 0.02, "{share} vs {want}");
    }

    #[test]
    fn volume_iou_of_offset_spheres_matches_the_lens_formula() {
        let r = 0.1;
        let d = 0.08;
        let a = sphere(r, Vec3::zeros());
        let b = sphere(r, Vec3::new(d, 0.0, 0.0));
        let v = volume_iou(&a, &b, 80).unwrap();
        let ball = 4.0 / 3.0 * PI * r * r * r;
        let lens = PI * (4.0 * r + d) * (2.0 * r - d).powi(2) / 12.0;
        let want = lens / (2.0 * ball - lens);
        assert!(
            (v.volume_a - ball).abs() < 0.02 * ball,
            "{} vs {ball}",
            v.volume_a
        );
        assert!(
            (v.iou().unwrap() - want).abs() < 0.02,
            "{:?} vs {want}",
            v.iou()
        );
        let same = volume_iou(&a, &a, 40).unwrap();
        assert_eq!(same.iou(), Some(1.0));
        let apart = volume_iou(&a, &sphere(r, Vec3::new(0.3, 0.0, 0.0)), 40).unwrap();
        assert_eq!(apart.iou(), Some(0.0));
        assert!(volume_iou(&a, &b, 0).is_err());
    }

    #[test]
    fn pose_error_is_the_relative_angle_and_offset() {
        let truth = Isometry3::new(Vec3::new(0.1, 0.2, 1.0), Vec3::new(0.0, 0.3, 0.0));
        let est = Isometry3::new(Vec3::new(0.1, 0.23, 0.96), Vec3::new(0.0, 0.3, 0.1));
        let e = pose_error(&est, &truth);
        assert!((e.translation_m - 0.05).abs() < 1e-12);
        // Rotations about y by 0.3 and about (0, 0.3, 0.1): their relative angle.
        let rel = est.rotation.inverse() * truth.rotation;
        assert!((e.rotation_rad - rel.angle()).abs() < 1e-12);
        let quarter = Isometry3::new(Vec3::zeros(), Vec3::new(0.0, 0.0, PI / 2.0));
        let e = pose_error(&quarter, &Isometry3::identity());
        assert!((e.rotation_rad - PI / 2.0).abs() < 1e-12);
        assert_eq!(e.translation_m, 0.0);
    }

    #[test]
    fn pose_surface_error_ignores_a_turn_about_an_axis_of_symmetry() {
        let truth = Isometry3::new(Vec3::new(0.05, -0.02, 0.9), Vec3::new(0.2, 0.5, 0.0));
        let turned = |axis: Vec3| truth * Isometry3::new(Vec3::zeros(), axis);
        // A ball turned about its centre by 90°: pose_error sees the turn,
        // the surface does not (within the lattice's facets, 0.1 mm).
        let ball = SurfaceSamples::new(&sphere(0.1, Vec3::zeros()), 4000, 1).unwrap();
        let est = turned(Vec3::new(0.0, 0.0, PI / 2.0));
        assert!((pose_error(&est, &truth).rotation_rad - PI / 2.0).abs() < 1e-9);
        assert!(ball.pose_surface_error(&est, &truth) < 1e-4);
        assert!(ball.pose_surface_error(&truth, &truth) < 1e-12);
        // Shifted by s ≪ r: a sample at angle θ to the shift lies
        // s·|cos θ| off the sphere, s/2 on average over the sphere.
        let s = 0.004;
        let shifted = Isometry3::translation(s, 0.0, 0.0) * truth;
        let e = ball.pose_surface_error(&shifted, &truth);
        assert!((e - s / 2.0).abs() < 0.1 * s, "{e}");
        // The ellipsoid (0.5 × 0.35 × 0.25) has no axis of symmetry: turned
        // by 90° about its shortest axis its long ends stand 0.15 m out.
        let ell = crate::shapes::ellipsoid(32).unwrap().mesh;
        let ell = SurfaceSamples::new(&ell, 4000, 1).unwrap();
        let e = ell.pose_surface_error(&turned(Vec3::new(0.0, 0.0, PI / 2.0)), &truth);
        assert!(e > 0.03, "{e}");
        // The can (a surface of revolution about z, 64 facets around)
        // turned about its own axis stays within its facets' chords (0.3
        // mm); turned about x it does not.
        let can = SurfaceSamples::new(&crate::shapes::can(64).unwrap().mesh, 4000, 1).unwrap();
        let about_own = can.pose_surface_error(&turned(Vec3::new(0.0, 0.0, 1.0)), &truth);
        let about_x = can.pose_surface_error(&turned(Vec3::new(0.3, 0.0, 0.0)), &truth);
        assert!(about_own < 0.005 && about_x > 0.03, "{about_own} {about_x}");
    }

    #[test]
    fn coverage_of_a_sphere_is_the_visible_cap_then_both_caps() {
        // From distance D a sphere of radius r shows the cap of height
        // r − r²/D: the share (1 − r/D)/2 of its area.
        let r = 0.1;
        let mesh = sphere(r, Vec3::zeros());
        let mut cov = Coverage::new(&mesh, 20_000, 90.0, 3).unwrap();
        let cam = Camera::kinect();
        let d = 0.5;
        let front = Isometry3::translation(0.0, 0.0, d);
        cov.observe(&cam, &front);
        let cap = (1.0 - r / d) / 2.0;
        assert!(
            (cov.share() - cap).abs() < 0.015,
            "{} vs {cap}",
            cov.share()
        );
        // The same view again adds nothing; the opposite view adds its own cap.
        cov.observe(&cam, &front);
        assert!((cov.share() - cap).abs() < 0.015);
        let back = Isometry3::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, d),
            nalgebra::UnitQuaternion::from_scaled_axis(Vec3::new(0.0, PI, 0.0)),
        );
        cov.observe(&cam, &back);
        assert!((cov.share() - 2.0 * cap).abs() < 0.02, "{}", cov.share());
    }
}
