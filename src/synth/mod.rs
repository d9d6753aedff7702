//! Sensor simulation: what a depth camera would see of moving meshes.
//!
//! A pinhole depth camera (optical frame: x right, y down, z forward, at the
//! origin) renders one or more posed triangle meshes with a z-buffer, so
//! only the surface visible from the camera produces points and objects
//! occlude each other. Each covered pixel becomes one point, back-projected
//! from a noisy depth: the axial noise is Gaussian with the Kinect-like
//! depth dependence σ(z) = σ₀ + k·z² (Khoshelham & Elberink 2012; Nguyen et
//! al. 2012). Surfaces seen at grazing incidence return no depth, as on a
//! real sensor. Optionally a fraction of outliers is added, uniform in the
//! visible scene's bounding box enlarged by a margin, and every point can
//! carry the object's colour (shaded by incidence; outliers dark random)
//! and a segment label (`label` channel; outliers get label 0).
//!
//! These are the partial, one-sided views that the membrane must close
//! (paper §III: the membrane wraps the actual points 𝒫; the unseen side has
//! no data at all). [`Motion`] moves objects smoothly over frames; the
//! ground-truth pose of every object is returned with each frame so that
//! every frame can be scored. Everything is deterministic for a seed
//! (ChaCha8, one stream per frame).

use crate::cloud::{Aabb, Attribute, PointCloud, Vec3};
use crate::mesh::TriMesh;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
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

/// Pinhole depth camera at the origin, looking along +z (ROS optical frame).
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

    fn validate(&self) -> Result<(), SynthError> {
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
    /// Quadratic coefficient k of σ(z) = σ₀ + k·z² (1/m); Kinect ≈ 0.0019.
    pub sigma_quadratic: f64,
    /// Outliers added, as a fraction of the visible points.
    pub outlier_fraction: f64,
    /// Margin (m) by which the visible bounding box is enlarged for outliers.
    pub outlier_margin: f64,
    /// Incidence angle (degrees, between the view ray and the surface normal)
    /// beyond which the sensor returns no depth.
    pub max_incidence_deg: f64,
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
        }
    }

    /// Kinect-like: σ(z) = 0.0012 + 0.0019·z² (1.3 mm at 0.3 m, 3.1 mm at 1 m), 1 % outliers.
    pub fn kinect() -> Self {
        Self {
            sigma_const: 0.0012,
            sigma_quadratic: 0.0019,
            outlier_fraction: 0.01,
            outlier_margin: 0.05,
            max_incidence_deg: 80.0,
        }
    }

    /// Axial standard deviation at depth `z`.
    pub fn sigma(&self, z: f64) -> f64 {
        self.sigma_const + self.sigma_quadratic * z * z
    }

    fn validate(&self) -> Result<(), SynthError> {
        let ok = self.sigma_const >= 0.0
            && self.sigma_quadratic >= 0.0
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
                    "{self:?}: need σ ≥ 0, outlier fraction in [0, 10], incidence in (0, 90]"
                ),
            })
        }
    }
}

/// Smooth rigid motion: `pose(k) = start · T(v·k + a·sin(2πk/P)) · R(ω·k)`,
/// the rotation being about the object's own origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Translation per frame (m), in the camera frame.
    pub velocity: Vec3,
    /// Rotation per frame as a scaled axis (rad), in the object frame.
    pub angular_velocity: Vec3,
    /// Amplitude of a sinusoidal wobble added to the translation (m).
    pub wobble: Vec3,
    /// Period of the wobble in frames (ignored when the wobble is zero).
    pub wobble_period: f64,
}

impl Motion {
    /// No motion.
    pub fn still() -> Self {
        Self {
            velocity: Vec3::zeros(),
            angular_velocity: Vec3::zeros(),
            wobble: Vec3::zeros(),
            wobble_period: 1.0,
        }
    }

    /// Pose at frame `k` given the pose at frame 0.
    pub fn pose_at(&self, start: &Isometry3<f64>, k: usize) -> Isometry3<f64> {
        let k = k as f64;
        let wob = if self.wobble_period > 0.0 {
            self.wobble * (std::f64::consts::TAU * k / self.wobble_period).sin()
        } else {
            Vec3::zeros()
        };
        let shift = Translation3::from(self.velocity * k + wob);
        let spin = UnitQuaternion::from_scaled_axis(self.angular_velocity * k);
        let mut pose = *start;
        pose.append_translation_mut(&shift);
        pose.rotation *= spin;
        pose
    }
}

/// One object of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// Name (mesh id) reported with the ground truth.
    pub name: String,
    /// The mesh in its own frame (see [`centred_scaled`]).
    pub mesh: TriMesh,
    /// Pose at frame 0 (object frame → camera frame).
    pub start: Isometry3<f64>,
    /// Motion over the frames.
    pub motion: Motion,
    /// Segment label written to the `label` channel (0 is reserved for outliers).
    pub label: u32,
    /// Base colour in `[0, 1]`.
    pub colour: [f32; 3],
}

/// What to render.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The sensor.
    pub camera: Camera,
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
    /// The object's name.
    pub name: String,
    /// Its label.
    pub label: u32,
    /// Its pose (object frame → camera frame).
    pub pose: Isometry3<f64>,
    /// Points of the frame that lie on it (before outliers).
    pub visible_points: usize,
}

/// One rendered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Frame number.
    pub index: usize,
    /// The simulated measurement (camera frame).
    pub cloud: PointCloud,
    /// Ground truth of every object.
    pub truth: Vec<ObjectTruth>,
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

/// Z-buffer renderer with reusable buffers.
#[derive(Debug, Default)]
pub struct Renderer {
    depth: Vec<f64>,
    /// Per pixel: object index (u32::MAX = empty) and triangle index.
    hit: Vec<(u32, u32)>,
    verts: Vec<Vec3>,
    normals: Vec<Vec<Vec3>>,
}

impl Renderer {
    /// A renderer (buffers grow on first use).
    pub fn new() -> Self {
        Self::default()
    }

    /// Render frame `index` of `scene`.
    ///
    /// # Errors
    /// [`SynthError`] for invalid camera or noise parameters or a bad mesh.
    pub fn render(&mut self, scene: &Scene, index: usize) -> Result<Frame, SynthError> {
        scene.camera.validate()?;
        scene.noise.validate()?;
        let cam = scene.camera;
        let npix = cam.width * cam.height;
        self.depth.clear();
        self.depth.resize(npix, f64::INFINITY);
        self.hit.clear();
        self.hit.resize(npix, (u32::MAX, 0));
        self.normals.resize(scene.objects.len(), Vec::new());
        let poses: Vec<Isometry3<f64>> = scene
            .objects
            .iter()
            .map(|o| o.motion.pose_at(&o.start, index))
            .collect();
        for (oi, (obj, pose)) in scene.objects.iter().zip(&poses).enumerate() {
            let nv = obj.mesh.vertices.len();
            if obj
                .mesh
                .triangles
                .iter()
                .any(|t| t.iter().any(|&i| i as usize >= nv))
            {
                return Err(SynthError::BadMesh {
                    object: obj.name.clone(),
                    reason: "triangle index out of range".into(),
                });
            }
            self.verts.clear();
            self.verts.extend(
                obj.mesh
                    .vertices
                    .iter()
                    .map(|v| (pose * Point3::from(*v)).coords),
            );
            let normals = &mut self.normals[oi];
            normals.clear();
            for (ti, t) in obj.mesh.triangles.iter().enumerate() {
                let [a, b, c] = t.map(|i| self.verts[i as usize]);
                normals.push((b - a).cross(&(c - a)));
                rasterise(
                    &cam,
                    [a, b, c],
                    oi as u32,
                    ti as u32,
                    &mut self.depth,
                    &mut self.hit,
                );
            }
        }
        // Back-project the covered pixels with noise.
        let mut rng = ChaCha8Rng::seed_from_u64(
            scene.seed
                ^ (index as u64)
                    .wrapping_add(1)
                    .wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        let cos_min = scene.noise.max_incidence_deg.to_radians().cos();
        let mut points = Vec::new();
        let mut obj_of = Vec::new();
        let mut shade = Vec::new();
        let mut counts = vec![0usize; scene.objects.len()];
        for (pix, (&z, &(oi, ti))) in self.depth.iter().zip(&self.hit).enumerate() {
            if oi == u32::MAX {
                continue;
            }
            let u = (pix % cam.width) as f64 + 0.5;
            let v = (pix / cam.width) as f64 + 0.5;
            let ray = Vec3::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
            let n = self.normals[oi as usize][ti as usize];
            let cos = (n.dot(&ray) / (n.norm() * ray.norm())).abs();
            if cos.is_nan() || cos < cos_min.max(1e-9) {
                continue;
            }
            let sigma = scene.noise.sigma(z);
            let zn = if sigma > 0.0 {
                let e: f64 = rng.sample(StandardNormal);
                z + sigma * e
            } else {
                z
            };
            if zn < cam.min_depth || zn > cam.max_depth {
                continue;
            }
            points.push(ray * zn);
            obj_of.push(oi);
            shade.push(0.55 + 0.45 * cos as f32);
            counts[oi as usize] += 1;
        }
        let visible = points.len();
        // Outliers, uniform in the enlarged box of the visible points.
        let n_out = (scene.noise.outlier_fraction * visible as f64).round() as usize;
        if n_out > 0 {
            let bb: Aabb = Aabb::from_points(&points).inflated(scene.noise.outlier_margin);
            for _ in 0..n_out {
                let p = Vec3::new(
                    rng.random_range(bb.min.x..=bb.max.x),
                    rng.random_range(bb.min.y..=bb.max.y),
                    rng.random_range(bb.min.z..=bb.max.z),
                );
                points.push(p);
            }
        }
        let mut attributes = Vec::new();
        if scene.colour {
            let mut ch = [
                Vec::with_capacity(points.len()),
                Vec::with_capacity(points.len()),
                Vec::with_capacity(points.len()),
            ];
            for (&oi, &s) in obj_of.iter().zip(&shade) {
                let c = scene.objects[oi as usize].colour;
                for (chan, base) in ch.iter_mut().zip(c) {
                    chan.push((base * s).clamp(0.0, 1.0));
                }
            }
            for _ in 0..n_out {
                for c in &mut ch {
                    c.push(rng.random_range(0.0..0.15f32));
                }
            }
            for (name, values) in ["r", "g", "b"].into_iter().zip(ch) {
                attributes.push(Attribute {
                    name: name.into(),
                    values,
                });
            }
        }
        if scene.labels {
            let mut l: Vec<f32> = obj_of
                .iter()
                .map(|&oi| scene.objects[oi as usize].label as f32)
                .collect();
            l.resize(points.len(), 0.0);
            attributes.push(Attribute {
                name: "label".into(),
                values: l,
            });
        }
        let truth = scene
            .objects
            .iter()
            .zip(poses)
            .zip(counts)
            .map(|((o, pose), visible_points)| ObjectTruth {
                name: o.name.clone(),
                label: o.label,
                pose,
                visible_points,
            })
            .collect();
        Ok(Frame {
            index,
            cloud: PointCloud { points, attributes },
            truth,
            outliers: n_out,
        })
    }
}

/// Rasterise one camera-frame triangle into the z-buffer (pixel centres,
/// perspective-correct depth: 1/z is affine in the image).
fn rasterise(
    cam: &Camera,
    tri: [Vec3; 3],
    object: u32,
    triangle: u32,
    depth: &mut [f64],
    hit: &mut [(u32, u32)],
) {
    if tri
        .iter()
        .any(|p| !p.iter().all(|c| c.is_finite()) || p.z < cam.min_depth)
    {
        return; // behind or too close to the camera: not measurable
    }
    let proj = tri.map(|p| {
        (
            cam.fx * p.x / p.z + cam.cx,
            cam.fy * p.y / p.z + cam.cy,
            1.0 / p.z,
        )
    });
    let area = (proj[1].0 - proj[0].0) * (proj[2].1 - proj[0].1)
        - (proj[2].0 - proj[0].0) * (proj[1].1 - proj[0].1);
    if area.abs() < 1e-12 {
        return;
    }
    let minx = proj.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let maxx = proj.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let miny = proj.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let maxy = proj.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    // Pixel (i, j) has its centre at (i + 0.5, j + 0.5).
    let x0 = (minx - 0.5).ceil().max(0.0);
    let x1 = (maxx - 0.5).floor().min(cam.width as f64 - 1.0);
    let y0 = (miny - 0.5).ceil().max(0.0);
    let y1 = (maxy - 0.5).floor().min(cam.height as f64 - 1.0);
    if x0 > x1 || y0 > y1 {
        return;
    }
    let inv = 1.0 / area;
    let edge = |a: (f64, f64, f64), b: (f64, f64, f64), x: f64, y: f64| {
        (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0)
    };
    for j in y0 as usize..=y1 as usize {
        let y = j as f64 + 0.5;
        for i in x0 as usize..=x1 as usize {
            let x = i as f64 + 0.5;
            let w0 = edge(proj[1], proj[2], x, y) * inv;
            let w1 = edge(proj[2], proj[0], x, y) * inv;
            let w2 = 1.0 - w0 - w1;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let inv_z = w0 * proj[0].2 + w1 * proj[1].2 + w2 * proj[2].2;
            let z = 1.0 / inv_z;
            let k = j * cam.width + i;
            if z < depth[k] {
                depth[k] = z;
                hit[k] = (object, triangle);
            }
        }
    }
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
            noise,
            objects: vec![SceneObject {
                name: "o".into(),
                mesh,
                start: Isometry3::translation(at.x, at.y, at.z),
                motion: Motion::still(),
                label: 20,
                colour: [0.8, 0.2, 0.1],
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
        let m = Motion {
            velocity: Vec3::new(0.01, 0.0, 0.0),
            angular_velocity: Vec3::new(0.0, 0.1, 0.0),
            wobble: Vec3::zeros(),
            wobble_period: 10.0,
        };
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
