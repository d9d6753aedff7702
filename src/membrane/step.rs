//! One sample's step (paper §III-D steps 2–3): the oriented cuboid search
//! for the boundary of maximum separability η* (Eq. 7, or the weighted
//! Eq. 9; the external energy `E_sep = −η*` of Eqs. 11–12) and the shift
//! rule that turns its profile into a move along the sample's normal.
//!
//! The shift rule adds three mechanisms to the paper's "move to t*":
//! - **inner side denser** with an **inner margin** (`step.inside_denser`,
//!   its `inner_margin`): only boundaries whose inner region is the denser
//!   one and at least a fixed fraction of the cuboid's depth are accepted.
//!   Eq. 7 rewards a thin `r1` that a layer fills almost completely, so a
//!   layer just inside the cuboid's inner end could outscore the layer a
//!   sample sits on: as the decaying depth passed the thickness of a thin
//!   wall, samples on one face jumped to the other one and the membrane
//!   crumpled inside the wall (the bowl: F 0.74 on clean points against
//!   0.92 with noise, whose thicker layer the cuboid's end cuts);
//! - **dense-side significance** (`step.significance`): the band around `t*` must
//!   hold a fraction of the expected surface count `M_w·M_h/δ²`;
//! - **robust centring**: the shift is the median normal offset of the band's
//!   points nearest to the sample's axis, which limits the curvature bias
//!   of wide cuboids.
//!
//! A camera sees only surfaces that face it, so (opt-in,
//! `step.facing_away`) a sample of a fused cloud whose outward normal faces
//! away from every camera that saw the points (the fused model's views and
//! its latest one, [`view::Seen::fused_eyes`]) lies on a side no camera
//! saw: it does not search, and only the gated inward force below may move
//! it. Its search found the seen shell from behind and pulled the unseen
//! side onto it: the unseen side of a sphere turning before the camera kept
//! 0.02 of its volume, that of a YCB banana 0.01 (the measurement, and why
//! the rule is off by default, are in `launch/sepmem.json5`). A cold start
//! counts a sample as facing away only past a stricter angle
//! (`cold_max_cos`): the initial octagon's facets do not follow the object.
//!
//! A sample with no significant boundary that lies in empty space outside
//! the object ([`OutsideGrid`]) gets the gated **inward force**
//! (`step.inward`): `−inward.shift·depth` along its normal when the normal
//! faces away from the points' centroid. A sample whose normal faces the
//! centroid belongs either to a legitimately concave part (a bowl's inner
//! wall) or to a pocket that folded over while wrapping a limb, and the
//! normal line decides: when it meets solid space in front before behind
//! (the folded-over case), the sample moves along the normal; when it meets
//! solid space only behind (a sheet hanging in a cavity), against it;
//! otherwise it stays. Without the first case such pockets hang in the
//! empty space between the legs of an animal or beside the step of a CAD
//! part (Table 1: Spot F 0.75 → 0.88, Fandisk 0.78 → 0.85, hammer 0.69 →
//! 0.84); the second took the bowl from 0.90 to 0.98 (genus-0 F 0.929 →
//! 0.935; the procedural torus 0.926 → 0.906). A single view keeps the
//! withholding rule: there the fold rule raised the F-score of cold frames
//! but set warm-started frames off course (synth bottle sequence: warm
//! frames within 0.01 of cold 19/19 → 9/19).

use super::config::StepConfig;
use super::occupancy::OutsideGrid;
use super::view;
use crate::cloud::Vec3;
use crate::separability::search::{BestRule, Cuboid, SearchScratch, Searcher};
use crate::spline::{ClosedSurface, Layout, SurfacePoint};
use rayon::prelude::*;

/// The robust shift centres on the nearest 1/KEEP_DIV of the band points.
const KEEP_DIV: usize = 2;

/// What the search decided for one sample.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SampleState {
    /// No data force: the sample stays (unless a regulariser moves it).
    #[default]
    Still,
    /// A significant boundary was found: the shift centres on it.
    Boundary,
    /// The gated inward force moves it.
    Inward,
    /// A sparse (checkerboard) iteration did not search it;
    /// [`super::regularize::fill_skipped`] gives it its neighbours' result.
    Skipped,
}

impl SampleState {
    /// Whether the sample has a data force (a boundary or the inward force).
    pub fn moves(self) -> bool {
        matches!(self, Self::Boundary | Self::Inward)
    }
}

/// Per-sample search result.
#[derive(Debug, Clone, Copy, Default)]
pub struct SampleOut {
    /// Signed move along `n` (before β).
    pub shift: f64,
    /// Accepted maximum separability η* (0 without a boundary).
    pub eta: f64,
    /// What the search decided.
    pub state: SampleState,
    /// The sample point and its unit normal, for the move `p + β·shift·n`.
    pub p: Vec3,
    /// Unit outward normal at `p`.
    pub n: Vec3,
}

/// Per-thread buffers: the search's own plus the centring band.
#[derive(Debug, Default)]
pub struct ThreadScratch {
    search: SearchScratch,
    /// (lateral distance², normal offset) of the band's points.
    band: Vec<(f64, f64)>,
}

/// One search pass over a surface's samples.
#[derive(Clone, Copy)]
pub struct Pass<'a> {
    /// The surface searched.
    pub surface: &'a ClosedSurface,
    /// Its sample layout.
    pub layout: &'a Layout,
    /// Search depth M_d.
    pub depth: f64,
    /// Whether the gated inward force may act (not in the final scoring pass).
    pub allow_inward: bool,
    /// Sparse search: only samples with `i + j + p` even are searched.
    pub skip: Option<usize>,
}

/// Everything the per-sample search needs.
pub struct Stepper<'a> {
    /// The step's parameters.
    pub cfg: &'a StepConfig,
    /// The separability search over the used points.
    pub searcher: Searcher<'a>,
    /// Global point spacing δ.
    pub delta: f64,
    /// Occupancy grid of the inward force (`None` when it is off).
    pub outside: Option<&'a OutsideGrid>,
    /// What the cameras saw: beyond the occupancy grid it decides what is
    /// outside ([`view::outside_at`]).
    pub seen: view::Seen<'a>,
    /// Cross-section cap in input units.
    pub cross_max: f64,
    /// Centroid of the points: a normal facing away from it is the
    /// unambiguous case of the inward force ([`Self::inward_sign`]).
    pub center: Vec3,
    /// How far [`Self::inward_sign`] looks along the normal line.
    pub reach: f64,
    /// `step.facing_away.max_cos` (`None`: every sample searches).
    pub facing: Option<f64>,
    /// The cameras of a fused cloud's views (none otherwise).
    pub eyes: Vec<Vec3>,
}

impl Stepper<'_> {
    /// Search sample `(i, j)` of `pass` and apply the shift rule.
    fn sample(&self, pass: &Pass<'_>, i: usize, j: usize, ts: &mut ThreadScratch) -> SampleOut {
        let cfg = self.cfg;
        let (layout, depth) = (pass.layout, pass.depth);
        let sp = pass.surface.eval_at(layout, i, j);
        let still = unsearched(pass.surface, &sp, SampleState::Still);
        if self.faces_away(&sp.p, &still.n) {
            return self.inward(pass, &sp.p, still);
        }
        let (w, h) = cross_section(cfg, self.delta, self.cross_max, &sp, layout);
        let mut cub = Cuboid::new(sp.p, still.n, w, h, depth);
        if sp.su.norm_squared() > 0.0 {
            cub = cub.with_tangent(sp.su);
        }
        let rule = match &cfg.inside_denser {
            Some(d) => BestRule::InnerDenser {
                min_inner: d.inner_margin * depth,
            },
            None => BestRule::Any,
        };
        let Ok(out) = self.searcher.search_best(&cub, rule, &mut ts.search) else {
            return still;
        };
        let d = if out.delta > 0.0 {
            out.delta
        } else {
            self.delta
        };
        if let Some(best) = out.best {
            if let Some(shift) = self.centre(ts, best.offset, d, w * h / (d * d)) {
                return SampleOut {
                    shift,
                    eta: best.eta,
                    state: SampleState::Boundary,
                    ..still
                };
            }
        }
        self.inward(pass, &sp.p, still)
    }

    /// A sample without a boundary at `p`: the gated inward force where it
    /// lies outside the object, else `still`. Inward means toward the
    /// object: `inward_sign` decides the side (against the normal, along it
    /// for a folded-over pocket, or none).
    fn inward(&self, pass: &Pass<'_>, p: &Vec3, still: SampleOut) -> SampleOut {
        let inward = self.cfg.inward.as_ref().filter(|_| pass.allow_inward);
        let Some(w) = inward.filter(|_| self.is_outside(p)) else {
            return still;
        };
        let sign = self.inward_sign(p, &still.n);
        if sign == 0.0 {
            return still;
        }
        SampleOut {
            shift: -sign * w.shift * pass.depth,
            eta: 0.0,
            state: SampleState::Inward,
            ..still
        }
    }

    /// Whether the sample at `p` with outward normal `n` faces away from
    /// every camera that saw the points (`step.facing_away`): no camera saw
    /// a surface there, so their points must not pull it.
    fn faces_away(&self, p: &Vec3, n: &Vec3) -> bool {
        let Some(max_cos) = self.facing else {
            return false;
        };
        !self.eyes.is_empty()
            && self.eyes.iter().all(|e| {
                let to_eye = e - p;
                n.dot(&to_eye) <= max_cos * to_eye.norm()
            })
    }

    /// Robust centring on the layer at offset `t`: the median normal offset
    /// of the band's points (offsets in `[t − inner·d, t + outer·d]`)
    /// nearest to the sample's axis (the nearer half, at least 3). `None`
    /// when the band holds fewer than `significance × expected` points.
    fn centre(&self, ts: &mut ThreadScratch, t: f64, d: f64, expected: f64) -> Option<f64> {
        let cfg = self.cfg;
        let lo = t - cfg.band_inner_delta * d;
        let hi = t + cfg.band_outer_delta * d;
        ts.band.clear();
        let s = &ts.search;
        for (&off, &r2) in s.offsets().iter().zip(s.sq_distances()) {
            if off >= lo && off <= hi {
                ts.band.push(((r2 - off * off).max(0.0), off));
            }
        }
        let count = ts.band.len();
        let significant = count > 0 && count as f64 >= cfg.significance * expected;
        if !significant {
            return None;
        }
        let keep = count.div_ceil(KEEP_DIV).max(3).min(count);
        if keep < count {
            if count <= SMALL {
                // What `select_nth_unstable_by` does at this length (a
                // stable insertion sort, as 0 < keep − 1 < count − 1), with
                // the comparison inlined: the same `keep` nearest points,
                // ties included.
                insertion_sort_by(&mut ts.band, |e| e.0);
            } else {
                ts.band
                    .select_nth_unstable_by(keep - 1, |a, b| a.0.total_cmp(&b.0));
            }
        }
        let near = &mut ts.band[..keep];
        let mid = keep / 2;
        // The mid-th smallest offset (a value: any exact selection gives it).
        Some(if keep <= SMALL {
            let mut buf = [0.0f64; SMALL];
            for (b, e) in buf.iter_mut().zip(near.iter()) {
                *b = e.1;
            }
            insertion_sort_by(&mut buf[..keep], |&x| x);
            buf[mid]
        } else {
            near.select_nth_unstable_by(mid, |a, b| a.1.total_cmp(&b.1));
            near[mid].1
        })
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
            Some(g) if !matches!(self.seen, view::Seen::View(_)) => g,
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
            .is_some_and(|grid| view::outside_at(grid, self.seen, p))
    }

    /// Search every sample of `pass` (in parallel, coarse row chunks, one
    /// scratch per chunk) into `outs`; with `pass.skip = Some(p)` only those
    /// with `i + j + p` even, the others are only evaluated and marked
    /// [`SampleState::Skipped`].
    pub fn search_all(
        &self,
        pass: &Pass<'_>,
        outs: &mut Vec<SampleOut>,
        scratches: &mut [ThreadScratch],
    ) {
        let un = pass.layout.u_n();
        let vn = pass.layout.v_n();
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
                    *o = if pass.skip.is_some_and(|p| (i + j + p) % 2 == 1) {
                        let sp = pass.surface.eval_at(pass.layout, i, j);
                        unsearched(pass.surface, &sp, SampleState::Skipped)
                    } else {
                        self.sample(pass, i, j, scratch)
                    };
                }
            });
    }
}

/// The cross-section `M_w × M_h` of the cuboid at the sample `sp` of
/// `layout`: the sample spacing times `cross_scale`, at least
/// `cross_min_delta`·δ and at most `cross_max` (input units).
pub(crate) fn cross_section(
    cfg: &StepConfig,
    delta: f64,
    cross_max: f64,
    sp: &SurfacePoint,
    layout: &Layout,
) -> (f64, f64) {
    let cmin = cfg.cross_min_delta * delta;
    let cmax = cross_max.max(cmin);
    let w = (sp.su.norm() / layout.u_n() as f64 * cfg.cross_scale).clamp(cmin, cmax);
    let h = (sp.sv.norm() / layout.v_n() as f64 * cfg.cross_scale).clamp(cmin, cmax);
    (w, h)
}

/// A sample at `sp` that does not move (yet): its point and unit normal,
/// with `state`.
fn unsearched(surface: &ClosedSurface, sp: &SurfacePoint, state: SampleState) -> SampleOut {
    SampleOut {
        p: sp.p,
        n: surface.normal(sp),
        state,
        ..SampleOut::default()
    }
}

/// Slices up to this length are ordered by [`insertion_sort_by`].
pub(crate) const SMALL: usize = 16;

/// Stable sort of a short slice by `key` under `f64::total_cmp` (inlined;
/// the generic sort and selection routines call their comparator out of
/// line, which dominates on the handful of values of a sample's band or
/// 3×3 neighbourhood).
#[inline]
pub(crate) fn insertion_sort_by<T: Copy>(v: &mut [T], key: impl Fn(&T) -> f64) {
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
