//! `sensor_msgs/PointCloud2` ↔ [`PointCloud`], plus splitting a cloud by a
//! segment-label channel.
//!
//! Decoding ([`decode_pointcloud2`]) accepts any field order and
//! `point_step`, FLOAT32 or FLOAT64 `x`/`y`/`z`, both byte orders, and
//! organised clouds (`height > 1`, rows `row_step` apart). Besides the
//! position it keeps:
//! * `rgb` / `rgba` (packed in a FLOAT32's bits, or UINT32/INT32, as
//!   `0x00RRGGBB` / `0xAARRGGBB`) → channels `r`, `g`, `b` in `[0, 1]`;
//! * UINT8 fields named `r`, `g`, `b` → the same channels, divided by 255;
//! * every other numeric field (`intensity`, `label`, …) → a channel of that
//!   name as `f32` (a field with `count > 1` gives `name_0`, `name_1`, …).
//!
//! Decoding is linear in the message size (measured by the regression test
//! `absurd_field_count_is_rejected_in_linear_time` and the fuzz targets):
//! the fields may expand into at most `min(point_step, MAX_CHANNELS)`
//! channels, those with `count > 1` into at most `MAX_EXPANDED` (both
//! checked before a single name is formatted), and channel names are
//! deduplicated in a hash set. Before this, a 133-byte message with one
//! INT8 field of count 4·10⁹ stalled a compute thread for good.
//!
//! Points with a NaN or infinite coordinate are skipped and counted, never
//! an error. Layout problems (field outside `point_step`, data shorter than
//! `row_step · height`, `row_step < width · point_step`, missing `x`/`y`/`z`,
//! unknown datatypes) and clouds above the configured limits are typed
//! [`PointCloud2Error`]s; no input can make the decoder panic (proptest
//! fuzzing in `tests/wire_pointcloud2.rs`).
//!
//! The encoder ([`encode_pointcloud2`]) writes FLOAT32 `x y z`, a packed
//! FLOAT32 `rgb` when the cloud has colour, and every other channel as a
//! FLOAT32 field of its name, little-endian and unorganised.

use std::collections::BTreeMap;

use indexmap::IndexSet;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::msgs::{Header, PointCloud2, PointField};
use crate::cloud::{Attribute, PointCloud, Vec3};

/// Limits applied to every incoming cloud (config section `wire`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WireConfig {
    /// Largest accepted `width · height` of a PointCloud2.
    pub max_points: usize,
    /// Largest accepted PointCloud2 `data` length, in bytes.
    pub max_bytes: usize,
}

impl Default for WireConfig {
    fn default() -> Self {
        Self {
            max_points: 5_000_000,
            max_bytes: 256 << 20,
        }
    }
}

/// Errors decoding a PointCloud2 into points.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PointCloud2Error {
    /// A coordinate field is absent.
    #[error("PointCloud2 has no `{0}` field")]
    MissingField(&'static str),
    /// A field has a datatype code outside 1..=8 (or a non-float coordinate).
    #[error("PointCloud2 field `{field}` has unsupported datatype {datatype}")]
    UnsupportedDatatype {
        /// Field name.
        field: String,
        /// Datatype code.
        datatype: u8,
    },
    /// A field does not lie inside one point.
    #[error("PointCloud2 field `{field}` (offset {offset}, {size} bytes) exceeds point_step {point_step}")]
    FieldOutsidePoint {
        /// Field name.
        field: String,
        /// Field offset.
        offset: u32,
        /// Field byte size (element size × count).
        size: u64,
        /// Bytes per point.
        point_step: u32,
    },
    /// `row_step` is smaller than a row of points.
    #[error("PointCloud2 row_step {row_step} < width {width} × point_step {point_step}")]
    RowStep {
        /// Declared row step.
        row_step: u32,
        /// Points per row.
        width: u32,
        /// Bytes per point.
        point_step: u32,
    },
    /// `data` is shorter than the layout says.
    #[error("PointCloud2 data has {got} bytes, the layout needs {expected} (row_step × height)")]
    DataLength {
        /// Bytes required.
        expected: u64,
        /// Bytes present.
        got: usize,
    },
    /// More points than allowed.
    #[error("PointCloud2 has {points} points, more than the limit wire.max_points = {max}")]
    TooManyPoints {
        /// width × height.
        points: u64,
        /// Limit.
        max: usize,
    },
    /// More bytes than allowed.
    #[error("PointCloud2 data has {bytes} bytes, more than the limit wire.max_bytes = {max}")]
    TooManyBytes {
        /// Data length.
        bytes: usize,
        /// Limit.
        max: usize,
    },
    /// The fields expand into more channels than `point_step` bytes can
    /// hold, or than [`MAX_CHANNELS`].
    #[error("PointCloud2 fields expand into {channels} channels, more than {max} (the smaller of point_step and {MAX_CHANNELS})")]
    TooManyChannels {
        /// Sum of the `count`s of the non-coordinate fields.
        channels: u64,
        /// The limit applied.
        max: u64,
    },
    /// The fields with `count > 1` expand into more channels together than
    /// [`MAX_EXPANDED`].
    #[error("PointCloud2 fields with count > 1 expand into {channels} channels, more than {MAX_EXPANDED}")]
    TooManyExpanded {
        /// Sum of the `count`s of the non-coordinate fields with count > 1.
        channels: u64,
    },
    /// The CDR bytes are not a valid PointCloud2.
    #[error(transparent)]
    Cdr(#[from] super::WireError),
}

/// A decoded cloud and what was dropped from it.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedCloud {
    /// Stamp and frame of the message.
    pub header: Header,
    /// The finite points and their channels.
    pub cloud: PointCloud,
    /// `width · height` of the message.
    pub points_in: usize,
    /// Points skipped because a coordinate was NaN or infinite.
    pub dropped_non_finite: usize,
}

fn datatype_size(dt: u8) -> Option<usize> {
    Some(match dt {
        PointField::INT8 | PointField::UINT8 => 1,
        PointField::INT16 | PointField::UINT16 => 2,
        PointField::INT32 | PointField::UINT32 | PointField::FLOAT32 => 4,
        PointField::FLOAT64 => 8,
        _ => return None,
    })
}

#[derive(Clone, Copy)]
enum Kind {
    /// Plain numeric value into one channel, times `scale`.
    Value { scale: f32 },
    /// Packed colour into the three colour channels starting at this index.
    PackedRgb,
}

#[derive(Clone, Copy)]
struct Reader {
    offset: usize,
    datatype: u8,
    channel: usize,
    kind: Kind,
}

#[inline]
fn read_bytes<const N: usize>(p: &[u8], off: usize) -> [u8; N] {
    let mut a = [0u8; N];
    if let Some(s) = p.get(off..off + N) {
        a.copy_from_slice(s);
    }
    a
}

#[inline(always)]
fn read_f64(p: &[u8], off: usize, dt: u8, be: bool) -> f64 {
    macro_rules! rd {
        ($t:ty, $n:literal) => {{
            let b = read_bytes::<$n>(p, off);
            if be {
                <$t>::from_be_bytes(b)
            } else {
                <$t>::from_le_bytes(b)
            }
        }};
    }
    match dt {
        PointField::INT8 => f64::from(rd!(i8, 1)),
        PointField::UINT8 => f64::from(rd!(u8, 1)),
        PointField::INT16 => f64::from(rd!(i16, 2)),
        PointField::UINT16 => f64::from(rd!(u16, 2)),
        PointField::INT32 => f64::from(rd!(i32, 4)),
        PointField::UINT32 => f64::from(rd!(u32, 4)),
        PointField::FLOAT32 => f64::from(rd!(f32, 4)),
        _ => rd!(f64, 8),
    }
}

#[inline]
fn read_u32_bits(p: &[u8], off: usize, be: bool) -> u32 {
    let b = read_bytes::<4>(p, off);
    if be {
        u32::from_be_bytes(b)
    } else {
        u32::from_le_bytes(b)
    }
}

/// Most channels one PointCloud2 may expand into (a field with `count` k
/// gives k channels). PCL's widest descriptor (SHOT, 1344 + 9 values) fits.
pub const MAX_CHANNELS: u64 = 1 << 16;

/// Most channels the fields with `count > 1` may expand into together.
/// Each is a formatted name, so this bounds what a small message can ask
/// for: libFuzzer found a 203-byte message (point_step 59,136, no points)
/// whose counts expanded into ~59 k channel names, 279 ms per decode under
/// coverage instrumentation. Under the earlier bound of 4096, the 1 M
/// stable fuzzing pass still found 203-byte messages expanding into 2,577
/// names at 1.4–2.0 ms (best of 5, against the 1 ms floor); a name now
/// costs about 120 ns, so 2048 names stay near 0.25 ms. PCL's widest
/// descriptor (SHOT, 1344 + 9 values) fits. One channel per field needs
/// no such bound: each field costs its bytes in the message.
pub const MAX_EXPANDED: u64 = 2048;

/// The channel names and one reader per channel (the first field claiming a
/// channel name wins, e.g. `rgb` before separate `r`/`g`/`b`).
///
/// Linear in the field list: the expanded element count is checked against
/// `point_step` and [`MAX_CHANNELS`] before any name is formatted, and
/// names are checked for duplicates in a hash set.
fn channel_layout(msg: &PointCloud2) -> Result<(Vec<String>, Vec<Reader>), PointCloud2Error> {
    let expanded: u64 = msg
        .fields
        .iter()
        .filter(|f| !matches!(f.name.as_str(), "x" | "y" | "z"))
        .map(|f| u64::from(f.count))
        .sum();
    let max = MAX_CHANNELS.min(u64::from(msg.point_step));
    if expanded > max {
        return Err(PointCloud2Error::TooManyChannels {
            channels: expanded,
            max,
        });
    }
    let multi: u64 = msg
        .fields
        .iter()
        .filter(|f| f.count > 1 && !matches!(f.name.as_str(), "x" | "y" | "z"))
        .map(|f| u64::from(f.count))
        .sum();
    if multi > MAX_EXPANDED {
        return Err(PointCloud2Error::TooManyExpanded { channels: multi });
    }
    // Insertion-ordered set of the channel names: each name is formatted
    // into one reused buffer and copied in only when it is new (the first
    // field claiming a name wins).
    let capacity = expanded as usize + 3;
    let mut names: IndexSet<String, ahash::RandomState> =
        IndexSet::with_capacity_and_hasher(capacity, ahash::RandomState::new());
    let mut readers: Vec<Reader> = Vec::with_capacity(capacity);
    let mut name = String::new();
    let mut digits = itoa::Buffer::new();
    for f in &msg.fields {
        match f.name.as_str() {
            "x" | "y" | "z" => {}
            _ if f.count == 0 => {}
            "rgb" | "rgba"
                if matches!(
                    f.datatype,
                    PointField::FLOAT32 | PointField::UINT32 | PointField::INT32
                ) =>
            {
                if ["r", "g", "b"].iter().any(|c| names.contains(*c)) {
                    continue;
                }
                readers.push(Reader {
                    offset: f.offset as usize,
                    datatype: f.datatype,
                    channel: names.len(),
                    kind: Kind::PackedRgb,
                });
                names.extend(["r", "g", "b"].map(String::from));
            }
            n => {
                let size = datatype_size(f.datatype).unwrap_or(1);
                let scale = if matches!(n, "r" | "g" | "b") && f.datatype == PointField::UINT8 {
                    1.0 / 255.0
                } else {
                    1.0
                };
                for k in 0..f.count as usize {
                    name.clear();
                    name.push_str(n);
                    if f.count > 1 {
                        name.push('_');
                        name.push_str(digits.format(k));
                    }
                    if names.contains(name.as_str()) {
                        continue;
                    }
                    readers.push(Reader {
                        offset: f.offset as usize + k * size,
                        datatype: f.datatype,
                        channel: names.len(),
                        kind: Kind::Value { scale },
                    });
                    names.insert(name.clone());
                }
            }
        }
    }
    Ok((names.into_iter().collect(), readers))
}

/// Decode a PointCloud2 into a [`PointCloud`] (see the module docs).
///
/// # Errors
/// [`PointCloud2Error`] naming the layout problem or the exceeded limit.
pub fn decode_pointcloud2(
    msg: &PointCloud2,
    limits: &WireConfig,
) -> Result<DecodedCloud, PointCloud2Error> {
    let points_in = u64::from(msg.width) * u64::from(msg.height);
    if points_in > limits.max_points as u64 {
        return Err(PointCloud2Error::TooManyPoints {
            points: points_in,
            max: limits.max_points,
        });
    }
    if msg.data.len() > limits.max_bytes {
        return Err(PointCloud2Error::TooManyBytes {
            bytes: msg.data.len(),
            max: limits.max_bytes,
        });
    }
    let step = msg.point_step as usize;
    // Every field must lie inside one point.
    for f in &msg.fields {
        let size =
            datatype_size(f.datatype).ok_or_else(|| PointCloud2Error::UnsupportedDatatype {
                field: f.name.clone(),
                datatype: f.datatype,
            })?;
        let bytes = size as u64 * u64::from(f.count);
        if u64::from(f.offset) + bytes > u64::from(msg.point_step) {
            return Err(PointCloud2Error::FieldOutsidePoint {
                field: f.name.clone(),
                offset: f.offset,
                size: bytes,
                point_step: msg.point_step,
            });
        }
    }
    let coord = |name: &'static str| -> Result<(usize, u8), PointCloud2Error> {
        let f = msg
            .fields
            .iter()
            .find(|f| f.name == name && f.count >= 1)
            .ok_or(PointCloud2Error::MissingField(name))?;
        if f.datatype != PointField::FLOAT32 && f.datatype != PointField::FLOAT64 {
            return Err(PointCloud2Error::UnsupportedDatatype {
                field: f.name.clone(),
                datatype: f.datatype,
            });
        }
        Ok((f.offset as usize, f.datatype))
    };
    let (ox, tx) = coord("x")?;
    let (oy, ty) = coord("y")?;
    let (oz, tz) = coord("z")?;
    let row_bytes = u64::from(msg.width) * u64::from(msg.point_step);
    if u64::from(msg.row_step) < row_bytes {
        return Err(PointCloud2Error::RowStep {
            row_step: msg.row_step,
            width: msg.width,
            point_step: msg.point_step,
        });
    }
    let expected = u64::from(msg.row_step) * u64::from(msg.height);
    if (msg.data.len() as u64) < expected {
        return Err(PointCloud2Error::DataLength {
            expected,
            got: msg.data.len(),
        });
    }

    let (names, readers) = channel_layout(msg)?;
    let n = points_in as usize;
    let be = msg.is_bigendian;
    let mut points = Vec::with_capacity(n);
    let mut channels: Vec<Vec<f32>> = names.iter().map(|_| Vec::with_capacity(n)).collect();
    let mut dropped = 0usize;
    for row in 0..msg.height as usize {
        let row_start = row * msg.row_step as usize;
        for col in 0..msg.width as usize {
            let start = row_start + col * step;
            let p = msg.data.get(start..start + step).unwrap_or(&[]);
            let v = Vec3::new(
                read_f64(p, ox, tx, be),
                read_f64(p, oy, ty, be),
                read_f64(p, oz, tz, be),
            );
            if !v.iter().all(|c| c.is_finite()) {
                dropped += 1;
                continue;
            }
            points.push(v);
            for r in &readers {
                match r.kind {
                    Kind::Value { scale } => channels[r.channel]
                        .push(read_f64(p, r.offset, r.datatype, be) as f32 * scale),
                    Kind::PackedRgb => {
                        let bits = read_u32_bits(p, r.offset, be);
                        let c = |shift: u32| ((bits >> shift) & 0xff) as f32 / 255.0;
                        channels[r.channel].push(c(16));
                        channels[r.channel + 1].push(c(8));
                        channels[r.channel + 2].push(c(0));
                    }
                }
            }
        }
    }
    let attributes = names
        .into_iter()
        .zip(channels)
        .map(|(name, values)| Attribute { name, values })
        .collect();
    Ok(DecodedCloud {
        header: msg.header.clone(),
        cloud: PointCloud { points, attributes },
        points_in: n,
        dropped_non_finite: dropped,
    })
}

/// Decode a CDR-encoded PointCloud2 (as received from a topic or a bag)
/// into points, rejecting payloads above `limits.max_bytes` (plus 64 KiB
/// for the header and field list) before anything is decoded.
///
/// # Errors
/// [`PointCloud2Error`], including [`PointCloud2Error::Cdr`] for malformed CDR.
pub fn decode_pointcloud2_cdr(
    bytes: &[u8],
    limits: &WireConfig,
) -> Result<DecodedCloud, PointCloud2Error> {
    if bytes.len() > limits.max_bytes.saturating_add(1 << 16) {
        return Err(PointCloud2Error::TooManyBytes {
            bytes: bytes.len(),
            max: limits.max_bytes,
        });
    }
    let msg: PointCloud2 = super::decode(bytes)?;
    decode_pointcloud2(&msg, limits)
}

/// Encode a cloud as an unorganised little-endian PointCloud2: FLOAT32
/// `x y z`, a packed FLOAT32 `rgb` (`0x00RRGGBB` in the float's bits) when
/// the cloud has `r`, `g`, `b` channels, and every other channel as a FLOAT32
/// field of its name.
pub fn encode_pointcloud2(cloud: &PointCloud, header: Header) -> PointCloud2 {
    let colour = match (
        cloud.attribute("r"),
        cloud.attribute("g"),
        cloud.attribute("b"),
    ) {
        (Some(r), Some(g), Some(b)) => Some((r, g, b)),
        _ => None,
    };
    let extras: Vec<&Attribute> = cloud
        .attributes
        .iter()
        .filter(|a| !(colour.is_some() && matches!(a.name.as_str(), "r" | "g" | "b")))
        .filter(|a| a.values.len() == cloud.points.len())
        .collect();
    let mut fields = vec![
        field("x", 0, PointField::FLOAT32),
        field("y", 4, PointField::FLOAT32),
        field("z", 8, PointField::FLOAT32),
    ];
    let mut offset = 12u32;
    if colour.is_some() {
        fields.push(field("rgb", offset, PointField::FLOAT32));
        offset += 4;
    }
    for a in &extras {
        fields.push(field(&a.name, offset, PointField::FLOAT32));
        offset += 4;
    }
    let point_step = offset;
    let n = cloud.points.len();
    let mut data = Vec::with_capacity(n * point_step as usize);
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u32;
    for (i, p) in cloud.points.iter().enumerate() {
        for c in [p.x, p.y, p.z] {
            data.extend_from_slice(&(c as f32).to_le_bytes());
        }
        if let Some((r, g, b)) = colour {
            let bits = (q(r[i]) << 16) | (q(g[i]) << 8) | q(b[i]);
            data.extend_from_slice(&bits.to_le_bytes());
        }
        for a in &extras {
            data.extend_from_slice(&a.values[i].to_le_bytes());
        }
    }
    let is_dense = cloud.points.iter().all(|p| p.iter().all(|c| c.is_finite()));
    PointCloud2 {
        header,
        height: 1,
        width: n as u32,
        fields,
        is_bigendian: false,
        point_step,
        row_step: point_step * n as u32,
        data,
        is_dense,
    }
}

fn field(name: &str, offset: u32, datatype: u8) -> PointField {
    PointField::new(name, offset, datatype, 1)
}

/// Split a cloud by the integer value of channel `label` (rounded), for
/// per-(topic, label) streams. The label channel is removed from the parts;
/// points with a non-finite label are left out. Returns `None` when the
/// cloud has no such channel.
pub fn split_by_label(cloud: &PointCloud, label: &str) -> Option<BTreeMap<i64, PointCloud>> {
    let labels = cloud.attribute(label)?;
    let mut groups: BTreeMap<i64, Vec<usize>> = BTreeMap::new();
    for (i, &l) in labels.iter().enumerate() {
        if l.is_finite() {
            groups.entry(l.round() as i64).or_default().push(i);
        }
    }
    Some(
        groups
            .into_iter()
            .map(|(l, idx)| {
                let mut part = cloud.select(&idx);
                part.attributes.retain(|a| a.name != label);
                (l, part)
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xyz_cloud(be: bool, f64xyz: bool) -> PointCloud2 {
        // Fields deliberately out of order, with padding and a uint16 label.
        let (dt, sz) = if f64xyz {
            (PointField::FLOAT64, 8u32)
        } else {
            (PointField::FLOAT32, 4u32)
        };
        let step = 4 + 3 * sz + 2 + 2;
        let pts = [[1.0, 2.0, 3.0], [f64::NAN, 0.0, 0.0], [-1.5, 0.25, 8.0]];
        let mut data = Vec::new();
        for (i, p) in pts.iter().enumerate() {
            let mut buf = vec![0u8; step as usize];
            let put = |buf: &mut Vec<u8>, off: usize, v: f64| {
                let b: Vec<u8> = match (f64xyz, be) {
                    (true, true) => v.to_be_bytes().to_vec(),
                    (true, false) => v.to_le_bytes().to_vec(),
                    (false, true) => (v as f32).to_be_bytes().to_vec(),
                    (false, false) => (v as f32).to_le_bytes().to_vec(),
                };
                buf[off..off + b.len()].copy_from_slice(&b);
            };
            put(&mut buf, 4 + 2 * sz as usize, p[0]);
            put(&mut buf, 4, p[1]);
            put(&mut buf, 4 + sz as usize, p[2]);
            let lab = (10 + i as u16).to_le_bytes();
            let lab = if be { [lab[1], lab[0]] } else { lab };
            buf[(4 + 3 * sz) as usize..(4 + 3 * sz + 2) as usize].copy_from_slice(&lab);
            buf[0..4].copy_from_slice(&if be {
                0x00ff8000u32.to_be_bytes()
            } else {
                0x00ff8000u32.to_le_bytes()
            });
            data.extend(buf);
        }
        PointCloud2 {
            header: Header::default(),
            height: 1,
            width: 3,
            fields: vec![
                field("rgb", 0, PointField::UINT32),
                field("y", 4, dt),
                field("z", 4 + sz, dt),
                field("x", 4 + 2 * sz, dt),
                field("label", 4 + 3 * sz, PointField::UINT16),
            ],
            is_bigendian: be,
            point_step: step,
            row_step: 3 * step,
            data,
            is_dense: false,
        }
    }

    #[test]
    fn decodes_any_order_both_endians_and_widths() {
        for be in [false, true] {
            for f64xyz in [false, true] {
                let d = decode_pointcloud2(&xyz_cloud(be, f64xyz), &WireConfig::default()).unwrap();
                assert_eq!(d.points_in, 3);
                assert_eq!(d.dropped_non_finite, 1);
                assert_eq!(
                    d.cloud.points,
                    vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.5, 0.25, 8.0)]
                );
                assert_eq!(d.cloud.attribute("label").unwrap(), &[10.0, 12.0]);
                assert_eq!(d.cloud.attribute("r").unwrap(), &[1.0, 1.0]);
                assert!((d.cloud.attribute("g").unwrap()[0] - 128.0 / 255.0).abs() < 1e-6);
                assert_eq!(d.cloud.attribute("b").unwrap(), &[0.0, 0.0]);
            }
        }
    }

    #[test]
    fn layout_errors_are_typed() {
        let lim = WireConfig::default();
        let mut m = xyz_cloud(false, false);
        m.fields[4].offset = m.point_step - 1;
        assert!(matches!(
            decode_pointcloud2(&m, &lim),
            Err(PointCloud2Error::FieldOutsidePoint { .. })
        ));
        let mut m = xyz_cloud(false, false);
        m.data.pop();
        assert!(matches!(
            decode_pointcloud2(&m, &lim),
            Err(PointCloud2Error::DataLength { .. })
        ));
        let mut m = xyz_cloud(false, false);
        m.row_step -= 1;
        assert!(matches!(
            decode_pointcloud2(&m, &lim),
            Err(PointCloud2Error::RowStep { .. })
        ));
        let mut m = xyz_cloud(false, false);
        m.fields.retain(|f| f.name != "z");
        assert_eq!(
            decode_pointcloud2(&m, &lim),
            Err(PointCloud2Error::MissingField("z"))
        );
        let mut m = xyz_cloud(false, false);
        m.fields[4].datatype = 9;
        assert!(matches!(
            decode_pointcloud2(&m, &lim),
            Err(PointCloud2Error::UnsupportedDatatype { .. })
        ));
        let small = WireConfig {
            max_points: 2,
            max_bytes: 1 << 20,
        };
        assert!(matches!(
            decode_pointcloud2(&xyz_cloud(false, false), &small),
            Err(PointCloud2Error::TooManyPoints { points: 3, max: 2 })
        ));
        let small = WireConfig {
            max_points: 10,
            max_bytes: 10,
        };
        assert!(matches!(
            decode_pointcloud2(&xyz_cloud(false, false), &small),
            Err(PointCloud2Error::TooManyBytes { .. })
        ));
    }

    /// The 133-byte message of issue 22: x y z plus one INT8 field of count
    /// 4·10⁹, point_step 4·10⁹ + 12, no points. It passes every size check;
    /// the old decoder then formatted and searched 4·10⁹ names.
    fn poisoned(count: u32) -> PointCloud2 {
        let mut fields = vec![
            field("x", 0, PointField::FLOAT32),
            field("y", 4, PointField::FLOAT32),
            field("z", 8, PointField::FLOAT32),
        ];
        fields.push(PointField {
            name: "i".into(),
            offset: 12,
            datatype: PointField::INT8,
            count,
        });
        PointCloud2 {
            fields,
            point_step: count.saturating_add(12),
            ..Default::default()
        }
    }

    #[test]
    fn absurd_field_count_is_rejected_in_linear_time() {
        let m = poisoned(4_000_000_000);
        let bytes = super::super::encode(&m).unwrap();
        assert!(bytes.len() <= 140, "{} bytes", bytes.len());
        let e = decode_pointcloud2_cdr(&bytes, &WireConfig::default()).unwrap_err();
        assert_eq!(
            e,
            PointCloud2Error::TooManyChannels {
                channels: 4_000_000_000,
                max: MAX_CHANNELS
            }
        );
        // 10⁵ elements (45 s in `replay` before): rejected as well.
        assert!(matches!(
            decode_pointcloud2(&poisoned(100_000), &WireConfig::default()),
            Err(PointCloud2Error::TooManyChannels { .. })
        ));
        // More channels than point_step bytes: only overlapping fields can do that.
        let mut m = poisoned(8);
        for name in ["j", "k"] {
            m.fields.push(PointField {
                name: name.into(),
                offset: 12,
                datatype: PointField::INT8,
                count: 8,
            });
        }
        assert_eq!(
            decode_pointcloud2(&m, &WireConfig::default()),
            Err(PointCloud2Error::TooManyChannels {
                channels: 24,
                max: 20
            })
        );
    }

    /// Found by libFuzzer: a message of a few hundred bytes whose field
    /// counts fit its large point_step (59,136) expanded into ~59 k channel
    /// names (279 ms per decode under coverage instrumentation).
    #[test]
    fn a_small_message_cannot_ask_for_many_expanded_channels() {
        let mut m = poisoned(50_000);
        m.point_step = 60_000;
        let bytes = super::super::encode(&m).unwrap();
        assert!(bytes.len() <= 140, "{} bytes", bytes.len());
        assert_eq!(
            decode_pointcloud2_cdr(&bytes, &WireConfig::default()).unwrap_err(),
            PointCloud2Error::TooManyExpanded { channels: 50_000 }
        );
        // The 1 M stable fuzzing pass's slow input: 203 bytes whose counts
        // 17 + 2560 expanded into 2,577 names (1.4–2.0 ms a decode).
        let mut m = poisoned(17);
        m.fields.push(PointField {
            name: "label".into(),
            offset: 29,
            datatype: PointField::FLOAT32,
            count: 2560,
        });
        m.point_step = 29 + 4 * 2560;
        let bytes = super::super::encode(&m).unwrap();
        assert!(bytes.len() <= 160, "{} bytes", bytes.len());
        assert_eq!(
            decode_pointcloud2_cdr(&bytes, &WireConfig::default()).unwrap_err(),
            PointCloud2Error::TooManyExpanded { channels: 2577 }
        );
        // A SHOT descriptor (1344 + 9 values) still decodes.
        let mut m = poisoned(1353);
        m.height = 1;
        m.width = 1;
        m.row_step = m.point_step;
        m.data = vec![0; m.point_step as usize];
        let c = decode_pointcloud2(&m, &WireConfig::default()).unwrap();
        assert_eq!(c.cloud.attributes.len(), 1353);
    }

    #[test]
    fn forty_thousand_fields_decode_with_every_channel() {
        // 4.2 s before (a linear name search per field); one point, 40 k UINT8 fields.
        let n = 40_000u32;
        let mut fields = vec![
            field("x", 0, PointField::FLOAT32),
            field("y", 4, PointField::FLOAT32),
            field("z", 8, PointField::FLOAT32),
        ];
        fields.extend((0..n).map(|k| field(&format!("f{k}"), 12 + k, PointField::UINT8)));
        let mut data = vec![0u8; 12 + n as usize];
        for k in 0..n as usize {
            data[12 + k] = (k % 251) as u8;
        }
        let m = PointCloud2 {
            height: 1,
            width: 1,
            fields,
            point_step: 12 + n,
            row_step: 12 + n,
            data,
            ..Default::default()
        };
        let d = decode_pointcloud2(&m, &WireConfig::default()).unwrap();
        assert_eq!(d.cloud.attributes.len(), n as usize);
        assert_eq!(
            d.cloud.attribute("f39999").unwrap(),
            &[(39_999 % 251) as f32]
        );
    }

    #[test]
    fn organised_rows_with_padding() {
        // 2×2 organised cloud, row_step has 4 padding bytes after each row.
        let step = 12u32;
        let row_step = 2 * step + 4;
        let mut data = Vec::new();
        for r in 0..2 {
            for c in 0..2 {
                for v in [c as f32, r as f32, 1.0f32] {
                    data.extend_from_slice(&v.to_le_bytes());
                }
            }
            data.extend_from_slice(&[0xAB; 4]);
        }
        let m = PointCloud2 {
            height: 2,
            width: 2,
            fields: vec![
                field("x", 0, PointField::FLOAT32),
                field("y", 4, PointField::FLOAT32),
                field("z", 8, PointField::FLOAT32),
            ],
            point_step: step,
            row_step,
            data,
            ..Default::default()
        };
        let d = decode_pointcloud2(&m, &WireConfig::default()).unwrap();
        assert_eq!(d.cloud.points[3], Vec3::new(1.0, 1.0, 1.0));
        assert_eq!(d.cloud.points[2], Vec3::new(0.0, 1.0, 1.0));
    }

    #[test]
    fn encode_then_decode_round_trips_and_splits() {
        let mut c = PointCloud::from_points(vec![
            Vec3::new(0.5, 1.0, -2.0),
            Vec3::new(3.0, 4.0, 5.0),
            Vec3::new(6.0, 7.0, 8.0),
        ]);
        c.set_attribute("r", vec![1.0, 0.0, 0.2]).unwrap();
        c.set_attribute("g", vec![0.0, 1.0, 0.4]).unwrap();
        c.set_attribute("b", vec![0.0, 0.0, 0.6]).unwrap();
        c.set_attribute("label", vec![3.0, 1.0, 3.0]).unwrap();
        let m = encode_pointcloud2(&c, Header::default());
        assert_eq!(m.point_step, 20);
        let d = decode_pointcloud2(&m, &WireConfig::default()).unwrap();
        assert_eq!(d.cloud.points, c.points);
        for ch in ["r", "g", "b"] {
            for (a, b) in d
                .cloud
                .attribute(ch)
                .unwrap()
                .iter()
                .zip(c.attribute(ch).unwrap())
            {
                assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6, "{ch}: {a} vs {b}");
            }
        }
        let parts = split_by_label(&d.cloud, "label").unwrap();
        assert_eq!(parts.keys().copied().collect::<Vec<_>>(), vec![1, 3]);
        assert_eq!(parts[&3].len(), 2);
        assert_eq!(parts[&1].points[0], Vec3::new(3.0, 4.0, 5.0));
        assert!(parts[&3].attribute("label").is_none());
        assert!(parts[&3].attribute("r").is_some());
        assert!(split_by_label(&d.cloud, "nope").is_none());
        // Through CDR, with the payload limit.
        let bytes = super::super::encode(&m).unwrap();
        let d2 = decode_pointcloud2_cdr(&bytes, &WireConfig::default()).unwrap();
        assert_eq!(d2, d);
        let tiny = WireConfig {
            max_points: 10,
            max_bytes: 0,
        };
        let big = vec![0u8; (1 << 16) + 1];
        assert!(matches!(
            decode_pointcloud2_cdr(&big, &tiny),
            Err(PointCloud2Error::TooManyBytes { .. })
        ));
        assert!(matches!(
            decode_pointcloud2_cdr(&bytes[..10], &tiny),
            Err(PointCloud2Error::Cdr(_))
        ));
    }
}
