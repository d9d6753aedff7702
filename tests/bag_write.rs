//! sepmem's MCAP bag writer: read back by sepmem's reader, and by the
//! independent Python readers (`rosbags`, `mcap` + `mcap-ros2-support`)
//! through `tests/python/check_bag.py` when they are installed.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use sepmem::bag::{Bag, BagWriter, Qos};
use sepmem::cloud::{PointCloud, Vec3};
use sepmem::wire::msgs::*;
use sepmem::wire::pointcloud2::encode_pointcloud2;
use sepmem::wire::{decode, msgdef};

fn external_check(bag: &Path, args: &[String], test: &str) -> Option<String> {
    common::external_bag_check(bag, args, test)
}

fn sample_cloud(n: usize) -> PointCloud {
    let mut c = PointCloud::from_points(
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.1;
                Vec3::new(t.cos(), t.sin(), 0.01 * i as f64)
            })
            .collect(),
    );
    c.set_attribute("r", (0..n).map(|i| (i % 7) as f32 / 6.0).collect())
        .unwrap();
    c.set_attribute("g", vec![0.5; n]).unwrap();
    c.set_attribute("b", vec![1.0; n]).unwrap();
    c.set_attribute("label", (0..n).map(|i| (i % 3) as f32).collect())
        .unwrap();
    c
}

fn header(ns: i64) -> Header {
    Header {
        stamp: Time::from_nanos(ns),
        frame_id: "map".into(),
    }
}

fn write_sample_bag(path: &Path) -> sepmem::bag::BagSummary {
    let mut w = BagWriter::create(path).unwrap();
    w.add_topic("/seg/points", PointCloud2::TYPE_NAME, Qos::sensor_data())
        .unwrap();
    let t0 = 1_700_000_000_000_000_000i64;
    for k in 0..3i64 {
        let t = t0 + k * 100_000_000;
        let cloud = encode_pointcloud2(&sample_cloud(50 + k as usize), header(t));
        w.write("/seg/points", t as u64, &cloud).unwrap();
        let surf = SurfaceMesh {
            header: header(t),
            stream_id: "/seg/points#1".into(),
            object_id: 1,
            vertices: vec![
                Point {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                },
                Point {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                },
                Point {
                    x: 0.0,
                    y: 1.0,
                    z: 0.0,
                },
                Point {
                    x: 0.0,
                    y: 0.0,
                    z: 1.0,
                },
            ],
            triangles: [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
                .map(|v| MeshTriangle { vertex_indices: v })
                .to_vec(),
            vertex_separability: vec![0.9, 0.8, 0.7, 0.6],
            global_separability: 0.75,
            grid_m: 8,
            grid_l: 5,
            iterations: 10 - k as u32,
            warm_start: k > 0,
            start_reason: if k == 0 {
                "first_frame"
            } else {
                "previous_surface"
            }
            .into(),
            stop_reason: "converged".into(),
            quality: SurfaceMesh::FITTED,
        };
        w.write("/sepmem/surface", t as u64 + 5_000_000, &surf)
            .unwrap();
        let markers = MarkerArray {
            markers: vec![
                Marker {
                    header: header(t),
                    action: Marker::DELETEALL,
                    ..Default::default()
                },
                Marker {
                    header: header(t),
                    ns: "sepmem".into(),
                    id: 1,
                    type_: Marker::TRIANGLE_LIST,
                    scale: Vector3 {
                        x: 1.0,
                        y: 1.0,
                        z: 1.0,
                    },
                    color: ColorRGBA {
                        r: 0.2,
                        g: 0.7,
                        b: 1.0,
                        a: 0.8,
                    },
                    points: surf
                        .triangles
                        .iter()
                        .flat_map(|t| t.vertex_indices.map(|i| surf.vertices[i as usize]))
                        .collect(),
                    ..Default::default()
                },
            ],
        };
        w.write("/sepmem/markers", t as u64 + 5_000_000, &markers)
            .unwrap();
        let frame = FrameDiagnostics {
            header: header(t),
            stream_id: "/seg/points#1".into(),
            frame_index: k as u64,
            points_in: 50 + k as u32,
            points_used: 50 + k as u32,
            iterations: 10 - k as u32,
            global_separability: 0.75,
            latency_ms: 3.0,
            warm_start: k > 0,
            start_reason: "first_frame".into(),
            stop_reason: "converged".into(),
            ..Default::default()
        };
        w.write("/sepmem/frames", t as u64 + 5_000_000, &frame)
            .unwrap();
    }
    let diag = DiagnosticArray {
        header: header(t0),
        status: vec![DiagnosticStatus {
            level: DiagnosticStatus::OK,
            name: "sepmem: /seg/points#1".into(),
            message: "ok".into(),
            hardware_id: "test".into(),
            values: vec![KeyValue {
                key: "eta_g".into(),
                value: "0.75".into(),
            }],
        }],
    };
    w.write("/diagnostics", t0 as u64 + 300_000_000, &diag)
        .unwrap();
    let mesh = Mesh::default();
    w.write("/sepmem/mesh", t0 as u64, &mesh).unwrap();
    w.finish().unwrap()
}

const EXPECTED: &[(&str, &str, u64)] = &[
    ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", 1),
    ("/seg/points", "sensor_msgs/msg/PointCloud2", 3),
    ("/sepmem/frames", "sepmem_msgs/msg/FrameDiagnostics", 3),
    ("/sepmem/markers", "visualization_msgs/msg/MarkerArray", 3),
    ("/sepmem/mesh", "shape_msgs/msg/Mesh", 1),
    ("/sepmem/surface", "sepmem_msgs/msg/SurfaceMesh", 3),
];

fn check_readback(bag_path: &Path) {
    let bag = Bag::open(bag_path).unwrap();
    let got: Vec<(&str, &str, u64)> = bag
        .topics
        .iter()
        .map(|t| (t.name.as_str(), t.type_name.as_str(), t.message_count))
        .collect();
    assert_eq!(got, EXPECTED);
    for t in &bag.topics {
        assert_eq!(Some(t.type_hash.as_str()), type_hash(&t.type_name));
        assert!(t.offered_qos_profiles.contains("history: keep_last"));
    }
    assert!(bag
        .topic("/seg/points")
        .unwrap()
        .offered_qos_profiles
        .contains("reliability: best_effort"));
    let msgs = bag.read(&[]).unwrap();
    assert!(msgs.windows(2).all(|w| w[0].log_time <= w[1].log_time));
    let clouds: Vec<PointCloud2> = msgs
        .iter()
        .filter(|m| m.topic == "/seg/points")
        .map(|m| decode(&m.data).unwrap())
        .collect();
    assert_eq!(
        clouds.iter().map(|c| c.width).collect::<Vec<_>>(),
        vec![50, 51, 52]
    );
    let s: SurfaceMesh = decode(
        &msgs
            .iter()
            .find(|m| m.topic == "/sepmem/surface")
            .unwrap()
            .data,
    )
    .unwrap();
    assert_eq!(s.triangles.len(), 4);
}

#[test]
fn written_bag_directory_reads_back_here_and_in_python() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("out_bag");
    let summary = write_sample_bag(&dir);
    assert_eq!(summary.mcap_path, dir.join("out_bag_0.mcap"));
    let meta = std::fs::read_to_string(summary.metadata_path.unwrap()).unwrap();
    assert!(meta.contains("version: 9"));
    assert!(meta.contains("message_count: 14"));
    check_readback(&dir);
    // Schemas are the full concatenated definitions.
    let buf = std::fs::read(&summary.mcap_path).unwrap();
    let s = mcap::Summary::read(&buf).unwrap().unwrap();
    for schema in s.schemas.values() {
        assert_eq!(schema.encoding, "ros2msg");
        assert_eq!(
            std::str::from_utf8(&schema.data).unwrap(),
            msgdef::full_definition(&schema.name).unwrap()
        );
    }
    let mut args = Vec::new();
    for (t, ty, n) in EXPECTED {
        args.push("--expect".to_string());
        args.push(format!("{t}={n}"));
        args.push("--type".to_string());
        args.push(format!("{t}={ty}"));
    }
    if let Some(out) = external_check(&dir, &args, "bag_write::directory") {
        eprintln!("check_bag.py {}:\n{out}", dir.display());
        assert!(
            out.contains("OK rosbags+mcap: 6 topics, 14 messages decoded"),
            "{out}"
        );
    }
}

#[test]
fn written_single_mcap_file_reads_back_here_and_in_python() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("single.mcap");
    let summary = write_sample_bag(&file);
    assert!(summary.metadata_path.is_none());
    check_readback(&file);
    if let Some(out) = external_check(&file, &[], "bag_write::single_file") {
        assert!(
            out.contains("OK rosbags+mcap: 6 topics, 14 messages decoded"),
            "{out}"
        );
    }
}

#[test]
fn committed_bags_pass_the_external_check() {
    for (dir, line) in [
        (
            "bags/mosd_rosbags",
            "OK rosbags+mcap: 4 topics, 12 messages decoded",
        ),
        (
            "bags/mosd_rosbags_db3",
            "OK rosbags: 1 topics, 2 messages decoded",
        ),
    ] {
        let path = common::data_dir().join(dir);
        if let Some(out) = external_check(&path, &[], "bag_write::committed_bags") {
            assert!(out.contains(line), "{dir}: {out}");
        }
    }
}

#[test]
fn writer_rejects_conflicts_and_unknown_topics() {
    let tmp = tempfile::tempdir().unwrap();
    let mut w = BagWriter::create(&tmp.path().join("x.mcap")).unwrap();
    w.add_topic("/a", PointCloud2::TYPE_NAME, Qos::default())
        .unwrap();
    assert!(w.add_topic("/a", Mesh::TYPE_NAME, Qos::default()).is_err());
    assert!(w
        .add_topic("/b", "nope_msgs/msg/Nope", Qos::default())
        .is_err());
    assert!(w.write_raw("/c", 0, 0, &[0, 1, 0, 0]).is_err());
}

/// The rosbag2-written reference bags (`tests/data/rosbag2`, see SOURCE.md).
fn rosbag2_fixture(name: &str) -> std::path::PathBuf {
    common::data_dir().join("rosbag2").join(name)
}

/// The last `rosbag2` metadata record's `serialized_metadata` of an MCAP file.
fn serialized_metadata(path: &Path) -> String {
    let buf = std::fs::read(path).unwrap();
    let mut last = None;
    for record in mcap::read::LinearReader::new(&buf).unwrap() {
        if let mcap::records::Record::Metadata(m) = record.unwrap() {
            if m.name == "rosbag2" {
                last = m.metadata.get("serialized_metadata").cloned();
            }
        }
    }
    last.expect("no rosbag2 metadata record")
}

/// Keys at the root of a block-style YAML map.
fn root_keys(yaml: &str) -> Vec<String> {
    yaml.lines()
        .filter(|l| !l.starts_with(' ') && !l.starts_with('-'))
        .filter_map(|l| l.split_once(':').map(|(k, _)| k.to_string()))
        .collect()
}

#[test]
fn serialized_metadata_is_the_bare_bag_metadata_map_of_rosbag2() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("meta_bag");
    let summary = write_sample_bag(&dir);
    let ours = serialized_metadata(&summary.mcap_path);
    // rosbag2_storage_mcap's reader: node["version"].as<int>() at the root.
    assert!(ours.starts_with("version: 9\n"), "{ours}");
    assert!(!ours.contains("rosbag2_bagfile_information"));
    let reference = serialized_metadata(&rosbag2_fixture("only_topics.mcap"));
    assert_eq!(root_keys(&ours), root_keys(&reference));
    // metadata.yaml keeps the wrapper key, with the same map under it.
    let yaml = std::fs::read_to_string(summary.metadata_path.unwrap()).unwrap();
    let fixture_yaml = std::fs::read_to_string(rosbag2_fixture("metadata.yaml")).unwrap();
    assert_eq!(root_keys(&yaml), ["rosbag2_bagfile_information"]);
    assert_eq!(root_keys(&yaml), root_keys(&fixture_yaml));
    // The whole structure, key for key, parsed by PyYAML as rosbag2 parses it.
    if !common::python_tools() {
        common::skipped(
            "serialized_metadata (PyYAML check)",
            "python3 with mcap not available (pip install -r tests/python/requirements.txt)",
        );
        return;
    }
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_rosbag2_metadata.py");
    for fixture in [
        "only_topics.mcap",
        "bag_with_topics_and_service_events.mcap",
    ] {
        let out = std::process::Command::new("python3")
            .arg(&script)
            .arg(&summary.mcap_path)
            .arg(rosbag2_fixture(fixture))
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        eprintln!("check_rosbag2_metadata.py vs {fixture}: {stdout}");
        assert!(
            out.status.success(),
            "{stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
        assert_eq!(v["version"], 9);
        assert_eq!(v["key_paths"], v["reference_key_paths"]);
        assert_eq!(v["topics"].as_object().unwrap().len(), 6);
    }
}

#[test]
fn rosbag2_written_fixtures_read_with_the_bag_reader() {
    for (file, topics, messages) in [
        ("only_topics.mcap", 3, 7),
        ("bag_with_topics_and_service_events.mcap", 5, 10),
    ] {
        let bag = Bag::open(&rosbag2_fixture(file)).unwrap();
        assert_eq!(
            bag.topics.len() + bag.skipped_topics.len(),
            topics,
            "{file}"
        );
        assert_eq!(bag.message_count(), messages, "{file}");
        let pe = bag.topics.iter().find(|t| t.name == "/parameter_events");
        if let Some(t) = pe {
            assert_eq!(t.type_name, "rcl_interfaces/msg/ParameterEvent");
            assert_eq!(
                t.type_hash,
                "RIHS01_043e627780fcad87a22d225bc2a037361dba713fca6a6b9f4b869a5aa0393204"
            );
        }
        let names: Vec<&str> = bag.topics.iter().map(|t| t.name.as_str()).collect();
        let read = bag.read(&names).unwrap();
        assert_eq!(read.len() as u64, messages, "{file}");
        assert!(read.windows(2).all(|w| w[0].log_time <= w[1].log_time));
    }
}
