//! CDR byte-exactness and RIHS01 hashes against an independent
//! implementation (Python `rosbags`, fixtures made by
//! `tests/python/make_cdr_fixtures.py`, committed under `tests/data/cdr/`).
#![allow(clippy::unwrap_used)]

mod common;

use sepmem::wire::msgdef::{self, BaseType, DefMap};
use sepmem::wire::msgs::*;
use sepmem::wire::{decode, encode, RosMessage, WireError};

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(common::data_dir().join("cdr").join(name)).unwrap()
}

fn header(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header {
        stamp: Time { sec, nanosec },
        frame_id: frame.to_string(),
    }
}

fn pf(name: &str, offset: u32, datatype: u8) -> PointField {
    PointField::new(name, offset, datatype, 1)
}

fn pc2_xyzrgb() -> PointCloud2 {
    PointCloud2 {
        header: header(12, 345, "map"),
        height: 1,
        width: 3,
        fields: vec![
            pf("x", 0, 7),
            pf("y", 4, 7),
            pf("z", 8, 7),
            pf("rgb", 12, 7),
        ],
        is_bigendian: false,
        point_step: 16,
        row_step: 48,
        data: (0..48u32).map(|i| ((i * 7 + 3) % 256) as u8).collect(),
        is_dense: true,
    }
}

fn pc2_utf8() -> PointCloud2 {
    PointCloud2 {
        header: header(-5, 999_999_999, "caméra_ß"),
        height: 2,
        width: 2,
        fields: vec![
            pf("z", 16, 8),
            pf("x", 0, 8),
            pf("y", 8, 8),
            pf("label", 24, 2),
        ],
        is_bigendian: false,
        point_step: 32,
        row_step: 64,
        data: (0..128u32).map(|i| ((i * 13 + 1) % 256) as u8).collect(),
        is_dense: false,
    }
}

fn p(x: f64, y: f64, z: f64) -> Point {
    Point { x, y, z }
}

fn rgba(r: f32, g: f32, b: f32, a: f32) -> ColorRGBA {
    ColorRGBA { r, g, b, a }
}

fn marker_array() -> MarkerArray {
    let delete_all = Marker {
        header: header(1, 2, "map"),
        action: Marker::DELETEALL,
        ..Default::default()
    };
    let tri = Marker {
        header: header(1, 2, "map"),
        ns: "sepmem".into(),
        id: 7,
        type_: Marker::TRIANGLE_LIST,
        action: Marker::ADD,
        scale: Vector3 {
            x: 1.0,
            y: 1.0,
            z: 1.0,
        },
        color: rgba(0.2, 0.6, 1.0, 0.8),
        lifetime: Duration {
            sec: 0,
            nanosec: 500_000_000,
        },
        points: vec![p(0.0, 0.0, 0.0), p(1.0, 0.0, 0.0), p(0.0, 1.0, 0.5)],
        colors: vec![
            rgba(1.0, 0.0, 0.0, 1.0),
            rgba(0.0, 1.0, 0.0, 1.0),
            rgba(0.0, 0.0, 1.0, 1.0),
        ],
        ..Default::default()
    };
    MarkerArray {
        markers: vec![delete_all, tri],
    }
}

fn kv(k: &str, v: &str) -> KeyValue {
    KeyValue {
        key: k.into(),
        value: v.into(),
    }
}

fn diagnostic_array() -> DiagnosticArray {
    DiagnosticArray {
        header: header(100, 5, ""),
        status: vec![
            DiagnosticStatus {
                level: DiagnosticStatus::OK,
                name: "sepmem: stream /seg/points".into(),
                message: "warm".into(),
                hardware_id: "host1".into(),
                values: vec![kv("eta_g", "0.912"), kv("iterations", "4")],
            },
            DiagnosticStatus {
                level: DiagnosticStatus::ERROR,
                name: "sepmem: stream /seg/points#3".into(),
                message: "cold: eta drop".into(),
                hardware_id: "host1".into(),
                values: vec![],
            },
        ],
    }
}

fn mesh() -> Mesh {
    Mesh {
        triangles: vec![
            MeshTriangle {
                vertex_indices: [0, 1, 2],
            },
            MeshTriangle {
                vertex_indices: [0, 2, 3],
            },
        ],
        vertices: vec![
            p(0.0, 0.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(1.0, 1.0, 0.0),
            p(0.25, -1.5, 2.0),
        ],
    }
}

fn collision_object() -> CollisionObject {
    let pose = Pose {
        position: p(0.1, -0.2, 1.5),
        orientation: Quaternion::default(),
    };
    CollisionObject {
        header: header(7, 8, "camera"),
        pose,
        id: "sepmem/seg/points#3".into(),
        object_type: ObjectType {
            key: "k".into(),
            db: String::new(),
        },
        primitives: vec![SolidPrimitive {
            kind: 1,
            dimensions: vec![0.1, 0.2, 0.3],
            polygon: Polygon {
                points: vec![Point32 {
                    x: 1.0,
                    y: 2.0,
                    z: 3.0,
                }],
            },
        }],
        primitive_poses: vec![pose],
        meshes: vec![mesh()],
        mesh_poses: vec![pose],
        planes: vec![Plane {
            coef: [0.0, 0.0, 1.0, -0.5],
        }],
        plane_poses: vec![pose],
        subframe_names: vec!["tip".into()],
        subframe_poses: vec![pose],
        operation: CollisionObject::ADD,
    }
}

fn surface_mesh() -> SurfaceMesh {
    SurfaceMesh {
        header: header(7, 8, "base_link"),
        stream_id: "/seg/points#3".into(),
        object_id: 3,
        vertices: vec![p(0.5, 0.0, 0.0), p(0.0, 0.5, 0.0), p(0.0, 0.0, 0.5)],
        triangles: vec![MeshTriangle {
            vertex_indices: [0, 1, 2],
        }],
        vertex_separability: vec![0.25, 0.5, 0.75],
        global_separability: 0.875,
        grid_m: 16,
        grid_l: 9,
        iterations: 12,
        warm_start: true,
        start_reason: "previous_surface".into(),
        stop_reason: "converged".into(),
        quality: SurfaceMesh::HELD,
    }
}

fn frame_diagnostics() -> FrameDiagnostics {
    FrameDiagnostics {
        header: header(7, 8, "base_link"),
        stream_id: "/seg/points#3".into(),
        frame_index: 41,
        points_in: 20000,
        points_used: 19876,
        points_dropped: 124,
        iterations: 12,
        global_separability: 0.875,
        latency_ms: 6.5,
        warm_start: false,
        start_reason: "first_frame".into(),
        stop_reason: "iteration_cap".into(),
    }
}

fn ground_truth() -> GroundTruth {
    GroundTruth {
        header: header(7, 8, "camera"),
        stream_id: "/synth/points#2".into(),
        mesh_id: "torus".into(),
        pose: Pose {
            position: Point {
                x: 0.1,
                y: -0.2,
                z: 1.5,
            },
            orientation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.6,
                w: 0.8,
            },
        },
        world_frame_id: "world".into(),
        camera_pose: Pose {
            position: Point {
                x: -0.5,
                y: 0.25,
                z: 0.125,
            },
            orientation: Quaternion {
                x: 0.6,
                y: 0.0,
                z: 0.0,
                w: 0.8,
            },
        },
        width: 640,
        height: 480,
        fx: 525.0,
        fy: 526.5,
        cx: 319.5,
        cy: 239.25,
        visible_points: 1234,
        vertices: vec![
            Point {
                x: 0.5,
                y: 0.0,
                z: 0.0,
            },
            Point {
                x: 0.0,
                y: 0.5,
                z: 0.0,
            },
            Point {
                x: 0.0,
                y: 0.0,
                z: 0.5,
            },
        ],
        triangles: vec![MeshTriangle {
            vertex_indices: [0, 2, 1],
        }],
    }
}

fn check<M: RosMessage + PartialEq + std::fmt::Debug>(name: &str, msg: &M) {
    let want = fixture(name);
    let got = encode(msg).unwrap();
    assert_eq!(got, want, "{name}: our CDR differs from rosbags'");
    assert_eq!(&decode::<M>(&want).unwrap(), msg, "{name}: decode");
    // Trailing bytes (DDS alignment padding) are ignored.
    let mut padded = want.clone();
    padded.extend_from_slice(&[0, 0, 0]);
    assert_eq!(
        &decode::<M>(&padded).unwrap(),
        msg,
        "{name}: trailing bytes"
    );
    // Every truncation is a typed error, never a panic.
    for cut in 0..want.len() {
        let r = decode::<M>(&want[..cut]);
        // Cutting only trailing alignment-free bytes can still decode.
        if let Ok(m) = r {
            assert_eq!(&m, msg, "{name}: cut {cut} decoded to something else");
        }
    }
}

#[test]
fn encodings_match_rosbags_byte_for_byte() {
    check("pointcloud2_xyzrgb.cdr", &pc2_xyzrgb());
    check("pointcloud2_utf8_organised.cdr", &pc2_utf8());
    check("marker_array.cdr", &marker_array());
    check("diagnostic_array.cdr", &diagnostic_array());
    check("mesh.cdr", &mesh());
    check("surface_mesh.cdr", &surface_mesh());
    check("frame_diagnostics.cdr", &frame_diagnostics());
    check("ground_truth.cdr", &ground_truth());
    check("collision_object.cdr", &collision_object());
}

#[test]
fn big_endian_cdr_from_rosbags_decodes() {
    let be = fixture("pointcloud2_utf8_organised_be.cdr");
    assert_eq!(&be[..4], &[0, 0, 0, 0], "fixture should be CDR_BE");
    assert_eq!(decode::<PointCloud2>(&be).unwrap(), pc2_utf8());
}

#[test]
fn forged_lengths_and_xcdr2_are_typed_errors() {
    let mut b = fixture("pointcloud2_xyzrgb.cdr");
    // frame_id length at payload offset 8 (byte 12): make it huge.
    b[12..16].copy_from_slice(&0x7fff_fff0u32.to_le_bytes());
    assert!(matches!(
        decode::<PointCloud2>(&b),
        Err(WireError::Truncated { .. })
    ));
    let mut b = fixture("pointcloud2_xyzrgb.cdr");
    b[1] = 7; // XCDR2 / unknown representation
    assert!(matches!(
        decode::<PointCloud2>(&b),
        Err(WireError::BadEncapsulation { .. })
    ));
    let mut b = fixture("pointcloud2_xyzrgb.cdr");
    let n = b.len();
    b[n - 1] = 7; // is_dense is a bool: 7 is invalid
    assert!(matches!(
        decode::<PointCloud2>(&b),
        Err(WireError::Decode { .. })
    ));
}

fn rosbags_table() -> serde_json::Map<String, serde_json::Value> {
    let text = std::fs::read_to_string(common::data_dir().join("cdr/rosbags_types.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// Registry with sepmem's own types re-parsed from `msg/msg/*.msg` on disk.
fn registry_from_disk() -> DefMap {
    let mut defs = msgdef::registry().unwrap().clone();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("msg/msg");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "msg") {
            let name = path.file_stem().unwrap().to_str().unwrap();
            let type_name = format!("sepmem_msgs/msg/{name}");
            let text = std::fs::read_to_string(&path).unwrap();
            defs.insert(
                type_name.clone(),
                msgdef::parse_msg(&type_name, &text).unwrap(),
            );
            n += 1;
        }
    }
    assert!(n >= 2, "expected sepmem's .msg files in {}", dir.display());
    defs
}

#[test]
fn rihs01_constants_recomputed_by_the_rep2011_algorithm() {
    let defs = registry_from_disk();
    for (name, hash) in TYPE_HASHES {
        assert_eq!(
            &msgdef::rihs01(&defs, name).unwrap(),
            hash,
            "recomputed RIHS01 of {name}"
        );
    }
    // Every registered type has a hard-coded hash and every .msg on disk is registered.
    for t in msgdef::known_types() {
        assert!(type_hash(t).is_some(), "{t} has no hard-coded hash");
    }
    for t in defs.keys() {
        assert!(
            type_hash(t).is_some(),
            "{t} (from msg/) has no hard-coded hash"
        );
    }
    // Published reference values (REP-2011 tables quoted in the interop notes).
    assert_eq!(
        PointCloud2::TYPE_HASH,
        "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5"
    );
    assert_eq!(
        MarkerArray::TYPE_HASH,
        "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"
    );
}

#[test]
fn hashes_and_fields_agree_with_rosbags() {
    let table = rosbags_table();
    let defs = registry_from_disk();
    assert_eq!(table.len(), TYPE_HASHES.len());
    for (name, entry) in &table {
        assert_eq!(
            entry["rihs01"].as_str().unwrap(),
            type_hash(name).unwrap(),
            "{name}: rosbags' RIHS01"
        );
        // rosbags' own definition text, parsed by our parser, has the same
        // fields as our registry's text.
        let root = entry["msgdef"]
            .as_str()
            .unwrap()
            .split("\n=====")
            .next()
            .unwrap();
        let theirs = msgdef::parse_msg(name, root).unwrap();
        let ours = &defs[name];
        assert_eq!(theirs.fields, ours.fields, "{name}: fields");
        let const_names =
            |d: &msgdef::MsgDef| d.constants.iter().map(|c| c.0.clone()).collect::<Vec<_>>();
        assert_eq!(const_names(&theirs), const_names(ours), "{name}: constants");
    }
}

#[test]
fn full_definitions_are_rosbag2_concatenations() {
    for (name, _) in TYPE_HASHES {
        let text = msgdef::full_definition(name).unwrap();
        let sep = format!("\n{}\nMSG: ", "=".repeat(80));
        let mut sections = text.split(sep.as_str());
        assert_eq!(
            sections.next().unwrap(),
            msgdef::definition_text(name).unwrap()
        );
        // Each dependency exactly once, and exactly the transitive closure.
        let mut seen = std::collections::BTreeSet::new();
        for s in sections {
            let (short, body) = s.split_once('\n').unwrap();
            let (pkg, ty) = short.split_once('/').unwrap();
            let full = format!("{pkg}/msg/{ty}");
            assert_eq!(
                body,
                msgdef::definition_text(&full).unwrap(),
                "{name}: {full}"
            );
            assert!(seen.insert(full), "{name}: duplicate {short}");
        }
        let defs = msgdef::registry().unwrap();
        assert_eq!(seen, msgdef::dependencies(defs, name).unwrap(), "{name}");
    }
    let pc2 = msgdef::full_definition(PointCloud2::TYPE_NAME).unwrap();
    let order: Vec<&str> = pc2
        .lines()
        .filter_map(|l| l.strip_prefix("MSG: "))
        .collect();
    assert_eq!(
        order,
        [
            "sensor_msgs/PointField",
            "std_msgs/Header",
            "builtin_interfaces/Time"
        ]
    );
    // Nested types exist in the registry with fields (no empty text).
    for t in msgdef::known_types() {
        let d = &msgdef::registry().unwrap()[t];
        assert!(!d.fields.is_empty(), "{t}");
        for f in &d.fields {
            if let BaseType::Nested(n) = &f.base {
                assert!(msgdef::definition_text(n).is_some(), "{t}.{}: {n}", f.name);
            }
        }
    }
}
