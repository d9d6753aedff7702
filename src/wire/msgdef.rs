//! ROS 2 message definitions: the `.msg` texts sepmem speaks, a small `.msg`
//! parser, RIHS01 type hashes (REP-2011), rosbag2-style concatenated
//! definitions for MCAP schemas, and a structural CDR checker.
//!
//! * [`definition_text`] holds the `.msg` text of every type in the registry:
//!   the standard types (as shipped by ROS 2 Jazzy, comments removed) and
//!   sepmem's own messages (embedded verbatim from `msg/msg/*.msg`) and
//!   MoveIt's `CollisionObject` with `ObjectType` (embedded verbatim from
//!   `msg/third_party/`, see its README for sources and licences).
//! * [`parse_msg`] parses one `.msg` text into fields and constants.
//! * [`rihs01`] computes a type hash by the reference algorithm of
//!   `rosidl_generator_type_description` (type description JSON, default
//!   values removed, referenced types sorted by name, Python `json.dumps`
//!   spacing, SHA-256). The hard-coded constants in [`super::msgs`] are
//!   checked against it by the tests.
//! * [`full_definition`] concatenates the root text and every dependency as
//!   rosbag2's `LocalMessageDefinitionSource::get_full_text` does
//!   (`=`×80 separators and `MSG: pkg/Type` lines), for `ros2msg` schemas.
//! * [`check_cdr`] walks CDR bytes against a definition and fails with a
//!   typed error when a length or field runs past the end. The `cdr` crate
//!   allocates a string or byte blob of the announced length before reading
//!   it, so a forged length would otherwise allocate gigabytes.

use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::OnceLock;

use super::WireError;

/// `(type name, .msg text)` of every type sepmem encodes or decodes.
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n"),
    ("builtin_interfaces/msg/Duration", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/msg/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    (
        "std_msgs/msg/ColorRGBA",
        "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    ),
    (
        "sensor_msgs/msg/PointField",
        "uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\n\
         uint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n\
         string name\nuint32 offset\nuint8  datatype\nuint32 count\n",
    ),
    (
        "sensor_msgs/msg/PointCloud2",
        "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n\
         bool    is_bigendian\nuint32  point_step\nuint32  row_step\nuint8[] data\nbool is_dense\n",
    ),
    (
        "sensor_msgs/msg/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
    ),
    ("geometry_msgs/msg/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/msg/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/msg/Pose",
        "Point position\nQuaternion orientation\n",
    ),
    ("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("visualization_msgs/msg/UVCoordinate", "float32 u\nfloat32 v\n"),
    (
        "visualization_msgs/msg/MeshFile",
        "string filename\nuint8[] data\n",
    ),
    (
        "visualization_msgs/msg/Marker",
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
         int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
         int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
         int32 ARROW_STRIP=12\n\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\n\
         std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
         geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
         builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
         std_msgs/ColorRGBA[] colors\nstring texture_resource\nsensor_msgs/CompressedImage texture\n\
         UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\nMeshFile mesh_file\n\
         bool mesh_use_embedded_materials\n",
    ),
    ("visualization_msgs/msg/MarkerArray", "Marker[] markers\n"),
    ("shape_msgs/msg/MeshTriangle", "uint32[3] vertex_indices\n"),
    (
        "shape_msgs/msg/Mesh",
        "MeshTriangle[] triangles\ngeometry_msgs/Point[] vertices\n",
    ),
    ("geometry_msgs/msg/Point32", "float32 x\nfloat32 y\nfloat32 z\n"),
    ("geometry_msgs/msg/Polygon", "Point32[] points\n"),
    (
        "shape_msgs/msg/SolidPrimitive",
        "uint8 BOX=1\nuint8 SPHERE=2\nuint8 CYLINDER=3\nuint8 CONE=4\nuint8 PRISM=5\n\n\
         uint8 type\n\nfloat64[<=3] dimensions\n\nuint8 BOX_X=0\nuint8 BOX_Y=1\nuint8 BOX_Z=2\n\n\
         uint8 SPHERE_RADIUS=0\n\nuint8 CYLINDER_HEIGHT=0\nuint8 CYLINDER_RADIUS=1\n\n\
         uint8 CONE_HEIGHT=0\nuint8 CONE_RADIUS=1\n\nuint8 PRISM_HEIGHT=0\n\n\
         geometry_msgs/Polygon polygon\n",
    ),
    ("shape_msgs/msg/Plane", "float64[4] coef\n"),
    (
        "object_recognition_msgs/msg/ObjectType",
        include_str!("../../msg/third_party/object_recognition_msgs/msg/ObjectType.msg"),
    ),
    (
        "moveit_msgs/msg/CollisionObject",
        include_str!("../../msg/third_party/moveit_msgs/msg/CollisionObject.msg"),
    ),
    ("diagnostic_msgs/msg/KeyValue", "string key\nstring value\n"),
    (
        "diagnostic_msgs/msg/DiagnosticStatus",
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n\nbyte level\nstring name\n\
         string message\nstring hardware_id\nKeyValue[] values\n",
    ),
    (
        "diagnostic_msgs/msg/DiagnosticArray",
        "std_msgs/Header header\nDiagnosticStatus[] status\n",
    ),
    (
        "sepmem_msgs/msg/SurfaceMesh",
        include_str!("../../msg/msg/SurfaceMesh.msg"),
    ),
    (
        "sepmem_msgs/msg/FrameDiagnostics",
        include_str!("../../msg/msg/FrameDiagnostics.msg"),
    ),
    (
        "sepmem_msgs/msg/GroundTruth",
        include_str!("../../msg/msg/GroundTruth.msg"),
    ),
];

/// Names of every type in the registry, in registry order.
pub fn known_types() -> impl Iterator<Item = &'static str> {
    DEFINITIONS.iter().map(|(n, _)| *n)
}

/// The `.msg` text of a registered type (`pkg/msg/Name`).
pub fn definition_text(type_name: &str) -> Option<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(n, _)| *n == type_name)
        .map(|(_, t)| *t)
}

/// A primitive ROS field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primitive {
    /// `bool` (1 byte).
    Bool,
    /// `byte` (octet, 1 byte).
    Byte,
    /// `char` (uint8 in ROS 2 `.msg`).
    Char,
    /// `int8`.
    Int8,
    /// `uint8`.
    Uint8,
    /// `int16`.
    Int16,
    /// `uint16`.
    Uint16,
    /// `int32`.
    Int32,
    /// `uint32`.
    Uint32,
    /// `int64`.
    Int64,
    /// `uint64`.
    Uint64,
    /// `float32`.
    Float32,
    /// `float64`.
    Float64,
}

impl Primitive {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "bool" => Self::Bool,
            "byte" => Self::Byte,
            "char" => Self::Char,
            "int8" => Self::Int8,
            "uint8" => Self::Uint8,
            "int16" => Self::Int16,
            "uint16" => Self::Uint16,
            "int32" => Self::Int32,
            "uint32" => Self::Uint32,
            "int64" => Self::Int64,
            "uint64" => Self::Uint64,
            "float32" => Self::Float32,
            "float64" => Self::Float64,
            _ => return None,
        })
    }

    /// Size in bytes on the CDR wire (also its alignment).
    pub fn size(self) -> usize {
        match self {
            Self::Bool | Self::Byte | Self::Char | Self::Int8 | Self::Uint8 => 1,
            Self::Int16 | Self::Uint16 => 2,
            Self::Int32 | Self::Uint32 | Self::Float32 => 4,
            Self::Int64 | Self::Uint64 | Self::Float64 => 8,
        }
    }

    /// `FieldType.msg` type id (REP-2011).
    fn type_id(self) -> u32 {
        match self {
            Self::Int8 => 2,
            Self::Uint8 | Self::Char => 3,
            Self::Int16 => 4,
            Self::Uint16 => 5,
            Self::Int32 => 6,
            Self::Uint32 => 7,
            Self::Int64 => 8,
            Self::Uint64 => 9,
            Self::Float32 => 10,
            Self::Float64 => 11,
            Self::Bool => 15,
            Self::Byte => 16,
        }
    }
}

/// The element type of a field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BaseType {
    /// A primitive number or bool.
    Primitive(Primitive),
    /// `string` or `string<=N` (capacity 0 = unbounded).
    String {
        /// Upper bound on the length, 0 when unbounded.
        capacity: usize,
    },
    /// `wstring` or `wstring<=N`.
    WString {
        /// Upper bound on the length, 0 when unbounded.
        capacity: usize,
    },
    /// Another message, fully qualified (`pkg/msg/Name`).
    Nested(String),
}

/// Array-ness of a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArrayKind {
    /// A single value.
    Single,
    /// `T[N]`.
    Fixed(usize),
    /// `T[<=N]`.
    Bounded(usize),
    /// `T[]`.
    Unbounded,
}

/// One field of a message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// Field name.
    pub name: String,
    /// Element type.
    pub base: BaseType,
    /// Array-ness.
    pub array: ArrayKind,
}

/// A parsed `.msg` definition.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MsgDef {
    /// Fully qualified name, `pkg/msg/Name`.
    pub type_name: String,
    /// Fields in declaration order (constants excluded).
    pub fields: Vec<Field>,
    /// Constants as `(name, value text)`.
    pub constants: Vec<(String, String)>,
}

fn qualify(ty: &str, own_pkg: &str) -> String {
    match ty.split('/').collect::<Vec<_>>().as_slice() {
        [name] if *name == "Header" => "std_msgs/msg/Header".to_string(),
        [name] => format!("{own_pkg}/msg/{name}"),
        [pkg, name] => format!("{pkg}/msg/{name}"),
        _ => ty.to_string(),
    }
}

fn msg_error(type_name: &str, line: usize, problem: String) -> WireError {
    WireError::MsgDef {
        type_name: type_name.to_string(),
        line,
        problem,
    }
}

/// Parse a `.msg` text for type `type_name` (`pkg/msg/Name`).
///
/// Handles comments, constants (`TYPE NAME=VALUE`), default values
/// (`TYPE NAME VALUE`), bounded strings (`string<=N`), and fixed, bounded and
/// unbounded arrays. Unqualified nested types resolve to the same package.
///
/// # Errors
/// [`WireError::MsgDef`] naming the line and the problem.
pub fn parse_msg(type_name: &str, text: &str) -> Result<MsgDef, WireError> {
    let own_pkg = type_name.split('/').next().unwrap_or_default();
    let mut def = MsgDef {
        type_name: type_name.to_string(),
        fields: Vec::new(),
        constants: Vec::new(),
    };
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (ty, rest) = line
            .split_once(char::is_whitespace)
            .ok_or_else(|| msg_error(type_name, line_no, format!("no field name in `{line}`")))?;
        let rest = rest.trim_start();
        // Constant: NAME=VALUE (the value of a string constant may hold '#').
        let eq = rest.find('=');
        let hash = rest.find('#');
        if let Some(eq) = eq.filter(|&e| hash.is_none_or(|h| e < h)) {
            let name = rest[..eq].trim().to_string();
            let mut value = rest[eq + 1..].trim();
            if !ty.starts_with("string") {
                value = value.split('#').next().unwrap_or_default().trim();
            }
            def.constants.push((name, value.to_string()));
            continue;
        }
        let rest = rest.split('#').next().unwrap_or_default();
        let name = rest
            .split_whitespace()
            .next()
            .ok_or_else(|| msg_error(type_name, line_no, format!("no field name in `{line}`")))?;
        if !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(msg_error(
                type_name,
                line_no,
                format!("invalid field name `{name}`"),
            ));
        }
        let (elem, array) = match ty.find('[') {
            None => (ty, ArrayKind::Single),
            Some(b) => {
                let inner = ty[b + 1..].strip_suffix(']').ok_or_else(|| {
                    msg_error(type_name, line_no, format!("unclosed array in `{ty}`"))
                })?;
                let parse_n = |s: &str| {
                    s.trim().parse::<usize>().map_err(|_| {
                        msg_error(type_name, line_no, format!("bad array size in `{ty}`"))
                    })
                };
                let kind = if inner.is_empty() {
                    ArrayKind::Unbounded
                } else if let Some(n) = inner.strip_prefix("<=") {
                    ArrayKind::Bounded(parse_n(n)?)
                } else {
                    ArrayKind::Fixed(parse_n(inner)?)
                };
                (&ty[..b], kind)
            }
        };
        let base = if let Some(p) = Primitive::parse(elem) {
            BaseType::Primitive(p)
        } else if let Some(cap) = elem.strip_prefix("string") {
            BaseType::String {
                capacity: parse_capacity(cap, type_name, line_no)?,
            }
        } else if let Some(cap) = elem.strip_prefix("wstring") {
            BaseType::WString {
                capacity: parse_capacity(cap, type_name, line_no)?,
            }
        } else if elem
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/')
            && elem.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
        {
            BaseType::Nested(qualify(elem, own_pkg))
        } else {
            return Err(msg_error(
                type_name,
                line_no,
                format!("unknown field type `{elem}`"),
            ));
        };
        def.fields.push(Field {
            name: name.to_string(),
            base,
            array,
        });
    }
    Ok(def)
}

fn parse_capacity(s: &str, type_name: &str, line: usize) -> Result<usize, WireError> {
    if s.is_empty() {
        return Ok(0);
    }
    s.strip_prefix("<=")
        .and_then(|n| n.trim().parse().ok())
        .ok_or_else(|| msg_error(type_name, line, format!("bad string bound `{s}`")))
}

/// Parsed definitions by type name.
pub type DefMap = HashMap<String, MsgDef>;

/// The parsed registry (parsed once, on first use).
///
/// # Errors
/// [`WireError::MsgDef`] if an embedded definition does not parse (the tests
/// rule this out).
pub fn registry() -> Result<&'static DefMap, WireError> {
    static REGISTRY: OnceLock<Result<DefMap, WireError>> = OnceLock::new();
    REGISTRY
        .get_or_init(|| {
            DEFINITIONS
                .iter()
                .map(|(n, t)| parse_msg(n, t).map(|d| (n.to_string(), d)))
                .collect()
        })
        .as_ref()
        .map_err(Clone::clone)
}

fn lookup<'a>(defs: &'a DefMap, type_name: &str) -> Result<&'a MsgDef, WireError> {
    defs.get(type_name)
        .ok_or_else(|| WireError::UnknownType(type_name.to_string()))
}

/// Every type `root` refers to, directly or not (excluding `root`), sorted.
///
/// # Errors
/// [`WireError::UnknownType`] when a referenced type is not in `defs`.
pub fn dependencies(defs: &DefMap, root: &str) -> Result<BTreeSet<String>, WireError> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![root.to_string()];
    while let Some(t) = stack.pop() {
        for f in &lookup(defs, &t)?.fields {
            if let BaseType::Nested(n) = &f.base {
                if n != root && seen.insert(n.clone()) {
                    stack.push(n.clone());
                }
            }
        }
    }
    Ok(seen)
}

fn json_type_description(def: &MsgDef, out: &mut String) {
    out.push_str("{\"type_name\": \"");
    out.push_str(&def.type_name);
    out.push_str("\", \"fields\": [");
    let dummy = [Field {
        name: "structure_needs_at_least_one_member".to_string(),
        base: BaseType::Primitive(Primitive::Uint8),
        array: ArrayKind::Single,
    }];
    let fields: &[Field] = if def.fields.is_empty() {
        &dummy
    } else {
        &def.fields
    };
    for (i, f) in fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let (base_id, string_capacity, nested) = match &f.base {
            BaseType::Primitive(p) => (p.type_id(), 0, ""),
            BaseType::String { capacity: 0 } => (17, 0, ""),
            BaseType::WString { capacity: 0 } => (18, 0, ""),
            BaseType::String { capacity } => (21, *capacity, ""),
            BaseType::WString { capacity } => (22, *capacity, ""),
            BaseType::Nested(n) => (1, 0, n.as_str()),
        };
        let (offset, capacity) = match f.array {
            ArrayKind::Single => (0, 0),
            ArrayKind::Fixed(n) => (48, n),
            ArrayKind::Bounded(n) => (96, n),
            ArrayKind::Unbounded => (144, 0),
        };
        out.push_str(&format!(
            "{{\"name\": \"{}\", \"type\": {{\"type_id\": {}, \"capacity\": {}, \"string_capacity\": {}, \"nested_type_name\": \"{}\"}}}}",
            f.name,
            base_id + offset,
            capacity,
            string_capacity,
            nested
        ));
    }
    out.push_str("]}");
}

/// The RIHS01 hash of `type_name` (`RIHS01_<64 hex>`) computed from `defs`.
///
/// # Errors
/// [`WireError::UnknownType`] when the type or one it refers to is missing.
pub fn rihs01(defs: &DefMap, type_name: &str) -> Result<String, WireError> {
    let root = lookup(defs, type_name)?;
    let mut s = String::from("{\"type_description\": ");
    json_type_description(root, &mut s);
    s.push_str(", \"referenced_type_descriptions\": [");
    for (i, dep) in dependencies(defs, type_name)?.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        json_type_description(lookup(defs, dep)?, &mut s);
    }
    s.push_str("]}");
    Ok(format!(
        "RIHS01_{}",
        hex::encode(Sha256::digest(s.as_bytes()))
    ))
}

/// `pkg/msg/Name` → `pkg/Name`, the spelling used after `MSG:` in schemas.
fn short_name(type_name: &str) -> String {
    type_name.replacen("/msg/", "/", 1)
}

/// The rosbag2 full message definition of a registered type: the root
/// `.msg` text followed, depth first with each level's dependencies in
/// sorted order (each type once), by `\n` + `=`×80 + `\nMSG: pkg/Name\n` + text.
///
/// # Errors
/// [`WireError::UnknownType`] when the type or a dependency is not registered.
pub fn full_definition(type_name: &str) -> Result<String, WireError> {
    let defs = registry()?;
    let mut out = definition_text(type_name)
        .ok_or_else(|| WireError::UnknownType(type_name.to_string()))?
        .to_string();
    let mut seen = BTreeSet::new();
    append_dependencies(defs, type_name, &mut seen, &mut out)?;
    Ok(out)
}

fn append_dependencies(
    defs: &DefMap,
    type_name: &str,
    seen: &mut BTreeSet<String>,
    out: &mut String,
) -> Result<(), WireError> {
    let direct: BTreeSet<&str> = lookup(defs, type_name)?
        .fields
        .iter()
        .filter_map(|f| match &f.base {
            BaseType::Nested(n) => Some(n.as_str()),
            _ => None,
        })
        .collect();
    for dep in direct {
        if seen.insert(dep.to_string()) {
            let text =
                definition_text(dep).ok_or_else(|| WireError::UnknownType(dep.to_string()))?;
            out.push('\n');
            out.push_str(&"=".repeat(80));
            out.push_str("\nMSG: ");
            out.push_str(&short_name(dep));
            out.push('\n');
            out.push_str(text);
            append_dependencies(defs, dep, seen, out)?;
        }
    }
    Ok(())
}

/// Map of field names to constants, for documentation and tests.
pub fn constants(type_name: &str) -> Result<BTreeMap<String, String>, WireError> {
    Ok(lookup(registry()?, type_name)?
        .constants
        .iter()
        .cloned()
        .collect())
}

/// Walk CDR `bytes` (with the 4-byte encapsulation header) against the
/// definition of `type_name`; return the byte length of the payload used.
///
/// Alignment is relative to the first byte after the header (XCDR1); both
/// endiannesses are accepted; trailing bytes are allowed.
///
/// # Errors
/// [`WireError::BadEncapsulation`] or [`WireError::Truncated`] naming the
/// field whose data runs past the end.
pub fn check_cdr(type_name: &str, bytes: &[u8]) -> Result<usize, WireError> {
    let header: [u8; 4] = bytes
        .get(..4)
        .and_then(|h| h.try_into().ok())
        .ok_or_else(|| WireError::Truncated {
            type_name: type_name.to_string(),
            field: "encapsulation header".to_string(),
            offset: 0,
            need: 4,
            have: bytes.len(),
        })?;
    let little = match header[..2] {
        [0, 0] | [0, 2] => false,
        [0, 1] | [0, 3] => true,
        _ => return Err(WireError::BadEncapsulation { header }),
    };
    let mut w = Walker {
        buf: &bytes[4..],
        pos: 0,
        little,
        root: type_name,
    };
    w.message(registry()?, type_name, "")?;
    Ok(w.pos)
}

/// `(alignment, size)` of message `type_name` when every primitive in it
/// (nested messages and fixed arrays included) has one size `a` and it holds
/// no string or sequence: its CDR encoding is then exactly `size` bytes at
/// any offset aligned to `a`, with no padding. `None` otherwise (and for
/// empty messages, or nesting deeper than 16).
fn uniform_layout(defs: &DefMap, type_name: &str, depth: usize) -> Option<(usize, usize)> {
    if depth > 16 {
        return None;
    }
    let def = defs.get(type_name)?;
    let (mut align, mut size) = (0usize, 0usize);
    for f in &def.fields {
        let n = match f.array {
            ArrayKind::Single => 1,
            ArrayKind::Fixed(n) => n,
            ArrayKind::Bounded(_) | ArrayKind::Unbounded => return None,
        };
        let (a, s) = match &f.base {
            BaseType::Primitive(prim) => (prim.size(), prim.size()),
            BaseType::Nested(m) => uniform_layout(defs, m, depth + 1)?,
            BaseType::String { .. } | BaseType::WString { .. } => return None,
        };
        if align != 0 && a != align {
            return None;
        }
        align = a;
        size = size.checked_add(s.checked_mul(n)?)?;
    }
    (size > 0).then_some((align, size))
}

struct Walker<'a> {
    buf: &'a [u8],
    pos: usize,
    little: bool,
    root: &'a str,
}

impl Walker<'_> {
    fn truncated(&self, field: &str, need: usize) -> WireError {
        WireError::Truncated {
            type_name: self.root.to_string(),
            field: field.to_string(),
            offset: self.pos + 4,
            need,
            have: self.buf.len().saturating_sub(self.pos),
        }
    }

    fn take(&mut self, align: usize, n: usize, field: &str) -> Result<&[u8], WireError> {
        let start = self.pos.div_ceil(align) * align;
        let end = start
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| self.truncated(field, n))?;
        self.pos = end;
        Ok(&self.buf[start..end])
    }

    fn u32(&mut self, field: &str) -> Result<usize, WireError> {
        let b = self.take(4, 4, field)?;
        let arr = [b[0], b[1], b[2], b[3]];
        Ok(if self.little {
            u32::from_le_bytes(arr)
        } else {
            u32::from_be_bytes(arr)
        } as usize)
    }

    fn message(&mut self, defs: &DefMap, type_name: &str, path: &str) -> Result<(), WireError> {
        let def = lookup(defs, type_name)?;
        for f in &def.fields {
            let p = if path.is_empty() {
                f.name.clone()
            } else {
                format!("{path}.{}", f.name)
            };
            let count = match f.array {
                ArrayKind::Single => None,
                ArrayKind::Fixed(n) => Some(n),
                ArrayKind::Bounded(_) | ArrayKind::Unbounded => Some(self.u32(&p)?),
            };
            match (&f.base, count) {
                (BaseType::Primitive(prim), n) => {
                    let size = prim.size();
                    let n = n.unwrap_or(1);
                    let total = n.checked_mul(size).ok_or_else(|| self.truncated(&p, n))?;
                    self.take(size, total, &p)?;
                }
                (BaseType::String { .. } | BaseType::WString { .. }, n) => {
                    for _ in 0..n.unwrap_or(1) {
                        let len = self.u32(&p)?;
                        self.take(1, len, &p)?;
                    }
                }
                (BaseType::Nested(n), Some(count)) if count > 1 => {
                    if let Some((align, size)) = uniform_layout(defs, n, 0) {
                        // Elements of one primitive size and no sequences
                        // (points, triangles, colours): contiguous on the
                        // wire, so the array is checked as one block.
                        let total = count
                            .checked_mul(size)
                            .ok_or_else(|| self.truncated(&p, count))?;
                        self.take(align, total, &p)?;
                        continue;
                    }
                    for _ in 0..count {
                        let before = self.pos;
                        self.message(defs, n, &p)?;
                        if self.pos == before {
                            // An element without data: all the others are empty too.
                            break;
                        }
                    }
                }
                (BaseType::Nested(n), count) => {
                    for _ in 0..count.unwrap_or(1) {
                        let before = self.pos;
                        self.message(defs, n, &p)?;
                        if self.pos == before {
                            // An element without data: all the others are empty too.
                            break;
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parser_handles_constants_defaults_arrays_and_bounds() {
        let d = parse_msg(
            "p/msg/T",
            "# comment\nuint8 A = 3 # c\nstring S=\"x # y\"\nfloat64 w 1\nint32[3] f\n\
             string<=8[<=4] names\nOther[] o\nq/R r\n",
        )
        .unwrap();
        assert_eq!(d.constants.len(), 2);
        assert_eq!(d.constants[1].1, "\"x # y\"");
        assert_eq!(d.fields.len(), 5);
        assert_eq!(d.fields[1].array, ArrayKind::Fixed(3));
        assert_eq!(d.fields[2].base, BaseType::String { capacity: 8 });
        assert_eq!(d.fields[2].array, ArrayKind::Bounded(4));
        assert_eq!(d.fields[3].base, BaseType::Nested("p/msg/Other".into()));
        assert_eq!(d.fields[4].base, BaseType::Nested("q/msg/R".into()));
        assert!(parse_msg("p/msg/T", "int32[x] a\n").is_err());
        assert!(parse_msg("p/msg/T", "int32\n").is_err());
        assert!(parse_msg("p/msg/T", "in-t a\n").is_err());
    }

    #[test]
    fn uniform_arrays_are_checked_as_one_block_with_the_same_verdict() {
        let defs = registry().unwrap();
        assert_eq!(
            uniform_layout(defs, "geometry_msgs/msg/Point", 0),
            Some((8, 24))
        );
        assert_eq!(
            uniform_layout(defs, "std_msgs/msg/ColorRGBA", 0),
            Some((4, 16))
        );
        assert_eq!(uniform_layout(defs, "std_msgs/msg/Header", 0), None);
        // A marker whose points and colours hold 1000 entries each: the
        // encoder's bytes pass, and every truncation of them fails.
        let marker = crate::wire::msgs::Marker {
            points: vec![crate::wire::msgs::Point::default(); 1000],
            colors: vec![crate::wire::msgs::ColorRGBA::default(); 1000],
            ..Default::default()
        };
        let bytes = crate::wire::encode(&marker).unwrap();
        assert_eq!(
            check_cdr("visualization_msgs/msg/Marker", &bytes).unwrap(),
            bytes.len() - 4
        );
        for cut in [bytes.len() - 1, bytes.len() - 17, bytes.len() / 2, 40] {
            assert!(
                matches!(
                    check_cdr("visualization_msgs/msg/Marker", &bytes[..cut]),
                    Err(WireError::Truncated { .. })
                ),
                "cut {cut}"
            );
        }
    }

    #[test]
    fn walker_rejects_huge_lengths_without_allocating() {
        // Header with frame_id length 0xFFFFFFF0.
        let mut b = vec![0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0];
        b.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        let e = check_cdr("std_msgs/msg/Header", &b).unwrap_err();
        assert!(matches!(e, WireError::Truncated { ref field, .. } if field == "frame_id"));
        assert!(matches!(
            check_cdr("std_msgs/msg/Header", &[9, 9, 0, 0]),
            Err(WireError::BadEncapsulation { .. })
        ));
    }
}
