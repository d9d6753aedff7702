//! Procedural closed test shapes for the benchmark (`sepmem bench`, Table 1).
//!
//! Every shape is a closed, watertight, outward-oriented [`TriMesh`]
//! (positive signed volume), centred on its bounding-box centre and scaled to
//! a unit longest bounding-box edge, the normalisation the evaluation protocol
//! uses (F-score threshold 0.01 = 1 % of the longest edge). The set is fixed
//! so that benchmark results compare over time:
//!
//! | shape | construction | genus |
//! |---|---|---|
//! | `sphere` | cube-sphere lattice projected on a sphere | 0 |
//! | `ellipsoid` | the sphere scaled to semi-axes 0.5 × 0.35 × 0.25 | 0 |
//! | `rounded_box` | cube lattice mapped onto a box with rounded edges (Minkowski sum of a box and a ball) | 0 |
//! | `bottle` | surface of revolution: filleted base, body, shoulder, neck, rounded lip | 0 |
//! | `bowl` | thick-walled hemispherical bowl: outer and inner walls joined at a rounded rim (a closed solid, strongly concave) | 0 |
//! | `torus` | periodic (u, v) grid | 1 |
//! | `mug` | marching tetrahedra on an implicit cup with a handle | 1 |
//!
//! Shapes built from a parametrisation carry their analytic volume and area
//! (after normalisation) so that tests can check the triangulation against an
//! independent value. [`euler_characteristic`] and [`genus`] classify any mesh
//! (procedural or loaded) as genus 0 or with tunnels.

use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use std::collections::HashMap;
use std::f64::consts::PI;
use thiserror::Error;

/// Errors building a procedural shape.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ShapeError {
    /// The requested tessellation resolution is too coarse for the shape.
    #[error("shape `{shape}`: resolution {got} is below the minimum {min}")]
    Resolution {
        /// Shape name.
        shape: &'static str,
        /// Requested resolution.
        got: usize,
        /// Smallest accepted resolution.
        min: usize,
    },
    /// An unknown shape name was requested.
    #[error("unknown procedural shape `{0}` (known: {known})", known = procedural_names().collect::<Vec<_>>().join(", "))]
    Unknown(String),
}

/// A procedural shape: its mesh (unit longest edge, centred) plus what is
/// known about it analytically.
#[derive(Debug, Clone)]
pub struct Shape {
    /// Short name (`sphere`, `torus`, ...).
    pub name: &'static str,
    /// The closed, outward-oriented mesh.
    pub mesh: TriMesh,
    /// Genus of the surface by construction (0 for sphere-like shapes).
    pub genus: u32,
    /// Analytic enclosed volume of the ideal (untessellated) surface after
    /// normalisation, when known in closed form.
    pub volume: Option<f64>,
    /// Analytic surface area of the ideal surface after normalisation, when known.
    pub area: Option<f64>,
}

/// Names of every procedural shape, in benchmark order.
pub const NAMES: [&str; 7] = [
    "sphere",
    "ellipsoid",
    "rounded_box",
    "bottle",
    "bowl",
    "torus",
    "mug",
];

/// Further procedural shapes for the robot's-view sequences (`sepmem synth`;
/// issue 20 names a capsule and a banana-like bent tube; a can is the
/// solid of revolution whose rings are all alike), not in Table 1.
pub const SEQUENCE_NAMES: [&str; 3] = ["capsule", "bent_tube", "can"];

/// Every procedural shape [`by_name`] knows: Table 1's, then the sequences'.
pub fn procedural_names() -> impl Iterator<Item = &'static str> {
    NAMES.iter().chain(&SEQUENCE_NAMES).copied()
}

/// Build the shape called `name` at tessellation resolution `res` (roughly
/// the number of segments around the shape; 96 gives ~50k triangles).
///
/// # Errors
/// [`ShapeError::Unknown`] for an unknown name, [`ShapeError::Resolution`]
/// when `res` is too small.
pub fn by_name(name: &str, res: usize) -> Result<Shape, ShapeError> {
    match name {
        "sphere" => sphere(res),
        "ellipsoid" => ellipsoid(res),
        "rounded_box" => rounded_box(res),
        "bottle" => bottle(res),
        "bowl" => bowl(res),
        "torus" => torus(res),
        "mug" => mug(res),
        "capsule" => capsule(res),
        "bent_tube" => bent_tube(res),
        "can" => can(res),
        other => Err(ShapeError::Unknown(other.to_string())),
    }
}

/// Every procedural shape at resolution `res`.
///
/// # Errors
/// [`ShapeError::Resolution`] when `res` is too small.
pub fn all(res: usize) -> Result<Vec<Shape>, ShapeError> {
    NAMES.iter().map(|n| by_name(n, res)).collect()
}

fn check_res(shape: &'static str, got: usize, min: usize) -> Result<(), ShapeError> {
    if got < min {
        Err(ShapeError::Resolution { shape, got, min })
    } else {
        Ok(())
    }
}

/// `n` points of the Fibonacci lattice on the unit sphere about the origin
/// (a golden-angle spiral over equal-area latitude bands): nearly uniform,
/// for the tests and seeds that need points on a sphere rather than a mesh.
pub fn fibonacci_sphere(n: usize) -> Vec<Vec3> {
    let golden = PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let t = golden * i as f64;
            Vec3::new(r * t.cos(), r * t.sin(), z)
        })
        .collect()
}

/// Centre `mesh` on its bounding-box centre and scale it to a unit longest
/// edge. Returns the scale factor applied (1 for an empty or flat-zero mesh).
pub fn normalise_unit_longest_edge(mesh: &mut TriMesh) -> f64 {
    let bb = mesh.aabb();
    let longest = bb.longest_edge();
    if mesh.vertices.is_empty() || !longest.is_finite() || longest <= 0.0 {
        return 1.0;
    }
    let c = bb.center();
    let s = 1.0 / longest;
    for v in &mut mesh.vertices {
        *v = (*v - c) * s;
    }
    s
}

/// Euler characteristic χ = V − E + F, counting only vertices used by a triangle.
pub fn euler_characteristic(mesh: &TriMesh) -> i64 {
    let mut used = vec![false; mesh.vertices.len()];
    let mut edges: HashMap<(u32, u32), ()> = HashMap::with_capacity(mesh.triangles.len() * 3 / 2);
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if let Some(u) = used.get_mut(a as usize) {
                *u = true;
            }
            edges.insert((a.min(b), a.max(b)), ());
        }
    }
    let v = used.iter().filter(|&&u| u).count() as i64;
    v - edges.len() as i64 + mesh.triangles.len() as i64
}

/// Number of connected components of the triangles (sharing a vertex).
pub fn components(mesh: &TriMesh) -> usize {
    let n = mesh.vertices.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    let mut used = vec![false; n];
    for t in &mesh.triangles {
        if t.iter().any(|&i| i as usize >= n) {
            continue;
        }
        for &i in t {
            used[i as usize] = true;
        }
        for k in 1..3 {
            let (a, b) = (
                find(&mut parent, t[0] as usize),
                find(&mut parent, t[k] as usize),
            );
            if a != b {
                parent[a] = b;
            }
        }
    }
    (0..n)
        .filter(|&i| used[i] && find(&mut parent, i) == i)
        .count()
}

/// Total genus of a closed mesh, from χ = 2·components − 2·genus. `None`
/// when the mesh is not watertight (genus is then undefined) or χ is odd.
pub fn genus(mesh: &TriMesh) -> Option<u32> {
    if mesh.is_empty() || !mesh.topology().is_watertight() {
        return None;
    }
    let twice = 2 * components(mesh) as i64 - euler_characteristic(mesh);
    if twice < 0 || twice % 2 != 0 {
        return None;
    }
    u32::try_from(twice / 2).ok()
}

/// Flip the mesh if its signed volume is negative.
fn orient_outward(mesh: &mut TriMesh) {
    if mesh.signed_volume() < 0.0 {
        mesh.flip();
    }
}

/// Finish a shape: orient, normalise, scale the analytic measures.
fn finish(
    name: &'static str,
    mut mesh: TriMesh,
    genus: u32,
    volume: Option<f64>,
    area: Option<f64>,
    analytic_longest: f64,
) -> Shape {
    orient_outward(&mut mesh);
    normalise_unit_longest_edge(&mut mesh);
    let s = 1.0 / analytic_longest;
    Shape {
        name,
        mesh,
        genus,
        volume: volume.map(|v| v * s * s * s),
        area: area.map(|a| a * s * s),
    }
}

/// A closed lattice on the surface of the cube [-1, 1]³ with `n` cells per
/// face edge, each lattice point mapped by `map`. Vertices on shared cube
/// edges are welded through their integer lattice coordinates, so the result
/// is watertight for any continuous injective `map`.
fn cube_lattice(n: usize, map: impl Fn(Vec3) -> Vec3) -> TriMesh {
    let mut index: HashMap<[i64; 3], u32> = HashMap::new();
    let mut mesh = TriMesh::default();
    let ni = n as i64;
    let mut vid = |key: [i64; 3], mesh: &mut TriMesh| -> u32 {
        *index.entry(key).or_insert_with(|| {
            let q = Vec3::new(
                2.0 * key[0] as f64 / n as f64 - 1.0,
                2.0 * key[1] as f64 / n as f64 - 1.0,
                2.0 * key[2] as f64 / n as f64 - 1.0,
            );
            mesh.vertices.push(map(q));
            (mesh.vertices.len() - 1) as u32
        })
    };
    for axis in 0..3 {
        let (ua, va) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, ni] {
            for i in 0..ni {
                for j in 0..ni {
                    let key = |a: i64, b: i64| {
                        let mut k = [0i64; 3];
                        k[axis] = side;
                        k[ua] = a;
                        k[va] = b;
                        k
                    };
                    let p00 = vid(key(i, j), &mut mesh);
                    let p10 = vid(key(i + 1, j), &mut mesh);
                    let p11 = vid(key(i + 1, j + 1), &mut mesh);
                    let p01 = vid(key(i, j + 1), &mut mesh);
                    // (ua, va, axis) is right-handed, so (p00, p10, p11) faces +axis.
                    if side == ni {
                        mesh.triangles.push([p00, p10, p11]);
                        mesh.triangles.push([p00, p11, p01]);
                    } else {
                        mesh.triangles.push([p00, p11, p10]);
                        mesh.triangles.push([p00, p01, p11]);
                    }
                }
            }
        }
    }
    mesh
}

/// Equal-angle warp of a cube-surface point before projecting it on a
/// sphere: gives a more uniform vertex spacing than the plain cube sphere.
fn equal_angle(q: Vec3) -> Vec3 {
    q.map(|c| (c * PI / 4.0).tan())
}

/// Unit sphere lattice direction for a cube-surface point.
fn sphere_dir(q: Vec3) -> Vec3 {
    equal_angle(q).normalize()
}

/// Sphere of radius 0.5 (diameter 1).
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn sphere(res: usize) -> Result<Shape, ShapeError> {
    check_res("sphere", res, 8)?;
    let r = 0.5;
    let mesh = cube_lattice(res.div_ceil(4).max(2), |q| sphere_dir(q) * r);
    Ok(finish(
        "sphere",
        mesh,
        0,
        Some(4.0 / 3.0 * PI * r * r * r),
        Some(4.0 * PI * r * r),
        2.0 * r,
    ))
}

/// Ellipsoid with semi-axes 0.5 × 0.35 × 0.25. Its area uses Thomsen's
/// approximation (relative error ≤ 1.1 %).
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn ellipsoid(res: usize) -> Result<Shape, ShapeError> {
    check_res("ellipsoid", res, 8)?;
    let (a, b, c) = (0.5, 0.35, 0.25);
    let mesh = cube_lattice(res.div_ceil(4).max(2), |q| {
        let d = sphere_dir(q);
        Vec3::new(a * d.x, b * d.y, c * d.z)
    });
    let p = 1.6075f64;
    let area =
        4.0 * PI * (((a * b).powf(p) + (a * c).powf(p) + (b * c).powf(p)) / 3.0).powf(1.0 / p);
    Ok(finish(
        "ellipsoid",
        mesh,
        0,
        Some(4.0 / 3.0 * PI * a * b * c),
        Some(area),
        2.0 * a,
    ))
}

/// Box 1.0 × 0.7 × 0.5 with edges and corners rounded at radius 0.1: the
/// Minkowski sum of a 0.8 × 0.5 × 0.3 box and a ball of radius 0.1.
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn rounded_box(res: usize) -> Result<Shape, ShapeError> {
    check_res("rounded_box", res, 8)?;
    let r = 0.1;
    let h = Vec3::new(0.4, 0.25, 0.15); // core half extents
    let outer = h.add_scalar(r);
    // A cube-surface point q maps to s = q ⊙ (h + r); its clamp to the core
    // box plus r times the unit offset is the rounded-box point.
    let mesh = cube_lattice(res.div_ceil(4).max(2), |q| {
        let s = q.component_mul(&outer);
        let c = Vec3::new(
            s.x.clamp(-h.x, h.x),
            s.y.clamp(-h.y, h.y),
            s.z.clamp(-h.z, h.z),
        );
        let d = s - c;
        let len = d.norm();
        if len > 0.0 {
            c + d * (r / len)
        } else {
            c
        }
    });
    let (ax, ay, az) = (2.0 * h.x, 2.0 * h.y, 2.0 * h.z);
    let volume = ax * ay * az
        + 2.0 * r * (ax * ay + ay * az + az * ax)
        + PI * r * r * (ax + ay + az)
        + 4.0 / 3.0 * PI * r * r * r;
    let area =
        2.0 * (ax * ay + ay * az + az * ax) + 2.0 * PI * r * (ax + ay + az) + 4.0 * PI * r * r;
    Ok(finish(
        "rounded_box",
        mesh,
        0,
        Some(volume),
        Some(area),
        ax + 2.0 * r,
    ))
}

/// Surface of revolution about z of the profile `(r, z)`, whose first and
/// last points lie on the axis (r = 0) and all others off it, with `n`
/// segments around. The two axis points become the poles, closed by fans.
fn revolve(profile: &[(f64, f64)], n: usize) -> TriMesh {
    let k = profile.len();
    let rings = k.saturating_sub(2);
    let mut mesh = TriMesh::default();
    mesh.vertices.push(Vec3::new(0.0, 0.0, profile[0].1));
    for &(r, z) in &profile[1..k - 1] {
        for i in 0..n {
            let a = 2.0 * PI * i as f64 / n as f64;
            mesh.vertices.push(Vec3::new(r * a.cos(), r * a.sin(), z));
        }
    }
    mesh.vertices.push(Vec3::new(0.0, 0.0, profile[k - 1].1));
    let top = (mesh.vertices.len() - 1) as u32;
    let at = |ring: usize, i: usize| (1 + ring * n + i % n) as u32;
    for i in 0..n {
        mesh.triangles.push([0, at(0, i + 1), at(0, i)]);
        for ring in 0..rings.saturating_sub(1) {
            let (a, b) = (at(ring, i), at(ring, i + 1));
            let (c, d) = (at(ring + 1, i + 1), at(ring + 1, i));
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([a, c, d]);
        }
        mesh.triangles
            .push([top, at(rings - 1, i), at(rings - 1, i + 1)]);
    }
    mesh
}

/// Volume and area of the solid obtained by revolving the polyline profile
/// continuously (Pappus / frustum formulas), independent of the mesh.
pub fn revolved_polyline_measures(profile: &[(f64, f64)]) -> (f64, f64) {
    let mut vol = 0.0;
    let mut area = 0.0;
    for w in profile.windows(2) {
        let ((r1, z1), (r2, z2)) = (w[0], w[1]);
        // Signed: a profile traversed from bottom to top on the outside
        // (increasing z at positive r) counts positive.
        vol += PI * (z2 - z1) * (r1 * r1 + r1 * r2 + r2 * r2) / 3.0;
        area += PI * (r1 + r2) * ((r2 - r1).powi(2) + (z2 - z1).powi(2)).sqrt();
    }
    (vol.abs(), area)
}

/// Append the arc of centre `(cr, cz)` and radius `rad` from angle `a0` to
/// `a1` (radians, in the (r, z) half-plane), excluding its start point.
fn arc(out: &mut Vec<(f64, f64)>, centre: (f64, f64), rad: f64, a0: f64, a1: f64, steps: usize) {
    for s in 1..=steps {
        let a = a0 + (a1 - a0) * s as f64 / steps as f64;
        out.push((centre.0 + rad * a.cos(), centre.1 + rad * a.sin()));
    }
}

/// Append the straight segment to `to`, in `steps` pieces, excluding its start.
fn line(out: &mut Vec<(f64, f64)>, to: (f64, f64), steps: usize) {
    let from = out.last().copied().unwrap_or(to);
    for s in 1..=steps {
        let t = s as f64 / steps as f64;
        out.push((from.0 + (to.0 - from.0) * t, from.1 + (to.1 - from.1) * t));
    }
}

/// The bottle's (r, z) profile, from the bottom pole to the top pole.
fn bottle_profile(res: usize) -> Vec<(f64, f64)> {
    let (body_r, neck_r, f) = (0.18, 0.07, 0.03);
    let (body_top, neck_bottom, top) = (0.55, 0.72, 1.0);
    let s = res.max(8);
    let mut p = vec![(0.0, 0.0)];
    line(&mut p, (body_r - f, 0.0), s / 8 + 1);
    arc(&mut p, (body_r - f, f), f, -PI / 2.0, 0.0, s / 8 + 1);
    line(&mut p, (body_r, body_top), s / 2);
    // Shoulder: cosine blend from the body radius to the neck radius.
    let steps = s / 2;
    for i in 1..=steps {
        let t = i as f64 / steps as f64;
        let w = 0.5 - 0.5 * (PI * t).cos();
        p.push((
            body_r + (neck_r - body_r) * w,
            body_top + (neck_bottom - body_top) * t,
        ));
    }
    line(&mut p, (neck_r, top - f), s / 4);
    arc(&mut p, (neck_r - f, top - f), f, 0.0, PI / 2.0, s / 8 + 1);
    line(&mut p, (0.0, top), s / 8 + 1);
    p
}

/// Bottle (height 1): filleted flat base, cylindrical body, cosine shoulder,
/// neck and rounded lip, as a surface of revolution. The analytic measures
/// are those of the continuously revolved profile.
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn bottle(res: usize) -> Result<Shape, ShapeError> {
    check_res("bottle", res, 8)?;
    let profile = bottle_profile(res);
    let (vol, area) = revolved_polyline_measures(&profile);
    let mesh = revolve(&profile, res);
    Ok(finish("bottle", mesh, 0, Some(vol), Some(area), 1.0))
}

/// Capsule (height 1): a cylinder of radius 0.2 and length 0.6 between two
/// hemispheres, as a surface of revolution.
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn capsule(res: usize) -> Result<Shape, ShapeError> {
    check_res("capsule", res, 8)?;
    let (r, len) = (0.2f64, 0.6f64);
    let s = res.max(8);
    let mut p = vec![(0.0, 0.0)];
    arc(&mut p, (0.0, r), r, -PI / 2.0, 0.0, s / 4);
    line(&mut p, (r, r + len), s / 2);
    arc(&mut p, (0.0, r + len), r, 0.0, PI / 2.0, s / 4);
    let mesh = revolve(&p, res);
    let volume = PI * r * r * len + 4.0 / 3.0 * PI * r.powi(3);
    let area = 2.0 * PI * r * len + 4.0 * PI * r * r;
    Ok(finish(
        "capsule",
        mesh,
        0,
        Some(volume),
        Some(area),
        len + 2.0 * r,
    ))
}

/// Can (height 1): a cylinder of radius 0.28 with flat ends and filleted
/// rims (radius 0.03), as a surface of revolution. The analytic measures
/// are those of the continuously revolved profile.
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn can(res: usize) -> Result<Shape, ShapeError> {
    check_res("can", res, 8)?;
    let (r, f, top) = (0.28f64, 0.03f64, 1.0f64);
    let s = res.max(8);
    let mut p = vec![(0.0, 0.0)];
    line(&mut p, (r - f, 0.0), s / 4);
    arc(&mut p, (r - f, f), f, -PI / 2.0, 0.0, s / 8 + 1);
    line(&mut p, (r, top - f), s);
    arc(&mut p, (r - f, top - f), f, 0.0, PI / 2.0, s / 8 + 1);
    line(&mut p, (0.0, top), s / 4);
    let (vol, area) = revolved_polyline_measures(&p);
    let mesh = revolve(&p, res);
    Ok(finish("can", mesh, 0, Some(vol), Some(area), 1.0))
}

/// The bent tube's arc radius, tube radius and half angle.
const BENT_TUBE: (f64, f64, f64) = (0.5, 0.1, 50.0 * PI / 180.0);

/// Signed distance to the bent tube (negative inside): a ball of radius
/// 0.1 swept along a circular arc of radius 0.5 over 100° in the xz-plane
/// (centre at the origin, bowing toward −z), round-ended like a banana.
fn bent_tube_field(p: Vec3) -> f64 {
    let (big, tube, half) = BENT_TUBE;
    let phi = p.x.atan2(-p.z);
    let d = if phi.abs() <= half {
        let rho = p.x.hypot(p.z);
        (rho - big).hypot(p.y)
    } else {
        let end = Vec3::new(big * half.sin() * phi.signum(), 0.0, -big * half.cos());
        (p - end).norm()
    };
    d - tube
}

/// Banana-like bent tube (see [`bent_tube_field`]), extracted by
/// [`marching_tetrahedra`] with `res` cells along the longest edge. Its
/// volume and area are those of the swept ball (Pappus: the tube's section
/// times the arc's length, plus one ball).
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 24` (the tube must span cells).
pub fn bent_tube(res: usize) -> Result<Shape, ShapeError> {
    check_res("bent_tube", res, 24)?;
    let (big, tube, half) = BENT_TUBE;
    let pad = tube * 1.2;
    let lo = Vec3::new(-big * half.sin() - pad, -pad, -big - pad);
    let hi = Vec3::new(big * half.sin() + pad, pad, -big * half.cos() + pad);
    let cell = (hi - lo).max() / res as f64;
    let mesh = marching_tetrahedra(bent_tube_field, lo, hi, cell);
    let arc = 2.0 * half * big;
    let volume = PI * tube * tube * arc + 4.0 / 3.0 * PI * tube.powi(3);
    let area = 2.0 * PI * tube * arc + 4.0 * PI * tube * tube;
    let longest = 2.0 * (big * half.sin() + tube);
    Ok(finish(
        "bent_tube",
        mesh,
        0,
        Some(volume),
        Some(area),
        longest,
    ))
}

/// Thick-walled hemispherical bowl: outer wall radius 0.5, inner wall radius
/// 0.42, joined at the rim by a half torus of tube radius 0.04. A closed
/// solid, strongly concave (the cavity opens upward).
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn bowl(res: usize) -> Result<Shape, ShapeError> {
    check_res("bowl", res, 8)?;
    let (ro, ri) = (0.5f64, 0.42f64);
    let w = (ro - ri) / 2.0;
    let c = (ro + ri) / 2.0;
    let s = res.max(8);
    let mut p = vec![(0.0, -ro)];
    arc(&mut p, (0.0, 0.0), ro, -PI / 2.0, 0.0, s / 2);
    arc(&mut p, (c, 0.0), w, 0.0, PI, s / 4);
    arc(&mut p, (0.0, 0.0), ri, 0.0, -PI / 2.0, s / 2);
    let mesh = revolve(&p, res);
    let volume = 2.0 / 3.0 * PI * (ro.powi(3) - ri.powi(3)) + PI * PI * w * w * c;
    let area = 2.0 * PI * (ro * ro + ri * ri) + 2.0 * PI * PI * w * c;
    Ok(finish("bowl", mesh, 0, Some(volume), Some(area), 2.0 * ro))
}

/// Torus with major radius 0.35 and tube radius 0.15 (outer diameter 1), genus 1.
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 8`.
pub fn torus(res: usize) -> Result<Shape, ShapeError> {
    check_res("torus", res, 8)?;
    let (big, small) = (0.35, 0.15);
    let (nu, nv) = (res, (res / 2).max(6));
    let mut mesh = TriMesh::default();
    for i in 0..nu {
        let a = 2.0 * PI * i as f64 / nu as f64;
        for j in 0..nv {
            let b = 2.0 * PI * j as f64 / nv as f64;
            let rr = big + small * b.cos();
            mesh.vertices
                .push(Vec3::new(rr * a.cos(), rr * a.sin(), small * b.sin()));
        }
    }
    let at = |i: usize, j: usize| ((i % nu) * nv + j % nv) as u32;
    for i in 0..nu {
        for j in 0..nv {
            let (p00, p10, p11, p01) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            mesh.triangles.push([p00, p10, p11]);
            mesh.triangles.push([p00, p11, p01]);
        }
    }
    Ok(finish(
        "torus",
        mesh,
        1,
        Some(2.0 * PI * PI * big * small * small),
        Some(4.0 * PI * PI * big * small),
        2.0 * (big + small),
    ))
}

/// Signed implicit function of the mug (negative inside): an open cup
/// (outer radius 0.3, height 0.8, wall 0.05, floor 0.06) with a handle made
/// of the outer half of a torus in the xz-plane.
fn mug_field(p: Vec3) -> f64 {
    let (ro, ri, h, floor) = (0.3, 0.25, 0.8, 0.06);
    let rxy = (p.x * p.x + p.y * p.y).sqrt();
    // Solid cylinder minus the cavity (intersection with the complement).
    let outer = (rxy - ro).max((p.z - h).max(-p.z));
    let cavity = (rxy - ri).max(floor - p.z);
    let cup = outer.max(-cavity);
    // Handle: torus centred at (0.42, 0, 0.4), major 0.18, tube 0.045, axis y,
    // kept only outside the cup's mid-wall (x ≥ 0.275).
    let (cx, cz, big, tube) = (0.42, 0.4, 0.18, 0.045);
    let q = ((p.x - cx).powi(2) + (p.z - cz).powi(2)).sqrt() - big;
    let torus = (q * q + p.y * p.y).sqrt() - tube;
    let handle = torus.max(0.275 - p.x);
    cup.min(handle)
}

/// Mug with a handle (genus 1), extracted by [`marching_tetrahedra`] from
/// an implicit cup-plus-handle function; `res` cells along the longest edge.
/// No closed-form volume (the handle meets the curved wall).
///
/// # Errors
/// [`ShapeError::Resolution`] when `res < 48` (the wall must span cells).
pub fn mug(res: usize) -> Result<Shape, ShapeError> {
    check_res("mug", res, 48)?;
    let lo = Vec3::new(-0.32, -0.32, -0.02);
    let hi = Vec3::new(0.67, 0.32, 0.82);
    let cell = (hi - lo).max() / res as f64;
    let mesh = marching_tetrahedra(mug_field, lo, hi, cell);
    let longest = mesh.aabb().longest_edge();
    Ok(finish("mug", mesh, 1, None, None, longest))
}

/// The mug's implicit function, exposed so that tests can integrate its
/// volume independently of the extracted mesh.
pub fn mug_field_and_bounds() -> (fn(Vec3) -> f64, Vec3, Vec3) {
    (
        mug_field,
        Vec3::new(-0.32, -0.32, -0.02),
        Vec3::new(0.67, 0.32, 0.82),
    )
}

/// Extract the zero level set of `f` (negative inside) over the box
/// `[lo, hi]` on a grid of spacing `cell`, by marching tetrahedra (each cube
/// split into the six Kuhn tetrahedra around its main diagonal, which tile
/// conformingly). Edge crossings are shared through their grid-edge key, so
/// the surface is watertight whenever `f > 0` on the box boundary. Triangles
/// are oriented so that their normal points from the negative to the
/// positive side.
pub fn marching_tetrahedra(f: impl Fn(Vec3) -> f64, lo: Vec3, hi: Vec3, cell: f64) -> TriMesh {
    let dims = (hi - lo).map(|e| (e / cell).ceil().max(1.0) as usize + 1);
    let (nx, ny, nz) = (dims.x, dims.y, dims.z);
    let gid = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
    let pos = |i: usize, j: usize, k: usize| lo + Vec3::new(i as f64, j as f64, k as f64) * cell;
    // Sample the field; nudge exact zeros to the outside so no vertex lies on the surface.
    let mut val = vec![0.0f64; nx * ny * nz];
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let v = f(pos(i, j, k));
                val[gid(i, j, k)] = if v == 0.0 { 1e-12 } else { v };
            }
        }
    }
    const TETS: [[usize; 4]; 6] = [
        [0, 1, 3, 7],
        [0, 3, 2, 7],
        [0, 2, 6, 7],
        [0, 6, 4, 7],
        [0, 4, 5, 7],
        [0, 5, 1, 7],
    ];
    let mut mesh = TriMesh::default();
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    let mut crossing = |a: usize, b: usize, pa: Vec3, pb: Vec3, mesh: &mut TriMesh| -> u32 {
        let key = (a.min(b), a.max(b));
        *edge_vertex.entry(key).or_insert_with(|| {
            let (va, vb) = (val[a], val[b]);
            let t = va / (va - vb);
            mesh.vertices.push(pa + (pb - pa) * t);
            (mesh.vertices.len() - 1) as u32
        })
    };
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let corner = |c: usize| (i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                for tet in TETS {
                    let ids = tet.map(|c| {
                        let (a, b, d) = corner(c);
                        gid(a, b, d)
                    });
                    let mut inside = [0usize; 4];
                    let mut outside = [0usize; 4];
                    let (mut ni, mut no) = (0, 0);
                    for (m, &id) in ids.iter().enumerate() {
                        if val[id] < 0.0 {
                            inside[ni] = m;
                            ni += 1;
                        } else {
                            outside[no] = m;
                            no += 1;
                        }
                    }
                    if ni == 0 || no == 0 {
                        continue;
                    }
                    let (inside, outside) = (&inside[..ni], &outside[..no]);
                    let ps = tet.map(|c| {
                        let (a, b, d) = corner(c);
                        pos(a, b, d)
                    });
                    let c_in = inside.iter().map(|&m| ps[m]).sum::<Vec3>() / inside.len() as f64;
                    let c_out = outside.iter().map(|&m| ps[m]).sum::<Vec3>() / outside.len() as f64;
                    let out_dir = c_out - c_in;
                    let mut emit = |tri: [(usize, usize); 3], mesh: &mut TriMesh| {
                        let v = tri.map(|(a, b)| crossing(ids[a], ids[b], ps[a], ps[b], mesh));
                        let [p0, p1, p2] = v.map(|x| mesh.vertices[x as usize]);
                        let n = (p1 - p0).cross(&(p2 - p0));
                        if n.dot(&out_dir) >= 0.0 {
                            mesh.triangles.push(v);
                        } else {
                            mesh.triangles.push([v[0], v[2], v[1]]);
                        }
                    };
                    match (inside.len(), outside.len()) {
                        (1, 3) => {
                            let a = inside[0];
                            emit(
                                [(a, outside[0]), (a, outside[1]), (a, outside[2])],
                                &mut mesh,
                            );
                        }
                        (3, 1) => {
                            let b = outside[0];
                            emit([(inside[0], b), (inside[1], b), (inside[2], b)], &mut mesh);
                        }
                        _ => {
                            let (a, b) = (inside[0], inside[1]);
                            let (c, d) = (outside[0], outside[1]);
                            // Quad ac, ad, bd, bc (cyclic around the tet).
                            emit([(a, c), (a, d), (b, d)], &mut mesh);
                            emit([(a, c), (b, d), (b, c)], &mut mesh);
                        }
                    }
                }
            }
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    /// Table 1's shapes and the sequences' own.
    fn every(res: usize) -> Vec<Shape> {
        procedural_names()
            .map(|n| by_name(n, res).unwrap())
            .collect()
    }

    #[test]
    fn every_shape_is_closed_oriented_normalised_with_expected_genus() {
        for s in every(64) {
            let topo = s.mesh.topology();
            assert!(topo.is_watertight(), "{}: {topo:?}", s.name);
            assert!(s.mesh.signed_volume() > 0.0, "{}", s.name);
            let bb = s.mesh.aabb();
            assert!((bb.longest_edge() - 1.0).abs() < 1e-9, "{}", s.name);
            assert!(bb.center().norm() < 1e-9, "{}", s.name);
            assert_eq!(genus(&s.mesh), Some(s.genus), "{}", s.name);
            assert_eq!(components(&s.mesh), 1, "{}", s.name);
        }
    }

    #[test]
    fn analytic_volume_and_area_match_the_tessellation() {
        for s in every(96) {
            if let Some(v) = s.volume {
                let got = s.mesh.signed_volume();
                assert!(rel(got, v) < 0.01, "{} volume {got} vs {v}", s.name);
            }
            if let Some(a) = s.area {
                let got = s.mesh.area();
                // Thomsen's ellipsoid area formula is itself within 1.1 %.
                let tol = if s.name == "ellipsoid" { 0.02 } else { 0.01 };
                assert!(rel(got, a) < tol, "{} area {got} vs {a}", s.name);
            }
        }
    }

    #[test]
    fn sphere_vertices_lie_on_the_sphere() {
        let s = sphere(32).unwrap();
        for v in &s.mesh.vertices {
            assert!((v.norm() - 0.5).abs() < 1e-9);
        }
    }

    #[test]
    fn mug_volume_matches_midpoint_integration_of_its_field() {
        let shape = mug(64).unwrap();
        let (f, lo, hi) = mug_field_and_bounds();
        // Independent estimate: count inside points on a finer staggered grid.
        let h = 0.006;
        let n = (hi - lo).map(|e| (e / h).ceil() as usize);
        let mut inside = 0usize;
        for k in 0..n.z {
            for j in 0..n.y {
                for i in 0..n.x {
                    let p = lo + Vec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * h;
                    if f(p) < 0.0 {
                        inside += 1;
                    }
                }
            }
        }
        // The unnormalised mesh longest edge is the mug's x extent.
        let raw = marching_tetrahedra(f, lo, hi, (hi - lo).max() / 64.0);
        let s = 1.0 / raw.aabb().longest_edge();
        let expected = inside as f64 * h * h * h * s * s * s;
        let got = shape.mesh.signed_volume();
        assert!(rel(got, expected) < 0.03, "mug volume {got} vs {expected}");
    }

    #[test]
    fn genus_detects_tunnels_and_open_meshes() {
        let t = torus(16).unwrap();
        assert_eq!(euler_characteristic(&t.mesh), 0);
        let mut open = sphere(16).unwrap().mesh;
        open.triangles.pop();
        assert_eq!(genus(&open), None);
    }

    #[test]
    fn bad_resolution_and_name_are_errors() {
        assert!(matches!(sphere(2), Err(ShapeError::Resolution { .. })));
        assert!(matches!(mug(10), Err(ShapeError::Resolution { .. })));
        assert!(matches!(by_name("teapot", 32), Err(ShapeError::Unknown(_))));
    }
}
