//! Conversions between sepmem's [`TriMesh`] and the mesh messages it
//! publishes: `shape_msgs/Mesh` (indexed, for machine consumers),
//! `visualization_msgs/Marker` TRIANGLE_LIST (viewable in RViz2 and
//! Foxglove without plugins; consecutive vertex triples, identity pose,
//! unit scale) with the `DELETEALL` marker that clears vanished objects,
//! and the geometry of `sepmem_msgs/SurfaceMesh`.

use thiserror::Error;

use super::msgs::{ColorRGBA, Header, Marker, Mesh, MeshTriangle, Point, SurfaceMesh, Vector3};
use crate::cloud::Vec3;
use crate::mesh::TriMesh;

/// Errors converting a received mesh message into a [`TriMesh`].
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ConvertError {
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "mesh message triangle {triangle} uses vertex {index}, but there are {vertices} vertices"
    )]
    IndexOutOfRange {
        /// Triangle number.
        triangle: usize,
        /// Offending index.
        index: u32,
        /// Vertex count.
        vertices: usize,
    },
    /// A vertex is NaN or infinite.
    #[error("mesh message vertex {0} is not finite")]
    NonFiniteVertex(usize),
}

fn point(v: &Vec3) -> Point {
    Point {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

/// `shape_msgs/Mesh` of a triangle mesh (scalars are dropped).
pub fn to_shape_mesh(mesh: &TriMesh) -> Mesh {
    Mesh {
        triangles: mesh
            .triangles
            .iter()
            .map(|&t| MeshTriangle { vertex_indices: t })
            .collect(),
        vertices: mesh.vertices.iter().map(point).collect(),
    }
}

/// A TRIANGLE_LIST marker of `mesh` (one point triple per triangle, in
/// the triangle's winding) in namespace `ns` with id `id`.
pub fn to_triangle_list_marker(
    mesh: &TriMesh,
    header: Header,
    ns: &str,
    id: i32,
    color: ColorRGBA,
) -> Marker {
    Marker {
        header,
        ns: ns.to_string(),
        id,
        type_: Marker::TRIANGLE_LIST,
        action: Marker::ADD,
        scale: Vector3 {
            x: 1.0,
            y: 1.0,
            z: 1.0,
        },
        color,
        points: mesh
            .triangles
            .iter()
            .flat_map(|t| t.map(|i| point(&mesh.vertices[i as usize])))
            .collect(),
        ..Default::default()
    }
}

/// The `DELETEALL` marker that starts each frame's MarkerArray.
pub fn delete_all_marker(header: Header) -> Marker {
    Marker {
        header,
        action: Marker::DELETEALL,
        ..Default::default()
    }
}

/// Geometry of a received `shape_msgs/Mesh` or `SurfaceMesh` as a [`TriMesh`].
///
/// # Errors
/// [`ConvertError`] for an index out of range or a non-finite vertex.
pub fn trimesh_from_parts(
    vertices: &[Point],
    triangles: &[MeshTriangle],
) -> Result<TriMesh, ConvertError> {
    let mut v = Vec::with_capacity(vertices.len());
    for (i, p) in vertices.iter().enumerate() {
        let q = Vec3::new(p.x, p.y, p.z);
        if !q.iter().all(|c| c.is_finite()) {
            return Err(ConvertError::NonFiniteVertex(i));
        }
        v.push(q);
    }
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&index) = tri.vertex_indices.iter().find(|&&i| i as usize >= v.len()) {
            return Err(ConvertError::IndexOutOfRange {
                triangle: t,
                index,
                vertices: v.len(),
            });
        }
    }
    Ok(TriMesh {
        vertices: v,
        triangles: triangles.iter().map(|t| t.vertex_indices).collect(),
        vertex_scalars: Vec::new(),
    })
}

/// Geometry of a received `sepmem_msgs/SurfaceMesh`, with its per-vertex
/// separability as the scalar `separability` when it has one value per vertex.
///
/// # Errors
/// As [`trimesh_from_parts`].
pub fn trimesh_from_surface(msg: &SurfaceMesh) -> Result<TriMesh, ConvertError> {
    let mut m = trimesh_from_parts(&msg.vertices, &msg.triangles)?;
    if msg.vertex_separability.len() == m.vertices.len() {
        m.vertex_scalars
            .push(("separability".to_string(), msg.vertex_separability.clone()));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::mesh::tests::tetra;

    #[test]
    fn shape_mesh_round_trip_and_marker_layout() {
        let m = tetra();
        let s = to_shape_mesh(&m);
        assert_eq!(trimesh_from_parts(&s.vertices, &s.triangles).unwrap(), m);
        let mk = to_triangle_list_marker(&m, Header::default(), "sepmem", 3, ColorRGBA::default());
        assert_eq!(mk.points.len(), 12);
        assert_eq!(mk.points[4], point(&m.vertices[1]));
        assert_eq!(mk.type_, 11);
        assert_eq!(delete_all_marker(Header::default()).action, 3);
    }

    #[test]
    fn bad_meshes_are_typed_errors() {
        let mut s = to_shape_mesh(&tetra());
        s.triangles[2].vertex_indices[1] = 9;
        assert!(matches!(
            trimesh_from_parts(&s.vertices, &s.triangles),
            Err(ConvertError::IndexOutOfRange {
                triangle: 2,
                index: 9,
                vertices: 4
            })
        ));
        let mut s = to_shape_mesh(&tetra());
        s.vertices[1].y = f64::NAN;
        assert_eq!(
            trimesh_from_parts(&s.vertices, &s.triangles),
            Err(ConvertError::NonFiniteVertex(1))
        );
    }
}
