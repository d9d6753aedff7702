//! Least-squares fit of the control net to samples (paper §III-D, step 4).
//!
//! Unknowns are one point per pole plus the `M·(L−2)` ring control points.
//! With `A` the sample-to-unknown basis matrix (fixed for a given grid size
//! and sample layout) and `R` a roughness operator (second differences along
//! u, along v and across each pole), the control net minimises
//! `‖A X − P‖² + λ‖R X‖²`, `λ = w·tr(AᵀA)/n`. The normal matrix
//! `AᵀA + λRᵀR` is banded (bandwidth ≈ 4M with row-major ordering and the
//! poles first/last), so it is factored once per layout with a banded
//! Cholesky and each iteration only back-substitutes three right-hand sides.

use super::basis::{clamped, periodic};
use super::surface::{ClosedSurface, Layout};
use super::SplineError;
use crate::cloud::Vec3;
use std::sync::Arc;

/// A factored least-squares system for one `(M, L, u_n, v_n)` sample layout.
#[derive(Debug, Clone)]
pub struct FitSystem {
    layout: Layout,
    n: usize,
    bw: usize,
    /// Banded lower Cholesky factor: row i holds columns i−bw..=i. Shared:
    /// a clone of the system (one per reconstruction, from the process-wide
    /// cache) copies only the right-hand side buffers.
    chol: Arc<[f64]>,
    /// Per sample: 16 (unknown, weight) pairs (poles may repeat). Shared.
    rows: Arc<[[(u32, f64); 16]]>,
    rhs: Vec<Vec3>,
    x: Vec<Vec3>,
    roughness: f64,
}

impl FitSystem {
    /// Build and factor the system for `layout` with roughness weight `w`
    /// (relative: `λ = w·tr(AᵀA)/n`).
    ///
    /// # Errors
    /// [`SplineError::Singular`] if the normal matrix is not positive definite.
    pub fn new(layout: Layout, roughness: f64) -> Result<Self, SplineError> {
        let (m, l) = (layout.m, layout.l);
        let n = 2 + m * (l - 2);
        let unknown = |r: usize, c: usize| -> u32 {
            if r == 0 {
                0
            } else if r == l - 1 {
                (n - 1) as u32
            } else {
                (1 + (r - 1) * m + c % m) as u32
            }
        };
        let bw = (4 * m).min(n - 1);
        let width = bw + 1;
        let mut band = vec![0.0f64; n * width];
        let add = |band: &mut [f64], i: usize, j: usize, v: f64| {
            let (i, j) = if i >= j { (i, j) } else { (j, i) };
            // i - j <= bw by construction of the ordering.
            if i - j <= bw {
                band[i * width + (j + bw - i)] += v;
            }
        };
        let un = layout.u_n();
        let mut rows = Vec::with_capacity(layout.len());
        for j in 0..layout.v_n() {
            let bv = layout.bv[j];
            for i in 0..un {
                let bu = layout.bu[i];
                let mut row = [(0u32, 0.0f64); 16];
                for b in 0..4 {
                    for a in 0..4 {
                        row[b * 4 + a] = (unknown(bv.first + b, bu.first + a), bv.w[b] * bu.w[a]);
                    }
                }
                for &(p, wp) in &row {
                    for &(q, wq) in &row {
                        if p >= q {
                            add(&mut band, p as usize, q as usize, wp * wq);
                        }
                    }
                }
                rows.push(row);
            }
        }
        let trace: f64 = (0..n).map(|i| band[i * width + bw]).sum();
        let lambda = roughness * trace / n as f64;
        // Roughness stencils: second differences along u, v and across poles.
        let mut stencils: Vec<[(u32, f64); 3]> = Vec::new();
        for r in 1..l - 1 {
            for c in 0..m {
                stencils.push([
                    (unknown(r, c + m - 1), 1.0),
                    (unknown(r, c), -2.0),
                    (unknown(r, c + 1), 1.0),
                ]);
                stencils.push([
                    (unknown(r - 1, c), 1.0),
                    (unknown(r, c), -2.0),
                    (unknown(r + 1, c), 1.0),
                ]);
            }
        }
        for (pole_row, ring_row) in [(0, 1), (l - 1, l - 2)] {
            for c in 0..m.div_ceil(2) {
                stencils.push([
                    (unknown(ring_row, c), 1.0),
                    (unknown(pole_row, c), -2.0),
                    (unknown(ring_row, c + m / 2), 1.0),
                ]);
            }
        }
        if lambda > 0.0 {
            for s in &stencils {
                for &(p, wp) in s {
                    for &(q, wq) in s {
                        if p >= q {
                            add(&mut band, p as usize, q as usize, lambda * wp * wq);
                        }
                    }
                }
            }
        }
        let ridge = 1e-10 * trace / n as f64;
        for i in 0..n {
            band[i * width + bw] += ridge;
        }
        factor_band(&mut band, n, bw)?;
        Ok(Self {
            layout,
            n,
            bw,
            chol: band.into(),
            rows: rows.into(),
            rhs: vec![Vec3::zeros(); n],
            x: vec![Vec3::zeros(); n],
            roughness,
        })
    }

    /// Bytes a cache holds for this system: the shared factor and sample
    /// rows (a clone copies neither) and the layout's parameter arrays.
    pub fn cached_bytes(&self) -> usize {
        let l = &self.layout;
        std::mem::size_of_val(&*self.chol)
            + std::mem::size_of_val(&*self.rows)
            + std::mem::size_of_val(l.us.as_slice())
            + std::mem::size_of_val(l.vs.as_slice())
            + std::mem::size_of_val(l.bu.as_slice())
            + std::mem::size_of_val(l.bv.as_slice())
    }

    /// The sample layout this system was built for.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The relative roughness weight it was built with.
    pub fn roughness(&self) -> f64 {
        self.roughness
    }

    /// Fit `surface`'s control net (which must be `M × L` of this layout) to
    /// `targets` (one per layout sample, flat index `j·u_n + i`).
    ///
    /// # Errors
    /// [`SplineError::SampleCount`] when `targets` has the wrong length,
    /// [`SplineError::GridMismatch`] when the surface has another grid size.
    pub fn fit(
        &mut self,
        surface: &mut ClosedSurface,
        targets: &[Vec3],
    ) -> Result<(), SplineError> {
        if targets.len() != self.rows.len() {
            return Err(SplineError::SampleCount {
                expected: self.rows.len(),
                got: targets.len(),
            });
        }
        if surface.m() != self.layout.m || surface.l() != self.layout.l {
            return Err(SplineError::GridMismatch {
                surface: (surface.m(), surface.l()),
                system: (self.layout.m, self.layout.l),
            });
        }
        self.rhs.fill(Vec3::zeros());
        for (row, t) in self.rows.iter().zip(targets) {
            for &(p, w) in row {
                self.rhs[p as usize] += t * w;
            }
        }
        solve_band(&self.chol, self.n, self.bw, &self.rhs, &mut self.x);
        if self.x.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(SplineError::NonFinite);
        }
        surface.set_from_unknowns(&self.x);
        Ok(())
    }
}

/// In-place banded Cholesky `A = L Lᵀ`; row i stores columns i−bw..=i.
fn factor_band(a: &mut [f64], n: usize, bw: usize) -> Result<(), SplineError> {
    let width = bw + 1;
    for i in 0..n {
        let i0 = i.saturating_sub(bw);
        for j in i0..=i {
            let p0 = i0.max(j.saturating_sub(bw));
            let ri = i * width + bw - i;
            let rj = j * width + bw - j;
            let s = a[i * width + (j + bw - i)] - dot(&a[ri + p0..ri + j], &a[rj + p0..rj + j]);
            if i == j {
                if s.is_nan() || s <= 0.0 || !s.is_finite() {
                    return Err(SplineError::Singular { row: i });
                }
                a[i * width + bw] = s.sqrt();
            } else {
                a[i * width + (j + bw - i)] = s / a[j * width + bw];
            }
        }
    }
    Ok(())
}

/// `Σ a_k b_k` with four independent partial sums (the factorisation's
/// inner loop; one running sum would be a serial chain of dependent adds).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Solve `L Lᵀ x = b` for three right-hand sides at once.
fn solve_band(l: &[f64], n: usize, bw: usize, b: &[Vec3], x: &mut [Vec3]) {
    let width = bw + 1;
    for i in 0..n {
        let p0 = i.saturating_sub(bw);
        let row = &l[i * width + bw - (i - p0)..i * width + bw];
        let mut s = b[i];
        for (xp, &lip) in x[p0..i].iter().zip(row) {
            s -= xp * lip;
        }
        x[i] = s / l[i * width + bw];
    }
    // Lᵀ x = y by columns of Lᵀ (rows of L, contiguous in the band): once
    // x_i is final, remove its share from the unknowns above it.
    for i in (0..n).rev() {
        let xi = x[i] / l[i * width + bw];
        x[i] = xi;
        let p0 = i.saturating_sub(bw);
        let row = &l[i * width + bw - (i - p0)..i * width + bw];
        for (xp, &lip) in x[p0..i].iter_mut().zip(row) {
            *xp -= xi * lip;
        }
    }
}

/// Refit `surface` onto a new `M' × L'` grid with the sample layout and
/// roughness of `system` (whose layout is `M' × L'`), keeping the shape up to
/// the fit error: the old surface is evaluated at the new layout's samples
/// and fitted.
///
/// # Errors
/// Propagates [`FitSystem::fit`] errors.
pub fn regrid(
    surface: &ClosedSurface,
    system: &mut FitSystem,
) -> Result<ClosedSurface, SplineError> {
    let lay = system.layout().clone();
    let net = ClosedSurface::from_net(lay.m, lay.l, vec![Vec3::zeros(); lay.m * lay.l])?;
    let mut out = refit_at(surface, system, net, &lay.us, &lay.vs)?;
    out.fix_orientation();
    Ok(out)
}

/// Parameter stretch of `surface` along `u` (`along_u`, the rings) or `v`
/// (the meridians): the largest ratio, over `n` equal parameter intervals,
/// of the mean arc length per unit parameter to its mean over the whole
/// curve (1 when equal parameter steps are equal arc lengths). Lengths are
/// averaged over `lines` rings (at `v = (k+½)/lines`) or meridians. Leaves
/// the cumulative mean arc length at `k/n`, `k = 0..=n`, in `cum` (sized
/// once; no allocation when it already holds `n + 1` values).
pub fn param_stretch(
    surface: &ClosedSurface,
    along_u: bool,
    lines: usize,
    n: usize,
    cum: &mut Vec<f64>,
) -> f64 {
    let (lines, n) = (lines.max(1), n.max(2));
    let (m, l) = (surface.m(), surface.l());
    cum.clear();
    cum.resize(n + 1, 0.0);
    for line in 0..lines {
        // The line's basis once (the clamped one is the costly half).
        let fixed = if along_u {
            clamped((line as f64 + 0.5) / lines as f64, l)
        } else {
            periodic(line as f64 / lines as f64, m)
        };
        let at = |t: f64| {
            if along_u {
                surface.eval_span(&periodic(t, m), &fixed).p
            } else {
                surface.eval_span(&fixed, &clamped(t, l)).p
            }
        };
        let mut prev = at(0.0);
        for (k, c) in cum.iter_mut().enumerate().skip(1) {
            let p = at(k as f64 / n as f64);
            *c += (p - prev).norm();
            prev = p;
        }
    }
    let mut total = 0.0;
    let mut widest: f64 = 0.0;
    for c in cum.iter_mut() {
        let len = *c / lines as f64;
        widest = widest.max(len);
        total += len;
        *c = total;
    }
    if total > 0.0 && total.is_finite() {
        widest * n as f64 / total
    } else {
        1.0
    }
}

/// Redistribute the samples of `surface` along `u` (`along_u`) or `v`:
/// refit it (with `system`'s layout, which must be on the surface's grid)
/// to itself evaluated at `t' = A⁻¹(t·A(1))`, where `A` is the cumulative
/// mean arc length `cum` from [`param_stretch`]: equal parameter steps
/// become equal arc lengths, so samples and control points move from
/// compressed regions into stretched ones (a sheet pulled deep into a
/// cavity) while the shape stays the same up to the fit error.
///
/// # Errors
/// Propagates [`FitSystem::fit`] errors.
pub fn redistribute(
    surface: &ClosedSurface,
    system: &mut FitSystem,
    along_u: bool,
    cum: &[f64],
) -> Result<ClosedSurface, SplineError> {
    let lay = system.layout();
    let n = cum.len().saturating_sub(1).max(1);
    let total = cum.last().copied().unwrap_or(0.0);
    let remap = |t: f64| {
        // A⁻¹(t·A(1)) by linear interpolation of the cumulative lengths.
        let a = t * total;
        let k = cum.partition_point(|&c| c < a).clamp(1, n);
        let (c0, c1) = (cum[k - 1], cum[k]);
        let f = if c1 > c0 { (a - c0) / (c1 - c0) } else { 0.5 };
        (((k - 1) as f64 + f.clamp(0.0, 1.0)) / n as f64).clamp(0.0, 1.0)
    };
    let (us, vs): (Vec<f64>, Vec<f64>) = if along_u {
        (lay.us.iter().map(|&u| remap(u)).collect(), lay.vs.clone())
    } else {
        (lay.us.clone(), lay.vs.iter().map(|&v| remap(v)).collect())
    };
    refit_at(surface, system, surface.clone(), &us, &vs)
}

/// Fit `out` (on `system`'s grid) to `surface` evaluated at the grid of
/// parameters `us × vs`, taken as the layout's samples in order.
fn refit_at(
    surface: &ClosedSurface,
    system: &mut FitSystem,
    mut out: ClosedSurface,
    us: &[f64],
    vs: &[f64],
) -> Result<ClosedSurface, SplineError> {
    let mut targets = Vec::with_capacity(us.len() * vs.len());
    for &v in vs {
        for &u in us {
            targets.push(surface.eval(u, v).p);
        }
    }
    system.fit(&mut out, &targets)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn sphere_targets(lay: &Layout, r: f64) -> Vec<Vec3> {
        let mut t = Vec::new();
        for &v in &lay.vs {
            for &u in &lay.us {
                let th = std::f64::consts::PI * v;
                let ph = 2.0 * std::f64::consts::PI * u;
                t.push(Vec3::new(
                    r * th.sin() * ph.cos(),
                    r * th.sin() * ph.sin(),
                    -r * th.cos(),
                ));
            }
        }
        t
    }

    #[test]
    fn band_cholesky_matches_dense() {
        let n = 30;
        let bw = 5;
        let mut dense = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                if i.abs_diff(j) <= bw {
                    dense[(i, j)] =
                        1.0 / (1.0 + (i as f64 - j as f64).abs()) + if i == j { 5.0 } else { 0.0 };
                }
            }
        }
        let width = bw + 1;
        let mut band = vec![0.0; n * width];
        for i in 0..n {
            for j in i.saturating_sub(bw)..=i {
                band[i * width + (j + bw - i)] = dense[(i, j)];
            }
        }
        factor_band(&mut band, n, bw).unwrap();
        let b: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f64, 1.0, -(i as f64).sin()))
            .collect();
        let mut x = vec![Vec3::zeros(); n];
        solve_band(&band, n, bw, &b, &mut x);
        let chol = dense.clone().cholesky().unwrap();
        for k in 0..3 {
            let rhs = nalgebra::DVector::from_iterator(n, b.iter().map(|v| v[k]));
            let xs = chol.solve(&rhs);
            for i in 0..n {
                assert!((xs[i] - x[i][k]).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn fit_reproduces_a_sphere() {
        let lay = Layout::samples(16, 10, 40, 40).unwrap();
        let targets = sphere_targets(&lay, 0.5);
        let mut sys = FitSystem::new(lay.clone(), 1e-3).unwrap();
        let mut s = ClosedSurface::from_net(16, 10, vec![Vec3::zeros(); 160]).unwrap();
        sys.fit(&mut s, &targets).unwrap();
        s.fix_orientation();
        let mut worst: f64 = 0.0;
        for j in 0..50 {
            for i in 0..50 {
                let p = s.eval(i as f64 / 50.0, j as f64 / 49.0).p;
                worst = worst.max((p.norm() - 0.5).abs());
            }
        }
        assert!(worst < 0.01, "max radial error {worst}");
    }

    #[test]
    fn redistribution_evens_out_a_stretched_ring_and_keeps_the_shape() {
        // A sphere whose u runs unevenly: φ = 2π·(u + 0.12·sin 2πu), so the
        // arc length per unit u varies by a factor of ~7 around each ring.
        let lay = Layout::samples(24, 15, 72, 45).unwrap();
        let mut targets = Vec::new();
        for &v in &lay.vs {
            for &u in &lay.us {
                let th = std::f64::consts::PI * v;
                let ph = 2.0
                    * std::f64::consts::PI
                    * (u + 0.12 * (2.0 * std::f64::consts::PI * u).sin());
                targets.push(Vec3::new(
                    th.sin() * ph.cos(),
                    th.sin() * ph.sin(),
                    -th.cos(),
                ));
            }
        }
        let mut sys = FitSystem::new(lay, 1e-4).unwrap();
        let mut s = ClosedSurface::from_net(24, 15, vec![Vec3::zeros(); 24 * 15]).unwrap();
        sys.fit(&mut s, &targets).unwrap();
        s.fix_orientation();
        let mut cum = Vec::new();
        let before = param_stretch(&s, true, 16, 144, &mut cum);
        assert!(before > 1.5, "stretch of the uneven sphere {before}");
        assert_eq!(cum.len(), 145);
        assert!(cum.windows(2).all(|w| w[1] >= w[0]));
        let r = redistribute(&s, &mut sys, true, &cum).unwrap();
        let after = param_stretch(&r, true, 16, 144, &mut cum);
        assert!(
            after < 1.15,
            "stretch after redistribution {after} (before {before})"
        );
        // The v direction was even and is measured as such.
        let along_v = param_stretch(&r, false, 16, 90, &mut cum);
        assert!(along_v < before, "v stretch {along_v}");
        let mut worst: f64 = 0.0;
        for j in 1..40 {
            for i in 0..60 {
                let p = r.eval(i as f64 / 60.0, j as f64 / 40.0).p;
                worst = worst.max((p.norm() - 1.0).abs());
            }
        }
        assert!(
            worst < 0.02,
            "redistribution moved the surface off the sphere by {worst}"
        );
        assert_eq!(r.orientation(), s.orientation());
    }

    #[test]
    fn regrid_keeps_the_shape() {
        let lay = Layout::samples(8, 5, 40, 40).unwrap();
        let targets = sphere_targets(&lay, 1.0);
        let mut sys = FitSystem::new(lay, 1e-3).unwrap();
        let mut s = ClosedSurface::from_net(8, 5, vec![Vec3::zeros(); 40]).unwrap();
        sys.fit(&mut s, &targets).unwrap();
        s.fix_orientation();
        let mut big = FitSystem::new(Layout::samples(24, 15, 48, 29).unwrap(), 1e-4).unwrap();
        let g = regrid(&s, &mut big).unwrap();
        assert_eq!((g.m(), g.l()), (24, 15));
        let mut worst: f64 = 0.0;
        for j in 1..30 {
            for i in 0..30 {
                let (u, v) = (i as f64 / 30.0, j as f64 / 30.0);
                worst = worst.max((s.eval(u, v).p - g.eval(u, v).p).norm());
            }
        }
        assert!(worst < 0.02, "regrid moved the surface by {worst}");
        assert_eq!(g.orientation(), s.orientation());
    }
}
