//! Indexed triangle meshes: the membrane's output and the ground truth.
//!
//! A membrane mesh is the triangulated sample grid of the closed B-spline
//! surface (paper Eq. 10, `S(u, v)`), closed at each pole by a fan. It must be
//! watertight (every edge shared by exactly two triangles, consistently
//! oriented) and outward-oriented (positive signed volume). Each vertex may
//! carry scalars, for example the separability `η*` found at that sample.

use crate::cloud::{Aabb, Vec3};
use std::collections::HashMap;

/// An indexed triangle mesh with optional per-vertex scalar channels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<Vec3>,
    /// Triangles as counter-clockwise (seen from outside) vertex indices.
    pub triangles: Vec<[u32; 3]>,
    /// Named per-vertex scalars, each as long as `vertices`.
    pub vertex_scalars: Vec<(String, Vec<f32>)>,
}

/// Result of [`TriMesh::topology`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Topology {
    /// Edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Edges used twice in the same direction (inconsistent winding).
    pub misoriented_edges: usize,
    /// Triangles with a repeated vertex index or an index out of range.
    pub degenerate_triangles: usize,
}

impl Topology {
    /// Closed, edge-manifold and consistently oriented.
    pub fn is_watertight(&self) -> bool {
        self.boundary_edges == 0
            && self.non_manifold_edges == 0
            && self.misoriented_edges == 0
            && self.degenerate_triangles == 0
    }
}

impl TriMesh {
    /// The closed, outward-oriented tetrahedron on the origin and the three
    /// unit points: the smallest watertight mesh (a fixture for tests and
    /// fuzz seeds).
    pub fn unit_tetrahedron() -> TriMesh {
        TriMesh {
            vertices: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            vertex_scalars: vec![],
        }
    }

    /// True when the mesh has no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// A copy moved rigidly by `by` (its vertices' scalars kept).
    pub fn transformed(&self, by: &nalgebra::Isometry3<f64>) -> TriMesh {
        let mut m = self.clone();
        for v in &mut m.vertices {
            *v = (by * nalgebra::Point3::from(*v)).coords;
        }
        m
    }

    /// Bounding box of the vertices.
    pub fn aabb(&self) -> Aabb {
        Aabb::from_points(&self.vertices)
    }

    /// The three corner positions of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Signed enclosed volume (divergence theorem); positive when the
    /// triangles face outward.
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Area-weighted unit vertex normals (outward for a counter-clockwise
    /// mesh); zero for a vertex no non-degenerate triangle uses.
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut n = vec![Vec3::zeros(); self.vertices.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| i as usize);
            if a.max(b).max(c) >= self.vertices.len() {
                continue;
            }
            let f =
                (self.vertices[b] - self.vertices[a]).cross(&(self.vertices[c] - self.vertices[a]));
            n[a] += f;
            n[b] += f;
            n[c] += f;
        }
        for v in &mut n {
            let l = v.norm();
            *v = if l > 0.0 { *v / l } else { Vec3::zeros() };
        }
        n
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Reverse the winding of every triangle.
    pub fn flip(&mut self) {
        for t in &mut self.triangles {
            t.swap(1, 2);
        }
    }

    /// Edge-use statistics: boundary, non-manifold and misoriented edges.
    pub fn topology(&self) -> Topology {
        let n = self.vertices.len() as u32;
        let mut directed: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        let mut degenerate = 0;
        for t in &self.triangles {
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || t.iter().any(|&i| i >= n) {
                degenerate += 1;
                continue;
            }
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        let mut undirected: HashMap<(u32, u32), (u32, u32)> =
            HashMap::with_capacity(directed.len());
        for (&(a, b), &count) in &directed {
            let e = undirected.entry((a.min(b), a.max(b))).or_default();
            if a < b {
                e.0 += count;
            } else {
                e.1 += count;
            }
        }
        let mut topo = Topology {
            boundary_edges: 0,
            non_manifold_edges: 0,
            misoriented_edges: 0,
            degenerate_triangles: degenerate,
        };
        for &(fwd, bwd) in undirected.values() {
            match fwd + bwd {
                1 => topo.boundary_edges += 1,
                2 if fwd == 1 => {}
                2 => topo.misoriented_edges += 1,
                _ => topo.non_manifold_edges += 1,
            }
        }
        topo
    }

    /// The per-vertex scalar channel named `name`.
    pub fn scalar(&self, name: &str) -> Option<&[f32]> {
        self.vertex_scalars
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The unit tetrahedron (test fixture, also used by other modules' tests).
    pub(crate) fn tetra() -> TriMesh {
        TriMesh::unit_tetrahedron()
    }

    #[test]
    fn tetra_is_watertight_with_volume_one_sixth() {
        let m = tetra();
        assert!(m.topology().is_watertight());
        assert!((m.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
        let mut f = m.clone();
        f.flip();
        assert!((f.signed_volume() + 1.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn open_and_misoriented_meshes_are_detected() {
        let mut m = tetra();
        m.triangles.pop();
        assert_eq!(m.topology().boundary_edges, 3);
        let mut m = tetra();
        m.triangles[0].swap(1, 2);
        assert_eq!(m.topology().misoriented_edges, 3);
    }
}
