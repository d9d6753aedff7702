//! ROS 2 wire format: message types, CDR encoding and decoding, type hashes,
//! and PointCloud2 conversion.
//!
//! * [`msgs`]: serde structs for the messages sepmem speaks (PointCloud2,
//!   Marker/MarkerArray, shape_msgs/Mesh, DiagnosticArray, and sepmem's own
//!   `sepmem_msgs/SurfaceMesh` and `FrameDiagnostics` from `msg/`), each with
//!   its type name and hard-coded RIHS01 hash ([`msgs::RosMessage`]).
//! * [`msgdef`]: the `.msg` texts, a `.msg` parser, the RIHS01 algorithm,
//!   rosbag2's concatenated definitions for MCAP schemas, and a structural
//!   CDR checker run before every decode.
//! * [`pointcloud2`]: PointCloud2 ↔ [`crate::cloud::PointCloud`].
//! * [`convert`]: [`crate::mesh::TriMesh`] ↔ `shape_msgs/Mesh`, TRIANGLE_LIST
//!   markers and `SurfaceMesh` geometry.
//!
//! Encoding is XCDR1 little-endian with the 4-byte encapsulation header
//! `00 01 00 00` (what rmw_zenoh, rosbag2 and the DDS bridges carry);
//! decoding accepts both byte orders and ignores trailing bytes (DDS may
//! append alignment padding). Strings are written as UTF-8 bytes plus a NUL:
//! the `cdr` crate 0.2.4 does not restrict `&str` to ASCII (only Rust `char`,
//! which no ROS type uses here since ROS `char` maps to `u8`), and the
//! fixture `pointcloud2_utf8_organised.cdr` made by Python `rosbags` checks
//! that a non-ASCII frame id is byte-exact. Invalid UTF-8 in received strings
//! is a typed [`WireError::Decode`].

pub mod convert;
pub mod msgdef;
pub mod msgs;
pub mod pointcloud2;

pub use msgs::RosMessage;

use thiserror::Error;

/// Errors of the wire layer (message definitions and CDR).
#[derive(Debug, Error, Clone, PartialEq)]
pub enum WireError {
    /// A `.msg` text does not parse.
    #[error("message definition {type_name}, line {line}: {problem}")]
    MsgDef {
        /// Type being parsed.
        type_name: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        problem: String,
    },
    /// A type is not in sepmem's registry.
    #[error("unknown message type `{0}` (not in sepmem's registry)")]
    UnknownType(String),
    /// The 4-byte encapsulation header is not plain CDR (BE or LE).
    #[error(
        "CDR encapsulation header {header:02x?} is not CDR_BE/CDR_LE (XCDR2 is not supported)"
    )]
    BadEncapsulation {
        /// The header bytes.
        header: [u8; 4],
    },
    /// A field runs past the end of the bytes.
    #[error("{type_name}: field `{field}` at byte {offset} needs {need} bytes, {have} left")]
    Truncated {
        /// Message type.
        type_name: String,
        /// Dotted field path.
        field: String,
        /// Byte offset (from the start, header included).
        offset: usize,
        /// Bytes (or elements) the field announces.
        need: usize,
        /// Bytes left.
        have: usize,
    },
    /// The `cdr` crate could not encode the message.
    #[error("cannot encode {type_name} as CDR: {message}")]
    Encode {
        /// Message type.
        type_name: String,
        /// `cdr` error text.
        message: String,
    },
    /// The `cdr` crate could not decode the message (bad bool, invalid UTF-8, …).
    #[error("cannot decode {type_name} from CDR: {message}")]
    Decode {
        /// Message type.
        type_name: String,
        /// `cdr` error text.
        message: String,
    },
}

/// Encode `msg` as CDR little-endian with the encapsulation header, into
/// `buf` (cleared first; reuse it across messages to avoid reallocations).
///
/// # Errors
/// [`WireError::Encode`] when a field cannot be represented (e.g. a sequence
/// longer than `u32::MAX`).
pub fn encode_into<M: RosMessage>(msg: &M, buf: &mut Vec<u8>) -> Result<(), WireError> {
    buf.clear();
    // One allocation of the exact size: growing by doubling left up to
    // twice the message in every encoded output a publisher cache holds,
    // and a chain of freed halves behind each (heap fragmentation).
    let size = usize::try_from(cdr::calc_serialized_size(msg)).unwrap_or(0);
    buf.reserve_exact(size);
    cdr::serialize_into::<_, _, _, cdr::CdrLe>(&mut *buf, msg, cdr::Infinite).map_err(|e| {
        WireError::Encode {
            type_name: M::TYPE_NAME.to_string(),
            message: e.to_string(),
        }
    })
}

/// Encode `msg` as CDR little-endian with the encapsulation header.
///
/// # Errors
/// See [`encode_into`].
pub fn encode<M: RosMessage>(msg: &M) -> Result<Vec<u8>, WireError> {
    let mut buf = Vec::new();
    encode_into(msg, &mut buf)?;
    Ok(buf)
}

/// Decode CDR `bytes` (with encapsulation header, either byte order) as `M`.
///
/// The bytes are first walked against `M`'s definition, so forged lengths
/// fail with [`WireError::Truncated`] before anything is allocated.
///
/// # Errors
/// [`WireError::BadEncapsulation`], [`WireError::Truncated`] or [`WireError::Decode`].
pub fn decode<M: RosMessage>(bytes: &[u8]) -> Result<M, WireError> {
    msgdef::check_cdr(M::TYPE_NAME, bytes)?;
    cdr::deserialize::<M>(bytes).map_err(|e| WireError::Decode {
        type_name: M::TYPE_NAME.to_string(),
        message: e.to_string(),
    })
}

/// The DDS type name rmw implementations use in keys:
/// `sensor_msgs/msg/PointCloud2` → `sensor_msgs::msg::dds_::PointCloud2_`.
pub fn dds_type_name(type_name: &str) -> String {
    match type_name.rsplit_once('/') {
        Some((pkg_kind, name)) => format!("{}::dds_::{name}_", pkg_kind.replace('/', "::")),
        None => format!("{type_name}_"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_encoded_message_holds_no_spare_capacity() {
        use msgs::{Header, Point, SurfaceMesh};
        let mesh = SurfaceMesh {
            header: Header::default(),
            stream_id: "/a/points#7".into(),
            vertices: (0..5000)
                .map(|i| Point {
                    x: f64::from(i),
                    y: 0.5,
                    z: -1.0,
                })
                .collect(),
            vertex_separability: vec![0.25; 5000],
            start_reason: "tracked".into(),
            ..SurfaceMesh::default()
        };
        let bytes = encode(&mesh).unwrap();
        // Odd-length strings before 8-byte-aligned doubles: the size
        // includes the padding, so the one allocation is exact.
        assert_eq!(bytes.capacity(), bytes.len());
        assert_eq!(decode::<SurfaceMesh>(&bytes).unwrap(), mesh);
    }

    #[test]
    fn dds_names() {
        assert_eq!(
            dds_type_name("sensor_msgs/msg/PointCloud2"),
            "sensor_msgs::msg::dds_::PointCloud2_"
        );
    }

    #[test]
    fn header_round_trip_and_truncation() {
        let h = msgs::Header {
            stamp: msgs::Time { sec: 3, nanosec: 4 },
            frame_id: "map".into(),
        };
        let b = encode(&h).unwrap();
        assert_eq!(&b[..4], &[0, 1, 0, 0]);
        assert_eq!(decode::<msgs::Header>(&b).unwrap(), h);
        for cut in 0..b.len() - 1 {
            assert!(decode::<msgs::Header>(&b[..cut]).is_err(), "cut {cut}");
        }
    }
}
