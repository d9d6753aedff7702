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

/// One cached system and when it was last handed out.
#[derive(Debug)]
struct Cached {
    sys: FitSystem,
    bytes: usize,
    used: u64,
}

/// The cached systems, their total size and a use clock.
#[derive(Debug, Default)]
struct Held {
    map: HashMap<FitKey, Cached>,
    bytes: usize,
    clock: u64,
}

impl Held {
    /// The next value of the use clock.
    fn tick(&mut self) -> u64 {
        self.clock += 1;
        self.clock
    }

    /// Drop least recently used systems until `extra` more bytes fit in
    /// `budget` (or nothing is left).
    fn make_room(&mut self, extra: usize, budget: usize) {
        while self.bytes + extra > budget {
            let Some(oldest) = self.map.iter().min_by_key(|(_, c)| c.used).map(|(k, _)| *k) else {
                return;
            };
            if let Some(c) = self.map.remove(&oldest) {
                self.bytes -= c.bytes;
            }
        }
    }
}

/// Factored fit systems by grid, sample counts and roughness (see the
/// module docs), least recently used first out when they would hold more
/// than `fit.cache_mib`. Shared by the reconstructions of one
/// [`super::Membrane`] (and its variants), which may run in parallel.
///
/// The budget is in bytes, not systems: a 40 × 25 grid's factor and
/// sample rows take about 2 MiB, a 16 × 10 grid's about 0.2 MiB, so a
/// count says little about memory. Measured in the hostile soak (`sepmem
/// bench-node --hostile`, `RUST_LOG=sepmem::membrane::fit=debug`): the
/// node's four healthy streams and five hostile ones use 9 systems, 7.6 MiB,
/// all factored in the first seconds.
#[derive(Debug)]
pub struct FitCache {
    held: Mutex<Held>,
    budget: usize,
}

impl FitCache {
    /// An empty cache holding at most `cache_mib` MiB of systems.
    pub fn new(cache_mib: usize) -> Self {
        Self {
            held: Mutex::default(),
            budget: cache_mib.saturating_mul(1 << 20),
        }
    }

    fn key(cfg: &FitConfig, alpha: f64, m: usize, l: usize) -> FitKey {
        let (un, vn) = sample_counts(cfg, alpha, m, l);
        (m, l, un, vn, cfg.roughness.to_bits())
    }

    fn held(&self) -> std::sync::MutexGuard<'_, Held> {
        self.held
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn lookup(&self, key: &FitKey) -> Option<FitSystem> {
        let mut held = self.held();
        let now = held.tick();
        let c = held.map.get_mut(key)?;
        c.used = now;
        Some(c.sys.clone())
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
        let bytes = sys.cached_bytes();
        if bytes <= self.budget {
            let mut held = self.held();
            held.make_room(bytes, self.budget);
            let used = held.tick();
            let cached = Cached {
                sys: sys.clone(),
                bytes,
                used,
            };
            if let Some(old) = held.map.insert(key, cached) {
                held.bytes -= old.bytes;
            }
            held.bytes += bytes;
            tracing::debug!(
                m,
                l,
                systems = held.map.len(),
                bytes = held.bytes,
                "fit system cached"
            );
        }
        Ok(sys)
    }

    /// Whether the system of an `m × l` grid sampled with `alpha` is cached.
    pub fn contains(&self, cfg: &FitConfig, alpha: f64, m: usize, l: usize) -> bool {
        self.held().map.contains_key(&Self::key(cfg, alpha, m, l))
    }

    /// Number of systems held and their bytes.
    pub fn held_bytes(&self) -> (usize, usize) {
        let held = self.held();
        (held.map.len(), held.bytes)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes_of(cfg: &FitConfig, m: usize, l: usize) -> usize {
        FitCache::new(1024)
            .get(cfg, cfg.alpha, m, l)
            .unwrap()
            .cached_bytes()
    }

    #[test]
    fn the_cache_holds_its_budget_and_drops_the_least_recently_used_first() {
        let cfg = FitConfig::default();
        let (small, large) = (bytes_of(&cfg, 8, 6), bytes_of(&cfg, 40, 25));
        assert!(large > 4 * small, "{small} {large}");
        // Room for the large system and two small ones, not for a third.
        let mib = (large + 2 * small).div_ceil(1 << 20);
        let budget = mib << 20;
        let fits = FitCache::new(mib);
        fits.get(&cfg, cfg.alpha, 40, 25).unwrap();
        fits.get(&cfg, cfg.alpha, 8, 6).unwrap();
        fits.get(&cfg, cfg.alpha, 8, 8).unwrap();
        // Use the large system again: the 8 × 6 one is now the oldest.
        fits.get(&cfg, cfg.alpha, 40, 25).unwrap();
        let mut m = 10;
        while fits.held_bytes().1 + bytes_of(&cfg, m, 6) <= budget {
            fits.get(&cfg, cfg.alpha, m, 6).unwrap();
            m += 2;
        }
        fits.get(&cfg, cfg.alpha, m, 6).unwrap();
        let (_, held) = fits.held_bytes();
        assert!(held <= budget, "{held} > {budget}");
        assert!(!fits.contains(&cfg, cfg.alpha, 8, 6));
        assert!(fits.contains(&cfg, cfg.alpha, 40, 25));
        assert!(fits.contains(&cfg, cfg.alpha, m, 6));
    }

    #[test]
    fn a_system_larger_than_the_budget_is_factored_but_not_kept() {
        let cfg = FitConfig::default();
        let fits = FitCache::new(1);
        assert!(bytes_of(&cfg, 40, 25) > 1 << 20);
        let sys = fits.get(&cfg, cfg.alpha, 40, 25).unwrap();
        assert_eq!(sys.layout().m, 40);
        assert_eq!(fits.held_bytes(), (0, 0));
    }
}
