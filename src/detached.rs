//! Points detached from an object's main body (`membrane.prepare.detached`).
//!
//! A segmented object's cloud is not always one object. A mask that bled
//! onto the wall behind the object, a label the segmenter gave two objects,
//! a cluster of stray returns: each is a group of points far from the body,
//! too many and too dense for the outlier filter (a point whose own
//! neighbours are close is no outlier), and the membrane wraps it with the
//! body in one surface. Measured on the committed turning capsule
//! (`tests/data/bags/robot_view/turn_capsule.mcap`, 2–4 k points a frame)
//! with a 10 cm patch of 300 points 0.6 m behind it in every frame
//! (`tests/python/add_detached.py`): last-third F 0.994 → 0.004, seen side
//! 0.969 → 0.164, and meshes of up to 426 times the object's volume, which a
//! planner takes for an obstacle. A robot's perception stack keeps the
//! object's main Euclidean cluster for this reason; so does sepmem, before
//! anything else looks at the points.
//!
//! The points are binned into cells of a quarter of their robust spread
//! (the largest median absolute deviation about the median point, over the
//! three axes: about 16 cells across the body, whatever lies far off), and
//! the occupied cells are split into groups that touch (26-neighbourhood).
//! The body starts as the group with the most points. A group joins it when
//! the gap between their bounding boxes is at most `gap` times the body's
//! bounding-box diagonal, and the body's box grows by it; the rest are
//! dropped. An object cut in two by an occluder (a gripper's fingers
//! across a bottle) keeps both parts: their gap is a fraction of the
//! parts' size. So does an object that hides its own middle: the camera
//! orbiting the bent tube sees it end-on at frame 14, its far arm 5.3 cm
//! behind the near one, whose box diagonal is 9.8 cm. `gap` 0.5 dropped
//! that arm (the sequence's last-third F 0.904 → 0.507); at the default
//! 1.0 none of the 45 sequences of `benches/robot_view_eval.sh` loses a
//! point, and Table 1 and the sphere sweep of `sepmem bench` score as
//! without the filter. A group nearer than a cell (a bleed onto the table
//! the object stands on) is part of the body: this filter does not
//! separate what touches, nor a bleed nearer than the object's size.
//!
//! Closer to the camera the same self-occlusion parts the arms by more
//! than the near arm's diagonal: orbiting the bent tube at 0.5 m (6.7 k
//! points a frame), the far arm went at frame 16 (1 813 of 4 181 points),
//! the cloud's size fell by 73 %, the frame restarted cold and the fused
//! model with it (last-third F 0.657; 0.974 with nothing dropped). So a
//! tracked object's fused model says what the object is: a group that lies
//! within the box the model spans in the cloud's frame (under the last
//! tracked pose), grown by [`KNOWN_MARGIN`] of its diagonal, joins the
//! body whatever its gap ([`Known`]). A bleed onto the wall behind lies
//! beyond the model, and goes as before.

use crate::cloud::{Aabb, Vec3};
use crate::spatial::CELL_NEIGHBOURS;
use ahash::AHashMap;
use serde::{Deserialize, Serialize};

/// `membrane.prepare.detached`: which groups of points count as detached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DetachedConfig {
    /// A group whose bounding box lies farther from the body's than this
    /// share of the body's bounding-box diagonal is dropped.
    pub gap: f64,
}

impl Default for DetachedConfig {
    fn default() -> Self {
        Self { gap: 1.0 }
    }
}

/// Cells per robust spread (the largest median absolute deviation).
const CELLS_PER_SPREAD: f64 = 4.0;

/// The share of the known box's diagonal by which [`Known`] grows it: the
/// object moved since the pose that placed the box.
pub const KNOWN_MARGIN: f64 = 0.1;

/// Where the object is known to lie: the box its tracked model spans in
/// the cloud's frame, grown by [`KNOWN_MARGIN`] of its diagonal (module
/// docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Known(Aabb);

impl Known {
    /// The known box of an object whose model spans `extent`; `None` for
    /// an empty or non-finite box (an empty model knows nothing).
    pub fn new(extent: Aabb) -> Option<Self> {
        let diagonal = extent.diagonal();
        (!extent.is_empty() && diagonal.is_finite())
            .then(|| Self(extent.inflated(KNOWN_MARGIN * diagonal)))
    }

    /// True when the box from `lo` to `hi` lies within the known box.
    fn holds(&self, lo: &Vec3, hi: &Vec3) -> bool {
        self.0.contains(lo) && self.0.contains(hi)
    }
}

/// Cell coordinates are clamped to this magnitude: a point 10³⁰ m away
/// lands in a far cell instead of overflowing.
const MAX_CELL: f64 = (1u64 << 40) as f64;

/// The main body's box, when `points` hold groups detached from it
/// (module docs); `None` when every group belongs to the body, or the
/// cloud has fewer than two finite points or no spread. A group that
/// `known` holds belongs to the body.
///
/// A point of `points` belongs to the body exactly when it lies in this
/// box: a group whose box met the body's would have joined it. The box
/// found on a subsample of a cloud (the frame pipeline's thinned points)
/// also holds the rest of the body's points, with [`Body::contains`]'s
/// margin of one cell.
pub fn body(points: &[Vec3], cfg: &DetachedConfig, known: Option<&Known>) -> Option<Body> {
    let (origin, cell) = binning(points)?;
    let cells: Vec<Option<[i64; 3]>> = points.iter().map(|p| cell_of(p, origin, cell)).collect();
    let groups = Groups::of(&cells, points);
    let (kept, lo, hi) = groups.body(cfg.gap, known);
    (!kept.iter().all(|&k| k)).then_some(Body {
        lo,
        hi,
        margin: cell,
    })
}

/// The main body's bounding box, with a margin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    lo: Vec3,
    hi: Vec3,
    margin: f64,
}

impl Body {
    /// True when `p` lies in the body's box widened by one cell on every
    /// side; false for a non-finite point.
    pub fn contains(&self, p: &Vec3) -> bool {
        (0..3).all(|k| p[k] >= self.lo[k] - self.margin && p[k] <= self.hi[k] + self.margin)
    }
}

/// The median point and the cell edge, or `None` for fewer than two finite
/// points or no spread.
fn binning(points: &[Vec3]) -> Option<(Vec3, f64)> {
    let finite: Vec<&Vec3> = points.iter().filter(|p| is_finite(p)).collect();
    if finite.len() < 2 {
        return None;
    }
    let mut axis: Vec<f64> = Vec::with_capacity(finite.len());
    let mut origin = Vec3::zeros();
    let mut spread = 0.0_f64;
    for k in 0..3 {
        axis.clear();
        axis.extend(finite.iter().map(|p| p[k]));
        let centre = median(&mut axis);
        axis.iter_mut().for_each(|x| *x = (*x - centre).abs());
        spread = spread.max(median(&mut axis));
        origin[k] = centre;
    }
    let cell = spread / CELLS_PER_SPREAD;
    (cell > 0.0 && cell.is_finite()).then_some((origin, cell))
}

fn median(values: &mut [f64]) -> f64 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

fn is_finite(p: &Vec3) -> bool {
    p.iter().all(|c| c.is_finite())
}

/// The cell of `p`; `None` for a non-finite point.
fn cell_of(p: &Vec3, origin: Vec3, cell: f64) -> Option<[i64; 3]> {
    if !is_finite(p) {
        return None;
    }
    let at = |k: usize| {
        ((p[k] - origin[k]) / cell)
            .floor()
            .clamp(-MAX_CELL, MAX_CELL) as i64
    };
    Some([at(0), at(1), at(2)])
}

/// The 26 cells around `c`.
fn neighbours(c: [i64; 3]) -> impl Iterator<Item = [i64; 3]> {
    CELL_NEIGHBOURS
        .map(|o| [0, 1, 2].map(|k| c[k] + i64::from(o[k])))
        .into_iter()
}

/// Each occupied cell's group: cells that touch (26-neighbourhood) share
/// one. Groups are numbered in the order of their least cell, so the
/// numbering does not depend on the points' order.
fn label(cells: &[Option<[i64; 3]>]) -> AHashMap<[i64; 3], u32> {
    const UNSEEN: u32 = u32::MAX;
    let mut group: AHashMap<[i64; 3], u32> = cells.iter().flatten().map(|&c| (c, UNSEEN)).collect();
    let mut order: Vec<[i64; 3]> = group.keys().copied().collect();
    order.sort_unstable();
    let (mut count, mut stack) = (0u32, Vec::new());
    for seed in order {
        if group[&seed] != UNSEEN {
            continue;
        }
        group.insert(seed, count);
        stack.push(seed);
        while let Some(c) = stack.pop() {
            for n in neighbours(c) {
                if let Some(g) = group.get_mut(&n).filter(|g| **g == UNSEEN) {
                    *g = count;
                    stack.push(n);
                }
            }
        }
        count += 1;
    }
    group
}

/// The groups of touching occupied cells: each one's point count and
/// bounding box.
struct Groups {
    points: Vec<usize>,
    lo: Vec<Vec3>,
    hi: Vec<Vec3>,
}

impl Groups {
    /// The groups of the points whose cells are `cells` (`None`: a
    /// non-finite point, in no group).
    fn of(cells: &[Option<[i64; 3]>], points: &[Vec3]) -> Self {
        let group = label(cells);
        let n = group.values().max().map_or(0, |&g| g as usize + 1);
        let mut g = Self {
            points: vec![0; n],
            lo: vec![Vec3::repeat(f64::INFINITY); n],
            hi: vec![Vec3::repeat(f64::NEG_INFINITY); n],
        };
        for (c, p) in cells.iter().zip(points) {
            if let Some(c) = c {
                let k = group[c] as usize;
                g.points[k] += 1;
                g.lo[k] = g.lo[k].inf(p);
                g.hi[k] = g.hi[k].sup(p);
            }
        }
        g
    }

    /// Which groups the body keeps, growing from the largest (module
    /// docs), and the body's bounding box.
    fn body(&self, gap: f64, known: Option<&Known>) -> (Vec<bool>, Vec3, Vec3) {
        let n = self.points.len();
        let mut kept = vec![false; n];
        // The most points; of equal counts, the first group.
        let Some(first) = (0..n).max_by_key(|&g| (self.points[g], std::cmp::Reverse(g))) else {
            return (kept, Vec3::zeros(), Vec3::zeros());
        };
        kept[first] = true;
        let (mut lo, mut hi) = (self.lo[first], self.hi[first]);
        let mut grown = true;
        while grown {
            grown = false;
            let reach = gap * (hi - lo).norm();
            for ((k, g_lo), g_hi) in kept.iter_mut().zip(&self.lo).zip(&self.hi) {
                let apart = (g_lo - hi).sup(&(lo - g_hi)).sup(&Vec3::zeros());
                let held = known.is_some_and(|b| b.holds(g_lo, g_hi));
                if !*k && (apart.norm() <= reach || held) {
                    *k = true;
                    lo = lo.inf(g_lo);
                    hi = hi.sup(g_hi);
                    grown = true;
                }
            }
        }
        (kept, lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// `n` points on a sphere of radius `r` about `c`.
    fn sphere(n: usize, r: f64, c: Vec3, seed: u64) -> Vec<Vec3> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let v = Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                c + v.normalize() * r
            })
            .collect()
    }

    fn cfg() -> DetachedConfig {
        DetachedConfig::default()
    }

    #[test]
    fn one_object_has_nothing_detached() {
        assert_eq!(
            body(&sphere(2_000, 0.1, Vec3::zeros(), 1), &cfg(), None),
            None
        );
    }

    #[test]
    fn a_far_group_is_dropped_and_the_body_kept() {
        let object = sphere(2_000, 0.1, Vec3::zeros(), 1);
        // The sphere's box diagonal is 0.35: the group's box is 0.65 and more away.
        for far in [0.8, 5.0, 500.0, 1e30] {
            let group = sphere(400, 0.05, Vec3::new(far, 0.0, 0.0), 2);
            let all: Vec<Vec3> = object.iter().chain(&group).copied().collect();
            let b = body(&all, &cfg(), None).expect("a detached group");
            assert!(object.iter().all(|p| b.contains(p)), "at {far}");
            assert!(group.iter().all(|p| !b.contains(p)), "at {far}");
        }
    }

    #[test]
    fn a_far_group_the_known_box_holds_is_kept_and_one_beyond_it_dropped() {
        // A tube seen end-on: its near arm (the most points) and its far arm
        // 0.5 m behind, more than the near arm's diagonal (0.35) away.
        let near = sphere(2_000, 0.1, Vec3::zeros(), 1);
        let far = sphere(400, 0.05, Vec3::new(0.0, 0.0, 0.5), 2);
        let all: Vec<Vec3> = near.iter().chain(&far).copied().collect();
        assert!(body(&all, &cfg(), None).is_some());
        // The model spans both arms, seen from the side in earlier frames.
        let spans_both = Known::new(Aabb::from_points(&all));
        assert_eq!(body(&all, &cfg(), spans_both.as_ref()), None);
        // A model that spans the near arm alone does not hold the far one.
        let near_only = Known::new(Aabb::from_points(&near));
        let b = body(&all, &cfg(), near_only.as_ref()).expect("the far arm goes");
        assert!(near.iter().all(|p| b.contains(p)));
        assert!(far.iter().all(|p| !b.contains(p)));
        // An empty model knows nothing.
        assert_eq!(Known::new(Aabb::empty()), None);
    }

    #[test]
    fn a_group_nearer_than_the_bodys_diagonal_is_kept() {
        // The sphere's box diagonal is 0.35; the group's box 0.25 away.
        let object = sphere(2_000, 0.1, Vec3::zeros(), 1);
        let group = sphere(400, 0.05, Vec3::new(0.4, 0.0, 0.0), 2);
        let all: Vec<Vec3> = object.iter().chain(&group).copied().collect();
        assert_eq!(body(&all, &cfg(), None), None);
    }

    #[test]
    fn an_object_cut_by_an_occluder_keeps_both_parts() {
        // A 20 cm bar with its middle 4 cm hidden (a gripper's fingers).
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let bar: Vec<Vec3> = (0..3_000)
            .map(|_| {
                let x: f64 = rng.random_range(-0.1..0.1);
                Vec3::new(
                    x,
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                )
            })
            .filter(|p| p.x.abs() > 0.02)
            .collect();
        assert_eq!(body(&bar, &cfg(), None), None);
    }

    #[test]
    fn the_larger_of_two_far_objects_is_the_body() {
        let big = sphere(1_500, 0.1, Vec3::zeros(), 1);
        let small = sphere(1_000, 0.1, Vec3::new(3.0, 0.0, 0.0), 2);
        let mut all: Vec<Vec3> = small.iter().chain(&big).copied().collect();
        let b = body(&all, &cfg(), None).expect("two objects");
        assert!(big.iter().all(|p| b.contains(p)));
        assert!(small.iter().all(|p| !b.contains(p)));
        // The same body whatever the points' order.
        all.reverse();
        assert_eq!(body(&all, &cfg(), None), Some(b));
    }

    #[test]
    fn odd_clouds_keep_every_point() {
        let nan = Vec3::repeat(f64::NAN);
        for cloud in [
            vec![],
            vec![Vec3::zeros()],
            vec![Vec3::zeros(); 100],
            vec![nan, nan, Vec3::zeros()],
        ] {
            assert_eq!(body(&cloud, &cfg(), None), None, "{cloud:?}");
        }
        let mut with_nan = sphere(500, 0.1, Vec3::zeros(), 1);
        with_nan.push(nan);
        assert_eq!(body(&with_nan, &cfg(), None), None);
    }
}
