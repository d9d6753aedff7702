//! Point separability η_p of two adjacent regions (paper Eqs. 4, 7 and 8).
//!
//! The augmented cloud 𝒫̂ = 𝒫 ∪ ℬ holds the actual points (f = 1, paper
//! Eq. 3) and estimated non-data points (f = 0). Non-data points are never
//! created: only their count per region is estimated from the local
//! spacing δ_R of the merged region R = r1 ∪ r2 (paper Eq. 4):
//!
//! ```text
//! b_r = max(0, ⌊Vol(r) / δ_R³⌋ − o_r)
//! ```
//!
//! (the paper writes the expression without the clamp; an over-full region
//! has no empty space, so it gets no non-data points). With
//! `n_r = o_r + b_r`, `N = n1 + n2`, `μ_r = o_r / n_r` and
//! `μ_T = (o1 + o2) / N` the point separability is (paper Eqs. 7, 8)
//!
//! ```text
//! η_p = [n1 (μ1 − μ_T)² + n2 (μ2 − μ_T)²] / [N μ_T (1 − μ_T)]
//! ```
//!
//! the Fisher ratio σ_b²/σ_T² of the binary occupancy f (paper Eq. 1). It is
//! in [0, 1]. Where it is undefined (an empty region, μ_T ∈ {0, 1}, or a
//! non-positive / non-finite δ) it is 0.

/// The full evaluation of Eq. 7 for one pair of regions.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointSeparability {
    /// Actual points in r1.
    pub o1: f64,
    /// Actual points in r2.
    pub o2: f64,
    /// Estimated non-data points in r1 (Eq. 4).
    pub b1: f64,
    /// Estimated non-data points in r2 (Eq. 4).
    pub b2: f64,
    /// Occupancy mean of r1, `o1 / n1` (0 when `n1 = 0`).
    pub mu1: f64,
    /// Occupancy mean of r2, `o2 / n2` (0 when `n2 = 0`).
    pub mu2: f64,
    /// η_p (Eq. 7), 0 where undefined.
    pub eta: f64,
}

/// Estimated number of non-data points of a region (paper Eq. 4):
/// `max(0, ⌊volume / δ³⌋ − actual)`. Returns 0 for a non-positive or
/// non-finite δ or volume.
#[inline]
pub fn non_data_count(volume: f64, delta: f64, actual: f64) -> f64 {
    (capacity(volume, delta) - actual).max(0.0)
}

/// Point capacity `⌊volume / δ³⌋` of a region, the `n_r` of a fully
/// occupied region (paper Eq. 4, [`non_data_count`] is `max(0, capacity −
/// actual)`). 0 for a non-positive or non-finite δ or volume, or a
/// non-finite quotient.
#[inline]
pub fn capacity(volume: f64, delta: f64) -> f64 {
    if !(delta.is_finite() && volume.is_finite() && delta > 0.0 && volume > 0.0) {
        return 0.0;
    }
    let q = volume / (delta * delta * delta);
    // ⌊q⌋ of a non-negative q below 2⁵² is its truncation, which compiles to
    // two conversions instead of a libm `floor` call (this runs per boundary
    // of every search); larger finite values are already integers.
    if q < TWO_52 {
        (q as i64) as f64
    } else if q.is_finite() {
        q
    } else {
        0.0
    }
}

/// 2⁵²: every f64 at or above it is an integer.
const TWO_52: f64 = 4_503_599_627_370_496.0;

/// `out[j] = capacity(unit_volume · j, delta)` for `j` in `0..count`,
/// bit-identical to [`capacity`] but with one division per call instead of
/// one per entry (the search needs the capacities of all `K` region sizes).
///
/// `q = (unit_volume·j)·(1/δ³)` is within 3.1 ulps of the quotient that
/// [`capacity`] rounds, so the two floors agree unless `q` lies within that
/// distance of an integer; such entries (and every invalid input) take the
/// division of [`capacity`].
pub fn capacities(unit_volume: f64, delta: f64, count: usize, out: &mut Vec<f64>) {
    out.clear();
    let valid = delta.is_finite() && unit_volume.is_finite() && delta > 0.0 && unit_volume > 0.0;
    let inv = 1.0 / (delta * delta * delta);
    out.extend((0..count).map(|j| {
        let volume = unit_volume * j as f64;
        let q = volume * inv;
        if valid && q > 0.0 && q < TWO_52 {
            let t = (q as i64) as f64;
            let margin = 4e-15 * q;
            if q - t > margin && t + 1.0 - q > margin {
                return t;
            }
        }
        capacity(volume, delta)
    }));
}

/// η_p from the four counts (paper Eqs. 7, 8); 0 where undefined.
///
/// Counts are `f64` because ⌊Vol/δ³⌋ can exceed any integer type for tiny δ.
#[inline]
pub fn eta_from_counts(o1: f64, b1: f64, o2: f64, b2: f64) -> f64 {
    let n1 = o1 + b1;
    let n2 = o2 + b2;
    let n = n1 + n2;
    if !(n1 > 0.0 && n2 > 0.0) {
        return 0.0;
    }
    let mu1 = o1 / n1;
    let mu2 = o2 / n2;
    let mu_t = (o1 + o2) / n;
    let denom = n * mu_t * (1.0 - mu_t);
    if !(denom.is_finite() && denom > 0.0) {
        return 0.0;
    }
    let eta = (n1 * (mu1 - mu_t).powi(2) + n2 * (mu2 - mu_t).powi(2)) / denom;
    if eta.is_finite() {
        eta.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// η_p by its closed form, the squared phi coefficient of the 2×2 table
/// `[[o1, b1], [o2, b2]]`: `(o1 b2 − o2 b1)² / (n1 n2 (o1 + o2) (b1 + b2))`,
/// 0 where [`eta_from_counts`] is 0 (an empty region, `μ_T ∈ {0, 1}`).
///
/// Mathematically equal to [`eta_from_counts`] with one division instead of
/// four; with integer counts whose pairwise products stay below 2⁵³ the
/// numerator is exact, so the value is within a few ulps of the exact η_p
/// and free of the cancellation of `μ_r − μ_T`. The search uses it only to
/// screen boundaries before evaluating [`eta_from_counts`], which remains
/// the reported value.
#[inline]
pub fn eta_phi2(o1: f64, b1: f64, o2: f64, b2: f64) -> f64 {
    let [num, den] = eta_phi2_ratio(o1, b1, o2, b2);
    num / den
}

/// [`eta_phi2`] as an unevaluated ratio `[num, den]` with `den > 0`
/// (`[0, 1]` where η_p is 0), so that values can be compared by
/// cross-multiplication without a division.
#[inline]
pub fn eta_phi2_ratio(o1: f64, b1: f64, o2: f64, b2: f64) -> [f64; 2] {
    let den = (o1 + b1) * (o2 + b2) * ((o1 + o2) * (b1 + b2));
    if !(den.is_finite() && den > 0.0) {
        return [0.0, 1.0];
    }
    let d = o1 * b2 - o2 * b1;
    [d * d, den]
}

/// Evaluate Eqs. 4, 7 and 8 for regions with `o1`, `o2` actual points and
/// volumes `vol1`, `vol2`, at spacing `delta` (global δ or local δ_R).
#[inline]
pub fn point_separability(o1: f64, o2: f64, vol1: f64, vol2: f64, delta: f64) -> PointSeparability {
    let b1 = non_data_count(vol1, delta, o1);
    let b2 = non_data_count(vol2, delta, o2);
    let n1 = o1 + b1;
    let n2 = o2 + b2;
    PointSeparability {
        o1,
        o2,
        b1,
        b2,
        mu1: if n1 > 0.0 { o1 / n1 } else { 0.0 },
        mu2: if n2 > 0.0 { o2 / n2 } else { 0.0 },
        eta: eta_from_counts(o1, b1, o2, b2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn non_data_count_hand_values() {
        // Vol 1, δ 0.5: capacity 8.
        assert_eq!(non_data_count(1.0, 0.5, 3.0), 5.0);
        // Floor: 1.0 / 0.3³ = 37.03… → 37.
        assert_eq!(non_data_count(1.0, 0.3, 7.0), 30.0);
        // Over-full region: clamped at 0.
        assert_eq!(non_data_count(1.0, 0.5, 20.0), 0.0);
        assert_eq!(non_data_count(1.0, 0.0, 1.0), 0.0);
        assert_eq!(non_data_count(1.0, f64::NAN, 1.0), 0.0);
        assert_eq!(non_data_count(0.0, 0.5, 1.0), 0.0);
        // Capacity: the truncation equals ⌊·⌋ below 2⁵², big values pass through.
        assert_eq!(capacity(1.0, 0.3), 37.0);
        assert_eq!(capacity(1.0, 0.5), 8.0);
        assert_eq!(capacity(1e30, 1e-3), 1e30 / (1e-3 * 1e-3 * 1e-3));
        assert_eq!(capacity(f64::MAX, 1e-3), 0.0);
        for v in [0.1, 0.7, 1.0, 3.3, 1e6, 1e15, 4.5e15, 1e17] {
            let d = 0.037;
            assert_eq!(capacity(v, d), (v / (d * d * d)).floor(), "{v}");
        }
    }

    #[test]
    fn capacities_match_capacity() {
        let mut out = Vec::new();
        // Exact multiples: unit volume 8·δ³ gives integer quotients 8j,
        // where a rounded reciprocal could land just below the integer.
        let mut units: Vec<(f64, f64)> = vec![(1.0, 0.5), (0.008, 0.1), (1.0, 0.3), (3.0, 0.1)];
        let mut x = 0.123_456_789f64;
        for _ in 0..2000 {
            x = (x * 9.87 + 0.31).fract();
            units.push((1e-6 + x * 0.02, 0.001 + x.sqrt() * 0.05));
        }
        units.extend([
            (0.0, 0.1),
            (-1.0, 0.1),
            (1.0, 0.0),
            (1.0, -0.5),
            (1.0, f64::NAN),
        ]);
        units.extend([(f64::INFINITY, 0.1), (1e300, 1e-100), (1.0, 1e-120)]);
        for (unit, delta) in units {
            capacities(unit, delta, 40, &mut out);
            assert_eq!(out.len(), 40);
            for (j, &c) in out.iter().enumerate() {
                let want = capacity(unit * j as f64, delta);
                assert_eq!(
                    c.to_bits(),
                    want.to_bits(),
                    "unit {unit} delta {delta} j {j}"
                );
            }
        }
    }

    #[test]
    fn eta_hand_computed() {
        // r1 full (o1=8, b1=0), r2 empty (o2=0, b2=8): perfect separation.
        assert!((eta_from_counts(8.0, 0.0, 0.0, 8.0) - 1.0).abs() < 1e-15);
        // Same occupancy on both sides: no separation.
        assert_eq!(eta_from_counts(2.0, 6.0, 2.0, 6.0), 0.0);
        // o1=6,b1=2 (μ1=.75), o2=2,b2=6 (μ2=.25), N=16, μT=.5:
        // num = 8·.0625 + 8·.0625 = 1; den = 16·.25 = 4 → 0.25.
        assert!((eta_from_counts(6.0, 2.0, 2.0, 6.0) - 0.25).abs() < 1e-15);
        // o1=3,b1=1 (μ1=.75), o2=1,b2=7 (μ2=.125), N=12, μT=1/3:
        // num = 4·(5/12)² + 8·(5/24)² = 0.69444 + 0.34722 = 1.041666…
        // den = 12·(1/3)·(2/3) = 8/3 → η = 0.390625.
        assert!((eta_from_counts(3.0, 1.0, 1.0, 7.0) - 0.390625).abs() < 1e-12);
        // Undefined cases.
        assert_eq!(eta_from_counts(0.0, 0.0, 5.0, 5.0), 0.0); // empty r1
        assert_eq!(eta_from_counts(4.0, 0.0, 5.0, 0.0), 0.0); // μT = 1
        assert_eq!(eta_from_counts(0.0, 4.0, 0.0, 5.0), 0.0); // μT = 0
    }

    #[test]
    fn point_separability_uses_eq4_counts() {
        // Two unit-volume regions at δ = 0.5 (capacity 8 each); 6 and 2 actual points.
        let s = point_separability(6.0, 2.0, 1.0, 1.0, 0.5);
        assert_eq!((s.b1, s.b2), (2.0, 6.0));
        assert_eq!((s.mu1, s.mu2), (0.75, 0.25));
        assert!((s.eta - 0.25).abs() < 1e-15);
        // Undefined δ → 0 non-data points → μT = 1 → η 0.
        let s = point_separability(6.0, 2.0, 1.0, 1.0, 0.0);
        assert_eq!(s.eta, 0.0);
    }

    /// Closed form: η_p equals the squared phi coefficient of the 2×2 table.
    fn phi2(o1: f64, b1: f64, o2: f64, b2: f64) -> f64 {
        let num = (o1 * b2 - o2 * b1).powi(2);
        let den = (o1 + b1) * (o2 + b2) * (o1 + o2) * (b1 + b2);
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }

    proptest! {
        #[test]
        fn eta_in_unit_interval_and_equals_phi2(
            o1 in 0u32..500, b1 in 0u32..500, o2 in 0u32..500, b2 in 0u32..500,
        ) {
            let (o1, b1, o2, b2) = (o1 as f64, b1 as f64, o2 as f64, b2 as f64);
            let e = eta_from_counts(o1, b1, o2, b2);
            prop_assert!((0.0..=1.0).contains(&e));
            prop_assert!((e - phi2(o1, b1, o2, b2)).abs() < 1e-9);
            prop_assert!((eta_phi2(o1, b1, o2, b2) - e).abs() < 1e-12);
        }

        #[test]
        fn invariant_under_joint_scale_of_regions_and_delta(
            o1 in 0u32..200, o2 in 0u32..200,
            w in 0.05f64..2.0, h in 0.05f64..2.0, d1 in 0.05f64..2.0, d2 in 0.05f64..2.0,
            delta in 0.02f64..0.5, scale in 0.1f64..10.0,
        ) {
            // Region volumes depend only on extents (translation-free, see the
            // search tests for translating actual clouds); a joint
            // scale s multiplies volumes by s³ and δ by s. Scale by a power of
            // two to keep ⌊Vol/δ³⌋ bit-exact.
            let s = (scale.log2().round()).exp2();
            let a = point_separability(o1 as f64, o2 as f64, w * h * d1, w * h * d2, delta);
            let b = point_separability(
                o1 as f64, o2 as f64,
                (w * s) * (h * s) * (d1 * s), (w * s) * (h * s) * (d2 * s), delta * s,
            );
            prop_assert!((0.0..=1.0).contains(&a.eta));
            prop_assert_eq!(a.b1, b.b1);
            prop_assert_eq!(a.b2, b.b2);
            prop_assert!((a.eta - b.eta).abs() < 1e-12);
        }
    }
}
