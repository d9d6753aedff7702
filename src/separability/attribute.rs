//! Attribute separability and the weighted separability (paper Eqs. 1 and 9).
//!
//! For a scalar attribute `a` over the *actual* points of two adjacent
//! regions r1, r2 (non-data points carry no attribute), the separability is
//! the Fisher ratio of paper Eq. 1:
//!
//! ```text
//! η_a = σ_b² / σ_T²,   σ_b² = [n1 (μ1 − μ)² + n2 (μ2 − μ)²] / N,
//!                      σ_T² = (1/N) Σ (a_i − μ)²
//! ```
//!
//! computed from running sums `(count, Σa, Σa²)`: per slab of the search
//! cuboid, then prefix sums, so every boundary costs O(1). The values are
//! shifted by the channel's cloud mean before summing, which keeps
//! `Σa²/N − μ²` free of cancellation.
//!
//! The separability vector `[η_p, η_a1, …, η_ad]` is combined with weights
//! `w` into `η_w = Σ w_j η_j / Σ w_j` (paper Eq. 9).
//!
//! Channels ([`AttributeSet::from_cloud`]): `intensity`, colour `luma`
//! (Rec. 601 from `r, g, b`), local `density` (neighbour count within a
//! radius, computed once per cloud), and any named float channel.

use crate::cloud::{PointCloud, Vec3};
use crate::separability::grid::{GridError, OrientedBox, SpatialIndex};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors while preparing attribute channels.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AttributeError {
    /// A weight is negative or not finite.
    #[error("attribute weight for `{name}` is {weight}; weights must be finite and >= 0")]
    BadWeight {
        /// Channel name (`point` for η_p).
        name: String,
        /// The weight.
        weight: f64,
    },
    /// A channel does not have one value per point.
    #[error("attribute `{name}` has {got} values for {points} points")]
    Length {
        /// Channel name.
        name: String,
        /// Values present.
        got: usize,
        /// Points in the cloud.
        points: usize,
    },
    /// The density-attribute radius is not a positive finite length.
    #[error("density attribute radius {0} is not a positive finite length")]
    BadRadius(f64),
    /// The spatial index for the density attribute could not be built.
    #[error("density attribute: {0}")]
    Grid(#[from] GridError),
}

/// A named weight for any float channel of the input.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelWeight {
    /// Channel name as carried by the cloud (e.g. a PLY/PCD field).
    pub name: String,
    /// Weight in Eq. 9.
    pub weight: f64,
}

/// Weights of the separability vector (paper Eq. 9); 0 disables a term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttributeWeights {
    /// Weight of the point separability η_p.
    pub point: f64,
    /// Weight of the `intensity` channel.
    pub intensity: f64,
    /// Weight of the colour luma (from `r`, `g`, `b`).
    pub luma: f64,
    /// Weight of the local density (neighbour count within `density_radius`·δ).
    pub density: f64,
    /// Weights of further named channels.
    pub channels: Vec<ChannelWeight>,
}

impl Default for AttributeWeights {
    fn default() -> Self {
        Self {
            point: 1.0,
            intensity: 0.0,
            luma: 0.0,
            density: 0.0,
            channels: Vec::new(),
        }
    }
}

impl AttributeWeights {
    /// True when any attribute term has a positive weight.
    pub fn uses_attributes(&self) -> bool {
        self.intensity > 0.0
            || self.luma > 0.0
            || self.density > 0.0
            || self.channels.iter().any(|c| c.weight > 0.0)
    }
}

/// One prepared channel: values (shifted by their mean) and weight.
#[derive(Debug, Clone, PartialEq)]
pub struct AttributeChannel {
    /// Channel name.
    pub name: String,
    /// Weight in Eq. 9 (> 0).
    pub weight: f64,
    /// Values minus their cloud mean, one per point.
    pub values: Vec<f64>,
}

/// The attribute channels of one cloud used by the weighted search.
#[derive(Debug, Clone, PartialEq)]
pub struct AttributeSet {
    point_weight: f64,
    channels: Vec<AttributeChannel>,
    missing: Vec<String>,
}

impl AttributeSet {
    /// Only η_p (no attribute channel).
    pub fn point_only() -> Self {
        Self {
            point_weight: 1.0,
            channels: Vec::new(),
            missing: Vec::new(),
        }
    }

    /// Build from explicit channels `(name, values, weight)`; zero-weight
    /// channels are dropped.
    ///
    /// # Errors
    /// [`AttributeError::BadWeight`] or [`AttributeError::Length`] when the
    /// channels differ in length.
    pub fn new(
        point_weight: f64,
        channels: &[(&str, &[f32], f64)],
    ) -> Result<Self, AttributeError> {
        check_weight("point", point_weight)?;
        let mut set = Self {
            point_weight,
            channels: Vec::new(),
            missing: Vec::new(),
        };
        let len = channels.first().map(|c| c.1.len());
        for &(name, values, weight) in channels {
            check_weight(name, weight)?;
            if Some(values.len()) != len {
                return Err(AttributeError::Length {
                    name: name.to_string(),
                    got: values.len(),
                    points: len.unwrap_or(0),
                });
            }
            set.push(name, values.iter().map(|&v| f64::from(v)), weight);
        }
        Ok(set)
    }

    /// Prepare the channels that `weights` enables from `cloud`.
    ///
    /// `delta` is the cloud's global δ; the density attribute counts the
    /// neighbours within `density_radius · delta`. Requested channels the
    /// cloud does not carry are skipped and listed in [`Self::missing`].
    ///
    /// # Errors
    /// [`AttributeError`] for bad weights, channel lengths or radius.
    pub fn from_cloud(
        cloud: &PointCloud,
        weights: &AttributeWeights,
        delta: f64,
        density_radius: f64,
    ) -> Result<Self, AttributeError> {
        check_weight("point", weights.point)?;
        let mut set = Self {
            point_weight: weights.point,
            channels: Vec::new(),
            missing: Vec::new(),
        };
        let n = cloud.len();
        let check_len = |name: &str, got: usize| {
            if got == n {
                Ok(())
            } else {
                Err(AttributeError::Length {
                    name: name.to_string(),
                    got,
                    points: n,
                })
            }
        };
        check_weight("intensity", weights.intensity)?;
        if weights.intensity > 0.0 {
            match cloud.attribute("intensity") {
                Some(v) => {
                    check_len("intensity", v.len())?;
                    set.push(
                        "intensity",
                        v.iter().map(|&x| f64::from(x)),
                        weights.intensity,
                    );
                }
                None => set.missing.push("intensity".into()),
            }
        }
        check_weight("luma", weights.luma)?;
        if weights.luma > 0.0 {
            match cloud.luma() {
                Some(v) => {
                    check_len("luma", v.len())?;
                    set.push("luma", v.iter().map(|&x| f64::from(x)), weights.luma);
                }
                None => set.missing.push("luma".into()),
            }
        }
        check_weight("density", weights.density)?;
        if weights.density > 0.0 {
            let radius = density_radius * delta;
            let counts = neighbour_counts(&cloud.points, radius)?;
            set.push(
                "density",
                counts.iter().map(|&c| f64::from(c)),
                weights.density,
            );
        }
        for cw in &weights.channels {
            check_weight(&cw.name, cw.weight)?;
            if cw.weight == 0.0 {
                continue;
            }
            match cloud.attribute(&cw.name) {
                Some(v) => {
                    check_len(&cw.name, v.len())?;
                    set.push(&cw.name, v.iter().map(|&x| f64::from(x)), cw.weight);
                }
                None => set.missing.push(cw.name.clone()),
            }
        }
        Ok(set)
    }

    fn push(&mut self, name: &str, values: impl Iterator<Item = f64>, weight: f64) {
        if weight == 0.0 {
            return;
        }
        let mut values: Vec<f64> = values
            .map(|v| if v.is_finite() { v } else { f64::NAN })
            .collect();
        let (sum, cnt) = values
            .iter()
            .filter(|v| v.is_finite())
            .fold((0.0, 0usize), |(s, c), v| (s + v, c + 1));
        let mean = if cnt > 0 { sum / cnt as f64 } else { 0.0 };
        for v in &mut values {
            // Non-finite values get the mean: they add nothing to σ_b².
            *v = if v.is_finite() { *v - mean } else { 0.0 };
        }
        self.channels.push(AttributeChannel {
            name: name.to_string(),
            weight,
            values,
        });
    }

    /// Weight of η_p.
    pub fn point_weight(&self) -> f64 {
        self.point_weight
    }

    /// The prepared channels (positive weights only).
    pub fn channels(&self) -> &[AttributeChannel] {
        &self.channels
    }

    /// Requested channels absent from the cloud (skipped).
    pub fn missing(&self) -> &[String] {
        &self.missing
    }

    /// Sum of all weights (η_p's and the channels').
    pub fn total_weight(&self) -> f64 {
        self.point_weight + self.channels.iter().map(|c| c.weight).sum::<f64>()
    }
}

fn check_weight(name: &str, weight: f64) -> Result<(), AttributeError> {
    if weight.is_finite() && weight >= 0.0 {
        Ok(())
    } else {
        Err(AttributeError::BadWeight {
            name: name.to_string(),
            weight,
        })
    }
}

/// Number of other points within `radius` of each point (the local-density
/// attribute), computed once per cloud with a grid of cell `radius`.
///
/// # Errors
/// [`AttributeError::BadRadius`] or a grid error.
pub fn neighbour_counts(points: &[Vec3], radius: f64) -> Result<Vec<u32>, AttributeError> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(AttributeError::BadRadius(radius));
    }
    let index = SpatialIndex::with_cell_size(points, radius)?;
    let r2 = radius * radius;
    let axes = [Vec3::x(), Vec3::y(), Vec3::z()];
    Ok(points
        .iter()
        .map(|p| {
            if !p.iter().all(|c| c.is_finite()) {
                return 0;
            }
            let b = OrientedBox {
                center: *p,
                axes,
                half: [radius; 3],
            };
            let mut count = 0u32;
            index.for_each_in_box(&b, |_, s, _| {
                if s[0] * s[0] + s[1] * s[1] + s[2] * s[2] <= r2 {
                    count += 1;
                }
            });
            count.saturating_sub(1)
        })
        .collect())
}

/// Fisher ratio σ_b²/σ_T² (paper Eq. 1) from the sums of two groups:
/// counts `n1, n2`, sums `s1, s2`, sums of squares `q1, q2`. 0 where
/// undefined (an empty group, or no total variance).
#[inline]
pub fn fisher_ratio(n1: f64, s1: f64, q1: f64, n2: f64, s2: f64, q2: f64) -> f64 {
    let n = n1 + n2;
    if !(n1 > 0.0 && n2 > 0.0) {
        return 0.0;
    }
    let mu = (s1 + s2) / n;
    let var_t = (q1 + q2) / n - mu * mu;
    let mu1 = s1 / n1;
    let mu2 = s2 / n2;
    let var_b = (n1 * (mu1 - mu).powi(2) + n2 * (mu2 - mu).powi(2)) / n;
    // Relative floor: the total variance must exceed rounding noise of Σa².
    let scale = (q1 + q2) / n;
    if !(var_t > 1e-12 * scale && var_t > 0.0) {
        return 0.0;
    }
    let eta = var_b / var_t;
    if eta.is_finite() {
        eta.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Weighted separability (paper Eq. 9): `Σ w_j η_j / Σ w_j`; 0 when every weight is 0.
pub fn weighted_mean(etas: &[f64], weights: &[f64]) -> f64 {
    let (num, den) = etas
        .iter()
        .zip(weights)
        .fold((0.0, 0.0), |(n, d), (e, w)| (n + w * e, d + w));
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn direct_fisher(a: &[f64], b: &[f64]) -> f64 {
        let all: Vec<f64> = a.iter().chain(b).copied().collect();
        let n = all.len() as f64;
        let mu = all.iter().sum::<f64>() / n;
        let var_t = all.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / n;
        let m1 = a.iter().sum::<f64>() / a.len() as f64;
        let m2 = b.iter().sum::<f64>() / b.len() as f64;
        let var_b = (a.len() as f64 * (m1 - mu).powi(2) + b.len() as f64 * (m2 - mu).powi(2)) / n;
        var_b / var_t
    }

    fn sums(v: &[f64]) -> (f64, f64, f64) {
        (
            v.len() as f64,
            v.iter().sum(),
            v.iter().map(|x| x * x).sum(),
        )
    }

    #[test]
    fn fisher_hand_computed() {
        // {0, 0} vs {1, 1}: all variance is between classes.
        assert!((fisher_ratio(2.0, 0.0, 0.0, 2.0, 2.0, 2.0) - 1.0).abs() < 1e-15);
        // {0, 2} vs {1, 1}: equal means → 0.
        assert_eq!(fisher_ratio(2.0, 2.0, 4.0, 2.0, 2.0, 2.0), 0.0);
        // {0, 1} vs {3}: μ = 4/3, σ_T² = (16/9 + 1/9 + 25/9)/3 = 14/9,
        // σ_b² = [2·(1/2 − 4/3)² + (3 − 4/3)²]/3 = (25/18 + 25/9)/3 = 25/18 → η = 25/28.
        assert!((fisher_ratio(2.0, 1.0, 1.0, 1.0, 3.0, 9.0) - 25.0 / 28.0).abs() < 1e-12);
        // Undefined: an empty group, constant values.
        assert_eq!(fisher_ratio(0.0, 0.0, 0.0, 3.0, 3.0, 3.0), 0.0);
        assert_eq!(fisher_ratio(2.0, 2.0, 2.0, 3.0, 3.0, 3.0), 0.0);
    }

    #[test]
    fn weighted_mean_eq9() {
        assert!((weighted_mean(&[0.2, 0.8], &[1.0, 3.0]) - 0.65).abs() < 1e-15);
        assert_eq!(weighted_mean(&[0.2, 0.8], &[0.0, 0.0]), 0.0);
    }

    #[test]
    fn neighbour_counts_match_brute_force() {
        let pts: Vec<Vec3> = (0..300)
            .map(|i| {
                let f = i as f64;
                Vec3::new((f * 0.37).sin(), (f * 0.11).cos(), (f * 0.05).sin() * 0.3)
            })
            .collect();
        let got = neighbour_counts(&pts, 0.2).unwrap();
        for (i, p) in pts.iter().enumerate() {
            let want = pts
                .iter()
                .enumerate()
                .filter(|&(j, q)| j != i && (p - q).norm_squared() <= 0.04)
                .count() as u32;
            assert_eq!(got[i], want);
        }
        assert!(matches!(
            neighbour_counts(&pts, 0.0),
            Err(AttributeError::BadRadius(_))
        ));
    }

    #[test]
    fn attribute_set_from_cloud() {
        let mut c = PointCloud::from_points(
            (0..10)
                .map(|i| Vec3::new(i as f64 * 0.1, 0.0, 0.0))
                .collect(),
        );
        c.set_attribute("intensity", (0..10).map(|i| i as f32).collect())
            .unwrap();
        c.set_attribute("curv", vec![1.0; 10]).unwrap();
        let w = AttributeWeights {
            point: 2.0,
            intensity: 1.0,
            luma: 1.0,
            density: 0.5,
            channels: vec![
                ChannelWeight {
                    name: "curv".into(),
                    weight: 1.0,
                },
                ChannelWeight {
                    name: "nothere".into(),
                    weight: 1.0,
                },
            ],
        };
        let s = AttributeSet::from_cloud(&c, &w, 0.1, 1.5).unwrap();
        let names: Vec<&str> = s.channels().iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["intensity", "density", "curv"]);
        assert_eq!(s.missing(), ["luma", "nothere"]);
        // Intensity shifted by its mean 4.5.
        assert_eq!(s.channels()[0].values[0], -4.5);
        // Density: neighbours within 0.15 on a 0.1-spaced line: 1 at the ends, 2 inside.
        let dens = &s.channels()[1].values;
        let mean = (2.0 * 1.0 + 8.0 * 2.0) / 10.0;
        assert!((dens[0] - (1.0 - mean)).abs() < 1e-12);
        assert!((dens[5] - (2.0 - mean)).abs() < 1e-12);
        // point 2 + intensity 1 + density 0.5 + curv 1 (missing ones add nothing).
        assert!((s.total_weight() - 4.5).abs() < 1e-15);
        let bad = AttributeWeights {
            luma: -1.0,
            ..AttributeWeights::default()
        };
        assert!(matches!(
            AttributeSet::from_cloud(&c, &bad, 0.1, 1.5),
            Err(AttributeError::BadWeight { .. })
        ));
    }

    proptest! {
        #[test]
        fn fisher_from_sums_matches_direct_and_is_bounded(
            a in prop::collection::vec(-100.0f64..100.0, 1..40),
            b in prop::collection::vec(-100.0f64..100.0, 1..40),
        ) {
            let (n1, s1, q1) = sums(&a);
            let (n2, s2, q2) = sums(&b);
            let e = fisher_ratio(n1, s1, q1, n2, s2, q2);
            prop_assert!((0.0..=1.0).contains(&e));
            let d = direct_fisher(&a, &b);
            if d.is_finite() {
                prop_assert!((e - d).abs() < 1e-6, "{} vs {}", e, d);
            }
        }
    }
}
