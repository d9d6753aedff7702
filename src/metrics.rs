//! Reconstruction metrics: the Occupancy Networks / Shape-as-Points protocol.
//!
//! The paper reports Chamfer distance, F-score and normal consistency
//! (§IV-C, Table 1). sepmem follows the `MeshEvaluator` of ONet / ConvONet /
//! SAP:
//!
//! 1. both meshes are normalised with the **ground truth's** bounding box:
//!    centre at the origin, longest edge 1 ([`Normalization`]);
//! 2. each mesh is sampled with `n` area-uniform points carrying the face
//!    normal ([`sample_surface`], seeded and reproducible);
//! 3. nearest-neighbour distances are Euclidean (not squared):
//!    *accuracy* = mean over predicted samples of the distance to the ground
//!    truth, *completeness* = mean over ground-truth samples of the distance
//!    to the prediction;
//! 4. Chamfer-L1 = ½(accuracy + completeness); Chamfer-L2 = ½(mean acc² +
//!    mean comp²);
//! 5. precision / recall = share of accuracy / completeness distances ≤ τ
//!    (τ = 0.01 by default, absolute in the normalised frame), F = 2PR/(P+R);
//! 6. normal consistency = ½(mean |n_pred·n_gt| over accuracy pairs + the
//!    same over completeness pairs).
//!
//! An empty prediction (no triangle of positive area) scores F = 0 with
//! ONet's sentinels: accuracy = completeness = Chamfer-L1 = √3,
//! Chamfer-L2 = 3, normal consistency = −1.

use crate::cloud::{Aabb, Vec3};
use crate::mesh::TriMesh;
use crate::spatial::nearest;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors of the metrics.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MetricsError {
    /// The ground-truth mesh has no triangle of positive area.
    #[error("ground-truth mesh has no surface (no triangle of positive area)")]
    EmptyGroundTruth,
    /// The ground truth's bounding box has no extent.
    #[error("ground-truth mesh is degenerate: bounding box extent {0:?}")]
    DegenerateGroundTruth([f64; 3]),
    /// A triangle refers to a vertex that does not exist.
    #[error("{mesh} mesh: triangle {triangle} refers to vertex {vertex}, but there are {vertices} vertices")]
    BadIndex {
        /// `pred` or `gt`.
        mesh: &'static str,
        /// Triangle index.
        triangle: usize,
        /// Offending vertex index.
        vertex: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// Zero samples or a non-positive / non-finite threshold was requested.
    #[error("metrics: invalid parameter {what} = {value}")]
    BadParameter {
        /// Parameter name.
        what: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Largest `metrics.samples`: 10⁷ samples per mesh need about 1.5 GB
/// (positions, normals, the k-d tree, the distances) for the two meshes;
/// 10⁹ aborted on the allocation before.
pub const MAX_SAMPLES: usize = 10_000_000;

/// Reject `metrics.samples` outside `1..=MAX_SAMPLES` while the
/// configuration is read, naming the key.
fn samples_in_range<'de, D: serde::Deserializer<'de>>(d: D) -> Result<usize, D::Error> {
    let n = usize::deserialize(d)?;
    if n == 0 || n > MAX_SAMPLES {
        return Err(serde::de::Error::custom(format!(
            "metrics.samples = {n} is outside 1..={MAX_SAMPLES}"
        )));
    }
    Ok(n)
}

/// The `metrics` configuration (used by `sepmem eval` and the benchmark).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MetricsConfig {
    /// Samples per mesh, 1 to [`MAX_SAMPLES`].
    #[serde(deserialize_with = "samples_in_range")]
    pub samples: usize,
    /// F-score threshold τ in the normalised frame.
    pub tau: f64,
    /// Seed of the surface sampling.
    pub seed: u64,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        Self {
            samples: 100_000,
            tau: 0.01,
            seed: 0,
        }
    }
}

/// Scores of a predicted mesh against the ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Mean distance from predicted samples to the ground truth.
    pub accuracy: f64,
    /// Mean distance from ground-truth samples to the prediction.
    pub completeness: f64,
    /// ½(accuracy + completeness).
    pub chamfer_l1: f64,
    /// ½(mean squared accuracy + mean squared completeness).
    pub chamfer_l2: f64,
    /// Share of predicted samples within τ of the ground truth.
    pub precision: f64,
    /// Share of ground-truth samples within τ of the prediction.
    pub recall: f64,
    /// 2PR/(P+R) (0 when P + R = 0).
    pub fscore: f64,
    /// ½(mean |dot| of normals over both directions); −1 for an empty prediction.
    pub normal_consistency: f64,
    /// The threshold τ used.
    pub tau: f64,
    /// Samples per mesh.
    pub samples: usize,
    /// True when the prediction had no surface.
    pub empty_prediction: bool,
}

/// The similarity transform that maps the ground truth's bounding box to a
/// box centred at the origin with longest edge 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// Centre of the ground-truth bounding box.
    pub center: Vec3,
    /// Longest edge of the ground-truth bounding box.
    pub scale: f64,
}

impl Normalization {
    /// From a bounding box.
    ///
    /// # Errors
    /// [`MetricsError::DegenerateGroundTruth`] for an empty or zero-size box.
    pub fn from_aabb(b: &Aabb) -> Result<Self, MetricsError> {
        let e = b.extent();
        let scale = e.max();
        if b.is_empty() || !(scale.is_finite() && scale > 0.0) {
            return Err(MetricsError::DegenerateGroundTruth([e.x, e.y, e.z]));
        }
        Ok(Self {
            center: b.center(),
            scale,
        })
    }

    /// Map a point into the normalised frame.
    pub fn apply(&self, p: &Vec3) -> Vec3 {
        (p - self.center) / self.scale
    }

    /// A copy of `mesh` in the normalised frame.
    pub fn mesh(&self, mesh: &TriMesh) -> TriMesh {
        TriMesh {
            vertices: mesh.vertices.iter().map(|p| self.apply(p)).collect(),
            triangles: mesh.triangles.clone(),
            vertex_scalars: Vec::new(),
        }
    }
}

/// Area-uniform samples of a mesh surface with the normal of the face each
/// sample lies on.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceSamples {
    /// Sample positions.
    pub points: Vec<Vec3>,
    /// Unit face normals (orientation from the triangle winding).
    pub normals: Vec<Vec3>,
}

fn check_indices(mesh: &TriMesh, name: &'static str) -> Result<(), MetricsError> {
    let nv = mesh.vertices.len();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v as usize >= nv) {
            return Err(MetricsError::BadIndex {
                mesh: name,
                triangle: t,
                vertex: v,
                vertices: nv,
            });
        }
    }
    Ok(())
}

/// Sample `n` points uniformly by area over `mesh`, with face normals,
/// reproducibly from `seed`. Triangles of zero or non-finite area are never
/// chosen; a mesh without surface gives no samples.
///
/// # Errors
/// [`MetricsError::BadIndex`] for a triangle with an out-of-range vertex.
pub fn sample_surface(mesh: &TriMesh, n: usize, seed: u64) -> Result<SurfaceSamples, MetricsError> {
    check_indices(mesh, "input")?;
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut normals = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0;
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        let cr = (b - a).cross(&(c - a));
        let area = 0.5 * cr.norm();
        if area > 0.0 && area.is_finite() {
            total += area;
            normals.push(cr / (2.0 * area));
        } else {
            normals.push(Vec3::zeros());
        }
        cumulative.push(total);
    }
    let mut out = SurfaceSamples::default();
    if !(total > 0.0 && n > 0) {
        return Ok(out);
    }
    out.points.reserve(n);
    out.normals.reserve(n);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..n {
        let x = rng.random_range(0.0..total);
        // First triangle whose cumulative area exceeds x (never a zero-area one).
        let t = cumulative
            .partition_point(|&c| c <= x)
            .min(cumulative.len() - 1);
        let [a, b, c] = mesh.corners(t);
        let (r1, r2): (f64, f64) = (rng.random(), rng.random());
        let s = r1.sqrt();
        let p = a * (1.0 - s) + b * (s * (1.0 - r2)) + c * (s * r2);
        out.points.push(p);
        out.normals.push(normals[t]);
    }
    Ok(out)
}

/// Compare two sets of oriented samples already in the normalised frame.
///
/// # Errors
/// [`MetricsError::BadParameter`] for a non-positive τ;
/// [`MetricsError::EmptyGroundTruth`] when `gt` has no sample.
pub fn compare_samples(
    pred: &SurfaceSamples,
    gt: &SurfaceSamples,
    tau: f64,
) -> Result<Metrics, MetricsError> {
    if !(tau.is_finite() && tau > 0.0) {
        return Err(MetricsError::BadParameter {
            what: "tau",
            value: tau,
        });
    }
    if gt.points.is_empty() {
        return Err(MetricsError::EmptyGroundTruth);
    }
    if pred.points.is_empty() {
        let sqrt3 = 3f64.sqrt();
        return Ok(Metrics {
            accuracy: sqrt3,
            completeness: sqrt3,
            chamfer_l1: sqrt3,
            chamfer_l2: 3.0,
            precision: 0.0,
            recall: 0.0,
            fscore: 0.0,
            normal_consistency: -1.0,
            tau,
            samples: gt.points.len(),
            empty_prediction: true,
        });
    }
    // Accuracy: predicted samples against the ground truth; completeness: the reverse.
    let acc = nearest(&gt.points, &pred.points);
    let comp = nearest(&pred.points, &gt.points);
    let stats = |pairs: &[(f64, usize)], from_n: &[Vec3], to_n: &[Vec3]| {
        let n = pairs.len() as f64;
        let (mut d1, mut d2, mut within, mut nc) = (0.0, 0.0, 0usize, 0.0);
        for (i, &(d, j)) in pairs.iter().enumerate() {
            d1 += d;
            d2 += d * d;
            if d <= tau {
                within += 1;
            }
            nc += from_n[i].dot(&to_n[j]).abs();
        }
        (d1 / n, d2 / n, within as f64 / n, nc / n)
    };
    let (acc1, acc2, precision, nc_acc) = stats(&acc, &pred.normals, &gt.normals);
    let (comp1, comp2, recall, nc_comp) = stats(&comp, &gt.normals, &pred.normals);
    let fscore = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    Ok(Metrics {
        accuracy: acc1,
        completeness: comp1,
        chamfer_l1: 0.5 * (acc1 + comp1),
        chamfer_l2: 0.5 * (acc2 + comp2),
        precision,
        recall,
        fscore,
        normal_consistency: 0.5 * (nc_acc + nc_comp),
        tau,
        samples: gt.points.len(),
        empty_prediction: false,
    })
}

/// Evaluate `pred` against `gt` with the ONet/SAP protocol (see the module docs).
///
/// # Errors
/// [`MetricsError`] for an empty or degenerate ground truth, bad indices or
/// bad parameters. An empty prediction is not an error (F = 0).
pub fn evaluate(
    pred: &TriMesh,
    gt: &TriMesh,
    cfg: &MetricsConfig,
) -> Result<Metrics, MetricsError> {
    if cfg.samples == 0 || cfg.samples > MAX_SAMPLES {
        return Err(MetricsError::BadParameter {
            what: "samples",
            value: cfg.samples as f64,
        });
    }
    check_indices(pred, "pred")?;
    check_indices(gt, "gt")?;
    // Bounding box of the vertices actually used by triangles.
    let mut bb = Aabb::empty();
    for tri in &gt.triangles {
        for &v in tri {
            bb.grow(&gt.vertices[v as usize]);
        }
    }
    let norm = Normalization::from_aabb(&bb)?;
    let gt_s = sample_surface(&norm.mesh(gt), cfg.samples, cfg.seed)?;
    if gt_s.points.is_empty() {
        return Err(MetricsError::EmptyGroundTruth);
    }
    let pred_s = sample_surface(&norm.mesh(pred), cfg.samples, cfg.seed.wrapping_add(1))?;
    compare_samples(&pred_s, &gt_s, cfg.tau)
}

/// A UV sphere (for tests and synthetic data): `rings` latitude bands,
/// `segments` longitude segments, outward-facing, watertight.
pub fn uv_sphere(center: Vec3, radius: f64, rings: u32, segments: u32) -> TriMesh {
    let rings = rings.max(2);
    let segments = segments.max(3);
    let mut vertices = vec![center + Vec3::new(0.0, 0.0, radius)];
    for i in 1..rings {
        let theta = std::f64::consts::PI * f64::from(i) / f64::from(rings);
        for j in 0..segments {
            let phi = 2.0 * std::f64::consts::PI * f64::from(j) / f64::from(segments);
            vertices.push(
                center
                    + radius
                        * Vec3::new(
                            theta.sin() * phi.cos(),
                            theta.sin() * phi.sin(),
                            theta.cos(),
                        ),
            );
        }
    }
    vertices.push(center - Vec3::new(0.0, 0.0, radius));
    let south = (vertices.len() - 1) as u32;
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + (j % segments);
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
        triangles.push([south, ring(rings - 1, j + 1), ring(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            triangles.push([a, c, d]);
            triangles.push([a, d, b]);
        }
    }
    TriMesh {
        vertices,
        triangles,
        vertex_scalars: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(samples: usize) -> MetricsConfig {
        MetricsConfig {
            samples,
            tau: 0.01,
            seed: 7,
        }
    }

    #[test]
    fn far_apart_meshes_score_their_true_distance() {
        // Issue 22 (9): a sphere against itself offset by 10 diameters (10 s
        // before), and one triangle against a sphere (36 s before). The mean
        // distance from a sphere of radius r to the centre of another at
        // distance D is D + r²/(3D) (shell theorem), so accuracy is that
        // minus r in the normalised frame (r = 0.5, D = 10).
        let gt = uv_sphere(Vec3::zeros(), 1.0, 48, 96);
        let pred = uv_sphere(Vec3::new(20.0, 0.0, 0.0), 1.0, 48, 96);
        let m = evaluate(&pred, &gt, &cfg(20_000)).unwrap();
        let want = 10.0 + 0.25 / 30.0 - 0.5;
        assert!((m.accuracy - want).abs() < 0.01, "{} vs {want}", m.accuracy);
        assert!((m.completeness - want).abs() < 0.01, "{}", m.completeness);
        assert_eq!(m.fscore, 0.0);
        let tri = TriMesh {
            vertices: vec![
                Vec3::new(5.0, 0.0, 0.0),
                Vec3::new(5.0, 1.0, 0.0),
                Vec3::new(5.0, 0.0, 1.0),
            ],
            triangles: vec![[0, 1, 2]],
            vertex_scalars: Vec::new(),
        };
        let m = evaluate(&tri, &gt, &cfg(20_000)).unwrap();
        // Every triangle point is at least 2 (radius 0.5, plane x = 2.5) away.
        assert!(m.accuracy > 2.0 && m.completeness > 2.0, "{m:?}");
        let m = evaluate(&gt, &gt, &cfg(0)).unwrap_err();
        assert!(matches!(
            m,
            MetricsError::BadParameter {
                what: "samples",
                ..
            }
        ));
        let too_many = evaluate(&gt, &gt, &cfg(MAX_SAMPLES + 1)).unwrap_err();
        assert!(matches!(
            too_many,
            MetricsError::BadParameter {
                what: "samples",
                ..
            }
        ));
    }

    #[test]
    fn uv_sphere_is_closed_and_outward() {
        let s = uv_sphere(Vec3::zeros(), 1.0, 16, 32);
        assert!(s.topology().is_watertight());
        let v = s.signed_volume();
        assert!(
            v > 0.0 && (v - 4.0 / 3.0 * std::f64::consts::PI).abs() < 0.1,
            "{v}"
        );
    }

    #[test]
    fn sampling_is_area_uniform_with_face_normals() {
        // Two triangles of a unit square (area 0.5 each) plus one of area 2
        // far away and a degenerate one: 1/6 of the samples land on each
        // small one, 2/3 on the far one.
        let mesh = TriMesh {
            vertices: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(10.0, 0.0, 0.0),
                Vec3::new(10.0, 2.0, 0.0),
                Vec3::new(10.0, 0.0, 2.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [0, 0, 1]],
            vertex_scalars: Vec::new(),
        };
        let s = sample_surface(&mesh, 20_000, 3).unwrap();
        assert_eq!(s.points.len(), 20_000);
        let far = s.points.iter().filter(|p| p.x > 5.0).count() as f64 / 20_000.0;
        assert!((far - 2.0 / 3.0).abs() < 0.015, "{far}");
        let lower = s.points.iter().filter(|p| p.x < 5.0 && p.y < p.x).count() as f64 / 20_000.0;
        assert!((lower - 1.0 / 6.0).abs() < 0.015, "{lower}");
        for (p, n) in s.points.iter().zip(&s.normals) {
            if p.x > 5.0 {
                assert!((n - Vec3::x()).norm() < 1e-12);
                assert!(
                    (p.x - 10.0).abs() < 1e-12
                        && p.y >= 0.0
                        && p.z >= 0.0
                        && p.y + p.z <= 2.0 + 1e-12
                );
            } else {
                assert!((n - Vec3::z()).norm() < 1e-12);
            }
        }
        // Same seed, same samples.
        assert_eq!(
            sample_surface(&mesh, 100, 9).unwrap(),
            sample_surface(&mesh, 100, 9).unwrap()
        );
        let bad = TriMesh {
            vertices: vec![Vec3::zeros()],
            triangles: vec![[0, 1, 2]],
            vertex_scalars: Vec::new(),
        };
        assert!(matches!(
            sample_surface(&bad, 10, 0),
            Err(MetricsError::BadIndex { vertex: 1, .. })
        ));
    }

    #[test]
    fn mesh_against_itself() {
        let gt = uv_sphere(Vec3::new(3.0, -1.0, 2.0), 7.0, 48, 96);
        let m = evaluate(&gt, &gt, &cfg(100_000)).unwrap();
        // Two independent 100k samples of a unit-diameter sphere (area π):
        // NN distances are ~0.5·sqrt(π/100k) ≈ 0.003, and exceed τ = 0.01 with
        // probability exp(−100k/π · π τ²) = exp(−10) ≈ 5e-5.
        assert!(m.fscore > 0.999, "{m:?}");
        assert!(m.precision > 0.999 && m.recall > 0.999, "{m:?}");
        assert!(m.chamfer_l1 < 0.004, "{m:?}");
        assert!(m.normal_consistency > 0.98, "{m:?}");
        assert!(!m.empty_prediction);
    }

    #[test]
    fn sphere_of_wrong_radius_gives_analytic_distance() {
        // GT radius 0.5 at the origin: normalisation leaves it unchanged.
        let gt = uv_sphere(Vec3::zeros(), 0.5, 96, 192);
        let pred = uv_sphere(Vec3::zeros(), 0.45, 96, 192);
        let m = evaluate(&pred, &gt, &cfg(20_000)).unwrap();
        // Every point of one sphere is 0.05 from the other (up to sampling density).
        assert!((m.accuracy - 0.05).abs() < 2e-3, "{m:?}");
        assert!((m.completeness - 0.05).abs() < 4e-3, "{m:?}");
        assert!((m.chamfer_l1 - 0.05).abs() < 3e-3, "{m:?}");
        assert!((m.chamfer_l2 - 0.0025).abs() < 4e-4, "{m:?}");
        assert_eq!(m.fscore, 0.0);
        // Within τ: radius 0.497 is 0.003 away.
        let close = uv_sphere(Vec3::zeros(), 0.497, 96, 192);
        let m = evaluate(&close, &gt, &cfg(100_000)).unwrap();
        assert!(m.fscore > 0.99, "{m:?}");
        // Scaling both meshes together changes nothing (normalised by the GT).
        let gt10 = uv_sphere(Vec3::new(5.0, 5.0, 5.0), 5.0, 96, 192);
        let pred10 = uv_sphere(Vec3::new(5.0, 5.0, 5.0), 4.5, 96, 192);
        let m10 = evaluate(&pred10, &gt10, &cfg(20_000)).unwrap();
        assert!((m10.chamfer_l1 - 0.05).abs() < 3e-3, "{m10:?}");
    }

    #[test]
    fn empty_prediction_scores_zero() {
        let gt = uv_sphere(Vec3::zeros(), 1.0, 8, 16);
        let m = evaluate(&TriMesh::default(), &gt, &cfg(1000)).unwrap();
        assert_eq!(m.fscore, 0.0);
        assert!(m.empty_prediction);
        assert_eq!(m.chamfer_l1, 3f64.sqrt());
        assert_eq!(
            evaluate(&gt, &TriMesh::default(), &cfg(1000)).unwrap_err(),
            MetricsError::DegenerateGroundTruth([0.0, 0.0, 0.0])
        );
        assert!(matches!(
            evaluate(
                &gt,
                &gt,
                &MetricsConfig {
                    tau: 0.0,
                    ..cfg(10)
                }
            ),
            Err(MetricsError::BadParameter { what: "tau", .. })
        ));
    }
}
