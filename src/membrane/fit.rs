//! The least-squares refit of the control net (paper §III-D step 4) and the
//! sample counts of Eq. 14, with a cache of factored fit systems.
//!
//! The normal matrix of the fit depends only on the control grid, the sample
//! layout and the roughness weight, never on the points: a [`FitCache`]
//! factors it once per grid and hands out clones (the Cholesky factor is
//! shared through an `Arc`). The cache belongs to a
//! [`super::Membrane`] value — the node reconstructs the same grids every
//! frame, so after the first frames no frame factors anything — and
//! [`Fits`] is one reconstruction's view of it.

use super::config::FitConfig;
use super::MembraneError;
use crate::spline::{FitSystem, Layout};
use std::collections::HashMap;
use std::sync::Mutex;

/// Sample counts `(u_n, v_n)` for an `M × L` grid sampled with `alpha`
/// (paper Eq. 14: `div_n = max(div_min, α(q−1)+1)`).
pub fn sample_counts(cfg: &FitConfig, alpha: f64, m: usize, l: usize) -> (usize, usize) {
    let div = |q: usize| -> usize {
        let d = (alpha * (q as f64 - 1.0) + 1.0).round() as usize;
        d.max(cfg.div_min)
    };
    // u is periodic: q columns span q intervals, i.e. the same as q+1 clamped points.
    (div(m + 1), div(l))
}

/// Key of a factored fit system: grid, sample counts and roughness bits.
type FitKey = (usize, usize, usize, usize, u64);

/// Largest number of factored systems a [`FitCache`] keeps.
const FIT_CACHE_MAX: usize = 64;

/// Factored fit systems by grid, sample counts and roughness (see the
/// module docs). Shared by the reconstructions of one [`super::Membrane`]
/// (and its variants), which may run in parallel.
#[derive(Debug, Default)]
pub struct FitCache {
    map: Mutex<HashMap<FitKey, FitSystem>>,
}

impl FitCache {
    fn key(cfg: &FitConfig, alpha: f64, m: usize, l: usize) -> FitKey {
        let (un, vn) = sample_counts(cfg, alpha, m, l);
        (m, l, un, vn, cfg.roughness.to_bits())
    }

    fn lookup(&self, key: &FitKey) -> Option<FitSystem> {
        self.map
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .get(key)
            .cloned()
    }

    /// The factored fit system of an `m × l` grid sampled with `alpha`,
    /// from the cache or factored now and stored.
    ///
    /// # Errors
    /// [`MembraneError`] when the grid is invalid or the system singular.
    pub fn get(
        &self,
        cfg: &FitConfig,
        alpha: f64,
        m: usize,
        l: usize,
    ) -> Result<FitSystem, MembraneError> {
        let key = Self::key(cfg, alpha, m, l);
        if let Some(s) = self.lookup(&key) {
            return Ok(s);
        }
        let sys = FitSystem::new(Layout::samples(m, l, key.2, key.3)?, cfg.roughness)?;
        let mut map = self
            .map
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if map.len() >= FIT_CACHE_MAX {
            map.clear();
        }
        map.insert(key, sys.clone());
        Ok(sys)
    }

    /// Whether the system of an `m × l` grid sampled with `alpha` is cached.
    pub fn contains(&self, cfg: &FitConfig, alpha: f64, m: usize, l: usize) -> bool {
        self.lookup(&Self::key(cfg, alpha, m, l)).is_some()
    }
}

/// One reconstruction's fit systems, one per control grid, filled from a
/// [`FitCache`].
pub(crate) struct Fits<'a> {
    cfg: &'a FitConfig,
    cache: &'a FitCache,
    /// `α` of the sample counts (`fit.alpha`, or `fit.alpha_warm` for a warm start).
    pub(crate) alpha: f64,
    map: HashMap<(usize, usize), FitSystem>,
}

impl<'a> Fits<'a> {
    /// Fits sampled with `alpha`, drawn from `cache`.
    pub(crate) fn new(cfg: &'a FitConfig, cache: &'a FitCache, alpha: f64) -> Self {
        Self {
            cfg,
            cache,
            alpha,
            map: HashMap::new(),
        }
    }

    /// The fit system of the `m × l` grid.
    pub(crate) fn get(&mut self, m: usize, l: usize) -> Result<&mut FitSystem, MembraneError> {
        if !self.map.contains_key(&(m, l)) {
            let sys = self.cache.get(self.cfg, self.alpha, m, l)?;
            self.map.insert((m, l), sys);
        }
        self.map
            .get_mut(&(m, l))
            .ok_or(MembraneError::Internal("fit cache lost a grid"))
    }

    /// Sample counts of the `m × l` grid at this reconstruction's `α`.
    pub(crate) fn samples(&self, m: usize, l: usize) -> (usize, usize) {
        sample_counts(self.cfg, self.alpha, m, l)
    }
}
