//! The oriented search primitive: separability profile along a direction.
//!
//! Given a centre `c`, a unit direction `n` and a cuboid (cross-section
//! `M_w × M_h` across `n`, depth `M_d` along it), the cuboid is split by `K`
//! boundary planes ⟂ `n` into `r1` (the side of `−n`, "inner") and `r2` (the
//! side of `+n`, "outer"). For every boundary the point separability η_p of
//! paper Eq. 7 is evaluated (optionally weighted with attribute
//! separabilities, paper Eqs. 1 and 9), and the argmax is reported. This is
//! step 3 of the membrane (paper §III-D), and, with `K = 1`, one evaluation of
//! the 3D separability filter (§IV-A).
//!
//! Implementation (one call, `O(gathered + K)`):
//! 1. gather the actual points of the cuboid once from a [`SpatialIndex`];
//! 2. bin their signed offsets `t = (p − c)·n` into `K + 1` equal slabs of
//!    width `Δ = M_d/(K + 1)`; boundary `k` lies at `t_k = −M_d/2 + (k+1)Δ`,
//!    so `r1 = [−M_d/2, t_k)` holds slabs `0..=k`;
//! 3. prefix sums of the slab counts give `o1`, `o2` for every boundary in
//!    O(1); `b1`, `b2` follow from Eq. 4 with `Vol(r1) = M_w M_h (k+1) Δ`,
//!    from a per-call table of the capacities `⌊M_w M_h j Δ / δ³⌋` of the
//!    `K` region sizes (`r1` of boundary `k` and `r2` of boundary `K−1−k`
//!    share a size).
//!
//! [`Searcher::search`] records the full profile. [`Searcher::search_best`]
//! returns only the best boundary under a [`BestRule`] (the membrane's
//! inside-denser rule); it screens the boundaries with the one-division
//! closed form of η_p and evaluates Eq. 7 only near the maximum, with the
//! same result as scanning the full profile.
//!
//! δ is either a fixed global value or the local δ_R of the merged region
//! `R = r1 ∪ r2` (the whole cuboid, so one value per call): the mean of the
//! per-point `d_i` of the gathered points (paper Eq. 6).
//!
//! All buffers live in a caller-owned [`SearchScratch`] (one per rayon
//! thread); in steady state a call allocates nothing. The kernel applies no
//! membrane policy: it exposes the full profile (offsets, `o1, o2, b1, b2,
//! μ1, μ2`, η per boundary) and the gathered points' offsets and indices, so
//! the caller can apply rules such as "inner side denser" or robust centring.

use crate::cloud::Vec3;
use crate::density::local_mean;
use crate::separability::attribute::{fisher_ratio, AttributeSet};
use crate::separability::grid::{OrientedBox, SpatialIndex};
use crate::separability::point::{capacities, eta_from_counts, eta_phi2_ratio};
use thiserror::Error;

/// Errors of the oriented search.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SearchError {
    /// The cuboid's centre or direction is not finite, or the direction is zero.
    #[error("search cuboid: centre {center:?} / direction {direction:?} must be finite and the direction non-zero")]
    BadFrame {
        /// The centre given.
        center: [f64; 3],
        /// The direction given.
        direction: [f64; 3],
    },
    /// A cuboid extent is not a positive finite length.
    #[error("search cuboid: {what} = {value} is not a positive finite length")]
    BadExtent {
        /// Which extent (`width`, `height`, `depth`).
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// `K = 0` boundary positions.
    #[error("search: the number of boundary positions K must be at least 1")]
    NoBoundaries,
    /// The global δ is not a positive finite length.
    #[error("search: global delta {0} is not a positive finite length")]
    BadDelta(f64),
    /// The per-point density does not cover the indexed cloud.
    #[error("search: local delta has {got} per-point values for a cloud of {need} points")]
    DensityLength {
        /// Values given.
        got: usize,
        /// Points in the cloud the index was built from.
        need: usize,
    },
    /// An attribute channel does not cover the indexed cloud.
    #[error("search: attribute `{name}` has {got} values for a cloud of {need} points")]
    AttributeLength {
        /// Channel name.
        name: String,
        /// Values given.
        got: usize,
        /// Points in the cloud.
        need: usize,
    },
}

/// The search cuboid: centre, direction and extents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cuboid {
    /// Centre `c` (the boundary offsets are measured from here).
    pub center: Vec3,
    /// Search direction `n` (normalised by the search; points from r1 to r2).
    pub direction: Vec3,
    /// Optional first cross-section axis (projected ⟂ `n`); an arbitrary
    /// stable axis is chosen when `None` or parallel to `n`.
    pub tangent: Option<Vec3>,
    /// `M_w`: extent along the first cross-section axis.
    pub width: f64,
    /// `M_h`: extent along the second cross-section axis `n × tangent`.
    pub height: f64,
    /// `M_d`: extent along `n`.
    pub depth: f64,
}

impl Cuboid {
    /// A cuboid with an automatically chosen cross-section frame.
    pub fn new(center: Vec3, direction: Vec3, width: f64, height: f64, depth: f64) -> Self {
        Self {
            center,
            direction,
            tangent: None,
            width,
            height,
            depth,
        }
    }

    /// The same cuboid with its width measured along `tangent` (projected ⟂ `n`).
    pub fn with_tangent(mut self, tangent: Vec3) -> Self {
        self.tangent = Some(tangent);
        self
    }

    /// Volume `M_w M_h M_d`.
    pub fn volume(&self) -> f64 {
        self.width * self.height * self.depth
    }

    /// Validate and build the orthonormal frame `(n, a1, a2)`.
    ///
    /// # Errors
    /// [`SearchError::BadFrame`] or [`SearchError::BadExtent`].
    pub fn oriented_box(&self) -> Result<OrientedBox, SearchError> {
        let bad_frame = || SearchError::BadFrame {
            center: [self.center.x, self.center.y, self.center.z],
            direction: [self.direction.x, self.direction.y, self.direction.z],
        };
        let finite = |v: &Vec3| v.iter().all(|c| c.is_finite());
        if !finite(&self.center) || !finite(&self.direction) {
            return Err(bad_frame());
        }
        let len = self.direction.norm();
        if !(len.is_finite() && len > 0.0) {
            return Err(bad_frame());
        }
        for (what, value) in [
            ("width", self.width),
            ("height", self.height),
            ("depth", self.depth),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(SearchError::BadExtent { what, value });
            }
        }
        let n = self.direction / len;
        let project = |t: Vec3| {
            let p = t - n * n.dot(&t);
            let l = p.norm();
            (l > 1e-9 && l.is_finite()).then(|| p / l)
        };
        let a1 = self
            .tangent
            .filter(finite)
            .and_then(project)
            .or_else(|| {
                let helper = if n.x.abs() < 0.6 {
                    Vec3::x()
                } else {
                    Vec3::y()
                };
                project(helper)
            })
            .ok_or_else(bad_frame)?;
        let a2 = n.cross(&a1);
        Ok(OrientedBox {
            center: self.center,
            axes: [n, a1, a2],
            half: [0.5 * self.depth, 0.5 * self.width, 0.5 * self.height],
        })
    }
}

/// Where δ comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Delta<'a> {
    /// One δ for every cuboid (the cloud's global estimate).
    Global(f64),
    /// Local δ_R: the mean of these per-point `d_i` (indexed like the cloud)
    /// over the points gathered in the cuboid (paper Eq. 6).
    Local(&'a [f64]),
}

/// Statistics of one boundary position.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BoundaryStats {
    /// Signed offset `t_k` of the boundary plane from the centre, along `n`.
    pub offset: f64,
    /// Actual points in r1 (`t < t_k`).
    pub o1: u32,
    /// Actual points in r2 (`t ≥ t_k`).
    pub o2: u32,
    /// Estimated non-data points in r1 (Eq. 4).
    pub b1: f64,
    /// Estimated non-data points in r2 (Eq. 4).
    pub b2: f64,
    /// Occupancy mean `o1/n1` of r1.
    pub mu1: f64,
    /// Occupancy mean `o2/n2` of r2.
    pub mu2: f64,
    /// Point separability η_p (Eq. 7).
    pub eta_point: f64,
    /// The separability used for the argmax: η_p, or the weighted η_w
    /// (Eq. 9) when attributes are enabled.
    pub eta: f64,
}

/// Which boundaries may be reported as the best one.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum BestRule {
    /// Every boundary: the plain argmax of η.
    #[default]
    Any,
    /// Only boundaries whose inner side is at least as dense as the outer
    /// one (`μ1 ≥ μ2`): the membrane's inside-denser rule, which keeps the
    /// search from locking onto the outer face of a neighbouring layer.
    ///
    /// `min_inner` (a length, 0 = none) also skips boundaries whose inner
    /// region `r1` is thinner than it. A layer at the far inner end of the
    /// cuboid fills such a thin `r1` almost completely, and its η_p can then
    /// beat the layer the sample sits on: with a second layer (the other face
    /// of a thin wall) just inside the cuboid's end, the Fisher ratio of a
    /// full thin slab against a sparse rest exceeds that of the true boundary.
    InnerDenser {
        /// Smallest thickness of the inner region `r1` of an admitted boundary.
        min_inner: f64,
    },
}

/// The argmax of a profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Best {
    /// Boundary index `k` in `0..K`.
    pub boundary: usize,
    /// Its offset `t_k`.
    pub offset: f64,
    /// Its separability (`eta` of the boundary).
    pub eta: f64,
}

/// Summary of one search call; the details stay in the [`SearchScratch`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchOutcome {
    /// Number of actual points gathered in the cuboid.
    pub gathered: usize,
    /// δ used (global, or local δ_R; 0 when local and nothing was gathered).
    pub delta: f64,
    /// Boundary with the largest positive separability (first one on ties);
    /// `None` when every boundary has η = 0.
    pub best: Option<Best>,
}

/// Reusable buffers of the search; keep one per thread.
#[derive(Debug, Clone, Default)]
pub struct SearchScratch {
    offsets: Vec<f64>,
    sq_distances: Vec<f64>,
    indices: Vec<u32>,
    slab_counts: Vec<u32>,
    profile: Vec<BoundaryStats>,
    band: Vec<f64>,
    slab_of: Vec<u32>,
    /// Per channel and slab: (Σa, Σa²), channel-major.
    attr_sums: Vec<[f64; 2]>,
    /// Running prefix (Σa, Σa²) per channel.
    attr_run: Vec<[f64; 2]>,
    /// Totals (Σa, Σa²) per channel.
    attr_tot: Vec<[f64; 2]>,
    /// η of each channel per boundary, boundary-major.
    attr_eta: Vec<f64>,
    channels: usize,
    slab_width: f64,
    half_depth: f64,
    /// Eq. 4 capacity of a region of `j` slabs, `j` in `0..=K`.
    capacity: Vec<f64>,
    /// `[M_w M_h Δ, δ]` the capacity table was computed for.
    capacity_key: Option<[f64; 2]>,
    /// Screening key `[num, den]` per boundary of [`Searcher::search_best`].
    screen: Vec<[f64; 2]>,
}

impl SearchScratch {
    /// Empty scratch; buffers grow on first use and are then reused.
    pub fn new() -> Self {
        Self::default()
    }

    /// Profile of the last search, one entry per boundary, innermost first.
    pub fn profile(&self) -> &[BoundaryStats] {
        &self.profile
    }

    /// Signed offsets `t = (p − c)·n` of the points gathered by the last search.
    pub fn offsets(&self) -> &[f64] {
        &self.offsets
    }

    /// Squared distances `|p − c|²` of the gathered points from the centre
    /// (parallel to [`Self::offsets`]).
    pub fn sq_distances(&self) -> &[f64] {
        &self.sq_distances
    }

    /// Cloud indices of the gathered points (parallel to [`Self::offsets`]).
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// Point count of each of the `K + 1` slabs, innermost first.
    pub fn slab_counts(&self) -> &[u32] {
        &self.slab_counts
    }

    /// Number of attribute channels of the last search (0 without attributes).
    pub fn attribute_count(&self) -> usize {
        self.channels
    }

    /// Attribute separabilities η_a (Eq. 1) at boundary `k`, in the order of
    /// [`AttributeSet::channels`]; empty without attributes or out of range.
    pub fn attribute_eta(&self, k: usize) -> &[f64] {
        let c = self.channels;
        self.attr_eta.get(k * c..(k + 1) * c).unwrap_or(&[])
    }

    /// Slab width `Δ = M_d / (K + 1)` of the last search.
    pub fn slab_width(&self) -> f64 {
        self.slab_width
    }

    /// Number of gathered points with offset in `[lo, hi]`.
    pub fn count_in_band(&self, lo: f64, hi: f64) -> usize {
        self.offsets.iter().filter(|&&t| t >= lo && t <= hi).count()
    }

    /// Median of the gathered offsets in `[lo, hi]` (mean of the middle pair
    /// for an even count); `None` when the band is empty. For robust
    /// centring on a layer of points. Allocation-free in steady state.
    pub fn median_offset_in_band(&mut self, lo: f64, hi: f64) -> Option<f64> {
        self.band.clear();
        self.band
            .extend(self.offsets.iter().copied().filter(|&t| t >= lo && t <= hi));
        let n = self.band.len();
        if n == 0 {
            return None;
        }
        let mid = n / 2;
        let (below, upper, _) = self.band.select_nth_unstable_by(mid, f64::total_cmp);
        let upper = *upper;
        if n % 2 == 1 {
            Some(upper)
        } else {
            let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            Some(0.5 * (lower + upper))
        }
    }
}

/// The oriented search over one indexed cloud. Cheap to build; shareable
/// across threads (each thread brings its own [`SearchScratch`]).
#[derive(Debug, Clone)]
pub struct Searcher<'a> {
    index: &'a SpatialIndex,
    delta: Delta<'a>,
    boundaries: usize,
    attributes: Option<&'a AttributeSet>,
}

impl<'a> Searcher<'a> {
    /// A search over `index` with `boundaries` (K) positions and the given δ.
    ///
    /// # Errors
    /// [`SearchError::NoBoundaries`], [`SearchError::BadDelta`] for a global δ
    /// that is not positive and finite, [`SearchError::DensityLength`] when
    /// the per-point values are fewer than the indexed points.
    pub fn new(
        index: &'a SpatialIndex,
        delta: Delta<'a>,
        boundaries: usize,
    ) -> Result<Self, SearchError> {
        if boundaries == 0 {
            return Err(SearchError::NoBoundaries);
        }
        match delta {
            Delta::Global(d) if !(d.is_finite() && d > 0.0) => {
                return Err(SearchError::BadDelta(d));
            }
            Delta::Local(per_point) if per_point.len() < index.source_len() => {
                return Err(SearchError::DensityLength {
                    got: per_point.len(),
                    need: index.source_len(),
                });
            }
            _ => {}
        }
        Ok(Self {
            index,
            delta,
            boundaries,
            attributes: None,
        })
    }

    /// Enable the weighted separability η_w (paper Eq. 9) with `attributes`.
    /// Each boundary's `eta` then is η_w, `eta_point` stays η_p. A set
    /// without channels and with a positive point weight behaves like η_p alone.
    ///
    /// # Errors
    /// [`SearchError::AttributeLength`] when a channel does not cover the cloud.
    pub fn with_attributes(mut self, attributes: &'a AttributeSet) -> Result<Self, SearchError> {
        let need = self.index.source_len();
        if let Some(c) = attributes.channels().iter().find(|c| c.values.len() < need) {
            return Err(SearchError::AttributeLength {
                name: c.name.clone(),
                got: c.values.len(),
                need,
            });
        }
        self.attributes = Some(attributes);
        Ok(self)
    }

    /// Number of boundary positions K.
    pub fn boundaries(&self) -> usize {
        self.boundaries
    }

    /// The spatial index searched.
    pub fn index(&self) -> &'a SpatialIndex {
        self.index
    }

    /// Evaluate the separability profile of `cuboid`; details go to `scratch`.
    /// The reported best is the plain argmax of η ([`BestRule::Any`]).
    ///
    /// # Errors
    /// [`SearchError::BadFrame`] / [`SearchError::BadExtent`] for an invalid cuboid.
    pub fn search(
        &self,
        cuboid: &Cuboid,
        scratch: &mut SearchScratch,
    ) -> Result<SearchOutcome, SearchError> {
        let (gathered, delta) = self.gather(cuboid, scratch)?;
        let best = self.profile_pass(scratch, BestRule::Any);
        Ok(SearchOutcome {
            gathered,
            delta,
            best,
        })
    }

    /// The best boundary of `cuboid` under `rule`, without the full profile.
    ///
    /// The outcome (gathered count, δ, best boundary with its offset and η)
    /// is the same as [`Self::search`] followed by a scan of the profile for
    /// the first largest positive η among the boundaries `rule` admits. The
    /// gathered offsets, indices and slab counts are in `scratch` as after
    /// [`Self::search`]; [`SearchScratch::profile`] is left empty unless
    /// attributes are enabled (the weighted η needs every boundary's sums, so
    /// the full profile is computed then).
    ///
    /// Without attributes η_p is evaluated only where it can be the maximum:
    /// each admitted boundary is screened with the one-division closed form
    /// [`eta_phi2`](crate::separability::point::eta_phi2), and [`eta_from_counts`] (the value reported, identical
    /// to the profile's) runs only for boundaries within a rounding
    /// tolerance of the screened maximum.
    ///
    /// # Errors
    /// [`SearchError::BadFrame`] / [`SearchError::BadExtent`] for an invalid cuboid.
    pub fn search_best(
        &self,
        cuboid: &Cuboid,
        rule: BestRule,
        scratch: &mut SearchScratch,
    ) -> Result<SearchOutcome, SearchError> {
        let (gathered, delta) = self.gather(cuboid, scratch)?;
        let best = if self.attributes.is_some() {
            self.profile_pass(scratch, rule)
        } else {
            scratch.profile.clear();
            Self::screened_best(scratch, rule)
        };
        Ok(SearchOutcome {
            gathered,
            delta,
            best,
        })
    }

    /// Gather the cuboid's points into `scratch` (offsets, indices, slab
    /// counts, and the slab of each point when attributes need it), fix δ
    /// and fill the capacity table. Returns (gathered, δ).
    fn gather(
        &self,
        cuboid: &Cuboid,
        scratch: &mut SearchScratch,
    ) -> Result<(usize, f64), SearchError> {
        let obb = cuboid.oriented_box()?;
        let k_count = self.boundaries;
        let slabs = k_count + 1;
        let half_depth = obb.half[0];
        let slab_width = cuboid.depth / slabs as f64;
        let inv_slab = 1.0 / slab_width;
        let keep_slab = self.attributes.is_some();

        scratch.offsets.clear();
        scratch.sq_distances.clear();
        scratch.indices.clear();
        scratch.slab_of.clear();
        scratch.slab_counts.clear();
        scratch.slab_counts.resize(slabs, 0);
        scratch.slab_width = slab_width;
        scratch.half_depth = half_depth;
        {
            let (offsets, sq_distances, indices, counts, slab_of) = (
                &mut scratch.offsets,
                &mut scratch.sq_distances,
                &mut scratch.indices,
                &mut scratch.slab_counts,
                &mut scratch.slab_of,
            );
            self.index.for_each_in_box(&obb, |i, s, r2| {
                let t = s[0];
                let slab = (((t + half_depth) * inv_slab) as usize).min(slabs - 1);
                counts[slab] += 1;
                offsets.push(t);
                sq_distances.push(r2);
                indices.push(i);
                if keep_slab {
                    slab_of.push(slab as u32);
                }
            });
        }
        let gathered = scratch.offsets.len();
        let delta = match self.delta {
            Delta::Global(d) => d,
            Delta::Local(per_point) => {
                local_mean(per_point, scratch.indices.iter().map(|&i| i as usize)).unwrap_or(0.0)
            }
        };
        // Eq. 4 capacities of the K possible region volumes: r1 of boundary
        // k spans k + 1 slabs and r2 spans K − k, so `capacity[j]` (j slabs)
        // serves both sides. The volume expression is the one of the
        // profile's definition, so the counts are bit-identical to
        // `non_data_count(area·Δ·j, δ, o)`.
        // Consecutive membrane samples often share the cross-section (clamped
        // at its minimum) and δ: the table is then reused.
        let key = [cuboid.width * cuboid.height * slab_width, delta];
        if scratch.capacity_key != Some(key) || scratch.capacity.len() != slabs {
            capacities(key[0], delta, slabs, &mut scratch.capacity);
            scratch.capacity_key = Some(key);
        }
        Ok((gathered, delta))
    }

    /// `(o1, b1, o2, b2)` of boundary `k` given its `o1` (Eq. 4 with the
    /// capacity table of [`Self::gather`]).
    #[inline]
    fn counts(scratch: &SearchScratch, k: usize, o1: u32, total: u32) -> [f64; 4] {
        let k_count = scratch.capacity.len() - 1;
        let (fo1, fo2) = (f64::from(o1), f64::from(total - o1));
        let b1 = (scratch.capacity[k + 1] - fo1).max(0.0);
        let b2 = (scratch.capacity[k_count - k] - fo2).max(0.0);
        [fo1, b1, fo2, b2]
    }

    /// Thickness of the inner region `r1` of boundary `k` (`t_k` from the
    /// cuboid's inner end), as [`BestRule::InnerDenser`] compares it.
    #[inline]
    fn inner_thickness(scratch: &SearchScratch, k: usize) -> f64 {
        Self::offset(scratch, k) + scratch.half_depth
    }

    /// Offset `t_k` of boundary `k`.
    #[inline]
    fn offset(scratch: &SearchScratch, k: usize) -> f64 {
        -scratch.half_depth + scratch.slab_width * (k + 1) as f64
    }

    /// The full profile of the gathered points into `scratch.profile` (and
    /// the attribute η per boundary); returns the best boundary under `rule`.
    fn profile_pass(&self, scratch: &mut SearchScratch, rule: BestRule) -> Option<Best> {
        let k_count = self.boundaries;
        let slabs = k_count + 1;
        // Attribute running sums per slab (Eq. 1 from (count, Σa, Σa²)).
        let channels = self.attributes.map_or(&[][..], |a| a.channels());
        let nch = channels.len();
        scratch.channels = nch;
        scratch.attr_eta.clear();
        scratch.attr_sums.clear();
        scratch.attr_sums.resize(nch * slabs, [0.0; 2]);
        scratch.attr_run.clear();
        scratch.attr_run.resize(nch, [0.0; 2]);
        scratch.attr_tot.clear();
        scratch.attr_tot.resize(nch, [0.0; 2]);
        for (ch, channel) in channels.iter().enumerate() {
            let sums = &mut scratch.attr_sums[ch * slabs..(ch + 1) * slabs];
            let tot = &mut scratch.attr_tot[ch];
            for (&i, &slab) in scratch.indices.iter().zip(&scratch.slab_of) {
                let v = channel.values.get(i as usize).copied().unwrap_or(0.0);
                let cell = &mut sums[slab as usize];
                cell[0] += v;
                cell[1] += v * v;
                tot[0] += v;
                tot[1] += v * v;
            }
        }
        let point_weight = self.attributes.map_or(1.0, |a| a.point_weight());
        let total_weight = self.attributes.map_or(1.0, |a| a.total_weight());

        scratch.profile.clear();
        let mut best: Option<Best> = None;
        let mut o1 = 0u32;
        let total = scratch.offsets.len() as u32;
        for k in 0..k_count {
            o1 += scratch.slab_counts[k];
            let [fo1, b1, fo2, b2] = Self::counts(scratch, k, o1, total);
            let (n1, n2) = (fo1 + b1, fo2 + b2);
            let eta_point = eta_from_counts(fo1, b1, fo2, b2);
            let mut eta = eta_point;
            if nch > 0 {
                let mut num = point_weight * eta_point;
                for (ch, channel) in channels.iter().enumerate() {
                    let add = scratch.attr_sums[ch * slabs + k];
                    let run = &mut scratch.attr_run[ch];
                    run[0] += add[0];
                    run[1] += add[1];
                    let tot = scratch.attr_tot[ch];
                    let eta_a =
                        fisher_ratio(fo1, run[0], run[1], fo2, tot[0] - run[0], tot[1] - run[1]);
                    scratch.attr_eta.push(eta_a);
                    num += channel.weight * eta_a;
                }
                eta = if total_weight > 0.0 {
                    num / total_weight
                } else {
                    0.0
                };
            }
            let offset = Self::offset(scratch, k);
            let stats = BoundaryStats {
                offset,
                o1,
                o2: total - o1,
                b1,
                b2,
                mu1: if n1 > 0.0 { fo1 / n1 } else { 0.0 },
                mu2: if n2 > 0.0 { fo2 / n2 } else { 0.0 },
                eta_point,
                eta,
            };
            let admitted = match rule {
                BestRule::Any => true,
                BestRule::InnerDenser { min_inner } => {
                    stats.mu1 >= stats.mu2 && Self::inner_thickness(scratch, k) >= min_inner
                }
            };
            if admitted && stats.eta > 0.0 && best.is_none_or(|b| stats.eta > b.eta) {
                best = Some(Best {
                    boundary: k,
                    offset,
                    eta: stats.eta,
                });
            }
            scratch.profile.push(stats);
        }
        best
    }

    /// The best boundary under `rule` by η_p alone, evaluating
    /// [`eta_from_counts`] only near the maximum (see [`Self::search_best`]).
    ///
    /// Exactness: with every count and capacity below 2²⁶ all products of
    /// two counts are exact, so (a) `μ1 < μ2` is decided exactly by
    /// `o1·n2 < o2·n1`, which agrees with comparing the rounded quotients
    /// (distinct fractions with `n1·n2 < 2⁵²` differ by more than their
    /// rounding), and (b) [`eta_phi2`](crate::separability::point::eta_phi2) is within 8 ulps of the exact η_p while
    /// [`eta_from_counts`] is within `12u·N/min(O, B) + 6u ≤ 12u·N + 6u` of it
    /// (the cancellation in `μ_r − μ_T`; `N` counts, `O`, `B` actual and
    /// non-data totals, `u = 2⁻⁵³`). A boundary screened more than
    /// `tol = 10⁻¹⁴·(N_max + 2)` below the screened maximum therefore has a
    /// smaller η than the maximiser and cannot be the first argmax. Beyond
    /// 2²⁶ every admitted boundary is evaluated.
    fn screened_best(scratch: &mut SearchScratch, rule: BestRule) -> Option<Best> {
        const EXACT: f64 = 67_108_864.0; // 2²⁶
        let k_count = scratch.capacity.len() - 1;
        let total = scratch.offsets.len() as u32;
        let cap_max = scratch.capacity.iter().copied().fold(0.0, f64::max);
        let n_max = 2.0 * cap_max + f64::from(total);
        let exact = n_max < EXACT;
        // Screening keys as ratios [num, den] (den > 0), compared by
        // cross-multiplication: no division per boundary. Rejected
        // boundaries get −1, below any threshold (tol < 1 here).
        scratch.screen.clear();
        let mut top: Option<[f64; 2]> = None;
        let mut o1 = 0u32;
        for k in 0..k_count {
            o1 += scratch.slab_counts[k];
            let [fo1, b1, fo2, b2] = Self::counts(scratch, k, o1, total);
            let (n1, n2) = (fo1 + b1, fo2 + b2);
            // η_p is 0 with an empty side: never the best.
            let admitted = n1 > 0.0
                && n2 > 0.0
                && match rule {
                    BestRule::Any => true,
                    // μ1 ≥ μ2, i.e. not (o1/n1 < o2/n2).
                    BestRule::InnerDenser { min_inner } => {
                        Self::inner_thickness(scratch, k) >= min_inner
                            && if exact {
                                fo1 * n2 >= fo2 * n1
                            } else {
                                fo1 / n1 >= fo2 / n2
                            }
                    }
                };
            let key = match (admitted, exact) {
                (false, _) => [-1.0, 1.0],
                (true, true) => eta_phi2_ratio(fo1, b1, fo2, b2),
                (true, false) => [1.0, 1.0],
            };
            if admitted && top.is_none_or(|t| key[0] * t[1] > t[0] * key[1]) {
                top = Some(key);
            }
            scratch.screen.push(key);
        }
        // A cross-multiplied maximum off by rounding only lowers the
        // threshold (more candidates), which the tolerance covers anyway.
        let top = top?;
        let floor = top[0] / top[1] - 1e-14 * (n_max + 2.0);
        let mut best: Option<Best> = None;
        let mut o1 = 0u32;
        for k in 0..k_count {
            o1 += scratch.slab_counts[k];
            let [num, den] = scratch.screen[k];
            if num < floor * den {
                continue;
            }
            let [fo1, b1, fo2, b2] = Self::counts(scratch, k, o1, total);
            let eta = eta_from_counts(fo1, b1, fo2, b2);
            if eta > 0.0 && best.is_none_or(|b| eta > b.eta) {
                best = Some(Best {
                    boundary: k,
                    offset: Self::offset(scratch, k),
                    eta,
                });
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::separability::point::point_separability;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A square sheet of points on the plane z = z0, spacing `s`, over [-1, 1]².
    fn sheet(z0: f64, s: f64) -> Vec<Vec3> {
        let n = (2.0 / s) as i32;
        let mut v = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                v.push(Vec3::new(-1.0 + i as f64 * s, -1.0 + j as f64 * s, z0));
            }
        }
        v
    }

    #[test]
    fn plane_is_found_at_its_offset() {
        // Sheet at z = 0.13, searched from the origin along +z.
        let pts = sheet(0.13, 0.02);
        let idx = SpatialIndex::new(&pts).unwrap();
        let s = Searcher::new(&idx, Delta::Global(0.02), 39).unwrap();
        let mut scratch = SearchScratch::new();
        let cub = Cuboid::new(Vec3::zeros(), Vec3::z(), 0.09, 0.09, 0.8);
        let out = s.search(&cub, &mut scratch).unwrap();
        // 5 × 5 grid points of spacing 0.02 (x, y in −0.04..=0.04) in the cross-section.
        assert_eq!(out.gathered, 25);
        let best = out.best.unwrap();
        // Slab width 0.02; the sheet at 0.13 lies in slab (0.13+0.4)/0.02 = 26.5 → 26;
        // the best boundary is right after it (r1 = slabs 0..=26 holds every
        // point while r2 is empty) or right before it (symmetric).
        let before = -0.4 + 0.02 * 26.0;
        let after = -0.4 + 0.02 * 27.0;
        assert!(
            (best.offset - after).abs() < 1e-9 || (best.offset - before).abs() < 1e-9,
            "{best:?}"
        );
        assert_eq!(scratch.profile().len(), 39);
        assert_eq!(scratch.slab_counts()[26], 25);
        assert!(scratch.offsets().iter().all(|t| (t - 0.13).abs() < 1e-12));
        assert_eq!(scratch.median_offset_in_band(0.0, 0.2), Some(0.13));
        assert_eq!(scratch.median_offset_in_band(0.2, 0.3), None);
        assert_eq!(scratch.count_in_band(0.1, 0.2), 25);
    }

    #[test]
    fn profile_matches_brute_force_counts() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let pts: Vec<Vec3> = (0..4000)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0) * rng.random_range(0.0f64..1.0).powi(3),
                )
            })
            .collect();
        let per_point: Vec<f64> = (0..pts.len())
            .map(|i| 0.01 + (i % 7) as f64 * 0.01)
            .collect();
        let idx = SpatialIndex::new(&pts).unwrap();
        let mut scratch = SearchScratch::new();
        for q in 0..50 {
            let local = q % 2 == 0;
            let delta = if local {
                Delta::Local(&per_point)
            } else {
                Delta::Global(0.05)
            };
            let k = 1 + q % 17;
            let s = Searcher::new(&idx, delta, k).unwrap();
            let dir = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let cub = Cuboid::new(
                Vec3::new(
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                    0.0,
                ),
                dir,
                rng.random_range(0.05..0.4),
                rng.random_range(0.05..0.4),
                rng.random_range(0.1..1.0),
            )
            .with_tangent(Vec3::new(0.3, -0.2, 0.9));
            let out = s.search(&cub, &mut scratch).unwrap();
            // Brute force: explicit frame, every point.
            let b = cub.oriented_box().unwrap();
            let inside: Vec<(usize, f64)> = pts
                .iter()
                .enumerate()
                .filter_map(|(i, p)| {
                    let d = p - cub.center;
                    let s: Vec<f64> = b.axes.iter().map(|a| d.dot(a)).collect();
                    (0..3).all(|j| s[j].abs() <= b.half[j]).then_some((i, s[0]))
                })
                .collect();
            assert_eq!(out.gathered, inside.len());
            let delta_ref = if local {
                inside.iter().map(|&(i, _)| per_point[i]).sum::<f64>() / inside.len().max(1) as f64
            } else {
                0.05
            };
            if !inside.is_empty() {
                assert!((out.delta - delta_ref).abs() < 1e-12);
            }
            let dw = cub.depth / (k + 1) as f64;
            let mut best = (0.0, None);
            for (kk, st) in scratch.profile().iter().enumerate() {
                let tk = -cub.depth / 2.0 + dw * (kk + 1) as f64;
                assert!((st.offset - tk).abs() < 1e-12);
                // Exclude points within rounding distance of the plane.
                let o1 = inside.iter().filter(|&&(_, t)| t < tk).count() as u32;
                let near = inside
                    .iter()
                    .filter(|&&(_, t)| (t - tk).abs() < 1e-9)
                    .count() as u32;
                assert!(st.o1 >= o1 && st.o1 <= o1 + near, "o1 {} vs {o1}", st.o1);
                assert_eq!(st.o1 + st.o2, inside.len() as u32);
                let area = cub.width * cub.height;
                let r = point_separability(
                    f64::from(st.o1),
                    f64::from(st.o2),
                    area * dw * (kk + 1) as f64,
                    area * dw * (k - kk) as f64,
                    out.delta,
                );
                assert_eq!((st.b1, st.b2, st.mu1, st.mu2), (r.b1, r.b2, r.mu1, r.mu2));
                assert_eq!(st.eta_point, r.eta);
                assert_eq!(st.eta, r.eta);
                if r.eta > best.0 {
                    best = (r.eta, Some(kk));
                }
            }
            assert_eq!(out.best.map(|b| b.boundary), best.1);
            let mut idx_sorted = scratch.indices().to_vec();
            idx_sorted.sort_unstable();
            let want: Vec<u32> = inside.iter().map(|&(i, _)| i as u32).collect();
            assert_eq!(idx_sorted, want);
        }
    }

    #[test]
    fn empty_cuboid_and_bad_input() {
        let pts = sheet(0.0, 0.1);
        let idx = SpatialIndex::new(&pts).unwrap();
        let per_point = vec![0.1; pts.len()];
        let s = Searcher::new(&idx, Delta::Local(&per_point), 10).unwrap();
        let mut scratch = SearchScratch::new();
        let out = s
            .search(
                &Cuboid::new(Vec3::new(0.0, 0.0, 5.0), Vec3::z(), 0.1, 0.1, 0.5),
                &mut scratch,
            )
            .unwrap();
        assert_eq!((out.gathered, out.delta, out.best), (0, 0.0, None));
        assert!(scratch.profile().iter().all(|b| b.eta == 0.0));
        assert!(matches!(
            s.search(
                &Cuboid::new(Vec3::zeros(), Vec3::zeros(), 0.1, 0.1, 0.5),
                &mut scratch
            ),
            Err(SearchError::BadFrame { .. })
        ));
        assert!(matches!(
            s.search(
                &Cuboid::new(Vec3::repeat(f64::NAN), Vec3::z(), 0.1, 0.1, 0.5),
                &mut scratch
            ),
            Err(SearchError::BadFrame { .. })
        ));
        assert!(matches!(
            s.search(
                &Cuboid::new(Vec3::zeros(), Vec3::z(), 0.1, -1.0, 0.5),
                &mut scratch
            ),
            Err(SearchError::BadExtent { what: "height", .. })
        ));
        assert_eq!(
            Searcher::new(&idx, Delta::Global(0.1), 0).unwrap_err(),
            SearchError::NoBoundaries
        );
        assert!(matches!(
            Searcher::new(&idx, Delta::Global(f64::NAN), 3),
            Err(SearchError::BadDelta(_))
        ));
        assert!(matches!(
            Searcher::new(&idx, Delta::Local(&per_point[1..]), 3),
            Err(SearchError::DensityLength { .. })
        ));
    }

    #[test]
    fn denser_side_and_direction_flip() {
        // Dense sheet at z = 0 with a sparse sheet at z = 0.2: searching along
        // +z and −z finds the same physical plane, with mirrored offsets.
        let mut pts = sheet(0.0, 0.02);
        pts.extend(sheet(0.2, 0.1));
        let idx = SpatialIndex::new(&pts).unwrap();
        let s = Searcher::new(&idx, Delta::Global(0.02), 29).unwrap();
        let mut scratch = SearchScratch::new();
        let c = Vec3::new(0.0, 0.0, 0.05);
        let up = s
            .search(&Cuboid::new(c, Vec3::z(), 0.2, 0.2, 0.6), &mut scratch)
            .unwrap()
            .best
            .unwrap();
        let down = s
            .search(&Cuboid::new(c, -Vec3::z(), 0.2, 0.2, 0.6), &mut scratch)
            .unwrap()
            .best
            .unwrap();
        let dw = 0.6 / 30.0;
        // The dense layer at z = 0 is at offset −0.05 (up) and +0.05 (down).
        assert!((up.offset - -0.05).abs() <= dw + 1e-9, "{up:?}");
        assert!((down.offset - 0.05).abs() <= dw + 1e-9, "{down:?}");
    }

    #[test]
    fn inner_margin_keeps_a_sample_on_its_face_of_a_thin_wall() {
        // A thin wall: faces at z = 0 (where the sample sits, normal +z) and
        // z = −0.09, just inside the cuboid's inner end (half depth 0.1).
        let mut pts = sheet(0.0, 0.02);
        pts.extend(sheet(-0.09, 0.02));
        let idx = SpatialIndex::new(&pts).unwrap();
        let s = Searcher::new(&idx, Delta::Global(0.02), 30).unwrap();
        let mut scratch = SearchScratch::new();
        let cub = Cuboid::new(Vec3::new(0.0, 0.0, 0.001), Vec3::z(), 0.2, 0.2, 0.2);
        let best = |min_inner: f64, scratch: &mut SearchScratch| {
            s.search_best(&cub, BestRule::InnerDenser { min_inner }, scratch)
                .unwrap()
                .best
                .unwrap()
        };
        // Without a margin the full thin slab at the far end wins: the
        // sample would jump through the wall.
        let jump = best(0.0, &mut scratch);
        assert!(jump.offset < -0.07, "{jump:?}");
        // With r1 at least a quarter of the depth, the face it sits on wins.
        let stay = best(0.25 * cub.depth, &mut scratch);
        assert!(stay.offset.abs() < 0.02, "{stay:?}");
        assert!(stay.eta > 0.0);
    }

    /// The first largest positive η of the profile among the boundaries
    /// `rule` admits (`half_depth`: half the cuboid's depth).
    fn scan(
        profile: &[BoundaryStats],
        rule: BestRule,
        half_depth: f64,
    ) -> Option<(usize, f64, f64)> {
        let mut best: Option<(usize, f64, f64)> = None;
        for (k, st) in profile.iter().enumerate() {
            if st.eta <= best.map_or(0.0, |b| b.2) {
                continue;
            }
            if let BestRule::InnerDenser { min_inner } = rule {
                if st.mu1 < st.mu2 || st.offset + half_depth < min_inner {
                    continue;
                }
            }
            best = Some((k, st.offset, st.eta));
        }
        best
    }

    #[test]
    fn search_best_matches_profile_scan() {
        use crate::separability::attribute::AttributeSet;
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        // A noisy double layer plus a sparse background, and a regular sheet
        // (many equal counts and ties between boundaries).
        let mut pts: Vec<Vec3> = (0..3000)
            .map(|i| {
                let z = if i % 3 == 0 { 0.1 } else { -0.05 };
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    z + rng.random_range(-0.02..0.02),
                )
            })
            .collect();
        pts.extend((0..500).map(|_| {
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-0.5..0.5),
            )
        }));
        pts.extend(sheet(0.3, 0.05));
        let per_point: Vec<f64> = (0..pts.len())
            .map(|i| 0.01 + (i % 5) as f64 * 0.01)
            .collect();
        let vals: Vec<f32> = pts.iter().map(|p| (p.z * 10.0) as f32).collect();
        let set = AttributeSet::new(1.0, &[("a", &vals, 1.0)]).unwrap();
        let idx = SpatialIndex::new(&pts).unwrap();
        let mut full = SearchScratch::new();
        let mut lean = SearchScratch::new();
        let mut found = 0;
        for q in 0..600 {
            let k = 1 + q % 40;
            // Global δ from typical to tiny (capacities beyond 2²⁶: the
            // unscreened branch), local δ, and the weighted mode.
            let delta = match q % 5 {
                0 => Delta::Global(0.02),
                1 => Delta::Global(1e-4),
                2 => Delta::Local(&per_point),
                _ => Delta::Global(rng.random_range(0.005..0.08)),
            };
            let s = Searcher::new(&idx, delta, k).unwrap();
            let s = if q % 7 == 0 {
                s.with_attributes(&set).unwrap()
            } else {
                s
            };
            let cub = Cuboid::new(
                Vec3::new(
                    rng.random_range(-0.8..0.8),
                    rng.random_range(-0.8..0.8),
                    rng.random_range(-0.2..0.3),
                ),
                Vec3::new(
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                    if q % 2 == 0 { 1.0 } else { -1.0 },
                ),
                rng.random_range(0.02..0.3),
                rng.random_range(0.02..0.3),
                rng.random_range(0.1..0.8),
            );
            let a = s.search(&cub, &mut full).unwrap();
            let margin = BestRule::InnerDenser {
                min_inner: cub.depth * [0.1, 0.25, 0.4][q % 3],
            };
            for rule in [
                BestRule::Any,
                BestRule::InnerDenser { min_inner: 0.0 },
                margin,
            ] {
                let b = s.search_best(&cub, rule, &mut lean).unwrap();
                assert_eq!((a.gathered, a.delta), (b.gathered, b.delta));
                assert_eq!(full.offsets(), lean.offsets());
                assert_eq!(full.slab_counts(), lean.slab_counts());
                let want = scan(full.profile(), rule, cub.depth / 2.0);
                let got = b.best.map(|x| (x.boundary, x.offset, x.eta));
                assert_eq!(got, want, "query {q} rule {rule:?}");
                if rule == BestRule::Any {
                    assert_eq!(a.best, b.best);
                }
                found += usize::from(got.is_some());
            }
        }
        assert!(found > 600, "{found}");
    }

    #[test]
    fn weighted_profile_matches_brute_force() {
        use crate::separability::attribute::AttributeSet;
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let pts: Vec<Vec3> = (0..3000)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.2..0.2),
                )
            })
            .collect();
        let vals: Vec<f32> = pts
            .iter()
            .map(|p| 100.0 + (p.x * 3.0).sin() as f32 + rng.random_range(-0.3f32..0.3))
            .collect();
        let set = AttributeSet::new(1.0, &[("intensity", &vals, 2.0)]).unwrap();
        let idx = SpatialIndex::new(&pts).unwrap();
        let s = Searcher::new(&idx, Delta::Global(0.05), 12)
            .unwrap()
            .with_attributes(&set)
            .unwrap();
        let mut scratch = SearchScratch::new();
        for q in 0..20 {
            let cub = Cuboid::new(
                Vec3::new(
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                    0.0,
                ),
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    0.1,
                ),
                0.3,
                0.3,
                0.8,
            );
            s.search(&cub, &mut scratch).unwrap();
            assert_eq!(scratch.attribute_count(), 1);
            let gathered: Vec<(f64, f64)> = scratch
                .offsets()
                .iter()
                .zip(scratch.indices())
                .map(|(&t, &i)| (t, f64::from(vals[i as usize])))
                .collect();
            for (k, st) in scratch.profile().iter().enumerate() {
                type Side<'s> = Vec<&'s (f64, f64)>;
                let (a, b): (Side, Side) = gathered.iter().partition(|(t, _)| *t < st.offset);
                let direct = if a.is_empty() || b.is_empty() {
                    0.0
                } else {
                    let all: Vec<f64> = gathered.iter().map(|x| x.1).collect();
                    let n = all.len() as f64;
                    let mu = all.iter().sum::<f64>() / n;
                    let vt = all.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / n;
                    let m1 = a.iter().map(|x| x.1).sum::<f64>() / a.len() as f64;
                    let m2 = b.iter().map(|x| x.1).sum::<f64>() / b.len() as f64;
                    let vb = (a.len() as f64 * (m1 - mu).powi(2)
                        + b.len() as f64 * (m2 - mu).powi(2))
                        / n;
                    vb / vt
                };
                let got = scratch.attribute_eta(k)[0];
                assert!(
                    (got - direct).abs() < 1e-7,
                    "query {q} k {k}: {got} vs {direct}"
                );
                assert!((st.eta - (st.eta_point + 2.0 * got) / 3.0).abs() < 1e-12);
            }
        }
        // A channel shorter than the cloud is rejected.
        let short = AttributeSet::new(1.0, &[("x", &vals[..10], 1.0)]).unwrap();
        assert!(matches!(
            Searcher::new(&idx, Delta::Global(0.05), 3)
                .unwrap()
                .with_attributes(&short),
            Err(SearchError::AttributeLength { .. })
        ));
    }

    #[test]
    fn colour_edge_found_by_attribute_alone() {
        use crate::separability::attribute::AttributeSet;
        // Uniform sheet (columns at even hundredths); luma steps from 0.2 to
        // 0.8 at x = 0.31, midway between two columns.
        let pts = sheet(0.0, 0.02);
        let luma: Vec<f32> = pts
            .iter()
            .map(|p| if p.x < 0.31 { 0.2 } else { 0.8 })
            .collect();
        let set = AttributeSet::new(0.0, &[("luma", &luma, 1.0)]).unwrap();
        let idx = SpatialIndex::new(&pts).unwrap();
        let s = Searcher::new(&idx, Delta::Global(0.02), 29)
            .unwrap()
            .with_attributes(&set)
            .unwrap();
        let mut scratch = SearchScratch::new();
        let out = s
            .search(
                &Cuboid::new(Vec3::x() * 0.01, Vec3::x(), 0.1, 0.1, 0.9),
                &mut scratch,
            )
            .unwrap();
        let best = out.best.unwrap();
        // Boundaries at 0.01 − 0.45 + 0.03(k+1): the edge 0.31 is boundary 24, offset 0.30.
        assert_eq!(best.boundary, 24, "{best:?}");
        assert!((best.offset - 0.3).abs() < 1e-9, "{best:?}");
        assert!(best.eta > 0.99, "{best:?}");
    }

    /// Dyadic coordinates keep offsets bit-exact under translation by
    /// integers and scaling by powers of two.
    fn dyadic_cloud(seed: u64) -> Vec<Vec3> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..600)
            .map(|_| {
                Vec3::new(
                    f64::from(rng.random_range(-64i32..64)) / 64.0,
                    f64::from(rng.random_range(-64i32..64)) / 64.0,
                    f64::from(rng.random_range(-16i32..16)) / 256.0,
                )
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn profile_invariant_under_translation_and_scale(
            seed in 0u64..1000, axis in 0usize..3, k in 1usize..40,
            shift in (-8i32..8, -8i32..8, -8i32..8), scale_exp in -3i32..4,
            w in 1u32..32, d in 1u32..64, delta_i in 1u32..16,
        ) {
            let pts = dyadic_cloud(seed);
            let s = 2f64.powi(scale_exp);
            let shift = Vec3::new(f64::from(shift.0), f64::from(shift.1), f64::from(shift.2));
            let moved: Vec<Vec3> = pts.iter().map(|p| (p + shift) * s).collect();
            let dir = [Vec3::x(), Vec3::y(), Vec3::z()][axis];
            let (w, d, delta) = (f64::from(w) / 32.0, f64::from(d) / 32.0, f64::from(delta_i) / 128.0);
            // Centre off the lattice so no point sits on a boundary plane.
            let c = Vec3::new(1.0 / 1024.0, 3.0 / 1024.0, 5.0 / 2048.0);
            let run = |pts: &[Vec3], c: Vec3, w: f64, d: f64, delta: f64| {
                let idx = SpatialIndex::new(pts).unwrap();
                let searcher = Searcher::new(&idx, Delta::Global(delta), k).unwrap();
                let mut scratch = SearchScratch::new();
                let out = searcher.search(&Cuboid::new(c, dir, w, w, d), &mut scratch).unwrap();
                (out, scratch.profile().to_vec())
            };
            let (a, pa) = run(&pts, c, w, d, delta);
            let (b, pb) = run(&moved, (c + shift) * s, w * s, d * s, delta * s);
            prop_assert_eq!(a.gathered, b.gathered);
            prop_assert_eq!(a.best.map(|x| x.boundary), b.best.map(|x| x.boundary));
            for (x, y) in pa.iter().zip(&pb) {
                prop_assert!((0.0..=1.0).contains(&x.eta));
                prop_assert_eq!((x.o1, x.o2), (y.o1, y.o2));
                prop_assert!((x.eta - y.eta).abs() < 1e-12);
            }
        }
    }
}
