//! Wavefront OBJ meshes: read with `tobj`, write as plain `v`/`f` lines.
//!
//! Reading triangulates polygons (fans), ignores points, lines, normals,
//! texture coordinates and materials (a dangling `mtllib` is not an error).
//! `tobj` numbers the vertices in order of first use by a face and leaves
//! out vertices no face uses; the report gives the file's `v` count and how
//! many were left out.
//! Read as a point cloud ([`parse_cloud`]), every `v` record is a point: a
//! vertex-only OBJ read as "empty" before.
//! Several objects/groups are concatenated; vertices that `tobj` split
//! between groups are merged back by exact position so that a closed mesh
//! stays closed.

use super::{read_bytes, IoError, LoadedCloud, LoadedMesh, MeshReport};
use crate::cloud::{Attribute, PointCloud, Vec3};
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

/// Parse OBJ bytes as a point cloud: every `v x y z [w]` record (faces and
/// everything else ignored), so that a vertex-only OBJ (a scan exported as
/// points) is a cloud rather than an empty mesh. `v x y z r g b` (the common
/// colour extension) gives the channels `r`, `g`, `b`.
///
/// # Errors
/// [`IoError::Parse`] naming the line of a `v` record that is not 3, 4 or 6
/// numbers.
pub fn parse_cloud(bytes: &[u8], path: &Path) -> Result<LoadedCloud, IoError> {
    let mut points = Vec::new();
    let mut rgb: [Vec<f32>; 3] = Default::default();
    let mut values: Vec<f64> = Vec::with_capacity(6);
    let mut first_coloured: Option<bool> = None;
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = line.trim_ascii();
        if line.len() < 2 || line[0] != b'v' || !line[1].is_ascii_whitespace() {
            continue;
        }
        let bad = |reason: String| IoError::Parse {
            path: path.to_path_buf(),
            line: i + 1,
            reason,
        };
        let text = std::str::from_utf8(&line[2..]).map_err(|_| bad("not text".into()))?;
        values.clear();
        for t in text.split_ascii_whitespace() {
            values.push(
                t.parse()
                    .map_err(|_| bad(format!("cannot parse {t:?} as a number")))?,
            );
        }
        let coloured = values.len() == 6;
        if !matches!(values.len(), 3 | 4 | 6) || *first_coloured.get_or_insert(coloured) != coloured
        {
            return Err(bad(format!(
                "vertex with {} values (x y z [w] or x y z r g b on every line)",
                values.len()
            )));
        }
        points.push(Vec3::new(values[0], values[1], values[2]));
        if coloured {
            for (c, v) in rgb.iter_mut().zip(&values[3..]) {
                c.push(*v as f32);
            }
        }
    }
    let n = points.len();
    let mut cloud = PointCloud::from_points(points);
    if !rgb[0].is_empty() {
        for (name, v) in ["r", "g", "b"].into_iter().zip(rgb) {
            cloud.attributes.push(Attribute {
                name: name.into(),
                values: v,
            });
        }
    }
    Ok(super::finish_cloud(cloud, n, 1))
}

/// Read an OBJ file's vertices as a point cloud (see [`parse_cloud`]).
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn read_cloud(path: &Path) -> Result<LoadedCloud, IoError> {
    parse_cloud(&read_bytes(path)?, path)
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
    fn vertex_only_obj_is_a_cloud() {
        let text = b"# points\nv 0 0 0\nv 1 0 0\nv 0 1 0 1.0\n  v 0 0 nan\nvn 0 0 1\n";
        let c = parse_cloud(text, Path::new("p.obj")).unwrap();
        assert_eq!(c.report.points_read, 4);
        assert_eq!(c.report.dropped_non_finite, 1);
        assert_eq!(c.cloud.points[2], Vec3::new(0.0, 1.0, 0.0));
        let c = parse_cloud(b"v 0 0 0 1 0.5 0\nv 1 1 1 0 0 1\n", Path::new("c.obj")).unwrap();
        assert_eq!(c.cloud.attribute("g").unwrap(), &[0.5, 0.0]);
        let e = parse_cloud(b"v 0 0 0\nv 1 x 0\n", Path::new("b.obj")).unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 2, .. }), "{e}");
        let e = parse_cloud(b"v 0 0 0 1 1 1\nv 1 0 0\n", Path::new("b.obj")).unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 2, .. }), "{e}");
    }

    #[test]
    fn bad_index_is_an_error() {
        let e = parse_mesh(b"v 0 0 0\nv 1 0 0\nf 1 2 9\n", Path::new("b.obj")).unwrap_err();
        assert!(e.to_string().contains("b.obj"), "{e}");
    }
}
