//! Wavefront OBJ meshes: read with `tobj`, write as plain `v`/`f` lines.
//!
//! Reading triangulates polygons (fans), ignores points, lines, normals,
//! texture coordinates and materials (a dangling `mtllib` is not an error).
//! `tobj` numbers the vertices in order of first use by a face and leaves
//! out vertices no face uses; the report gives the file's `v` count and how
//! many were left out.
//! Several objects/groups are concatenated; vertices that `tobj` split
//! between groups are merged back by exact position so that a closed mesh
//! stays closed.

use super::{read_bytes, IoError, LoadedMesh, MeshReport};
use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// Parse OBJ bytes as a triangle mesh; `path` names the source in errors.
///
/// # Errors
/// [`IoError::Obj`] when `tobj` rejects the file (bad numbers, bad indices).
pub fn parse_mesh(bytes: &[u8], path: &Path) -> Result<LoadedMesh, IoError> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let mut reader = std::io::BufReader::new(bytes);
    let (models, _materials) =
        tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed)).map_err(
            |source| IoError::Obj {
                path: path.to_path_buf(),
                source,
            },
        )?;
    let mut mesh = TriMesh::default();
    let mut seen: HashMap<[u64; 3], u32> = HashMap::new();
    let multi = models.len() > 1;
    for m in &models {
        let pos = &m.mesh.positions;
        let nv = pos.len() / 3;
        let mut remap = Vec::with_capacity(nv);
        for k in 0..nv {
            let p = Vec3::new(
                pos[3 * k] as f64,
                pos[3 * k + 1] as f64,
                pos[3 * k + 2] as f64,
            );
            let idx = if multi {
                let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
                *seen.entry(key).or_insert_with(|| {
                    mesh.vertices.push(p);
                    (mesh.vertices.len() - 1) as u32
                })
            } else {
                mesh.vertices.push(p);
                (mesh.vertices.len() - 1) as u32
            };
            remap.push(idx);
        }
        for (f, t) in m.mesh.indices.chunks_exact(3).enumerate() {
            let mut tri = [0u32; 3];
            for (k, &i) in t.iter().enumerate() {
                tri[k] = *remap
                    .get(i as usize)
                    .ok_or_else(|| IoError::IndexOutOfRange {
                        path: path.to_path_buf(),
                        face: f,
                        index: i as i64,
                        vertices: nv,
                    })?;
            }
            mesh.triangles.push(tri);
        }
    }
    // The file's own vertex count (`v` records), for the report.
    let vertices_read = bytes
        .split(|&b| b == b'\n')
        .filter(|l| {
            let l = l.trim_ascii_start();
            l.len() > 1 && l[0] == b'v' && l[1].is_ascii_whitespace()
        })
        .count();
    let unreferenced_dropped = vertices_read.saturating_sub(mesh.vertices.len());
    let faces_read = mesh.triangles.len();
    let dropped = super::drop_non_finite_vertices(&mut mesh);
    Ok(LoadedMesh {
        mesh,
        report: MeshReport {
            vertices_read,
            faces_read,
            faces_skipped: 0,
            dropped_non_finite: dropped,
            unreferenced_dropped,
        },
    })
}

/// Read an OBJ file as a triangle mesh.
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn read_mesh(path: &Path) -> Result<LoadedMesh, IoError> {
    parse_mesh(&read_bytes(path)?, path)
}

/// Encode a mesh as OBJ text (`v x y z` lines, then 1-based `f a b c` lines).
/// Vertex scalars are not representable in OBJ and are not written.
pub fn encode_mesh(mesh: &TriMesh) -> Vec<u8> {
    let mut out = Vec::with_capacity(mesh.vertices.len() * 40 + mesh.triangles.len() * 24 + 64);
    // Writing into a Vec cannot fail.
    let _ = writeln!(
        out,
        "# written by sepmem: {} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    for v in &mesh.vertices {
        let _ = writeln!(out, "v {} {} {}", v.x, v.y, v.z);
    }
    for t in &mesh.triangles {
        let _ = writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    out
}

/// Write a mesh as OBJ (see [`encode_mesh`]).
///
/// # Errors
/// [`IoError::BadInput`] when a triangle index is out of range, [`IoError::Io`] on write failure.
pub fn write_mesh(path: &Path, mesh: &TriMesh) -> Result<(), IoError> {
    let nv = mesh.vertices.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= nv))
    {
        return Err(IoError::BadInput {
            path: path.to_path_buf(),
            reason: format!("triangle {t} has an index >= {nv} vertices"),
        });
    }
    std::fs::write(path, encode_mesh(mesh)).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_are_triangulated_and_mtllib_ignored() {
        let text = b"mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n";
        let m = parse_mesh(text, Path::new("q.obj")).unwrap();
        assert_eq!(m.mesh.vertices.len(), 4);
        assert_eq!(m.mesh.triangles.len(), 2);
        assert!((m.mesh.area() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn groups_share_vertices_after_merge() {
        // A tetrahedron split into two groups: still watertight after loading.
        let text =
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ng a\nf 1 3 2\nf 1 2 4\ng b\nf 1 4 3\nf 2 3 4\n";
        let m = parse_mesh(text, Path::new("t.obj")).unwrap();
        assert_eq!(m.mesh.vertices.len(), 4);
        assert!(m.mesh.topology().is_watertight());
        assert!((m.mesh.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn bad_index_is_an_error() {
        let e = parse_mesh(b"v 0 0 0\nv 1 0 0\nf 1 2 9\n", Path::new("b.obj")).unwrap_err();
        assert!(e.to_string().contains("b.obj"), "{e}");
    }
}
