//! The background rebuild (`pipeline.rebuild`): a cold membrane on the
//! fused model, run off the frame path, whose surface a later warm frame
//! starts from instead of the warm chain's.
//!
//! The warm chain's shape, not its tracking, limits it: on the 39
//! sensor-true sequences of `benches/robot_view_eval.sh`, a cold membrane on
//! the fused model forced on every frame raised the median last-third F of
//! the 15 tuned sequences 0.721 -> 0.796 (8 held out: 0.591 -> 0.643), at
//! the cost of a cold start (about 30 iterations, 60-170 ms on one core)
//! per frame. A warm surface keeps the pole axis, grid and folds of its
//! first cold start; four iterations a frame on the fused model do not
//! undo them, and more warm iterations did not either.
//!
//! Here the cold membrane runs on a worker pool of its own
//! ([`Workers`], `workers` threads shared by every stream of the node), on
//! a copy of the model in the object's frame, after the frame's outputs are
//! made. The first warm frame at least `lag_frames` later starts from its
//! surface, moved by the tracked pose, and runs the usual warm iterations
//! on the fused points of that frame; then the next rebuild starts. A frame
//! never waits for a rebuild when it has a deadline: the live node adopts
//! one when it is done, so on a busy machine rebuilds come less often.
//! Without a deadline (`sepmem replay`, deterministic) the frame waits, so
//! every run adopts the same rebuilds. A rebuild no frame waits for runs at
//! the lowest CPU priority; one a frame will wait for runs at the process's
//! own, on a second pool ([`Urgency`]): at the lowest, a replay under two
//! busy loops took a median 7.5 s instead of 4.5 s (3.0 s idle), with its
//! frames waiting behind the other processes. A machine with no idle time
//! starves the lowest priority: a rebuild still not done `starved_frames`
//! after it was due restarts on the stream's newer model on a third pool,
//! at [`STARVED_NICE`] ([`Pending::is_starved`]). Without that, two
//! `sepmem replay --realtime` on two cores (one thread each) adopted
//! hardly a rebuild: the 45 sequences' median last-third F fell from 0.891
//! (no deadline) to 0.725, and to 0.859 with the escalation.
//!
//! A rebuild is adopted only when it fits the frame's points about as well
//! as the warm start does (`max_misfit`): it was made on the model of a few
//! frames before, and where that model or its cold membrane went wrong (a
//! fin, a fold), the four warm iterations do not undo it. Over the 39
//! sequences, 95 of 356 adoptions lowered the frame's F, 12 by more than
//! 0.05 (a turning bent tube: 0.826 -> 0.701, with 14 % of the visible
//! points more than 3σ outside, at a misfit 3.5× the warm start's). With
//! `max_misfit` 3 against null: that bent tube's last-third F 0.722 ->
//! 0.752 and its visible points outside 1.1 % -> 0.05 %; the median share
//! of visible points outside over the sequences 0.0056 -> 0.0047; median
//! last-third F 0.850 either way (mean 0.764 -> 0.765), the worst change
//! −0.010 (a turning box). At 2 the median share fell to 0.0035 and the
//! median F rose to 0.857, but the committed turning bent tube refused the
//! rebuilds it gained from (last-third IoU 0.784 -> 0.643); at 1.5 the
//! median F fell to 0.846.
//!
//! Re-measured on the 45 sequences once registration on the model, the
//! shape priors and the seen side's snap had landed, 2 against 3: mean
//! last-third F 0.830 -> 0.833 (6 up, 3 down, worst −0.016), the median of
//! each sequence's largest silhouette excess in earlier views 0.031 ->
//! 0.018, and the committed turning bent tube's last-third IoU 0.858 ->
//! 0.894 (F 0.837 -> 0.827). Late in a turn the warm chain has converged
//! and a cold membrane on the model often fits worse: the turning bottles'
//! rebuilds at 2.0-2.4 times the warm start's misfit cut their seen side
//! from 0.95 to 0.79-0.86 (last-third F +0.04 without them). So the
//! default is 2.
//!
//! The misfit does not see a surface in front of the points, only points
//! off the surface. A second test was tried beside it: refuse a rebuild
//! when more of its samples (64 × 32) lie where a view of the model saw
//! empty space than the warm start's, by more than 1 % of the samples.
//! The committed turning bent tube's frame-16 rebuild (misfit ratio 1.36,
//! 3.4 % of its samples seen empty against 1.1 %) started its fold of
//! frames 16-21, and refusing it raised its last-third F 0.827 -> 0.845;
//! over the 45 sequences the mean fell 0.833 -> 0.826 (7 up, 14 down; the
//! bowl -0.14), so it was not kept.
//!
//! A stream keeps at most one rebuild. A cold frame (which restarts or
//! refits the model) cancels it and starts none unless its deadline cut
//! its cold membrane short: a rebuild would repeat that membrane on the
//! same points. Two kinds of warm frame replace it by one on their own
//! model, due the next frame ([`Pending::hasten`]): a refit in the
//! background (`pipeline.refit.path`), and a frame where a shape prior's
//! completion starts or stops, whose warm surface was evolved under the
//! other prior (a turning bowl that first showed the camera its outside,
//! a ball until its rim turned into view: last-third F 0.470 -> 0.552 over
//! `benches/robot_view_eval.sh`; a turning torus +0.017, the swap -0.030,
//! no other sequence changed). The stream's end cancels it too. A
//! cancelled rebuild that has not started never runs, and one that has
//! stops before its next iteration ([`Budget::wanted`]): it no longer
//! holds a worker, at the lowest priority for seconds on a busy machine,
//! that the stream's next rebuild waits for.

use crate::cloud::{PointCloud, Vec3};
use crate::membrane::view::FreeSpace;
use crate::membrane::{Budget, ConfigError, Membrane, Start, StopReason};
use crate::model::ObjectModel;
use crate::pipeline::align::Rigid;
use crate::pipeline::Factor;
use crate::spatial::KnnIndex;
use crate::spline::ClosedSurface;
use crate::spline::Layout;
use crossbeam_channel::{Receiver, TryRecvError};
use serde::{Deserialize, Serialize};
use std::num::NonZeroUsize;
use std::sync::Arc;

/// `pipeline.rebuild` (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RebuildConfig {
    /// Frames from a rebuild's start to the first frame that may adopt it
    /// (1: the next frame).
    pub lag_frames: NonZeroUsize,
    /// Threads of each rebuild pool ([`Urgency`]), shared by every stream
    /// of a node.
    pub workers: NonZeroUsize,
    /// A rebuild whose [`misfit`] to the frame's points is more than this
    /// many times the warm start's is not adopted; `None`: always adopted.
    #[serde(default)]
    pub max_misfit: Option<Factor>,
    /// A rebuild at the lowest priority ([`Urgency::Idle`]) still not done
    /// this many frames after it was due is starved: the machine has no
    /// idle time for it. It restarts on the stream's newer model on a pool
    /// of its own at [`STARVED_NICE`] ([`Urgency::Starved`]). `None`: it
    /// waits for idle time however long that takes.
    #[serde(default)]
    pub starved_frames: Option<NonZeroUsize>,
}

impl Default for RebuildConfig {
    fn default() -> Self {
        Self {
            lag_frames: NonZeroUsize::MIN.saturating_add(2),
            workers: NonZeroUsize::MIN,
            max_misfit: Some(Factor(2.0)),
            starved_frames: NonZeroUsize::new(3),
        }
    }
}

/// The surface samples (u × v) a [`misfit`] measures against: about 8 mm
/// apart on a 20 cm object, so the distance is taken to the nearest
/// sample's tangent plane.
const MISFIT_GRID: (usize, usize) = (64, 32);

/// At most this many of the frame's points (evenly strided) are measured.
const MISFIT_POINTS: usize = 400;

/// How badly `surface` fits the frame's `points`: the mean squared distance
/// of a point to the tangent plane of its nearest surface sample, each
/// capped at `trim`²; a point farther than twice `trim` from every sample
/// counts as `trim`². `INFINITY` for a surface without a sample grid.
pub fn misfit(surface: &ClosedSurface, points: &[Vec3], trim: f64) -> f64 {
    let (u, v) = MISFIT_GRID;
    let Ok(layout) = Layout::samples(surface.m(), surface.l(), u, v) else {
        return f64::INFINITY;
    };
    let (mut pos, mut nrm) = (Vec::new(), Vec::new());
    surface.eval_grid(&layout, &mut pos, &mut nrm);
    let index = KnnIndex::new(pos);
    let cap = trim * trim;
    let stride = (points.len() / MISFIT_POINTS).max(1);
    let costs = points.iter().step_by(stride).map(|p| {
        let (d2, i) = index.nearest_one(p);
        match d2 > 4.0 * cap {
            true => cap,
            false => (p - index.points()[i]).dot(&nrm[i]).powi(2).min(cap),
        }
    });
    let (sum, n) = costs.fold((0.0, 0usize), |(s, n), c| (s + c, n + 1));
    sum / n.max(1) as f64
}

/// Whether a frame will wait for a rebuild, which decides the pool it
/// runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Urgency {
    /// No frame waits for it (frames with a deadline: the live node): it
    /// runs at the lowest CPU priority, on time the frames leave idle.
    Idle,
    /// A frame will wait for it (no deadline: `sepmem replay`, a node with
    /// `pipeline.deadline_ms` 0): it runs at the process's own priority.
    /// At the lowest, a frame would wait behind every other busy process
    /// of the machine (a priority inversion: under two busy loops the
    /// lock-step node test's frames waited seconds for their rebuilds).
    /// Also the rebuild of a frame whose view contradicted its model, with
    /// or without a deadline: the surface it replaces is the old object's
    /// (`pipeline::PathReason::Contradicted`).
    Awaited,
    /// An [`Urgency::Idle`] rebuild that the machine left no idle time for
    /// ([`RebuildConfig::starved_frames`]), run again at [`STARVED_NICE`]:
    /// between the frames' priority and the lowest.
    Starved,
}

/// The nice value of a starved rebuild's pool. Against one busy thread at
/// nice 0 it gets about a tenth of a core (the kernel's weights 110 and
/// 1024), so a rebuild of 30-100 ms lands within a few hundred ms while
/// the frames keep most of the CPU. Measured with two `sepmem replay
/// --realtime` on two cores (one thread each) over the 45 sequences of
/// `benches/robot_view_eval.sh` (no deadline: median last-third F 0.891,
/// mean 0.829), never escalated / at nice 10 / at nice 0: median F 0.725 /
/// 0.859 / 0.863, mean 0.715 / 0.780 / 0.802, volume IoU 0.810 / 0.946 /
/// 0.942; the sequences' median warm latency p50 15.8 / 16.0 / 30.8 ms,
/// p95 20.4 / 21.5 / 42.3 ms.
pub const STARVED_NICE: i32 = 10;

/// The rebuild pools: `workers` threads of their own for each
/// [`Urgency`], so a rebuild never takes a thread from the frames, and the
/// membranes they run.
#[derive(Debug, Clone)]
pub struct Workers {
    idle: Arc<rayon::ThreadPool>,
    awaited: Arc<rayon::ThreadPool>,
    starved_pool: Arc<rayon::ThreadPool>,
    lag: u64,
    /// `starved_frames`.
    starved: Option<u64>,
    /// The frames' cold and warm membranes on these pools' threads
    /// (`step.threads` 0: never the frames' own workers), sharing their
    /// fit cache.
    engines: Arc<(Membrane, Membrane)>,
}

impl Workers {
    /// The pools of `cfg` for the frames' membranes `cold` and `warm`.
    ///
    /// # Errors
    /// [`ConfigError`] naming `pipeline.rebuild.workers` when the threads
    /// cannot be started.
    pub fn new(cfg: &RebuildConfig, cold: &Membrane, warm: &Membrane) -> Result<Self, ConfigError> {
        let own = |m: &Membrane| m.variant(|c| c.step.threads = 0);
        Ok(Self {
            idle: pool(cfg.workers, Urgency::Idle)?,
            awaited: pool(cfg.workers, Urgency::Awaited)?,
            starved_pool: pool(cfg.workers, Urgency::Starved)?,
            lag: cfg.lag_frames.get() as u64,
            starved: cfg.starved_frames.map(|n| n.get() as u64),
            engines: Arc::new((own(cold)?, own(warm)?)),
        })
    }

    /// Start a cold membrane on `model`'s points in the
    /// object's frame, thinned to `max_points`, under `budget` (no deadline:
    /// it runs off the frame path), as the stream's frame `frame`, on the
    /// pool of its `urgency`, for adoption `lag_frames` later; the warm
    /// fit of its grid is then factored, so the frame that adopts it does
    /// not pay for that.
    pub fn start(
        &self,
        model: ObjectModel,
        max_points: usize,
        budget: Budget,
        frame: u64,
        urgency: Urgency,
    ) -> Pending {
        let (tx, rx) = crossbeam_channel::bounded(1);
        let alive = Arc::new(());
        // Dropping every clone of the stream's Pending stops the membrane
        // before its next iteration.
        let budget = Budget {
            wanted: Some(Arc::downgrade(&alive)),
            ..budget
        };
        let engines = Arc::clone(&self.engines);
        let pool = match urgency {
            Urgency::Idle => &self.idle,
            Urgency::Awaited => &self.awaited,
            Urgency::Starved => &self.starved_pool,
        };
        pool.spawn(move || {
            let (cold, warm) = &*engines;
            if let Some(surface) = run(cold, warm, &model, max_points, &budget) {
                // The stream may be gone; then nobody wants the surface.
                let _ = tx.send(surface);
            }
        });
        Pending {
            rx,
            _alive: alive,
            started: frame,
            ready_at: frame.saturating_add(self.lag),
            hastened: false,
            starved_after: self.starved.filter(|_| urgency == Urgency::Idle),
        }
    }
}

/// The pool of `threads` threads for rebuilds of `urgency`.
fn pool(threads: NonZeroUsize, urgency: Urgency) -> Result<Arc<rayon::ThreadPool>, ConfigError> {
    let name = match urgency {
        Urgency::Idle => "sepmem-rebuild",
        Urgency::Awaited => "sepmem-rebuild-awaited",
        Urgency::Starved => "sepmem-rebuild-starved",
    };
    let mut b = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.get())
        .thread_name(move |i| format!("{name}-{i}"))
        // A panic in a rebuild loses that rebuild (its stream sees it as
        // failed), never the process.
        .panic_handler(|_| tracing::error!("a rebuild panicked"));
    match urgency {
        Urgency::Idle => b = b.start_handler(|_| lower_priority(19)),
        Urgency::Starved => b = b.start_handler(|_| lower_priority(STARVED_NICE)),
        Urgency::Awaited => {}
    }
    b.build()
        .map(Arc::new)
        .map_err(|e| ConfigError::new("pipeline.rebuild.workers", format!("no threads: {e}")))
}

/// Lower the calling thread's CPU priority to `nice` (Linux only; 19, the
/// lowest, so that rebuilds take only CPU time that frames, the transport
/// and the rest of the robot leave idle). Best effort: without it the pool
/// still holds at most `workers` threads.
fn lower_priority(nice: i32) {
    #[cfg(target_os = "linux")]
    if let Err(e) = rustix::process::setpriority_process(Some(rustix::thread::gettid()), nice) {
        tracing::debug!("rebuild thread keeps its priority: {e}");
    }
    #[cfg(not(target_os = "linux"))]
    let _ = nice;
}

/// The rebuild itself, on the `cold` membrane, then the `warm` one's fit
/// factored; `None` when it was cancelled before it started or the
/// membrane failed on the model's points.
fn run(
    cold: &Membrane,
    warm: &Membrane,
    model: &ObjectModel,
    max_points: usize,
    budget: &Budget,
) -> Option<ClosedSurface> {
    if !budget.is_wanted() {
        return None;
    }
    let object = Rigid::identity();
    let points = PointCloud::from_points(model.points_in(&object));
    let points = points.thinned(max_points, 0);
    let carving = model.free_space(&object);
    let free: &dyn FreeSpace = &carving;
    match cold.reconstruct_seen(&points, budget, &Start::Cold, Some(free)) {
        Ok(rec) if rec.report.stop == StopReason::Cancelled || !budget.is_wanted() => None,
        Ok(rec) => {
            let [m, l] = rec.report.grid;
            if let Err(e) = warm.prefactor_warm(m, l) {
                tracing::debug!("rebuild's warm fit not prepared: {e}");
            }
            Some(rec.surface)
        }
        Err(e) => {
            tracing::debug!("rebuild failed: {e}");
            None
        }
    }
}

/// A stream's rebuild in flight: dropping it cancels it.
#[derive(Debug, Clone)]
pub struct Pending {
    rx: Receiver<ClosedSurface>,
    /// The rebuild runs only while some clone of this is alive.
    _alive: Arc<()>,
    started: u64,
    ready_at: u64,
    /// [`Pending::hasten`] made it due sooner.
    hastened: bool,
    /// Frames after `ready_at` from which it is starved
    /// ([`RebuildConfig::starved_frames`]; only at the lowest priority).
    starved_after: Option<u64>,
}

/// What a frame gets from a stream's rebuild.
#[derive(Debug)]
pub enum Adopt {
    /// Not yet: too early, or (with a deadline) not done.
    NotYet,
    /// Done: its surface in the object's frame.
    Surface(ClosedSurface),
    /// It failed or was lost: start another.
    Failed,
}

impl Pending {
    /// The stream's frame it started after.
    pub fn started(&self) -> u64 {
        self.started
    }

    /// Make it due by the stream's frame `frame` at the latest.
    pub fn hasten(&mut self, frame: u64) {
        self.ready_at = self.ready_at.min(frame);
        self.hastened = true;
    }

    /// Whether [`Self::hasten`] made it due sooner.
    pub fn is_hastened(&self) -> bool {
        self.hastened
    }

    /// Whether it runs at the lowest priority and is still not done
    /// `starved_frames` after it was due, by the stream's frame `frame`.
    pub fn is_starved(&self, frame: u64) -> bool {
        let starved = |n: u64| frame >= self.ready_at.saturating_add(n);
        self.starved_after.is_some_and(starved) && self.rx.is_empty()
    }

    /// Whether `lag_frames` have passed by the stream's frame `frame`.
    pub fn is_due(&self, frame: u64) -> bool {
        frame >= self.ready_at
    }

    /// The rebuild's surface for the stream's frame `frame`, once
    /// `lag_frames` have passed: waiting for it when `wait` (a frame
    /// without a deadline), else only when it is done.
    pub fn adopt(&self, frame: u64, wait: bool) -> Adopt {
        if !self.is_due(frame) {
            return Adopt::NotYet;
        }
        let got = if wait {
            self.rx.recv().map_err(|_| TryRecvError::Disconnected)
        } else {
            self.rx.try_recv()
        };
        match got {
            Ok(surface) => Adopt::Surface(surface),
            Err(TryRecvError::Empty) => Adopt::NotYet,
            Err(TryRecvError::Disconnected) => Adopt::Failed,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;
    use crate::cloud::Vec3;
    use crate::membrane::MembraneConfig;
    use crate::model::{ModelConfig, ObjectModel};
    use crate::pipeline::{Membranes, PipelineConfig};
    use std::time::{Duration, Instant};

    /// A model of a sphere of radius 0.1 m at 1 m (all of it, as if seen
    /// from all around).
    fn sphere_model() -> ObjectModel {
        let centre = Vec3::new(0.0, 0.0, 1.0);
        let n = 3000;
        let points: Vec<Vec3> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                let r = (1.0 - z * z).sqrt();
                Vec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .map(|d| centre + 0.1 * d)
            .collect();
        let mut model = ObjectModel::new(ModelConfig::default(), 0.2);
        model.integrate(&points, &Rigid::identity());
        model
    }

    fn membranes() -> Membranes {
        Membranes::new(&MembraneConfig::default(), &PipelineConfig::default()).unwrap()
    }

    /// A rebuild of [`sphere_model`] as the stream's frame `frame`.
    fn sphere_rebuild(workers: &Workers, frame: u64, urgency: Urgency) -> Pending {
        workers.start(sphere_model(), 2500, Budget::iterations(40), frame, urgency)
    }

    #[test]
    fn a_rebuild_is_adopted_after_its_lag_and_wraps_the_model() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().expect("on by default");
        let pending = sphere_rebuild(workers, 10, Urgency::Awaited);
        // Lag 3 (the default): frames 11 and 12 may not adopt it, even waiting.
        assert!(matches!(pending.adopt(11, true), Adopt::NotYet));
        assert!(matches!(pending.adopt(12, true), Adopt::NotYet));
        let Adopt::Surface(surface) = pending.adopt(13, true) else {
            panic!("no surface at frame 13")
        };
        // The surface wraps the sphere: its points lie near it.
        let centre = Vec3::new(0.0, 0.0, 1.0);
        let near = (0..20)
            .flat_map(|i| (1..10).map(move |j| (i as f64 / 20.0, j as f64 / 10.0)))
            .filter(|&(u, v)| ((surface.eval(u, v).p - centre).norm() - 0.1).abs() < 0.01)
            .count();
        assert!(near >= 162, "{near} of 180 surface points within 1 cm");
        // Taken: nothing more comes (waiting: until its worker let go of it).
        assert!(matches!(pending.adopt(14, true), Adopt::Failed));
    }

    #[test]
    fn a_surfaces_misfit_grows_as_it_leaves_the_frames_points() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().expect("on by default");
        let Adopt::Surface(surface) = sphere_rebuild(workers, 0, Urgency::Awaited).adopt(3, true)
        else {
            panic!("no surface")
        };
        let points = sphere_model().points_in(&Rigid::identity());
        let trim = 0.03 * 0.2;
        let on = misfit(&surface, &points, trim);
        let moved = |d: f64| {
            let mut s = surface.clone();
            s.translate(&Vec3::new(d, 0.0, 0.0));
            misfit(&s, &points, trim)
        };
        // On the points: well within the trim; 4 mm off: several times
        // more; far away: every point counts the trim.
        assert!(on < 0.1 * trim * trim, "{on}");
        assert!(moved(0.004) > 3.0 * on, "{} vs {on}", moved(0.004));
        assert!((moved(0.5) - trim * trim).abs() < 1e-12);
    }

    #[test]
    fn a_hastened_rebuild_is_due_by_the_frame_it_names() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().unwrap();
        let mut pending = sphere_rebuild(workers, 10, Urgency::Awaited);
        assert!(!pending.is_hastened() && !pending.is_due(11));
        pending.hasten(11);
        assert!(pending.is_hastened() && pending.is_due(11));
        // Never later than it was.
        pending.hasten(20);
        assert!(pending.is_due(11));
        assert!(matches!(pending.adopt(11, true), Adopt::Surface(_)));
    }

    #[test]
    fn a_dropped_rebuild_that_has_not_started_never_runs() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().unwrap();
        // The one worker is kept busy by the first rebuild; the second,
        // queued behind it, is dropped before it starts.
        let busy = sphere_rebuild(workers, 0, Urgency::Idle);
        let dropped = sphere_rebuild(workers, 0, Urgency::Idle);
        let rx = dropped.rx.clone();
        drop(dropped);
        assert!(matches!(busy.adopt(3, true), Adopt::Surface(_)));
        // The dropped rebuild's sender went without sending.
        assert!(rx.recv().is_err());
    }

    #[test]
    fn a_dropped_rebuild_stops_before_its_next_iteration() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().unwrap();
        let (cold, warm) = &*workers.engines;
        let owner = Arc::new(());
        let budget = Budget {
            wanted: Some(Arc::downgrade(&owner)),
            ..Budget::iterations(40)
        };
        let model = sphere_model();
        assert!(run(cold, warm, &model, 2500, &budget).is_some());
        drop(owner);
        assert!(run(cold, warm, &model, 2500, &budget).is_none());
        // The membrane itself stops before an iteration nobody wants.
        let points = PointCloud::from_points(model.points_in(&Rigid::identity()));
        let rec = cold.reconstruct(&points, &budget, &Start::Cold).unwrap();
        assert_eq!(rec.report.stop, StopReason::Cancelled);
        assert_eq!(rec.report.iterations, 0);
    }

    #[test]
    fn a_rebuild_left_no_idle_time_is_starved_after_starved_frames() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().unwrap();
        // The idle pool's one worker held until the test lets it go: the
        // machine has no idle time.
        let (release, held) = crossbeam_channel::bounded::<()>(0);
        workers.idle.spawn(move || {
            let _ = held.recv();
        });
        let idle = sphere_rebuild(workers, 0, Urgency::Idle);
        let awaited = sphere_rebuild(workers, 0, Urgency::Awaited);
        // Due at frame 3 (lag 3), starved from frame 6 (starved_frames 3).
        assert!(!idle.is_starved(5));
        assert!(idle.is_starved(6));
        // A rebuild a frame waits for runs at the process's own priority
        // and is never starved.
        assert!(!awaited.is_starved(100));
        // Once done, it is not starved however late.
        release.send(()).unwrap();
        let start = Instant::now();
        while idle.rx.is_empty() && start.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(!idle.is_starved(100));
        assert!(matches!(idle.adopt(100, false), Adopt::Surface(_)));
    }

    #[test]
    fn a_frame_that_restarts_a_starved_rebuild_says_so() {
        // The committed turning capsule, each frame with a deadline (a
        // minute away: it never waits for its rebuild), the idle pool held.
        let cfg = crate::config::Config::load(None, &[]).unwrap();
        let membranes = Membranes::new(&cfg.membrane, &cfg.pipeline).unwrap();
        let workers = membranes.rebuild.as_ref().unwrap();
        let (release, held) = crossbeam_channel::bounded::<()>(0);
        workers.idle.spawn(move || {
            let _ = held.recv();
        });
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/bags/robot_view/turn_capsule.mcap"
        );
        let topic = "/synth/capsule/points";
        let bag = crate::bag::Bag::open(std::path::Path::new(path)).unwrap();
        let mut tracker = crate::pipeline::Tracker::new(crate::pipeline::StreamKey::topic(topic));
        let mut flagged = Vec::new();
        for m in bag.read(&[topic]).unwrap().iter().take(12) {
            let sample =
                crate::pipeline::engine::decode_sample(topic, &m.data, &cfg.wire, &cfg.pipeline)
                    .unwrap();
            let before = tracker.rebuild_started();
            let deadlines = crate::pipeline::Deadlines::after(Instant::now(), 6e4, 6e4);
            let r = (tracker.process_by(
                &sample.streams[0].cloud,
                &membranes,
                &cfg.pipeline,
                deadlines,
            ))
            .unwrap();
            if r.rebuild_starved {
                // Restarted by this frame, at least lag + starved_frames
                // after the rebuild it replaced started.
                assert_eq!(tracker.rebuild_started(), Some(r.frame));
                assert!(r.frame >= before.unwrap() + workers.lag + workers.starved.unwrap());
                flagged.push(r.frame);
            }
        }
        release.send(()).unwrap();
        // The first warm frame's rebuild (frame 1, due at 4) starved at 7.
        assert_eq!(flagged.first(), Some(&7), "{flagged:?}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn only_rebuilds_no_frame_waits_for_run_at_the_lowest_priority() {
        let membranes = membranes();
        let workers = membranes.rebuild.as_ref().unwrap();
        let nice = || rustix::process::getpriority_process(Some(rustix::thread::gettid())).unwrap();
        let own = nice();
        assert_eq!(workers.idle.install(nice), 19.max(own));
        assert_eq!(workers.starved_pool.install(nice), STARVED_NICE.max(own));
        assert_eq!(workers.awaited.install(nice), own);
    }
}
