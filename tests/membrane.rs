//! End-to-end tests of the separability membrane: convergence on analytic
//! shapes (F-score against the true surface), robustness to outliers, warm
//! start, budgets, and watertight outward output meshes.
#![allow(clippy::unwrap_used)]

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sepmem::membrane::{
    reconstruct, AttributeWeight, Budget, MembraneConfig, StopReason, WarmStart,
};
use sepmem::{PointCloud, TriMesh, Vec3};
use std::time::{Duration, Instant};

/// Area-uniform random points on the ellipsoid with semi-axes `a`, centred
/// at `c`: uniform directions mapped onto the ellipsoid, accepted with
/// probability proportional to the map's area element `a_x a_y a_z ‖d/a‖`.
fn ellipsoid(n: usize, a: Vec3, c: Vec3, seed: u64) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let d = Vec3::new(
            normal.sample(&mut rng),
            normal.sample(&mut rng),
            normal.sample(&mut rng),
        )
        .normalize();
        let accept = a.min() * Vec3::new(d.x / a.x, d.y / a.y, d.z / a.z).norm();
        if rng.random::<f64>() <= accept {
            out.push(d.component_mul(&a) + c);
        }
    }
    out
}

fn sample_mesh(mesh: &TriMesh, n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let areas: Vec<f64> = (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .collect();
    let total: f64 = areas.iter().sum();
    let mut cum = Vec::with_capacity(areas.len());
    let mut s = 0.0;
    for a in &areas {
        s += a / total;
        cum.push(s);
    }
    (0..n)
        .map(|_| {
            let r: f64 = rng.random();
            let t = cum.partition_point(|&c| c < r).min(areas.len() - 1);
            let [a, b, c] = mesh.corners(t);
            let (mut u, mut v): (f64, f64) = (rng.random(), rng.random());
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            a + (b - a) * u + (c - a) * v
        })
        .collect()
}

/// F-score at τ (absolute) between two point samples.
fn fscore(pred: &[Vec3], gt: &[Vec3], tau: f64) -> f64 {
    let tree = |pts: &[Vec3]| {
        let c: Vec<[f64; 3]> = pts.iter().map(|p| [p.x, p.y, p.z]).collect();
        ImmutableKdTree::<f64, 3>::new_from_slice(&c)
    };
    let (tp, tg) = (tree(pred), tree(gt));
    let frac = |from: &[Vec3], to: &ImmutableKdTree<f64, 3>| {
        from.iter()
            .filter(|p| {
                to.nearest_one::<SquaredEuclidean>(&[p.x, p.y, p.z])
                    .distance
                    <= tau * tau
            })
            .count() as f64
            / from.len() as f64
    };
    let precision = frac(pred, &tg);
    let recall = frac(gt, &tp);
    if precision + recall == 0.0 {
        0.0
    } else {
        2.0 * precision * recall / (precision + recall)
    }
}

fn check_mesh(mesh: &TriMesh) {
    let topo = mesh.topology();
    assert!(topo.is_watertight(), "mesh not watertight: {topo:?}");
    assert!(mesh.signed_volume() > 0.0, "mesh not outward");
    let eta = mesh.scalar("separability").unwrap();
    assert_eq!(eta.len(), mesh.vertices.len());
    assert!(eta
        .iter()
        .all(|e| e.is_finite() && *e >= 0.0 && *e <= 1.0 + 1e-6));
}

fn serial() -> MembraneConfig {
    let mut cfg = MembraneConfig::default();
    cfg.step.threads = 1;
    cfg
}

fn score(mesh: &TriMesh, gt_dense: &[Vec3]) -> f64 {
    fscore(&sample_mesh(mesh, 100_000, 7), gt_dense, 0.01)
}

/// F-score of the default (one-thread) membrane on `n` clean samplings of
/// 20,000 points of `gt` (seeds 1..=n), each output checked for
/// watertightness: the per-sampling scores and their mean.
fn clean_samplings_f(gt: &TriMesh, n: u64) -> (Vec<f64>, f64) {
    let dense = sample_mesh(gt, 100_000, 98);
    let fs: Vec<f64> = (1..=n)
        .map(|seed| {
            let cloud = PointCloud::from_points(sample_mesh(gt, 20_000, seed));
            let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
            check_mesh(&rec.mesh);
            score(&rec.mesh, &dense)
        })
        .collect();
    let mean = fs.iter().sum::<f64>() / fs.len() as f64;
    (fs, mean)
}

#[test]
fn sphere_converges() {
    let a = Vec3::repeat(0.5);
    let c = Vec3::new(0.3, -0.2, 1.0);
    let cloud = PointCloud::from_points(ellipsoid(8_000, a, c, 1));
    let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    check_mesh(&rec.mesh);
    let f = score(&rec.mesh, &ellipsoid(100_000, a, c, 99));
    eprintln!("sphere: F={f:.4} report={:?}", rec.report);
    assert!(f >= 0.97, "sphere F = {f}");
}

/// A thick-walled bowl (unit longest edge) from 20,000 clean surface points,
/// four samplings: the membrane must fill the bowl's hollow. Mean F 0.995
/// (0.981–1.000); 0.827 with `inner_margin` 0 (samples jump through the
/// wall to its other face and the membrane crumples there), 0.805 without
/// the cavity case of the inward force (the cap that descended into the
/// hollow stalls below the centroid), 0.75 with neither.
#[test]
fn bowl_hollow_is_entered_on_clean_points() {
    let gt = sepmem::shapes::bowl(96).unwrap().mesh;
    let (fs, mean) = clean_samplings_f(&gt, 4);
    eprintln!("bowl: F {fs:.3?}, mean {mean:.3}");
    assert!(mean >= 0.93, "bowl mean F = {mean} ({fs:?})");
}

/// The procedural mug (genus 1, unit longest edge) from 20,000 clean
/// points, two samplings, with and without the sample redistribution along
/// the rings. The poles lie on the mug's short horizontal axis, so the sheet
/// that pushes into the cup spans the rings; without redistribution its few
/// columns stall in a coarse V halfway down. Measured: mean F 0.769 with,
/// 0.732 without.
#[test]
fn mug_cavity_gets_samples_from_the_ring_redistribution() {
    let gt = sepmem::shapes::mug(128).unwrap().mesh;
    let dense = sample_mesh(&gt, 100_000, 98);
    let run = |stretch: Option<f64>| -> f64 {
        let mut cfg = serial();
        cfg.fit.redistribute_stretch = stretch;
        (1..=2)
            .map(|seed| {
                let cloud = PointCloud::from_points(sample_mesh(&gt, 20_000, seed));
                let rec = reconstruct(&cloud, &cfg, &Budget::unlimited(), None).unwrap();
                check_mesh(&rec.mesh);
                score(&rec.mesh, &dense)
            })
            .sum::<f64>()
            / 2.0
    };
    let (on, off) = (
        run(MembraneConfig::default().fit.redistribute_stretch),
        run(None),
    );
    eprintln!("mug: mean F {on:.3} with redistribution, {off:.3} without");
    assert!(
        on >= 0.75,
        "mug mean F = {on} (without redistribution {off})"
    );
    assert!(on >= off + 0.015, "redistribution: mug F {off} -> {on}");
}

/// The procedural torus (unit longest edge, axis z) from 20,000 clean
/// points. Along the shortest edge (the default first axis) the poles sit
/// in the hole, whose two caps then stall apart; the second candidate
/// (the longest edge) wraps the ring from the side and wins the selection.
/// Measured: F 0.893 with one axis, 0.939 with two.
#[test]
fn torus_pole_axis_selection_takes_the_poles_out_of_the_hole() {
    let gt = sepmem::shapes::torus(128).unwrap().mesh;
    let dense = sample_mesh(&gt, 100_000, 98);
    let cloud = PointCloud::from_points(sample_mesh(&gt, 20_000, 1));
    let run = |candidates: usize| {
        let mut cfg = serial();
        cfg.init.pole_axis_candidates = candidates;
        let rec = reconstruct(&cloud, &cfg, &Budget::unlimited(), None).unwrap();
        check_mesh(&rec.mesh);
        (score(&rec.mesh, &dense), rec.report)
    };
    let (f1, r1) = run(1);
    let (f2, r2) = run(2);
    eprintln!(
        "torus: F {f1:.3} (axis {}, 1 tried), {f2:.3} (axis {}, {} tried, other axes {:.1} ms)",
        r1.pole_axis, r2.pole_axis, r2.pole_axes_tried, r2.times.other_axes_ms
    );
    assert_eq!(r1.pole_axis, 2, "the torus's shortest edge is its axis");
    assert_eq!((r1.pole_axes_tried, r2.pole_axes_tried), (1, 2));
    assert_ne!(r2.pole_axis, 2, "the selection kept the poles in the hole");
    assert!(r2.times.other_axes_ms > 0.0);
    assert!(f2 >= 0.92, "torus F with two pole axes = {f2}");
    assert!(f2 >= f1 + 0.02, "pole-axis selection: torus F {f1} -> {f2}");
}

/// Spot the cow (K. Crane, public domain; unit longest edge) from 20,000
/// clean points, two samplings. Wrapping the legs folds parts of the
/// membrane over (their normals turn to face the object) in the empty space
/// between the legs; the gated inward force pulls such a pocket toward
/// whichever side of its normal line holds the object. Measured: mean F
/// 0.89 with that rule, 0.74 when a folded-over pocket is left where it is
/// (a sheet hangs between the legs).
#[test]
fn spot_folded_pockets_between_the_legs_are_pulled_in() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/spot_low_resolution.obj"
    );
    let mut gt = sepmem::io::load_mesh(path).unwrap().mesh;
    sepmem::shapes::normalise_unit_longest_edge(&mut gt);
    let (fs, mean) = clean_samplings_f(&gt, 2);
    eprintln!("spot: F {fs:.3?}, mean {mean:.3}");
    assert!(mean >= 0.83, "spot mean F = {mean} ({fs:?})");
}

#[test]
fn ellipsoid_converges() {
    let a = Vec3::new(0.5, 0.3, 0.2);
    let c = Vec3::zeros();
    let cloud = PointCloud::from_points(ellipsoid(8_000, a, c, 2));
    let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    check_mesh(&rec.mesh);
    let f = score(&rec.mesh, &ellipsoid(100_000, a, c, 98));
    eprintln!("ellipsoid: F={f:.4} report={:?}", rec.report);
    assert!(f >= 0.97, "ellipsoid F = {f}");
}

/// Issue 20: 20,000 points of a procedural shape whose density falls 8:1
/// along its longest axis (`sepmem bench`'s `non_uniform` condition:
/// [`sepmem::bench::clouds::density_falloff`] of 160,000 area-uniform
/// samples). Returns F with `prepare.local_spacing` on (the default) and
/// off (the global δ everywhere).
fn non_uniform_f(name: &str, seed: u64) -> (f64, f64) {
    use sepmem::bench::clouds::{density_falloff, NON_UNIFORM_RATIO};
    let gt = sepmem::shapes::by_name(name, 96).unwrap().mesh;
    let dense = sample_mesh(&gt, 100_000, 98);
    let candidates = sample_mesh(&gt, 160_000, seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 1);
    let pts = density_falloff(&candidates, 20_000, NON_UNIFORM_RATIO, &mut rng);
    assert_eq!(pts.len(), 20_000);
    let cloud = PointCloud::from_points(pts);
    let run = |cfg: &MembraneConfig| {
        let rec = reconstruct(&cloud, cfg, &Budget::unlimited(), None).unwrap();
        check_mesh(&rec.mesh);
        score(&rec.mesh, &dense)
    };
    let mut local = serial();
    local.prepare.local_spacing = Some(sepmem::membrane::LocalSpacingConfig::default());
    let mut global = serial();
    global.prepare.local_spacing = None;
    (run(&local), run(&global))
}

/// The local spacing (`membrane.prepare.local_spacing`) keeps a thinly
/// sampled end of an object from reading as empty space. Measured (seed
/// 21): F 1.000 (ellipsoid) and 1.000 (bottle) with it, 0.702 and 0.609
/// with the global δ, filter and occupancy counts.
#[test]
fn non_uniform_density_is_followed_by_the_local_spacing() {
    for name in ["ellipsoid", "bottle"] {
        let (on, off) = non_uniform_f(name, 21);
        eprintln!("non-uniform {name}: F {on:.4} with the local spacing, {off:.4} without");
        assert!(
            on >= 0.97,
            "non-uniform {name}: F {on} (without local spacing {off})"
        );
        assert!(
            on >= off + 0.1,
            "local spacing: non-uniform {name} F {off} -> {on}"
        );
    }
}

/// A few points far off an object (stray returns 10⁶ m away) are outliers,
/// not a reason to call the object flat: the spread check runs after the
/// outlier filter. Before, their spread dwarfed the sphere's and the cloud
/// was refused as "degenerate: it lies on a plane or a line".
#[test]
fn far_stray_points_do_not_make_an_object_read_as_flat() {
    let a = Vec3::repeat(0.5);
    let mut pts = ellipsoid(3_000, a, Vec3::zeros(), 5);
    pts.extend((0..5).map(|i| Vec3::new(1e6, 1e6 + f64::from(i), -1e6)));
    let cloud = PointCloud::from_points(pts);
    let truth = ellipsoid(100_000, a, Vec3::zeros(), 97);
    // The outlier filter drops them when the detached-group filter (which
    // drops them first by default) is off.
    let mut outliers_only = serial();
    outliers_only.prepare.detached = None;
    let rec = reconstruct(&cloud, &outliers_only, &Budget::unlimited(), None).unwrap();
    check_mesh(&rec.mesh);
    assert!(rec.report.points_outliers >= 5, "{:?}", rec.report);
    let f = score(&rec.mesh, &truth);
    assert!(f >= 0.95, "sphere with far stray points: F = {f}");
    let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    assert_eq!(rec.report.points_detached, 5, "{:?}", rec.report);
    let f = score(&rec.mesh, &truth);
    assert!(f >= 0.95, "sphere with far stray points, detached: F = {f}");
}

/// The membrane's mesh does not depend on the unit of its cloud within
/// [`sepmem::cloud::EXTENT_RANGE`] (a micrometre-sized and a 1 000 km
/// sphere score as the unit one), and a cloud beyond that range gets a
/// typed error that says so. Before the range check, a sphere of radius
/// 1e150 "converged" to η 0 everywhere, and those of 1e200 and 1e-200
/// were refused as lying on a plane (their covariance overflowed).
#[test]
fn a_clouds_unit_does_not_change_its_mesh_and_beyond_the_range_it_is_refused() {
    let a = Vec3::repeat(0.5);
    let pts = ellipsoid(2_000, a, Vec3::zeros(), 5);
    let truth = ellipsoid(50_000, a, Vec3::zeros(), 97);
    for scale in [1e-6, 1.0, 1e6] {
        let cloud = PointCloud::from_points(pts.iter().map(|p| p * scale).collect());
        let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
        check_mesh(&rec.mesh);
        let scaled: Vec<Vec3> = truth.iter().map(|p| p * scale).collect();
        let f = fscore(&sample_mesh(&rec.mesh, 50_000, 7), &scaled, 0.01 * scale);
        assert!(f >= 0.95, "sphere at scale {scale}: F = {f}");
    }
    for scale in [1e-200, 1e-12, 1e12, 1e150, 1e200] {
        let cloud = PointCloud::from_points(pts.iter().map(|p| p * scale).collect());
        let err = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap_err();
        assert!(
            err.to_string().contains("outside the supported"),
            "scale {scale}: {err}"
        );
    }
}

/// A cloud with too few usable points says what became of the others:
/// 10 000 copies of 5 points 1 m apart (and a NaN each) leave 5 points,
/// which the detached-group filter takes for one body and four strays.
#[test]
fn a_cloud_of_too_few_usable_points_says_what_became_of_the_others() {
    let five: Vec<Vec3> = (0..5).map(|k| Vec3::new(f64::from(k), 0.0, 1.0)).collect();
    let mut pts: Vec<Vec3> = five.iter().cycle().take(10_000).copied().collect();
    pts.extend((0..10_000).map(|_| Vec3::new(f64::NAN, 0.0, 0.0)));
    let cloud = PointCloud::from_points(pts);
    let err = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap_err();
    let said = err.to_string();
    for part in [
        "1 of the cloud's 20000 points are usable",
        "10000 non-finite",
        "9995 duplicates",
        "4 detached",
        "at least 16",
    ] {
        assert!(said.contains(part), "{said}");
    }
}

/// A dense group of points far off the object (a mask that bled onto the
/// wall behind it: 600 points on a patch 2.4 diameters away) is no
/// outlier, point by point, but it is detached from the object's body, and
/// the membrane wraps the object alone (`membrane.prepare.detached`).
/// Without that filter the membrane wraps both (F 0.000, checked below).
#[test]
fn a_group_of_points_detached_from_the_object_is_dropped() {
    let a = Vec3::repeat(0.5);
    let mut pts = ellipsoid(3_000, a, Vec3::zeros(), 5);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    pts.extend((0..600).map(|_| {
        let (u, v): (f64, f64) = (rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1));
        Vec3::new(3.0 + u, v, 0.3)
    }));
    let cloud = PointCloud::from_points(pts);
    let truth = ellipsoid(100_000, a, Vec3::zeros(), 97);
    let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    check_mesh(&rec.mesh);
    assert_eq!(rec.report.points_detached, 600, "{:?}", rec.report);
    let f = score(&rec.mesh, &truth);
    assert!(f >= 0.95, "sphere with a detached patch: F = {f}");
    let mut keep = serial();
    keep.prepare.detached = None;
    let rec = reconstruct(&cloud, &keep, &Budget::unlimited(), None).unwrap();
    let f = score(&rec.mesh, &truth);
    assert!(f < 0.5, "the patch kept: F = {f}");
}

/// The paper's robustness sweep on a unit-diameter sphere: 1,000 surface
/// points (sampling `seed`) plus 1,000 duplicates perturbed with N(0, σ²)
/// per coordinate. Returns the F-score of the reconstruction.
fn sphere_with_duplicates_f(sigma: f64, seed: u64) -> f64 {
    let a = Vec3::repeat(0.5);
    let surface = ellipsoid(1_000, a, Vec3::zeros(), seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 1);
    let pts = sepmem::bench::clouds::with_perturbed_duplicates(&surface, sigma, &mut rng);
    let rec = reconstruct(
        &PointCloud::from_points(pts),
        &serial(),
        &Budget::unlimited(),
        None,
    )
    .unwrap();
    check_mesh(&rec.mesh);
    let f = score(&rec.mesh, &ellipsoid(100_000, a, Vec3::zeros(), 97));
    eprintln!(
        "sphere sigma {sigma} seed {seed}: F={f:.4} report={:?}",
        rec.report
    );
    f
}

#[test]
fn sphere_with_outliers_sigma_02() {
    // Measured F 0.966 with δ from the lower quartile of d_i (0.92 with the
    // median).
    let f = sphere_with_duplicates_f(0.2, 3);
    assert!(f >= 0.95, "sphere+outliers F = {f}");
}

/// σ = 0.1, the hardest level of the sweep, over four samplings: a pole
/// caught in the outlier shell must not stay out as a horn. Mean F 0.920
/// (0.880–0.969); 0.872 without the pole tension (`pole_tension` 0).
#[test]
fn sphere_sweep_sigma_01_poles_are_not_left_as_horns() {
    let fs: Vec<f64> = (10..14)
        .map(|seed| sphere_with_duplicates_f(0.1, seed))
        .collect();
    let mean = fs.iter().sum::<f64>() / fs.len() as f64;
    eprintln!("sphere sigma 0.1: F {fs:.3?}, mean {mean:.3}");
    assert!(mean >= 0.90, "sphere sigma 0.1 mean F = {mean} ({fs:?})");
}

#[test]
fn sampled_density_filters_outliers_and_finds_delta_like_the_exact_one() {
    // membrane.prepare.density_sample (the warm frames' fast prepare): d_i of 256
    // points only and a voxel-count outlier filter, against the paper's
    // per-point filter, on a sphere with 5 % uniform outliers around it.
    let a = Vec3::repeat(0.5);
    let mut pts = ellipsoid(8_000, a, Vec3::zeros(), 5);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let outliers = 400;
    for _ in 0..outliers {
        pts.push(Vec3::new(
            rng.random_range(-0.6..0.6),
            rng.random_range(-0.6..0.6),
            rng.random_range(-0.6..0.6),
        ));
    }
    let cloud = PointCloud::from_points(pts);
    let gt = ellipsoid(100_000, a, Vec3::zeros(), 96);
    let exact = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    let mut sampled_cfg = serial();
    sampled_cfg.prepare.density_sample = Some(256);
    let sampled = reconstruct(&cloud, &sampled_cfg, &Budget::unlimited(), None).unwrap();
    let (re, rs) = (&exact.report, &sampled.report);
    eprintln!(
        "exact: delta {:.5} outliers {}; sampled: delta {:.5} outliers {}",
        re.delta, re.points_outliers, rs.delta, rs.points_outliers
    );
    assert!(
        (rs.delta / re.delta - 1.0).abs() < 0.1,
        "sampled delta {} vs exact {}",
        rs.delta,
        re.delta
    );
    // Most of the 400 outliers go, and few surface points with them.
    assert!(
        rs.points_outliers >= 300 && rs.points_outliers <= outliers + 160,
        "sampled filter dropped {} points",
        rs.points_outliers
    );
    check_mesh(&sampled.mesh);
    let (fe, fs) = (score(&exact.mesh, &gt), score(&sampled.mesh, &gt));
    eprintln!("F exact {fe:.4} sampled {fs:.4}");
    assert!(
        fs >= 0.95 && fs >= fe - 0.02,
        "F sampled {fs} vs exact {fe}"
    );
}

#[test]
fn warm_start_converges_faster_than_cold() {
    let a = Vec3::new(0.5, 0.4, 0.35);
    let cloud0 = PointCloud::from_points(ellipsoid(6_000, a, Vec3::zeros(), 5));
    let cfg = serial();
    let first = reconstruct(&cloud0, &cfg, &Budget::unlimited(), None).unwrap();
    // The object moved slightly: the previous surface is a warm start.
    let shift = Vec3::new(0.015, -0.01, 0.01);
    let moved: Vec<Vec3> = ellipsoid(6_000, a, shift, 6);
    let cloud1 = PointCloud::from_points(moved);
    let cold = reconstruct(&cloud1, &cfg, &Budget::unlimited(), None).unwrap();
    let warm = reconstruct(
        &cloud1,
        &cfg,
        &Budget::unlimited(),
        Some(&WarmStart {
            surface: first.surface.clone(),
            phase: 0,
        }),
    )
    .unwrap();
    check_mesh(&warm.mesh);
    let gt = ellipsoid(100_000, a, shift, 96);
    let (fc, fw) = (score(&cold.mesh, &gt), score(&warm.mesh, &gt));
    eprintln!(
        "cold: {} iterations F={fc:.4}; warm: {} iterations F={fw:.4}",
        cold.report.iterations, warm.report.iterations
    );
    assert!(warm.report.warm);
    assert!(warm.report.iterations < cold.report.iterations);
    // A warm start keeps its own pole axis; a cold ellipsoid, whose membrane
    // lies on the data everywhere (support ≥ pole_axis_support), needs no
    // second one either (the torus test below needs it).
    assert_eq!(warm.report.pole_axes_tried, 1);
    assert_eq!(cold.report.pole_axes_tried, 1);
    assert_eq!(warm.report.times.other_axes_ms, 0.0);
    assert!(fw >= 0.97, "warm F = {fw}");
}

#[test]
fn iteration_budget_and_deadline_are_respected() {
    let a = Vec3::new(0.5, 0.4, 0.3);
    let cloud = PointCloud::from_points(ellipsoid(20_000, a, Vec3::zeros(), 8));
    let cfg = serial();
    let rec = reconstruct(&cloud, &cfg, &Budget::iterations(3), None).unwrap();
    check_mesh(&rec.mesh);
    assert_eq!(rec.report.iterations, 3);
    assert_eq!(rec.report.stop, StopReason::IterationBudget);

    // A deadline already passed: no iteration, still a valid enclosing mesh.
    let past = Budget {
        deadline: Some(Instant::now()),
        ..Budget::default()
    };
    let rec = reconstruct(&cloud, &cfg, &past, None).unwrap();
    check_mesh(&rec.mesh);
    assert_eq!(rec.report.iterations, 0);
    assert_eq!(rec.report.stop, StopReason::Deadline);

    // A short deadline: the run stops early, and no iteration starts after
    // the deadline, so it is exceeded by at most one iteration (plus the
    // final mesh pass). Checked with the run's own measured phase times,
    // which keeps the test independent of CPU load: the measured work before
    // the last iteration's start is a lower bound of its start time, which
    // must precede the deadline.
    let full = reconstruct(&cloud, &cfg, &Budget::unlimited(), None).unwrap();
    let allowed = Duration::from_secs_f64(full.report.times.total_ms / 3e3);
    let allowed_ms = allowed.as_secs_f64() * 1e3;
    let rec = reconstruct(&cloud, &cfg, &Budget::within(allowed), None).unwrap();
    check_mesh(&rec.mesh);
    let r = &rec.report;
    assert_eq!(r.stop, StopReason::Deadline);
    assert!(r.iterations < full.report.iterations);
    let n = r.iteration_ms.len();
    assert_eq!(n, r.iterations);
    if n > 0 {
        let before_last: f64 =
            r.times.prepare_ms + r.times.init_ms + r.iteration_ms[..n - 1].iter().sum::<f64>();
        assert!(
            before_last <= allowed_ms,
            "the last iteration started after the deadline: {before_last:.1} ms > {allowed_ms:.1} ms"
        );
    }
}

/// A sphere cloud where five points are each repeated 2,000 times (a driver
/// re-sending a stale buffer, a careless merge): the repeats are dropped and
/// counted. Kept, they made most k-NN distances 0 and δ collapse (η_g 0).
#[test]
fn exact_duplicate_points_are_dropped_and_counted() {
    let a = Vec3::repeat(0.5);
    let mut pts = ellipsoid(3_000, a, Vec3::zeros(), 11);
    let repeated: Vec<Vec3> = pts[..5].to_vec();
    for p in &repeated {
        pts.extend(std::iter::repeat_n(*p, 2_000));
    }
    let cloud = PointCloud::from_points(pts);
    let rec = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    check_mesh(&rec.mesh);
    assert_eq!(rec.report.points_duplicate, 10_000);
    let f = score(&rec.mesh, &ellipsoid(100_000, a, Vec3::zeros(), 12));
    eprintln!(
        "sphere with repeats: F={f:.4} eta_g={:.3}",
        rec.report.eta_final
    );
    assert!(f >= 0.97, "F = {f}");
}

#[test]
fn bad_inputs_give_errors_not_panics() {
    let cfg = serial();
    assert!(reconstruct(&PointCloud::default(), &cfg, &Budget::unlimited(), None).is_err());
    let nan = PointCloud::from_points(vec![Vec3::new(f64::NAN, 0.0, 0.0); 100]);
    assert!(reconstruct(&nan, &cfg, &Budget::unlimited(), None).is_err());
    let flat = PointCloud::from_points(
        (0..500)
            .map(|i| Vec3::new((i % 25) as f64, (i / 25) as f64, 0.0))
            .collect(),
    );
    assert!(reconstruct(&flat, &cfg, &Budget::unlimited(), None).is_err());
    let mut bad = serial();
    bad.step.beta = 0.0;
    let ok = PointCloud::from_points(ellipsoid(500, Vec3::repeat(0.5), Vec3::zeros(), 9));
    let err = reconstruct(&ok, &bad, &Budget::unlimited(), None).unwrap_err();
    assert!(err.to_string().contains("`step.beta`"), "{err}");
}

#[test]
fn colour_weighting_separates_object_from_same_density_clutter() {
    // A white sphere (r = 0.5) inside a dark concentric shell of clutter
    // (r = 0.6) with as many points: spatially the shell is the outermost
    // dense layer, so the spatial-only membrane settles on it; with the
    // colour (luma) separability weighted in (paper Eq. 9) the boundary
    // between the white and the dark layer wins and the membrane finds the
    // object.
    let inner = ellipsoid(2_000, Vec3::repeat(0.5), Vec3::zeros(), 21);
    let outer = ellipsoid(2_000, Vec3::repeat(0.6), Vec3::zeros(), 22);
    let n = inner.len();
    let mut pts = inner;
    pts.extend(outer);
    let mut cloud = PointCloud::from_points(pts);
    let shade: Vec<f32> = (0..2 * n).map(|i| if i < n { 1.0 } else { 0.15 }).collect();
    for ch in ["r", "g", "b"] {
        cloud.set_attribute(ch, shade.clone()).unwrap();
    }
    let gt = ellipsoid(100_000, Vec3::repeat(0.5), Vec3::zeros(), 95);
    let spatial = reconstruct(&cloud, &serial(), &Budget::unlimited(), None).unwrap();
    let mut weighted_cfg = serial();
    weighted_cfg.step.spatial_weight = 1.0;
    weighted_cfg.step.attributes = vec![AttributeWeight {
        name: "luma".into(),
        weight: 1.0,
    }];
    let weighted = reconstruct(&cloud, &weighted_cfg, &Budget::unlimited(), None).unwrap();
    check_mesh(&weighted.mesh);
    let (fs, fw) = (score(&spatial.mesh, &gt), score(&weighted.mesh, &gt));
    eprintln!("white sphere in a dark shell: spatial F={fs:.4}, spatial+luma F={fw:.4}");
    assert!(fw >= 0.9, "weighted F = {fw}");
    assert!(fw >= fs + 0.3, "weighting must help: {fs} -> {fw}");

    // A channel the cloud does not carry is a typed error.
    let mut missing = serial();
    missing.step.attributes = vec![AttributeWeight {
        name: "temperature".into(),
        weight: 1.0,
    }];
    let err = reconstruct(&cloud, &missing, &Budget::unlimited(), None).unwrap_err();
    assert!(err.to_string().contains("temperature"), "{err}");
}
