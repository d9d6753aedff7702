//! MoveIt collision objects (`moveit_msgs/msg/CollisionObject`) from the
//! frame meshes, for a planning scene (MoveIt's PlanningSceneMonitor
//! subscribes to `/collision_object` and keeps such objects out of its
//! octomap).
//!
//! One object per tracked object stream, id `<id_prefix><stream>`, stamped
//! with the input cloud's header. Its pose is the mesh's vertex centroid
//! (identity orientation: the membrane mesh is in the sensor frame) and its
//! mesh is given relative to that pose, simplified to at most
//! `max_triangles` triangles (planners collide against every triangle;
//! meshoptimizer's edge-collapse simplifier, via the `meshopt` crate).
//!
//! * **ADD** when the mesh changed: the first time, or when some vertex of
//!   the centred mesh moved more than `move_tolerance_m` from the last
//!   mesh sent (the membrane's sampling grid gives every frame the same
//!   vertex order, so the vertices are compared one to one), at most once
//!   per `shape_period_ms` of the clouds' stamps. Simplifying takes 2.1 ms
//!   for a 4,800-triangle mesh and 4.1 ms for 9,400 (measured, release);
//!   a turning object's mesh changes a little every frame, and a planning
//!   scene does not need new shapes 30 times a second. In `sepmem demo`
//!   the median latency went from 19.1 to 17.8 ms (3 runs each; the demo's
//!   run-to-run spread is of the same order).
//! * **MOVE** with empty geometry when only the pose changed (rigid
//!   translation of an unchanged shape), or when the shape changed within
//!   `shape_period_ms` of the last ADD.
//! * **REMOVE** when the object's tracker is gone (evicted) or the stream is.

use super::FrameResult;
use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use crate::wire::msgs::{CollisionObject, Header, Mesh, MeshTriangle, Point, Pose};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// `node.outputs.collision_objects`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CollisionConfig {
    /// Topic (MoveIt's default is `/collision_object`).
    pub topic: String,
    /// Prefix of every object id (the stream id follows it).
    pub id_prefix: String,
    /// Meshes are simplified to at most this many triangles (>= 4).
    pub max_triangles: usize,
    /// A centred vertex moving more than this (m) makes the mesh "changed" (ADD);
    /// below it, a frame only moves the object (MOVE).
    pub move_tolerance_m: f64,
    /// A changed mesh is sent (ADD) at most once per this period (ms, by the
    /// clouds' stamps); the frames in between MOVE the object (0: every
    /// changed frame).
    pub shape_period_ms: u64,
}

impl Default for CollisionConfig {
    fn default() -> Self {
        Self {
            topic: "/collision_object".into(),
            id_prefix: "sepmem".into(),
            max_triangles: 500,
            move_tolerance_m: 0.003,
            shape_period_ms: 200,
        }
    }
}

/// What was last sent for one object.
#[derive(Debug, Clone)]
struct Sent {
    /// Centred vertices of the full (unsimplified) mesh of the last ADD.
    shape: Vec<Vec3>,
    /// Pose position of the last ADD or MOVE.
    position: Vec3,
    /// Stamp of the last ADD (ns).
    added_ns: i64,
}

/// The collision objects of one input stream.
#[derive(Debug, Clone)]
pub struct CollisionObjects {
    cfg: CollisionConfig,
    sent: BTreeMap<String, Sent>,
}

fn centroid(v: &[Vec3]) -> Vec3 {
    let n = v.len().max(1) as f64;
    v.iter().fold(Vec3::zeros(), |a, p| a + p) / n
}

fn pose_at(p: Vec3) -> Pose {
    Pose {
        position: Point {
            x: p.x,
            y: p.y,
            z: p.z,
        },
        ..Pose::default()
    }
}

/// `mesh` simplified to at most `max_triangles` (meshoptimizer edge
/// collapse, then its sloppy clustering if needed), with unused vertices
/// dropped. `None` when even that cannot reach the bound.
pub fn simplified(mesh: &TriMesh, max_triangles: usize) -> Option<TriMesh> {
    if mesh.triangles.len() <= max_triangles {
        return Some(TriMesh {
            vertices: mesh.vertices.clone(),
            triangles: mesh.triangles.clone(),
            vertex_scalars: Vec::new(),
        });
    }
    let pos: Vec<[f32; 3]> = mesh
        .vertices
        .iter()
        .map(|v| [v.x as f32, v.y as f32, v.z as f32])
        .collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let adapter = meshopt::VertexDataAdapter::new(meshopt::typed_to_bytes(&pos), 12, 0).ok()?;
    let target = 3 * max_triangles;
    let mut out = meshopt::simplify(
        &indices,
        &adapter,
        target,
        1.0,
        meshopt::SimplifyOptions::None,
        None,
    );
    let mut sloppy_target = target;
    while out.len() > target && sloppy_target >= 12 {
        out = meshopt::simplify_sloppy(&indices, &adapter, sloppy_target, 1.0, None);
        sloppy_target /= 2;
    }
    if out.len() > target || out.is_empty() {
        return None;
    }
    let mut remap = vec![u32::MAX; mesh.vertices.len()];
    let mut vertices = Vec::new();
    let mut triangles = Vec::with_capacity(out.len() / 3);
    for t in out.chunks_exact(3) {
        let mut tri = [0u32; 3];
        for (k, &i) in t.iter().enumerate() {
            let slot = remap.get_mut(i as usize)?;
            if *slot == u32::MAX {
                *slot = u32::try_from(vertices.len()).ok()?;
                vertices.push(mesh.vertices[i as usize]);
            }
            tri[k] = *slot;
        }
        triangles.push(tri);
    }
    Some(TriMesh {
        vertices,
        triangles,
        vertex_scalars: Vec::new(),
    })
}

impl CollisionObjects {
    /// No object sent yet.
    pub fn new(cfg: CollisionConfig) -> Self {
        Self {
            cfg,
            sent: BTreeMap::new(),
        }
    }

    fn message(&self, stream: &str, header: &Header, operation: u8) -> CollisionObject {
        CollisionObject {
            header: header.clone(),
            id: format!("{}{stream}", self.cfg.id_prefix),
            operation,
            ..CollisionObject::default()
        }
    }

    /// Whether the object sent as `s` stays as it is (a MOVE): its last ADD
    /// is less than `shape_period_ms` before `stamp`, or no vertex of the
    /// centred `shape` moved more than `move_tolerance_m`.
    fn keeps(&self, s: &Sent, stamp: i64, shape: &[Vec3]) -> bool {
        let period = i64::try_from(self.cfg.shape_period_ms)
            .unwrap_or(i64::MAX)
            .saturating_mul(1_000_000);
        let tol = self.cfg.move_tolerance_m;
        (s.added_ns..s.added_ns.saturating_add(period)).contains(&stamp)
            || s.shape.len() == shape.len()
                && s.shape
                    .iter()
                    .zip(shape)
                    .all(|(a, b)| (a - b).norm() <= tol)
    }

    /// The message for `stream`'s mesh of this frame: ADD (with the
    /// simplified mesh) when the shape changed, MOVE otherwise.
    ///
    /// # Errors
    /// A message when the mesh is empty or cannot be simplified to the bound
    /// (nothing is sent then; the previous object stays in the scene).
    pub fn update(
        &mut self,
        stream: &str,
        header: &Header,
        mesh: &TriMesh,
    ) -> Result<CollisionObject, String> {
        if mesh.vertices.is_empty() || mesh.triangles.is_empty() {
            return Err(format!("collision object {stream}: empty mesh"));
        }
        let c = centroid(&mesh.vertices);
        let stamp = header.stamp.to_nanos();
        let shape: Vec<Vec3> = mesh.vertices.iter().map(|v| v - c).collect();
        if self
            .sent
            .get(stream)
            .is_some_and(|s| self.keeps(s, stamp, &shape))
        {
            let mut msg = self.message(stream, header, CollisionObject::MOVE);
            msg.pose = pose_at(c);
            if let Some(s) = self.sent.get_mut(stream) {
                s.position = c;
            }
            return Ok(msg);
        }
        let small = simplified(mesh, self.cfg.max_triangles).ok_or_else(|| {
            format!(
                "collision object {stream}: cannot simplify {} triangles to {}",
                mesh.triangles.len(),
                self.cfg.max_triangles
            )
        })?;
        let mut msg = self.message(stream, header, CollisionObject::ADD);
        msg.pose = pose_at(c);
        msg.meshes = vec![Mesh {
            triangles: small
                .triangles
                .iter()
                .map(|&t| MeshTriangle { vertex_indices: t })
                .collect(),
            vertices: small
                .vertices
                .iter()
                .map(|v| Point {
                    x: v.x - c.x,
                    y: v.y - c.y,
                    z: v.z - c.z,
                })
                .collect(),
        }];
        msg.mesh_poses = vec![Pose::default()];
        let sent = Sent {
            shape,
            position: c,
            added_ns: stamp,
        };
        self.sent.insert(stream.to_string(), sent);
        Ok(msg)
    }

    /// REMOVE for every sent object for which `alive` is false (its tracker
    /// was evicted), forgetting them.
    pub fn retain(
        &mut self,
        header: &Header,
        alive: impl Fn(&str) -> bool,
    ) -> Vec<CollisionObject> {
        let gone: Vec<String> = self.sent.keys().filter(|k| !alive(k)).cloned().collect();
        gone.into_iter()
            .map(|k| {
                self.sent.remove(&k);
                self.message(&k, header, CollisionObject::REMOVE)
            })
            .collect()
    }

    /// The last pose sent for `stream`, if any.
    pub fn position(&self, stream: &str) -> Option<Vec3> {
        self.sent.get(stream).map(|s| s.position)
    }

    /// The messages of one frame: ADD or MOVE for each result, then REMOVE
    /// for each object sent before whose tracker `alive` no longer knows.
    /// Objects that could not be simplified are reported in the second list.
    pub fn frame(
        &mut self,
        results: &[&FrameResult],
        header: &Header,
        alive: impl Fn(&str) -> bool,
    ) -> (Vec<CollisionObject>, Vec<String>) {
        let mut out = Vec::with_capacity(results.len());
        let mut errors = Vec::new();
        for r in results {
            match self.update(&r.stream.to_string(), header, &r.reconstruction.mesh) {
                Ok(m) => out.push(m),
                Err(e) => errors.push(e),
            }
        }
        out.extend(self.retain(header, alive));
        (out, errors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UV sphere (`n` rings × `2n` segments) of radius `r` at `c`.
    fn sphere(n: usize, r: f64, c: Vec3) -> TriMesh {
        let mut vertices = vec![c + Vec3::new(0.0, 0.0, r), c - Vec3::new(0.0, 0.0, r)];
        let seg = 2 * n;
        for i in 1..n {
            let th = std::f64::consts::PI * i as f64 / n as f64;
            for j in 0..seg {
                let ph = 2.0 * std::f64::consts::PI * j as f64 / seg as f64;
                vertices
                    .push(c + r * Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
            }
        }
        let ring = |i: usize, j: usize| (2 + (i - 1) * seg + j % seg) as u32;
        let mut triangles = Vec::new();
        for j in 0..seg {
            triangles.push([0, ring(1, j), ring(1, j + 1)]);
            triangles.push([1, ring(n - 1, j + 1), ring(n - 1, j)]);
        }
        for i in 1..n - 1 {
            for j in 0..seg {
                triangles.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
                triangles.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
            }
        }
        TriMesh {
            vertices,
            triangles,
            vertex_scalars: Vec::new(),
        }
    }

    #[test]
    fn simplification_respects_the_bound_and_keeps_the_shape() {
        let m = sphere(24, 0.1, Vec3::new(0.0, 0.0, 1.0));
        assert!(m.triangles.len() > 2000);
        let s = simplified(&m, 200).unwrap();
        assert!(
            s.triangles.len() <= 200 && s.triangles.len() >= 50,
            "{}",
            s.triangles.len()
        );
        // Every kept vertex is one of the sphere's (on the surface), and the
        // simplified volume stays within 15 % of the sphere's.
        for v in &s.vertices {
            assert!(((v - Vec3::new(0.0, 0.0, 1.0)).norm() - 0.1).abs() < 1e-6);
        }
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 1e-3;
        let vol = s.signed_volume().abs();
        assert!((vol - exact).abs() < 0.15 * exact, "{vol} vs {exact}");
        assert!(s.topology().is_watertight());
    }

    #[test]
    fn add_then_move_then_add_then_remove() {
        let mut co = CollisionObjects::new(CollisionConfig {
            max_triangles: 100,
            ..CollisionConfig::default()
        });
        let at = |ms: i64| Header {
            stamp: crate::wire::msgs::Time::from_nanos(ms * 1_000_000),
            ..Header::default()
        };
        let h = at(1000);
        let m0 = sphere(12, 0.1, Vec3::new(0.0, 0.0, 1.0));
        let a = co.update("/s#1", &h, &m0).unwrap();
        assert_eq!(a.operation, CollisionObject::ADD);
        assert_eq!(a.id, "sepmem/s#1");
        assert!(a.meshes[0].triangles.len() <= 100);
        assert!((a.pose.position.z - 1.0).abs() < 1e-9);
        // Pure translation: MOVE, no geometry, new pose.
        let m1 = sphere(12, 0.1, Vec3::new(0.05, 0.0, 1.0));
        let b = co.update("/s#1", &h, &m1).unwrap();
        assert_eq!(b.operation, CollisionObject::MOVE);
        assert!(b.meshes.is_empty() && b.mesh_poses.is_empty());
        assert!((b.pose.position.x - 0.05).abs() < 1e-9);
        // Grown by 1 cm: the shape changed, but within shape_period_ms
        // (200) of the last ADD only the pose is sent; after it, ADD again.
        let m2 = sphere(12, 0.11, Vec3::new(0.06, 0.0, 1.0));
        let c = co.update("/s#1", &at(1100), &m2).unwrap();
        assert_eq!(c.operation, CollisionObject::MOVE);
        assert!((c.pose.position.x - 0.06).abs() < 1e-9);
        assert_eq!(
            co.update("/s#1", &at(1200), &m2).unwrap().operation,
            CollisionObject::ADD
        );
        // With period 0, every changed frame is an ADD.
        co.cfg.shape_period_ms = 0;
        let m3 = sphere(12, 0.12, Vec3::new(0.06, 0.0, 1.0));
        assert_eq!(
            co.update("/s#1", &at(1201), &m3).unwrap().operation,
            CollisionObject::ADD
        );
        let r = co.retain(&h, |_| false);
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].operation, CollisionObject::REMOVE);
        assert!(co.retain(&h, |_| false).is_empty());
    }
}
