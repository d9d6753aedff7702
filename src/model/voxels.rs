//! The point memory: one running mean per occupied voxel of the object's frame.
//!
//! Overlapping views make an accumulated cloud very uneven: a region seen in
//! every frame is many times denser than one seen once, and the membrane's
//! global δ then treats the sparse parts as empty (`robot-view-findings`:
//! fused raw clouds F 0.29–0.67, voxel-downsampled to 0.8 τ 0.39–0.93). A
//! voxel hash keeps one representative per voxel, so the fused cloud is
//! evenly dense by construction, and its size is bounded by the voxel count
//! rather than by the number of frames.
//!
//! Each voxel holds the mean of its points, how many frames hit it, and the
//! frame it was last seen in. A new observation pulls the mean toward
//! itself by `current_weight`, so the current view dominates where it sees
//! the object. Past `max_voxels` the least recently seen voxels (fewest hits
//! first among equals) are dropped.
//!
//! A sensor's outliers and flying pixels land in new voxels frame after
//! frame, and a memory of every voxel would pile them up around the object.
//! The fused points are therefore the confirmed voxels only
//! ([`VoxelMemory::confirmed`]): those the current frame hit, those hit in at
//! least `min_hits` frames, and those touching one of the latter (the fringe
//! of a surface, or observations that fell into two neighbouring voxels).
//! Unconfirmed voxels stay in the memory, and a later hit confirms them. A
//! surface that only one earlier frame saw therefore waits for a second
//! look. Measured over 18 turning and orbited synth sequences with the
//! Kinect model's 1 % outliers, half of them with flying pixels on 30 % of
//! the depth edges (`sepmem synth`, 480×360 camera at 1 m, as in
//! `benches/robot_view_eval.sh`): mean last-third F 0.557 without, 0.709
//! with (all 18 up; IoU 0.797 → 0.843, seen side 0.867 → 0.909); the same
//! sequences without the faults 0.817 → 0.810, and the 45 sequences of
//! `benches/robot_view_eval.sh` 0.833 → 0.832 (10 up, 15 down: the spread any
//! change to tracking gives). Counting instead a voxel hit once while 9 of
//! its 26 neighbours are occupied (a thick patch) rose the faults' mean to
//! 0.764 but cost the 45 0.014 (0.819; a turning rounded box −0.13, an
//! ellipsoid turned 360° −0.25); `min_hits` alone, 0.756.

use crate::cloud::Vec3;
use crate::spatial::{cell_key, FixedMap, CELL_NEIGHBOURS};

/// Integer voxel coordinates.
pub type VoxelKey = [i32; 3];

/// One occupied voxel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Voxel {
    /// Mean position of the points it holds, in the object's frame.
    pub mean: [f32; 3],
    /// Frames that hit it (saturating).
    pub hits: u16,
    /// Frames in which a view saw through it since it was last hit.
    pub contradictions: u16,
    /// The model frame it was last hit in.
    pub last_seen: u32,
}

impl Voxel {
    /// The mean as a position.
    pub fn position(&self) -> Vec3 {
        Vec3::new(
            f64::from(self.mean[0]),
            f64::from(self.mean[1]),
            f64::from(self.mean[2]),
        )
    }
}

/// A bounded voxel hash of observed points.
#[derive(Debug, Clone)]
pub struct VoxelMemory {
    size: f64,
    max_voxels: usize,
    voxels: FixedMap<VoxelKey, Voxel>,
}

impl VoxelMemory {
    /// An empty memory with voxels of edge `size` (metres, > 0), holding at
    /// most `max_voxels`.
    pub fn new(size: f64, max_voxels: usize) -> Self {
        Self {
            size,
            max_voxels: max_voxels.max(1),
            voxels: FixedMap::default(),
        }
    }

    /// The voxel edge.
    pub fn voxel_size(&self) -> f64 {
        self.size
    }

    /// The key of the voxel holding `p`.
    pub fn key(&self, p: &Vec3) -> VoxelKey {
        cell_key(p, self.size)
    }

    /// Add the points of frame `frame` (object frame): per voxel, the mean of
    /// this frame's points, blended into the stored mean with weight
    /// `current_weight`. Returns the number of voxels the frame hit.
    pub fn insert(&mut self, points: &[Vec3], frame: u32, current_weight: f32) -> usize {
        let mut frame_means: FixedMap<VoxelKey, (Vec3, u32)> = FixedMap::default();
        for p in points.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
            let e = frame_means.entry(self.key(p)).or_insert((Vec3::zeros(), 0));
            e.0 += p;
            e.1 += 1;
        }
        let hit = frame_means.len();
        for (key, (sum, n)) in frame_means {
            let m = sum / f64::from(n);
            let m = [m.x as f32, m.y as f32, m.z as f32];
            self.voxels
                .entry(key)
                .and_modify(|v| {
                    for (a, b) in v.mean.iter_mut().zip(m) {
                        *a += current_weight * (b - *a);
                    }
                    v.hits = v.hits.saturating_add(1);
                    v.contradictions = 0;
                    v.last_seen = frame;
                })
                .or_insert(Voxel {
                    mean: m,
                    hits: 1,
                    contradictions: 0,
                    last_seen: frame,
                });
        }
        self.enforce_cap();
        hit
    }

    /// Drop the least recently seen voxels until at most `max_voxels` remain
    /// (to 90 % of the cap, so the pass runs once per many inserts).
    fn enforce_cap(&mut self) {
        if self.voxels.len() <= self.max_voxels {
            return;
        }
        let keep = self.max_voxels - self.max_voxels / 10;
        let mut order: Vec<(u32, u16, VoxelKey)> = self
            .voxels
            .iter()
            .map(|(k, v)| (v.last_seen, v.hits, *k))
            .collect();
        let drop = order.len() - keep;
        order.select_nth_unstable_by(drop - 1, |a, b| (a.0, a.1).cmp(&(b.0, b.1)));
        for (_, _, k) in &order[..drop] {
            self.voxels.remove(k);
        }
        self.voxels.shrink_to(self.max_voxels);
    }

    /// Mark the voxels for which `seen_through` holds as contradicted by this
    /// frame; a voxel contradicted in `forget_after` frames without a hit in
    /// between is removed. Returns (voxels tested, voxels contradicted).
    pub fn contradict(
        &mut self,
        frame: u32,
        forget_after: u16,
        mut seen_through: impl FnMut(&Voxel) -> Option<bool>,
    ) -> (usize, usize) {
        let (mut tested, mut contradicted) = (0, 0);
        self.voxels.retain(|_, v| {
            if v.last_seen == frame {
                return true;
            }
            match seen_through(v) {
                Some(true) => {
                    tested += 1;
                    contradicted += 1;
                    v.contradictions = v.contradictions.saturating_add(1);
                    v.contradictions < forget_after
                }
                Some(false) => {
                    tested += 1;
                    true
                }
                None => true,
            }
        });
        (tested, contradicted)
    }

    /// The voxels that count as observed in model frame `frame` (module
    /// docs): hit in `frame`, hit in at least `min_hits` frames, or touching
    /// (26-neighbourhood) a voxel hit in at least `min_hits`.
    pub fn confirmed(&self, frame: u32, min_hits: u16) -> impl Iterator<Item = &Voxel> {
        let firm = move |v: &Voxel| v.hits >= min_hits;
        self.voxels.iter().filter_map(move |(k, v)| {
            let kept = firm(v) || v.last_seen == frame || self.touches(k, firm);
            kept.then_some(v)
        })
    }

    /// True when a voxel around `k` (its 26 neighbours) is `firm`.
    fn touches(&self, k: &VoxelKey, firm: impl Fn(&Voxel) -> bool) -> bool {
        CELL_NEIGHBOURS.iter().any(|o| {
            let n = [k[0] + o[0], k[1] + o[1], k[2] + o[2]];
            self.voxels.get(&n).is_some_and(&firm)
        })
    }

    /// The occupied voxels.
    pub fn iter(&self) -> impl Iterator<Item = &Voxel> {
        self.voxels.values()
    }

    /// Number of occupied voxels.
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    /// True when nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// Bytes held (the table's capacity times its entry size, plus control bytes).
    pub fn bytes(&self) -> usize {
        let entry = std::mem::size_of::<(VoxelKey, Voxel)>() + 1;
        self.voxels.capacity() * entry
    }

    /// Forget everything.
    pub fn clear(&mut self) {
        self.voxels = FixedMap::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_representative_per_voxel_whatever_the_density() {
        let mut mem = VoxelMemory::new(0.1, 10_000);
        // 1,000 points in one voxel and one point in another.
        let mut pts: Vec<Vec3> = (0..1000)
            .map(|i| Vec3::new(0.01 + 0.00008 * i as f64, 0.05, 0.05))
            .collect();
        pts.push(Vec3::new(0.55, 0.05, 0.05));
        assert_eq!(mem.insert(&pts, 0, 1.0), 2);
        assert_eq!(mem.len(), 2);
        let mut xs: Vec<f64> = mem.iter().map(|v| v.position().x).collect();
        xs.sort_by(f64::total_cmp);
        assert!(
            (xs[0] - 0.05).abs() < 1e-3,
            "mean of the dense voxel {}",
            xs[0]
        );
        assert!((xs[1] - 0.55).abs() < 1e-6);
    }

    #[test]
    fn the_current_view_pulls_the_mean_by_its_weight() {
        let mut mem = VoxelMemory::new(1.0, 10);
        mem.insert(&[Vec3::new(0.2, 0.5, 0.5)], 0, 1.0);
        mem.insert(&[Vec3::new(0.6, 0.5, 0.5)], 1, 0.75);
        let v = *mem.iter().next().unwrap();
        assert!((v.position().x - 0.5).abs() < 1e-6);
        assert_eq!((v.hits, v.last_seen), (2, 1));
    }

    #[test]
    fn the_cap_drops_the_least_recently_seen() {
        let mut mem = VoxelMemory::new(1.0, 100);
        for f in 0..50u32 {
            let pts: Vec<Vec3> = (0..10)
                .map(|i| Vec3::new(f64::from(f) * 10.0 + f64::from(i) + 0.5, 0.5, 0.5))
                .collect();
            mem.insert(&pts, f, 1.0);
            assert!(mem.len() <= 100);
        }
        let oldest = mem.iter().map(|v| v.last_seen).min().unwrap();
        assert!(oldest >= 40, "oldest kept frame {oldest}");
        assert!(mem.bytes() < 100 * 64 * 4);
    }

    #[test]
    fn contradicted_voxels_are_forgotten_after_the_given_frames() {
        let mut mem = VoxelMemory::new(1.0, 100);
        mem.insert(
            &[Vec3::new(0.5, 0.5, 0.5), Vec3::new(5.5, 0.5, 0.5)],
            0,
            1.0,
        );
        let through = |v: &Voxel| Some(v.position().x < 1.0);
        assert_eq!(mem.contradict(1, 2, through), (2, 1));
        assert_eq!(mem.len(), 2);
        assert_eq!(mem.contradict(2, 2, through), (2, 1));
        assert_eq!(mem.len(), 1);
        // A voxel hit in the frame itself is never tested.
        mem.insert(&[Vec3::new(0.5, 0.5, 0.5)], 3, 1.0);
        assert_eq!(mem.contradict(3, 1, |_| Some(true)), (1, 1));
        assert_eq!(mem.len(), 1);
    }

    /// The confirmed voxels' x coordinates (cell index), sorted.
    fn confirmed_x(mem: &VoxelMemory, frame: u32, min_hits: u16) -> Vec<i64> {
        let mut x: Vec<i64> = mem
            .confirmed(frame, min_hits)
            .map(|v| v.position().x.floor() as i64)
            .collect();
        x.sort_unstable();
        x
    }

    #[test]
    fn a_voxel_hit_once_counts_in_its_frame_and_next_to_a_confirmed_one() {
        let mut mem = VoxelMemory::new(1.0, 100);
        let at = |x: f64| Vec3::new(x, 0.5, 0.5);
        // Frame 0: a surface voxel at x = 0 and a stray return at x = 5.
        mem.insert(&[at(0.5), at(5.5)], 0, 1.0);
        assert_eq!(confirmed_x(&mem, 0, 2), vec![0, 5]);
        // Frame 1: the surface again, its fringe at x = 1, another stray at x = 9.
        mem.insert(&[at(0.5), at(1.5), at(9.5)], 1, 1.0);
        assert_eq!(confirmed_x(&mem, 1, 2), vec![0, 1, 9]);
        // Frame 2 hits the surface only: the stray returns no longer count,
        // the fringe does (it touches the surface voxel hit twice).
        mem.insert(&[at(0.5)], 2, 1.0);
        assert_eq!(confirmed_x(&mem, 2, 2), vec![0, 1]);
        // The unconfirmed ones stay in memory.
        assert_eq!(mem.len(), 4);
    }
}
