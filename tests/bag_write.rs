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

/// Keys at the root of a YAML map, parsed by a YAML 1.2 parser.
fn root_keys(yaml: &str) -> Vec<String> {
    let doc = yaml_doc(yaml);
    doc.as_hash()
        .map(|h| {
            h.keys()
                .filter_map(|k| k.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default()
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
    for fixture in [
        "only_topics.mcap",
        "bag_with_topics_and_service_events.mcap",
    ] {
        let v = python_metadata_check(&summary.mcap_path, &rosbag2_fixture(fixture));
        assert_eq!(v["version"], 9);
        assert_eq!(v["topics"].as_object().unwrap().len(), 6);
    }
}

/// `tests/python/check_rosbag2_metadata.py BAG REFERENCE` (PyYAML): its JSON
/// report, asserting that it found no difference in the key structure.
fn python_metadata_check(bag: &Path, reference: &Path) -> serde_json::Value {
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_rosbag2_metadata.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .arg(bag)
        .arg(reference)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!(
        "check_rosbag2_metadata.py {} vs {}: {stdout}",
        bag.display(),
        reference.display()
    );
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(v["key_paths"], v["reference_key_paths"]);
    v
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

// ---- rosbag2's reading of the `rosbag2` metadata record -------------------

use std::collections::BTreeMap;
use yaml_rust2::{Yaml, YamlLoader};

/// The one document of `text`, parsed by a YAML 1.2 parser (yaml-rust2;
/// rosbag2 uses yaml-cpp).
fn yaml_doc(text: &str) -> Yaml {
    let mut docs = YamlLoader::load_from_str(text).unwrap();
    assert_eq!(docs.len(), 1, "one YAML document expected:\n{text}");
    docs.remove(0)
}

/// `node[key]`, an error naming `at` when the key is absent.
fn field<'a>(node: &'a Yaml, key: &str, at: &str) -> Result<&'a Yaml, String> {
    match &node[key] {
        Yaml::BadValue => Err(format!("{at}: no `{key}`")),
        v => Ok(v),
    }
}

/// yaml-cpp's `as<std::string>()`: any scalar but null.
fn text(node: &Yaml, key: &str, at: &str) -> Result<String, String> {
    match field(node, key, at)? {
        Yaml::String(s) | Yaml::Real(s) => Ok(s.clone()),
        Yaml::Integer(i) => Ok(i.to_string()),
        Yaml::Boolean(b) => Ok(b.to_string()),
        v => Err(format!("{at}/{key}: {v:?} is not a string")),
    }
}

/// yaml-cpp's `as<uint64_t>()`.
fn unsigned(node: &Yaml, key: &str, at: &str) -> Result<u64, String> {
    match field(node, key, at)? {
        Yaml::Integer(i) if *i >= 0 => Ok(*i as u64),
        v => Err(format!("{at}/{key}: {v:?} is not an unsigned integer")),
    }
}

fn sequence<'a>(node: &'a Yaml, key: &str, at: &str) -> Result<&'a [Yaml], String> {
    field(node, key, at)?
        .as_vec()
        .map(Vec::as_slice)
        .ok_or_else(|| format!("{at}/{key}: not a sequence"))
}

/// One topic of `topics_with_message_count`, as rosbag2 decodes it.
#[derive(Debug, PartialEq)]
struct Rosbag2Topic {
    name: String,
    type_name: String,
    serialization_format: String,
    qos_profiles: usize,
    type_description_hash: String,
    message_count: u64,
}

/// The fields `convert<BagMetadata>::decode` (rosbag2_storage/yaml.hpp)
/// reads, with their types and version gates.
#[derive(Debug)]
struct Rosbag2Metadata {
    version: i64,
    storage_identifier: String,
    duration_ns: u64,
    starting_time_ns: u64,
    message_count: u64,
    topics: Vec<Rosbag2Topic>,
    relative_file_paths: Vec<String>,
    /// (path, starting time, duration, message count).
    files: Vec<(String, u64, u64, u64)>,
}

/// One `Rosbag2QoS` (rosbag2_storage/qos.cpp): `history` an int or an rmw
/// policy name, reliability / durability / liveliness ints up to version 8
/// and rmw policy names from 9, three `{sec, nsec}` durations, a bool.
fn decode_qos(q: &Yaml, version: i64, at: &str) -> Result<(), String> {
    let policy = |key: &str, names: &[&str]| -> Result<(), String> {
        match field(q, key, at)? {
            Yaml::Integer(_) if version <= 8 || key == "history" => Ok(()),
            Yaml::String(s) if version >= 9 && names.contains(&s.as_str()) => Ok(()),
            v => Err(format!(
                "{at}/{key}: {v:?} is no {key} policy of version {version}"
            )),
        }
    };
    policy(
        "history",
        &["keep_last", "keep_all", "system_default", "unknown"],
    )?;
    policy(
        "reliability",
        &[
            "reliable",
            "best_effort",
            "system_default",
            "best_available",
            "unknown",
        ],
    )?;
    policy(
        "durability",
        &[
            "volatile",
            "transient_local",
            "system_default",
            "best_available",
            "unknown",
        ],
    )?;
    policy(
        "liveliness",
        &[
            "automatic",
            "manual_by_topic",
            "system_default",
            "best_available",
            "unknown",
        ],
    )?;
    if matches!(&q["history"], Yaml::Integer(1)) || q["history"].as_str() == Some("keep_last") {
        unsigned(q, "depth", at)?;
    }
    for d in ["deadline", "lifespan", "liveliness_lease_duration"] {
        let t = field(q, d, at)?;
        unsigned(t, "sec", &format!("{at}/{d}"))?;
        unsigned(t, "nsec", &format!("{at}/{d}"))?;
    }
    match field(q, "avoid_ros_namespace_conventions", at)? {
        Yaml::Boolean(_) => Ok(()),
        v => Err(format!("{at}/avoid_ros_namespace_conventions: {v:?}")),
    }
}

/// `offered_qos_profiles`: a YAML string holding the list up to version 8,
/// the list itself from version 9.
fn decode_qos_profiles(t: &Yaml, version: i64, at: &str) -> Result<usize, String> {
    let parsed;
    let list = match field(t, "offered_qos_profiles", at)? {
        Yaml::String(s) if version <= 8 => {
            parsed = yaml_doc(s);
            parsed.as_vec().cloned().unwrap_or_default()
        }
        Yaml::Array(a) if version >= 9 => a.clone(),
        v => {
            return Err(format!(
                "{at}/offered_qos_profiles: {v:?} in version {version}"
            ))
        }
    };
    for (i, q) in list.iter().enumerate() {
        decode_qos(q, version, &format!("{at}/offered_qos_profiles[{i}]"))?;
    }
    Ok(list.len())
}

fn decode_topic(t: &Yaml, version: i64, at: &str) -> Result<Rosbag2Topic, String> {
    let m = field(t, "topic_metadata", at)?;
    let at_m = format!("{at}/topic_metadata");
    Ok(Rosbag2Topic {
        name: text(m, "name", &at_m)?,
        type_name: text(m, "type", &at_m)?,
        serialization_format: text(m, "serialization_format", &at_m)?,
        qos_profiles: if version >= 4 {
            decode_qos_profiles(m, version, &at_m)?
        } else {
            0
        },
        type_description_hash: if version >= 7 {
            text(m, "type_description_hash", &at_m)?
        } else {
            String::new()
        },
        message_count: unsigned(t, "message_count", at)?,
    })
}

/// Decode `serialized_metadata` as rosbag2_storage_mcap's `read_metadata`
/// does: `YAML::Load`, then `node.as<BagMetadata>()` from the root.
fn decode_rosbag2_metadata(serialized: &str) -> Result<Rosbag2Metadata, String> {
    let root = yaml_doc(serialized);
    let version = match field(&root, "version", "root")? {
        Yaml::Integer(v) => *v,
        v => return Err(format!("root/version: {v:?} is not an int")),
    };
    let topics = sequence(&root, "topics_with_message_count", "root")?
        .iter()
        .enumerate()
        .map(|(i, t)| decode_topic(t, version, &format!("topics_with_message_count[{i}]")))
        .collect::<Result<Vec<_>, _>>()?;
    let relative_file_paths = sequence(&root, "relative_file_paths", "root")?
        .iter()
        .map(|p| {
            p.as_str()
                .map(String::from)
                .ok_or("relative_file_paths: not a string")
        })
        .collect::<Result<Vec<_>, _>>()?;
    if version >= 3 {
        text(&root, "compression_format", "root")?;
        text(&root, "compression_mode", "root")?;
    }
    let mut files = Vec::new();
    if version >= 5 {
        for (i, f) in sequence(&root, "files", "root")?.iter().enumerate() {
            let at = format!("files[{i}]");
            files.push((
                text(f, "path", &at)?,
                unsigned(
                    field(f, "starting_time", &at)?,
                    "nanoseconds_since_epoch",
                    &at,
                )?,
                unsigned(field(f, "duration", &at)?, "nanoseconds", &at)?,
                unsigned(f, "message_count", &at)?,
            ));
        }
    }
    if version >= 6 {
        // Iterated as a map of strings; a null node iterates as empty.
        match field(&root, "custom_data", "root")? {
            Yaml::Null => {}
            Yaml::Hash(h) if h.values().all(|v| v.as_str().is_some()) => {}
            v => return Err(format!("root/custom_data: {v:?}")),
        }
    }
    if version >= 8 {
        text(&root, "ros_distro", "root")?;
    }
    Ok(Rosbag2Metadata {
        version,
        storage_identifier: text(&root, "storage_identifier", "root")?,
        duration_ns: unsigned(
            field(&root, "duration", "root")?,
            "nanoseconds",
            "root/duration",
        )?,
        starting_time_ns: unsigned(
            field(&root, "starting_time", "root")?,
            "nanoseconds_since_epoch",
            "root/starting_time",
        )?,
        message_count: unsigned(&root, "message_count", "root")?,
        topics,
        relative_file_paths,
        files,
    })
}

/// Every key path of a YAML node (sequences: the union over their items),
/// `offered_qos_profiles` strings (version 8) parsed first, as
/// `tests/python/check_rosbag2_metadata.py` does with PyYAML.
fn key_paths(node: &Yaml, path: &str, out: &mut std::collections::BTreeSet<String>) {
    match node {
        Yaml::Hash(h) => {
            for (k, v) in h {
                let key = k.as_str().unwrap_or("?");
                let here = format!("{path}/{key}");
                out.insert(here.clone());
                match v {
                    Yaml::String(s) if key == "offered_qos_profiles" => {
                        key_paths(&yaml_doc(s), &here, out)
                    }
                    _ => key_paths(v, &here, out),
                }
            }
        }
        Yaml::Array(a) => a
            .iter()
            .for_each(|v| key_paths(v, &format!("{path}[]"), out)),
        _ => {}
    }
}

fn key_paths_of(serialized: &str) -> std::collections::BTreeSet<String> {
    let mut out = std::collections::BTreeSet::new();
    key_paths(&yaml_doc(serialized), "", &mut out);
    out
}

/// What the MCAP file itself holds: per channel of its summary (schema
/// name, message encoding, `topic_type_hash`, messages), the messages
/// counted one by one (chunks decompressed), and the first and last log
/// time.
struct McapContents {
    topics: BTreeMap<String, (String, String, String, u64)>,
    log_times: Option<(u64, u64)>,
}

fn mcap_contents(path: &Path) -> McapContents {
    let buf = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&buf).unwrap().unwrap();
    let mut topics: BTreeMap<String, (String, String, String, u64)> = summary
        .channels
        .values()
        .map(|c| {
            let schema = c
                .schema
                .as_ref()
                .map(|s| s.name.clone())
                .unwrap_or_default();
            let hash = c
                .metadata
                .get("topic_type_hash")
                .cloned()
                .unwrap_or_default();
            (
                c.topic.clone(),
                (schema, c.message_encoding.clone(), hash, 0),
            )
        })
        .collect();
    let mut log_times: Option<(u64, u64)> = None;
    for m in mcap::MessageStream::new(&buf).unwrap() {
        let m = m.unwrap();
        topics.get_mut(&m.channel.topic).unwrap().3 += 1;
        let t = m.log_time;
        log_times = Some(log_times.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
    }
    McapContents { topics, log_times }
}

/// Decode the bag's metadata record as rosbag2 does and check it against the
/// file's own records and, key for key, against a rosbag2-written fixture.
fn assert_rosbag2_reads(path: &Path) -> Rosbag2Metadata {
    let serialized = serialized_metadata(path);
    let what = path.display();
    let m = decode_rosbag2_metadata(&serialized)
        .unwrap_or_else(|e| panic!("{what}: rosbag2 could not decode the metadata: {e}"));
    assert_eq!(m.version, 9, "{what}");
    assert_eq!(m.storage_identifier, "mcap", "{what}");
    let file = path.file_name().unwrap().to_str().unwrap().to_string();
    assert_eq!(m.relative_file_paths, std::slice::from_ref(&file), "{what}");
    let truth = mcap_contents(path);
    let (first, last) = truth.log_times.unwrap_or((0, 0));
    let total: u64 = truth.topics.values().map(|t| t.3).sum();
    assert_eq!(
        (m.message_count, m.starting_time_ns, m.duration_ns),
        (total, first, last - first),
        "{what}: message count, starting time, duration"
    );
    assert_eq!(m.files, [(file, first, last - first, total)], "{what}");
    let topics: BTreeMap<String, (String, String, String, u64)> = m
        .topics
        .iter()
        .map(|t| {
            assert!(t.qos_profiles >= 1, "{what}: {} has no QoS profile", t.name);
            let v = (
                t.type_name.clone(),
                t.serialization_format.clone(),
                t.type_description_hash.clone(),
                t.message_count,
            );
            (t.name.clone(), v)
        })
        .collect();
    assert_eq!(topics, truth.topics, "{what}: topics_with_message_count");
    let reference = serialized_metadata(&rosbag2_fixture("only_topics.mcap"));
    assert_eq!(
        key_paths_of(&serialized),
        key_paths_of(&reference),
        "{what}: key structure differs from the rosbag2-written only_topics.mcap"
    );
    m
}

/// Every MCAP file under `dir` (recursively) whose header names sepmem as
/// its writing library.
fn sepmem_written_mcaps(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.is_dir() {
            sepmem_written_mcaps(&p, out);
        } else if p.extension().is_some_and(|e| e == "mcap") {
            let buf = std::fs::read(&p).unwrap();
            let header = mcap::read::LinearReader::new(&buf)
                .ok()
                .and_then(|mut r| r.next())
                .and_then(Result::ok);
            if let Some(mcap::records::Record::Header(h)) = header {
                if h.library.starts_with("sepmem-") {
                    out.push(p);
                }
            }
        }
    }
}

#[test]
fn rosbag2_metadata_decoder_accepts_rosbag2_bags_and_rejects_the_wrapped_map() {
    // The decoder itself, on what rosbag2 wrote (version 8) ...
    for fixture in [
        "only_topics.mcap",
        "bag_with_topics_and_service_events.mcap",
    ] {
        let m = decode_rosbag2_metadata(&serialized_metadata(&rosbag2_fixture(fixture))).unwrap();
        assert_eq!((m.version, m.storage_identifier.as_str()), (8, "mcap"));
    }
    // ... and on the metadata.yaml text that sepmem used to embed.
    let yaml = std::fs::read_to_string(rosbag2_fixture("metadata.yaml")).unwrap();
    let err = decode_rosbag2_metadata(&yaml).unwrap_err();
    assert_eq!(err, "root: no `version`");
}

#[test]
fn every_committed_sepmem_bag_holds_metadata_that_rosbag2_reads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut bags = Vec::new();
    sepmem_written_mcaps(&root.join("tests/data"), &mut bags);
    // The fuzz seed corpus holds a whole bag too; `cut.mcap` is that bag
    // truncated on purpose (no metadata record).
    sepmem_written_mcaps(&root.join("tests/fuzz/corpus"), &mut bags);
    bags.retain(|p| !p.ends_with("cut.mcap"));
    bags.sort();
    let names: Vec<String> = bags
        .iter()
        .map(|p| p.strip_prefix(root).unwrap().display().to_string())
        .collect();
    assert_eq!(
        names,
        [
            "tests/data/bags/robot_view/occluded_orbit.mcap",
            "tests/data/bags/robot_view/orbit_bent_tube.mcap",
            "tests/data/bags/robot_view/orbit_ycb_banana.mcap",
            "tests/data/bags/robot_view/swap.mcap",
            "tests/data/bags/robot_view/turn_bent_tube.mcap",
            "tests/data/bags/robot_view/turn_bottle.mcap",
            "tests/data/bags/robot_view/turn_can.mcap",
            "tests/data/bags/robot_view/turn_capsule.mcap",
            "tests/data/bags/robot_view/turn_capsule_faults.mcap",
            "tests/data/bags/robot_view/turn_rounded_box.mcap",
            "tests/data/bags/robot_view/turn_sphere.mcap",
            "tests/data/bags/robot_view/turn_ycb_banana.mcap",
            "tests/data/bags/synth_ellipsoid.mcap",
            "tests/data/bags/synth_turn_mug.mcap",
            "tests/data/bags/synth_two_labelled.mcap",
            "tests/fuzz/corpus/mcap/bag.mcap",
        ]
    );
    for bag in &bags {
        let m = assert_rosbag2_reads(bag);
        eprintln!(
            "{}: rosbag2 decodes version {}, {} topics, {} messages",
            bag.display(),
            m.version,
            m.topics.len(),
            m.message_count
        );
    }
    // The same check by PyYAML (independent of this file's decoder).
    if !common::python_tools() {
        common::skipped(
            "every_committed_sepmem_bag (PyYAML check)",
            "python3 with mcap not available (pip install -r tests/python/requirements.txt)",
        );
        return;
    }
    for bag in &bags {
        let v = python_metadata_check(bag, &rosbag2_fixture("only_topics.mcap"));
        assert_eq!(v["version"], 9, "{}: {v}", bag.display());
    }
}

#[test]
fn a_bag_written_by_replay_matches_the_rosbag2_fixtures_key_for_key() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("replayed.mcap");
    let input = common::data_dir().join("bags/synth_ellipsoid.mcap");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["replay", "-q", "--no-score"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m = assert_rosbag2_reads(&out);
    let topics: Vec<(&str, u64)> = m
        .topics
        .iter()
        .map(|t| (t.name.as_str(), t.message_count))
        .collect();
    // One mesh, marker array, frame diagnostics and fused model per input
    // frame (12).
    assert_eq!(
        topics,
        [
            ("/synth/ellipsoid/points/membrane_diagnostics", 12),
            ("/synth/ellipsoid/points/mesh", 12),
            ("/synth/ellipsoid/points/mesh_markers", 12),
            ("/synth/ellipsoid/points/model", 12),
        ]
    );
    if common::python_tools() {
        for fixture in [
            "only_topics.mcap",
            "bag_with_topics_and_service_events.mcap",
        ] {
            python_metadata_check(&out, &rosbag2_fixture(fixture));
        }
    } else {
        common::skipped(
            "a_bag_written_by_replay (PyYAML check)",
            "python3 with mcap not available (pip install -r tests/python/requirements.txt)",
        );
    }
}

/// (topic, type, messages) of a bag as Python rosbags and mcap list them
/// (`tests/python/bag_topics.py`), or `None` without the Python tools.
fn python_topic_lists(bag: &Path) -> Option<[Vec<(String, String, u64)>; 2]> {
    if !common::python_tools() {
        common::skipped(
            "rosbag2_written_fixtures (Python topic lists)",
            "python3 with rosbags and mcap not available (pip install -r tests/python/requirements.txt)",
        );
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/bag_topics.py");
    let out = std::process::Command::new("python3")
        .arg(script)
        .arg(bag)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let list = |key: &str| -> Vec<(String, String, u64)> {
        serde_json::from_value(v[key].clone()).unwrap()
    };
    Some([list("rosbags"), list("mcap")])
}

#[test]
fn rosbag2_written_fixtures_replay_through_sepmem() {
    for file in [
        "only_topics.mcap",
        "bag_with_topics_and_service_events.mcap",
    ] {
        let path = rosbag2_fixture(file);
        let bag = Bag::open(&path).unwrap();
        assert!(
            bag.skipped_topics.is_empty(),
            "{file}: {:?}",
            bag.skipped_topics
        );
        let ours: Vec<(String, String, u64)> = bag
            .topics
            .iter()
            .map(|t| (t.name.clone(), t.type_name.clone(), t.message_count))
            .collect();
        if let Some([rosbags, mcap]) = python_topic_lists(&path) {
            assert_eq!(ours, rosbags, "{file}: the bag reader vs Python rosbags");
            assert_eq!(ours, mcap, "{file}: the bag reader vs Python mcap");
        }
        // rosbag2's test bags hold no PointCloud2: replay says so in one
        // line naming every topic it found, and exits with 1.
        assert!(ours.iter().all(|t| t.1 != PointCloud2::TYPE_NAME));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_sepmem"))
            .arg("replay")
            .arg(&path)
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{file}: {err}");
        assert!(o.stdout.is_empty(), "{file}");
        assert_eq!(err.lines().count(), 1, "{file}: {err}");
        let expected = format!(
            "error: no {} topic to replay in {} (topics: {})",
            PointCloud2::TYPE_NAME,
            path.display(),
            ours.iter()
                .map(|t| t.0.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
        assert_eq!(err.trim_end(), expected, "{file}");
    }
}
