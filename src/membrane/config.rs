//! The `membrane` section of the configuration: every parameter of the
//! separability membrane (paper §III-D/E/F) and the mechanisms this
//! implementation adds, in one sub-section per module of the membrane
//! (`prepare`, `init`, `step`, `regularize`, `fit`, `schedule`, `view`).
//! Documented key by key in `launch/sepmem.json5`.
//!
//! An optional mechanism with parameters is an `Option` of its own
//! section (`null` turns it off, e.g. `step.inward`, `schedule.growth`); a
//! choice between methods is an enum (`prepare.search_delta`,
//! `view.completion`). No key uses 0 to mean "off".
//!
//! Lengths are relative to the object size (the longest bounding-box edge of
//! the filtered cloud) unless their name ends in `_delta` (multiples of the
//! point spacing δ) or `_m` (metres).

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Which axis the two poles of the membrane lie on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PoleAxis {
    /// The x axis.
    X,
    /// The y axis.
    Y,
    /// The z axis.
    Z,
    /// The axis of the longest bounding-box edge.
    Longest,
    /// The axis of the shortest bounding-box edge.
    Shortest,
}

/// Which point spacing the separability search uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SearchDelta {
    /// One global δ per cloud.
    Global,
    /// The local δ_R of each cuboid (paper Eq. 6).
    Local,
}

/// How the unseen side of a single view is completed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Completion {
    /// Not at all: the back stays at the initial surface, held where the
    /// camera could not see.
    None,
    /// By mirroring the visible points (the symmetry prior of [`super::view`]).
    Mirror,
}

/// One attribute of the weighted separability (paper Eq. 9).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttributeWeight {
    /// Attribute channel name (`intensity`, `luma`, `density`, or a field of the input).
    pub name: String,
    /// Its weight `w_j` in Eq. 9.
    pub weight: f64,
}

/// Parameters of the separability membrane, one section per module.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MembraneConfig {
    /// Thinning, outlier filter and point spacing δ ([`super::prepare`]).
    pub prepare: PrepareConfig,
    /// The initial surface and its pole axis ([`super::init`], [`super::pole`]).
    pub init: InitConfig,
    /// The per-sample search and shift rule ([`super::step`]).
    pub step: StepConfig,
    /// The regularisers of the shifts ([`super::regularize`]).
    pub regularize: RegularizeConfig,
    /// Sample counts and the least-squares refit ([`super::fit`]).
    pub fit: FitConfig,
    /// Depth decay, grid growth and stopping ([`super::schedule`]).
    pub schedule: ScheduleConfig,
    /// Single-view clouds ([`super::view`]).
    pub view: ViewConfig,
}

/// `membrane.prepare`: what happens to the points before the evolution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrepareConfig {
    /// Thin larger clouds to at most this many points (deterministic
    /// pseudo-random subsample) before anything else; `None` keeps every point.
    pub max_points: Option<usize>,
    /// k of the per-point mean k-NN distance d_i (paper Eq. 5).
    pub knn_k: usize,
    /// Drop points whose d_i exceeds this multiple of the median d_i before
    /// anything else; `None`: no outlier filter.
    pub outlier_factor: Option<f64>,
    /// Compute d_i for at most this many points (a spread subset) and filter
    /// outliers by voxel counts instead of per-point d_i; `None`: every point.
    pub density_sample: Option<usize>,
    /// The search's δ: global, or the local δ_R of each cuboid (paper Eq. 6).
    pub search_delta: SearchDelta,
    /// Global δ of a whole object (not a single view, which uses the
    /// median): this quantile of the kept points' d_i (0.5: the median).
    pub delta_quantile: f64,
    /// Global δ of a whole object: that quantile times this factor.
    pub delta_scale: f64,
    /// With the global δ: the search's δ_R from the spacing of the points
    /// near each cuboid, never below δ, an outlier filter relative to the
    /// kept neighbours and area-weighted occupancy counts
    /// ([`super::spacing`], on by default; the weighted mode keeps only the
    /// filter); `None`: the global δ everywhere.
    pub local_spacing: Option<LocalSpacingConfig>,
    /// Drop groups of points detached from the object's main body (a mask
    /// that bled onto the background, a label shared by two objects) before
    /// anything else looks at the points ([`crate::detached`]; the frame
    /// pipeline applies it to each object's cloud before tracking); `None`
    /// keeps them.
    pub detached: Option<crate::detached::DetachedConfig>,
}

/// `membrane.prepare.local_spacing`: the density-robust spacing of the
/// search ([`super::spacing`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocalSpacingConfig {
    /// Neighbours (the point itself included) over whose d_i a point's
    /// local spacing is taken (their median).
    pub neighbours: usize,
    /// A point's spacing grows only where its neighbourhood is sparser than
    /// the cloud's median by more than this factor (≥ 1), and by the
    /// excess: `δ_i = δ · max(1, m_i / (tolerance · m))`.
    pub tolerance: f64,
}

impl Default for LocalSpacingConfig {
    fn default() -> Self {
        Self {
            neighbours: 32,
            tolerance: 1.25,
        }
    }
}

impl Default for PrepareConfig {
    fn default() -> Self {
        Self {
            max_points: Some(8000),
            knn_k: 8,
            outlier_factor: Some(2.0),
            density_sample: None,
            search_delta: SearchDelta::Global,
            delta_quantile: 0.25,
            delta_scale: 1.3,
            local_spacing: Some(LocalSpacingConfig::default()),
            detached: Some(crate::detached::DetachedConfig::default()),
        }
    }
}

/// `membrane.init`: the initial surface of a cold start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitConfig {
    /// Axis of the two poles.
    pub pole_axis: PoleAxis,
    /// Cold whole objects with an automatic `pole_axis`: how many pole axes
    /// to try (1–3; after the configured one, the most different
    /// bounding-box edge first); the reconstruction with the highest final
    /// η_g × point coverage is kept.
    pub pole_axis_candidates: usize,
    /// Other pole axes are tried only when less than this share of the
    /// first reconstruction's mesh vertices lie within one mean mesh edge
    /// of a used point (1 = always).
    pub pole_axis_support: f64,
    /// Quantile used for the robust extreme points of the initial octagon.
    pub quantile: f64,
    /// Enlargement of the initial surface beyond the smallest one enclosing every point.
    pub margin: f64,
    /// Initial control grid `[M, L]` (columns around, rows pole to pole).
    pub grid: [usize; 2],
    /// A warm start on fused views first encloses the points outside it
    /// ([`super::enclose`]); `None` turns it off.
    pub warm_enclose: Option<EncloseConfig>,
    /// A cold start on a partial cloud (one seen from a known camera)
    /// reaches back to the depth of a mirror prior ([`super::init`]);
    /// `None`: to the deepest point.
    pub unseen_back: Option<UnseenBackConfig>,
}

/// `membrane.init.unseen_back`: the depth, behind the seen front, of a
/// partial cloud's initial surface, as a factor on the mirror depth (`{}`
/// takes 1.0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UnseenBackConfig {
    /// The factor (positive) on `max(V, min(2V, L))`.
    pub extent: f64,
}

impl Default for UnseenBackConfig {
    fn default() -> Self {
        Self { extent: 1.0 }
    }
}

/// `membrane.init.warm_enclose`: how far outside a warm surface a point
/// must lie to push it out, and how far beyond the point it is pushed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncloseConfig {
    /// A point more than this many δ outside the surface pushes it out.
    pub margin_delta: f64,
    /// ... to this many δ beyond the point.
    pub pad_delta: f64,
}

impl Default for EncloseConfig {
    fn default() -> Self {
        Self {
            margin_delta: 2.0,
            pad_delta: 1.0,
        }
    }
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            pole_axis: PoleAxis::Shortest,
            pole_axis_candidates: 2,
            pole_axis_support: 0.99,
            quantile: 0.002,
            margin: 1.05,
            grid: [8, 5],
            warm_enclose: Some(EncloseConfig::default()),
            unseen_back: None,
        }
    }
}

/// `membrane.step`: the per-sample cuboid search and its shift rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepConfig {
    /// Number of boundary positions K tried in each search cuboid.
    pub boundaries: usize,
    /// Shift factor β (≤ 1) applied to each sample's move.
    pub beta: f64,
    /// Cross-section M_w, M_h as a multiple of the local sample spacing.
    pub cross_scale: f64,
    /// Cross-section floor, in multiples of δ.
    pub cross_min_delta: f64,
    /// Cross-section cap (relative to the object size).
    pub cross_max: f64,
    /// Robust shift band: points with offsets in `[t* − inner·δ, t* + outer·δ]` …
    pub band_inner_delta: f64,
    /// … are centred on by their median (`band_outer_delta` is `outer`).
    pub band_outer_delta: f64,
    /// Accept a boundary only where the inner region is the denser one
    /// (μ1 ≥ μ2); `None` accepts every boundary.
    pub inside_denser: Option<InsideDenserConfig>,
    /// A sample facing away from every camera that saw the points takes no
    /// force from them ([`super::step`]); `None` lets every sample search.
    pub facing_away: Option<FacingAwayConfig>,
    /// Dense-side significance: the band must hold this fraction of the
    /// expected surface count `M_w·M_h/δ²`.
    pub significance: f64,
    /// Warm-started iterations search a checkerboard half of the samples
    /// (alternating) and give the other half their neighbours' result.
    pub sparse_warm_search: bool,
    /// The same checkerboard search for cold reconstructions of whole
    /// objects (no single view) once the grid has reached its maximum, for
    /// clouds with at least as many points as the grid has samples.
    pub sparse_cold_search: bool,
    /// The gated inward force where the occupancy grid says the sample is
    /// outside; `None` turns it off.
    pub inward: Option<InwardConfig>,
    /// Weight of the point separability η_p in the weighted mean (Eq. 9).
    pub spatial_weight: f64,
    /// Attribute separabilities and weights (empty = spatial only).
    pub attributes: Vec<AttributeWeight>,
    /// Worker threads for the per-sample search (0 = all cores, 1 = serial).
    pub threads: usize,
    /// The outward move of each vertex of a published frame mesh that
    /// removes the centring's curvature bias ([`super::unbias`]); `None`
    /// publishes the membrane's surface as it is.
    pub unbias: Option<UnbiasConfig>,
}

/// `membrane.step.unbias`: the bound of the curvature-bias move.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnbiasConfig {
    /// Largest move, in multiples of δ.
    pub max_delta: f64,
}

impl Default for UnbiasConfig {
    fn default() -> Self {
        Self { max_delta: 0.25 }
    }
}

impl Default for StepConfig {
    fn default() -> Self {
        Self {
            boundaries: 30,
            beta: 0.9,
            cross_scale: 1.0,
            cross_min_delta: 3.0,
            cross_max: 0.1,
            band_inner_delta: 2.0,
            band_outer_delta: 1.0,
            inside_denser: Some(InsideDenserConfig::default()),
            facing_away: None,
            significance: 0.3,
            sparse_warm_search: true,
            sparse_cold_search: true,
            inward: Some(InwardConfig::default()),
            spatial_weight: 1.0,
            attributes: Vec::new(),
            threads: 0,
            unbias: Some(UnbiasConfig::default()),
        }
    }
}

/// `membrane.step.facing_away`: when a sample faces away from the cameras.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FacingAwayConfig {
    /// A sample of a warm start faces away from a camera when the cosine
    /// of the angle between its outward normal and the direction to the
    /// camera is at most this, in [-1, 1).
    pub max_cos: f64,
    /// The same bound for a cold start, whose initial octagon's facets do
    /// not follow the object, in [-1, 1).
    pub cold_max_cos: f64,
}

impl Default for FacingAwayConfig {
    fn default() -> Self {
        Self {
            max_cos: 0.0,
            cold_max_cos: -0.8,
        }
    }
}

impl FacingAwayConfig {
    /// The bound for a warm or a cold start.
    pub fn bound(&self, warm: bool) -> f64 {
        if warm {
            self.max_cos
        } else {
            self.cold_max_cos
        }
    }
}

/// `membrane.step.inside_denser`: the inner-side-denser boundary rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InsideDenserConfig {
    /// Smallest inner region `r1` of an accepted boundary, as a fraction of
    /// the search depth `M_d` (0 = any boundary with a denser inside).
    pub inner_margin: f64,
}

impl Default for InsideDenserConfig {
    fn default() -> Self {
        Self { inner_margin: 0.25 }
    }
}

/// `membrane.step.inward`: the gated inward force. Where the occupancy grid
/// says the sample is outside: against the normal, or, where the normal
/// faces the centroid, toward the solid space its normal line meets (along
/// it for a folded-over pocket, against it for a sheet hanging in a cavity).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InwardConfig {
    /// Voxel edge of the occupancy grid, in multiples of δ.
    pub voxel_delta: f64,
    /// Points in a voxel's 3×3×3 neighbourhood for it to be occupied.
    pub min_points: usize,
    /// Inward shift, as a fraction of the current search depth.
    pub shift: f64,
}

impl Default for InwardConfig {
    fn default() -> Self {
        Self {
            voxel_delta: 2.0,
            min_points: 20,
            shift: 0.5,
        }
    }
}

/// `membrane.regularize`: what happens to the shifts before the refit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegularizeConfig {
    /// 3×3 median filter of the per-sample shifts.
    pub median_filter: bool,
    /// Tension near the poles on samples without a data force (whole
    /// objects); `None` turns it off.
    pub pole_tension: Option<PoleTensionConfig>,
    /// Warm-started single views: smoothing of the occluded back without a
    /// data force (the fraction of the mean-free umbrella step); `None`
    /// turns it off.
    pub warm_back_smoothing: Option<f64>,
}

impl Default for RegularizeConfig {
    fn default() -> Self {
        Self {
            median_filter: true,
            pole_tension: Some(PoleTensionConfig::default()),
            warm_back_smoothing: Some(0.5),
        }
    }
}

/// `membrane.regularize.pole_tension`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoleTensionConfig {
    /// The fraction of the normal step to their neighbours' mean the samples move.
    pub strength: f64,
    /// Sample rows next to each pole where it acts.
    pub rows: usize,
}

impl Default for PoleTensionConfig {
    fn default() -> Self {
        Self {
            strength: 1.0,
            rows: 6,
        }
    }
}

/// `membrane.fit`: the sample counts of Eq. 14 and the least-squares refit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {
    /// `div_min` of the sample count `div_n = max(div_min, α(q−1)+1)`.
    pub div_min: usize,
    /// `α` of the sample count formula.
    pub alpha: f64,
    /// `α` used when warm-started from a previous surface (fewer samples:
    /// the surface is already close, and frames must be cheap).
    pub alpha_warm: f64,
    /// Roughness penalty weight w of the fit (`λ = w·tr(AᵀA)/n`).
    pub roughness: f64,
    /// Redistribute the samples along `u` (equal arc lengths) after a refit
    /// when the ring stretch exceeds this ratio (whole objects); `None`
    /// turns it off.
    pub redistribute_stretch: Option<f64>,
    /// Most MiB of factored fit systems kept for later frames (least
    /// recently used out first); a [`super::Membrane`] and its clones
    /// share one cache.
    pub cache_mib: usize,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            div_min: 24,
            alpha: 2.0,
            alpha_warm: 1.5,
            roughness: 1e-2,
            redistribute_stretch: Some(1.3),
            cache_mib: 32,
        }
    }
}

/// `membrane.schedule`: dynamic membrane adjustment (§III-F) and stopping.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleConfig {
    /// Initial search depth M_d (relative to the object size).
    pub depth_start: f64,
    /// Initial search depth for a warm start (relative).
    pub depth_warm: f64,
    /// Factor applied to the depth after every iteration.
    pub depth_decay: f64,
    /// Depth floor, in multiples of δ.
    pub depth_floor_delta: f64,
    /// Growth of the control grid; `None` keeps `init.grid` fixed.
    pub growth: Option<GrowthConfig>,
    /// Plateau: |Δη_g| below this …
    pub plateau_eps: f64,
    /// … for this many consecutive iterations on the final grid stops.
    pub plateau_patience: usize,
    /// Hard cap on iterations.
    pub max_iterations: usize,
    /// Wall-clock budget per reconstruction in ms used by the CLI; `None`: none.
    pub time_limit_ms: Option<f64>,
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        Self {
            depth_start: 0.3,
            depth_warm: 0.08,
            depth_decay: 0.85,
            depth_floor_delta: 4.0,
            growth: Some(GrowthConfig::default()),
            plateau_eps: 1e-3,
            plateau_patience: 3,
            max_iterations: 60,
            time_limit_ms: None,
        }
    }
}

/// `membrane.schedule.growth`: the control grid grows when η_g stops gaining.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrowthConfig {
    /// Largest control grid `[M, L]`.
    pub grid_max: [usize; 2],
    /// Control columns and rows added per adjustment `[m, l]`.
    pub grid_step: [usize; 2],
    /// Grow when the gain of η_g falls below this (g_min).
    pub g_min: f64,
    /// Minimum iterations on a grid before it may grow again.
    pub grow_after: usize,
    /// Most control points per point the membrane uses: the grid grows only
    /// to sizes with at most this many (`None`: up to `grid_max` whatever
    /// the points). See [`super::schedule`] for the measurement.
    pub max_control_per_point: Option<f64>,
}

impl Default for GrowthConfig {
    fn default() -> Self {
        Self {
            grid_max: [40, 25],
            grid_step: [8, 5],
            g_min: 0.01,
            grow_after: 2,
            max_control_per_point: Some(2.0),
        }
    }
}

/// `membrane.view`: single-view clouds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewConfig {
    /// Sensor position for single-view clouds: `"auto"` (the frame origin
    /// when the cloud is one layer seen from it), `"none"`, or `[x, y, z]`.
    pub viewpoint: super::view::Viewpoint,
    /// How the unseen side of a single view is completed.
    pub completion: Completion,
    /// The bound on the depth of the unseen side behind the seen front
    /// ([`super::view`], 4.); `None` (the default): unbounded (only the
    /// completion's back, with `completion = "mirror"`).
    pub back: Option<BackConfig>,
    /// The mirrored completion of a fused cloud's latest view while its
    /// model holds few views ([`super::view`], 6.); `None` turns it off.
    pub fused_completion: Option<FusedCompletionConfig>,
    /// The completion of a fused cloud that is a surface of revolution
    /// ([`super::revolution`]); `None` turns it off.
    pub revolution: Option<RevolutionConfig>,
    /// The completion of a fused cloud that is a sphere cap
    /// ([`super::sphere`]), when it is no surface of revolution; `None`
    /// turns it off.
    pub sphere: Option<SphereConfig>,
}

/// `membrane.view.sphere`: when a fused cloud counts as a sphere cap, and
/// which points of its sphere complete it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SphereConfig {
    /// Largest median distance of a point to the fitted sphere, in δ.
    pub max_misfit_delta: f64,
    /// Largest length of the mean unit direction from the centre to the
    /// points (0.5 on an evenly sampled hemisphere): the cap fixes the
    /// sphere.
    pub max_spread: f64,
    /// Largest share of the completed points that some view saw empty.
    pub max_contradicted: f64,
    /// Completed points within this many δ of a fused point are dropped.
    pub gap_delta: f64,
    /// At most this many completed points per fused point.
    pub max_added: f64,
    /// Beyond the ball by more than this many δ, the inward force may
    /// carve, as where a view saw empty; `None`: only there.
    pub carve_delta: Option<f64>,
}

impl Default for SphereConfig {
    fn default() -> Self {
        Self {
            max_misfit_delta: 0.25,
            max_spread: 0.7,
            max_contradicted: 0.02,
            gap_delta: 1.5,
            max_added: 2.0,
            carve_delta: Some(4.0),
        }
    }
}

/// `membrane.view.revolution`: when a fused cloud counts as a surface of
/// revolution, and which of its revolved points complete it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RevolutionConfig {
    /// Largest median |sin ψ| between a normal and the plane through the
    /// axis (0 on a surface of revolution).
    pub max_sin: f64,
    /// Least determinacy of the axis (the line complex's second smallest
    /// eigenvalue over its smallest): a sphere's normal lines fit every
    /// axis through its centre.
    pub min_determinacy: f64,
    /// Largest median distance of a point to its ring, in δ.
    pub max_ring_delta: f64,
    /// The smallest ring is at most this share of the largest, or no view
    /// saw through the axis: the axis passes through the object (not a
    /// torus arc's bend centre).
    pub max_ring_ratio: f64,
    /// Largest share of the revolved points that some view saw empty.
    pub max_contradicted: f64,
    /// Revolved points within this many δ of a fused point are dropped.
    pub gap_delta: f64,
    /// At most this many revolved points per fused point.
    pub max_added: f64,
    /// Beyond the revolved solid by more than this many δ, the inward
    /// force may carve, as where a view saw empty; `None`: only there.
    pub carve_delta: Option<f64>,
}

impl Default for RevolutionConfig {
    fn default() -> Self {
        Self {
            max_sin: 0.1,
            min_determinacy: 15.0,
            max_ring_delta: 1.5,
            max_ring_ratio: 0.7,
            max_contradicted: 0.1,
            gap_delta: 1.5,
            max_added: 1.5,
            carve_delta: Some(4.0),
        }
    }
}

/// `membrane.view.fused_completion`: when a fused cloud is completed, and
/// which mirror points it keeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FusedCompletionConfig {
    /// Completed only while the model keeps at most this many views.
    pub max_views: usize,
    /// Mirror points within this many δ of a fused point are dropped.
    pub gap_delta: f64,
}

impl Default for FusedCompletionConfig {
    fn default() -> Self {
        Self {
            max_views: 1,
            gap_delta: 6.0,
        }
    }
}

/// `membrane.view.back`: nothing of a single view's object lies deeper than
/// `z₀ + extent · max(V, min(Lᵤ, L_w))` behind its seen front `z₀` (`V` the
/// visible depth, `Lᵤ, L_w` the lateral extents); nor, for a fused cloud
/// whose carving no completed solid bounds, along its latest view, `V`
/// then the depth of all its fused points ([`super::view::BackBound`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackConfig {
    /// The factor on the seen extent (positive).
    pub extent: f64,
}

impl Default for BackConfig {
    fn default() -> Self {
        Self { extent: 1.0 }
    }
}

impl Default for ViewConfig {
    fn default() -> Self {
        Self {
            viewpoint: super::view::Viewpoint::Mode(super::view::ViewMode::Auto),
            completion: Completion::None,
            back: None,
            fused_completion: None,
            revolution: Some(RevolutionConfig::default()),
            sphere: Some(SphereConfig::default()),
        }
    }
}

/// A membrane parameter out of range: the key and what is wrong with it.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("membrane config: `{key}` {problem}")]
pub struct ConfigError {
    /// Dotted key within the `membrane` section (e.g. `step.beta`).
    pub key: &'static str,
    /// What is wrong with it.
    pub problem: String,
}

impl ConfigError {
    /// `key` is wrong because of `problem`.
    pub fn new(key: &'static str, problem: impl Into<String>) -> Self {
        Self {
            key,
            problem: problem.into(),
        }
    }
}

/// `Err` naming `key` and `problem` unless `ok`.
fn check(ok: bool, key: &'static str, problem: &str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::new(key, problem))
    }
}

/// The first of `keys` whose value fails `ok`, as a [`ConfigError`] saying `problem`.
fn check_each(
    keys: &[(&'static str, f64)],
    ok: impl Fn(f64) -> bool,
    problem: &str,
) -> Result<(), ConfigError> {
    match keys.iter().find(|(_, v)| !ok(*v)) {
        Some((k, _)) => Err(ConfigError::new(k, problem)),
        None => Ok(()),
    }
}

/// A share: a value in [0, 1].
fn share(x: f64) -> bool {
    (0.0..=1.0).contains(&x)
}

/// A positive, finite value.
fn pos(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}

/// A finite value ≥ 0.
fn non_negative(x: f64) -> bool {
    x >= 0.0 && x.is_finite()
}

/// Check every parameter's range.
///
/// # Errors
/// [`ConfigError`] naming the first bad key (dotted within `membrane`).
pub fn validate(cfg: &MembraneConfig) -> Result<(), ConfigError> {
    validate_prepare(&cfg.prepare)?;
    validate_init(&cfg.init)?;
    validate_step(&cfg.step)?;
    validate_regularize(&cfg.regularize)?;
    validate_fit(&cfg.fit)?;
    validate_schedule(&cfg.schedule, cfg.init.grid)?;
    check(
        cfg.view.back.as_ref().is_none_or(|b| pos(b.extent)),
        "view.back.extent",
        "must be positive (null leaves the back unbounded)",
    )?;
    check(
        cfg.view
            .fused_completion
            .as_ref()
            .is_none_or(|f| non_negative(f.gap_delta)),
        "view.fused_completion.gap_delta",
        "must be a finite value >= 0",
    )?;
    validate_revolution(cfg.view.revolution.as_ref())?;
    validate_sphere(cfg.view.sphere.as_ref())
}

fn validate_sphere(s: Option<&SphereConfig>) -> Result<(), ConfigError> {
    let Some(s) = s else {
        return Ok(());
    };
    check_each(
        &[
            ("view.sphere.max_spread", s.max_spread),
            ("view.sphere.max_contradicted", s.max_contradicted),
        ],
        share,
        "must lie in [0, 1]",
    )?;
    check_each(
        &[
            ("view.sphere.max_misfit_delta", s.max_misfit_delta),
            ("view.sphere.gap_delta", s.gap_delta),
            ("view.sphere.max_added", s.max_added),
        ],
        pos,
        "must be positive",
    )?;
    check(
        s.carve_delta.is_none_or(non_negative),
        "view.sphere.carve_delta",
        "must be finite and at least 0 (null: no carving beyond the ball)",
    )
}

fn validate_revolution(r: Option<&RevolutionConfig>) -> Result<(), ConfigError> {
    let Some(r) = r else {
        return Ok(());
    };
    check_each(
        &[
            ("view.revolution.max_sin", r.max_sin),
            ("view.revolution.max_ring_ratio", r.max_ring_ratio),
            ("view.revolution.max_contradicted", r.max_contradicted),
        ],
        share,
        "must lie in [0, 1]",
    )?;
    check_each(
        &[
            ("view.revolution.min_determinacy", r.min_determinacy),
            ("view.revolution.max_ring_delta", r.max_ring_delta),
            ("view.revolution.gap_delta", r.gap_delta),
            ("view.revolution.max_added", r.max_added),
        ],
        pos,
        "must be positive",
    )?;
    check(
        r.carve_delta.is_none_or(non_negative),
        "view.revolution.carve_delta",
        "must be finite and at least 0 (null: no carving beyond the solid)",
    )
}

fn validate_prepare(p: &PrepareConfig) -> Result<(), ConfigError> {
    check(
        p.max_points != Some(0),
        "prepare.max_points",
        "must be at least 1 (null keeps every point)",
    )?;
    check(p.knn_k > 0, "prepare.knn_k", "must be at least 1")?;
    check(
        p.outlier_factor.is_none_or(|f| f > 0.0),
        "prepare.outlier_factor",
        "must be positive (null turns the filter off)",
    )?;
    check(
        p.density_sample != Some(0),
        "prepare.density_sample",
        "must be at least 1 (null: every point)",
    )?;
    check(
        p.delta_quantile > 0.0 && p.delta_quantile <= 1.0,
        "prepare.delta_quantile",
        "must be in (0, 1]",
    )?;
    check(
        pos(p.delta_scale),
        "prepare.delta_scale",
        "must be positive",
    )?;
    check(
        p.local_spacing.as_ref().is_none_or(|l| l.neighbours >= 1),
        "prepare.local_spacing.neighbours",
        "must be at least 1 (null turns the local spacing off)",
    )?;
    check(
        p.local_spacing
            .as_ref()
            .is_none_or(|l| l.tolerance >= 1.0 && l.tolerance.is_finite()),
        "prepare.local_spacing.tolerance",
        "must be a finite factor of at least 1",
    )?;
    check(
        p.detached.as_ref().is_none_or(|d| pos(d.gap)),
        "prepare.detached.gap",
        "must be a positive share of the body's diagonal (null keeps detached points)",
    )
}

fn validate_init(i: &InitConfig) -> Result<(), ConfigError> {
    check(
        i.grid[0] >= 4 && i.grid[1] >= 4,
        "init.grid",
        "needs M >= 4 and L >= 4",
    )?;
    check(
        (1..=3).contains(&i.pole_axis_candidates),
        "init.pole_axis_candidates",
        "must be 1, 2 or 3",
    )?;
    check(
        (0.0..=1.0).contains(&i.pole_axis_support),
        "init.pole_axis_support",
        "must be in [0, 1]",
    )?;
    check(
        non_negative(i.quantile) && i.quantile < 0.5,
        "init.quantile",
        "must be in [0, 0.5)",
    )?;
    check(
        i.margin >= 1.0 && i.margin.is_finite(),
        "init.margin",
        "must be >= 1",
    )?;
    check(
        i.unseen_back.as_ref().is_none_or(|b| pos(b.extent)),
        "init.unseen_back.extent",
        "must be a finite value > 0",
    )?;
    let enclose = i.warm_enclose.as_ref();
    let distances = [
        (
            "init.warm_enclose.margin_delta",
            enclose.map_or(0.0, |e| e.margin_delta),
        ),
        (
            "init.warm_enclose.pad_delta",
            enclose.map_or(0.0, |e| e.pad_delta),
        ),
    ];
    check_each(&distances, non_negative, "must be a finite value >= 0")
}

fn validate_step(s: &StepConfig) -> Result<(), ConfigError> {
    check(s.boundaries > 0, "step.boundaries", "must be at least 1")?;
    check(
        s.unbias.as_ref().is_none_or(|u| pos(u.max_delta)),
        "step.unbias.max_delta",
        "must be positive",
    )?;
    check(
        s.beta > 0.0 && s.beta <= 1.0,
        "step.beta",
        "must be in (0, 1]",
    )?;
    let lengths = [
        ("step.cross_scale", s.cross_scale),
        ("step.cross_min_delta", s.cross_min_delta),
        ("step.cross_max", s.cross_max),
        (
            "step.inward.voxel_delta",
            s.inward.as_ref().map_or(1.0, |w| w.voxel_delta),
        ),
    ];
    check_each(&lengths, pos, "must be a positive length")?;
    let margin = s.inside_denser.as_ref().map_or(0.0, |d| d.inner_margin);
    check(
        (0.0..0.5).contains(&margin),
        "step.inside_denser.inner_margin",
        "must be in [0, 0.5)",
    )?;
    let facing = s.facing_away.clone().unwrap_or_default();
    let cosines = [
        ("step.facing_away.max_cos", facing.max_cos),
        ("step.facing_away.cold_max_cos", facing.cold_max_cos),
    ];
    check_each(&cosines, |c| (-1.0..1.0).contains(&c), "must be in [-1, 1)")?;
    let finite = [
        ("step.band_inner_delta", s.band_inner_delta),
        ("step.band_outer_delta", s.band_outer_delta),
        ("step.significance", s.significance),
        (
            "step.inward.shift",
            s.inward.as_ref().map_or(0.0, |w| w.shift),
        ),
        ("step.spatial_weight", s.spatial_weight),
    ];
    check_each(&finite, non_negative, "must be a finite value >= 0")
}

fn validate_regularize(r: &RegularizeConfig) -> Result<(), ConfigError> {
    let in_unit = |x: f64| x > 0.0 && x <= 1.0;
    check(
        r.pole_tension.as_ref().is_none_or(|t| in_unit(t.strength)),
        "regularize.pole_tension.strength",
        "must be in (0, 1] (null turns the tension off)",
    )?;
    check(
        r.warm_back_smoothing.is_none_or(in_unit),
        "regularize.warm_back_smoothing",
        "must be in (0, 1] (null turns it off)",
    )
}

fn validate_fit(f: &FitConfig) -> Result<(), ConfigError> {
    check(f.div_min >= 4, "fit.div_min", "must be at least 4")?;
    check(pos(f.alpha), "fit.alpha", "must be positive")?;
    check(pos(f.alpha_warm), "fit.alpha_warm", "must be positive")?;
    check(
        non_negative(f.roughness),
        "fit.roughness",
        "must be a finite value >= 0",
    )?;
    check(
        f.redistribute_stretch
            .is_none_or(|s| s > 1.0 && s.is_finite()),
        "fit.redistribute_stretch",
        "must be above 1 (null turns it off)",
    )?;
    check(
        (1..=1 << 20).contains(&f.cache_mib),
        "fit.cache_mib",
        "must be 1 to 1048576 (MiB)",
    )
}

fn validate_schedule(s: &ScheduleConfig, grid: [usize; 2]) -> Result<(), ConfigError> {
    let lengths = [
        ("schedule.depth_start", s.depth_start),
        ("schedule.depth_warm", s.depth_warm),
        ("schedule.depth_floor_delta", s.depth_floor_delta),
    ];
    check_each(&lengths, pos, "must be a positive length")?;
    check(
        s.depth_decay > 0.0 && s.depth_decay <= 1.0,
        "schedule.depth_decay",
        "must be in (0, 1]",
    )?;
    if let Some(g) = &s.growth {
        validate_growth(g, grid)?;
    }
    check(
        non_negative(s.plateau_eps),
        "schedule.plateau_eps",
        "must be a finite value >= 0",
    )?;
    check(
        s.max_iterations > 0,
        "schedule.max_iterations",
        "must be at least 1",
    )?;
    check(
        s.time_limit_ms.is_none_or(pos),
        "schedule.time_limit_ms",
        "must be positive (null: no limit)",
    )
}

fn validate_growth(g: &GrowthConfig, grid: [usize; 2]) -> Result<(), ConfigError> {
    check(
        g.grid_max[0] >= grid[0] && g.grid_max[1] >= grid[1],
        "schedule.growth.grid_max",
        "must be at least init.grid",
    )?;
    check(
        g.grid_step != [0, 0],
        "schedule.growth.grid_step",
        "must add at least one column or row",
    )?;
    check(
        non_negative(g.g_min),
        "schedule.growth.g_min",
        "must be a finite value >= 0",
    )?;
    check(
        g.max_control_per_point.is_none_or(pos),
        "schedule.growth.max_control_per_point",
        "must be positive (null: no bound)",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        validate(&MembraneConfig::default()).unwrap();
    }

    #[test]
    fn errors_name_the_dotted_key() {
        let mut cfg = MembraneConfig::default();
        cfg.fit.alpha = 0.0;
        assert_eq!(validate(&cfg).unwrap_err().key, "fit.alpha");
        let mut cfg = MembraneConfig::default();
        cfg.prepare.outlier_factor = Some(0.0);
        let err = validate(&cfg).unwrap_err();
        assert_eq!(err.key, "prepare.outlier_factor");
        assert!(err.to_string().contains("null"), "{err}");
        let mut cfg = MembraneConfig::default();
        cfg.init.grid = [48, 30];
        assert_eq!(validate(&cfg).unwrap_err().key, "schedule.growth.grid_max");
        cfg.schedule.growth = None;
        validate(&cfg).unwrap();
    }
}
