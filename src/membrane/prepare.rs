//! What the evolution needs from a cloud, prepared once per reconstruction
//! (and shared by its pole-axis candidates): the finite, distinct points,
//! thinned to `prepare.max_points`, without the groups detached from the
//! object's main body ([`crate::detached`]); the k-NN outlier filter; the point spacing δ
//! (paper Eq. 5); a single view's viewpoint and mirrored completion; the
//! spatial index of the search; the attribute channels of the weighted
//! separability (Eq. 9); the occupancy grid of the inward force.
//!
//! One k-NN index ([`KnnIndex`]) of the thinned points is built per
//! reconstruction and serves every k-NN query: the d_i of Eq. 5 (all points,
//! or the `density_sample` subset), hence δ, the outlier filter by d_i and
//! the per-point d_i of the local δ_R (Eq. 6, `search_delta = "local"`).
//! With `density_sample` the outlier filter counts points in voxels instead
//! (a grid of cell ⅔·outlier_factor·δ, which needs δ first); the cuboid
//! search has its own grid over the filtered points, with cells of
//! [`SEARCH_CELL_DELTA`]·δ (the automatic size in the weighted mode and
//! with a local δ).
//!
//! δ is the median of the per-point mean k-NN distances d_i for a single
//! view, where the spacing varies with depth and incidence, and
//! `delta_scale` × their `delta_quantile` for a whole object (1.3 × the
//! lower quartile by default, which measures the surface's own spacing even
//! when up to half the points are outliers: the prototype's outlier runs,
//! `../shared/notes/prototype-findings.md`). The keys are those of `membrane.prepare`.

use super::config::{Completion, MembraneConfig, PrepareConfig, SearchDelta};
use super::occupancy::OutsideGrid;
use super::solid::Solid;
use super::view::{self, Seen};
use super::MembraneError;
use crate::cloud::{Aabb, CloudError, PointCloud, Vec3};
use crate::density::{median_of, Density};
use crate::detached;
use crate::separability::attribute::{AttributeSet, AttributeWeights, ChannelWeight};
use crate::separability::grid::SpatialIndex;
use crate::spatial::KnnIndex;
use std::collections::HashSet;
use std::time::Instant;

/// Smallest number of points the membrane accepts.
pub const MIN_POINTS: usize = 16;

/// Cell edge of the cuboid search's grid, in multiples of δ. The automatic
/// size of [`SpatialIndex::new`] (about 3.7 δ on a surface cloud) made a warm
/// frame's cuboid (15 points inside) test 113 points in 8.7 cells; at 2.5 δ
/// the median thread-CPU time of a warm `bench-node` frame (one iteration,
/// 20 k points) fell by 4.6 % (2 δ: 3.6 %, 3 δ: 1.5 %, 4 δ: 0.1 %; 150
/// frames each, interleaved). The gathered set is the same at any size, and
/// so is the outcome of a search with the global δ and no attributes (counts
/// and order statistics); the weighted search and a local δ keep the
/// automatic cell, because their sums follow the gathering order (the colour
/// test's weighted F moved from 0.907 to 0.897 with 2.5 δ cells).
pub const SEARCH_CELL_DELTA: f64 = 2.5;

/// Radius of the `density` attribute (neighbour count), in multiples of δ.
const DENSITY_ATTRIBUTE_RADIUS: f64 = 2.0;

/// The prepared points of one reconstruction.
pub(crate) struct Prepared<'a> {
    pub(crate) counts: PointCounts,
    /// The used points (finite, thinned, outlier-filtered, plus a single
    /// view's completion).
    pub(crate) points: Vec<Vec3>,
    /// The d_i of the used points (δ where only δ is known).
    pub(crate) d_used: Vec<f64>,
    pub(crate) delta: f64,
    /// The per-point spacing δ_i of `prepare.local_spacing` (with the global
    /// δ and exact d_i only).
    pub(crate) spacing: Option<Vec<f64>>,
    /// Longest bounding-box edge of the used points.
    pub(crate) scale: f64,
    pub(crate) view: Option<view::ViewBuffer>,
    /// The free space of the views a fused cloud was made from.
    pub(crate) free: Option<&'a dyn view::FreeSpace>,
    /// The solid the fused cloud was completed to.
    pub(crate) solid: Option<super::solid::Solid>,
    pub(crate) index: SpatialIndex,
    pub(crate) attributes: Option<AttributeSet>,
    pub(crate) outside: Option<OutsideGrid>,
    pub(crate) prepare_ms: f64,
}

/// What the preparation did with the input points (see [`super::Report`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PointCounts {
    pub(crate) input: usize,
    pub(crate) non_finite: usize,
    pub(crate) duplicate: usize,
    pub(crate) thinned: usize,
    pub(crate) detached: usize,
    pub(crate) outliers: usize,
    pub(crate) completed: usize,
}

impl Prepared<'_> {
    /// What the cameras saw around the used points.
    pub(crate) fn seen(&self) -> Seen<'_> {
        Seen::of(self.view.as_ref(), self.free, self.solid.as_ref())
    }

    /// The camera of a partial cloud: the single view's, or the latest
    /// view's of a fused one (`None`: seen from all around).
    pub(crate) fn eye(&self) -> Option<Vec3> {
        match &self.view {
            Some(v) => Some(v.eye()),
            None => self.free.and_then(|f| f.latest_eye()),
        }
    }

    /// Whether the cloud was taken as a single depth view (a fused cloud
    /// with its views' free space, `free`, is not: it is seen from
    /// several sides, but like a single view it is partial, and the pole
    /// axes are not tried in turn for it).
    pub(crate) fn is_single_view(&self) -> bool {
        self.view.is_some()
    }
}

/// The indices of `cloud`'s finite points, exact repeats dropped (they
/// carry no new geometry, and many of them would collapse the k-NN
/// distances and with them δ), and how many were non-finite.
fn finite_distinct(cloud: &PointCloud) -> (Vec<usize>, usize) {
    let finite: Vec<usize> = cloud
        .points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.iter().all(|c| c.is_finite()))
        .map(|(i, _)| i)
        .collect();
    let non_finite = cloud.len() - finite.len();
    // aHash, keyed per process like SipHash (the points may come from a
    // hostile stream) but several times cheaper on 24-byte keys: with
    // SipHash this set was 1.3 % of a warm frame.
    let mut seen: HashSet<_, ahash::RandomState> =
        HashSet::with_capacity_and_hasher(finite.len(), ahash::RandomState::new());
    let distinct = finite
        .into_iter()
        .filter(|&i| {
            let p = cloud.points[i];
            seen.insert([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        })
        .collect();
    (distinct, non_finite)
}

/// The `q` quantile of `d` (reordering it), at least `1e-9 · scale`.
fn quantile(d: &mut [f64], q: f64, scale: f64) -> f64 {
    let at = ((d.len() as f64 * q) as usize).min(d.len().saturating_sub(1));
    d.select_nth_unstable_by(at, f64::total_cmp)
        .1
        .max(1e-9 * scale)
}

/// The finite, distinct points of a cloud, thinned to `prepare.max_points`,
/// with the indices (into the cloud) they came from, so that the attribute
/// channels of the weighted mode follow the same selection.
struct Usable {
    idx: Vec<usize>,
    points: Vec<Vec3>,
    non_finite: usize,
    duplicate: usize,
    thinned: usize,
    detached: usize,
}

/// The [`Usable`] points of `cloud`, or why there are too few (whether
/// they span a volume is checked after the outlier filter).
fn usable(cloud: &PointCloud, p: &PrepareConfig) -> Result<Usable, MembraneError> {
    let (finite_idx, non_finite) = finite_distinct(cloud);
    let duplicate = cloud.len() - non_finite - finite_idx.len();
    let finite_len = finite_idx.len();
    let idx = match p.max_points {
        Some(cap) => thin(finite_idx, cap),
        None => finite_idx,
    };
    let thinned = finite_len - idx.len();
    let mut points: Vec<Vec3> = idx.iter().map(|&i| cloud.points[i]).collect();
    let mut idx = idx;
    let body = p
        .detached
        .as_ref()
        .and_then(|d| detached::body(&points, d, None));
    if let Some(body) = body {
        idx.retain(|&i| body.contains(&cloud.points[i]));
        points.retain(|q| body.contains(q));
    }
    let detached = finite_len - thinned - idx.len();
    if points.is_empty() {
        return Err(CloudError::Empty.into());
    }
    if points.len() < MIN_POINTS {
        return Err(CloudError::TooFewUsable {
            usable: points.len(),
            points: cloud.len(),
            non_finite,
            duplicate,
            detached,
            need: MIN_POINTS,
        }
        .into());
    }
    Ok(Usable {
        idx,
        points,
        non_finite,
        duplicate,
        thinned,
        detached,
    })
}

/// The cuboid search's grid. The weighted profile sums attributes per slab,
/// and a local δ averages the gathered points' spacings, in the order the
/// grid gathers them: their results depend (in the last bits, then through
/// the argmax) on the cell size, so they keep the automatic cell; the
/// order-free default search gets cells of [`SEARCH_CELL_DELTA`] δ.
fn search_grid(
    points: &[Vec3],
    order_free: bool,
    delta: f64,
) -> Result<SpatialIndex, MembraneError> {
    Ok(if order_free {
        SpatialIndex::with_cell_size(points, SEARCH_CELL_DELTA * delta)?
    } else {
        SpatialIndex::new(points)?
    })
}

/// Prepare `cloud` (see the module docs).
/// `free`: the free space of the views a fused cloud was made from.
pub(crate) fn prepare<'a>(
    cloud: &PointCloud,
    cfg: &MembraneConfig,
    free: Option<&'a dyn view::FreeSpace>,
) -> Result<Prepared<'a>, MembraneError> {
    let t_start = Instant::now();
    let points_in = cloud.len();
    let p = &cfg.prepare;
    let Usable {
        idx: finite_idx,
        points: finite,
        non_finite,
        duplicate,
        thinned,
        detached,
    } = usable(cloud, p)?;
    // The frame's one k-NN index: d_i, δ and the outlier filter.
    let knn = KnnIndex::new(finite);
    let finite = knn.points();
    let sample = p
        .density_sample
        .filter(|&n| finite.len() > n && p.search_delta == SearchDelta::Global);
    let (keep, d_kept) = match sample {
        Some(n) => sampled_density(&knn, p, n)?,
        None => exact_density(&knn, p)?,
    };
    let points: Vec<Vec3> = keep.iter().map(|&k| finite[k]).collect();
    let outliers = finite.len() - points.len();
    // After the outlier filter: a few points far off an object (a flying
    // pixel, a stray return) would otherwise dwarf its spread and make it
    // read as flat.
    // The extent first: a spread's covariance overflows where the extent
    // is out of range.
    let e = Aabb::from_points(&points).extent();
    crate::cloud::check_extent(&e)?;
    crate::cloud::check_spread(&points)?;
    let scale = e.max();
    let mut d_order = d_kept.clone();
    let median = quantile(&mut d_order, 0.5, scale);
    // Single views: the viewpoint, its z-buffer, the bound on the unseen
    // side's depth and its mirrored completion (membrane/view.rs).
    // A fused cloud (given its views' free space) is never taken for one
    // view by the "auto" detection, which would otherwise flip between the
    // two treatments from frame to frame as its second layer fills in.
    let mut view = match (cfg.view.viewpoint, free) {
        (view::Viewpoint::Mode(view::ViewMode::Auto), Some(_)) => None,
        (viewpoint, _) => view::resolve(viewpoint, &points, median),
    };
    // A single view, and a fused cloud with its views' free space, keep
    // the median (membrane.prepare.delta_quantile's note).
    let delta = if view.is_some() || free.is_some() {
        median
    } else {
        (quantile(&mut d_order, p.delta_quantile, scale) * p.delta_scale).max(1e-9 * scale)
    };
    // Per-point d_i of the used points (the sampled density knows only δ).
    let exact = d_kept.len() == points.len();
    let mut d_used = if exact {
        d_kept
    } else {
        vec![delta; points.len()]
    };
    let mut points = points;
    let (completed, solid) = match (view.as_mut(), free) {
        (None, Some(f)) => complete_fused_cloud(cfg, f, delta, &mut points, &mut d_used),
        (view, _) => (complete_view(cfg, view, &mut points, &mut d_used), None),
    };
    let spacing = p
        .local_spacing
        .as_ref()
        .filter(|_| exact && p.search_delta == SearchDelta::Global && !weighted(cfg))
        .map(|l| super::spacing::local_spacing(&points, &d_used, delta, l));
    // Weighted mode (paper Eq. 9): the attribute channels of the used points.
    let attributes = if !weighted(cfg) {
        None
    } else {
        let used: Vec<usize> = keep.iter().map(|&k| finite_idx[k]).collect();
        Some(attribute_set(&cloud.select(&used), cfg, delta)?)
    };
    let order_free =
        attributes.is_none() && spacing.is_none() && p.search_delta == SearchDelta::Global;
    let index = search_grid(&points, order_free, delta)?;
    let seen = Seen::of(view.as_ref(), free, solid.as_ref());
    let outside = outside_grid(cfg, &points, spacing.as_deref(), delta, seen);
    Ok(Prepared {
        counts: PointCounts {
            input: points_in,
            non_finite,
            duplicate,
            thinned,
            detached,
            outliers,
            completed,
        },
        points,
        d_used,
        delta,
        spacing,
        scale,
        view,
        free,
        solid,
        index,
        attributes,
        outside,
        prepare_ms: t_start.elapsed().as_secs_f64() * 1e3,
    })
}

/// Whether the search runs in the weighted mode (paper Eq. 9): attribute
/// channels, or a spatial weight other than 1.
fn weighted(cfg: &MembraneConfig) -> bool {
    !cfg.step.attributes.is_empty() || cfg.step.spatial_weight != 1.0
}

/// A single view's back bound (`view.back`) and mirrored completion of its
/// unseen side (`view.completion`), appended to `points` and `d_used` (each
/// mirror point takes its source's d_i); returns how many were added.
fn complete_view(
    cfg: &MembraneConfig,
    view: Option<&mut view::ViewBuffer>,
    points: &mut Vec<Vec3>,
    d_used: &mut Vec<f64>,
) -> usize {
    let Some(vb) = view else {
        return 0;
    };
    if let Some(back) = &cfg.view.back {
        vb.bound_back(points, back.extent);
    }
    if cfg.view.completion != Completion::Mirror {
        return 0;
    }
    let extra = vb.complete(points);
    vb.set_back(extra.iter().map(|(q, _)| q));
    points.reserve(extra.len());
    d_used.reserve(extra.len());
    let added = extra.len();
    for (q, i) in extra {
        points.push(q);
        d_used.push(d_used[i]);
    }
    added
}

/// The completion of a fused cloud: revolved (`view.revolution`) when it is
/// a surface of revolution, else a sphere (`view.sphere`) when it is a
/// sphere cap, else mirrored (`view.fused_completion`); each added point
/// takes δ, or its mirror source's d_i. Returns how many were added, and
/// the solid that bounds the carving.
fn complete_fused_cloud(
    cfg: &MembraneConfig,
    free: &dyn view::FreeSpace,
    delta: f64,
    points: &mut Vec<Vec3>,
    d_used: &mut Vec<f64>,
) -> (usize, Option<Solid>) {
    let (added, solid) = complete_as_solid(cfg, free, delta, points);
    d_used.resize(points.len(), delta);
    let solid = solid.or_else(|| fused_back(cfg, free, delta, points));
    let added = match &cfg.view.fused_completion {
        Some(fc) if added == 0 => complete_fused(free, fc, delta, points, d_used),
        _ => added,
    };
    (added, solid)
}

/// The bound on the unseen side's depth of a fused cloud whose carving no
/// completed solid bounds (none completes it, or its `carve_delta` is
/// null): `view.back`, [`view::BackBound`], seen from its latest view's
/// camera.
fn fused_back(
    cfg: &MembraneConfig,
    free: &dyn view::FreeSpace,
    delta: f64,
    points: &[Vec3],
) -> Option<Solid> {
    let (back, eye) = (cfg.view.back.as_ref()?, free.latest_eye()?);
    view::BackBound::of(points, eye, delta, back.extent).map(Solid::Back)
}

/// The completion of a fused cloud as a solid of revolution, else as a
/// ball: how many points were added, and the solid when it bounds the
/// carving.
fn complete_as_solid(
    cfg: &MembraneConfig,
    free: &dyn view::FreeSpace,
    delta: f64,
    points: &mut Vec<Vec3>,
) -> (usize, Option<Solid>) {
    let (revolution, sphere) = (cfg.view.revolution.as_ref(), cfg.view.sphere.as_ref());
    if revolution.is_none() && sphere.is_none() {
        return (0, None);
    }
    let index = KnnIndex::new(points.clone());
    if let Some(r) =
        revolution.and_then(|rc| super::revolution::complete(free, rc, delta, &index, points))
    {
        return (r.added, r.solid.map(Solid::Revolution));
    }
    let Some((sc, c)) = sphere
        .and_then(|sc| super::sphere::complete(free, sc, delta, &index, points).map(|c| (sc, c)))
    else {
        return (0, None);
    };
    let solid = sc.carve_delta.map(|m| Solid::Ball(c.ball, m * delta));
    (c.added, solid)
}

/// The mirrored completion of a fused cloud (`view.fused_completion`,
/// [`view`] 6.): while the model keeps at most `max_views` views, the fused
/// points on its latest view's surface are completed as one view
/// ([`view::ViewBuffer::complete`]), keeping the mirror points that no
/// view saw empty and that lie more than `gap_delta`·δ from every fused
/// point; appended to `points` and `d_used` (each takes its source's
/// d_i). Returns how many were added. The gap is measured to the used
/// points, not through the frame's k-NN index, which holds the points
/// before the outlier filter (with it, the 15 sequences of the measurement
/// gave last-third IoU 0.768 instead of 0.834).
fn complete_fused(
    free: &dyn view::FreeSpace,
    cfg: &super::config::FusedCompletionConfig,
    delta: f64,
    points: &mut Vec<Vec3>,
    d_used: &mut Vec<f64>,
) -> usize {
    let Some(eye) = free
        .latest_eye()
        .filter(|_| free.views_kept() <= cfg.max_views)
    else {
        return 0;
    };
    let seen: Vec<usize> = (0..points.len())
        .filter(|&i| free.on_latest_surface(&points[i]))
        .collect();
    let front: Vec<Vec3> = seen.iter().map(|&i| points[i]).collect();
    let Some(vb) = view::ViewBuffer::new(&front, eye, delta) else {
        return 0;
    };
    let fused = KnnIndex::new(points.clone());
    let gap2 = (cfg.gap_delta * delta).powi(2);
    let extra: Vec<(Vec3, usize)> = vb
        .complete(&front)
        .into_iter()
        .filter(|(q, _)| !free.is_seen_free(q) && fused.nearest_one(q).0 > gap2)
        .collect();
    for &(q, k) in &extra {
        points.push(q);
        d_used.push(d_used[seen[k]]);
    }
    extra.len()
}

/// The occupancy grid of the inward force (`None` when it is off or the
/// grid would be too large); with the local spacing `spacing`, each point
/// counts for the area it samples, `(δ_i/δ)²`. The occluded back of a
/// single view is unknown, not empty — except beyond the back of the
/// completion; so is every place no view of a fused cloud saw empty.
fn outside_grid(
    cfg: &MembraneConfig,
    points: &[Vec3],
    spacing: Option<&[f64]>,
    delta: f64,
    seen: Seen<'_>,
) -> Option<OutsideGrid> {
    let inward = cfg.step.inward.as_ref()?;
    let weights: Option<Vec<f64>> =
        spacing.map(|s| s.iter().map(|&d| (d / delta).powi(2)).collect());
    OutsideGrid::weighted(
        points,
        weights.as_deref(),
        inward.voxel_delta * delta,
        inward.min_points,
        1 << 22,
    )
    .map(|mut g| {
        if !matches!(seen, Seen::AllAround) {
            g.restrict(|c| seen.may_be_outside(c));
        }
        g
    })
}

/// The attribute channels and weights of the weighted separability (paper
/// Eq. 9) named by `membrane.step.attributes` / `membrane.step.spatial_weight`, taken
/// from `cloud` (the used points). `intensity`, `luma` (colour from `r, g, b`)
/// and `density` are the built-in channels; any other name is a float
/// channel of the input.
///
/// # Errors
/// [`MembraneError::MissingAttribute`] when the cloud lacks a named channel;
/// [`MembraneError::Config`] for a bad weight.
fn attribute_set(
    cloud: &PointCloud,
    cfg: &MembraneConfig,
    delta: f64,
) -> Result<AttributeSet, MembraneError> {
    let mut w = AttributeWeights {
        point: cfg.step.spatial_weight,
        intensity: 0.0,
        luma: 0.0,
        density: 0.0,
        channels: Vec::new(),
    };
    for a in &cfg.step.attributes {
        match a.name.as_str() {
            "intensity" => w.intensity += a.weight,
            "luma" => w.luma += a.weight,
            "density" => w.density += a.weight,
            other => w.channels.push(ChannelWeight {
                name: other.to_string(),
                weight: a.weight,
            }),
        }
    }
    let set = AttributeSet::from_cloud(cloud, &w, delta, DENSITY_ATTRIBUTE_RADIUS)
        .map_err(|e| super::ConfigError::new("step.attributes", e.to_string()))?;
    if let Some(name) = set.missing().first() {
        return Err(MembraneError::MissingAttribute(name.clone()));
    }
    if set.total_weight() <= 0.0 {
        return Err(super::ConfigError::new(
            "step.spatial_weight",
            "the spatial weight and the attribute weights sum to 0",
        )
        .into());
    }
    Ok(set)
}

/// Keep at most `cap` of `points` (0 = all), by [`crate::cloud::thin_indices`]
/// (salt 0). Exactly `cap` points are kept.
pub fn thin<T: Copy>(points: Vec<T>, cap: usize) -> Vec<T> {
    if cap == 0 || points.len() <= cap {
        return points;
    }
    crate::cloud::thin_indices(points.len(), cap, 0)
        .into_iter()
        .map(|i| points[i])
        .collect()
}

/// The points kept by the outlier filter (indices into the points of
/// `knn`) and the d_i (paper Eq. 5) of every kept point: every point's
/// k-NN distance, and `d_i ≤ outlier_factor · median` keeps it (every point
/// without a factor; with `local_spacing` also a point within
/// `outlier_factor` of its kept neighbours' d_i,
/// [`super::spacing::kept_relative`]).
fn exact_density(
    knn: &KnnIndex,
    cfg: &PrepareConfig,
) -> Result<(Vec<usize>, Vec<f64>), MembraneError> {
    let density = Density::from_index(knn, cfg.knn_k)?;
    let d_all = density.per_point();
    let limit = cfg.outlier_factor.map(|f| f * density.median());
    // With the local spacing, a point as sparse as its kept neighbours is
    // kept too (membrane/spacing.rs).
    let relative = match (cfg.outlier_factor, limit, &cfg.local_spacing) {
        (Some(f), Some(l), Some(ls)) if cfg.search_delta == SearchDelta::Global => Some(
            super::spacing::kept_relative(knn, d_all, l, f, ls.neighbours),
        ),
        _ => None,
    };
    let keep = kept_or_all(knn.len(), limit.is_some(), |k| match &relative {
        Some(r) => r[k],
        None => limit.is_some_and(|l| d_all[k] <= l),
    });
    let d_kept = keep.iter().map(|&k| d_all[k]).collect();
    Ok((keep, d_kept))
}

/// The indices `0..n` that pass `keep` when `filter` is on, or all of them
/// when it is off or fewer than [`MIN_POINTS`] would remain.
fn kept_or_all(n: usize, filter: bool, keep: impl Fn(usize) -> bool) -> Vec<usize> {
    if filter {
        let kept: Vec<usize> = (0..n).filter(|&i| keep(i)).collect();
        if kept.len() >= MIN_POINTS {
            return kept;
        }
    }
    (0..n).collect()
}

/// `membrane.prepare.density_sample` (`sample`): the k-NN distances (in
/// the points of `knn`) of a spread subset of the points only (δ is their
/// median over the kept ones), and an outlier filter by voxel counts — a
/// point is kept when the 3×3×3 voxels of edge ⅔·outlier_factor·δ around
/// it hold more than `knn_k` points. Returns the kept indices and the d_i
/// of the kept subset points.
fn sampled_density(
    knn: &KnnIndex,
    cfg: &PrepareConfig,
    sample: usize,
) -> Result<(Vec<usize>, Vec<f64>), MembraneError> {
    let finite = knn.points();
    let k = cfg.knn_k.min(finite.len() - 1);
    if k == 0 {
        return Err(crate::density::DensityError::ZeroK.into());
    }
    let subset = thin((0..finite.len()).collect(), sample);
    let queries: Vec<Vec3> = subset.iter().map(|&i| finite[i]).collect();
    let d_sub = crate::density::knn_mean_distances(knn, &queries, k);
    let delta0 = median_of(&d_sub);
    let Some(factor) = cfg.outlier_factor.filter(|_| delta0 > 0.0) else {
        return Ok(((0..finite.len()).collect(), d_sub));
    };
    let index = SpatialIndex::with_cell_size(finite, factor * delta0 * 2.0 / 3.0)?;
    let inlier: Vec<bool> = finite
        .iter()
        .map(|p| index.count_around([p.x, p.y, p.z]) > k)
        .collect();
    let kept = kept_or_all(finite.len(), true, |i| inlier[i]);
    if kept.len() == finite.len() {
        return Ok((kept, d_sub));
    }
    let d_kept: Vec<f64> = subset
        .iter()
        .zip(&d_sub)
        .filter(|(&i, _)| inlier[i])
        .map(|(_, &d)| d)
        .collect();
    Ok((kept, if d_kept.is_empty() { d_sub } else { d_kept }))
}
