//! Sensor-true `sepmem synth`: the clouds written to a bag are what the pixel
//! rays of a pinhole depth camera see of the posed ground-truth meshes.
//! Checked against an independent brute-force ray–triangle intersection
//! (Möller–Trumbore over every triangle, written here): every point lies on
//! its object's true surface along its pixel ray within the axial noise
//! σ(z) = 0.0012 + 0.0019 (z − 0.4)², no point lies behind another object,
//! the density falls as 1/z² with range and as cos θ with incidence, the
//! motions move what the ground truth says, and the ground truth (object
//! pose, camera pose, intrinsics, mesh id) decodes with Python rosbags.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::Command;

use nalgebra::{Isometry3, UnitQuaternion};
use sepmem::bag::Bag;
use sepmem::cloud::Vec3;
use sepmem::mesh::TriMesh;
use sepmem::synth::sequence::{
    build_streams, write_sequence, Layout, SceneMotion, SequenceSpec, GROUND_TRUTH_TOPIC,
};
use sepmem::synth::truth::GroundTruthIndex;
use sepmem::synth::{Camera, CameraPath, Motion, Noise, Renderer, Scene, SceneObject};
use sepmem::wire::pointcloud2::{decode_pointcloud2_cdr, WireConfig};

/// Nearest `t > 0` with `o + t·d` on a triangle of `mesh` (Möller–Trumbore).
fn brute_first_hit(mesh: &TriMesh, o: &Vec3, d: &Vec3) -> Option<f64> {
    let mut best = f64::INFINITY;
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        let (e1, e2) = (b - a, c - a);
        let p = d.cross(&e2);
        let det = e1.dot(&p);
        if det.abs() < 1e-15 {
            continue;
        }
        let s = o - a;
        let u = s.dot(&p) / det;
        let q = s.cross(&e1);
        let v = d.dot(&q) / det;
        let h = e2.dot(&q) / det;
        if u >= -1e-9 && v >= -1e-9 && u + v <= 1.0 + 1e-9 && h > 0.0 && h < best {
            best = h;
        }
    }
    best.is_finite().then_some(best)
}

fn kinect_sigma(z: f64) -> f64 {
    0.0012 + 0.0019 * (z - 0.4) * (z - 0.4)
}

fn no_outliers() -> Noise {
    Noise {
        outlier_fraction: 0.0,
        ..Noise::kinect()
    }
}

fn spec(shapes: &[&str], frames: usize, motion: SceneMotion, layout: Layout) -> SequenceSpec {
    SequenceSpec {
        shapes: shapes.iter().map(|s| s.to_string()).collect(),
        frames,
        intrinsics: Some(Camera::kinect()),
        motion,
        noise: no_outliers(),
        layout,
        mesh_resolution: 48,
        distance: 0.8,
        seed: 3,
        ..SequenceSpec::default()
    }
}

/// A bag's clouds by topic, decoded, with their stamps, and the truth.
struct Written {
    clouds: Vec<(String, i64, sepmem::cloud::PointCloud)>,
    truth: GroundTruthIndex,
}

fn write_and_read(spec: &SequenceSpec, path: &Path) -> Written {
    write_sequence(spec, path, |_| {}).unwrap();
    let bag = Bag::open(path).unwrap();
    let truth = GroundTruthIndex::from_bag(&bag).unwrap();
    let topics: Vec<String> = bag
        .topics
        .iter()
        .filter(|t| t.name != GROUND_TRUTH_TOPIC)
        .map(|t| t.name.clone())
        .collect();
    let refs: Vec<&str> = topics.iter().map(|s| s.as_str()).collect();
    let clouds = bag
        .read(&refs)
        .unwrap()
        .into_iter()
        .map(|m| {
            let d = decode_pointcloud2_cdr(&m.data, &WireConfig::default()).unwrap();
            (m.topic.clone(), d.header.stamp.to_nanos(), d.cloud)
        })
        .collect();
    Written { clouds, truth }
}

/// Normalised depth residuals `(z − z*)/σ(z*)` of every `step`-th point
/// against the first hit of its pixel ray on `mesh` (camera frame).
fn residuals(points: &[Vec3], mesh: &TriMesh, step: usize) -> Vec<f64> {
    points
        .iter()
        .step_by(step)
        .map(|p| {
            let d = p / p.z;
            let z = brute_first_hit(mesh, &Vec3::zeros(), &d)
                .unwrap_or_else(|| panic!("the ray of {p:?} misses the true mesh"));
            (p.z - z) / kinect_sigma(z)
        })
        .collect()
}

#[test]
fn points_lie_on_the_true_posed_mesh_within_the_axial_noise() {
    let tmp = tempfile::tempdir().unwrap();
    let s = spec(
        &["mug"],
        4,
        SceneMotion::Turn { degrees: 180.0 },
        Layout::SeparateTopics,
    );
    let w = write_and_read(&s, &tmp.path().join("mug.mcap"));
    assert_eq!(w.clouds.len(), 4);
    let mut all = Vec::new();
    for (topic, stamp, cloud) in &w.clouds {
        let f = w.truth.frame(topic, *stamp).unwrap();
        assert_eq!(cloud.len(), f.visible_points as usize);
        // The fixed Kinect intrinsics: a 0.2 m mug at 0.8 m covers thousands of pixels.
        assert!((2_000..15_000).contains(&cloud.len()), "{}", cloud.len());
        let mesh = w.truth.posed_mesh(topic, *stamp).unwrap();
        all.extend(residuals(&cloud.points, &mesh, 4));
    }
    let n = all.len() as f64;
    let mean = all.iter().sum::<f64>() / n;
    let sd = (all.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
    let worst = all.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    eprintln!(
        "{} residuals: mean {mean:.3} σ, sd {sd:.3} σ, worst {worst:.2} σ",
        all.len()
    );
    assert!(mean.abs() < 0.1, "bias {mean} σ");
    assert!((sd - 1.0).abs() < 0.08, "spread {sd} σ");
    assert!(worst < 5.5, "a point {worst} σ off its surface");
}

#[test]
fn no_point_lies_behind_another_object_along_its_ray() {
    // The camera orbits two objects standing side by side; a quarter of the
    // way round they line up along the view, and the near one hides the far.
    let tmp = tempfile::tempdir().unwrap();
    let s = spec(
        &["sphere", "rounded_box"],
        5,
        SceneMotion::Orbit { degrees: 180.0 },
        Layout::Labelled {
            topic: "/cam/points".into(),
        },
    );
    let w = write_and_read(&s, &tmp.path().join("two.mcap"));
    let ids = ["/cam/points#1", "/cam/points#2"];
    let mut seen = [[0usize; 5]; 2];
    for (k, (_, stamp, cloud)) in w.clouds.iter().enumerate() {
        let labels = cloud.attribute("label").unwrap();
        let meshes: Vec<TriMesh> = ids
            .iter()
            .map(|id| w.truth.posed_mesh(id, *stamp).unwrap())
            .collect();
        for (o, id) in ids.iter().enumerate() {
            let own: Vec<Vec3> = cloud
                .points
                .iter()
                .zip(labels)
                .filter(|(_, l)| **l == (o + 1) as f32)
                .map(|(p, _)| *p)
                .collect();
            seen[o][k] = own.len();
            assert_eq!(
                own.len(),
                w.truth.frame(id, *stamp).unwrap().visible_points as usize
            );
            // On its own surface ...
            assert!(residuals(&own, &meshes[o], 3).iter().all(|r| r.abs() < 5.5));
            // ... and never behind the other object along its ray.
            let other = &meshes[1 - o];
            for p in own.iter().step_by(2) {
                if let Some(z) = brute_first_hit(other, &Vec3::zeros(), &(p / p.z)) {
                    assert!(
                        z > p.z - 5.0 * kinect_sigma(z),
                        "frame {k} {id}: {p:?} behind {z}"
                    );
                }
            }
        }
    }
    eprintln!("visible points per frame: {seen:?}");
    // At 90° (frame 2) one object is (mostly) hidden behind the other.
    let hidden = (0..2)
        .map(|o| seen[o][2] as f64 / seen[o][0] as f64)
        .fold(1.0, f64::min);
    assert!(hidden < 0.3, "no occlusion at the quarter turn: {seen:?}");
}

/// A square plate of side `s` in its own xy plane, facing −z.
fn plate(s: f64) -> TriMesh {
    let h = s / 2.0;
    TriMesh {
        vertices: vec![
            Vec3::new(-h, -h, 0.0),
            Vec3::new(h, -h, 0.0),
            Vec3::new(h, h, 0.0),
            Vec3::new(-h, h, 0.0),
        ],
        triangles: vec![[0, 2, 1], [0, 3, 2]],
        vertex_scalars: vec![],
    }
}

fn plate_points(z: f64, turn_deg: f64, noise: Noise) -> usize {
    let scene = Scene {
        camera: Camera::kinect(),
        camera_path: CameraPath::Fixed,
        noise,
        objects: vec![SceneObject {
            name: "plate".into(),
            mesh: plate(0.2),
            start: Isometry3::from_parts(
                nalgebra::Translation3::new(0.0, 0.0, z),
                UnitQuaternion::from_scaled_axis(Vec3::new(0.0, turn_deg.to_radians(), 0.0)),
            ),
            motion: Motion::still(),
            label: 1,
            colour: [0.5; 3],
            present: None,
        }],
        colour: false,
        labels: false,
        seed: 1,
    };
    Renderer::new().render(&scene, 0).unwrap().cloud.len()
}

#[test]
fn density_falls_with_range_and_incidence() {
    // A facing plate of side s at depth z covers (f·s/z)² pixels.
    for z in [0.6, 1.2] {
        let n = plate_points(z, 0.0, Noise::none()) as f64;
        let want = (525.0 * 0.2 / z).powi(2);
        assert!((n - want).abs() < 0.02 * want, "z {z}: {n} vs {want}");
    }
    let near = plate_points(0.6, 0.0, Noise::none()) as f64;
    let far = plate_points(1.2, 0.0, Noise::none()) as f64;
    assert!((near / far - 4.0).abs() < 0.1, "{near} / {far}");
    // Turned by 60°, it shows cos 60° = ½ of the pixels (to first order in s/z).
    let tilted = plate_points(1.0, 60.0, Noise::none()) as f64;
    let facing = plate_points(1.0, 0.0, Noise::none()) as f64;
    assert!((tilted / facing - 0.5).abs() < 0.02, "{tilted} / {facing}");
    // Beyond the Kinect's 80° incidence cut-off nothing comes back.
    assert_eq!(plate_points(1.0, 85.0, no_outliers()), 0);
    assert!(plate_points(1.0, 75.0, no_outliers()) > 1_000);
}

/// The world pose of an object at a frame: camera pose · object-in-camera pose.
fn world(id: &str, stamp: i64, truth: &GroundTruthIndex) -> Isometry3<f64> {
    let f = truth.frame(id, stamp).unwrap();
    f.camera_pose * f.pose
}

#[test]
fn motions_move_what_the_ground_truth_says() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = 7;
    let first_last = |truth: &GroundTruthIndex, id: &str| {
        let stamps: Vec<i64> = truth.streams[id].frames.keys().copied().collect();
        (stamps[0], stamps[stamps.len() - 1])
    };
    // Turning: 180° in place, camera still.
    let s = spec(
        &["bottle"],
        frames,
        SceneMotion::Turn { degrees: 180.0 },
        Layout::SeparateTopics,
    );
    let w = write_and_read(&s, &tmp.path().join("turn.mcap"));
    let id = "/synth/bottle/points";
    let (a, b) = first_last(&w.truth, id);
    let (p0, p1) = (world(id, a, &w.truth), world(id, b, &w.truth));
    assert!((p0.rotation.angle_to(&p1.rotation) - std::f64::consts::PI).abs() < 1e-9);
    assert!((p0.translation.vector - p1.translation.vector).norm() < 1e-12);
    assert_eq!(
        w.truth.frame(id, b).unwrap().camera_pose,
        Isometry3::identity()
    );
    // Orbit: the object stays put in the world; the camera goes half way round it.
    let s = spec(
        &["bottle"],
        frames,
        SceneMotion::Orbit { degrees: 180.0 },
        Layout::SeparateTopics,
    );
    let w = write_and_read(&s, &tmp.path().join("orbit.mcap"));
    let (a, b) = first_last(&w.truth, id);
    let (p0, p1) = (world(id, a, &w.truth), world(id, b, &w.truth));
    assert!((p0.translation.vector - p1.translation.vector).norm() < 1e-9);
    assert!(p0.rotation.angle_to(&p1.rotation) < 1e-9);
    let cam = w.truth.frame(id, b).unwrap().camera_pose;
    assert!((cam.rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
    assert!((cam.translation.vector - Vec3::new(0.0, 0.0, 1.6)).norm() < 1e-9);
    // The object seen from behind is the object turned by 180° in camera terms.
    let seen = w.truth.frame(id, b).unwrap().pose;
    assert!((seen.translation.vector - Vec3::new(0.0, 0.0, 0.8)).norm() < 1e-9);
    // Pick and place: rests, rises by ¾ of its size, set down half its size away.
    let s = spec(
        &["bottle"],
        11,
        SceneMotion::PickPlace,
        Layout::SeparateTopics,
    );
    let w = write_and_read(&s, &tmp.path().join("pick.mcap"));
    let track = &w.truth.streams[id];
    let heights: Vec<f64> = track
        .frames
        .keys()
        .map(|&t| -world(id, t, &w.truth).translation.vector.y)
        .collect();
    let top = heights.iter().cloned().fold(f64::MIN, f64::max);
    assert!((top - 0.15).abs() < 1e-9, "{heights:?}");
    assert!(heights[0].abs() < 1e-12 && heights[10].abs() < 1e-12);
    let (a, b) = first_last(&w.truth, id);
    let moved =
        world(id, b, &w.truth).translation.vector - world(id, a, &w.truth).translation.vector;
    assert!((moved - Vec3::new(0.1, 0.0, 0.0)).norm() < 1e-9, "{moved}");
}

#[test]
fn a_swapped_object_changes_the_mesh_id_on_the_same_stream() {
    let tmp = tempfile::tempdir().unwrap();
    let s = spec(
        &["sphere", "torus"],
        6,
        SceneMotion::Swap { degrees: 90.0 },
        Layout::SeparateTopics,
    );
    let streams = build_streams(&s).unwrap();
    assert_eq!(streams.len(), 1);
    let id = "/synth/sphere_then_torus/points";
    assert_eq!(streams[0].topic, id);
    let w = write_and_read(&s, &tmp.path().join("swap.mcap"));
    let track = &w.truth.streams[id];
    let ids: Vec<&str> = track
        .frames
        .keys()
        .map(|&t| track.mesh_at(t).unwrap().0)
        .collect();
    assert_eq!(
        ids,
        ["sphere", "sphere", "sphere", "torus", "torus", "torus"]
    );
    // The torus's points lie on the torus: the cloud changes object with the truth.
    for (topic, stamp, cloud) in &w.clouds {
        let mesh = w.truth.posed_mesh(topic, *stamp).unwrap();
        assert!(residuals(&cloud.points, &mesh, 5)
            .iter()
            .all(|r| r.abs() < 5.5));
    }
    ground_truth_with_rosbags(&tmp.path().join("swap.mcap"), &s, &w.truth);
}

/// The GroundTruth messages as decoded by Python rosbags, or `None` after a
/// visible SKIPPED line when the tools are missing.
fn rosbags_truth(bag: &Path) -> Option<Vec<serde_json::Value>> {
    if !common::python_tools() {
        eprintln!("SKIPPED synth_sensor (rosbags check): python3 with rosbags not available");
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/ground_truth.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(bag)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    Some(
        text.lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect(),
    )
}

fn pose_of(v: &serde_json::Value) -> Isometry3<f64> {
    let c: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    Isometry3::from_parts(
        nalgebra::Translation3::new(c[0], c[1], c[2]),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(c[6], c[3], c[4], c[5])),
    )
}

/// Every message rosbags decodes agrees with the scene built independently
/// of the bag (poses from the motions, intrinsics, mesh ids and meshes).
fn ground_truth_with_rosbags(bag: &Path, spec: &SequenceSpec, truth: &GroundTruthIndex) {
    let Some(msgs) = rosbags_truth(bag) else {
        return;
    };
    let n_truth: usize = truth.streams.values().map(|t| t.frames.len()).sum();
    assert_eq!(msgs.len(), n_truth);
    let streams = build_streams(spec).unwrap();
    let mut sent = std::collections::BTreeSet::new();
    for m in &msgs {
        let stream = streams.iter().find(|s| s.topic == m["stream_id"]).unwrap();
        let k = ((m["stamp"].as_i64().unwrap() - sepmem::synth::sequence::START_NS) / 100_000_000)
            as usize;
        let obj = stream
            .scene
            .objects
            .iter()
            .find(|o| o.name == m["mesh_id"])
            .unwrap();
        assert!(obj.present_at(k));
        let cam = stream.scene.camera_path.pose_at(k);
        let want = cam.inverse() * obj.motion.pose_at(&obj.start, k);
        let got = pose_of(&m["pose"]);
        assert!((got.translation.vector - want.translation.vector).norm() < 1e-12);
        assert!(got.rotation.angle_to(&want.rotation) < 1e-9);
        assert!(pose_of(&m["camera_pose"]).rotation.angle_to(&cam.rotation) < 1e-9);
        assert_eq!(m["world_frame_id"], "world");
        assert_eq!(m["frame_id"], "camera_depth_optical_frame");
        let intr: Vec<f64> = m["intrinsics"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(intr, [640.0, 480.0, 525.0, 525.0, 320.0, 240.0]);
        let first = sent.insert(obj.name.clone());
        let want_v = if first { obj.mesh.vertices.len() } else { 0 };
        assert_eq!(m["vertices"].as_u64().unwrap() as usize, want_v, "{m}");
    }
}

#[test]
fn ground_truth_of_an_orbit_decodes_with_rosbags() {
    let tmp = tempfile::tempdir().unwrap();
    let s = spec(
        &["ellipsoid"],
        4,
        SceneMotion::Orbit { degrees: 360.0 },
        Layout::SeparateTopics,
    );
    let path = tmp.path().join("orbit");
    let w = write_and_read(&s, &path);
    ground_truth_with_rosbags(&path, &s, &w.truth);
}

#[test]
fn synth_cli_takes_intrinsics_motions_and_rejects_bad_ones() {
    let tmp = tempfile::tempdir().unwrap();
    let bin = env!("CARGO_BIN_EXE_sepmem");
    let run = |args: &[&str]| Command::new(bin).arg("synth").args(args).output().unwrap();
    let out = tmp.path().join("a.mcap");
    let o = out.to_str().unwrap();
    let ok = run(&[
        "-o",
        o,
        "--shapes",
        "mug",
        "--frames",
        "3",
        "--motion",
        "turn",
        "--degrees",
        "360",
        "--width",
        "320",
        "--height",
        "240",
        "--focal",
        "262.5",
        "--flying-pixels",
        "0.5",
        "--quiet",
    ]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let bag = Bag::open(&out).unwrap();
    let truth = GroundTruthIndex::from_bag(&bag).unwrap();
    let f = truth.streams["/synth/mug/points"]
        .frames
        .values()
        .next()
        .unwrap();
    assert_eq!(
        (f.camera.width, f.camera.height, f.camera.fx),
        (320, 240, 262.5)
    );
    for (args, needle) in [
        (
            vec!["--points", "100", "--focal", "500"],
            "cannot be used with",
        ),
        (
            vec!["--motion", "spin"],
            "expected drift, turn, orbit, pick or swap",
        ),
        (vec!["--motion", "turn", "--degrees", "400"], "0–360"),
        (vec!["--motion", "swap"], "swap needs two or more shapes"),
        (vec!["--flying-pixels", "1.5"], "flying-pixel probability"),
        (vec!["--focal=-1"], "camera.fx/fy"),
    ] {
        let mut a = vec!["-o", o, "--frames", "2"];
        a.extend(args.iter());
        let bad = run(&a);
        let err = String::from_utf8_lossy(&bad.stderr);
        assert!(
            !bad.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn committed_turning_mug_is_what_the_script_says() {
    let path = common::data_dir().join("bags/synth_turn_mug.mcap");
    let bag = Bag::open(&path).unwrap();
    let id = "/synth/mug/points";
    assert_eq!(bag.topic(id).unwrap().message_count, 30);
    let truth = GroundTruthIndex::from_bag(&bag).unwrap();
    let track = &truth.streams[id];
    assert_eq!(track.frames.len(), 30);
    let (first, last) = (
        track.frames.values().next().unwrap(),
        track.frames.values().last().unwrap(),
    );
    assert_eq!(first.camera, Camera::kinect());
    assert!(
        (first.pose.rotation.angle_to(&last.pose.rotation) - std::f64::consts::PI).abs() < 1e-9
    );
    for (k, m) in bag.read(&[id]).unwrap().into_iter().enumerate().step_by(10) {
        let d = decode_pointcloud2_cdr(&m.data, &WireConfig::default()).unwrap();
        let stamp = d.header.stamp.to_nanos();
        assert_eq!(
            d.cloud.len(),
            truth.frame(id, stamp).unwrap().visible_points as usize
        );
        let mesh = truth.posed_mesh(id, stamp).unwrap();
        let r = residuals(&d.cloud.points, &mesh, 7);
        assert!(r.iter().all(|r| r.abs() < 5.5), "frame {k}");
    }
}
