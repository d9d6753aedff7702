//! The decoders under fuzzing, one entry point per target. Shared by the
//! libFuzzer targets of this crate (`cargo +nightly fuzz run --fuzz-dir
//! tests/fuzz TARGET`) and by the stable short pass `tests/fuzz_short.rs`
//! of the main crate, which includes this file with `#[path]`.
//!
//! Every entry point feeds arbitrary bytes to a reader and only requires it
//! to return (an error is fine): a panic, an abort or a stall is a finding.

use std::path::Path;

/// The fuzz targets, by name (also the corpus folder names).
pub const TARGETS: [&str; 6] = ["pointcloud2", "ply", "pcd", "xyz", "obj", "mcap"];

/// PointCloud2 from CDR bytes, with the default wire limits.
pub fn pointcloud2(data: &[u8]) {
    let limits = sepmem::wire::pointcloud2::WireConfig::default();
    let _ = sepmem::wire::pointcloud2::decode_pointcloud2_cdr(data, &limits);
}

/// PLY as a cloud and as a mesh (ascii, binary little and big endian).
pub fn ply(data: &[u8]) {
    let _ = sepmem::io::ply::parse_cloud(data, Path::new("fuzz.ply"));
    let _ = sepmem::io::ply::parse_mesh(data, Path::new("fuzz.ply"));
}

/// PCD (ascii, binary, binary_compressed).
pub fn pcd(data: &[u8]) {
    let _ = sepmem::io::pcd::parse_cloud(data, Path::new("fuzz.pcd"));
}

/// XYZ text.
pub fn xyz(data: &[u8]) {
    let _ = sepmem::io::xyz::parse_cloud(data, Path::new("fuzz.xyz"));
}

/// OBJ as a mesh (tobj) and as a cloud (every `v` record).
pub fn obj(data: &[u8]) {
    let _ = sepmem::io::obj::parse_mesh(data, Path::new("fuzz.obj"));
    let _ = sepmem::io::obj::parse_cloud(data, Path::new("fuzz.obj"));
}

/// The MCAP bag reader: topics (summary or message scan) and every message.
pub fn mcap(data: &[u8]) {
    let _ = sepmem::bag::parse_mcap(Path::new("fuzz.mcap"), data);
}

/// Run target `name` on `data`; false for an unknown name.
pub fn run(name: &str, data: &[u8]) -> bool {
    match name {
        "pointcloud2" => pointcloud2(data),
        "ply" => ply(data),
        "pcd" => pcd(data),
        "xyz" => xyz(data),
        "obj" => obj(data),
        "mcap" => mcap(data),
        _ => return false,
    }
    true
}
