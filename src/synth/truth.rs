//! Ground truth read back from a bag: the `sepmem_msgs/msg/GroundTruth`
//! side channel written by [`crate::synth::sequence`], indexed by stream id
//! (`topic` or `topic#label`, the [`StreamKey`](crate::stream::StreamKey)
//! display string) and stamp, so that every replayed frame can be scored.
//!
//! The first message of each mesh id on a stream carries the mesh in the
//! object frame (a stream's mesh id changes when its object is swapped for
//! another); every message carries the object's pose in the cloud's frame,
//! the camera's pose in the world frame and the camera's intrinsics at that
//! stamp. The posed ground-truth surface of a frame is that frame's mesh
//! transformed by that frame's pose; it is the full closed surface,
//! including the side the camera does not see.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use thiserror::Error;

use super::Camera;
use crate::bag::{Bag, BagError};
use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use crate::wire::msgs::{GroundTruth, Pose};
use crate::wire::{self, RosMessage, WireError};

/// Errors of reading ground truth.
#[derive(Debug, Error)]
pub enum TruthError {
    /// The bag could not be read.
    #[error("reading ground truth from the bag: {0}")]
    Bag(#[from] BagError),
    /// A GroundTruth message did not decode.
    #[error("ground-truth message at {stamp_ns} ns does not decode: {source}")]
    Decode {
        /// Log time of the message.
        stamp_ns: u64,
        /// Cause.
        source: WireError,
    },
    /// The first message of a mesh id on a stream carries no mesh.
    #[error("stream `{stream}`: first ground-truth message of mesh `{mesh_id}` (stamp {stamp_ns} ns) has no mesh")]
    MissingMesh {
        /// Stream id.
        stream: String,
        /// Mesh id.
        mesh_id: String,
        /// Stamp of that message.
        stamp_ns: i64,
    },
    /// A mesh is malformed.
    #[error("stream `{stream}`: bad ground-truth mesh: {reason}")]
    BadMesh {
        /// Stream id.
        stream: String,
        /// What is wrong.
        reason: String,
    },
    /// A pose is not finite or its quaternion is not of unit length.
    #[error("stream `{stream}` at {stamp_ns} ns: bad pose {pose:?}")]
    BadPose {
        /// Stream id.
        stream: String,
        /// Stamp.
        stamp_ns: i64,
        /// The pose as received.
        pose: Pose,
    },
    /// The camera intrinsics are not usable.
    #[error("stream `{stream}` at {stamp_ns} ns: bad camera intrinsics: {reason}")]
    BadCamera {
        /// Stream id.
        stream: String,
        /// Stamp.
        stamp_ns: i64,
        /// What is wrong.
        reason: String,
    },
}

/// Ground truth of one object in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthFrame {
    /// Object frame → cloud frame.
    pub pose: Isometry3<f64>,
    /// Cloud (camera optical) frame → world frame.
    pub camera_pose: Isometry3<f64>,
    /// The camera's intrinsics (depth range: the [`Camera::kinect`] defaults).
    pub camera: Camera,
    /// Index of the frame's mesh in [`TruthTrack::meshes`].
    pub mesh: usize,
    /// Points of the frame on the object (before flying pixels and outliers).
    pub visible_points: u32,
}

/// Ground truth of one stream.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthTrack {
    /// Mesh identifier (object name) of the stream's first frame.
    pub mesh_id: String,
    /// The mesh of the stream's first frame, in the object frame.
    pub mesh: TriMesh,
    /// Every mesh seen on the stream, in order of appearance, with its id
    /// (the first is `mesh_id`, `mesh`).
    pub meshes: Vec<(String, TriMesh)>,
    /// Per stamp (ns since the epoch).
    pub frames: BTreeMap<i64, TruthFrame>,
}

impl TruthTrack {
    /// The mesh id and mesh (object frame) of the frame at `stamp_ns`.
    pub fn mesh_at(&self, stamp_ns: i64) -> Option<(&str, &TriMesh)> {
        let f = self.frames.get(&stamp_ns)?;
        self.meshes.get(f.mesh).map(|(id, m)| (id.as_str(), m))
    }

    /// The ground-truth surface at `stamp_ns` (that frame's mesh moved by its pose).
    pub fn posed_mesh(&self, stamp_ns: i64) -> Option<TriMesh> {
        let f = self.frames.get(&stamp_ns)?;
        Some(self.mesh_at(stamp_ns)?.1.transformed(&f.pose))
    }
}

/// All ground truth of a bag, by stream id.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GroundTruthIndex {
    /// Tracks by stream id (`topic` or `topic#label`).
    pub streams: BTreeMap<String, TruthTrack>,
}

fn pose_from_msg(p: &Pose) -> Option<Isometry3<f64>> {
    let o = p.orientation;
    let q = Quaternion::new(o.w, o.x, o.y, o.z);
    let t = Vec3::new(p.position.x, p.position.y, p.position.z);
    let finite = q.coords.iter().chain(t.iter()).all(|c| c.is_finite());
    if !finite || (q.norm() - 1.0).abs() > 1e-6 {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_quaternion(q),
    ))
}

impl GroundTruthIndex {
    /// Read every GroundTruth message of `bag` (any topic of that type); an
    /// empty index when the bag has none.
    ///
    /// # Errors
    /// [`TruthError`] for unreadable bags or malformed messages.
    pub fn from_bag(bag: &Bag) -> Result<Self, TruthError> {
        let topics: Vec<&str> = bag
            .topics
            .iter()
            .filter(|t| t.type_name == GroundTruth::TYPE_NAME)
            .map(|t| t.name.as_str())
            .collect();
        if topics.is_empty() {
            return Ok(Self::default());
        }
        let mut msgs = Vec::new();
        for m in bag.read(&topics)? {
            let gt: GroundTruth = wire::decode(&m.data).map_err(|source| TruthError::Decode {
                stamp_ns: m.log_time,
                source,
            })?;
            msgs.push(gt);
        }
        Self::from_messages(msgs)
    }

    /// Index messages given in log order (the first of each stream must carry the mesh).
    ///
    /// # Errors
    /// [`TruthError`] for a missing or malformed mesh or a bad pose.
    pub fn from_messages(msgs: impl IntoIterator<Item = GroundTruth>) -> Result<Self, TruthError> {
        let mut streams: BTreeMap<String, TruthTrack> = BTreeMap::new();
        for gt in msgs {
            let stamp = gt.header.stamp.to_nanos();
            let bad_pose = |pose: &Pose| TruthError::BadPose {
                stream: gt.stream_id.clone(),
                stamp_ns: stamp,
                pose: *pose,
            };
            let pose = pose_from_msg(&gt.pose).ok_or_else(|| bad_pose(&gt.pose))?;
            let camera_pose =
                pose_from_msg(&gt.camera_pose).ok_or_else(|| bad_pose(&gt.camera_pose))?;
            let camera = camera_from_msg(&gt)?;
            let known = streams
                .get(&gt.stream_id)
                .and_then(|t| t.meshes.iter().position(|(id, _)| *id == gt.mesh_id));
            let mesh = match known {
                Some(i) => i,
                None => {
                    let m = mesh_from_msg(&gt)?;
                    let track = streams
                        .entry(gt.stream_id.clone())
                        .or_insert_with(|| TruthTrack {
                            mesh_id: gt.mesh_id.clone(),
                            mesh: m.clone(),
                            meshes: Vec::new(),
                            frames: BTreeMap::new(),
                        });
                    track.meshes.push((gt.mesh_id.clone(), m));
                    track.meshes.len() - 1
                }
            };
            if let Some(track) = streams.get_mut(&gt.stream_id) {
                track.frames.insert(
                    stamp,
                    TruthFrame {
                        pose,
                        camera_pose,
                        camera,
                        mesh,
                        visible_points: gt.visible_points,
                    },
                );
            }
        }
        Ok(Self { streams })
    }

    /// The truth of `stream` at `stamp_ns`.
    pub fn frame(&self, stream: &str, stamp_ns: i64) -> Option<&TruthFrame> {
        self.streams.get(stream)?.frames.get(&stamp_ns)
    }

    /// The posed ground-truth surface of `stream` at `stamp_ns`.
    pub fn posed_mesh(&self, stream: &str, stamp_ns: i64) -> Option<TriMesh> {
        self.streams.get(stream)?.posed_mesh(stamp_ns)
    }

    /// Whether no ground truth was found.
    pub fn is_empty(&self) -> bool {
        self.streams.is_empty()
    }
}

fn camera_from_msg(gt: &GroundTruth) -> Result<Camera, TruthError> {
    let camera = Camera {
        width: gt.width as usize,
        height: gt.height as usize,
        fx: gt.fx,
        fy: gt.fy,
        cx: gt.cx,
        cy: gt.cy,
        ..Camera::kinect()
    };
    camera.validate().map_err(|e| TruthError::BadCamera {
        stream: gt.stream_id.clone(),
        stamp_ns: gt.header.stamp.to_nanos(),
        reason: e.to_string(),
    })?;
    Ok(camera)
}

fn mesh_from_msg(gt: &GroundTruth) -> Result<TriMesh, TruthError> {
    let bad = |reason: String| TruthError::BadMesh {
        stream: gt.stream_id.clone(),
        reason,
    };
    if gt.vertices.is_empty() || gt.triangles.is_empty() {
        return Err(TruthError::MissingMesh {
            stream: gt.stream_id.clone(),
            mesh_id: gt.mesh_id.clone(),
            stamp_ns: gt.header.stamp.to_nanos(),
        });
    }
    let nv = gt.vertices.len();
    if gt
        .triangles
        .iter()
        .any(|t| t.vertex_indices.iter().any(|&i| i as usize >= nv))
    {
        return Err(bad(format!("triangle index ≥ {nv} vertices")));
    }
    let vertices: Vec<Vec3> = gt
        .vertices
        .iter()
        .map(|p| Vec3::new(p.x, p.y, p.z))
        .collect();
    if vertices.iter().any(|v| !v.iter().all(|c| c.is_finite())) {
        return Err(bad("non-finite vertex".into()));
    }
    Ok(TriMesh {
        vertices,
        triangles: gt.triangles.iter().map(|t| t.vertex_indices).collect(),
        vertex_scalars: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::msgs::{Header, MeshTriangle, Point, Quaternion as QMsg, Time};

    fn msg(stream: &str, ns: i64, with_mesh: bool, pose: Pose) -> GroundTruth {
        let (vertices, triangles) = if with_mesh {
            (
                [
                    [0.0, 0.0, 0.0],
                    [1.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0],
                    [0.0, 0.0, 1.0],
                ]
                .map(|[x, y, z]| Point { x, y, z })
                .to_vec(),
                [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
                    .map(|v| MeshTriangle { vertex_indices: v })
                    .to_vec(),
            )
        } else {
            (vec![], vec![])
        };
        GroundTruth {
            header: Header {
                stamp: Time::from_nanos(ns),
                frame_id: "cam".into(),
            },
            stream_id: stream.into(),
            mesh_id: "tet".into(),
            pose,
            world_frame_id: "world".into(),
            camera_pose: shifted(0.0),
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            visible_points: 10,
            vertices,
            triangles,
        }
    }

    fn shifted(z: f64) -> Pose {
        Pose {
            position: Point { x: 0.0, y: 0.0, z },
            orientation: QMsg::default(),
        }
    }

    #[test]
    fn posed_mesh_applies_each_frames_pose() {
        let idx = GroundTruthIndex::from_messages([
            msg("/a", 1, true, shifted(1.0)),
            msg("/a", 2, false, shifted(2.0)),
        ])
        .unwrap();
        assert_eq!(idx.posed_mesh("/a", 1).unwrap().vertices[3].z, 2.0);
        assert_eq!(idx.posed_mesh("/a", 2).unwrap().vertices[3].z, 3.0);
        assert!(idx.posed_mesh("/a", 3).is_none());
        assert!(idx.posed_mesh("/b", 1).is_none());
        assert_eq!(idx.frame("/a", 2).unwrap().camera.fx, 50.0);
    }

    #[test]
    fn a_swapped_mesh_is_indexed_from_its_first_message() {
        let mut swapped = msg("/a", 3, true, shifted(1.0));
        swapped.mesh_id = "other".into();
        swapped.vertices[3].z = 5.0;
        let mut later = msg("/a", 4, false, shifted(1.0));
        later.mesh_id = "other".into();
        let idx = GroundTruthIndex::from_messages([
            msg("/a", 1, true, shifted(1.0)),
            msg("/a", 2, false, shifted(1.0)),
            swapped,
            later,
        ])
        .unwrap();
        let track = &idx.streams["/a"];
        assert_eq!(track.mesh_id, "tet");
        assert_eq!(track.mesh_at(2).unwrap().0, "tet");
        assert_eq!(track.mesh_at(4).unwrap().0, "other");
        assert_eq!(idx.posed_mesh("/a", 2).unwrap().vertices[3].z, 2.0);
        assert_eq!(idx.posed_mesh("/a", 4).unwrap().vertices[3].z, 6.0);
        // A new mesh id without its mesh is an error naming it.
        let mut bare = msg("/a", 5, false, shifted(1.0));
        bare.mesh_id = "third".into();
        let err = GroundTruthIndex::from_messages([msg("/a", 1, true, shifted(1.0)), bare]);
        assert!(matches!(err, Err(TruthError::MissingMesh { mesh_id, .. }) if mesh_id == "third"));
    }

    #[test]
    fn malformed_truth_is_a_typed_error() {
        assert!(matches!(
            GroundTruthIndex::from_messages([msg("/a", 1, false, shifted(1.0))]),
            Err(TruthError::MissingMesh { .. })
        ));
        let mut p = shifted(1.0);
        p.orientation.w = 2.0;
        assert!(matches!(
            GroundTruthIndex::from_messages([msg("/a", 1, true, p)]),
            Err(TruthError::BadPose { .. })
        ));
        let mut m = msg("/a", 1, true, shifted(1.0));
        m.fx = 0.0;
        assert!(matches!(
            GroundTruthIndex::from_messages([m]),
            Err(TruthError::BadCamera { .. })
        ));
        let mut m = msg("/a", 1, true, shifted(1.0));
        m.triangles[0].vertex_indices[0] = 9;
        assert!(matches!(
            GroundTruthIndex::from_messages([m]),
            Err(TruthError::BadMesh { .. })
        ));
    }
}
