//! The Separability Membrane (paper §III-D to §III-F): reconstruct a
//! watertight mesh of one object from its raw points.
//!
//! A closed cubic B-spline surface (paper Eq. 10, [`crate::spline`]) starts
//! around the object (the "3D octagon" of §III-E, [`init`]) and evolves
//! ([`evolve`], one module per step):
//!
//! 1. sample the surface at `u_n × v_n` with `div_n = max(div_min, α(q−1)+1)`
//!    (Eq. 14, [`fit::sample_counts`]);
//! 2. at each sample, slide the boundary of a cuboid search region along the
//!    outward normal and take the position of maximum point separability η*
//!    (Eq. 7, or the weighted Eq. 9) — the external energy `E_sep = −η*`
//!    (Eqs. 11–12) — and turn it into a shift ([`step`]);
//! 3. regularise the shifts ([`regularize`]) and move each sample by `β`
//!    times its shift;
//! 4. refit the control net by least squares ([`fit`]);
//! 5. track the global separability `η_g` (mean of the per-sample η*); grow
//!    the control grid when it stops gaining (dynamic membrane adjustment,
//!    §III-F), and stop on a plateau, at the iteration cap, or when the
//!    caller's [`Budget`] runs out ([`schedule`]).
//!
//! Before the loop, [`prepare`] thins the points, filters outliers and
//! measures the spacing δ (Eq. 5); a cold whole object may be evolved along
//! several pole axes ([`pole`]); [`extract`] turns the final surface into a
//! mesh. On top of the paper's recipe this implementation adds the
//! mechanisms that decided the outcome in the prototype (see
//! `../shared/notes/prototype-findings.md`); each module's doc names the measurement
//! behind its mechanisms.
//!
//! [`Membrane`] is the engine: built once from a validated configuration, it
//! owns the fit cache and is shared by every reconstruction.

pub mod config;
pub mod enclose;
pub mod evolve;
pub mod extract;
pub mod fit;
pub mod init;
pub mod occupancy;
pub mod pole;
pub mod prepare;
pub mod regularize;
pub mod revolution;
pub mod schedule;
pub mod solid;
pub mod spacing;
pub mod sphere;
pub mod step;
pub mod unbias;
pub mod view;

pub use config::{
    AttributeWeight, Completion, ConfigError, EncloseConfig, FitConfig, FusedCompletionConfig,
    GrowthConfig, InitConfig, InsideDenserConfig, InwardConfig, LocalSpacingConfig, MembraneConfig,
    PoleAxis, PoleTensionConfig, PrepareConfig, RegularizeConfig, RevolutionConfig, ScheduleConfig,
    SearchDelta, SphereConfig, StepConfig, ViewConfig,
};
pub use extract::{extract_mesh, SEPARABILITY_CHANNEL};

use crate::cloud::{CloudError, PointCloud, Vec3};
use crate::mesh::TriMesh;
use crate::spline::{ClosedSurface, SplineError};
use fit::FitCache;
use serde::Serialize;
use std::sync::{Arc, Weak};
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
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An attribute named in the config is not carried by the cloud.
    #[error(
        "membrane: attribute `{0}` named in membrane.step.attributes is not in the input cloud"
    )]
    MissingAttribute(String),
    /// An internal invariant did not hold (a bug, reported instead of a panic).
    #[error("membrane internal error: {0}")]
    Internal(&'static str),
}

/// What the caller allows one reconstruction to spend.
#[derive(Debug, Clone, Default)]
pub struct Budget {
    /// At most this many iterations (in addition to the config's cap).
    pub max_iterations: Option<usize>,
    /// Stop starting iterations that would end after this instant.
    pub deadline: Option<Instant>,
    /// Run at least this many iterations even past the deadline (the
    /// iteration caps still apply). Default 0.
    pub min_iterations: usize,
    /// Stop before the next iteration once every owner of the matching
    /// [`Arc`] is gone: nobody wants the result any more
    /// (a background rebuild its stream replaced, `pipeline::rebuild`).
    /// `None`: always wanted.
    pub wanted: Option<Weak<()>>,
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
            ..Self::default()
        }
    }

    /// A wall-clock budget of `d` from now.
    pub fn within(d: Duration) -> Self {
        Self {
            deadline: Some(Instant::now() + d),
            ..Self::default()
        }
    }

    /// Whether the caller still wants the result ([`Self::wanted`]).
    pub fn is_wanted(&self) -> bool {
        self.wanted.as_ref().is_none_or(|w| w.strong_count() > 0)
    }
}

/// A previous surface to start from (the node's frame-to-frame warm start).
#[derive(Debug, Clone, PartialEq)]
pub struct WarmStart {
    /// The surface to continue from (its grid size is kept).
    pub surface: ClosedSurface,
    /// Which checkerboard half of the samples the first iteration searches
    /// when `membrane.step.sparse_warm_search` is on (its parity; consecutive
    /// frames pass consecutive values so both halves take turns).
    pub phase: usize,
}

/// Why the evolution stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// η_g reached a plateau on the final grid.
    Converged,
    /// The configuration's `schedule.max_iterations` was reached.
    MaxIterations,
    /// The caller's iteration budget was used up.
    IterationBudget,
    /// The caller's deadline would have been passed by another iteration.
    Deadline,
    /// The caller no longer wanted the result ([`Budget::wanted`]).
    Cancelled,
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Converged => "converged",
            Self::MaxIterations => "max_iterations",
            Self::IterationBudget => "iteration_budget",
            Self::Deadline => "deadline",
            Self::Cancelled => "cancelled",
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
    /// (`init.pole_axis_candidates`; they share the preparation).
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
    /// Points left out by the `prepare.max_points` subsample.
    pub points_thinned: usize,
    /// Points dropped as detached from the object's main body
    /// (`prepare.detached`, [`crate::detached`]).
    pub points_detached: usize,
    /// Points dropped by the k-NN outlier filter.
    pub points_outliers: usize,
    /// Points the membrane used (including the completion points).
    pub points_used: usize,
    /// Mirror points completing the unseen side of a single view (0 without a viewpoint).
    pub points_completed: usize,
    /// The viewpoint used (given or detected), if any.
    pub viewpoint: Option<[f64; 3]>,
    /// Global point spacing δ in input units: the median k-NN distance d_i
    /// for a single view, `prepare.delta_scale` × the `prepare.delta_quantile` of the d_i
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
    /// Pole axes tried (`init.pole_axis_candidates`; 1 when only one ran).
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
    /// Per mesh vertex, the outward move that removes the curvature bias of
    /// the centring ([`unbias`], `step.unbias`); not applied to `mesh` (see
    /// [`Self::unbias_mesh`]); empty when off.
    pub unbias: Vec<Vec3>,
}

impl Reconstruction {
    /// Apply [`Self::unbias`] to the mesh (once: it is emptied).
    pub fn unbias_mesh(&mut self) {
        if self.unbias.len() == self.mesh.vertices.len() {
            for (v, m) in self.mesh.vertices.iter_mut().zip(&self.unbias) {
                *v += m;
            }
        }
        self.unbias.clear();
    }

    /// A warm start for the next reconstruction of the same object.
    pub fn warm_start(&self) -> WarmStart {
        WarmStart {
            surface: self.surface.clone(),
            phase: self.report.iterations,
        }
    }
}

/// How a reconstruction starts.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Start {
    /// From the octagon around the points (paper §III-E), along up to
    /// `init.pole_axis_candidates` pole axes ([`pole`]).
    #[default]
    Cold,
    /// From a previous surface (the node's frame-to-frame warm start).
    Warm(WarmStart),
}

impl Start {
    /// The warm start, if any.
    pub fn warm(&self) -> Option<&WarmStart> {
        match self {
            Self::Cold => None,
            Self::Warm(w) => Some(w),
        }
    }
}

/// The reconstruction engine: a validated configuration with the cache of
/// factored fit systems ([`fit::FitCache`]) and the worker pool, built once
/// and used for every reconstruction (clones share the cache and the pool).
#[derive(Debug, Clone)]
pub struct Membrane {
    cfg: Arc<MembraneConfig>,
    fits: Arc<FitCache>,
    /// `step.threads` workers, or `None` for rayon's global pool (`step.threads = 0`).
    pool: Option<Arc<rayon::ThreadPool>>,
}

impl Membrane {
    /// Validate `cfg` and build the engine.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first bad key (or `step.threads` when the
    /// worker pool cannot be created).
    pub fn new(cfg: MembraneConfig) -> Result<Self, ConfigError> {
        let fits = Arc::new(FitCache::new(cfg.fit.cache_mib));
        Self::with_cache(cfg, fits, None)
    }

    fn with_cache(
        cfg: MembraneConfig,
        fits: Arc<FitCache>,
        pool: Option<Arc<rayon::ThreadPool>>,
    ) -> Result<Self, ConfigError> {
        config::validate(&cfg)?;
        let pool = match (cfg.step.threads, pool) {
            (0, _) => None,
            (n, Some(p)) if p.current_num_threads() == n => Some(p),
            (n, _) => Some(Arc::new(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| {
                        ConfigError::new("step.threads", format!("no thread pool: {e}"))
                    })?,
            )),
        };
        Ok(Self {
            cfg: Arc::new(cfg),
            fits,
            pool,
        })
    }

    /// Another engine whose configuration is this one's changed by `edit`,
    /// sharing the fit cache and the pool (built once, e.g. the pipeline's
    /// warm-frame variant).
    ///
    /// # Errors
    /// [`ConfigError`] when the edited configuration is invalid.
    pub fn variant(&self, edit: impl FnOnce(&mut MembraneConfig)) -> Result<Self, ConfigError> {
        let mut cfg = (*self.cfg).clone();
        edit(&mut cfg);
        Self::with_cache(cfg, Arc::clone(&self.fits), self.pool.clone())
    }

    /// The configuration.
    pub fn config(&self) -> &MembraneConfig {
        &self.cfg
    }

    /// Reconstruct a watertight mesh of the object whose points are `cloud`,
    /// within `budget`, from `start`.
    ///
    /// # Errors
    /// [`MembraneError`] for an unusable cloud (empty, too few points,
    /// flat) or a missing attribute in weighted mode.
    pub fn reconstruct(
        &self,
        cloud: &PointCloud,
        budget: &Budget,
        start: &Start,
    ) -> Result<Reconstruction, MembraneError> {
        self.reconstruct_seen(cloud, budget, start, None)
    }

    /// [`Self::reconstruct`] of a cloud fused from several views, given
    /// the free space those views saw (`free`, in the cloud's frame): the
    /// inward force then acts only where some view saw through, as it does
    /// for a single view ([`view::FreeSpace`]). `None` is
    /// [`Self::reconstruct`].
    ///
    /// # Errors
    /// As [`Self::reconstruct`].
    pub fn reconstruct_seen(
        &self,
        cloud: &PointCloud,
        budget: &Budget,
        start: &Start,
        free: Option<&dyn view::FreeSpace>,
    ) -> Result<Reconstruction, MembraneError> {
        let run = || pole::reconstruct(cloud, &self.cfg, &self.fits, budget, start.warm(), free);
        match &self.pool {
            None => run(),
            Some(pool) => pool.install(run),
        }
    }

    /// Factor the fit system that a warm start from an `m × l` surface will
    /// use (sampled with `fit.alpha_warm`), so that the first warm frame after a
    /// cold one does not pay for it. The frame pipeline calls this at the
    /// end of a cold frame, whose budget is the longer one.
    ///
    /// # Errors
    /// [`MembraneError`] when the grid is invalid or the system is singular.
    pub fn prefactor_warm(&self, m: usize, l: usize) -> Result<(), MembraneError> {
        let alpha = self.cfg.fit.alpha_warm;
        if !self.fits.contains(&self.cfg.fit, alpha, m, l) {
            self.fits.get(&self.cfg.fit, alpha, m, l)?;
        }
        Ok(())
    }
}

/// Reconstruct once with `cfg` (a one-off [`Membrane`]: repeated
/// reconstructions should build the engine once and share its fit cache).
///
/// # Errors
/// [`MembraneError`] for an invalid configuration or an unusable cloud.
pub fn reconstruct(
    cloud: &PointCloud,
    cfg: &MembraneConfig,
    budget: &Budget,
    warm: Option<&WarmStart>,
) -> Result<Reconstruction, MembraneError> {
    let start = warm.map_or(Start::Cold, |w| Start::Warm(w.clone()));
    Membrane::new(cfg.clone())?.reconstruct(cloud, budget, &start)
}
