//! `sepmem synth` bags: written sequences read back with the expected topics,
//! counts and types (sepmem's reader and, when installed, the independent
//! Python readers via `tests/python/check_bag.py`); the ground truth
//! round-trips and agrees with the rendered points; output is deterministic;
//! the committed fixture bags are what `make_synth_bags.sh` says.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use sepmem::bag::Bag;
use sepmem::synth::sequence::{
    build_streams, write_sequence, Layout, SequenceSpec, GROUND_TRUTH_TOPIC, START_NS,
};
use sepmem::synth::truth::GroundTruthIndex;
use sepmem::synth::Noise;
use sepmem::wire::pointcloud2::{decode_pointcloud2_cdr, WireConfig};

const PC2: &str = "sensor_msgs/msg/PointCloud2";
const GT: &str = "sepmem_msgs/msg/GroundTruth";

fn external_check(bag: &Path, expect: &[(&str, &str, u64)], test: &str) -> Option<String> {
    let mut args = Vec::new();
    for (topic, ty, n) in expect {
        args.extend(["--expect".to_string(), format!("{topic}={n}")]);
        args.extend(["--type".to_string(), format!("{topic}={ty}")]);
    }
    common::external_bag_check(bag, &args, test)
}

fn spheres(layout: Layout, frames: usize) -> SequenceSpec {
    SequenceSpec {
        shapes: vec!["sphere".into(), "sphere".into()],
        frames,
        points_per_object: 800,
        noise: Noise::none(),
        colour: true,
        layout,
        mesh_resolution: 24,
        seed: 5,
        ..SequenceSpec::default()
    }
}

/// Topics of a bag as (name, type, count).
fn topics(bag: &Bag) -> Vec<(String, String, u64)> {
    bag.topics
        .iter()
        .map(|t| (t.name.clone(), t.type_name.clone(), t.message_count))
        .collect()
}

#[test]
fn labelled_bag_reads_back_and_truth_matches_the_points() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("two.mcap");
    let spec = spheres(
        Layout::Labelled {
            topic: "/cam/points".into(),
        },
        4,
    );
    write_sequence(&spec, &path, |_| {}).unwrap();
    let bag = Bag::open(&path).unwrap();
    assert_eq!(
        topics(&bag),
        [
            ("/cam/points".to_string(), PC2.to_string(), 4),
            (GROUND_TRUTH_TOPIC.to_string(), GT.to_string(), 8),
        ]
    );
    let truth = GroundTruthIndex::from_bag(&bag).unwrap();
    let ids: Vec<&str> = truth.streams.keys().map(|s| s.as_str()).collect();
    assert_eq!(ids, ["/cam/points#1", "/cam/points#2"]);
    assert_eq!(truth.streams["/cam/points#1"].mesh_id, "sphere");
    assert_eq!(truth.streams["/cam/points#2"].mesh_id, "sphere_2");
    for m in bag.read(&["/cam/points"]).unwrap() {
        let d = decode_pointcloud2_cdr(&m.data, &WireConfig::default()).unwrap();
        let stamp = d.header.stamp.to_nanos();
        assert_eq!(stamp as u64, m.log_time);
        assert!(d.cloud.attribute("r").is_some());
        let labels = d.cloud.attribute("label").unwrap();
        let mut per_label: BTreeMap<i64, Vec<usize>> = BTreeMap::new();
        for (i, &l) in labels.iter().enumerate() {
            per_label.entry(l as i64).or_default().push(i);
        }
        for label in [1i64, 2] {
            let id = format!("/cam/points#{label}");
            let f = truth.frame(&id, stamp).unwrap();
            let idx = &per_label[&label];
            assert_eq!(idx.len(), f.visible_points as usize, "{id}");
            assert!(idx.len() > 400, "{id}: {} points", idx.len());
            // Noise-free sphere of radius 0.1 (longest edge 0.2): every point of the
            // segment lies on the sphere centred at the ground-truth position
            // (within float32 rounding and the facets' sagitta).
            let c = f.pose.translation.vector;
            for &i in idx {
                let r = (d.cloud.points[i] - c).norm();
                assert!((0.097..=0.1001).contains(&r), "{id}: r = {r}");
            }
            // ... and so does the posed GT mesh (its vertices are on that sphere).
            let mesh = truth.posed_mesh(&id, stamp).unwrap();
            for v in &mesh.vertices {
                assert!(((v - c).norm() - 0.1).abs() < 1e-9);
            }
        }
    }
    let expect = [("/cam/points", PC2, 4), (GROUND_TRUTH_TOPIC, GT, 8)];
    if let Some(out) = external_check(&path, &expect, "synth_bag::labelled") {
        assert!(
            out.contains("OK rosbags+mcap: 2 topics, 12 messages decoded"),
            "{out}"
        );
    }
}

#[test]
fn ground_truth_round_trips_mesh_and_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("sep");
    let mut spec = spheres(Layout::SeparateTopics, 3);
    spec.shapes = vec!["torus".into(), "bottle".into()];
    spec.rate_hz = 20.0;
    let summary = write_sequence(&spec, &path, |_| {}).unwrap();
    assert!(summary.mcap_path.starts_with(&path));
    assert!(path.join("metadata.yaml").is_file());
    let bag = Bag::open(&path).unwrap();
    assert_eq!(
        topics(&bag),
        [
            ("/synth/bottle/points".to_string(), PC2.to_string(), 3),
            (GROUND_TRUTH_TOPIC.to_string(), GT.to_string(), 6),
            ("/synth/torus/points".to_string(), PC2.to_string(), 3),
        ]
    );
    let truth = GroundTruthIndex::from_bag(&bag).unwrap();
    // Reference: the same scene built independently of the bag.
    for stream in build_streams(&spec).unwrap() {
        let obj = &stream.scene.objects[0];
        let track = &truth.streams[&stream.topic];
        assert_eq!(track.mesh_id, obj.name);
        assert_eq!(track.mesh.vertices, obj.mesh.vertices);
        assert_eq!(track.mesh.triangles, obj.mesh.triangles);
        let stamps: Vec<i64> = track.frames.keys().copied().collect();
        assert_eq!(
            stamps,
            [START_NS, START_NS + 50_000_000, START_NS + 100_000_000]
        );
        for (k, &t) in stamps.iter().enumerate() {
            let want = obj.motion.pose_at(&obj.start, k);
            let got = track.frames[&t].pose;
            assert!((got.translation.vector - want.translation.vector).norm() < 1e-12);
            assert!(got.rotation.angle_to(&want.rotation) < 1e-9);
            let posed = track.posed_mesh(t).unwrap();
            for (p, v) in posed.vertices.iter().zip(&obj.mesh.vertices) {
                let w = want * nalgebra::Point3::from(*v);
                assert!((p - w.coords).norm() < 1e-12);
            }
        }
    }
    let expect = [
        ("/synth/bottle/points", PC2, 3),
        ("/synth/torus/points", PC2, 3),
        (GROUND_TRUTH_TOPIC, GT, 6),
    ];
    external_check(&path, &expect, "synth_bag::separate");
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let mut spec = spheres(
        Layout::Labelled {
            topic: "/synth/points".into(),
        },
        2,
    );
    spec.noise = Noise::kinect();
    let write = |dir: &str, spec: &SequenceSpec| {
        let d = tmp.path().join(dir);
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("seq.mcap");
        write_sequence(spec, &p, |_| {}).unwrap();
        std::fs::read(p).unwrap()
    };
    let a = write("a", &spec);
    let b = write("b", &spec);
    assert!(a.len() > 10_000);
    assert!(a == b, "same seed gave different bytes");
    spec.seed += 1;
    assert!(write("c", &spec) != a, "another seed gave the same bytes");
}

#[test]
fn committed_synth_fixtures_hold_what_the_script_says() {
    let dir = common::data_dir().join("bags");
    for (file, cloud_topic, streams) in [
        (
            "synth_ellipsoid.mcap",
            "/synth/ellipsoid/points",
            vec!["/synth/ellipsoid/points"],
        ),
        (
            "synth_two_labelled.mcap",
            "/synth/points",
            vec!["/synth/points#1", "/synth/points#2"],
        ),
    ] {
        let path = dir.join(file);
        let bag = Bag::open(&path).unwrap();
        let n_gt = 12 * streams.len() as u64;
        assert_eq!(bag.topic(cloud_topic).unwrap().message_count, 12, "{file}");
        assert_eq!(bag.topic(cloud_topic).unwrap().type_name, PC2);
        assert_eq!(bag.topic(GROUND_TRUTH_TOPIC).unwrap().message_count, n_gt);
        let truth = GroundTruthIndex::from_bag(&bag).unwrap();
        let ids: Vec<&str> = truth.streams.keys().map(|s| s.as_str()).collect();
        assert_eq!(ids, streams, "{file}");
        let mut outliers = 0usize;
        let mut total = 0usize;
        for m in bag.read(&[cloud_topic]).unwrap() {
            let d = decode_pointcloud2_cdr(&m.data, &WireConfig::default()).unwrap();
            let stamp = d.header.stamp.to_nanos();
            let on_objects: u32 = streams
                .iter()
                .map(|s| truth.frame(s, stamp).unwrap().visible_points)
                .sum();
            for s in &streams {
                let n = truth.frame(s, stamp).unwrap().visible_points;
                assert!((800..=4_000).contains(&n), "{file} {s}: {n} points");
            }
            total += d.cloud.len();
            outliers += d.cloud.len() - on_objects as usize;
            if streams.len() > 1 {
                assert!(d.cloud.attribute("r").is_some());
                let labels = d.cloud.attribute("label").unwrap();
                let zeros = labels.iter().filter(|&&l| l == 0.0).count();
                assert_eq!(zeros, d.cloud.len() - on_objects as usize);
            }
        }
        let frac = outliers as f64 / (total - outliers) as f64;
        let want = if streams.len() > 1 { 0.03 } else { 0.01 };
        assert!(
            (frac - want).abs() < 0.002,
            "{file}: outlier fraction {frac}"
        );
        let expect = [(cloud_topic, PC2, 12), (GROUND_TRUTH_TOPIC, GT, n_gt)];
        external_check(&path, &expect, "synth_bag::committed");
    }
}
