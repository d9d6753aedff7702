//! The pole-axis choice of a cold whole object.
//!
//! The membrane is a sphere topologically, and where its poles sit decides
//! how it meets a tunnel or a deep cavity: with the poles in a torus's hole
//! the two hole caps stall apart, while from the side the ring is wrapped
//! closely. A cold whole object whose membrane leaves data-free parts (less
//! than `init.pole_axis_support` of its mesh vertices near a point) is therefore
//! reconstructed along up to `init.pole_axis_candidates` pole axes (the
//! configured one, then the most different bounding-box edge), and the
//! result with the highest final `η_g` × point coverage is kept.

use super::config::{MembraneConfig, PoleAxis};
use super::evolve::evolve;
use super::fit::{FitCache, Fits};
use super::init::quantile_bounds;
use super::prepare::prepare;
use super::view::FreeSpace;
use super::{Budget, MembraneError, Reconstruction, StopReason, WarmStart};
use crate::cloud::{PointCloud, Vec3};
use crate::mesh::TriMesh;
use crate::spatial::nearest;
use std::time::Instant;

/// The evolution along the configured pole axis and, for a cold whole
/// object with an automatic axis (`shortest`/`longest`) whose first
/// reconstruction has a [`support`] below `init.pole_axis_support`, along up to
/// `init.pole_axis_candidates − 1` other axes, the most different bounding-box
/// edge first. The reconstruction with the highest [`selection_score`] is
/// kept.
pub(crate) fn reconstruct(
    cloud: &PointCloud,
    cfg: &MembraneConfig,
    cache: &FitCache,
    budget: &Budget,
    warm: Option<&WarmStart>,
    free: Option<&dyn FreeSpace>,
) -> Result<Reconstruction, MembraneError> {
    let t0 = Instant::now();
    let prep = prepare(cloud, cfg, free)?;
    let alpha = if warm.is_some() {
        cfg.fit.alpha_warm
    } else {
        cfg.fit.alpha
    };
    let run = |warm: Option<&WarmStart>, pole: Option<usize>| {
        evolve(
            &prep,
            cfg,
            budget,
            warm,
            pole,
            &mut Fits::new(&cfg.fit, cache, alpha),
        )
    };
    let first = run(warm, None)?;
    let within_budget = |r: &Reconstruction| {
        matches!(
            r.report.stop,
            StopReason::Converged | StopReason::MaxIterations
        )
    };
    let init = &cfg.init;
    let farthest_first = match init.pole_axis {
        PoleAxis::Shortest => true,
        PoleAxis::Longest => false,
        PoleAxis::X | PoleAxis::Y | PoleAxis::Z => return Ok(first),
    };
    if init.pole_axis_candidates <= 1
        || warm.is_some()
        || prep.is_single_view()
        || prep.free.is_some()
        || !within_budget(&first)
    {
        return Ok(first);
    }
    // A membrane lying on the data everywhere has nothing to gain from
    // another axis; one spanning a hole or a cavity opening has.
    if support(&first, &prep.points) >= init.pole_axis_support {
        return Ok(first);
    }
    let (lo, hi) = quantile_bounds(&prep.points, init.quantile);
    let extent = hi - lo;
    let mut others: Vec<usize> = (0..3).filter(|&a| a != first.report.pole_axis).collect();
    others.sort_by(|&a, &b| extent[a].total_cmp(&extent[b]));
    if farthest_first {
        others.reverse();
    }
    others.truncate(init.pole_axis_candidates - 1);
    let mut best_score = selection_score(&first, &prep.points);
    let mut best = first;
    let mut tried = 1;
    let mut discarded_ms = 0.0;
    for axis in others {
        let t = Instant::now();
        tried += 1;
        // A failure along another axis keeps what we have; so does a run
        // cut short by the deadline (its score is not comparable).
        match run(None, Some(axis)) {
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
