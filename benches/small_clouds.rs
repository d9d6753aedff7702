//! Cold starts on small clouds, with and without the growth bound
//! `membrane.schedule.growth.max_control_per_point` (the table in
//! `src/membrane/schedule.rs`): the seven procedural shapes × 3
//! samplings per point count, F at τ = 0.01 and 0.02 against the shape's
//! mesh, mean iterations and median wall time.
//!
//! `cargo bench --bench small_clouds -- 50 150 250 450 700` (point counts;
//! those five without arguments).

use sepmem::cloud::PointCloud;
use sepmem::membrane::{Budget, Membrane, MembraneConfig, Start};
use sepmem::metrics::{evaluate, sample_surface, MetricsConfig};
use std::time::Instant;

/// One configuration's runs at one point count.
#[derive(Default)]
struct Runs {
    f01: Vec<f64>,
    f02: Vec<f64>,
    iterations: Vec<f64>,
    ms: Vec<f64>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn fscore(mesh: &sepmem::mesh::TriMesh, gt: &sepmem::mesh::TriMesh, tau: f64) -> f64 {
    let cfg = MetricsConfig {
        samples: 20_000,
        tau,
        seed: 5,
    };
    evaluate(mesh, gt, &cfg).map_or(0.0, |m| m.fscore)
}

fn runs(engine: &Membrane, shapes: &[sepmem::shapes::Shape], n: usize) -> Runs {
    let mut r = Runs::default();
    for (k, shape) in shapes.iter().enumerate() {
        for seed in 0..3u64 {
            let pts = sample_surface(&shape.mesh, n, 1000 + seed * 7 + k as u64)
                .expect("sampling a procedural shape")
                .points;
            let t = Instant::now();
            let rec = engine.reconstruct(
                &PointCloud::from_points(pts),
                &Budget::unlimited(),
                &Start::Cold,
            );
            r.ms.push(t.elapsed().as_secs_f64() * 1e3);
            let (f01, f02, it) = rec.map_or((0.0, 0.0, 0.0), |rec| {
                (
                    fscore(&rec.mesh, &shape.mesh, 0.01),
                    fscore(&rec.mesh, &shape.mesh, 0.02),
                    rec.report.iterations as f64,
                )
            });
            r.f01.push(f01);
            r.f02.push(f02);
            r.iterations.push(it);
        }
    }
    r.ms.sort_by(f64::total_cmp);
    r
}

fn main() {
    let mut counts: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    if counts.is_empty() {
        counts = vec![50, 150, 250, 450, 700];
    }
    let shapes = sepmem::shapes::all(96).expect("procedural shapes");
    for n in counts {
        for bound in [None, Some(2.0)] {
            let mut cfg = MembraneConfig::default();
            if let Some(g) = cfg.schedule.growth.as_mut() {
                g.max_control_per_point = bound;
            }
            let engine = Membrane::new(cfg).expect("valid configuration");
            let r = runs(&engine, &shapes, n);
            println!(
                "{n:5} points, max_control_per_point {bound:?}: F(0.01) {:.4} F(0.02) {:.4} iterations {:.1} median {:.1} ms",
                mean(&r.f01),
                mean(&r.f02),
                mean(&r.iterations),
                r.ms[r.ms.len() / 2]
            );
        }
    }
}
