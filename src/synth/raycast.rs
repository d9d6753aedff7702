//! First-hit ray casting against a triangle mesh, through parry's bounding
//! volume hierarchy: the sensor model of [`crate::synth`] (one ray per pixel
//! of a pinhole camera; the first surface along the ray is what a depth
//! camera measures, so self- and inter-object occlusion are exact) and the
//! ground truth of the view metrics (a ray's first hit on the true mesh is
//! the true depth of that pixel). Inside tests count the crossings of one
//! ray (Jordan parity), which is exact for closed meshes.

use nalgebra::{Point3, Vector3};
use parry3d_f64::query::{PointQuery, Ray, RayCast};
use parry3d_f64::shape::{FeatureId, TriMesh as ParryMesh, TriMeshFlags};
use thiserror::Error;

use crate::cloud::Vec3;
use crate::mesh::TriMesh;

/// Errors of building a ray caster.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RaycastError {
    /// The mesh has no triangles, a bad index or a non-finite vertex.
    #[error("mesh cannot be ray cast: {0}")]
    BadMesh(String),
}

/// The first surface point along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter: the hit is `origin + t·dir`.
    pub t: f64,
    /// Index of the triangle hit.
    pub triangle: u32,
}

/// A mesh prepared for ray casting (in the mesh's own frame).
#[derive(Debug, Clone)]
pub struct MeshCaster {
    shape: ParryMesh,
    normals: Vec<Vec3>,
}

impl MeshCaster {
    /// Build the hierarchy of `mesh`.
    ///
    /// # Errors
    /// [`RaycastError::BadMesh`] for an empty mesh, an index out of range or
    /// a non-finite vertex.
    pub fn new(mesh: &TriMesh) -> Result<Self, RaycastError> {
        let nv = mesh.vertices.len();
        if mesh.triangles.is_empty() {
            return Err(RaycastError::BadMesh("no triangles".into()));
        }
        if mesh.triangles.iter().flatten().any(|&i| i as usize >= nv) {
            return Err(RaycastError::BadMesh("triangle index out of range".into()));
        }
        if mesh
            .vertices
            .iter()
            .any(|v| !v.iter().all(|c| c.is_finite()))
        {
            return Err(RaycastError::BadMesh("non-finite vertex".into()));
        }
        let normals = (0..mesh.triangles.len())
            .map(|t| {
                let [a, b, c] = mesh.corners(t);
                (b - a)
                    .cross(&(c - a))
                    .try_normalize(0.0)
                    .unwrap_or_default()
            })
            .collect();
        let vertices = mesh.vertices.iter().map(|v| Point3::from(*v)).collect();
        let shape = ParryMesh::with_flags(vertices, mesh.triangles.clone(), TriMeshFlags::empty())
            .map_err(|e| RaycastError::BadMesh(e.to_string()))?;
        Ok(Self { shape, normals })
    }

    /// The first hit along `origin + t·dir` with `0 ≤ t ≤ max_t`, if any.
    pub fn first_hit(&self, origin: &Vec3, dir: &Vec3, max_t: f64) -> Option<Hit> {
        let ray = Ray::new(Point3::from(*origin), Vector3::from(*dir));
        let hit = self
            .shape
            .cast_local_ray_and_get_normal(&ray, max_t, false)?;
        let n = self.normals.len() as u32;
        let triangle = match hit.feature {
            // parry numbers back-face hits after the front faces.
            FeatureId::Face(f) if f >= n => f - n,
            FeatureId::Face(f) => f,
            // Not produced for triangle meshes; an unknown triangle has a zero normal.
            _ => u32::MAX,
        };
        Some(Hit {
            t: hit.time_of_impact,
            triangle,
        })
    }

    /// Unit normal of triangle `t` (zero for a degenerate triangle).
    pub fn normal(&self, t: u32) -> Vec3 {
        self.normals.get(t as usize).copied().unwrap_or_default()
    }

    /// Distance from `p` to the nearest point of the mesh's surface.
    pub fn distance(&self, p: &Vec3) -> f64 {
        let q = Point3::from(*p);
        (self.shape.project_local_point(&q, false).point - q).norm()
    }

    /// Whether `p` is inside the closed mesh: the parity of the crossings of
    /// a ray from `p` in a fixed, axis-skew direction.
    pub fn contains(&self, p: &Vec3) -> bool {
        const DIR: Vec3 = Vec3::new(
            0.534_522_483_824_848_8,
            0.267_261_241_912_424_4,
            0.801_783_725_737_273_2,
        );
        let mut origin = *p;
        let mut inside = false;
        // Each crossing moves the origin just past the hit; bounded by the triangle count.
        for _ in 0..=self.normals.len() {
            match self.first_hit(&origin, &DIR, f64::MAX) {
                Some(h) => {
                    inside = !inside;
                    origin += DIR * (h.t + 1e-9);
                }
                None => break,
            }
        }
        inside
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_cube() -> TriMesh {
        let v = |x: f64, y: f64, z: f64| Vec3::new(x, y, z);
        TriMesh {
            vertices: vec![
                v(0.0, 0.0, 0.0),
                v(1.0, 0.0, 0.0),
                v(1.0, 1.0, 0.0),
                v(0.0, 1.0, 0.0),
                v(0.0, 0.0, 1.0),
                v(1.0, 0.0, 1.0),
                v(1.0, 1.0, 1.0),
                v(0.0, 1.0, 1.0),
            ],
            triangles: vec![
                [0, 2, 1],
                [0, 3, 2],
                [4, 5, 6],
                [4, 6, 7],
                [0, 1, 5],
                [0, 5, 4],
                [2, 3, 7],
                [2, 7, 6],
                [1, 2, 6],
                [1, 6, 5],
                [0, 4, 7],
                [0, 7, 3],
            ],
            vertex_scalars: vec![],
        }
    }

    #[test]
    fn first_hit_is_the_near_face_and_respects_the_range() {
        let c = MeshCaster::new(&unit_cube()).unwrap();
        let o = Vec3::new(0.3, 0.6, -2.0);
        let d = Vec3::new(0.0, 0.0, 1.0);
        let h = c.first_hit(&o, &d, 10.0).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12);
        assert!(h.triangle < 2, "{h:?}");
        assert!((c.normal(h.triangle) - Vec3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert!(c.first_hit(&o, &d, 1.9).is_none());
        // From inside, the first hit is the far face.
        let h = c.first_hit(&Vec3::new(0.5, 0.5, 0.25), &d, 10.0).unwrap();
        assert!((h.t - 0.75).abs() < 1e-12);
        assert!(c.first_hit(&o, &Vec3::new(1.0, 0.0, 0.0), 10.0).is_none());
    }

    #[test]
    fn inside_test_by_parity() {
        let c = MeshCaster::new(&unit_cube()).unwrap();
        assert!(c.contains(&Vec3::new(0.5, 0.5, 0.5)));
        assert!(c.contains(&Vec3::new(0.01, 0.98, 0.5)));
        assert!(!c.contains(&Vec3::new(1.5, 0.5, 0.5)));
        assert!(!c.contains(&Vec3::new(-0.2, -0.1, -0.3)));
    }

    #[test]
    fn bad_meshes_are_errors() {
        let mut m = unit_cube();
        m.triangles.push([0, 1, 99]);
        assert!(MeshCaster::new(&m).is_err());
        assert!(MeshCaster::new(&TriMesh::default()).is_err());
    }
}
