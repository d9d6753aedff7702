//! Dynamic membrane adjustment (paper §III-F) as a state machine: the
//! search depth decays, the control grid grows when the global
//! separability stops gaining, and the evolution stops on a plateau, at an
//! iteration cap or at the caller's deadline.
//!
//! After every iteration [`Schedule::next`] takes the iteration's `η_g` and
//! returns [`Next::Continue`], [`Next::Grow`] (with `growth` on, the grid
//! grows by `growth.grid_step` when the gain `Δη_g` fell below
//! `growth.g_min` after at least `growth.grow_after` iterations on the grid;
//! 8×5 → 40×25 by default) or
//! [`Next::Stop`] (on the final grid, `|Δη_g| < plateau_eps` for
//! `plateau_patience` iterations). Before every iteration
//! [`Schedule::budget_stop`] checks the caps and predicts whether another
//! iteration still ends before the deadline.
//!
//! Growth stops at the grid with at most `growth.max_control_per_point`
//! control points per point the membrane uses ([`largest_grid`]): a
//! 50-point segment (a label bomb's, or a far object's) otherwise grew to
//! 40×25 (1,000 control points) and cost as much per iteration as a
//! 20,000-point object. Cold starts of the seven procedural shapes × 3
//! samplings (`cargo bench --bench small_clouds`, F at
//! τ = 0.01 / 0.02 against the mesh, median time), unbounded → bound 2:
//!
//! | points | F τ=0.01 | F τ=0.02 | median ms |
//! |---|---|---|---|
//! | 50 | 0.027 → 0.012 | 0.063 → 0.026 | 937 → 102 |
//! | 150 | 0.116 → 0.121 | 0.315 → 0.311 | 753 → 136 |
//! | 250 | 0.218 → 0.207 | 0.513 → 0.504 | 595 → 222 |
//! | 450 | 0.384 → 0.376 | 0.724 → 0.724 | 577 → 279 |
//! | 700 and more | unchanged (the bound reaches 40×25) | | |
//!
//! From 150 points on, F moves by at most 0.011 while a cold start
//! takes a half to a fifth of the time, within the node's 200 ms cold
//! budget where it used to run out of it; at 50 points every grid scores
//! below 0.07.
//!
//! The depth shrinks by `depth_decay` per iteration, but not below a floor
//! of `depth_floor_delta`·δ, nor below what the membrane still travels
//! (2.5× the 90th percentile of the moving samples' shifts): a fixed decay
//! left far-off parts of the membrane outside their own search range.

use super::config::{GrowthConfig, ScheduleConfig};
use super::step::SampleOut;
use super::{Budget, StopReason};
use std::time::Instant;

/// What the evolution does after an iteration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next {
    /// Iterate again on the same grid.
    Continue,
    /// Regrid to this control grid `[M, L]`, then iterate again.
    Grow([usize; 2]),
    /// Stop.
    Stop(StopReason),
}

/// The schedule of one evolution (see the module docs).
#[derive(Debug)]
pub struct Schedule<'a> {
    cfg: &'a ScheduleConfig,
    budget: &'a Budget,
    depth: f64,
    floor: f64,
    max_grid: [usize; 2],
    iter_on_grid: usize,
    plateau: usize,
    /// Duration (ms) and sample count of the last iteration, for the deadline.
    last: (f64, usize),
    /// η_g at the start of each iteration.
    pub eta: Vec<f64>,
    /// Control grid of each iteration.
    pub grids: Vec<[usize; 2]>,
    /// Wall-clock duration of each iteration (ms).
    pub iteration_ms: Vec<f64>,
    moving: Vec<f64>,
}

impl<'a> Schedule<'a> {
    /// A schedule starting at `depth` (in input units, floored at `floor`)
    /// on `grid`, which may grow ([`largest_grid`]) when `growth` is on;
    /// `points` is the number of points the membrane uses.
    pub fn new(
        cfg: &'a ScheduleConfig,
        budget: &'a Budget,
        depth: f64,
        floor: f64,
        grid: [usize; 2],
        points: usize,
    ) -> Self {
        let max_grid = cfg
            .growth
            .as_ref()
            .map_or(grid, |g| largest_grid(g, grid, points));
        Self {
            cfg,
            budget,
            depth: depth.max(floor),
            floor,
            max_grid,
            iter_on_grid: 0,
            plateau: 0,
            last: (0.0, 1),
            eta: Vec::new(),
            grids: Vec::new(),
            iteration_ms: Vec::new(),
            moving: Vec::new(),
        }
    }

    /// The current search depth.
    pub fn depth(&self) -> f64 {
        self.depth
    }

    /// The depth floor (`depth_floor_delta`·δ), the final scoring pass's depth.
    pub fn floor(&self) -> f64 {
        self.floor
    }

    /// Iterations run so far.
    pub fn iterations(&self) -> usize {
        self.eta.len()
    }

    /// Whether `grid` is the largest the schedule reaches.
    pub fn at_max_grid(&self, grid: [usize; 2]) -> bool {
        grid == self.max_grid
    }

    /// Why no further iteration may start, if so: an iteration cap, a caller
    /// that no longer wants the result, or a
    /// deadline that the next iteration (predicted from the last one,
    /// scaled to `samples`, its sample count) would pass.
    pub fn budget_stop(&self, samples: usize) -> Option<StopReason> {
        let it = self.iterations();
        if it >= self.cfg.max_iterations {
            return Some(StopReason::MaxIterations);
        }
        if self.budget.max_iterations.is_some_and(|n| it >= n) {
            return Some(StopReason::IterationBudget);
        }
        if !self.budget.is_wanted() {
            return Some(StopReason::Cancelled);
        }
        let dl = self
            .budget
            .deadline
            .filter(|_| it >= self.budget.min_iterations)?;
        let predicted = self.last.0 * samples as f64 / self.last.1.max(1) as f64;
        let now = Instant::now();
        (now >= dl || (dl - now).as_secs_f64() * 1e3 < predicted).then_some(StopReason::Deadline)
    }

    /// Record an iteration on `grid` with global separability `eta_g`
    /// (`sparse`: it searched one checkerboard half, and is compared with
    /// the last iteration that searched the same half), decay the depth
    /// against the travel of `outs`/`shifts`, and decide what comes next.
    pub fn next(
        &mut self,
        eta_g: f64,
        sparse: bool,
        grid: [usize; 2],
        outs: &[SampleOut],
        shifts: &[f64],
    ) -> Next {
        self.grids.push(grid);
        let back = if sparse { 2 } else { 1 };
        let prev = self.eta.len().checked_sub(back).map(|k| self.eta[k]);
        self.eta.push(eta_g);
        self.iter_on_grid += 1;
        let travel = self.travel(outs, shifts);
        self.depth = (self.depth * self.cfg.depth_decay)
            .max(travel)
            .min(self.depth)
            .max(self.floor);
        let gain = prev.map_or(f64::INFINITY, |p| eta_g - p);
        let [m, l] = grid;
        if let Some(g) = self.growth_on(grid) {
            if self.iter_on_grid >= g.grow_after.max(1) && gain < g.g_min {
                self.iter_on_grid = 0;
                self.plateau = 0;
                return Next::Grow([
                    (m + g.grid_step[0]).min(self.max_grid[0]),
                    (l + g.grid_step[1]).min(self.max_grid[1]),
                ]);
            }
            return Next::Continue;
        }
        if gain.abs() < self.cfg.plateau_eps {
            self.plateau += 1;
        } else {
            self.plateau = 0;
        }
        if self.plateau >= self.cfg.plateau_patience.max(1) {
            return Next::Stop(StopReason::Converged);
        }
        Next::Continue
    }

    /// The growth parameters while `grid` is below the largest grid.
    fn growth_on(&self, grid: [usize; 2]) -> Option<&'a GrowthConfig> {
        let cfg: &'a ScheduleConfig = self.cfg;
        let below = grid[0] < self.max_grid[0] || grid[1] < self.max_grid[1];
        cfg.growth.as_ref().filter(|_| below)
    }

    /// Record the wall-clock time of the iteration just decided (including a
    /// regrid) and its sample count.
    pub fn timed(&mut self, ms: f64, samples: usize) {
        self.last = (ms, samples);
        self.iteration_ms.push(ms);
    }

    /// What the membrane still travels: 2.5× the 90th percentile of the
    /// moving samples' |shift| (0 when none moves).
    fn travel(&mut self, outs: &[SampleOut], shifts: &[f64]) -> f64 {
        self.moving.clear();
        self.moving.extend(
            outs.iter()
                .zip(shifts)
                .filter(|(o, _)| o.state.moves())
                .map(|(_, s)| s.abs()),
        );
        if self.moving.is_empty() {
            return 0.0;
        }
        let k = (self.moving.len() * 9 / 10).min(self.moving.len() - 1);
        let (_, q, _) = self.moving.select_nth_unstable_by(k, f64::total_cmp);
        2.5 * *q
    }
}

/// The largest grid that growth reaches from `start`: steps of
/// `grid_step` up to `grid_max`, and no step to a grid with more than
/// `max_control_per_point` control points per point of `points`.
pub fn largest_grid(g: &GrowthConfig, start: [usize; 2], points: usize) -> [usize; 2] {
    let cap = [g.grid_max[0].max(start[0]), g.grid_max[1].max(start[1])];
    let allowed = g
        .max_control_per_point
        .map_or(f64::INFINITY, |k| k * points as f64);
    let mut grid = start;
    loop {
        let next = [
            (grid[0] + g.grid_step[0]).min(cap[0]),
            (grid[1] + g.grid_step[1]).min(cap[1]),
        ];
        if next == grid || (next[0] * next[1]) as f64 > allowed {
            return grid;
        }
        grid = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn growth_stops_at_the_points_bound() {
        let mut g = GrowthConfig::default();
        // 2 control points per point, steps of [8, 5] from 8x5.
        assert_eq!(largest_grid(&g, [8, 5], 50), [8, 5]);
        assert_eq!(largest_grid(&g, [8, 5], 80), [16, 10]);
        assert_eq!(largest_grid(&g, [8, 5], 180), [24, 15]);
        assert_eq!(largest_grid(&g, [8, 5], 499), [32, 20]);
        assert_eq!(largest_grid(&g, [8, 5], 500), [40, 25]);
        assert_eq!(largest_grid(&g, [8, 5], 1_000_000), [40, 25]);
        // A warm start on a larger grid keeps it.
        assert_eq!(largest_grid(&g, [48, 30], 10), [48, 30]);
        g.max_control_per_point = None;
        assert_eq!(largest_grid(&g, [8, 5], 1), [40, 25]);
    }

    #[test]
    fn an_iteration_nobody_wants_does_not_start() {
        let cfg = ScheduleConfig::default();
        let owner = std::sync::Arc::new(());
        let budget = Budget {
            wanted: Some(std::sync::Arc::downgrade(&owner)),
            ..Budget::default()
        };
        let schedule = Schedule::new(&cfg, &budget, 1.0, 0.1, [8, 5], 1000);
        assert_eq!(schedule.budget_stop(100), None);
        // Its owner gone, the next iteration is not started.
        drop(owner);
        assert_eq!(schedule.budget_stop(100), Some(StopReason::Cancelled));
        // The iteration caps still come first.
        let capped = Budget {
            max_iterations: Some(0),
            ..budget.clone()
        };
        let schedule = Schedule::new(&cfg, &capped, 1.0, 0.1, [8, 5], 1000);
        assert_eq!(schedule.budget_stop(100), Some(StopReason::IterationBudget));
    }
}
