//! The evolution loop of the separability membrane (paper §III-D steps 1–5,
//! dynamic adjustment §III-F).
//!
//! Each iteration samples the surface on the grid of Eq. 14, runs the
//! oriented separability search (Eq. 7 / Eq. 9) along every sample's outward
//! normal, turns the profile into a shift (inner-side-denser rule with an
//! inner margin, dense-side significance, median of the offsets in a band
//! around `t*`, gated inward force), median-filters the shifts over the 3×3
//! sample neighbourhood, moves the samples by `β·shift` and refits the
//! control net. `η_g` is the mean of the per-sample accepted maxima `η*`.
//!
//! The inner margin (`inner_margin`) admits only boundaries whose inner
//! region is at least a fixed fraction of the cuboid's depth. Eq. 7 rewards a
//! thin `r1` that a layer fills almost completely, so a layer just inside the
//! cuboid's inner end could outscore the layer a sample sits on: as the
//! decaying depth passed the thickness of a thin wall, samples on one face
//! jumped to the other one and the membrane crumpled inside the wall (the
//! bowl: F 0.74 on clean points against 0.92 with noise, whose thicker layer
//! the cuboid's end cuts).
//!
//! Warm starts, and cold whole-object reconstructions on the final grid of a
//! cloud at least as dense as the samples, search a checkerboard half of
//! the samples per iteration (alternating); the other half take their
//! searched neighbours' median shift (`sparse_warm_search`,
//! `sparse_cold_search`).
//!
//! Near the poles, samples without a data force get a membrane tension
//! (`pole_tension`): the normal component of the step to their grid
//! neighbours' mean. A pole caught in a thick shell of outliers otherwise
//! stays out as a thin horn that no search sees, because its samples' normals
//! point across it.
//!
//! Whole objects redistribute their samples along the rings
//! (`redistribute_stretch`): the sample grid is fixed in `(u, v)`, so where
//! the membrane stretches (a sheet pushed into a cavity whose opening lies
//! across the rings) its samples and control columns thin out and the sheet
//! stalls in a coarse V. When a ring's largest arc length per unit `u`
//! exceeds `redistribute_stretch` × its mean, the refitted surface is
//! refitted once more to itself at the arc-length parameters.
//!
//! A warm-started single view smooths its occluded back
//! (`warm_back_smoothing`): samples behind the seen surface with no data
//! force move by the mean-free umbrella step, so dents carried over from
//! earlier frames fade.
//!
//! The gated inward force acts on samples with no significant boundary that
//! lie in empty space outside the object ([`OutsideGrid`]). It moves a
//! sample by `−inward_step·depth` along its normal when the normal faces
//! away from the points' centroid. A sample whose normal faces the centroid
//! belongs either to a legitimately concave part (a bowl's inner wall) or to
//! a pocket that folded over while wrapping a limb, and "inward" is
//! ambiguous there, and the normal line decides: when it meets solid space
//! in front before behind (the folded-over case, whose normal faces the
//! object), the sample moves along the normal; when it meets solid space
//! only behind (a sheet hanging in a cavity, such as the membrane's cap
//! that descended into a bowl and stalled below the centroid), against it;
//! otherwise it stays. Without the first case such pockets hang in the
//! empty space between the legs of an animal or beside the step of a CAD
//! part (Table 1: Spot F 0.75 → 0.88, Fandisk 0.78 → 0.85, hammer 0.69 →
//! 0.84); the second took the bowl from 0.90 to 0.98 (genus-0 F 0.929 →
//! 0.935; the procedural torus 0.926 → 0.906, whose hole caps it moves on
//! a little further). A single view keeps the withholding rule: there the
//! fold rule raised the F-score of cold frames but set warm-started frames
//! off course (synth bottle sequence: warm frames within 0.01 of cold 19/19
//! → 9/19).

use super::config::{MembraneConfig, PoleAxis};
use super::extract::extract_mesh;
use super::init::{self, octagon};
use super::occupancy::OutsideGrid;
use super::view;
use super::{Budget, MembraneError, PhaseTimes, Reconstruction, Report, StopReason, WarmStart};
use crate::cloud::{Aabb, CloudError, PointCloud, Vec3};
use crate::density::{median_of, Density};
use crate::separability::attribute::{AttributeSet, AttributeWeights, ChannelWeight};
use crate::separability::grid::SpatialIndex;
use crate::separability::search::{BestRule, Cuboid, Delta, SearchScratch, Searcher};
use crate::spline::{
    param_stretch, redistribute, regrid, ClosedSurface, FitSystem, Layout, SurfacePoint,
};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// The robust shift centres on the nearest 1/KEEP_DIV of the band points.
const KEEP_DIV: usize = 2;

/// Smallest number of points the membrane accepts.
pub const MIN_POINTS: usize = 16;

/// Rings over which the ring stretch of `redistribute_stretch` is averaged.
const STRETCH_RINGS: usize = 16;

/// Check every parameter's range.
///
/// # Errors
/// [`MembraneError::Config`] naming the first bad key.
pub fn validate(cfg: &MembraneConfig) -> Result<(), MembraneError> {
    let bad = |key: &'static str, problem: &str| {
        Err(MembraneError::Config {
            key,
            problem: problem.to_string(),
        })
    };
    let pos = |x: f64| x > 0.0 && x.is_finite();
    if cfg.knn_k == 0 {
        return bad("knn_k", "must be at least 1");
    }
    if cfg.outlier_factor.is_nan() || cfg.outlier_factor < 0.0 {
        return bad("outlier_factor", "must be >= 0");
    }
    if cfg.grid_start[0] < 4 || cfg.grid_start[1] < 4 {
        return bad("grid_start", "needs M >= 4 and L >= 4");
    }
    if cfg.grid_max[0] < cfg.grid_start[0] || cfg.grid_max[1] < cfg.grid_start[1] {
        return bad("grid_max", "must be at least grid_start");
    }
    if cfg.adaptive && cfg.grid_step[0] == 0 && cfg.grid_step[1] == 0 {
        return bad("grid_step", "must add at least one column or row");
    }
    if cfg.div_min < 4 {
        return bad("div_min", "must be at least 4");
    }
    if !pos(cfg.alpha) {
        return bad("alpha", "must be positive");
    }
    if !pos(cfg.alpha_warm) {
        return bad("alpha_warm", "must be positive");
    }
    if cfg.boundaries == 0 {
        return bad("boundaries", "must be at least 1");
    }
    if cfg.beta.is_nan() || cfg.beta <= 0.0 || cfg.beta > 1.0 {
        return bad("beta", "must be in (0, 1]");
    }
    for (k, v) in [
        ("depth_start", cfg.depth_start),
        ("depth_warm", cfg.depth_warm),
        ("depth_floor_delta", cfg.depth_floor_delta),
        ("cross_scale", cfg.cross_scale),
        ("cross_min_delta", cfg.cross_min_delta),
        ("cross_max", cfg.cross_max),
        ("inward_voxel_delta", cfg.inward_voxel_delta),
    ] {
        if !pos(v) {
            return bad(k, "must be a positive length");
        }
    }
    if !(cfg.pole_tension >= 0.0 && cfg.pole_tension <= 1.0) {
        return bad("pole_tension", "must be in [0, 1]");
    }
    if !(1..=3).contains(&cfg.pole_axis_candidates) {
        return bad("pole_axis_candidates", "must be 1, 2 or 3");
    }
    if !(cfg.pole_axis_support >= 0.0 && cfg.pole_axis_support <= 1.0) {
        return bad("pole_axis_support", "must be in [0, 1]");
    }
    if !(cfg.redistribute_stretch == 0.0
        || (cfg.redistribute_stretch > 1.0 && cfg.redistribute_stretch.is_finite()))
    {
        return bad("redistribute_stretch", "must be 0 (off) or above 1");
    }
    if !(cfg.warm_back_smoothing >= 0.0 && cfg.warm_back_smoothing <= 1.0) {
        return bad("warm_back_smoothing", "must be in [0, 1]");
    }
    if !(cfg.inner_margin >= 0.0 && cfg.inner_margin < 0.5) {
        return bad("inner_margin", "must be in [0, 0.5)");
    }
    if !(cfg.depth_decay > 0.0 && cfg.depth_decay <= 1.0) {
        return bad("depth_decay", "must be in (0, 1]");
    }
    for (k, v) in [
        ("band_inner_delta", cfg.band_inner_delta),
        ("band_outer_delta", cfg.band_outer_delta),
        ("significance", cfg.significance),
        ("inward_step", cfg.inward_step),
        ("roughness", cfg.roughness),
        ("g_min", cfg.g_min),
        ("plateau_eps", cfg.plateau_eps),
        ("time_limit_ms", cfg.time_limit_ms),
        ("init_quantile", cfg.init_quantile),
        ("spatial_weight", cfg.spatial_weight),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            return bad(k, "must be a finite value >= 0");
        }
    }
    if !(cfg.delta_quantile > 0.0 && cfg.delta_quantile <= 1.0) {
        return bad("delta_quantile", "must be in (0, 1]");
    }
    if !pos(cfg.delta_scale) {
        return bad("delta_scale", "must be positive");
    }
    if cfg.init_quantile >= 0.5 {
        return bad("init_quantile", "must be below 0.5");
    }
    if !(cfg.init_margin >= 1.0 && cfg.init_margin.is_finite()) {
        return bad("init_margin", "must be >= 1");
    }
    if cfg.max_iterations == 0 {
        return bad("max_iterations", "must be at least 1");
    }
    Ok(())
}

/// Sample counts `(u_n, v_n)` for an `M × L` grid (paper Eq. 14).
pub fn sample_counts(cfg: &MembraneConfig, m: usize, l: usize) -> (usize, usize) {
    sample_counts_alpha(cfg, cfg.alpha, m, l)
}

/// [`sample_counts`] with another `α` (warm starts use `alpha_warm`).
pub fn sample_counts_alpha(cfg: &MembraneConfig, alpha: f64, m: usize, l: usize) -> (usize, usize) {
    let div = |q: usize| -> usize {
        let d = (alpha * (q as f64 - 1.0) + 1.0).round() as usize;
        d.max(cfg.div_min)
    };
    // u is periodic: q columns span q intervals, i.e. the same as q+1 clamped points.
    (div(m + 1), div(l))
}

/// Key of a factored fit system: grid, sample counts and roughness bits.
type FitKey = (usize, usize, usize, usize, u64);

/// Process-wide cache of factored fit systems. The normal matrix depends
/// only on the control grid, the sample layout and the roughness weight, so
/// it is factored once per process and reused by every reconstruction (the
/// node reconstructs the same grids every frame).
fn shared_fits() -> &'static Mutex<HashMap<FitKey, FitSystem>> {
    static CACHE: OnceLock<Mutex<HashMap<FitKey, FitSystem>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// Largest number of factored systems kept by [`shared_fits`].
const SHARED_FITS_MAX: usize = 64;

/// The [`shared_fits`] key of an `m × l` grid sampled with `alpha`.
fn fit_key(cfg: &MembraneConfig, alpha: f64, roughness: f64, m: usize, l: usize) -> FitKey {
    let (un, vn) = sample_counts_alpha(cfg, alpha, m, l);
    (m, l, un, vn, roughness.to_bits())
}

/// The factored fit system of an `m × l` grid sampled with `alpha`, from
/// [`shared_fits`] or factored now and stored there.
fn shared_fit(
    cfg: &MembraneConfig,
    alpha: f64,
    roughness: f64,
    m: usize,
    l: usize,
) -> Result<FitSystem, MembraneError> {
    let key = fit_key(cfg, alpha, roughness, m, l);
    let cached = shared_fits()
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .get(&key)
        .cloned();
    if let Some(s) = cached {
        return Ok(s);
    }
    let sys = FitSystem::new(Layout::samples(m, l, key.2, key.3)?, roughness)?;
    let mut shared = shared_fits()
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if shared.len() >= SHARED_FITS_MAX {
        shared.clear();
    }
    shared.insert(key, sys.clone());
    Ok(sys)
}

/// Factor, once per process, the fit system that a warm start from an
/// `m × l` surface will use (sampled with `alpha_warm`), so that the first
/// warm frame after a cold one does not pay for it. The frame pipeline calls
/// this at the end of a cold frame, whose budget is the longer one.
///
/// # Errors
/// [`MembraneError`] when the grid is invalid or the system is singular.
pub fn prefactor_warm(cfg: &MembraneConfig, m: usize, l: usize) -> Result<(), MembraneError> {
    let key = fit_key(cfg, cfg.alpha_warm, cfg.roughness, m, l);
    let cached = shared_fits()
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .contains_key(&key);
    if cached {
        return Ok(());
    }
    shared_fit(cfg, cfg.alpha_warm, cfg.roughness, m, l).map(|_| ())
}

/// Cache of factored fit systems, one per control grid (per reconstruction;
/// filled from [`shared_fits`]).
struct Fits {
    roughness: f64,
    /// `α` of the sample counts.
    alpha: f64,
    map: HashMap<(usize, usize), FitSystem>,
}

impl Fits {
    fn get(
        &mut self,
        cfg: &MembraneConfig,
        m: usize,
        l: usize,
    ) -> Result<&mut FitSystem, MembraneError> {
        if !self.map.contains_key(&(m, l)) {
            let sys = shared_fit(cfg, self.alpha, self.roughness, m, l)?;
            self.map.insert((m, l), sys);
        }
        self.map.get_mut(&(m, l)).ok_or(MembraneError::Config {
            key: "grid_start",
            problem: "fit cache lost a grid".into(),
        })
    }
}

/// Per-sample search result.
#[derive(Debug, Clone, Copy, Default)]
struct SampleOut {
    shift: f64,
    eta: f64,
    /// 0 = no move, 1 = boundary found, 2 = inward force.
    state: u8,
    /// The sample point and its unit normal, for the move `p + β·shift·n`.
    p: Vec3,
    n: Vec3,
}

/// Per-thread buffers: the search's own plus the centring band.
#[derive(Debug, Default)]
struct ThreadScratch {
    search: SearchScratch,
    /// (lateral distance², normal offset) of the band's points.
    band: Vec<(f64, f64)>,
}

/// Everything the per-sample search needs.
struct Stepper<'a> {
    cfg: &'a MembraneConfig,
    searcher: Searcher<'a>,
    delta: f64,
    outside: Option<&'a OutsideGrid>,
    /// The single view, if any: beyond the occupancy grid it decides what is outside.
    view: Option<&'a view::ViewBuffer>,
    cross_max: f64,
    /// Centroid of the points: a normal facing away from it is the
    /// unambiguous case of the inward force ([`Self::inward_sign`]).
    center: Vec3,
    /// How far [`Self::inward_sign`] looks along the normal line.
    reach: f64,
}

impl Stepper<'_> {
    #[allow(clippy::too_many_arguments)]
    fn sample(
        &self,
        surface: &ClosedSurface,
        layout: &Layout,
        i: usize,
        j: usize,
        depth: f64,
        allow_inward: bool,
        ts: &mut ThreadScratch,
    ) -> SampleOut {
        let scratch = &mut ts.search;
        let cfg = self.cfg;
        let sp = surface.eval_at(layout, i, j);
        let still = unsearched(surface, &sp, 0);
        let n = still.n;
        let cmin = cfg.cross_min_delta * self.delta;
        let cmax = self.cross_max.max(cmin);
        let w = (sp.su.norm() / layout.u_n() as f64 * cfg.cross_scale).clamp(cmin, cmax);
        let h = (sp.sv.norm() / layout.v_n() as f64 * cfg.cross_scale).clamp(cmin, cmax);
        let mut cub = Cuboid::new(sp.p, n, w, h, depth);
        if sp.su.norm_squared() > 0.0 {
            cub = cub.with_tangent(sp.su);
        }
        let rule = if cfg.inside_denser {
            BestRule::InnerDenser {
                min_inner: cfg.inner_margin * depth,
            }
        } else {
            BestRule::Any
        };
        let out = match self.searcher.search_best(&cub, rule, scratch) {
            Ok(o) => o,
            Err(_) => return still,
        };
        let d = if out.delta > 0.0 {
            out.delta
        } else {
            self.delta
        };
        let expected = w * h / (d * d);
        if let Some(best) = out.best {
            let (t, eta) = (best.offset, best.eta);
            let lo = t - cfg.band_inner_delta * d;
            let hi = t + cfg.band_outer_delta * d;
            // Robust centring on the layer: median normal offset of the
            // band's points nearest to the sample's axis (the nearer half,
            // at least 3), which limits the curvature bias of wide boxes.
            ts.band.clear();
            for (&off, &r2) in scratch.offsets().iter().zip(scratch.sq_distances()) {
                if off >= lo && off <= hi {
                    ts.band.push(((r2 - off * off).max(0.0), off));
                }
            }
            let count = ts.band.len();
            if count > 0 && count as f64 >= cfg.significance * expected {
                let keep = count.div_ceil(KEEP_DIV).max(3).min(count);
                if keep < count {
                    if count <= SMALL {
                        // What `select_nth_unstable_by` does at this length
                        // (a stable insertion sort, as 0 < keep − 1 < count − 1),
                        // with the comparison inlined: the same `keep` nearest
                        // points, ties included.
                        insertion_sort_by(&mut ts.band, |e| e.0);
                    } else {
                        ts.band
                            .select_nth_unstable_by(keep - 1, |a, b| a.0.total_cmp(&b.0));
                    }
                }
                let near = &mut ts.band[..keep];
                let mid = keep / 2;
                // The mid-th smallest offset (a value: any exact selection gives it).
                let m = if keep <= SMALL {
                    let mut buf = [0.0f64; SMALL];
                    for (b, e) in buf.iter_mut().zip(near.iter()) {
                        *b = e.1;
                    }
                    insertion_sort_by(&mut buf[..keep], |&x| x);
                    buf[mid]
                } else {
                    near.select_nth_unstable_by(mid, |a, b| a.1.total_cmp(&b.1));
                    near[mid].1
                };
                return SampleOut {
                    shift: m,
                    eta,
                    state: 1,
                    ..still
                };
            }
        }
        // Inward means toward the object: `inward_sign` decides the side
        // (against the normal, along it for a folded-over pocket, or none).
        if allow_inward && self.is_outside(&sp.p) {
            let sign = self.inward_sign(&sp.p, &n);
            if sign == 0.0 {
                return still;
            }
            return SampleOut {
                shift: -sign * cfg.inward_step * depth,
                eta: 0.0,
                state: 2,
                ..still
            };
        }
        still
    }

    /// Direction of the inward force at an outside sample, as the sign
    /// `s` of the move `−s·step·n` (see the module docs): 1 (against the
    /// normal) when the normal faces away from the centroid; when it faces
    /// the centroid, −1 (along it) if the normal line meets solid space in
    /// front before behind (a folded-over pocket), 1 if only behind (a sheet
    /// hanging in a cavity), else 0. With a single view only the first rule
    /// applies (see the module docs).
    fn inward_sign(&self, p: &Vec3, n: &Vec3) -> f64 {
        if n.dot(&(p - self.center)) > 0.0 {
            return 1.0;
        }
        let grid = match self.outside {
            Some(g) if self.view.is_none() => g,
            _ => return 0.0,
        };
        // The back ray runs only as far as a front hit, or the full reach
        // when there is none.
        match grid.distance_to_solid(p, n, self.reach) {
            // Solid in front, none nearer behind: a folded-over pocket.
            Some(f) if grid.distance_to_solid(p, &(-n), f).is_none() => -1.0,
            // Open in front, solid behind: a sheet hanging in a cavity.
            None if grid.distance_to_solid(p, &(-n), self.reach).is_some() => 1.0,
            _ => 0.0,
        }
    }

    /// Whether the inward force may act at `p` ([`view::outside_at`]).
    fn is_outside(&self, p: &Vec3) -> bool {
        self.outside
            .is_some_and(|grid| view::outside_at(grid, self.view, p))
    }

    /// Search every sample of `layout` (in parallel, coarse row chunks) into
    /// `outs`; with `skip = Some(p)` only those with `i + j + p` even, the
    /// others are only evaluated and marked [`SKIPPED`].
    #[allow(clippy::too_many_arguments)]
    fn search_all(
        &self,
        surface: &ClosedSurface,
        layout: &Layout,
        depth: f64,
        allow_inward: bool,
        skip: Option<usize>,
        outs: &mut Vec<SampleOut>,
        scratches: &mut [ThreadScratch],
    ) {
        let un = layout.u_n();
        let vn = layout.v_n();
        outs.resize(un * vn, SampleOut::default());
        let chunks = scratches.len().max(1);
        let rows_per = vn.div_ceil(chunks).max(1);
        outs.par_chunks_mut(rows_per * un)
            .zip(scratches.par_iter_mut())
            .enumerate()
            .for_each(|(c, (chunk, scratch))| {
                for (k, o) in chunk.iter_mut().enumerate() {
                    let j = c * rows_per + k / un;
                    let i = k % un;
                    *o = if skip.is_some_and(|p| (i + j + p) % 2 == 1) {
                        unsearched(surface, &surface.eval_at(layout, i, j), SKIPPED)
                    } else {
                        self.sample(surface, layout, i, j, depth, allow_inward, scratch)
                    };
                }
            });
    }
}

/// A sample at `sp` that does not move (yet): its point and unit normal,
/// with `state`.
fn unsearched(surface: &ClosedSurface, sp: &SurfacePoint, state: u8) -> SampleOut {
    SampleOut {
        p: sp.p,
        n: surface.normal(sp),
        state,
        ..SampleOut::default()
    }
}

/// [`SampleOut::state`] of a sample a sparse (checkerboard) iteration did
/// not search; [`fill_skipped`] gives it its neighbours' result.
const SKIPPED: u8 = 3;

/// Give every [`SKIPPED`] sample the result of its searched 4-neighbours
/// (periodic in u, clamped in v): the median shift of those that moved
/// (state 1 or 2; the sample stays put when none did) and the mean η of all
/// of them. `fills` is scratch.
fn fill_skipped(outs: &mut [SampleOut], un: usize, vn: usize, fills: &mut Vec<(usize, SampleOut)>) {
    fills.clear();
    for j in 0..vn {
        for i in 0..un {
            let k = j * un + i;
            if outs[k].state != SKIPPED {
                continue;
            }
            let left = if i == 0 { un - 1 } else { i - 1 };
            let right = if i + 1 == un { 0 } else { i + 1 };
            let mut moved = [0.0f64; 4];
            let (mut n_moved, mut n_eta, mut eta) = (0usize, 0usize, 0.0);
            let mut visit = |o: &SampleOut| {
                if o.state == SKIPPED {
                    return;
                }
                n_eta += 1;
                eta += o.eta;
                if o.state != 0 {
                    moved[n_moved] = o.shift;
                    n_moved += 1;
                }
            };
            visit(&outs[j * un + left]);
            visit(&outs[j * un + right]);
            if j > 0 {
                visit(&outs[k - un]);
            }
            if j + 1 < vn {
                visit(&outs[k + un]);
            }
            let mut out = SampleOut {
                state: 0,
                shift: 0.0,
                eta: if n_eta > 0 { eta / n_eta as f64 } else { 0.0 },
                ..outs[k]
            };
            if n_moved > 0 {
                out.shift = median_of_few(&mut moved[..n_moved]);
                out.state = 1;
            }
            fills.push((k, out));
        }
    }
    for &(k, o) in fills.iter() {
        outs[k] = o;
    }
}

/// Slices up to this length are ordered by [`insertion_sort_by`].
const SMALL: usize = 16;

/// Stable sort of a short slice by `key` under `f64::total_cmp` (inlined;
/// the generic sort and selection routines call their comparator out of
/// line, which dominates on the handful of values of a sample's band or
/// 3×3 neighbourhood).
#[inline]
fn insertion_sort_by<T: Copy>(v: &mut [T], key: impl Fn(&T) -> f64) {
    for i in 1..v.len() {
        let x = v[i];
        let kx = key(&x);
        let mut j = i;
        while j > 0 && kx.total_cmp(&key(&v[j - 1])).is_lt() {
            v[j] = v[j - 1];
            j -= 1;
        }
        v[j] = x;
    }
}

/// Median of a short non-empty slice (the middle pair's mean for an even
/// length); sorts it in place.
fn median_of_few(s: &mut [f64]) -> f64 {
    insertion_sort_by(s, |&x| x);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Membrane tension near the poles: each sample of the first and last
/// `rows` sample rows that has no data force (state 0) gets, as its shift,
/// `tension` times the normal component of the step to the mean of its four
/// grid neighbours (for the rows next to a pole, the sample across the pole
/// stands in for the missing neighbour). Writes into `shifts`.
fn pole_tension(
    outs: &[SampleOut],
    un: usize,
    vn: usize,
    tension: f64,
    rows: usize,
    shifts: &mut [f64],
) {
    for j in 0..vn {
        if j >= rows && j + rows < vn {
            continue;
        }
        for i in 0..un {
            let k = j * un + i;
            if outs[k].state == 0 {
                shifts[k] = tension * umbrella(outs, un, vn, i, j);
            }
        }
    }
}

/// Normal component of the step from sample `(i, j)` to the mean of its four
/// grid neighbours (periodic in u; for the rows next to a pole, the sample
/// across the pole stands in for the missing neighbour).
fn umbrella(outs: &[SampleOut], un: usize, vn: usize, i: usize, j: usize) -> f64 {
    let k = j * un + i;
    let left = if i == 0 { un - 1 } else { i - 1 };
    let right = if i + 1 == un { 0 } else { i + 1 };
    let across = (i + un / 2) % un;
    let up = if j == 0 { across } else { k - un };
    let down = if j + 1 == vn {
        (vn - 1) * un + across
    } else {
        k + un
    };
    let q = (outs[j * un + left].p + outs[j * un + right].p + outs[up].p + outs[down].p) / 4.0;
    (q - outs[k].p).dot(&outs[k].n)
}

/// Smoothing of a warm-started single view's occluded back: every sample
/// without a data force that lies behind the seen surface moves `weight`
/// times its [`umbrella`] step minus the mean step of all such samples, so
/// dents carried over from earlier frames fade while the back as a whole
/// neither shrinks nor grows. `sel` is a reused buffer.
fn smooth_occluded_back(
    outs: &[SampleOut],
    un: usize,
    vn: usize,
    vb: &view::ViewBuffer,
    weight: f64,
    sel: &mut Vec<(usize, f64)>,
    shifts: &mut [f64],
) {
    sel.clear();
    for j in 0..vn {
        for i in 0..un {
            let o = &outs[j * un + i];
            if o.state == 0 && vb.is_occluded(&o.p) {
                sel.push((j * un + i, umbrella(outs, un, vn, i, j)));
            }
        }
    }
    if sel.is_empty() {
        return;
    }
    let mean = sel.iter().map(|s| s.1).sum::<f64>() / sel.len() as f64;
    for &(k, step) in sel.iter() {
        shifts[k] = weight * (step - mean);
    }
}

/// Median of the shifts of moving samples in each 3×3 neighbourhood
/// (periodic in u, clamped in v); samples that do not move stay put.
fn median_filter(outs: &[SampleOut], un: usize, vn: usize, shifts: &mut Vec<f64>) {
    shifts.resize(outs.len(), 0.0);
    let mut buf = [0.0f64; 9];
    for j in 0..vn {
        for i in 0..un {
            let k = j * un + i;
            if outs[k].state == 0 {
                shifts[k] = 0.0;
                continue;
            }
            let mut n = 0;
            // Periodic in u (no modulo: this runs for every sample).
            let left = if i == 0 { un - 1 } else { i - 1 };
            let right = if i + 1 == un { 0 } else { i + 1 };
            for jj in j.saturating_sub(1)..(j + 2).min(vn) {
                let row = &outs[jj * un..(jj + 1) * un];
                for ii in [left, i, right] {
                    let o = &row[ii];
                    if o.state != 0 {
                        buf[n] = o.shift;
                        n += 1;
                    }
                }
            }
            shifts[k] = median_of_few(&mut buf[..n]);
        }
    }
}

/// Radius of the `density` attribute (neighbour count), in multiples of δ.
const DENSITY_ATTRIBUTE_RADIUS: f64 = 2.0;

/// The attribute channels and weights of the weighted separability (paper
/// Eq. 9) named by `membrane.attributes` / `membrane.spatial_weight`, taken
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
        point: cfg.spatial_weight,
        intensity: 0.0,
        luma: 0.0,
        density: 0.0,
        channels: Vec::new(),
    };
    for a in &cfg.attributes {
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
    let set =
        AttributeSet::from_cloud(cloud, &w, delta, DENSITY_ATTRIBUTE_RADIUS).map_err(|e| {
            MembraneError::Config {
                key: "attributes",
                problem: e.to_string(),
            }
        })?;
    if let Some(name) = set.missing().first() {
        return Err(MembraneError::MissingAttribute(name.clone()));
    }
    if set.total_weight() <= 0.0 {
        return Err(MembraneError::Config {
            key: "spatial_weight",
            problem: "the spatial weight and the attribute weights sum to 0".into(),
        });
    }
    Ok(set)
}

/// Keep at most `cap` of `points` (0 = all): the points whose index hash
/// falls below `cap/len`, a deterministic pseudo-random subsample that does
/// not alias with scan-line order. Exactly `cap` points are kept.
pub fn thin<T>(points: Vec<T>, cap: usize) -> Vec<T> {
    let n = points.len();
    if cap == 0 || n <= cap {
        return points;
    }
    // SplitMix64 of the index: a fixed pseudo-random key per index.
    let key = |i: usize| -> u64 {
        let mut z = (i as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let mut keys: Vec<u64> = (0..n).map(key).collect();
    let (_, kth, _) = keys.select_nth_unstable(cap - 1);
    let limit = *kth;
    let mut out = Vec::with_capacity(cap);
    for (i, p) in points.into_iter().enumerate() {
        if key(i) <= limit && out.len() < cap {
            out.push(p);
        }
    }
    out
}

/// The points kept by the outlier filter (indices into `finite`) and the
/// d_i (paper Eq. 5) of every kept point: every point's k-NN distance, and
/// `d_i ≤ outlier_factor · median` keeps it.
fn exact_density(
    finite: &[Vec3],
    cfg: &MembraneConfig,
) -> Result<(Vec<usize>, Vec<f64>), MembraneError> {
    let density = Density::new(finite, cfg.knn_k)?;
    let d_all = density.per_point();
    let limit = cfg.outlier_factor * density.median();
    let keep = kept_or_all(finite.len(), cfg.outlier_factor > 0.0, |k| {
        d_all[k] <= limit
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

/// `membrane.density_sample`: the k-NN distances of a spread subset of
/// the points only (δ is their median over the kept ones), and an outlier
/// filter by voxel counts — a point is kept when the 3×3×3 voxels of edge
/// ⅔·outlier_factor·δ around it hold more than `knn_k` points. Returns the
/// kept indices and the d_i of the kept subset points.
fn sampled_density(
    finite: &[Vec3],
    cfg: &MembraneConfig,
) -> Result<(Vec<usize>, Vec<f64>), MembraneError> {
    let k = cfg.knn_k.min(finite.len() - 1);
    if k == 0 {
        return Err(crate::density::DensityError::ZeroK.into());
    }
    let subset = thin((0..finite.len()).collect(), cfg.density_sample);
    let queries: Vec<Vec3> = subset.iter().map(|&i| finite[i]).collect();
    let d_sub = crate::density::knn_mean_distances(finite, &queries, k);
    let delta0 = median_of(&d_sub);
    if !(cfg.outlier_factor > 0.0 && delta0 > 0.0) {
        return Ok(((0..finite.len()).collect(), d_sub));
    }
    let index = SpatialIndex::with_cell_size(finite, cfg.outlier_factor * delta0 * 2.0 / 3.0)?;
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

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// What the evolution needs from the cloud, prepared once (and shared by
/// the pole-axis candidates of one reconstruction).
pub(crate) struct Prepared {
    counts: PointCounts,
    /// The used points (finite, thinned, outlier-filtered, plus a single
    /// view's completion).
    pub(crate) points: Vec<Vec3>,
    d_used: Vec<f64>,
    delta: f64,
    scale: f64,
    view: Option<view::ViewBuffer>,
    index: SpatialIndex,
    attributes: Option<AttributeSet>,
    outside: Option<OutsideGrid>,
    pub(crate) prepare_ms: f64,
}

/// What the preparation did with the input points (see [`Report`]).
#[derive(Debug, Clone, Copy)]
struct PointCounts {
    input: usize,
    non_finite: usize,
    duplicate: usize,
    thinned: usize,
    outliers: usize,
    completed: usize,
}

impl Prepared {
    /// Whether the cloud was taken as a single depth view.
    pub(crate) fn is_single_view(&self) -> bool {
        self.view.is_some()
    }
}

/// Prepare `cloud`: finite points, subsample, outlier filter, δ, single-view
/// detection and completion, spatial index, attributes, occupancy grid.
pub(crate) fn prepare(cloud: &PointCloud, cfg: &MembraneConfig) -> Result<Prepared, MembraneError> {
    let t_start = Instant::now();

    // ---- prepare: finite points, outlier filter, δ, index, occupancy ----
    let points_in = cloud.len();
    // Indices (into `cloud`) of the points kept by each step, so that the
    // attribute channels of the weighted mode follow the same selection.
    let finite_idx: Vec<usize> = cloud
        .points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.iter().all(|c| c.is_finite()))
        .map(|(i, _)| i)
        .collect();
    let points_non_finite = points_in - finite_idx.len();
    // Exact repeats of a point carry no new geometry; many of them would
    // collapse the k-NN distances and with them δ.
    let mut seen = HashSet::with_capacity(finite_idx.len());
    let finite_idx: Vec<usize> = finite_idx
        .into_iter()
        .filter(|&i| {
            let p = cloud.points[i];
            seen.insert([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        })
        .collect();
    let points_duplicate = points_in - points_non_finite - finite_idx.len();
    let finite_len = finite_idx.len();
    let finite_idx = thin(finite_idx, cfg.max_points);
    let points_thinned = finite_len - finite_idx.len();
    let finite: Vec<Vec3> = finite_idx.iter().map(|&i| cloud.points[i]).collect();
    if finite.is_empty() {
        return Err(CloudError::Empty.into());
    }
    if finite.len() < MIN_POINTS {
        return Err(CloudError::TooFewPoints {
            got: finite.len(),
            need: MIN_POINTS,
        }
        .into());
    }
    let (keep, d_kept) =
        if cfg.density_sample > 0 && finite.len() > cfg.density_sample && !cfg.local_delta {
            sampled_density(&finite, cfg)?
        } else {
            exact_density(&finite, cfg)?
        };
    let points: Vec<Vec3> = keep.iter().map(|&k| finite[k]).collect();
    let points_outliers = finite.len() - points.len();
    let bb = Aabb::from_points(&points);
    let e = bb.extent();
    let scale = e.max();
    if scale.is_nan() || scale <= 0.0 || e.min() < 1e-6 * scale {
        return Err(CloudError::Degenerate {
            extent: [e.x, e.y, e.z],
        }
        .into());
    }
    crate::cloud::check_spread(&points)?;
    // δ: the median d_i for a single view, where the spacing varies with
    // depth and incidence; delta_scale × the delta_quantile of d_i for a
    // whole object (default 1.3 × the lower quartile, which measures the
    // surface's own spacing even when up to half the points are outliers).
    let mut d_order = d_kept.clone();
    let mut quantile = |q: f64| {
        let at = ((d_order.len() as f64 * q) as usize).min(d_order.len().saturating_sub(1));
        d_order
            .select_nth_unstable_by(at, f64::total_cmp)
            .1
            .max(1e-9 * scale)
    };
    let median = quantile(0.5);
    // Single views: the viewpoint, its z-buffer, and the mirrored completion
    // of the unseen side (membrane/view.rs).
    let mut view = view::resolve(cfg.viewpoint, &points, median);
    let delta = if view.is_some() {
        median
    } else {
        (quantile(cfg.delta_quantile) * cfg.delta_scale).max(1e-9 * scale)
    };
    // Per-point d_i of the used points (the sampled density knows only δ).
    let d_used = if d_kept.len() == points.len() {
        d_kept
    } else {
        vec![delta; points.len()]
    };
    let (mut points, mut d_used) = (points, d_used);
    let mut points_completed = 0;
    if let (Some(vb), true) = (&mut view, cfg.view_completion) {
        let extra = vb.complete(&points);
        vb.set_back(extra.iter().map(|(q, _)| q));
        points_completed = extra.len();
        points.reserve(extra.len());
        d_used.reserve(extra.len());
        for (q, i) in extra {
            points.push(q);
            d_used.push(d_used[i]);
        }
    }
    let index = SpatialIndex::new(&points)?;
    // Weighted mode (paper Eq. 9): the attribute channels of the used points.
    let attributes = if cfg.attributes.is_empty() && cfg.spatial_weight == 1.0 {
        None
    } else {
        let used: Vec<usize> = keep.iter().map(|&k| finite_idx[k]).collect();
        Some(attribute_set(&cloud.select(&used), cfg, delta)?)
    };
    let outside = if cfg.inward_force {
        OutsideGrid::new(
            &points,
            cfg.inward_voxel_delta * delta,
            cfg.inward_min_points,
            1 << 22,
        )
        .map(|mut g| {
            // The occluded back of a single view is unknown, not empty —
            // except beyond the back of the completion.
            if let Some(vb) = &view {
                g.restrict(|c| vb.is_seen_free(c) || vb.is_beyond_back(c));
            }
            g
        })
    } else {
        None
    };
    Ok(Prepared {
        counts: PointCounts {
            input: points_in,
            non_finite: points_non_finite,
            duplicate: points_duplicate,
            thinned: points_thinned,
            outliers: points_outliers,
            completed: points_completed,
        },
        points,
        d_used,
        delta,
        scale,
        view,
        index,
        attributes,
        outside,
        prepare_ms: ms(t_start),
    })
}

/// Evolve the membrane on prepared points (see the module docs); `pole`
/// overrides the configured pole axis (0 = x, 1 = y, 2 = z) of a cold start.
pub(crate) fn evolve(
    prep: &Prepared,
    cfg: &MembraneConfig,
    budget: &Budget,
    warm: Option<&WarmStart>,
    pole: Option<usize>,
) -> Result<Reconstruction, MembraneError> {
    let t_start = Instant::now();
    let mut times = PhaseTimes {
        prepare_ms: prep.prepare_ms,
        ..PhaseTimes::default()
    };
    let Prepared {
        counts,
        ref points,
        ref d_used,
        delta,
        scale,
        ref view,
        ref index,
        ref attributes,
        ref outside,
        ..
    } = *prep;
    let searcher = if cfg.local_delta {
        Searcher::new(index, Delta::Local(d_used), cfg.boundaries)?
    } else {
        Searcher::new(index, Delta::Global(delta), cfg.boundaries)?
    };
    let searcher = match attributes {
        Some(a) => searcher.with_attributes(a)?,
        None => searcher,
    };
    let stepper = Stepper {
        cfg,
        searcher,
        delta,
        outside: outside.as_ref(),
        view: view.as_ref(),
        cross_max: cfg.cross_max * scale,
        center: points.iter().sum::<Vec3>() / points.len() as f64,
        reach: scale,
    };

    // ---- initial surface ----
    let t_init = Instant::now();
    let mut fits = Fits {
        roughness: cfg.roughness,
        alpha: if warm.is_some() {
            cfg.alpha_warm
        } else {
            cfg.alpha
        },
        map: HashMap::new(),
    };
    // The poles' coordinate axis: a warm start's from its own poles (no pass
    // over the points on the per-frame path), a cold start's resolved once
    // and given to the octagon explicitly.
    let (mut surface, pole_axis) = match warm {
        Some(w) => {
            let mut s = w.surface.clone();
            s.fix_orientation();
            let [a, b] = s.poles();
            let axis = (b - a).abs().imax();
            (s, axis)
        }
        None => {
            let pole_axis = pole
                .unwrap_or_else(|| init::pole_axis_of(points, cfg.pole_axis, cfg.init_quantile));
            let [m, l] = cfg.grid_start;
            let fit = fits.get(cfg, m, l)?;
            let surface = octagon(
                points,
                [PoleAxis::X, PoleAxis::Y, PoleAxis::Z][pole_axis],
                cfg.init_quantile,
                cfg.init_margin,
                fit,
            )?;
            (surface, pole_axis)
        }
    };
    times.init_ms = ms(t_init);

    // ---- evolution ----
    let floor = cfg.depth_floor_delta * delta;
    let mut depth = (if warm.is_some() {
        cfg.depth_warm
    } else {
        cfg.depth_start
    } * scale)
        .max(floor);
    let chunks = 4 * rayon::current_num_threads().max(1);
    let mut scratches: Vec<ThreadScratch> = (0..chunks).map(|_| ThreadScratch::default()).collect();
    let mut outs: Vec<SampleOut> = Vec::new();
    let mut fills: Vec<(usize, SampleOut)> = Vec::new();
    let mut shifts: Vec<f64> = Vec::new();
    let mut targets: Vec<Vec3> = Vec::new();
    let mut moving: Vec<f64> = Vec::new();
    let mut back: Vec<(usize, f64)> = Vec::new();
    let mut arc: Vec<f64> = Vec::new();
    let mut eta_hist: Vec<f64> = Vec::new();
    let mut grids: Vec<[usize; 2]> = Vec::new();
    let mut iteration_ms: Vec<f64> = Vec::new();
    let mut iter_on_grid = 0usize;
    // Per-sample η* of the last iteration and its grid: the output's
    // per-vertex separability when the grid did not change after it.
    let mut last_eta: Vec<f64> = Vec::new();
    let mut last_eta_grid = [0usize; 2];
    let mut plateau = 0usize;
    let mut last_iter = 0.0f64;
    let mut last_samples = 1usize;
    let max_grid = if cfg.adaptive {
        [
            cfg.grid_max[0].max(surface.m()),
            cfg.grid_max[1].max(surface.l()),
        ]
    } else {
        [surface.m(), surface.l()]
    };
    let stop = loop {
        let it = eta_hist.len();
        if it >= cfg.max_iterations {
            break StopReason::MaxIterations;
        }
        if budget.max_iterations.is_some_and(|n| it >= n) {
            break StopReason::IterationBudget;
        }
        if let Some(dl) = budget.deadline.filter(|_| it >= budget.min_iterations) {
            // Predict this iteration's time from the last one, scaled by the
            // sample count when the grid grew since.
            let (un, vn) = sample_counts_alpha(cfg, fits.alpha, surface.m(), surface.l());
            let predicted = last_iter * (un * vn) as f64 / last_samples.max(1) as f64;
            let now = Instant::now();
            if now >= dl || (dl - now).as_secs_f64() * 1e3 < predicted {
                break StopReason::Deadline;
            }
        }
        let t_it = Instant::now();
        let (m, l) = (surface.m(), surface.l());
        let fit = fits.get(cfg, m, l)?;
        let layout = fit.layout().clone();
        let t_search = Instant::now();
        // Sparse search: a checkerboard half of the samples, the half
        // alternating from iteration to iteration (and frame to frame); for
        // warm starts, and for whole objects on the final grid.
        let sparse = if warm.is_some() {
            cfg.sparse_warm_search
        } else {
            cfg.sparse_cold_search
                && view.is_none()
                && [m, l] == max_grid
                && points.len() >= layout.len()
        };
        let skip = sparse.then(|| (it + warm.map_or(0, |w| w.phase)) % 2);
        stepper.search_all(
            &surface,
            &layout,
            depth,
            true,
            skip,
            &mut outs,
            &mut scratches,
        );
        if skip.is_some() {
            fill_skipped(&mut outs, layout.u_n(), layout.v_n(), &mut fills);
        }
        let eta_g = outs.iter().map(|o| o.eta).sum::<f64>() / outs.len() as f64;
        last_eta.clear();
        last_eta.extend(outs.iter().map(|o| o.eta));
        last_eta_grid = [m, l];
        if cfg.median_filter {
            median_filter(&outs, layout.u_n(), layout.v_n(), &mut shifts);
        } else {
            shifts.clear();
            shifts.extend(outs.iter().map(|o| o.shift));
        }
        // Pole tension (whole objects only: the unseen back of a single view
        // is held where it is).
        if cfg.pole_tension > 0.0 && view.is_none() {
            pole_tension(
                &outs,
                layout.u_n(),
                layout.v_n(),
                cfg.pole_tension,
                cfg.pole_tension_rows,
                &mut shifts,
            );
        }
        if let (Some(vb), true) = (&view, warm.is_some() && cfg.warm_back_smoothing > 0.0) {
            smooth_occluded_back(
                &outs,
                layout.u_n(),
                layout.v_n(),
                vb,
                cfg.warm_back_smoothing,
                &mut back,
                &mut shifts,
            );
        }
        targets.clear();
        targets.extend(
            outs.iter()
                .zip(&shifts)
                .map(|(o, &s)| o.p + o.n * (cfg.beta * s)),
        );
        times.search_ms += ms(t_search);
        let t_fit = Instant::now();
        // The orientation sign is fixed once (init, warm start, regrid):
        // a refit moves the samples by small shifts and cannot turn the
        // surface inside out.
        fit.fit(&mut surface, &targets)?;
        // Sample redistribution along the rings (whole objects): equal u
        // steps become equal arc lengths when the rings have stretched.
        if cfg.redistribute_stretch > 0.0 && view.is_none() {
            let n = 2 * layout.u_n();
            if param_stretch(&surface, true, STRETCH_RINGS, n, &mut arc) > cfg.redistribute_stretch
            {
                surface = redistribute(&surface, fit, true, &arc)?;
                // The searched η* belong to the samples before the move.
                last_eta_grid = [0, 0];
            }
        }
        times.fit_ms += ms(t_fit);
        grids.push([m, l]);
        // A sparse iteration's η_g is compared with the last one that
        // searched the same half (two back): the halves differ a little.
        let back = if skip.is_some() { 2 } else { 1 };
        let prev = eta_hist
            .len()
            .checked_sub(back)
            .and_then(|k| eta_hist.get(k))
            .copied();
        eta_hist.push(eta_g);
        iter_on_grid += 1;
        // Shrink the search depth, but not below what the membrane still
        // travels: 2.5× the 90th percentile of the moving samples' shifts.
        moving.clear();
        moving.extend(
            outs.iter()
                .zip(&shifts)
                .filter(|(o, _)| o.state != 0)
                .map(|(_, s)| s.abs()),
        );
        let travel = if moving.is_empty() {
            0.0
        } else {
            let k = (moving.len() * 9 / 10).min(moving.len() - 1);
            let (_, q, _) = moving.select_nth_unstable_by(k, f64::total_cmp);
            2.5 * *q
        };
        depth = (depth * cfg.depth_decay).max(travel).min(depth).max(floor);
        let gain = prev.map_or(f64::INFINITY, |p| eta_g - p);
        let can_grow = m < max_grid[0] || l < max_grid[1];
        if can_grow {
            if iter_on_grid >= cfg.grow_after.max(1) && gain < cfg.g_min {
                let t_grow = Instant::now();
                let nm = (m + cfg.grid_step[0]).min(max_grid[0]);
                let nl = (l + cfg.grid_step[1]).min(max_grid[1]);
                let next = fits.get(cfg, nm, nl)?;
                surface = regrid(&surface, next)?;
                iter_on_grid = 0;
                plateau = 0;
                times.fit_ms += ms(t_grow);
            }
        } else {
            if gain.abs() < cfg.plateau_eps {
                plateau += 1;
            } else {
                plateau = 0;
            }
            if plateau >= cfg.plateau_patience.max(1) {
                iteration_ms.push(ms(t_it));
                break StopReason::Converged;
            }
        }
        last_iter = ms(t_it);
        last_samples = layout.len();
        iteration_ms.push(last_iter);
    };

    // ---- final scoring pass and mesh ----
    let t_mesh = Instant::now();
    let (m, l) = (surface.m(), surface.l());
    let layout = fits.get(cfg, m, l)?.layout().clone();
    // The last iteration's search already scored this layout (the returned
    // surface is its refit, a sub-δ move): reuse it; search afresh only when
    // the grid changed after it (or no iteration ran).
    let eta: Vec<f64> = if last_eta_grid == [m, l] && last_eta.len() == layout.len() {
        last_eta
    } else {
        stepper.search_all(
            &surface,
            &layout,
            floor,
            false,
            None,
            &mut outs,
            &mut scratches,
        );
        outs.iter().map(|o| o.eta).collect()
    };
    let eta_final = eta.iter().sum::<f64>() / eta.len().max(1) as f64;
    let mesh = extract_mesh(&surface, &layout, &eta);
    times.mesh_ms = ms(t_mesh);
    times.total_ms = prep.prepare_ms + ms(t_start);
    let report = Report {
        points_in: counts.input,
        points_non_finite: counts.non_finite,
        points_duplicate: counts.duplicate,
        points_thinned: counts.thinned,
        points_outliers: counts.outliers,
        points_used: points.len(),
        points_completed: counts.completed,
        viewpoint: view.as_ref().map(|v| {
            let e = v.eye();
            [e.x, e.y, e.z]
        }),
        delta,
        scale,
        grid: [m, l],
        samples: [layout.u_n(), layout.v_n()],
        iterations: eta_hist.len(),
        eta: eta_hist,
        grids,
        iteration_ms,
        eta_final,
        stop,
        warm: warm.is_some(),
        pole_axis,
        pole_axes_tried: 1,
        times,
    };
    Ok(Reconstruction {
        mesh,
        surface,
        report,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn searched(shift: f64, eta: f64, state: u8) -> SampleOut {
        SampleOut {
            shift,
            eta,
            state,
            ..SampleOut::default()
        }
    }

    #[test]
    fn occluded_back_smoothing_lifts_a_dent_without_moving_the_back_as_a_whole() {
        // The camera at the origin sees a sheet at z = 1; the back samples
        // lie behind it on a curved patch z = 1.2 + 3(x² + y²) (normals +z,
        // away from the camera: plain smoothing would move the patch as a
        // whole), one of them dented 0.1 toward the camera.
        let mut seen = Vec::new();
        for a in -20..=20 {
            for b in -20..=20 {
                seen.push(Vec3::new(a as f64 * 0.01, b as f64 * 0.01, 1.0));
            }
        }
        let vb = view::ViewBuffer::new(&seen, Vec3::zeros(), 0.01).unwrap();
        let (un, vn) = (8, 6);
        let mut outs = vec![SampleOut::default(); un * vn];
        for j in 0..vn {
            for i in 0..un {
                let (x, y) = (i as f64 * 0.02 - 0.07, j as f64 * 0.02 - 0.05);
                let dent = if (i, j) == (3, 2) { 0.1 } else { 0.0 };
                outs[j * un + i] = SampleOut {
                    p: Vec3::new(x, y, 1.2 + 3.0 * (x * x + y * y) - dent),
                    n: Vec3::z(),
                    ..SampleOut::default()
                };
            }
        }
        // A sample with a data force keeps its shift.
        outs[0].state = 1;
        outs[0].shift = 0.5;
        let mut shifts: Vec<f64> = outs.iter().map(|o| o.shift).collect();
        let mut sel = Vec::new();
        smooth_occluded_back(&outs, un, vn, &vb, 1.0, &mut sel, &mut shifts);
        assert_eq!(shifts[0], 0.5);
        let dent = shifts[2 * un + 3];
        assert!(dent > 0.08, "the dent moves back out: {dent}");
        assert!(shifts[2 * un + 2] < 0.0, "its neighbours move in a little");
        let raw: f64 = (1..un * vn)
            .map(|k| umbrella(&outs, un, vn, k % un, k / un))
            .sum();
        assert!(
            raw.abs() > 0.005,
            "plain umbrella steps would move the back: {raw}"
        );
        let sum: f64 = shifts[1..].iter().sum();
        assert!(sum.abs() < 1e-12, "the back as a whole stays: {sum}");
        // Samples in front of the seen sheet are not smoothed.
        let mut front = outs.clone();
        for o in &mut front {
            o.p.z = 0.5;
            o.state = 0;
        }
        front[2 * un + 3].p.z = 0.4;
        let mut shifts = vec![0.0; un * vn];
        smooth_occluded_back(&front, un, vn, &vb, 1.0, &mut sel, &mut shifts);
        assert!(shifts.iter().all(|&s| s == 0.0));
    }

    #[test]
    fn skipped_samples_take_the_median_shift_of_their_moving_neighbours() {
        // 4 × 3 samples (u periodic), checkerboard: (i + j) odd skipped.
        let (un, vn) = (4, 3);
        let mut outs = vec![SampleOut::default(); un * vn];
        for j in 0..vn {
            for i in 0..un {
                let k = j * un + i;
                outs[k] = if (i + j) % 2 == 1 {
                    SampleOut {
                        p: Vec3::new(i as f64, j as f64, 0.0),
                        state: SKIPPED,
                        ..SampleOut::default()
                    }
                } else {
                    // Shift = flat index; row 2 does not move.
                    searched(k as f64, 0.1 * k as f64, u8::from(j < 2))
                };
            }
        }
        let mut fills = Vec::new();
        fill_skipped(&mut outs, un, vn, &mut fills);
        // (1, 0): neighbours (0,0)=0, (2,0)=2 and (1,1)=5 moved -> median 2.
        assert_eq!(outs[1].state, 1);
        assert_eq!(outs[1].shift, 2.0);
        assert!((outs[1].eta - 0.1 * (0.0 + 2.0 + 5.0) / 3.0).abs() < 1e-12);
        assert_eq!(outs[1].p, Vec3::new(1.0, 0.0, 0.0));
        // (3, 0): periodic left (2,0)=2, right (0,0)=0, below (3,1)=7.
        assert_eq!(outs[3].shift, 2.0);
        // (0, 1): left wraps to (3,1)=7, right (1,1)=5, up (0,0)=0,
        // down (0,2) does not move -> median of 0, 5, 7.
        assert_eq!(outs[4].shift, 5.0);
        assert!((outs[4].eta - 0.1 * (7.0 + 5.0 + 0.0 + 8.0) / 4.0).abs() < 1e-12);
        // (1, 2): (0,2), (2,2) do not move, (1,1)=5 moved.
        assert_eq!(outs[9].shift, 5.0);
        // Nothing is left skipped.
        assert!(outs.iter().all(|o| o.state != SKIPPED));

        // A skipped sample whose neighbours all stayed put stays put.
        let mut still = vec![searched(1.0, 0.5, 0); 4];
        still[1] = SampleOut {
            state: SKIPPED,
            shift: 9.0,
            ..SampleOut::default()
        };
        fill_skipped(&mut still, 4, 1, &mut fills);
        assert_eq!((still[1].state, still[1].shift), (0, 0.0));
        assert!((still[1].eta - 0.5).abs() < 1e-12);
    }
}
