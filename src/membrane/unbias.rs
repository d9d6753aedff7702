//! The curvature bias of the robust centring, and its removal from the
//! mesh a frame publishes (`membrane.step.unbias`).
//!
//! The shift rule ([`super::step`]) centres a sample on the median normal
//! offset of the band points nearest to its axis: the nearer half of a
//! `w × h` cross-section, a disc of radius `r` with `π r² = w h / 2`. On a
//! surface of mean curvature `H` the points at lateral distance `ρ` lie
//! `H ρ² / 2` below the tangent plane (exactly on a sphere, on average over
//! the directions elsewhere); `ρ²` is uniform on `[0, r²]` over the disc,
//! so the median offset, where the sample settles, lies
//!
//! ```text
//! b = H r² / 4 = H w h / (8 π)
//! ```
//!
//! inside a convex surface (outside a concave one). With the cross-section
//! floor of 3δ and a capsule of radius 35 mm seen at 1 m (δ ≈ 6.5 mm),
//! `b ≈ 0.07 δ ≈ 0.4 mm`: a fifth of τ, but along the rim, where the camera's
//! rays graze the surface, it puts the first hit of a ray behind the true
//! depth by more than τ. Of the rays the committed turning capsule failed on
//! (7 236 over its 30 frames), 91 % hit the true surface at more than 60°
//! incidence, and nearly all of those met the mesh behind it or not at all.
//!
//! **The facets.** The published mesh joins samples of the spline by
//! flat triangles, and on a convex surface a chord lies inside it: linear
//! interpolation of a surface of normal curvature `κ` over an edge of
//! length `c` lies `κ c (x)(c − x)/2` inside, `κ c² / 12` on average. With
//! 48 samples around a 0.2 m object (c ≈ 13 mm at its widest) that is
//! about 0.1 mm, again a fraction of τ that the grazing rays of the rim
//! turn into a depth error: of the rays that meet the true surface within
//! one pixel of its silhouette, the committed turning capsule's mesh met
//! 48 % within τ, 56 % when extracted on a sample grid twice as fine.
//!
//! [`centring_bias`] gives each mesh vertex the outward move `b` (from the
//! surface's own curvature along the sample rows and columns) plus the
//! facets' mean inset `(κᵤ cᵤ² + κᵥ cᵥ²) / 12` (so that the triangles
//! straddle the spline, with zero mean offset; only along edges that turn
//! the normal by at most [`MAX_EDGE_TURN`]), bounded by `max_delta`·δ. It
//! is applied to the mesh a frame publishes only: the warm chain and the
//! tracking keep the membrane's own surface. Measured on
//! the 23 sensor-true sequences of `benches/robot_view_eval.sh` (same
//! tracking, so the meshes differ by the move alone): seen-side median
//! 0.820 -> 0.874 (15 used while tuning) and 0.879 -> 0.905 (8 held out),
//! mean last-third F 0.690 -> 0.700 and 0.609 -> 0.622, volume IoU
//! unchanged; F rose on 22 of the 23. The facets' term, on the 39
//! sequences of that script (against the centring's move alone, same
//! tracking): seen-side median 0.898 -> 0.909 (higher on 32, lower on 5),
//! median last-third F 0.727 -> 0.734 (mean 0.709 -> 0.712), points more
//! than 3σ outside the mesh 0.58 % -> 0.56 %; a drifting bowl loses
//! 0.007. A sample grid twice as fine for the published mesh instead gave
//! 0.904 and 0.733, at four times the vertices.

use super::config::StepConfig;
use super::step::cross_section;
use crate::cloud::Vec3;
use crate::spline::{ClosedSurface, Layout};

/// The outward move of every vertex of the mesh extracted from `surface`
/// on `layout` ([`super::extract_mesh`]'s order: the `u_n × v_n` samples
/// row by row, then the two poles, which do not move), for the centring of
/// `step` with point spacing `delta` and cross-section cap `cross_max`,
/// plus the facets' mean inset, each bounded by `max_delta · delta`.
pub(crate) fn centring_bias(
    surface: &ClosedSurface,
    layout: &Layout,
    step: &StepConfig,
    delta: f64,
    cross_max: f64,
    max_delta: f64,
) -> Vec<Vec3> {
    let (un, vn) = (layout.u_n(), layout.v_n());
    let mut samples = Vec::with_capacity(un * vn);
    for j in 0..vn {
        for i in 0..un {
            let sp = surface.eval_at(layout, i, j);
            samples.push((sp, surface.normal(&sp)));
        }
    }
    // Normal curvature along the chord between two samples.
    let kappa = |a: usize, b: usize| {
        let dp = samples[b].0.p - samples[a].0.p;
        let l2 = dp.norm_squared();
        if l2 > 0.0 {
            (samples[b].1 - samples[a].1).dot(&dp) / l2
        } else {
            0.0
        }
    };
    // The squared edge length along a chord of `steps` edges.
    let edge2 = |a: usize, b: usize, steps: usize| {
        (samples[b].0.p - samples[a].0.p).norm_squared() / (steps * steps) as f64
    };
    let bound = max_delta * delta;
    let mut moves = Vec::with_capacity(un * vn + 2);
    for j in 0..vn {
        let (j0, j1) = (j.saturating_sub(1), (j + 1).min(vn - 1));
        for i in 0..un {
            let (left, right) = (j * un + (i + un - 1) % un, j * un + (i + 1) % un);
            let (k_u, c_u2) = (kappa(left, right), edge2(left, right, 2));
            let (k_v, c_v2) = if j1 > j0 {
                let (below, above) = (j0 * un + i, j1 * un + i);
                (kappa(below, above), edge2(below, above, j1 - j0))
            } else {
                (0.0, 0.0)
            };
            let (sp, n) = &samples[j * un + i];
            let (w, h) = cross_section(step, delta, cross_max, sp, layout);
            let centring = 0.5 * (k_u + k_v) * w * h / (8.0 * std::f64::consts::PI);
            let facets = (facet_inset(k_u, c_u2) + facet_inset(k_v, c_v2)) / 12.0;
            moves.push(n * (centring + facets).clamp(-bound, bound));
        }
    }
    moves.extend([Vec3::zeros(); 2]);
    moves
}

/// Largest turn of the normal over one edge (radians) for which the
/// facets' inset is taken out: the estimate is the parabola's, and an edge
/// that turns the normal further does not resolve the surface (a crease,
/// a thin rim).
const MAX_EDGE_TURN: f64 = 0.5;

/// `κ c²` (12 times the mean inset of an edge of squared length `c2` on a
/// normal curvature `κ`), or 0 where the edge turns the normal by more
/// than [`MAX_EDGE_TURN`].
fn facet_inset(kappa: f64, c2: f64) -> f64 {
    if kappa.abs() * c2.sqrt() <= MAX_EDGE_TURN {
        kappa * c2
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spline::{ClosedSurface, Layout};

    /// A closed surface through points of the sphere of radius `r`.
    fn sphere(r: f64) -> (ClosedSurface, Layout) {
        let (m, l) = (12, 10);
        let mut net = Vec::with_capacity(m * l);
        for j in 0..l {
            let theta = std::f64::consts::PI * j as f64 / (l - 1) as f64;
            for i in 0..m {
                let phi = 2.0 * std::f64::consts::PI * i as f64 / m as f64;
                net.push(
                    Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    ) * r,
                );
            }
        }
        let s = ClosedSurface::from_net(m, l, net).unwrap();
        (s, Layout::samples(m, l, 48, 40).unwrap())
    }

    #[test]
    fn a_convex_surface_moves_out_by_the_median_offset_of_its_disc() {
        let step = StepConfig::default();
        let (delta, r) = (0.01, 0.2);
        let (s, layout) = sphere(r);
        let moves = centring_bias(&s, &layout, &step, delta, 1.0, 1.0);
        assert_eq!(moves.len(), layout.len() + 2);
        // Away from the poles the cross-section is the 3δ floor, and the
        // mean curvature that of the spline, near 1/r; the facets add the
        // mean inset of their edges, c²/(12 r) along each direction.
        let (un, vn) = (layout.u_n(), layout.v_n());
        let w = step.cross_min_delta * delta;
        let centring = w * w / (8.0 * std::f64::consts::PI * r);
        for j in vn / 4..3 * vn / 4 {
            for i in 0..un {
                let sp = s.eval_at(&layout, i, j);
                let at = |i: usize, j: usize| s.eval_at(&layout, i % un, j).p;
                let c_u = (at(i + 1, j) - sp.p).norm();
                let c_v = (at(i, j + 1) - sp.p).norm();
                let want = centring + (c_u * c_u + c_v * c_v) / (12.0 * r);
                let m = moves[j * un + i];
                let out = m.dot(&s.normal(&sp));
                assert!(
                    (out - want).abs() < 0.35 * want,
                    "sample ({i}, {j}): {out} against {want}"
                );
            }
        }
        // Bounded by max_delta·δ.
        let capped = centring_bias(&s, &layout, &step, delta, 1.0, 0.01);
        assert!(capped.iter().all(|m| m.norm() <= 0.01 * delta + 1e-12));
    }
}
