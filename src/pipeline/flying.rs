//! Flying pixels: the mixed depths a depth camera returns on an object's
//! depth edges (`pipeline.flying`).
//!
//! A time-of-flight or structured-light pixel that straddles an object's
//! rim mixes the rim's depth with the background's and returns a depth
//! between them, on its own ray, behind the rim. The segmenter labels it as
//! the object. Such points form a veil behind the silhouette that no other
//! view confirms the same way twice, and the current frame's always counts:
//! measured with `sepmem synth --flying-pixels 0.3` (30 % of the edge
//! pixels fly, up to 10 cm behind), the turning capsule's last-third F
//! falls from 0.994 to 0.741, while 1 % outliers alone cost it 0.014.
//!
//! Seen from the sensor (the cloud frame's origin, where the fused model
//! puts it too, `crate::model`), each point lies on its own pixel's ray.
//! Between two neighbouring pixels an angular pitch `a` apart at range `r`,
//! a surface seen at incidence θ steps by about `r·a·tan θ`; a flying pixel
//! lies farther than the pixels inside the rim by whatever the mix gave it.
//! So, as the scan-shadows filter of ROS's `laser_filters` does for a laser
//! scan, a pair of neighbouring points (one or √2 pitches apart: the
//! 8-neighbourhood on the pixel grid) is a *jump* when the segment between them lies within
//! `min_angle_deg` of the farther point's ray, i.e. when the farther point
//! lies more than `r·a / tan(min_angle)` behind, and *continuous*
//! otherwise, and no step within [`NOISE_STEPS`] times the median step
//! between neighbouring pixels is a jump (the sensor's axial noise: 20 k
//! points of a 20 cm object at 1 m are pixels 1 mm apart, where a 10°
//! jump is 5.7 mm and the Kinect model's σ 1.9 mm; without that floor the
//! far tail of the noise went, and a single-view track drifted). A point is
//! flying when more of its neighbours lie nearer
//! across a jump than continue its surface. A surface behind a
//! self-occlusion (a mug's body beside its handle) keeps its edge: its
//! points continue their own surface on more sides than they meet the
//! occluder. The pitch is measured, not configured: the median angular
//! distance from a point to its nearest neighbour, which on a depth image
//! is the camera's pixel pitch (the sensor's noise is along the rays).
//!
//! Measured on the 18 fault sequences of `benches/robot_view_eval.sh` (the
//! nine shapes turning with 1 % outliers, and orbited with flying pixels
//! on 30 % of the depth edges besides), against no filter: mean last-third
//! F 0.709 → 0.806, median 0.726 → 0.877, volume IoU 0.843 → 0.947 (the
//! orbited capsule 0.607 → 0.973); without the noise floor, at 5° 0.785,
//! at 10° 0.809, at 15° 0.802. Without the floor, the clean twins 0.810 →
//! 0.820, and the 45 clean sequences 0.832 → 0.831, where 1–30 points a
//! sequence go. On single views (`pipeline.model` null) the filter is not
//! neutral: a turning 20 k-point ellipsoid's track drifts in its last
//! third (F 0.473 → 0.395; `tests/tracking.rs`). Against the simulator's truth
//! (`tests/flying_pixels.rs`): 85 % of the flying pixels caught (those less
//! than about 1.4 cm behind their surface at 1 m are a surface's step), and
//! 0.01 % of the surface points taken.
//!
//! The filter acts only on what is one depth image seen from the origin:
//! points on a pixel grid ([`MIN_ON_GRID_SHARE`]), all in front of the
//! eye. A cloud in a frame other than the sensor's, merged from several
//! views, or thinned on a voxel grid before it came keeps every point: it
//! would show a jump wherever its far side lies behind its near side.
//! Such a frame is counted ([`Outcome::not_an_image`], `StreamStats`), the
//! tracker warns once a stream has sent [`super::NOT_AN_IMAGE_WARN_AFTER`]
//! of them, and `replay` says how many there were: the fused model takes
//! the same origin for the camera, so such a stream needs its clouds in
//! the camera's optical frame.
//!
//! A point whose 3×3 bins hold more than [`MAX_AROUND`] points is not
//! looked at closely: a cloud piled on a few rays (100 000 points on three
//! rays) cost each sampled point a scan of all the points on its ray,
//! 0.2–0.3 s a frame, and 40–85 ms without them (two busy cores beside).

use crate::cloud::Vec3;
use crate::gnomonic::ViewFrame;
use serde::{Deserialize, Serialize};
use std::ops::Range;

checked_f64!(
    /// An angle in degrees in (0, 45], checked when the configuration is parsed.
    JumpAngle,
    |v| v > 0.0 && v <= 45.0,
    "an angle in degrees in (0, 45]"
);

/// `pipeline.flying`: when a step between neighbouring pixels is a jump.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlyingConfig {
    /// A pair of neighbouring points is a jump when the segment between
    /// them lies within this angle of the farther point's ray (degrees).
    pub min_angle_deg: JumpAngle,
}

impl Default for FlyingConfig {
    fn default() -> Self {
        Self {
            min_angle_deg: JumpAngle(10.0),
        }
    }
}

/// A depth image's points lie on their pixels' rays, which seen from the
/// camera form a square grid: nearly every point's nearest neighbour lies
/// one pitch away, within [`GRID_TOLERANCE`]. When fewer than this share
/// of the points do, the cloud is no one view from the origin (module
/// docs), and every point is kept. Measured (`tests/flying_pixels.rs`):
/// 0.98–1.0 in the depth images of `sepmem synth` (with 1 % outliers);
/// 0.08–0.82 in the same clouds seen from 0.6 m aside or from behind.
pub const MIN_ON_GRID_SHARE: f64 = 0.9;

/// Relative tolerance of a nearest-neighbour distance on the pixel grid.
pub const GRID_TOLERANCE: f64 = 0.1;

/// Least points for a pitch and a neighbourhood.
const MIN_POINTS: usize = 16;

/// The cone about the direction to the points' centroid (cosine) that
/// holds one camera's view of an object; a point beyond it is not in the
/// view.
const VIEW_MIN_COS: f64 = 0.5;

/// Neighbours lie within this many pitches (the 8-neighbourhood).
const NEIGHBOUR_PITCHES: f64 = 1.5;

/// A jump is at least this many times the median step between
/// neighbouring pixels (module docs): the sensor's noise must not read as
/// one. The median absolute difference of two normal depths is 0.95 σ of
/// each; six of it is 5.7 σ, or 4 σ of their difference.
const NOISE_STEPS: f64 = 6.0;

/// A point whose 3×3 bins hold more points than this is not looked at
/// closely: on a pixel grid they hold about 20 (bins of 1.5 pitches), or
/// a few hundred for the pitch's coarser bins of a thin object; a cloud
/// piled on a few rays (a hostile one) would otherwise cost each of its
/// points a scan of all of them.
const MAX_AROUND: usize = 1024;

/// Points sampled for the pitch (every k-th point of a larger cloud).
const PITCH_SAMPLES: usize = 2048;

/// What [`flying`] found a cloud to be.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Found {
    /// Fewer finite points than the filter looks at, or no extent.
    TooFew,
    /// Not one depth image seen from the origin (a point outside the
    /// view's cone, or the points not on one pixel grid): every point is
    /// kept. A cloud in a frame other than the camera's looks so.
    NotAnImage,
    /// One depth image seen from the origin, and which of its points are
    /// flying pixels (`None` when none is).
    Image(Option<Vec<bool>>),
}

impl Found {
    /// Which points are flying pixels; `None` when none is.
    pub fn mask(self) -> Option<Vec<bool>> {
        match self {
            Self::Image(mask) => mask,
            Self::TooFew | Self::NotAnImage => None,
        }
    }
}

/// What the filter did to one frame's cloud.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Outcome {
    /// Points dropped as flying pixels.
    pub dropped: usize,
    /// The cloud was not one depth image seen from its frame's origin
    /// ([`Found::NotAnImage`]), so every point was kept.
    pub not_an_image: bool,
}

/// Which of `points` are flying pixels seen from the origin (module docs).
/// Non-finite points are never flying.
pub fn flying(points: &[Vec3], cfg: &FlyingConfig) -> Found {
    let view = match View::of(points) {
        Ok(view) => view,
        Err(found) => return found,
    };
    let Some(coarse) = Image::new(&view, view.fill_bin()) else {
        return Found::TooFew;
    };
    let Some(pitch) = coarse.pitch() else {
        return Found::NotAnImage;
    };
    let Some(image) = Image::new(&view, NEIGHBOUR_PITCHES * pitch) else {
        return Found::TooFew;
    };
    let tan = cfg.min_angle_deg.get().to_radians().tan();
    let jump = Jump {
        pitch,
        tan,
        floor: NOISE_STEPS * image.median_step(pitch),
    };
    let mut mask = vec![false; points.len()];
    let mut count = 0;
    let nearest = image.nearest_ranges();
    for (k, at) in image.at.iter().enumerate() {
        // No neighbour on the grid can lie nearer across a jump than the
        // nearest range around: most points need no closer look.
        let least = jump.least((1.0 - GRID_TOLERANCE) * pitch, at.along);
        let beside = image.nearest_around(&nearest, at.uv);
        let closer = at.range - beside > least && image.crowd(at.uv) <= MAX_AROUND;
        if closer && image.is_flying(k, &jump) {
            mask[at.index] = true;
            count += 1;
        }
    }
    Found::Image((count > 0).then_some(mask))
}

/// When a step between two neighbours on the pixel grid is a jump.
#[derive(Debug, Clone, Copy)]
struct Jump {
    /// The grid's pitch (gnomonic).
    pitch: f64,
    /// The tangent of the jump angle.
    tan: f64,
    /// The least jump (m): [`NOISE_STEPS`] times the median step.
    floor: f64,
}

impl Jump {
    /// The least step of a jump between points `d` apart (gnomonic) at
    /// depth `along`.
    fn least(&self, d: f64, along: f64) -> f64 {
        (d * along / self.tan).max(self.floor)
    }
}

/// A point seen from the origin: its gnomonic position, depth along the
/// view direction, range, and index in the caller's slice.
#[derive(Debug, Clone, Copy, Default)]
struct Seen {
    uv: [f64; 2],
    along: f64,
    range: f64,
    index: usize,
}

/// The finite points seen from the origin, looking at their centroid, and
/// the gnomonic window that holds them.
struct View {
    seen: Vec<Seen>,
    lo: [f64; 2],
    hi: [f64; 2],
}

impl View {
    /// [`Found::TooFew`] for too few finite points or no extent,
    /// [`Found::NotAnImage`] for a point outside the view's cone (or a
    /// centroid at the eye).
    fn of(points: &[Vec3]) -> Result<Self, Found> {
        let finite = || points.iter().filter(|p| p.iter().all(|c| c.is_finite()));
        let (n, sum) = finite().fold((0, Vec3::zeros()), |(n, s), p| (n + 1, s + p));
        if n < MIN_POINTS {
            return Err(Found::TooFew);
        }
        let frame =
            ViewFrame::looking_at(Vec3::zeros(), sum / n as f64).ok_or(Found::NotAnImage)?;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut seen = Vec::with_capacity(n);
        for (index, p) in points.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                continue;
            }
            let (uv, along) = frame.project(p).ok_or(Found::NotAnImage)?;
            let range = p.norm();
            if along < VIEW_MIN_COS * range {
                return Err(Found::NotAnImage);
            }
            for k in 0..2 {
                lo[k] = lo[k].min(uv[k]);
                hi[k] = hi[k].max(uv[k]);
            }
            seen.push(Seen {
                uv,
                along,
                range,
                index,
            });
        }
        if hi[0] > lo[0] || hi[1] > lo[1] {
            Ok(Self { seen, lo, hi })
        } else {
            Err(Found::TooFew)
        }
    }

    /// 1.5 times the pitch the window would have if the points filled it:
    /// at least 1.5 times the pitch they have.
    fn fill_bin(&self) -> f64 {
        let (w, h) = (self.hi[0] - self.lo[0], self.hi[1] - self.lo[1]);
        NEIGHBOUR_PITCHES * (w * h / self.seen.len() as f64).sqrt()
    }
}

/// The points of a [`View`] binned by gnomonic position in square bins
/// (compressed rows: the points of bin `b` are `at[start[b]..start[b + 1]]`).
struct Image {
    at: Vec<Seen>,
    start: Vec<usize>,
    lo: [f64; 2],
    bin: f64,
    dims: [usize; 2],
}

impl Image {
    /// `view` in bins of edge `bin`, or coarser so that there are at most
    /// about four bins per point; `None` without a positive finite edge.
    fn new(view: &View, bin: f64) -> Option<Self> {
        let (w, h) = (view.hi[0] - view.lo[0], view.hi[1] - view.lo[1]);
        let n = view.seen.len() as f64;
        let bin = bin.max((w * h / (4.0 * n)).sqrt()).max((w + h) / n);
        if !(bin > 0.0 && bin.is_finite()) {
            return None;
        }
        let dims = [(w / bin) as usize + 1, (h / bin) as usize + 1];
        let mut image = Self {
            at: vec![Seen::default(); view.seen.len()],
            start: vec![0; dims[0] * dims[1] + 1],
            lo: view.lo,
            bin,
            dims,
        };
        image.fill(&view.seen);
        Some(image)
    }

    /// Bin `seen` (a counting sort by bin).
    fn fill(&mut self, seen: &[Seen]) {
        for s in seen {
            let b = self.bin_of(s.uv);
            self.start[b + 1] += 1;
        }
        for b in 1..self.start.len() {
            self.start[b] += self.start[b - 1];
        }
        let mut next = self.start.clone();
        for s in seen {
            let b = self.bin_of(s.uv);
            self.at[next[b]] = *s;
            next[b] += 1;
        }
    }

    fn bin_of(&self, uv: [f64; 2]) -> usize {
        let [x, y] = self.cell(uv);
        y * self.dims[0] + x
    }

    /// The bin of gnomonic position `uv`, clamped to the image.
    fn cell(&self, uv: [f64; 2]) -> [usize; 2] {
        // The cast truncates, which is the floor of a non-negative value,
        // and saturates (a negative value to 0).
        let at = |k: usize| (((uv[k] - self.lo[k]) / self.bin) as usize).min(self.dims[k] - 1);
        [at(0), at(1)]
    }

    /// The bins about the bin of `uv`, 3×3 but clamped to the image: one
    /// range of bin indices per row.
    fn block(&self, uv: [f64; 2]) -> impl Iterator<Item = Range<usize>> + '_ {
        let [x, y] = self.cell(uv);
        let (x0, x1) = (x.saturating_sub(1), (x + 1).min(self.dims[0] - 1));
        (y.saturating_sub(1)..=(y + 1).min(self.dims[1] - 1)).map(move |yy| {
            let row = yy * self.dims[0];
            row + x0..row + x1 + 1
        })
    }

    /// The points in the 3×3 bins about the bin of `uv`.
    fn around(&self, uv: [f64; 2]) -> impl Iterator<Item = &Seen> + '_ {
        self.block(uv)
            .flat_map(|bins| self.at[self.start[bins.start]..self.start[bins.end]].iter())
    }

    /// How many points the 3×3 bins about the bin of `uv` hold.
    fn crowd(&self, uv: [f64; 2]) -> usize {
        self.block(uv)
            .map(|bins| self.start[bins.end] - self.start[bins.start])
            .sum()
    }

    /// The nearest range in each bin (infinite in an empty one).
    fn nearest_ranges(&self) -> Vec<f64> {
        (0..self.start.len() - 1)
            .map(|b| {
                let bin = &self.at[self.start[b]..self.start[b + 1]];
                bin.iter().map(|s| s.range).fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    /// The nearest range of `nearest` (per bin) over the 3×3 bins about
    /// the bin of `uv`.
    fn nearest_around(&self, nearest: &[f64], uv: [f64; 2]) -> f64 {
        self.block(uv)
            .flat_map(|bins| nearest[bins].iter().copied())
            .fold(f64::INFINITY, f64::min)
    }

    /// The median gnomonic distance from a point to its nearest neighbour
    /// within a bin (the camera's pixel pitch on a depth image), when the
    /// points lie on a pixel grid: `None` when fewer than
    /// [`MIN_ON_GRID_SHARE`] of them have their nearest neighbour at that
    /// distance, or too few points have a neighbour.
    fn pitch(&self) -> Option<f64> {
        let every = self.at.len().div_ceil(PITCH_SAMPLES);
        let sampled = self.at.len().div_ceil(every);
        let mut nearest: Vec<f64> = (0..self.at.len())
            .step_by(every)
            .filter(|&k| self.crowd(self.at[k].uv) <= MAX_AROUND)
            .filter_map(|k| {
                let me = &self.at[k];
                self.around(me.uv)
                    .filter(|o| o.index != me.index)
                    .map(|o| dist2(me.uv, o.uv))
                    .filter(|d2| *d2 <= self.bin * self.bin)
                    .min_by(f64::total_cmp)
            })
            .collect();
        if nearest.len() < MIN_POINTS {
            return None;
        }
        let mid = nearest.len() / 2;
        let pitch = nearest.select_nth_unstable_by(mid, f64::total_cmp).1.sqrt();
        let (lo, hi) = (
            (1.0 - GRID_TOLERANCE) * pitch,
            (1.0 + GRID_TOLERANCE) * pitch,
        );
        let on_grid = nearest
            .iter()
            .filter(|d2| (lo * lo..=hi * hi).contains(*d2))
            .count();
        let grid = on_grid as f64 >= MIN_ON_GRID_SHARE * sampled as f64;
        (pitch > 0.0 && grid).then_some(pitch)
    }

    /// Whether point `k` is flying: more of its neighbours on the grid (one
    /// or √2 pitches away) lie nearer across a jump than continue its
    /// surface (module docs), with pitch `pitch` and `tan` the tangent of
    /// the jump angle.
    fn is_flying(&self, k: usize, jump: &Jump) -> bool {
        let me = &self.at[k];
        let (mut jumps, mut continuous) = (0usize, 0usize);
        for (d, o) in self.grid_neighbours(me, jump.pitch) {
            let step = me.range - o.range;
            let least = jump.least(d, me.along);
            if step > least {
                jumps += 1;
            } else if step >= -least {
                continuous += 1;
            }
        }
        jumps > continuous
    }

    /// The neighbours of `me` on the grid of `pitch` (one or √2 pitches
    /// away, within the grid's tolerance), with their gnomonic distances.
    fn grid_neighbours<'a>(
        &'a self,
        me: &'a Seen,
        pitch: f64,
    ) -> impl Iterator<Item = (f64, &'a Seen)> + 'a {
        let inner = (1.0 - GRID_TOLERANCE) * pitch;
        let outer = (NEIGHBOUR_PITCHES * pitch).min(self.bin);
        self.around(me.uv).filter_map(move |o| {
            let d2 = dist2(me.uv, o.uv);
            (d2 >= inner * inner && d2 <= outer * outer).then(|| (d2.sqrt(), o))
        })
    }

    /// The median step in range between neighbours on the grid of `pitch`
    /// over a sample of the points: the sensor's noise (and the surface's
    /// slope) between neighbouring pixels; 0 without neighbours.
    fn median_step(&self, pitch: f64) -> f64 {
        let every = self.at.len().div_ceil(PITCH_SAMPLES);
        let mut steps: Vec<f64> = (0..self.at.len())
            .step_by(every)
            .flat_map(|k| {
                let me = &self.at[k];
                self.grid_neighbours(me, pitch)
                    .map(move |(_, o)| (me.range - o.range).abs())
            })
            .collect();
        if steps.is_empty() {
            return 0.0;
        }
        let mid = steps.len() / 2;
        *steps.select_nth_unstable_by(mid, f64::total_cmp).1
    }
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The pixels of a 640×480, f = 525 camera that see the sphere of
    /// radius `r` about `c`, each at its first hit (a depth image), with no
    /// return beyond 80° incidence (as `sepmem synth`'s Kinect model).
    pub(crate) fn sphere_view(c: Vec3, r: f64) -> Vec<(usize, usize, Vec3)> {
        let mut out = Vec::new();
        for v in 0..480 {
            for u in 0..640 {
                let d = Vec3::new((u as f64 - 319.5) / 525.0, (v as f64 - 239.5) / 525.0, 1.0)
                    .normalize();
                let b = d.dot(&c);
                let disc = b * b - (c.norm_squared() - r * r);
                let hit = d * (b - disc.sqrt());
                let incidence = ((hit - c) / r).dot(&-d);
                if disc > 0.0 && incidence > 80f64.to_radians().cos() {
                    out.push((u, v, hit));
                }
            }
        }
        out
    }

    fn is_rim(view: &[(usize, usize, Vec3)], u: usize, v: usize) -> bool {
        let has = |uu: usize, vv: usize| view.iter().any(|&(a, b, _)| a == uu && b == vv);
        !(has(u + 1, v) && has(u - 1, v) && has(u, v + 1) && has(u, v - 1))
    }

    #[test]
    fn the_veil_behind_a_rim_flies_and_the_surface_stays() {
        let view = sphere_view(Vec3::new(0.05, -0.02, 0.8), 0.06);
        let mut points: Vec<Vec3> = Vec::new();
        let mut flies: Vec<bool> = Vec::new();
        for (k, &(u, v, p)) in view.iter().enumerate() {
            // Every third rim pixel flies 2–8 cm behind its surface.
            let fly = is_rim(&view, u, v) && k % 3 == 0;
            let behind = 0.02 + 0.06 * ((k * 7919) % 100) as f64 / 100.0;
            points.push(if fly {
                p * (1.0 + behind / p.norm())
            } else {
                p
            });
            flies.push(fly);
        }
        let n_fly = flies.iter().filter(|&&f| f).count();
        assert!(n_fly > 20, "{n_fly} flying pixels");
        let mask = flying(&points, &FlyingConfig::default())
            .mask()
            .expect("flying pixels found");
        let caught = mask.iter().zip(&flies).filter(|(m, f)| **m && **f).count();
        let wrong = mask.iter().zip(&flies).filter(|(m, f)| **m && !**f).count();
        assert!(caught as f64 >= 0.95 * n_fly as f64, "{caught} of {n_fly}");
        assert!(
            wrong as f64 <= 0.002 * points.len() as f64,
            "{wrong} surface points"
        );
    }

    #[test]
    fn a_surface_behind_a_self_occlusion_keeps_its_edge() {
        // A far plate with a near bar across it: one object's view.
        let mut points = Vec::new();
        for v in 200..280 {
            for u in 280..360 {
                let d = Vec3::new((u as f64 - 319.5) / 525.0, (v as f64 - 239.5) / 525.0, 1.0);
                let z = if (310..318).contains(&u) { 0.7 } else { 0.8 };
                points.push(d * z);
            }
        }
        assert_eq!(
            flying(&points, &FlyingConfig::default()),
            Found::Image(None)
        );
    }

    #[test]
    fn a_cloud_seen_through_from_the_origin_is_kept_whole() {
        // A whole sphere: its back lies behind its front on every ray.
        let c = Vec3::new(0.0, 0.0, 0.8);
        let points: Vec<Vec3> = crate::shapes::fibonacci_sphere(4000)
            .into_iter()
            .map(|p| c + 0.1 * p)
            .collect();
        let found = flying(&points, &FlyingConfig::default());
        assert_eq!(found, Found::NotAnImage);
    }

    #[test]
    fn a_points_neighbourhood_is_every_point_of_the_3x3_bins_about_it() {
        let points: Vec<Vec3> = crate::shapes::fibonacci_sphere(3000)
            .into_iter()
            .map(|p| p * 0.2 + Vec3::new(0.1, 0.0, 1.0))
            .collect();
        let view = View::of(&points).unwrap();
        let image = Image::new(&view, view.fill_bin()).unwrap();
        for me in image.at.iter().step_by(37) {
            let [x, y] = image.cell(me.uv);
            let near = |o: &Seen| {
                let [ox, oy] = image.cell(o.uv);
                ox.abs_diff(x) <= 1 && oy.abs_diff(y) <= 1
            };
            let mut brute: Vec<usize> = image
                .at
                .iter()
                .filter(|o| near(o))
                .map(|o| o.index)
                .collect();
            let mut around: Vec<usize> = image.around(me.uv).map(|o| o.index).collect();
            brute.sort_unstable();
            around.sort_unstable();
            assert_eq!(around, brute);
            assert_eq!(image.crowd(me.uv), brute.len());
        }
    }

    #[test]
    fn a_cloud_piled_on_two_rays_is_kept_without_a_scan_of_every_pair() {
        // 100 000 points on two rays: without the bound on a neighbourhood's
        // crowd, each of 2 048 sampled points scanned 50 000 others.
        let points: Vec<Vec3> = (0..100_000)
            .map(|k| {
                let r = 0.5 + (k % 997) as f64 / 997.0;
                let d = if k % 2 == 0 { [0.01, 0.0] } else { [0.0, 0.01] };
                Vec3::new(d[0], d[1], 1.0) * r
            })
            .collect();
        let found = flying(&points, &FlyingConfig::default());
        assert_eq!(found, Found::NotAnImage);
    }

    #[test]
    fn odd_clouds_keep_every_point() {
        let cfg = FlyingConfig::default();
        assert_eq!(flying(&[], &cfg), Found::TooFew);
        let nan = vec![Vec3::new(f64::NAN, 0.0, 1.0); 100];
        assert_eq!(flying(&nan, &cfg), Found::TooFew);
        let same = vec![Vec3::new(0.1, 0.0, 1.0); 100];
        assert_eq!(flying(&same, &cfg), Found::TooFew);
        // Around the eye: points behind it.
        let around: Vec<Vec3> = (0..100)
            .map(|k| Vec3::new((k as f64).cos(), (k as f64).sin(), 0.1))
            .collect();
        assert_eq!(flying(&around, &cfg), Found::NotAnImage);
        // On one line of pixels.
        let line: Vec<Vec3> = (0..100)
            .map(|k| Vec3::new(k as f64 / 525.0, 0.0, 1.0 + 0.01 * (k % 2) as f64))
            .collect();
        assert!(flying(&line, &cfg).mask().is_none_or(|m| m.len() == 100));
    }
}
