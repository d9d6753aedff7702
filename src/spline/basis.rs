//! Cubic B-spline basis functions for the membrane's two parametric directions.
//!
//! The membrane surface (paper Eq. 10, `S(u,v) = Σ N_{i,3}(u) N_{j,3}(v) Q_{i,j}`)
//! uses two kinds of cubic basis:
//!
//! * **u, periodic uniform.** `M` control columns, `u ∈ [0, 1)` mapped to
//!   `x = u·M`; segment `i = ⌊x⌋` blends columns `i, i+1, i+2, i+3 (mod M)`
//!   with the uniform cubic weights `(1−t)³/6, (3t³−6t²+4)/6,
//!   (−3t³+3t²+3t+1)/6, t³/6` where `t = x − i`.
//! * **v, clamped.** `L` control rows, knots `0,0,0,0, 1/(L−3), …, 1,1,1,1`;
//!   evaluated with Cox–de Boor (Piegl & Tiller A2.2) plus the first
//!   derivative from the degree-2 basis (A2.3). Rows 0 and `L−1` are the poles.

/// The four non-zero basis values (and first derivatives) at one parameter.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Span4 {
    /// Index of the first of the four control columns/rows (before any `mod M`).
    pub first: usize,
    /// Basis values `N_{first+a}` for `a = 0..4`.
    pub w: [f64; 4],
    /// First derivatives `dN_{first+a}/dparam` for `a = 0..4`.
    pub dw: [f64; 4],
}

/// Periodic uniform cubic basis on `M` columns at `u` (any real; wrapped to `[0,1)`).
/// `first` is the first column index in `0..M`; columns are `first + a (mod M)`.
/// Derivatives are with respect to `u` (not `x = u·M`).
pub fn periodic(u: f64, m: usize) -> Span4 {
    let mf = m as f64;
    let uw = u - u.floor();
    let x = uw * mf;
    let mut i = x.floor();
    let mut t = x - i;
    if i >= mf {
        i = 0.0;
        t = 0.0;
    }
    let (t2, t3) = (t * t, t * t * t);
    let s = 1.0 - t;
    let w = [
        s * s * s / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    ];
    let dw = [
        -s * s / 2.0 * mf,
        (3.0 * t2 - 4.0 * t) / 2.0 * mf,
        (-3.0 * t2 + 2.0 * t + 1.0) / 2.0 * mf,
        t2 / 2.0 * mf,
    ];
    Span4 {
        first: i as usize % m,
        w,
        dw,
    }
}

/// Knot value `U[k]` of the clamped uniform cubic knot vector for `L` rows
/// (`L + 4` knots: four zeros, interior `j/(L−3)`, four ones).
fn knot(k: usize, l: usize) -> f64 {
    let inner = (l - 3) as f64;
    if k <= 3 {
        0.0
    } else if k >= l {
        1.0
    } else {
        (k - 3) as f64 / inner
    }
}

/// Clamped cubic basis on `L ≥ 4` rows at `v ∈ [0, 1]` (clamped to that range).
/// `first` is the first of the four rows with non-zero weight.
pub fn clamped(v: f64, l: usize) -> Span4 {
    let v = v.clamp(0.0, 1.0);
    let inner = (l - 3) as f64;
    // Span s with U[s] <= v < U[s+1], s in 3..=L-1.
    let s = ((3.0 + (v * inner).floor()) as usize).min(l - 1);
    let mut n = [0.0f64; 4];
    let mut left = [0.0f64; 4];
    let mut right = [0.0f64; 4];
    let mut n2 = [0.0f64; 3];
    n[0] = 1.0;
    for j in 1..=3 {
        left[j] = v - knot(s + 1 - j, l);
        right[j] = knot(s + j, l) - v;
        let mut saved = 0.0;
        for r in 0..j {
            let den = right[r + 1] + left[j - r];
            let temp = if den != 0.0 { n[r] / den } else { 0.0 };
            n[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        n[j] = saved;
        if j == 2 {
            n2.copy_from_slice(&n[..3]);
        }
    }
    // dN_{k,3} = 3 N_{k,2}/(U[k+3]-U[k]) - 3 N_{k+1,2}/(U[k+4]-U[k+1]), k = s-3+r.
    let mut dw = [0.0f64; 4];
    for (r, d) in dw.iter_mut().enumerate() {
        let k = s - 3 + r;
        let a = if r >= 1 {
            let den = knot(k + 3, l) - knot(k, l);
            if den > 0.0 {
                3.0 * n2[r - 1] / den
            } else {
                0.0
            }
        } else {
            0.0
        };
        let b = if r <= 2 {
            let den = knot(k + 4, l) - knot(k + 1, l);
            if den > 0.0 {
                3.0 * n2[r] / den
            } else {
                0.0
            }
        } else {
            0.0
        };
        *d = a - b;
    }
    Span4 {
        first: s - 3,
        w: n,
        dw,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn periodic_partition_of_unity(u in -3.0f64..3.0, m in 4usize..50) {
            let b = periodic(u, m);
            prop_assert!((b.w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            prop_assert!(b.dw.iter().sum::<f64>().abs() < 1e-9 * m as f64);
            prop_assert!(b.w.iter().all(|&w| w >= -1e-15));
            prop_assert!(b.first < m);
        }

        #[test]
        fn clamped_partition_of_unity(v in 0.0f64..=1.0, l in 4usize..30) {
            let b = clamped(v, l);
            prop_assert!((b.w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            prop_assert!(b.dw.iter().sum::<f64>().abs() < 1e-9 * l as f64);
            prop_assert!(b.first + 3 < l);
        }

        #[test]
        fn clamped_derivative_matches_finite_difference(v in 0.01f64..0.99, l in 4usize..20) {
            let h = 1e-6;
            let (a, b, c) = (clamped(v - h, l), clamped(v + h, l), clamped(v, l));
            // Compare the full-length basis vectors (spans may differ at knots).
            let mut fa = vec![0.0; l];
            let mut fb = vec![0.0; l];
            let mut dc = vec![0.0; l];
            for k in 0..4 {
                fa[a.first + k] += a.w[k];
                fb[b.first + k] += b.w[k];
                dc[c.first + k] += c.dw[k];
            }
            for k in 0..l {
                let fd = (fb[k] - fa[k]) / (2.0 * h);
                prop_assert!((fd - dc[k]).abs() < 1e-4 * (1.0 + l as f64), "k={} fd={} d={}", k, fd, dc[k]);
            }
        }
    }

    #[test]
    fn clamped_interpolates_end_rows() {
        let b0 = clamped(0.0, 5);
        assert_eq!(b0.first, 0);
        assert!((b0.w[0] - 1.0).abs() < 1e-15);
        let b1 = clamped(1.0, 5);
        assert_eq!(b1.first, 1);
        assert!((b1.w[3] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn periodic_is_continuous_across_the_seam() {
        let m = 8;
        let a = periodic(1.0 - 1e-12, m);
        let b = periodic(0.0, m);
        // Full-length comparison modulo m.
        let mut fa = [0.0; 8];
        let mut fb = [0.0; 8];
        for k in 0..4 {
            fa[(a.first + k) % m] += a.w[k];
            fb[(b.first + k) % m] += b.w[k];
        }
        for k in 0..m {
            assert!((fa[k] - fb[k]).abs() < 1e-9);
        }
    }
}
