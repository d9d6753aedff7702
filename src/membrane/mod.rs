//! The Separability Membrane (paper §III-D to §III-F): reconstruct a
//! watertight mesh of one object from its raw points.
//!
//! A closed cubic B-spline surface (paper Eq. 10, [`crate::spline`]) starts
//! around the object (the "3D octagon" of §III-E, [`init`]) and evolves:
//!
//! 1. sample the surface at `u_n × v_n` with `div_n = max(div_min, α(q−1)+1)` (Eq. 14);
//! 2. at each sample, slide the boundary of a cuboid search region along the
//!    outward normal and take the position of maximum point separability η*
//!    (Eq. 7, or the weighted Eq. 9) — the external energy `E_sep = −η*`
//!    (Eqs. 11–12);
//! 3. move the sample by `β` times its (robustly centred) shift;
//! 4. refit the control net by least squares;
//! 5. track the global separability `η_g` (mean of the per-sample η*) and stop
//!    on a plateau, at the iteration cap, or when the caller's [`Budget`] runs out.
//!
//! Dynamic membrane adjustment (§III-F) grows the control grid (8×5 → 40×25 by
//! default) whenever `Δη_g < g_min`. On top of the paper's recipe this
//! implementation adds the mechanisms that decided the outcome in the
//! prototype (see `notes/prototype-findings.md`): a k-NN outlier filter, δ as
//! a robust k-NN distance (the median of d_i, Eq. 5, for a single view;
//! 1.3 × their lower quartile for a whole object), the
//! "inner side denser" rule, a dense-side
//! significance test, a robust median shift, a 3×3 median filter of shifts,
//! a roughness-penalised fit, a shrinking search depth with a δ floor, and an
//! inward force gated by an occupancy inside/outside grid ([`occupancy`]).
//!
//! The membrane is a sphere topologically, and where its poles sit decides
//! how it meets a tunnel or a deep cavity: with the poles in a torus's hole
//! the two hole caps stall apart, while from the side the ring is wrapped
//! closely. A cold whole object whose membrane leaves data-free parts (less
//! than `pole_axis_support` of its mesh vertices near a point) is therefore
//! reconstructed along up to `pole_axis_candidates` pole axes (the
//! configured one, then the most different bounding-box edge), and the
//! result with the highest final `η_g` × point coverage is kept
//! ([`reconstruct`]).

pub mod config;
pub mod evolve;
pub mod extract;
pub mod init;
pub mod occupancy;
pub mod view;

pub use config::{AttributeWeight, MembraneConfig, PoleAxis};
pub use extract::{extract_mesh, SEPARABILITY_CHANNEL};

use crate::cloud::{CloudError, PointCloud, Vec3};
use crate::mesh::TriMesh;
use crate::metrics::nearest;
use crate::spline::{ClosedSurface, SplineError};
use serde::Serialize;
use std::time::{Duration, Instant};
use thiserror::Error;

/// Errors of the membrane.
#[derive(Debug, Error)]
pub enum MembraneError {
    /// The input cloud is unusable (empty, too few points, flat).
    #[error("membrane input: {0}")]
    Cloud(#[from] CloudError),
    /// The density estimate failed.
    #[error("membrane density: {0}")]
    Density(#[from] crate::density::DensityError),
    /// The spatial index could not be built.
    #[error("membrane spatial index: {0}")]
    Index(#[from] crate::separability::grid::GridError),
    /// The search primitive rejected its parameters.
    #[error("membrane search: {0}")]
    Search(#[from] crate::separability::search::SearchError),
    /// The spline surface or its fit failed.
    #[error("membrane surface: {0}")]
    Spline(#[from] SplineError),
    /// A configuration value is out of range.
    #[error("membrane config: `{key}` {problem}")]
    Config {
        /// Parameter name.
        key: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// An attribute named in the config is not carried by the cloud.
    #[error("membrane: attribute `{0}` named in membrane.attributes is not in the input cloud")]
    MissingAttribute(String),
    /// The worker thread pool could not be created.
    #[error("membrane: cannot create a thread pool: {0}")]
    ThreadPool(String),
}

/// What the caller allows one reconstruction to spend.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Budget {
    /// At most this many iterations (in addition to the config's cap).
    pub max_iterations: Option<usize>,
    /// Stop starting iterations that would end after this instant.
    pub deadline: Option<Instant>,
    /// Run at least this many iterations even past the deadline (the
    /// iteration caps still apply). Default 0.
    pub min_iterations: usize,
}

impl Budget {
    /// No limit beyond the configuration's own iteration cap.
    pub fn unlimited() -> Self {
        Self::default()
    }

    /// At most `n` iterations.
    pub fn iterations(n: usize) -> Self {
        Self {
            max_iterations: Some(n),
            deadline: None,
            min_iterations: 0,
        }
    }

    /// A wall-clock budget of `d` from now.
    pub fn within(d: Duration) -> Self {
        Self {
            max_iterations: None,
            deadline: Some(Instant::now() + d),
            min_iterations: 0,
        }
    }
}

/// A previous surface to start from (the node's frame-to-frame warm start).
#[derive(Debug, Clone, PartialEq)]
pub struct WarmStart {
    /// The surface to continue from (its grid size is kept).
    pub surface: ClosedSurface,
    /// Which checkerboard half of the samples the first iteration searches
    /// when `membrane.sparse_warm_search` is on (its parity; consecutive
    /// frames pass consecutive values so both halves take turns).
    pub phase: usize,
}

/// Why the evolution stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// η_g reached a plateau on the final grid.
    Converged,
    /// The configuration's `max_iterations` was reached.
    MaxIterations,
    /// The caller's iteration budget was used up.
    IterationBudget,
    /// The caller's deadline would have been passed by another iteration.
    Deadline,
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Converged => "converged",
            Self::MaxIterations => "max_iterations",
            Self::IterationBudget => "iteration_budget",
            Self::Deadline => "deadline",
        })
    }
}

/// Wall-clock time per phase, in milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct PhaseTimes {
    /// Subsample, outlier filter, density, spatial index, occupancy grid.
    pub prepare_ms: f64,
    /// Initial surface (octagon fit or warm start).
    pub init_ms: f64,
    /// Per-sample separability searches (all iterations).
    pub search_ms: f64,
    /// Least-squares refits, factorisations and regrids.
    pub fit_ms: f64,
    /// Final scoring pass and mesh extraction.
    pub mesh_ms: f64,
    /// Evolutions along other pole axes that were tried and not kept
    /// (`pole_axis_candidates`; they share the preparation).
    pub other_axes_ms: f64,
    /// Everything.
    pub total_ms: f64,
}

/// What one reconstruction did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Points in the input.
    pub points_in: usize,
    /// Points dropped as NaN/inf.
    pub points_non_finite: usize,
    /// Exact repeats of an earlier point, dropped.
    pub points_duplicate: usize,
    /// Points left out by the `max_points` subsample.
    pub points_thinned: usize,
    /// Points dropped by the k-NN outlier filter.
    pub points_outliers: usize,
    /// Points the membrane used (including the completion points).
    pub points_used: usize,
    /// Mirror points completing the unseen side of a single view (0 without a viewpoint).
    pub points_completed: usize,
    /// The viewpoint used (given or detected), if any.
    pub viewpoint: Option<[f64; 3]>,
    /// Global point spacing δ in input units: the median k-NN distance d_i
    /// for a single view, `delta_scale` × the `delta_quantile` of the d_i
    /// for a whole object.
    pub delta: f64,
    /// Object size (longest bounding-box edge of the used points) in input units.
    pub scale: f64,
    /// Final control grid `[M, L]`.
    pub grid: [usize; 2],
    /// Final sample grid `[u_n, v_n]` (also the mesh resolution).
    pub samples: [usize; 2],
    /// Iterations run.
    pub iterations: usize,
    /// η_g of the surface at the start of each iteration.
    pub eta: Vec<f64>,
    /// Control grid of each iteration.
    pub grids: Vec<[usize; 2]>,
    /// Wall-clock duration of each iteration (ms).
    pub iteration_ms: Vec<f64>,
    /// η_g of the returned surface: the mean of its per-vertex separability
    /// (the last iteration's search, whose refit is the returned surface, or
    /// a fresh search when the grid grew after it).
    pub eta_final: f64,
    /// Why the evolution stopped.
    pub stop: StopReason,
    /// Whether it started from a warm start.
    pub warm: bool,
    /// Coordinate axis (0 = x, 1 = y, 2 = z) of the initial surface's poles
    /// (for a warm start, the axis nearest the line through its poles).
    pub pole_axis: usize,
    /// Pole axes tried (`pole_axis_candidates`; 1 when only one ran).
    pub pole_axes_tried: usize,
    /// Time per phase.
    pub times: PhaseTimes,
}

/// The result of [`reconstruct`].
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// Watertight, outward-oriented mesh with a per-vertex `separability` channel.
    pub mesh: TriMesh,
    /// The final surface (pass it back as a [`WarmStart`] for the next frame).
    pub surface: ClosedSurface,
    /// What happened.
    pub report: Report,
}

impl Reconstruction {
    /// A warm start for the next reconstruction of the same object.
    pub fn warm_start(&self) -> WarmStart {
        WarmStart {
            surface: self.surface.clone(),
            phase: self.report.iterations,
        }
    }
}

/// Reconstruct a watertight mesh of the object whose points are `cloud`.
///
/// # Errors
/// [`MembraneError`] for an unusable cloud (empty, too few points, flat), an
/// invalid configuration, or a missing attribute in weighted mode.
pub fn reconstruct(
    cloud: &PointCloud,
    cfg: &MembraneConfig,
    budget: &Budget,
    warm: Option<&WarmStart>,
) -> Result<Reconstruction, MembraneError> {
    evolve::validate(cfg)?;
    if cfg.threads == 0 {
        return select_pole_axis(cloud, cfg, budget, warm);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| MembraneError::ThreadPool(e.to_string()))?;
    pool.install(|| select_pole_axis(cloud, cfg, budget, warm))
}

/// The evolution along the configured pole axis and, for a cold whole
/// object with an automatic axis (`shortest`/`longest`) whose first
/// reconstruction has a [`support`] below `pole_axis_support`, along up to
/// `pole_axis_candidates − 1` other axes, the most different bounding-box
/// edge first. The reconstruction with the highest [`selection_score`] is
/// kept.
fn select_pole_axis(
    cloud: &PointCloud,
    cfg: &MembraneConfig,
    budget: &Budget,
    warm: Option<&WarmStart>,
) -> Result<Reconstruction, MembraneError> {
    let t0 = Instant::now();
    let prep = evolve::prepare(cloud, cfg)?;
    let first = evolve::evolve(&prep, cfg, budget, warm, None)?;
    let within_budget = |r: &Reconstruction| {
        matches!(
            r.report.stop,
            StopReason::Converged | StopReason::MaxIterations
        )
    };
    let farthest_first = match cfg.pole_axis {
        PoleAxis::Shortest => true,
        PoleAxis::Longest => false,
        PoleAxis::X | PoleAxis::Y | PoleAxis::Z => return Ok(first),
    };
    if cfg.pole_axis_candidates <= 1
        || warm.is_some()
        || prep.is_single_view()
        || !within_budget(&first)
    {
        return Ok(first);
    }
    // A membrane lying on the data everywhere has nothing to gain from
    // another axis; one spanning a hole or a cavity opening has.
    if support(&first, &prep.points) >= cfg.pole_axis_support {
        return Ok(first);
    }
    let (lo, hi) = init::quantile_bounds(&prep.points, cfg.init_quantile);
    let extent = hi - lo;
    let mut others: Vec<usize> = (0..3).filter(|&a| a != first.report.pole_axis).collect();
    others.sort_by(|&a, &b| extent[a].total_cmp(&extent[b]));
    if farthest_first {
        others.reverse();
    }
    others.truncate(cfg.pole_axis_candidates - 1);
    let mut best_score = selection_score(&first, &prep.points);
    let mut best = first;
    let mut tried = 1;
    let mut discarded_ms = 0.0;
    for axis in others {
        let t = Instant::now();
        tried += 1;
        // A failure along another axis keeps what we have; so does a run
        // cut short by the deadline (its score is not comparable).
        match evolve::evolve(&prep, cfg, budget, None, Some(axis)) {
            Ok(rec) if within_budget(&rec) => {
                let score = selection_score(&rec, &prep.points);
                if score > best_score {
                    discarded_ms += best.report.times.total_ms - prep.prepare_ms;
                    best_score = score;
                    best = rec;
                } else {
                    discarded_ms += t.elapsed().as_secs_f64() * 1e3;
                }
            }
            _ => discarded_ms += t.elapsed().as_secs_f64() * 1e3,
        }
    }
    best.report.pole_axes_tried = tried;
    best.report.times.other_axes_ms = discarded_ms;
    best.report.times.total_ms = t0.elapsed().as_secs_f64() * 1e3;
    Ok(best)
}

/// Mean edge length of a mesh: the tolerance of [`support`] and
/// [`selection_score`].
fn mean_edge(mesh: &TriMesh) -> f64 {
    let v = &mesh.vertices;
    mesh.triangles
        .iter()
        .map(|t| (v[t[0] as usize] - v[t[1] as usize]).norm())
        .sum::<f64>()
        / mesh.triangles.len().max(1) as f64
}

/// Share of the mesh's vertices within one mean mesh edge of a used point:
/// below 1 where the membrane spans space without data, such as a torus's
/// hole or a cup's opening.
fn support(rec: &Reconstruction, points: &[Vec3]) -> f64 {
    let v = &rec.mesh.vertices;
    if v.is_empty() || points.is_empty() {
        return 0.0;
    }
    let tol = mean_edge(&rec.mesh);
    let near = nearest(points, v).iter().filter(|(d, _)| *d <= tol).count();
    near as f64 / v.len() as f64
}

/// Points at most this many of whose are checked by [`selection_score`].
const COVERAGE_QUERIES: usize = 5000;

/// Score of a reconstruction for the pole-axis selection: its final η_g
/// times its *coverage*, the share of the used points (after the outlier
/// filter; at most [`COVERAGE_QUERIES`], evenly strided) within one mean
/// mesh edge of a mesh vertex. η_g alone rewards a membrane that lies well on the parts it
/// reaches, even when it slipped inside a thin tube and left the rest of the
/// surface uncovered; coverage alone ignores how well it separates.
fn selection_score(rec: &Reconstruction, points: &[Vec3]) -> f64 {
    if rec.mesh.vertices.is_empty() || points.is_empty() || rec.mesh.triangles.is_empty() {
        return 0.0;
    }
    let tol = mean_edge(&rec.mesh);
    let step = points.len().div_ceil(COVERAGE_QUERIES).max(1);
    let queries: Vec<Vec3> = points.iter().step_by(step).copied().collect();
    let hit = nearest(&rec.mesh.vertices, &queries)
        .iter()
        .filter(|(d, _)| *d <= tol)
        .count();
    rec.report.eta_final * hit as f64 / queries.len() as f64
}
