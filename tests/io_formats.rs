//! Readers and writers against real files: every shared dataset loads with
//! the counts stated in `../shared/datasets/SOURCES.md`, committed fixtures
//! decode to independently known values, writers round-trip, and truncated
//! or mutated files give errors, never panics.
#![allow(clippy::unwrap_used)]

mod common;

use proptest::prelude::*;
use sepmem::cloud::{PointCloud, Vec3};
use sepmem::io::{self, obj, pcd, ply, xyz, IoError};
use sepmem::mesh::TriMesh;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Point files: (name, records in the file, finite points), from SOURCES.md.
const CLOUDS: &[(&str, usize, usize)] = &[
    ("milk.pcd", 13_704, 13_704),
    ("milk_color.pcd", 13_704, 13_704),
    ("bunny.pcd", 397, 397),
    ("bun0.pcd", 397, 397),
    ("bun01.pcd", 200, 200),
    ("bun02.pcd", 217, 217),
    ("bun03.pcd", 197, 197),
    ("bun4.pcd", 361, 361),
    ("car6.pcd", 10_031, 10_031),
    ("lamppost.pcd", 1_771, 1_771),
    ("milk_cartoon_all_small_clorox.pcd", 307_200, 241_407),
    ("table_scene_mug_stereo_textured.pcd", 307_200, 209_280),
    ("test0.pcd", 307_200, 189_198),
    ("test31.pcd", 307_200, 170_909),
    ("test36.pcd", 307_200, 173_864),
    ("test44.pcd", 307_200, 172_274),
    ("test50.pcd", 307_200, 184_757),
    ("test44_label60_toilet_paper_roll.pcd", 3_942, 3_942),
    ("test31_label40_pringles_can.pcd", 10_249, 10_249),
    ("test31_label30_black_canister.pcd", 9_906, 9_906),
    ("test36_label30_red_can.pcd", 7_389, 7_389),
    ("test0_label20_cereal_box.pcd", 16_630, 16_630),
];

/// Mesh files: (name, vertices, faces, watertight per SOURCES.md).
const MESHES: &[(&str, usize, usize, bool)] = &[
    ("cube.ply", 24, 12, false), // WT only after welding its duplicated corners
    ("tum_rabbit_converted.ply", 10_429, 20_715, false),
    ("hammer.obj", 30_082, 60_160, true),
    ("torus.obj", 2_304, 4_608, true),
    ("sphere.obj", 642, 1_280, true),
    ("armadillo.obj", 14_587, 29_170, true),
    ("bunny.obj", 3_301, 6_598, true),
    ("spot_low_resolution.obj", 829, 1_654, true),
    ("stanford-bunny.obj", 35_947, 69_451, false),
    ("fandisk.obj", 6_475, 12_946, true),
    ("YcbBanana.obj", 7_866, 15_728, true),
    ("YcbMustardBottle.obj", 7_866, 15_728, true),
    ("YcbTomatoSoupCan.obj", 7_850, 15_728, true),
    ("YcbCrackerBox.obj", 7_866, 15_728, true),
];

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            walk(&p, out);
        } else {
            out.push(p);
        }
    }
}

fn name(p: &Path) -> &str {
    p.file_name().unwrap().to_str().unwrap()
}

#[test]
fn every_shared_dataset_file_loads_with_the_documented_counts() {
    let Some(root) =
        common::shared_datasets("every_shared_dataset_file_loads_with_the_documented_counts")
    else {
        return;
    };
    let mut files = Vec::new();
    walk(&root, &mut files);
    files.sort();
    let mut checked = Vec::new();
    for f in &files {
        let ext = f
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let n = name(f);
        match ext.as_str() {
            "pcd" => {
                let c = io::load_cloud(f).unwrap_or_else(|e| panic!("{e}"));
                let &(_, read, kept) = CLOUDS
                    .iter()
                    .find(|c| c.0 == n)
                    .unwrap_or_else(|| panic!("{n} is not in the expectation table"));
                assert_eq!(c.report.points_read, read, "{n}");
                assert_eq!(c.cloud.len(), kept, "{n}");
                assert_eq!(c.report.dropped_non_finite, read - kept, "{n}");
                assert!(c
                    .cloud
                    .points
                    .iter()
                    .all(|p| p.iter().all(|v| v.is_finite())));
                if let Some(r) = c.cloud.attribute("r") {
                    assert!(r.iter().all(|v| (0.0..=1.0).contains(v)), "{n}");
                }
                checked.push(n.to_string());
            }
            "ply" | "obj" => {
                let m = io::load_mesh(f).unwrap_or_else(|e| panic!("{e}"));
                let &(_, v, t, wt) = MESHES
                    .iter()
                    .find(|c| c.0 == n)
                    .unwrap_or_else(|| panic!("{n} is not in the expectation table"));
                assert_eq!(m.report.vertices_read, v, "{n}");
                assert_eq!(
                    m.mesh.vertices.len() + m.report.unreferenced_dropped,
                    v,
                    "{n}"
                );
                if n != "stanford-bunny.obj" {
                    assert_eq!(m.report.unreferenced_dropped, 0, "{n}");
                }
                assert_eq!(m.mesh.triangles.len(), t, "{n}");
                assert_eq!(m.mesh.topology().degenerate_triangles, 0, "{n}");
                if wt {
                    assert!(
                        m.mesh.topology().is_watertight(),
                        "{n}: {:?}",
                        m.mesh.topology()
                    );
                }
                // The same file also loads as a cloud of its vertices: for an
                // OBJ every `v` record (tobj reorders and leaves out unused ones).
                let mut cloud = io::load_cloud(f).unwrap().cloud.points;
                if ext == "obj" {
                    assert_eq!(cloud.len(), v, "{n}");
                    // tobj reads float32; the cloud reader keeps the file's f64.
                    let key =
                        |p: &sepmem::cloud::Vec3| [p.x, p.y, p.z].map(|c| (c as f32).to_bits());
                    let mut used: Vec<_> = m.mesh.vertices.iter().map(key).collect();
                    let all: std::collections::HashSet<_> = cloud.iter().map(key).collect();
                    used.retain(|k| !all.contains(k));
                    assert!(used.is_empty(), "{n}: mesh vertices missing from the cloud");
                    cloud = m.mesh.vertices.clone();
                }
                assert_eq!(cloud, m.mesh.vertices, "{n}");
                checked.push(n.to_string());
            }
            _ => {}
        }
    }
    for n in CLOUDS.iter().map(|c| c.0).chain(MESHES.iter().map(|m| m.0)) {
        assert!(
            checked.iter().any(|c| c == n),
            "{n} listed in SOURCES.md but not found"
        );
    }
}

#[test]
fn mosd_labels_match_sources_and_the_extracted_objects() {
    let Some(root) = common::shared_datasets("mosd_labels_match_sources_and_the_extracted_objects")
    else {
        return;
    };
    let dir = root.join("mosd_tabletop_segmentation");
    let scene = io::load_cloud(dir.join("test31.pcd")).unwrap().cloud;
    let labels = scene.attribute("label").unwrap();
    let mut counts: BTreeMap<u32, usize> = BTreeMap::new();
    for &l in labels {
        *counts.entry(l as u32).or_default() += 1;
    }
    assert_eq!(counts[&20], 12_425);
    assert_eq!(counts[&30], 9_906);
    assert_eq!(counts[&40], 10_249);
    // The extracted object (binary PCD written by the dataset's own Python
    // decoder) must equal our binary_compressed decode of the scene.
    let obj = io::load_cloud(dir.join("extracted_objects/test31_label40_pringles_can.pcd"))
        .unwrap()
        .cloud;
    let idx: Vec<usize> = (0..scene.len()).filter(|&i| labels[i] == 40.0).collect();
    let sel = scene.select(&idx);
    assert_eq!(sel.points, obj.points);
    for ch in ["r", "g", "b"] {
        assert_eq!(
            sel.attribute(ch).unwrap(),
            obj.attribute(ch).unwrap(),
            "{ch}"
        );
    }
    // Real colours: not all black.
    assert!(obj.luma().unwrap().iter().any(|&l| l > 0.2));
}

#[test]
fn committed_pcd_fixtures_decode_to_known_values() {
    let d = common::data_dir();
    let car = io::load_cloud(d.join("car6.pcd")).unwrap();
    assert_eq!(car.report.points_read, 10_031);
    assert_eq!(car.cloud.len(), 10_031);
    let e = car.cloud.aabb().extent();
    // SOURCES.md: about 6.2 × 6.7 × 1.6 m.
    for (got, want) in e.iter().zip([6.2, 6.7, 1.6]) {
        assert!((got - want).abs() < 0.1, "extent {e:?}");
    }
    let bun = io::load_cloud(d.join("bun01.pcd")).unwrap().cloud;
    assert_eq!(bun.len(), 200);
    // First and last data lines of the file.
    let first = Vec3::new(0.0054216, 0.11349, 0.040749);
    assert!((bun.points[0] - first).norm() < 1e-7);
    let text = std::fs::read_to_string(d.join("bun01.pcd")).unwrap();
    let last: Vec<f64> = text
        .lines()
        .last()
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    assert!((bun.points[199] - Vec3::new(last[0], last[1], last[2])).norm() < 1e-7);
}

#[test]
fn committed_ply_fixtures_little_big_endian_and_ascii_agree() {
    let d = common::data_dir();
    let le = io::load_mesh(d.join("cube.ply")).unwrap().mesh;
    let be = io::load_mesh(d.join("cube_be.ply")).unwrap().mesh;
    assert_eq!(le.vertices.len(), 24);
    assert_eq!(le.triangles.len(), 12);
    assert_eq!(le.vertices, be.vertices);
    assert_eq!(le.triangles, be.triangles);
    assert!((le.aabb().extent() - Vec3::new(2.0, 2.0, 2.0)).norm() < 1e-12);
    assert!((le.area() - 24.0).abs() < 1e-9);
    assert!((le.signed_volume().abs() - 8.0).abs() < 1e-9);
    // Colour and quality as make_fixtures.py wrote them.
    let be_cloud = io::load_cloud(d.join("cube_be.ply")).unwrap().cloud;
    for i in 0..24 {
        assert_eq!(be_cloud.attribute("r").unwrap()[i], (10 * i) as f32 / 255.0);
        assert_eq!(
            be_cloud.attribute("g").unwrap()[i],
            (255 - 10 * i) as f32 / 255.0
        );
        assert_eq!(be_cloud.attribute("b").unwrap()[i], 7.0 / 255.0);
        assert_eq!(be_cloud.attribute("quality").unwrap()[i], i as f32 / 2.0);
    }
    let tet = io::load_mesh(d.join("tetra_ascii.ply")).unwrap().mesh;
    assert!(tet.topology().is_watertight());
    assert!((tet.signed_volume() - 1.0 / 6.0).abs() < 1e-7);
    assert_eq!(tet.scalar("b").unwrap(), &[0.0, 0.0, 1.0, 1.0]);
}

fn icosphere_like() -> TriMesh {
    // An octahedron with per-vertex scalars: closed, outward.
    TriMesh {
        vertices: vec![
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, -1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, -1.0),
        ],
        triangles: vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ],
        vertex_scalars: vec![
            ("eta".into(), vec![0.0, 0.1, 0.2, 0.3, 0.4, 0.5]),
            ("weight".into(), vec![1.0, -2.0, 3.5, 0.25, 8.0, 1e-3]),
        ],
    }
}

#[test]
fn mesh_round_trips_through_ply_and_obj() {
    let dir = tempfile::tempdir().unwrap();
    let m = icosphere_like();
    assert!((m.signed_volume() - 4.0 / 3.0).abs() < 1e-12);
    let colours: Vec<[u8; 3]> = (0..6).map(|i| [i * 40, 255 - i * 40, 3]).collect();
    let p = dir.path().join("m.ply");
    ply::write_mesh(&p, &m, Some(&colours)).unwrap();
    let back = io::load_mesh(&p).unwrap().mesh;
    assert_eq!(back.vertices, m.vertices);
    assert_eq!(back.triangles, m.triangles);
    assert_eq!(back.scalar("eta").unwrap(), m.scalar("eta").unwrap());
    assert_eq!(back.scalar("weight").unwrap(), m.scalar("weight").unwrap());
    let r: Vec<f32> = colours.iter().map(|c| c[0] as f32 / 255.0).collect();
    assert_eq!(back.scalar("r").unwrap(), &r[..]);
    // The header is what the PLY spec says (independent of our reader).
    let bytes = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(
        &bytes[..bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()],
    );
    assert!(text.contains("format binary_little_endian 1.0"));
    assert!(text.contains("element vertex 6"));
    assert!(text.contains("property float eta"));
    assert!(text.contains("element face 8"));
    // Size: header + 6 × (12 + 8 + 3) + 8 × 13 bytes.
    let header_len = text.len() + 11;
    assert_eq!(bytes.len(), header_len + 6 * 23 + 8 * 13);

    let o = dir.path().join("m.obj");
    io::save_mesh(&o, &m).unwrap();
    let back = io::load_mesh(&o).unwrap().mesh;
    // tobj renumbers vertices by first use; the geometry of every triangle is kept.
    assert_eq!(back.vertices.len(), m.vertices.len());
    assert_eq!(back.triangles.len(), m.triangles.len());
    for t in 0..m.triangles.len() {
        assert_eq!(back.corners(t), m.corners(t));
    }
    assert!(back.topology().is_watertight());
}

#[test]
fn cloud_round_trips_through_ply_and_pcd() {
    let dir = tempfile::tempdir().unwrap();
    let n = 300;
    let mut c = PointCloud::from_points(
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.1;
                Vec3::new(t.cos(), t.sin(), 0.01 * i as f64)
            })
            .collect(),
    );
    let eta: Vec<f32> = (0..n).map(|i| i as f32 / n as f32).collect();
    let rgb: Vec<[u8; 3]> = eta.iter().map(|&e| io::colormap(e)).collect();
    for (k, ch) in ["r", "g", "b"].iter().enumerate() {
        c.set_attribute(ch, rgb.iter().map(|c| c[k] as f32 / 255.0).collect())
            .unwrap();
    }
    c.set_attribute("separability", eta.clone()).unwrap();
    let p = dir.path().join("map.ply");
    ply::write_cloud(&p, &c).unwrap();
    let back = io::load_cloud(&p).unwrap();
    assert_eq!(back.report.points_read, n);
    for (a, b) in back.cloud.points.iter().zip(&c.points) {
        assert!((a - b).norm() < 1e-6);
    }
    assert_eq!(back.cloud.attribute("separability").unwrap(), &eta[..]);
    for ch in ["r", "g", "b"] {
        assert_eq!(back.cloud.attribute(ch), c.attribute(ch), "{ch}");
    }
    for compressed in [false, true] {
        let p = dir.path().join(format!("c{compressed}.pcd"));
        pcd::write_cloud(&p, &c, compressed).unwrap();
        let back = io::load_cloud(&p).unwrap().cloud;
        assert_eq!(back.len(), n);
        assert_eq!(back.attribute("separability").unwrap(), &eta[..]);
        assert_eq!(back.attribute("g"), c.attribute("g"));
    }
}

#[test]
fn pcd_writer_output_matches_the_pcl_reference_layout() {
    // Re-encode car6.pcd (PCL's own binary_compressed file) and compare the
    // decoded points, and the binary layout size against POINTS·12 bytes.
    let d = common::data_dir();
    let car = io::load_cloud(d.join("car6.pcd")).unwrap().cloud;
    let bin = pcd::encode_cloud(&car, false);
    let header_end = bin.windows(12).position(|w| w == b"DATA binary\n").unwrap() + 12;
    assert_eq!(bin.len() - header_end, car.len() * 12);
    let back = pcd::parse_cloud(&bin, Path::new("x.pcd")).unwrap().cloud;
    assert_eq!(back.points, car.points);
}

/// Parse `bytes` with every reader; none may panic.
fn all_readers(bytes: &[u8]) {
    let p = Path::new("fuzz");
    let _ = ply::parse_cloud(bytes, p);
    let _ = ply::parse_mesh(bytes, p);
    let _ = pcd::parse_cloud(bytes, p);
    let _ = xyz::parse_cloud(bytes, p);
    let _ = obj::parse_mesh(bytes, p);
}

fn fixtures() -> Vec<Vec<u8>> {
    let d = common::data_dir();
    let mut v: Vec<Vec<u8>> = [
        "cube.ply",
        "cube_be.ply",
        "tetra_ascii.ply",
        "bun01.pcd",
        "car6.pcd",
    ]
    .iter()
    .map(|f| std::fs::read(d.join(f)).unwrap())
    .collect();
    let m = icosphere_like();
    v.push(ply::encode_mesh(&m, None, Path::new("m")).unwrap());
    v.push(obj::encode_mesh(&m));
    let c = PointCloud::from_points(m.vertices.clone());
    v.push(pcd::encode_cloud(&c, true));
    v.push(pcd::encode_cloud(&c, false));
    v.push(b"1 2 3 4\n5 6 7 8\n".to_vec());
    v
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn truncated_and_mutated_files_never_panic(
        which in 0usize..10,
        cut in 0.0f64..=1.0,
        edits in proptest::collection::vec((0.0f64..1.0, any::<u8>()), 0..8),
    ) {
        let files = fixtures();
        let mut b = files[which % files.len()].clone();
        for &(at, byte) in &edits {
            if !b.is_empty() {
                let i = ((at * b.len() as f64) as usize).min(b.len() - 1);
                b[i] = byte;
            }
        }
        let keep = (cut * b.len() as f64) as usize;
        b.truncate(keep);
        all_readers(&b);
    }
}

#[test]
fn every_truncation_of_the_small_fixtures_is_an_error_or_a_prefix() {
    // Cutting a binary file anywhere inside its data must be reported, not ignored.
    let d = common::data_dir();
    for f in ["cube.ply", "cube_be.ply"] {
        let bytes = std::fs::read(d.join(f)).unwrap();
        for cut in 0..bytes.len() {
            let r = ply::parse_mesh(&bytes[..cut], Path::new(f));
            assert!(r.is_err(), "{f} cut at {cut} of {} parsed", bytes.len());
        }
    }
    let car = std::fs::read(d.join("car6.pcd")).unwrap();
    // PCL pads the file after the LZF block; cut anywhere up to the block's end.
    let data = car
        .windows(23)
        .position(|w| w == b"DATA binary_compressed\n")
        .unwrap()
        + 23;
    let csize = u32::from_le_bytes(car[data..data + 4].try_into().unwrap()) as usize;
    let end = data + 8 + csize;
    assert!(end <= car.len());
    for cut in (0..end).step_by(97).chain([end - 1]) {
        let e = pcd::parse_cloud(&car[..cut], Path::new("car6.pcd"));
        assert!(e.is_err(), "cut at {cut}");
        assert!(e.unwrap_err().to_string().contains("car6.pcd"));
    }
    let e = io::load_cloud("does/not/exist.pcd").unwrap_err();
    assert!(matches!(e, IoError::Io { .. }));
}
