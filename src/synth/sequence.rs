//! Recorded synthetic sequences: scenes built from shape names or mesh
//! files, rendered frame by frame by the depth camera of [`crate::synth`]
//! and written as a rosbag2 MCAP bag (what `sepmem synth` does).
//!
//! Each object is scaled to a tabletop size, placed in front of the camera
//! and moved over the frames by one of the [`SceneMotion`]s: a smooth drift
//! (sinusoidal wobble and a steady rotation about a tilted axis), a turn in
//! place by up to 360°, a pick and place, the camera orbiting the static
//! objects, or objects swapped one for the next on one stream. The camera
//! has fixed intrinsics (default 640×480, f = 525) or, for the legacy point
//! budget, the focal length that gives about that many points at frame 0.
//! Objects are recorded either on one topic each (`/synth/<name>/points`,
//! each object rendered as its own segmented stream) or together in one
//! cloud on one topic, as segments told apart by the `label` field (labels
//! 1, 2, …; outliers carry label 0). The ground truth of every object in
//! every frame goes to [`GROUND_TRUTH_TOPIC`] as a
//! `sepmem_msgs/msg/GroundTruth` whose `stream_id` is the
//! [`crate::stream::StreamKey`] of the stream the object lands
//! in (`topic` or `topic#label`) and whose stamp equals the cloud's. It
//! carries the object pose in the camera frame, the camera pose in the world
//! frame, the camera intrinsics and the mesh id; the mesh itself (in the
//! object frame) is sent with the first message of each mesh id on a
//! stream, so that every replayed frame can be scored against the full,
//! closed surface even though the camera sees one side only (paper §III:
//! the membrane wraps the measured points 𝒫 and must close the unseen side).
//! Read the truth back with [`crate::synth::truth`].

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use thiserror::Error;

use super::motion::UP;
use super::{
    centred_scaled, focal_for_points, Camera, CameraPath, Drift, Motion, Noise, Renderer, Scene,
    SceneObject, SynthError,
};
use crate::bag::{BagError, BagWriter, Qos};
use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use crate::stream::StreamKey;
use crate::wire::msgs::{
    GroundTruth, Header, MeshTriangle, Point, PointCloud2, Pose, Quaternion, Time,
};
use crate::wire::pointcloud2::encode_pointcloud2;
use crate::wire::RosMessage;

/// Topic of the ground-truth side channel.
pub const GROUND_TRUTH_TOPIC: &str = "/synth/ground_truth";

/// Stamp of frame 0 (ns since the epoch); fixed so that bags are reproducible.
pub const START_NS: i64 = 1_700_000_000_000_000_000;

/// Errors of sequence building and writing.
#[derive(Debug, Error)]
pub enum SequenceError {
    /// A parameter of the sequence is out of range.
    #[error("synth sequence parameter `{name}` is invalid: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// A noise specification is neither `kinect`, `none` nor a σ in metres.
    #[error("noise `{0}`: expected `kinect`, `none` or a non-negative σ in metres")]
    BadNoise(String),
    /// A shape is neither a procedural shape nor a readable mesh file.
    #[error("shape `{name}`: {reason}")]
    BadShape {
        /// The shape name or path as given.
        name: String,
        /// What went wrong.
        reason: String,
    },
    /// The sensor simulation rejected the scene.
    #[error("rendering: {0}")]
    Render(#[from] SynthError),
    /// Writing the bag failed.
    #[error("writing bag {path}: {source}")]
    Bag {
        /// The bag path.
        path: PathBuf,
        /// Cause.
        source: BagError,
    },
}

/// How objects are distributed over topics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Layout {
    /// One topic per object, `/synth/<name>/points`.
    SeparateTopics,
    /// All objects in one cloud on this topic, with a `label` field.
    Labelled {
        /// The topic.
        topic: String,
    },
}

/// How the objects (or the camera) move over a sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SceneMotion {
    /// Smooth drift, wobble and spin about a tilted axis (the legacy motion).
    Drift,
    /// Every object turns in place about the vertical by `degrees` over the sequence.
    Turn {
        /// Total angle, 0–360°.
        degrees: f64,
    },
    /// The objects stand still; the camera orbits their centre about the
    /// vertical by `degrees` over the sequence.
    Orbit {
        /// Total angle, 0–360°.
        degrees: f64,
    },
    /// Every object is picked up, carried sideways and set down again.
    PickPlace,
    /// The objects appear one after another on one stream (one label), each
    /// for an equal share of the frames, turning by `degrees` over the sequence.
    Swap {
        /// Total angle, 0–360°.
        degrees: f64,
    },
}

impl SceneMotion {
    /// Parse `drift`, `turn`, `orbit`, `pick` or `swap`, with `degrees` for
    /// the turning motions.
    ///
    /// # Errors
    /// [`SequenceError::InvalidParameter`] for another name.
    pub fn parse(name: &str, degrees: f64) -> Result<Self, SequenceError> {
        match name {
            "drift" => Ok(Self::Drift),
            "turn" => Ok(Self::Turn { degrees }),
            "orbit" => Ok(Self::Orbit { degrees }),
            "pick" => Ok(Self::PickPlace),
            "swap" => Ok(Self::Swap { degrees }),
            other => Err(SequenceError::InvalidParameter {
                name: "motion",
                reason: format!("`{other}`: expected drift, turn, orbit, pick or swap"),
            }),
        }
    }

    fn degrees(&self) -> Option<f64> {
        match self {
            Self::Turn { degrees } | Self::Orbit { degrees } | Self::Swap { degrees } => {
                Some(*degrees)
            }
            Self::Drift | Self::PickPlace => None,
        }
    }
}

/// Everything that defines a synthetic sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceSpec {
    /// Procedural shape names ([`crate::shapes::procedural_names`]) or mesh file paths.
    pub shapes: Vec<String>,
    /// Number of frames.
    pub frames: usize,
    /// Approximate number of visible points per object and frame, reached
    /// by choosing the focal length (Kinect field of view); used only when
    /// `intrinsics` is `None`.
    pub points_per_object: usize,
    /// Fixed camera intrinsics (e.g. [`Camera::kinect`]) instead of the point budget.
    pub intrinsics: Option<Camera>,
    /// How the objects or the camera move.
    pub motion: SceneMotion,
    /// Frame rate (Hz): stamps are `START_NS + k / rate`.
    pub rate_hz: f64,
    /// Depth noise and outliers.
    pub noise: Noise,
    /// Add `rgb` colour.
    pub colour: bool,
    /// Topic layout.
    pub layout: Layout,
    /// Seed of the noise streams.
    pub seed: u64,
    /// Longest bounding-box edge of every object (m).
    pub object_size: f64,
    /// Distance of the objects from the camera (m).
    pub distance: f64,
    /// Tessellation resolution of the procedural shapes.
    pub mesh_resolution: usize,
    /// `header.frame_id` of clouds and ground truth (the camera's optical frame).
    pub frame_id: String,
    /// The fixed frame in which the ground truth gives the camera pose.
    pub world_frame_id: String,
}

impl Default for SequenceSpec {
    fn default() -> Self {
        Self {
            shapes: vec!["ellipsoid".into()],
            frames: 30,
            points_per_object: 20_000,
            intrinsics: None,
            motion: SceneMotion::Drift,
            rate_hz: 10.0,
            noise: Noise::kinect(),
            colour: false,
            layout: Layout::SeparateTopics,
            seed: 1,
            object_size: 0.2,
            distance: 1.0,
            mesh_resolution: 48,
            frame_id: "camera_depth_optical_frame".into(),
            world_frame_id: "world".into(),
        }
    }
}

/// Parse a noise specification: `kinect` ([`Noise::kinect`]), `none`
/// ([`Noise::none`]) or a constant axial σ in metres (no outliers,
/// Kinect's 80° incidence cut-off).
///
/// # Errors
/// [`SequenceError::BadNoise`] for anything else.
pub fn parse_noise(spec: &str) -> Result<Noise, SequenceError> {
    match spec {
        "kinect" => Ok(Noise::kinect()),
        "none" => Ok(Noise::none()),
        s => match s.parse::<f64>() {
            Ok(sigma) if sigma >= 0.0 && sigma.is_finite() => Ok(Noise {
                sigma_const: sigma,
                sigma_quadratic: 0.0,
                outlier_fraction: 0.0,
                ..Noise::kinect()
            }),
            _ => Err(SequenceError::BadNoise(s.to_string())),
        },
    }
}

/// One recorded stream: the topic it is published on and the scene that
/// renders it.
#[derive(Debug, Clone, PartialEq)]
pub struct Stream {
    /// Topic of its clouds.
    pub topic: String,
    /// Whether its clouds carry a `label` field (one stream key per label).
    pub labelled: bool,
    /// The scene (camera focal chosen for the point budget).
    pub scene: Scene,
}

impl Stream {
    /// The stream id (`StreamKey` display string) of the object with `label`.
    pub fn stream_id(&self, label: u32) -> String {
        StreamKey {
            topic: self.topic.clone(),
            label: self.labelled.then_some(i64::from(label)),
        }
        .to_string()
    }
}

/// Base colours given to objects in order.
const PALETTE: [[f32; 3]; 6] = [
    [0.85, 0.25, 0.15],
    [0.15, 0.55, 0.85],
    [0.25, 0.75, 0.25],
    [0.9, 0.75, 0.2],
    [0.6, 0.3, 0.8],
    [0.9, 0.5, 0.6],
];

/// A topic-safe name (`[A-Za-z0-9_]`, starting with a letter) for a shape
/// name or mesh path.
fn object_name(shape: &str) -> String {
    let stem = Path::new(shape)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(shape);
    let mut n: String = stem
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !n.starts_with(|c: char| c.is_ascii_alphabetic()) {
        n.insert(0, 'o');
    }
    n
}

/// The mesh of `shape`: a procedural shape by name, else a mesh file.
fn shape_mesh(shape: &str, res: usize) -> Result<TriMesh, SequenceError> {
    let bad = |reason: String| SequenceError::BadShape {
        name: shape.to_string(),
        reason,
    };
    if crate::shapes::procedural_names().any(|n| n == shape) {
        return crate::shapes::by_name(shape, res)
            .map(|s| s.mesh)
            .map_err(|e| bad(e.to_string()));
    }
    if !Path::new(shape).is_file() {
        return Err(bad(format!(
            "neither a procedural shape ({}) nor a mesh file",
            crate::shapes::procedural_names()
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    let loaded = crate::io::load_mesh(shape).map_err(|e| bad(e.to_string()))?;
    if loaded.mesh.triangles.is_empty() {
        return Err(bad("the mesh has no triangles".into()));
    }
    Ok(loaded.mesh)
}

/// Check the ranges of `spec`'s scalar parameters.
fn validate(spec: &SequenceSpec) -> Result<(), SequenceError> {
    let invalid = |name, reason: &str| {
        Err(SequenceError::InvalidParameter {
            name,
            reason: reason.to_string(),
        })
    };
    if spec.shapes.is_empty() {
        return invalid("shapes", "at least one shape is needed");
    }
    if spec.shapes.len() > 64 {
        return invalid("shapes", "at most 64 objects");
    }
    if spec.frames == 0 {
        return invalid("frames", "must be at least 1");
    }
    if spec.points_per_object == 0 || spec.points_per_object > 2_000_000 {
        return invalid("points", "must be in 1..=2000000");
    }
    if !(spec.rate_hz > 0.0 && spec.rate_hz.is_finite() && spec.rate_hz <= 1e6) {
        return invalid("rate", "must be positive and finite (≤ 1 MHz)");
    }
    if !(spec.object_size > 0.0 && spec.object_size.is_finite()) {
        return invalid("object_size", "must be positive and finite");
    }
    if !(spec.distance > 2.0 * spec.object_size && spec.distance.is_finite()) {
        return invalid("distance", "must exceed twice the object size");
    }
    if spec
        .motion
        .degrees()
        .is_some_and(|d| !(0.0..=360.0).contains(&d))
    {
        return invalid("degrees", "the total turn must be within 0–360°");
    }
    if let SceneMotion::Swap { .. } = spec.motion {
        if spec.shapes.len() < 2 || spec.frames < spec.shapes.len() {
            return invalid(
                "motion",
                "swap needs two or more shapes and a frame for each",
            );
        }
    }
    if let Some(cam) = &spec.intrinsics {
        cam.validate()?;
    }
    Ok(())
}

/// The motion of the `i`-th object (`sign` alternates between objects).
fn object_motion(spec: &SequenceSpec, i: usize, sign: f64) -> Motion {
    let size = spec.object_size;
    match spec.motion {
        SceneMotion::Drift => {
            // Total drift over the sequence is bounded so that objects stay in view.
            let step = (0.02 * size).min(0.5 * size / spec.frames as f64);
            Motion::Drift(Drift {
                velocity: Vec3::new(-sign * step, 0.4 * step, 0.6 * step),
                angular_velocity: Vec3::new(0.3 * sign, 1.0, 0.2).normalize() * 0.06 * sign,
                wobble: Vec3::new(0.05, 0.08, 0.1) * size,
                wobble_period: 24.0 + 6.0 * i as f64,
            })
        }
        SceneMotion::Turn { degrees } | SceneMotion::Swap { degrees } => {
            Motion::turn(sign * degrees.to_radians(), spec.frames)
        }
        SceneMotion::Orbit { .. } => Motion::Still,
        SceneMotion::PickPlace => Motion::PickPlace {
            frames: spec.frames,
            lift: UP * (0.75 * size),
            shift: Vec3::new(sign * 0.5 * size, 0.0, 0.0),
            tilt: Vec3::new(0.0, 0.0, 0.35 * sign),
        },
    }
}

/// A unique object name per shape, in order (`sphere`, `sphere_2`, …).
fn unique_names(shapes: &[String]) -> Vec<String> {
    let mut used: BTreeMap<String, usize> = BTreeMap::new();
    shapes
        .iter()
        .map(|shape| {
            let base = object_name(shape);
            let count = used.entry(base.clone()).or_insert(0);
            *count += 1;
            if *count == 1 {
                base
            } else {
                format!("{base}_{count}")
            }
        })
        .collect()
}

/// The scene objects of `spec`, in order: named uniquely, labelled 1, 2, …
/// (all 1 when swapped), placed side by side at `spec.distance` (all at the
/// centre when swapped) and moved as `spec.motion` says.
///
/// # Errors
/// [`SequenceError`] for bad parameters or unusable shapes.
pub fn build_objects(spec: &SequenceSpec) -> Result<Vec<SceneObject>, SequenceError> {
    validate(spec)?;
    let n = spec.shapes.len();
    let swap = matches!(spec.motion, SceneMotion::Swap { .. });
    let spacing = 1.5 * spec.object_size;
    let mut objects = Vec::with_capacity(n);
    for (i, (shape, name)) in spec
        .shapes
        .iter()
        .zip(unique_names(&spec.shapes))
        .enumerate()
    {
        let mesh = centred_scaled(&shape_mesh(shape, spec.mesh_resolution)?, spec.object_size)?;
        let x = if swap {
            0.0
        } else {
            (i as f64 - (n as f64 - 1.0) / 2.0) * spacing
        };
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        let tilt = UnitQuaternion::from_scaled_axis(Vec3::new(0.3, 0.2 * sign, 0.1));
        objects.push(SceneObject {
            name,
            mesh,
            start: Isometry3::from_parts(Translation3::new(x, 0.0, spec.distance), tilt),
            motion: object_motion(spec, i, sign),
            label: if swap { 1 } else { i as u32 + 1 },
            colour: PALETTE[i % PALETTE.len()],
            present: swap.then(|| i * spec.frames / n..(i + 1) * spec.frames / n),
        });
    }
    Ok(objects)
}

/// A scene of `objects` with the camera of `spec`: its fixed intrinsics, or
/// the focal length chosen so that the scene shows about `target` points at
/// frame 0, keeping the Kinect field of view.
fn scene_for(
    objects: Vec<SceneObject>,
    spec: &SequenceSpec,
    labels: bool,
    seed: u64,
    target: usize,
) -> Result<Scene, SequenceError> {
    let camera_path = match spec.motion {
        SceneMotion::Orbit { degrees } => CameraPath::orbit(
            Vec3::new(0.0, 0.0, spec.distance),
            degrees.to_radians(),
            spec.frames,
        ),
        _ => CameraPath::Fixed,
    };
    let mut scene = Scene {
        camera: spec.intrinsics.unwrap_or_else(Camera::kinect),
        camera_path,
        noise: spec.noise,
        objects,
        colour: spec.colour,
        labels,
        seed,
    };
    if spec.intrinsics.is_some() {
        return Ok(scene);
    }
    let mut f = focal_for_points(&scene, target)?;
    // `focal_for_points` probes without the incidence cut-off; one more
    // probe with it (still noise-free) corrects for the grazing pixels lost.
    let mut probe = scene.clone();
    probe.noise = Noise {
        sigma_const: 0.0,
        sigma_quadratic: 0.0,
        outlier_fraction: 0.0,
        flying: None,
        ..spec.noise
    };
    probe.camera = kinect_fov(f)?;
    let seen = Renderer::new().render(&probe, 0)?.truth;
    let n: usize = seen.iter().map(|t| t.visible_points).sum();
    if n > 0 {
        f *= (target as f64 / n as f64).sqrt();
    }
    scene.camera = kinect_fov(f)?;
    Ok(scene)
}

/// A camera of focal `f` with the Kinect's field of view.
fn kinect_fov(f: f64) -> Result<Camera, SequenceError> {
    let base = Camera::kinect();
    let s = f / base.fx;
    let (w, h) = (
        (base.width as f64 * s).ceil() as usize,
        (base.height as f64 * s).ceil() as usize,
    );
    if w.saturating_mul(h) > 16 << 20 {
        return Err(SequenceError::InvalidParameter {
            name: "points",
            reason: format!("needs a {w}×{h} image; lower the point count or the distance"),
        });
    }
    Ok(Camera::with_resolution(w, h, f))
}

/// The streams of `spec`: one per label for [`Layout::SeparateTopics`]
/// (each object, or each run of swapped objects, rendered alone with its own
/// noise seed), or one labelled stream of all objects.
///
/// # Errors
/// [`SequenceError`] for bad parameters, shapes, or when an object is not visible.
pub fn build_streams(spec: &SequenceSpec) -> Result<Vec<Stream>, SequenceError> {
    let objects = build_objects(spec)?;
    match &spec.layout {
        Layout::Labelled { topic } => {
            check_topic(topic)?;
            let target = spec.points_per_object * objects.len();
            Ok(vec![Stream {
                topic: topic.clone(),
                labelled: true,
                scene: scene_for(objects, spec, true, spec.seed, target)?,
            }])
        }
        Layout::SeparateTopics => {
            let mut groups: BTreeMap<u32, Vec<SceneObject>> = BTreeMap::new();
            for o in objects {
                groups.entry(o.label).or_default().push(o);
            }
            groups
                .into_values()
                .enumerate()
                .map(|(i, group)| {
                    let names: Vec<&str> = group.iter().map(|o| o.name.as_str()).collect();
                    let topic = format!("/synth/{}/points", names.join("_then_"));
                    let seed = spec.seed ^ (i as u64).wrapping_mul(0xD1B5_4A32_D192_ED03);
                    Ok(Stream {
                        topic,
                        labelled: false,
                        scene: scene_for(group, spec, false, seed, spec.points_per_object)?,
                    })
                })
                .collect()
        }
    }
}

fn check_topic(topic: &str) -> Result<(), SequenceError> {
    let ok = topic.starts_with('/')
        && topic.len() > 1
        && !topic.ends_with('/')
        && !topic.contains("//")
        && topic
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
    if ok && topic != GROUND_TRUTH_TOPIC {
        Ok(())
    } else {
        Err(SequenceError::InvalidParameter {
            name: "topic",
            reason: format!("`{topic}` is not a usable absolute ROS topic name"),
        })
    }
}

/// A rigid pose as a `geometry_msgs/Pose`.
pub fn pose_to_msg(pose: &Isometry3<f64>) -> Pose {
    let t = pose.translation.vector;
    let q = pose.rotation.into_inner();
    Pose {
        position: Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceSummary {
    /// The `.mcap` file written.
    pub mcap_path: PathBuf,
    /// Messages per topic.
    pub counts: BTreeMap<String, u64>,
    /// Stream ids (`topic` or `topic#label`) with their object names.
    pub streams: Vec<(String, String)>,
    /// Mean visible points per object and frame.
    pub mean_points_per_object: f64,
    /// Outliers over all frames.
    pub outliers: usize,
}

/// Render `spec` and write it as a rosbag2 MCAP bag at `out` (a `.mcap`
/// file, or a bag directory with `metadata.yaml`). Calls `progress(k)` after
/// each frame. The bag's bytes depend only on `spec` and the crate version.
///
/// # Errors
/// [`SequenceError`] for bad parameters or shapes, rendering or bag failures.
pub fn write_sequence(
    spec: &SequenceSpec,
    out: &Path,
    mut progress: impl FnMut(usize),
) -> Result<SequenceSummary, SequenceError> {
    let streams = build_streams(spec)?;
    let bag_err = |source| SequenceError::Bag {
        path: out.to_path_buf(),
        source,
    };
    let mut w = BagWriter::create(out).map_err(bag_err)?;
    for s in &streams {
        w.add_topic(&s.topic, PointCloud2::TYPE_NAME, Qos::sensor_data())
            .map_err(bag_err)?;
    }
    w.add_topic(GROUND_TRUTH_TOPIC, GroundTruth::TYPE_NAME, Qos::default())
        .map_err(bag_err)?;
    let period_ns = (1e9 / spec.rate_hz).round() as i64;
    let mut renderer = Renderer::new();
    let (mut visible, mut outliers, mut records) = (0usize, 0usize, 0usize);
    // (stream id, mesh id) pairs whose mesh has been sent.
    let mut sent: BTreeSet<(String, String)> = BTreeSet::new();
    for k in 0..spec.frames {
        let t = START_NS + k as i64 * period_ns;
        let header = Header {
            stamp: Time::from_nanos(t),
            frame_id: spec.frame_id.clone(),
        };
        for s in &streams {
            let frame = renderer.render(&s.scene, k)?;
            outliers += frame.outliers;
            let cloud = encode_pointcloud2(&frame.cloud, header.clone());
            w.write(&s.topic, t as u64, &cloud).map_err(bag_err)?;
            for truth in &frame.truth {
                visible += truth.visible_points;
                records += 1;
                let stream_id = s.stream_id(truth.label);
                let first = sent.insert((stream_id.clone(), truth.name.clone()));
                let mesh = first.then_some(&s.scene.objects[truth.object].mesh);
                let gt = GroundTruth {
                    header: header.clone(),
                    stream_id,
                    world_frame_id: spec.world_frame_id.clone(),
                    ..ground_truth_msg(&s.scene.camera, &frame, truth, mesh)
                };
                w.write(GROUND_TRUTH_TOPIC, t as u64, &gt)
                    .map_err(bag_err)?;
            }
        }
        progress(k);
    }
    let summary = w.finish().map_err(bag_err)?;
    Ok(SequenceSummary {
        mcap_path: summary.mcap_path,
        counts: summary.counts,
        streams: streams
            .iter()
            .flat_map(|s| {
                s.scene
                    .objects
                    .iter()
                    .map(|o| (s.stream_id(o.label), o.name.clone()))
            })
            .collect(),
        mean_points_per_object: visible as f64 / records.max(1) as f64,
        outliers,
    })
}

/// The GroundTruth message of `truth` in `frame` (poses, intrinsics, counts),
/// with `mesh` when given; header, stream and world frame left default.
fn ground_truth_msg(
    camera: &Camera,
    frame: &super::Frame,
    truth: &super::ObjectTruth,
    mesh: Option<&TriMesh>,
) -> GroundTruth {
    let (vertices, triangles) = mesh.map_or_else(
        || (Vec::new(), Vec::new()),
        |m| {
            (
                m.vertices
                    .iter()
                    .map(|v| Point {
                        x: v.x,
                        y: v.y,
                        z: v.z,
                    })
                    .collect(),
                m.triangles
                    .iter()
                    .map(|&t| MeshTriangle { vertex_indices: t })
                    .collect(),
            )
        },
    );
    GroundTruth {
        mesh_id: truth.name.clone(),
        pose: pose_to_msg(&truth.pose),
        camera_pose: pose_to_msg(&frame.camera_pose),
        width: u32::try_from(camera.width).unwrap_or(u32::MAX),
        height: u32::try_from(camera.height).unwrap_or(u32::MAX),
        fx: camera.fx,
        fy: camera.fy,
        cx: camera.cx,
        cy: camera.cy,
        visible_points: u32::try_from(truth.visible_points).unwrap_or(u32::MAX),
        vertices,
        triangles,
        ..GroundTruth::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(layout: Layout) -> SequenceSpec {
        SequenceSpec {
            shapes: vec!["sphere".into(), "torus".into(), "sphere".into()],
            frames: 4,
            points_per_object: 1_500,
            noise: Noise::none(),
            layout,
            mesh_resolution: 16,
            ..SequenceSpec::default()
        }
    }

    #[test]
    fn noise_specs_parse() {
        assert_eq!(parse_noise("none").unwrap(), Noise::none());
        assert_eq!(parse_noise("kinect").unwrap(), Noise::kinect());
        let n = parse_noise("0.002").unwrap();
        assert_eq!((n.sigma_const, n.sigma_quadratic), (0.002, 0.0));
        assert!(parse_noise("-1").is_err());
        assert!(parse_noise("loud").is_err());
        assert!(parse_noise("NaN").is_err());
    }

    #[test]
    fn objects_get_unique_names_labels_and_separate_topics() {
        let streams = build_streams(&small(Layout::SeparateTopics)).unwrap();
        let topics: Vec<&str> = streams.iter().map(|s| s.topic.as_str()).collect();
        assert_eq!(
            topics,
            [
                "/synth/sphere/points",
                "/synth/torus/points",
                "/synth/sphere_2/points"
            ]
        );
        assert_eq!(streams[1].stream_id(2), "/synth/torus/points");
        let one = build_streams(&small(Layout::Labelled {
            topic: "/synth/points".into(),
        }))
        .unwrap();
        assert_eq!(one.len(), 1);
        let labels: Vec<u32> = one[0].scene.objects.iter().map(|o| o.label).collect();
        assert_eq!(labels, [1, 2, 3]);
        assert_eq!(one[0].stream_id(2), "/synth/points#2");
    }

    #[test]
    fn point_budget_is_met_per_object() {
        for s in build_streams(&small(Layout::SeparateTopics)).unwrap() {
            let n = Renderer::new().render(&s.scene, 0).unwrap().cloud.len() as f64;
            assert!((n - 1_500.0).abs() < 150.0, "{}: {n}", s.topic);
        }
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        let mut spec = small(Layout::SeparateTopics);
        spec.shapes = vec!["no_such_shape".into()];
        assert!(matches!(
            build_streams(&spec),
            Err(SequenceError::BadShape { .. })
        ));
        spec.shapes = vec![];
        assert!(build_streams(&spec).is_err());
        let mut spec = small(Layout::Labelled {
            topic: "no/leading/slash".into(),
        });
        assert!(matches!(
            build_streams(&spec),
            Err(SequenceError::InvalidParameter { name: "topic", .. })
        ));
        spec.layout = Layout::SeparateTopics;
        spec.frames = 0;
        assert!(build_streams(&spec).is_err());
        spec.frames = 3;
        spec.rate_hz = f64::NAN;
        assert!(build_streams(&spec).is_err());
    }
}
