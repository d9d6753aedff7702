//! Single-view clouds: what a depth camera could and could not see.
//!
//! On a robot the normal input is a *partial view*: one depth camera sees the
//! side of the object facing it. The paper's membrane (§III-D) assumes points
//! all around; on a partial view the occupancy inside/outside grid
//! ([`super::occupancy`]) leaks through the unseen back, the inward force
//! folds the back of the membrane onto the visible shell, and the closure
//! collapses. This module supplies what the sensor geometry knows:
//!
//! 1. **Viewpoint.** Given (`membrane.view.viewpoint = [x, y, z]`), or detected
//!    (`"auto"`): the origin of the cloud's frame (a sensor frame) is taken
//!    as the viewpoint when it lies at least [`MIN_VIEW_DISTANCE`] object
//!    sizes outside the cloud's bounding box (a cloud in a model or object
//!    frame has its origin in or next to the object) and the cloud is a
//!    single layer seen from it — in an angular z-buffer from the
//!    origin, at most [`MAX_TWO_LAYER_FRACTION`] of the occupied bins hold
//!    two depth layers (a gap over [`LAYER_GAP_DELTA`]·δ), where a scan from
//!    all around holds two layers (front and back) in nearly every bin.
//! 2. **Visibility.** The z-buffer keeps the nearest range per bin. A place
//!    is *seen free* when it is nearer than the surface seen in its direction
//!    (or nothing was seen there); it is *occluded* when it is behind it.
//!    The inward force then acts only in seen-free space: the unseen back is
//!    unknown space, not empty space.
//! 3. **Completion** (`membrane.view.completion = "mirror"`). The unseen side is
//!    completed by a symmetry prior: the visible points are mirrored through
//!    the plane perpendicular to the mean view direction at depth
//!    `z₀ + max(V, ½·min(Lᵤ, L_w))` (`z₀` the front, `V` the visible depth,
//!    `Lᵤ, L_w` the lateral extents). For a sphere cap or a cylinder seen from
//!    the side this is the rim plane (the true back), for a box seen corner-on
//!    the far corner, and for a box seen face-on a depth equal to its smaller
//!    width. Mirrored points that fall in seen-free space are discarded: the
//!    camera saw that space empty. These completion points are a shape prior,
//!    reported as `points_completed`; the separability's non-data counts are
//!    still never materialised.
//! 4. **Back bound** (`membrane.view.back`, off by default). Without a bound
//!    the occluded back is unknown space all the way to the initial surface,
//!    and the membrane's unseen side bulges into a lobe behind the object
//!    (a real mOSD bottle seen from its side: 2.7–3× its volume). With it,
//!    space deeper than `z₀ + extent · max(V, min(Lᵤ, L_w))` counts as
//!    outside, and the inward force pulls the back in: a sphere, cylinder or
//!    box is then bounded at (about) its true depth, and an object seen
//!    end-on (deeper than wide) is cut at its width — a prior of bounded
//!    depth, as the robot's-view issue asks ("the depth behind the seen
//!    surface is bounded by the object's seen extent"). Measured on 12
//!    sensor-true `sepmem synth` sequences (turn and orbit by 180°, Kinect
//!    noise, `sepmem replay` defaults) with `extent` 1.0: the largest volume
//!    ratio falls (bottle turn 2.55 → 1.56, bottle orbit 4.67 → 1.36, median
//!    1.67 → 1.45) but the last third's median F falls 0.266 → 0.242 and the
//!    seen-side median 0.738 → 0.679 (the warm start then tracks worse), so
//!    it stays off until tracking no longer drifts. A fused cloud (5.) whose
//!    carving no completed solid bounds gets the same bound ([`BackBound`]), seen from its
//!    latest view's camera, with `V` the depth of all its fused points along
//!    that view: the sides earlier views saw count (its measurement, a trade
//!    of fewer phantom lobes for lower F, is in `launch/sepmem.json5`).
//! 5. **Fused views** ([`FreeSpace`]). A cloud fused from many views (the
//!    tracker's per-object model) is no single view, but the caller knows
//!    where its views saw through; given that, the inward force acts only
//!    there, as with one view (`Membrane::reconstruct_seen`; the
//!    measurement is in [`crate::model`]).
//! 6. **Fused completion** (`membrane.view.fused_completion`). A fused
//!    cloud is no single view, so 3. does not apply, and in the first
//!    frames of a stream its membrane's unseen side collapsed onto the seen
//!    surface (a sphere turning before the camera kept 0.31 of its volume).
//!    While the model keeps few views, the fused points on its latest
//!    view's surface are completed as in 3., and mirror points that any
//!    view saw empty, or that lie near a fused point, are dropped (the
//!    measurement is in `launch/sepmem.json5`).

use super::occupancy::OutsideGrid;
use crate::cloud::{Aabb, Vec3};
use crate::gnomonic::{RangeImage, ViewFrame};
use serde::{Deserialize, Serialize};

/// Least distance of an auto-detected viewpoint from the cloud's bounding
/// box, in multiples of its longest edge. Depth cameras stand well away
/// from what they segment (a tabletop object at 0.5–1.5 m is 2–20 sizes
/// away); the PCL bunny scan, stored in the mesh's frame, has the origin
/// 0.2 sizes below the bunny's feet, and taking it as the camera cost F
/// 0.21 -> 0.12.
pub const MIN_VIEW_DISTANCE: f64 = 0.5;
/// Largest fraction of two-layer bins for a cloud to count as one view.
pub const MAX_TWO_LAYER_FRACTION: f64 = 0.2;
/// Depth gap (in δ) that separates two layers within one z-buffer bin.
pub const LAYER_GAP_DELTA: f64 = 4.0;
/// Angular z-buffer bin edge, in δ at the median range.
const BIN_DELTA: f64 = 2.0;
/// Visibility margin, in δ: within it a place counts as on the seen surface.
const MARGIN_DELTA: f64 = 2.0;
/// Largest z-buffer side (bins).
const MAX_SIDE: usize = 1024;

/// Where the sensor was (`membrane.view.viewpoint`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Viewpoint {
    /// `"auto"` or `"none"`.
    Mode(ViewMode),
    /// A known sensor position in the cloud's frame.
    Point([f64; 3]),
}

/// Automatic or no viewpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ViewMode {
    /// The frame origin, when the cloud is a single view from it.
    Auto,
    /// Treat every cloud as seen from all around.
    None,
}

/// An angular z-buffer of a cloud seen from a viewpoint (gnomonic projection
/// on the plane perpendicular to the mean view direction).
#[derive(Debug, Clone)]
pub struct ViewBuffer {
    /// Nearest range per bin (`INFINITY` where nothing was seen).
    image: RangeImage<f64>,
    margin: f64,
    /// Depth (along the view direction) beyond which nothing of the object
    /// lies: the back of the completion (`INFINITY` without one).
    back: f64,
}

impl ViewBuffer {
    /// Build the z-buffer of `points` seen from `eye`. `None` when a point is
    /// not in front of the eye (within 80° of the mean view direction) or the
    /// geometry is degenerate.
    pub fn new(points: &[Vec3], eye: Vec3, delta: f64) -> Option<Self> {
        if points.is_empty() || !(delta > 0.0 && delta.is_finite()) {
            return None;
        }
        let centroid = points.iter().sum::<Vec3>() / points.len() as f64;
        let frame = ViewFrame::looking_at(eye, centroid)?;
        let (lo, hi) = frame.window(points, 10f64.to_radians().sin())?;
        let ranges: Vec<f64> = points.iter().map(|p| frame.range(p)).collect();
        let mut sorted = ranges.clone();
        let mid = sorted.len() / 2;
        let (_, median_r, _) = sorted.select_nth_unstable_by(mid, f64::total_cmp);
        let mut bin = BIN_DELTA * delta / median_r.max(f64::MIN_POSITIVE);
        loop {
            let dims = RangeImage::<f64>::dims_for(lo, hi, bin);
            if dims[0] <= MAX_SIDE && dims[1] <= MAX_SIDE {
                break;
            }
            bin *= 1.5;
        }
        let mut image = RangeImage::new(frame, lo, hi, bin);
        for (p, &r) in points.iter().zip(&ranges) {
            if let Some(c) = image.cell(p) {
                image.record(c, r);
            }
        }
        Some(Self {
            image,
            margin: MARGIN_DELTA * delta,
            back: f64::INFINITY,
        })
    }

    /// The viewpoint.
    pub fn eye(&self) -> Vec3 {
        self.image.frame().eye()
    }

    fn frame(&self) -> &ViewFrame {
        self.image.frame()
    }

    /// Nearest seen range in the direction of `p` over its bin and the 8
    /// around it (`INFINITY` when nothing was seen there).
    fn nearest_seen(&self, p: &Vec3) -> f64 {
        self.image.nearest_around(p).unwrap_or(f64::INFINITY)
    }

    /// True when the camera saw through `p`: it is nearer than the surface
    /// seen in its direction (by more than the margin), or nothing was seen
    /// in its direction.
    pub fn is_seen_free(&self, p: &Vec3) -> bool {
        self.frame().range(p) + self.margin < self.nearest_seen(p)
    }

    /// Set the back of the object to the deepest of `points` (the
    /// completion), unless an earlier back is nearer: space beyond it
    /// counts as outside.
    pub fn set_back<'a>(&mut self, points: impl Iterator<Item = &'a Vec3>) {
        let deepest = points
            .map(|q| self.frame().depth(q))
            .fold(f64::NEG_INFINITY, f64::max);
        if deepest.is_finite() {
            self.back = self.back.min(deepest + self.margin);
        }
    }

    /// True when `p` lies deeper than the back of the completion.
    pub fn is_beyond_back(&self, p: &Vec3) -> bool {
        self.frame().depth(p) > self.back
    }

    /// True when `p` lies behind the seen surface (by more than the margin).
    pub fn is_occluded(&self, p: &Vec3) -> bool {
        let near = self.nearest_seen(p);
        near.is_finite() && self.frame().range(p) > near + self.margin
    }

    /// Fraction of occupied bins (with at least two points) holding two
    /// depth layers separated by more than `gap`.
    ///
    /// The ranges are positive (a [`ViewBuffer`] is only made of points in
    /// front of the eye), so their bit patterns sort as their values: the
    /// integer sort is half the cost of comparing with `total_cmp`.
    fn two_layer_fraction(&self, points: &[Vec3], gap: f64) -> f64 {
        let mut keyed: Vec<(usize, u64)> = points
            .iter()
            .filter_map(|p| {
                let c = self.image.cell(p)?;
                let r = self.frame().range(p);
                (r > 0.0).then_some((c, r.to_bits()))
            })
            .collect();
        keyed.sort_unstable();
        let range = |k: usize| f64::from_bits(keyed[k].1);
        let (mut bins, mut layered) = (0usize, 0usize);
        let mut i = 0;
        while i < keyed.len() {
            let mut j = i + 1;
            let mut split = false;
            while j < keyed.len() && keyed[j].0 == keyed[i].0 {
                split |= range(j) - range(j - 1) > gap;
                j += 1;
            }
            if j - i >= 2 {
                bins += 1;
                layered += usize::from(split);
            }
            i = j;
        }
        if bins == 0 {
            1.0
        } else {
            layered as f64 / bins as f64
        }
    }

    /// The seen extent of `points` in this view ([`seen_extent`]).
    fn extent(&self, points: &[Vec3]) -> Option<SeenExtent> {
        seen_extent(self.frame(), points)
    }

    /// The mirrored completion of `points` (see the module docs): the mirror
    /// images that fall in occluded space, each with the index of its source.
    pub fn complete(&self, points: &[Vec3]) -> Vec<(Vec3, usize)> {
        let Some(e) = self.extent(points) else {
            return Vec::new();
        };
        let f = self.frame();
        let plane = e.front + e.visible.max(0.5 * e.lateral);
        points
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let z = f.depth(p);
                if z >= plane {
                    return None;
                }
                let q = p + f.dir() * (2.0 * (plane - z));
                self.is_occluded(&q).then_some((q, i))
            })
            .collect()
    }

    /// Bound the back (module docs, 4.): nothing of the object lies deeper
    /// than `z₀ + extent · max(V, min(Lᵤ, L_w))` behind the seen front of
    /// `points` (nor deeper than an earlier back).
    pub fn bound_back(&mut self, points: &[Vec3], extent: f64) {
        if let Some(e) = self.extent(points) {
            self.back = self.back.min(e.back(extent) + self.margin);
        }
    }
}

/// The back bound of a fused cloud (module docs, 4.), seen from its
/// latest view's camera: nothing of the object lies deeper than
/// `z₀ + extent · max(V, min(Lᵤ, L_w))` of all its points along that
/// view's direction (plus the visibility margin), where V now spans every
/// side the views have seen. Beyond it the inward force acts as in space
/// seen empty ([`super::solid::Solid::Back`]).
#[derive(Debug, Clone, Copy)]
pub struct BackBound {
    frame: ViewFrame,
    back: f64,
}

impl BackBound {
    /// The bound of `points` seen from `eye` with spacing `delta`; `None`
    /// for fewer than 8 points or a degenerate geometry.
    pub fn of(points: &[Vec3], eye: Vec3, delta: f64, extent: f64) -> Option<Self> {
        if points.is_empty() || !(delta > 0.0 && delta.is_finite()) {
            return None;
        }
        let centroid = points.iter().sum::<Vec3>() / points.len() as f64;
        let frame = ViewFrame::looking_at(eye, centroid)?;
        let back = seen_extent(&frame, points)?.back(extent) + MARGIN_DELTA * delta;
        back.is_finite().then_some(Self { frame, back })
    }

    /// True when `p` lies deeper than the bound.
    pub fn is_beyond(&self, p: &Vec3) -> bool {
        self.frame.depth(p) > self.back
    }
}

/// The seen extent of `points` in `frame` (robust: the 0.2 % and 99.8 %
/// quantiles, so a few stray points do not define it, where a wide trim
/// would shrink it); `None` for fewer than 8 points.
fn seen_extent(frame: &ViewFrame, points: &[Vec3]) -> Option<SeenExtent> {
    let n = points.len();
    if n < 8 {
        return None;
    }
    let quantiles = |mut v: Vec<f64>| -> (f64, f64) {
        let lo_i = (0.002 * (n - 1) as f64) as usize;
        let hi_i = (0.998 * (n - 1) as f64).ceil() as usize;
        let (_, lo, _) = v.select_nth_unstable_by(lo_i, f64::total_cmp);
        let lo = *lo;
        let (_, hi, _) = v.select_nth_unstable_by(hi_i, f64::total_cmp);
        (lo, *hi)
    };
    let (front, deepest) = quantiles(points.iter().map(|p| frame.depth(p)).collect());
    let (u0, u1) = quantiles(points.iter().map(|p| frame.lateral(p)[0]).collect());
    let (w0, w1) = quantiles(points.iter().map(|p| frame.lateral(p)[1]).collect());
    Some(SeenExtent {
        front,
        visible: deepest - front,
        lateral: (u1 - u0).min(w1 - w0),
    })
}

/// How far a view's points reach, in the view's frame.
struct SeenExtent {
    /// Depth of the front (z₀).
    front: f64,
    /// Visible depth V: from the front to the deepest seen point.
    visible: f64,
    /// The smaller lateral extent, min(Lᵤ, L_w).
    lateral: f64,
}

impl SeenExtent {
    /// The back bound `z₀ + extent · max(V, min(Lᵤ, L_w))` (module docs, 4.).
    fn back(&self, extent: f64) -> f64 {
        self.front + extent * self.visible.max(self.lateral)
    }
}

/// Whether `p` is outside the object, for the inward force: the occupancy
/// grid's label where it has one (already restricted to seen-free space for
/// a single view). Beyond the grid nothing was measured: with a single view
/// that space is outside only where the camera saw it empty or beyond the
/// completion's back, never in the occluded back. (The membrane's initial
/// surface and its poles lie beyond the grid; pulling the unseen back in
/// there folded it into loops.) Without a view, everything beyond the grid
/// is outside.
///
/// A cloud that is no single view but comes with the free space of the
/// views it was fused from ([`FreeSpace`]) is treated like a single view:
/// beyond the grid only their seen-free space is outside. Inside the grid
/// the label stands even where a view saw empty but the flood fill found
/// the cell enclosed: taking that space for outside too carved the phantom
/// of a turning bent tube (its samples in seen-free space fell from 10-16 %
/// to under 1 % within a frame's four iterations), but over the 45 sequences
/// of `benches/robot_view_eval.sh` the mean last-third F fell 0.833 ->
/// 0.823 and the median share of visible points more than 3σ outside rose
/// 0.2 % -> 0.6 %: under the tracked pose's error, free space next to the
/// surface cuts into the object.
pub fn outside_at(grid: &OutsideGrid, seen: Seen<'_>, p: &Vec3) -> bool {
    grid.label(p).unwrap_or_else(|| seen.may_be_outside(p))
}

/// What the cameras saw of the space around a cloud's points.
#[derive(Clone, Copy)]
pub enum Seen<'a> {
    /// Nothing: the points lie all around the object.
    AllAround,
    /// The cloud is one depth view.
    View(&'a ViewBuffer),
    /// A fused cloud, with the free space of the views it was made from,
    /// and the solid it was completed to.
    Views(&'a dyn FreeSpace, Option<&'a super::solid::Solid>),
}

impl<'a> Seen<'a> {
    /// A single view when there is one, else the fused views' free space
    /// when given, else nothing.
    pub fn of(
        view: Option<&'a ViewBuffer>,
        free: Option<&'a dyn FreeSpace>,
        solid: Option<&'a super::solid::Solid>,
    ) -> Self {
        match (view, free) {
            (Some(vb), _) => Self::View(vb),
            (None, Some(f)) => Self::Views(f, solid),
            (None, None) => Self::AllAround,
        }
    }

    /// The cameras of a fused cloud's views (none for a single view or
    /// points from all around: see `step.facing_away`).
    pub fn fused_eyes(&self) -> Vec<Vec3> {
        match self {
            Self::AllAround | Self::View(_) => Vec::new(),
            Self::Views(f, _) => f.eyes(),
        }
    }

    /// Whether the inward force may take `p` for outside: anywhere without
    /// a view; with one, only where it was seen empty or lies beyond the
    /// completion's back; with fused views, only where one saw it empty or
    /// beyond the solid they were completed to.
    pub fn may_be_outside(&self, p: &Vec3) -> bool {
        match self {
            Self::AllAround => true,
            Self::View(vb) => vb.is_seen_free(p) || vb.is_beyond_back(p),
            Self::Views(f, solid) => f.is_seen_free(p) || solid.is_some_and(|s| s.is_beyond(p)),
        }
    }
}

/// Free space seen by the views a fused cloud was made from (the tracker's
/// per-object model, [`crate::model`]), in the cloud's frame. A fused cloud
/// holds points from many sides and is no single view, so the membrane
/// would otherwise take every place without points, the sides no view has
/// seen yet included, for outside, and its inward force dented and
/// crumpled the membrane there. With it, the inward force acts only where
/// some view saw through (module docs of [`crate::model`] for the measurement).
pub trait FreeSpace: Sync {
    /// True when some view saw `p` empty.
    fn is_seen_free(&self, p: &Vec3) -> bool;

    /// [`Self::is_seen_free`], but a point beside a view's silhouette only
    /// when it lies more than `tol` beyond it; [`Self::is_seen_free`]
    /// where the views say no more.
    fn is_seen_free_beyond(&self, p: &Vec3, _tol: f64) -> bool {
        self.is_seen_free(p)
    }

    /// The latest view's camera position, in the cloud's frame (`None`
    /// without a view).
    fn latest_eye(&self) -> Option<Vec3>;

    /// True when `p` lies on the surface the latest view saw.
    fn on_latest_surface(&self, p: &Vec3) -> bool;

    /// How many distinct views the model keeps.
    fn views_kept(&self) -> usize;

    /// The cameras of the kept views and of the latest one, in the cloud's
    /// frame.
    fn eyes(&self) -> Vec<Vec3>;
}

/// Views that saw empty where the predicate holds, and nothing else (no
/// eye, no latest surface): the completions' tests.
#[cfg(test)]
pub(crate) struct SeenWhere<F>(pub F);

/// No view saw anything empty.
#[cfg(test)]
pub(crate) const UNSEEN: SeenWhere<fn(&Vec3) -> bool> = SeenWhere(|_| false);

#[cfg(test)]
impl<F: Fn(&Vec3) -> bool + Sync> FreeSpace for SeenWhere<F> {
    fn is_seen_free(&self, p: &Vec3) -> bool {
        (self.0)(p)
    }
    fn latest_eye(&self) -> Option<Vec3> {
        None
    }
    fn on_latest_surface(&self, _: &Vec3) -> bool {
        false
    }
    fn views_kept(&self) -> usize {
        1
    }
    fn eyes(&self) -> Vec<Vec3> {
        Vec::new()
    }
}

/// The view of `points` for `viewpoint` (see the module docs): `None` for
/// `"none"`, and for `"auto"` unless the origin sees the cloud as one layer.
pub fn resolve(viewpoint: Viewpoint, points: &[Vec3], delta: f64) -> Option<ViewBuffer> {
    match viewpoint {
        Viewpoint::Mode(ViewMode::None) => None,
        Viewpoint::Point(p) => ViewBuffer::new(points, Vec3::new(p[0], p[1], p[2]), delta),
        Viewpoint::Mode(ViewMode::Auto) => {
            let eye = Vec3::zeros();
            let bb = Aabb::from_points(points);
            let gap = bb.distance_to(&eye);
            let size = bb.longest_edge();
            if !(gap > MIN_VIEW_DISTANCE * size && gap > delta) {
                return None;
            }
            let vb = ViewBuffer::new(points, eye, delta)?;
            (vb.two_layer_fraction(points, LAYER_GAP_DELTA * delta) <= MAX_TWO_LAYER_FRACTION)
                .then_some(vb)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fibonacci sphere of `n` points, radius `r`, centre `c`.
    fn sphere(n: usize, r: f64, c: Vec3) -> Vec<Vec3> {
        crate::shapes::fibonacci_sphere(n)
            .into_iter()
            .map(|u| c + u * r)
            .collect()
    }

    #[test]
    fn auto_detects_a_single_view_and_rejects_a_full_scan() {
        let c = Vec3::new(0.1, -0.05, 1.0);
        let full = sphere(6000, 0.1, c);
        // δ ≈ spacing of 6000 points on a 0.1 sphere.
        let delta = (4.0 * std::f64::consts::PI * 0.01 / 6000.0).sqrt();
        assert!(resolve(Viewpoint::Mode(ViewMode::Auto), &full, delta).is_none());
        // The cap facing the origin.
        let cap: Vec<Vec3> = full
            .iter()
            .copied()
            .filter(|p| (p - c).dot(&(-c).normalize()) > 0.05 * 0.1)
            .collect();
        let vb = resolve(Viewpoint::Mode(ViewMode::Auto), &cap, delta).expect("single view");
        assert_eq!(vb.eye(), Vec3::zeros());
        // A cloud around the origin has no outside viewpoint.
        let around = sphere(2000, 1.0, Vec3::zeros());
        assert!(resolve(Viewpoint::Mode(ViewMode::Auto), &around, 0.05).is_none());
        // Nor has a cap whose frame's origin lies just off it (a model
        // frame): 0.3 sizes away.
        let near = Vec3::new(0.0, 0.0, 0.2 * 0.3 + 0.1);
        let cap_near: Vec<Vec3> = sphere(6000, 0.1, near)
            .into_iter()
            .filter(|p| (p - near).dot(&(-near).normalize()) > 0.05 * 0.1)
            .collect();
        assert!(resolve(Viewpoint::Mode(ViewMode::Auto), &cap_near, delta).is_none());
        assert!(resolve(Viewpoint::Mode(ViewMode::None), &cap, delta).is_none());
        assert!(resolve(Viewpoint::Point([0.0, 0.0, 0.0]), &cap, delta).is_some());
    }

    /// The front cap (z < 1) of a sphere of radius 0.1 at (0, 0, 1), seen
    /// from the origin: (centre, radius, δ, cap, view).
    fn sphere_cap_view() -> (Vec3, f64, f64, Vec<Vec3>, ViewBuffer) {
        let c = Vec3::new(0.0, 0.0, 1.0);
        let r = 0.1;
        let full = sphere(8000, r, c);
        let delta = (4.0 * std::f64::consts::PI * r * r / 8000.0).sqrt();
        let cap: Vec<Vec3> = full.iter().copied().filter(|p| p.z < c.z).collect();
        let vb = ViewBuffer::new(&cap, Vec3::zeros(), delta).unwrap();
        (c, r, delta, cap, vb)
    }

    #[test]
    fn beyond_the_grid_only_seen_free_space_is_outside() {
        let (_, _, delta, cap, vb) = sphere_cap_view();
        let mut grid = OutsideGrid::new(&cap, 2.0 * delta, 20, 1 << 22).unwrap();
        grid.restrict(|q| vb.is_seen_free(q));
        // Behind the cap, beyond the grid (the cap ends at z = 1): occluded,
        // so not outside with the view, outside without it.
        let back = Vec3::new(0.0, 0.0, 1.15);
        assert_eq!(grid.label(&back), None);
        assert!(!outside_at(&grid, Seen::View(&vb), &back));
        assert!(outside_at(&grid, Seen::AllAround, &back));
        // In front of the cap, beyond the grid: seen free, outside either way.
        let front = Vec3::new(0.0, 0.0, 0.7);
        assert_eq!(grid.label(&front), None);
        assert!(outside_at(&grid, Seen::View(&vb), &front));
        // On the grid the (restricted) label decides.
        assert!(!outside_at(
            &grid,
            Seen::View(&vb),
            &Vec3::new(0.0, 0.0, 0.95)
        ));
        // A fused cloud's views (no single view): their free space decides,
        // here the single view's own, behind which nothing was seen free.
        struct Views<'a>(&'a ViewBuffer);
        impl FreeSpace for Views<'_> {
            fn is_seen_free(&self, p: &Vec3) -> bool {
                self.0.is_seen_free(p)
            }

            fn latest_eye(&self) -> Option<Vec3> {
                Some(self.0.eye())
            }

            fn on_latest_surface(&self, p: &Vec3) -> bool {
                !self.0.is_seen_free(p) && !self.0.is_occluded(p)
            }

            fn views_kept(&self) -> usize {
                1
            }

            fn eyes(&self) -> Vec<Vec3> {
                vec![self.0.eye()]
            }
        }
        let views = Views(&vb);
        assert!(!outside_at(&grid, Seen::Views(&views, None), &back));
        assert!(outside_at(&grid, Seen::Views(&views, None), &front));
    }

    #[test]
    fn visibility_and_mirror_completion_of_a_sphere_cap() {
        let (c, r, _, cap, vb) = sphere_cap_view();
        // In front of the cap and beside the sphere: seen free; the centre and
        // the back: occluded.
        assert!(vb.is_seen_free(&Vec3::new(0.0, 0.0, 0.85)));
        assert!(vb.is_seen_free(&Vec3::new(0.2, 0.0, 1.0)));
        assert!(vb.is_occluded(&c));
        assert!(vb.is_occluded(&Vec3::new(0.0, 0.0, 1.1)));
        assert!(!vb.is_seen_free(&c));
        // The mirror completes the back hemisphere: every completion point lies
        // on the sphere, and they cover the back.
        let done = vb.complete(&cap);
        assert!(
            done.len() > cap.len() * 8 / 10,
            "{} of {}",
            done.len(),
            cap.len()
        );
        for (q, i) in &done {
            assert!(*i < cap.len());
            assert!(((q - c).norm() - r).abs() < 0.1 * r, "{q:?}");
            assert!(q.z >= c.z - 0.02 * r, "{q:?}");
        }
        // A face-on square gets a back at the depth of its width.
        let mut face = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                face.push(Vec3::new(
                    -0.1 + 0.005 * f64::from(i),
                    -0.1 + 0.005 * f64::from(j),
                    1.0 + 0.0001 * f64::from((i * j) % 3),
                ));
            }
        }
        let vb = ViewBuffer::new(&face, Vec3::zeros(), 0.005).unwrap();
        let done = vb.complete(&face);
        assert!(!done.is_empty());
        let mean_z = done.iter().map(|(q, _)| q.z).sum::<f64>() / done.len() as f64;
        assert!((mean_z - 1.19).abs() < 0.03, "back at {mean_z}");
    }

    #[test]
    fn the_back_bound_ends_the_unseen_side_at_the_seen_extent() {
        let (c, r, _, cap, mut vb) = sphere_cap_view();
        let behind = |dz: f64| Vec3::new(0.0, 0.0, c.z + dz);
        // Unbounded, the whole occluded back is unknown.
        assert!(!vb.is_beyond_back(&behind(3.0 * r)));
        // Front 0.9, V = r, lateral 2r: the back at the true back (1.1).
        vb.bound_back(&cap, 1.0);
        assert!(vb.is_occluded(&behind(0.9 * r)));
        assert!(!vb.is_beyond_back(&behind(0.9 * r)));
        assert!(vb.is_beyond_back(&behind(1.3 * r)));
        // A deeper completion does not push a bound back out; a larger
        // factor on a fresh view does.
        vb.set_back([behind(2.0 * r)].iter());
        assert!(vb.is_beyond_back(&behind(1.3 * r)));
        let (_, _, _, _, mut wide) = sphere_cap_view();
        wide.bound_back(&cap, 1.5);
        assert!(!wide.is_beyond_back(&behind(1.3 * r)));
        assert!(wide.is_beyond_back(&behind(2.3 * r)));
    }

    #[test]
    fn a_fused_clouds_back_bound_spans_every_side_seen() {
        let (c, r, delta, cap, _) = sphere_cap_view();
        let behind = |dz: f64| Vec3::new(0.0, 0.0, c.z + dz);
        // The latest view's front cap alone: its back at the true back.
        let b = BackBound::of(&cap, Vec3::zeros(), delta, 1.0).unwrap();
        assert!(!b.is_beyond(&behind(0.9 * r)));
        assert!(b.is_beyond(&behind(1.3 * r)));
        assert!(!b.is_beyond(&behind(-0.9 * r)));
        // An earlier view saw a tail 3r deep: the fused points' depth, not
        // the latest view's alone, bounds the back.
        let mut fused = cap.clone();
        fused.extend((0..400).map(|i| behind(r * (1.0 + 2.0 * f64::from(i) / 399.0))));
        let b = BackBound::of(&fused, Vec3::zeros(), delta, 1.0).unwrap();
        assert!(!b.is_beyond(&behind(2.9 * r)));
        assert!(b.is_beyond(&behind(4.5 * r)));
        // Degenerate input gives no bound.
        assert!(BackBound::of(&cap[..7], Vec3::zeros(), delta, 1.0).is_none());
        assert!(BackBound::of(&cap, Vec3::zeros(), f64::NAN, 1.0).is_none());
    }

    #[test]
    fn degenerate_input_gives_no_view() {
        assert!(ViewBuffer::new(&[], Vec3::zeros(), 0.01).is_none());
        let p = [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0)];
        assert!(ViewBuffer::new(&p, Vec3::zeros(), 0.01).is_none());
        assert!(ViewBuffer::new(&p[..1], Vec3::zeros(), f64::NAN).is_none());
        let cfg: Viewpoint = serde_json::from_str("\"auto\"").unwrap();
        assert_eq!(cfg, Viewpoint::Mode(ViewMode::Auto));
        let cfg: Viewpoint = serde_json::from_str("[1, 2, 3]").unwrap();
        assert_eq!(cfg, Viewpoint::Point([1.0, 2.0, 3.0]));
        assert!(serde_json::from_str::<Viewpoint>("\"sideways\"").is_err());
    }
}
