//! Mesh extraction: triangulate the membrane's sample grid, close the poles.
//!
//! The surface `S(u,v)` (paper Eq. 10) is evaluated on a `u_n × v_n` grid
//! (`v_j = (j+½)/v_n`, never at a pole). Neighbouring grid rows are joined by
//! two triangles per cell (periodic in u), and each pole `S(·,0)`, `S(·,1)`
//! closes its end row with a fan. Every edge is then shared by exactly two
//! triangles; the winding follows the outward normal `±S_u × S_v`, so the
//! mesh has positive signed volume. Each vertex carries the separability η*
//! found at that sample (`"separability"` channel).

use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use crate::spline::{ClosedSurface, Layout};

/// Name of the per-vertex separability channel of extracted meshes.
pub const SEPARABILITY_CHANNEL: &str = "separability";

/// Triangulate `surface` on `layout` (built for the surface's grid).
/// `eta` holds one separability per sample (flat index `j·u_n + i`) or is
/// empty; pole vertices get the mean of their adjacent row.
pub fn extract_mesh(surface: &ClosedSurface, layout: &Layout, eta: &[f64]) -> TriMesh {
    let (un, vn) = (layout.u_n(), layout.v_n());
    let mut vertices = Vec::with_capacity(un * vn + 2);
    for j in 0..vn {
        for i in 0..un {
            vertices.push(surface.eval_at(layout, i, j).p);
        }
    }
    let [pole0, pole1] = surface.poles();
    let p0 = vertices.len() as u32;
    vertices.push(pole0);
    let p1 = vertices.len() as u32;
    vertices.push(pole1);
    let idx = |i: usize, j: usize| (j * un + i % un) as u32;
    let mut triangles = Vec::with_capacity(2 * un * vn);
    for j in 0..vn.saturating_sub(1) {
        for i in 0..un {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    for i in 0..un {
        triangles.push([idx(i + 1, 0), idx(i, 0), p0]);
        triangles.push([idx(i, vn - 1), idx(i + 1, vn - 1), p1]);
    }
    let mut mesh = TriMesh {
        vertices,
        triangles,
        vertex_scalars: Vec::new(),
    };
    if surface.orientation() < 0.0 {
        mesh.flip();
    }
    if eta.len() == un * vn {
        let mut s: Vec<f32> = eta.iter().map(|&e| e as f32).collect();
        let mean = |row: usize| -> f32 {
            let r = &eta[row * un..(row + 1) * un];
            (r.iter().sum::<f64>() / un as f64) as f32
        };
        s.push(mean(0));
        s.push(mean(vn - 1));
        mesh.vertex_scalars
            .push((SEPARABILITY_CHANNEL.to_string(), s));
    }
    mesh
}

/// Mean position of a mesh's vertices (helper for tests and reports).
pub fn vertex_centroid(mesh: &TriMesh) -> Option<Vec3> {
    if mesh.vertices.is_empty() {
        return None;
    }
    Some(mesh.vertices.iter().sum::<Vec3>() / mesh.vertices.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_net(m: usize, l: usize, flip: bool) -> ClosedSurface {
        let mut ctrl = Vec::new();
        for r in 0..l {
            let th = std::f64::consts::PI * r as f64 / (l - 1) as f64;
            for c in 0..m {
                let mut ph = 2.0 * std::f64::consts::PI * c as f64 / m as f64;
                if flip {
                    ph = -ph;
                }
                ctrl.push(Vec3::new(
                    th.sin() * ph.cos(),
                    th.sin() * ph.sin(),
                    -th.cos(),
                ));
            }
        }
        ClosedSurface::from_net(m, l, ctrl).unwrap()
    }

    #[test]
    fn extracted_mesh_is_watertight_and_outward_for_both_parameterisations() {
        for flip in [false, true] {
            let s = sphere_net(8, 5, flip);
            let lay = Layout::samples(8, 5, 20, 15).unwrap();
            let eta = vec![0.5; lay.len()];
            let m = extract_mesh(&s, &lay, &eta);
            assert!(m.topology().is_watertight(), "{:?}", m.topology());
            assert!(m.signed_volume() > 0.0, "flip={flip}");
            assert_eq!(m.vertices.len(), 20 * 15 + 2);
            assert_eq!(
                m.scalar(SEPARABILITY_CHANNEL).unwrap().len(),
                m.vertices.len()
            );
        }
    }
}
