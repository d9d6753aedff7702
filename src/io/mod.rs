//! Reading and writing point clouds and triangle meshes.
//!
//! Input clouds are the actual-point set 𝒫 of the paper (§III-A): only
//! measured points are kept. Points whose position is NaN or infinite (the
//! invalid pixels of organised depth-camera clouds) are dropped and counted
//! in a [`LoadReport`]. Every other per-point field of the file is kept as a
//! named `f32` attribute channel so that the attribute separability (paper
//! Eqs. 1 and 9) can use it: colour becomes the channels `r`, `g`, `b` in
//! `[0, 1]`, intensity the channel `intensity`, a segment label the channel
//! `label`.
//!
//! Formats:
//!
//! | format | read cloud | read mesh | write |
//! |---|---|---|---|
//! | PLY (ascii, binary little/big endian) | [`ply`] | [`ply`] | binary little-endian mesh with per-vertex scalars and colour; cloud with colour |
//! | PCL PCD (ascii, binary, binary_compressed/LZF) | [`pcd`] | – | – |
//! | XYZ text (`x y z [extra columns]`) | [`xyz`] | – | – |
//! | Wavefront OBJ (mesh via `tobj`) | every `v` record | [`obj`] | [`obj`] |
//!
//! [`load_cloud`] and [`load_mesh`] dispatch on the file extension. Malformed
//! input (bad header, truncated data, unsupported types, count mismatches,
//! out-of-range indices) gives an [`IoError`] naming the file and the
//! problem; no input makes a reader panic (a property test feeds truncated
//! and mutated files).

pub mod obj;
pub mod pcd;
pub mod ply;
pub mod xyz;

use crate::cloud::{PointCloud, Vec3};
use crate::mesh::TriMesh;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors of the readers and writers. Every variant names the file.
#[derive(Debug, Error)]
pub enum IoError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The extension does not name a supported format.
    #[error("{path}: unsupported file extension (expected {expected})")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// The supported extensions.
        expected: &'static str,
    },
    /// The header is missing, malformed or inconsistent.
    #[error("{path}: bad header: {reason}")]
    BadHeader {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The header is valid but asks for something this reader does not support.
    #[error("{path}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The unsupported feature.
        what: String,
    },
    /// The data ends before everything the header announced was read.
    #[error("{path}: truncated data: {what}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What was being read when the data ended.
        what: String,
    },
    /// A value in the data section could not be parsed.
    #[error("{path}: line {line}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number (0 when unknown).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A count in the file disagrees with another count or with the data.
    #[error("{path}: {what}: expected {expected}, found {found}")]
    CountMismatch {
        /// The file.
        path: PathBuf,
        /// What was counted.
        what: String,
        /// The count announced or required.
        expected: usize,
        /// The count found.
        found: usize,
    },
    /// A face refers to a vertex that does not exist.
    #[error("{path}: face {face} refers to vertex {index}, but there are {vertices} vertices")]
    IndexOutOfRange {
        /// The file.
        path: PathBuf,
        /// Face number (0-based).
        face: usize,
        /// The offending vertex index.
        index: i64,
        /// Number of vertices.
        vertices: usize,
    },
    /// LZF decompression of a PCD `binary_compressed` block failed.
    #[error("{path}: LZF decompression failed: {reason}")]
    Decompress {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        reason: String,
    },
    /// The OBJ parser (`tobj`) rejected the file.
    #[error("{path}: OBJ parse error: {source}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: tobj::LoadError,
    },
    /// The data to write is inconsistent (e.g. a scalar channel of the wrong length).
    #[error("{path}: cannot write: {reason}")]
    BadInput {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// What a cloud reader found: records in the file and points kept.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoadReport {
    /// Point records read from the file (including invalid ones).
    pub points_read: usize,
    /// Records dropped because a coordinate was NaN or infinite.
    pub dropped_non_finite: usize,
    /// Width of an organised cloud (PCD `WIDTH`), or the point count.
    pub width: usize,
    /// Height of an organised cloud (PCD `HEIGHT`); 1 for unorganised clouds.
    pub height: usize,
}

impl LoadReport {
    /// Points kept (`points_read − dropped_non_finite`).
    pub fn points_kept(&self) -> usize {
        self.points_read - self.dropped_non_finite
    }
}

/// What a mesh reader found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MeshReport {
    /// Vertices read from the file.
    pub vertices_read: usize,
    /// Faces (polygons) read from the file.
    pub faces_read: usize,
    /// Faces with fewer than three vertices, skipped.
    pub faces_skipped: usize,
    /// Vertices dropped because a coordinate was NaN or infinite (faces using them are dropped too).
    pub dropped_non_finite: usize,
    /// Vertices of the file used by no face, dropped (OBJ only: `tobj` keeps referenced vertices).
    pub unreferenced_dropped: usize,
}

/// A cloud together with its [`LoadReport`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadedCloud {
    /// The finite points and their channels.
    pub cloud: PointCloud,
    /// Counts of read and dropped records.
    pub report: LoadReport,
}

/// A mesh together with its [`MeshReport`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadedMesh {
    /// The triangle mesh (polygons fan-triangulated).
    pub mesh: TriMesh,
    /// Counts of read and skipped elements.
    pub report: MeshReport,
}

/// Lower-case extension of `path` (empty when none).
fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default()
}

/// Read the whole file.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    std::fs::read(path).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Load a point cloud, choosing the reader by extension: `.ply`, `.pcd`,
/// `.xyz`/`.txt`/`.csv`, or `.obj` (every `v` record, faces or not). NaN/inf points are dropped
/// and counted in the report.
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn load_cloud(path: impl AsRef<Path>) -> Result<LoadedCloud, IoError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "ply" => ply::read_cloud(path),
        "pcd" => pcd::read_cloud(path),
        "xyz" | "txt" | "csv" => xyz::read_cloud(path),
        "obj" => obj::read_cloud(path),
        _ => Err(IoError::UnknownFormat {
            path: path.to_path_buf(),
            expected: ".ply, .pcd, .xyz, .txt, .csv, .obj",
        }),
    }
}

/// Load a triangle mesh, choosing the reader by extension: `.ply` or `.obj`.
/// Polygons are fan-triangulated.
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn load_mesh(path: impl AsRef<Path>) -> Result<LoadedMesh, IoError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "ply" => ply::read_mesh(path),
        "obj" => obj::read_mesh(path),
        _ => Err(IoError::UnknownFormat {
            path: path.to_path_buf(),
            expected: ".ply, .obj",
        }),
    }
}

/// Write a mesh, choosing the writer by extension: `.ply` (binary
/// little-endian, with the vertex scalars) or `.obj`.
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn save_mesh(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<(), IoError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "ply" => ply::write_mesh(path, mesh, None),
        "obj" => obj::write_mesh(path, mesh),
        _ => Err(IoError::UnknownFormat {
            path: path.to_path_buf(),
            expected: ".ply, .obj",
        }),
    }
}

/// Write a point cloud, choosing the writer by extension: `.ply` (binary
/// little-endian, colour as `red green blue` when the cloud has `r g b`
/// channels, every other channel as a float property) or `.pcd` (binary).
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn save_cloud(path: impl AsRef<Path>, cloud: &PointCloud) -> Result<(), IoError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "ply" => ply::write_cloud(path, cloud),
        "pcd" => pcd::write_cloud(path, cloud, false),
        _ => Err(IoError::UnknownFormat {
            path: path.to_path_buf(),
            expected: ".ply, .pcd",
        }),
    }
}

/// What an output file will hold, for [`check_output`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    /// A mesh ([`save_mesh`]: `.ply`, `.obj`).
    Mesh,
    /// A point cloud ([`save_cloud`]: `.ply`, `.pcd`).
    Cloud,
}

/// Check, before any long computation, that `path` has an extension the
/// writer supports and can be opened for writing (its folder exists and is
/// writable). A file this creates is removed again; an existing file is
/// left as it is. An unwritable output was reported only after the whole
/// reconstruction before.
///
/// # Errors
/// [`IoError::UnknownFormat`] or [`IoError::Io`] naming the file.
pub fn check_output(path: impl AsRef<Path>, kind: OutputKind) -> Result<(), IoError> {
    let path = path.as_ref();
    let (ok, expected) = match (kind, extension(path).as_str()) {
        (OutputKind::Mesh, "ply" | "obj") | (OutputKind::Cloud, "ply" | "pcd") => (true, ""),
        (OutputKind::Mesh, _) => (false, ".ply, .obj"),
        (OutputKind::Cloud, _) => (false, ".ply, .pcd"),
    };
    if !ok {
        return Err(IoError::UnknownFormat {
            path: path.to_path_buf(),
            expected,
        });
    }
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|source| IoError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    if !existed {
        // Best effort: the real write follows and replaces it anyway.
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

/// Drop the non-finite points of a freshly read cloud and build its report.
pub(crate) fn finish_cloud(mut cloud: PointCloud, width: usize, height: usize) -> LoadedCloud {
    let points_read = cloud.len();
    let dropped_non_finite = cloud.drop_non_finite();
    LoadedCloud {
        cloud,
        report: LoadReport {
            points_read,
            dropped_non_finite,
            width,
            height,
        },
    }
}

/// Drop non-finite vertices (and the faces that use them), re-indexing the rest.
/// Returns the number of vertices dropped.
pub(crate) fn drop_non_finite_vertices(mesh: &mut TriMesh) -> usize {
    let finite = |p: &Vec3| p.iter().all(|c| c.is_finite());
    if mesh.vertices.iter().all(finite) {
        return 0;
    }
    let mut remap = vec![u32::MAX; mesh.vertices.len()];
    let mut next = 0u32;
    for (i, p) in mesh.vertices.iter().enumerate() {
        if finite(p) {
            remap[i] = next;
            next += 1;
        }
    }
    let dropped = mesh.vertices.len() - next as usize;
    let keep: Vec<bool> = remap.iter().map(|&r| r != u32::MAX).collect();
    let mut it = keep.iter();
    mesh.vertices.retain(|_| *it.next().unwrap_or(&false));
    for (_, values) in &mut mesh.vertex_scalars {
        let mut it = keep.iter();
        values.retain(|_| *it.next().unwrap_or(&false));
    }
    mesh.triangles.retain_mut(|t| {
        let mapped = t.map(|i| remap.get(i as usize).copied().unwrap_or(u32::MAX));
        if mapped.contains(&u32::MAX) {
            false
        } else {
            *t = mapped;
            true
        }
    });
    dropped
}

/// Map a value in `[0, 1]` to an RGB colour (blue → cyan → green → yellow →
/// red, a perceptually ordered "jet"-like ramp), for coloured maps such as
/// the separability map. Values outside `[0, 1]` are clamped; NaN is grey.
pub fn colormap(value: f32) -> [u8; 3] {
    if value.is_nan() {
        return [128, 128, 128];
    }
    let v = value.clamp(0.0, 1.0);
    // Piecewise-linear through 5 stops.
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 1.0],
        [0.0, 1.0, 1.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
    ];
    let x = v * 4.0;
    let i = (x.floor() as usize).min(3);
    let f = x - i as f32;
    let c = |k: usize| ((STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f) * 255.0).round() as u8;
    [c(0), c(1), c(2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colormap_ends_and_middle() {
        assert_eq!(colormap(0.0), [0, 0, 255]);
        assert_eq!(colormap(1.0), [255, 0, 0]);
        assert_eq!(colormap(0.5), [0, 255, 0]);
        assert_eq!(colormap(-3.0), [0, 0, 255]);
        assert_eq!(colormap(f32::NAN), [128, 128, 128]);
    }

    #[test]
    fn non_finite_vertices_are_dropped_with_their_faces() {
        let mut m = TriMesh {
            vertices: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(f64::NAN, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            vertex_scalars: vec![("q".into(), vec![0.0, 1.0, 2.0, 3.0])],
        };
        assert_eq!(drop_non_finite_vertices(&mut m), 1);
        assert_eq!(m.vertices.len(), 3);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert_eq!(m.vertex_scalars[0].1, vec![0.0, 2.0, 3.0]);
    }

    #[test]
    fn outputs_are_checked_before_the_work() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("m.ply");
        check_output(&ok, OutputKind::Mesh).unwrap();
        assert!(!ok.exists(), "the probe file is removed");
        let missing = dir.path().join("no/such/dir/m.obj");
        let e = check_output(&missing, OutputKind::Mesh).unwrap_err();
        assert!(
            matches!(e, IoError::Io { .. }) && e.to_string().contains("m.obj"),
            "{e}"
        );
        let e = check_output(dir.path().join("m.pcd"), OutputKind::Mesh).unwrap_err();
        assert!(matches!(e, IoError::UnknownFormat { .. }), "{e}");
        check_output(dir.path().join("c.pcd"), OutputKind::Cloud).unwrap();
        // A folder is not a writable file.
        assert!(check_output(dir.path().join("d.ply"), OutputKind::Cloud).is_ok());
        std::fs::create_dir(dir.path().join("d.ply")).unwrap();
        assert!(check_output(dir.path().join("d.ply"), OutputKind::Cloud).is_err());
    }

    #[test]
    fn unknown_extension_is_an_error_naming_the_file() {
        let e = load_cloud("/nonexistent/cloud.foo").unwrap_err();
        assert!(e.to_string().contains("cloud.foo"), "{e}");
        let e = load_mesh("/nonexistent/mesh.pcd").unwrap_err();
        assert!(matches!(e, IoError::UnknownFormat { .. }));
        let e = load_cloud("/nonexistent/cloud.ply").unwrap_err();
        assert!(matches!(e, IoError::Io { .. }), "{e}");
    }
}
