//! The evolution loop of the separability membrane (paper §III-D steps 1–5):
//! sample → step → regularize → fit → schedule.
//!
//! Each iteration samples the surface on the grid of Eq. 14 ([`super::fit`]),
//! runs the oriented separability search with its shift rule at every
//! sample ([`super::step`]), regularises the shifts ([`super::regularize`]),
//! moves the samples by `β·shift` along their normals and refits the control
//! net ([`super::fit`]); [`super::schedule`] (§III-F) then decays the depth
//! and decides whether to continue, grow the grid or stop. `η_g` is the mean
//! of the per-sample accepted maxima `η*`.
//!
//! Whole objects redistribute their samples along the rings
//! (`fit.redistribute_stretch`): the sample grid is fixed in `(u, v)`, so where
//! the membrane stretches (a sheet pushed into a cavity whose opening lies
//! across the rings) its samples and control columns thin out and the sheet
//! stalls in a coarse V. When a ring's largest arc length per unit `u`
//! exceeds `fit.redistribute_stretch` × its mean, the refitted surface is
//! refitted once more to itself at the arc-length parameters.

use super::config::{MembraneConfig, SearchDelta};
use super::enclose;
use super::extract::extract_mesh;
use super::fit::Fits;
use super::prepare::Prepared;
use super::regularize::{self, Samples};
use super::schedule::{Next, Schedule};
use super::step::{Pass, SampleOut, Stepper, ThreadScratch};
use super::unbias;
use super::view::Seen;
use super::{
    init, Budget, MembraneError, PhaseTimes, Reconstruction, Report, StopReason, WarmStart,
};
use crate::cloud::Vec3;
use crate::separability::search::{Delta, Searcher};
use crate::spline::{param_stretch, redistribute, regrid, ClosedSurface, FitSystem};
use std::time::Instant;

/// Rings over which the ring stretch of `fit.redistribute_stretch` is averaged.
const STRETCH_RINGS: usize = 16;

/// The per-sample search over prepared points.
fn stepper<'a>(
    prep: &'a Prepared<'_>,
    cfg: &'a MembraneConfig,
    warm: bool,
) -> Result<Stepper<'a>, MembraneError> {
    let delta = match (cfg.prepare.search_delta, prep.spacing.as_deref()) {
        (SearchDelta::Local, _) => Delta::Local(&prep.d_used),
        // The mean of the per-point spacing over the cuboid's points (membrane/spacing.rs).
        (SearchDelta::Global, Some(spacing)) => Delta::Local(spacing),
        (SearchDelta::Global, None) => Delta::Global(prep.delta),
    };
    let searcher = Searcher::new(&prep.index, delta, cfg.step.boundaries)?;
    let searcher = match &prep.attributes {
        Some(a) => searcher.with_attributes(a)?,
        None => searcher,
    };
    Ok(Stepper {
        cfg: &cfg.step,
        searcher,
        delta: prep.delta,
        outside: prep.outside.as_ref(),
        seen: prep.seen(),
        cross_max: cfg.step.cross_max * prep.scale,
        center: prep.points.iter().sum::<Vec3>() / prep.points.len() as f64,
        reach: prep.scale,
        facing: cfg.step.facing_away.as_ref().map(|f| f.bound(warm)),
        eyes: prep.seen().fused_eyes(),
    })
}

/// The reused buffers of one evolution.
#[derive(Default)]
struct Buffers {
    scratches: Vec<ThreadScratch>,
    outs: Vec<SampleOut>,
    fills: Vec<(usize, SampleOut)>,
    shifts: Vec<f64>,
    targets: Vec<Vec3>,
    arc: Vec<f64>,
    regularize: regularize::Scratch,
    /// Per-sample η* of the last iteration and its grid: the output's
    /// per-vertex separability when the grid did not change after it.
    last_eta: Vec<f64>,
    last_eta_grid: [usize; 2],
}

/// Evolve the membrane on prepared points (see the module docs) from a
/// warm start or, cold, from the octagon around the poles on `pole` (0 = x,
/// 1 = y, 2 = z; `None`: the configured axis), drawing fit systems from
/// `fits`.
pub(crate) fn evolve(
    prep: &Prepared<'_>,
    cfg: &MembraneConfig,
    budget: &Budget,
    warm: Option<&WarmStart>,
    pole: Option<usize>,
    fits: &mut Fits<'_>,
) -> Result<Reconstruction, MembraneError> {
    let t_start = Instant::now();
    let t_init = Instant::now();
    let (mut surface, pole_axis) =
        init::initial(&prep.points, &cfg.init, warm, prep.eye(), pole, fits)?;
    if let (Some(_), Some(e), Seen::Views(..)) = (warm, &cfg.init.warm_enclose, prep.seen()) {
        let fit = fits.get(surface.m(), surface.l())?;
        let (margin, pad) = (e.margin_delta * prep.delta, e.pad_delta * prep.delta);
        enclose::enclose(&mut surface, fit, &prep.points, margin, pad)?;
    }
    let mut times = PhaseTimes {
        prepare_ms: prep.prepare_ms,
        init_ms: ms(t_init),
        ..PhaseTimes::default()
    };
    let stepper = stepper(prep, cfg, warm.is_some())?;
    let sc = &cfg.schedule;
    let floor = sc.depth_floor_delta * prep.delta;
    let depth = if warm.is_some() {
        sc.depth_warm
    } else {
        sc.depth_start
    } * prep.scale;
    let grid = [surface.m(), surface.l()];
    let mut schedule = Schedule::new(sc, budget, depth, floor, grid, prep.points.len());
    let chunks = 4 * rayon::current_num_threads().max(1);
    let mut b = Buffers {
        scratches: (0..chunks).map(|_| ThreadScratch::default()).collect(),
        ..Buffers::default()
    };
    let stop = loop {
        let (m, l) = (surface.m(), surface.l());
        let (un, vn) = fits.samples(m, l);
        if let Some(stop) = schedule.budget_stop(un * vn) {
            break stop;
        }
        let t_it = Instant::now();
        let fit = fits.get(m, l)?;
        let layout = fit.layout().clone();
        let t_search = Instant::now();
        // Sparse search: a checkerboard half of the samples, the half
        // alternating from iteration to iteration (and frame to frame); for
        // warm starts, and for whole objects on the final grid.
        let sparse = if warm.is_some() {
            cfg.step.sparse_warm_search
        } else {
            cfg.step.sparse_cold_search
                && prep.view.is_none()
                && schedule.at_max_grid([m, l])
                && prep.points.len() >= layout.len()
        };
        let it = schedule.iterations();
        let pass = Pass {
            surface: &surface,
            layout: &layout,
            depth: schedule.depth(),
            allow_inward: true,
            skip: sparse.then(|| (it + warm.map_or(0, |w| w.phase)) % 2),
        };
        stepper.search_all(&pass, &mut b.outs, &mut b.scratches);
        if sparse {
            regularize::fill_skipped(&mut b.outs, un, vn, &mut b.fills);
        }
        let eta_g = b.outs.iter().map(|o| o.eta).sum::<f64>() / b.outs.len() as f64;
        b.last_eta.clear();
        b.last_eta.extend(b.outs.iter().map(|o| o.eta));
        b.last_eta_grid = [m, l];
        times.search_ms += ms(t_search);
        move_and_refit(
            prep,
            cfg,
            warm.is_some(),
            &mut surface,
            fit,
            &mut b,
            &mut times,
        )?;
        let next = schedule.next(eta_g, sparse, [m, l], &b.outs, &b.shifts);
        if let Next::Grow([nm, nl]) = next {
            let t_grow = Instant::now();
            surface = regrid(&surface, fits.get(nm, nl)?)?;
            times.fit_ms += ms(t_grow);
        }
        schedule.timed(ms(t_it), layout.len());
        if let Next::Stop(reason) = next {
            break reason;
        }
    };
    let done = Evolved {
        surface,
        pole_axis,
        stop,
        warm: warm.is_some(),
        schedule,
        times,
        t_start,
    };
    finish(prep, &stepper, fits, done, b)
}

/// Regularise the searched shifts in `b.outs`, move the samples by
/// `β·shift` along their normals and refit `surface` to them with `fit`;
/// then, for a whole object whose rings stretched, redistribute its samples
/// along them (see the module docs).
fn move_and_refit(
    prep: &Prepared<'_>,
    cfg: &MembraneConfig,
    warm: bool,
    surface: &mut ClosedSurface,
    fit: &mut FitSystem,
    b: &mut Buffers,
    times: &mut PhaseTimes,
) -> Result<(), MembraneError> {
    let t_reg = Instant::now();
    let (un, vn) = (fit.layout().u_n(), fit.layout().v_n());
    let samples = Samples {
        outs: &b.outs,
        un,
        vn,
    };
    let view = prep.view.as_ref();
    regularize::shifts(
        &cfg.regularize,
        samples,
        view,
        warm,
        &mut b.regularize,
        &mut b.shifts,
    );
    b.targets.clear();
    b.targets.extend(
        b.outs
            .iter()
            .zip(&b.shifts)
            .map(|(o, &s)| o.p + o.n * (cfg.step.beta * s)),
    );
    times.search_ms += ms(t_reg);
    let t_fit = Instant::now();
    // The orientation sign is fixed once (init, regrid; a warm start keeps its own): a
    // refit moves the samples by small shifts and cannot turn the surface
    // inside out.
    fit.fit(surface, &b.targets)?;
    // Sample redistribution along the rings (whole objects): equal u steps
    // become equal arc lengths when the rings have stretched.
    if let (Some(limit), None) = (cfg.fit.redistribute_stretch, view) {
        let stretch = param_stretch(surface, true, STRETCH_RINGS, 2 * un, &mut b.arc);
        if stretch > limit {
            *surface = redistribute(surface, fit, true, &b.arc)?;
            // The searched η* belong to the samples before the move.
            b.last_eta_grid = [0, 0];
        }
    }
    times.fit_ms += ms(t_fit);
    Ok(())
}

/// The end state of an evolution.
struct Evolved<'a> {
    surface: ClosedSurface,
    pole_axis: usize,
    stop: StopReason,
    warm: bool,
    schedule: Schedule<'a>,
    times: PhaseTimes,
    t_start: Instant,
}

/// The final scoring pass and the mesh. The last iteration's search already
/// scored the returned surface's layout (the returned surface is its refit,
/// a sub-δ move): its η* are reused; the surface is searched afresh only
/// when the grid changed after it (or no iteration ran).
fn finish(
    prep: &Prepared<'_>,
    stepper: &Stepper<'_>,
    fits: &mut Fits<'_>,
    done: Evolved<'_>,
    mut b: Buffers,
) -> Result<Reconstruction, MembraneError> {
    let Evolved {
        surface,
        pole_axis,
        stop,
        warm,
        schedule,
        mut times,
        t_start,
    } = done;
    let t_mesh = Instant::now();
    let (m, l) = (surface.m(), surface.l());
    let layout = fits.get(m, l)?.layout().clone();
    let eta: Vec<f64> = if b.last_eta_grid == [m, l] && b.last_eta.len() == layout.len() {
        b.last_eta
    } else {
        let pass = Pass {
            surface: &surface,
            layout: &layout,
            depth: schedule.floor(),
            allow_inward: false,
            skip: None,
        };
        stepper.search_all(&pass, &mut b.outs, &mut b.scratches);
        b.outs.iter().map(|o| o.eta).collect()
    };
    let eta_final = eta.iter().sum::<f64>() / eta.len().max(1) as f64;
    let mesh = extract_mesh(&surface, &layout, &eta);
    let unbias = stepper.cfg.unbias.as_ref().map_or_else(Vec::new, |u| {
        let (d, cmax) = (stepper.delta, stepper.cross_max);
        unbias::centring_bias(&surface, &layout, stepper.cfg, d, cmax, u.max_delta)
    });
    times.mesh_ms = ms(t_mesh);
    times.total_ms = prep.prepare_ms + ms(t_start);
    let c = prep.counts;
    let report = Report {
        points_in: c.input,
        points_non_finite: c.non_finite,
        points_duplicate: c.duplicate,
        points_thinned: c.thinned,
        points_detached: c.detached,
        points_outliers: c.outliers,
        points_used: prep.points.len(),
        points_completed: c.completed,
        viewpoint: prep.view.as_ref().map(|v| {
            let e = v.eye();
            [e.x, e.y, e.z]
        }),
        delta: prep.delta,
        scale: prep.scale,
        grid: [m, l],
        samples: [layout.u_n(), layout.v_n()],
        iterations: schedule.iterations(),
        eta: schedule.eta,
        grids: schedule.grids,
        iteration_ms: schedule.iteration_ms,
        eta_final,
        stop,
        warm,
        pole_axis,
        pole_axes_tried: 1,
        times,
    };
    Ok(Reconstruction {
        mesh,
        surface,
        report,
        unbias,
    })
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}
