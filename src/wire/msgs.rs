//! Serde structs for the ROS 2 messages sepmem reads and writes.
//!
//! Field order and types follow the `.msg` definitions in
//! [`super::msgdef`] exactly, since CDR is positional. ROS `uint8[]` blobs use
//! `serde_bytes` (one `write_all` instead of one call per byte); ROS `char`
//! and `byte` are `u8`; fixed arrays are Rust arrays (no length prefix).
//! Every message type implements [`RosMessage`], which carries its type name
//! and its RIHS01 hash (hard-coded; the tests recompute them).

use serde::{Deserialize, Serialize};

/// A ROS 2 message type with a registered definition.
pub trait RosMessage: Serialize + for<'de> Deserialize<'de> {
    /// Fully qualified type name, `pkg/msg/Name`.
    const TYPE_NAME: &'static str;
    /// RIHS01 type hash (`RIHS01_<64 hex>`), REP-2011.
    const TYPE_HASH: &'static str;
}

macro_rules! ros_message {
    ($t:ty, $name:literal, $hash:literal) => {
        impl RosMessage for $t {
            const TYPE_NAME: &'static str = $name;
            const TYPE_HASH: &'static str = $hash;
        }
    };
}

/// builtin_interfaces/msg/Time.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch (saturating at the `i32` second range).
    pub fn from_nanos(ns: i64) -> Self {
        let sec = ns.div_euclid(1_000_000_000);
        Self {
            sec: sec.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32,
            nanosec: ns.rem_euclid(1_000_000_000) as u32,
        }
    }

    /// Nanoseconds since the epoch.
    pub fn to_nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// builtin_interfaces/msg/Duration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds.
    pub nanosec: u32,
}

/// std_msgs/msg/Header.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// std_msgs/msg/ColorRGBA.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRGBA {
    /// Red in [0, 1].
    pub r: f32,
    /// Green in [0, 1].
    pub g: f32,
    /// Blue in [0, 1].
    pub b: f32,
    /// Alpha in [0, 1].
    pub a: f32,
}

/// sensor_msgs/msg/PointField.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PointField {
    /// Field name (`x`, `rgb`, `intensity`, …).
    pub name: String,
    /// Byte offset inside a point.
    pub offset: u32,
    /// Datatype code (see [`PointField::FLOAT32`] and siblings).
    pub datatype: u8,
    /// Number of elements.
    pub count: u32,
}

impl PointField {
    /// `int8`.
    pub const INT8: u8 = 1;
    /// `uint8`.
    pub const UINT8: u8 = 2;
    /// `int16`.
    pub const INT16: u8 = 3;
    /// `uint16`.
    pub const UINT16: u8 = 4;
    /// `int32`.
    pub const INT32: u8 = 5;
    /// `uint32`.
    pub const UINT32: u8 = 6;
    /// `float32`.
    pub const FLOAT32: u8 = 7;
    /// `float64`.
    pub const FLOAT64: u8 = 8;

    /// A field of `count` elements of `datatype` at `offset`.
    pub fn new(name: &str, offset: u32, datatype: u8, count: u32) -> Self {
        Self {
            name: name.to_string(),
            offset,
            datatype,
            count,
        }
    }
}

/// sensor_msgs/msg/PointCloud2.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Stamp and frame.
    pub header: Header,
    /// Rows (1 for unorganised clouds).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Layout of one point.
    pub fields: Vec<PointField>,
    /// Byte order of `data`.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// Point data, `row_step * height` bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    /// True when no point is invalid.
    pub is_dense: bool,
}

/// sensor_msgs/msg/CompressedImage (embedded in `Marker.texture`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Stamp and frame.
    pub header: Header,
    /// Image format (`jpeg`, `png`).
    pub format: String,
    /// Encoded image.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// geometry_msgs/msg/Point.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// geometry_msgs/msg/Quaternion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    /// The identity rotation (ROS default `w = 1`).
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// geometry_msgs/msg/Pose.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// geometry_msgs/msg/Vector3.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// visualization_msgs/msg/UVCoordinate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct UVCoordinate {
    /// u.
    pub u: f32,
    /// v.
    pub v: f32,
}

/// visualization_msgs/msg/MeshFile.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeshFile {
    /// File name (its extension tells the format).
    pub filename: String,
    /// File contents.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// visualization_msgs/msg/Marker.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    /// Stamp and frame.
    pub header: Header,
    /// Namespace.
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// Marker type ([`Marker::TRIANGLE_LIST`], …).
    #[serde(rename = "type")]
    pub type_: i32,
    /// Action ([`Marker::ADD`], [`Marker::DELETEALL`], …).
    pub action: i32,
    /// Pose of the marker frame.
    pub pose: Pose,
    /// Scale (1,1,1 for triangle lists).
    pub scale: Vector3,
    /// Colour used when `colors` is empty.
    pub color: ColorRGBA,
    /// How long the marker lives (0 = forever).
    pub lifetime: Duration,
    /// Re-transform every frame.
    pub frame_locked: bool,
    /// Geometry (consecutive triples for triangle lists).
    pub points: Vec<Point>,
    /// Optional per-point colours.
    pub colors: Vec<ColorRGBA>,
    /// Texture URI.
    pub texture_resource: String,
    /// Embedded texture.
    pub texture: CompressedImage,
    /// Texture coordinates.
    pub uv_coordinates: Vec<UVCoordinate>,
    /// Text for TEXT_VIEW_FACING.
    pub text: String,
    /// Mesh URI for MESH_RESOURCE.
    pub mesh_resource: String,
    /// Embedded mesh file.
    pub mesh_file: MeshFile,
    /// Use the mesh's own materials.
    pub mesh_use_embedded_materials: bool,
}

impl Marker {
    /// Marker type: list of triangles (consecutive point triples).
    pub const TRIANGLE_LIST: i32 = 11;
    /// Action: add or modify.
    pub const ADD: i32 = 0;
    /// Action: delete this marker.
    pub const DELETE: i32 = 2;
    /// Action: delete every marker (of this namespace, or all).
    pub const DELETEALL: i32 = 3;
}

/// visualization_msgs/msg/MarkerArray.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    /// Markers.
    pub markers: Vec<Marker>,
}

/// shape_msgs/msg/MeshTriangle.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeshTriangle {
    /// Vertex indices.
    pub vertex_indices: [u32; 3],
}

/// shape_msgs/msg/Mesh.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    /// Triangles.
    pub triangles: Vec<MeshTriangle>,
    /// Vertices.
    pub vertices: Vec<Point>,
}

/// geometry_msgs/msg/Point32.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point32 {
    /// X.
    pub x: f32,
    /// Y.
    pub y: f32,
    /// Z.
    pub z: f32,
}

/// geometry_msgs/msg/Polygon.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    /// Corners.
    pub points: Vec<Point32>,
}

/// shape_msgs/msg/SolidPrimitive.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SolidPrimitive {
    /// BOX=1, SPHERE=2, CYLINDER=3, CONE=4, PRISM=5.
    #[serde(rename = "type")]
    pub kind: u8,
    /// Dimensions (at most 3).
    pub dimensions: Vec<f64>,
    /// Prism base polygon.
    pub polygon: Polygon,
}

/// shape_msgs/msg/Plane.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Plane {
    /// ax + by + cz + d = 0.
    pub coef: [f64; 4],
}

/// object_recognition_msgs/msg/ObjectType.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObjectType {
    /// Key of the object in its database.
    pub key: String,
    /// Database parameters.
    pub db: String,
}

/// moveit_msgs/msg/CollisionObject (`ros2` branch).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CollisionObject {
    /// Frame and stamp the pose is relative to.
    pub header: Header,
    /// Object pose; shapes are relative to it.
    pub pose: Pose,
    /// Object id (name in MoveIt's planning scene).
    pub id: String,
    /// Database type.
    #[serde(rename = "type")]
    pub object_type: ObjectType,
    /// Solid primitives.
    pub primitives: Vec<SolidPrimitive>,
    /// Their poses.
    pub primitive_poses: Vec<Pose>,
    /// Meshes.
    pub meshes: Vec<Mesh>,
    /// Their poses.
    pub mesh_poses: Vec<Pose>,
    /// Planes.
    pub planes: Vec<Plane>,
    /// Their poses.
    pub plane_poses: Vec<Pose>,
    /// Subframe names.
    pub subframe_names: Vec<String>,
    /// Subframe poses.
    pub subframe_poses: Vec<Pose>,
    /// ADD, REMOVE, APPEND or MOVE.
    pub operation: u8,
}

impl CollisionObject {
    /// Add the object (replacing an object of the same id).
    pub const ADD: u8 = 0;
    /// Remove the object.
    pub const REMOVE: u8 = 1;
    /// Append shapes to an existing object.
    pub const APPEND: u8 = 2;
    /// Move an existing object (geometry arrays empty).
    pub const MOVE: u8 = 3;
}

/// diagnostic_msgs/msg/KeyValue.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value (numbers as text).
    pub value: String,
}

/// diagnostic_msgs/msg/DiagnosticStatus.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// Level ([`DiagnosticStatus::OK`], …).
    pub level: u8,
    /// Name (`"node: task"`).
    pub name: String,
    /// Human-readable summary.
    pub message: String,
    /// Device or host.
    pub hardware_id: String,
    /// Key-value details.
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    /// Level OK.
    pub const OK: u8 = 0;
    /// Level WARN.
    pub const WARN: u8 = 1;
    /// Level ERROR.
    pub const ERROR: u8 = 2;
    /// Level STALE.
    pub const STALE: u8 = 3;
}

/// diagnostic_msgs/msg/DiagnosticArray.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// Statuses.
    pub status: Vec<DiagnosticStatus>,
}

/// sepmem_msgs/msg/SurfaceMesh (see `msg/msg/SurfaceMesh.msg`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfaceMesh {
    /// Stamp and frame of the input cloud.
    pub header: Header,
    /// Stream id (topic, plus `#<label>` for labelled segments).
    pub stream_id: String,
    /// Object id within the stream.
    pub object_id: u32,
    /// Mesh vertices.
    pub vertices: Vec<Point>,
    /// Triangles.
    pub triangles: Vec<MeshTriangle>,
    /// Local separability η_p per vertex (paper Eq. 7).
    pub vertex_separability: Vec<f32>,
    /// Global separability η_g (paper Eq. 8).
    pub global_separability: f32,
    /// Control grid size M (around).
    pub grid_m: u32,
    /// Control grid size L (pole to pole).
    pub grid_l: u32,
    /// Iterations spent on this frame.
    pub iterations: u32,
    /// Warm-started from the previous surface.
    pub warm_start: bool,
    /// Why warm or cold.
    pub start_reason: String,
    /// Why the iterations stopped.
    pub stop_reason: String,
    /// Verdict on the surface: [`SurfaceMesh::FITTED`] … [`SurfaceMesh::HELD`].
    pub quality: u8,
}

impl SurfaceMesh {
    /// Converged, or evolved long enough since its cold start.
    pub const FITTED: u8 = 0;
    /// Stopped by its budget before converging.
    pub const UNCONVERGED: u8 = 1;
    /// Not evolved (the start surface) or separating nothing.
    pub const UNFITTED: u8 = 2;
    /// This frame was not fitted: the object's last fitted mesh, republished.
    pub const HELD: u8 = 3;
}

/// sepmem_msgs/msg/FrameDiagnostics (see `msg/msg/FrameDiagnostics.msg`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameDiagnostics {
    /// Stamp and frame of the input cloud.
    pub header: Header,
    /// Stream id.
    pub stream_id: String,
    /// Frame number within the stream.
    pub frame_index: u64,
    /// Points received.
    pub points_in: u32,
    /// Points used.
    pub points_used: u32,
    /// Points dropped.
    pub points_dropped: u32,
    /// Iterations spent.
    pub iterations: u32,
    /// Global separability η_g (paper Eq. 8).
    pub global_separability: f32,
    /// Latency in milliseconds.
    pub latency_ms: f32,
    /// Warm-started.
    pub warm_start: bool,
    /// Why warm or cold.
    pub start_reason: String,
    /// Why the iterations stopped.
    pub stop_reason: String,
}

ros_message!(
    Time,
    "builtin_interfaces/msg/Time",
    "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
);
ros_message!(
    Duration,
    "builtin_interfaces/msg/Duration",
    "RIHS01_e8d009f659816f758b75334ee1a9ca5b5c0b859843261f14c7f937349599d93b"
);
ros_message!(
    Header,
    "std_msgs/msg/Header",
    "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
);
ros_message!(
    ColorRGBA,
    "std_msgs/msg/ColorRGBA",
    "RIHS01_77a7a5b9ae477306097665106e0413ba74440245b1f3d0c6d6405fe5c7813fe8"
);
ros_message!(
    PointField,
    "sensor_msgs/msg/PointField",
    "RIHS01_5c6a4750728c2bcfbbf7037225b20b02d4429634732146b742dee1726637ef01"
);
ros_message!(
    PointCloud2,
    "sensor_msgs/msg/PointCloud2",
    "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5"
);
ros_message!(
    CompressedImage,
    "sensor_msgs/msg/CompressedImage",
    "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a"
);
ros_message!(
    Point,
    "geometry_msgs/msg/Point",
    "RIHS01_6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881"
);
ros_message!(
    Quaternion,
    "geometry_msgs/msg/Quaternion",
    "RIHS01_8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684"
);
ros_message!(
    Pose,
    "geometry_msgs/msg/Pose",
    "RIHS01_d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa"
);
ros_message!(
    Vector3,
    "geometry_msgs/msg/Vector3",
    "RIHS01_cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d"
);
ros_message!(
    UVCoordinate,
    "visualization_msgs/msg/UVCoordinate",
    "RIHS01_f27f7ed21fe360c6066944f856b801a0c0d1e94e815b6886444b42d90b196a26"
);
ros_message!(
    MeshFile,
    "visualization_msgs/msg/MeshFile",
    "RIHS01_7710ece15a148fb7c9b546364cfb215bb06098087bd6394fe5b73a493508f8c4"
);
ros_message!(
    Marker,
    "visualization_msgs/msg/Marker",
    "RIHS01_45b13ccf791f225962bf74e746f9644518855d783a6f42ba0cc14fde2b4f3ce0"
);
ros_message!(
    MarkerArray,
    "visualization_msgs/msg/MarkerArray",
    "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"
);
ros_message!(
    MeshTriangle,
    "shape_msgs/msg/MeshTriangle",
    "RIHS01_618e5c073eeb729e433ef6226e72c01d995c459fb7d76348c9700409a5020bd0"
);
ros_message!(
    Mesh,
    "shape_msgs/msg/Mesh",
    "RIHS01_f2150b82d8ee7e8bc3f396a2b158aefb4b9a5510a474be271ba1268aebb55289"
);
ros_message!(
    KeyValue,
    "diagnostic_msgs/msg/KeyValue",
    "RIHS01_d68081eaa540288c5440753baecef0c4e16e81a5f78ad68902ded5100413bb42"
);
ros_message!(
    DiagnosticStatus,
    "diagnostic_msgs/msg/DiagnosticStatus",
    "RIHS01_b0e3e692ea2d54a8af2f4ef1930e81556a2db55216b771f8a7d2724ed47bf0e4"
);
ros_message!(
    DiagnosticArray,
    "diagnostic_msgs/msg/DiagnosticArray",
    "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"
);
/// sepmem_msgs/msg/GroundTruth (see `msg/msg/GroundTruth.msg`): written by
/// `sepmem synth` so that replayed frames can be scored.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// Stamp and frame of the cloud this truth belongs to.
    pub header: Header,
    /// Stream the object appears in.
    pub stream_id: String,
    /// Ground-truth mesh identifier.
    pub mesh_id: String,
    /// Pose of the mesh frame in `header.frame_id`.
    pub pose: Pose,
    /// Fixed world frame of `camera_pose`.
    pub world_frame_id: String,
    /// Pose of `header.frame_id` (the camera) in `world_frame_id`.
    pub camera_pose: Pose,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Focal length along x (pixels).
    pub fx: f64,
    /// Focal length along y (pixels).
    pub fy: f64,
    /// Principal point x (pixels).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
    /// Points of the frame on this object (before flying pixels and outliers).
    pub visible_points: u32,
    /// Mesh vertices in the mesh frame (first frame of a stream only).
    pub vertices: Vec<Point>,
    /// Mesh triangles (first frame of a stream only).
    pub triangles: Vec<MeshTriangle>,
}

ros_message!(
    GroundTruth,
    "sepmem_msgs/msg/GroundTruth",
    "RIHS01_8cb0540f8bd243f3a70299627cf22ec4ce7f64c6bf29f31d6257458d4f7248dd"
);
ros_message!(
    SurfaceMesh,
    "sepmem_msgs/msg/SurfaceMesh",
    "RIHS01_05633ada0a679eeaaaa89e1eecb13fcaa2c6ad46ede862663d5350f5617743b3"
);
ros_message!(
    FrameDiagnostics,
    "sepmem_msgs/msg/FrameDiagnostics",
    "RIHS01_2eb2d504d144086cb5f775b10c332339b62e324b794e06e869bb21bcebbf0de4"
);

ros_message!(
    Point32,
    "geometry_msgs/msg/Point32",
    "RIHS01_2fc4db7cae16a4582c79a56b66173a8d48d52c7dc520ddc55a0d4bcf2a4bfdbc"
);
ros_message!(
    Polygon,
    "geometry_msgs/msg/Polygon",
    "RIHS01_3782f9f0bf044964d692d6c017d705e37611afb1f0bf6a9dee248a7dda0f784a"
);
ros_message!(
    SolidPrimitive,
    "shape_msgs/msg/SolidPrimitive",
    "RIHS01_2802a15190aadc3f496584df4b0b4c5824d8a0b31aaef839faa75bc34dda38ac"
);
ros_message!(
    Plane,
    "shape_msgs/msg/Plane",
    "RIHS01_dfbfe8314689c850615d4a727af017e9aa86c10e369a606c8c851ef8f16c58c8"
);
ros_message!(
    ObjectType,
    "object_recognition_msgs/msg/ObjectType",
    "RIHS01_5eb3ee3976403366d7c50d7dbee8bec96b3bced1e752674a7194a35841632134"
);
ros_message!(
    CollisionObject,
    "moveit_msgs/msg/CollisionObject",
    "RIHS01_74b0acd6d56be032bf4f764b2c2633f50588b5fb2bd71e97206c59052747cf7e"
);

/// `(type name, RIHS01)` of every message type above, for lookups by name.
pub const TYPE_HASHES: &[(&str, &str)] = &[
    (Time::TYPE_NAME, Time::TYPE_HASH),
    (Duration::TYPE_NAME, Duration::TYPE_HASH),
    (Header::TYPE_NAME, Header::TYPE_HASH),
    (ColorRGBA::TYPE_NAME, ColorRGBA::TYPE_HASH),
    (PointField::TYPE_NAME, PointField::TYPE_HASH),
    (PointCloud2::TYPE_NAME, PointCloud2::TYPE_HASH),
    (CompressedImage::TYPE_NAME, CompressedImage::TYPE_HASH),
    (Point::TYPE_NAME, Point::TYPE_HASH),
    (Quaternion::TYPE_NAME, Quaternion::TYPE_HASH),
    (Pose::TYPE_NAME, Pose::TYPE_HASH),
    (Vector3::TYPE_NAME, Vector3::TYPE_HASH),
    (UVCoordinate::TYPE_NAME, UVCoordinate::TYPE_HASH),
    (MeshFile::TYPE_NAME, MeshFile::TYPE_HASH),
    (Marker::TYPE_NAME, Marker::TYPE_HASH),
    (MarkerArray::TYPE_NAME, MarkerArray::TYPE_HASH),
    (MeshTriangle::TYPE_NAME, MeshTriangle::TYPE_HASH),
    (Mesh::TYPE_NAME, Mesh::TYPE_HASH),
    (KeyValue::TYPE_NAME, KeyValue::TYPE_HASH),
    (DiagnosticStatus::TYPE_NAME, DiagnosticStatus::TYPE_HASH),
    (DiagnosticArray::TYPE_NAME, DiagnosticArray::TYPE_HASH),
    (SurfaceMesh::TYPE_NAME, SurfaceMesh::TYPE_HASH),
    (FrameDiagnostics::TYPE_NAME, FrameDiagnostics::TYPE_HASH),
    (GroundTruth::TYPE_NAME, GroundTruth::TYPE_HASH),
    (Point32::TYPE_NAME, Point32::TYPE_HASH),
    (Polygon::TYPE_NAME, Polygon::TYPE_HASH),
    (SolidPrimitive::TYPE_NAME, SolidPrimitive::TYPE_HASH),
    (Plane::TYPE_NAME, Plane::TYPE_HASH),
    (ObjectType::TYPE_NAME, ObjectType::TYPE_HASH),
    (CollisionObject::TYPE_NAME, CollisionObject::TYPE_HASH),
];

/// The hard-coded RIHS01 hash of a registered type.
pub fn type_hash(type_name: &str) -> Option<&'static str> {
    TYPE_HASHES
        .iter()
        .find(|(n, _)| *n == type_name)
        .map(|(_, h)| *h)
}
