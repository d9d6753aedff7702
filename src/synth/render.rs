//! The depth camera's measurement: one ray per pixel centre against the
//! posed meshes (first hit wins), then incidence cut-off, axial noise,
//! optional flying pixels and outliers (see [`crate::synth`] for the model).

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::raycast::MeshCaster;
use super::{Camera, FlyingPixels, Frame, ObjectTruth, Scene, SynthError};
use crate::cloud::{Aabb, Attribute, PointCloud, Vec3};

/// An object as the camera sees it in one frame.
struct Target {
    /// Index in the scene's objects.
    object: usize,
    caster: MeshCaster,
    /// Object frame → world.
    world: Isometry3<f64>,
    /// Object frame → camera optical frame.
    pose: Isometry3<f64>,
    /// Bounding box in the object frame.
    bounds: Aabb,
}

/// The measured pixels of one frame, in pixel order.
#[derive(Default)]
struct Measured {
    points: Vec<Vec3>,
    /// Target index of each point.
    target_of: Vec<u32>,
    shade: Vec<f32>,
    flying: Vec<Vec3>,
    flying_target: Vec<u32>,
    flying_shade: Vec<f32>,
}

/// Ray-casting depth camera with reusable per-pixel buffers.
#[derive(Debug, Default)]
pub struct Renderer {
    /// Depth (camera z) of the first hit per pixel, `∞` where nothing is hit.
    depth: Vec<f64>,
    /// Per pixel: target index (`u32::MAX` = nothing) and triangle index.
    hit: Vec<(u32, u32)>,
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
        let camera_pose = scene.camera_path.pose_at(index);
        let targets = targets(scene, index, &camera_pose)?;
        self.cast(&scene.camera, &targets);
        let mut rng = ChaCha8Rng::seed_from_u64(
            scene.seed
                ^ (index as u64)
                    .wrapping_add(1)
                    .wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        let m = self.measure(scene, &targets, &mut rng);
        let mut counts = vec![(0usize, 0usize); targets.len()];
        m.target_of.iter().for_each(|&t| counts[t as usize].0 += 1);
        m.flying_target
            .iter()
            .for_each(|&t| counts[t as usize].1 += 1);
        let (visible, flying) = (m.points.len(), m.flying.len());
        let mut points = m.points;
        points.extend_from_slice(&m.flying);
        // Outliers, uniform in the enlarged box of the surface points.
        let n_out = (scene.noise.outlier_fraction * visible as f64).round() as usize;
        if n_out > 0 {
            let bb = Aabb::from_points(&points[..visible]).inflated(scene.noise.outlier_margin);
            for _ in 0..n_out {
                points.push(Vec3::new(
                    rng.random_range(bb.min.x..=bb.max.x),
                    rng.random_range(bb.min.y..=bb.max.y),
                    rng.random_range(bb.min.z..=bb.max.z),
                ));
            }
        }
        let target_of: Vec<u32> = m.target_of.into_iter().chain(m.flying_target).collect();
        let shade: Vec<f32> = m.shade.into_iter().chain(m.flying_shade).collect();
        let labelled: Vec<usize> = target_of
            .iter()
            .map(|&t| targets[t as usize].object)
            .collect();
        let attributes = attributes(scene, &labelled, &shade, n_out, &mut rng);
        let truth = targets
            .iter()
            .zip(counts)
            .map(|(t, (visible_points, flying_pixels))| {
                let o = &scene.objects[t.object];
                ObjectTruth {
                    object: t.object,
                    name: o.name.clone(),
                    label: o.label,
                    pose: t.pose,
                    world_pose: t.world,
                    visible_points,
                    flying_pixels,
                }
            })
            .collect();
        Ok(Frame {
            index,
            cloud: PointCloud { points, attributes },
            camera_pose,
            truth,
            flying,
            outliers: n_out,
        })
    }

    /// Cast every pixel ray that can meet a target; keep the first hit.
    fn cast(&mut self, cam: &Camera, targets: &[Target]) {
        let npix = cam.width * cam.height;
        self.depth.clear();
        self.depth.resize(npix, f64::INFINITY);
        self.hit.clear();
        self.hit.resize(npix, (u32::MAX, 0));
        for (ti, t) in targets.iter().enumerate() {
            let Some((i0, i1, j0, j1)) = pixel_rect(cam, &t.pose, &t.bounds) else {
                continue;
            };
            // The ray in the object frame; its parameter is still the camera depth.
            let inv = t.pose.inverse();
            let origin = inv.translation.vector;
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let k = j * cam.width + i;
                    let dir = inv.rotation * cam.pixel_ray(i, j);
                    let max_t = self.depth[k].min(cam.max_depth);
                    if let Some(h) = t.caster.first_hit(&origin, &dir, max_t) {
                        if h.t < self.depth[k] {
                            self.depth[k] = h.t;
                            self.hit[k] = (ti as u32, h.triangle);
                        }
                    }
                }
            }
        }
    }

    /// Turn the hit pixels into noisy points (and flying pixels), in pixel order.
    fn measure(&self, scene: &Scene, targets: &[Target], rng: &mut ChaCha8Rng) -> Measured {
        let cam = &scene.camera;
        let noise = &scene.noise;
        let cos_min = noise.max_incidence_deg.to_radians().cos().max(1e-9);
        let rotations: Vec<UnitQuaternion<f64>> = targets.iter().map(|t| t.pose.rotation).collect();
        let mut m = Measured::default();
        for (pix, (&z, &(ti, tri))) in self.depth.iter().zip(&self.hit).enumerate() {
            if ti == u32::MAX {
                continue;
            }
            let ray = cam.pixel_ray(pix % cam.width, pix / cam.width);
            let n = rotations[ti as usize] * targets[ti as usize].caster.normal(tri);
            let cos = (n.dot(&ray) / ray.norm()).abs();
            if cos.is_nan() || cos < cos_min {
                continue;
            }
            let sigma = noise.sigma(z);
            let mut zn = z;
            if sigma > 0.0 {
                let e: f64 = rng.sample(StandardNormal);
                zn += sigma * e;
            }
            let spread = noise
                .flying
                .and_then(|f| self.edge_spread(cam, pix, z, &f).map(|s| (f, s)));
            let flies = spread.is_some_and(|(f, _)| rng.random::<f64>() < f.probability);
            if flies {
                zn += rng.random::<f64>() * spread.map_or(0.0, |(_, s)| s);
            }
            if zn < cam.min_depth || zn > cam.max_depth {
                continue;
            }
            let shade = 0.55 + 0.45 * cos as f32;
            if flies {
                m.flying.push(ray * zn);
                m.flying_target.push(ti);
                m.flying_shade.push(shade);
            } else {
                m.points.push(ray * zn);
                m.target_of.push(ti);
                m.shade.push(shade);
            }
        }
        m
    }

    /// How far behind pixel `pix` (depth `z`) the surface beyond its depth
    /// edge lies, capped at `f.max_spread`; `None` when it is on no edge.
    fn edge_spread(&self, cam: &Camera, pix: usize, z: f64, f: &FlyingPixels) -> Option<f64> {
        let (i, j) = (pix % cam.width, pix / cam.width);
        let mut neighbours = [None; 4];
        if i > 0 {
            neighbours[0] = Some(pix - 1);
        }
        if i + 1 < cam.width {
            neighbours[1] = Some(pix + 1);
        }
        if j > 0 {
            neighbours[2] = Some(pix - cam.width);
        }
        if j + 1 < cam.height {
            neighbours[3] = Some(pix + cam.width);
        }
        neighbours
            .into_iter()
            .flatten()
            .filter_map(|q| {
                let behind = self.depth[q] - z;
                (behind > f.min_jump).then_some(behind.min(f.max_spread))
            })
            .reduce(f64::max)
    }
}

/// The objects present at frame `index`, posed and prepared for casting.
fn targets(
    scene: &Scene,
    index: usize,
    camera_pose: &Isometry3<f64>,
) -> Result<Vec<Target>, SynthError> {
    let to_camera = camera_pose.inverse();
    scene
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| o.present_at(index))
        .map(|(object, o)| {
            let caster = MeshCaster::new(&o.mesh).map_err(|e| SynthError::BadMesh {
                object: o.name.clone(),
                reason: e.to_string(),
            })?;
            let world = o.motion.pose_at(&o.start, index);
            Ok(Target {
                object,
                caster,
                world,
                pose: to_camera * world,
                bounds: o.mesh.aabb(),
            })
        })
        .collect()
}

/// The pixels (inclusive ranges `i0..=i1`, `j0..=j1`) whose centres can see
/// the box `bounds` posed by `pose`: the projection of its corners (exact for
/// a box in front of the camera; the whole image when a corner is behind it).
pub(super) fn pixel_rect(
    cam: &Camera,
    pose: &Isometry3<f64>,
    bounds: &Aabb,
) -> Option<(usize, usize, usize, usize)> {
    let (lo, hi) = (bounds.min, bounds.max);
    let mut u = (f64::INFINITY, f64::NEG_INFINITY);
    let mut v = (f64::INFINITY, f64::NEG_INFINITY);
    let mut in_front = 0;
    for c in 0..8 {
        let p = Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        let q = (pose * Point3::from(p)).coords;
        match cam.project(&q) {
            Some((x, y)) if q.z > 1e-6 => {
                in_front += 1;
                u = (u.0.min(x), u.1.max(x));
                v = (v.0.min(y), v.1.max(y));
            }
            _ => {}
        }
    }
    let (w, h) = (cam.width as f64, cam.height as f64);
    if in_front == 0 {
        return None;
    }
    if in_front < 8 {
        u = (0.0, w);
        v = (0.0, h);
    }
    // Pixel i has its centre at i + 0.5.
    let i0 = (u.0 - 0.5).ceil().max(0.0);
    let i1 = (u.1 - 0.5).floor().min(w - 1.0);
    let j0 = (v.0 - 0.5).ceil().max(0.0);
    let j1 = (v.1 - 0.5).floor().min(h - 1.0);
    (i0 <= i1 && j0 <= j1).then_some((i0 as usize, i1 as usize, j0 as usize, j1 as usize))
}

/// Colour (`r`, `g`, `b`, shaded) and `label` channels for points of the
/// objects `object_of`, followed by `n_out` outliers (dark random, label 0).
fn attributes(
    scene: &Scene,
    object_of: &[usize],
    shade: &[f32],
    n_out: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<Attribute> {
    let mut attributes = Vec::new();
    let n = object_of.len() + n_out;
    if scene.colour {
        let mut ch = [
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        ];
        for (&oi, &s) in object_of.iter().zip(shade) {
            let c = scene.objects[oi].colour;
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
        let mut l: Vec<f32> = object_of
            .iter()
            .map(|&oi| scene.objects[oi].label as f32)
            .collect();
        l.resize(n, 0.0);
        attributes.push(Attribute {
            name: "label".into(),
            values: l,
        });
    }
    attributes
}
