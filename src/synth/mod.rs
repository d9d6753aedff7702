//! Sensor simulation: what a depth camera sees of posed meshes.
//!
//! A pinhole depth camera (optical frame: x right, y down, z forward; default
//! 640×480 px, f = 525 px) casts one ray through the centre of every pixel
//! against the posed triangle meshes ([`raycast`], a bounding volume
//! hierarchy), so each pixel measures the first surface along its ray: self-
//! and inter-object occlusion are exact, and the density of the points falls
//! with range (∝ 1/z²) and with incidence (∝ cos θ) as on a real sensor.
//! Surfaces seen at grazing incidence return no depth. Each measured pixel
//! becomes one point, back-projected from a noisy depth: the axial noise is
//! Gaussian with σ(z) = σ₀ + k·(z − z₀)², Kinect: 0.0012 + 0.0019 (z − 0.4)² m
//! (Nguyen, Izadi & Lovell 2012). Optionally the pixels on a depth edge
//! return mixed depths between the foreground and what lies behind it
//! (flying pixels, [`FlyingPixels`]), and a fraction of outliers is added,
//! uniform in the visible scene's bounding box enlarged by a margin. Every
//! point can carry the object's colour (shaded by incidence; outliers dark
//! random) and a segment label (`label` channel; outliers get label 0).
//!
//! These are the partial, one-sided views that the membrane must close
//! (paper §III: the membrane wraps the actual points 𝒫; the unseen side has
//! no data at all). Objects and the camera move in a world frame
//! ([`motion`]: turning, pick and place, drift; the camera may orbit); the
//! ground-truth pose of every object, the camera pose and the mesh id are
//! returned with each frame so that every frame can be scored. Everything is
//! deterministic for a seed (ChaCha8, one stream per frame).

pub mod motion;
pub mod raycast;
mod render;
pub mod sequence;
pub mod truth;
pub mod view_metrics;

pub use motion::{CameraPath, Drift, Motion};
pub use render::Renderer;

use std::ops::Range;

use crate::cloud::{PointCloud, Vec3};
use crate::mesh::TriMesh;
use nalgebra::Isometry3;
use thiserror::Error;

/// Errors of the sensor simulation.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SynthError {
    /// A parameter is out of its valid range.
    #[error("synth parameter `{name}` is invalid: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// An object's mesh has no triangles or a bad index.
    #[error("object `{object}`: {reason}")]
    BadMesh {
        /// The object's name.
        object: String,
        /// What is wrong.
        reason: String,
    },
}

/// Pinhole depth camera: its intrinsics, in its optical frame (x right, y down, z forward).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Focal length in pixels along x.
    pub fx: f64,
    /// Focal length in pixels along y.
    pub fy: f64,
    /// Principal point x (pixels).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
    /// Nearest measurable depth (m).
    pub min_depth: f64,
    /// Farthest measurable depth (m).
    pub max_depth: f64,
}

impl Camera {
    /// A Kinect-like 640×480 camera (f = 525 px, 0.3–8 m).
    pub fn kinect() -> Self {
        Self::with_resolution(640, 480, 525.0)
    }

    /// A camera of the given size and focal length, principal point at the centre.
    pub fn with_resolution(width: usize, height: usize, f: f64) -> Self {
        Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            min_depth: 0.3,
            max_depth: 8.0,
        }
    }

    /// The ray through the centre of pixel `(i, j)`, scaled to unit depth
    /// (`z = 1`), so that its parameter along the ray is the depth.
    pub fn pixel_ray(&self, i: usize, j: usize) -> Vec3 {
        Vec3::new(
            (i as f64 + 0.5 - self.cx) / self.fx,
            (j as f64 + 0.5 - self.cy) / self.fy,
            1.0,
        )
    }

    /// The image position `(u, v)` of a point in front of the camera.
    pub fn project(&self, p: &Vec3) -> Option<(f64, f64)> {
        (p.z > 0.0).then(|| (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// Check the intrinsics and depth range.
    ///
    /// # Errors
    /// [`SynthError::InvalidParameter`] naming the bad field.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |name, reason: &str| {
            Err(SynthError::InvalidParameter {
                name,
                reason: reason.to_string(),
            })
        };
        if self.width == 0 || self.height == 0 || self.width * self.height > 64 << 20 {
            return bad("camera.width/height", "must be positive, at most 64 Mpixel");
        }
        if !(self.fx > 0.0 && self.fy > 0.0 && self.fx.is_finite() && self.fy.is_finite()) {
            return bad("camera.fx/fy", "must be positive and finite");
        }
        if !(self.cx.is_finite() && self.cy.is_finite()) {
            return bad("camera.cx/cy", "must be finite");
        }
        if !(self.min_depth > 0.0 && self.max_depth > self.min_depth) {
            return bad(
                "camera.min_depth/max_depth",
                "need 0 < min_depth < max_depth",
            );
        }
        Ok(())
    }
}

/// Depth noise and outliers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Constant part σ₀ of the axial depth noise (m).
    pub sigma_const: f64,
    /// Quadratic coefficient k of σ(z) = σ₀ + k·(z − z₀)² (1/m); Kinect 0.0019.
    pub sigma_quadratic: f64,
    /// Depth z₀ (m) of least noise in σ(z) = σ₀ + k·(z − z₀)²; Kinect 0.4.
    pub sigma_depth: f64,
    /// Outliers added, as a fraction of the visible points.
    pub outlier_fraction: f64,
    /// Margin (m) by which the visible bounding box is enlarged for outliers.
    pub outlier_margin: f64,
    /// Incidence angle (degrees, between the view ray and the surface normal)
    /// beyond which the sensor returns no depth.
    pub max_incidence_deg: f64,
    /// Mixed depths at depth edges, if simulated.
    pub flying: Option<FlyingPixels>,
}

/// Flying pixels: a pixel on a depth edge (a 4-neighbour lies farther by
/// more than `min_jump`, or sees nothing) returns, with probability
/// `probability`, a depth uniform between its own surface and the surface
/// behind the edge (at most `max_spread` behind), as the mixed returns of a
/// time-of-flight or structured-light sensor do. It keeps the foreground
/// object's label; it lies on no surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlyingPixels {
    /// Chance that an edge pixel flies.
    pub probability: f64,
    /// Smallest depth step (m) between neighbours that counts as an edge.
    pub min_jump: f64,
    /// Farthest a flying pixel lies behind its surface (m).
    pub max_spread: f64,
}

impl FlyingPixels {
    /// Edge pixels fly with `probability`; a 2 cm step is an edge; at most 10 cm behind.
    pub fn with_probability(probability: f64) -> Self {
        Self {
            probability,
            min_jump: 0.02,
            max_spread: 0.1,
        }
    }
}

impl Noise {
    /// No noise, no outliers, no incidence cut-off (exact visible surface).
    pub fn none() -> Self {
        Self {
            sigma_const: 0.0,
            sigma_quadratic: 0.0,
            outlier_fraction: 0.0,
            outlier_margin: 0.0,
            max_incidence_deg: 90.0,
            sigma_depth: 0.0,
            flying: None,
        }
    }

    /// Kinect (Nguyen et al. 2012): σ(z) = 0.0012 + 0.0019·(z − 0.4)² m
    /// (1.2 mm at 0.4 m, 1.9 mm at 1 m, 5.5 mm at 2 m), 1 % outliers, no
    /// return beyond 80° incidence, no flying pixels.
    pub fn kinect() -> Self {
        Self {
            sigma_const: 0.0012,
            sigma_quadratic: 0.0019,
            sigma_depth: 0.4,
            outlier_fraction: 0.01,
            outlier_margin: 0.05,
            max_incidence_deg: 80.0,
            flying: None,
        }
    }

    /// Axial standard deviation at depth `z`.
    pub fn sigma(&self, z: f64) -> f64 {
        self.sigma_const + self.sigma_quadratic * (z - self.sigma_depth).powi(2)
    }

    fn validate(&self) -> Result<(), SynthError> {
        let flying_ok = self.flying.is_none_or(|f| {
            (0.0..=1.0).contains(&f.probability) && f.min_jump > 0.0 && f.max_spread >= 0.0
        });
        let ok = flying_ok
            && self.sigma_const >= 0.0
            && self.sigma_quadratic >= 0.0
            && self.sigma_depth.is_finite()
            && (0.0..=10.0).contains(&self.outlier_fraction)
            && self.outlier_margin >= 0.0
            && self.max_incidence_deg > 0.0
            && self.max_incidence_deg <= 90.0;
        if ok {
            Ok(())
        } else {
            Err(SynthError::InvalidParameter {
                name: "noise",
                reason: format!(
                    "{self:?}: need σ ≥ 0, outlier fraction in [0, 10], incidence in (0, 90], \
                     flying-pixel probability in [0, 1], jump > 0, spread ≥ 0"
                ),
            })
        }
    }
}

/// One object of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// Name (mesh id) reported with the ground truth.
    pub name: String,
    /// The mesh in its own frame (see [`centred_scaled`]).
    pub mesh: TriMesh,
    /// Pose at frame 0 (object frame → world).
    pub start: Isometry3<f64>,
    /// Motion over the frames.
    pub motion: Motion,
    /// Segment label written to the `label` channel (0 is reserved for outliers).
    pub label: u32,
    /// Base colour in `[0, 1]`.
    pub colour: [f32; 3],
    /// Frames in which the object is in the scene (`None`: all of them). An
    /// object swapped for another shares its label with the other and has a
    /// disjoint range.
    pub present: Option<Range<usize>>,
}

impl SceneObject {
    /// Whether the object is in the scene at frame `k`.
    pub fn present_at(&self, k: usize) -> bool {
        self.present.as_ref().is_none_or(|r| r.contains(&k))
    }
}

/// What to render.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The sensor's intrinsics.
    pub camera: Camera,
    /// Where the sensor is, frame by frame.
    pub camera_path: CameraPath,
    /// Noise model.
    pub noise: Noise,
    /// The objects.
    pub objects: Vec<SceneObject>,
    /// Add `r`, `g`, `b` channels.
    pub colour: bool,
    /// Add a `label` channel.
    pub labels: bool,
    /// Seed of the random streams.
    pub seed: u64,
}

/// Ground truth of one object in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectTruth {
    /// Index of the object in [`Scene::objects`].
    pub object: usize,
    /// The object's name (its mesh id).
    pub name: String,
    /// Its label.
    pub label: u32,
    /// Its pose (object frame → camera optical frame).
    pub pose: Isometry3<f64>,
    /// Its pose in the world (object frame → world).
    pub world_pose: Isometry3<f64>,
    /// Points of the frame that lie on it (before flying pixels and outliers).
    pub visible_points: usize,
    /// Flying pixels on its depth edges (labelled as it, on no surface).
    pub flying_pixels: usize,
}

/// One rendered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Frame number.
    pub index: usize,
    /// The simulated measurement (camera frame): the surface points, then the
    /// `flying` flying pixels, then the `outliers` outliers.
    pub cloud: PointCloud,
    /// Camera pose (optical frame → world).
    pub camera_pose: Isometry3<f64>,
    /// Ground truth of every object present in the frame.
    pub truth: Vec<ObjectTruth>,
    /// Number of flying pixels in `cloud` (after the surface points).
    pub flying: usize,
    /// Number of outliers in `cloud` (they are its last points).
    pub outliers: usize,
}

/// Translate a mesh so that its bounding-box centre is the origin and scale
/// it so that its longest bounding-box edge is `longest_edge`.
///
/// # Errors
/// [`SynthError::BadMesh`] for a mesh without extent.
pub fn centred_scaled(mesh: &TriMesh, longest_edge: f64) -> Result<TriMesh, SynthError> {
    let bb = mesh.aabb();
    let l = bb.longest_edge();
    if !(l > 0.0 && l.is_finite()) {
        return Err(SynthError::BadMesh {
            object: "mesh".into(),
            reason: "no extent to scale".into(),
        });
    }
    let c = bb.center();
    let s = longest_edge / l;
    let mut m = mesh.clone();
    for v in &mut m.vertices {
        *v = (*v - c) * s;
    }
    Ok(m)
}

/// Render frames `0..n` of a scene (one renderer, reused buffers).
///
/// # Errors
/// [`SynthError`] as for [`Renderer::render`].
pub fn render_sequence(scene: &Scene, n: usize) -> Result<Vec<Frame>, SynthError> {
    let mut r = Renderer::new();
    (0..n).map(|k| r.render(scene, k)).collect()
}

/// Focal length that makes `scene` (at frame 0) cover about `target` pixels,
/// found from one render at the current focal length (coverage scales with f²).
///
/// # Errors
/// [`SynthError`] as for [`Renderer::render`], or when nothing is visible.
pub fn focal_for_points(scene: &Scene, target: usize) -> Result<f64, SynthError> {
    let mut probe = scene.clone();
    probe.noise = Noise::none();
    let n = Renderer::new().render(&probe, 0)?.cloud.len();
    if n == 0 {
        return Err(SynthError::InvalidParameter {
            name: "scene",
            reason: "no object is visible at frame 0".into(),
        });
    }
    Ok(scene.camera.fx * (target as f64 / n as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// UV sphere of radius r (closed, outward).
    fn sphere(r: f64, rings: usize, segs: usize) -> TriMesh {
        let mut m = TriMesh::default();
        m.vertices.push(Vec3::new(0.0, 0.0, r));
        for i in 1..rings {
            let th = std::f64::consts::PI * i as f64 / rings as f64;
            for j in 0..segs {
                let ph = std::f64::consts::TAU * j as f64 / segs as f64;
                m.vertices
                    .push(r * Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
            }
        }
        m.vertices.push(Vec3::new(0.0, 0.0, -r));
        let south = (m.vertices.len() - 1) as u32;
        let idx = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as u32;
        for j in 0..segs {
            m.triangles.push([0, idx(1, j), idx(1, j + 1)]);
            m.triangles
                .push([south, idx(rings - 1, j + 1), idx(rings - 1, j)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segs {
                m.triangles
                    .push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
                m.triangles
                    .push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
            }
        }
        m
    }

    fn one_object(mesh: TriMesh, at: Vec3, noise: Noise) -> Scene {
        Scene {
            camera: Camera::kinect(),
            camera_path: CameraPath::Fixed,
            noise,
            objects: vec![SceneObject {
                name: "o".into(),
                mesh,
                start: Isometry3::translation(at.x, at.y, at.z),
                motion: Motion::still(),
                label: 20,
                colour: [0.8, 0.2, 0.1],
                present: None,
            }],
            colour: true,
            labels: true,
            seed: 7,
        }
    }

    #[test]
    fn sphere_mesh_is_closed() {
        let s = sphere(1.0, 24, 48);
        assert!(s.topology().is_watertight());
        assert!(s.signed_volume() > 0.0);
    }

    #[test]
    fn only_the_visible_cap_of_a_sphere_is_seen() {
        let (r, c) = (0.2, Vec3::new(0.05, -0.03, 1.0));
        let scene = one_object(sphere(r, 64, 128), c, Noise::none());
        let f = Renderer::new().render(&scene, 0).unwrap();
        let n = f.cloud.len();
        assert!(n > 5_000, "{n} points");
        // From the camera at o the visible cap is where (p−c)·(o−c)/|o−c| ≥ r²/|o−c|.
        let oc = -c;
        let d = oc.norm();
        let mut min_cap = f64::INFINITY;
        for p in &f.cloud.points {
            let q = p - c;
            // On the (faceted) sphere surface.
            assert!(q.norm() <= r + 1e-9 && q.norm() > r * 0.99, "{}", q.norm());
            min_cap = min_cap.min(q.dot(&oc) / d);
        }
        // Facets let the silhouette move by at most the chord sagitta; nothing from the back.
        assert!(min_cap > r * r / d - 0.05 * r, "min cap height {min_cap}");
        assert!(f.cloud.points.iter().all(|p| (p - c).dot(&oc) > 0.0));
        assert_eq!(f.truth[0].visible_points, n);
        assert_eq!(f.cloud.attribute("label").unwrap()[0], 20.0);
        // Pixel count ≈ projected disc area (f·r/z)² π within 5 %.
        let expect = std::f64::consts::PI * (525.0 * r / (d * d - r * r).sqrt()).powi(2);
        assert!((n as f64 - expect).abs() < 0.05 * expect, "{n} vs {expect}");
    }

    #[test]
    fn measured_depth_noise_matches_sigma() {
        // A large plane facing the camera at z = 1.5 m.
        let plane = TriMesh {
            vertices: vec![
                Vec3::new(-0.4, -0.3, 0.0),
                Vec3::new(0.4, -0.3, 0.0),
                Vec3::new(0.4, 0.3, 0.0),
                Vec3::new(-0.4, 0.3, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            vertex_scalars: vec![],
        };
        let z = 1.5;
        let mut noise = Noise::none();
        noise.sigma_const = 0.001;
        noise.sigma_quadratic = 0.002;
        let scene = one_object(plane, Vec3::new(0.0, 0.0, z), noise);
        let f = Renderer::new().render(&scene, 0).unwrap();
        let n = f.cloud.len() as f64;
        assert!(n > 50_000.0);
        let mean = f.cloud.points.iter().map(|p| p.z - z).sum::<f64>() / n;
        let sd = (f
            .cloud
            .points
            .iter()
            .map(|p| (p.z - z - mean).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        let want = 0.001 + 0.002 * z * z;
        assert!((sd - want).abs() < 0.03 * want, "sd {sd} vs {want}");
        assert!(mean.abs() < 0.05 * want, "bias {mean}");
    }

    #[test]
    fn same_seed_same_cloud_other_seed_other_cloud() {
        let mut scene = one_object(
            sphere(0.1, 24, 48),
            Vec3::new(0.0, 0.0, 0.8),
            Noise::kinect(),
        );
        let a = Renderer::new().render(&scene, 3).unwrap();
        let b = Renderer::new().render(&scene, 3).unwrap();
        assert_eq!(a, b);
        assert!(a.outliers > 0);
        scene.seed = 8;
        let c = Renderer::new().render(&scene, 3).unwrap();
        assert_ne!(a.cloud.points, c.cloud.points);
    }

    #[test]
    fn occlusion_and_labels_with_two_objects() {
        // A small sphere in front of a big one: the big one loses the occluded pixels.
        let mut scene = one_object(sphere(0.2, 32, 64), Vec3::new(0.0, 0.0, 1.5), Noise::none());
        let alone = Renderer::new().render(&scene, 0).unwrap().truth[0].visible_points;
        scene.objects.push(SceneObject {
            name: "front".into(),
            mesh: sphere(0.05, 24, 48),
            start: Isometry3::translation(0.0, 0.0, 0.8),
            motion: Motion::still(),
            label: 30,
            colour: [0.1, 0.1, 0.9],
            present: None,
        });
        let f = Renderer::new().render(&scene, 0).unwrap();
        let (back, front) = (f.truth[0].visible_points, f.truth[1].visible_points);
        assert!(front > 1_000);
        // The front sphere hides a disc of the back one of about its own image size.
        let hidden = (alone - back) as f64;
        assert!(
            (hidden - front as f64).abs() <= 0.02 * front as f64,
            "{alone} {back} {front}"
        );
        let labels = f.cloud.attribute("label").unwrap();
        assert_eq!(labels.iter().filter(|&&l| l == 30.0).count(), front);
        for (p, &l) in f.cloud.points.iter().zip(labels) {
            if l == 30.0 {
                assert!(p.z < 0.86);
            } else {
                assert!(p.z > 1.29);
            }
        }
    }

    #[test]
    fn motion_follows_the_configured_velocity() {
        let m = Motion::Drift(Drift {
            velocity: Vec3::new(0.01, 0.0, 0.0),
            angular_velocity: Vec3::new(0.0, 0.1, 0.0),
            wobble: Vec3::zeros(),
            wobble_period: 10.0,
        });
        let start = Isometry3::translation(0.0, 0.0, 1.0);
        let p = m.pose_at(&start, 5);
        assert!((p.translation.vector - Vec3::new(0.05, 0.0, 1.0)).norm() < 1e-12);
        assert!((p.rotation.angle() - 0.5).abs() < 1e-12);
        let mut scene = one_object(sphere(0.1, 24, 48), Vec3::new(0.0, 0.0, 1.0), Noise::none());
        scene.objects[0].motion = m;
        let frames = render_sequence(&scene, 6).unwrap();
        // Every point of frame k lies on the sphere at its frame-k position.
        for f in [&frames[0], &frames[5]] {
            let c = f.truth[0].pose.translation.vector;
            assert!((c.x - 0.01 * f.index as f64).abs() < 1e-12);
            assert!(f.cloud.len() > 1_000);
            for p in &f.cloud.points {
                assert!(((p - c).norm() - 0.1).abs() < 0.002);
            }
        }
    }

    #[test]
    fn focal_for_points_hits_the_target() {
        let mut scene = one_object(sphere(0.1, 32, 64), Vec3::new(0.0, 0.0, 1.0), Noise::none());
        scene.camera.fx = 300.0;
        scene.camera.fy = 300.0;
        let f = focal_for_points(&scene, 20_000).unwrap();
        scene.camera.fx = f;
        scene.camera.fy = f;
        let n = Renderer::new().render(&scene, 0).unwrap().cloud.len() as f64;
        assert!((n - 20_000.0).abs() < 1_000.0, "{n}");
    }

    #[test]
    fn invalid_parameters_are_errors() {
        let mut scene = one_object(sphere(0.1, 8, 16), Vec3::new(0.0, 0.0, 1.0), Noise::none());
        scene.noise.sigma_const = -1.0;
        assert!(Renderer::new().render(&scene, 0).is_err());
        scene.noise = Noise::none();
        scene.camera.width = 0;
        assert!(Renderer::new().render(&scene, 0).is_err());
        scene.camera = Camera::kinect();
        scene.objects[0].mesh.triangles.push([0, 1, 999]);
        assert!(matches!(
            Renderer::new().render(&scene, 0),
            Err(SynthError::BadMesh { .. })
        ));
    }
}
