//! Initial surface from the six extreme points: the "3D octagon" (paper §III-E).
//!
//! The extreme points (top, bottom, front, back, left, right) are taken as
//! quantiles of the coordinates, so that a few stray points do not define
//! them. The middle ring is the ExtremeNet octagon of the four horizontal
//! extremes: each extreme is extended by ±1/8 of the box edge along its side,
//! which in box-normalised coordinates `q` is the gauge
//! `N_oct(q₀, q₁) = max(|q₀|, |q₁|, (|q₀|+|q₁|)/1.25)`. Rings toward the two
//! poles are the same octagon scaled by `cos θ`, i.e. the level set of
//! `N(q) = √(N_oct(q₀,q₁)² + q₂²)`. The surface is scaled so that it encloses
//! every point (times a margin) and the control net is fitted by least
//! squares to samples of this solid.

use super::config::{InitConfig, PoleAxis};
use super::fit::Fits;
use super::{MembraneError, WarmStart};
use crate::cloud::Vec3;
use crate::spline::{ClosedSurface, FitSystem, SplineError};

/// Octagon gauge in the horizontal plane (ExtremeNet cut at 1/8 of each edge).
fn n_oct(a: f64, b: f64) -> f64 {
    a.abs().max(b.abs()).max((a.abs() + b.abs()) / 1.25)
}

fn gauge(q: &Vec3) -> f64 {
    let h = n_oct(q.x, q.y);
    (h * h + q.z * q.z).sqrt()
}

/// The permutation `[a0, a1, pole]` of the coordinate axes for `axis`.
pub fn axes_for(axis: PoleAxis, extent: &Vec3) -> [usize; 3] {
    let pole = match axis {
        PoleAxis::X => 0,
        PoleAxis::Y => 1,
        PoleAxis::Z => 2,
        PoleAxis::Longest => extent.imax(),
        PoleAxis::Shortest => extent.imin(),
    };
    [(pole + 1) % 3, (pole + 2) % 3, pole]
}

/// Robust per-axis bounds: the `q` and `1−q` quantiles of each coordinate.
pub fn quantile_bounds(points: &[Vec3], q: f64) -> (Vec3, Vec3) {
    let mut lo = Vec3::zeros();
    let mut hi = Vec3::zeros();
    let n = points.len();
    if n == 0 {
        return (lo, hi);
    }
    let q = q.clamp(0.0, 0.49);
    let ilo = ((q * (n - 1) as f64).floor() as usize).min(n - 1);
    let ihi = (((1.0 - q) * (n - 1) as f64).ceil() as usize).min(n - 1);
    let mut buf: Vec<f64> = Vec::with_capacity(n);
    for k in 0..3 {
        buf.clear();
        buf.extend(points.iter().map(|p| p[k]));
        let (_, l, _) = buf.select_nth_unstable_by(ilo, f64::total_cmp);
        lo[k] = *l;
        let (_, h, _) = buf.select_nth_unstable_by(ihi, f64::total_cmp);
        hi[k] = *h;
    }
    (lo, hi)
}

/// The coordinate axis the poles of [`octagon`] take for `axis` on `points`.
pub fn pole_axis_of(points: &[Vec3], axis: PoleAxis, quantile: f64) -> usize {
    let (lo, hi) = quantile_bounds(points, quantile);
    axes_for(axis, &(hi - lo))[2]
}

/// Build the enclosing 3D-octagon surface for `points` on the grid of `fit`.
///
/// # Errors
/// [`SplineError`] from the fit.
pub fn octagon(
    points: &[Vec3],
    axis: PoleAxis,
    quantile: f64,
    margin: f64,
    fit: &mut FitSystem,
) -> Result<ClosedSurface, SplineError> {
    let (lo, hi) = quantile_bounds(points, quantile);
    let extent = hi - lo;
    let size = extent.max().max(f64::MIN_POSITIVE);
    let ax = axes_for(axis, &extent);
    let center = (lo + hi) * 0.5;
    let half = Vec3::new(
        (0.5 * extent[ax[0]]).max(1e-3 * size),
        (0.5 * extent[ax[1]]).max(1e-3 * size),
        (0.5 * extent[ax[2]]).max(1e-3 * size),
    );
    let to_q = |p: &Vec3| {
        let d = p - center;
        Vec3::new(d[ax[0]] / half.x, d[ax[1]] / half.y, d[ax[2]] / half.z)
    };
    let enclose = points
        .iter()
        .map(|p| gauge(&to_q(p)))
        .fold(1.0f64, f64::max);
    let s = enclose * margin.max(1.0);
    let lay = fit.layout().clone();
    let mut targets = Vec::with_capacity(lay.len());
    for &v in &lay.vs {
        let th = std::f64::consts::PI * (v - 0.5);
        for &u in &lay.us {
            let ph = 2.0 * std::f64::consts::PI * u;
            let d = Vec3::new(ph.cos() * th.cos(), ph.sin() * th.cos(), th.sin());
            let q = d * (s / gauge(&d));
            let mut p = center;
            p[ax[0]] += q.x * half.x;
            p[ax[1]] += q.y * half.y;
            p[ax[2]] += q.z * half.z;
            targets.push(p);
        }
    }
    let mut surf = ClosedSurface::from_net(lay.m, lay.l, vec![Vec3::zeros(); lay.m * lay.l])?;
    fit.fit(&mut surf, &targets)?;
    surf.fix_orientation();
    Ok(surf)
}

/// The initial surface of an evolution and the coordinate axis of its
/// poles: a warm start's surface (its poles' axis read from the surface, no
/// pass over the points on the per-frame path), or the octagon around
/// `points` on the first grid, its poles on `pole` (0 = x, 1 = y, 2 = z;
/// `None`: the configured `pole_axis`).
pub(crate) fn initial(
    points: &[Vec3],
    cfg: &InitConfig,
    warm: Option<&WarmStart>,
    pole: Option<usize>,
    fits: &mut Fits<'_>,
) -> Result<(ClosedSurface, usize), MembraneError> {
    if let Some(w) = warm {
        // Its orientation sign is the one fixed when the surface was made
        // (`ClosedSurface::from_net`, a regrid); refits (`evolve`) and rigid
        // motions keep it. Recomputing it here, a 64×64 volume integral,
        // was 4 % of a warm frame (`node/warm_frame_20k` bench).
        let s = w.surface.clone();
        let [a, b] = s.poles();
        let axis = (b - a).abs().imax();
        return Ok((s, axis));
    }
    let pole_axis = pole.unwrap_or_else(|| pole_axis_of(points, cfg.pole_axis, cfg.quantile));
    let [m, l] = cfg.grid;
    let surface = octagon(
        points,
        [PoleAxis::X, PoleAxis::Y, PoleAxis::Z][pole_axis],
        cfg.quantile,
        cfg.margin,
        fits.get(m, l)?,
    )?;
    Ok((surface, pole_axis))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spline::Layout;

    #[test]
    fn octagon_encloses_a_box_cloud() {
        let mut pts = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (a, b) = (i as f64 / 19.0 - 0.5, j as f64 / 19.0 - 0.5);
                pts.push(Vec3::new(a * 2.0, b, 0.25));
                pts.push(Vec3::new(a * 2.0, b, -0.25));
                pts.push(Vec3::new(1.0, a, b * 0.5));
                pts.push(Vec3::new(-1.0, a, b * 0.5));
            }
        }
        let mut fit = FitSystem::new(Layout::samples(8, 5, 24, 24).unwrap(), 1e-2).unwrap();
        let s = octagon(&pts, PoleAxis::Z, 0.0, 1.05, &mut fit).unwrap();
        let mesh = crate::membrane::extract_mesh(&s, fit.layout(), &[]);
        assert!(mesh.signed_volume() > 0.0);
        // Every point is inside: its radial distance from the centre is
        // below that of the surface in the same direction (ray test on samples).
        let c = Vec3::zeros();
        for p in &pts {
            let d = (p - c).normalize();
            let nearest = mesh
                .vertices
                .iter()
                .max_by(|a, b| {
                    (*a - c)
                        .normalize()
                        .dot(&d)
                        .total_cmp(&(*b - c).normalize().dot(&d))
                })
                .unwrap();
            assert!(
                (nearest - c).norm() > (p - c).norm() * 0.95,
                "{p:?} vs {nearest:?}"
            );
        }
    }
}
