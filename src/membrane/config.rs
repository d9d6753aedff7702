//! The `membrane` section of the configuration: every parameter of the
//! separability membrane (paper §III-D/E/F) and the mechanisms this
//! implementation adds. Documented key by key in `launch/sepmem.json5`.
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

/// One attribute of the weighted separability (paper Eq. 9).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttributeWeight {
    /// Attribute channel name (`intensity`, `luma`, `density`, or a field of the input).
    pub name: String,
    /// Its weight `w_j` in Eq. 9.
    pub weight: f64,
}

/// Parameters of the separability membrane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MembraneConfig {
    /// Thin larger clouds to at most this many points (deterministic
    /// pseudo-random subsample) before anything else; 0 keeps every point.
    pub max_points: usize,
    /// k of the per-point mean k-NN distance d_i (paper Eq. 5).
    pub knn_k: usize,
    /// Drop points whose d_i exceeds this multiple of the median d_i before
    /// anything else (0 disables the outlier filter).
    pub outlier_factor: f64,
    /// Compute d_i for at most this many points (a spread subset) and filter
    /// outliers by voxel counts instead of per-point d_i (0: every point).
    pub density_sample: usize,
    /// Use the local δ_R (paper Eq. 6) in the search instead of the global δ.
    pub local_delta: bool,
    /// Global δ of a whole object (not a single view, which uses the
    /// median): this quantile of the kept points' d_i (0.5: the median).
    pub delta_quantile: f64,
    /// Global δ of a whole object: that quantile times this factor.
    pub delta_scale: f64,
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
    pub init_quantile: f64,
    /// Enlargement of the initial surface beyond the smallest one enclosing every point.
    pub init_margin: f64,
    /// Initial control grid `[M, L]` (columns around, rows pole to pole).
    pub grid_start: [usize; 2],
    /// Largest control grid `[M, L]` reached by dynamic adjustment.
    pub grid_max: [usize; 2],
    /// Control columns and rows added per adjustment `[m, l]`.
    pub grid_step: [usize; 2],
    /// Dynamic membrane adjustment (§III-F); false keeps `grid_start` fixed.
    pub adaptive: bool,
    /// `div_min` of the sample count `div_n = max(div_min, α(q−1)+1)`.
    pub div_min: usize,
    /// `α` of the sample count formula.
    pub alpha: f64,
    /// `α` used when warm-started from a previous surface (fewer samples:
    /// the surface is already close, and frames must be cheap).
    pub alpha_warm: f64,
    /// Number of boundary positions K tried in each search cuboid.
    pub boundaries: usize,
    /// Shift factor β (< 1) applied to each sample's move.
    pub beta: f64,
    /// Initial search depth M_d (relative to the object size).
    pub depth_start: f64,
    /// Initial search depth for a warm start (relative).
    pub depth_warm: f64,
    /// Factor applied to the depth after every iteration.
    pub depth_decay: f64,
    /// Depth floor, in multiples of δ.
    pub depth_floor_delta: f64,
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
    /// Accept a boundary only where the inner region is the denser one (μ1 ≥ μ2).
    pub inside_denser: bool,
    /// Smallest inner region `r1` of an accepted boundary, as a fraction of
    /// the search depth `M_d` (0 = any boundary; needs `inside_denser`).
    pub inner_margin: f64,
    /// Dense-side significance: the band must hold this fraction of the
    /// expected surface count `M_w·M_h/δ²`.
    pub significance: f64,
    /// 3×3 median filter of the per-sample shifts.
    pub median_filter: bool,
    /// Warm-started iterations search a checkerboard half of the samples
    /// (alternating) and give the other half their neighbours' result.
    pub sparse_warm_search: bool,
    /// The same checkerboard search for cold reconstructions of whole
    /// objects (no single view) once the grid has reached its maximum, for
    /// clouds with at least as many points as the grid has samples.
    pub sparse_cold_search: bool,
    /// Redistribute the samples along `u` (equal arc lengths) after a refit
    /// when the ring stretch exceeds this ratio (0 = off; whole objects).
    pub redistribute_stretch: f64,
    /// Gated inward force where the occupancy grid says the sample is
    /// outside: against the normal, or, where the normal faces the centroid,
    /// toward the solid space its normal line meets (along it for a
    /// folded-over pocket, against it for a sheet hanging in a cavity).
    pub inward_force: bool,
    /// Tension near the poles on samples without a data force: the fraction
    /// of the normal step to their neighbours' mean they move (0 = off).
    pub pole_tension: f64,
    /// Sample rows next to each pole where `pole_tension` acts.
    pub pole_tension_rows: usize,
    /// Warm-started single views: smoothing of the occluded back without a
    /// data force (the fraction of the mean-free umbrella step; 0 = off).
    pub warm_back_smoothing: f64,
    /// Voxel edge of the occupancy grid, in multiples of δ.
    pub inward_voxel_delta: f64,
    /// Points in a voxel's 3×3×3 neighbourhood for it to be occupied.
    pub inward_min_points: usize,
    /// Inward move, as a fraction of the current search depth.
    pub inward_step: f64,
    /// Roughness penalty weight w of the fit (`λ = w·tr(AᵀA)/n`).
    pub roughness: f64,
    /// Grow the control grid when the gain of η_g falls below this (g_min).
    pub g_min: f64,
    /// Minimum iterations on a grid before it may grow again.
    pub grow_after: usize,
    /// Plateau: |Δη_g| below this …
    pub plateau_eps: f64,
    /// … for this many consecutive iterations on the final grid stops.
    pub plateau_patience: usize,
    /// Hard cap on iterations.
    pub max_iterations: usize,
    /// Wall-clock budget per reconstruction in ms used by the CLI (0 = none).
    pub time_limit_ms: f64,
    /// Weight of the point separability η_p in the weighted mean (Eq. 9).
    pub spatial_weight: f64,
    /// Attribute separabilities and weights (empty = spatial only).
    pub attributes: Vec<AttributeWeight>,
    /// Worker threads for the per-sample search (0 = all cores, 1 = serial).
    pub threads: usize,
    /// Sensor position for single-view clouds: `"auto"` (the frame origin
    /// when the cloud is one layer seen from it), `"none"`, or `[x, y, z]`.
    pub viewpoint: super::view::Viewpoint,
    /// Complete the unseen side of a single view by the mirror prior.
    pub view_completion: bool,
}

impl Default for MembraneConfig {
    fn default() -> Self {
        Self {
            max_points: 8000,
            knn_k: 8,
            outlier_factor: 2.0,
            density_sample: 0,
            local_delta: false,
            delta_quantile: 0.25,
            delta_scale: 1.3,
            pole_axis: PoleAxis::Shortest,
            pole_axis_candidates: 2,
            pole_axis_support: 0.99,
            init_quantile: 0.002,
            init_margin: 1.05,
            grid_start: [8, 5],
            grid_max: [40, 25],
            grid_step: [8, 5],
            adaptive: true,
            div_min: 24,
            alpha: 2.0,
            alpha_warm: 1.5,
            boundaries: 30,
            beta: 0.9,
            depth_start: 0.3,
            depth_warm: 0.08,
            depth_decay: 0.85,
            depth_floor_delta: 4.0,
            cross_scale: 1.0,
            cross_min_delta: 3.0,
            cross_max: 0.1,
            band_inner_delta: 2.0,
            band_outer_delta: 1.0,
            inside_denser: true,
            inner_margin: 0.25,
            significance: 0.3,
            median_filter: true,
            sparse_warm_search: true,
            sparse_cold_search: true,
            redistribute_stretch: 1.3,
            inward_force: true,
            pole_tension: 1.0,
            pole_tension_rows: 6,
            warm_back_smoothing: 0.5,
            inward_voxel_delta: 2.0,
            inward_min_points: 20,
            inward_step: 0.5,
            roughness: 1e-2,
            g_min: 0.01,
            grow_after: 2,
            plateau_eps: 1e-3,
            plateau_patience: 3,
            max_iterations: 60,
            time_limit_ms: 0.0,
            spatial_weight: 1.0,
            attributes: Vec::new(),
            threads: 0,
            viewpoint: super::view::Viewpoint::Mode(super::view::ViewMode::Auto),
            view_completion: false,
        }
    }
}

/// A membrane parameter out of range: the key and what is wrong with it.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("membrane config: `{key}` {problem}")]
pub struct ConfigError {
    /// Parameter name.
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

/// Check every parameter's range.
///
/// # Errors
/// [`ConfigError`] naming the first bad key.
pub fn validate(cfg: &MembraneConfig) -> Result<(), ConfigError> {
    let bad = |key: &'static str, problem: &str| Err(ConfigError::new(key, problem));
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
    let lengths = [
        ("depth_start", cfg.depth_start),
        ("depth_warm", cfg.depth_warm),
        ("depth_floor_delta", cfg.depth_floor_delta),
        ("cross_scale", cfg.cross_scale),
        ("cross_min_delta", cfg.cross_min_delta),
        ("cross_max", cfg.cross_max),
        ("inward_voxel_delta", cfg.inward_voxel_delta),
    ];
    check_each(&lengths, pos, "must be a positive length")?;
    validate_mechanisms(cfg)
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

/// The second half of [`validate`]: the mechanisms' and the schedule's keys.
fn validate_mechanisms(cfg: &MembraneConfig) -> Result<(), ConfigError> {
    let bad = |key: &'static str, problem: &str| Err(ConfigError::new(key, problem));
    let pos = |x: f64| x > 0.0 && x.is_finite();
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
    let non_negative = [
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
    ];
    check_each(
        &non_negative,
        |v| v >= 0.0 && v.is_finite(),
        "must be a finite value >= 0",
    )?;
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
