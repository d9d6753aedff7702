//! `pipeline.model` (issue 20, deliver 3): with the fused model on, a warm
//! frame's membrane is evolved on what the earlier views saw too. Views of
//! a still sphere from one camera: the first two show a vertical strip of
//! its front cap (a voxel one earlier frame alone saw counts only once
//! confirmed, `pipeline.model.confirm`), the third a horizontal one (all
//! centred, so the centroid shift is nil; ICP is off, since a sphere cap
//! slides along itself and its motion is ambiguous: this isolates the
//! fusion from the registration). The third frame's mesh is measured
//! against the first view's points far from the second strip: with the
//! model they lie on it, without it they are farther off.
#![allow(clippy::unwrap_used)]

mod common;

use sepmem::cloud::{PointCloud, Vec3};
use sepmem::config::Config;
use sepmem::pipeline::{Membranes, StartPath, StreamKey, Tracker};
use sepmem::spatial::PointIndex;

const R: f64 = 0.1;

/// Fibonacci-lattice points of the sphere's camera-facing cap (camera at
/// the origin, sphere at z = 0.8) for which `keep(x, y)` holds.
fn cap(keep: impl Fn(f64, f64) -> bool) -> Vec<Vec3> {
    let c = Vec3::new(0.0, 0.0, 0.8);
    // The lattice with its pole axis along y.
    sepmem::shapes::fibonacci_sphere(12_000)
        .into_iter()
        .map(|u| Vec3::new(u.x, u.z, u.y))
        .filter(|d| d.z < -0.3)
        .map(|d| c + d * R)
        .filter(|p| keep(p.x, p.y))
        .collect()
}

/// Mean distance of `points` to the nearest vertex of the last frame's
/// mesh, after two frames of `first` and one of `second`.
fn second_mesh_distance(model: bool, first: &[Vec3], second: &[Vec3], probe: &[Vec3]) -> f64 {
    let mut cfg = Config::load(None, &[]).unwrap();
    cfg.pipeline.model = model.then(|| serde_json::from_str("{}").unwrap());
    cfg.pipeline.deadline_ms = 0.0;
    cfg.pipeline.icp_steps = 0;
    // A strip across the previous one separates poorly from the previous
    // surface; keep the warm frame (a cold restart restarts the model).
    cfg.pipeline.warm_eta_ratio = 0.0;
    // Nor is the second strip near the first one's surface: the track is
    // not lost, the view moved across the still sphere.
    cfg.pipeline.icp_min_inliers = None;
    let membranes = Membranes::new(&cfg.membrane, &cfg.pipeline).unwrap();
    let mut t = Tracker::new(StreamKey::topic("/fused"));
    let frames = [
        (first, StartPath::Cold),
        (first, StartPath::Warm),
        (second, StartPath::Warm),
    ];
    let mut last = None;
    for (points, path) in frames {
        let cloud = PointCloud::from_points(points.to_vec());
        let r = t.process(&cloud, &membranes, &cfg.pipeline).unwrap();
        assert_eq!(r.path, path, "{:?}", r.reason);
        last = Some(r);
    }
    let b = last.unwrap();
    let index = PointIndex::new(&b.reconstruction.mesh.vertices);
    probe.iter().map(|p| index.nearest(p).0).sum::<f64>() / probe.len() as f64
}

#[test]
fn a_warm_frame_with_the_model_keeps_what_an_earlier_view_saw() {
    let first = cap(|x, _| x.abs() < 0.03);
    let second = cap(|_, y| y.abs() < 0.03);
    // The first view's points far from the second strip.
    let probe: Vec<Vec3> = first.iter().copied().filter(|p| p.y.abs() > 0.05).collect();
    assert!(probe.len() > 100 && second.len() > 1000);
    let off = second_mesh_distance(false, &first, &second, &probe);
    let on = second_mesh_distance(true, &first, &second, &probe);
    println!("mean distance of the first view's far points to the second mesh: off {off:.4} m, on {on:.4} m");
    // Measured with the first strip held two frames (the voxels' confirmation):
    // off 4.4 mm, on 2.6 mm. Before it, one frame of each: off 4.3 mm, on 3.0 mm (model voxel 0.02 of the size;
    // 3.3 and 2.7 mm at 0.008); with the carving (the fused cloud keeps
    // the median spacing for δ) on 3.3 mm (the nearest vertex, whose
    // spacing sets a floor near 2.5 mm; the warm start itself keeps much
    // of the first strip's surface). Without the fusion both runs are the
    // same.
    assert!(on < 0.0036, "with the model: {on}");
    assert!(on < 0.9 * off, "on {on} off {off}");
}

/// With `pipeline.model` set, each frame's messages carry one labelled
/// PointCloud2 of every object's fused model in the input's frame (what the
/// node publishes on `{topic}/model` and `replay` writes to its bag): on
/// the real mOSD tabletop bag, every evolved object's label is in it, and
/// its points lie on that object's scan. Without the model there is none.
#[test]
fn the_frame_messages_carry_every_objects_fused_model_on_its_scan() {
    use sepmem::bag::Bag;
    use sepmem::pipeline::engine::Engine;
    use sepmem::wire::msgs::PointCloud2;
    use sepmem::wire::pointcloud2::{decode_pointcloud2, WireConfig};
    let bag = Bag::open(&common::data_dir().join("bags/mosd_rosbags")).unwrap();
    let messages = bag.read(&[]).unwrap();
    for model in [false, true] {
        let mut cfg = Config::load(None, &["pipeline.deadline_ms=0".into()]).unwrap();
        cfg.pipeline.model = model.then(|| serde_json::from_str("{}").unwrap());
        let label = cfg.pipeline.label_channel.clone();
        let mut engine =
            Engine::new(&cfg.membrane, cfg.pipeline.clone(), cfg.wire.clone()).unwrap();
        let (mut clouds, mut worst) = (0, 0.0f64);
        for m in messages.iter().take(6) {
            let now = i64::try_from(m.log_time).unwrap();
            let frame = engine.handle(&m.topic, &m.data, None, now).unwrap();
            let msgs = frame.messages("sepmem", &label);
            let Some(msg) = msgs.model else {
                assert!(!model, "{}: no model cloud with pipeline.model", m.topic);
                continue;
            };
            assert!(model, "a model cloud without pipeline.model");
            clouds += 1;
            let msg: PointCloud2 = msg;
            let cloud = decode_pointcloud2(&msg, &WireConfig::default())
                .unwrap()
                .cloud;
            let labels = cloud.attribute(&label).unwrap();
            for s in &frame.sample.streams {
                let l = s.key.label.unwrap() as f32;
                let mine: Vec<Vec3> = cloud
                    .points
                    .iter()
                    .zip(labels)
                    .filter(|(_, v)| **v == l)
                    .map(|(p, _)| *p)
                    .collect();
                assert!(mine.len() > 20, "{}: {} model points", s.key, mine.len());
                // Median distance of the model's points to the object's scan.
                let index = PointIndex::new(&s.cloud.points);
                let mut d: Vec<f64> = mine.iter().map(|p| index.nearest(p).0).collect();
                d.sort_by(f64::total_cmp);
                worst = worst.max(d[d.len() / 2]);
            }
        }
        println!(
            "model {model}: {clouds} model clouds, worst median distance to the scan {worst:.4} m"
        );
        if model {
            assert_eq!(clouds, 6);
            // One point per 8 mm voxel (the running mean of its points).
            assert!(worst < 0.008, "median distance {worst}");
        }
    }
}

/// The live node publishes the fused models on `{topic}/model` over real
/// zenoh sessions on loopback: one labelled PointCloud2 per frame, with
/// every object's label; the first frame's (every model fresh from its
/// view, before any motion is estimated) byte for byte what the in-process
/// engine makes of the same sample.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_node_publishes_the_fused_models_on_the_model_topic() {
    use sepmem::bag::Bag;
    use sepmem::node::loopback::{inbox_lock, LoopbackNode};
    use sepmem::pipeline::engine::Engine;
    use sepmem::transport::liveliness::Qos;
    use sepmem::transport::RosType;
    use sepmem::wire::msgs::PointCloud2;
    use sepmem::wire::pointcloud2::{decode_pointcloud2, WireConfig};
    use sepmem::wire::{decode, encode, RosMessage};
    use std::time::Duration;
    let bag = Bag::open(&common::data_dir().join("bags/mosd_rosbags")).unwrap();
    let messages: Vec<_> = bag.read(&[]).unwrap().into_iter().take(3).collect();
    let mut cfg = Config::load(
        None,
        &[
            "pipeline.deadline_ms=0".into(),
            // Lock step on a loaded machine: never evicted as silent between
            // two frames (CI once stalled for a minute there).
            "node.evict_after_ms=3600000".into(),
            // Lock step on a loaded machine: the node (receipt time) must not
            // forget an object the engine (log time) still tracks.
            "pipeline.objects.forget_after_ms=600000".into(),
            "node.outputs_keep_all=true".into(),
            "node.transport.node_name=\"sepmem_model_test\"".into(),
        ],
    )
    .unwrap();
    cfg.pipeline.model = Some(serde_json::from_str("{}").unwrap());
    let mut node_cfg = cfg.node.clone();
    // A pattern that also matches the node's own `{topic}/model` clouds
    // (PointCloud2 like the input): they must not become input streams.
    node_cfg.topics = vec![format!("{}/**", messages[0].topic)];
    let ty = RosType::new(PointCloud2::TYPE_NAME, PointCloud2::TYPE_HASH);
    let backend = std::sync::Arc::new(cfg.pipeline_backend().unwrap());
    let node = LoopbackNode::start(&node_cfg, backend).await.unwrap();
    let model_topic = format!("{}/model", messages[0].topic);
    let (_sub, models) = node.collect(&model_topic, &ty).await.unwrap();
    assert!(
        node.wait_ready(Duration::from_secs(30)).await,
        "node not up"
    );
    let input = node
        .harness
        .publisher(&messages[0].topic, &ty, Qos::DEFAULT_10);
    let input = input.await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let label = cfg.pipeline.label_channel.clone();
    let mut engine = Engine::new(&cfg.membrane, cfg.pipeline.clone(), cfg.wire.clone()).unwrap();
    for (k, m) in messages.iter().enumerate() {
        let now = i64::try_from(m.log_time).unwrap();
        let frame = engine.handle(&m.topic, &m.data, None, now).unwrap();
        let want = frame.messages("sepmem", &label).model.unwrap();
        input.put(m.data.clone()).await.unwrap();
        for _ in 0..2400 {
            if inbox_lock(&models).len() > k {
                break;
            }
            tokio::time::sleep(Duration::from_millis(25)).await;
        }
        let got = inbox_lock(&models).get(k).map(|r| r.payload.clone());
        let got = got.unwrap_or_else(|| panic!("no model cloud for frame {k}"));
        if k == 0 {
            assert_eq!(
                got,
                encode(&want).unwrap(),
                "frame 0: the engine's model cloud"
            );
        }
        let cloud = decode_pointcloud2(
            &decode::<PointCloud2>(&got).unwrap(),
            &WireConfig::default(),
        )
        .unwrap()
        .cloud;
        let mut labels: Vec<i64> = cloud
            .attribute(&label)
            .unwrap()
            .iter()
            .map(|v| *v as i64)
            .collect();
        labels.dedup();
        let mut expected: Vec<i64> = frame
            .sample
            .streams
            .iter()
            .filter_map(|s| s.key.label)
            .collect();
        expected.sort_unstable();
        labels.sort_unstable();
        labels.dedup();
        assert_eq!(labels, expected, "frame {k}: the objects' labels");
    }
    input.undeclare().await.unwrap();
    let summary = node.stop().await.unwrap();
    let streams: Vec<&str> = summary.streams.iter().map(|s| s.topic.as_str()).collect();
    assert_eq!(streams, [messages[0].topic.as_str()], "input streams");
    assert!(
        summary.own_outputs >= 1,
        "the node's own model clouds were seen and ignored: {summary:?}"
    );
}
