//! The published mesh's seen side, moved along the camera's rays onto the
//! frame's own points (`pipeline.snap`).
//!
//! The membrane's surface is a smooth B-spline on a coarse control net,
//! evolved on the fused model: where the camera sees the object, it lies off
//! the frame's points by the tracked pose's error, the net's smoothing and
//! the model's blur of earlier views. The seen-side accuracy (the share of
//! the camera's rays whose first hit on the mesh is within τ of the true
//! depth) counts every such offset above τ.
//!
//! Each vertex of the published mesh that faces the eye is moved along its
//! ray to the depth of the frame's points there: a least-squares quadric
//! `z = c₀ + c₁u + c₂v + c₃u² + c₄uv + c₅v²` of the points' depth over
//! their lateral offsets `(u, v)` from the ray, within `radius_delta`·δ of
//! it, gives the depth `c₀`.
//!
//! The points are binned first, by direction from the eye, in bins of a
//! quarter of that radius (at the points' centroid), and the quadric is
//! fitted to the centroids of the bins within the radius, each weighted by
//! its count: a frame's cost then does not grow with its density. On one
//! core: 6 k points +1.0 ms at the median, 20 k +1.5 ms; fitting the points
//! themselves, +1.2 and +2.7 ms for a seen-side median of 0.940 against
//! 0.939 over the 43 sequences below; bins of a half or a third of the
//! radius gave 0.926 and 0.936.
//!
//! A quadric, not a plane: with a plane over windows of 1–2δ the turning
//! bent tube's seen-side median fell 0.855 → 0.41–0.73 (the plane cuts
//! through the tube's curve), and a window of 0.5δ, too small to average
//! the noise, gained 0.01 only.
//!
//! A vertex moves only when the window holds at least `min_points` points,
//! the move is at most `max_move_delta`·δ (a vertex far from the points is
//! not on the seen surface: an occluded face, the unseen side) and the
//! fit's RMS residual is at most `rms_factor` times the median over the
//! frame's fits (a window across a depth edge, such as a mug's rim over
//! its inside, fits no quadric). A ray that grazes the surface moves its
//! vertex mostly across the surface, and the vertices of one triangle then
//! cross: the part of a move across the vertex's normal is capped at
//! `max_slide` times its mean edge length (the move scaled down). Over the
//! 30 frames of the committed turning box and bent tube the triangles whose
//! normal flips fell 1 592 → 1 076 and 4 711 → 2 187 (0.25: 502 and 1 136,
//! but the tube's visible points > 3σ outside no longer fell), for a
//! seen-side median over the 43 sequences below of 0.936 against 0.939
//! uncapped, with the same mean F. What still folds is taken back
//! ([`keep_orientation`]): a vertex of a triangle that the moves turned over
//! has its move halved, twice at most, then undone, so the published mesh
//! never holds a triangle the snap turned over (before, 1 076, 2 187, 1 487
//! and 4 677 of them over the 30 frames of the committed turning box, bent
//! tube and capsule and orbited YCB banana, 0.8–3.9 % of the triangles);
//! over the 43 sequences the seen-side median stays 0.936 (mean 0.912 →
//! 0.910, the orbited banana 0.705 → 0.686), the median share of visible
//! points > 3σ outside 0.33 % → 0.34 %.
//!
//! The contour (`contour`): the points sit on pixel rays, and the object's
//! silhouette lies between the outermost pixel that sees it and the first
//! that does not, so a membrane through the points stops inside it, and the
//! rays on the silhouette's rim (most of the seen side's failures: on the
//! turning box 3 029 of its 8 203 failed rays missed the mesh there) pass
//! beside the mesh. A vertex whose normal is nearly square to its ray
//! (cosine within [`CONTOUR_COS`]) and that no fit moved moves outward across
//! its ray by `offset` times the frame's point spacing ([`point_spacing`]).
//! Over the 43 sequences, { offset: 0.4 } against null: seen-side median
//! 0.936 → 0.940 (mean 0.910 → 0.914), higher on 42 of 43 (the turning YCB
//! banana −0.001); mean last-third F 0.8241 → 0.8248, visible points > 3σ
//! outside unchanged (median share 0.34 %); but the meshes grow: sequences
//! with a frame above 1.5× the true volume 7 → 11 (the bent tubes' largest
//! ratio 1.46–1.58 → 1.48–1.61). With the band reaching cosine −0.3 (behind
//! the contour): seen side 0.943, mean F 0.8231 (capsules −0.03 to −0.05),
//! 13 above 1.5×; offset 0.5 there (half a pixel): 0.945, mean F 0.818.
//! Moving contour vertices onto the
//! outermost points of their windows instead turned the misses into hits in
//! front of the true depth (the box 0.942 → 0.938). Like
//! `membrane.step.unbias`, only the
//! published mesh moves: the tracking and the next warm start keep the
//! membrane's own surface.
//!
//! Measured on the 43 sensor-true sequences of `benches/robot_view_eval.sh`
//! (same tracking, so the meshes differ by this move alone), against null:
//! - seen-side median 0.918 → 0.936, higher on 41 of 43 (two balls 0.001–
//!   0.002 lower); the orbited YCB banana 0.614 → 0.705;
//! - visible points more than 3σ outside the mesh (median share) 0.37 % →
//!   0.33 % (the orbited banana 12 % → 9.8 %), lower on 40 of 43;
//! - mean last-third F 0.820 → 0.825 (median 0.870 → 0.872);
//! - without the residual test the orbited mugs' seen side fell 0.80 →
//!   0.76 (their rims); with it it rises to 0.82–0.87;
//! - cost: about 1 ms per frame on one core (above).

use crate::cloud::Vec3;
use crate::gnomonic::ViewFrame;
use crate::mesh::TriMesh;
use nalgebra::{Matrix6, Vector6};
use serde::{Deserialize, Serialize};

/// `pipeline.snap`: the seen side of the published mesh moved onto the
/// frame's points (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SnapConfig {
    /// Radius of a vertex's window of points, in δ.
    pub radius_delta: super::Factor,
    /// Least points in a window for its vertex to move.
    pub min_points: std::num::NonZeroUsize,
    /// Largest move, in δ.
    pub max_move_delta: super::Factor,
    /// Largest RMS residual of a window's fit, over the median of the frame's.
    pub rms_factor: super::Factor,
    /// Largest component of a move across the vertex's normal, over the
    /// vertex's mean edge length (a longer one is scaled down).
    pub max_slide: super::Factor,
    /// The contour's move out to the silhouette (module docs); `None` keeps
    /// the contour where the membrane put it.
    pub contour: Option<ContourConfig>,
}

/// `pipeline.snap.contour`: the vertices on the mesh's contour, seen from
/// the eye, move outward across their rays (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContourConfig {
    /// The move, in the frame's point spacing (at the vertex's depth).
    pub offset: super::Factor,
}

impl Default for SnapConfig {
    fn default() -> Self {
        Self {
            radius_delta: super::Factor(1.5),
            min_points: std::num::NonZeroUsize::MIN.saturating_add(14),
            max_move_delta: super::Factor(4.0),
            rms_factor: super::Factor(2.0),
            max_slide: super::Factor(0.5),
            contour: Some(ContourConfig {
                offset: super::Factor(0.4),
            }),
        }
    }
}

/// The eye a frame's points were seen from: the membrane's viewpoint of a
/// single view, else for a `fused` model's frame the cloud frame's origin
/// (where [`crate::model`] puts the sensor); `None` when neither.
pub fn eye_of(report: &crate::membrane::Report, fused: bool) -> Option<Vec3> {
    match report.viewpoint {
        Some([x, y, z]) => Some(Vec3::new(x, y, z)),
        None => fused.then(Vec3::zeros),
    }
}

/// [`snap_seen_side`] on the mesh of `rec` (a frame's reconstruction of
/// `points`, on a `fused` model or not) with its δ, seen from [`eye_of`];
/// nothing without a `cfg` or an eye. Returns how many vertices moved.
pub fn apply(
    rec: &mut crate::membrane::Reconstruction,
    points: &[Vec3],
    fused: bool,
    cfg: Option<&SnapConfig>,
) -> usize {
    match (cfg, eye_of(&rec.report, fused)) {
        (Some(c), Some(eye)) => snap_seen_side(&mut rec.mesh, points, eye, rec.report.delta, c),
        _ => 0,
    }
}

/// Least bins in a window: the quadric has six coefficients.
const MIN_BINS: usize = 9;

/// Bins of the points' image per window radius (module docs).
const BINS_PER_RADIUS: usize = 4;

/// Largest number of bins of the points' image (8 MiB): a bound on the
/// memory of a cloud that spans a wide angle at a small δ. δ comes from the
/// membrane's thinned points (`pipeline.max_points`), so an object's image
/// holds about seven bins per such point (2 500 points: some 18 000 bins).
const MAX_BINS: usize = 1 << 18;

/// Move the vertices of `mesh` that face `eye` onto `points` (the frame's,
/// seen from `eye`) as the module docs say, with δ = `delta`; returns how
/// many moved.
pub fn snap_seen_side(
    mesh: &mut TriMesh,
    points: &[Vec3],
    eye: Vec3,
    delta: f64,
    cfg: &SnapConfig,
) -> usize {
    let min_points = cfg.min_points.get().max(6);
    let radius = cfg.radius_delta.get() * delta;
    if points.len() < min_points || !(radius > 0.0 && radius.is_finite()) {
        return 0;
    }
    let Some(image) = PointImage::new(points, eye, radius) else {
        return 0;
    };
    let normals = mesh.vertex_normals();
    let max_move = cfg.max_move_delta.get() * delta;
    let fits = fit_windows(mesh, &normals, &image, eye, min_points, max_move);
    let mut residuals: Vec<f64> = fits.iter().map(|f| f.rms).collect();
    if residuals.is_empty() {
        return 0;
    }
    let bound = cfg.rms_factor.get() * crate::density::upper_median(&mut residuals);
    let edge = mean_edge_lengths(mesh);
    let before = mesh.vertices.clone();
    let mut moved = vec![false; before.len()];
    let spacing = point_spacing(&fits, radius);
    for f in fits.into_iter().filter(|f| f.rms <= bound) {
        let v = &mut mesh.vertices[f.vertex];
        let d = (*v - eye) * (f.fitted / f.depth - 1.0);
        // A ray that grazes the surface moves its vertex mostly across it.
        let n = normals[f.vertex];
        let slide = (d - n * n.dot(&d)).norm();
        let cap = cfg.max_slide.get() * edge[f.vertex];
        *v += if slide > cap { d * (cap / slide) } else { d };
        moved[f.vertex] = true;
    }
    if let Some(c) = &cfg.contour {
        let offset = c.offset.get() * spacing / image.scale;
        move_contour(mesh, &normals, eye, &image.frame, offset, &mut moved);
    }
    keep_orientation(mesh, &before, &mut moved);
    moved.iter().filter(|&&m| m).count()
}

/// A facing vertex's window of points and the depth its quadric gives.
struct Fit {
    vertex: usize,
    /// The quadric's depth at the vertex's ray.
    fitted: f64,
    /// The vertex's own depth.
    depth: f64,
    /// The fit's RMS residual.
    rms: f64,
    /// The points in the window.
    points: f64,
}

/// The quadric fits of the windows of the vertices of `mesh` that face
/// `eye` (with `normals`): those with at least `min_points` points in
/// [`MIN_BINS`] bins whose fitted depth is positive and within `max_move`.
fn fit_windows(
    mesh: &TriMesh,
    normals: &[Vec3],
    image: &PointImage,
    eye: Vec3,
    min_points: usize,
    max_move: f64,
) -> Vec<Fit> {
    let mut window = Vec::new();
    (mesh.vertices.iter().zip(normals).enumerate())
        .filter(|(_, (v, n))| n.dot(&(eye - **v)) > 0.0)
        .filter_map(|(vertex, (v, _))| {
            let (uv, depth) = image.frame.project(v)?;
            image.window(uv, &mut window);
            let points = window.iter().map(|b| b[0]).sum::<f64>();
            if points < min_points as f64 || window.len() < MIN_BINS {
                return None;
            }
            let (fitted, rms) = quadric_depth(&window)?;
            let keep = (fitted - depth).abs() <= max_move && fitted > 0.0;
            keep.then_some(Fit {
                vertex,
                fitted,
                depth,
                rms,
                points,
            })
        })
        .collect()
}

/// The frame's point spacing at the image's reference depth: the median,
/// over the fitted windows (of `radius`), of `√(πr²/n)` for a window of `n`
/// points. On the 480×360 (f = 393.75) camera at 1 m: 2.45 mm, the pixel
/// pitch being 2.54 mm.
fn point_spacing(fits: &[Fit], radius: f64) -> f64 {
    let area = std::f64::consts::PI * radius * radius;
    let mut spacing: Vec<f64> = fits.iter().map(|f| (area / f.points).sqrt()).collect();
    crate::density::upper_median(&mut spacing)
}

/// Cosines between a vertex's normal and its ray to the eye within which
/// the vertex lies on the contour ([`move_contour`]).
const CONTOUR_COS: (f64, f64) = (-0.1, 0.05);

/// Move each vertex of `mesh` on its contour seen from `eye` (its normal
/// within [`CONTOUR_COS`] of square to its ray) and not moved yet, outward
/// across its ray by `offset` times its depth in `frame` (module docs),
/// marking it in `moved`.
fn move_contour(
    mesh: &mut TriMesh,
    normals: &[Vec3],
    eye: Vec3,
    frame: &ViewFrame,
    offset: f64,
    moved: &mut [bool],
) {
    for ((v, n), m) in mesh.vertices.iter_mut().zip(normals).zip(moved) {
        let Some(ray) = (eye - *v).try_normalize(1e-12) else {
            continue;
        };
        let c = n.dot(&ray);
        let across = (n - ray * c).try_normalize(1e-9);
        if let (false, true, Some(out)) = (*m, c > CONTOUR_COS.0 && c < CONTOUR_COS.1, across) {
            *v += out * (offset * frame.depth(v));
            *m = true;
        }
    }
}

/// A vertex of a triangle that its moves turned over has its move halved
/// this many times, and is then put back.
const HALVINGS: u8 = 2;

/// Shrink the moves of the vertices of every triangle that they turned
/// over (its normal now at more than 90° from the one it had in `before`)
/// until none is: each vertex moves along its own ray, and where neighbours
/// moved by different depths across a grazed or thin part their triangle
/// folded. A move is halved [`HALVINGS`] times, then undone (its vertex
/// unmarked in `moved`). Ends, as each pass shrinks at least one move and a
/// vertex put back leaves its triangles as they were.
fn keep_orientation(mesh: &mut TriMesh, before: &[Vec3], moved: &mut [bool]) {
    let face = |v: &[Vec3], [a, b, c]: [usize; 3]| (v[b] - v[a]).cross(&(v[c] - v[a]));
    let n = before.len();
    let mut halved = vec![0u8; n];
    let mut shrink = Vec::new();
    loop {
        shrink.clear();
        for t in &mesh.triangles {
            let t = t.map(|i| i as usize);
            if t.iter().any(|&i| i >= n) || !t.iter().any(|&i| moved[i]) {
                continue;
            }
            let was = face(before, t);
            if was.norm_squared() > 0.0 && was.dot(&face(&mesh.vertices, t)) <= 0.0 {
                shrink.extend(t.into_iter().filter(|&i| moved[i]));
            }
        }
        if shrink.is_empty() {
            return;
        }
        shrink.sort_unstable();
        shrink.dedup();
        for &i in &shrink {
            if halved[i] < HALVINGS {
                halved[i] += 1;
                mesh.vertices[i] = before[i] + (mesh.vertices[i] - before[i]) * 0.5;
            } else {
                mesh.vertices[i] = before[i];
                moved[i] = false;
            }
        }
    }
}

/// The mean length of the edges at each vertex of `mesh` (0 for a vertex
/// of no triangle).
fn mean_edge_lengths(mesh: &TriMesh) -> Vec<f64> {
    let n = mesh.vertices.len();
    let (mut sum, mut count) = (vec![0.0; n], vec![0usize; n]);
    for t in &mesh.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (a, b) = (a as usize, b as usize);
            if a < n && b < n {
                let l = (mesh.vertices[a] - mesh.vertices[b]).norm();
                sum[a] += l;
                sum[b] += l;
                count[a] += 1;
                count[b] += 1;
            }
        }
    }
    sum.iter()
        .zip(count)
        .map(|(s, c)| if c > 0 { s / c as f64 } else { 0.0 })
        .collect()
}

/// The frame's points binned by direction from the eye (gnomonic
/// coordinates): each bin keeps its points' count and the sums of their
/// lateral offsets (metres at the reference depth) and depths.
struct PointImage {
    frame: ViewFrame,
    /// Metres per gnomonic unit: the depth of the points' centroid.
    scale: f64,
    lo: [f64; 2],
    bin: f64,
    dims: [usize; 2],
    /// Per bin: `[n, Σu, Σv, Σz]`.
    sums: Vec<[f64; 4]>,
}

impl PointImage {
    /// The image of `points` from `eye`, with bins of `radius` over
    /// [`BINS_PER_RADIUS`] at the points' centroid; `None` when no point lies in front of the
    /// eye or the image would be too large.
    fn new(points: &[Vec3], eye: Vec3, radius: f64) -> Option<Self> {
        let finite = points.iter().filter(|p| p.iter().all(|x| x.is_finite()));
        let (sum, n) = finite.fold((Vec3::zeros(), 0usize), |(s, n), p| (s + p, n + 1));
        let centroid = sum / n.max(1) as f64;
        let frame = ViewFrame::looking_at(eye, centroid)?;
        let scale = frame.depth(&centroid);
        let projected: Vec<([f64; 2], f64)> = points
            .iter()
            .filter_map(|p| frame.project(p))
            .filter(|(uv, z)| uv.iter().chain([z]).all(|x| x.is_finite()))
            .collect();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (uv, _) in &projected {
            for k in 0..2 {
                lo[k] = lo[k].min(uv[k]);
                hi[k] = hi[k].max(uv[k]);
            }
        }
        let bin = radius / scale / BINS_PER_RADIUS as f64;
        let side = |k: usize| ((hi[k] - lo[k]) / bin).floor() + 1.0;
        let (w, h) = (side(0), side(1));
        // (NaN-safe: a NaN bin or side fails both.)
        let bounded = bin > 0.0 && w * h <= MAX_BINS as f64;
        if projected.is_empty() || !bounded {
            return None;
        }
        let mut image = Self {
            frame,
            scale,
            lo,
            bin,
            dims: [w as usize, h as usize],
            sums: vec![[0.0; 4]; w as usize * h as usize],
        };
        for (uv, z) in projected {
            if let Some((x, y)) = image.cell(uv) {
                let s = &mut image.sums[y * image.dims[0] + x];
                *s = [
                    s[0] + 1.0,
                    s[1] + uv[0] * scale,
                    s[2] + uv[1] * scale,
                    s[3] + z,
                ];
            }
        }
        Some(image)
    }

    /// The bin of gnomonic coordinates `uv` (clamped to the image).
    fn cell(&self, uv: [f64; 2]) -> Option<(usize, usize)> {
        let at = |k: usize| {
            let i = ((uv[k] - self.lo[k]) / self.bin).floor();
            (i >= 0.0).then(|| (i as usize).min(self.dims[k] - 1))
        };
        Some((at(0)?, at(1)?))
    }

    /// The bins whose points' centroid lies within the window radius of
    /// the ray through `uv`, as `[n, u, v, z]`: the count, the centroid's
    /// lateral offsets from the ray (metres at the reference depth) and
    /// its depth.
    fn window(&self, uv: [f64; 2], out: &mut Vec<[f64; 4]>) {
        out.clear();
        let Some((x, y)) = self.cell(uv) else { return };
        let (u0, v0) = (uv[0] * self.scale, uv[1] * self.scale);
        let r = self.bin * self.scale * BINS_PER_RADIUS as f64;
        let w = BINS_PER_RADIUS;
        let (x0, x1) = (x.saturating_sub(w), (x + w).min(self.dims[0] - 1));
        for yy in y.saturating_sub(w)..=(y + w).min(self.dims[1] - 1) {
            let row = &self.sums[yy * self.dims[0]..][x0..=x1];
            for &[n, su, sv, sz] in row.iter().filter(|s| s[0] > 0.0) {
                let (du, dv) = (su / n - u0, sv / n - v0);
                if du * du + dv * dv <= r * r {
                    out.push([n, du, dv, sz / n]);
                }
            }
        }
    }
}

/// The depth `c₀` at the window's ray of the least-squares quadric of the
/// window's depths over their lateral offsets (each bin's centroid
/// weighted by its count), with the fit's RMS residual over the bins;
/// `None` when the fit is singular (bins on one line).
fn quadric_depth(window: &[[f64; 4]]) -> Option<(f64, f64)> {
    let n: f64 = window.iter().map(|b| b[0]).sum();
    let z0 = window.iter().map(|b| b[0] * b[3]).sum::<f64>() / n;
    let (mut a, mut b, mut zz) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros(), 0.0);
    for &[w, u, v, z] in window {
        let j = Vector6::new(1.0, u, v, u * u, u * v, v * v);
        a.syger(w, &j, &j, 1.0);
        b.axpy(w * (z - z0), &j, 1.0);
        zz += w * (z - z0) * (z - z0);
    }
    a.fill_upper_triangle_with_lower_triangle();
    let x = a.cholesky()?.solve(&b);
    // At the least-squares solution the residual's square sum is
    // Σw(z − z₀)² − xᵀb.
    let rms = ((zz - x.dot(&b)).max(0.0) / n).sqrt();
    let depth = x[0] + z0;
    (depth.is_finite() && rms.is_finite()).then_some((depth, rms))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the sphere of radius `r` about `c` that face the origin,
    /// on a lateral grid of `step`, their depth perturbed by `noise`
    /// (a deterministic ±noise pattern).
    fn front_cap(c: Vec3, r: f64, step: f64, noise: f64) -> Vec<Vec3> {
        let mut out = Vec::new();
        let k = (r / step) as i64;
        for i in -k..=k {
            for j in -k..=k {
                let (x, y) = (i as f64 * step, j as f64 * step);
                let h2 = r * r - x * x - y * y;
                if h2 > 0.0 {
                    let s = if (i + j) % 2 == 0 { noise } else { -noise };
                    out.push(Vec3::new(c.x + x, c.y + y, c.z - h2.sqrt() + s));
                }
            }
        }
        out
    }

    /// A closed mesh of the sphere of radius `r` about `c`.
    fn sphere_mesh(c: Vec3, r: f64) -> TriMesh {
        crate::metrics::uv_sphere(c, r, 32, 64)
    }

    #[test]
    fn facing_vertices_move_onto_the_points_and_the_back_stays() {
        let (c, r) = (Vec3::new(0.0, 0.0, 1.0), 0.05);
        let points = front_cap(c, r, 0.002, 0.0005);
        // The mesh 2 mm inside the points' sphere.
        let mut mesh = sphere_mesh(c, r - 0.002);
        let before = mesh.clone();
        let moved = snap_seen_side(
            &mut mesh,
            &points,
            Vec3::zeros(),
            0.004,
            &SnapConfig::default(),
        );
        assert!(moved > 100, "{moved}");
        let mut worst_front: f64 = 0.0;
        for (v, w) in mesh.vertices.iter().zip(&before.vertices) {
            if w.z < c.z - 0.6 * r {
                // Facing the eye well inside the silhouette (the surface at
                // most 53° from square to the rays): on the sphere.
                worst_front = worst_front.max(((v - c).norm() - r).abs());
            } else if w.z > c.z + 0.5 * r {
                // Behind the contour (whose vertices, up to 0.1 r behind the
                // equator, move out).
                assert_eq!(v, w, "a back vertex moved");
            }
        }
        assert!(worst_front < 0.0006, "{worst_front}");
        assert!(!any_turned_over(&mesh, &before));
    }

    #[test]
    fn the_contour_moves_out_by_its_share_of_the_point_spacing() {
        // A sphere seen from the origin, its front on a 2 mm lateral grid;
        // the mesh on the sphere. The vertices on its equator (z = 1) lie on
        // the contour: 0.4 of the spacing out, about 0.8 mm.
        let (c, r) = (Vec3::new(0.0, 0.0, 1.0), 0.05);
        let points = front_cap(c, r, 0.002, 0.0);
        let mesh = sphere_mesh(c, r);
        let off = |v: &Vec3| v.x.hypot(v.y);
        let run = |cfg: &SnapConfig| {
            let mut m = mesh.clone();
            snap_seen_side(&mut m, &points, Vec3::zeros(), 0.004, cfg);
            m
        };
        let (on, off_cfg) = (
            SnapConfig::default(),
            SnapConfig {
                contour: None,
                ..Default::default()
            },
        );
        let (moved, kept) = (run(&on), run(&off_cfg));
        let mut equator = 0;
        for ((v, w), u) in moved
            .vertices
            .iter()
            .zip(&mesh.vertices)
            .zip(&kept.vertices)
        {
            if (w.z - c.z).abs() < 1e-9 {
                equator += 1;
                let out = off(v) - off(w);
                assert!((0.0006..0.001).contains(&out), "{w:?} -> {v:?}: {out}");
                assert_eq!(u, w, "moved without the contour");
            } else if w.z > c.z + 0.5 * r {
                assert_eq!(v, w, "a back vertex moved");
            }
        }
        assert!(equator >= 32, "{equator}");
        assert!(!any_turned_over(&moved, &mesh));
    }

    #[test]
    fn a_window_across_a_depth_edge_does_not_move_its_vertex() {
        // Two planes facing the eye, 30 mm apart in depth, meeting at x = 0;
        // the mesh's vertices lie 2 mm in front of the far one.
        let mut points = Vec::new();
        for i in -40..=40 {
            for j in -40..=40 {
                let (x, y) = (i as f64 * 0.002, j as f64 * 0.002);
                let z = if x < 0.0 { 0.97 } else { 1.0 };
                points.push(Vec3::new(
                    x,
                    y,
                    z + if (i + j) % 2 == 0 { 3e-4 } else { -3e-4 },
                ));
            }
        }
        let mut mesh = TriMesh {
            vertices: (0..=50)
                .map(|k| Vec3::new(-0.01 + k as f64 * 0.001, 0.0, 0.998))
                .collect(),
            triangles: Vec::new(),
            vertex_scalars: Vec::new(),
        };
        // Normals toward the eye: a fan of triangles with the eye in front.
        let n = mesh.vertices.len() as u32;
        mesh.vertices.push(Vec3::new(0.0, 0.01, 0.998));
        mesh.triangles = (0..n - 1).map(|k| [k, n, k + 1]).collect();
        let before = mesh.clone();
        let cfg = SnapConfig::default();
        snap_seen_side(&mut mesh, &points, Vec3::zeros(), 0.004, &cfg);
        for (v, w) in mesh.vertices.iter().zip(&before.vertices) {
            // A window (radius 6 mm) that holds points of both planes
            // leaves its vertex; beyond it the vertex lands on its plane.
            if w.x.abs() < 0.0035 {
                assert_eq!(v, w, "moved across the edge: {w:?} -> {v:?}");
            } else if w.x > 0.0065 {
                assert!((v.z - 1.0).abs() < 4e-4, "{w:?} -> {v:?}");
            }
        }
    }

    #[test]
    fn degenerate_input_moves_nothing() {
        let (c, r) = (Vec3::new(0.0, 0.0, 1.0), 0.05);
        let cfg = SnapConfig::default();
        let mesh = sphere_mesh(c, r);
        let mut points = front_cap(c, r, 0.002, 0.0);
        points.push(Vec3::new(f64::NAN, 0.0, 1.0));
        points.push(Vec3::new(f64::INFINITY, 0.0, 1.0));
        for (pts, delta) in [
            (&points[..0], 0.004),
            (&points[..3], 0.004),
            (&points[..points.len() - 2], 0.0),
            (&points[..points.len() - 2], f64::NAN),
            // A window smaller than the points' spacing holds too few.
            (&points[..points.len() - 2], 1e-5),
        ] {
            let mut m = mesh.clone();
            assert_eq!(snap_seen_side(&mut m, pts, Vec3::zeros(), delta, &cfg), 0);
            assert_eq!(m.vertices, mesh.vertices);
        }
        // One point at infinity does not stop the others.
        let mut m = mesh.clone();
        assert!(snap_seen_side(&mut m, &points, Vec3::zeros(), 0.004, &cfg) > 0);
        // The eye among the points.
        let mut m = mesh.clone();
        snap_seen_side(&mut m, &points[..points.len() - 2], c, 0.004, &cfg);
        assert!(m.vertices.iter().all(|v| v.iter().all(|x| x.is_finite())));
    }

    /// Whether any triangle of `mesh` faces against its normal in `before`.
    fn any_turned_over(mesh: &TriMesh, before: &TriMesh) -> bool {
        (0..mesh.triangles.len()).any(|t| {
            let ([a, b, c], [p, q, r]) = (before.corners(t), mesh.corners(t));
            (b - a).cross(&(c - a)).dot(&(q - p).cross(&(r - p))) <= 0.0
        })
    }

    #[test]
    fn moves_that_turn_a_triangle_over_are_halved_then_undone() {
        // Two rows of three vertices in z = 1, four triangles facing +z.
        let v = |x: f64, y: f64| Vec3::new(x, y, 1.0);
        let before = TriMesh {
            vertices: vec![
                v(0., 0.),
                v(1., 0.),
                v(2., 0.),
                v(0., 1.),
                v(1., 1.),
                v(2., 1.),
            ],
            triangles: vec![[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]],
            vertex_scalars: Vec::new(),
        };
        let check = |to: Vec3, expect: Vec3, kept: bool| {
            let mut mesh = before.clone();
            mesh.vertices[0] = to;
            // A move that folds nothing.
            mesh.vertices[5].z = 0.9;
            let mut moved = vec![true, false, false, false, false, true];
            assert!(any_turned_over(&mesh, &before));
            keep_orientation(&mut mesh, &before.vertices, &mut moved);
            assert!(!any_turned_over(&mesh, &before), "{:?}", mesh.vertices);
            assert!(
                (mesh.vertices[0] - expect).norm() < 1e-12,
                "{:?}",
                mesh.vertices[0]
            );
            assert_eq!(moved, [kept, false, false, false, false, true]);
            assert_eq!(mesh.vertices[5].z, 0.9);
        };
        // Past the edge 1-4: halved once, it folds nothing.
        check(v(1.5, 0.5), v(0.75, 0.25), true);
        // Far past it: still folded (or flat) after two halvings, undone.
        check(v(4.0, 0.5), v(0.0, 0.0), false);
    }

    #[test]
    fn a_move_across_a_grazed_surface_is_capped_by_the_edges() {
        // Points on the plane z = 1 + 2x (its normal 63° from the rays), the
        // mesh a strip of 1 mm edges on the same plane 3 mm deeper.
        let plane = |x: f64, y: f64, dz: f64| Vec3::new(x, y, 1.0 + 2.0 * x + dz);
        let mut points = Vec::new();
        for i in -30..=30 {
            for j in -30..=30 {
                points.push(plane(i as f64 * 0.001, j as f64 * 0.001, 0.0));
            }
        }
        let n = 21u32;
        let row = |y: f64| (0..n).map(move |k| plane(-0.01 + k as f64 * 0.001, y, 0.003));
        let mut mesh = TriMesh {
            vertices: row(0.0).chain(row(0.001)).collect(),
            triangles: (0..n - 1)
                .flat_map(|k| [[k, k + n, k + 1], [k + 1, k + n, k + n + 1]])
                .collect(),
            vertex_scalars: Vec::new(),
        };
        let before = mesh.clone();
        let normals = before.vertex_normals();
        let edges = mean_edge_lengths(&before);
        let cfg = SnapConfig::default();
        assert!(snap_seen_side(&mut mesh, &points, Vec3::zeros(), 0.002, &cfg) > 10);
        for ((v, w), (nv, e)) in mesh
            .vertices
            .iter()
            .zip(&before.vertices)
            .zip(normals.iter().zip(&edges))
        {
            let d = v - w;
            let slide = (d - nv * nv.dot(&d)).norm();
            assert!(slide <= 0.5 * e + 1e-12, "{w:?} -> {v:?}: {slide} over {e}");
            // Toward the points: less deep.
            assert!(v.z <= w.z, "{w:?} -> {v:?}");
        }
        assert!(!any_turned_over(&mesh, &before));
    }
}
