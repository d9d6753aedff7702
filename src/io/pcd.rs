//! PCL PCD reader (`DATA ascii`, `binary` and `binary_compressed`).
//!
//! Header keys: `VERSION`, `FIELDS`, `SIZE`, `TYPE` (`I`, `U`, `F`),
//! `COUNT` (optional, default 1), `WIDTH`, `HEIGHT`, `VIEWPOINT` (ignored),
//! `POINTS` (optional, default `WIDTH·HEIGHT`) and `DATA`. `binary` data is
//! an array of little-endian point records; `binary_compressed` data is two
//! little-endian `u32` (compressed and uncompressed size) followed by an
//! LZF block which decompresses to the fields stored one after the other
//! (structure of arrays: all `x`, then all `y`, …).
//!
//! Fields: `x y z` are the position; a packed `rgb`/`rgba` field (`F` 4 bytes
//! holding the bits, or `U` 4) is split into the channels `r`, `g`, `b`
//! in `[0, 1]` from `0xAARRGGBB`; every other single-element field (e.g.
//! `intensity`, `label`, `normal_x`, `curvature`) becomes a channel of its
//! own name. Fields with `COUNT` > 1 (descriptors) and padding fields `_`
//! are skipped; `COUNT 0` is a typed header error (it panicked before: 3 of
//! 300 random mutations of a binary PCD hit it). Organised clouds (`HEIGHT` > 1) are flattened row by row;
//! their NaN points are dropped and counted.

use super::{finish_cloud, read_bytes, IoError, LoadedCloud};
use crate::cloud::{Attribute, PointCloud, Vec3};
use std::collections::HashSet;
use std::path::Path;

#[derive(Debug, Clone)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

#[derive(Debug)]
struct Header {
    fields: Vec<Field>,
    width: usize,
    height: usize,
    points: usize,
    data: Data,
    data_start: usize,
    header_lines: usize,
}

fn bad(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::BadHeader {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, IoError> {
    let mut pos = 0;
    let mut fields: Vec<String> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let mut kinds: Vec<u8> = Vec::new();
    let mut counts: Option<Vec<usize>> = None;
    let (mut width, mut height, mut points) = (None, None, None);
    let mut lineno = 0;
    let (data, data_start) = loop {
        if pos >= bytes.len() {
            return Err(bad(path, "no DATA line"));
        }
        let nl = bytes[pos..].iter().position(|&b| b == b'\n');
        let end = nl.map_or(bytes.len(), |n| pos + n);
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| bad(path, format!("header line {} is not text", lineno + 1)))?
            .trim();
        pos = nl.map_or(bytes.len(), |n| pos + n + 1);
        lineno += 1;
        if lineno > 10_000 {
            return Err(bad(path, "no DATA line in the first 10000 lines"));
        }
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tok = line.split_whitespace();
        let Some(kw) = tok.next() else { continue };
        let rest: Vec<&str> = tok.collect();
        let ulenlist = |what: &str| -> Result<Vec<usize>, IoError> {
            rest.iter()
                .map(|t| {
                    t.parse::<usize>()
                        .map_err(|_| bad(path, format!("line {lineno}: bad {what} value {t:?}")))
                })
                .collect()
        };
        let one = |what: &str| -> Result<usize, IoError> {
            match rest.as_slice() {
                [v] => v
                    .parse()
                    .map_err(|_| bad(path, format!("line {lineno}: bad {what} {v:?}"))),
                _ => Err(bad(path, format!("line {lineno}: {what} needs one value"))),
            }
        };
        match kw.to_ascii_uppercase().as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => fields = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => sizes = ulenlist("SIZE")?,
            "TYPE" => {
                kinds = rest
                    .iter()
                    .map(|t| match *t {
                        "I" | "i" => Ok(b'I'),
                        "U" | "u" => Ok(b'U'),
                        "F" | "f" => Ok(b'F'),
                        other => Err(bad(path, format!("line {lineno}: bad TYPE {other:?}"))),
                    })
                    .collect::<Result<_, _>>()?
            }
            "COUNT" => counts = Some(ulenlist("COUNT")?),
            "WIDTH" => width = Some(one("WIDTH")?),
            "HEIGHT" => height = Some(one("HEIGHT")?),
            "POINTS" => points = Some(one("POINTS")?),
            "DATA" => {
                let d = match rest.first().map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => Data::Ascii,
                    Some("binary") => Data::Binary,
                    Some("binary_compressed") => Data::Compressed,
                    other => {
                        return Err(IoError::Unsupported {
                            path: path.to_path_buf(),
                            what: format!("DATA {other:?}"),
                        })
                    }
                };
                break (d, pos);
            }
            other => {
                return Err(bad(
                    path,
                    format!("line {lineno}: unknown keyword {other:?}"),
                ))
            }
        }
    };
    if fields.is_empty() {
        return Err(bad(path, "no FIELDS"));
    }
    let nf = fields.len();
    let counts = counts.unwrap_or_else(|| vec![1; nf]);
    // Ascii files may omit both SIZE and TYPE: default to float.
    if data == Data::Ascii && sizes.is_empty() && kinds.is_empty() {
        sizes = vec![4; nf];
        kinds = vec![b'F'; nf];
    }
    // Every list must then match FIELDS (an ascii header with a short COUNT
    // and no SIZE/TYPE indexed past its end: found by the fuzz pass).
    for (what, n) in [
        ("SIZE", sizes.len()),
        ("TYPE", kinds.len()),
        ("COUNT", counts.len()),
    ] {
        if n != nf {
            return Err(IoError::CountMismatch {
                path: path.to_path_buf(),
                what: format!("{what} entries for the {nf} FIELDS"),
                expected: nf,
                found: n,
            });
        }
    }
    let mut out = Vec::with_capacity(nf);
    for i in 0..nf {
        let (size, kind) = (sizes[i], kinds[i]);
        let ok = match kind {
            b'F' => matches!(size, 4 | 8),
            _ => matches!(size, 1 | 2 | 4 | 8),
        };
        if !ok {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                what: format!(
                    "field `{}` of TYPE {} and SIZE {size}",
                    fields[i], kind as char
                ),
            });
        }
        // COUNT 0 would make a field occupy no bytes yet be read (a panic before).
        if counts[i] == 0 || counts[i] > 100_000 {
            return Err(bad(
                path,
                format!(
                    "field `{}` has COUNT {} (1 to 100000 allowed)",
                    fields[i], counts[i]
                ),
            ));
        }
        out.push(Field {
            name: fields[i].clone(),
            size,
            kind,
            count: counts[i],
        });
    }
    for c in ["x", "y", "z"] {
        if !out.iter().any(|f| f.name == c && f.count == 1) {
            return Err(bad(path, format!("no single-valued field `{c}`")));
        }
    }
    let width = width.ok_or_else(|| bad(path, "no WIDTH"))?;
    let height = height.unwrap_or(1);
    let wh = width
        .checked_mul(height)
        .ok_or_else(|| bad(path, "WIDTH·HEIGHT overflows"))?;
    let points = points.unwrap_or(wh);
    if points != wh {
        return Err(IoError::CountMismatch {
            path: path.to_path_buf(),
            what: "POINTS vs WIDTH·HEIGHT".into(),
            expected: wh,
            found: points,
        });
    }
    Ok(Header {
        fields: out,
        width,
        height,
        points,
        data,
        data_start,
        header_lines: lineno,
    })
}

/// How a field is stored into the cloud.
#[derive(Clone, Copy)]
enum Role {
    Pos(usize),
    Rgb,
    Channel(usize),
    Skip,
}

/// Decode one little-endian value of a field from `b` (exactly `size` bytes).
fn value(b: &[u8], kind: u8, size: usize) -> f64 {
    let mut a = [0u8; 8];
    a[..size].copy_from_slice(&b[..size]);
    match (kind, size) {
        (b'F', 4) => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        (b'F', _) => f64::from_le_bytes(a),
        (b'I', 1) => a[0] as i8 as f64,
        (b'I', 2) => i16::from_le_bytes([a[0], a[1]]) as f64,
        (b'I', 4) => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        (b'I', _) => i64::from_le_bytes(a) as f64,
        (_, _) => u64::from_le_bytes(a) as f64,
    }
}

/// Raw 32 bits of a packed colour field.
fn packed(b: &[u8]) -> u32 {
    let mut a = [0u8; 4];
    let n = b.len().min(4);
    a[..n].copy_from_slice(&b[..n]);
    u32::from_le_bytes(a)
}

struct Builder {
    points: Vec<Vec3>,
    channels: Vec<Attribute>,
    rgb: Option<[Vec<f32>; 3]>,
    roles: Vec<Role>,
}

impl Builder {
    fn new(fields: &[Field], capacity: usize) -> Self {
        let mut channels = Vec::new();
        // Names already given a channel: a hash set keeps 40 k fields linear.
        let mut seen: HashSet<&str> = HashSet::new();
        let mut rgb = None;
        let roles = fields
            .iter()
            .map(|f| match f.name.as_str() {
                "x" if f.count == 1 => Role::Pos(0),
                "y" if f.count == 1 => Role::Pos(1),
                "z" if f.count == 1 => Role::Pos(2),
                "rgb" | "rgba" if f.count == 1 && f.size == 4 && rgb.is_none() => {
                    rgb = Some([
                        Vec::with_capacity(capacity),
                        Vec::with_capacity(capacity),
                        Vec::with_capacity(capacity),
                    ]);
                    Role::Rgb
                }
                "_" => Role::Skip,
                n if f.count == 1 && seen.insert(n) => {
                    channels.push(Attribute {
                        name: n.to_string(),
                        values: Vec::with_capacity(capacity),
                    });
                    Role::Channel(channels.len() - 1)
                }
                _ => Role::Skip,
            })
            .collect();
        Self {
            points: Vec::with_capacity(capacity),
            channels,
            rgb,
            roles,
        }
    }

    fn push_rgb(&mut self, v: u32) {
        if let Some(rgb) = &mut self.rgb {
            rgb[0].push(((v >> 16) & 0xff) as f32 / 255.0);
            rgb[1].push(((v >> 8) & 0xff) as f32 / 255.0);
            rgb[2].push((v & 0xff) as f32 / 255.0);
        }
    }

    fn finish(self, width: usize, height: usize) -> LoadedCloud {
        let mut attributes = Vec::new();
        if let Some([r, g, b]) = self.rgb {
            for (n, v) in [("r", r), ("g", g), ("b", b)] {
                attributes.push(Attribute {
                    name: n.into(),
                    values: v,
                });
            }
        }
        attributes.extend(self.channels);
        finish_cloud(
            PointCloud {
                points: self.points,
                attributes,
            },
            width,
            height,
        )
    }
}

/// Parse PCD bytes; `path` names the source in errors.
///
/// # Errors
/// [`IoError`] for a malformed, truncated or unsupported file.
pub fn parse_cloud(bytes: &[u8], path: &Path) -> Result<LoadedCloud, IoError> {
    let h = parse_header(path, bytes)?;
    let body = &bytes[h.data_start.min(bytes.len())..];
    let record: usize = h.fields.iter().map(|f| f.size * f.count).sum();
    let truncated = |what: String| IoError::Truncated {
        path: path.to_path_buf(),
        what,
    };
    match h.data {
        Data::Ascii => {
            // Never trust POINTS for the allocation: each point needs ≥ 2 bytes per value.
            let mut b = Builder::new(&h.fields, h.points.min(body.len() / 2));
            let values_per_point: usize = h.fields.iter().map(|f| f.count).sum();
            let text = std::str::from_utf8(body).map_err(|e| IoError::Parse {
                path: path.to_path_buf(),
                line: 0,
                reason: format!("ascii data is not text ({e})"),
            })?;
            let mut tokens: Vec<&str> = Vec::with_capacity(values_per_point);
            let mut read = 0;
            let roles = b.roles.clone();
            for (i, line) in text.lines().enumerate() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') {
                    continue;
                }
                if read == h.points {
                    return Err(IoError::CountMismatch {
                        path: path.to_path_buf(),
                        what: "data lines vs POINTS".into(),
                        expected: h.points,
                        found: read + 1,
                    });
                }
                let lineno = h.header_lines + i + 1;
                tokens.clear();
                tokens.extend(line.split_whitespace());
                if tokens.len() != values_per_point {
                    return Err(IoError::Parse {
                        path: path.to_path_buf(),
                        line: lineno,
                        reason: format!("{} values, expected {values_per_point}", tokens.len()),
                    });
                }
                let mut p = Vec3::zeros();
                let mut k = 0;
                for (f, &role) in h.fields.iter().zip(&roles) {
                    let t = tokens[k];
                    k += f.count;
                    let parse_err = || IoError::Parse {
                        path: path.to_path_buf(),
                        line: lineno,
                        reason: format!("field `{}`: cannot parse {t:?}", f.name),
                    };
                    match role {
                        Role::Skip => {}
                        Role::Rgb => {
                            // Packed colour: float bits (F) or integer (U/I).
                            let bits = if f.kind == b'F' {
                                t.parse::<f32>().map_err(|_| parse_err())?.to_bits()
                            } else {
                                t.parse::<f64>().map_err(|_| parse_err())? as u32
                            };
                            b.push_rgb(bits);
                        }
                        Role::Pos(c) => p[c] = t.parse::<f64>().map_err(|_| parse_err())?,
                        Role::Channel(c) => b.channels[c]
                            .values
                            .push(t.parse::<f64>().map_err(|_| parse_err())? as f32),
                    }
                }
                b.points.push(p);
                read += 1;
            }
            if read != h.points {
                return Err(truncated(format!(
                    "{read} data lines of the {} POINTS",
                    h.points
                )));
            }
            Ok(b.finish(h.width, h.height))
        }
        Data::Binary => {
            let need = h
                .points
                .checked_mul(record)
                .ok_or_else(|| bad(path, "POINTS·record size overflows"))?;
            if body.len() < need {
                return Err(truncated(format!(
                    "{} POINTS of {record} bytes need {need} bytes, {} present",
                    h.points,
                    body.len()
                )));
            }
            let mut b = Builder::new(&h.fields, h.points);
            for rec in body[..need].chunks_exact(record.max(1)).take(h.points) {
                let mut p = Vec3::zeros();
                let mut off = 0;
                for (i, f) in h.fields.iter().enumerate() {
                    let v = &rec[off..off + f.size];
                    off += f.size * f.count;
                    match b.roles[i] {
                        Role::Skip => {}
                        Role::Rgb => b.push_rgb(packed(v)),
                        Role::Pos(c) => p[c] = value(v, f.kind, f.size),
                        Role::Channel(c) => {
                            b.channels[c].values.push(value(v, f.kind, f.size) as f32)
                        }
                    }
                }
                b.points.push(p);
            }
            Ok(b.finish(h.width, h.height))
        }
        Data::Compressed => {
            if body.len() < 8 {
                return Err(truncated("binary_compressed size words".into()));
            }
            let csize = u32::from_le_bytes([body[0], body[1], body[2], body[3]]) as usize;
            let ulen = u32::from_le_bytes([body[4], body[5], body[6], body[7]]) as usize;
            let need = h
                .points
                .checked_mul(record)
                .ok_or_else(|| bad(path, "POINTS·record size overflows"))?;
            if ulen != need {
                return Err(IoError::CountMismatch {
                    path: path.to_path_buf(),
                    what: "uncompressed bytes vs POINTS·record size".into(),
                    expected: need,
                    found: ulen,
                });
            }
            if body.len() - 8 < csize {
                return Err(truncated(format!(
                    "compressed block of {csize} bytes, {} present",
                    body.len() - 8
                )));
            }
            let raw = if need == 0 {
                Vec::new()
            } else {
                // LZF expands at most ~ (264/3)x; reject claims beyond that before allocating.
                if need > csize.saturating_mul(100) + 1024 {
                    return Err(IoError::Decompress {
                        path: path.to_path_buf(),
                        reason: format!("{csize} compressed bytes cannot hold {need} bytes"),
                    });
                }
                lzf::decompress(&body[8..8 + csize], need).map_err(|e| IoError::Decompress {
                    path: path.to_path_buf(),
                    reason: e.to_string(),
                })?
            };
            if raw.len() != need {
                return Err(IoError::CountMismatch {
                    path: path.to_path_buf(),
                    what: "decompressed bytes".into(),
                    expected: need,
                    found: raw.len(),
                });
            }
            let n = h.points;
            let mut b = Builder::new(&h.fields, n);
            b.points.resize(n, Vec3::zeros());
            // Structure of arrays: field i occupies n·size·count bytes.
            let mut off = 0;
            for (i, f) in h.fields.iter().enumerate() {
                let stride = f.size * f.count;
                let block = &raw[off..off + n * stride];
                off += n * stride;
                match b.roles[i] {
                    Role::Skip => {}
                    Role::Rgb => {
                        for v in block.chunks_exact(stride) {
                            b.push_rgb(packed(&v[..f.size]));
                        }
                    }
                    Role::Pos(c) => {
                        for (p, v) in b.points.iter_mut().zip(block.chunks_exact(stride)) {
                            p[c] = value(v, f.kind, f.size);
                        }
                    }
                    Role::Channel(c) => {
                        let ch = &mut b.channels[c].values;
                        ch.extend(
                            block
                                .chunks_exact(stride)
                                .map(|v| value(v, f.kind, f.size) as f32),
                        );
                    }
                }
            }
            Ok(b.finish(h.width, h.height))
        }
    }
}

/// Read a PCD file.
///
/// # Errors
/// [`IoError`] naming the file and the problem.
pub fn read_cloud(path: &Path) -> Result<LoadedCloud, IoError> {
    parse_cloud(&read_bytes(path)?, path)
}

/// Encode a cloud as PCD. `compressed` selects `binary_compressed` (LZF,
/// structure of arrays) instead of `binary`. Positions are written as
/// `F 4`; `r`, `g`, `b` channels are packed into one `rgb` `U 4` field
/// (`0x00RRGGBB`); other channels are written as `F 4` fields.
pub fn encode_cloud(cloud: &PointCloud, compressed: bool) -> Vec<u8> {
    let n = cloud.len();
    let (rgb, mut others) = cloud.rgb_and_other_channels();
    others.retain(|a| a.values.len() == n);
    let mut names = vec!["x".to_string(), "y".into(), "z".into()];
    if rgb.is_some() {
        names.push("rgb".into());
    }
    names.extend(
        others
            .iter()
            .map(|a| a.name.replace(char::is_whitespace, "_")),
    );
    let nf = names.len();
    let kinds: Vec<&str> = (0..nf)
        .map(|i| if rgb.is_some() && i == 3 { "U" } else { "F" })
        .collect();
    let header = format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\nCOUNT {}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {}\n",
        names.join(" "),
        vec!["4"; nf].join(" "),
        kinds.join(" "),
        vec!["1"; nf].join(" "),
        if compressed { "binary_compressed" } else { "binary" }
    );
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u32;
    let field = |fi: usize, i: usize| -> [u8; 4] {
        if fi < 3 {
            (cloud.points[i][fi] as f32).to_le_bytes()
        } else if let (Some(ch), true) = (&rgb, fi == 3) {
            ((byte(ch[0][i]) << 16) | (byte(ch[1][i]) << 8) | byte(ch[2][i])).to_le_bytes()
        } else {
            let k = fi - 3 - usize::from(rgb.is_some());
            others[k].values[i].to_le_bytes()
        }
    };
    let mut raw = Vec::with_capacity(n * nf * 4);
    if compressed {
        for fi in 0..nf {
            for i in 0..n {
                raw.extend_from_slice(&field(fi, i));
            }
        }
    } else {
        for i in 0..n {
            for fi in 0..nf {
                raw.extend_from_slice(&field(fi, i));
            }
        }
    }
    let mut out = header.into_bytes();
    if compressed {
        // lzf refuses incompressible input; store it as literal runs then.
        let comp = lzf::compress(&raw).unwrap_or_else(|_| literal_lzf(&raw));
        out.extend_from_slice(&(comp.len() as u32).to_le_bytes());
        out.extend_from_slice(&(raw.len() as u32).to_le_bytes());
        out.extend_from_slice(&comp);
    } else {
        out.extend_from_slice(&raw);
    }
    out
}

/// LZF stream made only of literal runs (valid for any input).
fn literal_lzf(raw: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(raw.len() + raw.len() / 32 + 1);
    for chunk in raw.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

/// Write a cloud as PCD (see [`encode_cloud`]).
///
/// # Errors
/// [`IoError::Io`] naming the file.
pub fn write_cloud(path: &Path, cloud: &PointCloud, compressed: bool) -> Result<(), IoError> {
    std::fs::write(path, encode_cloud(cloud, compressed)).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.pcd")
    }

    #[test]
    fn ascii_with_packed_float_rgb_label_and_nan() {
        // rgb 0x00FF8000 as float bits.
        let f = f32::from_bits(0x00FF_8000);
        let text = format!(
            "# c\nVERSION .7\nFIELDS x y z rgb label\nSIZE 4 4 4 4 4\nTYPE F F F F U\nCOUNT 1 1 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA ascii\n1 2 3 {f:e} 7\nnan nan nan 0 0\n4 5 6 {f:e} 8\n0 0 0 0 9\n"
        );
        let c = parse_cloud(text.as_bytes(), p()).unwrap();
        assert_eq!(c.report.points_read, 4);
        assert_eq!(c.report.dropped_non_finite, 1);
        assert_eq!((c.report.width, c.report.height), (2, 2));
        assert_eq!(c.cloud.points[1], Vec3::new(4.0, 5.0, 6.0));
        assert_eq!(c.cloud.attribute("r").unwrap()[0], 1.0);
        assert!((c.cloud.attribute("g").unwrap()[0] - 128.0 / 255.0).abs() < 1e-6);
        assert_eq!(c.cloud.attribute("b").unwrap()[0], 0.0);
        assert_eq!(c.cloud.attribute("label").unwrap(), &[7.0, 8.0, 9.0]);
    }

    #[test]
    fn binary_and_compressed_decode_hand_made_bytes() {
        // Two points, fields x y z rgba(U) intensity(u16), hand-encoded.
        let pts = [
            ([1.0f32, 2.0, 3.0], 0xFF10_2030u32, 5u16),
            ([-1.0, 0.5, 9.0], 0x0000_00FF, 65535),
        ];
        let head = |d: &str| {
            format!("VERSION 0.7\nFIELDS x y z rgba intensity\nSIZE 4 4 4 4 2\nTYPE F F F U U\nCOUNT 1 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA {d}\n").into_bytes()
        };
        let mut bin = head("binary");
        for (xyz, c, i) in pts {
            for v in xyz {
                bin.extend_from_slice(&v.to_le_bytes());
            }
            bin.extend_from_slice(&c.to_le_bytes());
            bin.extend_from_slice(&i.to_le_bytes());
        }
        let mut soa = Vec::new();
        for k in 0..3 {
            for (xyz, _, _) in pts {
                soa.extend_from_slice(&xyz[k].to_le_bytes());
            }
        }
        for (_, c, _) in pts {
            soa.extend_from_slice(&c.to_le_bytes());
        }
        for (_, _, i) in pts {
            soa.extend_from_slice(&i.to_le_bytes());
        }
        let lit = literal_lzf(&soa);
        let mut comp = head("binary_compressed");
        comp.extend_from_slice(&(lit.len() as u32).to_le_bytes());
        comp.extend_from_slice(&(soa.len() as u32).to_le_bytes());
        comp.extend_from_slice(&lit);
        for bytes in [&bin, &comp] {
            let c = parse_cloud(bytes, p()).unwrap();
            assert_eq!(
                c.cloud.points,
                vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 9.0)]
            );
            assert_eq!(c.cloud.attribute("r").unwrap(), &[16.0 / 255.0, 0.0]);
            assert_eq!(c.cloud.attribute("g").unwrap(), &[32.0 / 255.0, 0.0]);
            assert_eq!(c.cloud.attribute("b").unwrap(), &[48.0 / 255.0, 1.0]);
            assert_eq!(c.cloud.attribute("intensity").unwrap(), &[5.0, 65535.0]);
        }
        let e = parse_cloud(&bin[..bin.len() - 1], p()).unwrap_err();
        assert!(matches!(e, IoError::Truncated { .. }), "{e}");
        let mut lie = comp.clone();
        let at = lie.len() - lit.len() - 4;
        lie[at..at + 4].copy_from_slice(&1000u32.to_le_bytes());
        assert!(matches!(
            parse_cloud(&lie, p()),
            Err(IoError::CountMismatch { .. })
        ));
    }

    #[test]
    fn header_errors() {
        let cases = [
            "FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n",
            "FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA binary\n",
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 1\nDATA ascii\n",
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA xml\n",
            "FIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA binary\n",
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\n",
        ];
        for c in cases {
            let e = parse_cloud(c.as_bytes(), p()).unwrap_err();
            assert!(e.to_string().contains("t.pcd"), "{e}");
        }
    }

    #[test]
    fn count_zero_is_a_header_error_in_every_encoding() {
        for data in ["ascii\n1 2 3\n", "binary\n", "binary_compressed\n"] {
            let mut b = format!(
                "FIELDS x y z w\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 0\nWIDTH 1\nPOINTS 1\nDATA {data}"
            )
            .into_bytes();
            b.extend_from_slice(&[0u8; 32]);
            let e = parse_cloud(&b, p()).unwrap_err();
            assert!(
                matches!(&e, IoError::BadHeader { reason, .. } if reason.contains("COUNT 0")),
                "{data}: {e}"
            );
        }
    }

    #[test]
    fn a_short_count_list_without_size_and_type_is_a_count_mismatch() {
        // The fuzz pass's panic (index out of bounds), minimised.
        let b = b"FIELDS x y z w\nCOUNT 1 1 1\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3 4\n";
        let e = parse_cloud(b, p()).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::CountMismatch {
                    expected: 4,
                    found: 3,
                    ..
                }
            ),
            "{e}"
        );
        // Without SIZE, TYPE and COUNT an ascii file is still read as floats.
        let b = b"FIELDS x y z w\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3 4\n";
        assert_eq!(
            parse_cloud(b, p()).unwrap().cloud.attribute("w").unwrap(),
            &[4.0]
        );
    }

    #[test]
    fn forty_thousand_fields_are_read_in_linear_time() {
        // 13 s before (a linear name search per field); one binary point of 40 k U 1 fields.
        let n = 40_000;
        let names: Vec<String> = (0..n).map(|k| format!("f{k}")).collect();
        let rep = |s: &str| vec![s; n].join(" ");
        let mut b = format!(
            "FIELDS x y z {}\nSIZE 4 4 4 {}\nTYPE F F F {}\nCOUNT 1 1 1 {}\nWIDTH 1\nPOINTS 1\nDATA binary\n",
            names.join(" "),
            rep("1"),
            rep("U"),
            rep("1")
        )
        .into_bytes();
        b.extend_from_slice(&[0u8; 12]);
        b.extend((0..n).map(|k| (k % 251) as u8));
        let c = parse_cloud(&b, p()).unwrap();
        assert_eq!(c.cloud.attributes.len(), n);
        assert_eq!(
            c.cloud.attribute("f39999").unwrap(),
            &[(39_999 % 251) as f32]
        );
    }

    #[test]
    fn writer_round_trips_binary_and_compressed() {
        let mut cloud = PointCloud::from_points(
            (0..50)
                .map(|i| Vec3::new(i as f64, 0.5 * i as f64, -1.0))
                .collect(),
        );
        let r: Vec<f32> = (0..50).map(|i| (i * 5) as f32 / 255.0).collect();
        cloud.set_attribute("r", r.clone()).unwrap();
        cloud.set_attribute("g", vec![0.0; 50]).unwrap();
        cloud.set_attribute("b", vec![1.0; 50]).unwrap();
        cloud
            .set_attribute("label", (0..50).map(|i| (i % 3) as f32).collect())
            .unwrap();
        for compressed in [false, true] {
            let c = parse_cloud(&encode_cloud(&cloud, compressed), p())
                .unwrap()
                .cloud;
            assert_eq!(c.points, cloud.points);
            assert_eq!(c.attribute("r").unwrap(), &r[..]);
            assert_eq!(c.attribute("label"), cloud.attribute("label"));
        }
    }
}
